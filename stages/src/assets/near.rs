//! Whether a point lies within a distance of a triangle mesh: a bounding-volume tree over the
//! triangles, walked with a fixed stack until the first triangle close enough.
//!
//! The decomposition ([`super::decompose`]) measures each candidate part by the largest
//! distance outside the mesh of points sampled on its faces. Most samples lie on or next to the
//! mesh and cannot raise the largest distance found so far; for those, "is some triangle
//! within `r`" settles the question, and it is much cheaper than the nearest-point query that
//! parry3d answers (a best-first walk with a heap allocated per query, which must prove that
//! no nearer triangle exists). Only the samples this test cannot rule out go to parry3d, so the
//! decomposition's figures stay those of parry3d's queries bit for bit: the test works in `f64`
//! on the mesh's own coordinates and is used with a margin larger than the rounding of
//! parry3d's `f32` millimetres ([`NearTest::slack_m`]).
//!
//! Hand-written because parry3d's tree has no "any leaf within a distance" walk with early
//! exit, and its traversal allocates per query; the tree is [`crate::tri_tree`]'s.

use super::reach::distance_point_triangle;
use crate::tri_tree::{self, Node, Stack};

/// A bounding-volume tree over a mesh's triangles, for "within a distance" tests.
pub(crate) struct NearTest {
    nodes: Vec<Node>,
    /// The triangles' corners in tree order.
    triangles: Vec<[[f64; 3]; 3]>,
    slack_m: f64,
}

impl NearTest {
    /// The tree of the triangles `triangles` of `positions` (metres).
    pub(crate) fn new(positions: &[[f64; 3]], triangles: &[[u32; 3]]) -> Self {
        let corners: Vec<[[f64; 3]; 3]> = triangles
            .iter()
            .map(|t| t.map(|i| positions[i as usize]))
            .collect();
        let largest = positions
            .iter()
            .flatten()
            .fold(0.0f64, |m, v| m.max(v.abs()));
        let (nodes, order) = tri_tree::build(&corners);
        Self {
            nodes,
            triangles: order.iter().map(|&i| corners[i as usize]).collect(),
            // parry3d sees `f32` millimetres: a coordinate of `largest` metres is rounded by
            // about 6e-8 of it; its distances are a few such roundings off. One micrometre
            // plus ten parts per million of the largest coordinate covers them many times.
            slack_m: 1e-6 + 1e-5 * largest,
        }
    }

    /// A margin above the difference between this test's distances and parry3d's on the same
    /// mesh: a point this test finds within `r - slack_m` is within `r` for parry3d too.
    pub(crate) fn slack_m(&self) -> f64 {
        self.slack_m
    }

    /// Whether some triangle is within `r` metres of `p` (`false` for a negative `r`).
    pub(crate) fn within(&self, p: [f64; 3], r: f64) -> bool {
        if r < 0.0 || self.nodes.is_empty() {
            return false;
        }
        let r2 = r * r;
        let mut stack = Stack::new();
        while let Some(n) = stack.pop() {
            let node = &self.nodes[n as usize];
            if node.distance2(p) > r2 {
                continue;
            }
            if node.count > 0 {
                if self.triangles[node.triangles()]
                    .iter()
                    .any(|[a, b, c]| distance_point_triangle(p, *a, *b, *c) <= r)
                {
                    return true;
                }
                continue;
            }
            stack.push_children_nearer_first(&self.nodes, n, p);
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic scatter of triangles and points (a small linear congruential generator:
    /// the test needs no randomness crate).
    fn scatter(n: usize, seed: u64) -> Vec<[f64; 3]> {
        let mut s = seed;
        (0..n)
            .map(|_| {
                std::array::from_fn(|_| {
                    s = s
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    ((s >> 11) as f64 / (1u64 << 53) as f64) * 0.2 - 0.1
                })
            })
            .collect()
    }

    #[test]
    fn within_agrees_with_the_nearest_triangle_found_by_brute_force() {
        let positions = scatter(600, 7);
        let triangles: Vec<[u32; 3]> = (0..200u32).map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect();
        let near = NearTest::new(&positions, &triangles);
        let mut agree = 0;
        for p in scatter(400, 11) {
            let nearest = triangles
                .iter()
                .map(|t| {
                    let [a, b, c] = t.map(|i| positions[i as usize]);
                    distance_point_triangle(p, a, b, c)
                })
                .fold(f64::INFINITY, f64::min);
            // Just above and just below the nearest distance.
            assert!(near.within(p, nearest * (1.0 + 1e-9) + 1e-15), "{p:?}");
            assert!(!near.within(p, nearest * (1.0 - 1e-6)), "{p:?}");
            agree += 1;
        }
        assert_eq!(agree, 400);
        // Control: a radius of zero finds nothing for points off every triangle.
        assert!(!near.within([1.0, 1.0, 1.0], 0.0));
        assert!(!near.within([0.0; 3], -1.0));
    }
}
