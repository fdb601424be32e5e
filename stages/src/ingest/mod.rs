//! `ingest`: the annotator's edited scene GLB read back into the refined layout (SPEC 5.5).
//!
//! The GLB is read as Blender exports it: one node per object named after it (Blender adds
//! `.001`, `.002`, ... to the copies of a duplicated object), TRS on the nodes, vertices in
//! local space, extras only when custom properties were exported, maybe shared meshes,
//! non-uniform scale, Draco compression, parents.
//!
//! - **Names.** A node's instance is its exact name with a trailing `.NNN` removed, never a
//!   prefix (`pen_1` is not `pen_10`). Among the nodes of one instance, the one with the
//!   exact name (else the lowest suffix) is the object itself; the others are duplicates and
//!   become new instances of the same asset with the next free index of their category
//!   (`mug_0.001` → `mug_2` when `mug_0` and `mug_1` exist). Objects without a node were
//!   deleted. A node that is none of the pack's is an error unless allowed; two nodes with
//!   the same exact name, a name with a path separator, a duplicated table, figure or
//!   restricted zone are errors.
//! - **The table frame moves with the table.** The table node's top proximal-left corner
//!   is the origin and its axes the frame's: an object is read relative to the table, and a
//!   resized table top is the new placement zone.
//! - **Per object**, in that frame: position = the world centre of the mesh's local bounding
//!   box; rotation = the node's world rotation; size = local box extents × the node's world
//!   scale, per axis (non-uniform allowed); scale factor = size / the asset's size in the
//!   pack. A rotation whose up axis leaves +z by more than the threshold is reported as a
//!   tilt (it is kept, and has no `z_rotation`). The mesh is compared with the pack's: a
//!   mesh whose scale or location was applied (Ctrl+A) is still read exactly; one whose
//!   vertices were edited, or whose rotation was applied, is reported.
//! - **The H1 check.** The figure is 1.70 m tall in the pack; at another height the whole
//!   scene is rescaled by 1.70 m / height about the table origin (the annotator scaled the
//!   scene, figure included), and the diff says so.
//! - **Exactness.** A value that differs from the baseline by less than float noise (10 µm,
//!   0.001°) is the baseline's own value, and an object with no change keeps its baseline
//!   entry as it is: a pack ingested without edits gives back the baseline layout byte for
//!   byte.

pub mod geometry;
pub mod images;
#[cfg(test)]
mod tests;

use std::collections::{BTreeMap, BTreeSet, HashMap};

use mesa_schemas::annotation::{
    FigureCheck, IngestDiffArtifact, ObjectChange, PackIndexArtifact, TableChange, ZoneChange,
    INGEST_DIFF_SCHEMA,
};
use mesa_schemas::convert::category_of_instance;
use mesa_schemas::layout::{DatasetLayout, LayoutObject, Provenance};
use mesa_schemas::rotation::{normalize_deg, tilt_deg_from_quat_xyzw, yaw_deg_from_quat_xyzw};
use mesa_schemas::units::{PositionCm, QuatXyzw, ScaleFactor, SizeCm, ZoneCm};
use nalgebra::{Matrix3, Matrix4, Point3, Rotation3, UnitQuaternion, Vector3};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use self::geometry::{compare_meshes, MeshComparison};
use crate::glb_read::{open_glb, GlbDocument, GlbError};
use crate::gltf_frames::{object_from_gltf_axes, table_from_gltf_point, table_from_gltf_quat};
use crate::pack::{safe_instance_name, H1_NODE, RESTRICTED_ZONE_NODE, TABLE_NODE};

/// Float noise of a position or size, cm: a smaller difference is no edit.
pub const UNCHANGED_CM: f64 = 1e-3;
/// Float noise of a rotation, degrees: a smaller turn is no edit.
pub const UNCHANGED_DEG: f64 = 1e-3;

/// The `[ingest]` section of `mesa.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct IngestConfig {
    /// Ignore nodes that are none of the pack's (an annotator's added camera, empty or
    /// helper object) instead of failing the scene; they are listed in `diff.json`.
    pub allow_unknown_nodes: bool,
    /// An object whose up axis leaves +z by more than this many degrees (roll or pitch) is
    /// reported as tilted.
    pub tilt_threshold_deg: f64,
    /// The H1 figure may differ from 170 cm by this many cm before the scene is rescaled.
    pub h1_tolerance_cm: f64,
    /// An object whose longest side is more than this many times the table top's longest
    /// side is an error, not a warning (a scale typed wrong, a unit mix-up: a node scale of
    /// 1e30 would make a mug wider than a city).
    pub max_size_over_table: f64,
    /// An object whose longest side is shorter than this many cm is an error (a scale near
    /// zero).
    pub min_object_side_cm: f64,
    /// An object whose centre lies farther than this many cm from the table top (outside its
    /// edges, above or below it) is an error: it left the table.
    pub max_distance_from_table_cm: f64,
    /// A table top whose longest side is longer than this many cm is an error (the table
    /// node scaled by mistake).
    pub max_table_side_cm: f64,
}

impl Default for IngestConfig {
    fn default() -> Self {
        Self {
            allow_unknown_nodes: false,
            tilt_threshold_deg: 5.0,
            h1_tolerance_cm: 0.1,
            max_size_over_table: 2.0,
            min_object_side_cm: 0.1,
            max_distance_from_table_cm: 200.0,
            max_table_side_cm: 1000.0,
        }
    }
}

