//! An adaptive convex decomposition whose parts stay within a tolerance of the mesh.
//!
//! V-HACD bounds a part's concavity by volume, relative to the whole asset: on a bowl or a tray
//! a part may bridge several millimetres of the cavity, and a fruit resting in the bowl would
//! then overlap the bowl's parts. `mesa check` needs the opposite guarantee — a part reaches at
//! most a small distance beyond the object — so this decomposition bounds that distance
//! directly:
//!
//! 1. A box (first the mesh's bounds) holds the piece of the object inside it: the triangles
//!    clipped to the box and, for a closed mesh, the box corners inside the solid. The piece's
//!    convex hull is a candidate part.
//! 2. Its **deviation** is how far the hull reaches outside the object: the largest distance
//!    from sample points of the hull's faces to the mesh, for points outside the solid (a
//!    closed, consistently oriented mesh is a solid; any other mesh is a surface, and every
//!    point counts).
//! 3. A candidate deviating more than the tolerance is cut in two across the longest side of
//!    its content, and each half is treated the same way (breadth first, so that a part budget
//!    runs out evenly); otherwise it is a part.
//!
//! The part budget grows with what the shape needs: it starts at
//! [`AdaptiveParams::max_parts`] and doubles, up to [`AdaptiveParams::most_parts`], as long as
//! the last two doublings lowered the largest deviation by at least a quarter
//! ([`BUDGET_GAIN`]; one doubling alone may not: a bowl's first quarters still bridge its
//! cavity). A box or a bowl stops well below the first
//! budget; a detailed asset (an engine of 80 pieces) gets the parts its detail needs; a shape
//! whose deviation no longer falls (noise, a surface thinner than the cuts can follow) stops
//! growing instead of spending parts for nothing. Why a decomposition ends beyond the
//! tolerance is returned ([`OverTolerance`]).
//!
//! Every step is deterministic: the same mesh gives the same parts, unless the time budget
//! ([`AdaptiveParams::deadline`]) runs out: cutting then stops (checked before each cut and
//! between the trial cuts of a piece, never by stopping a thread) and the pieces left are
//! kept as parts, their deviation measured as any part's.

use std::cell::RefCell;
use std::collections::{BinaryHeap, HashMap};
use std::time::Instant;

use parry3d::math::Point;
use parry3d::query::PointQuery;
use parry3d::shape::{TriMesh, TriMeshFlags};
use parry3d::transformation::try_convex_hull;

use super::near::NearTest;
use crate::mesh;

/// The limits of a decomposition.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdaptiveParams {
    /// The most a part may reach outside the object, metres.
    pub tolerance_m: f64,
    /// The first part budget.
    pub max_parts: usize,
    /// The most the part budget may grow to (at least `max_parts`).
    pub most_parts: usize,
    /// Pieces smaller than this along every side are not cut again, metres.
    pub min_size_m: f64,
    /// When cutting stops whatever the deviation (the time budget of one asset).
    pub deadline: Option<Instant>,
}

impl AdaptiveParams {
    /// How far apart [`measured_deviation`] samples a hull face: twice the tolerance.
    fn sample_spacing_m(&self) -> f64 {
        2.0 * self.tolerance_m.max(1e-4)
    }

    fn out_of_time(&self) -> bool {
        self.deadline.is_some_and(|d| Instant::now() >= d)
    }
}

/// The part budget doubles when the worst deviation as it runs out is at most this fraction
/// of the worst deviation when the budget two doublings before ran out (the first two
/// doublings are free).
pub const BUDGET_GAIN: f64 = 0.75;

/// Why a decomposition ended with a part beyond the tolerance.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OverTolerance {
    /// The part budget grew to [`AdaptiveParams::most_parts`] and ran out.
    PartCap,
    /// Two doublings of the part budget had not lowered the worst deviation by a quarter:
    /// more parts would not follow the shape (noise, walls thinner than the cuts).
    NoGain,
    /// The piece beyond the tolerance is smaller than [`AdaptiveParams::min_size_m`] on every
    /// side, or no cut splits it: cutting it again cannot help (a surface with gaps, or
    /// folded on itself).
    MinSize,
    /// The deadline stopped the cutting.
    OutOfTime,
}

impl OverTolerance {
    /// The code recorded in the index (`decomposition.over_tolerance`).
    pub fn code(self) -> &'static str {
        match self {
            Self::PartCap => "part_cap",
            Self::NoGain => "no_gain",
            Self::MinSize => "min_size",
            Self::OutOfTime => "out_of_time",
        }
    }
}

/// One part: its hull's vertices and volume.
#[derive(Debug, Clone, PartialEq)]
pub struct Part {
    /// The hull's vertices, metres.
    pub points_m: Vec<[f64; 3]>,
    /// The hull's volume, cubic metres (0 for a flat piece).
    pub volume_m3: f64,
}

