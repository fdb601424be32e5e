//! `mesa graph` against an independent implementation of SCENE_GRAPH.md's rules, on layouts
//! far from the demo's.
//!
//! The reference is `bench/graph_rules.py`: the same rules written in Python the way a user
//! would write them without mesa, with numpy for the pairwise quantities and shapely for the
//! rotated-rectangle intersections. It shares no code with mesa.
//!
//! The graph's fast paths each changed how the rules are computed. On the 1,000 demo scenes
//! the results stayed byte-identical, but demo scenes are tidy. The fast paths are:
//! - a footprint made only when two objects' circles meet;
//! - the five nearest neighbours chosen without a branch per candidate;
//! - duplicate names found pair by pair up to 64 objects, and by sorting above;
//! - a grid of boxes above 64 objects.
//!
//! This test generates layouts that are not tidy, from a fixed seed:
//! - from 1 to 150 objects, so both sides of the 64-object paths run;
//! - objects stacked on others, sunk into them by about the 1 cm that `above` allows;
//! - small objects in containers, and containers in containers;
//! - footprints whose circles just touch or just overlap, with their corners pointed at each
//!   other;
//! - equal distances (objects on a grid, twins at one spot) and yaws on the facing sectors'
//!   22.5° boundaries;
//! - thin objects, and objects reaching out of the zone;
//! - tilted rotations, and `z_rotation` present or absent;
//! - every third layout in a model's form (a yaw per object instead of a rotation).
//!
//! Every layout's `mesa graph --layout` output must be byte-identical to the reference's
//! text. The control test moves one object of a layout for the reference only, and requires
//! the outputs to differ, so the comparison can fail.
//!
//! Needs a Python with numpy and shapely (`MESA_PYTHON`, or the `.venv-tools` that
//! scripts/test.sh makes). Without one the test is SKIPPED; under `MESA_REQUIRE_TOOLS` it
//! fails.

mod common;

use std::f64::consts::PI;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use common::{mesa, python_with};
use mesa_stages::mesh::{quat_from_axis_angle, quat_mul};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::{json, Value};

/// Categories drawn for objects: containers by SCENE_GRAPH.md's keyword rule (bowl, cup,
/// basket, ...) and others, `tray` among them (not a container).
const CATEGORIES: [&str; 16] = [
    "bowl",
    "cup",
    "mug",
    "basket",
    "pen_holder",
    "storage_box",
    "tray",
    "book",
    "plate",
    "laptop",
    "bottle",
    "apple",
    "desk_lamp",
    "paper",
    "remote",
    "candle",
];

/// One object as it is being generated.
struct Object {
    instance: String,
    position: [f64; 3],
    size: [f64; 3],
    yaw_deg: f64,
}

impl Object {
    fn top(&self) -> f64 {
        self.position[2] + self.size[2] / 2.0
    }

    fn half_diagonal(&self) -> f64 {
        (self.size[0].hypot(self.size[1])) / 2.0
    }
}

/// A point of `object`'s footprint, scaled by `reach` about its centre (above 1: a little way
/// out of it), drawn in the object's own turned frame: near its edges and corners as often as
/// near its centre.
fn within_footprint(rng: &mut ChaCha8Rng, object: &Object, reach: f64) -> [f64; 2] {
    let u = rng.random_range(-0.5..=0.5) * reach * object.size[0];
    let v = rng.random_range(-0.5..=0.5) * reach * object.size[1];
    let (sin, cos) = object.yaw_deg.to_radians().sin_cos();
    [
        object.position[0] + u * cos - v * sin,
        object.position[1] + u * sin + v * cos,
    ]
}

/// A yaw: any angle, a multiple of 22.5° (the facing sectors' boundaries) or of 90°.
fn draw_yaw(rng: &mut ChaCha8Rng) -> f64 {
    match rng.random_range(0..4) {
        0 => f64::from(rng.random_range(-8..=8)) * 22.5,
        1 => f64::from(rng.random_range(-2..=2)) * 90.0,
        _ => rng.random_range(-180.0..180.0),
    }
}

