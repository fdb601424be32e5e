//! The registry of artifact kinds: name, schema id, file form, JSON Schema and semantic checks.

use std::sync::OnceLock;

use schemars::JsonSchema;
use serde::de::DeserializeOwned;
use serde_json::Value;

use crate::annotate::{
    AnnotateReject, AnnotateSummary, ANNOTATE_REJECT_SCHEMA, ANNOTATE_SUMMARY_SCHEMA,
};
use crate::annotation::*;
use crate::artifacts::*;
use crate::eval::{EvalMetrics, EvalSample, EVAL_METRICS_SCHEMA, EVAL_SAMPLE_SCHEMA};
use crate::layout::{DatasetLayout, LAYOUT_SCHEMA};
use crate::llm::{GalleryRecord, LlmLayout, TaskInfo};
use crate::render::{
    annotation_problems, AssetAnnotationsFile, RenderCameraArtifact, ReportStats, ReportThumbs,
    RENDER_CAMERA_SCHEMA, REPORT_STATS_SCHEMA, REPORT_THUMBS_SCHEMA,
};
use crate::validate::{nonfinite_problems, Problem, Validator};

/// How a kind's file is laid out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FileForm {
    /// One JSON document.
    Json,
    /// One JSON document per non-empty line.
    JsonLines,
}

/// An artifact kind.
pub struct Kind {
    /// Short name, used by `mesa validate --kind` and for the schema file name.
    pub name: &'static str,
    /// The `schema` id its files carry; `None` for official formats, which carry none.
    pub schema_id: Option<&'static str>,
    /// One document or JSON Lines.
    pub form: FileForm,
    /// What the kind is, for `--help` and the docs.
    pub summary: &'static str,
    generate: fn() -> Value,
    semantic: fn(&Value) -> Vec<Problem>,
}

impl std::fmt::Debug for Kind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Kind").field("name", &self.name).finish()
    }
}

fn schema_of<T: JsonSchema>() -> Value {
    schemars::schema_for!(T).to_value()
}

fn no_semantics(_: &Value) -> Vec<Problem> {
    Vec::new()
}

fn typed<T: DeserializeOwned>(value: &Value, check: impl Fn(&T) -> Vec<Problem>) -> Vec<Problem> {
    // Read from the borrowed value: no copy of the document.
    match T::deserialize(value) {
        Ok(typed) => check(&typed),
        // The structural walk already reported why; nothing more to say here.
        Err(_) => Vec::new(),
    }
}

