//! What `tasks` and `records` read of a scene: its layout (the first of `qa/` and `refined/`
//! `layout.json`, the rule of `mesa graph`) in the LLM form, and its scene graph
//! (`graph/graph.txt` and `graph/graph.json`), checked to belong together; and whether a scene
//! still awaits its annotator.

use anyhow::{anyhow, bail, Context as _};
use mesa_schemas::artifacts::{GraphArtifact, MarkerStatus};
use mesa_schemas::convert::llm_from_dataset;
use mesa_schemas::layout_file::AnyLayout;
use mesa_schemas::LlmLayout;
use mesa_stages::paths::scene::{
    pack_glb, refined_glb, COARSE_LAYOUT, GRAPH_JSON, GRAPH_TXT, LAYOUT_CANDIDATES,
};

use crate::fsio::{read_text_bounded, JSON_LIMIT};
use crate::layouts::{chosen_layout, read_layout_file};
use crate::runner::{marker_path, read_marker, Scene};

/// A scene's layout and scene graph.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneDocs {
    /// The layout file used, relative to the scene folder.
    pub layout_rel: &'static str,
    /// SHA-256 of its bytes.
    pub layout_sha256: String,
    /// The layout in the LLM form, objects in the file's order (the scene graph's order).
    pub layout: LlmLayout,
    /// The triplet lines of `graph/graph.txt`.
    pub graph_lines: Vec<String>,
    /// `graph/graph.json`.
    pub graph: GraphArtifact,
    /// What the reader noticed (a tilted object, objects not in descending-footprint order).
    pub warnings: Vec<String>,
}

/// Why a scene cannot go past `ingest` yet: it has no refined (or settled) layout because its
/// annotator has not returned the edited scene, it was not ingested yet, or its ingest failed
/// (the error, and the marker that keeps it). `None` when it has
/// one, or when it is not that far (no coarse layout: the stages before fail instead).
pub fn awaiting_annotation(scene: &Scene) -> Option<String> {
    if chosen_layout(scene).is_some() || !scene.path(COARSE_LAYOUT).is_file() {
        return None;
    }
    let refined = refined_glb(&scene.scene_id);
    if scene.path(&refined).is_file() {
        if let Some(failure) = failed_ingest(scene) {
            return Some(failure);
        }
        return Some(format!(
            "{refined} is in but not ingested yet (run `mesa ingest`)"
        ));
    }
    Some(awaiting_edit(scene))
}

/// The failure of the scene's last `mesa ingest`, when its marker records one: the error and
/// where it is kept, so a later stage does not call an edit that could not be read "not
/// ingested yet".
fn failed_ingest(scene: &Scene) -> Option<String> {
    // The scene folder is `<dataset>/scenes/<table_type>/<scene_id>`.
    let dataset = scene.dir.ancestors().nth(3)?;
    let marker_file = marker_path(dataset, "ingest", scene);
    let marker = read_marker(&marker_file)?;
    if marker.status != MarkerStatus::Failed {
        return None;
    }
    let error = if marker.error.is_empty() {
        "no error recorded".to_owned()
    } else {
        marker.error.join(": ")
    };
    Some(format!(
        "ingest failed: {error} (recorded in {}; fix the edited scene {} and run `mesa ingest` \
         again)",
        marker_file.display(),
        scene.rel(&refined_glb(&scene.scene_id))
    ))
}

/// What a scene without the annotator's edited GLB waits for: the pack to send and where the
/// edit goes, or the pack itself.
pub fn awaiting_edit(scene: &Scene) -> String {
    let refined = refined_glb(&scene.scene_id);
    let pack = pack_glb(&scene.scene_id);
    if scene.path(&pack).is_file() {
        format!(
            "awaiting annotation: send {} (the pack/ folder) to an annotator; put the edited \
             scene at {}",
            scene.rel(&pack),
            scene.rel(&refined)
        )
    } else {
        format!(
            "awaiting annotation: no pack yet (run `mesa pack`), then the annotator's {}",
            scene.rel(&refined)
        )
    }
}

