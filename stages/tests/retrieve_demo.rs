//! Retrieval and placement on the `mesa demo` dataset, against its ground truth: every scene is
//! lifted, the library indexed, each lifted instance retrieved and placed as the pipeline does
//! (the library functions behind `mesa lift`, `mesa assets`, `mesa retrieve`, `mesa place`).
//!
//! - the lexical encoder picks an asset of the true category for at least 90 % of the lifted
//!   instances (84 of 85 on the default scenes; 333 of 334 on 24 scenes, 94 % of them without
//!   the label in the query);
//! - the features encoder, fed exact embeddings (each instance's query is its true asset's
//!   embedding, as SBERT gives the same text the same vector), reproduces a brute-force f64
//!   ranking exactly, and picks the true asset;
//! - every coarse layout passes `mesa validate`, and every object rests on the table or on an
//!   object under it.
//!
//! `MESA_RETRIEVE_TEST_SCENES` (default 6, one per table type) and `MESA_RETRIEVE_TEST_SEED`
//! (default 7) make deeper runs (for example 60 scenes with `cargo test --release`).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use mesa_schemas::artifacts::{
    AssetIndexArtifact, AssetRecord, LiftArtifact, TruthInstances, ASSET_INDEX_SCHEMA,
};
use mesa_schemas::layout::DatasetLayout;
use mesa_stages::annotations::Annotations;
use mesa_stages::assets::{build_text_index, index_asset, AssetsConfig};
use mesa_stages::demo::{write_demo, DemoOptions};
use mesa_stages::lift::{lift_scene, LiftConfig};
use mesa_stages::place::{footprints_overlap, place_scene, PlaceConfig};
use mesa_stages::retrieve::features::{cosine_f64, FeatureMatrix};
use mesa_stages::retrieve::lexical::LexicalIndex;
use mesa_stages::retrieve::npy::Matrix;
use mesa_stages::retrieve::{
    query_text, retrieve_scene, size_cosine, Catalog, Query, RetrieveConfig, TextScorer,
};
use rand::{Rng, SeedableRng};

fn env_or(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .ok()
        .map(|v| {
            v.parse()
                .unwrap_or_else(|_| panic!("{name}={v}: expected a number"))
        })
        .unwrap_or(default)
}

fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> T {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

struct Demo {
    _dir: tempfile::TempDir,
    annotations: Annotations,
    index: AssetIndexArtifact,
    scenes: Vec<(PathBuf, LiftArtifact, TruthInstances)>,
}

/// The demo, lifted, with its asset index (made once for both tests).
fn demo() -> &'static Demo {
    static DEMO: std::sync::OnceLock<Demo> = std::sync::OnceLock::new();
    DEMO.get_or_init(make_demo)
}

fn make_demo() -> Demo {
    let dir = tempfile::tempdir().expect("temp dir");
    let options = DemoOptions::default()
        .with_scenes(env_or("MESA_RETRIEVE_TEST_SCENES", 6) as usize)
        .with_seed(env_or("MESA_RETRIEVE_TEST_SEED", 7));
    let summary = write_demo(dir.path(), &options).expect("mesa demo");
    let annotations =
        Annotations::read(&dir.path().join("assets/annotations.json")).expect("annotations");
    let config = AssetsConfig::default();
    let mut assets = BTreeMap::new();
    let library = dir.path().join("assets/library");
    for entry in std::fs::read_dir(&library).expect("library") {
        let path = entry.expect("entry").path();
        let uid = path
            .file_stem()
            .expect("stem")
            .to_string_lossy()
            .into_owned();
        let bytes = std::fs::read(&path).expect("read");
        let indexed = index_asset(&uid, "", &bytes, annotations.get(&uid), &config);
        assert_eq!(indexed.invalid, None, "{uid}");
        assets.insert(
            uid,
            AssetRecord {
                file: String::new(),
                glb_bytes: bytes.len() as u64,
                glb_sha256: String::new(),
                inputs_sha256: String::new(),
                valid: true,
                reason: None,
                reason_code: None,
                annotated: true,
                geometry: indexed.geometry,
                shapes: None,
                warnings: indexed.warnings,
            },
        );
    }
    let index = AssetIndexArtifact {
        schema: ASSET_INDEX_SCHEMA.to_owned(),
        config_digest: String::new(),
        assets,
        annotated_without_glb: vec![],
    };
    let scenes = summary
        .scenes
        .iter()
        .map(|s| {
            let scene = dir
                .path()
                .join("scenes")
                .join(&s.table_type)
                .join(&s.scene_id);
            let lifted = lift_scene(&scene.join("input"), &s.scene_id, 0, &LiftConfig::default())
                .unwrap_or_else(|e| panic!("{}: {e}", s.scene_id));
            let truth: TruthInstances = read_json(&scene.join("truth/instances.json"));
            (scene, lifted.artifact, truth)
        })
        .collect();
    Demo {
        _dir: dir,
        annotations,
        index,
        scenes,
    }
}

