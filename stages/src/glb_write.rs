//! Writing binary glTF (GLB) files with `gltf-json`'s typed indices.
//!
//! [`GlbBuilder`] collects textures (embedded PNG), materials, meshes (one or more primitives,
//! each with its material), nodes (TRS, children, extras) and one scene, then lays everything
//! out in a single buffer: every buffer view starts on a 4-byte boundary, the JSON chunk is
//! padded with spaces and the BIN chunk with zeros, as the GLB container requires. The output
//! depends only on what was added, in the order it was added, so the same calls give the same
//! bytes. Everything it writes is meant to pass the Khronos glTF validator with no error (a
//! test in `stages/tests/` runs the validator when it is installed).

use std::collections::BTreeMap;

use gltf_json as json;
use json::validation::{Checked::Valid, USize64};
use json::Index;
use thiserror::Error;

use crate::mesh::{MeshError, TriMesh};

/// Why a GLB could not be written.
#[derive(Debug, Error)]
pub enum GlbWriteError {
    /// A primitive's mesh is malformed.
    #[error("mesh \"{mesh}\", primitive {primitive}: {source}")]
    Mesh {
        /// The mesh name.
        mesh: String,
        /// Index of the primitive within the mesh.
        primitive: usize,
        /// What is wrong.
        source: MeshError,
    },
    /// A primitive without triangles (glTF forbids empty accessors).
    #[error("mesh \"{mesh}\", primitive {primitive}: no triangles")]
    EmptyPrimitive {
        /// The mesh name.
        mesh: String,
        /// Index of the primitive.
        primitive: usize,
    },
    /// A mesh without primitives.
    #[error("mesh \"{mesh}\" has no primitive")]
    NoPrimitive {
        /// The mesh name.
        mesh: String,
    },
    /// Bytes that are not a PNG image were given as a PNG texture.
    #[error("texture \"{name}\": the image bytes are not a PNG (no PNG signature)")]
    NotPng {
        /// The texture name.
        name: String,
    },
    /// Image bytes that are not of their stated type, or of a type glTF 2.0 core does not
    /// allow.
    #[error(
        "texture \"{name}\": {problem} (glTF 2.0 embeds PNG and JPEG images; convert it to \
         PNG)"
    )]
    Image {
        /// The texture name.
        name: String,
        /// What is wrong.
        problem: String,
    },
    /// Node extras that are not a JSON object.
    #[error("node \"{node}\": extras must be a JSON object")]
    Extras {
        /// The node name.
        node: String,
    },
    /// The file would exceed the 4 GiB limit of the GLB container.
    #[error("the GLB would be {bytes} bytes, above the container's 4 GiB limit")]
    TooLarge {
        /// The size it would have.
        bytes: u64,
    },
    /// The glTF JSON could not be serialised.
    #[error("glTF JSON serialisation failed: {0}")]
    Json(#[from] serde_json::Error),
}

/// How a material's alpha is used (glTF `alphaMode`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum AlphaSpec {
    /// Alpha ignored.
    #[default]
    Opaque,
    /// Alpha tested against a cutoff.
    Mask(f32),
    /// Alpha blended.
    Blend,
}

/// How a texture is sampled (glTF sampler constants; `None` filters are the viewer's
/// choice).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SamplerSpec {
    /// `magFilter` (9728 nearest, 9729 linear).
    pub mag_filter: Option<u32>,
    /// `minFilter` (9728, 9729, 9984..=9987).
    pub min_filter: Option<u32>,
    /// `wrapS` (33071 clamp, 33648 mirrored repeat, 10497 repeat).
    pub wrap_s: u32,
    /// `wrapT`.
    pub wrap_t: u32,
}

impl Default for SamplerSpec {
    fn default() -> Self {
        Self {
            mag_filter: Some(9729),
            min_filter: Some(9987),
            wrap_s: 10497,
            wrap_t: 10497,
        }
    }
}

