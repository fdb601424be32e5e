//! `render` (SPEC 5.10): pictures of a layout with its assets, on the CPU, with the
//! rasterizer of [`crate::raster`].
//!
//! - Scene views ([`SceneView`]): `front` and `perspective` (the views the multimodal prompts
//!   use) and `back`, `left`, `right` for QA, framed as MesaTask's own renderer frames them
//!   ([`camera`]).
//! - Asset views: eight views around z of one asset, for annotating assets with a
//!   vision-language model and checking their front alignment.
//!
//! A picture is drawn with base-colour textures (and vertex colours), one directional light
//! with a shadow map plus a weaker fill light and hemisphere ambient light, the table as a
//! slab over the placement zone (the sink's restricted zone marked on it), `supersampling`²
//! samples per pixel, on a transparent (alpha = coverage) or black background. Each view also
//! gets a camera file (intrinsics, the table-from-camera pose, and the pixels each object
//! covers).
//!
//! Cost: only silhouette pixels are sampled `supersampling`² times, the rest once (the same
//! bytes as sampling all of them, see [`render_picture_shadowed`]), and the views of one
//! scene share its shadow map ([`LayoutScene`]).
//!
//! An object is drawn as MesaTask's reader (`dataset/reconstruct_blender.py`) places it: the
//! asset's vertices in its table-aligned frame (the frame `mesa assets` measures), moved so
//! their bounding-box centre is at the origin, scaled per axis to the layout's `size`, turned
//! by `rotation`, moved to `position`.
//!
//! Everything here is deterministic and single-threaded per view; callers run views and
//! scenes in parallel.

pub mod asset;
pub mod camera;

use std::collections::BTreeMap;
use std::ops::Range;
use std::sync::OnceLock;

use mesa_schemas::render::{RenderCameraArtifact, RENDER_CAMERA_SCHEMA};
use mesa_schemas::DatasetLayout;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::image_io::{encode_rgb8, encode_rgba8, ImageError};
use crate::mesh::{closed_outward, normalize3, Aabb, Affine3, TriMesh};
use crate::raster::{
    linear_to_srgb_u8, srgb_u8_to_linear, visibility, visibility_of_selected, DirectionalLight,
    DrawItem, Hit, Lighting, SampleMask, Shader, ShadowMap, SurfaceMaterial, VisibilityBuffer,
};

pub use asset::{load_render_asset, AssetPart, RenderAsset, RenderAssetError};
pub use camera::{SceneView, ViewCamera, ASSET_VIEWS};

/// Which layout of a scene `mesa render` draws.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum LayoutChoice {
    /// The most refined present: `qa/layout.json` (settled), else `refined/layout.json` (what
    /// the annotator returned). A scene with neither fails.
    Refined,
    /// `coarse/layout.json`, the placement before the annotator (for looking at it, and for
    /// datasets without an annotation round).
    Coarse,
    /// `truth/layout.json` of a `mesa demo` scene.
    Truth,
}

impl LayoutChoice {
    /// The layout files this choice reads, in order of preference, relative to the scene.
    pub fn candidates(self) -> &'static [&'static str] {
        match self {
            LayoutChoice::Refined => &crate::paths::scene::LAYOUT_CANDIDATES,
            LayoutChoice::Coarse => &[crate::paths::scene::COARSE_LAYOUT],
            LayoutChoice::Truth => &[crate::paths::scene::TRUTH_LAYOUT],
        }
    }
}

/// Background of the pictures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Background {
    /// RGBA; alpha is the fraction of a pixel's samples that hit something.
    Transparent,
    /// RGB over black.
    Black,
}

impl Background {
    /// The name written into camera files.
    pub fn name(self) -> &'static str {
        match self {
            Background::Transparent => "transparent",
            Background::Black => "black",
        }
    }
}

/// The `[render]` section of `mesa.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct RenderConfig {
    /// The layout drawn: "refined" (qa/layout.json, else refined/layout.json; the default),
    /// "coarse" (coarse/layout.json, before the annotator) or "truth" (a demo scene's
    /// truth/layout.json). `mesa render --layout` overrides it.
    pub layout: LayoutChoice,
    /// Picture width in pixels.
    pub width_px: u32,
    /// Picture height in pixels.
    pub height_px: u32,
    /// Samples per pixel along each axis (2: 4 samples a pixel, anti-aliased edges).
    pub supersampling: u32,
    /// "transparent" (RGBA PNG, as MesaTask's renders) or "black" (RGB PNG).
    pub background: Background,
    /// Horizontal field of view of scene views in degrees (39.6: MesaTask's 50 mm lens on a
    /// 36 mm sensor).
    pub fov_x_deg: f64,
    /// Scene views: camera distance as a multiple of the scene box's largest side (MesaTask:
    /// 1.5); farther when the box would be cut at the picture's edges.
    pub distance_factor: f64,
    /// Cast shadows from the main light (a shadow map).
    pub shadows: bool,
    /// Textures larger than this on a side, in pixels, are reduced when an asset is loaded.
    pub max_texture_px: u32,
    /// Asset views: the camera's elevation above the horizontal, degrees.
    pub asset_elevation_deg: f64,
    /// Asset views: the fraction of the picture's half-size the asset's bounding sphere
    /// fills.
    pub asset_fill: f64,
    /// Loaded assets kept in memory between scenes, megabytes (meshes and decoded
    /// textures); 0 keeps none.
    pub asset_cache_mb: u64,
}

impl Default for RenderConfig {
    fn default() -> Self {
        Self {
            layout: LayoutChoice::Refined,
            width_px: 512,
            height_px: 512,
            supersampling: 2,
            background: Background::Transparent,
            fov_x_deg: 39.6,
            distance_factor: 1.5,
            shadows: true,
            max_texture_px: 1024,
            asset_elevation_deg: 20.0,
            asset_fill: 0.9,
            asset_cache_mb: 1024,
        }
    }
}

impl RenderConfig {
    /// Values that parse but cannot work, each with the key and the fix.
    pub fn problems(&self) -> Vec<String> {
        let mut out = Vec::new();
        if !(16..=8192).contains(&self.width_px) || !(16..=8192).contains(&self.height_px) {
            out.push(format!(
                "[render] width_px = {}, height_px = {}: a picture is 16 to 8192 pixels a side",
                self.width_px, self.height_px
            ));
        }
        if !(1..=8).contains(&self.supersampling) {
            out.push(format!(
                "[render] supersampling = {}: expected 1 to 8 samples per pixel along each axis",
                self.supersampling
            ));
        }
        if !(self.fov_x_deg > 1.0 && self.fov_x_deg < 170.0) {
            out.push(format!(
                "[render] fov_x_deg = {}: expected a field of view between 1 and 170 degrees",
                self.fov_x_deg
            ));
        }
        if !(self.distance_factor > 0.1 && self.distance_factor.is_finite()) {
            out.push(format!(
                "[render] distance_factor = {}: expected a number above 0.1",
                self.distance_factor
            ));
        }
        if self.max_texture_px < 1 {
            out.push("[render] max_texture_px = 0: expected at least 1".to_owned());
        }
        if !(self.asset_fill > 0.0 && self.asset_fill <= 1.0) {
            out.push(format!(
                "[render] asset_fill = {}: expected a fraction in (0, 1]",
                self.asset_fill
            ));
        }
        if !(-89.0..=89.0).contains(&self.asset_elevation_deg) {
            out.push(format!(
                "[render] asset_elevation_deg = {}: expected -89 to 89 degrees",
                self.asset_elevation_deg
            ));
        }
        out
    }
}

