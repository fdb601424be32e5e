//! Dataset-level stages (`assets`, `records`, `report`, `release`, `render --assets`): they
//! run once over the whole dataset, not per scene, through the same runner as per-scene
//! stages: one thread pool ([`super::thread_pool`]), one progress display
//! ([`crate::progress`]), the same `--jobs`, `--progress` and `--quiet` behaviour, and a run
//! record at `.mesa/runs/<stage>/run.json` (`shard-<k>-of-<N>.json` for a shard). The stage says what one unit of work is (an asset,
//! a scene) through [`Executor::map`]; the executor owns the pool and the display. A stage
//! whose output depends on all its inputs at once keeps a dataset marker
//! (`.mesa/markers/<stage>.json`, the per-scene marker's format with scene `(dataset)`), and
//! holds the stage's lock ([`super::lock`]) for the whole run.

use std::path::PathBuf;

use mesa_schemas::artifacts::RunMarker;
use rayon::prelude::*;

use super::core::{progress, thread_pool, write_run_record, RunOptions, StageContext, RUN_DIR};
use crate::exit::UsageError;
use crate::progress::Tick;

/// A stage that runs once over the dataset.
pub trait DatasetStage: Sync {
    /// The stage name (the subcommand), like `records`.
    fn name(&self) -> &'static str;

    /// Checks the settings before any work (`mesa run` asks every stage before the first one
    /// runs): a setting that cannot work is a usage error, exit code 2.
    fn preflight(&self, _ctx: &StageContext<'_>) -> Result<(), UsageError> {
        Ok(())
    }

    /// Why `mesa run` leaves this stage out on this dataset (printed), or `None`.
    fn skipped_by_run(&self, _ctx: &StageContext<'_>) -> Option<String> {
        None
    }

    /// Does the work on the executor's threads.
    fn run(&self, ctx: &StageContext<'_>, exec: &Executor<'_>) -> anyhow::Result<DatasetReport>;
}

/// What a dataset-level stage reports.
#[derive(Debug, Clone)]
pub struct DatasetReport {
    /// Whether the run succeeded (exit code 0).
    pub success: bool,
    /// The summary for the terminal, one or more lines.
    pub text: String,
    /// The run record kept at `.mesa/runs/<stage>/run.json` (counts, warnings, timings).
    pub record: serde_json::Value,
}

/// The threads and the progress display of a stage run.
pub struct Executor<'a> {
    name: &'static str,
    pool: rayon::ThreadPool,
    options: &'a RunOptions,
}

impl<'a> Executor<'a> {
    /// The executor of stage `name` with `options` (its `jobs`, `progress`, `quiet`).
    pub fn new(name: &'static str, options: &'a RunOptions) -> anyhow::Result<Self> {
        Ok(Self {
            name,
            pool: thread_pool(options.jobs)?,
            options,
        })
    }

    /// The options of the run (`force`, `scenes`, ...).
    pub fn options(&self) -> &RunOptions {
        self.options
    }

    /// Runs `work` on the pool (for rayon iterators of the stage's own shape).
    pub fn install<R: Send>(&self, work: impl FnOnce() -> R + Send) -> R {
        self.pool.install(work)
    }

    /// Maps `items` in parallel on the pool, results in the order of `items` (so outputs are
    /// the same for any thread count), counting each in the progress display as `unit`.
    pub fn map<T: Sync, R: Send>(
        &self,
        unit: &'static str,
        items: &[T],
        work: impl Fn(&T) -> R + Sync,
    ) -> Vec<R> {
        self.map_ticked(unit, items, work, |_| Tick::Done)
    }

    /// [`Executor::map`], with `tick` saying how each result counts (done, skipped, failed).
    pub fn map_ticked<T: Sync, R: Send>(
        &self,
        unit: &'static str,
        items: &[T],
        work: impl Fn(&T) -> R + Sync,
        tick: impl Fn(&R) -> Tick + Sync,
    ) -> Vec<R> {
        let progress = progress(self.name, unit, items.len(), self.options);
        let results = self.pool.install(|| {
            items
                .par_iter()
                .map(|item| {
                    let result = work(item);
                    progress.tick(tick(&result));
                    result
                })
                .collect()
        });
        progress.finish();
        results
    }

    /// A progress display of `total` units for work that goes in chunks (call
    /// [`crate::progress::Progress::advance`], then `finish`).
    pub fn progress(&self, unit: &'static str, total: usize) -> crate::progress::Progress {
        progress(self.name, unit, total, self.options)
    }

    /// Where this stage's dataset marker lives: `.mesa/markers/<stage>.json`.
    pub fn marker_path(&self, ctx: &StageContext<'_>) -> PathBuf {
        marker_path(ctx, self.name)
    }

    /// This stage's dataset marker, when one was written and can be read.
    pub fn read_marker(&self, ctx: &StageContext<'_>) -> Option<RunMarker> {
        super::core::read_marker(&self.marker_path(ctx))
    }
}

/// Where the dataset marker of `stage` lives.
pub fn marker_path(ctx: &StageContext<'_>, stage: &str) -> PathBuf {
    ctx.dataset
        .join(RUN_DIR)
        .join("markers")
        .join(format!("{stage}.json"))
}

/// Runs a dataset-level stage: its executor, its work, its run record. The caller prints
/// [`DatasetReport::text`].
pub fn run_dataset_stage(
    stage: &dyn DatasetStage,
    ctx: &StageContext<'_>,
    options: &RunOptions,
) -> anyhow::Result<DatasetReport> {
    // A folder that does not exist gets no lock folder: the stage says what is wrong.
    let _lock = if ctx.dataset.is_dir() {
        Some(super::lock::lock_stage(ctx, stage.name(), options.shard)?)
    } else {
        None
    };
    let exec = Executor::new(stage.name(), options)?;
    let report = stage.run(ctx, &exec)?;
    // A sharded run (`mesa assets` as an array) one record per shard, as per-scene stages.
    let name = if options.shard.count > 1 {
        format!(
            "shard-{}-of-{}.json",
            options.shard.index, options.shard.count
        )
    } else {
        "run.json".to_owned()
    };
    let record = ctx
        .dataset
        .join(RUN_DIR)
        .join("runs")
        .join(stage.name())
        .join(name);
    write_run_record(&record, &report.record);
    Ok(report)
}

/// Runs a dataset-level stage, prints its summary, and gives the exit code (its preflight is
/// the caller's: `mesa run` checks every stage before the first runs).
pub fn run_and_report_dataset(
    stage: &dyn DatasetStage,
    ctx: &StageContext<'_>,
    options: &RunOptions,
) -> anyhow::Result<std::process::ExitCode> {
    let report = run_dataset_stage(stage, ctx, options)?;
    eprint!("{}", report.text);
    Ok(crate::exit::code(report.success))
}
