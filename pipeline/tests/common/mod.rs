//! Helpers shared by the CLI tests: the `mesa` binary, the published records in
//! ../shared/realdata, byte snapshots of a dataset's outputs, a local OpenAI-compatible chat
//! server (a real HTTP/1.1 server on 127.0.0.1, one thread per connection) answering from a
//! handler, and a "model" that answers mesa's three prompts validly by reading them.
#![allow(dead_code)] // Each test file uses its own subset.

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use assert_cmd::Command;
use serde_json::{json, Value};

/// The pid of a process that has exited and been reaped (the writer of a leftover that a run
/// may sweep).
pub fn dead_pid() -> u32 {
    let mut child = std::process::Command::new("true")
        .spawn()
        .expect("spawn true");
    let pid = child.id();
    child.wait().expect("wait");
    pid
}

/// The `mesa` binary under test.
pub fn mesa() -> Command {
    Command::cargo_bin("mesa").expect("the mesa binary")
}

/// A Python with `bpy` (Blender 4.3 as a module: `MESA_BLENDER_PYTHON`, which scripts/test.sh
/// sets, or `MESA_PYTHON`), or a skip naming `what` (a failure under MESA_REQUIRE_TOOLS).
#[allow(dead_code)]
pub fn blender(what: &str) -> Option<PathBuf> {
    let found = ["MESA_BLENDER_PYTHON", "MESA_PYTHON"]
        .iter()
        .find_map(|var| {
            let python = PathBuf::from(std::env::var_os(var)?);
            std::process::Command::new(&python)
                .args(["-c", "import bpy"])
                .output()
                .is_ok_and(|o| o.status.success())
                .then_some(python)
        });
    if found.is_none() {
        let how = "set MESA_BLENDER_PYTHON to a Python with bpy 4.3; scripts/test.sh installs one";
        assert!(
            std::env::var_os("MESA_REQUIRE_TOOLS").is_none(),
            "Blender is missing and MESA_REQUIRE_TOOLS is set ({how})"
        );
        eprintln!("SKIPPED: {what} ({how})");
    }
    found
}

/// A Python that imports `modules` (comma-separated): `MESA_PYTHON`, else the repository's
/// `.venv-tools` (scripts/test.sh installs it); None says SKIPPED naming `what`, and fails
/// under `MESA_REQUIRE_TOOLS`.
pub fn python_with(modules: &str, what: &str) -> Option<PathBuf> {
    let candidates = [
        std::env::var_os("MESA_PYTHON").map(PathBuf::from),
        Some(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../.venv-tools/bin/python")),
    ];
    let found = candidates.into_iter().flatten().find(|python| {
        std::process::Command::new(python)
            .args(["-c", &format!("import {modules}")])
            .output()
            .is_ok_and(|o| o.status.success())
    });
    if found.is_none() {
        let how = format!(
            "set MESA_PYTHON to a Python with {modules}; scripts/test.sh installs one from \
             scripts/requirements-tools.txt"
        );
        assert!(
            std::env::var_os("MESA_REQUIRE_TOOLS").is_none(),
            "{what}: no Python with {modules} and MESA_REQUIRE_TOOLS is set ({how})"
        );
        eprintln!("SKIPPED: {what} ({how})");
    }
    found
}

/// `../shared` beside the repository (or `$MESA_SHARED`).
pub fn shared() -> PathBuf {
    std::env::var_os("MESA_SHARED")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared"))
}

/// The 7 published MesaTask gallery records, sorted.
pub fn gallery() -> Vec<PathBuf> {
    let dir = shared().join("realdata/layouts/mesatask_gallery");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e} (the tests need ../shared/realdata)", dir.display()))
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .collect();
    files.sort();
    assert_eq!(files.len(), 7);
    files
}

