//! `mesa annotate assets`: the asset library's annotations (category, description, onTable,
//! mass, frontView, isContainer, materials) from a vision-language model shown four renders
//! of each asset (live or through offline batches, through the reply cache of `mesa tasks`),
//! or from the offline placeholder ([`mesa_stages::annotate::offline`]); merged into
//! `assets/annotations.json` without touching a person's fields, each field's source recorded
//! ([`mesa_stages::annotate`]).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;

use anyhow::{anyhow, Context as _};
use clap::{Args as ClapArgs, Subcommand, ValueEnum};
use mesa_schemas::annotate::{
    AnnotateReject, AnnotateSummary, ANNOTATE_REJECT_SCHEMA, ANNOTATE_SUMMARY_SCHEMA,
};
use mesa_schemas::artifacts::InstanceEntry;
use mesa_schemas::artifacts::{AssetIndexArtifact, AssetRecord};
use mesa_schemas::json::{parse_lenient, to_sorted_line, to_sorted_pretty};
use mesa_stages::annotate::instances::{
    instance_fields_to_annotate, instance_placeholder, instance_prompt, instance_request,
    merge_instance, validate_instance_reply, INSTANCE_FIELDS, INSTANCE_PROMPT,
    INSTANCE_PROMPT_FILE,
};
use mesa_stages::annotate::offline::{asset_names, hollowness, material_names, placeholder_fields};
use mesa_stages::annotate::{
    asset_prompt, asset_request, count_sources, fields_to_annotate, front_view_of_file,
    merge_entry, parse_taxonomy, validate_asset_reply, AnnotateBackend, AnnotationsConfig,
    AssetFields, AssetInput, ASSET_PROMPT, ASSET_PROMPT_FILE, VIEW_AZIMUTHS_DEG,
};
use mesa_stages::annotations::Annotations;
use mesa_stages::lift::inputs::{read_masks, read_png, PngLimit};
use mesa_stages::pack::snapshot::{snapshot_png, Margin, Photo};
use mesa_stages::paths::dataset::{
    asset_glb, ANNOTATE_REJECTS, ANNOTATE_SUMMARY, ANNOTATIONS, ASSET_RENDERS, INDEX,
    INSTANCE_REJECTS,
};
use mesa_stages::paths::scene::INSTANCES;
use mesa_stages::tasks::chat::{Chat, ChatError, ChatRequest, View};
use mesa_stages::tasks::prompts::PromptTemplate;
use serde_json::{json, Value};

use crate::chat::{
    custom_id, import_batch_files, pending_by_id, request_digest, write_batch, ChatClient, Mode,
};
use crate::cli::{DatasetArgs, Global, SceneArgs};
use crate::exit::{usage, UsageError};
use crate::fsio::{
    read_bounded, read_json, read_text_bounded, write_atomic, GLB_LIMIT, JSON_LIMIT,
};
use crate::progress::Tick;
use crate::runner::{
    discover_scenes, select_scenes, DatasetReport, DatasetStage, Executor, RunError, Scene,
    StageContext,
};

/// `mesa annotate`.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// What to annotate.
    #[command(subcommand)]
    pub what: What,
}

/// What `mesa annotate` annotates.
#[derive(Debug, Subcommand)]
pub enum What {
    /// The library's assets without an annotation (or whose fields are missing, or hold the
    /// offline placeholder when a model annotates): category, description, onTable, mass,
    /// frontView, isContainer, materials, merged into assets/annotations.json with the source
    /// of every field (a person's fields are never changed). Needs `mesa assets` first.
    Assets(AssetsArgs),
    /// Each scene's photo instances lacking a label or a description (input/instances.json):
    /// the model is shown the instance's crop (the pack's snapshot) and the whole photo; the
    /// fields are written back with their source (a person's text is never changed).
    Instances(InstancesArgs),
}

/// `--backend`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum BackendArg {
    /// The placeholder from the asset's names and geometry (no model; marked as such).
    Offline,
    /// The chat endpoint of [annotations.llm] (its API key from the variable api_key_env
    /// names).
    Llm,
}

/// `mesa annotate assets`.
#[derive(Debug, ClapArgs)]
pub struct AssetsArgs {
    /// The dataset and its run flags.
    #[command(flatten)]
    pub common: DatasetArgs,
    /// Annotate every asset again (fields mesa wrote are replaced; a person's fields are
    /// still kept).
    #[arg(long)]
    pub force: bool,
    /// The backend (default: [annotations] backend of mesa.toml).
    #[arg(long, value_enum)]
    pub backend: Option<BackendArg>,
    /// Only assets whose uid matches this glob.
    #[arg(long, value_name = "GLOB")]
    pub uids: Option<String>,
    /// Offline batches: write the requests still unanswered to FILE as OpenAI Batch JSONL
    /// (one request per asset, its four views as data URLs; implies --backend llm).
    #[arg(long, value_name = "FILE")]
    pub batch_out: Option<PathBuf>,
    /// Offline batches: read a provider's batch output JSONL (repeatable); replies are joined
    /// to requests by custom_id and stored in the reply cache (implies --backend llm).
    #[arg(long, value_name = "FILE")]
    pub batch_in: Vec<PathBuf>,
}

