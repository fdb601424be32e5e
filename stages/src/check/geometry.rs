//! Placed collision shapes and the queries `check` asks of them: signed distance and
//! penetration depth of two convex parts (parry3d's GJK and EPA), and how far a part can fall
//! straight down before it touches another (a GJK shape cast).
//!
//! A part is the convex hull of its points. Its points are kept relative to the part's own
//! centre, in `f32` (parry3d's precision) and in **millimetres**, while the centre is kept in
//! `f64` metres; moving a body only moves centres and bounds. Millimetres because parry3d's
//! GJK has absolute tolerances (about 10⁻⁵ of a unit): in metres it misjudges millimetre-thin
//! parts (a cup's wall), in millimetres it resolves them to a few nanometres.

use std::sync::{Arc, OnceLock};

use parry3d::math::{Isometry, Point, Real, Vector};
use parry3d::query::details::{
    cast_shapes_support_map_support_map, contact_support_map_support_map, ShapeCastOptions,
};
use parry3d::shape::SupportMap;

/// Millimetres per metre: parry3d sees millimetres.
const MM: f64 = 1000.0;

/// An axis-aligned box, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bounds {
    /// Minimum corner.
    pub min: [f64; 3],
    /// Maximum corner.
    pub max: [f64; 3],
}

impl Bounds {
    /// The empty box (the neutral element of [`Bounds::union`]).
    pub fn empty() -> Self {
        Self {
            min: [f64::INFINITY; 3],
            max: [f64::NEG_INFINITY; 3],
        }
    }

    /// The smallest box holding both.
    pub fn union(&self, other: &Bounds) -> Bounds {
        Bounds {
            min: std::array::from_fn(|k| self.min[k].min(other.min[k])),
            max: std::array::from_fn(|k| self.max[k].max(other.max[k])),
        }
    }

    /// This box moved by `t`.
    pub fn translated(&self, t: [f64; 3]) -> Bounds {
        Bounds {
            min: std::array::from_fn(|k| self.min[k] + t[k]),
            max: std::array::from_fn(|k| self.max[k] + t[k]),
        }
    }

    /// Whether the boxes, each grown by `margin` on every side, overlap.
    pub fn overlaps(&self, other: &Bounds, margin: f64) -> bool {
        (0..3).all(|k| self.min[k] - margin <= other.max[k] && other.min[k] - margin <= self.max[k])
    }

    /// Whether the boxes' projections on the table plane overlap (grown by `margin`).
    pub fn overlaps_xy(&self, other: &Bounds, margin: f64) -> bool {
        (0..2).all(|k| self.min[k] - margin <= other.max[k] && other.min[k] - margin <= self.max[k])
    }

    /// The distance between the boxes (0 when they overlap).
    pub fn distance(&self, other: &Bounds) -> f64 {
        let gap: f64 = (0..3)
            .map(|k| {
                let d = (other.min[k] - self.max[k]).max(self.min[k] - other.max[k]);
                d.max(0.0).powi(2)
            })
            .sum();
        gap.sqrt()
    }

    /// The centre.
    pub fn center(&self) -> [f64; 3] {
        std::array::from_fn(|k| 0.5 * (self.min[k] + self.max[k]))
    }
}

/// A hull's points as given and its triangles, to find its faces' normals from.
#[derive(Debug, Clone)]
struct Faces {
    /// The points as given, table frame, metres.
    points: GivenPoints,
    /// The triangles (indices into the points), shared with the shape they were placed from.
    triangles: Arc<[[u32; 3]]>,
    /// Whether the triangles wind inward (a mirroring placement turns them inside out): the
    /// normals are then those of the triangles, negated.
    inward: bool,
}