impl IngestConfig {
    /// Values that parse but cannot work.
    pub fn problems(&self) -> Vec<String> {
        let mut out = Vec::new();
        if !(self.tilt_threshold_deg >= 0.0 && self.tilt_threshold_deg.is_finite()) {
            out.push(format!(
                "[ingest] tilt_threshold_deg = {}: expected degrees >= 0",
                self.tilt_threshold_deg
            ));
        }
        if !(self.h1_tolerance_cm >= 0.0 && self.h1_tolerance_cm.is_finite()) {
            out.push(format!(
                "[ingest] h1_tolerance_cm = {}: expected cm >= 0",
                self.h1_tolerance_cm
            ));
        }
        for (key, value) in [
            ("max_size_over_table", self.max_size_over_table),
            ("min_object_side_cm", self.min_object_side_cm),
            (
                "max_distance_from_table_cm",
                self.max_distance_from_table_cm,
            ),
            ("max_table_side_cm", self.max_table_side_cm),
        ] {
            if !(value > 0.0 && value.is_finite()) {
                out.push(format!(
                    "[ingest] {key} = {value}: expected a finite number > 0"
                ));
            }
        }
        if self.min_object_side_cm >= self.max_table_side_cm * self.max_size_over_table {
            out.push(format!(
                "[ingest] min_object_side_cm = {}: expected less than max_table_side_cm × \
                 max_size_over_table ({})",
                self.min_object_side_cm,
                self.max_table_side_cm * self.max_size_over_table
            ));
        }
        out
    }
}

/// What a scene's ingest reads.
#[derive(Debug, Clone, Copy)]
pub struct IngestRequest<'a> {
    /// The scene id.
    pub scene_id: &'a str,
    /// The edited GLB (`refined/<scene_id>.glb`).
    pub refined_glb: &'a [u8],
    /// Its path relative to the scene folder (for the diff).
    pub refined_rel: &'a str,
    /// The pack's GLB (`pack/<scene_id>.glb`): the meshes as sent.
    pub pack_glb: &'a [u8],
    /// The pack's `index.json`.
    pub index: &'a PackIndexArtifact,
    /// The layout the pack was made from.
    pub baseline: &'a DatasetLayout,
}

/// What ingesting a scene gives.
#[derive(Debug, Clone, PartialEq)]
pub struct IngestOutput {
    /// `refined/layout.json`.
    pub layout: DatasetLayout,
    /// `refined/diff.json`.
    pub diff: IngestDiffArtifact,
}

/// Why an edited scene cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum IngestError {
    /// The edited GLB is not a readable glTF.
    #[error("{0}")]
    Glb(#[from] GlbError),
    /// The pack's own GLB cannot be read (re-run `mesa pack`).
    #[error("the pack's GLB: {0} (re-run `mesa pack --force`)")]
    PackGlb(GlbError),
    /// An embedded image is unusable.
    #[error("{path}: {problem}")]
    Image {
        /// Like `images[0]`.
        path: String,
        /// What is wrong.
        problem: String,
    },
    /// A node name that cannot be an instance.
    #[error("nodes[{node}] \"{name}\": the name {problem} (expected an object name of the pack, like mug_0 or mug_0.001)")]
    BadName {
        /// Node index.
        node: usize,
        /// Its name.
        name: String,
        /// What is wrong.
        problem: String,
    },
    /// Two nodes with the same exact name.
    #[error("nodes[{first}] and nodes[{second}] are both named \"{name}\": two nodes claim the same instance (expected unique names, as Blender writes them)")]
    SameName {
        /// The name.
        name: String,
        /// First node.
        first: usize,
        /// Second node.
        second: usize,
    },
    /// Nodes that are none of the pack's.
    #[error("nodes that are not in the pack: {names} (rename them back to their pack name, delete them, or set [ingest] allow_unknown_nodes = true / pass --allow-unknown-nodes to ignore them){hint}")]
    UnknownNodes {
        /// Their names, comma-separated.
        names: String,
        /// A hint when extras tell which object a renamed node was.
        hint: String,
    },
    /// The table, the figure or the zone was duplicated.
    #[error("\"{name}\" is there twice (nodes {nodes}): the {what} must not be duplicated (delete the copy)")]
    Duplicated {
        /// The node base name.
        name: String,
        /// What it is.
        what: &'static str,
        /// The node indices.
        nodes: String,
    },
    /// The table was deleted.
    #[error("the \"table\" node is missing: the table frame cannot be found (restore the table: re-import the pack's table, or undo its deletion)")]
    NoTable,
    /// A known node lacks a mesh, or its mesh has no vertex.
    #[error("node \"{name}\" has no mesh with vertices (expected the object's mesh as packed: do not replace it or delete its vertices)")]
    NoMesh {
        /// The node name.
        name: String,
    },
    /// A transform that a layout cannot hold.
    #[error("node \"{name}\": {problem}")]
    Transform {
        /// The node name.
        name: String,
        /// What is wrong and the fix.
        problem: String,
    },
    /// A transform that gives an absurd object or table (beyond the `[ingest]` plausible
    /// ranges).
    #[error("nodes[{node}] \"{name}\".{field}: {problem} (fix: {fix})")]
    Implausible {
        /// Node index.
        node: usize,
        /// The node name.
        name: String,
        /// The node's field that gives it (`scale`, `translation`).
        field: &'static str,
        /// What is absurd, with the range it leaves.
        problem: String,
        /// How to fix it.
        fix: String,
    },
    /// The pack and the baseline layout disagree.
    #[error("{0}")]
    Pack(String),
}

/// The table top an object must stay on and fit, as `[ingest]` bounds it.
struct Plausible<'a> {
    config: &'a IngestConfig,
    /// The table top (after any H1 rescale), cm.
    zone: ZoneCm,
}

