//! The simulated annotator of the demo: it plays the person of SPEC step 7 on a demo scene's
//! pack, with the demo's ground truth as the photo it compares with, and writes the edited
//! scene as Blender's glTF exporter writes it after such a session.
//!
//! What it does, as a person would in Blender:
//! - the table top is scaled and moved to the true table top (a resized table);
//! - each object is moved, turned and scaled to its true place, turn and size (the scale is
//!   per axis: non-uniform where the retrieved asset's proportions differ from the true
//!   object's);
//! - an object detected twice (two pack objects for one true object) loses its copy, and an
//!   object that is in no photo is deleted;
//! - a true object missing from the pack is made by duplicating (Shift+D) an object of the
//!   same asset, which Blender names `<name>.001`; in some scenes (chosen by the seed) one
//!   object of an asset used twice is deleted and made again from its twin the same way;
//! - a sink missing from the pack is added as a box named `restricted_zone`;
//! - the file is exported with Blender's defaults: custom properties (extras) are not
//!   written, every object keeps its mesh in local space, copies get their own mesh data.
//!
//! The output is deterministic: a function of the pack, the truth, the seed and the scene id.

use std::collections::{BTreeMap, BTreeSet, HashMap};

use mesa_schemas::annotation::PackIndexArtifact;
use mesa_schemas::artifacts::TruthInstances;
use mesa_schemas::layout::{DatasetLayout, LayoutObject};
use rand::Rng as _;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::glb_read::{open_glb, GlbDocument, GlbError};
use crate::glb_write::{GlbBuilder, GlbWriteError, MaterialSpec, NodeSpec};
use crate::gltf_frames::{
    gltf_from_object_axes, gltf_from_table_point, gltf_from_table_quat, object_from_gltf_axes,
    table_from_gltf_point, table_from_gltf_quat,
};
use crate::mesh::{normalize3, quat_normalize, TriMesh};
use crate::pack::bake::MaterialReader;
use crate::pack::{
    add_materials, H1_NODE, RESTRICTED_ZONE_HEIGHT_M, RESTRICTED_ZONE_NODE, TABLE_NODE,
};

/// The generator string Blender 4.3's exporter writes.
pub const BLENDER_GENERATOR: &str = "Khronos glTF Blender I/O v4.3.47";

/// Who edits the packs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema, Default)]
#[serde(rename_all = "snake_case")]
pub enum Annotator {
    /// A person: `mesa run` stops each scene after `pack` until its edited
    /// `refined/<scene_id>.glb` arrives, and reports it as awaiting annotation.
    #[default]
    Human,
    /// The simulated annotator of `mesa demo` (demo datasets only: it reads `truth/`).
    Simulated,
}

/// The `[annotate]` section of `mesa.toml`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct AnnotateConfig {
    /// "human" (mesa run waits for each scene's refined/<scene_id>.glb) or "simulated" (the
    /// demo's simulated annotator edits every pack from truth/, between pack and ingest;
    /// `mesa demo` writes this).
    pub annotator: Annotator,
}

/// What the simulated annotator reads.
#[derive(Debug, Clone, Copy)]
pub struct AnnotateRequest<'a> {
    /// The scene id.
    pub scene_id: &'a str,
    /// `pack/<scene_id>.glb`.
    pub pack_glb: &'a [u8],
    /// `pack/index.json`.
    pub index: &'a PackIndexArtifact,
    /// The layout the pack was made from.
    pub baseline: &'a DatasetLayout,
    /// `truth/layout.json`.
    pub truth: &'a DatasetLayout,
    /// `truth/instances.json`.
    pub truth_instances: &'a TruthInstances,
    /// `[run] seed`.
    pub seed: u64,
}

/// What the simulated annotator did.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Annotation {
    /// The edited scene, as Blender exports it.
    pub glb: Vec<u8>,
    /// Pack objects deleted (duplicates, objects in no photo, objects re-made from a twin).
    pub deleted: Vec<String>,
    /// Copies made: (node name, the object copied).
    pub duplicated: Vec<(String, String)>,
    /// True objects it could not make (no pack object of their asset to copy).
    pub missing: Vec<String>,
    /// Whether it added the restricted zone.
    pub restricted_zone_added: bool,
    /// The same session as Blender operations, in order (`scripts/blender_pack.py edit`
    /// applies them to the pack: the check that this writes what Blender writes).
    pub blender_ops: Vec<serde_json::Value>,
}

