//! Reading library assets: a GLB file → its triangles in the glTF scene frame (metres, +Y up),
//! with what the asset index reports about it.
//!
//! What is read:
//! - the GLB container, every problem with the Khronos validator's code (`container`);
//! - the glTF 2.0 JSON with the `gltf-json` crate (the `gltf` crate's document model), and its
//!   validation (every `(JSON path, problem)` pair);
//! - the default scene's node tree with each node's `matrix` or TRS, every primitive of every
//!   mesh instance (TRIANGLES, TRIANGLE_STRIP, TRIANGLE_FAN; point and line primitives are
//!   skipped and counted), u8/u16/u32 indices or none, sparse accessors, normalized and
//!   quantized (`KHR_mesh_quantization`) positions;
//! - skinned meshes at their rest pose (joint world matrices × inverse bind matrices, weighted)
//!   and morph targets at their default weights, as a viewer shows the file;
//! - `KHR_draco_mesh_compression`, decoded with a pure-Rust Draco decoder (`draco`);
//! - buffers and images embedded in the BIN chunk or in data URIs.
//!
//! What is rejected, with the reason and how to fix it: anything that is not a GLB, glTF 1.0
//! (GLB version 1), external URIs (the asset must be self-contained), `EXT_meshopt_compression`,
//! `EXT_mesh_gpu_instancing` when required, other required extensions that change geometry,
//! out-of-range data, and files without a single triangle.

mod accessor;
mod container;
mod draco;
mod surface;

pub use surface::{AlphaMode, GlbSurface, SurfaceImage, SurfaceMaterial, SurfacePrimitive};

use std::borrow::Cow;
use std::collections::{BTreeSet, HashMap};
use std::rc::Rc;

use base64::Engine as _;
use gltf_json::accessor::ComponentType;
use gltf_json::mesh::{Mode, Semantic};
use gltf_json::validation::{Checked, Validate};
use gltf_json::Root;
use nalgebra::{Matrix4, Quaternion, UnitQuaternion, Vector3};
use serde_json::Value;
use thiserror::Error;

use accessor::{read_accessor, read_indices, Buffers};

/// How to get rid of meshopt compression.
pub(crate) const MESHOPT_FIX: &str = "decompress it, e.g. `gltfpack -i in.glb -o out.glb -noq` \
     (gltfpack writes no meshopt compression without -c), or re-export it from its source \
     without meshopt";

/// Why a GLB cannot be read. [`GlbError::code`] gives a short machine-readable code.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum GlbError {
    /// Not a GLB at all.
    #[error(
        "not a GLB file: {problem} (fix: export it as glTF Binary (.glb); pack a .gltf and its \
         files into one with `npx @gltf-transform/cli copy in.gltf out.glb`)"
    )]
    NotGlb {
        /// `GLB_INVALID_MAGIC`, the validator's code, or `not_glb` for a glTF JSON file (which
        /// the validator reads as JSON, not as a GLB container).
        code: &'static str,
        /// What the bytes are.
        problem: String,
    },
    /// A damaged GLB container.
    #[error("{code} at byte {offset}: {problem} (fix: {fix})")]
    Container {
        /// The glTF-Validator issue code.
        code: &'static str,
        /// Byte offset of the problem.
        offset: usize,
        /// What is wrong.
        problem: String,
        /// How to fix it.
        fix: &'static str,
    },
    /// glTF 1.0.
    #[error(
        "glTF 1.0 (GLB version 1, KHR_binary_glTF): mesa reads glTF 2.0 (fix: convert it with \
         gltf-pipeline, `npx gltf-pipeline -i in.glb -o out.glb`, or re-export it from its \
         source as glTF 2.0 Binary)"
    )]
    Gltf1,
    /// The JSON chunk is not a glTF document.
    #[error("JSON chunk: {problem} (expected a glTF 2.0 JSON document)")]
    Json {
        /// What is wrong.
        problem: String,
    },
    /// An unsupported glTF version.
    #[error("asset.version is \"{version}\" (expected \"2.0\"; re-export it as glTF 2.0)")]
    Version {
        /// The declared version.
        version: String,
    },
    /// The document breaks glTF 2.0 rules.
    #[error("invalid glTF: {}", summarize(problems))]
    Invalid {
        /// Every problem, as `<json path>: <problem>`.
        problems: Vec<String>,
    },
    /// A required extension mesa does not read.
    #[error("requires the extension {extension}, which mesa does not read (fix: {fix})")]
    UnsupportedExtension {
        /// The extension.
        extension: String,
        /// How to fix it.
        fix: &'static str,
    },
    /// A buffer or image lives in another file.
    #[error(
        "{what} refers to the external file \"{uri}\": the asset is not self-contained (fix: \
         export it as glTF Binary with everything embedded, as Blender's \"glTF Binary (.glb)\" \
         does, or pack it with `npx @gltf-transform/cli copy in.gltf out.glb`)"
    )]
    ExternalUri {
        /// Which object, like `images[0]`.
        what: String,
        /// The URI.
        uri: String,
    },
    /// Data that cannot be read as the JSON describes it.
    #[error("{path}: {problem}")]
    Data {
        /// Where, as a JSON path.
        path: String,
        /// What is wrong.
        problem: String,
    },
    /// A Draco stream that cannot be decoded.
    #[error("{path}: KHR_draco_mesh_compression: {problem} (fix: {fix})", fix = draco::DRACO_FIX)]
    Draco {
        /// Where, as a JSON path.
        path: String,
        /// What is wrong.
        problem: String,
    },
    /// Nothing to place.
    #[error(
        "no triangle mesh: {detail} (expected a node of the scene placing a mesh of triangles: \
         export the object's mesh, not only empties, lights or cameras)"
    )]
    NoMesh {
        /// Why there is none.
        detail: String,
    },
}

impl GlbError {
    /// A short code for the kind of problem: the validator's code for container problems
    /// (`GLB_LENGTH_MISMATCH`, ...; a GLB of version 1 is `GLB_INVALID_VERSION`, bytes that
    /// are not a GLB `GLB_INVALID_MAGIC`), else one of `not_glb`, `gltf1`, `json`, `version`,
    /// `invalid_gltf`, `unsupported_extension`, `external_uri`, `data`, `draco`, `no_mesh`.
    pub fn code(&self) -> &'static str {
        match self {
            Self::NotGlb { code, .. } => code,
            Self::Container { code, .. } => code,
            Self::Gltf1 => "gltf1",
            Self::Json { .. } => "json",
            Self::Version { .. } => "version",
            Self::Invalid { .. } => "invalid_gltf",
            Self::UnsupportedExtension { .. } => "unsupported_extension",
            Self::ExternalUri { .. } => "external_uri",
            Self::Data { .. } => "data",
            Self::Draco { .. } => "draco",
            Self::NoMesh { .. } => "no_mesh",
        }
    }
}

fn summarize(problems: &[String]) -> String {
    const SHOWN: usize = 5;
    let mut text = problems
        .iter()
        .take(SHOWN)
        .cloned()
        .collect::<Vec<_>>()
        .join("; ");
    if problems.len() > SHOWN {
        text.push_str(&format!("; and {} more", problems.len() - SHOWN));
    }
    text
}

/// A material of the asset.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MaterialInfo {
    /// Its name, or `material_<index>` when it has none.
    pub name: String,
    /// Whether it has a base colour texture.
    pub textured: bool,
}

