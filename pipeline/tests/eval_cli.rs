//! End-to-end tests of `mesa eval` (issue #19) over a demo dataset built once (`mesa demo` +
//! `mesa run`, split so that it has test and DPO scenes):
//!
//! - the dataset's own test references as outputs: success 100 %, the colliding pairs `mesa
//!   check` found on those scenes, graph self-consistency ≥ 0.99, full task coverage; a broken
//!   copy of one output is a failure with its reason while the others are still evaluated;
//! - the DPO rejected outputs, one file per corruption, each against the chosen outputs of the
//!   same prompts: the collision corruption raises the collision rate, the missing-object one
//!   lowers task coverage, the relation one lowers graph self-consistency;
//! - MesaTask-style inference folders with broken outputs: failures with reasons, no crash;
//! - FID, KID and CKL against numpy / scipy (`MESA_PYTHON`, else `.venv-tools`), to 1e-6;
//! - the GPT score against a local OpenAI-compatible server (tests/common): two views and the
//!   template's text per request, a good reply's mean, rejects with their reasons, a rerun
//!   without requests and the same bytes at 1 and 3 jobs, the API key in no file or log,
//!   offline batches with one request per successful sample, a missing judge refused.

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use common::{mesa, user_text, MockServer, Reply};
use mesa_schemas::artifacts::{CheckArtifact, DpoRecord, SftRecord};
use mesa_schemas::eval::{EvalMetrics, EvalSample, SampleGptScore};
use mesa_schemas::output::{parse_model_output, FINAL_ANSWER_MARKER};
use mesa_stages::eval::ckl;
use mesa_stages::eval::features::{fid, kid, Features};
use rand::{Rng, SeedableRng};
use serde_json::{json, Value};

fn read<T: serde::de::DeserializeOwned>(path: &Path) -> T {
    serde_json::from_slice(
        &std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
    )
    .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn ok(args: &[&str]) -> String {
    let out = mesa().args(args).output().expect("runs");
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(out.status.success(), "mesa {args:?}: {stderr}{stdout}");
    stdout
}

/// The demo dataset, built once for every test of this file under cargo's temporary folder
/// for tests (`target/tmp/eval_cli/`, rebuilt by each run; the split puts most scenes in test
/// and dpo).
fn dataset() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let root = Path::new(env!("CARGO_TARGET_TMPDIR")).join("eval_cli");
        if root.exists() {
            std::fs::remove_dir_all(&root).expect("remove the last run's dataset");
        }
        std::fs::create_dir_all(&root).expect("mkdir");
        let path = root.join("demo");
        let p = path.to_str().expect("utf-8");
        ok(&["demo", p, "--scenes", "6", "--seed", "5"]);
        let config = path.join("mesa.toml");
        let mut text = std::fs::read_to_string(&config).expect("mesa.toml");
        text.push_str("\n[records.split]\ntrain = 0.2\ndpo = 0.4\ntest = 0.4\n");
        std::fs::write(&config, text).expect("mesa.toml");
        let out = mesa()
            .args(["run", p, "--progress", "off", "-q"])
            .output()
            .expect("runs");
        assert!(
            out.status.code().is_some_and(|c| c <= 1),
            "mesa run: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        path
    })
}

/// `(id, output)` pairs.
type Outputs = Vec<(String, String)>;

/// Writes `{"id", "output"}` lines.
fn write_outputs(path: &Path, outputs: &[(String, String)]) {
    let text: String = outputs
        .iter()
        .map(|(id, output)| format!("{}\n", json!({"id": id, "output": output})))
        .collect();
    std::fs::write(path, text).expect("write outputs");
}

/// Runs `mesa eval` and returns its metrics and samples.
fn eval(data: &Path, outputs: &Path, name: &str, extra: &[&str]) -> (EvalMetrics, Vec<EvalSample>) {
    let d = data.to_str().expect("utf-8");
    let o = outputs.to_str().expect("utf-8");
    let mut args = vec!["eval", d, "--outputs", o, "--name", name];
    args.extend_from_slice(extra);
    ok(&args);
    let dir = data.join("eval").join(name);
    let samples = std::fs::read_to_string(dir.join("samples.jsonl"))
        .expect("samples.jsonl")
        .lines()
        .map(|l| serde_json::from_str(l).expect("a sample line"))
        .collect();
    (read(&dir.join("metrics.json")), samples)
}

/// Sorted instance names of an output's layout (what finds its scene).
fn instance_key(output: &str) -> Vec<String> {
    let parsed = parse_model_output(output).expect("a reference parses");
    let mut names: Vec<String> = parsed
        .layout
        .objects
        .iter()
        .map(|o| o.instance.clone())
        .collect();
    names.sort();
    names
}

/// Per scene (by sorted instance names): the colliding pairs of its qa/check.json.
fn check_pairs(data: &Path) -> BTreeMap<Vec<String>, usize> {
    let mut out = BTreeMap::new();
    for scene in common::scene_dirs(data) {
        let check = scene.join("qa/check.json");
        if !check.is_file() {
            continue;
        }
        let check: CheckArtifact = read(&check);
        let layout: Value = read(&scene.join(&check.layout));
        let mut names: Vec<String> = layout["objects"]
            .as_array()
            .expect("objects")
            .iter()
            .map(|o| o["instance"].as_str().expect("instance").to_owned())
            .collect();
        names.sort();
        out.insert(names, check.collisions.len());
    }
    out
}

