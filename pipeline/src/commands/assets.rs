//! `mesa assets DATASET`: the asset index, a dataset-level stage (it runs once over the
//! library, not per scene).
//!
//! Every `assets/library/<uid>.glb` is indexed in parallel by
//! [`mesa_stages::assets::index_asset`]; an asset whose GLB, annotation and `[assets]`
//! configuration are unchanged since the last run keeps its record and shapes file (the record
//! holds the digest of those inputs). Outputs, each written atomically:
//!
//! - `assets/index/shapes/<uid>.json`: collision shapes of each valid asset (compact JSON);
//! - `assets/index/text.json`: the lexical encoder's text index over the annotations;
//! - `assets/index/assets.json`: one record per GLB, written last, so an index that exists
//!   is complete.
//!
//! Broken assets are recorded with the reason (and how to fix it), never fatal; `--strict`
//! makes them exit with code 1.
//!
//! Sharded (`--shard I/N`, or a Slurm array task): task I indexes asset number k of the sorted
//! library when k mod N = I, writes their shapes files and its part of the records
//! (`.mesa/parts/assets/<I>-of-<N>.json`), then takes the merge lock: the task that finds every
//! part of the same run present (the last to finish; a run is keyed by the library listing,
//! the annotations, the settings, N and the array job) writes `text.json` and `assets.json`
//! from the parts' records, exactly as one task would, and deletes the parts. The index bytes
//! do not depend on N. A part of another run is only a source of records to reuse, each when
//! its inputs' digest still matches, like the last index.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{anyhow, Context as _};
use clap::Args as ClapArgs;
use mesa_schemas::artifacts::{AssetIndexArtifact, AssetRecord, ShapesRef, ASSET_INDEX_SCHEMA};
use mesa_schemas::json::{parse_lenient, to_sorted_pretty};
use mesa_stages::annotations::Annotations;
use mesa_stages::assets::budget::AssetBudget;
use mesa_stages::assets::{build_text_index, index_asset, AssetsConfig, INDEX_VERSION};
use mesa_stages::paths::dataset::{
    asset_glb, shapes as shapes_rel, ANNOTATIONS, INDEX, LIBRARY, SHAPES_DIR, TEXT_INDEX,
};
use serde::Serialize;

use crate::cli::{DatasetStageArgs, Global};
use crate::config::Config;
use crate::exit::UsageError;
use crate::fsio::{sha256_hex, sweep_dead_tmp_in, sweep_tmp_for, write_atomic};
use crate::runner::{
    digest_of, DatasetReport, DatasetStage, Executor, Shard, StageContext, RUN_DIR,
};

/// `mesa assets`.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// The dataset, its run flags and --force.
    #[command(flatten)]
    pub stage: DatasetStageArgs,
    /// Exit with code 1 when some asset is invalid (by default invalid assets are listed, and
    /// retrieval never chooses them).
    #[arg(long)]
    pub strict: bool,
    /// Index only asset k of the sorted library when k mod N = I; the last of the N tasks to
    /// finish writes the index (default: from SLURM_ARRAY_TASK_ID / SLURM_ARRAY_TASK_COUNT
    /// when set).
    #[arg(long, value_name = "I/N")]
    pub shard: Option<Shard>,
}

/// Runs `mesa assets`.
pub fn run(args: Args, global: Global) -> anyhow::Result<ExitCode> {
    let mut resolved = args.stage.resolve(global)?;
    let shard = match args.shard {
        Some(shard) => shard,
        None => Shard::from_slurm_env()
            .map_err(UsageError)?
            .unwrap_or_default(),
    };
    // Each shard its own stage lock (the runner's); the merge has one of its own.
    resolved.options.shard = shard;
    resolved.run_dataset(&AssetsStage {
        strict: args.strict,
        shard,
        run_id: std::env::var("SLURM_ARRAY_JOB_ID").unwrap_or_default(),
    })
}