/// Runs `mesa annotate`.
pub fn run(args: Args, global: Global) -> anyhow::Result<ExitCode> {
    match args.what {
        What::Assets(args) => run_assets(args, global),
        What::Instances(args) => run_instances(args, global),
    }
}

fn run_assets(args: AssetsArgs, global: Global) -> anyhow::Result<ExitCode> {
    let mut resolved = args.common.resolve(global)?;
    let batch = args.batch_out.is_some() || !args.batch_in.is_empty();
    if batch && args.backend == Some(BackendArg::Offline) {
        return Err(usage(
            "--batch-out and --batch-in are for the llm backend (not --backend offline)",
        ));
    }
    let config = &mut resolved.config.annotations;
    if let Some(backend) = args.backend {
        config.backend = match backend {
            BackendArg::Offline => AnnotateBackend::Offline,
            BackendArg::Llm => AnnotateBackend::Llm,
        };
    }
    if batch {
        config.backend = AnnotateBackend::Llm;
    }
    let problems = config.problems();
    if !problems.is_empty() {
        return Err(usage(problems.join("\n")));
    }
    let (template, taxonomy) = load_inputs(&resolved.dataset, config).map_err(UsageError)?;
    let client = match config.backend {
        AnnotateBackend::Offline => None,
        AnnotateBackend::Llm => {
            let mode = if batch { Mode::CacheOnly } else { Mode::Live };
            let client = ChatClient::new(&resolved.dataset, &config.llm, mode)
                .map_err(|e| UsageError(e.replace("[tasks.llm]", "[annotations.llm]")))?;
            if !batch && args.common.jobs.is_none() {
                // Assets wait on the network, not the CPU.
                resolved.options.jobs = config.llm.max_concurrency;
            }
            Some(Arc::new(client))
        }
    };
    let stage = AnnotateAssetsStage {
        force: args.force,
        uids: args.uids,
        batch_out: args.batch_out,
        batch_in: args.batch_in,
        chat: client.clone().map(|c| c as Arc<dyn Chat + Send + Sync>),
        client: client.clone(),
        template,
        taxonomy,
    };
    let code = resolved.run_dataset(&stage)?;
    if let Some(client) = client {
        eprintln!(
            "annotate assets: {}: {}",
            resolved.config.annotations.llm.model,
            client.stats.summary()
        );
        for warning in client.warnings() {
            eprintln!("annotate assets: warning: {warning}");
        }
    }
    Ok(code)
}

/// The prompt (`[annotations] prompts_dir`, else the built-in one) and the taxonomy
/// (`[annotations] categories`, else free text). Errors name the file and the key.
pub fn load_inputs(
    dataset: &Path,
    config: &AnnotationsConfig,
) -> Result<(PromptTemplate, Vec<String>), String> {
    let template = if config.prompts_dir.is_empty() {
        asset_prompt(&format!("built-in {ASSET_PROMPT_FILE}"), ASSET_PROMPT)
    } else {
        let path = dataset.join(&config.prompts_dir).join(ASSET_PROMPT_FILE);
        let text = std::fs::read_to_string(&path).map_err(|e| {
            format!(
                "[annotations] prompts_dir: {}: cannot read: {e} (expected the folder to hold \
                 {ASSET_PROMPT_FILE}; copy data/prompts/{ASSET_PROMPT_FILE} there to edit it)",
                path.display()
            )
        })?;
        asset_prompt(&path.display().to_string(), &text)
    }
    .map_err(|e| format!("[annotations] prompts_dir: {e}"))?;
    let taxonomy = if config.categories.is_empty() {
        Vec::new()
    } else {
        let path = dataset.join(&config.categories);
        let text = std::fs::read_to_string(&path).map_err(|e| {
            format!(
                "[annotations] categories: {}: cannot read: {e} (expected a text file with one \
                 category per line, relative to the dataset folder, or \"\" for free text)",
                path.display()
            )
        })?;
        let taxonomy = parse_taxonomy(&text);
        if taxonomy.is_empty() {
            return Err(format!(
                "[annotations] categories: {}: no category in it (expected one per line)",
                path.display()
            ));
        }
        taxonomy
    };
    Ok((template, taxonomy))
}

/// The `mesa annotate assets` stage.
pub struct AnnotateAssetsStage {
    force: bool,
    uids: Option<String>,
    batch_out: Option<PathBuf>,
    batch_in: Vec<PathBuf>,
    chat: Option<Arc<dyn Chat + Send + Sync>>,
    client: Option<Arc<ChatClient>>,
    template: PromptTemplate,
    taxonomy: Vec<String>,
}

/// An asset to annotate.
struct Target<'a> {
    uid: &'a str,
    record: &'a AssetRecord,
    fields: Vec<&'static str>,
}

/// What annotating one asset gave.
enum Outcome {
    Done(AssetFields),
    Pending(Box<ChatRequest>),
    Failed(String),
}

