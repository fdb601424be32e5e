//! The annotator round trip from the command line: `mesa pack`, the demo's simulated
//! annotator, `mesa ingest`, the refined layouts against the demo's truth, scenes awaiting
//! their annotator, and damaged edited files failing alone.
//!
//! The pack GLBs also go through the Khronos glTF validator when it is installed (a check
//! whose tool is missing says SKIPPED, and fails when `MESA_REQUIRE_TOOLS` is set, as in CI).

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command as Process;

use common::{mesa, scene_dirs};
use mesa_schemas::annotation::{IngestDiffArtifact, PackIndexArtifact};
use mesa_schemas::layout::DatasetLayout;
use mesa_schemas::rotation::{tilt_deg_from_quat_xyzw, yaw_deg_from_quat_xyzw};

fn read<T: serde::de::DeserializeOwned>(path: &Path) -> T {
    serde_json::from_slice(
        &std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
    )
    .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn run(args: &[&str], dir: &Path) -> (Option<i32>, String) {
    let out = mesa().args(args).arg(dir).output().expect("runs");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn scene_id(scene: &Path) -> String {
    scene
        .file_name()
        .expect("a name")
        .to_string_lossy()
        .into_owned()
}

fn require_tools() -> bool {
    std::env::var_os("MESA_REQUIRE_TOOLS").is_some()
}

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("workspace root")
        .to_path_buf()
}

/// Validates GLB files with the Khronos validator: every file 0 errors (and, ours, 0
/// warnings). Skipped (or failed under MESA_REQUIRE_TOOLS) without node and the package.
fn validate_glbs(files: &[PathBuf]) {
    let node_ok = Process::new("node")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !node_ok
        || !repo_root()
            .join("scripts/node_modules/gltf-validator")
            .is_dir()
    {
        let how = "needs node and scripts/node_modules/gltf-validator: run `npm ci` in scripts/";
        assert!(!require_tools(), "glTF validator missing ({how})");
        eprintln!("SKIPPED: glTF validator check of the pack GLBs ({how})");
        return;
    }
    let out = Process::new("node")
        .arg(repo_root().join("scripts/validate_glb.cjs"))
        .args(files)
        .output()
        .expect("node runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}");
    let lines: Vec<serde_json::Value> = stdout
        .lines()
        .map(|l| serde_json::from_str(l).expect("a JSON line"))
        .collect();
    assert_eq!(lines.len(), files.len());
    for line in lines {
        assert_eq!(line["errors"], 0, "{line}");
        assert_eq!(line["warnings"], 0, "{line}");
    }
}

/// Pairs each refined object with the true object nearest to it (the retrieved asset may
/// differ from the true one: the annotator fixes size and place, not the asset), and returns
/// the worst position (mm) and rotation (degrees) errors, and the worst yaw error of the
/// objects that are not tilted.
fn compare_with_truth(refined: &DatasetLayout, truth: &DatasetLayout) -> (f64, f64, f64) {
    let mut free: Vec<&mesa_schemas::LayoutObject> = truth.objects.iter().collect();
    let (mut position_mm, mut rotation_deg, mut yaw_deg) = (0.0f64, 0.0f64, 0.0f64);
    assert_eq!(refined.objects.len(), truth.objects.len());
    for object in &refined.objects {
        let (k, true_object) = free
            .iter()
            .enumerate()
            .min_by(|(_, a), (_, b)| {
                let d = |t: &mesa_schemas::LayoutObject| {
                    (0..3)
                        .map(|i| (t.position_cm.0[i] - object.position_cm.0[i]).powi(2))
                        .sum::<f64>()
                };
                d(a).total_cmp(&d(b))
            })
            .unwrap_or_else(|| panic!("{}: no true object left", object.instance));
        let distance_cm = (0..3)
            .map(|i| (true_object.position_cm.0[i] - object.position_cm.0[i]).powi(2))
            .sum::<f64>()
            .sqrt();
        position_mm = position_mm.max(distance_cm * 10.0);
        let dot: f64 = (0..4)
            .map(|i| true_object.rotation.0[i] * object.rotation.0[i])
            .sum();
        rotation_deg = rotation_deg.max(2.0 * dot.abs().min(1.0).acos().to_degrees());
        if tilt_deg_from_quat_xyzw(true_object.rotation.0) < 1.0 {
            let d = mesa_schemas::rotation::normalize_deg(
                yaw_deg_from_quat_xyzw(object.rotation.0)
                    - yaw_deg_from_quat_xyzw(true_object.rotation.0),
            );
            yaw_deg = yaw_deg.max(d.abs());
        }
        free.remove(k);
    }
    (position_mm, rotation_deg, yaw_deg)
}

#[test]
fn the_simulated_annotator_and_ingest_reproduce_the_truth() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ws = dir.path().join("demo");
    mesa()
        .args(["demo", "--scenes", "6", "--seed", "7", "-q"])
        .arg(&ws)
        .assert()
        .success();
    let config = std::fs::read_to_string(ws.join("mesa.toml")).expect("mesa.toml");
    assert!(config.contains("annotator = \"simulated\""), "{config}");
    let (code, stderr) = run(&["run", "--progress", "off"], &ws);
    assert_eq!(code, Some(0), "{stderr}");
    for stage in ["pack", "annotate", "ingest", "graph", "tasks"] {
        assert!(
            stderr.contains(&format!("{stage}: 6 scenes: 6 done")),
            "{stage}: {stderr}"
        );
    }
    let mut packs = Vec::new();
    let (mut added, mut removed) = (0, 0);
    let (mut worst_mm, mut worst_deg) = (0.0f64, 0.0f64);
    for scene in scene_dirs(&ws) {
        let id = scene_id(&scene);
        let refined: DatasetLayout = read(&scene.join("refined/layout.json"));
        let truth: DatasetLayout = read(&scene.join("truth/layout.json"));
        let (position_mm, rotation_deg, yaw_deg) = compare_with_truth(&refined, &truth);
        worst_mm = worst_mm.max(position_mm);
        worst_deg = worst_deg.max(rotation_deg);
        assert!(
            position_mm < 1.0,
            "{id}: a position is {position_mm} mm off"
        );
        assert!(yaw_deg < 0.1, "{id}: a yaw is {yaw_deg}° off");
        assert!(
            rotation_deg < 0.1,
            "{id}: a rotation is {rotation_deg}° off"
        );
        for i in [1, 3] {
            assert!(
                (refined.zone_cm.0[i] - truth.zone_cm.0[i]).abs() < 0.1,
                "{id}: zone {:?} vs {:?}",
                refined.zone_cm,
                truth.zone_cm
            );
        }
        assert_eq!(
            refined.restricted_zone_cm.is_some(),
            truth.restricted_zone_cm.is_some(),
            "{id}: the sink"
        );
        let diff: IngestDiffArtifact = read(&scene.join("refined/diff.json"));
        assert_eq!(
            diff.generator.as_deref(),
            Some("Khronos glTF Blender I/O v4.3.47")
        );
        added += diff.added.len();
        removed += diff.removed.len();
        assert!(diff.table.resized, "{id}: the annotator fits the table top");
        let index: PackIndexArtifact = read(&scene.join("pack/index.json"));
        assert_eq!(index.scene_id, id);
        for object in index.objects.values() {
            let snapshot = object.snapshot.as_ref().expect("a snapshot");
            assert!(scene.join("pack").join(snapshot).is_file());
        }
        for file in ["README.txt", "reference.png"] {
            assert!(scene.join("pack").join(file).is_file(), "{id}: {file}");
        }
        packs.push(scene.join(format!("pack/{id}.glb")));
        packs.push(scene.join(format!("refined/{id}.glb")));
    }
    eprintln!(
        "refined vs truth over 6 scenes: worst position {worst_mm:.6} mm, worst rotation \
         {worst_deg:.6}°; {added} copies added, {removed} objects deleted"
    );
    // Over six scenes the annotator made copies (`.001`) and deleted objects.
    assert!(added > 0 && removed > 0, "added {added}, removed {removed}");
    validate_glbs(&packs);
    // Every artifact validates.
    mesa()
        .arg("validate")
        .arg(ws.join("scenes"))
        .assert()
        .success();
    // Packs are byte-identical when redone, at any thread count.
    let before: BTreeMap<PathBuf, Vec<u8>> = packs
        .iter()
        .map(|p| (p.clone(), std::fs::read(p).expect("read")))
        .collect();
    let (code, stderr) = run(
        &["pack", "--force", "--jobs", "1", "--progress", "off"],
        &ws,
    );
    assert_eq!(code, Some(0), "{stderr}");
    for (path, bytes) in &before {
        assert!(
            std::fs::read(path).expect("read") == *bytes,
            "{} changed",
            path.display()
        );
    }
}

