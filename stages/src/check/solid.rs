//! An object's own triangle mesh placed by its layout: what `check` judges on where the convex
//! parts are not faithful enough.
//!
//! Convex parts reach outside the mesh they cover by up to the reach `mesa assets` measured,
//! and a layout's scale multiplies it (a pencil part 0.5 mm outside its mesh is 10 mm outside
//! at ×21). An object whose parts may reach past its mesh by more than half the penetration
//! tolerance at its layout's scale is *loose* ([`super::Body::loose`]): its collisions, falls and
//! table contact are measured here, on the meshes, as the exact-mesh reference of the tests
//! does (`scripts/mesh_reference.py`):
//! - **depth**: the largest distance to the other mesh's surface of a point of one object
//!   (its vertices and area-uniform surface samples) inside the other — a lower bound of the
//!   penetration depth, exact at the deepest point sampled. A collision found on parts between
//!   any two objects takes at least this depth: several convex parts meeting inside a solid
//!   each overlap a piercing object less than the solid does.
//! - **inside**: signed crossings of a ray along each axis (the winding number of a closed
//!   mesh; several overlapping closed pieces count once), the majority of the three axes, so a
//!   crack in the surface misleads at most one of them.
//! - **fall**: the shortest vertical ray from the object's points down to the other mesh or
//!   from the other's points up to it (0 when a point of one lies inside the other).
//!
//! Hand-written because parry3d's `TriMesh` tells inside from outside by pseudo-normals, which
//! need one closed manifold surface (asset meshes are often several overlapping pieces), and
//! has no vertical-ray walk over the triangles that answers "every hit below this point".

use super::geometry::{Bounds, Placement};
use crate::assets::reach::closest_point_triangle;
use crate::mesh::{add3, cross3, dot3, norm3, scale3, sub3};
use crate::tri_tree::{self, Node, Stack};

/// Surface samples taken on a mesh besides its vertices (area-uniform, deterministic).
pub const SURFACE_SAMPLES: usize = 4000;

/// An asset's triangle mesh in the frame of its collision parts (table-aligned, metres,
/// relative to the centre of its bounding box), with the points the queries use.
///
/// The bounding-volume tree over the triangles is built once, here, in the asset's frame;
/// placing the mesh keeps its shape and refits its boxes to the placed triangles (an affine
/// map keeps every triangle in its leaf; only the boxes change), so a layout's placement costs
/// a pass over the vertices and nodes, not a sort.
#[derive(Debug, Clone, PartialEq)]
pub struct AssetMesh {
    positions_m: Vec<[f64; 3]>,
    /// In the tree's order: a leaf's triangles are consecutive.
    triangles: Vec<[u32; 3]>,
    /// The vertices, then [`SURFACE_SAMPLES`] area-uniform samples of the surface.
    points_m: Vec<[f64; 3]>,
    /// The tree over `triangles`, boxes in the asset's frame.
    nodes: Vec<Node>,
}

impl AssetMesh {
    /// A mesh of `positions_m` (the parts' frame) and `triangles` (indices into it; triangles
    /// naming a missing vertex are left out).
    pub fn new(positions_m: Vec<[f64; 3]>, triangles: Vec<[u32; 3]>) -> Self {
        let n = positions_m.len() as u32;
        let triangles: Vec<[u32; 3]> = triangles
            .into_iter()
            .filter(|t| t.iter().all(|&i| i < n))
            .collect();
        let mut points_m = positions_m.clone();
        points_m.extend(surface_samples(&positions_m, &triangles, SURFACE_SAMPLES));
        let corners: Vec<[[f64; 3]; 3]> = triangles
            .iter()
            .map(|t| t.map(|i| positions_m[i as usize]))
            .collect();
        let (nodes, order) = tri_tree::build(&corners);
        Self {
            triangles: order.iter().map(|&i| triangles[i as usize]).collect(),
            positions_m,
            points_m,
            nodes,
        }
    }

