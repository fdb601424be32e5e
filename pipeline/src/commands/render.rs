//! `mesa render`: the runner adapter of [`mesa_stages::render`].
//!
//! Per scene, the layout of `[render] layout` (by default the most refined present:
//! `qa/layout.json`, else `refined/layout.json`; never a silent fall back to the coarse
//! layout) with its assets → `render/<view>.png` and `render/<view>_camera.json` for the five
//! scene views. Views are rendered in parallel, as scenes are.
//!
//! With `--assets`, the eight views around z of every library asset instead
//! (`assets/renders/<uid>/view_<azimuth>.png` and camera files), skipped while the asset's
//! GLB, front alignment and the `[render]` settings are unchanged (`views.json` records them).

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::Path;
use std::process::ExitCode;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use anyhow::anyhow;
use clap::Args as ClapArgs;
use mesa_schemas::artifacts::AssetIndexArtifact;
use mesa_schemas::json::to_sorted_pretty;
use mesa_schemas::DatasetLayout;
use mesa_stages::paths::dataset::{asset_glb, ASSET_RENDERS, IMPORT_SUMMARY, INDEX, LIBRARY};
use mesa_stages::paths::scene::RENDER_DIR;
use mesa_stages::render::{
    asset_view_name, load_render_asset, place_layout, render_asset_view, LayoutChoice, LayoutScene,
    RenderAsset, RenderConfig, SceneView, ASSET_VIEWS,
};
use rayon::prelude::*;

use crate::cli::{Global, LayoutArg, SceneArgs};
use crate::config::Config;
use crate::dataset_cache::DatasetCache;
use crate::exit::UsageError;
use crate::fsio::{
    read_bounded, read_json, read_text_bounded, sha256_hex, sweep_tmp_for, write_atomic, GLB_LIMIT,
    JSON_LIMIT,
};
use crate::layouts::read_dataset_layout;
use crate::progress::Tick;
use crate::runner::{
    digest_of, DatasetReport, DatasetStage, Executor, Scene, SceneOutput, SceneStage, StageContext,
};

/// `mesa render`.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// The runner flags.
    #[command(flatten)]
    pub stage: SceneArgs,
    /// The layout drawn (default: [render] layout of mesa.toml, "refined"). Never falls back
    /// to another: a scene without it fails.
    #[arg(long, value_enum)]
    pub layout: Option<LayoutArg>,
    /// Render the eight views around z of every library asset (assets/renders/<uid>/
    /// view_<azimuth>.png, for annotating assets and checking their front) instead of scenes.
    #[arg(long, conflicts_with_all = ["scenes", "shard", "layout"])]
    pub assets: bool,
    /// With --assets: only assets whose uid matches this glob.
    #[arg(long, value_name = "GLOB", requires = "assets")]
    pub uids: Option<String>,
}

/// Runs `mesa render`.
pub fn run(args: Args, global: Global) -> anyhow::Result<ExitCode> {
    let mut resolved = args.stage.resolve(global)?;
    if let Some(layout) = args.layout {
        resolved.config.render.layout = layout.into();
    }
    if args.assets {
        return resolved.run_dataset(&AssetViewsStage { uids: args.uids });
    }
    resolved.run(&RenderStage::new())
}

/// The files of a scene's render of `view`, relative to the scene folder: (picture, camera).
pub fn view_files(view: SceneView) -> (String, String) {
    (
        format!("{RENDER_DIR}/{}.png", view.name()),
        format!("{RENDER_DIR}/{}_camera.json", view.name()),
    )
}

/// The layouts of `choice` present in a scene, most refined first.
pub fn present_layouts(scene: &Scene, choice: LayoutChoice) -> Vec<&'static str> {
    choice
        .candidates()
        .iter()
        .copied()
        .filter(|rel| scene.path(rel).is_file())
        .collect()
}

