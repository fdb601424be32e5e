//! `mesa tasks` with the llm backend, end to end against a local OpenAI-compatible server
//! (tests/common: a real HTTP server on 127.0.0.1 answering like a compliant model):
//!
//! - a 429, a 500, a slow reply (timeout) and an unreadable body are retried; a reply that is
//!   not valid JSON is rejected, kept in tasks/rejects.jsonl with its reason, and asked again
//!   with the next seed;
//! - the rendered view goes with the description call as a base64 PNG data URL, and the record
//!   says it was used;
//! - a rerun costs nothing (zero requests) and gives the same files;
//! - the API key reaches the server as a Bearer token and appears in no output, log or file;
//! - offline batches (Batch JSONL out → a provider's output, shuffled, with one error line → in,
//!   round after round) give the same tasks as the direct path.

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use assert_cmd::Command;
use common::{answer, call_of, completion_body, user_text, MockServer, Reply};
use mesa_schemas::artifacts::{TaskRecord, TaskReject};
use serde_json::{json, Value};

const KEY_VAR: &str = "MESA_TASKS_TEST_KEY";
const KEY: &str = "sk-mesa-tasks-test-4b1d9c";
const FRONT_PNG: &[u8] = b"\x89PNG\r\n\x1a\nnot really an image, but the bytes go as they are";

/// The reply of the model: valid answers, except the first tasks call of the scene with the
/// desk lamp, which gets text that is not JSON.
fn model(body: &Value) -> String {
    if call_of(body) == "tasks" && user_text(body).contains("Desk Lamp(") && body["seed"] == 0 {
        return "{not json".to_owned();
    }
    answer(body)
}

fn config(base_url: &str) -> String {
    format!(
        "[tasks]\nbackend = \"llm\"\n\n[tasks.llm]\nbase_url = \"{base_url}\"\nmodel = \"mock-model\"\n\
         api_key_env = \"{KEY_VAR}\"\nmax_retries = 4\nbackoff_initial_s = 0.01\n\
         backoff_max_s = 0.2\ntimeout_s = 1.0\nmax_concurrency = 2\n"
    )
}

/// The published layouts, their scene graphs, and a front view for the first scene.
fn dataset(base_url: &str) -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("tempdir");
    common::gallery_dataset(dir.path());
    std::fs::write(dir.path().join("mesa.toml"), config(base_url)).expect("config");
    let out = mesa()
        .args(["graph", "--progress", "off"])
        .arg(dir.path())
        .output()
        .expect("graph");
    assert!(out.status.success());
    let render = dir
        .path()
        .join("scenes/dining_table/dining_table_0001/render/front.png");
    std::fs::create_dir_all(render.parent().expect("parent")).expect("mkdir");
    std::fs::write(&render, FRONT_PNG).expect("png");
    dir
}

fn mesa() -> Command {
    Command::cargo_bin("mesa").expect("the mesa binary")
}

/// The tasks files of every scene.
fn task_files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    common::all_files(dir)
        .into_iter()
        .filter(|(k, _)| k.starts_with("scenes/") && k.contains("/tasks/"))
        .collect()
}

