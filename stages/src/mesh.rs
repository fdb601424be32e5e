//! Triangle meshes, transforms and bounds, shared by the stages that build, place, render or
//! check geometry.
//!
//! Conventions:
//! - Lengths are metres. Mesh data is `f32` (what glTF stores); transforms and bounds are `f64`.
//! - Quaternions are `[x, y, z, w]` (the dataset layout's order).
//! - A transform is named after the frames it connects: `table_from_gltf` maps glTF-frame points
//!   to table-frame points (SPEC section 2: table (x, y, z) = glTF (X, -Z, Y)).
//! - Triangles are counter-clockwise seen from the side their normal points to (glTF's front
//!   faces).

use std::f64::consts::{PI, TAU};

use thiserror::Error;

/// An affine map `p ↦ linear · p + translation` (row-major 3×3 linear part).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Affine3 {
    /// The linear part, row-major: `linear[row][column]`.
    pub linear: [[f64; 3]; 3],
    /// The translation, applied after the linear part.
    pub translation: [f64; 3],
}

impl Default for Affine3 {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Affine3 {
    /// The identity map.
    pub const IDENTITY: Affine3 = Affine3 {
        linear: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        translation: [0.0; 3],
    };

    /// A pure translation.
    pub fn from_translation(translation: [f64; 3]) -> Self {
        Self {
            translation,
            ..Self::IDENTITY
        }
    }

    /// A pure rotation by a quaternion `[x, y, z, w]` (normalised first).
    pub fn from_quat_xyzw(q: [f64; 4]) -> Self {
        Self {
            linear: quat_to_matrix(q),
            translation: [0.0; 3],
        }
    }

    /// A per-axis scale.
    pub fn from_scale(scale: [f64; 3]) -> Self {
        Self {
            linear: [
                [scale[0], 0.0, 0.0],
                [0.0, scale[1], 0.0],
                [0.0, 0.0, scale[2]],
            ],
            translation: [0.0; 3],
        }
    }

    /// Translation · rotation · scale, the order of a glTF node's TRS.
    pub fn from_trs(translation: [f64; 3], rotation_xyzw: [f64; 4], scale: [f64; 3]) -> Self {
        let r = quat_to_matrix(rotation_xyzw);
        let mut linear = [[0.0; 3]; 3];
        for (row, r_row) in linear.iter_mut().zip(r) {
            for (c, value) in row.iter_mut().enumerate() {
                *value = r_row[c] * scale[c];
            }
        }
        Self {
            linear,
            translation,
        }
    }

    /// The map from a row-major 4×4 homogeneous matrix (the last row is ignored).
    pub fn from_rows_4x4(m: [[f64; 4]; 4]) -> Self {
        Self {
            linear: [
                [m[0][0], m[0][1], m[0][2]],
                [m[1][0], m[1][1], m[1][2]],
                [m[2][0], m[2][1], m[2][2]],
            ],
            translation: [m[0][3], m[1][3], m[2][3]],
        }
    }

    /// The row-major 4×4 homogeneous matrix of this map.
    pub fn to_rows_4x4(&self) -> [[f64; 4]; 4] {
        let l = &self.linear;
        let t = &self.translation;
        [
            [l[0][0], l[0][1], l[0][2], t[0]],
            [l[1][0], l[1][1], l[1][2], t[1]],
            [l[2][0], l[2][1], l[2][2], t[2]],
            [0.0, 0.0, 0.0, 1.0],
        ]
    }

    /// The composition that applies `other` first, then `self`:
    /// `a_from_c = a_from_b.mul(&b_from_c)`.
    pub fn mul(&self, other: &Affine3) -> Affine3 {
        let mut linear = [[0.0; 3]; 3];
        for (r, row) in linear.iter_mut().enumerate() {
            for (c, value) in row.iter_mut().enumerate() {
                *value = (0..3).map(|k| self.linear[r][k] * other.linear[k][c]).sum();
            }
        }
        let translation = add3(self.apply_vector(other.translation), self.translation);
        Affine3 {
            linear,
            translation,
        }
    }

    /// Maps a point.
    pub fn apply_point(&self, p: [f64; 3]) -> [f64; 3] {
        add3(self.apply_vector(p), self.translation)
    }

    /// Maps a direction (the linear part only).
    pub fn apply_vector(&self, v: [f64; 3]) -> [f64; 3] {
        let l = &self.linear;
        [
            l[0][0] * v[0] + l[0][1] * v[1] + l[0][2] * v[2],
            l[1][0] * v[0] + l[1][1] * v[1] + l[1][2] * v[2],
            l[2][0] * v[0] + l[2][1] * v[1] + l[2][2] * v[2],
        ]
    }

    /// Determinant of the linear part (negative for a mirroring map).
    pub fn determinant(&self) -> f64 {
        det3(&self.linear)
    }

    /// The inverse map, `None` when the linear part is singular.
    pub fn inverse(&self) -> Option<Affine3> {
        let inv = inverse3(&self.linear)?;
        let t = self.translation;
        let it = [
            -(inv[0][0] * t[0] + inv[0][1] * t[1] + inv[0][2] * t[2]),
            -(inv[1][0] * t[0] + inv[1][1] * t[1] + inv[1][2] * t[2]),
            -(inv[2][0] * t[0] + inv[2][1] * t[1] + inv[2][2] * t[2]),
        ];
        Some(Affine3 {
            linear: inv,
            translation: it,
        })
    }

    /// The matrix that maps normals: the inverse transpose of the linear part.
    pub fn normal_matrix(&self) -> Option<[[f64; 3]; 3]> {
        let inv = inverse3(&self.linear)?;
        Some([
            [inv[0][0], inv[1][0], inv[2][0]],
            [inv[0][1], inv[1][1], inv[2][1]],
            [inv[0][2], inv[1][2], inv[2][2]],
        ])
    }
}

/// The rotation taking glTF-frame coordinates (Y up, front +Z) to table-frame coordinates
/// (Z up, front -Y): `(X, Y, Z) ↦ (X, -Z, Y)`, a quarter turn about +x.
pub fn table_from_gltf() -> Affine3 {
    Affine3 {
        linear: [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]],
        translation: [0.0; 3],
    }
}

/// The quaternion `[x, y, z, w]` of [`table_from_gltf`].
pub fn table_from_gltf_quat_xyzw() -> [f64; 4] {
    let h = std::f64::consts::FRAC_1_SQRT_2;
    [h, 0.0, 0.0, h]
}

/// The inverse of [`table_from_gltf`]: `(x, y, z) ↦ (x, z, -y)`.
pub fn gltf_from_table() -> Affine3 {
    Affine3 {
        linear: [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]],
        translation: [0.0; 3],
    }
}

// ---------------------------------------------------------------------------------------------
// Small vector and quaternion helpers.

