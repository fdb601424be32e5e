//! `mesa export` end to end on demo datasets, checked with the real simulator.
//!
//! - With usd-core: every scene's USD opens with the physics schemas applied as stated (and a
//!   file stripped of them is caught).
//! - Without Python: the manifest validates, the bytes are the same when exported again, a
//!   rerun skips, and a bad `[export]` setting is a usage error naming its key.
//! - With PyBullet as well: every URDF set loads (bodies named after the instances, one
//!   collision shape per part) and the same stillness test and control hold.
//! - Textures (issue #17), with MuJoCo, PyBullet, usd-core and trimesh: every visual material
//!   and texture the manifest lists reaches MuJoCo (`ntex`, `nmat`, per geom its material,
//!   its texture and its mesh's texture coordinates), PyBullet (visual shapes and their
//!   textures) and usd-core (each visual mesh's `st` and bound material whose shader graph
//!   reaches the PNG on disk); a deleted PNG is caught by usd-core and MuJoCo (the control).
//!   trimesh, reading both the exported OBJ + MTL + PNG and the source GLBs, gives the same
//!   colour at every vertex and triangle centroid, and the control (the `vt` unflipped) does
//!   not.
//! - The same on real GLBs of ../shared/realdata (Duck, BoxTextured, CesiumMilkTruck with 4
//!   materials, AlphaBlendModeTest's JPEG texture re-encoded as PNG, ShapeCollection without
//!   materials), exported with `--assets`: MuJoCo and PyBullet load each with the manifest's
//!   materials and textures, and trimesh's colours agree (and not with v unflipped).
//! - With MuJoCo (`MESA_PYTHON`, else the repository's `.venv-tools`; SKIPPED without it, a
//!   failure under `MESA_REQUIRE_TOOLS`): every exported MJCF loads with one body per object,
//!   named its instance, and one collision geom per convex part; 2 s of simulation keep the
//!   settled scenes still, while the coarse layouts and a deliberately sunk object move (the
//!   controls); an apple dropped into an exported bowl stays in its cavity, and sits on top
//!   when the bowl is exported as a single convex hull (the control).

mod common;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use common::{mesa, python_with, read_json, scene_dirs, shared};
use mesa_schemas::artifacts::{
    AssetIndexArtifact, CheckArtifact, CheckSummaryArtifact, ExportArtifact, SimulationReport,
};
use serde_json::{json, Value};

fn ok(args: &[&str], dir: &Path) -> String {
    let out = mesa().args(args).arg(dir).output().expect("runs");
    assert!(
        out.status.success(),
        "mesa {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr)
}

/// A demo dataset of `scenes` scenes run through `mesa run`.
fn demo(root: &Path, scenes: u32, seed: u64) -> PathBuf {
    let dir = root.join(format!("seed{seed}"));
    mesa()
        .args([
            "demo",
            "--scenes",
            &scenes.to_string(),
            "--seed",
            &seed.to_string(),
            "-q",
        ])
        .arg(&dir)
        .assert()
        .success();
    ok(&["run", "--progress", "off", "-q"], &dir);
    dir
}

/// The sim/ files of every scene, by path.
fn sim_files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    common::all_files(dir)
        .into_iter()
        .filter(|(k, _)| k.contains("scenes/") && k.contains("/sim/"))
        .collect()
}

