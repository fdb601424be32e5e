//! Reading a layout document of any form: a dataset layout, an LLM layout, or a published
//! MesaTask record (its `scene_layout_json`, inline or stored as a JSON string). The form is
//! recognised by shape, the document validated, and problems inside `objects[i]` name the
//! instance, so that every reader of layouts (`convert`, `graph --layout`, the stages) reports
//! the same way.

use serde_json::Value;

use crate::json::{parse_lenient, NONFINITE_PREFIX};
use crate::layout::{DatasetLayout, LAYOUT_SCHEMA};
use crate::llm::LlmLayout;
use crate::{Kind, Problem};

pub use crate::layout_plain::read_plain_dataset_layout;

/// The form a layout document was recognised as.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LayoutForm {
    /// A dataset layout (`layout.json`: quaternions, `retrieved_uid`).
    Dataset,
    /// An LLM layout (the model's output JSON: `z_rotation`).
    Llm,
    /// A published MesaTask record: its `scene_layout_json`.
    GalleryRecord,
}

impl LayoutForm {
    /// A short name for messages.
    pub fn name(self) -> &'static str {
        match self {
            Self::Dataset => "dataset layout",
            Self::Llm => "LLM layout",
            Self::GalleryRecord => "published record",
        }
    }
}

/// A layout in the form it was read in.
#[derive(Debug, Clone, PartialEq)]
pub enum AnyLayout {
    /// A dataset layout.
    Dataset(DatasetLayout),
    /// An LLM layout (also what a published record holds).
    Llm(LlmLayout),
}

/// A validated layout document.
#[derive(Debug, Clone, PartialEq)]
pub struct ReadLayout {
    /// What the document was recognised as.
    pub form: LayoutForm,
    /// The layout, objects in the document's order.
    pub layout: AnyLayout,
}

/// The form of a layout document: a `scene_layout_json` field makes a published record;
/// `"schema": "mesa.layout/1"`, or a first object with `rotation` or `retrieved_uid`, a
/// dataset layout; a first object with `z_rotation`, or a `sink_zone`, an LLM layout; anything
/// else is read as a dataset layout (whose validation then says what is missing).
pub fn layout_form_of(value: &Value) -> LayoutForm {
    if value.get("scene_layout_json").is_some() {
        return LayoutForm::GalleryRecord;
    }
    if value.get("schema").and_then(Value::as_str) == Some(LAYOUT_SCHEMA) {
        return LayoutForm::Dataset;
    }
    let first = value
        .get("objects")
        .and_then(Value::as_array)
        .and_then(|objects| objects.first());
    match first {
        Some(o) if o.get("rotation").is_some() || o.get("retrieved_uid").is_some() => {
            LayoutForm::Dataset
        }
        Some(o) if o.get("z_rotation").is_some() => LayoutForm::Llm,
        _ if value.get("sink_zone").is_some() => LayoutForm::Llm,
        _ => LayoutForm::Dataset,
    }
}

/// Reads and validates layout text of any form; every problem is returned.
///
/// A layout as mesa writes it is read straight into its type (the `layout_plain` module); any
/// other document, and every invalid one, goes through the general reader, which names each
/// problem's JSON path. Both give the same result for what the quick one accepts.
pub fn read_layout_text(text: &str) -> Result<ReadLayout, Vec<Problem>> {
    if let Some(layout) = crate::layout_plain::read_plain_dataset_layout(text) {
        return Ok(ReadLayout {
            form: LayoutForm::Dataset,
            layout: AnyLayout::Dataset(layout),
        });
    }
    read_layout_text_general(text)
}

/// [`read_layout_text`] without the quick reader of plain dataset layouts: the document parsed
/// into a `Value`, recognised, checked against its kind's JSON Schema, then converted.
pub fn read_layout_text_general(text: &str) -> Result<ReadLayout, Vec<Problem>> {
    let value = parse_lenient(text).map_err(|e| {
        vec![Problem::new(
            "$",
            format!("is not valid JSON: {e}"),
            "a layout JSON document",
        )]
    })?;
    read_layout_value(&value)
}

