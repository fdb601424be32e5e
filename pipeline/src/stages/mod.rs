//! The per-scene stages of `mesa run`, in pipeline order, as runner adapters over the pure
//! functions of `mesa-stages`, and the dataset-level `mesa assets` ([`assets`]), which `mesa
//! run` runs before them.

pub mod assets;
pub mod check;
pub mod graph;
pub mod lift;
pub mod place;
pub mod records;
pub mod retrieve;
pub mod scene_docs;
pub mod tasks;

use crate::runner::SceneStage;

/// Every per-scene stage, in the order `mesa run` runs them. The dataset-level stages
/// (`records`) run after them, once.
pub fn pipeline_stages() -> Vec<Box<dyn SceneStage>> {
    vec![
        Box::new(lift::Lift),
        Box::new(retrieve::RetrieveStage::new()),
        Box::new(place::PlaceStage::new()),
        // pack, the annotator and ingest come here once they exist.
        Box::new(check::CheckStage::new()),
        Box::new(graph::GraphStage::new()),
        Box::new(tasks::TasksStage::new()),
    ]
}
