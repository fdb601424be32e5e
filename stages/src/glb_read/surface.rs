//! What a renderer needs of a GLB besides its triangles: per-vertex normals, texture
//! coordinates and colours, each primitive's material (base colour factor and texture, alpha
//! mode), and the embedded images. Read by [`super::read_glb_surface`]; the geometry reader
//! ([`super::read_glb`]) never pays for it.
//!
//! Materials are read as the metallic-roughness model's base colour, or the diffuse colour of
//! `KHR_materials_pbrSpecularGlossiness` (still common in Objaverse assets); `KHR_materials_unlit`
//! is noted. Attributes that are malformed (a count that differs from the positions') are
//! dropped with a warning: the asset still draws, flat-shaded or untextured.

use gltf_json::mesh::Semantic;
use gltf_json::validation::Checked;
use gltf_json::Root;
use nalgebra::{Matrix3, Matrix4};
use serde_json::Value;

use super::accessor::{read_accessor, Buffers};
use super::{data_uri, Reader};

/// How a material's alpha is used (glTF `alphaMode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum AlphaMode {
    /// Alpha is ignored.
    #[default]
    Opaque,
    /// Fragments with alpha below the cutoff are not drawn.
    Mask,
    /// Alpha blends with what is behind.
    Blend,
}

/// A material's base colour, as a renderer reads it.
#[derive(Debug, Clone, PartialEq)]
pub struct SurfaceMaterial {
    /// Its name, or `material_<index>`.
    pub name: String,
    /// Linear RGBA base colour factor.
    pub base_color_factor: [f32; 4],
    /// The image of the base colour texture (index into [`GlbSurface::images`]).
    pub base_color_image: Option<usize>,
    /// Which `TEXCOORD_n` set the texture uses.
    pub tex_coord: u32,
    /// The alpha mode.
    pub alpha_mode: AlphaMode,
    /// The alpha cutoff of [`AlphaMode::Mask`].
    pub alpha_cutoff: f32,
    /// `KHR_materials_unlit`: the base colour is shown as it is, without lighting.
    pub unlit: bool,
}

impl Default for SurfaceMaterial {
    fn default() -> Self {
        Self {
            name: "default".to_owned(),
            base_color_factor: [1.0; 4],
            base_color_image: None,
            tex_coord: 0,
            alpha_mode: AlphaMode::Opaque,
            alpha_cutoff: 0.5,
            unlit: false,
        }
    }
}

/// An embedded image, still encoded.
#[derive(Debug, Clone, PartialEq)]
pub struct SurfaceImage {
    /// Its MIME type (`image/png`, `image/jpeg`, ...), from the file or the data URI.
    pub mime_type: String,
    /// The encoded bytes; `None` when the image could not be found (a warning says why).
    pub bytes: Option<Vec<u8>>,
}

/// One placed primitive: a range of [`super::GlbMesh`]'s vertices and triangles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SurfacePrimitive {
    /// First vertex in `positions_m`.
    pub first_vertex: u32,
    /// Number of vertices.
    pub vertices: u32,
    /// First triangle in `triangles`.
    pub first_triangle: u32,
    /// Number of triangles.
    pub triangles: u32,
    /// Its material (index into [`GlbSurface::materials`]); `None`: glTF's default material.
    pub material: Option<usize>,
    /// Whether the file gave normals (else they are zero and must be computed).
    pub has_normals: bool,
    /// Whether the file gave the texture coordinates its material's texture uses.
    pub has_uvs: bool,
}

/// The surface of a GLB, parallel to [`super::GlbMesh`]'s vertices.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct GlbSurface {
    /// Unit normals in the glTF scene frame, one per vertex (zero where the file has none).
    pub normals: Vec<[f32; 3]>,
    /// Texture coordinates of the material's base colour texture, one per vertex.
    pub uvs: Vec<[f32; 2]>,
    /// Linear RGBA vertex colours (`COLOR_0`), one per vertex; 1 where the file has none.
    pub colors: Vec<[f32; 4]>,
    /// The placed primitives, in the order of the triangles.
    pub primitives: Vec<SurfacePrimitive>,
    /// The file's materials.
    pub materials: Vec<SurfaceMaterial>,
    /// The file's images.
    pub images: Vec<SurfaceImage>,
}

/// A primitive's surface attributes in its own frame.
#[derive(Debug, Default)]
pub(super) struct Attributes {
    normals: Option<Vec<[f64; 3]>>,
    uvs: Option<Vec<[f32; 2]>>,
    colors: Option<Vec<[f32; 4]>>,
}