fn run_direct(dir: &Path, extra: &[&str]) -> (bool, String, String) {
    let out = mesa()
        .args(["-vv", "tasks", "--progress", "off", "--jobs", "1"])
        .args(extra)
        .arg(dir)
        .env(KEY_VAR, KEY)
        // The most verbose logging there is, HTTP client included.
        .env("MESA_LOG", "trace")
        .output()
        .expect("runs");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn the_direct_path_retries_rejects_caches_and_keeps_the_key_secret() {
    let server = MockServer::start(|request, n| match n {
        0 => Reply::error(429, "rate limited").with_header("Retry-After", "0"),
        1 => Reply::error(500, "internal"),
        2 => Reply::completion("too late").after(std::time::Duration::from_millis(2500)),
        3 => Reply {
            status: 200,
            headers: vec![],
            body: "<html>bad gateway</html>".to_owned(),
            delay: std::time::Duration::ZERO,
        },
        _ => Reply::completion(&model(&request.json())),
    });
    let dir = dataset(&server.base_url);
    let (success, stdout, stderr) = run_direct(dir.path(), &[]);
    assert!(success, "{stderr}");
    assert!(stderr.contains("tasks: 7 scenes: 7 done"), "{stderr}");
    // 7 descriptions, 8 tasks calls (one rejected), 35 reasonings, 4 transient failures.
    let sent = server.requests();
    assert_eq!(sent, 7 + 8 + 35 + 4, "{stderr}");
    assert!(
        stderr.contains(&format!(
            "tasks: mock-model: {sent} requests, 0 cache hits, 4 retries, 0 failed"
        )),
        "{stderr}"
    );
    let received = server.received();
    for request in &received {
        assert_eq!(
            request.header("authorization"),
            Some(format!("Bearer {KEY}"))
        );
        assert!(!request.body.contains(KEY), "the key is never in a body");
    }
    // The view went as a data URL with the description call of its scene.
    let with_image: Vec<_> = received
        .iter()
        .filter(|r| r.body.contains("data:image/png;base64,"))
        .collect();
    assert_eq!(
        with_image.len(),
        1,
        "the description call of the scene with a view"
    );
    assert_eq!(call_of(&with_image[0].json()), "description");
    let url = &with_image[0].json()["messages"][1]["content"][1]["image_url"]["url"];
    assert_eq!(
        url.as_str().expect("url"),
        format!("data:image/png;base64,{}", base64_of(FRONT_PNG))
    );

    // Records: the LLM wrote them; the first scene says which view it saw.
    let files = task_files(dir.path());
    let records: Vec<TaskRecord> = files
        .iter()
        .filter(|(k, _)| k.ends_with("tasks.jsonl"))
        .flat_map(|(_, b)| {
            String::from_utf8_lossy(b)
                .lines()
                .map(|l| serde_json::from_str::<TaskRecord>(l).expect("record"))
                .collect::<Vec<_>>()
        })
        .collect();
    assert_eq!(records.len(), 35);
    assert!(records.iter().all(|r| r.generator == "llm:mock-model"));
    for r in &records {
        let expected: &[&str] = if r.scene_id == "dining_table_0001" {
            &["render/front.png"]
        } else {
            &[]
        };
        assert_eq!(r.views, expected, "{}", r.scene_id);
    }
    // The malformed reply is kept with its reason, in the scene with the desk lamp.
    let rejects: Vec<(&String, &Vec<u8>)> = files
        .iter()
        .filter(|(k, _)| k.ends_with("rejects.jsonl"))
        .collect();
    assert_eq!(rejects.len(), 1, "{:?}", files.keys());
    let reject: TaskReject =
        serde_json::from_str(String::from_utf8_lossy(rejects[0].1).trim()).expect("one reject");
    assert_eq!((reject.call.as_str(), reject.attempt), ("tasks", 0));
    assert_eq!(reject.reply, "{not json");
    assert!(
        reject.reasons[0].contains("not valid JSON"),
        "{:?}",
        reject.reasons
    );
    assert!(stderr.contains("1 model replies rejected"), "{stderr}");

    // A rerun costs nothing and changes nothing.
    let (success, stdout2, stderr2) = run_direct(dir.path(), &["--force"]);
    assert!(success, "{stderr2}");
    assert_eq!(server.requests(), sent, "zero requests the second time");
    assert!(stderr2.contains("0 requests, 50 cache hits"), "{stderr2}");
    assert!(task_files(dir.path()) == files);

    // The key is in no output and no file.
    for text in [&stdout, &stderr, &stdout2, &stderr2] {
        assert!(!text.contains(KEY));
    }
    for (path, bytes) in common::all_files(dir.path()) {
        assert!(
            !bytes.windows(KEY.len()).any(|w| w == KEY.as_bytes()),
            "{path} holds the key"
        );
    }

    // Tasks and rejects are valid artifacts.
    let out = mesa()
        .arg("validate")
        .arg(dir.path().join("scenes"))
        .output()
        .expect("validate");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );

    // The tasks feed the records as the template's do.
    let out = mesa()
        .args(["records", "--progress", "off"])
        .arg(dir.path())
        .output()
        .expect("records");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn base64_of(bytes: &[u8]) -> String {
    mesa_stages::tasks::chat::png_data_url(bytes)
        .trim_start_matches("data:image/png;base64,")
        .to_owned()
}

/// A provider's batch output for a batch input file: one line per request, in a shuffled
/// order, the `error_first` request answered by an error line.
fn provider_output(input: &Path, output: &Path, error_first: bool) -> usize {
    let text = std::fs::read_to_string(input).expect("batch input");
    let mut lines: Vec<(String, Value)> = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let request: Value = serde_json::from_str(line).expect("a JSON line");
        assert_eq!(request["method"], "POST");
        assert_eq!(request["url"], "/v1/chat/completions");
        assert_eq!(request["body"]["model"], "mock-model");
        let id = request["custom_id"].as_str().expect("custom_id").to_owned();
        let out = if error_first && i == 0 {
            json!({"id": format!("batch_req_{i}"), "custom_id": id, "response": null,
                   "error": {"code": "server_error", "message": "the request could not be processed"}})
        } else {
            json!({"id": format!("batch_req_{i}"), "custom_id": id,
                   "response": {"status_code": 200, "request_id": format!("req_{i}"),
                                "body": completion_body(&model(&request["body"]))},
                   "error": null})
        };
        lines.push((id, out));
    }
    // Not the input's order: providers return lines as they finish.
    lines.sort_by(|a, b| a.0.chars().rev().cmp(b.0.chars().rev()));
    let body: String = lines.iter().map(|(_, v)| format!("{v}\n")).collect();
    std::fs::write(output, body).expect("write output");
    lines.len()
}

