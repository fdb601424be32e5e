//! The artifacts of `render`, `report` and `release` (SPEC 5.10): a camera file per rendered
//! view, the dataset statistics, and the annotation file of a MesaTask-10K release.

use std::collections::BTreeMap;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::validate::Problem;

/// Schema id of `render/<view>_camera.json` and `assets/renders/<uid>/<view>_camera.json`.
pub const RENDER_CAMERA_SCHEMA: &str = "mesa.render-camera/1";
/// Schema id of `report/stats.json`.
pub const REPORT_STATS_SCHEMA: &str = "mesa.report-stats/1";
/// Schema id of `report/thumbs/sources.json`.
pub const REPORT_THUMBS_SCHEMA: &str = "mesa.report-thumbs/1";

/// `report/thumbs/sources.json`: what each thumbnail of the report was made from, so that a
/// later report makes again only those whose front view changed.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ReportThumbs {
    /// `mesa.report-thumbs/1`.
    pub schema: String,
    /// How the thumbnails were made (crop and filter); a report with another recipe makes
    /// them all again.
    pub recipe: String,
    /// Per thumbnail (`thumbs/<table_type>/<scene_id>.png`), the SHA-256 (hex) of the
    /// `render/front.png` it was made from.
    pub sources: BTreeMap<String, String>,
}

/// The camera of one rendered view: intrinsics and pose in the table frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RenderCameraArtifact {
    /// `mesa.render-camera/1`.
    pub schema: String,
    /// The view: `front`, `back`, `left`, `right`, `perspective`, or `view_<azimuth>` for an
    /// asset view (like `view_045`).
    pub view: String,
    /// The picture, relative to the folder of this file (`front.png`).
    pub image: String,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Focal length along x in pixels (OpenCV: x right, y down, z forward).
    pub fx: f64,
    /// Focal length along y in pixels.
    pub fy: f64,
    /// Principal point x in pixels (pixel `u` is sampled at `u`, SPEC 2).
    pub cx: f64,
    /// Principal point y in pixels.
    pub cy: f64,
    /// Horizontal field of view in degrees.
    pub fov_x_deg: f64,
    /// Rigid transform taking camera-frame points (OpenCV, metres) to the table frame
    /// (metres), row-major 4×4: the world-from-camera pose.
    pub table_from_camera: [[f64; 4]; 4],
    /// The point the camera looks at, table frame, metres.
    pub look_at_m: [f64; 3],
    /// Scene views: the layout drawn, relative to the scene folder.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub layout: Option<String>,
    /// Scene views: SHA-256 of the layout file drawn.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub layout_sha256: Option<String>,
    /// Asset views: the asset drawn.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uid: Option<String>,
    /// Asset views: the camera's azimuth, degrees counter-clockwise about +z from the front
    /// (−y).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub azimuth_deg: Option<f64>,
    /// Asset views: the camera's elevation above the horizontal, degrees.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub elevation_deg: Option<f64>,
    /// `transparent` (RGBA, alpha = coverage) or `black` (RGB over black).
    pub background: String,
    /// Samples per pixel along each axis (anti-aliasing).
    pub supersampling: u32,
    /// Pixels where each object is the visible surface at the pixel's centre, by instance;
    /// objects hidden in this view are listed with 0.
    pub visible_px: BTreeMap<String, u64>,
}