/// What a GLB holds besides its triangles.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct GlbInfo {
    /// `asset.generator`.
    pub generator: Option<String>,
    /// Nodes in the file.
    pub nodes: usize,
    /// Nodes of the scene that place a mesh.
    pub mesh_instances: usize,
    /// Triangle primitives placed (a primitive of a mesh used twice counts twice).
    pub primitives: usize,
    /// Point and line primitives skipped.
    pub skipped_primitives: usize,
    /// Materials.
    pub materials: Vec<MaterialInfo>,
    /// Textures.
    pub textures: usize,
    /// The MIME type of each image (`image/png`, ...).
    pub image_mime_types: Vec<String>,
    /// `extensionsUsed`.
    pub extensions_used: Vec<String>,
    /// `extensionsRequired`.
    pub extensions_required: Vec<String>,
    /// Whether some geometry was Draco-compressed.
    pub draco: bool,
    /// Whether some mesh instance is skinned.
    pub skinned: bool,
    /// Whether some mesh has morph targets.
    pub morph_targets: bool,
}

/// A GLB's triangles in the glTF scene frame: metres, +Y up, the asset's front toward +Z.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct GlbMesh {
    /// Vertex positions of every placed triangle primitive, in metres.
    pub positions_m: Vec<[f64; 3]>,
    /// Triangles as indices into `positions_m`.
    pub triangles: Vec<[u32; 3]>,
    /// What else the file holds.
    pub info: GlbInfo,
    /// Things that do not stop the asset from being used (validator warnings, skipped
    /// primitives, unusual transforms).
    pub warnings: Vec<String>,
}

/// Extensions that may be required without changing the geometry mesa reads (materials,
/// texture formats, lights, metadata): the asset is read, the requirement is recorded.
const GEOMETRY_NEUTRAL: &[&str] = &[
    "KHR_lights_punctual",
    "KHR_texture_transform",
    "KHR_texture_basisu",
    "EXT_texture_webp",
    "EXT_texture_avif",
    "MSFT_texture_dds",
    "KHR_xmp_json_ld",
    "KHR_materials_variants",
];

fn required_extension_fix(extension: &str) -> Option<&'static str> {
    match extension {
        "KHR_draco_mesh_compression" | "KHR_mesh_quantization" => None,
        e if e.starts_with("KHR_materials_") => None,
        e if GEOMETRY_NEUTRAL.contains(&e) => None,
        "EXT_meshopt_compression" | "KHR_meshopt_compression" => Some(MESHOPT_FIX),
        "EXT_mesh_gpu_instancing" => Some(
            "realise the instances before exporting (Blender: Object > Apply > Make Instances \
             Real) or export without GPU instancing",
        ),
        _ => Some("re-export the asset without this extension"),
    }
}

/// A GLB file opened and checked: its container split, its glTF JSON parsed and validated,
/// its required extensions judged, its buffers resolved. The parts are read on demand.
pub struct GlbDocument<'a> {
    root: Root,
    buffers: Buffers<'a>,
    warnings: Vec<String>,
}

impl std::fmt::Debug for GlbDocument<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GlbDocument")
            .field("nodes", &self.root.nodes.len())
            .field("meshes", &self.root.meshes.len())
            .finish()
    }
}

/// Opens a GLB file: everything [`read_glb`] checks before it reads geometry.
pub fn open_glb(bytes: &[u8]) -> Result<GlbDocument<'_>, GlbError> {
    let mut warnings = Vec::new();
    let chunks = container::split(bytes, &mut warnings)?;
    let root = parse_root(chunks.json, &mut warnings)?;
    validate(&root, &mut warnings)?;
    for extension in &root.extensions_required {
        if let Some(fix) = required_extension_fix(extension) {
            return Err(GlbError::UnsupportedExtension {
                extension: extension.clone(),
                fix,
            });
        }
    }
    if root
        .extensions_used
        .iter()
        .any(|e| e == "EXT_mesh_gpu_instancing")
    {
        warnings.push(
            "EXT_mesh_gpu_instancing is used but not required: the instances it adds are \
             ignored, the base meshes are read"
                .to_owned(),
        );
    }
    let buffers = resolve_buffers(&root, chunks.bin)?;
    Ok(GlbDocument {
        root,
        buffers,
        warnings,
    })
}

/// One triangle primitive placed by a node of the scene, in the glTF scene frame.
#[derive(Debug, Clone, PartialEq)]
pub struct PlacedPrimitive {
    /// The node placing it.
    pub node: usize,
    /// The mesh and the primitive within it.
    pub mesh: usize,
    /// Index of the primitive in the mesh.
    pub primitive: usize,
    /// Vertex positions in the scene frame, metres (morphed and skinned as a viewer shows
    /// them).
    pub positions_m: Vec<[f64; 3]>,
    /// Triangles as indices into `positions_m`.
    pub triangles: Vec<[u32; 3]>,
    /// Unit normals in the scene frame, one per vertex, when attributes were asked for and
    /// the primitive has them (never for skinned or morphed primitives, whose normals a
    /// reader recomputes).
    pub normals: Option<Vec<[f64; 3]>>,
    /// `TEXCOORD_0`, one per vertex, when attributes were asked for and the primitive has it.
    pub uvs: Option<Vec<[f64; 2]>>,
    /// The primitive's material.
    pub material: Option<usize>,
    /// Whether the node's world transform mirrors (negative determinant): its triangles'
    /// front faces are then the other side (glTF 2.0 §3.7.4), as `positions_m` are placed.
    pub mirrored: bool,
}

/// One triangle primitive of a mesh, in the mesh's own frame.
#[derive(Debug, Clone, PartialEq)]
pub struct LocalPrimitive {
    /// Vertex positions, metres.
    pub positions: Vec<[f64; 3]>,
    /// Triangles as indices into `positions`.
    pub triangles: Vec<[u32; 3]>,
    /// NORMAL, when attributes were asked for and present.
    pub normals: Option<Vec<[f64; 3]>>,
    /// TEXCOORD_0, when attributes were asked for and present.
    pub uvs: Option<Vec<[f64; 2]>>,
    /// The primitive's material.
    pub material: Option<usize>,
}

/// Every triangle primitive of a GLB's scene, with what else the file holds.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PlacedScene {
    /// The primitives, in node order (depth first from the scene's roots).
    pub primitives: Vec<PlacedPrimitive>,
    /// What else the file holds.
    pub info: GlbInfo,
    /// What does not stop the file from being used.
    pub warnings: Vec<String>,
}

impl<'a> GlbDocument<'a> {
    /// The glTF document.
    pub fn root(&self) -> &Root {
        &self.root
    }

    /// What opening the file noticed (validator warnings and infos).
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// Every node's world matrix (column vectors, glTF scene frame), `None` for nodes outside
    /// the default scene. A node reached twice (a cycle, two parents) is an error.
    pub fn world_matrices(&self) -> Result<Vec<Option<Matrix4<f64>>>, GlbError> {
        let mut warnings = Vec::new();
        Ok(scene_instances(&self.root, &mut warnings)?.world)
    }

    /// The triangle primitives of a mesh in its own frame (before any node transform, morph
    /// or skin), Draco decoded; with `attributes`, also normals and texture coordinates.
    pub fn mesh_primitives(
        &self,
        mesh: usize,
        attributes: bool,
    ) -> Result<Vec<LocalPrimitive>, GlbError> {
        let primitives = &self
            .root
            .meshes
            .get(mesh)
            .ok_or_else(|| data_error(format!("meshes[{mesh}]"), "does not exist"))?
            .primitives;
        let reader = Reader {
            root: &self.root,
            buffers: &self.buffers,
            world: &[],
            surface: false,
            attributes,
        };
        let mut info = GlbInfo::default();
        let mut warnings = Vec::new();
        let mut out = Vec::new();
        for (p, primitive) in primitives.iter().enumerate() {
            let mode = match primitive.mode {
                Checked::Valid(mode) => mode,
                Checked::Invalid => {
                    return Err(data_error(
                        format!("meshes[{mesh}].primitives[{p}]"),
                        "invalid mode",
                    ))
                }
            };
            if !matches!(
                mode,
                Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
            ) {
                continue;
            }
            let geometry = reader.primitive(mesh, p, mode, &mut info, &mut warnings)?;
            out.push(LocalPrimitive {
                positions: geometry.positions,
                triangles: geometry.triangles,
                normals: geometry.normals,
                uvs: geometry.uvs,
                material: primitive.material.map(|m| m.value()),
            });
        }
        Ok(out)
    }

