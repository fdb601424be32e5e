//! Collision shapes for `mesa check`: the convex hull of an asset and a convex decomposition
//! (by default the adaptive one of [`super::decompose`], whose parts stay within a tolerance of
//! the mesh; or parry3d's V-HACD), so that a bowl's or a cup's inside stays empty instead of
//! being filled by one hull.

use std::time::Instant;

use mesa_schemas::artifacts::{ConvexPart, Decomposition};
use parry3d::math::Point;
use parry3d::transformation::try_convex_hull;
use parry3d::transformation::vhacd::{VHACDParameters, VHACD};
use parry3d::transformation::voxelization::FillMode;

use super::decompose::{decompose, AdaptiveParams, OverTolerance};
use super::{AssetsConfig, DecompositionMethod};

/// The hull and the parts of one asset.
#[derive(Debug, Clone, PartialEq)]
pub struct Shapes {
    /// The convex hull of the whole asset.
    pub hull: ConvexPart,
    /// The convex decomposition.
    pub parts: Vec<ConvexPart>,
    /// How the parts were made.
    pub decomposition: Decomposition,
    /// Why the decomposition fell back to the hull, if it did.
    pub warning: Option<String>,
}

/// The volume enclosed by a closed triangle mesh (divergence theorem), cubic metres.
fn volume(points: &[Point<f32>], triangles: &[[u32; 3]]) -> f64 {
    let p = |i: u32| {
        let v = points[i as usize];
        [f64::from(v.x), f64::from(v.y), f64::from(v.z)]
    };
    let mut six_v = 0.0;
    for t in triangles {
        let (a, b, c) = (p(t[0]), p(t[1]), p(t[2]));
        six_v += a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
            + a[2] * (b[0] * c[1] - b[1] * c[0]);
    }
    (six_v / 6.0).abs()
}

/// `v` rounded to a multiple of `precision_m`, computed so that it prints short (0.4043, not
/// 0.40430000000000005).
fn round(v: f32, precision_m: f64) -> f64 {
    let v = f64::from(v);
    if precision_m > 0.0 {
        let scale = (1.0 / precision_m).round();
        (v * scale).round() / scale
    } else {
        v
    }
}

/// `v` metres rounded to a multiple of `precision_m`, printing short.
pub fn round_m(v: f64, precision_m: f64) -> f64 {
    if precision_m > 0.0 {
        let scale = (1.0 / precision_m).round();
        (v * scale).round() / scale
    } else {
        v
    }
}

/// The volume of a mesh that is closed once coincident vertices are merged (every edge shared
/// by exactly two triangles); `None` for an open mesh, whose divergence-theorem volume means
/// nothing (a single-surface bowl would look as full as its hull).
pub fn closed_volume(positions_m: &[[f64; 3]], triangles: &[[u32; 3]]) -> Option<f64> {
    // Seams split vertices that share a position: weld them (to 0.1 µm).
    let welded = crate::mesh::weld(positions_m, triangles.iter().copied(), 1e7)?;
    let mut edges: Vec<(u32, u32)> = welded
        .triangles
        .iter()
        .flat_map(|t| (0..3).map(move |k| (t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]))))
        .collect();
    edges.sort_unstable();
    if edges.is_empty() || edges.chunk_by(|a, b| a == b).any(|edge| edge.len() != 2) {
        return None;
    }
    Some(crate::mesh::signed_volume_of(positions_m, triangles.iter().copied()).abs())
}

/// A closed mesh filling at least this fraction of its hull is taken as convex: its hull is
/// its one part (V-HACD would cut even a cube, for voxelisation error).
const CONVEX_FILL: f64 = 0.98;

fn part(points: &[Point<f32>], triangles: &[[u32; 3]], precision_m: f64) -> ConvexPart {
    ConvexPart {
        points_m: points
            .iter()
            .map(|p| {
                [
                    round(p.x, precision_m),
                    round(p.y, precision_m),
                    round(p.z, precision_m),
                ]
            })
            .collect(),
        volume_m3: volume(points, triangles),
    }
}

/// The shapes of a triangle mesh given in the asset's table-aligned frame (metres). `None`
/// when the points span no volume (the caller has already rejected flat assets).
pub fn collision_shapes(
    positions_m: &[[f64; 3]],
    triangles: &[[u32; 3]],
    config: &AssetsConfig,
) -> Option<Shapes> {
    collision_shapes_until(positions_m, triangles, config, None)
}

