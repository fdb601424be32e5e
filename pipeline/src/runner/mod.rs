//! The stage runner: a stage says how it lists a scene's inputs and how it processes one
//! scene; the runner owns everything else.
//!
//! - scene discovery under `scenes/<table_type>/<scene_id>/`, sorted, filtered by `--scenes`,
//!   sharded (`--shard I/N`: scene k of the sorted list when k mod N = I);
//! - rayon parallelism with `--jobs` threads (results collected in scene order, so the summary
//!   and every file are the same for any thread count);
//! - skip-done: a done marker records the digests of the scene's inputs and of the stage's
//!   configuration; a rerun skips scenes whose marker still matches, redoes changed ones, and
//!   `--force` redoes all;
//! - atomic writes: a stage returns its files in memory; the runner writes them only when the
//!   scene succeeded, each through a temporary file and a rename, and the done marker last
//!   (datatrove's rule: a relaunch trusts only completed markers);
//! - a failing (or panicking) scene gets a failed marker with the error chain and leaves no
//!   output; the other scenes go on;
//! - the stage lifecycle: [`SceneStage::preflight`] before any work (bad settings fail in the
//!   first second), [`SceneStage::prepare`] once before the scenes, [`SceneStage::finish`]
//!   once after the last (a dataset summary);
//! - one thread pool and one progress display per stage run, for per-scene stages and for the
//!   dataset-level stages of [`dataset`] alike.
//!
//! The datatrove executor is the model: a stage says what one unit of work is; the runner owns
//! pools, progress, summaries, markers and skip-done.

pub mod dataset;

use std::collections::BTreeMap;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Component, Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context as _;
use mesa_schemas::artifacts::{MarkerStatus, RunMarker, MARKER_SCHEMA};
use mesa_schemas::json::to_sorted_pretty;
use rayon::prelude::*;
use serde::Serialize;

use crate::config::{Config, ProgressMode};
use crate::exit::UsageError;
use crate::fsio::{sha256_hex, sweep_tmp_for, write_atomic, DigestCache};
use crate::progress::{Progress, Tick};

pub use self::dataset::{run_dataset_stage, DatasetReport, DatasetStage, Executor};
/// The folder of run records inside a dataset.
pub use mesa_stages::paths::dataset::RUN_DIR;

/// One scene of a dataset.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct Scene {
    /// The table type folder, like `office_table`.
    pub table_type: String,
    /// The scene id, like `office_table_0001`.
    pub scene_id: String,
    /// The scene folder.
    pub dir: PathBuf,
}

impl Scene {
    /// `<table_type>/<scene_id>`, the scene's name in markers, globs and summaries.
    pub fn key(&self) -> String {
        format!("{}/{}", self.table_type, self.scene_id)
    }

    /// A path inside the scene folder, relative to the dataset: `scenes/<t>/<s>/<rel>`.
    pub fn rel(&self, rel: &str) -> String {
        format!("scenes/{}/{}/{rel}", self.table_type, self.scene_id)
    }

    /// A path inside the scene folder.
    pub fn path(&self, rel: &str) -> PathBuf {
        self.dir.join(rel)
    }
}

/// What a stage sees besides the scene.
#[derive(Debug, Clone, Copy)]
pub struct StageContext<'a> {
    /// The dataset folder.
    pub dataset: &'a Path,
    /// The resolved configuration.
    pub config: &'a Config,
}

/// The files a stage produced for one scene, written by the runner only if the scene succeeds.
#[derive(Debug, Default)]
pub struct SceneOutput {
    files: BTreeMap<String, Vec<u8>>,
    warnings: Vec<String>,
}

impl SceneOutput {
    /// An empty output.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a file at `rel` (relative to the scene folder).
    pub fn add_file(&mut self, rel: impl Into<String>, bytes: Vec<u8>) {
        self.files.insert(rel.into(), bytes);
    }

    /// Adds a JSON file with sorted keys.
    pub fn add_json<T: Serialize + ?Sized>(
        &mut self,
        rel: impl Into<String>,
        value: &T,
    ) -> anyhow::Result<()> {
        let rel = rel.into();
        let bytes = to_sorted_pretty(value).with_context(|| format!("serialising {rel}"))?;
        self.files.insert(rel, bytes);
        Ok(())
    }