#[test]
fn the_test_references_succeed_and_agree_with_check_and_their_graphs() {
    let data = dataset();
    let tests: Vec<SftRecord> = read(&data.join("records/test.json"));
    assert!(tests.len() >= 5, "{} test prompts", tests.len());
    let refs: Vec<(String, String)> = tests
        .iter()
        .enumerate()
        .map(|(i, r)| (i.to_string(), r.output.clone()))
        .collect();
    let file = data.join("refs.jsonl");
    write_outputs(&file, &refs);
    let (m, samples) = eval(data, &file, "refs", &[]);
    assert_eq!(m.samples, tests.len() as u64);
    assert_eq!(m.success_rate, 1.0, "{:?}", m.failures);
    assert!(m.failures.is_empty());
    // `mesa check` on the scenes the eval built (eval/refs/layouts/) finds the same pairs.
    let checked = data.with_file_name("check_refs");
    std::fs::create_dir_all(checked.join("scenes/eval")).expect("mkdir");
    std::os::unix::fs::symlink(data.join("assets"), checked.join("assets")).expect("symlink");
    std::fs::copy(data.join("mesa.toml"), checked.join("mesa.toml")).expect("config");
    for s in &samples {
        let scene = checked.join(format!("scenes/eval/eval_{}", s.id));
        std::fs::create_dir_all(scene.join("refined")).expect("mkdir");
        std::fs::copy(
            data.join(format!("eval/refs/layouts/{}.json", s.id)),
            scene.join("refined/layout.json"),
        )
        .expect("copy the eval's layout");
    }
    let c = checked.to_str().expect("utf-8");
    let out = mesa()
        .args(["check", c, "--progress", "off", "-q"])
        .output()
        .expect("runs");
    assert!(
        out.status.code().is_some_and(|c| c <= 1),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (mut pairs, mut colliding, mut floating) = (0, 0, 0);
    for s in &samples {
        let check: CheckArtifact =
            read(&checked.join(format!("scenes/eval/eval_{}/qa/check.json", s.id)));
        pairs += check.pairs_total;
        colliding += check.collisions.len() as u64;
        floating += check.floating.len() as u64;
        assert_eq!(
            check.collisions.len(),
            s.collisions.len(),
            "sample {}",
            s.id
        );
    }
    assert_eq!(m.physics.pairs, pairs);
    assert_eq!(m.physics.colliding_pairs, colliding);
    assert_eq!(m.physics.objects_floating, floating);
    // Against mesa check of the dataset's own scenes: the LLM form keeps only the yaw, so a
    // tilted object (a pencil lying on its side) comes back turned otherwise; the retrieval
    // picks the scene's own asset for most objects.
    let original = check_pairs(data);
    let scene_pairs: usize = tests
        .iter()
        .map(|r| {
            *original
                .get(&instance_key(&r.output))
                .expect("the prompt's scene was checked")
        })
        .sum();
    eprintln!(
        "references: {} colliding pairs of {} in the eval's scenes, {} in mesa check of the \
         dataset's scenes",
        m.physics.colliding_pairs, m.physics.pairs, scene_pairs
    );
    assert!(m.physics.objects_unchecked == 0, "{:#?}", m.physics);
    eprintln!(
        "references: {} samples, success {}, graph precision {:.4} recall {:.4}, coverage {:.4}, \
         implausible sizes {:.4}, CKL {:?}",
        m.samples,
        m.success_rate,
        m.graph.precision,
        m.graph.recall,
        m.task_coverage.coverage,
        m.size.share,
        m.ckl_mean
    );
    assert!(
        m.graph.precision >= 0.99 && m.graph.recall >= 0.99,
        "{:#?}",
        m.graph
    );
    assert_eq!(m.task_coverage.coverage, 1.0, "{:#?}", m.task_coverage);
    // Every prompt found its scene's table type, so CKL is computed.
    assert!(samples.iter().all(|s| s.table_type.is_some()));
    assert!(m.ckl_mean.is_some_and(|c| c.is_finite()));
    // The artifact validates.
    let metrics = data.join("eval/refs/metrics.json");
    ok(&["validate", metrics.to_str().expect("utf-8")]);
    ok(&[
        "validate",
        "--kind",
        "eval-sample",
        data.join("eval/refs/samples.jsonl")
            .to_str()
            .expect("utf-8"),
    ]);

    // Control: the same outputs with one broken, one missing and one repeated; the rest are
    // evaluated as before.
    let mut broken = refs.clone();
    broken[0].1 = broken[0].1.replace(FINAL_ANSWER_MARKER, "\nThe layout:\n");
    broken.remove(1);
    broken.push(refs[2].clone());
    broken.push(("no-such-id".to_owned(), refs[2].1.clone()));
    let file = data.join("broken.jsonl");
    write_outputs(&file, &broken);
    let (b, samples) = eval(data, &file, "broken", &[]);
    assert_eq!(b.succeeded, m.succeeded - 2);
    assert_eq!(b.failures.get("no_marker"), Some(&1));
    assert_eq!(b.failures.get("no_output"), Some(&1));
    assert_eq!(b.ignored_outputs.len(), 2, "{:?}", b.ignored_outputs);
    assert_eq!(
        samples[0].failure.as_ref().map(|f| f.reason.as_str()),
        Some("no_marker")
    );
    assert!(samples[2].success);
    let page = std::fs::read_to_string(data.join("eval/broken/index.html")).expect("page");
    assert!(page.contains("no: no_marker"), "the page flags the failure");

    // The same bytes for one thread as for several.
    let file = data.join("refs.jsonl");
    let (_, one) = eval(data, &file, "refs_one_thread", &["--jobs", "1"]);
    assert_eq!(one, eval(data, &file, "refs", &["--jobs", "3"]).1);
    assert_eq!(
        std::fs::read(data.join("eval/refs_one_thread/samples.jsonl")).expect("read"),
        std::fs::read(data.join("eval/refs/samples.jsonl")).expect("read")
    );

    // --compare puts the runs side by side.
    let table = ok(&[
        "eval",
        data.to_str().expect("utf-8"),
        "--compare",
        "refs,broken",
    ]);
    let rows: Vec<&str> = table
        .lines()
        .filter(|l| l.starts_with("| refs") || l.starts_with("| broken"))
        .collect();
    assert_eq!(rows.len(), 2, "{table}");
    assert!(rows[0].contains("| 100.0 % |"), "{table}");
    assert!(!rows[1].contains("| 100.0 % |"), "{table}");
    assert!(data.join("eval/compare.md").is_file());
    let missing = mesa()
        .args([
            "eval",
            data.to_str().expect("utf-8"),
            "--compare",
            "refs,nobody",
        ])
        .output()
        .expect("runs");
    assert!(!missing.status.success());
    assert!(String::from_utf8_lossy(&missing.stderr).contains("nobody"));
}

/// The corruption of a rejected output, from how it differs from the chosen one.
fn corruption(chosen: &str, rejected: &str) -> &'static str {
    let c = parse_model_output(chosen).expect("chosen parses");
    let r = parse_model_output(rejected).expect("rejected parses");
    if r.layout.objects.len() < c.layout.objects.len() {
        "missing_object"
    } else if r.layout == c.layout {
        "relation"
    } else {
        "collision"
    }
}

