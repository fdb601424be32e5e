//! `mesa records`: the dataset-level stage run once after every scene's tasks. It merges the
//! tasks of all scenes into the training files under `records/`, over
//! [`mesa_stages::records`]:
//!
//! - `sft.json`, `test.json` (LLaMA-Factory alpaca), `dpo.json` (alpaca preference);
//! - `trl_sft.jsonl`, `trl_test.jsonl`, `trl_dpo.jsonl` (TRL conversational);
//! - `dataset_info.json` (LLaMA-Factory's registry) and `split.json`.
//!
//! Deterministic (scenes in sorted order, every random choice seeded; byte-identical for any
//! `--jobs`), streamed (scenes go through in chunks, records straight to disk: memory stays
//! flat at any dataset size), atomic (every file is written under a temporary name and renamed
//! when all are complete; the done marker comes last), and skipped when nothing it reads has
//! changed since the last run (`--force` redoes it).

use mesa_stages::paths::dataset::RECORDS_DIR;
use std::collections::BTreeMap;
use std::path::Path;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{anyhow, bail, Context as _};
use mesa_schemas::artifacts::{
    CheckArtifact, MarkerStatus, RunMarker, SettleStatus, SplitArtifact, TaskRecord, MARKER_SCHEMA,
    SPLIT_SCHEMA,
};
use mesa_schemas::json::to_sorted_pretty;
use mesa_stages::graph::{extract_graph, GraphOptions, GraphScene};
use mesa_stages::records::split::{assign, Split};
use mesa_stages::records::write::{
    dataset_info, JsonArrayWriter, JsonLinesWriter, DPO_FILE, SFT_FILE, TEST_FILE, TRL_DPO_FILE,
    TRL_SFT_FILE, TRL_TEST_FILE,
};
use mesa_stages::records::{
    dpo_pairs, round_layout, sft_record, trl_dpo, trl_sft, RecordsConfig, SceneRecordsInput,
};
use mesa_stages::tasks::prompts::{layout_instruction, LAYOUT_GENERATION};
use serde::Serialize;
use sha2::{Digest as _, Sha256};

use mesa_stages::paths::dataset::INDEX;
use mesa_stages::paths::scene::{CHECK as CHECK_FILE, GRAPH_JSON, GRAPH_TXT, TASKS as TASKS_FILE};
use mesa_stages::records::collide::Collider;

use crate::cli::{DatasetStageArgs, Global};
use crate::commands::check::ShapeLibrary;
use crate::config::Config;
use crate::exit::UsageError;
use crate::fsio::{sha256_hex, write_atomic, AtomicFile};
use crate::layouts::{chosen_layout, read_dataset_layout};
use crate::runner::{
    digest_of, discover_scenes, DatasetReport, DatasetStage, Executor, RunError, Scene,
    StageContext,
};
use crate::scene_docs::read_scene_docs;

/// `mesa records`: the dataset, its run flags and --force.
pub type Args = DatasetStageArgs;

/// Runs `mesa records`.
pub fn run(args: Args, global: Global) -> anyhow::Result<ExitCode> {
    args.resolve(global)?.run_dataset(&RecordsStage)
}

/// The `records` stage: the training records, once over the dataset.
#[derive(Debug, Default)]
pub struct RecordsStage;

impl DatasetStage for RecordsStage {
    fn name(&self) -> &'static str {
        "records"
    }

    fn preflight(&self, ctx: &StageContext<'_>) -> Result<(), UsageError> {
        let problems = ctx.config.records.problems();
        if !problems.is_empty() {
            return Err(UsageError(problems.join("\n")));
        }
        instruction(ctx.dataset, &ctx.config.records).map_err(UsageError)?;
        Ok(())
    }

    fn run(&self, ctx: &StageContext<'_>, exec: &Executor<'_>) -> anyhow::Result<DatasetReport> {
        let summary = run_records(ctx, exec)?;
        Ok(DatasetReport {
            success: summary.excluded.is_empty(),
            text: format_records_summary(&summary),
            record: serde_json::to_value(&summary)?,
        })
    }
}

