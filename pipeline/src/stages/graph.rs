//! `mesa graph`: the scene graph of every scene (`graph/graph.json`, `graph/graph.txt`), and
//! of one layout file (`mesa graph --layout FILE`), over [`mesa_stages::graph`].

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::{Arc, Mutex};

use anyhow::{anyhow, bail, Context as _};
use mesa_schemas::convert::category_of_instance;
use mesa_stages::annotations::Annotations;
use mesa_stages::graph::{
    annotated_containers, extract_graph, keyword_containers, read_layout_text, GraphConfig,
    GraphOptions, LayoutReadError, LoadedLayout,
};

use crate::runner::{digest_of, Scene, SceneOutput, SceneStage, StageContext};

/// The layouts the stages after `ingest` read, most refined first: the first one present is
/// used. The coarse layout is not among them: a scene whose annotator has not returned it
/// waits (see [`crate::stages::scene_docs::awaiting_annotation`]).
pub const LAYOUT_CANDIDATES: [&str; 2] = ["qa/layout.json", "refined/layout.json"];

/// The asset annotations, relative to the dataset folder.
pub const ANNOTATIONS: &str = "assets/annotations.json";

/// The `graph` stage.
#[derive(Default)]
pub struct GraphStage {
    /// Annotations by dataset folder, read once per run (the file serves every scene).
    annotations: Mutex<BTreeMap<PathBuf, Result<Arc<Annotations>, String>>>,
}

impl GraphStage {
    /// A stage with nothing read yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// The dataset's annotations, or `None` when it has no annotations file.
    fn annotations(&self, dataset: &Path) -> anyhow::Result<Option<Arc<Annotations>>> {
        let path = dataset.join(ANNOTATIONS);
        if !path.exists() {
            return Ok(None);
        }
        let mut cache = self
            .annotations
            .lock()
            .map_err(|_| anyhow!("internal error: the annotations cache is poisoned"))?;
        let entry = cache.entry(dataset.to_owned()).or_insert_with(|| {
            Annotations::read(&path)
                .map(Arc::new)
                .map_err(|e| e.to_string())
        });
        match entry {
            Ok(annotations) => Ok(Some(Arc::clone(annotations))),
            Err(message) => bail!("{message}"),
        }
    }
}

/// The layout files of a scene that exist, most refined first.
fn present_layouts(scene: &Scene) -> Vec<&'static str> {
    LAYOUT_CANDIDATES
        .into_iter()
        .filter(|rel| scene.path(rel).is_file())
        .collect()
}

fn no_layout(scene: &Scene) -> anyhow::Error {
    anyhow!(
        "{}: no layout (expected {}; run `mesa place`, `mesa pack`, the annotation, then \
         `mesa ingest` first)",
        scene.dir.display(),
        LAYOUT_CANDIDATES.join(", ")
    )
}

/// A layout read error with the file in front of every problem, one per line.
fn in_file(path: &Path, error: &LayoutReadError) -> anyhow::Error {
    let lines: Vec<String> = error
        .problems
        .iter()
        .map(|p| format!("{}: {p}", path.display()))
        .collect();
    anyhow!("{}", lines.join("\n"))
}

fn read_layout(path: &Path) -> anyhow::Result<LoadedLayout> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    read_layout_text(&text).map_err(|e| in_file(path, &e))
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
        if ctx.dataset.join(ANNOTATIONS).exists() {
            inputs.push(ANNOTATIONS.to_owned());
        }
        Ok(inputs)
    }

    fn config_digest(&self, ctx: &StageContext<'_>) -> String {
        digest_of(&ctx.config.graph)
    }

    fn waiting(&self, _ctx: &StageContext<'_>, scene: &Scene) -> Option<String> {
        crate::stages::scene_docs::awaiting_annotation(scene)
    }

    fn run(&self, ctx: &StageContext<'_>, scene: &Scene) -> anyhow::Result<SceneOutput> {
        let rel = *present_layouts(scene)
            .first()
            .ok_or_else(|| no_layout(scene))?;
        let path = scene.path(rel);
        let loaded = read_layout(&path)?;
        let annotations = self.annotations(ctx.dataset)?;
        let options = GraphOptions::from(&ctx.config.graph);
        let containers = annotated_containers(
            &loaded.scene,
            &loaded.retrieved_uids,
            annotations.as_deref(),
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
        output.add_json("graph/graph.json", &graph.to_artifact(&scene.scene_id, rel))?;
        output.add_file("graph/graph.txt", graph.to_text().into_bytes());
        Ok(output)
    }
}

/// The container flags of `--containers`: objects named by instance or by category; `""`
/// names none. Also the names that matched nothing.
pub fn containers_from_list(loaded: &LoadedLayout, list: &str) -> (Vec<bool>, Vec<String>) {
    let names: Vec<&str> = list
        .split(',')
        .map(str::trim)
        .filter(|n| !n.is_empty())
        .collect();
    let objects = &loaded.scene.objects;
    let flags = objects
        .iter()
        .map(|o| {
            names
                .iter()
                .any(|n| *n == o.instance || *n == category_of_instance(&o.instance))
        })
        .collect();
    let unmatched = names
        .iter()
        .filter(|n| {
            !objects
                .iter()
                .any(|o| **n == o.instance || **n == category_of_instance(&o.instance))
        })
        .map(|n| (*n).to_owned())
        .collect();
    (flags, unmatched)
}

/// `mesa graph --layout FILE`: prints the triplet lines of one layout to standard output.
/// Warnings go to standard error; a malformed file is an error naming the file, the object
/// and the field.
pub fn print_layout_graph(
    path: &Path,
    containers: Option<&str>,
    equally_spaced: bool,
) -> anyhow::Result<ExitCode> {
    let loaded = read_layout(path)?;
    let options = GraphOptions::from(&GraphConfig::default()).with_equally_spaced(equally_spaced);
    let flags = match containers {
        None => keyword_containers(&loaded.scene, &options),
        Some(list) => {
            let (flags, unmatched) = containers_from_list(&loaded, list);
            for name in unmatched {
                eprintln!(
                    "warning: {}: --containers: \"{name}\" names no object or category of this layout",
                    path.display()
                );
            }
            flags
        }
    };
    for warning in &loaded.warnings {
        eprintln!("warning: {}: {warning}", path.display());
    }
    let graph = extract_graph(&loaded.scene, &flags, &options)
        .map_err(|e| anyhow!("{}: {e}", path.display()))?;
    print!("{}", graph.to_text());
    Ok(ExitCode::SUCCESS)
}
