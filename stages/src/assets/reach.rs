//! How far convex parts reach outside a mesh: the cost, in collision accuracy, of making them
//! from a decimated copy of it ([`super::simplify`]).
//!
//! The parts are sampled as the decomposition samples its own (each hull's vertices and 7
//! points of each face) and each sample's distance to the original mesh is measured, for
//! samples outside it. Inside and outside come from a voxel grid over the mesh: cells crossed
//! by a triangle's box are *surface*, cells reached from the border without crossing one are
//! *outside*, the rest *inside* (an open mesh has no inside: every sample counts, as in
//! [`super::decompose`]). A sample in a surface cell counts with its distance too, so the
//! figure is an upper bound by at most a cell's diagonal where the parts meet the surface.
//! Distances are exact (point to triangle), searched ring by ring in the grid.

use parry3d::math::Point;
use parry3d::transformation::try_convex_hull;

/// Cells along the longest side of the mesh, at most.
const MOST_CELLS: usize = 128;

/// Triangle references kept in the grid, at most (a coarser grid is used beyond).
const MOST_ENTRIES: usize = 64 << 20;

const SURFACE: u8 = 1;
const OUTSIDE: u8 = 2;

struct Grid {
    origin: [f64; 3],
    cell: f64,
    dims: [usize; 3],
    /// CSR: the triangles of cell i are `entries[starts[i]..starts[i + 1]]`.
    starts: Vec<u32>,
    entries: Vec<u32>,
    state: Vec<u8>,
}

impl Grid {
    fn index(&self, p: [f64; 3]) -> ([usize; 3], bool) {
        let mut inside = true;
        let cell = std::array::from_fn(|k| {
            let i = ((p[k] - self.origin[k]) / self.cell).floor();
            if !(i >= 0.0 && i < self.dims[k] as f64) {
                inside = false;
            }
            if i.is_nan() || i < 0.0 {
                0
            } else {
                (i as usize).min(self.dims[k] - 1)
            }
        });
        (cell, inside)
    }

    fn flat(&self, c: [usize; 3]) -> usize {
        (c[2] * self.dims[1] + c[1]) * self.dims[0] + c[0]
    }