/// `records/split.json`.
pub const SPLIT_FILE: &str = "split.json";
/// `records/dataset_info.json`.
pub const DATASET_INFO_FILE: &str = "dataset_info.json";

/// Scenes handled together: built in parallel, then written in order.
const CHUNK: usize = 64;

/// What a records run did.
#[derive(Debug, Clone, Default, Serialize)]
pub struct RecordsSummary {
    /// True when the records were up to date and nothing was written.
    pub up_to_date: bool,
    /// True when every scene awaits its annotator: no records yet, nothing written.
    pub nothing_ready: bool,
    /// Scenes whose records were written.
    pub scenes: usize,
    /// Scenes left out, with why.
    pub excluded: BTreeMap<String, String>,
    /// Scenes left out because they await their annotator (not a failure).
    pub waiting: BTreeMap<String, String>,
    /// Scenes left out because their `mesa check` failed, with what it found (not a failure
    /// of the records: `[records] keep_failed_check` keeps them).
    pub failed_check: BTreeMap<String, String>,
    /// Scenes per split.
    pub splits: BTreeMap<String, usize>,
    /// Records per file.
    pub records: BTreeMap<String, u64>,
    /// DPO pairs per corruption.
    pub corruptions: BTreeMap<String, u64>,
    /// DPO scenes by how their collision corruptions were verified (`meshes`: the assets'
    /// collision shapes, as `mesa check` tests; `boxes`: oriented boxes, without assets).
    pub collision_checks: BTreeMap<String, u64>,
    /// DPO prompts that got fewer rejected outputs than asked.
    pub prompts_short: u64,
    /// Warnings, by scene.
    pub warnings: Vec<(String, String)>,
    /// Bytes per file written.
    pub bytes: BTreeMap<String, u64>,
    /// Wall time in seconds.
    pub elapsed_s: f64,
}

/// The layout-generation instruction of a configuration.
pub fn instruction(dataset: &Path, config: &RecordsConfig) -> Result<String, String> {
    let text = if config.layout_prompt.is_empty() {
        LAYOUT_GENERATION.to_owned()
    } else {
        let path = dataset.join(&config.layout_prompt);
        std::fs::read_to_string(&path).map_err(|e| {
            format!(
                "[records] layout_prompt: {}: cannot read: {e}",
                path.display()
            )
        })?
    };
    layout_instruction(&text).map_err(|e| format!("[records] layout_prompt: {e}"))
}

/// A scene, and the digest of what its records read (or why it has no records).
struct Planned {
    scene: Scene,
    inputs: Result<String, String>,
    /// Why the scene has no records yet, when it awaits its annotator.
    waiting: Option<String>,
    /// What its check found, when the scene is left out for it.
    failed_check: Option<String>,
}

/// Why a scene failed its `mesa check`, or `None` when it passed or was never checked:
/// `qa/check.json` (of the layout as it is now) finds it not clean and no settled layout
/// replaced it. A check that could not run (a dataset without assets fails it for want of an
/// asset index) wrote no verdict: the scene is kept, as an unchecked one.
fn failed_check(scene: &Scene) -> Option<String> {
    let bytes = std::fs::read(scene.path(CHECK_FILE)).ok()?;
    let check: CheckArtifact = match serde_json::from_slice(&bytes) {
        Ok(check) => check,
        Err(e) => {
            return Some(format!(
                "{CHECK_FILE}: cannot be read: {e} (rerun `mesa check --force`)"
            ))
        }
    };
    // A check of another version of the layout says nothing of this one (and a layout path
    // that leaves the scene folder names none of its layouts).
    let inside = std::path::Path::new(&check.layout)
        .components()
        .all(|c| matches!(c, std::path::Component::Normal(_)));
    if !inside {
        return None;
    }
    let checked = std::fs::read(scene.path(&check.layout)).ok()?;
    if sha256_hex(&checked) != check.layout_sha256 {
        return None;
    }
    if check.clean
        || check
            .settle
            .as_ref()
            .is_some_and(|s| s.status == SettleStatus::Settled)
    {
        return None;
    }
    Some(format!(
        "{CHECK_FILE}: {} is not clean: {} collisions, {} floating objects, {} zone violations, \
         {} objects unchecked (fix the layout, or settle it with `mesa check --settle`; \
         [records] keep_failed_check = true keeps it)",
        check.layout,
        check.collisions.len(),
        check.floating.len(),
        check.zone_violations.len(),
        check.unchecked.len()
    ))
}

