//! `mesa eval`: the benchmark of task-to-scene models (`docs/eval.md`) over
//! [`mesa_stages::eval`]: model outputs for the dataset's test prompts (JSON Lines `{"id",
//! "output"}`, or MesaTask's inference folders) → `eval/<name>/metrics.json`,
//! `eval/<name>/samples.jsonl` and `eval/<name>/index.html`; `--compare a,b,c` puts several
//! runs side by side; `--gpt-score` asks a chat model (`[eval.llm]`, live or through offline
//! batches, the reply cache of `mesa tasks`) to score the rendered scenes on the paper's five
//! criteria.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{anyhow, bail, Context as _};
use clap::Args as ClapArgs;
use mesa_schemas::artifacts::{AssetIndexArtifact, TextIndexArtifact};
use mesa_schemas::convert::category_of_instance;
use mesa_schemas::eval::{EvalMetrics, EvalSample, FeatureMetrics, SampleGptScore};
use mesa_schemas::json::{to_sorted_line, to_sorted_pretty};
use mesa_schemas::layout_file::AnyLayout;
use mesa_schemas::output::parse_model_output;
use mesa_schemas::DatasetLayout;
use mesa_stages::eval::features::{fid, kid, Features};
use mesa_stages::eval::gpt_score::{
    aggregate_gpt_scores, parse_prompt, parse_score_reply, score_request, EvalConfig, ScoreInput,
    BUILTIN_SOURCE, GPT_SCORE_PROMPT,
};
use mesa_stages::eval::{
    aggregate, evaluate_sample, EvalLibrary, ReferenceScenes, RunInfo, SampleInput, SizeStats,
};
use mesa_stages::graph::GraphOptions;
use mesa_stages::paths::dataset::{INDEX, TEXT_INDEX};
use mesa_stages::retrieve::lexical::LexicalIndex;
use mesa_stages::retrieve::npy::parse_matrix_f64;
use mesa_stages::retrieve::{Catalog, TextScorer};
use mesa_stages::tasks::chat::{Chat, ChatError, ChatRequest};
use mesa_stages::tasks::prompts::PromptTemplate;
use rayon::prelude::*;
use serde_json::Value;

use crate::chat::{
    custom_id, import_batch_files, request_digest, write_batch, ApiKey, ChatClient, Mode,
};
use crate::cli::{DatasetArgs, Global};
use crate::commands::check::ShapeLibrary;
use crate::dataset_cache::read_annotations;
use crate::exit::{usage, EXIT_FAILED};
use crate::fsio::{
    read_bounded, read_json, read_text_bounded, write_atomic, SizeLimit, JSON_LIMIT, RECORDS_LIMIT,
};
use crate::layouts::{chosen_layout, read_layout_file};
use crate::runner::{discover_scenes, thread_pool};

/// A feature file of `--real-features` / `--generated-features` (2 GiB: 100,000 × 2,048
/// float64 values are 1.6 GiB).
const FEATURES_LIMIT: SizeLimit = SizeLimit {
    bytes: 2 << 30,
    what: "a feature file",
    name: "FEATURES_LIMIT",
};

/// The prompts file read by default, relative to the dataset.
const TEST_PROMPTS: &str = "records/test.json";

/// `mesa eval`.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// The dataset and its run flags.
    #[command(flatten)]
    pub common: DatasetArgs,
    /// The model's outputs: JSON Lines `{"id": ..., "output": "..."}`, the id of a prompt being
    /// its position (from 0) in the prompts file.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["mesatask", "compare"])]
    pub outputs: Option<PathBuf>,
    /// MesaTask's inference folder instead: `task_NNN/scene_NNN/scene_layout.txt` (the model
    /// output) with `task_info.json` beside it or in `task_NNN/` (or the task folder's only
    /// `.json` file, as MesaTask's inference.py reads it); each scene is a sample.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["outputs", "compare"])]
    pub mesatask: Option<PathBuf>,
    /// The prompts, relative to the dataset or absolute: alpaca records (`records/test.json`,
    /// `records/dpo.json`) or a JSON list of task infos.
    #[arg(long, value_name = "FILE", default_value = TEST_PROMPTS)]
    pub prompts: String,
    /// The model's name: the results go to DATASET/eval/<name>/ (default: the outputs file's
    /// name without its extension).
    #[arg(long, value_name = "MODEL")]
    pub name: Option<String>,
    /// Features of real renders (N × D `.npy`, float32 or float64) for FID and KID.
    #[arg(long, value_name = "FILE", requires = "generated_features")]
    pub real_features: Option<PathBuf>,
    /// Features of the model's renders (N × D `.npy`) for FID and KID.
    #[arg(long, value_name = "FILE", requires = "real_features")]
    pub generated_features: Option<PathBuf>,
    /// Also draw each successful sample's scene (front and perspective views, `mesa render`'s
    /// renderer and `[render]` settings) into eval/<name>/render/ and show them on the page.
    #[arg(long)]
    pub render: bool,
    /// Print the metrics of earlier runs side by side (names, comma-separated) and write
    /// DATASET/eval/compare.md.
    #[arg(long, value_name = "A,B,...")]
    pub compare: Option<String>,
    /// Ask the GPT score of each successful sample: the chat endpoint of [eval.llm] (with
    /// [eval] judge = "llm") scores its front and perspective views 1 to 10 on the paper's
    /// five criteria (draws the views, as --render; default: [eval] gpt_score).
    #[arg(long)]
    pub gpt_score: bool,
    /// GPT score through offline batches: write the requests whose reply is not cached to FILE
    /// as OpenAI Batch JSONL (implies --gpt-score); samples whose reply is still missing are
    /// `pending` in samples.jsonl.
    #[arg(long, value_name = "FILE")]
    pub batch_out: Option<PathBuf>,
    /// GPT score through offline batches: read a provider's batch output JSONL (repeatable)
    /// into the reply cache before scoring (joined by custom_id; implies --gpt-score).
    #[arg(long, value_name = "FILE")]
    pub batch_in: Vec<PathBuf>,
}