/// The `assets` stage: the asset index, once over the library (or a shard of it).
#[derive(Debug, Default)]
pub struct AssetsStage {
    /// Invalid assets fail the run (exit code 1).
    pub strict: bool,
    /// This task's share of the library (the whole library by default).
    pub shard: Shard,
    /// What tells the parts of one array run from those of another (the Slurm array job id);
    /// empty outside Slurm.
    pub run_id: String,
}

impl DatasetStage for AssetsStage {
    fn name(&self) -> &'static str {
        "assets"
    }

    fn skipped_by_run(&self, ctx: &StageContext<'_>) -> Option<String> {
        let library = ctx.dataset.join(LIBRARY);
        (!library.is_dir()).then(|| {
            format!(
                "{} does not exist: no asset index (retrieve and place need one)",
                library.display()
            )
        })
    }

    fn run(&self, ctx: &StageContext<'_>, exec: &Executor<'_>) -> anyhow::Result<DatasetReport> {
        if self.shard.count > 1 {
            let summary = index_shard(ctx, exec, self.shard, &self.run_id)?;
            let merged_invalid = summary.merged.as_ref().map_or(0, |m| m.invalid.len());
            return Ok(DatasetReport {
                success: !self.strict || (summary.invalid.is_empty() && merged_invalid == 0),
                text: format_shard_summary(&summary),
                record: serde_json::to_value(&summary)?,
            });
        }
        let summary = index_library(ctx.dataset, ctx.config, exec)?;
        Ok(DatasetReport {
            success: !self.strict || summary.invalid.is_empty(),
            text: format_summary(&summary),
            record: serde_json::to_value(&summary)?,
        })
    }
}

/// What a run of `mesa assets` did.
#[derive(Debug, Clone, Default, Serialize)]
pub struct AssetsSummary {
    /// GLB files in the library.
    pub assets: usize,
    /// Valid assets.
    pub valid: usize,
    /// Invalid assets with their reason.
    pub invalid: Vec<(String, String)>,
    /// Records kept from the last run (unchanged inputs).
    pub reused: usize,
    /// Assets indexed by this run.
    pub indexed: usize,
    /// Warnings by uid.
    pub warnings: Vec<(String, String)>,
    /// Annotated uids without a GLB.
    pub annotated_without_glb: Vec<String>,
    /// GLBs without an annotation (retrieval cannot choose them).
    pub glb_without_annotation: Vec<String>,
    /// Assets with a text for the lexical encoder.
    pub text_documents: usize,
    /// Files of the library that are not GLB files and were ignored.
    pub ignored_files: Vec<String>,
    /// Wall time, seconds.
    pub elapsed_s: f64,
}

fn list_library(dataset: &Path) -> anyhow::Result<(Vec<String>, Vec<String>)> {
    let dir = dataset.join(LIBRARY);
    let entries = std::fs::read_dir(&dir).map_err(|e| {
        anyhow!(
            "{}: cannot list the asset library: {e} (expected DATASET/{LIBRARY}/<uid>.glb)",
            dir.display()
        )
    })?;
    let mut uids = Vec::new();
    let mut ignored = Vec::new();
    for entry in entries {
        let entry = entry.with_context(|| format!("{}: cannot list", dir.display()))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.starts_with('.') || !entry.path().is_file() {
            continue;
        }
        match name.strip_suffix(".glb") {
            Some(uid) if !uid.is_empty() => uids.push(uid.to_owned()),
            _ => ignored.push(name),
        }
    }
    uids.sort();
    ignored.sort();
    Ok((uids, ignored))
}

/// The raw JSON of each annotation (its part of the record's input digest).
fn raw_annotations(path: &Path) -> anyhow::Result<BTreeMap<String, String>> {
    if !path.exists() {
        return Ok(BTreeMap::new());
    }
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    let value = parse_lenient(&text).map_err(|e| anyhow!("{}: {e}", path.display()))?;
    Ok(value
        .as_object()
        .map(|entries| {
            entries
                .iter()
                // serde_json's map is sorted: the text is canonical.
                .map(|(uid, v)| (uid.clone(), v.to_string()))
                .collect()
        })
        .unwrap_or_default())
}

