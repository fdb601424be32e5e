//! The per-stage artifacts (SPEC sections 3 and 4): inputs handed over by the model-driven
//! steps, and what each stage writes. Field names carry their units.

use std::collections::BTreeMap;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::llm::TaskInfo;
use crate::units::{PositionCm, SizeCm, ZoneCm};

/// Schema id of `coarse/lift.json`.
pub const LIFT_SCHEMA: &str = "mesa.lift/1";
/// Schema id of `coarse/retrieval.json`.
pub const RETRIEVAL_SCHEMA: &str = "mesa.retrieval/1";
/// Schema id of `assets/index/assets.json`.
pub const ASSET_INDEX_SCHEMA: &str = "mesa.asset-index/1";
/// Schema id of `assets/index/text.json`.
pub const TEXT_INDEX_SCHEMA: &str = "mesa.text-index/1";
/// Schema id of `assets/index/shapes/<uid>.json`.
pub const SHAPES_SCHEMA: &str = "mesa.shapes/1";
/// Schema id of `qa/check.json`.
pub const CHECK_SCHEMA: &str = "mesa.check/1";
/// Schema id of the dataset's `qa/summary.json`.
pub const CHECK_SUMMARY_SCHEMA: &str = "mesa.check-summary/1";
/// Schema id of `graph/graph.json`.
pub const GRAPH_SCHEMA: &str = "mesa.graph/1";
/// Schema id of each line of `tasks/tasks.jsonl`.
pub const TASKS_SCHEMA: &str = "mesa.tasks/1";
/// Schema id of each line of `tasks/rejects.jsonl`.
pub const TASK_REJECT_SCHEMA: &str = "mesa.task-reject/1";
/// Schema id of `records/split.json`.
pub const SPLIT_SCHEMA: &str = "mesa.split/1";
/// Schema id of `sim/export.json`.
pub const EXPORT_SCHEMA: &str = "mesa.export/1";
/// Schema id of `sim/urdf/scene.json`.
pub const URDF_SCENE_SCHEMA: &str = "mesa.urdf-scene/1";
/// Schema id of the runner's done / failed markers.
pub const MARKER_SCHEMA: &str = "mesa.marker/1";

// ---------------------------------------------------------------------------------------------
// Inputs handed over by the model-driven steps.

/// `input/camera.json`: pinhole intrinsics, or only a horizontal field of view.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(untagged)]
pub enum CameraJson {
    /// Full pinhole intrinsics in pixels (OpenCV convention).
    Intrinsics {
        /// Image width in pixels.
        width: u32,
        /// Image height in pixels.
        height: u32,
        /// Focal length along x in pixels.
        fx: f64,
        /// Focal length along y in pixels.
        fy: f64,
        /// Principal point x in pixels.
        cx: f64,
        /// Principal point y in pixels.
        cy: f64,
        /// Affine calibration `depth_m = scale · value + shift` when the depth map is a
        /// relative (disparity-like) map.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        depth_calibration: Option<DepthCalibration>,
    },
    /// Only a horizontal field of view (generated photos have no intrinsics).
    Fov {
        /// Image width in pixels.
        width: u32,
        /// Image height in pixels.
        height: u32,
        /// Horizontal field of view in degrees.
        fov_x_deg: f64,
        /// Affine calibration of a relative depth map, see above.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        depth_calibration: Option<DepthCalibration>,
    },
}

/// How a relative depth map becomes metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct DepthCalibration {
    /// `disparity` (depth_m = 1 / (scale · value + shift)) or `depth` (depth_m = scale · value
    /// + shift).
    pub kind: CalibrationKind,
    /// Multiplier applied to the stored value.
    pub scale: f64,
    /// Offset added after scaling.
    pub shift: f64,
}

/// What a relative depth map stores.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum CalibrationKind {
    /// Inverse depth up to an affine map.
    Disparity,
    /// Depth up to an affine map.
    Depth,
}

/// `input/instances.json`: the instances of a scene's photo.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct InstancesJson {
    /// One entry per mask id.
    pub instances: Vec<InstanceEntry>,
}

/// One instance of `instances.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct InstanceEntry {
    /// The mask id: label value in `masks.png`, or the file `masks/<id>.png`.
    pub id: u32,
    /// A short label, like `mug`.
    pub label: String,
    /// A description of the instance (the retrieval query).
    #[serde(default)]
    pub description: String,
    /// True for the table itself (the support surface).
    #[serde(default)]
    pub support: bool,
    /// A COCO RLE mask (`{"size": [h, w], "counts": ...}`), instead of a mask image.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rle: Option<serde_json::Value>,
    /// A precomputed query embedding for the `features` text encoder.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub embedding: Option<Vec<f32>>,
}

// ---------------------------------------------------------------------------------------------
// lift

/// `coarse/lift.json`: the table frame, the placement zone and one box per instance.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LiftArtifact {
    /// `mesa.lift/1`.
    pub schema: String,
    /// The scene id, like `office_table_0001`.
    pub scene_id: String,
    /// The camera used: resolved intrinsics in pixels.
    pub camera: ResolvedCamera,
    /// Rigid transform taking camera-frame points (metres) to the table frame (metres),
    /// row-major 4×4.
    pub table_from_camera: [[f64; 4]; 4],
    /// The fitted table plane.
    pub plane: PlaneFit,
    /// The item placement zone [x_min, x_max, y_min, y_max] in cm.
    #[serde(rename = "item_placement_zone")]
    pub zone_cm: ZoneCm,
    /// One entry per non-support instance, in instance-id order, except those in `dropped`.
    pub instances: Vec<LiftedInstance>,
    /// Instances left out because too few of their points survived filtering (absent when
    /// none was): they get no box, no asset and no place in the layout.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub dropped: Vec<DroppedInstance>,
}

/// An instance that `mesa lift` left out of a scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct DroppedInstance {
    /// The name it would have had, like `pen_0`.
    pub instance: String,
    /// Its id in `input/instances.json`.
    pub mask_id: u32,
    /// Its label.
    pub label: String,
    /// Points it kept after filtering.
    pub points_kept: u64,
    /// Why it was left out, and how to keep it.
    pub reason: String,
}

/// Intrinsics after resolving a FOV-only camera.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ResolvedCamera {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Focal lengths and principal point in pixels.
    pub fx: f64,
    /// Focal length along y in pixels.
    pub fy: f64,
    /// Principal point x in pixels.
    pub cx: f64,
    /// Principal point y in pixels.
    pub cy: f64,
    /// `intrinsics` (from camera.json) or `fov` (derived from a field of view).
    pub source: String,
}

