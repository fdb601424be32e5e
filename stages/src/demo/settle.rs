//! Exact vertical resting: how far an object must be lifted so that, on every vertical line,
//! it lies above another mesh.
//!
//! For two triangles whose projections on the table plane overlap, the height difference
//! `z_fixed(x, y) - z_moving(x, y)` is affine over the overlap polygon, so its maximum is at
//! one of the polygon's corners. The largest such value over all pairs is the smallest lift
//! that puts the moving mesh above the fixed one wherever both exist; lifted by that much
//! (plus a clearance) the meshes cannot interpenetrate, and the moving one touches the fixed
//! one (it rests on it). Vertical triangles are skipped: in a closed mesh the extreme heights
//! on a vertical line are reached on the faces that meet them.

use crate::mesh::{Aabb, Affine3, TriMesh};

/// A triangle projected on the table plane, with its heights.
#[derive(Debug, Clone, Copy)]
struct Tri {
    /// Corners, counter-clockwise in (x, y).
    xy: [[f64; 2]; 3],
    z: [f64; 3],
    /// Bounds of the projection: [x_min, x_max, y_min, y_max].
    bounds: [f64; 4],
}

impl Tri {
    fn new(p: [[f64; 3]; 3]) -> Option<Self> {
        let mut xy = [[p[0][0], p[0][1]], [p[1][0], p[1][1]], [p[2][0], p[2][1]]];
        let mut z = [p[0][2], p[1][2], p[2][2]];
        let area = cross2(sub2(xy[1], xy[0]), sub2(xy[2], xy[0]));
        if area.abs() < 1e-12 {
            return None;
        }
        if area < 0.0 {
            xy.swap(1, 2);
            z.swap(1, 2);
        }
        let bounds = [
            xy.iter().map(|p| p[0]).fold(f64::INFINITY, f64::min),
            xy.iter().map(|p| p[0]).fold(f64::NEG_INFINITY, f64::max),
            xy.iter().map(|p| p[1]).fold(f64::INFINITY, f64::min),
            xy.iter().map(|p| p[1]).fold(f64::NEG_INFINITY, f64::max),
        ];
        Some(Self { xy, z, bounds })
    }

    /// Height of the triangle's plane above (x, y).
    fn height_at(&self, p: [f64; 2]) -> f64 {
        let [a, b, c] = self.xy;
        let area = cross2(sub2(b, a), sub2(c, a));
        let l1 = cross2(sub2(p, a), sub2(c, a)) / area;
        let l2 = cross2(sub2(b, a), sub2(p, a)) / area;
        let l0 = 1.0 - l1 - l2;
        l0 * self.z[0] + l1 * self.z[1] + l2 * self.z[2]
    }
}

