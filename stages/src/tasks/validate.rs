//! Validation of the replies of the description and tasks calls (the reasoning text is
//! checked by [`crate::tasks::reasoning::check_reasoning`]). Every check gives reasons a
//! person can act on; a reply that fails is kept in the rejects file with them.

use mesa_schemas::llm::{check_action, PRIMITIVE_ACTIONS};
use serde_json::Value;

use crate::tasks::chat::ChatReply;
use crate::tasks::types::{looks_like_instance, SceneTypes};

/// Longest table description accepted, in characters.
pub const MAX_DESCRIPTION_CHARS: usize = 1200;

/// A task as the tasks call writes it (the task info without the zones and environment, which
/// come from the layout and the description).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TaskDraft {
    /// The task instruction.
    pub task: String,
    /// Its steps.
    pub goal: Vec<String>,
    /// Its primitive actions.
    pub action_sequence: Vec<String>,
    /// The object types it involves.
    pub objects_cluster: Vec<String>,
}

impl TaskDraft {
    /// The draft as the JSON object the tasks call replies with (for rejects and the template
    /// backend's replies).
    pub fn to_value(&self) -> Value {
        serde_json::json!({
            "Task": self.task,
            "Goal": self.goal,
            "Action Sequence": self.action_sequence,
            "Objects cluster": self.objects_cluster,
        })
    }
}

/// Reasons common to every reply: cut at max_tokens, or empty.
fn reply_problems(reply: &ChatReply) -> Vec<String> {
    let mut problems = Vec::new();
    if reply.finish_reason.as_deref() == Some("length") {
        problems.push("the reply was cut at max_tokens (finish_reason \"length\")".to_owned());
    }
    if reply.content.trim().is_empty() {
        problems.push("the reply is empty".to_owned());
    }
    problems
}

/// Instance-like words (`mug_0`) in a text.
fn instance_words(text: &str) -> Vec<&str> {
    text.split(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
        .filter(|w| looks_like_instance(w))
        .collect()
}

/// Everything wrong with a model reply, each reason a sentence; shown joined by `; ` (how the
/// rejects record them).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{}", .0.join("; "))]
pub struct ReplyProblems(pub Vec<String>);

impl From<ReplyProblems> for Vec<String> {
    fn from(problems: ReplyProblems) -> Self {
        problems.0
    }
}

/// Checks a table description; the description (trimmed) when it passes.
pub fn check_description(reply: &ChatReply) -> Result<String, ReplyProblems> {
    description_problems(reply).map_err(ReplyProblems)
}

fn description_problems(reply: &ChatReply) -> Result<String, Vec<String>> {
    let mut problems = reply_problems(reply);
    let text = reply.content.trim();
    if text.starts_with('{') || text.starts_with('[') || text.starts_with("```") {
        problems.push("the description is JSON or code, not prose".to_owned());
    }
    if text.split_whitespace().count() < 4 {
        problems.push(format!(
            "the description \"{text}\" is shorter than 4 words (expected a sentence or two)"
        ));
    }
    let chars = text.chars().count();
    if chars > MAX_DESCRIPTION_CHARS {
        problems.push(format!(
            "the description has {chars} characters (expected at most {MAX_DESCRIPTION_CHARS})"
        ));
    }
    let ids = instance_words(text);
    if !ids.is_empty() {
        problems.push(format!(
            "the description names instances ({}; expected object types)",
            ids.join(", ")
        ));
    }
    if problems.is_empty() {
        Ok(text.to_owned())
    } else {
        Err(problems)
    }
}

/// The verdict on a tasks reply whose JSON could be read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TasksVerdict {
    /// The tasks that passed, in reply order.
    pub accepted: Vec<TaskDraft>,
    /// The tasks that failed: their index in the reply, their JSON, and why.
    pub rejected: Vec<(usize, String, Vec<String>)>,
}

/// Reads a tasks reply (`{"tasks": [...]}`, or a bare list; a code fence is tolerated) and
/// checks each task. Errors are problems of the whole reply.
pub fn read_tasks_reply(
    reply: &ChatReply,
    scene: &SceneTypes,
    min_task_objects: usize,
) -> Result<TasksVerdict, ReplyProblems> {
    tasks_reply(reply, scene, min_task_objects).map_err(ReplyProblems)
}

