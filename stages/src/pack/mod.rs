//! `pack`: the annotator pack of a scene (SPEC 5.4).
//!
//! One GLB per scene, written with `gltf-json` through [`crate::glb_write`]:
//! - `table`: a slab over the placement zone, its top at z = 0;
//! - `restricted_zone`: a thin translucent patch over the sink, when the layout has one;
//! - one node per object, named exactly its instance, drawing one mesh: the asset's node
//!   hierarchy baked in its table-aligned frame with the origin at its bounding-box centre
//!   ([`bake`]); the node's translation is the layout position, its rotation the layout
//!   rotation, its scale the layout size over the mesh's size (per axis, as MesaTask's
//!   reconstruction scales each axis to the target size); assets used twice share one mesh;
//!   materials, textures and samplers are kept; `extras.mesa = {instance, uid, scene_id}`;
//! - `H1_reference`: a 1.70 m figure standing on the floor beside the front-left corner.
//!
//! Beside the GLB: `reference.png` (the photo), `snapshots/<instance>.png` ([`snapshot`]),
//! `index.json` (`mesa.pack-index/1`), `README.txt` for the annotator ([`readme`]), and, when
//! configured, `<scene_id>.zip` of all of them. The same inputs give the same bytes.

pub mod bake;
pub mod figure;
pub mod readme;
pub mod snapshot;

use std::collections::{BTreeMap, HashMap};
use std::io::Write as _;

use mesa_schemas::annotation::{
    PackAsset, PackFigure, PackIndexArtifact, PackObject, PackTable, PACK_INDEX_SCHEMA,
};
use mesa_schemas::convert::category_of_instance;
use mesa_schemas::layout::DatasetLayout;
use mesa_schemas::units::PositionCm;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use self::bake::{bake_asset, BakeError, BakedAsset, SourceImage, SourceMaterial, SourceTexture};
use self::figure::{h1_figure, slab, table_height_m, H1_HEIGHT_M};
use self::snapshot::{snapshot_png, Margin, Photo};
use crate::glb_write::{AlphaSpec, GlbBuilder, GlbWriteError, MaterialSpec, NodeSpec};
use crate::gltf_frames::{gltf_from_object_axes, gltf_from_table_point, gltf_from_table_quat};
use crate::mesh::quat_normalize;

/// The node names of the pack's own nodes.
pub const TABLE_NODE: &str = "table";
/// The restricted zone's node.
pub const RESTRICTED_ZONE_NODE: &str = "restricted_zone";
/// The reference figure's node.
pub const H1_NODE: &str = "H1_reference";
/// Height of the restricted-zone patch, metres (centred on the table top, so it shows above
/// it).
pub const RESTRICTED_ZONE_HEIGHT_M: f64 = 0.002;

/// The `[pack]` section of `mesa.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct PackConfig {
    /// Also write `pack/<scene_id>.zip` holding every file of the pack (to send as one file).
    pub zip: bool,
    /// Thickness of the table slab below the table top, cm.
    pub table_thickness_cm: f64,
    /// Margin of a snapshot around its instance's mask, as a fraction of the mask box's larger
    /// side.
    pub snapshot_margin: f64,
    /// The smallest snapshot margin, pixels.
    pub snapshot_min_margin_px: u32,
}

impl Default for PackConfig {
    fn default() -> Self {
        Self {
            zip: false,
            table_thickness_cm: 2.0,
            snapshot_margin: 0.25,
            snapshot_min_margin_px: 16,
        }
    }
}

impl PackConfig {
    /// Values that parse but cannot work.
    pub fn problems(&self) -> Vec<String> {
        let mut out = Vec::new();
        if !(self.table_thickness_cm > 0.0 && self.table_thickness_cm.is_finite()) {
            out.push(format!(
                "[pack] table_thickness_cm = {}: expected a positive number of cm",
                self.table_thickness_cm
            ));
        }
        if !(self.snapshot_margin >= 0.0 && self.snapshot_margin.is_finite()) {
            out.push(format!(
                "[pack] snapshot_margin = {}: expected a fraction >= 0",
                self.snapshot_margin
            ));
        }
        out
    }
}

