//! What each subcommand does: raw flags become a validated configuration before any work
//! starts (bad usage fails in the first second with exit code 2), then the library runs.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

use anyhow::{bail, Context as _};
use mesa_schemas::convert::{dataset_from_llm, llm_from_dataset};
use mesa_schemas::json::to_sorted_pretty;
use mesa_schemas::output::parse_model_output;
use mesa_schemas::{kinds, validate_text, Kind};

use crate::cli::{
    AssetsArgs, BackendArg, CheckArgs, DemoArgs, GraphArgs, RecordsArgs, StatusArgs, TasksArgs,
    ValidateArgs,
};
use crate::cli::{Cli, Command, ConvertArgs, LayoutForm, ParseOutputArgs, RunArgs, StageArgs};
use crate::config::{annotated_toml, Config};
use crate::fsio::{write_atomic, DigestCache};
use crate::layouts::{read_any_layout, AnyLayout};
use crate::runner::{
    discover_scenes, format_summary, run_stage, scene_state, RunOptions, SceneStage, SceneState,
    Shard, StageContext,
};
use crate::stages::pipeline_stages;

/// Exit code: every scene done / the files are valid.
pub const EXIT_OK: u8 = 0;
/// Exit code: some scenes failed / some files are invalid.
pub const EXIT_FAILED: u8 = 1;
/// Exit code: bad usage or configuration.
pub const EXIT_USAGE: u8 = 2;

/// A usage or configuration error (exit code 2), as opposed to failed scenes (exit code 1).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct UsageError(pub String);

/// Runs a parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    match cli.command {
        Command::Run(args) => run_all(args, cli.quiet),
        Command::Status(args) => status(args),
        Command::Validate(args) => validate(args),
        Command::Convert(args) => convert(args),
        Command::ParseOutput(args) => parse_output(args),
        Command::Demo(args) => demo(args, cli.quiet),
        Command::Lift(args) => run_one(&crate::stages::lift::Lift, &resolve(&args, cli.quiet)?),
        Command::Assets(args) => assets(args, cli.quiet),
        Command::Retrieve(args) => run_one(
            &crate::stages::retrieve::RetrieveStage::new(),
            &resolve(&args, cli.quiet)?,
        ),
        Command::Place(args) => run_one(
            &crate::stages::place::PlaceStage::new(),
            &resolve(&args, cli.quiet)?,
        ),
        Command::Pack(args) => run_one(
            &crate::stages::pack::PackStage::new(),
            &resolve(&args, cli.quiet)?,
        ),
        Command::Ingest(args) => {
            let mut resolved = resolve(&args.stage, cli.quiet)?;
            if args.allow_unknown_nodes {
                resolved.config.ingest.allow_unknown_nodes = true;
            }
            run_one(&crate::stages::ingest::IngestStage::new(), &resolved)
        }
        Command::Check(args) => check(args, cli.quiet),
        Command::Graph(args) => graph(args, cli.quiet),
        Command::Tasks(args) => tasks(args, cli.quiet),
        Command::Records(args) => records(args, cli.quiet),
        Command::Render(args) => render(args, cli.quiet),
        Command::Report(args) => report(args, cli.quiet),
        Command::Release(args) => release(args, cli.quiet),
    }
}

/// The resolved configuration and runner options of a stage command.
pub struct Resolved {
    /// The dataset folder.
    pub dataset: PathBuf,
    /// The configuration.
    pub config: Config,
    /// The runner options.
    pub options: RunOptions,
}

