//! Hostile files where mesa expects a small regular file: a FIFO or a device as a scene input,
//! a huge sparse file as a layout or JSON artifact, special files as `convert -o` targets, and
//! a standard output that is closed or full. Every crafted file is made here, in a temp folder,
//! and every command runs under a deadline so a hang fails the test instead of stalling it.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

/// How long any one command may take before the test calls it hung.
const DEADLINE: Duration = Duration::from_secs(60);

fn mesa_bin() -> PathBuf {
    assert_cmd::cargo::cargo_bin("mesa")
}

/// Waits for `child` at most [`DEADLINE`], killing it (and failing the test) on timeout.
fn wait_with_deadline(mut child: Child, what: &str) -> Output {
    let start = Instant::now();
    loop {
        match child.try_wait().expect("poll the child") {
            Some(_) => return child.wait_with_output().expect("collect output"),
            None if start.elapsed() > DEADLINE => {
                let _ = child.kill();
                let _ = child.wait();
                panic!("`{what}` still running after {DEADLINE:?}: it hangs");
            }
            None => std::thread::sleep(Duration::from_millis(50)),
        }
    }
}

/// Runs `mesa ARGS` with stdout and stderr captured, under the deadline.
fn run_mesa(args: &[&std::ffi::OsStr]) -> Output {
    let child = Command::new(mesa_bin())
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn mesa");
    let what = format!(
        "mesa {}",
        args.join(std::ffi::OsStr::new(" ")).to_string_lossy()
    );
    wait_with_deadline(child, &what)
}

fn os(s: &str) -> &std::ffi::OsStr {
    std::ffi::OsStr::new(s)
}

