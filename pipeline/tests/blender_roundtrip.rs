//! The annotator round trip through real Blender (4.3, the version MesaTask pins, as the
//! `bpy` module): a pack opens with every object where the layout puts it; the edits a person
//! makes (move, turn about z, uniform and non-uniform scale, delete, duplicate, move the
//! table; scale the H1 figure) exported with Blender's defaults (and once with custom
//! properties) come back through `mesa ingest`; and the demo's simulated annotator writes
//! what Blender writes for the same session.
//!
//! Blender is `MESA_BLENDER_PYTHON` (a Python with `bpy`; scripts/test.sh sets it) or
//! `MESA_PYTHON` when that one has `bpy`. Without it the tests say SKIPPED, and fail when
//! `MESA_REQUIRE_TOOLS` is set, as in CI.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command as Process;
use std::sync::OnceLock;

use common::{copy_tree, mesa};
use mesa_schemas::annotation::{IngestDiffArtifact, PackIndexArtifact};
use mesa_schemas::artifacts::TruthInstances;
use mesa_schemas::layout::DatasetLayout;
use mesa_schemas::rotation::{normalize_deg, yaw_deg_from_quat_xyzw};
use serde_json::{json, Value};

const SCENE: &str = "scenes/office_table/office_table_0001";
const ID: &str = "office_table_0001";

/// Blender, or a skip (a failure under MESA_REQUIRE_TOOLS).
fn blender() -> Option<PathBuf> {
    common::blender("Blender round trip")
}

fn script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/blender_pack.py")
}

fn read<T: serde::de::DeserializeOwned>(path: &Path) -> T {
    serde_json::from_slice(
        &std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
    )
    .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Runs `blender_pack.py` and returns the objects it prints, by name.
fn blender_objects(python: &Path, args: &[&Path]) -> Vec<Value> {
    let out = Process::new(python)
        .arg(script())
        .args(args)
        .output()
        .expect("Blender runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "blender_pack.py failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
        .lines()
        .filter(|l| l.starts_with('{'))
        .map(|l| serde_json::from_str(l).expect("a JSON line"))
        .collect()
}

fn object<'a>(objects: &'a [Value], name: &str) -> &'a Value {
    objects
        .iter()
        .find(|o| o["name"] == name)
        .unwrap_or_else(|| panic!("Blender has no object {name}"))
}

fn vec3(v: &Value) -> [f64; 3] {
    [0, 1, 2].map(|i| v[i].as_f64().expect("a number"))
}

/// A demo scene packed for a person to edit: the dataset, written once per test binary.
fn packed() -> &'static Path {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = tempfile::tempdir().expect("tempdir");
        mesa()
            .args(["demo", "--scenes", "6", "--seed", "3", "-q"])
            .arg(dir.path())
            .assert()
            .success();
        std::fs::write(
            dir.path().join("mesa.toml"),
            "[annotate]\nannotator = \"human\"\n",
        )
        .expect("toml");
        mesa()
            .args(["run", "--progress", "off", "-q"])
            .arg(dir.path())
            .assert()
            .success();
        dir
    })
    .path()
}

/// A copy of the packed office scene with `refined` as the annotator's file, ingested.
fn ingest(refined: &Path) -> (tempfile::TempDir, DatasetLayout, IngestDiffArtifact) {
    ingest_scene(SCENE, refined)
}

/// A copy of a packed scene (`scenes/<table_type>/<scene_id>`) with `refined` as the
/// annotator's file, ingested.
fn ingest_scene(
    rel: &str,
    refined: &Path,
) -> (tempfile::TempDir, DatasetLayout, IngestDiffArtifact) {
    let id = Path::new(rel)
        .file_name()
        .expect("a scene id")
        .to_string_lossy()
        .into_owned();
    let dir = tempfile::tempdir().expect("tempdir");
    let scene = dir.path().join(rel);
    let from = packed().join(rel);
    for sub in ["coarse", "pack"] {
        copy_tree(&from.join(sub), &scene.join(sub));
    }
    std::fs::create_dir_all(scene.join("refined")).expect("mkdir");
    std::fs::copy(refined, scene.join(format!("refined/{id}.glb"))).expect("copy");
    let out = mesa()
        .args(["ingest", "--progress", "off"])
        .arg(dir.path())
        .output()
        .expect("runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let layout = read(&scene.join("refined/layout.json"));
    let diff = read(&scene.join("refined/diff.json"));
    (dir, layout, diff)
}

fn coarse() -> DatasetLayout {
    read(&packed().join(SCENE).join("coarse/layout.json"))
}

fn layout_object<'a>(layout: &'a DatasetLayout, instance: &str) -> &'a mesa_schemas::LayoutObject {
    layout
        .objects
        .iter()
        .find(|o| o.instance == instance)
        .unwrap_or_else(|| panic!("no {instance} in the layout"))
}