/// Where a hull's points as given come from.
#[derive(Debug, Clone)]
enum GivenPoints {
    /// Kept as they were given.
    Kept(Arc<[[f64; 3]]>),
    /// A shape's part (its own frame) and the placement that put it in the table frame: the
    /// points are placed again, by the same arithmetic, when the normals are asked for. Most
    /// placed parts never are, so placing a part keeps no copy of its points in metres and
    /// allocates nothing but its points in millimetres.
    Placed {
        part: Arc<[[f64; 3]]>,
        placement: Arc<Placement>,
    },
}

impl GivenPoints {
    fn get(&self, i: usize) -> [f64; 3] {
        match self {
            Self::Kept(points) => points[i],
            Self::Placed { part, placement } => placement.apply(part[i]),
        }
    }
}

/// How a layout places a shape's points in the table frame: scale in the asset's frame, then
/// turn (`rotation`, a rotation matrix), then move.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    /// The rotation matrix.
    pub rotation: [[f64; 3]; 3],
    /// The scale along the asset's axes.
    pub scale: [f64; 3],
    /// The translation, metres.
    pub translation: [f64; 3],
}

impl Placement {
    /// Scale by `scale` along the asset's axes, turn by `rotation_xyzw` (a quaternion), move
    /// to `position_m`.
    pub fn new(position_m: [f64; 3], rotation_xyzw: [f64; 4], scale: [f64; 3]) -> Self {
        Self {
            rotation: crate::mesh::quat_to_matrix(rotation_xyzw),
            scale,
            translation: position_m,
        }
    }

    /// The point `p` of the asset's frame in the table frame.
    #[inline(always)]
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let (m, s, t) = (&self.rotation, self.scale, self.translation);
        let q = [p[0] * s[0], p[1] * s[1], p[2] * s[2]];
        std::array::from_fn(|r| t[r] + m[r][0] * q[0] + m[r][1] * q[1] + m[r][2] * q[2])
    }

    /// Whether the placement mirrors (turns faces inside out).
    pub fn mirrors(&self) -> bool {
        let s = self.scale;
        s[0] * s[1] * s[2] < 0.0
    }
}

/// The bounds of `points`, taken point by point in order.
fn bounds_of(points: &[[f64; 3]]) -> Bounds {
    let mut bounds = Bounds::empty();
    for p in points {
        bounds = bounds.union(&Bounds { min: *p, max: *p });
    }
    bounds
}

/// `part`'s points placed by `placement` into `out` (cleared first), and their bounds.
fn place_points(part: &[[f64; 3]], placement: &Placement, out: &mut Vec<[f64; 3]>) -> Bounds {
    out.clear();
    out.extend(part.iter().map(|&p| placement.apply(p)));
    bounds_of(out)
}

/// One convex part placed in the table frame.
#[derive(Debug, Clone)]
pub struct Hull {
    /// The centre the points are relative to, table frame, metres.
    pub center: [f64; 3],
    /// The points relative to `center`.
    points: Vec<Point<Real>>,
    /// The points as given and the outward faces, to find the faces' normals from when a
    /// depth needs them ([`Hull::normals`]): most placed parts never touch another, and
    /// finding the normals of every part was most of a check's time.
    faces: Faces,
    /// The outward normals of the hull's faces (unit), when its faces are known: found once,
    /// on first use.
    normals: OnceLock<Vec<[f64; 3]>>,
    /// Bounds in the table frame.
    pub bounds: Bounds,
}

/// The support function of a point set is that of its convex hull.
struct PointsRef<'a>(&'a [Point<Real>]);

impl SupportMap for PointsRef<'_> {
    fn local_support_point(&self, dir: &Vector<Real>) -> Point<Real> {
        let mut best = self.0[0];
        let mut best_dot = best.coords.dot(dir);
        for p in &self.0[1..] {
            let d = p.coords.dot(dir);
            if d > best_dot {
                best_dot = d;
                best = *p;
            }
        }
        best
    }
}

impl Hull {
    /// The hull of `points` (table frame, metres); `None` without points.
    pub fn new(points: &[[f64; 3]]) -> Option<Self> {
        let faces = Faces {
            points: GivenPoints::Kept(Arc::new([])),
            triangles: Arc::new([]),
            inward: false,
        };
        Self::of_points(points, bounds_of(points), faces)
    }