/// One prompt.
struct Prompt {
    id: String,
    task_info: Option<Value>,
    table_type: Option<String>,
    /// The output (MesaTask folders carry theirs), or why it cannot be read.
    output: Option<Result<String, String>>,
}

/// Runs `mesa eval`.
pub fn run(args: Args, global: Global) -> anyhow::Result<ExitCode> {
    let mut resolved = args.common.resolve(global)?;
    let dataset = resolved.dataset.clone();
    if let Some(names) = &args.compare {
        return compare(&dataset, names, global.quiet);
    }
    let started = Instant::now();
    let batch = args.batch_out.is_some() || !args.batch_in.is_empty();
    if args.gpt_score || batch {
        resolved.config.eval.gpt_score = true;
    }
    // The judge, its prompt and its API key are checked before any work starts.
    let judge = if resolved.config.eval.gpt_score {
        Some(GptJudge::new(&dataset, &resolved.config.eval, batch)?)
    } else {
        None
    };
    let (mut prompts, prompts_label, name) = match (&args.outputs, &args.mesatask) {
        (Some(outputs), None) => {
            let name = match &args.name {
                Some(n) => n.clone(),
                None => outputs
                    .file_stem()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_default(),
            };
            let prompts_path = if Path::new(&args.prompts).is_absolute() {
                PathBuf::from(&args.prompts)
            } else {
                dataset.join(&args.prompts)
            };
            let prompts = read_prompts(&prompts_path, &dataset, resolved.config.records.decimals)?;
            (prompts, args.prompts.clone(), name)
        }
        (None, Some(dir)) => {
            let name = args.name.clone().unwrap_or_else(|| "mesatask".to_owned());
            (read_mesatask_dir(dir)?, dir.display().to_string(), name)
        }
        _ => {
            return Err(usage(
                "give --outputs FILE, --mesatask DIR or --compare A,B,...",
            ))
        }
    };
    check_name(&name)?;
    let mut ignored = Vec::new();
    if let Some(outputs) = &args.outputs {
        ignored = join_outputs(outputs, &mut prompts)?;
    }

    // The library: retrieval's text index and catalog, the collision shapes, size statistics.
    let index: AssetIndexArtifact =
        read_json(&dataset.join(INDEX), "run `mesa assets` to write it")?;
    let text: TextIndexArtifact =
        read_json(&dataset.join(TEXT_INDEX), "run `mesa assets` to write it")?;
    let annotations = read_annotations(&dataset)?;
    let scorer = TextScorer::Lexical(LexicalIndex::new(&text));
    let catalog = Catalog::new(scorer.uids(), &annotations, &index);
    let sizes = SizeStats::of_library(&index, Some(&annotations));
    let shapes = ShapeLibrary::load(&dataset)?;
    let shape_of = |uid: &str| shapes.shape_of_uid(&dataset, uid);
    let graph = GraphOptions::from(&resolved.config.graph);
    let retrieve = resolved.config.retrieve.clone();
    let library = EvalLibrary {
        scorer: &scorer,
        catalog: &catalog,
        retrieve: &retrieve,
        annotations: Some(&annotations),
        shape_of: &shape_of,
        sizes: &sizes,
        check: &resolved.config.check,
        graph: &graph,
    };
    let references = reference_scenes(&dataset)?;

    let pool = thread_pool(resolved.options.jobs).map_err(|e| anyhow!("{e}"))?;
    let evaluated: Vec<(EvalSample, Option<DatasetLayout>)> = pool.install(|| {
        prompts
            .par_iter()
            .map(|prompt| {
                let output = match &prompt.output {
                    None => Ok(None),
                    Some(Ok(text)) => Ok(Some(text.as_str())),
                    Some(Err(why)) => Err(why.as_str()),
                };
                let input = SampleInput {
                    id: &prompt.id,
                    table_type: prompt.table_type.as_deref(),
                    task_info: prompt.task_info.as_ref(),
                    output,
                };
                evaluate_sample(&input, &library)
            })
            .collect()
    });

    let (samples, scenes): (Vec<EvalSample>, Vec<Option<DatasetLayout>>) =
        evaluated.into_iter().unzip();
    let mut metrics = aggregate(
        RunInfo {
            name: name.clone(),
            prompts: prompts_label,
            prompts_total: prompts.len() as u64,
            ignored_outputs: ignored,
        },
        &samples,
        &references,
    );
    if let (Some(real), Some(generated)) = (&args.real_features, &args.generated_features) {
        metrics.features = Some(feature_metrics(real, generated)?);
    }

    let out_dir = dataset.join("eval").join(&name);
    // The scenes as checked, for `mesa check`, `mesa render` or Blender.
    let layouts_dir = out_dir.join("layouts");
    // Those of an earlier run of this name would be stale.
    match std::fs::remove_dir_all(&layouts_dir) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => bail!(
            "{}: cannot remove the earlier layouts: {e}",
            layouts_dir.display()
        ),
    }
    for (sample, scene) in samples.iter().zip(&scenes) {
        let Some(scene) = scene else { continue };
        let path = layouts_dir.join(format!("{}.json", file_stem_of(&sample.id)));
        write_atomic(&path, &to_sorted_pretty(scene)?)
            .with_context(|| format!("{}: cannot write", path.display()))?;
    }
    let pictures = if args.render || judge.is_some() {
        render_samples(
            &dataset,
            &resolved.config.render,
            &out_dir,
            &samples,
            &scenes,
            &pool,
        )?
    } else {
        BTreeMap::new()
    };
    let mut samples = samples;
    let mut exit = ExitCode::SUCCESS;
    if let Some(judge) = &judge {
        let (scores, code) =
            judge.score(&args, &prompts, &samples, &scenes, &pictures, global.quiet)?;
        for (sample, score) in samples.iter_mut().zip(scores) {
            sample.gpt_score = score;
        }
        metrics.gpt_score = Some(aggregate_gpt_scores(
            &judge.config.model,
            &judge.prompt_source,
            samples.iter().filter_map(|s| s.gpt_score.as_ref()),
        ));
        exit = code;
    }
    let metrics_path = out_dir.join("metrics.json");
    write_atomic(&metrics_path, &to_sorted_pretty(&metrics)?)
        .with_context(|| format!("{}: cannot write", metrics_path.display()))?;
    let mut lines = String::new();
    for sample in &samples {
        lines.push_str(&to_sorted_line(sample)?);
        lines.push('\n');
    }
    let samples_path = out_dir.join("samples.jsonl");
    write_atomic(&samples_path, lines.as_bytes())
        .with_context(|| format!("{}: cannot write", samples_path.display()))?;
    let page_path = out_dir.join("index.html");
    write_atomic(&page_path, page(&metrics, &samples, &pictures).as_bytes())
        .with_context(|| format!("{}: cannot write", page_path.display()))?;
    if !global.quiet {
        println!("{}", summary(&metrics));
        println!(
            "eval: {} samples in {:.2} s: {}",
            samples.len(),
            started.elapsed().as_secs_f64(),
            out_dir.display()
        );
    }
    Ok(exit)
}

