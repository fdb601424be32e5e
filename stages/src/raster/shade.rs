//! The shader: what a visible sample looks like (base colour with texture and vertex colours,
//! hemisphere ambient light, Lambert and Blinn-Phong directional lights, the shadow map).
//!
//! It shades many samples at once ([`Shader::shade_hits`]): each batch is first gathered
//! sample by sample (vertex positions, normals and texture colours are found through the
//! triangle's indices), then lit in loops over planes of single floats, one per quantity, that
//! the compiler turns into SIMD instructions; the shadow lookups in between read the map sample
//! by sample. The lighting is the same arithmetic in the same order for each sample, so a
//! sample shaded alone ([`Shader::shade`]) or in any batch gets the same bits.

use std::borrow::Cow;

use wide::{f32x8, CmpGe, CmpGt, CmpLe, CmpLt};

use super::{DrawItem, Lighting, ShadowLookup, ShadowMap, Texture};
use crate::mesh::{dot3, normalize3, to_f32, Affine3};

// The scalar arithmetic of the tests' reference shader (and of `ShadowMap::light_fraction`, the
// reference of `light_fractions`): the batches do the same operations lane by lane.

#[cfg(test)]
pub(super) fn add3f(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

#[cfg(test)]
pub(super) fn scale3f(a: [f32; 3], s: f32) -> [f32; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}

#[cfg(test)]
fn dot3f(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// An item's (positions, normals) in the world frame.
type WorldVertices = (Vec<[f32; 3]>, Vec<[f32; 3]>);

/// Shades visible samples: the per-item world-frame vertices and normals, the shadow map and
/// the lights of one render, computed once.
pub struct Shader<'s, 'a> {
    items: &'s [DrawItem<'a>],
    lighting: &'s Lighting,
    /// Per item, in the world frame.
    world: Vec<WorldVertices>,
    shadow: Option<Cow<'s, ShadowMap>>,
    shadow_light: Option<usize>,
    camera_center_world: [f32; 3],
    /// The lighting's up vector.
    up_world: [f32; 3],
    /// Per light, its direction normalised (once, not per pixel).
    toward_lights: Vec<[f32; 3]>,
    /// Per item, its Blinn-Phong exponent and specular strength (from the roughness).
    specular: Vec<(f32, f32)>,
}

impl<'s, 'a> Shader<'s, 'a> {
    /// Prepares shading `items` seen from a camera at `camera_from_world` under `lighting`
    /// (builds the shadow map of the first shadowed light when a shadow region is set).
    pub fn new(
        camera_from_world: &Affine3,
        items: &'s [DrawItem<'a>],
        lighting: &'s Lighting,
    ) -> Self {
        let shadow = ShadowMap::of_lighting(lighting, items).map(Cow::Owned);
        Self::with(camera_from_world, items, lighting, shadow)
    }

    /// As [`Shader::new`], with the shadow map built beforehand: `shadow` must be
    /// [`ShadowMap::of_lighting`] of the same `lighting` and `items`.
    pub fn with_shadow_map(
        camera_from_world: &Affine3,
        items: &'s [DrawItem<'a>],
        lighting: &'s Lighting,
        shadow: Option<&'s ShadowMap>,
    ) -> Self {
        Self::with(
            camera_from_world,
            items,
            lighting,
            shadow.map(Cow::Borrowed),
        )
    }

    fn with(
        camera_from_world: &Affine3,
        items: &'s [DrawItem<'a>],
        lighting: &'s Lighting,
        shadow: Option<Cow<'s, ShadowMap>>,
    ) -> Self {
        let world_from_camera = camera_from_world.inverse().unwrap_or(Affine3::IDENTITY);
        let camera_center_world = to_f32(world_from_camera.translation);
        let shadow_light = lighting.lights.iter().position(|l| l.casts_shadow);
        let world = items
            .iter()
            .map(|item| {
                let m = &item.world_from_mesh;
                let nm = m.normal_matrix().unwrap_or(m.linear);
                let positions = item
                    .mesh
                    .positions
                    .iter()
                    .map(|p| to_f32(m.apply_point([p[0] as f64, p[1] as f64, p[2] as f64])))
                    .collect();
                let normals = item
                    .mesh
                    .normals
                    .iter()
                    .map(|n| {
                        let n = [n[0] as f64, n[1] as f64, n[2] as f64];
                        to_f32(normalize3([dot3(nm[0], n), dot3(nm[1], n), dot3(nm[2], n)]))
                    })
                    .collect();
                (positions, normals)
            })
            .collect();
        let specular = items
            .iter()
            .map(|item| {
                let roughness = item.material.roughness;
                (
                    (2.0 / roughness.clamp(0.05, 1.0).powi(4) - 2.0).clamp(1.0, 4096.0),
                    0.35 * (1.0 - roughness.clamp(0.0, 1.0)).powi(2),
                )
            })
            .collect();
        Self {
            items,
            lighting,
            world,
            shadow,
            shadow_light,
            camera_center_world,
            up_world: to_f32(lighting.up_world),
            toward_lights: lighting
                .lights
                .iter()
                .map(|l| to_f32(normalize3(l.toward_light_world)))
                .collect(),
            specular,
        }
    }

    /// The linear RGB colour of one hit ([`Shader::shade_hits`] of one).
    pub fn shade(&self, hit: Hit) -> [f32; 3] {
        let mut color = [[0.0; 3]];
        self.shade_hits(&[hit], &mut color);
        color[0]
    }

    /// The linear RGB colour of each hit, into `colors` (of the same length), [`SHADE_BATCH`]
    /// hits at a time.
    ///
    /// # Panics
    /// When `colors` is not as long as `hits`, or a hit names an item or triangle that is not
    /// there.
    pub fn shade_hits(&self, hits: &[Hit], colors: &mut [[f32; 3]]) {
        assert_eq!(hits.len(), colors.len(), "one colour per hit");
        let mut planes = Planes::default();
        let mut lookups = Vec::with_capacity(SHADE_BATCH);
        for (hits, colors) in hits.chunks(SHADE_BATCH).zip(colors.chunks_mut(SHADE_BATCH)) {
            lookups.clear();
            self.gather(hits, &mut planes, &mut lookups);
            // The texture lookups in a loop of their own: their cache misses overlap.
            for &(i, texture, uv) in &lookups {
                let t = texture.sample_linear_rgb(uv);
                for (plane, t) in planes.albedo.iter_mut().zip(t) {
                    *lane_mut(plane, i) *= t;
                }
            }
            self.light(&mut planes, hits.len());
            for (i, color) in colors.iter_mut().enumerate() {
                *color = get3(&planes.color, i);
            }
        }
    }

    /// Fills the planes' first `hits.len()` lanes with each hit's interpolated world position
    /// and normal (not yet normalised), its base colour, its vertex colour (the tint; one
    /// without) and its item's specular terms, and lists the texture lookups: the albedo is
    /// the base colour times the texture's colour, times the tint.
    fn gather<'t>(
        &'t self,
        hits: &[Hit],
        planes: &mut Planes,
        lookups: &mut Vec<(usize, &'t Texture, [f32; 2])>,
    ) {
        for (i, hit) in hits.iter().enumerate() {
            let item = &self.items[hit.item as usize];
            let (positions, normals) = &self.world[hit.item as usize];
            let tri = item.mesh.triangles[hit.triangle as usize];
            let [b1, b2] = hit.barycentric;
            let weights = [1.0 - b1 - b2, b1, b2];
            let interp = |arr: &[[f32; 3]]| -> [f32; 3] {
                let [a, b, c] = tri.map(|i| arr[i as usize]);
                std::array::from_fn(|k| weights[0] * a[k] + weights[1] * b[k] + weights[2] * c[k])
            };
            let p = interp(positions);
            let n = interp(normals);
            let material = item.material;
            if let (Some(texture), true) = (&material.texture, item.mesh.has_uvs()) {
                let uv: [f32; 2] = std::array::from_fn(|k| {
                    (0..3)
                        .map(|j| weights[j] * item.mesh.uvs[tri[j] as usize][k])
                        .sum::<f32>()
                });
                lookups.push((i, &**texture, uv));
            }
            let tint = match item.vertex_colors {
                Some(colors) => std::array::from_fn(|k| {
                    (0..3)
                        .map(|j| weights[j] * colors[tri[j] as usize][k])
                        .sum::<f32>()
                }),
                None => [1.0; 3],
            };
            set3(&mut planes.albedo, i, material.base_color);
            set3(&mut planes.tint, i, tint);
            let (shininess, strength) = self.specular[hit.item as usize];
            set3(&mut planes.position, i, p);
            set3(&mut planes.normal, i, n);
            set(&mut planes.shininess, i, shininess);
            set(&mut planes.strength, i, strength);
        }
    }

    /// Lights the planes' lanes: all of them in the vector steps (lanes past the batch hold
    /// the last batch's values or zeros, lit for nothing), the first `len` in the shadow
    /// lookups.
    fn light(&self, planes: &mut Planes, len: usize) {
        let lighting = self.lighting;
        let Planes {
            position,
            normal,
            to_eye,
            albedo,
            tint,
            shininess,
            strength,
            visible,
            color,
        } = planes;
        let eye = self.camera_center_world.map(V::splat);
        let up = self.up_world.map(V::splat);
        for c in 0..CHUNKS {
            let p = [position[0][c], position[1][c], position[2][c]];
            let n = normalize(std::array::from_fn(|k| normal[k][c]));
            let e = normalize(std::array::from_fn(|k| eye[k] - p[k]));
            // Facing away from the eye: the other side of the surface is seen.
            let flip = dot(n, e).cmp_lt(V::ZERO).blend(V::splat(-1.0), V::ONE);
            let n = n.map(|x| x * flip);
            let hemi = V::HALF + V::HALF * dot(n, up);
            for k in 0..3 {
                normal[k][c] = n[k];
                to_eye[k][c] = e[k];
                // Times one where there is no vertex colour: the same bits.
                albedo[k][c] *= tint[k][c];
                color[k][c] = albedo[k][c]
                    * (V::splat(lighting.sky_color[k]) * hemi
                        + V::splat(lighting.ground_color[k]) * (V::ONE - hemi));
            }
        }
        for (li, (light, &l)) in lighting.lights.iter().zip(&self.toward_lights).enumerate() {
            match (&self.shadow, self.shadow_light) {
                (Some(map), Some(s)) if s == li => {
                    let l = l.map(V::splat);
                    for c in 0..chunks_of(len) {
                        let n = [normal[0][c], normal[1][c], normal[2][c]];
                        let p = [position[0][c], position[1][c], position[2][c]];
                        // Where the light does not reach the surface, none of it arrives.
                        let reaches = dot(n, l).cmp_gt(V::ZERO);
                        visible[c] = if reaches.any() {
                            reaches.blend(light_fractions(map, p, n), V::ZERO)
                        } else {
                            V::ZERO
                        };
                    }
                }
                _ => *visible = [V::ONE; CHUNKS],
            }
            let l = l.map(V::splat);
            for c in 0..CHUNKS {
                let n = [normal[0][c], normal[1][c], normal[2][c]];
                let e = [to_eye[0][c], to_eye[1][c], to_eye[2][c]];
                let ndotl = positive(dot(n, l));
                let half = normalize(std::array::from_fn(|k| l[k] + e[k]));
                // Schlick's rational stand-in for x^n: cheap, and close where it matters.
                let x = positive(dot(n, half));
                let (s, v) = (shininess[c], visible[c]);
                let spec = x / (s - s * x + x) * strength[c];
                // Unlit (facing away, or in shadow): nothing added, not even a zero.
                let unlit = ndotl.cmp_le(V::ZERO) | v.cmp_le(V::ZERO);
                for k in 0..3 {
                    let was = color[k][c];
                    let added = was
                        + V::splat(light.color[k])
                            * v
                            * (albedo[k][c] * ndotl + spec * ndotl.sqrt());
                    color[k][c] = unlit.blend(was, added);
                }
            }
        }
    }
}