    /// The hull of `points` whose faces are `triangles` (indices into `points`), which make
    /// penetration depths exact for face contacts. The triangles wind outward, or inward when
    /// `inward` (a mirrored placement of outward ones: they are shared with the shape, not
    /// rewound).
    pub fn with_faces(
        points: Vec<[f64; 3]>,
        triangles: Arc<[[u32; 3]]>,
        inward: bool,
    ) -> Option<Self> {
        let faces = Faces {
            points: GivenPoints::Kept(Arc::from(&points[..])),
            triangles,
            inward,
        };
        Self::of_points(&points, bounds_of(&points), faces)
    }

    /// The hull of a shape's part (its own frame) put in the table frame by `placement`,
    /// with the part's outward faces: [`Hull::with_faces`] of the placed points, which are
    /// placed into `scratch` (reused from part to part) and not kept.
    pub fn placed(
        part: &Arc<[[f64; 3]]>,
        triangles: &Arc<[[u32; 3]]>,
        placement: &Arc<Placement>,
        scratch: &mut Vec<[f64; 3]>,
    ) -> Option<Self> {
        let bounds = place_points(part, placement, scratch);
        let faces = Faces {
            points: GivenPoints::Placed {
                part: Arc::clone(part),
                placement: Arc::clone(placement),
            },
            triangles: Arc::clone(triangles),
            inward: placement.mirrors(),
        };
        Self::of_points(scratch, bounds, faces)
    }

    /// The hull of `points` (their bounds given), with `faces`.
    fn of_points(points: &[[f64; 3]], bounds: Bounds, faces: Faces) -> Option<Self> {
        if points.is_empty() {
            return None;
        }
        let center = bounds.center();
        let relative = points
            .iter()
            .map(|p| {
                Point::new(
                    ((p[0] - center[0]) * MM) as Real,
                    ((p[1] - center[1]) * MM) as Real,
                    ((p[2] - center[2]) * MM) as Real,
                )
            })
            .collect();
        Some(Self {
            center,
            points: relative,
            faces,
            normals: OnceLock::new(),
            bounds,
        })
    }

    /// The outward normals of the hull's faces (unit; parallel ones once), from its points as
    /// given (a later [`Hull::translate`] leaves them as they were).
    fn normals(&self) -> &[[f64; 3]] {
        self.normals.get_or_init(|| {
            let Faces {
                points: raw,
                triangles,
                inward,
            } = &self.faces;
            let mut normals: Vec<[f64; 3]> = Vec::with_capacity(triangles.len());
            for t in triangles.iter() {
                let [a, b, c] = t.map(|i| raw.get(i as usize));
                // Inward triangles are read rewound, [a, c, b]: the same arithmetic, so the
                // same bits (a negated cross product would differ in the sign of zeros).
                let (u, v) = if *inward {
                    (sub(c, a), sub(b, a))
                } else {
                    (sub(b, a), sub(c, a))
                };
                let n = [
                    u[1] * v[2] - u[2] * v[1],
                    u[2] * v[0] - u[0] * v[2],
                    u[0] * v[1] - u[1] * v[0],
                ];
                let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
                if len > 1e-15 {
                    let n = n.map(|x| x / len);
                    if !normals.iter().any(|m| dot(*m, n) > 1.0 - 1e-9) {
                        normals.push(n);
                    }
                }
            }
            normals
        })
    }

    /// The hull's points in the table frame, metres.
    pub fn points(&self) -> Vec<[f64; 3]> {
        self.points
            .iter()
            .map(|p| std::array::from_fn(|k| self.center[k] + f64::from(p[k]) / MM))
            .collect()
    }

    /// Moves the hull by `t` (metres).
    pub fn translate(&mut self, t: [f64; 3]) {
        for (c, v) in self.center.iter_mut().zip(t) {
            *c += v;
        }
        self.bounds = self.bounds.translated(t);
    }

