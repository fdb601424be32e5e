//! The command line: clap types only. Each doc comment is the `--help` text; the work is in
//! [`crate::app`].

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};

use crate::config::ProgressMode;
use crate::runner::Shard;

/// mesa builds MesaTask-style tabletop-scene datasets: depth and masks to boxes, asset
/// retrieval and placement, the annotator round trip, physics QA, scene graphs, and training
/// records.
#[derive(Debug, Parser)]
#[command(name = "mesa", version, about, max_term_width = 100)]
pub struct Cli {
    /// More log output (-v: debug, -vv: trace).
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    pub verbose: u8,
    /// Only errors and the final summary.
    #[arg(short, long, global = true)]
    pub quiet: bool,
    /// The command.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run every stage over a dataset, in order.
    Run(RunArgs),
    /// Print, per stage, how many scenes are done, stale, failed and pending.
    Status(StatusArgs),
    /// Validate artifacts against their schemas, reporting every problem.
    Validate(ValidateArgs),
    /// Convert a layout between the dataset form and the LLM form.
    Convert(ConvertArgs),
    /// Parse a model output text (reasoning, scene graph, marker, layout JSON).
    ParseOutput(ParseOutputArgs),
    /// Write a synthetic dataset workspace with ground truth: procedural assets, photos,
    /// depth, masks, cameras and instances, and the true layouts.
    Demo(DemoArgs),
    /// Depth maps and instance masks → point clouds, the table frame, and object boxes.
    Lift(StageArgs),
    /// Index the asset library (assets/index/): per asset its bounds in the table frame,
    /// counts, materials and validity, its collision shapes, and the text index. Unchanged
    /// assets are not re-indexed.
    Assets(AssetsArgs),
    /// Choose an asset for every lifted instance by text and size, MesaTask's recipe
    /// (coarse/retrieval.json).
    Retrieve(StageArgs),
    /// Scale each retrieved asset isometrically into its lifted box: the coarse layout
    /// (coarse/layout.json).
    Place(StageArgs),
    /// Write each scene's annotator pack (pack/): the scene as a GLB for Blender (table,
    /// objects named after their instances, a 1.70 m H1 figure), the photo, a snapshot per
    /// object, index.json and a README for the annotator.
    Pack(StageArgs),
    /// Read each annotator's edited scene (refined/<scene_id>.glb) back into the refined
    /// layout (refined/layout.json) and what changed (refined/diff.json). Scenes whose edited
    /// GLB has not arrived are reported as awaiting annotation.
    Ingest(IngestArgs),
    /// Physics QA of every scene's layout on the assets' collision shapes: colliding pairs with
    /// their penetration depth, floating objects, zone violations, the collision rate
    /// (qa/check.json); with --settle, the least motion that puts the scene at rest
    /// (qa/layout.json, read by later stages). Ends with the dataset summary qa/summary.json.
    Check(CheckArgs),
    /// Extract the scene graph of every scene (graph/graph.json and graph/graph.txt), or print
    /// the triplets of one layout file with --layout.
    Graph(GraphArgs),
    /// Write each scene's table description, tasks and reasoning texts (tasks/tasks.jsonl;
    /// rejected model replies in tasks/rejects.jsonl), with the built-in template writer or a
    /// chat model, live or through offline batches.
    Tasks(TasksArgs),
    /// Merge every scene's tasks into the training records under records/ (SFT, DPO and TRL
    /// files, dataset_info.json, split.json). Run it once, after all scenes (and all shards).
    Records(RecordsArgs),
    /// Render each scene's layout with its assets on the CPU: front, back, left, right and
    /// perspective views (render/<view>.png) with a camera file each; or, with --assets, eight
    /// views around every library asset (assets/renders/<uid>/).
    Render(RenderArgs),
    /// Write the dataset's statistics and plots (report/stats.json, report/*.svg) and one page
    /// with a thumbnail, the QA flags and the files of every scene (report/index.html). Run it
    /// once, after all scenes (and all shards).
    Report(ReportArgs),
    /// Write the MesaTask-10K tree of the dataset: Layout_info/<table_type>/<scene_id>/
    /// {layout.json, front.png} from each scene's refined (or settled) layout and its front
    /// render, and Asset_annotation.json for the assets they use.
    Release(ReleaseArgs),
}