/// `a + b`.
pub fn add3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// `a - b`.
pub fn sub3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `s · a`.
pub fn scale3(a: [f64; 3], s: f64) -> [f64; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// Dot product.
pub fn dot3(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Cross product.
pub fn cross3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Euclidean norm.
pub fn norm3(a: [f64; 3]) -> f64 {
    dot3(a, a).sqrt()
}

/// `a / |a|`, or `a` itself when it is zero.
pub fn normalize3(a: [f64; 3]) -> [f64; 3] {
    let n = norm3(a);
    if n > 0.0 {
        scale3(a, 1.0 / n)
    } else {
        a
    }
}

fn det3(m: &[[f64; 3]; 3]) -> f64 {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}

fn inverse3(m: &[[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let det = det3(m);
    if det.abs() < 1e-300 || !det.is_finite() {
        return None;
    }
    let inv_det = 1.0 / det;
    Some([
        [
            (m[1][1] * m[2][2] - m[1][2] * m[2][1]) * inv_det,
            (m[0][2] * m[2][1] - m[0][1] * m[2][2]) * inv_det,
            (m[0][1] * m[1][2] - m[0][2] * m[1][1]) * inv_det,
        ],
        [
            (m[1][2] * m[2][0] - m[1][0] * m[2][2]) * inv_det,
            (m[0][0] * m[2][2] - m[0][2] * m[2][0]) * inv_det,
            (m[0][2] * m[1][0] - m[0][0] * m[1][2]) * inv_det,
        ],
        [
            (m[1][0] * m[2][1] - m[1][1] * m[2][0]) * inv_det,
            (m[0][1] * m[2][0] - m[0][0] * m[2][1]) * inv_det,
            (m[0][0] * m[1][1] - m[0][1] * m[1][0]) * inv_det,
        ],
    ])
}

/// The quaternion `[x, y, z, w]` of a rotation by `angle_rad` about `axis` (normalised here).
pub fn quat_from_axis_angle(axis: [f64; 3], angle_rad: f64) -> [f64; 4] {
    let a = normalize3(axis);
    let (s, c) = (angle_rad / 2.0).sin_cos();
    [a[0] * s, a[1] * s, a[2] * s, c]
}

/// Hamilton product `a · b` (apply `b` first, then `a`).
pub fn quat_mul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    let [ax, ay, az, aw] = a;
    let [bx, by, bz, bw] = b;
    [
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ]
}

/// The quaternion scaled to unit norm (the identity when it is zero).
pub fn quat_normalize(q: [f64; 4]) -> [f64; 4] {
    let n = q.iter().map(|c| c * c).sum::<f64>().sqrt();
    if n > 0.0 {
        [q[0] / n, q[1] / n, q[2] / n, q[3] / n]
    } else {
        [0.0, 0.0, 0.0, 1.0]
    }
}

/// The rotation matrix (row-major) of a quaternion `[x, y, z, w]` (normalised first).
pub fn quat_to_matrix(q: [f64; 4]) -> [[f64; 3]; 3] {
    let [x, y, z, w] = quat_normalize(q);
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - z * w),
            2.0 * (x * z + y * w),
        ],
        [
            2.0 * (x * y + z * w),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - x * w),
        ],
        [
            2.0 * (x * z - y * w),
            2.0 * (y * z + x * w),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

// ---------------------------------------------------------------------------------------------
// Bounds.

/// An axis-aligned box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    /// Smallest coordinates.
    pub min: [f64; 3],
    /// Largest coordinates.
    pub max: [f64; 3],
}

impl Aabb {
    /// The box of one point.
    pub fn from_point(p: [f64; 3]) -> Self {
        Self { min: p, max: p }
    }

    /// The box of some points; `None` when there are none.
    pub fn from_points(points: impl IntoIterator<Item = [f64; 3]>) -> Option<Self> {
        let mut it = points.into_iter();
        let mut b = Self::from_point(it.next()?);
        for p in it {
            b.extend(p);
        }
        Some(b)
    }

    /// Grows the box to contain `p`.
    pub fn extend(&mut self, p: [f64; 3]) {
        for (i, &c) in p.iter().enumerate() {
            self.min[i] = self.min[i].min(c);
            self.max[i] = self.max[i].max(c);
        }
    }

    /// The smallest box containing both.
    pub fn union(&self, other: &Aabb) -> Aabb {
        let mut b = *self;
        b.extend(other.min);
        b.extend(other.max);
        b
    }

    /// Centre point.
    pub fn center(&self) -> [f64; 3] {
        [
            (self.min[0] + self.max[0]) / 2.0,
            (self.min[1] + self.max[1]) / 2.0,
            (self.min[2] + self.max[2]) / 2.0,
        ]
    }

    /// Extents along each axis.
    pub fn size(&self) -> [f64; 3] {
        sub3(self.max, self.min)
    }

    /// The eight corners.
    pub fn corners(&self) -> [[f64; 3]; 8] {
        let (a, b) = (self.min, self.max);
        [
            [a[0], a[1], a[2]],
            [b[0], a[1], a[2]],
            [a[0], b[1], a[2]],
            [b[0], b[1], a[2]],
            [a[0], a[1], b[2]],
            [b[0], a[1], b[2]],
            [a[0], b[1], b[2]],
            [b[0], b[1], b[2]],
        ]
    }

    /// The axis-aligned box of this box's image under `map` (a bound, not tight for rotations).
    pub fn transformed(&self, map: &Affine3) -> Aabb {
        let corners = self.corners();
        let mut b = Aabb::from_point(map.apply_point(corners[0]));
        for c in &corners[1..] {
            b.extend(map.apply_point(*c));
        }
        b
    }

    /// True when the boxes share interior or boundary points.
    pub fn intersects(&self, other: &Aabb) -> bool {
        (0..3).all(|i| self.min[i] <= other.max[i] && other.min[i] <= self.max[i])
    }
}

// ---------------------------------------------------------------------------------------------
// Triangle meshes.

/// What is wrong with a mesh.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum MeshError {
    /// A triangle refers to a vertex that does not exist.
    #[error("triangle {triangle} refers to vertex {vertex}, but the mesh has {vertices} vertices")]
    IndexOutOfRange {
        /// Triangle index.
        triangle: usize,
        /// The bad vertex index.
        vertex: u32,
        /// Number of vertices.
        vertices: usize,
    },
    /// Attribute arrays of different lengths.
    #[error("{attribute} has {len} entries for {vertices} vertices")]
    AttributeLength {
        /// `normals` or `uvs`.
        attribute: &'static str,
        /// Its length.
        len: usize,
        /// Number of vertices.
        vertices: usize,
    },
    /// A NaN or infinite coordinate.
    #[error("vertex {vertex} has a non-finite {attribute}")]
    NonFinite {
        /// `position`, `normal` or `uv`.
        attribute: &'static str,
        /// Vertex index.
        vertex: usize,
    },
    /// A normal that is not of unit length.
    #[error("vertex {vertex} has a normal of length {length} (expected 1)")]
    NonUnitNormal {
        /// Vertex index.
        vertex: usize,
        /// Its length.
        length: f32,
    },
    /// A triangle of zero area.
    #[error("triangle {triangle} has zero area")]
    Degenerate {
        /// Triangle index.
        triangle: usize,
    },
}