fn stderr_of(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// A 2-scene demo dataset; returns its folder and the scene folders (relative, sorted).
fn demo(dir: &Path) -> (PathBuf, Vec<String>) {
    let ws = dir.join("demo");
    let out = run_mesa(&[
        os("demo"),
        ws.as_os_str(),
        os("--scenes"),
        os("2"),
        os("--seed"),
        os("7"),
        os("-q"),
    ]);
    assert!(out.status.success(), "demo: {}", stderr_of(&out));
    let mut scenes = Vec::new();
    for table in std::fs::read_dir(ws.join("scenes")).expect("scenes") {
        let table = table.expect("entry").path();
        for scene in std::fs::read_dir(&table).expect("table") {
            let scene = scene.expect("entry").path();
            let rel = scene.strip_prefix(ws.join("scenes")).expect("prefix");
            scenes.push(rel.to_string_lossy().into_owned());
        }
    }
    scenes.sort();
    assert_eq!(scenes.len(), 2, "{scenes:?}");
    (ws, scenes)
}

fn mkfifo(path: &Path) {
    let status = Command::new("mkfifo")
        .arg(path)
        .status()
        .expect("run mkfifo");
    assert!(status.success(), "mkfifo {}", path.display());
}

/// Lifts a demo whose first scene's camera.json was replaced by `make_special`; the scene
/// fails with a marker naming the file as not a regular file, the other is lifted.
fn lift_with_special_camera(make_special: impl FnOnce(&Path), kind: &str) {
    let dir = tempfile::tempdir().expect("tempdir");
    let (ws, scenes) = demo(dir.path());
    let camera = ws.join("scenes").join(&scenes[0]).join("input/camera.json");
    std::fs::remove_file(&camera).expect("remove camera.json");
    make_special(&camera);

    let out = run_mesa(&[os("lift"), os("--progress"), os("off"), ws.as_os_str()]);
    let stderr = stderr_of(&out);
    assert_eq!(out.status.code(), Some(1), "one scene fails: {stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");

    let marker = ws
        .join(".mesa/markers/lift")
        .join(format!("{}.json", scenes[0]));
    let marker: Value =
        serde_json::from_slice(&std::fs::read(&marker).expect("failed marker")).expect("json");
    assert_eq!(marker["status"], "failed", "{marker}");
    let error = marker["error"].to_string();
    assert!(
        error.contains("input/camera.json") && error.contains("not a regular file"),
        "the marker names the file and says what is wrong: {error}"
    );
    assert!(error.contains(kind), "{error}");

    // The other scene finished.
    let lifted = ws.join("scenes").join(&scenes[1]).join("coarse/lift.json");
    assert!(lifted.is_file(), "the other scene is lifted: {stderr}");
}

#[test]
fn a_fifo_as_a_scene_input_fails_that_scene_only() {
    lift_with_special_camera(mkfifo, "a FIFO");
}

#[test]
fn a_symlink_to_dev_zero_as_a_scene_input_fails_that_scene_only() {
    lift_with_special_camera(
        |camera| std::os::unix::fs::symlink("/dev/zero", camera).expect("symlink"),
        "a character device",
    );
}

/// A 3 GiB sparse file (no disk used).
fn sparse(path: &Path) {
    let file = std::fs::File::create(path).expect("create");
    file.set_len(3 << 30).expect("set_len");
}

/// Asserts `out` is a quick refusal naming the file, its size and the limit.
fn assert_too_big(out: &Output, path: &Path, text: &str) {
    assert_eq!(out.status.code(), Some(1), "{text}");
    assert!(!text.contains("panicked"), "{text}");
    for part in [
        path.display().to_string().as_str(),
        "3221225472 bytes (3.0 GiB)",
        "over the limit of 67108864 bytes (64.0 MiB) for a layout or JSON file",
        "check it is the file meant",
    ] {
        assert!(text.contains(part), "missing {part:?} in: {text}");
    }
}

#[test]
fn a_huge_layout_is_refused_before_it_is_read() {
    let dir = tempfile::tempdir().expect("tempdir");
    let big = dir.path().join("layout.json");
    sparse(&big);

    let out = run_mesa(&[os("convert"), big.as_os_str(), os("--to"), os("llm")]);
    assert_too_big(&out, &big, &stderr_of(&out));

    let out = run_mesa(&[os("graph"), os("--layout"), big.as_os_str()]);
    assert_too_big(&out, &big, &stderr_of(&out));

    // validate reports on standard output, one line per problem.
    let out = run_mesa(&[os("validate"), big.as_os_str()]);
    assert_too_big(&out, &big, &String::from_utf8_lossy(&out.stdout));

    let out = run_mesa(&[os("parse-output"), big.as_os_str()]);
    assert_too_big(&out, &big, &stderr_of(&out));
}

#[test]
fn a_huge_or_special_config_is_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (ws, _) = demo(dir.path());
    let config = ws.join("mesa.toml");
    sparse(&config);
    let out = run_mesa(&[os("lift"), os("--progress"), os("off"), ws.as_os_str()]);
    let stderr = stderr_of(&out);
    assert_eq!(
        out.status.code(),
        Some(2),
        "a configuration error: {stderr}"
    );
    assert!(
        stderr.contains("mesa.toml")
            && stderr
                .contains("over the limit of 1048576 bytes (1.0 MiB) for a configuration file"),
        "{stderr}"
    );

    std::fs::remove_file(&config).expect("remove");
    mkfifo(&config);
    let out = run_mesa(&[os("lift"), os("--progress"), os("off"), ws.as_os_str()]);
    let stderr = stderr_of(&out);
    assert_eq!(
        out.status.code(),
        Some(2),
        "a configuration error: {stderr}"
    );
    assert!(
        stderr.contains("mesa.toml") && stderr.contains("not a regular file (a FIFO)"),
        "{stderr}"
    );
}

/// An LLM layout of `n` small objects on a grid (a long graph to print).
fn grid_layout(path: &Path, n: usize) {
    let objects: Vec<Value> = (0..n)
        .map(|i| {
            let (x, y) = ((i % 20) as f64 * 10.0 + 5.0, (i / 20) as f64 * 10.0 + 5.0);
            serde_json::json!({"instance": format!("cup_{i}"), "size": [4.0, 4.0, 8.0],
                "position": [x, y, 4.0], "z_rotation": 0.0, "description": ""})
        })
        .collect();
    let rows = n.div_ceil(20) as f64;
    let layout = serde_json::json!({
        "item_placement_zone": [0.0, 200.0, 0.0, rows * 10.0],
        "objects": objects,
    });
    std::fs::write(path, serde_json::to_vec_pretty(&layout).expect("json")).expect("write");
}

#[test]
fn a_closed_stdout_is_a_quiet_exit_not_a_panic() {
    let dir = tempfile::tempdir().expect("tempdir");
    let layout = dir.path().join("layout.json");
    grid_layout(&layout, 200);
    let mut child = Command::new(mesa_bin())
        .args([os("graph"), os("--layout"), layout.as_os_str()])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn");
    // Close the read end before mesa has parsed the layout, so its first write meets a
    // closed pipe.
    drop(child.stdout.take());
    let out = wait_with_deadline(child, "mesa graph --layout");
    let stderr = stderr_of(&out);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(!stderr.contains("error"), "quiet: {stderr}");
}

