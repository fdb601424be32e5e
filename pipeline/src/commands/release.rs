//! `mesa release DATASET OUT`: the MesaTask-10K tree, on demand (`mesa run` writes it to
//! `DATASET/release/` only for a dataset of imported scenes).
//!
//! Per scene, the layout of `[render] layout` (by default the most refined present:
//! `qa/layout.json`, else `refined/layout.json`) becomes
//! `OUT/Layout_info/<table_type>/<scene_id>/layout.json` ([`mesa_stages::release`]) beside a
//! copy of `render/front.png`, which must have been drawn from that very layout (its camera
//! file records the layout's digest; an imported scene whose layout is still the imported one
//! may use the release's own `imported/front.png`); `OUT/Asset_annotation.json` holds the
//! annotations of every asset the released layouts use and of every other asset of
//! `assets/annotations.json` (the library's and those a release could not ship), without the
//! `description_source` field `mesa import` adds; `OUT/sbert_text_features.pkl` (pickle protocol 4,
//! what MesaTask's `compress_pickle.load` reads) when the dataset has
//! `assets/text_features.npy`. Every file written is validated (the `layout` and
//! `asset-annotations` kinds of `mesa validate`). A scene that cannot be released is reported
//! and left out; the others are written.
//!
//! `OUT/Assets_library/` holds `<uid>.glb` for every asset the released layouts use that the
//! library has, as `[release] assets` (or `--assets`) says: by default hard-linked when
//! MesaTask's reconstruction places the file right as it is, else written flattened (node
//! transforms baked into the vertices: [`mesa_stages::release::flat_asset_glb`]); a hard link
//! that the file system refuses (another device) becomes a copy, counted as such. Beside them
//! the table and sink GLBs MesaTask's `config.yaml` names. Uids whose GLB the library lacks
//! (assets a release could not ship) are counted and named in the summary.
//!
//! OUT must be new, empty, or an earlier release (nothing but `Layout_info/`,
//! `Assets_library/`, `Asset_annotation.json` and `sbert_text_features.pkl`), which is
//! replaced.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{anyhow, bail, Context as _};
use mesa_schemas::json::parse_lenient;
use mesa_schemas::render::RenderCameraArtifact;
use mesa_schemas::Kind;
use mesa_stages::release::{release_annotations, release_layout};

use clap::Args as ClapArgs;
use mesa_stages::paths::dataset::{asset_glb, ANNOTATIONS, SCENES, TEXT_FEATURES, TEXT_UIDS};
use mesa_stages::paths::scene::{IMPORT_FRONT, IMPORT_NOTES, RENDER_DIR};
use mesa_stages::release::{
    flat_asset_glb, placed_right_by_mesatask, plain_uid, zone_box_glb, ReleaseAssets, SINK_GLB_UID,
    TABLE_GLB_UID,
};
use serde::Serialize;

use super::render::{no_layout, present_layouts};
use crate::cli::{DatasetArgs, Global, LayoutArg};
use crate::config::Config;
use crate::exit::UsageError;
use crate::fsio::{
    read_bounded, read_text_bounded, sweep_tmp_for, write_atomic, GLB_LIMIT, IMAGE_LIMIT,
    JSON_LIMIT,
};
use crate::layouts::read_dataset_layout;
use crate::runner::{
    discover_scenes, select_scenes, DatasetReport, DatasetStage, Executor, RunError, Scene, Shard,
    StageContext,
};

/// `mesa release`.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// The dataset and its run flags.
    #[command(flatten)]
    pub common: DatasetArgs,
    /// The folder to write the tree into (new or empty, or an earlier release of this dataset,
    /// which is replaced).
    pub out: PathBuf,
    /// The layout released (default: "refined": qa/layout.json, else refined/layout.json).
    #[arg(long, value_enum)]
    pub layout: Option<LayoutArg>,
    /// Only scenes whose "<table_type>/<scene_id>" or "<scene_id>" matches this glob.
    #[arg(long, value_name = "GLOB")]
    pub scenes: Option<String>,
    /// How Assets_library/ is written (default: `[release] assets`, "auto": hard-link the GLBs
    /// MesaTask places right as they are, flatten the others).
    #[arg(long, value_enum)]
    pub assets: Option<AssetsArg>,
}

