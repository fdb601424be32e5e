//! A library asset made ready to draw: its GLB read with its surface ([`read_glb_surface`]),
//! turned into the asset's table-aligned frame (the frame `mesa assets` measures: glTF → table
//! `x = X, y = -Z, z = Y`, then the front alignment yaw), one mesh per material, textures
//! decoded and bounded in size.

use std::collections::BTreeMap;
use std::sync::Arc;

use thiserror::Error;

use crate::assets::table_aligned_from_gltf;
use crate::glb_read::{read_glb_surface, AlphaMode, GlbError, GlbSurface};
use crate::mesh::{closed_outward, Aabb, TriMesh};
use crate::raster::{SurfaceMaterial, Texture};

/// One material's triangles of an asset.
#[derive(Debug, Clone)]
pub struct AssetPart {
    /// The triangles in the asset's table-aligned frame, metres.
    pub mesh: TriMesh,
    /// How they look.
    pub material: SurfaceMaterial,
    /// Linear RGB vertex colours, one per vertex, when the GLB gives `COLOR_0`.
    pub vertex_colors: Option<Vec<[f32; 3]>>,
}

/// An asset ready to draw.
#[derive(Debug, Clone)]
pub struct RenderAsset {
    /// Its parts, one per material used.
    pub parts: Vec<AssetPart>,
    /// Bounds of every vertex in the table-aligned frame (the box a layout's `size` is the
    /// scaled extent of), metres.
    pub bounds: Aabb,
    /// Triangles in all.
    pub triangles: usize,
    /// Whether its parts together bound solids, wound counter-clockwise seen from outside
    /// ([`closed_outward`]): a view from outside never shows a triangle facing away, and the
    /// rasterizer skips those.
    pub closed: bool,
    /// Things drawn differently from a full glTF viewer (alpha ignored, an image that could
    /// not be decoded), and the reader's warnings.
    pub warnings: Vec<String>,
}

impl RenderAsset {
    /// Approximate bytes held (meshes and textures), for cache budgets.
    pub fn heap_bytes(&self) -> usize {
        let mut textures: Vec<*const Texture> = Vec::new();
        let mut bytes = 0;
        for part in &self.parts {
            let m = &part.mesh;
            bytes += m.positions.len() * 12 + m.normals.len() * 12 + m.uvs.len() * 8;
            bytes += m.triangles.len() * 12;
            bytes += part.vertex_colors.as_ref().map_or(0, |c| c.len() * 12);
            if let Some(t) = &part.material.texture {
                let ptr = Arc::as_ptr(t);
                if !textures.contains(&ptr) {
                    textures.push(ptr);
                    bytes += t.rgba.len();
                }
            }
        }
        bytes
    }
}

