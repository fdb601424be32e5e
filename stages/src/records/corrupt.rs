//! The three corruptions of a chosen output that make DPO rejected outputs (SPEC 5.9), each
//! seeded by the run seed, the scene and the task, and each verified before it is used:
//!
//! - **collision**: a random subset of objects is perturbed (position with probability 0.8,
//!   else rotation or size) by up to 20% of the zone's width / depth, staying inside the zone;
//!   kept only when the layout then has a colliding pair it did not have (the assets' collision
//!   shapes interpenetrating deeper than the tolerance, as `mesa check` tests them; oriented
//!   boxes for layouts without assets; see [`crate::records::collide`]). The scene-graph lines are
//!   those of the perturbed layout, so the only flaw is the collision.
//! - **relation**: a subset of the scene graph's relation edges is removed or replaced by a
//!   wrong one (left of ↔ right of, in front of ↔ behind, above → below, in → above); the
//!   layout is unchanged.
//! - **missing object**: one or more objects of the task's types are deleted from the layout,
//!   from the scene-graph lines that name them, and from the reasoning's counts.

use std::collections::BTreeSet;

use mesa_schemas::artifacts::TaskRecord;
use mesa_schemas::output::{compose_model_output, parse_model_output};
use mesa_schemas::rotation::normalize_deg;
use mesa_schemas::LlmLayout;
use rand::seq::index::sample;
use rand::seq::SliceRandom as _;
use rand::Rng as _;
use rand_chacha::ChaCha8Rng;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::graph::{extract_graph, GraphOptions, GraphScene};
use crate::records::collide::YawBox;
use crate::records::{round_layout, RecordsConfig, SceneRecordsInput};
use crate::seeding::rng_for;
use crate::tasks::reasoning::rewrite_counts;
use crate::tasks::scene::core_types;
use crate::tasks::types::SceneTypes;

/// A way to corrupt a chosen output.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize, JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum Corruption {
    /// Perturb objects until a new colliding pair appears.
    Collision,
    /// Remove or falsify scene-graph relations.
    Relation,
    /// Delete objects the task needs.
    MissingObject,
}

impl Corruption {
    /// `collision`, `relation` or `missing_object`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Collision => "collision",
            Self::Relation => "relation",
            Self::MissingObject => "missing_object",
        }
    }
}

/// The `[records.collision]` section.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct CollisionConfig {
    /// The most objects perturbed at once, as a share of the scene's objects (at least one).
    pub subset_fraction: f64,
    /// Probability that a perturbed object is moved (else turned or resized).
    pub position_probability: f64,
    /// Probability that it is turned (the rest: resized).
    pub rotation_probability: f64,
    /// Largest move along x and along y, as a share of the zone's width and depth.
    pub max_shift_fraction: f64,
    /// Largest turn in degrees (turns are at least 15°).
    pub max_rotation_deg: f64,
    /// Largest growth of a resized object, as a share of its size (growth is at least 5%).
    pub max_size_growth: f64,
    /// Two boxes collide when they interpenetrate deeper than this, in mm (SPEC 5.6's
    /// default penetration tolerance).
    pub tolerance_mm: f64,
    /// Perturbations tried before giving the corruption up for a prompt.
    pub attempts: u32,
}

impl Default for CollisionConfig {
    fn default() -> Self {
        Self {
            subset_fraction: 0.3,
            position_probability: 0.8,
            rotation_probability: 0.1,
            max_shift_fraction: 0.2,
            max_rotation_deg: 90.0,
            max_size_growth: 0.2,
            tolerance_mm: 2.0,
            attempts: 20,
        }
    }
}

impl CollisionConfig {
    pub(crate) fn problems(&self) -> Vec<String> {
        let mut problems = Vec::new();
        for (name, value, low, high) in [
            ("subset_fraction", self.subset_fraction, 0.0, 1.0),
            ("position_probability", self.position_probability, 0.0, 1.0),
            ("rotation_probability", self.rotation_probability, 0.0, 1.0),
            ("max_shift_fraction", self.max_shift_fraction, 0.0, 1.0),
            ("max_size_growth", self.max_size_growth, 0.05, 10.0),
            ("max_rotation_deg", self.max_rotation_deg, 15.0, 180.0),
            ("tolerance_mm", self.tolerance_mm, 0.0, 1000.0),
        ] {
            if !(low..=high).contains(&value) {
                problems.push(format!(
                    "[records.collision] {name} is {value} (expected {low} to {high})"
                ));
            }
        }
        if self.position_probability + self.rotation_probability > 1.0 {
            problems.push(
                "[records.collision] position_probability + rotation_probability exceeds 1"
                    .to_owned(),
            );
        }
        if self.attempts == 0 {
            problems.push("[records.collision] attempts is 0 (expected at least 1)".to_owned());
        }
        problems
    }
}