    /// The number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// The mesh scaled by `scale` along the asset's axes, turned by `rotation_xyzw`, moved to
    /// `position_m` (as a layout places the parts: [`super::shapes::Pose`]).
    pub fn place(&self, position_m: [f64; 3], rotation_xyzw: [f64; 4], scale: [f64; 3]) -> Solid {
        let placement = Placement::new(position_m, rotation_xyzw, scale);
        let map = |p: &[f64; 3]| placement.apply(*p);
        let positions: Vec<[f64; 3]> = self.positions_m.iter().map(map).collect();
        let corners: Vec<[[f64; 3]; 3]> = self
            .triangles
            .iter()
            .map(|tri| tri.map(|i| positions[i as usize]))
            .collect();
        let points: Vec<[f64; 3]> = self.points_m.iter().map(map).collect();
        let mut nodes = self.nodes.clone();
        tri_tree::refit(&mut nodes, &corners);
        let bounds = nodes.first().map_or(Bounds::empty(), |root| Bounds {
            min: root.min,
            max: root.max,
        });
        Solid {
            nodes,
            triangles: corners,
            points,
            bounds,
        }
    }
}

/// Area-uniform points on the triangles: the k-th of `count` at the k-th step of the cumulative
/// area, at a point of the R2 low-discrepancy sequence within its triangle.
fn surface_samples(positions: &[[f64; 3]], triangles: &[[u32; 3]], count: usize) -> Vec<[f64; 3]> {
    let areas: Vec<f64> = triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| positions[i as usize]);
            0.5 * norm3(cross3(sub3(b, a), sub3(c, a)))
        })
        .collect();
    let total: f64 = areas.iter().sum();
    if total.is_nan() || total <= 0.0 || !total.is_finite() {
        return Vec::new();
    }
    const A1: f64 = 0.754_877_666_246_692_7;
    const A2: f64 = 0.569_840_290_998_053_2;
    let mut out = Vec::with_capacity(count);
    let (mut tri, mut below) = (0usize, 0.0f64);
    for k in 0..count {
        let target = (k as f64 + 0.5) / count as f64 * total;
        while tri + 1 < areas.len() && below + areas[tri] < target {
            below += areas[tri];
            tri += 1;
        }
        let (mut r1, mut r2) = ((0.5 + k as f64 * A1).fract(), (0.5 + k as f64 * A2).fract());
        if r1 + r2 > 1.0 {
            (r1, r2) = (1.0 - r1, 1.0 - r2);
        }
        let [a, b, c] = triangles[tri].map(|i| positions[i as usize]);
        out.push(std::array::from_fn(|d| {
            a[d] + r1 * (b[d] - a[d]) + r2 * (c[d] - a[d])
        }));
    }
    out
}

/// A placed mesh: its triangles in a bounding-volume tree, its points, its box (table frame,
/// metres).
#[derive(Debug, Clone)]
pub struct Solid {
    nodes: Vec<Node>,
    triangles: Vec<[[f64; 3]; 3]>,
    points: Vec<[f64; 3]>,
    bounds: Bounds,
}

impl Solid {
    /// The mesh's box (empty without triangles).
    pub fn bounds(&self) -> Bounds {
        self.bounds
    }

    /// Visits the triangles whose boxes meet `bounds`.
    fn in_box(&self, bounds: &Bounds, mut visit: impl FnMut(&[[f64; 3]; 3])) {
        if self.nodes.is_empty() {
            return;
        }
        let mut stack = Stack::new();
        while let Some(n) = stack.pop() {
            let node = &self.nodes[n as usize];
            if (0..3).any(|k| node.max[k] < bounds.min[k] || node.min[k] > bounds.max[k]) {
                continue;
            }
            if node.count > 0 {
                let range = node.triangles();
                self.triangles[range].iter().for_each(&mut visit);
            } else {
                stack.push(node.first);
                stack.push(n + 1);
            }
        }
    }

    /// Visits the triangles whose boxes meet the line through `p` along `axis`.
    fn on_line(&self, axis: usize, p: [f64; 3], mut visit: impl FnMut(&[[f64; 3]; 3])) {
        if self.nodes.is_empty() {
            return;
        }
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        let mut stack = Stack::new();
        while let Some(n) = stack.pop() {
            let node = &self.nodes[n as usize];
            if p[u] < node.min[u] || p[u] > node.max[u] || p[v] < node.min[v] || p[v] > node.max[v]
            {
                continue;
            }
            if node.count > 0 {
                let range = node.triangles();
                self.triangles[range].iter().for_each(&mut visit);
            } else {
                stack.push(node.first);
                stack.push(n + 1);
            }
        }
    }