/// An indexed triangle mesh with per-vertex normals and (optionally) texture coordinates.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TriMesh {
    /// Vertex positions, metres.
    pub positions: Vec<[f32; 3]>,
    /// Unit vertex normals, one per position.
    pub normals: Vec<[f32; 3]>,
    /// Texture coordinates (glTF convention: v grows downward in the image), one per
    /// position, or empty when the mesh has none.
    pub uvs: Vec<[f32; 2]>,
    /// Triangles as vertex indices, counter-clockwise seen from the front.
    pub triangles: Vec<[u32; 3]>,
}

/// How [`TriMesh::lathe`] shades the joints of its profile.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LatheOptions {
    /// Number of segments around the axis (at least 3).
    pub segments: usize,
    /// Joints of the profile whose turn is at most this angle (degrees) are shaded smooth;
    /// sharper joints get a crease.
    pub smooth_angle_deg: f64,
    /// Rotation of the seam about +Y, radians: the first segment starts at this angle from +Z
    /// toward +X.
    pub phase_rad: f64,
}

impl Default for LatheOptions {
    fn default() -> Self {
        Self {
            segments: 32,
            smooth_angle_deg: 35.0,
            phase_rad: 0.0,
        }
    }
}

impl LatheOptions {
    /// These options with `segments` segments.
    pub fn with_segments(mut self, segments: usize) -> Self {
        self.segments = segments;
        self
    }

    /// These options with a different smoothing angle.
    pub fn with_smooth_angle_deg(mut self, angle_deg: f64) -> Self {
        self.smooth_angle_deg = angle_deg;
        self
    }

    /// These options with the seam rotated by `phase_rad`.
    pub fn with_phase_rad(mut self, phase_rad: f64) -> Self {
        self.phase_rad = phase_rad;
        self
    }
}

/// `p` in single precision.
pub(crate) fn to_f32(p: [f64; 3]) -> [f32; 3] {
    [p[0] as f32, p[1] as f32, p[2] as f32]
}

fn to_f64(p: [f32; 3]) -> [f64; 3] {
    [p[0] as f64, p[1] as f64, p[2] as f64]
}

impl TriMesh {
    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// True when the mesh has no triangle.
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// True when the mesh carries texture coordinates.
    pub fn has_uvs(&self) -> bool {
        !self.uvs.is_empty()
    }

    /// Position `i` as `f64`.
    pub fn position(&self, i: u32) -> [f64; 3] {
        to_f64(self.positions[i as usize])
    }

    /// The three corners of triangle `t`.
    pub fn triangle_points(&self, t: usize) -> [[f64; 3]; 3] {
        let [a, b, c] = self.triangles[t];
        [self.position(a), self.position(b), self.position(c)]
    }

    /// The bounds of the vertices; `None` for a mesh without vertices.
    pub fn bounds(&self) -> Option<Aabb> {
        Aabb::from_points(self.positions.iter().map(|p| to_f64(*p)))
    }

    /// Appends `other`; texture coordinates are kept only when both meshes have them (a mesh
    /// without any gets zeros when the other has some and this one is empty).
    pub fn append(&mut self, other: &TriMesh) {
        let base = self.positions.len() as u32;
        let keep_uvs = (self.has_uvs() || self.positions.is_empty()) && other.has_uvs();
        if !keep_uvs {
            self.uvs.clear();
        }
        self.positions.extend_from_slice(&other.positions);
        self.normals.extend_from_slice(&other.normals);
        if keep_uvs {
            self.uvs.extend_from_slice(&other.uvs);
        }
        self.triangles.extend(
            other
                .triangles
                .iter()
                .map(|t| [t[0] + base, t[1] + base, t[2] + base]),
        );
    }

    /// This mesh with every vertex mapped by `map`; normals follow the inverse transpose and a
    /// mirroring map flips the winding so that front faces stay front faces.
    pub fn transformed(&self, map: &Affine3) -> TriMesh {
        let normal_matrix = map.normal_matrix().unwrap_or(map.linear);
        let positions = self
            .positions
            .iter()
            .map(|p| to_f32(map.apply_point(to_f64(*p))))
            .collect();
        let normals = self
            .normals
            .iter()
            .map(|n| {
                let n = to_f64(*n);
                let m = &normal_matrix;
                to_f32(normalize3([
                    m[0][0] * n[0] + m[0][1] * n[1] + m[0][2] * n[2],
                    m[1][0] * n[0] + m[1][1] * n[1] + m[1][2] * n[2],
                    m[2][0] * n[0] + m[2][1] * n[1] + m[2][2] * n[2],
                ]))
            })
            .collect();
        let triangles = if map.determinant() < 0.0 {
            self.triangles.iter().map(|t| [t[0], t[2], t[1]]).collect()
        } else {
            self.triangles.clone()
        };
        TriMesh {
            positions,
            normals,
            uvs: self.uvs.clone(),
            triangles,
        }
    }