#[test]
fn a_full_stdout_is_an_error_with_a_message() {
    let dir = tempfile::tempdir().expect("tempdir");
    let layout = dir.path().join("layout.json");
    grid_layout(&layout, 20);
    for args in [
        vec![os("graph"), os("--layout"), layout.as_os_str()],
        vec![os("convert"), layout.as_os_str(), os("--to"), os("dataset")],
    ] {
        let full = std::fs::OpenOptions::new()
            .write(true)
            .open("/dev/full")
            .expect("/dev/full");
        let child = Command::new(mesa_bin())
            .args(&args)
            .stdin(Stdio::null())
            .stdout(Stdio::from(full))
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn");
        let out = wait_with_deadline(child, "mesa > /dev/full");
        let stderr = stderr_of(&out);
        assert!(!stderr.contains("panicked"), "{stderr}");
        assert_eq!(out.status.code(), Some(1), "{stderr}");
        assert!(
            stderr.contains("standard output: cannot write") && stderr.contains("No space left"),
            "{stderr}"
        );
    }
}

/// `mesa convert LAYOUT --to dataset -o TARGET`, under the deadline.
fn convert_to(layout: &Path, target: &Path) -> Output {
    run_mesa(&[
        os("convert"),
        layout.as_os_str(),
        os("--to"),
        os("dataset"),
        os("-o"),
        target.as_os_str(),
    ])
}

#[test]
fn convert_output_onto_a_symlink_updates_its_target() {
    let dir = tempfile::tempdir().expect("tempdir");
    let layout = dir.path().join("layout.json");
    grid_layout(&layout, 3);
    let real = dir.path().join("real.json");
    std::fs::write(&real, b"old").expect("write");
    let link = dir.path().join("link.json");
    std::os::unix::fs::symlink(&real, &link).expect("symlink");
    let out = convert_to(&layout, &link);
    assert!(out.status.success(), "{}", stderr_of(&out));
    assert!(
        std::fs::symlink_metadata(&link)
            .expect("link")
            .file_type()
            .is_symlink(),
        "the symlink stays a symlink"
    );
    let written = std::fs::read_to_string(&real).expect("read");
    assert!(
        written.contains("cup_0"),
        "its target is updated: {written}"
    );
}

#[test]
fn convert_output_dash_is_standard_output() {
    let dir = tempfile::tempdir().expect("tempdir");
    let layout = dir.path().join("layout.json");
    grid_layout(&layout, 3);
    let out = convert_to(&layout, Path::new("-"));
    assert!(out.status.success(), "{}", stderr_of(&out));
    assert!(String::from_utf8_lossy(&out.stdout).contains("cup_0"));
    assert!(!dir.path().join("-").exists() && !Path::new("-").exists());
}

#[test]
fn convert_output_onto_a_fifo_writes_through_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    let layout = dir.path().join("layout.json");
    grid_layout(&layout, 3);
    let fifo = dir.path().join("out.fifo");
    mkfifo(&fifo);
    let reader = {
        let fifo = fifo.clone();
        std::thread::spawn(move || std::fs::read(&fifo).expect("read the fifo"))
    };
    let out = convert_to(&layout, &fifo);
    assert!(out.status.success(), "{}", stderr_of(&out));
    let received = reader.join().expect("reader");
    assert!(String::from_utf8_lossy(&received).contains("cup_0"));
    use std::os::unix::fs::FileTypeExt as _;
    assert!(
        std::fs::symlink_metadata(&fifo)
            .expect("fifo")
            .file_type()
            .is_fifo(),
        "the FIFO remains a FIFO"
    );
}