/// Every file under `scenes/` and `.mesa/markers/` of a dataset, by relative path.
pub fn snapshot(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    fn walk(root: &Path, dir: &Path, out: &mut BTreeMap<String, Vec<u8>>) {
        let Ok(entries) = std::fs::read_dir(dir) else {
            return;
        };
        for entry in entries {
            let path = entry.expect("entry").path();
            if path.is_dir() {
                walk(root, &path, out);
            } else {
                let rel = path
                    .strip_prefix(root)
                    .expect("prefix")
                    .to_string_lossy()
                    .into_owned();
                out.insert(rel, std::fs::read(&path).expect("read"));
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(dir, &dir.join("scenes"), &mut out);
    walk(dir, &dir.join(".mesa/markers"), &mut out);
    out
}

// ---------------------------------------------------------------------------------------------
// A local chat server.

/// A request the server received.
#[derive(Debug, Clone)]
pub struct Received {
    /// `POST /v1/chat/completions`.
    pub request_line: String,
    /// Header lines as received.
    pub headers: Vec<String>,
    /// The body.
    pub body: String,
}

impl Received {
    /// A header's value (case-insensitive name).
    pub fn header(&self, name: &str) -> Option<String> {
        self.headers.iter().find_map(|h| {
            let (k, v) = h.split_once(':')?;
            k.trim()
                .eq_ignore_ascii_case(name)
                .then(|| v.trim().to_owned())
        })
    }

    /// The body as JSON.
    pub fn json(&self) -> Value {
        serde_json::from_str(&self.body).expect("the client sends JSON")
    }
}

/// What the server answers.
#[derive(Debug, Clone)]
pub struct Reply {
    /// HTTP status.
    pub status: u16,
    /// Extra headers.
    pub headers: Vec<(String, String)>,
    /// Body text.
    pub body: String,
    /// Wait this long before answering.
    pub delay: Duration,
}

impl Reply {
    /// 200 with a chat completion whose content is `content`.
    pub fn completion(content: &str) -> Self {
        Self {
            status: 200,
            headers: vec![],
            body: json!({
                "id": "chatcmpl-test",
                "object": "chat.completion",
                "model": "mock-model-2026",
                "choices": [{"index": 0, "message": {"role": "assistant", "content": content},
                             "finish_reason": "stop"}],
                "usage": {"prompt_tokens": 10, "completion_tokens": 10, "total_tokens": 20}
            })
            .to_string(),
            delay: Duration::ZERO,
        }
    }

    /// A status with a JSON error body.
    pub fn error(status: u16, message: &str) -> Self {
        Self {
            status,
            headers: vec![],
            body: json!({"error": {"message": message, "type": "test"}}).to_string(),
            delay: Duration::ZERO,
        }
    }

    /// With a header.
    pub fn with_header(mut self, name: &str, value: &str) -> Self {
        self.headers.push((name.to_owned(), value.to_owned()));
        self
    }

    /// After a delay.
    pub fn after(mut self, delay: Duration) -> Self {
        self.delay = delay;
        self
    }
}

type Handler = dyn Fn(&Received, usize) -> Reply + Send + Sync;

/// The server. Dropping it stops it.
pub struct MockServer {
    /// `http://127.0.0.1:PORT/v1`.
    pub base_url: String,
    received: Arc<Mutex<Vec<Received>>>,
    count: Arc<AtomicUsize>,
    stop: Arc<AtomicBool>,
    addr: std::net::SocketAddr,
    thread: Option<JoinHandle<()>>,
}

impl MockServer {
    /// Starts a server whose handler sees each request and its number (from 0, in arrival
    /// order).
    pub fn start(handler: impl Fn(&Received, usize) -> Reply + Send + Sync + 'static) -> Self {
        let listener = TcpListener::bind("127.0.0.1:0").expect("bind 127.0.0.1");
        let addr = listener.local_addr().expect("address");
        let received = Arc::new(Mutex::new(Vec::new()));
        let count = Arc::new(AtomicUsize::new(0));
        let stop = Arc::new(AtomicBool::new(false));
        let handler: Arc<Handler> = Arc::new(handler);
        let thread = {
            let (received, count, stop) = (received.clone(), count.clone(), stop.clone());
            std::thread::spawn(move || {
                for stream in listener.incoming() {
                    if stop.load(Ordering::SeqCst) {
                        break;
                    }
                    let Ok(stream) = stream else { continue };
                    let (received, count, handler) =
                        (received.clone(), count.clone(), handler.clone());
                    std::thread::spawn(move || serve(stream, &received, &count, handler.as_ref()));
                }
            })
        };
        Self {
            base_url: format!("http://{addr}/v1"),
            received,
            count,
            stop,
            addr,
            thread: Some(thread),
        }
    }

    /// Requests received so far.
    pub fn requests(&self) -> usize {
        self.count.load(Ordering::SeqCst)
    }

    /// Every request received, in arrival order.
    pub fn received(&self) -> Vec<Received> {
        self.received.lock().expect("lock").clone()
    }
}

impl Drop for MockServer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        let _ = TcpStream::connect(self.addr);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

fn serve(
    stream: TcpStream,
    received: &Mutex<Vec<Received>>,
    count: &AtomicUsize,
    handler: &Handler,
) {
    let mut reader = BufReader::new(stream.try_clone().expect("clone stream"));
    let mut stream = stream;
    // Keep-alive: answer requests on this connection until the client closes it.
    loop {
        let mut request_line = String::new();
        match reader.read_line(&mut request_line) {
            Ok(0) | Err(_) => return,
            Ok(_) => {}
        }
        let mut headers = Vec::new();
        let mut length = 0usize;
        loop {
            let mut line = String::new();
            if reader.read_line(&mut line).unwrap_or(0) == 0 {
                return;
            }
            let line = line.trim_end().to_owned();
            if line.is_empty() {
                break;
            }
            if let Some((k, v)) = line.split_once(':') {
                if k.trim().eq_ignore_ascii_case("content-length") {
                    length = v.trim().parse().unwrap_or(0);
                }
            }
            headers.push(line);
        }
        let mut body = vec![0u8; length];
        if reader.read_exact(&mut body).is_err() {
            return;
        }
        let request = Received {
            request_line: request_line.trim_end().to_owned(),
            headers,
            body: String::from_utf8_lossy(&body).into_owned(),
        };
        let n = count.fetch_add(1, Ordering::SeqCst);
        received.lock().expect("lock").push(request.clone());
        let reply = handler(&request, n);
        std::thread::sleep(reply.delay);
        let reason = match reply.status {
            200 => "OK",
            400 => "Bad Request",
            401 => "Unauthorized",
            429 => "Too Many Requests",
            500 => "Internal Server Error",
            503 => "Service Unavailable",
            _ => "Status",
        };
        let mut head = format!(
            "HTTP/1.1 {} {reason}\r\nContent-Type: application/json\r\nContent-Length: {}\r\n",
            reply.status,
            reply.body.len()
        );
        for (k, v) in &reply.headers {
            head.push_str(&format!("{k}: {v}\r\n"));
        }
        head.push_str("\r\n");
        if stream.write_all(head.as_bytes()).is_err()
            || stream.write_all(reply.body.as_bytes()).is_err()
        {
            return;
        }
        let _ = stream.flush();
    }
}

// ---------------------------------------------------------------------------------------------
// A model that answers mesa's prompts.

/// Which of mesa's calls a request makes, from its system message.
pub fn call_of(body: &Value) -> &'static str {
    let system = body["messages"][0]["content"].as_str().unwrap_or("");
    if system.contains("describe tabletop scenes") {
        "description"
    } else if system.contains("manipulation tasks") {
        "tasks"
    } else if system.contains("explain tabletop layouts") {
        "reasoning"
    } else {
        "unknown"
    }
}

/// The user message's text (the first text part when it has images).
pub fn user_text(body: &Value) -> String {
    let content = &body["messages"][1]["content"];
    match content {
        Value::String(text) => text.clone(),
        Value::Array(parts) => parts[0]["text"].as_str().unwrap_or("").to_owned(),
        _ => String::new(),
    }
}

/// The `Type(count)` list following `marker` on its line.
fn list_after(text: &str, marker: &str) -> Vec<(String, usize)> {
    let Some(line) = text.lines().find(|l| l.contains(marker)) else {
        return Vec::new();
    };
    let list = &line[line.find(marker).expect("marker") + marker.len()..];
    list.trim()
        .trim_end_matches('.')
        .split(", ")
        .filter_map(|item| {
            let (name, count) = item.trim().rsplit_once('(')?;
            Some((
                name.trim().to_owned(),
                count.trim_end_matches(')').parse().ok()?,
            ))
        })
        .collect()
}

/// A valid answer to one of mesa's prompts, written from what the prompt says (like a
/// compliant model): the description names the types, the tasks use the first three types of
/// the list, the reasoning copies the lists it is given.
pub fn answer(body: &Value) -> String {
    let text = user_text(body);
    match call_of(body) {
        "description" => {
            let objects = list_after(&text, "as Type(count): ");
            let names: Vec<String> = objects.iter().map(|(n, _)| n.to_lowercase()).collect();
            format!(
                "A tidy table holding {}, spread from left to right.",
                names.join(", ")
            )
        }
        "tasks" => {
            let objects = list_after(&text, "Objects on it, as Type(count): ");
            let names: Vec<&str> = objects.iter().map(|(n, _)| n.as_str()).take(3).collect();
            let tasks: Vec<Value> = (0..5)
                .map(|k| {
                    let a = names[k % names.len()];
                    let b = names[(k + 1) % names.len()];
                    json!({
                        "Task": format!("Task {k}: move the {a} next to the {b}"),
                        "Goal": [format!("Pick up the {a}"), format!("Place it next to the {b}")],
                        "Action Sequence": [format!("Pick({a})"), format!("PlaceAt(next to {b})")],
                        "Objects cluster": names,
                    })
                })
                .collect();
            json!({ "tasks": tasks }).to_string()
        }
        "reasoning" => {
            let core = list_after(
                &text,
                "the types the task involves as Type(count), separated by commas: ",
            );
            let environment = list_after(
                &text,
                "every other type as Type(count), separated by commas: ",
            );
            let show = |items: &[(String, usize)]| {
                if items.is_empty() {
                    "None".to_owned()
                } else {
                    items
                        .iter()
                        .map(|(n, c)| format!("{n}({c})"))
                        .collect::<Vec<_>>()
                        .join(", ")
                }
            };
            format!(
                "The goal is a layout for the task at hand.\n\n**Core Task Objects:**\n{}\n\n\
                 **Environment Objects:**\n{}\n\nThe objects stand where the task needs them. \
                 Based on this analysis, the scene graph is as follows:",
                show(&core),
                show(&environment)
            )
        }
        other => panic!("the mock model got an unknown call {other}"),
    }
}

/// The completion body of an answer (as a provider's batch output holds it).
pub fn completion_body(content: &str) -> Value {
    serde_json::from_str(&Reply::completion(content).body).expect("json")
}

// ---------------------------------------------------------------------------------------------
// Datasets.

/// Writes a dataset whose scenes have only a layout: the seven published layouts, converted to
/// the dataset form (sorted by footprint, as mesa writes layouts), each as
/// `scenes/<table_type>/<table_type>_000<k>/refined/layout.json` (as annotated and
/// ingested), spread over table types.
pub fn gallery_dataset(dir: &Path) {
    use mesa_schemas::convert::dataset_from_llm;
    let table_types = [
        "dining_table",
        "office_table",
        "kitchen_counter",
        "office_table",
        "bathroom_vanity",
        "kitchen_counter",
        "coffee_table",
    ];
    for (k, path) in gallery().iter().enumerate() {
        let record: mesa_schemas::GalleryRecord =
            serde_json::from_str(&std::fs::read_to_string(path).expect("read")).expect("record");
        let llm = record.scene_layout_json.resolve().expect("layout");
        let mut dataset = dataset_from_llm(&llm).layout;
        dataset.sort_objects();
        for object in &mut dataset.objects {
            object.retrieved_uid = format!("uid-{}", object.instance);
        }
        let table = table_types[k];
        let scene = dir.join(format!(
            "scenes/{table}/{table}_{:04}/refined/layout.json",
            k + 1
        ));
        std::fs::create_dir_all(scene.parent().expect("parent")).expect("mkdir");
        std::fs::write(
            &scene,
            mesa_schemas::json::to_sorted_pretty(&dataset).expect("json"),
        )
        .expect("write layout");
    }
}

/// Every file under `dir`, relative path → bytes (for comparing record files and scanning a
/// whole dataset for secrets).
pub fn all_files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_owned()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).expect("list") {
            let path = entry.expect("entry").path();
            if path.is_dir() {
                stack.push(path);
            } else {
                let rel = path
                    .strip_prefix(dir)
                    .expect("prefix")
                    .to_string_lossy()
                    .into_owned();
                out.insert(rel, std::fs::read(&path).expect("read"));
            }
        }
    }
    out
}

