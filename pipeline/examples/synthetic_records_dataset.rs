//! Writes a synthetic dataset ready for `mesa records`: N scenes of synthetic layouts, their
//! scene graphs and template tasks (`bench/records_10k.sh` times `mesa records` on it).
//!
//! ```text
//! cargo run --release -p mesa-pipeline --example synthetic_records_dataset -- DIR N [SEED]
//! ```

#[path = "../benches/synthetic/mod.rs"]
mod synthetic;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(dir), Some(scenes)) = (args.first(), args.get(1)) else {
        anyhow::bail!("usage: synthetic_records_dataset DIR N [SEED]");
    };
    let scenes: usize = scenes.parse()?;
    let seed: u64 = args.get(2).map_or(Ok(1), |s| s.parse())?;
    let started = std::time::Instant::now();
    synthetic::write_dataset(std::path::Path::new(dir), scenes, seed)?;
    eprintln!(
        "{scenes} scenes (layouts, graphs, template tasks) written to {dir} in {:.1} s",
        started.elapsed().as_secs_f64()
    );
    Ok(())
}
