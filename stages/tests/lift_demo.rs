//! `lift` against the demo's ground truth (issue 4): the table frame's z axis within 1°, the
//! zone's size within 2 cm, and each object's box against its visible-surface box — the part
//! of the true object the camera sees, computed from the same scene rendered without sensor
//! noise (exact depth and masks of the true meshes), in the true table frame. Boxes are
//! compared as a layout holds them: table-frame coordinates against table-frame coordinates.
//!
//! A monocular depth estimator's output (the demo's `depth.npy` scenes) carries a global
//! scale error that no single depth map can reveal: every length lift measures is off by that
//! factor (2.7 % on a 117 cm vanity is 3.2 cm). The targets are asserted against the truth as
//! the depth map states it (lengths times the scale the demo applied, recorded in
//! `truth/scene.json`); the raw figures are printed beside them.
//!
//! Prints the full distribution; run with `--nocapture` to see it (`MESA_LIFT_DEBUG=1` adds a
//! line per object).

use std::collections::BTreeMap;
use std::path::Path;

use mesa_schemas::artifacts::TruthScene;
use mesa_stages::demo::{write_demo, DemoOptions};
use mesa_stages::lift::{lift_scene, LiftConfig};
use nalgebra::{Matrix4, Vector3, Vector4};

/// Scenes in the test (`MESA_LIFT_SCENES` sets another count, e.g. to look past the twelve
/// the defaults were chosen on).
fn scene_count() -> usize {
    std::env::var("MESA_LIFT_SCENES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(12)
}

fn read<T: serde::de::DeserializeOwned>(path: &Path) -> T {
    serde_json::from_slice(
        &std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
    )
    .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn matrix(rows: [[f64; 4]; 4]) -> Matrix4<f64> {
    Matrix4::from_fn(|r, c| rows[r][c])
}

/// Pixels of each mask id in a scene's exact masks.
fn exact_masks(input: &Path, width: usize) -> BTreeMap<u32, Vec<(usize, usize)>> {
    let mut out: BTreeMap<u32, Vec<(usize, usize)>> = BTreeMap::new();
    let label = input.join("masks.png");
    if label.exists() {
        let image = image::open(&label).expect("labels").into_luma16();
        for (i, p) in image.pixels().enumerate() {
            if p.0[0] != 0 {
                out.entry(u32::from(p.0[0]))
                    .or_default()
                    .push((i % width, i / width));
            }
        }
    } else {
        for entry in std::fs::read_dir(input.join("masks")).expect("masks") {
            let path = entry.expect("entry").path();
            let id: u32 = path
                .file_stem()
                .and_then(|s| s.to_str())
                .and_then(|s| s.parse().ok())
                .expect("id");
            let image = image::open(&path).expect("mask").into_luma8();
            let list = image
                .pixels()
                .enumerate()
                .filter(|(_, p)| p.0[0] != 0)
                .map(|(i, _)| (i % width, i / width))
                .collect();
            out.insert(id, list);
        }
    }
    out
}

fn exact_depth(input: &Path, width: usize, height: usize) -> Vec<f32> {
    if input.join("depth.png").exists() {
        let image = image::open(input.join("depth.png"))
            .expect("depth")
            .into_luma16();
        image
            .pixels()
            .map(|p| {
                if p.0[0] == 0 {
                    f32::NAN
                } else {
                    f32::from(p.0[0]) / 1000.0
                }
            })
            .collect()
    } else {
        let file = std::fs::File::open(input.join("depth.npy")).expect("npy");
        let array: ndarray::ArrayD<f32> = ndarray_npy::ReadNpyExt::read_npy(file).expect("npy");
        assert_eq!(array.len(), width * height);
        array.iter().copied().collect()
    }
}

fn iou(a: ([f64; 3], [f64; 3]), b: ([f64; 3], [f64; 3])) -> f64 {
    let mut inter = 1.0;
    let (mut va, mut vb) = (1.0, 1.0);
    for k in 0..3 {
        let (lo_a, hi_a) = (a.0[k] - a.1[k] / 2.0, a.0[k] + a.1[k] / 2.0);
        let (lo_b, hi_b) = (b.0[k] - b.1[k] / 2.0, b.0[k] + b.1[k] / 2.0);
        inter *= (hi_a.min(hi_b) - lo_a.max(lo_b)).max(0.0);
        va *= a.1[k];
        vb *= b.1[k];
    }
    inter / (va + vb - inter)
}

fn quantiles(values: &mut [f64]) -> String {
    values.sort_by(f64::total_cmp);
    let q = |p: f64| values[((values.len() - 1) as f64 * p).round() as usize];
    format!(
        "min {:.3} p10 {:.3} p25 {:.3} median {:.3} p75 {:.3} p90 {:.3} max {:.3} (n = {})",
        q(0.0),
        q(0.1),
        q(0.25),
        q(0.5),
        q(0.75),
        q(0.9),
        q(1.0),
        values.len()
    )
}

#[test]
fn lift_matches_the_demo_truth() {
    let noisy = tempfile::tempdir().expect("tempdir");
    let exact = tempfile::tempdir().expect("tempdir");
    let options = DemoOptions::default().with_scenes(scene_count());
    write_demo(noisy.path(), &options).expect("noisy demo");
    write_demo(exact.path(), &options.clone().with_depth_noise(false)).expect("exact demo");

    let mut axis_deg = vec![];
    // [raw, as the depth states it]
    let mut zone_err_cm: [Vec<f64>; 2] = Default::default();
    let mut centre_err_cm: [Vec<f64>; 2] = Default::default();
    let mut ious: [Vec<f64>; 2] = Default::default();
    let mut ratios: [Vec<f64>; 3] = Default::default();
    let debug = std::env::var_os("MESA_LIFT_DEBUG").is_some();
    let mut scenes = 0;
    for table in std::fs::read_dir(noisy.path().join("scenes")).expect("scenes") {
        let table = table.expect("table").path();
        for scene in std::fs::read_dir(&table).expect("scene dir") {
            let scene = scene.expect("scene").path();
            let rel = scene.strip_prefix(noisy.path()).expect("rel").to_owned();
            let twin = exact.path().join(&rel);
            let truth: TruthScene = read(&scene.join("truth/scene.json"));
            let scene_id = scene.file_name().and_then(|n| n.to_str()).expect("id");
            let lifted = lift_scene(&scene.join("input"), scene_id, 0, &LiftConfig::default())
                .unwrap_or_else(|e| panic!("{}: {e}", rel.display()));
            let art = &lifted.artifact;
            scenes += 1;
            let scales = [1.0, truth.depth.scale];

            let truth_tfc = matrix(truth.table_from_camera);
            let lift_tfc = matrix(art.table_from_camera);
            let z_truth = Vector3::new(truth_tfc[(2, 0)], truth_tfc[(2, 1)], truth_tfc[(2, 2)]);
            let z_lift = Vector3::new(lift_tfc[(2, 0)], lift_tfc[(2, 1)], lift_tfc[(2, 2)]);
            axis_deg.push(
                z_truth
                    .normalize()
                    .dot(&z_lift.normalize())
                    .clamp(-1.0, 1.0)
                    .acos()
                    .to_degrees(),
            );
            let tz = truth.table.zone_cm.0;
            let truth_zone = [tz[1] - tz[0], tz[3] - tz[2]];
            for (errors, scale) in zone_err_cm.iter_mut().zip(scales) {
                errors.push(
                    (art.zone_cm.0[1] - truth_zone[0] * scale)
                        .abs()
                        .max((art.zone_cm.0[3] - truth_zone[1] * scale).abs()),
                );
            }
            if debug {
                println!(
                    "{rel:?} depth scale {:.4}: zone {:.1} x {:.1} (truth {:.1} x {:.1})",
                    truth.depth.scale,
                    art.zone_cm.0[1],
                    art.zone_cm.0[3],
                    truth_zone[0],
                    truth_zone[1]
                );
            }

            // Visible-surface boxes from the exact twin, in the true table frame.
            let (w, h) = (truth.camera.width as usize, truth.camera.height as usize);
            let depth = exact_depth(&twin.join("input"), w, h);
            let masks = exact_masks(&twin.join("input"), w);
            for instance in &art.instances {
                let Some(pixels) = masks.get(&instance.mask_id) else {
                    continue;
                };
                let mut lo = [f64::INFINITY; 3];
                let mut hi = [f64::NEG_INFINITY; 3];
                for &(u, v) in pixels {
                    let d = f64::from(depth[v * w + u]);
                    if !d.is_finite() {
                        continue;
                    }
                    let c = &truth.camera;
                    let cam = Vector4::new(
                        (u as f64 - c.cx) * d / c.fx,
                        (v as f64 - c.cy) * d / c.fy,
                        d,
                        1.0,
                    );
                    let t = truth_tfc * cam;
                    for k in 0..3 {
                        lo[k] = lo[k].min(t[k]);
                        hi[k] = hi[k].max(t[k]);
                    }
                }
                if !lo[0].is_finite() {
                    continue;
                }
                lo[2] = lo[2].max(0.0);
                let (centre, size) = (instance.center_cm.0, instance.size_cm.0);
                for (slot, scale) in scales.into_iter().enumerate() {
                    let truth_box: ([f64; 3], [f64; 3]) = (
                        std::array::from_fn(|k| (lo[k] + hi[k]) * 50.0 * scale),
                        std::array::from_fn(|k| ((hi[k] - lo[k]) * 100.0 * scale).max(0.1)),
                    );
                    let err = (0..3)
                        .map(|k| (centre[k] - truth_box.0[k]).powi(2))
                        .sum::<f64>()
                        .sqrt();
                    centre_err_cm[slot].push(err);
                    ious[slot].push(iou((centre, size), truth_box));
                    if slot == 1 {
                        for (k, ratio) in ratios.iter_mut().enumerate() {
                            ratio.push(size[k] / truth_box.1[k]);
                        }
                        if debug {
                            println!(
                                "{rel:?} {:<16} truth size {:>5.1} {:>5.1} {:>5.1} \
                                 centre error {:>5.2} {:>5.2} {:>5.2} size ratio {:.2} {:.2} \
                                 {:.2} IoU {:.2}",
                                instance.instance,
                                truth_box.1[0],
                                truth_box.1[1],
                                truth_box.1[2],
                                centre[0] - truth_box.0[0],
                                centre[1] - truth_box.0[1],
                                centre[2] - truth_box.0[2],
                                size[0] / truth_box.1[0],
                                size[1] / truth_box.1[1],
                                size[2] / truth_box.1[2],
                                iou((centre, size), truth_box)
                            );
                        }
                    }
                }
            }
        }
    }
    assert_eq!(scenes, scene_count());
    println!("table z axis error (deg):   {}", quantiles(&mut axis_deg));
    for (slot, name) in ["raw", "as the depth states it"].iter().enumerate() {
        println!("-- against the truth {name}:");
        println!(
            "zone size error (cm):       {}",
            quantiles(&mut zone_err_cm[slot])
        );
        println!(
            "box centre error (cm):      {}",
            quantiles(&mut centre_err_cm[slot])
        );
        println!("box 3D IoU:                 {}", quantiles(&mut ious[slot]));
    }
    for (axis, r) in ["x", "y", "z"].iter().zip(ratios.iter_mut()) {
        println!("size ratio lift/truth {axis}:   {}", quantiles(r));
    }
    // The targets: the z axis within 1° in every scene, the zone within 2 cm in every
    // scene, the median centre error within 1.5 cm and the median IoU at least 0.7.
    assert!(axis_deg.iter().all(|a| *a <= 1.0), "z axis: {axis_deg:?}");
    let [_, zone] = &zone_err_cm;
    assert!(zone.iter().all(|e| *e <= 2.0), "zone: {zone:?}");
    let median = |v: &[f64]| v[v.len() / 2];
    assert!(median(&centre_err_cm[1]) <= 1.5, "median centre error");
    assert!(median(&ious[1]) >= 0.7, "median IoU");
}