/// The `[records.relation]` section.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct RelationConfig {
    /// The least share of the relation edges changed (at least one edge).
    pub min_fraction: f64,
    /// The largest share of the relation edges changed.
    pub max_fraction: f64,
    /// Probability that a changed edge is removed (else replaced by a wrong relation).
    pub removal_probability: f64,
}

impl Default for RelationConfig {
    fn default() -> Self {
        Self {
            min_fraction: 0.2,
            max_fraction: 0.5,
            removal_probability: 0.5,
        }
    }
}

impl RelationConfig {
    pub(crate) fn problems(&self) -> Vec<String> {
        let mut problems = Vec::new();
        if !(0.0..=1.0).contains(&self.min_fraction)
            || !(0.0..=1.0).contains(&self.max_fraction)
            || self.min_fraction > self.max_fraction
        {
            problems.push(format!(
                "[records.relation] min_fraction {} and max_fraction {} (expected 0 <= min <= max <= 1)",
                self.min_fraction, self.max_fraction
            ));
        }
        if !(0.0..=1.0).contains(&self.removal_probability) {
            problems.push(format!(
                "[records.relation] removal_probability is {} (expected 0 to 1)",
                self.removal_probability
            ));
        }
        problems
    }
}

/// The `[records.missing_object]` section.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct MissingObjectConfig {
    /// The most task objects deleted at once (at least one; never the last object).
    pub max_removed: u32,
}

impl Default for MissingObjectConfig {
    fn default() -> Self {
        Self { max_removed: 2 }
    }
}

/// A corrupted output text and what was done to it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Corrupted {
    /// The rejected output text.
    pub text: String,
    /// What changed, for logs and tests.
    pub detail: String,
}

fn rng(seed: u64, what: &str, scene_id: &str, task_index: u32) -> ChaCha8Rng {
    rng_for(seed, &["records", what, scene_id, &task_index.to_string()])
}

/// The corruptions to try for a prompt, in a seeded order.
pub fn order(
    corruptions: &[Corruption],
    seed: u64,
    scene_id: &str,
    task_index: u32,
) -> Vec<Corruption> {
    let mut order = corruptions.to_vec();
    order.shuffle(&mut rng(seed, "order", scene_id, task_index));
    order
}

/// Why a corruption cannot be applied to a task (recorded as a note, the pair skipped).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CorruptError {
    /// A collision needs two objects.
    #[error("a collision needs two objects")]
    TooFewObjects,
    /// The perturbed layout has no scene graph.
    #[error("the perturbed layout has no scene graph: {0}")]
    NoGraph(String),
    /// No perturbation made a new collision.
    #[error("no new colliding pair in {attempts} perturbations")]
    NoCollision {
        /// The perturbations tried.
        attempts: u32,
    },
    /// The graph has no relation edge to flip.
    #[error("the scene graph has no relation edge")]
    NoRelation,
    /// No object of the task's types.
    #[error("no object of the task's types is in the layout")]
    NoTaskObject,
    /// Deleting would empty the layout.
    #[error("deleting a task object would leave the layout empty")]
    WouldEmptyLayout,
    /// The reasoning's object counts cannot be updated.
    #[error("the reasoning has no readable object lists to update")]
    NoReasoningLists,
    /// The model output cannot be composed.
    #[error("{0}")]
    Compose(String),
    /// The composed text does not parse.
    #[error("the corrupted text does not parse: {0}")]
    Unparsable(String),
    /// The composed text parses to something else.
    #[error("the corrupted text does not give back its layout and lines")]
    NotRoundTrip,
}

/// Applies a corruption to a task's chosen output; the reason when it is not possible.
pub fn corrupt(
    corruption: Corruption,
    input: &SceneRecordsInput,
    task: &TaskRecord,
    config: &RecordsConfig,
    graph: &GraphOptions,
    seed: u64,
) -> Result<Corrupted, CorruptError> {
    let mut rng = rng(seed, corruption.name(), &input.scene_id, task.task_index);
    let (layout, lines, reasoning, detail) = match corruption {
        Corruption::Collision => collision(input, config, graph, &mut rng)?,
        Corruption::Relation => relation(input, &config.relation, &mut rng)?,
        Corruption::MissingObject => missing_object(input, task, &config.missing_object, &mut rng)?,
    };
    let reasoning = reasoning.unwrap_or_else(|| task.reasoning.clone());
    let text = compose_model_output(&reasoning, &lines, &layout)
        .map_err(|e| CorruptError::Compose(e.to_string()))?;
    // The rejected output must read back as what was meant: a success of the parser, with the
    // corrupted layout and lines.
    let parsed = parse_model_output(&text).map_err(|e| CorruptError::Unparsable(e.to_string()))?;
    if parsed.layout != layout || parsed.graph_lines != lines {
        return Err(CorruptError::NotRoundTrip);
    }
    Ok(Corrupted { text, detail })
}