impl Plausible<'_> {
    fn table_side_cm(&self) -> f64 {
        self.zone.width_cm().max(self.zone.depth_cm())
    }

    /// How far a point (table frame, cm) is from the table top: from the zone's rectangle at
    /// z = 0.
    fn distance_cm(&self, p: [f64; 3]) -> f64 {
        let [x0, x1, y0, y1] = self.zone.0;
        let dx = (x0 - p[0]).max(p[0] - x1).max(0.0);
        let dy = (y0 - p[1]).max(p[1] - y1).max(0.0);
        (dx * dx + dy * dy + p[2] * p[2]).sqrt()
    }

    /// An error when an object read from `node` is absurd: not finite, larger than the table
    /// by more than the factor, near zero, or far from the table top. Only what the edit made
    /// absurd counts: an object beyond a bound that its baseline entry (`before`) was already
    /// beyond, and that the edit did not take further out, is left as the layout had it.
    fn check(
        &self,
        node: usize,
        name: &str,
        read: &ReadObject,
        before: &LayoutObject,
    ) -> Result<(), IngestError> {
        let config = self.config;
        let implausible =
            |field: &'static str, problem: String, fix: String| IngestError::Implausible {
                node,
                name: name.to_owned(),
                field,
                problem,
                fix,
            };
        let values = read
            .position_cm
            .iter()
            .chain(&read.size_cm)
            .chain(&read.rotation);
        if values.clone().any(|v| !v.is_finite()) {
            return Err(implausible(
                "translation",
                format!(
                    "the object's position {:?} cm or size {:?} cm is not finite",
                    read.position_cm, read.size_cm
                ),
                "give the node a finite translation, rotation and scale".to_owned(),
            ));
        }
        let longest = read.size_cm.iter().copied().fold(0.0, f64::max);
        let longest_before = before.size_cm.0.iter().copied().fold(0.0, f64::max);
        let table = self.table_side_cm();
        let limit = config.max_size_over_table * table;
        if longest > limit && longest > longest_before + UNCHANGED_CM {
            return Err(implausible(
                "scale",
                format!(
                    "the object is {} cm ({:.4e} × {:.4e} × {:.4e} cm), {} times the table \
                     top's longest side ({table:.1} cm) (expected at most {} times: [ingest] \
                     max_size_over_table)",
                    fmt_big(longest),
                    read.size_cm[0],
                    read.size_cm[1],
                    read.size_cm[2],
                    fmt_big(longest / table),
                    config.max_size_over_table
                ),
                format!(
                    "scale the object back to its size in Blender (S), or clear a wrong scale \
                     (Alt+S); raise [ingest] max_size_over_table if an object larger than {} × \
                     the table is meant",
                    config.max_size_over_table
                ),
            ));
        }
        if longest < config.min_object_side_cm && longest < longest_before - UNCHANGED_CM {
            return Err(implausible(
                "scale",
                format!(
                    "the object's longest side is {} cm (expected at least {} cm: [ingest] \
                     min_object_side_cm)",
                    fmt_big(longest),
                    config.min_object_side_cm
                ),
                "scale the object back up to its size in Blender (S), or clear a wrong scale \
                 (Alt+S)"
                    .to_owned(),
            ));
        }
        let [x0, x1, y0, y1] = self.zone.0;
        let p = read.position_cm;
        let distance = self.distance_cm(p);
        if distance > config.max_distance_from_table_cm
            && distance > self.distance_cm(before.position_cm.0) + UNCHANGED_CM
        {
            return Err(implausible(
                "translation",
                format!(
                    "the object's centre is at ({}, {}, {}) cm in the table frame, {} cm from \
                     the table top (x {x0:.1}..{x1:.1}, y {y0:.1}..{y1:.1}, z 0) (expected at \
                     most {} cm: [ingest] max_distance_from_table_cm)",
                    fmt_big(p[0]),
                    fmt_big(p[1]),
                    fmt_big(p[2]),
                    fmt_big(distance),
                    config.max_distance_from_table_cm
                ),
                "move the object back onto the table (or clear a wrong location with Alt+G), \
                 or delete it"
                    .to_owned(),
            ));
        }
        Ok(())
    }
}

/// A length in cm or a ratio, in plain notation when it is of a table's order, else in
/// scientific notation (`1.2e31`).
fn fmt_big(v: f64) -> String {
    if v.abs() < 1e6 {
        format!("{v:.1}")
    } else {
        format!("{v:.3e}")
    }
}

/// A node's mesh box and transform, read once.
struct NodeGeometry {
    /// Local bounding box of the mesh, glTF axes.
    local_min: [f64; 3],
    local_max: [f64; 3],
    /// World matrix, glTF scene frame.
    world: Matrix4<f64>,
}

/// A rigid frame: the table frame in the glTF world.
struct TableFrame {
    /// World position of the frame origin (glTF).
    origin: Vector3<f64>,
    /// World rotation of the table (glTF).
    rotation: UnitQuaternion<f64>,
    /// Added to every converted point: the baseline zone's minimum corner (0 in a valid
    /// layout), metres, table frame.
    offset: [f64; 3],
    /// The H1 rescale factor.
    scale: f64,
}

impl TableFrame {
    /// A world point in the table frame, metres.
    fn point(&self, world: Vector3<f64>) -> [f64; 3] {
        let local = self.rotation.inverse() * (world - self.origin);
        let t = table_from_gltf_point([local.x, local.y, local.z]);
        [0, 1, 2].map(|i| (t[i] + self.offset[i]) * self.scale)
    }

    /// A world rotation in the table frame, xyzw, `w >= 0`.
    fn rotation(&self, world: UnitQuaternion<f64>) -> [f64; 4] {
        let relative = self.rotation.inverse() * world;
        let q = relative.quaternion();
        let t = table_from_gltf_quat([q.i, q.j, q.k, q.w]);
        let sign = if t[3] < 0.0 { -1.0 } else { 1.0 };
        t.map(|c| c * sign)
    }
}

/// A world matrix split into translation, rotation and per-axis scale (glTF local axes).
struct Decomposed {
    rotation: UnitQuaternion<f64>,
    scale: [f64; 3],
}

fn decompose(name: &str, m: &Matrix4<f64>) -> Result<Decomposed, IngestError> {
    let linear: Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).into_owned();
    let scale = [0, 1, 2].map(|i| linear.column(i).norm());
    if scale.iter().any(|s| !(*s > 1e-12 && s.is_finite())) {
        return Err(IngestError::Transform {
            name: name.to_owned(),
            problem: format!(
                "its world scale is {scale:?}: zero or not finite (give it a positive scale)"
            ),
        });
    }
    let r = Matrix3::from_columns(&[0, 1, 2].map(|i| linear.column(i) / scale[i]));
    let orthogonality = (r.transpose() * r - Matrix3::identity()).abs().max();
    if orthogonality > 1e-4 {
        return Err(IngestError::Transform {
            name: name.to_owned(),
            problem: "its world transform is sheared (a parent scaled along other axes than \
                      the object's): clear its parent with Alt+P > Clear and Keep Transformation, \
                      then apply the parent's scale"
                .to_owned(),
        });
    }
    if r.determinant() < 0.0 {
        return Err(IngestError::Transform {
            name: name.to_owned(),
            problem: "it is mirrored (a negative scale): a layout cannot hold a mirrored \
                      object (undo the mirroring, or scale by a positive factor)"
                .to_owned(),
        });
    }
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    Ok(Decomposed { rotation, scale })
}