fn sub2(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

fn cross2(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

fn overlaps(a: &[f64; 4], b: &[f64; 4]) -> bool {
    a[0] <= b[1] && b[0] <= a[1] && a[2] <= b[3] && b[2] <= a[3]
}

/// A mesh placed in the table frame, prepared for vertical queries.
#[derive(Debug, Clone)]
pub(crate) struct VerticalMesh {
    tris: Vec<Tri>,
    /// Bounds of the placed mesh.
    pub bounds: Aabb,
    /// A uniform grid over the projection bounds, listing triangles by cell.
    grid: Grid,
}

#[derive(Debug, Clone)]
struct Grid {
    x0: f64,
    y0: f64,
    cell: f64,
    nx: usize,
    ny: usize,
    cells: Vec<Vec<u32>>,
}

impl Grid {
    fn cell_range(&self, b: &[f64; 4]) -> (usize, usize, usize, usize) {
        let clamp_x =
            |v: f64| (((v - self.x0) / self.cell).floor().max(0.0) as usize).min(self.nx - 1);
        let clamp_y =
            |v: f64| (((v - self.y0) / self.cell).floor().max(0.0) as usize).min(self.ny - 1);
        (clamp_x(b[0]), clamp_x(b[1]), clamp_y(b[2]), clamp_y(b[3]))
    }
}

impl VerticalMesh {
    /// The meshes mapped by `world_from_mesh`, as one vertical-query mesh; `None` when
    /// there is no triangle.
    pub(crate) fn new(meshes: &[&TriMesh], world_from_mesh: &Affine3) -> Option<Self> {
        let mut tris = Vec::new();
        let mut bounds: Option<Aabb> = None;
        for mesh in meshes {
            let points: Vec<[f64; 3]> = mesh
                .positions
                .iter()
                .map(|p| world_from_mesh.apply_point([p[0] as f64, p[1] as f64, p[2] as f64]))
                .collect();
            for p in &points {
                match &mut bounds {
                    Some(b) => b.extend(*p),
                    None => bounds = Some(Aabb::from_point(*p)),
                }
            }
            for t in &mesh.triangles {
                if let Some(tri) = Tri::new([
                    points[t[0] as usize],
                    points[t[1] as usize],
                    points[t[2] as usize],
                ]) {
                    tris.push(tri);
                }
            }
        }
        let bounds = bounds?;
        let size = bounds.size();
        let cell = ((size[0] * size[1]).sqrt() / 24.0).max(0.004);
        let nx = ((size[0] / cell).ceil() as usize).clamp(1, 256);
        let ny = ((size[1] / cell).ceil() as usize).clamp(1, 256);
        let mut grid = Grid {
            x0: bounds.min[0],
            y0: bounds.min[1],
            cell,
            nx,
            ny,
            cells: vec![Vec::new(); nx * ny],
        };
        for (i, t) in tris.iter().enumerate() {
            let (x_a, x_b, y_a, y_b) = grid.cell_range(&t.bounds);
            for y in y_a..=y_b {
                for x in x_a..=x_b {
                    grid.cells[y * nx + x].push(i as u32);
                }
            }
        }
        Some(Self { tris, bounds, grid })
    }

    /// The projection bounds `[x_min, x_max, y_min, y_max]`.
    pub(crate) fn footprint(&self) -> [f64; 4] {
        [
            self.bounds.min[0],
            self.bounds.max[0],
            self.bounds.min[1],
            self.bounds.max[1],
        ]
    }
}

/// Clips convex polygon `subject` (counter-clockwise) by triangle `clip` (counter-clockwise).
fn clip_polygon(
    subject: &[[f64; 2]],
    clip: &[[f64; 2]; 3],
    out: &mut Vec<[f64; 2]>,
    scratch: &mut Vec<[f64; 2]>,
) {
    out.clear();
    out.extend_from_slice(subject);
    for i in 0..3 {
        let (a, b) = (clip[i], clip[(i + 1) % 3]);
        let edge = sub2(b, a);
        let side = |p: [f64; 2]| cross2(edge, sub2(p, a));
        std::mem::swap(out, scratch);
        out.clear();
        let n = scratch.len();
        for k in 0..n {
            let p = scratch[k];
            let q = scratch[(k + 1) % n];
            let (sp, sq) = (side(p), side(q));
            if sp >= -1e-15 {
                out.push(p);
            }
            if (sp >= -1e-15) != (sq >= -1e-15) {
                let t = sp / (sp - sq);
                out.push([p[0] + (q[0] - p[0]) * t, p[1] + (q[1] - p[1]) * t]);
            }
        }
        if out.is_empty() {
            return;
        }
    }
}

/// The smallest upward shift of `moving` that puts it above `fixed` on every vertical line
/// crossing both; `None` when no vertical line crosses both.
pub(crate) fn lift_to_clear(moving: &VerticalMesh, fixed: &VerticalMesh) -> Option<f64> {
    let fm = moving.footprint();
    if !overlaps(&fm, &fixed.footprint()) {
        return None;
    }
    let mut best: Option<f64> = None;
    let mut stamp = vec![u32::MAX; moving.tris.len()];
    let mut poly = Vec::with_capacity(9);
    let mut scratch = Vec::with_capacity(9);
    for (fi, f) in fixed.tris.iter().enumerate() {
        if !overlaps(&f.bounds, &fm) {
            continue;
        }
        let (x_a, x_b, y_a, y_b) = moving.grid.cell_range(&f.bounds);
        for y in y_a..=y_b {
            for x in x_a..=x_b {
                for &mi in &moving.grid.cells[y * moving.grid.nx + x] {
                    if stamp[mi as usize] == fi as u32 {
                        continue;
                    }
                    stamp[mi as usize] = fi as u32;
                    let m = &moving.tris[mi as usize];
                    if !overlaps(&m.bounds, &f.bounds) {
                        continue;
                    }
                    clip_polygon(&m.xy, &f.xy, &mut poly, &mut scratch);
                    for p in &poly {
                        let d = f.height_at(*p) - m.height_at(*p);
                        if best.is_none_or(|b| d > b) {
                            best = Some(d);
                        }
                    }
                }
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    fn placed(mesh: &TriMesh, at: [f64; 3]) -> VerticalMesh {
        VerticalMesh::new(&[mesh], &Affine3::from_translation(at)).expect("mesh")
    }

    #[test]
    fn a_box_rests_on_a_box() {
        let cube = TriMesh::cuboid([0.1, 0.1, 0.1]);
        let below = placed(&cube, [0.0, 0.0, 0.05]);
        // A smaller box centred at z = 0 and offset sideways but still overlapping.
        let small = TriMesh::cuboid([0.04, 0.04, 0.04]);
        let above = placed(&small, [0.03, 0.0, 0.0]);
        let lift = lift_to_clear(&above, &below).expect("overlap");
        // Its bottom (-0.02) must reach the top (0.1).
        // f32 vertices: exact to a micrometre.
        assert_abs_diff_eq!(lift, 0.12, epsilon = 1e-6);
        let apart = placed(&small, [0.3, 0.0, 0.0]);
        assert!(lift_to_clear(&apart, &below).is_none());
    }

    #[test]
    fn a_ball_sinks_into_a_bowl_until_it_touches() {
        // A hemispherical shell bowl approximated by a dish; a ball above its centre rests
        // lower than the rim.
        let bowl = crate::demo::shapes::dish(0.1, 0.06, 0.004, 0.03, 1.6, 48)
            .transformed(&crate::mesh::table_from_gltf());
        let fixed = placed(&bowl, [0.0; 3]);
        let ball = TriMesh::uv_sphere(0.03, 24, 12);
        let moving = placed(&ball, [0.0; 3]);
        let lift = lift_to_clear(&moving, &fixed).expect("overlap");
        // The ball's bottom (at -0.03 + lift) sits between the floor and the rim.
        let bottom = lift - 0.03;
        assert!((0.004 - 1e-9..0.03).contains(&bottom), "bottom {bottom}");
    }
}