/// The error of a scene without a layout of `choice`, with what to run.
pub fn no_layout(scene: &Scene, choice: LayoutChoice) -> anyhow::Error {
    let fix = match choice {
        LayoutChoice::Refined => {
            "run `mesa ingest` (and `mesa check --settle`) first; `--layout coarse` draws the \
             coarse layout instead"
        }
        LayoutChoice::Coarse => "run `mesa place` first",
        LayoutChoice::Truth => "only `mesa demo` scenes have one",
    };
    anyhow!(
        "{}: no layout to draw (expected {}: {fix})",
        scene.dir.display(),
        choice.candidates().join(" or ")
    )
}

/// Loaded assets shared by the scenes of a run, bounded by `[render] asset_cache_mb`.
#[derive(Default)]
pub struct AssetCache {
    inner: Mutex<CacheInner>,
}

#[derive(Default)]
struct CacheInner {
    assets: HashMap<String, (Arc<RenderAsset>, usize, u64)>,
    bytes: usize,
    tick: u64,
}

impl AssetCache {
    /// The asset `uid`, loaded by `load` unless cached. Assets least recently used are
    /// dropped beyond `budget_bytes`.
    pub fn get(
        &self,
        uid: &str,
        budget_bytes: usize,
        load: impl FnOnce() -> Result<RenderAsset, String>,
    ) -> Result<Arc<RenderAsset>, String> {
        {
            let mut inner = self.inner.lock().unwrap_or_else(|e| e.into_inner());
            inner.tick += 1;
            let tick = inner.tick;
            if let Some((asset, _, used)) = inner.assets.get_mut(uid) {
                *used = tick;
                return Ok(Arc::clone(asset));
            }
        }
        // Loaded outside the lock: two scenes may load the same asset at once, which only
        // costs time.
        let asset = Arc::new(load()?);
        let size = asset.heap_bytes();
        let mut inner = self.inner.lock().unwrap_or_else(|e| e.into_inner());
        if size <= budget_bytes && !inner.assets.contains_key(uid) {
            inner.tick += 1;
            let tick = inner.tick;
            inner.bytes += size;
            inner
                .assets
                .insert(uid.to_owned(), (Arc::clone(&asset), size, tick));
            while inner.bytes > budget_bytes {
                let Some(oldest) = inner
                    .assets
                    .iter()
                    .min_by_key(|(_, (_, _, used))| *used)
                    .map(|(k, _)| k.clone())
                else {
                    break;
                };
                if let Some((_, bytes, _)) = inner.assets.remove(&oldest) {
                    inner.bytes -= bytes;
                }
            }
        }
        Ok(asset)
    }
}

/// What rendering reads once per dataset and run.
struct Library {
    index: AssetIndexArtifact,
    /// Uids a release names but does not ship (`assets/import.json`'s `uids_missing_glb`,
    /// written by `mesa import`). Only these are left out of pictures; any other uid missing
    /// from the index is an error.
    unshipped: BTreeSet<String>,
}

/// The part of `assets/import.json` render reads.
#[derive(serde::Deserialize)]
struct ImportSummaryUids {
    #[serde(default)]
    uids_missing_glb: Vec<String>,
}

/// The `render` stage.
#[derive(Default)]
pub struct RenderStage {
    libraries: DatasetCache<Library>,
    cache: AssetCache,
    /// In `mesa run`: a scene whose refined layout has not come back from the annotator yet
    /// is waiting, not failed (see [`RenderStage::for_pipeline`]).
    waits_for_annotator: bool,
}

/// The warning of a scene still waiting for its refined layout.
pub const WAITING: &str = "waiting for the annotator: no qa/layout.json or refined/layout.json \
     yet, so nothing was rendered (run `mesa ingest` once the annotator's GLB is back; `mesa \
     render --layout coarse` draws the coarse layout)";

/// The `[render]` values that change pictures (the cache size does not).
fn fingerprint(config: &RenderConfig) -> String {
    let mut config = config.clone();
    config.asset_cache_mb = 0;
    digest_of(&config)
}

impl RenderStage {
    /// The stage of `mesa render`: a scene without the layout asked for fails.
    pub fn new() -> Self {
        Self::default()
    }

