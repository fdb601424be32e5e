//! `mesa import mesatask`: the released MesaTask-10K tree read into a mesa dataset whose scenes
//! enter at the refined stage (docs/import.md).
//!
//! ```text
//! SRC/Layout_info/<table_type>/<scene_id>/layout.json  → scenes/<t>/<s>/refined/layout.json
//! SRC/Layout_info/<table_type>/<scene_id>/front.png    → scenes/<t>/<s>/imported/front.png
//!                                     (what was dropped, fixed, missing) → imported/import.json
//! SRC/Asset_annotation.json                            → assets/annotations.json
//! SRC/sbert_text_features.pkl                          → assets/text_features.npy, text_uids.json
//! SRC/Assets_library/<uid>.glb                         → assets/library/<uid>.glb (linked)
//! ```
//!
//! This module holds the pure parts: a released layout read into a validated dataset layout
//! with what was dropped or fixed ([`import_layout`]), and the annotations with their text
//! field normalised ([`normalise_annotations`]).

use std::collections::{BTreeMap, BTreeSet};

use mesa_schemas::json::parse_lenient;
use mesa_schemas::layout::Provenance;
use mesa_schemas::validate::{describe, instance_name_problem, suggested_instance_name};
use mesa_schemas::{DatasetLayout, LayoutObject};
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};
use thiserror::Error;

use crate::annotations::AssetAnnotation;

/// Schema id of `imported/import.json`.
pub const IMPORT_SCHEMA: &str = "mesa.import/1";

/// The provenance stage of an object that came without one.
pub const IMPORT_STAGE: &str = "import";

/// Why a scene's layout cannot be imported at all (its objects are judged one by one).
#[derive(Debug, Error, PartialEq)]
pub enum ImportError {
    /// The file is not JSON.
    #[error("{file}: is not JSON: {problem} (expected MesaTask's layout.json, SPEC section 4)")]
    Json {
        /// The file, relative to the release.
        file: String,
        /// The parser's message.
        problem: String,
    },
    /// A field that the whole scene needs is wrong.
    #[error("{file}: {field}: {problem} (expected {expected})")]
    Field {
        /// The file, relative to the release.
        file: String,
        /// The JSON path.
        field: String,
        /// What is wrong.
        problem: String,
        /// What is expected.
        expected: String,
    },
}

/// An object left out of a scene, and why.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DroppedObject {
    /// Its index in the released `objects`.
    pub index: usize,
    /// Its instance name, when it had one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub instance: Option<String>,
    /// Why (`<field>: <problem>`).
    pub reason: String,
}

/// An object whose asset is not in the release's library.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct MissingGlb {
    /// The object.
    pub instance: String,
    /// The uid with no `Assets_library/<uid>.glb`.
    pub uid: String,
}

/// `imported/import.json`: where a scene came from and what the import changed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ImportNotes {
    /// [`IMPORT_SCHEMA`].
    pub schema: String,
    /// The released layout, relative to the release (`Layout_info/<t>/<s>/layout.json`).
    pub source: String,
    /// SHA-256 of that file.
    pub source_sha256: String,
    /// Objects in the released file.
    pub objects_released: usize,
    /// Objects in `refined/layout.json`.
    pub objects_kept: usize,
    /// Objects left out (MesaTask's own reader skips those without `retrieved_uid` or a
    /// three-number `scale_factor`).
    pub dropped: Vec<DroppedObject>,
    /// What was repaired, one line each (`$.objects[3].rotation: normalised (norm 0.98)`).
    pub fixed: Vec<String>,
    /// Objects kept whose GLB the release does not ship: stages that need meshes skip them.
    pub missing_glbs: Vec<MissingGlb>,
    /// Whether the release had `front.png` for the scene (kept as `imported/front.png`).
    pub front_png: bool,
    /// SHA-256 of the `refined/layout.json` written: while the scene's layout still has it,
    /// the release's `front.png` shows that layout (`mesa release` may use it).
    #[serde(default)]
    pub layout_sha256: String,
}

fn numbers(value: &Value, n: usize) -> Option<Vec<f64>> {
    let items = value.as_array()?;
    if items.len() != n {
        return None;
    }
    items
        .iter()
        .map(|v| v.as_f64().filter(|x| x.is_finite()))
        .collect()
}