/// Why a layout cannot be drawn.
#[derive(Debug, Error)]
pub enum RenderError {
    /// An object names no asset.
    #[error("$.objects[{index}] ({instance}): retrieved_uid is empty (expected the uid of a library asset; run `mesa retrieve` and `mesa place`, or fix the layout)")]
    NoAsset {
        /// The object's index.
        index: usize,
        /// Its instance.
        instance: String,
    },
    /// An object's asset is not available.
    #[error("$.objects[{index}] ({instance}): asset {uid}: {reason}")]
    Asset {
        /// The object's index.
        index: usize,
        /// Its instance.
        instance: String,
        /// The asset.
        uid: String,
        /// Why it cannot be drawn.
        reason: String,
    },
    /// An object's size cannot scale its asset.
    #[error("$.objects[{index}] ({instance}).size: {size_cm:?} cm is not a positive size (expected three numbers above 0)")]
    BadSize {
        /// The object's index.
        index: usize,
        /// Its instance.
        instance: String,
        /// The size.
        size_cm: [f64; 3],
    },
    /// A picture cannot be encoded.
    #[error("{0}")]
    Image(#[from] ImageError),
}

/// One object of a layout, ready to draw.
#[derive(Debug, Clone)]
pub struct PlacedObject<'a> {
    /// Its instance name.
    pub instance: String,
    /// Its asset.
    pub asset: &'a RenderAsset,
    /// Asset table-aligned frame → table frame (metres).
    pub table_from_asset: Affine3,
}

/// The map placing an asset as MesaTask's reader does (see the module documentation), and a
/// note when the layout's `scale_factor` disagrees with its `size` by more than 1 %.
pub fn table_from_asset(
    position_cm: [f64; 3],
    rotation_xyzw: [f64; 4],
    size_cm: [f64; 3],
    scale_factor: [f64; 3],
    asset_bounds: &Aabb,
) -> (Affine3, Option<String>) {
    let asset_size = asset_bounds.size();
    let centre = asset_bounds.center();
    let scale: [f64; 3] = std::array::from_fn(|k| {
        if asset_size[k] > 1e-9 {
            size_cm[k] / 100.0 / asset_size[k]
        } else {
            scale_factor[k]
        }
    });
    let disagrees = (0..3).any(|k| {
        scale_factor[k] > 0.0 && ((scale[k] - scale_factor[k]) / scale_factor[k]).abs() > 0.01
    });
    let note = disagrees.then(|| {
        format!(
            "scale_factor {scale_factor:?} disagrees with size {size_cm:?} cm over the asset's \
             {:?} m: drawn at size (scale {:?}), as MesaTask's reader does",
            asset_size.map(|v| (v * 1e4).round() / 1e4),
            scale.map(|v| (v * 1e4).round() / 1e4)
        )
    });
    let q = crate::mesh::quat_normalize(rotation_xyzw);
    let map = Affine3::from_trs(position_cm.map(|v| v / 100.0), q, scale).mul(
        &Affine3::from_translation([-centre[0], -centre[1], -centre[2]]),
    );
    (map, note)
}

/// Places every object of a layout, with `asset_of(uid)` giving each asset (or why it cannot
/// be drawn). Also returns notes about objects drawn differently from their fields.
pub fn place_layout<'a, F>(
    layout: &DatasetLayout,
    mut asset_of: F,
) -> Result<(Vec<PlacedObject<'a>>, Vec<String>), RenderError>
where
    F: FnMut(&str) -> Result<&'a RenderAsset, String>,
{
    let mut placed = Vec::with_capacity(layout.objects.len());
    let mut notes = Vec::new();
    for (index, object) in layout.objects.iter().enumerate() {
        if object.retrieved_uid.is_empty() {
            return Err(RenderError::NoAsset {
                index,
                instance: object.instance.clone(),
            });
        }
        let size_cm = object.size_cm.0;
        if size_cm.iter().any(|v| !(*v > 0.0 && v.is_finite())) {
            return Err(RenderError::BadSize {
                index,
                instance: object.instance.clone(),
                size_cm,
            });
        }
        let asset = asset_of(&object.retrieved_uid).map_err(|reason| RenderError::Asset {
            index,
            instance: object.instance.clone(),
            uid: object.retrieved_uid.clone(),
            reason,
        })?;
        let (map, note) = table_from_asset(
            object.position_cm.0,
            object.rotation.0,
            size_cm,
            object.scale_factor.0,
            &asset.bounds,
        );
        if let Some(note) = note {
            notes.push(format!("{}: {note}", object.instance));
        }
        placed.push(PlacedObject {
            instance: object.instance.clone(),
            asset,
            table_from_asset: map,
        });
    }
    Ok((placed, notes))
}

/// Thickness of the drawn table slab, metres.
const TABLE_THICKNESS_M: f64 = 0.03;

/// How far below the table top an object may reach before the slab must cast shadows on it
/// (objects rest on the top up to rounding; a part that dips in is inside the slab, hidden).
const SLAB_SHADOW_TOLERANCE_M: f64 = 1e-4;

/// The table: a slab over the placement zone with its top at z = 0, and the restricted zone
/// (the sink) as a thin dark plate on it.
pub struct TableGeometry {
    slab: TriMesh,
    slab_material: SurfaceMaterial,
    /// Whether the slab goes into the shadow map. Its top face is its highest point and every
    /// light shines from above, so it can only shade what lies below the top: the slab itself
    /// (whose faces turned to a light are lit and whose others are dark anyway) and objects
    /// that reach below the top. Left out when no object does, it costs the shadow map a
    /// million texels less and changes no pixel.
    slab_casts_shadow: bool,
    sink: Option<TriMesh>,
    sink_material: SurfaceMaterial,
    /// The bounds of the slab and of the sink when they are closed (boxes are: their faces
    /// turned away are skipped, [`DrawItem::closed_within`]).
    closed_within: [Option<Aabb>; 2],
}

fn srgb(c: [u8; 3]) -> [f32; 3] {
    c.map(srgb_u8_to_linear)
}

impl TableGeometry {
    /// The table of a zone `[x_min, x_max, y_min, y_max]` and an optional restricted zone, cm.
    pub fn new(zone_cm: [f64; 4], restricted_cm: Option<[f64; 4]>) -> Self {
        let box_of = |z: [f64; 4], bottom: f64, top: f64| {
            let (x0, x1, y0, y1) = (z[0] / 100.0, z[1] / 100.0, z[2] / 100.0, z[3] / 100.0);
            TriMesh::cuboid([x1 - x0, y1 - y0, top - bottom]).transformed(
                &Affine3::from_translation([
                    (x0 + x1) / 2.0,
                    (y0 + y1) / 2.0,
                    (top + bottom) / 2.0,
                ]),
            )
        };
        let slab = box_of(zone_cm, -TABLE_THICKNESS_M, 0.0);
        let sink = restricted_cm.map(|z| box_of(z, -0.0005, 0.0005));
        let closed = |mesh: &TriMesh| closed_outward([mesh]).then(|| mesh.bounds()).flatten();
        Self {
            closed_within: [closed(&slab), sink.as_ref().and_then(closed)],
            slab,
            slab_casts_shadow: true,
            slab_material: SurfaceMaterial::plain(srgb([178, 136, 96]), 0.7),
            // Half a millimetre proud of the top: drawn over it, and far below any contact
            // tolerance.
            sink,
            sink_material: SurfaceMaterial::plain(srgb([78, 98, 140]), 0.4),
        }
    }
}

/// Whether the table slab can shade objects with these bounds (table frame, metres): when they
/// reach below its top ([`TableGeometry`]'s `slab_casts_shadow`).
fn slab_shades(objects: Option<&Aabb>) -> bool {
    objects.is_some_and(|b| b.min[2] < -SLAB_SHADOW_TOLERANCE_M)
}

/// The draw list of a placed layout: objects (instance = index + 1), then the table and the
/// sink (instance 0).
pub fn draw_items<'a>(
    objects: &'a [PlacedObject<'a>],
    table: Option<&'a TableGeometry>,
) -> Vec<DrawItem<'a>> {
    let mut items = Vec::new();
    for (i, object) in objects.iter().enumerate() {
        for part in &object.asset.parts {
            items.push(DrawItem {
                mesh: &part.mesh,
                world_from_mesh: object.table_from_asset,
                material: &part.material,
                instance: i as u32 + 1,
                casts_shadow: true,
                vertex_colors: part.vertex_colors.as_deref(),
                closed_within: object.asset.closed.then_some(object.asset.bounds),
            });
        }
    }
    if let Some(table) = table {
        items.push(DrawItem {
            mesh: &table.slab,
            world_from_mesh: Affine3::IDENTITY,
            material: &table.slab_material,
            instance: 0,
            casts_shadow: table.slab_casts_shadow,
            vertex_colors: None,
            closed_within: table.closed_within[0],
        });
        if let Some(sink) = &table.sink {
            items.push(DrawItem {
                mesh: sink,
                world_from_mesh: Affine3::IDENTITY,
                material: &table.sink_material,
                instance: 0,
                casts_shadow: false,
                vertex_colors: None,
                closed_within: table.closed_within[1],
            });
        }
    }
    items
}