#[test]
fn convert_output_onto_a_regular_file_is_still_atomic() {
    let dir = tempfile::tempdir().expect("tempdir");
    let layout = dir.path().join("layout.json");
    grid_layout(&layout, 3);
    let target = dir.path().join("out.json");
    std::fs::write(&target, b"old").expect("write");
    let inode_before = std::os::unix::fs::MetadataExt::ino(&std::fs::metadata(&target).expect("m"));
    let out = convert_to(&layout, &target);
    assert!(out.status.success(), "{}", stderr_of(&out));
    let meta = std::fs::metadata(&target).expect("meta");
    assert!(meta.is_file());
    // A rename over the target gives it a new inode; an in-place write would keep the old one.
    assert_ne!(std::os::unix::fs::MetadataExt::ino(&meta), inode_before);
    assert!(std::fs::read_to_string(&target)
        .expect("read")
        .contains("cup_0"));
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .expect("list")
        .map(|e| e.expect("entry").file_name())
        .filter(|n| n.to_string_lossy().contains(".mesa-tmp-"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

#[test]
fn a_nan_in_camera_json_is_named_not_shown_as_a_sentinel() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (ws, scenes) = demo(dir.path());
    let camera = ws.join("scenes").join(&scenes[0]).join("input/camera.json");
    let mut value: Value =
        serde_json::from_slice(&std::fs::read(&camera).expect("read")).expect("json");
    value["width"] = Value::from("__NAN__");
    let text = serde_json::to_string_pretty(&value)
        .expect("json")
        .replace("\"__NAN__\"", "NaN");
    std::fs::write(&camera, text).expect("write");

    let out = run_mesa(&[os("lift"), os("--progress"), os("off"), ws.as_os_str()]);
    let stderr = stderr_of(&out);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    let marker = ws
        .join(".mesa/markers/lift")
        .join(format!("{}.json", scenes[0]));
    let marker = std::fs::read_to_string(&marker).expect("failed marker");
    assert!(
        marker.contains("width: is NaN, which is not a number JSON allows"),
        "{marker}"
    );
    assert!(
        !marker.contains("nonfinite") && !stderr.contains("nonfinite"),
        "no internal sentinel: {marker}\n{stderr}"
    );
    assert!(ws
        .join("scenes")
        .join(&scenes[1])
        .join("coarse/lift.json")
        .is_file());
}

#[test]
fn a_byte_order_mark_is_named_by_every_json_reader() {
    let dir = tempfile::tempdir().expect("tempdir");
    let plain = dir.path().join("plain.json");
    grid_layout(&plain, 3);
    let layout = dir.path().join("layout.json");
    let mut bytes = "\u{feff}".as_bytes().to_vec();
    bytes.extend(std::fs::read(&plain).expect("read"));
    std::fs::write(&layout, bytes).expect("write");

    for args in [
        vec![os("convert"), layout.as_os_str(), os("--to"), os("dataset")],
        vec![os("graph"), os("--layout"), layout.as_os_str()],
        vec![os("validate"), layout.as_os_str()],
    ] {
        let out = run_mesa(&args);
        let text = format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            stderr_of(&out)
        );
        assert_eq!(out.status.code(), Some(1), "{text}");
        assert!(
            text.contains("starts with a UTF-8 byte order mark") && text.contains("without one"),
            "{args:?}: {text}"
        );
        assert!(!text.contains("expected value at line 1"), "{text}");
    }
}

/// Copies the first demo scene to a sibling folder named `name` (raw bytes on Unix).
fn copy_scene_as(ws: &Path, scene: &str, name: &std::ffi::OsStr) -> PathBuf {
    let from = ws.join("scenes").join(scene);
    let to = from.parent().expect("table").join(name);
    let status = Command::new("cp")
        .arg("-r")
        .arg(&from)
        .arg(&to)
        .status()
        .expect("cp");
    assert!(status.success());
    to
}

#[test]
fn scene_folders_mesa_cannot_name_fail_alone_and_say_why() {
    use std::os::unix::ffi::OsStrExt;
    let dir = tempfile::tempdir().expect("tempdir");
    let (ws, scenes) = demo(dir.path());
    let long = "s".repeat(230);
    let bad = [
        (
            std::ffi::OsStr::from_bytes(b"scene_\xff\xfe"),
            "not valid UTF-8",
        ),
        (os(&long), "has 230 bytes (at most 200"),
        (os("scene\nline"), "control character"),
    ];
    for (name, _) in &bad {
        copy_scene_as(&ws, &scenes[0], name);
    }
    copy_scene_as(&ws, &scenes[0], os("..x"));

    let out = run_mesa(&[os("lift"), os("--progress"), os("off"), ws.as_os_str()]);
    let stderr = stderr_of(&out);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    for (_, why) in &bad {
        assert!(stderr.contains(why), "{why}: {stderr}");
    }
    assert!(
        stderr.contains("..x: a hidden folder (its name starts with '.') is not a scene"),
        "a hidden folder is named, not skipped silently: {stderr}"
    );
    assert!(stderr.contains("5 scenes: 2 done"), "{stderr}");
    assert!(stderr.contains("3 failed"), "{stderr}");
    // The valid scenes are lifted, and no output is left under the bad folders.
    for scene in &scenes {
        assert!(ws
            .join("scenes")
            .join(scene)
            .join("coarse/lift.json")
            .is_file());
    }
    let table = ws.join("scenes").join(&scenes[0]);
    let table = table.parent().expect("table");
    for name in bad.iter().map(|(n, _)| n) {
        assert!(!table.join(name).join("coarse").exists(), "{name:?}");
    }

    // Control: without the bad folders (the hidden one stays), the run succeeds.
    for (name, _) in &bad {
        std::fs::remove_dir_all(table.join(name)).expect("remove");
    }
    let out = run_mesa(&[os("lift"), os("--progress"), os("off"), ws.as_os_str()]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr_of(&out));
}

#[test]
fn a_missing_raw_input_says_no_stage_writes_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (ws, scenes) = demo(dir.path());
    std::fs::remove_file(ws.join("scenes").join(&scenes[0]).join("input/camera.json"))
        .expect("remove");
    let out = run_mesa(&[os("lift"), os("--progress"), os("off"), ws.as_os_str()]);
    let stderr = stderr_of(&out);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains(
            "input/camera.json: missing input of `mesa lift` (a raw input: no stage writes it"
        ),
        "{stderr}"
    );
    assert!(!stderr.contains("run the stage that writes it"), "{stderr}");

    // A missing stage output names its stage.
    let out = run_mesa(&[os("retrieve"), os("--progress"), os("off"), ws.as_os_str()]);
    let stderr = stderr_of(&out);
    assert!(
        stderr
            .contains("coarse/lift.json: missing input of `mesa retrieve` (run `mesa lift` first)"),
        "{stderr}"
    );
}