/// The RANSAC table plane.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PlaneFit {
    /// Unit normal in the camera frame, pointing toward the camera side.
    pub normal_in_camera: [f64; 3],
    /// Plane offset d in metres (n·p + d = 0).
    pub offset_m: f64,
    /// `support` (the table instance's points) or `background`.
    pub source: String,
    /// Points within the inlier threshold.
    pub inliers: u64,
    /// Inliers / points considered.
    pub inlier_fraction: f64,
    /// Root-mean-square distance of the inliers to the plane, in metres.
    pub rmse_m: f64,
}

/// One lifted instance.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LiftedInstance {
    /// The instance name given to it, like `mug_0`.
    pub instance: String,
    /// Its id in `instances.json`.
    pub mask_id: u32,
    /// Its label.
    pub label: String,
    /// Its description.
    pub description: String,
    /// Box centre in the table frame, cm.
    pub center_cm: PositionCm,
    /// Box extents (x, y, z) in the table frame, cm.
    pub size_cm: SizeCm,
    /// Estimated yaw in degrees, when the lift estimated one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub yaw_deg: Option<f64>,
    /// The point cloud file, relative to the scene folder.
    pub points: String,
    /// How much of the mask produced points.
    pub stats: LiftStats,
}

/// Per-instance statistics of the lift.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LiftStats {
    /// Pixels in the mask.
    pub mask_px: u64,
    /// Mask pixels with a valid depth.
    pub valid_depth_px: u64,
    /// valid_depth_px / mask_px.
    pub valid_depth_fraction: f64,
    /// Pixels left after erosion (with valid depth).
    pub eroded_px: u64,
    /// Points removed as outliers.
    pub points_removed_outliers: u64,
    /// Points kept in the cloud.
    pub points_kept: u64,
}

// ---------------------------------------------------------------------------------------------
// assets

/// `assets/index/assets.json`: every GLB of `assets/library/`, read once, with its verdict.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct AssetIndexArtifact {
    /// `mesa.asset-index/1`.
    pub schema: String,
    /// SHA-256 of the `[assets]` configuration the records were made with.
    pub config_digest: String,
    /// One record per GLB in `assets/library/`, by uid (the file name without `.glb`).
    pub assets: BTreeMap<String, AssetRecord>,
    /// Uids of `annotations.json` that have no GLB in the library.
    pub annotated_without_glb: Vec<String>,
}

/// What `mesa assets` found in one GLB.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct AssetRecord {
    /// The GLB, relative to the dataset: `assets/library/<uid>.glb`.
    pub file: String,
    /// Size of the GLB in bytes.
    pub glb_bytes: u64,
    /// SHA-256 of the GLB.
    pub glb_sha256: String,
    /// SHA-256 of everything the record depends on (the GLB, the asset's annotation, the
    /// `[assets]` configuration, the index version): an unchanged digest means the record is
    /// reused as it is.
    pub inputs_sha256: String,
    /// Whether the asset can be retrieved and placed.
    pub valid: bool,
    /// Why it cannot, with how to fix it (invalid assets only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// A short code for the reason: a glTF-Validator code for a damaged container
    /// (`GLB_LENGTH_MISMATCH`, ...; a GLB of version 1 is `GLB_INVALID_VERSION`, bytes that are
    /// not a GLB `GLB_INVALID_MAGIC`), else `not_glb` (a glTF JSON file), `gltf1`, `json`,
    /// `version`, `invalid_gltf`,
    /// `unsupported_extension`, `external_uri`, `data`, `draco`, `no_mesh`, `zero_size_axis`,
    /// `io` (the file cannot be read), `internal`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason_code: Option<String>,
    /// Whether `annotations.json` has an entry for it.
    pub annotated: bool,
    /// The geometry, when the GLB could be read.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub geometry: Option<AssetGeometry>,
    /// The collision shapes, when they were computed (valid assets).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shapes: Option<ShapesRef>,
    /// Things that do not make the asset invalid.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
}

/// The geometry of an asset in its table-aligned frame: the glTF frame turned to the table
/// frame (`x = X, y = -Z, z = Y`: front toward -y, the observer) and then by the front
/// alignment yaw, metres, origin at the asset's glTF origin.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct AssetGeometry {
    /// Yaw about +z applied after the glTF → table conversion to bring the asset's front to -y,
    /// degrees (0 unless `[assets] front_alignment` uses the annotation).
    pub front_yaw_deg: f64,
    /// Minimum corner of the bounding box, metres.
    pub bounds_min_m: [f64; 3],
    /// Maximum corner of the bounding box, metres.
    pub bounds_max_m: [f64; 3],
    /// [width (x), depth (y), height (z)] of the bounding box, metres.
    pub size_m: [f64; 3],
    /// Extents along glTF X, Y (up), Z before any alignment, metres: the frame annotation
    /// bboxes are written in.
    pub gltf_extents_m: [f64; 3],
    /// Triangles placed (a mesh used by two nodes counts twice).
    pub triangles: u64,
    /// Vertices placed.
    pub vertices: u64,
    /// Triangle primitives placed.
    pub primitives: u64,
    /// Nodes that place a mesh.
    pub mesh_instances: u64,
    /// Material names (`material_<i>` for unnamed ones).
    pub materials: Vec<String>,
    /// Materials with a base colour texture.
    pub textured_materials: u64,
    /// Textures.
    pub textures: u64,
    /// MIME type of each embedded image.
    pub images: Vec<String>,
    /// `asset.generator` of the GLB.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub generator: Option<String>,
    /// Whether geometry was Draco-compressed (and decoded).
    pub draco: bool,
    /// Whether a mesh is skinned (read at its rest pose).
    pub skinned: bool,
    /// `extensionsRequired` of the GLB.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub extensions_required: Vec<String>,
}

/// Where an asset's collision shapes are.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ShapesRef {
    /// The shapes file, relative to the dataset: `assets/index/shapes/<uid>.json`.
    pub file: String,
    /// SHA-256 of the shapes file.
    pub sha256: String,
    /// Convex parts of the decomposition.
    pub parts: u64,
}

/// `assets/index/shapes/<uid>.json`: an asset's collision shapes for `mesa check`, in the
/// asset's table-aligned frame ([`AssetGeometry`]), metres.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ShapesArtifact {
    /// `mesa.shapes/1`.
    pub schema: String,
    /// The asset.
    pub uid: String,
    /// SHA-256 of the GLB the shapes were made from.
    pub glb_sha256: String,
    /// The convex hull of the whole asset.
    pub hull: ConvexPart,
    /// The convex decomposition: parts whose union follows the asset's shape, cavities
    /// included (a bowl's inside stays empty).
    pub parts: Vec<ConvexPart>,
    /// How the parts were made.
    pub decomposition: Decomposition,
}

/// One convex shape: the convex hull of its points.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ConvexPart {
    /// The hull's vertices, metres.
    pub points_m: Vec<[f64; 3]>,
    /// Its volume, cubic metres.
    pub volume_m3: f64,
}