#[test]
fn a_pack_opens_in_blender_with_every_object_where_the_layout_puts_it() {
    let Some(python) = blender() else { return };
    let pack = packed().join(SCENE).join(format!("pack/{ID}.glb"));
    let objects = blender_objects(&python, &[Path::new("inspect"), &pack]);
    let layout = coarse();
    for o in &layout.objects {
        let b = object(&objects, &o.instance);
        assert_eq!(b["type"], "MESH");
        assert_eq!(b["rotation_mode"], "QUATERNION");
        assert_eq!(b["parent"], Value::Null);
        assert_eq!(
            b["properties"],
            json!(["mesa"]),
            "extras become custom properties"
        );
        let location = vec3(&b["location"]);
        let dimensions = vec3(&b["dimensions"]);
        for i in 0..3 {
            assert!(
                (location[i] * 100.0 - o.position_cm.0[i]).abs() < 1e-3,
                "{}: location {location:?} m vs position {:?} cm",
                o.instance,
                o.position_cm.0
            );
            assert!(
                (dimensions[i] * 100.0 - o.size_cm.0[i]).abs() < 1e-3,
                "{}: dimensions {dimensions:?} m vs size {:?} cm",
                o.instance,
                o.size_cm.0
            );
        }
        let q = &b["rotation_wxyz"];
        let [x, y, z, w] = o.rotation.0;
        let dot = q[0].as_f64().expect("w") * w
            + q[1].as_f64().expect("x") * x
            + q[2].as_f64().expect("y") * y
            + q[3].as_f64().expect("z") * z;
        assert!(
            (dot.abs() - 1.0).abs() < 1e-6,
            "{}: rotation {q}",
            o.instance
        );
    }
    // The table top: its upper face at z = 0, its front-left corner at the origin.
    let table = object(&objects, "table");
    let (location, dimensions) = (vec3(&table["location"]), vec3(&table["dimensions"]));
    assert!((location[2] + dimensions[2] / 2.0).abs() < 1e-6);
    assert!((location[0] - dimensions[0] / 2.0).abs() < 1e-6);
    assert!((location[1] - dimensions[1] / 2.0).abs() < 1e-6);
    assert!((dimensions[0] * 100.0 - layout.zone_cm.width_cm()).abs() < 1e-3);
    // The figure is 1.70 m tall, standing on the floor in front of the table's left.
    let h1 = object(&objects, "H1_reference");
    assert!((vec3(&h1["dimensions"])[2] - 1.70).abs() < 1e-6);
    assert!(vec3(&h1["location"])[0] < 0.0 && vec3(&h1["location"])[1] < 0.0);
}

