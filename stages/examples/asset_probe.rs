//! Indexes the GLB files given as `mesa assets` would (default `[assets]` configuration) and
//! prints, per file, the verdict, the size in the table frame, the counts, the collision
//! shapes and the time taken:
//! `cargo run --release -p mesa-stages --example asset_probe -- FILE.glb...`.

use std::time::Instant;

use mesa_stages::assets::{index_asset, AssetsConfig};

fn main() {
    let config = AssetsConfig::default();
    for path in std::env::args().skip(1) {
        let bytes = match std::fs::read(&path) {
            Ok(b) => b,
            Err(e) => {
                println!("{path}: cannot read: {e}");
                continue;
            }
        };
        let started = Instant::now();
        let indexed = index_asset(&path, "", &bytes, None, &config);
        let elapsed_ms = started.elapsed().as_secs_f64() * 1e3;
        match (&indexed.invalid, &indexed.geometry) {
            (Some((code, reason)), _) => println!("{path}: INVALID [{code}] {reason}"),
            (None, Some(g)) => {
                let shapes = indexed.shapes.as_ref();
                let shape_bytes = shapes
                    .and_then(|s| serde_json::to_vec(s).ok())
                    .map_or(0, |b| b.len());
                println!(
                    "{path}: valid: size {:.4?} m, {} triangles, {} vertices, {} materials, {} \
                     parts ({}), shapes {} kB, {elapsed_ms:.0} ms",
                    g.size_m,
                    g.triangles,
                    g.vertices,
                    g.materials.len(),
                    shapes.map_or(0, |s| s.parts.len()),
                    shapes.map_or("-", |s| s.decomposition.method.as_str()),
                    shape_bytes / 1024
                );
            }
            (None, None) => println!("{path}: no geometry"),
        }
        for warning in &indexed.warnings {
            println!("  warning: {warning}");
        }
    }
}
