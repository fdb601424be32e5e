//! Per-scene stages: the [`SceneStage`] lifecycle, skip-done markers, atomic outputs, failed
//! markers, the run over a dataset's scenes and its summary.

use std::collections::BTreeMap;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Component, Path, PathBuf};
use std::time::{Instant, SystemTime};

use anyhow::Context as _;
use mesa_schemas::artifacts::{MarkerStatus, RunMarker, MARKER_SCHEMA};
use mesa_schemas::json::to_sorted_pretty;
use rayon::prelude::*;
use serde::Serialize;

use super::core::{
    discover_all, progress, read_marker, select_scenes, thread_pool, write_run_record, RunError,
    RunOptions, Scene, StageContext, MARKER_LIMIT, RUN_DIR,
};
use super::digests::{FolderLook, RememberedDigests};
use super::scene_files;
use crate::exit::UsageError;
use crate::fsio::{
    open_own_file, read_own_small, sha256_hex, sweep_dead_tmp_in, sweep_tmp_for, write_atomic,
    write_if_changed, write_if_changed_kept, DigestCache,
};
use crate::progress::Tick;

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

/// A scene failure that still leaves files: what the stage kept before it failed (the
/// rejected replies a `tasks` error names), written before the failure is recorded, and
/// whether the outputs of the scene's last success stay (a failed rerun of `tasks` does not
/// take the previous `tasks.jsonl` away). A stage returns it as its error
/// (`anyhow::Error::new(failure)`); its message and causes are those of the error it wraps.
#[derive(Debug)]
pub struct FailureOutputs {
    files: BTreeMap<String, Vec<u8>>,
    keep_previous: bool,
    error: anyhow::Error,
}

impl FailureOutputs {
    /// The failure `error`, with no file yet.
    pub fn new(error: anyhow::Error) -> Self {
        Self {
            files: BTreeMap::new(),
            keep_previous: false,
            error,
        }
    }

    /// Adds a file at `rel` (relative to the scene folder), written although the scene failed.
    pub fn add_file(&mut self, rel: impl Into<String>, bytes: Vec<u8>) {
        self.files.insert(rel.into(), bytes);
    }

    /// Keeps the outputs of the last success (those the failure does not rewrite).
    pub fn keep_previous_outputs(mut self) -> Self {
        self.keep_previous = true;
        self
    }
}

impl std::fmt::Display for FailureOutputs {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        std::fmt::Display::fmt(&*self.error, f)
    }
}

impl std::error::Error for FailureOutputs {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        self.error.source()
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