fn tasks_reply(
    reply: &ChatReply,
    scene: &SceneTypes,
    min_task_objects: usize,
) -> Result<TasksVerdict, Vec<String>> {
    let problems = reply_problems(reply);
    if !problems.is_empty() {
        return Err(problems);
    }
    let text = strip_fence(reply.content.trim());
    let value = mesa_schemas::json::parse_unique(text)
        .map_err(|e| vec![format!("the reply is not valid JSON: {e}")])?;
    let items = match &value {
        Value::Array(items) => items,
        Value::Object(map) => match map.get("tasks") {
            Some(Value::Array(items)) => items,
            _ => {
                return Err(vec![
                    "the reply has no \"tasks\" list (expected {\"tasks\": [...]})".to_owned(),
                ])
            }
        },
        _ => return Err(vec!["the reply is not a JSON object or list".to_owned()]),
    };
    if items.is_empty() {
        return Err(vec!["the \"tasks\" list is empty".to_owned()]);
    }
    let mut verdict = TasksVerdict {
        accepted: Vec::new(),
        rejected: Vec::new(),
    };
    for (i, item) in items.iter().enumerate() {
        let json = serde_json::to_string(item).unwrap_or_default();
        match draft_of(item) {
            Ok(draft) => {
                let problems = check_task(&draft, scene, min_task_objects);
                if problems.is_empty() {
                    verdict.accepted.push(draft);
                } else {
                    verdict.rejected.push((i, json, problems));
                }
            }
            Err(problems) => verdict.rejected.push((i, json, problems)),
        }
    }
    Ok(verdict)
}

/// The text inside a ```` ```json ```` fence, or the text itself.
pub fn strip_fence(text: &str) -> &str {
    let Some(inner) = text
        .strip_prefix("```json")
        .or_else(|| text.strip_prefix("```"))
    else {
        return text;
    };
    inner.trim().strip_suffix("```").unwrap_or(inner).trim()
}

fn draft_of(item: &Value) -> Result<TaskDraft, Vec<String>> {
    let Some(object) = item.as_object() else {
        return Err(vec!["the task is not a JSON object".to_owned()]);
    };
    let mut problems = Vec::new();
    let text = |key: &str, problems: &mut Vec<String>| match object.get(key) {
        Some(Value::String(s)) if !s.trim().is_empty() => s.trim().to_owned(),
        Some(Value::String(_)) => {
            problems.push(format!("\"{key}\" is empty"));
            String::new()
        }
        Some(_) => {
            problems.push(format!("\"{key}\" is not a string"));
            String::new()
        }
        None => {
            problems.push(format!("\"{key}\" is missing"));
            String::new()
        }
    };
    let list = |key: &str, problems: &mut Vec<String>| -> Vec<String> {
        match object.get(key) {
            Some(Value::Array(items)) if !items.is_empty() => {
                let mut out = Vec::new();
                for (i, v) in items.iter().enumerate() {
                    match v.as_str().map(str::trim) {
                        Some(s) if !s.is_empty() => out.push(s.to_owned()),
                        _ => problems.push(format!("\"{key}\"[{i}] is not a non-empty string")),
                    }
                }
                out
            }
            Some(Value::Array(_)) => {
                problems.push(format!("\"{key}\" is empty"));
                Vec::new()
            }
            Some(_) => {
                problems.push(format!("\"{key}\" is not a list of strings"));
                Vec::new()
            }
            None => {
                problems.push(format!("\"{key}\" is missing"));
                Vec::new()
            }
        }
    };
    let draft = TaskDraft {
        task: text("Task", &mut problems),
        goal: list("Goal", &mut problems),
        action_sequence: list("Action Sequence", &mut problems),
        objects_cluster: list("Objects cluster", &mut problems),
    };
    for key in object.keys() {
        if !["Task", "Goal", "Action Sequence", "Objects cluster"].contains(&key.as_str()) {
            problems.push(format!(
                "unexpected key \"{key}\" (expected Task, Goal, Action Sequence, Objects cluster)"
            ));
        }
    }
    if problems.is_empty() {
        Ok(draft)
    } else {
        Err(problems)
    }
}

/// Splits `Name(a, b)` into the name and its trimmed arguments.
pub fn split_action(action: &str) -> Option<(&str, Vec<&str>)> {
    let (name, rest) = action.trim().split_once('(')?;
    let args = rest.strip_suffix(')')?;
    Some((
        name.trim(),
        args.split(',')
            .map(str::trim)
            .filter(|a| !a.is_empty())
            .collect(),
    ))
}

