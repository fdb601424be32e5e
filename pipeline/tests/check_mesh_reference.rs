//! `mesa check` against an independent reference on the placed triangle meshes
//! (`scripts/mesh_reference.py`: FCL on the meshes' BVHs, winding numbers for containment,
//! rays for falls; it never sees mesa's convex parts).
//!
//! Two demo datasets of 12 scenes (seeds 7 and 8) go through lift, retrieve, place, pack, the
//! simulated annotator and ingest; each scene is checked four times: the coarse layout, the
//! refined one, and both after `--settle`. Each of these layouts is written as a scene GLB by
//! `mesa pack`'s writer (node per instance; its placement is the one Blender and MesaTask's
//! reconstruction read back exactly), and the reference computes on it:
//! - every pair whose meshes overlap, with a bracket [lo, hi] of its penetration depth;
//! - every object's fall straight down onto the table or another mesh.
//!
//! Agreement (tolerance t = 2 mm, slack s = 1 mm), as issue #16 defines it:
//! - a pair with lo > t + s must be reported by `check`; a pair `check` reports at depth d
//!   must have hi > t − s and lo − s ≤ d ≤ hi + s;
//! - an object whose mesh could fall more than t + s must be reported floating; an object
//!   reported floating by g must have a reference fall within s of g.
//!
//! A second test makes the 12 refined layouts of seed 9 untidy twice (objects nudged,
//! turned, tilted, stood on others, sunk into or raised above them around the tolerance):
//! the near-tolerance contacts and stacks that hand-edited and generated scenes have and the
//! demo's do not.
//!
//! Asserted: every layout, coarse, refined, settled and untidy, agrees with the meshes (0
//! disagreements). Objects whose parts reach past their meshes at the layout's scale (a pencil
//! ×21), deep pairs of many parts and steep supports are judged on the meshes by `check`
//! itself (`stages/src/check/solid.rs`); before that, coarse layouts had 21 disagreements.
//!
//! The reference needs Python with trimesh, python-fcl, rtree and scipy (`.venv-tools`,
//! installed by scripts/test.sh); without it the test says SKIPPED, and fails instead when
//! `MESA_REQUIRE_TOOLS` is set, as in CI.

mod common;

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Stdio;

use common::{copy_tree, dataset_shapes, mesa, read_json, scene_dirs};
use std::sync::Arc;

use mesa_schemas::artifacts::{AssetIndexArtifact, CheckArtifact, CheckFindings};
use mesa_schemas::json::to_sorted_pretty;
use mesa_schemas::DatasetLayout;
use mesa_stages::check::{AssetShape, PhysicsScene};
use mesa_stages::mesh::{quat_from_axis_angle, quat_mul, quat_normalize};
use mesa_stages::pack::{pack_scene, AssetSource, PackConfig, PackRequest};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::Value;

const TOLERANCE_MM: f64 = 2.0;
const SLACK_MM: f64 = 1.0;

