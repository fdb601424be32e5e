//! End-to-end tests of the `mesa` binary: validate, convert, parse-output, configuration and
//! exit codes. Real published records are read from ../shared/realdata.

mod common;

use common::{gallery, mesa};

use std::path::{Path, PathBuf};

use predicates::prelude::*;
use serde_json::Value;

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).expect("write");
    path
}

#[test]
fn validate_reports_every_problem_with_file_path_and_expectation() {
    let dir = tempfile::tempdir().expect("tempdir");
    let dataset_layout = dir.path().join("good.json");
    mesa()
        .args(["convert", "--to", "dataset", "-o"])
        .arg(&dataset_layout)
        .arg(&gallery()[0])
        .assert()
        .success();
    mesa()
        .arg("validate")
        .arg(&dataset_layout)
        .assert()
        .success();

    let mut v: Value =
        serde_json::from_slice(&std::fs::read(&dataset_layout).expect("read")).expect("json");
    v["objects"][0]["position"] = Value::from("abc");
    v["objects"][1].as_object_mut().expect("obj").remove("size");
    v["objects"][2]["size"] = serde_json::json!([10.0, 12.0]);
    v["objects"][3]["size"][2] = Value::from(-4.0);
    v["objects"][5]["position"][0] = Value::from(123456.5);
    let text = serde_json::to_string_pretty(&v)
        .expect("ser")
        .replacen("123456.5", "NaN", 1);
    let bad = write(dir.path(), "bad.json", &text);
    let mut unknown = v.clone();
    unknown["schema"] = Value::from("mesa.whatever/1");
    let unknown = write(dir.path(), "unknown.json", &unknown.to_string());

    let output = mesa()
        .arg("validate")
        .arg(&bad)
        .arg(&unknown)
        .output()
        .expect("run");
    assert_eq!(output.status.code(), Some(1));
    let stdout = String::from_utf8(output.stdout).expect("utf8");
    let bad_name = bad.display().to_string();
    for expected in [
        format!("{bad_name}: $.objects[0].position: is a string \"abc\" (expected an array"),
        format!("{bad_name}: $.objects[1].size: missing required key \"size\" (expected "),
        format!("{bad_name}: $.objects[2].size: has 2 items (expected exactly 3 items"),
        format!("{bad_name}: $.objects[3].size[2]: is -4 (expected a number > 0)"),
        format!("{bad_name}: $.objects[5].position[0]: is NaN (expected a finite number)"),
        format!(
            "{}: $.schema: unknown schema \"mesa.whatever/1\" (expected one of mesa.layout/1",
            unknown.display()
        ),
    ] {
        assert_eq!(
            stdout.lines().filter(|l| l.starts_with(&expected)).count(),
            1,
            "missing {expected:?} in\n{stdout}"
        );
    }
    assert_eq!(stdout.lines().count(), 6, "{stdout}");
}

#[test]
fn validate_takes_a_kind_for_official_files_and_rejects_unknown_kinds() {
    for record in gallery() {
        mesa()
            .args(["validate", "--kind", "gallery-record"])
            .arg(&record)
            .assert()
            .success();
    }
    mesa()
        .args(["validate", "--kind", "nonsense"])
        .arg(&gallery()[0])
        .assert()
        .code(2)
        .stderr(predicate::str::contains("--kind nonsense: unknown kind"));
    // Without --kind, a record (no schema field, no known file name) is a problem, not a guess.
    mesa()
        .arg("validate")
        .arg(&gallery()[0])
        .assert()
        .code(1)
        .stdout(predicate::str::contains("has no \"schema\" field"));
}

fn numbers_close(a: &Value, b: &Value) -> bool {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => {
            (x.as_f64().expect("f64") - y.as_f64().expect("f64")).abs() <= 1e-6
        }
        (Value::Array(x), Value::Array(y)) => {
            x.len() == y.len() && x.iter().zip(y).all(|(p, q)| numbers_close(p, q))
        }
        (Value::Object(x), Value::Object(y)) => {
            x.len() == y.len()
                && x.iter()
                    .all(|(k, v)| y.get(k).is_some_and(|w| numbers_close(v, w)))
        }
        _ => a == b,
    }
}

