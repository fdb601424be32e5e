//! One scene's tasks: the calls in order (description, tasks, one reasoning per task), each
//! validated, retried with a new seed while attempts remain, rejects kept with their reasons.

use std::collections::BTreeMap;

use mesa_schemas::artifacts::{
    GraphArtifact, TaskRecord, TaskReject, TASKS_SCHEMA, TASK_REJECT_SCHEMA,
};
use mesa_schemas::llm::PRIMITIVE_ACTIONS;
use mesa_schemas::{LlmLayout, TaskInfo};

use crate::tasks::chat::{build_request, CallKind, Chat, ChatError, ChatReply, ChatRequest};
use crate::tasks::prompts::{PromptError, PromptTemplate, Prompts, RenderedPrompt};
use crate::tasks::reasoning::check_reasoning;
use crate::tasks::template::{table_phrase, TemplateScene};
use crate::tasks::types::{ObjectType, SceneTypes};
use crate::tasks::validate::{check_description, check_task, read_tasks_reply, TaskDraft};
use crate::tasks::{Backend, TasksConfig};

// Defined beside the chat requests that carry the images, so chat needs nothing from here.
pub use crate::tasks::chat::View;

/// Everything the tasks of a scene are written from.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneInput {
    /// The scene id.
    pub scene_id: String,
    /// The table type.
    pub table_type: String,
    /// The layout in the LLM form, objects in the scene graph's order.
    pub layout: LlmLayout,
    /// The layout file, relative to the scene folder.
    pub layout_file: String,
    /// SHA-256 of the layout file.
    pub layout_sha256: String,
    /// The scene graph's triplet lines (`graph/graph.txt`).
    pub graph_lines: Vec<String>,
    /// The scene graph with its node flags (`graph/graph.json`).
    pub graph: GraphArtifact,
    /// The rendered views found (front, perspective), possibly none.
    pub views: Vec<View>,
}

/// What the tasks stage writes for a scene.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SceneTasks {
    /// `tasks/tasks.jsonl`, one record per task.
    pub records: Vec<TaskRecord>,
    /// `tasks/rejects.jsonl`: replies that failed validation.
    pub rejects: Vec<TaskReject>,
    /// Things the user should know (fewer tasks than asked, dropped tasks).
    pub warnings: Vec<String>,
}

/// Why a scene has no tasks.
#[derive(Debug, thiserror::Error)]
pub enum TasksError {
    /// Offline batch mode: replies are still missing; the requests belong to the next batch
    /// (the reasoning calls of all tasks at once, the other calls one by one).
    #[error("waiting for {} replies (offline batch mode)", .0.len())]
    Pending(Vec<ChatRequest>),
    /// The chat endpoint failed for good.
    #[error("the {call} call failed: {message}")]
    Chat {
        /// The call.
        call: &'static str,
        /// Why (the key is never in it).
        message: String,
    },
    /// No reply of a call passed validation.
    #[error(
        "no valid reply to the {call} call in {attempts} attempts (the rejects, with reasons, \
         are in tasks/rejects.jsonl); last: {last}"
    )]
    NoValidReply {
        /// The call.
        call: &'static str,
        /// Attempts made.
        attempts: u32,
        /// The reasons of the last reject.
        last: String,
    },
    /// A prompt template could not be filled.
    #[error(transparent)]
    Prompt(#[from] PromptError),
    /// The template backend wrote something its own validation refuses: a bug in mesa.
    #[error("internal error: the template backend wrote an invalid {call}: {reasons} (a bug in mesa: please report it with this scene)")]
    Template {
        /// The call.
        call: &'static str,
        /// Why.
        reasons: String,
    },
    /// The scene has nothing to write tasks about.
    #[error("the layout has no object")]
    EmptyLayout,
}

