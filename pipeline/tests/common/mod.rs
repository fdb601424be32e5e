//! Helpers shared by the CLI tests: the `mesa` binary, the published records in
//! ../shared/realdata, and byte snapshots of a dataset's outputs.
#![allow(dead_code)] // Each test file uses its own subset.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use assert_cmd::Command;

/// The `mesa` binary under test.
pub fn mesa() -> Command {
    Command::cargo_bin("mesa").expect("the mesa binary")
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
