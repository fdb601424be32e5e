//! The pack on small fixtures: what the GLB holds, where its nodes are, and that the same
//! inputs give the same bytes.

use approx::assert_abs_diff_eq;

use super::testing::{fixture, hierarchy_asset, pack, split_glb, LAMP, MUG};
use super::*;
use crate::glb_read::open_glb;
use crate::gltf_frames::{table_from_gltf_point, table_from_gltf_quat};

#[test]
fn the_pack_is_deterministic_and_complete() {
    let f = fixture();
    let a = pack(&f, &PackConfig::default());
    let b = pack(&f, &PackConfig::default());
    assert_eq!(a, b, "the same inputs give the same pack");
    let names: Vec<&str> = a.files.keys().map(String::as_str).collect();
    for expected in [
        "office_table_0001.glb",
        "reference.png",
        "index.json",
        "README.txt",
        "snapshots/mug_0.png",
        "snapshots/pen_10.png",
    ] {
        assert!(names.contains(&expected), "{expected} missing: {names:?}");
    }
    assert!(!names.iter().any(|n| n.ends_with(".zip")));
    let zipped = pack(
        &f,
        &PackConfig {
            zip: true,
            ..PackConfig::default()
        },
    );
    let zip_a = &zipped.files["office_table_0001.zip"];
    let zip_b = &pack(
        &f,
        &PackConfig {
            zip: true,
            ..PackConfig::default()
        },
    )
    .files["office_table_0001.zip"];
    assert_eq!(zip_a, zip_b, "the zip is deterministic");
    let mut archive = zip::ZipArchive::new(std::io::Cursor::new(zip_a.clone())).expect("zip");
    assert_eq!(archive.len(), zipped.files.len() - 1);
    let mut readme = String::new();
    std::io::Read::read_to_string(
        &mut archive
            .by_name("office_table_0001/README.txt")
            .expect("README in the zip"),
        &mut readme,
    )
    .expect("read");
    assert!(readme.contains("Do not apply transforms"));
    assert!(readme.contains("glTF Binary (.glb)"));
    assert!(readme.contains("pen_10"));
}

#[test]
fn nodes_are_named_after_instances_with_extras_and_shared_meshes() {
    let f = fixture();
    let out = pack(&f, &PackConfig::default());
    let glb = &out.files["office_table_0001.glb"];
    let (root, _) = split_glb(glb);
    let names: Vec<&str> = root
        .nodes
        .iter()
        .filter_map(|n| n.name.as_deref())
        .collect();
    assert_eq!(names[0], TABLE_NODE);
    assert_eq!(names[1], RESTRICTED_ZONE_NODE);
    assert_eq!(*names.last().expect("nodes"), H1_NODE);
    for object in &f.layout.objects {
        let node = &root.nodes[super::testing::node(&root, &object.instance)];
        let extras: serde_json::Value =
            serde_json::from_str(node.extras.as_ref().expect("extras").get()).expect("json");
        assert_eq!(extras["mesa"]["instance"], object.instance.as_str());
        assert_eq!(extras["mesa"]["uid"], object.retrieved_uid.as_str());
        assert_eq!(extras["mesa"]["scene_id"], "office_table_0001");
    }
    // The two mugs share one mesh; every asset has one mesh.
    let mesh_of = |name: &str| root.nodes[super::testing::node(&root, name)].mesh;
    assert_eq!(mesh_of("mug_0"), mesh_of("mug_1"));
    assert_ne!(mesh_of("mug_0"), mesh_of("book_0"));
    assert_eq!(
        root.meshes.len(),
        4 + 3,
        "4 assets, the table, the zone, the figure"
    );
    // Textures are kept: the mug's glaze samples its image.
    assert_eq!(root.images.len(), 1);
    assert!(root
        .materials
        .iter()
        .any(|m| m.pbr_metallic_roughness.base_color_texture.is_some()));
    assert_eq!(out.index.objects.len(), 6);
    assert_eq!(out.index.assets[MUG].mesh, MUG);
}