/// `report/stats.json`: statistics of a dataset.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ReportStats {
    /// `mesa.report-stats/1`.
    pub schema: String,
    /// Scenes in the dataset.
    pub scenes: u64,
    /// Scenes by table type.
    pub table_types: BTreeMap<String, u64>,
    /// Scenes by the layout their later stages read: `qa/layout.json`, `refined/layout.json`,
    /// `coarse/layout.json`, or `none`.
    pub layouts: BTreeMap<String, u64>,
    /// Objects per scene, over scenes with a layout.
    pub objects_per_scene: Distribution,
    /// Objects in all layouts.
    pub objects: u64,
    /// Distinct categories.
    pub categories: u64,
    /// The most frequent categories (at most 100), by count, then name.
    pub top_categories: Vec<NameCount>,
    /// Scene-graph relations by type (`left of`, `in`, ...) over every `graph/graph.json`, plus
    /// the node relations `is at` and `face to`.
    pub relations: BTreeMap<String, u64>,
    /// Scenes with a scene graph.
    pub scenes_with_graph: u64,
    /// Physics QA from `qa/check.json`.
    pub collisions: CollisionStats,
    /// Scenes with all five rendered views.
    pub scenes_rendered: u64,
    /// Task records (lines of `tasks/tasks.jsonl`) in all.
    pub tasks: u64,
    /// Scenes whose last run of a stage failed, by stage.
    pub failed: BTreeMap<String, u64>,
    /// Scenes that entered by `mesa import` (`imported/import.json`).
    #[serde(default)]
    pub imported: u64,
    /// Objects of imported scenes whose GLB the release does not ship (left out of the stages
    /// that need meshes).
    #[serde(default)]
    pub objects_missing_glb: u64,
    /// Imported scenes with at least one such object.
    #[serde(default)]
    pub scenes_with_missing_glb: u64,
    /// Annotated fields of `assets/annotations.json` (category, description, onTable, mass,
    /// frontView, isContainer, materials) by source: `person` (no recorded source), `offline`
    /// (the placeholder of `mesa annotate`), `llm:<model>`. Absent without annotations.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub annotation_sources: BTreeMap<String, u64>,
    /// Assets whose annotation holds placeholder fields (`mesa_placeholder`).
    #[serde(default, skip_serializing_if = "crate::render::is_zero")]
    pub annotation_placeholder_assets: u64,
}

/// A distribution of counts.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Distribution {
    /// How many items had each value, by increasing value (values no item had are left out).
    pub histogram: Vec<Bin>,
    /// Smallest value (0 when there is none).
    pub min: u64,
    /// Largest value.
    pub max: u64,
    /// Mean value.
    pub mean: f64,
    /// Median value.
    pub median: f64,
}

/// One bar of a histogram.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Bin {
    /// The value.
    pub value: u64,
    /// How many items had it.
    pub count: u64,
}

/// A name and its count.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct NameCount {
    /// The name.
    pub name: String,
    /// Its count.
    pub count: u64,
}

/// Collision statistics: the paper's collision rate (colliding pairs / all pairs) before
/// settling (the layouts as checked) and after (the layouts later stages read: the settled
/// `qa/layout.json` where `mesa check --settle` wrote one, the checked layout elsewhere).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CollisionStats {
    /// Scenes with a `qa/check.json`.
    pub checked: u64,
    /// Scenes without one ("not checked").
    pub not_checked: u64,
    /// Before settling: the checked layout.
    pub before: RateStats,
    /// After settling; `None` when settling was not tried on any scene.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub after: Option<RateStats>,
}

/// Collision rates over scenes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RateStats {
    /// Scenes counted.
    pub scenes: u64,
    /// Colliding pairs in all.
    pub colliding_pairs: u64,
    /// Object pairs in all.
    pub pairs: u64,
    /// Colliding pairs / all pairs over every scene counted (0 without pairs).
    pub collision_rate: f64,
    /// Mean of the scenes' own collision rates.
    pub mean_scene_rate: f64,
    /// Scenes with at least one colliding pair.
    pub scenes_with_collisions: u64,
    /// Floating objects in all.
    pub floating: u64,
    /// Zone violations in all.
    pub zone_violations: u64,
}

fn is_zero(n: &u64) -> bool {
    *n == 0
}

/// `Asset_annotation.json` of a release (and `assets/annotations.json`): per uid the asset's
/// annotation in the MesaTask / objathor form.
pub type AssetAnnotationsFile = BTreeMap<String, BTreeMap<String, Value>>;

/// What the JSON Schema of an annotation file cannot say: each annotation names a category
/// and a description as strings, the fields MesaTask's retrieval reads.
pub fn annotation_problems(file: &AssetAnnotationsFile) -> Vec<Problem> {
    let mut problems = Vec::new();
    for (uid, fields) in file {
        let at = crate::validate::path_key("$", uid);
        for key in ["category", "description"] {
            match fields.get(key) {
                Some(Value::String(_)) => {}
                Some(other) => problems.push(Problem::new(
                    crate::validate::path_key(&at, key),
                    crate::validate::describe(other),
                    "a string",
                )),
                None => problems.push(Problem::new(
                    at.clone(),
                    format!("has no \"{key}\""),
                    format!("a \"{key}\" string"),
                )),
            }
        }
    }
    problems
}