/// A metallic-roughness material.
#[derive(Debug, Clone, PartialEq)]
pub struct MaterialSpec {
    /// The material name.
    pub name: String,
    /// Linear RGBA base colour (multiplied with the texture when there is one).
    pub base_color_factor: [f32; 4],
    /// The base-colour texture (sRGB), from [`GlbBuilder::add_png_texture`].
    pub base_color_texture: Option<Index<json::Texture>>,
    /// Metalness in [0, 1].
    pub metallic: f32,
    /// Roughness in [0, 1].
    pub roughness: f32,
    /// Render both sides (for open, zero-thickness surfaces).
    pub double_sided: bool,
    /// The metallic-roughness texture (blue: metalness, green: roughness).
    pub metallic_roughness_texture: Option<Index<json::Texture>>,
    /// The tangent-space normal map and its scale.
    pub normal_texture: Option<(Index<json::Texture>, f32)>,
    /// The occlusion texture and its strength.
    pub occlusion_texture: Option<(Index<json::Texture>, f32)>,
    /// The emissive texture (sRGB).
    pub emissive_texture: Option<Index<json::Texture>>,
    /// Linear RGB emission (multiplied with the emissive texture when there is one).
    pub emissive_factor: [f32; 3],
    /// How alpha is used.
    pub alpha: AlphaSpec,
}

impl MaterialSpec {
    /// A plain, non-metallic material of a linear RGB colour.
    pub fn plain(name: impl Into<String>, linear_rgb: [f32; 3], roughness: f32) -> Self {
        Self {
            name: name.into(),
            base_color_factor: [linear_rgb[0], linear_rgb[1], linear_rgb[2], 1.0],
            base_color_texture: None,
            metallic: 0.0,
            roughness,
            double_sided: false,
            metallic_roughness_texture: None,
            normal_texture: None,
            occlusion_texture: None,
            emissive_texture: None,
            emissive_factor: [0.0; 3],
            alpha: AlphaSpec::Opaque,
        }
    }

    /// Whether the material samples any texture (then primitives carry texture coordinates).
    pub fn is_textured(&self) -> bool {
        self.base_color_texture.is_some()
            || self.metallic_roughness_texture.is_some()
            || self.normal_texture.is_some()
            || self.occlusion_texture.is_some()
            || self.emissive_texture.is_some()
    }
}

/// A node: a name, an optional mesh, a TRS transform, children and extras.
#[derive(Debug, Clone, PartialEq)]
pub struct NodeSpec {
    /// The node name.
    pub name: String,
    /// The mesh drawn at this node.
    pub mesh: Option<Index<json::Mesh>>,
    /// Translation in the parent's frame.
    pub translation: [f64; 3],
    /// Rotation `[x, y, z, w]` (normalised when written).
    pub rotation_xyzw: [f64; 4],
    /// Scale per axis.
    pub scale: [f64; 3],
    /// Child nodes (added before this one).
    pub children: Vec<Index<json::Node>>,
    /// A JSON object stored as the node's `extras`.
    pub extras: Option<serde_json::Value>,
}

impl NodeSpec {
    /// A node with the identity transform.
    pub fn new(name: impl Into<String>) -> Self {
        Self {
            name: name.into(),
            mesh: None,
            translation: [0.0; 3],
            rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
            scale: [1.0; 3],
            children: Vec::new(),
            extras: None,
        }
    }

    /// This node drawing `mesh`.
    pub fn with_mesh(mut self, mesh: Index<json::Mesh>) -> Self {
        self.mesh = Some(mesh);
        self
    }

    /// This node with a translation.
    pub fn with_translation(mut self, translation: [f64; 3]) -> Self {
        self.translation = translation;
        self
    }

    /// This node with a rotation `[x, y, z, w]`.
    pub fn with_rotation_xyzw(mut self, rotation_xyzw: [f64; 4]) -> Self {
        self.rotation_xyzw = rotation_xyzw;
        self
    }

    /// This node with a scale.
    pub fn with_scale(mut self, scale: [f64; 3]) -> Self {
        self.scale = scale;
        self
    }

    /// This node with children.
    pub fn with_children(mut self, children: Vec<Index<json::Node>>) -> Self {
        self.children = children;
        self
    }