/// Flags shared by every per-scene stage.
#[derive(Debug, Args, Clone)]
pub struct StageArgs {
    /// The dataset folder (holds scenes/, assets/, mesa.toml).
    pub dataset: PathBuf,
    /// Only scenes whose "<table_type>/<scene_id>" or "<scene_id>" matches this glob.
    #[arg(long, value_name = "GLOB")]
    pub scenes: Option<String>,
    /// Worker threads (default: [run] jobs of mesa.toml; 0 = one per core).
    #[arg(short, long, value_name = "N")]
    pub jobs: Option<usize>,
    /// Process only scene k of the sorted scene list when k mod N = I (default: from
    /// SLURM_ARRAY_TASK_ID / SLURM_ARRAY_TASK_COUNT when set).
    #[arg(long, value_name = "I/N")]
    pub shard: Option<Shard>,
    /// Redo every scene, even those whose done marker still matches.
    #[arg(long)]
    pub force: bool,
    /// The configuration file (default: DATASET/mesa.toml when it exists).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Progress display (default: [run] progress of mesa.toml).
    #[arg(long, value_enum)]
    pub progress: Option<ProgressArg>,
}

/// `--layout` of `mesa check`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CheckLayoutArg {
    /// refined/layout.json (written by `mesa ingest` from the annotator's GLB).
    Refined,
    /// coarse/layout.json (written by `mesa place`).
    Coarse,
}

impl From<CheckLayoutArg> for mesa_stages::check::LayoutSource {
    fn from(value: CheckLayoutArg) -> Self {
        match value {
            CheckLayoutArg::Refined => Self::Refined,
            CheckLayoutArg::Coarse => Self::Coarse,
        }
    }
}

/// `mesa check`.
#[derive(Debug, Args)]
pub struct CheckArgs {
    /// The runner flags.
    #[command(flatten)]
    pub stage: StageArgs,
    /// The layout to check (default: [check] layout of mesa.toml, "refined").
    #[arg(long, value_enum)]
    pub layout: Option<CheckLayoutArg>,
    /// Also settle each scene: the least motion that removes collisions and floating, keeping
    /// what holds what; writes qa/layout.json (default: [check] settle of mesa.toml).
    #[arg(long)]
    pub settle: bool,
}

/// `mesa assets`.
#[derive(Debug, Args, Clone)]
pub struct AssetsArgs {
    /// The dataset folder (holds assets/library/<uid>.glb and assets/annotations.json).
    pub dataset: PathBuf,
    /// Worker threads (default: [run] jobs of mesa.toml; 0 = one per core).
    #[arg(short, long, value_name = "N")]
    pub jobs: Option<usize>,
    /// Re-index every asset, even those whose GLB, annotation and configuration are unchanged.
    #[arg(long)]
    pub force: bool,
    /// The configuration file (default: DATASET/mesa.toml when it exists).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Progress display (default: [run] progress of mesa.toml).
    #[arg(long, value_enum)]
    pub progress: Option<ProgressArg>,
    /// Exit with code 1 when some asset is invalid (by default invalid assets are listed, and
    /// retrieval never chooses them).
    #[arg(long)]
    pub strict: bool,
}

/// `--progress`.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum ProgressArg {
    /// A bar on a terminal, periodic lines otherwise.
    Auto,
    /// Always a bar.
    Bar,
    /// Periodic lines.
    Lines,
    /// Only the summary.
    Off,
}

impl From<ProgressArg> for ProgressMode {
    fn from(value: ProgressArg) -> Self {
        match value {
            ProgressArg::Auto => Self::Auto,
            ProgressArg::Bar => Self::Bar,
            ProgressArg::Lines => Self::Lines,
            ProgressArg::Off => Self::Off,
        }
    }
}

/// `mesa run`.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// The runner flags.
    #[command(flatten)]
    pub stage: StageArgs,
    /// Print the resolved configuration (every key, documented) and exit.
    #[arg(long)]
    pub print_config: bool,
}