/// One asset's outcome with what it cost.
struct Annotated {
    outcome: Outcome,
    rejects: Vec<AnnotateReject>,
    requests: u64,
    text_tokens: u64,
}

impl Annotated {
    fn failed(why: String) -> Self {
        Self {
            outcome: Outcome::Failed(why),
            rejects: Vec::new(),
            requests: 0,
            text_tokens: 0,
        }
    }
}

/// The files of the four views sent (0°, 90°, 180°, 270°), relative to the dataset.
pub fn view_files(uid: &str) -> Vec<String> {
    VIEW_AZIMUTHS_DEG
        .iter()
        .map(|deg| format!("{ASSET_RENDERS}/{uid}/view_{deg:03}.png"))
        .collect()
}

/// Text tokens of a request's messages, estimated as characters / 4 (rounded up).
fn text_tokens(request: &ChatRequest) -> u64 {
    let mut chars = 0usize;
    for message in request.body["messages"].as_array().into_iter().flatten() {
        match &message["content"] {
            Value::String(text) => chars += text.chars().count(),
            Value::Array(parts) => {
                for part in parts {
                    if let Some(text) = part["text"].as_str() {
                        chars += text.chars().count();
                    }
                }
            }
            _ => {}
        }
    }
    chars.div_ceil(4) as u64
}

/// Asks the model for `key` up to `[annotations] max_attempts` times (the seed plus the
/// attempt), until a reply passes `validate`; rejected replies are kept with their reasons.
fn ask(
    chat: &(dyn Chat + Send + Sync),
    config: &AnnotationsConfig,
    key: &str,
    request: impl Fn(u32) -> Result<ChatRequest, String>,
    validate: impl Fn(&str) -> Result<AssetFields, Vec<String>>,
    rejects_file: &str,
) -> Annotated {
    let source = config.source();
    let mut done = Annotated {
        outcome: Outcome::Failed(String::new()),
        rejects: Vec::new(),
        requests: 0,
        text_tokens: 0,
    };
    for attempt in 0..config.max_attempts {
        let request = match request(attempt) {
            Ok(request) => request,
            Err(e) => {
                done.outcome = Outcome::Failed(e);
                return done;
            }
        };
        done.requests += 1;
        done.text_tokens += text_tokens(&request);
        let reply = match chat.complete(&request) {
            Ok(reply) => reply,
            Err(ChatError::Pending(request)) => {
                done.outcome = Outcome::Pending(request);
                return done;
            }
            Err(ChatError::Failed(why)) => {
                done.outcome = Outcome::Failed(why);
                return done;
            }
        };
        let mut checked = validate(&reply.content);
        if reply.finish_reason.as_deref() == Some("length") {
            let cut = "the reply was cut at max_tokens ([annotations.llm] max_tokens)".to_owned();
            checked = Err(match checked {
                Ok(_) => vec![cut],
                Err(mut reasons) => {
                    reasons.push(cut);
                    reasons
                }
            });
        }
        match checked {
            Ok(fields) => {
                done.outcome = Outcome::Done(fields);
                return done;
            }
            Err(reasons) => done.rejects.push(AnnotateReject {
                schema: ANNOTATE_REJECT_SCHEMA.to_owned(),
                uid: key.to_owned(),
                attempt,
                source: source.clone(),
                request_sha256: request_digest(&request),
                reasons,
                reply: reply.content,
                redacted: reply.redacted,
            }),
        }
    }
    done.outcome = Outcome::Failed(format!(
        "every one of the {} replies was rejected (their reasons are in {rejects_file})",
        config.max_attempts
    ));
    done
}

impl AnnotateAssetsStage {
    fn config<'a>(&self, ctx: &'a StageContext<'_>) -> &'a AnnotationsConfig {
        &ctx.config.annotations
    }

    fn annotate_one(&self, ctx: &StageContext<'_>, target: &Target<'_>) -> Annotated {
        let config = self.config(ctx);
        let uid = target.uid;
        let path = ctx.dataset.join(asset_glb(uid));
        let glb = match read_bounded(&path, GLB_LIMIT) {
            Ok(bytes) => bytes,
            Err(e) => return Annotated::failed(format!("{}: cannot read: {e}", path.display())),
        };
        let names = match asset_names(&glb) {
            Ok(names) => names,
            Err(e) => return Annotated::failed(format!("{}: {e}", path.display())),
        };
        let Some(geometry) = target.record.geometry.as_ref() else {
            return Annotated::failed(format!(
                "{uid}: the index has no geometry (run `mesa assets`)"
            ));
        };
        let extents = geometry.gltf_extents_m;
        let Some(chat) = &self.chat else {
            let hollow = match mesa_stages::glb_read::read_glb(&glb) {
                Ok(mesh) => hollowness(&mesh),
                Err(e) => return Annotated::failed(format!("{}: {e}", path.display())),
            };
            let materials = material_names(&glb).unwrap_or_default();
            return Annotated {
                outcome: Outcome::Done(placeholder_fields(
                    &names,
                    &materials,
                    extents,
                    hollow,
                    &self.taxonomy,
                )),
                rejects: Vec::new(),
                requests: 0,
                text_tokens: 0,
            };
        };
        let mut views = Vec::new();
        for (deg, file) in VIEW_AZIMUTHS_DEG.iter().zip(view_files(uid)) {
            match read_bounded(&ctx.dataset.join(&file), JSON_LIMIT) {
                Ok(png) => views.push(View {
                    name: format!("view_{deg:03}"),
                    file,
                    png,
                }),
                Err(e) => {
                    return Annotated::failed(format!(
                        "{file}: cannot read the view: {e} (`mesa render --assets` writes it)"
                    ))
                }
            }
        }
        let input = AssetInput {
            uid: uid.to_owned(),
            names,
            gltf_extents_m: extents,
            views,
        };
        let yaw = geometry.front_yaw_deg;
        ask(
            chat.as_ref(),
            config,
            uid,
            |attempt| {
                asset_request(&self.template, config, &self.taxonomy, &input, attempt)
                    .map_err(|e| e.to_string())
            },
            |content| {
                let mut fields = validate_asset_reply(content, &input, &self.taxonomy, config)?;
                // The views show the asset turned by the index's front yaw.
                if let Some(k) = fields.get("frontView").and_then(Value::as_u64) {
                    fields.insert("frontView".into(), json!(front_view_of_file(k, yaw)));
                }
                Ok(fields)
            },
            ANNOTATE_REJECTS,
        )
    }