/// Reads and validates a layout document of any form; every problem is returned.
pub fn read_layout_value(value: &Value) -> Result<ReadLayout, Vec<Problem>> {
    if !value.is_object() {
        return Err(vec![Problem::new(
            "$",
            crate::validate::describe(value),
            "a JSON object: a dataset layout, an LLM layout or a published record",
        )]);
    }
    let form = layout_form_of(value);
    if form == LayoutForm::GalleryRecord {
        // The record's own structure first, then the layout inside it (which a record may
        // store as a JSON string, out of the record schema's reach).
        const AT: &str = "$.scene_layout_json";
        let inner = inner_layout(&value["scene_layout_json"]);
        let problems = validate_kind("gallery-record", value);
        if !problems.is_empty() {
            return Err(name_objects(problems, inner.as_ref(), AT));
        }
        let inner = inner.ok_or_else(|| {
            vec![Problem::new(
                AT,
                "is a string that is not JSON",
                "an LLM layout, inline or as a JSON string",
            )]
        })?;
        let problems: Vec<Problem> = validate_kind("llm-layout", &inner)
            .into_iter()
            .map(|mut p| {
                p.path = p.path.replacen('$', AT, 1);
                p
            })
            .collect();
        if !problems.is_empty() {
            return Err(name_objects(problems, Some(&inner), AT));
        }
        return Ok(ReadLayout {
            form,
            layout: AnyLayout::Llm(typed(&inner)?),
        });
    }
    let kind = if form == LayoutForm::Dataset {
        "layout"
    } else {
        "llm-layout"
    };
    // The structure, then the semantic checks on the typed layout: what `validate_kind` does,
    // with the document converted once.
    let problems = match Kind::by_name(kind) {
        Some(kind) => kind.structure_problems(value),
        None => validate_kind(kind, value),
    };
    if !problems.is_empty() {
        return Err(name_objects(problems, Some(value), "$"));
    }
    let (layout, problems) = match form {
        LayoutForm::Dataset => {
            let layout: DatasetLayout = typed(value)?;
            let problems = layout.problems();
            (AnyLayout::Dataset(layout), problems)
        }
        _ => {
            let layout: LlmLayout = typed(value)?;
            let problems = layout.problems();
            (AnyLayout::Llm(layout), problems)
        }
    };
    if !problems.is_empty() {
        return Err(name_objects(problems, Some(value), "$"));
    }
    Ok(ReadLayout { form, layout })
}

fn validate_kind(kind: &str, value: &Value) -> Vec<Problem> {
    match Kind::by_name(kind) {
        Some(kind) => kind.validate_value(value),
        None => vec![Problem::new(
            "$",
            format!("no kind \"{kind}\""),
            "a known kind",
        )],
    }
}

fn typed<T: serde::de::DeserializeOwned>(value: &Value) -> Result<T, Vec<Problem>> {
    // Read from the borrowed value: no copy of the document.
    T::deserialize(value).map_err(|e| {
        vec![Problem::new(
            "$",
            format!("does not parse: {e}"),
            "a layout",
        )]
    })
}

/// The layout inside a record's `scene_layout_json` (inline, or a JSON string), if it parses.
fn inner_layout(inner: &Value) -> Option<Value> {
    match inner {
        Value::String(text) => parse_lenient(text).ok(),
        other => Some(other.clone()),
    }
}

