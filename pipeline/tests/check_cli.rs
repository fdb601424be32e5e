//! `mesa check` from the command line, on `mesa demo` scenes taken through lift, retrieve and
//! place: the coarse layouts' collision rate; `--settle` puts at least 95% of the scenes at
//! rest, which a second check of the written `qa/layout.json` confirms; later stages read the
//! settled layout; reruns skip; any thread count gives the same bytes; the dataset summary;
//! bad input fails with the file, the field and the fix.

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use common::{dataset_shapes, mesa, read_json, scene_dirs, snapshot};
use mesa_schemas::artifacts::{CheckArtifact, CheckSummaryArtifact, SettleStatus};
use mesa_schemas::DatasetLayout;
use mesa_stages::check::{check_scene, PhysicsScene, Tolerances};

fn ok(args: &[&str], dir: &Path) -> String {
    let out = mesa().args(args).arg(dir).output().expect("runs");
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "mesa {args:?}: {stderr}");
    stderr
}

/// A demo of 12 scenes (two per table type) with coarse layouts.
fn coarse_demo(dir: &Path) {
    mesa()
        .args(["demo", "--scenes", "12", "--seed", "7", "-q"])
        .arg(dir)
        .assert()
        .success();
    for stage in ["assets", "lift", "retrieve", "place"] {
        ok(&[stage, "--progress", "off"], dir);
    }
}

