//! The recipe on small catalogs, the fallback, the features encoder against a brute-force
//! reference, and the query inputs.

use mesa_schemas::artifacts::{LiftStats, PlaneFit, ResolvedCamera};
use mesa_schemas::units::{PositionCm, SizeCm, ZoneCm};
use rand::{Rng, SeedableRng};

use super::features::cosine_f64;
use super::npy::{write_matrix, Matrix};
use super::*;

pub(crate) fn lifted(
    instance: &str,
    mask_id: u32,
    description: &str,
    size_cm: [f64; 3],
) -> LiftedInstance {
    LiftedInstance {
        instance: instance.to_owned(),
        mask_id,
        label: instance
            .rsplit_once('_')
            .map_or(instance, |(l, _)| l)
            .to_owned(),
        description: description.to_owned(),
        center_cm: PositionCm([50.0, 50.0, size_cm[2] / 2.0]),
        size_cm: SizeCm(size_cm),
        yaw_deg: None,
        points: format!("coarse/points/{instance}.ply"),
        stats: LiftStats {
            mask_px: 100,
            valid_depth_px: 100,
            valid_depth_fraction: 1.0,
            eroded_px: 90,
            points_removed_outliers: 0,
            points_kept: 90,
        },
    }
}

pub(crate) fn lift_of(instances: Vec<LiftedInstance>) -> LiftArtifact {
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
        table_from_camera: [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ],
        plane: PlaneFit {
            normal_in_camera: [0.0, -1.0, 0.0],
            offset_m: 0.5,
            source: "support".to_owned(),
            inliers: 1000,
            inlier_fraction: 0.9,
            rmse_m: 0.001,
        },
        zone_cm: ZoneCm([0.0, 120.0, 0.0, 80.0]),
        instances,
        dropped: Vec::new(),
    }
}

/// Features whose text scores are set by hand: asset i's row is e_0·cos θ_i + e_(i+1)·sin θ_i,
/// the query is e_0, so the text score of asset i is cos θ_i.
fn handmade(scores: &[f64]) -> (FeatureMatrix, Vec<f32>) {
    let n = scores.len();
    let cols = n + 1;
    let mut data = vec![0.0f32; n * cols];
    for (i, s) in scores.iter().enumerate() {
        data[i * cols] = *s as f32;
        data[i * cols + i + 1] = (1.0 - s * s).max(0.0).sqrt() as f32;
    }
    let uids = (0..n).map(|i| format!("a{i:02}")).collect();
    let matrix = FeatureMatrix::new(
        Matrix {
            rows: n,
            cols,
            data,
        },
        uids,
    )
    .expect("valid");
    let mut query = vec![0.0f32; cols];
    query[0] = 1.0;
    (matrix, query)
}

fn facts(sizes: &[[f64; 3]], rejected: &[usize]) -> Catalog {
    Catalog::from_facts(
        sizes
            .iter()
            .enumerate()
            .map(|(i, s)| AssetFacts {
                size: Some((*s, "annotation")),
                rejection: rejected.contains(&i).then(|| "mark_deletion".to_owned()),
            })
            .collect(),
    )
}

#[test]
fn the_size_score_reorders_the_text_top_k() {
    // Text: a00 0.90, a01 0.89. Size: a01 matches the target's shape, a00 does not.
    let (matrix, query) = handmade(&[0.90, 0.89, 0.5]);
    let catalog = facts(&[[1.0, 0.0, 0.0], [0.1, 0.1, 0.2], [0.1, 0.1, 0.2]], &[]);
    let lift = lift_of(vec![lifted("mug_0", 1, "a mug", [10.0, 10.0, 20.0])]);
    let out = retrieve_scene(
        &lift,
        &[Query::Embedding(query)],
        &TextScorer::Features(matrix),
        &catalog,
        &RetrieveConfig::default(),
    )
    .expect("retrieves");
    let r = &out.artifact.instances[0];
    assert_eq!(r.chosen.as_deref(), Some("a01"));
    assert_eq!(r.candidates[0].uid, "a01");
    assert_eq!(r.candidates[0].text_rank, 1);
    let c = &r.candidates[0];
    assert!((c.final_score - (0.9 * c.text_score + 0.1 * c.size_score)).abs() < 1e-15);
    assert!((c.size_score - 1.0).abs() < 1e-12);
    assert_eq!(c.size_source, "annotation");
    assert!(!r.fallback);
    assert!(out.warnings.is_empty());
    assert_eq!(out.artifact.encoder, "features/4");
    assert_eq!(out.artifact.candidate_assets, 3);
}

