//! `mesa check`: the runner adapter of [`mesa_stages::check`]: a scene's layout
//! (`refined/layout.json`, or `coarse/layout.json` with `--layout coarse`) and the assets'
//! collision shapes (`assets/index/`) → `qa/check.json`, and with `--settle` the settled
//! layout `qa/layout.json` (which later stages read first). After the scenes, the dataset
//! summary `qa/summary.json`: collision rates over every checked scene, before and after
//! settling.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::ExitCode;
use std::sync::{Arc, Mutex};

use anyhow::Context as _;
use clap::{Args as ClapArgs, ValueEnum};
use mesa_schemas::artifacts::{
    AssetIndexArtifact, AssetRecord, CheckArtifact, CheckFindings, CheckSummaryArtifact,
    RateSummary, SettleReport, SettleStatus, SettleSummary, ShapesArtifact, SimulationReport,
    SimulationSummary, CHECK_SUMMARY_SCHEMA,
};
use mesa_schemas::LayoutObject;
use mesa_stages::annotations::Annotations;
use mesa_stages::check::solid::AssetMesh;
use mesa_stages::check::{check_layout, AssetShape, CheckedLayout, LayoutSource, SETTLED_LAYOUT};
use mesa_stages::export::VisualMesh;
use mesa_stages::glb_read::read_glb;
use mesa_stages::graph::{annotated_containers, GraphOptions, GraphScene};
use serde::Serialize;

use mesa_stages::paths::dataset::{ANNOTATIONS, CHECK_SUMMARY, INDEX};
use mesa_stages::paths::scene::CHECK;

use crate::cli::{Global, SceneArgs};
use crate::dataset_cache::DatasetCache;
use crate::fsio::{read_bounded, read_json, sha256_hex, sweep_tmp_for, write_atomic, GLB_LIMIT};
use crate::layouts::read_dataset_layout;
use crate::runner::{digest_of, discover_scenes, Scene, SceneOutput, SceneStage, StageContext};

/// `--layout` of `mesa check`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CheckLayoutArg {
    /// refined/layout.json (written by `mesa ingest` from the annotator's GLB).
    Refined,
    /// coarse/layout.json (written by `mesa place`).
    Coarse,
}

impl From<CheckLayoutArg> for LayoutSource {
    fn from(value: CheckLayoutArg) -> Self {
        match value {
            CheckLayoutArg::Refined => Self::Refined,
            CheckLayoutArg::Coarse => Self::Coarse,
        }
    }
}

/// `mesa check`.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// The runner flags.
    #[command(flatten)]
    pub stage: SceneArgs,
    /// The layout to check (default: [check] layout of mesa.toml, "refined").
    #[arg(long, value_enum)]
    pub layout: Option<CheckLayoutArg>,
    /// Also settle each scene: the least motion that removes collisions and floating, keeping
    /// what holds what; writes qa/layout.json (default: [check] settle of mesa.toml).
    #[arg(long)]
    pub settle: bool,
}

/// Runs `mesa check`.
pub fn run(args: Args, global: Global) -> anyhow::Result<ExitCode> {
    let mut resolved = args.stage.resolve(global)?;
    if let Some(layout) = args.layout {
        resolved.config.check.layout = layout.into();
    }
    if args.settle {
        resolved.config.check.settle = true;
    }
    resolved.run(&CheckStage::new())
}

/// What the check reads once per dataset and run: the asset index, the annotations, and the
/// shapes of the assets used so far (also what `mesa records` verifies collisions with).
pub struct ShapeLibrary {
    index: AssetIndexArtifact,
    annotations: Option<Annotations>,
    shapes: Mutex<BTreeMap<String, Result<Arc<AssetShape>, String>>>,
}

impl ShapeLibrary {
    /// Reads the asset index and the annotations of a dataset.
    pub fn load(dataset: &Path) -> anyhow::Result<Self> {
        let index = read_json(&dataset.join(INDEX), "run `mesa assets` to write it")?;
        let path = dataset.join(ANNOTATIONS);
        let annotations = if path.exists() {
            Some(Annotations::read(&path)?)
        } else {
            None
        };
        Ok(Self {
            index,
            annotations,
            shapes: Mutex::new(BTreeMap::new()),
        })
    }

    /// The dataset's asset annotations, if it has an annotations file.
    pub fn annotations(&self) -> Option<&Annotations> {
        self.annotations.as_ref()
    }

