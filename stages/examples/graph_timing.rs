//! Times scene-graph extraction in process over every scene of a dataset, the mesa side of
//! `bench/compare_graph.py`: each scene's layout (the first present of `qa/layout.json`,
//! `refined/layout.json`) is read and its container flags decided first, as the `graph` stage
//! does (asset annotations, else the keyword rule); then `extract_graph` and `to_text` over all
//! scenes are timed, one warm-up pass and `--repeat` timed passes, on one thread. Prints JSON:
//! the seconds per scene of each pass, their min and median, and the min and median of as many
//! passes of `extract_graph` alone (no text), of reading the layouts' text
//! (`read_layout_text`), and of writing `graph.json` (`to_json`): the other parts of the
//! `graph` stage's work, for where its time goes.
//!
//! With `--serve`, the timed passes are asked for on standard input instead, so that a
//! comparison script can alternate them with its own (`bench/compare_graph.py`): after the
//! warm-up, each line read, `N [WARM_SECONDS]`, asks for untimed passes for WARM_SECONDS (at
//! least one: the caches and the core's speed back to their steady state after the other
//! side's turn), then N timed passes, printed as one JSON line, `{"runs_s_per_scene":
//! [...]}`. At the end of the input, the report above is printed as the last line, its runs
//! those served.
//!
//! It allocates through mimalloc, as the `mesa` executable does (pipeline/src/main.rs).
//!
//! `cargo run --release -p mesa-stages --example graph_timing -- DATASET [--repeat 5] [--serve]`

#[path = "support/serve.rs"]
mod serve;

use std::error::Error;
use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::time::Instant;

use mesa_stages::annotations::Annotations;
use mesa_stages::graph::{
    annotated_containers, extract_graph, read_layout_text, GraphError, GraphOptions, GraphScene,
};
use mesa_stages::paths::dataset::{ANNOTATIONS, SCENES};
use mesa_stages::paths::scene::LAYOUT_CANDIDATES;

/// The allocator of the `mesa` executable (pipeline/src/main.rs), so that the figure is the
/// one the `graph` stage gets.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

const USAGE: &str = "usage: graph_timing DATASET [--repeat N] [--serve]";

/// The sub-folders of `path`, hidden ones left out, sorted (as mesa lists scenes).
fn sorted_dirs(path: &Path) -> Result<Vec<PathBuf>, Box<dyn Error>> {
    let mut dirs = Vec::new();
    for entry in std::fs::read_dir(path).map_err(|e| format!("{}: {e}", path.display()))? {
        let path = entry?.path();
        let hidden = path
            .file_name()
            .is_some_and(|name| name.to_string_lossy().starts_with('.'));
        if path.is_dir() && !hidden {
            dirs.push(path);
        }
    }
    dirs.sort();
    Ok(dirs)
}

/// A scene's graph input: the scene and its container flags.
type SceneInput = (GraphScene, Vec<bool>);

/// Every scene's graph input, and the text of its layout.
fn read_scenes(dataset: &Path) -> Result<(Vec<SceneInput>, Vec<String>), Box<dyn Error>> {
    let annotations_path = dataset.join(ANNOTATIONS);
    let annotations = if annotations_path.exists() {
        Some(Annotations::read(&annotations_path)?)
    } else {
        None
    };
    let options = GraphOptions::default();
    let mut scenes = Vec::new();
    let mut texts = Vec::new();
    for table in sorted_dirs(&dataset.join(SCENES))? {
        for scene in sorted_dirs(&table)? {
            let Some(path) = LAYOUT_CANDIDATES
                .iter()
                .map(|rel| scene.join(rel))
                .find(|p| p.is_file())
            else {
                continue;
            };
            let text =
                std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
            let loaded = read_layout_text(&text).map_err(|e| format!("{}: {e}", path.display()))?;
            let containers = annotated_containers(
                &loaded.scene,
                &loaded.retrieved_uids,
                annotations.as_ref(),
                &options,
            );
            scenes.push((loaded.scene, containers.flags));
            texts.push(text);
        }
    }
    if scenes.is_empty() {
        return Err(format!("{}: no scene with a layout", dataset.display()).into());
    }
    Ok((scenes, texts))
}