fn read_previous(dataset: &Path) -> Option<AssetIndexArtifact> {
    let text = std::fs::read_to_string(dataset.join(INDEX)).ok()?;
    serde_json::from_str(&text).ok()
}

/// One asset: its record and, when it was (re)indexed, its shapes file bytes.
struct Outcome {
    uid: String,
    record: AssetRecord,
    reused: bool,
}

#[allow(clippy::too_many_arguments)]
fn index_one(
    dataset: &Path,
    uid: &str,
    annotations: &Annotations,
    raw: &BTreeMap<String, String>,
    candidates: &Candidates,
    config: &Config,
    config_digest: &str,
    force: bool,
) -> anyhow::Result<Outcome> {
    let file = asset_glb(uid);
    let path = dataset.join(&file);
    let bytes = match std::fs::read(&path) {
        Ok(bytes) => bytes,
        // An unreadable file is one broken asset, not a failed run.
        Err(e) => {
            return Ok(Outcome {
                uid: uid.to_owned(),
                record: AssetRecord {
                    file,
                    glb_bytes: 0,
                    glb_sha256: String::new(),
                    inputs_sha256: String::new(),
                    valid: false,
                    reason: Some(format!("cannot read the file: {e}")),
                    reason_code: Some("io".to_owned()),
                    annotated: annotations.get(uid).is_some(),
                    geometry: None,
                    shapes: None,
                    warnings: Vec::new(),
                },
                reused: false,
            })
        }
    };
    let glb_sha256 = sha256_hex(&bytes);
    let annotation_json = raw.get(uid).map_or("null", String::as_str);
    let inputs_sha256 = sha256_hex(
        format!(
            "mesa asset index {INDEX_VERSION}\n{glb_sha256}\n{annotation_json}\n{config_digest}\n"
        )
        .as_bytes(),
    );
    if !force {
        for old in candidates.get(uid).into_iter().flatten() {
            if old.inputs_sha256 != inputs_sha256 {
                continue;
            }
            let shapes_intact = match &old.shapes {
                None => true,
                Some(s) => std::fs::read(dataset.join(&s.file))
                    .map(|b| sha256_hex(&b) == s.sha256)
                    .unwrap_or(false),
            };
            if shapes_intact {
                return Ok(Outcome {
                    uid: uid.to_owned(),
                    record: old.clone(),
                    reused: true,
                });
            }
        }
    }
    let annotation = annotations.get(uid);
    // A panic in a geometry library must cost one asset, not the run.
    let indexed = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        index_asset(uid, &glb_sha256, &bytes, annotation, &config.assets)
    }));
    let mut record = AssetRecord {
        file,
        glb_bytes: bytes.len() as u64,
        glb_sha256,
        inputs_sha256,
        valid: false,
        reason: None,
        reason_code: None,
        annotated: annotation.is_some(),
        geometry: None,
        shapes: None,
        warnings: Vec::new(),
    };
    let indexed = match indexed {
        Ok(indexed) => indexed,
        Err(_) => {
            record.reason = Some(
                "internal error while indexing this asset (a bug in mesa: please report it with \
                 the GLB)"
                    .to_owned(),
            );
            record.reason_code = Some("internal".to_owned());
            return Ok(Outcome {
                uid: uid.to_owned(),
                record,
                reused: false,
            });
        }
    };
    record.geometry = indexed.geometry;
    record.warnings = indexed.warnings;
    match indexed.invalid {
        Some((code, reason)) => {
            record.reason_code = Some(code);
            record.reason = Some(reason);
        }
        None => record.valid = true,
    }
    if let Some(shapes) = indexed.shapes {
        let rel = shapes_rel(uid);
        let target = dataset.join(&rel);
        // Compact: shapes are numbers, read by programs, and there are thousands of them.
        let bytes = serde_json::to_vec(&shapes).context("serialising shapes")?;
        write_atomic(&target, &bytes)
            .with_context(|| format!("{}: cannot write", target.display()))?;
        record.shapes = Some(ShapesRef {
            file: rel,
            sha256: sha256_hex(&bytes),
            parts: shapes.parts.len() as u64,
        });
    }
    Ok(Outcome {
        uid: uid.to_owned(),
        record,
        reused: false,
    })
}