fn plan_scene(keep_failed_check: bool, scene: Scene) -> Planned {
    if let Some(reason) = crate::scene_docs::awaiting_annotation(&scene) {
        return Planned {
            scene,
            inputs: Err(reason.clone()),
            waiting: Some(reason),
            failed_check: None,
        };
    }
    if !keep_failed_check {
        if let Some(why) = failed_check(&scene) {
            return Planned {
                scene,
                inputs: Err(why.clone()),
                waiting: None,
                failed_check: Some(why),
            };
        }
    }
    let inputs = (|| -> Result<String, String> {
        let tasks_path = scene.path(TASKS_FILE);
        if !tasks_path.is_file() {
            return Err(format!("no {TASKS_FILE} (run `mesa tasks`)"));
        }
        let layout_rel = chosen_layout(&scene).ok_or("no layout (run `mesa place`)")?;
        let mut digests = Vec::new();
        let mut tasks_text = String::new();
        for rel in [TASKS_FILE, layout_rel, GRAPH_TXT, GRAPH_JSON] {
            let path = scene.path(rel);
            let bytes = std::fs::read(&path)
                .map_err(|e| format!("{rel}: cannot read: {e} (run the stage that writes it)"))?;
            digests.push(format!("{rel} {}", sha256_hex(&bytes)));
            if rel == TASKS_FILE {
                tasks_text = String::from_utf8(bytes).map_err(|_| format!("{rel}: not UTF-8"))?;
            }
        }
        // Tasks written for another layout are stale: the records would pair a task with a
        // layout it was not written for.
        let first = tasks_text
            .lines()
            .find(|l| !l.trim().is_empty())
            .ok_or_else(|| format!("{TASKS_FILE} is empty (rerun `mesa tasks`)"))?;
        let record: TaskRecord = serde_json::from_str(first)
            .map_err(|e| format!("{TASKS_FILE}:1: not a mesa.tasks/1 record: {e}"))?;
        if record.layout != layout_rel || !digests[1].ends_with(&record.layout_sha256) {
            return Err(format!(
                "{TASKS_FILE} was written for another version of the layout ({} then, {layout_rel} \
                 now; rerun `mesa tasks`)",
                record.layout
            ));
        }
        Ok(sha256_hex(digests.join("\n").as_bytes()))
    })();
    Planned {
        scene,
        inputs,
        waiting: None,
        failed_check: None,
    }
}

/// One scene's records, serialised.
#[derive(Default)]
struct SceneOut {
    files: BTreeMap<&'static str, Vec<String>>,
    corruptions: BTreeMap<&'static str, u64>,
    /// How its collision corruptions were verified (DPO scenes).
    collider: Option<&'static str>,
    prompts_short: u64,
    warnings: Vec<String>,
}

struct Shared<'a> {
    /// The dataset folder.
    dataset: &'a Path,
    /// The assets' collision shapes, when the dataset has an asset index.
    shapes: Option<ShapeLibrary>,
    instruction: &'a str,
    records: &'a RecordsConfig,
    graph: GraphOptions,
    seed: u64,
}

