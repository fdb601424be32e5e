use approx::assert_abs_diff_eq;

use super::mass::unit_density;
use super::*;
use crate::check::geometry::convex_hull;

fn cube_parts(half: f64, offset: [f64; 3]) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let mut points = Vec::new();
    for x in [-half, half] {
        for y in [-half, half] {
            for z in [-half, half] {
                points.push([x + offset[0], y + offset[1], z + offset[2]]);
            }
        }
    }
    convex_hull(&points)
}

#[test]
fn a_cube_has_the_volume_centre_and_inertia_of_a_solid_cube() {
    let parts = vec![cube_parts(0.05, [0.1, 0.0, 0.0])];
    let unit = unit_density(&parts);
    assert_abs_diff_eq!(unit.volume_m3, 0.001, epsilon = 1e-12);
    let m = unit.with_mass(2.0, [0.1; 3], [1.0; 3]);
    assert_abs_diff_eq!(m.center_m[0], 0.1, epsilon = 1e-9);
    // A solid cube of side a: m a² / 6 about each axis through its centre.
    for k in 0..3 {
        assert_abs_diff_eq!(m.inertia_kg_m2[k], 2.0 * 0.01 / 6.0, epsilon = 1e-9);
        assert_abs_diff_eq!(m.inertia_kg_m2[3 + k], 0.0, epsilon = 1e-9);
    }
    assert!(!m.fallback_box);
}

#[test]
fn two_cubes_sum_their_volumes_and_shift_the_centre() {
    let parts = vec![
        cube_parts(0.05, [0.0, 0.0, 0.0]),
        cube_parts(0.05, [0.2, 0.0, 0.0]),
    ];
    let unit = unit_density(&parts);
    assert_abs_diff_eq!(unit.volume_m3, 0.002, epsilon = 1e-12);
    let m = unit.with_mass(1.0, [0.3, 0.1, 0.1], [1.0; 3]);
    assert_abs_diff_eq!(m.center_m[0], 0.1, epsilon = 1e-9);
    // Parallel axes: each cube 0.5 kg at 0.1 m from the centre adds 0.5 · 0.01 about y and z.
    assert_abs_diff_eq!(m.inertia_kg_m2[0], 0.01 / 6.0, epsilon = 1e-9);
    assert_abs_diff_eq!(m.inertia_kg_m2[1], 0.01 / 6.0 + 0.01, epsilon = 1e-9);
}

#[test]
fn numbers_are_fixed_and_never_negative_zero() {
    assert_eq!(obj::fixed(-0.0000001), "0.000000");
    assert_eq!(obj::fixed(-1.5), "-1.500000");
    assert_eq!(obj::sci(0.0), "0");
    assert_eq!(obj::sci(1.25e-7), "1.25000000e-7");
}

fn layout(restricted: Option<[f64; 4]>) -> DatasetLayout {
    let mut text = serde_json::json!({
        "schema": "mesa.layout/1",
        "item_placement_zone": [0.0, 100.0, 0.0, 60.0],
        "objects": []
    });
    if let Some(r) = restricted {
        text["restricted_zone"] = serde_json::json!(r);
    }
    serde_json::from_value(text).expect("a layout")
}

#[test]
fn the_table_top_is_at_zero_and_a_sink_is_a_hole_over_a_basin() {
    let config = ExportConfig::default();
    let plain = table_boxes(&layout(None), &config);
    assert_eq!(plain.len(), 1);
    let top = plain[0];
    assert_abs_diff_eq!(top.center_m[2] + top.half_size_m[2], 0.0, epsilon = 1e-12);
    assert_abs_diff_eq!(
        top.half_size_m[0],
        0.5 + config.table_margin_m,
        epsilon = 1e-12
    );

    let sink = table_boxes(&layout(Some([40.0, 60.0, 20.0, 40.0])), &config);
    assert_eq!(sink.len(), 5);
    // No top box covers the hole's centre (0.5, 0.3); the floor lies under it.
    for b in &sink {
        let covers = (0..2).all(|k| (b.center_m[k] - [0.5, 0.3][k]).abs() < b.half_size_m[k]);
        if b.name == "sink_floor" {
            assert!(covers);
            assert_abs_diff_eq!(
                b.center_m[2] + b.half_size_m[2],
                -config.sink_depth_m,
                epsilon = 1e-12
            );
        } else {
            assert!(!covers, "{} covers the sink", b.name);
        }
    }
}

