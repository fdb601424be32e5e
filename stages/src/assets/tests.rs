//! Indexing synthetic assets: frames, sizes, validity, collision shapes.

use approx::assert_abs_diff_eq;
use parry3d::math::Point;

use super::synthetic::Mesh;
use super::*;
use crate::annotations::BboxExtents;

fn index(mesh: &Mesh, annotation: Option<&AssetAnnotation>, config: &AssetsConfig) -> IndexedAsset {
    index_asset("uid", "digest", &mesh.to_glb(1.0), annotation, config)
}

/// Whether a part's convex hull holds `p`: `p` is on the inner side of every face of the hull
/// (within 1e-6 m). Face planes from parry's hull, oriented away from the hull's centroid;
/// parry's `ConvexPolyhedron` refuses some valid hulls (coplanar faces it cannot merge).
fn contains(part: &mesa_schemas::artifacts::ConvexPart, p: [f64; 3]) -> bool {
    let points: Vec<Point<f32>> = part
        .points_m
        .iter()
        .map(|q| Point::new(q[0] as f32, q[1] as f32, q[2] as f32))
        .collect();
    let Ok((vertices, faces)) = parry3d::transformation::try_convex_hull(&points) else {
        return false;
    };
    if faces.is_empty() {
        return false;
    }
    let v = |i: u32| {
        let q = vertices[i as usize];
        [f64::from(q.x), f64::from(q.y), f64::from(q.z)]
    };
    let n = vertices.len() as f64;
    let centroid: [f64; 3] =
        std::array::from_fn(|k| vertices.iter().map(|q| f64::from(q[k])).sum::<f64>() / n);
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    faces.iter().all(|f| {
        let (a, b, c) = (v(f[0]), v(f[1]), v(f[2]));
        let (e1, e2) = (sub(b, a), sub(c, a));
        let mut normal = [
            e1[1] * e2[2] - e1[2] * e2[1],
            e1[2] * e2[0] - e1[0] * e2[2],
            e1[0] * e2[1] - e1[1] * e2[0],
        ];
        let len = dot(normal, normal).sqrt();
        if len < 1e-12 {
            return true;
        }
        if dot(normal, sub(centroid, a)) > 0.0 {
            normal = normal.map(|x| -x);
        }
        dot(normal, sub(p, a)) / len <= 1e-6
    })
}

#[test]
fn a_box_is_measured_in_the_table_frame() {
    // glTF X = 0.1 wide, Y = 0.2 tall, Z = 0.3 deep (toward the viewer).
    let indexed = index(
        &Mesh::cuboid([0.1, 0.2, 0.3]),
        None,
        &AssetsConfig::default(),
    );
    assert_eq!(indexed.invalid, None);
    let g = indexed.geometry.expect("geometry");
    assert_abs_diff_eq!(g.size_m[0], 0.1, epsilon = 1e-6);
    assert_abs_diff_eq!(g.size_m[1], 0.3, epsilon = 1e-6);
    assert_abs_diff_eq!(g.size_m[2], 0.2, epsilon = 1e-6);
    assert_abs_diff_eq!(g.gltf_extents_m[1], 0.2, epsilon = 1e-6);
    // glTF +Z (the front) is table -y: the box spans y in [-0.15, 0.15], z in [0, 0.2].
    assert_abs_diff_eq!(g.bounds_min_m[2], 0.0, epsilon = 1e-9);
    assert_abs_diff_eq!(g.bounds_max_m[1], 0.15, epsilon = 1e-6);
    assert_eq!(g.triangles, 12);
    assert_eq!(g.vertices, 8);
    assert_eq!(g.materials, ["surface"]);
    let shapes = indexed.shapes.expect("shapes");
    assert_abs_diff_eq!(shapes.hull.volume_m3, 0.1 * 0.2 * 0.3, epsilon = 1e-5);
    // A closed convex mesh is its own hull: one part.
    assert_eq!(shapes.decomposition.method, "adaptive");
    assert_eq!(shapes.decomposition.solid, Some(true));
    assert_eq!(shapes.parts.len(), 1);
}

