//! `eval`: the benchmark of task-to-scene models (`docs/eval.md`), from the pieces the
//! pipeline already has:
//!
//! - the model output parser and the paper's success rule ([`mesa_schemas::output`]);
//! - MesaTask's inference recipe: an asset per object by description and size
//!   ([`crate::retrieve::retrieve_instances`]), scaled to the object's `size`;
//! - `mesa check` on the assets' convex parts ([`crate::check::check_scene`]);
//! - the rule-based scene graph ([`crate::graph`]) against the graph the model wrote;
//! - the task's "Objects cluster" matched to the layout's types ([`crate::tasks::types`]);
//! - category statistics (CKL, object counts) and size plausibility;
//! - FID and KID from feature files ([`features`]);
//! - the GPT score's prompt, request and reply validation ([`gpt_score`]).
//!
//! [`evaluate_sample`] turns one output into an [`EvalSample`]; [`aggregate`] the samples into
//! [`EvalMetrics`]. Both are pure functions of their inputs.

pub mod features;
pub mod gpt_score;

use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

use mesa_schemas::artifacts::{AssetIndexArtifact, LiftStats, LiftedInstance};
use mesa_schemas::convert::{category_of_instance, dataset_from_llm};
use mesa_schemas::eval::{
    CategoryMetrics, Coverage, EvalMetrics, EvalSample, GraphConsistency, PhysicsMetrics,
    SampleFailure, SampleObject, SizePlausibility, EVAL_METRICS_SCHEMA, EVAL_SAMPLE_SCHEMA,
};
use mesa_schemas::output::{parse_model_output, OutputError};
use mesa_schemas::units::{PositionCm, ScaleFactor};
use mesa_schemas::{DatasetLayout, LlmLayout};
use serde_json::Value;

use crate::annotations::Annotations;
use crate::check::{check_scene, round_to, AssetShape, CheckConfig, PhysicsScene, ViolationKind};
use crate::graph::{annotated_containers, extract_graph, GraphOptions, GraphScene};
use crate::retrieve::{retrieve_instances, Catalog, Query, RetrieveConfig, TextScorer};
use crate::tasks::types::SceneTypes;

/// The smoothing of the CKL's logarithms (ATISS, DiffuScene, PhyScene use 1e-6).
pub const CKL_EPSILON: f64 = 1e-6;

/// An object is implausibly sized when its largest dimension is below its category's smallest
/// asset's divided by this factor, or above its largest asset's times it.
pub const SIZE_FACTOR: f64 = 2.0;

/// What the evaluation of a sample reads besides the sample: the asset library and settings.
pub struct EvalLibrary<'a> {
    /// The text side of retrieval (the dataset's text index).
    pub scorer: &'a TextScorer,
    /// What retrieval knows of each asset.
    pub catalog: &'a Catalog,
    /// The `[retrieve]` recipe.
    pub retrieve: &'a RetrieveConfig,
    /// The asset annotations (categories, container flags).
    pub annotations: Option<&'a Annotations>,
    /// The collision shape of an asset, or why there is none.
    pub shape_of: &'a (dyn Fn(&str) -> Result<Arc<AssetShape>, String> + Sync),
    /// Size statistics of the library's categories.
    pub sizes: &'a SizeStats,
    /// The `[check]` tolerances.
    pub check: &'a CheckConfig,
    /// The scene-graph rules.
    pub graph: &'a GraphOptions,
}

/// Per category of the library, the smallest and largest asset's largest dimension (cm).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SizeStats {
    /// Category (lower case) → (smallest, largest) largest dimension, cm.
    pub by_category: BTreeMap<String, (f64, f64)>,
}

impl SizeStats {
    /// The statistics of the valid assets of an index whose annotation names a category.
    pub fn of_library(index: &AssetIndexArtifact, annotations: Option<&Annotations>) -> Self {
        let mut by_category: BTreeMap<String, (f64, f64)> = BTreeMap::new();
        let Some(annotations) = annotations else {
            return Self { by_category };
        };
        for (uid, record) in &index.assets {
            let (Some(geometry), Some(category)) = (
                record.geometry.as_ref().filter(|_| record.valid),
                annotations.get(uid).and_then(|a| a.category.as_deref()),
            ) else {
                continue;
            };
            let largest_cm = geometry.size_m.iter().fold(0.0f64, |m, v| m.max(*v)) * 100.0;
            if largest_cm <= 0.0 {
                continue;
            }
            let entry = by_category
                .entry(category.to_lowercase())
                .or_insert((largest_cm, largest_cm));
            entry.0 = entry.0.min(largest_cm);
            entry.1 = entry.1.max(largest_cm);
        }
        Self { by_category }
    }
}