    fn annotate_all(
        &self,
        ctx: &StageContext<'_>,
        exec: &Executor<'_>,
        targets: &[Target<'_>],
    ) -> Vec<Annotated> {
        exec.map_ticked(
            "assets",
            targets,
            |target| self.annotate_one(ctx, target),
            |done| match done.outcome {
                Outcome::Done(_) => Tick::Done,
                Outcome::Pending(_) => Tick::Skipped,
                Outcome::Failed(_) => Tick::Failed,
            },
        )
    }
}

impl DatasetStage for AnnotateAssetsStage {
    fn name(&self) -> &'static str {
        "annotate-assets"
    }

    fn run(&self, ctx: &StageContext<'_>, exec: &Executor<'_>) -> anyhow::Result<DatasetReport> {
        let started = std::time::Instant::now();
        let config = self.config(ctx);
        let index: AssetIndexArtifact =
            read_json(&ctx.dataset.join(INDEX), "run `mesa assets` to write it")?;
        let annotations_path = ctx.dataset.join(ANNOTATIONS);
        let (original_text, mut document) = if annotations_path.exists() {
            let text = read_text_bounded(&annotations_path, JSON_LIMIT)
                .with_context(|| format!("{}: cannot read", annotations_path.display()))?;
            // The reader of `mesa assets` and `mesa retrieve` must accept the file first.
            Annotations::parse(&text)
                .map_err(|e| anyhow!("{}: {e}", annotations_path.display()))?;
            let value =
                parse_lenient(&text).map_err(|e| anyhow!("{}: {e}", annotations_path.display()))?;
            (Some(text), value)
        } else {
            (None, json!({}))
        };
        let matcher = match &self.uids {
            Some(glob) => Some(
                globset::Glob::new(glob)
                    .map_err(|e| {
                        UsageError(format!(
                            "--uids \"{glob}\": {} (expected a glob like \"a3*\")",
                            e.kind()
                        ))
                    })?
                    .compile_matcher(),
            ),
            None => None,
        };
        let source = config.source();
        let mut summary = AnnotateSummary {
            schema: ANNOTATE_SUMMARY_SCHEMA.to_owned(),
            source: source.clone(),
            ..AnnotateSummary::default()
        };
        let mut targets = Vec::new();
        for (uid, record) in &index.assets {
            if !record.valid || matcher.as_ref().is_some_and(|m| !m.is_match(uid)) {
                continue;
            }
            summary.assets += 1;
            let fields = fields_to_annotate(document.get(uid), &source, self.force);
            if !fields.is_empty() {
                targets.push(Target {
                    uid,
                    record,
                    fields,
                });
            }
        }
        summary.targets = targets.len() as u64;
        let mut notes = Vec::new();
        if self.chat.is_some() && !targets.is_empty() {
            let wanted: BTreeSet<&str> = targets.iter().map(|t| t.uid).collect();
            let views = crate::commands::render::render_asset_views_of(
                ctx.dataset,
                ctx.config,
                |uid| wanted.contains(uid),
                exec,
            )?;
            notes.push(format!(
                "views: {} rendered, {} current",
                views.rendered, views.skipped
            ));
        }
        let mut outcomes = self.annotate_all(ctx, exec, &targets);
        let mut failed_lines = 0usize;
        if !self.batch_in.is_empty() {
            let by_id: BTreeMap<String, String> = outcomes
                .iter()
                .filter_map(|a| match &a.outcome {
                    Outcome::Pending(request) => {
                        let digest = request_digest(request);
                        Some((custom_id(&digest), digest))
                    }
                    _ => None,
                })
                .collect();
            let client = self
                .client
                .as_ref()
                .ok_or_else(|| anyhow!("internal error: batches without a chat client"))?;
            let imported = import_batch_files(&self.batch_in, &by_id, client.cache())?;
            notes.extend(imported.lines);
            failed_lines += imported.failed;
            outcomes = self.annotate_all(ctx, exec, &targets);
        }
        let pending: Vec<ChatRequest> = outcomes
            .iter()
            .filter_map(|a| match &a.outcome {
                Outcome::Pending(request) => Some((**request).clone()),
                _ => None,
            })
            .collect();
        match &self.batch_out {
            Some(path) if !pending.is_empty() => {
                let lines = write_batch(path, &pending)
                    .with_context(|| format!("{}: cannot write", path.display()))?;
                notes.push(format!(
                    "{lines} requests written to {} (OpenAI Batch JSONL; read the provider's \
                     output with --batch-in)",
                    path.display()
                ));
            }
            Some(path) => notes.push(format!(
                "no request is pending, so {} was not written",
                path.display()
            )),
            None => {}
        }
        // The merge, in uid order.
        let entries = document
            .as_object_mut()
            .ok_or_else(|| anyhow!("{}: not a JSON object", annotations_path.display()))?;
        let mut rejects = Vec::new();
        for (target, annotated) in targets.iter().zip(outcomes) {
            summary.requests += annotated.requests;
            summary.prompt_text_tokens += annotated.text_tokens;
            summary.rejected_replies += annotated.rejects.len() as u64;
            rejects.extend(annotated.rejects);
            match annotated.outcome {
                Outcome::Done(fields) => {
                    let extents = target
                        .record
                        .geometry
                        .as_ref()
                        .map_or([0.0; 3], |g| g.gltf_extents_m);
                    let merged = merge_entry(
                        entries.get(target.uid),
                        &fields,
                        &target.fields,
                        &source,
                        extents,
                    );
                    entries.insert(target.uid.to_owned(), merged);
                    summary.annotated.push(target.uid.to_owned());
                }
                Outcome::Pending(_) => summary.pending.push(target.uid.to_owned()),
                Outcome::Failed(why) => {
                    summary.failed.insert(target.uid.to_owned(), why);
                }
            }
        }
        let new_text = String::from_utf8(to_sorted_pretty(&document)?)?;
        let changed = match &original_text {
            Some(text) => parse_lenient(text).ok().as_ref() != Some(&document),
            None => !summary.annotated.is_empty(),
        };
        if changed {
            // What is written must read back as annotations.
            Annotations::parse(&new_text)
                .map_err(|e| anyhow!("internal error: the merged annotations: {e}"))?;
            write_atomic(&annotations_path, new_text.as_bytes())
                .with_context(|| format!("{}: cannot write", annotations_path.display()))?;
        }
        notes.extend(write_rejects(ctx.dataset, ANNOTATE_REJECTS, &rejects)?);
        let (by_source, placeholders) = count_sources(&document);
        summary.fields_by_source = by_source;
        summary.placeholder_assets = placeholders;
        let summary_path = ctx.dataset.join(ANNOTATE_SUMMARY);
        write_atomic(&summary_path, &to_sorted_pretty(&summary)?)
            .with_context(|| format!("{}: cannot write", summary_path.display()))?;
        let elapsed_s = started.elapsed().as_secs_f64();
        let text = format_summary(&summary, changed, &notes, elapsed_s);
        let mut record = serde_json::to_value(&summary)?;
        record["elapsed_s"] = json!(elapsed_s);
        Ok(DatasetReport {
            success: summary.failed.is_empty() && failed_lines == 0,
            text,
            record,
        })
    }
}

