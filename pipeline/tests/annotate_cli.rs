//! `mesa annotate assets` end to end, against a local OpenAI-compatible server (tests/common:
//! a real HTTP server on 127.0.0.1) and with the offline placeholder:
//!
//! - one request per asset to annotate, its four views (0°, 90°, 180°, 270°) as data URLs of
//!   the rendered files; replies with malformed JSON, an out-of-range mass, an unknown front
//!   view or a wrong type are rejected with their reasons (assets/annotate/rejects.jsonl) and
//!   asked again; a rerun sends zero requests (and a control without the cache sends them);
//! - the batch file holds exactly one request per asset, and the batch path gives the same
//!   annotations as the live one;
//! - a person's fields are never changed, every field mesa writes has its source; the API key
//!   is in no file and no output;
//! - after the offline backend, `mesa assets` keeps the index record bytes of the assets whose
//!   annotation did not change (and changes those whose did: the control);
//! - `assets/annotate/rejects.jsonl` (and `instance_rejects.jsonl`) hold the last run's
//!   rejects: a run that rejects nothing removes the earlier file (the control: a run that
//!   rejects writes it again);
//! - MesaTask's retrieval (scripts/mesatask_retrieval.py, its reading re-implemented; a Python
//!   with numpy and compress_pickle from `MESA_PYTHON` or `.venv-tools`, SKIPPED without one
//!   unless `MESA_REQUIRE_TOOLS`) reads every uid's size of the merged file, in each bbox form,
//!   as mesa's reader does, filters on onTable / mark_deletion / is_composite as mesa does,
//!   reads a person's entries as before the merge, and reads the release's
//!   Asset_annotation.json and sbert_text_features.pkl; the controls are forms mesa takes and
//!   MesaTask does not read the same, and a merge that changes a person's bbox.

mod common;

use std::collections::BTreeMap;
use std::path::Path;

use common::{all_files, mesa, MockServer, Reply};
use mesa_stages::assets::synthetic::Mesh;
use serde_json::{json, Value};

const KEY_VAR: &str = "MESA_ANNOTATE_TEST_KEY";
const KEY: &str = "sk-mesa-annotate-test-77f3a1";

fn read_json(path: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(path).expect("read")).expect("json")
}

/// The person's annotations before mesa: the book complete, the mug's category only.
fn person_annotations() -> Value {
    json!({
        "book_red": {"category": "book", "description": "A red hardcover book.",
                     "bbox": {"x": 0.15, "y": 0.03, "z": 0.22}, "onTable": true, "mass": 0.6,
                     "frontView": 0, "isContainer": false, "materials": ["paper"]},
        "mug_white": {"category": "mug"}
    })
}

/// The three synthetic assets of [`dataset`].
fn library() -> Vec<(&'static str, Mesh)> {
    vec![
        ("mug_white", Mesh::vessel(0.04, 0.095, 0.004, 0.007)),
        ("bowl_blue", Mesh::vessel(0.075, 0.06, 0.004, 0.006)),
        ("book_red", Mesh::cuboid([0.15, 0.03, 0.22])),
    ]
}

/// A library of three synthetic assets with the person's annotations, indexed by `mesa assets`.
fn dataset(base_url: &str) -> tempfile::TempDir {
    dataset_of(base_url, library(), &person_annotations())
}

/// A library of `assets` with `annotations` (written as a person would), indexed by
/// `mesa assets`.
fn dataset_of(base_url: &str, assets: Vec<(&str, Mesh)>, annotations: &Value) -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("tempdir");
    let library = dir.path().join("assets/library");
    std::fs::create_dir_all(&library).expect("mkdir");
    for (uid, mesh) in assets {
        std::fs::write(library.join(format!("{uid}.glb")), mesh.to_glb(1.0)).expect("write");
    }
    std::fs::write(
        dir.path().join("assets/annotations.json"),
        serde_json::to_vec_pretty(annotations).expect("json"),
    )
    .expect("write");
    std::fs::write(
        dir.path().join("mesa.toml"),
        format!(
            "[annotations.llm]\nbase_url = \"{base_url}\"\nmodel = \"mock-vlm\"\n\
             api_key_env = \"{KEY_VAR}\"\nmax_retries = 1\nbackoff_initial_s = 0.01\n\
             backoff_max_s = 0.05\ntimeout_s = 5.0\n"
        ),
    )
    .expect("config");
    let out = mesa()
        .args(["assets", "--progress", "off"])
        .arg(dir.path())
        .output()
        .expect("assets");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    dir
}

/// The model: which asset a request is for (by the size in its prompt) and its attempt (the
/// seed) decide the reply. Bowl: malformed JSON, then an out-of-range mass, then valid. Mug:
/// an unknown front view, then a wrong type, then valid.
fn model(body: &Value) -> String {
    let text = body["messages"][1]["content"][0]["text"]
        .as_str()
        .expect("text");
    let attempt = body["seed"].as_u64().expect("seed");
    let valid = |category: &str, mass: f64, front: u32| {
        json!({"category": category, "description": format!("A glazed ceramic {category} in pale blue."),
               "onTable": true, "mass": mass, "frontView": front, "isContainer": true,
               "materials": ["ceramic"]})
        .to_string()
    };
    if text.contains("15.0 x 15.0 x 6.0") {
        match attempt {
            0 => "{\"category\": \"bowl\", ".to_owned(),
            1 => valid("bowl", 500.0, 0),
            _ => valid("bowl", 0.4, 2),
        }
    } else if text.contains("8.0 x 8.0 x 9.5") {
        match attempt {
            0 => valid("cup", 0.3, 7),
            1 => valid("cup", 0.3, 1).replace("\"onTable\":true", "\"onTable\":\"yes\""),
            _ => valid("cup", 0.3, 1),
        }
    } else {
        panic!("a request for an unexpected asset: {text}")
    }
}