#[test]
fn the_front_view_turns_the_asset() {
    let front = AssetAnnotation {
        front_view: Some(1),
        ..AssetAnnotation::default()
    };
    let config = AssetsConfig {
        front_alignment: FrontAlignment::FrontView,
        ..AssetsConfig::default()
    };
    let g = index(&Mesh::cuboid([0.1, 0.2, 0.3]), Some(&front), &config)
        .geometry
        .expect("geometry");
    assert_eq!(g.front_yaw_deg, -90.0);
    // A quarter turn swaps width and depth.
    assert_abs_diff_eq!(g.size_m[0], 0.3, epsilon = 1e-6);
    assert_abs_diff_eq!(g.size_m[1], 0.1, epsilon = 1e-6);
    // The glTF convention ignores frontView.
    let g = index(
        &Mesh::cuboid([0.1, 0.2, 0.3]),
        Some(&front),
        &AssetsConfig::default(),
    )
    .geometry
    .expect("geometry");
    assert_eq!(g.front_yaw_deg, 0.0);
    let bad = AssetAnnotation {
        front_view: Some(9),
        ..AssetAnnotation::default()
    };
    let indexed = index(&Mesh::cuboid([0.1, 0.2, 0.3]), Some(&bad), &config);
    assert!(
        indexed.warnings.iter().any(|w| w.contains("frontView 9")),
        "{:?}",
        indexed.warnings
    );
}

#[test]
fn the_table_aligned_frame_follows_spec_section_2() {
    // glTF (X, Y, Z) = (0.3, 0.05, -0.2) is the table point (0.3, 0.2, 0.05).
    assert_eq!(
        table_aligned_from_gltf([0.3, 0.05, -0.2], 0.0),
        [0.3, 0.2, 0.05]
    );
    // A yaw of +90° turns +x to +y.
    let p = table_aligned_from_gltf([1.0, 0.0, 0.0], 90.0);
    assert_abs_diff_eq!(p[0], 0.0, epsilon = 1e-12);
    assert_abs_diff_eq!(p[1], 1.0, epsilon = 1e-12);
}

#[test]
fn a_centimetre_model_under_a_scaled_node_is_in_metres() {
    let cm = Mesh::cuboid([10.0, 20.0, 30.0]).to_glb(0.01);
    let g = index_asset("uid", "d", &cm, None, &AssetsConfig::default())
        .geometry
        .expect("geometry");
    assert_abs_diff_eq!(g.size_m[2], 0.2, epsilon = 1e-6);
    // Without the scale it would be implausible, and says so.
    let big = index_asset(
        "uid",
        "d",
        &Mesh::cuboid([10.0, 20.0, 30.0]).to_glb(1.0),
        None,
        &AssetsConfig::default(),
    );
    assert!(
        big.warnings.iter().any(|w| w.contains("centimetres")),
        "{:?}",
        big.warnings
    );
}

#[test]
fn a_flat_asset_is_invalid() {
    let flat = Mesh::cuboid([0.2, 0.0, 0.3]);
    let indexed = index(&flat, None, &AssetsConfig::default());
    let (code, reason) = indexed.invalid.expect("invalid");
    assert_eq!(code, "zero_size_axis");
    assert!(
        reason.starts_with("the asset is flat: its extent along z (height) is 0.0000 mm"),
        "{reason}"
    );
    assert!(indexed.shapes.is_none());
    assert!(indexed.geometry.is_some());
}

#[test]
fn an_unreadable_glb_is_invalid_with_the_readers_reason() {
    let indexed = index_asset(
        "uid",
        "d",
        b"glTF\x01\x00\x00\x00",
        None,
        &AssetsConfig::default(),
    );
    let (code, reason) = indexed.invalid.expect("invalid");
    assert_eq!(code, "GLB_UNEXPECTED_END_OF_HEADER");
    assert!(
        reason.contains("fewer than the 12-byte GLB header"),
        "{reason}"
    );
    assert!(indexed.geometry.is_none());
}

#[test]
fn a_bbox_that_disagrees_with_the_mesh_is_a_warning() {
    let annotation = AssetAnnotation {
        bbox: Some(BboxExtents {
            x: 0.1,
            y: 0.4,
            z: 0.3,
        }),
        ..AssetAnnotation::default()
    };
    let indexed = index(
        &Mesh::cuboid([0.1, 0.2, 0.3]),
        Some(&annotation),
        &AssetsConfig::default(),
    );
    assert_eq!(indexed.warnings.len(), 1, "{:?}", indexed.warnings);
    assert!(
        indexed.warnings[0].contains("Y 0.4000 m vs 0.2000 m"),
        "{:?}",
        indexed.warnings
    );
}