    fn support(&self) -> PointsRef<'_> {
        PointsRef(&self.points)
    }

    /// The largest value of `p · dir` over the hull's points (its support function), metres.
    pub fn support_value(&self, dir: [f64; 3]) -> f64 {
        let c: f64 = (0..3).map(|k| self.center[k] * dir[k]).sum();
        let local = self
            .points
            .iter()
            .map(|p| f64::from(p.x) * dir[0] + f64::from(p.y) * dir[1] + f64::from(p.z) * dir[2])
            .fold(f64::NEG_INFINITY, f64::max);
        c + local / MM
    }

    fn offset_to(&self, other: &Hull) -> Isometry<Real> {
        Isometry::translation(
            ((other.center[0] - self.center[0]) * MM) as Real,
            ((other.center[1] - self.center[1]) * MM) as Real,
            ((other.center[2] - self.center[2]) * MM) as Real,
        )
    }
}

/// The convex hull of points (metres): its vertices and outward triangles; the points
/// themselves, without faces, when they span no volume.
pub fn convex_hull(points: &[[f64; 3]]) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let scaled: Vec<Point<Real>> = points
        .iter()
        .map(|p| {
            Point::new(
                (p[0] * MM) as Real,
                (p[1] * MM) as Real,
                (p[2] * MM) as Real,
            )
        })
        .collect();
    // parry3d's hull can panic on degenerate input.
    match std::panic::catch_unwind(|| parry3d::transformation::try_convex_hull(&scaled)) {
        Ok(Ok((hull, triangles))) if !triangles.is_empty() => (
            hull.iter()
                .map(|p| {
                    [
                        f64::from(p.x) / MM,
                        f64::from(p.y) / MM,
                        f64::from(p.z) / MM,
                    ]
                })
                .collect(),
            triangles,
        ),
        _ => (points.to_vec(), Vec::new()),
    }
}

/// How two convex parts relate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Proximity {
    /// Signed distance, metres: the gap when apart, minus the penetration depth when they
    /// overlap (the length of the shortest translation that separates them).
    pub signed_distance_m: f64,
    /// The direction from the first part toward the second (unit): moving the second along it
    /// (or the first against it) separates them fastest.
    pub normal: [f64; 3],
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// How far the parts overlap along the unit direction `d` (from `a` toward `b`): moving `b`
/// by that much along `d` separates them; negative when a gap separates them along `d`.
pub fn overlap_along(a: &Hull, b: &Hull, d: [f64; 3]) -> f64 {
    a.support_value(d) + b.support_value(d.map(|v| -v))
}

/// The signed distance of two convex parts (GJK, and EPA when they overlap), verified.
///
/// parry3d's answer is a direction and a distance; along that direction the parts' projections
/// must be exactly that far apart (or overlap by that much). When they are not — GJK or EPA
/// stopped early on a degenerate configuration (two boxes face to face) — the answer is the
/// least overlap over the parts' face normals, parry3d's direction and a fixed set of
/// directions: exact for face contacts, and never less than the true depth.
pub fn proximity(a: &Hull, b: &Hull) -> Proximity {
    let pos12 = a.offset_to(b);
    // A huge prediction makes GJK report the closest points of separated parts too, so that
    // `None` only means EPA failed on overlapping parts.
    let found =
        contact_support_map_support_map(&pos12, &a.support(), &b.support(), 1e9).map(|contact| {
            Proximity {
                signed_distance_m: f64::from(contact.dist) / MM,
                normal: [
                    f64::from(contact.normal1.x),
                    f64::from(contact.normal1.y),
                    f64::from(contact.normal1.z),
                ],
            }
        });
    if let Some(p) = found {
        let along = overlap_along(a, b, p.normal);
        // f32 in millimetres: consistent to well under a micrometre.
        if (along + p.signed_distance_m).abs() <= 1e-6 + 1e-4 * p.signed_distance_m.abs() {
            return p;
        }
    }
    least_overlap(a, b, found.map(|p| p.normal))
}