/// A demo dataset whose packs a person edits (the default annotator): packed, not annotated.
fn human_workspace(dir: &Path) -> PathBuf {
    let ws = dir.join("demo");
    mesa()
        .args(["demo", "--scenes", "2", "--seed", "3", "-q"])
        .arg(&ws)
        .assert()
        .success();
    std::fs::write(ws.join("mesa.toml"), "[annotate]\nannotator = \"human\"\n").expect("toml");
    ws
}

#[test]
fn scenes_wait_for_their_annotator_and_go_on_when_the_edit_arrives() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ws = human_workspace(dir.path());
    let (code, stderr) = run(&["run", "--progress", "off"], &ws);
    assert_eq!(code, Some(0), "awaiting scenes are not failures: {stderr}");
    assert!(!stderr.contains("annotate:"), "{stderr}");
    assert!(
        stderr.contains("ingest: 2 scenes: 0 done, 0 skipped, 0 failed, 2 waiting"),
        "{stderr}"
    );
    assert!(
        stderr.contains(
            "waiting office_table/office_table_0001: awaiting annotation: send \
             scenes/office_table/office_table_0001/pack/office_table_0001.glb"
        ),
        "{stderr}"
    );
    for stage in ["graph", "tasks"] {
        assert!(
            stderr.contains(&format!(
                "{stage}: 2 scenes: 0 done, 0 skipped, 0 failed, 2 waiting"
            )),
            "{stage}: {stderr}"
        );
    }
    assert!(
        stderr.contains("records: not built: all 2 scenes await annotation"),
        "{stderr}"
    );
    let office = ws.join("scenes/office_table/office_table_0001");
    assert!(
        !office.join("graph").exists(),
        "no graph from the coarse layout"
    );
    let out = mesa().arg("status").arg(&ws).output().expect("runs");
    let status = String::from_utf8_lossy(&out.stdout);
    assert!(status.contains("2 scenes wait"), "{status}");
    assert!(
        status.contains("pack/office_table_0001.glb"),
        "the pack to send: {status}"
    );

    // The annotator returns the scene unedited: ingest gives back the coarse layout byte for
    // byte, and the later stages go on for that scene only.
    std::fs::create_dir_all(office.join("refined")).expect("mkdir");
    std::fs::copy(
        office.join("pack/office_table_0001.glb"),
        office.join("refined/office_table_0001.glb"),
    )
    .expect("copy");
    let (code, stderr) = run(&["run", "--progress", "off"], &ws);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(
        stderr.contains("ingest: 2 scenes: 1 done, 0 skipped, 0 failed, 1 waiting"),
        "{stderr}"
    );
    assert!(stderr.contains("graph: 2 scenes: 1 done"), "{stderr}");
    assert_eq!(
        std::fs::read(office.join("refined/layout.json")).expect("refined"),
        std::fs::read(office.join("coarse/layout.json")).expect("coarse"),
        "pack → ingest without edits is the coarse layout"
    );
    let diff: IngestDiffArtifact = read(&office.join("refined/diff.json"));
    assert!(diff.objects.iter().all(|o| o.status == "unchanged"));
    assert_eq!(
        read::<serde_json::Value>(&office.join("graph/graph.json"))["layout"],
        "refined/layout.json"
    );

    // `mesa demo annotate` plays the annotator on the other scene.
    let (code, stderr) = run(&["demo", "annotate", "--progress", "off"], &ws);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(ws
        .join("scenes/dining_table/dining_table_0001/refined/dining_table_0001.glb")
        .is_file());
    // Re-packing under an annotator's file made from another layout is refused.
    let coarse = office.join("coarse/layout.json");
    let text = std::fs::read_to_string(&coarse).expect("coarse");
    std::fs::write(&coarse, text.replacen("\"objects\"", "\"objects\" ", 1)).expect("touch");
    let (code, stderr) = run(&["pack", "--progress", "off"], &ws);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains("was made from the pack of an earlier coarse/layout.json"),
        "{stderr}"
    );
}