/// Draws the front and perspective views of every successful sample's scene (objects without
/// an asset left out) into `out_dir/render/<id>_<view>.png`. Returns per sample id the
/// pictures' paths relative to `out_dir` with their PNG bytes (front, then perspective), or why
/// the scene could not be drawn (one failure never stops the others).
fn render_samples(
    dataset: &Path,
    config: &mesa_stages::render::RenderConfig,
    out_dir: &Path,
    samples: &[EvalSample],
    scenes: &[Option<DatasetLayout>],
    pool: &rayon::ThreadPool,
) -> anyhow::Result<BTreeMap<String, Drawn>> {
    let renderer = crate::commands::render::RenderStage::new();
    let render_dir = out_dir.join("render");
    match std::fs::remove_dir_all(&render_dir) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => bail!(
            "{}: cannot remove the earlier renders: {e}",
            render_dir.display()
        ),
    }
    let drawn: Vec<(String, Drawn)> = pool.install(|| {
        samples
            .par_iter()
            .zip(scenes.par_iter())
            .filter_map(|(sample, scene)| {
                let mut scene = scene.clone()?;
                scene.objects.retain(|o| !o.retrieved_uid.is_empty());
                let stem = file_stem_of(&sample.id);
                let result = renderer
                    .render_layout(dataset, config, &scene)
                    .map_err(|e| format!("{e:#}"))
                    .and_then(|(views, _)| {
                        let mut files = Vec::new();
                        // Front first, then perspective: the order the GPT score sends them.
                        for name in ["front", "perspective"] {
                            let Some(view) = views.iter().find(|v| v.name == name) else {
                                continue;
                            };
                            let rel = format!("render/{stem}_{}.png", view.name);
                            write_atomic(&out_dir.join(&rel), &view.png)
                                .map_err(|e| format!("{rel}: cannot write: {e}"))?;
                            files.push((rel, view.png.clone()));
                        }
                        Ok(files)
                    });
                Some((sample.id.clone(), result))
            })
            .collect()
    });
    Ok(drawn.into_iter().collect())
}

/// The GPT score's judge: the prompt and the chat client of `[eval.llm]`, made before any work
/// starts.
struct GptJudge {
    config: mesa_stages::tasks::LlmConfig,
    template: PromptTemplate,
    prompt_source: String,
    client: Arc<ChatClient>,
}

/// What a sample's GPT score request is, before it is sent.
enum Planned {
    /// A failed sample: no GPT score.
    Nothing,
    /// No request can be made (the score says why).
    Settled(SampleGptScore),
    /// The request.
    Request(Box<ChatRequest>),
}

fn gpt_status(status: &str, problems: Vec<String>) -> SampleGptScore {
    SampleGptScore {
        status: status.to_owned(),
        scores: BTreeMap::new(),
        mean: None,
        reason: None,
        problems,
        rejected_criteria: Vec::new(),
        reply: None,
        request_sha256: None,
    }
}

