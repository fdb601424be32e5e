//! Every artifact of a demo `mesa run`, read back into its Rust type, is written by mesa's
//! sorted-key writer (`json::to_sorted_pretty`, `json::to_sorted_line`) byte for byte as
//! serde_json writes it through its `Value` tree, the way mesa wrote every file before the
//! writer existed. The files' kinds come from their `schema` fields (and, for the files of
//! official formats without one, from their names); the test requires most kinds of the run to
//! be covered, so that it cannot pass on an empty tree.

mod common;

use std::collections::BTreeSet;

use mesa_schemas::annotate::{AnnotateReject, AnnotateSummary};
use mesa_schemas::annotation::{IngestDiffArtifact, PackIndexArtifact};
use mesa_schemas::artifacts::*;
use mesa_schemas::json::{to_sorted_line, to_sorted_pretty};
use mesa_schemas::llm::{GalleryRecord, LlmLayout, TaskInfo};
use mesa_schemas::render::{AssetAnnotationsFile, RenderCameraArtifact, ReportStats, ReportThumbs};
use mesa_schemas::{kind_of_document, DatasetLayout};
use serde::de::DeserializeOwned;
use serde::Serialize;
use serde_json::Value;

/// A writer of sorted JSON: pretty (with its newline) and on one line.
type Writer<T> = fn(&T) -> Result<(Vec<u8>, String), serde_json::Error>;

/// mesa's writer.
fn mesa_writer<T: Serialize>(typed: &T) -> Result<(Vec<u8>, String), serde_json::Error> {
    Ok((to_sorted_pretty(typed)?, to_sorted_line(typed)?))
}

/// Reads `value` as a `T` and writes it with `writer` and through serde_json's `Value`; `Err`
/// names what differs.
fn both_ways_with<T: DeserializeOwned + Serialize>(
    value: &Value,
    writer: Writer<T>,
) -> Result<(), String> {
    let typed: T = serde_json::from_value(value.clone()).map_err(|e| format!("read: {e}"))?;
    let tree = serde_json::to_value(&typed).map_err(|e| e.to_string())?;
    let mut pretty = serde_json::to_vec_pretty(&tree).map_err(|e| e.to_string())?;
    pretty.push(b'\n');
    let line = serde_json::to_string(&tree).map_err(|e| e.to_string())?;
    let (written, written_line) = writer(&typed).map_err(|e| e.to_string())?;
    if written != pretty {
        return Err(format!(
            "pretty differs:\n{}\nagainst\n{}",
            String::from_utf8_lossy(&written),
            String::from_utf8_lossy(&pretty)
        ));
    }
    if written_line != line {
        return Err(format!(
            "one line differs:\n{written_line}\nagainst\n{line}"
        ));
    }
    Ok(())
}

fn both_ways<T: DeserializeOwned + Serialize>(value: &Value) -> Result<(), String> {
    both_ways_with::<T>(value, mesa_writer::<T>)
}

/// The typed comparison for a kind, by the kind's name; `None` for a kind this test does not
/// know (reported, and counted against the coverage).
fn compare(kind: &str, value: &Value) -> Option<Result<(), String>> {
    Some(match kind {
        "layout" => both_ways::<DatasetLayout>(value),
        "llm-layout" => both_ways::<LlmLayout>(value),
        "task-info" => both_ways::<TaskInfo>(value),
        "gallery-record" => both_ways::<GalleryRecord>(value),
        "camera" => both_ways::<CameraJson>(value),
        "instances" => both_ways::<InstancesJson>(value),
        "lift" => both_ways::<LiftArtifact>(value),
        "retrieval" => both_ways::<RetrievalArtifact>(value),
        "asset-index" => both_ways::<AssetIndexArtifact>(value),
        "text-index" => both_ways::<TextIndexArtifact>(value),
        "shapes" => both_ways::<ShapesArtifact>(value),
        "pack-index" => both_ways::<PackIndexArtifact>(value),
        "ingest-diff" => both_ways::<IngestDiffArtifact>(value),
        "check" => both_ways::<CheckArtifact>(value),
        "check-summary" => both_ways::<CheckSummaryArtifact>(value),
        "graph" => both_ways::<GraphArtifact>(value),
        "tasks" => both_ways::<TaskRecord>(value),
        "task-rejects" => both_ways::<TaskReject>(value),
        "sft" => both_ways::<Vec<SftRecord>>(value),
        "dpo" => both_ways::<Vec<DpoRecord>>(value),
        "trl-sft" => both_ways::<TrlSftRecord>(value),
        "trl-dpo" => both_ways::<TrlDpoRecord>(value),
        "dataset-info" => both_ways::<std::collections::BTreeMap<String, DatasetInfoEntry>>(value),
        "split" => both_ways::<SplitArtifact>(value),
        "marker" => both_ways::<RunMarker>(value),
        "truth-scene" => both_ways::<TruthScene>(value),
        "truth-instances" => both_ways::<TruthInstances>(value),
        "render-camera" => both_ways::<RenderCameraArtifact>(value),
        "report-stats" => both_ways::<ReportStats>(value),
        "report-thumbs" => both_ways::<ReportThumbs>(value),
        "asset-annotations" => both_ways::<AssetAnnotationsFile>(value),
        "annotate-rejects" => both_ways::<AnnotateReject>(value),
        "annotate-summary" => both_ways::<AnnotateSummary>(value),
        "asset-views" => both_ways::<AssetViewsRecord>(value),
        "chat-reply" => both_ways::<CachedChatReply>(value),
        _ => return None,
    })
}