    /// The winding number of `p` counted on the ray from it along `+axis`: the signed
    /// crossings of the surface (outward normals pointing along the ray count +1).
    fn crossings(&self, axis: usize, p: [f64; 3]) -> i32 {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        let mut sum = 0;
        self.on_line(axis, p, |t| {
            if let Some((sign, at)) = cover(t, u, v, axis, p, true) {
                if at > p[axis] {
                    sum += sign;
                }
            }
        });
        sum
    }

    /// Whether `p` lies inside the mesh (two of the three axis rays say so).
    pub fn contains(&self, p: [f64; 3]) -> bool {
        if !self.bounds.overlaps(&Bounds { min: p, max: p }, 0.0) {
            return false;
        }
        let votes = (0..3).filter(|&axis| self.crossings(axis, p) != 0).count();
        votes >= 2
    }

    /// The distance from `p` to the nearest triangle.
    pub fn distance(&self, p: [f64; 3]) -> f64 {
        self.nearest(p).0
    }

    /// The distance from `p` to the nearest triangle, and the nearest point (`p` itself with
    /// an infinite distance for a mesh without triangles).
    pub fn nearest(&self, p: [f64; 3]) -> (f64, [f64; 3]) {
        if self.nodes.is_empty() {
            return (f64::INFINITY, p);
        }
        let mut best2 = f64::INFINITY;
        let mut best = p;
        let mut stack = Stack::new();
        while let Some(n) = stack.pop() {
            let node = &self.nodes[n as usize];
            if node.distance2(p) >= best2 {
                continue;
            }
            if node.count > 0 {
                let range = node.triangles();
                for t in &self.triangles[range] {
                    let q = closest_point_triangle(p, t[0], t[1], t[2]);
                    let d = sub3(p, q);
                    let d2 = dot3(d, d);
                    if d2 < best2 {
                        best2 = d2;
                        best = q;
                    }
                }
            } else {
                stack.push_children_nearer_first(&self.nodes, n, p);
            }
        }
        (best2.sqrt(), best)
    }

    /// What the vertical line through `p` meets: whether `p` is inside (the signed crossings
    /// above it; only with `need_inside`, else `false`), how far below it the nearest surface
    /// point under it is, and how far above it the nearest over it (a surface within a
    /// nanometre of `p` counts as 0 either way).
    ///
    /// Only gaps shorter than `below_limit` (under `p`) and `above_limit` (over it) are sought:
    /// a node of the tree wholly under `p` is skipped when its top is `below_limit` or more
    /// under it, one wholly over `p` when its bottom is `above_limit` or more over it and the
    /// crossings are not needed. What is found under a limit is exact.
    fn column(&self, p: [f64; 3], need_inside: bool, below_limit: f64, above_limit: f64) -> Column {
        let mut column = Column {
            inside: false,
            below: None,
            above: None,
        };
        if self.nodes.is_empty() {
            return column;
        }
        let mut crossings = 0;
        let mut stack = Stack::new();
        while let Some(n) = stack.pop() {
            let node = &self.nodes[n as usize];
            if p[0] < node.min[0] || p[0] > node.max[0] || p[1] < node.min[1] || p[1] > node.max[1]
            {
                continue;
            }
            if node.max[2] < p[2] && p[2] - node.max[2] >= below_limit {
                continue;
            }
            if node.min[2] > p[2] && !need_inside && node.min[2] - p[2] >= above_limit {
                continue;
            }
            if node.count == 0 {
                stack.push(node.first);
                stack.push(n + 1);
                continue;
            }
            let range = node.triangles();
            for t in &self.triangles[range] {
                let Some((sign, z)) = cover(t, 0, 1, 2, p, true) else {
                    continue;
                };
                if z > p[2] {
                    crossings += sign;
                }
                let (down, up) = (p[2] - z, z - p[2]);
                if down >= -1e-9 {
                    let d = down.max(0.0);
                    column.below = Some(column.below.map_or(d, |b: f64| b.min(d)));
                }
                if up >= -1e-9 {
                    let d = up.max(0.0);
                    column.above = Some(column.above.map_or(d, |b: f64| b.min(d)));
                }
            }
        }
        column.inside = need_inside && crossings != 0;
        column
    }
}

