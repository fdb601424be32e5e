//! The committed JSON Schemas under `schemas/json/` are generated from the Rust types; this
//! test fails when they are stale. Regenerate with `MESA_BLESS=1 cargo test -p mesa-schemas
//! --test json_schemas`.

use std::path::PathBuf;

use mesa_schemas::kinds;

#[test]
fn committed_json_schemas_are_fresh() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("json");
    let bless = std::env::var_os("MESA_BLESS").is_some();
    let mut stale = Vec::new();
    let mut expected_files = Vec::new();
    for kind in kinds() {
        let file = format!("{}.schema.json", kind.name);
        expected_files.push(file.clone());
        let path = dir.join(&file);
        let mut generated = serde_json::to_string_pretty(kind.json_schema()).expect("schema");
        generated.push('\n');
        let committed = std::fs::read_to_string(&path).unwrap_or_default();
        if committed != generated {
            if bless {
                std::fs::create_dir_all(&dir).expect("mkdir");
                std::fs::write(&path, &generated).expect("write schema");
            } else {
                stale.push(file);
            }
        }
    }
    let mut extra: Vec<String> = std::fs::read_dir(&dir)
        .map(|entries| {
            entries
                .filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.ends_with(".schema.json") && !expected_files.contains(n))
                .collect()
        })
        .unwrap_or_default();
    extra.sort();
    if bless {
        for name in &extra {
            std::fs::remove_file(dir.join(name)).expect("remove stale schema");
        }
        return;
    }
    assert!(
        stale.is_empty() && extra.is_empty(),
        "stale JSON Schemas {stale:?}, schemas of removed kinds {extra:?}: regenerate with \
         `MESA_BLESS=1 cargo test -p mesa-schemas --test json_schemas`"
    );
}