    /// The stage of `mesa run`: with `[render] layout = "refined"`, a scene that has neither
    /// `qa/layout.json` nor `refined/layout.json` is still with the annotator. It is done with
    /// a warning and no picture (never a picture of the coarse layout), and rendered by the
    /// first run after its refined layout appears (its inputs change then). Explicit choices
    /// (`coarse`, `truth`) still fail when their layout is missing.
    pub fn for_pipeline() -> Self {
        Self {
            waits_for_annotator: true,
            ..Self::default()
        }
    }

    /// Whether a scene is waiting for its refined layout (and this stage lets it wait).
    fn waits(&self, choice: LayoutChoice, scene: &Scene) -> bool {
        self.waits_for_annotator
            && choice == LayoutChoice::Refined
            && present_layouts(scene, choice).is_empty()
    }

    fn library(&self, dataset: &Path) -> anyhow::Result<Arc<Library>> {
        self.libraries.get_or_load(dataset, || {
            let index = read_json(&dataset.join(INDEX), "run `mesa assets` to write it")?;
            let summary = dataset.join(IMPORT_SUMMARY);
            let unshipped = if summary.is_file() {
                let uids: ImportSummaryUids = read_json(
                    &summary,
                    "written by `mesa import`; import again to rewrite it",
                )?;
                uids.uids_missing_glb.into_iter().collect()
            } else {
                BTreeSet::new()
            };
            Ok(Library { index, unshipped })
        })
    }

    /// The asset `uid`, read from the library with the index's front alignment.
    fn asset(
        &self,
        dataset: &Path,
        library: &Library,
        config: &RenderConfig,
        uid: &str,
    ) -> Result<Arc<RenderAsset>, String> {
        let record = library.index.assets.get(uid).ok_or_else(|| {
            format!(
                "not in the asset index (expected {LIBRARY}/{uid}.glb; run `mesa assets` after \
                 adding it)"
            )
        })?;
        if !record.valid {
            return Err(format!(
                "invalid in the asset index: {}",
                record.reason.as_deref().unwrap_or("no reason recorded")
            ));
        }
        let yaw = record.geometry.as_ref().map_or(0.0, |g| g.front_yaw_deg);
        let budget =
            usize::try_from(config.asset_cache_mb.saturating_mul(1 << 20)).unwrap_or(usize::MAX);
        self.cache.get(uid, budget, || {
            let path = dataset.join(asset_glb(uid));
            let bytes =
                read_bounded(&path, GLB_LIMIT).map_err(|e| format!("{}: {e}", path.display()))?;
            if sha256_hex(&bytes) != record.glb_sha256 {
                return Err(format!(
                    "{} changed since it was indexed (run `mesa assets` again)",
                    path.display()
                ));
            }
            load_render_asset(&bytes, yaw, config.max_texture_px)
                .map_err(|e| format!("{}: {e}", path.display()))
        })
    }

