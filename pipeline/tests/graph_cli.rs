//! End-to-end tests of `mesa graph`: one layout file (`--layout`, every form, `--containers`,
//! `--equally-spaced`, malformed input) and whole datasets (which layout is read, annotations,
//! skip-done and redo, failures that stay with their scene). Published records are read from
//! ../shared/realdata (or $MESA_SHARED).

mod common;

use common::{gallery, mesa};

use std::path::{Path, PathBuf};

use mesa_schemas::convert::dataset_from_llm;
use mesa_schemas::json::to_sorted_pretty;
use mesa_schemas::{DatasetLayout, GalleryRecord, LlmLayout};
use predicates::prelude::*;
use serde_json::{json, Value};

fn gallery_layout(path: &Path) -> LlmLayout {
    let record: GalleryRecord =
        serde_json::from_str(&std::fs::read_to_string(path).expect("read")).expect("record");
    record.scene_layout_json.resolve().expect("layout")
}

/// The dataset form of an LLM layout, objects in the same order, each with a `retrieved_uid`
/// of `uid-<instance>`.
fn dataset_of(llm: &LlmLayout) -> DatasetLayout {
    let mut dataset = dataset_from_llm(llm).layout;
    for object in &mut dataset.objects {
        object.retrieved_uid = format!("uid-{}", object.instance);
    }
    dataset
}

fn write_bytes(path: &Path, bytes: &[u8]) {
    std::fs::create_dir_all(path.parent().expect("parent")).expect("mkdir");
    std::fs::write(path, bytes).expect("write");
}

fn write_json(path: &Path, value: &Value) {
    write_bytes(path, &serde_json::to_vec_pretty(value).expect("json"));
}

fn write_dataset_layout(path: &Path, layout: &DatasetLayout) {
    write_bytes(path, &to_sorted_pretty(layout).expect("json"));
}

fn stdout_of(args: &[&str], file: &Path) -> String {
    let out = mesa().args(args).arg(file).output().expect("runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("utf8")
}

fn llm_object(instance: &str, size: [f64; 3], position: [f64; 3]) -> Value {
    json!({"instance": instance, "size": size, "position": position, "z_rotation": 0.0,
           "description": ""})
}

/// tray_0 with apple_0 on its surface (held only if the tray counts as a container), and
/// lemon_0 in bowl_0.
fn tray_scene() -> Value {
    json!({
        "item_placement_zone": [0.0, 100.0, 0.0, 60.0],
        "objects": [
            llm_object("tray_0", [40.0, 30.0, 4.0], [30.0, 30.0, 2.0]),
            llm_object("bowl_0", [12.0, 12.0, 6.0], [80.0, 30.0, 3.0]),
            llm_object("apple_0", [6.0, 6.0, 6.0], [30.0, 30.0, 3.0]),
            llm_object("lemon_0", [5.0, 5.0, 5.0], [80.0, 30.0, 3.5]),
        ]
    })
}

// --- one layout file -------------------------------------------------------------------------

#[test]
fn layout_prints_the_same_triplets_from_every_form() {
    let dir = tempfile::tempdir().expect("tempdir");
    for record in gallery() {
        let from_record = stdout_of(&["graph", "--layout"], &record);
        let llm = gallery_layout(&record);
        let llm_path = dir.path().join("llm.json");
        write_bytes(&llm_path, &serde_json::to_vec_pretty(&llm).expect("json"));
        let dataset_path = dir.path().join("dataset.json");
        write_dataset_layout(&dataset_path, &dataset_of(&llm));
        assert_eq!(stdout_of(&["graph", "--layout"], &llm_path), from_record);
        assert_eq!(
            stdout_of(&["graph", "--layout"], &dataset_path),
            from_record
        );
        // Two lines per object first, in layout order, then the edges; a trailing newline.
        let lines: Vec<&str> = from_record.lines().collect();
        assert!(from_record.ends_with(")\n"));
        for (i, object) in llm.objects.iter().enumerate() {
            assert!(lines[2 * i].starts_with(&format!("({}, is at, ", object.instance)));
            assert!(lines[2 * i + 1].starts_with(&format!("({}, face to, ", object.instance)));
        }
        assert!(lines.len() > 2 * llm.objects.len(), "{}", record.display());
    }
}

#[test]
fn containers_are_named_by_instance_or_category() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("tray.json");
    write_json(&path, &tray_scene());
    let in_lines = |containers: Option<&str>| -> Vec<String> {
        let mut args = vec!["graph"];
        let list;
        if let Some(c) = containers {
            list = format!("--containers={c}");
            args.push(&list);
        }
        args.push("--layout");
        stdout_of(&args, &path)
            .lines()
            .filter(|l| l.contains(", in, "))
            .map(str::to_owned)
            .collect()
    };
    // The keyword rule: a bowl holds, a tray does not.
    assert_eq!(in_lines(None), ["(lemon_0, in, bowl_0)"]);
    assert!(in_lines(Some("")).is_empty());
    assert_eq!(in_lines(Some("tray_0")), ["(apple_0, in, tray_0)"]);
    assert_eq!(
        in_lines(Some("tray, bowl")),
        ["(apple_0, in, tray_0)", "(lemon_0, in, bowl_0)"]
    );
    mesa()
        .args(["graph", "--containers", "vase,bowl", "--layout"])
        .arg(&path)
        .assert()
        .success()
        .stdout(predicate::str::contains("(lemon_0, in, bowl_0)"))
        .stderr(predicate::str::contains(
            "--containers: \"vase\" names no object or category of this layout",
        ));
}

