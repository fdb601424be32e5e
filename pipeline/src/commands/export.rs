//! `mesa export`: the runner adapter of [`mesa_stages::export`]: a scene's layout (the one the
//! later stages read: settled, else refined; or `--layout`), the assets' convex parts
//! (`assets/index/`, the shapes `mesa check` uses) and their GLBs → `sim/mjcf/scene.xml`,
//! `sim/mjcf/meshes/*.obj` and the manifest `sim/export.json`. After the scenes, one summary
//! line over every exported scene.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::ExitCode;
use std::sync::{Arc, Mutex};

use anyhow::anyhow;
use clap::{Args as ClapArgs, ValueEnum};
use mesa_schemas::artifacts::{ExportArtifact, MassSource, UncheckedObject};
use mesa_stages::check::{AssetShape, Pose};
use mesa_stages::export::{export_scene, ExportObject, ExportRequest, VisualMesh};
use mesa_stages::glb_read::read_glb;
use mesa_stages::paths::dataset::{ANNOTATIONS, INDEX};
use mesa_stages::paths::scene::{
    COARSE_LAYOUT, EXPORT_MANIFEST, LAYOUT_CANDIDATES, REFINED_LAYOUT, SETTLED_LAYOUT,
};
use serde::Serialize;

use super::check::ShapeLibrary;
use crate::cli::{Global, SceneArgs};
use crate::dataset_cache::DatasetCache;
use crate::exit::UsageError;
use crate::fsio::{read_bounded, read_json, GLB_LIMIT};
use crate::layouts::{present_layouts, read_dataset_layout};
use crate::runner::{digest_of, discover_scenes, Scene, SceneOutput, SceneStage, StageContext};

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
    #[arg(long, value_enum, default_value = "auto")]
    pub layout: ExportLayoutArg,
}

/// Runs `mesa export`.
pub fn run(args: Args, global: Global) -> anyhow::Result<ExitCode> {
    let resolved = args.stage.resolve(global)?;
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

    /// The visual mesh of an asset, or why there is none.
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
        let geometry = record.geometry.as_ref().ok_or_else(|| {
            format!("asset {uid} has no geometry in {INDEX} (run `mesa assets --force`)")
        })?;
        let path = dataset.join(&record.file);
        let bytes = read_bounded(&path, GLB_LIMIT)
            .map_err(|e| format!("{}: cannot read: {e}", path.display()))?;
        let mesh = read_glb(&bytes).map_err(|e| format!("{}: {e}", path.display()))?;
        Ok(VisualMesh::from_glb(&mesh, geometry))
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
