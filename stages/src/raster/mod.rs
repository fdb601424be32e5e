//! A CPU z-buffer rasterizer: pinhole cameras with OpenCV intrinsics, per-pixel depth in
//! metres, instance ids, and a shaded colour image (base colour with texture sampling,
//! Lambert + Blinn-Phong lighting, a directional shadow map, supersampled anti-aliasing).
//!
//! Camera convention (SPEC section 2): OpenCV, x right, y down, z forward. Pixel `(u, v)` with
//! integer indices is sampled at exactly `(u, v)` in image coordinates, so a pixel with depth
//! `d` back-projects to `((u - cx) d / fx, (v - cy) d / fy, d)`. Depth is the camera-frame z,
//! not the distance along the ray.
//!
//! The renderer first fills a visibility buffer (depth, drawn item, triangle, perspective-
//! correct barycentrics) and shades only what is visible ([`Shader`], in `shade.rs`, many
//! samples at a time). It is single-threaded and deterministic: ties in depth keep the item
//! drawn first.

use std::sync::Arc;

use crate::mesh::{add3, cross3, normalize3, scale3, sub3, Aabb, Affine3, TriMesh};

mod shade;

#[cfg(test)]
use shade::{add3f, scale3f};
pub use shade::{Hit, Shader, SHADE_BATCH};

/// Pinhole intrinsics in pixels (OpenCV convention).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PinholeCamera {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
}

impl PinholeCamera {
    /// Square pixels and the principal point at the image centre `(width / 2, height / 2)`,
    /// with the focal length that gives a horizontal field of view of `fov_x_deg`.
    pub fn from_fov_x_deg(width: u32, height: u32, fov_x_deg: f64) -> Self {
        let f = width as f64 / 2.0 / (fov_x_deg.to_radians() / 2.0).tan();
        Self {
            width,
            height,
            fx: f,
            fy: f,
            cx: width as f64 / 2.0,
            cy: height as f64 / 2.0,
        }
    }

    /// The horizontal field of view in degrees.
    pub fn fov_x_deg(&self) -> f64 {
        2.0 * (self.width as f64 / 2.0 / self.fx).atan().to_degrees()
    }

    /// The camera of the same view at `factor` times the resolution, whose pixel `(U, V)`
    /// samples the base image at `((U - (factor - 1) / 2) / factor, ...)`: the `factor ×
    /// factor` block of a base pixel is centred on that pixel.
    pub fn supersampled(&self, factor: u32) -> Self {
        let k = factor as f64;
        Self {
            width: self.width * factor,
            height: self.height * factor,
            fx: self.fx * k,
            fy: self.fy * k,
            cx: self.cx * k + (k - 1.0) / 2.0,
            cy: self.cy * k + (k - 1.0) / 2.0,
        }
    }

    /// Projects a camera-frame point to pixel coordinates; `None` behind the camera.
    pub fn project(&self, p_camera: [f64; 3]) -> Option<[f64; 2]> {
        (p_camera[2] > 0.0).then(|| {
            [
                self.fx * p_camera[0] / p_camera[2] + self.cx,
                self.fy * p_camera[1] / p_camera[2] + self.cy,
            ]
        })
    }

    /// The camera-frame point seen at pixel `(u, v)` with depth `depth_m`.
    pub fn back_project(&self, u: f64, v: f64, depth_m: f64) -> [f64; 3] {
        [
            (u - self.cx) * depth_m / self.fx,
            (v - self.cy) * depth_m / self.fy,
            depth_m,
        ]
    }
}

/// An sRGB RGBA8 texture.
#[derive(Debug, Clone, PartialEq)]
pub struct Texture {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Row-major RGBA bytes, sRGB encoded.
    pub rgba: Vec<u8>,
}

impl Texture {
    /// Bilinear sample with repeat wrapping at glTF texture coordinates (v down), linear RGB.
    pub fn sample_linear_rgb(&self, uv: [f32; 2]) -> [f32; 3] {
        let lut = srgb_to_linear_lut();
        let (w, h) = (self.width as i64, self.height as i64);
        if w == 0 || h == 0 {
            return [1.0; 3];
        }
        let x = uv[0] as f64 * w as f64 - 0.5;
        let y = uv[1] as f64 * h as f64 - 0.5;
        let (x0, y0) = (floor_f64(x), floor_f64(y));
        let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
        let pow2 = (w & (w - 1)) == 0 && (h & (h - 1)) == 0;
        let (x0, y0) = (x0 as i64, y0 as i64);
        let (a, b, c, d) = (
            self.texel(lut, pow2, x0, y0),
            self.texel(lut, pow2, x0 + 1, y0),
            self.texel(lut, pow2, x0, y0 + 1),
            self.texel(lut, pow2, x0 + 1, y0 + 1),
        );
        std::array::from_fn(|i| {
            let top = a[i] + (b[i] - a[i]) * fx;
            let bottom = c[i] + (d[i] - c[i]) * fx;
            top + (bottom - top) * fy
        })
    }

    /// The linear RGB of texel `(xi, yi)` wrapped into the texture (`pow2`: both sides are
    /// powers of two, so the wrap is a mask).
    #[inline(always)]
    fn texel(&self, lut: &[f32; 256], pow2: bool, xi: i64, yi: i64) -> [f32; 3] {
        let (w, h) = (self.width as i64, self.height as i64);
        let (xi, yi) = if pow2 {
            ((xi & (w - 1)) as usize, (yi & (h - 1)) as usize)
        } else {
            (xi.rem_euclid(w) as usize, yi.rem_euclid(h) as usize)
        };
        let o = (yi * self.width as usize + xi) * 4;
        [
            lut[self.rgba[o] as usize],
            lut[self.rgba[o + 1] as usize],
            lut[self.rgba[o + 2] as usize],
        ]
    }
}

/// How a surface looks.
#[derive(Debug, Clone, PartialEq)]
pub struct SurfaceMaterial {
    /// Linear RGB base colour (multiplied with the texture).
    pub base_color: [f32; 3],
    /// Base-colour texture, sampled with the mesh's texture coordinates.
    pub texture: Option<Arc<Texture>>,
    /// Roughness in [0, 1]: low values give a small bright highlight.
    pub roughness: f32,
}

impl SurfaceMaterial {
    /// An untextured material.
    pub fn plain(base_color: [f32; 3], roughness: f32) -> Self {
        Self {
            base_color,
            texture: None,
            roughness,
        }
    }
}

/// One mesh to draw.
#[derive(Debug, Clone)]
pub struct DrawItem<'a> {
    /// The triangles, in their own frame.
    pub mesh: &'a TriMesh,
    /// Where the mesh is.
    pub world_from_mesh: Affine3,
    /// How it looks.
    pub material: &'a SurfaceMaterial,
    /// The id written to the instance buffer (0 is reserved for "nothing").
    pub instance: u32,
    /// Whether it casts shadows.
    pub casts_shadow: bool,
    /// Linear RGB colours multiplied with the material's, one per mesh vertex (glTF
    /// `COLOR_0`); `None` for none.
    pub vertex_colors: Option<&'a [[f32; 3]]>,
    /// `Some(bounds)` when the mesh is part of a surface that bounds solids, wound
    /// counter-clockwise seen from outside ([`crate::mesh::closed_outward`], the other parts
    /// drawn too), with the bounds of that whole surface in the mesh's frame. Its triangles
    /// that face away are then skipped whenever the surface is seen from outside (always from
    /// a light; from a camera when the bounds lie wholly in front of its near plane): the
    /// first surface seen there faces the eye, so the picture is the one drawing them gives.
    /// `None`: every triangle is drawn.
    pub closed_within: Option<Aabb>,
}

/// A light infinitely far away.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DirectionalLight {
    /// Unit vector from the scene toward the light, world frame.
    pub toward_light_world: [f64; 3],
    /// Linear RGB intensity.
    pub color: [f32; 3],
    /// Whether it casts shadows (only the first shadowed light does).
    pub casts_shadow: bool,
}

/// The lights of a shaded render.
#[derive(Debug, Clone, PartialEq)]
pub struct Lighting {
    /// World up vector (for the hemisphere ambient term).
    pub up_world: [f64; 3],
    /// Ambient light from above, linear RGB.
    pub sky_color: [f32; 3],
    /// Ambient light from below, linear RGB.
    pub ground_color: [f32; 3],
    /// Directional lights.
    pub lights: Vec<DirectionalLight>,
    /// World region the shadow map covers; outside it nothing is shadowed.
    pub shadow_region: Option<Aabb>,
    /// Shadow map resolution (texels per side).
    pub shadow_map_px: u32,
    /// Colour where nothing is drawn, sRGB.
    pub background_srgb: [u8; 3],
}