    /// Checks indices, attribute lengths, finiteness, unit normals and non-degenerate
    /// triangles (what the glTF validator also checks).
    pub fn check(&self) -> Result<(), MeshError> {
        let n = self.positions.len();
        if self.normals.len() != n {
            return Err(MeshError::AttributeLength {
                attribute: "normals",
                len: self.normals.len(),
                vertices: n,
            });
        }
        if !self.uvs.is_empty() && self.uvs.len() != n {
            return Err(MeshError::AttributeLength {
                attribute: "uvs",
                len: self.uvs.len(),
                vertices: n,
            });
        }
        for (i, p) in self.positions.iter().enumerate() {
            if p.iter().any(|c| !c.is_finite()) {
                return Err(MeshError::NonFinite {
                    attribute: "position",
                    vertex: i,
                });
            }
        }
        for (i, v) in self.normals.iter().enumerate() {
            if v.iter().any(|c| !c.is_finite()) {
                return Err(MeshError::NonFinite {
                    attribute: "normal",
                    vertex: i,
                });
            }
            let length = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            if (length - 1.0).abs() > 5e-4 {
                return Err(MeshError::NonUnitNormal { vertex: i, length });
            }
        }
        for (i, uv) in self.uvs.iter().enumerate() {
            if uv.iter().any(|c| !c.is_finite()) {
                return Err(MeshError::NonFinite {
                    attribute: "uv",
                    vertex: i,
                });
            }
        }
        for (t, tri) in self.triangles.iter().enumerate() {
            for &vertex in tri {
                if vertex as usize >= n {
                    return Err(MeshError::IndexOutOfRange {
                        triangle: t,
                        vertex,
                        vertices: n,
                    });
                }
            }
            // Degenerate as the validator sees it: in f32 positions.
            let [a, b, c] = tri.map(|i| self.positions[i as usize]);
            let e1 = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            let e2 = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
            let cross = [
                e1[1] * e2[2] - e1[2] * e2[1],
                e1[2] * e2[0] - e1[0] * e2[2],
                e1[0] * e2[1] - e1[1] * e2[0],
            ];
            if cross == [0.0; 3] || tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
                return Err(MeshError::Degenerate { triangle: t });
            }
        }
        Ok(())
    }

    /// The signed volume enclosed by the mesh (positive for a closed mesh with outward
    /// normals; meaningless for an open one).
    pub fn signed_volume(&self) -> f64 {
        self.triangles
            .iter()
            .enumerate()
            .map(|(t, _)| {
                let [a, b, c] = self.triangle_points(t);
                dot3(a, cross3(b, c)) / 6.0
            })
            .sum()
    }

    /// Area of all triangles.
    pub fn area(&self) -> f64 {
        (0..self.triangles.len())
            .map(|t| {
                let [a, b, c] = self.triangle_points(t);
                norm3(cross3(sub3(b, a), sub3(c, a))) / 2.0
            })
            .sum()
    }

    // -----------------------------------------------------------------------------------------
    // Builders.

    /// A box of `size` (x, y, z) centred at the origin, flat-shaded, each face mapped to the
    /// whole texture (u along the face's first in-plane axis, v downward).
    pub fn cuboid(size: [f64; 3]) -> TriMesh {
        let h = [size[0] / 2.0, size[1] / 2.0, size[2] / 2.0];
        // (normal, u axis, v axis) per face: u points right and v down as the face is seen
        // from outside, so u × v = -normal and the corners (-u,-v) (+u,-v) (+u,+v) (-u,+v)
        // run clockwise seen from outside; the triangles take them in reverse.
        let faces: [([f64; 3], [f64; 3], [f64; 3]); 6] = [
            ([1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, -1.0, 0.0]),
            ([-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]),
            ([0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
            ([0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]),
            ([0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]),
            ([0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]),
        ];
        let mut mesh = TriMesh::default();
        for (normal, u, v) in faces {
            let base = mesh.positions.len() as u32;
            for (su, sv) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                let p: [f64; 3] =
                    std::array::from_fn(|i| (normal[i] + su * u[i] + sv * v[i]) * h[i]);
                mesh.positions.push(to_f32(p));
                mesh.normals.push(to_f32(normal));
                mesh.uvs
                    .push([((su + 1.0) / 2.0) as f32, ((sv + 1.0) / 2.0) as f32]);
            }
            mesh.triangles.push([base, base + 2, base + 1]);
            mesh.triangles.push([base, base + 3, base + 2]);
        }
        mesh
    }

    /// A surface of revolution about +Y. `profile` is a polyline of `(radius, y)` points; a
    /// point with radius 0 is a pole. The outside of the surface is on the right of the
    /// profile's direction in the (radius, y) half-plane: a profile that starts on the axis at
    /// the bottom, runs outward and up the outer wall, over the rim and down the inner wall
    /// back to the axis encloses a solid (a cup). Texture coordinates: u around the axis, v
    /// along the profile (by arc length).
    pub fn lathe(profile: &[[f64; 2]], options: LatheOptions) -> TriMesh {
        let segments = options.segments.max(3);
        let mut mesh = TriMesh::default();
        if profile.len() < 2 {
            return mesh;
        }
        // Segment directions and normals in the (r, y) half-plane.
        let seg_count = profile.len() - 1;
        let mut seg_normals = Vec::with_capacity(seg_count);
        let mut lengths = Vec::with_capacity(seg_count);
        for i in 0..seg_count {
            let dr = profile[i + 1][0] - profile[i][0];
            let dy = profile[i + 1][1] - profile[i][1];
            let len = (dr * dr + dy * dy).sqrt();
            lengths.push(len);
            seg_normals.push(if len > 0.0 {
                [dy / len, -dr / len]
            } else {
                [0.0, 0.0]
            });
        }
        let total: f64 = lengths.iter().sum::<f64>().max(1e-12);
        let cos_smooth = options.smooth_angle_deg.to_radians().cos();
        let mut arc = 0.0;
        for i in 0..seg_count {
            let (a, b) = (profile[i], profile[i + 1]);
            if lengths[i] <= 0.0 || (a[0] <= 0.0 && b[0] <= 0.0) {
                arc += lengths[i];
                continue;
            }
            let n = seg_normals[i];
            let joint_normal = |j: Option<usize>| -> [f64; 2] {
                match j {
                    Some(j) if lengths[j] > 0.0 => {
                        let m = seg_normals[j];
                        if n[0] * m[0] + n[1] * m[1] >= cos_smooth {
                            let s = [n[0] + m[0], n[1] + m[1]];
                            let l = (s[0] * s[0] + s[1] * s[1]).sqrt();
                            if l > 1e-9 {
                                return [s[0] / l, s[1] / l];
                            }
                        }
                        n
                    }
                    _ => n,
                }
            };
            let na = if i > 0 { joint_normal(Some(i - 1)) } else { n };
            let nb = if i + 1 < seg_count {
                joint_normal(Some(i + 1))
            } else {
                n
            };
            let va = arc / total;
            arc += lengths[i];
            let vb = arc / total;
            let base = mesh.positions.len() as u32;
            let ring = segments as u32 + 1;
            for (point, normal, v) in [(a, na, va), (b, nb, vb)] {
                for s in 0..=segments {
                    let phi = options.phase_rad + TAU * s as f64 / segments as f64;
                    let (sin, cos) = phi.sin_cos();
                    mesh.positions
                        .push(to_f32([point[0] * sin, point[1], point[0] * cos]));
                    mesh.normals.push(to_f32(normalize3([
                        normal[0] * sin,
                        normal[1],
                        normal[0] * cos,
                    ])));
                    mesh.uvs
                        .push([(s as f64 / segments as f64) as f32, v as f32]);
                }
            }
            for s in 0..segments as u32 {
                let (a0, a1) = (base + s, base + s + 1);
                let (b0, b1) = (base + ring + s, base + ring + s + 1);
                if a[0] > 0.0 {
                    mesh.triangles.push([a0, a1, b1]);
                }
                if b[0] > 0.0 {
                    mesh.triangles.push([a0, b1, b0]);
                }
            }
        }
        mesh.remove_unused_vertices();
        mesh
    }

    /// A sphere of `radius` centred at the origin (a lathe with poles on the Y axis).
    pub fn uv_sphere(radius: f64, segments: usize, rings: usize) -> TriMesh {
        let rings = rings.max(2);
        let profile: Vec<[f64; 2]> = (0..=rings)
            .map(|i| {
                let t = -PI / 2.0 + PI * i as f64 / rings as f64;
                let r = if i == 0 || i == rings {
                    0.0
                } else {
                    radius * t.cos()
                };
                [r, radius * t.sin()]
            })
            .collect();
        TriMesh::lathe(
            &profile,
            LatheOptions::default()
                .with_segments(segments)
                .with_smooth_angle_deg(90.0),
        )
    }

    /// A closed cylinder about +Y from y = 0 to y = `height`.
    pub fn cylinder(radius: f64, height: f64, segments: usize) -> TriMesh {
        TriMesh::lathe(
            &[[0.0, 0.0], [radius, 0.0], [radius, height], [0.0, height]],
            LatheOptions::default().with_segments(segments),
        )
    }

    /// A tube of radius `tube_radius` swept along an arc of radius `arc_radius` in the XY
    /// plane, centred at the origin, from angle `start_rad` to `end_rad` (measured from +X
    /// toward +Y), with flat end caps. A mug handle is the arc from -90° to +90°.
    pub fn tube_arc(
        arc_radius: f64,
        tube_radius: f64,
        start_rad: f64,
        end_rad: f64,
        arc_segments: usize,
        tube_segments: usize,
    ) -> TriMesh {
        let arc_segments = arc_segments.max(1);
        let tube_segments = tube_segments.max(3);
        let mut mesh = TriMesh::default();
        let ring = tube_segments as u32 + 1;
        for i in 0..=arc_segments {
            let t = start_rad + (end_rad - start_rad) * i as f64 / arc_segments as f64;
            let (st, ct) = t.sin_cos();
            let centre = [arc_radius * ct, arc_radius * st, 0.0];
            let radial = [ct, st, 0.0];
            for j in 0..=tube_segments {
                let a = TAU * j as f64 / tube_segments as f64;
                let (sa, ca) = a.sin_cos();
                let normal = [radial[0] * ca, radial[1] * ca, sa];
                mesh.positions
                    .push(to_f32(add3(centre, scale3(normal, tube_radius))));
                mesh.normals.push(to_f32(normal));
                mesh.uvs.push([
                    (i as f64 / arc_segments as f64) as f32,
                    (j as f64 / tube_segments as f64) as f32,
                ]);
            }
        }
        let forward = end_rad >= start_rad;
        for i in 0..arc_segments as u32 {
            for j in 0..tube_segments as u32 {
                let a0 = i * ring + j;
                let a1 = a0 + 1;
                let b0 = a0 + ring;
                let b1 = b0 + 1;
                if forward {
                    mesh.triangles.push([a0, b0, b1]);
                    mesh.triangles.push([a0, b1, a1]);
                } else {
                    mesh.triangles.push([a0, b1, b0]);
                    mesh.triangles.push([a0, a1, b1]);
                }
            }
        }
        // End caps: discs facing along the arc's tangent, outward.
        for (t, outward_sign) in [(start_rad, -1.0), (end_rad, 1.0)] {
            let (st, ct) = t.sin_cos();
            let centre = [arc_radius * ct, arc_radius * st, 0.0];
            let radial = [ct, st, 0.0];
            let sweep_sign = if forward { 1.0 } else { -1.0 };
            let tangent = scale3([-st, ct, 0.0], outward_sign * sweep_sign);
            let base = mesh.positions.len() as u32;
            mesh.positions.push(to_f32(centre));
            mesh.normals.push(to_f32(tangent));
            mesh.uvs.push([0.5, 0.5]);
            for j in 0..tube_segments {
                let a = TAU * j as f64 / tube_segments as f64;
                let (sa, ca) = a.sin_cos();
                let offset = [radial[0] * ca, radial[1] * ca, sa];
                mesh.positions
                    .push(to_f32(add3(centre, scale3(offset, tube_radius))));
                mesh.normals.push(to_f32(tangent));
                mesh.uvs
                    .push([(0.5 + 0.5 * ca) as f32, (0.5 + 0.5 * sa) as f32]);
            }
            for j in 0..tube_segments as u32 {
                let a = base + 1 + j;
                let b = base + 1 + (j + 1) % tube_segments as u32;
                // Orient each cap triangle by its geometric normal.
                let p = [mesh.position(base), mesh.position(a), mesh.position(b)];
                let geometric = cross3(sub3(p[1], p[0]), sub3(p[2], p[0]));
                if dot3(geometric, tangent) >= 0.0 {
                    mesh.triangles.push([base, a, b]);
                } else {
                    mesh.triangles.push([base, b, a]);
                }
            }
        }
        mesh
    }

    /// Drops vertices no triangle uses (keeping the order of the others).
    pub fn remove_unused_vertices(&mut self) {
        let mut used = vec![false; self.positions.len()];
        for t in &self.triangles {
            for &i in t {
                used[i as usize] = true;
            }
        }
        if used.iter().all(|u| *u) {
            return;
        }
        let mut remap = vec![u32::MAX; self.positions.len()];
        let mut next = 0u32;
        for (i, u) in used.iter().enumerate() {
            if *u {
                remap[i] = next;
                next += 1;
            }
        }
        fn keep<T>(v: &mut Vec<T>, used: &[bool]) {
            let mut k = 0;
            v.retain(|_| {
                let r = used[k];
                k += 1;
                r
            });
        }
        keep(&mut self.positions, &used);
        keep(&mut self.normals, &used);
        if !self.uvs.is_empty() {
            keep(&mut self.uvs, &used);
        }
        for t in &mut self.triangles {
            for i in t.iter_mut() {
                *i = remap[*i as usize];
            }
        }
    }
}