/// What a vertical line through a point meets ([`Solid::column`]).
struct Column {
    inside: bool,
    below: Option<f64>,
    above: Option<f64>,
}

/// A placed mesh moved by `offset` (a settled object moves without its mesh being rebuilt).
#[derive(Debug, Clone, Copy)]
pub struct SolidAt<'a> {
    /// The mesh as placed by the layout.
    pub solid: &'a Solid,
    /// How far it has moved since, metres.
    pub offset: [f64; 3],
}

impl SolidAt<'_> {
    /// The box, moved.
    pub fn bounds(&self) -> Bounds {
        self.solid.bounds.translated(self.offset)
    }

    fn local(&self, p: [f64; 3]) -> [f64; 3] {
        sub3(p, self.offset)
    }

    fn points(&self) -> impl Iterator<Item = [f64; 3]> + '_ {
        self.solid.points.iter().map(|p| add3(*p, self.offset))
    }

    /// Whether `p` (table frame) lies inside.
    pub fn contains(&self, p: [f64; 3]) -> bool {
        self.solid.contains(self.local(p))
    }
}

/// The depth is found to within this, metres.
pub const DEPTH_RESOLUTION_M: f64 = 0.000_5;

/// Pieces of triangle measured in one [`deepest`] search, at most (the resolution is then
/// coarser than [`DEPTH_RESOLUTION_M`]: the result stays a lower bound of the depth).
const MOST_PIECES: usize = 200_000;

/// The largest distance to `b`'s surface of a point of `a`'s surface inside `b`, metres (0 when
/// none is), to within [`DEPTH_RESOLUTION_M`] where it exceeds `floor_m`, and at most `floor_m`
/// otherwise (a caller judging against a tolerance need not measure a contact face finely).
///
/// A branch and bound over `a`'s triangles that meet `b`'s box. A piece of triangle whose
/// centre lies outside `b`, `d` from its surface, with corners at most `r` from the centre,
/// holds no point deeper than `r - d`; one whose centre lies inside holds none deeper than the
/// distance from its farthest corner to the surface point nearest the centre (a point's depth
/// is at most its distance to any surface point, and a triangle's farthest point from a point
/// is a corner). The piece most promising is halved while its bound beats the deepest
/// point found (by more than the resolution) and `floor_m`, and `r` exceeds the resolution.
pub fn deepest(a: SolidAt<'_>, b: SolidAt<'_>, floor_m: f64) -> f64 {
    let bb = b.bounds();
    if !a.bounds().overlaps(&bb, 0.0) {
        return 0.0;
    }
    let local_box = bb.translated(scale3(a.offset, -1.0));
    let mut best = 0.0f64;
    let mut measured = 0usize;
    // Each piece with the most it could hold; the most promising is split first, so the search
    // ends as soon as no piece can beat the deepest point found.
    let mut open: std::collections::BinaryHeap<Piece> = std::collections::BinaryHeap::new();
    let measure = |t: [[f64; 3]; 3],
                   best: &mut f64,
                   measured: &mut usize,
                   open: &mut std::collections::BinaryHeap<Piece>| {
        let c = scale3(add3(add3(t[0], t[1]), t[2]), 1.0 / 3.0);
        let r = t.iter().map(|p| norm3(sub3(*p, c))).fold(0.0, f64::max);
        let q = b.local(c);
        let (distance, surface) = b.solid.nearest(q);
        *measured += 1;
        // Inside or not, nothing deeper than distance + r: no need to know which.
        if distance + r <= (*best + DEPTH_RESOLUTION_M).max(floor_m) {
            return;
        }
        let (d, bound) = if b.solid.contains(q) {
            // A point of the piece is no deeper than its distance to the surface point nearest
            // the centre, at most that of the farthest corner (much less than distance + r
            // where the piece lies parallel to the surface).
            let farthest = t
                .iter()
                .map(|p| norm3(sub3(b.local(*p), surface)))
                .fold(0.0, f64::max);
            (distance, farthest)
        } else {
            (-distance, r - distance)
        };
        *best = best.max(d);
        if r > DEPTH_RESOLUTION_M && bound > (*best + DEPTH_RESOLUTION_M).max(floor_m) {
            open.push(Piece { bound, t });
        }
    };
    let mut first = Vec::new();
    a.solid
        .in_box(&local_box, |t| first.push(t.map(|p| add3(p, a.offset))));
    for t in first {
        measure(t, &mut best, &mut measured, &mut open);
    }
    while let Some(piece) = open.pop() {
        if piece.bound <= (best + DEPTH_RESOLUTION_M).max(floor_m) {
            break;
        }
        if measured >= MOST_PIECES {
            // Out of budget: the deepest point found stands (a lower bound).
            break;
        }
        // Halved across its longest side: pieces stay well shaped (a sliver of a scaled-up
        // pencil face, metres long and centimetres wide, becomes pieces as wide as long).
        let t = piece.t;
        let k = (0..3)
            .max_by(|&i, &j| {
                let li = norm3(sub3(t[(i + 1) % 3], t[i]));
                let lj = norm3(sub3(t[(j + 1) % 3], t[j]));
                li.total_cmp(&lj).then(j.cmp(&i))
            })
            .unwrap_or(0);
        let (p, q, o) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
        let m = mid(p, q);
        for t in [[p, m, o], [m, q, o]] {
            measure(t, &mut best, &mut measured, &mut open);
        }
    }
    best
}