#[test]
fn bad_settings_are_named_with_their_key() {
    let config = ExportConfig {
        density_kg_m3: 0.0,
        condim: 5,
        ..ExportConfig::default()
    };
    let problems = config.problems();
    assert_eq!(problems.len(), 2, "{problems:?}");
    assert!(problems[0].starts_with("[export] density_kg_m3"));
    assert!(problems[1].starts_with("[export] condim"));
    assert!(ExportConfig::default().problems().is_empty());
}

#[test]
fn a_part_a_tenth_of_a_millimetre_thin_is_kept_and_thickened() {
    let mut points = Vec::new();
    for x in [0.0, 0.12] {
        for y in [0.0, 0.0001] {
            for z in [0.0, 0.0026] {
                points.push([x, y, z]);
            }
        }
    }
    let (hull, triangles) = solid_part(&points, 0.0005).expect("a hull");
    assert_eq!(triangles.len(), 12);
    let unit = unit_density(&[(hull, triangles)]);
    // Made 0.5 mm thick about its middle.
    assert_abs_diff_eq!(unit.volume_m3, 0.12 * 0.0005 * 0.0026, epsilon = 1e-12);
    // A thick enough part keeps its own volume, turned or not.
    let (hull, triangles) = solid_part(&points, 0.00005).expect("a hull");
    assert_abs_diff_eq!(
        unit_density(&[(hull, triangles)]).volume_m3,
        0.12 * 0.0001 * 0.0026,
        epsilon = 1e-12
    );
}

#[test]
fn a_flat_polygon_part_is_thickened_and_a_segment_is_left_out() {
    // A slanted square: flat along no table axis.
    let square = [
        [0.0, 0.0, 0.0],
        [0.01, 0.0, 0.01],
        [0.0, 0.01, 0.0],
        [0.01, 0.01, 0.01],
    ];
    let (hull, triangles) = solid_part(&square, 0.0005).expect("a hull");
    assert_abs_diff_eq!(
        unit_density(&[(hull, triangles)]).volume_m3,
        0.01 * 0.01 * 2f64.sqrt() * 0.0005,
        epsilon = 1e-12
    );
    let segment = [[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.005, 0.0, 0.0]];
    assert!(solid_part(&segment, 0.0005).is_none());
}

#[test]
fn usd_prim_names_are_identifiers_and_unique() {
    let mut taken = std::collections::BTreeSet::new();
    assert_eq!(usd::prim_name("mug_0", &mut taken), "mug_0");
    assert_eq!(usd::prim_name("mug-0", &mut taken), "mug_0_1");
    assert_eq!(usd::prim_name("3d_print", &mut taken), "_3d_print");
    assert_eq!(usd::prim_name("table", &mut taken), "table_object");
}

#[test]
fn principal_axes_diagonalise_the_inertia() {
    // A tensor with a product of inertia: its principal axes turn it diagonal.
    let inertia = [2.0, 3.0, 4.0, 0.5, 0.0, 0.0];
    let (d, q) = usd::principal_inertia(inertia);
    let r = crate::mesh::quat_to_matrix([q[1], q[2], q[3], q[0]]);
    let m = [[2.0, 0.5, 0.0], [0.5, 3.0, 0.0], [0.0, 0.0, 4.0]];
    // Rᵀ M R = diag(d).
    for a in 0..3 {
        for b in 0..3 {
            let v: f64 = (0..3)
                .flat_map(|i| (0..3).map(move |j| (i, j)))
                .map(|(i, j)| r[i][a] * m[i][j] * r[j][b])
                .sum();
            let expected = if a == b { d[a] } else { 0.0 };
            assert_abs_diff_eq!(v, expected, epsilon = 1e-9);
        }
    }
    assert_abs_diff_eq!(d.iter().sum::<f64>(), 9.0, epsilon = 1e-9);
}

#[test]
fn the_formats_must_name_something_once() {
    assert!(ExportConfig::default().problems().is_empty());
    let none = ExportConfig {
        formats: Vec::new(),
        ..ExportConfig::default()
    };
    assert!(none
        .problems()
        .iter()
        .any(|p| p.contains("formats: is empty")));
    let twice = ExportConfig {
        formats: vec![ExportFormat::Usd, ExportFormat::Usd],
        ..ExportConfig::default()
    };
    assert!(twice.problems().iter().any(|p| p.contains("twice")));
}