/// Resolves the runner flags against `mesa.toml` and the Slurm environment.
pub fn resolve(args: &StageArgs, quiet: bool) -> anyhow::Result<Resolved> {
    if !args.dataset.is_dir() {
        return Err(UsageError(format!(
            "{}: no such dataset folder (expected a folder with scenes/; `mesa demo DIR` writes one)",
            args.dataset.display()
        ))
        .into());
    }
    let config = Config::load(&args.dataset, args.config.as_deref())
        .map_err(|e| UsageError(e.to_string()))?;
    let mut options = RunOptions::from_config(&config);
    options.scenes = args.scenes.clone();
    if let Some(jobs) = args.jobs {
        options.jobs = jobs;
    }
    options.shard = match args.shard {
        Some(shard) => shard,
        None => Shard::from_slurm_env()
            .map_err(UsageError)?
            .unwrap_or_default(),
    };
    options.force = args.force;
    if let Some(progress) = args.progress {
        options.progress = progress.into();
    }
    if quiet {
        options.progress = crate::config::ProgressMode::Off;
    }
    options.progress_interval = Duration::from_secs_f64(config.run.progress_interval_s.max(0.1));
    Ok(Resolved {
        dataset: args.dataset.clone(),
        config,
        options,
    })
}

/// Runs one stage with resolved flags, prints the summary, and gives the exit code.
pub fn run_one(stage: &dyn SceneStage, resolved: &Resolved) -> anyhow::Result<ExitCode> {
    let ctx = StageContext {
        dataset: &resolved.dataset,
        config: &resolved.config,
    };
    let summary =
        run_stage(stage, &ctx, &resolved.options).map_err(|e| UsageError(e.to_string()))?;
    eprint!("{}", format_summary(&summary));
    Ok(ExitCode::from(if summary.success() {
        EXIT_OK
    } else {
        EXIT_FAILED
    }))
}

fn run_all(args: RunArgs, quiet: bool) -> anyhow::Result<ExitCode> {
    let resolved = resolve(&args.stage, quiet)?;
    if args.print_config {
        print!("{}", annotated_toml(&resolved.config)?);
        return Ok(ExitCode::SUCCESS);
    }
    let stages = pipeline_stages(&resolved.config);
    if stages.is_empty() {
        bail!("this build of mesa has no per-scene stage to run");
    }
    // Bad settings of later stages fail now, not after hours of earlier ones.
    crate::stages::tasks::preflight(&resolved.dataset, &resolved.config).map_err(UsageError)?;
    records_preflight(&resolved)?;
    // The resolved configuration of the last run, for the record.
    let resolved_toml = annotated_toml(&resolved.config)?;
    write_atomic(
        &resolved.dataset.join(".mesa/config.resolved.toml"),
        resolved_toml.as_bytes(),
    )
    .with_context(|| format!("{}: cannot write .mesa/", resolved.dataset.display()))?;
    let mut failed = false;
    // The asset index is a dataset-level step: it comes before the per-scene stages that read
    // it. With --shard, every shard would index the library at once: it must run before them.
    let library = resolved.dataset.join(crate::stages::assets::LIBRARY);
    if resolved.options.shard.count > 1 {
        eprintln!(
            "assets: not run by `mesa run --shard` (every shard would index the library): run              `mesa assets {}` once before the shards",
            resolved.dataset.display()
        );
    } else if library.is_dir() {
        let summary = crate::stages::assets::index_library(
            &resolved.dataset,
            &resolved.config,
            &assets_options(&resolved.options),
        )?;
        eprint!("{}", crate::stages::assets::format_summary(&summary));
    } else {
        eprintln!(
            "assets: {} does not exist: no asset index (retrieve and place need one)",
            library.display()
        );
    }
    for stage in &stages {
        let code = run_one(stage.as_ref(), &resolved)?;
        failed |= code != ExitCode::SUCCESS;
        if stage.name() == "check" {
            print_check_summary(&resolved, quiet)?;
        }
    }
    // The dataset-level stages merge every scene: with shards, each shard has only its part.
    if resolved.options.shard.count > 1 {
        eprintln!(
            "records: not run by a shard; run `mesa records {}` once every shard is done",
            resolved.dataset.display()
        );
        eprintln!(
            "report: not run by a shard; run `mesa report {}` once every shard is done",
            resolved.dataset.display()
        );
    } else {
        failed |= run_records_stage(&resolved)? != ExitCode::SUCCESS;
        failed |= run_report_stage(&resolved)? != ExitCode::SUCCESS;
    }
    Ok(ExitCode::from(if failed { EXIT_FAILED } else { EXIT_OK }))
}