/// `--assets`.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum AssetsArg {
    /// Hard-link the GLBs MesaTask's reconstruction places right; flatten the others.
    Auto,
    /// Flatten every GLB (node transforms baked into the vertices).
    Bake,
    /// Hard-link every GLB as it is.
    Link,
    /// No Assets_library/.
    None,
}

impl From<AssetsArg> for ReleaseAssets {
    fn from(value: AssetsArg) -> Self {
        match value {
            AssetsArg::Auto => Self::Auto,
            AssetsArg::Bake => Self::Bake,
            AssetsArg::Link => Self::Link,
            AssetsArg::None => Self::None,
        }
    }
}

/// Runs `mesa release`.
pub fn run(args: Args, global: Global) -> anyhow::Result<ExitCode> {
    let mut resolved = args.common.resolve(global)?;
    resolved.options.scenes = args.scenes;
    if let Some(layout) = args.layout {
        resolved.config.render.layout = layout.into();
    }
    if let Some(assets) = args.assets {
        resolved.config.release.assets = assets.into();
    }
    resolved.run_dataset(&ReleaseStage {
        out: Some(args.out),
    })
}

/// The `release` stage: the MesaTask-10K tree into `out`.
#[derive(Debug)]
pub struct ReleaseStage {
    /// The folder written; `None`: `DATASET/release` ([`IMPORTED_RELEASE_DIR`]), which
    /// `mesa run` writes on a dataset of imported scenes.
    pub out: Option<PathBuf>,
}

/// Where `mesa run` writes the release of a dataset with imported scenes.
pub const IMPORTED_RELEASE_DIR: &str = "release";

impl DatasetStage for ReleaseStage {
    fn name(&self) -> &'static str {
        "release"
    }

    /// `mesa run` releases a dataset of imported scenes (their tree goes back out with what
    /// mesa added); any other dataset is released on demand.
    fn skipped_by_run(&self, ctx: &StageContext<'_>) -> Option<String> {
        let imported = discover_scenes(ctx.dataset)
            .map(|scenes| scenes.iter().any(Scene::imported))
            .unwrap_or(false);
        (!imported).then(|| {
            format!(
                "on demand (`mesa release {} OUT`; `mesa run` writes {IMPORTED_RELEASE_DIR}/ only \
                 for imported scenes)",
                ctx.dataset.display()
            )
        })
    }

    fn run(&self, ctx: &StageContext<'_>, exec: &Executor<'_>) -> anyhow::Result<DatasetReport> {
        let out = self
            .out
            .clone()
            .unwrap_or_else(|| ctx.dataset.join(IMPORTED_RELEASE_DIR));
        let summary = write_release(ctx.dataset, &out, ctx.config, exec)?;
        Ok(DatasetReport {
            success: summary.failed.is_empty(),
            text: format_release_summary(&summary),
            record: serde_json::to_value(&summary)?,
        })
    }
}

/// The folder of layouts in a release.
pub const LAYOUT_INFO: &str = "Layout_info";
/// The annotation file of a release.
pub const ASSET_ANNOTATION: &str = "Asset_annotation.json";
/// The text features of a release (MesaTask's retrieval loads it with `compress_pickle`).
pub const TEXT_FEATURES_PKL: &str = "sbert_text_features.pkl";
/// The asset GLBs of a release.
pub const ASSETS_LIBRARY: &str = "Assets_library";

/// What a release run wrote.
#[derive(Debug, Serialize)]
pub struct ReleaseSummary {
    /// The release folder.
    pub out: PathBuf,
    /// Scenes selected.
    pub scenes: usize,
    /// Scenes released.
    pub released: usize,
    /// Assets annotated (those the layouts use and every other annotated asset).
    pub assets: usize,
    /// Rows of `sbert_text_features.pkl` (0: the dataset has no text features).
    pub text_features: usize,
    /// `Assets_library/` GLBs hard-linked to the dataset's library.
    pub assets_linked: usize,
    /// `Assets_library/` GLBs written flattened.
    pub assets_flattened: usize,
    /// `Assets_library/` GLBs copied because a hard link was refused (another file system).
    pub assets_copied: usize,
    /// Uids the released layouts use whose GLB the dataset's library does not have.
    pub assets_missing: Vec<String>,
    /// What could not be released, with why (`<table_type>/<scene_id>`, or the annotation
    /// file).
    pub failed: Vec<(String, String)>,
    /// Wall time.
    pub elapsed_s: f64,
}

