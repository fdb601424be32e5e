//! `mesa demo` from the command line: the workspace it writes is one the pipeline runs on, a
//! rerun with the same options changes nothing, other options need --force, and a folder it
//! did not write is never touched.

mod common;

use common::{mesa, snapshot};
use predicates::prelude::*;

#[test]
fn demo_writes_a_dataset_the_pipeline_runs_on() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ws = dir.path().join("demo");
    mesa()
        .args(["demo", "--scenes", "2", "--seed", "3"])
        .arg(&ws)
        .assert()
        .success()
        .stderr(predicate::str::contains("2 scenes over 2 table types"));
    // Every artifact of the scenes validates.
    mesa()
        .arg("validate")
        .arg(ws.join("scenes"))
        .assert()
        .success();
    // The first stage lifts every scene.
    mesa()
        .args(["lift", "--progress", "off"])
        .arg(&ws)
        .assert()
        .success()
        .stderr(predicate::str::contains("2 done"));
    for scene in [
        "office_table/office_table_0001",
        "dining_table/dining_table_0001",
    ] {
        assert!(ws
            .join("scenes")
            .join(scene)
            .join("coarse/lift.json")
            .is_file());
    }

    // The same options again: the same bytes, and the lift outputs stay done; a file lost
    // (a run killed half-way) comes back.
    let before = snapshot(&ws);
    std::fs::remove_file(ws.join("scenes/office_table/office_table_0001/input/image.png"))
        .expect("remove");
    mesa()
        .args(["demo", "--scenes", "2", "--seed", "3", "-q"])
        .arg(&ws)
        .assert()
        .success();
    assert!(
        snapshot(&ws) == before,
        "a rerun with the same options changed the workspace"
    );

    // Other options need --force, which replaces the demo (and what was made from it).
    mesa()
        .args(["demo", "--scenes", "1", "--seed", "4"])
        .arg(&ws)
        .assert()
        .code(2)
        .stderr(predicate::str::contains("--force"));
    mesa()
        .args(["demo", "--scenes", "1", "--seed", "4", "--force", "-q"])
        .arg(&ws)
        .assert()
        .success();
    assert!(!ws.join("scenes/dining_table").exists());
    assert!(!ws
        .join("scenes/office_table/office_table_0001/coarse")
        .exists());
}

#[test]
fn demo_never_touches_a_folder_it_did_not_write() {
    let dir = tempfile::tempdir().expect("tempdir");
    let keep = dir.path().join("notes.txt");
    std::fs::write(&keep, "mine").expect("write");
    for force in [false, true] {
        let mut cmd = mesa();
        cmd.args(["demo", "--scenes", "1"]).arg(dir.path());
        if force {
            cmd.arg("--force");
        }
        cmd.assert().code(2).stderr(predicate::str::contains(
            dir.path().to_string_lossy().as_ref(),
        ));
    }
    assert_eq!(std::fs::read_to_string(&keep).expect("kept"), "mine");
    assert_eq!(std::fs::read_dir(dir.path()).expect("dir").count(), 1);
    mesa()
        .args(["demo", "--scenes", "0"])
        .arg(dir.path().join("new"))
        .assert()
        .code(2)
        .stderr(predicate::str::contains("--scenes 0"));
}