/// A JSON file read into `T`, panicking with the path on any problem.
pub fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> T {
    serde_json::from_slice(
        &std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
    )
    .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Copies the folder `from` to `to`, files and subfolders.
pub fn copy_tree(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).expect("mkdir");
    for entry in std::fs::read_dir(from).expect("read_dir") {
        let path = entry.expect("entry").path();
        let target = to.join(path.file_name().expect("name"));
        if path.is_dir() {
            copy_tree(&path, &target);
        } else {
            std::fs::copy(&path, &target).expect("copy");
        }
    }
}

/// Every scene folder of a dataset (`scenes/<table_type>/<scene_id>`), sorted.
pub fn scene_dirs(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for table in std::fs::read_dir(dir.join("scenes")).expect("scenes") {
        for scene in std::fs::read_dir(table.expect("entry").path()).expect("table") {
            out.push(scene.expect("entry").path());
        }
    }
    out.sort();
    out
}

/// The dataset's collision shapes by uid, read from the asset index as `mesa check` reads them.
pub fn dataset_shapes(dir: &Path) -> BTreeMap<String, Arc<mesa_stages::check::AssetShape>> {
    let index: mesa_schemas::artifacts::AssetIndexArtifact =
        read_json(&dir.join("assets/index/assets.json"));
    index
        .assets
        .iter()
        .filter_map(|(uid, record)| {
            let (s, g) = (record.shapes.as_ref()?, record.geometry.as_ref()?);
            let artifact: mesa_schemas::artifacts::ShapesArtifact = read_json(&dir.join(&s.file));
            // With its mesh, as `mesa check` holds it (loose objects are judged on it).
            let (dataset, id, rec) = (dir.to_owned(), uid.clone(), record.clone());
            let shape = mesa_stages::check::AssetShape::new(uid, &artifact, g)
                .expect("shape")
                .with_mesh_loader(move || {
                    mesa_pipeline::commands::check::read_asset_mesh(&dataset, &id, &rec).map(|m| {
                        mesa_stages::check::solid::AssetMesh::new(m.positions_m, m.triangles)
                    })
                });
            Some((uid.clone(), Arc::new(shape)))
        })
        .collect()
}
