//! `mesa import mesatask SRC DATASET`: the released MesaTask-10K tree read into a mesa dataset
//! whose scenes enter at the refined stage (docs/import.md). `mesa run` on the dataset then
//! runs check, graph, render, tasks, records and report; lift, retrieve, place, pack and
//! ingest leave imported scenes out (they made the refined layout, which the release has).
//!
//! Per scene (in parallel, results in scene order): `refined/layout.json` (validated, with
//! what was dropped or fixed), `imported/import.json` (those notes and the objects whose GLB
//! the release lacks), `imported/front.png` (the release's picture, hard-linked or copied).
//! Dataset-wide: `assets/annotations.json` (every field kept, the text normalised),
//! `assets/text_features.npy` + `assets/text_uids.json` (read from the pickle by mesa's own
//! reader: no code from it runs), `assets/library/<uid>.glb` linked to the release's GLBs, and
//! `assets/import.json` (counts). A file whose bytes are already those is not rewritten, so a
//! second import of the same release writes nothing and a changed release rewrites only what
//! changed. One bad scene is reported and the others go on.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{anyhow, Context as _};
use clap::{Args as ClapArgs, Subcommand, ValueEnum};
use mesa_schemas::json::{parse_lenient, to_sorted_pretty};
use mesa_stages::import_mesatask::{import_layout, normalise_annotations, ImportNotes};
use mesa_stages::paths::dataset::{
    ANNOTATIONS, IMPORT_SUMMARY, LIBRARY, SCENES, TEXT_FEATURES, TEXT_UIDS,
};
use mesa_stages::paths::scene::{IMPORT_FRONT, IMPORT_NOTES, REFINED_LAYOUT};
use mesa_stages::pickle::read_text_features;
use serde::Serialize;

use crate::cli::{DatasetArgs, Global};
use crate::exit::UsageError;
use crate::fsio::{read_bounded, sweep_tmp_for, write_atomic, SizeLimit, IMAGE_LIMIT, JSON_LIMIT};
use crate::runner::{DatasetReport, DatasetStage, Executor, StageContext};

/// `Asset_annotation.json` read whole (1 GiB): 15,507 annotations are about 20 MiB.
pub const RELEASE_ANNOTATIONS_LIMIT: SizeLimit = SizeLimit {
    bytes: 1 << 30,
    what: "an Asset_annotation.json",
    name: "RELEASE_ANNOTATIONS_LIMIT",
};

/// `sbert_text_features.pkl` read whole (2 GiB): 15,507 × 768 float32 features are 48 MiB.
pub const PICKLE_LIMIT: SizeLimit = SizeLimit {
    bytes: 2 << 30,
    what: "a features pickle",
    name: "PICKLE_LIMIT",
};

/// `mesa import`.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// What to import.
    #[command(subcommand)]
    pub source: Source,
}

/// The releases `mesa import` reads.
#[derive(Debug, Subcommand)]
pub enum Source {
    /// The released MesaTask-10K tree: Layout_info/<table_type>/<scene_id>/{layout.json,
    /// front.png}, Asset_annotation.json, sbert_text_features.pkl, Assets_library/<uid>.glb
    Mesatask(MesataskArgs),
}

/// `mesa import mesatask`.
#[derive(Debug, ClapArgs)]
pub struct MesataskArgs {
    /// The release's folder (holds Layout_info/).
    pub src: PathBuf,
    /// The dataset to write (created when missing) and its run flags.
    #[command(flatten)]
    pub common: DatasetArgs,
    /// How assets/library/<uid>.glb points at the release's GLB (the library is 10+ GB).
    #[arg(long, value_enum, default_value_t = LinkMode::Hard)]
    pub link: LinkMode,
}

/// How the library is made.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LinkMode {
    /// Hard links (no space used; same file system only, else a symbolic link, said in the
    /// summary): the dataset keeps working if the release is moved or deleted.
    Hard,
    /// Symbolic links to the release's files (absolute paths): the release must stay in place.
    Symlink,
    /// Copies (the space of the library again).
    Copy,
}

