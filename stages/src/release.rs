//! `release` (SPEC 5.10): the files of the MesaTask-10K tree.
//!
//! ```text
//! OUT/Layout_info/<table_type>/<scene_id>/layout.json   the scene's layout
//! OUT/Layout_info/<table_type>/<scene_id>/front.png     its front view
//! OUT/Asset_annotation.json                             the annotations of the assets used
//! ```
//!
//! A released `layout.json` is the dataset layout without mesa's `schema` field, as the
//! released MesaTask-10K files are (mesa reads a file without it as `mesa.layout/1`, so the
//! file reads back into the same layout): `item_placement_zone`, `restricted_zone` where there
//! is a sink, and per object the fields MesaTask's reader (`dataset/vis_single.py` →
//! `reconstruct_blender.py`) uses, `instance`, `retrieved_uid`, `position` (cm), `rotation`
//! (quaternion x, y, z, w), `size` (cm), `scale_factor` (three numbers), `z_rotation`, with
//! mesa's `category`, `description` and `provenance` beside them (the reader ignores keys it
//! does not know). The official reader silently skips an object without `retrieved_uid` or
//! with a `scale_factor` that is not three numbers: [`release_layout`] refuses them instead.

use std::collections::{BTreeMap, BTreeSet};

use mesa_schemas::json::to_sorted_pretty;
use mesa_schemas::DatasetLayout;
use serde_json::Value;
use thiserror::Error;

/// Why a layout or the annotations cannot be released.
#[derive(Debug, Error, PartialEq)]
pub enum ReleaseError {
    /// An object has no asset.
    #[error("$.objects[{index}] ({instance}).retrieved_uid: empty (expected the uid of its asset: MesaTask's reader skips objects without one)")]
    NoUid {
        /// The object's index.
        index: usize,
        /// Its instance.
        instance: String,
    },
    /// An object's scale factor is not three positive numbers.
    #[error("$.objects[{index}] ({instance}).scale_factor: {scale:?} (expected three positive numbers: MesaTask's reader skips objects without them)")]
    BadScale {
        /// The object's index.
        index: usize,
        /// Its instance.
        instance: String,
        /// The scale factor.
        scale: [f64; 3],
    },
    /// Assets used by the layouts have no annotation.
    #[error("no annotation for {} assets used by the released layouts: {} (expected an entry per uid in assets/annotations.json)", .0.len(), .0.join(", "))]
    Unannotated(Vec<String>),
    /// The annotations file is not a JSON object by uid.
    #[error("assets/annotations.json: {0} (expected a JSON object keyed by asset uid)")]
    Annotations(String),
    /// Serialisation failed.
    #[error("cannot serialise: {0}")]
    Json(String),
}

/// The bytes of a released `layout.json` (see the module documentation).
pub fn release_layout(layout: &DatasetLayout) -> Result<Vec<u8>, ReleaseError> {
    for (index, object) in layout.objects.iter().enumerate() {
        if object.retrieved_uid.is_empty() {
            return Err(ReleaseError::NoUid {
                index,
                instance: object.instance.clone(),
            });
        }
        let scale = object.scale_factor.0;
        if scale.iter().any(|s| !(*s > 0.0 && s.is_finite())) {
            return Err(ReleaseError::BadScale {
                index,
                instance: object.instance.clone(),
                scale,
            });
        }
    }
    let mut value = serde_json::to_value(layout).map_err(|e| ReleaseError::Json(e.to_string()))?;
    if let Some(object) = value.as_object_mut() {
        object.remove("schema");
    }
    to_sorted_pretty(&value).map_err(|e| ReleaseError::Json(e.to_string()))
}

/// `Asset_annotation.json`: the annotations (as written in `assets/annotations.json`) of the
/// assets `uids`, by uid.
pub fn release_annotations(
    annotations: &Value,
    uids: &BTreeSet<String>,
) -> Result<Vec<u8>, ReleaseError> {
    let all = annotations
        .as_object()
        .ok_or_else(|| ReleaseError::Annotations(mesa_schemas::validate::describe(annotations)))?;
    let mut out = BTreeMap::new();
    let mut missing = Vec::new();
    for uid in uids {
        match all.get(uid) {
            Some(entry) => {
                out.insert(uid.clone(), entry.clone());
            }
            None => missing.push(uid.clone()),
        }
    }
    if !missing.is_empty() {
        return Err(ReleaseError::Unannotated(missing));
    }
    to_sorted_pretty(&out).map_err(|e| ReleaseError::Json(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use mesa_schemas::layout_file::{read_layout_text, AnyLayout};

    fn layout() -> DatasetLayout {
        serde_json::from_value(serde_json::json!({
            "schema": "mesa.layout/1",
            "item_placement_zone": [0.0, 120.0, 0.0, 60.0],
            "objects": [{
                "instance": "mug_0", "retrieved_uid": "u1", "position": [10.0, 20.0, 5.0],
                "rotation": [0.0, 0.0, 0.0, 1.0], "size": [8.0, 8.0, 10.0],
                "scale_factor": [1.0, 1.0, 1.0], "category": "mug", "z_rotation": 0.0
            }]
        }))
        .expect("layout")
    }

    #[test]
    fn a_released_layout_has_no_schema_and_reads_back_the_same() {
        let bytes = release_layout(&layout()).expect("release");
        let text = String::from_utf8(bytes).expect("utf8");
        assert!(!text.contains("\"schema\""), "{text}");
        let read = read_layout_text(&text).expect("reads");
        match read.layout {
            AnyLayout::Dataset(back) => assert_eq!(back, layout()),
            AnyLayout::Llm(_) => panic!("read as an LLM layout"),
        }
    }

    #[test]
    fn objects_the_official_reader_would_skip_are_refused() {
        let mut l = layout();
        l.objects[0].retrieved_uid.clear();
        assert_eq!(
            release_layout(&l),
            Err(ReleaseError::NoUid {
                index: 0,
                instance: "mug_0".into()
            })
        );
        let mut l = layout();
        l.objects[0].scale_factor.0 = [1.0, 0.0, 1.0];
        let err = release_layout(&l).expect_err("zero scale");
        assert!(err.to_string().contains("scale_factor"), "{err}");
    }

    #[test]
    fn annotations_of_used_assets_only_and_missing_ones_named() {
        let all = serde_json::json!({"u1": {"category": "mug"}, "u2": {"category": "book"}});
        let uids = BTreeSet::from(["u1".to_owned()]);
        let bytes = release_annotations(&all, &uids).expect("annotations");
        let back: Value = serde_json::from_slice(&bytes).expect("json");
        assert_eq!(back, serde_json::json!({"u1": {"category": "mug"}}));
        let uids = BTreeSet::from(["u3".to_owned()]);
        let err = release_annotations(&all, &uids).expect_err("missing");
        assert!(err.to_string().contains("u3"), "{err}");
    }
}