/// Records an asset may keep when its inputs' digest still matches: the last index's and
/// those of the parts sharded tasks wrote, by uid.
type Candidates = BTreeMap<String, Vec<AssetRecord>>;

/// What every task reads of the library before indexing.
struct Library {
    uids: Vec<String>,
    ignored: Vec<String>,
    annotations: Annotations,
    raw: BTreeMap<String, String>,
    config_digest: String,
}

fn load_library(dataset: &Path, config: &Config) -> anyhow::Result<Library> {
    let (uids, ignored) = list_library(dataset)?;
    let annotations_path = dataset.join(ANNOTATIONS);
    let annotations = if annotations_path.exists() {
        Annotations::read(&annotations_path)?
    } else {
        Annotations::default()
    };
    let raw = raw_annotations(&annotations_path)?;
    Ok(Library {
        uids,
        ignored,
        annotations,
        raw,
        config_digest: assets_config_digest(&config.assets),
    })
}

/// The records a run may reuse: the last index's (unless `with_index` is false: `--force`)
/// and every part's.
fn candidates(dataset: &Path, with_index: bool) -> Candidates {
    let mut out: Candidates = BTreeMap::new();
    if with_index {
        if let Some(previous) = read_previous(dataset) {
            for (uid, record) in previous.assets {
                out.entry(uid).or_default().push(record);
            }
        }
    }
    for part in read_parts(dataset) {
        for (uid, record) in part.records {
            out.entry(uid).or_default().push(record);
        }
    }
    out
}

/// Indexes `uids` of the library on `exec`, in their order.
fn index_uids(
    dataset: &Path,
    library: &Library,
    uids: &[String],
    candidates: &Candidates,
    config: &Config,
    exec: &Executor<'_>,
    force: bool,
) -> anyhow::Result<Vec<Outcome>> {
    // One file an asset: swept of dead writers' temp files once, not beside each file (a
    // listing of the folder an asset, quadratic in the library).
    let shapes = dataset.join(SHAPES_DIR);
    sweep_dead_tmp_in(&shapes).with_context(|| format!("{}: sweeping", shapes.display()))?;
    exec.map("assets", uids, |uid| {
        index_one(
            dataset,
            uid,
            &library.annotations,
            &library.raw,
            candidates,
            config,
            &library.config_digest,
            force,
        )
    })
    .into_iter()
    .collect()
}

/// Indexes the asset library of a dataset, an asset a unit of `exec`.
pub fn index_library(
    dataset: &Path,
    config: &Config,
    exec: &Executor<'_>,
) -> anyhow::Result<AssetsSummary> {
    let force = exec.options().force;
    let started = Instant::now();
    let library = load_library(dataset, config)?;
    let candidates = candidates(dataset, !force);
    let outcomes = index_uids(
        dataset,
        &library,
        &library.uids,
        &candidates,
        config,
        exec,
        force,
    )?;
    let summary = write_index(dataset, config, library, outcomes, started)?;
    remove_parts(dataset)?;
    Ok(summary)
}