/// Adds the instance name to problems located inside `<root>.objects[i]`.
fn name_objects(problems: Vec<Problem>, layout: Option<&Value>, root: &str) -> Vec<Problem> {
    let objects = layout
        .and_then(|l| l.get("objects"))
        .and_then(Value::as_array);
    let prefix = format!("{root}.objects[");
    problems
        .into_iter()
        .map(|mut problem| {
            let index = problem
                .path
                .strip_prefix(&prefix)
                .and_then(|rest| rest.split(']').next())
                .and_then(|i| i.parse::<usize>().ok());
            let instance = index
                .and_then(|i| objects?.get(i))
                .and_then(|o| o.get("instance"))
                .and_then(Value::as_str)
                .filter(|name| !name.starts_with(NONFINITE_PREFIX))
                // A name that breaks the rule is quoted in its own problem, never printed raw.
                .filter(|name| crate::validate::instance_name_problem(name).is_none());
            if let Some(instance) = instance {
                problem.problem = format!("{instance}: {}", problem.problem);
            }
            problem
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn forms_are_recognised_by_shape() {
        let llm = serde_json::json!({"item_placement_zone": [0, 1, 0, 1], "objects": [
            {"instance": "a_0", "size": [1, 1, 1], "position": [0, 0, 0], "z_rotation": 0}]});
        assert_eq!(layout_form_of(&llm), LayoutForm::Llm);
        let record = serde_json::json!({"scene_layout_json": llm.to_string()});
        assert_eq!(layout_form_of(&record), LayoutForm::GalleryRecord);
        assert_eq!(
            layout_form_of(&serde_json::json!({"objects": []})),
            LayoutForm::Dataset
        );
    }

    /// Reading a layout converts it to its type once and runs the semantic checks on that:
    /// the problems are exactly those of the kind's whole validation, named the same way.
    /// Control: each document has problems of the kind checked (structure or semantic).
    #[test]
    fn one_conversion_reports_what_the_kinds_validation_reports() {
        let object = |name: &str, quat: &str| {
            format!(
                r#"{{"instance": "{name}", "category": "mug", "position": [1, 2, 3],
                "size": [1, 1, 1], "rotation": {quat}, "scale_factor": [1, 1, 1],
                "retrieved_uid": "u"}}"#
            )
        };
        let unit = "[0, 0, 0, 1]";
        let dataset = |zone: &str, objects: &[String]| {
            format!(
                r#"{{"schema": "mesa.layout/1", "item_placement_zone": {zone},
                "objects": [{}]}}"#,
                objects.join(",")
            )
        };
        let llm = |zone: &str, names: &[&str]| {
            let objects: Vec<String> = names
                .iter()
                .map(|n| {
                    format!(
                        r#"{{"instance": "{n}", "size": [1, 1, 1], "position": [0, 0, 0],
                        "z_rotation": 0}}"#
                    )
                })
                .collect();
            format!(
                r#"{{"item_placement_zone": {zone}, "objects": [{}]}}"#,
                objects.join(",")
            )
        };
        let cases = [
            (
                "layout",
                dataset("[0, 10, 0, 10]", &[object("mug_0", unit)]),
            ),
            // Semantic: a reversed zone, a repeated instance, a quaternion far from unit.
            (
                "layout",
                dataset(
                    "[10, 0, 0, 10]",
                    &[object("mug_0", unit), object("mug_0", "[0, 0, 0, 2]")],
                ),
            ),
            // Structural: a missing size.
            (
                "layout",
                dataset(
                    "[0, 10, 0, 10]",
                    &[object("mug_0", unit).replace(r#""size": [1, 1, 1],"#, "")],
                ),
            ),
            ("llm-layout", llm("[0, 10, 0, 10]", &["a_0", "b_0"])),
            ("llm-layout", llm("[0, 10, 10, 0]", &["a_0", "a_0"])),
        ];
        let mut failing = 0;
        for (kind, text) in &cases {
            let value: Value = serde_json::from_str(text).expect("json");
            let whole = Kind::by_name(kind).expect("kind").validate_value(&value);
            let read = read_layout_text(text);
            if whole.is_empty() {
                assert!(read.is_ok(), "{text}: {read:?}");
            } else {
                failing += 1;
                let expected = name_objects(whole, Some(&value), "$");
                assert_eq!(read.expect_err("problems"), expected, "{text}");
            }
        }
        assert_eq!(failing, 3);
    }

    #[test]
    fn problems_inside_objects_name_the_instance() {
        let text = r#"{"item_placement_zone": [0, 1, 0, 1], "objects": [
            {"instance": "pen_0", "size": [1, 0, 1], "position": [0, 0, 0], "z_rotation": 0}]}"#;
        let problems = read_layout_text(text).expect_err("zero size");
        assert_eq!(problems.len(), 1);
        assert_eq!(problems[0].path, "$.objects[0].size[1]");
        assert!(
            problems[0].problem.starts_with("pen_0: is 0"),
            "{}",
            problems[0]
        );
    }
}
