//! `mesa place`: the runner adapter of [`mesa_stages::place`]: `coarse/lift.json`,
//! `coarse/retrieval.json` and the asset index → `coarse/layout.json`.

use mesa_stages::paths::scene::{COARSE_LAYOUT, LIFT, RETRIEVAL};
use std::sync::Arc;

use mesa_schemas::artifacts::{AssetIndexArtifact, LiftArtifact, RetrievalArtifact};
use mesa_stages::annotations::Annotations;
use mesa_stages::place::place_scene;

use crate::cli::{Global, SceneArgs};
use crate::dataset_cache::{read_annotations, DatasetCache};
use crate::fsio::read_json;
use crate::runner::{digest_of, Scene, SceneOutput, SceneStage, StageContext};
use mesa_stages::paths::dataset::{ANNOTATIONS, INDEX};
use std::process::ExitCode;

/// `mesa place`: the runner flags.
pub type Args = SceneArgs;

/// Runs `mesa place`.
pub fn run(args: Args, global: Global) -> anyhow::Result<ExitCode> {
    args.resolve(global)?.run(&PlaceStage::new())
}

/// What placement reads once per dataset and run.
struct Library {
    index: AssetIndexArtifact,
    annotations: Annotations,
}

/// The `place` stage.
#[derive(Default)]
pub struct PlaceStage {
    libraries: DatasetCache<Library>,
}

impl PlaceStage {
    /// A stage with nothing loaded yet.
    pub fn new() -> Self {
        Self::default()
    }

    fn library(&self, ctx: &StageContext<'_>) -> anyhow::Result<Arc<Library>> {
        self.libraries.get_or_load(ctx.dataset, || {
            let index = read_json(&ctx.dataset.join(INDEX), "run `mesa assets` to write it")?;
            let annotations = read_annotations(ctx.dataset)?;
            Ok(Library { index, annotations })
        })
    }
}

impl SceneStage for PlaceStage {
    fn name(&self) -> &'static str {
        "place"
    }

    fn before_refined(&self) -> bool {
        true
    }

    fn inputs(&self, ctx: &StageContext<'_>, scene: &Scene) -> anyhow::Result<Vec<String>> {
        let mut inputs = vec![scene.rel(LIFT), scene.rel(RETRIEVAL), INDEX.to_owned()];
        if ctx.dataset.join(ANNOTATIONS).exists() {
            inputs.push(ANNOTATIONS.to_owned());
        }
        Ok(inputs)
    }

    fn config_digest(&self, ctx: &StageContext<'_>) -> String {
        digest_of(&ctx.config.place)
    }

    fn run(&self, ctx: &StageContext<'_>, scene: &Scene) -> anyhow::Result<SceneOutput> {
        let lift: LiftArtifact = read_json(&scene.path(LIFT), "run `mesa lift` to write it")?;
        let retrieval: RetrievalArtifact =
            read_json(&scene.path(RETRIEVAL), "run `mesa retrieve` to write it")?;
        let library = self.library(ctx)?;
        let placed = place_scene(
            &lift,
            &retrieval,
            &library.index,
            &library.annotations,
            &ctx.config.place,
        )?;
        let mut out = SceneOutput::new();
        out.add_json(COARSE_LAYOUT, &placed.layout)?;
        for warning in placed.warnings {
            out.warn(warning);
        }
        Ok(out)
    }
}