/// Writes the index of the whole library from every asset's outcome (in uid order): the
/// summary, stale shapes removed, `text.json`, then `assets.json`.
fn write_index(
    dataset: &Path,
    config: &Config,
    library: Library,
    outcomes: Vec<Outcome>,
    started: Instant,
) -> anyhow::Result<AssetsSummary> {
    let Library {
        uids,
        ignored,
        annotations,
        config_digest,
        ..
    } = library;
    let mut summary = AssetsSummary {
        assets: uids.len(),
        ignored_files: ignored,
        ..AssetsSummary::default()
    };
    let mut records = BTreeMap::new();
    for outcome in outcomes {
        if outcome.reused {
            summary.reused += 1;
        } else {
            summary.indexed += 1;
        }
        if outcome.record.valid {
            summary.valid += 1;
        } else {
            summary.invalid.push((
                outcome.uid.clone(),
                outcome.record.reason.clone().unwrap_or_default(),
            ));
        }
        if !outcome.record.annotated {
            summary.glb_without_annotation.push(outcome.uid.clone());
        }
        summary.warnings.extend(
            outcome
                .record
                .warnings
                .iter()
                .map(|w| (outcome.uid.clone(), w.clone())),
        );
        records.insert(outcome.uid, outcome.record);
    }
    remove_stale_shapes(dataset, &records)?;
    summary.annotated_without_glb = annotations
        .iter()
        .map(|(uid, _)| uid)
        .filter(|uid| !records.contains_key(*uid))
        .map(str::to_owned)
        .collect();

    let text_index = build_text_index(&annotations, &config.assets);
    summary.text_documents = text_index.documents.len();
    write_json(dataset, TEXT_INDEX, &text_index)?;
    let index = AssetIndexArtifact {
        schema: ASSET_INDEX_SCHEMA.to_owned(),
        config_digest,
        assets: records,
        annotated_without_glb: summary.annotated_without_glb.clone(),
    };
    write_json(dataset, INDEX, &index)?;
    summary.elapsed_s = started.elapsed().as_secs_f64();
    Ok(summary)
}

/// Where sharded tasks leave their records for the merge, under the dataset's `.mesa/`.
const PARTS_DIR: &str = "parts/assets";

/// The schema of a part.
const PART_SCHEMA: &str = "mesa.asset-index-part/1";

/// One sharded task's records: `.mesa/parts/assets/<I>-of-<N>.json`.
#[derive(Debug, Serialize, serde::Deserialize)]
struct Part {
    schema: String,
    /// The run this part belongs to (see [`run_key`]): only parts of one run are merged.
    run: String,
    /// `I/N`.
    shard: String,
    /// The records of the shard's assets.
    records: BTreeMap<String, AssetRecord>,
}

fn parts_dir(dataset: &Path) -> PathBuf {
    dataset.join(RUN_DIR).join(PARTS_DIR)
}

fn part_path(dataset: &Path, shard: Shard) -> PathBuf {
    parts_dir(dataset).join(format!("{}-of-{}.json", shard.index, shard.count))
}

/// Every readable part (an unreadable one is a leftover of a killed writer: ignored).
fn read_parts(dataset: &Path) -> Vec<Part> {
    let Ok(entries) = std::fs::read_dir(parts_dir(dataset)) else {
        return Vec::new();
    };
    let mut paths: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .collect();
    paths.sort();
    paths
        .iter()
        .filter_map(|p| std::fs::read_to_string(p).ok())
        .filter_map(|text| serde_json::from_str::<Part>(&text).ok())
        .filter(|part| part.schema == PART_SCHEMA)
        .collect()
}

/// Removes the parts once the index holds them.
fn remove_parts(dataset: &Path) -> anyhow::Result<()> {
    let dir = parts_dir(dataset);
    match std::fs::remove_dir_all(&dir) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => {
            return Err(anyhow!(
                "{}: cannot remove the merged parts: {e}",
                dir.display()
            ))
        }
    }
    // `.mesa/parts/` too when nothing else is in it.
    if let Some(parent) = dir.parent() {
        let _ = std::fs::remove_dir(parent);
    }
    Ok(())
}

