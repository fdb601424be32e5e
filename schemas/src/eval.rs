//! The artifacts of `mesa eval` (the benchmark of task-to-scene models, `docs/eval.md`):
//! `eval/<name>/metrics.json` ([`EvalMetrics`]) and one [`EvalSample`] per line of
//! `eval/<name>/samples.jsonl`.

use std::collections::BTreeMap;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// The `schema` of `eval/<name>/metrics.json`.
pub const EVAL_METRICS_SCHEMA: &str = "mesa.eval-metrics/1";
/// The `schema` of each line of `eval/<name>/samples.jsonl`.
pub const EVAL_SAMPLE_SCHEMA: &str = "mesa.eval-sample/1";

/// `eval/<name>/metrics.json`: the benchmark's numbers over every sample.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct EvalMetrics {
    /// `mesa.eval-metrics/1`.
    pub schema: String,
    /// The model's name (`--name`).
    pub name: String,
    /// Where the prompts came from (a file name relative to the dataset, or the inference
    /// folder given).
    pub prompts: String,
    /// Prompts read.
    pub prompts_total: u64,
    /// Samples evaluated: one per prompt (a prompt without an output is a failure).
    pub samples: u64,
    /// Samples whose output passes the paper's success rule.
    pub succeeded: u64,
    /// succeeded / samples.
    pub success_rate: f64,
    /// Failures by reason code (`no_output`, `no_marker`, `not_json`, `not_a_layout`,
    /// `no_valid_object`, `unreadable`).
    pub failures: BTreeMap<String, u64>,
    /// Output lines that matched no prompt (unknown or repeated ids), with why.
    pub ignored_outputs: Vec<String>,
    /// Physics: the successful samples placed with retrieved assets and checked on meshes.
    pub physics: PhysicsMetrics,
    /// Category statistics against the dataset's scenes, by table type.
    pub categories: BTreeMap<String, CategoryMetrics>,
    /// The mean of the table types' CKL (each over its samples), as the paper's table reports.
    pub ckl_mean: Option<f64>,
    /// Scene-graph self-consistency: the graph the model wrote against the graph mesa extracts
    /// from the model's own layout.
    pub graph: GraphConsistency,
    /// Coverage of the task's "Objects cluster" by the layout.
    pub task_coverage: Coverage,
    /// Objects whose size is implausible for their retrieved asset's category.
    pub size: SizePlausibility,
    /// FID and KID from user-supplied feature files, when given.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub features: Option<FeatureMetrics>,
    /// The GPT score (`--gpt-score`): a chat model's 1–10 scores of the rendered scenes on the
    /// paper's five criteria.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gpt_score: Option<GptScoreMetrics>,
}

/// The GPT score over the samples (MesaTask paper §5: each criterion scored 1–10 by a chat
/// model from the rendered views; a sample's GPT score is the mean of its five).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct GptScoreMetrics {
    /// The judge model (`[eval.llm] model`).
    pub model: String,
    /// The prompt template (`built-in data/prompts/gpt_score.txt`, or the file of
    /// `[eval] gpt_score_prompt`).
    pub prompt: String,
    /// Samples a request was made for (successful and drawn).
    pub requested: u64,
    /// Samples whose reply passed validation.
    pub scored: u64,
    /// Samples whose reply was rejected (not JSON, a criterion missing or not an integer in
    /// 1..=10); the reasons are in samples.jsonl.
    pub rejected: u64,
    /// Samples still waiting for their reply (offline batches).
    pub pending: u64,
    /// Samples whose request the endpoint failed for good.
    pub failed: u64,
    /// Successful samples that could not be drawn (no request).
    pub not_drawn: u64,
    /// The mean over scored samples of each sample's mean of the five criteria (the paper's
    /// GPT score); absent when none was scored.
    pub mean: Option<f64>,
    /// Per criterion key (`consistency_with_task`, `object_size_reasonableness`,
    /// `placement_plausibility`, `layout_coherence`, `object_visibility`).
    pub criteria: BTreeMap<String, CriterionScore>,
}