impl Default for Lighting {
    fn default() -> Self {
        Self {
            up_world: [0.0, 0.0, 1.0],
            sky_color: [0.42, 0.42, 0.45],
            ground_color: [0.18, 0.17, 0.16],
            lights: vec![DirectionalLight {
                toward_light_world: normalize3([-0.35, -0.45, 0.82]),
                color: [0.85, 0.83, 0.8],
                casts_shadow: true,
            }],
            shadow_region: None,
            shadow_map_px: 2048,
            background_srgb: [255, 255, 255],
        }
    }
}

/// Nearest depth the perspective camera keeps, metres.
const NEAR_M: f64 = 1e-3;

/// What each pixel sees.
#[derive(Debug, Clone, PartialEq)]
pub struct VisibilityBuffer {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Camera-frame depth in metres (`f32::INFINITY` where nothing is drawn).
    pub depth_m: Vec<f32>,
    /// Index of the drawn item (`u32::MAX` where nothing is drawn).
    pub item: Vec<u32>,
    /// Index of the triangle within the item's mesh.
    pub triangle: Vec<u32>,
    /// Perspective-correct barycentric coordinates (b1, b2) within that triangle.
    pub barycentric: Vec<[f32; 2]>,
}

impl VisibilityBuffer {
    fn new(width: u32, height: u32) -> Self {
        let n = width as usize * height as usize;
        Self {
            width,
            height,
            depth_m: vec![f32::INFINITY; n],
            item: vec![u32::MAX; n],
            triangle: vec![0; n],
            barycentric: vec![[0.0; 2]; n],
        }
    }

    /// What sample `o` sees (meaningful where an item is drawn).
    pub fn hit(&self, o: usize) -> Hit {
        Hit {
            item: self.item[o],
            triangle: self.triangle[o],
            barycentric: self.barycentric[o],
        }
    }

    /// Instance ids per pixel (0 where nothing is drawn), from the items' `instance` fields.
    pub fn instance_ids(&self, items: &[DrawItem<'_>]) -> Vec<u32> {
        self.item
            .iter()
            .map(|&i| {
                if i == u32::MAX {
                    0
                } else {
                    items[i as usize].instance
                }
            })
            .collect()
    }
}

#[derive(Debug, Clone, Copy)]
enum Projection {
    Perspective(PinholeCamera),
    /// `sx = (x - x0) / texel`, `sy = (y - y0) / texel`, depth = z.
    Orthographic {
        x0: f64,
        y0: f64,
        texel: f64,
    },
}

#[derive(Clone, Copy)]
struct ClipVertex {
    p: [f64; 3],
    bary: [f64; 3],
}

fn lerp_clip(a: &ClipVertex, b: &ClipVertex, t: f64) -> ClipVertex {
    ClipVertex {
        p: add3(a.p, scale3(sub3(b.p, a.p), t)),
        bary: add3(a.bary, scale3(sub3(b.bary, a.bary), t)),
    }
}

/// Clips a triangle against `z >= near` (Sutherland–Hodgman); 0, 3 or 4 vertices.
fn clip_near(tri: [ClipVertex; 3], near: f64, out: &mut Vec<ClipVertex>) {
    out.clear();
    for i in 0..3 {
        let a = &tri[i];
        let b = &tri[(i + 1) % 3];
        let (ina, inb) = (a.p[2] >= near, b.p[2] >= near);
        if ina {
            out.push(*a);
        }
        if ina != inb {
            let t = (near - a.p[2]) / (b.p[2] - a.p[2]);
            out.push(lerp_clip(a, b, t));
        }
    }
}

/// Where the rasterizer stores the sample of pixel `(x, y)` of its grid: every pixel of a full
/// buffer ([`Every`]), or only the pixels a [`SampleMask`] selects.
trait Samples {
    /// The grid's width and height in pixels (the rasterizer clips to it).
    fn grid(&self) -> (i64, i64);
    /// Calls `visit(x, index)` for every kept pixel `(x, y)` with `x_lo <= x <= x_hi`, in
    /// increasing `x`, with its buffer index.
    fn visit_row(&self, y: i64, x_lo: i64, x_hi: i64, visit: impl FnMut(i64, usize));
    /// Whether any pixel of the box `x0..=x1 × y0..=y1` is kept (a triangle over none is
    /// skipped whole).
    fn any_in(&self, x0: i64, y0: i64, x1: i64, y1: i64) -> bool;
    /// Whether any pixel of row `y` with `x0 <= x <= x1` is kept (a triangle's row over none
    /// is skipped before its span is worked out).
    fn any_in_row(&self, y: i64, x0: i64, x1: i64) -> bool;
}

/// The side of a [`Tiled`] buffer's tiles, pixels.
const SHADOW_TILE: i64 = 8;

/// Every pixel of a square `size × size` buffer stored in tiles of
/// [`SHADOW_TILE`]² pixels, row-major within a tile and tiles row-major: the four texels a
/// shadow lookup reads, and those of the pixels next to it, are in one or two cache lines
/// instead of two rows four kilobytes apart (a 1024² shadow map is 4 MB, larger than a
/// core's cache, and a view's pixels walk it diagonally).
#[derive(Debug, Clone)]
struct Tiled {
    size: i64,
    tiles_x: i64,
}

impl Tiled {
    fn new(size: u32) -> Self {
        let size = i64::from(size);
        Self {
            size,
            tiles_x: (size + SHADOW_TILE - 1) / SHADOW_TILE,
        }
    }

    /// The buffer's length: whole tiles.
    fn len(&self) -> usize {
        (self.tiles_x * self.tiles_x * SHADOW_TILE * SHADOW_TILE) as usize
    }

    /// Where pixel `(x, y)` is stored.
    #[inline(always)]
    fn index(&self, x: i64, y: i64) -> usize {
        let tile = (y / SHADOW_TILE) * self.tiles_x + x / SHADOW_TILE;
        (tile * SHADOW_TILE * SHADOW_TILE + (y % SHADOW_TILE) * SHADOW_TILE + x % SHADOW_TILE)
            as usize
    }

    /// [`Tiled::index`] of a texel of the map, in unsigned arithmetic (no rounding toward
    /// zero to correct for: the shader's lookups).
    #[inline(always)]
    fn index_of_texel(&self, x: u32, y: u32) -> usize {
        const SHIFT: u32 = SHADOW_TILE.trailing_zeros();
        const MASK: u32 = SHADOW_TILE as u32 - 1;
        let (x, y) = (x as usize, y as usize);
        let tile = (y >> SHIFT) * self.tiles_x as usize + (x >> SHIFT);
        (tile << (2 * SHIFT)) + ((y & MASK as usize) << SHIFT) + (x & MASK as usize)
    }
}

impl Samples for Tiled {
    fn grid(&self) -> (i64, i64) {
        (self.size, self.size)
    }

    #[inline(always)]
    fn visit_row(&self, y: i64, x_lo: i64, x_hi: i64, mut visit: impl FnMut(i64, usize)) {
        for x in x_lo..=x_hi {
            visit(x, self.index(x, y));
        }
    }

    fn any_in(&self, _: i64, _: i64, _: i64, _: i64) -> bool {
        true
    }

    fn any_in_row(&self, _: i64, _: i64, _: i64) -> bool {
        true
    }
}

/// Every pixel of a `width`-wide buffer, row-major.
struct Every {
    width: i64,
    height: i64,
}

impl Samples for Every {
    fn grid(&self) -> (i64, i64) {
        (self.width, self.height)
    }

    #[inline(always)]
    fn visit_row(&self, y: i64, x_lo: i64, x_hi: i64, mut visit: impl FnMut(i64, usize)) {
        let row = y * self.width;
        for x in x_lo..=x_hi {
            visit(x, (row + x) as usize);
        }
    }

    fn any_in(&self, _: i64, _: i64, _: i64, _: i64) -> bool {
        true
    }