#[test]
fn a_damaged_edited_file_fails_its_scene_alone_with_no_output() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ws = human_workspace(dir.path());
    let (code, stderr) = run(&["run", "--progress", "off"], &ws);
    assert_eq!(code, Some(0), "{stderr}");
    let scenes = scene_dirs(&ws);
    for (k, scene) in scenes.iter().enumerate() {
        let id = scene_id(scene);
        let pack = std::fs::read(scene.join(format!("pack/{id}.glb"))).expect("pack");
        let refined = if k == 0 {
            pack[..pack.len() - 100].to_vec()
        } else {
            pack
        };
        std::fs::create_dir_all(scene.join("refined")).expect("mkdir");
        std::fs::write(scene.join(format!("refined/{id}.glb")), refined).expect("write");
    }
    let (code, stderr) = run(&["ingest", "--progress", "off"], &ws);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(stderr.contains("1 done, 0 skipped, 1 failed"), "{stderr}");
    let bad = scene_id(&scenes[0]);
    assert!(
        stderr.contains(&format!(
            "refined/{bad}.glb: GLB_UNEXPECTED_END_OF_CHUNK_DATA"
        )),
        "{stderr}"
    );
    assert!(!scenes[0].join("refined/layout.json").exists());
    assert!(!scenes[0].join("refined/diff.json").exists());
    assert!(scenes[1].join("refined/layout.json").is_file());
}