/// Grid steps a metre at which [`closed_outward`] welds positions: positions closer than a
/// nanometre are one vertex (a lathe's seam computed as `sin(2π) · r` lands about 1e-18 m
/// from its start, while distinct vertices of a mesh in metres are farther apart than that).
const CLOSED_WELD_PER_M: f64 = 1e9;

/// How far from the origin [`weld`] takes positions, metres (a thousand kilometres: at a
/// nanometre grid, 1e15 steps, well inside an `i64`).
pub const WELD_REACH_M: f64 = 1e6;

/// A triangle soup with the vertices at one position taken as one ([`weld`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Welded {
    /// One position per welded vertex, that of its first vertex, in order of first appearance.
    pub positions: Vec<[f64; 3]>,
    /// The triangles over the welded vertices, in their order; those with a repeated corner
    /// are left out.
    pub triangles: Vec<[u32; 3]>,
}

/// Welds the vertices of a triangle soup: positions that round to one point of a grid of
/// `per_m` steps a metre are one vertex. Meshes split their vertices at seams, creases and
/// materials; edges and pieces are only found after welding. `None` when a position is not
/// finite or lies farther than [`WELD_REACH_M`] from the origin (where the grid would not hold
/// it). Every triangle index must be below `positions.len()`.
///
/// Shared positions are found by sorting, not hashing: std's SipHash over a 121,000-triangle
/// asset took a hundred milliseconds, sorting a few.
pub fn weld(
    positions: &[[f64; 3]],
    triangles: impl IntoIterator<Item = [u32; 3]>,
    per_m: f64,
) -> Option<Welded> {
    let mut keys: Vec<([i64; 3], u32)> = Vec::with_capacity(positions.len());
    for (i, p) in positions.iter().enumerate() {
        if !p.iter().all(|c| c.abs() <= WELD_REACH_M) {
            return None;
        }
        keys.push((p.map(|c| (c * per_m).round() as i64), i as u32));
    }
    keys.sort_unstable();
    // Each vertex's first vertex at its grid point (lower indices sort first), then ids in
    // order of first appearance.
    let mut first = vec![0u32; positions.len()];
    for group in keys.chunk_by(|a, b| a.0 == b.0) {
        for &(_, i) in group {
            first[i as usize] = group[0].1;
        }
    }
    let mut id = vec![0u32; positions.len()];
    let mut welded = Vec::new();
    for (i, p) in positions.iter().enumerate() {
        id[i] = if first[i] as usize == i {
            welded.push(*p);
            welded.len() as u32 - 1
        } else {
            id[first[i] as usize]
        };
    }
    let triangles = triangles
        .into_iter()
        .map(|t| t.map(|i| id[i as usize]))
        .filter(|[a, b, c]| a != b && b != c && a != c)
        .collect();
    Some(Welded {
        positions: welded,
        triangles,
    })
}