#[test]
fn offline_batches_give_the_same_tasks_as_the_direct_path() {
    // The direct path, against the server.
    let server = MockServer::start(|request, _| Reply::completion(&model(&request.json())));
    let direct = dataset(&server.base_url);
    let (success, _, stderr) = run_direct(direct.path(), &[]);
    assert!(success, "{stderr}");
    let expected = task_files(direct.path());

    // The batch path: no server, no key.
    let batched = dataset("http://127.0.0.1:9/v1");
    let dir = batched.path();
    let mut previous: Option<PathBuf> = None;
    let mut rounds = Vec::new();
    for round in 0..10 {
        let out_file = dir.join(format!("batch_{round}.jsonl"));
        let mut command = mesa();
        command
            .args(["tasks", "--progress", "off", "--batch-out"])
            .arg(&out_file);
        if let Some(input) = &previous {
            command.arg("--batch-in").arg(input);
        }
        let out = command.arg(dir).output().expect("runs");
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        if !out_file.exists() {
            assert!(out.status.success(), "{stderr}");
            assert!(stderr.contains("no request is pending"), "{stderr}");
            rounds.push((0, stderr));
            break;
        }
        let provider = dir.join(format!("output_{round}.jsonl"));
        let lines = provider_output(&out_file, &provider, round == 0);
        rounds.push((lines, stderr));
        previous = Some(provider);
    }
    // Round 0: the 7 description calls; round 1 reads their output, one line of which failed.
    assert_eq!(rounds[0].0, 7);
    assert!(
        rounds[1]
            .1
            .contains("6 replies stored, 0 already cached, 1 lines failed"),
        "{}",
        rounds[1].1
    );
    assert!(
        rounds[1]
            .1
            .contains("server_error: the request could not be processed"),
        "{}",
        rounds[1].1
    );
    // The failed request went out again with the 6 tasks calls.
    assert_eq!(rounds[1].0, 7);
    // Descriptions, tasks, then all reasonings of a scene in one round: four rounds of
    // requests (the failed line and the rejected reply each cost their scene one more).
    assert_eq!(
        rounds.len(),
        5,
        "{:?}",
        rounds.iter().map(|r| r.0).collect::<Vec<_>>()
    );
    assert_eq!(
        rounds.last().expect("rounds").0,
        0,
        "the last round has nothing to send"
    );
    let got = task_files(dir);
    assert_eq!(
        got.keys().collect::<Vec<_>>(),
        expected.keys().collect::<Vec<_>>()
    );
    for (path, bytes) in &expected {
        assert!(got[path] == *bytes, "{path} differs from the direct path");
    }
    // Lines whose custom_id belongs to no pending request are reported, not used.
    let stray = dir.join("stray.jsonl");
    std::fs::write(
        &stray,
        "{\"custom_id\": \"mesa-0000\", \"response\": {\"status_code\": 200, \"body\": {}}}\nnot json\n",
    )
    .expect("stray");
    let out = mesa()
        .args(["tasks", "--progress", "off", "--batch-in"])
        .arg(&stray)
        .arg(dir)
        .output()
        .expect("runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("stray.jsonl:1: mesa-0000: not a request of this dataset"),
        "{stderr}"
    );
    assert!(stderr.contains("stray.jsonl:2: not JSON"), "{stderr}");
}