/// One sample to evaluate.
#[derive(Debug, Clone, Copy)]
pub struct SampleInput<'a> {
    /// The prompt's id.
    pub id: &'a str,
    /// The table type of the prompt's scene, when known.
    pub table_type: Option<&'a str>,
    /// The task info JSON of the prompt.
    pub task_info: Option<&'a Value>,
    /// The model's output text (`None`: the model gave none), or why it could not be read.
    pub output: Result<Option<&'a str>, &'a str>,
}

fn failure(reason: &str, message: impl Into<String>) -> SampleFailure {
    SampleFailure {
        reason: reason.to_owned(),
        message: message.into(),
    }
}

fn empty_sample(input: &SampleInput<'_>, fail: Option<SampleFailure>) -> EvalSample {
    EvalSample {
        schema: EVAL_SAMPLE_SCHEMA.to_owned(),
        id: input.id.to_owned(),
        table_type: input.table_type.map(str::to_owned),
        success: fail.is_none(),
        failure: fail,
        dropped_objects: Vec::new(),
        objects: Vec::new(),
        pairs: 0,
        collisions: Vec::new(),
        mesatask_rule_pairs: 0,
        floating: Vec::new(),
        outside_zone: Vec::new(),
        in_sink_zone: Vec::new(),
        below_table: Vec::new(),
        unchecked: Vec::new(),
        notes: Vec::new(),
        graph_unsupported: Vec::new(),
        graph_unwritten: Vec::new(),
        graph_counts: [0; 3],
        missing_task_types: Vec::new(),
        task_types: 0,
        size_checked: 0,
        implausible_size: Vec::new(),
        gpt_score: None,
    }
}

/// Parses an output under the paper's success rule, then drops objects without a description
/// (MesaTask's inference retrieves by description: such an object cannot become a scene).
pub fn parse_for_eval(text: &str) -> Result<(LlmLayout, Vec<String>, Vec<String>), SampleFailure> {
    let parsed = parse_model_output(text).map_err(|e| {
        let reason = match &e {
            OutputError::NoMarker => "no_marker",
            OutputError::NotJson(_) => "not_json",
            OutputError::NotALayout(_) => "not_a_layout",
            OutputError::NoValidObject(_) => "no_valid_object",
        };
        failure(reason, e.to_string())
    })?;
    let mut dropped = parsed.dropped_objects;
    let mut layout = parsed.layout;
    let mut kept = Vec::with_capacity(layout.objects.len());
    for object in layout.objects {
        if object.description.trim().is_empty() {
            dropped.push(format!(
                "{}: no description (retrieval needs one)",
                object.instance
            ));
        } else {
            kept.push(object);
        }
    }
    if kept.is_empty() {
        return Err(failure(
            "no_valid_object",
            format!("the layout has no valid object ({})", dropped.join("; ")),
        ));
    }
    layout.objects = kept;
    Ok((layout, parsed.graph_lines, dropped))
}

