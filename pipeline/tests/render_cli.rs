//! `mesa render`, `mesa report` and `mesa release` from the command line, on a small demo
//! whose annotator round is simulated: each scene's true layout is its `refined/layout.json`.
//!
//! The report page is opened in headless Chromium (scripts/check_html.cjs, Debian's
//! `chromium`): no console error, every scene shown, and a broken page is caught. Without
//! chromium or node the check says SKIPPED, and fails instead when `MESA_REQUIRE_TOOLS` is set,
//! as in CI.

mod common;

use common::mesa;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use mesa_schemas::json::to_sorted_pretty;
use mesa_schemas::layout_file::{read_layout_text, AnyLayout};
use mesa_schemas::render::{RenderCameraArtifact, ReportStats};
use mesa_schemas::DatasetLayout;
use predicates::prelude::*;
use serde_json::Value;

const SCENES: [&str; 4] = [
    "coffee_table/coffee_table_0001",
    "dining_table/dining_table_0001",
    "kitchen_counter/kitchen_counter_0001",
    "office_table/office_table_0001",
];

/// Small pictures keep the unoptimised test build quick; the renderer is the same.
const CONFIG: &str = "[render]\nwidth_px = 160\nheight_px = 120\n";

/// A demo of 4 scenes with its asset index; each scene's `refined/layout.json` is its true
/// layout with one object turned by 30° (so the released layout is not the demo's own file).
fn base() -> &'static Path {
    static BASE: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    let (_, path) = BASE.get_or_init(|| {
        let dir = tempfile::tempdir().expect("tempdir");
        let ws = dir.path().join("demo");
        mesa()
            .args(["demo", "--scenes", "4", "--seed", "7", "-q"])
            .arg(&ws)
            .assert()
            .success();
        std::fs::write(ws.join("mesa.toml"), CONFIG).expect("config");
        mesa().args(["assets", "-q"]).arg(&ws).assert().success();
        for scene in SCENES {
            let dir = ws.join("scenes").join(scene);
            let mut layout = read_layout(&dir.join("truth/layout.json"));
            let object = &mut layout.objects[0];
            let yaw = object.z_rotation_deg.unwrap_or(0.0) + 30.0;
            object.rotation.0 = mesa_schemas::rotation::quat_xyzw_from_yaw_deg(yaw);
            object.z_rotation_deg = Some(mesa_schemas::rotation::normalize_deg(yaw));
            std::fs::create_dir_all(dir.join("refined")).expect("mkdir");
            std::fs::write(
                dir.join("refined/layout.json"),
                to_sorted_pretty(&layout).expect("json"),
            )
            .expect("write");
        }
        (dir, ws)
    });
    path
}