    /// This node with extras (a JSON object).
    pub fn with_extras(mut self, extras: serde_json::Value) -> Self {
        self.extras = Some(extras);
        self
    }
}

/// Builds one GLB file.
#[derive(Debug)]
pub struct GlbBuilder {
    root: json::Root,
    bin: Vec<u8>,
    samplers: Vec<(SamplerSpec, Index<json::texture::Sampler>)>,
    scene_roots: Vec<Index<json::Node>>,
    scene_name: Option<String>,
    /// Per material: whether it samples a texture (only then do primitives carry texture
    /// coordinates, which would otherwise be unused data).
    textured: Vec<bool>,
}

const GLB_MAGIC: &[u8; 4] = b"glTF";
const CHUNK_JSON: u32 = 0x4E4F_534A;
const CHUNK_BIN: u32 = 0x004E_4942;
const PNG_SIGNATURE: &[u8; 8] = b"\x89PNG\r\n\x1a\n";

impl GlbBuilder {
    /// An empty file whose `asset.generator` is `generator`.
    pub fn new(generator: &str) -> Self {
        let root = json::Root {
            asset: json::Asset {
                generator: Some(generator.to_owned()),
                version: "2.0".to_owned(),
                ..Default::default()
            },
            ..Default::default()
        };
        Self {
            root,
            bin: Vec::new(),
            samplers: Vec::new(),
            scene_roots: Vec::new(),
            scene_name: None,
            textured: Vec::new(),
        }
    }

    fn push_view(
        &mut self,
        bytes: &[u8],
        target: Option<json::buffer::Target>,
    ) -> Index<json::buffer::View> {
        debug_assert_eq!(self.bin.len() % 4, 0);
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        while self.bin.len() % 4 != 0 {
            self.bin.push(0);
        }
        self.root.push(json::buffer::View {
            buffer: Index::new(0),
            byte_length: USize64::from(bytes.len()),
            byte_offset: Some(USize64::from(offset)),
            byte_stride: None,
            extensions: None,
            extras: Default::default(),
            name: None,
            target: target.map(Valid),
        })
    }

    /// Embeds a PNG image and returns a texture sampling it (linear filtering, repeat).
    pub fn add_png_texture(
        &mut self,
        name: &str,
        png_bytes: &[u8],
    ) -> Result<Index<json::Texture>, GlbWriteError> {
        if !png_bytes.starts_with(PNG_SIGNATURE) {
            return Err(GlbWriteError::NotPng {
                name: name.to_owned(),
            });
        }
        let image = self.add_image(name, png_bytes, "image/png")?;
        Ok(self.add_texture(name, image, SamplerSpec::default()))
    }

    /// Embeds a PNG or JPEG image (checked against its signature) and returns its index.
    pub fn add_image(
        &mut self,
        name: &str,
        bytes: &[u8],
        mime: &str,
    ) -> Result<Index<json::Image>, GlbWriteError> {
        let signature_ok = match mime {
            "image/png" => bytes.starts_with(PNG_SIGNATURE),
            "image/jpeg" => bytes.starts_with(&[0xFF, 0xD8, 0xFF]),
            other => {
                return Err(GlbWriteError::Image {
                    name: name.to_owned(),
                    problem: format!("MIME type \"{other}\""),
                })
            }
        };
        if !signature_ok {
            return Err(GlbWriteError::Image {
                name: name.to_owned(),
                problem: format!("the bytes are not a {mime} image (wrong signature)"),
            });
        }
        let view = self.push_view(bytes, None);
        Ok(self.root.push(json::Image {
            buffer_view: Some(view),
            mime_type: Some(json::image::MimeType(mime.to_owned())),
            name: Some(name.to_owned()),
            uri: None,
            extensions: None,
            extras: Default::default(),
        }))
    }