/// Reads a released `layout.json` (`bytes`, named `file` in messages) into a dataset layout:
/// objects MesaTask's reader would skip, or that mesa cannot read, are dropped with the reason;
/// what can be repaired is repaired and said (a quaternion off unit norm, a `z_rotation` that
/// disagrees with `rotation`, a missing, invalid or repeated instance name); objects keep
/// their order and every other key. `has_glb` says whether the release ships a uid's GLB.
pub fn import_layout(
    bytes: &[u8],
    file: &str,
    has_glb: &dyn Fn(&str) -> bool,
) -> Result<(DatasetLayout, ImportNotes), ImportError> {
    let field_error = |field: &str, problem: String, expected: &str| ImportError::Field {
        file: file.to_owned(),
        field: field.to_owned(),
        problem,
        expected: expected.to_owned(),
    };
    let text = std::str::from_utf8(bytes).map_err(|e| ImportError::Json {
        file: file.to_owned(),
        problem: format!("not UTF-8: {e}"),
    })?;
    let value = parse_lenient(text).map_err(|e| ImportError::Json {
        file: file.to_owned(),
        problem: e.to_string(),
    })?;
    let Value::Object(mut top) = value else {
        return Err(field_error(
            "$",
            describe(&value),
            "an object with item_placement_zone and objects",
        ));
    };
    let objects = match top.remove("objects") {
        Some(Value::Array(objects)) => objects,
        Some(other) => {
            return Err(field_error(
                "$.objects",
                describe(&other),
                "a list of objects",
            ))
        }
        None => {
            return Err(field_error(
                "$.objects",
                "missing".into(),
                "a list of objects",
            ))
        }
    };
    let mut notes = ImportNotes {
        schema: IMPORT_SCHEMA.to_owned(),
        source: file.to_owned(),
        source_sha256: crate::sha256_hex(bytes),
        objects_released: objects.len(),
        objects_kept: 0,
        dropped: Vec::new(),
        fixed: Vec::new(),
        missing_glbs: Vec::new(),
        front_png: false,
        layout_sha256: String::new(),
    };
    top.remove("schema");
    // The scene without its objects: zone, restricted zone and other keys, checked by serde.
    top.insert("objects".into(), Value::Array(Vec::new()));
    let mut layout: DatasetLayout = serde_json::from_value(Value::Object(top)).map_err(|e| {
        field_error(
            "$",
            e.to_string(),
            "item_placement_zone [x_min, x_max, y_min, y_max] in cm and an optional restricted_zone",
        )
    })?;
    let zone_problems: Vec<_> = layout
        .problems()
        .into_iter()
        .filter(|p| p.path.contains("zone"))
        .collect();
    if let Some(problem) = zone_problems.first() {
        return Err(field_error(
            &problem.path,
            problem.problem.clone(),
            &problem.expected,
        ));
    }
    let mut used: BTreeSet<String> = BTreeSet::new();
    for (index, raw) in objects.into_iter().enumerate() {
        let at = format!("$.objects[{index}]");
        let instance = raw
            .get("instance")
            .and_then(Value::as_str)
            .map(str::to_owned);
        let mut drop = |reason: String| {
            notes.dropped.push(DroppedObject {
                index,
                instance: instance.clone(),
                reason,
            });
        };
        let Value::Object(mut object) = raw else {
            drop(format!("{at}: {} (expected an object)", describe(&raw)));
            continue;
        };
        match object.get("retrieved_uid") {
            Some(Value::String(uid)) if !uid.is_empty() => {}
            other => {
                drop(format!(
                    "{at}.retrieved_uid: {} (MesaTask's reader skips an object without it)",
                    other.map_or("missing".to_owned(), describe)
                ));
                continue;
            }
        }
        match object.get("scale_factor").map(|v| numbers(v, 3)) {
            Some(Some(scale)) if scale.iter().all(|s| *s > 0.0) => {}
            other => {
                drop(format!(
                    "{at}.scale_factor: {} (expected three positive numbers; MesaTask's reader \
                     skips an object without them)",
                    match other {
                        None => "missing".to_owned(),
                        Some(_) => object
                            .get("scale_factor")
                            .map_or_else(String::new, describe),
                    }
                ));
                continue;
            }
        }
        let mut bad = None;
        for (key, n) in [("position", 3), ("rotation", 4), ("size", 3)] {
            if object.get(key).and_then(|v| numbers(v, n)).is_none() {
                bad = Some(format!(
                    "{at}.{key}: {} (expected {n} finite numbers)",
                    object.get(key).map_or("missing".to_owned(), describe)
                ));
                break;
            }
        }
        if let Some(reason) = bad {
            drop(reason);
            continue;
        }
        // Instance: present, valid, unique; else a name from the category or uid.
        let name = match &instance {
            Some(name) if instance_name_problem(name).is_none() => name.clone(),
            Some(name) => {
                let fixed = suggested_instance_name(name);
                notes.fixed.push(format!(
                    "{at}.instance: {name:?} is not a valid instance name; renamed {fixed:?}"
                ));
                fixed
            }
            None => {
                let base = object
                    .get("category")
                    .and_then(Value::as_str)
                    .map_or_else(|| "object".to_owned(), suggested_instance_name);
                let fixed = format!("{base}_{index}");
                let fixed = if instance_name_problem(&fixed).is_none() {
                    fixed
                } else {
                    format!("object_{index}")
                };
                notes
                    .fixed
                    .push(format!("{at}.instance: missing; named {fixed:?}"));
                fixed
            }
        };
        let mut unique = name.clone();
        let mut k = 1;
        while used.contains(&unique) {
            unique = format!("{name}_dup{k}");
            k += 1;
        }
        if unique != name {
            notes.fixed.push(format!(
                "{at}.instance: {name:?} repeats an earlier object; renamed {unique:?}"
            ));
        }
        used.insert(unique.clone());
        object.insert("instance".into(), Value::String(unique.clone()));
        // The quaternion: MesaTask's reader uses it as is; a non-unit one is normalised.
        let rotation = numbers(&object["rotation"], 4).unwrap_or_default();
        let norm = rotation.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm < 1e-9 {
            drop(format!(
                "{at}.rotation: {rotation:?} has norm 0 (expected a unit quaternion [x, y, z, w])"
            ));
            used.remove(&unique);
            continue;
        }
        if (norm - 1.0).abs() > 1e-3 {
            let unit: Vec<Value> = rotation.iter().map(|x| Value::from(x / norm)).collect();
            object.insert("rotation".into(), Value::Array(unit));
            notes.fixed.push(format!(
                "{at}.rotation: norm {norm:.6}, normalised (expected a unit quaternion [x, y, z, w])"
            ));
        }
        if object.get("z_rotation").is_some_and(|v| !v.is_number()) {
            notes.fixed.push(format!(
                "{at}.z_rotation: {} is not a number; removed",
                describe(&object["z_rotation"])
            ));
            object.remove("z_rotation");
        }
        for key in ["category", "description"] {
            if object.get(key).is_some_and(|v| !v.is_string()) {
                let value = object.remove(key).unwrap_or(Value::Null);
                object.insert(format!("released_{key}"), value);
                notes
                    .fixed
                    .push(format!("{at}.{key}: not a string; kept as released_{key}"));
            }
        }
        if object
            .get("provenance")
            .is_some_and(|v| serde_json::from_value::<Provenance>(v.clone()).is_err())
        {
            let value = object.remove("provenance").unwrap_or(Value::Null);
            object.insert("released_provenance".into(), value);
            notes.fixed.push(format!(
                "{at}.provenance: not mesa's form; kept as released_provenance"
            ));
        }
        let mut parsed: LayoutObject = match serde_json::from_value(Value::Object(object)) {
            Ok(parsed) => parsed,
            Err(e) => {
                drop(format!("{at}: {e}"));
                used.remove(&unique);
                continue;
            }
        };
        if let Some(yaw) = parsed.z_rotation_deg {
            let q = parsed.rotation.0;
            let tilt = mesa_schemas::rotation::tilt_deg_from_quat_xyzw(q);
            let from_quat = mesa_schemas::rotation::yaw_deg_from_quat_xyzw(q);
            let diff = mesa_schemas::rotation::normalize_deg(yaw - from_quat).abs();
            if tilt < 1e-6 && diff > 1e-3 {
                notes.fixed.push(format!(
                    "{at}.z_rotation: {yaw} disagrees with rotation (yaw {from_quat:.4}); \
                     removed (rotation is what MesaTask's reader uses)"
                ));
                parsed.z_rotation_deg = None;
            }
        }
        if parsed.provenance.is_none() {
            parsed.provenance = Some(Provenance {
                stage: IMPORT_STAGE.to_owned(),
                source_instance: None,
                notes: Vec::new(),
            });
        }
        if !has_glb(&parsed.retrieved_uid) {
            notes.missing_glbs.push(MissingGlb {
                instance: parsed.instance.clone(),
                uid: parsed.retrieved_uid.clone(),
            });
        }
        layout.objects.push(parsed);
    }
    notes.objects_kept = layout.objects.len();
    if let Some(problem) = layout.problems().first() {
        // Every problem the checks know was repaired above; one left is a bug or a new case.
        return Err(field_error(
            &problem.path,
            problem.problem.clone(),
            &problem.expected,
        ));
    }
    Ok((layout, notes))
}