/// A piece of triangle waiting in [`deepest`]'s search, ordered by the most it could hold.
struct Piece {
    bound: f64,
    t: [[f64; 3]; 3],
}

impl PartialEq for Piece {
    fn eq(&self, other: &Self) -> bool {
        self.bound.total_cmp(&other.bound).is_eq()
    }
}

impl Eq for Piece {}

impl PartialOrd for Piece {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Piece {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.bound.total_cmp(&other.bound)
    }
}

fn mid(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    scale3(add3(a, b), 0.5)
}

/// How far `moving` could fall straight down onto `fixed`, metres, if `fixed` is under it
/// at all: 0 when a point of one lies inside the other; else the shortest vertical ray from
/// `moving`'s points down to `fixed` or from `fixed`'s points up to `moving`.
///
/// Only a gap shorter than `limit_m` is sought (`None` when there is none), and the search
/// stops at the first within `touch_m` (which it returns: the object rests): what the caller
/// asks is "does it rest, else is this the shortest fall so far", and points and parts of the
/// tree that cannot answer shorter are skipped.
pub fn fall_onto(
    moving: SolidAt<'_>,
    fixed: SolidAt<'_>,
    touch_m: f64,
    limit_m: f64,
) -> Option<f64> {
    let (mb, fb) = (moving.bounds(), fixed.bounds());
    if !mb.overlaps_xy(&fb, 0.0) || fb.min[2] >= mb.max[2] {
        return None;
    }
    let in_column = |b: &Bounds, p: &[f64; 3]| {
        p[0] >= b.min[0] && p[0] <= b.max[0] && p[1] >= b.min[1] && p[1] <= b.max[1]
    };
    // The shortest gap found so far, or the limit.
    let mut best = limit_m;
    // Down from the moving object's points; a point inside the other means sunk: it rests.
    for p in moving
        .points()
        .filter(|p| in_column(&fb, p) && p[2] >= fb.min[2] - 1e-9)
    {
        if p[2] - fb.max[2] >= best {
            continue;
        }
        let q = fixed.local(p);
        // Only a point within the other's height can be inside it.
        let column = fixed
            .solid
            .column(q, p[2] <= fb.max[2], best, f64::NEG_INFINITY);
        // The vertical line's word alone is fooled by a crack or an open rim: confirmed by
        // the three axes.
        if column.inside && fixed.solid.contains(q) {
            return Some(0.0);
        }
        if let Some(g) = column.below.filter(|&g| g < best) {
            best = g;
            if best <= touch_m {
                return Some(best);
            }
        }
    }
    for p in fixed
        .points()
        .filter(|p| in_column(&mb, p) && p[2] <= mb.max[2] + 1e-9)
    {
        if mb.min[2] - p[2] >= best {
            continue;
        }
        let q = moving.local(p);
        let column = moving
            .solid
            .column(q, p[2] >= mb.min[2], f64::NEG_INFINITY, best);
        if column.inside && moving.solid.contains(q) {
            return Some(0.0);
        }
        if let Some(g) = column.above.filter(|&g| g < best) {
            best = g;
            if best <= touch_m {
                return Some(best);
            }
        }
    }
    (best < limit_m).then_some(best)
}

