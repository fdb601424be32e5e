//! `render`: one 512×512 view (the front view, 2×2 samples per pixel, shadows) of a 15-object
//! demo scene (`dressing_table_0001` of `mesa demo --seed 7`), its assets already loaded (the
//! figure the issue asks for: under 100 ms on one core; run with `RAYON_NUM_THREADS=1`, though
//! a view is single-threaded anyway), shadow map included; the five views of that scene, as
//! `mesa render` draws them (one shadow map for all). Also the same view with its assets read
//! from their GLB files, as the first scene using them pays. `bench/compare_blender.sh` renders the same view
//! with Blender.

use std::collections::BTreeMap;

use criterion::{criterion_group, criterion_main, Criterion};
use mesa_schemas::DatasetLayout;
use mesa_stages::demo::{write_demo, DemoOptions};
use mesa_stages::render::{
    load_render_asset, place_layout, LayoutScene, RenderAsset, RenderConfig, SceneView,
};

fn load_assets(library: &std::path::Path, layout: &DatasetLayout) -> BTreeMap<String, RenderAsset> {
    let config = RenderConfig::default();
    let mut assets = BTreeMap::new();
    for object in &layout.objects {
        let uid = &object.retrieved_uid;
        if !assets.contains_key(uid) {
            let bytes = std::fs::read(library.join(format!("{uid}.glb"))).expect("glb");
            let asset = load_render_asset(&bytes, 0.0, config.max_texture_px).expect("asset");
            assets.insert(uid.clone(), asset);
        }
    }
    assets
}

fn bench(c: &mut Criterion) {
    let dir = tempfile::tempdir().expect("tempdir");
    write_demo(
        dir.path(),
        &DemoOptions::default().with_scenes(5).with_seed(7),
    )
    .expect("demo");
    let scene = dir
        .path()
        .join("scenes/dressing_table/dressing_table_0001/truth/layout.json");
    let layout: DatasetLayout =
        serde_json::from_str(&std::fs::read_to_string(scene).expect("layout")).expect("json");
    assert_eq!(layout.objects.len(), 15);
    let library = dir.path().join("assets/library");
    let assets = load_assets(&library, &layout);
    let config = RenderConfig::default();
    let (placed, _) = place_layout(&layout, |uid| Ok(&assets[uid])).expect("placed");
    let triangles: usize = placed.iter().map(|p| p.asset.triangles).sum();
    eprintln!("render bench: 15 objects, {triangles} triangles");

    let mut group = c.benchmark_group("render");
    group.sample_size(20);
    // A new scene each time: the view pays for the scene's shadow map, as a scene's first
    // view does.
    group.bench_function("front_512_15_objects", |b| {
        b.iter(|| {
            LayoutScene::new(&layout, &placed, &config)
                .render_view(SceneView::Front, &config)
                .expect("render")
        })
    });
    // What `mesa render` draws of a scene: its five views, sharing one shadow map.
    group.bench_function("five_views_512_15_objects", |b| {
        b.iter(|| {
            let scene = LayoutScene::new(&layout, &placed, &config);
            SceneView::ALL
                .iter()
                .map(|view| scene.render_view(*view, &config).expect("render"))
                .collect::<Vec<_>>()
        })
    });
    let no_shadows = RenderConfig {
        shadows: false,
        ..RenderConfig::default()
    };
    group.bench_function("front_512_15_objects_no_shadows", |b| {
        b.iter(|| {
            LayoutScene::new(&layout, &placed, &no_shadows)
                .render_view(SceneView::Front, &no_shadows)
                .expect("render")
        })
    });
    group.bench_function("front_512_15_objects_assets_from_glb", |b| {
        b.iter(|| {
            let assets = load_assets(&library, &layout);
            let (placed, _) = place_layout(&layout, |uid| Ok(&assets[uid])).expect("placed");
            let scene = LayoutScene::new(&layout, &placed, &config);
            scene
                .render_view(SceneView::Front, &config)
                .expect("render")
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