    /// Records a warning about this scene (kept in its done marker and counted in the summary).
    pub fn warn(&mut self, message: impl Into<String>) {
        self.warnings.push(message.into());
    }

    /// The files, by path relative to the scene folder.
    pub fn files(&self) -> &BTreeMap<String, Vec<u8>> {
        &self.files
    }
}

/// A per-scene stage.
pub trait SceneStage: Sync {
    /// The stage name (the subcommand), like `graph`.
    fn name(&self) -> &'static str;

    /// The files this scene's outputs depend on, relative to the dataset folder (use
    /// [`Scene::rel`] for files in the scene). A missing file fails the scene.
    fn inputs(&self, ctx: &StageContext<'_>, scene: &Scene) -> anyhow::Result<Vec<String>>;

    /// A digest of every configuration value that changes this stage's outputs.
    fn config_digest(&self, ctx: &StageContext<'_>) -> String;

    /// Processes one scene.
    fn run(&self, ctx: &StageContext<'_>, scene: &Scene) -> anyhow::Result<SceneOutput>;

    /// Why the scene cannot run yet although nothing is wrong with it (a scene awaiting its
    /// annotator), or `None`. A waiting scene is neither run nor failed: it is reported, and
    /// its earlier outputs and marker are left as they are.
    fn waiting(&self, _ctx: &StageContext<'_>, _scene: &Scene) -> Option<String> {
        None
    }

    /// Checks the settings before any work (`mesa run` asks every stage before the first
    /// one runs): a setting that cannot work is a usage error, exit code 2.
    fn preflight(&self, _ctx: &StageContext<'_>) -> Result<(), UsageError> {
        Ok(())
    }

    /// Called once before the scenes of a run (load what every scene shares). What fails
    /// here is remembered by the stage and fails each scene that needs it, with its reason.
    fn prepare(&self, _ctx: &StageContext<'_>) {}

    /// Called once after the last scene of a run: a dataset-level step over the scenes'
    /// outputs (check's `qa/summary.json`). Returns lines for the terminal.
    fn finish(&self, _ctx: &StageContext<'_>) -> anyhow::Result<Option<String>> {
        Ok(None)
    }
}

/// The digest of a serialisable configuration section.
pub fn digest_of<T: Serialize>(section: &T) -> String {
    // serde_json output of a struct is deterministic (field order), which is all we need.
    sha256_hex(&serde_json::to_vec(section).unwrap_or_default())
}

/// `--shard I/N`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    /// This shard, from 0.
    pub index: usize,
    /// The number of shards.
    pub count: usize,
}

impl Default for Shard {
    fn default() -> Self {
        Self { index: 0, count: 1 }
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl std::str::FromStr for Shard {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let (i, n) = s
            .split_once('/')
            .ok_or_else(|| format!("shard \"{s}\" is not I/N (expected like 0/4)"))?;
        let index: usize = i
            .trim()
            .parse()
            .map_err(|_| format!("shard index \"{i}\" is not a number (expected like 0/4)"))?;
        let count: usize = n
            .trim()
            .parse()
            .map_err(|_| format!("shard count \"{n}\" is not a number (expected like 0/4)"))?;
        if count == 0 || index >= count {
            return Err(format!(
                "shard {index}/{count} is out of range (expected 0 <= I < N)"
            ));
        }
        Ok(Self { index, count })
    }
}

impl Shard {
    /// The shard of a Slurm array task: `SLURM_ARRAY_TASK_ID - SLURM_ARRAY_TASK_MIN` of
    /// `SLURM_ARRAY_TASK_COUNT`; `None` outside an array job.
    pub fn from_slurm_env() -> Result<Option<Self>, String> {
        Self::from_vars(|name| std::env::var(name).ok())
    }

    fn from_vars(var: impl Fn(&str) -> Option<String>) -> Result<Option<Self>, String> {
        let Some(id) = var("SLURM_ARRAY_TASK_ID") else {
            return Ok(None);
        };
        let parse = |name: &str, value: String| {
            value
                .trim()
                .parse::<usize>()
                .map_err(|_| format!("{name}=\"{value}\" is not a number"))
        };
        let id = parse("SLURM_ARRAY_TASK_ID", id)?;
        let count = var("SLURM_ARRAY_TASK_COUNT").ok_or(
            "SLURM_ARRAY_TASK_ID is set but SLURM_ARRAY_TASK_COUNT is not \
             (pass --shard I/N explicitly)",
        )?;
        let count = parse("SLURM_ARRAY_TASK_COUNT", count)?;
        let min = match var("SLURM_ARRAY_TASK_MIN") {
            Some(min) => parse("SLURM_ARRAY_TASK_MIN", min)?,
            None => 0,
        };
        let index = id.checked_sub(min).ok_or_else(|| {
            format!("SLURM_ARRAY_TASK_ID {id} is below SLURM_ARRAY_TASK_MIN {min}")
        })?;
        format!("{index}/{count}").parse().map(Some)
    }

    /// Whether scene number `k` of the sorted list belongs to this shard.
    pub fn owns(&self, k: usize) -> bool {
        k % self.count == self.index
    }
}

/// How a stage run is asked to go.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// Only scenes whose `<table_type>/<scene_id>` or `<scene_id>` matches this glob.
    pub scenes: Option<String>,
    /// Worker threads (0 = one per core).
    pub jobs: usize,
    /// The shard of the scene list to process.
    pub shard: Shard,
    /// Redo scenes even when their done marker matches.
    pub force: bool,
    /// Progress display.
    pub progress: ProgressMode,
    /// Seconds between progress lines.
    pub progress_interval: Duration,
    /// Only errors and the summary (`--quiet`): no progress, no closing lines of
    /// [`SceneStage::finish`].
    pub quiet: bool,
    /// When set, only these scenes (`<table_type>/<scene_id>`) of the selection run; the
    /// others are left alone (`mesa tasks` with offline batches runs the scenes whose replies
    /// are all in).
    pub only: Option<std::collections::BTreeSet<String>>,
}

impl RunOptions {
    /// Options from the configuration's `[run]` section, no filter, one shard.
    pub fn from_config(config: &Config) -> Self {
        Self {
            scenes: None,
            jobs: config.run.jobs,
            shard: Shard::default(),
            force: false,
            progress: config.run.progress,
            progress_interval: Duration::from_secs_f64(config.run.progress_interval_s.max(0.1)),
            quiet: false,
            only: None,
        }
    }
}

/// Errors that stop a whole stage run (bad usage or a dataset that is not one).
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The folder has no `scenes/`.
    #[error("{0}: not a mesa dataset: it has no scenes/ folder (expected DATASET/scenes/<table_type>/<scene_id>/; `mesa demo DIR` writes one)")]
    NotADataset(PathBuf),
    /// The `--scenes` glob is malformed.
    #[error("--scenes \"{glob}\": {message} (expected a glob like \"office_table/*\" or \"*_00[0-4]?\")")]
    BadGlob {
        /// The glob.
        glob: String,
        /// The parser's message.
        message: String,
    },
    /// The thread pool could not start.
    #[error("cannot start {jobs} worker threads: {message}")]
    Threads {
        /// Requested threads.
        jobs: usize,
        /// The error.
        message: String,
    },
    /// I/O on the dataset folder failed.
    #[error("{path}: {source}")]
    Io {
        /// The path.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
}

impl RunError {
    /// As an error of a command: a folder that is no dataset and a bad glob are usage errors
    /// (exit code 2); threads and I/O are not.
    pub fn into_anyhow(self) -> anyhow::Error {
        match self {
            Self::NotADataset(_) | Self::BadGlob { .. } => UsageError(self.to_string()).into(),
            Self::Threads { .. } | Self::Io { .. } => self.into(),
        }
    }
}

/// Lists the scenes of a dataset, sorted by table type then scene id.
pub fn discover_scenes(dataset: &Path) -> Result<Vec<Scene>, RunError> {
    let root = dataset.join(mesa_stages::paths::dataset::SCENES);
    if !root.is_dir() {
        return Err(RunError::NotADataset(dataset.to_owned()));
    }
    let io = |path: &Path| {
        let path = path.to_owned();
        move |source| RunError::Io { path, source }
    };
    let mut scenes = Vec::new();
    for table in std::fs::read_dir(&root).map_err(io(&root))? {
        let table = table.map_err(io(&root))?;
        let table_name = table.file_name().to_string_lossy().into_owned();
        if table_name.starts_with('.') || !table.path().is_dir() {
            continue;
        }
        for scene in std::fs::read_dir(table.path()).map_err(io(&table.path()))? {
            let scene = scene.map_err(io(&table.path()))?;
            let scene_name = scene.file_name().to_string_lossy().into_owned();
            if scene_name.starts_with('.') || !scene.path().is_dir() {
                continue;
            }
            scenes.push(Scene {
                table_type: table_name.clone(),
                scene_id: scene_name,
                dir: scene.path(),
            });
        }
    }
    scenes.sort();
    Ok(scenes)
}

/// Filters scenes by glob, then keeps this shard's share of the sorted list.
pub fn select_scenes(
    scenes: Vec<Scene>,
    glob: Option<&str>,
    shard: Shard,
) -> Result<Vec<Scene>, RunError> {
    let matcher = match glob {
        Some(glob) => Some(
            globset::GlobBuilder::new(glob)
                .literal_separator(false)
                .build()
                .map_err(|e| RunError::BadGlob {
                    glob: glob.to_owned(),
                    message: e.kind().to_string(),
                })?
                .compile_matcher(),
        ),
        None => None,
    };
    Ok(scenes
        .into_iter()
        .filter(|s| {
            matcher
                .as_ref()
                .is_none_or(|m| m.is_match(s.key()) || m.is_match(&s.scene_id))
        })
        .enumerate()
        .filter(|(k, _)| shard.owns(*k))
        .map(|(_, s)| s)
        .collect())
}

/// What happened to one scene.
#[derive(Debug, Clone, PartialEq)]
pub enum SceneOutcome {
    /// Processed and written.
    Done {
        /// Warnings the stage reported.
        warnings: Vec<String>,
    },
    /// Its done marker still matched.
    Skipped,
    /// Failed; nothing of this run was written.
    Failed {
        /// The error chain, outermost first.
        error: Vec<String>,
    },
    /// Not run: it waits for something outside mesa (see [`SceneStage::waiting`]).
    Waiting {
        /// What it waits for.
        reason: String,
    },
}

/// The result of running a stage over a dataset (one shard of it).
#[derive(Debug, Clone, Serialize)]
pub struct StageSummary {
    /// The stage.
    pub stage: String,
    /// The shard.
    pub shard: String,
    /// Scenes this run considered.
    pub scenes: usize,
    /// Scenes processed.
    pub done: usize,
    /// Scenes skipped (still done).
    pub skipped: usize,
    /// Scenes that failed, with their error chain.
    pub failed: Vec<(String, Vec<String>)>,
    /// Warnings, by scene.
    pub warnings: Vec<(String, String)>,
    /// Scenes that wait for something outside mesa (an annotator), with what they wait for.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub waiting: Vec<(String, String)>,
    /// Wall time in seconds.
    pub elapsed_s: f64,
    /// The lines of [`SceneStage::finish`] for the terminal.
    #[serde(skip)]
    pub closing: Option<String>,
}

impl StageSummary {
    /// Whether every scene is done.
    pub fn success(&self) -> bool {
        self.failed.is_empty()
    }
}

/// Where a stage's marker for a scene lives.
pub fn marker_path(dataset: &Path, stage: &str, scene: &Scene) -> PathBuf {
    dataset
        .join(RUN_DIR)
        .join("markers")
        .join(stage)
        .join(&scene.table_type)
        .join(format!("{}.json", scene.scene_id))
}

/// Reads a marker; `None` when absent or unreadable (an unreadable marker means "redo").
pub fn read_marker(path: &Path) -> Option<RunMarker> {
    let text = std::fs::read_to_string(path).ok()?;
    serde_json::from_str(&text).ok()
}

/// The state of a scene for a stage, as `mesa status` reports it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SceneState {
    /// Done, and the marker still matches inputs, config and outputs.
    Done,
    /// Done once, but something changed since (the reason).
    Stale(String),
    /// Failed (the first line of the error).
    Failed(String),
    /// Never run.
    Pending,
    /// Cannot run yet (the reason): it waits for something outside mesa.
    Waiting(String),
}

struct Prepared {
    inputs: BTreeMap<String, String>,
    previous: Option<RunMarker>,
}

fn prepare(
    stage: &dyn SceneStage,
    ctx: &StageContext<'_>,
    scene: &Scene,
    cache: &DigestCache,
) -> anyhow::Result<Prepared> {
    let previous = read_marker(&marker_path(ctx.dataset, stage.name(), scene));
    let listed = stage.inputs(ctx, scene)?;
    let scene_prefix = scene.rel("");
    let mut inputs = BTreeMap::new();
    for rel in listed {
        let path = ctx.dataset.join(&rel);
        let shared = !rel.starts_with(&scene_prefix);
        let digest = cache.digest(&path, shared).map_err(|e| {
            if e.kind() == std::io::ErrorKind::NotFound {
                anyhow::anyhow!(
                    "{}: missing input of `mesa {}` (run the stage that writes it first)",
                    path.display(),
                    stage.name()
                )
            } else {
                anyhow::anyhow!("{}: cannot read input: {e}", path.display())
            }
        })?;
        inputs.insert(rel, digest);
    }
    Ok(Prepared { inputs, previous })
}

/// Why a done marker no longer holds, or `None` when it does.
fn staleness(
    marker: &RunMarker,
    inputs: &BTreeMap<String, String>,
    config_digest: &str,
    dataset: &Path,
) -> Option<String> {
    if marker.status != MarkerStatus::Done {
        return Some("failed last time".to_owned());
    }
    if marker.config_digest != config_digest {
        return Some("configuration changed".to_owned());
    }
    if &marker.inputs != inputs {
        let changed: Vec<&str> = inputs
            .iter()
            .filter(|(k, v)| marker.inputs.get(*k) != Some(v))
            .map(|(k, _)| k.as_str())
            .chain(
                marker
                    .inputs
                    .keys()
                    .filter(|k| !inputs.contains_key(*k))
                    .map(String::as_str),
            )
            .collect();
        return Some(format!("inputs changed: {}", changed.join(", ")));
    }
    if let Some(missing) = marker.outputs.keys().find(|k| !dataset.join(k).exists()) {
        return Some(format!("output {missing} is missing"));
    }
    None
}

/// The state of one scene for one stage (hashes the scene's inputs).
pub fn scene_state(
    stage: &dyn SceneStage,
    ctx: &StageContext<'_>,
    scene: &Scene,
    config_digest: &str,
    cache: &DigestCache,
) -> SceneState {
    if let Some(reason) = stage.waiting(ctx, scene) {
        return SceneState::Waiting(reason);
    }
    let Some(marker) = read_marker(&marker_path(ctx.dataset, stage.name(), scene)) else {
        return SceneState::Pending;
    };
    if marker.status == MarkerStatus::Failed {
        return SceneState::Failed(marker.error.first().cloned().unwrap_or_default());
    }
    match prepare(stage, ctx, scene, cache) {
        Err(e) => SceneState::Stale(format!("{e:#}")),
        Ok(prepared) => match staleness(&marker, &prepared.inputs, config_digest, ctx.dataset) {
            None => SceneState::Done,
            Some(reason) => SceneState::Stale(reason),
        },
    }
}

fn check_output_path(rel: &str) -> anyhow::Result<()> {
    let path = Path::new(rel);
    let ok = !rel.is_empty() && path.components().all(|c| matches!(c, Component::Normal(_)));
    anyhow::ensure!(
        ok,
        "internal error: stage output path \"{rel}\" is not a relative path inside the scene"
    );
    Ok(())
}

fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_owned()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "unknown panic".to_owned()
    }
}