/// The text fields of an annotation, in the order one is taken as `description`: mesa's and
/// objathor's `description`, then what MesaTask's downstream code reads.
pub const TEXT_FIELDS: [&str; 3] = ["description", "detailed_caption", "caption"];

/// The field naming where `description` came from.
pub const TEXT_SOURCE_FIELD: &str = "description_source";

/// An annotation as a release writes it: [`TEXT_SOURCE_FIELD`] removed, so that release →
/// import → release gives the same `Asset_annotation.json`. The `description` stays (mesa's
/// `asset-annotations` kind requires it; MesaTask's code reads `detailed_caption`, which is
/// kept beside it).
pub fn released_annotation(entry: &Value) -> Value {
    let Value::Object(fields) = entry else {
        return entry.clone();
    };
    let mut fields = fields.clone();
    fields.remove(TEXT_SOURCE_FIELD);
    Value::Object(fields)
}

/// What [`normalise_annotations`] did.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct AnnotationReport {
    /// Annotations kept.
    pub kept: usize,
    /// How many took `description` from each field.
    pub text_from: BTreeMap<String, usize>,
    /// Annotations with no text field.
    pub without_text: usize,
    /// Entries left out, with the reason (`<uid>.<field>: <problem>`).
    pub dropped: BTreeMap<String, String>,
}