#[test]
fn each_object_sits_at_its_layout_place_with_its_layout_size() {
    let f = fixture();
    let out = pack(&f, &PackConfig::default());
    let document = open_glb(&out.files["office_table_0001.glb"]).expect("reads");
    let root = document.root();
    let world = document.world_matrices().expect("scene");
    for object in &f.layout.objects {
        let n = super::testing::node(root, &object.instance);
        let node = &root.nodes[n];
        let positions = document
            .mesh_positions(node.mesh.expect("mesh").value())
            .expect("mesh");
        let (min, max) = crate::ingest::geometry::bounds(&positions).expect("vertices");
        // The mesh is centred on its box.
        for i in 0..3 {
            assert_abs_diff_eq!((min[i] + max[i]) / 2.0, 0.0, epsilon = 1e-6);
        }
        let m = world[n].expect("in the scene");
        let position = table_from_gltf_point([m[(0, 3)], m[(1, 3)], m[(2, 3)]]);
        for (p, expected) in position.iter().zip(&object.position_cm.0) {
            assert_abs_diff_eq!(p * 100.0, expected, epsilon = 1e-4);
        }
        let q = node
            .rotation
            .map_or([0.0, 0.0, 0.0, 1.0], |q| q.0.map(f64::from));
        let q = table_from_gltf_quat(q);
        let dot: f64 = q.iter().zip(&object.rotation.0).map(|(a, b)| a * b).sum();
        assert_abs_diff_eq!(dot.abs(), 1.0, epsilon = 1e-6);
        let s = node.scale.unwrap_or([1.0; 3]).map(f64::from);
        let size = [
            (max[0] - min[0]) * s[0],
            (max[2] - min[2]) * s[2],
            (max[1] - min[1]) * s[1],
        ];
        for (s, expected) in size.iter().zip(&object.size_cm.0) {
            assert_abs_diff_eq!(s * 100.0, expected, epsilon = 1e-4);
        }
    }
    // The table top is at z = 0 over the zone; the figure is 1.70 m tall on the floor.
    let table = super::testing::node(root, TABLE_NODE);
    let m = world[table].expect("table");
    let positions = document
        .mesh_positions(root.nodes[table].mesh.expect("mesh").value())
        .expect("mesh");
    let (min, max) = crate::ingest::geometry::bounds(&positions).expect("vertices");
    assert_abs_diff_eq!(m[(1, 3)] + max[1], 0.0, epsilon = 1e-7);
    assert_abs_diff_eq!((max[0] - min[0]) * 100.0, 120.0, epsilon = 1e-4);
    assert_abs_diff_eq!((max[2] - min[2]) * 100.0, 60.0, epsilon = 1e-4);
    let figure = super::testing::node(root, H1_NODE);
    let positions = document
        .mesh_positions(root.nodes[figure].mesh.expect("mesh").value())
        .expect("mesh");
    let (min, max) = crate::ingest::geometry::bounds(&positions).expect("vertices");
    assert_abs_diff_eq!(max[1] - min[1], 1.70, epsilon = 1e-6);
    let m = world[figure].expect("figure");
    assert_abs_diff_eq!(m[(1, 3)] + min[1], -0.75, epsilon = 1e-6);
}

#[test]
fn the_asset_hierarchy_is_baked_into_one_mesh_with_its_box() {
    // The lamp: a root scaled by 2 over a base, an arm turned 30° and a head scaled by 0.5.
    let baked = bake::bake_asset(&hierarchy_asset(), 0.0).expect("bakes");
    let whole = crate::glb_read::read_glb(&hierarchy_asset()).expect("reads");
    let b = crate::mesh::Aabb::from_points(whole.positions_m.iter().copied()).expect("box");
    let expected = crate::gltf_frames::object_from_gltf_axes(b.size());
    for i in 0..3 {
        assert_abs_diff_eq!(baked.size_m[i], expected[i], epsilon = 1e-6);
    }
    assert_eq!(baked.materials.len(), 1);
    assert_eq!(baked.parts.len(), 1, "one primitive per material");
    // Turned by a front-alignment yaw of 90°, width and depth swap.
    let turned = bake::bake_asset(&hierarchy_asset(), 90.0).expect("bakes");
    assert_abs_diff_eq!(turned.size_m[0], baked.size_m[1], epsilon = 1e-6);
    assert_abs_diff_eq!(turned.size_m[1], baked.size_m[0], epsilon = 1e-6);
}

#[test]
fn bad_layouts_and_missing_assets_are_errors_naming_the_instance() {
    let mut f = fixture();
    f.layout.objects[0].instance = "../mug_0".to_owned();
    let assets: BTreeMap<String, AssetSource<'_>> = f
        .assets
        .iter()
        .map(|(u, g)| {
            (
                u.clone(),
                AssetSource {
                    glb: g,
                    front_yaw_deg: 0.0,
                },
            )
        })
        .collect();
    let request = |layout: &DatasetLayout, assets: &BTreeMap<String, AssetSource<'_>>| {
        let masks = BTreeMap::new();
        pack_scene(
            &PackRequest {
                scene_id: "s",
                table_type: "office_table",
                layout,
                layout_rel: "coarse/layout.json",
                layout_bytes: b"{}",
                assets,
                photo: None,
                masks: &masks,
            },
            &PackConfig::default(),
        )
        .map(|_| ())
        .map_err(|e| e.to_string())
    };
    let e = request(&f.layout, &assets).expect_err("a path in a name");
    assert!(
        e.contains("../mug_0") && e.contains("path separator"),
        "{e}"
    );
    let f = fixture();
    let mut fewer = assets.clone();
    fewer.remove(LAMP);
    let e = request(&f.layout, &fewer).expect_err("a missing asset");
    assert!(e.contains("lamp_0") && e.contains(LAMP), "{e}");
}
