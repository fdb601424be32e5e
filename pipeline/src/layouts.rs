//! Reading layouts in any of their forms, for `convert`, `graph --layout` and the stages.

use std::path::Path;

use anyhow::{bail, Context as _};
use mesa_schemas::json::parse_lenient;
use mesa_schemas::{DatasetLayout, GalleryRecord, Kind, LlmLayout};
use serde_json::Value;

/// A layout read from a file, in the form it had.
#[derive(Debug, Clone, PartialEq)]
pub enum AnyLayout {
    /// A dataset layout.
    Dataset(DatasetLayout),
    /// An LLM layout (or a gallery record's `scene_layout_json`).
    Llm(LlmLayout),
}

/// Which form a layout document has: a gallery record, a dataset layout or an LLM layout.
pub fn layout_kind_of(value: &Value) -> &'static str {
    if value.get("scene_layout_json").is_some() {
        return "gallery-record";
    }
    if value.get("schema").and_then(Value::as_str) == Some(mesa_schemas::LAYOUT_SCHEMA) {
        return "layout";
    }
    let first = value
        .get("objects")
        .and_then(Value::as_array)
        .and_then(|o| o.first());
    match first {
        Some(o) if o.get("rotation").is_some() || o.get("retrieved_uid").is_some() => "layout",
        Some(o) if o.get("z_rotation").is_some() => "llm-layout",
        _ if value.get("sink_zone").is_some() => "llm-layout",
        _ => "layout",
    }
}

/// Reads a layout file of any form, validating it first and reporting every problem.
pub fn read_any_layout(path: &Path) -> anyhow::Result<AnyLayout> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    parse_any_layout(path, &text)
}

/// Parses the text of a layout file of any form (`path` names it in messages), validating it
/// first and reporting every problem.
pub fn parse_any_layout(path: &Path, text: &str) -> anyhow::Result<AnyLayout> {
    let value =
        parse_lenient(text).with_context(|| format!("{}: not valid JSON", path.display()))?;
    let kind_name = layout_kind_of(&value);
    let kind = Kind::by_name(kind_name).context("layout kinds are registered")?;
    let problems = kind.validate_value(&value);
    if !problems.is_empty() {
        let lines: Vec<String> = problems
            .iter()
            .map(|p| format!("{}: {p}", path.display()))
            .collect();
        bail!(
            "{} is not a valid {kind_name}:\n{}",
            path.display(),
            lines.join("\n")
        );
    }
    Ok(match kind_name {
        "gallery-record" => {
            let record: GalleryRecord = serde_json::from_value(value)?;
            AnyLayout::Llm(
                record
                    .scene_layout_json
                    .resolve()
                    .with_context(|| format!("{}: $.scene_layout_json", path.display()))?,
            )
        }
        "llm-layout" => AnyLayout::Llm(serde_json::from_value(value)?),
        _ => AnyLayout::Dataset(serde_json::from_value(value)?),
    })
}
