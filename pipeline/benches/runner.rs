//! The runner's per-scene overhead: what it costs beyond the stage's own work.
//!
//! - `skip_done`: a rerun over a done scene (read the marker, hash the inputs, compare);
//! - `write_scene`: a scene processed again with a trivial stage (`--force`: run, then the
//!   output and the marker compared with the files, which hold the same bytes after the first
//!   iteration, so nothing is written: the cost of a forced rerun);
//! - `noop_10k/{write,skip}`: `run_stage` of a stage that does nothing, over 10,000 scenes of
//!   one table type, on one thread: a forced run (every scene run, its marker written the
//!   first time and compared after) and a rerun (every scene skipped). Divided by 10,000, the runner's own cost a scene at dataset scale, where a
//!   table type's marker folder holds thousands of files.

use std::path::Path;

use criterion::{criterion_group, criterion_main, Criterion};
use mesa_pipeline::config::Config;
use mesa_pipeline::fsio::DigestCache;
use mesa_pipeline::runner::{
    digest_of, discover_scenes, process_scene, run_stage, RunOptions, Scene, SceneOutcome,
    SceneOutput, SceneStage, StageContext,
};

struct Tiny;

impl SceneStage for Tiny {
    fn name(&self) -> &'static str {
        "tiny"
    }
    fn inputs(&self, _: &StageContext<'_>, scene: &Scene) -> anyhow::Result<Vec<String>> {
        Ok(vec![
            scene.rel("input/layout.json"),
            scene.rel("input/instances.json"),
        ])
    }
    fn config_digest(&self, ctx: &StageContext<'_>) -> String {
        digest_of(&ctx.config.run.seed)
    }
    fn run(&self, _: &StageContext<'_>, _: &Scene) -> anyhow::Result<SceneOutput> {
        let mut out = SceneOutput::new();
        out.add_file("tiny/out.json", vec![b'x'; 4096]);
        Ok(out)
    }
}

/// A stage that reads nothing and writes nothing but its marker.
struct Noop;

impl SceneStage for Noop {
    fn name(&self) -> &'static str {
        "noop"
    }
    fn inputs(&self, _: &StageContext<'_>, _: &Scene) -> anyhow::Result<Vec<String>> {
        Ok(Vec::new())
    }
    fn config_digest(&self, _: &StageContext<'_>) -> String {
        String::new()
    }
    fn run(&self, _: &StageContext<'_>, _: &Scene) -> anyhow::Result<SceneOutput> {
        Ok(SceneOutput::new())
    }
}

const SCENES: usize = 10_000;

fn noop_dataset(dir: &Path) {
    for i in 0..SCENES {
        let input = dir.join(format!("scenes/office_table/office_table_{i:05}/input"));
        std::fs::create_dir_all(&input).expect("mkdir");
    }
}

fn bench_noop(c: &mut Criterion) {
    let dir = tempfile::tempdir().expect("tempdir");
    noop_dataset(dir.path());
    let config = Config::default();
    let ctx = StageContext {
        dataset: dir.path(),
        config: &config,
    };
    let options = |force| RunOptions {
        jobs: 1,
        force,
        quiet: true,
        progress: mesa_pipeline::config::ProgressMode::Off,
        ..RunOptions::from_config(&config)
    };
    let mut group = c.benchmark_group("noop_10k");
    group.sample_size(10);
    group.bench_function("write", |b| {
        b.iter(|| {
            let summary = run_stage(&Noop, &ctx, &options(true)).expect("run");
            assert_eq!(summary.done, SCENES);
        })
    });
    group.bench_function("skip", |b| {
        b.iter(|| {
            let summary = run_stage(&Noop, &ctx, &options(false)).expect("run");
            assert_eq!(summary.skipped, SCENES);
        })
    });
    group.finish();
}

fn dataset(dir: &Path) {
    let scene = dir.join("scenes/office_table/office_table_0000/input");
    std::fs::create_dir_all(&scene).expect("mkdir");
    // Inputs of realistic size for a layout stage: a few kB of JSON.
    std::fs::write(scene.join("layout.json"), vec![b' '; 8 * 1024]).expect("write");
    std::fs::write(scene.join("instances.json"), vec![b' '; 2 * 1024]).expect("write");
}

fn bench(c: &mut Criterion) {
    let dir = tempfile::tempdir().expect("tempdir");
    dataset(dir.path());
    let config = Config::default();
    let ctx = StageContext {
        dataset: dir.path(),
        config: &config,
    };
    let scene = discover_scenes(dir.path()).expect("scenes").remove(0);
    let digest = Tiny.config_digest(&ctx);
    let cache = DigestCache::default();
    let first = process_scene(&Tiny, &ctx, &scene, &digest, false, &cache);
    assert!(matches!(first, SceneOutcome::Done { .. }));

    c.bench_function("skip_done", |b| {
        b.iter(|| {
            let outcome = process_scene(&Tiny, &ctx, &scene, &digest, false, &cache);
            assert_eq!(outcome, SceneOutcome::Skipped);
        })
    });
    c.bench_function("write_scene", |b| {
        b.iter(|| {
            let outcome = process_scene(&Tiny, &ctx, &scene, &digest, true, &cache);
            assert!(matches!(outcome, SceneOutcome::Done { .. }));
        })
    });
}

criterion_group!(benches, bench, bench_noop);
criterion_main!(benches);
