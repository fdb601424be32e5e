//! The prompt templates: editable text files under `data/prompts/` (our own wording), built
//! into the binary, and replaceable per dataset by a folder of edited copies
//! (`[tasks] prompts_dir`).
//!
//! A chat prompt file has comment lines (`#`) at the top, then a `[system]` section and a
//! `[user]` section; `{{name}}` placeholders are filled from the scene. Each prompt declares
//! the placeholders it accepts, and a file using another one is refused when it is loaded, so a
//! typo fails in the first second rather than reaching the model.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The built-in table-description prompt (`data/prompts/table_description.txt`).
pub const TABLE_DESCRIPTION: &str = include_str!("../../../data/prompts/table_description.txt");
/// The built-in tasks prompt (`data/prompts/tasks.txt`).
pub const TASKS: &str = include_str!("../../../data/prompts/tasks.txt");
/// The built-in reasoning prompt (`data/prompts/reasoning.txt`).
pub const REASONING: &str = include_str!("../../../data/prompts/reasoning.txt");
/// The built-in layout-generation prompt, the `instruction` of every SFT and DPO record
/// (`data/prompts/layout_generation.txt`).
pub const LAYOUT_GENERATION: &str = include_str!("../../../data/prompts/layout_generation.txt");

/// The file names of the chat prompts, in call order.
pub const PROMPT_FILES: [&str; 3] = ["table_description.txt", "tasks.txt", "reasoning.txt"];

/// The placeholders each chat prompt accepts.
const PLACEHOLDERS: [(&str, &[&str]); 3] = [
    (
        "table_description.txt",
        &["table_type", "objects", "scene_graph", "views"],
    ),
    (
        "tasks.txt",
        &[
            "table_type",
            "description",
            "objects",
            "scene_graph",
            "task_count",
            "min_task_objects",
            "actions",
        ],
    ),
    (
        "reasoning.txt",
        &[
            "table_type",
            "task_info",
            "objects",
            "scene_graph",
            "task_types",
            "environment_types",
        ],
    ),
];

/// A prompt template that cannot be used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{file}: {problem}")]
pub struct PromptError {
    /// The file (or `built-in <name>`).
    pub file: String,
    /// What is wrong and how to fix it.
    pub problem: String,
}

/// A chat prompt: system and user text with placeholders.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PromptTemplate {
    /// Where it came from, for messages.
    pub source: String,
    /// The system message template ("" for none).
    pub system: String,
    /// The user message template.
    pub user: String,
}

/// A prompt with its placeholders filled.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RenderedPrompt {
    /// The system message ("" for none).
    pub system: String,
    /// The user message.
    pub user: String,
}

impl PromptTemplate {
    /// Parses a prompt file's text; `allowed` are the placeholders it may use.
    pub fn parse(source: &str, text: &str, allowed: &[&str]) -> Result<Self, PromptError> {
        let fail = |problem: String| PromptError {
            file: source.to_owned(),
            problem,
        };
        // Section 0 is the system message, 1 the user message.
        let mut sections: [Option<Vec<&str>>; 2] = [None, None];
        let mut current: Option<usize> = None;
        for (number, line) in text.lines().enumerate() {
            let header = match line.trim_end() {
                "[system]" => Some(0),
                "[user]" => Some(1),
                _ => None,
            };
            match (header, current) {
                (Some(index), _) => {
                    if sections[index].is_some() {
                        return Err(fail(format!(
                            "line {}: section {} appears twice (expected one [system] and one \
                             [user])",
                            number + 1,
                            line.trim()
                        )));
                    }
                    sections[index] = Some(Vec::new());
                    current = Some(index);
                }
                (None, Some(index)) => {
                    if let Some(lines) = sections[index].as_mut() {
                        lines.push(line);
                    }
                }
                (None, None) if line.trim().is_empty() || line.starts_with('#') => {}
                (None, None) => {
                    return Err(fail(format!(
                        "line {}: text before the first section (expected comment lines \
                         starting with '#', then [system] and [user])",
                        number + 1
                    )))
                }
            }
        }
        let [system, user] = sections;
        let join = |lines: Vec<&str>| lines.join("\n").trim().to_owned();
        let template = Self {
            source: source.to_owned(),
            system: join(system.unwrap_or_default()),
            user: join(user.ok_or_else(|| fail("no [user] section".to_owned()))?),
        };
        if template.user.is_empty() {
            return Err(fail("the [user] section is empty".to_owned()));
        }
        for name in placeholders(&template.system).chain(placeholders(&template.user)) {
            if !allowed.contains(&name) {
                return Err(fail(format!(
                    "unknown placeholder {{{{{name}}}}} (expected one of {})",
                    allowed
                        .iter()
                        .map(|a| format!("{{{{{a}}}}}"))
                        .collect::<Vec<_>>()
                        .join(", ")
                )));
            }
        }
        Ok(template)
    }

    /// Fills the placeholders. Every placeholder the template uses must have a value.
    pub fn render(&self, values: &BTreeMap<&str, String>) -> Result<RenderedPrompt, PromptError> {
        Ok(RenderedPrompt {
            system: fill(&self.system, values, &self.source)?,
            user: fill(&self.user, values, &self.source)?,
        })
    }
}

fn placeholders(text: &str) -> impl Iterator<Item = &str> {
    text.split("{{")
        .skip(1)
        .filter_map(|rest| rest.split_once("}}").map(|(name, _)| name.trim()))
}

