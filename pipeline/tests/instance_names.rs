//! Issue #20 item 9: instance names are restricted to what layouts, scene-graph lines and file
//! names can carry (`mesa_schemas::validate::instance_name_problem`). `validate`, `convert`,
//! `graph --layout` and the stages' layout reader refuse a name with a line break, a comma,
//! parentheses or nothing at all, with a message naming the file, the name (quoted) and the
//! fix; `graph` never prints an injected triplet line. Every crafted file is made here.

mod common;

use std::path::Path;

use common::mesa;
use serde_json::{json, Value};

/// An LLM layout with a mug named `name` and a pen.
fn layout_with(path: &Path, name: &str) {
    let layout = json!({
        "item_placement_zone": [0.0, 100.0, 0.0, 60.0],
        "objects": [
            {"instance": name, "size": [8.0, 8.0, 10.0], "position": [20.0, 20.0, 5.0],
             "z_rotation": 0.0, "description": "a mug"},
            {"instance": "pen_0", "size": [1.0, 14.0, 1.0], "position": [60.0, 30.0, 0.5],
             "z_rotation": 0.0, "description": "a pen"},
        ],
    });
    std::fs::write(path, serde_json::to_vec_pretty(&layout).expect("json")).expect("write");
}

fn output_of(cmd: &mut assert_cmd::Command) -> (Option<i32>, String, String) {
    let out = cmd.output().expect("runs");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

const INJECTED: &str = "mug_0, left of, pen_0)\n(pen_0, in, mug_0";

#[test]
fn bad_instance_names_are_refused_by_validate_convert_and_graph() {
    let dir = tempfile::tempdir().expect("tempdir");
    let cases = [
        (
            INJECTED,
            "holds a comma",
            "\"mug_0_left_of_pen_0_pen_0_in_mug_0\"",
        ),
        (
            "mug_0\n(pen_0, in, mug_0)",
            "holds a line break",
            "\"mug_0_pen_0_in_mug_0\"",
        ),
        ("mug(0)", "holds a parenthesis", "\"mug_0\""),
        ("", "is empty", "\"object_0\""),
        (&"m".repeat(65), "is 65 characters long", "\"mmmm"),
    ];
    for (k, (name, problem, fix)) in cases.iter().enumerate() {
        let layout = dir.path().join(format!("bad_{k}.json"));
        layout_with(&layout, name);
        let file = layout.display().to_string();
        let quoted = Value::String((*name).to_owned()).to_string();
        for args in [
            vec!["validate", "--kind", "llm-layout", &file],
            vec!["convert", &file, "--to", "dataset"],
            vec!["graph", "--layout", &file],
        ] {
            let (code, stdout, stderr) = output_of(mesa().args(&args));
            let text = format!("{stdout}{stderr}");
            assert_eq!(code, Some(1), "{args:?}: {text}");
            assert!(text.contains(&file), "{args:?} names the file: {text}");
            assert!(
                text.contains(&format!(
                    "$.objects[0].instance: the instance name {quoted} {problem}"
                )),
                "{args:?}: {text}"
            );
            assert!(
                text.contains("1 to 64 ASCII letters, digits, '_' or '-'")
                    && text.contains(&format!("rename it, e.g. to {fix}")),
                "{args:?}: {text}"
            );
            // Nothing injected reaches the output as a line of its own (the name is quoted,
            // its line break escaped).
            assert!(
                !text.lines().any(|l| l.trim_start().starts_with('(')),
                "{args:?}: {text}"
            );
        }
    }

    // Control: the same layout with a plain name passes, and graph prints its lines.
    let layout = dir.path().join("good.json");
    layout_with(&layout, "mug_0");
    let file = layout.display().to_string();
    let (code, _, stderr) = output_of(mesa().args(["validate", "--kind", "llm-layout", &file]));
    assert_eq!(code, Some(0), "{stderr}");
    let (code, _, stderr) = output_of(mesa().args(["convert", &file, "--to", "dataset"]));
    assert_eq!(code, Some(0), "{stderr}");
    let (code, stdout, stderr) = output_of(mesa().args(["graph", "--layout", &file]));
    assert_eq!(code, Some(0), "{stderr}");
    assert!(
        stdout.contains("(mug_0, is at, ") && stdout.contains("(pen_0, is at, "),
        "{stdout}"
    );
}

/// A scene whose ingested layout holds an injected name fails `mesa graph` with the message;
/// the other scenes finish.
#[test]
fn a_scene_layout_with_a_bad_name_fails_only_that_scene() {
    let dir = tempfile::tempdir().expect("tempdir");
    common::gallery_dataset(dir.path());
    let layout = dir
        .path()
        .join("scenes/coffee_table/coffee_table_0007/refined/layout.json");
    let mut value: Value =
        serde_json::from_slice(&std::fs::read(&layout).expect("read")).expect("json");
    value["objects"][0]["instance"] = Value::String(INJECTED.to_owned());
    std::fs::write(&layout, serde_json::to_vec_pretty(&value).expect("json")).expect("write");
    let (code, _, stderr) = output_of(mesa().args(["graph", "--progress", "off"]).arg(dir.path()));
    assert_eq!(code, Some(1), "{stderr}");
    assert!(stderr.contains("7 scenes: 6 done"), "{stderr}");
    assert!(
        stderr.contains("failed coffee_table/coffee_table_0007")
            && stderr.contains("refined/layout.json")
            && stderr.contains(
                "the instance name \"mug_0, left of, pen_0)\\n(pen_0, in, mug_0\" holds a comma"
            ),
        "{stderr}"
    );
    let graph = dir
        .path()
        .join("scenes/coffee_table/coffee_table_0007/graph/graph.txt");
    assert!(!graph.exists());
}