#[test]
fn export_writes_valid_deterministic_files_and_skips_when_done() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let dir = tmp.path().join("seed3");
    mesa()
        .args(["demo", "--scenes", "2", "--seed", "3", "-q"])
        .arg(&dir)
        .assert()
        .success();
    for stage in ["assets", "lift", "retrieve", "place"] {
        ok(&[stage, "--progress", "off"], &dir);
    }
    let first = ok(&["export", "--layout", "coarse", "--progress", "off"], &dir);
    assert!(first.contains("export summary: 2 scenes"), "{first}");
    let files = sim_files(&dir);
    assert!(!files.is_empty());
    for scene in scene_dirs(&dir) {
        let manifest = scene.join("sim/export.json");
        mesa()
            .args(["validate", "--kind", "export"])
            .arg(&manifest)
            .assert()
            .success();
        let artifact: ExportArtifact = read_json(&manifest);
        assert_eq!(artifact.formats, ["mjcf", "urdf", "usd"]);
        mesa()
            .args(["validate", "--kind", "urdf-scene"])
            .arg(scene.join("sim/urdf/scene.json"))
            .assert()
            .success();
        for file in &artifact.files {
            assert!(scene.join(file).is_file(), "{file} listed but missing");
        }
        let xml = std::fs::read_to_string(scene.join("sim/mjcf/scene.xml")).expect("xml");
        for object in &artifact.objects {
            assert!(xml.contains(&format!("<body name=\"{}\"", object.instance)));
            assert!(object.mass_kg > 0.0 && object.collision_parts > 0);
        }
    }
    usd_check(&dir);
    assets_check(&dir);
    // A rerun skips; a forced one writes the same bytes.
    let again = ok(&["export", "--layout", "coarse", "--progress", "off"], &dir);
    assert!(again.contains("2 skipped"), "{again}");
    ok(
        &[
            "export",
            "--layout",
            "coarse",
            "--force",
            "--progress",
            "off",
        ],
        &dir,
    );
    assert!(sim_files(&dir) == files, "a forced export changed bytes");

    // `--format` writes only what it names, the same bytes as a full export.
    for scene in scene_dirs(&dir) {
        std::fs::remove_dir_all(scene.join("sim")).expect("removes sim/");
    }
    ok(
        &[
            "export",
            "--layout",
            "coarse",
            "--format",
            "usd,mjcf",
            "--progress",
            "off",
        ],
        &dir,
    );
    let some = sim_files(&dir);
    assert!(!some.is_empty());
    for (rel, bytes) in &some {
        if rel.ends_with("sim/export.json") {
            continue;
        }
        assert!(!rel.contains("/sim/urdf/"), "{rel} written without urdf");
        assert!(
            files.get(rel) == Some(bytes),
            "{rel} differs from the full export"
        );
    }
    for scene in scene_dirs(&dir) {
        let artifact: ExportArtifact = read_json(&scene.join("sim/export.json"));
        assert_eq!(artifact.formats, ["mjcf", "usd"]);
        assert!(scene.join("sim/usd/scene.usda").is_file());
        assert!(!scene.join("sim/urdf").exists());
        for file in &artifact.files {
            assert!(scene.join(file).is_file(), "{file} listed but missing");
        }
    }
    // URDF alone still writes the meshes its files name, not the MJCF scene.
    for scene in scene_dirs(&dir) {
        std::fs::remove_dir_all(scene.join("sim")).expect("removes sim/");
    }
    ok(
        &[
            "export",
            "--layout",
            "coarse",
            "--format",
            "urdf",
            "--progress",
            "off",
        ],
        &dir,
    );
    for scene in scene_dirs(&dir) {
        let artifact: ExportArtifact = read_json(&scene.join("sim/export.json"));
        assert_eq!(artifact.formats, ["urdf"]);
        assert!(!scene.join("sim/mjcf/scene.xml").exists());
        for file in &artifact.files {
            assert!(scene.join(file).is_file(), "{file} listed but missing");
        }
        let urdf = std::fs::read_to_string(scene.join("sim/urdf/table.urdf")).expect("urdf");
        assert!(urdf.contains("<robot"), "{urdf}");
        for entry in std::fs::read_dir(scene.join("sim/urdf")).expect("urdf dir") {
            let text = std::fs::read_to_string(entry.expect("entry").path()).expect("text");
            for mesh in text.split("filename=\"").skip(1) {
                let rel = mesh.split('"').next().expect("a file name");
                assert!(
                    scene.join("sim/urdf").join(rel).is_file(),
                    "{rel} named by a URDF is missing"
                );
            }
        }
    }

    // A bad setting is a usage error that names its key.
    std::fs::write(dir.join("mesa.toml"), "[export]\ndensity_kg_m3 = -1.0\n").expect("toml");
    let out = mesa()
        .args(["export", "--layout", "coarse", "--progress", "off"])
        .arg(&dir)
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("[export] density_kg_m3"));
}

/// Every scene's USD opened with usd-core: the physics schemas as stated, each object's mass
/// and collider count as the manifest says; and the control: a file stripped of a MassAPI and
/// of a convexHull approximation is caught.
fn usd_check(dir: &Path) {
    let Some(python) = python_with("pxr", "the USD check of the export") else {
        return;
    };
    let scenes = scene_dirs(dir);
    for (scene, r) in simulate(&python, "usd", &scenes) {
        assert_eq!(r["loaded"], true, "{scene}: {}", r["error"]);
        assert_eq!(r["problems"], json!([]), "{scene}");
        assert!(
            r["static_colliders"].as_u64() >= Some(1),
            "{scene}: no table"
        );
        let manifest: ExportArtifact = read_json(&Path::new(&scene).join("sim/export.json"));
        let bodies: BTreeSet<&str> = r["bodies"]
            .as_array()
            .expect("bodies")
            .iter()
            .filter_map(Value::as_str)
            .collect();
        let instances: BTreeSet<&str> = manifest
            .objects
            .iter()
            .map(|o| o.instance.as_str())
            .collect();
        assert_eq!(bodies, instances, "{scene}");
        for o in &manifest.objects {
            assert_eq!(
                r["colliders"][&o.instance].as_u64(),
                Some(o.collision_parts),
                "{scene}: {}",
                o.instance
            );
            let mass = r["masses"][&o.instance].as_f64().expect("a mass");
            assert!(
                (mass - o.mass_kg).abs() <= 1e-5 * o.mass_kg,
                "{scene}: {}: mass {mass} in the USD, {} in the manifest",
                o.instance,
                o.mass_kg
            );
        }
        println!(
            "usd | {} | {} rigid bodies with MassAPI, {} convex colliders, {} static",
            Path::new(&scene)
                .file_name()
                .expect("a scene")
                .to_string_lossy(),
            bodies.len(),
            manifest
                .objects
                .iter()
                .map(|o| o.collision_parts)
                .sum::<u64>(),
            r["static_colliders"]
        );
    }
    // The control.
    let scene = &scenes[0];
    let path = scene.join("sim/usd/scene.usda");
    let text = std::fs::read_to_string(&path).expect("usda");
    let broken = text
        .replacen(
            "[\"PhysicsRigidBodyAPI\", \"PhysicsMassAPI\"]",
            "[\"PhysicsRigidBodyAPI\"]",
            1,
        )
        .replacen("= \"convexHull\"", "= \"none\"", 1);
    std::fs::write(&path, broken).expect("writes");
    let results = simulate(&python, "usd", std::slice::from_ref(scene));
    let problems = results.values().next().expect("a scene")["problems"]
        .as_array()
        .expect("problems")
        .len();
    assert_eq!(problems, 2, "the USD check missed a broken file");
    std::fs::write(&path, text).expect("writes");
}

