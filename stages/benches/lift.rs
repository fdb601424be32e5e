//! `lift` on a 1024×1024 depth map with 15 instances, image decoding included (the figure the
//! issue asks for: under 40 ms per scene). `bench/compare_open3d.py` runs the same input
//! through Open3D.

use criterion::{criterion_group, criterion_main, Criterion};
use mesa_stages::lift::synthetic::SyntheticScene;
use mesa_stages::lift::{lift_scene, LiftConfig};

fn bench(c: &mut Criterion) {
    let dir = tempfile::tempdir().expect("tempdir");
    let input = dir.path().join("input");
    SyntheticScene::default()
        .write(&input)
        .expect("write scene");
    let config = LiftConfig::default();
    let out = lift_scene(&input, "bench", 0, &config).expect("lift");
    assert_eq!(out.artifact.instances.len(), 15);
    let mut group = c.benchmark_group("lift");
    group.sample_size(20);
    group.bench_function("1024x1024_15_instances", |b| {
        b.iter(|| lift_scene(&input, "bench", 0, &config).expect("lift"))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
