//! `mesa graph`: the scene graph of every scene (`graph/graph.json`, `graph/graph.txt`), over
//! [`mesa_stages::graph`]; with `--layout FILE`, the triplets of one layout file
//! ([`super::files::print_layout_graph`]).

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;

use anyhow::anyhow;
use clap::Args as ClapArgs;
use mesa_stages::annotations::Annotations;
use mesa_stages::graph::{annotated_containers, extract_graph, GraphOptions};
use mesa_stages::paths::dataset::ANNOTATIONS;
use mesa_stages::paths::scene::{GRAPH_JSON, GRAPH_TXT, LAYOUT_CANDIDATES};

use crate::cli::{DatasetArgs, Global, SceneArgs, SceneSelection};
use crate::dataset_cache::DatasetCache;
use crate::exit::usage;
use crate::layouts::{present_layouts, read_graph_layout};
use crate::runner::{digest_of, Scene, SceneOutput, SceneStage, StageContext};

/// `mesa graph`.
#[derive(Debug, ClapArgs)]
#[command(group = clap::ArgGroup::new("source").required(true).args(["dataset", "layout"]))]
pub struct Args {
    /// The dataset and its run flags (a DATASET, or --layout FILE instead).
    #[command(flatten)]
    pub common: Option<DatasetArgs>,
    /// Which scenes, and whether to redo them.
    #[command(flatten)]
    pub select: SceneSelection,
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

/// Runs `mesa graph`.
pub fn run(args: Args, global: Global) -> anyhow::Result<ExitCode> {
    if let Some(layout) = &args.layout {
        return super::files::print_layout_graph(
            layout,
            args.containers.as_deref(),
            args.equally_spaced,
        );
    }
    let Some(common) = args.common else {
        return Err(usage("give a DATASET, or --layout FILE"));
    };
    let mut resolved = SceneArgs {
        common,
        select: args.select,
    }
    .resolve(global)?;
    if args.equally_spaced {
        resolved.config.graph.equally_spaced = true;
    }
    resolved.run(&GraphStage::new())
}

/// The `graph` stage.
#[derive(Default)]
pub struct GraphStage {
    /// Annotations by dataset folder, read once per run (the file serves every scene).
    annotations: DatasetCache<Option<Annotations>>,
}

impl GraphStage {
    /// A stage with nothing read yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// The dataset's annotations (`None` when it has no annotations file).
    fn annotations(&self, dataset: &Path) -> anyhow::Result<Arc<Option<Annotations>>> {
        self.annotations.get_or_load(dataset, || {
            let path = dataset.join(ANNOTATIONS);
            if path.exists() {
                Ok(Some(Annotations::read(&path)?))
            } else {
                Ok(None)
            }
        })
    }
}

fn no_layout(scene: &Scene) -> anyhow::Error {
    anyhow!(
        "{}: no layout (expected {}; run `mesa place`, `mesa pack`, the annotation, then \
         `mesa ingest` first)",
        scene.dir.display(),
        LAYOUT_CANDIDATES.join(", ")
    )
}

impl SceneStage for GraphStage {
    fn name(&self) -> &'static str {
        "graph"
    }

    fn inputs(&self, ctx: &StageContext<'_>, scene: &Scene) -> anyhow::Result<Vec<String>> {
        // Every layout present counts: a new qa/layout.json makes the graph stale.
        let layouts = present_layouts(scene);
        if layouts.is_empty() {
            return Err(no_layout(scene));
        }
        let mut inputs: Vec<String> = layouts.iter().map(|rel| scene.rel(rel)).collect();
        // Read once a run (the cache), not looked up again for every scene.
        if self.annotations(ctx.dataset)?.is_some() {
            inputs.push(ANNOTATIONS.to_owned());
        }
        Ok(inputs)
    }

    fn config_digest(&self, ctx: &StageContext<'_>) -> String {
        digest_of(&ctx.config.graph)
    }

    fn waiting(&self, _ctx: &StageContext<'_>, scene: &Scene) -> Option<String> {
        crate::scene_docs::awaiting_annotation(scene)
    }

    fn run(&self, ctx: &StageContext<'_>, scene: &Scene) -> anyhow::Result<SceneOutput> {
        let rel = *present_layouts(scene)
            .first()
            .ok_or_else(|| no_layout(scene))?;
        let path = scene.path(rel);
        let loaded = read_graph_layout(&path)?;
        let annotations = self.annotations(ctx.dataset)?;
        let options = GraphOptions::from(&ctx.config.graph);
        let containers = annotated_containers(
            &loaded.scene,
            &loaded.retrieved_uids,
            annotations.as_ref().as_ref(),
            &options,
        );
        let graph = extract_graph(&loaded.scene, &containers.flags, &options)
            .map_err(|e| anyhow!("{}: {e}", path.display()))?;
        let mut output = SceneOutput::new();
        for warning in &loaded.warnings {
            output.warn(format!("{rel}: {warning}"));
        }
        if !containers.by_keyword.is_empty() {
            output.warn(format!(
                "containers by the keyword rule, for want of an annotation: {}",
                containers.by_keyword.join(", ")
            ));
        }
        output.add_file(GRAPH_JSON, graph.to_json(&scene.scene_id, rel));
        output.add_file(GRAPH_TXT, graph.to_text().into_bytes());
        Ok(output)
    }
}
