//! The model output text (the SFT target, SPEC section 4) and its parser.
//!
//! The text is: a reasoning paragraph, the scene-graph triplets one per line, the exact marker
//! [`FINAL_ANSWER_MARKER`], then the layout JSON in the LLM form. The parser tolerates what
//! models emit around the JSON (a ```` ```json ```` fence, a trailing `<|im_end|>`), as the
//! official `extract_json_from_response` does, and applies the paper's success rule: the marker
//! is found, the JSON parses, and it has at least one valid object.

use serde_json::Value;

use crate::llm::{LlmLayout, LlmObject};
use crate::units::ZoneCm;

/// The exact text between the scene graph and the layout JSON.
pub const FINAL_ANSWER_MARKER: &str = "\nTherefore, the scene layout is:\n**Final Answer**\n";

/// The end-of-turn token of Qwen chat templates, which raw generations may keep.
pub const IM_END: &str = "<|im_end|>";

/// A model output that passed the success rule.
#[derive(Debug, Clone, PartialEq)]
pub struct ParsedOutput {
    /// The reasoning paragraph (text before the triplet lines).
    pub reasoning: String,
    /// The scene-graph triplet lines, in order.
    pub graph_lines: Vec<String>,
    /// The layout, with only the objects that are valid.
    pub layout: LlmLayout,
    /// Objects that were dropped, with the reason (`objects[i]: ...`).
    pub dropped_objects: Vec<String>,
}

/// Why a model output does not count as a success.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OutputError {
    /// The marker text is missing.
    #[error(
        "the marker \"\\nTherefore, the scene layout is:\\n**Final Answer**\\n\" was not found"
    )]
    NoMarker,
    /// The text after the marker is not JSON.
    #[error("the text after the marker is not valid JSON: {0}")]
    NotJson(String),
    /// The JSON is not a layout object.
    #[error("the layout JSON is not usable: {0}")]
    NotALayout(String),
    /// The layout has no valid object.
    #[error("the layout has no valid object ({0})")]
    NoValidObject(String),
}

/// Composes a model output text from its three parts (the SFT target).
///
/// `reasoning` + `"\n"` + the triplet lines joined by `"\n"` + [`FINAL_ANSWER_MARKER`] + the
/// layout as one-line JSON with the published key order.
pub fn compose_model_output(
    reasoning: &str,
    graph_lines: &[String],
    layout: &LlmLayout,
) -> Result<String, serde_json::Error> {
    let json = serde_json::to_string(layout)?;
    let mut text = String::with_capacity(reasoning.len() + json.len() + 64 * graph_lines.len());
    text.push_str(reasoning.trim_end());
    text.push('\n');
    text.push_str(&graph_lines.join("\n"));
    text.push_str(FINAL_ANSWER_MARKER);
    text.push_str(&json);
    Ok(text)
}

/// Extracts the layout JSON text after the marker, stripping `<|im_end|>` and a code fence.
pub fn layout_json_text(text: &str) -> Result<&str, OutputError> {
    let start = text
        .find(FINAL_ANSWER_MARKER)
        .ok_or(OutputError::NoMarker)?;
    let mut json = text[start + FINAL_ANSWER_MARKER.len()..].trim();
    if let Some(stripped) = json.strip_suffix(IM_END) {
        json = stripped.trim();
    }
    if let Some(stripped) = json.strip_suffix("```") {
        json = stripped.trim();
    }
    if let Some(stripped) = json.strip_prefix("```json") {
        json = stripped.trim();
    } else if let Some(stripped) = json.strip_prefix("```") {
        json = stripped.trim();
    }
    Ok(json)
}

/// Parses a model output under the paper's success rule.
pub fn parse_model_output(text: &str) -> Result<ParsedOutput, OutputError> {
    let json = layout_json_text(text)?;
    let value = crate::json::parse_unique(json).map_err(|e| OutputError::NotJson(e.to_string()))?;
    let layout = layout_from_value(&value)?;
    let start = text.find(FINAL_ANSWER_MARKER).unwrap_or(0);
    let (reasoning, graph_lines) = split_reasoning_and_graph(&text[..start]);
    Ok(ParsedOutput {
        reasoning,
        graph_lines,
        layout: layout.0,
        dropped_objects: layout.1,
    })
}