impl GptJudge {
    /// The judge of `[eval]`: refused (naming the key) without `judge = "llm"`, a prompt that
    /// cannot be read or parsed, or (live) an API key that is not set.
    fn new(dataset: &Path, config: &EvalConfig, batch: bool) -> anyhow::Result<Self> {
        use mesa_stages::eval::gpt_score::Judge;
        if config.judge != Judge::Llm {
            return Err(usage(
                "--gpt-score needs a chat backend, and [eval] judge is \"none\" (set [eval] \
                 judge = \"llm\" in DATASET/mesa.toml and the endpoint in [eval.llm]: base_url, \
                 model, api_key_env; see docs/eval.md)",
            ));
        }
        let (prompt_source, text) = if config.gpt_score_prompt.is_empty() {
            (BUILTIN_SOURCE.to_owned(), GPT_SCORE_PROMPT.to_owned())
        } else {
            let path = dataset.join(&config.gpt_score_prompt);
            let text = read_text_bounded(&path, JSON_LIMIT).map_err(|e| {
                usage(format!(
                    "[eval] gpt_score_prompt: {}: cannot read: {e} (copy data/prompts/\
                     gpt_score.txt there and edit it, or set gpt_score_prompt = \"\" for the \
                     built-in prompt)",
                    path.display()
                ))
            })?;
            (config.gpt_score_prompt.clone(), text)
        };
        let template = parse_prompt(&prompt_source, &text)
            .map_err(|e| usage(format!("[eval] gpt_score_prompt: {e}")))?;
        // ApiKey names [tasks.llm] in its messages; the judge's key is [eval.llm]'s.
        let rename = |e: String| e.replace("[tasks.llm]", "[eval.llm]");
        let (mode, key) = if batch {
            // Nothing is sent; the key, when set, only serves to redact batch replies.
            (
                Mode::CacheOnly,
                ApiKey::from_env(&config.llm.api_key_env).ok().flatten(),
            )
        } else {
            let key = ApiKey::from_env(&config.llm.api_key_env).map_err(|e| usage(rename(e)))?;
            (Mode::Live, key)
        };
        Ok(Self {
            config: config.llm.clone(),
            template,
            prompt_source,
            client: Arc::new(ChatClient::with_key(dataset, &config.llm, mode, key)),
        })
    }

    /// The request of each sample (in sample order).
    fn plan(
        &self,
        prompts: &[Prompt],
        samples: &[EvalSample],
        scenes: &[Option<DatasetLayout>],
        pictures: &BTreeMap<String, Drawn>,
    ) -> Vec<Planned> {
        samples
            .iter()
            .zip(scenes)
            .zip(prompts)
            .map(|((sample, scene), prompt)| {
                let Some(scene) = scene.as_ref().filter(|_| sample.success) else {
                    return Planned::Nothing;
                };
                let views = match pictures.get(&sample.id) {
                    None => return Planned::Settled(gpt_status("not_drawn", Vec::new())),
                    Some(Err(why)) => {
                        return Planned::Settled(gpt_status("not_drawn", vec![why.clone()]))
                    }
                    Some(Ok(views)) => views,
                };
                let png = |suffix: &str| {
                    views
                        .iter()
                        .find(|(rel, _)| rel.ends_with(suffix))
                        .map(|(_, png)| png.as_slice())
                };
                let (Some(front_png), Some(perspective_png)) =
                    (png("_front.png"), png("_perspective.png"))
                else {
                    return Planned::Settled(gpt_status(
                        "not_drawn",
                        vec!["the renderer gave no front or no perspective view".to_owned()],
                    ));
                };
                let input = ScoreInput {
                    table_type: prompt.table_type.as_deref(),
                    task_info: prompt.task_info.as_ref(),
                    layout: scene,
                    front_png,
                    perspective_png,
                };
                match score_request(&self.config, &self.template, &input) {
                    Ok(request) => Planned::Request(Box::new(request)),
                    Err(e) => Planned::Settled(gpt_status("failed", vec![e.to_string()])),
                }
            })
            .collect()
    }

