//! `mesa tasks`: per scene, the table description, the tasks and their reasoning texts
//! (`tasks/tasks.jsonl`, rejected replies in `tasks/rejects.jsonl`), over
//! [`mesa_stages::tasks`], with the template backend or a chat endpoint (live, or offline
//! batches through the reply cache).

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::{Arc, OnceLock};

use anyhow::{anyhow, bail, Context as _};
use mesa_schemas::artifacts::TaskReject;
use mesa_schemas::json::to_sorted_line;
use mesa_stages::tasks::chat::{Chat, ChatRequest};
use mesa_stages::tasks::prompts::Prompts;
use mesa_stages::tasks::scene::NoChat;
use mesa_stages::tasks::{
    write_scene_tasks_keeping_rejects, Backend, FailedScene, SceneInput, SceneTasks, TasksError,
    View,
};
use serde::Serialize;

use clap::{Args as ClapArgs, ValueEnum};
use mesa_stages::paths::scene::{GRAPH_JSON, GRAPH_TXT, REJECTS, TASKS};

use crate::cli::{Global, Resolved, SceneArgs};
use crate::exit::{usage, UsageError, EXIT_FAILED, EXIT_OK};
use crate::fsio::DigestCache;
use crate::layouts::present_layouts;
use crate::runner::{
    digest_of, discover_scenes, scene_state, select_scenes, FailureOutputs, RunError, Scene,
    SceneOutput, SceneStage, SceneState, StageContext,
};
use crate::scene_docs::read_scene_docs;
use rayon::prelude::*;

/// The rendered views sent with the description call when they exist: (name, file).
pub const VIEWS: [(&str, &str); 2] = [
    ("front", "render/front.png"),
    ("perspective", "render/perspective.png"),
];

/// `--backend`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum BackendArg {
    /// The built-in deterministic writer (offline; records say "generator": "template").
    Template,
    /// The chat endpoint of [tasks.llm] (its API key from the variable api_key_env names).
    Llm,
}

impl From<BackendArg> for mesa_stages::tasks::Backend {
    fn from(value: BackendArg) -> Self {
        match value {
            BackendArg::Template => Self::Template,
            BackendArg::Llm => Self::Llm,
        }
    }
}

/// `mesa tasks`.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// The runner flags.
    #[command(flatten)]
    pub stage: SceneArgs,
    /// The backend (default: [tasks] backend of mesa.toml). With llm and no --jobs, the
    /// scenes run [tasks.llm] max_concurrency at a time.
    #[arg(long, value_enum)]
    pub backend: Option<BackendArg>,
    /// Offline batches: write the requests still unanswered to FILE as OpenAI Batch JSONL
    /// (one call per scene and round: description, then tasks, then reasoning; implies
    /// --backend llm). Scenes whose replies are all in get their tasks written.
    #[arg(long, value_name = "FILE")]
    pub batch_out: Option<PathBuf>,
    /// Offline batches: read a provider's batch output JSONL (repeatable); replies are joined
    /// to requests by custom_id and stored in the reply cache, failed lines are reported and
    /// their requests go into the next --batch-out (implies --backend llm).
    #[arg(long, value_name = "FILE")]
    pub batch_in: Vec<PathBuf>,
}

/// Runs `mesa tasks`.
pub fn run(args: Args, global: Global) -> anyhow::Result<ExitCode> {
    use crate::chat::{ChatClient, Mode};

    let mut resolved = args.stage.resolve(global)?;
    let batch = args.batch_out.is_some() || !args.batch_in.is_empty();
    if batch && args.backend == Some(BackendArg::Template) {
        return Err(usage(
            "--batch-out and --batch-in are for the llm backend (not --backend template)",
        ));
    }
    if let Some(backend) = args.backend {
        resolved.config.tasks.backend = backend.into();
    }
    if batch {
        resolved.config.tasks.backend = Backend::Llm;
        let problems = resolved.config.tasks.problems();
        if !problems.is_empty() {
            return Err(usage(problems.join("\n")));
        }
        load_prompts(&resolved.dataset, &resolved.config.tasks.prompts_dir).map_err(UsageError)?;
        return batch_tasks(&args, resolved);
    }
    if resolved.config.tasks.backend == Backend::Template {
        return resolved.run(&TasksStage::new());
    }
    preflight(&resolved.dataset, &resolved.config).map_err(UsageError)?;
    let llm = &resolved.config.tasks.llm;
    let client = Arc::new(ChatClient::new(&resolved.dataset, llm, Mode::Live).map_err(UsageError)?);
    if args.stage.common.jobs.is_none() {
        // Scenes wait on the network, not the CPU: run as many as may be in flight.
        resolved.options.jobs = llm.max_concurrency;
    }
    let code = resolved.run(&TasksStage::with_chat(client.clone()))?;
    eprintln!("tasks: {}: {}", llm.model, client.stats.summary());
    for warning in client.warnings() {
        eprintln!("tasks: warning: {warning}");
    }
    Ok(code)
}