/// What one sample sees: triangle `triangle` of item `item` at perspective-correct barycentrics
/// `(b1, b2)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Index of the item.
    pub item: u32,
    /// Index of the triangle within the item's mesh.
    pub triangle: u32,
    /// Perspective-correct barycentric coordinates (b1, b2) within that triangle.
    pub barycentric: [f32; 2],
}

/// How many hits [`Shader::shade_hits`] lights at once: its planes (21 floats a hit) stay in
/// the first-level cache.
pub const SHADE_BATCH: usize = 64;

/// The vector of the lighting steps: eight lanes (two SSE registers on the x86-64 baseline).
type V = f32x8;

/// Lanes of a [`V`].
const LANES: usize = 8;

/// Vectors of a plane.
const CHUNKS: usize = SHADE_BATCH / LANES;

/// One quantity of a batch, lane `i` of the batch at lane `i % LANES` of vector `i / LANES`.
type Plane = [V; CHUNKS];

/// Lane `i` of a plane.
fn lane_mut(plane: &mut Plane, i: usize) -> &mut f32 {
    &mut plane[i / LANES].as_array_mut()[i % LANES]
}

fn set(plane: &mut Plane, i: usize, x: f32) {
    *lane_mut(plane, i) = x;
}

fn set3(planes: &mut [Plane; 3], i: usize, x: [f32; 3]) {
    for (plane, x) in planes.iter_mut().zip(x) {
        set(plane, i, x);
    }
}

