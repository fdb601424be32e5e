//! `mesa demo`: 20 scenes (every table type, every input form) and the asset library, written
//! to a fresh folder, on the machine's cores (the figure the issue asks for: under 10 s on 2
//! cores). `RAYON_NUM_THREADS` pins the thread count.

use std::time::Duration;

use criterion::{criterion_group, criterion_main, BatchSize, Criterion};
use mesa_stages::demo::{write_demo, DemoOptions};

fn bench(c: &mut Criterion) {
    let options = DemoOptions::default().with_scenes(20).with_seed(7);
    let mut group = c.benchmark_group("demo");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(60));
    group.bench_function("20_scenes", |b| {
        b.iter_batched(
            || tempfile::tempdir().expect("tempdir"),
            |dir| {
                let summary = write_demo(dir.path(), &options).expect("demo");
                assert_eq!(summary.scenes.len(), 20);
                dir
            },
            BatchSize::PerIteration,
        )
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