/// One criterion of the GPT score over the samples.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CriterionScore {
    /// The criterion's name in the paper (`Consistency with Task`).
    pub name: String,
    /// The mean of its scores over the scored samples; absent when none was scored.
    pub mean: Option<f64>,
    /// Scored samples (each gives every criterion a score).
    pub count: u64,
    /// Rejected replies in which this criterion was missing or not an integer in 1..=10.
    pub rejects: u64,
}

/// The GPT score of one sample.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SampleGptScore {
    /// `scored`, `rejected` (the reply failed validation), `pending` (offline batches: no
    /// reply yet), `failed` (the endpoint gave no reply) or `not_drawn` (no views, no request).
    pub status: String,
    /// The criteria's scores (1–10) by key, when scored.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub scores: BTreeMap<String, u32>,
    /// The mean of the five scores, when scored.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mean: Option<f64>,
    /// The model's short reason, when it gave one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// Why the reply was rejected or why there is none, one problem each.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub problems: Vec<String>,
    /// The criteria keys a rejected reply got wrong (missing or not an integer in 1..=10).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub rejected_criteria: Vec<String>,
    /// The rejected reply as received (the API key redacted).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reply: Option<String>,
    /// SHA-256 of the request body (the reply cache's key, `.mesa/cache/chat/`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub request_sha256: Option<String>,
}

/// The physics figures of `mesa check`, over the successful samples.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PhysicsMetrics {
    /// Samples checked (successful ones).
    pub scenes: u64,
    /// Layout objects.
    pub objects: u64,
    /// Objects retrieval found no asset for (not checked).
    pub objects_without_asset: u64,
    /// Objects without a collision shape (no asset, no shapes file): in no pair.
    pub objects_unchecked: u64,
    /// Pairs of checked objects.
    pub pairs: u64,
    /// Pairs interpenetrating deeper than `[check] penetration_tolerance_mm`.
    pub colliding_pairs: u64,
    /// colliding_pairs / pairs (the paper's collision rate, pooled).
    pub collision_rate: f64,
    /// Mean over scenes of each scene's collision rate.
    pub collision_rate_scene_mean: f64,
    /// Scenes with at least one colliding pair.
    pub scenes_with_collision: u64,
    /// scenes_with_collision / scenes.
    pub scenes_with_collision_rate: f64,
    /// Pairs closer than MesaTask's 5 cm (its released code's rule).
    pub mesatask_rule_pairs: u64,
    /// mesatask_rule_pairs / pairs.
    pub mesatask_rule_rate: f64,
    /// Scenes with a pair under MesaTask's rule.
    pub scenes_with_mesatask_rule_pair: u64,
    /// Objects reaching beyond the item placement zone.
    pub objects_outside_zone: u64,
    /// Objects over the sink (restricted) zone.
    pub objects_in_sink_zone: u64,
    /// Objects sunk into the table top.
    pub objects_below_table: u64,
    /// Floating objects.
    pub objects_floating: u64,
    /// Scenes with no collision, no floating, no zone violation and every object checked.
    pub clean_scenes: u64,
}

/// Category statistics of one table type.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CategoryMetrics {
    /// The dataset's scenes of this table type.
    pub reference_scenes: u64,
    /// Successful samples of this table type.
    pub generated_scenes: u64,
    /// Σ p·(log(p+1e-6) − log(q+1e-6)) over categories, p the dataset's category
    /// frequencies, q the generated ones (ATISS, DiffuScene, PhyScene); absent without a
    /// generated or a reference object.
    pub ckl: Option<f64>,
    /// Objects per scene in the dataset: histogram (count → scenes).
    pub reference_object_counts: BTreeMap<String, u64>,
    /// Objects per scene in the samples: histogram (count → scenes).
    pub generated_object_counts: BTreeMap<String, u64>,
    /// Mean objects per scene in the dataset.
    pub reference_objects_mean: f64,
    /// Mean objects per scene in the samples.
    pub generated_objects_mean: f64,
}

/// Precision and recall of the written scene graph against the extracted one.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct GraphConsistency {
    /// Successful samples.
    pub samples: u64,
    /// Triplets the models wrote (distinct per sample).
    pub written: u64,
    /// Triplets mesa extracts from the layouts.
    pub extracted: u64,
    /// Triplets in both.
    pub matched: u64,
    /// matched / written (pooled; 1 when nothing was written and nothing extracted).
    pub precision: f64,
    /// matched / extracted (pooled).
    pub recall: f64,
    /// Harmonic mean of precision and recall.
    pub f1: f64,
}