/// Containers keep their cavity: a point inside a bowl or a cup, above its floor, is inside the
/// convex hull but in no part of the decomposition; a point in the wall is in some part.
#[test]
fn the_decomposition_of_a_vessel_keeps_its_cavity() {
    for (name, radius, height) in [("bowl", 0.08, 0.06), ("cup", 0.04, 0.10)] {
        let vessel = Mesh::vessel(radius, height, 0.006, 0.008);
        let indexed = index(&vessel, None, &AssetsConfig::default());
        let shapes = indexed.shapes.expect("shapes");
        assert_eq!(shapes.decomposition.method, "adaptive", "{name}");
        assert!(
            shapes.parts.len() > 1,
            "{name}: {} parts",
            shapes.parts.len()
        );
        for cavity in [
            [radius / 3.0, radius / 4.0, height * 0.6],
            [-radius / 3.0, 0.01, height * 0.5],
            [0.01, -radius / 2.0, height * 0.8],
        ] {
            assert!(contains(&shapes.hull, cavity), "{name}");
            assert!(
                !shapes.parts.iter().any(|p| contains(p, cavity)),
                "{name}: the cavity is filled at {cavity:?}"
            );
        }
        // The wall and the floor are solid (points off the axis: the parts of a solid of
        // revolution meet there, with gaps far below a millimetre).
        let wall = [radius - 0.003, 0.002, height * 0.6];
        assert!(
            shapes.parts.iter().any(|p| contains(p, wall)),
            "{name}: the wall is missing"
        );
        let floor = [0.01, 0.005, 0.004];
        assert!(
            shapes.parts.iter().any(|p| contains(p, floor)),
            "{name}: the floor is missing"
        );
        let total: f64 = shapes.parts.iter().map(|p| p.volume_m3).sum();
        assert!(
            total < 0.6 * shapes.hull.volume_m3,
            "{name}: parts {total} vs hull {}",
            shapes.hull.volume_m3
        );
    }
}

#[test]
fn the_text_index_holds_category_and_description() {
    let annotations = Annotations::parse(
        r#"{"u1": {"category": "coffee_mug", "description": "A white porcelain cup."},
            "u2": {"description": "A ceramic vase."},
            "u3": {"mass": 1.0}}"#,
    )
    .expect("annotations");
    let index = build_text_index(&annotations, &AssetsConfig::default());
    assert_eq!(index.encoder, "lexical/1");
    assert_eq!(index.documents.keys().collect::<Vec<_>>(), ["u1", "u2"]);
    assert_eq!(
        index.documents["u1"].text,
        "coffee mug. A white porcelain cup."
    );
    assert_eq!(index.document_frequency["c:ceramic"], 2);
    assert_eq!(index.document_frequency["w:mug"], 1);
    let without = build_text_index(
        &annotations,
        &AssetsConfig {
            text_includes_category: false,
            ..AssetsConfig::default()
        },
    );
    assert_eq!(without.documents["u1"].text, "A white porcelain cup.");
}

#[test]
fn only_closed_meshes_have_a_volume() {
    let closed = Mesh::cuboid([1.0, 2.0, 3.0]);
    let v = shapes::closed_volume(&closed.positions, &closed.triangles).expect("closed");
    assert_abs_diff_eq!(v, 6.0, epsilon = 1e-9);
    // Drop the top face: open.
    let open = Mesh {
        triangles: closed.triangles[..2]
            .iter()
            .chain(&closed.triangles[4..])
            .copied()
            .collect(),
        ..closed.clone()
    };
    assert_eq!(
        shapes::closed_volume(&open.positions, &open.triangles),
        None
    );
    // Every triangle with its own vertices (seams everywhere, as in Box.glb): welded.
    let seamed = Mesh {
        positions: closed
            .triangles
            .iter()
            .flat_map(|t| t.map(|i| closed.positions[i as usize]))
            .collect(),
        triangles: (0..closed.triangles.len() as u32)
            .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
            .collect(),
    };
    let v = shapes::closed_volume(&seamed.positions, &seamed.triangles).expect("welded");
    assert_abs_diff_eq!(v, 6.0, epsilon = 1e-9);
}

/// A config whose budget nothing reaches.
fn unbounded() -> AssetsConfig {
    AssetsConfig {
        budget: budget::AssetBudget {
            triangles: u64::MAX,
            instances: u64::MAX,
            max_triangles: u64::MAX,
            simplified_triangles: u64::MAX,
            seconds: 1e9,
        },
        ..AssetsConfig::default()
    }
}

/// 150 small spheres, 3 cm apart on a 10 × 15 grid: one mesh placed by 150 nodes.
fn instanced_spheres() -> (Mesh, Vec<[f64; 3]>) {
    let sphere = Mesh::sphere(0.01, 12, 12);
    let translations = (0..150)
        .map(|i| [0.03 * f64::from(i % 10), 0.0, 0.03 * f64::from(i / 10)])
        .collect();
    (sphere, translations)
}

