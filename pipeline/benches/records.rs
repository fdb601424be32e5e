//! `mesa records` throughput: the records of a synthetic dataset (template tasks, 5 per scene)
//! rebuilt with `--force`, in scenes per second. The 10,000-scene figure (wall time and peak
//! memory of the `mesa` process) comes from `bench/records_10k.sh`.

use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use mesa_pipeline::commands::records::run_records;
use mesa_pipeline::config::{Config, ProgressMode};
use mesa_pipeline::runner::{Executor, RunOptions, StageContext};

mod synthetic;

const SCENES: usize = 120;

fn bench(c: &mut Criterion) {
    let dir = tempfile::tempdir().expect("tempdir");
    synthetic::write_dataset(dir.path(), SCENES, 1).expect("a synthetic dataset");
    let config = Config::default();
    let options = RunOptions {
        jobs: 0,
        force: true,
        progress: ProgressMode::Off,
        ..RunOptions::from_config(&config)
    };
    let exec = Executor::new("records", &options).expect("threads");
    let ctx = StageContext {
        dataset: dir.path(),
        config: &config,
    };
    let mut group = c.benchmark_group("records");
    group.throughput(Throughput::Elements(SCENES as u64));
    group.sample_size(10);
    group.measurement_time(Duration::from_secs(15));
    group.bench_function(format!("{SCENES}_scenes"), |b| {
        b.iter(|| {
            let summary = run_records(&ctx, &exec).expect("records");
            assert_eq!(summary.scenes, SCENES);
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
