//! The LLM layout (the model's output JSON), task info, and the published MesaTask records.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::units::{PositionCm, SizeCm, ZoneCm};
use crate::Problem;

/// A layout in the form the MesaTask model writes: centimetres, yaw in degrees.
///
/// This is a foreign format (no `schema` field; keys in the order the published records use).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct LlmLayout {
    /// The item placement zone [x_min, x_max, y_min, y_max] in cm.
    #[serde(rename = "item_placement_zone")]
    pub zone_cm: ZoneCm,
    /// The sink of a bathroom vanity [x_min, x_max, y_min, y_max] in cm.
    #[serde(rename = "sink_zone", default, skip_serializing_if = "Option::is_none")]
    pub sink_zone_cm: Option<ZoneCm>,
    /// Objects by descending footprint w·d (ties by instance name).
    pub objects: Vec<LlmObject>,
}

/// One object of an LLM layout, fields in the published records' order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct LlmObject {
    /// Instance name: category and index, like `pen_0`.
    /// 1 to 64 ASCII letters, digits, `_` or `-`, starting with a letter or digit.
    #[schemars(pattern(crate::validate::INSTANCE_NAME_PATTERN))]
    pub instance: String,
    /// [width, depth, height] in cm before rotation.
    #[serde(rename = "size")]
    pub size_cm: SizeCm,
    /// Centre of the bounding box [x, y, z] in cm.
    #[serde(rename = "position")]
    pub position_cm: PositionCm,
    /// Yaw in degrees: 0 faces the observer (-y), counter-clockwise positive seen from above.
    #[serde(rename = "z_rotation")]
    pub z_rotation_deg: f64,
    /// A brief description of the object.
    #[serde(default)]
    pub description: String,
}

impl LlmLayout {
    /// Sorts objects by descending footprint w·d, ties by instance name (the published order);
    /// whether the order changed.
    pub fn sort_objects(&mut self) -> bool {
        crate::order::sort_by_footprint(&mut self.objects, |o| (&o.instance, o.size_cm.0))
    }

    /// Checks what the JSON Schema cannot say: unique instances and ordered zones.
    pub fn problems(&self) -> Vec<Problem> {
        let mut problems = Vec::new();
        crate::units::check_zone(&self.zone_cm, "$.item_placement_zone", true, &mut problems);
        if let Some(zone) = &self.sink_zone_cm {
            crate::units::check_zone(zone, "$.sink_zone", false, &mut problems);
        }
        problems.extend(crate::validate::invalid_instances(
            self.objects.iter().map(|o| o.instance.as_str()),
        ));
        problems.extend(crate::validate::duplicate_instances(
            self.objects.iter().map(|o| o.instance.as_str()),
        ));
        problems
    }
}

/// The task description a layout is generated from (the model's input, SPEC section 4).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TaskInfo {
    /// A sentence describing the tabletop environment.
    #[serde(rename = "Environment")]
    pub environment: String,
    /// The item placement zone [x_min, x_max, y_min, y_max] in cm.
    #[serde(rename = "item_placement_zone")]
    pub zone_cm: ZoneCm,
    /// The sink of a bathroom vanity [x_min, x_max, y_min, y_max] in cm.
    #[serde(rename = "sink_zone", default, skip_serializing_if = "Option::is_none")]
    pub sink_zone_cm: Option<ZoneCm>,
    /// The task instruction.
    #[serde(rename = "Task")]
    pub task: String,
    /// Goal statements.
    #[serde(rename = "Goal")]
    pub goal: Vec<String>,
    /// Primitive actions: Pick(obj), PlaceOn(obj), PlaceAt(pos), Push(obj, dir, dist),
    /// RevoluteJointOpen(obj), RevoluteJointClose(obj), PrismaticJointOpen(obj),
    /// PrismaticJointClose(obj), Press(obj). Absent in the published records.
    #[serde(
        rename = "Action Sequence",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub action_sequence: Option<Vec<String>>,
    /// Object types (not instance ids) the task involves.
    #[serde(rename = "Objects cluster")]
    pub objects_cluster: Vec<String>,
}