#[test]
fn equally_spaced_is_written_only_on_request() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("pens.json");
    write_json(
        &path,
        &json!({
            "item_placement_zone": [0.0, 100.0, 0.0, 60.0],
            "objects": [
                llm_object("pen_0", [1.0, 14.0, 1.0], [20.0, 30.0, 0.5]),
                llm_object("pen_1", [1.0, 14.0, 1.0], [40.0, 30.0, 0.5]),
                llm_object("pen_2", [1.0, 14.0, 1.0], [60.0, 30.0, 0.5]),
            ]
        }),
    );
    let line = "(pen_0, pen_1, pen_2, are equally spaced along, x)";
    assert!(!stdout_of(&["graph", "--layout"], &path).contains(line));
    let with = stdout_of(&["graph", "--equally-spaced", "--layout"], &path);
    assert!(with.ends_with(&format!("{line}\n")), "{with}");
}

#[test]
fn malformed_layouts_fail_naming_file_object_and_field() {
    let dir = tempfile::tempdir().expect("tempdir");
    let fails = |name: &str, text: &str, expected: &[&str]| {
        let path = dir.path().join(name);
        write_bytes(&path, text.as_bytes());
        let out = mesa()
            .args(["graph", "--layout"])
            .arg(&path)
            .output()
            .expect("runs");
        assert_eq!(out.status.code(), Some(1), "{name}");
        assert!(out.stdout.is_empty(), "{name}: no triplets on failure");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            stderr.contains(&path.display().to_string()),
            "{name}: {stderr}"
        );
        for part in expected {
            assert!(
                stderr.contains(part),
                "{name}: expected {part:?} in {stderr}"
            );
        }
    };
    let mut scene = tray_scene();
    scene["objects"][2]["size"][2] = json!(-6.0);
    fails(
        "negative.json",
        &scene.to_string(),
        &["$.objects[2].size[2]: apple_0: ", "-6"],
    );
    let mut scene = tray_scene();
    scene["objects"][1]["size"][0] = json!(0.0);
    fails(
        "zero.json",
        &scene.to_string(),
        &["$.objects[1].size[0]: bowl_0: "],
    );
    let mut scene = tray_scene();
    scene["objects"][3]["position"][1] = json!(123456.5);
    fails(
        "nan.json",
        &scene.to_string().replace("123456.5", "NaN"),
        &["$.objects[3].position[1]: lemon_0: is NaN"],
    );
    let mut scene = tray_scene();
    scene["objects"][3]["instance"] = json!("apple_0");
    fails(
        "duplicate.json",
        &scene.to_string(),
        &["$.objects[3].instance", "duplicate instance \"apple_0\""],
    );
    let mut scene = tray_scene();
    scene["item_placement_zone"] = json!([0.0, 100.0, 60.0, 60.0]);
    fails(
        "zone.json",
        &scene.to_string(),
        &["$.item_placement_zone", "empty zone"],
    );
    // A published record whose layout is a JSON string: the layout inside is checked too.
    let mut inner = tray_scene();
    inner["objects"][0]["size"][1] = json!(-1.0);
    let record = json!({
        "prompt_instructions": "p", "input_task_description": "{}", "reasoning_paragraph": "r",
        "scene_graph": [], "scene_layout_json": inner.to_string(),
    });
    fails(
        "record.json",
        &record.to_string(),
        &["$.scene_layout_json.objects[0].size[1]: tray_0: "],
    );
    fails("syntax.json", "{\"objects\": [", &["$: is not valid JSON"]);
    let missing = dir.path().join("absent.json");
    mesa()
        .args(["graph", "--layout"])
        .arg(&missing)
        .assert()
        .code(1)
        .stderr(predicate::str::contains("absent.json: cannot read"));
}