/// Ingests Blender's export of `ops` applied to the pack and checks every object of Blender's
/// scene against the refined layout: positions within 0.1 mm, yaws within 0.01°, sizes within
/// 0.1 mm (in the table frame, which follows the table, scaled by the H1 rescale).
fn round_trip(python: &Path, ops: &Value, extras: bool) -> (DatasetLayout, IngestDiffArtifact) {
    let work = tempfile::tempdir().expect("tempdir");
    let ops_path = work.path().join("ops.json");
    std::fs::write(&ops_path, serde_json::to_vec(ops).expect("json")).expect("write");
    let out = work.path().join(format!("{ID}.glb"));
    let pack = packed().join(SCENE).join(format!("pack/{ID}.glb"));
    let mut args: Vec<&Path> = vec![Path::new("edit"), &pack, &ops_path, &out];
    if extras {
        args.push(Path::new("--extras"));
    }
    let objects = blender_objects(python, &args);
    let (_dir, layout, diff) = ingest(&out);
    let table = object(&objects, "table");
    let index: PackIndexArtifact = read(&packed().join(SCENE).join("pack/index.json"));
    // The table's front-left top corner in Blender's world: the table frame's origin.
    let corner = {
        let (l, d) = (vec3(&table["location"]), vec3(&table["dimensions"]));
        [l[0] - d[0] / 2.0, l[1] - d[1] / 2.0]
    };
    let h1 = object(&objects, "H1_reference");
    let f = index.h1.height_cm / 100.0 / vec3(&h1["dimensions"])[2];
    let (mut worst_position, mut worst_size, mut worst_yaw) = (0.0f64, 0.0f64, 0.0f64);
    for b in &objects {
        let name = b["name"].as_str().expect("name");
        if ["table", "H1_reference", "restricted_zone"].contains(&name) {
            continue;
        }
        let instance = diff
            .objects
            .iter()
            .find(|c| c.node.as_deref() == Some(name))
            .map(|c| c.instance.clone())
            .unwrap_or_else(|| panic!("{name}: not in diff.json"));
        let o = layout_object(&layout, &instance);
        let location = vec3(&b["location"]);
        let expected = [
            (location[0] - corner[0]) * f,
            (location[1] - corner[1]) * f,
            location[2] * f,
        ];
        let dimensions = vec3(&b["dimensions"]);
        for i in 0..3 {
            worst_position = worst_position.max((o.position_cm.0[i] - expected[i] * 100.0).abs());
            worst_size = worst_size.max((o.size_cm.0[i] - dimensions[i] * f * 100.0).abs());
            assert!(
                (o.position_cm.0[i] - expected[i] * 100.0).abs() < 0.01,
                "{instance}: position {:?} cm, Blender shows {expected:?} m",
                o.position_cm.0
            );
            assert!(
                (o.size_cm.0[i] - dimensions[i] * f * 100.0).abs() < 0.01,
                "{instance}: size {:?} cm, Blender shows {dimensions:?} m",
                o.size_cm.0
            );
        }
        let q = &b["rotation_wxyz"];
        let blender_yaw = yaw_deg_from_quat_xyzw([
            q[1].as_f64().expect("x"),
            q[2].as_f64().expect("y"),
            q[3].as_f64().expect("z"),
            q[0].as_f64().expect("w"),
        ]);
        let yaw = o.z_rotation_deg.expect("not tilted: a z_rotation");
        worst_yaw = worst_yaw.max(normalize_deg(yaw - blender_yaw).abs());
        assert!(
            normalize_deg(yaw - blender_yaw).abs() < 0.01,
            "{instance}: yaw {yaw}, Blender shows {blender_yaw}"
        );
    }
    eprintln!(
        "Blender vs ingest: worst position {:.6} mm, size {:.6} mm, yaw {worst_yaw:.6}°",
        worst_position * 10.0,
        worst_size * 10.0
    );
    (layout, diff)
}

fn person_ops() -> Value {
    json!([
        {"op": "move", "name": "mug_0", "by": [0.05, -0.03, 0.0]},
        {"op": "rotate_z", "name": "book_0", "deg": 30.0},
        {"op": "rotate_z", "name": "mug_0", "deg": -75.5},
        {"op": "scale", "name": "cup_0", "by": [1.2, 1.2, 1.2]},
        {"op": "scale", "name": "notebook_0", "by": [1.5, 1.0, 0.8]},
        {"op": "delete", "name": "pencil_1"},
        {"op": "duplicate", "name": "book_1", "as": "book_1.001"},
        {"op": "move", "name": "book_1.001", "by": [-0.10, 0.02, 0.0]},
        {"op": "rotate_z", "name": "book_1.001", "deg": 12.0},
        {"op": "move", "name": "table", "by": [0.10, 0.05, 0.0]}
    ])
}