/// A connected piece of a welded triangle soup ([`pieces`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Piece {
    /// Its triangles, ascending.
    pub triangles: Vec<u32>,
    /// Whether it is closed and consistently oriented: each edge of its triangles is walked
    /// exactly once each way by them.
    pub closed: bool,
}

/// The pieces of a welded triangle soup: triangles joined across manifold edges (an edge
/// walked exactly once each way). Two closed boxes sharing an edge or a corner stay two
/// pieces. In order of their first triangle.
pub fn pieces(triangles: &[[u32; 3]]) -> Vec<Piece> {
    assert!(triangles.len() < 1 << 31, "pieces: 2^31 triangles or more");
    // Every edge as its two ends (lower first, packed in a u64) and (walked from the higher
    // end, triangle) packed in a u32, sorted: the entries of one edge are adjacent, the way
    // from the lower end first. Plain integers sort twice as fast as a tuple of four.
    const BACKWARD: u32 = 1 << 31;
    let mut edges: Vec<(u64, u32)> = Vec::with_capacity(3 * triangles.len());
    for (t, c) in triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (c[k], c[(k + 1) % 3]);
            let ends = (u64::from(a.min(b)) << 32) | u64::from(a.max(b));
            edges.push((ends, t as u32 | if a > b { BACKWARD } else { 0 }));
        }
    }
    edges.sort_unstable();
    // An edge walked exactly once each way (the forward entry sorts first).
    let manifold = |edge: &[(u64, u32)]| match *edge {
        [(_, s), (_, t)] => s & BACKWARD == 0 && t & BACKWARD != 0,
        _ => false,
    };
    let mut parent: Vec<u32> = (0..triangles.len() as u32).collect();
    fn root(parent: &mut [u32], mut x: u32) -> u32 {
        while parent[x as usize] != x {
            parent[x as usize] = parent[parent[x as usize] as usize];
            x = parent[x as usize];
        }
        x
    }
    for edge in edges.chunk_by(|a, b| a.0 == b.0) {
        if manifold(edge) {
            let (a, b) = (
                root(&mut parent, edge[0].1 & !BACKWARD),
                root(&mut parent, edge[1].1 & !BACKWARD),
            );
            if a != b {
                parent[a.max(b) as usize] = a.min(b);
            }
        }
    }
    // The pieces, numbered in order of their first triangle.
    let mut piece_of_root = vec![u32::MAX; triangles.len()];
    let mut out: Vec<Piece> = Vec::new();
    let mut piece_of = Vec::with_capacity(triangles.len());
    for t in 0..triangles.len() as u32 {
        let r = root(&mut parent, t) as usize;
        if piece_of_root[r] == u32::MAX {
            piece_of_root[r] = out.len() as u32;
            out.push(Piece {
                triangles: Vec::new(),
                closed: true,
            });
        }
        out[piece_of_root[r] as usize].triangles.push(t);
        piece_of.push(piece_of_root[r]);
    }
    // A piece is closed when, for every edge of its triangles, its own entries are exactly one
    // each way. An edge joined above is so; the others are sorted out per piece.
    let mut local: Vec<(u32, bool)> = Vec::new();
    for edge in edges.chunk_by(|a, b| a.0 == b.0) {
        if manifold(edge) {
            continue;
        }
        local.clear();
        local.extend(
            edge.iter()
                .map(|&(_, e)| (piece_of[(e & !BACKWARD) as usize], e & BACKWARD != 0)),
        );
        local.sort_unstable();
        for own in local.chunk_by(|a, b| a.0 == b.0) {
            if !matches!(*own, [(_, false), (_, true)]) {
                out[own[0].0 as usize].closed = false;
            }
        }
    }
    out
}

/// The signed volume bounded by `triangles` over `points` (the sum of the tetrahedra from the
/// origin): positive for a closed surface wound counter-clockwise seen from outside.
pub fn signed_volume_of(points: &[[f64; 3]], triangles: impl IntoIterator<Item = [u32; 3]>) -> f64 {
    let mut six_v = 0.0;
    for t in triangles {
        let [a, b, c] = t.map(|i| points[i as usize]);
        six_v += a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
            + a[2] * (b[0] * c[1] - b[1] * c[0]);
    }
    six_v / 6.0
}