#[test]
fn fifos_among_the_files_report_and_release_read_never_hang_them() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (ws, scenes) = demo(dir.path());
    let scene = ws.join("scenes").join(&scenes[0]);
    for rel in [
        "graph/graph.json",
        "qa/check.json",
        "render/front.png",
        "render/front_camera.json",
        "tasks/tasks.jsonl",
    ] {
        std::fs::create_dir_all(scene.join(rel).parent().expect("parent")).expect("mkdir");
        mkfifo(&scene.join(rel));
    }
    // A layout to release: the demo's truth, as if ingested.
    std::fs::create_dir_all(scene.join("refined")).expect("mkdir");
    std::fs::copy(
        scene.join("truth/layout.json"),
        scene.join("refined/layout.json"),
    )
    .expect("copy");
    // Under the deadline of run_mesa: a read of any FIFO would block forever.
    let out = run_mesa(&[os("report"), ws.as_os_str(), os("-q")]);
    assert!(!stderr_of(&out).contains("panicked"), "{}", stderr_of(&out));
    assert!(
        ws.join("report/index.html").is_file(),
        "{}",
        stderr_of(&out)
    );
    let out = run_mesa(&[
        os("release"),
        ws.as_os_str(),
        dir.path().join("release").as_os_str(),
        os("-q"),
    ]);
    let stderr = stderr_of(&out);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(
        stderr.contains("front_camera.json") && stderr.contains("not a regular file (a FIFO)"),
        "{stderr}"
    );
}

