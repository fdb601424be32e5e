//! `mesa check` of one scene of about 15 objects with cached collision shapes (issue 7). Run:
//! `cargo bench -p mesa-stages --bench check`.
//!
//! The scene is a `mesa demo` true layout (real procedural assets: bowls, mugs, lamps, books,
//! decomposed by `mesa assets`' adaptive decomposition), the one with the number of objects
//! closest to 15. Shapes and meshes are loaded once (the asset index's cache); each iteration
//! places every object's convex parts (position, rotation, scale), and the meshes of the objects
//! judged on them (loose objects, deep pairs, steep supports), and checks:
//!
//! - `collisions`: every pair's penetration depth (what trimesh's `CollisionManager` answers:
//!   `bench/check_vs_fcl.sh` compares the two on the same convex parts);
//! - `full`: the whole check of `qa/check.json`: collisions, the fall of every object (floating),
//!   zones, MesaTask's 5 cm rule.
//!
//! `MESA_CHECK_BENCH_DATASET` (a dataset with `assets/index/`) and `MESA_CHECK_BENCH_LAYOUT` (a
//! dataset layout file) bench that scene instead (what the comparison script does).

mod common;

use std::collections::BTreeMap;
use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use common::read;
use criterion::{criterion_group, criterion_main, Criterion};
use mesa_schemas::artifacts::{AssetIndexArtifact, ShapesArtifact};
use mesa_stages::check::solid::AssetMesh;
use mesa_stages::check::{check_scene, collisions_of, AssetShape, PhysicsScene, Tolerances};
use mesa_stages::export::VisualMesh;
use mesa_stages::glb_read::read_glb;

/// The allocator of the `mesa` executable (pipeline/src/main.rs), so that the figures are the
/// ones `mesa check` gets: placing a scene allocates each part's points.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// Shapes from a dataset's asset index.
fn indexed_shapes(dataset: &Path) -> BTreeMap<String, Arc<AssetShape>> {
    let index: AssetIndexArtifact = read(&dataset.join("assets/index/assets.json"));
    index
        .assets
        .iter()
        .filter_map(|(uid, r)| {
            let (s, g) = (r.shapes.as_ref()?, r.geometry.as_ref()?);
            let artifact: ShapesArtifact = read(&dataset.join(&s.file));
            let bytes = std::fs::read(dataset.join(&r.file)).expect("glb");
            let visual = VisualMesh::from_glb(&read_glb(&bytes).expect("glb"), g);
            let shape = AssetShape::new(uid, &artifact, g)
                .expect("shape")
                .with_mesh(AssetMesh::new(visual.positions_m, visual.triangles));
            Some((uid.clone(), Arc::new(shape)))
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let (layout, shapes) = match (
        std::env::var_os("MESA_CHECK_BENCH_DATASET"),
        std::env::var_os("MESA_CHECK_BENCH_LAYOUT"),
    ) {
        (Some(dataset), Some(layout)) => (
            read(&PathBuf::from(layout)),
            indexed_shapes(Path::new(&dataset)),
        ),
        _ => {
            let scene = common::demo_scene();
            (scene.layout, scene.shapes)
        }
    };
    let parts: usize = layout
        .objects
        .iter()
        .map(|o| shapes[&o.retrieved_uid].part_count())
        .sum();
    eprintln!(
        "check bench: {} objects, {parts} convex parts",
        layout.objects.len()
    );
    let tolerances = Tolerances::default();
    let place = || {
        PhysicsScene::from_layout(&layout, |o| {
            shapes
                .get(&o.retrieved_uid)
                .cloned()
                .ok_or_else(|| "no shape".to_owned())
        })
    };
    let mut group = c.benchmark_group("check");
    group.bench_function("collisions", |b| {
        b.iter(|| black_box(collisions_of(&place(), tolerances.penetration_m)))
    });
    // The query alone on parts placed beforehand: the counterpart of FCL's query on trees
    // built and scaled beforehand (`bench/check_vs_fcl.py`). Each iteration gets a freshly
    // placed scene, so what a part works out only when a query needs it is timed with the
    // query; the scene is dropped untimed, as FCL's trees are.
    group.bench_function("collisions_placed", |b| {
        b.iter_batched_ref(
            place,
            |scene| black_box(collisions_of(scene, tolerances.penetration_m)),
            criterion::BatchSize::SmallInput,
        )
    });
    group.bench_function("full", |b| {
        b.iter(|| black_box(check_scene(&place(), &tolerances)))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