fn annotate(dir: &Path, extra: &[&str]) -> (bool, String) {
    let out = mesa()
        .args(["-vv", "annotate", "assets", "--progress", "off"])
        .args(extra)
        .arg(dir)
        .env(KEY_VAR, KEY)
        .env("MESA_LOG", "trace")
        .output()
        .expect("runs");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.success(), text)
}

fn assert_no_key(dir: &Path, outputs: &[&String]) {
    for text in outputs {
        assert!(!text.contains(KEY), "an output holds the key");
    }
    for (path, bytes) in all_files(dir) {
        assert!(
            !bytes.windows(KEY.len()).any(|w| w == KEY.as_bytes()),
            "{path} holds the key"
        );
    }
}

#[test]
fn the_live_path_validates_rejects_caches_and_keeps_a_persons_fields() {
    let server = MockServer::start(|request, _| Reply::completion(&model(&request.json())));
    let data = dataset(&server.base_url);
    let dir = data.path();
    let (success, out) = annotate(dir, &["--backend", "llm"]);
    assert!(success, "{out}");
    // Bowl 3 attempts, mug 3, the book (complete, a person's) none.
    assert_eq!(server.requests(), 6, "{out}");
    let received = server.received();
    for request in &received {
        assert_eq!(
            request.header("authorization"),
            Some(format!("Bearer {KEY}"))
        );
        let body = request.json();
        let parts = body["messages"][1]["content"].as_array().expect("parts");
        let urls: Vec<&str> = parts[1..]
            .iter()
            .map(|p| p["image_url"]["url"].as_str().expect("url"))
            .collect();
        assert_eq!(urls.len(), 4, "four views per request");
        // The views are the rendered files, in objathor's order.
        let uid = if parts[0]["text"]
            .as_str()
            .expect("text")
            .contains("15.0 x 15.0")
        {
            "bowl_blue"
        } else {
            "mug_white"
        };
        for (url, deg) in urls.iter().zip(["000", "090", "180", "270"]) {
            let png = std::fs::read(dir.join(format!("assets/renders/{uid}/view_{deg}.png")))
                .expect("view");
            let expected = mesa_stages::tasks::chat::png_data_url(&png);
            assert_eq!(*url, expected, "{uid} view {deg}");
        }
    }
    // Four replies rejected, each with its reason.
    let rejects_path = dir.join("assets/annotate/rejects.jsonl");
    let rejects_text = std::fs::read_to_string(&rejects_path).expect("rejects");
    let rejects: Vec<Value> = rejects_text
        .lines()
        .map(|l| serde_json::from_str(l).expect("json line"))
        .collect();
    let reasons: Vec<(String, u64, String)> = rejects
        .iter()
        .map(|r| {
            (
                r["uid"].as_str().expect("uid").to_owned(),
                r["attempt"].as_u64().expect("attempt"),
                r["reasons"][0].as_str().expect("reason").to_owned(),
            )
        })
        .collect();
    assert_eq!(reasons.len(), 4, "{reasons:?}");
    let find = |uid: &str, attempt: u64| {
        reasons
            .iter()
            .find(|(u, a, _)| u == uid && *a == attempt)
            .map(|(_, _, r)| r.as_str())
            .unwrap_or_default()
    };
    assert!(
        find("bowl_blue", 0).contains("not valid JSON"),
        "{reasons:?}"
    );
    assert!(
        find("bowl_blue", 1).starts_with("mass: 500 kg is implausible"),
        "{reasons:?}"
    );
    assert!(
        find("mug_white", 0).starts_with("frontView: ")
            && find("mug_white", 0).contains("one of the 4 views"),
        "{reasons:?}"
    );
    assert!(find("mug_white", 1).starts_with("onTable: "), "{reasons:?}");

    // The merge: a person's fields kept, every field mesa wrote has its source.
    let annotations = read_json(&dir.join("assets/annotations.json"));
    assert_eq!(annotations["book_red"], person_annotations()["book_red"]);
    let mug = &annotations["mug_white"];
    assert_eq!(mug["category"], "mug", "the person's category stays");
    assert!(mug["mesa_sources"].get("category").is_none());
    assert_eq!(mug["frontView"], 1);
    assert_eq!(mug["mesa_sources"]["frontView"], "llm:mock-vlm");
    assert_eq!(mug["mesa_sources"]["bbox"], "mesh");
    let bowl = &annotations["bowl_blue"];
    assert_eq!(bowl["category"], "bowl");
    assert_eq!(bowl["frontView"], 2);
    assert_eq!(bowl["mass"], 0.4);
    assert!(bowl.get("mesa_placeholder").is_none());
    let summary = read_json(&dir.join("assets/annotate/summary.json"));
    assert_eq!(summary["requests"], 6);
    assert_eq!(summary["fields_by_source"]["llm:mock-vlm"], 13);
    assert_eq!(summary["fields_by_source"]["person"], 8);
    let ok = mesa()
        .args(["validate"])
        .arg(dir.join("assets/annotate/summary.json"))
        .arg(dir.join("assets/annotate/rejects.jsonl"))
        .arg(dir.join("assets/annotations.json"))
        .output()
        .expect("validate");
    assert!(
        ok.status.success(),
        "{}",
        String::from_utf8_lossy(&ok.stdout)
    );

    // A rerun sends nothing: nothing is left to annotate; with --force, every reply is cached.
    let before = std::fs::read(dir.join("assets/annotations.json")).expect("read");
    let (success, out2) = annotate(dir, &["--backend", "llm"]);
    assert!(success, "{out2}");
    assert!(out2.contains("0 to annotate"), "{out2}");
    // That run rejected nothing, so the first run's rejects are gone (they would be stale).
    assert!(!rejects_path.exists(), "stale rejects left: {out2}");
    assert!(
        out2.contains("removed assets/annotate/rejects.jsonl"),
        "{out2}"
    );
    let (success, out3) = annotate(dir, &["--backend", "llm", "--force"]);
    assert!(success, "{out3}");
    assert!(
        out3.contains("mock-vlm: 0 requests, 6 cache hits"),
        "{out3}"
    );
    // The control: a run that rejects (the cached replies, validated again) writes them again.
    assert_eq!(
        std::fs::read_to_string(&rejects_path).expect("rejects written again"),
        rejects_text
    );
    assert_eq!(server.requests(), 6, "zero requests on reruns");
    assert_eq!(
        std::fs::read(dir.join("assets/annotations.json")).expect("read"),
        before
    );
    // The control: without the cache, --force asks again.
    std::fs::remove_dir_all(dir.join(".mesa/cache/chat")).expect("rm cache");
    let (success, out4) = annotate(dir, &["--backend", "llm", "--force"]);
    assert!(success, "{out4}");
    assert_eq!(server.requests(), 12, "{out4}");
    assert!(rejects_path.exists(), "{out4}");

    // A run that annotates and whose replies are all valid leaves no rejects behind.
    let valid = MockServer::start(|request, _| {
        let mut body = request.json();
        body["seed"] = json!(2);
        Reply::completion(&model(&body))
    });
    let config = std::fs::read_to_string(dir.join("mesa.toml")).expect("config");
    std::fs::write(
        dir.join("mesa.toml"),
        config.replace(&server.base_url, &valid.base_url),
    )
    .expect("config");
    std::fs::remove_dir_all(dir.join(".mesa/cache/chat")).expect("rm cache");
    let (success, out5) = annotate(dir, &["--backend", "llm", "--force"]);
    assert!(success, "{out5}");
    assert!(
        out5.contains("2 annotated") && out5.contains("0 replies rejected"),
        "{out5}"
    );
    assert_eq!(valid.requests(), 2, "{out5}");
    assert!(!rejects_path.exists(), "stale rejects left: {out5}");
    assert_no_key(dir, &[&out, &out2, &out3, &out4, &out5]);

    // MesaTask's retrieval reads the file the live path merged as mesa does.
    if let Some(python) = common::python_with("numpy, compress_pickle", "MesaTask's reader") {
        let path = dir.join("assets/annotations.json");
        let after = mesatask_reads(&python, &path, &[]).0;
        assert_eq!(disagreements_with_mesa(&after, &path), Vec::<String>::new());
        let before = mesatask_reads_value(&python, &person_annotations());
        assert_eq!(
            changed_person_reads(&person_annotations(), &before, &after),
            Vec::<String>::new()
        );
    }
}

