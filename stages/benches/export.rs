//! `mesa export` of one scene of about 15 objects (issue 17): the MJCF, URDF and USD files
//! with every mesh (the visual meshes and one OBJ per convex part), made in memory from the
//! assets' shapes and meshes loaded once, as the stage holds them. What is left out is the
//! writing of the files. Run: `cargo bench -p mesa-stages --bench export`.

mod common;

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use mesa_stages::check::Pose;
use mesa_stages::export::{export_scene, ExportConfig, ExportObject, ExportRequest};

fn bench(c: &mut Criterion) {
    let scene = common::demo_scene();
    let objects: Vec<ExportObject<'_>> = scene
        .layout
        .objects
        .iter()
        .map(|o| ExportObject {
            instance: &o.instance,
            uid: &o.retrieved_uid,
            pose: Pose::of_object(o),
            shape: &scene.shapes[&o.retrieved_uid],
            visual: scene.visuals.get(&o.retrieved_uid),
            annotated_mass_kg: None,
        })
        .collect();
    let request = ExportRequest {
        scene_id: "bench_0001",
        layout_file: "qa/layout.json",
        layout_sha256: "0",
        layout: &scene.layout,
        objects,
        skipped: Vec::new(),
        with_table: true,
    };
    let config = ExportConfig::default();
    let once = export_scene(&request, &config).expect("exports");
    let bytes: usize = once.files.values().map(Vec::len).sum();
    let meshes = once.files.keys().filter(|k| k.ends_with(".obj")).count();
    eprintln!(
        "export bench: {} objects, {} files ({meshes} OBJ), {:.1} MB",
        scene.layout.objects.len(),
        once.files.len(),
        bytes as f64 / 1e6
    );
    c.bench_function("export/scene", |b| {
        b.iter(|| black_box(export_scene(&request, &config).expect("exports")))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