    /// A texture sampling `image` with `sampler` (samplers are shared between textures).
    pub fn add_texture(
        &mut self,
        name: &str,
        image: Index<json::Image>,
        sampler: SamplerSpec,
    ) -> Index<json::Texture> {
        let sampler_index = match self.samplers.iter().find(|(s, _)| *s == sampler) {
            Some((_, index)) => *index,
            None => {
                let mag = match sampler.mag_filter {
                    Some(9728) => Some(Valid(json::texture::MagFilter::Nearest)),
                    Some(_) => Some(Valid(json::texture::MagFilter::Linear)),
                    None => None,
                };
                let min = sampler.min_filter.map(|f| {
                    Valid(match f {
                        9728 => json::texture::MinFilter::Nearest,
                        9729 => json::texture::MinFilter::Linear,
                        9984 => json::texture::MinFilter::NearestMipmapNearest,
                        9985 => json::texture::MinFilter::LinearMipmapNearest,
                        9986 => json::texture::MinFilter::NearestMipmapLinear,
                        _ => json::texture::MinFilter::LinearMipmapLinear,
                    })
                });
                let wrap = |w: u32| {
                    Valid(match w {
                        33071 => json::texture::WrappingMode::ClampToEdge,
                        33648 => json::texture::WrappingMode::MirroredRepeat,
                        _ => json::texture::WrappingMode::Repeat,
                    })
                };
                let index = self.root.push(json::texture::Sampler {
                    mag_filter: mag,
                    min_filter: min,
                    wrap_s: wrap(sampler.wrap_s),
                    wrap_t: wrap(sampler.wrap_t),
                    ..Default::default()
                });
                self.samplers.push((sampler, index));
                index
            }
        };
        self.root.push(json::Texture {
            name: Some(name.to_owned()),
            sampler: Some(sampler_index),
            source: image,
            extensions: None,
            extras: Default::default(),
        })
    }

    /// Adds a material.
    pub fn add_material(&mut self, spec: &MaterialSpec) -> Index<json::Material> {
        let clamp = |v: f32| v.clamp(0.0, 1.0);
        let info = |index: Index<json::Texture>| json::texture::Info {
            index,
            tex_coord: 0,
            extensions: None,
            extras: Default::default(),
        };
        self.textured.push(spec.is_textured());
        let (alpha_mode, alpha_cutoff) = match spec.alpha {
            AlphaSpec::Opaque => (json::material::AlphaMode::Opaque, None),
            AlphaSpec::Mask(cutoff) => (
                json::material::AlphaMode::Mask,
                Some(json::material::AlphaCutoff(cutoff.max(0.0))),
            ),
            AlphaSpec::Blend => (json::material::AlphaMode::Blend, None),
        };
        self.root.push(json::Material {
            name: Some(spec.name.clone()),
            double_sided: spec.double_sided,
            alpha_mode: Valid(alpha_mode),
            alpha_cutoff,
            pbr_metallic_roughness: json::material::PbrMetallicRoughness {
                base_color_factor: json::material::PbrBaseColorFactor(
                    spec.base_color_factor.map(clamp),
                ),
                base_color_texture: spec.base_color_texture.map(info),
                metallic_factor: json::material::StrengthFactor(clamp(spec.metallic)),
                roughness_factor: json::material::StrengthFactor(clamp(spec.roughness)),
                metallic_roughness_texture: spec.metallic_roughness_texture.map(info),
                ..Default::default()
            },
            normal_texture: spec.normal_texture.map(|(index, scale)| {
                json::material::NormalTexture {
                    index,
                    scale,
                    tex_coord: 0,
                    extensions: None,
                    extras: Default::default(),
                }
            }),
            occlusion_texture: spec.occlusion_texture.map(|(index, strength)| {
                json::material::OcclusionTexture {
                    index,
                    strength: json::material::StrengthFactor(clamp(strength)),
                    tex_coord: 0,
                    extensions: None,
                    extras: Default::default(),
                }
            }),
            emissive_texture: spec.emissive_texture.map(info),
            emissive_factor: json::material::EmissiveFactor(
                spec.emissive_factor.map(|v| v.max(0.0)),
            ),
            ..Default::default()
        })
    }