/// A provider's output for a batch input: each request answered by the model, in reverse
/// order (joined by custom_id, never by position).
fn provider_output(input: &Path, output: &Path) -> usize {
    let text = std::fs::read_to_string(input).expect("batch input");
    let mut lines: Vec<String> = text
        .lines()
        .map(|line| {
            let request: Value = serde_json::from_str(line).expect("json");
            json!({"id": "batch_req", "custom_id": request["custom_id"],
                   "response": {"status_code": 200, "body": common::completion_body(&model(&request["body"]))},
                   "error": null})
            .to_string()
        })
        .collect();
    lines.reverse();
    std::fs::write(output, lines.join("\n") + "\n").expect("write");
    lines.len()
}

#[test]
fn offline_batches_hold_one_request_per_asset_and_give_the_live_annotations() {
    let server = MockServer::start(|request, _| Reply::completion(&model(&request.json())));
    let live = dataset(&server.base_url);
    let (success, out) = annotate(live.path(), &["--backend", "llm"]);
    assert!(success, "{out}");

    // No server at all for the batch path.
    let batched = dataset("http://127.0.0.1:9/v1");
    let dir = batched.path();
    let mut outputs = Vec::new();
    let mut batch_in: Option<std::path::PathBuf> = None;
    for round in 0..5 {
        let batch = dir.join(format!("batch_{round}.jsonl"));
        let mut args = vec!["--batch-out".to_owned(), batch.display().to_string()];
        if let Some(input) = &batch_in {
            args.extend(["--batch-in".to_owned(), input.display().to_string()]);
        }
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let (success, out) = annotate(dir, &args);
        assert!(success, "{out}");
        outputs.push(out);
        if !batch.exists() {
            break;
        }
        let lines: Vec<Value> = std::fs::read_to_string(&batch)
            .expect("batch")
            .lines()
            .map(|l| serde_json::from_str(l).expect("json"))
            .collect();
        if round == 0 {
            // Exactly one request per asset to annotate (the book is complete).
            assert_eq!(lines.len(), 2);
            for line in &lines {
                assert_eq!(line["url"], "/v1/chat/completions");
                assert!(line["custom_id"].as_str().expect("id").starts_with("mesa-"));
                let parts = line["body"]["messages"][1]["content"]
                    .as_array()
                    .expect("parts");
                assert_eq!(parts.len(), 5, "the prompt and four views");
                for part in &parts[1..] {
                    assert!(part["image_url"]["url"]
                        .as_str()
                        .expect("url")
                        .starts_with("data:image/png;base64,"));
                }
            }
        }
        let output = dir.join(format!("output_{round}.jsonl"));
        provider_output(&batch, &output);
        batch_in = Some(output);
    }
    assert_eq!(server.requests(), 6, "the batch path sends nothing");
    assert_eq!(
        read_json(&dir.join("assets/annotations.json")),
        read_json(&live.path().join("assets/annotations.json"))
    );
    let refs: Vec<&String> = outputs.iter().collect();
    assert_no_key(dir, &refs);
}