    /// Renders every scene view of a layout.
    pub fn render_layout(
        &self,
        dataset: &Path,
        config: &RenderConfig,
        layout: &DatasetLayout,
    ) -> anyhow::Result<(Vec<mesa_stages::render::RenderedView>, Vec<String>)> {
        let library = self.library(dataset)?;
        // Objects whose GLB a release could not ship (flagged by `mesa import`) are left out
        // of the pictures with a warning; the scene is drawn. Any other unknown uid fails.
        let (kept, absent): (Vec<_>, Vec<_>) = layout.objects.iter().partition(|o| {
            library.index.assets.contains_key(&o.retrieved_uid)
                || !library.unshipped.contains(&o.retrieved_uid)
                || dataset.join(asset_glb(&o.retrieved_uid)).exists()
        });
        let mut warnings = Vec::new();
        let trimmed;
        let layout = if absent.is_empty() {
            layout
        } else {
            warnings.push(format!(
                "not drawn: no GLB in {LIBRARY} for {}",
                absent
                    .iter()
                    .map(|o| format!("{} ({})", o.instance, o.retrieved_uid))
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
            let mut copy = layout.clone();
            copy.objects = kept.into_iter().cloned().collect();
            trimmed = copy;
            &trimmed
        };
        let mut assets: BTreeMap<String, Result<Arc<RenderAsset>, String>> = BTreeMap::new();
        for object in &layout.objects {
            if !object.retrieved_uid.is_empty() && !assets.contains_key(&object.retrieved_uid) {
                let asset = self.asset(dataset, &library, config, &object.retrieved_uid);
                assets.insert(object.retrieved_uid.clone(), asset);
            }
        }
        for (uid, asset) in &assets {
            if let Ok(asset) = asset {
                warnings.extend(asset.warnings.iter().map(|w| format!("asset {uid}: {w}")));
            }
        }
        let (placed, notes) = place_layout(layout, |uid| match assets.get(uid) {
            Some(Ok(asset)) => Ok(asset.as_ref()),
            Some(Err(reason)) => Err(reason.clone()),
            None => Err("not loaded".to_owned()),
        })?;
        warnings.extend(notes);
        let scene = LayoutScene::new(layout, &placed, config);
        let views: Vec<_> = SceneView::ALL
            .par_iter()
            .map(|view| scene.render_view(*view, config))
            .collect::<Result<_, _>>()?;
        Ok((views, warnings))
    }
}

impl SceneStage for RenderStage {
    fn name(&self) -> &'static str {
        "render"
    }

    fn inputs(&self, ctx: &StageContext<'_>, scene: &Scene) -> anyhow::Result<Vec<String>> {
        let choice = ctx.config.render.layout;
        if self.waits(choice, scene) {
            return Ok(Vec::new());
        }
        let layouts = present_layouts(scene, choice);
        let Some(first) = layouts.first() else {
            return Err(no_layout(scene, choice));
        };
        let mut inputs: Vec<String> = layouts.iter().map(|rel| scene.rel(rel)).collect();
        inputs.push(INDEX.to_owned());
        let (layout, _) = read_dataset_layout(&scene.path(first), "draw")?;
        let uids: std::collections::BTreeSet<&str> = layout
            .objects
            .iter()
            .map(|o| o.retrieved_uid.as_str())
            .filter(|u| !u.is_empty())
            .collect();
        // A missing GLB is left to `run`, which names the object and the uid (a failed scene
        // runs again next time, so the file is picked up once it is there).
        inputs.extend(
            uids.iter()
                .map(|uid| asset_glb(uid))
                .filter(|rel| ctx.dataset.join(rel).is_file()),
        );
        Ok(inputs)
    }

    fn config_digest(&self, ctx: &StageContext<'_>) -> String {
        fingerprint(&ctx.config.render)
    }

    fn waiting(&self, ctx: &StageContext<'_>, scene: &Scene) -> Option<String> {
        // Reported as waiting by the runner, as graph and tasks report it (the run fallback
        // above stays for callers that run the stage without the runner).
        self.waits(ctx.config.render.layout, scene).then(|| {
            crate::scene_docs::awaiting_annotation(scene).unwrap_or_else(|| WAITING.to_owned())
        })
    }

    fn run(&self, ctx: &StageContext<'_>, scene: &Scene) -> anyhow::Result<SceneOutput> {
        let config = &ctx.config.render;
        if self.waits(config.layout, scene) {
            let mut out = SceneOutput::new();
            out.warn(WAITING);
            return Ok(out);
        }
        let rel = *present_layouts(scene, config.layout)
            .first()
            .ok_or_else(|| no_layout(scene, config.layout))?;
        let path = scene.path(rel);
        let (layout, sha) = read_dataset_layout(&path, "draw")?;
        let (views, warnings) = self
            .render_layout(ctx.dataset, config, &layout)
            .map_err(|e| anyhow!("{}: {e:#}", path.display()))?;
        let mut out = SceneOutput::new();
        for mut view in views {
            view.camera.layout = Some(rel.to_owned());
            view.camera.layout_sha256 = Some(sha.clone());
            let hidden: Vec<&str> = view
                .camera
                .visible_px
                .iter()
                .filter(|(_, px)| **px == 0)
                .map(|(instance, _)| instance.as_str())
                .collect();
            if view.name == "front" && !hidden.is_empty() {
                out.warn(format!(
                    "hidden in the front view: {} (the multimodal model will not see them)",
                    hidden.join(", ")
                ));
            }
            out.add_file(format!("{RENDER_DIR}/{}.png", view.name), view.png);
            out.add_json(
                format!("{RENDER_DIR}/{}_camera.json", view.name),
                &view.camera,
            )?;
        }
        for warning in warnings {
            out.warn(warning);
        }
        Ok(out)
    }
}

// ---------------------------------------------------------------------------------------------
// Asset views

// The record is a mesa-schemas artifact so `mesa validate` knows it.
pub use mesa_schemas::artifacts::{AssetViewsRecord, ASSET_VIEWS_SCHEMA};

/// What a run of `mesa render --assets` did.
#[derive(Debug, Default, serde::Serialize)]
pub struct AssetViewsSummary {
    /// Assets selected.
    pub assets: usize,
    /// Assets rendered.
    pub rendered: usize,
    /// Assets whose views were current.
    pub skipped: usize,
    /// Assets that could not be rendered, with why.
    pub failed: Vec<(String, String)>,
    /// Selected assets left out because the index marks them invalid.
    pub invalid: usize,
    /// Wall time.
    pub elapsed_s: f64,
}

/// `mesa render --assets`: the eight views around z of every library asset, an asset a unit.
#[derive(Debug, Default)]
pub struct AssetViewsStage {
    /// Only uids matching this glob.
    pub uids: Option<String>,
}

impl DatasetStage for AssetViewsStage {
    fn name(&self) -> &'static str {
        "render"
    }