/// [`collision_shapes`], the adaptive decomposition stopping at `deadline` (V-HACD cannot be
/// stopped: an asset over its budget reaches it decimated).
pub fn collision_shapes_until(
    positions_m: &[[f64; 3]],
    triangles: &[[u32; 3]],
    config: &AssetsConfig,
    deadline: Option<Instant>,
) -> Option<Shapes> {
    // f32 is parry3d's precision: 0.1 µm at a metre, far below the collision tolerances.
    let points: Vec<Point<f32>> = positions_m
        .iter()
        .map(|p| Point::new(p[0] as f32, p[1] as f32, p[2] as f32))
        .collect();
    let (hull_points, hull_triangles) = try_convex_hull(&points).ok()?;
    if hull_triangles.is_empty() {
        return None;
    }
    let hull = part(&hull_points, &hull_triangles, config.shape_precision_m);
    if config.decomposition == DecompositionMethod::Adaptive {
        return Some(adaptive_shapes(
            positions_m,
            triangles,
            hull,
            config,
            deadline,
        ));
    }
    let decomposition = Decomposition {
        method: "vhacd".to_owned(),
        max_parts: config.vhacd_max_parts,
        tolerance_m: None,
        max_deviation_m: None,
        solid: None,
        resolution: Some(config.vhacd_resolution),
        convex_hull_approximation: Some(true),
        concavity: Some(config.vhacd_concavity),
        out_of_time: None,
        simplified: None,
        part_budget: None,
        over_tolerance: None,
    };
    if hull.volume_m3 > 0.0
        && closed_volume(positions_m, triangles).is_some_and(|v| v >= CONVEX_FILL * hull.volume_m3)
    {
        return Some(Shapes {
            parts: vec![hull.clone()],
            hull,
            decomposition: Decomposition {
                method: "convex".to_owned(),
                ..decomposition
            },
            warning: None,
        });
    }
    // parry3d's V-HACD can fail (a panic inside its convex hull) on degenerate voxel sets; a
    // slightly different voxel grid or exact clipping hulls usually get past it.
    let attempts = [
        (config.vhacd_resolution, true),
        (config.vhacd_resolution, false),
        (
            config.vhacd_resolution + config.vhacd_resolution / 8 + 1,
            true,
        ),
        (
            config
                .vhacd_resolution
                .saturating_sub(config.vhacd_resolution / 8 + 1)
                .max(8),
            true,
        ),
    ];
    let mut parts: Vec<ConvexPart> = Vec::new();
    let mut used = decomposition.clone();
    for (resolution, approximation) in attempts {
        let params = VHACDParameters {
            resolution,
            concavity: config.vhacd_concavity as f32,
            max_convex_hulls: config.vhacd_max_parts,
            convex_hull_approximation: approximation,
            fill_mode: FillMode::FloodFill {
                detect_cavities: false,
            },
            ..VHACDParameters::default()
        };
        // V-HACD must not take a whole indexing run down on a mesh it cannot handle.
        let decomposed = std::panic::catch_unwind(|| {
            let vhacd = VHACD::decompose(&params, &points, triangles, true);
            vhacd.compute_exact_convex_hulls(&points, triangles)
        });
        if let Ok(hulls) = decomposed {
            parts = hulls
                .iter()
                .filter(|(p, t)| !p.is_empty() && !t.is_empty())
                .map(|(p, t)| part(p, t, config.shape_precision_m))
                .collect();
            used.resolution = Some(resolution);
            used.convex_hull_approximation = Some(approximation);
            if !parts.is_empty() {
                break;
            }
        }
    }
    let decomposition = used;
    if parts.is_empty() {
        return Some(Shapes {
            parts: vec![hull.clone()],
            hull,
            decomposition: Decomposition {
                method: "hull".to_owned(),
                ..decomposition
            },
            warning: Some(
                "the convex decomposition failed on this mesh: its collision shape is the \
                 convex hull (cavities are filled)"
                    .to_owned(),
            ),
        });
    }
    Some(Shapes {
        hull,
        parts,
        decomposition,
        warning: None,
    })
}