/// An asset to pack: its GLB and its front alignment.
#[derive(Debug, Clone, Copy)]
pub struct AssetSource<'a> {
    /// The GLB bytes.
    pub glb: &'a [u8],
    /// The asset index's `front_yaw_deg`.
    pub front_yaw_deg: f64,
}

impl<'a> AssetSource<'a> {
    /// The sources of GLBs by uid, each facing the front as it is (`front_yaw_deg` 0).
    pub fn facing_front(glbs: &'a BTreeMap<String, Vec<u8>>) -> BTreeMap<String, Self> {
        glbs.iter()
            .map(|(uid, glb)| {
                (
                    uid.clone(),
                    Self {
                        glb,
                        front_yaw_deg: 0.0,
                    },
                )
            })
            .collect()
    }
}

/// Everything a scene's pack is made from.
#[derive(Debug, Clone, Copy)]
pub struct PackRequest<'a> {
    /// The scene id.
    pub scene_id: &'a str,
    /// The table type (the H1 figure's floor is below the table top by a typical height).
    pub table_type: &'a str,
    /// The layout to pack.
    pub layout: &'a DatasetLayout,
    /// Where it is, relative to the scene folder.
    pub layout_rel: &'a str,
    /// Its bytes (their digest goes into the index).
    pub layout_bytes: &'a [u8],
    /// The assets, by uid.
    pub assets: &'a BTreeMap<String, AssetSource<'a>>,
    /// The photo: its PNG bytes (copied as `reference.png`) and its pixels.
    pub photo: Option<(&'a [u8], &'a Photo)>,
    /// Mask pixels (row-major indices into the photo) by instance.
    pub masks: &'a BTreeMap<String, Vec<u32>>,
}

/// A scene's pack.
#[derive(Debug, Clone, PartialEq)]
pub struct PackOutput {
    /// The files, relative to the pack folder.
    pub files: BTreeMap<String, Vec<u8>>,
    /// `index.json` as written.
    pub index: PackIndexArtifact,
    /// What is worth a look.
    pub warnings: Vec<String>,
}

