//! `release` (SPEC 5.10): the files of the MesaTask-10K tree.
//!
//! ```text
//! OUT/Layout_info/<table_type>/<scene_id>/layout.json   the scene's layout
//! OUT/Layout_info/<table_type>/<scene_id>/front.png     its front view
//! OUT/Asset_annotation.json                             the annotations of the assets used
//! OUT/Assets_library/<uid>.glb                          each asset used, flattened
//! OUT/Assets_library/3cc47c3f78d34985bf4314de2f8196dd.glb   the table MesaTask's config names
//! OUT/Assets_library/sink_cube.glb                      the sink it names
//! ```
//!
//! MesaTask's reconstruction (`reconstruct_blender.py`) imports `<uid>.glb`, applies and joins
//! the transforms of the *mesh* objects only, scales the joined mesh to `size` and places it at
//! `position`; an empty parent node stays in place and still transforms its children, so a GLB
//! authored in centimetres under a root scaled by 0.01 lands at 1/100 of its place.
//! [`flat_asset_glb`] therefore writes each asset as one node without a transform drawing one
//! mesh whose vertices carry every node transform (the pack's bake, without the front turn:
//! the asset keeps its own axes, which `rotation` refers to), centred on its bounding box,
//! with its materials, textures and samplers. [`zone_box_glb`] writes the table and sink: a
//! 1 m cube each, which the reconstruction scales to the zone (1 cm and 0.5 cm thick).
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

use std::collections::{BTreeMap, BTreeSet, HashMap};

use mesa_schemas::json::to_sorted_pretty;
use mesa_schemas::DatasetLayout;
use serde_json::Value;
use thiserror::Error;

use crate::glb_write::{GlbBuilder, GlbWriteError, MaterialSpec, NodeSpec};
use crate::mesh::TriMesh;
use crate::pack::bake::bake_asset;
use crate::pack::{add_asset, PackError};

/// How a release writes `Assets_library/`.
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Default,
    serde::Serialize,
    serde::Deserialize,
    schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum ReleaseAssets {
    /// Hard-link each used GLB that MesaTask's reconstruction places right as it is
    /// ([`placed_right_by_mesatask`]); write the others flattened ([`flat_asset_glb`]).
    #[default]
    Auto,
    /// Write every used GLB flattened.
    Bake,
    /// Hard-link every used GLB as it is (MesaTask misplaces GLBs with transformed parents).
    Link,
    /// No `Assets_library/` (layouts and annotations only).
    None,
}

/// The `[release]` section of `mesa.toml`.
#[derive(
    Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize, schemars::JsonSchema,
)]
#[serde(default, deny_unknown_fields)]
pub struct ReleaseConfig {
    /// How `Assets_library/` is written: "auto" (hard-link the GLBs MesaTask's reconstruction
    /// places right as they are, flatten the others: node transforms baked into the vertices),
    /// "bake" (flatten all), "link" (hard-link all as they are) or "none". The table and sink
    /// GLBs MesaTask's config names are written unless "none". `mesa release --assets`
    /// overrides it.
    pub assets: ReleaseAssets,
}

/// The table GLB MesaTask's `config.yaml` names (`table_model_path`), a file stem.
pub const TABLE_GLB_UID: &str = "3cc47c3f78d34985bf4314de2f8196dd";
/// The sink GLB it names (`sink_model_path`), a file stem.
pub const SINK_GLB_UID: &str = "sink_cube";

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

/// Whether `uid` names a file of `Assets_library/` and nothing else: not empty, not `.` or
/// `..`, no path separator, no NUL, no leading dot. A layout's `retrieved_uid` is outside input:
/// a release writes `Assets_library/<uid>.glb` only for such names.
pub fn plain_uid(uid: &str) -> bool {
    !uid.is_empty() && !uid.starts_with('.') && !uid.contains(['/', '\\', '\0']) && uid.len() <= 200
}

/// The release copy of the library GLB `bytes` of asset `uid`: one node without a transform,
/// one mesh with every node transform baked into its vertices, centred on its bounding box
/// (see the module documentation).
pub fn flat_asset_glb(uid: &str, bytes: &[u8]) -> Result<Vec<u8>, PackError> {
    let baked = bake_asset(bytes, 0.0).map_err(|source| PackError::Asset {
        uid: uid.to_owned(),
        instance: "(release)".to_owned(),
        source,
    })?;
    let mut b = GlbBuilder::new(concat!("mesa release ", env!("CARGO_PKG_VERSION")));
    let mut images = HashMap::new();
    let mesh = add_asset(&mut b, uid, &baked, &mut images)?;
    let node = b.add_node(NodeSpec::new(uid).with_mesh(mesh))?;
    b.set_scene(uid, vec![node]);
    Ok(b.finish()?)
}