#[test]
fn each_dpo_corruption_moves_its_metric() {
    let data = dataset();
    let dpo: Vec<DpoRecord> = read(&data.join("records/dpo.json"));
    let mut by_kind: BTreeMap<&str, (Outputs, Outputs)> = BTreeMap::new();
    for (i, r) in dpo.iter().enumerate() {
        let entry = by_kind
            .entry(corruption(&r.chosen, &r.rejected))
            .or_default();
        entry.0.push((i.to_string(), r.chosen.clone()));
        entry.1.push((i.to_string(), r.rejected.clone()));
    }
    let kinds: Vec<&&str> = by_kind.keys().collect();
    assert_eq!(
        kinds,
        [&"collision", &"missing_object", &"relation"],
        "the demo must have every corruption"
    );
    let mut results = BTreeMap::new();
    for (kind, (chosen, rejected)) in &by_kind {
        let c = data.join(format!("chosen_{kind}.jsonl"));
        let r = data.join(format!("rejected_{kind}.jsonl"));
        write_outputs(&c, chosen);
        write_outputs(&r, rejected);
        let prompts = ["--prompts", "records/dpo.json"];
        let (mc, _) = eval(data, &c, &format!("chosen_{kind}"), &prompts);
        let (mr, _) = eval(data, &r, &format!("rejected_{kind}"), &prompts);
        assert_eq!(mc.succeeded, chosen.len() as u64);
        assert_eq!(mr.succeeded, rejected.len() as u64);
        results.insert(*kind, (mc, mr));
    }
    for (kind, (c, r)) in &results {
        eprintln!(
            "{kind}: collision rate {:.4} → {:.4}, coverage {:.4} → {:.4}, graph F1 {:.4} → {:.4}",
            c.physics.collision_rate,
            r.physics.collision_rate,
            c.task_coverage.coverage,
            r.task_coverage.coverage,
            c.graph.f1,
            r.graph.f1
        );
    }
    let (c, r) = &results["collision"];
    assert!(
        r.physics.collision_rate > c.physics.collision_rate,
        "collision: {} vs {}",
        r.physics.collision_rate,
        c.physics.collision_rate
    );
    let (c, r) = &results["missing_object"];
    assert!(
        r.task_coverage.coverage < c.task_coverage.coverage,
        "missing object: {:?} vs {:?}",
        r.task_coverage,
        c.task_coverage
    );
    let (c, r) = &results["relation"];
    assert!(
        r.graph.f1 < c.graph.f1 && r.graph.precision.min(r.graph.recall) < 0.99,
        "relation: {:?} vs {:?}",
        r.graph,
        c.graph
    );
    // The layouts of the relation corruption are unchanged: so is the physics.
    assert_eq!(r.physics.colliding_pairs, c.physics.colliding_pairs);
}

#[test]
fn broken_mesatask_inference_folders_are_failures_with_reasons() {
    let data = dataset();
    let tests: Vec<SftRecord> = read(&data.join("records/test.json"));
    let good = tests[0].output.clone();
    let info: Value = serde_json::from_str(&tests[0].input).expect("task info");
    let root = tempfile::tempdir().expect("tempdir");
    let out = root.path().join("output");
    let scene = |task: &str, scene: &str, text: Option<&str>| {
        let dir = out.join(task).join(scene);
        std::fs::create_dir_all(&dir).expect("mkdir");
        if let Some(text) = text {
            std::fs::write(dir.join("scene_layout.txt"), text).expect("write");
        }
    };
    std::fs::create_dir_all(out.join("task_000")).expect("mkdir");
    std::fs::write(
        out.join("task_000/office_task.json"),
        serde_json::to_string(&info).expect("json"),
    )
    .expect("write");
    scene("task_000", "scene_000", Some(&good));
    scene(
        "task_000",
        "scene_001",
        Some(&good.replace(FINAL_ANSWER_MARKER, "\n")),
    );
    let cut = good.len() - 40;
    scene("task_000", "scene_002", Some(&good[..cut]));
    let (head, json_text) = good.split_at(good.find(FINAL_ANSWER_MARKER).expect("marker"));
    let mut layout: Value =
        serde_json::from_str(&json_text[FINAL_ANSWER_MARKER.len()..]).expect("layout");
    for object in layout["objects"].as_array_mut().expect("objects") {
        object
            .as_object_mut()
            .expect("object")
            .remove("description");
    }
    scene(
        "task_001",
        "scene_000",
        Some(&format!("{head}{FINAL_ANSWER_MARKER}{layout}")),
    );
    scene("task_001", "scene_001", None);
    let d = data.to_str().expect("utf-8");
    ok(&[
        "eval",
        d,
        "--mesatask",
        out.to_str().expect("utf-8"),
        "--name",
        "mesatask_broken",
    ]);
    let m: EvalMetrics = read(&data.join("eval/mesatask_broken/metrics.json"));
    assert_eq!(m.samples, 5);
    assert_eq!(m.succeeded, 1);
    let expected: BTreeMap<String, u64> = [
        ("no_marker", 1),
        ("not_json", 1),
        ("no_valid_object", 1),
        ("unreadable", 1),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_owned(), v))
    .collect();
    assert_eq!(m.failures, expected);
    // The good sample read its task info from the task folder's only JSON file, as MesaTask's
    // inference.py takes it (any name).
    assert_eq!(m.task_coverage.samples, 1);
}