#[test]
fn bad_usage_exits_2() {
    mesa().arg("graph").assert().code(2);
    let record = &gallery()[0];
    mesa()
        .args(["graph", "--jobs", "2", "--layout"])
        .arg(record)
        .assert()
        .code(2);
    mesa()
        .args(["graph", "--containers", "bowl"])
        .arg(std::env::temp_dir())
        .assert()
        .code(2);
    mesa()
        .arg("graph")
        .arg(std::env::temp_dir().join("no-such-mesa-dataset"))
        .assert()
        .code(2)
        .stderr(predicate::str::contains("no such dataset folder"));
}

// --- datasets ------------------------------------------------------------------------------

fn scene_dir(dataset: &Path, scene: &str) -> PathBuf {
    let table = scene.rsplit_once('_').expect("table_type_nnnn").0;
    dataset.join("scenes").join(table).join(scene)
}

fn read_json(path: &Path) -> Value {
    serde_json::from_slice(
        &std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
    )
    .expect("json")
}

fn run_graph(dataset: &Path) -> (Option<i32>, String) {
    let out = mesa()
        .args(["graph", "--progress", "off"])
        .arg(dataset)
        .output()
        .expect("runs");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn dataset_graphs_follow_the_most_refined_layout_and_rerun_only_what_changed() {
    let dir = tempfile::tempdir().expect("tempdir");
    let dataset = dir.path();
    let records = gallery();
    // office_table_0001: coarse and refined layouts. dining_table_0002: coarse, refined and
    // qa. coffee_table_0003: only a coarse layout: it awaits its annotator, and the graph
    // waits for it (the coarse layout is never used after `ingest`).
    let office = scene_dir(dataset, "office_table_0001");
    let office_layout = dataset_of(&gallery_layout(&records[1]));
    let mut office_coarse = office_layout.clone();
    office_coarse.objects.pop();
    write_dataset_layout(&office.join("coarse/layout.json"), &office_coarse);
    write_dataset_layout(&office.join("refined/layout.json"), &office_layout);
    let waiting = scene_dir(dataset, "coffee_table_0003");
    write_dataset_layout(&waiting.join("coarse/layout.json"), &office_layout);
    let dining = scene_dir(dataset, "dining_table_0002");
    let dining_layout = dataset_of(&gallery_layout(&records[0]));
    for stage in ["coarse", "refined", "qa"] {
        let mut layout = dining_layout.clone();
        // Each file differs, so a wrong pick shows in the graph.
        if stage != "qa" {
            layout.objects.pop();
        }
        write_dataset_layout(&dining.join(format!("{stage}/layout.json")), &layout);
    }

    let (code, stderr) = run_graph(dataset);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(
        stderr.contains("graph: 3 scenes: 2 done, 0 skipped, 0 failed, 1 waiting"),
        "{stderr}"
    );
    assert!(
        stderr.contains("waiting coffee_table/coffee_table_0003: awaiting annotation: no pack yet"),
        "{stderr}"
    );
    assert!(!waiting.join("graph").exists());
    // No annotations file: the keyword rule, and a warning that says so.
    assert!(
        stderr.contains("containers by the keyword rule"),
        "{stderr}"
    );
    assert!(stderr.contains("(no annotations file)"), "{stderr}");

    for (scene, scene_id, rel) in [
        (&office, "office_table_0001", "refined/layout.json"),
        (&dining, "dining_table_0002", "qa/layout.json"),
    ] {
        let text = std::fs::read_to_string(scene.join("graph/graph.txt")).expect("graph.txt");
        assert_eq!(text, stdout_of(&["graph", "--layout"], &scene.join(rel)));
        let graph = read_json(&scene.join("graph/graph.json"));
        assert_eq!(graph["schema"], "mesa.graph/1");
        assert_eq!(graph["scene_id"], scene_id);
        assert_eq!(graph["layout"], rel);
        let edges = graph["edges"].as_array().expect("edges");
        let nodes = graph["nodes"].as_array().expect("nodes");
        assert_eq!(text.lines().count(), 2 * nodes.len() + edges.len());
        assert!(edges
            .iter()
            .all(|e| !e["numbers"].as_object().expect("numbers").is_empty()));
        mesa()
            .arg("validate")
            .arg(scene.join("graph/graph.json"))
            .assert()
            .success();
    }
    assert_eq!(
        read_json(&dining.join("graph/graph.json"))["nodes"]
            .as_array()
            .expect("nodes")
            .len(),
        dining_layout.objects.len()
    );

    // Nothing changed: nothing redone.
    let (code, stderr) = run_graph(dataset);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(stderr.contains("3 scenes: 0 done, 2 skipped"), "{stderr}");

    // A settled layout appears for the office scene: only that scene is redone, from it.
    let mut settled = office_layout.clone();
    settled.objects[0].position_cm.0[0] += 30.0;
    write_dataset_layout(&office.join("qa/layout.json"), &settled);
    let (code, stderr) = run_graph(dataset);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(stderr.contains("3 scenes: 1 done, 1 skipped"), "{stderr}");
    assert_eq!(
        read_json(&office.join("graph/graph.json"))["layout"],
        "qa/layout.json"
    );

    // A configuration change redoes every scene.
    std::fs::write(
        dataset.join("mesa.toml"),
        "[graph]\nequally_spaced = true\n",
    )
    .expect("toml");
    let (code, stderr) = run_graph(dataset);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(stderr.contains("3 scenes: 2 done, 0 skipped"), "{stderr}");

    // The refined layout of the waiting scene arrives: it is done, from it.
    write_dataset_layout(&waiting.join("refined/layout.json"), &office_layout);
    let (code, stderr) = run_graph(dataset);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(stderr.contains("3 scenes: 1 done, 2 skipped"), "{stderr}");
    assert_eq!(
        read_json(&waiting.join("graph/graph.json"))["layout"],
        "refined/layout.json"
    );
}

#[test]
fn annotations_decide_containers_by_retrieved_uid() {
    let dir = tempfile::tempdir().expect("tempdir");
    let dataset = dir.path();
    let scene = scene_dir(dataset, "kitchen_counter_0001");
    let llm: LlmLayout = serde_json::from_value(tray_scene()).expect("layout");
    write_dataset_layout(&scene.join("refined/layout.json"), &dataset_of(&llm));
    let annotations = dataset.join("assets/annotations.json");
    // The tray's asset is a container, the bowl's is not; the others say nothing.
    write_json(
        &annotations,
        &json!({
            "uid-tray_0": {"category": "tray", "isContainer": true},
            "uid-bowl_0": {"category": "bowl", "receptacle": false},
            "uid-apple_0": {"category": "apple", "mass": 0.2},
        }),
    );
    let (code, stderr) = run_graph(dataset);
    assert_eq!(code, Some(0), "{stderr}");
    let graph_txt = scene.join("graph/graph.txt");
    let text = std::fs::read_to_string(&graph_txt).expect("graph.txt");
    assert!(text.contains("(apple_0, in, tray_0)\n"), "{text}");
    assert!(!text.contains(", in, bowl_0)"), "{text}");
    let marker =
        read_json(&dataset.join(".mesa/markers/graph/kitchen_counter/kitchen_counter_0001.json"));
    let warnings = marker["warnings"].to_string();
    assert!(
        warnings.contains("apple_0 (the annotation of uid-apple_0 has no isContainer)")
            && warnings.contains("lemon_0 (asset uid-lemon_0 is not annotated)"),
        "{warnings}"
    );
    assert!(marker["inputs"]
        .as_object()
        .expect("inputs")
        .contains_key("assets/annotations.json"));
    let flags: Vec<bool> = read_json(&scene.join("graph/graph.json"))["nodes"]
        .as_array()
        .expect("nodes")
        .iter()
        .map(|n| n["container"].as_bool().expect("container"))
        .collect();
    assert_eq!(flags, [true, false, false, false]);

    // New annotations: the scene is redone, and a bad field fails it with uid and field named.
    write_json(
        &annotations,
        &json!({"uid-tray_0": {"isContainer": "maybe"}}),
    );
    let (code, stderr) = run_graph(dataset);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains(
            "assets/annotations.json: $[\"uid-tray_0\"].isContainer: is a string \"maybe\""
        ),
        "{stderr}"
    );
    // The runner's rule: a failed scene keeps no outputs of an earlier success, which no
    // longer match its inputs.
    assert!(!graph_txt.exists());
}