/// The primitive actions as the tasks prompt lists them.
fn actions_text() -> String {
    PRIMITIVE_ACTIONS
        .iter()
        .map(|(name, arity)| match (*name, *arity) {
            ("PlaceAt", _) => "PlaceAt(place)".to_owned(),
            ("Push", _) => "Push(type, direction, distance)".to_owned(),
            (name, _) => format!("{name}(type)"),
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// The task info JSON as the SFT input and the reasoning prompt show it: 2-space indent,
/// UTF-8 unescaped.
pub fn task_info_json(info: &TaskInfo) -> String {
    serde_json::to_string_pretty(info).unwrap_or_default()
}

/// The task info of a draft: the description as `Environment`, the zones from the layout.
pub fn task_info_of(draft: &TaskDraft, description: &str, layout: &LlmLayout) -> TaskInfo {
    TaskInfo {
        environment: description.to_owned(),
        zone_cm: layout.zone_cm,
        sink_zone_cm: layout.sink_zone_cm,
        task: draft.task.clone(),
        goal: draft.goal.clone(),
        action_sequence: Some(draft.action_sequence.clone()),
        objects_cluster: draft.objects_cluster.clone(),
    }
}

/// The scene types a task involves (matched from its objects cluster), in scene order.
pub fn core_types<'a>(types: &'a SceneTypes, objects_cluster: &[String]) -> Vec<&'a ObjectType> {
    types
        .types
        .iter()
        .filter(|t| {
            objects_cluster
                .iter()
                .any(|w| types.matching(w).iter().any(|m| m.key == t.key))
        })
        .collect()
}

struct Writer<'a> {
    input: &'a SceneInput,
    config: &'a TasksConfig,
    chat: &'a dyn Chat,
    types: SceneTypes,
    generator: String,
    rejects: Vec<TaskReject>,
    /// Whether the reply being judged had the API key redacted from it.
    reply_redacted: bool,
    /// Replies that had the API key redacted from them.
    redacted_replies: usize,
}

impl Writer<'_> {
    fn base_values(&self) -> BTreeMap<&'static str, String> {
        BTreeMap::from([
            ("table_type", table_phrase(&self.input.table_type)),
            ("objects", SceneTypes::list(&self.types.types)),
            ("scene_graph", self.input.graph_lines.join("\n")),
        ])
    }

    fn render(
        &self,
        template: &PromptTemplate,
        extra: impl IntoIterator<Item = (&'static str, String)>,
    ) -> Result<RenderedPrompt, PromptError> {
        let mut values = self.base_values();
        values.extend(extra);
        template.render(&values)
    }

    fn reject(
        &mut self,
        call: CallKind,
        task_index: Option<u32>,
        attempt: u32,
        reasons: Vec<String>,
        reply: String,
    ) {
        self.rejects.push(TaskReject {
            schema: TASK_REJECT_SCHEMA.to_owned(),
            scene_id: self.input.scene_id.clone(),
            call: call.name().to_owned(),
            task_index,
            attempt,
            generator: self.generator.clone(),
            reasons,
            reply,
            redacted: self.reply_redacted,
        });
    }

    fn ask(&self, request: &ChatRequest) -> Result<ChatReply, TasksError> {
        self.chat.complete(request).map_err(|e| match e {
            ChatError::Pending(request) => TasksError::Pending(vec![*request]),
            ChatError::Failed(message) => TasksError::Chat {
                call: request.call.name(),
                message,
            },
        })
    }

    /// Sends a call until a reply passes `accept`, keeping rejects; `accept` returns the value
    /// or the reasons (and whether to keep the reply as a reject with a task index).
    fn call<T>(
        &mut self,
        call: CallKind,
        prompt: &RenderedPrompt,
        images: &[View],
        json: bool,
        task_index: Option<u32>,
        mut accept: impl FnMut(&mut Self, &ChatReply, u32) -> Result<T, Vec<String>>,
    ) -> Result<T, TasksError> {
        let mut last = String::new();
        for attempt in 0..self.config.max_attempts {
            let request = build_request(call, &self.config.llm, prompt, images, json, attempt);
            let reply = self.ask(&request)?;
            self.reply_redacted = reply.redacted;
            self.redacted_replies += usize::from(reply.redacted);
            match accept(self, &reply, attempt) {
                Ok(value) => return Ok(value),
                Err(reasons) => {
                    last = reasons.join("; ");
                    self.reject(call, task_index, attempt, reasons, reply.content);
                }
            }
        }
        Err(TasksError::NoValidReply {
            call: call.name(),
            attempts: self.config.max_attempts,
            last,
        })
    }
}

/// A scene whose tasks failed, with the replies its calls rejected before the failure: the
/// caller writes them (`tasks/rejects.jsonl`) before it reports the error that names them.
#[derive(Debug)]
pub struct FailedScene {
    /// Why the scene has no tasks.
    pub error: TasksError,
    /// The rejected replies, with their reasons (empty for the template backend).
    pub rejects: Vec<TaskReject>,
}

impl From<TasksError> for FailedScene {
    fn from(error: TasksError) -> Self {
        Self {
            error,
            rejects: Vec::new(),
        }
    }
}

