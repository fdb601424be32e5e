//! `mesa report DATASET`: a dataset-level stage run once at the end (`mesa run` runs it last,
//! unsharded). It reads what every scene has — the layout later stages read, `graph/graph.json`,
//! `qa/check.json`, the renders and their camera files, `tasks/tasks.jsonl`, the runner's
//! markers — and writes, each file atomically:
//!
//! - `report/stats.json` (`mesa.report-stats/1`);
//! - `report/objects_per_scene.svg`, `categories.svg` (the 100 most frequent), `table_types.svg`,
//!   `relations.svg`, `collisions.svg` (before / after settling, or "not checked");
//! - `report/thumbs/<table_type>/<scene_id>.png`, a 232-pixel copy of each front view, made
//!   again only when the front view changed (`report/thumbs/sources.json` records each one's
//!   source digest);
//! - `report/index.html`: the summary, the plots inline, and a card per scene with its
//!   thumbnail, QA flags and relative links to its files; no script and no network.

use mesa_stages::paths::dataset::REPORT_DIR;
use mesa_stages::paths::scene::{
    CHECK, GRAPH_JSON, GRAPH_TXT, IMAGE, IMPORT_NOTES, RENDER_DIR, SETTLED_LAYOUT, TASKS,
};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use clap::Args as ClapArgs;

use anyhow::{anyhow, Context as _};
use mesa_schemas::artifacts::{GraphArtifact, MarkerStatus, CHECK_SCHEMA};
use mesa_schemas::convert::category_of_instance;
use mesa_schemas::json::to_sorted_pretty;
use mesa_schemas::layout_file::{read_layout_text, AnyLayout};
use mesa_schemas::render::{RenderCameraArtifact, ReportThumbs, REPORT_THUMBS_SCHEMA};
use mesa_stages::render::SceneView;
use mesa_stages::report::{compute_stats, html, plots, CheckFacts, SceneFacts, SceneLink};
use serde::Serialize;
use serde_json::Value;

use crate::cli::{DatasetArgs, Global};
use crate::fsio::{
    read_bounded, read_text_bounded, sha256_hex, sweep_tmp_for, write_atomic, IMAGE_LIMIT,
    JSON_LIMIT, RECORDS_LIMIT,
};
use crate::layouts::chosen_layout;
use crate::runner::{
    discover_scenes, read_marker, DatasetReport, DatasetStage, Executor, RunError, Scene,
    StageContext, RUN_DIR,
};

/// Side of the thumbnails, pixels.
pub const THUMBNAIL_PX: u32 = 232;

/// What a report run wrote.
#[derive(Debug, Serialize)]
pub struct ReportSummary {
    /// Scenes reported.
    pub scenes: usize,
    /// The report folder.
    pub dir: PathBuf,
    /// Scenes without a thumbnail (not rendered).
    pub without_thumbnail: usize,
    /// Scenes flagged `bad` (a failure, a collision, a floating object, ...).
    pub flagged: usize,
    /// Wall time.
    pub elapsed_s: f64,
}