/// The instance part of a node name: the name without a trailing `.NNN` (Blender's suffix
/// for copies: a dot and three or more digits), and the suffix number.
pub fn split_blender_suffix(name: &str) -> (&str, Option<u32>) {
    if let Some((base, digits)) = name.rsplit_once('.') {
        if digits.len() >= 3 && digits.bytes().all(|b| b.is_ascii_digit()) && !base.is_empty() {
            if let Ok(n) = digits.parse() {
                return (base, Some(n));
            }
        }
    }
    (name, None)
}

fn angle_between_deg(a: [f64; 4], b: [f64; 4]) -> f64 {
    let dot: f64 = a.iter().zip(&b).map(|(x, y)| x * y).sum::<f64>().abs();
    let na = a.iter().map(|v| v * v).sum::<f64>().sqrt();
    let nb = b.iter().map(|v| v * v).sum::<f64>().sqrt();
    2.0 * (dot / (na * nb)).clamp(-1.0, 1.0).acos().to_degrees()
}

fn round6(v: f64) -> f64 {
    // `+ 0.0` turns -0.0 into 0.0.
    (v * 1e6).round() / 1e6 + 0.0
}

fn node_geometry(
    document: &GlbDocument<'_>,
    node: usize,
    name: &str,
    world: &Matrix4<f64>,
    cache: &mut HashMap<usize, ([f64; 3], [f64; 3])>,
) -> Result<NodeGeometry, IngestError> {
    let mesh = document.root().nodes[node]
        .mesh
        .map(|m| m.value())
        .ok_or_else(|| IngestError::NoMesh {
            name: name.to_owned(),
        })?;
    let (local_min, local_max) = match cache.get(&mesh) {
        Some(b) => *b,
        None => {
            let positions = document.mesh_positions(mesh)?;
            let b = geometry::bounds(&positions).ok_or_else(|| IngestError::NoMesh {
                name: name.to_owned(),
            })?;
            cache.insert(mesh, b);
            b
        }
    };
    Ok(NodeGeometry {
        local_min,
        local_max,
        world: *world,
    })
}

fn world_point(m: &Matrix4<f64>, p: [f64; 3]) -> Vector3<f64> {
    let v = m.transform_point(&Point3::new(p[0], p[1], p[2]));
    Vector3::new(v.x, v.y, v.z)
}

/// A measured zone with each bound within float noise of the baseline's replaced by it.
fn snap_zone(measured: ZoneCm, baseline: Option<&ZoneCm>) -> ZoneCm {
    match baseline {
        None => measured,
        Some(b) => ZoneCm([0, 1, 2, 3].map(|i| {
            if (measured.0[i] - b.0[i]).abs() < UNCHANGED_CM {
                b.0[i]
            } else {
                measured.0[i]
            }
        })),
    }
}

