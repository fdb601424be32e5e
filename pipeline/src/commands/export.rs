//! `mesa export`: the runner adapter of [`mesa_stages::export`]: a scene's layout (the one the
//! later stages read: settled, else refined; or `--layout`), the assets' convex parts
//! (`assets/index/`, the shapes `mesa check` uses) and their GLBs (triangles, materials and
//! base-colour images) → `sim/mjcf/scene.xml`, `sim/mjcf/meshes/`, `sim/urdf/`,
//! `sim/usd/scene.usda`, `sim/textures/` and the manifest `sim/export.json`. After the scenes,
//! one summary line over every exported scene.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::ExitCode;
use std::sync::{Arc, Mutex};

use anyhow::{anyhow, Context as _};
use clap::{Args as ClapArgs, ValueEnum};
use mesa_schemas::artifacts::{ExportArtifact, MassSource, UncheckedObject};
use mesa_stages::check::{AssetShape, Pose};
use mesa_stages::export::{export_scene, ExportObject, ExportRequest, VisualMesh};
use mesa_stages::paths::dataset::{ANNOTATIONS, ASSET_SIM, INDEX};
use mesa_stages::paths::scene::{
    COARSE_LAYOUT, EXPORT_MANIFEST, LAYOUT_CANDIDATES, REFINED_LAYOUT, SETTLED_LAYOUT,
};
use serde::Serialize;

use super::check::{read_indexed_glb, ShapeLibrary};
use crate::cli::{Global, SceneArgs};
use crate::dataset_cache::DatasetCache;
use crate::exit::UsageError;
use crate::fsio::{read_json, write_atomic};
use crate::layouts::{present_layouts, read_dataset_layout};
use crate::progress::Tick;
use crate::runner::{
    digest_of, discover_scenes, DatasetReport, DatasetStage, Executor, Scene, SceneOutput,
    SceneStage, StageContext,
};

/// `--layout` of `mesa export`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ExportLayoutArg {
    /// The layout the later stages read: qa/layout.json (settled), else refined/layout.json.
    Auto,
    /// qa/layout.json (written by `mesa check --settle`).
    Settled,
    /// refined/layout.json (written by `mesa ingest`).
    Refined,
    /// coarse/layout.json (written by `mesa place`; unsettled, for comparison).
    Coarse,
}

impl ExportLayoutArg {
    /// The file, when fixed.
    fn file(self) -> Option<&'static str> {
        match self {
            Self::Auto => None,
            Self::Settled => Some(SETTLED_LAYOUT),
            Self::Refined => Some(REFINED_LAYOUT),
            Self::Coarse => Some(COARSE_LAYOUT),
        }
    }
}

/// `mesa export`.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// The runner flags.
    #[command(flatten)]
    pub stage: SceneArgs,
    /// The layout to export (default: the one later stages read, settled else refined).
    #[arg(long, value_enum, default_value = "auto", conflicts_with = "assets")]
    pub layout: ExportLayoutArg,
    /// Export every valid library asset on its own instead of scenes: assets/sim/<uid>/
    /// (MJCF, URDF, USD and export.json; the object's bottom at z = 0, no table), for users
    /// who compose their own scenes. An asset whose files are current is skipped.
    #[arg(long)]
    pub assets: bool,
    /// The formats to write, comma-separated (default: `[export] formats`, all three).
    #[arg(long, value_enum, value_delimiter = ',')]
    pub format: Vec<FormatArg>,
}

/// `--format`.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum FormatArg {
    /// MuJoCo (sim/mjcf/).
    Mjcf,
    /// PyBullet, SAPIEN, Drake (sim/urdf/).
    Urdf,
    /// Isaac Sim (sim/usd/).
    Usd,
}

impl From<FormatArg> for mesa_stages::export::ExportFormat {
    fn from(f: FormatArg) -> Self {
        match f {
            FormatArg::Mjcf => Self::Mjcf,
            FormatArg::Urdf => Self::Urdf,
            FormatArg::Usd => Self::Usd,
        }
    }
}