/// Runs `mesa import`.
pub fn run(args: Args, global: Global) -> anyhow::Result<ExitCode> {
    match args.source {
        Source::Mesatask(args) => {
            let layout_info = args.src.join("Layout_info");
            if !layout_info.is_dir() {
                return Err(UsageError(format!(
                    "{}: no such folder (expected the MesaTask-10K release: \
                     Layout_info/<table_type>/<scene_id>/layout.json)",
                    layout_info.display()
                ))
                .into());
            }
            std::fs::create_dir_all(&args.common.dataset)
                .with_context(|| format!("{}: cannot create", args.common.dataset.display()))?;
            let src = std::path::absolute(&args.src)
                .with_context(|| format!("{}: cannot resolve", args.src.display()))?;
            let resolved = args.common.resolve(global)?;
            resolved.run_dataset(&ImportStage {
                src,
                link: args.link,
            })
        }
    }
}

/// The `import` stage.
#[derive(Debug)]
pub struct ImportStage {
    /// The release's folder (absolute).
    pub src: PathBuf,
    /// How the library is linked.
    pub link: LinkMode,
}

/// What one scene's import gave.
#[derive(Debug, Clone, Serialize)]
struct SceneResult {
    scene: String,
    written: usize,
    dropped: usize,
    fixed: usize,
    missing_glb_objects: usize,
    missing_uids: Vec<String>,
}

/// `assets/import.json`.
#[derive(Debug, Serialize)]
struct ImportSummary {
    schema: &'static str,
    source: String,
    scenes_imported: usize,
    scenes_failed: BTreeMap<String, String>,
    objects_dropped: usize,
    objects_fixed: usize,
    objects_missing_glb: usize,
    uids_missing_glb: Vec<String>,
    scenes_with_missing_glb: usize,
    library_glbs: usize,
    library_link: String,
    annotations: Option<mesa_stages::import_mesatask::AnnotationReport>,
    text_features: Option<FeaturesSummary>,
    problems: Vec<String>,
}

#[derive(Debug, Serialize)]
struct FeaturesSummary {
    rows: usize,
    cols: usize,
    dtype: &'static str,
}

/// Writes `bytes` at `path` unless the file already holds them; whether it wrote.
fn write_if_changed(path: &Path, bytes: &[u8]) -> anyhow::Result<bool> {
    if let Ok(meta) = std::fs::metadata(path) {
        if meta.is_file() && meta.len() == bytes.len() as u64 {
            if let Ok(old) = std::fs::read(path) {
                if old == bytes {
                    return Ok(false);
                }
            }
        }
    }
    sweep_tmp_for(path).with_context(|| format!("{}: sweeping", path.display()))?;
    write_atomic(path, bytes).with_context(|| format!("{}: cannot write", path.display()))?;
    Ok(true)
}

/// Whether `a` and `b` are the same file (a hard link, or a symbolic link to it).
fn same_file(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt as _;
        match (std::fs::metadata(a), std::fs::metadata(b)) {
            (Ok(x), Ok(y)) => x.dev() == y.dev() && x.ino() == y.ino(),
            _ => false,
        }
    }
    #[cfg(not(unix))]
    {
        let _ = (a, b);
        false
    }
}