/// The attribute names a primitive's surface needs: `NORMAL`, the `TEXCOORD_n` of its
/// material's base colour texture, `COLOR_0`.
pub(super) fn wanted_attributes(
    root: &Root,
    primitive: &gltf_json::mesh::Primitive,
) -> Vec<String> {
    let set = primitive
        .material
        .and_then(|m| root.materials.get(m.value()))
        .map_or(0, |m| material_texture(m).map_or(0, |(_, set)| set));
    vec![
        "NORMAL".to_owned(),
        format!("TEXCOORD_{set}"),
        "COLOR_0".to_owned(),
    ]
}

/// The texture index and texture-coordinate set of a material's base colour.
fn material_texture(material: &gltf_json::Material) -> Option<(usize, u32)> {
    if let Some(info) = &material.pbr_metallic_roughness.base_color_texture {
        return Some((info.index.value(), info.tex_coord));
    }
    let diffuse = spec_gloss(material)?.get("diffuseTexture")?;
    let index = diffuse.get("index")?.as_u64()? as usize;
    let set = diffuse.get("texCoord").and_then(Value::as_u64).unwrap_or(0) as u32;
    Some((index, set))
}

fn spec_gloss(material: &gltf_json::Material) -> Option<&Value> {
    material
        .extensions
        .as_ref()?
        .others
        .get("KHR_materials_pbrSpecularGlossiness")
}

impl Attributes {
    /// Attributes decoded from a Draco stream, by glTF name.
    pub(super) fn from_named(
        named: Vec<(String, Vec<f64>, usize)>,
        vertices: usize,
        path: &str,
        warnings: &mut Vec<String>,
    ) -> Self {
        let mut out = Self::default();
        for (name, values, width) in named {
            out.set(&name, values, width, vertices, path, warnings);
        }
        out
    }