/// Reads an edited scene back.
pub fn ingest_scene(
    request: &IngestRequest<'_>,
    config: &IngestConfig,
) -> Result<IngestOutput, IngestError> {
    let index = request.index;
    let baseline = request.baseline;
    let document = open_glb(request.refined_glb)?;
    images::check_images(&document)?;
    let world = document.world_matrices()?;
    let root = document.root();
    let mut warnings: Vec<String> = Vec::new();

    // Names → roles.
    let mut by_name: BTreeMap<&str, usize> = BTreeMap::new();
    let mut unknown: Vec<(usize, String)> = Vec::new();
    let mut table_nodes = Vec::new();
    let mut zone_nodes = Vec::new();
    let mut figure_nodes = Vec::new();
    // Instance → [(suffix, node)].
    let mut object_nodes: BTreeMap<&str, Vec<(Option<u32>, usize)>> = BTreeMap::new();
    for (i, node) in root.nodes.iter().enumerate() {
        if world[i].is_none() {
            warnings.push(format!(
                "nodes[{i}] ({}) is not part of the scene and is ignored",
                node.name.as_deref().unwrap_or("unnamed")
            ));
            continue;
        }
        let Some(name) = node.name.as_deref() else {
            unknown.push((i, format!("nodes[{i}] (unnamed)")));
            continue;
        };
        safe_instance_name(name).map_err(|problem| IngestError::BadName {
            node: i,
            name: name.to_owned(),
            problem: problem.to_string(),
        })?;
        if let Some(first) = by_name.insert(name, i) {
            return Err(IngestError::SameName {
                name: name.to_owned(),
                first,
                second: i,
            });
        }
        let (base, suffix) = split_blender_suffix(name);
        let base_instance = index.objects.get_key_value(base).map(|(k, _)| k.as_str());
        match base {
            TABLE_NODE => table_nodes.push(i),
            RESTRICTED_ZONE_NODE => zone_nodes.push(i),
            H1_NODE => figure_nodes.push(i),
            _ => match base_instance {
                Some(instance) => object_nodes.entry(instance).or_default().push((suffix, i)),
                None => unknown.push((i, name.to_owned())),
            },
        }
    }
    for (nodes, name, what) in [
        (&table_nodes, TABLE_NODE, "table"),
        (&zone_nodes, RESTRICTED_ZONE_NODE, "restricted zone"),
        (&figure_nodes, H1_NODE, "H1 reference figure"),
    ] {
        if nodes.len() > 1 {
            return Err(IngestError::Duplicated {
                name: name.to_owned(),
                what,
                nodes: nodes
                    .iter()
                    .map(usize::to_string)
                    .collect::<Vec<_>>()
                    .join(", "),
            });
        }
    }
    let mut ignored_nodes = Vec::new();
    if !unknown.is_empty() {
        // Nodes that only hold known nodes (an empty parent) are still unknown: they are
        // reported, and their transform applies to their children either way.
        if config.allow_unknown_nodes {
            for (_, name) in &unknown {
                ignored_nodes.push(name.clone());
            }
            warnings.push(format!(
                "{} nodes that are not in the pack were ignored: {}",
                unknown.len(),
                ignored_nodes.join(", ")
            ));
        } else {
            let mut hints = Vec::new();
            for (i, name) in &unknown {
                let claimed = root.nodes[*i]
                    .extras
                    .as_ref()
                    .and_then(|raw| serde_json::from_str::<serde_json::Value>(raw.get()).ok())
                    .and_then(|v| {
                        v.pointer("/mesa/instance")
                            .and_then(|x| x.as_str())
                            .map(str::to_owned)
                    });
                if let Some(instance) = claimed {
                    hints.push(format!(
                        "\"{name}\" was {instance} (its custom properties say so)"
                    ));
                }
            }
            let hint = if hints.is_empty() {
                String::new()
            } else {
                format!("; renamed: {}", hints.join(", "))
            };
            return Err(IngestError::UnknownNodes {
                names: unknown
                    .iter()
                    .map(|(_, n)| n.as_str())
                    .collect::<Vec<_>>()
                    .join(", "),
                hint,
            });
        }
    }

    let mut mesh_boxes = HashMap::new();
    let geometry_of = |node: usize,
                       mesh_boxes: &mut HashMap<usize, ([f64; 3], [f64; 3])>|
     -> Result<NodeGeometry, IngestError> {
        let name = root.nodes[node].name.as_deref().unwrap_or("unnamed");
        let m = world[node].ok_or_else(|| IngestError::NoMesh {
            name: name.to_owned(),
        })?;
        node_geometry(&document, node, name, &m, mesh_boxes)
    };

    // The table frame.
    let table_node = *table_nodes.first().ok_or(IngestError::NoTable)?;
    let table = geometry_of(table_node, &mut mesh_boxes)?;
    let table_t = decompose(TABLE_NODE, &table.world)?;
    let width_m = (table.local_max[0] - table.local_min[0]) * table_t.scale[0];
    let depth_m = (table.local_max[2] - table.local_min[2]) * table_t.scale[2];
    let corner = world_point(
        &table.world,
        [table.local_min[0], table.local_max[1], table.local_max[2]],
    );
    let zone_min = [
        baseline.zone_cm.0[0] / 100.0,
        baseline.zone_cm.0[2] / 100.0,
        0.0,
    ];
    // Where the pack put that corner, and how the table moved from there.
    let pack_corner = Vector3::new(zone_min[0], 0.0, -zone_min[1]);
    let table_moved = table_from_gltf_point([
        corner.x - pack_corner.x,
        corner.y - pack_corner.y,
        corner.z - pack_corner.z,
    ]);
    let table_turn_deg = {
        let q = table_t.rotation.quaternion();
        angle_between_deg([q.i, q.j, q.k, q.w], [0.0, 0.0, 0.0, 1.0])
    };
    let table_tilt = tilt_deg_from_quat_xyzw(table_from_gltf_quat({
        let q = table_t.rotation.quaternion();
        [q.i, q.j, q.k, q.w]
    }));
    if table_tilt > config.tilt_threshold_deg {
        warnings.push(format!(
            "the table is tilted by {table_tilt:.1}°: objects are read relative to its top"
        ));
    }
    let unmoved = table_moved.iter().all(|v| v.abs() * 100.0 < UNCHANGED_CM)
        && table_turn_deg < UNCHANGED_DEG;

    // The H1 check.
    let mut h1 = FigureCheck {
        present: false,
        height_cm: None,
        rescaled_by: None,
    };
    let mut scale = 1.0;
    if let Some(&node) = figure_nodes.first() {
        let figure = geometry_of(node, &mut mesh_boxes)?;
        let t = decompose(H1_NODE, &figure.world)?;
        let height_m = (figure.local_max[1] - figure.local_min[1]) * t.scale[1];
        h1.present = true;
        h1.height_cm = Some(round6(height_m * 100.0));
        if (height_m * 100.0 - index.h1.height_cm).abs() > config.h1_tolerance_cm {
            scale = index.h1.height_cm / 100.0 / height_m;
            h1.rescaled_by = Some(scale);
            warnings.push(format!(
                "H1_reference is {:.2} cm tall instead of {:.0} cm: the whole scene was rescaled \
                 by {scale:.6} about the table origin",
                height_m * 100.0,
                index.h1.height_cm
            ));
        }
    } else {
        warnings
            .push("H1_reference was deleted: the scene's scale could not be checked".to_owned());
    }

    let frame = TableFrame {
        origin: if unmoved { pack_corner } else { corner },
        rotation: if unmoved {
            UnitQuaternion::identity()
        } else {
            table_t.rotation
        },
        offset: zone_min,
        scale,
    };
    let zone_after = {
        let measured = ZoneCm([
            baseline.zone_cm.0[0] * scale,
            (zone_min[0] + width_m) * 100.0 * scale,
            baseline.zone_cm.0[2] * scale,
            (zone_min[1] + depth_m) * 100.0 * scale,
        ]);
        snap_zone(measured, Some(&baseline.zone_cm))
    };
    let table_side_cm = zone_after.width_cm().max(zone_after.depth_cm());
    let table_side_before_cm = baseline.zone_cm.width_cm().max(baseline.zone_cm.depth_cm());
    if !table_side_cm.is_finite()
        || (table_side_cm > config.max_table_side_cm
            && table_side_cm > table_side_before_cm + UNCHANGED_CM)
    {
        return Err(IngestError::Implausible {
            node: table_node,
            name: TABLE_NODE.to_owned(),
            field: "scale",
            problem: format!(
                "the table top is {} × {} cm (expected a longest side of at most {} cm: \
                 [ingest] max_table_side_cm)",
                fmt_big(zone_after.width_cm()),
                fmt_big(zone_after.depth_cm()),
                config.max_table_side_cm
            ),
            fix: "scale the table back to its size in Blender (S), or clear a wrong scale \
                  (Alt+S); raise [ingest] max_table_side_cm if a larger table is meant"
                .to_owned(),
        });
    }
    let plausible = Plausible {
        config,
        zone: zone_after,
    };
    let resized = zone_after != baseline.zone_cm;
    if resized {
        warnings.push(format!(
            "the table top is now {:.1} × {:.1} cm (was {:.1} × {:.1} cm): the placement zone \
             follows it",
            zone_after.width_cm(),
            zone_after.depth_cm(),
            baseline.zone_cm.width_cm(),
            baseline.zone_cm.depth_cm()
        ));
    }
    if !unmoved {
        warnings.push(format!(
            "the table was moved by ({:.2}, {:.2}, {:.2}) cm and turned by {table_turn_deg:.2}°: \
             objects are read relative to the table",
            table_moved[0] * 100.0,
            table_moved[1] * 100.0,
            table_moved[2] * 100.0
        ));
    }

    // The restricted zone.
    let restricted_after = match zone_nodes.first() {
        Some(&node) => {
            let zone = geometry_of(node, &mut mesh_boxes)?;
            let mut xs = Vec::new();
            let mut ys = Vec::new();
            for corner in geometry::corners(zone.local_min, zone.local_max) {
                let p = frame.point(world_point(&zone.world, corner));
                xs.push(p[0]);
                ys.push(p[1]);
            }
            let min = |v: &[f64]| v.iter().copied().fold(f64::INFINITY, f64::min);
            let max = |v: &[f64]| v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let measured = ZoneCm([
                min(&xs) * 100.0,
                max(&xs) * 100.0,
                min(&ys) * 100.0,
                max(&ys) * 100.0,
            ]);
            Some(snap_zone(measured, baseline.restricted_zone_cm.as_ref()))
        }
        None => {
            if baseline.restricted_zone_cm.is_some() {
                warnings.push(
                    "the restricted_zone node was deleted: the layout has no restricted zone"
                        .to_owned(),
                );
            }
            None
        }
    };

    // The pack's meshes, to tell edited meshes.
    let pack = open_glb(request.pack_glb).map_err(IngestError::PackGlb)?;
    let pack_mesh_of: BTreeMap<&str, usize> = pack
        .root()
        .nodes
        .iter()
        .filter_map(|n| Some((n.name.as_deref()?, n.mesh?.value())))
        .collect();
    let mut pack_positions: HashMap<usize, Vec<[f64; 3]>> = HashMap::new();
    let mut refined_positions: HashMap<usize, Vec<[f64; 3]>> = HashMap::new();

    // Objects: originals first (in baseline order), then duplicates.
    let mut taken: BTreeSet<String> = baseline
        .objects
        .iter()
        .map(|o| o.instance.clone())
        .collect();
    let mut objects = Vec::new();
    let mut changes = Vec::new();
    let mut duplicates: Vec<(&str, Option<u32>, usize)> = Vec::new();
    let mut removed = Vec::new();
    let mut lists = DiffLists::default();
    for object in &baseline.objects {
        let Some(nodes) = object_nodes.get_mut(object.instance.as_str()) else {
            removed.push(object.instance.clone());
            changes.push(ObjectChange {
                instance: object.instance.clone(),
                status: "removed".to_owned(),
                ..empty_change()
            });
            continue;
        };
        nodes.sort();
        // The exact name (no suffix) sorts first; else the lowest suffix is the original.
        let (_, node) = nodes[0];
        for (suffix, other) in &nodes[1..] {
            duplicates.push((object.instance.as_str(), *suffix, *other));
        }
        let read = read_object(
            &document,
            node,
            &frame,
            index,
            &object.retrieved_uid,
            &mut mesh_boxes,
            &world,
        )?;
        plausible.check(
            node,
            root.nodes[node].name.as_deref().unwrap_or("unnamed"),
            &read,
            object,
        )?;
        let mesh_status = mesh_status(
            &document,
            node,
            &pack,
            pack_mesh_of.get(object.instance.as_str()).copied(),
            &mut pack_positions,
            &mut refined_positions,
        )?;
        let (entry, change) = compare_with_baseline(object, &read, config, &mut lists);
        let mut change = change;
        change.node = root.nodes[node].name.clone();
        if mesh_status != MeshComparison::Unchanged {
            change.mesh = Some(mesh_status.as_str().to_owned());
            lists.mesh_changed.push(object.instance.clone());
            if mesh_status == MeshComparison::Edited {
                warnings.push(format!(
                    "{}: its mesh was edited or had its rotation applied: its size is the box of \
                     the edited mesh in its own axes",
                    object.instance
                ));
            }
            if change.status == "unchanged" {
                change.status = "edited".to_owned();
            }
        }
        objects.push(entry);
        changes.push(change);
    }
    duplicates.sort();
    for (source, _suffix, node) in duplicates {
        let object = baseline
            .objects
            .iter()
            .find(|o| o.instance == source)
            .ok_or_else(|| IngestError::Pack(format!("{source}: not in the baseline layout")))?;
        let instance = next_instance(source, &taken);
        taken.insert(instance.clone());
        let read = read_object(
            &document,
            node,
            &frame,
            index,
            &object.retrieved_uid,
            &mut mesh_boxes,
            &world,
        )?;
        plausible.check(
            node,
            root.nodes[node].name.as_deref().unwrap_or("unnamed"),
            &read,
            object,
        )?;
        let mesh_status = mesh_status(
            &document,
            node,
            &pack,
            pack_mesh_of.get(source).copied(),
            &mut pack_positions,
            &mut refined_positions,
        )?;
        let node_name = root.nodes[node].name.clone().unwrap_or_default();
        let mut entry = new_object(object, &instance, &read, config);
        entry.provenance = Some(Provenance {
            stage: "ingest".to_owned(),
            source_instance: object.provenance.as_ref().and_then(|p| p.source_instance),
            notes: vec![format!(
                "duplicated by the annotator from {source} (node {node_name})"
            )],
        });
        let tilt = tilt_deg_from_quat_xyzw(read.rotation);
        if tilt > config.tilt_threshold_deg {
            lists.tilted.push(instance.clone());
        }
        lists.added.push(instance.clone());
        if mesh_status != MeshComparison::Unchanged {
            lists.mesh_changed.push(instance.clone());
        }
        changes.push(ObjectChange {
            instance: instance.clone(),
            status: "added".to_owned(),
            node: Some(node_name),
            duplicate_of: Some(source.to_owned()),
            tilt_deg: (tilt > config.tilt_threshold_deg).then_some(round6(tilt)),
            mesh: (mesh_status != MeshComparison::Unchanged)
                .then(|| mesh_status.as_str().to_owned()),
            ..empty_change()
        });
        objects.push(entry);
    }
    for instance in &lists.tilted {
        warnings.push(format!(
            "{instance}: tilted by more than {}° (its rotation is kept; it has no z_rotation)",
            config.tilt_threshold_deg
        ));
    }
    if !removed.is_empty() {
        warnings.push(format!("deleted by the annotator: {}", removed.join(", ")));
    }

    let mut layout = DatasetLayout {
        schema: baseline.schema.clone(),
        zone_cm: zone_after,
        restricted_zone_cm: restricted_after,
        objects,
        extra: baseline.extra.clone(),
    };
    layout.sort_objects();
    changes.sort_by(|a, b| a.instance.cmp(&b.instance));
    let diff = IngestDiffArtifact {
        schema: INGEST_DIFF_SCHEMA.to_owned(),
        scene_id: request.scene_id.to_owned(),
        source: request.refined_rel.to_owned(),
        generator: root.asset.generator.clone(),
        baseline: index.layout.clone(),
        moved: sorted(lists.moved),
        rotated: sorted(lists.rotated),
        scaled: sorted(lists.scaled),
        added: sorted(lists.added),
        removed: sorted(removed),
        tilted: sorted(lists.tilted),
        mesh_changed: sorted(lists.mesh_changed),
        objects: changes,
        table: TableChange {
            zone_before_cm: baseline.zone_cm,
            zone_after_cm: zone_after,
            resized,
            moved_cm: if unmoved {
                [0.0; 3]
            } else {
                table_moved.map(|v| round6(v * 100.0))
            },
            rotated_deg: if unmoved { 0.0 } else { round6(table_turn_deg) },
        },
        restricted_zone: (baseline.restricted_zone_cm.is_some() || restricted_after.is_some())
            .then_some(ZoneChange {
                before_cm: baseline.restricted_zone_cm,
                after_cm: restricted_after,
            }),
        h1,
        ignored_nodes,
        warnings,
    };
    Ok(IngestOutput { layout, diff })
}