    /// Adds a mesh with one primitive per `(triangles, material)` pair. Texture coordinates
    /// are written when the triangle mesh has them and the material samples a texture.
    pub fn add_mesh(
        &mut self,
        name: &str,
        primitives: &[(&TriMesh, Index<json::Material>)],
    ) -> Result<Index<json::Mesh>, GlbWriteError> {
        if primitives.is_empty() {
            return Err(GlbWriteError::NoPrimitive {
                mesh: name.to_owned(),
            });
        }
        let mut out = Vec::with_capacity(primitives.len());
        for (i, (mesh, material)) in primitives.iter().enumerate() {
            if mesh.is_empty() {
                return Err(GlbWriteError::EmptyPrimitive {
                    mesh: name.to_owned(),
                    primitive: i,
                });
            }
            mesh.check().map_err(|source| GlbWriteError::Mesh {
                mesh: name.to_owned(),
                primitive: i,
                source,
            })?;
            out.push(self.primitive(mesh, *material));
        }
        Ok(self.root.push(json::Mesh {
            name: Some(name.to_owned()),
            primitives: out,
            weights: None,
            extensions: None,
            extras: Default::default(),
        }))
    }

    fn float_accessor(
        &mut self,
        data: &[u8],
        count: usize,
        type_: json::accessor::Type,
        bounds: Option<([f32; 3], [f32; 3])>,
    ) -> Index<json::Accessor> {
        let view = self.push_view(data, Some(json::buffer::Target::ArrayBuffer));
        self.root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64::from(count),
            component_type: Valid(json::accessor::GenericComponentType(
                json::accessor::ComponentType::F32,
            )),
            extensions: None,
            extras: Default::default(),
            type_: Valid(type_),
            min: bounds.map(|(min, _)| json::Value::from(min.to_vec())),
            max: bounds.map(|(_, max)| json::Value::from(max.to_vec())),
            name: None,
            normalized: false,
            sparse: None,
        })
    }

    fn primitive(
        &mut self,
        mesh: &TriMesh,
        material: Index<json::Material>,
    ) -> json::mesh::Primitive {
        let n = mesh.positions.len();
        let mut min = [f32::INFINITY; 3];
        let mut max = [f32::NEG_INFINITY; 3];
        for p in &mesh.positions {
            for i in 0..3 {
                min[i] = min[i].min(p[i]);
                max[i] = max[i].max(p[i]);
            }
        }
        let positions: Vec<u8> = mesh
            .positions
            .iter()
            .flatten()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let normals: Vec<u8> = mesh
            .normals
            .iter()
            .flatten()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let mut attributes = BTreeMap::new();
        let pos = self.float_accessor(&positions, n, json::accessor::Type::Vec3, Some((min, max)));
        attributes.insert(Valid(json::mesh::Semantic::Positions), pos);
        let nor = self.float_accessor(&normals, n, json::accessor::Type::Vec3, None);
        attributes.insert(Valid(json::mesh::Semantic::Normals), nor);
        let textured = self
            .textured
            .get(material.value())
            .copied()
            .unwrap_or(false);
        if mesh.has_uvs() && textured {
            let uvs: Vec<u8> = mesh
                .uvs
                .iter()
                .flatten()
                .flat_map(|v| v.to_le_bytes())
                .collect();
            let uv = self.float_accessor(&uvs, n, json::accessor::Type::Vec2, None);
            attributes.insert(Valid(json::mesh::Semantic::TexCoords(0)), uv);
        }
        let index_count = mesh.triangles.len() * 3;
        let (bytes, component) = if n <= u16::MAX as usize {
            (
                mesh.triangles
                    .iter()
                    .flatten()
                    .flat_map(|&i| (i as u16).to_le_bytes())
                    .collect::<Vec<u8>>(),
                json::accessor::ComponentType::U16,
            )
        } else {
            (
                mesh.triangles
                    .iter()
                    .flatten()
                    .flat_map(|i| i.to_le_bytes())
                    .collect(),
                json::accessor::ComponentType::U32,
            )
        };
        let view = self.push_view(&bytes, Some(json::buffer::Target::ElementArrayBuffer));
        let indices = self.root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64::from(index_count),
            component_type: Valid(json::accessor::GenericComponentType(component)),
            extensions: None,
            extras: Default::default(),
            type_: Valid(json::accessor::Type::Scalar),
            min: None,
            max: None,
            name: None,
            normalized: false,
            sparse: None,
        });
        json::mesh::Primitive {
            attributes,
            extensions: None,
            extras: Default::default(),
            indices: Some(indices),
            material: Some(material),
            mode: Valid(json::mesh::Mode::Triangles),
            targets: None,
        }
    }

    /// Adds a node (its children must have been added already).
    pub fn add_node(&mut self, spec: NodeSpec) -> Result<Index<json::Node>, GlbWriteError> {
        let extras = match &spec.extras {
            None => None,
            Some(value) if value.is_object() => Some(serde_json::value::to_raw_value(value)?),
            Some(_) => return Err(GlbWriteError::Extras { node: spec.name }),
        };
        let f = |v: [f64; 3]| v.map(|c| c as f32);
        let q = crate::mesh::quat_normalize(spec.rotation_xyzw);
        let rotation =
            (q != [0.0, 0.0, 0.0, 1.0]).then(|| json::scene::UnitQuaternion(q.map(|c| c as f32)));
        Ok(self.root.push(json::Node {
            name: Some(spec.name),
            mesh: spec.mesh,
            translation: (spec.translation != [0.0; 3]).then(|| f(spec.translation)),
            rotation,
            scale: (spec.scale != [1.0; 3]).then(|| f(spec.scale)),
            children: (!spec.children.is_empty()).then_some(spec.children),
            extras,
            ..Default::default()
        }))
    }

    /// Makes `roots` the nodes of the file's (single, default) scene.
    pub fn set_scene(&mut self, name: &str, roots: Vec<Index<json::Node>>) {
        self.scene_name = Some(name.to_owned());
        self.scene_roots = roots;
    }

    /// The glTF document built so far (for inspection in tests).
    pub fn root(&self) -> &json::Root {
        &self.root
    }

    /// Lays out the buffer and returns the GLB bytes.
    pub fn finish(mut self) -> Result<Vec<u8>, GlbWriteError> {
        let scene = self.root.push(json::Scene {
            name: self.scene_name.take(),
            nodes: std::mem::take(&mut self.scene_roots),
            extensions: None,
            extras: Default::default(),
        });
        self.root.scene = Some(scene);
        if !self.bin.is_empty() {
            self.root.buffers = vec![json::Buffer {
                byte_length: USize64::from(self.bin.len()),
                name: None,
                uri: None,
                extensions: None,
                extras: Default::default(),
            }];
        }
        let mut json_bytes = json::serialize::to_vec(&self.root)?;
        while json_bytes.len() % 4 != 0 {
            json_bytes.push(b' ');
        }
        let bin_chunk = if self.bin.is_empty() {
            0
        } else {
            8 + self.bin.len()
        };
        let total = 12 + 8 + json_bytes.len() + bin_chunk;
        let total_u32 = u32::try_from(total).map_err(|_| GlbWriteError::TooLarge {
            bytes: total as u64,
        })?;
        let mut out = Vec::with_capacity(total);
        out.extend_from_slice(GLB_MAGIC);
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&total_u32.to_le_bytes());
        out.extend_from_slice(&(json_bytes.len() as u32).to_le_bytes());
        out.extend_from_slice(&CHUNK_JSON.to_le_bytes());
        out.extend_from_slice(&json_bytes);
        if !self.bin.is_empty() {
            out.extend_from_slice(&(self.bin.len() as u32).to_le_bytes());
            out.extend_from_slice(&CHUNK_BIN.to_le_bytes());
            out.extend_from_slice(&self.bin);
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image_io::encode_rgba8;

    fn sample_glb() -> Vec<u8> {
        let mut b = GlbBuilder::new("mesa test");
        let png = encode_rgba8(2, 2, &[255; 16]).expect("png");
        let tex = b.add_png_texture("white", &png).expect("texture");
        let mut textured = MaterialSpec::plain("textured", [1.0, 1.0, 1.0], 0.5);
        textured.base_color_texture = Some(tex);
        let m0 = b.add_material(&textured);
        let m1 = b.add_material(&MaterialSpec::plain("red", [0.8, 0.05, 0.05], 0.4));
        let cube = TriMesh::cuboid([0.1, 0.2, 0.3]);
        let cyl = TriMesh::cylinder(0.02, 0.1, 12);
        let mesh = b
            .add_mesh("parts", &[(&cube, m0), (&cyl, m1)])
            .expect("mesh");
        let child = b
            .add_node(
                NodeSpec::new("child")
                    .with_mesh(mesh)
                    .with_translation([0.0, 0.1, 0.0])
                    .with_rotation_xyzw([0.0, 0.38268343, 0.0, 0.92387953]),
            )
            .expect("node");
        let root = b
            .add_node(
                NodeSpec::new("root")
                    .with_children(vec![child])
                    .with_scale([0.5, 0.5, 0.5])
                    .with_extras(serde_json::json!({"mesa": {"uid": "x"}})),
            )
            .expect("node");
        b.set_scene("scene", vec![root]);
        b.finish().expect("glb")
    }

    #[test]
    fn glb_is_deterministic_padded_and_readable() {
        let bytes = sample_glb();
        assert_eq!(bytes, sample_glb());
        assert_eq!(&bytes[0..4], b"glTF");
        assert_eq!(
            u32::from_le_bytes(bytes[8..12].try_into().expect("4")) as usize,
            bytes.len()
        );
        let json_len = u32::from_le_bytes(bytes[12..16].try_into().expect("4")) as usize;
        assert_eq!(json_len % 4, 0);
        let bin_len_at = 20 + json_len;
        let bin_len =
            u32::from_le_bytes(bytes[bin_len_at..bin_len_at + 4].try_into().expect("4")) as usize;
        assert_eq!(bin_len % 4, 0);
        assert_eq!(bin_len_at + 8 + bin_len, bytes.len());

        let (doc, buffers, images) = gltf::import_slice(&bytes).expect("gltf reads it");
        assert_eq!(images.len(), 1);
        let mesh = doc.meshes().next().expect("mesh");
        assert_eq!(mesh.primitives().count(), 2);
        let prim = mesh.primitives().next().expect("primitive");
        let reader = prim.reader(|b| Some(&buffers[b.index()]));
        assert_eq!(reader.read_positions().expect("positions").count(), 24);
        assert_eq!(
            reader.read_indices().expect("indices").into_u32().count(),
            36
        );
        let root = doc
            .nodes()
            .find(|n| n.name() == Some("root"))
            .expect("root");
        assert_eq!(root.transform().decomposed().2, [0.5, 0.5, 0.5]);
        assert!(root
            .extras()
            .as_ref()
            .expect("extras")
            .get()
            .contains("\"uid\""));
    }

    #[test]
    fn bad_inputs_are_errors() {
        let mut b = GlbBuilder::new("t");
        assert!(matches!(
            b.add_png_texture("x", b"nope"),
            Err(GlbWriteError::NotPng { .. })
        ));
        let m = b.add_material(&MaterialSpec::plain("m", [1.0; 3], 1.0));
        let empty = TriMesh::default();
        assert!(matches!(
            b.add_mesh("e", &[(&empty, m)]),
            Err(GlbWriteError::EmptyPrimitive { .. })
        ));
        let mut broken = TriMesh::cuboid([1.0; 3]);
        broken.triangles.push([0, 1, 99]);
        assert!(matches!(
            b.add_mesh("b", &[(&broken, m)]),
            Err(GlbWriteError::Mesh { .. })
        ));
        assert!(matches!(
            b.add_node(NodeSpec::new("n").with_extras(serde_json::json!([1]))),
            Err(GlbWriteError::Extras { .. })
        ));
    }
}