/// What identifies one sharded run: the library listing, the annotations, the `[assets]`
/// settings, the number of tasks and the array job. A part of an earlier run (other inputs,
/// or an array that never finished) does not count towards this run's merge.
fn run_key(library: &Library, count: usize, run_id: &str) -> String {
    let mut text = format!(
        "mesa asset parts {INDEX_VERSION}\n{}\n{count}\n{run_id}\n",
        library.config_digest
    );
    for uid in &library.uids {
        text.push_str(uid);
        text.push('\n');
    }
    for (uid, annotation) in &library.raw {
        text.push_str(uid);
        text.push('\t');
        text.push_str(annotation);
        text.push('\n');
    }
    sha256_hex(text.as_bytes())
}

/// What one sharded task of `mesa assets` did.
#[derive(Debug, Clone, Default, Serialize)]
pub struct ShardSummary {
    /// `I/N`.
    pub shard: String,
    /// GLB files in the library.
    pub library: usize,
    /// Assets of this shard.
    pub assets: usize,
    /// Of them, indexed by this task.
    pub indexed: usize,
    /// Of them, records kept (unchanged inputs).
    pub reused: usize,
    /// Invalid assets of this shard with their reason.
    pub invalid: Vec<(String, String)>,
    /// Parts of this run present when this task looked (its own included).
    pub parts_present: usize,
    /// The index this task wrote, when it was the last to finish.
    pub merged: Option<AssetsSummary>,
    /// Whether another task had already merged this task's part.
    pub merged_by_another: bool,
    /// Wall time, seconds.
    pub elapsed_s: f64,
}

/// One sharded task: its share of the library, its part, and the merge when it is the last.
fn index_shard(
    ctx: &StageContext<'_>,
    exec: &Executor<'_>,
    shard: Shard,
    run_id: &str,
) -> anyhow::Result<ShardSummary> {
    let (dataset, config) = (ctx.dataset, ctx.config);
    let force = exec.options().force;
    let started = Instant::now();
    let library = load_library(dataset, config)?;
    let key = run_key(&library, shard.count, run_id);
    let mine: Vec<String> = library
        .uids
        .iter()
        .enumerate()
        .filter(|(k, _)| shard.owns(*k))
        .map(|(_, uid)| uid.clone())
        .collect();
    let outcomes = index_uids(
        dataset,
        &library,
        &mine,
        &candidates(dataset, !force),
        config,
        exec,
        force,
    )?;
    let mut summary = ShardSummary {
        shard: shard.to_string(),
        library: library.uids.len(),
        assets: mine.len(),
        ..ShardSummary::default()
    };
    let mut records = BTreeMap::new();
    for outcome in outcomes {
        if outcome.reused {
            summary.reused += 1;
        } else {
            summary.indexed += 1;
        }
        if !outcome.record.valid {
            summary.invalid.push((
                outcome.uid.clone(),
                outcome.record.reason.clone().unwrap_or_default(),
            ));
        }
        records.insert(outcome.uid, outcome.record);
    }
    let part = Part {
        schema: PART_SCHEMA.to_owned(),
        run: key.clone(),
        shard: shard.to_string(),
        records,
    };
    let own = part_path(dataset, shard);
    write_json_path(&own, &part)?;

    // The merge: one task at a time looks at the parts (the others wait for the lock).
    let merge_config = Config {
        run: crate::config::RunConfig {
            lock: crate::config::LockMode::Wait,
            ..config.run.clone()
        },
        ..config.clone()
    };
    let merge_ctx = StageContext {
        dataset,
        config: &merge_config,
    };
    let _lock = crate::runner::lock::lock_stage(&merge_ctx, "assets-merge", Shard::default())?;
    if !own.exists() {
        // A task that finished after this one wrote its part merged it already.
        summary.merged_by_another = true;
        summary.elapsed_s = started.elapsed().as_secs_f64();
        return Ok(summary);
    }
    let parts: Vec<Part> = read_parts(dataset)
        .into_iter()
        .filter(|p| p.run == key)
        .collect();
    let present: std::collections::BTreeSet<&str> =
        parts.iter().map(|p| p.shard.as_str()).collect();
    summary.parts_present = present.len();
    let complete = (0..shard.count).all(|i| {
        present.contains(
            Shard {
                index: i,
                count: shard.count,
            }
            .to_string()
            .as_str(),
        )
    });
    if complete {
        // Every asset's record is in a part of this run (the library listing, annotations and
        // settings it was keyed by are those read above), indexed by its task from the bytes
        // it hashed: the records one task would write, taken as they are. An asset no part
        // holds (none, when the parts are complete) is indexed here.
        let merge_started = Instant::now();
        let mut from_parts: BTreeMap<String, AssetRecord> = BTreeMap::new();
        for part in parts {
            from_parts.extend(part.records);
        }
        let missing: Vec<String> = library
            .uids
            .iter()
            .filter(|uid| !from_parts.contains_key(*uid))
            .cloned()
            .collect();
        let indexed = index_uids(
            dataset,
            &library,
            &missing,
            &Candidates::new(),
            config,
            exec,
            force,
        )?;
        let mut outcomes: BTreeMap<String, Outcome> =
            indexed.into_iter().map(|o| (o.uid.clone(), o)).collect();
        for (uid, record) in from_parts {
            if library.uids.binary_search(&uid).is_ok() {
                outcomes.insert(
                    uid.clone(),
                    Outcome {
                        uid,
                        record,
                        reused: true,
                    },
                );
            }
        }
        let outcomes: Vec<Outcome> = outcomes.into_values().collect();
        let merged = write_index(dataset, config, library, outcomes, merge_started)?;
        remove_parts(dataset)?;
        summary.merged = Some(merged);
    }
    summary.elapsed_s = started.elapsed().as_secs_f64();
    Ok(summary)
}