fn sorted(mut v: Vec<String>) -> Vec<String> {
    v.sort();
    v.dedup();
    v
}

#[derive(Default)]
struct DiffLists {
    moved: Vec<String>,
    rotated: Vec<String>,
    scaled: Vec<String>,
    added: Vec<String>,
    tilted: Vec<String>,
    mesh_changed: Vec<String>,
}

fn empty_change() -> ObjectChange {
    ObjectChange {
        instance: String::new(),
        status: String::new(),
        node: None,
        duplicate_of: None,
        moved_cm: None,
        moved_distance_cm: None,
        rotated_deg: None,
        yaw_change_deg: None,
        size_ratio: None,
        tilt_deg: None,
        mesh: None,
    }
}

/// An object as read from its node, in the table frame.
struct ReadObject {
    position_cm: [f64; 3],
    rotation: [f64; 4],
    size_cm: [f64; 3],
    scale_factor: [f64; 3],
}

fn read_object(
    document: &GlbDocument<'_>,
    node: usize,
    frame: &TableFrame,
    index: &PackIndexArtifact,
    uid: &str,
    mesh_boxes: &mut HashMap<usize, ([f64; 3], [f64; 3])>,
    world: &[Option<Matrix4<f64>>],
) -> Result<ReadObject, IngestError> {
    let name = document.root().nodes[node]
        .name
        .as_deref()
        .unwrap_or("unnamed");
    let m = world[node].ok_or_else(|| IngestError::NoMesh {
        name: name.to_owned(),
    })?;
    let g = node_geometry(document, node, name, &m, mesh_boxes)?;
    let t = decompose(name, &g.world)?;
    let centre_local = [0, 1, 2].map(|i| (g.local_min[i] + g.local_max[i]) / 2.0);
    let position = frame.point(world_point(&g.world, centre_local));
    let rotation = frame.rotation(t.rotation);
    let extents = [0, 1, 2].map(|i| (g.local_max[i] - g.local_min[i]) * t.scale[i]);
    let size_m = object_from_gltf_axes(extents).map(|v| v * frame.scale);
    let asset = index.assets.get(uid).ok_or_else(|| {
        IngestError::Pack(format!(
            "{name}: its asset {uid} is not in the pack's index.json (re-run `mesa pack`)"
        ))
    })?;
    if size_m.iter().any(|v| *v <= 0.0) {
        return Err(IngestError::Transform {
            name: name.to_owned(),
            problem: format!(
                "its size is {:?} cm: flat along an axis (scale it back up)",
                size_m.map(|v| v * 100.0)
            ),
        });
    }
    Ok(ReadObject {
        position_cm: position.map(|v| v * 100.0),
        rotation,
        size_cm: size_m.map(|v| v * 100.0),
        scale_factor: [0, 1, 2].map(|i| size_m[i] / asset.size_m[i]),
    })
}