/// Writes the tasks of one scene with the configured backend. `chat` serves the `llm`
/// backend (the template backend asks nothing of it); `seed` is `[run] seed`. On failure the
/// rejects are dropped: [`write_scene_tasks_keeping_rejects`] returns them.
pub fn write_scene_tasks(
    input: &SceneInput,
    config: &TasksConfig,
    prompts: &Prompts,
    chat: &dyn Chat,
    seed: u64,
) -> Result<SceneTasks, TasksError> {
    write_scene_tasks_keeping_rejects(input, config, prompts, chat, seed).map_err(|f| f.error)
}

/// [`write_scene_tasks`], whose failure keeps the replies rejected before it.
pub fn write_scene_tasks_keeping_rejects(
    input: &SceneInput,
    config: &TasksConfig,
    prompts: &Prompts,
    chat: &dyn Chat,
    seed: u64,
) -> Result<SceneTasks, FailedScene> {
    if input.layout.objects.is_empty() {
        return Err(TasksError::EmptyLayout.into());
    }
    let types = SceneTypes::of_layout(&input.layout);
    let count = config.tasks_per_scene as usize;
    let min_objects = config.min_task_objects as usize;
    let generator = config.generator();
    let mut warnings = Vec::new();
    let record = |index: usize,
                  description: &str,
                  views: &[String],
                  draft: &TaskDraft,
                  reasoning: String| TaskRecord {
        schema: TASKS_SCHEMA.to_owned(),
        scene_id: input.scene_id.clone(),
        task_index: index as u32,
        generator: generator.clone(),
        layout: input.layout_file.clone(),
        layout_sha256: input.layout_sha256.clone(),
        views: views.to_vec(),
        table_description: description.to_owned(),
        task_info: task_info_of(draft, description, &input.layout),
        reasoning,
    };
    if config.backend == Backend::Template {
        let template = TemplateScene {
            scene_id: &input.scene_id,
            table_type: &input.table_type,
            types: &types,
            graph: &input.graph,
        };
        let description = template.description();
        let check = check_description(&ChatReply {
            content: description.clone(),
            finish_reason: None,
            redacted: false,
        });
        let description = check.map_err(|reasons| TasksError::Template {
            call: "description",
            reasons: reasons.to_string(),
        })?;
        let drafts = template.tasks(count, min_objects, seed);
        if drafts.len() < count {
            warnings.push(format!(
                "the template found {} different tasks for this scene ({count} asked)",
                drafts.len()
            ));
        }
        let mut records = Vec::new();
        for (index, draft) in drafts.iter().enumerate() {
            let problems = check_task(draft, &types, min_objects);
            if !problems.is_empty() {
                return Err(TasksError::Template {
                    call: "task",
                    reasons: problems.join("; "),
                }
                .into());
            }
            let core: Vec<String> = core_types(&types, &draft.objects_cluster)
                .iter()
                .map(|t| t.key.clone())
                .collect();
            let reasoning = template.reasoning(&draft.task, &core);
            let problems = check_reasoning(&reasoning, &types, &draft.objects_cluster);
            if !problems.is_empty() {
                return Err(TasksError::Template {
                    call: "reasoning",
                    reasons: problems.join("; "),
                }
                .into());
            }
            records.push(record(index, &description, &[], draft, reasoning));
        }
        if records.is_empty() {
            return Err(TasksError::Template {
                call: "tasks",
                reasons: "no task could be built from this scene".to_owned(),
            }
            .into());
        }
        return Ok(SceneTasks {
            records,
            rejects: Vec::new(),
            warnings,
        });
    }

    let mut writer = Writer {
        input,
        config,
        chat,
        types,
        generator: generator.clone(),
        rejects: Vec::new(),
        reply_redacted: false,
        redacted_replies: 0,
    };
    // The calls, in a closure so that their rejects survive a failure (the caller writes them
    // before the error that names them).
    let result = (|| -> Result<SceneTasks, TasksError> {
        // Call 1: the table description, from the views when there are any.
        let images: Vec<View> = if config.llm.send_images {
            input.views.clone()
        } else {
            Vec::new()
        };
        let views_text = if images.is_empty() {
            "No rendered view of this table is available: describe it from the object list and the \
             scene graph below."
                .to_owned()
        } else {
            let names: Vec<&str> = images.iter().map(|v| v.name.as_str()).collect();
            format!(
                "Attached are {} rendered view{} of the table ({}).",
                images.len(),
                if images.len() == 1 { "" } else { "s" },
                names.join(", ")
            )
        };
        let view_files: Vec<String> = images.iter().map(|v| v.file.clone()).collect();
        let prompt = writer.render(&prompts.table_description, [("views", views_text)])?;
        let description = writer.call(
            CallKind::Description,
            &prompt,
            &images,
            false,
            None,
            |_, reply, _| check_description(reply).map_err(Vec::from),
        )?;

        // Call 2: the tasks.
        let prompt = writer.render(
            &prompts.tasks,
            [
                ("description", description.clone()),
                ("task_count", count.to_string()),
                ("min_task_objects", min_objects.to_string()),
                ("actions", actions_text()),
            ],
        )?;
        let types = writer.types.clone();
        let drafts = writer.call(
            CallKind::Tasks,
            &prompt,
            &[],
            true,
            None,
            |w, reply, attempt| {
                let verdict = read_tasks_reply(reply, &types, min_objects)?;
                for (i, json, reasons) in verdict.rejected {
                    w.reject(CallKind::Tasks, Some(i as u32), attempt, reasons, json);
                }
                if verdict.accepted.is_empty() {
                    return Err(vec![
                        "no task of the reply passed validation (see the rejects of single tasks)"
                            .to_owned(),
                    ]);
                }
                Ok(verdict.accepted)
            },
        )?;
        let mut drafts = drafts;
        if drafts.len() > count {
            warnings.push(format!(
                "the model wrote {} valid tasks; the first {count} are kept",
                drafts.len()
            ));
            drafts.truncate(count);
        } else if drafts.len() < count {
            warnings.push(format!(
                "the model wrote {} valid tasks ({count} asked)",
                drafts.len()
            ));
        }

        // Call 3, per task: the reasoning text. The tasks do not depend on each other: in batch
        // mode every missing reply of this round is collected before the scene waits.
        let mut records = Vec::new();
        let mut pending = Vec::new();
        for draft in &drafts {
            let info = task_info_of(draft, &description, &input.layout);
            let core = core_types(&types, &draft.objects_cluster);
            let environment: Vec<&ObjectType> = types
                .types
                .iter()
                .filter(|t| !core.iter().any(|c| c.key == t.key))
                .collect();
            let prompt = writer.render(
                &prompts.reasoning,
                [
                    ("task_info", task_info_json(&info)),
                    ("task_types", SceneTypes::list(core.iter().copied())),
                    (
                        "environment_types",
                        SceneTypes::list(environment.iter().copied()),
                    ),
                ],
            )?;
            let index = (records.len() + pending.len()) as u32;
            let result = writer.call(
                CallKind::Reasoning,
                &prompt,
                &[],
                false,
                Some(index),
                |_, reply, _| {
                    let mut problems = Vec::new();
                    if reply.finish_reason.as_deref() == Some("length") {
                        problems.push(
                            "the reply was cut at max_tokens (finish_reason \"length\")".to_owned(),
                        );
                    }
                    problems.extend(check_reasoning(
                        &reply.content,
                        &types,
                        &draft.objects_cluster,
                    ));
                    if problems.is_empty() {
                        Ok(reply.content.trim().to_owned())
                    } else {
                        Err(problems)
                    }
                },
            );
            match result {
                Ok(reasoning) => records.push(record(
                    records.len(),
                    &description,
                    &view_files,
                    draft,
                    reasoning,
                )),
                Err(TasksError::Pending(mut requests)) => pending.append(&mut requests),
                Err(TasksError::NoValidReply { attempts, .. }) => warnings.push(format!(
                    "task \"{}\" dropped: no reasoning reply passed validation in {attempts} attempts \
                     (see tasks/rejects.jsonl)",
                    draft.task
                )),
                Err(other) => return Err(other),
            }
        }
        if !pending.is_empty() {
            return Err(TasksError::Pending(pending));
        }
        if records.is_empty() {
            return Err(TasksError::NoValidReply {
                call: "reasoning",
                attempts: config.max_attempts,
                last: "every task lost its reasoning text".to_owned(),
            });
        }
        if writer.redacted_replies > 0 {
            warnings.push(format!(
                "{} model replies held the API key: it was replaced by <redacted> before anything \
                 was written (their cache entries and rejects say \"redacted\": true)",
                writer.redacted_replies
            ));
        }
        Ok(SceneTasks {
            records,
            rejects: std::mem::take(&mut writer.rejects),
            warnings,
        })
    })();
    result.map_err(|error| FailedScene {
        error,
        rejects: writer.rejects,
    })
}

/// A [`Chat`] that answers nothing: for the template backend, which never calls one.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoChat;

impl Chat for NoChat {
    fn complete(&self, request: &ChatRequest) -> Result<ChatReply, ChatError> {
        Err(ChatError::Failed(format!(
            "internal error: the {} call reached a backend that has no chat endpoint",
            request.call.name()
        )))
    }
}
