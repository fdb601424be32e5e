//! Helpers shared by the integration tests of mesa-schemas.

use std::path::PathBuf;

/// `../shared/realdata` beside the repository (override with `MESA_SHARED`).
pub fn realdata() -> PathBuf {
    let shared = std::env::var_os("MESA_SHARED")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared"));
    let dir = shared.join("realdata");
    assert!(
        dir.is_dir(),
        "{} is missing: the tests read real data from ../shared/realdata beside the repository \
         (or set MESA_SHARED)",
        dir.display()
    );
    dir
}

/// The published MesaTask gallery records.
pub fn gallery_records() -> Vec<(String, String)> {
    let dir = realdata().join("layouts/mesatask_gallery");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .expect("gallery folder")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .collect();
    files.sort();
    assert_eq!(files.len(), 7, "the 7 published gallery records");
    files
        .into_iter()
        .map(|p| {
            let name = p.file_name().expect("name").to_string_lossy().into_owned();
            (name, std::fs::read_to_string(&p).expect("read record"))
        })
        .collect()
}
