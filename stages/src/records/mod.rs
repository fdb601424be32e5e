//! Training records (SPEC 5.9): SFT records in LLaMA-Factory's alpaca form and TRL's
//! conversational form, DPO pairs from three verified corruptions of the chosen output, the
//! `dataset_info.json` registry, and the stratified split.
//!
//! - the SFT `instruction` is the layout-generation prompt (`data/prompts/layout_generation.txt`),
//!   the `input` the task info JSON (zones from the layout), the `output` the model output text
//!   (SPEC 4): reasoning, scene-graph lines, the marker, the LLM layout JSON;
//! - [`corrupt`]: the collision, relation and missing-object corruptions, each verified;
//! - [`collide`]: the collision test of the collision corruption (`mesa check`'s mesh test,
//!   or oriented boxes for layouts without assets);
//! - [`split`]: train / dpo / test by scene, deterministic, stratified by table type;
//! - [`write`](mod@write): streaming JSON array and JSON Lines writers, `dataset_info.json`.
//!
//! Everything here is a pure function of its inputs and the seed; the pipeline's `records`
//! command reads the scenes, calls these, and writes the files atomically.

pub mod collide;
pub mod corrupt;
pub mod split;
pub mod write;

use mesa_schemas::artifacts::{
    ChatMessage, DpoRecord, SftRecord, TaskRecord, TrlDpoRecord, TrlSftRecord,
};
use mesa_schemas::output::{compose_model_output, parse_model_output};
use mesa_schemas::units::{PositionCm, SizeCm, ZoneCm};
use mesa_schemas::LlmLayout;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::graph::GraphOptions;
use crate::tasks::scene::task_info_json;

pub use corrupt::Corruption;

/// The `[records]` section of `mesa.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct RecordsConfig {
    /// Decimals kept of every length (cm) and angle (degrees) in the records' layouts and
    /// zones (the published records have 1).
    pub decimals: u32,
    /// A layout-generation prompt file (the `instruction` of every record), relative to the
    /// dataset folder; "" uses the built-in data/prompts/layout_generation.txt.
    pub layout_prompt: String,
    /// Rejected outputs per DPO prompt, each from a different corruption (the paper: 2).
    pub rejected_per_prompt: u32,
    /// The corruptions DPO rejected outputs are drawn from, in a seeded order per prompt:
    /// "collision", "relation", "missing_object".
    pub corruptions: Vec<Corruption>,
    /// The collision corruption.
    pub collision: corrupt::CollisionConfig,
    /// The relation corruption.
    pub relation: corrupt::RelationConfig,
    /// The missing-object corruption.
    pub missing_object: corrupt::MissingObjectConfig,
    /// The share of scenes in each split.
    pub split: split::SplitRatios,
    /// Keep the scenes that failed `mesa check`: qa/check.json finds the layout not clean (a
    /// collision, a floating object, a zone violation, an object it could not check) and no
    /// settled layout replaced it. By default they are left out of the records, listed in
    /// records/split.json and counted in the summary. Scenes never checked (or whose check
    /// could not run, e.g. without an asset index) are kept.
    pub keep_failed_check: bool,
}

impl Default for RecordsConfig {
    fn default() -> Self {
        Self {
            decimals: 1,
            layout_prompt: String::new(),
            rejected_per_prompt: 2,
            corruptions: vec![
                Corruption::Collision,
                Corruption::Relation,
                Corruption::MissingObject,
            ],
            collision: corrupt::CollisionConfig::default(),
            relation: corrupt::RelationConfig::default(),
            missing_object: corrupt::MissingObjectConfig::default(),
            split: split::SplitRatios::default(),
            keep_failed_check: false,
        }
    }
}

impl RecordsConfig {
    /// What is wrong with the values, one line each (checked before any work starts).
    pub fn problems(&self) -> Vec<String> {
        let mut problems = self.split.problems();
        if self.decimals > 6 {
            problems.push(format!(
                "[records] decimals is {} (expected 0 to 6)",
                self.decimals
            ));
        }
        let mut seen = Vec::new();
        for c in &self.corruptions {
            if seen.contains(c) {
                problems.push(format!(
                    "[records] corruptions lists \"{}\" twice",
                    c.name()
                ));
            }
            seen.push(*c);
        }
        if self.rejected_per_prompt as usize > self.corruptions.len() {
            problems.push(format!(
                "[records] rejected_per_prompt is {} but corruptions has {} (each rejected output \
                 of a prompt comes from a different corruption)",
                self.rejected_per_prompt,
                self.corruptions.len()
            ));
        }
        problems.extend(self.collision.problems());
        problems.extend(self.relation.problems());
        if self.missing_object.max_removed == 0 {
            problems.push("[records.missing_object] max_removed is 0 (expected at least 1)".into());
        }
        problems
    }
}

/// A value rounded to `decimals` (and never `-0`).
pub fn round_to(value: f64, decimals: u32) -> f64 {
    let scale = 10f64.powi(decimals as i32);
    (value * scale).round() / scale + 0.0
}