/// The summary of one sharded task.
pub fn format_shard_summary(summary: &ShardSummary) -> String {
    use std::fmt::Write as _;
    let mut out = format!(
        "assets (shard {}): {} of {} GLBs ({} indexed, {} unchanged, {} invalid) in {:.2} s\n",
        summary.shard,
        summary.assets,
        summary.library,
        summary.indexed,
        summary.reused,
        summary.invalid.len(),
        summary.elapsed_s
    );
    let count = summary.shard.split('/').nth(1).unwrap_or("?");
    match &summary.merged {
        Some(merged) => {
            let _ = writeln!(
                out,
                "assets (shard {}): every part present: this task merged the index",
                summary.shard
            );
            out.push_str(&format_summary(merged));
        }
        None if summary.merged_by_another => {
            let _ = writeln!(
                out,
                "assets (shard {}): the index was merged by a task that finished later",
                summary.shard
            );
        }
        None => {
            let _ = writeln!(
                out,
                "assets (shard {}): {} of {count} parts written; the last task to finish \
                 merges the index",
                summary.shard, summary.parts_present
            );
        }
    }
    out
}

fn write_json<T: Serialize>(dataset: &Path, rel: &str, value: &T) -> anyhow::Result<()> {
    write_json_path(&dataset.join(rel), value)
}

fn write_json_path<T: Serialize>(path: &Path, value: &T) -> anyhow::Result<()> {
    let bytes =
        to_sorted_pretty(value).with_context(|| format!("serialising {}", path.display()))?;
    sweep_tmp_for(path).with_context(|| format!("{}: sweeping", path.display()))?;
    write_atomic(path, &bytes).with_context(|| format!("{}: cannot write", path.display()))
}

/// The digest of the `[assets]` settings. `[assets.budget]` joined the section after indexes
/// were written: at its defaults it is left out (the JSON ends `,"budget":{..}}`, the last
/// field), so that those indexes, whose assets were all within it unless they stalled, stay
/// valid and a default run gives the bytes it gave before. Any other budget changes the digest.
pub fn assets_config_digest(assets: &AssetsConfig) -> String {
    if assets.budget != AssetBudget::default() {
        return digest_of(assets);
    }
    let full = serde_json::to_vec(assets).unwrap_or_default();
    let budget = serde_json::to_vec(&assets.budget).unwrap_or_default();
    let tail = [b",\"budget\":".as_slice(), &budget, b"}"].concat();
    match full.strip_suffix(tail.as_slice()) {
        Some(head) => sha256_hex(&[head, b"}"].concat()),
        None => digest_of(assets),
    }
}

