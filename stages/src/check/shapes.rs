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

use mesa_schemas::artifacts::{AssetGeometry, ShapesArtifact};
use mesa_schemas::LayoutObject;

use super::geometry::{convex_hull, Bounds, Hull};
use crate::mesh::quat_to_matrix;

/// A convex hull as vertices and triangles.
pub type HullMesh = (Vec<[f64; 3]>, Vec<[u32; 3]>);

/// An asset's convex parts, relative to the centre of its bounding box.
#[derive(Debug, Clone, PartialEq)]
pub struct AssetShape {
    /// The asset.
    pub uid: String,
    /// The parts: hull vertices (metres, relative to the bounding-box centre of the asset) and
    /// faces.
    parts: Vec<HullMesh>,
    /// The asset's size [w, d, h] in its table-aligned frame, metres.
    pub size_m: [f64; 3],
    /// How far the parts reach outside the asset's mesh, as `mesa assets` measured it, in the
    /// asset's own metres (a layout's scale multiplies it: [`AssetShape::reach_at`]).
    pub reach_m: f64,
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
            parts.push(convex_hull(&centred));
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
        })
    }

    /// A shape from parts given directly (points relative to the asset's bounding-box centre),
    /// for tests and benchmarks.
    pub fn from_parts(uid: &str, parts: Vec<Vec<[f64; 3]>>, size_m: [f64; 3]) -> Self {
        Self {
            uid: uid.to_owned(),
            parts: parts.iter().map(|p| convex_hull(p)).collect(),
            size_m,
            reach_m: 0.0,
        }
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
    pub fn parts(&self) -> &[HullMesh] {
        &self.parts
    }

    /// The number of convex parts.
    pub fn part_count(&self) -> usize {
        self.parts.len()
    }

    /// The parts placed in the table frame.
    pub fn place(&self, pose: &Pose) -> Vec<Hull> {
        let m = quat_to_matrix(pose.rotation_xyzw);
        let s = pose.scale;
        let t = pose.position_m;
        self.parts
            .iter()
            .filter_map(|(points, triangles)| {
                let placed: Vec<[f64; 3]> = points
                    .iter()
                    .map(|p| {
                        // Scale in the asset's frame, then turn, then move.
                        let q = [p[0] * s[0], p[1] * s[1], p[2] * s[2]];
                        std::array::from_fn(|r| {
                            t[r] + m[r][0] * q[0] + m[r][1] * q[1] + m[r][2] * q[2]
                        })
                    })
                    .collect();
                // A mirroring scale turns the faces inside out.
                if s[0] * s[1] * s[2] < 0.0 {
                    let flipped: Vec<[u32; 3]> =
                        triangles.iter().map(|t| [t[0], t[2], t[1]]).collect();
                    Hull::with_faces(&placed, &flipped)
                } else {
                    Hull::with_faces(&placed, triangles)
                }
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

/// One object of a scene placed in the table frame: its parts and their bounds.
#[derive(Debug, Clone)]
pub struct Body {
    /// The convex parts.
    pub hulls: Vec<Hull>,
    /// Bounds of all parts.
    pub bounds: Bounds,
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
        Some(Self { hulls, bounds })
    }

    /// Moves the body by `t`, metres.
    pub fn translate(&mut self, t: [f64; 3]) {
        for h in &mut self.hulls {
            h.translate(t);
        }
        self.bounds = self.bounds.translated(t);
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