/// Makes `dest` point at `src` the `mode` way (nothing when it already does); the way used.
fn link_file(src: &Path, dest: &Path, mode: LinkMode) -> anyhow::Result<Option<LinkMode>> {
    let is_symlink = std::fs::symlink_metadata(dest).is_ok_and(|m| m.file_type().is_symlink());
    match mode {
        LinkMode::Hard | LinkMode::Symlink if same_file(src, dest) => {
            let current = if is_symlink {
                LinkMode::Symlink
            } else {
                LinkMode::Hard
            };
            if current == mode || mode == LinkMode::Hard {
                return Ok(None);
            }
        }
        LinkMode::Copy if !is_symlink && !same_file(src, dest) => {
            if let (Ok(a), Ok(b)) = (std::fs::metadata(src), std::fs::metadata(dest)) {
                if a.len() == b.len() && std::fs::read(src).ok() == std::fs::read(dest).ok() {
                    return Ok(None);
                }
            }
        }
        _ => {}
    }
    if std::fs::symlink_metadata(dest).is_ok() {
        std::fs::remove_file(dest)
            .with_context(|| format!("{}: cannot replace", dest.display()))?;
    }
    let symlink = |src: &Path, dest: &Path| -> anyhow::Result<()> {
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink(src, dest)
                .with_context(|| format!("{}: cannot link to {}", dest.display(), src.display()))
        }
        #[cfg(not(unix))]
        {
            std::fs::copy(src, dest)
                .map(|_| ())
                .with_context(|| format!("{}: cannot copy {}", dest.display(), src.display()))
        }
    };
    match mode {
        LinkMode::Hard => match std::fs::hard_link(src, dest) {
            Ok(()) => Ok(Some(LinkMode::Hard)),
            // Another file system (EXDEV) or one without hard links: a symbolic link.
            Err(_) => symlink(src, dest).map(|()| Some(LinkMode::Symlink)),
        },
        LinkMode::Symlink => symlink(src, dest).map(|()| Some(LinkMode::Symlink)),
        LinkMode::Copy => {
            let bytes = read_bounded(src, crate::fsio::GLB_LIMIT)
                .with_context(|| format!("{}: cannot read", src.display()))?;
            write_atomic(dest, &bytes)
                .with_context(|| format!("{}: cannot write", dest.display()))?;
            Ok(Some(LinkMode::Copy))
        }
    }
}

/// A folder name mesa can carry as a table type or scene id (runner::core's rule).
fn name_problem(name: &str) -> Option<&'static str> {
    if name.len() > 200 {
        Some("longer than 200 bytes")
    } else if name.chars().any(char::is_control) {
        Some("has control characters")
    } else {
        None
    }
}

/// A release's scene: (table type, scene id).
type SceneName = (String, String);

/// The release's scenes, sorted, and folders that cannot be scenes.
fn list_scenes(layout_info: &Path) -> anyhow::Result<(Vec<SceneName>, Vec<String>)> {
    let mut scenes = Vec::new();
    let mut problems = Vec::new();
    let read = |dir: &Path| -> anyhow::Result<Vec<(String, PathBuf)>> {
        let mut out = Vec::new();
        for entry in
            std::fs::read_dir(dir).with_context(|| format!("{}: cannot list", dir.display()))?
        {
            let entry = entry.with_context(|| format!("{}: cannot list", dir.display()))?;
            if !entry.file_type().is_ok_and(|t| t.is_dir()) {
                continue;
            }
            match entry.file_name().into_string() {
                Ok(name) => out.push((name, entry.path())),
                Err(name) => out.push((format!("{name:?}"), PathBuf::new())),
            }
        }
        out.sort();
        Ok(out)
    };
    for (table, table_dir) in read(layout_info)? {
        if table.starts_with('.') {
            continue;
        }
        if table_dir.as_os_str().is_empty() || name_problem(&table).is_some() {
            problems.push(format!(
                "Layout_info/{table}: not a table type mesa can carry (UTF-8, at most 200 \
                 bytes, no control characters); left out"
            ));
            continue;
        }
        for (scene, scene_dir) in read(&table_dir)? {
            if scene.starts_with('.') {
                continue;
            }
            if scene_dir.as_os_str().is_empty() || name_problem(&scene).is_some() {
                problems.push(format!(
                    "Layout_info/{table}/{scene}: not a scene id mesa can carry (UTF-8, at most \
                     200 bytes, no control characters); left out"
                ));
                continue;
            }
            scenes.push((table.clone(), scene));
        }
    }
    Ok((scenes, problems))
}