fn read_tasks(scene: &Scene) -> Result<Vec<TaskRecord>, String> {
    let path = scene.path(TASKS_FILE);
    let text = std::fs::read_to_string(&path).map_err(|e| format!("{TASKS_FILE}: {e}"))?;
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, line)| {
            serde_json::from_str(line)
                .map_err(|e| format!("{TASKS_FILE}:{}: not a mesa.tasks/1 record: {e}", i + 1))
        })
        .collect()
}

/// How a DPO scene's collision corruptions are verified: on the assets' collision shapes (as
/// `mesa check` tests) when every object has one, else on boxes, with why.
fn collider_of(scene: &Scene, layout_rel: &str, shared: &Shared<'_>) -> (Collider, Option<String>) {
    let Some(library) = &shared.shapes else {
        // No asset index (a dataset of published layouts): boxes, as documented.
        return (Collider::Boxes, None);
    };
    let boxes = |why: String| {
        (
            Collider::Boxes,
            Some(format!("collision corruptions verified on boxes: {why}")),
        )
    };
    let layout = match read_dataset_layout(&scene.path(layout_rel), "check") {
        Ok((layout, _)) => layout,
        Err(e) => return boxes(format!("{e:#}")),
    };
    let mut shapes = BTreeMap::new();
    for object in &layout.objects {
        match library.shape_of(shared.dataset, object) {
            Ok(shape) => {
                shapes.insert(object.instance.clone(), shape);
            }
            Err(why) => return boxes(format!("{}: {why}", object.instance)),
        }
    }
    (Collider::Meshes(shapes), None)
}

fn build_scene(scene: &Scene, split: Split, shared: &Shared<'_>) -> Result<SceneOut, String> {
    let docs = read_scene_docs(scene).map_err(|e| format!("{e:#}"))?;
    let tasks = read_tasks(scene)?;
    if let Some(stale) = tasks.iter().find(|t| t.layout_sha256 != docs.layout_sha256) {
        return Err(format!(
            "{TASKS_FILE}: task {} was written for another version of {} (rerun `mesa tasks`)",
            stale.task_index, docs.layout_rel
        ));
    }
    let mut out = SceneOut {
        warnings: docs.warnings.clone(),
        ..SceneOut::default()
    };
    let collider = if split == Split::Dpo {
        let (collider, why) = collider_of(scene, docs.layout_rel, shared);
        out.warnings.extend(why);
        out.collider = Some(collider.name());
        collider
    } else {
        Collider::Boxes
    };
    let layout = round_layout(&docs.layout, shared.records.decimals);
    let containers: Vec<bool> = docs.graph.nodes.iter().map(|n| n.container).collect();
    // The scene graph of the layout as the record writes it (rounded), not of graph/graph.txt's
    // unrounded one: an object on the edge of a position band (y = 55.33 of a 65.08 cm zone is
    // back_middle, 55.3 of 65.1 is center) would otherwise teach a graph its own layout
    // contradicts. The corrupted completions are made the same way.
    let graph_lines = extract_graph(&GraphScene::from_llm(&layout), &containers, &shared.graph)
        .map_err(|e| format!("the scene graph of the rounded layout: {e}"))?
        .triplet_lines();
    let input = SceneRecordsInput {
        scene_id: scene.scene_id.clone(),
        layout,
        graph_lines,
        containers,
        tasks,
        collider,
    };
    for task in &input.tasks {
        let sft = match sft_record(shared.instruction, &input, task) {
            Ok(sft) => sft,
            Err(e) => {
                out.warnings.push(format!("{e}; the task is left out"));
                continue;
            }
        };
        match split {
            Split::Train | Split::Test => {
                let (alpaca, trl) = if split == Split::Train {
                    (SFT_FILE, TRL_SFT_FILE)
                } else {
                    (TEST_FILE, TRL_TEST_FILE)
                };
                out.files.entry(alpaca).or_default().push(json(&sft)?);
                out.files
                    .entry(trl)
                    .or_default()
                    .push(json(&trl_sft(&sft))?);
            }
            Split::Dpo => {
                let (pairs, notes) = dpo_pairs(
                    shared.instruction,
                    &input,
                    task,
                    &sft,
                    shared.records,
                    &shared.graph,
                    shared.seed,
                );
                if pairs.len() < shared.records.rejected_per_prompt as usize {
                    out.prompts_short += 1;
                    out.warnings.push(notes.join("; "));
                }
                for pair in pairs {
                    *out.corruptions.entry(pair.corruption.name()).or_default() += 1;
                    out.files
                        .entry(DPO_FILE)
                        .or_default()
                        .push(json(&pair.record)?);
                    out.files
                        .entry(TRL_DPO_FILE)
                        .or_default()
                        .push(json(&trl_dpo(&pair.record))?);
                }
            }
        }
    }
    Ok(out)
}

