//! `mesa tasks`: per scene, the table description, the tasks and their reasoning texts
//! (`tasks/tasks.jsonl`, rejected replies in `tasks/rejects.jsonl`), over
//! [`mesa_stages::tasks`], with the template backend or a chat endpoint (live, or offline
//! batches through the reply cache).

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};

use anyhow::{anyhow, bail, Context as _};
use mesa_schemas::json::to_sorted_line;
use mesa_stages::tasks::chat::{Chat, ChatRequest};
use mesa_stages::tasks::prompts::Prompts;
use mesa_stages::tasks::scene::NoChat;
use mesa_stages::tasks::{write_scene_tasks, Backend, SceneInput, SceneTasks, TasksError, View};
use serde::Serialize;

use crate::fsio::DigestCache;
use crate::runner::{
    digest_of, scene_state, Scene, SceneOutput, SceneStage, SceneState, StageContext,
};
use crate::stages::scene_docs::{present_layouts, read_scene_docs, GRAPH_JSON, GRAPH_TXT};
use rayon::prelude::*;

/// The tasks of a scene, relative to the scene folder.
pub const TASKS_FILE: &str = "tasks/tasks.jsonl";
/// The rejected replies of a scene.
pub const REJECTS_FILE: &str = "tasks/rejects.jsonl";
/// The rendered views sent with the description call when they exist: (name, file).
pub const VIEWS: [(&str, &str); 2] = [
    ("front", "render/front.png"),
    ("perspective", "render/perspective.png"),
];

/// The prompts of a dataset: its `[tasks] prompts_dir`, else the built-in ones.
pub fn load_prompts(dataset: &Path, prompts_dir: &str) -> Result<Prompts, String> {
    let result = if prompts_dir.is_empty() {
        Prompts::builtin()
    } else {
        Prompts::from_dir(&dataset.join(prompts_dir))
    };
    result.map_err(|e| format!("[tasks] prompts_dir: {e}"))
}

/// The outcome of one scene.
#[derive(Debug)]
pub enum Computed {
    /// Every call answered.
    Done(SceneTasks),
    /// Offline batch mode: these requests' replies are still missing.
    Pending(Vec<ChatRequest>),
}

/// Where the scenes of an offline-batch run stand.
#[derive(Debug, Default)]
pub struct BatchPlan {
    /// Scenes to run now (`<table_type>/<scene_id>`): every reply is cached (or they fail for
    /// another reason, which the run then records).
    pub complete: BTreeSet<String>,
    /// The scenes that wait for a reply, with the request.
    pub pending: Vec<(String, ChatRequest)>,
}

/// The `tasks` stage.
pub struct TasksStage {
    chat: Option<Arc<dyn Chat + Send + Sync>>,
    loaded: OnceLock<Result<Loaded, String>>,
}

/// The prompts and chat backend of a run, made on first use.
struct Loaded {
    dataset: PathBuf,
    prompts: Prompts,
    chat: Arc<dyn Chat + Send + Sync>,
}

/// Checks what a tasks run needs before any work starts: the configuration, the prompts, and
/// for the live `llm` backend the API key. The message says how to fix it.
pub fn preflight(dataset: &Path, config: &crate::config::Config) -> Result<(), String> {
    let problems = config.tasks.problems();
    if !problems.is_empty() {
        return Err(problems.join("\n"));
    }
    load_prompts(dataset, &config.tasks.prompts_dir)?;
    if config.tasks.backend == Backend::Llm {
        crate::chat::ApiKey::from_env(&config.tasks.llm.api_key_env)?;
    }
    Ok(())
}

impl Default for TasksStage {
    fn default() -> Self {
        Self::new()
    }
}