    fn set(
        &mut self,
        name: &str,
        values: Vec<f64>,
        width: usize,
        vertices: usize,
        path: &str,
        warnings: &mut Vec<String>,
    ) {
        let expected = match name {
            "NORMAL" => &[3][..],
            "COLOR_0" => &[3, 4][..],
            _ => &[2][..],
        };
        if !expected.contains(&width) || values.len() != vertices * width {
            warnings.push(format!(
                "{path}.attributes.{name}: {} values of width {width} for {vertices} vertices: \
                 ignored (drawn without it)",
                values.len()
            ));
            return;
        }
        match name {
            "NORMAL" => {
                self.normals = Some(values.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
            }
            "COLOR_0" => {
                self.colors = Some(
                    values
                        .chunks_exact(width)
                        .map(|c| {
                            [
                                c[0] as f32,
                                c[1] as f32,
                                c[2] as f32,
                                if width == 4 { c[3] as f32 } else { 1.0 },
                            ]
                        })
                        .collect(),
                )
            }
            _ => {
                self.uvs = Some(
                    values
                        .chunks_exact(2)
                        .map(|c| [c[0] as f32, c[1] as f32])
                        .collect(),
                )
            }
        }
    }
}

impl Reader<'_, '_> {
    /// Reads the named surface attributes of an uncompressed primitive; one that cannot be
    /// read is dropped with a warning.
    pub(super) fn surface_attributes(
        &self,
        primitive: &gltf_json::mesh::Primitive,
        wanted: &[String],
        vertices: usize,
        path: &str,
        warnings: &mut Vec<String>,
    ) -> Attributes {
        let mut out = Attributes::default();
        for name in wanted {
            let semantic = match name.as_str() {
                "NORMAL" => Semantic::Normals,
                "COLOR_0" => Semantic::Colors(0),
                other => match other.strip_prefix("TEXCOORD_").and_then(|n| n.parse().ok()) {
                    Some(set) => Semantic::TexCoords(set),
                    None => continue,
                },
            };
            let Some(accessor) = primitive
                .attributes
                .get(&Checked::Valid(semantic))
                .map(|a| a.value())
            else {
                continue;
            };
            let here = format!("{path}.attributes.{name}");
            match read_accessor(self.root, self.buffers, accessor, &here) {
                Ok((values, width)) => out.set(name, values, width, vertices, path, warnings),
                Err(e) => warnings.push(format!("{e}: ignored (drawn without it)")),
            }
        }
        out
    }
}

/// The materials and images of a file (the per-vertex data is added primitive by primitive).
pub(super) fn surface_materials(
    root: &Root,
    buffers: &Buffers<'_>,
    warnings: &mut Vec<String>,
) -> GlbSurface {
    let materials = root
        .materials
        .iter()
        .enumerate()
        .map(|(i, m)| {
            let pbr = &m.pbr_metallic_roughness;
            let mut factor = pbr.base_color_factor.0;
            if pbr.base_color_texture.is_none() {
                if let Some(diffuse) = spec_gloss(m)
                    .and_then(|e| e.get("diffuseFactor"))
                    .and_then(Value::as_array)
                    .filter(|a| a.len() == 4)
                {
                    for (k, v) in diffuse.iter().enumerate() {
                        factor[k] = v.as_f64().unwrap_or(1.0) as f32;
                    }
                }
            }
            let base_color_image = material_texture(m).and_then(|(texture, _)| {
                let source = root.textures.get(texture).map(|t| t.source.value());
                if source.is_none() {
                    warnings.push(format!(
                        "materials[{i}]: texture {texture} does not exist: drawn untextured"
                    ));
                }
                source
            });
            SurfaceMaterial {
                name: m.name.clone().unwrap_or_else(|| format!("material_{i}")),
                base_color_factor: factor,
                base_color_image,
                tex_coord: material_texture(m).map_or(0, |(_, set)| set),
                alpha_mode: match m.alpha_mode {
                    Checked::Valid(gltf_json::material::AlphaMode::Mask) => AlphaMode::Mask,
                    Checked::Valid(gltf_json::material::AlphaMode::Blend) => AlphaMode::Blend,
                    _ => AlphaMode::Opaque,
                },
                alpha_cutoff: m.alpha_cutoff.map_or(0.5, |c| c.0),
                unlit: m
                    .extensions
                    .as_ref()
                    .is_some_and(|e| e.others.contains_key("KHR_materials_unlit")),
            }
        })
        .collect();
    let images = root
        .images
        .iter()
        .enumerate()
        .map(|(i, image)| {
            let from_uri = image.uri.as_deref().and_then(|u| {
                u.strip_prefix("data:")
                    .and_then(|r| r.split([';', ',']).next())
                    .map(str::to_owned)
            });
            let mime_type = image
                .mime_type
                .as_ref()
                .map(|m| m.0.clone())
                .or(from_uri)
                .unwrap_or_else(|| "unknown".to_owned());
            let bytes = match (&image.buffer_view, &image.uri) {
                (Some(view), _) => view_bytes(root, buffers, view.value()),
                (None, Some(uri)) => data_uri(uri),
                (None, None) => None,
            };
            if bytes.is_none() {
                warnings.push(format!(
                    "images[{i}]: its bytes cannot be found: textures using it are drawn \
                     without it"
                ));
            }
            SurfaceImage { mime_type, bytes }
        })
        .collect();
    GlbSurface {
        materials,
        images,
        ..GlbSurface::default()
    }
}

fn view_bytes(root: &Root, buffers: &Buffers<'_>, view: usize) -> Option<Vec<u8>> {
    let view = root.buffer_views.get(view)?;
    let data = buffers.data.get(view.buffer.value())?.as_deref()?;
    let start = view.byte_offset.map_or(0, |o| o.0) as usize;
    let end = start.checked_add(view.byte_length.0 as usize)?;
    data.get(start..end).map(<[u8]>::to_vec)
}

impl GlbSurface {
    /// Appends one placed primitive: its attributes, normals turned by `world` (the node's
    /// matrix; `None` when the primitive was deformed and its normals must be recomputed).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn push_primitive(
        &mut self,
        attributes: &Attributes,
        world: Option<&Matrix4<f64>>,
        material: Option<usize>,
        first_vertex: u32,
        vertices: usize,
        first_triangle: u32,
        triangles: usize,
    ) {
        let normal_matrix: Option<Matrix3<f64>> = world.and_then(|m| {
            m.fixed_view::<3, 3>(0, 0)
                .into_owned()
                .try_inverse()
                .map(|inv| inv.transpose())
        });
        let normals = match (&attributes.normals, normal_matrix) {
            (Some(normals), Some(nm)) => {
                for n in normals {
                    let v = nm * nalgebra::Vector3::new(n[0], n[1], n[2]);
                    let len = v.norm();
                    self.normals.push(if len > 0.0 && len.is_finite() {
                        [
                            (v[0] / len) as f32,
                            (v[1] / len) as f32,
                            (v[2] / len) as f32,
                        ]
                    } else {
                        [0.0; 3]
                    });
                }
                true
            }
            _ => {
                self.normals.extend(std::iter::repeat_n([0.0; 3], vertices));
                false
            }
        };
        let uvs = match &attributes.uvs {
            Some(uvs) => {
                self.uvs.extend_from_slice(uvs);
                true
            }
            None => {
                self.uvs.extend(std::iter::repeat_n([0.0; 2], vertices));
                false
            }
        };
        match &attributes.colors {
            Some(colors) => self.colors.extend_from_slice(colors),
            None => self.colors.extend(std::iter::repeat_n([1.0; 4], vertices)),
        }
        self.primitives.push(SurfacePrimitive {
            first_vertex,
            vertices: u32::try_from(vertices).unwrap_or(u32::MAX),
            first_triangle,
            triangles: u32::try_from(triangles).unwrap_or(u32::MAX),
            material,
            has_normals: normals,
            has_uvs: uvs,
        });
    }
}
