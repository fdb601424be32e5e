//! Task instructions and reasoning texts (SPEC 5.8): per scene, three kinds of model call, as
//! in the paper: a table description from the rendered views, tasks from the scene graph
//! (task info JSON, SPEC 4), and, per task, the reasoning text that leads to the layout.
//!
//! - [`types`]: object types (`Desk Lamp`) from instance names, and matching written types back;
//! - [`prompts`]: the editable prompt templates (`data/prompts/`, our own wording);
//! - [`chat`]: what the library asks of a chat backend ([`chat::Chat`]) and the OpenAI
//!   request bodies it builds; the HTTP client, the reply cache and batches live in the
//!   pipeline crate;
//! - [`validate`] and [`reasoning`]: every reply is checked, rejects carry their reasons;
//! - [`template`]: the built-in deterministic writer (the default backend, offline);
//! - [`scene`]: one scene's calls in order, with attempts and rejects.

pub mod chat;
pub mod prompts;
pub mod reasoning;
pub mod scene;
pub mod template;
pub mod types;
pub mod validate;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

pub use scene::{
    write_scene_tasks, write_scene_tasks_keeping_rejects, FailedScene, SceneInput, SceneTasks,
    TasksError, View,
};

/// Which backend writes the tasks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Backend {
    /// The built-in deterministic writer: no model, no network; every record says
    /// `"generator": "template"`.
    Template,
    /// An OpenAI-compatible chat endpoint (`[tasks.llm]`), live or through offline batches.
    Llm,
}

/// The `[tasks]` section of `mesa.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct TasksConfig {
    /// "template" (the built-in deterministic writer, offline; the default) or "llm" (the
    /// chat endpoint of [tasks.llm]). `--backend` overrides it.
    pub backend: Backend,
    /// Tasks written per scene (the paper: 5).
    pub tasks_per_scene: u32,
    /// The least number of different object types a task involves, where the scene has that
    /// many types (the paper: 3).
    pub min_task_objects: u32,
    /// Attempts per model call: a reply that fails validation is kept in tasks/rejects.jsonl
    /// and the call is sent again with the seed plus the attempt number.
    pub max_attempts: u32,
    /// A folder of edited prompt templates (table_description.txt, tasks.txt, reasoning.txt),
    /// relative to the dataset folder; "" uses the built-in copies of data/prompts/.
    pub prompts_dir: String,
    /// The chat endpoint of the "llm" backend.
    pub llm: LlmConfig,
}

impl Default for TasksConfig {
    fn default() -> Self {
        Self {
            backend: Backend::Template,
            tasks_per_scene: 5,
            min_task_objects: 3,
            max_attempts: 3,
            prompts_dir: String::new(),
            llm: LlmConfig::default(),
        }
    }
}

/// The `[tasks.llm]` section: an OpenAI-compatible chat completions endpoint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct LlmConfig {
    /// The API root; requests go to <base_url>/chat/completions.
    pub base_url: String,
    /// The model name sent with every request (a multimodal model, for the rendered views).
    pub model: String,
    /// The environment variable holding the API key (sent as a Bearer token, never printed,
    /// logged or written); "" sends no key (local servers).
    pub api_key_env: String,
    /// Sampling temperature.
    pub temperature: f64,
    /// Most tokens per reply.
    pub max_tokens: u32,
    /// Seed sent with each request (plus the attempt number), for servers that sample
    /// reproducibly.
    pub seed: u64,
    /// Ask for a JSON object reply (`response_format`) on the tasks call. When a server
    /// rejects the field, the request is sent once more without it and a warning says so.
    pub json_mode: bool,
    /// Send the rendered views (render/front.png, render/perspective.png) with the
    /// description call when they exist.
    pub send_images: bool,
    /// Requests in flight at once, across all worker threads.
    pub max_concurrency: usize,
    /// Retries of one request after a 429, a 5xx, a timeout, a broken connection or an
    /// unreadable response body.
    pub max_retries: u32,
    /// First backoff delay in seconds; it doubles with each retry (with jitter), up to
    /// backoff_max_s. A Retry-After header takes precedence, within the same bound.
    pub backoff_initial_s: f64,
    /// Longest backoff delay in seconds.
    pub backoff_max_s: f64,
    /// Seconds before a request is abandoned as timed out (and retried).
    pub timeout_s: f64,
}

impl Default for LlmConfig {
    fn default() -> Self {
        Self {
            base_url: "https://api.openai.com/v1".to_owned(),
            model: "gpt-4o".to_owned(),
            api_key_env: "OPENAI_API_KEY".to_owned(),
            temperature: 0.7,
            max_tokens: 2048,
            seed: 0,
            json_mode: true,
            send_images: true,
            max_concurrency: 8,
            max_retries: 5,
            backoff_initial_s: 1.0,
            backoff_max_s: 60.0,
            timeout_s: 120.0,
        }
    }
}

impl LlmConfig {
    /// What is wrong with the values, one line each, named under `[section]`; the URL and the
    /// model are only checked when the endpoint is `used`.
    pub fn problems(&self, section: &str, used: bool) -> Vec<String> {
        let mut problems = Vec::new();
        if used {
            if !(self.base_url.starts_with("http://") || self.base_url.starts_with("https://")) {
                problems.push(format!(
                    "[{section}] base_url \"{}\" is not an http(s) URL (expected like \
                     https://api.openai.com/v1)",
                    self.base_url
                ));
            }
            if self.model.trim().is_empty() {
                problems.push(format!("[{section}] model is empty"));
            }
        }
        if self.max_concurrency == 0 {
            problems.push(format!(
                "[{section}] max_concurrency is 0 (expected at least 1)"
            ));
        }
        for (name, value) in [
            ("temperature", self.temperature),
            ("backoff_initial_s", self.backoff_initial_s),
            ("backoff_max_s", self.backoff_max_s),
            ("timeout_s", self.timeout_s),
        ] {
            if !value.is_finite() || value < 0.0 {
                problems.push(format!(
                    "[{section}] {name} is {value} (expected a finite number >= 0)"
                ));
            }
        }
        if self.timeout_s == 0.0 {
            problems.push(format!("[{section}] timeout_s is 0 (expected > 0)"));
        }
        problems
    }
}

impl TasksConfig {
    /// What is wrong with the values, one line each (checked before any work starts).
    pub fn problems(&self) -> Vec<String> {
        let mut problems = Vec::new();
        if self.tasks_per_scene == 0 {
            problems.push("[tasks] tasks_per_scene is 0 (expected at least 1)".to_owned());
        }
        if self.max_attempts == 0 {
            problems.push("[tasks] max_attempts is 0 (expected at least 1)".to_owned());
        }
        problems.extend(self.llm.problems("tasks.llm", self.backend == Backend::Llm));
        problems
    }

    /// The generator name written into every record: `template` or `llm:<model>`.
    pub fn generator(&self) -> String {
        match self.backend {
            Backend::Template => "template".to_owned(),
            Backend::Llm => format!("llm:{}", self.llm.model),
        }
    }
}
