//! `mesa export`: a scene's layout as files a physics simulator loads (SPEC 5.11, issue #17).
//!
//! Every format shares one model of the scene, built here from the layout and the assets'
//! convex parts (the collision shapes of [`crate::check`]):
//!
//! - metres, z up, the table frame of the layout (SPEC 2): the table top is z = 0;
//! - the table: a static box under the item placement zone (grown by `table_margin_m`), its
//!   top at z = 0; over a vanity's restricted zone (the sink) the top has a hole and a static
//!   basin floor `sink_depth_m` below it;
//! - one rigid body per object, named its `instance`, whose frame is the object's pose: origin
//!   at the centre of its bounding box (the layout's `position`), axes turned by its
//!   `rotation`. Its geometry is in that frame with the layout's `scale_factor` applied (so
//!   every mesh file is the object's, not the asset's);
//! - its colliders: one convex mesh per convex part;
//! - its mass: the asset annotation's `mass` when present, else `density_kg_m3` × the parts'
//!   volume; its centre of mass and inertia are those of the parts, solid and uniform, scaled
//!   to that mass;
//! - its visual mesh: every triangle of the asset's GLB, one mesh per glTF material with its
//!   base colour and base-colour texture ([`visual`]; see `docs/export.md`).

pub mod mass;
pub mod mjcf;
pub mod obj;
pub mod urdf;
pub mod usd;
pub mod visual;

use std::collections::{BTreeMap, BTreeSet};

use mesa_schemas::artifacts::{
    AssetGeometry, ExportArtifact, ExportedObject, MassSource, UncheckedObject, EXPORT_SCHEMA,
};
use mesa_schemas::DatasetLayout;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::assets::table_aligned_from_gltf;
use crate::check::{AssetShape, HullMesh, Pose};
use crate::glb_read::GlbMesh;

pub use self::mass::MassProperties;
pub use self::visual::{VisualMaterial, VisualTexture};

/// The MJCF folder, relative to the scene folder.
pub use crate::paths::scene::{EXPORT_MANIFEST, MJCF_DIR, TEXTURES_DIR, URDF_DIR, USD_SCENE};

/// What an object collides with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Colliders {
    /// One convex mesh per convex part of the asset index: a bowl keeps its cavity.
    #[default]
    Parts,
    /// One convex hull of the whole object (what MesaTask's Drake step does with a visual
    /// mesh): cheaper, and a bowl is a solid lump. For comparison.
    Hull,
}

/// A simulator format `mesa export` writes.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize, JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum ExportFormat {
    /// MuJoCo: `sim/mjcf/scene.xml` and its meshes.
    Mjcf,
    /// PyBullet, SAPIEN, Drake: `sim/urdf/` (one URDF per object, the table, the poses).
    Urdf,
    /// Isaac Sim and other USD readers: `sim/usd/scene.usda`.
    Usd,
}

impl ExportFormat {
    /// Every format, in the order they are written.
    pub const ALL: [ExportFormat; 3] = [Self::Mjcf, Self::Urdf, Self::Usd];

    /// The name in `export.json` and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Self::Mjcf => "mjcf",
            Self::Urdf => "urdf",
            Self::Usd => "usd",
        }
    }
}