/// Every kind mesa knows.
pub fn kinds() -> &'static [Kind] {
    static KINDS: OnceLock<Vec<Kind>> = OnceLock::new();
    KINDS.get_or_init(|| {
        vec![
            Kind {
                name: "layout",
                schema_id: Some(LAYOUT_SCHEMA),
                form: FileForm::Json,
                summary:
                    "dataset layout (coarse/, refined/, qa/ layout.json; MesaTask-10K layout.json)",
                generate: schema_of::<DatasetLayout>,
                semantic: |v| typed(v, DatasetLayout::problems),
            },
            Kind {
                name: "llm-layout",
                schema_id: None,
                form: FileForm::Json,
                summary: "LLM layout (the model's output JSON: cm, z_rotation in degrees)",
                generate: schema_of::<LlmLayout>,
                semantic: |v| typed(v, LlmLayout::problems),
            },
            Kind {
                name: "task-info",
                schema_id: None,
                form: FileForm::Json,
                summary: "task info (the model's input JSON)",
                generate: schema_of::<TaskInfo>,
                semantic: |v| typed(v, TaskInfo::problems),
            },
            Kind {
                name: "gallery-record",
                schema_id: None,
                form: FileForm::Json,
                summary: "a published MesaTask record (prompt, task, reasoning, graph, layout)",
                generate: schema_of::<GalleryRecord>,
                semantic: |v| {
                    typed(v, |r: &GalleryRecord| match r.scene_layout_json.resolve() {
                        Ok(layout) => prefix(layout.problems(), "$.scene_layout_json"),
                        Err(e) => vec![Problem::new(
                            "$.scene_layout_json",
                            format!("does not parse as an LLM layout: {e}"),
                            "an LLM layout, inline or as a JSON string",
                        )],
                    })
                },
            },
            Kind {
                name: "camera",
                schema_id: None,
                form: FileForm::Json,
                summary: "input/camera.json (intrinsics or a field of view)",
                generate: schema_of::<CameraJson>,
                semantic: no_semantics,
            },
            Kind {
                name: "instances",
                schema_id: None,
                form: FileForm::Json,
                summary: "input/instances.json (labels and descriptions by mask id)",
                generate: schema_of::<InstancesJson>,
                semantic: no_semantics,
            },
            Kind {
                name: "lift",
                schema_id: Some(LIFT_SCHEMA),
                form: FileForm::Json,
                summary: "coarse/lift.json (table frame, zone, per-instance boxes)",
                generate: schema_of::<LiftArtifact>,
                semantic: no_semantics,
            },
            Kind {
                name: "retrieval",
                schema_id: Some(RETRIEVAL_SCHEMA),
                form: FileForm::Json,
                summary: "coarse/retrieval.json (candidates and scores per instance)",
                generate: schema_of::<RetrievalArtifact>,
                semantic: no_semantics,
            },
            Kind {
                name: "asset-index",
                schema_id: Some(ASSET_INDEX_SCHEMA),
                form: FileForm::Json,
                summary: "assets/index/assets.json (per-asset bounds, counts, validity)",
                generate: schema_of::<AssetIndexArtifact>,
                semantic: no_semantics,
            },
            Kind {
                name: "text-index",
                schema_id: Some(TEXT_INDEX_SCHEMA),
                form: FileForm::Json,
                summary: "assets/index/text.json (asset texts for the lexical encoder)",
                generate: schema_of::<TextIndexArtifact>,
                semantic: no_semantics,
            },
            Kind {
                name: "shapes",
                schema_id: Some(SHAPES_SCHEMA),
                form: FileForm::Json,
                summary: "assets/index/shapes/<uid>.json (convex hull and decomposition)",
                generate: schema_of::<ShapesArtifact>,
                semantic: no_semantics,
            },
            Kind {
                name: "pack-index",
                schema_id: Some(PACK_INDEX_SCHEMA),
                form: FileForm::Json,
                summary: "pack/index.json (the annotator pack: objects, assets, snapshots)",
                generate: schema_of::<PackIndexArtifact>,
                semantic: no_semantics,
            },
            Kind {
                name: "ingest-diff",
                schema_id: Some(INGEST_DIFF_SCHEMA),
                form: FileForm::Json,
                summary: "refined/diff.json (what the annotator changed)",
                generate: schema_of::<IngestDiffArtifact>,
                semantic: no_semantics,
            },
            Kind {
                name: "check",
                schema_id: Some(CHECK_SCHEMA),
                form: FileForm::Json,
                summary: "qa/check.json (collisions, floating, zone violations, settling)",
                generate: schema_of::<CheckArtifact>,
                semantic: no_semantics,
            },
            Kind {
                name: "eval-metrics",
                schema_id: Some(EVAL_METRICS_SCHEMA),
                form: FileForm::Json,
                summary: "eval/<name>/metrics.json (the benchmark's numbers, `mesa eval`)",
                generate: schema_of::<EvalMetrics>,
                semantic: no_semantics,
            },
            Kind {
                name: "eval-sample",
                schema_id: Some(EVAL_SAMPLE_SCHEMA),
                form: FileForm::JsonLines,
                summary: "eval/<name>/samples.jsonl (one evaluated sample per line, `mesa eval`)",
                generate: schema_of::<EvalSample>,
                semantic: no_semantics,
            },
            Kind {
                name: "check-summary",
                schema_id: Some(CHECK_SUMMARY_SCHEMA),
                form: FileForm::Json,
                summary:
                    "qa/summary.json (collision rates over the dataset, before and after settling)",
                generate: schema_of::<CheckSummaryArtifact>,
                semantic: no_semantics,
            },
            Kind {
                name: "export",
                schema_id: Some(EXPORT_SCHEMA),
                form: FileForm::Json,
                summary: "sim/export.json (the simulator export: formats, masses, parts)",
                generate: schema_of::<ExportArtifact>,
                semantic: no_semantics,
            },
            Kind {
                name: "urdf-scene",
                schema_id: Some(URDF_SCENE_SCHEMA),
                form: FileForm::Json,
                summary: "sim/urdf/scene.json (each URDF of a scene and its pose)",
                generate: schema_of::<UrdfSceneArtifact>,
                semantic: no_semantics,
            },
            Kind {
                name: "graph",
                schema_id: Some(GRAPH_SCHEMA),
                form: FileForm::Json,
                summary: "graph/graph.json (nodes and edges with their numbers)",
                generate: schema_of::<GraphArtifact>,
                semantic: no_semantics,
            },
            Kind {
                name: "tasks",
                schema_id: Some(TASKS_SCHEMA),
                form: FileForm::JsonLines,
                summary: "tasks/tasks.jsonl (one task with its reasoning per line)",
                generate: schema_of::<TaskRecord>,
                semantic: |v| {
                    typed(v, |t: &TaskRecord| {
                        prefix(t.task_info.problems(), "$.task_info")
                    })
                },
            },
            Kind {
                name: "task-rejects",
                schema_id: Some(TASK_REJECT_SCHEMA),
                form: FileForm::JsonLines,
                summary: "tasks/rejects.jsonl (model replies that failed validation, with why)",
                generate: schema_of::<TaskReject>,
                semantic: no_semantics,
            },
            Kind {
                name: "sft",
                schema_id: None,
                form: FileForm::Json,
                summary: "records/sft.json, records/test.json (LLaMA-Factory alpaca records)",
                generate: schema_of::<Vec<SftRecord>>,
                semantic: no_semantics,
            },
            Kind {
                name: "dpo",
                schema_id: None,
                form: FileForm::Json,
                summary: "records/dpo.json (LLaMA-Factory alpaca preference records)",
                generate: schema_of::<Vec<DpoRecord>>,
                semantic: no_semantics,
            },
            Kind {
                name: "trl-sft",
                schema_id: None,
                form: FileForm::JsonLines,
                summary: "records/trl_sft.jsonl, records/trl_test.jsonl (TRL conversational SFT)",
                generate: schema_of::<TrlSftRecord>,
                semantic: no_semantics,
            },
            Kind {
                name: "trl-dpo",
                schema_id: None,
                form: FileForm::JsonLines,
                summary: "records/trl_dpo.jsonl (TRL conversational preference)",
                generate: schema_of::<TrlDpoRecord>,
                semantic: no_semantics,
            },
            Kind {
                name: "dataset-info",
                schema_id: None,
                form: FileForm::Json,
                summary: "records/dataset_info.json (LLaMA-Factory dataset registry)",
                generate: schema_of::<std::collections::BTreeMap<String, DatasetInfoEntry>>,
                semantic: no_semantics,
            },
            Kind {
                name: "split",
                schema_id: Some(SPLIT_SCHEMA),
                form: FileForm::Json,
                summary: "records/split.json (train / dpo / test by scene)",
                generate: schema_of::<SplitArtifact>,
                semantic: no_semantics,
            },
            Kind {
                name: "marker",
                schema_id: Some(MARKER_SCHEMA),
                form: FileForm::Json,
                summary: ".mesa/markers/... (the runner's done / failed markers)",
                generate: schema_of::<RunMarker>,
                semantic: no_semantics,
            },
            Kind {
                name: "truth-scene",
                schema_id: Some(TRUTH_SCENE_SCHEMA),
                form: FileForm::Json,
                summary: "truth/scene.json of a demo scene (exact camera, pose, depth noise)",
                generate: schema_of::<TruthScene>,
                semantic: no_semantics,
            },
            Kind {
                name: "render-camera",
                schema_id: Some(RENDER_CAMERA_SCHEMA),
                form: FileForm::Json,
                summary: "render/<view>_camera.json (intrinsics and pose of a rendered view)",
                generate: schema_of::<RenderCameraArtifact>,
                semantic: no_semantics,
            },
            Kind {
                name: "report-stats",
                schema_id: Some(REPORT_STATS_SCHEMA),
                form: FileForm::Json,
                summary: "report/stats.json (dataset statistics)",
                generate: schema_of::<ReportStats>,
                semantic: no_semantics,
            },
            Kind {
                name: "report-thumbs",
                schema_id: Some(REPORT_THUMBS_SCHEMA),
                form: FileForm::Json,
                summary: "report/thumbs/sources.json (the front view each thumbnail was made from)",
                generate: schema_of::<ReportThumbs>,
                semantic: no_semantics,
            },
            Kind {
                name: "asset-annotations",
                schema_id: None,
                form: FileForm::Json,
                summary: "assets/annotations.json, a release's Asset_annotation.json (per uid)",
                generate: schema_of::<AssetAnnotationsFile>,
                semantic: |v| typed(v, annotation_problems),
            },
            Kind {
                name: "annotate-rejects",
                schema_id: Some(ANNOTATE_REJECT_SCHEMA),
                form: FileForm::JsonLines,
                summary: "assets/annotate/rejects.jsonl (asset annotation replies that failed \
                          validation, with why)",
                generate: schema_of::<AnnotateReject>,
                semantic: no_semantics,
            },
            Kind {
                name: "annotate-summary",
                schema_id: Some(ANNOTATE_SUMMARY_SCHEMA),
                form: FileForm::Json,
                summary: "assets/annotate/summary.json (what `mesa annotate assets` did, \
                          annotations by source)",
                generate: schema_of::<AnnotateSummary>,
                semantic: no_semantics,
            },
            Kind {
                name: "asset-views",
                schema_id: Some(ASSET_VIEWS_SCHEMA),
                form: FileForm::Json,
                summary: "assets/renders/<uid>/views.json (what an asset's views were made from)",
                generate: schema_of::<AssetViewsRecord>,
                semantic: no_semantics,
            },
            Kind {
                name: "chat-reply",
                schema_id: Some(CHAT_REPLY_SCHEMA),
                form: FileForm::Json,
                summary: ".mesa/cache/chat/<aa>/<digest>.json (a cached model reply)",
                generate: schema_of::<CachedChatReply>,
                semantic: no_semantics,
            },
            Kind {
                name: "truth-instances",
                schema_id: Some(TRUTH_INSTANCES_SCHEMA),
                form: FileForm::Json,
                summary: "truth/instances.json of a demo scene (mask id -> instance, asset)",
                generate: schema_of::<TruthInstances>,
                semantic: no_semantics,
            },
        ]
    })
}