/// Runs `mesa export`.
pub fn run(args: Args, global: Global) -> anyhow::Result<ExitCode> {
    let mut resolved = args.stage.resolve(global)?;
    if !args.format.is_empty() {
        let mut formats: Vec<mesa_stages::export::ExportFormat> =
            args.format.iter().map(|f| (*f).into()).collect();
        formats.sort();
        formats.dedup();
        resolved.config.export.formats = formats;
    }
    if args.assets {
        return resolved.run_dataset(&ExportAssetsStage);
    }
    resolved.run(&ExportStage::new(args.layout))
}

/// What the export reads once per dataset: the shapes library (index, annotations, parts) and
/// the visual meshes of the assets used so far.
struct ExportLibrary {
    shapes: ShapeLibrary,
    visuals: Mutex<BTreeMap<String, Arc<Result<VisualMesh, String>>>>,
}

impl ExportLibrary {
    fn load(dataset: &Path) -> anyhow::Result<Self> {
        Ok(Self {
            shapes: ShapeLibrary::load(dataset)?,
            visuals: Mutex::new(BTreeMap::new()),
        })
    }

    /// The visual mesh of an asset with its materials and textures, or why there is none.
    fn visual(&self, dataset: &Path, uid: &str) -> Arc<Result<VisualMesh, String>> {
        let cached = self.visuals.lock().ok().and_then(|c| c.get(uid).cloned());
        if let Some(hit) = cached {
            return hit;
        }
        let loaded = Arc::new(self.load_visual(dataset, uid));
        if let Ok(mut cache) = self.visuals.lock() {
            cache.insert(uid.to_owned(), loaded.clone());
        }
        loaded
    }

    fn load_visual(&self, dataset: &Path, uid: &str) -> Result<VisualMesh, String> {
        let record = self
            .shapes
            .record(uid)
            .ok_or_else(|| format!("asset {uid} is not in {INDEX} (run `mesa assets`)"))?;
        let (path, bytes, geometry) = read_indexed_glb(dataset, uid, record)?;
        let (mesh, surface) = mesa_stages::glb_read::read_glb_surface(&bytes)
            .map_err(|e| format!("{}: {e}", path.display()))?;
        Ok(VisualMesh::from_glb_surface(&mesh, &surface, geometry))
    }
}

/// The `export` stage.
pub struct ExportStage {
    layout: ExportLayoutArg,
    libraries: DatasetCache<ExportLibrary>,
}

impl ExportStage {
    /// A stage exporting `layout`, nothing loaded yet.
    pub fn new(layout: ExportLayoutArg) -> Self {
        Self {
            layout,
            libraries: DatasetCache::default(),
        }
    }

    fn library(&self, dataset: &Path) -> anyhow::Result<Arc<ExportLibrary>> {
        self.libraries
            .get_or_load(dataset, || ExportLibrary::load(dataset))
    }

    /// The layout file this scene exports, if present.
    fn layout_of(&self, scene: &Scene) -> Option<&'static str> {
        match self.layout.file() {
            Some(rel) => scene.path(rel).is_file().then_some(rel),
            None => present_layouts(scene).first().copied(),
        }
    }
}

/// What the export's outputs depend on besides the scene files.
#[derive(Serialize)]
struct Fingerprint<'a> {
    export: &'a mesa_stages::export::ExportConfig,
    layout: ExportLayoutArg,
    version: &'a str,
    writer_revision: u32,
}

fn no_layout(scene: &Scene, layout: ExportLayoutArg) -> anyhow::Error {
    let expected = match layout.file() {
        Some(rel) => rel.to_owned(),
        None => LAYOUT_CANDIDATES.join(" or "),
    };
    anyhow!(
        "{}: no layout to export (expected {expected}; `mesa check --settle` writes \
         qa/layout.json, `mesa ingest` refined/layout.json, `mesa place` coarse/layout.json)",
        scene.dir.display()
    )
}