/// The least overlap of two parts over candidate directions (see [`proximity`]).
fn least_overlap(a: &Hull, b: &Hull, hint: Option<[f64; 3]>) -> Proximity {
    let mut least = f64::INFINITY;
    let mut normal = [0.0, 0.0, 1.0];
    let candidates = sample_directions(a, b)
        .into_iter()
        .chain(hint)
        .chain(a.normals().iter().copied())
        .chain(b.normals().iter().map(|n| n.map(|v| -v)));
    for d in candidates {
        let overlap = overlap_along(a, b, d);
        if overlap < least {
            least = overlap;
            normal = d;
        }
    }
    Proximity {
        signed_distance_m: -least,
        normal,
    }
}

/// The directions a penetration depth is estimated along when EPA fails: the 26 directions of
/// a cube's faces, edges and corners, and the line between the centres.
fn sample_directions(a: &Hull, b: &Hull) -> Vec<[f64; 3]> {
    let mut dirs = Vec::with_capacity(27);
    for x in -1i32..=1 {
        for y in -1i32..=1 {
            for z in -1i32..=1 {
                if (x, y, z) != (0, 0, 0) {
                    let n = f64::from(x * x + y * y + z * z).sqrt();
                    dirs.push([f64::from(x) / n, f64::from(y) / n, f64::from(z) / n]);
                }
            }
        }
    }
    let d: [f64; 3] = std::array::from_fn(|k| b.center[k] - a.center[k]);
    let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    if n > 1e-12 {
        dirs.push(d.map(|v| v / n));
    }
    dirs
}