/// The bounds of every placed object, table frame, metres.
pub fn objects_bounds(objects: &[PlacedObject<'_>]) -> Option<Aabb> {
    objects
        .iter()
        .map(|o| o.asset.bounds.transformed(&o.table_from_asset))
        .reduce(|a, b| a.union(&b))
}

/// The lights: a main light from the front right above (where MesaTask's area light is),
/// casting shadows over `shadow_region` when `shadows`; a weak fill light from the left; sky
/// and ground ambient light.
pub fn lighting(shadow_region: Option<Aabb>, shadows: bool) -> Lighting {
    Lighting {
        up_world: [0.0, 0.0, 1.0],
        sky_color: [0.42, 0.42, 0.45],
        ground_color: [0.2, 0.19, 0.18],
        lights: vec![
            DirectionalLight {
                toward_light_world: normalize3([0.8, -0.8, 1.2]),
                color: [0.85, 0.83, 0.8],
                casts_shadow: shadows,
            },
            DirectionalLight {
                toward_light_world: normalize3([-0.7, -0.3, 0.6]),
                color: [0.18, 0.18, 0.2],
                casts_shadow: false,
            },
        ],
        shadow_region: if shadows { shadow_region } else { None },
        shadow_map_px: 1024,
        background_srgb: [0, 0, 0],
    }
}

/// A rendered picture.
#[derive(Debug, Clone, PartialEq)]
pub struct Picture {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Row-major sRGB RGBA, straight alpha (alpha = coverage).
    pub rgba: Vec<u8>,
    /// Per pixel, the instance seen at its centre `(u, v)` (0: nothing, or the table).
    pub instances: Vec<u32>,
}

impl Picture {
    /// The PNG of the picture on `background`.
    pub fn png(&self, background: Background) -> Result<Vec<u8>, ImageError> {
        match background {
            Background::Transparent => encode_rgba8(self.width, self.height, &self.rgba),
            Background::Black => {
                let rgb: Vec<u8> = self
                    .rgba
                    .chunks_exact(4)
                    .flat_map(|p| {
                        let a = f32::from(p[3]) / 255.0;
                        [0, 1, 2].map(|k| linear_to_srgb_u8(srgb_u8_to_linear(p[k]) * a))
                    })
                    .collect();
                encode_rgb8(self.width, self.height, &rgb)
            }
        }
    }

    /// Pixels per instance (instance ids as drawn: 1 + object index).
    pub fn instance_pixels(&self) -> BTreeMap<u32, u64> {
        let mut out = BTreeMap::new();
        for &i in &self.instances {
            if i != 0 {
                *out.entry(i).or_insert(0) += 1;
            }
        }
        out
    }
}

/// Draws `items` from `camera` with `supersampling`² visibility samples per pixel, shading
/// each object once per pixel (at its first sample there, as multisampling does): colour is
/// the sample-weighted mean in linear light over the samples that hit something, alpha their
/// fraction. The instance map samples each pixel at its centre.
pub fn render_picture(
    items: &[DrawItem<'_>],
    camera: &ViewCamera,
    lighting: &Lighting,
    supersampling: u32,
) -> Picture {
    let shadow = ShadowMap::of_lighting(lighting, items);
    render_picture_shadowed(items, camera, lighting, supersampling, shadow.as_ref())
}

/// Which pixels need all their samples: those whose centre sees another item than the centre of
/// one of its eight neighbours (those nine centres enclose all its samples), and the pixels of
/// the picture's border (their outer samples lie beyond every centre), grown by one pixel, so
/// that a part thinner than a pixel between centres is still found where a neighbour's centre
/// sees it. Everywhere else one item covers the pixel, and it is shaded at its centre.
fn silhouette_pixels(centres: &VisibilityBuffer) -> Vec<bool> {
    let (w, h) = (centres.width as usize, centres.height as usize);
    if w == 0 || h == 0 {
        return Vec::new();
    }
    // Row by row: the 2×2 block of centres whose top left is (x, y) is not of one item. A
    // pixel differs from a neighbour exactly when one of the four blocks holding it does.
    let mut block = vec![false; w * h];
    for y in 0..h - 1 {
        let row = &centres.item[y * w..(y + 1) * w];
        let below = &centres.item[(y + 1) * w..(y + 2) * w];
        let out = &mut block[y * w..(y + 1) * w];
        for x in 0..w - 1 {
            let item = row[x];
            out[x] = (row[x + 1] != item) | (below[x] != item) | (below[x + 1] != item);
        }
    }
    let mut differs = vec![false; w * h];
    for y in 0..h {
        let out = &mut differs[y * w..(y + 1) * w];
        if y == 0 || y + 1 == h {
            out.fill(true);
            continue;
        }
        let (above, here) = (&block[(y - 1) * w..y * w], &block[y * w..(y + 1) * w]);
        out[0] = true;
        out[w - 1] = true;
        for x in 1..w - 1 {
            out[x] = above[x - 1] | above[x] | here[x - 1] | here[x];
        }
    }
    // Grown by one pixel: a 3×3 dilation, done as a horizontal then a vertical pass.
    let mut wide = vec![false; w * h];
    for (row, out) in differs.chunks_exact(w).zip(wide.chunks_exact_mut(w)) {
        out[0] = row[0] | row.get(1).is_some_and(|&d| d);
        for x in 1..w - 1 {
            out[x] = row[x - 1] | row[x] | row[x + 1];
        }
        if w > 1 {
            out[w - 1] = row[w - 2] | row[w - 1];
        }
    }
    let mut selected = vec![false; w * h];
    for (y, out) in selected.chunks_exact_mut(w).enumerate() {
        let (lo, hi) = (y.saturating_sub(1), (y + 1).min(h - 1));
        out.copy_from_slice(&wide[y * w..(y + 1) * w]);
        for yy in [lo, hi] {
            for (o, &d) in out.iter_mut().zip(&wide[yy * w..(yy + 1) * w]) {
                *o |= d;
            }
        }
    }
    selected
}

/// [`render_picture`] with the shadow map built beforehand (`shadow`: [`ShadowMap::of_lighting`]
/// of the same `lighting` and `items`), so that the views of one scene share it.
///
/// Only silhouette pixels (`silhouette_pixels`) are sampled `supersampling`² times; the
/// others are shaded once at their first sample. Where the silhouette test is right (one item
/// under all samples of a pixel it leaves out) the picture is the same, byte for byte, as
/// sampling every pixel fully: that pixel's samples all hit that item, and its colour is that
/// item's shade at its first sample either way.
pub fn render_picture_shadowed(
    items: &[DrawItem<'_>],
    camera: &ViewCamera,
    lighting: &Lighting,
    supersampling: u32,
    shadow: Option<&ShadowMap>,
) -> Picture {
    render_selected(
        items,
        camera,
        lighting,
        supersampling,
        shadow,
        silhouette_pixels,
    )
}

/// Which pixels are sampled fully, from what the centres see.
type Selection = fn(&VisibilityBuffer) -> Vec<bool>;

/// [`render_picture_shadowed`] with the pixels sampled fully chosen by `select`.
fn render_selected(
    items: &[DrawItem<'_>],
    camera: &ViewCamera,
    lighting: &Lighting,
    supersampling: u32,
    shadow: Option<&ShadowMap>,
    select: Selection,
) -> Picture {
    let f = supersampling.max(1);
    let intrinsics = camera.intrinsics;
    let camera_from_table = camera
        .table_from_camera
        .inverse()
        .unwrap_or(Affine3::IDENTITY);
    let shader = Shader::with_shadow_map(&camera_from_table, items, lighting, shadow);
    let (w, h) = (intrinsics.width as usize, intrinsics.height as usize);
    // What each pixel's centre (u, v) sees, as the camera files say pixels are sampled: the
    // silhouettes of the picture in SPEC 2's convention, comparable with masks, the point
    // where a pixel is shaded, and what chooses the pixels sampled fully.
    let centres = visibility(&intrinsics, &camera_from_table, items);
    let instances: Vec<u32> = centres.instance_ids(items);
    let mut rgba = vec![0u8; w * h * 4];
    let mut put = |p: usize, color: [f32; 3], alpha: u8| {
        for k in 0..3 {
            rgba[p * 4 + k] = linear_to_srgb_u8(color[k]);
        }
        rgba[p * 4 + 3] = alpha;
    };
    // The silhouettes' samples, when pixels have more than one.
    let sampled = (f > 1).then(|| {
        let mask = SampleMask::new(intrinsics.width, intrinsics.height, f, &select(&centres));
        let samples = visibility_of_selected(
            &intrinsics.supersampled(f),
            &camera_from_table,
            items,
            &mask,
        );
        (mask, samples)
    });
    let per_pixel = (f * f) as usize;
    // Row by row: the row's pixels planned, then shaded in one batch.
    let mut batch = Batch::default();
    for y in 0..h {
        for p in y * w..(y + 1) * w {
            let silhouette = sampled
                .as_ref()
                .and_then(|(mask, samples)| Some((mask.samples_of(p)?, samples)));
            match silhouette {
                Some((at, samples)) => batch.add_samples(Pixel {
                    samples,
                    at: at..at + per_pixel,
                    centres: &centres,
                    p,
                }),
                None => batch.add_centre(&centres, p),
            }
        }
        batch.finish(&shader, per_pixel, &mut put);
    }
    Picture {
        width: intrinsics.width,
        height: intrinsics.height,
        rgba,
        instances,
    }
}

/// The samples of one pixel: their indices `at` in `samples`, in order, and the pixel's index
/// `p` in `centres`.
struct Pixel<'a, I> {
    samples: &'a VisibilityBuffer,
    at: I,
    centres: &'a VisibilityBuffer,
    p: usize,
}

/// The shading of a run of pixels, planned pixel by pixel and then shaded in one batch
/// ([`Shader::shade_hits`], whose lighting runs in SIMD over many hits).
#[derive(Default)]
struct Batch {
    /// What is shaded.
    hits: Vec<Hit>,
    /// Per hit, how many of its pixel's samples it stands for.
    weights: Vec<usize>,
    /// The planned pixels, in order.
    pixels: Vec<Planned>,
    /// Per hit, its colour (scratch of [`Batch::finish`]).
    colors: Vec<[f32; 3]>,
    /// (item, first sample, samples) of the pixel being planned (scratch).
    items: Vec<(u32, usize, usize)>,
}

/// A pixel of a [`Batch`].
enum Planned {
    /// Pixel `p` is the colour of hit `hit`, opaque.
    Centre { p: usize, hit: usize },
    /// Pixel `p` is the mean of hits `hits`, each weighted by its samples, over the `covered`
    /// samples that hit something; alpha is the fraction of the pixel's samples covered.
    Samples {
        p: usize,
        hits: Range<usize>,
        covered: usize,
    },
}

impl Batch {
    /// Plans pixel `p`, one sample at its centre: what the centre sees, if anything.
    fn add_centre(&mut self, centres: &VisibilityBuffer, p: usize) {
        if centres.item[p] != u32::MAX {
            self.pixels.push(Planned::Centre {
                p,
                hit: self.hits.len(),
            });
            self.hits.push(centres.hit(p));
            self.weights.push(1);
        }
    }

    /// Plans a pixel from its samples: each item they hit is shaded once (at the pixel's
    /// centre when the centre sees it, else at its first sample) and weighted by its samples.
    /// Nothing when no sample hits anything.
    fn add_samples(&mut self, pixel: Pixel<'_, impl Iterator<Item = usize>>) {
        let Pixel {
            samples,
            at,
            centres,
            p,
        } = pixel;
        self.items.clear();
        for o in at {
            let item = samples.item[o];
            if item == u32::MAX {
                continue;
            }
            match self.items.iter_mut().find(|(i, _, _)| *i == item) {
                Some((_, _, n)) => *n += 1,
                None => self.items.push((item, o, 1)),
            }
        }
        let covered: usize = self.items.iter().map(|(_, _, n)| n).sum();
        if covered == 0 {
            return;
        }
        let first = self.hits.len();
        for &(item, o, n) in &self.items {
            self.hits.push(if centres.item[p] == item {
                centres.hit(p)
            } else {
                samples.hit(o)
            });
            self.weights.push(n);
        }
        self.pixels.push(Planned::Samples {
            p,
            hits: first..self.hits.len(),
            covered,
        });
    }

    /// Shades the planned hits and gives `put` each planned pixel's colour and alpha (of
    /// `per_pixel` samples a pixel), in order; the batch is then empty.
    fn finish(
        &mut self,
        shader: &Shader<'_, '_>,
        per_pixel: usize,
        mut put: impl FnMut(usize, [f32; 3], u8),
    ) {
        self.colors.resize(self.hits.len(), [0.0; 3]);
        shader.shade_hits(&self.hits, &mut self.colors);
        for pixel in self.pixels.drain(..) {
            match pixel {
                Planned::Centre { p, hit } => put(p, self.colors[hit], 255),
                Planned::Samples { p, hits, covered } => {
                    let mut acc = [0f32; 3];
                    for h in hits {
                        let (c, n) = (self.colors[h], self.weights[h]);
                        for k in 0..3 {
                            acc[k] += c[k] * n as f32;
                        }
                    }
                    let alpha = ((covered * 255 + per_pixel / 2) / per_pixel) as u8;
                    put(p, acc.map(|a| a / covered as f32), alpha);
                }
            }
        }
        self.hits.clear();
        self.weights.clear();
    }
}

/// One rendered view: its picture (PNG) and camera file.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderedView {
    /// The view's name (the PNG is `<name>.png`, the camera `<name>_camera.json`).
    pub name: String,
    /// The PNG bytes.
    pub png: Vec<u8>,
    /// The camera file.
    pub camera: RenderCameraArtifact,
    /// The decoded picture.
    pub picture: Picture,
}

fn camera_artifact(
    name: &str,
    camera: &ViewCamera,
    config: &RenderConfig,
    visible_px: BTreeMap<String, u64>,
) -> RenderCameraArtifact {
    let k = camera.intrinsics;
    RenderCameraArtifact {
        schema: RENDER_CAMERA_SCHEMA.to_owned(),
        view: name.to_owned(),
        image: format!("{name}.png"),
        width: k.width,
        height: k.height,
        fx: k.fx,
        fy: k.fy,
        cx: k.cx,
        cy: k.cy,
        fov_x_deg: k.fov_x_deg(),
        table_from_camera: camera.table_from_camera.to_rows_4x4(),
        look_at_m: camera.look_at_m,
        layout: None,
        layout_sha256: None,
        uid: None,
        azimuth_deg: None,
        elevation_deg: None,
        background: config.background.name().to_owned(),
        supersampling: config.supersampling,
        visible_px,
    }
}

/// A placed layout ready to render from any view.
pub struct LayoutScene<'a> {
    /// The objects.
    pub objects: &'a [PlacedObject<'a>],
    /// The table.
    pub table: TableGeometry,
    /// The box scene views frame.
    pub frame: Aabb,
    /// The lights.
    pub lighting: Lighting,
    /// The shadow map of `lighting` over the objects and the table, built by the first view
    /// and shared by the others (it does not depend on the camera); so `lighting` and
    /// `objects` must not change once a view is rendered.
    shadow: OnceLock<Option<ShadowMap>>,
}