    /// The local vertex positions of every triangle primitive of a mesh (its own frame, before
    /// any node transform, morph or skin), Draco decoded, concatenated.
    pub fn mesh_positions(&self, mesh: usize) -> Result<Vec<[f64; 3]>, GlbError> {
        Ok(self
            .mesh_primitives(mesh, false)?
            .into_iter()
            .flat_map(|p| p.positions)
            .collect())
    }

    /// The bytes and MIME type of image `index` (from its buffer view or data URI).
    pub fn image(&self, index: usize) -> Result<(Cow<'_, [u8]>, Option<String>), GlbError> {
        let path = format!("images[{index}]");
        let image = self
            .root
            .images
            .get(index)
            .ok_or_else(|| data_error(&path, "does not exist"))?;
        let mime = image.mime_type.as_ref().map(|m| m.0.clone());
        if let Some(view) = image.buffer_view {
            let (bytes, _) = accessor::view_bytes(&self.root, &self.buffers, view.value(), &path)?;
            return Ok((Cow::Borrowed(bytes), mime));
        }
        match &image.uri {
            Some(uri) if uri.starts_with("data:") => {
                let bytes = data_uri(uri).ok_or_else(|| {
                    data_error(&path, "INVALID_URI: the data URI cannot be decoded")
                })?;
                let mime = mime.or_else(|| {
                    uri.strip_prefix("data:")
                        .and_then(|r| r.split([';', ',']).next())
                        .map(str::to_owned)
                });
                Ok((Cow::Owned(bytes), mime))
            }
            Some(uri) => Err(GlbError::ExternalUri {
                what: path,
                uri: uri.clone(),
            }),
            None => Err(data_error(&path, "has neither a bufferView nor a uri")),
        }
    }

    /// Every triangle primitive the default scene places, transformed to the scene frame;
    /// with `attributes`, also normals and texture coordinates. An error when the file has
    /// no triangle.
    pub fn placed_primitives(&self, attributes: bool) -> Result<PlacedScene, GlbError> {
        let root = &self.root;
        let mut warnings = self.warnings.clone();
        let mut info = GlbInfo {
            generator: root.asset.generator.clone(),
            nodes: root.nodes.len(),
            textures: root.textures.len(),
            extensions_used: root.extensions_used.clone(),
            extensions_required: root.extensions_required.clone(),
            ..GlbInfo::default()
        };
        info.image_mime_types = images(root)?;
        info.materials = root
            .materials
            .iter()
            .enumerate()
            .map(|(i, m)| MaterialInfo {
                name: m.name.clone().unwrap_or_else(|| format!("material_{i}")),
                textured: m.pbr_metallic_roughness.base_color_texture.is_some(),
            })
            .collect();
        let scene = scene_instances(root, &mut warnings)?;
        let instances = &scene.instances;
        let mut unused_meshes: BTreeSet<usize> = (0..root.meshes.len()).collect();
        let mut cache = HashMap::new();
        let reader = Reader {
            root,
            buffers: &self.buffers,
            world: &scene.world,
            surface: false,
            attributes,
        };
        let mut primitives = Vec::new();
        for instance in instances {
            unused_meshes.remove(&instance.mesh);
            info.mesh_instances += 1;
            reader.add_instance_placed(
                instance,
                &mut cache,
                &mut primitives,
                &mut info,
                &mut warnings,
            )?;
        }
        check_placed(
            root,
            instances.is_empty(),
            primitives.iter().all(|p| p.triangles.is_empty()),
            &unused_meshes,
            &info,
            &mut warnings,
        )?;
        Ok(PlacedScene {
            primitives,
            info,
            warnings,
        })
    }
}

/// Reads a GLB file's triangles.
pub fn read_glb(bytes: &[u8]) -> Result<GlbMesh, GlbError> {
    read_glb_impl(bytes, false).map(|(mesh, _)| mesh)
}

/// Reads a GLB file's triangles and what a renderer needs to draw them: per-vertex normals,
/// texture coordinates and colours, the material of each primitive, and the embedded images
/// (see [`GlbSurface`]). The triangles are exactly those of [`read_glb`].
pub fn read_glb_surface(bytes: &[u8]) -> Result<(GlbMesh, GlbSurface), GlbError> {
    let (mesh, surface) = read_glb_impl(bytes, true)?;
    Ok((mesh, surface.unwrap_or_default()))
}

fn read_glb_impl(
    bytes: &[u8],
    want_surface: bool,
) -> Result<(GlbMesh, Option<GlbSurface>), GlbError> {
    let mut warnings = Vec::new();
    let chunks = container::split(bytes, &mut warnings)?;
    let root = parse_root(chunks.json, &mut warnings)?;
    validate(&root, &mut warnings)?;
    let mut info = GlbInfo {
        generator: root.asset.generator.clone(),
        nodes: root.nodes.len(),
        textures: root.textures.len(),
        extensions_used: root.extensions_used.clone(),
        extensions_required: root.extensions_required.clone(),
        ..GlbInfo::default()
    };
    for extension in &root.extensions_required {
        if let Some(fix) = required_extension_fix(extension) {
            return Err(GlbError::UnsupportedExtension {
                extension: extension.clone(),
                fix,
            });
        }
    }
    if root
        .extensions_used
        .iter()
        .any(|e| e == "EXT_mesh_gpu_instancing")
    {
        warnings.push(
            "EXT_mesh_gpu_instancing is used but not required: the instances it adds are \
             ignored, the base meshes are read"
                .to_owned(),
        );
    }
    let buffers = resolve_buffers(&root, chunks.bin)?;
    info.image_mime_types = images(&root)?;
    info.materials = root
        .materials
        .iter()
        .enumerate()
        .map(|(i, m)| MaterialInfo {
            name: m.name.clone().unwrap_or_else(|| format!("material_{i}")),
            textured: m.pbr_metallic_roughness.base_color_texture.is_some(),
        })
        .collect();

    let scene = scene_instances(&root, &mut warnings)?;
    let instances = &scene.instances;
    let mut mesh = GlbMesh::default();
    let mut surface = if want_surface {
        Some(surface::surface_materials(&root, &buffers, &mut warnings))
    } else {
        None
    };
    let mut unused_meshes: BTreeSet<usize> = (0..root.meshes.len()).collect();
    let mut cache = HashMap::new();
    for instance in instances {
        unused_meshes.remove(&instance.mesh);
        info.mesh_instances += 1;
        let reader = Reader {
            root: &root,
            buffers: &buffers,
            world: &scene.world,
            surface: want_surface,
            attributes: false,
        };
        reader.add_instance(
            instance,
            &mut cache,
            &mut mesh,
            surface.as_mut(),
            &mut info,
            &mut warnings,
        )?;
    }
    check_placed(
        &root,
        instances.is_empty(),
        mesh.triangles.is_empty(),
        &unused_meshes,
        &info,
        &mut warnings,
    )?;
    mesh.info = info;
    mesh.warnings = warnings;
    Ok((mesh, surface))
}