/// Why a scene cannot be annotated.
#[derive(Debug, thiserror::Error)]
pub enum AnnotateError {
    /// The pack's GLB cannot be read.
    #[error("the pack's GLB: {0}")]
    Pack(#[from] GlbError),
    /// The pack and its index disagree.
    #[error("{0}")]
    Inconsistent(String),
    /// The edited GLB cannot be written.
    #[error("writing the edited GLB: {0}")]
    Write(#[from] GlbWriteError),
}

/// A node of the edited scene: a mesh of the pack and a transform.
struct EditedNode {
    name: String,
    /// The pack node whose mesh it draws.
    pack_node: String,
    translation: [f64; 3],
    rotation: [f64; 4],
    scale: [f64; 3],
    /// Blender's Shift+D copies the mesh data: the copy gets its own mesh.
    own_mesh: bool,
}

fn trs_of(root: &gltf_json::Root, name: &str) -> Option<([f64; 3], [f64; 4], [f64; 3])> {
    let node = root
        .nodes
        .iter()
        .find(|n| n.name.as_deref() == Some(name))?;
    Some((
        node.translation.unwrap_or([0.0; 3]).map(f64::from),
        node.rotation
            .map_or([0.0, 0.0, 0.0, 1.0], |q| q.0.map(f64::from)),
        node.scale.unwrap_or([1.0; 3]).map(f64::from),
    ))
}

/// The node transform placing a pack mesh of `mesh_size_m` (object frame) as `object`.
fn placement(object: &LayoutObject, mesh_size_m: [f64; 3]) -> ([f64; 3], [f64; 4], [f64; 3]) {
    let size_m = object.size_cm.0.map(|v| v / 100.0);
    (
        gltf_from_table_point(object.position_cm.0.map(|v| v / 100.0)),
        gltf_from_table_quat(quat_normalize(object.rotation.0)),
        gltf_from_object_axes([0, 1, 2].map(|i| size_m[i] / mesh_size_m[i])),
    )
}

/// Plays the annotator on one scene.
pub fn annotate_scene(request: &AnnotateRequest<'_>) -> Result<Annotation, AnnotateError> {
    let index = request.index;
    let baseline = request.baseline;
    let truth = request.truth;
    let pack = open_glb(request.pack_glb)?;
    let root = pack.root();
    let mut annotation = Annotation::default();

    // Which true object each pack object shows (through its mask id).
    let truth_of_mask: BTreeMap<u32, &str> = request
        .truth_instances
        .instances
        .iter()
        .filter_map(|i| Some((i.id, i.instance.as_deref()?)))
        .collect();
    let truth_by_name: BTreeMap<&str, &LayoutObject> = truth
        .objects
        .iter()
        .map(|o| (o.instance.as_str(), o))
        .collect();
    let mut shown: BTreeMap<&str, Vec<&LayoutObject>> = BTreeMap::new();
    for object in &baseline.objects {
        let true_instance = object
            .provenance
            .as_ref()
            .and_then(|p| p.source_instance)
            .and_then(|id| truth_of_mask.get(&id).copied())
            .filter(|t| truth_by_name.contains_key(t));
        match true_instance {
            Some(t) => shown.entry(t).or_default().push(object),
            None => annotation.deleted.push(object.instance.clone()),
        }
    }
    // One pack object per true object: the one of the true asset, else the first by name.
    let mut kept: BTreeMap<&str, &LayoutObject> = BTreeMap::new();
    for (t, mut objects) in shown {
        let true_uid = &truth_by_name[t].retrieved_uid;
        objects.sort_by_key(|o| (o.retrieved_uid != *true_uid, o.instance.clone()));
        kept.insert(t, objects[0]);
        for copy in &objects[1..] {
            annotation.deleted.push(copy.instance.clone());
        }
    }

    // Some scenes: delete one of two objects of the same asset and make it again from its
    // twin (Shift+D), as a person who found it easier than fixing it does.
    let mut rng = crate::seeding::rng_for(request.seed, &["annotate", request.scene_id]);
    let mut remake: Option<(&str, &str)> = None;
    if rng.random_bool(0.5) {
        let mut twins: Vec<(&str, &str)> = Vec::new();
        for (t1, o1) in &kept {
            for (t2, o2) in &kept {
                if t1 < t2 && o1.retrieved_uid == o2.retrieved_uid {
                    twins.push((t1, t2));
                }
            }
        }
        if !twins.is_empty() {
            let (source, target) = twins[rng.random_range(0..twins.len())];
            remake = Some((source, target));
        }
    }
    if let Some((_, target)) = remake {
        if let Some(object) = kept.remove(target) {
            annotation.deleted.push(object.instance.clone());
        }
    }

    let mesh_size = |instance: &str| -> Result<[f64; 3], AnnotateError> {
        let uid = &index
            .objects
            .get(instance)
            .ok_or_else(|| {
                AnnotateError::Inconsistent(format!("{instance}: not in the pack's index.json"))
            })?
            .uid;
        index.assets.get(uid).map(|a| a.size_m).ok_or_else(|| {
            AnnotateError::Inconsistent(format!("asset {uid}: not in the pack's index.json"))
        })
    };

    // The edited nodes: the table, the objects kept, the copies, the figure.
    let mut nodes: Vec<EditedNode> = Vec::new();
    let zone = truth.zone_cm.0.map(|v| v / 100.0);
    let pack_zone = index.zone_cm.0.map(|v| v / 100.0);
    let thickness = index.table.thickness_cm / 100.0;
    nodes.push(EditedNode {
        name: TABLE_NODE.to_owned(),
        pack_node: TABLE_NODE.to_owned(),
        translation: gltf_from_table_point([
            (zone[0] + zone[1]) / 2.0,
            (zone[2] + zone[3]) / 2.0,
            -thickness / 2.0,
        ]),
        rotation: [0.0, 0.0, 0.0, 1.0],
        scale: gltf_from_object_axes([
            (zone[1] - zone[0]) / (pack_zone[1] - pack_zone[0]),
            (zone[3] - zone[2]) / (pack_zone[3] - pack_zone[2]),
            1.0,
        ]),
        own_mesh: false,
    });
    let mut names: BTreeSet<String> = root.nodes.iter().filter_map(|n| n.name.clone()).collect();
    for (t, object) in &kept {
        let (translation, rotation, scale) =
            placement(truth_by_name[t], mesh_size(&object.instance)?);
        nodes.push(EditedNode {
            name: object.instance.clone(),
            pack_node: object.instance.clone(),
            translation,
            rotation,
            scale,
            own_mesh: false,
        });
    }
    // True objects without a pack object: copies of an object of the same asset.
    let made: BTreeSet<&str> = kept.keys().copied().collect();
    for object in &truth.objects {
        if made.contains(object.instance.as_str()) {
            continue;
        }
        let source = remake
            .filter(|(_, target)| *target == object.instance)
            .and_then(|(source, _)| kept.get(source))
            .or_else(|| {
                kept.values()
                    .find(|o| o.retrieved_uid == object.retrieved_uid)
            });
        let Some(source) = source else {
            annotation.missing.push(object.instance.clone());
            continue;
        };
        let name = blender_copy_name(&source.instance, &names);
        names.insert(name.clone());
        let (translation, rotation, scale) = placement(object, mesh_size(&source.instance)?);
        annotation
            .duplicated
            .push((name.clone(), source.instance.clone()));
        nodes.push(EditedNode {
            name,
            pack_node: source.instance.clone(),
            translation,
            rotation,
            scale,
            own_mesh: true,
        });
    }
    if let Some((t, r, s)) = trs_of(root, H1_NODE) {
        nodes.push(EditedNode {
            name: H1_NODE.to_owned(),
            pack_node: H1_NODE.to_owned(),
            translation: t,
            rotation: r,
            scale: s,
            own_mesh: false,
        });
    }
    // A restricted zone the truth has: the pack's own, resized, else a box the person adds.
    let mut added_zone = None;
    if let Some(zone) = &truth.restricted_zone_cm {
        let [x0, x1, y0, y1] = zone.0.map(|v| v / 100.0);
        let centre = gltf_from_table_point([(x0 + x1) / 2.0, (y0 + y1) / 2.0, 0.0]);
        match (
            trs_of(root, RESTRICTED_ZONE_NODE),
            &index.restricted_zone_cm,
        ) {
            (Some(_), Some(before)) => {
                let [bx0, bx1, by0, by1] = before.0.map(|v| v / 100.0);
                nodes.push(EditedNode {
                    name: RESTRICTED_ZONE_NODE.to_owned(),
                    pack_node: RESTRICTED_ZONE_NODE.to_owned(),
                    translation: centre,
                    rotation: [0.0, 0.0, 0.0, 1.0],
                    scale: gltf_from_object_axes([
                        (x1 - x0) / (bx1 - bx0),
                        (y1 - y0) / (by1 - by0),
                        1.0,
                    ]),
                    own_mesh: false,
                });
            }
            _ => {
                annotation.restricted_zone_added = true;
                added_zone = Some((centre, [x1 - x0, RESTRICTED_ZONE_HEIGHT_M, y1 - y0]));
            }
        }
    }
    annotation.deleted.sort();
    annotation.blender_ops = blender_ops(&annotation.deleted, &nodes, added_zone);
    annotation.glb = export_like_blender(&pack, &nodes, added_zone)?;
    Ok(annotation)
}

/// The session as Blender operations (Blender's world is the table frame): deletions, then
/// each object set to its place (a copy duplicated from its source first), then the added box.
fn blender_ops(
    deleted: &[String],
    nodes: &[EditedNode],
    added_zone: Option<([f64; 3], [f64; 3])>,
) -> Vec<serde_json::Value> {
    let mut ops: Vec<serde_json::Value> = deleted
        .iter()
        .map(|name| serde_json::json!({"op": "delete", "name": name}))
        .collect();
    for node in nodes {
        if node.own_mesh {
            ops.push(
                serde_json::json!({"op": "duplicate", "name": node.pack_node, "as": node.name}),
            );
        }
        let q = table_from_gltf_quat(node.rotation);
        ops.push(serde_json::json!({
            "op": "set",
            "name": node.name,
            "location": table_from_gltf_point(node.translation),
            "rotation_wxyz": [q[3], q[0], q[1], q[2]],
            "scale": object_from_gltf_axes(node.scale),
        }));
    }
    if let Some((centre, size)) = added_zone {
        ops.push(serde_json::json!({
            "op": "add_box",
            "name": RESTRICTED_ZONE_NODE,
            "location": table_from_gltf_point(centre),
            "size": object_from_gltf_axes(size),
        }));
    }
    ops
}

/// The name Blender gives a copy of `source`: `<source>.001`, or the next free number.
pub fn blender_copy_name(source: &str, taken: &BTreeSet<String>) -> String {
    (1..)
        .map(|k| format!("{source}.{k:03}"))
        .find(|n| !taken.contains(n))
        .unwrap_or_else(|| format!("{source}.999"))
}

/// Writes the edited scene as Blender 4.3's exporter does with its defaults (checked against
/// it: `pipeline/tests/blender_roundtrip.rs`): one root node per object, in the order the
/// objects were made (the imported ones in the pack's order, then the copies, then added
/// objects), non-default TRS only, no extras, one mesh per mesh datablock (shared where the
/// import shared it; a copy made with Shift+D has its own, named `<mesh>.001`), the scene
/// named "Scene".
fn export_like_blender(
    pack: &GlbDocument<'_>,
    nodes: &[EditedNode],
    added_zone: Option<([f64; 3], [f64; 3])>,
) -> Result<Vec<u8>, AnnotateError> {
    let root = pack.root();
    let mut b = GlbBuilder::new(BLENDER_GENERATOR);
    let mut reader = MaterialReader::new(pack);
    // Mesh index of each pack node, read with its attributes.
    let mesh_of = |name: &str| -> Result<usize, AnnotateError> {
        root.nodes
            .iter()
            .find(|n| n.name.as_deref() == Some(name))
            .and_then(|n| n.mesh)
            .map(|m| m.value())
            .ok_or_else(|| AnnotateError::Inconsistent(format!("the pack has no mesh node {name}")))
    };
    let mut parts: HashMap<usize, Vec<(TriMesh, usize)>> = HashMap::new();
    let mut order: Vec<usize> = Vec::new();
    for node in nodes {
        let mesh = mesh_of(&node.pack_node)?;
        if parts.contains_key(&mesh) {
            continue;
        }
        let mut list = Vec::new();
        for primitive in pack.mesh_primitives(mesh, true)? {
            let (material, textured) = reader.material(primitive.material);
            list.push((to_trimesh(&primitive, textured), material));
        }
        parts.insert(mesh, list);
        order.push(mesh);
    }
    let mut zone_material = None;
    if added_zone.is_some() {
        zone_material = Some(
            reader.material(
                root.nodes
                    .iter()
                    .find(|n| n.name.as_deref() == Some(TABLE_NODE))
                    .and_then(|n| n.mesh)
                    .and_then(|m| root.meshes[m.value()].primitives.first())
                    .and_then(|p| p.material)
                    .map(|m| m.value()),
            ),
        );
    }
    let (materials, textures, images, _) = reader.finish();
    let mut image_cache = HashMap::new();
    let material_index =
        add_materials(&mut b, "", &materials, &textures, &images, &mut image_cache)?;
    let mut meshes: HashMap<usize, gltf_json::Index<gltf_json::Mesh>> = HashMap::new();
    let add = |b: &mut GlbBuilder, name: &str, list: &[(TriMesh, usize)]| {
        let primitives: Vec<_> = list.iter().map(|(m, k)| (m, material_index[*k])).collect();
        b.add_mesh(name, &primitives)
    };
    for mesh in &order {
        let name = root.meshes[*mesh].name.clone().unwrap_or_default();
        meshes.insert(*mesh, add(&mut b, &name, &parts[mesh])?);
    }
    // Creation order: imported objects as in the pack, then copies as made.
    let pack_order = |name: &str| {
        root.nodes
            .iter()
            .position(|n| n.name.as_deref() == Some(name))
            .unwrap_or(usize::MAX)
    };
    let mut ordered: Vec<&EditedNode> = nodes.iter().collect();
    ordered.sort_by_key(|n| {
        if n.own_mesh {
            (1, 0)
        } else {
            (0, pack_order(&n.name))
        }
    });
    let mut specs: Vec<NodeSpec> = Vec::new();
    let mut copies = BTreeMap::new();
    for node in ordered {
        let mesh = mesh_of(&node.pack_node)?;
        let index = if node.own_mesh {
            let name = root.meshes[mesh].name.clone().unwrap_or_default();
            let count = copies.entry(mesh).or_insert(0u32);
            *count += 1;
            add(&mut b, &format!("{name}.{:03}", *count), &parts[&mesh])?
        } else {
            meshes[&mesh]
        };
        specs.push(
            NodeSpec::new(node.name.clone())
                .with_mesh(index)
                .with_translation(node.translation)
                .with_rotation_xyzw(node.rotation)
                .with_scale(node.scale),
        );
    }
    if let Some((translation, size)) = added_zone {
        // Add > Mesh > Cube, scaled flat in Edit Mode, renamed; the table's material.
        let (k, _) = zone_material.unwrap_or((0, false));
        let material = if materials.is_empty() {
            b.add_material(&MaterialSpec::plain("Material", [0.8, 0.8, 0.8], 0.5))
        } else {
            material_index[k]
        };
        let mesh = b.add_mesh("Cube", &[(&TriMesh::cuboid(size), material)])?;
        specs.push(
            NodeSpec::new(RESTRICTED_ZONE_NODE)
                .with_mesh(mesh)
                .with_translation(translation),
        );
    }
    let mut roots = Vec::new();
    for spec in specs {
        roots.push(b.add_node(spec)?);
    }
    b.set_scene("Scene", roots);
    Ok(b.finish()?)
}

fn to_trimesh(primitive: &crate::glb_read::LocalPrimitive, textured: bool) -> TriMesh {
    let f = |p: &[f64; 3]| [p[0] as f32, p[1] as f32, p[2] as f32];
    let normals = match &primitive.normals {
        Some(n) => n.iter().map(|v| f(&normalize3(*v))).collect(),
        None => vec![[0.0, 1.0, 0.0]; primitive.positions.len()],
    };
    TriMesh {
        positions: primitive.positions.iter().map(f).collect(),
        normals,
        uvs: match (&primitive.uvs, textured) {
            (Some(uvs), true) => uvs.iter().map(|c| [c[0] as f32, c[1] as f32]).collect(),
            _ => Vec::new(),
        },
        triangles: primitive.triangles.clone(),
    }
}