impl<'a> LayoutScene<'a> {
    /// The scene of placed `objects` on the table of `layout`.
    pub fn new(
        layout: &DatasetLayout,
        objects: &'a [PlacedObject<'a>],
        config: &RenderConfig,
    ) -> Self {
        let zone = layout.zone_cm.0;
        let mut table = TableGeometry::new(zone, layout.restricted_zone_cm.as_ref().map(|z| z.0));
        let bounds = objects_bounds(objects);
        table.slab_casts_shadow = slab_shades(bounds.as_ref());
        let top = bounds.as_ref().map_or(0.0, |b| b.max[2]);
        let zone_m = zone.map(|v| v / 100.0);
        let frame = camera::scene_box(zone_m, top);
        let mut shadow_region = Aabb {
            min: [zone_m[0] - 0.1, zone_m[2] - 0.1, -TABLE_THICKNESS_M],
            max: [zone_m[1] + 0.1, zone_m[3] + 0.1, top.max(0.01)],
        };
        if let Some(b) = bounds {
            shadow_region = shadow_region.union(&b);
        }
        Self {
            objects,
            table,
            frame,
            lighting: lighting(Some(shadow_region), config.shadows),
            shadow: OnceLock::new(),
        }
    }

    /// Renders one scene view.
    pub fn render_view(
        &self,
        view: SceneView,
        config: &RenderConfig,
    ) -> Result<RenderedView, RenderError> {
        let camera = camera::scene_camera(
            view,
            &self.frame,
            config.width_px,
            config.height_px,
            config.fov_x_deg,
            config.distance_factor,
        );
        self.render_from(view.name(), &camera, config)
    }

    /// Renders from any camera (the picture is named `name`).
    pub fn render_from(
        &self,
        name: &str,
        camera: &ViewCamera,
        config: &RenderConfig,
    ) -> Result<RenderedView, RenderError> {
        let items = draw_items(self.objects, Some(&self.table));
        let shadow = self
            .shadow
            .get_or_init(|| ShadowMap::of_lighting(&self.lighting, &items));
        let picture = render_picture_shadowed(
            &items,
            camera,
            &self.lighting,
            config.supersampling,
            shadow.as_ref(),
        );
        let pixels = picture.instance_pixels();
        let visible_px = self
            .objects
            .iter()
            .enumerate()
            .map(|(i, o)| {
                (
                    o.instance.clone(),
                    pixels.get(&(i as u32 + 1)).copied().unwrap_or(0),
                )
            })
            .collect();
        Ok(RenderedView {
            name: name.to_owned(),
            png: picture.png(config.background)?,
            camera: camera_artifact(name, camera, config, visible_px),
            picture,
        })
    }
}