/// What both readers conclude once every instance is read: no triangles at all is an error
/// that says why (no mesh, no node placing one, only points or lines, empty primitives);
/// meshes no node places and point or line primitives are warnings.
fn check_placed(
    root: &Root,
    no_instances: bool,
    no_triangles: bool,
    unused_meshes: &BTreeSet<usize>,
    info: &GlbInfo,
    warnings: &mut Vec<String>,
) -> Result<(), GlbError> {
    if no_triangles {
        let detail = if root.meshes.is_empty() {
            "the file has no mesh".to_owned()
        } else if no_instances {
            format!(
                "no node of the scene places any of its {} meshes",
                root.meshes.len()
            )
        } else if info.skipped_primitives > 0 {
            format!(
                "its {} primitives are points or lines, not triangles",
                info.skipped_primitives
            )
        } else {
            "its primitives have no triangles".to_owned()
        };
        return Err(GlbError::NoMesh { detail });
    }
    if !unused_meshes.is_empty() {
        warnings.push(format!(
            "{} of {} meshes are not placed by any node of the scene and are ignored",
            unused_meshes.len(),
            root.meshes.len()
        ));
    }
    if info.skipped_primitives > 0 {
        warnings.push(format!(
            "{} point or line primitives are ignored",
            info.skipped_primitives
        ));
    }
    Ok(())
}

fn parse_root(json: &[u8], warnings: &mut Vec<String>) -> Result<Root, GlbError> {
    // Some writers pad the JSON chunk with NULs instead of spaces.
    let end = json
        .iter()
        .rposition(|b| !matches!(b, b' ' | b'\t' | b'\r' | b'\n' | 0))
        .map_or(0, |i| i + 1);
    if json[end..].contains(&0) {
        warnings.push("the JSON chunk is padded with NUL bytes (expected spaces)".to_owned());
    }
    let text = &json[..end];
    // The usual case, a glTF 2.0 document, is read straight into its types (a third of the
    // time of reading a small asset went into building a `Value` first); anything that fails
    // that, or is another version, takes the path through a `Value`, which names the problem
    // (and reads what it always read: a repeated key's last value, for one).
    if let Ok(root) = serde_json::from_slice::<Root>(text) {
        let asset = &root.asset;
        if asset.version.starts_with("2.")
            && asset.min_version.as_deref().is_none_or(|min| min == "2.0")
        {
            return Ok(root);
        }
    }
    let value: Value = serde_json::from_slice(text).map_err(|e| GlbError::Json {
        problem: format!("INVALID_JSON: {e}"),
    })?;
    let version = value
        .get("asset")
        .and_then(|a| a.get("version"))
        .ok_or_else(|| GlbError::Json {
            problem: "UNDEFINED_PROPERTY: $.asset.version is missing".to_owned(),
        })?;
    let version = match version {
        Value::String(s) => s.clone(),
        other => other.to_string(),
    };
    if version.starts_with("1.") || version == "1" {
        return Err(GlbError::Gltf1);
    }
    if !version.starts_with("2.") {
        return Err(GlbError::Version { version });
    }
    if let Some(min) = value
        .get("asset")
        .and_then(|a| a.get("minVersion"))
        .and_then(Value::as_str)
    {
        if min != "2.0" {
            return Err(GlbError::Version {
                version: format!("{version} (minVersion {min})"),
            });
        }
    }
    serde_json::from_value(value).map_err(|e| GlbError::Json {
        problem: e.to_string(),
    })
}

/// POSITION attributes that name no accessor: gltf-json's own validation indexes the accessor
/// list with them without a check (and panics), so they are caught first.
fn position_indices_out_of_range(root: &Root) -> Vec<String> {
    let mut problems = Vec::new();
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            if let Some(index) = primitive
                .attributes
                .get(&Checked::Valid(Semantic::Positions))
            {
                if index.value() >= root.accessors.len() {
                    problems.push(format!(
                        "meshes[{m}].primitives[{p}].attributes[\"POSITION\"]: Index out of \
                         range (accessor {} of {})",
                        index.value(),
                        root.accessors.len()
                    ));
                }
            }
        }
    }
    problems
}

/// The component types glTF 2.0 allows for an attribute mesa reads, as (type, normalized)
/// pairs: the core table (§3.7.2.1), widened by `KHR_mesh_quantization` when the file uses it.
fn allowed_formats(
    semantic: &Semantic,
    quantized: bool,
) -> Option<&'static [(ComponentType, bool)]> {
    use ComponentType::{F32, I16, I8, U16, U8};
    Some(match (semantic, quantized) {
        (Semantic::Positions, false) | (Semantic::Normals, false) => &[(F32, false)],
        (Semantic::Positions, true) => &[
            (F32, false),
            (I8, false),
            (I8, true),
            (U8, false),
            (U8, true),
            (I16, false),
            (I16, true),
            (U16, false),
            (U16, true),
        ],
        (Semantic::Normals, true) => &[(F32, false), (I8, true), (I16, true)],
        (Semantic::TexCoords(_), false) => &[(F32, false), (U8, true), (U16, true)],
        (Semantic::TexCoords(_), true) => &[
            (F32, false),
            (I8, false),
            (I8, true),
            (U8, false),
            (U8, true),
            (I16, false),
            (I16, true),
            (U16, false),
            (U16, true),
        ],
        _ => return None,
    })
}

fn format_name(kind: ComponentType, normalized: bool) -> String {
    let name = match kind {
        ComponentType::I8 => "BYTE",
        ComponentType::U8 => "UNSIGNED_BYTE",
        ComponentType::I16 => "SHORT",
        ComponentType::U16 => "UNSIGNED_SHORT",
        ComponentType::U32 => "UNSIGNED_INT",
        ComponentType::F32 => "FLOAT",
    };
    if normalized {
        format!("normalized {name}")
    } else {
        name.to_owned()
    }
}

/// POSITION, NORMAL and TEXCOORD_n accessors of a component type glTF 2.0 does not allow for
/// them (the validator's MESH_PRIMITIVE_ATTRIBUTES_ACCESSOR_INVALID_FORMAT): read as the
/// integers they hold, they would give absurd sizes (an UNSIGNED_BYTE position is up to 255
/// m), so they are errors that say which extension the data would need.
fn attribute_formats(root: &Root) -> Result<(), GlbError> {
    let quantized = root
        .extensions_used
        .iter()
        .any(|e| e == "KHR_mesh_quantization");
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            for (semantic, index) in &primitive.attributes {
                let Checked::Valid(semantic) = semantic else {
                    continue;
                };
                let Some(allowed) = allowed_formats(semantic, quantized) else {
                    continue;
                };
                let Some(accessor) = root.accessors.get(index.value()) else {
                    continue;
                };
                let Checked::Valid(kind) = accessor.component_type else {
                    continue;
                };
                let format = (kind.0, accessor.normalized);
                if allowed.contains(&format) {
                    continue;
                }
                let name = semantic.to_string();
                let allowed_names: Vec<String> =
                    allowed.iter().map(|(k, n)| format_name(*k, *n)).collect();
                let fix = if quantized
                    || allowed_formats(semantic, true).is_some_and(|a| !a.contains(&format))
                {
                    format!(
                        "re-export the mesh with {} {name} data",
                        allowed_names.join(" or ")
                    )
                } else {
                    format!(
                        "re-export the mesh with FLOAT {name} data; if the data is quantized on \
                         purpose, list KHR_mesh_quantization in extensionsUsed and \
                         extensionsRequired and put the dequantization in the node transform \
                         (`gltf-transform quantize` does both)"
                    )
                };
                return Err(data_error(
                    format!(
                        "meshes[{m}].primitives[{p}].attributes.{name} (accessor {})",
                        index.value()
                    ),
                    format!(
                        "MESH_PRIMITIVE_ATTRIBUTES_ACCESSOR_INVALID_FORMAT: componentType {} \
                         {} (expected {}{}) (fix: {fix})",
                        format_name(kind.0, accessor.normalized),
                        if quantized {
                            "is not allowed for it even with KHR_mesh_quantization"
                        } else {
                            "is not allowed for it without KHR_mesh_quantization"
                        },
                        allowed_names.join(", "),
                        if quantized { "" } else { ", as glTF 2.0 says" }
                    ),
                ));
            }
        }
    }
    Ok(())
}

