//! The per-scene stages of `mesa run`, in pipeline order, as runner adapters over the pure
//! functions of `mesa-stages`, and the dataset-level `mesa assets` ([`assets`]), which `mesa
//! run` runs before them.

pub mod annotate;
pub mod assets;
pub mod check;
pub mod dataset_cache;
pub mod graph;
pub mod ingest;
pub mod lift;
pub mod pack;
pub mod place;
pub mod records;
pub mod release;
pub mod render;
pub mod report;
pub mod retrieve;
pub mod scene_docs;
pub mod tasks;

use crate::config::Config;
use crate::runner::SceneStage;
use mesa_stages::demo::annotator::Annotator;

/// Every per-scene stage, in the order `mesa run` runs them: the simulated annotator between
/// `pack` and `ingest` only when the configuration names it (`[annotate] annotator =
/// "simulated"`, as `mesa demo` writes). The dataset-level stages (`records`, then `report`)
/// run after them, once.
pub fn pipeline_stages(config: &Config) -> Vec<Box<dyn SceneStage>> {
    let mut stages: Vec<Box<dyn SceneStage>> = vec![
        Box::new(lift::Lift),
        Box::new(retrieve::RetrieveStage::new()),
        Box::new(place::PlaceStage::new()),
        Box::new(pack::PackStage::new()),
    ];
    if config.annotate.annotator == Annotator::Simulated {
        stages.push(Box::new(annotate::AnnotateStage));
    }
    stages.extend([
        Box::new(ingest::IngestStage::new()) as Box<dyn SceneStage>,
        Box::new(check::CheckStage::new()),
        Box::new(graph::GraphStage::new()),
        Box::new(render::RenderStage::for_pipeline()),
        Box::new(tasks::TasksStage::new()),
    ]);
    stages
}