/// Whether triangle `t` covers `p` seen along `axis` (in the plane of axes `u`, `v`, a cyclic
/// order after `axis`), with the sign of its normal along `axis` and where along `axis` the
/// line through `p` meets it. With `exclusive`, a point on an edge shared by two triangles is
/// covered by exactly one of them (a rasterizer's top-left rule), so a ray through an edge
/// counts one crossing.
fn cover(
    t: &[[f64; 3]; 3],
    u: usize,
    v: usize,
    axis: usize,
    p: [f64; 3],
    exclusive: bool,
) -> Option<(i32, f64)> {
    let q = |x: &[f64; 3]| [x[u], x[v]];
    let (a, b, c) = (q(&t[0]), q(&t[1]), q(&t[2]));
    let area = cross2(sub2(b, a), sub2(c, a));
    if area == 0.0 || !area.is_finite() {
        return None;
    }
    let (sign, a3, b3, c3) = if area > 0.0 {
        (1, t[0], t[1], t[2])
    } else {
        (-1, t[0], t[2], t[1])
    };
    let (a, b, c) = (q(&a3), q(&b3), q(&c3));
    let pp = [p[u], p[v]];
    let mut w = [0.0; 3];
    for (k, (x, y)) in [(b, c), (c, a), (a, b)].into_iter().enumerate() {
        let e = cross2(sub2(y, x), sub2(pp, x));
        if e < 0.0 {
            return None;
        }
        if e == 0.0 && exclusive {
            let d = sub2(y, x);
            if !(d[1] < 0.0 || (d[1] == 0.0 && d[0] > 0.0)) {
                return None;
            }
        }
        w[k] = e;
    }
    let total = area.abs();
    let at = (w[0] * a3[axis] + w[1] * b3[axis] + w[2] * c3[axis]) / total;
    Some((sign, at))
}