/// The `[export]` section of `mesa.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct ExportConfig {
    /// The formats written: any of "mjcf", "urdf", "usd" (`--format` overrides it).
    pub formats: Vec<ExportFormat>,
    /// The colliders of each object: `parts` (one per convex part) or `hull` (one hull).
    pub colliders: Colliders,
    /// Density of objects whose asset annotation gives no `mass`, kg/m³ (500: between wood
    /// and plastic; the parts are solid, so a hollow object counts its walls only).
    pub density_kg_m3: f64,
    /// Sliding friction coefficient of every contact (MuJoCo `friction[0]`, PyBullet
    /// `lateralFriction`).
    pub friction_sliding: f64,
    /// Torsional friction (MuJoCo `friction[1]`, PyBullet `spinningFriction`), metres.
    pub friction_torsional: f64,
    /// Rolling friction (MuJoCo `friction[2]`, PyBullet `rollingFriction`), metres.
    pub friction_rolling: f64,
    /// Contact dimensionality of MuJoCo's geoms: 3 (sliding), 4 (+ torsional) or 6 (+ rolling).
    pub condim: u32,
    /// MuJoCo `solref` time constant of contacts, seconds (at least twice the timestep).
    /// MuJoCo's own default, 0.02: at 0.005 a toothbrush leaning in its cup creeps along the
    /// rim (5 cm in 2 s) where at 0.02 it stays (0.09 cm).
    pub solref_timeconst_s: f64,
    /// MuJoCo `solref` damping ratio of contacts.
    pub solref_dampratio: f64,
    /// The simulation timestep written into the MJCF `option`, seconds.
    pub timestep_s: f64,
    /// How far the table box reaches beyond the item placement zone on each side, metres.
    pub table_margin_m: f64,
    /// Thickness of the table box, metres (its top is the table top).
    pub table_thickness_m: f64,
    /// Depth of a vanity's sink basin below the table top, metres.
    pub sink_depth_m: f64,
    /// Thickness given to a convex part that is a flat polygon (the asset index stores parts
    /// thinner than its 0.1 mm grid flat), metres: simulators need a volume to collide.
    pub flat_part_thickness_m: f64,
}

impl Default for ExportConfig {
    fn default() -> Self {
        Self {
            formats: ExportFormat::ALL.to_vec(),
            colliders: Colliders::Parts,
            density_kg_m3: 500.0,
            friction_sliding: 0.8,
            friction_torsional: 0.005,
            friction_rolling: 0.0001,
            condim: 4,
            solref_timeconst_s: 0.02,
            solref_dampratio: 1.0,
            timestep_s: 0.002,
            table_margin_m: crate::check::simulate::TABLE_MARGIN_M,
            table_thickness_m: crate::check::simulate::TABLE_THICKNESS_M,
            sink_depth_m: crate::check::simulate::SINK_DEPTH_M,
            flat_part_thickness_m: crate::check::simulate::FLAT_PART_THICKNESS_M,
        }
    }
}

impl ExportConfig {
    /// Settings that cannot give a loadable scene, each as `[export] key: problem (expected
    /// ...)`.
    pub fn problems(&self) -> Vec<String> {
        let mut out = Vec::new();
        let mut positive = |key: &str, v: f64| {
            if !(v.is_finite() && v > 0.0) {
                out.push(format!(
                    "[export] {key}: is {v} (expected a finite number > 0)"
                ));
            }
        };
        positive("density_kg_m3", self.density_kg_m3);
        positive("solref_timeconst_s", self.solref_timeconst_s);
        positive("solref_dampratio", self.solref_dampratio);
        positive("timestep_s", self.timestep_s);
        positive("table_thickness_m", self.table_thickness_m);
        positive("sink_depth_m", self.sink_depth_m);
        positive("flat_part_thickness_m", self.flat_part_thickness_m);
        for (key, v) in [
            ("friction_sliding", self.friction_sliding),
            ("friction_torsional", self.friction_torsional),
            ("friction_rolling", self.friction_rolling),
            ("table_margin_m", self.table_margin_m),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                out.push(format!(
                    "[export] {key}: is {v} (expected a finite number >= 0)"
                ));
            }
        }
        if self.formats.is_empty() {
            out.push(
                "[export] formats: is empty (expected one or more of \"mjcf\", \"urdf\", \"usd\")"
                    .to_owned(),
            );
        }
        let mut seen = self.formats.clone();
        seen.sort();
        seen.dedup();
        if seen.len() != self.formats.len() {
            out.push(
                "[export] formats: names a format twice (expected each at most once)".to_owned(),
            );
        }
        if ![3, 4, 6].contains(&self.condim) {
            out.push(format!(
                "[export] condim: is {} (expected 3, 4 or 6)",
                self.condim
            ));
        }
        out
    }
}