/// Checks OUT and clears an earlier release in it.
fn prepare_out(out: &Path) -> anyhow::Result<()> {
    if out.exists() && !out.is_dir() {
        return Err(UsageError(format!(
            "{}: not a folder (expected a new or empty folder, or an earlier release)",
            out.display()
        ))
        .into());
    }
    if out.is_dir() {
        let mut others = Vec::new();
        for entry in std::fs::read_dir(out).with_context(|| format!("{}", out.display()))? {
            let name = entry?.file_name().to_string_lossy().into_owned();
            if ![
                LAYOUT_INFO,
                ASSETS_LIBRARY,
                ASSET_ANNOTATION,
                TEXT_FEATURES_PKL,
            ]
            .contains(&name.as_str())
            {
                others.push(name);
            }
        }
        if !others.is_empty() {
            others.sort();
            return Err(UsageError(format!(
                "{}: not empty and not an earlier release (it holds {}): give a new or empty \
                 folder",
                out.display(),
                others.join(", ")
            ))
            .into());
        }
        for folder in [LAYOUT_INFO, ASSETS_LIBRARY] {
            let folder = out.join(folder);
            if folder.is_dir() {
                std::fs::remove_dir_all(&folder).with_context(|| {
                    format!("{}: cannot remove the earlier release", folder.display())
                })?;
            }
        }
        for file in [ASSET_ANNOTATION, TEXT_FEATURES_PKL] {
            let path = out.join(file);
            if path.exists() {
                std::fs::remove_file(&path)
                    .with_context(|| format!("{}: cannot remove", path.display()))?;
            }
        }
    }
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create", out.display()))
}

fn write(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    sweep_tmp_for(path).with_context(|| format!("{}: sweeping", path.display()))?;
    write_atomic(path, bytes).with_context(|| format!("{}: cannot write", path.display()))
}

/// Problems of a file against a kind, each on a line.
fn validate(path: &Path, bytes: &[u8], kind: &str) -> anyhow::Result<()> {
    let kind = Kind::by_name(kind).ok_or_else(|| anyhow!("internal error: no kind {kind}"))?;
    let text = std::str::from_utf8(bytes).map_err(|_| anyhow!("{}: not UTF-8", path.display()))?;
    let value = parse_lenient(text).map_err(|e| anyhow!("{}: {e}", path.display()))?;
    let problems = kind.validate_value(&value);
    if !problems.is_empty() {
        let lines: Vec<String> = problems
            .iter()
            .map(|p| format!("{}: {p}", path.display()))
            .collect();
        bail!("{}", lines.join("\n"));
    }
    Ok(())
}

/// Releases one scene: its layout and front view. Returns the uids it uses.
fn release_scene(config: &Config, scene: &Scene, out: &Path) -> anyhow::Result<BTreeSet<String>> {
    let choice = config.render.layout;
    let rel = *present_layouts(scene, choice)
        .first()
        .ok_or_else(|| no_layout(scene, choice))?;
    let path = scene.path(rel);
    let (layout, sha) = read_dataset_layout(&path, "draw")?;
    let bytes = release_layout(&layout).map_err(|e| anyhow!("{}: {e}", path.display()))?;
    let camera_path = scene.path(&format!("{RENDER_DIR}/front_camera.json"));
    let png_path = scene.path(&format!("{RENDER_DIR}/front.png"));
    // An imported scene whose layout is still the one imported has the release's picture of
    // it (used when no render of that layout exists).
    let imported_front = imported_front(scene, &sha);
    let png = match (
        front_render(&camera_path, &png_path, &sha, rel, choice),
        imported_front,
    ) {
        (Ok(png), _) => png,
        (Err(_), Some(png)) => png,
        (Err(e), None) => return Err(e),
    };
    let dir = out
        .join(LAYOUT_INFO)
        .join(&scene.table_type)
        .join(&scene.scene_id);
    let layout_out = dir.join("layout.json");
    validate(&layout_out, &bytes, "layout")?;
    write(&layout_out, &bytes)?;
    write(&dir.join("front.png"), &png)?;
    Ok(layout
        .objects
        .iter()
        .map(|o| o.retrieved_uid.clone())
        .collect())
}