#[test]
fn the_filter_takes_the_first_unrejected_of_the_top_five() {
    let scores: Vec<f64> = (0..30).map(|i| 0.99 - 0.01 * i as f64).collect();
    let (matrix, query) = handmade(&scores);
    let catalog = facts(&vec![[1.0, 1.0, 1.0]; 30], &[0, 1, 2]);
    let lift = lift_of(vec![lifted("cup_0", 1, "a cup", [10.0, 10.0, 10.0])]);
    let out = retrieve_scene(
        &lift,
        &[Query::Embedding(query)],
        &TextScorer::Features(matrix),
        &catalog,
        &RetrieveConfig::default(),
    )
    .expect("retrieves");
    let r = &out.artifact.instances[0];
    assert_eq!(r.chosen.as_deref(), Some("a03"));
    assert!(!r.fallback);
    assert_eq!(r.candidates.len(), 20);
    assert_eq!(r.candidates[0].rejected.as_deref(), Some("mark_deletion"));
}

#[test]
fn the_fallback_goes_past_the_top_five_and_then_past_the_top_twenty() {
    let scores: Vec<f64> = (0..30).map(|i| 0.99 - 0.01 * i as f64).collect();
    let lift = lift_of(vec![lifted("cup_0", 1, "a cup", [10.0, 10.0, 10.0])]);
    let run = |rejected: Vec<usize>, fallback: bool| {
        let (matrix, query) = handmade(&scores);
        let catalog = facts(&vec![[1.0, 1.0, 1.0]; 30], &rejected);
        let config = RetrieveConfig {
            fallback,
            ..RetrieveConfig::default()
        };
        retrieve_scene(
            &lift,
            &[Query::Embedding(query)],
            &TextScorer::Features(matrix),
            &catalog,
            &config,
        )
        .expect("retrieves")
    };
    // The top five rejected: the sixth.
    let out = run((0..5).collect(), true);
    let r = &out.artifact.instances[0];
    assert_eq!(r.chosen.as_deref(), Some("a05"));
    assert!(r.fallback);
    assert!(
        out.warnings[0].contains("fell back to a05"),
        "{:?}",
        out.warnings
    );
    // The whole top twenty rejected: the next window, by text rank.
    let out = run((0..22).collect(), true);
    let r = &out.artifact.instances[0];
    assert_eq!(r.chosen.as_deref(), Some("a22"));
    assert_eq!(r.candidates.len(), 23);
    assert_eq!(r.candidates.last().map(|c| c.text_rank), Some(22));
    // Everything rejected: no asset, and a warning.
    let out = run((0..30).collect(), true);
    assert_eq!(out.artifact.instances[0].chosen, None);
    assert!(
        out.warnings[0].contains("no asset passes the filters"),
        "{:?}",
        out.warnings
    );
    // MesaTask's behaviour: no fallback.
    let out = run((0..5).collect(), false);
    assert_eq!(out.artifact.instances[0].chosen, None);
    assert!(!out.artifact.instances[0].fallback);
}