    fn run(&self, ctx: &StageContext<'_>, exec: &Executor<'_>) -> anyhow::Result<DatasetReport> {
        let summary = render_asset_views(ctx.dataset, ctx.config, self.uids.as_deref(), exec)?;
        Ok(DatasetReport {
            success: summary.failed.is_empty(),
            text: format_asset_views_summary(&summary),
            record: serde_json::to_value(&summary)?,
        })
    }
}

/// Renders the eight views around z of the library's assets.
pub fn render_asset_views(
    dataset: &Path,
    config: &Config,
    uids: Option<&str>,
    exec: &Executor<'_>,
) -> anyhow::Result<AssetViewsSummary> {
    let matcher = match uids {
        Some(glob) => Some(
            globset::Glob::new(glob)
                .map_err(|e| {
                    UsageError(format!(
                        "--uids \"{glob}\": {} (expected a glob like \"a3*\")",
                        e.kind()
                    ))
                })?
                .compile_matcher(),
        ),
        None => None,
    };
    render_asset_views_of(
        dataset,
        config,
        |uid| matcher.as_ref().is_none_or(|m| m.is_match(uid)),
        exec,
    )
}

/// Renders the eight views around z of the library's assets that `select` keeps (`mesa
/// annotate assets` renders the assets it annotates).
pub fn render_asset_views_of(
    dataset: &Path,
    config: &Config,
    select: impl Fn(&str) -> bool,
    exec: &Executor<'_>,
) -> anyhow::Result<AssetViewsSummary> {
    let started = Instant::now();
    let force = exec.options().force;
    let stage = RenderStage::new();
    let library = stage.library(dataset)?;
    let selected: Vec<&String> = library
        .index
        .assets
        .keys()
        .filter(|uid| select(uid.as_str()))
        .collect();
    // Invalid assets cannot be drawn; the index says why.
    let (uids, invalid): (Vec<&String>, Vec<&String>) = selected
        .into_iter()
        .partition(|uid| library.index.assets[*uid].valid);
    let render = &config.render;
    let digest = fingerprint(render);
    let outcomes: Vec<Result<bool, String>> = exec.map_ticked(
        "assets",
        &uids,
        |uid| render_one_asset(dataset, &stage, &library, render, &digest, uid, force),
        |outcome| match outcome {
            Ok(true) => Tick::Done,
            Ok(false) => Tick::Skipped,
            Err(_) => Tick::Failed,
        },
    );
    let mut summary = AssetViewsSummary {
        assets: uids.len(),
        invalid: invalid.len(),
        ..AssetViewsSummary::default()
    };
    for (uid, outcome) in uids.iter().zip(outcomes) {
        match outcome {
            Ok(true) => summary.rendered += 1,
            Ok(false) => summary.skipped += 1,
            Err(e) => summary.failed.push(((*uid).clone(), e)),
        }
    }
    summary.elapsed_s = started.elapsed().as_secs_f64();
    Ok(summary)
}