#[test]
fn convert_round_trips_every_published_layout() {
    let dir = tempfile::tempdir().expect("tempdir");
    for record in gallery() {
        let dataset = dir.path().join("dataset.json");
        let llm = dir.path().join("llm.json");
        mesa()
            .args(["convert", "--to", "dataset", "-o"])
            .arg(&dataset)
            .arg(&record)
            .assert()
            .success()
            .stderr(predicate::str::contains("have no asset yet"));
        mesa().arg("validate").arg(&dataset).assert().success();
        mesa()
            .args(["convert", "--to", "llm", "-o"])
            .arg(&llm)
            .arg(&dataset)
            .assert()
            .success();
        let original: Value =
            serde_json::from_slice(&std::fs::read(&record).expect("read")).expect("json");
        let original = &original["scene_layout_json"];
        let back: Value =
            serde_json::from_slice(&std::fs::read(&llm).expect("read")).expect("json");
        assert!(numbers_close(
            &original["item_placement_zone"],
            &back["item_placement_zone"]
        ));
        let objects = original["objects"].as_array().expect("objects");
        assert_eq!(
            back["objects"].as_array().expect("objects").len(),
            objects.len()
        );
        for object in objects {
            let twin = back["objects"]
                .as_array()
                .expect("objects")
                .iter()
                .find(|o| o["instance"] == object["instance"])
                .expect("same instance");
            assert!(
                numbers_close(object, twin),
                "{}: {object} vs {twin}",
                record.display()
            );
        }
    }
}

#[test]
fn convert_names_tilted_objects() {
    let dir = tempfile::tempdir().expect("tempdir");
    let dataset = dir.path().join("dataset.json");
    mesa()
        .args(["convert", "--to", "dataset", "-o"])
        .arg(&dataset)
        .arg(&gallery()[0])
        .assert()
        .success();
    let mut v: Value =
        serde_json::from_slice(&std::fs::read(&dataset).expect("read")).expect("json");
    let h = std::f64::consts::FRAC_1_SQRT_2;
    v["objects"][1]["rotation"] = serde_json::json!([0.0, h, 0.0, h]);
    v["objects"][1]
        .as_object_mut()
        .expect("obj")
        .remove("z_rotation");
    let name = v["objects"][1]["instance"]
        .as_str()
        .expect("name")
        .to_owned();
    std::fs::write(&dataset, v.to_string()).expect("write");
    mesa()
        .args(["convert", "--to", "llm"])
        .arg(&dataset)
        .assert()
        .success()
        .stderr(predicate::str::contains(format!(
            "{name}: rotation is tilted by 90.000°"
        )));
}

#[test]
fn parse_output_accepts_assembled_gallery_texts_and_explains_failures() {
    let dir = tempfile::tempdir().expect("tempdir");
    for record in gallery() {
        let v: Value =
            serde_json::from_slice(&std::fs::read(&record).expect("read")).expect("json");
        let lines: Vec<&str> = v["scene_graph"]
            .as_array()
            .expect("lines")
            .iter()
            .map(|l| l.as_str().expect("line"))
            .collect();
        let text = format!(
            "{}\n{}\nTherefore, the scene layout is:\n**Final Answer**\n```json\n{}\n```<|im_end|>",
            v["reasoning_paragraph"].as_str().expect("reasoning"),
            lines.join("\n"),
            v["scene_layout_json"]
        );
        let file = write(dir.path(), "output.txt", &text);
        let out = mesa().arg("parse-output").arg(&file).output().expect("run");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let layout: Value = serde_json::from_slice(&out.stdout).expect("layout JSON on stdout");
        assert_eq!(layout["objects"], v["scene_layout_json"]["objects"]);
        assert!(String::from_utf8_lossy(&out.stderr).contains(&format!(
            "success: {} objects, {} scene-graph lines",
            layout["objects"].as_array().expect("objects").len(),
            lines.len()
        )));
    }
    let no_marker = write(dir.path(), "bad.txt", "just some text {\"objects\": []}");
    mesa()
        .arg("parse-output")
        .arg(&no_marker)
        .assert()
        .code(1)
        .stderr(predicate::str::contains("not a success: the marker"));
}

#[test]
fn configuration_is_printed_documented_and_typos_are_usage_errors() {
    let dir = tempfile::tempdir().expect("tempdir");
    std::fs::create_dir_all(dir.path().join("scenes")).expect("mkdir");
    let out = mesa()
        .args(["run", "--print-config"])
        .arg(dir.path())
        .output()
        .expect("run");
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).expect("utf8");
    assert!(text.contains("[run]\n"));
    assert!(text.contains("# Worker threads"));
    let parsed: toml::Table = toml::from_str(&text).expect("valid TOML");
    assert!(parsed.contains_key("run"));

    std::fs::write(dir.path().join("mesa.toml"), "[run]\njobz = 3\n").expect("write");
    mesa()
        .args(["run", "--print-config"])
        .arg(dir.path())
        .assert()
        .code(2)
        .stderr(predicate::str::contains("mesa.toml").and(predicate::str::contains("jobz")));
}

#[test]
fn a_folder_that_is_not_a_dataset_is_a_usage_error() {
    let dir = tempfile::tempdir().expect("tempdir");
    mesa()
        .arg("status")
        .arg(dir.path())
        .assert()
        .code(2)
        .stderr(predicate::str::contains("not a mesa dataset"));
    mesa()
        .args(["run", "--shard", "3/3"])
        .arg(dir.path())
        .assert()
        .code(2)
        .stderr(predicate::str::contains("out of range"));
}