/// The parameters of a convex decomposition.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Decomposition {
    /// `adaptive` (parts within `tolerance_m` of the mesh); `vhacd` (parry3d's V-HACD);
    /// `convex` when V-HACD was asked and the asset is a closed mesh filling its hull (the hull
    /// is its one part); `hull` when the decomposition failed and the parts are the single hull
    /// (the asset's warnings say why).
    pub method: String,
    /// Most parts allowed: for `adaptive`, the first part budget (`decomposition_max_parts`).
    pub max_parts: u32,
    /// Adaptive: the part budget the decomposition ended with, grown from `max_parts` (up to
    /// `decomposition_most_parts`) as far as the shape needed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub part_budget: Option<u32>,
    /// Adaptive: why `max_deviation_m` exceeds `tolerance_m`, when it does: `part_cap` (the
    /// budget grew to `decomposition_most_parts` and ran out), `no_gain` (two doublings of the
    /// budget had not lowered the largest deviation by a quarter), `min_size` (the piece is too small
    /// to cut, or no cut splits it), `out_of_time` (`[assets.budget] seconds`). The asset has
    /// a warning saying the same.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub over_tolerance: Option<String>,
    /// Adaptive: the most a part may reach outside the object, metres.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tolerance_m: Option<f64>,
    /// Adaptive: how far the parts reach outside the object at most (sampled on their faces),
    /// metres; above `tolerance_m` only when `max_parts` ran out (the asset then has a warning).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_deviation_m: Option<f64>,
    /// Adaptive: whether the mesh was read as a solid (closed and consistently oriented), so
    /// that its inside counts as the object; otherwise only its surface does.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub solid: Option<bool>,
    /// V-HACD: voxels along the longest axis (the configured resolution, or the one a retry
    /// used when V-HACD failed on the configured one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub resolution: Option<u32>,
    /// V-HACD: whether the parts' hulls were approximated while cutting (its default; a retry
    /// turns it off).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub convex_hull_approximation: Option<bool>,
    /// V-HACD: maximum concavity of a part.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub concavity: Option<f64>,
    /// Adaptive: true when the time budget (`[assets.budget] seconds`) stopped the cutting
    /// with some part still beyond `tolerance_m` (`max_deviation_m` says how far; the parts
    /// then depend on the machine's speed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub out_of_time: Option<bool>,
    /// Set when the asset was over its cost budget (`[assets.budget]`): the parts were made
    /// from a decimated copy of the mesh, and how far they reach outside the original.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub simplified: Option<Simplification>,
}

/// How an asset over its cost budget was simplified for its collision shape.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Simplification {
    /// `vertex_clustering`: the vertices in each cell of a uniform grid merged into their mean.
    pub method: String,
    /// The grid's cell size, metres.
    pub cell_m: f64,
    /// Triangles of the original mesh (placed).
    pub triangles: u64,
    /// Triangles of the decimated mesh the parts were made from.
    pub simplified_triangles: u64,
    /// How far the parts reach outside the original mesh, metres: sampled on the parts'
    /// faces, an upper bound by at most one cell of the measuring grid (1/128 of the asset's
    /// longest side) where they meet the surface.
    pub reach_m: f64,
}

/// `assets/index/text.json`: the asset texts and their features for the built-in lexical
/// encoder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TextIndexArtifact {
    /// `mesa.text-index/1`.
    pub schema: String,
    /// The encoder, `lexical/1`.
    pub encoder: String,
    /// Per annotated asset with a description or a category, by uid.
    pub documents: BTreeMap<String, TextDocument>,
    /// In how many documents each feature occurs.
    pub document_frequency: BTreeMap<String, u64>,
}

/// The text of one asset.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TextDocument {
    /// The text encoded (the category, then the description).
    pub text: String,
    /// Raw feature weights (before inverse document frequency).
    pub features: BTreeMap<String, f64>,
}

// ---------------------------------------------------------------------------------------------
// retrieve

/// `coarse/retrieval.json`: the candidates of every instance, with their scores.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RetrievalArtifact {
    /// `mesa.retrieval/1`.
    pub schema: String,
    /// The scene id.
    pub scene_id: String,
    /// The text encoder used: `lexical/1` or `features` (with the embedding width, like
    /// `features/768`).
    pub encoder: String,
    /// The recipe's parameters.
    pub recipe: RetrievalRecipe,
    /// Assets the text ranking ran over.
    pub candidate_assets: u64,
    /// Per instance, in instance order.
    pub instances: Vec<RetrievedInstance>,
}

/// The parameters of the retrieval recipe (SPEC 5.2; MesaTask's values are the defaults).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RetrievalRecipe {
    /// Candidates kept by text score (20).
    pub text_top_k: u32,
    /// Candidates kept by final score, among which the first unfiltered is chosen (5).
    pub final_top_k: u32,
    /// Weight of the text score (0.9).
    pub text_weight: f64,
    /// Weight of the size score (0.1).
    pub size_weight: f64,
    /// Whether further candidates are taken when the filters reject the whole top
    /// `final_top_k` (mesa's fallback; MesaTask's code gives up).
    pub fallback: bool,
}

/// The retrieval of one instance.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RetrievedInstance {
    /// The instance name.
    pub instance: String,
    /// Its id in `instances.json`.
    pub mask_id: u32,
    /// Its label.
    pub label: String,
    /// The query text (the instance description).
    pub query: String,
    /// Target [w, d, h] in cm.
    pub target_size_cm: SizeCm,
    /// The top `text_top_k` by text score in final-score order, then, when the fallback ran,
    /// the further candidates it examined in the order it examined them.
    pub candidates: Vec<RetrievalCandidate>,
    /// The chosen asset uid; absent when nothing passed the filters.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub chosen: Option<String>,
    /// True when the top `final_top_k` were all filtered out and a further candidate was
    /// taken.
    pub fallback: bool,
}

/// One candidate asset.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RetrievalCandidate {
    /// Asset uid.
    pub uid: String,
    /// Rank by text score, from 0.
    pub text_rank: u64,
    /// Cosine of the text embeddings.
    pub text_score: f64,
    /// Cosine of the target size and the asset's [bbox.x, bbox.z, bbox.y].
    pub size_score: f64,
    /// Where the asset's size came from: `annotation` (its bbox), `mesh` (the asset index,
    /// for want of a bbox) or `none`.
    pub size_source: String,
    /// text_weight · text + size_weight · size.
    pub final_score: f64,
    /// Why the filters rejected it (`onTable false`, `mark_deletion`, `is_composite`,
    /// `no annotation`, `no GLB in the library`, `invalid GLB: <code>`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rejected: Option<String>,
}

// ---------------------------------------------------------------------------------------------
// check