    /// The uids of the index, sorted.
    pub fn uids(&self) -> impl Iterator<Item = &String> {
        self.index.assets.keys()
    }

    /// The index's record of an asset.
    pub fn record(&self, uid: &str) -> Option<&mesa_schemas::artifacts::AssetRecord> {
        self.index.assets.get(uid)
    }

    /// The collision shape of an object's asset, or why there is none.
    pub fn shape_of(
        &self,
        dataset: &Path,
        object: &LayoutObject,
    ) -> Result<Arc<AssetShape>, String> {
        let uid = object.retrieved_uid.as_str();
        if uid.is_empty() {
            return Err("no retrieved_uid (run `mesa retrieve` and `mesa place`)".to_owned());
        }
        self.shape_of_uid(dataset, uid)
    }

    /// The collision shape of an asset, or why there is none.
    pub fn shape_of_uid(&self, dataset: &Path, uid: &str) -> Result<Arc<AssetShape>, String> {
        let mut cache = self
            .shapes
            .lock()
            .map_err(|_| "internal error: the shapes cache is poisoned".to_owned())?;
        cache
            .entry(uid.to_owned())
            .or_insert_with(|| self.load_shape(dataset, uid).map(Arc::new))
            .clone()
    }

    fn load_shape(&self, dataset: &Path, uid: &str) -> Result<AssetShape, String> {
        let record = self.index.assets.get(uid).ok_or_else(|| {
            format!(
                "asset {uid} is not in {INDEX} (put its GLB in the library and run `mesa assets`)"
            )
        })?;
        if !record.valid {
            return Err(format!(
                "asset {uid} is invalid: {}",
                record.reason.as_deref().unwrap_or("no reason recorded")
            ));
        }
        let (Some(shapes), Some(geometry)) = (&record.shapes, &record.geometry) else {
            return Err(format!(
                "asset {uid} has no collision shapes in {INDEX} (run `mesa assets --force`)"
            ));
        };
        let path = dataset.join(&shapes.file);
        let bytes = std::fs::read(&path)
            .map_err(|e| format!("{}: cannot read: {e} (run `mesa assets`)", path.display()))?;
        if sha256_hex(&bytes) != shapes.sha256 {
            return Err(format!(
                "{}: does not match its digest in {INDEX} (run `mesa assets`)",
                path.display()
            ));
        }
        let artifact: ShapesArtifact = serde_json::from_slice(&bytes)
            .map_err(|e| format!("{}: {e} (run `mesa assets --force`)", path.display()))?;
        let shape = AssetShape::new(uid, &artifact, geometry)
            .map_err(|e| format!("{}: {e}", path.display()))?;
        // The mesh is read only if an object of this asset is loose (its parts reach too far
        // at its scale) or collides.
        let (dataset, uid, record) = (dataset.to_owned(), uid.to_owned(), record.clone());
        Ok(shape.with_mesh_loader(move || {
            read_asset_mesh(&dataset, &uid, &record)
                .map(|m| AssetMesh::new(m.positions_m, m.triangles))
        }))
    }
}

/// An asset's triangle mesh in the frame of its index record (table-aligned, centred on its
/// box), read from its GLB, which must still be the one indexed.
pub fn read_asset_mesh(
    dataset: &Path,
    uid: &str,
    record: &AssetRecord,
) -> Result<VisualMesh, String> {
    let (path, bytes, geometry) = read_indexed_glb(dataset, uid, record)?;
    let mesh = read_glb(&bytes).map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(VisualMesh::from_glb(&mesh, geometry))
}

/// An asset's GLB (its path and bytes, which must still be those indexed) and the geometry its
/// index record measured.
pub fn read_indexed_glb<'r>(
    dataset: &Path,
    uid: &str,
    record: &'r AssetRecord,
) -> Result<
    (
        std::path::PathBuf,
        Vec<u8>,
        &'r mesa_schemas::artifacts::AssetGeometry,
    ),
    String,
> {
    let geometry = record.geometry.as_ref().ok_or_else(|| {
        format!("asset {uid} has no geometry in {INDEX} (run `mesa assets --force`)")
    })?;
    let path = dataset.join(&record.file);
    let bytes = read_bounded(&path, GLB_LIMIT)
        .map_err(|e| format!("{}: cannot read: {e}", path.display()))?;
    if sha256_hex(&bytes) != record.glb_sha256 {
        return Err(format!(
            "{}: not the file indexed in {INDEX} (run `mesa assets`)",
            path.display()
        ));
    }
    Ok((path, bytes, geometry))
}