/// The decomposition of a mesh.
#[derive(Debug, Clone, PartialEq)]
pub struct Decomposed {
    /// The parts.
    pub parts: Vec<Part>,
    /// Whether some piece of the mesh was read as a solid (closed and consistently oriented);
    /// the other pieces are surfaces.
    pub solid: bool,
    /// The largest deviation of a part (sampled), metres: at most the tolerance unless the
    /// part budget or the time ran out.
    pub max_deviation_m: f64,
    /// Whether the deadline stopped the cutting while some piece was still beyond the
    /// tolerance.
    pub out_of_time: bool,
    /// The part budget at the end (grown from `max_parts` as the shape needed).
    pub part_budget: usize,
    /// Why the largest deviation exceeds the tolerance, when it does.
    pub over_tolerance: Option<OverTolerance>,
}

/// A mesh welded, split into connected pieces; each closed, consistently oriented piece is a
/// solid, turned outward.
struct Welded {
    positions: Vec<[f64; 3]>,
    triangles: Vec<[u32; 3]>,
    /// The triangles of each solid piece.
    solids: Vec<Vec<u32>>,
}

/// The mesh welded (to 0.1 µm), each closed piece a solid, turned outward; `None` for a
/// position that is not finite or beyond [`mesh::WELD_REACH_M`].
fn weld(positions: &[[f64; 3]], triangles: &[[u32; 3]]) -> Option<Welded> {
    let mesh::Welded {
        positions,
        mut triangles,
    } = mesh::weld(positions, triangles.iter().copied(), 1e7)?;
    let mut solids = Vec::new();
    for piece in mesh::pieces(&triangles) {
        if !piece.closed {
            continue;
        }
        let corners = piece.triangles.iter().map(|&t| triangles[t as usize]);
        if mesh::signed_volume_of(&positions, corners) < 0.0 {
            for &t in &piece.triangles {
                triangles[t as usize].swap(1, 2);
            }
        }
        solids.push(piece.triangles);
    }
    Some(Welded {
        positions,
        triangles,
        solids,
    })
}

/// An axis-aligned box.
#[derive(Debug, Clone, Copy)]
struct Cell {
    min: [f64; 3],
    max: [f64; 3],
}

impl Cell {
    fn corners(&self) -> [[f64; 3]; 8] {
        std::array::from_fn(|i| {
            [
                if i & 1 == 0 { self.min[0] } else { self.max[0] },
                if i & 2 == 0 { self.min[1] } else { self.max[1] },
                if i & 4 == 0 { self.min[2] } else { self.max[2] },
            ]
        })
    }

    fn center(&self) -> [f64; 3] {
        std::array::from_fn(|k| 0.5 * (self.min[k] + self.max[k]))
    }
}

/// The part of a polygon on one side of the plane `x[axis] = bound` (Sutherland–Hodgman).
fn clip_by_plane(
    polygon: &mut Vec<[f64; 3]>,
    axis: usize,
    bound: f64,
    keep_below: bool,
    scratch: &mut Vec<[f64; 3]>,
) {
    if polygon.is_empty() {
        return;
    }
    scratch.clear();
    let inside = |p: &[f64; 3]| {
        if keep_below {
            p[axis] <= bound
        } else {
            p[axis] >= bound
        }
    };
    let n = polygon.len();
    for i in 0..n {
        let p = polygon[i];
        let q = polygon[(i + 1) % n];
        let (ip, iq) = (inside(&p), inside(&q));
        if ip {
            scratch.push(p);
        }
        if ip != iq {
            let t = (bound - p[axis]) / (q[axis] - p[axis]);
            let mut x: [f64; 3] = std::array::from_fn(|k| p[k] + (q[k] - p[k]) * t);
            x[axis] = bound;
            scratch.push(x);
        }
    }
    std::mem::swap(polygon, scratch);
}

/// A closed piece of the mesh, for inside tests.
struct Solid {
    query: TriMesh,
    bounds: Cell,
}

struct Mesh {
    welded: Welded,
    /// Whether every triangle belongs to a solid piece (no loose surface).
    all_solid: bool,
    /// Every triangle, for distances.
    surface: TriMesh,
    solids: Vec<Solid>,
    tri_bounds: Vec<Cell>,
    /// Every triangle again, for the cheap "within a distance" test that rules samples out
    /// before parry3d's exact query ([`NearTest`]).
    near: NearTest,
    /// Whether the mesh is one solid piece (its solid's triangles are the surface's).
    one_solid: bool,
    /// [`Mesh::inside`] of the corners of the boxes seen so far: a cut's two halves share
    /// four corners with the piece, and each trial cut of a piece makes the same halves'
    /// corners again.
    corners_inside: RefCell<HashMap<[u64; 3], bool>>,
}