/// The uids of `Assets_library/*.glb`.
fn list_library(library: &Path) -> anyhow::Result<BTreeSet<String>> {
    let mut uids = BTreeSet::new();
    if !library.is_dir() {
        return Ok(uids);
    }
    for entry in
        std::fs::read_dir(library).with_context(|| format!("{}: cannot list", library.display()))?
    {
        let entry = entry.with_context(|| format!("{}: cannot list", library.display()))?;
        let Ok(name) = entry.file_name().into_string() else {
            continue;
        };
        if let Some(uid) = name.strip_suffix(".glb") {
            if !uid.is_empty() && !uid.starts_with('.') && entry.path().is_file() {
                uids.insert(uid.to_owned());
            }
        }
    }
    Ok(uids)
}

impl ImportStage {
    fn import_scene(
        &self,
        dataset: &Path,
        table: &str,
        scene_id: &str,
        library: &BTreeSet<String>,
    ) -> anyhow::Result<SceneResult> {
        let rel = format!("Layout_info/{table}/{scene_id}/layout.json");
        let source = self.src.join(&rel);
        let bytes = read_bounded(&source, JSON_LIMIT).map_err(|e| {
            anyhow!(
                "{}: {e} (every scene folder of the release holds its layout.json)",
                source.display()
            )
        })?;
        let (layout, mut notes): (_, ImportNotes) =
            import_layout(&bytes, &rel, &|uid| library.contains(uid))?;
        let scene_dir = dataset.join(SCENES).join(table).join(scene_id);
        if scene_dir.join(REFINED_LAYOUT).is_file() && !scene_dir.join(IMPORT_NOTES).is_file() {
            anyhow::bail!(
                "{}: a scene of this dataset that was not imported has that name: import into \
                 a new dataset folder",
                scene_dir.display()
            );
        }
        let mut written = 0;
        let front_src = self
            .src
            .join(format!("Layout_info/{table}/{scene_id}/front.png"));
        let front_dest = scene_dir.join(IMPORT_FRONT);
        if front_src.is_file() {
            crate::fsio::check_regular_file(&front_src, IMAGE_LIMIT)
                .map_err(|e| anyhow!("{}: {e}", front_src.display()))?;
            notes.front_png = true;
            std::fs::create_dir_all(scene_dir.join("imported"))
                .with_context(|| format!("{}: cannot create", scene_dir.display()))?;
            // The picture is the release's: hard-linked where possible, else copied.
            let mode = if self.link == LinkMode::Symlink {
                LinkMode::Symlink
            } else {
                LinkMode::Hard
            };
            if link_file(&front_src, &front_dest, mode)?.is_some() {
                written += 1;
            }
        } else if std::fs::symlink_metadata(&front_dest).is_ok() {
            std::fs::remove_file(&front_dest)
                .with_context(|| format!("{}: cannot remove", front_dest.display()))?;
        }
        let layout_bytes = to_sorted_pretty(&layout).map_err(|e| anyhow!("{e}"))?;
        notes.layout_sha256 = crate::fsio::sha256_hex(&layout_bytes);
        let notes_bytes = to_sorted_pretty(&notes).map_err(|e| anyhow!("{e}"))?;
        written += usize::from(write_if_changed(
            &scene_dir.join(REFINED_LAYOUT),
            &layout_bytes,
        )?);
        // The notes last: they mark the scene as imported.
        written += usize::from(write_if_changed(
            &scene_dir.join(IMPORT_NOTES),
            &notes_bytes,
        )?);
        let missing_uids: BTreeSet<String> =
            notes.missing_glbs.iter().map(|m| m.uid.clone()).collect();
        Ok(SceneResult {
            scene: format!("{table}/{scene_id}"),
            written,
            dropped: notes.dropped.len(),
            fixed: notes.fixed.len(),
            missing_glb_objects: notes.missing_glbs.len(),
            missing_uids: missing_uids.into_iter().collect(),
        })
    }

