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
//! exit, and its traversal allocates per query.

use super::reach::distance_point_triangle;

/// Triangles per leaf, at most.
const LEAF: usize = 4;

/// A node: its box, and either its children (`count == 0`: `first` is the right child, the
/// left one follows the node) or its triangles (`first..first + count` of the ordered list).
struct Node {
    min: [f64; 3],
    max: [f64; 3],
    first: u32,
    count: u32,
}

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
        let mut order: Vec<u32> = (0..corners.len() as u32).collect();
        let mut nodes = Vec::with_capacity(2 * corners.len() / LEAF + 1);
        if !corners.is_empty() {
            build(&corners, &mut order, 0, &mut nodes);
        }
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
        let mut stack = [0u32; 64];
        let mut depth = 1;
        while depth > 0 {
            depth -= 1;
            let node = &self.nodes[stack[depth] as usize];
            if box_distance2(node, p) > r2 {
                continue;
            }
            if node.count > 0 {
                let first = node.first as usize;
                for [a, b, c] in &self.triangles[first..first + node.count as usize] {
                    if distance_point_triangle(p, *a, *b, *c) <= r {
                        return true;
                    }
                }
                continue;
            }
            let left = stack[depth] + 1;
            let right = node.first;
            // The nearer child is walked first (pushed last).
            let (near, far) = if box_distance2(&self.nodes[left as usize], p)
                <= box_distance2(&self.nodes[right as usize], p)
            {
                (left, right)
            } else {
                (right, left)
            };
            if depth + 2 > stack.len() {
                // Deeper than a balanced tree of 2^62 leaves can be; never reached.
                return self.within_linear(p, r);
            }
            stack[depth] = far;
            stack[depth + 1] = near;
            depth += 2;
        }
        false
    }

    fn within_linear(&self, p: [f64; 3], r: f64) -> bool {
        self.triangles
            .iter()
            .any(|[a, b, c]| distance_point_triangle(p, *a, *b, *c) <= r)
    }
}

/// The squared distance from `p` to a node's box (0 inside it).
fn box_distance2(node: &Node, p: [f64; 3]) -> f64 {
    (0..3)
        .map(|k| {
            let d = (node.min[k] - p[k]).max(p[k] - node.max[k]).max(0.0);
            d * d
        })
        .sum()
}

/// Builds the subtree of `order` (indices into `corners`) at the end of `nodes`, median split
/// of the centroids along their longest side; returns nothing, the subtree's root is the node
/// at the length `nodes` had on entry. `offset` is where `order` starts in the full list.
fn build(corners: &[[[f64; 3]; 3]], order: &mut [u32], offset: usize, nodes: &mut Vec<Node>) {
    let mut min = [f64::INFINITY; 3];
    let mut max = [f64::NEG_INFINITY; 3];
    let mut cmin = [f64::INFINITY; 3];
    let mut cmax = [f64::NEG_INFINITY; 3];
    for &t in order.iter() {
        let tri = &corners[t as usize];
        for k in 0..3 {
            for p in tri {
                min[k] = min[k].min(p[k]);
                max[k] = max[k].max(p[k]);
            }
            let c = (tri[0][k] + tri[1][k] + tri[2][k]) / 3.0;
            cmin[k] = cmin[k].min(c);
            cmax[k] = cmax[k].max(c);
        }
    }
    let at = nodes.len();
    nodes.push(Node {
        min,
        max,
        first: offset as u32,
        count: order.len() as u32,
    });
    if order.len() <= LEAF {
        return;
    }
    let axis = (0..3)
        .max_by(|a, b| (cmax[*a] - cmin[*a]).total_cmp(&(cmax[*b] - cmin[*b])))
        .unwrap_or(0);
    let centroid = |t: u32| {
        let tri = &corners[t as usize];
        tri[0][axis] + tri[1][axis] + tri[2][axis]
    };
    let half = order.len() / 2;
    order.select_nth_unstable_by(half, |a, b| {
        centroid(*a).total_cmp(&centroid(*b)).then(a.cmp(b))
    });
    let (low, high) = order.split_at_mut(half);
    build(corners, low, offset, nodes);
    let right = nodes.len() as u32;
    build(corners, high, offset + half, nodes);
    nodes[at].first = right;
    nodes[at].count = 0;
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