fn sub2(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

fn cross2(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::assets::synthetic::Mesh;
    use crate::assets::table_aligned_from_gltf;

    /// A synthetic mesh (glTF frame) as the check holds an asset's: table-aligned, centred on
    /// its box.
    fn asset(mesh: &Mesh) -> AssetMesh {
        let aligned: Vec<[f64; 3]> = mesh
            .positions
            .iter()
            .map(|p| table_aligned_from_gltf(*p, 0.0))
            .collect();
        let b = aligned.iter().fold(Bounds::empty(), |b, p| {
            b.union(&Bounds { min: *p, max: *p })
        });
        let c = b.center();
        AssetMesh::new(
            aligned.iter().map(|p| sub3(*p, c)).collect(),
            mesh.triangles.clone(),
        )
    }

    /// A box of width, depth and height (table frame).
    fn block(w: f64, d: f64, h: f64) -> Mesh {
        Mesh::cuboid([w, h, d])
    }

    /// Placed at `at`, unturned, unscaled.
    fn placed(mesh: &AssetMesh, at: [f64; 3]) -> Solid {
        mesh.place(at, [0.0, 0.0, 0.0, 1.0], [1.0; 3])
    }

    fn at(solid: &Solid) -> SolidAt<'_> {
        SolidAt {
            solid,
            offset: [0.0; 3],
        }
    }

    #[test]
    fn inside_outside_and_distance_of_a_box() {
        let cube = asset(&block(0.1, 0.1, 0.1));
        let s = placed(&cube, [0.0; 3]);
        assert!(s.contains([0.0, 0.0, 0.0]));
        assert!(s.contains([0.049, 0.049, -0.049]));
        assert!(!s.contains([0.051, 0.0, 0.0]));
        assert!((s.distance([0.0, 0.0, 0.0]) - 0.05).abs() < 1e-12);
        assert!((s.distance([0.0, 0.0, 0.08]) - 0.03).abs() < 1e-12);
        // A vertical ray through an edge and a vertex of the grid counts one crossing.
        assert!(s.contains([0.0, 0.0, 0.01]));
        assert!(s.contains([0.02, -0.02, 0.0]));
    }

    #[test]
    fn two_overlapping_closed_pieces_are_one_solid() {
        let other = Mesh::cuboid([0.1, 0.1, 0.1]).translated([0.05, 0.0, 0.0]);
        let two = Mesh::cuboid([0.1, 0.1, 0.1]).merged(&other);
        let s = placed(&asset(&two), [0.0; 3]);
        // Centred on the pair's box: the pieces span x in [-0.075, 0.025] and [-0.025, 0.075].
        // In both: winding number 2, still inside.
        assert!(s.contains([0.0, 0.0, 0.0]));
        assert!(s.contains([0.05, 0.0, 0.0]));
        assert!(s.contains([-0.05, 0.0, 0.0]));
        assert!(!s.contains([0.085, 0.0, 0.0]));
    }

    #[test]
    fn depth_of_a_thin_object_buried_in_another() {
        // A 1.7 mm phone 27 mm deep inside a towel 100 mm thick: depth about 27 mm, whatever
        // the phone's thinness.
        let towel = placed(&asset(&block(0.3, 0.3, 0.1)), [0.0, 0.0, 0.05]);
        let phone = placed(&asset(&block(0.07, 0.15, 0.0017)), [0.0, 0.0, 0.073]);
        let d = deepest(at(&phone), at(&towel), 0.0);
        assert!((d - 0.027).abs() < 1e-3, "{d}");
        // Control: the phone lying on the towel is not inside it.
        let on = placed(&asset(&block(0.07, 0.15, 0.0017)), [0.0, 0.0, 0.101]);
        assert_eq!(deepest(at(&on), at(&towel), 0.0), 0.0);
    }

    #[test]
    fn falls_on_meshes() {
        let table_box = placed(&asset(&block(0.2, 0.2, 0.02)), [0.0, 0.0, 0.01]);
        let ball = placed(
            &asset(&Mesh::sphere(0.03, 12, 24)),
            [0.0, 0.0, 0.02 + 0.03 + 0.005],
        );
        let gap = fall_onto(at(&ball), at(&table_box), 0.0, f64::INFINITY).expect("over it");
        assert!((gap - 0.005).abs() < 2e-4, "{gap}");
        // Beside it: nothing under.
        let beside = placed(&asset(&Mesh::sphere(0.03, 12, 24)), [0.5, 0.0, 0.1]);
        assert_eq!(
            fall_onto(at(&beside), at(&table_box), 0.0, f64::INFINITY),
            None
        );
        // Sunk in: 0.
        let sunk = placed(&asset(&Mesh::sphere(0.03, 12, 24)), [0.0, 0.0, 0.045]);
        assert_eq!(
            fall_onto(at(&sunk), at(&table_box), 0.0, f64::INFINITY),
            Some(0.0)
        );
        // Moved by an offset, as settling moves it.
        let moved = SolidAt {
            solid: &ball,
            offset: [0.0, 0.0, 0.01],
        };
        let gap = fall_onto(moved, at(&table_box), 0.0, f64::INFINITY).expect("over it");
        assert!((gap - 0.015).abs() < 2e-4, "{gap}");
    }

    #[test]
    fn samples_are_spread_by_area_and_the_same_every_time() {
        let m = Mesh::cuboid([0.4, 0.1, 0.1]);
        let a = asset(&m);
        assert_eq!(a, asset(&m));
        let samples = &a.points_m[m.positions.len()..];
        assert_eq!(samples.len(), SURFACE_SAMPLES);
        // The two 0.1 × 0.1 ends hold 2 / 18 of the area.
        let ends = samples.iter().filter(|p| p[0].abs() > 0.2 - 1e-12).count();
        let expected = SURFACE_SAMPLES as f64 * 2.0 / 18.0;
        assert!((ends as f64 - expected).abs() < 0.05 * expected, "{ends}");
    }
}