/// Writes this run's rejected replies to `rel`, or, when it has none, removes the file an
/// earlier run wrote: as the runner removes a scene output its last run wrote and this one
/// does not, so that the file always holds the last run's rejects and never stale ones.
/// Returns the note saying a file was removed.
fn write_rejects(
    dataset: &Path,
    rel: &str,
    rejects: &[AnnotateReject],
) -> anyhow::Result<Option<String>> {
    let path = dataset.join(rel);
    if rejects.is_empty() {
        return match std::fs::remove_file(&path) {
            Ok(()) => Ok(Some(format!(
                "removed {rel}, which the last run wrote and this one does not (no reply was \
                 rejected; it would be stale)"
            ))),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(e).with_context(|| {
                format!(
                    "{}: cannot remove the rejects of the last run (remove it by hand)",
                    path.display()
                )
            }),
        };
    }
    let mut lines = String::new();
    for reject in rejects {
        lines.push_str(&to_sorted_line(reject)?);
        lines.push('\n');
    }
    write_atomic(&path, lines.as_bytes())
        .with_context(|| format!("{}: cannot write", path.display()))?;
    Ok(None)
}

fn format_summary(
    summary: &AnnotateSummary,
    changed: bool,
    notes: &[String],
    elapsed_s: f64,
) -> String {
    use std::fmt::Write as _;
    let mut out = format!(
        "annotate assets: {} assets, {} to annotate ({}): {} annotated, {} pending, {} failed, \
         {} replies rejected, {} requests in {elapsed_s:.2} s\n",
        summary.assets,
        summary.targets,
        summary.source,
        summary.annotated.len(),
        summary.pending.len(),
        summary.failed.len(),
        summary.rejected_replies,
        summary.requests,
    );
    for note in notes {
        let _ = writeln!(out, "  {note}");
    }
    let mut sources: Vec<String> = summary
        .fields_by_source
        .iter()
        .map(|(source, n)| format!("{n} {source}"))
        .collect();
    if sources.is_empty() {
        sources.push("none".to_owned());
    }
    let _ = writeln!(
        out,
        "  {ANNOTATIONS}: {} (fields by source: {}; {} assets hold placeholder fields)",
        if changed { "updated" } else { "unchanged" },
        sources.join(", "),
        summary.placeholder_assets
    );
    if summary.rejected_replies > 0 {
        let _ = writeln!(out, "  rejected replies are in {ANNOTATE_REJECTS}");
    }
    if !summary.pending.is_empty() {
        let _ = writeln!(
            out,
            "  {} assets wait for replies (write the next batch with --batch-out FILE)",
            summary.pending.len()
        );
    }
    for (uid, why) in &summary.failed {
        let _ = writeln!(out, "  failed {uid}: {why}");
    }
    out
}