fn draw_size(rng: &mut ChaCha8Rng, category: &str) -> [f64; 3] {
    let mut size = [
        rng.random_range(2.0..45.0),
        rng.random_range(2.0..45.0),
        rng.random_range(1.0..30.0),
    ];
    if category == "paper" || rng.random_bool(0.05) {
        size[2] = rng.random_range(0.05..0.6); // thin
    }
    size
}

/// The forms of a layout file that `mesa graph --layout` reads and the reference reads too.
#[derive(Clone, Copy)]
enum Form {
    /// Quaternion rotations (some tilted), `z_rotation` present or absent, asset uids.
    Dataset,
    /// A model's output: a yaw (`z_rotation`) per object and a description.
    Llm,
}

/// One layout of `n` objects in `form`, as JSON.
fn layout(rng: &mut ChaCha8Rng, n: usize, form: Form) -> Value {
    // The table frame's origin is the zone's proximal-left corner.
    let zone = [
        0.0,
        rng.random_range(40.0..240.0),
        0.0,
        rng.random_range(30.0..120.0),
    ];
    let mut objects: Vec<Object> = Vec::new();
    let mut counts = std::collections::BTreeMap::<&str, usize>::new();
    // A grid's spacing, for equal distances.
    let grid = rng.random_range(8.0..30.0);
    for _ in 0..n {
        let category = CATEGORIES[rng.random_range(0..CATEGORIES.len())];
        let index = counts.entry(category).or_default();
        let instance = format!("{category}_{index}");
        *index += 1;
        let mut size = draw_size(rng, category);
        let yaw_deg = draw_yaw(rng);
        let free = |rng: &mut ChaCha8Rng, size: &[f64; 3]| {
            [
                rng.random_range(zone[0] - 10.0..zone[1] + 10.0),
                rng.random_range(zone[2] - 10.0..zone[3] + 10.0),
                size[2] / 2.0,
            ]
        };
        let position = match (objects.is_empty(), rng.random_range(0..8)) {
            (true, _) => free(rng, &size),
            (false, 2) => {
                // On a grid: equal distances between neighbours.
                let (i, j) = (rng.random_range(0..8), rng.random_range(0..5));
                [
                    zone[0] + grid * f64::from(i),
                    zone[2] + grid * f64::from(j),
                    size[2] / 2.0,
                ]
            }
            (false, 3) => {
                // Stacked on another, sunk into it by about the 1 cm that `above` allows.
                let below = &objects[rng.random_range(0..objects.len())];
                let gap = [-1.5, -1.001, -1.0, -0.9999, -0.999, -0.3, 0.0, 0.5, 3.0]
                    [rng.random_range(0..9)];
                if rng.random_bool(0.4) {
                    size[0] = rng.random_range(0.5..5.0);
                    size[1] = rng.random_range(0.5..5.0);
                }
                let [x, y] = within_footprint(rng, below, 1.1);
                [x, y, below.top() + gap + size[2] / 2.0]
            }
            (false, 4) => {
                // Inside another (a container or not): smaller, within its height.
                let outer = &objects[rng.random_range(0..objects.len())];
                size = [
                    outer.size[0] * rng.random_range(0.2..1.05),
                    outer.size[1] * rng.random_range(0.2..1.05),
                    outer.size[2] * rng.random_range(0.2..1.2),
                ];
                let bottom = outer.position[2] - outer.size[2] / 2.0;
                let [x, y] = within_footprint(rng, outer, 0.6);
                [
                    x,
                    y,
                    bottom + size[2] / 2.0 + rng.random_range(0.0..0.5) * outer.size[2],
                ]
            }
            (false, 5) => {
                // Circles just touching or just overlapping, corners pointed at each other.
                let other = &objects[rng.random_range(0..objects.len())];
                let reach = other.half_diagonal() + (size[0].hypot(size[1])) / 2.0;
                let k = [0.98, 0.999, 1.0, 1.001, 1.02][rng.random_range(0..5)];
                let corner = (other.size[1].atan2(other.size[0])).to_degrees() + other.yaw_deg;
                let angle = if rng.random_bool(0.5) {
                    corner.to_radians()
                } else {
                    rng.random_range(-PI..PI)
                };
                [
                    other.position[0] + k * reach * angle.cos(),
                    other.position[1] + k * reach * angle.sin(),
                    other.position[2],
                ]
            }
            (false, 6) => {
                // A twin at the same spot: equal distances to everything.
                let twin = &objects[rng.random_range(0..objects.len())];
                size = twin.size;
                twin.position
            }
            // Three draws in eight: anywhere.
            _ => free(rng, &size),
        };
        objects.push(Object {
            instance,
            position,
            size,
            yaw_deg,
        });
    }
    let objects: Vec<Value> = objects
        .iter()
        .enumerate()
        .map(|(i, o)| {
            if let Form::Llm = form {
                return json!({
                    "instance": o.instance,
                    "size": o.size,
                    "position": o.position,
                    "z_rotation": o.yaw_deg,
                    "description": format!("object {i}"),
                });
            }
            let twist = quat_from_axis_angle([0.0, 0.0, 1.0], o.yaw_deg.to_radians());
            let tilted = rng.random_bool(0.08);
            let rotation = if tilted {
                // A tilt about x or y before the yaw: the graph keeps the yaw only.
                let tilt = rng.random_range(5.0f64..95.0).to_radians();
                let axis = if rng.random_bool(0.5) {
                    [1.0, 0.0, 0.0]
                } else {
                    [0.0, 1.0, 0.0]
                };
                quat_mul(twist, quat_from_axis_angle(axis, tilt))
            } else {
                twist
            };
            let mut object = json!({
                "instance": o.instance,
                "retrieved_uid": format!("uid_{i}"),
                "position": o.position,
                "rotation": rotation,
                "scale_factor": [1.0, 1.0, 1.0],
                "size": o.size,
            });
            if !tilted && rng.random_bool(0.5) {
                object["z_rotation"] = json!(o.yaw_deg);
            }
            object
        })
        .collect();
    match form {
        Form::Dataset => {
            json!({"schema": "mesa.layout/1", "item_placement_zone": zone, "objects": objects})
        }
        Form::Llm => json!({"item_placement_zone": zone, "objects": objects}),
    }
}