/// Millimetres per metre: parry3d's queries see millimetres (its tolerances are absolute, about
/// 10⁻⁵ of a unit: too coarse for millimetre walls in metres).
const MM: f64 = 1000.0;

/// A point in metres as parry3d sees it (millimetres, `f32`).
fn to_f32(p: [f64; 3]) -> Point<f32> {
    Point::new((p[0] * MM) as f32, (p[1] * MM) as f32, (p[2] * MM) as f32)
}

/// A point parry3d gave back, in metres.
fn from_f32(p: &Point<f32>) -> [f64; 3] {
    [
        f64::from(p.x) / MM,
        f64::from(p.y) / MM,
        f64::from(p.z) / MM,
    ]
}

impl Mesh {
    /// Whether `p` is strictly inside one of the solid pieces (pieces may overlap: a mug's
    /// handle entering its body); a point on a face is not.
    fn inside(&self, p: [f64; 3]) -> bool {
        let q = to_f32(p);
        self.solids.iter().any(|s| {
            (0..3).all(|k| p[k] > s.bounds.min[k] && p[k] < s.bounds.max[k]) && {
                let proj = s.query.project_local_point(&q, false);
                proj.is_inside && f64::from((proj.point - q).norm()) / MM > INSIDE_MARGIN_M
            }
        })
    }

    /// How far `p` is outside the object (0 inside a solid piece).
    fn deviation(&self, p: [f64; 3]) -> f64 {
        let q = to_f32(p);
        if self.one_solid {
            // The solid is the whole surface: the projection that tells inside from outside
            // gives the distance too (one query instead of two).
            let s = &self.solids[0];
            if (0..3).all(|k| p[k] > s.bounds.min[k] && p[k] < s.bounds.max[k]) {
                let proj = s.query.project_local_point(&q, false);
                let d = f64::from((proj.point - q).norm()) / MM;
                return if proj.is_inside && d > INSIDE_MARGIN_M {
                    0.0
                } else {
                    d
                };
            }
        } else if self.inside(p) {
            return 0.0;
        }
        let proj = self.surface.project_local_point(&q, false);
        f64::from((proj.point - q).norm()) / MM
    }

    /// [`Mesh::inside`] for a box corner, remembered.
    fn corner_inside(&self, p: [f64; 3]) -> bool {
        let key = p.map(f64::to_bits);
        if let Some(&known) = self.corners_inside.borrow().get(&key) {
            return known;
        }
        let inside = self.inside(p);
        self.corners_inside.borrow_mut().insert(key, inside);
        inside
    }

    /// Whether `p` provably deviates no more than `r` (some triangle is within `r` of it, with
    /// the margin of [`NearTest::slack_m`]): [`Mesh::deviation`] would not find more, since a
    /// point's deviation is at most its distance to the surface.
    fn deviates_at_most(&self, p: [f64; 3], r: f64) -> bool {
        self.near.within(p, r - self.near.slack_m())
    }

    fn has_solids(&self) -> bool {
        !self.solids.is_empty()
    }
}

/// The piece of the object inside a box: the surface clipped to the box, and the box corners
/// inside a solid.
#[derive(Clone)]
struct Piece {
    cell: Cell,
    polygons: Vec<Vec<[f64; 3]>>,
}

/// A piece's convex hull.
struct Candidate {
    hull_points: Vec<[f64; 3]>,
    hull_triangles: Vec<[u32; 3]>,
    /// Bounds of the piece's points.
    content: Cell,
}

impl Candidate {
    fn extent(&self) -> [f64; 3] {
        std::array::from_fn(|k| self.content.max[k] - self.content.min[k])
    }

    fn volume(&self) -> f64 {
        hull_volume(&self.hull_points, &self.hull_triangles)
    }
}

fn lexical(a: &[f64; 3], b: &[f64; 3]) -> std::cmp::Ordering {
    a[0].total_cmp(&b[0])
        .then(a[1].total_cmp(&b[1]))
        .then(a[2].total_cmp(&b[2]))
}