/// `mesa export --assets`: a folder per valid asset with a valid manifest of one object and
/// no table; a rerun finds them current; with MuJoCo, PyBullet and usd-core, each loads.
fn assets_check(dir: &Path) {
    let out = ok(&["export", "--assets", "--progress", "off"], dir);
    let index: AssetIndexArtifact = read_json(&dir.join("assets/index/assets.json"));
    let valid: Vec<&String> = index
        .assets
        .iter()
        .filter(|(_, r)| r.valid)
        .map(|(uid, _)| uid)
        .collect();
    assert!(
        out.contains(&format!("{} assets: {} written", valid.len(), valid.len())),
        "{out}"
    );
    for uid in &valid {
        let manifest = dir.join(format!("assets/sim/{uid}/export.json"));
        mesa()
            .args(["validate", "--kind", "export"])
            .arg(&manifest)
            .assert()
            .success();
        let artifact: ExportArtifact = read_json(&manifest);
        assert_eq!(artifact.objects.len(), 1);
        assert_eq!(artifact.table_size_m, [0.0; 3]);
        for file in &artifact.files {
            assert!(
                dir.join(format!("assets/sim/{uid}/{file}")).is_file(),
                "{file}"
            );
        }
    }
    let again = ok(&["export", "--assets", "--progress", "off"], dir);
    assert!(
        again.contains(&format!("0 written, {} current", valid.len())),
        "{again}"
    );
    let Some(python) = python_with("mujoco, pybullet, pxr", "loading the single-asset export")
    else {
        return;
    };
    let script = "import mujoco, os, sys, pybullet as p\n\
        from pxr import Usd, UsdPhysics\n\
        p.connect(p.DIRECT)\n\
        root = sys.argv[1]\n\
        n = 0\n\
        for uid in sorted(os.listdir(root)):\n\
        \x20   m = mujoco.MjModel.from_xml_path(f'{root}/{uid}/mjcf/scene.xml')\n\
        \x20   assert m.nbody == 2, (uid, m.nbody)\n\
        \x20   p.loadURDF(f'{root}/{uid}/urdf/{uid}.urdf', flags=p.URDF_USE_INERTIA_FROM_FILE)\n\
        \x20   s = Usd.Stage.Open(f'{root}/{uid}/usd/scene.usda')\n\
        \x20   assert sum(x.HasAPI(UsdPhysics.RigidBodyAPI) for x in s.Traverse()) == 1, uid\n\
        \x20   n += 1\n\
        print('assets loaded', n)\n";
    let out = std::process::Command::new(python)
        .args(["-c", script])
        .arg(dir.join("assets/sim"))
        .output()
        .expect("python runs");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && text.contains(&format!("assets loaded {}", valid.len())),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Runs scripts/sim_export.py on the scenes: its JSON by scene folder.
fn simulate(python: &Path, sim: &str, scenes: &[PathBuf]) -> BTreeMap<String, Value> {
    simulate_for(python, sim, "2.0", scenes)
}

/// Runs scripts/sim_export.py on the scenes for `seconds` of simulated time.
fn simulate_for(
    python: &Path,
    sim: &str,
    seconds: &str,
    scenes: &[PathBuf],
) -> BTreeMap<String, Value> {
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scripts/sim_export.py");
    let out = std::process::Command::new(python)
        .arg(script)
        .args([sim, seconds])
        .args(scenes)
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "sim_export.py: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("JSON from sim_export.py")
}

/// What a layout kind's simulation gave.
#[derive(Debug, Default, Clone, Copy)]
struct Stillness {
    objects: usize,
    moved: usize,
    fell: usize,
    /// Objects standing on the table alone (not over another object's footprint).
    free: usize,
    /// Of those, moved ≥ 1 cm.
    free_moved: usize,
    /// The largest motion of an object resting in or on another, cm.
    held_worst_cm: f64,
}

/// The object that holds `instance` in `layout` (its centre lies over the other's footprint,
/// and its bottom lies between the other's bottom and top): fruit in a bowl, a book on a book.
fn holder(layout: &Value, instance: &str) -> Option<String> {
    let objects = layout["objects"].as_array()?;
    let get = |o: &Value, k: &str, i: usize| o[k][i].as_f64().unwrap_or(0.0);
    let me = objects.iter().find(|o| o["instance"] == instance)?;
    let bottom = get(me, "position", 2) - get(me, "size", 2) / 2.0;
    objects
        .iter()
        .filter(|o| o["instance"] != instance)
        .find(|o| {
            let radius = get(o, "size", 0).max(get(o, "size", 1)) / 2.0;
            let dx = get(me, "position", 0) - get(o, "position", 0);
            let dy = get(me, "position", 1) - get(o, "position", 1);
            let (lo, hi) = (
                get(o, "position", 2) - get(o, "size", 2) / 2.0,
                get(o, "position", 2) + get(o, "size", 2) / 2.0,
            );
            dx.hypot(dy) < radius && bottom > lo + 0.2 && bottom < hi + 0.5
        })
        .and_then(|o| o["instance"].as_str().map(str::to_owned))
}

/// Per layout kind: the stillness figures; prints a line per scene (the movers with what
/// holds them).
fn stillness(kind: &str, file: &str, results: &BTreeMap<String, Value>) -> Stillness {
    let mut total = Stillness::default();
    for (scene, r) in results {
        assert_eq!(r["loaded"], true, "{scene}: {}", r["error"]);
        let layout: Value = read_json(&Path::new(scene).join(file));
        let name = Path::new(scene)
            .file_name()
            .expect("a scene")
            .to_string_lossy()
            .into_owned();
        let obj = r["objects"].as_object().expect("objects");
        let mut movers: Vec<(String, f64)> = obj
            .iter()
            .map(|(n, o)| (n.clone(), o["moved_cm"].as_f64().expect("moved_cm")))
            .filter(|(_, m)| *m >= 1.0)
            .collect();
        movers.sort_by(|a, b| b.1.total_cmp(&a.1));
        let f = obj.values().filter(|o| o["fell"] == true).count();
        let worst = obj
            .values()
            .map(|o| o["moved_cm"].as_f64().expect("moved_cm"))
            .fold(0.0, f64::max);
        for (n, o) in obj {
            let m = o["moved_cm"].as_f64().expect("moved_cm");
            if holder(&layout, n).is_some() {
                total.held_worst_cm = total.held_worst_cm.max(m);
            } else {
                total.free += 1;
                total.free_moved += usize::from(m >= 1.0);
            }
        }
        let listed: Vec<String> = movers
            .iter()
            .map(|(n, m)| match holder(&layout, n) {
                Some(h) => format!("{n} {m:.1} (on/in {h})"),
                None => format!("{n} {m:.1}"),
            })
            .collect();
        println!(
            "{kind} | {name} | {} objects | {} moved >= 1 cm | {f} fell | worst {worst:.2} cm | {}",
            obj.len(),
            movers.len(),
            listed.join(", ")
        );
        total.objects += obj.len();
        total.moved += movers.len();
        total.fell += f;
    }
    println!(
        "{kind}: {} objects, {} moved >= 1 cm in 2 s ({:.1} % still), {} fell; standing on \
         the table: {} of {} moved; resting in or on another object: at most {:.2} cm",
        total.objects,
        total.moved,
        100.0 * (total.objects - total.moved) as f64 / total.objects.max(1) as f64,
        total.fell,
        total.free_moved,
        total.free,
        total.held_worst_cm
    );
    total
}

/// Every scene loads with its bodies named after its instances and one collision geom per
/// part (as the manifest says).
fn assert_structure(results: &BTreeMap<String, Value>) {
    for (scene, r) in results {
        assert_eq!(r["loaded"], true, "{scene}: {}", r["error"]);
        let manifest: ExportArtifact = read_json(&Path::new(scene).join("sim/export.json"));
        let bodies: BTreeSet<String> = r["bodies"]
            .as_array()
            .expect("bodies")
            .iter()
            .map(|b| b.as_str().expect("a name").to_owned())
            .collect();
        let instances: BTreeSet<String> = manifest
            .objects
            .iter()
            .map(|o| o.instance.clone())
            .collect();
        assert_eq!(bodies, instances, "{scene}");
        for o in &manifest.objects {
            assert_eq!(
                r["colliders"][&o.instance].as_u64(),
                Some(o.collision_parts),
                "{scene}: {}",
                o.instance
            );
        }
    }
}

#[test]
fn exported_scenes_load_and_stay_still_in_mujoco() {
    let Some(python) = python_with("mujoco, numpy", "the MuJoCo export test") else {
        return;
    };
    let tmp = tempfile::tempdir().expect("tempdir");
    let scenes: u32 = std::env::var("MESA_EXPORT_TEST_SCENES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(4);
    let dir = demo(tmp.path(), scenes, 7);
    let out = ok(&["check", "--settle", "--progress", "off"], &dir);
    let all = scene_dirs(&dir);
    // The dataset summary counts what the simulation did, scene by scene.
    assert!(out.contains("simulation (rapier3d): "), "{out}");
    let summary: CheckSummaryArtifact = read_json(&dir.join("qa/summary.json"));
    let sim = summary
        .settle
        .and_then(|s| s.simulation)
        .expect("a simulation summary");
    let reports: Vec<SimulationReport> = all
        .iter()
        .filter_map(|s| read_json::<CheckArtifact>(&s.join("qa/check.json")).settle)
        .filter_map(|s| s.simulation)
        .collect();
    assert!(reports.len() >= 2, "{} scenes simulated", reports.len());
    assert_eq!(sim.scenes, reports.len() as u64, "{sim:?}");
    let moved: u64 = reports.iter().map(|r| r.objects_moved).sum();
    assert_eq!(sim.objects_moved, moved, "{sim:?}");
    let pybullet = python_with("pybullet, numpy", "the PyBullet half of the export test");
    let mut kinds = BTreeMap::new();
    let mut bullet_kinds = BTreeMap::new();
    for layout in ["coarse", "refined", "auto"] {
        let started = std::time::Instant::now();
        ok(
            &["export", "--layout", layout, "--progress", "off", "-q"],
            &dir,
        );
        let exported = started.elapsed().as_secs_f64();
        let results = simulate(&python, "mujoco", &all);
        println!(
            "export --layout {layout}: {exported:.1} s for {} scenes",
            all.len()
        );
        assert_structure(&results);
        let (kind, file) = match layout {
            "auto" => ("settled", "qa/layout.json"),
            "refined" => ("refined", "refined/layout.json"),
            _ => ("coarse", "coarse/layout.json"),
        };
        kinds.insert(kind, stillness(kind, file, &results));
        if let Some(python) = &pybullet {
            let results = simulate(python, "pybullet", &all);
            assert_structure(&results);
            bullet_kinds.insert(kind, stillness(&format!("pybullet {kind}"), file, &results));
        }
    }
    // Settled layouts (`mesa check --settle`, which ends in a rigid-body simulation by
    // default): none falls, and at least 99 % of all objects, on the table or held by another,
    // move less than 1 cm, in MuJoCo and in PyBullet (issues 16 and 17).
    let still = |s: &Stillness| s.fell == 0 && (s.moved as f64) <= 0.01 * s.objects as f64;
    let settled = kinds["settled"];
    assert!(
        settled.objects >= 20,
        "too few settled objects to judge: {settled:?}"
    );
    assert!(still(&settled), "settled layouts: {settled:?}");
    // The control: unsettled coarse layouts fail that test.
    let coarse = kinds["coarse"];
    assert!(
        !still(&coarse),
        "coarse layouts pass the stillness test: {coarse:?}"
    );
    // The same in PyBullet, when it is there.
    if let Some(settled) = bullet_kinds.get("settled") {
        assert!(still(settled), "PyBullet, settled layouts: {settled:?}");
        let coarse = bullet_kinds["coarse"];
        assert!(
            !still(&coarse),
            "PyBullet, coarse layouts pass the stillness test: {coarse:?}"
        );
    }
    // The second control: an object sunk 3 cm into the table moves.
    let scene = &all[0];
    let path = scene.join("qa/layout.json");
    let mut layout: Value = read_json(&path);
    let sunk = layout["objects"][0]["instance"]
        .as_str()
        .expect("an instance")
        .to_owned();
    let z = layout["objects"][0]["position"][2]
        .as_f64()
        .expect("a position");
    layout["objects"][0]["position"][2] = json!(z - 3.0);
    std::fs::write(
        &path,
        serde_json::to_vec_pretty(&layout).expect("serialises"),
    )
    .expect("writes");
    ok(&["export", "--progress", "off", "-q"], &dir);
    let results = simulate(&python, "mujoco", std::slice::from_ref(scene));
    let moved = results
        .values()
        .next()
        .expect("a scene")
        .pointer(&format!("/objects/{sunk}/moved_cm"))
        .and_then(Value::as_f64)
        .expect("the sunk object");
    println!("control: {sunk} sunk 3 cm into the table moved {moved:.2} cm");
    assert!(moved >= 1.0, "{sunk} sunk 3 cm moved only {moved:.2} cm");
}

/// A layout of a bowl at rest on the table and an apple 5 mm above its rim, over its centre.
fn bowl_and_apple(dir: &Path) -> Value {
    let index: AssetIndexArtifact = read_json(&dir.join("assets/index/assets.json"));
    let annotations: Value = read_json(&dir.join("assets/annotations.json"));
    let find = |category: &str, word: &str| {
        let uid = annotations
            .as_object()
            .expect("annotations")
            .iter()
            .find(|(_, a)| {
                a["category"] == category
                    && a["description"].as_str().is_some_and(|d| d.contains(word))
            })
            .map(|(uid, _)| uid.clone())
            .unwrap_or_else(|| panic!("no {category} asset with {word}"));
        let size_m = index.assets[&uid]
            .geometry
            .as_ref()
            .expect("geometry")
            .size_m;
        (uid, size_m.map(|v| v * 100.0))
    };
    let (bowl, bowl_cm) = find("bowl", "wooden");
    let (apple, apple_cm) = find("fruit", "apple");
    let object = |instance: &str, uid: &str, size: [f64; 3], z: f64| {
        json!({
            "instance": instance, "category": instance.trim_end_matches("_0"),
            "description": instance, "retrieved_uid": uid,
            "position": [50.0, 40.0, z], "rotation": [0.0, 0.0, 0.0, 1.0],
            "size": size, "scale_factor": [1.0, 1.0, 1.0]
        })
    };
    println!(
        "bowl {bowl}: {:.1} × {:.1} × {:.1} cm; apple {apple}: {:.1} cm high",
        bowl_cm[0], bowl_cm[1], bowl_cm[2], apple_cm[2]
    );
    json!({
        "schema": "mesa.layout/1",
        "item_placement_zone": [0.0, 100.0, 0.0, 80.0],
        "objects": [
            object("bowl_0", &bowl, bowl_cm, bowl_cm[2] / 2.0),
            object("apple_0", &apple, apple_cm, bowl_cm[2] + apple_cm[2] / 2.0 + 0.5),
        ]
    })
}

#[test]
fn an_apple_dropped_into_an_exported_bowl_stays_inside() {
    let Some(python) = python_with("mujoco, numpy", "the MuJoCo bowl test") else {
        return;
    };
    let tmp = tempfile::tempdir().expect("tempdir");
    let dir = tmp.path().join("bowl");
    mesa()
        .args(["demo", "--scenes", "1", "--seed", "7", "-q"])
        .arg(&dir)
        .assert()
        .success();
    ok(&["assets", "--progress", "off", "-q"], &dir);
    let layout = bowl_and_apple(&dir);
    let bowl_height_cm = layout["objects"][0]["size"][2].as_f64().expect("a size");
    let scene = dir.join("scenes/dining_table/bowl_drop");
    std::fs::create_dir_all(scene.join("refined")).expect("mkdir");
    std::fs::write(
        scene.join("refined/layout.json"),
        serde_json::to_vec_pretty(&layout).expect("serialises"),
    )
    .expect("writes");
    let mut apple_z = BTreeMap::new();
    for colliders in ["parts", "hull"] {
        std::fs::write(
            dir.join("mesa.toml"),
            format!("[export]\ncolliders = \"{colliders}\"\n"),
        )
        .expect("toml");
        ok(
            &[
                "export",
                "--scenes",
                "dining_table/bowl_drop",
                "--progress",
                "off",
                "-q",
            ],
            &dir,
        );
        let results = simulate(&python, "mujoco", std::slice::from_ref(&scene));
        let r = results.values().next().expect("a scene");
        assert_eq!(r["loaded"], true, "{}", r["error"]);
        let manifest: ExportArtifact = read_json(&scene.join("sim/export.json"));
        println!(
            "colliders = {colliders}: the bowl has {} collision geoms",
            manifest.objects[0].collision_parts
        );
        let z = r
            .pointer("/final_z_cm/apple_0")
            .and_then(Value::as_f64)
            .expect("the apple's final height");
        let drift = r
            .pointer("/final_xy_offset_cm/apple_0")
            .and_then(Value::as_f64)
            .expect("the apple's drift");
        println!(
            "colliders = {colliders}: the apple's centre ends {z:.2} cm above the table, \
             {drift:.2} cm from where it was dropped (the bowl's rim: {bowl_height_cm:.2} cm)"
        );
        apple_z.insert(colliders, (z, drift));
    }
    let (inside_z, inside_drift) = apple_z["parts"];
    assert!(
        inside_z < bowl_height_cm && inside_drift < 5.0,
        "the apple did not stay in the bowl's cavity: centre at {inside_z:.2} cm, rim at \
         {bowl_height_cm:.2} cm, {inside_drift:.2} cm off"
    );
    // The control: a single hull fills the cavity, and the apple stays above the rim.
    let (hull_z, _) = apple_z["hull"];
    assert!(
        hull_z > bowl_height_cm,
        "with one hull per object the apple still sank into the bowl ({hull_z:.2} cm)"
    );
}

/// Per scene object of the manifest: (instance, visual materials, texture files).
fn visual_records(scene: &Path) -> Vec<(String, u64, Vec<String>)> {
    let manifest: ExportArtifact = read_json(&scene.join("sim/export.json"));
    manifest
        .objects
        .into_iter()
        .map(|o| (o.instance, o.visual_materials, o.textures))
        .collect()
}

#[test]
fn exported_materials_and_textures_reach_mujoco_pybullet_and_usd_and_match_the_glb_colours() {
    let Some(python) = python_with(
        "mujoco, pybullet, pxr, trimesh, PIL, scipy",
        "the textured export test",
    ) else {
        return;
    };
    let tmp = tempfile::tempdir().expect("tempdir");
    let dir = tmp.path().join("seed3");
    mesa()
        .args(["demo", "--scenes", "2", "--seed", "3", "-q"])
        .arg(&dir)
        .assert()
        .success();
    for stage in ["assets", "lift", "retrieve", "place"] {
        ok(&[stage, "--progress", "off", "-q"], &dir);
    }
    ok(
        &["export", "--layout", "coarse", "--progress", "off", "-q"],
        &dir,
    );
    let scenes = scene_dirs(&dir);
    let mujoco = simulate_for(&python, "mujoco", "0", &scenes);
    let bullet = simulate_for(&python, "pybullet", "0", &scenes);
    let usd = simulate_for(&python, "usd", "0", &scenes);
    let (mut objects, mut textured_objects, mut materials) = (0, 0, 0);
    for scene in &scenes {
        let key = scene.to_string_lossy().into_owned();
        let records = visual_records(scene);
        let (m, b, u) = (&mujoco[&key], &bullet[&key], &usd[&key]);
        for r in [m, b, u] {
            assert_eq!(r["loaded"], true, "{key}: {}", r["error"]);
        }
        assert_eq!(u["problems"], json!([]), "{key}");
        let images: BTreeSet<&String> = records.iter().flat_map(|r| &r.2).collect();
        let all_materials: u64 = records.iter().map(|r| r.1).sum();
        // MuJoCo compiled a texture per image and a material per (object, material).
        assert_eq!(
            m["visuals"]["ntex"].as_u64(),
            Some(images.len() as u64),
            "{key}"
        );
        assert_eq!(m["visuals"]["nmat"].as_u64(), Some(all_materials), "{key}");
        for (instance, count, textures) in &records {
            let textured = !textures.is_empty();
            let mv = &m["visuals"]["bodies"][instance];
            assert_eq!(mv["geoms"].as_u64(), Some(*count), "{key}: {instance}");
            assert_eq!(
                mv["with_material"].as_u64(),
                Some(*count),
                "{key}: {instance}"
            );
            assert_eq!(
                mv["textured"].as_u64() >= Some(1),
                textured,
                "{key}: {instance}: {mv}"
            );
            let bv = &b["visuals"][instance];
            assert_eq!(bv["shapes"].as_u64(), Some(*count), "{key}: {instance}");
            assert_eq!(
                bv["textured"].as_u64() >= Some(1),
                textured,
                "{key}: {instance}: {bv}"
            );
            let uv = &u["visuals"][instance];
            assert_eq!(uv["meshes"].as_u64(), Some(*count), "{key}: {instance}");
            assert_eq!(uv["textured"], uv["with_st"], "{key}: {instance}");
            assert_eq!(uv["files"], json!(textures), "{key}: {instance}");
            objects += 1;
            textured_objects += usize::from(textured);
            materials += count;
        }
        println!(
            "textures | {} | {} objects, {all_materials} visual materials, {} images",
            scene.file_name().expect("a scene").to_string_lossy(),
            records.len(),
            images.len()
        );
    }
    assert!(
        textured_objects >= 2 && materials > objects as u64,
        "the demo scenes should hold textured, multi-material objects: {textured_objects} \
         textured, {materials} materials for {objects} objects"
    );

    // The control: a missing PNG is caught by usd-core and refused by MuJoCo.
    let (scene, image) = scenes
        .iter()
        .find_map(|s| {
            let records = visual_records(s);
            let first = records.iter().find_map(|r| r.2.first().cloned());
            first.map(|f| (s.clone(), f))
        })
        .expect("a textured scene");
    let png = scene.join(&image);
    let bytes = std::fs::read(&png).expect("the PNG");
    std::fs::remove_file(&png).expect("removes the PNG");
    let key = scene.to_string_lossy().into_owned();
    let usd = simulate_for(&python, "usd", "0", std::slice::from_ref(&scene));
    let problems = usd[&key]["problems"].to_string();
    assert!(
        problems.contains("does not resolve to a file"),
        "usd-core missed a missing texture: {problems}"
    );
    let mujoco = simulate_for(&python, "mujoco", "0", std::slice::from_ref(&scene));
    assert_eq!(
        mujoco[&key]["loaded"], false,
        "MuJoCo loaded without {image}"
    );
    std::fs::write(&png, bytes).expect("restores the PNG");
    // The control of texture coordinates: an object's OBJs stripped of `vt` leave MuJoCo
    // none, and its geoms untextured.
    let instance = visual_records(&scene)
        .into_iter()
        .find(|r| !r.2.is_empty())
        .map(|r| r.0)
        .expect("a textured object");
    for entry in std::fs::read_dir(scene.join("sim/mjcf/meshes")).expect("meshes") {
        let path = entry.expect("an entry").path();
        let name = path
            .file_name()
            .expect("a name")
            .to_string_lossy()
            .into_owned();
        if !(name.starts_with(&format!("{instance}.visual_")) && name.ends_with(".obj")) {
            continue;
        }
        let text = std::fs::read_to_string(&path).expect("an OBJ");
        let stripped: String = text
            .lines()
            .filter(|l| !l.starts_with("vt "))
            .map(|l| match l.strip_prefix("f ") {
                Some(face) => {
                    let corners: Vec<&str> = face
                        .split(' ')
                        .map(|c| c.split('/').next().expect("a vertex"))
                        .collect();
                    format!("f {}\n", corners.join(" "))
                }
                None => format!("{l}\n"),
            })
            .collect();
        std::fs::write(&path, stripped).expect("writes");
    }
    let mujoco = simulate_for(&python, "mujoco", "0", std::slice::from_ref(&scene));
    let r = &mujoco[&key];
    assert_eq!(r["loaded"], true, "{}", r["error"]);
    assert_eq!(
        r["visuals"]["bodies"][&instance]["textured"].as_u64(),
        Some(0),
        "{instance}: textured in MuJoCo without texture coordinates"
    );

    // trimesh's colours of the exported OBJ + MTL + PNG and of the source GLBs agree; with
    // the v axis left unflipped (the control), they do not.
    ok(&["export", "--assets", "--progress", "off", "-q"], &dir);
    let reference = |control: bool| texture_reference(&python, &dir, control)["all"].clone();
    let share = |r: &Value, part: &str, whole: &str| {
        r[part].as_f64().expect("a count") / r[whole].as_f64().expect("a count").max(1.0)
    };
    let right = reference(false);
    let flipped = reference(true);
    println!(
        "trimesh colour reference: {} samples ({} textured): {:.2} % agree ({:.2} % of the \
         textured); v left unflipped (control): {:.2} % of the textured",
        right["samples"],
        right["textured"],
        100.0 * share(&right, "agree", "samples"),
        100.0 * share(&right, "textured_agree", "textured"),
        100.0 * share(&flipped, "textured_agree", "textured")
    );
    assert_eq!(right["unmatched"], 0, "{right}");
    assert!(right["textured"].as_u64() >= Some(1000), "{right}");
    assert!(share(&right, "agree", "samples") >= 0.99, "{right}");
    assert!(
        share(&right, "textured_agree", "textured") >= 0.99,
        "{right}"
    );
    assert!(
        share(&flipped, "textured_agree", "textured") < 0.95,
        "the colour reference missed an unflipped v: {flipped}"
    );
}

/// Runs scripts/texture_reference.py on a dataset's single-asset export: its JSON.
fn texture_reference(python: &Path, dir: &Path, control: bool) -> Value {
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scripts/texture_reference.py");
    let mut command = std::process::Command::new(python);
    command.arg(script).arg(dir);
    if control {
        command.arg("--flip-v");
    }
    let out = command.output().expect("python runs");
    assert!(
        out.status.success(),
        "texture_reference.py: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("JSON")
}

#[test]
fn real_textured_glbs_export_load_and_keep_their_colours() {
    let Some(python) = python_with(
        "mujoco, pybullet, trimesh, PIL, scipy",
        "the real-GLB texture test",
    ) else {
        return;
    };
    let tmp = tempfile::tempdir().expect("tempdir");
    let library = tmp.path().join("assets/library");
    std::fs::create_dir_all(&library).expect("mkdir");
    // (file, uid, visual materials, images): linked, not copied.
    let glbs = [
        ("Duck.glb", "duck", 1, 1usize),
        ("BoxTextured.glb", "boxtextured", 1, 1),
        ("CesiumMilkTruck.glb", "cesiummilktruck", 4, 1),
        ("AlphaBlendModeTest.glb", "alphablendmodetest", 6, 6),
        ("ShapeCollection.glb", "shapecollection", 1, 0),
    ];
    for (file, uid, _, _) in glbs {
        let source = shared().join("realdata/glb").join(file);
        assert!(
            source.is_file(),
            "{} (../shared/realdata)",
            source.display()
        );
        std::os::unix::fs::symlink(&source, library.join(format!("{uid}.glb"))).expect("links");
    }
    ok(&["assets", "--progress", "off", "-q"], tmp.path());
    ok(
        &["export", "--assets", "--progress", "off", "-q"],
        tmp.path(),
    );
    for (file, uid, materials, images) in glbs {
        let manifest: ExportArtifact =
            read_json(&tmp.path().join(format!("assets/sim/{uid}/export.json")));
        let o = &manifest.objects[0];
        assert_eq!(
            (o.visual_materials, o.textures.len()),
            (materials, images),
            "{file}: {:?}",
            manifest.warnings
        );
        assert!(
            manifest.warnings.is_empty(),
            "{file}: {:?}",
            manifest.warnings
        );
    }
    // Every image is a PNG on disk, AlphaBlendModeTest's JPEG (images[2]) included.
    for entry in std::fs::read_dir(tmp.path().join("assets/sim/alphablendmodetest/textures"))
        .expect("textures")
    {
        let bytes = std::fs::read(entry.expect("an entry").path()).expect("an image");
        assert!(bytes.starts_with(b"\x89PNG\r\n\x1a\n"));
    }
    let script = "import mujoco, json, os, sys, pybullet as p\n\
        p.connect(p.DIRECT)\n\
        root = sys.argv[1]\n\
        out = {}\n\
        for uid in sorted(os.listdir(root)):\n\
        \x20   m = mujoco.MjModel.from_xml_path(f'{root}/{uid}/mjcf/scene.xml')\n\
        \x20   b = p.loadURDF(f'{root}/{uid}/urdf/{uid}.urdf', flags=p.URDF_USE_INERTIA_FROM_FILE)\n\
        \x20   v = p.getVisualShapeData(b, flags=p.VISUAL_SHAPE_DATA_TEXTURE_UNIQUE_IDS)\n\
        \x20   out[uid] = [m.ntex, m.nmat, int((m.mesh_texcoordnum > 0).sum()), len(v), sum(s[8] >= 0 for s in v)]\n\
        print(json.dumps(out))\n";
    let out = std::process::Command::new(&python)
        .args(["-c", script])
        .arg(tmp.path().join("assets/sim"))
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    let loaded: Value = serde_json::from_str(text.lines().last().expect("JSON")).expect("JSON");
    for (file, uid, materials, images) in glbs {
        let [ntex, nmat, texcoords, shapes, textured] =
            std::array::from_fn(|k| loaded[uid][k].as_u64().expect("a count"));
        println!(
            "real | {file} | MuJoCo: {ntex} textures, {nmat} materials, {texcoords} meshes with \
             texcoords | PyBullet: {shapes} visual shapes, {textured} textured"
        );
        assert_eq!(
            (ntex, nmat, shapes),
            (images as u64, materials, materials),
            "{file}"
        );
        assert_eq!(texcoords >= 1, images >= 1, "{file}");
        assert_eq!(textured >= 1, images >= 1, "{file}");
    }
    let right = texture_reference(&python, tmp.path(), false);
    let flipped = texture_reference(&python, tmp.path(), true);
    for (file, uid, _, images) in glbs {
        let (r, f) = (&right[uid], &flipped[uid]);
        let count = |v: &Value, k: &str| v[k].as_u64().expect("a count");
        println!(
            "real | {file} | trimesh: {} of {} samples agree ({} of {} textured); v unflipped: \
             {} of the textured",
            count(r, "agree"),
            count(r, "samples"),
            count(r, "textured_agree"),
            count(r, "textured"),
            count(f, "textured_agree")
        );
        assert_eq!(count(r, "unmatched"), 0, "{file}: {r}");
        assert_eq!(count(r, "agree"), count(r, "samples"), "{file}: {r}");
        if images > 0 {
            assert!(count(r, "textured") > 0, "{file}: {r}");
            assert!(
                (count(f, "textured_agree") as f64) < 0.95 * count(f, "textured") as f64,
                "{file}: the control passed: {f}"
            );
        }
    }
}
