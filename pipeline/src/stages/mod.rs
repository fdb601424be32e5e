//! The per-scene stages of `mesa run`, in pipeline order, as runner adapters over the pure
//! functions of `mesa-stages`, and the dataset-level `mesa assets` ([`assets`]), which `mesa
//! run` runs before them.

pub mod assets;
pub mod dataset_cache;
pub mod graph;
pub mod lift;
pub mod place;
pub mod records;
pub mod release;
pub mod render;
pub mod report;
pub mod retrieve;
pub mod scene_docs;
pub mod tasks;

use crate::runner::SceneStage;

/// Every per-scene stage, in the order `mesa run` runs them. The dataset-level stages
/// (`records`, then `report`) run after them, once.
pub fn pipeline_stages() -> Vec<Box<dyn SceneStage>> {
    vec![
        Box::new(lift::Lift),
        Box::new(retrieve::RetrieveStage::new()),
        Box::new(place::PlaceStage::new()),
        Box::new(graph::GraphStage::new()),
        Box::new(render::RenderStage::for_pipeline()),
        Box::new(tasks::TasksStage::new()),
    ]
}