#[test]
fn the_cost_is_read_from_accessor_counts_and_instancing() {
    let (sphere, translations) = instanced_spheres();
    let glb = sphere.to_instanced_glb(&translations);
    let document = crate::glb_read::open_glb(&glb).expect("opens");
    let cost = budget::glb_cost(&document).expect("cost");
    assert_eq!(cost.instances, 150);
    assert_eq!(cost.triangles, 150 * sphere.triangles.len() as u64);
}

#[test]
fn an_asset_over_the_triangle_budget_is_decimated_with_its_reach_reported() {
    let sphere = Mesh::sphere(0.05, 100, 100);
    assert_eq!(sphere.triangles.len(), 19_800);
    let config = AssetsConfig {
        budget: budget::AssetBudget {
            triangles: 5_000,
            simplified_triangles: 1_000,
            ..budget::AssetBudget::default()
        },
        ..AssetsConfig::default()
    };
    let indexed = index(&sphere, None, &config);
    assert_eq!(indexed.invalid, None);
    assert_eq!(
        indexed.geometry.as_ref().expect("geometry").triangles,
        19_800
    );
    let shapes = indexed.shapes.expect("shapes");
    let simplified = shapes.decomposition.simplified.expect("simplified");
    assert_eq!(simplified.method, "vertex_clustering");
    assert_eq!(simplified.triangles, 19_800);
    assert!(simplified.simplified_triangles <= 1_000);
    assert!(simplified.simplified_triangles > 100);
    // Cluster means of a convex surface lie inside it: the parts reach out by rounding only.
    assert!(
        (0.0..0.001).contains(&simplified.reach_m),
        "{}",
        simplified.reach_m
    );
    let warning = indexed
        .warnings
        .iter()
        .find(|w| w.contains("decimated mesh"))
        .expect("a warning");
    assert!(
        warning.starts_with(
            "the asset is over [assets.budget] (19800 triangles > triangles = 5000): its \
             collision shape was made from a decimated mesh (vertex clustering on a "
        ),
        "{warning}"
    );
    assert!(
        warning.ends_with(&format!(
            "convex parts reach up to {:.1} mm outside the original mesh",
            simplified.reach_m * 1000.0
        )),
        "{warning}"
    );
}

#[test]
fn a_decimated_bowl_reports_how_far_its_parts_reach_outside_it() {
    // Clustering on a grid coarser than the wall merges the inner and outer walls: the parts
    // then bulge out of the original by a measurable amount.
    let bowl = Mesh::vessel(0.08, 0.06, 0.006, 0.008);
    let config = AssetsConfig {
        budget: budget::AssetBudget {
            triangles: 100,
            simplified_triangles: 200,
            ..budget::AssetBudget::default()
        },
        ..AssetsConfig::default()
    };
    let indexed = index(&bowl, None, &config);
    assert_eq!(indexed.invalid, None);
    let shapes = indexed.shapes.expect("shapes");
    let simplified = shapes.decomposition.simplified.expect("simplified");
    assert!(simplified.simplified_triangles <= 200);
    // Measured against the original: the parts stay within a couple of grid cells of it.
    let bound = 2.0 * simplified.cell_m * 3f64.sqrt() + 0.002;
    assert!(
        simplified.reach_m > 0.0 && simplified.reach_m < bound,
        "reach {} (bound {bound})",
        simplified.reach_m
    );
    // Every part vertex is within the reported reach of the original bowl (plus rounding).
    let parts: Vec<Vec<[f64; 3]>> = shapes.parts.iter().map(|p| p.points_m.clone()).collect();
    let aligned: Vec<[f64; 3]> = bowl
        .positions
        .iter()
        .map(|p| table_aligned_from_gltf(*p, 0.0))
        .collect();
    let again = reach::reach_outside(&aligned, &bowl.triangles, &parts);
    assert_abs_diff_eq!(again, simplified.reach_m, epsilon = 1e-4);
}