fn records_preflight(resolved: &Resolved) -> anyhow::Result<()> {
    let problems = resolved.config.records.problems();
    if !problems.is_empty() {
        return Err(UsageError(problems.join("\n")).into());
    }
    crate::stages::records::instruction(&resolved.dataset, &resolved.config.records)
        .map_err(UsageError)?;
    Ok(())
}

fn run_records_stage(resolved: &Resolved) -> anyhow::Result<ExitCode> {
    let options = crate::stages::records::RecordsOptions {
        jobs: resolved.options.jobs,
        force: resolved.options.force,
        progress: resolved.options.progress,
        progress_interval: resolved.options.progress_interval,
    };
    let summary =
        crate::stages::records::run_records(&resolved.dataset, &resolved.config, &options)?;
    eprint!(
        "{}",
        crate::stages::records::format_records_summary(&summary)
    );
    Ok(ExitCode::from(if summary.excluded.is_empty() {
        EXIT_OK
    } else {
        EXIT_FAILED
    }))
}

fn records(args: RecordsArgs, quiet: bool) -> anyhow::Result<ExitCode> {
    let stage_args = StageArgs {
        dataset: args.dataset,
        scenes: None,
        jobs: args.jobs,
        // Records merge every scene: no shard applies (nor the Slurm variables).
        shard: Some(Shard::default()),
        force: args.force,
        config: args.config,
        progress: args.progress,
    };
    let resolved = resolve(&stage_args, quiet)?;
    records_preflight(&resolved)?;
    run_records_stage(&resolved)
}

fn tasks(args: TasksArgs, quiet: bool) -> anyhow::Result<ExitCode> {
    use crate::chat::{ChatClient, Mode};
    use crate::stages::tasks::{preflight, TasksStage};
    use mesa_stages::tasks::Backend;
    use std::sync::Arc;

    let mut resolved = resolve(&args.stage, quiet)?;
    let batch = args.batch_out.is_some() || !args.batch_in.is_empty();
    if batch && args.backend == Some(BackendArg::Template) {
        return Err(UsageError(
            "--batch-out and --batch-in are for the llm backend (not --backend template)".into(),
        )
        .into());
    }
    if let Some(backend) = args.backend {
        resolved.config.tasks.backend = backend.into();
    }
    if batch {
        resolved.config.tasks.backend = Backend::Llm;
        let problems = resolved.config.tasks.problems();
        if !problems.is_empty() {
            return Err(UsageError(problems.join("\n")).into());
        }
        crate::stages::tasks::load_prompts(&resolved.dataset, &resolved.config.tasks.prompts_dir)
            .map_err(UsageError)?;
        return batch_tasks(&args, resolved);
    }
    preflight(&resolved.dataset, &resolved.config).map_err(UsageError)?;
    if resolved.config.tasks.backend == Backend::Template {
        return run_one(&TasksStage::new(), &resolved);
    }
    let llm = &resolved.config.tasks.llm;
    let client = Arc::new(ChatClient::new(&resolved.dataset, llm, Mode::Live).map_err(UsageError)?);
    if args.stage.jobs.is_none() {
        // Scenes wait on the network, not the CPU: run as many as may be in flight.
        resolved.options.jobs = llm.max_concurrency;
    }
    let code = run_one(&TasksStage::with_chat(client.clone()), &resolved)?;
    eprintln!("tasks: {}: {}", llm.model, client.stats.summary());
    for warning in client.warnings() {
        eprintln!("tasks: warning: {warning}");
    }
    Ok(code)
}