/// Removes shapes files of assets that are gone or no longer have shapes.
fn remove_stale_shapes(
    dataset: &Path,
    records: &BTreeMap<String, AssetRecord>,
) -> anyhow::Result<()> {
    let dir = dataset.join(SHAPES_DIR);
    let Ok(entries) = std::fs::read_dir(&dir) else {
        return Ok(());
    };
    let keep: std::collections::BTreeSet<PathBuf> = records
        .values()
        .filter_map(|r| r.shapes.as_ref())
        .map(|s| dataset.join(&s.file))
        .collect();
    for entry in entries {
        let path = entry
            .with_context(|| format!("{}: cannot list", dir.display()))?
            .path();
        if path.extension().is_some_and(|e| e == "json") && !keep.contains(&path) {
            std::fs::remove_file(&path).with_context(|| {
                format!("{}: cannot remove a stale shapes file", path.display())
            })?;
        }
    }
    Ok(())
}

/// The human summary of `mesa assets`.
pub fn format_summary(summary: &AssetsSummary) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    let _ = writeln!(
        out,
        "assets: {} GLBs: {} valid, {} invalid ({} indexed, {} unchanged) in {:.2} s; {} asset \
         texts indexed",
        summary.assets,
        summary.valid,
        summary.invalid.len(),
        summary.indexed,
        summary.reused,
        summary.elapsed_s,
        summary.text_documents
    );
    for (uid, reason) in &summary.invalid {
        let _ = writeln!(out, "  invalid {uid}: {reason}");
    }
    const SHOWN: usize = 10;
    let lists = [
        (
            "annotated but no GLB in the library",
            &summary.annotated_without_glb,
        ),
        (
            "GLBs without an annotation (retrieval cannot choose them)",
            &summary.glb_without_annotation,
        ),
        ("files ignored (not .glb)", &summary.ignored_files),
    ];
    for (what, list) in lists {
        if !list.is_empty() {
            let shown: Vec<&str> = list.iter().take(SHOWN).map(String::as_str).collect();
            let more = if list.len() > SHOWN {
                format!(", ... ({} in all)", list.len())
            } else {
                String::new()
            };
            let _ = writeln!(out, "  {what}: {}{more}", shown.join(", "));
        }
    }
    for (uid, warning) in summary.warnings.iter().take(SHOWN) {
        let _ = writeln!(out, "  warning {uid}: {warning}");
    }
    if summary.warnings.len() > SHOWN {
        let _ = writeln!(
            out,
            "  ... and {} more warnings (in {INDEX})",
            summary.warnings.len() - SHOWN
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_default_budget_leaves_the_assets_digest_as_it_was() {
        // The digest of the default [assets] section, pinned: [assets.budget] at its default
        // is left out of it (so adding that section changed nothing), and any other change of
        // the defaults must be deliberate (decomposition_most_parts came with INDEX_VERSION 4,
        // which re-indexes every asset anyway).
        let config = AssetsConfig::default();
        assert_eq!(
            assets_config_digest(&config),
            "efa7a813eab8eb2146e258e067dcf6654543c8a1e5a532ad4dc5af2ade10e730"
        );
        let tighter = AssetsConfig {
            budget: AssetBudget {
                triangles: 1000,
                ..AssetBudget::default()
            },
            ..AssetsConfig::default()
        };
        assert_eq!(assets_config_digest(&tighter), digest_of(&tighter));
        assert_ne!(
            assets_config_digest(&tighter),
            assets_config_digest(&config)
        );
    }
}