    fn import_annotations(
        &self,
        dataset: &Path,
        summary: &mut ImportSummary,
    ) -> anyhow::Result<usize> {
        let path = self.src.join("Asset_annotation.json");
        if !path.exists() {
            summary.problems.push(
                "Asset_annotation.json: not in the release (the graph and retrieval read \
                 categories and containers from it)"
                    .to_owned(),
            );
            return Ok(0);
        }
        let bytes = read_bounded(&path, RELEASE_ANNOTATIONS_LIMIT)
            .map_err(|e| anyhow!("{}: {e}", path.display()))?;
        let text =
            String::from_utf8(bytes).map_err(|e| anyhow!("{}: not UTF-8: {e}", path.display()))?;
        let value = parse_lenient(&text).map_err(|e| anyhow!("{}: {e}", path.display()))?;
        let (entries, report) = normalise_annotations(value, "Asset_annotation.json")?;
        let bytes = to_sorted_pretty(&entries).map_err(|e| anyhow!("{e}"))?;
        let written = usize::from(write_if_changed(&dataset.join(ANNOTATIONS), &bytes)?);
        for (uid, why) in &report.dropped {
            summary
                .problems
                .push(format!("Asset_annotation.json: {uid}: left out: {why}"));
        }
        summary.annotations = Some(report);
        Ok(written)
    }

    fn import_features(
        &self,
        dataset: &Path,
        summary: &mut ImportSummary,
    ) -> anyhow::Result<usize> {
        let path = self.src.join("sbert_text_features.pkl");
        if !path.exists() {
            return Ok(0);
        }
        let bytes =
            read_bounded(&path, PICKLE_LIMIT).map_err(|e| anyhow!("{}: {e}", path.display()))?;
        let features =
            read_text_features(&bytes).map_err(|e| anyhow!("{}: {e}", path.display()))?;
        let uids = serde_json::to_vec_pretty(&features.uids).map_err(|e| anyhow!("{e}"))?;
        let mut written = usize::from(write_if_changed(
            &dataset.join(TEXT_FEATURES),
            &features.to_npy(),
        )?);
        written += usize::from(write_if_changed(&dataset.join(TEXT_UIDS), &uids)?);
        summary.text_features = Some(FeaturesSummary {
            rows: features.uids.len(),
            cols: features.cols,
            dtype: match features.kind {
                mesa_stages::pickle::FloatKind::F16 => "float16",
                mesa_stages::pickle::FloatKind::F32 => "float32",
            },
        });
        Ok(written)
    }
}