/// The official recipe computed the slow way: every text score in f64, a full sort, the top
/// 20, final scores, a stable sort, the top 5, the filter.
fn reference_choice(
    rows: &Matrix,
    uids: &[String],
    query: &[f32],
    target: [f64; 3],
    sizes: &[[f64; 3]],
    rejected: &[bool],
) -> Option<String> {
    let mut text: Vec<(usize, f64)> = (0..rows.rows)
        .map(|i| {
            (
                i,
                cosine_f64(&rows.data[i * rows.cols..(i + 1) * rows.cols], query),
            )
        })
        .collect();
    text.sort_by(|a, b| b.1.total_cmp(&a.1).then_with(|| uids[a.0].cmp(&uids[b.0])));
    let mut top: Vec<(usize, f64)> = text[..20]
        .iter()
        .map(|(i, t)| (*i, 0.9 * t + 0.1 * size_cosine(target, sizes[*i])))
        .collect();
    // Stable: equal final scores keep their text order.
    top.sort_by(|a, b| b.1.total_cmp(&a.1));
    top[..5]
        .iter()
        .find(|(i, _)| !rejected[*i])
        .map(|(i, _)| uids[*i].clone())
}

#[test]
fn features_reproduce_the_brute_force_recipe_exactly() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let (n, dim) = (2000, 48);
    let rows = Matrix {
        rows: n,
        cols: dim,
        data: (0..n * dim)
            .map(|_| rng.random_range(-1.0f32..1.0))
            .collect(),
    };
    let uids: Vec<String> = (0..n)
        .map(|i| format!("{:08x}", i * 2654435761usize % 4294967291))
        .collect();
    let sizes: Vec<[f64; 3]> = (0..n)
        .map(|_| {
            [
                rng.random_range(0.02..0.5),
                rng.random_range(0.02..0.5),
                rng.random_range(0.02..0.5),
            ]
        })
        .collect();
    let rejected: Vec<bool> = (0..n).map(|_| rng.random_bool(0.3)).collect();
    let catalog = Catalog::from_facts(
        (0..n)
            .map(|i| AssetFacts {
                size: Some((sizes[i], "annotation")),
                rejection: rejected[i].then(|| "onTable false".to_owned()),
            })
            .collect(),
    );
    let matrix = FeatureMatrix::new(rows.clone(), uids.clone()).expect("valid");
    // Exact embeddings of assets (as SBERT gives the same text the same vector) and others.
    let mut queries = Vec::new();
    let mut instances = Vec::new();
    for q in 0..15 {
        let embedding: Vec<f32> = if q % 2 == 0 {
            rows.data[q * 101 * dim..(q * 101 + 1) * dim].to_vec()
        } else {
            (0..dim).map(|_| rng.random_range(-1.0f32..1.0)).collect()
        };
        let size = [
            rng.random_range(2.0..40.0),
            rng.random_range(2.0..40.0),
            rng.random_range(2.0..40.0),
        ];
        instances.push(lifted(&format!("thing_{q}"), q as u32 + 1, "", size));
        queries.push(Query::Embedding(embedding));
    }
    let lift = lift_of(instances);
    let config = RetrieveConfig {
        fallback: false,
        ..RetrieveConfig::default()
    };
    let out = retrieve_scene(
        &lift,
        &queries,
        &TextScorer::Features(matrix),
        &catalog,
        &config,
    )
    .expect("retrieves");
    for ((r, q), lifted) in out
        .artifact
        .instances
        .iter()
        .zip(&queries)
        .zip(&lift.instances)
    {
        let Query::Embedding(v) = q else {
            unreachable!()
        };
        let expected = reference_choice(&rows, &uids, v, lifted.size_cm.0, &sizes, &rejected);
        assert_eq!(r.chosen, expected, "{}", r.instance);
        // The recorded text scores are the exact cosines.
        for c in &r.candidates {
            let i = uids.iter().position(|u| *u == c.uid).expect("uid");
            assert_eq!(
                c.text_score,
                cosine_f64(&rows.data[i * dim..(i + 1) * dim], v)
            );
        }
    }
}