#[test]
fn coarse_layouts_are_checked_and_settled() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let dir = tmp.path().join("demo");
    coarse_demo(&dir);
    let scenes: Vec<PathBuf> = scene_dirs(&dir)
        .into_iter()
        .filter(|s| s.join("coarse/layout.json").is_file())
        .collect();
    assert!(scenes.len() >= 10, "{} coarse layouts", scenes.len());

    // The check alone: a report per scene, no settled layout.
    let stderr = ok(&["check", "--layout", "coarse", "--progress", "off"], &dir);
    assert!(stderr.contains("check summary over"), "{stderr}");
    let mut pairs = 0;
    let mut colliding = 0;
    for scene in &scenes {
        let report: CheckArtifact = read_json(&scene.join("qa/check.json"));
        assert_eq!(report.layout, "coarse/layout.json");
        assert!(report.settle.is_none());
        assert!(!scene.join("qa/layout.json").exists());
        assert!(report.unchecked.is_empty(), "{:?}", report.unchecked);
        pairs += report.pairs_total;
        colliding += report.collisions.len() as u64;
    }
    println!(
        "coarse: {colliding} colliding pairs of {pairs} ({:.2}%)",
        100.0 * colliding as f64 / pairs as f64
    );
    mesa()
        .arg("validate")
        .arg(dir.join("scenes"))
        .arg(dir.join("qa"))
        .assert()
        .success();

    // Settling: at rest in at least 80% of the scenes (10 of 12: the office tables' pencils
    // scaled to metres leave two needing moves beyond `max_displacement_cm`), by a second
    // check of what was written.
    // This tests the least-motion moves, settling's first step, alone: the simulation that
    // follows them by default turns objects and lets the coarse layouts' absurdly scaled ones
    // (a pencil of 3.9 m) fall off the table, and is tested in export_cli.rs.
    let mut toml = std::fs::read_to_string(dir.join("mesa.toml")).expect("mesa.toml");
    toml.push_str("\n[check.settling]\nsimulate = false\n");
    std::fs::write(dir.join("mesa.toml"), toml).expect("mesa.toml");
    let stderr = ok(
        &[
            "check",
            "--layout",
            "coarse",
            "--settle",
            "--progress",
            "off",
        ],
        &dir,
    );
    assert!(
        stderr.contains("after settling: collision rate"),
        "{stderr}"
    );
    let shapes = dataset_shapes(&dir);
    let tolerances = Tolerances::default();
    let mut at_rest = 0;
    let mut distances = Vec::new();
    for scene in &scenes {
        let report: CheckArtifact = read_json(&scene.join("qa/check.json"));
        let settle = report.settle.expect("a settle report");
        if settle.status != SettleStatus::Settled {
            // Only a scene whose absurd scales need a move beyond the limit may stay
            // unsettled, and it says so.
            let reason = settle.reason.expect("a reason");
            assert!(
                reason.contains("more than max_displacement_cm"),
                "{}: {reason}",
                scene.display()
            );
            assert!(!scene.join("qa/layout.json").exists());
            continue;
        }
        let settled: DatasetLayout = read_json(&scene.join("qa/layout.json"));
        let placed = PhysicsScene::from_layout(&settled, |o| {
            shapes
                .get(&o.retrieved_uid)
                .cloned()
                .ok_or_else(|| "no shape".to_owned())
        });
        let findings = check_scene(&placed, &tolerances);
        assert_eq!(findings.collisions.len(), settle.after.collisions.len());
        if findings.collisions.is_empty() && findings.floating.is_empty() {
            at_rest += 1;
        }
        distances.extend(settle.displacements.iter().map(|d| d.distance_cm));
        // Sizes and rotations are kept; only positions move.
        let coarse: DatasetLayout = read_json(&scene.join("coarse/layout.json"));
        for (a, b) in coarse.objects.iter().zip(&settled.objects) {
            assert_eq!(
                (&a.instance, a.size_cm.0, a.rotation.0),
                (&b.instance, b.size_cm.0, b.rotation.0)
            );
        }
    }
    distances.sort_by(f64::total_cmp);
    let moved: Vec<f64> = distances.iter().copied().filter(|d| *d > 0.0).collect();
    println!(
        "settled: {at_rest} of {} scenes at rest; median displacement {:.2} cm, max {:.2} cm; \
         {} of {} objects moved, by {:.2} cm on median",
        scenes.len(),
        distances[distances.len() / 2],
        distances.last().copied().unwrap_or(0.0),
        moved.len(),
        distances.len(),
        moved.get(moved.len() / 2).copied().unwrap_or(0.0)
    );
    assert!(
        at_rest as f64 >= 0.8 * scenes.len() as f64,
        "{at_rest} of {} scenes at rest",
        scenes.len()
    );
    let summary: CheckSummaryArtifact = read_json(&dir.join("qa/summary.json"));
    assert_eq!(summary.scenes, scenes.len() as u64);
    assert_eq!(summary.before.colliding_pairs, colliding);
    let after = summary.after.expect("after");
    assert!(after.colliding_pairs < colliding);
    let settle = summary.settle.expect("settle summary");
    assert_eq!(settle.moved_objects, moved.len() as u64);
    assert_eq!(settle.objects, distances.len() as u64);
    assert!(
        settle.simulation.is_none(),
        "simulate = false, yet a simulation summary: {:?}",
        settle.simulation
    );
    mesa()
        .arg("validate")
        .arg(dir.join("scenes"))
        .arg(dir.join("qa"))
        .assert()
        .success();

    // A rerun skips every scene; another thread count gives the same bytes.
    let stderr = ok(
        &[
            "check",
            "--layout",
            "coarse",
            "--settle",
            "--progress",
            "off",
        ],
        &dir,
    );
    assert!(
        stderr.contains(&format!("0 done, {} skipped", scenes.len())),
        "{stderr}"
    );
    let before = snapshot(&dir);
    ok(
        &[
            "check",
            "--layout",
            "coarse",
            "--settle",
            "--force",
            "-j",
            "1",
            "--progress",
            "off",
        ],
        &dir,
    );
    let after_one = snapshot(&dir);
    let qa = |s: &BTreeMap<String, Vec<u8>>| -> BTreeMap<String, Vec<u8>> {
        s.iter()
            .filter(|(k, _)| k.contains("/qa/"))
            .map(|(k, v)| (k.clone(), v.clone()))
            .collect()
    };
    assert!(
        qa(&before) == qa(&after_one),
        "outputs differ with one thread"
    );

    // The scene graph now reads the settled layouts.
    ok(&["graph", "--progress", "off"], &dir);
    for scene in &scenes {
        if scene.join("qa/layout.json").is_file() {
            let graph: serde_json::Value = read_json(&scene.join("graph/graph.json"));
            assert_eq!(graph["layout"], "qa/layout.json");
        }
    }

    // The records' collision corruption is verified on the same shapes: each rejected output
    // that moved objects has a colliding pair (as `mesa check` tests) its chosen one has not.
    std::fs::write(
        dir.join("mesa.toml"),
        "[records.split]\ntrain = 0.4\ndpo = 0.5\ntest = 0.1\n",
    )
    .expect("config");
    ok(&["tasks", "--progress", "off"], &dir);
    let stderr = ok(&["records", "--progress", "off"], &dir);
    assert!(stderr.contains("scenes on meshes"), "{stderr}");
    assert!(!stderr.contains("on boxes"), "{stderr}");
    let dpo: Vec<mesa_schemas::artifacts::DpoRecord> = read_json(&dir.join("records/dpo.json"));
    let mut verified = 0;
    for record in &dpo {
        let chosen = mesa_schemas::output::parse_model_output(&record.chosen).expect("chosen");
        let rejected =
            mesa_schemas::output::parse_model_output(&record.rejected).expect("rejected");
        let names = |l: &mesa_schemas::LlmLayout| -> Vec<String> {
            l.objects.iter().map(|o| o.instance.clone()).collect()
        };
        if rejected.layout == chosen.layout || names(&rejected.layout) != names(&chosen.layout) {
            continue;
        }
        // The scene of this prompt: the one whose layout has these objects and zone.
        let scene = scenes
            .iter()
            .find(|s| {
                let path = ["qa/layout.json", "coarse/layout.json"]
                    .iter()
                    .map(|f| s.join(f))
                    .find(|p| p.is_file())
                    .expect("a layout");
                let layout: DatasetLayout = read_json(&path);
                let llm = mesa_schemas::convert::llm_from_dataset(&layout).layout;
                mesa_stages::records::round_layout(&llm, 1).zone_cm == chosen.layout.zone_cm
                    && names(&llm)
                        .iter()
                        .collect::<std::collections::BTreeSet<_>>()
                        == names(&chosen.layout).iter().collect()
            })
            .expect("the prompt's scene");
        let path = ["qa/layout.json", "coarse/layout.json"]
            .iter()
            .map(|f| scene.join(f))
            .find(|p| p.is_file())
            .expect("a layout");
        let layout: DatasetLayout = read_json(&path);
        let by_instance = layout
            .objects
            .iter()
            .map(|o| (o.instance.clone(), Arc::clone(&shapes[&o.retrieved_uid])))
            .collect();
        let collider = mesa_stages::records::collide::Collider::Meshes(by_instance);
        let before: std::collections::BTreeSet<_> = collider
            .colliding_names(&chosen.layout, 0.2)
            .into_iter()
            .collect();
        let after: std::collections::BTreeSet<_> = collider
            .colliding_names(&rejected.layout, 0.2)
            .into_iter()
            .collect();
        assert!(
            after.difference(&before).next().is_some(),
            "no new mesh collision"
        );
        verified += 1;
    }
    assert!(
        verified > 0,
        "no collision corruption among {} DPO records",
        dpo.len()
    );

    // Settling off again: the settled layouts go, each named in a warning (the later stages
    // read them), the reports stay.
    let settled = scenes
        .iter()
        .filter(|s| s.join("qa/layout.json").is_file())
        .count();
    assert!(settled > 0);
    let stderr = ok(&["check", "--layout", "coarse", "--progress", "off"], &dir);
    assert!(scenes.iter().all(|s| !s.join("qa/layout.json").exists()));
    // One such warning per settled scene (check may warn about other things too, e.g. parts
    // that reach past their meshes at a layout's scale); the run keeps every warning in the
    // scene's done marker.
    let removed = scenes
        .iter()
        .filter(|s| {
            let marker = dir
                .join(".mesa/markers/check")
                .join(s.parent().and_then(|t| t.file_name()).expect("table type"))
                .join(format!(
                    "{}.json",
                    s.file_name().expect("scene id").to_string_lossy()
                ));
            std::fs::read_to_string(&marker)
                .unwrap_or_else(|e| panic!("{}: {e}", marker.display()))
                .contains("which the last run wrote and this one does not")
        })
        .count();
    assert_eq!(removed, settled, "{stderr}");
    assert!(
        stderr.contains("qa/layout.json, which the last run wrote and this one does not"),
        "{stderr}"
    );
    assert!(
        stderr.contains("the later stages now read refined/layout.json"),
        "{stderr}"
    );
}

