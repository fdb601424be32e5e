//! An asset's collision shape (the convex parts `mesa assets` cached) and how a layout places
//! it in the table frame.
//!
//! A layout object's `position` is the centre of its bounding box, its `scale_factor` scales
//! the asset along the asset's own axes, its `rotation` turns the result (SPEC 2 and 4). So a
//! point `p` of the asset (its table-aligned frame, the frame of the asset index) lands at
//!
//! ```text
//! position + R · (S · (p - c))
//! ```
//!
//! with `c` the centre of the asset's bounding box, `S = diag(scale_factor)` and `R` the
//! rotation. The scale acts before the rotation, in the asset's frame: a non-uniform scale of
//! a turned part is a scale along the asset's axes, not the table's. A linear map takes the
//! convex hull of points to the convex hull of their images, so each part is placed by placing
//! its points.

use std::sync::{Arc, OnceLock};

use mesa_schemas::artifacts::{AssetGeometry, ShapesArtifact};
use mesa_schemas::LayoutObject;

use super::geometry::{convex_hull, Bounds, Hull, Placement};
use super::solid::{AssetMesh, Solid, SolidAt};

/// Parts that may reach outside their mesh by more than this at a layout's scale make their
/// object *loose*: judged on its mesh ([`super::solid`]). A quarter of the default penetration
/// tolerance. A depth measured on parts is off by at most their reach, but whether a leaning
/// object rests is not: a cup's inner wall bulging 0.78 mm into the cavity held a slanted
/// toothbrush 14.6 mm over the cup's floor (a demo scene, against the exact-mesh reference).
pub const LOOSE_REACH_M: f64 = 0.000_5;

/// Loads an asset's mesh on first use (most objects never need theirs).
type MeshLoader = Arc<dyn Fn() -> Result<AssetMesh, String> + Send + Sync>;

/// Where an asset's mesh comes from, and the mesh once loaded.
#[derive(Clone, Default)]
struct MeshSource {
    load: Option<MeshLoader>,
    loaded: Arc<OnceLock<Result<Arc<AssetMesh>, String>>>,
}

impl MeshSource {
    fn get(&self) -> Option<Result<Arc<AssetMesh>, String>> {
        let load = self.load.as_ref()?;
        Some(self.loaded.get_or_init(|| load().map(Arc::new)).clone())
    }
}

impl std::fmt::Debug for MeshSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(if self.load.is_some() {
            "MeshSource(some)"
        } else {
            "MeshSource(none)"
        })
    }
}

impl PartialEq for MeshSource {
    /// Two sources are the same when both have none or both load into the same slot.
    fn eq(&self, other: &Self) -> bool {
        self.load.is_some() == other.load.is_some() && Arc::ptr_eq(&self.loaded, &other.loaded)
            || self.load.is_none() && other.load.is_none()
    }
}

/// A convex hull as vertices and triangles.
pub type HullMesh = (Vec<[f64; 3]>, Vec<[u32; 3]>);

/// A convex part of a shape: its vertices and triangles, the triangles shared by every
/// placement of the part.
pub type PartMesh = (Arc<[[f64; 3]]>, Arc<[[u32; 3]]>);

/// An asset's convex parts, relative to the centre of its bounding box.
#[derive(Debug, Clone, PartialEq)]
pub struct AssetShape {
    /// The asset.
    pub uid: String,
    /// The parts: hull vertices (metres, relative to the bounding-box centre of the asset) and
    /// faces.
    parts: Vec<PartMesh>,
    /// The asset's size [w, d, h] in its table-aligned frame, metres.
    pub size_m: [f64; 3],
    /// How far the parts reach outside the asset's mesh, as `mesa assets` measured it, in the
    /// asset's own metres (a layout's scale multiplies it: [`AssetShape::reach_at`]).
    pub reach_m: f64,
    /// The asset's triangle mesh, for objects whose parts reach too far at their scale.
    mesh: MeshSource,
}

/// Why a shapes file does not give an asset's shape (the caller names the file); each says to
/// rerun `mesa assets --force`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ShapeError {
    /// The file describes another asset.
    #[error(
        "the shapes file is of asset \"{found}\", not \"{uid}\" (rerun `mesa assets --force`)"
    )]
    OtherAsset {
        /// The uid in the file.
        found: String,
        /// The uid asked for.
        uid: String,
    },
    /// The file has no part.
    #[error("the shapes file has no convex part (rerun `mesa assets --force`)")]
    NoPart,
    /// A part has no point.
    #[error("part {part} has no point (rerun `mesa assets --force`)")]
    EmptyPart {
        /// The part's index.
        part: usize,
    },
    /// A part has a NaN or infinite coordinate.
    #[error("part {part} has a non-finite coordinate (rerun `mesa assets --force`)")]
    NonFinite {
        /// The part's index.
        part: usize,
    },
}

