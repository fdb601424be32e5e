//! The graph stage's work in a bare loop, without the runner: the floor under `mesa graph`'s
//! time, for `bench/compare_graph.py`.
//!
//! For every scene of a dataset (sorted, as the Python side of the comparison walks them) it
//! does what the stage does for a scene and nothing else: read the layout the stage reads (the
//! first of `qa/layout.json`, `refined/layout.json` that is a file) with `std::fs`, extract the
//! graph with the dataset's `[graph]` configuration and annotations, and make `graph.json` and
//! `graph.txt`. Then one of:
//!
//! - `--compare`: read the scene's `graph/graph.json` and `graph/graph.txt` and compare them
//!   byte for byte with the new ones, as a forced `mesa graph` does before it leaves a file
//!   alone; exits 1 if any differs (so the loop is known to do the stage's work);
//! - `--out DIR`: write them under `DIR/scenes/<table>/<scene>/graph/` with `std::fs::write`,
//!   as the Python side writes its files (a file already there is truncated and rewritten).
//!
//! What it leaves out is what the runner adds for each scene: the lock, the previous done
//! marker read and the new one compared or written, the SHA-256 of the layout and of both
//! outputs, the sweep of the output folder for dead writers' temporary files, the atomic
//! replacement of a file that changed. Prints one JSON line: scenes, seconds, differing.
//!
//! `cargo run --release -p mesa-pipeline --example graph_bare -- DATASET (--compare | --out DIR)`

use std::error::Error;
use std::fs;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use mesa_pipeline::config::Config;
use mesa_stages::annotations::Annotations;
use mesa_stages::graph::{annotated_containers, extract_graph, read_layout_text, GraphOptions};
use mesa_stages::paths::dataset::ANNOTATIONS;
use mesa_stages::paths::scene::{GRAPH_JSON, GRAPH_TXT, LAYOUT_CANDIDATES};

/// The allocator of the `mesa` executable (pipeline/src/main.rs).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// What to do with a scene's new outputs.
enum Mode {
    Compare,
    Write(PathBuf),
}

/// The folders under `dir` whose names do not start with a dot, sorted.
fn subfolders(dir: &Path) -> Result<Vec<PathBuf>, Box<dyn Error>> {
    let mut found = Vec::new();
    for entry in fs::read_dir(dir)? {
        let entry = entry?;
        if entry.file_type()?.is_dir() && !entry.file_name().to_string_lossy().starts_with('.') {
            found.push(entry.path());
        }
    }
    found.sort();
    Ok(found)
}

fn name(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
}

fn main() -> Result<ExitCode, Box<dyn Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (dataset, mode) = match args.as_slice() {
        [dataset, flag] if flag == "--compare" => (PathBuf::from(dataset), Mode::Compare),
        [dataset, flag, out] if flag == "--out" => {
            (PathBuf::from(dataset), Mode::Write(PathBuf::from(out)))
        }
        _ => return Err("usage: graph_bare DATASET (--compare | --out DIR)".into()),
    };
    let start = Instant::now();
    let config = Config::load(&dataset, None)?;
    let options = GraphOptions::from(&config.graph);
    let annotations_path = dataset.join(ANNOTATIONS);
    let annotations = if annotations_path.exists() {
        Some(Annotations::read(&annotations_path)?)
    } else {
        None
    };
    let (mut scenes, mut differing) = (0usize, Vec::new());
    for table in subfolders(&dataset.join("scenes"))? {
        for scene in subfolders(&table)? {
            let Some(rel) = LAYOUT_CANDIDATES
                .into_iter()
                .find(|rel| scene.join(rel).is_file())
            else {
                continue;
            };
            let scene_id = name(&scene);
            let text = fs::read_to_string(scene.join(rel))?;
            let loaded = read_layout_text(&text).map_err(|e| format!("{scene_id}: {e}"))?;
            let containers = annotated_containers(
                &loaded.scene,
                &loaded.retrieved_uids,
                annotations.as_ref(),
                &options,
            );
            let graph = extract_graph(&loaded.scene, &containers.flags, &options)?;
            let outputs = [
                (GRAPH_JSON, graph.to_json(&scene_id, rel)),
                (GRAPH_TXT, graph.to_text().into_bytes()),
            ];
            match &mode {
                Mode::Compare => {
                    for (rel, bytes) in &outputs {
                        if fs::read(scene.join(rel)).ok().as_ref() != Some(bytes) {
                            differing.push(format!("{}/{scene_id}/{rel}", name(&table)));
                        }
                    }
                }
                Mode::Write(out) => {
                    let folder = out.join("scenes").join(name(&table)).join(&scene_id);
                    for (rel, bytes) in &outputs {
                        let path = folder.join(rel);
                        if let Some(parent) = path.parent() {
                            fs::create_dir_all(parent)?;
                        }
                        fs::write(path, bytes)?;
                    }
                }
            }
            scenes += 1;
        }
    }
    println!(
        "{}",
        serde_json::json!({
            "scenes": scenes,
            "seconds": start.elapsed().as_secs_f64(),
            "differing": differing.len(),
        })
    );
    if differing.is_empty() {
        Ok(ExitCode::SUCCESS)
    } else {
        eprintln!("differ from the new outputs: {}", differing.join(", "));
        Ok(ExitCode::FAILURE)
    }
}
