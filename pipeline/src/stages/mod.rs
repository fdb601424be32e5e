//! The per-scene stages of `mesa run`, in pipeline order, as runner adapters over the pure
//! functions of `mesa-stages`.

use crate::runner::SceneStage;

pub mod graph;

/// Every per-scene stage, in the order `mesa run` runs them.
pub fn pipeline_stages() -> Vec<Box<dyn SceneStage>> {
    vec![Box::new(graph::GraphStage::new())]
}