fn error_chain(e: &anyhow::Error) -> Vec<String> {
    e.chain().map(|c| c.to_string()).collect()
}

/// Processes one scene: skip, run and write, or record the failure.
pub fn process_scene(
    stage: &dyn SceneStage,
    ctx: &StageContext<'_>,
    scene: &Scene,
    config_digest: &str,
    force: bool,
    cache: &DigestCache,
) -> SceneOutcome {
    if let Some(reason) = stage.waiting(ctx, scene) {
        return SceneOutcome::Waiting { reason };
    }
    let marker_file = marker_path(ctx.dataset, stage.name(), scene);
    let mut base = RunMarker {
        schema: MARKER_SCHEMA.to_owned(),
        stage: stage.name().to_owned(),
        scene: scene.key(),
        status: MarkerStatus::Failed,
        mesa_version: env!("CARGO_PKG_VERSION").to_owned(),
        config_digest: config_digest.to_owned(),
        inputs: BTreeMap::new(),
        outputs: BTreeMap::new(),
        warnings: Vec::new(),
        error: Vec::new(),
    };
    let prepared = match prepare(stage, ctx, scene, cache) {
        Ok(p) => p,
        Err(e) => {
            let previous = read_marker(&marker_file);
            return fail(ctx, &marker_file, base, previous.as_ref(), error_chain(&e));
        }
    };
    base.inputs = prepared.inputs.clone();
    if !force {
        if let Some(previous) = &prepared.previous {
            if staleness(previous, &prepared.inputs, config_digest, ctx.dataset).is_none() {
                return SceneOutcome::Skipped;
            }
        }
    }
    let result = catch_unwind(AssertUnwindSafe(|| stage.run(ctx, scene)));
    let output = match result {
        Ok(Ok(output)) => output,
        Ok(Err(e)) => {
            return fail(
                ctx,
                &marker_file,
                base,
                prepared.previous.as_ref(),
                error_chain(&e),
            )
        }
        Err(payload) => {
            let error = vec![
                format!("internal error: {}", panic_message(payload.as_ref())),
                "this is a bug in mesa: please report it with this scene's inputs".to_owned(),
            ];
            return fail(ctx, &marker_file, base, prepared.previous.as_ref(), error);
        }
    };
    match write_outputs(ctx, scene, &output, prepared.previous.as_ref()) {
        Ok(outputs) => {
            base.status = MarkerStatus::Done;
            base.outputs = outputs;
            base.warnings = output.warnings.clone();
            match write_marker(&marker_file, &base) {
                Ok(()) => SceneOutcome::Done {
                    warnings: output.warnings,
                },
                Err(e) => SceneOutcome::Failed {
                    error: vec![format!(
                        "{}: cannot write marker: {e}",
                        marker_file.display()
                    )],
                },
            }
        }
        Err(e) => fail(
            ctx,
            &marker_file,
            base,
            prepared.previous.as_ref(),
            error_chain(&e),
        ),
    }
}