fn batch_tasks(args: &TasksArgs, mut resolved: Resolved) -> anyhow::Result<ExitCode> {
    use crate::chat::{custom_id, import_batch, request_digest, write_batch, ChatClient, Mode};
    use crate::stages::tasks::{BatchPlan, TasksStage};
    use std::sync::Arc;

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
        let ctx = StageContext {
            dataset: &resolved.dataset,
            config: &resolved.config,
        };
        let scenes = crate::runner::select_scenes(
            discover_scenes(&resolved.dataset).map_err(|e| UsageError(e.to_string()))?,
            resolved.options.scenes.as_deref(),
            resolved.options.shard,
        )
        .map_err(|e| UsageError(e.to_string()))?;
        Ok(stage.plan_batch(&ctx, &scenes, resolved.options.force))
    };
    let mut failed_lines = 0usize;
    if !args.batch_in.is_empty() {
        let BatchPlan { pending, .. } = ctx_plan(&resolved)?;
        let by_id: std::collections::BTreeMap<String, String> = pending
            .iter()
            .map(|(_, request)| {
                let digest = request_digest(request);
                (custom_id(&digest), digest)
            })
            .collect();
        for file in &args.batch_in {
            let text = std::fs::read_to_string(file).map_err(|e| {
                UsageError(format!(
                    "{}: cannot read the batch output: {e}",
                    file.display()
                ))
            })?;
            let report = import_batch(file, &text, &by_id, client.cache());
            eprintln!(
                "tasks: {}: {} replies stored, {} already cached, {} lines failed",
                file.display(),
                report.stored,
                report.already_cached,
                report.failed.len()
            );
            for failure in &report.failed {
                eprintln!("  failed {failure}");
            }
            failed_lines += report.failed.len();
        }
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
        run_one(&stage, &resolved)?
    };
    Ok(if failed_lines > 0 {
        ExitCode::from(EXIT_FAILED)
    } else {
        code
    })
}

fn assets_options(options: &RunOptions) -> crate::stages::assets::AssetsOptions {
    crate::stages::assets::AssetsOptions {
        jobs: options.jobs,
        force: options.force,
        progress: options.progress,
        progress_interval: options.progress_interval,
    }
}

fn assets(args: AssetsArgs, quiet: bool) -> anyhow::Result<ExitCode> {
    let stage = StageArgs {
        dataset: args.dataset.clone(),
        scenes: None,
        jobs: args.jobs,
        shard: Some(Shard::default()),
        force: args.force,
        config: args.config.clone(),
        progress: args.progress,
    };
    let resolved = resolve(&stage, quiet)?;
    // Under a Slurm array, one task indexes the library; the others have nothing to do.
    if let Some(shard) = Shard::from_slurm_env().map_err(UsageError)? {
        if shard.index != 0 {
            eprintln!(
                "assets: the library is indexed by array task 0 (this is task {shard}): nothing                  to do here"
            );
            return Ok(ExitCode::SUCCESS);
        }
    }
    let summary = crate::stages::assets::index_library(
        &resolved.dataset,
        &resolved.config,
        &assets_options(&resolved.options),
    )?;
    eprint!("{}", crate::stages::assets::format_summary(&summary));
    Ok(ExitCode::from(
        if args.strict && !summary.invalid.is_empty() {
            EXIT_FAILED
        } else {
            EXIT_OK
        },
    ))
}

fn check(args: CheckArgs, quiet: bool) -> anyhow::Result<ExitCode> {
    let mut resolved = resolve(&args.stage, quiet)?;
    if let Some(layout) = args.layout {
        resolved.config.check.layout = layout.into();
    }
    if args.settle {
        resolved.config.check.settle = true;
    }
    let code = run_one(&crate::stages::check::CheckStage::new(), &resolved)?;
    print_check_summary(&resolved, quiet)?;
    Ok(code)
}

/// Writes the dataset's check summary (`qa/summary.json`) and prints it.
fn print_check_summary(resolved: &Resolved, quiet: bool) -> anyhow::Result<()> {
    let lines = crate::stages::check::write_summary(&resolved.dataset)?;
    if !quiet {
        if let Some(lines) = lines {
            eprint!("{lines}");
        }
    }
    Ok(())
}

