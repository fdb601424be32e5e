//! The collision test of the collision corruption (SPEC 5.9: a corruption is kept only if
//! `check` finds a new colliding pair), on an LLM layout:
//!
//! - [`Collider::Meshes`]: `mesa check`'s own test ([`crate::check`]): each object is its
//!   asset's collision shape, placed at its position, turned by its yaw, scaled to its size
//!   along the asset's axes; two collide when their convex parts interpenetrate deeper than the
//!   tolerance. Used when every object's asset has collision shapes in the asset index.
//! - [`Collider::Boxes`]: each object is its oriented bounding box (size before rotation, turned
//!   by its yaw, centred at its position). For layouts without assets (the published records):
//!   boxes overestimate shapes (a mug's box includes the air beside its handle), but the
//!   corruption compares against the pairs that already overlap in the chosen layout, so a new
//!   overlap is still a collision it made.

use std::collections::BTreeMap;
use std::sync::Arc;

use mesa_schemas::rotation::quat_xyzw_from_yaw_deg;
use mesa_schemas::LlmLayout;

use crate::check::{collisions_of, AssetShape, Body, PhysicsScene, PlacedObject, Pose};
use crate::graph::sin_cos_deg;

/// How the collision corruption tests a layout.
#[derive(Debug, Clone, PartialEq)]
pub enum Collider {
    /// Oriented bounding boxes.
    Boxes,
    /// The assets' collision shapes, by instance (every object of the layout has one).
    Meshes(BTreeMap<String, Arc<AssetShape>>),
}

impl Collider {
    /// `meshes` or `boxes`.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Boxes => "boxes",
            Self::Meshes(_) => "meshes",
        }
    }

    /// The colliding pairs of a layout by instance names (sorted within and across pairs):
    /// penetration deeper than `tolerance_cm`.
    pub fn colliding_names(&self, layout: &LlmLayout, tolerance_cm: f64) -> Vec<(String, String)> {
        match self {
            Self::Boxes => colliding_names(layout, tolerance_cm),
            Self::Meshes(shapes) => mesh_colliding_names(layout, shapes, tolerance_cm),
        }
    }
}

/// The pose of an LLM layout object for its asset: its box centre, its yaw, and the scale that
/// makes the asset its size (per axis of the asset).
fn llm_pose(object: &mesa_schemas::LlmObject, shape: &AssetShape) -> Pose {
    let size_m = object.size_cm.0.map(|v| v / 100.0);
    Pose {
        position_m: object.position_cm.0.map(|v| v / 100.0),
        rotation_xyzw: quat_xyzw_from_yaw_deg(object.z_rotation_deg),
        scale: std::array::from_fn(|k| {
            if shape.size_m[k] > 0.0 {
                size_m[k] / shape.size_m[k]
            } else {
                1.0
            }
        }),
    }
}

fn mesh_colliding_names(
    layout: &LlmLayout,
    shapes: &BTreeMap<String, Arc<AssetShape>>,
    tolerance_cm: f64,
) -> Vec<(String, String)> {
    let scene = PhysicsScene {
        zone_m: layout.zone_cm.0.map(|v| v / 100.0),
        restricted_zone_m: None,
        objects: layout
            .objects
            .iter()
            .map(|o| PlacedObject {
                instance: o.instance.clone(),
                reach_m: 0.0,
                body: shapes
                    .get(&o.instance)
                    .and_then(|shape| Body::new(shape.place(&llm_pose(o, shape))))
                    .ok_or_else(|| format!("{}: no collision shape", o.instance)),
            })
            .collect(),
    };
    let mut names: Vec<(String, String)> = collisions_of(&scene, tolerance_cm / 100.0)
        .into_iter()
        .map(|c| {
            let (a, b) = (&layout.objects[c.a].instance, &layout.objects[c.b].instance);
            if a <= b {
                (a.clone(), b.clone())
            } else {
                (b.clone(), a.clone())
            }
        })
        .collect();
    names.sort();
    names
}

/// An object's oriented bounding box: yaw only (the LLM form has no tilt).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct YawBox {
    /// Centre [x, y, z] in cm.
    pub center_cm: [f64; 3],
    /// Half extents along the object's own x, y and z, in cm.
    pub half_cm: [f64; 3],
    /// Yaw in degrees, counter-clockwise seen from above.
    pub yaw_deg: f64,
}

impl YawBox {
    /// The box of a layout object.
    pub fn of(object: &mesa_schemas::LlmObject) -> Self {
        let [w, d, h] = object.size_cm.0;
        Self {
            center_cm: object.position_cm.0,
            half_cm: [w / 2.0, d / 2.0, h / 2.0],
            yaw_deg: object.z_rotation_deg,
        }
    }

    /// The box's x and y axes in the table frame.
    fn axes(&self) -> [[f64; 2]; 2] {
        let (s, c) = sin_cos_deg(self.yaw_deg);
        [[c, s], [-s, c]]
    }

    /// Half of the footprint's extent along a unit direction of the table plane.
    fn radius_along(&self, u: [f64; 2]) -> f64 {
        let [ax, ay] = self.axes();
        (u[0] * ax[0] + u[1] * ax[1]).abs() * self.half_cm[0]
            + (u[0] * ay[0] + u[1] * ay[1]).abs() * self.half_cm[1]
    }

    /// Half extents of the rotated footprint along the table's x and y.
    pub fn footprint_half_cm(&self) -> [f64; 2] {
        [self.radius_along([1.0, 0.0]), self.radius_along([0.0, 1.0])]
    }
}