/// The stages whose markers the report reads, in pipeline order.
fn marker_stages(dataset: &Path) -> Vec<String> {
    let mut stages: Vec<String> = std::fs::read_dir(dataset.join(RUN_DIR).join("markers"))
        .map(|entries| {
            entries
                .filter_map(Result::ok)
                .filter(|e| e.path().is_dir())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    stages.sort();
    stages
}

/// A smaller copy of a front view, cropped to a square around what is drawn (pixels with
/// some alpha, or not black on a black background).
fn thumbnail(png: &[u8]) -> anyhow::Result<Vec<u8>> {
    let image = image::load_from_memory(png)?.to_rgba8();
    let (w, h) = image.dimensions();
    let (mut x0, mut y0, mut x1, mut y1) = (w, h, 0u32, 0u32);
    let transparent = image.pixels().any(|p| p[3] < 255);
    for (x, y, p) in image.enumerate_pixels() {
        let drawn = if transparent {
            p[3] > 0
        } else {
            p.0[..3] != [0, 0, 0]
        };
        if drawn {
            x0 = x0.min(x);
            y0 = y0.min(y);
            x1 = x1.max(x + 1);
            y1 = y1.max(y + 1);
        }
    }
    let image = if x1 > x0 && y1 > y0 {
        // A square around the drawn box, with a margin, inside the picture where it can be.
        let side = ((x1 - x0).max(y1 - y0) as f64 * 1.08).ceil() as u32;
        let side = side.min(w).min(h).max(1);
        let cx = (x0 + x1) / 2;
        let cy = (y0 + y1) / 2;
        let left = cx.saturating_sub(side / 2).min(w - side);
        let top = cy.saturating_sub(side / 2).min(h - side);
        image::imageops::crop_imm(&image, left, top, side, side).to_image()
    } else {
        image
    };
    let small = image::imageops::resize(
        &image,
        THUMBNAIL_PX,
        THUMBNAIL_PX,
        image::imageops::FilterType::Triangle,
    );
    Ok(mesa_stages::image_io::encode_rgba8(
        THUMBNAIL_PX,
        THUMBNAIL_PX,
        small.as_raw(),
    )?)
}

/// Where the thumbnails' front views are recorded ([`ReportThumbs`]). A thumbnail whose front
/// view is unchanged, made by the same recipe, and whose file is there is not made again
/// (decoding and resizing a 512² view is most of a report's time).
const THUMB_SOURCES: &str = "thumbs/sources.json";

/// How thumbnails are made; a report whose recipe differs from the record's makes them all
/// again. Change it whenever [`thumbnail`] changes its output.
const THUMB_RECIPE: &str = "mesa.thumbnail/1 crop-1.08 triangle-232";

/// A scene's thumbnail: the digest of its front view, and its bytes when it was made anew
/// (`None`: the file from the last report stays).
struct Thumb {
    source_sha256: String,
    bytes: Option<Vec<u8>>,
}

/// What the report learns of one scene, and its thumbnail. `previous` is the last report's
/// [`THUMB_SOURCES`].
fn scene_facts(
    dataset: &Path,
    scene: &Scene,
    stages: &[String],
    previous: &BTreeMap<String, String>,
) -> (SceneFacts, Option<Thumb>) {
    let mut facts = SceneFacts {
        table_type: scene.table_type.clone(),
        scene_id: scene.scene_id.clone(),
        ..SceneFacts::default()
    };
    let mut layout_sha = None;
    if let Some(rel) = chosen_layout(scene) {
        facts.layout = Some(rel.to_owned());
        facts.links.push(SceneLink {
            label: "layout".into(),
            path: scene.rel(rel),
        });
        match read_bounded(&scene.path(rel), JSON_LIMIT) {
            Ok(bytes) => {
                layout_sha = Some(sha256_hex(&bytes));
                let text = String::from_utf8_lossy(&bytes);
                match read_layout_text(&text) {
                    Ok(read) => {
                        facts.objects = match read.layout {
                            AnyLayout::Dataset(l) => l
                                .objects
                                .into_iter()
                                .map(|o| {
                                    let category = o.category.unwrap_or_else(|| {
                                        category_of_instance(&o.instance).to_owned()
                                    });
                                    (o.instance, category)
                                })
                                .collect(),
                            AnyLayout::Llm(l) => l
                                .objects
                                .into_iter()
                                .map(|o| {
                                    let category = category_of_instance(&o.instance).to_owned();
                                    (o.instance, category)
                                })
                                .collect(),
                        }
                    }
                    Err(problems) => facts.failed.push((
                        "layout".into(),
                        format!("{rel} is not a valid layout ({} problems)", problems.len()),
                    )),
                }
            }
            Err(e) => facts.failed.push(("layout".into(), format!("{rel}: {e}"))),
        }
    }
    if let Ok(text) = read_text_bounded(&scene.path(IMPORT_NOTES), JSON_LIMIT) {
        match serde_json::from_str::<mesa_stages::import_mesatask::ImportNotes>(&text) {
            Ok(notes) => {
                facts.imported = true;
                facts.missing_glbs = notes
                    .missing_glbs
                    .into_iter()
                    .map(|m| (m.instance, m.uid))
                    .collect();
            }
            Err(e) => facts.failed.push((
                "import".into(),
                format!("{IMPORT_NOTES} cannot be read: {e}"),
            )),
        }
    }
    if let Ok(text) = read_text_bounded(&scene.path(GRAPH_JSON), JSON_LIMIT) {
        if let Ok(graph) = serde_json::from_str::<GraphArtifact>(&text) {
            facts.has_graph = true;
            let nodes = graph.nodes.len() as u64;
            *facts.relations.entry("is at".into()).or_insert(0) += nodes;
            *facts.relations.entry("face to".into()).or_insert(0) += nodes;
            for edge in &graph.edges {
                *facts.relations.entry(edge.relation.clone()).or_insert(0) += 1;
            }
            if !graph.equally_spaced.is_empty() {
                *facts
                    .relations
                    .entry("are equally spaced along".into())
                    .or_insert(0) += graph.equally_spaced.len() as u64;
            }
        }
    }
    if let Ok(text) = read_text_bounded(&scene.path(CHECK), JSON_LIMIT) {
        match check_facts(&text) {
            Some((before, after, tried)) => {
                facts.check_before = Some(before);
                facts.check_after = after;
                facts.settle_tried = tried;
            }
            None => facts.failed.push((
                "check".into(),
                "qa/check.json is not a mesa.check/1 artifact".into(),
            )),
        }
    }
    let mut thumb = None;
    for view in SceneView::ALL {
        let png = scene.path(&format!("{RENDER_DIR}/{}.png", view.name()));
        if png.is_file() {
            facts.rendered.push(view.name().to_owned());
        }
    }
    if let Ok(text) = read_text_bounded(
        &scene.path(&format!("{RENDER_DIR}/front_camera.json")),
        JSON_LIMIT,
    ) {
        if let Ok(camera) = serde_json::from_str::<RenderCameraArtifact>(&text) {
            facts.hidden_in_front = camera
                .visible_px
                .iter()
                .filter(|(_, px)| **px == 0)
                .map(|(instance, _)| instance.clone())
                .collect();
            facts.render_stale = camera.layout.as_deref() != facts.layout.as_deref()
                || camera.layout_sha256 != layout_sha;
        }
    }
    if let Ok(png) = read_bounded(&scene.path(&format!("{RENDER_DIR}/front.png")), IMAGE_LIMIT) {
        let rel = format!("thumbs/{}/{}.png", scene.table_type, scene.scene_id);
        let source_sha256 = sha256_hex(&png);
        let unchanged = previous.get(&rel) == Some(&source_sha256)
            && dataset.join(REPORT_DIR).join(&rel).is_file();
        let made = if unchanged {
            Ok(None)
        } else {
            thumbnail(&png).map(Some)
        };
        match made {
            Ok(bytes) => {
                facts.thumbnail = Some(rel);
                thumb = Some(Thumb {
                    source_sha256,
                    bytes,
                });
            }
            Err(e) => facts.failed.push((
                "render".into(),
                format!("render/front.png cannot be read: {e}"),
            )),
        }
    }
    if let Ok(text) = read_text_bounded(&scene.path(TASKS), RECORDS_LIMIT) {
        facts.tasks = text.lines().filter(|l| !l.trim().is_empty()).count() as u64;
    }
    for stage in stages {
        let marker = dataset
            .join(RUN_DIR)
            .join("markers")
            .join(stage)
            .join(&scene.table_type)
            .join(format!("{}.json", scene.scene_id));
        let Some(marker) = read_marker(&marker) else {
            continue;
        };
        match marker.status {
            MarkerStatus::Failed => facts.failed.push((
                stage.clone(),
                marker.error.first().cloned().unwrap_or_default(),
            )),
            MarkerStatus::Done if !marker.warnings.is_empty() => {
                facts
                    .warnings
                    .insert(stage.clone(), marker.warnings.len() as u64);
            }
            MarkerStatus::Done => {}
        }
    }
    let links = [
        ("photo", IMAGE),
        ("graph", GRAPH_TXT),
        ("check", CHECK),
        ("tasks", TASKS),
        ("back", "render/back.png"),
        ("left", "render/left.png"),
        ("right", "render/right.png"),
        ("perspective", "render/perspective.png"),
    ];
    for (label, rel) in links {
        if scene.path(rel).is_file() {
            facts.links.push(SceneLink {
                label: label.into(),
                path: scene.rel(rel),
            });
        }
    }
    let glb = format!("pack/{}.glb", scene.scene_id);
    if scene.path(&glb).is_file() {
        facts.links.push(SceneLink {
            label: "pack".into(),
            path: scene.rel(&glb),
        });
    }
    (facts, thumb)
}

/// Counts of a check's findings (`qa/check.json`'s top level, or its `settle.after`).
fn findings(value: &Value, layout: &str) -> Option<CheckFacts> {
    let count = |key: &str| {
        value
            .get(key)
            .and_then(Value::as_array)
            .map(|a| a.len() as u64)
    };
    Some(CheckFacts {
        layout: layout.to_owned(),
        pairs: value.get("pairs_total")?.as_u64()?,
        colliding: count("collisions")?,
        collision_rate: value.get("collision_rate")?.as_f64()?,
        floating: count("floating")?,
        zone_violations: count("zone_violations")?,
    })
}

/// What `qa/check.json` says: the checked layout's findings, the settled layout's (when
/// `--settle` wrote one), and whether settling was tried.
fn check_facts(text: &str) -> Option<(CheckFacts, Option<CheckFacts>, bool)> {
    let value: Value = serde_json::from_str(text).ok()?;
    if value.get("schema").and_then(Value::as_str) != Some(CHECK_SCHEMA) {
        return None;
    }
    let layout = value.get("layout")?.as_str()?;
    let before = findings(&value, layout)?;
    let settle = value.get("settle").filter(|s| !s.is_null());
    let after = settle
        .filter(|s| s.get("status").and_then(Value::as_str) == Some("settled"))
        .and_then(|s| {
            let layout = s
                .get("layout")
                .and_then(Value::as_str)
                .unwrap_or(SETTLED_LAYOUT);
            findings(s.get("after")?, layout)
        });
    Some((before, after, settle.is_some()))
}

fn write(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    sweep_tmp_for(path).with_context(|| format!("{}: sweeping", path.display()))?;
    write_atomic(path, bytes).with_context(|| format!("{}: cannot write", path.display()))
}

/// Removes thumbnails of scenes that no longer have one.
fn remove_stale_thumbnails(dir: &Path, keep: &BTreeSet<PathBuf>) {
    let Ok(tables) = std::fs::read_dir(dir) else {
        return;
    };
    for table in tables.filter_map(Result::ok) {
        let Ok(files) = std::fs::read_dir(table.path()) else {
            continue;
        };
        for file in files.filter_map(Result::ok) {
            let path = file.path();
            if path.extension().is_some_and(|e| e == "png") && !keep.contains(&path) {
                let _ = std::fs::remove_file(&path);
            }
        }
    }
}

/// `mesa report`.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// The dataset and its run flags.
    #[command(flatten)]
    pub common: DatasetArgs,
}

/// Runs `mesa report`.
pub fn run(args: Args, global: Global) -> anyhow::Result<ExitCode> {
    args.common.resolve(global)?.run_dataset(&ReportStage)
}

/// The `report` stage: statistics, plots and the page, once over the dataset.
#[derive(Debug, Default)]
pub struct ReportStage;

impl DatasetStage for ReportStage {
    fn name(&self) -> &'static str {
        "report"
    }

    fn run(&self, ctx: &StageContext<'_>, exec: &Executor<'_>) -> anyhow::Result<DatasetReport> {
        let summary = write_report(ctx.dataset, exec)?;
        Ok(DatasetReport {
            success: true,
            text: format_report_summary(&summary),
            record: serde_json::to_value(&summary)?,
        })
    }
}