fn check_person_edits(layout: &DatasetLayout, diff: &IngestDiffArtifact) {
    let before = coarse();
    assert_eq!(diff.removed, vec!["pencil_1"]);
    assert_eq!(diff.added.len(), 1);
    let copy = diff
        .objects
        .iter()
        .find(|c| c.status == "added")
        .expect("the copy");
    assert_eq!(copy.node.as_deref(), Some("book_1.001"));
    assert_eq!(copy.duplicate_of.as_deref(), Some("book_1"));
    assert!(copy.instance.starts_with("book_") && copy.instance != "book_1");
    // What the person meant, read back (the table moved by (10, 5) cm, so unmoved objects
    // are 10 cm left and 5 cm nearer in its frame).
    let (b, a) = (
        layout_object(&before, "mug_0"),
        layout_object(layout, "mug_0"),
    );
    assert!((a.position_cm.0[0] - (b.position_cm.0[0] + 5.0 - 10.0)).abs() < 0.01);
    assert!((a.position_cm.0[1] - (b.position_cm.0[1] - 3.0 - 5.0)).abs() < 0.01);
    let (b, a) = (
        layout_object(&before, "book_0"),
        layout_object(layout, "book_0"),
    );
    let turned = normalize_deg(a.z_rotation_deg.expect("yaw") - b.z_rotation_deg.expect("yaw"));
    assert!((turned - 30.0).abs() < 0.01, "{turned}");
    let (b, a) = (
        layout_object(&before, "notebook_0"),
        layout_object(layout, "notebook_0"),
    );
    for (i, k) in [1.5, 1.0, 0.8].iter().enumerate() {
        assert!((a.size_cm.0[i] - b.size_cm.0[i] * k).abs() < 0.01);
    }
    assert!(
        diff.scaled.contains(&"cup_0".to_owned()) && diff.scaled.contains(&"notebook_0".to_owned())
    );
    assert!((diff.table.moved_cm[0] - 10.0).abs() < 0.01);
    assert_eq!(layout.zone_cm, before.zone_cm, "moved, not resized");
}

#[test]
fn the_edits_a_person_makes_in_blender_come_back() {
    let Some(python) = blender() else { return };
    let (layout, diff) = round_trip(&python, &person_ops(), false);
    check_person_edits(&layout, &diff);
    assert_eq!(
        diff.generator.as_deref(),
        Some("Khronos glTF Blender I/O v4.3.47")
    );
}

#[test]
fn custom_properties_exported_change_nothing() {
    let Some(python) = blender() else { return };
    let (with_extras, diff) = round_trip(&python, &person_ops(), true);
    check_person_edits(&with_extras, &diff);
    let (without, _) = round_trip(&python, &person_ops(), false);
    assert_eq!(with_extras, without);
}

#[test]
fn a_scaled_h1_figure_rescales_the_scene() {
    let Some(python) = blender() else { return };
    let ops = json!([
        {"op": "scale", "name": "H1_reference", "by": [1.1, 1.1, 1.1]},
        {"op": "move", "name": "cup_0", "by": [0.02, 0.0, 0.0]}
    ]);
    let (layout, diff) = round_trip(&python, &ops, false);
    let f = diff.h1.rescaled_by.expect("rescaled");
    assert!((f - 1.0 / 1.1).abs() < 1e-6, "{f}");
    let before = coarse();
    assert!((layout.zone_cm.0[1] - before.zone_cm.0[1] * f).abs() < 0.01);
    let (b, a) = (
        layout_object(&before, "book_0"),
        layout_object(&layout, "book_0"),
    );
    for i in 0..3 {
        assert!((a.position_cm.0[i] - b.position_cm.0[i] * f).abs() < 0.01);
        assert!((a.size_cm.0[i] - b.size_cm.0[i] * f).abs() < 0.01);
    }
}

#[test]
fn no_edits_through_blender_give_the_coarse_layout_back() {
    let Some(python) = blender() else { return };
    let (layout, diff) = round_trip(&python, &json!([]), false);
    assert_eq!(layout, coarse());
    assert!(
        diff.objects.iter().all(|c| c.status == "unchanged"),
        "{diff:?}"
    );
}