/// The `check` stage.
#[derive(Default)]
pub struct CheckStage {
    libraries: DatasetCache<ShapeLibrary>,
}

impl CheckStage {
    /// A stage with nothing loaded yet.
    pub fn new() -> Self {
        Self::default()
    }

    fn library(&self, dataset: &Path) -> anyhow::Result<Arc<ShapeLibrary>> {
        self.libraries
            .get_or_load(dataset, || ShapeLibrary::load(dataset))
    }
}

/// What the check's outputs depend on besides the scene files.
#[derive(Serialize)]
struct Fingerprint<'a> {
    check: &'a mesa_stages::check::CheckConfig,
    graph: &'a mesa_stages::graph::GraphConfig,
    version: &'a str,
}

impl SceneStage for CheckStage {
    fn name(&self) -> &'static str {
        "check"
    }

    fn inputs(&self, ctx: &StageContext<'_>, scene: &Scene) -> anyhow::Result<Vec<String>> {
        let layout = ctx.config.check.layout.file();
        let mut inputs = Vec::new();
        // A scene waiting for its refined layout is done with nothing to check; the layout's
        // arrival changes this list, which makes the scene stale.
        if scene.path(layout).is_file() || ctx.config.check.layout == LayoutSource::Coarse {
            inputs.push(scene.rel(layout));
        }
        // The index records each shapes file's digest: a changed shape changes it.
        inputs.push(INDEX.to_owned());
        if ctx.dataset.join(ANNOTATIONS).exists() {
            inputs.push(ANNOTATIONS.to_owned());
        }
        Ok(inputs)
    }

    fn config_digest(&self, ctx: &StageContext<'_>) -> String {
        digest_of(&Fingerprint {
            check: &ctx.config.check,
            graph: &ctx.config.graph,
            version: env!("CARGO_PKG_VERSION"),
        })
    }

    /// A scene whose refined layout has not arrived waits for its annotator (unless the
    /// coarse layout is checked).
    fn waiting(&self, ctx: &StageContext<'_>, scene: &Scene) -> Option<String> {
        let layout = ctx.config.check.layout;
        if layout == LayoutSource::Refined && !scene.path(layout.file()).is_file() {
            crate::scene_docs::awaiting_annotation(scene)
        } else {
            None
        }
    }

    /// Loads the asset index, the annotations and the shapes cache once per run (a failure
    /// fails each scene with its reason).
    fn prepare(&self, ctx: &StageContext<'_>) {
        let _ = self.library(ctx.dataset);
    }

    /// The dataset summary `qa/summary.json` over every scene's `qa/check.json`.
    fn finish(&self, ctx: &StageContext<'_>) -> anyhow::Result<Option<String>> {
        write_summary(ctx.dataset)
    }

    fn run(&self, ctx: &StageContext<'_>, scene: &Scene) -> anyhow::Result<SceneOutput> {
        let config = &ctx.config.check;
        let rel = config.layout.file();
        let path = scene.path(rel);
        let mut out = SceneOutput::new();
        if !path.is_file() {
            out.warn(format!(
                "not checked: no {rel} yet (`mesa ingest` writes it from the annotator's GLB; \
                 `mesa check --layout coarse` checks the coarse layout)"
            ));
            return Ok(out);
        }
        let (layout, sha256) = read_dataset_layout(&path, "check")?;
        let library = self.library(ctx.dataset)?;
        let options = GraphOptions::from(&ctx.config.graph);
        let uids: Vec<String> = layout
            .objects
            .iter()
            .map(|o| o.retrieved_uid.clone())
            .collect();
        let containers = annotated_containers(
            &GraphScene::from_dataset(&layout),
            &uids,
            library.annotations.as_ref(),
            &options,
        );
        let checked = check_layout(
            CheckedLayout {
                scene_id: &scene.scene_id,
                file: rel,
                sha256: &sha256,
                layout: &layout,
            },
            |object| library.shape_of(ctx.dataset, object),
            &containers.flags,
            &options,
            config,
            config.settle,
        );
        for warning in checked.warnings {
            out.warn(warning);
        }
        if let Some(report) = &checked.artifact.settle {
            if report.status == SettleStatus::Unsettled {
                out.warn(format!(
                    "unsettled: {}",
                    report.reason.as_deref().unwrap_or("no reason recorded")
                ));
            }
        }
        out.add_json(CHECK, &checked.artifact)?;
        if let Some(settled) = &checked.settled {
            out.add_json(SETTLED_LAYOUT, settled)?;
        }
        Ok(out)
    }
}