/// The issue's scale: 12,000 assets × 768-d float16 features written as `text_features.npy`,
/// read back, 15 queries retrieved exactly as a brute force ranks them. (The time it takes is
/// measured by `cargo bench -p mesa-stages --bench retrieve`.)
#[test]
fn twelve_thousand_float16_features_from_npy() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let (n, dim) = (12_000, 768);
    let rows = Matrix {
        rows: n,
        cols: dim,
        data: (0..n * dim)
            .map(|_| rng.random_range(-1.0f32..1.0))
            .collect(),
    };
    let dir = tempfile::tempdir().expect("temp dir");
    let npy = dir.path().join("text_features.npy");
    let uids_path = dir.path().join("text_uids.json");
    std::fs::write(&npy, write_matrix(&rows, true)).expect("write npy");
    let uids: Vec<String> = (0..n).map(|i| format!("asset_{i:05}")).collect();
    std::fs::write(
        &uids_path,
        serde_json::to_vec(&serde_json::json!({"uids": uids})).expect("json"),
    )
    .expect("write uids");
    let matrix = FeatureMatrix::read(&npy, &uids_path).expect("reads");
    assert_eq!(matrix.dim(), 768);
    // The float16 values, as read.
    let stored = super::npy::read_matrix(&npy).expect("npy");
    let queries: Vec<Vec<f32>> = (0..15)
        .map(|q| stored.data[q * 800 * dim..(q * 800 + 1) * dim].to_vec())
        .collect();
    let refs: Vec<&[f32]> = queries.iter().map(Vec::as_slice).collect();
    let ranked = matrix.top_k(&refs, 20);
    for (q, top) in ranked.iter().enumerate() {
        // Each query is asset q·800's own embedding: it comes first, with cosine 1.
        assert_eq!(top[0].0, q * 800);
        assert!((top[0].1 - 1.0).abs() < 1e-12);
        let mut all: Vec<(usize, f64)> = (0..n)
            .map(|i| (i, cosine_f64(&stored.data[i * dim..(i + 1) * dim], refs[q])))
            .collect();
        all.sort_by(|a, b| b.1.total_cmp(&a.1).then_with(|| uids[a.0].cmp(&uids[b.0])));
        assert_eq!(top.as_slice(), &all[..20]);
    }
}

#[test]
fn query_embeddings_come_from_instances_or_a_sidecar() {
    let dir = tempfile::tempdir().expect("temp dir");
    let instances = dir.path().join("instances.json");
    let lift = lift_of(vec![
        lifted("mug_0", 1, "a mug", [8.0, 8.0, 10.0]),
        lifted("book_0", 3, "a book", [20.0, 15.0, 3.0]),
    ]);
    std::fs::write(
        &instances,
        r#"{"instances": [
            {"id": 1, "label": "mug", "embedding": [1.0, 0.0]},
            {"id": 2, "label": "table", "support": true},
            {"id": 3, "label": "book", "embedding": [0.0, 1.0]}]}"#,
    )
    .expect("write");
    let q = query_embeddings(&instances, None, &lift).expect("inline");
    assert_eq!(q, vec![vec![1.0, 0.0], vec![0.0, 1.0]]);

    // A sidecar: one row per entry of instances.json, the table's row unused.
    let sidecar = dir.path().join("query_features.npy");
    let rows = Matrix {
        rows: 3,
        cols: 2,
        data: vec![1.0, 1.0, 9.0, 9.0, 2.0, 2.0],
    };
    std::fs::write(&sidecar, write_matrix(&rows, false)).expect("write");
    let e = query_embeddings(&instances, Some(&sidecar), &lift).expect_err("both");
    assert!(e.to_string().contains("keep one of the two"), "{e}");
    std::fs::write(
        &instances,
        r#"{"instances": [{"id": 1, "label": "mug"}, {"id": 2, "label": "table", "support": true},
            {"id": 3, "label": "book"}]}"#,
    )
    .expect("write");
    let q = query_embeddings(&instances, Some(&sidecar), &lift).expect("sidecar");
    assert_eq!(q, vec![vec![1.0, 1.0], vec![2.0, 2.0]]);
    // Without either: the instance and the fix are named.
    let e = query_embeddings(&instances, None, &lift).expect_err("missing");
    assert!(
        e.to_string().starts_with("mug_0: no query embedding"),
        "{e}"
    );
}