/// An asset's visual mesh in the asset's table-aligned frame, relative to the centre of its
/// bounding box (the frame of [`AssetShape`]'s parts), metres; split by material.
#[derive(Debug, Clone, PartialEq)]
pub struct VisualMesh {
    /// Vertices.
    pub positions_m: Vec<[f64; 3]>,
    /// Triangles (counter-clockwise seen from outside).
    pub triangles: Vec<[u32; 3]>,
    /// glTF texture coordinates (v pointing down the image), one per vertex; empty when no
    /// material is textured.
    pub uvs: Vec<[f32; 2]>,
    /// The materials: each triangle is in exactly one (one grey material when the asset has
    /// none).
    pub materials: Vec<VisualMaterial>,
    /// The base-colour images the materials use.
    pub textures: Vec<VisualTexture>,
    /// Why an image or a material's texture was not carried over, each naming it.
    pub texture_warnings: Vec<String>,
}

impl VisualMesh {
    /// The visual mesh of a GLB read by [`crate::glb_read::read_glb`], in the frame the asset
    /// index measured (`geometry`: its front yaw and bounds), in one grey material.
    pub fn from_glb(mesh: &GlbMesh, geometry: &AssetGeometry) -> Self {
        let c: [f64; 3] =
            std::array::from_fn(|k| 0.5 * (geometry.bounds_min_m[k] + geometry.bounds_max_m[k]));
        let positions_m = mesh
            .positions_m
            .iter()
            .map(|p| {
                let q = table_aligned_from_gltf(*p, geometry.front_yaw_deg);
                [q[0] - c[0], q[1] - c[1], q[2] - c[2]]
            })
            .collect();
        Self::untextured(positions_m, mesh.triangles.clone())
    }

    /// A mesh in one grey material.
    pub fn untextured(positions_m: Vec<[f64; 3]>, triangles: Vec<[u32; 3]>) -> Self {
        let all = (0..triangles.len() as u32).collect();
        Self {
            positions_m,
            triangles,
            uvs: Vec::new(),
            materials: vec![VisualMaterial::grey(all)],
            textures: Vec::new(),
            texture_warnings: Vec::new(),
        }
    }
}

/// One object to export.
#[derive(Debug, Clone)]
pub struct ExportObject<'a> {
    /// The layout's instance.
    pub instance: &'a str,
    /// The asset.
    pub uid: &'a str,
    /// Where the layout puts it.
    pub pose: Pose,
    /// Its convex parts.
    pub shape: &'a AssetShape,
    /// Its visual mesh (`None`: the parts are drawn instead, with a warning).
    pub visual: Option<&'a VisualMesh>,
    /// The annotation's mass, kg.
    pub annotated_mass_kg: Option<f64>,
}

/// A scene to export.
#[derive(Debug, Clone)]
pub struct ExportRequest<'a> {
    /// The scene id (the MJCF model name).
    pub scene_id: &'a str,
    /// The layout file, relative to the scene folder.
    pub layout_file: &'a str,
    /// SHA-256 of its bytes.
    pub layout_sha256: &'a str,
    /// The layout (for the zones).
    pub layout: &'a DatasetLayout,
    /// The objects that have a shape, in layout order.
    pub objects: Vec<ExportObject<'a>>,
    /// Objects left out, with the reason.
    pub skipped: Vec<UncheckedObject>,
    /// Whether to write the table (a single asset's files have none).
    pub with_table: bool,
}

pub use crate::check::simulate::TableBox;

/// The table as static boxes: the top (split around the sink's hole) and the sink's floor —
/// the same table `mesa check --settle` simulates on, with this section's sizes.
pub fn table_boxes(layout: &DatasetLayout, config: &ExportConfig) -> Vec<TableBox> {
    crate::check::simulate::table_boxes(
        layout,
        config.table_margin_m,
        config.table_thickness_m,
        config.sink_depth_m,
    )
}

/// An object's geometry in its body frame (scaled), with its mass properties.
#[derive(Debug, Clone)]
pub struct BodyModel {
    /// The instance.
    pub instance: String,
    /// The pose (position and rotation of the body frame).
    pub pose: Pose,
    /// Convex parts that span a volume: vertices and outward triangles, body frame.
    pub parts: Vec<HullMesh>,
    /// The visual mesh, body frame.
    pub visual: VisualMesh,
    /// Mass, centre of mass and inertia.
    pub mass: MassProperties,
    /// The manifest's record.
    pub record: ExportedObject,
}

