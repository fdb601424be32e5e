//! The command line's shared parts: the global flags as commands see them, the flag groups every command over a
//! dataset flattens in ([`DatasetArgs`], [`SceneArgs`]), and how they resolve against
//! `mesa.toml` and the Slurm environment ([`Resolved`]). Each command's own flags live in its
//! file under [`crate::commands`]; doc comments are the `--help` text.

// Doc comments here are `--help` text, read by rustdoc as links and HTML tags: see the same
// allowance in commands/mod.rs.
#![allow(rustdoc::broken_intra_doc_links, rustdoc::invalid_html_tags)]

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use clap::{Args, ValueEnum};

use crate::config::{Config, ProgressMode};
use crate::exit::{usage, UsageError};
use crate::runner::dataset::run_and_report_dataset;
use crate::runner::{run_and_report, DatasetStage, RunOptions, SceneStage, Shard, StageContext};

/// The global flags, as every command sees them.
#[derive(Debug, Clone, Copy)]
pub struct Global {
    /// `--quiet`.
    pub quiet: bool,
}

/// Flags of every command over a dataset.
#[derive(Debug, Args, Clone)]
pub struct DatasetArgs {
    /// The dataset folder (holds scenes/, assets/, mesa.toml).
    pub dataset: PathBuf,
    /// Worker threads (default: [run] jobs of mesa.toml; 0 = one per core); the files are
    /// the same for any number.
    #[arg(short, long, value_name = "N")]
    pub jobs: Option<usize>,
    /// The configuration file (default: DATASET/mesa.toml when it exists).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Progress display (default: [run] progress of mesa.toml).
    #[arg(long, value_enum)]
    pub progress: Option<ProgressArg>,
}

/// Flags of every per-scene stage.
#[derive(Debug, Args, Clone)]
pub struct SceneArgs {
    /// The dataset and its run flags.
    #[command(flatten)]
    pub common: DatasetArgs,
    /// Which scenes, and whether to redo them.
    #[command(flatten)]
    pub select: SceneSelection,
}

/// Which scenes a per-scene stage runs.
#[derive(Debug, Args, Clone)]
pub struct SceneSelection {
    /// Only scenes whose "<table_type>/<scene_id>" or "<scene_id>" matches this glob.
    #[arg(long, value_name = "GLOB")]
    pub scenes: Option<String>,
    /// Process only scene k of the sorted scene list when k mod N = I (default: from
    /// SLURM_ARRAY_TASK_ID / SLURM_ARRAY_TASK_COUNT when set).
    #[arg(long, value_name = "I/N")]
    pub shard: Option<Shard>,
    /// Redo every scene, even those whose done marker still matches.
    #[arg(long)]
    pub force: bool,
}

/// Flags of a dataset-level stage that keeps what is current (`mesa assets`, `mesa records`).
#[derive(Debug, Args, Clone)]
pub struct DatasetStageArgs {
    /// The dataset and its run flags.
    #[command(flatten)]
    pub common: DatasetArgs,
    /// Redo the work even when nothing it reads has changed (every asset is re-indexed, the
    /// records rebuilt).
    #[arg(long)]
    pub force: bool,
}

impl DatasetStageArgs {
    /// Resolves the flags against `mesa.toml`, with `--force`.
    pub fn resolve(&self, global: Global) -> anyhow::Result<Resolved> {
        let mut resolved = self.common.resolve(global)?;
        resolved.options.force = self.force;
        Ok(resolved)
    }
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

/// The resolved configuration and runner options of a command over a dataset.
pub struct Resolved {
    /// The dataset folder.
    pub dataset: PathBuf,
    /// The configuration (with the command's overrides applied by the command).
    pub config: Config,
    /// The runner options.
    pub options: RunOptions,
}

impl Resolved {
    /// What a stage sees.
    pub fn ctx(&self) -> StageContext<'_> {
        StageContext {
            dataset: &self.dataset,
            config: &self.config,
        }
    }

    /// Runs a per-scene stage: preflight, the scenes, the summary, the exit code.
    pub fn run(&self, stage: &dyn SceneStage) -> anyhow::Result<ExitCode> {
        stage.preflight(&self.ctx())?;
        run_and_report(stage, &self.ctx(), &self.options)
    }

    /// Runs a dataset-level stage: preflight, the work, the summary, the exit code.
    pub fn run_dataset(&self, stage: &dyn DatasetStage) -> anyhow::Result<ExitCode> {
        stage.preflight(&self.ctx())?;
        run_and_report_dataset(stage, &self.ctx(), &self.options)
    }
}

impl DatasetArgs {
    /// Resolves the flags against `mesa.toml`: the whole dataset, one shard, no `--force`.
    pub fn resolve(&self, global: Global) -> anyhow::Result<Resolved> {
        if !self.dataset.is_dir() {
            return Err(usage(format!(
                "{}: no such dataset folder (expected a folder with scenes/; `mesa demo DIR` \
                 writes one)",
                self.dataset.display()
            )));
        }
        let config = Config::load(&self.dataset, self.config.as_deref())
            .map_err(|e| UsageError(e.to_string()))?;
        let mut options = RunOptions::from_config(&config);
        if let Some(jobs) = self.jobs {
            options.jobs = jobs;
        }
        if let Some(progress) = self.progress {
            options.progress = progress.into();
        }
        if global.quiet {
            options.progress = ProgressMode::Off;
            options.quiet = true;
        }
        options.progress_interval =
            Duration::from_secs_f64(config.run.progress_interval_s.max(0.1));
        Ok(Resolved {
            dataset: self.dataset.clone(),
            config,
            options,
        })
    }
}

impl SceneArgs {
    /// Resolves the flags against `mesa.toml` and the Slurm environment.
    pub fn resolve(&self, global: Global) -> anyhow::Result<Resolved> {
        let mut resolved = self.common.resolve(global)?;
        let select = &self.select;
        resolved.options.scenes = select.scenes.clone();
        resolved.options.shard = match select.shard {
            Some(shard) => shard,
            None => Shard::from_slurm_env()
                .map_err(UsageError)?
                .unwrap_or_default(),
        };
        resolved.options.force = select.force;
        Ok(resolved)
    }
}