fn write_outputs(
    ctx: &StageContext<'_>,
    scene: &Scene,
    output: &SceneOutput,
    previous: Option<&RunMarker>,
) -> anyhow::Result<BTreeMap<String, String>> {
    let mut written = BTreeMap::new();
    for (rel, bytes) in &output.files {
        check_output_path(rel)?;
        let path = scene.path(rel);
        sweep_tmp_for(&path).with_context(|| format!("{}: sweeping", path.display()))?;
        write_atomic(&path, bytes).with_context(|| format!("{}: cannot write", path.display()))?;
        written.insert(scene.rel(rel), sha256_hex(bytes));
    }
    // Outputs of an earlier run that this run no longer writes would be stale.
    if let Some(previous) = previous {
        for rel in previous.outputs.keys() {
            if !written.contains_key(rel) {
                let _ = std::fs::remove_file(ctx.dataset.join(rel));
            }
        }
    }
    Ok(written)
}

fn fail(
    ctx: &StageContext<'_>,
    marker_file: &Path,
    mut marker: RunMarker,
    previous: Option<&RunMarker>,
    error: Vec<String>,
) -> SceneOutcome {
    // The outputs of an earlier success no longer match this scene's inputs: remove them so
    // that nothing downstream reads them as current.
    if let Some(previous) = previous.filter(|p| p.status == MarkerStatus::Done) {
        for rel in previous.outputs.keys() {
            let _ = std::fs::remove_file(ctx.dataset.join(rel));
        }
    }
    marker.status = MarkerStatus::Failed;
    marker.error = error.clone();
    if let Err(e) = write_marker(marker_file, &marker) {
        let mut error = error;
        error.push(format!(
            "{}: cannot write marker: {e}",
            marker_file.display()
        ));
        return SceneOutcome::Failed { error };
    }
    SceneOutcome::Failed { error }
}