#[test]
fn a_bad_scene_fails_alone() {
    let dir = tempfile::tempdir().expect("tempdir");
    let dataset = dir.path();
    let llm: LlmLayout = serde_json::from_value(tray_scene()).expect("layout");
    let good = scene_dir(dataset, "office_table_0001");
    write_dataset_layout(&good.join("refined/layout.json"), &dataset_of(&llm));
    let bad = scene_dir(dataset, "office_table_0002");
    let mut broken = serde_json::to_value(dataset_of(&llm)).expect("json");
    broken["objects"][1]["size"][2] = json!(-3.0);
    write_json(&bad.join("refined/layout.json"), &broken);
    let empty = scene_dir(dataset, "office_table_0003");
    std::fs::create_dir_all(empty.join("input")).expect("mkdir");

    let (code, stderr) = run_graph(dataset);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains("3 scenes: 1 done, 0 skipped, 2 failed"),
        "{stderr}"
    );
    assert!(
        stderr.contains("refined/layout.json: $.objects[1].size[2]: bowl_0: "),
        "{stderr}"
    );
    assert!(
        stderr
            .contains("no layout (expected qa/layout.json, refined/layout.json; run `mesa place`"),
        "{stderr}"
    );
    assert!(good.join("graph/graph.txt").is_file());
    assert!(!bad.join("graph").exists());
    assert!(!empty.join("graph").exists());
}