/// Scales points by the pose's scale (in the asset's frame) and flips triangles when the scale
/// mirrors.
fn scaled(points: &[[f64; 3]], triangles: &[[u32; 3]], s: [f64; 3]) -> HullMesh {
    let p = points
        .iter()
        .map(|p| [p[0] * s[0], p[1] * s[1], p[2] * s[2]])
        .collect();
    let t = if s[0] * s[1] * s[2] < 0.0 {
        triangles.iter().map(|t| [t[0], t[2], t[1]]).collect()
    } else {
        triangles.to_vec()
    };
    (p, t)
}

/// A convex part as a solid a simulator accepts: the hull of its points, computed in their
/// principal frame stretched to a unit box (a rotation and a positive scale per axis map
/// hulls to hulls and keep the faces' orientation), so that a part a fraction of a millimetre
/// thin still gets its faces. A part thinner than `thickness_m` along its thinnest principal
/// axis (the asset index stores parts thinner than its 0.1 mm grid as flat polygons; MuJoCo's
/// qhull rejects near-coplanar points) is first doubled at ± `thickness_m` / 2 along that
/// axis. `None` for points that span no polygon (a segment or a point).
pub fn solid_part(points: &[[f64; 3]], thickness_m: f64) -> Option<HullMesh> {
    use nalgebra::{Matrix3, SymmetricEigen, Vector3};
    if points.len() < 3 {
        return None;
    }
    let n = points.len() as f64;
    let c: [f64; 3] = std::array::from_fn(|k| points.iter().map(|p| p[k]).sum::<f64>() / n);
    let mut cov = Matrix3::<f64>::zeros();
    for p in points {
        let d = Vector3::new(p[0] - c[0], p[1] - c[1], p[2] - c[2]);
        cov += d * d.transpose();
    }
    let eigen = SymmetricEigen::new(cov);
    // Axes sorted by decreasing spread; a right-handed frame.
    let mut order = [0usize, 1, 2];
    order.sort_by(|a, b| eigen.eigenvalues[*b].total_cmp(&eigen.eigenvalues[*a]));
    let e0: Vector3<f64> = eigen.eigenvectors.column(order[0]).into();
    let e1: Vector3<f64> = eigen.eigenvectors.column(order[1]).into();
    let e2 = e0.cross(&e1);
    let axes = [e0, e1, e2];
    let local: Vec<[f64; 3]> = points
        .iter()
        .map(|p| {
            let d = Vector3::new(p[0] - c[0], p[1] - c[1], p[2] - c[2]);
            [axes[0].dot(&d), axes[1].dot(&d), axes[2].dot(&d)]
        })
        .collect();
    let bounds = crate::mesh::Aabb::from_points(local.iter().copied())?;
    let size = bounds.size();
    if !(size[0] > 1e-9 && size[1] > 1e-9) {
        return None;
    }
    let mut local = local;
    if size[2] < thickness_m {
        let mid = bounds.center()[2];
        let flat: Vec<[f64; 3]> = local.iter().map(|p| [p[0], p[1], mid]).collect();
        local = [-0.5, 0.5]
            .iter()
            .flat_map(|s| {
                flat.iter()
                    .map(move |p| [p[0], p[1], p[2] + s * thickness_m])
            })
            .collect();
    }
    let bounds = crate::mesh::Aabb::from_points(local.iter().copied())?;
    let (lc, size) = (bounds.center(), bounds.size());
    let unit: Vec<[f64; 3]> = local
        .iter()
        .map(|p| std::array::from_fn(|k| (p[k] - lc[k]) / size[k]))
        .collect();
    let (hull, triangles) = crate::check::geometry::convex_hull(&unit);
    if triangles.is_empty() {
        return None;
    }
    let back = hull
        .iter()
        .map(|q| {
            let l: [f64; 3] = std::array::from_fn(|k| q[k] * size[k] + lc[k]);
            std::array::from_fn(|r| {
                c[r] + axes[0][r] * l[0] + axes[1][r] * l[1] + axes[2][r] * l[2]
            })
        })
        .collect();
    Some((back, triangles))
}

