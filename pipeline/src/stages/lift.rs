//! `mesa lift`: the runner adapter of [`mesa_stages::lift`].

use anyhow::Context as _;
use mesa_stages::lift::lift_scene;

use crate::runner::{digest_of, Scene, SceneOutput, SceneStage, StageContext};

/// Depth + masks → `coarse/lift.json` and `coarse/points/<instance>.ply`.
pub struct Lift;

impl SceneStage for Lift {
    fn name(&self) -> &'static str {
        "lift"
    }

    fn inputs(&self, _: &StageContext<'_>, scene: &Scene) -> anyhow::Result<Vec<String>> {
        let mut inputs = vec![
            scene.rel("input/camera.json"),
            scene.rel("input/instances.json"),
        ];
        let depth_png = scene.path("input/depth.png");
        let depth_npy = scene.path("input/depth.npy");
        if depth_npy.exists() {
            inputs.push(scene.rel("input/depth.npy"));
        }
        if depth_png.exists() || !depth_npy.exists() {
            inputs.push(scene.rel("input/depth.png"));
        }
        for optional in ["input/masks.png", "input/image.png"] {
            if scene.path(optional).exists() {
                inputs.push(scene.rel(optional));
            }
        }
        let folder = scene.path("input/masks");
        if folder.is_dir() {
            let mut files: Vec<String> = std::fs::read_dir(&folder)
                .with_context(|| format!("{}: cannot list", folder.display()))?
                .filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.ends_with(".png"))
                .collect();
            files.sort();
            inputs.extend(files.iter().map(|n| scene.rel(&format!("input/masks/{n}"))));
        }
        Ok(inputs)
    }

    fn config_digest(&self, ctx: &StageContext<'_>) -> String {
        digest_of(&(&ctx.config.lift, ctx.config.run.seed))
    }

    fn run(&self, ctx: &StageContext<'_>, scene: &Scene) -> anyhow::Result<SceneOutput> {
        let lifted = lift_scene(
            &scene.path("input"),
            &scene.scene_id,
            ctx.config.run.seed,
            &ctx.config.lift,
        )?;
        let mut out = SceneOutput::new();
        out.add_json("coarse/lift.json", &lifted.artifact)?;
        for (instance, bytes) in lifted.clouds {
            out.add_file(format!("coarse/points/{instance}.ply"), bytes);
        }
        for warning in lifted.warnings {
            out.warn(warning);
        }
        Ok(out)
    }
}