fn validate(root: &Root, warnings: &mut Vec<String>) -> Result<(), GlbError> {
    let out_of_range = position_indices_out_of_range(root);
    if !out_of_range.is_empty() {
        return Err(GlbError::Invalid {
            problems: out_of_range,
        });
    }
    let mut problems = Vec::new();
    let mut without_bounds = 0;
    root.validate(root, gltf_json::Path::new, &mut |path, error| {
        let path = path();
        let path = path.as_str();
        // Required extensions are judged by mesa's own list (see `read_glb`).
        let required_extension = path.starts_with("extensionsRequired")
            && error == gltf_json::validation::Error::Unsupported;
        // glTF 2.0 allows an accessor without bufferView: it reads as zeros, unless sparse
        // values or an extension (KHR_draco_mesh_compression) provide the data.
        let accessor_without_view = path.starts_with("accessors[")
            && path.ends_with("].bufferView")
            && error == gltf_json::validation::Error::Missing;
        // POSITION accessors must state min and max; mesa computes bounds from the vertices,
        // so their absence only earns a warning.
        let position_bounds = path.contains(".attributes[\"POSITION\"].m")
            && (path.ends_with(".min") || path.ends_with(".max"))
            && error == gltf_json::validation::Error::Missing;
        if position_bounds {
            without_bounds += 1;
        } else if !(required_extension || accessor_without_view) {
            problems.push(format!("{path}: {error}"));
        }
    });
    if without_bounds > 0 {
        warnings.push(format!(
            "{} POSITION accessors lack min/max (required by glTF 2.0; bounds are computed \
             from the vertices)",
            without_bounds / 2
        ));
    }
    if problems.is_empty() {
        attribute_formats(root)
    } else {
        Err(GlbError::Invalid { problems })
    }
}

/// Decodes a `data:` URI (base64 or percent-encoded).
fn data_uri(uri: &str) -> Option<Vec<u8>> {
    let rest = uri.strip_prefix("data:")?;
    let (header, payload) = rest.split_once(',')?;
    if header.ends_with(";base64") {
        base64::engine::general_purpose::STANDARD
            .decode(payload.trim())
            .ok()
    } else {
        let bytes = payload.as_bytes();
        let mut out = Vec::with_capacity(bytes.len());
        let mut i = 0;
        while i < bytes.len() {
            if bytes[i] == b'%' && i + 2 < bytes.len() {
                let hex = std::str::from_utf8(&bytes[i + 1..i + 3]).ok()?;
                out.push(u8::from_str_radix(hex, 16).ok()?);
                i += 3;
            } else {
                out.push(bytes[i]);
                i += 1;
            }
        }
        Some(out)
    }
}

fn resolve_buffers<'a>(root: &Root, bin: Option<&'a [u8]>) -> Result<Buffers<'a>, GlbError> {
    let mut data = Vec::with_capacity(root.buffers.len());
    for (i, buffer) in root.buffers.iter().enumerate() {
        let bytes: Option<Cow<'a, [u8]>> = match &buffer.uri {
            None if i == 0 => Some(Cow::Borrowed(bin.ok_or_else(|| {
                GlbError::Data {
                    path: "buffers[0]".to_owned(),
                    problem: "BUFFER_MISSING_GLB_DATA: the buffer has no uri but the file has no \
                          BIN chunk"
                        .to_owned(),
                }
            })?)),
            None => None,
            Some(uri) if uri.starts_with("data:") => {
                Some(Cow::Owned(data_uri(uri).ok_or_else(|| GlbError::Data {
                    path: format!("buffers[{i}].uri"),
                    problem: "INVALID_URI: the data URI cannot be decoded".to_owned(),
                })?))
            }
            Some(uri) => {
                return Err(GlbError::ExternalUri {
                    what: format!("buffers[{i}]"),
                    uri: uri.clone(),
                })
            }
        };
        if let Some(bytes) = &bytes {
            let declared = buffer.byte_length.0 as usize;
            if bytes.len() < declared {
                return Err(GlbError::Data {
                    path: format!("buffers[{i}]"),
                    problem: format!(
                        "byteLength is {declared} but only {} bytes are present",
                        bytes.len()
                    ),
                });
            }
        }
        data.push(bytes);
    }
    Ok(Buffers { data })
}

fn images(root: &Root) -> Result<Vec<String>, GlbError> {
    root.images
        .iter()
        .enumerate()
        .map(|(i, image)| {
            if let Some(uri) = &image.uri {
                if !uri.starts_with("data:") {
                    return Err(GlbError::ExternalUri {
                        what: format!("images[{i}]"),
                        uri: uri.clone(),
                    });
                }
            }
            let from_uri = image.uri.as_deref().and_then(|u| {
                u.strip_prefix("data:")
                    .and_then(|r| r.split([';', ',']).next())
                    .map(str::to_owned)
            });
            Ok(image
                .mime_type
                .as_ref()
                .map(|m| m.0.clone())
                .or(from_uri)
                .unwrap_or_else(|| "unknown".to_owned()))
        })
        .collect()
}

/// A node of the scene that places a mesh.
struct Instance {
    node: usize,
    mesh: usize,
    /// The node's world matrix (glTF scene frame).
    world: Matrix4<f64>,
}

/// The nodes of the scene: the mesh instances and every node's world matrix (`None` for nodes
/// outside the scene).
struct SceneNodes {
    instances: Vec<Instance>,
    world: Vec<Option<Matrix4<f64>>>,
}

fn local_matrix(node: &gltf_json::scene::Node) -> Matrix4<f64> {
    if let Some(m) = node.matrix {
        // Column-major, as glTF stores it.
        return Matrix4::from_iterator(m.iter().map(|v| f64::from(*v)));
    }
    let t = node.translation.unwrap_or([0.0; 3]).map(f64::from);
    let r = node
        .rotation
        .map_or([0.0, 0.0, 0.0, 1.0], |q| q.0.map(f64::from));
    let s = node.scale.unwrap_or([1.0; 3]).map(f64::from);
    let rotation = UnitQuaternion::from_quaternion(Quaternion::new(r[3], r[0], r[1], r[2]));
    Matrix4::new_translation(&Vector3::from(t))
        * rotation.to_homogeneous()
        * Matrix4::new_nonuniform_scaling(&Vector3::from(s))
}