impl DatasetStage for ImportStage {
    fn name(&self) -> &'static str {
        "import"
    }

    fn run(&self, ctx: &StageContext<'_>, exec: &Executor<'_>) -> anyhow::Result<DatasetReport> {
        let started = std::time::Instant::now();
        let dataset = ctx.dataset;
        let library_src = self.src.join("Assets_library");
        let library = list_library(&library_src)?;
        let (scenes, mut problems) = list_scenes(&self.src.join("Layout_info"))?;
        let results = exec.map("scenes", &scenes, |(table, scene)| {
            self.import_scene(dataset, table, scene, &library)
                .map_err(|e| format!("{e:#}"))
        });
        let mut summary = ImportSummary {
            schema: "mesa.import-summary/1",
            source: self.src.display().to_string(),
            scenes_imported: 0,
            scenes_failed: BTreeMap::new(),
            objects_dropped: 0,
            objects_fixed: 0,
            objects_missing_glb: 0,
            uids_missing_glb: Vec::new(),
            scenes_with_missing_glb: 0,
            library_glbs: library.len(),
            library_link: String::new(),
            annotations: None,
            text_features: None,
            problems: Vec::new(),
        };
        summary.problems.append(&mut problems);
        let mut written = 0;
        let mut missing = BTreeSet::new();
        for ((table, scene), result) in scenes.iter().zip(results) {
            match result {
                Ok(r) => {
                    summary.scenes_imported += 1;
                    summary.objects_dropped += r.dropped;
                    summary.objects_fixed += r.fixed;
                    summary.objects_missing_glb += r.missing_glb_objects;
                    summary.scenes_with_missing_glb += usize::from(r.missing_glb_objects > 0);
                    missing.extend(r.missing_uids);
                    written += r.written;
                }
                Err(e) => {
                    summary.scenes_failed.insert(format!("{table}/{scene}"), e);
                }
            }
        }
        summary.uids_missing_glb = missing.into_iter().collect();
        // The library: one link per GLB of the release (also those no layout uses: the
        // release's Asset_annotation.json covers the library).
        let uids: Vec<&String> = library.iter().collect();
        std::fs::create_dir_all(dataset.join(LIBRARY))
            .with_context(|| format!("{}: cannot create", dataset.join(LIBRARY).display()))?;
        let links = exec.map("assets", &uids, |uid| {
            link_file(
                &library_src.join(format!("{uid}.glb")),
                &dataset.join(mesa_stages::paths::dataset::asset_glb(uid)),
                self.link,
            )
            .map_err(|e| format!("{e:#}"))
        });
        let mut modes = BTreeMap::<String, usize>::new();
        for (uid, link) in uids.iter().zip(links) {
            match link {
                Ok(Some(mode)) => {
                    written += 1;
                    *modes.entry(format!("{mode:?}").to_lowercase()).or_default() += 1;
                }
                Ok(None) => {}
                Err(e) => summary
                    .problems
                    .push(format!("Assets_library/{uid}.glb: {e}")),
            }
        }
        summary.library_link = format!("{:?}", self.link).to_lowercase();
        if let Some(symlinks) = modes.get("symlink").filter(|_| self.link == LinkMode::Hard) {
            summary.problems.push(format!(
                "{symlinks} GLBs are symbolic links: the dataset and the release are on different \
                 file systems (keep the release in place, or import with --link copy)"
            ));
        }
        match self.import_annotations(dataset, &mut summary) {
            Ok(n) => written += n,
            Err(e) => summary.problems.push(format!("{e:#}")),
        }
        let features_failed = match self.import_features(dataset, &mut summary) {
            Ok(n) => {
                written += n;
                false
            }
            Err(e) => {
                summary.problems.push(format!("{e:#}"));
                true
            }
        };
        // The summary holds no times, so that it is the same for every run of the same release.
        let summary_bytes = to_sorted_pretty(&summary).map_err(|e| anyhow!("{e}"))?;
        written += usize::from(write_if_changed(
            &dataset.join(IMPORT_SUMMARY),
            &summary_bytes,
        )?);
        let elapsed = started.elapsed().as_secs_f64();
        let mut text = format!(
            "import: {} scenes imported, {} failed, {} files written in {elapsed:.2} s; {} \
             objects dropped, {} fixed, {} objects in {} scenes without a GLB ({} uids); {} \
             library GLBs\n",
            summary.scenes_imported,
            summary.scenes_failed.len(),
            written,
            summary.objects_dropped,
            summary.objects_fixed,
            summary.objects_missing_glb,
            summary.scenes_with_missing_glb,
            summary.uids_missing_glb.len(),
            summary.library_glbs,
        );
        for (scene, e) in summary.scenes_failed.iter().take(20) {
            text.push_str(&format!("  failed {scene}: {e}\n"));
        }
        for p in summary.problems.iter().take(20) {
            text.push_str(&format!("  warning: {p}\n"));
        }
        text.push_str(&format!(
            "  details: {} and each scene's {IMPORT_NOTES}\n",
            dataset.join(IMPORT_SUMMARY).display()
        ));
        let mut record = serde_json::to_value(&summary).map_err(|e| anyhow!("{e}"))?;
        record["elapsed_s"] = serde_json::json!(elapsed);
        record["files_written"] = serde_json::json!(written);
        Ok(DatasetReport {
            success: summary.scenes_failed.is_empty() && !features_failed,
            text,
            record,
        })
    }
}
