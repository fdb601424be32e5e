//! `mesa demo DIR`: a synthetic dataset workspace with ground truth
//! ([`mesa_stages::demo`]); and `mesa demo annotate DIR`, the simulated annotator of demo
//! datasets (also run by `mesa run` when `[annotate] annotator = "simulated"`): each scene's
//! `pack/` and `truth/` → `refined/<scene_id>.glb`, as Blender would export it after a person
//! fixed the scene ([`mesa_stages::demo::annotator`]).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args as ClapArgs, Subcommand};

use crate::cli::{Global, SceneArgs};
use crate::exit::{usage, UsageError};
use crate::runner::thread_pool;

use anyhow::{anyhow, Context as _};
use mesa_schemas::annotation::PackIndexArtifact;
use mesa_schemas::artifacts::TruthInstances;
use mesa_schemas::layout::DatasetLayout;
use mesa_stages::demo::annotator::{annotate_scene, AnnotateRequest};

/// `mesa demo`.
#[derive(Debug, ClapArgs)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct Args {
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
    Annotate(SceneArgs),
}

/// Runs `mesa demo`.
pub fn run(args: Args, global: Global) -> anyhow::Result<ExitCode> {
    use mesa_stages::demo::{write_demo, DemoError, DemoOptions};
    if let Some(DemoAction::Annotate(stage)) = &args.action {
        return stage.resolve(global)?.run(&AnnotateStage);
    }
    let Some(dir) = args.dir.clone() else {
        return Err(usage("give the folder to write: `mesa demo DIR`"));
    };
    let options = DemoOptions::default()
        .with_scenes(args.scenes)
        .with_seed(args.seed)
        .with_overwrite(args.force);
    let pool = thread_pool(args.jobs)?;
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
    if !global.quiet {
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

use crate::fsio::read_json;
use crate::runner::{Scene, SceneOutput, SceneStage, StageContext};
use mesa_stages::paths::scene::{pack_glb, refined_glb, PACK_INDEX, TRUTH_INSTANCES, TRUTH_LAYOUT};

/// The `annotate` stage (demo datasets).
#[derive(Debug, Default)]
pub struct AnnotateStage;

impl SceneStage for AnnotateStage {
    fn name(&self) -> &'static str {
        "annotate"
    }

    fn before_refined(&self) -> bool {
        true
    }

    fn inputs(&self, _ctx: &StageContext<'_>, scene: &Scene) -> anyhow::Result<Vec<String>> {
        let mut inputs = vec![
            scene.rel(&pack_glb(&scene.scene_id)),
            scene.rel(PACK_INDEX),
            scene.rel(TRUTH_LAYOUT),
            scene.rel(TRUTH_INSTANCES),
        ];
        if let Ok(index) = read_json::<PackIndexArtifact>(&scene.path(PACK_INDEX), "mesa pack") {
            inputs.push(scene.rel(&index.layout));
        }
        Ok(inputs)
    }

    fn config_digest(&self, ctx: &StageContext<'_>) -> String {
        // The seed chooses the scenes where an object is made again from its twin.
        crate::runner::digest_of(&ctx.config.run.seed)
    }

    fn run(&self, ctx: &StageContext<'_>, scene: &Scene) -> anyhow::Result<SceneOutput> {
        let index: PackIndexArtifact = read_json(&scene.path(PACK_INDEX), "run `mesa pack`")?;
        let baseline: DatasetLayout = read_json(&scene.path(&index.layout), "run `mesa place`")?;
        let truth: DatasetLayout = read_json(
            &scene.path(TRUTH_LAYOUT),
            "the simulated annotator needs a demo scene's truth/ (made by `mesa demo`)",
        )?;
        let truth_instances: TruthInstances = read_json(
            &scene.path(TRUTH_INSTANCES),
            "the simulated annotator needs a demo scene's truth/ (made by `mesa demo`)",
        )?;
        let pack_path = scene.path(&pack_glb(&scene.scene_id));
        let pack = std::fs::read(&pack_path)
            .with_context(|| format!("{}: cannot read", pack_path.display()))?;
        let annotation = annotate_scene(&AnnotateRequest {
            scene_id: &scene.scene_id,
            pack_glb: &pack,
            index: &index,
            baseline: &baseline,
            truth: &truth,
            truth_instances: &truth_instances,
            seed: ctx.config.run.seed,
        })
        .map_err(|e| anyhow!("{}: {e}", pack_path.display()))?;
        let mut out = SceneOutput::new();
        out.add_file(refined_glb(&scene.scene_id), annotation.glb);
        if !annotation.missing.is_empty() {
            out.warn(format!(
                "true objects the simulated annotator could not make (no object of their asset \
                 to copy): {}",
                annotation.missing.join(", ")
            ));
        }
        Ok(out)
    }
}
