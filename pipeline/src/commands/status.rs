//! `mesa status`: per per-scene stage, how many scenes are done, stale, failed, waiting and
//! pending, and which scenes were imported at the refined stage (the stages before it do
//! not apply to them), from the done markers (nothing is run).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args as ClapArgs;

use super::pipeline::scene_stages;
use crate::cli::Global;
use crate::config::Config;
use crate::exit::UsageError;
use crate::fsio::DigestCache;
use crate::runner::{discover_scenes, scene_state, RunError, SceneState, StageContext};

/// `mesa status`.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// The dataset folder.
    pub dataset: PathBuf,
    /// The configuration file (default: DATASET/mesa.toml when it exists).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
}

/// Runs `mesa status`.
pub fn run(args: Args, _global: Global) -> anyhow::Result<ExitCode> {
    let config = Config::load(&args.dataset, args.config.as_deref())
        .map_err(|e| UsageError(e.to_string()))?;
    let ctx = StageContext {
        dataset: &args.dataset,
        config: &config,
    };
    let scenes = discover_scenes(&args.dataset).map_err(RunError::into_anyhow)?;
    let cache = DigestCache::default();
    let mut out = String::new();
    out.push_str(&format!(
        "{}: {} scenes{}\n{:<10} {:>7} {:>7} {:>7} {:>7} {:>7} {:>8}\n",
        args.dataset.display(),
        scenes.len(),
        match scenes.iter().filter(|s| s.imported()).count() {
            0 => String::new(),
            n => format!(" ({n} imported: they enter at the refined stage)"),
        },
        "stage",
        "done",
        "stale",
        "failed",
        "waiting",
        "pending",
        "imported"
    ));
    let mut notes = Vec::new();
    // Scenes awaiting annotation, once each (every stage after ingest waits for them too).
    let mut awaiting = std::collections::BTreeMap::new();
    for stage in scene_stages(&config) {
        let digest = stage.config_digest(&ctx);
        let (mut done, mut stale, mut failed, mut waiting, mut pending, mut imported) =
            (0, 0, 0, 0, 0, 0);
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
                SceneState::Imported => imported += 1,
            }
        }
        out.push_str(&format!(
            "{:<10} {done:>7} {stale:>7} {failed:>7} {waiting:>7} {pending:>7} {imported:>8}\n",
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