impl AssetShape {
    /// The shape of an asset from its shapes file and its geometry record (both written by
    /// `mesa assets`, in the same table-aligned frame). An error says what is wrong.
    pub fn new(
        uid: &str,
        shapes: &ShapesArtifact,
        geometry: &AssetGeometry,
    ) -> Result<Self, ShapeError> {
        if shapes.uid != uid {
            return Err(ShapeError::OtherAsset {
                found: shapes.uid.clone(),
                uid: uid.to_owned(),
            });
        }
        if shapes.parts.is_empty() {
            return Err(ShapeError::NoPart);
        }
        let c: [f64; 3] =
            std::array::from_fn(|k| 0.5 * (geometry.bounds_min_m[k] + geometry.bounds_max_m[k]));
        let mut parts = Vec::with_capacity(shapes.parts.len());
        for (i, part) in shapes.parts.iter().enumerate() {
            if part.points_m.is_empty() {
                return Err(ShapeError::EmptyPart { part: i });
            }
            if part.points_m.iter().flatten().any(|v| !v.is_finite()) {
                return Err(ShapeError::NonFinite { part: i });
            }
            let centred: Vec<[f64; 3]> = part
                .points_m
                .iter()
                .map(|p| [p[0] - c[0], p[1] - c[1], p[2] - c[2]])
                .collect();
            let (points, triangles) = convex_hull(&centred);
            parts.push((points.into(), triangles.into()));
        }
        let d = &shapes.decomposition;
        let reach_m = d
            .max_deviation_m
            .unwrap_or(0.0)
            .max(d.simplified.as_ref().map_or(0.0, |s| s.reach_m));
        Ok(Self {
            uid: uid.to_owned(),
            parts,
            size_m: geometry.size_m,
            reach_m: if reach_m.is_finite() { reach_m } else { 0.0 },
            mesh: MeshSource::default(),
        })
    }

    /// A shape from parts given directly (points relative to the asset's bounding-box centre),
    /// for tests and benchmarks.
    pub fn from_parts(uid: &str, parts: Vec<Vec<[f64; 3]>>, size_m: [f64; 3]) -> Self {
        Self {
            uid: uid.to_owned(),
            parts: parts
                .iter()
                .map(|p| {
                    let (points, triangles) = convex_hull(p);
                    (points.into(), triangles.into())
                })
                .collect(),
            size_m,
            reach_m: 0.0,
            mesh: MeshSource::default(),
        }
    }

    /// The shape with its mesh (in the parts' frame), for judging loose objects.
    pub fn with_mesh(self, mesh: AssetMesh) -> Self {
        let mesh = Ok(Arc::new(mesh));
        self.with_mesh_loader(move || mesh.as_ref().map(|m| (**m).clone()).map_err(String::clone))
    }

    /// The shape whose mesh `load` reads when an object first needs it (once per shape); an
    /// error says why the mesh cannot be had.
    pub fn with_mesh_loader(
        mut self,
        load: impl Fn() -> Result<AssetMesh, String> + Send + Sync + 'static,
    ) -> Self {
        self.mesh = MeshSource {
            load: Some(Arc::new(load)),
            loaded: Arc::new(OnceLock::new()),
        };
        self
    }

    /// The asset's mesh: `None` when the shape has no source for it, else the mesh or why it
    /// could not be read.
    pub fn mesh(&self) -> Option<Result<Arc<AssetMesh>, String>> {
        self.mesh.get()
    }

    /// The shape with another measured reach (metres, the asset's own size), for tests.
    pub fn with_reach_m(mut self, reach_m: f64) -> Self {
        self.reach_m = reach_m;
        self
    }

    /// How far the parts may reach outside the mesh once a pose scales them: the measured
    /// reach times the largest scale (a distance outside the mesh grows at most by it).
    pub fn reach_at(&self, pose: &Pose) -> f64 {
        self.reach_m * pose.scale.iter().fold(0.0_f64, |m, s| m.max(s.abs()))
    }

    /// The convex parts: hull vertices (metres, relative to the centre of the asset's bounding
    /// box, in its table-aligned frame) and outward triangles (none for a part that spans no
    /// volume).
    pub fn parts(&self) -> &[PartMesh] {
        &self.parts
    }

    /// The number of convex parts.
    pub fn part_count(&self) -> usize {
        self.parts.len()
    }

    /// The parts placed in the table frame.
    pub fn place(&self, pose: &Pose) -> Vec<Hull> {
        let placement = Arc::new(Placement::new(
            pose.position_m,
            pose.rotation_xyzw,
            pose.scale,
        ));
        let mut scratch = Vec::new();
        self.parts
            .iter()
            .filter_map(|(points, triangles)| {
                Hull::placed(points, triangles, &placement, &mut scratch)
            })
            .collect()
    }
}

/// Where and how big a layout puts an asset.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// The centre of the object's bounding box, table frame, metres.
    pub position_m: [f64; 3],
    /// The rotation, quaternion `[x, y, z, w]`.
    pub rotation_xyzw: [f64; 4],
    /// The scale along the asset's own axes.
    pub scale: [f64; 3],
}

impl Pose {
    /// The pose of a dataset layout object (cm to metres; its `scale_factor`).
    pub fn of_object(object: &LayoutObject) -> Self {
        Self {
            position_m: object.position_cm.0.map(|v| v / 100.0),
            rotation_xyzw: object.rotation.0,
            scale: object.scale_factor.0,
        }
    }
}