/// Compact JSON of a record, fields in their declared order (official formats keep it).
fn json<T: Serialize>(value: &T) -> Result<String, String> {
    serde_json::to_string(value).map_err(|e| e.to_string())
}

enum Sink {
    Array(JsonArrayWriter<AtomicFile>),
    Lines(JsonLinesWriter<AtomicFile>),
}

impl Sink {
    fn push_raw(&mut self, json: &str) -> std::io::Result<()> {
        match self {
            Self::Array(w) => w.push_raw(json),
            Self::Lines(w) => w.push_raw(json),
        }
    }

    fn count(&self) -> u64 {
        match self {
            Self::Array(w) => w.count(),
            Self::Lines(w) => w.count(),
        }
    }

    fn into_file(self) -> std::io::Result<AtomicFile> {
        match self {
            Self::Array(w) => w.finish(),
            Self::Lines(w) => Ok(w.finish()),
        }
    }
}

/// The digest of everything a records run depends on besides the scene files.
fn config_digest(dataset: &Path, config: &Config, instruction: &str) -> String {
    #[derive(Serialize)]
    struct Fingerprint<'a> {
        records: &'a RecordsConfig,
        graph: &'a mesa_stages::graph::GraphConfig,
        seed: u64,
        instruction: &'a str,
        version: &'a str,
        /// The collision corruption reads the assets' shapes (the index has their digests).
        asset_index: Option<String>,
    }
    digest_of(&Fingerprint {
        records: &config.records,
        graph: &config.graph,
        seed: config.run.seed,
        instruction,
        version: env!("CARGO_PKG_VERSION"),
        asset_index: std::fs::read(dataset.join(INDEX))
            .ok()
            .map(|b| sha256_hex(&b)),
    })
}