/// The body of one object, and warnings about it.
pub fn body_model(object: &ExportObject<'_>, config: &ExportConfig) -> (BodyModel, Vec<String>) {
    let mut warnings = Vec::new();
    let s = object.pose.scale;
    let mut parts = Vec::new();
    let mut flat = 0;
    let sources: Vec<Vec<[f64; 3]>> = match config.colliders {
        Colliders::Parts => object
            .shape
            .parts()
            .iter()
            .map(|(points, _)| points.to_vec())
            .collect(),
        Colliders::Hull => vec![object
            .shape
            .parts()
            .iter()
            .flat_map(|(points, _)| points.iter().copied())
            .collect()],
    };
    for points in &sources {
        // Thinness is judged at the layout's scale: scale first, then make the solid.
        let (scaled_points, _) = scaled(points, &[], s);
        match solid_part(&scaled_points, config.flat_part_thickness_m) {
            Some(part) => parts.push(part),
            None => flat += 1,
        }
    }
    if flat > 0 {
        warnings.push(format!(
            "{}: {flat} of its {} convex parts span neither a volume nor a polygon and are left \
             out of the colliders",
            object.instance,
            sources.len()
        ));
    }
    let visual = match object.visual {
        Some(v) => {
            let (positions_m, triangles) = scaled(&v.positions_m, &v.triangles, s);
            VisualMesh {
                positions_m,
                triangles,
                uvs: v.uvs.clone(),
                materials: v.materials.clone(),
                textures: v.textures.clone(),
                texture_warnings: Vec::new(),
            }
        }
        None => {
            warnings.push(format!(
                "{}: no visual mesh (the asset's GLB could not be read): its convex parts are \
                 drawn instead",
                object.instance
            ));
            let (mut positions_m, mut triangles) = (Vec::new(), Vec::new());
            for (points, part_triangles) in &parts {
                let base = positions_m.len() as u32;
                positions_m.extend_from_slice(points);
                triangles.extend(part_triangles.iter().map(|t| t.map(|i| i + base)));
            }
            VisualMesh::untextured(positions_m, triangles)
        }
    };
    let unit = mass::unit_density(&parts);
    let (mass_kg, mass_source) = match object.annotated_mass_kg {
        Some(m) if m > 0.0 && m.is_finite() => (m, MassSource::Annotation),
        _ => (config.density_kg_m3 * unit.volume_m3, MassSource::Density),
    };
    let mass = unit.with_mass(mass_kg, object.shape.size_m, s);
    if mass.fallback_box {
        warnings.push(format!(
            "{}: its convex parts have no volume: inertia of its bounding box",
            object.instance
        ));
    }
    let record = ExportedObject {
        instance: object.instance.to_owned(),
        uid: object.uid.to_owned(),
        mass_kg: mass.mass_kg,
        mass_source,
        volume_m3: unit.volume_m3,
        center_of_mass_m: mass.center_m,
        inertia_kg_m2: mass.inertia_kg_m2,
        collision_parts: parts.len() as u64,
        visual_triangles: visual.triangles.len() as u64,
        visual_materials: visual.materials.len() as u64,
        textures: {
            let mut files: Vec<String> = visual
                .materials
                .iter()
                .filter_map(|m| m.texture)
                .map(|t| {
                    format!(
                        "{TEXTURES_DIR}/{}",
                        visual::texture_file(object.uid, visual.textures[t].image)
                    )
                })
                .collect();
            files.sort();
            files.dedup();
            files
        },
    };
    (
        BodyModel {
            instance: object.instance.to_owned(),
            pose: object.pose,
            parts,
            visual,
            mass,
            record,
        },
        warnings,
    )
}

/// The revision of what the writers make of the same inputs, for the runner's fingerprints: a
/// new revision redoes exports made by an older one (2: visual meshes split by material, with
/// textures).
pub const WRITER_REVISION: u32 = 2;

/// What a scene's export gives: files relative to the scene folder, and the manifest.
#[derive(Debug, Clone)]
pub struct SceneExport {
    /// Files, relative to the scene folder.
    pub files: BTreeMap<String, Vec<u8>>,
    /// `sim/export.json`.
    pub manifest: ExportArtifact,
}

