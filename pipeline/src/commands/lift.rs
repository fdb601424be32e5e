//! `mesa lift`: the runner adapter of [`mesa_stages::lift`].

use std::process::ExitCode;

use anyhow::Context as _;
use mesa_stages::lift::lift_scene;
use mesa_stages::paths::scene::{
    points, CAMERA, DEPTH_NPY, DEPTH_PNG, IMAGE, INPUT, INSTANCES, LIFT, MASKS_DIR, MASKS_PNG,
};

use crate::cli::{Global, SceneArgs};
use crate::runner::{digest_of, Scene, SceneOutput, SceneStage, StageContext};

/// `mesa lift`: the runner flags.
pub type Args = SceneArgs;

/// Runs `mesa lift`.
pub fn run(args: Args, global: Global) -> anyhow::Result<ExitCode> {
    args.resolve(global)?.run(&Lift)
}

/// Depth + masks → `coarse/lift.json` and `coarse/points/<instance>.ply`.
pub struct Lift;

impl SceneStage for Lift {
    fn name(&self) -> &'static str {
        "lift"
    }

    fn before_refined(&self) -> bool {
        true
    }

    fn inputs(&self, _: &StageContext<'_>, scene: &Scene) -> anyhow::Result<Vec<String>> {
        let mut inputs = vec![scene.rel(CAMERA), scene.rel(INSTANCES)];
        let depth_png = scene.path(DEPTH_PNG);
        let depth_npy = scene.path(DEPTH_NPY);
        if depth_npy.exists() {
            inputs.push(scene.rel(DEPTH_NPY));
        }
        if depth_png.exists() || !depth_npy.exists() {
            inputs.push(scene.rel(DEPTH_PNG));
        }
        for optional in [MASKS_PNG, IMAGE] {
            if scene.path(optional).exists() {
                inputs.push(scene.rel(optional));
            }
        }
        let folder = scene.path(MASKS_DIR);
        if folder.is_dir() {
            let mut files: Vec<String> = std::fs::read_dir(&folder)
                .with_context(|| format!("{}: cannot list", folder.display()))?
                .filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.ends_with(".png"))
                .collect();
            files.sort();
            inputs.extend(files.iter().map(|n| scene.rel(&format!("{MASKS_DIR}/{n}"))));
        }
        Ok(inputs)
    }

    fn config_digest(&self, ctx: &StageContext<'_>) -> String {
        digest_of(&(&ctx.config.lift, ctx.config.run.seed))
    }

    fn run(&self, ctx: &StageContext<'_>, scene: &Scene) -> anyhow::Result<SceneOutput> {
        let lifted = lift_scene(
            &scene.path(INPUT),
            &scene.scene_id,
            ctx.config.run.seed,
            &ctx.config.lift,
        )?;
        let mut out = SceneOutput::new();
        out.add_json(LIFT, &lifted.artifact)?;
        for (instance, bytes) in lifted.clouds {
            out.add_file(points(&instance), bytes);
        }
        for warning in lifted.warnings {
            out.warn(warning);
        }
        Ok(out)
    }
}