fn graph(args: GraphArgs, quiet: bool) -> anyhow::Result<ExitCode> {
    if let Some(layout) = &args.layout {
        return crate::stages::graph::print_layout_graph(
            layout,
            args.containers.as_deref(),
            args.equally_spaced,
        );
    }
    let Some(stage_args) = &args.stage else {
        return Err(UsageError("give a DATASET, or --layout FILE".to_owned()).into());
    };
    let mut resolved = resolve(stage_args, quiet)?;
    if args.equally_spaced {
        resolved.config.graph.equally_spaced = true;
    }
    run_one(&crate::stages::graph::GraphStage::new(), &resolved)
}

fn render(args: crate::cli::RenderArgs, quiet: bool) -> anyhow::Result<ExitCode> {
    let mut resolved = resolve(&args.stage, quiet)?;
    if let Some(layout) = args.layout {
        resolved.config.render.layout = layout.into();
    }
    if args.assets {
        let options = crate::stages::render::AssetViewsOptions {
            uids: args.uids.clone(),
            jobs: resolved.options.jobs,
            force: resolved.options.force,
            progress: resolved.options.progress,
            progress_interval: resolved.options.progress_interval,
        };
        let summary = crate::stages::render::render_asset_views(
            &resolved.dataset,
            &resolved.config,
            &options,
        )?;
        eprint!(
            "{}",
            crate::stages::render::format_asset_views_summary(&summary)
        );
        return Ok(ExitCode::from(if summary.failed.is_empty() {
            EXIT_OK
        } else {
            EXIT_FAILED
        }));
    }
    run_one(&crate::stages::render::RenderStage::new(), &resolved)
}

fn report(args: crate::cli::ReportArgs, quiet: bool) -> anyhow::Result<ExitCode> {
    let stage_args = StageArgs {
        dataset: args.dataset,
        scenes: None,
        jobs: args.jobs,
        // The report covers every scene: no shard applies (nor the Slurm variables).
        shard: Some(Shard::default()),
        force: false,
        config: args.config,
        progress: None,
    };
    let resolved = resolve(&stage_args, quiet)?;
    run_report_stage(&resolved)
}

fn run_report_stage(resolved: &Resolved) -> anyhow::Result<ExitCode> {
    let summary = crate::stages::report::write_report(
        &resolved.dataset,
        &resolved.config,
        resolved.options.jobs,
    )?;
    eprint!("{}", crate::stages::report::format_report_summary(&summary));
    Ok(ExitCode::SUCCESS)
}

fn release(args: crate::cli::ReleaseArgs, quiet: bool) -> anyhow::Result<ExitCode> {
    let stage_args = StageArgs {
        dataset: args.dataset.clone(),
        scenes: args.scenes.clone(),
        jobs: args.jobs,
        shard: Some(Shard::default()),
        force: false,
        config: args.config.clone(),
        progress: None,
    };
    let mut resolved = resolve(&stage_args, quiet)?;
    if let Some(layout) = args.layout {
        resolved.config.render.layout = layout.into();
    }
    let summary = crate::stages::release::write_release(
        &resolved.dataset,
        &args.out,
        &resolved.config,
        resolved.options.scenes.as_deref(),
        resolved.options.jobs,
    )?;
    eprint!(
        "{}",
        crate::stages::release::format_release_summary(&summary)
    );
    Ok(ExitCode::from(if summary.failed.is_empty() {
        EXIT_OK
    } else {
        EXIT_FAILED
    }))
}