type Parts = (LlmLayout, Vec<String>, Option<String>, String);

/// The fields of a triplet line `(a, rel, b)` (or of any parenthesised line).
pub fn triplet_fields(line: &str) -> Option<Vec<&str>> {
    let inner = line.trim().strip_prefix('(')?.strip_suffix(')')?;
    Some(inner.split(", ").collect())
}

/// The relations a relation corruption may touch, with their wrong replacement.
pub const WRONG_RELATION: [(&str, &str); 6] = [
    ("left of", "right of"),
    ("right of", "left of"),
    ("in front of", "behind"),
    ("behind", "in front of"),
    ("above", "below"),
    ("in", "above"),
];

fn collision(
    input: &SceneRecordsInput,
    config: &RecordsConfig,
    graph: &GraphOptions,
    rng: &mut ChaCha8Rng,
) -> Result<Parts, CorruptError> {
    let cfg = &config.collision;
    let layout = &input.layout;
    let n = layout.objects.len();
    if n < 2 {
        return Err(CorruptError::TooFewObjects);
    }
    let tolerance_cm = cfg.tolerance_mm / 10.0;
    let before: BTreeSet<(String, String)> = input
        .collider
        .colliding_names(layout, tolerance_cm)
        .into_iter()
        .collect();
    let [x_min, x_max, y_min, y_max] = layout.zone_cm.0;
    let (width, depth) = (x_max - x_min, y_max - y_min);
    let most = ((n as f64 * cfg.subset_fraction).ceil() as usize).clamp(1, n);
    for _ in 0..cfg.attempts {
        let mut perturbed = layout.clone();
        let mut changes = Vec::new();
        let k = rng.random_range(1..=most);
        for i in sample(rng, n, k).into_iter() {
            let object = &mut perturbed.objects[i];
            let draw: f64 = rng.random();
            if draw < cfg.position_probability {
                let dx = rng.random_range(-1.0..=1.0) * cfg.max_shift_fraction * width;
                let dy = rng.random_range(-1.0..=1.0) * cfg.max_shift_fraction * depth;
                object.position_cm.0[0] += dx;
                object.position_cm.0[1] += dy;
                changes.push(format!(
                    "moved {} by ({dx:.1}, {dy:.1}) cm",
                    object.instance
                ));
            } else if draw < cfg.position_probability + cfg.rotation_probability {
                let turn = rng.random_range(15.0..=cfg.max_rotation_deg)
                    * if rng.random_bool(0.5) { 1.0 } else { -1.0 };
                object.z_rotation_deg = normalize_deg(object.z_rotation_deg + turn);
                changes.push(format!("turned {} by {turn:.1}°", object.instance));
            } else {
                let growth = rng.random_range(0.05..=cfg.max_size_growth);
                let height = object.size_cm.0[2];
                object.size_cm.0 = object.size_cm.0.map(|s| s * (1.0 + growth));
                // The bottom stays where it was.
                object.position_cm.0[2] += growth * height / 2.0;
                changes.push(format!(
                    "grew {} by {:.0}%",
                    object.instance,
                    growth * 100.0
                ));
            }
            keep_inside(object, &layout.zone_cm.0);
        }
        let perturbed = round_layout(&perturbed, config.decimals);
        let new: Vec<(String, String)> = input
            .collider
            .colliding_names(&perturbed, tolerance_cm)
            .into_iter()
            .filter(|pair| !before.contains(pair))
            .collect();
        if new.is_empty() {
            continue;
        }
        let scene = GraphScene::from_llm(&perturbed);
        let lines = extract_graph(&scene, &input.containers, graph)
            .map_err(|e| CorruptError::NoGraph(e.to_string()))?
            .triplet_lines();
        let pairs: Vec<String> = new.iter().map(|(a, b)| format!("{a} × {b}")).collect();
        let detail = format!("{}; new collision {}", changes.join(", "), pairs.join(", "));
        return Ok((perturbed, lines, None, detail));
    }
    Err(CorruptError::NoCollision {
        attempts: cfg.attempts,
    })
}