fn prefix(problems: Vec<Problem>, at: &str) -> Vec<Problem> {
    problems
        .into_iter()
        .map(|mut p| {
            p.path = p.path.replacen('$', at, 1);
            p
        })
        .collect()
}

impl Kind {
    /// Looks a kind up by name.
    pub fn by_name(name: &str) -> Option<&'static Kind> {
        kinds().iter().find(|k| k.name == name)
    }

    /// Looks a kind up by the `schema` id its files carry.
    pub fn by_schema_id(id: &str) -> Option<&'static Kind> {
        kinds().iter().find(|k| k.schema_id == Some(id))
    }

    /// The kind's JSON Schema, generated from its Rust type (the `schema` field pinned to the
    /// kind's id).
    pub fn json_schema(&self) -> &'static Value {
        static CACHE: OnceLock<Vec<OnceLock<Value>>> = OnceLock::new();
        self.cached(&CACHE, || {
            let mut schema = (self.generate)();
            if let Some(id) = self.schema_id {
                if let Some(field) = schema.pointer_mut("/properties/schema") {
                    field["const"] = Value::String(id.to_owned());
                }
                schema["$id"] = Value::String(format!("https://mesa.dev/schemas/{id}"));
            }
            schema
        })
    }

    /// The kind's JSON Schema made ready to validate documents, once per process.
    fn validator(&self) -> &'static Validator<'static> {
        static CACHE: OnceLock<Vec<OnceLock<Validator<'static>>>> = OnceLock::new();
        self.cached(&CACHE, || Validator::new(self.json_schema()))
    }

    /// This kind's slot of `cache` (one slot per kind, in the order of [`kinds`]), filled by
    /// `make` the first time this kind asks for it.
    fn cached<T>(
        &self,
        cache: &'static OnceLock<Vec<OnceLock<T>>>,
        make: impl FnOnce() -> T,
    ) -> &'static T {
        let slots = cache.get_or_init(|| kinds().iter().map(|_| OnceLock::new()).collect());
        let index = kinds()
            .iter()
            .position(|k| k.name == self.name)
            .expect("every kind is listed");
        slots[index].get_or_init(make)
    }

    /// Validates one JSON document of this kind: non-finite numbers, the JSON Schema, then the
    /// semantic checks (only when the structure is sound, so each problem is reported once).
    pub fn validate_value(&self, value: &Value) -> Vec<Problem> {
        let mut problems = self.structure_problems(value);
        if problems.is_empty() {
            problems.extend((self.semantic)(value));
        }
        problems
    }

    /// The first part of [`Kind::validate_value`]: non-finite numbers and the JSON Schema. A
    /// reader that converts the document to its type anyway runs the semantic checks on the
    /// typed value itself, converting once.
    pub fn structure_problems(&self, value: &Value) -> Vec<Problem> {
        let mut problems = Vec::new();
        nonfinite_problems(value, "$", &mut problems);
        self.validator().validate(value, "$", &mut problems);
        problems
    }
}