#[test]
fn a_failed_ingest_is_reported_by_later_stages_as_failed_not_as_not_ingested_yet() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ws = human_workspace(dir.path());
    let (code, stderr) = run(&["run", "--progress", "off"], &ws);
    assert_eq!(code, Some(0), "{stderr}");
    let scenes = scene_dirs(&ws);
    for (k, scene) in scenes.iter().enumerate() {
        let id = scene_id(scene);
        let pack = std::fs::read(scene.join(format!("pack/{id}.glb"))).expect("pack");
        let refined = if k == 0 {
            pack[..pack.len() - 100].to_vec()
        } else {
            pack
        };
        std::fs::create_dir_all(scene.join("refined")).expect("mkdir");
        std::fs::write(scene.join(format!("refined/{id}.glb")), refined).expect("write");
    }
    let bad = scene_id(&scenes[0]);
    // Control: an edit that was never ingested is "not ingested yet".
    let (code, stderr) = run(&["graph", "--progress", "off"], &ws);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(
        stderr.contains(&format!("refined/{bad}.glb is in but not ingested yet")),
        "{stderr}"
    );
    let (code, stderr) = run(&["ingest", "--progress", "off"], &ws);
    assert_eq!(code, Some(1), "{stderr}");
    // Once its ingest failed, the later stages say so, with the error and where it is kept;
    // the other scene goes on.
    let (code, stderr) = run(&["graph", "--progress", "off"], &ws);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(stderr.contains("graph: 2 scenes: 1 done"), "{stderr}");
    assert!(!stderr.contains("not ingested yet"), "{stderr}");
    let marker = format!(".mesa/markers/ingest/{}/{bad}.json", {
        let table = scenes[0].parent().expect("table folder");
        table
            .file_name()
            .expect("name")
            .to_string_lossy()
            .into_owned()
    });
    for expected in [
        "ingest failed: ",
        &format!("refined/{bad}.glb: GLB_UNEXPECTED_END_OF_CHUNK_DATA"),
        &marker,
        "fix the edited scene scenes/",
        "and run `mesa ingest` again",
    ] {
        assert!(stderr.contains(expected), "{expected}: {stderr}");
    }
    let out = mesa().arg("status").arg(&ws).output().expect("runs");
    let status = String::from_utf8_lossy(&out.stdout);
    assert!(!status.contains("not ingested yet"), "{status}");
}

