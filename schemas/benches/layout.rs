//! Reading a dataset layout (`read_layout_text`): the quick reader of plain layouts against the
//! general one (a `Value`, the JSON Schema walk, the conversion), on a 15-object layout as mesa
//! writes it (pretty-printed, full-precision numbers, provenance). Run:
//! `cargo bench -p mesa-schemas --bench layout`.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use mesa_schemas::layout_file::{read_layout_text, read_layout_text_general};
use serde_json::json;

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

/// A 15-object layout text in the shape `mesa place` and `mesa ingest` write.
fn layout_text() -> String {
    let mut rng = Rng(0x5eed);
    let objects: Vec<_> = (0..15)
        .map(|i| {
            let yaw: f64 = rng.range(-180.0, 180.0);
            let half = yaw.to_radians() / 2.0;
            json!({
                "category": "mug",
                "description": "a white ceramic mug with a handle",
                "instance": format!("mug_{i}"),
                "position": [rng.range(0.0, 120.0), rng.range(0.0, 70.0), rng.range(0.0, 10.0)],
                "provenance": {"notes": ["edited by the annotator: moved 0.34 cm"], "source_instance": i, "stage": "ingest"},
                "retrieved_uid": "50ce242b825ba943e125da188b0ea32a",
                "rotation": [0.0, 0.0, half.sin(), half.cos()],
                "scale_factor": [rng.range(0.5, 2.0), rng.range(0.5, 2.0), rng.range(0.5, 2.0)],
                "size": [rng.range(2.0, 30.0), rng.range(2.0, 30.0), rng.range(2.0, 30.0)],
                "z_rotation": yaw,
            })
        })
        .collect();
    let layout = json!({
        "item_placement_zone": [0.0, 143.8086968960789, 0.0, 57.5349001727524],
        "objects": objects,
        "schema": "mesa.layout/1",
    });
    serde_json::to_string_pretty(&layout).expect("json")
}

fn bench(c: &mut Criterion) {
    let text = layout_text();
    // Both readers give the same layout (the quick one's tests say so on generated layouts).
    assert_eq!(
        read_layout_text(&text).expect("valid"),
        read_layout_text_general(&text).expect("valid")
    );
    let mut group = c.benchmark_group("layout_read");
    group.throughput(Throughput::Bytes(text.len() as u64));
    group.bench_function("quick_15_objects", |b| {
        b.iter(|| read_layout_text(black_box(&text)))
    });
    group.bench_function("general_15_objects", |b| {
        b.iter(|| read_layout_text_general(black_box(&text)))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