fn scene_instances(root: &Root, warnings: &mut Vec<String>) -> Result<SceneNodes, GlbError> {
    let scene = root
        .scene
        .map(|s| s.value())
        .or((!root.scenes.is_empty()).then_some(0));
    let roots: Vec<usize> = match scene {
        // Indices were validated: the scene and its nodes exist.
        Some(scene) => root.scenes[scene].nodes.iter().map(|n| n.value()).collect(),
        None => {
            let mut has_parent = vec![false; root.nodes.len()];
            for node in &root.nodes {
                for child in node.children.iter().flatten() {
                    has_parent[child.value()] = true;
                }
            }
            let roots: Vec<usize> = (0..root.nodes.len()).filter(|i| !has_parent[*i]).collect();
            if !roots.is_empty() {
                warnings.push(
                    "the file has no scene: every node without a parent is taken as a root"
                        .to_owned(),
                );
            }
            roots
        }
    };
    let mut world: Vec<Option<Matrix4<f64>>> = vec![None; root.nodes.len()];
    let mut instances = Vec::new();
    let mut stack: Vec<(usize, Matrix4<f64>)> = roots
        .iter()
        .rev()
        .map(|n| (*n, Matrix4::identity()))
        .collect();
    while let Some((node_index, parent)) = stack.pop() {
        if world[node_index].is_some() {
            // A node reached twice: a cycle, two parents, or a root listed twice.
            return Err(GlbError::Invalid {
                problems: vec![format!(
                    "nodes[{node_index}]: the node is reached twice from the scene's roots (a \
                     cycle in the hierarchy, or two parents)"
                )],
            });
        }
        let node = &root.nodes[node_index];
        if let Some(q) = node.rotation.filter(|_| node.matrix.is_none()) {
            // Normalising a zero quaternion divides by zero: say so rather than report the
            // NaN it would leave in the transform.
            let norm =
                q.0.iter()
                    .map(|c| f64::from(*c).powi(2))
                    .sum::<f64>()
                    .sqrt();
            if norm.is_finite() && norm < 1e-12 {
                return Err(GlbError::Data {
                    path: format!("nodes[{node_index}].rotation"),
                    problem: format!(
                        "is the zero quaternion {:?}, not a rotation (expected a unit \
                         quaternion [x, y, z, w], e.g. [0, 0, 0, 1] for none)",
                        q.0
                    ),
                });
            }
        }
        let matrix = parent * local_matrix(node);
        if matrix.iter().any(|v| !v.is_finite()) {
            return Err(GlbError::Data {
                path: format!("nodes[{node_index}]"),
                problem: "the transform has a non-finite value".to_owned(),
            });
        }
        world[node_index] = Some(matrix);
        if let Some(mesh) = node.mesh {
            instances.push(Instance {
                node: node_index,
                mesh: mesh.value(),
                world: matrix,
            });
        }
        for child in node.children.iter().flatten().rev() {
            stack.push((child.value(), matrix));
        }
    }
    Ok(SceneNodes { instances, world })
}

/// One primitive's geometry in its own frame, before morphing, skinning or placement.
struct Primitive {
    positions: Vec<[f64; 3]>,
    triangles: Vec<[u32; 3]>,
    /// Surface attributes, read only for [`read_glb_surface`].
    attributes: surface::Attributes,
    /// NORMAL, when the document API asks for attributes and the primitive has them.
    normals: Option<Vec<[f64; 3]>>,
    /// TEXCOORD_0, likewise.
    uvs: Option<Vec<[f64; 2]>>,
}

struct Reader<'a, 'b> {
    root: &'a Root,
    buffers: &'a Buffers<'b>,
    world: &'a [Option<Matrix4<f64>>],
    /// Whether to read the surface attributes too.
    surface: bool,
    /// Whether to read NORMAL and TEXCOORD_0 for the document API ([`GlbDocument`]).
    attributes: bool,
}

fn data_error(path: impl Into<String>, problem: impl Into<String>) -> GlbError {
    GlbError::Data {
        path: path.into(),
        problem: problem.into(),
    }
}