fn index_records(dir: &Path) -> BTreeMap<String, String> {
    read_json(&dir.join("assets/index/assets.json"))["assets"]
        .as_object()
        .expect("assets")
        .iter()
        .map(|(uid, record)| (uid.clone(), record.to_string()))
        .collect()
}

#[test]
fn the_offline_placeholder_is_marked_and_unchanged_assets_keep_their_index_bytes() {
    let data = dataset("http://127.0.0.1:9/v1");
    let dir = data.path();
    let before = index_records(dir);
    // The same bytes with one thread and with two.
    let original = std::fs::read(dir.join("assets/annotations.json")).expect("read");
    let (success, out) = annotate(dir, &["--jobs", "1"]);
    assert!(success, "{out}");
    let one_thread = std::fs::read(dir.join("assets/annotations.json")).expect("read");
    assert_ne!(one_thread, original);
    std::fs::write(dir.join("assets/annotations.json"), &original).expect("restore");
    let (success, out) = annotate(dir, &["--jobs", "2"]);
    assert!(success, "{out}");
    assert_eq!(
        std::fs::read(dir.join("assets/annotations.json")).expect("read"),
        one_thread
    );
    assert!(
        out.contains("2 to annotate (offline): 2 annotated"),
        "{out}"
    );
    let annotations = read_json(&dir.join("assets/annotations.json"));
    assert_eq!(annotations["book_red"], person_annotations()["book_red"]);
    let bowl = &annotations["bowl_blue"];
    assert_eq!(bowl["mesa_placeholder"], true);
    assert_eq!(bowl["mesa_sources"]["description"], "offline");
    assert!(bowl["description"]
        .as_str()
        .expect("description")
        .contains("placeholder"));
    assert_eq!(bowl["isContainer"], true, "the bowl is hollow");
    assert_eq!(annotations["mug_white"]["category"], "mug");
    // mesa's reader (the fields and bbox forms retrieval reads) takes the merged file.
    let read = mesa_stages::annotations::Annotations::read(&dir.join("assets/annotations.json"))
        .expect("readable");
    assert!(read.get("bowl_blue").expect("bowl").bbox.is_some());
    assert_eq!(read.get("bowl_blue").expect("bowl").rejection(), None);

    let out = mesa()
        .args(["assets", "--progress", "off"])
        .arg(dir)
        .output()
        .expect("assets");
    assert!(out.status.success());
    let after = index_records(dir);
    assert_eq!(
        after["book_red"], before["book_red"],
        "unchanged annotation"
    );
    // The control: the records of the annotated assets did change.
    assert_ne!(after["bowl_blue"], before["bowl_blue"]);
    assert_ne!(after["mug_white"], before["mug_white"]);
    // A rerun of the offline backend has nothing to do.
    let (success, out) = annotate(dir, &[]);
    assert!(success, "{out}");
    assert!(
        out.contains("0 to annotate") && out.contains("unchanged"),
        "{out}"
    );
    // The report counts the fields by source.
    std::fs::create_dir_all(dir.join("scenes")).expect("mkdir");
    let report = mesa()
        .args(["report", "--progress", "off"])
        .arg(dir)
        .output()
        .expect("report");
    assert!(
        report.status.success(),
        "{}",
        String::from_utf8_lossy(&report.stderr)
    );
    let stats = read_json(&dir.join("report/stats.json"));
    assert_eq!(
        stats["annotation_sources"],
        json!({"offline": 13, "person": 8}),
        "bowl 7 and mug 6 placeholder fields; the book's 7 and the mug's category a person's"
    );
    assert_eq!(stats["annotation_placeholder_assets"], 2);
    let page = std::fs::read_to_string(dir.join("report/index.html")).expect("page");
    assert!(
        page.contains("fields by source: 13 offline, 8 person"),
        "report page"
    );
}

/// A synthetic scene of four boxes whose instances.json lacks some labels and descriptions:
/// 1 has a person's label only, 2 has neither, 3 and 4 are complete (a person's).
fn instance_scene(base_url: &str) -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("tempdir");
    let input = dir
        .path()
        .join("scenes/office_table/office_table_0001/input");
    mesa_stages::lift::synthetic::SyntheticScene {
        size_px: 256,
        boxes: 4,
        ..Default::default()
    }
    .write(&input)
    .expect("synthetic scene");
    let path = input.join("instances.json");
    let mut instances = read_json(&path);
    let entries = instances["instances"].as_array_mut().expect("instances");
    entries[0] = json!({"id": 1, "label": "mug", "description": ""});
    entries[1] = json!({"id": 2});
    std::fs::write(&path, serde_json::to_vec_pretty(&instances).expect("json")).expect("write");
    std::fs::write(
        dir.path().join("mesa.toml"),
        format!(
            "[annotations.llm]\nbase_url = \"{base_url}\"\nmodel = \"mock-vlm\"\n\
             api_key_env = \"{KEY_VAR}\"\nmax_retries = 1\ntimeout_s = 5.0\n"
        ),
    )
    .expect("config");
    dir
}

