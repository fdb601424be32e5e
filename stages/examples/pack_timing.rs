//! Times `pack_scene` on the pack bench's scene (`benches/common/pack_scene.rs`: 15 objects of
//! the demo's office_table_0003, seed 7, snapshots and README included), the mesa side of
//! `bench/compare_blender_pack.py`: one warm-up run, then `--repeat` runs timed one by one on
//! one thread, as the script times Blender. Prints one JSON line: the seconds of each run.
//!
//! It allocates through mimalloc, as the `mesa` executable does (pipeline/src/main.rs). With
//! glibc's allocator, `_int_malloc`, `malloc_consolidate` and fresh pages were 6 % of the
//! profile, a cost `mesa pack` does not pay.
//!
//! With `--serve`, the timed runs are asked for on standard input instead (`support/serve.rs`),
//! so that `bench/compare_blender_pack.py` can alternate them with Blender's; at the end of the
//! input, the usual line is printed, its runs those served.
//!
//! `cargo run --release -p mesa-stages --example pack_timing -- [--repeat 5 | --serve]`

#[path = "support/serve.rs"]
mod serve;

use std::convert::Infallible;
use std::error::Error;
use std::hint::black_box;
use std::time::Instant;

use mesa_stages::pack::{pack_scene, PackConfig};

/// The allocator of the `mesa` executable (pipeline/src/main.rs), so that the figure is the
/// one the `pack` stage gets.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

#[path = "../benches/common/pack_scene.rs"]
// Parts of it serve one of its two users only.
#[allow(dead_code)]
mod pack_scene;

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    // How many runs to time, or none when they are served.
    let repeat: Option<usize> = match args.as_slice() {
        [] => Some(5),
        [flag, n] if flag == "--repeat" => Some(n.parse()?),
        [flag] if flag == "--serve" => None,
        _ => return Err("usage: pack_timing [--repeat N | --serve]".into()),
    };
    let inputs = pack_scene::PackScene::new();
    let assets = inputs.assets();
    let request = inputs.request(&assets);
    let config = PackConfig::default();
    let objects = pack_scene(&request, &config)?.index.objects.len();
    let timed_run = || {
        let start = Instant::now();
        black_box(pack_scene(&request, &config).expect("packs"));
        start.elapsed().as_secs_f64()
    };
    let runs: Vec<f64> = match repeat {
        Some(repeat) => (0..repeat).map(|_| timed_run()).collect(),
        None => serve::served("runs_s", || Ok::<_, Infallible>(timed_run()))?,
    };
    println!(
        "{}",
        serde_json::json!({ "objects": objects, "runs_s": runs })
    );
    Ok(())
}