fn batch_tasks(args: &Args, mut resolved: Resolved) -> anyhow::Result<ExitCode> {
    use crate::chat::{import_batch_files, pending_by_id, write_batch, ChatClient, Mode};

    let client = Arc::new(
        ChatClient::new(
            &resolved.dataset,
            &resolved.config.tasks.llm,
            Mode::CacheOnly,
        )
        .map_err(UsageError)?,
    );
    let stage = TasksStage::with_chat(client.clone());
    let ctx_plan = |resolved: &Resolved| -> anyhow::Result<BatchPlan> {
        let scenes = select_scenes(
            discover_scenes(&resolved.dataset).map_err(RunError::into_anyhow)?,
            resolved.options.scenes.as_deref(),
            resolved.options.shard,
        )
        .map_err(RunError::into_anyhow)?;
        Ok(stage.plan_batch(&resolved.ctx(), &scenes, resolved.options.force))
    };
    let mut failed_lines = 0usize;
    if !args.batch_in.is_empty() {
        let BatchPlan { pending, .. } = ctx_plan(&resolved)?;
        let imported = import_batch_files(
            &args.batch_in,
            &pending_by_id(pending.iter().map(|(_, request)| request)),
            client.cache(),
        )?;
        for line in &imported.lines {
            // A file's line gets the command's name; its failed lines are indented.
            if line.starts_with(' ') {
                eprintln!("{line}");
            } else {
                eprintln!("tasks: {line}");
            }
        }
        failed_lines += imported.failed;
    }
    let BatchPlan { complete, pending } = ctx_plan(&resolved)?;
    let waiting: std::collections::BTreeSet<&str> =
        pending.iter().map(|(k, _)| k.as_str()).collect();
    match &args.batch_out {
        Some(path) if !pending.is_empty() => {
            let requests: Vec<_> = pending.iter().map(|(_, r)| r.clone()).collect();
            let lines = write_batch(path, &requests)
                .with_context(|| format!("{}: cannot write", path.display()))?;
            eprintln!(
                "tasks: {lines} requests for {} scenes written to {} (OpenAI Batch JSONL; read \
                 the provider's output with --batch-in)",
                waiting.len(),
                path.display()
            );
        }
        Some(path) => eprintln!(
            "tasks: no request is pending, so {} was not written",
            path.display()
        ),
        None if !pending.is_empty() => eprintln!(
            "tasks: {} scenes still wait for replies (write the next batch with --batch-out FILE)",
            waiting.len()
        ),
        None => {}
    }
    let code = if complete.is_empty() {
        if waiting.is_empty() {
            eprintln!("tasks: every selected scene is done (--force redoes them)");
        } else {
            eprintln!("tasks: no scene has all its replies yet");
        }
        ExitCode::from(EXIT_OK)
    } else {
        resolved.options.only = Some(complete);
        resolved.run(&stage)?
    };
    Ok(if failed_lines > 0 {
        ExitCode::from(EXIT_FAILED)
    } else {
        code
    })
}

/// The prompts of a dataset: its `[tasks] prompts_dir`, else the built-in ones.
pub fn load_prompts(dataset: &Path, prompts_dir: &str) -> Result<Prompts, String> {
    let result = if prompts_dir.is_empty() {
        Prompts::builtin()
    } else {
        Prompts::from_dir(&dataset.join(prompts_dir))
    };
    result.map_err(|e| format!("[tasks] prompts_dir: {e}"))
}

/// `tasks/rejects.jsonl`: one sorted JSON line per reject.
fn rejects_jsonl(rejects: &[TaskReject]) -> anyhow::Result<Vec<u8>> {
    let mut lines = String::new();
    for reject in rejects {
        lines.push_str(&to_sorted_line(reject)?);
        lines.push('\n');
    }
    Ok(lines.into_bytes())
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
        match write_scene_tasks_keeping_rejects(
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
            Err(FailedScene {
                error: TasksError::Pending(request),
                ..
            }) => Ok(Computed::Pending(request)),
            Err(FailedScene { error, rejects }) => {
                // The rejects are written before the error that names them, and the tasks of
                // the last success stay (records use them while they match the layout).
                let mut failure = FailureOutputs::new(anyhow!(error)).keep_previous_outputs();
                if !rejects.is_empty() {
                    failure.add_file(REJECTS, rejects_jsonl(&rejects)?);
                }
                Err(anyhow::Error::new(failure))
            }
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

    /// The configuration, the prompts, and for the live `llm` backend the API key (a stage
    /// given its chat backend by its caller has had its key checked there).
    fn preflight(&self, ctx: &StageContext<'_>) -> Result<(), UsageError> {
        if self.chat.is_some() {
            return Ok(());
        }
        preflight(ctx.dataset, ctx.config).map_err(UsageError)
    }

    fn waiting(&self, _ctx: &StageContext<'_>, scene: &Scene) -> Option<String> {
        crate::scene_docs::awaiting_annotation(scene)
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
        output.add_file(TASKS, lines.into_bytes());
        if !tasks.rejects.is_empty() {
            output.add_file(REJECTS, rejects_jsonl(&tasks.rejects)?);
            output.warn(format!(
                "{} model replies rejected (kept with their reasons in {REJECTS})",
                tasks.rejects.len()
            ));
        }
        for warning in tasks.warnings {
            output.warn(warning);
        }
        Ok(output)
    }
}