/// The name of asset view `k`: `view_<azimuth>` (`view_000`, `view_045`, ...).
pub fn asset_view_name(k: usize) -> String {
    format!("view_{:03}", camera::asset_view_azimuth_deg(k) as u32)
}

/// Renders asset view `k` of one asset (no table; the asset at its own size).
pub fn render_asset_view(
    uid: &str,
    asset: &RenderAsset,
    k: usize,
    config: &RenderConfig,
) -> Result<RenderedView, RenderError> {
    let camera = camera::asset_camera(
        k,
        &asset.bounds,
        config.width_px,
        config.height_px,
        config.fov_x_deg,
        config.asset_elevation_deg,
        config.asset_fill,
    );
    let object = [PlacedObject {
        instance: uid.to_owned(),
        asset,
        table_from_asset: Affine3::IDENTITY,
    }];
    let items = draw_items(&object, None);
    let light = lighting(Some(asset.bounds), config.shadows);
    let picture = render_picture(&items, &camera, &light, config.supersampling);
    let name = asset_view_name(k);
    let visible = picture.instance_pixels().get(&1).copied().unwrap_or(0);
    let mut artifact = camera_artifact(
        &name,
        &camera,
        config,
        BTreeMap::from([(uid.to_owned(), visible)]),
    );
    artifact.uid = Some(uid.to_owned());
    artifact.azimuth_deg = Some(camera::asset_view_azimuth_deg(k));
    artifact.elevation_deg = Some(config.asset_elevation_deg);
    Ok(RenderedView {
        name,
        png: picture.png(config.background)?,
        camera: artifact,
        picture,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;
    use proptest::prelude::*;

    /// The picture of sampling every pixel `f × f` times (a full supersampled visibility
    /// buffer) and resolving each pixel as the renderer does: the renderer before silhouette
    /// sampling, kept as the reference for which samples a pixel has.
    fn every_sample_reference(
        items: &[DrawItem<'_>],
        camera: &ViewCamera,
        lighting: &Lighting,
        f: usize,
    ) -> Vec<u8> {
        let intrinsics = camera.intrinsics;
        let big = intrinsics.supersampled(f as u32);
        let camera_from_table = camera.table_from_camera.inverse().expect("pose");
        let vis = visibility(&big, &camera_from_table, items);
        let centres = visibility(&intrinsics, &camera_from_table, items);
        let shader = Shader::new(&camera_from_table, items, lighting);
        let (w, h, bw) = (
            intrinsics.width as usize,
            intrinsics.height as usize,
            big.width as usize,
        );
        let mut rgba = vec![0u8; w * h * 4];
        let mut batch = Batch::default();
        for y in 0..h {
            for x in 0..w {
                batch.add_samples(Pixel {
                    samples: &vis,
                    at: (0..f * f).map(|j| (y * f + j / f) * bw + x * f + j % f),
                    centres: &centres,
                    p: y * w + x,
                });
            }
            batch.finish(&shader, f * f, |p, color, alpha| {
                for k in 0..3 {
                    rgba[p * 4 + k] = linear_to_srgb_u8(color[k]);
                }
                rgba[p * 4 + 3] = alpha;
            });
        }
        rgba
    }

    /// The silhouette test, written row by row with blocks and a separable dilation, against
    /// its definition pixel by pixel, on random item buffers (runs of items so that both sparse
    /// and dense silhouettes occur). Controls: the definition without the growth by one pixel,
    /// or with four neighbours instead of eight, selects fewer pixels, and the comparison sees
    /// it.
    #[test]
    fn silhouette_pixels_follow_their_definition() {
        fn by_definition(centres: &VisibilityBuffer, grow: bool, diagonals: bool) -> Vec<bool> {
            let (w, h) = (centres.width as usize, centres.height as usize);
            let differs = |x: usize, y: usize| {
                let item = centres.item[y * w + x];
                let border = x == 0 || y == 0 || x + 1 == w || y + 1 == h;
                border
                    || (-1i64..=1).any(|dy| {
                        (-1i64..=1).any(|dx| {
                            let near = (x as i64 + dx) as usize + (y as i64 + dy) as usize * w;
                            (diagonals || dx == 0 || dy == 0) && centres.item[near] != item
                        })
                    })
            };
            let mut selected = vec![false; w * h];
            for y in 0..h {
                for x in 0..w {
                    let near = |d: usize| if grow { d } else { 0 };
                    selected[y * w + x] = (y.saturating_sub(near(1))..=(y + near(1)).min(h - 1))
                        .any(|yy| {
                            (x.saturating_sub(near(1))..=(x + near(1)).min(w - 1))
                                .any(|xx| differs(xx, yy))
                        });
                }
            }
            selected
        }
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        let (mut fewer, mut fewer_without_diagonals) = (0, 0);
        for (w, h) in [(1, 1), (1, 7), (9, 1), (17, 13), (64, 48)] {
            for run in [12, 40, 200] {
                let mut item = 0u32;
                let mut items = Vec::with_capacity(w * h);
                for _ in 0..w * h {
                    if next() % run == 0 {
                        item = match next() % 4 {
                            0 => u32::MAX,
                            k => k as u32,
                        };
                    }
                    items.push(item);
                }
                let centres = VisibilityBuffer {
                    width: w as u32,
                    height: h as u32,
                    depth_m: vec![1.0; w * h],
                    item: items,
                    triangle: vec![0; w * h],
                    barycentric: vec![[0.0; 2]; w * h],
                };
                let expected = by_definition(&centres, true, true);
                assert_eq!(silhouette_pixels(&centres), expected, "{w}×{h}");
                fewer += usize::from(by_definition(&centres, false, true) != expected);
                fewer_without_diagonals += usize::from(
                    by_definition(&centres, false, false) != by_definition(&centres, false, true),
                );
            }
        }
        assert!(fewer > 0);
        assert!(fewer_without_diagonals > 0);
    }

    /// The slab is left out of the shadow map when every object stands on the table: the
    /// pictures of every view are the same, byte for byte, as with the slab in it. Control: a
    /// box hanging beside the table below its top is in the slab's shadow, the slab goes back
    /// into the map for it, and leaving it out would light the box.
    #[test]
    fn the_slab_casts_shadows_only_on_what_reaches_below_the_table_top() {
        let material = SurfaceMaterial::plain([0.7, 0.6, 0.5], 0.4);
        let at = |size: [f64; 3], centre: [f64; 3]| {
            TriMesh::cuboid(size).transformed(&Affine3::from_translation(centre))
        };
        let standing = vec![
            at([0.2, 0.15, 0.1], [0.3, 0.3, 0.05]),
            at([0.05, 0.05, 0.25], [0.7, 0.4, 0.125]),
            // Flush with the table's front and right edges.
            at([0.1, 0.1, 0.2], [0.95, 0.05, 0.1]),
        ];
        // Left of the table, 5 to 15 cm below its top: the light (from the right, the front
        // and above) reaches it through the slab.
        let mut with_hanging = standing.clone();
        with_hanging.push(at([0.06, 0.1, 0.1], [-0.04, 0.3, -0.1]));
        let bounds = |meshes: &[TriMesh]| {
            meshes
                .iter()
                .filter_map(|m| Aabb::from_points(m.positions.iter().map(|p| p.map(f64::from))))
                .reduce(|a, b| a.union(&b))
        };
        assert!(!slab_shades(bounds(&standing).as_ref()));
        assert!(slab_shades(bounds(&with_hanging).as_ref()));
        assert!(!slab_shades(None));

        let table = |slab_casts_shadow: bool| TableGeometry {
            slab_casts_shadow,
            ..TableGeometry::new([0.0, 100.0, 0.0, 60.0], None)
        };
        let (casting, not_casting) = (table(true), table(false));
        fn with_table<'a>(
            meshes: &'a [TriMesh],
            material: &'a SurfaceMaterial,
            table: &'a TableGeometry,
        ) -> Vec<DrawItem<'a>> {
            let mut items: Vec<DrawItem<'a>> = meshes
                .iter()
                .enumerate()
                .map(|(i, mesh)| DrawItem {
                    mesh,
                    world_from_mesh: Affine3::IDENTITY,
                    material,
                    instance: i as u32 + 1,
                    casts_shadow: true,
                    vertex_colors: None,
                    closed_within: None,
                })
                .collect();
            items.extend(draw_items(&[], Some(table)));
            items
        }
        let items = |meshes, table| with_table(meshes, &material, table);
        let frame = camera::scene_box([-0.1, 1.0, 0.0, 0.6], 0.25);
        let region = Aabb {
            min: [-0.2, -0.1, -0.2],
            max: [1.1, 0.7, 0.3],
        };
        let light = lighting(Some(region), true);
        let picture = |items: &[DrawItem<'_>], view: SceneView| {
            let cam = camera::scene_camera(view, &frame, 160, 120, 39.6, 1.5);
            render_picture(items, &cam, &light, 2).rgba
        };
        for view in SceneView::ALL {
            assert_eq!(
                picture(&items(&standing, &casting), view),
                picture(&items(&standing, &not_casting), view),
                "{view:?}"
            );
        }
        let changed = |view: SceneView| {
            let a = picture(&items(&with_hanging, &casting), view);
            let b = picture(&items(&with_hanging, &not_casting), view);
            a.chunks_exact(4)
                .zip(b.chunks_exact(4))
                .filter(|(p, q)| p != q)
                .count()
        };
        let changed: Vec<usize> = SceneView::ALL.iter().map(|v| changed(*v)).collect();
        assert!(changed.iter().any(|&n| n > 50), "{changed:?}");
    }

    /// Boxes at several sizes and turns, a thin tilted slab and a pole thinner than a pixel,
    /// on the table, in each scene view.
    #[test]
    fn silhouette_sampling_gives_the_pictures_of_sampling_every_pixel() {
        let turned = |yaw: f64, pitch: f64, at: [f64; 3]| {
            let (cy, sy) = (yaw.cos(), yaw.sin());
            let (cp, sp) = (pitch.cos(), pitch.sin());
            let yaw_m = Affine3 {
                linear: [[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]],
                translation: [0.0; 3],
            };
            let pitch_m = Affine3 {
                linear: [[1.0, 0.0, 0.0], [0.0, cp, -sp], [0.0, sp, cp]],
                translation: [0.0; 3],
            };
            Affine3::from_translation(at).mul(&yaw_m.mul(&pitch_m))
        };
        let shapes = [
            (
                TriMesh::cuboid([0.2, 0.15, 0.1]),
                turned(0.3, 0.0, [0.3, 0.3, 0.05]),
            ),
            (
                TriMesh::cuboid([0.05, 0.05, 0.25]),
                turned(1.1, 0.2, [0.7, 0.4, 0.13]),
            ),
            (
                TriMesh::cuboid([0.3, 0.2, 0.004]),
                turned(-0.4, 0.5, [0.5, 0.15, 0.08]),
            ),
            (
                TriMesh::cuboid([0.008, 0.008, 0.3]),
                turned(0.0, 0.3, [0.2, 0.5, 0.15]),
            ),
            (
                TriMesh::cuboid([0.12, 0.12, 0.12]),
                turned(0.8, 0.8, [0.8, 0.2, 0.08]),
            ),
        ];
        let materials: Vec<SurfaceMaterial> = (0..shapes.len())
            .map(|i| {
                SurfaceMaterial::plain([0.2 + 0.15 * i as f32, 0.5, 0.8 - 0.1 * i as f32], 0.3)
            })
            .collect();
        let table = TableGeometry::new([0.0, 100.0, 0.0, 60.0], None);
        let mut items: Vec<DrawItem<'_>> = shapes
            .iter()
            .zip(&materials)
            .enumerate()
            .map(|(i, ((mesh, pose), material))| DrawItem {
                mesh,
                world_from_mesh: *pose,
                material,
                instance: i as u32 + 1,
                casts_shadow: true,
                vertex_colors: None,
                closed_within: None,
            })
            .collect();
        items.push(DrawItem {
            mesh: &table.slab,
            world_from_mesh: Affine3::IDENTITY,
            material: &table.slab_material,
            instance: 0,
            casts_shadow: false,
            vertex_colors: None,
            closed_within: None,
        });
        let frame = camera::scene_box([0.0, 1.0, 0.0, 0.6], 0.35);
        let region = Aabb {
            min: [-0.1, -0.1, -0.05],
            max: [1.1, 0.7, 0.4],
        };
        let light = lighting(Some(region), true);
        let (w, h) = (160, 120);
        let mut selected_share = Vec::new();
        for view in SceneView::ALL {
            let cam = camera::scene_camera(view, &frame, w, h, 39.6, 1.5);
            let reference = every_sample_reference(&items, &cam, &light, 2);
            let picture = render_picture(&items, &cam, &light, 2);
            let differing = reference
                .chunks_exact(4)
                .zip(picture.rgba.chunks_exact(4))
                .filter(|(a, b)| a != b)
                .count();
            assert_eq!(differing, 0, "{view:?}: {differing} pixels differ");
            // Every pixel selected: the sparse pass is the full one.
            let shadow = ShadowMap::of_lighting(&light, &items);
            let all = render_selected(&items, &cam, &light, 2, shadow.as_ref(), |c| {
                vec![true; c.item.len()]
            });
            assert_eq!(all.rgba, reference, "{view:?}");
            // Control: no pixel selected (each shaded once, fully covered, at its centre)
            // loses the anti-aliased edges, and the comparison sees it.
            let none = render_selected(&items, &cam, &light, 2, shadow.as_ref(), |c| {
                vec![false; c.item.len()]
            });
            let lost = reference
                .chunks_exact(4)
                .zip(none.rgba.chunks_exact(4))
                .filter(|(a, b)| a != b)
                .count();
            assert!(lost > 100, "{view:?}: {lost}");
            let centres = visibility(
                &cam.intrinsics,
                &cam.table_from_camera.inverse().expect("pose"),
                &items,
            );
            let chosen = silhouette_pixels(&centres);
            selected_share.push(chosen.iter().filter(|&&c| c).count() as f64 / (w * h) as f64);
        }
        // Silhouette sampling samples a minority of the pixels fully.
        assert!(
            selected_share.iter().all(|&s| s < 0.5),
            "{selected_share:?}"
        );

        // The limit: a part narrower than half a pixel can fall between the first samples and
        // the centres all along its length (here a 1.5 mm pole, about 0.2 px wide): those
        // pixels keep the colour of what is behind it. Only they differ.
        let pole = TriMesh::cuboid([0.0015, 0.0015, 0.3]);
        let pole_material = SurfaceMaterial::plain([0.9, 0.1, 0.1], 0.3);
        items.push(DrawItem {
            mesh: &pole,
            world_from_mesh: turned(0.0, 0.3, [0.45, 0.5, 0.15]),
            material: &pole_material,
            instance: 9,
            casts_shadow: true,
            vertex_colors: None,
            closed_within: None,
        });
        for view in SceneView::ALL {
            let cam = camera::scene_camera(view, &frame, w, h, 39.6, 1.5);
            let reference = every_sample_reference(&items, &cam, &light, 2);
            let picture = render_picture(&items, &cam, &light, 2);
            let differing = reference
                .chunks_exact(4)
                .zip(picture.rgba.chunks_exact(4))
                .filter(|(a, b)| a != b)
                .count();
            assert!(
                differing <= h as usize / 2,
                "{view:?}: {differing} pixels differ"
            );
        }
    }

    proptest! {
        /// Placed as MesaTask's reader places it: the asset's box centre lands on `position`
        /// and its box, turned back by the rotation, has exactly the layout's `size`.
        #[test]
        fn an_asset_box_becomes_the_layout_box(
            lo in prop::array::uniform3(-0.5f64..0.5),
            extent in prop::array::uniform3(0.01f64..0.8),
            size_cm in prop::array::uniform3(1.0f64..120.0),
            position_cm in prop::array::uniform3(-50.0f64..150.0),
            yaw_deg in -180.0f64..180.0,
        ) {
            let bounds = Aabb { min: lo, max: [lo[0] + extent[0], lo[1] + extent[1], lo[2] + extent[2]] };
            let q = mesa_schemas::rotation::quat_xyzw_from_yaw_deg(yaw_deg);
            let (map, _) = table_from_asset(position_cm, q, size_cm, [1.0; 3], &bounds);
            let centre = map.apply_point(bounds.center());
            for (c, p) in centre.iter().zip(position_cm) {
                prop_assert!((c - p / 100.0).abs() < 1e-9);
            }
            let unturn = Affine3::from_quat_xyzw(q).inverse().expect("rotation");
            let back = bounds.transformed(&unturn.mul(&map));
            for (b, s) in back.size().iter().zip(size_cm) {
                prop_assert!((b - s / 100.0).abs() < 1e-9);
            }
        }

        /// Every scene view shows the whole scene box, whatever the table's shape.
        #[test]
        fn every_view_frames_the_scene(
            width_cm in 30.0f64..300.0,
            depth_cm in 20.0f64..120.0,
            top_cm in 0.0f64..80.0,
        ) {
            let scene = camera::scene_box([0.0, width_cm / 100.0, 0.0, depth_cm / 100.0], top_cm / 100.0);
            for view in SceneView::ALL {
                let cam = camera::scene_camera(view, &scene, 512, 512, 39.6, 1.5);
                let camera_from_table = cam.table_from_camera.inverse().expect("rigid");
                for corner in scene.corners() {
                    let uv = cam.intrinsics.project(camera_from_table.apply_point(corner));
                    prop_assert!(uv.is_some_and(|[u, v]| (0.0..=511.0).contains(&u) && (0.0..=511.0).contains(&v)),
                        "{:?}: {:?} at {:?}", view, corner, uv);
                }
            }
        }
    }

    #[test]
    fn a_scale_factor_that_disagrees_with_size_is_noted() {
        let bounds = Aabb {
            min: [0.0; 3],
            max: [0.1, 0.1, 0.2],
        };
        let q = [0.0, 0.0, 0.0, 1.0];
        let (_, note) = table_from_asset([0.0; 3], q, [10.0, 10.0, 20.0], [1.0; 3], &bounds);
        assert!(note.is_none());
        let (map, note) = table_from_asset([0.0; 3], q, [10.0, 10.0, 20.0], [2.0; 3], &bounds);
        assert!(note.expect("a note").contains("drawn at size"));
        // The picture follows size.
        assert_abs_diff_eq!(map.linear[0][0], 1.0, epsilon = 1e-12);
    }

    #[test]
    fn transparent_and_black_backgrounds() {
        let picture = Picture {
            width: 2,
            height: 1,
            rgba: vec![255, 255, 255, 255, 255, 0, 0, 0],
            instances: vec![1, 0],
        };
        let png = picture.png(Background::Black).expect("png");
        let decoded = crate::image_io::decode_png(&png).expect("decodes");
        assert_eq!(decoded.layout, crate::image_io::PixelLayout::Rgb8);
        assert_eq!(decoded.samples, vec![255, 255, 255, 0, 0, 0]);
        let png = picture.png(Background::Transparent).expect("png");
        let decoded = crate::image_io::decode_png(&png).expect("decodes");
        assert_eq!(decoded.layout, crate::image_io::PixelLayout::Rgba8);
        assert_eq!(picture.instance_pixels(), BTreeMap::from([(1, 1)]));
    }

    #[test]
    fn configuration_problems_name_the_key() {
        let config = RenderConfig {
            supersampling: 0,
            asset_fill: 1.5,
            ..RenderConfig::default()
        };
        let problems = config.problems().join("\n");
        assert!(
            problems.contains("[render] supersampling = 0"),
            "{problems}"
        );
        assert!(problems.contains("[render] asset_fill = 1.5"), "{problems}");
        assert!(RenderConfig::default().problems().is_empty());
    }
}
