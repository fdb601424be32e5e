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
    /// The uid of each row of [`TEXT_FEATURES`].
    pub const TEXT_UIDS: &str = "assets/text_uids.json";
    /// The views around every asset: `assets/renders/<uid>/`.
    pub const ASSET_RENDERS: &str = "assets/renders";
    /// The dataset's check summary.
    pub const CHECK_SUMMARY: &str = "qa/summary.json";
    /// The training records.
    pub const RECORDS_DIR: &str = "records";
    /// The report.
    pub const REPORT_DIR: &str = "report";
    /// The chat reply cache.
    pub const CHAT_CACHE: &str = ".mesa/cache/chat";

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