/// `qa/check.json`: the physics QA of one scene layout (SPEC 5.6), on the assets' collision
/// shapes (the convex decompositions of `assets/index/shapes/`) placed by the layout.
///
/// The findings at the top level are those of the layout checked (`layout`); when `mesa check
/// --settle` ran, `settle` says what it did and holds the findings of the settled layout
/// (`qa/layout.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CheckArtifact {
    /// `mesa.check/1`.
    pub schema: String,
    /// The scene id.
    pub scene_id: String,
    /// The layout checked, relative to the scene folder (`refined/layout.json`, or
    /// `coarse/layout.json` with `--layout coarse`).
    pub layout: String,
    /// SHA-256 of that layout file's bytes.
    pub layout_sha256: String,
    /// Penetration depth above which a pair collides, mm.
    pub penetration_tolerance_mm: f64,
    /// An object floats when its gap to the nearest support below exceeds this, mm.
    pub floating_tolerance_mm: f64,
    /// An object may cross the placement zone's edge, or reach into the restricted zone, by this
    /// much before it is a violation, mm.
    pub zone_tolerance_mm: f64,
    /// The distance under which MesaTask's released code calls a pair colliding, cm (5).
    pub mesatask_rule_distance_cm: f64,
    /// Objects in the layout.
    pub objects: u64,
    /// Objects that could not be checked (no asset, no collision shapes), with why; they take
    /// part in no pair, so `pairs_total` counts the checked objects only.
    pub unchecked: Vec<UncheckedObject>,
    /// Colliding pairs (penetration deeper than the tolerance), sorted by `a` then `b`.
    pub collisions: Vec<CollisionPair>,
    /// Floating objects, in instance order.
    pub floating: Vec<FloatingObject>,
    /// Objects outside the zone, inside the restricted zone, or below the table, in instance
    /// order then kind.
    pub zone_violations: Vec<ZoneViolation>,
    /// Number of pairs of checked objects, n·(n-1)/2.
    pub pairs_total: u64,
    /// Colliding pairs / all pairs (the paper's collision rate); 0 when there are no pairs.
    pub collision_rate: f64,
    /// Pairs whose shapes are closer than `mesatask_rule_distance_cm` (MesaTask's released
    /// rule, for comparison only: it calls touching and nearby objects colliding).
    pub mesatask_rule_pairs: u64,
    /// True when every object was checked and there is no collision, no floating object and
    /// no zone violation.
    pub clean: bool,
    /// What `--settle` did; absent when it was not asked.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub settle: Option<SettleReport>,
}

/// An object `mesa check` could not test.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct UncheckedObject {
    /// The instance.
    pub instance: String,
    /// Why (no `retrieved_uid`, an asset missing from the index or invalid, no shapes file).
    pub reason: String,
}

/// Two objects that interpenetrate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CollisionPair {
    /// First instance (the smaller name).
    pub a: String,
    /// Second instance.
    pub b: String,
    /// Penetration depth in mm: the deepest overlap of a convex part of `a` with one of `b`
    /// (the shortest translation that separates those two parts).
    pub depth_mm: f64,
}

/// An object with nothing close enough below it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FloatingObject {
    /// The instance.
    pub instance: String,
    /// How far it would fall straight down before touching something, mm.
    pub gap_mm: f64,
    /// What it would land on: `table`, or an instance.
    pub over: String,
}

/// An object where it may not be.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ZoneViolation {
    /// The instance.
    pub instance: String,
    /// `outside_zone` (its shape reaches beyond the item placement zone), `in_restricted_zone`
    /// (its shape reaches over the restricted zone, the sink) or `below_table` (it sinks into
    /// the table top).
    pub kind: String,
    /// How far: beyond the zone's edge, into the restricted zone (the shortest horizontal move
    /// out of it), or below the table top, in cm.
    pub amount_cm: f64,
}

/// The findings of a check, as in [`CheckArtifact`]'s top level.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CheckFindings {
    /// Colliding pairs, sorted by `a` then `b`.
    pub collisions: Vec<CollisionPair>,
    /// Floating objects, in instance order.
    pub floating: Vec<FloatingObject>,
    /// Zone violations, in instance order then kind.
    pub zone_violations: Vec<ZoneViolation>,
    /// Number of pairs of checked objects.
    pub pairs_total: u64,
    /// Colliding pairs / all pairs; 0 when there are no pairs.
    pub collision_rate: f64,
    /// Pairs closer than MesaTask's 5 cm.
    pub mesatask_rule_pairs: u64,
    /// True when every object was checked and there is no collision, no floating object and
    /// no zone violation.
    pub clean: bool,
}

/// What `mesa check --settle` did to a scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SettleReport {
    /// `settled`: `qa/layout.json` was written and checks clean; `unsettled`: no layout
    /// was written (`reason` says why; later stages read the unsettled layout).
    pub status: SettleStatus,
    /// `least_motion`: objects pushed apart in the plane and dropped onto what is under them,
    /// stacks and contents moving with what holds them; `least_motion+simulation`: then
    /// simulated under gravity until at rest (`simulation`).
    pub method: String,
    /// Why the scene could not be settled.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// The settled layout, relative to the scene folder (`qa/layout.json`); absent when
    /// unsettled.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub layout: Option<String>,
    /// Rounds of push-apart and drop used.
    pub iterations: u32,
    /// How far each object moved, in instance order (every object, moved or not).
    pub displacements: Vec<Displacement>,
    /// The largest displacement, cm.
    pub max_displacement_cm: f64,
    /// The median displacement over all objects, cm.
    pub median_displacement_cm: f64,
    /// Relations of the scene graph (`in`, `above`) the settled layout would lose; a settled
    /// layout loses none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub relations_lost: Vec<String>,
    /// The findings of a check of the layout settle arrived at (of `qa/layout.json` when
    /// settled).
    pub after: CheckFindings,
    /// The simulation after the least-motion moves, when one ran.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub simulation: Option<SimulationReport>,
}

/// Whether a scene was settled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum SettleStatus {
    /// `qa/layout.json` written, clean.
    Settled,
    /// Not settled; nothing written.
    Unsettled,
}

/// How far settling moved one object.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Displacement {
    /// The instance.
    pub instance: String,
    /// The move of its position [dx, dy, dz], cm.
    pub offset_cm: [f64; 3],
    /// Its length, cm.
    pub distance_cm: f64,
    /// Whether the simulation moved it (further than `rest_motion_mm`): its position and
    /// rotation are then the simulation's.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub simulated: bool,
    /// How far the simulation moved it (the largest motion of a corner of its box), cm; absent
    /// without a simulation.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub simulation_cm: Option<f64>,
    /// The angle the simulation turned it by, degrees (0 when it kept its pose).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub turned_deg: Option<f64>,
}