    /// Asks (or, with offline batches, reads from the cache) the GPT score of every successful
    /// sample; writes `--batch-out`. Returns the scores in sample order and the exit code (1
    /// when a `--batch-in` line could not be used).
    fn score(
        &self,
        args: &Args,
        prompts: &[Prompt],
        samples: &[EvalSample],
        scenes: &[Option<DatasetLayout>],
        pictures: &BTreeMap<String, Drawn>,
        quiet: bool,
    ) -> anyhow::Result<(Vec<Option<SampleGptScore>>, ExitCode)> {
        let planned = self.plan(prompts, samples, scenes, pictures);
        let mut code = ExitCode::SUCCESS;
        if !args.batch_in.is_empty() {
            let cache = self.client.cache();
            let pending: BTreeMap<String, String> = planned
                .iter()
                .filter_map(|p| match p {
                    Planned::Request(request) => Some(request_digest(request)),
                    _ => None,
                })
                .filter(|digest| !cache.contains(digest))
                .map(|digest| (custom_id(&digest), digest))
                .collect();
            let imported = import_batch_files(&args.batch_in, &pending, cache)?;
            for line in &imported.lines {
                // A file's line gets the command's name; its failed lines are indented.
                if line.starts_with(' ') {
                    eprintln!("{line}");
                } else {
                    eprintln!("eval: {line}");
                }
            }
            if imported.failed > 0 {
                code = ExitCode::from(EXIT_FAILED);
            }
        }
        // Requests wait on the network: as many threads as may be in flight.
        let pool = thread_pool(self.config.max_concurrency).map_err(|e| anyhow!("{e}"))?;
        let answered: Vec<(Option<SampleGptScore>, Option<ChatRequest>)> = pool.install(|| {
            planned
                .into_par_iter()
                .map(|p| match p {
                    Planned::Nothing => (None, None),
                    Planned::Settled(score) => (Some(score), None),
                    Planned::Request(request) => self.answer(*request),
                })
                .collect()
        });
        let mut scores = Vec::with_capacity(answered.len());
        let mut waiting = Vec::new();
        for (score, pending) in answered {
            scores.push(score);
            waiting.extend(pending);
        }
        match &args.batch_out {
            Some(path) if !waiting.is_empty() => {
                let lines = write_batch(path, &waiting)
                    .with_context(|| format!("{}: cannot write", path.display()))?;
                eprintln!(
                    "eval: {lines} GPT score requests written to {} (OpenAI Batch JSONL; read \
                     the provider's output with --batch-in)",
                    path.display()
                );
            }
            Some(path) => eprintln!(
                "eval: no GPT score request is pending, so {} was not written",
                path.display()
            ),
            None if !waiting.is_empty() => eprintln!(
                "eval: {} samples wait for their GPT score (write the batch with --batch-out \
                 FILE)",
                waiting.len()
            ),
            None => {}
        }
        if !quiet {
            eprintln!(
                "eval: GPT score: {}: {}",
                self.config.model,
                self.client.stats.summary()
            );
        }
        for warning in self.client.warnings() {
            eprintln!(
                "eval: warning: {}",
                warning.replace("[tasks.llm]", "[eval.llm]")
            );
        }
        Ok((scores, code))
    }

    /// One sample's reply, validated; the request when it is still pending.
    fn answer(&self, request: ChatRequest) -> (Option<SampleGptScore>, Option<ChatRequest>) {
        let digest = request_digest(&request);
        let mut score = match self.client.complete(&request) {
            Ok(reply) => match parse_score_reply(&reply.content) {
                Ok(scored) => SampleGptScore {
                    status: "scored".to_owned(),
                    scores: scored.scores,
                    mean: Some(scored.mean),
                    reason: Some(scored.reason).filter(|r| !r.is_empty()),
                    ..gpt_status("scored", Vec::new())
                },
                Err(reject) => {
                    let mut problems = reject.problems;
                    if reply.finish_reason.as_deref() == Some("length") {
                        problems.push(
                            "the reply was cut at [eval.llm] max_tokens (raise it)".to_owned(),
                        );
                    }
                    SampleGptScore {
                        rejected_criteria: reject.criteria,
                        reply: Some(reply.content),
                        ..gpt_status("rejected", problems)
                    }
                }
            },
            Err(ChatError::Pending(_)) => {
                let mut score = gpt_status(
                    "pending",
                    vec![
                        "no reply yet: write the batch with --batch-out FILE, read the \
                          provider's output with --batch-in FILE"
                            .to_owned(),
                    ],
                );
                score.request_sha256 = Some(digest);
                return (Some(score), Some(request));
            }
            Err(ChatError::Failed(why)) => gpt_status("failed", vec![why]),
        };
        score.request_sha256 = Some(digest);
        (Some(score), None)
    }
}

/// A sample's drawn views: (path relative to the run's folder, PNG bytes), or why not drawn.
type Drawn = Result<Vec<(String, Vec<u8>)>, String>;

/// A sample id as a file name: characters other than ASCII letters, digits, `-`, `_` and `.`
/// become `_` (`task_000/scene_001` → `task_000_scene_001`), and a leading `.` too.
fn file_stem_of(id: &str) -> String {
    let mut stem: String = id
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') {
                c
            } else {
                '_'
            }
        })
        .collect();
    if stem.starts_with('.') || stem.is_empty() {
        stem.insert(0, '_');
    }
    stem.truncate(200);
    stem
}

/// A name usable as a folder: letters, digits, `.`, `_`, `-`, not starting with `.`.
fn check_name(name: &str) -> anyhow::Result<()> {
    let fine = !name.is_empty()
        && name.len() <= 100
        && !name.starts_with('.')
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-'));
    if fine {
        Ok(())
    } else {
        Err(usage(format!(
            "--name \"{name}\": not usable as a folder name (expected 1 to 100 ASCII letters, \
             digits, '.', '_' or '-', not starting with '.')"
        )))
    }
}

/// A key of a layout for finding the prompt's scene: its sorted instance names.
fn instances_key<'a>(instances: impl Iterator<Item = &'a str>) -> String {
    let mut names: Vec<&str> = instances.collect();
    names.sort_unstable();
    names.join(",")
}

/// Every scene of the dataset with a layout: table type, zone, instance key, categories.
struct SceneFacts {
    table_type: String,
    zone_cm: [f64; 4],
    key: String,
    categories: Vec<String>,
}