/// Writes the report of a dataset (see the module documentation), a scene a unit of `exec`.
pub fn write_report(dataset: &Path, exec: &Executor<'_>) -> anyhow::Result<ReportSummary> {
    let started = Instant::now();
    let scenes = discover_scenes(dataset).map_err(RunError::into_anyhow)?;
    let stages = marker_stages(dataset);
    let dir = dataset.join(REPORT_DIR);
    // A missing, unreadable or other-recipe record only means every thumbnail is made again.
    let previous: BTreeMap<String, String> =
        read_text_bounded(&dir.join(THUMB_SOURCES), JSON_LIMIT)
            .ok()
            .and_then(|text| serde_json::from_str::<ReportThumbs>(&text).ok())
            .filter(|record| record.schema == REPORT_THUMBS_SCHEMA && record.recipe == THUMB_RECIPE)
            .map(|record| record.sources)
            .unwrap_or_default();
    let gathered: Vec<(SceneFacts, Option<Thumb>)> = exec.map("scenes", &scenes, |scene| {
        scene_facts(dataset, scene, &stages, &previous)
    });
    let mut kept = BTreeSet::new();
    let mut sources = BTreeMap::new();
    for (facts, thumb) in &gathered {
        if let (Some(rel), Some(thumb)) = (&facts.thumbnail, thumb) {
            let path = dir.join(rel);
            if let Some(bytes) = &thumb.bytes {
                write(&path, bytes)?;
            }
            kept.insert(path);
            sources.insert(rel.clone(), thumb.source_sha256.clone());
        }
    }
    remove_stale_thumbnails(&dir.join("thumbs"), &kept);
    let record = ReportThumbs {
        schema: REPORT_THUMBS_SCHEMA.into(),
        recipe: THUMB_RECIPE.into(),
        sources,
    };
    write(&dir.join(THUMB_SOURCES), &to_sorted_pretty(&record)?)?;
    let facts: Vec<SceneFacts> = gathered.into_iter().map(|(f, _)| f).collect();
    let mut stats = compute_stats(&facts);
    // Where the library's annotations came from (`mesa annotate`): fields by source.
    let annotations = dataset.join(mesa_stages::paths::dataset::ANNOTATIONS);
    if let Ok(text) = crate::fsio::read_text_bounded(&annotations, crate::fsio::JSON_LIMIT) {
        if let Ok(document) = mesa_schemas::json::parse_lenient(&text) {
            let (sources, placeholders) = mesa_stages::annotate::count_sources(&document);
            stats.annotation_sources = sources;
            stats.annotation_placeholder_assets = placeholders;
        }
    }
    let svgs = plots(&stats).map_err(|e| anyhow!("cannot draw the plots: {e}"))?;
    write(&dir.join("stats.json"), &to_sorted_pretty(&stats)?)?;
    for (name, svg) in &svgs {
        write(&dir.join(name), svg.as_bytes())?;
    }
    write(
        &dir.join("index.html"),
        html(&stats, &facts, &svgs).as_bytes(),
    )?;
    Ok(ReportSummary {
        scenes: facts.len(),
        without_thumbnail: facts.iter().filter(|f| f.thumbnail.is_none()).count(),
        flagged: facts
            .iter()
            .filter(|f| {
                mesa_stages::report::flags(f)
                    .iter()
                    .any(|(s, _)| *s == "bad")
            })
            .count(),
        dir,
        elapsed_s: started.elapsed().as_secs_f64(),
    })
}

/// The human summary of a report run.
pub fn format_report_summary(summary: &ReportSummary) -> String {
    format!(
        "report: {} scenes ({} without a render, {} flagged) in {:.2} s: {}\n",
        summary.scenes,
        summary.without_thumbnail,
        summary.flagged,
        summary.elapsed_s,
        summary.dir.join("index.html").display()
    )
}