// ---------------------------------------------------------------------------------------------
// Instances

/// `mesa annotate instances`.
#[derive(Debug, ClapArgs)]
pub struct InstancesArgs {
    /// The runner flags (--scenes, --shard, --force: annotate again the fields mesa wrote).
    #[command(flatten)]
    pub stage: SceneArgs,
    /// The backend (default: [annotations] backend of mesa.toml).
    #[arg(long, value_enum)]
    pub backend: Option<BackendArg>,
    /// Offline batches: write the requests still unanswered to FILE as OpenAI Batch JSONL
    /// (one request per instance, its crop and the photo as data URLs; implies --backend llm).
    #[arg(long, value_name = "FILE")]
    pub batch_out: Option<PathBuf>,
    /// Offline batches: read a provider's batch output JSONL (repeatable; implies --backend
    /// llm).
    #[arg(long, value_name = "FILE")]
    pub batch_in: Vec<PathBuf>,
}

fn run_instances(args: InstancesArgs, global: Global) -> anyhow::Result<ExitCode> {
    let mut resolved = args.stage.resolve(global)?;
    let batch = args.batch_out.is_some() || !args.batch_in.is_empty();
    if batch && args.backend == Some(BackendArg::Offline) {
        return Err(usage(
            "--batch-out and --batch-in are for the llm backend (not --backend offline)",
        ));
    }
    let config = &mut resolved.config.annotations;
    if let Some(backend) = args.backend {
        config.backend = match backend {
            BackendArg::Offline => AnnotateBackend::Offline,
            BackendArg::Llm => AnnotateBackend::Llm,
        };
    }
    if batch {
        config.backend = AnnotateBackend::Llm;
    }
    let problems = config.problems();
    if !problems.is_empty() {
        return Err(usage(problems.join("\n")));
    }
    let template = load_prompt(
        &resolved.dataset,
        config,
        INSTANCE_PROMPT_FILE,
        INSTANCE_PROMPT,
        instance_prompt,
    )
    .map_err(UsageError)?;
    let client = match config.backend {
        AnnotateBackend::Offline => None,
        AnnotateBackend::Llm => {
            let mode = if batch { Mode::CacheOnly } else { Mode::Live };
            let client = ChatClient::new(&resolved.dataset, &config.llm, mode)
                .map_err(|e| UsageError(e.replace("[tasks.llm]", "[annotations.llm]")))?;
            if !batch && args.stage.common.jobs.is_none() {
                resolved.options.jobs = config.llm.max_concurrency;
            }
            Some(Arc::new(client))
        }
    };
    let stage = AnnotateInstancesStage {
        chat: client.clone().map(|c| c as Arc<dyn Chat + Send + Sync>),
        client: client.clone(),
        batch_out: args.batch_out,
        batch_in: args.batch_in,
        template,
    };
    let code = resolved.run_dataset(&stage)?;
    if let Some(client) = client {
        eprintln!(
            "annotate instances: {}: {}",
            resolved.config.annotations.llm.model,
            client.stats.summary()
        );
    }
    Ok(code)
}

/// A prompt of `[annotations] prompts_dir` (`file`), else the built-in `builtin`.
fn load_prompt(
    dataset: &Path,
    config: &AnnotationsConfig,
    file: &str,
    builtin: &str,
    parse: fn(&str, &str) -> Result<PromptTemplate, mesa_stages::tasks::prompts::PromptError>,
) -> Result<PromptTemplate, String> {
    if config.prompts_dir.is_empty() {
        return parse(&format!("built-in {file}"), builtin)
            .map_err(|e| format!("[annotations] prompts_dir: {e}"));
    }
    let path = dataset.join(&config.prompts_dir).join(file);
    let text = std::fs::read_to_string(&path).map_err(|e| {
        format!(
            "[annotations] prompts_dir: {}: cannot read: {e} (expected the folder to hold \
             {file}; copy data/prompts/{file} there to edit it)",
            path.display()
        )
    })?;
    parse(&path.display().to_string(), &text).map_err(|e| format!("[annotations] prompts_dir: {e}"))
}

