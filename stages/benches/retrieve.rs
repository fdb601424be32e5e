//! Retrieval of one scene's 15 instances over a 12,000-asset library (issue 5's target: under
//! 20 ms a scene with 768-d features). Run: `cargo bench -p mesa-stages --bench retrieve`.
//!
//! - `features_12000x768`: `text_features.npy`-sized float32 embeddings (12,000 × 768, seeded
//!   random values, as read from a float16 or float32 file), 15 query embeddings, the whole
//!   recipe (exact top 20 by text, size scores, final scores, filters). Measured: 15.4 ms a
//!   scene on 2 cores shared with other work (load average 6); the integer screening pass is
//!   about 10 ms of one core (`examples/retrieve_timing.rs` times the parts);
//! - `lexical_12000`: the built-in encoder over 12,000 synthetic asset descriptions (2.7 ms a
//!   scene).

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use mesa_schemas::artifacts::{
    LiftArtifact, LiftStats, LiftedInstance, PlaneFit, ResolvedCamera, TextDocument,
    TextIndexArtifact, TEXT_INDEX_SCHEMA,
};
use mesa_schemas::units::{PositionCm, SizeCm, ZoneCm};
use mesa_stages::retrieve::features::FeatureMatrix;
use mesa_stages::retrieve::lexical::LexicalIndex;
use mesa_stages::retrieve::npy::Matrix;
use mesa_stages::retrieve::{
    retrieve_scene, AssetFacts, Catalog, Query, RetrieveConfig, TextScorer,
};
use mesa_stages::text::{document_frequency, features, LEXICAL_ENCODER};
use rand::{Rng, SeedableRng};

const ASSETS: usize = 12_000;
const DIM: usize = 768;
const QUERIES: usize = 15;

fn lift(rng: &mut impl Rng) -> LiftArtifact {
    let instances = (0..QUERIES)
        .map(|i| LiftedInstance {
            instance: format!("thing_{i}"),
            mask_id: i as u32 + 1,
            label: "thing".to_owned(),
            description: format!("a small white ceramic thing number {i}"),
            center_cm: PositionCm([50.0, 40.0, 5.0]),
            size_cm: SizeCm([
                rng.random_range(3.0..40.0),
                rng.random_range(3.0..40.0),
                rng.random_range(2.0..30.0),
            ]),
            yaw_deg: None,
            points: String::new(),
            stats: LiftStats {
                mask_px: 1,
                valid_depth_px: 1,
                valid_depth_fraction: 1.0,
                eroded_px: 1,
                points_removed_outliers: 0,
                points_kept: 1,
            },
        })
        .collect();
    LiftArtifact {
        schema: "mesa.lift/1".to_owned(),
        scene_id: "office_table_0001".to_owned(),
        camera: ResolvedCamera {
            width: 640,
            height: 480,
            fx: 500.0,
            fy: 500.0,
            cx: 320.0,
            cy: 240.0,
            source: "intrinsics".to_owned(),
        },
        table_from_camera: [[0.0; 4]; 4],
        plane: PlaneFit {
            normal_in_camera: [0.0, -1.0, 0.0],
            offset_m: 0.5,
            source: "support".to_owned(),
            inliers: 1,
            inlier_fraction: 1.0,
            rmse_m: 0.0,
        },
        zone_cm: ZoneCm([0.0, 120.0, 0.0, 80.0]),
        instances,
        dropped: Vec::new(),
    }
}

fn catalog(rng: &mut impl Rng) -> Catalog {
    Catalog::from_facts(
        (0..ASSETS)
            .map(|i| AssetFacts {
                size: Some((
                    [
                        rng.random_range(0.02..0.5),
                        rng.random_range(0.02..0.5),
                        rng.random_range(0.02..0.5),
                    ],
                    "annotation",
                )),
                rejection: (i % 10 == 0).then(|| "mark_deletion".to_owned()),
            })
            .collect(),
    )
}

fn bench_features(c: &mut Criterion) {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(12_000);
    let matrix = Matrix {
        rows: ASSETS,
        cols: DIM,
        data: (0..ASSETS * DIM)
            .map(|_| rng.random_range(-1.0f32..1.0))
            .collect(),
    };
    let uids = (0..ASSETS).map(|i| format!("{i:032x}")).collect();
    let scorer = TextScorer::Features(FeatureMatrix::new(matrix, uids).expect("features"));
    let lift = lift(&mut rng);
    let queries: Vec<Query> = (0..QUERIES)
        .map(|_| Query::Embedding((0..DIM).map(|_| rng.random_range(-1.0f32..1.0)).collect()))
        .collect();
    let catalog = catalog(&mut rng);
    let config = RetrieveConfig::default();
    c.bench_function("features_12000x768_15_queries", |b| {
        b.iter(|| {
            black_box(
                retrieve_scene(&lift, &queries, &scorer, &catalog, &config).expect("retrieves"),
            )
        })
    });
}

fn bench_lexical(c: &mut Criterion) {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    const WORDS: [&str; 24] = [
        "white", "ceramic", "mug", "wooden", "bowl", "red", "book", "glass", "bottle", "metal",
        "lamp", "small", "large", "round", "square", "plastic", "box", "blue", "vase", "plate",
        "handle", "striped", "tall", "pen",
    ];
    let documents = (0..ASSETS)
        .map(|i| {
            let text: Vec<&str> = (0..12)
                .map(|_| WORDS[rng.random_range(0..WORDS.len())])
                .collect();
            let text = text.join(" ");
            let features = features(&text);
            (format!("{i:032x}"), TextDocument { text, features })
        })
        .collect::<std::collections::BTreeMap<_, _>>();
    let document_frequency = document_frequency(documents.values().map(|d| &d.features));
    let index = TextIndexArtifact {
        schema: TEXT_INDEX_SCHEMA.to_owned(),
        encoder: LEXICAL_ENCODER.to_owned(),
        documents,
        document_frequency,
    };
    let scorer = TextScorer::Lexical(LexicalIndex::new(&index));
    let lift = lift(&mut rng);
    let queries: Vec<Query> = lift
        .instances
        .iter()
        .map(|i| Query::Text(i.description.clone()))
        .collect();
    let catalog = catalog(&mut rng);
    let config = RetrieveConfig::default();
    c.bench_function("lexical_12000_15_queries", |b| {
        b.iter(|| {
            black_box(
                retrieve_scene(&lift, &queries, &scorer, &catalog, &config).expect("retrieves"),
            )
        })
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30);
    targets = bench_features, bench_lexical
}
criterion_main!(benches);
