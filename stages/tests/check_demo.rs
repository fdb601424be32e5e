//! `check` on the `mesa demo` ground truth: the demo drops every object until it rests on the
//! table or on what is under it (on its triangle meshes), so its true layouts must check clean
//! on the assets' collision shapes: no colliding pair, nothing floating, no zone violation.
//! This measures the decomposition as much as the check: a part bridging a bowl's cavity would
//! make the fruit in it collide.
//!
//! `MESA_CHECK_TEST_SCENES` (default 12, two per table type) and `MESA_CHECK_TEST_SEED`
//! (default 7) make deeper runs (48 scenes: 0 collisions in 4,695 pairs, 0 floating).

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use mesa_schemas::DatasetLayout;
use mesa_stages::annotations::Annotations;
use mesa_stages::assets::{index_asset, AssetsConfig};
use mesa_stages::check::{check_scene, AssetShape, PhysicsScene, Tolerances};
use mesa_stages::demo::{write_demo, DemoOptions};

fn env_or(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .ok()
        .map(|v| {
            v.parse()
                .unwrap_or_else(|_| panic!("{name}={v}: expected a number"))
        })
        .unwrap_or(default)
}

fn read_layout(path: &Path) -> DatasetLayout {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

#[test]
fn the_demo_truth_layouts_check_clean() {
    let dir = tempfile::tempdir().expect("tempdir");
    let options = DemoOptions::default()
        .with_scenes(env_or("MESA_CHECK_TEST_SCENES", 12) as usize)
        .with_seed(env_or("MESA_CHECK_TEST_SEED", 7));
    let summary = write_demo(dir.path(), &options).expect("mesa demo");
    let annotations =
        Annotations::read(&dir.path().join("assets/annotations.json")).expect("annotations");
    let layouts: Vec<(String, DatasetLayout)> = summary
        .scenes
        .iter()
        .map(|s| {
            let path = dir
                .path()
                .join("scenes")
                .join(&s.table_type)
                .join(&s.scene_id)
                .join("truth/layout.json");
            (s.scene_id.clone(), read_layout(&path))
        })
        .collect();
    // The shapes of the assets the scenes use, as `mesa assets` makes them.
    let mut shapes: BTreeMap<String, Arc<AssetShape>> = BTreeMap::new();
    for (_, layout) in &layouts {
        for object in &layout.objects {
            let uid = &object.retrieved_uid;
            if shapes.contains_key(uid) {
                continue;
            }
            let glb = dir.path().join(format!("assets/library/{uid}.glb"));
            let bytes = std::fs::read(&glb).expect("glb");
            let indexed = index_asset(
                uid,
                "",
                &bytes,
                annotations.get(uid),
                &AssetsConfig::default(),
            );
            let artifact = indexed.shapes.expect("shapes");
            let geometry = indexed.geometry.expect("geometry");
            let shape = AssetShape::new(uid, &artifact, &geometry).expect("shape");
            shapes.insert(uid.clone(), Arc::new(shape));
        }
    }
    let tolerances = Tolerances::default();
    let (mut pairs, mut objects) = (0u64, 0usize);
    let mut problems = Vec::new();
    for (scene_id, layout) in &layouts {
        let scene = PhysicsScene::from_layout(layout, |o| {
            shapes
                .get(&o.retrieved_uid)
                .cloned()
                .ok_or_else(|| "no shape".to_owned())
        });
        let findings = check_scene(&scene, &tolerances);
        pairs += findings.pairs_total;
        objects += scene.objects.len();
        let schema = findings.to_schema(&scene);
        if !schema.clean {
            problems.push(format!(
                "{scene_id}: {}",
                serde_json::to_string(&schema).expect("json")
            ));
        }
    }
    println!(
        "{} truth layouts, {objects} objects, {pairs} pairs: {} not clean",
        layouts.len(),
        problems.len()
    );
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}