/// Builds the records of a dataset, a scene a unit of `exec`.
pub fn run_records(ctx: &StageContext<'_>, exec: &Executor<'_>) -> anyhow::Result<RecordsSummary> {
    let (dataset, config) = (ctx.dataset, ctx.config);
    let started = Instant::now();
    let problems = config.records.problems();
    if !problems.is_empty() {
        bail!("{}", problems.join("\n"));
    }
    let instruction = instruction(dataset, &config.records).map_err(|e| anyhow!(e))?;
    let scenes = discover_scenes(dataset).map_err(RunError::into_anyhow)?;

    // 1. Which scenes have current tasks, and the digests of what their records read.
    let planned: Vec<Planned> = exec.install(|| {
        use rayon::prelude::*;
        let keep = config.records.keep_failed_check;
        scenes
            .into_par_iter()
            .map(|scene| plan_scene(keep, scene))
            .collect()
    });
    let mut summary = RecordsSummary::default();
    // One line per scene, in scene order, into one digest: nothing per scene stays in memory.
    let mut inputs = Sha256::new();
    let mut included = Vec::new();
    for plan in planned {
        let key = plan.scene.key();
        match plan.inputs {
            Ok(digest) => {
                inputs.update(format!("{key} {digest}\n"));
                included.push(plan.scene);
            }
            Err(why) => {
                inputs.update(format!("{key} excluded: {why}\n"));
                if plan.waiting.is_some() {
                    summary.waiting.insert(key, why);
                } else if plan.failed_check.is_some() {
                    summary.failed_check.insert(key, why);
                } else {
                    summary.excluded.insert(key, why);
                }
            }
        }
    }
    let inputs_digest = mesa_stages::hex(&inputs.finalize());
    let config_digest = config_digest(dataset, config, &instruction);
    let marker_path = exec.marker_path(ctx);
    let out_dir = dataset.join(RECORDS_DIR);
    if !exec.options().force {
        if let Some(marker) = exec.read_marker(ctx) {
            let current = marker.status == MarkerStatus::Done
                && marker.config_digest == config_digest
                && marker.inputs.get("scenes") == Some(&inputs_digest)
                && marker.outputs.keys().all(|rel| dataset.join(rel).is_file());
            if current {
                summary.up_to_date = true;
                summary.elapsed_s = started.elapsed().as_secs_f64();
                return Ok(summary);
            }
        }
    }
    if included.is_empty() && summary.excluded.is_empty() && !summary.waiting.is_empty() {
        // Every scene awaits its annotator: nothing to build yet, and nothing wrong.
        summary.nothing_ready = true;
        summary.elapsed_s = started.elapsed().as_secs_f64();
        return Ok(summary);
    }
    if included.is_empty() && summary.excluded.is_empty() && !summary.failed_check.is_empty() {
        bail!(
            "{}: every scene that has tasks failed its check ({} scenes; {}): no records (fix \
             the layouts, or set [records] keep_failed_check = true to keep them)",
            dataset.display(),
            summary.failed_check.len(),
            summary
                .failed_check
                .iter()
                .next()
                .map(|(scene, why)| format!("{scene}: {why}"))
                .unwrap_or_default()
        );
    }
    if included.is_empty() {
        bail!(
            "{}: no scene has tasks to make records of (run `mesa tasks` first){}",
            dataset.display(),
            match summary.excluded.iter().next() {
                Some((scene, why)) => format!("; {scene}: {why}"),
                None => String::new(),
            }
        );
    }

    // 2. The split, then the records, chunk by chunk, straight into the files.
    let keys: Vec<(String, String)> = included
        .iter()
        .map(|s| (s.table_type.clone(), s.scene_id.clone()))
        .collect();
    let splits = assign(&keys, &config.records.split, config.run.seed);
    let mut sinks: BTreeMap<&'static str, Sink> = BTreeMap::new();
    for file in [SFT_FILE, TEST_FILE, DPO_FILE] {
        let path = out_dir.join(file);
        let atomic = AtomicFile::create(&path).with_context(|| format!("{}", path.display()))?;
        sinks.insert(file, Sink::Array(JsonArrayWriter::new(atomic)?));
    }
    for file in [TRL_SFT_FILE, TRL_TEST_FILE, TRL_DPO_FILE] {
        let path = out_dir.join(file);
        let atomic = AtomicFile::create(&path).with_context(|| format!("{}", path.display()))?;
        sinks.insert(file, Sink::Lines(JsonLinesWriter::new(atomic)));
    }
    let shapes = if dataset.join(INDEX).is_file() {
        Some(ShapeLibrary::load(dataset)?)
    } else {
        None
    };
    let shared = Shared {
        dataset,
        shapes,
        instruction: &instruction,
        records: &config.records,
        graph: GraphOptions::from(&config.graph),
        seed: config.run.seed,
    };
    let progress = exec.progress("scenes", included.len());
    let mut assigned: BTreeMap<String, String> = BTreeMap::new();
    let mut counts: BTreeMap<String, BTreeMap<String, u64>> = BTreeMap::new();
    let work: Vec<(Scene, Split)> = included.into_iter().zip(splits).collect();
    for chunk in work.chunks(CHUNK) {
        let built: Vec<Result<SceneOut, String>> = exec.install(|| {
            use rayon::prelude::*;
            chunk
                .par_iter()
                .map(|(scene, split)| build_scene(scene, *split, &shared))
                .collect()
        });
        for ((scene, split), result) in chunk.iter().zip(built) {
            match result {
                Ok(out) => {
                    for (file, lines) in &out.files {
                        let sink = sinks
                            .get_mut(file)
                            .ok_or_else(|| anyhow!("internal error: no sink for {file}"))?;
                        for line in lines {
                            sink.push_raw(line).with_context(|| {
                                format!("{}/{file}: cannot write", out_dir.display())
                            })?;
                        }
                    }
                    for (kind, n) in out.corruptions {
                        *summary.corruptions.entry(kind.to_owned()).or_default() += n;
                    }
                    if let Some(collider) = out.collider {
                        *summary
                            .collision_checks
                            .entry(collider.to_owned())
                            .or_default() += 1;
                    }
                    summary.prompts_short += out.prompts_short;
                    summary
                        .warnings
                        .extend(out.warnings.into_iter().map(|w| (scene.key(), w)));
                    assigned.insert(scene.key(), split.name().to_owned());
                    *counts
                        .entry(scene.table_type.clone())
                        .or_default()
                        .entry(split.name().to_owned())
                        .or_default() += 1;
                    *summary.splits.entry(split.name().to_owned()).or_default() += 1;
                }
                Err(why) => {
                    summary.excluded.insert(scene.key(), why);
                }
            }
        }
        progress.advance(chunk.len());
    }
    progress.finish();
    summary.scenes = assigned.len();

    // 3. Commit: the record files, then the registry and the split, then the marker.
    let mut outputs = BTreeMap::new();
    let mut files = Vec::new();
    for (file, sink) in sinks {
        summary.records.insert(file.to_owned(), sink.count());
        files.push((file, sink.into_file()?));
    }
    for (file, atomic) in files {
        let path = atomic.target().to_owned();
        atomic
            .commit()
            .with_context(|| format!("{}: cannot write", path.display()))?;
        outputs.insert(format!("{RECORDS_DIR}/{file}"), file_digest(&path)?);
        summary
            .bytes
            .insert(file.to_owned(), std::fs::metadata(&path)?.len());
    }
    let split = SplitArtifact {
        schema: SPLIT_SCHEMA.to_owned(),
        seed: config.run.seed,
        ratios: config.records.split.by_name(),
        scenes: assigned,
        counts,
        excluded: summary
            .excluded
            .iter()
            .chain(&summary.waiting)
            .chain(&summary.failed_check)
            .map(|(k, v)| (k.clone(), v.clone()))
            .collect(),
    };
    for (file, bytes) in [
        (DATASET_INFO_FILE, to_sorted_pretty(&dataset_info())?),
        (SPLIT_FILE, to_sorted_pretty(&split)?),
    ] {
        let path = out_dir.join(file);
        write_atomic(&path, &bytes).with_context(|| format!("{}: cannot write", path.display()))?;
        outputs.insert(format!("{RECORDS_DIR}/{file}"), sha256_hex(&bytes));
        summary.bytes.insert(file.to_owned(), bytes.len() as u64);
    }
    summary.elapsed_s = started.elapsed().as_secs_f64();
    let marker = RunMarker {
        schema: MARKER_SCHEMA.to_owned(),
        stage: "records".to_owned(),
        scene: "(dataset)".to_owned(),
        status: MarkerStatus::Done,
        mesa_version: env!("CARGO_PKG_VERSION").to_owned(),
        config_digest,
        inputs: BTreeMap::from([("scenes".to_owned(), inputs_digest)]),
        outputs,
        warnings: Vec::new(),
        error: Vec::new(),
    };
    write_atomic(&marker_path, &marker.to_pretty_json())
        .with_context(|| format!("{}: cannot write", marker_path.display()))?;
    Ok(summary)
}