fn instance_model(body: &Value) -> String {
    let text = body["messages"][1]["content"][0]["text"]
        .as_str()
        .expect("text");
    if text.contains("label so far: \"mug\"") {
        return json!({"label": "cup", "description": "white ceramic mug"}).to_string();
    }
    match body["seed"].as_u64() {
        Some(0) => "{\"label\": ".to_owned(),
        _ => json!({"label": "Bowl", "description": "shallow blue bowl"}).to_string(),
    }
}

fn annotate_instances(dir: &Path, extra: &[&str]) -> (bool, String) {
    let out = mesa()
        .args(["annotate", "instances", "--progress", "off"])
        .args(extra)
        .arg(dir)
        .env(KEY_VAR, KEY)
        .output()
        .expect("runs");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.success(), text)
}

#[test]
fn instances_get_labels_from_their_crop_and_the_photo_and_keep_a_persons_text() {
    let server =
        MockServer::start(|request, _| Reply::completion(&instance_model(&request.json())));
    let data = instance_scene(&server.base_url);
    let dir = data.path();
    let input = dir.join("scenes/office_table/office_table_0001/input");
    let before = read_json(&input.join("instances.json"));
    let (success, out) = annotate_instances(dir, &["--backend", "llm"]);
    assert!(success, "{out}");
    // Instance 1 once, instance 2 twice (its first reply is malformed).
    assert_eq!(server.requests(), 3, "{out}");
    let photo = mesa_stages::tasks::chat::png_data_url(
        &std::fs::read(input.join("image.png")).expect("photo"),
    );
    for request in server.received() {
        let parts = request.json()["messages"][1]["content"].clone();
        let crop = parts[1]["image_url"]["url"]
            .as_str()
            .expect("crop")
            .to_owned();
        assert!(crop.starts_with("data:image/png;base64,") && crop != photo);
        assert_eq!(
            parts[2]["image_url"]["url"],
            photo.as_str(),
            "the whole photo"
        );
    }
    let after = read_json(&input.join("instances.json"));
    let entries = after["instances"].as_array().expect("instances");
    assert_eq!(entries[0]["label"], "mug", "a person's label stays");
    assert_eq!(entries[0]["description"], "white ceramic mug");
    assert_eq!(
        entries[0]["mesa_sources"],
        json!({"description": "llm:mock-vlm"})
    );
    assert_eq!(entries[1]["label"], "bowl");
    assert_eq!(entries[1]["mesa_sources"]["label"], "llm:mock-vlm");
    assert_eq!(
        entries[2], before["instances"][2],
        "complete entries untouched"
    );
    assert_eq!(entries[4], before["instances"][4], "the table untouched");
    let rejects = std::fs::read_to_string(dir.join("assets/annotate/instance_rejects.jsonl"))
        .expect("rejects");
    assert_eq!(rejects.lines().count(), 1);
    assert!(rejects.contains("not valid JSON"), "{rejects}");
    // A rerun sends nothing, rejects nothing, and leaves no stale rejects.
    let (success, out2) = annotate_instances(dir, &["--backend", "llm"]);
    assert!(success, "{out2}");
    assert_eq!(server.requests(), 3);
    assert!(
        !dir.join("assets/annotate/instance_rejects.jsonl").exists(),
        "{out2}"
    );
    // The written file is still a valid input: lift reads it.
    let lift = mesa()
        .args(["lift", "--progress", "off"])
        .arg(dir)
        .output()
        .expect("lift");
    assert!(
        lift.status.success(),
        "{}",
        String::from_utf8_lossy(&lift.stderr)
    );
    assert_no_key(dir, &[&out, &out2]);

    // The offline backend on the same inputs: placeholders, marked.
    let offline = instance_scene("http://127.0.0.1:9/v1");
    let (success, out) = annotate_instances(offline.path(), &[]);
    assert!(success, "{out}");
    let entries = read_json(
        &offline
            .path()
            .join("scenes/office_table/office_table_0001/input/instances.json"),
    )["instances"]
        .clone();
    assert_eq!(entries[1]["label"], "object");
    assert_eq!(entries[1]["mesa_sources"]["label"], "offline");
    assert!(entries[0]["description"]
        .as_str()
        .expect("text")
        .starts_with("mug at the "));
}

#[test]
fn instance_batches_give_the_live_labels() {
    let server =
        MockServer::start(|request, _| Reply::completion(&instance_model(&request.json())));
    let live = instance_scene(&server.base_url);
    let (success, out) = annotate_instances(live.path(), &["--backend", "llm"]);
    assert!(success, "{out}");
    let batched = instance_scene("http://127.0.0.1:9/v1");
    let dir = batched.path();
    let mut batch_in: Option<std::path::PathBuf> = None;
    let mut rounds = 0;
    for round in 0..5 {
        let batch = dir.join(format!("batch_{round}.jsonl"));
        let mut args = vec!["--batch-out".to_owned(), batch.display().to_string()];
        if let Some(input) = &batch_in {
            args.extend(["--batch-in".to_owned(), input.display().to_string()]);
        }
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let (success, out) = annotate_instances(dir, &args);
        assert!(success, "{out}");
        if !batch.exists() {
            break;
        }
        rounds += 1;
        let text = std::fs::read_to_string(&batch).expect("batch");
        if round == 0 {
            assert_eq!(
                text.lines().count(),
                2,
                "one request per instance to annotate"
            );
        }
        let output = dir.join(format!("output_{round}.jsonl"));
        let lines: Vec<String> = text
            .lines()
            .map(|line| {
                let request: Value = serde_json::from_str(line).expect("json");
                json!({"custom_id": request["custom_id"], "error": null,
                       "response": {"status_code": 200,
                                    "body": common::completion_body(&instance_model(&request["body"]))}})
                .to_string()
            })
            .collect();
        std::fs::write(&output, lines.join("\n") + "\n").expect("write");
        batch_in = Some(output);
    }
    assert_eq!(rounds, 2, "the malformed reply costs a second round");
    assert_eq!(server.requests(), 3, "the batch path sends nothing");
    let rel = "scenes/office_table/office_table_0001/input/instances.json";
    assert_eq!(read_json(&dir.join(rel)), read_json(&live.path().join(rel)));
}