/// `Asset_annotation.json` (a JSON object by uid) with every field kept and the text field
/// normalised: `description` is set from the first of [`TEXT_FIELDS`] present and
/// [`TEXT_SOURCE_FIELD`] names it. Entries mesa cannot read (a bbox that is not one of the four
/// forms, a non-object) are left out and reported. Bboxes stay as released (glTF Y-up, every
/// form read by [`crate::annotations`]).
pub fn normalise_annotations(
    value: Value,
    file: &str,
) -> Result<(Map<String, Value>, AnnotationReport), ImportError> {
    let Value::Object(entries) = value else {
        return Err(ImportError::Field {
            file: file.to_owned(),
            field: "$".into(),
            problem: describe(&value),
            expected: "a JSON object keyed by asset uid".into(),
        });
    };
    let mut out = Map::new();
    let mut report = AnnotationReport::default();
    for (uid, entry) in entries {
        let Value::Object(mut fields) = entry else {
            report.dropped.insert(
                uid.clone(),
                format!("{uid}: {} (expected an object)", describe(&entry)),
            );
            continue;
        };
        let source = TEXT_FIELDS.iter().find(|k| {
            fields
                .get(**k)
                .and_then(Value::as_str)
                .is_some_and(|s| !s.trim().is_empty())
        });
        match source {
            Some(&key) => {
                let text = fields[key].clone();
                fields.insert("description".into(), text);
                fields.insert(TEXT_SOURCE_FIELD.into(), Value::String(key.to_owned()));
                *report.text_from.entry(key.to_owned()).or_default() += 1;
            }
            None => report.without_text += 1,
        }
        let entry = Value::Object(fields);
        if let Err(e) = AssetAnnotation::from_value(&uid, &entry) {
            report.dropped.insert(uid.clone(), e.to_string());
            continue;
        }
        out.insert(uid, entry);
    }
    report.kept = out.len();
    Ok((out, report))
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn layout_bytes(objects: Value) -> Vec<u8> {
        serde_json::to_vec(&json!({"item_placement_zone": [0, 120, 0, 60], "objects": objects}))
            .expect("json")
    }

    fn object(instance: &str, uid: &str) -> Value {
        json!({"instance": instance, "retrieved_uid": uid, "position": [10, 20, 5],
               "rotation": [0, 0, 0, 1], "size": [8, 8, 10], "scale_factor": [1, 1, 1]})
    }

    #[test]
    fn objects_their_reader_skips_are_dropped_with_the_reason() {
        let mut no_scale = object("mug_1", "u2");
        no_scale.as_object_mut().expect("o").remove("scale_factor");
        let mut no_uid = object("mug_2", "u3");
        no_uid.as_object_mut().expect("o").remove("retrieved_uid");
        let bytes = layout_bytes(json!([object("mug_0", "u1"), no_scale, no_uid]));
        let (layout, notes) = import_layout(&bytes, "l.json", &|_| true).expect("imports");
        assert_eq!(layout.objects.len(), 1);
        assert_eq!(notes.dropped.len(), 2);
        assert!(notes.dropped[0].reason.contains("scale_factor"));
        assert!(notes.dropped[1].reason.contains("retrieved_uid"));
        // Control: a complete scene drops nothing.
        let bytes = layout_bytes(json!([object("mug_0", "u1")]));
        let (_, notes) = import_layout(&bytes, "l.json", &|_| true).expect("imports");
        assert!(notes.dropped.is_empty() && notes.fixed.is_empty());
    }

    #[test]
    fn repairs_are_said_and_missing_glbs_flagged() {
        let mut tilted = object("mug_0", "u1");
        tilted["rotation"] = json!([0, 0, 0, 2]);
        let bytes = layout_bytes(json!([tilted, object("mug_0", "u2")]));
        let (layout, notes) = import_layout(&bytes, "l.json", &|uid| uid == "u1").expect("ok");
        assert_eq!(layout.objects[0].rotation.0, [0.0, 0.0, 0.0, 1.0]);
        assert_eq!(layout.objects[1].instance, "mug_0_dup1");
        assert_eq!(notes.fixed.len(), 2, "{:?}", notes.fixed);
        assert_eq!(
            notes.missing_glbs,
            vec![MissingGlb {
                instance: "mug_0_dup1".into(),
                uid: "u2".into()
            }]
        );
    }

    #[test]
    fn a_broken_zone_fails_the_scene_naming_the_field() {
        let bytes = serde_json::to_vec(&json!({"objects": []})).expect("json");
        let err = import_layout(&bytes, "a/layout.json", &|_| true).expect_err("no zone");
        assert!(err.to_string().starts_with("a/layout.json: "), "{err}");
        assert!(import_layout(b"{", "x", &|_| true).is_err());
    }

    #[test]
    fn detailed_caption_becomes_description_with_its_source() {
        let (out, report) = normalise_annotations(
            json!({"a": {"detailed_caption": "a red mug", "bbox": {"x": 1, "y": 2, "z": 3}},
                   "b": {"description": "a book", "detailed_caption": "other"},
                   "c": {"category": "cup"},
                   "d": {"bbox": "wide"}}),
            "Asset_annotation.json",
        )
        .expect("ok");
        assert_eq!(out["a"]["description"], "a red mug");
        assert_eq!(out["a"][TEXT_SOURCE_FIELD], "detailed_caption");
        assert_eq!(out["a"]["bbox"], json!({"x": 1, "y": 2, "z": 3}));
        assert_eq!(out["b"]["description"], "a book");
        assert_eq!(out["b"]["detailed_caption"], "other");
        assert_eq!(report.without_text, 2);
        // For a release: without the source field, and normalising again changes nothing.
        assert_eq!(
            released_annotation(&out["a"]),
            json!({"description": "a red mug", "detailed_caption": "a red mug",
                   "bbox": {"x": 1, "y": 2, "z": 3}})
        );
        assert_eq!(
            released_annotation(&out["b"]),
            json!({"description": "a book", "detailed_caption": "other"})
        );
        assert!(report.dropped.contains_key("d"), "{report:?}");
        assert_eq!(report.kept, 3);
    }
}