/// `imported/front.png` when the scene was imported and its layout (digest `sha`) is the one
/// the import wrote.
fn imported_front(scene: &Scene, sha: &str) -> Option<Vec<u8>> {
    let text = read_text_bounded(&scene.path(IMPORT_NOTES), JSON_LIMIT).ok()?;
    let notes: mesa_stages::import_mesatask::ImportNotes = serde_json::from_str(&text).ok()?;
    if notes.layout_sha256 != sha || !notes.front_png {
        return None;
    }
    read_bounded(&scene.path(IMPORT_FRONT), IMAGE_LIMIT).ok()
}

/// `render/front.png` when its camera file says it was drawn from the layout of digest `sha`.
fn front_render(
    camera_path: &Path,
    png_path: &Path,
    sha: &str,
    rel: &str,
    choice: mesa_stages::render::LayoutChoice,
) -> anyhow::Result<Vec<u8>> {
    let camera_text = match read_text_bounded(camera_path, JSON_LIMIT) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => bail!(
            "{}: no front view (run `mesa render` first)",
            camera_path.display()
        ),
        Err(e) => bail!("{}: cannot read: {e}", camera_path.display()),
    };
    let camera: RenderCameraArtifact = serde_json::from_str(&camera_text).map_err(|e| {
        anyhow!(
            "{}: not a render camera file: {e} (run `mesa render --force` to draw it again)",
            camera_path.display()
        )
    })?;
    if camera.layout_sha256.as_deref() != Some(sha) {
        bail!(
            "{}: drawn from {} as it was before, not from the released {rel} (run `mesa render` \
             again{})",
            png_path.display(),
            camera.layout.as_deref().unwrap_or("another layout"),
            if choice == mesa_stages::render::LayoutChoice::Refined {
                ""
            } else {
                " with the same --layout"
            }
        );
    }
    read_bounded(png_path, IMAGE_LIMIT).with_context(|| {
        format!(
            "{}: cannot read (run `mesa render` first)",
            png_path.display()
        )
    })
}

/// `sbert_text_features.pkl` from `assets/text_features.npy` and `assets/text_uids.json`;
/// `None` when the dataset has no features.
fn features_pickle(dataset: &Path) -> anyhow::Result<Option<(Vec<u8>, usize)>> {
    let npy_path = dataset.join(TEXT_FEATURES);
    let uids_path = dataset.join(TEXT_UIDS);
    if !npy_path.is_file() {
        return Ok(None);
    }
    let uids_text = read_text_bounded(&uids_path, JSON_LIMIT).map_err(|e| {
        anyhow!(
            "{}: {e} (the uid of each row of {TEXT_FEATURES})",
            uids_path.display()
        )
    })?;
    let value = parse_lenient(&uids_text).map_err(|e| anyhow!("{}: {e}", uids_path.display()))?;
    let list = value.get("uids").unwrap_or(&value).clone();
    let uids: Vec<String> = serde_json::from_value(list).map_err(|_| {
        anyhow!(
            "{}: not a list of uid strings (expected [\"uid\", ...])",
            uids_path.display()
        )
    })?;
    let npy = read_bounded(&npy_path, crate::commands::import::PICKLE_LIMIT)
        .map_err(|e| anyhow!("{}: {e}", npy_path.display()))?;
    let features = mesa_stages::pickle::TextFeatures::from_npy(&npy, uids)
        .map_err(|e| anyhow!("{}: {e}", npy_path.display()))?;
    let rows = features.uids.len();
    Ok(Some((
        mesa_stages::pickle::write_text_features(&features),
        rows,
    )))
}