fn write_marker(path: &Path, marker: &RunMarker) -> std::io::Result<()> {
    let bytes = to_sorted_pretty(marker).map_err(std::io::Error::other)?;
    sweep_tmp_for(path)?;
    write_atomic(path, &bytes)
}

/// The worker threads of a stage run: every stage, per-scene or dataset-level, runs on one of
/// these (named `mesa-worker-<i>`: a panic there is caught and reported with its scene or
/// asset, not printed with a backtrace).
pub fn thread_pool(jobs: usize) -> Result<rayon::ThreadPool, RunError> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(jobs)
        .thread_name(|i| format!("mesa-worker-{i}"))
        .build()
        .map_err(|e| RunError::Threads {
            jobs,
            message: e.to_string(),
        })
}

/// The progress display of a stage run with `options`.
pub fn progress(name: &str, unit: &'static str, total: usize, options: &RunOptions) -> Progress {
    let mode = if options.quiet {
        ProgressMode::Off
    } else {
        options.progress
    };
    Progress::new(name, unit, total, mode, options.progress_interval)
}

/// Runs a stage over the selected scenes of a dataset: `prepare`, every scene, then `finish`
/// (whose lines land in [`StageSummary::closing`]).
pub fn run_stage(
    stage: &dyn SceneStage,
    ctx: &StageContext<'_>,
    options: &RunOptions,
) -> anyhow::Result<StageSummary> {
    let started = Instant::now();
    let mut scenes = select_scenes(
        discover_scenes(ctx.dataset).map_err(RunError::into_anyhow)?,
        options.scenes.as_deref(),
        options.shard,
    )
    .map_err(RunError::into_anyhow)?;
    if let Some(only) = &options.only {
        scenes.retain(|s| only.contains(&s.key()));
    }
    let config_digest = stage.config_digest(ctx);
    let cache = DigestCache::default();
    let pool = thread_pool(options.jobs)?;
    let progress = progress(stage.name(), "scenes", scenes.len(), options);
    let outcomes: Vec<SceneOutcome> = pool.install(|| {
        stage.prepare(ctx);
        scenes
            .par_iter()
            .map(|scene| {
                let outcome =
                    process_scene(stage, ctx, scene, &config_digest, options.force, &cache);
                progress.tick(match outcome {
                    SceneOutcome::Skipped => Tick::Skipped,
                    SceneOutcome::Failed { .. } => Tick::Failed,
                    SceneOutcome::Done { .. } | SceneOutcome::Waiting { .. } => Tick::Done,
                });
                outcome
            })
            .collect()
    });
    progress.finish();
    let mut summary = StageSummary {
        stage: stage.name().to_owned(),
        shard: options.shard.to_string(),
        scenes: scenes.len(),
        done: 0,
        skipped: 0,
        failed: Vec::new(),
        warnings: Vec::new(),
        waiting: Vec::new(),
        elapsed_s: 0.0,
        closing: None,
    };
    for (scene, outcome) in scenes.iter().zip(outcomes) {
        match outcome {
            SceneOutcome::Done { warnings } => {
                summary.done += 1;
                summary
                    .warnings
                    .extend(warnings.into_iter().map(|w| (scene.key(), w)));
            }
            SceneOutcome::Skipped => summary.skipped += 1,
            SceneOutcome::Failed { error } => summary.failed.push((scene.key(), error)),
            SceneOutcome::Waiting { reason } => summary.waiting.push((scene.key(), reason)),
        }
    }
    summary.elapsed_s = started.elapsed().as_secs_f64();
    let record = ctx
        .dataset
        .join(RUN_DIR)
        .join("runs")
        .join(stage.name())
        .join(format!(
            "shard-{}-of-{}.json",
            options.shard.index, options.shard.count
        ));
    write_run_record(&record, &summary);
    summary.closing = stage.finish(ctx)?;
    Ok(summary)
}