fn ok(args: &[&str], dir: &Path) {
    let out = mesa().args(args).arg(dir).output().expect("runs");
    assert!(
        out.status.success(),
        "mesa {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The Python of the reference, or None (after saying SKIPPED) when it is missing.
fn reference_python() -> Option<PathBuf> {
    let required = std::env::var_os("MESA_REQUIRE_TOOLS").is_some();
    let python = std::env::var_os("MESA_PYTHON").map(PathBuf::from);
    let usable = python.as_ref().is_some_and(|p| {
        std::process::Command::new(p)
            .args(["-c", "import trimesh, fcl, rtree, scipy"])
            .output()
            .is_ok_and(|o| o.status.success())
    });
    if usable {
        return python;
    }
    assert!(
        !required,
        "the mesh reference needs MESA_PYTHON with trimesh, python-fcl, rtree and scipy \
         (scripts/test.sh installs them) and MESA_REQUIRE_TOOLS is set"
    );
    eprintln!(
        "SKIPPED: the exact-mesh reference of mesa check (set MESA_PYTHON to a Python with \
         trimesh, python-fcl, rtree and scipy; scripts/test.sh does)"
    );
    None
}

/// One checked layout of a scene: what `check` found, and the layout itself.
struct Checked {
    /// `seed<S>/<scene_id>/<coarse|refined>[-settled]`.
    key: String,
    layout: DatasetLayout,
    findings: CheckFindings,
}

fn findings_of(report: &CheckArtifact) -> CheckFindings {
    CheckFindings {
        collisions: report.collisions.clone(),
        floating: report.floating.clone(),
        zone_violations: report.zone_violations.clone(),
        pairs_total: report.pairs_total,
        collision_rate: report.collision_rate,
        mesatask_rule_pairs: report.mesatask_rule_pairs,
        clean: report.clean,
    }
}

/// The scene id of a scene folder (its name).
fn scene_name(scene: &Path) -> String {
    scene
        .file_name()
        .expect("a scene folder")
        .to_string_lossy()
        .into_owned()
}

/// Runs the demo of `seed` (12 scenes) up to ingest, in `root/seed<seed>`.
fn ingested_demo(root: &Path, seed: u64) -> PathBuf {
    let dir = root.join(format!("seed{seed}"));
    mesa()
        .args(["demo", "--scenes", "12", "--seed", &seed.to_string(), "-q"])
        .arg(&dir)
        .assert()
        .success();
    for stage in ["assets", "lift", "retrieve", "place", "pack"] {
        ok(&[stage, "--progress", "off"], &dir);
    }
    ok(&["demo", "annotate"], &dir);
    ok(&["ingest", "--progress", "off"], &dir);
    dir
}

/// Runs the demo of `seed` up to ingest, then check and settle on coarse and refined layouts.
fn checked_layouts(root: &Path, seed: u64) -> (PathBuf, Vec<Checked>) {
    let dir = ingested_demo(root, seed);
    let mut out = Vec::new();
    for source in ["coarse", "refined"] {
        ok(
            &["check", "--layout", source, "--settle", "--progress", "off"],
            &dir,
        );
        for scene in scene_dirs(&dir) {
            let name = scene_name(&scene);
            let report_path = scene.join("qa/check.json");
            if !report_path.is_file() {
                continue;
            }
            let report: CheckArtifact = read_json(&report_path);
            let layout: DatasetLayout = read_json(&scene.join(format!("{source}/layout.json")));
            out.push(Checked {
                key: format!("seed{seed}/{name}/{source}"),
                layout,
                findings: findings_of(&report),
            });
            let settle = report.settle.as_ref().expect("a settle report");
            if let Some(file) = &settle.layout {
                out.push(Checked {
                    key: format!("seed{seed}/{name}/{source}-settled"),
                    layout: read_json(&scene.join(file)),
                    findings: settle.after.clone(),
                });
            }
        }
    }
    (dir, out)
}

/// The layout as a scene GLB, written by the pack's writer.
fn scene_glb(dataset: &Path, index: &AssetIndexArtifact, layout: &DatasetLayout, path: &Path) {
    let mut bytes: BTreeMap<String, (Vec<u8>, f64)> = BTreeMap::new();
    for object in &layout.objects {
        let record = &index.assets[&object.retrieved_uid];
        let glb = std::fs::read(dataset.join(&record.file)).expect("asset");
        let yaw = record.geometry.as_ref().map_or(0.0, |g| g.front_yaw_deg);
        bytes.insert(object.retrieved_uid.clone(), (glb, yaw));
    }
    let assets: BTreeMap<String, AssetSource<'_>> = bytes
        .iter()
        .map(|(uid, (glb, yaw))| {
            (
                uid.clone(),
                AssetSource {
                    glb,
                    front_yaw_deg: *yaw,
                },
            )
        })
        .collect();
    let layout_bytes = serde_json::to_vec(layout).expect("json");
    let out = pack_scene(
        &PackRequest {
            scene_id: "scene",
            table_type: "office_table",
            layout,
            layout_rel: "layout.json",
            layout_bytes: &layout_bytes,
            assets: &assets,
            photo: None,
            masks: &BTreeMap::new(),
        },
        &PackConfig::default(),
    )
    .expect("packs");
    std::fs::write(path, &out.files["scene.glb"]).expect("write");
}

/// A drop-test scene: every object's convex parts placed by the layout.
fn drop_scene(
    key: &str,
    layout: &DatasetLayout,
    shapes: &BTreeMap<String, Arc<AssetShape>>,
) -> Value {
    let placed = PhysicsScene::from_layout(layout, |o| {
        shapes
            .get(&o.retrieved_uid)
            .cloned()
            .ok_or_else(|| "no shape".to_owned())
    });
    let objects: Vec<Value> = placed
        .objects
        .iter()
        .filter_map(|o| {
            let body = o.body.as_ref().ok()?;
            let parts: Vec<Vec<[f64; 3]>> = body.hulls.iter().map(|h| h.points()).collect();
            Some(serde_json::json!({"name": o.instance, "parts": parts}))
        })
        .collect();
    serde_json::json!({"key": key, "table": placed.zone_m, "objects": objects})
}

/// Runs a Python script on jobs split in two halves (two processes).
fn run_split(
    python: &Path,
    script: &str,
    jobs: Vec<Value>,
    extra: Value,
) -> BTreeMap<String, Value> {
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../scripts")
        .join(script);
    let half = jobs.len().div_ceil(2);
    let children: Vec<_> = jobs
        .chunks(half.max(1))
        .map(|chunk| {
            let mut child = std::process::Command::new(python)
                .arg(&script)
                .stdin(Stdio::piped())
                .stdout(Stdio::piped())
                .stderr(Stdio::piped())
                .spawn()
                .expect("python starts");
            let mut job = extra.clone();
            job["scenes"] = Value::from(chunk.to_vec());
            child
                .stdin
                .take()
                .expect("well-formed")
                .write_all(&serde_json::to_vec(&job).expect("well-formed"))
                .expect("well-formed");
            child
        })
        .collect();
    let mut out = BTreeMap::new();
    for child in children {
        let result = child.wait_with_output().expect("python runs");
        assert!(
            result.status.success(),
            "{}: {}",
            script.display(),
            String::from_utf8_lossy(&result.stderr)
        );
        let map: BTreeMap<String, Value> = serde_json::from_slice(&result.stdout).expect("json");
        out.extend(map);
    }
    out
}

/// The disagreements of one checked layout with the reference, one line each.
fn disagreements(checked: &Checked, reference: &Value) -> Vec<String> {
    let (t, s) = (TOLERANCE_MM, SLACK_MM);
    let mut out = Vec::new();
    let pairs: BTreeMap<(String, String), (f64, f64)> = reference["pairs"]
        .as_array()
        .expect("well-formed")
        .iter()
        .map(|p| {
            let (a, b) = (
                p["a"].as_str().expect("well-formed"),
                p["b"].as_str().expect("well-formed"),
            );
            let key = if a <= b { (a, b) } else { (b, a) };
            (
                (key.0.to_owned(), key.1.to_owned()),
                (
                    p["lo_mm"].as_f64().expect("well-formed"),
                    p["hi_mm"].as_f64().expect("well-formed"),
                ),
            )
        })
        .collect();
    let reported: BTreeMap<(String, String), f64> = checked
        .findings
        .collisions
        .iter()
        .map(|c| ((c.a.clone(), c.b.clone()), c.depth_mm))
        .collect();
    for (pair, (lo, hi)) in &pairs {
        if *lo > t + s && !reported.contains_key(pair) {
            out.push(format!(
                "{}: {} / {} collide on the meshes ({lo:.2}–{hi:.2} mm), check reports nothing",
                checked.key, pair.0, pair.1
            ));
        }
    }
    for (pair, depth) in &reported {
        let (lo, hi) = pairs.get(pair).copied().unwrap_or((0.0, 0.0));
        if hi <= t - s || *depth < lo - s || *depth > hi + s {
            out.push(format!(
                "{}: {} / {}: check says {depth:.2} mm, the meshes {lo:.2}–{hi:.2} mm",
                checked.key, pair.0, pair.1
            ));
        }
    }
    let gaps = reference["gaps_mm"].as_object().expect("well-formed");
    let floating: BTreeMap<&str, f64> = checked
        .findings
        .floating
        .iter()
        .map(|f| (f.instance.as_str(), f.gap_mm))
        .collect();
    for (instance, gap) in gaps {
        let gap = gap.as_f64().expect("well-formed");
        match floating.get(instance.as_str()) {
            None if gap > t + s => out.push(format!(
                "{}: {instance} could fall {gap:.2} mm on the meshes, check says it rests",
                checked.key
            )),
            Some(g) if (g - gap).abs() > s => out.push(format!(
                "{}: {instance} floats {g:.2} mm by check, {gap:.2} mm on the meshes",
                checked.key
            )),
            _ => {}
        }
    }
    out
}

/// Writes every checked layout of `datasets` as a scene GLB under `glbs`, runs the mesh
/// reference on them and returns the disagreements, one line each (after printing them, with
/// the counts).
fn compare_with_meshes(
    python: &Path,
    glbs: &Path,
    datasets: &[(PathBuf, Vec<Checked>)],
) -> Vec<String> {
    std::fs::create_dir_all(glbs).expect("well-formed");
    let mut jobs = Vec::new();
    for (dir, checked) in datasets {
        let index: AssetIndexArtifact = read_json(&dir.join("assets/index/assets.json"));
        for c in checked {
            let path = glbs.join(format!("{}.glb", c.key.replace('/', "_")));
            scene_glb(dir, &index, &c.layout, &path);
            jobs.push(serde_json::json!({
                "key": c.key,
                "glb": path,
                "instances": c.layout.objects.iter().map(|o| &o.instance).collect::<Vec<_>>(),
            }));
        }
    }
    let started = std::time::Instant::now();
    let references = run_split(
        python,
        "mesh_reference.py",
        jobs,
        serde_json::json!({"tolerance_mm": TOLERANCE_MM}),
    );
    println!(
        "the mesh reference: {:.0} s",
        started.elapsed().as_secs_f64()
    );
    let mut problems = Vec::new();
    let (mut layouts, mut pairs, mut reported, mut floating, mut objects) = (0, 0, 0, 0, 0);
    for c in datasets.iter().flat_map(|(_, checked)| checked) {
        let r = &references[&c.key];
        layouts += 1;
        pairs += r["pairs"]
            .as_array()
            .expect("well-formed")
            .iter()
            .filter(|p| p["lo_mm"].as_f64().expect("well-formed") > TOLERANCE_MM)
            .count();
        reported += c.findings.collisions.len();
        floating += c.findings.floating.len();
        objects += c.layout.objects.len();
        problems.extend(disagreements(c, r));
    }
    println!(
        "{layouts} checked layouts, {objects} objects: {pairs} pairs deeper than {TOLERANCE_MM} \
         mm on the meshes, {reported} reported by check, {floating} objects floating by check; \
         {} disagreements",
        problems.len(),
    );
    for p in &problems {
        println!("  {p}");
    }
    problems
}

#[test]
fn check_agrees_with_the_meshes_on_demo_scenes() {
    let Some(python) = reference_python() else {
        return;
    };
    let tmp = tempfile::tempdir().expect("tempdir");
    let started = std::time::Instant::now();
    let root = tmp.path();
    let datasets: Vec<(PathBuf, Vec<Checked>)> = std::thread::scope(|s| {
        let runs: Vec<_> = [7, 8]
            .map(|seed| s.spawn(move || checked_layouts(root, seed)))
            .into_iter()
            .collect();
        runs.into_iter().map(|r| r.join().expect("seed")).collect()
    });
    println!(
        "mesa demo → ingest, check and settle: {:.0} s",
        started.elapsed().as_secs_f64()
    );
    let mut drops = Vec::new();
    for (dir, checked) in &datasets {
        let shapes = dataset_shapes(dir);
        for c in checked {
            // MuJoCo takes about 10 s a layout on 2 cores: the drop test runs on one scene
            // per table type of seed 8, as its coarse layout (the control) and its settled
            // refined layout.
            if c.key.starts_with("seed8/")
                && c.key.contains("_0001/")
                && (c.key.ends_with("/coarse") || c.key.ends_with("/refined-settled"))
            {
                drops.push(drop_scene(&c.key, &c.layout, &shapes));
            }
        }
    }
    let layouts: usize = datasets.iter().map(|(_, checked)| checked.len()).sum();
    let problems = compare_with_meshes(&python, &tmp.path().join("glbs"), &datasets);
    assert!(
        layouts >= 90,
        "{layouts} layouts (coarse, refined, and settled ones)"
    );
    assert!(problems.is_empty(), "{} disagreements", problems.len());

    // The drop test is opt-in until its time is bounded: on coarse layouts with deep overlaps
    // MuJoCo took minutes a layout on 2 loaded cores.
    if std::env::var_os("MESA_DROP_TEST").is_none() {
        eprintln!("SKIPPED: the MuJoCo drop test (set MESA_DROP_TEST=1 to run it)");
    } else if mujoco_python(&python) {
        drop_test(&python, drops);
    }
}

/// Turns `q` by `angle_deg` about `axis` (table frame) after it.
fn turned(q: [f64; 4], axis: [f64; 3], angle_deg: f64) -> [f64; 4] {
    quat_normalize(quat_mul(
        quat_from_axis_angle(axis, angle_deg.to_radians()),
        q,
    ))
}

/// A layout made untidy from `layout`, as a careless annotator or a model leaves one: every
/// object nudged by up to 3 cm across and 4 mm up or down and turned by up to 25°, some
/// tilted by up to 40°, and a few stood on others, sunk into them or raised above them by
/// -10 to +30 mm (around `check`'s 2 mm tolerance).
fn untidy(layout: &DatasetLayout, rng: &mut ChaCha8Rng) -> DatasetLayout {
    let mut layout = layout.clone();
    for o in &mut layout.objects {
        let mut q = o.rotation.0;
        if rng.random_bool(0.5) {
            o.position_cm.0[0] += rng.random_range(-3.0..3.0);
            o.position_cm.0[1] += rng.random_range(-3.0..3.0);
            o.position_cm.0[2] += rng.random_range(-0.4..0.4);
            q = turned(q, [0.0, 0.0, 1.0], rng.random_range(-25.0..25.0));
        }
        if rng.random_bool(0.15) {
            let axis = if rng.random_bool(0.5) {
                [1.0, 0.0, 0.0]
            } else {
                [0.0, 1.0, 0.0]
            };
            q = turned(q, axis, rng.random_range(5.0..40.0));
        }
        o.rotation.0 = q;
        // The rotation is no longer a pure yaw in general.
        o.z_rotation_deg = None;
    }
    let n = layout.objects.len();
    for _ in 0..n.min(3) {
        let (a, b) = (rng.random_range(0..n), rng.random_range(0..n));
        if a == b {
            continue;
        }
        let below = layout.objects[b].clone();
        let gap_mm = [-10.0, -3.5, -2.5, -1.5, 0.0, 1.5, 2.5, 3.5, 30.0][rng.random_range(0..9)];
        let reach = below.size_cm.0[0].min(below.size_cm.0[1]) * 0.3;
        let above = &mut layout.objects[a];
        above.position_cm.0 = [
            below.position_cm.0[0] + rng.random_range(-reach..=reach),
            below.position_cm.0[1] + rng.random_range(-reach..=reach),
            below.position_cm.0[2]
                + below.size_cm.0[2] / 2.0
                + above.size_cm.0[2] / 2.0
                + gap_mm / 10.0,
        ];
    }
    layout
}

/// `check` against the meshes on untidy layouts: the demo's refined layouts of seed 9, each
/// made untidy twice ([`untidy`]), checked as the dataset's refined layouts. The demo's own
/// layouts come from a renderer, a lift and an annotator who all keep objects tidy; these have
/// the near-tolerance contacts, stacks and tilts that hand-edited and generated scenes have.
#[test]
fn check_agrees_with_the_meshes_on_untidy_layouts() {
    let Some(python) = reference_python() else {
        return;
    };
    let tmp = tempfile::tempdir().expect("tempdir");
    let demo = ingested_demo(tmp.path(), 9);
    let mut rng = ChaCha8Rng::seed_from_u64(0x756e_7469_6479);
    let mut datasets = Vec::new();
    for round in 0..2 {
        // A copy of the dataset per round, its refined layouts replaced by untidy ones.
        let dir = tmp.path().join(format!("untidy{round}"));
        copy_tree(&demo, &dir);
        for scene in scene_dirs(&dir) {
            let path = scene.join("refined/layout.json");
            let layout: DatasetLayout = read_json(&path);
            let layout = untidy(&layout, &mut rng);
            std::fs::write(&path, to_sorted_pretty(&layout).expect("json")).expect("write");
        }
        ok(&["check", "--layout", "refined", "--progress", "off"], &dir);
        let mut checked = Vec::new();
        for scene in scene_dirs(&dir) {
            let name = scene_name(&scene);
            let report: CheckArtifact = read_json(&scene.join("qa/check.json"));
            checked.push(Checked {
                key: format!("untidy{round}/{name}"),
                layout: read_json(&scene.join("refined/layout.json")),
                findings: findings_of(&report),
            });
        }
        datasets.push((dir, checked));
    }
    let problems = compare_with_meshes(&python, &tmp.path().join("glbs"), &datasets);
    let reported: usize = datasets
        .iter()
        .flat_map(|(_, checked)| checked)
        .map(|c| c.findings.collisions.len() + c.findings.floating.len())
        .sum();
    // The layouts are untidy enough that check has something to say about them.
    assert!(
        reported >= 24,
        "only {reported} findings on 24 untidy layouts"
    );
    assert!(problems.is_empty(), "{} disagreements", problems.len());
}

/// Whether the reference's Python has MuJoCo (SKIPPED, or a failure under
/// `MESA_REQUIRE_TOOLS`, without it).
fn mujoco_python(python: &Path) -> bool {
    let has = std::process::Command::new(python)
        .args(["-c", "import mujoco"])
        .output()
        .is_ok_and(|o| o.status.success());
    assert!(
        has || std::env::var_os("MESA_REQUIRE_TOOLS").is_none(),
        "the drop test needs mujoco in MESA_PYTHON (scripts/test.sh installs it) and \
         MESA_REQUIRE_TOOLS is set"
    );
    if !has {
        eprintln!("SKIPPED: the MuJoCo drop test (no mujoco in MESA_PYTHON)");
    }
    has
}

/// The MuJoCo drop test of 2 s on every layout: per layout kind, the share of objects that
/// move less than 1 cm, and those that fall off the table; per scene for the settled ones.
fn drop_test(python: &Path, drops: Vec<Value>) {
    let started = std::time::Instant::now();
    let results = run_split(
        python,
        "mujoco_drop.py",
        drops,
        serde_json::json!({"seconds": 2.0, "density": 500.0}),
    );
    println!(
        "the MuJoCo drop test: {:.0} s",
        started.elapsed().as_secs_f64()
    );
    let mut by_kind: BTreeMap<String, (usize, usize, usize)> = BTreeMap::new();
    println!("scene | layout | objects | moved > 1 cm | fell off | worst (cm)");
    for (key, objects) in &results {
        let kind = key.rsplit('/').next().unwrap_or("").to_owned();
        let objects = objects.as_object().expect("well-formed");
        let moved: Vec<(&String, f64)> = objects
            .iter()
            .map(|(n, o)| (n, o["moved_cm"].as_f64().expect("well-formed")))
            .filter(|(_, m)| *m >= 1.0)
            .collect();
        let fell = objects
            .values()
            .filter(|o| o["fell"].as_bool().expect("well-formed"))
            .count();
        let entry = by_kind.entry(kind.clone()).or_default();
        entry.0 += objects.len();
        entry.1 += moved.len();
        entry.2 += fell;
        let worst = objects
            .values()
            .map(|o| o["moved_cm"].as_f64().expect("well-formed"))
            .fold(0.0, f64::max);
        println!(
            "{key} | {} | {} | {fell} | {worst:.2}",
            objects.len(),
            moved.len()
        );
    }
    for (kind, (objects, moved, fell)) in &by_kind {
        println!(
            "{kind}: {objects} objects, {moved} moved more than 1 cm in 2 s ({:.1} % still), \
             {fell} fell off the table",
            100.0 * (objects - moved) as f64 / *objects as f64
        );
    }
    // The control: coarse layouts, before settling, fail the test a settled scene must pass.
    let (objects, moved, fell) = by_kind["coarse"];
    assert!(
        moved as f64 > 0.01 * objects as f64 || fell > 0,
        "coarse layouts pass the drop test: {moved} of {objects} moved"
    );
}

/// The comparison itself can fail: a depth off the bracket, a missed pair, a missed fall and a
/// wrong gap are each one disagreement (the control of the test above).
#[test]
fn the_comparison_finds_each_kind_of_disagreement() {
    use mesa_schemas::artifacts::{CollisionPair, FloatingObject};
    let layout: DatasetLayout = serde_json::from_value(serde_json::json!({
        "item_placement_zone": [0, 100, 0, 60],
        "objects": []
    }))
    .expect("a layout");
    let findings = |collisions: Vec<CollisionPair>, floating: Vec<FloatingObject>| CheckFindings {
        collisions,
        floating,
        zone_violations: Vec::new(),
        pairs_total: 3,
        collision_rate: 0.0,
        mesatask_rule_pairs: 0,
        clean: false,
    };
    let reference = serde_json::json!({
        "pairs": [
            {"a": "a", "b": "b", "lo_mm": 5.0, "hi_mm": 6.0},
            {"a": "a", "b": "c", "lo_mm": 4.0, "hi_mm": 4.5},
        ],
        "gaps_mm": {"a": 0.0, "b": 8.0, "c": 3.5},
    });
    let pair = |a: &str, b: &str, depth_mm: f64| CollisionPair {
        a: a.to_owned(),
        b: b.to_owned(),
        depth_mm,
    };
    let float = |instance: &str, gap_mm: f64| FloatingObject {
        instance: instance.to_owned(),
        gap_mm,
        over: "table".to_owned(),
    };
    let agreeing = Checked {
        key: "agreeing".to_owned(),
        layout: layout.clone(),
        findings: findings(
            vec![pair("a", "b", 5.5), pair("a", "c", 4.2)],
            vec![float("b", 7.8), float("c", 3.4)],
        ),
    };
    assert_eq!(disagreements(&agreeing, &reference), Vec::<String>::new());
    let wrong = Checked {
        key: "wrong".to_owned(),
        layout,
        findings: findings(vec![pair("a", "b", 9.0)], vec![float("b", 5.0)]),
    };
    let found = disagreements(&wrong, &reference);
    assert_eq!(found.len(), 4, "{found:#?}");
}
