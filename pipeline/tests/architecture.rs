//! The shape of the code (docs/ARCHITECTURE.md): no two modules of a crate import each other
//! (`scripts/import_cycles.py`, whose own tests, with crates that do have cycles, are the
//! control), and the command registry stays dispatch only.

use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("workspace root")
        .to_owned()
}

fn python(args: &[&str]) -> std::process::Output {
    Command::new("python3")
        .args(args)
        .current_dir(root())
        .output()
        .expect("python3 runs")
}

#[test]
fn the_cycle_finder_finds_cycles_in_crates_that_have_them() {
    let out = python(&["scripts/test_import_cycles.py"]);
    assert!(
        out.status.success(),
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn no_two_modules_of_a_crate_import_each_other() {
    for krate in ["schemas/src", "stages/src", "pipeline/src"] {
        let out = python(&["scripts/import_cycles.py", "--crate-root", krate]);
        assert!(
            out.status.success(),
            "{krate}: {}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

#[test]
fn the_command_registry_is_dispatch_only() {
    let text = std::fs::read_to_string(root().join("pipeline/src/commands/mod.rs")).expect("read");
    let lines = text.lines().count();
    assert!(lines < 250, "commands/mod.rs has {lines} lines");
    assert!(
        !root().join("pipeline/src/app.rs").exists(),
        "app.rs is gone: each command lives in its file"
    );
}