/// Finds the kind of a document from its `schema` field.
pub fn kind_of_document(value: &Value) -> Result<&'static Kind, Problem> {
    let Some(schema) = value.get("schema") else {
        return Err(Problem::new(
            "$",
            "has no \"schema\" field",
            "a mesa artifact with \"schema\": \"mesa.<kind>/<n>\", or pass --kind for an \
             official file (layout, llm-layout, task-info, gallery-record, camera, instances, \
             sft, dpo, trl-sft, trl-dpo, dataset-info)",
        ));
    };
    let Some(id) = schema.as_str() else {
        return Err(Problem::new(
            "$.schema",
            crate::validate::describe(schema),
            "a string \"mesa.<kind>/<n>\"",
        ));
    };
    if let Some(kind) = Kind::by_schema_id(id) {
        return Ok(kind);
    }
    let known: Vec<&str> = kinds().iter().filter_map(|k| k.schema_id).collect();
    let family = id.split('/').next().unwrap_or(id);
    if let Some(current) = known.iter().find(|k| k.split('/').next() == Some(family)) {
        return Err(Problem::new(
            "$.schema",
            format!("unsupported version \"{id}\""),
            format!("\"{current}\" (this mesa reads that version)"),
        ));
    }
    Err(Problem::new(
        "$.schema",
        format!("unknown schema \"{id}\""),
        format!("one of {}", known.join(", ")),
    ))
}