/// The min and median seconds per item of `repeat` timed passes of `f` over `n` items.
fn timed(repeat: usize, n: usize, mut f: impl FnMut()) -> (f64, f64) {
    let runs: Vec<f64> = (0..repeat)
        .map(|_| {
            let started = Instant::now();
            f();
            started.elapsed().as_secs_f64() / n as f64
        })
        .collect();
    min_median(&runs)
}

/// One pass over every scene, the graph's text made too when `text`: the seconds per scene.
fn pass(
    scenes: &[(GraphScene, Vec<bool>)],
    options: &GraphOptions,
    text: bool,
) -> Result<f64, GraphError> {
    let started = Instant::now();
    for (scene, flags) in scenes {
        let graph = extract_graph(black_box(scene), flags, options)?;
        if text {
            black_box(graph.to_text());
        } else {
            black_box(&graph);
        }
    }
    Ok(started.elapsed().as_secs_f64() / scenes.len() as f64)
}

/// The min and median of some timings.
fn min_median(runs: &[f64]) -> (f64, f64) {
    let mut sorted = runs.to_vec();
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len();
    let median = if n % 2 == 1 {
        sorted[n / 2]
    } else {
        (sorted[n / 2 - 1] + sorted[n / 2]) / 2.0
    };
    (sorted[0], median)
}

fn main() -> Result<(), Box<dyn Error>> {
    let mut args = std::env::args().skip(1);
    let mut dataset: Option<PathBuf> = None;
    let mut repeat = 5usize;
    let mut serving = false;
    while let Some(arg) = args.next() {
        if arg == "--repeat" {
            repeat = args.next().and_then(|v| v.parse().ok()).ok_or(USAGE)?;
        } else if arg == "--serve" {
            serving = true;
        } else {
            dataset = Some(PathBuf::from(arg));
        }
    }
    let dataset = dataset.ok_or(USAGE)?;
    let repeat = repeat.max(1);

    let (scenes, texts) = read_scenes(&dataset)?;
    let options = GraphOptions::default();
    pass(&scenes, &options, true)?; // warm-up
    let runs = if serving {
        serve::served("runs_s_per_scene", || pass(&scenes, &options, true))?
    } else {
        (0..repeat)
            .map(|_| pass(&scenes, &options, true))
            .collect::<Result<Vec<f64>, _>>()?
    };
    let (min, median) = min_median(&runs);
    // The same passes without the text, for where the time goes.
    let bare = (0..repeat)
        .map(|_| pass(&scenes, &options, false))
        .collect::<Result<Vec<f64>, _>>()?;
    let (bare_min, bare_median) = min_median(&bare);
    // The other parts of the stage's work: reading the layouts, writing graph.json.
    let (parse_min, parse_median) = timed(repeat, texts.len(), || {
        for text in &texts {
            black_box(read_layout_text(black_box(text)).expect("read once already"));
        }
    });
    let graphs = scenes
        .iter()
        .map(|(scene, flags)| extract_graph(scene, flags, &options))
        .collect::<Result<Vec<_>, _>>()?;
    let (json_min, json_median) = timed(repeat, graphs.len(), || {
        for graph in &graphs {
            black_box(graph.to_json("table/scene_0001", "refined/layout.json"));
        }
    });
    let report = serde_json::json!({
        "scenes": scenes.len(),
        "repeat": repeat,
        "min_s_per_scene": min,
        "median_s_per_scene": median,
        "runs_s_per_scene": runs,
        "extract_only_min_s_per_scene": bare_min,
        "extract_only_median_s_per_scene": bare_median,
        "read_layout_min_s_per_scene": parse_min,
        "read_layout_median_s_per_scene": parse_median,
        "to_json_min_s_per_scene": json_min,
        "to_json_median_s_per_scene": json_median,
    });
    println!("{report}");
    Ok(())
}