/// The rigid-body simulation that ends settling (`[check.settling] simulate`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SimulationReport {
    /// The engine: `rapier3d 0.26`.
    pub engine: String,
    /// Simulated time, seconds: at least `[check.settling] simulated_s`, longer while
    /// something still moved.
    pub simulated_s: f64,
    /// Steps run.
    pub steps: u32,
    /// The rest window (the last seconds of the simulation), seconds.
    pub rest_window_s: f64,
    /// Motion below this is no motion, mm.
    pub rest_motion_mm: f64,
    /// Objects the simulation moved (they take its pose).
    pub objects_moved: u64,
    /// The largest motion of an object in the simulation, cm.
    pub max_motion_cm: f64,
    /// Objects still moving over the rest window (more than `rest_motion_mm`): the scene is
    /// not at rest.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub still_moving: Vec<String>,
    /// Objects that ended under the table top (off the table, or into the sink).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub fell: Vec<String>,
}

/// `qa/summary.json` (dataset level): the collision rate over every checked scene, before and
/// after settling (`mesa check` writes it after each run, from every scene's `qa/check.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CheckSummaryArtifact {
    /// `mesa.check-summary/1`.
    pub schema: String,
    /// Scenes with a `qa/check.json`.
    pub scenes: u64,
    /// How many scenes were checked on each layout file (`refined/layout.json`, ...).
    pub layouts: BTreeMap<String, u64>,
    /// The layouts as checked.
    pub before: RateSummary,
    /// The layouts later stages read: the settled layout of settled scenes, the checked one of
    /// the others; absent when no scene was settled or tried.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub after: Option<RateSummary>,
    /// Settling, over the scenes where it ran.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub settle: Option<SettleSummary>,
}

/// Collision and QA rates over a set of scenes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RateSummary {
    /// Scenes counted.
    pub scenes: u64,
    /// Pairs over all scenes.
    pub pairs_total: u64,
    /// Colliding pairs over all scenes.
    pub colliding_pairs: u64,
    /// colliding_pairs / pairs_total (pooled over the scenes); 0 without pairs.
    pub collision_rate: f64,
    /// The mean of the scenes' collision rates.
    pub mean_scene_collision_rate: f64,
    /// Scenes with at least one colliding pair.
    pub scenes_with_collisions: u64,
    /// Floating objects over all scenes.
    pub floating_objects: u64,
    /// Scenes with at least one floating object.
    pub scenes_with_floating: u64,
    /// Zone violations over all scenes.
    pub zone_violations: u64,
    /// Scenes with no collision, no floating object and no zone violation.
    pub clean_scenes: u64,
    /// Pairs under MesaTask's released 5 cm rule, over all scenes.
    pub mesatask_rule_pairs: u64,
    /// mesatask_rule_pairs / pairs_total.
    pub mesatask_rule_rate: f64,
}

/// What settling did over a dataset.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SettleSummary {
    /// Scenes settled.
    pub settled: u64,
    /// Scenes that could not be settled.
    pub unsettled: u64,
    /// Object displacements counted (every object of the settled scenes).
    pub objects: u64,
    /// Median displacement over those objects, cm.
    pub median_displacement_cm: f64,
    /// Mean displacement, cm.
    pub mean_displacement_cm: f64,
    /// Largest displacement, cm.
    pub max_displacement_cm: f64,
    /// Objects settling moved (displacement above 0).
    pub moved_objects: u64,
    /// Median displacement over the moved objects only, cm (0 when none moved).
    pub median_moved_displacement_cm: f64,
    /// What the rigid-body simulation did, over the scenes it ran on (absent when it ran on
    /// none: `[check.settling] simulate = false`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub simulation: Option<SimulationSummary>,
}

/// What settling's rigid-body simulation did over a dataset.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SimulationSummary {
    /// Scenes simulated.
    pub scenes: u64,
    /// Objects the simulation moved (they took its pose), over those scenes.
    pub objects_moved: u64,
    /// The largest motion of an object in a simulation, cm.
    pub max_motion_cm: f64,
    /// Objects still moving at the end (their scenes are unsettled).
    pub still_moving: u64,
    /// Objects that ended under the table top (their scenes are unsettled).
    pub fell: u64,
    /// The longest simulated time of a scene, seconds.
    pub max_simulated_s: f64,
}

// ---------------------------------------------------------------------------------------------
// graph

/// `graph/graph.json`: the scene graph with the numbers that decided each edge.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct GraphArtifact {
    /// `mesa.graph/1`.
    pub schema: String,
    /// The scene id.
    pub scene_id: String,
    /// The layout the graph was extracted from, relative to the scene folder.
    pub layout: String,
    /// One node per object, in layout order.
    pub nodes: Vec<GraphNode>,
    /// Edges in output order.
    pub edges: Vec<GraphEdge>,
    /// `are equally spaced along` triples (written only when that optional relation is on).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub equally_spaced: Vec<GraphSpacing>,
}

/// A node: where an object is and where it faces.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct GraphNode {
    /// The instance.
    pub instance: String,
    /// Nine-grid cell, like `front_left` or `center`.
    pub is_at: String,
    /// One of eight directions, like `front_right`.
    pub face_to: String,
    /// Whether the object counted as a container (asset annotation, else the keyword rule).
    pub container: bool,
}

/// An edge `(subject, relation, object)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct GraphEdge {
    /// Subject instance.
    pub subject: String,
    /// `in`, `above`, `left of`, `right of`, `in front of` or `behind`.
    pub relation: String,
    /// Object instance.
    pub object: String,
    /// The numbers that decided the edge (distances in cm, overlap ratios).
    pub numbers: BTreeMap<String, f64>,
}

/// Three objects equally spaced along an axis: `(a, b, c, are equally spaced along, x)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct GraphSpacing {
    /// The three instances, by increasing coordinate along the axis.
    pub instances: [String; 3],
    /// `x` or `y`.
    pub axis: String,
    /// The numbers that decided it (the two gaps and the spread across the axis, in cm).
    pub numbers: BTreeMap<String, f64>,
}

// ---------------------------------------------------------------------------------------------
// tasks and records

/// One line of `tasks/tasks.jsonl`: a task with its reasoning text.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TaskRecord {
    /// `mesa.tasks/1`.
    pub schema: String,
    /// The scene id.
    pub scene_id: String,
    /// Index of the task within the scene, from 0.
    pub task_index: u32,
    /// `template` for the built-in offline writer (deterministic, no model involved), else
    /// `llm:<model>` for replies of an OpenAI-compatible chat endpoint.
    pub generator: String,
    /// The layout the tasks were written for, relative to the scene folder (like
    /// `qa/layout.json`).
    pub layout: String,
    /// SHA-256 of that layout file's bytes, so `mesa records` can tell stale tasks.
    pub layout_sha256: String,
    /// The rendered views the table description was written from, relative to the scene
    /// folder (like `render/front.png`); empty when the scene had no renders, or with the
    /// template backend, which reads none.
    pub views: Vec<String>,
    /// The table description the tasks were written from (the task info's `Environment`).
    pub table_description: String,
    /// The task info (the model's input).
    pub task_info: TaskInfo,
    /// The reasoning text (the first part of the model output): an introduction, the
    /// `Core Task Objects:` and `Environment Objects:` lists with counts, the placement
    /// paragraph, and a closing sentence leading to the scene graph.
    pub reasoning: String,
}