/// `mesa ingest`.
#[derive(Debug, Args)]
pub struct IngestArgs {
    /// The runner flags.
    #[command(flatten)]
    pub stage: StageArgs,
    /// Ignore nodes that are none of the pack's (overrides [ingest] allow_unknown_nodes);
    /// they are listed in refined/diff.json.
    #[arg(long)]
    pub allow_unknown_nodes: bool,
}

/// `mesa demo`.
#[derive(Debug, Args)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct DemoArgs {
    /// What else to do with a demo dataset.
    #[command(subcommand)]
    pub action: Option<DemoAction>,
    /// The folder to write (created if needed; new, empty, or an earlier `mesa demo` output).
    #[arg(required = true)]
    pub dir: Option<PathBuf>,
    /// Number of scenes; they cycle through the six table types.
    #[arg(long, value_name = "N", default_value_t = 20)]
    pub scenes: usize,
    /// The seed every random choice derives from (with the scene id).
    #[arg(long, value_name = "S", default_value_t = 7)]
    pub seed: u64,
    /// Replace an earlier `mesa demo` output made with other options (its assets/, scenes/
    /// and mesa.toml are deleted first; a folder `mesa demo` did not write is never touched).
    #[arg(long)]
    pub force: bool,
    /// Worker threads (0 = one per core); the output does not depend on it.
    #[arg(short, long, value_name = "N", default_value_t = 0)]
    pub jobs: usize,
}

/// `mesa demo` subcommands.
#[derive(Debug, Subcommand)]
pub enum DemoAction {
    /// Play the annotator on every pack/<scene_id>.glb of a demo dataset: write
    /// refined/<scene_id>.glb as Blender would export it after a person fixed the scene from
    /// the photo (here: from truth/).
    Annotate(StageArgs),
}

/// `mesa status`.
#[derive(Debug, Args)]
pub struct StatusArgs {
    /// The dataset folder.
    pub dataset: PathBuf,
    /// The configuration file (default: DATASET/mesa.toml when it exists).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
}

/// `mesa validate`.
#[derive(Debug, Args)]
pub struct ValidateArgs {
    /// Files or folders (folders: every .json and .jsonl file below them).
    #[arg(required = true)]
    pub paths: Vec<PathBuf>,
    /// The kind of files that carry no "schema" field (official formats): layout,
    /// llm-layout, task-info, gallery-record, camera, instances, sft, dpo, trl-sft, trl-dpo,
    /// dataset-info, ... (`mesa validate --list-kinds` shows all).
    #[arg(long, value_name = "KIND")]
    pub kind: Option<String>,
    /// List the kinds and exit.
    #[arg(long, exclusive = true)]
    pub list_kinds: bool,
}

/// `--to`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LayoutForm {
    /// The LLM layout (cm, z_rotation in degrees, objects by descending footprint).
    Llm,
    /// The dataset layout (cm, quaternion xyzw, retrieved_uid, scale_factor).
    Dataset,
}

/// `mesa convert`.
#[derive(Debug, Args)]
pub struct ConvertArgs {
    /// A dataset layout, an LLM layout, or a published MesaTask record (its
    /// `scene_layout_json`).
    pub input: PathBuf,
    /// The form to write.
    #[arg(long, value_enum)]
    pub to: LayoutForm,
    /// Where to write (default: standard output).
    #[arg(short, long, value_name = "FILE")]
    pub output: Option<PathBuf>,
    /// Keep the input's object order instead of sorting by descending footprint w·d (the
    /// scene graph's "layout order" depends on it).
    #[arg(long)]
    pub keep_order: bool,
}