fn demo(args: DemoArgs, quiet: bool) -> anyhow::Result<ExitCode> {
    use mesa_stages::demo::{write_demo, DemoError, DemoOptions};
    if let Some(crate::cli::DemoAction::Annotate(stage)) = &args.action {
        return run_one(
            &crate::stages::annotate::AnnotateStage,
            &resolve(stage, quiet)?,
        );
    }
    let Some(dir) = args.dir.clone() else {
        return Err(UsageError("give the folder to write: `mesa demo DIR`".to_owned()).into());
    };
    let options = DemoOptions::default()
        .with_scenes(args.scenes)
        .with_seed(args.seed)
        .with_overwrite(args.force);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.jobs)
        .build()
        .context("cannot start the worker threads")?;
    let started = std::time::Instant::now();
    let summary = pool
        .install(|| write_demo(&dir, &options))
        .map_err(|e| -> anyhow::Error {
            match e {
                DemoError::Options(_) | DemoError::NotEmpty { .. } | DemoError::NotADemo { .. } => {
                    UsageError(e.to_string()).into()
                }
                other => other.into(),
            }
        })?;
    if !quiet {
        let objects: usize = summary.scenes.iter().map(|s| s.objects).sum();
        let types: std::collections::BTreeSet<&str> = summary
            .scenes
            .iter()
            .map(|s| s.table_type.as_str())
            .collect();
        eprintln!(
            "mesa demo: {} scenes over {} table types ({objects} objects), {} assets ({} used in \
             scenes, {} categories) written to {} in {:.1} s",
            summary.scenes.len(),
            types.len(),
            summary.assets,
            summary.scene_assets,
            summary.categories,
            summary.dir.display(),
            started.elapsed().as_secs_f64()
        );
    }
    Ok(ExitCode::SUCCESS)
}

fn status(args: StatusArgs) -> anyhow::Result<ExitCode> {
    let config = Config::load(&args.dataset, args.config.as_deref())
        .map_err(|e| UsageError(e.to_string()))?;
    let ctx = StageContext {
        dataset: &args.dataset,
        config: &config,
    };
    let scenes = discover_scenes(&args.dataset).map_err(|e| UsageError(e.to_string()))?;
    let cache = DigestCache::default();
    let mut out = String::new();
    out.push_str(&format!(
        "{}: {} scenes\n{:<10} {:>7} {:>7} {:>7} {:>7} {:>7}\n",
        args.dataset.display(),
        scenes.len(),
        "stage",
        "done",
        "stale",
        "failed",
        "waiting",
        "pending"
    ));
    let mut notes = Vec::new();
    // Scenes awaiting annotation, once each (every stage after ingest waits for them too).
    let mut awaiting = std::collections::BTreeMap::new();
    for stage in pipeline_stages(&config) {
        let digest = stage.config_digest(&ctx);
        let (mut done, mut stale, mut failed, mut waiting, mut pending) = (0, 0, 0, 0, 0);
        for scene in &scenes {
            match scene_state(stage.as_ref(), &ctx, scene, &digest, &cache) {
                SceneState::Done => done += 1,
                SceneState::Stale(why) => {
                    stale += 1;
                    if notes.len() < 20 {
                        notes.push(format!("  {} {}: stale: {why}", stage.name(), scene.key()));
                    }
                }
                SceneState::Failed(why) => {
                    failed += 1;
                    if notes.len() < 20 {
                        notes.push(format!("  {} {}: failed: {why}", stage.name(), scene.key()));
                    }
                }
                SceneState::Waiting(why) => {
                    waiting += 1;
                    awaiting.entry(scene.key()).or_insert(why);
                }
                SceneState::Pending => pending += 1,
            }
        }
        out.push_str(&format!(
            "{:<10} {done:>7} {stale:>7} {failed:>7} {waiting:>7} {pending:>7}\n",
            stage.name()
        ));
    }
    if !awaiting.is_empty() {
        out.push_str(&format!("{} scenes wait:\n", awaiting.len()));
        for (scene, why) in &awaiting {
            out.push_str(&format!("  {scene}: {why}\n"));
        }
    }
    for note in notes {
        out.push_str(&note);
        out.push('\n');
    }
    print!("{out}");
    Ok(ExitCode::SUCCESS)
}