/// How deep two boxes interpenetrate, in cm: the shortest translation that separates them
/// (separating-axis test over both footprints' axes and z, which is exact for boxes turned
/// only about z); 0 when they are apart or touch.
pub fn penetration_depth_boxes(a: &YawBox, b: &YawBox) -> f64 {
    let dz = (a.center_cm[2] - b.center_cm[2]).abs();
    let mut depth = a.half_cm[2] + b.half_cm[2] - dz;
    if depth <= 0.0 {
        return 0.0;
    }
    let d = [
        b.center_cm[0] - a.center_cm[0],
        b.center_cm[1] - a.center_cm[1],
    ];
    for u in a.axes().into_iter().chain(b.axes()) {
        let distance = (d[0] * u[0] + d[1] * u[1]).abs();
        let overlap = a.radius_along(u) + b.radius_along(u) - distance;
        if overlap <= 0.0 {
            return 0.0;
        }
        depth = depth.min(overlap);
    }
    depth
}

/// The pairs of objects (indices, a < b) whose boxes interpenetrate by more than
/// `tolerance_cm`, with the depth.
pub fn colliding_pairs(layout: &LlmLayout, tolerance_cm: f64) -> Vec<(usize, usize, f64)> {
    let boxes: Vec<YawBox> = layout.objects.iter().map(YawBox::of).collect();
    let mut pairs = Vec::new();
    for i in 0..boxes.len() {
        for j in i + 1..boxes.len() {
            let depth = penetration_depth_boxes(&boxes[i], &boxes[j]);
            if depth > tolerance_cm {
                pairs.push((i, j, depth));
            }
        }
    }
    pairs
}

/// The colliding pairs of a layout by instance names (sorted within and across pairs).
pub fn colliding_names(layout: &LlmLayout, tolerance_cm: f64) -> Vec<(String, String)> {
    let mut names: Vec<(String, String)> = colliding_pairs(layout, tolerance_cm)
        .into_iter()
        .map(|(i, j, _)| {
            let (a, b) = (&layout.objects[i].instance, &layout.objects[j].instance);
            if a <= b {
                (a.clone(), b.clone())
            } else {
                (b.clone(), a.clone())
            }
        })
        .collect();
    names.sort();
    names
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use proptest::prelude::*;

    fn cube(center: [f64; 3], size: f64, yaw_deg: f64) -> YawBox {
        YawBox {
            center_cm: center,
            half_cm: [size / 2.0; 3],
            yaw_deg,
        }
    }

    #[test]
    fn axis_aligned_overlaps_are_the_least_overlap() {
        let a = cube([0.0, 0.0, 5.0], 10.0, 0.0);
        assert_relative_eq!(
            penetration_depth_boxes(&a, &cube([8.0, 1.0, 5.0], 10.0, 0.0)),
            2.0
        );
        assert_eq!(
            penetration_depth_boxes(&a, &cube([10.0, 0.0, 5.0], 10.0, 0.0)),
            0.0
        );
        // Stacked: touching faces do not collide; sinking 1 cm does.
        assert_eq!(
            penetration_depth_boxes(&a, &cube([0.0, 0.0, 15.0], 10.0, 0.0)),
            0.0
        );
        assert_relative_eq!(
            penetration_depth_boxes(&a, &cube([0.0, 0.0, 14.0], 10.0, 0.0)),
            1.0
        );
    }

    #[test]
    fn turned_boxes_use_their_own_axes() {
        // A 10 cm cube turned 45° reaches 5·√2 ≈ 7.07 cm along x. 11 cm from an axis-aligned
        // cube: overlap 5 + 7.07 - 11 ≈ 1.07 along x, 4.29 along the turned cube's axes (its
        // radius 5, the other's 7.07, distance 11·cos 45°), 12.07 along y: the least is x.
        let a = cube([0.0, 0.0, 5.0], 10.0, 0.0);
        let b = cube([11.0, 0.0, 5.0], 10.0, 45.0);
        let depth = penetration_depth_boxes(&a, &b);
        assert_relative_eq!(depth, 5.0 + 5.0 * 2f64.sqrt() - 11.0, epsilon = 1e-9);
        assert_eq!(
            penetration_depth_boxes(&a, &cube([12.5, 0.0, 5.0], 10.0, 45.0)),
            0.0
        );
    }

    proptest! {
        #[test]
        fn depth_is_symmetric_and_zero_when_far(
            ax in -50.0f64..50.0, ay in -50.0f64..50.0, bx in -50.0f64..50.0, by in -50.0f64..50.0,
            ya in -180.0f64..180.0, yb in -180.0f64..180.0, sa in 1.0f64..20.0, sb in 1.0f64..20.0,
        ) {
            let a = cube([ax, ay, sa / 2.0], sa, ya);
            let b = cube([bx, by, sb / 2.0], sb, yb);
            let ab = penetration_depth_boxes(&a, &b);
            let ba = penetration_depth_boxes(&b, &a);
            prop_assert!((ab - ba).abs() < 1e-9);
            let centre_distance = ((ax - bx).powi(2) + (ay - by).powi(2)).sqrt();
            // Beyond the sum of the circumscribed radii nothing can touch.
            if centre_distance > (sa + sb) * 0.5 * 2f64.sqrt() {
                prop_assert_eq!(ab, 0.0);
            }
            // Inside the sum of the inscribed radii they must overlap.
            if centre_distance < (sa + sb) * 0.5 - 1e-9 {
                prop_assert!(ab > 0.0);
            }
        }
    }
}
