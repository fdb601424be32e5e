//! What `mesa run` runs, in order: [`pipeline`].

use crate::config::Config;
use crate::runner::{DatasetStage, SceneStage};
use mesa_stages::demo::annotator::Annotator;

/// One step of `mesa run`.
pub enum Step {
    /// A per-scene stage.
    Scene(Box<dyn SceneStage>),
    /// A dataset-level stage (left out by shards: it covers the whole dataset).
    Dataset(Box<dyn DatasetStage>),
}

impl Step {
    /// The stage name.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Scene(stage) => stage.name(),
            Self::Dataset(stage) => stage.name(),
        }
    }
}

/// Every step of `mesa run`, in order: the asset index, the per-scene stages (the simulated
/// annotator between `pack` and `ingest` only when the configuration names it: `[annotate]
/// annotator = "simulated"`, as `mesa demo` writes), then `records` and `report` once, and
/// `release` into `DATASET/release/` when the scenes were imported (`mesa import`).
pub fn pipeline(config: &Config) -> Vec<Step> {
    let mut steps = vec![
        Step::Dataset(Box::new(super::assets::AssetsStage::default())),
        Step::Scene(Box::new(super::lift::Lift)),
        Step::Scene(Box::new(super::retrieve::RetrieveStage::new())),
        Step::Scene(Box::new(super::place::PlaceStage::new())),
        Step::Scene(Box::new(super::pack::PackStage::new())),
    ];
    if config.annotate.annotator == Annotator::Simulated {
        steps.push(Step::Scene(Box::new(super::demo::AnnotateStage)));
    }
    steps.extend([
        Step::Scene(Box::new(super::ingest::IngestStage::new())),
        Step::Scene(Box::new(super::check::CheckStage::new())),
        Step::Scene(Box::new(super::graph::GraphStage::new())),
        Step::Scene(Box::new(super::render::RenderStage::for_pipeline())),
        Step::Scene(Box::new(super::tasks::TasksStage::new())),
        Step::Dataset(Box::new(super::records::RecordsStage)),
        Step::Dataset(Box::new(super::report::ReportStage)),
        // Only on a dataset of imported scenes (`skipped_by_run` says why not otherwise).
        Step::Dataset(Box::new(super::release::ReleaseStage { out: None })),
    ]);
    steps
}

/// The per-scene stages of `mesa run`, in order (what `mesa status` counts).
pub fn scene_stages(config: &Config) -> Vec<Box<dyn SceneStage>> {
    pipeline(config)
        .into_iter()
        .filter_map(|step| match step {
            Step::Scene(stage) => Some(stage),
            Step::Dataset(_) => None,
        })
        .collect()
}