/// One line of `tasks/rejects.jsonl`: a model reply that failed validation, kept with why.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TaskReject {
    /// `mesa.task-reject/1`.
    pub schema: String,
    /// The scene id.
    pub scene_id: String,
    /// Which call the reply answered: `description`, `tasks` or `reasoning`.
    pub call: String,
    /// The task the reply was for (reasoning replies, and single tasks rejected from a tasks
    /// reply); absent for whole-reply rejects of the description and tasks calls.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub task_index: Option<u32>,
    /// The attempt, from 0 (each attempt sends the request with the seed plus the attempt).
    pub attempt: u32,
    /// `template` or `llm:<model>`, as in `tasks.jsonl`.
    pub generator: String,
    /// Every reason the reply was rejected.
    pub reasons: Vec<String>,
    /// The reply text as received (for a single task, that task's JSON), except that the API
    /// key, when the reply held it, is replaced by `<redacted>`.
    pub reply: String,
    /// Present and true when the reply held the API key, replaced by `<redacted>` before
    /// anything was written.
    #[serde(default, skip_serializing_if = "crate::artifacts::is_false")]
    pub redacted: bool,
}

/// An SFT record in LLaMA-Factory's alpaca form (`records/sft.json` and `records/test.json`
/// are lists of these). The user turn a trainer builds is `instruction + "\n" + input`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SftRecord {
    /// The layout-generation prompt (`data/prompts/layout_generation.txt`).
    pub instruction: String,
    /// The task info JSON (2-space indent, UTF-8 unescaped, cm).
    pub input: String,
    /// The model output text: reasoning, scene-graph lines, the marker, the layout JSON.
    pub output: String,
}

/// A DPO record in LLaMA-Factory's alpaca preference form (`records/dpo.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct DpoRecord {
    /// The layout-generation prompt.
    pub instruction: String,
    /// The task info JSON.
    pub input: String,
    /// The preferred output (the SFT output of the same task).
    pub chosen: String,
    /// The corrupted output.
    pub rejected: String,
}

/// A chat message of TRL's conversational format.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ChatMessage {
    /// `system`, `user` or `assistant`.
    pub role: String,
    /// The message text.
    pub content: String,
}

/// A line of `records/trl_sft.jsonl` (and `trl_test.jsonl`): TRL's conversational language
/// modelling format.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TrlSftRecord {
    /// The user turn (`instruction + "\n" + input`) then the assistant turn (`output`).
    pub messages: Vec<ChatMessage>,
}

/// A line of `records/trl_dpo.jsonl` (TRL's conversational preference format).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TrlDpoRecord {
    /// The user turn.
    pub prompt: Vec<ChatMessage>,
    /// The preferred assistant turn.
    pub chosen: Vec<ChatMessage>,
    /// The rejected assistant turn.
    pub rejected: Vec<ChatMessage>,
}

/// An entry of LLaMA-Factory's `dataset_info.json` (its `data/README.md` format; keys as its
/// `DatasetAttr` parser reads them).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct DatasetInfoEntry {
    /// The data file, relative to `dataset_info.json`.
    pub file_name: String,
    /// `alpaca` or `sharegpt`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub formatting: Option<String>,
    /// True for preference (DPO) data.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ranking: Option<bool>,
    /// Column mapping (LLaMA-Factory name → field of the file). When present, every column
    /// the format uses must be named: an absent one is read as "no such column".
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub columns: Option<BTreeMap<String, String>>,
    /// Message tags of the `sharegpt` format (`role_tag`, `content_tag`, `user_tag`,
    /// `assistant_tag`, `system_tag`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tags: Option<BTreeMap<String, String>>,
}

/// `records/split.json`: which scenes are train, dpo or test.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SplitArtifact {
    /// `mesa.split/1`.
    pub schema: String,
    /// The seed the scene order was drawn with (`[run] seed`).
    pub seed: u64,
    /// Ratios by split name (`train`, `dpo`, `test`).
    pub ratios: BTreeMap<String, f64>,
    /// Split name by scene, keyed `<table_type>/<scene_id>`.
    pub scenes: BTreeMap<String, String>,
    /// Scenes per split, by table type then split name.
    pub counts: BTreeMap<String, BTreeMap<String, u64>>,
    /// Scenes left out of every split, with why (no tasks, stale tasks, unreadable files).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub excluded: BTreeMap<String, String>,
}

// ---------------------------------------------------------------------------------------------
// runner

/// A done or failed marker under `.mesa/markers/<stage>/<table_type>/<scene_id>.json`.
///
/// It holds no time stamp, so the same work gives the same marker bytes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RunMarker {
    /// `mesa.marker/1`.
    pub schema: String,
    /// The stage.
    pub stage: String,
    /// `<table_type>/<scene_id>`.
    pub scene: String,
    /// `done` or `failed`.
    pub status: MarkerStatus,
    /// The mesa version that wrote it.
    pub mesa_version: String,
    /// SHA-256 of the stage's resolved configuration section.
    pub config_digest: String,
    /// SHA-256 of each input file, by path relative to the scene folder.
    pub inputs: BTreeMap<String, String>,
    /// SHA-256 of each output file, by path relative to the scene folder (done only).
    #[serde(default)]
    pub outputs: BTreeMap<String, String>,
    /// Warnings the stage reported for this scene.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
    /// The error chain, outermost first (failed only).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub error: Vec<String>,
}