/// An LLM layout with every number rounded to `decimals`; sizes stay positive (at least one
/// unit of the last decimal).
pub fn round_layout(layout: &LlmLayout, decimals: u32) -> LlmLayout {
    let zone = |z: &ZoneCm| ZoneCm(z.0.map(|v| round_to(v, decimals)));
    let least = 10f64.powi(-(decimals as i32));
    LlmLayout {
        zone_cm: zone(&layout.zone_cm),
        sink_zone_cm: layout.sink_zone_cm.as_ref().map(zone),
        objects: layout
            .objects
            .iter()
            .map(|o| mesa_schemas::LlmObject {
                instance: o.instance.clone(),
                size_cm: SizeCm(o.size_cm.0.map(|v| round_to(v, decimals).max(least))),
                position_cm: PositionCm(o.position_cm.0.map(|v| round_to(v, decimals))),
                z_rotation_deg: round_to(o.z_rotation_deg, decimals),
                description: o.description.clone(),
            })
            .collect(),
    }
}

/// What the records of one scene are built from.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneRecordsInput {
    /// The scene id.
    pub scene_id: String,
    /// The layout in the LLM form, objects in the scene graph's order, rounded
    /// ([`round_layout`]).
    pub layout: LlmLayout,
    /// The scene-graph lines (`graph/graph.txt`).
    pub graph_lines: Vec<String>,
    /// The container flag of each object, in layout order (`graph/graph.json`), for the scene
    /// graph of a corrupted layout.
    pub containers: Vec<bool>,
    /// The scene's tasks.
    pub tasks: Vec<TaskRecord>,
    /// How the collision corruption finds colliding pairs.
    pub collider: collide::Collider,
}

/// A record that could not be built, with why.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("task {task_index}: {problem}")]
pub struct RecordError {
    /// The task.
    pub task_index: u32,
    /// What went wrong.
    pub problem: String,
}

/// The SFT `input` of a task: its task info with the zones of the (rounded) layout, as
/// 2-space-indented JSON with non-ASCII characters unescaped.
pub fn sft_input(task: &TaskRecord, layout: &LlmLayout) -> String {
    let mut info = task.task_info.clone();
    info.zone_cm = layout.zone_cm;
    info.sink_zone_cm = layout.sink_zone_cm;
    task_info_json(&info)
}

/// The SFT record of a task, checked: its output parses under the paper's success rule and
/// gives back exactly the layout, the graph lines and the reasoning.
pub fn sft_record(
    instruction: &str,
    input: &SceneRecordsInput,
    task: &TaskRecord,
) -> Result<SftRecord, RecordError> {
    let fail = |problem: String| RecordError {
        task_index: task.task_index,
        problem,
    };
    let output = compose_model_output(&task.reasoning, &input.graph_lines, &input.layout)
        .map_err(|e| fail(format!("cannot serialise the layout: {e}")))?;
    let parsed = parse_model_output(&output)
        .map_err(|e| fail(format!("the output text does not parse: {e}")))?;
    if parsed.layout != input.layout
        || parsed.graph_lines != input.graph_lines
        || parsed.reasoning != task.reasoning.trim_end()
    {
        return Err(fail(
            "the output text does not give back its parts (a reasoning line shaped like a \
             triplet, or a layout value JSON cannot carry)"
                .to_owned(),
        ));
    }
    Ok(SftRecord {
        instruction: instruction.to_owned(),
        input: sft_input(task, &input.layout),
        output,
    })
}

/// The user turn a trainer builds from an alpaca record: `instruction + "\n" + input`
/// (LLaMA-Factory's alpaca converter joins the two with one line break).
pub fn user_turn(instruction: &str, input: &str) -> String {
    let mut turn = String::with_capacity(instruction.len() + input.len() + 1);
    turn.push_str(instruction);
    turn.push('\n');
    turn.push_str(input);
    turn
}

fn message(role: &str, content: String) -> ChatMessage {
    ChatMessage {
        role: role.to_owned(),
        content,
    }
}

/// The TRL conversational form of an SFT record.
pub fn trl_sft(record: &SftRecord) -> TrlSftRecord {
    TrlSftRecord {
        messages: vec![
            message("user", user_turn(&record.instruction, &record.input)),
            message("assistant", record.output.clone()),
        ],
    }
}

/// The TRL conversational preference form of a DPO record.
pub fn trl_dpo(record: &DpoRecord) -> TrlDpoRecord {
    TrlDpoRecord {
        prompt: vec![message(
            "user",
            user_turn(&record.instruction, &record.input),
        )],
        chosen: vec![message("assistant", record.chosen.clone())],
        rejected: vec![message("assistant", record.rejected.clone())],
    }
}

/// A DPO pair with the corruption that made its rejected output.
#[derive(Debug, Clone, PartialEq)]
pub struct DpoPair {
    /// The record.
    pub record: DpoRecord,
    /// The corruption.
    pub corruption: Corruption,
    /// What it changed, for the logs (`moved mug_0 by (3.1, -4.0) cm; new collision mug_0 ×
    /// tray_0`).
    pub detail: String,
}