#[test]
fn bad_usage_and_missing_inputs_say_what_to_do() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = mesa()
        .args([
            "annotate",
            "assets",
            "--backend",
            "offline",
            "--batch-out",
            "b.jsonl",
        ])
        .arg(dir.path())
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("for the llm backend"));
    // No index yet: the error names the file and the command that writes it.
    let out = mesa()
        .args(["annotate", "assets", "--progress", "off"])
        .arg(dir.path())
        .output()
        .expect("runs");
    assert_ne!(out.status.code(), Some(0));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("assets/index/assets.json") && stderr.contains("run `mesa assets`"),
        "{stderr}"
    );
    // A taxonomy file that is not there is a usage error naming the key.
    std::fs::write(
        dir.path().join("mesa.toml"),
        "[annotations]\ncategories = \"taxonomy.txt\"\n",
    )
    .expect("config");
    let out = mesa()
        .args(["annotate", "assets"])
        .arg(dir.path())
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("[annotations] categories") && stderr.contains("taxonomy.txt"),
        "{stderr}"
    );
    // The live backend without its key is a usage error naming the variable.
    std::fs::write(
        dir.path().join("mesa.toml"),
        "[annotations.llm]\napi_key_env = \"MESA_ANNOTATE_UNSET_KEY\"\n",
    )
    .expect("config");
    let out = mesa()
        .args(["annotate", "assets", "--backend", "llm"])
        .arg(dir.path())
        .env_remove("MESA_ANNOTATE_UNSET_KEY")
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("MESA_ANNOTATE_UNSET_KEY") && stderr.contains("[annotations.llm]"),
        "{stderr}"
    );
}

// ---------------------------------------------------------------------------------------------
// MesaTask's retrieval as the reader of the merged file (scripts/mesatask_retrieval.py).

/// scripts/mesatask_retrieval.py on `annotations` with `extra` arguments: its per-uid lines by
/// uid, and its other lines in order.
fn mesatask_reads(
    python: &Path,
    annotations: &Path,
    extra: &[&str],
) -> (BTreeMap<String, Value>, Vec<Value>) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/mesatask_retrieval.py");
    let out = std::process::Command::new(python)
        .arg(script)
        .arg(annotations)
        .args(extra)
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "mesatask_retrieval.py {}: {}",
        annotations.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    let (mut by_uid, mut others) = (BTreeMap::new(), Vec::new());
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        let value: Value = serde_json::from_str(line).expect("a JSON line");
        match value["uid"].as_str() {
            Some(uid) => {
                by_uid.insert(uid.to_owned(), value);
            }
            None => others.push(value),
        }
    }
    (by_uid, others)
}

/// [`mesatask_reads`] of an annotation document (written to a scratch file).
fn mesatask_reads_value(python: &Path, annotations: &Value) -> BTreeMap<String, Value> {
    let scratch = tempfile::tempdir().expect("tempdir");
    let path = scratch.path().join("annotations.json");
    std::fs::write(&path, serde_json::to_vec_pretty(annotations).expect("json")).expect("write");
    mesatask_reads(python, &path, &[]).0
}

/// Where MesaTask's reading of `annotations` (`reads`) and mesa's reader disagree, one line per
/// uid and field: the size ([x, z, y], within 1e-9, or both without one) and whether the asset
/// passes the retrieval filter (onTable, mark_deletion, is_composite).
fn disagreements_with_mesa(reads: &BTreeMap<String, Value>, annotations: &Path) -> Vec<String> {
    let ours = mesa_stages::annotations::Annotations::read(annotations).expect("mesa reads it");
    let mut out = Vec::new();
    let uids: Vec<&str> = ours.iter().map(|(uid, _)| uid).collect();
    let theirs: Vec<&str> = reads.keys().map(String::as_str).collect();
    if uids != theirs {
        out.push(format!("uids: mesa {uids:?}, MesaTask {theirs:?}"));
    }
    for (uid, annotation) in ours.iter() {
        let Some(read) = reads.get(uid) else { continue };
        let size: Option<Vec<f64>> = read["size"]
            .as_array()
            .map(|a| a.iter().map(|v| v.as_f64().expect("a number")).collect());
        let mesa_size = annotation.bbox.map(|b| b.size_table_frame());
        let same = match (&size, &mesa_size) {
            (Some(t), Some(o)) => {
                t.len() == 3 && t.iter().zip(o).all(|(t, o)| (t - o).abs() <= 1e-9)
            }
            (None, None) => true,
            _ => false,
        };
        if !same {
            out.push(format!(
                "{uid}: size {size:?} (MesaTask; {}) but {mesa_size:?} (mesa)",
                read["problem"]
            ));
        }
        if read["kept"].as_bool() != Some(annotation.rejection().is_none()) {
            out.push(format!(
                "{uid}: MesaTask's filter keeps it: {} (onTable {}, mark_deletion {}, \
                 is_composite {}), mesa's rejects it for {:?}",
                read["kept"],
                read["on_table"],
                read["mark_deletion"],
                read["is_composite"],
                annotation.rejection()
            ));
        }
    }
    out
}