#[test]
fn run_runs_graph_and_print_config_documents_its_section() {
    let dir = tempfile::tempdir().expect("tempdir");
    let dataset = dir.path();
    let llm: LlmLayout = serde_json::from_value(tray_scene()).expect("layout");
    let scene = scene_dir(dataset, "coffee_table_0001");
    write_dataset_layout(&scene.join("refined/layout.json"), &dataset_of(&llm));
    let out = mesa()
        .args(["run", "--print-config"])
        .arg(dataset)
        .output()
        .expect("runs");
    assert!(out.status.success());
    let config = String::from_utf8(out.stdout).expect("utf8");
    let lines: Vec<&str> = config.lines().collect();
    for key in [
        "[graph]",
        "container_keywords = [",
        "equally_spaced = false",
    ] {
        let at = lines
            .iter()
            .position(|l| l.starts_with(key))
            .unwrap_or_else(|| panic!("{key} missing from\n{config}"));
        assert!(lines[at - 1].starts_with("# "), "{key} is undocumented");
    }
    assert!(config.contains("\"organizer\""));
    // A typo in the section is bad configuration (exit 2) naming the key.
    std::fs::write(
        dataset.join("mesa.toml"),
        "[graph]\ncontainer_keyword = [\"bowl\"]\n",
    )
    .expect("toml");
    mesa()
        .args(["graph", "--progress", "off"])
        .arg(dataset)
        .assert()
        .code(2)
        .stderr(predicate::str::contains("container_keyword"));
    std::fs::write(
        dataset.join("mesa.toml"),
        "[graph]\ncontainer_keywords = [\"tray\"]\n",
    )
    .expect("toml");
    // `mesa run` runs graph after the stages before it, whatever they made of this dataset
    // (it has a layout but no photo inputs, so lift fails its scene; the exit code says so).
    mesa()
        .args(["run", "--progress", "off"])
        .arg(dataset)
        .assert()
        .stderr(predicate::str::contains("graph: 1 scenes: 1 done"));
    // With [graph] container_keywords = ["tray"], the tray holds the apple and the bowl
    // holds nothing.
    let text = std::fs::read_to_string(scene.join("graph/graph.txt")).expect("graph.txt");
    assert!(text.contains("(apple_0, in, tray_0)\n"), "{text}");
    assert!(!text.contains(", in, bowl_0)"), "{text}");
}