/// The adaptive decomposition, or the hull with a warning when it gives no part.
fn adaptive_shapes(
    positions_m: &[[f64; 3]],
    triangles: &[[u32; 3]],
    hull: ConvexPart,
    config: &AssetsConfig,
    deadline: Option<Instant>,
) -> Shapes {
    let params = AdaptiveParams {
        tolerance_m: config.decomposition_tolerance_m,
        max_parts: config.decomposition_max_parts.max(1) as usize,
        most_parts: config
            .decomposition_most_parts
            .max(config.decomposition_max_parts)
            .max(1) as usize,
        // Below a fifth of the tolerance, cutting again cannot help.
        min_size_m: config.decomposition_tolerance_m / 5.0,
        deadline,
    };
    let mut decomposition = Decomposition {
        method: "adaptive".to_owned(),
        max_parts: config.decomposition_max_parts,
        tolerance_m: Some(config.decomposition_tolerance_m),
        max_deviation_m: None,
        solid: None,
        resolution: None,
        convex_hull_approximation: None,
        concavity: None,
        out_of_time: None,
        simplified: None,
        part_budget: None,
        over_tolerance: None,
    };
    let decomposed = decompose(positions_m, triangles, &params);
    let Some(decomposed) = decomposed.filter(|d| !d.parts.is_empty()) else {
        return Shapes {
            parts: vec![hull.clone()],
            hull,
            decomposition: Decomposition {
                method: "hull".to_owned(),
                ..decomposition
            },
            warning: Some(
                "the convex decomposition found no part in this mesh: its collision shape is \
                 the convex hull (cavities are filled)"
                    .to_owned(),
            ),
        };
    };
    let mut parts: Vec<ConvexPart> = decomposed
        .parts
        .iter()
        .map(|p| ConvexPart {
            points_m: p
                .points_m
                .iter()
                .map(|q| q.map(|v| round(v as f32, config.shape_precision_m)))
                .collect(),
            volume_m3: p.volume_m3,
        })
        // A sliver thinner than the precision in two directions rounds to a segment: it spans
        // no area, so it can touch nothing.
        .filter(|p| !super::decompose::collinear(&p.points_m))
        .collect();
    if parts.is_empty() {
        parts.push(hull.clone());
    }
    decomposition.max_deviation_m = Some(round(
        decomposed.max_deviation_m as f32,
        config.shape_precision_m / 10.0,
    ));
    decomposition.solid = Some(decomposed.solid);
    decomposition.part_budget = Some(decomposed.part_budget as u32);
    decomposition.over_tolerance = decomposed.over_tolerance.map(|w| w.code().to_owned());
    if decomposed.out_of_time {
        decomposition.out_of_time = Some(true);
        let warning = format!(
            "the convex decomposition ran out of its time budget ([assets.budget] seconds = \
             {} s) and kept the {} parts it had: they reach up to {:.1} mm outside the mesh, \
             more than decomposition_tolerance_m ({:.1} mm) (raise seconds, or decimate the \
             asset)",
            config.budget.seconds,
            parts.len(),
            decomposed.max_deviation_m * 1000.0,
            config.decomposition_tolerance_m * 1000.0
        );
        return Shapes {
            hull,
            parts,
            decomposition,
            warning: Some(warning),
        };
    }
    let warning = decomposed.over_tolerance.map(|why| {
        let because = match why {
            OverTolerance::PartCap => format!(
                "the part budget grew to decomposition_most_parts = {} and ran out (raise it)",
                config.decomposition_most_parts
            ),
            OverTolerance::NoGain => format!(
                "two doublings of the part budget (now {}) did not lower the reach by a \
                 quarter: the mesh has detail the parts cannot follow (noise, walls thinner than the \
                 cuts; repair or decimate the asset)",
                decomposed.part_budget
            ),
            OverTolerance::MinSize => "a piece beyond it is too small to cut again (a \
                                       surface with gaps or folded on itself: repair the \
                                       asset)"
                .to_owned(),
            // Handled above.
            OverTolerance::OutOfTime => "its time budget ran out".to_owned(),
        };
        format!(
            "the collision shape's {} convex parts reach up to {:.1} mm outside the mesh, more \
             than decomposition_tolerance_m ({:.1} mm): {because}; `mesa check` may see \
             contacts with this asset as collisions",
            parts.len(),
            decomposed.max_deviation_m * 1000.0,
            config.decomposition_tolerance_m * 1000.0
        )
    });
    Shapes {
        hull,
        parts,
        decomposition,
        warning,
    }
}