/// A GLB with its JSON chunk edited by `edit` (the BIN chunk kept as it is).
fn edit_glb_json(glb: &[u8], edit: impl FnOnce(&mut serde_json::Value)) -> Vec<u8> {
    let json_len = u32::from_le_bytes(glb[12..16].try_into().expect("4 bytes")) as usize;
    let mut json: serde_json::Value =
        serde_json::from_slice(&glb[20..20 + json_len]).expect("JSON chunk");
    edit(&mut json);
    let rest = &glb[20 + json_len..];
    let mut text = serde_json::to_vec(&json).expect("json");
    while text.len() % 4 != 0 {
        text.push(b' ');
    }
    let mut out = b"glTF".to_vec();
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&((12 + 8 + text.len() + rest.len()) as u32).to_le_bytes());
    out.extend_from_slice(&(text.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&text);
    out.extend_from_slice(rest);
    out
}

#[test]
fn an_absurd_scale_fails_its_scene_alone_naming_the_file_the_node_and_the_fix() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ws = human_workspace(dir.path());
    let (code, stderr) = run(&["run", "--progress", "off"], &ws);
    assert_eq!(code, Some(0), "{stderr}");
    let scenes = scene_dirs(&ws);
    let mut scaled = String::new();
    for (k, scene) in scenes.iter().enumerate() {
        let id = scene_id(scene);
        let pack = std::fs::read(scene.join(format!("pack/{id}.glb"))).expect("pack");
        let refined = if k == 0 {
            edit_glb_json(&pack, |j| {
                // The first object node of the pack (not the table, the zone or the figure).
                let nodes = j["nodes"].as_array_mut().expect("nodes");
                let node = nodes
                    .iter_mut()
                    .find(|n| {
                        n["mesh"].is_u64()
                            && !["table", "restricted_zone", "H1_reference"]
                                .contains(&n["name"].as_str().unwrap_or(""))
                    })
                    .expect("an object node");
                scaled = node["name"].as_str().expect("name").to_owned();
                node["scale"] = serde_json::json!([1e30, 1e30, 1e30]);
            })
        } else {
            pack
        };
        std::fs::create_dir_all(scene.join("refined")).expect("mkdir");
        std::fs::write(scene.join(format!("refined/{id}.glb")), refined).expect("write");
    }
    let (code, stderr) = run(&["ingest", "--progress", "off"], &ws);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(stderr.contains("1 done, 0 skipped, 1 failed"), "{stderr}");
    let bad = scene_id(&scenes[0]);
    for expected in [
        format!("refined/{bad}.glb: nodes["),
        format!("\"{scaled}\".scale: the object is "),
        "[ingest] max_size_over_table".to_owned(),
        "(fix: scale the object back".to_owned(),
    ] {
        assert!(stderr.contains(&expected), "{expected}: {stderr}");
    }
    assert!(!scenes[0].join("refined/layout.json").exists());
    assert!(scenes[1].join("refined/layout.json").is_file());
}