fn rates<'a>(findings: impl Iterator<Item = &'a CheckFindings>) -> RateSummary {
    let mut summary = RateSummary {
        scenes: 0,
        pairs_total: 0,
        colliding_pairs: 0,
        collision_rate: 0.0,
        mean_scene_collision_rate: 0.0,
        scenes_with_collisions: 0,
        floating_objects: 0,
        scenes_with_floating: 0,
        zone_violations: 0,
        clean_scenes: 0,
        mesatask_rule_pairs: 0,
        mesatask_rule_rate: 0.0,
    };
    let mut rate_sum = 0.0;
    for f in findings {
        summary.scenes += 1;
        summary.pairs_total += f.pairs_total;
        summary.colliding_pairs += f.collisions.len() as u64;
        rate_sum += f.collision_rate;
        summary.scenes_with_collisions += u64::from(!f.collisions.is_empty());
        summary.floating_objects += f.floating.len() as u64;
        summary.scenes_with_floating += u64::from(!f.floating.is_empty());
        summary.zone_violations += f.zone_violations.len() as u64;
        summary.clean_scenes += u64::from(f.clean);
        summary.mesatask_rule_pairs += f.mesatask_rule_pairs;
    }
    if summary.pairs_total > 0 {
        summary.collision_rate = summary.colliding_pairs as f64 / summary.pairs_total as f64;
        summary.mesatask_rule_rate =
            summary.mesatask_rule_pairs as f64 / summary.pairs_total as f64;
    }
    if summary.scenes > 0 {
        summary.mean_scene_collision_rate = rate_sum / summary.scenes as f64;
    }
    summary
}

fn findings_of(check: &CheckArtifact) -> CheckFindings {
    CheckFindings {
        collisions: check.collisions.clone(),
        floating: check.floating.clone(),
        zone_violations: check.zone_violations.clone(),
        pairs_total: check.pairs_total,
        collision_rate: check.collision_rate,
        mesatask_rule_pairs: check.mesatask_rule_pairs,
        clean: check.clean,
    }
}

/// The dataset summary over every scene's `qa/check.json`.
pub fn summarize(dataset: &Path) -> anyhow::Result<CheckSummaryArtifact> {
    let mut checks = Vec::new();
    for scene in discover_scenes(dataset)? {
        let path = scene.path(CHECK);
        if path.is_file() {
            let check: CheckArtifact = read_json(&path, "rerun `mesa check`")?;
            checks.push(check);
        }
    }
    let mut layouts = BTreeMap::new();
    for check in &checks {
        *layouts.entry(check.layout.clone()).or_default() += 1;
    }
    let before: Vec<CheckFindings> = checks.iter().map(findings_of).collect();
    let tried = checks.iter().any(|c| c.settle.is_some());
    let after: Vec<CheckFindings> = checks
        .iter()
        .zip(&before)
        .map(|(check, before)| match &check.settle {
            Some(report) if report.status == SettleStatus::Settled => report.after.clone(),
            _ => before.clone(),
        })
        .collect();
    let settle = tried.then(|| {
        let mut distances: Vec<f64> = Vec::new();
        let (mut settled, mut unsettled) = (0, 0);
        for report in checks.iter().filter_map(|c| c.settle.as_ref()) {
            if report.status == SettleStatus::Settled {
                settled += 1;
                distances.extend(report.displacements.iter().map(|d| d.distance_cm));
            } else {
                unsettled += 1;
            }
        }
        distances.sort_by(f64::total_cmp);
        let n = distances.len();
        let median_of = |sorted: &[f64]| match sorted.len() {
            0 => 0.0,
            n if n % 2 == 1 => sorted[n / 2],
            n => 0.5 * (sorted[n / 2 - 1] + sorted[n / 2]),
        };
        let median = median_of(&distances);
        let moved: Vec<f64> = distances.iter().copied().filter(|d| *d > 0.0).collect();
        SettleSummary {
            settled,
            unsettled,
            objects: n as u64,
            median_displacement_cm: median,
            mean_displacement_cm: if n > 0 {
                distances.iter().sum::<f64>() / n as f64
            } else {
                0.0
            },
            max_displacement_cm: distances.last().copied().unwrap_or(0.0),
            moved_objects: moved.len() as u64,
            median_moved_displacement_cm: median_of(&moved),
            simulation: simulation_summary(checks.iter().filter_map(|c| c.settle.as_ref())),
        }
    });
    Ok(CheckSummaryArtifact {
        schema: CHECK_SUMMARY_SCHEMA.to_owned(),
        scenes: checks.len() as u64,
        layouts,
        before: rates(before.iter()),
        after: tried.then(|| rates(after.iter())),
        settle,
    })
}