#[test]
fn an_asset_over_the_instance_budget_is_decimated() {
    let (sphere, translations) = instanced_spheres();
    let glb = sphere.to_instanced_glb(&translations);
    let indexed = index_asset("uid", "digest", &glb, None, &AssetsConfig::default());
    assert_eq!(indexed.invalid, None);
    let geometry = indexed.geometry.expect("geometry");
    assert_eq!(geometry.mesh_instances, 150);
    let shapes = indexed.shapes.expect("shapes");
    let simplified = shapes.decomposition.simplified.expect("simplified");
    assert_eq!(simplified.triangles, 150 * sphere.triangles.len() as u64);
    assert!(simplified.reach_m.is_finite() && simplified.reach_m >= 0.0);
    assert!(
        indexed.warnings.iter().any(|w| w
            .contains("the asset is over [assets.budget] (150 mesh instances > instances = 100)")
            && w.contains("mm outside the original mesh")),
        "{:?}",
        indexed.warnings
    );
}

#[test]
fn an_asset_over_the_hard_cap_is_rejected_before_its_meshes_are_read() {
    let sphere = Mesh::sphere(0.05, 30, 30);
    let config = AssetsConfig {
        budget: budget::AssetBudget {
            max_triangles: 1_000,
            ..budget::AssetBudget::default()
        },
        ..AssetsConfig::default()
    };
    let indexed = index(&sphere, None, &config);
    let (code, reason) = indexed.invalid.expect("rejected");
    assert_eq!(code, "over_budget");
    assert_eq!(
        reason,
        "the asset places 1740 triangles (1 mesh instances), over [assets.budget] \
         max_triangles = 1000: indexing it would take gigabytes of memory (decimate it, e.g. \
         Blender's Decimate modifier, or raise max_triangles)"
    );
    assert_eq!(indexed.geometry, None);
    assert_eq!(indexed.shapes, None);
}

#[test]
fn the_time_budget_stops_the_decomposition_and_reports_the_reach() {
    let bowl = Mesh::vessel(0.08, 0.06, 0.006, 0.008);
    let config = AssetsConfig {
        budget: budget::AssetBudget {
            seconds: 0.0,
            ..budget::AssetBudget::default()
        },
        ..AssetsConfig::default()
    };
    let indexed = index(&bowl, None, &config);
    assert_eq!(indexed.invalid, None);
    let shapes = indexed.shapes.expect("shapes");
    assert_eq!(shapes.decomposition.out_of_time, Some(true));
    assert_eq!(shapes.decomposition.simplified, None);
    // No time for a single cut: the bowl's hull, which bridges its cavity.
    assert_eq!(shapes.parts.len(), 1);
    let reach = shapes.decomposition.max_deviation_m.expect("reach");
    assert!(reach > 0.01, "{reach}");
    let warning = indexed
        .warnings
        .iter()
        .find(|w| w.contains("time budget"))
        .expect("a warning");
    assert_eq!(
        warning,
        &format!(
            "the convex decomposition ran out of its time budget ([assets.budget] seconds = 0 \
             s) and kept the 1 parts it had: they reach up to {:.1} mm outside the mesh, more \
             than decomposition_tolerance_m (1.0 mm) (raise seconds, or decimate the asset)",
            reach * 1000.0
        )
    );
}

#[test]
fn an_asset_within_the_budget_is_indexed_as_without_one() {
    for mesh in [
        Mesh::vessel(0.08, 0.06, 0.006, 0.008),
        Mesh::sphere(0.05, 30, 30),
        Mesh::cuboid([0.1, 0.2, 0.3]),
    ] {
        let within = index(&mesh, None, &AssetsConfig::default());
        let shapes = within.shapes.as_ref().expect("shapes");
        assert_eq!(shapes.decomposition.simplified, None);
        assert_eq!(shapes.decomposition.out_of_time, None);
        assert_eq!(within, index(&mesh, None, &unbounded()));
    }
}

/// The worst assets of issue 20 at full size: a 2M-triangle sphere, and a 20k-triangle sphere
/// placed by 200 nodes. Slow in a debug build: run with
/// `cargo test --release -p mesa-stages worst_assets -- --ignored --nocapture`; with
/// `MESA_WORST_ASSETS_DIR` set, the GLBs are also written there (for `mesa assets --jobs 1`).
#[test]
#[ignore]
fn the_worst_assets_are_indexed_within_the_default_budget() {
    let dense = Mesh::sphere(0.1, 1000, 1000);
    assert!(dense.triangles.len() >= 1_998_000);
    let sphere = Mesh::sphere(0.05, 100, 101);
    let translations: Vec<[f64; 3]> = (0..200)
        .map(|i| [0.12 * f64::from(i % 20), 0.0, 0.12 * f64::from(i / 20)])
        .collect();
    let assets = [
        ("dense_sphere_2m", dense.to_glb(1.0)),
        ("sphere_20k_x200", sphere.to_instanced_glb(&translations)),
    ];
    for (name, glb) in &assets {
        if let Some(dir) = std::env::var_os("MESA_WORST_ASSETS_DIR") {
            let path = std::path::Path::new(&dir).join(format!("{name}.glb"));
            std::fs::write(&path, glb).expect("write");
        }
        let started = std::time::Instant::now();
        let indexed = index_asset(name, "digest", glb, None, &AssetsConfig::default());
        println!(
            "{name}: {} bytes, indexed in {:.1} s: {:?}",
            glb.len(),
            started.elapsed().as_secs_f64(),
            indexed.warnings
        );
        assert_eq!(indexed.invalid, None);
        let simplified = indexed
            .shapes
            .expect("shapes")
            .decomposition
            .simplified
            .expect("simplified");
        assert!(simplified.reach_m.is_finite());
    }
}