    fn build(positions: &[[f64; 3]], triangles: &[[u32; 3]]) -> Self {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in positions {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let longest = (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max).max(1e-9);
        let mut cells = MOST_CELLS;
        loop {
            let cell = longest / cells as f64;
            // One empty cell of margin on every side, so the border is outside.
            let origin = lo.map(|v| v - cell);
            let dims: [usize; 3] =
                std::array::from_fn(|k| ((hi[k] - lo[k]) / cell).floor() as usize + 3);
            let mut grid = Self {
                origin,
                cell,
                dims,
                starts: Vec::new(),
                entries: Vec::new(),
                state: Vec::new(),
            };
            let range = |t: &[u32; 3]| {
                let mut a = [usize::MAX; 3];
                let mut b = [0usize; 3];
                for &i in t {
                    let (c, _) = grid.index(positions[i as usize]);
                    for k in 0..3 {
                        a[k] = a[k].min(c[k]);
                        b[k] = b[k].max(c[k]);
                    }
                }
                (a, b)
            };
            let total: usize = triangles
                .iter()
                .map(|t| {
                    let (a, b) = range(t);
                    (0..3).map(|k| b[k] - a[k] + 1).product::<usize>()
                })
                .fold(0usize, usize::saturating_add);
            if total > MOST_ENTRIES && cells > 8 {
                cells /= 2;
                continue;
            }
            let n = dims[0] * dims[1] * dims[2];
            let mut counts = vec![0u32; n + 1];
            let each = |t: &[u32; 3], f: &mut dyn FnMut(usize)| {
                let (a, b) = range(t);
                for z in a[2]..=b[2] {
                    for y in a[1]..=b[1] {
                        for x in a[0]..=b[0] {
                            f((z * dims[1] + y) * dims[0] + x);
                        }
                    }
                }
            };
            for t in triangles {
                each(t, &mut |i| counts[i + 1] += 1);
            }
            for i in 0..n {
                counts[i + 1] += counts[i];
            }
            let mut fill = counts.clone();
            let mut entries = vec![0u32; counts[n] as usize];
            for (ti, t) in triangles.iter().enumerate() {
                each(t, &mut |i| {
                    entries[fill[i] as usize] = ti as u32;
                    fill[i] += 1;
                });
            }
            grid.starts = counts;
            grid.entries = entries;
            grid.state = (0..n)
                .map(|i| {
                    if grid.starts[i + 1] > grid.starts[i] {
                        SURFACE
                    } else {
                        0
                    }
                })
                .collect();
            grid.flood_outside();
            return grid;
        }
    }

    /// Marks every cell reached from the border through cells without a triangle.
    fn flood_outside(&mut self) {
        let [w, h, d] = self.dims;
        let mut stack: Vec<[usize; 3]> = Vec::new();
        for z in 0..d {
            for y in 0..h {
                for x in 0..w {
                    if x == 0 || y == 0 || z == 0 || x == w - 1 || y == h - 1 || z == d - 1 {
                        stack.push([x, y, z]);
                    }
                }
            }
        }
        while let Some(c) = stack.pop() {
            let i = self.flat(c);
            if self.state[i] != 0 {
                continue;
            }
            self.state[i] = OUTSIDE;
            for k in 0..3 {
                if c[k] > 0 {
                    let mut n = c;
                    n[k] -= 1;
                    stack.push(n);
                }
                if c[k] + 1 < self.dims[k] {
                    let mut n = c;
                    n[k] += 1;
                    stack.push(n);
                }
            }
        }
    }

    /// The distance from `p` to the mesh, or any value at most `enough` when it is at most
    /// that (the caller keeps a maximum and needs no more).
    fn distance(
        &self,
        p: [f64; 3],
        start: [usize; 3],
        positions: &[[f64; 3]],
        triangles: &[[u32; 3]],
        enough: f64,
    ) -> f64 {
        let mut best = f64::INFINITY;
        let most = self.dims.iter().copied().max().unwrap_or(1);
        for r in 0..=most {
            let r_i = r as i64;
            let lo: [i64; 3] = std::array::from_fn(|k| (start[k] as i64 - r_i).max(0));
            let hi: [i64; 3] =
                std::array::from_fn(|k| (start[k] as i64 + r_i).min(self.dims[k] as i64 - 1));
            for z in lo[2]..=hi[2] {
                for y in lo[1]..=hi[1] {
                    for x in lo[0]..=hi[0] {
                        let shell = (x - start[0] as i64).abs() == r_i
                            || (y - start[1] as i64).abs() == r_i
                            || (z - start[2] as i64).abs() == r_i;
                        if !shell {
                            continue;
                        }
                        let i = self.flat([x as usize, y as usize, z as usize]);
                        let (a, b) = (self.starts[i] as usize, self.starts[i + 1] as usize);
                        for &t in &self.entries[a..b] {
                            let [u, v, w] = triangles[t as usize].map(|j| positions[j as usize]);
                            best = best.min(distance_point_triangle(p, u, v, w));
                        }
                    }
                }
            }
            // Triangles in cells beyond ring r are at least r cells away.
            if best <= r as f64 * self.cell || best <= enough {
                break;
            }
        }
        best
    }
}

/// The distance from `p` to the triangle `abc`.
pub fn distance_point_triangle(p: [f64; 3], a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> f64 {
    let q = closest_point_triangle(p, a, b, c);
    let d = [p[0] - q[0], p[1] - q[1], p[2] - q[2]];
    (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
}

/// The point of the triangle `abc` nearest to `p` (Ericson, Real-Time Collision Detection
/// 5.1.5); for a degenerate triangle, the nearest of its corners.
pub fn closest_point_triangle(p: [f64; 3], a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> [f64; 3] {
    let sub = |u: [f64; 3], v: [f64; 3]| [u[0] - v[0], u[1] - v[1], u[2] - v[2]];
    let dot = |u: [f64; 3], v: [f64; 3]| u[0] * v[0] + u[1] * v[1] + u[2] * v[2];
    let at = |s: f64, u: [f64; 3], t: f64, v: [f64; 3]| -> [f64; 3] {
        std::array::from_fn(|k| a[k] + s * u[k] + t * v[k])
    };
    let (ab, ac, ap) = (sub(b, a), sub(c, a), sub(p, a));
    let (d1, d2) = (dot(ab, ap), dot(ac, ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = sub(p, b);
    let (d3, d4) = (dot(ab, bp), dot(ac, bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return at(v, ab, 0.0, ac);
    }
    let cp = sub(p, c);
    let (d5, d6) = (dot(ab, cp), dot(ac, cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return at(0.0, ab, w, ac);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return std::array::from_fn(|k| b[k] + w * (c[k] - b[k]));
    }
    let denom = va + vb + vc;
    if denom.abs() < f64::MIN_POSITIVE {
        let d2 = |q: [f64; 3]| dot(sub(p, q), sub(p, q));
        return [a, b, c]
            .into_iter()
            .min_by(|x, y| d2(*x).total_cmp(&d2(*y)))
            .unwrap_or(a);
    }
    let (v, w) = (vb / denom, vc / denom);
    at(v, ab, w, ac)
}

/// Sample points of a convex part: its hull's vertices and 7 points of each face.
fn samples(points_m: &[[f64; 3]]) -> Vec<[f64; 3]> {
    const MM: f64 = 1000.0;
    let as_f32: Vec<Point<f32>> = points_m
        .iter()
        .map(|p| Point::new((p[0] * MM) as f32, (p[1] * MM) as f32, (p[2] * MM) as f32))
        .collect();
    let hull = std::panic::catch_unwind(|| try_convex_hull(&as_f32))
        .ok()
        .and_then(Result::ok);
    let mut out: Vec<[f64; 3]> = points_m.to_vec();
    let Some((vertices, faces)) = hull else {
        return out;
    };
    let v = |i: u32| {
        let q = vertices[i as usize];
        [
            f64::from(q.x) / MM,
            f64::from(q.y) / MM,
            f64::from(q.z) / MM,
        ]
    };
    const WEIGHTS: [[f64; 3]; 7] = [
        [1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0],
        [2.0 / 3.0, 1.0 / 3.0, 0.0],
        [2.0 / 3.0, 0.0, 1.0 / 3.0],
        [1.0 / 3.0, 2.0 / 3.0, 0.0],
        [0.0, 2.0 / 3.0, 1.0 / 3.0],
        [1.0 / 3.0, 0.0, 2.0 / 3.0],
        [0.0, 1.0 / 3.0, 2.0 / 3.0],
    ];
    for f in &faces {
        let (a, b, c) = (v(f[0]), v(f[1]), v(f[2]));
        for w in WEIGHTS {
            out.push(std::array::from_fn(|k| {
                w[0] * a[k] + w[1] * b[k] + w[2] * c[k]
            }));
        }
    }
    out
}

/// How far the convex parts (each given by its points) reach outside the mesh, metres
/// (sampled; see the module documentation).
pub fn reach_outside(
    positions: &[[f64; 3]],
    triangles: &[[u32; 3]],
    parts: &[Vec<[f64; 3]>],
) -> f64 {
    if triangles.is_empty() {
        return 0.0;
    }
    let grid = Grid::build(positions, triangles);
    let mut worst: f64 = 0.0;
    for part in parts {
        for p in samples(part) {
            let (cell, in_grid) = grid.index(p);
            if in_grid && grid.state[grid.flat(cell)] == 0 {
                continue;
            }
            worst = worst.max(grid.distance(p, cell, positions, triangles, worst));
        }
    }
    worst
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::assets::synthetic::Mesh;
    use approx::assert_abs_diff_eq;

    #[test]
    fn point_triangle_distances() {
        let (a, b, c) = ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        assert_abs_diff_eq!(distance_point_triangle([0.2, 0.2, 0.5], a, b, c), 0.5);
        assert_abs_diff_eq!(distance_point_triangle([-1.0, 0.0, 0.0], a, b, c), 1.0);
        assert_abs_diff_eq!(distance_point_triangle([0.5, -2.0, 0.0], a, b, c), 2.0);
        assert_abs_diff_eq!(
            distance_point_triangle([1.0, 1.0, 0.0], a, b, c),
            0.5f64.sqrt(),
            epsilon = 1e-12
        );
    }

    #[test]
    fn a_part_inside_reaches_nothing_and_one_beyond_reaches_its_overhang() {
        let cube = Mesh::cuboid([0.1, 0.1, 0.1]);
        let inner = Mesh::cuboid([0.05, 0.05, 0.05]).translated([0.0, 0.02, 0.0]);
        assert_abs_diff_eq!(
            reach_outside(&cube.positions, &cube.triangles, &[inner.positions]),
            0.0
        );
        // A box 3 mm taller than the cube.
        let taller = Mesh::cuboid([0.1, 0.103, 0.1]);
        let reach = reach_outside(&cube.positions, &cube.triangles, &[taller.positions]);
        assert_abs_diff_eq!(reach, 0.003, epsilon = 1e-6);
    }
}