/// `mesa graph`.
#[derive(Debug, Args)]
#[command(group = clap::ArgGroup::new("source").required(true).args(["dataset", "layout"]))]
pub struct GraphArgs {
    /// The runner flags (a DATASET, or --layout FILE instead).
    #[command(flatten)]
    pub stage: Option<StageArgs>,
    /// Print the triplet lines of one layout file instead: a dataset layout, an LLM layout, or
    /// a published MesaTask record (its scene_layout_json), recognised by shape.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["scenes", "jobs", "shard", "force", "config", "progress"])]
    pub layout: Option<PathBuf>,
    /// With --layout: the containers, comma-separated, by instance (`bowl_0`) or category
    /// (`bowl`: every bowl); "" means no object is a container. Without it, the default
    /// keyword rule of SCENE_GRAPH.md decides (bowl, basket, box, cup, mug, ...; not tray).
    #[arg(long, value_name = "A,B,...", conflicts_with = "dataset")]
    pub containers: Option<String>,
    /// Also write `(a, b, c, are equally spaced along, x|y)` (overrides [graph]
    /// equally_spaced).
    #[arg(long)]
    pub equally_spaced: bool,
}

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
#[derive(Debug, Args)]
pub struct TasksArgs {
    /// The runner flags.
    #[command(flatten)]
    pub stage: StageArgs,
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

/// `mesa records`.
#[derive(Debug, Args)]
pub struct RecordsArgs {
    /// The dataset folder.
    pub dataset: PathBuf,
    /// Worker threads (default: [run] jobs of mesa.toml; 0 = one per core); the files are the
    /// same for any number.
    #[arg(short, long, value_name = "N")]
    pub jobs: Option<usize>,
    /// Rebuild the records even when nothing they read has changed.
    #[arg(long)]
    pub force: bool,
    /// The configuration file (default: DATASET/mesa.toml when it exists).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Progress display (default: [run] progress of mesa.toml).
    #[arg(long, value_enum)]
    pub progress: Option<ProgressArg>,
}

/// `--layout` of `mesa render` and `mesa release`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LayoutArg {
    /// The most refined present: qa/layout.json (settled), else refined/layout.json.
    Refined,
    /// coarse/layout.json (the placement before the annotator).
    Coarse,
    /// truth/layout.json of a `mesa demo` scene.
    Truth,
}

impl From<LayoutArg> for mesa_stages::render::LayoutChoice {
    fn from(value: LayoutArg) -> Self {
        match value {
            LayoutArg::Refined => Self::Refined,
            LayoutArg::Coarse => Self::Coarse,
            LayoutArg::Truth => Self::Truth,
        }
    }
}

/// `mesa render`.
#[derive(Debug, Args)]
pub struct RenderArgs {
    /// The runner flags.
    #[command(flatten)]
    pub stage: StageArgs,
    /// The layout drawn (default: [render] layout of mesa.toml, "refined"). Never falls back
    /// to another: a scene without it fails.
    #[arg(long, value_enum)]
    pub layout: Option<LayoutArg>,
    /// Render the eight views around z of every library asset (assets/renders/<uid>/
    /// view_<azimuth>.png, for annotating assets and checking their front) instead of scenes.
    #[arg(long, conflicts_with_all = ["scenes", "shard", "layout"])]
    pub assets: bool,
    /// With --assets: only assets whose uid matches this glob.
    #[arg(long, value_name = "GLOB", requires = "assets")]
    pub uids: Option<String>,
}

/// `mesa report`.
#[derive(Debug, Args)]
pub struct ReportArgs {
    /// The dataset folder.
    pub dataset: PathBuf,
    /// The configuration file (default: DATASET/mesa.toml when it exists).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Worker threads (default: [run] jobs of mesa.toml; 0 = one per core); the files are the
    /// same for any number.
    #[arg(short, long, value_name = "N")]
    pub jobs: Option<usize>,
}

/// `mesa release`.
#[derive(Debug, Args)]
pub struct ReleaseArgs {
    /// The dataset folder.
    pub dataset: PathBuf,
    /// The folder to write the tree into (new or empty, or an earlier release of this dataset,
    /// which is replaced).
    pub out: PathBuf,
    /// The layout released (default: "refined": qa/layout.json, else refined/layout.json).
    #[arg(long, value_enum)]
    pub layout: Option<LayoutArg>,
    /// Only scenes whose "<table_type>/<scene_id>" or "<scene_id>" matches this glob.
    #[arg(long, value_name = "GLOB")]
    pub scenes: Option<String>,
    /// The configuration file (default: DATASET/mesa.toml when it exists).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Worker threads (default: [run] jobs of mesa.toml; 0 = one per core).
    #[arg(short, long, value_name = "N")]
    pub jobs: Option<usize>,
}

/// `mesa parse-output`.
#[derive(Debug, Args)]
pub struct ParseOutputArgs {
    /// A text file holding one model output.
    pub file: PathBuf,
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn the_cli_is_well_formed() {
        Cli::command().debug_assert();
    }
}
