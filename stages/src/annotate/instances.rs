//! Instance labels and descriptions (`mesa annotate instances`): the request of one photo
//! instance (its crop and the whole photo), the validation of a reply, and the offline
//! placeholder. The fields mesa writes into `input/instances.json` are recorded under the
//! entry's `mesa_sources`, as for assets.

use std::collections::BTreeMap;

use serde_json::{json, Map, Value};

use crate::tasks::chat::{build_request, CallKind, ChatRequest, View};
use crate::tasks::prompts::{PromptError, PromptTemplate};

use super::{AnnotationsConfig, OFFLINE_SOURCE, SOURCES_KEY};

/// The built-in prompt of an instance (`data/prompts/annotate_instance.txt`).
pub const INSTANCE_PROMPT: &str = include_str!("../../../data/prompts/annotate_instance.txt");
/// The prompt's file name in `[annotations] prompts_dir`.
pub const INSTANCE_PROMPT_FILE: &str = "annotate_instance.txt";
/// The placeholders the instance prompt may use.
pub const INSTANCE_PLACEHOLDERS: [&str; 3] = ["table_type", "label", "description"];
/// The fields of an instance mesa annotates.
pub const INSTANCE_FIELDS: [&str; 2] = ["label", "description"];

/// The instance prompt.
pub fn instance_prompt(source: &str, text: &str) -> Result<PromptTemplate, PromptError> {
    PromptTemplate::parse(source, text, &INSTANCE_PLACEHOLDERS)
}

/// Which of an instance entry's fields to annotate: those missing or empty, and with `force`
/// those mesa wrote; a person's text is never replaced, nor a model's by the placeholder.
/// The support (the table) is never annotated.
pub fn instance_fields_to_annotate(entry: &Value, source: &str, force: bool) -> Vec<&'static str> {
    if entry.get("support").and_then(Value::as_bool) == Some(true) {
        return Vec::new();
    }
    let sources = entry.get(SOURCES_KEY).and_then(Value::as_object);
    INSTANCE_FIELDS
        .iter()
        .copied()
        .filter(|field| {
            let present = entry
                .get(*field)
                .and_then(Value::as_str)
                .is_some_and(|s| !s.trim().is_empty());
            if !present {
                return true;
            }
            match sources.and_then(|s| s.get(*field)).and_then(Value::as_str) {
                None => false,
                Some(old) => force || (old == OFFLINE_SOURCE && source != OFFLINE_SOURCE),
            }
        })
        .collect()
}

/// The request of one instance: the prompt, then the crop and the whole photo.
pub fn instance_request(
    template: &PromptTemplate,
    config: &AnnotationsConfig,
    table_type: &str,
    entry: &Value,
    crop: View,
    photo: View,
    attempt: u32,
) -> Result<ChatRequest, PromptError> {
    let known = |field: &str| {
        entry
            .get(field)
            .and_then(Value::as_str)
            .filter(|s| !s.trim().is_empty())
            .map_or_else(|| "unknown".to_owned(), |s| format!("\"{s}\""))
    };
    let mut values = BTreeMap::new();
    values.insert("table_type", table_type.replace('_', " "));
    values.insert("label", known("label"));
    values.insert("description", known("description"));
    let prompt = template.render(&values)?;
    Ok(build_request(
        CallKind::Description,
        &config.llm,
        &prompt,
        &[crop, photo],
        true,
        attempt,
    ))
}

/// Reads and checks a reply for one instance: a label of one to four words and a description
/// of at least two words, at most 300 characters.
pub fn validate_instance_reply(content: &str) -> Result<Map<String, Value>, Vec<String>> {
    let text = content.trim();
    let text = text
        .strip_prefix("```json")
        .or_else(|| text.strip_prefix("```"))
        .map_or(text, |t| t.trim_end().trim_end_matches("```").trim());
    let value: Value = serde_json::from_str(text)
        .map_err(|e| vec![format!("not valid JSON ({e}); expected one JSON object")])?;
    let Some(object) = value.as_object() else {
        return Err(vec![format!(
            "the reply is {} (expected a JSON object with the keys label, description)",
            mesa_schemas::validate::describe(&value)
        )]);
    };
    let mut reasons = Vec::new();
    let mut fields = Map::new();
    for (field, min_words, max_words, max_chars) in
        [("label", 1, 4, 64), ("description", 2, 60, 300)]
    {
        match object.get(field) {
            None => reasons.push(format!("{field}: missing")),
            Some(Value::String(s)) => {
                let s = s.trim();
                let words = s.split_whitespace().count();
                if words < min_words || words > max_words || s.chars().count() > max_chars {
                    reasons.push(format!(
                        "{field}: \"{s}\" has {words} words, {} characters (expected {min_words} \
                         to {max_words} words, at most {max_chars} characters)",
                        s.chars().count()
                    ));
                } else {
                    let s = if field == "label" {
                        s.to_lowercase()
                    } else {
                        s.to_owned()
                    };
                    fields.insert(field.to_owned(), json!(s));
                }
            }
            Some(other) => reasons.push(format!(
                "{field}: {} (expected a string)",
                mesa_schemas::validate::describe(other)
            )),
        }
    }
    if reasons.is_empty() {
        Ok(fields)
    } else {
        Err(reasons)
    }
}

