//! The simulated annotator of demo datasets (`mesa demo annotate DIR`, and `mesa run` when
//! `[annotate] annotator = "simulated"`): each scene's `pack/` and `truth/` →
//! `refined/<scene_id>.glb`, as Blender would export it after a person fixed the scene
//! ([`mesa_stages::demo::annotator`]).

use anyhow::{anyhow, Context as _};
use mesa_schemas::annotation::PackIndexArtifact;
use mesa_schemas::artifacts::TruthInstances;
use mesa_schemas::layout::DatasetLayout;
use mesa_stages::demo::annotator::{annotate_scene, AnnotateRequest};

use super::pack::{pack_glb, refined_glb, PACK_INDEX};
use super::retrieve::read_json;
use crate::runner::{Scene, SceneOutput, SceneStage, StageContext};

/// The demo's true layout, relative to the scene folder.
pub const TRUTH_LAYOUT: &str = "truth/layout.json";
/// The demo's mask id → true instance map, relative to the scene folder.
pub const TRUTH_INSTANCES: &str = "truth/instances.json";

/// The `annotate` stage (demo datasets).
#[derive(Debug, Default)]
pub struct AnnotateStage;

impl SceneStage for AnnotateStage {
    fn name(&self) -> &'static str {
        "annotate"
    }

    fn inputs(&self, _ctx: &StageContext<'_>, scene: &Scene) -> anyhow::Result<Vec<String>> {
        let mut inputs = vec![
            scene.rel(&pack_glb(scene)),
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
        let pack_path = scene.path(&pack_glb(scene));
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
        out.add_file(refined_glb(scene), annotation.glb);
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
