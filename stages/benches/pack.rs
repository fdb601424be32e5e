//! `pack` and `ingest` of a 15-object scene: the demo's office_table_0003 (seed 7), its true
//! layout cut to its first 15 objects (13 assets, textured and not, with node hierarchies),
//! with the photo and the instance masks (so the snapshots are made too). Ingest reads the
//! edited GLB the simulated annotator writes for it.
//!
//! `bench/compare_blender_pack.py` times the official approach (Blender importing each asset
//! GLB, transforming it, exporting the scene, as MesaTask's `reconstruct_blender.py` does) on
//! the same scene, against this bench's estimate.

use std::collections::BTreeMap;
use std::path::Path;

use criterion::{criterion_group, criterion_main, Criterion};
use mesa_schemas::annotation::PackIndexArtifact;
use mesa_schemas::artifacts::TruthInstances;
use mesa_schemas::layout::DatasetLayout;
use mesa_stages::demo::annotator::{annotate_scene, AnnotateRequest};
use mesa_stages::demo::{write_demo, DemoOptions};
use mesa_stages::ingest::{ingest_scene, IngestConfig, IngestRequest};
use mesa_stages::lift::inputs::{read_instances, read_masks};
use mesa_stages::pack::snapshot::Photo;
use mesa_stages::pack::{pack_scene, AssetSource, PackConfig, PackRequest};

const SCENE: &str = "scenes/office_table/office_table_0003";

fn read<T: serde::de::DeserializeOwned>(path: &Path) -> T {
    serde_json::from_slice(&std::fs::read(path).expect("read")).expect("json")
}

fn bench(c: &mut Criterion) {
    let dir = tempfile::tempdir().expect("tempdir");
    write_demo(
        dir.path(),
        &DemoOptions::default().with_scenes(20).with_seed(7),
    )
    .expect("demo");
    let scene = dir.path().join(SCENE);
    let mut layout: DatasetLayout = read(&scene.join("truth/layout.json"));
    layout.objects.truncate(15);
    let layout_bytes = mesa_schemas::json::to_sorted_pretty(&layout).expect("json");
    let glbs: BTreeMap<String, Vec<u8>> = layout
        .objects
        .iter()
        .map(|o| {
            let path = dir
                .path()
                .join(format!("assets/library/{}.glb", o.retrieved_uid));
            (o.retrieved_uid.clone(), std::fs::read(path).expect("asset"))
        })
        .collect();
    let assets: BTreeMap<String, AssetSource<'_>> = glbs
        .iter()
        .map(|(uid, glb)| {
            (
                uid.clone(),
                AssetSource {
                    glb,
                    front_yaw_deg: 0.0,
                },
            )
        })
        .collect();
    let png = std::fs::read(scene.join("input/image.png")).expect("photo");
    let image = image::load_from_memory(&png).expect("png").into_rgb8();
    let photo = Photo {
        width: image.width() as usize,
        height: image.height() as usize,
        rgb: image.pixels().map(|p| p.0).collect(),
    };
    let instances = read_instances(&scene.join("input/instances.json")).expect("instances");
    let masks =
        read_masks(&scene.join("input"), &instances, photo.width, photo.height).expect("masks");
    let by_instance: BTreeMap<String, Vec<u32>> = layout
        .objects
        .iter()
        .filter_map(|o| {
            let id = o.provenance.as_ref()?.source_instance?;
            Some((o.instance.clone(), masks.pixels.get(&id)?.clone()))
        })
        .collect();
    let request = PackRequest {
        scene_id: "office_table_0003",
        table_type: "office_table",
        layout: &layout,
        layout_rel: "coarse/layout.json",
        layout_bytes: &layout_bytes,
        assets: &assets,
        photo: Some((&png, &photo)),
        masks: &by_instance,
    };
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
        baseline: &layout,
        truth: &layout,
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
        baseline: &layout,
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
