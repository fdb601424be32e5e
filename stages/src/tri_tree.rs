//! A bounding-volume tree over a mesh's triangles, shared by the decomposition's "within a
//! distance" test ([`crate::assets`]) and the check's placed meshes ([`crate::check::solid`]).
//!
//! A median split of the triangles' centroids along their longest side, leaves of at most
//! [`LEAF`] triangles, stored depth first: a node's left child follows it, its right child is
//! at `first`. The walks themselves belong to their users (an early-exit "within r", lines,
//! nearest points); they share the nodes, the build, the refit and the fixed stack.
//!
//! Hand-written because parry3d's `Qbvh` allocates per traversal and has neither the early-exit
//! walk nor the vertical-line walk the users need, and works in `f32`.

/// Triangles per leaf, at most.
pub(crate) const LEAF: usize = 4;

/// A node: its box, and either its children (`count == 0`: `first` is the right child, the
/// left one follows the node) or its triangles (`first..first + count` of the ordered list).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Node {
    pub(crate) min: [f64; 3],
    pub(crate) max: [f64; 3],
    pub(crate) first: u32,
    pub(crate) count: u32,
}

impl Node {
    /// The squared distance from `p` to the node's box (0 inside it).
    pub(crate) fn distance2(&self, p: [f64; 3]) -> f64 {
        (0..3)
            .map(|k| {
                let d = (self.min[k] - p[k]).max(p[k] - self.max[k]).max(0.0);
                d * d
            })
            .sum()
    }

    /// The range of the leaf's triangles in the ordered list.
    pub(crate) fn triangles(&self) -> std::ops::Range<usize> {
        self.first as usize..(self.first + self.count) as usize
    }
}

/// The tree over triangles given by their corners: its nodes, and the order of the triangles
/// (the ordered list's `k`-th triangle is `corners[order[k]]`). No nodes without triangles.
pub(crate) fn build(corners: &[[[f64; 3]; 3]]) -> (Vec<Node>, Vec<u32>) {
    let mut order: Vec<u32> = (0..corners.len() as u32).collect();
    let mut nodes = Vec::with_capacity(2 * corners.len() / LEAF + 1);
    if !corners.is_empty() {
        build_into(corners, &mut order, 0, &mut nodes);
    }
    (nodes, order)
}

/// Builds the subtree of `order` (indices into `corners`) at the end of `nodes`; its root is
/// the node at the length `nodes` had on entry. `offset` is where `order` starts in the list.
fn build_into(corners: &[[[f64; 3]; 3]], order: &mut [u32], offset: usize, nodes: &mut Vec<Node>) {
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
    build_into(corners, low, offset, nodes);
    let right = nodes.len() as u32;
    build_into(corners, high, offset + half, nodes);
    nodes[at].first = right;
    nodes[at].count = 0;
}

/// Sets every node's box to what its triangles (`triangles`, in the tree's order) span, after
/// they moved: children come after their parent, so a backward pass meets every child before
/// its parent. An affine map keeps every triangle in its leaf; only the boxes change.
pub(crate) fn refit(nodes: &mut [Node], triangles: &[[[f64; 3]; 3]]) {
    for n in (0..nodes.len()).rev() {
        let (mut min, mut max) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        let node = &nodes[n];
        if node.count > 0 {
            for p in triangles[node.triangles()].iter().flatten() {
                for k in 0..3 {
                    min[k] = min[k].min(p[k]);
                    max[k] = max[k].max(p[k]);
                }
            }
        } else {
            let (left, right) = (&nodes[n + 1], &nodes[node.first as usize]);
            for k in 0..3 {
                min[k] = left.min[k].min(right.min[k]);
                max[k] = left.max[k].max(right.max[k]);
            }
        }
        nodes[n].min = min;
        nodes[n].max = max;
    }
}

/// A walk's nodes to visit: a fixed array, no allocation per query. The tree is balanced (its
/// depth is about log2(triangles / LEAF)) and each level leaves at most one node waiting, so
/// 96 entries hold the walk of any mesh that fits in memory.
pub(crate) struct Stack {
    nodes: [u32; 96],
    len: usize,
}

impl Stack {
    /// A walk from the root.
    pub(crate) fn new() -> Self {
        Self {
            nodes: [0; 96],
            len: 1,
        }
    }

    pub(crate) fn push(&mut self, n: u32) {
        self.nodes[self.len] = n;
        self.len += 1;
    }

    pub(crate) fn pop(&mut self) -> Option<u32> {
        self.len = self.len.checked_sub(1)?;
        Some(self.nodes[self.len])
    }

    /// Both children of `node` (at `n`), the one nearer `p` to be visited first.
    pub(crate) fn push_children_nearer_first(&mut self, nodes: &[Node], n: u32, p: [f64; 3]) {
        let (left, right) = (n + 1, nodes[n as usize].first);
        if nodes[left as usize].distance2(p) <= nodes[right as usize].distance2(p) {
            self.push(right);
            self.push(left);
        } else {
            self.push(left);
            self.push(right);
        }
    }
}