impl RunMarker {
    /// The marker as its file holds it: exactly the bytes of [`crate::json::to_sorted_pretty`]
    /// (sorted keys, two-space indentation, a trailing newline), written by hand. The runner
    /// makes one a scene and compares it with the file before writing; through serde that
    /// was 2.5 µs of a forced `mesa graph`'s 73 µs a scene (`docs/performance.md`). The test
    /// `marker_bytes_are_those_of_the_sorted_serde_path` compares the two on random markers.
    pub fn to_pretty_json(&self) -> Vec<u8> {
        let strings = |list: &[String]| list.iter().map(|s| s.len() + 8).sum::<usize>();
        let map = |map: &BTreeMap<String, String>| {
            map.iter()
                .map(|(k, v)| k.len() + v.len() + 12)
                .sum::<usize>()
        };
        let mut w = crate::pretty::Pretty::with_capacity(
            256 + map(&self.inputs)
                + map(&self.outputs)
                + strings(&self.warnings)
                + strings(&self.error),
        );
        // Keys in byte order: config_digest, error, inputs, mesa_version, outputs, scene,
        // schema, stage, status, warnings.
        w.raw(b"{\n  \"config_digest\": ");
        w.string(&self.config_digest);
        if !self.error.is_empty() {
            w.raw(b",\n  \"error\": ");
            w.string_list(&self.error);
        }
        w.raw(b",\n  \"inputs\": ");
        w.string_map(&self.inputs);
        w.raw(b",\n  \"mesa_version\": ");
        w.string(&self.mesa_version);
        w.raw(b",\n  \"outputs\": ");
        w.string_map(&self.outputs);
        w.raw(b",\n  \"scene\": ");
        w.string(&self.scene);
        w.raw(b",\n  \"schema\": ");
        w.string(&self.schema);
        w.raw(b",\n  \"stage\": ");
        w.string(&self.stage);
        w.raw(match self.status {
            MarkerStatus::Done => b",\n  \"status\": \"done\"",
            MarkerStatus::Failed => b",\n  \"status\": \"failed\"",
        });
        if !self.warnings.is_empty() {
            w.raw(b",\n  \"warnings\": ");
            w.string_list(&self.warnings);
        }
        w.raw(b"\n}\n");
        w.into_bytes()
    }
}

/// The state a marker records.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum MarkerStatus {
    /// All outputs written.
    Done,
    /// The scene failed; no output of this run was written.
    Failed,
}

// ---------------------------------------------------------------------------------------------
// demo ground truth

/// Schema id of a demo scene's `truth/scene.json`.
pub const TRUTH_SCENE_SCHEMA: &str = "mesa.truth-scene/1";
/// Schema id of a demo scene's `truth/instances.json`.
pub const TRUTH_INSTANCES_SCHEMA: &str = "mesa.truth-instances/1";

/// `truth/scene.json` of a `mesa demo` scene: how its inputs were made, so that every stage
/// can be measured against the truth (the layout itself is `truth/layout.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TruthScene {
    /// `mesa.truth-scene/1`.
    pub schema: String,
    /// The scene id, like `office_table_0001`.
    pub scene_id: String,
    /// The table type, like `office_table`.
    pub table_type: String,
    /// The `--seed` the scene was made with.
    pub seed: u64,
    /// A one-sentence description of the scene, as the scene-writing step would give it.
    pub environment: String,
    /// The camera that took the photo (exact intrinsics, also for a FOV-only `camera.json`).
    pub camera: TruthCamera,
    /// Rigid transform taking camera-frame points (OpenCV, metres) to the table frame
    /// (metres), row-major 4×4.
    pub table_from_camera: [[f64; 4]; 4],
    /// The table.
    pub table: TruthTable,
    /// How `input/depth.*` was made from the true depth.
    pub depth: TruthDepth,
    /// How the masks were written.
    pub masks: TruthMasks,
}

/// The exact camera of a demo photo.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TruthCamera {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Focal length along x in pixels.
    pub fx: f64,
    /// Focal length along y in pixels.
    pub fy: f64,
    /// Principal point x in pixels.
    pub cx: f64,
    /// Principal point y in pixels.
    pub cy: f64,
    /// Horizontal field of view in degrees.
    pub fov_x_deg: f64,
    /// What `input/camera.json` states: `intrinsics` or `fov` (then the principal point is
    /// the image centre `(width / 2, height / 2)` and `fx = fy`).
    pub camera_json: String,
    /// Camera pitch below the horizontal, degrees (the camera has no yaw or roll).
    pub pitch_deg: f64,
}

/// The table of a demo scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TruthTable {
    /// Its label in `instances.json`.
    pub label: String,
    /// Its description in `instances.json`.
    pub description: String,
    /// Height of the top above the floor, metres.
    pub height_m: f64,
    /// Thickness of the top, metres.
    pub top_thickness_m: f64,
    /// The placement zone (the whole top) [x_min, x_max, y_min, y_max] in cm.
    #[serde(rename = "item_placement_zone")]
    pub zone_cm: ZoneCm,
    /// The sink's restricted zone in cm, for a bathroom vanity.
    #[serde(
        rename = "restricted_zone",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub restricted_zone_cm: Option<ZoneCm>,
    /// Distance from the table's back edge to the wall behind it, metres.
    pub wall_gap_m: f64,
}

/// How a demo depth map departs from the true depth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TruthDepth {
    /// The depth file, relative to the scene folder.
    pub file: String,
    /// `sensor` (a structured-light camera: noise growing with distance, holes, mixed pixels
    /// at edges, millimetre steps) or `estimator` (a metric monocular estimator: a global
    /// scale error, smooth low-frequency error, edges blurred across objects).
    pub model: String,
    /// Global scale: away from edges, stored depth ≈ `scale` · true depth.
    pub scale: f64,
    /// Per-pixel noise σ(d) = `sigma_constant_m` + `sigma_linear` · d + `sigma_quadratic_per_m`
    /// · (d − 0.4 m)², in metres.
    pub sigma_constant_m: f64,
    /// See `sigma_constant_m`.
    pub sigma_linear: f64,
    /// See `sigma_constant_m` (per metre).
    pub sigma_quadratic_per_m: f64,
    /// Largest absolute value of the smooth low-frequency error, relative to depth.
    pub smooth_error_relative: f64,
    /// Storage step, metres (0.001 for a 16-bit millimetre PNG, 0 for float32).
    pub quantization_m: f64,
    /// Pixels with a valid depth.
    pub valid_px: u64,
    /// Pixels without a measurement (0, NaN, inf or negative).
    pub invalid_px: u64,
    /// Pixels at depth edges whose value mixes foreground and background (flying pixels).
    pub mixed_px: u64,
}

/// How the masks of a demo scene were written.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TruthMasks {
    /// `label_png` (`input/masks.png`) or `instance_pngs` (`input/masks/<id>.png`).
    pub form: String,
    /// Bits per label of `masks.png` (8 or 16); 8 for binary instance masks.
    pub bit_depth: u8,
    /// How far instance masks were grown beyond the visible region, pixels (so neighbours'
    /// masks overlap, as segmentation masks do); 0 for a label image.
    pub dilation_px: u32,
    /// Objects with fewer visible pixels than this were left out of the scene.
    pub min_visible_px: u32,
}

/// `truth/instances.json` of a `mesa demo` scene: what each mask id is.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TruthInstances {
    /// `mesa.truth-instances/1`.
    pub schema: String,
    /// The scene id.
    pub scene_id: String,
    /// One entry per id of `input/instances.json`, in id order.
    pub instances: Vec<TruthInstance>,
}