fn layout_from_value(value: &Value) -> Result<(LlmLayout, Vec<String>), OutputError> {
    let object = value
        .as_object()
        .ok_or_else(|| OutputError::NotALayout("it is not a JSON object".into()))?;
    let zone = |key: &str| -> Result<Option<ZoneCm>, OutputError> {
        match object.get(key) {
            None | Some(Value::Null) => Ok(None),
            Some(v) => serde_json::from_value::<ZoneCm>(v.clone())
                .map(Some)
                .map_err(|e| OutputError::NotALayout(format!("{key}: {e}"))),
        }
    };
    let zone_cm = zone("item_placement_zone")?
        .ok_or_else(|| OutputError::NotALayout("item_placement_zone is missing".into()))?;
    let sink_zone_cm = zone("sink_zone")?;
    let items = object
        .get("objects")
        .and_then(Value::as_array)
        .ok_or_else(|| OutputError::NotALayout("objects is missing or not a list".into()))?;
    let mut objects = Vec::new();
    let mut dropped = Vec::new();
    for (i, item) in items.iter().enumerate() {
        match serde_json::from_value::<LlmObject>(item.clone()) {
            Ok(o) if o.size_cm.0.iter().all(|s| s.is_finite() && *s > 0.0) => objects.push(o),
            Ok(_) => dropped.push(format!("objects[{i}]: size must be three positive numbers")),
            Err(e) => dropped.push(format!("objects[{i}]: {e}")),
        }
    }
    if objects.is_empty() {
        let why = if dropped.is_empty() {
            "objects is empty".to_owned()
        } else {
            dropped.join("; ")
        };
        return Err(OutputError::NoValidObject(why));
    }
    Ok((
        LlmLayout {
            zone_cm,
            sink_zone_cm,
            objects,
        },
        dropped,
    ))
}

/// Splits the text before the marker into the reasoning and the trailing triplet lines.
fn split_reasoning_and_graph(before: &str) -> (String, Vec<String>) {
    let lines: Vec<&str> = before.lines().collect();
    let mut first_graph = lines.len();
    while first_graph > 0 {
        let line = lines[first_graph - 1].trim();
        if line.is_empty() || (line.starts_with('(') && line.ends_with(')')) {
            first_graph -= 1;
        } else {
            break;
        }
    }
    let reasoning = lines[..first_graph].join("\n").trim_end().to_owned();
    let graph_lines = lines[first_graph..]
        .iter()
        .map(|l| l.trim())
        .filter(|l| !l.is_empty())
        .map(str::to_owned)
        .collect();
    (reasoning, graph_lines)
}

#[cfg(test)]
mod tests {
    use super::*;

    const LAYOUT: &str = r#"{"item_placement_zone": [0, 100, 0, 60], "objects": [
        {"instance": "mug_0", "size": [10, 8, 9], "position": [20, 30, 4.5], "z_rotation": 0, "description": "a mug"}]}"#;

    fn text(after_marker: &str) -> String {
        format!("Some reasoning.\n(mug_0, is at, middle_left)\n(mug_0, face to, front){FINAL_ANSWER_MARKER}{after_marker}")
    }

    #[test]
    fn plain_fenced_and_im_end_all_parse() {
        for tail in [
            LAYOUT.to_owned(),
            format!("```json\n{LAYOUT}\n```"),
            format!("```\n{LAYOUT}\n```<|im_end|>"),
            format!("{LAYOUT}<|im_end|>"),
        ] {
            let parsed = parse_model_output(&text(&tail)).expect("parses");
            assert_eq!(parsed.layout.objects.len(), 1);
            assert_eq!(parsed.reasoning, "Some reasoning.");
            assert_eq!(parsed.graph_lines.len(), 2);
        }
    }

    #[test]
    fn failures_say_why() {
        assert_eq!(parse_model_output(LAYOUT), Err(OutputError::NoMarker));
        assert!(matches!(
            parse_model_output(&text("{not json")),
            Err(OutputError::NotJson(_))
        ));
        assert!(matches!(
            parse_model_output(&text(
                r#"{"item_placement_zone": [0,1,0,1], "objects": []}"#
            )),
            Err(OutputError::NoValidObject(_))
        ));
        let bad = r#"{"item_placement_zone": [0,1,0,1], "objects": [{"instance": "a", "size": [1, -1, 1], "position": [0,0,0], "z_rotation": 0}]}"#;
        assert!(matches!(
            parse_model_output(&text(bad)),
            Err(OutputError::NoValidObject(_))
        ));
    }

    #[test]
    fn invalid_objects_are_dropped_not_fatal() {
        let mixed = r#"{"item_placement_zone": [0,1,0,1], "objects": [{"instance": "a"}, {"instance": "b", "size": [1,1,1], "position": [0,0,0], "z_rotation": 0}]}"#;
        let parsed = parse_model_output(&text(mixed)).expect("one valid object");
        assert_eq!(parsed.layout.objects.len(), 1);
        assert_eq!(parsed.dropped_objects.len(), 1);
    }
}