/// Writes the release (see the module documentation).
pub fn write_release(
    dataset: &Path,
    out: &Path,
    config: &Config,
    exec: &Executor<'_>,
) -> anyhow::Result<ReleaseSummary> {
    let started = Instant::now();
    let scenes = select_scenes(
        discover_scenes(dataset).map_err(RunError::into_anyhow)?,
        exec.options().scenes.as_deref(),
        Shard::default(),
    )
    .map_err(RunError::into_anyhow)?;
    let annotations_path = dataset.join(ANNOTATIONS);
    let annotations = read_text_bounded(&annotations_path, JSON_LIMIT)
        .map_err(|e| {
            UsageError(format!(
                "{}: {e} (a release needs the asset annotations)",
                annotations_path.display()
            ))
        })
        .and_then(|t| {
            parse_lenient(&t)
                .map_err(|e| UsageError(format!("{}: {e}", annotations_path.display())))
        })?;
    if out.starts_with(dataset.join(SCENES)) {
        return Err(UsageError(format!(
            "{}: inside the dataset's scenes/ (give a folder outside it)",
            out.display()
        ))
        .into());
    }
    prepare_out(out)?;
    let outcomes: Vec<anyhow::Result<BTreeSet<String>>> =
        exec.map("scenes", &scenes, |scene| release_scene(config, scene, out));
    let mut summary = ReleaseSummary {
        out: out.to_owned(),
        scenes: scenes.len(),
        released: 0,
        assets: 0,
        text_features: 0,
        assets_linked: 0,
        assets_flattened: 0,
        assets_copied: 0,
        assets_missing: Vec::new(),
        failed: Vec::new(),
        elapsed_s: 0.0,
    };
    let mut uids = BTreeSet::new();
    for (scene, outcome) in scenes.iter().zip(outcomes) {
        match outcome {
            Ok(used) => {
                summary.released += 1;
                uids.extend(used);
            }
            Err(e) => summary.failed.push((scene.key(), format!("{e:#}"))),
        }
    }
    write_assets_library(
        dataset,
        out,
        config.release.assets,
        &uids,
        exec,
        &mut summary,
    )?;
    // Every annotated asset too, not only those the layouts use (MesaTask's retrieval reads
    // the whole library; a release's annotations also cover assets it could not ship), each
    // entry as the release it came from had it.
    if let Some(entries) = annotations.as_object() {
        uids.extend(entries.keys().cloned());
    }
    let annotations = match annotations {
        serde_json::Value::Object(entries) => serde_json::Value::Object(
            entries
                .into_iter()
                .map(|(uid, entry)| {
                    let entry = mesa_stages::import_mesatask::released_annotation(&entry);
                    (uid, entry)
                })
                .collect(),
        ),
        other => other,
    };
    match features_pickle(dataset) {
        Ok(Some((bytes, rows))) => {
            write(&out.join(TEXT_FEATURES_PKL), &bytes)?;
            summary.text_features = rows;
        }
        Ok(None) => {}
        Err(e) => summary
            .failed
            .push((TEXT_FEATURES_PKL.to_owned(), format!("{e:#}"))),
    }
    let path = out.join(ASSET_ANNOTATION);
    match release_annotations(&annotations, &uids) {
        Ok(bytes) => {
            validate(&path, &bytes, "asset-annotations")?;
            write(&path, &bytes)?;
            summary.assets = uids.len();
        }
        Err(e) => summary
            .failed
            .push((ASSET_ANNOTATION.to_owned(), e.to_string())),
    }
    summary.elapsed_s = started.elapsed().as_secs_f64();
    Ok(summary)
}

/// How one asset went into `Assets_library/`.
enum Placed {
    Linked,
    Flattened,
    Copied,
    Missing,
}

