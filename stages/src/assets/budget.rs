//! Cost budgets of an asset: what indexing it may cost, judged up front from the GLB's JSON
//! (accessor counts and node instancing) before any mesh is expanded.
//!
//! Indexing an asset costs about its placed triangles (a mesh placed by 200 nodes counts 200
//! times): reading them, and above all the convex decomposition, whose cuts clip every
//! triangle of a piece. An asset over the budget (`[assets.budget]` `triangles` or
//! `instances`) gets its collision shape from a **decimated** copy of its mesh
//! ([`super::simplify`]: vertex clustering on a uniform grid, to at most
//! `simplified_triangles`), and the record says how far that shape reaches outside the
//! original mesh ([`super::reach`]). An asset over `max_triangles` is rejected with the reason
//! before its meshes are read. The decomposition itself stops cooperatively at `seconds`
//! (checked between cuts), keeping the pieces it has as parts.

use gltf_json::mesh::Mode;
use gltf_json::validation::Checked;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::glb_read::{GlbDocument, GlbError};

/// The `[assets.budget]` section: what indexing one asset may cost.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct AssetBudget {
    /// Placed triangles (accessor counts times the nodes placing each mesh, read before any
    /// mesh is expanded) above which the collision shape is made from a decimated mesh
    /// (vertex clustering); the record says how far it reaches outside the original.
    pub triangles: u64,
    /// Mesh instances (nodes placing a mesh) above which the collision shape is made from a
    /// decimated mesh, as for `triangles`.
    pub instances: u64,
    /// Placed triangles above which the asset is rejected (reason code `over_budget`) before
    /// its meshes are read: reading them alone would cost gigabytes.
    pub max_triangles: u64,
    /// The decimated mesh of an asset over the budget has at most this many triangles.
    pub simplified_triangles: u64,
    /// Seconds the convex decomposition of one asset may take (one core); when they run out
    /// it stops cutting and keeps the pieces it has as parts, with a warning saying how far
    /// they reach outside the mesh. Checked between cuts: an asset never stalls the run.
    pub seconds: f64,
}

impl Default for AssetBudget {
    fn default() -> Self {
        Self {
            triangles: 200_000,
            instances: 100,
            max_triangles: 50_000_000,
            simplified_triangles: 20_000,
            seconds: 20.0,
        }
    }
}

impl AssetBudget {
    /// Values that parse but cannot work, each naming its key.
    pub fn problems(&self) -> Vec<String> {
        let mut out = Vec::new();
        if !(self.seconds >= 0.0 && self.seconds.is_finite()) {
            out.push(format!(
                "[assets.budget] seconds = {}: expected a finite number of seconds >= 0",
                self.seconds
            ));
        }
        if self.simplified_triangles < 8 {
            out.push(format!(
                "[assets.budget] simplified_triangles = {}: expected at least 8 (a decimated \
                 mesh needs a few triangles)",
                self.simplified_triangles
            ));
        }
        out
    }
}

/// What indexing a GLB will cost, from its JSON alone.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct GlbCost {
    /// Triangles placed by the default scene (a mesh placed twice counts twice).
    pub triangles: u64,
    /// Nodes of the default scene that place a mesh.
    pub instances: u64,
}

/// The triangles a primitive of `count` indices (or vertices) in `mode` draws.
fn triangles_of(count: u64, mode: Mode) -> u64 {
    match mode {
        Mode::Triangles => count / 3,
        Mode::TriangleStrip | Mode::TriangleFan => count.saturating_sub(2),
        _ => 0,
    }
}

/// The cost of a GLB: its placed triangles from accessor counts and node instancing, without
/// reading any buffer. Draco primitives count by their accessors' declared counts (glTF
/// requires them to match the decoded data).
pub fn glb_cost(document: &GlbDocument<'_>) -> Result<GlbCost, GlbError> {
    let root = document.root();
    let accessor_count = |index: usize| root.accessors.get(index).map_or(0, |a| a.count.0);
    let mesh_triangles: Vec<u64> = root
        .meshes
        .iter()
        .map(|mesh| {
            mesh.primitives
                .iter()
                .map(|p| {
                    let Checked::Valid(mode) = p.mode else {
                        return 0;
                    };
                    let count = match p.indices {
                        Some(indices) => accessor_count(indices.value()),
                        None => p
                            .attributes
                            .iter()
                            .find(|(semantic, _)| {
                                matches!(
                                    semantic,
                                    Checked::Valid(gltf_json::mesh::Semantic::Positions)
                                )
                            })
                            .map_or(0, |(_, a)| accessor_count(a.value())),
                    };
                    triangles_of(count, mode)
                })
                .fold(0u64, u64::saturating_add)
        })
        .collect();
    let world = document.world_matrices()?;
    let mut cost = GlbCost::default();
    for (node, placed) in root.nodes.iter().zip(&world) {
        if let (Some(mesh), Some(_)) = (node.mesh, placed) {
            cost.instances += 1;
            let triangles = mesh_triangles.get(mesh.value()).copied().unwrap_or(0);
            cost.triangles = cost.triangles.saturating_add(triangles);
        }
    }
    Ok(cost)
}

/// What the budget says of an asset of this cost.
#[derive(Debug, Clone, PartialEq)]
pub enum Verdict {
    /// Within the budget: indexed as usual.
    Within,
    /// Over the budget: the collision shape is made from a decimated mesh; why.
    Simplify(String),
    /// Over the hard cap: rejected, with the reason and the fix.
    Reject(String),
}

/// Judges a cost against the budget.
pub fn judge(cost: GlbCost, budget: &AssetBudget) -> Verdict {
    if cost.triangles > budget.max_triangles {
        return Verdict::Reject(format!(
            "the asset places {} triangles ({} mesh instances), over [assets.budget] \
             max_triangles = {}: indexing it would take gigabytes of memory (decimate it, e.g. \
             Blender's Decimate modifier, or raise max_triangles)",
            cost.triangles, cost.instances, budget.max_triangles
        ));
    }
    let mut over = Vec::new();
    if cost.triangles > budget.triangles {
        over.push(format!(
            "{} triangles > triangles = {}",
            cost.triangles, budget.triangles
        ));
    }
    if cost.instances > budget.instances {
        over.push(format!(
            "{} mesh instances > instances = {}",
            cost.instances, budget.instances
        ));
    }
    if over.is_empty() {
        Verdict::Within
    } else {
        Verdict::Simplify(format!("over [assets.budget] ({})", over.join(", ")))
    }
}