/// The truth about one mask id.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TruthInstance {
    /// The id in `instances.json` and the masks.
    pub id: u32,
    /// The label given in `instances.json`.
    pub label: String,
    /// True for the table.
    pub support: bool,
    /// The object's instance in `truth/layout.json` (absent for the table).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub instance: Option<String>,
    /// The asset placed there (absent for the table).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uid: Option<String>,
    /// The asset's category (absent for the table).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub category: Option<String>,
    /// The instance it rests on or in (absent when it stands on the table).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rests_on: Option<String>,
    /// Pixels where it is the visible surface.
    pub visible_px: u64,
}

/// Schema id of `assets/renders/<uid>/views.json`.
pub const ASSET_VIEWS_SCHEMA: &str = "mesa.asset-views/1";

/// `assets/renders/<uid>/views.json`: what an asset's views were made from (written last).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct AssetViewsRecord {
    /// `mesa.asset-views/1`.
    pub schema: String,
    /// The asset.
    pub uid: String,
    /// SHA-256 of its GLB.
    pub glb_sha256: String,
    /// Its front alignment yaw, degrees.
    pub front_yaw_deg: f64,
    /// Digest of the `[render]` settings.
    pub config_digest: String,
    /// The views written (`view_000`, ...).
    pub views: Vec<String>,
}

/// Schema id of a cached model reply (`.mesa/cache/chat/<aa>/<digest>.json`).
pub const CHAT_REPLY_SCHEMA: &str = "mesa.chat-reply/1";

/// A cached model reply (`.mesa/cache/chat/<aa>/<digest>.json`), keyed by the digest of the
/// request it answers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CachedChatReply {
    /// `mesa.chat-reply/1`.
    pub schema: String,
    /// The digest of the request it answers.
    pub request_sha256: String,
    /// The model the server said answered.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model: Option<String>,
    /// The reply text.
    pub content: String,
    /// The finish reason.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub finish_reason: Option<String>,
    /// Present and true when the reply held the API key, replaced by `<redacted>` in `content`
    /// (and `model`) before the entry was written.
    #[serde(default, skip_serializing_if = "crate::artifacts::is_false")]
    pub redacted: bool,
}

/// For `skip_serializing_if`: flags written only when set, so files without them keep their
/// bytes.
pub(crate) fn is_false(value: &bool) -> bool {
    !*value
}

// ---------------------------------------------------------------------------------------------
// The simulator export.

/// Where an exported object's mass comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum MassSource {
    /// The asset annotation's `mass` (kg), as annotated (not scaled with the object).
    Annotation,
    /// `[export] density_kg_m3` × the volume of the convex parts at the layout's scale.
    Density,
}

/// One object of `sim/export.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ExportedObject {
    /// The layout's instance: the MJCF body, the URDF robot and the USD prim are named so.
    pub instance: String,
    /// The asset placed.
    pub uid: String,
    /// Mass, kg.
    pub mass_kg: f64,
    /// Where the mass comes from.
    pub mass_source: MassSource,
    /// Volume of the convex parts at the layout's scale, m³ (parts do not overlap: they are
    /// cut from disjoint boxes).
    pub volume_m3: f64,
    /// Centre of mass in the body frame (the object's bounding-box centre, turned by its
    /// rotation), metres.
    pub center_of_mass_m: [f64; 3],
    /// Inertia tensor about the centre of mass in the body frame, [ixx, iyy, izz, ixy, ixz,
    /// iyz], kg·m².
    pub inertia_kg_m2: [f64; 6],
    /// Collision geoms: one per convex part.
    pub collision_parts: u64,
    /// Triangles of the visual mesh.
    pub visual_triangles: u64,
    /// Visual meshes: one per glTF material the asset draws with (one grey one when it has
    /// none), each with its MJCF material, URDF visual and USD material.
    #[serde(default)]
    pub visual_materials: u64,
    /// The base-colour images its materials use, relative to the scene folder (under
    /// `sim/textures/`), sorted; none when it is untextured.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub textures: Vec<String>,
}

/// `sim/export.json`: what `mesa export` wrote for a scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ExportArtifact {
    /// `mesa.export/1`.
    pub schema: String,
    /// The scene.
    pub scene_id: String,
    /// The layout exported, relative to the scene folder.
    pub layout: String,
    /// SHA-256 of the layout's bytes (for a single asset, `mesa export --assets`: of the
    /// asset's inputs: its GLB, its shapes, its annotated mass and the settings).
    pub layout_sha256: String,
    /// The formats written (`mjcf`, ...), each a folder under `sim/`.
    pub formats: Vec<String>,
    /// The files written, relative to the scene folder, sorted.
    pub files: Vec<String>,
    /// Density used for objects without an annotated mass, kg/m³.
    pub density_kg_m3: f64,
    /// The table: a static box whose top is z = 0; [width, depth, thickness], metres (zeros in
    /// a single asset's files, which have no table).
    pub table_size_m: [f64; 3],
    /// The sink of a vanity: a hole in the table top over the restricted zone, with a static
    /// basin floor this far below the top, metres (absent without a restricted zone).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sink_depth_m: Option<f64>,
    /// The objects, in layout order.
    pub objects: Vec<ExportedObject>,
    /// Objects left out, each with the reason.
    pub skipped: Vec<UncheckedObject>,
    /// Things worth knowing (flat parts, a missing visual mesh, ...).
    pub warnings: Vec<String>,
}

/// Where one URDF of a scene goes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct UrdfPlacement {
    /// The instance (`table` for the table).
    pub instance: String,
    /// The URDF file, relative to `sim/urdf/`.
    pub urdf: String,
    /// Position of its root link's frame in the table frame, metres (z up, the table top at
    /// z = 0).
    pub position_m: [f64; 3],
    /// Orientation of its root link, quaternion [x, y, z, w] (PyBullet's order).
    pub orientation_xyzw: [f64; 4],
    /// Whether to load it with a fixed base (the table).
    pub fixed_base: bool,
}

/// `sim/urdf/scene.json`: the URDFs of a scene and their poses.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct UrdfSceneArtifact {
    /// `mesa.urdf-scene/1`.
    pub schema: String,
    /// The scene.
    pub scene_id: String,
    /// The table (static; absent in a single asset's files, `mesa export --assets`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub table: Option<UrdfPlacement>,
    /// The objects, in layout order.
    pub objects: Vec<UrdfPlacement>,
    /// The simulation step the scene was exported for, seconds (`[export] timestep_s`, the
    /// MJCF's `option timestep`): pass it to `p.setTimeStep` (PyBullet's own default, 1/240 s,
    /// lets a light pen lying on a narrow face roll off it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timestep_s: Option<f64>,
}
