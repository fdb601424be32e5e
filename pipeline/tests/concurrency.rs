//! Two runs on one dataset: a stage's lock (`.mesa/locks/<stage>.lock`) stops a second run of
//! the same stage with exit code 2, a lock left by a killed run is taken over, and a run sweeps
//! only the temporary files of writers that no longer run. Nothing of either stays in the
//! dataset after a run.

mod common;

use common::{all_files, dead_pid, gallery_dataset, mesa};

use std::path::{Path, PathBuf};

use serde_json::json;

fn lock_file(dataset: &Path) -> PathBuf {
    dataset.join(".mesa/locks/graph.lock")
}

fn hold_lock(dataset: &Path, pid: u32) {
    let path = lock_file(dataset);
    std::fs::create_dir_all(path.parent().expect("parent")).expect("mkdir");
    std::fs::write(&path, json!({ "pid": pid }).to_string()).expect("write lock");
}

fn graph(dataset: &Path) -> std::process::Output {
    mesa()
        .args(["graph", "--progress", "off"])
        .arg(dataset)
        .output()
        .expect("runs")
}

/// The scene's graph output, the first of the dataset.
fn first_graph_json(dataset: &Path) -> PathBuf {
    let files = all_files(dataset);
    let rel = files
        .keys()
        .find(|k| k.ends_with("graph/graph.json"))
        .expect("a graph.json");
    dataset.join(rel)
}

#[test]
fn a_lock_of_a_running_process_stops_the_run_with_code_2_naming_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    gallery_dataset(dir.path());
    // The control: without the lock the run succeeds and leaves no lock behind.
    let free = graph(dir.path());
    assert!(
        free.status.success(),
        "{}",
        String::from_utf8_lossy(&free.stderr)
    );
    assert!(!dir.path().join(".mesa/locks").exists(), "no lock stays");

    // This test's own process is alive: its pid holds the lock.
    hold_lock(dir.path(), std::process::id());
    let held = graph(dir.path());
    let stderr = String::from_utf8_lossy(&held.stderr);
    assert_eq!(held.status.code(), Some(2), "{stderr}");
    for part in [
        ".mesa/locks/graph.lock",
        "`mesa graph` is already running on this dataset",
        &format!("process {}", std::process::id()),
        "[run] lock = \"wait\"",
        "delete the lock file",
    ] {
        assert!(stderr.contains(part), "{part:?} not in: {stderr}");
    }
    assert!(
        lock_file(dir.path()).exists(),
        "another run's lock is left alone"
    );
}

#[test]
fn a_lock_of_a_dead_process_is_taken_over_with_a_warning() {
    let dir = tempfile::tempdir().expect("tempdir");
    gallery_dataset(dir.path());
    let dead = dead_pid();
    hold_lock(dir.path(), dead);
    let out = graph(dir.path());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    for part in [
        "warning:",
        "graph.lock",
        &format!("process {dead}"),
        "no longer runs",
    ] {
        assert!(stderr.contains(part), "{part:?} not in: {stderr}");
    }
    assert!(
        !dir.path().join(".mesa/locks").exists(),
        "the lock is released and its folder removed"
    );
}

#[test]
fn only_temporary_files_of_dead_writers_are_swept() {
    let dir = tempfile::tempdir().expect("tempdir");
    gallery_dataset(dir.path());
    let first = graph(dir.path());
    assert!(first.status.success());
    let output = first_graph_json(dir.path());
    let folder = output.parent().expect("folder");
    let live = folder.join(format!(".graph.json.mesa-tmp-{}-0", std::process::id()));
    let dead = folder.join(format!(".graph.json.mesa-tmp-{}-0", dead_pid()));
    std::fs::write(&live, b"another run's half-written file").expect("live");
    std::fs::write(&dead, b"a killed run's leftover").expect("dead");
    let out = mesa()
        .args(["graph", "--progress", "off", "--force"])
        .arg(dir.path())
        .output()
        .expect("runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(!dead.exists(), "a dead writer's leftover is swept");
    assert!(live.exists(), "a running writer's file is left alone");

    // The markers' folder (a file a scene) is swept once a run, before the scenes: a killed
    // run's half-written marker goes even when every scene is skipped.
    let markers = first_marker_folder(dir.path());
    let live = markers.join(format!(".x.json.mesa-tmp-{}-0", std::process::id()));
    let dead = markers.join(format!(".x.json.mesa-tmp-{}-0", dead_pid()));
    std::fs::write(&live, b"another run's half-written marker").expect("live");
    std::fs::write(&dead, b"a killed run's marker").expect("dead");
    let out = mesa()
        .args(["graph", "--progress", "off"])
        .arg(dir.path())
        .output()
        .expect("runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("0 done") && stderr.contains("skipped"),
        "{stderr}"
    );
    assert!(!dead.exists(), "a dead writer's marker is swept");
    assert!(live.exists(), "a running writer's marker is left alone");
}

/// The folder of the graph stage's markers of the first table type.
fn first_marker_folder(dataset: &std::path::Path) -> std::path::PathBuf {
    let root = dataset.join(".mesa/markers/graph");
    let mut folders: Vec<_> = std::fs::read_dir(&root)
        .expect("markers")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.is_dir())
        .collect();
    folders.sort();
    folders.remove(0)
}

#[test]
fn with_lock_wait_a_second_run_waits_for_the_holder_then_runs() {
    let dir = tempfile::tempdir().expect("tempdir");
    gallery_dataset(dir.path());
    std::fs::write(dir.path().join("mesa.toml"), "[run]\nlock = \"wait\"\n").expect("config");
    // A live process (not this test's: it must be able to go away) holds the lock.
    let mut holder = std::process::Command::new("sleep")
        .arg("60")
        .spawn()
        .expect("spawn sleep");
    hold_lock(dir.path(), holder.id());

    let mut waiting = std::process::Command::new(assert_cmd::cargo::cargo_bin("mesa"))
        .args(["graph", "--progress", "off"])
        .arg(dir.path())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("spawn mesa");
    std::thread::sleep(std::time::Duration::from_millis(1500));
    // It waits: still running, and nothing written yet.
    assert!(
        waiting.try_wait().expect("poll").is_none(),
        "with lock = \"wait\" the run must wait for the holder"
    );
    assert!(
        !all_files(dir.path())
            .keys()
            .any(|k| k.ends_with("graph/graph.json")),
        "nothing is written while the lock is held"
    );

    // The holder ends (killed: its lock stays behind, as after a crash) and the run goes on.
    holder.kill().expect("kill");
    holder.wait().expect("reap");
    let out = waiting.wait_with_output().expect("wait");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    for part in [
        "graph: waiting for",
        ".mesa/locks/graph.lock",
        "to be released",
        "no longer runs",
    ] {
        assert!(stderr.contains(part), "{part:?} not in: {stderr}");
    }
    assert!(first_graph_json(dir.path()).is_file());
    assert!(!lock_file(dir.path()).exists(), "its own lock is released");
}
