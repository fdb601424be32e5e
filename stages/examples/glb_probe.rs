//! Prints what `mesa`'s GLB reader makes of each file given: bounds, counts, or the reason it
//! rejects it.
fn main() {
    for path in std::env::args().skip(1) {
        let bytes = match std::fs::read(&path) {
            Ok(b) => b,
            Err(e) => {
                println!("{path}: cannot read: {e}");
                continue;
            }
        };
        match mesa_stages::glb_read::read_glb(&bytes) {
            Ok(mesh) => {
                let mut lo = [f64::INFINITY; 3];
                let mut hi = [f64::NEG_INFINITY; 3];
                for p in &mesh.positions_m {
                    for k in 0..3 {
                        lo[k] = lo[k].min(p[k]);
                        hi[k] = hi[k].max(p[k]);
                    }
                }
                println!(
                    "{path}: ok: {} vertices, {} triangles, {} primitives, min {lo:.4?} max {hi:.4?}, draco {}, skinned {}, warnings {:?}",
                    mesh.positions_m.len(),
                    mesh.triangles.len(),
                    mesh.info.primitives,
                    mesh.info.draco,
                    mesh.info.skinned,
                    mesh.warnings
                );
            }
            Err(e) => println!("{path}: REJECTED [{}] {e}", e.code()),
        }
    }
}
