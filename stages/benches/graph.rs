//! Scene-graph extraction over 10,000 synthetic 15-object layouts (issue 8's target: under
//! 5 s on 2 cores, under 0.5 ms a scene), and over single large layouts of 1,000 and 10,000
//! objects (issue 20: `graph --layout` must not be quadratic). Run:
//! `cargo bench -p mesa-stages --bench graph`.
//!
//! The layouts are generated from a fixed seed, table-top like: a 120 × 70 zone (scaled with
//! the object count for the large layouts, so the density stays that of a table), objects of
//! 3–40 cm standing on the table, about a fifth of them on or in another one, a third rotated.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, BatchSize, Criterion, Throughput};
use mesa_stages::graph::{
    extract_graph, keyword_containers, GraphOptions, GraphScene, SceneObject,
};

const SCENES: usize = 10_000;
const OBJECTS: usize = 15;
const CATEGORIES: [&str; 10] = [
    "bowl", "cup", "plate", "apple", "tray", "book", "box", "pen", "lamp", "vase",
];

/// A small deterministic generator (xorshift64*), so the bench needs no extra crate.
struct Rng(u64);

impl Rng {
    fn next_f64(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let bits = self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11;
        bits as f64 / (1u64 << 53) as f64
    }

    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next_f64()
    }
}

fn scenes() -> Vec<GraphScene> {
    let mut rng = Rng(0x6d65_7361_2d67_7261);
    (0..SCENES).map(|_| scene(&mut rng, OBJECTS)).collect()
}

/// One table-like layout of `count` objects, its zone scaled to keep 15 objects per 120 × 70.
fn scene(rng: &mut Rng, count: usize) -> GraphScene {
    let scale = (count as f64 / OBJECTS as f64).sqrt().max(1.0);
    let (width, depth) = (120.0 * scale, 70.0 * scale);
    let mut objects: Vec<SceneObject> = Vec::with_capacity(count);
    for i in 0..count {
        let category = CATEGORIES[(rng.next_f64() * CATEGORIES.len() as f64) as usize % 10];
        let size = [
            rng.range(3.0, 40.0),
            rng.range(3.0, 40.0),
            rng.range(1.0, 30.0),
        ];
        let yaw = if rng.next_f64() < 0.33 {
            rng.range(-180.0, 180.0)
        } else {
            0.0
        };
        let mut position = [rng.range(0.0, width), rng.range(0.0, depth), size[2] / 2.0];
        if i > 0 && rng.next_f64() < 0.2 {
            let base = &objects[(rng.next_f64() * i as f64) as usize % i];
            position = [
                base.position_cm[0] + rng.range(-3.0, 3.0),
                base.position_cm[1] + rng.range(-3.0, 3.0),
                base.position_cm[2] - base.size_cm[2] / 2.0
                    + rng.range(0.0, base.size_cm[2])
                    + size[2] / 2.0,
            ];
        }
        objects.push(SceneObject::new(
            format!("{category}_{i}"),
            position,
            size,
            yaw,
        ));
    }
    objects.sort_by(|a, b| {
        let (fa, fb) = (a.size_cm[0] * a.size_cm[1], b.size_cm[0] * b.size_cm[1]);
        fb.total_cmp(&fa).then_with(|| a.instance.cmp(&b.instance))
    });
    GraphScene {
        zone_cm: [0.0, width, 0.0, depth],
        objects,
    }
}

fn bench_graph(c: &mut Criterion) {
    let scenes = scenes();
    let options = GraphOptions::default();
    let containers: Vec<Vec<bool>> = scenes
        .iter()
        .map(|s| keyword_containers(s, &options))
        .collect();
    let mut group = c.benchmark_group("graph");
    group.sample_size(10);
    group.measurement_time(std::time::Duration::from_secs(10));
    group.throughput(Throughput::Elements(SCENES as u64));
    group.bench_function("10000 scenes x 15 objects, one thread", |b| {
        b.iter_batched(
            || (),
            |()| {
                let mut lines = 0usize;
                for (scene, flags) in scenes.iter().zip(&containers) {
                    let graph = extract_graph(black_box(scene), flags, &options)
                        .unwrap_or_else(|e| panic!("synthetic scenes are valid: {e}"));
                    lines += graph.triplet_lines().len();
                }
                black_box(lines)
            },
            BatchSize::PerIteration,
        );
    });
    group.finish();
}

fn bench_large_layouts(c: &mut Criterion) {
    let options = GraphOptions::default();
    let mut group = c.benchmark_group("graph large layout");
    group.sample_size(10);
    for count in [1_000usize, 10_000] {
        let scene = scene(&mut Rng(0x6c61_7267_652d_6c61 ^ count as u64), count);
        let flags = keyword_containers(&scene, &options);
        group.throughput(Throughput::Elements(count as u64));
        group.bench_function(format!("{count} objects"), |b| {
            b.iter(|| {
                let graph = extract_graph(black_box(&scene), &flags, &options)
                    .unwrap_or_else(|e| panic!("synthetic scenes are valid: {e}"));
                black_box(graph.triplet_lines().len())
            });
        });
    }
    group.finish();
}

criterion_group!(benches, bench_graph, bench_large_layouts);
criterion_main!(benches);