impl SceneStage for ExportStage {
    fn name(&self) -> &'static str {
        "export"
    }

    fn inputs(&self, ctx: &StageContext<'_>, scene: &Scene) -> anyhow::Result<Vec<String>> {
        let mut inputs: Vec<String> = match self.layout.file() {
            Some(rel) => vec![scene.rel(rel)],
            // Every candidate present counts: a new qa/layout.json makes the export stale.
            None => present_layouts(scene)
                .iter()
                .map(|rel| scene.rel(rel))
                .collect(),
        };
        if inputs.is_empty() {
            return Err(no_layout(scene, self.layout));
        }
        // The index records each shapes file's and each GLB's digest.
        inputs.push(INDEX.to_owned());
        if ctx.dataset.join(ANNOTATIONS).exists() {
            inputs.push(ANNOTATIONS.to_owned());
        }
        Ok(inputs)
    }

    fn config_digest(&self, ctx: &StageContext<'_>) -> String {
        digest_of(&Fingerprint {
            export: &ctx.config.export,
            layout: self.layout,
            version: env!("CARGO_PKG_VERSION"),
            writer_revision: mesa_stages::export::WRITER_REVISION,
        })
    }

    fn waiting(&self, _ctx: &StageContext<'_>, scene: &Scene) -> Option<String> {
        if self.layout == ExportLayoutArg::Auto && present_layouts(scene).is_empty() {
            crate::scene_docs::awaiting_annotation(scene)
        } else {
            None
        }
    }

    fn preflight(&self, ctx: &StageContext<'_>) -> Result<(), UsageError> {
        check_export_config(ctx)
    }

    fn prepare(&self, ctx: &StageContext<'_>) {
        let _ = self.library(ctx.dataset);
    }

    fn finish(&self, ctx: &StageContext<'_>) -> anyhow::Result<Option<String>> {
        summary_line(ctx.dataset)
    }

    fn run(&self, ctx: &StageContext<'_>, scene: &Scene) -> anyhow::Result<SceneOutput> {
        let rel = self
            .layout_of(scene)
            .ok_or_else(|| no_layout(scene, self.layout))?;
        let path = scene.path(rel);
        let (layout, sha256) = read_dataset_layout(&path, "export")?;
        let library = self.library(ctx.dataset)?;
        let mut out = SceneOutput::new();
        let mut shapes: Vec<(usize, Arc<AssetShape>)> = Vec::new();
        let mut visuals: BTreeMap<String, Arc<Result<VisualMesh, String>>> = BTreeMap::new();
        let mut skipped = Vec::new();
        for (i, object) in layout.objects.iter().enumerate() {
            match library.shapes.shape_of(ctx.dataset, object) {
                Ok(shape) => {
                    let uid = &object.retrieved_uid;
                    if !visuals.contains_key(uid) {
                        visuals.insert(uid.clone(), library.visual(ctx.dataset, uid));
                    }
                    shapes.push((i, shape));
                }
                Err(reason) => skipped.push(UncheckedObject {
                    instance: object.instance.clone(),
                    reason,
                }),
            }
        }
        for (uid, visual) in &visuals {
            if let Err(reason) = visual.as_ref() {
                out.warn(format!("asset {uid}: no visual mesh: {reason}"));
            }
        }
        let objects: Vec<ExportObject<'_>> = shapes
            .iter()
            .map(|(i, shape)| {
                let object = &layout.objects[*i];
                let uid = object.retrieved_uid.as_str();
                ExportObject {
                    instance: &object.instance,
                    uid,
                    pose: Pose::of_object(object),
                    shape,
                    visual: visuals.get(uid).and_then(|v| v.as_ref().as_ref().ok()),
                    annotated_mass_kg: library
                        .shapes
                        .annotations()
                        .and_then(|a| a.get(uid))
                        .and_then(|a| a.mass_kg),
                }
            })
            .collect();
        if !skipped.is_empty() {
            let names: Vec<String> = skipped
                .iter()
                .map(|s| format!("{} ({})", s.instance, s.reason))
                .collect();
            out.warn(format!("{rel}: left out: {}", names.join(", ")));
        }
        let exported = export_scene(
            &ExportRequest {
                scene_id: &scene.scene_id,
                layout_file: rel,
                layout_sha256: &sha256,
                layout: &layout,
                objects,
                skipped,
                with_table: true,
            },
            &ctx.config.export,
        )?;
        for warning in &exported.manifest.warnings {
            out.warn(warning.clone());
        }
        for (file, bytes) in exported.files {
            out.add_file(file, bytes);
        }
        out.add_json(EXPORT_MANIFEST, &exported.manifest)?;
        Ok(out)
    }
}

