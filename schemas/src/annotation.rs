//! The annotator round trip (SPEC 5.4 and 5.5): the pack index sent with a scene's GLB
//! (`pack/index.json`) and the report of what the annotator changed (`refined/diff.json`).

use std::collections::BTreeMap;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::units::{PositionCm, ZoneCm};

/// Schema id of `pack/index.json`.
pub const PACK_INDEX_SCHEMA: &str = "mesa.pack-index/1";
/// Schema id of `refined/diff.json`.
pub const INGEST_DIFF_SCHEMA: &str = "mesa.ingest-diff/1";

/// `pack/index.json`: what the annotator pack holds, and what `mesa ingest` needs to read the
/// edited scene back (the size of each asset's mesh as packed).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PackIndexArtifact {
    /// `mesa.pack-index/1`.
    pub schema: String,
    /// The scene id.
    pub scene_id: String,
    /// The scene GLB, relative to the pack folder: `<scene_id>.glb`.
    pub glb: String,
    /// The photo, relative to the pack folder (absent when the scene has none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference: Option<String>,
    /// The layout the pack was made from, relative to the scene folder.
    pub layout: String,
    /// SHA-256 of that layout file.
    pub layout_sha256: String,
    /// The item placement zone of that layout, cm.
    #[serde(rename = "item_placement_zone")]
    pub zone_cm: ZoneCm,
    /// The restricted zone of that layout, cm (the `restricted_zone` node).
    #[serde(
        rename = "restricted_zone",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub restricted_zone_cm: Option<ZoneCm>,
    /// The table slab (node `table`).
    pub table: PackTable,
    /// The metric reference figure (node `H1_reference`).
    pub h1: PackFigure,
    /// One entry per object node, by instance.
    pub objects: BTreeMap<String, PackObject>,
    /// One entry per asset placed (several objects may share it), by uid.
    pub assets: BTreeMap<String, PackAsset>,
}

/// The table slab of a pack.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PackTable {
    /// The node name, `table`.
    pub node: String,
    /// Thickness of the slab below z = 0, cm.
    pub thickness_cm: f64,
}

/// The H1 reference figure of a pack.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PackFigure {
    /// The node name, `H1_reference`.
    pub node: String,
    /// Its height, cm (170).
    pub height_cm: f64,
    /// The centre of its bounding box in the table frame, cm (it stands on the floor).
    #[serde(rename = "position")]
    pub position_cm: PositionCm,
}

/// One object node of a pack.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PackObject {
    /// The asset uid (`assets/library/<uid>.glb`).
    pub uid: String,
    /// The object's category.
    pub category: String,
    /// Its description, when the layout has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
    /// Its snapshot, relative to the pack folder (absent when its mask is unknown or empty).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub snapshot: Option<String>,
}

/// One asset mesh of a pack: the asset's node hierarchy baked into one mesh, in its
/// table-aligned frame (glTF axes), its bounding box centred on the origin.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PackAsset {
    /// The mesh name in the GLB.
    pub mesh: String,
    /// [width (x), depth (y), height (z)] of the mesh's bounding box, metres (object frame).
    pub size_m: [f64; 3],
    /// The yaw that turned the asset's front to -y before baking, degrees.
    pub front_yaw_deg: f64,
    /// Triangles of the mesh.
    pub triangles: u64,
}

/// `refined/diff.json`: what the annotator changed, per object and for the table, the
/// restricted zone and the H1 figure.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct IngestDiffArtifact {
    /// `mesa.ingest-diff/1`.
    pub schema: String,
    /// The scene id.
    pub scene_id: String,
    /// The edited GLB read, relative to the scene folder.
    pub source: String,
    /// Its `asset.generator` (like `Khronos glTF Blender I/O v4.3.47`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub generator: Option<String>,
    /// The layout the pack was made from (the baseline of the changes), relative to the scene
    /// folder.
    pub baseline: String,
    /// Instances whose position changed.
    pub moved: Vec<String>,
    /// Instances whose rotation changed.
    pub rotated: Vec<String>,
    /// Instances whose size changed.
    pub scaled: Vec<String>,
    /// Instances added (duplicated by the annotator).
    pub added: Vec<String>,
    /// Instances deleted by the annotator.
    pub removed: Vec<String>,
    /// Instances tilted by more than the threshold (roll or pitch).
    pub tilted: Vec<String>,
    /// Instances whose mesh was edited or had transforms applied.
    pub mesh_changed: Vec<String>,
    /// Per object of the baseline and per added object, in instance order.
    pub objects: Vec<ObjectChange>,
    /// The table.
    pub table: TableChange,
    /// The restricted zone, when the pack or the edited scene has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub restricted_zone: Option<ZoneChange>,
    /// The H1 figure.
    pub h1: FigureCheck,
    /// Nodes that are none of the pack's, ignored because unknown nodes were allowed.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub ignored_nodes: Vec<String>,
    /// Everything worth a look, one sentence each.
    pub warnings: Vec<String>,
}

/// What happened to one object.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ObjectChange {
    /// The instance (for an added object, the new instance name).
    pub instance: String,
    /// `unchanged`, `edited`, `added` or `removed`.
    pub status: String,
    /// The node it was read from (absent for a removed object).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub node: Option<String>,
    /// For an added object: the instance it is a duplicate of.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub duplicate_of: Option<String>,
    /// Displacement of the box centre, cm (table frame).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub moved_cm: Option<[f64; 3]>,
    /// Length of the displacement, cm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub moved_distance_cm: Option<f64>,
    /// Angle of the rotation change, degrees.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotated_deg: Option<f64>,
    /// Change of the yaw (the twist about +z), degrees in (-180, 180].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub yaw_change_deg: Option<f64>,
    /// New size / old size per axis [width, depth, height].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub size_ratio: Option<[f64; 3]>,
    /// Tilt (angle between the object's up axis and +z), degrees, when above the threshold.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tilt_deg: Option<f64>,
    /// `unchanged`, `transform_applied` (scale or location applied: read correctly) or
    /// `edited` (vertices edited or a rotation applied: the size is the local box's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mesh: Option<String>,
}

/// What happened to the table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TableChange {
    /// The placement zone of the baseline, cm.
    pub zone_before_cm: ZoneCm,
    /// The placement zone after the edit, cm (the new table top).
    pub zone_after_cm: ZoneCm,
    /// Whether the table top was resized.
    pub resized: bool,
    /// Displacement of the table's proximal-left top corner, cm (the table frame moves with
    /// the table: objects are read relative to it).
    pub moved_cm: [f64; 3],
    /// Turn of the table about +z, degrees.
    pub rotated_deg: f64,
}

/// What happened to the restricted zone.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ZoneChange {
    /// The restricted zone of the baseline, cm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub before_cm: Option<ZoneCm>,
    /// The restricted zone after the edit, cm (absent when its node was deleted).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub after_cm: Option<ZoneCm>,
}

/// The H1 scale check.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FigureCheck {
    /// Whether the figure's node is in the edited scene.
    pub present: bool,
    /// Its height in the edited scene, cm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub height_cm: Option<f64>,
    /// The factor the whole scene was rescaled by about the table origin (170 cm / height),
    /// when the figure's height was off.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rescaled_by: Option<f64>,
}