/// A triplet line with single spaces, for comparison.
fn normalise_triplet(line: &str) -> String {
    line.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// Evaluates one sample: parse, retrieve, check, graph, coverage, sizes. Returns the sample
/// and, for a successful one, the scene as it was checked (a dataset layout with the retrieved
/// assets and their scale factors, which `mesa check` reads as it is).
pub fn evaluate_sample(
    input: &SampleInput<'_>,
    library: &EvalLibrary<'_>,
) -> (EvalSample, Option<DatasetLayout>) {
    let text = match input.output {
        Err(why) => return (empty_sample(input, Some(failure("unreadable", why))), None),
        Ok(None) => {
            let why = "no output has this prompt's id (expected a line {\"id\", \"output\"})";
            return (empty_sample(input, Some(failure("no_output", why))), None);
        }
        Ok(Some(text)) => text,
    };
    let (layout, written, dropped) = match parse_for_eval(text) {
        Ok(parsed) => parsed,
        Err(fail) => return (empty_sample(input, Some(fail)), None),
    };
    let mut sample = empty_sample(input, None);
    sample.dropped_objects = dropped;

    // Retrieval: the description is the query (the official recipe), the size the target.
    let instances: Vec<LiftedInstance> = layout
        .objects
        .iter()
        .enumerate()
        .map(|(i, o)| LiftedInstance {
            instance: o.instance.clone(),
            mask_id: i as u32,
            label: category_of_instance(&o.instance).to_owned(),
            description: o.description.clone(),
            center_cm: PositionCm(o.position_cm.0),
            size_cm: o.size_cm,
            yaw_deg: Some(o.z_rotation_deg),
            points: String::new(),
            stats: LiftStats {
                mask_px: 0,
                valid_depth_px: 0,
                valid_depth_fraction: 0.0,
                eroded_px: 0,
                points_removed_outliers: 0,
                points_kept: 0,
            },
        })
        .collect();
    let queries: Vec<Query> = instances
        .iter()
        .map(|i| Query::Text(i.description.clone()))
        .collect();
    let chosen: Vec<Option<String>> = match retrieve_instances(
        &instances,
        &queries,
        library.scorer,
        library.catalog,
        library.retrieve,
    ) {
        Ok((retrieved, _)) => retrieved.into_iter().map(|r| r.chosen).collect(),
        Err(e) => {
            sample.notes.push(format!("retrieval failed: {e}"));
            vec![None; layout.objects.len()]
        }
    };
    let category_of = |uid: &Option<String>, instance: &str| -> String {
        uid.as_deref()
            .and_then(|u| library.annotations.and_then(|a| a.get(u)))
            .and_then(|a| a.category.clone())
            .unwrap_or_else(|| category_of_instance(instance).to_owned())
            .to_lowercase()
    };
    sample.objects = layout
        .objects
        .iter()
        .zip(&chosen)
        .map(|(o, uid)| SampleObject {
            instance: o.instance.clone(),
            uid: uid.clone(),
            category: category_of(uid, &o.instance),
        })
        .collect();

    // The scene: each asset scaled along its own axes to the object's size.
    let mut dataset = dataset_from_llm(&layout).layout;
    let mut shapes: Vec<Result<Arc<AssetShape>, String>> = Vec::with_capacity(chosen.len());
    for (object, uid) in dataset.objects.iter_mut().zip(&chosen) {
        let shape = match uid {
            None => Err("retrieval found no asset".to_owned()),
            Some(uid) => (library.shape_of)(uid),
        };
        if let (Some(uid), Ok(shape)) = (uid, &shape) {
            object.retrieved_uid = uid.clone();
            object.scale_factor = ScaleFactor(std::array::from_fn(|k| {
                let asset_cm = shape.size_m[k] * 100.0;
                if asset_cm > 0.0 {
                    object.size_cm.0[k] / asset_cm
                } else {
                    1.0
                }
            }));
        }
        shapes.push(shape);
    }
    let scene = PhysicsScene::from_layout(&dataset, |object| {
        let i = dataset
            .objects
            .iter()
            .position(|o| std::ptr::eq(o, object))
            .unwrap_or(0);
        shapes[i].clone()
    });
    let findings = check_scene(&scene, &library.check.tolerances());
    let name = |i: usize| scene.objects[i].instance.clone();
    sample.pairs = findings.pairs_total;
    sample.mesatask_rule_pairs = findings.mesatask_rule_pairs;
    sample.collisions = findings
        .collisions
        .iter()
        .map(|c| {
            let (a, b) = (name(c.a), name(c.b));
            let (a, b) = if a <= b { (a, b) } else { (b, a) };
            (a, b, round_to(c.depth_m * 1000.0, 3))
        })
        .collect();
    sample
        .collisions
        .sort_by(|x, y| (&x.0, &x.1).cmp(&(&y.0, &y.1)));
    sample.floating = findings.floating.iter().map(|f| name(f.object)).collect();
    for (i, kind, _) in &findings.violations {
        let list = match kind {
            ViolationKind::OutsideZone => &mut sample.outside_zone,
            ViolationKind::InRestrictedZone => &mut sample.in_sink_zone,
            ViolationKind::BelowTable => &mut sample.below_table,
        };
        if !list.contains(&name(*i)) {
            list.push(name(*i));
        }
    }
    sample
        .unchecked
        .extend(scene.objects.iter().filter_map(|o| {
            o.body
                .as_ref()
                .err()
                .map(|why| format!("{}: {why}", o.instance))
        }));

    // The graph the model wrote against the graph of its own layout.
    let graph_scene = GraphScene::from_llm(&layout);
    let uids: Vec<String> = chosen
        .iter()
        .map(|u| u.clone().unwrap_or_default())
        .collect();
    let containers = annotated_containers(&graph_scene, &uids, library.annotations, library.graph);
    let extracted: BTreeSet<String> =
        match extract_graph(&graph_scene, &containers.flags, library.graph) {
            Ok(graph) => graph
                .triplet_lines()
                .iter()
                .map(|l| normalise_triplet(l))
                .collect(),
            Err(e) => {
                sample.notes.push(format!("scene graph: {e}"));
                BTreeSet::new()
            }
        };
    let written: BTreeSet<String> = written.iter().map(|l| normalise_triplet(l)).collect();
    let matched = written.intersection(&extracted).count() as u64;
    sample.graph_counts = [written.len() as u64, extracted.len() as u64, matched];
    sample.graph_unsupported = written.difference(&extracted).cloned().collect();
    sample.graph_unwritten = extracted.difference(&written).cloned().collect();

    // The task's object types.
    if let Some(cluster) = input
        .task_info
        .and_then(|t| t.get("Objects cluster"))
        .and_then(Value::as_array)
    {
        let types = SceneTypes::of_layout(&layout);
        let mut seen = BTreeSet::new();
        for name in cluster.iter().filter_map(Value::as_str) {
            if !seen.insert(name.to_lowercase()) {
                continue;
            }
            sample.task_types += 1;
            if types.matching(name).is_empty() {
                sample.missing_task_types.push(name.to_owned());
            }
        }
    }

    // Sizes against the library's statistics of the retrieved category.
    for (object, sample_object) in layout.objects.iter().zip(&sample.objects) {
        let Some(&(small, large)) = library.sizes.by_category.get(&sample_object.category) else {
            continue;
        };
        sample.size_checked += 1;
        let largest = object.size_cm.0.iter().fold(0.0f64, |m, v| m.max(*v));
        if largest < small / SIZE_FACTOR || largest > large * SIZE_FACTOR {
            sample.implausible_size.push(format!(
                "{}: {largest:.1} cm for a {} (the library's are {small:.1} to {large:.1} cm)",
                object.instance, sample_object.category
            ));
        }
    }
    (sample, Some(dataset))
}

/// Σ p·(log(p+ε) − log(q+ε)) over the categories of either distribution (counts normalised).
pub fn ckl(reference: &BTreeMap<String, u64>, generated: &BTreeMap<String, u64>) -> Option<f64> {
    let total_p: u64 = reference.values().sum();
    let total_q: u64 = generated.values().sum();
    if total_p == 0 || total_q == 0 {
        return None;
    }
    let categories: BTreeSet<&String> = reference.keys().chain(generated.keys()).collect();
    Some(
        categories
            .into_iter()
            .map(|c| {
                let p = reference.get(c).copied().unwrap_or(0) as f64 / total_p as f64;
                let q = generated.get(c).copied().unwrap_or(0) as f64 / total_q as f64;
                p * ((p + CKL_EPSILON).ln() - (q + CKL_EPSILON).ln())
            })
            .sum(),
    )
}

/// The dataset's scenes of one table type: each scene's object categories.
pub type ReferenceScenes = BTreeMap<String, Vec<Vec<String>>>;

fn ratio(a: u64, b: u64) -> f64 {
    if b == 0 {
        0.0
    } else {
        a as f64 / b as f64
    }
}

fn histogram(counts: impl Iterator<Item = usize>) -> (BTreeMap<String, u64>, f64) {
    let mut hist: BTreeMap<usize, u64> = BTreeMap::new();
    let (mut sum, mut n) = (0usize, 0usize);
    for c in counts {
        *hist.entry(c).or_default() += 1;
        sum += c;
        n += 1;
    }
    let mean = if n == 0 { 0.0 } else { sum as f64 / n as f64 };
    // Keys zero-padded so that the sorted JSON keys are in numeric order.
    (
        hist.into_iter()
            .map(|(k, v)| (format!("{k:03}"), v))
            .collect(),
        mean,
    )
}

/// What the metrics say about where the prompts came from.
#[derive(Debug, Clone)]
pub struct RunInfo {
    /// The model's name.
    pub name: String,
    /// The prompts' source.
    pub prompts: String,
    /// Prompts read.
    pub prompts_total: u64,
    /// Output lines matched to no prompt, with why.
    pub ignored_outputs: Vec<String>,
}

/// The metrics of a run over its samples (in prompt order); `references` are the dataset's
/// scenes by table type.
pub fn aggregate(
    info: RunInfo,
    samples: &[EvalSample],
    references: &ReferenceScenes,
) -> EvalMetrics {
    let mut failures: BTreeMap<String, u64> = BTreeMap::new();
    let mut physics = PhysicsMetrics::default();
    let mut graph = GraphConsistency::default();
    let mut coverage = Coverage::default();
    let mut size = SizePlausibility {
        factor: SIZE_FACTOR,
        ..SizePlausibility::default()
    };
    let mut scene_rate_sum = 0.0;
    let mut generated: BTreeMap<String, Vec<&EvalSample>> = BTreeMap::new();
    let ok: Vec<&EvalSample> = samples.iter().filter(|s| s.success).collect();
    for sample in samples {
        if let Some(f) = &sample.failure {
            *failures.entry(f.reason.clone()).or_default() += 1;
        }
    }
    for s in &ok {
        physics.scenes += 1;
        physics.objects += s.objects.len() as u64;
        physics.objects_without_asset +=
            s.objects.iter().filter(|o| o.uid.is_none()).count() as u64;
        physics.objects_unchecked += s.unchecked.len() as u64;
        physics.pairs += s.pairs;
        physics.colliding_pairs += s.collisions.len() as u64;
        scene_rate_sum += ratio(s.collisions.len() as u64, s.pairs);
        physics.scenes_with_collision += u64::from(!s.collisions.is_empty());
        physics.mesatask_rule_pairs += s.mesatask_rule_pairs;
        physics.scenes_with_mesatask_rule_pair += u64::from(s.mesatask_rule_pairs > 0);
        physics.objects_outside_zone += s.outside_zone.len() as u64;
        physics.objects_in_sink_zone += s.in_sink_zone.len() as u64;
        physics.objects_below_table += s.below_table.len() as u64;
        physics.objects_floating += s.floating.len() as u64;
        physics.clean_scenes += u64::from(
            s.collisions.is_empty()
                && s.floating.is_empty()
                && s.outside_zone.is_empty()
                && s.in_sink_zone.is_empty()
                && s.below_table.is_empty()
                && s.unchecked.is_empty(),
        );
        graph.samples += 1;
        graph.written += s.graph_counts[0];
        graph.extracted += s.graph_counts[1];
        graph.matched += s.graph_counts[2];
        if s.task_types > 0 {
            coverage.samples += 1;
            coverage.types += s.task_types;
            coverage.present += s.task_types - s.missing_task_types.len() as u64;
            coverage.complete_samples += u64::from(s.missing_task_types.is_empty());
        }
        size.objects += s.size_checked;
        size.implausible += s.implausible_size.len() as u64;
        if let Some(t) = &s.table_type {
            generated.entry(t.clone()).or_default().push(s);
        }
    }
    physics.collision_rate = ratio(physics.colliding_pairs, physics.pairs);
    physics.collision_rate_scene_mean = if physics.scenes == 0 {
        0.0
    } else {
        scene_rate_sum / physics.scenes as f64
    };
    physics.scenes_with_collision_rate = ratio(physics.scenes_with_collision, physics.scenes);
    physics.mesatask_rule_rate = ratio(physics.mesatask_rule_pairs, physics.pairs);
    graph.precision = if graph.written == 0 && graph.extracted == 0 {
        1.0
    } else {
        ratio(graph.matched, graph.written)
    };
    graph.recall = if graph.extracted == 0 {
        1.0
    } else {
        ratio(graph.matched, graph.extracted)
    };
    graph.f1 = if graph.precision + graph.recall > 0.0 {
        2.0 * graph.precision * graph.recall / (graph.precision + graph.recall)
    } else {
        0.0
    };
    coverage.coverage = ratio(coverage.present, coverage.types);
    size.share = ratio(size.implausible, size.objects);

    let mut categories = BTreeMap::new();
    for (table_type, samples) in &generated {
        let scenes = references.get(table_type).map(Vec::as_slice).unwrap_or(&[]);
        let mut p: BTreeMap<String, u64> = BTreeMap::new();
        for scene in scenes {
            for c in scene {
                *p.entry(c.clone()).or_default() += 1;
            }
        }
        let mut q: BTreeMap<String, u64> = BTreeMap::new();
        for s in samples {
            for o in &s.objects {
                *q.entry(category_of_instance(&o.instance).to_lowercase())
                    .or_default() += 1;
            }
        }
        let (reference_object_counts, reference_objects_mean) =
            histogram(scenes.iter().map(Vec::len));
        let (generated_object_counts, generated_objects_mean) =
            histogram(samples.iter().map(|s| s.objects.len()));
        categories.insert(
            table_type.clone(),
            CategoryMetrics {
                reference_scenes: scenes.len() as u64,
                generated_scenes: samples.len() as u64,
                ckl: ckl(&p, &q),
                reference_object_counts,
                generated_object_counts,
                reference_objects_mean,
                generated_objects_mean,
            },
        );
    }
    let ckls: Vec<f64> = categories.values().filter_map(|c| c.ckl).collect();
    let ckl_mean = (!ckls.is_empty()).then(|| ckls.iter().sum::<f64>() / ckls.len() as f64);
    let succeeded = ok.len() as u64;
    EvalMetrics {
        schema: EVAL_METRICS_SCHEMA.to_owned(),
        name: info.name,
        prompts: info.prompts,
        prompts_total: info.prompts_total,
        samples: samples.len() as u64,
        succeeded,
        success_rate: ratio(succeeded, samples.len() as u64),
        failures,
        ignored_outputs: info.ignored_outputs,
        physics,
        categories,
        ckl_mean,
        graph,
        task_coverage: coverage,
        size,
        features: None,
        gpt_score: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn counts(pairs: &[(&str, u64)]) -> BTreeMap<String, u64> {
        pairs.iter().map(|(k, v)| ((*k).to_owned(), *v)).collect()
    }

    #[test]
    fn ckl_is_zero_for_equal_distributions_and_grows_with_difference() {
        let p = counts(&[("mug", 2), ("plate", 2)]);
        assert_relative_eq!(
            ckl(&p, &counts(&[("mug", 5), ("plate", 5)])).expect("ckl"),
            0.0
        );
        let near = ckl(&p, &counts(&[("mug", 6), ("plate", 4)])).expect("ckl");
        let far = ckl(&p, &counts(&[("mug", 9), ("plate", 1)])).expect("ckl");
        assert!(0.0 < near && near < far, "{near} {far}");
        // A category the model never writes costs p·(log(p+ε) − log ε).
        let missing = ckl(&p, &counts(&[("mug", 1)])).expect("ckl");
        let expected = 0.5 * ((0.5f64 + 1e-6).ln() - (1.0f64 + 1e-6).ln())
            + 0.5 * ((0.5f64 + 1e-6).ln() - 1e-6f64.ln());
        assert_relative_eq!(missing, expected, max_relative = 1e-12);
        assert_eq!(ckl(&p, &BTreeMap::new()), None);
    }

    #[test]
    fn objects_without_description_are_dropped_and_none_left_fails() {
        let marker = mesa_schemas::output::FINAL_ANSWER_MARKER;
        let one = |desc: &str| {
            format!(
                "R.\n(a_0, is at, center){marker}{{\"item_placement_zone\": [0, 100, 0, 60], \
                 \"objects\": [{{\"instance\": \"a_0\", \"size\": [1, 1, 1], \"position\": [5, 5, \
                 0.5], \"z_rotation\": 0, \"description\": \"{desc}\"}}]}}"
            )
        };
        assert!(parse_for_eval(&one("a red mug")).is_ok());
        let failed = parse_for_eval(&one("  ")).expect_err("no description left");
        assert_eq!(failed.reason, "no_valid_object");
        assert!(
            failed.message.contains("no description"),
            "{}",
            failed.message
        );
    }
}