/// How many of the task's object types are in the layouts.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Coverage {
    /// Successful samples whose task names object types.
    pub samples: u64,
    /// Object types the tasks name.
    pub types: u64,
    /// Of them, types with at least one object in the layout.
    pub present: u64,
    /// present / types (pooled).
    pub coverage: f64,
    /// Samples with every task type present.
    pub complete_samples: u64,
}

/// Objects whose size is implausible for their category.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SizePlausibility {
    /// The factor: an object is implausible when its largest dimension is below the
    /// category's smallest asset's divided by it, or above its largest asset's times it.
    pub factor: f64,
    /// Objects whose retrieved asset's category has size statistics.
    pub objects: u64,
    /// Of them, implausible ones.
    pub implausible: u64,
    /// implausible / objects.
    pub share: f64,
}

/// FID and KID between real and generated feature sets.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FeatureMetrics {
    /// The real features file.
    pub real: String,
    /// The generated features file.
    pub generated: String,
    /// Rows of each.
    pub real_rows: u64,
    /// Rows of the generated features.
    pub generated_rows: u64,
    /// Feature dimension.
    pub dimension: u64,
    /// Fréchet distance of the two Gaussians.
    pub fid: f64,
    /// Unbiased MMD² with the cubic polynomial kernel (x·y/d + 1)³.
    pub kid: f64,
}

/// One line of `eval/<name>/samples.jsonl`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct EvalSample {
    /// `mesa.eval-sample/1`.
    pub schema: String,
    /// The prompt's id.
    pub id: String,
    /// The table type, when the prompt's scene is known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub table_type: Option<String>,
    /// The output passes the paper's success rule.
    pub success: bool,
    /// Why not: a reason code and the parser's message.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub failure: Option<SampleFailure>,
    /// Objects of the layout the parser dropped, with why.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub dropped_objects: Vec<String>,
    /// The layout's objects: instance, retrieved asset, its category.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub objects: Vec<SampleObject>,
    /// Pairs of checked objects.
    pub pairs: u64,
    /// Colliding pairs `[a, b, depth_mm]`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub collisions: Vec<(String, String, f64)>,
    /// Pairs closer than MesaTask's 5 cm.
    pub mesatask_rule_pairs: u64,
    /// Floating objects.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub floating: Vec<String>,
    /// Objects beyond the placement zone.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub outside_zone: Vec<String>,
    /// Objects over the sink zone.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub in_sink_zone: Vec<String>,
    /// Objects sunk into the table.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub below_table: Vec<String>,
    /// Objects not checked, with why.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub unchecked: Vec<String>,
    /// Problems of the evaluation itself (retrieval or the scene graph failed), with why.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
    /// Written triplets missing from the extracted graph.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub graph_unsupported: Vec<String>,
    /// Extracted triplets the model did not write.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub graph_unwritten: Vec<String>,
    /// Written, extracted and matched triplet counts.
    pub graph_counts: [u64; 3],
    /// The task's object types absent from the layout.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub missing_task_types: Vec<String>,
    /// The task's object types (count).
    pub task_types: u64,
    /// Objects whose retrieved category has size statistics in the library.
    pub size_checked: u64,
    /// Objects whose size is implausible for their category, with why.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub implausible_size: Vec<String>,
    /// The GPT score of the sample (`--gpt-score`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gpt_score: Option<SampleGptScore>,
}

/// Why a sample failed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SampleFailure {
    /// `no_output`, `no_marker`, `not_json`, `not_a_layout`, `no_valid_object`, `unreadable`.
    pub reason: String,
    /// The details.
    pub message: String,
}

/// An object of a sample's layout and the asset it was given.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SampleObject {
    /// The instance.
    pub instance: String,
    /// The retrieved asset, absent when none passed the filters.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uid: Option<String>,
    /// The asset's category (its annotation), else the instance's.
    pub category: String,
}