/// An asset whose parts cannot get within the tolerance keeps its measured reach, the reason
/// in the index and a warning; the same asset with a budget free to grow needs none.
#[test]
fn an_asset_beyond_the_tolerance_records_why_and_warns() {
    let bowl = Mesh::vessel(0.08, 0.06, 0.006, 0.008);
    let capped = AssetsConfig {
        decomposition_max_parts: 4,
        decomposition_most_parts: 4,
        ..AssetsConfig::default()
    };
    let indexed = index(&bowl, None, &capped);
    let shapes = indexed.shapes.expect("shapes");
    let d = &shapes.decomposition;
    let reach = d.max_deviation_m.expect("reach");
    assert!(reach > 0.001, "{reach}");
    assert_eq!(d.over_tolerance.as_deref(), Some("part_cap"));
    assert_eq!(d.part_budget, Some(4));
    assert!(
        indexed.warnings.iter().any(|w| w.contains(&format!(
            "reach up to {:.1} mm outside the mesh, more than decomposition_tolerance_m (1.0 \
             mm): the part budget grew to decomposition_most_parts = 4 and ran out",
            reach * 1000.0
        ))),
        "{:?}",
        indexed.warnings
    );
    // Control: the same first budget, free to grow, gets the bowl within the tolerance.
    let growing = AssetsConfig {
        decomposition_max_parts: 4,
        ..AssetsConfig::default()
    };
    let indexed = index(&bowl, None, &growing);
    let d = indexed.shapes.expect("shapes").decomposition;
    assert!(d.max_deviation_m.expect("reach") <= 0.001);
    assert_eq!(d.over_tolerance, None);
    assert!(d.part_budget.expect("budget") > 4);
    assert!(indexed.warnings.is_empty(), "{:?}", indexed.warnings);
}

/// Every part of every demo asset spans an area: a piece cut down to an edge (a face lying on
/// a cut) is no part. The demo pen had 107 identical two-point parts of 128 (its clip's
/// edge), which used up its part budget: it now needs fewer parts and reaches less far.
#[test]
fn no_demo_asset_has_a_part_that_is_a_point_or_a_segment() {
    let dir = tempfile::tempdir().expect("tempdir");
    crate::demo::write_demo(
        dir.path(),
        &crate::demo::DemoOptions::default().with_scenes(1),
    )
    .expect("demo");
    let library = dir.path().join("assets/library");
    let mut glbs: Vec<_> = std::fs::read_dir(&library)
        .expect("library")
        .map(|e| e.expect("entry").path())
        .collect();
    glbs.sort();
    let config = AssetsConfig::default();
    let mut worst_pen = None;
    for glb in &glbs {
        let bytes = std::fs::read(glb).expect("read");
        let uid = glb
            .file_stem()
            .expect("stem")
            .to_string_lossy()
            .into_owned();
        let indexed = index_asset(&uid, "digest", &bytes, None, &config);
        let shapes = indexed.shapes.expect("shapes");
        for (i, part) in shapes.parts.iter().enumerate() {
            assert!(
                !super::decompose::collinear(&part.points_m),
                "{uid}: part {i} is {:?}",
                part.points_m
            );
        }
        // The pen: the slimmest asset (1 cm thick, 14 cm long).
        if uid == "49151422f1ad6513609fa49aec5cabbb" {
            worst_pen = Some((shapes.parts.len(), shapes.decomposition.max_deviation_m));
        }
    }
    let (parts, reach) = worst_pen.expect("the demo pen");
    println!("the demo pen: {parts} parts, reach {reach:?}");
    assert!(parts < 128, "{parts} parts");
}
