//! The pack's own meshes: the table slab, the restricted zone, and the `H1_reference`
//! figure, a 1.70 m humanoid in the proportions of a Unitree H1 (legs, pelvis, torso, arms,
//! a head unit), standing upright and facing the observer.
//!
//! Every mesh is in glTF axes (metres, +Y up, front +Z) with its bounding box centred on the
//! origin, as the object meshes are: a node's translation is its box centre.

use crate::mesh::{Affine3, TriMesh};

/// The figure's height, metres.
pub const H1_HEIGHT_M: f64 = 1.70;

/// The figure's parts: body (dark grey) and accents (head visor, joints; black).
pub struct Figure {
    /// The body.
    pub body: TriMesh,
    /// The accents.
    pub accents: TriMesh,
}

fn placed(mesh: TriMesh, at: [f64; 3]) -> TriMesh {
    mesh.transformed(&Affine3::from_translation(at))
}

/// A cylinder about +Y from `bottom` (its axis point) up `height`.
fn limb(radius: f64, bottom: [f64; 3], height: f64) -> TriMesh {
    placed(TriMesh::cylinder(radius, height, 16), bottom)
}

/// The H1 figure, its box centred on the origin and exactly [`H1_HEIGHT_M`] tall: the same in
/// every pack, so it is built once per process.
pub fn h1_figure() -> &'static Figure {
    static FIGURE: std::sync::OnceLock<Figure> = std::sync::OnceLock::new();
    FIGURE.get_or_init(build_h1_figure)
}

fn build_h1_figure() -> Figure {
    // Heights from the floor (y = 0), metres; x to the figure's left (+X), z forward (+Z).
    let foot_h = 0.06;
    let shin = 0.40;
    let thigh = 0.40;
    let pelvis_h = 0.12;
    let torso_h = 0.45;
    let neck = 0.05;
    let head_h = 0.22;
    debug_assert!(
        (foot_h + shin + thigh + pelvis_h + torso_h + neck + head_h - H1_HEIGHT_M).abs() < 1e-12
    );
    let hip_x = 0.10;
    let mut body = TriMesh::default();
    let mut accents = TriMesh::default();
    for side in [-1.0, 1.0] {
        let x = side * hip_x;
        // Foot, longer toward the front.
        body.append(&placed(
            TriMesh::cuboid([0.10, foot_h, 0.24]),
            [x, foot_h / 2.0, 0.04],
        ));
        body.append(&limb(0.045, [x, foot_h, 0.0], shin));
        accents.append(&placed(
            TriMesh::uv_sphere(0.06, 16, 8),
            [x, foot_h + shin, 0.0],
        ));
        body.append(&limb(0.06, [x, foot_h + shin, 0.0], thigh));
    }
    let hips = foot_h + shin + thigh;
    body.append(&placed(
        TriMesh::cuboid([0.32, pelvis_h, 0.18]),
        [0.0, hips + pelvis_h / 2.0, 0.0],
    ));
    let chest = hips + pelvis_h;
    body.append(&placed(
        TriMesh::cuboid([0.38, torso_h, 0.22]),
        [0.0, chest + torso_h / 2.0, 0.0],
    ));
    let shoulder_y = chest + torso_h - 0.06;
    for side in [-1.0, 1.0] {
        let x = side * 0.25;
        accents.append(&placed(
            TriMesh::uv_sphere(0.065, 16, 8),
            [x, shoulder_y, 0.0],
        ));
        // Upper arm and forearm hanging down.
        body.append(&limb(0.04, [x, shoulder_y - 0.30, 0.0], 0.30));
        accents.append(&placed(
            TriMesh::uv_sphere(0.045, 12, 6),
            [x, shoulder_y - 0.30, 0.0],
        ));
        body.append(&limb(0.035, [x, shoulder_y - 0.58, 0.0], 0.28));
    }
    let neck_y = chest + torso_h;
    body.append(&limb(0.05, [0.0, neck_y, 0.0], neck));
    let head_y = neck_y + neck;
    body.append(&placed(
        TriMesh::cuboid([0.18, head_h, 0.20]),
        [0.0, head_y + head_h / 2.0, 0.0],
    ));
    // The visor on the front of the head unit.
    accents.append(&placed(
        TriMesh::cuboid([0.14, 0.06, 0.01]),
        [0.0, head_y + head_h * 0.6, 0.105],
    ));
    centre(vec![body, accents])
}

/// Moves meshes together so that their common box is centred on the origin.
fn centre(meshes: Vec<TriMesh>) -> Figure {
    let mut all = TriMesh::default();
    for m in &meshes {
        all.append(m);
    }
    let c = all.bounds().map_or([0.0; 3], |b| b.center());
    let shift = Affine3::from_translation([-c[0], -c[1], -c[2]]);
    let mut it = meshes.into_iter().map(|m| m.transformed(&shift));
    Figure {
        body: it.next().unwrap_or_default(),
        accents: it.next().unwrap_or_default(),
    }
}

/// A slab of `width × thickness × depth` metres (glTF X × Y × Z), centred on the origin.
pub fn slab(width_m: f64, thickness_m: f64, depth_m: f64) -> TriMesh {
    TriMesh::cuboid([width_m, thickness_m, depth_m])
}

/// How far below the table top the floor is, metres, by table type (typical furniture
/// heights; the H1 figure stands on this floor).
pub fn table_height_m(table_type: &str) -> f64 {
    match table_type {
        "coffee_table" => 0.45,
        "kitchen_counter" => 0.90,
        "bathroom_vanity" => 0.85,
        _ => 0.75,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_figure_is_170_cm_tall_centred_and_valid() {
        let figure = h1_figure();
        let mut all = figure.body.clone();
        all.append(&figure.accents);
        let b = all.bounds().expect("bounds");
        approx::assert_abs_diff_eq!(b.size()[1], H1_HEIGHT_M, epsilon = 1e-6);
        for c in b.center() {
            approx::assert_abs_diff_eq!(c, 0.0, epsilon = 1e-6);
        }
        figure.body.check().expect("body");
        figure.accents.check().expect("accents");
    }
}