/// Which reads of a person's entries (`original`) changed between `before` and `after`: each
/// read of fields the person set (the size of an entry with a bbox in any form; onTable; the
/// filter's verdict when the person's fields decide it; mark_deletion and is_composite, which
/// mesa never writes).
fn changed_person_reads(
    original: &Value,
    before: &BTreeMap<String, Value>,
    after: &BTreeMap<String, Value>,
) -> Vec<String> {
    let mut out = Vec::new();
    for (uid, entry) in original.as_object().expect("an object") {
        let (Some(b), Some(a)) = (before.get(uid), after.get(uid)) else {
            out.push(format!("{uid}: not read before or after the merge"));
            continue;
        };
        let has = |keys: &[&str]| keys.iter().any(|k| entry.get(*k).is_some());
        let mut keys = vec!["mark_deletion", "is_composite"];
        if has(&["bbox", "min_point", "max_point"]) {
            keys.extend(["size", "problem", "breaks_query"]);
        }
        if has(&["onTable"]) {
            keys.push("on_table");
        }
        if has(&["onTable"]) || b["mark_deletion"] == true || b["is_composite"] == true {
            keys.push("kept");
        }
        for key in keys {
            if b[key] != a[key] {
                out.push(format!("{uid}.{key}: {} before, {} after", b[key], a[key]));
            }
        }
    }
    out
}

/// The library of [`dataset`] and three more assets, for every bbox form.
fn forms_library() -> Vec<(&'static str, Mesh)> {
    let mut assets = library();
    assets.extend([
        ("vase_green", Mesh::vessel(0.05, 0.2, 0.004, 0.006)),
        ("box_tan", Mesh::cuboid([0.3, 0.1, 0.2])),
        ("tray_grey", Mesh::cuboid([0.4, 0.02, 0.3])),
    ]);
    assets
}

/// The person's annotations of [`forms_library`]: each bbox form MesaTask's reader takes
/// (`bbox` x/y/z, `bbox.size`, `bbox.min/max`, top-level `min_point/max_point`), and each
/// field its filter reads, on entries mesa completes.
fn annotations_in_every_form() -> Value {
    let mut all = person_annotations();
    all["vase_green"] = json!({"category": "vase", "onTable": false,
                               "bbox": {"size": {"x": 0.1, "y": 0.2, "z": 0.1}}});
    all["box_tan"] = json!({"mark_deletion": true,
                            "bbox": {"min": {"x": -0.15, "y": 0.0, "z": -0.1},
                                     "max": {"x": 0.15, "y": 0.1, "z": 0.1}}});
    all["tray_grey"] = json!({"description": "A flat grey serving tray.", "is_composite": true,
                              "min_point": [-0.2, 0.0, -0.15], "max_point": [0.2, 0.02, 0.15]});
    all
}

/// Text features for `uids`: row k is e_k plus 0.05 everywhere (each row its own best match).
fn text_features(uids: &[String], cols: usize) -> mesa_stages::pickle::TextFeatures {
    let mut data_le = Vec::new();
    for k in 0..uids.len() {
        for j in 0..cols {
            let value: f32 = if j == k % cols { 1.05 } else { 0.05 };
            data_le.extend_from_slice(&value.to_le_bytes());
        }
    }
    mesa_stages::pickle::TextFeatures {
        uids: uids.to_vec(),
        kind: mesa_stages::pickle::FloatKind::F32,
        cols,
        data_le,
    }
}