/// The `mesa annotate instances` stage: scenes in parallel, each scene's instances in turn.
pub struct AnnotateInstancesStage {
    chat: Option<Arc<dyn Chat + Send + Sync>>,
    client: Option<Arc<ChatClient>>,
    batch_out: Option<PathBuf>,
    batch_in: Vec<PathBuf>,
    template: PromptTemplate,
}

/// What annotating one scene's instances gave.
#[derive(Default)]
struct SceneAnnotated {
    annotated: u64,
    failed: Vec<(String, String)>,
    rejects: Vec<AnnotateReject>,
    pending: Vec<ChatRequest>,
    requests: u64,
    text_tokens: u64,
    written: bool,
}

impl AnnotateInstancesStage {
    fn scene(
        &self,
        ctx: &StageContext<'_>,
        scene: &Scene,
        force: bool,
    ) -> anyhow::Result<SceneAnnotated> {
        let config = &ctx.config.annotations;
        let source = config.source();
        let path = scene.path(INSTANCES);
        let text = read_text_bounded(&path, JSON_LIMIT)
            .with_context(|| format!("{}: cannot read (the user writes it)", path.display()))?;
        let mut document = parse_lenient(&text).map_err(|e| anyhow!("{}: {e}", path.display()))?;
        let entries = document
            .get_mut("instances")
            .and_then(Value::as_array_mut)
            .ok_or_else(|| {
                anyhow!(
                    "{}: $.instances: missing (expected {{\"instances\": [...]}})",
                    path.display()
                )
            })?;
        let targets: Vec<(usize, Vec<&'static str>)> = entries
            .iter()
            .enumerate()
            .map(|(i, e)| (i, instance_fields_to_annotate(e, &source, force)))
            .filter(|(_, fields)| !fields.is_empty())
            .collect();
        let mut out = SceneAnnotated::default();
        if targets.is_empty() {
            return Ok(out);
        }
        // The photo and the masks, read as `mesa lift` and `mesa pack` read them.
        let input = scene.path("input");
        let photo_path = input.join("image.png");
        let photo_png = read_bounded(&photo_path, GLB_LIMIT).with_context(|| {
            format!("{}: cannot read (the user writes it)", photo_path.display())
        })?;
        let image = read_png(
            &photo_path,
            PngLimit::MaxPixels(ctx.config.lift.max_image_pixels),
        )?
        .into_rgb8();
        let photo = Photo {
            width: image.width() as usize,
            height: image.height() as usize,
            rgb: image.pixels().map(|p| p.0).collect(),
        };
        let typed: Vec<InstanceEntry> = entries
            .iter()
            .map(|e| {
                let mut e = e.clone();
                if let Some(o) = e.as_object_mut() {
                    for field in INSTANCE_FIELDS {
                        o.entry(field).or_insert(json!(""));
                    }
                }
                serde_json::from_value(e)
            })
            .collect::<Result<_, _>>()
            .map_err(|e| anyhow!("{}: $.instances: {e}", path.display()))?;
        let masks = read_masks(&input, &typed, photo.width, photo.height)?;
        let margin = Margin {
            fraction: ctx.config.pack.snapshot_margin,
            min_px: ctx.config.pack.snapshot_min_margin_px,
        };
        for (i, fields) in targets {
            let id = typed[i].id;
            let key = format!("{}#{id}", scene.key());
            let pixels = masks.pixels.get(&id).map(Vec::as_slice).unwrap_or_default();
            let annotated = match &self.chat {
                None => {
                    let mask_box = pixels.iter().fold(None, |b: Option<[usize; 4]>, p| {
                        let (u, v) = (*p as usize % photo.width, *p as usize / photo.width);
                        Some(match b {
                            None => [u, v, u, v],
                            Some([u0, v0, u1, v1]) => [u0.min(u), v0.min(v), u1.max(u), v1.max(v)],
                        })
                    });
                    Annotated {
                        outcome: Outcome::Done(instance_placeholder(
                            &entries[i],
                            mask_box,
                            [photo.width, photo.height],
                        )),
                        rejects: Vec::new(),
                        requests: 0,
                        text_tokens: 0,
                    }
                }
                Some(chat) => {
                    let Some(crop) = snapshot_png(&photo, pixels, margin)? else {
                        out.failed.push((
                            key,
                            format!("mask {id} is empty: nothing to show the model"),
                        ));
                        continue;
                    };
                    let entry = entries[i].clone();
                    ask(
                        chat.as_ref(),
                        config,
                        &key,
                        |attempt| {
                            instance_request(
                                &self.template,
                                config,
                                &scene.table_type,
                                &entry,
                                View {
                                    name: format!("instance_{id}"),
                                    file: format!("pack/snapshots/instance_{id}.png"),
                                    png: crop.clone(),
                                },
                                View {
                                    name: "photo".to_owned(),
                                    file: "input/image.png".to_owned(),
                                    png: photo_png.clone(),
                                },
                                attempt,
                            )
                            .map_err(|e| e.to_string())
                        },
                        validate_instance_reply,
                        INSTANCE_REJECTS,
                    )
                }
            };
            out.requests += annotated.requests;
            out.text_tokens += annotated.text_tokens;
            out.rejects.extend(annotated.rejects);
            match annotated.outcome {
                Outcome::Done(values) => {
                    merge_instance(&mut entries[i], &values, &fields, &source);
                    out.annotated += 1;
                }
                Outcome::Pending(request) => out.pending.push(*request),
                Outcome::Failed(why) => out.failed.push((key, why)),
            }
        }
        if out.annotated > 0 {
            write_atomic(&path, &to_sorted_pretty(&document)?)
                .with_context(|| format!("{}: cannot write", path.display()))?;
            out.written = true;
        }
        Ok(out)
    }
}

impl DatasetStage for AnnotateInstancesStage {
    fn name(&self) -> &'static str {
        "annotate-instances"
    }