/// Writes a run record (informational: failing to write it must not fail the run).
pub(crate) fn write_run_record<T: Serialize>(path: &Path, summary: &T) {
    if let Ok(bytes) = to_sorted_pretty(summary) {
        if let Err(e) = write_atomic(path, &bytes) {
            tracing::warn!("{}: cannot write run record: {e}", path.display());
        }
    }
}

/// Runs a per-scene stage with resolved options, prints its summary (and its closing lines
/// unless quiet), and gives the exit code: 1 when a scene failed.
pub fn run_and_report(
    stage: &dyn SceneStage,
    ctx: &StageContext<'_>,
    options: &RunOptions,
) -> anyhow::Result<std::process::ExitCode> {
    let summary = run_stage(stage, ctx, options)?;
    eprint!("{}", format_summary(&summary));
    if let (Some(lines), false) = (&summary.closing, options.quiet) {
        eprint!("{lines}");
    }
    Ok(crate::exit::code(summary.success()))
}

/// The human summary of a stage run, as printed at the end.
pub fn format_summary(summary: &StageSummary) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    let shard = if summary.shard == "0/1" {
        String::new()
    } else {
        format!(" (shard {})", summary.shard)
    };
    let waiting = if summary.waiting.is_empty() {
        String::new()
    } else {
        format!(", {} waiting", summary.waiting.len())
    };
    let _ = writeln!(
        out,
        "{}{shard}: {} scenes: {} done, {} skipped, {} failed{waiting}, {} warnings in {:.2} s",
        summary.stage,
        summary.scenes,
        summary.done,
        summary.skipped,
        summary.failed.len(),
        summary.warnings.len(),
        summary.elapsed_s
    );
    for (scene, error) in &summary.failed {
        let _ = writeln!(out, "  failed {scene}: {}", error.join(": "));
    }
    const SHOWN: usize = 10;
    for (scene, reason) in summary.waiting.iter().take(SHOWN) {
        let _ = writeln!(out, "  waiting {scene}: {reason}");
    }
    if summary.waiting.len() > SHOWN {
        let _ = writeln!(
            out,
            "  ... and {} more waiting (`mesa status` lists them)",
            summary.waiting.len() - SHOWN
        );
    }
    for (scene, warning) in summary.warnings.iter().take(SHOWN) {
        let _ = writeln!(out, "  warning {scene}: {warning}");
    }
    if summary.warnings.len() > SHOWN {
        let _ = writeln!(
            out,
            "  ... and {} more warnings (in the done markers under .mesa/markers/{}/)",
            summary.warnings.len() - SHOWN,
            summary.stage
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_parse_and_partition() {
        assert_eq!("1/3".parse::<Shard>(), Ok(Shard { index: 1, count: 3 }));
        assert!("3/3".parse::<Shard>().is_err());
        assert!("x/3".parse::<Shard>().is_err());
        assert!("1".parse::<Shard>().is_err());
        let shards: Vec<Shard> = (0..3).map(|i| Shard { index: i, count: 3 }).collect();
        for k in 0..100 {
            assert_eq!(shards.iter().filter(|s| s.owns(k)).count(), 1);
        }
    }

    #[test]
    fn slurm_variables_give_the_shard() {
        let vars = |pairs: &'static [(&'static str, &'static str)]| {
            move |name: &str| {
                pairs
                    .iter()
                    .find(|(k, _)| *k == name)
                    .map(|(_, v)| (*v).to_owned())
            }
        };
        assert_eq!(Shard::from_vars(vars(&[])), Ok(None));
        assert_eq!(
            Shard::from_vars(vars(&[
                ("SLURM_ARRAY_TASK_ID", "2"),
                ("SLURM_ARRAY_TASK_COUNT", "4")
            ])),
            Ok(Some(Shard { index: 2, count: 4 }))
        );
        // `--array=1-4` numbers tasks from 1.
        assert_eq!(
            Shard::from_vars(vars(&[
                ("SLURM_ARRAY_TASK_ID", "4"),
                ("SLURM_ARRAY_TASK_COUNT", "4"),
                ("SLURM_ARRAY_TASK_MIN", "1")
            ])),
            Ok(Some(Shard { index: 3, count: 4 }))
        );
        assert!(Shard::from_vars(vars(&[("SLURM_ARRAY_TASK_ID", "2")])).is_err());
    }

    #[test]
    fn output_paths_must_stay_inside_the_scene() {
        assert!(check_output_path("graph/graph.json").is_ok());
        assert!(check_output_path("../x").is_err());
        assert!(check_output_path("/etc/passwd").is_err());
        assert!(check_output_path("").is_err());
    }
}