/// Issue #20 item 13: a key given twice is refused by every JSON reader with the file, the key,
/// its JSON path and its line, instead of silently keeping the last value.
#[test]
fn a_duplicate_key_is_named_by_every_json_reader() {
    let dir = tempfile::tempdir().expect("tempdir");
    let plain = dir.path().join("plain.json");
    grid_layout(&plain, 3);
    let text = std::fs::read_to_string(&plain).expect("read");
    // The second object gets its size twice: the first [4, 4, 8], then a 1 m cup.
    let marker = "\"size\": [";
    let second = text.match_indices(marker).nth(1).expect("a second size").0;
    let mut twice = text.clone();
    twice.insert_str(second, "\"size\": [100.0, 100.0, 100.0],\n      ");
    let layout = dir.path().join("layout.json");
    std::fs::write(&layout, &twice).expect("write");
    let line = twice[..second].lines().count() + 1;

    for (file, code) in [(&layout, 1), (&plain, 0)] {
        for args in [
            vec![os("convert"), file.as_os_str(), os("--to"), os("dataset")],
            vec![os("graph"), os("--layout"), file.as_os_str()],
            vec![
                os("validate"),
                os("--kind"),
                os("llm-layout"),
                file.as_os_str(),
            ],
        ] {
            let out = run_mesa(&args);
            let text = format!(
                "{}{}",
                String::from_utf8_lossy(&out.stdout),
                stderr_of(&out)
            );
            // Control: the file without the duplicate passes every reader.
            assert_eq!(out.status.code(), Some(code), "{args:?}: {text}");
            if code == 1 {
                assert!(
                    text.contains(&file.display().to_string())
                        && text.contains("duplicate key \"size\" in $.objects[1]")
                        && text.contains("keep one of them")
                        && text.contains(&format!("at line {line} column")),
                    "{args:?}: {text}"
                );
            }
        }
    }
}

/// A key twice in a scene input fails that scene with the file and the key; the other scene
/// is lifted.
#[test]
fn a_duplicate_key_in_camera_json_fails_that_scene_only() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (ws, scenes) = demo(dir.path());
    let camera = ws.join("scenes").join(&scenes[0]).join("input/camera.json");
    let text = std::fs::read_to_string(&camera).expect("read");
    let twice = text.replacen('{', "{\n  \"width\": 1,", 1);
    assert_ne!(twice, text);
    std::fs::write(&camera, twice).expect("write");

    let out = run_mesa(&[os("lift"), os("--progress"), os("off"), ws.as_os_str()]);
    let stderr = stderr_of(&out);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    let marker = ws
        .join(".mesa/markers/lift")
        .join(format!("{}.json", scenes[0]));
    let marker = std::fs::read_to_string(&marker).expect("failed marker");
    assert!(
        marker.contains("input/camera.json")
            && marker.contains("duplicate key \\\"width\\\" in $")
            && marker.contains("line"),
        "{marker}"
    );
    let lifted = ws.join("scenes").join(&scenes[1]).join("coarse/lift.json");
    assert!(lifted.is_file(), "the other scene is lifted: {stderr}");
}

/// A `.npy` file of float32 whose header claims `shape`, followed by only `data_bytes` bytes.
fn npy_claiming(shape: &str, data_bytes: usize) -> Vec<u8> {
    let mut header = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {shape}, }}");
    // numpy pads the header with spaces and a newline to a multiple of 64 bytes.
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&u16::try_from(header.len()).expect("short").to_le_bytes());
    bytes.extend_from_slice(header.as_bytes());
    bytes.resize(bytes.len() + data_bytes, 0);
    bytes
}