/// One line over every scene's `sim/export.json` (none when no scene is exported).
fn summary_line(dataset: &Path) -> anyhow::Result<Option<String>> {
    let (mut scenes, mut objects, mut parts, mut annotated, mut skipped) = (0, 0, 0, 0, 0);
    let mut mass_kg = 0.0;
    for scene in discover_scenes(dataset)? {
        let path = scene.path(EXPORT_MANIFEST);
        if !path.is_file() {
            continue;
        }
        let manifest: ExportArtifact = read_json(&path, "rerun `mesa export`")?;
        scenes += 1;
        objects += manifest.objects.len();
        skipped += manifest.skipped.len();
        for o in &manifest.objects {
            parts += o.collision_parts;
            mass_kg += o.mass_kg;
            annotated += usize::from(o.mass_source == MassSource::Annotation);
        }
    }
    Ok((scenes > 0).then(|| {
        format!(
            "export summary: {scenes} scenes, {objects} objects ({annotated} with an annotated \
             mass, {} by density), {parts} convex colliders, {mass_kg:.2} kg in all, {skipped} \
             objects left out\n",
            objects - annotated
        )
    }))
}

// ---------------------------------------------------------------------------------------------
// Single assets

/// `mesa export --assets`: every valid library asset on its own, an asset a unit.
pub struct ExportAssetsStage;

impl DatasetStage for ExportAssetsStage {
    fn name(&self) -> &'static str {
        "export"
    }

    fn preflight(&self, ctx: &StageContext<'_>) -> Result<(), UsageError> {
        check_export_config(ctx)
    }

    fn run(&self, ctx: &StageContext<'_>, exec: &Executor<'_>) -> anyhow::Result<DatasetReport> {
        let started = std::time::Instant::now();
        let library = ExportLibrary::load(ctx.dataset)?;
        let uids: Vec<String> = library
            .shapes
            .uids()
            .filter(|uid| library.shapes.record(uid).is_some_and(|r| r.valid))
            .cloned()
            .collect();
        let force = exec.options().force;
        let outcomes = exec.map_ticked(
            "assets",
            &uids,
            |uid| export_asset(ctx, &library, uid, force).map_err(|e| format!("{e:#}")),
            |outcome| match outcome {
                Ok(true) => Tick::Done,
                Ok(false) => Tick::Skipped,
                Err(_) => Tick::Failed,
            },
        );
        let (mut written, mut current) = (0, 0);
        let mut failed = Vec::new();
        for (uid, outcome) in uids.iter().zip(outcomes) {
            match outcome {
                Ok(true) => written += 1,
                Ok(false) => current += 1,
                Err(e) => failed.push(format!("asset {uid}: {e}")),
            }
        }
        let mut text = format!(
            "export --assets: {} assets: {written} written, {current} current, {} failed in {:.2} s ({ASSET_SIM}/<uid>/)\n",
            uids.len(),
            failed.len(),
            started.elapsed().as_secs_f64()
        );
        for f in &failed {
            text.push_str(&format!("  failed {f}\n"));
        }
        Ok(DatasetReport {
            success: failed.is_empty(),
            text,
            record: serde_json::json!({
                "assets": uids.len(), "written": written, "current": current, "failed": failed
            }),
        })
    }
}