fn fill(text: &str, values: &BTreeMap<&str, String>, source: &str) -> Result<String, PromptError> {
    let mut out = String::with_capacity(text.len() + 256);
    let mut rest = text;
    while let Some(open) = rest.find("{{") {
        out.push_str(&rest[..open]);
        let after = &rest[open + 2..];
        let Some(close) = after.find("}}") else {
            out.push_str(&rest[open..]);
            return Ok(out);
        };
        let name = after[..close].trim();
        let value = values.get(name).ok_or_else(|| PromptError {
            file: source.to_owned(),
            problem: format!("internal error: no value for {{{{{name}}}}}"),
        })?;
        out.push_str(value);
        rest = &after[close + 2..];
    }
    out.push_str(rest);
    Ok(out)
}

/// The three chat prompts of the tasks stage.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Prompts {
    /// The table description (call 1).
    pub table_description: PromptTemplate,
    /// The tasks (call 2).
    pub tasks: PromptTemplate,
    /// The reasoning text of a task (call 3, once per task).
    pub reasoning: PromptTemplate,
}

impl Prompts {
    /// The built-in prompts.
    pub fn builtin() -> Result<Self, PromptError> {
        Self::from_texts(
            "built-in data/prompts/",
            [TABLE_DESCRIPTION, TASKS, REASONING],
        )
    }

    /// The prompts of a folder holding `table_description.txt`, `tasks.txt` and
    /// `reasoning.txt`.
    pub fn from_dir(dir: &Path) -> Result<Self, PromptError> {
        let mut texts = Vec::new();
        for name in PROMPT_FILES {
            let path = dir.join(name);
            let text = std::fs::read_to_string(&path).map_err(|e| PromptError {
                file: path.display().to_string(),
                problem: format!(
                    "cannot read: {e} (a prompts_dir holds table_description.txt, tasks.txt and \
                     reasoning.txt; copy them from data/prompts/)"
                ),
            })?;
            texts.push(text);
        }
        let [a, b, c]: [String; 3] = texts.try_into().map_err(|_| PromptError {
            file: dir.display().to_string(),
            problem: "internal error: three prompt files expected".to_owned(),
        })?;
        Self::from_texts(&format!("{}/", dir.display()), [&a, &b, &c])
    }

    fn from_texts(prefix: &str, texts: [&str; 3]) -> Result<Self, PromptError> {
        let parse = |i: usize| {
            let (name, allowed) = PLACEHOLDERS[i];
            PromptTemplate::parse(&format!("{prefix}{name}"), texts[i], allowed)
        };
        Ok(Self {
            table_description: parse(0)?,
            tasks: parse(1)?,
            reasoning: parse(2)?,
        })
    }

    /// The files a prompts folder contributes (inputs of the stage), relative to the dataset.
    pub fn files_in(dir: &str) -> Vec<PathBuf> {
        PROMPT_FILES
            .iter()
            .map(|name| Path::new(dir).join(name))
            .collect()
    }
}

/// The layout-generation instruction: the text of a prompt file without its final line break.
pub fn layout_instruction(text: &str) -> Result<String, PromptError> {
    let instruction = text.trim_end_matches(['\n', '\r']).to_owned();
    if instruction.trim().is_empty() {
        return Err(PromptError {
            file: "layout_generation.txt".to_owned(),
            problem: "the layout-generation prompt is empty".to_owned(),
        });
    }
    Ok(instruction)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_builtin_prompts_parse() {
        let prompts = Prompts::builtin().expect("built-in prompts parse");
        assert!(prompts.tasks.system.contains("JSON"));
        assert!(prompts.reasoning.user.contains("Core Task Objects:"));
        assert!(prompts.reasoning.user.contains("Environment Objects:"));
        let instruction = layout_instruction(LAYOUT_GENERATION).expect("instruction");
        assert!(instruction.ends_with("The task description:"));
        for needle in [
            "centimetres",
            "front_left",
            "left of",
            "Therefore, the scene layout is:",
            "**Final Answer**",
        ] {
            assert!(instruction.contains(needle), "{needle}");
        }
    }

    #[test]
    fn placeholders_are_checked_and_filled() {
        let template = PromptTemplate::parse(
            "t.txt",
            "# comment\n[system]\nBe brief.\n[user]\nA {{table_type}} with {{objects}}.\n",
            &["table_type", "objects"],
        )
        .expect("parses");
        let values = BTreeMap::from([
            ("table_type", "desk".to_owned()),
            ("objects", "Mug(1)".to_owned()),
        ]);
        let rendered = template.render(&values).expect("renders");
        assert_eq!(rendered.system, "Be brief.");
        assert_eq!(rendered.user, "A desk with Mug(1).");
        let err = PromptTemplate::parse("t.txt", "[user]\n{{tabel_type}}\n", &["table_type"])
            .expect_err("typo");
        assert!(
            err.to_string()
                .contains("unknown placeholder {{tabel_type}}"),
            "{err}"
        );
        let err = PromptTemplate::parse("t.txt", "hello\n[user]\nx\n", &[]).expect_err("stray");
        assert!(err.to_string().contains("line 1"), "{err}");
        assert!(PromptTemplate::parse("t.txt", "[system]\nx\n", &[]).is_err());
    }
}