#[test]
fn the_simulated_annotator_writes_what_blender_writes() {
    let Some(python) = blender() else { return };
    // The office scene with four seeds (with and without an object made again from its
    // twin), and the bathroom vanity, whose sink the annotator adds as a box.
    let cases = [
        (SCENE, 0),
        (SCENE, 1),
        (SCENE, 2),
        (SCENE, 3),
        ("scenes/bathroom_vanity/bathroom_vanity_0001", 0),
    ];
    let mut copies = 0;
    let mut boxes = 0;
    for (rel, seed) in cases {
        let scene = packed().join(rel);
        let id = Path::new(rel)
            .file_name()
            .expect("id")
            .to_string_lossy()
            .into_owned();
        let pack_glb = std::fs::read(scene.join(format!("pack/{id}.glb"))).expect("pack");
        let index: PackIndexArtifact = read(&scene.join("pack/index.json"));
        let baseline: DatasetLayout = read(&scene.join("coarse/layout.json"));
        let truth: DatasetLayout = read(&scene.join("truth/layout.json"));
        let truth_instances: TruthInstances = read(&scene.join("truth/instances.json"));
        {
            let annotation = mesa_stages::demo::annotator::annotate_scene(
                &mesa_stages::demo::annotator::AnnotateRequest {
                    scene_id: &id,
                    pack_glb: &pack_glb,
                    index: &index,
                    baseline: &baseline,
                    truth: &truth,
                    truth_instances: &truth_instances,
                    seed,
                },
            )
            .expect("annotates");
            copies += annotation.duplicated.len();
            boxes += usize::from(annotation.restricted_zone_added);
            let work = tempfile::tempdir().expect("tempdir");
            let simulated = work.path().join("simulated.glb");
            std::fs::write(&simulated, &annotation.glb).expect("write");
            let ops = work.path().join("ops.json");
            std::fs::write(
                &ops,
                serde_json::to_vec(&annotation.blender_ops).expect("json"),
            )
            .expect("write");
            let by_blender = work.path().join("blender.glb");
            blender_objects(
                &python,
                &[
                    Path::new("edit"),
                    &scene.join(format!("pack/{id}.glb")),
                    &ops,
                    &by_blender,
                ],
            );
            // The same nodes, in the same order, with the same meshes, and no extras.
            let structure = |path: &Path| {
                let bytes = std::fs::read(path).expect("read");
                let len = u32::from_le_bytes(bytes[12..16].try_into().expect("4")) as usize;
                let json: Value = serde_json::from_slice(&bytes[20..20 + len]).expect("json");
                let nodes: Vec<(String, String, bool)> = json["nodes"]
                    .as_array()
                    .expect("nodes")
                    .iter()
                    .map(|n| {
                        let mesh = n["mesh"].as_u64().expect("a mesh") as usize;
                        (
                            n["name"].as_str().expect("name").to_owned(),
                            json["meshes"][mesh]["name"]
                                .as_str()
                                .unwrap_or("")
                                .to_owned(),
                            n.get("extras").is_some(),
                        )
                    })
                    .collect();
                (
                    nodes,
                    json["asset"]["generator"].clone(),
                    json["scenes"][0]["name"].clone(),
                )
            };
            assert_eq!(
                structure(&simulated),
                structure(&by_blender),
                "{rel} seed {seed}"
            );
            // And ingest reads the same layout from both.
            let (_a, from_simulated, diff_s) = ingest_scene(rel, &simulated);
            let (_b, from_blender, diff_b) = ingest_scene(rel, &by_blender);
            assert_eq!(diff_s.added, diff_b.added, "{rel} seed {seed}");
            assert_eq!(diff_s.removed, diff_b.removed, "{rel} seed {seed}");
            assert_eq!(from_simulated.objects.len(), from_blender.objects.len());
            for (s, b) in from_simulated.objects.iter().zip(&from_blender.objects) {
                assert_eq!(s.instance, b.instance, "{rel} seed {seed}");
                for i in 0..3 {
                    assert!(
                        (s.position_cm.0[i] - b.position_cm.0[i]).abs() < 1e-3,
                        "{rel} seed {seed}: {}",
                        s.instance
                    );
                    assert!(
                        (s.size_cm.0[i] - b.size_cm.0[i]).abs() < 1e-3,
                        "{rel} seed {seed}: {}",
                        s.instance
                    );
                }
                let dot: f64 = (0..4).map(|i| s.rotation.0[i] * b.rotation.0[i]).sum();
                assert!(
                    (dot.abs() - 1.0).abs() < 1e-9,
                    "{rel} seed {seed}: {}",
                    s.instance
                );
            }
            for i in 0..4 {
                assert!((from_simulated.zone_cm.0[i] - from_blender.zone_cm.0[i]).abs() < 1e-3);
            }
            assert_eq!(
                from_simulated.restricted_zone_cm.is_some(),
                from_blender.restricted_zone_cm.is_some()
            );
            if let (Some(a), Some(b)) = (
                &from_simulated.restricted_zone_cm,
                &from_blender.restricted_zone_cm,
            ) {
                for i in 0..4 {
                    assert!((a.0[i] - b.0[i]).abs() < 1e-3, "{rel}: the sink");
                }
            }
        }
    }
    assert!(
        copies > 0,
        "no case made a copy: the check missed `.001` names"
    );
    assert!(boxes > 0, "no case added the sink");
}