#[test]
fn mesatasks_retrieval_reads_the_merged_annotations_and_the_release_as_mesa_does() {
    let Some(python) = common::python_with("numpy, compress_pickle", "MesaTask's retrieval reader")
    else {
        return;
    };
    let original = annotations_in_every_form();
    let data = dataset_of("http://127.0.0.1:9/v1", forms_library(), &original);
    let dir = data.path();
    let path = dir.join("assets/annotations.json");
    let before = mesatask_reads(&python, &path, &[]).0;
    assert_eq!(
        disagreements_with_mesa(&before, &path),
        Vec::<String>::new()
    );
    let (success, out) = annotate(dir, &[]);
    assert!(success, "{out}");
    assert!(
        out.contains("5 to annotate (offline): 5 annotated"),
        "{out}"
    );
    let merged = read_json(&path);
    let after = mesatask_reads(&python, &path, &[]).0;

    // Every uid's size read their way is mesa's, and so is the filter's verdict.
    assert_eq!(disagreements_with_mesa(&after, &path), Vec::<String>::new());
    // Every asset is now a candidate of their retrieval (before, the mug had no size).
    assert!(before["mug_white"]["size"].is_null());
    assert_eq!(after.len(), forms_library().len());
    for (uid, read) in &after {
        assert!(
            read["size"].is_array() && read["breaks_query"] == false,
            "{uid}: {read}"
        );
    }
    // The person's entries read as before the merge; mesa added a bbox only to entries that
    // had none in any form.
    assert_eq!(
        changed_person_reads(&original, &before, &after),
        Vec::<String>::new()
    );
    for uid in ["book_red", "vase_green", "box_tan", "tray_grey"] {
        assert!(merged[uid]["mesa_sources"].get("bbox").is_none(), "{uid}");
    }
    assert_eq!(merged["mug_white"]["mesa_sources"]["bbox"], "mesh");
    // Their filter has the person's three to drop.
    let dropped: Vec<&str> = after
        .iter()
        .filter(|(_, read)| read["kept"] == false)
        .map(|(uid, _)| uid.as_str())
        .collect();
    assert_eq!(dropped, ["box_tan", "tray_grey", "vase_green"]);

    // The controls: forms mesa's reader takes and theirs does not read the same (a `size`
    // list breaks their whole query, corners as objects are skipped, the string "False" is
    // truthy to them), and a merge that changed a person's bbox, are caught.
    let scratch = tempfile::tempdir().expect("tempdir");
    let mut corrupted = merged.clone();
    corrupted["book_red"]["bbox"] = json!({"size": [0.15, 0.03, 0.22]});
    corrupted["tray_grey"]["min_point"] = json!({"x": -0.2, "y": 0.0, "z": -0.15});
    corrupted["tray_grey"]["max_point"] = json!({"x": 0.2, "y": 0.02, "z": 0.15});
    corrupted["mug_white"]["onTable"] = json!("False");
    let corrupted_path = scratch.path().join("corrupted.json");
    std::fs::write(&corrupted_path, corrupted.to_string()).expect("write");
    let reads = mesatask_reads(&python, &corrupted_path, &[]).0;
    assert_eq!(reads["book_red"]["breaks_query"], true);
    let found = disagreements_with_mesa(&reads, &corrupted_path);
    let named: Vec<&str> = found
        .iter()
        .map(|line| line.split(':').next().expect("uid"))
        .collect();
    assert_eq!(named, ["book_red", "mug_white", "tray_grey"], "{found:#?}");
    let mut overwritten = merged.clone();
    overwritten["book_red"]["bbox"]["x"] = json!(0.16);
    let changed = changed_person_reads(
        &original,
        &before,
        &mesatask_reads_value(&python, &overwritten),
    );
    assert!(
        changed.len() == 1 && changed[0].starts_with("book_red.size"),
        "{changed:?}"
    );

    // The release, as MesaTask's config.yaml names its files: Asset_annotation.json and
    // sbert_text_features.pkl (loaded with compress_pickle), then their retrieval of one
    // asset's description and size.
    let uids: Vec<String> = merged
        .as_object()
        .expect("object")
        .keys()
        .cloned()
        .collect();
    let cols = 16;
    std::fs::write(
        dir.join("assets/text_features.npy"),
        text_features(&uids, cols).to_npy(),
    )
    .expect("write");
    std::fs::write(dir.join("assets/text_uids.json"), json!(uids).to_string()).expect("write");
    std::fs::create_dir_all(dir.join("scenes")).expect("mkdir");
    let release = scratch.path().join("release");
    let out = mesa()
        .args(["release", "--progress", "off", "--assets", "none"])
        .arg(dir)
        .arg(&release)
        .output()
        .expect("release");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let released = release.join("Asset_annotation.json");
    let ours = mesa_stages::annotations::Annotations::read(&released).expect("mesa reads it");
    let query = "bowl_blue";
    let target = ours
        .get(query)
        .expect("bowl")
        .bbox
        .expect("bbox")
        .size_table_frame();
    let target_args: Vec<String> = target.iter().map(|v| format!("{v}")).collect();
    let pkl = release.join("sbert_text_features.pkl");
    let (reads, others) = mesatask_reads(
        &python,
        &released,
        &[
            "--features",
            pkl.to_str().expect("utf-8 path"),
            "--target-size",
            &target_args[0],
            &target_args[1],
            &target_args[2],
            "--query-uid",
            query,
            "--top-k-final",
            &uids.len().to_string(),
        ],
    );
    assert_eq!(
        disagreements_with_mesa(&reads, &released),
        Vec::<String>::new()
    );
    for (uid, read) in &reads {
        let mut read = read.clone();
        // Their size step: the cosine of [x, z, y] with the target, in float32.
        let size = ours
            .get(uid)
            .expect("entry")
            .bbox
            .expect("bbox")
            .size_table_frame();
        let dot: f64 = size.iter().zip(&target).map(|(a, b)| a * b).sum();
        let norm = |v: &[f64; 3]| v.iter().map(|a| a * a).sum::<f64>().sqrt();
        let cosine = dot / (norm(&size) * norm(&target));
        let theirs = read["size_similarity"].as_f64().expect("similarity");
        assert!(
            (theirs - cosine).abs() < 1e-6,
            "{uid}: {theirs} vs {cosine}"
        );
        read.as_object_mut()
            .expect("object")
            .remove("size_similarity");
        assert_eq!(
            read, after[uid],
            "{uid}: the release reads as assets/annotations.json"
        );
    }
    assert_eq!(
        others[0],
        json!({"features": uids.len(), "cols": cols, "uids_without_entry": []})
    );
    let retrieval = &others[1];
    let ranked: Vec<&str> = retrieval["ranked"]
        .as_array()
        .expect("ranked")
        .iter()
        .map(|pair| pair[0].as_str().expect("uid"))
        .collect();
    assert_eq!(ranked.len(), uids.len(), "{retrieval}");
    assert_eq!(ranked[0], query, "its own text and size rank first");
    let kept_by_mesa: Vec<&str> = ranked
        .iter()
        .copied()
        .filter(|uid| ours.get(uid).expect("entry").rejection().is_none())
        .collect();
    assert_eq!(retrieval["retrieved"], json!(kept_by_mesa), "{retrieval}");
    assert!(
        kept_by_mesa.len() < ranked.len(),
        "the filter dropped the person's three"
    );
}