    fn run(&self, ctx: &StageContext<'_>, exec: &Executor<'_>) -> anyhow::Result<DatasetReport> {
        use std::fmt::Write as _;
        let started = std::time::Instant::now();
        let options = exec.options();
        let scenes = select_scenes(
            discover_scenes(ctx.dataset).map_err(RunError::into_anyhow)?,
            options.scenes.as_deref(),
            options.shard,
        )
        .map_err(RunError::into_anyhow)?;
        let (mut annotated, mut requests, mut tokens, mut written) = (0, 0, 0, 0);
        let mut failed = Vec::new();
        // By (instance, attempt): a second pass re-reads the replies of the first.
        let mut rejects: BTreeMap<(String, u32), AnnotateReject> = BTreeMap::new();
        let mut notes = Vec::new();
        let mut failed_lines = 0usize;
        let passes = if self.batch_in.is_empty() { 1 } else { 2 };
        let mut pending: Vec<ChatRequest> = Vec::new();
        for pass in 0..passes {
            if pass == 1 {
                let by_id = pending_by_id(pending.iter());
                let client = self
                    .client
                    .as_ref()
                    .ok_or_else(|| anyhow!("internal error: batches without a chat client"))?;
                let imported = import_batch_files(&self.batch_in, &by_id, client.cache())?;
                notes.extend(imported.lines);
                failed_lines += imported.failed;
            }
            let results = exec.map("scenes", &scenes, |scene| {
                self.scene(ctx, scene, options.force)
            });
            pending.clear();
            for (scene, result) in scenes.iter().zip(results) {
                match result {
                    Ok(r) => {
                        annotated += r.annotated;
                        requests += r.requests;
                        tokens += r.text_tokens;
                        written += u64::from(r.written);
                        pending.extend(r.pending);
                        if pass + 1 == passes {
                            failed.extend(r.failed);
                        }
                        for reject in r.rejects {
                            rejects.insert((reject.uid.clone(), reject.attempt), reject);
                        }
                    }
                    Err(e) if pass + 1 == passes => {
                        failed.push((scene.key(), format!("{e:#}")));
                    }
                    Err(_) => {}
                }
            }
        }
        match &self.batch_out {
            Some(path) if !pending.is_empty() => {
                let lines = write_batch(path, &pending)
                    .with_context(|| format!("{}: cannot write", path.display()))?;
                notes.push(format!(
                    "{lines} requests written to {} (OpenAI Batch JSONL; read the provider's \
                     output with --batch-in)",
                    path.display()
                ));
            }
            Some(path) => notes.push(format!(
                "no request is pending, so {} was not written",
                path.display()
            )),
            None => {}
        }
        let rejects: Vec<AnnotateReject> = rejects.into_values().collect();
        notes.extend(write_rejects(ctx.dataset, INSTANCE_REJECTS, &rejects)?);
        let elapsed_s = started.elapsed().as_secs_f64();
        let mut text = format!(
            "annotate instances: {} scenes ({}): {annotated} instances annotated in {written} \
             scenes, {} failed, {} replies rejected, {requests} requests in {elapsed_s:.2} s\n",
            scenes.len(),
            ctx.config.annotations.source(),
            failed.len(),
            rejects.len()
        );
        for note in &notes {
            let _ = writeln!(text, "  {note}");
        }
        if !pending.is_empty() {
            let _ = writeln!(
                text,
                "  {} instances wait for replies (write the next batch with --batch-out FILE)",
                pending.len()
            );
        }
        if !rejects.is_empty() {
            let _ = writeln!(text, "  rejected replies are in {INSTANCE_REJECTS}");
        }
        for (key, why) in &failed {
            let _ = writeln!(text, "  failed {key}: {why}");
        }
        Ok(DatasetReport {
            success: failed.is_empty() && failed_lines == 0,
            text,
            record: json!({
                "scenes": scenes.len(), "annotated": annotated, "requests": requests,
                "prompt_text_tokens": tokens, "rejected_replies": rejects.len(),
                "failed": failed, "elapsed_s": elapsed_s,
            }),
        })
    }
}
