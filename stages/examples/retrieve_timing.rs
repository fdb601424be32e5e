//! Times the screening pass of the features encoder alone and the whole top-20 ranking, for
//! 12,000 × 768 features and 15 queries, single-threaded and on every core:
//! `cargo run --release -p mesa-stages --example retrieve_timing`.

use std::time::Instant;

use mesa_stages::retrieve::features::FeatureMatrix;
use mesa_stages::retrieve::npy::Matrix;
use rand::{Rng, SeedableRng};

fn main() {
    let (n, dim) = (12_000, 768);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let matrix = Matrix {
        rows: n,
        cols: dim,
        data: (0..n * dim)
            .map(|_| rng.random_range(-1.0f32..1.0))
            .collect(),
    };
    let uids = (0..n).map(|i| format!("{i:032x}")).collect();
    let features = FeatureMatrix::new(matrix, uids).expect("features");
    let queries: Vec<Vec<f32>> = (0..15)
        .map(|_| (0..dim).map(|_| rng.random_range(-1.0f32..1.0)).collect())
        .collect();
    let refs: Vec<&[f32]> = queries.iter().map(Vec::as_slice).collect();
    for threads in [1, 0] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        pool.install(|| {
            let rounds = 20;
            let started = Instant::now();
            for _ in 0..rounds {
                std::hint::black_box(features.top_k(&refs, 20));
            }
            let cpu = started.elapsed().as_secs_f64() * 1e3 / f64::from(rounds);
            println!(
                "{} threads: top 20 of 12,000 × 768 for 15 queries: {cpu:.2} ms",
                pool.current_num_threads()
            );
        });
    }
}