/// Renders one asset's views; `Ok(false)` when they were current.
fn render_one_asset(
    dataset: &Path,
    stage: &RenderStage,
    library: &Library,
    config: &RenderConfig,
    digest: &str,
    uid: &str,
    force: bool,
) -> Result<bool, String> {
    let record = library
        .index
        .assets
        .get(uid)
        .ok_or_else(|| format!("{uid}: not in the asset index"))?;
    let yaw = record.geometry.as_ref().map_or(0.0, |g| g.front_yaw_deg);
    let dir = dataset.join(ASSET_RENDERS).join(uid);
    let manifest_path = dir.join("views.json");
    let names: Vec<String> = (0..ASSET_VIEWS).map(asset_view_name).collect();
    let expected = AssetViewsRecord {
        schema: ASSET_VIEWS_SCHEMA.to_owned(),
        uid: uid.to_owned(),
        glb_sha256: record.glb_sha256.clone(),
        front_yaw_deg: yaw,
        config_digest: digest.to_owned(),
        views: names.clone(),
    };
    if !force {
        let current = read_text_bounded(&manifest_path, JSON_LIMIT)
            .ok()
            .and_then(|t| serde_json::from_str::<AssetViewsRecord>(&t).ok());
        let complete = names.iter().all(|n| {
            dir.join(format!("{n}.png")).is_file() && dir.join(format!("{n}_camera.json")).is_file()
        });
        if current.as_ref() == Some(&expected) && complete {
            return Ok(false);
        }
    }
    let asset = stage.asset(dataset, library, config, uid)?;
    let views: Vec<_> = (0..ASSET_VIEWS)
        .into_par_iter()
        .map(|k| render_asset_view(uid, &asset, k, config))
        .collect::<Result<_, _>>()
        .map_err(|e| format!("{uid}: {e}"))?;
    let write = |path: &Path, bytes: &[u8]| -> Result<(), String> {
        sweep_tmp_for(path)
            .and_then(|()| write_atomic(path, bytes))
            .map_err(|e| format!("{}: cannot write: {e}", path.display()))
    };
    for view in &views {
        write(&dir.join(format!("{}.png", view.name)), &view.png)?;
        let camera = to_sorted_pretty(&view.camera).map_err(|e| e.to_string())?;
        write(&dir.join(format!("{}_camera.json", view.name)), &camera)?;
    }
    let manifest = to_sorted_pretty(&expected).map_err(|e| e.to_string())?;
    write(&manifest_path, &manifest)?;
    Ok(true)
}

/// The human summary of `mesa render --assets`.
pub fn format_asset_views_summary(summary: &AssetViewsSummary) -> String {
    use std::fmt::Write as _;
    let mut out = format!(
        "render --assets: {} assets: {} rendered, {} current, {} failed in {:.2} s ({ASSET_RENDERS}/<uid>/)\n",
        summary.assets,
        summary.rendered,
        summary.skipped,
        summary.failed.len(),
        summary.elapsed_s
    );
    if summary.invalid > 0 {
        let _ = writeln!(
            out,
            "  {} invalid assets left out (their reasons are in {INDEX})",
            summary.invalid
        );
    }
    for (uid, error) in &summary.failed {
        let _ = writeln!(out, "  failed {uid}: {error}");
    }
    out
}