/// Moves an object's centre so its turned footprint lies inside the zone (centred where the
/// footprint is wider than the zone).
fn keep_inside(object: &mut mesa_schemas::LlmObject, zone: &[f64; 4]) {
    let half = YawBox::of(object).footprint_half_cm();
    for axis in 0..2 {
        let (low, high) = (zone[2 * axis], zone[2 * axis + 1]);
        let value = &mut object.position_cm.0[axis];
        *value = if 2.0 * half[axis] >= high - low {
            (low + high) / 2.0
        } else {
            value.clamp(low + half[axis], high - half[axis])
        };
    }
}

fn relation(
    input: &SceneRecordsInput,
    cfg: &RelationConfig,
    rng: &mut ChaCha8Rng,
) -> Result<Parts, CorruptError> {
    let edges: Vec<usize> = input
        .graph_lines
        .iter()
        .enumerate()
        .filter(|(_, line)| {
            triplet_fields(line)
                .is_some_and(|f| f.len() == 3 && WRONG_RELATION.iter().any(|(r, _)| *r == f[1]))
        })
        .map(|(i, _)| i)
        .collect();
    if edges.is_empty() {
        return Err(CorruptError::NoRelation);
    }
    let m = edges.len();
    let share = rng.random_range(cfg.min_fraction..=cfg.max_fraction);
    let k = ((m as f64 * share).round() as usize).clamp(1, m);
    let chosen: BTreeSet<usize> = sample(rng, m, k).into_iter().map(|j| edges[j]).collect();
    let mut lines = Vec::with_capacity(input.graph_lines.len());
    let mut changes = Vec::new();
    for (i, line) in input.graph_lines.iter().enumerate() {
        if !chosen.contains(&i) {
            lines.push(line.clone());
            continue;
        }
        if rng.random_bool(cfg.removal_probability) {
            changes.push(format!("removed {line}"));
            continue;
        }
        let fields = triplet_fields(line).unwrap_or_default();
        let wrong = WRONG_RELATION
            .iter()
            .find(|(r, _)| *r == fields[1])
            .map_or(fields[1], |(_, w)| *w);
        let changed = format!("({}, {wrong}, {})", fields[0], fields[2]);
        changes.push(format!("{line} → {changed}"));
        lines.push(changed);
    }
    Ok((input.layout.clone(), lines, None, changes.join("; ")))
}

fn missing_object(
    input: &SceneRecordsInput,
    task: &TaskRecord,
    cfg: &MissingObjectConfig,
    rng: &mut ChaCha8Rng,
) -> Result<Parts, CorruptError> {
    let layout = &input.layout;
    let types = SceneTypes::of_layout(layout);
    let core = core_types(&types, &task.task_info.objects_cluster);
    let candidates: Vec<&str> = core
        .iter()
        .flat_map(|t| t.instances.iter().map(String::as_str))
        .collect();
    if candidates.is_empty() {
        return Err(CorruptError::NoTaskObject);
    }
    let most = (cfg.max_removed as usize)
        .min(candidates.len())
        .min(layout.objects.len() - 1);
    if most == 0 {
        return Err(CorruptError::WouldEmptyLayout);
    }
    let k = rng.random_range(1..=most);
    let mut removed: Vec<&str> = sample(rng, candidates.len(), k)
        .into_iter()
        .map(|i| candidates[i])
        .collect();
    removed.sort_unstable();
    let mut corrupted = layout.clone();
    corrupted
        .objects
        .retain(|o| !removed.contains(&o.instance.as_str()));
    let lines: Vec<String> = input
        .graph_lines
        .iter()
        .filter(|line| {
            !triplet_fields(line).is_some_and(|fields| fields.iter().any(|f| removed.contains(f)))
        })
        .cloned()
        .collect();
    let mut by_type: Vec<(String, usize)> = Vec::new();
    for instance in &removed {
        let key = types
            .types
            .iter()
            .find(|t| t.instances.iter().any(|i| i == instance))
            .map(|t| t.key.clone())
            .unwrap_or_default();
        match by_type.iter_mut().find(|(k, _)| *k == key) {
            Some((_, n)) => *n += 1,
            None => by_type.push((key, 1)),
        }
    }
    let reasoning =
        rewrite_counts(&task.reasoning, &types, &by_type).ok_or(CorruptError::NoReasoningLists)?;
    Ok((
        corrupted,
        lines,
        Some(reasoning),
        format!("deleted {}", removed.join(", ")),
    ))
}