/// Why a scene cannot be packed.
#[derive(Debug, thiserror::Error)]
pub enum PackError {
    /// An object's asset is not among the assets given.
    #[error("{instance}: its asset {uid} is not in the asset library (run `mesa assets`, or fix retrieved_uid)")]
    MissingAsset {
        /// The instance.
        instance: String,
        /// The uid.
        uid: String,
    },
    /// An asset cannot be baked.
    #[error("asset {uid} (used by {instance}): {source}")]
    Asset {
        /// The uid.
        uid: String,
        /// The first instance using it.
        instance: String,
        /// Why.
        source: BakeError,
    },
    /// A layout value that cannot be packed.
    #[error("{instance}: {problem}")]
    Layout {
        /// The instance.
        instance: String,
        /// What is wrong and the fix.
        problem: String,
    },
    /// The GLB cannot be written.
    #[error("writing the scene GLB: {0}")]
    Glb(#[from] GlbWriteError),
    /// An image cannot be encoded.
    #[error("encoding a snapshot: {0}")]
    Image(#[from] crate::image_io::ImageError),
    /// The index or the zip cannot be written.
    #[error("{0}")]
    Io(String),
}

fn linear_srgb(c: [f32; 3]) -> [f32; 3] {
    c.map(|v| {
        if v <= 0.04045 {
            v / 12.92
        } else {
            ((v + 0.055) / 1.055).powf(2.4)
        }
    })
}

/// Why an instance name cannot name a Blender object and a snapshot file (the text completes
/// "the instance name ...").
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum UnsafeName {
    /// The name is empty.
    #[error("is empty")]
    Empty,
    /// The name has a `/` or `\\`.
    #[error("contains a path separator")]
    PathSeparator,
    /// The name starts with `.` (or is `.` or `..`).
    #[error("starts with a dot")]
    LeadingDot,
    /// The name has a control character.
    #[error("contains a control character")]
    ControlCharacter,
    /// The name is longer than 200 bytes.
    #[error("is {bytes} bytes long (at most 200)")]
    TooLong {
        /// Its length in bytes.
        bytes: usize,
    },
}

/// Whether an instance name is safe as a node name and a file name (`snapshots/<name>.png`).
pub fn safe_instance_name(name: &str) -> Result<(), UnsafeName> {
    if name.is_empty() {
        return Err(UnsafeName::Empty);
    }
    if name.contains(['/', '\\']) {
        return Err(UnsafeName::PathSeparator);
    }
    if name == "." || name == ".." || name.starts_with('.') {
        return Err(UnsafeName::LeadingDot);
    }
    if name.chars().any(|c| c.is_control()) {
        return Err(UnsafeName::ControlCharacter);
    }
    if name.len() > 200 {
        return Err(UnsafeName::TooLong { bytes: name.len() });
    }
    Ok(())
}

/// Adds materials with their textures and images to a GLB (images shared by content across
/// calls through `images`); returns the material indices.
pub(crate) fn add_materials(
    b: &mut GlbBuilder,
    prefix: &str,
    materials: &[SourceMaterial],
    textures: &[SourceTexture],
    source_images: &[SourceImage],
    images: &mut HashMap<[u8; 32], gltf_json::Index<gltf_json::Image>>,
) -> Result<Vec<gltf_json::Index<gltf_json::Material>>, GlbWriteError> {
    let p = if prefix.is_empty() {
        String::new()
    } else {
        format!("{prefix}_")
    };
    let mut added = Vec::with_capacity(textures.len());
    for (t, texture) in textures.iter().enumerate() {
        let image = &source_images[texture.image];
        let digest: [u8; 32] = Sha256::digest(&image.bytes).into();
        let index = match images.get(&digest) {
            Some(index) => *index,
            None => {
                let index = b.add_image(
                    &format!("{p}image_{}", texture.image),
                    &image.bytes,
                    &image.mime,
                )?;
                images.insert(digest, index);
                index
            }
        };
        added.push(b.add_texture(&format!("{p}texture_{t}"), index, texture.sampler));
    }
    Ok(materials
        .iter()
        .map(|m| {
            b.add_material(&MaterialSpec {
                name: format!("{p}{}", m.name),
                base_color_factor: m.base_color_factor,
                base_color_texture: m.base_color_texture.map(|t| added[t]),
                metallic: m.metallic,
                roughness: m.roughness,
                double_sided: m.double_sided,
                metallic_roughness_texture: m.metallic_roughness_texture.map(|t| added[t]),
                normal_texture: m.normal_texture.map(|(t, s)| (added[t], s)),
                occlusion_texture: m.occlusion_texture.map(|(t, s)| (added[t], s)),
                emissive_texture: m.emissive_texture.map(|t| added[t]),
                emissive_factor: m.emissive_factor,
                alpha: m.alpha,
            })
        })
        .collect())
}

/// Adds one baked asset's images, textures, materials and mesh to the GLB; returns the mesh.
pub(crate) fn add_asset(
    b: &mut GlbBuilder,
    uid: &str,
    baked: &BakedAsset,
    images: &mut HashMap<[u8; 32], gltf_json::Index<gltf_json::Image>>,
) -> Result<gltf_json::Index<gltf_json::Mesh>, GlbWriteError> {
    let short = &uid[..uid.len().min(8)];
    let materials = add_materials(
        b,
        short,
        &baked.materials,
        &baked.textures,
        &baked.images,
        images,
    )?;
    let primitives: Vec<_> = baked
        .parts
        .iter()
        .map(|(mesh, m)| (mesh, materials[*m]))
        .collect();
    b.add_mesh(uid, &primitives)
}

/// Packs a scene.
pub fn pack_scene(request: &PackRequest<'_>, config: &PackConfig) -> Result<PackOutput, PackError> {
    let layout = request.layout;
    let scene_id = request.scene_id;
    let mut warnings = Vec::new();

    // Bake each asset once, in the order of first use.
    let mut baked: Vec<(String, BakedAsset)> = Vec::new();
    for object in &layout.objects {
        safe_instance_name(&object.instance).map_err(|problem| PackError::Layout {
            instance: object.instance.clone(),
            problem: format!(
                "the instance name {problem}: it names a Blender object and a snapshot file \
                 (rename it in the layout)"
            ),
        })?;
        let uid = &object.retrieved_uid;
        if baked.iter().any(|(u, _)| u == uid) {
            continue;
        }
        let source = request
            .assets
            .get(uid)
            .ok_or_else(|| PackError::MissingAsset {
                instance: object.instance.clone(),
                uid: uid.clone(),
            })?;
        let asset =
            bake_asset(source.glb, source.front_yaw_deg).map_err(|source| PackError::Asset {
                uid: uid.clone(),
                instance: object.instance.clone(),
                source,
            })?;
        for w in &asset.warnings {
            warnings.push(format!("asset {uid}: {w}"));
        }
        baked.push((uid.clone(), asset));
    }

    let mut b = GlbBuilder::new(concat!("mesa pack ", env!("CARGO_PKG_VERSION")));
    let mut images = HashMap::new();
    let mut meshes = BTreeMap::new();
    for (uid, asset) in &baked {
        meshes.insert(uid.clone(), add_asset(&mut b, uid, asset, &mut images)?);
    }

    // The table slab over the zone, its top at z = 0.
    let [x0, x1, y0, y1] = layout.zone_cm.0.map(|v| v / 100.0);
    let thickness = config.table_thickness_cm / 100.0;
    let table_material = b.add_material(&MaterialSpec::plain(
        "table",
        linear_srgb([0.62, 0.50, 0.38]),
        0.7,
    ));
    let table_mesh = b.add_mesh(
        TABLE_NODE,
        &[(&slab(x1 - x0, thickness, y1 - y0), table_material)],
    )?;
    let mut roots = Vec::new();
    roots.push(
        b.add_node(
            NodeSpec::new(TABLE_NODE)
                .with_mesh(table_mesh)
                .with_translation(gltf_from_table_point([
                    (x0 + x1) / 2.0,
                    (y0 + y1) / 2.0,
                    -thickness / 2.0,
                ]))
                .with_extras(serde_json::json!({"mesa": {"role": "table", "scene_id": scene_id}})),
        )?,
    );
    if let Some(zone) = &layout.restricted_zone_cm {
        let [rx0, rx1, ry0, ry1] = zone.0.map(|v| v / 100.0);
        let mut material = MaterialSpec::plain("restricted_zone", [0.8, 0.02, 0.02], 0.6);
        material.base_color_factor[3] = 0.45;
        material.alpha = AlphaSpec::Blend;
        material.double_sided = true;
        let material = b.add_material(&material);
        let mesh = b.add_mesh(
            RESTRICTED_ZONE_NODE,
            &[(
                &slab(rx1 - rx0, RESTRICTED_ZONE_HEIGHT_M, ry1 - ry0),
                material,
            )],
        )?;
        roots.push(
            b.add_node(
                NodeSpec::new(RESTRICTED_ZONE_NODE)
                    .with_mesh(mesh)
                    .with_translation(gltf_from_table_point([
                        (rx0 + rx1) / 2.0,
                        (ry0 + ry1) / 2.0,
                        0.0,
                    ]))
                    .with_extras(
                        serde_json::json!({"mesa": {"role": "restricted_zone", "scene_id": scene_id}}),
                    ),
            )?,
        );
    }

    // The objects.
    let mut objects = BTreeMap::new();
    for object in &layout.objects {
        let instance = &object.instance;
        let (_, asset) = baked
            .iter()
            .find(|(u, _)| *u == object.retrieved_uid)
            .ok_or_else(|| PackError::MissingAsset {
                instance: instance.clone(),
                uid: object.retrieved_uid.clone(),
            })?;
        let size_m = object.size_cm.0.map(|v| v / 100.0);
        let position_m = object.position_cm.0.map(|v| v / 100.0);
        let finite = size_m.iter().chain(&position_m).all(|v| v.is_finite())
            && object.rotation.0.iter().all(|v| v.is_finite());
        if !finite || size_m.iter().any(|v| *v <= 0.0) {
            return Err(PackError::Layout {
                instance: instance.clone(),
                problem: "position, rotation and size must be finite and the size positive \
                          (run `mesa validate` on the layout)"
                    .to_owned(),
            });
        }
        let scale = [0, 1, 2].map(|i| size_m[i] / asset.size_m[i]);
        let node = NodeSpec::new(instance.clone())
            .with_mesh(meshes[&object.retrieved_uid])
            .with_translation(gltf_from_table_point(position_m))
            .with_rotation_xyzw(gltf_from_table_quat(quat_normalize(object.rotation.0)))
            .with_scale(gltf_from_object_axes(scale))
            .with_extras(serde_json::json!({"mesa": {
                "instance": instance,
                "uid": object.retrieved_uid,
                "scene_id": scene_id,
            }}));
        roots.push(b.add_node(node)?);
        objects.insert(
            instance.clone(),
            PackObject {
                uid: object.retrieved_uid.clone(),
                category: object
                    .category
                    .clone()
                    .unwrap_or_else(|| category_of_instance(instance).to_owned()),
                description: object.description.clone(),
                snapshot: None,
            },
        );
    }

    // The H1 figure, on the floor beside the front-left corner, facing the observer.
    let figure = h1_figure();
    let body = b.add_material(&MaterialSpec::plain(
        "H1_body",
        linear_srgb([0.42, 0.43, 0.46]),
        0.5,
    ));
    let accents = b.add_material(&MaterialSpec::plain(
        "H1_accents",
        linear_srgb([0.06, 0.06, 0.07]),
        0.4,
    ));
    let figure_mesh = b.add_mesh(H1_NODE, &[(&figure.body, body), (&figure.accents, accents)])?;
    let floor = -table_height_m(request.table_type);
    let h1_position = [x0 - 0.45, y0 - 0.20, floor + H1_HEIGHT_M / 2.0];
    roots.push(
        b.add_node(
            NodeSpec::new(H1_NODE)
                .with_mesh(figure_mesh)
                .with_translation(gltf_from_table_point(h1_position))
                .with_extras(serde_json::json!({"mesa": {"role": "H1_reference", "height_m": H1_HEIGHT_M, "scene_id": scene_id}})),
        )?,
    );
    b.set_scene(scene_id, roots);
    let glb = b.finish()?;

    let mut files = BTreeMap::new();
    let glb_name = format!("{scene_id}.glb");
    files.insert(glb_name.clone(), glb);

    // The photo and the snapshots.
    if let Some((png, photo)) = request.photo {
        files.insert("reference.png".to_owned(), png.to_vec());
        let margin = Margin {
            fraction: config.snapshot_margin,
            min_px: config.snapshot_min_margin_px,
        };
        for (instance, entry) in objects.iter_mut() {
            match request.masks.get(instance) {
                Some(pixels) => match snapshot_png(photo, pixels, margin)? {
                    Some(png) => {
                        let rel = format!("snapshots/{instance}.png");
                        files.insert(rel.clone(), png);
                        entry.snapshot = Some(rel);
                    }
                    None => warnings.push(format!("{instance}: its mask is empty: no snapshot")),
                },
                None => warnings.push(format!("{instance}: no mask is known for it: no snapshot")),
            }
        }
    } else {
        warnings.push("no photo (input/image.png): no reference.png and no snapshots".to_owned());
    }

    let index = PackIndexArtifact {
        schema: PACK_INDEX_SCHEMA.to_owned(),
        scene_id: scene_id.to_owned(),
        glb: glb_name.clone(),
        reference: request.photo.map(|_| "reference.png".to_owned()),
        layout: request.layout_rel.to_owned(),
        layout_sha256: crate::sha256_hex(request.layout_bytes),
        zone_cm: layout.zone_cm,
        restricted_zone_cm: layout.restricted_zone_cm,
        table: PackTable {
            node: TABLE_NODE.to_owned(),
            thickness_cm: config.table_thickness_cm,
        },
        h1: PackFigure {
            node: H1_NODE.to_owned(),
            height_cm: H1_HEIGHT_M * 100.0,
            position_cm: PositionCm(h1_position.map(|v| v * 100.0)),
        },
        objects: objects.clone(),
        assets: baked
            .iter()
            .map(|(uid, asset)| {
                (
                    uid.clone(),
                    PackAsset {
                        mesh: uid.clone(),
                        size_m: asset.size_m,
                        front_yaw_deg: request.assets[uid].front_yaw_deg,
                        triangles: asset.triangles as u64,
                    },
                )
            })
            .collect(),
    };
    let index_bytes = mesa_schemas::json::to_sorted_pretty(&index)
        .map_err(|e| PackError::Io(format!("serialising index.json: {e}")))?;
    files.insert("index.json".to_owned(), index_bytes);

    let listed: Vec<(String, Option<String>, bool)> = objects
        .iter()
        .map(|(i, o)| (i.clone(), o.description.clone(), o.snapshot.is_some()))
        .collect();
    let readme_objects: Vec<(String, String, Option<String>, bool)> = layout
        .objects
        .iter()
        .filter_map(|o| {
            listed
                .iter()
                .find(|(i, _, _)| *i == o.instance)
                .map(|(i, d, s)| (i.clone(), objects[i].category.clone(), d.clone(), *s))
        })
        .collect();
    let readme = readme::readme_text(&readme::ReadmeFacts {
        scene_id,
        glb: &glb_name,
        reference: request.photo.is_some(),
        objects: &readme_objects,
        table_cm: [layout.zone_cm.width_cm(), layout.zone_cm.depth_cm()],
        restricted_zone: layout.restricted_zone_cm.is_some(),
    });
    files.insert("README.txt".to_owned(), readme.into_bytes());

    if config.zip {
        let zip = zip_files(scene_id, &files).map_err(|e| PackError::Io(e.to_string()))?;
        files.insert(format!("{scene_id}.zip"), zip);
    }
    Ok(PackOutput {
        files,
        index,
        warnings,
    })
}

/// Why the zip of a pack cannot be written.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ZipError {
    /// A file cannot be added.
    #[error("zip: {name}: {message}")]
    Entry {
        /// The file's name inside the scene folder.
        name: String,
        /// The zip library's error.
        message: String,
    },
    /// The archive cannot be closed.
    #[error("zip: {0}")]
    Finish(String),
}

/// A zip of `files` under the folder `<scene_id>/`, deterministic: sorted names, the DOS
/// epoch as every time stamp, fixed permissions.
pub fn zip_files(scene_id: &str, files: &BTreeMap<String, Vec<u8>>) -> Result<Vec<u8>, ZipError> {
    let mut out = std::io::Cursor::new(Vec::new());
    {
        let mut zip = zip::ZipWriter::new(&mut out);
        let options = zip::write::SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Deflated)
            .last_modified_time(zip::DateTime::default())
            .unix_permissions(0o644);
        for (name, bytes) in files {
            let entry = |e: &dyn std::fmt::Display| ZipError::Entry {
                name: name.clone(),
                message: e.to_string(),
            };
            zip.start_file(format!("{scene_id}/{name}"), options)
                .map_err(|e| entry(&e))?;
            zip.write_all(bytes).map_err(|e| entry(&e))?;
        }
        zip.finish().map_err(|e| ZipError::Finish(e.to_string()))?;
    }
    Ok(out.into_inner())
}

#[cfg(test)]
pub(crate) mod testing;
#[cfg(test)]
mod tests;