fn scene_facts(dataset: &Path) -> anyhow::Result<Vec<SceneFacts>> {
    let mut out = Vec::new();
    for scene in discover_scenes(dataset).map_err(|e| anyhow!("{e}"))? {
        let Some(rel) = chosen_layout(&scene) else {
            continue;
        };
        // A scene whose layout cannot be read is no reference; the others still are.
        let Ok((read, _)) = read_layout_file(&scene.path(rel)) else {
            continue;
        };
        let (zone_cm, instances): ([f64; 4], Vec<String>) = match read.layout {
            AnyLayout::Dataset(l) => (
                l.zone_cm.0,
                l.objects.into_iter().map(|o| o.instance).collect(),
            ),
            AnyLayout::Llm(l) => (
                l.zone_cm.0,
                l.objects.into_iter().map(|o| o.instance).collect(),
            ),
        };
        out.push(SceneFacts {
            table_type: scene.table_type.clone(),
            zone_cm,
            key: instances_key(instances.iter().map(String::as_str)),
            categories: instances
                .iter()
                .map(|i| category_of_instance(i).to_lowercase())
                .collect(),
        });
    }
    Ok(out)
}

/// The dataset's scenes by table type, as CKL and object counts compare against.
fn reference_scenes(dataset: &Path) -> anyhow::Result<ReferenceScenes> {
    let mut out: ReferenceScenes = BTreeMap::new();
    for facts in scene_facts(dataset)? {
        out.entry(facts.table_type)
            .or_default()
            .push(facts.categories);
    }
    Ok(out)
}

/// Reads the prompts: alpaca records (`input` holds the task info JSON; the reference
/// `output`/`chosen` finds the record's scene and table type) or bare task infos.
fn read_prompts(path: &Path, dataset: &Path, decimals: u32) -> anyhow::Result<Vec<Prompt>> {
    let text = read_text_bounded(path, RECORDS_LIMIT).with_context(|| {
        format!(
            "{}: cannot read the prompts (run `mesa records` to write records/test.json, or \
             give --prompts FILE)",
            path.display()
        )
    })?;
    let value: Value = serde_json::from_str(&text).map_err(|e| {
        anyhow!(
            "{}: {e} (expected a JSON list of alpaca records or task infos)",
            path.display()
        )
    })?;
    let Value::Array(items) = value else {
        bail!(
            "{}: $: not a list (expected a JSON list of alpaca records or task infos)",
            path.display()
        );
    };
    let scenes = scene_facts(dataset)?;
    let mut prompts = Vec::with_capacity(items.len());
    for (i, item) in items.iter().enumerate() {
        let (task_info, reference) = match item.get("input").and_then(Value::as_str) {
            Some(input) => (
                serde_json::from_str::<Value>(input).ok(),
                item.get("output")
                    .or_else(|| item.get("chosen"))
                    .and_then(Value::as_str),
            ),
            None if item.get("Task").is_some() => (Some(item.clone()), None),
            None => bail!(
                "{}: $[{i}]: neither an alpaca record (no \"input\") nor a task info (no \
                 \"Task\") (expected records/test.json's form)",
                path.display()
            ),
        };
        let table_type = reference
            .and_then(|r| parse_model_output(r).ok())
            .and_then(|parsed| {
                let key = instances_key(parsed.layout.objects.iter().map(|o| o.instance.as_str()));
                let zone = parsed.layout.zone_cm.0;
                let step = 10f64.powi(decimals as i32);
                scenes
                    .iter()
                    .filter(|s| s.key == key)
                    .min_by(|a, b| {
                        let d = |s: &SceneFacts| {
                            s.zone_cm
                                .iter()
                                .zip(zone)
                                .map(|(x, y)| ((x * step).round() / step - y).abs())
                                .sum::<f64>()
                        };
                        d(a).total_cmp(&d(b))
                    })
                    .map(|s| s.table_type.clone())
            });
        prompts.push(Prompt {
            id: i.to_string(),
            task_info,
            table_type,
            output: None,
        });
    }
    Ok(prompts)
}

/// Joins the output lines to the prompts by id; returns the lines that matched none, with why.
fn join_outputs(path: &Path, prompts: &mut [Prompt]) -> anyhow::Result<Vec<String>> {
    let text = read_text_bounded(path, RECORDS_LIMIT)
        .with_context(|| format!("{}: cannot read the outputs", path.display()))?;
    let by_id: BTreeMap<String, usize> = prompts
        .iter()
        .enumerate()
        .map(|(i, p)| (p.id.clone(), i))
        .collect();
    let mut ignored = Vec::new();
    for (n, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let at = format!("{}:{}", path.display(), n + 1);
        let value: Value = match serde_json::from_str(line) {
            Ok(v) => v,
            Err(e) => {
                ignored.push(format!(
                    "{at}: not JSON: {e} (expected {{\"id\", \"output\"}})"
                ));
                continue;
            }
        };
        let id = match value.get("id") {
            Some(Value::String(s)) => s.clone(),
            Some(Value::Number(n)) => n.to_string(),
            _ => {
                ignored.push(format!("{at}: id: missing or not a string or number"));
                continue;
            }
        };
        let Some(output) = value.get("output").and_then(Value::as_str) else {
            ignored.push(format!("{at}: output: missing or not a string (id {id})"));
            continue;
        };
        match by_id.get(&id) {
            None => ignored.push(format!("{at}: id {id}: no prompt has it")),
            Some(&i) if prompts[i].output.is_some() => {
                ignored.push(format!(
                    "{at}: id {id}: a second output (the first is kept)"
                ));
            }
            Some(&i) => prompts[i].output = Some(Ok(output.to_owned())),
        }
    }
    Ok(ignored)
}

/// The sorted subfolders of `dir` whose names start with `prefix`.
fn subfolders(dir: &Path, prefix: &str) -> anyhow::Result<Vec<PathBuf>> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("{}: cannot list", dir.display()))?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| {
            p.is_dir()
                && p.file_name()
                    .is_some_and(|n| n.to_string_lossy().starts_with(prefix))
        })
        .collect();
    out.sort();
    Ok(out)
}