    /// Whether this stage makes what comes before the refined layout (lift, retrieve, place,
    /// pack, the annotator, ingest): a scene imported at the refined stage (`mesa import`,
    /// [`Scene::imported`]) does not need it, and the runner leaves it out, counted apart.
    fn before_refined(&self) -> bool {
        false
    }

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
    /// Scenes imported at the refined stage that this stage (before it) left out.
    #[serde(skip_serializing_if = "is_zero")]
    pub imported: usize,
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

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// Where a stage's marker for a scene lives.
pub fn marker_path(dataset: &Path, stage: &str, scene: &Scene) -> PathBuf {
    per_scene_file(dataset, "markers", stage, scene, "json")
}

/// `.mesa/<folder>/<stage>/<table_type>/<scene_id>.<extension>`: how the runner lays out its
/// files of a stage and scene.
fn per_scene_file(
    dataset: &Path,
    folder: &str,
    stage: &str,
    scene: &Scene,
    extension: &str,
) -> PathBuf {
    dataset
        .join(RUN_DIR)
        .join(folder)
        .join(stage)
        .join(&scene.table_type)
        .join(format!("{}.{extension}", scene.scene_id))
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
    /// Imported at the refined stage: this stage, which comes before it, does not apply.
    Imported,
}

struct Prepared {
    inputs: BTreeMap<String, String>,
    previous: Option<RunMarker>,
    /// The digests remembered for the scene, with what hashing the inputs added; written back
    /// by [`save_remembered`] after the scene (a run does; `mesa status`, which holds no lock,
    /// only reads them).
    remembered: RememberedDigests,
}

/// Where the digests of a scene's files are remembered for a stage ([`digests`]).
///
/// [`digests`]: super::digests
pub fn digests_path(dataset: &Path, stage: &str, scene: &Scene) -> PathBuf {
    per_scene_file(dataset, "digests", stage, scene, "txt")
}

/// The scene's previous marker and the digests of its inputs. `forced`: a forced run, which on a
/// scene done before looks up and remembers its small files' digests too ([`digests`]).
///
/// [`digests`]: super::digests
fn prepare(
    stage: &dyn SceneStage,
    ctx: &StageContext<'_>,
    scene: &Scene,
    cache: &DigestCache,
    forced: bool,
) -> anyhow::Result<Prepared> {
    let previous = read_scene_marker(&marker_path(ctx.dataset, stage.name(), scene));
    let listed = stage.inputs(ctx, scene)?;
    let scene_prefix = scene.rel("");
    let mut remembered = RememberedDigests::at(digests_path(ctx.dataset, stage.name(), scene));
    if forced
        && previous
            .as_ref()
            .is_some_and(|m| m.status == MarkerStatus::Done)
    {
        remembered = remembered.for_rerun();
    }
    let now = SystemTime::now();
    let mut inputs = BTreeMap::new();
    for rel in listed {
        let path = ctx.dataset.join(&rel);
        let digest = if rel.starts_with(&scene_prefix) {
            remembered.digest(&path, &rel, now)
        } else {
            cache.digest(&path)
        };
        let digest = digest.map_err(|e| {
            if e.kind() == std::io::ErrorKind::NotFound {
                missing_input(&path, &rel, stage.name())
            } else {
                anyhow::anyhow!("{}: cannot read input: {e}", path.display())
            }
        })?;
        inputs.insert(rel, digest);
    }
    Ok(Prepared {
        inputs,
        previous,
        remembered,
    })
}

/// Writes back the digests remembered for a scene, keeping only those of its `inputs` and of
/// the `outputs` this run wrote or kept.
fn save_remembered(
    mut remembered: RememberedDigests,
    inputs: &BTreeMap<String, String>,
    outputs: Option<&BTreeMap<String, String>>,
) {
    remembered.retain(|rel| {
        inputs.contains_key(rel)
            || outputs.is_some_and(|outputs| {
                outputs.contains_key(rel)
                    // An output folder's entry (`look_at_folder`): a folder an output is in.
                    || rel.ends_with('/')
                        && outputs.keys().any(|output| {
                            output
                                .strip_prefix(rel)
                                .is_some_and(|name| !name.contains('/'))
                        })
            })
    });
    // Only a shortcut (see `digests`): a file not written means hashing again next time.
    let _ = remembered.save();
}

/// The error for a declared input that does not exist, with who writes it.
fn missing_input(path: &Path, rel: &str, stage: &str) -> anyhow::Error {
    use mesa_stages::paths::Writer;
    let fix = match mesa_stages::paths::writer_of(rel) {
        Some(Writer::User) => {
            "a raw input: no stage writes it; put it in place (docs/demo.md, \"The inputs, in every form\", lists the \
             inputs of a scene)"
                .to_owned()
        }
        Some(Writer::Annotator) => {
            "the annotator's edited scene: save it from Blender there (`mesa pack` wrote the \
             original)"
                .to_owned()
        }
        Some(Writer::Stage(writer)) => format!("run `mesa {writer}` first"),
        None => "run the stage that writes it first".to_owned(),
    };
    anyhow::anyhow!(
        "{}: missing input of `mesa {stage}` ({fix})",
        path.display()
    )
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
    if stage.before_refined() && scene.imported() {
        return SceneState::Imported;
    }
    if let Some(reason) = stage.waiting(ctx, scene) {
        return SceneState::Waiting(reason);
    }
    let Some(marker) = read_marker(&marker_path(ctx.dataset, stage.name(), scene)) else {
        return SceneState::Pending;
    };
    if marker.status == MarkerStatus::Failed {
        return SceneState::Failed(marker.error.first().cloned().unwrap_or_default());
    }
    match prepare(stage, ctx, scene, cache, false) {
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

/// Processes one scene: skip, run and write, or record the failure. What the runner reads of
/// the scene's files on the way is handed to the stage ([`scene_files`]).
pub fn process_scene(
    stage: &dyn SceneStage,
    ctx: &StageContext<'_>,
    scene: &Scene,
    config_digest: &str,
    force: bool,
    cache: &DigestCache,
) -> SceneOutcome {
    scene_files::within_scene(|| process_scene_here(stage, ctx, scene, config_digest, force, cache))
}

/// [`process_scene`] inside the scene's record of files.
fn process_scene_here(
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
    let Prepared {
        inputs,
        previous,
        mut remembered,
    } = match prepare(stage, ctx, scene, cache, force) {
        Ok(p) => p,
        Err(e) => {
            let previous = read_marker(&marker_file);
            return fail(ctx, scene, &marker_file, base, previous.as_ref(), &e);
        }
    };
    base.inputs = inputs.clone();
    if !force {
        if let Some(previous) = &previous {
            if staleness(previous, &inputs, config_digest, ctx.dataset).is_none() {
                save_remembered(remembered, &inputs, Some(&previous.outputs));
                return SceneOutcome::Skipped;
            }
        }
    }
    let result = match catch_unwind(AssertUnwindSafe(|| stage.run(ctx, scene))) {
        Ok(result) => result,
        Err(payload) => Err(anyhow::anyhow!(
            "this is a bug in mesa: please report it with this scene's inputs"
        )
        .context(format!(
            "internal error: {}",
            panic_message(payload.as_ref())
        ))),
    };
    let output = match result {
        Ok(output) => output,
        Err(e) => {
            save_remembered(remembered, &inputs, None);
            return fail(ctx, scene, &marker_file, base, previous.as_ref(), &e);
        }
    };
    let written = write_outputs(ctx, scene, &output, previous.as_ref(), &mut remembered);
    save_remembered(
        remembered,
        &inputs,
        written.as_ref().ok().map(|(outputs, _)| outputs),
    );
    match written {
        Ok((outputs, removed)) => {
            let mut output = output;
            for rel in removed {
                output.warn(removed_warning(&rel));
            }
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
        Err(e) => fail(ctx, scene, &marker_file, base, previous.as_ref(), &e),
    }
}

/// Writes the outputs a scene's run made (those that come out the same are left as they are),
/// removes those of the last run it no longer makes, and gives the digests of what it wrote
/// or kept, with the outputs it removed.
fn write_outputs(
    ctx: &StageContext<'_>,
    scene: &Scene,
    output: &SceneOutput,
    previous: Option<&RunMarker>,
    remembered: &mut RememberedDigests,
) -> anyhow::Result<(BTreeMap<String, String>, Vec<String>)> {
    let now = SystemTime::now();
    let mut written = BTreeMap::new();
    // Dead writers' temporary files are swept once per output folder (one listing), not once
    // per file; on a forced rerun, not at all from a folder that has not changed since it was
    // last found clean ([`RememberedDigests::look_at_folder`]). Each folder's look, and
    // whether it is still clean (nothing found by the sweep, nothing written in it since).
    let mut folders: BTreeMap<PathBuf, (FolderLook, bool)> = BTreeMap::new();
    for (rel, bytes) in &output.files {
        check_output_path(rel)?;
        let path = scene.path(rel);
        let dir = path.parent().unwrap_or(&path).to_owned();
        let rel = scene.rel(rel);
        if !folders.contains_key(&dir) {
            let folder_rel = match rel.rfind('/') {
                Some(at) => rel[..=at].to_owned(),
                None => String::new(),
            };
            let look = remembered.look_at_folder(&dir, folder_rel);
            let clean = look.unchanged
                || sweep_dead_tmp_in(&dir)
                    .with_context(|| format!("{}: sweeping", dir.display()))?
                    == 0;
            folders.insert(dir.clone(), (look, clean));
        }
        // On a forced rerun, an output whose identity and fingerprint say it holds these bytes
        // already is left unread ([`RememberedDigests::output_unchanged`]).
        if let Some(digest) = remembered.output_unchanged(&path, &rel, bytes) {
            written.insert(rel, digest);
            continue;
        }
        let kept = write_if_changed_kept(&path, bytes)
            .with_context(|| format!("{}: cannot write", path.display()))?;
        if kept.is_none() {
            if let Some((_, clean)) = folders.get_mut(&dir) {
                *clean = false;
            }
        }
        let digest = remembered.output_digest(&rel, bytes, kept, now);
        written.insert(rel, digest);
    }
    for (look, clean) in folders.into_values() {
        remembered.note_folder(look, clean, now);
    }
    // Outputs of an earlier run that this run no longer writes would be stale: removed, and
    // each named in a warning (a later stage may have read it).
    let mut removed = Vec::new();
    if let Some(previous) = previous {
        for rel in previous.outputs.keys() {
            if !written.contains_key(rel) {
                match std::fs::remove_file(ctx.dataset.join(rel)) {
                    Ok(()) => removed.push(rel.clone()),
                    Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                    Err(e) => {
                        return Err(e).with_context(|| {
                            format!(
                                "{}: cannot remove this stale output of the last run",
                                ctx.dataset.join(rel).display()
                            )
                        })
                    }
                }
            }
        }
    }
    Ok((written, removed))
}

/// The warning for an output of the last run that this run removed.
fn removed_warning(rel: &str) -> String {
    let settled = format!("/{}", mesa_stages::paths::scene::SETTLED_LAYOUT);
    let hint = if rel.ends_with(&settled) {
        ": the later stages now read refined/layout.json (`mesa check --settle` settles the \
         scene again)"
    } else {
        ""
    };
    format!(
        "removed {rel}, which the last run wrote and this one does not (it would be stale){hint}"
    )
}

fn fail(
    ctx: &StageContext<'_>,
    scene: &Scene,
    marker_file: &Path,
    mut marker: RunMarker,
    previous: Option<&RunMarker>,
    cause: &anyhow::Error,
) -> SceneOutcome {
    let mut error = error_chain(cause);
    let leftovers = cause.downcast_ref::<FailureOutputs>();
    // The files the failure leaves (rejects it names), written before it is recorded. A
    // failed marker lists them, so that a later success removes them.
    let mut written = BTreeMap::new();
    for (rel, bytes) in leftovers.map(|f| &f.files).into_iter().flatten() {
        let path = scene.path(rel);
        let result = check_output_path(rel)
            .and_then(|()| sweep_tmp_for(&path).map_err(anyhow::Error::from))
            .and_then(|()| write_atomic(&path, bytes).map_err(anyhow::Error::from));
        match result {
            Ok(()) => {
                written.insert(scene.rel(rel), sha256_hex(bytes));
            }
            Err(e) => error.push(format!("{}: cannot write: {e:#}", path.display())),
        }
    }
    let keep_previous = leftovers.is_some_and(|f| f.keep_previous);
    if let Some(previous) = previous {
        for (rel, digest) in &previous.outputs {
            if written.contains_key(rel) {
                continue;
            }
            if keep_previous {
                // Still the last success's outputs; listed so a later run replaces them.
                written.insert(rel.clone(), digest.clone());
            } else {
                // The outputs of an earlier run no longer match this scene's inputs: remove
                // them so that nothing downstream reads them as current.
                let _ = std::fs::remove_file(ctx.dataset.join(rel));
            }
        }
    }
    marker.outputs = written;
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

/// [`read_marker`], whose bytes are kept in the scene's record ([`scene_files`]) when it is a
/// regular file: writing the scene's marker then compares with them instead of reading the
/// file again.
fn read_scene_marker(path: &Path) -> Option<RunMarker> {
    // Opened without following a link, then statted through the open file: one walk of the
    // path (as `holding` in fsio does for the outputs).
    let file = match open_own_file(path) {
        Ok(file) => file,
        // A link: read through it as before, and compared on disk when written.
        Err(e) if e.raw_os_error() == Some(libc::ELOOP) => return read_marker(path),
        Err(_) => return None,
    };
    // A FIFO, a folder or an outsized file is no marker of mesa's (nothing, or an error, or
    // what does not parse): the scene is redone and its marker written over it.
    let bytes = read_own_small(&file, MARKER_LIMIT).ok()?;
    let marker = serde_json::from_slice(&bytes).ok()?;
    scene_files::keep(path, bytes);
    Some(marker)
}

/// Writes a scene's marker, unless the file holds these bytes already (compared with the
/// bytes [`read_scene_marker`] kept for the scene, else with the file). Its folder (one per
/// stage and table type, a file a scene) is swept of dead writers' temporary files once per
/// run by [`run_stage`], not here: sweeping beside each marker listed the whole folder once a
/// scene, quadratic in the scenes of a table type (10,000 scenes: 2.6 ms a scene of runner
/// cost, most of it listing).
fn write_marker(path: &Path, marker: &RunMarker) -> std::io::Result<()> {
    let bytes = marker.to_pretty_json();
    match scene_files::take(path) {
        Some(previous) if previous == bytes => Ok(()),
        Some(_) => write_atomic(path, &bytes),
        None => write_if_changed(path, &bytes).map(drop),
    }
}

/// Sweeps the marker folders of `scenes` (each once), and those of their remembered digests,
/// of dead writers' temporary files.
fn sweep_marker_folders(
    ctx: &StageContext<'_>,
    stage: &str,
    scenes: &[Scene],
) -> anyhow::Result<()> {
    // The remembered digests' folders too, laid out as the markers' are.
    let folders: std::collections::BTreeSet<PathBuf> = scenes
        .iter()
        .flat_map(|scene| {
            [
                marker_path(ctx.dataset, stage, scene),
                digests_path(ctx.dataset, stage, scene),
            ]
        })
        .filter_map(|path| path.parent().map(Path::to_path_buf))
        .collect();
    for folder in folders {
        sweep_dead_tmp_in(&folder).with_context(|| format!("{}: sweeping", folder.display()))?;
    }
    Ok(())
}

/// Runs a stage over the selected scenes of a dataset: `prepare`, every scene, then `finish`
/// (whose lines land in [`StageSummary::closing`]).
pub fn run_stage(
    stage: &dyn SceneStage,
    ctx: &StageContext<'_>,
    options: &RunOptions,
) -> anyhow::Result<StageSummary> {
    let started = Instant::now();
    let discovery = discover_all(ctx.dataset).map_err(RunError::into_anyhow)?;
    let mut scenes = select_scenes(discovery.scenes, options.scenes.as_deref(), options.shard)
        .map_err(RunError::into_anyhow)?;
    // Folders that cannot be scenes are reported once, by the first shard of an unfiltered run:
    // a failure (a name mesa cannot carry), or a warning for a hidden folder.
    let skipped = if options.shard.index == 0 && options.scenes.is_none() && options.only.is_none()
    {
        discovery.skipped
    } else {
        Vec::new()
    };
    if let Some(only) = &options.only {
        scenes.retain(|s| only.contains(&s.key()));
    }
    // Scenes imported at the refined stage do not need the stages that make it.
    let before = scenes.len();
    if stage.before_refined() {
        scenes.retain(|s| !s.imported());
    }
    let imported = before - scenes.len();
    // Held until the summary is made: a second run of this stage would sweep and rename
    // this one's files away.
    let _lock = super::lock::lock_stage(ctx, stage.name(), options.shard)?;
    sweep_marker_folders(ctx, stage.name(), &scenes)?;
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
        imported,
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
    for folder in skipped {
        let message = format!("scenes/{}: {}", folder.key, folder.problem);
        if folder.hidden {
            summary.warnings.push((folder.key, message));
        } else {
            summary.scenes += 1;
            summary.failed.push((folder.key, vec![message]));
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
    let waiting = if summary.imported == 0 {
        waiting
    } else {
        format!(
            "{waiting}, {} imported (they enter after this stage)",
            summary.imported
        )
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
    fn output_paths_must_stay_inside_the_scene() {
        assert!(check_output_path("graph/graph.json").is_ok());
        assert!(check_output_path("../x").is_err());
        assert!(check_output_path("/etc/passwd").is_err());
        assert!(check_output_path("").is_err());
    }
}