fn truth_of(truth: &TruthInstances, mask_id: u32) -> &mesa_schemas::artifacts::TruthInstance {
    truth
        .instances
        .iter()
        .find(|t| t.id == mask_id)
        .expect("every lifted instance is in the truth")
}

/// Every object rests on the table or on/in an object under it; none is below the table.
fn resting_problems(layout: &DatasetLayout) -> Vec<String> {
    let span = |o: &mesa_schemas::layout::LayoutObject| {
        let (z, h) = (o.position_cm.0[2], o.size_cm.0[2]);
        (z - h / 2.0, z + h / 2.0)
    };
    let half =
        |o: &mesa_schemas::layout::LayoutObject| [o.size_cm.0[0] / 2.0, o.size_cm.0[1] / 2.0];
    let mut problems = Vec::new();
    for o in &layout.objects {
        let (bottom, _) = span(o);
        if bottom < -1e-9 {
            problems.push(format!("{} is below the table ({bottom} cm)", o.instance));
        } else if bottom > 1e-9
            && !layout.objects.iter().any(|q| {
                let (qb, qt) = span(q);
                q.instance != o.instance
                    && footprints_overlap(o.position_cm.0, half(o), q.position_cm.0, half(q))
                    && qb - 1e-9 <= bottom
                    && bottom <= qt + 1e-9
            })
        {
            problems.push(format!("{} floats at {bottom} cm", o.instance));
        }
    }
    problems
}

#[test]
fn retrieval_and_placement_on_the_demo() {
    let demo = demo();
    let text_index = build_text_index(&demo.annotations, &AssetsConfig::default());
    let scorer = TextScorer::Lexical(LexicalIndex::new(&text_index));
    let catalog = Catalog::new(scorer.uids(), &demo.annotations, &demo.index);
    let config = RetrieveConfig::default();
    let (mut right, mut total) = (0usize, 0usize);
    let mut misses = Vec::new();
    for (scene, lift, truth) in &demo.scenes {
        let queries: Vec<Query> = lift
            .instances
            .iter()
            .map(|i| Query::Text(query_text(i, &config)))
            .collect();
        let out = retrieve_scene(lift, &queries, &scorer, &catalog, &config).expect("retrieves");
        for r in &out.artifact.instances {
            let t = truth_of(truth, r.mask_id);
            let chosen = r.chosen.as_deref().and_then(|u| demo.annotations.get(u));
            total += 1;
            if chosen.and_then(|a| a.category.as_deref()) == t.category.as_deref() {
                right += 1;
            } else {
                misses.push(format!(
                    "{}: {} \"{}\"",
                    scene.display(),
                    r.instance,
                    r.query
                ));
            }
        }
        // Placement: a valid coarse layout whose objects rest on something.
        let placed = place_scene(
            lift,
            &out.artifact,
            &demo.index,
            &demo.annotations,
            &PlaceConfig::default(),
        )
        .expect("places");
        assert_eq!(placed.layout.objects.len(), lift.instances.len());
        let text =
            String::from_utf8(mesa_schemas::json::to_sorted_pretty(&placed.layout).expect("json"))
                .expect("utf-8");
        let problems = mesa_schemas::validate_text(&text, None, false);
        assert!(problems.is_empty(), "{}: {problems:?}", scene.display());
        let resting = resting_problems(&placed.layout);
        assert!(resting.is_empty(), "{}: {resting:?}", scene.display());
        for o in &placed.layout.objects {
            assert!(!o.retrieved_uid.is_empty());
            assert!(o.scale_factor.0.iter().all(|s| *s > 0.0));
        }
    }
    let accuracy = right as f64 / total as f64;
    eprintln!("lexical retrieval: {right}/{total} = {accuracy:.3} of the lifted instances get an asset of the true category");
    assert!(total >= 50, "{total} instances");
    assert!(accuracy >= 0.9, "{accuracy:.3}: {misses:#?}");
}

