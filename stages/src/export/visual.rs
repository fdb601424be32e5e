//! An asset's visual mesh split by glTF material, with the texture coordinates and base-colour
//! images the export carries over (issue #17: "textured where MuJoCo allows").
//!
//! Only the base colour is carried: its factor and its texture. MuJoCo reads PNG textures
//! only, so a PNG image is kept as it is (once it is known to decode), a JPEG is decoded and
//! re-encoded as PNG, and any other image (WebP, KTX2, an unreadable or oversized one) leaves
//! its material untextured, with a warning that names the image and why.

use std::collections::BTreeMap;
use std::io::Cursor;
use std::sync::Arc;

use mesa_schemas::artifacts::AssetGeometry;

use crate::glb_read::{AlphaMode, GlbMesh, GlbSurface};

use super::VisualMesh;

/// The longest side of a texture the export decodes, pixels. 8192 is what GPUs commonly
/// accept; a larger image (a 16384² RGBA image is 1 GiB decoded) is refused with a warning.
pub const MAX_TEXTURE_SIDE_PX: u32 = 8192;

/// The most memory one texture's decoding may take, bytes (an 8192² RGBA image is 256 MiB).
const MAX_TEXTURE_ALLOC_BYTES: u64 = 512 << 20;

/// The colour of a material-less mesh, sRGB (the grey of the untextured export).
const DEFAULT_GREY_SRGB: f32 = 0.8;

/// One material of a visual mesh and the triangles drawn with it.
#[derive(Debug, Clone, PartialEq)]
pub struct VisualMaterial {
    /// The glTF material's name (`material_<i>` when unnamed; `default` for glTF's default
    /// material, drawn grey).
    pub name: String,
    /// Base colour factor, linear RGBA; alpha is 1 unless the material blends.
    pub rgba_linear: [f32; 4],
    /// Its base-colour texture (index into [`VisualMesh::textures`]): only when the image
    /// could be used and every triangle has texture coordinates.
    pub texture: Option<usize>,
    /// Its triangles (indices into [`VisualMesh::triangles`]), ascending.
    pub triangles: Vec<u32>,
}

impl VisualMaterial {
    /// A grey material drawing `triangles` (an asset without materials, or the convex parts
    /// drawn in place of a missing visual mesh).
    pub fn grey(triangles: Vec<u32>) -> Self {
        let g = linear_from_srgb(DEFAULT_GREY_SRGB);
        Self {
            name: "default".to_owned(),
            rgba_linear: [g, g, g, 1.0],
            texture: None,
            triangles,
        }
    }

    /// The base colour factor sRGB-encoded, alpha as is: MTL's `Kd`, MuJoCo's and URDF's
    /// `rgba` (which simulators display without a transfer function, as they do texels).
    pub fn rgba_srgb(&self) -> [f32; 4] {
        let c = self.rgba_linear;
        [
            srgb_from_linear(c[0]),
            srgb_from_linear(c[1]),
            srgb_from_linear(c[2]),
            c[3],
        ]
    }
}

/// A base-colour image of an asset, as PNG.
#[derive(Debug, Clone, PartialEq)]
pub struct VisualTexture {
    /// The glTF image index (the file is `textures/<uid>_<image>.png`).
    pub image: usize,
    /// The PNG bytes, shared by every object of the asset.
    pub png: Arc<Vec<u8>>,
}

/// The texture file of an asset's image `image`, relative to the textures folder.
pub fn texture_file(uid: &str, image: usize) -> String {
    format!("{uid}_{image}.png")
}