fn vec3s(values: Vec<f64>, width: usize, path: &str) -> Result<Vec<[f64; 3]>, GlbError> {
    if width != 3 {
        return Err(data_error(
            path,
            format!("has {width} components per element (expected VEC3)"),
        ));
    }
    Ok(values.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
}

/// Triangles from the index list of a primitive of `mode`.
fn triangles_of(
    indices: &[u32],
    mode: Mode,
    path: &str,
    warnings: &mut Vec<String>,
) -> Vec<[u32; 3]> {
    let n = indices.len();
    match mode {
        // glTF 2.0 §3.7.2.1: triangle i is (v_i, v_{i+1+i%2}, v_{i+2-i%2}).
        Mode::TriangleStrip => (0..n.saturating_sub(2))
            .map(|i| [indices[i], indices[i + 1 + i % 2], indices[i + 2 - i % 2]])
            .collect(),
        Mode::TriangleFan => (1..n.saturating_sub(1))
            .map(|i| [indices[0], indices[i], indices[i + 1]])
            .collect(),
        _ => {
            if n % 3 != 0 {
                warnings.push(format!(
                    "{path}: {n} indices is not a multiple of 3: the last {} are ignored",
                    n % 3
                ));
            }
            indices
                .chunks_exact(3)
                .map(|c| [c[0], c[1], c[2]])
                .collect()
        }
    }
}

impl Reader<'_, '_> {
    fn attribute(
        &self,
        primitive: &gltf_json::mesh::Primitive,
        semantic: Semantic,
    ) -> Option<usize> {
        primitive
            .attributes
            .get(&Checked::Valid(semantic))
            .map(|a| a.value())
    }

    /// The geometry of a primitive, decoded once per file.
    /// A triangle primitive of a mesh, read once per file (`cache`); `None` for points and
    /// lines, which are counted in `info.skipped_primitives`.
    fn cached_primitive(
        &self,
        mesh_index: usize,
        primitive_index: usize,
        primitive: &gltf_json::mesh::Primitive,
        cache: &mut HashMap<(usize, usize), Rc<Primitive>>,
        info: &mut GlbInfo,
        warnings: &mut Vec<String>,
    ) -> Result<Option<Rc<Primitive>>, GlbError> {
        let mode = match primitive.mode {
            Checked::Valid(mode) => mode,
            Checked::Invalid => {
                return Err(data_error(
                    format!("meshes[{mesh_index}].primitives[{primitive_index}]"),
                    "invalid mode",
                ))
            }
        };
        if !matches!(
            mode,
            Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
        ) {
            info.skipped_primitives += 1;
            return Ok(None);
        }
        if let Some(g) = cache.get(&(mesh_index, primitive_index)) {
            return Ok(Some(Rc::clone(g)));
        }
        let g = Rc::new(self.primitive(mesh_index, primitive_index, mode, info, warnings)?);
        cache.insert((mesh_index, primitive_index), Rc::clone(&g));
        Ok(Some(g))
    }

    fn primitive(
        &self,
        mesh_index: usize,
        primitive_index: usize,
        mode: Mode,
        info: &mut GlbInfo,
        warnings: &mut Vec<String>,
    ) -> Result<Primitive, GlbError> {
        let primitive = &self.root.meshes[mesh_index].primitives[primitive_index];
        let path = format!("meshes[{mesh_index}].primitives[{primitive_index}]");
        let position = self
            .attribute(primitive, Semantic::Positions)
            .ok_or_else(|| data_error(&path, "has no POSITION attribute"))?;
        let draco = primitive
            .extensions
            .as_ref()
            .and_then(|e| e.others.get("KHR_draco_mesh_compression"));
        let has_fallback = self
            .root
            .accessors
            .get(position)
            .is_some_and(|a| a.buffer_view.is_some());
        let wanted = if self.surface {
            surface::wanted_attributes(self.root, primitive)
        } else {
            Vec::new()
        };
        let mut attributes = surface::Attributes::default();
        let (positions, triangles, normals, uvs) = match draco {
            // Uncompressed fallback data wins when a file carries both.
            Some(extension) if !has_fallback => {
                info.draco = true;
                let mut names: Vec<&str> = wanted.iter().map(String::as_str).collect();
                if self.attributes {
                    for name in ["NORMAL", "TEXCOORD_0"] {
                        if !names.contains(&name) {
                            names.push(name);
                        }
                    }
                }
                let normalized = |name: &str| {
                    primitive
                        .attributes
                        .iter()
                        .find(|(semantic, _)| semantic.to_string() == name)
                        .and_then(|(_, a)| self.root.accessors.get(a.value()))
                        .is_some_and(|a| a.normalized)
                };
                let decoded = draco::decode_primitive_with(
                    self.root,
                    self.buffers,
                    extension,
                    &path,
                    &names,
                    &normalized,
                )?;
                let points = decoded.positions.len();
                let (mut normals, mut uvs) = (None, None);
                if self.attributes {
                    for (name, values, width) in &decoded.extra {
                        match (name.as_str(), width) {
                            ("NORMAL", 3) => {
                                normals = Some(
                                    values.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
                                )
                            }
                            ("TEXCOORD_0", 2) => {
                                uvs = Some(values.chunks_exact(2).map(|c| [c[0], c[1]]).collect())
                            }
                            _ => {}
                        }
                    }
                }
                if self.surface {
                    attributes =
                        surface::Attributes::from_named(decoded.extra, points, &path, warnings);
                }
                (decoded.positions, decoded.triangles, normals, uvs)
            }
            _ => {
                let (values, width) = read_accessor(
                    self.root,
                    self.buffers,
                    position,
                    &format!("{path}.attributes.POSITION"),
                )?;
                let positions = vec3s(values, width, &format!("{path}.attributes.POSITION"))?;
                let indices = match primitive.indices {
                    Some(accessor) => read_indices(
                        self.root,
                        self.buffers,
                        accessor.value(),
                        &format!("{path}.indices"),
                    )?,
                    None => {
                        let n = u32::try_from(positions.len())
                            .map_err(|_| data_error(&path, "more than 2^32 vertices"))?;
                        (0..n).collect()
                    }
                };
                if let Some(bad) = indices.iter().find(|i| **i as usize >= positions.len()) {
                    return Err(data_error(
                        format!("{path}.indices"),
                        format!(
                            "index {bad} is out of range of the {} vertices",
                            positions.len()
                        ),
                    ));
                }
                let triangles = triangles_of(&indices, mode, &path, warnings);
                if !wanted.is_empty() {
                    attributes = self.surface_attributes(
                        primitive,
                        &wanted,
                        positions.len(),
                        &path,
                        warnings,
                    );
                }
                let (normals, uvs) = if self.attributes {
                    self.plain_attributes(primitive, &path, positions.len())?
                } else {
                    (None, None)
                };
                (positions, triangles, normals, uvs)
            }
        };
        if positions.iter().flatten().any(|v| !v.is_finite()) {
            return Err(data_error(
                format!("{path}.attributes.POSITION"),
                "has a non-finite value",
            ));
        }
        Ok(Primitive {
            positions,
            triangles,
            attributes,
            normals,
            uvs,
        })
    }

    /// NORMAL and TEXCOORD_0 of an uncompressed primitive, each when present and well formed
    /// (one element per vertex); a malformed one is an error.
    #[allow(clippy::type_complexity)]
    fn plain_attributes(
        &self,
        primitive: &gltf_json::mesh::Primitive,
        path: &str,
        vertices: usize,
    ) -> Result<(Option<Vec<[f64; 3]>>, Option<Vec<[f64; 2]>>), GlbError> {
        let normals = match self.attribute(primitive, Semantic::Normals) {
            Some(accessor) => {
                let here = format!("{path}.attributes.NORMAL");
                let (values, width) = read_accessor(self.root, self.buffers, accessor, &here)?;
                let normals = vec3s(values, width, &here)?;
                if normals.len() != vertices {
                    return Err(data_error(
                        here,
                        format!("has {} elements for {vertices} vertices", normals.len()),
                    ));
                }
                Some(normals)
            }
            None => None,
        };
        let uvs = match self.attribute(primitive, Semantic::TexCoords(0)) {
            Some(accessor) => {
                let here = format!("{path}.attributes.TEXCOORD_0");
                let (values, width) = read_accessor(self.root, self.buffers, accessor, &here)?;
                if width != 2 || values.len() != 2 * vertices {
                    return Err(data_error(
                        here,
                        format!(
                            "has {} values of width {width} for {vertices} vertices (expected \
                             VEC2, one per vertex)",
                            values.len()
                        ),
                    ));
                }
                Some(values.chunks_exact(2).map(|c| [c[0], c[1]]).collect())
            }
            None => None,
        };
        Ok((normals, uvs))
    }

    /// Adds the morph target displacements at `weights` to `positions`.
    fn morph(
        &self,
        primitive: &gltf_json::mesh::Primitive,
        path: &str,
        weights: &[f64],
        positions: &mut [[f64; 3]],
    ) -> Result<(), GlbError> {
        for (k, target) in primitive.targets.iter().flatten().enumerate() {
            let weight = weights.get(k).copied().unwrap_or(0.0);
            let Some(accessor) = target.positions else {
                continue;
            };
            if weight == 0.0 {
                continue;
            }
            let here = format!("{path}.targets[{k}].POSITION");
            let (values, width) = read_accessor(self.root, self.buffers, accessor.value(), &here)?;
            let offsets = vec3s(values, width, &here)?;
            if offsets.len() != positions.len() {
                return Err(data_error(
                    here,
                    format!(
                        "has {} elements for {} vertices",
                        offsets.len(),
                        positions.len()
                    ),
                ));
            }
            for (p, d) in positions.iter_mut().zip(&offsets) {
                for c in 0..3 {
                    p[c] += weight * d[c];
                }
            }
        }
        Ok(())
    }

    /// The joint matrices of a skin (joint world matrix × inverse bind matrix).
    fn joint_matrices(&self, skin_index: usize) -> Result<Vec<Matrix4<f64>>, GlbError> {
        let skin = &self.root.skins[skin_index];
        let path = format!("skins[{skin_index}]");
        let inverse_bind: Vec<Matrix4<f64>> = match skin.inverse_bind_matrices {
            Some(accessor) => {
                let here = format!("{path}.inverseBindMatrices");
                let (values, width) =
                    read_accessor(self.root, self.buffers, accessor.value(), &here)?;
                if width != 16 {
                    return Err(data_error(here, "is not a MAT4 accessor"));
                }
                values
                    .chunks_exact(16)
                    .map(|m| Matrix4::from_iterator(m.iter().copied()))
                    .collect()
            }
            None => vec![Matrix4::identity(); skin.joints.len()],
        };
        if inverse_bind.len() < skin.joints.len() {
            return Err(data_error(
                format!("{path}.inverseBindMatrices"),
                format!(
                    "has {} matrices for {} joints",
                    inverse_bind.len(),
                    skin.joints.len()
                ),
            ));
        }
        skin.joints
            .iter()
            .zip(&inverse_bind)
            .enumerate()
            .map(|(j, (joint, ibm))| {
                let world = self.world[joint.value()].ok_or_else(|| {
                    data_error(
                        format!("{path}.joints[{j}]"),
                        format!("node {} is not part of the scene", joint.value()),
                    )
                })?;
                Ok(world * ibm)
            })
            .collect()
    }

    /// Skins positions at the rest pose; `None` when the primitive has no joint weights.
    fn skin(
        &self,
        primitive: &gltf_json::mesh::Primitive,
        path: &str,
        joints: &[Matrix4<f64>],
        positions: &[[f64; 3]],
    ) -> Result<Option<Vec<[f64; 3]>>, GlbError> {
        let mut blended = vec![Matrix4::<f64>::zeros(); positions.len()];
        let mut any = false;
        for set in 0.. {
            let (Some(joint_accessor), Some(weight_accessor)) = (
                self.attribute(primitive, Semantic::Joints(set)),
                self.attribute(primitive, Semantic::Weights(set)),
            ) else {
                break;
            };
            any = true;
            let jpath = format!("{path}.attributes.JOINTS_{set}");
            let wpath = format!("{path}.attributes.WEIGHTS_{set}");
            let (js, jw) = read_accessor(self.root, self.buffers, joint_accessor, &jpath)?;
            let (ws, ww) = read_accessor(self.root, self.buffers, weight_accessor, &wpath)?;
            if jw != 4 || ww != 4 || js.len() != positions.len() * 4 || ws.len() != js.len() {
                return Err(data_error(
                    jpath,
                    "JOINTS and WEIGHTS must be VEC4 with one element per vertex",
                ));
            }
            for (v, m) in blended.iter_mut().enumerate() {
                for c in 0..4 {
                    let weight = ws[v * 4 + c];
                    if weight == 0.0 {
                        continue;
                    }
                    // Joint indices are small unsigned integers read exactly as f64.
                    let joint = js[v * 4 + c] as usize;
                    let matrix = joints.get(joint).ok_or_else(|| {
                        data_error(
                            &jpath,
                            format!("joint {joint} is out of range ({} joints)", joints.len()),
                        )
                    })?;
                    *m += matrix * weight;
                }
            }
        }
        if !any {
            return Ok(None);
        }
        Ok(Some(
            positions
                .iter()
                .zip(&blended)
                .map(|(p, m)| transform(m, p))
                .collect(),
        ))
    }

    fn add_instance(
        &self,
        instance: &Instance,
        cache: &mut HashMap<(usize, usize), Rc<Primitive>>,
        out: &mut GlbMesh,
        mut surface: Option<&mut GlbSurface>,
        info: &mut GlbInfo,
        warnings: &mut Vec<String>,
    ) -> Result<(), GlbError> {
        let mesh = &self.root.meshes[instance.mesh];
        let node = &self.root.nodes[instance.node];
        let weights: Vec<f64> = node
            .weights
            .as_ref()
            .or(mesh.weights.as_ref())
            .map(|w| w.iter().map(|v| f64::from(*v)).collect())
            .unwrap_or_default();
        let joints = match node.skin {
            Some(skin) => {
                info.skinned = true;
                Some(self.joint_matrices(skin.value())?)
            }
            None => None,
        };
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            let path = format!("meshes[{}].primitives[{p}]", instance.mesh);
            let Some(geometry) =
                self.cached_primitive(instance.mesh, p, primitive, cache, info, warnings)?
            else {
                continue;
            };
            let mut positions = geometry.positions.clone();
            if primitive.targets.as_ref().is_some_and(|t| !t.is_empty()) {
                info.morph_targets = true;
                self.morph(primitive, &path, &weights, &mut positions)?;
            }
            let skinned = match &joints {
                Some(joints) => self.skin(primitive, &path, joints, &positions)?,
                None => None,
            };
            if let Some(surface) = surface.as_deref_mut() {
                // Normals follow the node's transform; a morphed or skinned primitive's
                // normals would need the same deformation, so they are recomputed instead.
                let deformed =
                    skinned.is_some() || primitive.targets.as_ref().is_some_and(|t| !t.is_empty());
                surface.push_primitive(
                    &geometry.attributes,
                    (!deformed).then_some(&instance.world),
                    primitive.material.map(|m| m.value()),
                    u32::try_from(out.positions_m.len()).unwrap_or(u32::MAX),
                    positions.len(),
                    u32::try_from(out.triangles.len()).unwrap_or(u32::MAX),
                    geometry.triangles.len(),
                );
            }
            let placed: Vec<[f64; 3]> = match skinned {
                Some(skinned) => skinned,
                None => positions
                    .iter()
                    .map(|v| transform(&instance.world, v))
                    .collect(),
            };
            let base = u32::try_from(out.positions_m.len())
                .ok()
                .filter(|b| b.checked_add(placed.len() as u32).is_some())
                .ok_or_else(|| data_error(&path, "the asset has more than 2^32 vertices"))?;
            out.positions_m.extend(placed);
            out.triangles.extend(
                geometry
                    .triangles
                    .iter()
                    .map(|t| [t[0] + base, t[1] + base, t[2] + base]),
            );
            info.primitives += 1;
        }
        Ok(())
    }

    /// Like `add_instance`, for the document API: each primitive placed on its own, with its
    /// material and, when asked, its normals and texture coordinates.
    fn add_instance_placed(
        &self,
        instance: &Instance,
        cache: &mut HashMap<(usize, usize), Rc<Primitive>>,
        out: &mut Vec<PlacedPrimitive>,
        info: &mut GlbInfo,
        warnings: &mut Vec<String>,
    ) -> Result<(), GlbError> {
        let mesh = &self.root.meshes[instance.mesh];
        let node = &self.root.nodes[instance.node];
        let weights: Vec<f64> = node
            .weights
            .as_ref()
            .or(mesh.weights.as_ref())
            .map(|w| w.iter().map(|v| f64::from(*v)).collect())
            .unwrap_or_default();
        let joints = match node.skin {
            Some(skin) => {
                info.skinned = true;
                Some(self.joint_matrices(skin.value())?)
            }
            None => None,
        };
        // Normals turn with the inverse transpose of the world matrix's linear part.
        let linear = instance.world.fixed_view::<3, 3>(0, 0).into_owned();
        let normal_matrix = linear.try_inverse().map(|m| m.transpose());
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            let path = format!("meshes[{}].primitives[{p}]", instance.mesh);
            let Some(geometry) =
                self.cached_primitive(instance.mesh, p, primitive, cache, info, warnings)?
            else {
                continue;
            };
            let mut positions = geometry.positions.clone();
            let morphed = primitive.targets.as_ref().is_some_and(|t| !t.is_empty());
            if morphed {
                info.morph_targets = true;
                self.morph(primitive, &path, &weights, &mut positions)?;
            }
            let skinned = match &joints {
                Some(joints) => self.skin(primitive, &path, joints, &positions)?,
                None => None,
            };
            let deformed = morphed || skinned.is_some();
            let placed: Vec<[f64; 3]> = match skinned {
                Some(skinned) => skinned,
                None => positions
                    .iter()
                    .map(|v| transform(&instance.world, v))
                    .collect(),
            };
            let normals = match (&geometry.normals, &normal_matrix) {
                (Some(normals), Some(m)) if !deformed => Some(
                    normals
                        .iter()
                        .map(|n| {
                            let v = m * Vector3::new(n[0], n[1], n[2]);
                            let len = v.norm();
                            if len > 0.0 && len.is_finite() {
                                [v[0] / len, v[1] / len, v[2] / len]
                            } else {
                                [0.0, 1.0, 0.0]
                            }
                        })
                        .collect(),
                ),
                _ => None,
            };
            out.push(PlacedPrimitive {
                node: instance.node,
                mesh: instance.mesh,
                primitive: p,
                positions_m: placed,
                triangles: geometry.triangles.clone(),
                normals,
                uvs: geometry.uvs.clone(),
                material: primitive.material.map(|m| m.value()),
                mirrored: !deformed && linear.determinant() < 0.0,
            });
            info.primitives += 1;
        }
        Ok(())
    }
}

fn transform(m: &Matrix4<f64>, p: &[f64; 3]) -> [f64; 3] {
    let v = m * nalgebra::Vector4::new(p[0], p[1], p[2], 1.0);
    [v[0], v[1], v[2]]
}

#[cfg(test)]
mod quantization_tests;
#[cfg(test)]
mod tests;