/// Issue #20 item 8: a server that echoes the key inside valid replies (the description and
/// every reasoning text) and inside a rejected one. The key is redacted before anything is
/// written: no file of the dataset holds it (tasks, rejects, cache, records, markers), and the
/// cache entries and the reject say `"redacted": true`.
#[test]
fn a_key_echoed_in_replies_is_redacted_before_anything_is_written() {
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Arc;
    let echoed = Arc::new(AtomicUsize::new(0));
    let server = {
        let echoed = echoed.clone();
        MockServer::start(move |request, _| {
            let body = request.json();
            let content = match call_of(&body) {
                "description" => format!("{} Inventory tag {KEY}.", answer(&body)),
                "reasoning" => answer(&body).replace(
                    "The objects stand where the task needs them.",
                    &format!("The objects stand where the task needs them (key {KEY})."),
                ),
                _ => model(&body).replace("{not json", &format!("{{not json {KEY}")),
            };
            let reply = Reply::completion(&content);
            // Control: the key really goes out in the replies.
            if reply.body.contains(KEY) {
                echoed.fetch_add(1, Ordering::SeqCst);
            }
            reply
        })
    };
    let dir = dataset(&server.base_url);
    let (success, stdout, stderr) = run_direct(dir.path(), &[]);
    assert!(success, "{stderr}");
    assert!(stderr.contains("tasks: 7 scenes: 7 done"), "{stderr}");
    // 7 descriptions, 35 reasonings and the rejected tasks reply.
    assert_eq!(echoed.load(Ordering::SeqCst), 7 + 35 + 1);
    assert!(
        stderr.contains("model replies held the API key: it was replaced by <redacted>"),
        "{stderr}"
    );
    let out = mesa()
        .args(["records", "--progress", "off"])
        .arg(dir.path())
        .output()
        .expect("records");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let files = common::all_files(dir.path());
    for (path, bytes) in &files {
        assert!(
            !bytes.windows(KEY.len()).any(|w| w == KEY.as_bytes()),
            "{path} holds the key"
        );
    }
    for text in [&stdout, &stderr] {
        assert!(!text.contains(KEY));
    }
    // The replies kept their place, redacted and marked.
    let text_of = |suffix: &str| -> Vec<String> {
        files
            .iter()
            .filter(|(k, _)| k.ends_with(suffix))
            .map(|(_, b)| String::from_utf8_lossy(b).into_owned())
            .collect()
    };
    let records = text_of("tasks.jsonl").concat();
    assert!(records.contains("(key <redacted>)"), "{records}");
    let rejects = text_of("rejects.jsonl");
    assert_eq!(rejects.len(), 1);
    let reject: TaskReject = serde_json::from_str(rejects[0].trim()).expect("reject");
    assert_eq!(reject.reply, "{not json <redacted>");
    assert!(reject.redacted);
    let cache: Vec<String> = files
        .iter()
        .filter(|(k, _)| k.starts_with(".mesa/cache/chat/"))
        .map(|(_, b)| String::from_utf8_lossy(b).into_owned())
        .collect();
    assert_eq!(cache.len(), 7 + 8 + 35);
    let marked = cache
        .iter()
        .filter(|c| c.contains("\"redacted\": true"))
        .count();
    assert_eq!(
        marked,
        7 + 35 + 1,
        "only the replies that held the key are marked"
    );
    // Marked entries are valid cache entries.
    let out = mesa()
        .arg("validate")
        .arg(dir.path().join(".mesa/cache/chat"))
        .output()
        .expect("validate");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
}