/// A copy of the base workspace for one test.
fn workspace() -> (tempfile::TempDir, PathBuf) {
    fn copy(from: &Path, to: &Path) {
        std::fs::create_dir_all(to).expect("mkdir");
        for entry in std::fs::read_dir(from).expect("read_dir") {
            let entry = entry.expect("entry");
            let target = to.join(entry.file_name());
            if entry.path().is_dir() {
                copy(&entry.path(), &target);
            } else {
                std::fs::copy(entry.path(), &target).expect("copy");
            }
        }
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let ws = dir.path().join("demo");
    copy(base(), &ws);
    (dir, ws)
}

fn read_layout(path: &Path) -> DatasetLayout {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    match read_layout_text(&text).expect("a layout").layout {
        AnyLayout::Dataset(layout) => layout,
        AnyLayout::Llm(_) => panic!("{}: an LLM layout", path.display()),
    }
}

fn render(ws: &Path, extra: &[&str]) -> assert_cmd::assert::Assert {
    mesa()
        .args(["render", "--progress", "off"])
        .args(extra)
        .arg(ws)
        .assert()
}

fn files_under(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    fn walk(root: &Path, dir: &Path, out: &mut BTreeMap<String, Vec<u8>>) {
        for entry in std::fs::read_dir(dir).into_iter().flatten() {
            let path = entry.expect("entry").path();
            if path.is_dir() {
                walk(root, &path, out);
            } else {
                let rel = path.strip_prefix(root).expect("prefix");
                out.insert(
                    rel.to_string_lossy().into_owned(),
                    std::fs::read(&path).expect("read"),
                );
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(dir, dir, &mut out);
    out
}

fn renders(ws: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut out = BTreeMap::new();
    for scene in SCENES {
        for (rel, bytes) in files_under(&ws.join("scenes").join(scene).join("render")) {
            out.insert(format!("{scene}/{rel}"), bytes);
        }
    }
    out
}

#[test]
fn render_draws_every_view_of_the_refined_layout_the_same_at_any_thread_count() {
    let (_dir, ws) = workspace();
    render(&ws, &["-j", "1"])
        .success()
        .stderr(predicate::str::contains("render: 4 scenes: 4 done"));
    let first = renders(&ws);
    for scene in SCENES {
        for view in ["front", "back", "left", "right", "perspective"] {
            let dir = ws.join("scenes").join(scene).join("render");
            let png = std::fs::read(dir.join(format!("{view}.png"))).expect("png");
            let image = mesa_stages::image_io::decode_png(&png).expect("decodes");
            assert_eq!((image.width, image.height), (160, 120), "{scene} {view}");
            let camera: RenderCameraArtifact = serde_json::from_slice(
                &std::fs::read(dir.join(format!("{view}_camera.json"))).expect("camera"),
            )
            .expect("a camera file");
            assert_eq!(camera.layout.as_deref(), Some("refined/layout.json"));
            assert_eq!(camera.image, format!("{view}.png"));
            // Something of the scene is drawn: most objects are seen from the front.
            let seen = camera.visible_px.values().filter(|px| **px > 0).count();
            assert!(
                seen * 2 > camera.visible_px.len(),
                "{scene} {view}: {seen} seen"
            );
        }
    }
    mesa()
        .arg("validate")
        .arg(ws.join("scenes"))
        .assert()
        .success();
    // Done scenes are skipped; --force redoes them, byte for byte, on two threads.
    render(&ws, &[])
        .success()
        .stderr(predicate::str::contains("4 skipped"));
    render(&ws, &["--force", "-j", "2"]).success();
    assert!(
        renders(&ws) == first,
        "renders differ between -j 1 and -j 2"
    );
    // A changed layout makes its scene stale.
    let layout = ws
        .join("scenes")
        .join(SCENES[0])
        .join("refined/layout.json");
    let mut l = read_layout(&layout);
    l.objects[0].position_cm.0[0] += 5.0;
    std::fs::write(&layout, to_sorted_pretty(&l).expect("json")).expect("write");
    render(&ws, &[])
        .success()
        .stderr(predicate::str::contains("1 done, 3 skipped"));
}

#[test]
fn render_never_falls_back_to_the_coarse_layout_and_names_what_is_wrong() {
    let (_dir, ws) = workspace();
    let scene = ws.join("scenes").join(SCENES[1]);
    std::fs::remove_file(scene.join("refined/layout.json")).expect("remove");
    render(&ws, &[])
        .code(1)
        .stderr(predicate::str::contains(
            "no layout to draw (expected qa/layout.json or refined/layout.json",
        ))
        .stderr(predicate::str::contains("--layout coarse"));
    assert!(!scene.join("render").exists());
    // Asked for explicitly, the coarse layout (none here: nothing was placed) or the truth.
    render(
        &ws,
        &["--layout", "coarse", "--scenes", "dining_table_0001"],
    )
    .code(1)
    .stderr(predicate::str::contains(
        "coarse/layout.json: run `mesa place` first",
    ));
    render(&ws, &["--layout", "truth", "--scenes", "dining_table_0001"]).success();
    let camera: RenderCameraArtifact = serde_json::from_slice(
        &std::fs::read(scene.join("render/front_camera.json")).expect("camera"),
    )
    .expect("camera");
    assert_eq!(camera.layout.as_deref(), Some("truth/layout.json"));

    // An object whose asset is not in the library: named with its uid.
    let other = ws
        .join("scenes")
        .join(SCENES[2])
        .join("refined/layout.json");
    let mut layout = read_layout(&other);
    layout.objects[1].retrieved_uid = "0123456789abcdef0123456789abcdef".into();
    let instance = layout.objects[1].instance.clone();
    std::fs::write(&other, to_sorted_pretty(&layout).expect("json")).expect("write");
    render(&ws, &["--scenes", "kitchen_counter_0001"])
        .code(1)
        .stderr(predicate::str::contains(format!(
        "$.objects[1] ({instance}): asset 0123456789abcdef0123456789abcdef: not in the asset index"
    )));
    // The same uid, recorded by `mesa import` as named by a release that does not ship its GLB:
    // the object is left out with a warning naming it, and the scene is drawn.
    std::fs::write(
        ws.join("assets/import.json"),
        r#"{"uids_missing_glb": ["0123456789abcdef0123456789abcdef"]}"#,
    )
    .expect("import summary");
    render(&ws, &["--scenes", "kitchen_counter_0001"])
        .success()
        .stderr(predicate::str::contains(format!(
            "not drawn: no GLB in assets/library for {instance} (0123456789abcdef0123456789abcdef)"
        )));
    std::fs::remove_file(ws.join("assets/import.json")).expect("remove");
    // A layout of the LLM form has no assets to draw.
    let llm = ws
        .join("scenes")
        .join(SCENES[3])
        .join("refined/layout.json");
    let out = mesa()
        .args(["convert", "--to", "llm"])
        .arg(&llm)
        .output()
        .expect("convert");
    std::fs::write(&llm, out.stdout).expect("write");
    render(&ws, &["--scenes", "office_table_0001"])
        .code(1)
        .stderr(predicate::str::contains(
            "an LLM layout has no assets to draw",
        ));
    // A bad configuration value is refused before any work, naming the key.
    std::fs::write(ws.join("mesa.toml"), "[render]\nsupersampling = 0\n").expect("config");
    render(&ws, &[])
        .code(2)
        .stderr(predicate::str::contains("[render] supersampling = 0"));
}

#[test]
fn asset_views_circle_each_asset_and_are_redone_only_when_it_changes() {
    let (_dir, ws) = workspace();
    let index: Value =
        serde_json::from_slice(&std::fs::read(ws.join("assets/index/assets.json")).expect("index"))
            .expect("json");
    let uid = index["assets"]
        .as_object()
        .expect("assets")
        .keys()
        .next()
        .expect("an asset")
        .clone();
    let glob = format!("{}*", &uid[..6]);
    mesa()
        .args(["render", "--assets", "--uids", &glob, "--progress", "off"])
        .arg(&ws)
        .assert()
        .success()
        .stderr(predicate::str::contains("1 rendered"));
    let dir = ws.join("assets/renders").join(&uid);
    for k in 0..8 {
        let name = format!("view_{:03}", k * 45);
        assert!(dir.join(format!("{name}.png")).is_file(), "{name}");
        let camera: RenderCameraArtifact = serde_json::from_slice(
            &std::fs::read(dir.join(format!("{name}_camera.json"))).expect("camera"),
        )
        .expect("camera");
        assert_eq!(camera.azimuth_deg, Some(45.0 * k as f64));
        assert_eq!(camera.uid.as_deref(), Some(uid.as_str()));
        assert!(
            camera.visible_px[&uid] > 1000,
            "{name}: the asset fills the view"
        );
    }
    mesa()
        .args(["render", "--assets", "--uids", &glob, "--progress", "off"])
        .arg(&ws)
        .assert()
        .success()
        .stderr(predicate::str::contains("0 rendered, 1 current"));
    // A view lost is made again.
    std::fs::remove_file(dir.join("view_090.png")).expect("remove");
    mesa()
        .args(["render", "--assets", "--uids", &glob, "--progress", "off"])
        .arg(&ws)
        .assert()
        .success()
        .stderr(predicate::str::contains("1 rendered"));
    // --assets is for the library, not scenes.
    mesa()
        .args(["render", "--assets", "--layout", "truth"])
        .arg(&ws)
        .assert()
        .code(2);
}

// ---------------------------------------------------------------------------------------------
// The report and its page in Chromium.

fn require_tools() -> bool {
    std::env::var_os("MESA_REQUIRE_TOOLS").is_some()
}

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("workspace root")
        .to_path_buf()
}

/// Runs scripts/check_html.cjs on a page: its JSON report, or `None` (SKIPPED) when node or
/// chromium is missing.
fn check_html(page: &Path, selector: &str) -> Option<Value> {
    let browser = std::env::var("MESA_CHROMIUM").unwrap_or_else(|_| "chromium".to_owned());
    let have = |program: &str, arg: &str| {
        Command::new(program)
            .arg(arg)
            .output()
            .is_ok_and(|o| o.status.success())
    };
    if !have("node", "--version") || !have(&browser, "--version") {
        assert!(
            !require_tools(),
            "node or {browser} is missing and MESA_REQUIRE_TOOLS is set (apt-get install chromium)"
        );
        eprintln!("SKIPPED: the report page in headless Chromium (node or {browser} is missing)");
        return None;
    }
    let out = Command::new("node")
        .arg(repo_root().join("scripts/check_html.cjs"))
        .arg(page)
        .args(["--count", selector])
        .output()
        .expect("node runs");
    assert!(
        matches!(out.status.code(), Some(0 | 1)),
        "check_html.cjs failed to run: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    Some(serde_json::from_slice(&out.stdout).expect("a JSON report"))
}

#[test]
fn the_report_counts_the_dataset_and_its_page_opens_in_chromium_without_errors() {
    let (_dir, ws) = workspace();
    mesa()
        .args(["graph", "--progress", "off"])
        .arg(&ws)
        .assert()
        .success();
    render(&ws, &[]).success();
    // One scene left unrendered: the page says so, without an image.
    let unrendered = ws.join("scenes").join(SCENES[3]).join("render");
    std::fs::remove_dir_all(&unrendered).expect("remove");
    // Two scenes checked (qa/check.json as `mesa check` writes it): one with a collision that
    // settling removed, one clean and not settled; the other two not checked.
    let findings = |colliding: usize| {
        serde_json::json!({
            "collisions": (0..colliding).map(|_| serde_json::json!({"a": "x_0", "b": "y_0", "depth_mm": 4.0})).collect::<Vec<_>>(),
            "floating": [], "zone_violations": [], "pairs_total": 10,
            "collision_rate": colliding as f64 / 10.0, "mesatask_rule_pairs": 0,
            "clean": colliding == 0
        })
    };
    for (scene, colliding, settled) in [(SCENES[0], 1, true), (SCENES[1], 0, false)] {
        let mut check = findings(colliding);
        check["schema"] = "mesa.check/1".into();
        check["layout"] = "refined/layout.json".into();
        if settled {
            check["settle"] = serde_json::json!({
                "status": "settled", "layout": "qa/layout.json", "after": findings(0)
            });
        }
        let path = ws.join("scenes").join(scene).join("qa/check.json");
        std::fs::create_dir_all(path.parent().expect("parent")).expect("mkdir");
        std::fs::write(&path, serde_json::to_vec_pretty(&check).expect("json")).expect("write");
    }
    mesa()
        .arg("report")
        .arg(&ws)
        .assert()
        .success()
        .stderr(predicate::str::contains(
            "report: 4 scenes (1 without a render",
        ));
    let report = ws.join("report");
    let stats: ReportStats =
        serde_json::from_slice(&std::fs::read(report.join("stats.json")).expect("stats"))
            .expect("stats");
    let layouts: Vec<DatasetLayout> = SCENES
        .iter()
        .map(|s| read_layout(&ws.join("scenes").join(s).join("refined/layout.json")))
        .collect();
    let objects: usize = layouts.iter().map(|l| l.objects.len()).sum();
    assert_eq!(stats.scenes, 4);
    assert_eq!(stats.objects, objects as u64);
    assert_eq!(
        stats.layouts,
        BTreeMap::from([("refined/layout.json".into(), 4)])
    );
    assert_eq!(stats.scenes_rendered, 3);
    assert_eq!(stats.collisions.checked, 2);
    assert_eq!(stats.collisions.not_checked, 2);
    assert_eq!(stats.collisions.before.colliding_pairs, 1);
    assert_eq!(stats.collisions.before.pairs, 20);
    let after = stats.collisions.after.as_ref().expect("settling was tried");
    assert_eq!((after.scenes, after.colliding_pairs), (2, 0));
    let categories: BTreeSet<String> = layouts
        .iter()
        .flat_map(|l| l.objects.iter().filter_map(|o| o.category.clone()))
        .collect();
    assert_eq!(stats.categories, categories.len() as u64);
    let edges: u64 = stats
        .relations
        .iter()
        .filter(|(r, _)| *r != "is at" && *r != "face to")
        .map(|(_, n)| n)
        .sum();
    assert!(edges > 0);
    assert_eq!(stats.relations["is at"], objects as u64);
    for plot in [
        "objects_per_scene.svg",
        "categories.svg",
        "table_types.svg",
        "relations.svg",
        "collisions.svg",
    ] {
        let svg = std::fs::read_to_string(report.join(plot)).expect("svg");
        assert!(svg.starts_with("<svg"), "{plot}");
    }
    let page = std::fs::read_to_string(report.join("index.html")).expect("page");
    assert!(page.contains("not checked"));
    assert!(page.contains("1 colliding pairs before settling (rate 0.100)"));
    assert!(page.contains("settled"));
    assert!(page.contains("not rendered"));
    mesa().arg("validate").arg(&report).assert().success();
    // A second report makes no thumbnail again (the file is not even rewritten) unless its front
    // view changed; one whose front view changed is made again. Control: SCENES[1]'s view
    // becomes SCENES[2]'s, and its thumbnail becomes SCENES[2]'s bytes.
    let thumb_of = |scene: &str| report.join("thumbs").join(format!("{scene}.png"));
    let stamp = |path: &Path| {
        let bytes = std::fs::read(path).expect("thumbnail");
        let modified = std::fs::metadata(path)
            .and_then(|m| m.modified())
            .expect("mtime");
        (bytes, modified)
    };
    let first = stamp(&thumb_of(SCENES[0]));
    let second = stamp(&thumb_of(SCENES[1]));
    let front = |scene: &str| ws.join("scenes").join(scene).join("render/front.png");
    std::fs::copy(front(SCENES[2]), front(SCENES[1])).expect("copy");
    std::thread::sleep(std::time::Duration::from_millis(20));
    mesa().arg("report").arg(&ws).assert().success();
    assert_eq!(
        stamp(&thumb_of(SCENES[0])),
        first,
        "an unchanged view's thumbnail was remade"
    );
    let remade = stamp(&thumb_of(SCENES[1]));
    assert_ne!(remade, second);
    assert_eq!(
        remade.0,
        std::fs::read(thumb_of(SCENES[2])).expect("thumbnail")
    );
    // A record of another recipe makes them all again.
    let sources = report.join("thumbs/sources.json");
    let record = std::fs::read_to_string(&sources).expect("sources");
    assert!(record.contains("mesa.thumbnail/"), "{record}");
    std::fs::write(
        &sources,
        record.replace("mesa.thumbnail/", "mesa.thumbnail/0-"),
    )
    .expect("write");
    std::thread::sleep(std::time::Duration::from_millis(20));
    mesa().arg("report").arg(&ws).assert().success();
    let again = stamp(&thumb_of(SCENES[0]));
    assert_eq!(again.0, first.0);
    assert_ne!(again.1, first.1, "another recipe's record was trusted");
    // Every link of the page leads to a file.
    let mut links = 0;
    for piece in page.split("href=\"").skip(1) {
        let target = &piece[..piece.find('"').expect("closing quote")];
        assert!(report.join(target).is_file(), "{target}: no such file");
        links += 1;
    }
    assert!(links > 4 * 5, "{links} links");

    let Some(checked) = check_html(&report.join("index.html"), "[data-scene]") else {
        return;
    };
    assert_eq!(checked["errors"], serde_json::json!([]), "{checked}");
    assert_eq!(checked["count"], 4, "{checked}");
    assert_eq!(checked["images"], 3, "{checked}");
    // A page that lost a thumbnail shows a console error: the check can fail.
    let thumb = report.join("thumbs").join(format!("{}.png", SCENES[0]));
    std::fs::remove_file(&thumb).expect("remove");
    let broken = check_html(&report.join("index.html"), "[data-scene]").expect("checked");
    let errors = broken["errors"].to_string();
    assert!(
        errors.contains("coffee_table_0001.png"),
        "the missing thumbnail went unnoticed: {broken}"
    );
}

#[test]
fn release_writes_the_mesatask_tree_which_reads_back_into_the_refined_layouts() {
    let (_dir, ws) = workspace();
    render(&ws, &[]).success();
    let out = ws.parent().expect("parent").join("release");
    mesa()
        .arg("release")
        .arg(&ws)
        .arg(&out)
        .assert()
        .success()
        .stderr(predicate::str::contains("release: 4 of 4 scenes released"));
    // The tree validates as it is.
    mesa().arg("validate").arg(&out).assert().success();
    let mut uids = BTreeSet::new();
    for scene in SCENES {
        let refined = read_layout(&ws.join("scenes").join(scene).join("refined/layout.json"));
        let dir = out.join("Layout_info").join(scene);
        let text = std::fs::read_to_string(dir.join("layout.json")).expect("layout");
        let value: Value = serde_json::from_str(&text).expect("json");
        assert!(
            value.get("schema").is_none(),
            "{scene}: the release has no schema field"
        );
        for object in value["objects"].as_array().expect("objects") {
            // What the official reader needs of every object.
            assert!(object["retrieved_uid"]
                .as_str()
                .is_some_and(|u| !u.is_empty()));
            assert_eq!(object["scale_factor"].as_array().map(Vec::len), Some(3));
            assert_eq!(object["rotation"].as_array().map(Vec::len), Some(4));
        }
        assert_eq!(read_layout(&dir.join("layout.json")), refined, "{scene}");
        assert_eq!(
            std::fs::read(dir.join("front.png")).expect("png"),
            std::fs::read(ws.join("scenes").join(scene).join("render/front.png")).expect("png"),
        );
        uids.extend(refined.objects.iter().map(|o| o.retrieved_uid.clone()));
    }
    let annotations: BTreeMap<String, Value> = serde_json::from_slice(
        &std::fs::read(out.join("Asset_annotation.json")).expect("annotations"),
    )
    .expect("json");
    let library: BTreeMap<String, Value> = serde_json::from_slice(
        &std::fs::read(ws.join("assets/annotations.json")).expect("annotations"),
    )
    .expect("json");
    // Every annotated asset, not only those used (MesaTask's retrieval reads the library).
    let keys: BTreeSet<String> = annotations.keys().cloned().collect();
    assert!(uids.is_subset(&keys));
    assert_eq!(keys, library.keys().cloned().collect::<BTreeSet<_>>());
    assert!(
        keys.len() > uids.len(),
        "the demo library has unused assets"
    );
    for (uid, entry) in &annotations {
        assert_eq!(entry, &library[uid], "{uid}");
    }

    // A render older than the layout is refused for its scene; the others are released, and
    // the earlier release is replaced.
    let layout = ws
        .join("scenes")
        .join(SCENES[0])
        .join("refined/layout.json");
    let mut l = read_layout(&layout);
    l.objects[0].position_cm.0[1] += 3.0;
    std::fs::write(&layout, to_sorted_pretty(&l).expect("json")).expect("write");
    mesa()
        .arg("release")
        .arg(&ws)
        .arg(&out)
        .assert()
        .code(1)
        .stderr(predicate::str::contains(
            "failed coffee_table/coffee_table_0001",
        ))
        .stderr(predicate::str::contains("run `mesa render` again"));
    assert!(!out.join("Layout_info").join(SCENES[0]).exists());
    assert!(out
        .join("Layout_info")
        .join(SCENES[1])
        .join("layout.json")
        .is_file());

    // A folder that is not a release is never written into.
    let other = ws.parent().expect("parent").join("other");
    std::fs::create_dir_all(&other).expect("mkdir");
    std::fs::write(other.join("notes.txt"), "mine").expect("write");
    mesa()
        .arg("release")
        .arg(&ws)
        .arg(&other)
        .assert()
        .code(2)
        .stderr(predicate::str::contains(
            "not empty and not an earlier release",
        ));
    assert_eq!(std::fs::read_dir(&other).expect("dir").count(), 1);
}

#[test]
fn mesa_run_renders_refined_scenes_lets_the_others_wait_and_reports_at_the_end() {
    let (_dir, ws) = workspace();
    // Two scenes are back from the annotator, two are not.
    for scene in &SCENES[2..] {
        std::fs::remove_file(ws.join("scenes").join(scene).join("refined/layout.json"))
            .expect("remove");
    }
    mesa()
        .args(["run", "--progress", "off"])
        .arg(&ws)
        .assert()
        .success()
        .stderr(predicate::str::contains(
            "render: 4 scenes: 2 done, 0 skipped, 0 failed, 2 waiting, 0 warnings",
        ))
        .stderr(predicate::str::contains("awaiting annotation"))
        .stderr(predicate::str::contains(
            "report: 4 scenes (2 without a render",
        ));
    for (k, scene) in SCENES.iter().enumerate() {
        let front = ws.join("scenes").join(scene).join("render/front.png");
        assert_eq!(front.is_file(), k < 2, "{scene}");
    }
    assert!(ws.join("report/index.html").is_file());
    // A refined layout that comes back is rendered by the next run; the others stay done.
    let scene = ws.join("scenes").join(SCENES[2]);
    std::fs::copy(
        scene.join("truth/layout.json"),
        scene.join("refined/layout.json"),
    )
    .expect("copy");
    mesa()
        .args(["run", "--progress", "off"])
        .arg(&ws)
        .assert()
        .success()
        .stderr(predicate::str::contains(
            "render: 4 scenes: 1 done, 2 skipped, 0 failed, 1 waiting",
        ));
    assert!(scene.join("render/front.png").is_file());
}