/// Writes `qa/summary.json` and returns its lines for the terminal (none when no scene has
/// been checked).
pub fn write_summary(dataset: &Path) -> anyhow::Result<Option<String>> {
    let summary = summarize(dataset)?;
    let path = dataset.join(CHECK_SUMMARY);
    let bytes = mesa_schemas::json::to_sorted_pretty(&summary)
        .with_context(|| format!("serialising {CHECK_SUMMARY}"))?;
    sweep_tmp_for(&path).with_context(|| format!("{}: sweeping", path.display()))?;
    write_atomic(&path, &bytes).with_context(|| format!("{}: cannot write", path.display()))?;
    Ok((summary.scenes > 0).then(|| format_summary(&summary, &path)))
}

fn format_rates(name: &str, r: &RateSummary) -> String {
    format!(
        "  {name}: collision rate {:.2}% ({} of {} pairs; MesaTask's 5 cm rule: {:.2}%), {} \
         floating objects, {} zone violations, {} of {} scenes clean\n",
        100.0 * r.collision_rate,
        r.colliding_pairs,
        r.pairs_total,
        100.0 * r.mesatask_rule_rate,
        r.floating_objects,
        r.zone_violations,
        r.clean_scenes,
        r.scenes
    )
}

/// The human lines of a summary.
pub fn format_summary(summary: &CheckSummaryArtifact, path: &Path) -> String {
    let mut out = format!(
        "check summary over {} scenes (written to {}):\n",
        summary.scenes,
        path.display()
    );
    out.push_str(&format_rates("as checked", &summary.before));
    if let Some(after) = &summary.after {
        out.push_str(&format_rates("after settling", after));
    }
    if let Some(s) = &summary.settle {
        out.push_str(&format!(
            "  settling: {} settled, {} unsettled; displacement median {:.2} cm, mean {:.2} cm, \
             max {:.2} cm over {} objects; {} moved, by {:.2} cm on median\n",
            s.settled,
            s.unsettled,
            s.median_displacement_cm,
            s.mean_displacement_cm,
            s.max_displacement_cm,
            s.objects,
            s.moved_objects,
            s.median_moved_displacement_cm
        ));
        if let Some(sim) = &s.simulation {
            out.push_str(&format!(
                "  simulation (rapier3d): {} scenes, {} objects moved by it (up to {:.2} cm), {} \
                 still moving, {} fell; up to {:.1} s simulated\n",
                sim.scenes,
                sim.objects_moved,
                sim.max_motion_cm,
                sim.still_moving,
                sim.fell,
                sim.max_simulated_s
            ));
        }
    }
    out
}

/// The simulation's figures over the settle reports that ran it (`None` when none did).
fn simulation_summary<'a>(
    reports: impl Iterator<Item = &'a SettleReport>,
) -> Option<SimulationSummary> {
    let runs: Vec<&SimulationReport> = reports.filter_map(|r| r.simulation.as_ref()).collect();
    (!runs.is_empty()).then(|| SimulationSummary {
        scenes: runs.len() as u64,
        objects_moved: runs.iter().map(|r| r.objects_moved).sum(),
        max_motion_cm: runs.iter().map(|r| r.max_motion_cm).fold(0.0, f64::max),
        still_moving: runs.iter().map(|r| r.still_moving.len() as u64).sum(),
        fell: runs.iter().map(|r| r.fell.len() as u64).sum(),
        max_simulated_s: runs.iter().map(|r| r.simulated_s).fold(0.0, f64::max),
    })
}