/// Issue #20 item 1 at run level: a 1 KB depth.npy whose header claims 100000×100000, and an
/// RLE mask whose `size` claims the same, each fail their own scene with a message naming the
/// file; `mesa lift` is not aborted (no allocation failure) and the other scenes are lifted.
#[test]
fn sizes_claimed_by_a_header_fail_their_scene_and_the_others_finish() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (ws, scenes) = demo(dir.path());
    let huge_depth = copy_scene_as(&ws, &scenes[0], os("huge_depth_0001"));
    let huge_rle = copy_scene_as(&ws, &scenes[0], os("huge_rle_0001"));

    for name in ["depth.png", "depth.npy"] {
        let _ = std::fs::remove_file(huge_depth.join("input").join(name));
    }
    std::fs::write(
        huge_depth.join("input/depth.npy"),
        npy_claiming("(100000, 100000)", 1024),
    )
    .expect("write depth.npy");

    let input = huge_rle.join("input");
    let _ = std::fs::remove_file(input.join("masks.png"));
    let _ = std::fs::remove_dir_all(input.join("masks"));
    let mut instances: Value =
        serde_json::from_slice(&std::fs::read(input.join("instances.json")).expect("read"))
            .expect("json");
    for instance in instances["instances"].as_array_mut().expect("array") {
        instance["rle"] = serde_json::json!({"size": [100000, 100000], "counts": "0"});
    }
    std::fs::write(
        input.join("instances.json"),
        serde_json::to_vec_pretty(&instances).expect("json"),
    )
    .expect("write instances.json");

    let started = Instant::now();
    let out = run_mesa(&[os("lift"), os("--progress"), os("off"), ws.as_os_str()]);
    let stderr = stderr_of(&out);
    assert_eq!(
        out.status.code(),
        Some(1),
        "two scenes fail, not abort: {stderr}"
    );
    assert!(!stderr.contains("panicked") && !stderr.contains("memory allocation"));
    assert!(stderr.contains("4 scenes: 2 done"), "{stderr}");
    assert!(stderr.contains("2 failed"), "{stderr}");
    for part in [
        "depth.npy",
        "has shape [100000, 100000], 40000000000 bytes",
        "instances.json",
        "instances[0].rle: size [100000, 100000] has more than 268435456 pixels",
    ] {
        assert!(stderr.contains(part), "missing {part:?}: {stderr}");
    }
    assert!(started.elapsed() < DEADLINE);
    for scene in &scenes {
        let lifted = ws.join("scenes").join(scene).join("coarse/lift.json");
        assert!(lifted.is_file(), "{scene} is lifted: {stderr}");
    }
    for bad in [&huge_depth, &huge_rle] {
        assert!(!bad.join("coarse").exists(), "{}", bad.display());
    }

    // Control: the same copies with their inputs as the demo wrote them lift like the others.
    for bad in [&huge_depth, &huge_rle] {
        std::fs::remove_dir_all(bad).expect("remove");
    }
    copy_scene_as(&ws, &scenes[0], os("huge_depth_0001"));
    copy_scene_as(&ws, &scenes[0], os("huge_rle_0001"));
    let out = run_mesa(&[os("lift"), os("--progress"), os("off"), ws.as_os_str()]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr_of(&out));
}

/// A FIFO, a folder or a link in place of a scene's done marker (mesa's own file) never hangs
/// or stops a run: a FIFO or a folder is read as no marker, so the scene is redone and its
/// marker written over it; a link is read through, as before, so its scene is skipped. The
/// control: before the run, the FIFO is a FIFO (a read of it, as the runner did before, never
/// returns).
#[test]
fn special_files_in_place_of_markers_are_redone_over() {
    use std::os::unix::fs::FileTypeExt as _;
    let dir = tempfile::tempdir().expect("tempdir");
    let (ws, scenes) = demo(dir.path());
    let out = run_mesa(&[os("lift"), ws.as_os_str(), os("--progress"), os("off")]);
    assert!(out.status.success(), "first lift: {}", stderr_of(&out));
    let marker = |scene: &str| ws.join(".mesa/markers/lift").join(format!("{scene}.json"));
    // Scene 0: a FIFO (a read of it would block forever).
    std::fs::remove_file(marker(&scenes[0])).expect("remove marker");
    mkfifo(&marker(&scenes[0]));
    assert!(std::fs::symlink_metadata(marker(&scenes[0]))
        .expect("meta")
        .file_type()
        .is_fifo());
    // Scene 1: a link to a copy of its own marker, read through.
    let copy = dir.path().join("marker-copy.json");
    std::fs::rename(marker(&scenes[1]), &copy).expect("move marker");
    std::os::unix::fs::symlink(&copy, marker(&scenes[1])).expect("symlink");

    let out = run_mesa(&[os("lift"), ws.as_os_str(), os("--progress"), os("off")]);
    let stderr = stderr_of(&out);
    assert!(out.status.success(), "second lift: {stderr}");
    assert!(stderr.contains("1 done, 1 skipped"), "{stderr}");
    let redone = std::fs::symlink_metadata(marker(&scenes[0])).expect("meta");
    assert!(redone.is_file(), "the FIFO is replaced by a marker");
    let redone: Value =
        serde_json::from_slice(&std::fs::read(marker(&scenes[0])).expect("read")).expect("json");
    assert_eq!(redone["status"], "done", "{redone}");

    // A folder in place of scene 0's marker: redone too (the marker cannot be written over a
    // folder, so the scene reports that).
    std::fs::remove_file(marker(&scenes[0])).expect("remove marker");
    std::fs::create_dir(marker(&scenes[0])).expect("mkdir");
    let out = run_mesa(&[os("lift"), ws.as_os_str(), os("--progress"), os("off")]);
    let stderr = stderr_of(&out);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(stderr.contains("0 done, 1 skipped, 1 failed"), "{stderr}");
    assert!(stderr.contains("cannot write marker"), "{stderr}");
}
