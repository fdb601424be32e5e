//! The stage runner: a stage says how it lists a scene's inputs and how it processes one
//! scene; the runner owns everything else.
//!
//! - scene discovery under `scenes/<table_type>/<scene_id>/`, sorted, filtered by `--scenes`,
//!   sharded (`--shard I/N`: scene k of the sorted list when k mod N = I);
//! - rayon parallelism with `--jobs` threads (results collected in scene order, so the summary
//!   and every file are the same for any thread count);
//! - skip-done: a done marker records the digests of the scene's inputs and of the stage's
//!   configuration; a rerun skips scenes whose marker still matches, redoes changed ones, and
//!   `--force` redoes all; the digest of a large input (and, in a forced rerun, of a small
//!   one or of an output that comes out the same) that has not changed since it was last
//!   hashed is taken from `.mesa/digests/` ([`digests`]), not hashed again;
//! - atomic writes: a stage returns its files in memory; the runner writes them only when the
//!   scene succeeded, each through a temporary file and a rename, and the done marker last
//!   (datatrove's rule: a relaunch trusts only completed markers);
//! - a failing (or panicking) scene gets a failed marker with the error chain and leaves no
//!   output; the other scenes go on;
//! - the stage lifecycle: [`SceneStage::preflight`] before any work (bad settings fail in the
//!   first second), [`SceneStage::prepare`] once before the scenes, [`SceneStage::finish`]
//!   once after the last (a dataset summary);
//! - one writer per stage and dataset: a run holds `.mesa/locks/<stage>.lock` ([`lock`]);
//! - one thread pool and one progress display per stage run, for per-scene stages and for the
//!   dataset-level stages of [`dataset`] alike.
//!
//! The datatrove executor is the model: a stage says what one unit of work is; the runner owns
//! pools, progress, summaries, markers and skip-done.

mod core;
pub mod dataset;
pub mod digests;
pub mod lock;
mod scene;
pub mod scene_files;

pub use self::core::{
    digest_of, discover_all, discover_scenes, progress, read_marker, select_scenes, thread_pool,
    RunError, RunOptions, Scene, Shard, SkippedFolder, StageContext, MAX_SCENE_NAME_BYTES, RUN_DIR,
};
pub use self::dataset::{run_dataset_stage, DatasetReport, DatasetStage, Executor};
pub use self::scene::{
    format_summary, marker_path, process_scene, run_and_report, run_stage, scene_state,
    FailureOutputs, SceneOutcome, SceneOutput, SceneStage, SceneState, StageSummary,
};