/// Exports a scene in the configured formats: MJCF (`sim/mjcf/scene.xml` and its meshes), URDF
/// (`sim/urdf/`) and USD (`sim/usd/scene.usda`).
pub fn export_scene(
    request: &ExportRequest<'_>,
    config: &ExportConfig,
) -> Result<SceneExport, serde_json::Error> {
    let mut warnings = Vec::new();
    // What could not be carried of an asset's materials, once per asset.
    let mut assets_warned = BTreeSet::new();
    for o in &request.objects {
        if let Some(v) = o.visual {
            if assets_warned.insert(o.uid) {
                warnings.extend(
                    v.texture_warnings
                        .iter()
                        .map(|w| format!("asset {}: {w}", o.uid)),
                );
            }
        }
    }
    let bodies: Vec<BodyModel> = request
        .objects
        .iter()
        .map(|o| {
            let (body, w) = body_model(o, config);
            warnings.extend(w);
            body
        })
        .collect();
    let table = if request.with_table {
        table_boxes(request.layout, config)
    } else {
        Vec::new()
    };
    let mut files = BTreeMap::new();
    // Each asset image once, whichever objects use it: every format reads it.
    for body in &bodies {
        for t in &body.visual.textures {
            files
                .entry(format!(
                    "{TEXTURES_DIR}/{}",
                    visual::texture_file(&body.record.uid, t.image)
                ))
                .or_insert_with(|| t.png.as_ref().clone());
        }
    }
    let mut formats = config.formats.clone();
    formats.sort();
    formats.dedup();
    for format in &formats {
        match format {
            ExportFormat::Mjcf => {
                for (rel, bytes) in mjcf::write_mjcf(request.scene_id, &table, &bodies, config) {
                    files.insert(format!("{MJCF_DIR}/{rel}"), bytes);
                }
            }
            ExportFormat::Urdf => {
                for (rel, bytes) in urdf::write_urdf(request.scene_id, &table, &bodies, config)? {
                    files.insert(format!("{URDF_DIR}/{rel}"), bytes);
                }
                // The URDFs name the MJCF's mesh files (`../mjcf/meshes/`): without the MJCF,
                // its meshes are still written.
                if !formats.contains(&ExportFormat::Mjcf) {
                    for (rel, bytes) in mjcf::write_mjcf(request.scene_id, &table, &bodies, config)
                    {
                        if rel.starts_with("meshes/") {
                            files.insert(format!("{MJCF_DIR}/{rel}"), bytes);
                        }
                    }
                }
            }
            ExportFormat::Usd => {
                files.insert(
                    USD_SCENE.to_owned(),
                    usd::write_usda(request.scene_id, &table, &bodies).into_bytes(),
                );
            }
        }
    }
    let m = config.table_margin_m;
    let zone = request.layout.zone_cm.0.map(|v| v / 100.0);
    let mut listed: Vec<String> = files.keys().cloned().collect();
    listed.push(EXPORT_MANIFEST.to_owned());
    listed.sort();
    let manifest = ExportArtifact {
        schema: EXPORT_SCHEMA.to_owned(),
        scene_id: request.scene_id.to_owned(),
        layout: request.layout_file.to_owned(),
        layout_sha256: request.layout_sha256.to_owned(),
        formats: formats.iter().map(|f| f.name().to_owned()).collect(),
        files: listed,
        density_kg_m3: config.density_kg_m3,
        table_size_m: if request.with_table {
            [
                zone[1] - zone[0] + 2.0 * m,
                zone[3] - zone[2] + 2.0 * m,
                config.table_thickness_m,
            ]
        } else {
            [0.0; 3]
        },
        sink_depth_m: request
            .layout
            .restricted_zone_cm
            .as_ref()
            .filter(|_| request.with_table)
            .map(|_| config.sink_depth_m),
        objects: bodies.into_iter().map(|b| b.record).collect(),
        skipped: request.skipped.clone(),
        warnings,
    };
    Ok(SceneExport { files, manifest })
}

#[cfg(test)]
mod tests;