    #[inline(always)]
    fn any_in_row(&self, _: i64, _: i64, _: i64) -> bool {
        true
    }
}

/// The pixels of a picture whose `factor × factor` samples are all needed (the silhouettes:
/// [`visibility_of_selected`]); the samples of the `k`-th selected pixel (row-major order) are
/// stored at `k · factor² + dy · factor + dx`.
pub struct SampleMask {
    factor: i64,
    /// `log2(factor)` when the factor is a power of two (shifts instead of divisions in the
    /// rasterizer's inner loop).
    shift: Option<u32>,
    width: i64,
    height: i64,
    /// Per picture pixel `p` (row-major) and one past the last, how many pixels before it are
    /// selected: pixel `p` is selected when `before[p + 1] > before[p]`, and `before[p]` is
    /// then its rank; a span of a row holds a selected pixel when the counts at its ends
    /// differ (a triangle's row over none is left at once).
    before: Vec<u32>,
    /// Per tile of `TILE × TILE` picture pixels, whether any is selected, as a summed-area
    /// table of `(tiles_x + 1) × (tiles_y + 1)` counts (a triangle over no selected tile is
    /// skipped whole).
    tiles: Vec<u32>,
    tiles_x: i64,
    selected: usize,
}

/// The side of a [`SampleMask`] tile, picture pixels.
const TILE: i64 = 4;

impl SampleMask {
    /// The mask of a `width × height` picture sampled `factor × factor` per pixel, selecting
    /// the pixels where `selected` is true (row-major, `width · height` values).
    pub fn new(width: u32, height: u32, factor: u32, selected: &[bool]) -> Self {
        let (w, h) = (width as usize, height as usize);
        assert_eq!(selected.len(), w * h, "one flag per pixel");
        let (tx, ty) = (w.div_ceil(TILE as usize), h.div_ceil(TILE as usize));
        let mut before = vec![0u32; w * h + 1];
        let mut count = 0u32;
        for (b, &s) in before.iter_mut().zip(selected) {
            *b = count;
            count += u32::from(s);
        }
        before[w * h] = count;
        let mut marked = vec![false; tx * ty];
        for (y, row) in selected.chunks_exact(w.max(1)).enumerate() {
            let tiles = &mut marked[y / TILE as usize * tx..];
            for (x, _) in row.iter().enumerate().filter(|(_, &s)| s) {
                tiles[x / TILE as usize] = true;
            }
        }
        let mut tiles = vec![0u32; (tx + 1) * (ty + 1)];
        for y in 0..ty {
            let mut row = 0u32;
            for x in 0..tx {
                row += u32::from(marked[y * tx + x]);
                tiles[(y + 1) * (tx + 1) + x + 1] = tiles[y * (tx + 1) + x + 1] + row;
            }
        }
        let factor = factor.max(1);
        Self {
            factor: factor as i64,
            shift: factor.is_power_of_two().then(|| factor.trailing_zeros()),
            width: w as i64,
            height: h as i64,
            before,
            tiles,
            tiles_x: tx as i64,
            selected: count as usize,
        }
    }

    /// How many pixels are selected.
    pub fn selected(&self) -> usize {
        self.selected
    }

    /// A sample coordinate split into its picture pixel and its sample within that pixel
    /// (shifts where the factor is a power of two).
    #[inline(always)]
    fn split(&self, v: i64) -> (i64, i64) {
        match self.shift {
            Some(s) => (v >> s, v & (self.factor - 1)),
            None => (v / self.factor, v % self.factor),
        }
    }

    /// Where the samples of picture pixel `p` (row-major) are stored, `factor²` of them from
    /// the one returned on, row by row (sample `(dx, dy)` at `dy · factor + dx` past it);
    /// `None` when the pixel is not selected.
    #[inline(always)]
    pub fn samples_of(&self, p: usize) -> Option<usize> {
        let k = self.before[p];
        (self.before[p + 1] > k).then(|| k as usize * (self.factor * self.factor) as usize)
    }
}

impl Samples for SampleMask {
    fn grid(&self) -> (i64, i64) {
        (self.width * self.factor, self.height * self.factor)
    }

    #[inline(always)]
    fn visit_row(&self, y: i64, x_lo: i64, x_hi: i64, mut visit: impl FnMut(i64, usize)) {
        if !self.any_in_row(y, x_lo, x_hi) {
            return;
        }
        let f = self.factor;
        let (py, dy) = self.split(y);
        let row = (py * self.width) as usize;
        for x in x_lo..=x_hi {
            let (px, dx) = self.split(x);
            let p = row + px as usize;
            let k = self.before[p];
            if self.before[p + 1] > k {
                visit(x, (k as i64 * f * f + dy * f + dx) as usize);
            }
        }
    }

    #[inline(always)]
    fn any_in_row(&self, y: i64, x0: i64, x1: i64) -> bool {
        let row = self.split(y).0 * self.width;
        let (first, last) = (self.split(x0).0, self.split(x1).0);
        self.before[(row + last) as usize + 1] > self.before[(row + first) as usize]
    }