/// Checks one task against the scene: primitive actions whose object arguments are types of
/// the scene, an objects cluster of at least `min(min_task_objects, scene types)` different
/// types of the scene, and object types, never instance names, everywhere.
pub fn check_task(draft: &TaskDraft, scene: &SceneTypes, min_task_objects: usize) -> Vec<String> {
    let mut problems = Vec::new();
    for (i, action) in draft.action_sequence.iter().enumerate() {
        if let Err(problem) = check_action(action) {
            problems.push(format!("\"Action Sequence\"[{i}]: {problem}"));
        }
    }
    let type_names = || SceneTypes::list(&scene.types);
    for (i, action) in draft.action_sequence.iter().enumerate() {
        let Some((name, args)) = split_action(action) else {
            continue; // reported above
        };
        let object_arg = match name {
            "PlaceAt" => None,
            _ if PRIMITIVE_ACTIONS.iter().any(|(n, _)| *n == name) => args.first().copied(),
            _ => None,
        };
        if let Some(arg) = object_arg {
            if looks_like_instance(arg) {
                problems.push(format!(
                    "\"Action Sequence\"[{i}] \"{action}\" names the instance {arg} (expected an \
                     object type)"
                ));
            } else if scene.matching(arg).is_empty() {
                problems.push(format!(
                    "\"Action Sequence\"[{i}] \"{action}\": \"{arg}\" is no object type of the \
                     scene (its types: {})",
                    type_names()
                ));
            }
        }
    }
    let mut matched: Vec<&str> = Vec::new();
    for written in &draft.objects_cluster {
        if looks_like_instance(written) {
            problems.push(format!(
                "\"Objects cluster\" names the instance {written} (expected an object type)"
            ));
            continue;
        }
        let found = scene.matching(written);
        if found.is_empty() {
            problems.push(format!(
                "\"Objects cluster\": \"{written}\" is no object type of the scene (its types: {})",
                type_names()
            ));
        }
        for t in found {
            if !matched.contains(&t.key.as_str()) {
                matched.push(&t.key);
            }
        }
    }
    let needed = min_task_objects.min(scene.types.len());
    if matched.len() < needed {
        problems.push(format!(
            "the task involves {} object types of the scene (expected at least {needed})",
            matched.len()
        ));
    }
    let mut named = Vec::new();
    for text in std::iter::once(&draft.task).chain(&draft.goal) {
        named.extend(instance_words(text));
    }
    if !named.is_empty() {
        problems.push(format!(
            "the task names instances ({}; expected object types)",
            named.join(", ")
        ));
    }
    problems
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reply(text: &str) -> ChatReply {
        ChatReply {
            content: text.to_owned(),
            finish_reason: Some("stop".to_owned()),
            redacted: false,
        }
    }

    fn scene() -> SceneTypes {
        SceneTypes::of_instances(["tray_0", "mug_0", "mug_1", "kettle_0", "desk_lamp_0"])
    }

    #[test]
    fn good_tasks_pass_and_bad_ones_say_why() {
        let text = r#"```json
        {"tasks": [
          {"Task": "Serve tea", "Goal": ["Pick the kettle", "Place it on the tray"],
           "Action Sequence": ["Pick(Kettle)", "PlaceOn(Tray)", "Pick(Mugs)", "PlaceAt(next to the kettle)"],
           "Objects cluster": ["Kettle", "Tray", "Mugs"]},
          {"Task": "Move mug_0", "Goal": ["Pick mug_0"], "Action Sequence": ["Grab(mug_0)"],
           "Objects cluster": ["mug_0"]},
          {"Task": "Light", "Goal": ["Press the switch"], "Action Sequence": ["Press(Switch)"],
           "Objects cluster": ["Desk Lamp", "Sofa"]}
        ]}
        ```"#;
        let verdict = read_tasks_reply(&reply(text), &scene(), 3).expect("readable");
        assert_eq!(verdict.accepted.len(), 1);
        assert_eq!(verdict.accepted[0].objects_cluster.len(), 3);
        let second = &verdict.rejected[0].2;
        assert!(
            second.iter().any(|p| p.contains("unknown action \"Grab\"")),
            "{second:?}"
        );
        assert!(
            second
                .iter()
                .any(|p| p.contains("names the instance mug_0")),
            "{second:?}"
        );
        let third = &verdict.rejected[1].2;
        assert!(
            third
                .iter()
                .any(|p| p.contains("\"Sofa\" is no object type")),
            "{third:?}"
        );
        assert!(
            third
                .iter()
                .any(|p| p.contains("\"Switch\" is no object type")),
            "{third:?}"
        );
        assert!(
            third.iter().any(|p| p.contains("expected at least 3")),
            "{third:?}"
        );
    }

    #[test]
    fn unreadable_replies_are_whole_rejects() {
        assert!(read_tasks_reply(&reply("{not json"), &scene(), 3).is_err());
        assert!(read_tasks_reply(&reply("{\"jobs\": []}"), &scene(), 3).is_err());
        let cut = ChatReply {
            content: "{\"tasks\": [".into(),
            finish_reason: Some("length".into()),
            redacted: false,
        };
        let err = read_tasks_reply(&cut, &scene(), 3).expect_err("cut");
        assert!(err.0[0].contains("max_tokens"));
    }

    #[test]
    fn descriptions_are_prose_about_types() {
        assert!(check_description(&reply("A desk with a lamp and two mugs.")).is_ok());
        assert!(check_description(&reply("mug_0 stands left of tray_0 here")).is_err());
        assert!(check_description(&reply("{\"a\": 1}")).is_err());
        assert!(check_description(&reply("Desk.")).is_err());
    }
}