/// MesaTask's inference output: `task_NNN/scene_NNN/scene_layout.txt` with `task_info.json` in
/// the scene folder or the task folder. A sample that cannot be read fails with why; the others
/// go on.
fn read_mesatask_dir(dir: &Path) -> anyhow::Result<Vec<Prompt>> {
    let tasks = subfolders(dir, "task_")?;
    if tasks.is_empty() {
        bail!(
            "{}: no task_NNN folder (expected MesaTask's inference output: \
             task_NNN/scene_NNN/scene_layout.txt)",
            dir.display()
        );
    }
    let mut prompts = Vec::new();
    for task in tasks {
        for scene in subfolders(&task, "scene_")? {
            let id = format!(
                "{}/{}",
                task.file_name()
                    .map(|n| n.to_string_lossy())
                    .unwrap_or_default(),
                scene
                    .file_name()
                    .map(|n| n.to_string_lossy())
                    .unwrap_or_default()
            );
            let info_path = [scene.join("task_info.json"), task.join("task_info.json")]
                .into_iter()
                .find(|p| p.is_file())
                .or_else(|| only_json_in(&task));
            let task_info = info_path.and_then(|p| {
                read_bounded(&p, JSON_LIMIT)
                    .ok()
                    .and_then(|b| serde_json::from_slice::<Value>(&b).ok())
            });
            let layout = scene.join("scene_layout.txt");
            let output = read_text_bounded(&layout, JSON_LIMIT)
                .map_err(|e| format!("{}: {e}", layout.display()));
            prompts.push(Prompt {
                id,
                task_info,
                table_type: None,
                output: Some(output),
            });
        }
    }
    Ok(prompts)
}

/// The one `.json` file of a folder (MesaTask's `inference.py` takes the task info file of
/// any name from the task folder), or None when there are none or several.
fn only_json_in(dir: &Path) -> Option<PathBuf> {
    let files: Vec<PathBuf> = std::fs::read_dir(dir)
        .ok()?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.is_file() && p.extension().is_some_and(|e| e == "json"))
        .collect();
    match files.as_slice() {
        [one] => Some(one.clone()),
        _ => None,
    }
}

fn read_features(path: &Path) -> anyhow::Result<Features> {
    let bytes = read_bounded(path, FEATURES_LIMIT)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    let (rows, cols, data) = parse_matrix_f64(&bytes).map_err(|e| {
        anyhow!(
            "{}: {e} (expected an N × D float32 or float64 .npy, as numpy.save writes)",
            path.display()
        )
    })?;
    Ok(Features { rows, cols, data })
}

fn feature_metrics(real: &Path, generated: &Path) -> anyhow::Result<FeatureMetrics> {
    let a = read_features(real)?;
    let b = read_features(generated)?;
    let pair = format!("{} and {}", real.display(), generated.display());
    Ok(FeatureMetrics {
        real: real.display().to_string(),
        generated: generated.display().to_string(),
        real_rows: a.rows as u64,
        generated_rows: b.rows as u64,
        dimension: a.cols as u64,
        fid: fid(&a, &b).map_err(|e| anyhow!("{pair}: {e}"))?,
        kid: kid(&a, &b).map_err(|e| anyhow!("{pair}: {e}"))?,
    })
}

/// The lines printed at the end.
fn summary(m: &EvalMetrics) -> String {
    let p = &m.physics;
    let mut s = format!(
        "eval {}: success {}/{} ({:.1} %), collision rate {:.4} ({} of {} pairs; {} of {} scenes \
         with a collision), MesaTask 5 cm rule {:.4}, floating {}, outside the zone {}, in the \
         sink {}",
        m.name,
        m.succeeded,
        m.samples,
        100.0 * m.success_rate,
        p.collision_rate,
        p.colliding_pairs,
        p.pairs,
        p.scenes_with_collision,
        p.scenes,
        p.mesatask_rule_rate,
        p.objects_floating,
        p.objects_outside_zone,
        p.objects_in_sink_zone
    );
    let _ = write!(
        s,
        "\n  graph self-consistency precision {:.4} recall {:.4}; task coverage {:.4}; \
         implausible sizes {:.4}",
        m.graph.precision, m.graph.recall, m.task_coverage.coverage, m.size.share
    );
    if let Some(ckl) = m.ckl_mean {
        let _ = write!(s, "; CKL {ckl:.4}");
    }
    if let Some(f) = &m.features {
        let _ = write!(s, "; FID {:.4}, KID {:.6}", f.fid, f.kid);
    }
    if let Some(g) = &m.gpt_score {
        let opt = |v: Option<f64>| v.map_or("–".to_owned(), |v| format!("{v:.2}"));
        let criteria: Vec<String> = g
            .criteria
            .iter()
            .map(|(key, c)| format!("{key} {}", opt(c.mean)))
            .collect();
        let _ = write!(
            s,
            "\n  GPT score ({}) {}: {} scored, {} rejected, {} pending, {} failed, {} not drawn; {}",
            g.model,
            opt(g.mean),
            g.scored,
            g.rejected,
            g.pending,
            g.failed,
            g.not_drawn,
            criteria.join(", ")
        );
    }
    if !m.failures.is_empty() {
        let reasons: Vec<String> = m.failures.iter().map(|(k, v)| format!("{k} {v}")).collect();
        let _ = write!(s, "\n  failures: {}", reasons.join(", "));
    }
    if !m.ignored_outputs.is_empty() {
        let _ = write!(
            s,
            "\n  {} output lines ignored (see metrics.json)",
            m.ignored_outputs.len()
        );
    }
    s
}

fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// `eval/<name>/index.html`: the numbers, then one row per sample with its flags.
fn page(m: &EvalMetrics, samples: &[EvalSample], pictures: &BTreeMap<String, Drawn>) -> String {
    let mut html = String::new();
    let _ = write!(
        html,
        "<!doctype html>\n<html><head><meta charset=\"utf-8\"><title>mesa eval: {name}</title>\
         <style>body{{font-family:sans-serif}}td,th{{border:1px solid #ccc;padding:2px 6px}}\
         table{{border-collapse:collapse}}.bad{{background:#fdd}}</style></head><body>\n\
         <h1>mesa eval: {name}</h1>\n<pre>{summary}</pre>\n<table><tr><th>id</th><th>table \
         type</th><th>success</th><th>objects</th><th>collisions</th><th>floating</th>\
         <th>outside zone</th><th>graph (written/extracted/matched)</th><th>missing task \
         types</th><th>implausible sizes</th><th>GPT score</th><th>views</th></tr>\n",
        name = escape(&m.name),
        summary = escape(&summary(m))
    );
    for s in samples {
        let flagged = !s.success || !s.collisions.is_empty() || !s.floating.is_empty();
        let collisions: Vec<String> = s
            .collisions
            .iter()
            .map(|(a, b, d)| format!("{a}–{b} {d:.1} mm"))
            .collect();
        let _ = writeln!(
            html,
            "<tr{}><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td>\
             <td>{}/{}/{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            if flagged { " class=\"bad\"" } else { "" },
            escape(&s.id),
            escape(s.table_type.as_deref().unwrap_or("")),
            match &s.failure {
                None => "yes".to_owned(),
                Some(f) => escape(&format!("no: {}: {}", f.reason, f.message)),
            },
            s.objects.len(),
            escape(&collisions.join(", ")),
            escape(&s.floating.join(", ")),
            escape(&s.outside_zone.join(", ")),
            s.graph_counts[0],
            s.graph_counts[1],
            s.graph_counts[2],
            escape(&s.missing_task_types.join(", ")),
            escape(&s.implausible_size.join("; ")),
            escape(&gpt_cell(s.gpt_score.as_ref())),
            match pictures.get(&s.id) {
                None => String::new(),
                Some(Ok(files)) => files
                    .iter()
                    .map(|(f, _)| format!("<img src=\"{}\" width=\"192\">", escape(f)))
                    .collect::<String>(),
                Some(Err(why)) => escape(&format!("not drawn: {why}")),
            },
        );
    }
    html.push_str("</table></body></html>\n");
    html
}

/// A sample's GPT score on the page: the mean and the five scores, or the status and why.
fn gpt_cell(score: Option<&SampleGptScore>) -> String {
    let Some(score) = score else {
        return String::new();
    };
    match score.mean {
        Some(mean) => {
            let each: Vec<String> = score.scores.values().map(u32::to_string).collect();
            let mut cell = format!("{mean:.1} ({})", each.join("/"));
            if let Some(reason) = &score.reason {
                cell.push_str(": ");
                cell.push_str(reason);
            }
            cell
        }
        None => format!("{}: {}", score.status, score.problems.join("; ")),
    }
}

/// `--compare a,b,c`: the runs' main numbers side by side (printed and eval/compare.md).
fn compare(dataset: &Path, names: &str, quiet: bool) -> anyhow::Result<ExitCode> {
    let mut table = String::from(
        "| model | samples | success | collision rate | scenes with collision | MesaTask 5 cm \
         | CKL | graph P | graph R | task coverage | implausible size | FID | KID | GPT score |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for name in names.split(',').map(str::trim).filter(|n| !n.is_empty()) {
        check_name(name)?;
        let path = dataset.join("eval").join(name).join("metrics.json");
        let m: EvalMetrics = read_json(
            &path,
            "run `mesa eval DATASET --outputs FILE --name NAME` first",
        )?;
        let opt = |v: Option<f64>, d: usize| v.map_or("–".to_owned(), |v| format!("{v:.d$}"));
        let _ = writeln!(
            table,
            "| {} | {} | {:.1} % | {:.4} | {:.4} | {:.4} | {} | {:.4} | {:.4} | {:.4} | {:.4} | {} | {} | {} |",
            m.name,
            m.samples,
            100.0 * m.success_rate,
            m.physics.collision_rate,
            m.physics.scenes_with_collision_rate,
            m.physics.mesatask_rule_rate,
            opt(m.ckl_mean, 4),
            m.graph.precision,
            m.graph.recall,
            m.task_coverage.coverage,
            m.size.share,
            opt(m.features.as_ref().map(|f| f.fid), 3),
            opt(m.features.as_ref().map(|f| f.kid), 5),
            opt(m.gpt_score.as_ref().and_then(|g| g.mean), 2),
        );
    }
    let path = dataset.join("eval").join("compare.md");
    write_atomic(&path, table.as_bytes())
        .with_context(|| format!("{}: cannot write", path.display()))?;
    if !quiet {
        print!("{table}");
    }
    Ok(ExitCode::SUCCESS)
}