fn file_digest(path: &Path) -> anyhow::Result<String> {
    crate::fsio::sha256_file(path).with_context(|| format!("{}: cannot read back", path.display()))
}

/// The human summary of a records run.
pub fn format_records_summary(summary: &RecordsSummary) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    if summary.nothing_ready {
        let _ = writeln!(
            out,
            "records: not built: all {} scenes await annotation (`mesa status` lists the packs \
             to send)",
            summary.waiting.len()
        );
        return out;
    }
    if summary.up_to_date {
        let _ = writeln!(
            out,
            "records: up to date (nothing they read changed; --force rebuilds them), {} scenes \
             without records{}",
            summary.excluded.len(),
            if summary.failed_check.is_empty() {
                String::new()
            } else {
                format!(
                    ", {} left out because their check failed",
                    summary.failed_check.len()
                )
            }
        );
        return out;
    }
    let count = |file: &str| summary.records.get(file).copied().unwrap_or(0);
    let mb = |file: &str| summary.bytes.get(file).copied().unwrap_or(0) as f64 / 1e6;
    let total: u64 = summary.records.values().sum();
    let _ = writeln!(
        out,
        "records: {} scenes (train {}, dpo {}, test {}), {} excluded, {} awaiting annotation, in \
         {:.2} s ({:.0} records/s)",
        summary.scenes,
        summary.splits.get("train").copied().unwrap_or(0),
        summary.splits.get("dpo").copied().unwrap_or(0),
        summary.splits.get("test").copied().unwrap_or(0),
        summary.excluded.len(),
        summary.waiting.len(),
        summary.elapsed_s,
        total as f64 / summary.elapsed_s.max(1e-9)
    );
    if !summary.failed_check.is_empty() {
        let _ = writeln!(
            out,
            "  left out {} scenes whose check failed ([records] keep_failed_check = true keeps \
             them; records/split.json lists them):",
            summary.failed_check.len()
        );
        const SHOWN: usize = 10;
        for (scene, why) in summary.failed_check.iter().take(SHOWN) {
            let _ = writeln!(out, "    {scene}: {why}");
        }
        if summary.failed_check.len() > SHOWN {
            let _ = writeln!(
                out,
                "    ... and {} more",
                summary.failed_check.len() - SHOWN
            );
        }
    }
    for file in [
        SFT_FILE,
        TEST_FILE,
        DPO_FILE,
        TRL_SFT_FILE,
        TRL_TEST_FILE,
        TRL_DPO_FILE,
    ] {
        let _ = writeln!(
            out,
            "  {RECORDS_DIR}/{file}: {} records, {:.1} MB",
            count(file),
            mb(file)
        );
    }
    if !summary.corruptions.is_empty() {
        let kinds: Vec<String> = summary
            .corruptions
            .iter()
            .map(|(k, n)| format!("{k} {n}"))
            .collect();
        let checks: Vec<String> = summary
            .collision_checks
            .iter()
            .map(|(k, n)| format!("{n} scenes on {k}"))
            .collect();
        let _ = writeln!(
            out,
            "  DPO rejected outputs by corruption: {}; {} prompts got fewer than asked; \
             collisions verified: {}",
            kinds.join(", "),
            summary.prompts_short,
            checks.join(", ")
        );
    }
    for (scene, why) in summary.excluded.iter().take(10) {
        let _ = writeln!(out, "  excluded {scene}: {why}");
    }
    if summary.excluded.len() > 10 {
        let _ = writeln!(
            out,
            "  ... and {} more excluded (all in {RECORDS_DIR}/{SPLIT_FILE})",
            summary.excluded.len() - 10
        );
    }
    for (scene, warning) in summary.warnings.iter().take(10) {
        let _ = writeln!(out, "  warning {scene}: {warning}");
    }
    if summary.warnings.len() > 10 {
        let _ = writeln!(
            out,
            "  ... and {} more warnings (in .mesa/runs/records/run.json)",
            summary.warnings.len() - 10
        );
    }
    out
}