/// The configuration values that change a scene's tasks.
#[derive(Serialize)]
struct Fingerprint<'a> {
    backend: Backend,
    tasks_per_scene: u32,
    min_task_objects: u32,
    max_attempts: u32,
    prompts: [&'a str; 6],
    seed: u64,
    llm: Option<(&'a str, f64, u32, u64, bool, bool)>,
}

impl TasksStage {
    /// The stage with the backend of the configuration: nothing for the template backend, a
    /// live client of `[tasks.llm]` for the `llm` backend (made on first use).
    pub fn new() -> Self {
        Self {
            chat: None,
            loaded: OnceLock::new(),
        }
    }

    /// The stage with a given chat backend (a client whose statistics the caller reads, or the
    /// cache alone for offline batches).
    pub fn with_chat(chat: Arc<dyn Chat + Send + Sync>) -> Self {
        Self {
            chat: Some(chat),
            loaded: OnceLock::new(),
        }
    }

    fn loaded(&self, ctx: &StageContext<'_>) -> anyhow::Result<&Loaded> {
        let loaded = self
            .loaded
            .get_or_init(|| {
                let prompts = load_prompts(ctx.dataset, &ctx.config.tasks.prompts_dir)?;
                let chat: Arc<dyn Chat + Send + Sync> = match (&self.chat, ctx.config.tasks.backend)
                {
                    (Some(chat), _) => Arc::clone(chat),
                    (None, Backend::Template) => Arc::new(NoChat),
                    (None, Backend::Llm) => Arc::new(crate::chat::ChatClient::new(
                        ctx.dataset,
                        &ctx.config.tasks.llm,
                        crate::chat::Mode::Live,
                    )?),
                };
                Ok(Loaded {
                    dataset: ctx.dataset.to_owned(),
                    prompts,
                    chat,
                })
            })
            .as_ref()
            .map_err(|e| anyhow!("{e}"))?;
        if loaded.dataset != ctx.dataset {
            bail!("internal error: one tasks stage used for two datasets");
        }
        Ok(loaded)
    }

    /// The scene's inputs, read and checked.
    fn scene_input(&self, scene: &Scene) -> anyhow::Result<(SceneInput, Vec<String>)> {
        let docs = read_scene_docs(scene)?;
        let mut views = Vec::new();
        for (name, rel) in VIEWS {
            let path = scene.path(rel);
            if path.is_file() {
                let png = std::fs::read(&path)
                    .with_context(|| format!("{}: cannot read", path.display()))?;
                views.push(View {
                    name: name.to_owned(),
                    file: rel.to_owned(),
                    png,
                });
            }
        }
        Ok((
            SceneInput {
                scene_id: scene.scene_id.clone(),
                table_type: scene.table_type.clone(),
                layout: docs.layout,
                layout_file: docs.layout_rel.to_owned(),
                layout_sha256: docs.layout_sha256,
                graph_lines: docs.graph_lines,
                graph: docs.graph,
                views,
            },
            docs.warnings,
        ))
    }

    /// Writes one scene's tasks in memory, or says which reply it waits for.
    pub fn compute(&self, ctx: &StageContext<'_>, scene: &Scene) -> anyhow::Result<Computed> {
        let loaded = self.loaded(ctx)?;
        let (input, warnings) = self.scene_input(scene)?;
        match write_scene_tasks(
            &input,
            &ctx.config.tasks,
            &loaded.prompts,
            loaded.chat.as_ref(),
            ctx.config.run.seed,
        ) {
            Ok(mut tasks) => {
                tasks.warnings.splice(0..0, warnings);
                Ok(Computed::Done(tasks))
            }
            Err(TasksError::Pending(request)) => Ok(Computed::Pending(request)),
            Err(e) => Err(anyhow!(e)),
        }
    }

    /// Offline batches: which of `scenes` can run now and which requests the others wait for
    /// (scenes still done are left out unless `force`). The stage's chat must answer from the
    /// cache alone.
    pub fn plan_batch(&self, ctx: &StageContext<'_>, scenes: &[Scene], force: bool) -> BatchPlan {
        let digest = self.config_digest(ctx);
        let cache = DigestCache::default();
        let planned: Vec<(String, Option<Vec<ChatRequest>>)> = scenes
            .par_iter()
            .map(|scene| {
                if !force && scene_state(self, ctx, scene, &digest, &cache) == SceneState::Done {
                    return (scene.key(), None);
                }
                // A scene that fails for another reason runs, so its failure is recorded.
                let pending = match self.compute(ctx, scene) {
                    Ok(Computed::Pending(requests)) => requests,
                    Ok(Computed::Done(_)) | Err(_) => Vec::new(),
                };
                (scene.key(), Some(pending))
            })
            .collect();
        let mut plan = BatchPlan::default();
        for (key, state) in planned {
            match state {
                None => {}
                Some(requests) if requests.is_empty() => {
                    plan.complete.insert(key);
                }
                Some(requests) => plan
                    .pending
                    .extend(requests.into_iter().map(|r| (key.clone(), r))),
            }
        }
        plan
    }
}

impl SceneStage for TasksStage {
    fn name(&self) -> &'static str {
        "tasks"
    }

    fn inputs(&self, ctx: &StageContext<'_>, scene: &Scene) -> anyhow::Result<Vec<String>> {
        let layouts = present_layouts(scene);
        if layouts.is_empty() {
            bail!(
                "{}: no layout (run `mesa ingest` first, then `mesa graph`)",
                scene.dir.display()
            );
        }
        let mut inputs: Vec<String> = layouts.iter().map(|rel| scene.rel(rel)).collect();
        inputs.push(scene.rel(GRAPH_TXT));
        inputs.push(scene.rel(GRAPH_JSON));
        let tasks = &ctx.config.tasks;
        if tasks.backend == Backend::Llm && tasks.llm.send_images {
            for (_, rel) in VIEWS {
                if scene.path(rel).is_file() {
                    inputs.push(scene.rel(rel));
                }
            }
        }
        if !tasks.prompts_dir.is_empty() {
            for file in Prompts::files_in(&tasks.prompts_dir) {
                inputs.push(file.to_string_lossy().into_owned());
            }
        }
        Ok(inputs)
    }

    fn waiting(&self, _ctx: &StageContext<'_>, scene: &Scene) -> Option<String> {
        crate::stages::scene_docs::awaiting_annotation(scene)
    }

    fn config_digest(&self, ctx: &StageContext<'_>) -> String {
        let tasks = &ctx.config.tasks;
        let llm = &tasks.llm;
        // Prompts that cannot be read fail every scene in `run`; the digest only has to differ.
        let p = match load_prompts(ctx.dataset, &tasks.prompts_dir) {
            Ok(prompts) => prompts,
            Err(e) => return digest_of(&e),
        };
        // Runtime settings (concurrency, retries, timeouts, the URL) change no output.
        digest_of(&Fingerprint {
            backend: tasks.backend,
            tasks_per_scene: tasks.tasks_per_scene,
            min_task_objects: tasks.min_task_objects,
            max_attempts: tasks.max_attempts,
            prompts: [
                &p.table_description.system,
                &p.table_description.user,
                &p.tasks.system,
                &p.tasks.user,
                &p.reasoning.system,
                &p.reasoning.user,
            ],
            seed: ctx.config.run.seed,
            llm: (tasks.backend == Backend::Llm).then_some((
                llm.model.as_str(),
                llm.temperature,
                llm.max_tokens,
                llm.seed,
                llm.json_mode,
                llm.send_images,
            )),
        })
    }

    fn run(&self, ctx: &StageContext<'_>, scene: &Scene) -> anyhow::Result<SceneOutput> {
        let tasks = match self.compute(ctx, scene)? {
            Computed::Done(tasks) => tasks,
            Computed::Pending(requests) => bail!(
                "waiting for {} replies: write the next offline batch with `mesa tasks \
                 --batch-out FILE` and read the provider's output with --batch-in",
                requests.len()
            ),
        };
        let mut output = SceneOutput::new();
        let mut lines = String::new();
        for record in &tasks.records {
            lines.push_str(&to_sorted_line(record)?);
            lines.push('\n');
        }
        output.add_file(TASKS_FILE, lines.into_bytes());
        if !tasks.rejects.is_empty() {
            let mut lines = String::new();
            for reject in &tasks.rejects {
                lines.push_str(&to_sorted_line(reject)?);
                lines.push('\n');
            }
            output.add_file(REJECTS_FILE, lines.into_bytes());
            output.warn(format!(
                "{} model replies rejected (kept with their reasons in {REJECTS_FILE})",
                tasks.rejects.len()
            ));
        }
        for warning in tasks.warnings {
            output.warn(warning);
        }
        Ok(output)
    }
}