/// One used asset into `Assets_library/`.
fn release_asset(
    dataset: &Path,
    dir: &Path,
    mode: ReleaseAssets,
    uid: &str,
) -> anyhow::Result<Placed> {
    if !plain_uid(uid) {
        bail!(
            "retrieved_uid {uid:?} is not a plain file name (expected the stem of a GLB in \
             assets/library, without path separators or a leading dot)"
        );
    }
    let source = dataset.join(asset_glb(uid));
    if !source.exists() {
        return Ok(Placed::Missing);
    }
    let dest = dir.join(format!("{uid}.glb"));
    let bytes =
        || read_bounded(&source, GLB_LIMIT).map_err(|e| anyhow!("{}: {e}", source.display()));
    let link = match mode {
        ReleaseAssets::Link => true,
        ReleaseAssets::Bake | ReleaseAssets::None => false,
        ReleaseAssets::Auto => {
            placed_right_by_mesatask(&bytes()?).map_err(|e| anyhow!("{}: {e}", source.display()))?
        }
    };
    if link {
        // The file itself, not a symlink the library may hold in its place.
        let target = std::fs::canonicalize(&source)
            .with_context(|| format!("{}: cannot resolve", source.display()))?;
        return match std::fs::hard_link(&target, &dest) {
            Ok(()) => Ok(Placed::Linked),
            Err(_) => {
                std::fs::copy(&target, &dest).with_context(|| {
                    format!("{}: cannot copy to {}", target.display(), dest.display())
                })?;
                Ok(Placed::Copied)
            }
        };
    }
    let flat = flat_asset_glb(uid, &bytes()?).map_err(|e| anyhow!("{}: {e}", source.display()))?;
    write(&dest, &flat)?;
    Ok(Placed::Flattened)
}

/// `Assets_library/`: every used asset the library has, and the table and sink GLBs.
fn write_assets_library(
    dataset: &Path,
    out: &Path,
    mode: ReleaseAssets,
    uids: &BTreeSet<String>,
    exec: &Executor<'_>,
    summary: &mut ReleaseSummary,
) -> anyhow::Result<()> {
    if mode == ReleaseAssets::None {
        return Ok(());
    }
    let dir = out.join(ASSETS_LIBRARY);
    std::fs::create_dir_all(&dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    for (uid, rgb) in [
        (TABLE_GLB_UID, [0.36, 0.23, 0.13]),
        (SINK_GLB_UID, [0.8, 0.8, 0.82]),
    ] {
        let bytes = zone_box_glb(uid, rgb).map_err(|e| anyhow!("{uid}.glb: {e}"))?;
        write(&dir.join(format!("{uid}.glb")), &bytes)?;
    }
    let uids: Vec<&String> = uids.iter().collect();
    let outcomes = exec.map("assets", &uids, |uid| {
        release_asset(dataset, &dir, mode, uid)
    });
    for (uid, outcome) in uids.into_iter().zip(outcomes) {
        match outcome {
            Ok(Placed::Linked) => summary.assets_linked += 1,
            Ok(Placed::Flattened) => summary.assets_flattened += 1,
            Ok(Placed::Copied) => summary.assets_copied += 1,
            Ok(Placed::Missing) => summary.assets_missing.push(uid.clone()),
            Err(e) => summary
                .failed
                .push((format!("{ASSETS_LIBRARY}/{uid}.glb"), format!("{e:#}"))),
        }
    }
    Ok(())
}

/// The human summary of a release run.
pub fn format_release_summary(summary: &ReleaseSummary) -> String {
    use std::fmt::Write as _;
    let mut out = format!(
        "release: {} of {} scenes released, {} assets annotated, {} text features, {} failed \
         in {:.2} s: {}\n",
        summary.released,
        summary.scenes,
        summary.assets,
        summary.text_features,
        summary.failed.len(),
        summary.elapsed_s,
        summary.out.display()
    );
    let glbs = summary.assets_linked + summary.assets_flattened + summary.assets_copied;
    if glbs > 0 || !summary.assets_missing.is_empty() {
        let _ = writeln!(
            out,
            "  {ASSETS_LIBRARY}: {glbs} GLBs ({} hard-linked, {} flattened, {} copied where a \
             hard link was refused), {} used assets have no GLB in the library{}",
            summary.assets_linked,
            summary.assets_flattened,
            summary.assets_copied,
            summary.assets_missing.len(),
            if summary.assets_missing.is_empty() {
                String::new()
            } else {
                let shown: Vec<&str> = summary
                    .assets_missing
                    .iter()
                    .take(8)
                    .map(String::as_str)
                    .collect();
                let more = summary.assets_missing.len() - shown.len();
                let more = if more > 0 {
                    format!(" and {more} more")
                } else {
                    String::new()
                };
                format!(" ({}{more})", shown.join(", "))
            }
        );
    }
    for (what, error) in &summary.failed {
        let _ = writeln!(out, "  failed {what}: {error}");
    }
    out
}