fn mesh_status(
    document: &GlbDocument<'_>,
    node: usize,
    pack: &GlbDocument<'_>,
    pack_mesh: Option<usize>,
    cache: &mut HashMap<usize, Vec<[f64; 3]>>,
    refined_cache: &mut HashMap<usize, Vec<[f64; 3]>>,
) -> Result<MeshComparison, IngestError> {
    let Some(pack_mesh) = pack_mesh else {
        return Ok(MeshComparison::Unchanged);
    };
    let Some(mesh) = document.root().nodes[node].mesh.map(|m| m.value()) else {
        return Ok(MeshComparison::Unchanged);
    };
    let pack_positions = match cache.entry(pack_mesh) {
        std::collections::hash_map::Entry::Occupied(e) => e.into_mut(),
        std::collections::hash_map::Entry::Vacant(e) => e.insert(
            pack.mesh_positions(pack_mesh)
                .map_err(IngestError::PackGlb)?,
        ),
    };
    let positions = match refined_cache.entry(mesh) {
        std::collections::hash_map::Entry::Occupied(e) => e.into_mut(),
        std::collections::hash_map::Entry::Vacant(e) => e.insert(document.mesh_positions(mesh)?),
    };
    Ok(compare_meshes(pack_positions, positions))
}

fn yaw_or_none(rotation: [f64; 4], config: &IngestConfig) -> Option<f64> {
    (tilt_deg_from_quat_xyzw(rotation) <= config.tilt_threshold_deg)
        .then(|| yaw_deg_from_quat_xyzw(rotation))
}