/// The primitive actions a task's action sequence may use, with their argument counts.
pub const PRIMITIVE_ACTIONS: [(&str, usize); 9] = [
    ("Pick", 1),
    ("PlaceOn", 1),
    ("PlaceAt", 1),
    ("Push", 3),
    ("RevoluteJointOpen", 1),
    ("RevoluteJointClose", 1),
    ("PrismaticJointOpen", 1),
    ("PrismaticJointClose", 1),
    ("Press", 1),
];

impl TaskInfo {
    /// Checks the action sequence against the primitive actions.
    pub fn problems(&self) -> Vec<Problem> {
        let mut problems = Vec::new();
        crate::units::check_zone(&self.zone_cm, "$.item_placement_zone", true, &mut problems);
        for (i, action) in self.action_sequence.iter().flatten().enumerate() {
            if let Err(problem) = check_action(action) {
                problems.push(Problem::new(
                    format!("$[\"Action Sequence\"][{i}]"),
                    problem,
                    "Name(arg, ...) with a primitive action: Pick, PlaceOn, PlaceAt, Push, \
                     RevoluteJointOpen, RevoluteJointClose, PrismaticJointOpen, \
                     PrismaticJointClose, Press",
                ));
            }
        }
        problems
    }
}

/// Checks one action of an action sequence: a primitive action with its number of arguments
/// (`Pick(mug)`, `Push(box, left, 10 cm)`); the error says what is wrong.
pub fn check_action(action: &str) -> Result<(), String> {
    let action = action.trim();
    let (name, rest) = action
        .split_once('(')
        .ok_or_else(|| format!("\"{action}\" has no argument list"))?;
    let args = rest
        .strip_suffix(')')
        .ok_or_else(|| format!("\"{action}\" does not end with ')'"))?;
    let Some((_, arity)) = PRIMITIVE_ACTIONS.iter().find(|(n, _)| *n == name.trim()) else {
        return Err(format!("unknown action \"{}\"", name.trim()));
    };
    // PlaceAt takes a position, which may itself contain commas: only check it is non-empty.
    let count = if *arity == 1 {
        usize::from(!args.trim().is_empty())
    } else {
        args.split(',').filter(|a| !a.trim().is_empty()).count()
    };
    if count != *arity {
        return Err(format!(
            "\"{action}\" has {count} arguments, {name} takes {arity}"
        ));
    }
    Ok(())
}

/// A value that published records store either inline or as a JSON string.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(untagged)]
pub enum InlineOrString<T> {
    /// The value itself.
    Inline(T),
    /// The value serialised to a JSON string.
    Text(String),
}

impl<T: serde::de::DeserializeOwned + Clone> InlineOrString<T> {
    /// The value, parsing it when it is stored as text.
    pub fn resolve(&self) -> Result<T, serde_json::Error> {
        match self {
            Self::Inline(value) => Ok(value.clone()),
            Self::Text(text) => serde_json::from_str(text),
        }
    }
}

/// A scene graph stored as a list of triplet lines or as one newline-separated text.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(untagged)]
pub enum GraphLines {
    /// One triplet per item.
    Lines(Vec<String>),
    /// Triplets separated by newlines.
    Text(String),
}

impl GraphLines {
    /// The triplet lines.
    pub fn lines(&self) -> Vec<String> {
        match self {
            Self::Lines(lines) => lines.clone(),
            Self::Text(text) => text
                .lines()
                .map(str::trim)
                .filter(|l| !l.is_empty())
                .map(str::to_owned)
                .collect(),
        }
    }
}

/// A published MesaTask record (the project page's gallery): prompt, task, model output parts.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct GalleryRecord {
    /// The layout-generation instruction given to the model.
    pub prompt_instructions: String,
    /// The task info, inline or as a JSON string.
    pub input_task_description: InlineOrString<TaskInfo>,
    /// The reasoning paragraph of the model output.
    pub reasoning_paragraph: String,
    /// The scene-graph triplets of the model output.
    pub scene_graph: GraphLines,
    /// The layout of the model output, inline or as a JSON string.
    pub scene_layout_json: InlineOrString<LlmLayout>,
}
