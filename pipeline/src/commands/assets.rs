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
use crate::fsio::{sha256_hex, sweep_tmp_for, write_atomic};
use crate::runner::{digest_of, DatasetReport, DatasetStage, Executor, Shard, StageContext};

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
}

/// Runs `mesa assets`.
pub fn run(args: Args, global: Global) -> anyhow::Result<ExitCode> {
    let resolved = args.stage.resolve(global)?;
    // Under a Slurm array, one task indexes the library; the others have nothing to do.
    if let Some(shard) = Shard::from_slurm_env().map_err(UsageError)? {
        if shard.index != 0 {
            eprintln!(
                "assets: the library is indexed by array task 0 (this is task {shard}): nothing \
                 to do here"
            );
            return Ok(ExitCode::SUCCESS);
        }
    }
    resolved.run_dataset(&AssetsStage {
        strict: args.strict,
    })
}

/// The `assets` stage: the asset index, once over the library.
#[derive(Debug, Default)]
pub struct AssetsStage {
    /// Invalid assets fail the run (exit code 1).
    pub strict: bool,
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
    previous: Option<&AssetIndexArtifact>,
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
        if let Some(old) = previous.and_then(|p| p.assets.get(uid)) {
            let shapes_intact = match &old.shapes {
                None => true,
                Some(s) => std::fs::read(dataset.join(&s.file))
                    .map(|b| sha256_hex(&b) == s.sha256)
                    .unwrap_or(false),
            };
            if old.inputs_sha256 == inputs_sha256 && shapes_intact {
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
        sweep_tmp_for(&target).with_context(|| format!("{}: sweeping", target.display()))?;
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

/// Indexes the asset library of a dataset, an asset a unit of `exec`.
pub fn index_library(
    dataset: &Path,
    config: &Config,
    exec: &Executor<'_>,
) -> anyhow::Result<AssetsSummary> {
    let force = exec.options().force;
    let started = Instant::now();
    let (uids, ignored) = list_library(dataset)?;
    let annotations_path = dataset.join(ANNOTATIONS);
    let annotations = if annotations_path.exists() {
        Annotations::read(&annotations_path)?
    } else {
        Annotations::default()
    };
    let raw = raw_annotations(&annotations_path)?;
    let previous = if force { None } else { read_previous(dataset) };
    let config_digest = assets_config_digest(&config.assets);
    let outcomes: Vec<anyhow::Result<Outcome>> = exec.map("assets", &uids, |uid| {
        index_one(
            dataset,
            uid,
            &annotations,
            &raw,
            previous.as_ref(),
            config,
            &config_digest,
            force,
        )
    });
    let mut summary = AssetsSummary {
        assets: uids.len(),
        ignored_files: ignored,
        ..AssetsSummary::default()
    };
    let mut records = BTreeMap::new();
    for outcome in outcomes {
        let outcome = outcome?;
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

fn write_json<T: Serialize>(dataset: &Path, rel: &str, value: &T) -> anyhow::Result<()> {
    let path = dataset.join(rel);
    let bytes = to_sorted_pretty(value).with_context(|| format!("serialising {rel}"))?;
    sweep_tmp_for(&path).with_context(|| format!("{}: sweeping", path.display()))?;
    write_atomic(&path, &bytes).with_context(|| format!("{}: cannot write", path.display()))
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
        // The digest of the default [assets] section before [assets.budget] existed: indexes
        // written then stay valid, and `mesa assets` on the demo gives the same bytes.
        let config = AssetsConfig::default();
        assert_eq!(
            assets_config_digest(&config),
            "1d6314fc44f0c11e6c16a526f518565fba41ca48a8eac0ce87ea6277db961b43"
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