/// The hull of a piece; `None` when the piece is empty.
fn candidate(mesh: &Mesh, piece: &Piece) -> Option<Candidate> {
    let mut points: Vec<[f64; 3]> = piece.polygons.iter().flatten().copied().collect();
    let surface_points = points.len();
    if mesh.has_solids() {
        if points.is_empty() && !mesh.inside(piece.cell.center()) {
            // No surface crosses the box and it is outside every solid.
            return None;
        }
        points.extend(
            piece
                .cell
                .corners()
                .into_iter()
                .filter(|c| mesh.corner_inside(*c)),
        );
    }
    if points.is_empty() {
        return None;
    }
    if mesh.all_solid && points.len() == surface_points {
        // Only faces, all on one plane of the box: a solid's face whose material lies in the
        // next box, not a part of its own.
        let flat = (0..3).any(|k| {
            let lo = points.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min);
            let hi = points
                .iter()
                .map(|p| p[k])
                .fold(f64::NEG_INFINITY, f64::max);
            hi - lo <= PLANAR_EPS_M
                && ((lo - piece.cell.min[k]).abs() <= PLANAR_EPS_M
                    || (hi - piece.cell.max[k]).abs() <= PLANAR_EPS_M)
        });
        if flat {
            return None;
        }
    }
    let mut content = Cell {
        min: [f64::INFINITY; 3],
        max: [f64::NEG_INFINITY; 3],
    };
    for p in &points {
        for (k, v) in p.iter().enumerate() {
            content.min[k] = content.min[k].min(*v);
            content.max[k] = content.max[k].max(*v);
        }
    }
    let as_f32: Vec<Point<f32>> = points.iter().map(|p| to_f32(*p)).collect();
    // parry3d's hull can panic on degenerate input: a flat piece is kept as its points.
    let hull = std::panic::catch_unwind(|| try_convex_hull(&as_f32))
        .ok()
        .and_then(Result::ok)
        .filter(|(_, t)| !t.is_empty());
    let (hull_points, hull_triangles) = match hull {
        Some((p, t)) => (p.iter().map(from_f32).collect(), t),
        None => {
            points.sort_by(lexical);
            points.dedup();
            if collinear(&points) {
                // A point or a segment: the piece holds only faces cut down to an edge (a face
                // lying on a cut), no area and no volume. As a part it would touch nothing
                // and take a place of the part budget (the demo pen had 107 such copies of
                // its clip's edge among its 128 parts).
                return None;
            }
            (points, Vec::new())
        }
    };
    Some(Candidate {
        hull_points,
        hull_triangles,
        content,
    })
}

/// A point this close to a face is on it, not inside, metres (f32 is 0.1 µm at a metre).
const INSIDE_MARGIN_M: f64 = 1e-6;

/// Coordinates closer than this are the same plane, metres.
const PLANAR_EPS_M: f64 = 1e-7;