    fn any_in(&self, x0: i64, y0: i64, x1: i64, y1: i64) -> bool {
        let t = self.factor * TILE;
        let tiles_y = (self.height + TILE - 1) / TILE;
        let (x0, y0) = ((x0 / t).max(0), (y0 / t).max(0));
        let (x1, y1) = ((x1 / t).min(self.tiles_x - 1), (y1 / t).min(tiles_y - 1));
        if x0 > x1 || y0 > y1 {
            return false;
        }
        let w1 = self.tiles_x + 1;
        let at = |x: i64, y: i64| self.tiles[(y * w1 + x) as usize] as i64;
        at(x1 + 1, y1 + 1) - at(x0, y1 + 1) - at(x1 + 1, y0) + at(x0, y0) > 0
    }
}

/// `x.floor() as i64` (saturating, NaN to 0) without a call into libm: the default x86-64
/// target has no rounding instruction, and the rasterizer rounds a few times per row.
#[inline(always)]
fn floor_i64(x: f64) -> i64 {
    let t = x as i64;
    if (t as f64) > x {
        t.saturating_sub(1)
    } else {
        t
    }
}

/// `x.floor()`, bit for bit, without a call into libm where `x` is finite and below 2^52 in
/// magnitude (every texture coordinate the shader meets); anything else goes to `f64::floor`.
#[inline(always)]
fn floor_f64(x: f64) -> f64 {
    if x.abs() < 4_503_599_627_370_496.0 {
        // Exact: |x| < 2^52, so the truncation and its conversion back are exact, and a
        // negative zero or a value in (-1, 0) gives -0.0 or -1.0 as `floor` does.
        let t = x as i64 as f64;
        let f = if t > x { t - 1.0 } else { t };
        if f == 0.0 && x.is_sign_negative() {
            -0.0
        } else {
            f
        }
    } else {
        x.floor()
    }
}

/// `x.ceil() as i64` (saturating, NaN to 0), as [`floor_i64`].
#[inline(always)]
fn ceil_i64(x: f64) -> i64 {
    let t = x as i64;
    if (t as f64) < x {
        t.saturating_add(1)
    } else {
        t
    }
}

impl Projection {
    /// A frame point's picture coordinates and `1 / z`.
    #[inline(always)]
    fn project(&self, p: [f64; 3]) -> ([f64; 2], f64) {
        let screen = match *self {
            Projection::Perspective(cam) => {
                [cam.fx * p[0] / p[2] + cam.cx, cam.fy * p[1] / p[2] + cam.cy]
            }
            Projection::Orthographic { x0, y0, texel } => {
                [(p[0] - x0) / texel, (p[1] - y0) / texel]
            }
        };
        (screen, 1.0 / p[2])
    }
}

/// A triangle corner ready to draw: where it is (frame point and barycentrics in the mesh
/// triangle), where it lands in the picture and `1 / z`.
#[derive(Clone, Copy)]
struct Corner {
    v: ClipVertex,
    screen: [f64; 2],
    inv_z: f64,
}

fn rasterize_into<S: Samples>(
    buffer: &mut VisibilityBuffer,
    samples: &S,
    projection: Projection,
    frame_from_world: &Affine3,
    items: &[DrawItem<'_>],
    only_shadow_casters: bool,
) {
    let (w, h) = samples.grid();
    let perspective = matches!(projection, Projection::Perspective(_));
    let mut polygon = Vec::with_capacity(4);
    let mut points: Vec<[f64; 3]> = Vec::new();
    let mut projected: Vec<([f64; 2], f64)> = Vec::new();
    const UNIT: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for (item_index, item) in items.iter().enumerate() {
        if only_shadow_casters && !item.casts_shadow {
            continue;
        }
        let frame_from_mesh = frame_from_world.mul(&item.world_from_mesh);
        let back = back_facing_sign(item, &frame_from_mesh, perspective);
        points.clear();
        points.extend(
            item.mesh
                .positions
                .iter()
                .map(|p| frame_from_mesh.apply_point([p[0] as f64, p[1] as f64, p[2] as f64])),
        );
        // Each vertex projected once (a vertex is shared by about six triangles); a triangle
        // that crosses the near plane is clipped and its new corners projected on their own.
        projected.clear();
        projected.extend(points.iter().map(|&p| projection.project(p)));
        for (t, tri) in item.mesh.triangles.iter().enumerate() {
            let corner = |k: usize| {
                let i = tri[k] as usize;
                Corner {
                    v: ClipVertex {
                        p: points[i],
                        bary: UNIT[k],
                    },
                    screen: projected[i].0,
                    inv_z: projected[i].1,
                }
            };
            let corners = [corner(0), corner(1), corner(2)];
            let in_front = |c: &Corner| c.v.p[2] >= NEAR_M;
            if !perspective || corners.iter().all(in_front) {
                raster_triangle(
                    buffer,
                    samples,
                    perspective,
                    back,
                    &corners,
                    item_index as u32,
                    t as u32,
                    w,
                    h,
                );
                continue;
            }
            if !corners.iter().any(in_front) {
                continue;
            }
            clip_near(corners.map(|c| c.v), NEAR_M, &mut polygon);
            for k in 1..polygon.len().saturating_sub(1) {
                let fan = [polygon[0], polygon[k], polygon[k + 1]].map(|v| {
                    let (screen, inv_z) = projection.project(v.p);
                    Corner { v, screen, inv_z }
                });
                raster_triangle(
                    buffer,
                    samples,
                    perspective,
                    back,
                    &fan,
                    item_index as u32,
                    t as u32,
                    w,
                    h,
                );
            }
        }
    }
}

/// The sign of the picture area of `item`'s triangles that face away from the eye (the
/// rasterizer skips those), or 0 to draw them all: `item` is not closed
/// ([`DrawItem::closed_within`]), or a perspective eye may be inside it (its surface's bounds
/// reach past the near plane).
///
/// In the picture (x right, y down, depth away from the eye), a triangle wound
/// counter-clockwise seen from the eye has a negative area `(s1 - s0) × (s2 - s0)`; a map
/// from the mesh that mirrors (negative determinant) swaps the two.
fn back_facing_sign(item: &DrawItem<'_>, frame_from_mesh: &Affine3, perspective: bool) -> f64 {
    let Some(bounds) = &item.closed_within else {
        return 0.0;
    };
    // Every corner in front of the near plane (a NaN corner is not).
    if perspective
        && !bounds
            .corners()
            .iter()
            .all(|&c| frame_from_mesh.apply_point(c)[2] >= NEAR_M)
    {
        return 0.0;
    }
    let det = frame_from_mesh.determinant();
    if det > 0.0 {
        1.0
    } else if det < 0.0 {
        -1.0
    } else {
        0.0
    }
}

#[allow(clippy::too_many_arguments)]
fn raster_triangle<S: Samples>(
    buffer: &mut VisibilityBuffer,
    samples: &S,
    perspective: bool,
    back: f64,
    corners: &[Corner; 3],
    item: u32,
    triangle: u32,
    w: i64,
    h: i64,
) {
    let screen: [[f64; 2]; 3] = corners.map(|c| c.screen);
    let v: [ClipVertex; 3] = corners.map(|c| c.v);
    let area = signed_area(&screen);
    // Degenerate, or facing away from the eye on a closed surface (`back`: the sign of such
    // areas, 0 for none).
    if area.abs() < 1e-12 || !area.is_finite() || area * back > 0.0 {
        return;
    }
    let min_x = screen.iter().map(|s| s[0]).fold(f64::INFINITY, f64::min);
    let max_x = screen
        .iter()
        .map(|s| s[0])
        .fold(f64::NEG_INFINITY, f64::max);
    let min_y = screen.iter().map(|s| s[1]).fold(f64::INFINITY, f64::min);
    let max_y = screen
        .iter()
        .map(|s| s[1])
        .fold(f64::NEG_INFINITY, f64::max);
    let x_start = ceil_i64(min_x).max(0);
    let x_end = floor_i64(max_x).min(w - 1);
    let y_start = ceil_i64(min_y).max(0);
    let y_end = floor_i64(max_y).min(h - 1);
    if x_start > x_end || y_start > y_end || !samples.any_in(x_start, y_start, x_end, y_end) {
        return;
    }
    let inv_area = 1.0 / area;
    let inv_z: [f64; 3] = corners.map(|c| c.inv_z);
    let (edges, minus_inv_a) = edge_functions(&screen, inv_area);
    // What the buffer keeps besides depth: nothing (a shadow map), or the item, triangle and
    // barycentrics (what is shaded).
    let with_attributes = !buffer.item.is_empty();
    let VisibilityBuffer {
        depth_m,
        item: items,
        triangle: triangles,
        barycentric: barycentrics,
        ..
    } = buffer;
    for y in y_start..=y_end {
        if !samples.any_in_row(y, x_start, x_end) {
            continue;
        }
        let Some((row, x_lo, x_hi)) = row_span(&edges, &minus_inv_a, y, (x_start, x_end), 1.0)
        else {
            continue;
        };
        samples.visit_row(y, x_lo, x_hi, |x, o| {
            let px = x as f64;
            let l0 = row[0].0 * px + row[0].1;
            let l1 = row[1].0 * px + row[1].1;
            let l2 = row[2].0 * px + row[2].1;
            if l0 < 0.0 || l1 < 0.0 || l2 < 0.0 {
                return;
            }
            // Perspective: the corners' weights over their depths, whose sum is 1 / depth.
            let (depth, q) = if perspective {
                let q = [l0 * inv_z[0], l1 * inv_z[1], l2 * inv_z[2]];
                let sum = q[0] + q[1] + q[2];
                if sum <= 0.0 {
                    return;
                }
                (1.0 / sum, q)
            } else {
                (
                    l0 * v[0].p[2] + l1 * v[1].p[2] + l2 * v[2].p[2],
                    [l0, l1, l2],
                )
            };
            let depth32 = depth as f32;
            if depth32 < depth_m[o] {
                depth_m[o] = depth32;
                if with_attributes {
                    items[o] = item;
                    // The corners' perspective-correct weights: q / sum, as q times the depth.
                    let mu = if perspective {
                        [q[0] * depth, q[1] * depth, q[2] * depth]
                    } else {
                        q
                    };
                    triangles[o] = triangle;
                    let b: [f64; 3] = std::array::from_fn(|k| {
                        mu[0] * v[0].bary[k] + mu[1] * v[1].bary[k] + mu[2] * v[2].bary[k]
                    });
                    barycentrics[o] = [b[1] as f32, b[2] as f32];
                }
            }
        });
    }
}

/// The signed area of a picture triangle, `(s1 - s0) × (s2 - s0)` (negative for corners
/// counter-clockwise seen from the eye: x right, y down).
fn signed_area(screen: &[[f64; 2]; 3]) -> f64 {
    (screen[1][0] - screen[0][0]) * (screen[2][1] - screen[0][1])
        - (screen[1][1] - screen[0][1]) * (screen[2][0] - screen[0][0])
}

/// The barycentric weights of a picture triangle as functions of the sample:
/// `l_k(x, y) = a_k x + b_k y + c_k` for the edge opposite corner `k` (`(a_k, b_k, c_k)`,
/// `inv_area` being one over the triangle's signed area), and per edge `-1 / a_k` (0 where
/// `a_k` is): each row's span bound is a product, not a division.
fn edge_functions(screen: &[[f64; 2]; 3], inv_area: f64) -> ([(f64, f64, f64); 3], [f64; 3]) {
    let coefficients = |p: [f64; 2], q: [f64; 2]| {
        let a = -(q[1] - p[1]) * inv_area;
        let b = (q[0] - p[0]) * inv_area;
        let c = (-(q[0] - p[0]) * p[1] + (q[1] - p[1]) * p[0]) * inv_area;
        (a, b, c)
    };
    let edges = [
        coefficients(screen[1], screen[2]),
        coefficients(screen[2], screen[0]),
        coefficients(screen[0], screen[1]),
    ];
    let minus_inv_a = edges.map(|(a, _, _)| if a != 0.0 { -1.0 / a } else { 0.0 });
    (edges, minus_inv_a)
}

/// A triangle's weights along one row: per edge `(a_k, b_k y + c_k)`, the weight at `x` being
/// `a_k x + (b_k y + c_k)`.
type RowWeights = [(f64, f64); 3];

/// The samples of row `y` to test against a triangle with edge functions
/// `l_k(x, y) = a_k x + b_k y + c_k` (`edges[k] = (a_k, b_k, c_k)`, `minus_inv_a[k] = -1 / a_k`
/// or 0): per edge `(a_k, b_k y + c_k)`, and the first and last `x` within
/// `x_start..=x_end` where no `l_k` is negative, widened by `slack` times a millionth of a
/// pixel plus a billionth of the bound each side; `None` when there is none.
///
/// The bounds are products with a rounded reciprocal, a few units in the last place from
/// where the weights computed at each sample change sign, so `slack` 1 never leaves out a
/// sample the exact test would keep (`row_spans_keep_every_sample_inside`), and adds one
/// outside only where a bound is within a millionth of a pixel of an integer.
#[inline(always)]
fn row_span(
    edges: &[(f64, f64, f64); 3],
    minus_inv_a: &[f64; 3],
    y: i64,
    (x_start, x_end): (i64, i64),
    slack: f64,
) -> Option<(RowWeights, i64, i64)> {
    let py = y as f64;
    let (mut lo, mut hi) = (x_start as f64, x_end as f64);
    let mut row = [(0.0, 0.0); 3];
    for (k, &(a, b, c)) in edges.iter().enumerate() {
        let offset = b * py + c;
        row[k] = (a, offset);
        if a > 0.0 {
            lo = lo.max(offset * minus_inv_a[k]);
        } else if a < 0.0 {
            hi = hi.min(offset * minus_inv_a[k]);
        } else if offset < 0.0 {
            return None;
        }
    }
    // An infinite bound (a reciprocal that overflowed) stays as it is.
    let widen = |bound: f64, outward: f64| {
        if bound.is_finite() {
            bound + outward * slack * (1e-6 + 1e-9 * bound.abs())
        } else {
            bound
        }
    };
    let x_lo = ceil_i64(widen(lo, -1.0)).max(x_start);
    let x_hi = floor_i64(widen(hi, 1.0)).min(x_end);
    (x_lo <= x_hi).then_some((row, x_lo, x_hi))
}

/// Fills a visibility buffer for a perspective camera at `camera_from_world`.
pub fn visibility(
    camera: &PinholeCamera,
    camera_from_world: &Affine3,
    items: &[DrawItem<'_>],
) -> VisibilityBuffer {
    let buffer = VisibilityBuffer::new(camera.width, camera.height);
    draw_every_pixel(buffer, camera, camera_from_world, items)
}

/// Draws `items` into `buffer`, one sample per pixel of `camera`.
fn draw_every_pixel(
    mut buffer: VisibilityBuffer,
    camera: &PinholeCamera,
    camera_from_world: &Affine3,
    items: &[DrawItem<'_>],
) -> VisibilityBuffer {
    rasterize_into(
        &mut buffer,
        &Every {
            width: camera.width as i64,
            height: camera.height as i64,
        },
        Projection::Perspective(*camera),
        camera_from_world,
        items,
        false,
    );
    buffer
}

/// The visibility of the samples of the pixels `mask` selects, seen by `camera` (the picture's
/// camera [`PinholeCamera::supersampled`] by the mask's factor). Each sample is exactly the
/// one [`visibility`] finds at that pixel of `camera`; the buffer holds `mask.selected() ·
/// factor²` samples in [`SampleMask`] order (its `width` is `factor²`, its `height`
/// the number of selected pixels). Triangles over no selected pixel are skipped whole.
pub fn visibility_of_selected(
    camera: &PinholeCamera,
    camera_from_world: &Affine3,
    items: &[DrawItem<'_>],
    mask: &SampleMask,
) -> VisibilityBuffer {
    let per_pixel = (mask.factor * mask.factor) as u32;
    debug_assert_eq!(
        (camera.width as i64, camera.height as i64),
        mask.grid(),
        "the mask's picture sampled by its factor"
    );
    let mut buffer = VisibilityBuffer::new(per_pixel, mask.selected as u32);
    rasterize_into(
        &mut buffer,
        mask,
        Projection::Perspective(*camera),
        camera_from_world,
        items,
        false,
    );
    buffer
}

/// The depth of the shadow casters seen from the first shadowed light over the lighting's
/// shadow region: it depends on the items and the lights, not on the camera, so every view of
/// one scene can share it ([`Shader::with_shadow_map`]).
#[derive(Debug, Clone)]
pub struct ShadowMap {
    /// The map's frame, for the tests that draw it again row by row.
    #[cfg(test)]
    frame: (Affine3, Projection),
    /// World point to texel coordinates and biased light depth, in single precision for the
    /// shader ([`ShadowLookup`]).
    lookup: ShadowLookup,
    /// The light's depth per texel, stored in tiles ([`Tiled`]).
    buffer: VisibilityBuffer,
    tiles: Tiled,
}

impl ShadowMap {
    /// The shadow map `lighting` asks for over `items` (its first shadowed light, over its
    /// shadow region); `None` when it has no shadowed light or no region.
    pub fn of_lighting(lighting: &Lighting, items: &[DrawItem<'_>]) -> Option<Self> {
        lighting
            .lights
            .iter()
            .find(|l| l.casts_shadow)
            .zip(lighting.shadow_region.as_ref())
            .map(|(light, region)| Self::build(light, region, lighting.shadow_map_px, items))
    }

    fn build(
        light: &DirectionalLight,
        region: &Aabb,
        size_px: u32,
        items: &[DrawItem<'_>],
    ) -> Self {
        // Light frame: z along the light's travel (depth grows away from the light).
        let z = scale3(normalize3(light.toward_light_world), -1.0);
        let helper = if z[2].abs() < 0.9 {
            [0.0, 0.0, 1.0]
        } else {
            [1.0, 0.0, 0.0]
        };
        let x = normalize3(cross3(helper, z));
        let y = cross3(z, x);
        let light_from_world = Affine3 {
            linear: [x, y, z],
            translation: [0.0; 3],
        };
        let bounds = region.transformed(&light_from_world);
        let extent = (bounds.max[0] - bounds.min[0]).max(bounds.max[1] - bounds.min[1]);
        let texel = (extent / size_px.max(1) as f64).max(1e-6);
        let (x0, y0) = (bounds.min[0], bounds.min[1]);
        // Depth only: no item, triangle or barycentric planes.
        let tiles = Tiled::new(size_px);
        let mut buffer = VisibilityBuffer {
            width: size_px,
            height: size_px,
            depth_m: vec![f32::INFINITY; tiles.len()],
            item: Vec::new(),
            triangle: Vec::new(),
            barycentric: Vec::new(),
        };
        rasterize_into(
            &mut buffer,
            &tiles,
            Projection::Orthographic { x0, y0, texel },
            &light_from_world,
            items,
            true,
        );
        // A texel's centre is at its coordinate + 0.5; the lookup wants the texel below-left.
        let row =
            |axis: [f64; 3], offset: f64| [axis[0], axis[1], axis[2], offset].map(|v| v as f32);
        let lookup = ShadowLookup {
            to_x: row(scale3(x, 1.0 / texel), -x0 / texel - 0.5),
            to_y: row(scale3(y, 1.0 / texel), -y0 / texel - 0.5),
            to_depth: row(z, -(2.0 * texel + 1e-3)),
            normal_offset: (1.5 * texel) as f32,
        };
        Self {
            #[cfg(test)]
            frame: (light_from_world, Projection::Orthographic { x0, y0, texel }),
            lookup,
            buffer,
            tiles,
        }
    }

    /// Fraction of light reaching `p_world` (percentage-closer filtering over the 2×2 texels
    /// around it, bilinearly weighted): the scalar reference of the shader's lookups, which
    /// do the same eight points at a time (`shade::light_fractions`).
    #[cfg(test)]
    fn light_fraction(&self, p_world: [f32; 3], normal_world: [f32; 3]) -> f32 {
        let ShadowLookup {
            to_x,
            to_y,
            to_depth,
            normal_offset,
        } = &self.lookup;
        // Offset along the normal and a depth bias keep surfaces from shadowing themselves.
        let p = add3f(p_world, scale3f(normal_world, *normal_offset));
        let affine = |r: &[f32; 4]| r[0] * p[0] + r[1] * p[1] + r[2] * p[2] + r[3];
        let (sx, sy) = (affine(to_x), affine(to_y));
        let size = self.tiles.size;
        // Outside the map (NaN included): lit. Past this test the truncation is the floor.
        if !(sx >= 0.0 && sy >= 0.0 && sx < (size - 1) as f32 && sy < (size - 1) as f32) {
            return 1.0;
        }
        let (x0, y0) = (sx as i64, sy as i64);
        let (fx, fy) = (sx - x0 as f32, sy - y0 as f32);
        let depth = affine(to_depth);
        let lit = |x: i64, y: i64| -> f32 {
            if depth <= self.buffer.depth_m[self.tiles.index(x, y)] {
                1.0
            } else {
                0.0
            }
        };
        let top = lit(x0, y0) * (1.0 - fx) + lit(x0 + 1, y0) * fx;
        let bottom = lit(x0, y0 + 1) * (1.0 - fx) + lit(x0 + 1, y0 + 1) * fx;
        top * (1.0 - fy) + bottom * fy
    }
}

/// Where the shader looks a world point up in a [`ShadowMap`]: each row `r` maps a point `p` to
/// `r[0]·p.x + r[1]·p.y + r[2]·p.z + r[3]` (texel coordinates whose integer part is the texel
/// below and left of the point, and the light depth less the bias). Single precision: a map
/// spans metres in a thousand texels, and a float's 24 bits hold a point to a ten-thousandth
/// of a texel there.
#[derive(Debug, Clone)]
struct ShadowLookup {
    to_x: [f32; 4],
    to_y: [f32; 4],
    to_depth: [f32; 4],
    /// How far along its normal a point moves before the lookup (1.5 texels).
    normal_offset: f32,
}

fn srgb_to_linear_lut() -> &'static [f32; 256] {
    static LUT: std::sync::OnceLock<[f32; 256]> = std::sync::OnceLock::new();
    LUT.get_or_init(|| {
        std::array::from_fn(|i| {
            let c = i as f32 / 255.0;
            if c <= 0.04045 {
                c / 12.92
            } else {
                ((c + 0.055) / 1.055).powf(2.4)
            }
        })
    })
}

/// Converts a linear value in [0, 1] to an sRGB byte.
pub fn linear_to_srgb_u8(c: f32) -> u8 {
    static LUT: std::sync::OnceLock<Vec<u8>> = std::sync::OnceLock::new();
    let lut = LUT.get_or_init(|| {
        (0..=4096)
            .map(|i| {
                let c = i as f32 / 4096.0;
                let s = if c <= 0.0031308 {
                    12.92 * c
                } else {
                    1.055 * c.powf(1.0 / 2.4) - 0.055
                };
                (s * 255.0 + 0.5).clamp(0.0, 255.0) as u8
            })
            .collect()
    });
    let i = (c.clamp(0.0, 1.0) * 4096.0 + 0.5) as usize;
    lut[i.min(4096)]
}

/// Converts an sRGB byte to a linear value in [0, 1].
pub fn srgb_u8_to_linear(c: u8) -> f32 {
    srgb_to_linear_lut()[c as usize]
}

/// A shaded render: the visibility buffer and its colour image.
#[derive(Debug, Clone, PartialEq)]
pub struct ShadedRender {
    /// What each pixel sees.
    pub visibility: VisibilityBuffer,
    /// Row-major sRGB RGB bytes.
    pub rgb: Vec<u8>,
}
/// Renders a shaded colour image (and its visibility buffer) at the camera's resolution.
pub fn render_shaded(
    camera: &PinholeCamera,
    camera_from_world: &Affine3,
    items: &[DrawItem<'_>],
    lighting: &Lighting,
) -> ShadedRender {
    let visibility = visibility(camera, camera_from_world, items);
    let shader = Shader::new(camera_from_world, items, lighting);
    let bg = lighting.background_srgb;
    let width = camera.width as usize;
    let mut rgb = vec![0u8; width * camera.height as usize * 3];
    // Row by row: the row's hits shaded in one batch.
    let (mut drawn, mut hits, mut colors) = (Vec::new(), Vec::new(), Vec::new());
    for y in 0..camera.height as usize {
        let row = &mut rgb[y * width * 3..(y + 1) * width * 3];
        drawn.clear();
        hits.clear();
        for x in 0..width {
            let o = y * width + x;
            if visibility.item[o] == u32::MAX {
                row[x * 3..x * 3 + 3].copy_from_slice(&bg);
            } else {
                drawn.push(x);
                hits.push(visibility.hit(o));
            }
        }
        colors.resize(hits.len(), [0.0; 3]);
        shader.shade_hits(&hits, &mut colors);
        for (&x, color) in drawn.iter().zip(&colors) {
            for k in 0..3 {
                row[x * 3 + k] = linear_to_srgb_u8(color[k]);
            }
        }
    }
    ShadedRender { visibility, rgb }
}

/// Renders a shaded image at `factor × factor` samples per pixel and averages each block (in
/// linear light), for an anti-aliased photo at the camera's own resolution.
pub fn render_shaded_supersampled(
    camera: &PinholeCamera,
    camera_from_world: &Affine3,
    items: &[DrawItem<'_>],
    lighting: &Lighting,
    factor: u32,
) -> Vec<u8> {
    let factor = factor.max(1);
    let big = camera.supersampled(factor);
    let render = render_shaded(&big, camera_from_world, items, lighting);
    if factor == 1 {
        return render.rgb;
    }
    let (w, h) = (camera.width as usize, camera.height as usize);
    let bw = big.width as usize;
    let f = factor as usize;
    let norm = 1.0 / (f * f) as f32;
    let mut out = vec![0u8; w * h * 3];
    for y in 0..h {
        for x in 0..w {
            let mut acc = [0f32; 3];
            for dy in 0..f {
                for dx in 0..f {
                    let o = ((y * f + dy) * bw + x * f + dx) * 3;
                    for (k, a) in acc.iter_mut().enumerate() {
                        *a += srgb_u8_to_linear(render.rgb[o + k]);
                    }
                }
            }
            for k in 0..3 {
                out[(y * w + x) * 3 + k] = linear_to_srgb_u8(acc[k] * norm);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    /// `mesh` drawn where it is, casting shadows, with no vertex colours and not taken as
    /// closed.
    fn plain<'a>(mesh: &'a TriMesh, material: &'a SurfaceMaterial, instance: u32) -> DrawItem<'a> {
        DrawItem {
            mesh,
            world_from_mesh: Affine3::IDENTITY,
            material,
            instance,
            casts_shadow: true,
            vertex_colors: None,
            closed_within: None,
        }
    }

    fn camera() -> PinholeCamera {
        PinholeCamera {
            width: 64,
            height: 48,
            fx: 50.0,
            fy: 50.0,
            cx: 31.5,
            cy: 23.5,
        }
    }

    #[test]
    fn a_plane_facing_the_camera_has_its_exact_depth() {
        // A 2 m wide square at z = 1.5 m in the camera frame.
        let mut quad = TriMesh::cuboid([2.0, 2.0, 0.0001]);
        quad = quad.transformed(&Affine3::from_translation([0.0, 0.0, 1.5]));
        let material = SurfaceMaterial::plain([0.5; 3], 0.5);
        let items = [DrawItem {
            casts_shadow: false,
            ..plain(&quad, &material, 7)
        }];
        let vis = visibility(&camera(), &Affine3::IDENTITY, &items);
        let ids = vis.instance_ids(&items);
        assert!(ids.iter().all(|&i| i == 7));
        for d in &vis.depth_m {
            assert_abs_diff_eq!(*d as f64, 1.5 - 0.00005, epsilon = 1e-5);
        }
    }

    #[test]
    fn a_tilted_plane_back_projects_onto_itself() {
        // The plane z = 2 + 0.5 x (camera frame), seen through every pixel.
        let mut plane = TriMesh::cuboid([6.0, 6.0, 0.0]);
        plane.triangles.truncate(0);
        let corners = [[-3.0, -3.0], [3.0, -3.0], [3.0, 3.0], [-3.0, 3.0]];
        plane.positions.clear();
        plane.normals.clear();
        plane.uvs.clear();
        for [x, y] in corners {
            plane
                .positions
                .push([x as f32, y as f32, (2.0 + 0.5 * x) as f32]);
            plane.normals.push([0.0, 0.0, 1.0]);
        }
        plane.triangles = vec![[0, 1, 2], [0, 2, 3]];
        let material = SurfaceMaterial::plain([0.5; 3], 0.5);
        let items = [DrawItem {
            casts_shadow: false,
            ..plain(&plane, &material, 1)
        }];
        let cam = camera();
        let vis = visibility(&cam, &Affine3::IDENTITY, &items);
        for v in 0..cam.height {
            for u in 0..cam.width {
                let d = vis.depth_m[(v * cam.width + u) as usize] as f64;
                let p = cam.back_project(u as f64, v as f64, d);
                assert_abs_diff_eq!(p[2], 2.0 + 0.5 * p[0], epsilon = 1e-5);
            }
        }
    }

    /// In how many pixels skipping the back faces of `mesh` (told it is closed within
    /// `bounds`, by default its own) changes what `camera_from_world` sees of it, placed by
    /// `world_from_mesh`, in depth or item.
    fn culling_changes_within(
        mesh: &TriMesh,
        bounds: Option<Aabb>,
        world_from_mesh: Affine3,
        camera_from_world: &Affine3,
    ) -> usize {
        let material = SurfaceMaterial::plain([0.5; 3], 0.5);
        let draw = |closed_within: Option<Aabb>| {
            let item = DrawItem {
                mesh,
                world_from_mesh,
                material: &material,
                instance: 1,
                casts_shadow: true,
                vertex_colors: None,
                closed_within,
            };
            visibility(&camera(), camera_from_world, &[item])
        };
        let (all, culled) = (draw(None), draw(bounds.or(mesh.bounds())));
        assert!(
            all.item.iter().any(|&i| i != u32::MAX),
            "the mesh is in view"
        );
        (0..all.depth_m.len())
            .filter(|&p| all.item[p] != culled.item[p] || all.depth_m[p] != culled.depth_m[p])
            .count()
    }

    fn culling_changes(mesh: &TriMesh, world_from_mesh: Affine3, camera: &Affine3) -> usize {
        culling_changes_within(mesh, None, world_from_mesh, camera)
    }

    #[test]
    fn skipping_back_faces_of_closed_meshes_changes_no_pixel() {
        let sphere = TriMesh::uv_sphere(0.4, 24, 12);
        let cuboid = TriMesh::cuboid([0.6, 0.5, 0.4]);
        let turned = Affine3::from_trs([0.1, -0.05, 0.0], [0.3, 0.2, 0.1, 0.927], [1.0; 3]);
        let eye = |p: [f64; 3]| {
            crate::render::camera::look_at(p, [0.0; 3])
                .inverse()
                .expect("a pose")
        };
        let views = [[0.0, -2.0, 0.5], [1.5, 1.0, 1.2], [0.2, 0.1, -1.8]].map(eye);
        for view in &views {
            for (name, mesh) in [("sphere", &sphere), ("cuboid", &cuboid)] {
                assert_eq!(culling_changes(mesh, turned, view), 0, "{name}");
                // Mirrored: the winding seen from outside flips with it.
                let mirror = turned.mul(&Affine3::from_scale([-1.0, 1.0, 1.0]));
                assert_eq!(culling_changes(mesh, mirror, view), 0, "{name} mirrored");
            }
        }
        // The eye inside the cuboid (its bounds reach past the near plane): nothing skipped,
        // it sees the inside of the walls.
        let inside = eye([0.05, 0.0, 0.02]);
        assert_eq!(culling_changes(&cuboid, Affine3::IDENTITY, &inside), 0);
        // Controls: a box without its top, seen from above, shows the inside of its walls
        // and floor, all facing away; told it is closed, they go. So does the inside of the
        // cuboid when the near-plane guard is fooled (bounds given wholly in front of the eye).
        let mut open_box = cuboid.clone();
        open_box.triangles.retain(|t| {
            !t.iter()
                .all(|&i| (f64::from(open_box.positions[i as usize][2]) - 0.2).abs() < 1e-6)
        });
        assert_eq!(open_box.triangles.len(), 10);
        let above = eye([0.3, -0.2, 2.0]);
        assert!(culling_changes(&open_box, Affine3::IDENTITY, &above) > 100);
        let ahead = Aabb {
            min: [-0.2, -0.1, -0.1],
            max: [-0.1, 0.1, 0.1],
        };
        assert!(culling_changes_within(&cuboid, Some(ahead), Affine3::IDENTITY, &inside) > 100);
    }

    #[test]
    fn nearer_objects_hide_farther_ones_and_clipping_keeps_geometry_behind_the_eye_out() {
        let near = TriMesh::cuboid([0.2, 0.2, 0.2])
            .transformed(&Affine3::from_translation([0.0, 0.0, 1.0]));
        // A floor-like plane crossing the camera plane (z from -5 to 5).
        let floor = TriMesh::cuboid([10.0, 0.01, 10.0])
            .transformed(&Affine3::from_translation([0.0, 0.5, 0.0]));
        let material = SurfaceMaterial::plain([0.5; 3], 0.5);
        let items = [plain(&floor, &material, 1), plain(&near, &material, 2)];
        let cam = camera();
        let vis = visibility(&cam, &Affine3::IDENTITY, &items);
        let ids = vis.instance_ids(&items);
        let centre = (24 * cam.width + 32) as usize;
        assert_eq!(ids[centre], 2);
        assert_abs_diff_eq!(vis.depth_m[centre] as f64, 0.9, epsilon = 1e-4);
        // Bottom rows see the floor (y = 0.495 m below the axis), top rows see nothing.
        let bottom = ((cam.height - 1) * cam.width + 5) as usize;
        assert_eq!(ids[bottom], 1);
        let d = vis.depth_m[bottom] as f64;
        let p = cam.back_project(5.0, (cam.height - 1) as f64, d);
        assert_abs_diff_eq!(p[1], 0.495, epsilon = 1e-4);
        assert_eq!(ids[5], 0);
    }

    #[test]
    fn shading_is_deterministic_and_shadows_darken() {
        // Looking straight at a wall 2 m away with a box sticking out of it toward the
        // camera; "up" is toward the camera and the light comes from +x.
        let wall = TriMesh::cuboid([4.0, 4.0, 0.01])
            .transformed(&Affine3::from_translation([0.0, 0.0, 2.005]));
        let block = TriMesh::cuboid([0.3, 0.3, 0.2])
            .transformed(&Affine3::from_translation([0.0, 0.0, 1.9]));
        let material = SurfaceMaterial::plain([0.6; 3], 0.8);
        let items = [plain(&wall, &material, 1), plain(&block, &material, 2)];
        let lighting = Lighting {
            up_world: [0.0, 0.0, -1.0],
            lights: vec![DirectionalLight {
                toward_light_world: normalize3([0.6, 0.0, -1.0]),
                color: [1.0; 3],
                casts_shadow: true,
            }],
            shadow_region: Aabb::from_points([[-1.0, -1.0, 1.5], [1.0, 1.0, 2.1]]),
            shadow_map_px: 512,
            ..Default::default()
        };
        let cam = camera();
        let a = render_shaded_supersampled(&cam, &Affine3::IDENTITY, &items, &lighting, 2);
        let b = render_shaded_supersampled(&cam, &Affine3::IDENTITY, &items, &lighting, 2);
        assert_eq!(a, b);
        // The shadow falls 0.12 m to the left of the block on the wall: wall pixels at
        // x = -0.22 m are shadowed, at x = +0.22 m they are lit.
        let vis = visibility(&cam, &Affine3::IDENTITY, &items);
        let ids = vis.instance_ids(&items);
        let row = 24u32;
        let (left, right) = (26u32, 37u32);
        assert_eq!(ids[(row * cam.width + left) as usize], 1);
        assert_eq!(ids[(row * cam.width + right) as usize], 1);
        let lum = |u: u32| a[((row * cam.width + u) * 3) as usize] as i32;
        assert!(
            lum(left) + 20 < lum(right),
            "left {} right {}",
            lum(left),
            lum(right)
        );
    }

    /// The shadow map, stored in tiles, holds at every texel the depth a row-major map of the
    /// same light holds, at sizes that fill whole tiles and sizes that do not; the padding is
    /// never written. Control: the tiled buffer read row by row differs (one tile's width aside).
    #[test]
    fn tiled_shadow_map_holds_the_row_major_depths() {
        let block = TriMesh::uv_sphere(0.3, 16, 8)
            .transformed(&Affine3::from_translation([0.1, -0.2, 1.9]));
        let floor = TriMesh::cuboid([2.0, 2.0, 0.01])
            .transformed(&Affine3::from_translation([0.0, 0.0, 2.0]));
        let material = SurfaceMaterial::plain([0.6; 3], 0.8);
        let items = [plain(&floor, &material, 1), plain(&block, &material, 2)];
        for size in [8u32, 37, 64, 101] {
            let lighting = Lighting {
                lights: vec![DirectionalLight {
                    toward_light_world: normalize3([0.6, 0.3, -1.0]),
                    color: [1.0; 3],
                    casts_shadow: true,
                }],
                shadow_region: Aabb::from_points([[-1.0, -1.0, 1.5], [1.0, 1.0, 2.1]]),
                shadow_map_px: size,
                ..Default::default()
            };
            let map = ShadowMap::of_lighting(&lighting, &items).expect("a shadowed light");
            let mut row_major = VisibilityBuffer {
                width: size,
                height: size,
                depth_m: vec![f32::INFINITY; (size * size) as usize],
                item: Vec::new(),
                triangle: Vec::new(),
                barycentric: Vec::new(),
            };
            let every = Every {
                width: i64::from(size),
                height: i64::from(size),
            };
            let (light_from_world, projection) = map.frame;
            rasterize_into(
                &mut row_major,
                &every,
                projection,
                &light_from_world,
                &items,
                true,
            );
            let n = i64::from(size);
            let tiled: Vec<f32> = (0..n * n)
                .map(|i| map.buffer.depth_m[map.tiles.index(i % n, i / n)])
                .collect();
            assert_eq!(tiled, row_major.depth_m, "size {size}");
            assert!(
                row_major.depth_m.iter().any(|d| d.is_finite()),
                "size {size}: drawn"
            );
            let written = map.buffer.depth_m.iter().filter(|d| d.is_finite()).count();
            let drawn = row_major.depth_m.iter().filter(|d| d.is_finite()).count();
            assert_eq!(
                written, drawn,
                "size {size}: nothing written in the padding"
            );
            let as_rows = &map.buffer.depth_m[..(n * n) as usize];
            if size > 8 {
                assert_ne!(as_rows, row_major.depth_m, "size {size}: control");
            }
        }
    }

    /// The rasterizer's own rounding is `f64::floor` / `f64::ceil` then `as i64` (which
    /// saturates and maps NaN to 0), and the texture sampler's `floor_f64` is `f64::floor` bit
    /// for bit, for every input: integers, halves, values beside integers, huge values,
    /// infinities, NaN, and random ones. Control: plain truncation (what `as i64` alone does)
    /// differs on negative fractions; a floor that loses the sign of a negative zero was tried
    /// and fails on `-0.0`.
    #[test]
    fn rounding_to_integers_matches_the_standard_library() {
        let mut values = vec![
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            2.5,
            -2.5,
            1e-300,
            -1e-300,
            4503599627370495.5,
            -4503599627370495.5,
            9.2e18,
            -9.2e18,
            9.3e18,
            -9.3e18,
            1e300,
            -1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            f64::MAX,
            f64::MIN,
        ];
        for k in -70..70 {
            let x = k as f64 * 0.37;
            values.extend([
                x,
                x.next_up(),
                x.next_down(),
                x.round().next_up(),
                x.round().next_down(),
            ]);
        }
        let mut state = 0x2545_f491_4f6c_dd1du64;
        for _ in 0..10_000 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            values.push(f64::from_bits(state));
            values.push((state % 1_000_000) as f64 / 997.0 - 500.0);
        }
        for &x in &values {
            assert_eq!(floor_i64(x), x.floor() as i64, "floor {x:e}");
            assert_eq!(ceil_i64(x), x.ceil() as i64, "ceil {x:e}");
            assert_eq!(
                floor_f64(x).to_bits(),
                x.floor().to_bits(),
                "floor_f64 {x:e}"
            );
        }
        // The inputs tell truncation from flooring and from ceiling, and reach the sign of a
        // zero (a negative zero floors to itself, not to +0).
        assert!(values.iter().any(|&x| x == 0.0 && x.is_sign_negative()));
        assert!(values.iter().any(|&x| x as i64 != x.floor() as i64));
        assert!(values.iter().any(|&x| x as i64 != x.ceil() as i64));
    }

    /// Every sample whose weights, computed as the rasterizer computes them, are all
    /// non-negative lies in its row's span, over random triangles whose corners fall on a
    /// quarter-pixel grid (edges through samples, where a weight is exactly zero), anywhere, or
    /// make slivers, with the picture clipping them. Control: without the slack the spans
    /// leave out samples the exact test keeps.
    #[test]
    fn row_spans_keep_every_sample_inside() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let (w, h) = (32i64, 24i64);
        let (mut kept, mut missed_without_slack) = (0usize, 0usize);
        for trial in 0..20_000 {
            let corner = |rng: &mut rand_chacha::ChaCha8Rng| -> [f64; 2] {
                match trial % 3 {
                    0 => [0, 1].map(|_| f64::from(rng.random_range(-20..160)) / 4.0),
                    _ => [0, 1].map(|_| rng.random_range(-8.0..40.0)),
                }
            };
            let mut screen = [corner(&mut rng), corner(&mut rng), corner(&mut rng)];
            if trial % 3 == 2 {
                // A sliver: the third corner a hair off the line through the other two.
                let t: f64 = rng.random();
                screen[2] = [0, 1].map(|k| {
                    screen[0][k] + t * (screen[1][k] - screen[0][k]) + rng.random_range(-1e-3..1e-3)
                });
            }
            let area = signed_area(&screen);
            if area.abs() < 1e-12 {
                continue;
            }
            let (edges, minus_inv_a) = edge_functions(&screen, 1.0 / area);
            for y in 0..h {
                let spans = [1.0, 0.0].map(|slack| {
                    row_span(&edges, &minus_inv_a, y, (0, w - 1), slack).map(|(_, lo, hi)| lo..=hi)
                });
                let py = y as f64;
                for x in 0..w {
                    let px = x as f64;
                    let inside = edges.iter().all(|&(a, b, c)| a * px + (b * py + c) >= 0.0);
                    if !inside {
                        continue;
                    }
                    kept += 1;
                    let within = |span: &Option<std::ops::RangeInclusive<i64>>| {
                        span.as_ref().is_some_and(|r| r.contains(&x))
                    };
                    assert!(within(&spans[0]), "{screen:?}: row {y} leaves out x = {x}");
                    missed_without_slack += usize::from(!within(&spans[1]));
                }
            }
        }
        assert!(kept > 100_000, "{kept} samples inside");
        assert!(missed_without_slack > 0, "the control missed nothing");
    }

    #[test]
    fn textures_are_sampled_with_repeat() {
        let t = Texture {
            width: 2,
            height: 1,
            rgba: vec![0, 0, 0, 255, 255, 255, 255, 255],
        };
        assert_abs_diff_eq!(t.sample_linear_rgb([0.25, 0.5])[0], 0.0, epsilon = 1e-6);
        assert_abs_diff_eq!(t.sample_linear_rgb([0.75, 0.5])[0], 1.0, epsilon = 1e-6);
        assert_abs_diff_eq!(t.sample_linear_rgb([1.75, 0.5])[0], 1.0, epsilon = 1e-6);
        assert_eq!(linear_to_srgb_u8(1.0), 255);
        assert_eq!(linear_to_srgb_u8(0.0), 0);
        assert_eq!(linear_to_srgb_u8(srgb_u8_to_linear(128)), 128);
    }

    #[test]
    fn supersampled_camera_is_centred_on_base_pixels() {
        let cam = camera();
        let big = cam.supersampled(2);
        // The 2×2 block of base pixel (10, 7) is (20..22, 14..16); its centre (20.5, 14.5)
        // must look along the same ray as (10, 7).
        let p = cam.back_project(10.0, 7.0, 1.0);
        let q = big.back_project(20.5, 14.5, 1.0);
        assert_abs_diff_eq!(p[0], q[0], epsilon = 1e-12);
        assert_abs_diff_eq!(p[1], q[1], epsilon = 1e-12);
        assert_abs_diff_eq!(
            PinholeCamera::from_fov_x_deg(640, 480, 60.0).fov_x_deg(),
            60.0,
            epsilon = 1e-9
        );
    }
}