/// How far `moving` can fall straight down before it touches `fixed`, metres (at most
/// `max_m`); `None` when falling never brings them together.
///
/// The fall is measured from `raise_m` higher up, less `raise_m`: a part resting on another
/// while sinking into it by less than `raise_m` (the contact tolerance) then lands on it
/// instead of overlapping it, whatever the overlap's shortest way out (which, against the
/// side of a neighbouring convex part of the same object, can be sideways). Parts that still
/// overlap once raised hold each other (fall 0). Parts side by side never meet.
pub fn fall_distance(moving: &Hull, fixed: &Hull, raise_m: f64, max_m: f64) -> Option<f64> {
    let mut raised = moving.clone();
    raised.translate([0.0, 0.0, raise_m]);
    let pos12 = raised.offset_to(fixed);
    if proximity(&raised, fixed).signed_distance_m < 0.0 {
        return Some(0.0);
    }
    // In the moving part's frame the fixed one rises.
    let vel12 = Vector::new(0.0, 0.0, 1.0);
    let options = ShapeCastOptions {
        max_time_of_impact: ((max_m + raise_m) * MM) as Real,
        target_distance: 0.0,
        stop_at_penetration: false,
        compute_impact_geometry_on_penetration: true,
    };
    cast_shapes_support_map_support_map(
        &pos12,
        &vel12,
        &raised.support(),
        &fixed.support(),
        options,
    )
    .map(|hit| (f64::from(hit.time_of_impact) / MM - raise_m).max(0.0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    fn cube(center: [f64; 3], half: f64) -> Hull {
        let mut points = Vec::new();
        for x in [-half, half] {
            for y in [-half, half] {
                for z in [-half, half] {
                    points.push([center[0] + x, center[1] + y, center[2] + z]);
                }
            }
        }
        Hull::new(&points).expect("points")
    }

    /// The face normals, found on first use, are those of the faces as placed: a box turned
    /// about z has its six (each face's two triangles count once), the same after a move.
    /// Control: without faces there are none.
    #[test]
    fn face_normals_are_found_on_first_use_from_the_faces_as_placed() {
        let (c, s) = (0.6f64.cos(), 0.6f64.sin());
        let turn = |p: [f64; 3]| [c * p[0] - s * p[1], s * p[0] + c * p[1], p[2]];
        let mesh = crate::mesh::TriMesh::cuboid([0.2, 0.1, 0.05]);
        let points: Vec<[f64; 3]> = mesh
            .positions
            .iter()
            .map(|p| turn(p.map(f64::from)))
            .collect();
        let triangles: Arc<[[u32; 3]]> = mesh.triangles.clone().into();
        let mut hull = Hull::with_faces(points.clone(), triangles.clone(), false).expect("hull");
        hull.translate([1.0, -2.0, 0.5]);
        let normals = hull.normals().to_vec();
        assert_eq!(normals.len(), 6, "{normals:?}");
        for axis in [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]] {
            for sign in [1.0, -1.0] {
                let want = turn(axis.map(|v: f64| v * sign));
                assert!(
                    normals.iter().any(|n| dot(*n, want) > 1.0 - 1e-9),
                    "{want:?} in {normals:?}"
                );
            }
        }
        assert!(Hull::new(&points).expect("hull").normals().is_empty());

        // Mirrored: the points through x = 0, the same triangles marked inward give, bit for
        // bit, the normals of the triangles rewound. Control: not marked, they point inward.
        let mirrored: Vec<[f64; 3]> = points.iter().map(|p| [-p[0], p[1], p[2]]).collect();
        let rewound: Arc<[[u32; 3]]> = mesh.triangles.iter().map(|t| [t[0], t[2], t[1]]).collect();
        let inward = Hull::with_faces(mirrored.clone(), triangles.clone(), true).expect("hull");
        let outward = Hull::with_faces(mirrored.clone(), rewound, false).expect("hull");
        let bits = |normals: &[[f64; 3]]| -> Vec<[u64; 3]> {
            normals.iter().map(|n| n.map(f64::to_bits)).collect()
        };
        assert_eq!(bits(inward.normals()), bits(outward.normals()));
        let unmarked = Hull::with_faces(mirrored, triangles, false).expect("hull");
        for (n, m) in unmarked.normals().iter().zip(outward.normals()) {
            assert_abs_diff_eq!(dot(*n, *m), -1.0, epsilon = 1e-12);
        }
    }

    /// A part placed by [`Hull::placed`] (its points placed into scratch space, placed again
    /// when the normals are asked for) is, bit for bit, the hull of the same points placed
    /// one by one and kept ([`Hull::with_faces`]): centre, points, bounds, normals, for a
    /// plain and a mirroring placement, with the scratch reused. Control: a placement turned
    /// by another angle gives other normals (the comparison sees a difference).
    #[test]
    fn a_placed_part_is_the_hull_of_its_placed_points_to_the_bit() {
        let mesh = crate::mesh::TriMesh::cuboid([0.2, 0.1, 0.05]);
        let part: Arc<[[f64; 3]]> = mesh
            .positions
            .iter()
            .map(|p| {
                [
                    f64::from(p[0]) + 0.013,
                    f64::from(p[1]),
                    f64::from(p[2]) * 1.7,
                ]
            })
            .collect();
        let triangles: Arc<[[u32; 3]]> = mesh.triangles.clone().into();
        let bits3 =
            |v: &[[f64; 3]]| -> Vec<[u64; 3]> { v.iter().map(|n| n.map(f64::to_bits)).collect() };
        let of_hull = |h: &Hull| {
            (
                h.center.map(f64::to_bits),
                bits3(&h.points()),
                bits3(&[h.bounds.min, h.bounds.max]),
                bits3(h.normals()),
            )
        };
        let mut scratch = Vec::new();
        let q = 0.3f64;
        for (rotation, scale) in [
            ([0.0, 0.0, q.sin(), q.cos()], [1.3, 0.7, 2.1]),
            ([0.1, -0.2, 0.3, 0.9], [-1.1, 0.9, 1.4]),
        ] {
            let placement = Arc::new(Placement::new([0.4, -0.25, 0.8], rotation, scale));
            let placed = Hull::placed(&part, &triangles, &placement, &mut scratch).expect("hull");
            // The placement written out: scale, turn, move.
            let (m, t) = (crate::mesh::quat_to_matrix(rotation), [0.4, -0.25, 0.8]);
            let one_by_one: Vec<[f64; 3]> = part
                .iter()
                .map(|p| {
                    let q = [p[0] * scale[0], p[1] * scale[1], p[2] * scale[2]];
                    std::array::from_fn(|r| t[r] + m[r][0] * q[0] + m[r][1] * q[1] + m[r][2] * q[2])
                })
                .collect();
            let inward = scale[0] * scale[1] * scale[2] < 0.0;
            let kept = Hull::with_faces(one_by_one, triangles.clone(), inward).expect("hull");
            assert_eq!(placed.normals().len(), 6);
            assert_eq!(of_hull(&placed), of_hull(&kept), "{rotation:?} {scale:?}");

            let turned = Arc::new(Placement::new(
                [0.4, -0.25, 0.8],
                [0.0, 0.0, 0.0, 1.0],
                scale,
            ));
            let other = Hull::placed(&part, &triangles, &turned, &mut scratch).expect("hull");
            assert_ne!(bits3(other.normals()), bits3(placed.normals()), "control");
        }
    }

    #[test]
    fn a_hull_gives_back_its_points_in_metres() {
        let mut hull = cube([1.0, 2.0, 0.5], 0.05);
        hull.translate([0.25, 0.0, -0.5]);
        let points = hull.points();
        assert_eq!(points.len(), 8);
        for p in &points {
            for (k, c) in [1.25, 2.0, 0.0].iter().enumerate() {
                assert_abs_diff_eq!((p[k] - c).abs(), 0.05, epsilon = 1e-6);
            }
        }
    }

    #[test]
    fn overlapping_cubes_have_their_overlap_as_depth() {
        let a = cube([0.0, 0.0, 0.05], 0.05);
        let b = cube([0.093, 0.0, 0.05], 0.05);
        let p = proximity(&a, &b);
        assert_abs_diff_eq!(p.signed_distance_m, -0.007, epsilon = 1e-6);
        assert_abs_diff_eq!(p.normal[0], 1.0, epsilon = 1e-5);
        let c = cube([0.13, 0.0, 0.05], 0.05);
        assert_abs_diff_eq!(proximity(&a, &c).signed_distance_m, 0.03, epsilon = 1e-6);
    }

    #[test]
    fn the_sampled_estimate_bounds_the_depth_from_above() {
        let a = cube([0.0, 0.0, 0.05], 0.05);
        let b = cube([0.093, 0.01, 0.05], 0.05);
        let exact = -proximity(&a, &b).signed_distance_m;
        let sampled = -least_overlap(&a, &b, None).signed_distance_m;
        assert!(sampled >= exact - 1e-9, "{sampled} vs {exact}");
        assert_abs_diff_eq!(sampled, 0.007, epsilon = 1e-6);
    }

    #[test]
    fn a_cube_falls_onto_the_one_below_and_not_onto_its_neighbour() {
        let below = cube([0.0, 0.0, 0.05], 0.05);
        let above = cube([0.02, 0.0, 0.2], 0.05);
        assert_abs_diff_eq!(
            fall_distance(&above, &below, 0.002, 1.0).expect("hit"),
            0.05,
            epsilon = 1e-6
        );
        // Resting on it, or sunk 1 mm into it: 0; beside it: never.
        for z in [0.15, 0.149] {
            let resting = cube([0.02, 0.0, z], 0.05);
            assert_abs_diff_eq!(
                fall_distance(&resting, &below, 0.002, 1.0).expect("hit"),
                0.0,
                epsilon = 1e-6
            );
        }
        let beside = cube([0.1, 0.0, 0.06], 0.05);
        assert!(fall_distance(&beside, &below, 0.002, 1.0).is_none());
    }
}
