//! The dataset layout (`layout.json`): a superset of MesaTask-10K's layout file.

use std::collections::BTreeMap;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::units::{PositionCm, QuatXyzw, ScaleFactor, SizeCm, ZoneCm};
use crate::Problem;

/// Schema id written into every dataset layout.
pub const LAYOUT_SCHEMA: &str = "mesa.layout/1";

/// A scene layout in the dataset form: table frame, centimetres, quaternions in xyzw.
///
/// Readable by the official MesaTask tools (`dataset/vis_single.py`, `reconstruct_blender.py`):
/// every object has `retrieved_uid` and a 3-number `scale_factor`. Files without the `schema`
/// field (the released MesaTask-10K files) are read as this version.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct DatasetLayout {
    /// Schema id, `mesa.layout/1` (absent in the released MesaTask-10K files).
    #[serde(default = "layout_schema")]
    pub schema: String,
    /// The item placement zone [x_min, x_max, y_min, y_max] in cm, x_min = y_min = 0.
    #[serde(rename = "item_placement_zone")]
    pub zone_cm: ZoneCm,
    /// The restricted zone (the sink of a bathroom vanity) [x_min, x_max, y_min, y_max] in cm.
    #[serde(
        rename = "restricted_zone",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub restricted_zone_cm: Option<ZoneCm>,
    /// The objects, in the order mesa writes them: descending footprint w·d, ties by instance.
    pub objects: Vec<LayoutObject>,
    /// Keys of other tools, kept as they are.
    #[serde(flatten)]
    pub extra: BTreeMap<String, Value>,
}

fn layout_schema() -> String {
    LAYOUT_SCHEMA.to_owned()
}

/// One object of a dataset layout.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct LayoutObject {
    /// Instance name: category and index, like `mug_0`.
    /// 1 to 64 ASCII letters, digits, `_` or `-`, starting with a letter or digit.
    #[schemars(pattern(crate::validate::INSTANCE_NAME_PATTERN))]
    pub instance: String,
    /// The uid of the asset placed here (the file `assets/library/<uid>.glb`); empty when no
    /// asset has been retrieved yet (such a layout cannot be released).
    pub retrieved_uid: String,
    /// Centre of the object's bounding box in the table frame, [x, y, z] in cm.
    #[serde(rename = "position")]
    pub position_cm: PositionCm,
    /// Rotation from the object frame to the table frame, quaternion [x, y, z, w].
    pub rotation: QuatXyzw,
    /// [width (x), depth (y), height (z)] of the object before rotation, in cm.
    #[serde(rename = "size")]
    pub size_cm: SizeCm,
    /// The asset's scale per axis, [sx, sy, sz] (object frame).
    pub scale_factor: ScaleFactor,
    /// The object's category, like `mug`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub category: Option<String>,
    /// A short description of the object.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
    /// Yaw in degrees (0 faces the observer, counter-clockwise positive); written when the
    /// rotation is a pure yaw.
    #[serde(
        rename = "z_rotation",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub z_rotation_deg: Option<f64>,
    /// Which stage produced or last changed this object.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub provenance: Option<Provenance>,
    /// Keys of other tools, kept as they are.
    #[serde(flatten)]
    pub extra: BTreeMap<String, Value>,
}

/// Where an object of a layout comes from.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Provenance {
    /// The stage that wrote the object: `place`, `ingest`, `check`, `convert`, `demo`, ...
    pub stage: String,
    /// The instance id in `input/instances.json` this object was lifted from, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source_instance: Option<u32>,
    /// Free-form notes (for example "duplicated by the annotator from mug_0").
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}

impl DatasetLayout {
    /// Checks what the JSON Schema cannot say: unique instances, an ordered zone, unit
    /// quaternions, a `z_rotation` that agrees with `rotation`.
    pub fn problems(&self) -> Vec<Problem> {
        let mut problems = Vec::new();
        crate::units::check_zone(&self.zone_cm, "$.item_placement_zone", true, &mut problems);
        if let Some(zone) = &self.restricted_zone_cm {
            crate::units::check_zone(zone, "$.restricted_zone", false, &mut problems);
        }
        problems.extend(crate::validate::invalid_instances(
            self.objects.iter().map(|o| o.instance.as_str()),
        ));
        problems.extend(crate::validate::duplicate_instances(
            self.objects.iter().map(|o| o.instance.as_str()),
        ));
        for (i, object) in self.objects.iter().enumerate() {
            let at = format!("$.objects[{i}]");
            let norm = crate::rotation::quat_norm(object.rotation.0);
            if (norm - 1.0).abs() > 1e-3 {
                problems.push(Problem::new(
                    format!("{at}.rotation"),
                    format!("quaternion has norm {norm:.6}"),
                    "a unit quaternion [x, y, z, w]",
                ));
            } else if let Some(yaw) = object.z_rotation_deg {
                let tilt = crate::rotation::tilt_deg_from_quat_xyzw(object.rotation.0);
                let from_quat = crate::rotation::yaw_deg_from_quat_xyzw(object.rotation.0);
                let diff = crate::rotation::normalize_deg(yaw - from_quat).abs();
                if tilt < 1e-6 && diff > 1e-3 {
                    problems.push(Problem::new(
                        format!("{at}.z_rotation"),
                        format!("z_rotation {yaw} disagrees with rotation (yaw {from_quat:.4})"),
                        "z_rotation equal to the yaw of rotation",
                    ));
                }
            }
        }
        problems
    }
}
