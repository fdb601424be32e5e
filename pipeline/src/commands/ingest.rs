//! `mesa ingest`: the runner adapter of [`mesa_stages::ingest`]: the annotator's
//! `refined/<scene_id>.glb`, the pack it was made from and the pack's layout →
//! `refined/layout.json` and `refined/diff.json`. A scene whose edited GLB has not arrived
//! waits (it is reported, not failed).

use anyhow::{anyhow, bail, Context as _};
use mesa_schemas::annotation::PackIndexArtifact;
use mesa_schemas::layout::DatasetLayout;
use mesa_stages::ingest::{ingest_scene, IngestRequest};

use mesa_stages::paths::scene::{pack_glb, refined_glb, PACK_INDEX, REFINED_DIFF, REFINED_LAYOUT};
use std::process::ExitCode;

use clap::Args as ClapArgs;

use crate::cli::{Global, SceneArgs};
use crate::fsio::read_json;
use crate::fsio::sha256_hex;
use crate::runner::{digest_of, Scene, SceneOutput, SceneStage, StageContext};

/// `mesa ingest`.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// The runner flags.
    #[command(flatten)]
    pub stage: SceneArgs,
    /// Ignore nodes that are none of the pack's (overrides [ingest] allow_unknown_nodes);
    /// they are listed in refined/diff.json.
    #[arg(long)]
    pub allow_unknown_nodes: bool,
}

/// Runs `mesa ingest`.
pub fn run(args: Args, global: Global) -> anyhow::Result<ExitCode> {
    let mut resolved = args.stage.resolve(global)?;
    if args.allow_unknown_nodes {
        resolved.config.ingest.allow_unknown_nodes = true;
    }
    resolved.run(&IngestStage::new())
}

/// The `ingest` stage.
#[derive(Default)]
pub struct IngestStage;

impl IngestStage {
    /// The stage.
    pub fn new() -> Self {
        Self
    }
}

fn index_of(scene: &Scene) -> anyhow::Result<PackIndexArtifact> {
    read_json(&scene.path(PACK_INDEX), "run `mesa pack` to write it")
}

impl SceneStage for IngestStage {
    fn name(&self) -> &'static str {
        "ingest"
    }

    fn before_refined(&self) -> bool {
        true
    }

    fn waiting(&self, _ctx: &StageContext<'_>, scene: &Scene) -> Option<String> {
        let refined = refined_glb(&scene.scene_id);
        if scene.path(&refined).is_file() {
            return None;
        }
        Some(crate::scene_docs::awaiting_edit(scene))
    }

    fn inputs(&self, _ctx: &StageContext<'_>, scene: &Scene) -> anyhow::Result<Vec<String>> {
        let mut inputs = vec![
            scene.rel(&refined_glb(&scene.scene_id)),
            scene.rel(&pack_glb(&scene.scene_id)),
            scene.rel(PACK_INDEX),
        ];
        // The baseline the pack was made from (a missing index is reported by the runner).
        if let Ok(index) = index_of(scene) {
            inputs.push(scene.rel(&index.layout));
        }
        Ok(inputs)
    }

    fn config_digest(&self, ctx: &StageContext<'_>) -> String {
        digest_of(&ctx.config.ingest)
    }

    fn run(&self, ctx: &StageContext<'_>, scene: &Scene) -> anyhow::Result<SceneOutput> {
        let index = index_of(scene)?;
        let baseline_path = scene.path(&index.layout);
        let baseline_bytes = std::fs::read(&baseline_path)
            .with_context(|| format!("{}: cannot read", baseline_path.display()))?;
        if sha256_hex(&baseline_bytes) != index.layout_sha256 {
            bail!(
                "{}: changed since the pack was made ({} holds the digest of the layout the \
                 annotator worked from): restore that layout, or re-run `mesa pack` and have \
                 the new pack annotated",
                baseline_path.display(),
                scene.path(PACK_INDEX).display()
            );
        }
        let baseline: DatasetLayout = serde_json::from_slice(&baseline_bytes)
            .map_err(|e| anyhow!("{}: {e}", baseline_path.display()))?;
        let refined_rel = refined_glb(&scene.scene_id);
        let refined_path = scene.path(&refined_rel);
        let refined = std::fs::read(&refined_path)
            .with_context(|| format!("{}: cannot read", refined_path.display()))?;
        let pack_path = scene.path(&pack_glb(&scene.scene_id));
        let pack = std::fs::read(&pack_path)
            .with_context(|| format!("{}: cannot read", pack_path.display()))?;
        let output = ingest_scene(
            &IngestRequest {
                scene_id: &scene.scene_id,
                refined_glb: &refined,
                refined_rel: &refined_rel,
                pack_glb: &pack,
                index: &index,
                baseline: &baseline,
            },
            &ctx.config.ingest,
        )
        .map_err(|e| anyhow!("{}: {e}", refined_path.display()))?;
        let mut out = SceneOutput::new();
        out.add_json(REFINED_LAYOUT, &output.layout)?;
        out.add_json(REFINED_DIFF, &output.diff)?;
        for warning in &output.diff.warnings {
            out.warn(warning.clone());
        }
        Ok(out)
    }
}