fn get3(planes: &[Plane; 3], i: usize) -> [f32; 3] {
    planes
        .each_ref()
        .map(|plane| plane[i / LANES].as_array_ref()[i % LANES])
}

/// The vectors that hold the first `len` lanes of a plane.
fn chunks_of(len: usize) -> usize {
    len.div_ceil(LANES)
}

/// `ShadowMap::light_fraction` (the tests' scalar reference) lane by lane: the same operations
/// in the same order, so the same bits. The texel coordinates, the depths and the bilinear
/// weights are computed eight lanes at a time; only the four texels of each lane are read one
/// by one. A lane outside the map is lit (its texels are read at the map's corner and not
/// used).
#[inline(always)]
fn light_fractions(map: &ShadowMap, p_world: [V; 3], normal: [V; 3]) -> V {
    let ShadowLookup {
        to_x,
        to_y,
        to_depth,
        normal_offset,
    } = &map.lookup;
    let offset = V::splat(*normal_offset);
    let p: [V; 3] = std::array::from_fn(|k| p_world[k] + normal[k] * offset);
    let affine = |r: &[f32; 4]| {
        V::splat(r[0]) * p[0] + V::splat(r[1]) * p[1] + V::splat(r[2]) * p[2] + V::splat(r[3])
    };
    let (sx, sy) = (affine(to_x), affine(to_y));
    let last = V::splat((map.tiles.size - 1) as f32);
    // NaN compares false: outside.
    let inside = sx.cmp_ge(V::ZERO) & sy.cmp_ge(V::ZERO) & sx.cmp_lt(last) & sy.cmp_lt(last);
    let (sx, sy) = (inside.blend(sx, V::ZERO), inside.blend(sy, V::ZERO));
    // In the map the coordinates are at least 0, so truncation is the floor.
    let (x0, y0) = (sx.trunc_int(), sy.trunc_int());
    let (fx, fy) = (sx - V::from_i32x8(x0), sy - V::from_i32x8(y0));
    let depth = affine(to_depth).to_array();
    let (xs, ys) = (x0.to_array(), y0.to_array());
    let mut lit = [[0.0f32; LANES]; 4];
    for lane in 0..LANES {
        // Not negative: in the map, or its corner.
        let (x, y) = (xs[lane] as u32, ys[lane] as u32);
        for (corner, (dx, dy)) in [(0, 0), (1, 0), (0, 1), (1, 1)].into_iter().enumerate() {
            let stored = map.buffer.depth_m[map.tiles.index_of_texel(x + dx, y + dy)];
            lit[corner][lane] = if depth[lane] <= stored { 1.0 } else { 0.0 };
        }
    }
    let [l00, l10, l01, l11] = lit.map(V::from);
    let top = l00 * (V::ONE - fx) + l10 * fx;
    let bottom = l01 * (V::ONE - fx) + l11 * fx;
    inside.blend(top * (V::ONE - fy) + bottom * fy, V::ONE)
}

