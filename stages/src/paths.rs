//! Where every artifact of a dataset lives (SPEC section 3, the workspace): the one owner of
//! these paths. Stages read and write through these names, and each stage's declared inputs
//! (the runner's skip-done digests) are built from the same names, so what a stage reads and
//! what it declares cannot drift apart.
//!
//! Scene paths are relative to the scene folder `scenes/<table_type>/<scene_id>/`; dataset
//! paths are relative to the dataset folder.

/// Dataset paths (relative to the dataset folder).
pub mod dataset {
    /// The configuration file.
    pub const CONFIG: &str = "mesa.toml";
    /// The scenes: `scenes/<table_type>/<scene_id>/`.
    pub const SCENES: &str = "scenes";
    /// mesa's own records: markers, run records, caches, the resolved configuration.
    pub const RUN_DIR: &str = ".mesa";
    /// The resolved configuration of the last `mesa run`.
    pub const RESOLVED_CONFIG: &str = ".mesa/config.resolved.toml";
    /// The asset library: `assets/library/<uid>.glb`.
    pub const LIBRARY: &str = "assets/library";
    /// The asset annotations.
    pub const ANNOTATIONS: &str = "assets/annotations.json";
    /// The asset index (written last by `mesa assets`: an index that exists is complete).
    pub const INDEX: &str = "assets/index/assets.json";
    /// The lexical text index.
    pub const TEXT_INDEX: &str = "assets/index/text.json";
    /// The collision shapes: `assets/index/shapes/<uid>.json`.
    pub const SHAPES_DIR: &str = "assets/index/shapes";
    /// The asset embeddings of the `features` encoder.
    pub const TEXT_FEATURES: &str = "assets/text_features.npy";
    /// What `mesa import` read and normalised, dataset-wide (counts, missing GLBs).
    pub const IMPORT_SUMMARY: &str = "assets/import.json";
    /// The uid of each row of [`TEXT_FEATURES`].
    pub const TEXT_UIDS: &str = "assets/text_uids.json";
    /// The views around every asset: `assets/renders/<uid>/`.
    pub const ASSET_RENDERS: &str = "assets/renders";
    /// The simulator files of every asset (`mesa export --assets`): `assets/sim/<uid>/`.
    pub const ASSET_SIM: &str = "assets/sim";
    /// The dataset's check summary.
    pub const CHECK_SUMMARY: &str = "qa/summary.json";
    /// The training records.
    pub const RECORDS_DIR: &str = "records";
    /// The report.
    pub const REPORT_DIR: &str = "report";
    /// The chat reply cache.
    pub const CHAT_CACHE: &str = ".mesa/cache/chat";
    /// The replies `mesa annotate assets` rejected, with their reasons.
    pub const ANNOTATE_REJECTS: &str = "assets/annotate/rejects.jsonl";
    /// The replies `mesa annotate instances` rejected, with their reasons.
    pub const INSTANCE_REJECTS: &str = "assets/annotate/instance_rejects.jsonl";
    /// What the last `mesa annotate assets` run did (counts by source, requests).
    pub const ANNOTATE_SUMMARY: &str = "assets/annotate/summary.json";

    /// The collision shapes file of an asset.
    pub fn shapes(uid: &str) -> String {
        format!("{SHAPES_DIR}/{uid}.json")
    }

    /// The GLB of an asset.
    pub fn asset_glb(uid: &str) -> String {
        format!("{LIBRARY}/{uid}.glb")
    }
}

/// Scene paths (relative to the scene folder).
pub mod scene {
    /// The raw inputs: photo, depth, masks, camera, instances.
    pub const INPUT: &str = "input";
    /// The camera.
    pub const CAMERA: &str = "input/camera.json";
    /// The instances (labels, descriptions, masks).
    pub const INSTANCES: &str = "input/instances.json";
    /// Depth in millimetres (16-bit PNG).
    pub const DEPTH_PNG: &str = "input/depth.png";
    /// Depth in metres (NPY).
    pub const DEPTH_NPY: &str = "input/depth.npy";
    /// All instance masks in one PNG.
    pub const MASKS_PNG: &str = "input/masks.png";
    /// One mask PNG per instance.
    pub const MASKS_DIR: &str = "input/masks";
    /// The photo.
    pub const IMAGE: &str = "input/image.png";
    /// Query embeddings of the instances (optional).
    pub const QUERY_FEATURES: &str = "input/query_features.npy";
    /// The lifted boxes.
    pub const LIFT: &str = "coarse/lift.json";
    /// The lifted point clouds: `coarse/points/<instance>.ply`.
    pub const POINTS_DIR: &str = "coarse/points";
    /// The retrieval.
    pub const RETRIEVAL: &str = "coarse/retrieval.json";
    /// The coarse layout (`mesa place`).
    pub const COARSE_LAYOUT: &str = "coarse/layout.json";
    /// The pack's index.
    pub const PACK_INDEX: &str = "pack/index.json";
    /// The refined layout (`mesa ingest`).
    pub const REFINED_LAYOUT: &str = "refined/layout.json";
    /// What the annotator changed.
    pub const REFINED_DIFF: &str = "refined/diff.json";
    /// The check report.
    pub const CHECK: &str = "qa/check.json";
    /// The settled layout (`mesa check --settle`), read first by the later stages.
    pub const SETTLED_LAYOUT: &str = "qa/layout.json";
    /// The scene graph with its numbers and node flags.
    pub const GRAPH_JSON: &str = "graph/graph.json";
    /// The scene graph's triplet lines.
    pub const GRAPH_TXT: &str = "graph/graph.txt";
    /// The renders.
    pub const RENDER_DIR: &str = "render";
    /// The tasks.
    pub const TASKS: &str = "tasks/tasks.jsonl";
    /// The rejected model replies.
    pub const REJECTS: &str = "tasks/rejects.jsonl";
    /// Where an imported scene came from and what the import dropped, fixed or found missing
    /// (`mesa import`; its presence marks the scene as imported).
    pub const IMPORT_NOTES: &str = "imported/import.json";
    /// The released scene's `front.png`, kept as its reference picture (`mesa import`).
    pub const IMPORT_FRONT: &str = "imported/front.png";
    /// The simulator export's folder (`mesa export`).
    pub const SIM_DIR: &str = "sim";
    /// The simulator export's manifest.
    pub const EXPORT_MANIFEST: &str = "sim/export.json";
    /// The MJCF export: `scene.xml` and `meshes/`.
    pub const MJCF_DIR: &str = "sim/mjcf";
    /// The URDF export: a URDF per object, `table.urdf` and `scene.json`.
    pub const URDF_DIR: &str = "sim/urdf";
    /// The USD export, one text file.
    pub const USD_SCENE: &str = "sim/usd/scene.usda";
    /// The export's base-colour images (PNG), one per asset image, shared by the three formats.
    pub const TEXTURES_DIR: &str = "sim/textures";
    /// The demo's true layout.
    pub const TRUTH_LAYOUT: &str = "truth/layout.json";
    /// The demo's true instances.
    pub const TRUTH_INSTANCES: &str = "truth/instances.json";