/// The triplet lines `graph.json` stands for, in `graph.txt`'s order.
fn lines_of(graph: &GraphArtifact) -> Vec<String> {
    let mut lines = Vec::with_capacity(2 * graph.nodes.len() + graph.edges.len());
    for node in &graph.nodes {
        lines.push(format!("({}, is at, {})", node.instance, node.is_at));
        lines.push(format!("({}, face to, {})", node.instance, node.face_to));
    }
    for edge in &graph.edges {
        lines.push(format!(
            "({}, {}, {})",
            edge.subject, edge.relation, edge.object
        ));
    }
    for spacing in &graph.equally_spaced {
        let [a, b, c] = &spacing.instances;
        lines.push(format!(
            "({a}, {b}, {c}, are equally spaced along, {})",
            spacing.axis
        ));
    }
    lines
}

/// Reads a scene's layout and scene graph; an error says which file is missing or stale and
/// which stage to rerun.
pub fn read_scene_docs(scene: &Scene) -> anyhow::Result<SceneDocs> {
    let layout_rel = chosen_layout(scene).ok_or_else(|| {
        anyhow!(
            "{}: no layout (expected {}; run `mesa ingest` first)",
            scene.dir.display(),
            LAYOUT_CANDIDATES.join(", ")
        )
    })?;
    let path = scene.path(layout_rel);
    let (read, layout_sha256) = read_layout_file(&path)?;
    let mut warnings = Vec::new();
    let layout = match read.layout {
        AnyLayout::Dataset(dataset) => {
            let converted = llm_from_dataset(&dataset);
            warnings.extend(
                converted
                    .warnings
                    .into_iter()
                    .filter(|w| w.contains("tilted"))
                    .map(|w| format!("{layout_rel}: {w}")),
            );
            converted.layout
        }
        AnyLayout::Llm(llm) => llm,
    };
    let mut sorted = layout.clone();
    if sorted.sort_objects() {
        warnings.push(format!(
            "{layout_rel}: objects are not in descending-footprint order; the records keep the \
             file's order, which the scene graph follows"
        ));
    }

    let graph_path = scene.path(GRAPH_JSON);
    let graph_text = read_text_bounded(&graph_path, JSON_LIMIT).with_context(|| {
        format!(
            "{}: cannot read (run `mesa graph` first)",
            graph_path.display()
        )
    })?;
    let graph: GraphArtifact = serde_json::from_str(&graph_text)
        .with_context(|| format!("{}: not a mesa.graph/1 artifact", graph_path.display()))?;
    if graph.layout != layout_rel {
        bail!(
            "{}: extracted from {}, but the scene's layout is now {layout_rel} (rerun `mesa graph`)",
            graph_path.display(),
            graph.layout
        );
    }
    let nodes: Vec<&str> = graph.nodes.iter().map(|n| n.instance.as_str()).collect();
    let objects: Vec<&str> = layout.objects.iter().map(|o| o.instance.as_str()).collect();
    if nodes != objects {
        bail!(
            "{}: its nodes are not the objects of {layout_rel} in order (rerun `mesa graph`)",
            graph_path.display()
        );
    }
    let txt_path = scene.path(GRAPH_TXT);
    let graph_lines: Vec<String> = read_text_bounded(&txt_path, JSON_LIMIT)
        .with_context(|| {
            format!(
                "{}: cannot read (run `mesa graph` first)",
                txt_path.display()
            )
        })?
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .map(str::to_owned)
        .collect();
    if graph_lines != lines_of(&graph) {
        bail!(
            "{} and {GRAPH_JSON} disagree (rerun `mesa graph`)",
            txt_path.display()
        );
    }
    Ok(SceneDocs {
        layout_rel,
        layout_sha256,
        layout,
        graph_lines,
        graph,
        warnings,
    })
}