/// [`dot3f`] lane by lane (the same operations in the same order).
#[inline(always)]
fn dot(a: [V; 3], b: [V; 3]) -> V {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Each lane's vector scaled to length one; a zero vector stays zero (it is scaled by one,
/// which keeps its bits).
#[inline(always)]
fn normalize(a: [V; 3]) -> [V; 3] {
    let n = dot(a, a).sqrt();
    let s = n.cmp_gt(V::ZERO).blend(V::ONE / n, V::ONE);
    a.map(|x| x * s)
}

/// Each lane when above zero, else zero (NaN included).
#[inline(always)]
fn positive(x: V) -> V {
    x.cmp_gt(V::ZERO).blend(x, V::ZERO)
}

/// A batch of hits being shaded, one plane per quantity (`[k]`: component `k`).
struct Planes {
    position: [Plane; 3],
    normal: [Plane; 3],
    to_eye: [Plane; 3],
    albedo: [Plane; 3],
    tint: [Plane; 3],
    shininess: Plane,
    strength: Plane,
    visible: Plane,
    color: [Plane; 3],
}

impl Default for Planes {
    fn default() -> Self {
        let zero = [V::ZERO; CHUNKS];
        Self {
            position: [zero; 3],
            normal: [zero; 3],
            to_eye: [zero; 3],
            albedo: [zero; 3],
            tint: [zero; 3],
            shininess: [V::ONE; CHUNKS],
            strength: zero,
            visible: zero,
            color: [zero; 3],
        }
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::mesh::{Aabb, TriMesh};
    use crate::raster::{DirectionalLight, SurfaceMaterial, Texture};

    /// The shader of one hit, sample by sample in scalar arithmetic: the shader as it was
    /// before it shaded batches (kept as the reference). `flip` and `shadows` switch off the
    /// turn of normals toward the eye and the shadow lookups (the controls).
    fn scalar(shader: &Shader<'_, '_>, hit: Hit, flip: bool, shadows: bool) -> [f32; 3] {
        let sub = |a: [f32; 3], b: [f32; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
        let normalize = |a: [f32; 3]| {
            let n = dot3f(a, a).sqrt();
            if n > 0.0 {
                scale3f(a, 1.0 / n)
            } else {
                a
            }
        };
        let lighting = shader.lighting;
        let item = &shader.items[hit.item as usize];
        let (positions, normals) = &shader.world[hit.item as usize];
        let tri = item.mesh.triangles[hit.triangle as usize];
        let [b1, b2] = hit.barycentric;
        let weights = [1.0 - b1 - b2, b1, b2];
        let interp = |arr: &[[f32; 3]]| -> [f32; 3] {
            let [a, b, c] = tri.map(|i| arr[i as usize]);
            std::array::from_fn(|k| weights[0] * a[k] + weights[1] * b[k] + weights[2] * c[k])
        };
        let p = interp(positions);
        let mut n = normalize(interp(normals));
        let to_eye = normalize(sub(shader.camera_center_world, p));
        if flip && dot3f(n, to_eye) < 0.0 {
            n = scale3f(n, -1.0);
        }
        let mut albedo = item.material.base_color;
        if let Some(texture) = &item.material.texture {
            let uv: [f32; 2] = std::array::from_fn(|k| {
                (0..3)
                    .map(|j| weights[j] * item.mesh.uvs[tri[j] as usize][k])
                    .sum::<f32>()
            });
            let t = texture.sample_linear_rgb(uv);
            albedo = [albedo[0] * t[0], albedo[1] * t[1], albedo[2] * t[2]];
        }
        if let Some(colors) = item.vertex_colors {
            for (k, a) in albedo.iter_mut().enumerate() {
                *a *= (0..3)
                    .map(|j| weights[j] * colors[tri[j] as usize][k])
                    .sum::<f32>();
            }
        }
        let hemi = 0.5 + 0.5 * dot3f(n, shader.up_world);
        let mut color: [f32; 3] = std::array::from_fn(|k| {
            albedo[k] * (lighting.sky_color[k] * hemi + lighting.ground_color[k] * (1.0 - hemi))
        });
        let (shininess, strength) = shader.specular[hit.item as usize];
        for (li, (light, &l)) in lighting
            .lights
            .iter()
            .zip(&shader.toward_lights)
            .enumerate()
        {
            let ndotl = dot3f(n, l).max(0.0);
            if ndotl <= 0.0 {
                continue;
            }
            let visible = match (&shader.shadow, shader.shadow_light) {
                (Some(map), Some(s)) if s == li && shadows => map.light_fraction(p, n),
                _ => 1.0,
            };
            if visible <= 0.0 {
                continue;
            }
            let half = normalize(add3f(l, to_eye));
            let x = dot3f(n, half).max(0.0);
            let spec = x / (shininess - shininess * x + x) * strength;
            for k in 0..3 {
                color[k] += light.color[k] * visible * (albedo[k] * ndotl + spec * ndotl.sqrt());
            }
        }
        color
    }

    /// Batches shade each hit to the bits of the scalar reference, whatever the batch: all
    /// hits at once (several batches and a part-filled last one), one at a time, and in reverse
    /// order. The scene has what the shader branches on: a texture, vertex colours, a shadow
    /// map, two lights, normals facing away from the eye and a zero normal. Controls: the
    /// reference without the turn of normals toward the eye, or without shadows, differs from
    /// the batches at some hits.
    #[test]
    fn batches_shade_each_hit_as_the_scalar_reference() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let ball = TriMesh::uv_sphere(0.3, 24, 12);
        let mut floor = TriMesh::cuboid([3.0, 3.0, 0.02])
            .transformed(&Affine3::from_translation([0.0, 0.0, -0.32]));
        floor.uvs = floor
            .positions
            .iter()
            .map(|p| [p[0] * 1.7, p[1] * 2.3])
            .collect();
        // A zero normal: shaded as what it is, not a NaN.
        floor.normals[0] = [0.0; 3];
        let texels: Vec<u8> = (0..8 * 8 * 4).map(|_| rng.random()).collect();
        let textured = SurfaceMaterial {
            base_color: [0.9, 0.8, 0.7],
            texture: Some(Arc::new(Texture {
                width: 8,
                height: 8,
                rgba: texels,
            })),
            roughness: 0.3,
        };
        let plain = SurfaceMaterial::plain([0.4, 0.5, 0.6], 0.9);
        let colors: Vec<[f32; 3]> = (0..ball.positions.len())
            .map(|_| [rng.random(), rng.random(), rng.random()])
            .collect();
        let item = |mesh, material, vertex_colors| DrawItem {
            mesh,
            world_from_mesh: Affine3::IDENTITY,
            material,
            instance: 1,
            casts_shadow: true,
            vertex_colors,
            closed_within: None,
        };
        let items = [
            item(&floor, &textured, None),
            item(&ball, &plain, Some(&colors[..])),
        ];
        let lighting = Lighting {
            lights: vec![
                DirectionalLight {
                    toward_light_world: crate::mesh::normalize3([0.5, -0.4, 1.0]),
                    color: [0.9, 0.85, 0.8],
                    casts_shadow: true,
                },
                DirectionalLight {
                    toward_light_world: crate::mesh::normalize3([-0.7, 0.2, 0.4]),
                    color: [0.2, 0.2, 0.25],
                    casts_shadow: false,
                },
            ],
            shadow_region: Aabb::from_points([[-1.5, -1.5, -0.4], [1.5, 1.5, 0.4]]),
            shadow_map_px: 256,
            ..Default::default()
        };
        let camera_from_world = Affine3::from_translation([0.1, -0.2, 2.5]);
        let shader = Shader::new(&camera_from_world, &items, &lighting);
        let hits: Vec<Hit> = (0..1000)
            .map(|_| {
                let item = rng.random_range(0..2u32);
                let b1: f32 = rng.random();
                Hit {
                    item,
                    triangle: rng.random_range(0..items[item as usize].mesh.triangles.len()) as u32,
                    barycentric: [b1, (1.0 - b1) * rng.random::<f32>()],
                }
            })
            .chain([Hit {
                item: 0,
                triangle: floor
                    .triangles
                    .iter()
                    .position(|t| t[0] == 0)
                    .expect("vertex 0") as u32,
                barycentric: [0.0, 0.0],
            }])
            .collect();
        let bits = |c: [f32; 3]| c.map(f32::to_bits);
        let reference: Vec<_> = hits
            .iter()
            .map(|&h| bits(scalar(&shader, h, true, true)))
            .collect();
        let mut all = vec![[0.0; 3]; hits.len()];
        shader.shade_hits(&hits, &mut all);
        assert_eq!(all.iter().map(|&c| bits(c)).collect::<Vec<_>>(), reference);
        let alone: Vec<_> = hits.iter().map(|&h| bits(shader.shade(h))).collect();
        assert_eq!(alone, reference);
        let reversed: Vec<Hit> = hits.iter().rev().copied().collect();
        let mut back = vec![[0.0; 3]; hits.len()];
        shader.shade_hits(&reversed, &mut back);
        back.reverse();
        assert_eq!(back.iter().map(|&c| bits(c)).collect::<Vec<_>>(), reference);
        // No NaN (the zero normal included); the controls show shadowed and back-facing hits.
        assert!(all.iter().flatten().all(|c| c.is_finite()));
        for (flip, shadows) in [(false, true), (true, false)] {
            let control = hits
                .iter()
                .zip(&reference)
                .filter(|&(&h, r)| bits(scalar(&shader, h, flip, shadows)) != *r)
                .count();
            assert!(
                control > 10,
                "flip {flip}, shadows {shadows}: {control} differ"
            );
        }
    }

    /// The shader's shadow lookups, eight points at a time, give the bits of the scalar
    /// lookup at every point: in the map, in the shadow and half in it, on texel edges, on
    /// the map's last texels and past them, behind the light, and at NaN. Controls: the
    /// points reach each kind of answer (lit, dark, between, outside), so a lookup that
    /// always answered one thing would fail.
    #[test]
    fn lookups_in_lanes_give_the_scalar_lookups_bits() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let ball = TriMesh::uv_sphere(0.3, 24, 12);
        let floor = TriMesh::cuboid([3.0, 3.0, 0.02])
            .transformed(&Affine3::from_translation([0.0, 0.0, -0.32]));
        let plain = SurfaceMaterial::plain([0.4, 0.5, 0.6], 0.9);
        let item = |mesh| DrawItem {
            mesh,
            world_from_mesh: Affine3::IDENTITY,
            material: &plain,
            instance: 1,
            casts_shadow: true,
            vertex_colors: None,
            closed_within: None,
        };
        let items = [item(&floor), item(&ball)];
        let lighting = Lighting {
            lights: vec![DirectionalLight {
                toward_light_world: crate::mesh::normalize3([0.5, -0.4, 1.0]),
                color: [1.0; 3],
                casts_shadow: true,
            }],
            shadow_region: Aabb::from_points([[-1.5, -1.5, -0.4], [1.5, 1.5, 0.4]]),
            shadow_map_px: 100,
            ..Default::default()
        };
        let map = ShadowMap::of_lighting(&lighting, &items).expect("a shadow map");
        let size = (map.tiles.size - 1) as f32;
        type PointNormal = ([f32; 3], [f32; 3]);
        let mut points: Vec<PointNormal> = (0..4000)
            .map(|_| {
                let p = [
                    rng.random_range(-2.0..2.0f32),
                    rng.random_range(-2.0..2.0f32),
                    rng.random_range(-0.4..0.4f32),
                ];
                let n = to_f32(normalize3([
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                ]));
                (p, n)
            })
            .collect();
        // Points whose map coordinates fall on (or within a rounding of) texel edges, the map's
        // last texels and just past them: solved from the lookup's rows for a chosen texel
        // position.
        let ShadowLookup { to_x, to_y, .. } = &map.lookup;
        for (sx, sy) in [
            (0.0, 0.0),
            (size, 3.0),
            (size - 0.5, size - 0.5),
            (12.0, 40.0),
            (-0.25, 5.0),
        ] {
            // Solve the 2×2 system in x and y at z = 0 (zero normal: no offset).
            let (a, b, c, d) = (to_x[0], to_x[1], to_y[0], to_y[1]);
            let (ex, ey) = (sx - to_x[3], sy - to_y[3]);
            let det = a * d - b * c;
            points.push((
                [(ex * d - b * ey) / det, (a * ey - c * ex) / det, 0.0],
                [0.0; 3],
            ));
        }
        points.push(([f32::NAN, 0.0, 0.0], [0.0, 0.0, 1.0]));
        points.push(([0.0; 3], [f32::NAN; 3]));
        let mut kinds = [0usize; 4];
        for chunk in points.chunks(LANES) {
            let lane = |get: &dyn Fn(&PointNormal) -> f32| {
                V::from(std::array::from_fn::<f32, LANES, _>(|i| {
                    chunk.get(i).map_or(0.0, get)
                }))
            };
            let p: [V; 3] = std::array::from_fn(|k| lane(&|q| q.0[k]));
            let n: [V; 3] = std::array::from_fn(|k| lane(&|q| q.1[k]));
            let got = light_fractions(&map, p, n).to_array();
            for (i, &(p, n)) in chunk.iter().enumerate() {
                let want = map.light_fraction(p, n);
                assert_eq!(got[i].to_bits(), want.to_bits(), "at {p:?}, normal {n:?}");
                // Where the lookup lands (the point moved along its normal, as it does).
                let p = add3f(p, scale3f(n, map.lookup.normal_offset));
                let (sx, sy) = (
                    to_x[0] * p[0] + to_x[1] * p[1] + to_x[2] * p[2] + to_x[3],
                    to_y[0] * p[0] + to_y[1] * p[1] + to_y[2] * p[2] + to_y[3],
                );
                let inside = sx >= 0.0 && sy >= 0.0 && sx < size && sy < size;
                kinds[match want {
                    _ if !inside => 3,
                    1.0 => 0,
                    0.0 => 1,
                    _ => 2,
                }] += 1;
            }
        }
        assert!(
            kinds.iter().all(|&k| k > 50),
            "lit, dark, between, outside: {kinds:?}"
        );
    }
}