/// A seeded unit embedding per asset, 64-d.
fn embeddings(uids: &[String]) -> Matrix {
    let dim = 64;
    let mut data = Vec::with_capacity(uids.len() * dim);
    for uid in uids {
        let seed = uid.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
            (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3)
        });
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        data.extend((0..dim).map(|_| rng.random_range(-1.0f32..1.0)));
    }
    Matrix {
        rows: uids.len(),
        cols: dim,
        data,
    }
}

#[test]
fn features_with_exact_embeddings_reproduce_the_brute_force_ranking() {
    let demo = demo();
    let uids: Vec<String> = demo.annotations.iter().map(|(u, _)| u.to_owned()).collect();
    let rows = embeddings(&uids);
    let scorer =
        TextScorer::Features(FeatureMatrix::new(rows.clone(), uids.clone()).expect("features"));
    let catalog = Catalog::new(scorer.uids(), &demo.annotations, &demo.index);
    let config = RetrieveConfig::default();
    let row = |uid: &str| {
        let i = uids.iter().position(|u| u == uid).expect("uid");
        rows.data[i * rows.cols..(i + 1) * rows.cols].to_vec()
    };
    let mut instances = 0;
    for (scene, lift, truth) in &demo.scenes {
        let queries: Vec<Query> = lift
            .instances
            .iter()
            .map(|i| Query::Embedding(row(truth_of(truth, i.mask_id).uid.as_deref().expect("uid"))))
            .collect();
        let out = retrieve_scene(lift, &queries, &scorer, &catalog, &config).expect("retrieves");
        for ((r, q), lifted) in out
            .artifact
            .instances
            .iter()
            .zip(&queries)
            .zip(&lift.instances)
        {
            let Query::Embedding(query) = q else {
                unreachable!()
            };
            // The brute force: every cosine in f64, a full sort, the top 20, the final scores.
            let mut all: Vec<(usize, f64)> = (0..rows.rows)
                .map(|i| {
                    (
                        i,
                        cosine_f64(&rows.data[i * rows.cols..(i + 1) * rows.cols], query),
                    )
                })
                .collect();
            all.sort_by(|a, b| b.1.total_cmp(&a.1).then_with(|| uids[a.0].cmp(&uids[b.0])));
            let mut top: Vec<(String, f64, f64)> = all[..20]
                .iter()
                .map(|(i, text)| {
                    let size = demo
                        .annotations
                        .get(&uids[*i])
                        .and_then(|a| a.bbox)
                        .map(|b| b.size_table_frame())
                        .expect("every demo asset has a bbox");
                    let size_score = size_cosine(lifted.size_cm.0, size);
                    (uids[*i].clone(), *text, 0.9 * text + 0.1 * size_score)
                })
                .collect();
            top.sort_by(|a, b| b.2.total_cmp(&a.2));
            let ours: Vec<(String, f64, f64)> = r
                .candidates
                .iter()
                .map(|c| (c.uid.clone(), c.text_score, c.final_score))
                .collect();
            assert_eq!(ours, top, "{}: {}", scene.display(), r.instance);
            let t = truth_of(truth, r.mask_id);
            assert_eq!(r.chosen, t.uid, "{}: {}", scene.display(), r.instance);
            instances += 1;
        }
    }
    assert!(instances >= 50, "{instances}");
}