/// The kind of an official file that carries no `schema` field, from its file name.
fn kind_from_file_name(path: &Path) -> Option<&'static Kind> {
    let name = path.file_name()?.to_str()?;
    let parent = path
        .parent()
        .and_then(|p| p.file_name())
        .and_then(|n| n.to_str());
    let kind = match (parent, name) {
        (_, "layout.json") => "layout",
        (Some("input"), "camera.json") => "camera",
        (Some("input" | "truth"), "instances.json") => "instances",
        (_, "sft.json") => "sft",
        (Some("records"), "test.json") => "sft",
        (_, "trl_test.jsonl") => "trl-sft",
        (_, "dpo.json") => "dpo",
        (_, "trl_sft.jsonl") => "trl-sft",
        (_, "trl_dpo.jsonl") => "trl-dpo",
        (_, "dataset_info.json") => "dataset-info",
        (_, "Asset_annotation.json") | (Some("assets"), "annotations.json") => "asset-annotations",
        _ => return None,
    };
    Kind::by_name(kind)
}

fn collect_files(path: &Path, out: &mut Vec<PathBuf>) -> std::io::Result<()> {
    if path.is_dir() {
        let mut entries: Vec<PathBuf> = std::fs::read_dir(path)?
            .map(|e| e.map(|e| e.path()))
            .collect::<Result<_, _>>()?;
        entries.sort();
        for entry in entries {
            let hidden = entry
                .file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with('.'));
            if entry.is_dir() && !hidden {
                collect_files(&entry, out)?;
            } else if !hidden
                && entry
                    .extension()
                    .is_some_and(|e| e == "json" || e == "jsonl")
            {
                out.push(entry);
            }
        }
    } else {
        out.push(path.to_owned());
    }
    Ok(())
}

fn validate(args: ValidateArgs) -> anyhow::Result<ExitCode> {
    if args.list_kinds {
        for kind in kinds() {
            println!(
                "{:<15} {:<18} {}",
                kind.name,
                kind.schema_id.unwrap_or("(no schema field)"),
                kind.summary
            );
        }
        return Ok(ExitCode::SUCCESS);
    }
    let forced = match &args.kind {
        Some(name) => Some(Kind::by_name(name).ok_or_else(|| {
            let names: Vec<&str> = kinds().iter().map(|k| k.name).collect();
            UsageError(format!(
                "--kind {name}: unknown kind (expected one of {})",
                names.join(", ")
            ))
        })?),
        None => None,
    };
    let mut files = Vec::new();
    for path in &args.paths {
        if !path.exists() {
            return Err(UsageError(format!("{}: no such file or folder", path.display())).into());
        }
        collect_files(path, &mut files).with_context(|| format!("{}", path.display()))?;
    }
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    let mut problems = 0usize;
    let mut bad_files = 0usize;
    for file in &files {
        let text = match std::fs::read(file) {
            Ok(bytes) => match String::from_utf8(bytes) {
                Ok(text) => text,
                Err(_) => {
                    writeln!(
                        out,
                        "{}: $: is not UTF-8 text (expected JSON)",
                        file.display()
                    )?;
                    problems += 1;
                    bad_files += 1;
                    continue;
                }
            },
            Err(e) => {
                writeln!(out, "{}: cannot read: {e}", file.display())?;
                problems += 1;
                bad_files += 1;
                continue;
            }
        };
        let jsonl = file.extension().is_some_and(|e| e == "jsonl");
        let kind = forced.or_else(|| {
            // Only files without a `schema` field fall back to their well-known names.
            let first_doc = if jsonl {
                text.lines().find(|l| !l.trim().is_empty()).unwrap_or("")
            } else {
                text.as_str()
            };
            let has_schema = mesa_schemas::json::parse_lenient(first_doc)
                .ok()
                .is_some_and(|v| v.get("schema").is_some());
            if has_schema {
                None
            } else {
                kind_from_file_name(file)
            }
        });
        let found = validate_text(&text, kind, jsonl);
        if !found.is_empty() {
            bad_files += 1;
        }
        for located in &found {
            problems += 1;
            match located.line {
                Some(line) if jsonl => {
                    writeln!(out, "{}:{line}: {}", file.display(), located.problem)?
                }
                Some(line) => {
                    writeln!(out, "{}: {} (line {line})", file.display(), located.problem)?
                }
                None => writeln!(out, "{}: {}", file.display(), located.problem)?,
            }
        }
    }
    eprintln!(
        "{} files checked: {} valid, {bad_files} with problems ({problems} problems)",
        files.len(),
        files.len() - bad_files
    );
    Ok(ExitCode::from(if problems == 0 {
        EXIT_OK
    } else {
        EXIT_FAILED
    }))
}