/// The placeholder of an instance without a model: its label, else `object`; a description
/// of the label and where the mask lies in the photo, marked as a placeholder.
pub fn instance_placeholder(
    entry: &Value,
    mask_box_px: Option<[usize; 4]>,
    photo_size_px: [usize; 2],
) -> Map<String, Value> {
    let label = entry
        .get("label")
        .and_then(Value::as_str)
        .filter(|s| !s.trim().is_empty())
        .unwrap_or("object")
        .trim()
        .to_owned();
    let place = match mask_box_px {
        Some([u0, v0, u1, v1]) => {
            let (cu, cv) = ((u0 + u1) as f64 / 2.0, (v0 + v1) as f64 / 2.0);
            let horizontal = match cu / photo_size_px[0].max(1) as f64 {
                x if x < 1.0 / 3.0 => "left",
                x if x > 2.0 / 3.0 => "right",
                _ => "middle",
            };
            let vertical = match cv / photo_size_px[1].max(1) as f64 {
                y if y < 1.0 / 3.0 => "back",
                y if y > 2.0 / 3.0 => "front",
                _ => "centre",
            };
            format!(
                " at the {vertical} {horizontal} of the photo, {} x {} px",
                u1 - u0 + 1,
                v1 - v0 + 1
            )
        }
        None => String::new(),
    };
    let mut fields = Map::new();
    fields.insert("label".into(), json!(label));
    fields.insert(
        "description".into(),
        json!(format!("{label}{place} (placeholder, no model)")),
    );
    fields
}

/// Writes annotated fields into an instance entry, each recorded under `mesa_sources`.
pub fn merge_instance(
    entry: &mut Value,
    fields: &Map<String, Value>,
    which: &[&str],
    source: &str,
) {
    let Some(object) = entry.as_object_mut() else {
        return;
    };
    let mut sources = object
        .get(SOURCES_KEY)
        .and_then(Value::as_object)
        .cloned()
        .unwrap_or_default();
    for field in which {
        if let Some(value) = fields.get(*field) {
            object.insert((*field).to_owned(), value.clone());
            sources.insert((*field).to_owned(), json!(source));
        }
    }
    if !sources.is_empty() {
        object.insert(SOURCES_KEY.to_owned(), Value::Object(sources));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn instance_fields_keep_a_persons_text() {
        let entry = json!({"id": 1, "label": "mug", "description": ""});
        assert_eq!(
            instance_fields_to_annotate(&entry, "llm:m", false),
            ["description"]
        );
        let table = json!({"id": 9, "label": "", "support": true});
        assert!(instance_fields_to_annotate(&table, "llm:m", true).is_empty());
        let mut e = entry.clone();
        let placeholder = instance_placeholder(&entry, Some([0, 0, 9, 9]), [100, 100]);
        merge_instance(&mut e, &placeholder, &["description"], OFFLINE_SOURCE);
        assert_eq!(e["label"], "mug");
        assert!(e["description"]
            .as_str()
            .expect("text")
            .contains("placeholder"));
        assert!(instance_fields_to_annotate(&e, OFFLINE_SOURCE, false).is_empty());
        assert_eq!(
            instance_fields_to_annotate(&e, "llm:m", false),
            ["description"]
        );
    }

    #[test]
    fn instance_replies_are_checked() {
        let ok = validate_instance_reply(r#"{"label": "Mug", "description": "white mug"}"#)
            .expect("valid");
        assert_eq!(ok["label"], "mug");
        let bad = validate_instance_reply(r#"{"label": 3, "description": "a b c d e f g h i j k l m n o p q r s t u v w x y z a b c d e f g h i j k l m n o p q r s t u v w x y z a b c d e f g h i j"}"#)
            .expect_err("bad");
        assert!(bad[0].starts_with("label: "), "{bad:?}");
        assert!(bad[1].starts_with("description: "), "{bad:?}");
        assert!(validate_instance_reply("nope").expect_err("x")[0].contains("not valid JSON"));
    }
}