/// sRGB encoding of a linear channel in [0, 1].
pub fn srgb_from_linear(v: f32) -> f32 {
    let v = v.clamp(0.0, 1.0);
    if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// Linear value of an sRGB-encoded channel in [0, 1].
pub fn linear_from_srgb(v: f32) -> f32 {
    let v = v.clamp(0.0, 1.0);
    if v <= 0.040_45 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// An embedded image as the PNG the export writes: a PNG as it is once it decodes, a JPEG
/// decoded and re-encoded; else why not (the reason names the format or the decoder's error).
pub fn texture_png(bytes: &[u8]) -> Result<Vec<u8>, String> {
    let format = image::guess_format(bytes)
        .map_err(|_| "not an image format mesa knows (expected PNG or JPEG)".to_owned())?;
    let name = match format {
        image::ImageFormat::Png => "PNG",
        image::ImageFormat::Jpeg => "JPEG",
        other => {
            return Err(format!(
                "{} is neither PNG nor JPEG (MuJoCo reads PNG; JPEG is converted)",
                other.extensions_str().first().unwrap_or(&"this format")
            ))
        }
    };
    let (width, height) = image::ImageReader::with_format(Cursor::new(bytes), format)
        .into_dimensions()
        .map_err(|e| format!("{name} header cannot be read: {e}"))?;
    if width == 0 || height == 0 || width > MAX_TEXTURE_SIDE_PX || height > MAX_TEXTURE_SIDE_PX {
        return Err(format!(
            "{name} of {width} × {height} pixels (expected 1 to {MAX_TEXTURE_SIDE_PX} on a side)"
        ));
    }
    let mut reader = image::ImageReader::with_format(Cursor::new(bytes), format);
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_TEXTURE_SIDE_PX);
    limits.max_image_height = Some(MAX_TEXTURE_SIDE_PX);
    limits.max_alloc = Some(MAX_TEXTURE_ALLOC_BYTES);
    reader.limits(limits);
    let decoded = reader
        .decode()
        .map_err(|e| format!("{name} cannot be decoded: {e}"))?;
    if format == image::ImageFormat::Png {
        // Checked to decode (MuJoCo refuses the whole model over one bad texture), kept as is.
        return Ok(bytes.to_vec());
    }
    let mut png = Vec::new();
    decoded
        .write_to(&mut Cursor::new(&mut png), image::ImageFormat::Png)
        .map_err(|e| format!("{name} cannot be re-encoded as PNG: {e}"))?;
    Ok(png)
}

impl VisualMesh {
    /// The visual mesh of a GLB read by [`crate::glb_read::read_glb_surface`] (the frame as
    /// [`VisualMesh::from_glb`]), split by glTF material, with the texture coordinates and the
    /// base-colour images of its textured materials. An image that cannot be used, or a
    /// textured material with a primitive without texture coordinates, leaves that material
    /// its colour, with a warning in [`VisualMesh::texture_warnings`].
    pub fn from_glb_surface(
        mesh: &GlbMesh,
        surface: &GlbSurface,
        geometry: &AssetGeometry,
    ) -> Self {
        let mut out = Self::from_glb(mesh, geometry);
        let covered: u64 = surface
            .primitives
            .iter()
            .map(|p| u64::from(p.triangles))
            .sum();
        if covered != out.triangles.len() as u64 {
            out.texture_warnings.push(format!(
                "its primitives cover {covered} of {} triangles: drawn in one grey material",
                out.triangles.len()
            ));
            return out;
        }
        // Triangles by glTF material (`None`: glTF's default material), in material order.
        let mut groups: BTreeMap<Option<usize>, (Vec<u32>, bool)> = BTreeMap::new();
        for p in &surface.primitives {
            let material = p.material.filter(|m| *m < surface.materials.len());
            let entry = groups.entry(material).or_insert((Vec::new(), true));
            entry
                .0
                .extend(p.first_triangle..p.first_triangle + p.triangles);
            entry.1 &= p.has_uvs;
        }
        let mut textures: BTreeMap<usize, Result<usize, String>> = BTreeMap::new();
        let mut materials = Vec::new();
        for (material, (mut triangles, has_uvs)) in groups {
            if triangles.is_empty() {
                continue;
            }
            triangles.sort_unstable();
            let Some(index) = material else {
                materials.push(VisualMaterial::grey(triangles));
                continue;
            };
            let m = &surface.materials[index];
            let mut rgba_linear = m.base_color_factor;
            if m.alpha_mode != AlphaMode::Blend {
                rgba_linear[3] = 1.0;
            }
            let texture = m.base_color_image.and_then(|image| {
                if !has_uvs {
                    out.texture_warnings.push(format!(
                        "material {:?}: a primitive has no TEXCOORD_{}: drawn in its colour \
                         without images[{image}]",
                        m.name, m.tex_coord
                    ));
                    return None;
                }
                let slot = textures.entry(image).or_insert_with(|| {
                    let found = surface.images.get(image);
                    let mime = found.map_or("missing", |i| i.mime_type.as_str());
                    let png = match found.and_then(|i| i.bytes.as_deref()) {
                        Some(bytes) => texture_png(bytes),
                        None => Err("its bytes cannot be found".to_owned()),
                    };
                    png.map(|png| {
                        out.textures.push(VisualTexture {
                            image,
                            png: Arc::new(png),
                        });
                        out.textures.len() - 1
                    })
                    .map_err(|why| format!("images[{image}] ({mime}): {why}"))
                });
                match slot {
                    Ok(k) => Some(*k),
                    Err(why) => {
                        out.texture_warnings
                            .push(format!("{why}: material {:?} drawn in its colour", m.name));
                        None
                    }
                }
            });
            materials.push(VisualMaterial {
                name: m.name.clone(),
                rgba_linear,
                texture,
                triangles,
            });
        }
        if surface.uvs.len() != out.positions_m.len() {
            // Never so from the reader (its attributes are parallel to the vertices); were it
            // so, texture coordinates could not be trusted.
            for m in &mut materials {
                m.texture = None;
            }
            out.textures.clear();
        } else if materials.iter().any(|m| m.texture.is_some()) {
            out.uvs = surface.uvs.clone();
        }
        out.materials = materials;
        out
    }
}

/// The part of a visual mesh drawn with one material, its vertices renumbered.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct MaterialMesh {
    /// The vertices the material's triangles use, in their order in the whole mesh.
    pub positions_m: Vec<[f64; 3]>,
    /// The material's triangles, indices into `positions_m`.
    pub triangles: Vec<[u32; 3]>,
    /// glTF texture coordinates (v pointing down), one per vertex when the material is
    /// textured, else empty.
    pub uvs: Vec<[f32; 2]>,
}

impl VisualMesh {
    /// The part of the mesh drawn with material `k`.
    pub fn material_mesh(&self, k: usize) -> MaterialMesh {
        let material = &self.materials[k];
        let textured = material.texture.is_some() && self.uvs.len() == self.positions_m.len();
        let mut used: Vec<u32> = material
            .triangles
            .iter()
            .flat_map(|&t| self.triangles[t as usize])
            .collect();
        used.sort_unstable();
        used.dedup();
        let mut new_index = vec![0u32; self.positions_m.len()];
        for (new, &old) in used.iter().enumerate() {
            new_index[old as usize] = new as u32;
        }
        MaterialMesh {
            positions_m: used.iter().map(|&v| self.positions_m[v as usize]).collect(),
            triangles: material
                .triangles
                .iter()
                .map(|&t| self.triangles[t as usize].map(|i| new_index[i as usize]))
                .collect(),
            uvs: if textured {
                used.iter().map(|&v| self.uvs[v as usize]).collect()
            } else {
                Vec::new()
            },
        }
    }
}