#[test]
fn a_query_of_the_wrong_width_is_an_error() {
    let (matrix, _) = handmade(&[0.5, 0.4]);
    let lift = lift_of(vec![lifted("mug_0", 1, "a mug", [8.0, 8.0, 10.0])]);
    let e = retrieve_scene(
        &lift,
        &[Query::Embedding(vec![1.0; 7])],
        &TextScorer::Features(matrix),
        &facts(&[[1.0; 3]; 2], &[]),
        &RetrieveConfig::default(),
    )
    .expect_err("width");
    assert_eq!(
        e.to_string(),
        "mug_0: the query embedding has 7 components, the asset features 3 (expected \
         embeddings of the same model)"
    );
}

#[test]
fn a_bad_recipe_is_refused() {
    let config = RetrieveConfig {
        final_top_k: 30,
        ..RetrieveConfig::default()
    };
    assert!(config
        .check()
        .expect_err("final > text")
        .to_string()
        .contains("final_top_k 30"));
}

#[test]
fn the_catalog_gives_sizes_and_rejections() {
    use mesa_schemas::artifacts::{AssetGeometry, AssetRecord};
    let annotations = Annotations::parse(
        r#"{"a": {"bbox": {"x": 0.1, "y": 0.3, "z": 0.2}},
            "b": {"onTable": false},
            "c": {},
            "d": {}}"#,
    )
    .expect("annotations");
    let record = |valid: bool| AssetRecord {
        file: String::new(),
        glb_bytes: 0,
        glb_sha256: String::new(),
        inputs_sha256: String::new(),
        valid,
        reason: None,
        reason_code: (!valid).then(|| "draco".to_owned()),
        annotated: true,
        geometry: Some(AssetGeometry {
            front_yaw_deg: 0.0,
            bounds_min_m: [0.0; 3],
            bounds_max_m: [1.0; 3],
            size_m: [1.0; 3],
            gltf_extents_m: [0.5, 0.6, 0.7],
            triangles: 1,
            vertices: 3,
            primitives: 1,
            mesh_instances: 1,
            materials: vec![],
            textured_materials: 0,
            textures: 0,
            images: vec![],
            generator: None,
            draco: false,
            skinned: false,
            extensions_required: vec![],
        }),
        shapes: None,
        warnings: vec![],
    };
    let index = AssetIndexArtifact {
        schema: String::new(),
        config_digest: String::new(),
        assets: [
            ("a", true),
            ("b", true),
            ("c", true),
            ("e", true),
            ("d", false),
        ]
        .into_iter()
        .map(|(u, v)| (u.to_owned(), record(v)))
        .collect(),
        annotated_without_glb: vec![],
    };
    let uids: Vec<String> = ["a", "b", "c", "d", "e", "f"].map(str::to_owned).to_vec();
    let catalog = Catalog::new(&uids, &annotations, &index);
    let f = &catalog.facts;
    // Annotation bbox [x, z, y], else the mesh's glTF extents [X, Z, Y].
    assert_eq!(f[0].size, Some(([0.1, 0.2, 0.3], "annotation")));
    assert_eq!(f[2].size, Some(([0.5, 0.7, 0.6], "mesh")));
    assert_eq!(f[0].rejection, None);
    assert_eq!(f[1].rejection.as_deref(), Some("onTable false"));
    assert_eq!(f[3].rejection.as_deref(), Some("invalid GLB: draco"));
    assert_eq!(f[4].rejection.as_deref(), Some("no annotation"));
    assert_eq!(f[5].rejection.as_deref(), Some("no annotation"));
    assert_eq!(catalog.choosable(), 2);
}