/// Whether `points` lie on one line (within [`PLANAR_EPS_M`]): they span no area.
pub(crate) fn collinear(points: &[[f64; 3]]) -> bool {
    let Some(&a) = points.first() else {
        return true;
    };
    let dist = |p: &[f64; 3], q: &[f64; 3]| (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f64>();
    let Some(b) = points
        .iter()
        .max_by(|p, q| dist(p, &a).total_cmp(&dist(q, &a)))
    else {
        return true;
    };
    let ab = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let length = dist(b, &a).sqrt();
    if length <= PLANAR_EPS_M {
        return true;
    }
    points.iter().all(|p| {
        let ap = [p[0] - a[0], p[1] - a[1], p[2] - a[2]];
        let cross = [
            ab[1] * ap[2] - ab[2] * ap[1],
            ab[2] * ap[0] - ab[0] * ap[2],
            ab[0] * ap[1] - ab[1] * ap[0],
        ];
        (cross.iter().map(|c| c * c).sum::<f64>()).sqrt() / length <= PLANAR_EPS_M
    })
}

/// The (unnormalised) normal of a polygon, by its winding (Newell's method).
fn polygon_normal(polygon: &[[f64; 3]]) -> [f64; 3] {
    let mut n = [0.0; 3];
    for i in 0..polygon.len() {
        let (p, q) = (polygon[i], polygon[(i + 1) % polygon.len()]);
        n[0] += (p[1] - q[1]) * (p[2] + q[2]);
        n[1] += (p[2] - q[2]) * (p[0] + q[0]);
        n[2] += (p[0] - q[0]) * (p[1] + q[1]);
    }
    n
}

impl Piece {
    /// The area of its surface, square metres.
    fn area(&self) -> f64 {
        self.polygons
            .iter()
            .map(|p| {
                let n = polygon_normal(p);
                0.5 * (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt()
            })
            .sum()
    }
}

/// The piece split by the plane `x[axis] = cut`: the part below, the part above. A face lying
/// on the cut goes below when `on_plane_below` says so; without it, to the side its solid is
/// on (behind its outward normal).
fn split_piece(
    piece: &Piece,
    axis: usize,
    cut: f64,
    on_plane_below: Option<bool>,
) -> (Piece, Piece) {
    let mut low = Piece {
        cell: piece.cell,
        polygons: Vec::new(),
    };
    low.cell.max[axis] = cut;
    let mut high = Piece {
        cell: piece.cell,
        polygons: Vec::new(),
    };
    high.cell.min[axis] = cut;
    let mut scratch = Vec::with_capacity(9);
    for polygon in &piece.polygons {
        let lo = polygon
            .iter()
            .map(|p| p[axis])
            .fold(f64::INFINITY, f64::min);
        let hi = polygon
            .iter()
            .map(|p| p[axis])
            .fold(f64::NEG_INFINITY, f64::max);
        if hi - lo <= PLANAR_EPS_M && (lo - cut).abs() <= PLANAR_EPS_M {
            let below = on_plane_below.unwrap_or_else(|| polygon_normal(polygon)[axis] >= 0.0);
            if below {
                low.polygons.push(polygon.clone());
            } else {
                high.polygons.push(polygon.clone());
            }
        } else if hi <= cut {
            low.polygons.push(polygon.clone());
        } else if lo >= cut {
            high.polygons.push(polygon.clone());
        } else {
            for (side, keep_below) in [(&mut low, true), (&mut high, false)] {
                let mut clipped = polygon.clone();
                clip_by_plane(&mut clipped, axis, cut, keep_below, &mut scratch);
                let n = polygon_normal(&clipped);
                if clipped.len() >= 3 && n.iter().map(|v| v * v).sum::<f64>() > 1e-24 {
                    side.polygons.push(clipped);
                }
            }
        }
    }
    (low, high)
}

/// Whether a candidate's faces, sampled at seven points each, stay within `tolerance` of the
/// object. Samples that [`Mesh::deviates_at_most`] the tolerance are not measured.
fn within_tolerance(mesh: &Mesh, c: &Candidate, tolerance: f64) -> bool {
    // Points of each face at barycentric thirds (the vertices lie on the object).
    const SAMPLES: [[f64; 3]; 7] = [
        [1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0],
        [2.0 / 3.0, 1.0 / 3.0, 0.0],
        [2.0 / 3.0, 0.0, 1.0 / 3.0],
        [1.0 / 3.0, 2.0 / 3.0, 0.0],
        [0.0, 2.0 / 3.0, 1.0 / 3.0],
        [1.0 / 3.0, 0.0, 2.0 / 3.0],
        [0.0, 1.0 / 3.0, 2.0 / 3.0],
    ];
    for t in &c.hull_triangles {
        let [a, b, d] = t.map(|i| c.hull_points[i as usize]);
        for w in SAMPLES {
            let p = std::array::from_fn(|k| w[0] * a[k] + w[1] * b[k] + w[2] * d[k]);
            if !mesh.deviates_at_most(p, tolerance) && mesh.deviation(p) > tolerance {
                return false;
            }
        }
    }
    true
}

/// Faces are cut into at most this many steps along each side by [`measured_deviation`].
const MOST_STEPS: usize = 6;

/// The deviation of a candidate as the decomposition reports it: the largest distance outside
/// the object of points on a grid over each hull face, about `spacing_m` apart (at most
/// [`MOST_STEPS`] steps along a side), vertices included. The seven fixed points of
/// [`within_tolerance`] choose the cuts (cheap, many trials); this denser measure decides whether a
/// piece is kept, so what the index claims is what the faces were measured to reach: the
/// faces that bridge a hollow (an apple's dimple, a kettle's spout) are sampled where the
/// hollow is deepest, not only at their thirds.
///
/// Samples that cannot raise the worst distance found so far ([`Mesh::deviates_at_most`]) are
/// not measured: the figure is the same, for a fraction of the queries.
fn measured_deviation(mesh: &Mesh, c: &Candidate, spacing_m: f64) -> f64 {
    let mut worst: f64 = 0.0;
    let length = |p: [f64; 3], q: [f64; 3]| {
        ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
    };
    for t in &c.hull_triangles {
        let [a, b, d] = t.map(|i| c.hull_points[i as usize]);
        let longest = length(a, b).max(length(b, d)).max(length(d, a));
        let steps = ((longest / spacing_m).ceil() as usize).clamp(3, MOST_STEPS);
        for i in 0..=steps {
            for j in 0..=steps - i {
                let k = steps - i - j;
                let w = [i, j, k].map(|n| n as f64 / steps as f64);
                let p = std::array::from_fn(|m| w[0] * a[m] + w[1] * b[m] + w[2] * d[m]);
                // A sample that provably cannot raise the worst so far is not measured.
                if worst > 0.0 && mesh.deviates_at_most(p, worst) {
                    continue;
                }
                worst = worst.max(mesh.deviation(p));
            }
        }
    }
    worst
}

/// The volume of a closed hull, cubic metres.
fn hull_volume(points: &[[f64; 3]], triangles: &[[u32; 3]]) -> f64 {
    mesh::signed_volume_of(points, triangles.iter().copied()).abs()
}

/// Decomposes a triangle mesh (metres) into convex parts within `params.tolerance_m` of it;
/// `None` when the mesh has no triangle, or a position is not finite or beyond
/// [`mesh::WELD_REACH_M`].
pub fn decompose(
    positions: &[[f64; 3]],
    triangles: &[[u32; 3]],
    params: &AdaptiveParams,
) -> Option<Decomposed> {
    let welded = weld(positions, triangles)?;
    if welded.triangles.is_empty() {
        return None;
    }
    let vertices: Vec<Point<f32>> = welded.positions.iter().map(|p| to_f32(*p)).collect();
    let surface = TriMesh::new(vertices.clone(), welded.triangles.clone()).ok()?;
    let bounds_of = |tris: &mut dyn Iterator<Item = u32>| {
        let mut cell = Cell {
            min: [f64::INFINITY; 3],
            max: [f64::NEG_INFINITY; 3],
        };
        for t in tris {
            for &i in &welded.triangles[t as usize] {
                let p = welded.positions[i as usize];
                for (k, v) in p.iter().enumerate() {
                    cell.min[k] = cell.min[k].min(*v);
                    cell.max[k] = cell.max[k].max(*v);
                }
            }
        }
        cell
    };
    let tri_bounds: Vec<Cell> = (0..welded.triangles.len() as u32)
        .map(|t| bounds_of(&mut std::iter::once(t)))
        .collect();
    let mut solids = Vec::new();
    for piece in &welded.solids {
        // The piece's own vertices, renumbered.
        let mut local: HashMap<u32, u32> = HashMap::new();
        let mut piece_vertices = Vec::new();
        let tris: Vec<[u32; 3]> = piece
            .iter()
            .map(|&t| {
                welded.triangles[t as usize].map(|i| {
                    *local.entry(i).or_insert_with(|| {
                        piece_vertices.push(vertices[i as usize]);
                        (piece_vertices.len() - 1) as u32
                    })
                })
            })
            .collect();
        // A piece parry3d cannot orient is read as a surface.
        if let Ok(query) = TriMesh::with_flags(piece_vertices, tris, TriMeshFlags::ORIENTED) {
            if query.pseudo_normals_if_oriented().is_some() {
                solids.push(Solid {
                    query,
                    bounds: bounds_of(&mut piece.iter().copied()),
                });
            }
        }
    }
    let solid_triangles: usize = welded.solids.iter().map(Vec::len).sum();
    let all_solid =
        solids.len() == welded.solids.len() && solid_triangles == welded.triangles.len();
    let near = NearTest::new(&welded.positions, &welded.triangles);
    let mesh = Mesh {
        near,
        one_solid: all_solid && solids.len() == 1,
        corners_inside: RefCell::new(HashMap::new()),
        welded,
        all_solid,
        surface,
        solids,
        tri_bounds,
    };
    let mut root = Cell {
        min: [f64::INFINITY; 3],
        max: [f64::NEG_INFINITY; 3],
    };
    for b in &mesh.tri_bounds {
        for k in 0..3 {
            root.min[k] = root.min[k].min(b.min[k]);
            root.max[k] = root.max[k].max(b.max[k]);
        }
    }
    // A hair larger, so that no face lies on the box's boundary.
    let pad = 1e-6;
    for k in 0..3 {
        root.min[k] -= pad;
        root.max[k] += pad;
    }
    let root = Piece {
        cell: root,
        polygons: mesh
            .welded
            .triangles
            .iter()
            .map(|t| {
                t.iter()
                    .map(|&i| mesh.welded.positions[i as usize])
                    .collect()
            })
            .collect(),
    };
    let mut pending: BinaryHeap<Pending> = BinaryHeap::new();
    let mut sequence = 0u64;
    if let Some(root) = Pending::new(&mesh, root, params.sample_spacing_m(), &mut sequence) {
        pending.push(root);
    }
    let mut parts = Vec::new();
    let mut max_deviation: f64 = 0.0;
    let mut out_of_time = false;
    let mut budget = params.max_parts.max(1);
    let most_parts = params.most_parts.max(budget);
    // The worst deviation each time a budget ran out, and whether the budget may still grow.
    let mut worst_at_budgets: Vec<f64> = Vec::new();
    let mut growing = true;
    // Why the worst part kept beyond the tolerance was kept, with its deviation.
    let mut over_tolerance: Option<(f64, OverTolerance)> = None;
    // The worst piece first, so that a part budget goes where the deviation is.
    while let Some(worst) = pending.pop() {
        let beyond = worst.deviation > params.tolerance_m;
        let mut room = parts.len() + pending.len() + 2 <= budget;
        if beyond && !room && growing {
            // A single doubling may not lower the worst deviation (a bowl's first quarters
            // still bridge its cavity): the gain is judged over two.
            let paid_off = worst_at_budgets
                .len()
                .checked_sub(2)
                .is_none_or(|i| worst.deviation <= BUDGET_GAIN * worst_at_budgets[i]);
            worst_at_budgets.push(worst.deviation);
            if budget < most_parts && paid_off {
                budget = (budget * 2).min(most_parts);
                room = parts.len() + pending.len() + 2 <= budget;
            } else {
                // Pieces popped later deviate less: the budget is settled here.
                growing = false;
            }
        }
        let large = worst
            .candidate
            .extent()
            .iter()
            .any(|e| *e > params.min_size_m);
        if beyond && room && large {
            if out_of_time || params.out_of_time() {
                out_of_time = true;
            } else {
                let halves = split(&mesh, &worst, params, &mut sequence);
                if !halves.is_empty() {
                    pending.extend(halves);
                    continue;
                }
            }
        }
        if beyond {
            let why = if out_of_time {
                OverTolerance::OutOfTime
            } else if !room && budget >= most_parts {
                OverTolerance::PartCap
            } else if !room {
                OverTolerance::NoGain
            } else {
                // Too small to cut, or no cut gave two pieces.
                OverTolerance::MinSize
            };
            if over_tolerance.is_none_or(|(d, _)| worst.deviation > d) {
                over_tolerance = Some((worst.deviation, why));
            }
        }
        max_deviation = max_deviation.max(worst.deviation);
        let volume_m3 = worst.candidate.volume();
        parts.push(Part {
            points_m: worst.candidate.hull_points,
            volume_m3,
        });
    }
    Some(Decomposed {
        parts,
        solid: mesh.has_solids(),
        max_deviation_m: max_deviation,
        out_of_time,
        part_budget: budget,
        over_tolerance: over_tolerance.map(|(_, why)| why),
    })
}

/// A piece waiting to be cut or kept.
struct Pending {
    piece: Piece,
    candidate: Candidate,
    deviation: f64,
    /// Creation order: ties go to the older piece (determinism).
    sequence: u64,
}

impl Pending {
    /// A piece and its candidate part, whose deviation is measured densely (samples about
    /// `spacing_m` apart on each face, [`measured_deviation`]).
    fn new(mesh: &Mesh, piece: Piece, spacing_m: f64, sequence: &mut u64) -> Option<Self> {
        let candidate = candidate(mesh, &piece)?;
        let deviation = measured_deviation(mesh, &candidate, spacing_m);
        *sequence += 1;
        Some(Self {
            piece,
            candidate,
            deviation,
            sequence: *sequence,
        })
    }
}

impl PartialEq for Pending {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == std::cmp::Ordering::Equal
    }
}

impl Eq for Pending {}

impl PartialOrd for Pending {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Pending {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.deviation
            .total_cmp(&other.deviation)
            .then(other.sequence.cmp(&self.sequence))
    }
}

/// Where a piece may be cut along an axis: at the middle of its content and at the
/// coordinates of its surface's vertices (where a boxy object's faces are), a few of them.
fn cut_positions(piece: &Pending, axis: usize, surface_edges: bool, margin: f64) -> Vec<f64> {
    let (lo, hi) = (
        piece.candidate.content.min[axis],
        piece.candidate.content.max[axis],
    );
    // A cut at the content's edge peels a face lying there, for a mesh with loose surfaces
    // (an open box's wall); a solid's faces there go with the solid.
    let mut coords: Vec<f64> = piece
        .piece
        .polygons
        .iter()
        .flatten()
        .map(|p| p[axis])
        .filter(|c| {
            if surface_edges {
                *c >= lo && *c <= hi
            } else {
                *c > lo + margin && *c < hi - margin
            }
        })
        .collect();
    coords.sort_by(f64::total_cmp);
    coords.dedup_by(|a, b| (*a - *b).abs() <= 1e-5);
    const MOST: usize = 6;
    let mut out = vec![0.5 * (lo + hi)];
    if coords.len() <= MOST {
        out.extend(coords);
    }
    out
}

/// Where faces lying on a cut go: a solid's to its solid's side; with loose surfaces, to the
/// nearer edge of the piece (a cut at an open box's wall peels the wall off).
fn on_plane(mesh: &Mesh, piece: &Pending, axis: usize, cut: f64) -> Option<bool> {
    let content = &piece.candidate.content;
    (!mesh.all_solid).then(|| cut - content.min[axis] <= content.max[axis] - cut)
}

/// Cuts a piece in two. The cut that peels off the largest piece already within the
/// tolerance wins (a tray's base, then each of its rims); when no cut does, the middle of the
/// longest side (a bowl's curved wall, halved until its pieces are flat enough).
fn split(
    mesh: &Mesh,
    piece: &Pending,
    params: &AdaptiveParams,
    sequence: &mut u64,
) -> Vec<Pending> {
    let mut best: Option<(f64, usize, f64)> = None;
    for axis in 0..3 {
        if params.out_of_time() {
            // The best cut so far, or the middle one below.
            break;
        }
        for cut in cut_positions(piece, axis, !mesh.all_solid, params.min_size_m.max(1e-6)) {
            let (low, high) =
                split_piece(&piece.piece, axis, cut, on_plane(mesh, piece, axis, cut));
            let (Some(cl), Some(ch)) = (candidate(mesh, &low), candidate(mesh, &high)) else {
                continue;
            };
            let mut peeled = 0.0;
            for (half, c) in [(&low, &cl), (&high, &ch)] {
                if within_tolerance(mesh, c, params.tolerance_m) {
                    // A flat piece (a surface's face) has no volume: its area, a micrometre
                    // thick, still counts.
                    peeled += c.volume() + 1e-6 * half.area();
                }
            }
            if peeled > 0.0 && best.is_none_or(|(v, _, _)| peeled > v) {
                best = Some((peeled, axis, cut));
            }
        }
    }
    let (axis, cut) = match best {
        Some((_, axis, cut)) => (axis, cut),
        None => {
            let extent = piece.candidate.extent();
            let axis = (0..3)
                .max_by(|a, b| extent[*a].total_cmp(&extent[*b]).then(b.cmp(a)))
                .unwrap_or(0);
            let content = &piece.candidate.content;
            (axis, 0.5 * (content.min[axis] + content.max[axis]))
        }
    };
    let (low, high) = split_piece(&piece.piece, axis, cut, on_plane(mesh, piece, axis, cut));
    [low, high]
        .into_iter()
        .filter_map(|half| Pending::new(mesh, half, params.sample_spacing_m(), sequence))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::assets::synthetic::Mesh as Synthetic;

    fn params() -> AdaptiveParams {
        AdaptiveParams {
            tolerance_m: 0.001,
            max_parts: 256,
            most_parts: 256,
            min_size_m: 0.002,
            deadline: None,
        }
    }

    #[test]
    fn a_box_is_one_part() {
        let cube = Synthetic::cuboid([0.1, 0.05, 0.2]);
        let d = decompose(&cube.positions, &cube.triangles, &params()).expect("parts");
        assert!(d.solid);
        assert_eq!(d.parts.len(), 1);
        assert!((d.parts[0].volume_m3 - 0.001).abs() < 1e-9);
    }

    #[test]
    fn a_bowls_parts_stay_within_the_tolerance_of_its_wall() {
        let bowl = Synthetic::vessel(0.08, 0.06, 0.006, 0.008);
        let d = decompose(&bowl.positions, &bowl.triangles, &params()).expect("parts");
        assert!(d.solid);
        assert!(d.parts.len() > 1);
        assert!(d.max_deviation_m <= 0.001, "{}", d.max_deviation_m);
    }

    #[test]
    fn an_open_surface_is_decomposed_as_a_surface() {
        // A box without its top: not closed, so not a solid; its parts follow its faces.
        let mut open = Synthetic::cuboid([0.1, 0.1, 0.1]);
        open.triangles
            .retain(|t| t.iter().any(|&i| open.positions[i as usize][1] < 0.05));
        let d = decompose(&open.positions, &open.triangles, &params()).expect("parts");
        assert!(!d.solid);
        assert!(d.parts.len() > 1);
        assert!(d.max_deviation_m <= 0.001, "{}", d.max_deviation_m);
    }

    #[test]
    fn the_part_budget_grows_with_what_the_shape_needs() {
        let bowl = Synthetic::vessel(0.08, 0.06, 0.006, 0.008);
        let small = AdaptiveParams {
            max_parts: 4,
            most_parts: 4,
            ..params()
        };
        // Control: a budget that cannot grow leaves the bowl's parts bridging its cavity.
        let capped = decompose(&bowl.positions, &bowl.triangles, &small).expect("parts");
        assert!(capped.parts.len() <= 4);
        assert!(capped.max_deviation_m > 0.001, "{}", capped.max_deviation_m);
        assert_eq!(capped.over_tolerance, Some(OverTolerance::PartCap));
        assert_eq!(capped.part_budget, 4);
        // The same first budget, free to grow: as many parts as the bowl needs, no more.
        let grown = decompose(
            &bowl.positions,
            &bowl.triangles,
            &AdaptiveParams {
                most_parts: 1024,
                ..small
            },
        )
        .expect("parts");
        assert!(grown.max_deviation_m <= 0.001, "{}", grown.max_deviation_m);
        assert_eq!(grown.over_tolerance, None);
        assert!(grown.parts.len() > 4);
        assert!(grown.part_budget > 4 && grown.part_budget < 1024);
        assert!(grown.parts.len() <= grown.part_budget);
        // A box needs one part whatever the budget may grow to.
        let cube = Synthetic::cuboid([0.1, 0.05, 0.2]);
        let one = decompose(&cube.positions, &cube.triangles, &small).expect("parts");
        assert_eq!((one.parts.len(), one.part_budget), (1, 4));
    }
}