fn new_object(
    template: &LayoutObject,
    instance: &str,
    read: &ReadObject,
    config: &IngestConfig,
) -> LayoutObject {
    LayoutObject {
        instance: instance.to_owned(),
        retrieved_uid: template.retrieved_uid.clone(),
        position_cm: PositionCm(read.position_cm),
        rotation: QuatXyzw(read.rotation),
        size_cm: SizeCm(read.size_cm),
        scale_factor: ScaleFactor(read.scale_factor),
        category: template.category.clone(),
        description: template.description.clone(),
        z_rotation_deg: yaw_or_none(read.rotation, config),
        provenance: None,
        extra: template.extra.clone(),
    }
}

/// The refined entry of a baseline object and its change record: values within float noise
/// of the baseline are the baseline's; an object without any change is the baseline entry.
fn compare_with_baseline(
    before: &LayoutObject,
    read: &ReadObject,
    config: &IngestConfig,
    lists: &mut DiffLists,
) -> (LayoutObject, ObjectChange) {
    let instance = &before.instance;
    let delta = [0, 1, 2].map(|i| read.position_cm[i] - before.position_cm.0[i]);
    let moved = delta.iter().any(|d| d.abs() >= UNCHANGED_CM);
    let turn = angle_between_deg(read.rotation, before.rotation.0);
    let rotated = turn >= UNCHANGED_DEG;
    let resized = (0..3).any(|i| (read.size_cm[i] - before.size_cm.0[i]).abs() >= UNCHANGED_CM);
    let tilt = tilt_deg_from_quat_xyzw(read.rotation);
    let tilted = rotated && tilt > config.tilt_threshold_deg;
    let mut change = ObjectChange {
        instance: instance.clone(),
        status: "unchanged".to_owned(),
        ..empty_change()
    };
    if !(moved || rotated || resized) {
        return (before.clone(), change);
    }
    change.status = "edited".to_owned();
    let mut after = before.clone();
    let mut notes = Vec::new();
    // Coordinates within float noise of the baseline's are the baseline's.
    let keep = |read: f64, before: f64| {
        if (read - before).abs() < UNCHANGED_CM {
            before
        } else {
            read
        }
    };
    if moved {
        after.position_cm =
            PositionCm([0, 1, 2].map(|i| keep(read.position_cm[i], before.position_cm.0[i])));
        let distance = delta.iter().map(|d| d * d).sum::<f64>().sqrt();
        change.moved_cm = Some(delta.map(round6));
        change.moved_distance_cm = Some(round6(distance));
        notes.push(format!("moved {distance:.2} cm"));
        lists.moved.push(instance.clone());
    }
    if rotated {
        after.rotation = QuatXyzw(read.rotation);
        after.z_rotation_deg = yaw_or_none(read.rotation, config);
        let yaw_change = normalize_deg(
            yaw_deg_from_quat_xyzw(read.rotation) - yaw_deg_from_quat_xyzw(before.rotation.0),
        );
        change.rotated_deg = Some(round6(turn));
        change.yaw_change_deg = Some(round6(yaw_change));
        notes.push(format!("turned {turn:.2}°"));
        lists.rotated.push(instance.clone());
        if tilted {
            change.tilt_deg = Some(round6(tilt));
            lists.tilted.push(instance.clone());
        }
    }
    if resized {
        after.size_cm = SizeCm([0, 1, 2].map(|i| keep(read.size_cm[i], before.size_cm.0[i])));
        after.scale_factor = ScaleFactor([0, 1, 2].map(|i| {
            if after.size_cm.0[i] == before.size_cm.0[i] {
                before.scale_factor.0[i]
            } else {
                read.scale_factor[i]
            }
        }));
        let ratio = [0, 1, 2].map(|i| round6(read.size_cm[i] / before.size_cm.0[i]));
        change.size_ratio = Some(ratio);
        notes.push(format!(
            "resized ×{:.3} ×{:.3} ×{:.3}",
            ratio[0], ratio[1], ratio[2]
        ));
        lists.scaled.push(instance.clone());
    }
    after.provenance = Some(Provenance {
        stage: "ingest".to_owned(),
        source_instance: before.provenance.as_ref().and_then(|p| p.source_instance),
        notes: vec![format!("edited by the annotator: {}", notes.join(", "))],
    });
    (after, change)
}

/// The next free instance of `source`'s category: `mug_0` → `mug_2` when `mug_0` and `mug_1`
/// are taken.
fn next_instance(source: &str, taken: &BTreeSet<String>) -> String {
    let category = category_of_instance(source);
    let next = taken
        .iter()
        .filter_map(|name| {
            name.strip_prefix(category)
                .and_then(|rest| rest.strip_prefix('_'))
                .and_then(|n| n.parse::<u64>().ok())
        })
        .max()
        .map_or(0, |n| n + 1);
    let mut k = next;
    loop {
        let candidate = format!("{category}_{k}");
        if !taken.contains(&candidate) {
            return candidate;
        }
        k += 1;
    }
}