/// A Python with numpy and scipy: `MESA_PYTHON`, else the repository's `.venv-tools`; None
/// (SKIPPED) without one, a failure under `MESA_REQUIRE_TOOLS`.
fn scipy_python() -> Option<PathBuf> {
    let candidates = [
        std::env::var_os("MESA_PYTHON").map(PathBuf::from),
        Some(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../.venv-tools/bin/python")),
    ];
    let found = candidates.into_iter().flatten().find(|p| {
        std::process::Command::new(p)
            .args(["-c", "import numpy, scipy.linalg"])
            .output()
            .is_ok_and(|o| o.status.success())
    });
    if found.is_none() {
        assert!(
            std::env::var_os("MESA_REQUIRE_TOOLS").is_none(),
            "FID/KID reference needs MESA_PYTHON (or .venv-tools) with numpy and scipy, and \
             MESA_REQUIRE_TOOLS is set"
        );
        eprintln!("SKIPPED: FID/KID/CKL against numpy and scipy (set MESA_PYTHON)");
    }
    found
}

/// A float64 `.npy` as numpy.save writes it.
fn npy_f64(rows: usize, cols: usize, data: &[f64]) -> Vec<u8> {
    let mut header =
        format!("{{'descr': '<f8', 'fortran_order': False, 'shape': ({rows}, {cols}), }}");
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for v in data {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

const REFERENCE: &str = r#"
import json, sys
import numpy as np
from scipy import linalg
a = np.load(sys.argv[1]); b = np.load(sys.argv[2])
mu1, mu2 = a.mean(0), b.mean(0)
s1, s2 = np.cov(a, rowvar=False), np.cov(b, rowvar=False)
covmean = linalg.sqrtm(s1.dot(s2))
if np.iscomplexobj(covmean):
    covmean = covmean.real
fid = float(((mu1 - mu2) ** 2).sum() + np.trace(s1) + np.trace(s2) - 2 * np.trace(covmean))
d = a.shape[1]
k = lambda x, y: (x @ y.T / d + 1) ** 3
kxx, kyy, kxy = k(a, a), k(b, b), k(a, b)
m, n = a.shape[0], b.shape[0]
kid = float((kxx.sum() - np.trace(kxx)) / (m * (m - 1)) + (kyy.sum() - np.trace(kyy)) / (n * (n - 1)) - 2 * kxy.sum() / (m * n))
p = np.array(json.loads(sys.argv[3]), dtype=float); q = np.array(json.loads(sys.argv[4]), dtype=float)
p, q = p / p.sum(), q / q.sum()
ckl = float((p * (np.log(p + 1e-6) - np.log(q + 1e-6))).sum())
print(json.dumps({"fid": fid, "kid": kid, "ckl": ckl}))
"#;

#[test]
fn fid_kid_and_ckl_agree_with_numpy_and_scipy() {
    let Some(python) = scipy_python() else {
        return;
    };
    let dir = tempfile::tempdir().expect("tempdir");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(19);
    for (case, (n1, n2, d)) in [(300, 250, 32), (400, 350, 128)].into_iter().enumerate() {
        // Correlated features (a random mixing), the second set shifted and scaled.
        let mix: Vec<f64> = (0..d * d).map(|_| rng.random_range(-1.0..1.0)).collect();
        let sample = |n: usize, shift: f64, scale: f64, rng: &mut rand_chacha::ChaCha8Rng| {
            let raw: Vec<f64> = (0..n * d).map(|_| rng.random_range(-1.0..1.0)).collect();
            let mut out = vec![0.0; n * d];
            for r in 0..n {
                for c in 0..d {
                    out[r * d + c] = shift
                        + scale * (0..d).map(|k| raw[r * d + k] * mix[k * d + c]).sum::<f64>();
                }
            }
            Features {
                rows: n,
                cols: d,
                data: out,
            }
        };
        let a = sample(n1, 0.0, 1.0, &mut rng);
        let b = sample(n2, 0.3, 1.2, &mut rng);
        let pa = dir.path().join(format!("a{case}.npy"));
        let pb = dir.path().join(format!("b{case}.npy"));
        std::fs::write(&pa, npy_f64(a.rows, a.cols, &a.data)).expect("write");
        std::fs::write(&pb, npy_f64(b.rows, b.cols, &b.data)).expect("write");
        let p: Vec<u64> = (0..12).map(|_| rng.random_range(0..40)).collect();
        let q: Vec<u64> = (0..12).map(|_| rng.random_range(1..40)).collect();
        let out = std::process::Command::new(&python)
            .args(["-c", REFERENCE])
            .arg(&pa)
            .arg(&pb)
            .arg(serde_json::to_string(&p).expect("json"))
            .arg(serde_json::to_string(&q).expect("json"))
            .output()
            .expect("python runs");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let reference: Value = serde_json::from_slice(&out.stdout).expect("json");
        let close = |ours: f64, theirs: f64, what: &str| {
            let rel = (ours - theirs).abs() / theirs.abs().max(1e-300);
            assert!(
                rel < 1e-6,
                "{what} (case {case}): mesa {ours} numpy {theirs} (rel {rel:e})"
            );
        };
        close(
            fid(&a, &b).expect("fid"),
            reference["fid"].as_f64().expect("fid"),
            "FID",
        );
        close(
            kid(&a, &b).expect("kid"),
            reference["kid"].as_f64().expect("kid"),
            "KID",
        );
        let counts = |v: &[u64]| -> BTreeMap<String, u64> {
            v.iter()
                .enumerate()
                .map(|(i, c)| (format!("c{i:02}"), *c))
                .collect()
        };
        close(
            ckl(&counts(&p), &counts(&q)).expect("ckl"),
            reference["ckl"].as_f64().expect("ckl"),
            "CKL",
        );
        // Control: a different set gives a clearly different FID (the comparison can fail).
        let c = sample(n2, 0.0, 1.0, &mut rng);
        assert!((fid(&a, &c).expect("fid") - reference["fid"].as_f64().expect("fid")).abs() > 1e-3);
    }
}

#[test]
fn fid_and_kid_come_from_feature_files_through_the_cli() {
    let data = dataset();
    let tests: Vec<SftRecord> = read(&data.join("records/test.json"));
    let file = data.join("refs_features.jsonl");
    write_outputs(&file, &[("0".to_owned(), tests[0].output.clone())]);
    let (rows, cols) = (20, 6);
    let a: Vec<f64> = (0..rows * cols)
        .map(|i| ((i * 37) % 11) as f64 * 0.1)
        .collect();
    let b: Vec<f64> = a.iter().map(|v| v + 1.0).collect();
    std::fs::write(data.join("real.npy"), npy_f64(rows, cols, &a)).expect("write");
    std::fs::write(data.join("gen.npy"), npy_f64(rows, cols, &b)).expect("write");
    let real = data.join("real.npy");
    let gen = data.join("gen.npy");
    let (m, _) = eval(
        data,
        &file,
        "features",
        &[
            "--real-features",
            real.to_str().expect("utf-8"),
            "--generated-features",
            gen.to_str().expect("utf-8"),
            "--render",
        ],
    );
    // --render drew the scene and the page shows it.
    let front = data.join("eval/features/render/0_front.png");
    assert!(
        std::fs::read(&front)
            .expect("front view")
            .starts_with(b"\x89PNG"),
        "{}",
        front.display()
    );
    let page = std::fs::read_to_string(data.join("eval/features/index.html")).expect("page");
    assert!(page.contains("<img src=\"render/0_front.png\""), "{page}");
    let f = m.features.expect("features");
    // Same covariance, means 1 apart in 6 dimensions.
    assert!((f.fid - 6.0).abs() < 1e-6, "{}", f.fid);
    assert!(f.kid > 0.0);
    // A malformed feature file is an error naming it.
    std::fs::write(data.join("bad.npy"), b"not npy").expect("write");
    let out = mesa()
        .args(["eval", data.to_str().expect("utf-8"), "--outputs"])
        .arg(&file)
        .args(["--name", "badfeatures", "--real-features"])
        .arg(data.join("bad.npy"))
        .arg("--generated-features")
        .arg(&gen)
        .output()
        .expect("runs");
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("bad.npy"));
}

/// An output with its layout JSON changed by `edit`.
fn edited(output: &str, edit: impl Fn(&mut Value)) -> String {
    let at = output.find(FINAL_ANSWER_MARKER).expect("marker");
    let (head, tail) = output.split_at(at);
    let mut layout: Value =
        serde_json::from_str(&tail[FINAL_ANSWER_MARKER.len()..]).expect("layout JSON");
    edit(&mut layout);
    format!("{head}{FINAL_ANSWER_MARKER}{layout}")
}

#[test]
fn oversized_objects_and_foreign_categories_move_size_and_ckl() {
    let data = dataset();
    let tests: Vec<SftRecord> = read(&data.join("records/test.json"));
    let refs: Outputs = tests
        .iter()
        .enumerate()
        .map(|(i, r)| (i.to_string(), r.output.clone()))
        .collect();
    let file = data.join("sizes_refs.jsonl");
    write_outputs(&file, &refs);
    let (base, _) = eval(data, &file, "sizes_refs", &[]);
    assert_eq!(base.size.implausible, 0, "{:?}", base.size);
    assert!(base.size.objects > 0);

    // The first object of every output five times its size.
    let grown: Outputs = refs
        .iter()
        .map(|(id, o)| {
            let out = edited(o, |layout| {
                let size = &mut layout["objects"][0]["size"];
                for v in size.as_array_mut().expect("size") {
                    *v = json!(v.as_f64().expect("number") * 5.0);
                }
            });
            (id.clone(), out)
        })
        .collect();
    let file = data.join("sizes_grown.jsonl");
    write_outputs(&file, &grown);
    let (m, samples) = eval(data, &file, "sizes_grown", &[]);
    assert_eq!(m.size.implausible, refs.len() as u64, "{:?}", m.size);
    for s in &samples {
        let first = &s.objects[0].instance;
        assert!(
            s.implausible_size
                .iter()
                .any(|w| w.starts_with(first.as_str())),
            "{:?}",
            s.implausible_size
        );
    }

    // Every object renamed to one category the dataset has little of: CKL grows.
    let renamed: Outputs = refs
        .iter()
        .map(|(id, o)| {
            let out = edited(o, |layout| {
                for (i, object) in layout["objects"]
                    .as_array_mut()
                    .expect("objects")
                    .iter_mut()
                    .enumerate()
                {
                    object["instance"] = json!(format!("widget_{i}"));
                }
            });
            (id.clone(), out)
        })
        .collect();
    let file = data.join("ckl_renamed.jsonl");
    write_outputs(&file, &renamed);
    let (m, _) = eval(data, &file, "ckl_renamed", &[]);
    let (before, after) = (base.ckl_mean.expect("ckl"), m.ckl_mean.expect("ckl"));
    eprintln!("CKL: references {before:.4}, renamed {after:.4}");
    assert!(after > before + 1.0, "CKL {before} → {after}");
}

// ---------------------------------------------------------------------------------------------
// The GPT score.

const GPT_KEY_VAR: &str = "MESA_EVAL_GPT_TEST_KEY";
const GPT_KEY: &str = "sk-mesa-eval-gpt-test-7e2a91";

/// A good reply: the mean of its five scores is 8.
const GOOD_SCORES: &str = r#"{"consistency_with_task": 8, "object_size_reasonableness": 7, "placement_plausibility": 9, "layout_coherence": 6, "object_visibility": 10, "reason": "A plausible counter."}"#;

/// A configuration file beside the dataset's: its mesa.toml with a judge at `base_url`
/// (each test its own model name, so that the tests share no cached reply) and `extra` lines
/// in [eval].
fn gpt_config(data: &Path, name: &str, base_url: &str, model: &str, extra: &str) -> PathBuf {
    let mut text = std::fs::read_to_string(data.join("mesa.toml")).expect("mesa.toml");
    text.push_str(&format!(
        "\n[eval]\njudge = \"llm\"\n{extra}\n[eval.llm]\nbase_url = \"{base_url}\"\n\
         model = \"{model}\"\napi_key_env = \"{GPT_KEY_VAR}\"\nmax_retries = 0\ntimeout_s = 20.0\n\
         max_concurrency = 3\n"
    ));
    let path = data.with_file_name(format!("{name}.toml"));
    std::fs::write(&path, text).expect("config");
    path
}

/// The first `n` test prompts' reference outputs, and each one's task instruction.
fn first_references(data: &Path, n: usize) -> (Outputs, Vec<String>) {
    let tests: Vec<SftRecord> = read(&data.join("records/test.json"));
    assert!(tests.len() >= n);
    let outputs = (0..n)
        .map(|i| (i.to_string(), tests[i].output.clone()))
        .collect();
    let tasks = tests[..n]
        .iter()
        .map(|r| {
            let info: Value = serde_json::from_str(&r.input).expect("task info");
            info["Task"].as_str().expect("Task").to_owned()
        })
        .collect();
    (outputs, tasks)
}

/// `mesa eval` with the key in the environment and every log level on: (success, stdout,
/// stderr).
fn eval_gpt(data: &Path, outputs: &Path, name: &str, extra: &[&str]) -> (bool, String, String) {
    let out = mesa()
        .args(["-vv", "eval"])
        .arg(data)
        .arg("--outputs")
        .arg(outputs)
        .args(["--name", name, "--progress", "off"])
        .args(extra)
        .env(GPT_KEY_VAR, GPT_KEY)
        .env("MESA_LOG", "trace")
        .output()
        .expect("runs");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn gpt_of(samples: &[EvalSample], id: &str) -> SampleGptScore {
    samples
        .iter()
        .find(|s| s.id == id)
        .and_then(|s| s.gpt_score.clone())
        .unwrap_or_else(|| panic!("sample {id} has a GPT score"))
}

#[test]
fn the_gpt_score_sends_two_views_validates_replies_caches_and_keeps_the_key_secret() {
    let data = dataset();
    let (outputs, tasks) = first_references(data, 5);
    let distinct: std::collections::BTreeSet<&String> = tasks.iter().collect();
    assert_eq!(
        distinct.len(),
        5,
        "the replies are chosen by task: {tasks:?}"
    );
    // Sample i gets reply i: good, not JSON, a criterion missing, a score of 11, a string.
    let replies = [
        GOOD_SCORES.to_owned(),
        "{not json".to_owned(),
        GOOD_SCORES.replace("\"object_visibility\": 10, ", ""),
        GOOD_SCORES.replace("\"layout_coherence\": 6", "\"layout_coherence\": 11"),
        GOOD_SCORES.replace("\"layout_coherence\": 6", "\"layout_coherence\": \"6\""),
    ];
    let by_task: Vec<(String, String)> = tasks.iter().cloned().zip(replies).collect();
    let server = MockServer::start(move |request, _| {
        let text = user_text(&request.json());
        match by_task
            .iter()
            .find(|(task, _)| text.contains(&format!("Task instruction: {task}\n")))
        {
            Some((_, reply)) => Reply::completion(reply),
            None => Reply::error(400, "unknown sample"),
        }
    });
    let file = data.join("gpt_live.jsonl");
    write_outputs(&file, &outputs);
    let config = gpt_config(data, "gpt_live", &server.base_url, "judge-live", "");
    let c = config.to_str().expect("utf-8");

    let (success, stdout, stderr) = eval_gpt(
        data,
        &file,
        "gpt_live",
        &["--gpt-score", "--config", c, "--jobs", "1"],
    );
    assert!(success, "{stderr}");
    // One request per successful sample (the other five prompts have no output).
    assert_eq!(server.requests(), 5, "{stderr}");
    let dir = data.join("eval/gpt_live");
    let template = mesa_stages::eval::gpt_score::parse_prompt(
        "built-in",
        mesa_stages::eval::gpt_score::GPT_SCORE_PROMPT,
    )
    .expect("template");
    for request in server.received() {
        assert_eq!(
            request.header("authorization"),
            Some(format!("Bearer {GPT_KEY}"))
        );
        let body = request.json();
        assert_eq!(body["model"], "judge-live");
        assert_eq!(body["messages"][0]["content"], template.system.as_str());
        let parts = body["messages"][1]["content"].as_array().expect("parts");
        assert_eq!(parts.len(), 3, "the text and two images");
        let text = parts[0]["text"].as_str().expect("text");
        for line in [
            "Placement Plausibility & Intersections",
            "Object Visibility",
        ] {
            assert!(text.contains(line), "the template's text: {text}");
        }
        // The images are the sample's front and perspective views, in that order.
        let i = tasks
            .iter()
            .position(|t| text.contains(&format!("Task instruction: {t}\n")))
            .expect("a sample's task");
        for (part, view) in parts[1..].iter().zip(["front", "perspective"]) {
            let png = std::fs::read(dir.join(format!("render/{i}_{view}.png"))).expect("view");
            assert!(png.starts_with(b"\x89PNG"));
            assert_eq!(
                part["image_url"]["url"].as_str().expect("url"),
                mesa_stages::tasks::chat::png_data_url(&png),
                "sample {i} {view}"
            );
        }
    }

    let (m, samples) = (
        read::<EvalMetrics>(&dir.join("metrics.json")),
        std::fs::read_to_string(dir.join("samples.jsonl"))
            .expect("samples")
            .lines()
            .map(|l| serde_json::from_str::<EvalSample>(l).expect("sample"))
            .collect::<Vec<_>>(),
    );
    let good = gpt_of(&samples, "0");
    assert_eq!(
        (good.status.as_str(), good.mean),
        ("scored", Some(8.0)),
        "{good:?}"
    );
    assert_eq!(good.scores.len(), 5);
    assert_eq!(good.reason.as_deref(), Some("A plausible counter."));
    let not_json = gpt_of(&samples, "1");
    assert_eq!(not_json.status, "rejected");
    assert!(
        not_json.problems[0].contains("not valid JSON"),
        "{not_json:?}"
    );
    assert_eq!(not_json.reply.as_deref(), Some("{not json"));
    let missing = gpt_of(&samples, "2");
    assert_eq!(missing.rejected_criteria, ["object_visibility"]);
    assert!(
        missing.problems[0].contains("object_visibility: missing"),
        "{missing:?}"
    );
    let eleven = gpt_of(&samples, "3");
    assert_eq!(eleven.rejected_criteria, ["layout_coherence"]);
    assert!(
        eleven.problems[0].contains("11 is not an integer from 1 to 10"),
        "{eleven:?}"
    );
    let string = gpt_of(&samples, "4");
    assert_eq!(string.rejected_criteria, ["layout_coherence"]);
    assert!(string.problems[0].contains("is not a number"), "{string:?}");
    assert!(samples.iter().skip(5).all(|s| s.gpt_score.is_none()));
    let g = m.gpt_score.as_ref().expect("metrics.gpt_score");
    assert_eq!(
        (g.requested, g.scored, g.rejected, g.pending, g.failed),
        (5, 1, 4, 0, 0)
    );
    assert_eq!(g.mean, Some(8.0));
    assert_eq!(g.criteria["object_visibility"].rejects, 1);
    assert_eq!(g.criteria["layout_coherence"].rejects, 2);
    assert_eq!(g.criteria["layout_coherence"].mean, Some(6.0));
    assert_eq!(g.criteria["consistency_with_task"].count, 1);
    let page = std::fs::read_to_string(dir.join("index.html")).expect("page");
    assert!(page.contains("<th>GPT score</th>"), "{page}");
    assert!(page.contains("8.0 (8/6/7/10/9)"), "{page}");
    ok(&[
        "validate",
        dir.join("metrics.json").to_str().expect("utf-8"),
    ]);
    ok(&[
        "validate",
        "--kind",
        "eval-sample",
        dir.join("samples.jsonl").to_str().expect("utf-8"),
    ]);

    // A rerun at 3 jobs sends nothing and writes the same bytes.
    let before: Vec<Vec<u8>> = ["metrics.json", "samples.jsonl", "index.html"]
        .iter()
        .map(|f| std::fs::read(dir.join(f)).expect("read"))
        .collect();
    let (success, stdout2, stderr2) = eval_gpt(
        data,
        &file,
        "gpt_live",
        &["--gpt-score", "--config", c, "--jobs", "3"],
    );
    assert!(success, "{stderr2}");
    assert_eq!(server.requests(), 5, "zero requests the second time");
    assert!(
        stderr2.contains("judge-live: 0 requests, 5 cache hits"),
        "{stderr2}"
    );
    for (f, bytes) in ["metrics.json", "samples.jsonl", "index.html"]
        .iter()
        .zip(&before)
    {
        assert!(&std::fs::read(dir.join(f)).expect("read") == bytes, "{f}");
    }

    // Control: another template (a config key) is another request, with its own text, so the
    // counts above could have failed.
    let prompt = data.with_file_name("gpt_prompt_edited.txt");
    std::fs::write(
        &prompt,
        mesa_stages::eval::gpt_score::GPT_SCORE_PROMPT.replace(
            "Score the scene on each criterion",
            "EDITED: score the scene",
        ),
    )
    .expect("prompt");
    let edited_config = gpt_config(
        data,
        "gpt_live_edited",
        &server.base_url,
        "judge-live",
        &format!("gpt_score_prompt = \"{}\"\n", prompt.display()),
    );
    let (success, _, stderr3) = eval_gpt(
        data,
        &file,
        "gpt_live_edited",
        &[
            "--gpt-score",
            "--config",
            edited_config.to_str().expect("utf-8"),
        ],
    );
    assert!(success, "{stderr3}");
    assert_eq!(server.requests(), 10, "{stderr3}");
    assert!(server.received()[5..]
        .iter()
        .all(|r| user_text(&r.json()).contains("EDITED: score the scene")));

    // The key is in no output and no file.
    for text in [&stdout, &stderr, &stdout2, &stderr2, &stderr3] {
        assert!(!text.contains(GPT_KEY));
    }
    for (path, bytes) in common::all_files(data) {
        assert!(
            !bytes
                .windows(GPT_KEY.len())
                .any(|w| w == GPT_KEY.as_bytes()),
            "{path} holds the key"
        );
    }
    // Control: the search finds the key where it is.
    std::fs::write(data.join("eval/key_probe.txt"), GPT_KEY).expect("probe");
    assert!(common::all_files(data)
        .values()
        .any(|b| b.windows(GPT_KEY.len()).any(|w| w == GPT_KEY.as_bytes())));
    std::fs::remove_file(data.join("eval/key_probe.txt")).expect("remove the probe");
}

#[test]
fn gpt_score_batches_hold_one_request_per_successful_sample() {
    let data = dataset();
    let (mut outputs, _) = first_references(data, 4);
    // Sample 3 fails (no marker): no request for it.
    outputs[3].1 = outputs[3].1.replace(FINAL_ANSWER_MARKER, "\nThe layout:\n");
    let file = data.join("gpt_batch.jsonl");
    write_outputs(&file, &outputs);
    // A server that must not be asked.
    let server = MockServer::start(|_, _| Reply::error(500, "batch mode sends nothing"));
    let config = gpt_config(data, "gpt_batch", &server.base_url, "judge-batch", "");
    let c = config.to_str().expect("utf-8");
    let batch = data.with_file_name("gpt_batch_requests.jsonl");
    let b = batch.to_str().expect("utf-8");

    let (success, _, stderr) =
        eval_gpt(data, &file, "gpt_batch", &["--config", c, "--batch-out", b]);
    assert!(success, "{stderr}");
    let lines: Vec<Value> = std::fs::read_to_string(&batch)
        .expect("the batch file")
        .lines()
        .map(|l| serde_json::from_str(l).expect("a batch line"))
        .collect();
    assert_eq!(lines.len(), 3, "one request per successful sample");
    let ids: std::collections::BTreeSet<&str> = lines
        .iter()
        .map(|l| l["custom_id"].as_str().expect("custom_id"))
        .collect();
    assert_eq!(ids.len(), 3);
    for line in &lines {
        assert_eq!(line["url"], "/v1/chat/completions");
        let parts = line["body"]["messages"][1]["content"]
            .as_array()
            .expect("parts");
        assert_eq!(parts.len(), 3, "the text and two images");
    }
    let dir = data.join("eval/gpt_batch");
    let samples_of = || -> Vec<EvalSample> {
        std::fs::read_to_string(dir.join("samples.jsonl"))
            .expect("samples")
            .lines()
            .map(|l| serde_json::from_str(l).expect("sample"))
            .collect()
    };
    let samples = samples_of();
    for id in ["0", "1", "2"] {
        assert_eq!(gpt_of(&samples, id).status, "pending");
    }
    assert!(samples[3].gpt_score.is_none(), "the failed sample");
    let m: EvalMetrics = read(&dir.join("metrics.json"));
    assert_eq!(m.gpt_score.as_ref().map(|g| g.pending), Some(3));

    // The provider's output, in another order: two good replies and one error line.
    let line_of = |l: &Value, good: bool| {
        let line = if good {
            json!({"custom_id": l["custom_id"], "response": {"status_code": 200,
                "body": common::completion_body(GOOD_SCORES)}, "error": null})
        } else {
            json!({"custom_id": l["custom_id"], "response": null,
                "error": {"code": "server_error", "message": "try again"}})
        };
        format!("{line}\n")
    };
    let output: String = lines
        .iter()
        .rev()
        .enumerate()
        .map(|(i, l)| line_of(l, i != 0))
        .collect();
    let results = data.with_file_name("gpt_batch_results.jsonl");
    std::fs::write(&results, output).expect("results");
    std::fs::remove_file(&batch).expect("remove the batch file");
    let batch_in = |results: &Path| {
        mesa()
            .arg("eval")
            .arg(data)
            .arg("--outputs")
            .arg(&file)
            .args(["--name", "gpt_batch", "--config", c, "--batch-in"])
            .arg(results)
            .args(["--batch-out", b])
            .output()
            .expect("runs")
    };
    let out = batch_in(&results);
    let stderr = String::from_utf8_lossy(&out.stderr);
    // The error line is reported and exits with 1; its request goes into the next batch.
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("2 replies stored"), "{stderr}");
    assert!(stderr.contains("server_error: try again"), "{stderr}");
    let again: Vec<Value> = std::fs::read_to_string(&batch)
        .expect("the next batch")
        .lines()
        .map(|l| serde_json::from_str(l).expect("a batch line"))
        .collect();
    assert_eq!(again.len(), 1, "only the request whose line failed");
    let last = lines.last().expect("a line");
    assert_eq!(again[0]["custom_id"], last["custom_id"]);
    let samples = samples_of();
    let statuses: Vec<String> = ["0", "1", "2"]
        .iter()
        .map(|id| gpt_of(&samples, id).status)
        .collect();
    assert_eq!(
        statuses.iter().filter(|s| s.as_str() == "scored").count(),
        2,
        "{statuses:?}"
    );
    assert_eq!(
        statuses.iter().filter(|s| s.as_str() == "pending").count(),
        1,
        "{statuses:?}"
    );

    // The provider's answer to the retried request: every sample is scored, nothing pends.
    std::fs::write(&results, line_of(last, true)).expect("results");
    std::fs::remove_file(&batch).expect("remove the batch file");
    let out = batch_in(&results);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("1 replies stored"), "{stderr}");
    assert!(!batch.exists(), "nothing pending, no batch file: {stderr}");
    let samples = samples_of();
    for id in ["0", "1", "2"] {
        let g = gpt_of(&samples, id);
        assert_eq!((g.status.as_str(), g.mean), ("scored", Some(8.0)), "{g:?}");
    }
    let m: EvalMetrics = read(&dir.join("metrics.json"));
    let g = m.gpt_score.expect("gpt_score");
    assert_eq!((g.scored, g.pending, g.mean), (3, 0, Some(8.0)));
    assert_eq!(server.requests(), 0, "batch mode sends nothing");
}

#[test]
fn the_gpt_score_without_a_judge_or_key_is_refused_naming_the_key() {
    let data = dataset();
    let (outputs, _) = first_references(data, 1);
    let file = data.join("gpt_refused.jsonl");
    write_outputs(&file, &outputs);
    // The dataset's own mesa.toml has no [eval] judge.
    let out = mesa()
        .args(["eval", data.to_str().expect("utf-8"), "--outputs"])
        .arg(&file)
        .args(["--name", "gpt_refused", "--gpt-score"])
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("[eval] judge"), "{stderr}");
    assert!(
        !data.join("eval/gpt_refused").exists(),
        "refused before any work"
    );
    // With a judge but without its key (live mode).
    let config = gpt_config(
        data,
        "gpt_nokey",
        "http://127.0.0.1:9/v1",
        "judge-nokey",
        "",
    );
    let out = mesa()
        .args(["eval", data.to_str().expect("utf-8"), "--outputs"])
        .arg(&file)
        .args(["--name", "gpt_refused", "--gpt-score", "--config"])
        .arg(&config)
        .env_remove(GPT_KEY_VAR)
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains(&format!("{GPT_KEY_VAR} (named by [eval.llm] api_key_env)")),
        "{stderr}"
    );
    assert!(
        !data.join("eval/gpt_refused").exists(),
        "refused before any work"
    );
    // A template with an unknown placeholder, named with the key.
    let prompt = data.with_file_name("gpt_prompt_typo.txt");
    std::fs::write(&prompt, "[user]\nScore {{task}} with {{objekts}}\n").expect("prompt");
    let typo = gpt_config(
        data,
        "gpt_typo",
        "http://127.0.0.1:9/v1",
        "judge-typo",
        &format!("gpt_score_prompt = \"{}\"\n", prompt.display()),
    );
    let out = mesa()
        .args(["eval", data.to_str().expect("utf-8"), "--outputs"])
        .arg(&file)
        .args(["--name", "gpt_refused", "--gpt-score", "--config"])
        .arg(&typo)
        .env(GPT_KEY_VAR, GPT_KEY)
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("[eval] gpt_score_prompt") && stderr.contains("{{objekts}}"),
        "{stderr}"
    );
    assert!(
        !data.join("eval/gpt_refused").exists(),
        "refused before any work"
    );
    // Control: without --gpt-score the same command runs.
    let out = mesa()
        .args(["eval", data.to_str().expect("utf-8"), "--outputs"])
        .arg(&file)
        .args(["--name", "gpt_refused", "--config"])
        .arg(&config)
        .env_remove(GPT_KEY_VAR)
        .output()
        .expect("runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let m: EvalMetrics = read(&data.join("eval/gpt_refused/metrics.json"));
    assert!(m.gpt_score.is_none());
}