fn convert(args: ConvertArgs) -> anyhow::Result<ExitCode> {
    let layout = match read_any_layout(&args.input) {
        Ok(layout) => layout,
        Err(e) => {
            eprintln!("mesa: {e:#}");
            return Ok(ExitCode::from(EXIT_FAILED));
        }
    };
    const REORDERED: &str = "objects reordered by descending footprint w·d (the input had \
                             another order, which the scene graph's layout order follows; \
                             --keep-order keeps it)";
    let (bytes, warnings) = match (layout, args.to) {
        (AnyLayout::Dataset(dataset), LayoutForm::Llm) => {
            let mut converted = llm_from_dataset(&dataset);
            if !args.keep_order && converted.layout.sort_objects() {
                converted.warnings.push(REORDERED.to_owned());
            }
            (llm_bytes(&converted.layout)?, converted.warnings)
        }
        (AnyLayout::Llm(llm), LayoutForm::Dataset) => {
            let mut converted = dataset_from_llm(&llm);
            if !args.keep_order && converted.layout.sort_objects() {
                converted.warnings.push(REORDERED.to_owned());
            }
            (to_sorted_pretty(&converted.layout)?, converted.warnings)
        }
        (AnyLayout::Llm(mut llm), LayoutForm::Llm) => {
            let reordered = !args.keep_order && llm.sort_objects();
            (
                llm_bytes(&llm)?,
                if reordered {
                    vec![REORDERED.to_owned()]
                } else {
                    vec![]
                },
            )
        }
        (AnyLayout::Dataset(mut dataset), LayoutForm::Dataset) => {
            let reordered = !args.keep_order && dataset.sort_objects();
            (
                to_sorted_pretty(&dataset)?,
                if reordered {
                    vec![REORDERED.to_owned()]
                } else {
                    vec![]
                },
            )
        }
    };
    for warning in &warnings {
        eprintln!("warning: {}: {warning}", args.input.display());
    }
    match &args.output {
        Some(path) => write_atomic(path, &bytes)
            .with_context(|| format!("{}: cannot write", path.display()))?,
        None => std::io::stdout().write_all(&bytes)?,
    }
    Ok(ExitCode::SUCCESS)
}

/// An LLM layout as pretty JSON in the published key order, with a trailing newline.
pub fn llm_bytes(layout: &mesa_schemas::LlmLayout) -> anyhow::Result<Vec<u8>> {
    let mut bytes = serde_json::to_vec_pretty(layout)?;
    bytes.push(b'\n');
    Ok(bytes)
}

fn parse_output(args: ParseOutputArgs) -> anyhow::Result<ExitCode> {
    let text = std::fs::read_to_string(&args.file)
        .with_context(|| format!("{}: cannot read", args.file.display()))?;
    match parse_model_output(&text) {
        Ok(parsed) => {
            std::io::stdout().write_all(&llm_bytes(&parsed.layout)?)?;
            eprintln!(
                "{}: success: {} objects, {} scene-graph lines, reasoning of {} characters",
                args.file.display(),
                parsed.layout.objects.len(),
                parsed.graph_lines.len(),
                parsed.reasoning.chars().count()
            );
            for dropped in &parsed.dropped_objects {
                eprintln!("{}: dropped {dropped}", args.file.display());
            }
            Ok(ExitCode::SUCCESS)
        }
        Err(e) => {
            eprintln!("{}: not a success: {e}", args.file.display());
            Ok(ExitCode::from(EXIT_FAILED))
        }
    }
}