/// The kind of a document: its `schema` field, else its file's name (official formats).
fn kind_of(rel: &str, value: &Value) -> Option<&'static str> {
    if value.get("schema").is_some() {
        return kind_of_document(value).ok().map(|k| k.name);
    }
    let name = rel.rsplit('/').next().unwrap_or(rel);
    Some(match name {
        "sft.json" | "test.json" => "sft",
        "dpo.json" => "dpo",
        "trl_sft.jsonl" | "trl_test.jsonl" => "trl-sft",
        "trl_dpo.jsonl" => "trl-dpo",
        "dataset_info.json" => "dataset-info",
        "camera.json" => "camera",
        "instances.json" if rel.contains("/input/") => "instances",
        "annotations.json" => "asset-annotations",
        _ => return None,
    })
}

#[test]
fn every_artifact_of_a_demo_run_is_written_as_the_value_tree_writes_it() {
    let root = tempfile::tempdir().expect("tempdir");
    let dir = root.path().join("demo");
    common::mesa()
        .args(["demo", "--scenes", "3", "--seed", "11", "-q"])
        .arg(&dir)
        .assert()
        .success();
    common::mesa()
        .args(["run", "--progress", "off", "-q"])
        .arg(&dir)
        .assert()
        .success();

    let mut covered = BTreeSet::new();
    let mut unknown = BTreeSet::new();
    let mut documents = 0;
    let mut failures = Vec::new();
    for (rel, bytes) in common::all_files(&dir) {
        let lines = rel.ends_with(".jsonl");
        if !(lines || rel.ends_with(".json")) {
            continue;
        }
        let text = String::from_utf8(bytes).expect("UTF-8");
        let values: Vec<Value> = if lines {
            text.lines()
                .filter(|l| !l.trim().is_empty())
                .map(|l| serde_json::from_str(l).expect("a JSON line"))
                .collect()
        } else {
            vec![serde_json::from_str(&text).expect("JSON")]
        };
        for value in &values {
            let Some(kind) = kind_of(&rel, value) else {
                unknown.insert(rel.clone());
                continue;
            };
            match compare(kind, value) {
                Some(Ok(())) => {
                    covered.insert(kind);
                    documents += 1;
                }
                Some(Err(e)) => failures.push(format!("{rel} ({kind}): {e}")),
                None => {
                    unknown.insert(format!("{rel} (kind {kind})"));
                }
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
    eprintln!(
        "{documents} documents of {} kinds written alike: {covered:?}; not compared: {unknown:?}",
        covered.len()
    );
    // The run writes these kinds at least; a tree the walk misses would fail here.
    for kind in [
        "layout",
        "camera",
        "instances",
        "lift",
        "retrieval",
        "asset-index",
        "shapes",
        "pack-index",
        "ingest-diff",
        "check",
        "graph",
        "tasks",
        "sft",
        "dpo",
        "trl-sft",
        "trl-dpo",
        "dataset-info",
        "split",
        "marker",
        "truth-scene",
        "render-camera",
        "report-stats",
    ] {
        assert!(
            covered.contains(kind),
            "no {kind} document compared: {covered:?}"
        );
    }
}

/// Control: the same comparison fails for serde_json's direct writer (struct fields in
/// declaration order, f32 not widened) on a document of the run's kinds.
#[test]
fn the_comparison_sees_fields_in_declaration_order() {
    fn declared<T: Serialize>(typed: &T) -> Result<(Vec<u8>, String), serde_json::Error> {
        let mut pretty = serde_json::to_vec_pretty(typed)?;
        pretty.push(b'\n');
        Ok((pretty, serde_json::to_string(typed)?))
    }
    let text = std::fs::read_to_string(
        common::shared()
            .join("realdata/layouts/mesatask_gallery")
            .join(
                std::fs::read_dir(common::shared().join("realdata/layouts/mesatask_gallery"))
                    .expect("gallery")
                    .map(|e| e.expect("entry").file_name())
                    .filter(|n| n.to_string_lossy().ends_with(".json"))
                    .min()
                    .expect("a record"),
            ),
    )
    .expect("read");
    let record: Value = serde_json::from_str(&text).expect("JSON");
    assert!(both_ways::<GalleryRecord>(&record).is_ok());
    let e = both_ways_with::<GalleryRecord>(&record, declared::<GalleryRecord>)
        .expect_err("declaration order differs");
    assert!(e.contains("differs"), "{e}");
}