/// The object counts of the generated layouts: mostly small, then around the 64-object
/// paths, then large.
fn object_counts() -> Vec<usize> {
    let mut counts: Vec<usize> = (1..=20).cycle().take(160).collect();
    counts.extend([63, 64, 65, 66, 70, 80, 100, 120, 150]);
    counts
}

/// Writes the generated layouts under `dir`; their paths.
fn write_layouts(dir: &Path, seed: u64) -> Vec<PathBuf> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    object_counts()
        .into_iter()
        .enumerate()
        .map(|(i, n)| {
            // Every third layout in a model's form.
            let (form, name) = match i % 3 {
                2 => (Form::Llm, "llm"),
                _ => (Form::Dataset, "layout"),
            };
            let path = dir.join(format!("{name}_{i:03}_{n}.json"));
            let text = serde_json::to_string_pretty(&layout(&mut rng, n, form)).expect("json");
            std::fs::write(&path, text).expect("write layout");
            path
        })
        .collect()
}

/// The reference's triplet text of each file, in order (keyword containers, as `mesa graph
/// --layout` decides them without annotations). `moved`: a file whose first object the
/// reference sees 30 cm further along +x (the control).
fn reference_texts(python: &Path, files: &[PathBuf], moved: Option<&Path>) -> Vec<String> {
    let bench = Path::new(env!("CARGO_MANIFEST_DIR")).join("../bench");
    let script = r#"
import json, sys
sys.path.insert(0, sys.argv[1])
import graph_rules
moved = sys.argv[2]
texts = []
for path in sys.argv[3:]:
    scene = graph_rules.read_scene(path)
    if path == moved:
        scene.position[0, 0] += 30.0
    flags = graph_rules.container_flags(scene)
    texts.append(graph_rules.graph_text(graph_rules.extract_graph(scene, flags)))
json.dump(texts, sys.stdout)
"#;
    let out = std::process::Command::new(python)
        .arg("-c")
        .arg(script)
        .arg(&bench)
        .arg(moved.map(Path::as_os_str).unwrap_or_default())
        .args(files)
        .output()
        .expect("run the reference");
    assert!(
        out.status.success(),
        "bench/graph_rules.py failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("the reference's texts")
}

fn mesa_text(file: &Path) -> String {
    let out = mesa()
        .args(["graph", "--layout"])
        .arg(file)
        .output()
        .expect("run mesa graph");
    assert!(
        out.status.success(),
        "{}: {}",
        file.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("utf-8")
}

/// The lines only one side has, for a failure message.
fn line_difference(ours: &str, theirs: &str) -> String {
    let (a, b): (Vec<&str>, Vec<&str>) = (ours.lines().collect(), theirs.lines().collect());
    let mut message = String::new();
    for line in a.iter().filter(|l| !b.contains(l)) {
        let _ = writeln!(message, "  mesa only:      {line}");
    }
    for line in b.iter().filter(|l| !a.contains(l)) {
        let _ = writeln!(message, "  reference only: {line}");
    }
    if message.is_empty() {
        message.push_str("  the same lines in another order\n");
    }
    message
}

#[test]
fn mesa_graph_matches_the_python_rules_on_untidy_layouts() {
    let Some(python) = python_with("numpy, shapely", "mesa graph against bench/graph_rules.py")
    else {
        return;
    };
    let dir = tempfile::tempdir().expect("tempdir");
    let files = write_layouts(dir.path(), 0x6772_6170_6873);
    let reference = reference_texts(&python, &files, None);
    assert_eq!(reference.len(), files.len());
    let mut differing = Vec::new();
    let (mut triplets, mut relations) = (0, std::collections::BTreeMap::<String, usize>::new());
    for (file, theirs) in files.iter().zip(&reference) {
        let ours = mesa_text(file);
        for line in ours.lines() {
            triplets += 1;
            let relation = line.split(", ").nth(1).unwrap_or_default().to_owned();
            *relations.entry(relation).or_default() += 1;
        }
        if &ours != theirs {
            differing.push(format!(
                "{}:\n{}",
                file.file_name().unwrap_or_default().to_string_lossy(),
                line_difference(&ours, theirs)
            ));
        }
    }
    eprintln!(
        "{} layouts, {triplets} triplets; by relation: {relations:?}",
        files.len()
    );
    assert!(
        differing.is_empty(),
        "{} of {} layouts differ from bench/graph_rules.py:\n{}",
        differing.len(),
        files.len(),
        differing.join("\n")
    );
    // The layouts reach every relation the rules have, so each rule is compared.
    for relation in [
        "is at",
        "face to",
        "in",
        "above",
        "left of",
        "right of",
        "in front of",
        "behind",
    ] {
        assert!(
            relations.get(relation).copied().unwrap_or(0) >= 10,
            "too few `{relation}` triplets to compare the rule: {relations:?}"
        );
    }
}

#[test]
fn the_comparison_sees_one_object_moved() {
    let Some(python) = python_with("numpy, shapely", "the control of the graph comparison") else {
        return;
    };
    let dir = tempfile::tempdir().expect("tempdir");
    let files = write_layouts(dir.path(), 7);
    // A layout of some size, where moving its first object by 30 cm changes relations.
    let file = files
        .iter()
        .find(|f| f.to_string_lossy().ends_with("_12.json"))
        .expect("a 12-object layout");
    let same = reference_texts(&python, std::slice::from_ref(file), None);
    let moved = reference_texts(&python, std::slice::from_ref(file), Some(file));
    let ours = mesa_text(file);
    assert_eq!(ours, same[0], "{}", line_difference(&ours, &same[0]));
    assert_ne!(
        ours, moved[0],
        "moving an object did not change the reference's text: the comparison could not fail"
    );
}
