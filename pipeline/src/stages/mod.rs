//! The per-scene stages of `mesa run`, in pipeline order, as runner adapters over the pure
//! functions of `mesa-stages`.

pub mod graph;
pub mod lift;
pub mod records;
pub mod scene_docs;
pub mod tasks;

use crate::runner::SceneStage;

/// Every per-scene stage, in the order `mesa run` runs them. The dataset-level stages
/// (`records`) run after them, once.
pub fn pipeline_stages() -> Vec<Box<dyn SceneStage>> {
    vec![
        Box::new(lift::Lift),
        Box::new(graph::GraphStage::new()),
        Box::new(tasks::TasksStage::new()),
    ]
}
