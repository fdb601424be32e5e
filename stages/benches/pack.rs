//! `pack` and `ingest` of a 15-object scene: the demo's office_table_0003 (seed 7), its true
//! layout cut to its first 15 objects (13 assets, textured and not, with node hierarchies),
//! with the photo and the instance masks (so the snapshots are made too). Ingest reads the
//! edited GLB the simulated annotator writes for it.
//!
//! `bench/compare_blender_pack.py` times the official approach (Blender importing each asset
//! GLB, transforming it, exporting the scene, as MesaTask's `reconstruct_blender.py` does) on
//! the same scene, against `examples/pack_timing.rs` (this bench's pack, timed as Blender is).

use criterion::{criterion_group, criterion_main, Criterion};
use mesa_schemas::annotation::PackIndexArtifact;
use mesa_schemas::artifacts::TruthInstances;
use mesa_stages::demo::annotator::{annotate_scene, AnnotateRequest};
use mesa_stages::ingest::{ingest_scene, IngestConfig, IngestRequest};
use mesa_stages::pack::{pack_scene, PackConfig};

#[path = "common/pack_scene.rs"]
// Parts of it serve one of its two users only.
#[allow(dead_code)]
mod pack_scene;

use pack_scene::{read, PackScene};

fn bench(c: &mut Criterion) {
    let inputs = PackScene::new();
    let assets = inputs.assets();
    let request = inputs.request(&assets);
    let (layout, scene) = (&inputs.layout, &inputs.scene);
    let config = PackConfig::default();
    let packed = pack_scene(&request, &config).expect("packs");
    assert_eq!(packed.index.objects.len(), 15);

    let mut group = c.benchmark_group("pack");
    group.bench_function("pack_15_objects", |b| {
        b.iter(|| pack_scene(&request, &config).expect("packs"))
    });

    // The annotator's edit of it, then ingest.
    let glb = &packed.files["office_table_0003.glb"];
    let index: PackIndexArtifact = packed.index.clone();
    let truth_instances: TruthInstances = read(&scene.join("truth/instances.json"));
    let annotation = annotate_scene(&AnnotateRequest {
        scene_id: "office_table_0003",
        pack_glb: glb,
        index: &index,
        baseline: layout,
        truth: layout,
        truth_instances: &truth_instances,
        seed: 7,
    })
    .expect("annotates");
    let ingest = IngestRequest {
        scene_id: "office_table_0003",
        refined_glb: &annotation.glb,
        refined_rel: "refined/office_table_0003.glb",
        pack_glb: glb,
        index: &index,
        baseline: layout,
    };
    let ingest_config = IngestConfig::default();
    let out = ingest_scene(&ingest, &ingest_config).expect("ingests");
    assert_eq!(out.layout.objects.len(), 15);
    group.bench_function("ingest_15_objects", |b| {
        b.iter(|| ingest_scene(&ingest, &ingest_config).expect("ingests"))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