/// One object of a scene placed in the table frame: its parts and their bounds, and for a
/// loose object its mesh.
#[derive(Debug, Clone)]
pub struct Body {
    /// The convex parts.
    pub hulls: Vec<Hull>,
    /// Bounds of all parts.
    pub bounds: Bounds,
    /// How far the parts may reach outside the mesh at this pose, metres.
    pub reach_m: f64,
    solid: SolidSlot,
}

/// An object's mesh: placed by its pose on first use, then moved along with the body.
#[derive(Debug, Clone, Default)]
struct SolidSlot {
    source: Option<(Arc<AssetShape>, Pose)>,
    placed: OnceLock<Result<Arc<Solid>, String>>,
    offset: [f64; 3],
}

impl Body {
    /// A body of placed parts; `None` without any.
    pub fn new(hulls: Vec<Hull>) -> Option<Self> {
        if hulls.is_empty() {
            return None;
        }
        let bounds = hulls
            .iter()
            .fold(Bounds::empty(), |b, h| b.union(&h.bounds));
        Some(Self {
            hulls,
            bounds,
            reach_m: 0.0,
            solid: SolidSlot::default(),
        })
    }

    /// The body of an asset's shape placed by `pose`, with its reach at that scale and its mesh
    /// when the shape has one; `None` without any part.
    pub fn of_shape(shape: &Arc<AssetShape>, pose: &Pose) -> Option<Self> {
        let mut body = Self::new(shape.place(pose))?;
        body.reach_m = shape.reach_at(pose);
        body.solid.source = Some((shape.clone(), *pose));
        Some(body)
    }

    /// Moves the body by `t`, metres.
    pub fn translate(&mut self, t: [f64; 3]) {
        for h in &mut self.hulls {
            h.translate(t);
        }
        self.bounds = self.bounds.translated(t);
        for (o, v) in self.solid.offset.iter_mut().zip(t) {
            *o += v;
        }
    }

    /// Whether the parts may reach outside the mesh by more than [`LOOSE_REACH_M`] here, so
    /// that the object is judged on its mesh when it has one.
    pub fn loose(&self) -> bool {
        self.reach_m > LOOSE_REACH_M
    }

    /// The mesh, placed and moved as the body (`None` when the shape has none; `Err` when it
    /// could not be read).
    pub fn solid(&self) -> Option<Result<SolidAt<'_>, &str>> {
        let (shape, pose) = self.solid.source.as_ref()?;
        shape.mesh.load.as_ref()?;
        let placed = self.solid.placed.get_or_init(|| match shape.mesh() {
            Some(Ok(mesh)) => Ok(Arc::new(mesh.place(
                pose.position_m,
                pose.rotation_xyzw,
                pose.scale,
            ))),
            Some(Err(e)) => Err(e),
            None => Err("no mesh".to_owned()),
        });
        Some(match placed {
            Ok(solid) => Ok(SolidAt {
                solid,
                offset: self.solid.offset,
            }),
            Err(e) => Err(e.as_str()),
        })
    }

    /// The mesh when the body is judged on it: loose, with a mesh that could be read.
    pub fn judged_solid(&self) -> Option<SolidAt<'_>> {
        if !self.loose() {
            return None;
        }
        self.solid().and_then(Result::ok)
    }

    /// The box the body is judged by: its mesh's for a loose body with a mesh, else its parts'.
    pub fn judged_bounds(&self) -> Bounds {
        self.judged_solid().map_or(self.bounds, |s| s.bounds())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    /// A slab 0.2 × 0.02 × 0.1 m (long along the asset's x).
    fn slab() -> AssetShape {
        let mut points = Vec::new();
        for x in [-0.1, 0.1] {
            for y in [-0.01, 0.01] {
                for z in [-0.05, 0.05] {
                    points.push([x, y, z]);
                }
            }
        }
        AssetShape::from_parts("slab", vec![points], [0.2, 0.02, 0.1])
    }

    #[test]
    fn the_scale_acts_along_the_assets_axes_before_the_turn() {
        // Doubled along the asset's x, then turned 90° about z: the long side lies along the
        // table's y, 0.4 m long; along x it keeps the asset's 0.02 m depth.
        let half = std::f64::consts::FRAC_PI_4;
        let pose = Pose {
            position_m: [1.0, 2.0, 0.05],
            rotation_xyzw: [0.0, 0.0, half.sin(), half.cos()],
            scale: [2.0, 1.0, 1.0],
        };
        let body = Body::new(slab().place(&pose)).expect("parts");
        let size: Vec<f64> = (0..3)
            .map(|k| body.bounds.max[k] - body.bounds.min[k])
            .collect();
        assert_abs_diff_eq!(size[0], 0.02, epsilon = 1e-9);
        assert_abs_diff_eq!(size[1], 0.4, epsilon = 1e-9);
        assert_abs_diff_eq!(size[2], 0.1, epsilon = 1e-9);
        assert_abs_diff_eq!(body.bounds.center()[0], 1.0, epsilon = 1e-9);
        assert_abs_diff_eq!(body.bounds.center()[1], 2.0, epsilon = 1e-9);
    }
}
