//! What the benches share: a `mesa demo` scene of about 15 objects with its assets' collision
//! shapes and visual meshes, made as `mesa assets` makes them.
// Each bench binary compiles this module on its own and uses a part of it.
#![allow(dead_code)]

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use mesa_schemas::DatasetLayout;
use mesa_stages::annotations::Annotations;
use mesa_stages::assets::{index_asset, AssetsConfig};
use mesa_stages::check::solid::AssetMesh;
use mesa_stages::check::AssetShape;
use mesa_stages::demo::{write_demo, DemoOptions};
use mesa_stages::export::VisualMesh;
use mesa_stages::glb_read::read_glb;

/// A JSON file, or a panic naming it.
pub fn read<T: serde::de::DeserializeOwned>(path: &Path) -> T {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// A demo scene's true layout, and per asset its shape (with its mesh, as `mesa check` holds
/// it) and its visual mesh.
pub struct DemoScene {
    pub layout: DatasetLayout,
    pub shapes: BTreeMap<String, Arc<AssetShape>>,
    pub visuals: BTreeMap<String, VisualMesh>,
}

/// The scene of a 6-scene demo whose object count is closest to 15.
pub fn demo_scene() -> DemoScene {
    let dir = tempfile::tempdir().expect("tempdir");
    let summary = write_demo(dir.path(), &DemoOptions::default().with_scenes(6)).expect("demo");
    let scene = summary
        .scenes
        .iter()
        .min_by_key(|s| (s.objects as i64 - 15).abs())
        .expect("a scene");
    let layout: DatasetLayout = read(
        &dir.path()
            .join("scenes")
            .join(&scene.table_type)
            .join(&scene.scene_id)
            .join("truth/layout.json"),
    );
    let annotations =
        Annotations::read(&dir.path().join("assets/annotations.json")).expect("annotations");
    let mut shapes = BTreeMap::new();
    let mut visuals = BTreeMap::new();
    for object in &layout.objects {
        let uid = &object.retrieved_uid;
        if shapes.contains_key(uid) {
            continue;
        }
        let bytes =
            std::fs::read(dir.path().join(format!("assets/library/{uid}.glb"))).expect("glb");
        let indexed = index_asset(
            uid,
            "",
            &bytes,
            annotations.get(uid),
            &AssetsConfig::default(),
        );
        let geometry = indexed.geometry.expect("geometry");
        let visual = VisualMesh::from_glb(&read_glb(&bytes).expect("glb"), &geometry);
        let shape = AssetShape::new(uid, &indexed.shapes.expect("shapes"), &geometry)
            .expect("shape")
            .with_mesh(AssetMesh::new(
                visual.positions_m.clone(),
                visual.triangles.clone(),
            ));
        shapes.insert(uid.clone(), Arc::new(shape));
        visuals.insert(uid.clone(), visual);
    }
    DemoScene {
        layout,
        shapes,
        visuals,
    }
}