/// Whether `meshes` together bound solids, wound counter-clockwise seen from outside: with the
/// vertices at one position taken as one ([`weld`], on a nanometre grid), every piece
/// ([`pieces`]) is closed, and encloses a volume (at least `1e-9` of the cube of its bounding
/// diagonal, which leaves out back-to-back sheets and inside-out pieces). Seen from outside
/// such a surface, the first triangle a ray meets faces the ray, so a triangle facing away is
/// never what a picture shows: a rasterizer may skip it
/// ([`crate::raster::DrawItem::closed_within`]). Triangles with a repeated corner are left
/// out; a position that is not finite or lies farther than [`WELD_REACH_M`] from the origin
/// makes the answer `false`.
pub fn closed_outward<'a>(meshes: impl IntoIterator<Item = &'a TriMesh>) -> bool {
    let meshes: Vec<&TriMesh> = meshes.into_iter().collect();
    let positions: Vec<[f64; 3]> = meshes
        .iter()
        .flat_map(|m| m.positions.iter().map(|p| to_f64(*p)))
        .collect();
    let mut base = 0u32;
    let mut triangles = Vec::new();
    for mesh in &meshes {
        triangles.extend(mesh.triangles.iter().map(|t| t.map(|i| base + i)));
        base += mesh.positions.len() as u32;
    }
    let Some(welded) = weld(&positions, triangles, CLOSED_WELD_PER_M) else {
        return false;
    };
    let pieces = pieces(&welded.triangles);
    !pieces.is_empty()
        && pieces.iter().all(|piece| {
            let corners = piece
                .triangles
                .iter()
                .map(|&t| welded.triangles[t as usize]);
            let points = corners
                .clone()
                .flatten()
                .map(|i| welded.positions[i as usize]);
            let d = Aabb::from_points(points).map_or(0.0, |b| norm3(sub3(b.max, b.min)));
            piece.closed && signed_volume_of(&welded.positions, corners) > 1e-9 * d * d * d
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;
    use proptest::prelude::*;

    #[test]
    fn closed_outward_takes_solids_and_leaves_out_holes_flips_and_sheets() {
        // A cuboid splits its vertices per face, a cup (lathe) per crease, with its seam a
        // hair (sin 2π · r) from its start, a sphere has poles: all bound solids.
        let cuboid = TriMesh::cuboid([0.3, 0.2, 0.1]);
        let sphere = TriMesh::uv_sphere(0.05, 24, 12);
        let cup = TriMesh::lathe(
            &[
                [0.0, 0.0],
                [0.04, 0.0],
                [0.04, 0.09],
                [0.035, 0.09],
                [0.035, 0.005],
                [0.0, 0.005],
            ],
            LatheOptions::default().with_segments(32),
        );
        for (name, mesh) in [("cuboid", &cuboid), ("sphere", &sphere), ("cup", &cup)] {
            assert!(closed_outward([mesh]), "{name}");
        }
        // Two solids, one split over two meshes (an asset's parts, one per material).
        let far = cuboid.transformed(&Affine3::from_translation([1.0, 0.0, 0.0]));
        let (top, bottom) = (
            TriMesh {
                triangles: far.triangles[..6].to_vec(),
                ..far.clone()
            },
            TriMesh {
                triangles: far.triangles[6..].to_vec(),
                ..far.clone()
            },
        );
        assert!(closed_outward([&sphere, &top, &bottom]));
        // Controls: half of it alone, a face missing, a triangle flipped, the solid turned
        // inside out (beside one that is not), two triangles back to back, no triangles.
        assert!(!closed_outward([&sphere, &top]));
        let mut holed = cuboid.clone();
        holed.triangles.truncate(10);
        assert!(!closed_outward([&holed]));
        let mut flipped = cuboid.clone();
        flipped.triangles[3].swap(1, 2);
        assert!(!closed_outward([&flipped]));
        let mut inside_out = far.clone();
        for t in &mut inside_out.triangles {
            t.swap(1, 2);
        }
        assert!(!closed_outward([&inside_out]));
        assert!(!closed_outward([&sphere, &inside_out]));
        let sheet = TriMesh {
            positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            normals: vec![[0.0, 0.0, 1.0]; 3],
            uvs: Vec::new(),
            triangles: vec![[0, 1, 2], [0, 2, 1]],
        };
        assert!(!closed_outward([&sheet]));
        assert!(!closed_outward([&TriMesh::default()]));
        // Welding is on a nanometre grid: a seam a micrometre open is a hole.
        let mut cracked = cup.clone();
        let last = cracked.positions.len() - 1;
        cracked.positions[last][0] += 1e-6;
        assert!(!closed_outward([&cracked]));
        // Out of the grid's reach, or not finite: not taken as closed (a kilometre box is,
        // but not two thousand kilometres away).
        let big = TriMesh::cuboid([1e3, 1e3, 1e3]);
        assert!(closed_outward([&big]));
        let far = big.transformed(&Affine3::from_translation([2e6, 0.0, 0.0]));
        assert!(!closed_outward([&far]));
        for bad in [f32::NAN, f32::INFINITY] {
            let mut moved = cuboid.clone();
            moved.positions[0][1] = bad;
            assert!(!closed_outward([&moved]), "{bad}");
        }
    }

    #[test]
    fn an_inside_out_solid_touching_a_good_one_is_not_closed() {
        // A big box and a small box turned inside out, sharing one corner: every edge is
        // walked once each way and the summed volume is positive, but the small box's faces
        // point inward, so a picture may show its back faces.
        let big = TriMesh::cuboid([0.2, 0.2, 0.2])
            .transformed(&Affine3::from_translation([0.1, 0.1, 0.1]));
        let small = TriMesh::cuboid([0.05, 0.05, 0.05])
            .transformed(&Affine3::from_translation([-0.025, -0.025, -0.025]));
        assert!(closed_outward([&big, &small]), "both outward: closed");
        let mut inverted = small.clone();
        for t in &mut inverted.triangles {
            t.swap(1, 2);
        }
        assert!(!closed_outward([&big, &inverted]));
    }

    #[test]
    fn weld_keeps_first_seen_order_and_refuses_what_the_grid_cannot_hold() {
        let positions = [
            [0.3, 0.0, 0.0],
            [0.0, 0.0, 0.0],
            [0.3 + 4e-8, 0.0, 0.0], // within half a step of 0.1 µm: vertex 0
            [0.0, 0.2, 0.0],
            [0.0, 0.0, 1e-7], // a whole step away: its own vertex
        ];
        let welded = weld(
            &positions,
            [[0, 1, 3], [2, 3, 1], [0, 2, 4], [1, 4, 3]],
            1e7,
        )
        .expect("all within reach");
        assert_eq!(
            welded.positions,
            vec![positions[0], positions[1], positions[3], positions[4]]
        );
        // The third triangle has a repeated corner once welded: left out.
        assert_eq!(welded.triangles, vec![[0, 1, 2], [0, 2, 1], [1, 3, 2]]);
        for bad in [f64::NAN, f64::NEG_INFINITY, 2e6] {
            let mut moved = positions;
            moved[3][2] = bad;
            assert_eq!(weld(&moved, [[0, 1, 3]], 1e7), None, "{bad}");
        }
        assert!(weld(&[[-9e5, 9e5, 0.0]], [], 1e9).is_some());
    }

    #[test]
    fn pieces_join_across_manifold_edges_only() {
        // Two tetrahedra sharing an edge (2–3), and a lone triangle hanging on a corner.
        let a = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
        let b = [[4, 3, 2], [4, 2, 5], [4, 5, 3], [5, 2, 3]];
        let mut triangles: Vec<[u32; 3]> = a.iter().chain(&b).copied().collect();
        triangles.push([0, 6, 7]);
        let found = pieces(&triangles);
        assert_eq!(
            found,
            vec![
                Piece {
                    triangles: vec![0, 1, 2, 3],
                    closed: true
                },
                Piece {
                    triangles: vec![4, 5, 6, 7],
                    closed: true
                },
                Piece {
                    triangles: vec![8],
                    closed: false
                },
            ]
        );
        // Controls: a triangle of the first flipped cuts it off its neighbours and opens the
        // rest; a missing triangle opens its piece.
        let mut flipped = triangles.clone();
        flipped[1].swap(1, 2);
        let found = pieces(&flipped);
        assert!(found
            .iter()
            .filter(|p| p.triangles.contains(&1))
            .all(|p| !p.closed));
        assert!(found
            .iter()
            .any(|p| p.triangles == vec![4, 5, 6, 7] && p.closed));
        let found = pieces(&triangles[1..]);
        assert!(!found[0].closed && found[1].closed);
    }

    fn assert_outward(mesh: &TriMesh) {
        // Every triangle's geometric normal agrees with its vertex normals.
        for (t, tri) in mesh.triangles.iter().enumerate() {
            let [a, b, c] = mesh.triangle_points(t);
            let g = normalize3(cross3(sub3(b, a), sub3(c, a)));
            let n: [f64; 3] = std::array::from_fn(|i| {
                tri.iter()
                    .map(|&v| mesh.normals[v as usize][i] as f64)
                    .sum::<f64>()
            });
            assert!(
                dot3(g, n) > 0.0,
                "triangle {t} faces inward: {g:?} vs {n:?}"
            );
        }
    }

    #[test]
    fn cuboid_is_closed_outward_and_sized() {
        let m = TriMesh::cuboid([0.2, 0.1, 0.4]);
        m.check().expect("valid");
        assert_outward(&m);
        assert_abs_diff_eq!(m.signed_volume(), 0.2 * 0.1 * 0.4, epsilon = 1e-9);
        assert_abs_diff_eq!(
            m.area(),
            2.0 * (0.2 * 0.1 + 0.1 * 0.4 + 0.2 * 0.4),
            epsilon = 1e-7
        );
        let b = m.bounds().expect("bounds");
        let moved = Aabb {
            min: [0.1, 0.0, 0.0],
            max: [0.3, 0.1, 0.1],
        };
        assert!(b.intersects(&moved));
        assert!(!b.intersects(&Aabb::from_point([0.5, 0.0, 0.0])));
        let b = m.bounds().expect("bounds");
        assert_abs_diff_eq!(b.size()[2], 0.4, epsilon = 1e-7);
    }

    #[test]
    fn cylinder_volume_and_orientation() {
        let m = TriMesh::cylinder(0.05, 0.1, 64);
        m.check().expect("valid");
        assert_outward(&m);
        let exact = PI * 0.05 * 0.05 * 0.1;
        // A 64-gon has area (n/2) r² sin(2π/n).
        let polygon = 32.0 * 0.05 * 0.05 * (TAU / 64.0).sin() * 0.1;
        assert_abs_diff_eq!(m.signed_volume(), polygon, epsilon = 1e-9);
        assert!(m.signed_volume() < exact);
    }

    #[test]
    fn cup_profile_encloses_a_solid() {
        // Floor 5 mm, wall 4 mm.
        let profile = [
            [0.0, 0.0],
            [0.04, 0.0],
            [0.04, 0.1],
            [0.036, 0.1],
            [0.036, 0.005],
            [0.0, 0.005],
        ];
        let m = TriMesh::lathe(&profile, LatheOptions::default().with_segments(48));
        m.check().expect("valid");
        assert_outward(&m);
        let n = 48.0;
        let ring = |r: f64| n / 2.0 * r * r * (TAU / n).sin();
        let expected = ring(0.04) * 0.1 - ring(0.036) * 0.095;
        assert_abs_diff_eq!(m.signed_volume(), expected, epsilon = 1e-9);
    }

    #[test]
    fn sphere_is_outward() {
        let m = TriMesh::uv_sphere(0.1, 24, 12);
        m.check().expect("valid");
        assert_outward(&m);
        assert!(m.signed_volume() > 0.0);
    }

    #[test]
    fn tube_arc_is_closed_and_outward() {
        for (start, end) in [(-PI / 2.0, PI / 2.0), (PI / 2.0, -PI / 2.0)] {
            let m = TriMesh::tube_arc(0.03, 0.005, start, end, 16, 12);
            m.check().expect("valid");
            assert_outward(&m);
            assert!(m.signed_volume() > 0.0);
        }
    }

    #[test]
    fn mirroring_keeps_faces_outward() {
        let m =
            TriMesh::cylinder(0.05, 0.1, 16).transformed(&Affine3::from_scale([-1.0, 1.0, 1.0]));
        assert_outward(&m);
        assert!(m.signed_volume() > 0.0);
    }

    #[test]
    fn table_from_gltf_matches_the_spec() {
        let m = table_from_gltf();
        // glTF up (+Y) is table up (+z); glTF front (+Z) faces the observer (-y).
        assert_eq!(m.apply_point([0.0, 1.0, 0.0]), [0.0, 0.0, 1.0]);
        assert_eq!(m.apply_point([0.0, 0.0, 1.0]), [0.0, -1.0, 0.0]);
        assert_eq!(m.apply_point([1.0, 0.0, 0.0]), [1.0, 0.0, 0.0]);
        let q = Affine3::from_quat_xyzw(table_from_gltf_quat_xyzw());
        for (r, row) in q.linear.iter().enumerate() {
            for (c, v) in row.iter().enumerate() {
                assert_abs_diff_eq!(*v, m.linear[r][c], epsilon = 1e-12);
            }
        }
        let back = gltf_from_table().mul(&m);
        assert_eq!(back, Affine3::IDENTITY);
    }

    proptest! {
        #[test]
        fn affine_inverse_round_trips(
            t in proptest::array::uniform3(-2.0f64..2.0),
            axis in proptest::array::uniform3(-1.0f64..1.0),
            angle in -3.0f64..3.0,
            s in proptest::array::uniform3(0.2f64..3.0),
            p in proptest::array::uniform3(-1.0f64..1.0),
        ) {
            prop_assume!(norm3(axis) > 1e-3);
            let m = Affine3::from_trs(t, quat_from_axis_angle(axis, angle), s);
            let inv = m.inverse().expect("invertible");
            let back = inv.apply_point(m.apply_point(p));
            for i in 0..3 {
                prop_assert!((back[i] - p[i]).abs() < 1e-9);
            }
            let m4 = Affine3::from_rows_4x4(m.to_rows_4x4());
            prop_assert_eq!(m4, m);
        }

        #[test]
        fn quat_mul_composes_rotations(
            a in proptest::array::uniform3(-1.0f64..1.0),
            b in proptest::array::uniform3(-1.0f64..1.0),
            ta in -3.0f64..3.0,
            tb in -3.0f64..3.0,
            p in proptest::array::uniform3(-1.0f64..1.0),
        ) {
            prop_assume!(norm3(a) > 1e-3 && norm3(b) > 1e-3);
            let qa = quat_from_axis_angle(a, ta);
            let qb = quat_from_axis_angle(b, tb);
            let composed = Affine3::from_quat_xyzw(quat_mul(qa, qb)).apply_point(p);
            let sequential = Affine3::from_quat_xyzw(qa)
                .mul(&Affine3::from_quat_xyzw(qb))
                .apply_point(p);
            for i in 0..3 {
                prop_assert!((composed[i] - sequential[i]).abs() < 1e-9);
            }
        }
    }
}