/// Whether MesaTask's reconstruction places the GLB `bytes` right as it is: every node of its
/// default scene either has no transform, or is a root node drawing a mesh with no children
/// (its transform is one the reconstruction applies). Otherwise (a transform on an empty
/// parent, or on a node with children) the release needs [`flat_asset_glb`].
pub fn placed_right_by_mesatask(bytes: &[u8]) -> Result<bool, crate::glb_read::GlbError> {
    let document = crate::glb_read::open_glb(bytes)?;
    let root = document.root();
    let scene = root
        .scene
        .map(|s| s.value())
        .or((!root.scenes.is_empty()).then_some(0));
    let Some(scene) = scene.and_then(|s| root.scenes.get(s)) else {
        return Ok(false);
    };
    let moves = |node: &gltf_json::Node| {
        let identity = [
            1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
        ];
        node.matrix.is_some_and(|m| m != identity)
            || node.translation.is_some_and(|t| t != [0.0; 3])
            || node.rotation.is_some_and(|r| r.0 != [0.0, 0.0, 0.0, 1.0])
            || node.scale.is_some_and(|s| s != [1.0; 3])
    };
    let mut stack: Vec<(usize, bool)> = scene.nodes.iter().map(|n| (n.value(), true)).collect();
    let mut seen = BTreeSet::new();
    while let Some((index, top)) = stack.pop() {
        let Some(node) = root.nodes.get(index) else {
            return Ok(false);
        };
        if !seen.insert(index) {
            continue;
        }
        let children = node.children.as_deref().unwrap_or_default();
        if moves(node) && !(top && node.mesh.is_some() && children.is_empty()) {
            return Ok(false);
        }
        stack.extend(children.iter().map(|c| (c.value(), false)));
    }
    Ok(true)
}

/// A 1 m cube named `name` in `linear_rgb`, centred on the origin: the table or sink GLB of a
/// release (MesaTask's reconstruction scales it to its zone).
pub fn zone_box_glb(name: &str, linear_rgb: [f32; 3]) -> Result<Vec<u8>, GlbWriteError> {
    let mut b = GlbBuilder::new(concat!("mesa release ", env!("CARGO_PKG_VERSION")));
    let material = b.add_material(&MaterialSpec::plain(name, linear_rgb, 0.8));
    let mesh = b.add_mesh(name, &[(&TriMesh::cuboid([1.0, 1.0, 1.0]), material)])?;
    let node = b.add_node(NodeSpec::new(name).with_mesh(mesh))?;
    b.set_scene(name, vec![node]);
    b.finish()
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

    fn bounds(positions: &[[f64; 3]]) -> ([f64; 3], [f64; 3]) {
        let b = crate::mesh::Aabb::from_points(positions.iter().copied()).expect("points");
        (b.min, b.max)
    }

    #[test]
    fn a_released_asset_is_one_node_without_a_transform_drawing_the_baked_hierarchy() {
        use crate::glb_read::read_glb;
        use crate::pack::testing::{hierarchy_asset, split_glb, textured_asset};
        let source = hierarchy_asset();
        let flat = flat_asset_glb("lamp", &source).expect("flattens");
        let (root, _) = split_glb(&flat);
        assert_eq!(root.nodes.len(), 1);
        let node = &root.nodes[0];
        assert!(node.translation.is_none() && node.rotation.is_none() && node.scale.is_none());
        // The same triangles in the same places, up to the shift that centres them.
        let (a, b) = (
            read_glb(&source).expect("source"),
            read_glb(&flat).expect("flat"),
        );
        assert_eq!(a.triangles.len(), b.triangles.len());
        let (lo_a, hi_a) = bounds(&a.positions_m);
        let (lo_b, hi_b) = bounds(&b.positions_m);
        for axis in 0..3 {
            let size = hi_a[axis] - lo_a[axis];
            assert!(
                (size - (hi_b[axis] - lo_b[axis])).abs() < 1e-6,
                "axis {axis}"
            );
            assert!(
                (lo_b[axis] + hi_b[axis]).abs() < 1e-6,
                "centred on axis {axis}"
            );
        }
        // Control: the source is not flat (the root scales its children by 2).
        let (source_root, _) = split_glb(&source);
        assert!(source_root.nodes.iter().any(|n| n.scale.is_some()));
        // Textures, materials and samplers are kept.
        let (textured, _) = split_glb(&flat_asset_glb("mug", &textured_asset()).expect("mug"));
        assert_eq!(textured.images.len(), 1);
        assert_eq!(textured.materials.len(), 2);
        assert!(flat_asset_glb("junk", b"not a glb").is_err());
        // MesaTask places the flat one and the plain one right, not the hierarchy.
        assert!(placed_right_by_mesatask(&flat).expect("flat"));
        assert!(placed_right_by_mesatask(&textured_asset()).expect("plain"));
        assert!(!placed_right_by_mesatask(&source).expect("hierarchy"));
    }

    #[test]
    fn only_plain_uids_name_release_files() {
        for good in [
            "Duck",
            "3cc47c3f78d34985bf4314de2f8196dd",
            "mug_tinkercad",
            "a.b",
        ] {
            assert!(plain_uid(good), "{good}");
        }
        for bad in ["", ".", "..", "../x", "a/b", "a\\b", ".hidden", "a\0b"] {
            assert!(!plain_uid(bad), "{bad:?}");
        }
        assert!(!plain_uid(&"x".repeat(201)));
    }

    #[test]
    fn the_zone_boxes_are_unit_cubes() {
        let bytes = zone_box_glb("table", [0.5, 0.4, 0.3]).expect("box");
        let mesh = crate::glb_read::read_glb(&bytes).expect("reads");
        let (lo, hi) = bounds(&mesh.positions_m);
        for axis in 0..3 {
            assert!((lo[axis] + 0.5).abs() < 1e-6 && (hi[axis] - 0.5).abs() < 1e-6);
        }
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