/// Issue #20 item 8: when every reply of a call is rejected, `tasks/rejects.jsonl` is written
/// before the error that names it, the last success's `tasks.jsonl` stays, and the other
/// scenes finish; a later success replaces both.
#[test]
fn rejects_are_written_before_the_error_and_the_last_tasks_stay() {
    let server = MockServer::start(|request, _| {
        let body = request.json();
        // The second model answers the tasks call of the desk-lamp scene with text that is
        // never JSON, whatever the attempt.
        if body["model"] == "mock-model-2"
            && call_of(&body) == "tasks"
            && user_text(&body).contains("Desk Lamp(")
        {
            return Reply::completion("{not json, attempt after attempt");
        }
        Reply::completion(&answer(&body))
    });
    let dir = dataset(&server.base_url);
    let (success, _, stderr) = run_direct(dir.path(), &[]);
    assert!(success, "{stderr}");
    let before = task_files(dir.path());
    assert_eq!(before.len(), 7, "no rejects yet: {:?}", before.keys());
    // The desk-lamp scene: the one the second model fails.
    let (lamp_tasks, lamp_bytes) = before
        .iter()
        .find(|(_, b)| String::from_utf8_lossy(b).contains("Desk Lamp"))
        .map(|(k, b)| (k.clone(), b.clone()))
        .expect("a scene with a desk lamp");
    let lamp_rejects = lamp_tasks.replace("tasks.jsonl", "rejects.jsonl");

    let toml = config(&server.base_url).replace("mock-model", "mock-model-2");
    std::fs::write(dir.path().join("mesa.toml"), toml).expect("config");
    let (success, _, stderr) = run_direct(dir.path(), &[]);
    assert!(!success, "{stderr}");
    assert!(stderr.contains("7 scenes: 6 done"), "{stderr}");
    assert!(
        stderr.contains(
            "no valid reply to the tasks call in 3 attempts (the rejects, with reasons, are in \
             tasks/rejects.jsonl)"
        ),
        "{stderr}"
    );
    let after = task_files(dir.path());
    // The file the error names exists, with every attempt and its reason.
    let rejects = String::from_utf8_lossy(&after[&lamp_rejects]).into_owned();
    let rejects: Vec<TaskReject> = rejects
        .lines()
        .map(|l| serde_json::from_str(l).expect("reject"))
        .collect();
    assert_eq!(
        rejects.iter().map(|r| r.attempt).collect::<Vec<_>>(),
        [0, 1, 2]
    );
    assert!(rejects
        .iter()
        .all(|r| r.reasons[0].contains("not valid JSON")));
    // The previous tasks are kept, byte for byte; the other scenes have the new model's.
    assert_eq!(after[&lamp_tasks], lamp_bytes);
    for (path, bytes) in &after {
        if path.ends_with("tasks.jsonl") && *path != lamp_tasks {
            assert!(
                String::from_utf8_lossy(bytes).contains("llm:mock-model-2"),
                "{path}"
            );
        }
    }
    // Control: a successful run replaces the kept tasks and removes the stale rejects.
    let toml = config(&server.base_url).replace("mock-model", "mock-model-3");
    std::fs::write(dir.path().join("mesa.toml"), toml).expect("config");
    let (success, _, stderr) = run_direct(dir.path(), &[]);
    assert!(success, "{stderr}");
    let last = task_files(dir.path());
    assert!(!last.contains_key(&lamp_rejects), "{:?}", last.keys());
    assert_ne!(last[&lamp_tasks], lamp_bytes);
}

/// Issue #20 item 13: log lines carry ANSI colour codes only on a terminal, and not even there
/// with `NO_COLOR` set. The terminal is a pseudo-terminal from util-linux `script`.
#[test]
fn log_lines_are_coloured_only_on_a_terminal_without_no_color() {
    let server = MockServer::start(|request, _| Reply::completion(&answer(&request.json())));
    let dir = dataset(&server.base_url);
    let mesa_bin = assert_cmd::cargo::cargo_bin("mesa");
    // Each run takes another scene, so that it sends requests (and the HTTP client logs them
    // at debug level) instead of answering from the cache.
    let command = |scene: &str| {
        format!(
            "{} -v tasks --progress off --jobs 1 --scenes {scene} {}",
            mesa_bin.display(),
            dir.path().display()
        )
    };
    // Redirected: plain text.
    let out = std::process::Command::new("sh")
        .args(["-c", &command("dining_table_0001")])
        .env(KEY_VAR, KEY)
        .env_remove("NO_COLOR")
        .output()
        .expect("runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("DEBUG"), "the run logs: {stderr}");
    assert!(!stderr.contains('\u{1b}'), "no colour codes: {stderr:?}");
    // On a terminal: coloured (the control), unless NO_COLOR says otherwise.
    let on_terminal = |scene: &str, no_color: Option<&str>| {
        let mut cmd = std::process::Command::new("script");
        cmd.args(["-qec", &command(scene), "/dev/null"])
            .env(KEY_VAR, KEY)
            .env_remove("NO_COLOR");
        if let Some(value) = no_color {
            cmd.env("NO_COLOR", value);
        }
        let out = cmd.output().expect("script (util-linux) runs");
        let text = String::from_utf8_lossy(&out.stdout).into_owned();
        assert!(out.status.success(), "{text}");
        assert!(text.contains("DEBUG"), "the run logs: {text}");
        text
    };
    assert!(on_terminal("office_table_0002", None).contains("\u{1b}["));
    assert!(!on_terminal("kitchen_counter_0003", Some("1")).contains('\u{1b}'));
}
