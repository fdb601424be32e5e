//! `mesa retrieve`: the runner adapter of [`mesa_stages::retrieve`]: `coarse/lift.json` and the
//! asset index → `coarse/retrieval.json`.

use mesa_stages::paths::scene::{INSTANCES, LIFT, RETRIEVAL};
use std::sync::Arc;

use anyhow::bail;
use mesa_schemas::artifacts::{AssetIndexArtifact, LiftArtifact, TextIndexArtifact};
use mesa_stages::retrieve::features::FeatureMatrix;
use mesa_stages::retrieve::lexical::LexicalIndex;
use mesa_stages::retrieve::{
    query_embeddings, query_text, retrieve_scene, Catalog, Encoder, Query, TextScorer,
};

use mesa_stages::paths::dataset::{ANNOTATIONS, INDEX, TEXT_FEATURES, TEXT_INDEX, TEXT_UIDS};
use mesa_stages::paths::scene::QUERY_FEATURES;

use crate::cli::{Global, SceneArgs};
use crate::dataset_cache::{read_annotations, DatasetCache};
use crate::fsio::read_json;
use crate::runner::{digest_of, Scene, SceneOutput, SceneStage, StageContext};
use std::process::ExitCode;

/// `mesa retrieve`: the runner flags.
pub type Args = SceneArgs;

/// Runs `mesa retrieve`.
pub fn run(args: Args, global: Global) -> anyhow::Result<ExitCode> {
    args.resolve(global)?.run(&RetrieveStage::new())
}

/// The asset side of retrieval, loaded once per dataset and run.
struct Library {
    scorer: TextScorer,
    catalog: Catalog,
}

/// The `retrieve` stage.
#[derive(Default)]
pub struct RetrieveStage {
    libraries: DatasetCache<Library>,
}

impl RetrieveStage {
    /// A stage with nothing loaded yet.
    pub fn new() -> Self {
        Self::default()
    }

    fn library(&self, ctx: &StageContext<'_>) -> anyhow::Result<Arc<Library>> {
        self.libraries
            .get_or_load(ctx.dataset, || load_library(ctx))
    }
}

fn load_library(ctx: &StageContext<'_>) -> anyhow::Result<Library> {
    let index: AssetIndexArtifact =
        read_json(&ctx.dataset.join(INDEX), "run `mesa assets` to write it")?;
    let annotations = read_annotations(ctx.dataset)?;
    let scorer = match ctx.config.retrieve.encoder {
        Encoder::Lexical => {
            let text: TextIndexArtifact = read_json(
                &ctx.dataset.join(TEXT_INDEX),
                "run `mesa assets` to write it",
            )?;
            TextScorer::Lexical(LexicalIndex::new(&text))
        }
        Encoder::Features => TextScorer::Features(FeatureMatrix::read(
            &ctx.dataset.join(TEXT_FEATURES),
            &ctx.dataset.join(TEXT_UIDS),
        )?),
    };
    let catalog = Catalog::new(scorer.uids(), &annotations, &index);
    if catalog.choosable() == 0 {
        bail!(
            "no asset can be chosen: none of the {} assets of the {} encoder has an annotation, \
             a valid GLB and passes the filters (see {INDEX})",
            scorer.uids().len(),
            scorer.name()
        );
    }
    Ok(Library { scorer, catalog })
}

impl SceneStage for RetrieveStage {
    fn name(&self) -> &'static str {
        "retrieve"
    }

    fn before_refined(&self) -> bool {
        true
    }

    fn inputs(&self, ctx: &StageContext<'_>, scene: &Scene) -> anyhow::Result<Vec<String>> {
        let mut inputs = vec![scene.rel(LIFT), INDEX.to_owned()];
        if ctx.dataset.join(ANNOTATIONS).exists() {
            inputs.push(ANNOTATIONS.to_owned());
        }
        match ctx.config.retrieve.encoder {
            Encoder::Lexical => inputs.push(TEXT_INDEX.to_owned()),
            Encoder::Features => {
                inputs.push(TEXT_FEATURES.to_owned());
                inputs.push(TEXT_UIDS.to_owned());
                inputs.push(scene.rel(INSTANCES));
                if scene.path(QUERY_FEATURES).exists() {
                    inputs.push(scene.rel(QUERY_FEATURES));
                }
            }
        }
        Ok(inputs)
    }

    fn config_digest(&self, ctx: &StageContext<'_>) -> String {
        digest_of(&ctx.config.retrieve)
    }

    fn run(&self, ctx: &StageContext<'_>, scene: &Scene) -> anyhow::Result<SceneOutput> {
        let lift: LiftArtifact = read_json(&scene.path(LIFT), "run `mesa lift` to write it")?;
        let library = self.library(ctx)?;
        let config = &ctx.config.retrieve;
        let queries: Vec<Query> = match config.encoder {
            Encoder::Lexical => lift
                .instances
                .iter()
                .map(|i| Query::Text(query_text(i, config)))
                .collect(),
            Encoder::Features => {
                let sidecar = scene.path(QUERY_FEATURES);
                query_embeddings(
                    &scene.path(INSTANCES),
                    sidecar.exists().then_some(sidecar.as_path()),
                    &lift,
                )?
                .into_iter()
                .map(Query::Embedding)
                .collect()
            }
        };
        let retrieved = retrieve_scene(&lift, &queries, &library.scorer, &library.catalog, config)?;
        let mut out = SceneOutput::new();
        out.add_json(RETRIEVAL, &retrieved.artifact)?;
        for warning in retrieved.warnings {
            out.warn(warning);
        }
        Ok(out)
    }
}
