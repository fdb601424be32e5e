//! The per-scene stages of `mesa run`, in pipeline order, as runner adapters over the pure
//! functions of `mesa-stages`.

pub mod graph;
pub mod lift;

use crate::runner::SceneStage;

/// Every per-scene stage, in the order `mesa run` runs them.
pub fn pipeline_stages() -> Vec<Box<dyn SceneStage>> {
    vec![Box::new(lift::Lift), Box::new(graph::GraphStage::new())]
}