/// The DPO pairs of one task: up to `rejected_per_prompt` rejected outputs, each from a
/// different corruption tried in a seeded order, each verified. Also what could not be done.
pub fn dpo_pairs(
    instruction: &str,
    input: &SceneRecordsInput,
    task: &TaskRecord,
    sft: &SftRecord,
    config: &RecordsConfig,
    graph: &GraphOptions,
    seed: u64,
) -> (Vec<DpoPair>, Vec<String>) {
    let mut pairs = Vec::new();
    let mut notes = Vec::new();
    let order = corrupt::order(&config.corruptions, seed, &input.scene_id, task.task_index);
    for corruption in order {
        if pairs.len() == config.rejected_per_prompt as usize {
            break;
        }
        match corrupt::corrupt(corruption, input, task, config, graph, seed) {
            Ok(corrupted) => pairs.push(DpoPair {
                record: DpoRecord {
                    instruction: instruction.to_owned(),
                    input: sft.input.clone(),
                    chosen: sft.output.clone(),
                    rejected: corrupted.text,
                },
                corruption,
                detail: corrupted.detail,
            }),
            Err(why) => notes.push(format!(
                "task {}: no {} corruption: {why}",
                task.task_index,
                corruption.name()
            )),
        }
    }
    if pairs.len() < config.rejected_per_prompt as usize {
        notes.push(format!(
            "task {}: {} rejected outputs of {} asked",
            task.task_index,
            pairs.len(),
            config.rejected_per_prompt
        ));
    }
    (pairs, notes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use mesa_schemas::artifacts::TASKS_SCHEMA;
    use mesa_schemas::TaskInfo;

    fn task(info: TaskInfo) -> TaskRecord {
        TaskRecord {
            schema: TASKS_SCHEMA.to_owned(),
            scene_id: "bathroom_vanity_0001".to_owned(),
            task_index: 0,
            generator: "template".to_owned(),
            layout: "qa/layout.json".to_owned(),
            layout_sha256: String::new(),
            views: Vec::new(),
            table_description: info.environment.clone(),
            task_info: info,
            reasoning: String::new(),
        }
    }

    #[test]
    fn the_input_is_json_dumps_indent_2_without_ascii_escapes_with_the_layouts_zones() {
        let info = TaskInfo {
            environment: "Un lavabo: savon, crème \"douce\"".to_owned(),
            zone_cm: ZoneCm([0.0, 1.0, 0.0, 1.0]),
            sink_zone_cm: None,
            task: "Ranger".to_owned(),
            goal: vec!["Pick la crème".to_owned()],
            action_sequence: Some(vec!["Pick(Crème)".to_owned()]),
            objects_cluster: vec!["Crème".to_owned(), "Savon".to_owned()],
        };
        let layout = LlmLayout {
            zone_cm: ZoneCm([0.0, 187.0, 0.0, 52.3]),
            sink_zone_cm: Some(ZoneCm([68.7, 127.5, 7.4, 46.6])),
            objects: Vec::new(),
        };
        // What Python's json.dumps(info, indent=2, ensure_ascii=False) writes.
        let expected = "{\n  \"Environment\": \"Un lavabo: savon, crème \\\"douce\\\"\",\n  \
            \"item_placement_zone\": [\n    0.0,\n    187.0,\n    0.0,\n    52.3\n  ],\n  \
            \"sink_zone\": [\n    68.7,\n    127.5,\n    7.4,\n    46.6\n  ],\n  \
            \"Task\": \"Ranger\",\n  \"Goal\": [\n    \"Pick la crème\"\n  ],\n  \
            \"Action Sequence\": [\n    \"Pick(Crème)\"\n  ],\n  \
            \"Objects cluster\": [\n    \"Crème\",\n    \"Savon\"\n  ]\n}";
        let input = sft_input(&task(info), &layout);
        assert_eq!(input, expected);
        assert_eq!(
            user_turn("Lay it out.", &input),
            format!("Lay it out.\n{expected}")
        );
    }

    #[test]
    fn rounding_keeps_one_decimal_positive_sizes_and_no_negative_zero() {
        assert_eq!(round_to(116.70000000000002, 1), 116.7);
        assert_eq!(round_to(-0.04, 1).to_string(), "0");
        let layout = LlmLayout {
            zone_cm: ZoneCm([0.0, 100.04, 0.0, 50.0]),
            sink_zone_cm: None,
            objects: vec![mesa_schemas::LlmObject {
                instance: "pen_0".to_owned(),
                size_cm: SizeCm([0.01, 14.26, 1.0]),
                position_cm: PositionCm([10.05, 20.0, 0.5]),
                z_rotation_deg: -0.01,
                description: String::new(),
            }],
        };
        let rounded = round_layout(&layout, 1);
        assert_eq!(rounded.zone_cm.0[1], 100.0);
        assert_eq!(rounded.objects[0].size_cm.0, [0.1, 14.3, 1.0]);
        assert_eq!(
            serde_json::to_string(&rounded.objects[0].z_rotation_deg).expect("json"),
            "0.0"
        );
    }
}