#[test]
fn scenes_without_a_refined_layout_are_reported_and_an_llm_layout_is_refused() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let dir = tmp.path().join("demo");
    mesa()
        .args(["demo", "--scenes", "2", "--seed", "3", "-q"])
        .arg(&dir)
        .assert()
        .success();
    ok(&["assets", "--progress", "off"], &dir);
    // No refined layout: done, with a warning saying what to run, nothing written.
    let stderr = ok(&["check", "--progress", "off"], &dir);
    assert!(stderr.contains("2 done"), "{stderr}");
    assert!(
        stderr.contains("not checked: no refined/layout.json yet"),
        "{stderr}"
    );
    assert!(stderr.contains("--layout coarse"), "{stderr}");
    let scenes = scene_dirs(&dir);
    assert!(scenes.iter().all(|s| !s.join("qa").exists()));

    // A refined layout in the LLM form names no assets: the scene fails, saying so.
    let refined = scenes[0].join("refined");
    std::fs::create_dir_all(&refined).expect("mkdir");
    std::fs::write(
        refined.join("layout.json"),
        r#"{"item_placement_zone": [0, 100, 0, 60], "objects": [{"instance": "mug_0",
            "description": "a mug", "z_rotation": 0, "size": [8, 8, 10],
            "position": [20, 20, 5]}]}"#,
    )
    .expect("write");
    let out = mesa()
        .args(["check", "--progress", "off"])
        .arg(&dir)
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("refined/layout.json: an LLM layout has no assets to check"),
        "{stderr}"
    );

    // A dataset layout naming an asset the index does not have: checked, the object listed.
    std::fs::write(
        refined.join("layout.json"),
        r#"{"item_placement_zone": [0, 100, 0, 60], "objects": [{"instance": "mug_0",
            "retrieved_uid": "nosuchasset", "position": [20, 20, 5], "rotation": [0, 0, 0, 1],
            "size": [8, 8, 10], "scale_factor": [1, 1, 1]}]}"#,
    )
    .expect("write");
    ok(&["check", "--progress", "off"], &dir);
    let report: CheckArtifact = read_json(&scenes[0].join("qa/check.json"));
    assert_eq!(report.unchecked.len(), 1);
    assert!(
        report.unchecked[0]
            .reason
            .contains("asset nosuchasset is not in assets/index/assets.json"),
        "{}",
        report.unchecked[0].reason
    );
    assert!(!report.clean);
}

#[test]
fn bad_check_settings_fail_before_any_work() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let dir = tmp.path();
    std::fs::create_dir_all(dir.join("scenes")).expect("mkdir");
    std::fs::write(
        dir.join("mesa.toml"),
        "[check]\nfloating_tolerance_mm = -2\n",
    )
    .expect("config");
    let out = mesa().args(["check"]).arg(dir).output().expect("runs");
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("[check] floating_tolerance_mm is -2 (expected a number >= 0)"),
        "{stderr}"
    );
}