/// Exports one asset; `Ok(false)` when its files were current.
fn export_asset(
    ctx: &StageContext<'_>,
    library: &ExportLibrary,
    uid: &str,
    force: bool,
) -> anyhow::Result<bool> {
    let record = library
        .shapes
        .record(uid)
        .ok_or_else(|| anyhow!("not in {INDEX} (run `mesa assets`)"))?;
    let geometry = record
        .geometry
        .as_ref()
        .ok_or_else(|| anyhow!("no geometry in {INDEX} (run `mesa assets --force`)"))?;
    let mass_kg = library
        .shapes
        .annotations()
        .and_then(|a| a.get(uid))
        .and_then(|a| a.mass_kg);
    let inputs = digest_of(&(
        &record.glb_sha256,
        record.shapes.as_ref().map(|s| &s.sha256),
        mass_kg,
        &ctx.config.export,
        env!("CARGO_PKG_VERSION"),
        mesa_stages::export::WRITER_REVISION,
    ));
    let folder = ctx.dataset.join(ASSET_SIM).join(uid);
    let manifest_path = folder.join("export.json");
    if !force && manifest_path.is_file() {
        let current: Option<ExportArtifact> = read_json(&manifest_path, "").ok();
        if current.is_some_and(|m| m.layout_sha256 == inputs) {
            return Ok(false);
        }
    }
    let size_m = geometry.size_m;
    let layout: mesa_schemas::DatasetLayout = serde_json::from_value(serde_json::json!({
        "schema": "mesa.layout/1",
        "item_placement_zone": [0.0, 1.0, 0.0, 1.0],
        "objects": []
    }))?;
    let object = mesa_schemas::LayoutObject {
        retrieved_uid: uid.to_owned(),
        ..layout_object(uid, size_m)?
    };
    let shape = library
        .shapes
        .shape_of(ctx.dataset, &object)
        .map_err(|e| anyhow!("{e}"))?;
    let visual = library.visual(ctx.dataset, uid);
    let exported = export_scene(
        &ExportRequest {
            scene_id: uid,
            layout_file: "",
            layout_sha256: &inputs,
            layout: &layout,
            objects: vec![ExportObject {
                instance: uid,
                uid,
                pose: Pose::of_object(&object),
                shape: &shape,
                visual: visual.as_ref().as_ref().ok(),
                annotated_mass_kg: mass_kg,
            }],
            skipped: Vec::new(),
            with_table: false,
        },
        &ctx.config.export,
    )?;
    let mut manifest = exported.manifest;
    if let Err(reason) = visual.as_ref() {
        manifest.warnings.push(format!("no visual mesh: {reason}"));
    }
    let mut files: Vec<(String, Vec<u8>)> = exported
        .files
        .into_iter()
        .map(|(rel, bytes)| {
            let rel = rel.strip_prefix("sim/").unwrap_or(&rel).to_owned();
            (rel, bytes)
        })
        .collect();
    manifest.files = files.iter().map(|(rel, _)| rel.clone()).collect();
    for object in &mut manifest.objects {
        for texture in &mut object.textures {
            if let Some(rel) = texture.strip_prefix("sim/") {
                *texture = rel.to_owned();
            }
        }
    }
    manifest.files.push("export.json".to_owned());
    manifest.files.sort();
    // The manifest last: its digest marks the files complete.
    files.push((
        "export.json".to_owned(),
        mesa_schemas::json::to_sorted_pretty(&manifest)?,
    ));
    for (rel, bytes) in files {
        let path = folder.join(&rel);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent)
                .with_context(|| format!("{}: cannot create", parent.display()))?;
        }
        write_atomic(&path, &bytes).with_context(|| format!("{}: cannot write", path.display()))?;
    }
    Ok(true)
}

/// A layout object of an asset at its own size, bottom at z = 0, unturned.
fn layout_object(uid: &str, size_m: [f64; 3]) -> anyhow::Result<mesa_schemas::LayoutObject> {
    Ok(serde_json::from_value(serde_json::json!({
        "instance": "object",
        "category": "object",
        "description": uid,
        "retrieved_uid": uid,
        "position": [0.0, 0.0, 50.0 * size_m[2]],
        "rotation": [0.0, 0.0, 0.0, 1.0],
        "size": size_m.map(|v| v * 100.0),
        "scale_factor": [1.0, 1.0, 1.0]
    }))?)
}

/// The `[export]` settings' problems as one usage error (both export stages check them first).
fn check_export_config(ctx: &StageContext<'_>) -> Result<(), UsageError> {
    let problems = ctx.config.export.problems();
    if problems.is_empty() {
        Ok(())
    } else {
        Err(UsageError::new(format!(
            "mesa.toml: {} (fix the [export] section)",
            problems.join("; ")
        )))
    }
}