    /// The layouts the stages after `ingest` read, most refined first: the first present is
    /// the scene's layout (a settled layout wins over the refined one).
    pub const LAYOUT_CANDIDATES: [&str; 2] = [SETTLED_LAYOUT, REFINED_LAYOUT];

    /// The annotator pack's scene GLB.
    pub fn pack_glb(scene_id: &str) -> String {
        format!("pack/{scene_id}.glb")
    }

    /// The annotator's edited scene GLB.
    pub fn refined_glb(scene_id: &str) -> String {
        format!("refined/{scene_id}.glb")
    }

    /// The point cloud of an instance.
    pub fn points(instance: &str) -> String {
        format!("{POINTS_DIR}/{instance}.ply")
    }
}

/// Who writes a file a stage reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Writer {
    /// The user: a raw input of a scene (`input/`), the asset library or its annotations, the
    /// configuration. No stage writes it.
    User,
    /// The annotator, in Blender (the edited scene GLB).
    Annotator,
    /// A stage (its subcommand name).
    Stage(&'static str),
}

/// Who writes `rel`: a path relative to the dataset (`scenes/<table_type>/<scene_id>/...` for a
/// scene file). `None` when mesa does not know the path.
pub fn writer_of(rel: &str) -> Option<Writer> {
    let in_scene = rel
        .strip_prefix(&format!("{}/", dataset::SCENES))
        .and_then(|rest| rest.splitn(3, '/').nth(2));
    if let Some(file) = in_scene {
        let top = file.split('/').next().unwrap_or("");
        return match top {
            "input" => Some(Writer::User),
            "truth" => Some(Writer::Stage("demo")),
            "imported" => Some(Writer::Stage("import")),
            "coarse" if file == scene::RETRIEVAL => Some(Writer::Stage("retrieve")),
            "coarse" if file == scene::COARSE_LAYOUT => Some(Writer::Stage("place")),
            "coarse" => Some(Writer::Stage("lift")),
            "pack" => Some(Writer::Stage("pack")),
            "refined" if file.ends_with(".glb") => Some(Writer::Annotator),
            "refined" => Some(Writer::Stage("ingest")),
            "qa" => Some(Writer::Stage("check")),
            "graph" => Some(Writer::Stage("graph")),
            "render" => Some(Writer::Stage("render")),
            "tasks" => Some(Writer::Stage("tasks")),
            _ => None,
        };
    }
    if rel == dataset::CONFIG
        || rel == dataset::ANNOTATIONS
        || rel.starts_with(&format!("{}/", dataset::LIBRARY))
    {
        return Some(Writer::User);
    }
    if rel == dataset::IMPORT_SUMMARY {
        return Some(Writer::Stage("import"));
    }
    if rel.starts_with("assets/") {
        return Some(Writer::Stage("assets"));
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_known_path_has_its_writer() {
        let s = |f: &str| format!("scenes/office_desk/office_desk_0001/{f}");
        assert_eq!(writer_of(&s(scene::CAMERA)), Some(Writer::User));
        assert_eq!(writer_of(&s(scene::LIFT)), Some(Writer::Stage("lift")));
        assert_eq!(
            writer_of(&s(&scene::points("mug_0"))),
            Some(Writer::Stage("lift"))
        );
        assert_eq!(
            writer_of(&s(scene::RETRIEVAL)),
            Some(Writer::Stage("retrieve"))
        );
        assert_eq!(
            writer_of(&s(scene::COARSE_LAYOUT)),
            Some(Writer::Stage("place"))
        );
        assert_eq!(
            writer_of(&s(&scene::refined_glb("x"))),
            Some(Writer::Annotator)
        );
        assert_eq!(
            writer_of(&s(scene::REFINED_LAYOUT)),
            Some(Writer::Stage("ingest"))
        );
        assert_eq!(
            writer_of(&s(scene::SETTLED_LAYOUT)),
            Some(Writer::Stage("check"))
        );
        assert_eq!(writer_of(dataset::INDEX), Some(Writer::Stage("assets")));
        assert_eq!(writer_of(&dataset::asset_glb("u")), Some(Writer::User));
        assert_eq!(writer_of("elsewhere/file"), None);
    }
}