/// Why an asset cannot be drawn.
#[derive(Debug, Error)]
pub enum RenderAssetError {
    /// The GLB cannot be read.
    #[error("{0}")]
    Glb(#[from] GlbError),
}

/// Reads an asset for drawing. `front_yaw_deg` is its front alignment (the asset index's
/// `front_yaw_deg`); textures larger than `max_texture_px` on a side are reduced (a 512-pixel
/// view never samples more).
pub fn load_render_asset(
    bytes: &[u8],
    front_yaw_deg: f64,
    max_texture_px: u32,
) -> Result<RenderAsset, RenderAssetError> {
    let (mesh, surface) = read_glb_surface(bytes)?;
    let mut warnings = mesh.warnings.clone();
    let textures = decode_images(&surface, max_texture_px, &mut warnings);
    let aligned: Vec<[f64; 3]> = mesh
        .positions_m
        .iter()
        .map(|p| table_aligned_from_gltf(*p, front_yaw_deg))
        .collect();
    let bounds = Aabb::from_points(aligned.iter().copied()).unwrap_or(Aabb::from_point([0.0; 3]));

    // Primitives grouped by material, in order of first use.
    let mut groups: BTreeMap<Option<usize>, usize> = BTreeMap::new();
    let mut order: Vec<Option<usize>> = Vec::new();
    for p in &surface.primitives {
        if let std::collections::btree_map::Entry::Vacant(e) = groups.entry(p.material) {
            e.insert(order.len());
            order.push(p.material);
        }
    }
    let mut parts: Vec<AssetPart> = order
        .iter()
        .map(|m| AssetPart {
            mesh: TriMesh::default(),
            material: material(&surface, *m, &textures),
            vertex_colors: None,
        })
        .collect();
    let mut noted_alpha = false;
    let mut any_colors = vec![false; parts.len()];
    let mut colors: Vec<Vec<[f32; 3]>> = vec![Vec::new(); parts.len()];
    for p in &surface.primitives {
        let k = groups[&p.material];
        if let Some(m) = p.material.and_then(|m| surface.materials.get(m)) {
            if m.alpha_mode != AlphaMode::Opaque && !noted_alpha {
                noted_alpha = true;
                warnings.push(format!(
                    "material \"{}\" has alpha mode {:?}: drawn opaque",
                    m.name, m.alpha_mode
                ));
            }
        }
        let part = &mut parts[k];
        let v0 = p.first_vertex as usize;
        let vn = p.vertices as usize;
        let textured = part.material.texture.is_some();
        let vertex_colors = &surface.colors[v0..v0 + vn];
        if vertex_colors.iter().any(|c| c[..3] != [1.0, 1.0, 1.0]) {
            any_colors[k] = true;
        }
        let triangles =
            &mesh.triangles[p.first_triangle as usize..(p.first_triangle + p.triangles) as usize];
        let out = &mut part.mesh;
        if p.has_normals {
            let base = out.positions.len() as u32;
            for (v, p) in aligned.iter().enumerate().skip(v0).take(vn) {
                out.positions.push(to_f32(*p));
                let n = surface.normals[v];
                out.normals.push(to_f32(table_aligned_from_gltf(
                    [f64::from(n[0]), f64::from(n[1]), f64::from(n[2])],
                    front_yaw_deg,
                )));
                if textured {
                    out.uvs.push(surface.uvs[v]);
                }
                colors[k].push(rgb(surface.colors[v]));
            }
            out.triangles.extend(triangles.iter().map(|t| {
                [
                    t[0] - v0 as u32 + base,
                    t[1] - v0 as u32 + base,
                    t[2] - v0 as u32 + base,
                ]
            }));
        } else {
            // glTF: without normals, flat shading: each triangle gets its own corners.
            for t in triangles {
                let corners = t.map(|i| aligned[i as usize]);
                let n = crate::mesh::normalize3(crate::mesh::cross3(
                    crate::mesh::sub3(corners[1], corners[0]),
                    crate::mesh::sub3(corners[2], corners[0]),
                ));
                let base = out.positions.len() as u32;
                for (c, &i) in corners.iter().zip(t) {
                    out.positions.push(to_f32(*c));
                    out.normals.push(to_f32(n));
                    if textured {
                        out.uvs.push(surface.uvs[i as usize]);
                    }
                    colors[k].push(rgb(surface.colors[i as usize]));
                }
                out.triangles.push([base, base + 1, base + 2]);
            }
        }
    }
    for (k, part) in parts.iter_mut().enumerate() {
        if any_colors[k] {
            part.vertex_colors = Some(std::mem::take(&mut colors[k]));
        }
    }
    parts.retain(|p| !p.mesh.triangles.is_empty());
    Ok(RenderAsset {
        triangles: parts.iter().map(|p| p.mesh.triangles.len()).sum(),
        closed: closed_outward(parts.iter().map(|p| &p.mesh)),
        parts,
        bounds,
        warnings,
    })
}

fn to_f32(p: [f64; 3]) -> [f32; 3] {
    [p[0] as f32, p[1] as f32, p[2] as f32]
}

fn rgb(c: [f32; 4]) -> [f32; 3] {
    [c[0], c[1], c[2]]
}

/// glTF's default material: white, fully rough, as a viewer shows an asset without one.
const DEFAULT_ROUGHNESS: f32 = 0.8;

fn material(
    surface: &GlbSurface,
    index: Option<usize>,
    textures: &[Option<Arc<Texture>>],
) -> SurfaceMaterial {
    let Some(m) = index.and_then(|i| surface.materials.get(i)) else {
        return SurfaceMaterial::plain([0.8; 3], DEFAULT_ROUGHNESS);
    };
    let f = m.base_color_factor;
    SurfaceMaterial {
        base_color: [f[0], f[1], f[2]],
        texture: m
            .base_color_image
            .and_then(|i| textures.get(i).cloned().flatten()),
        roughness: DEFAULT_ROUGHNESS,
    }
}

/// Decodes every image (PNG or JPEG) to sRGB RGBA, reduced to at most `max_px` a side.
fn decode_images(
    surface: &GlbSurface,
    max_px: u32,
    warnings: &mut Vec<String>,
) -> Vec<Option<Arc<Texture>>> {
    surface
        .images
        .iter()
        .enumerate()
        .map(|(i, image)| {
            let bytes = image.bytes.as_deref()?;
            match image::load_from_memory(bytes) {
                Ok(decoded) => {
                    let mut rgba = decoded.to_rgba8();
                    let (w, h) = rgba.dimensions();
                    if w.max(h) > max_px.max(1) {
                        let k = f64::from(max_px.max(1)) / f64::from(w.max(h));
                        let nw = ((f64::from(w) * k).round() as u32).max(1);
                        let nh = ((f64::from(h) * k).round() as u32).max(1);
                        rgba = image::imageops::resize(
                            &rgba,
                            nw,
                            nh,
                            image::imageops::FilterType::Triangle,
                        );
                    }
                    let (width, height) = rgba.dimensions();
                    Some(Arc::new(Texture {
                        width,
                        height,
                        rgba: rgba.into_raw(),
                    }))
                }
                Err(e) => {
                    warnings.push(format!(
                        "images[{i}] ({}): cannot be decoded ({e}): textures using it are drawn \
                         without it",
                        image.mime_type
                    ));
                    None
                }
            }
        })
        .collect()
}
