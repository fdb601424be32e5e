//! Each bad input of a scene is a clear failure naming the file, the field and the fix; and
//! each accepted input form (label PNG, per-instance PNGs, RLE, npy, calibrated disparity, FOV)
//! gives the same boxes on the same synthetic scene.

use std::path::PathBuf;

use image::{GrayImage, ImageBuffer, Luma};
use mesa_stages::lift::rle::encode_counts;
use mesa_stages::lift::{lift_scene, LiftConfig, LiftError, LiftOutput};
use ndarray::Array2;
use ndarray_npy::WriteNpyExt;
use serde_json::{json, Value};

const W: u32 = 96;
const H: u32 = 72;
const FX: f64 = 80.0;

/// A camera 0.8 m above a table, looking down 45°, with two boxes standing on it. Returns
/// depth (m, row-major) and labels (0 = table, 1, 2 = boxes).
fn render() -> (Vec<f32>, Vec<u8>) {
    let (cx, cy) = (f64::from(W) / 2.0, f64::from(H) / 2.0);
    let tilt = 45f64.to_radians();
    // Camera frame: x right, y down, z forward. Table normal (up) in camera coordinates.
    let up = [0.0, -tilt.cos(), -tilt.sin()];
    let height = 0.8;
    let boxes = [([-0.08, 0.95], 0.06, 0.10), ([0.12, 1.1], 0.05, 0.04)]; // (x, along-floor), half width, height
    let mut depth = vec![0f32; (W * H) as usize];
    let mut labels = vec![0u8; (W * H) as usize];
    for v in 0..H {
        for u in 0..W {
            let ray = [(f64::from(u) - cx) / FX, (f64::from(v) - cy) / FX, 1.0];
            let dot = ray[0] * up[0] + ray[1] * up[1] + ray[2] * up[2];
            if dot >= -1e-6 {
                continue;
            }
            // Table plane: up·p = -height.
            let t = -height / dot;
            let p = [ray[0] * t, ray[1] * t, ray[2] * t];
            let mut best = (t, 0u8);
            // Boxes as vertical prisms: test the top face and the front face crudely by
            // marching along the ray.
            for (k, (centre, half, h)) in boxes.iter().enumerate() {
                let steps = 400;
                for s in 0..steps {
                    let tt = t * f64::from(s) / f64::from(steps);
                    let q = [ray[0] * tt, ray[1] * tt, ray[2] * tt];
                    let above = q[0] * up[0] + q[1] * up[1] + q[2] * up[2] + height;
                    // Along-floor coordinate: the component of q along the floor's forward axis.
                    let fwd = [0.0, tilt.sin(), -tilt.cos()];
                    let along = -(q[0] * fwd[0] + q[1] * fwd[1] + q[2] * fwd[2]);
                    if above >= 0.0
                        && above <= *h
                        && (q[0] - centre[0]).abs() <= *half
                        && (along - centre[1]).abs() <= *half
                    {
                        if tt < best.0 {
                            best = (tt, (k + 1) as u8);
                        }
                        break;
                    }
                }
            }
            let _ = p;
            let i = (v * W + u) as usize;
            depth[i] = (best.0 * ray[2]) as f32;
            labels[i] = best.1;
        }
    }
    (depth, labels)
}

struct Scene {
    dir: tempfile::TempDir,
}

impl Scene {
    /// The synthetic scene with a 16-bit depth.png, a label masks.png, intrinsics.
    fn new() -> Self {
        let scene = Self {
            dir: tempfile::tempdir().expect("tempdir"),
        };
        std::fs::create_dir_all(scene.input()).expect("mkdir");
        let (depth, labels) = render();
        scene.depth_png(&depth);
        GrayImage::from_raw(W, H, labels)
            .expect("labels")
            .save(scene.path("masks.png"))
            .expect("save");
        scene.json("camera.json", &json!({"width": W, "height": H, "fx": FX, "fy": FX, "cx": f64::from(W) / 2.0, "cy": f64::from(H) / 2.0}));
        scene.json(
            "instances.json",
            &json!({"instances": [
            {"id": 1, "label": "box", "description": "a tall box"},
            {"id": 2, "label": "box", "description": "a flat box"}]}),
        );
        scene
    }
    fn input(&self) -> PathBuf {
        self.dir.path().join("input")
    }
    fn path(&self, name: &str) -> PathBuf {
        self.input().join(name)
    }
    fn depth_png(&self, depth_m: &[f32]) {
        let mm: Vec<u16> = depth_m
            .iter()
            .map(|d| (d * 1000.0).round() as u16)
            .collect();
        ImageBuffer::<Luma<u16>, _>::from_raw(W, H, mm)
            .expect("depth")
            .save(self.path("depth.png"))
            .expect("save");
    }
    fn json(&self, name: &str, value: &Value) {
        std::fs::write(self.path(name), value.to_string()).expect("write");
    }
    fn lift(&self) -> Result<LiftOutput, LiftError> {
        self.lift_with(&LiftConfig {
            plane_min_points: 100,
            min_points: 5,
            ..LiftConfig::default()
        })
    }
    fn lift_with(&self, config: &LiftConfig) -> Result<LiftOutput, LiftError> {
        lift_scene(&self.input(), "synthetic", 0, config)
    }
    fn error(&self) -> String {
        match self.lift() {
            Ok(_) => panic!("expected a failure"),
            Err(e) => e.to_string(),
        }
    }
}

fn assert_mentions(message: &str, parts: &[&str]) {
    for part in parts {
        assert!(message.contains(part), "{part:?} not in: {message}");
    }
}

fn boxes(out: &LiftOutput) -> Vec<([f64; 3], [f64; 3])> {
    out.artifact
        .instances
        .iter()
        .map(|i| (i.center_cm.0, i.size_cm.0))
        .collect()
}

#[test]
fn the_synthetic_scene_lifts_to_two_boxes_on_the_table() {
    let out = Scene::new().lift().expect("lifts");
    let names: Vec<&str> = out
        .artifact
        .instances
        .iter()
        .map(|i| i.instance.as_str())
        .collect();
    assert_eq!(names, ["box_0", "box_1"]);
    let heights: Vec<f64> = out
        .artifact
        .instances
        .iter()
        .map(|i| i.center_cm.0[2] + i.size_cm.0[2] / 2.0)
        .collect();
    assert!((heights[0] - 10.0).abs() < 1.5, "{heights:?}");
    assert!((heights[1] - 4.0).abs() < 1.5, "{heights:?}");
    // The table's normal in the camera frame is (0, -cos 45°, -sin 45°).
    let n = out.artifact.plane.normal_in_camera;
    assert!(
        (n[1] + std::f64::consts::FRAC_1_SQRT_2).abs() < 0.01
            && (n[2] + std::f64::consts::FRAC_1_SQRT_2).abs() < 0.01,
        "{n:?}"
    );
}

#[test]
fn every_mask_form_gives_the_same_boxes() {
    let reference = boxes(&Scene::new().lift().expect("labels"));
    let (_, labels) = render();
    // Per-instance PNGs.
    let scene = Scene::new();
    std::fs::remove_file(scene.path("masks.png")).expect("rm");
    std::fs::create_dir_all(scene.path("masks")).expect("mkdir");
    for id in [1u8, 2] {
        let bits: Vec<u8> = labels
            .iter()
            .map(|l| if *l == id { 255 } else { 0 })
            .collect();
        GrayImage::from_raw(W, H, bits)
            .expect("mask")
            .save(scene.path(&format!("masks/{id}.png")))
            .expect("save");
    }
    assert_eq!(boxes(&scene.lift().expect("per-instance")), reference);
    // COCO RLE in instances.json.
    let scene = Scene::new();
    std::fs::remove_file(scene.path("masks.png")).expect("rm");
    let rle = |id: u8| {
        encode_counts(
            W as usize,
            H as usize,
            &labels.iter().map(|l| *l == id).collect::<Vec<_>>(),
        )
    };
    scene.json(
        "instances.json",
        &json!({"instances": [
        {"id": 1, "label": "box", "rle": rle(1)}, {"id": 2, "label": "box", "rle": rle(2)}]}),
    );
    assert_eq!(boxes(&scene.lift().expect("rle")), reference);
}

#[test]
fn npy_disparity_and_fov_inputs_are_read() {
    let (depth, _) = render();
    let reference = boxes(&Scene::new().lift().expect("png"));
    // float32 metres in .npy, rounded to millimetres as the PNG is.
    let scene = Scene::new();
    std::fs::remove_file(scene.path("depth.png")).expect("rm");
    let mm: Vec<f32> = depth
        .iter()
        .map(|d| (d * 1000.0).round() / 1000.0)
        .collect();
    let array = Array2::from_shape_vec((H as usize, W as usize), mm.clone()).expect("shape");
    array
        .write_npy(std::fs::File::create(scene.path("depth.npy")).expect("create"))
        .expect("npy");
    let npy = boxes(&scene.lift().expect("npy"));
    for (a, b) in npy.iter().zip(&reference) {
        for k in 0..3 {
            assert!(
                (a.0[k] - b.0[k]).abs() < 0.05 && (a.1[k] - b.1[k]).abs() < 0.05,
                "{a:?} {b:?}"
            );
        }
    }
    // A disparity map 1/d stored as 2·(1/d) - 0.5, with the matching calibration.
    let disparity: Vec<f32> = mm
        .iter()
        .map(|d| if *d > 0.0 { 2.0 / d - 0.5 } else { 0.0 })
        .collect();
    let array = Array2::from_shape_vec((H as usize, W as usize), disparity).expect("shape");
    array
        .write_npy(std::fs::File::create(scene.path("depth.npy")).expect("create"))
        .expect("npy");
    scene.json("camera.json", &json!({"width": W, "height": H, "fx": FX, "fy": FX, "cx": f64::from(W) / 2.0, "cy": f64::from(H) / 2.0,
        "depth_calibration": {"kind": "disparity", "scale": 0.5, "shift": 0.25}}));
    let calibrated = boxes(&scene.lift().expect("disparity"));
    for (a, b) in calibrated.iter().zip(&npy) {
        for k in 0..3 {
            assert!((a.0[k] - b.0[k]).abs() < 0.05, "{a:?} {b:?}");
        }
    }
    // Only a FOV: fx = (W/2) / tan(fov/2).
    let fov = 2.0 * (f64::from(W) / 2.0 / FX).atan().to_degrees();
    let scene = Scene::new();
    scene.json(
        "camera.json",
        &json!({"width": W, "height": H, "fov_x_deg": fov}),
    );
    let out = scene.lift().expect("fov");
    assert_eq!(out.artifact.camera.source, "fov");
    assert!((out.artifact.camera.fx - FX).abs() < 1e-9);
}

#[test]
fn depth_and_mask_of_different_sizes() {
    let scene = Scene::new();
    GrayImage::new(W / 2, H / 2)
        .save(scene.path("masks.png"))
        .expect("save");
    assert_mentions(
        &scene.error(),
        &[
            "masks.png",
            "size",
            "is 48×36 but the depth map is 96×72",
            "fix:",
        ],
    );
}

#[test]
fn a_mask_id_missing_from_instances_and_the_reverse() {
    let scene = Scene::new();
    scene.json(
        "instances.json",
        &json!({"instances": [{"id": 1, "label": "box"}]}),
    );
    assert_mentions(
        &scene.error(),
        &[
            "masks.png",
            "label 2",
            "has no entry in instances.json",
            "fix: add it to instances.json",
        ],
    );
    let scene = Scene::new();
    scene.json("instances.json", &json!({"instances": [{"id": 1, "label": "box"}, {"id": 2, "label": "box"}, {"id": 3, "label": "cup"}]}));
    assert_mentions(
        &scene.error(),
        &[
            "instances.json",
            "id 3",
            "instance 3 (\"cup\") has no mask",
            "fix:",
        ],
    );
}

#[test]
fn an_empty_mask() {
    let scene = Scene::new();
    std::fs::remove_file(scene.path("masks.png")).expect("rm");
    std::fs::create_dir_all(scene.path("masks")).expect("mkdir");
    GrayImage::new(W, H)
        .save(scene.path("masks/1.png"))
        .expect("save");
    scene.json(
        "instances.json",
        &json!({"instances": [{"id": 1, "label": "box"}]}),
    );
    assert_mentions(
        &scene.error(),
        &[
            "instances.json",
            "id 1",
            "the mask of instance 1 (\"box\") is empty",
            "fix:",
        ],
    );
}

#[test]
fn a_mask_without_valid_depth() {
    let scene = Scene::new();
    let (mut depth, labels) = render();
    for (d, l) in depth.iter_mut().zip(&labels) {
        if *l == 2 {
            *d = 0.0;
        }
    }
    scene.depth_png(&depth);
    assert_mentions(
        &scene.error(),
        &[
            "masks.png",
            "id 2",
            "none of the",
            "pixels of instance 2",
            "has a valid depth",
            "fix:",
        ],
    );
}

#[test]
fn all_zero_and_all_nan_depth() {
    let scene = Scene::new();
    scene.depth_png(&vec![0.0; (W * H) as usize]);
    assert_mentions(&scene.error(), &["depth.png", "has no valid depth", "fix:"]);
    let scene = Scene::new();
    std::fs::remove_file(scene.path("depth.png")).expect("rm");
    let array = Array2::from_elem((H as usize, W as usize), f32::NAN);
    array
        .write_npy(std::fs::File::create(scene.path("depth.npy")).expect("create"))
        .expect("npy");
    assert_mentions(&scene.error(), &["depth.npy", "has no valid depth"]);
}

#[test]
fn an_eight_bit_depth_png() {
    let scene = Scene::new();
    GrayImage::new(W, H)
        .save(scene.path("depth.png"))
        .expect("save");
    assert_mentions(
        &scene.error(),
        &[
            "depth.png",
            "L8",
            "not a 16-bit single-channel PNG",
            "fix: write depth as 16-bit",
        ],
    );
}

#[test]
fn missing_intrinsics_without_a_fov() {
    let scene = Scene::new();
    scene.json("camera.json", &json!({"width": W, "height": H}));
    let config = LiftConfig {
        default_fov_x_deg: 0.0,
        plane_min_points: 100,
        ..LiftConfig::default()
    };
    let message = scene
        .lift_with(&config)
        .expect_err("no intrinsics")
        .to_string();
    assert_mentions(
        &message,
        &[
            "camera.json",
            "fx",
            "no intrinsics",
            "default_fov_x_deg",
            "fix: add fov_x_deg",
        ],
    );
    // With the default FOV configured, the scene lifts and says which FOV it used.
    let out = scene.lift().expect("default fov");
    assert!(out
        .warnings
        .iter()
        .any(|w| w.contains("default_fov_x_deg = 60")));
}

#[test]
fn no_table_plane() {
    let scene = Scene::new();
    // Depth noise: no plane explains 30% of the points.
    let noise: Vec<f32> = (0..W * H)
        .map(|i| 0.5 + ((i.wrapping_mul(2_654_435_761) >> 7) % 1000) as f32 / 500.0)
        .collect();
    scene.depth_png(&noise);
    assert_mentions(
        &scene.error(),
        &[
            "no table plane",
            "background points",
            "expected at least 30%",
        ],
    );
}

#[test]
fn a_truncated_or_corrupt_image() {
    let scene = Scene::new();
    let bytes = std::fs::read(scene.path("depth.png")).expect("read");
    std::fs::write(scene.path("depth.png"), &bytes[..bytes.len() / 2]).expect("truncate");
    assert_mentions(
        &scene.error(),
        &[
            "depth.png",
            "cannot decode the image",
            "fix: re-export it as a complete PNG",
        ],
    );
    let scene = Scene::new();
    std::fs::write(scene.path("masks.png"), b"not a png at all").expect("corrupt");
    assert_mentions(&scene.error(), &["masks.png", "cannot decode the image"]);
}

/// The synthetic scene with a third instance: 9 scattered table pixels, a mask too
/// thin and broken to keep [lift] min_points = 10 points (isolated pixels: filtering keeps none).
fn scene_with_a_thin_mask() -> Scene {
    scene_with_a_pen_mask(false)
}

/// The scene with a pen on the table: nine single pixels along a row (`solid` false: too few
/// points survive filtering), or a solid 36×8 block over the same pixels (`solid` true).
fn scene_with_a_pen_mask(solid: bool) -> Scene {
    let scene = Scene::new();
    let (_, mut labels) = render();
    let (rows, step) = if solid {
        (H - 10..H - 2, 1)
    } else {
        (H - 3..H - 2, 4)
    };
    for row in rows {
        for u in (4..40).step_by(step) {
            let i = (row * W + u) as usize;
            assert_eq!(labels[i], 0, "the pen's mask lies on the table");
            labels[i] = 3;
        }
    }
    GrayImage::from_raw(W, H, labels)
        .expect("labels")
        .save(scene.path("masks.png"))
        .expect("save");
    scene.json(
        "instances.json",
        &json!({"instances": [
        {"id": 1, "label": "box", "description": "a tall box"},
        {"id": 2, "label": "box", "description": "a flat box"},
        {"id": 3, "label": "pen", "description": "a thin pen"}]}),
    );
    scene
}

fn names(out: &LiftOutput) -> Vec<&str> {
    out.artifact
        .instances
        .iter()
        .map(|i| i.instance.as_str())
        .collect()
}

#[test]
fn an_object_with_too_few_points_is_dropped_with_a_warning_and_the_scene_goes_on() {
    let scene = scene_with_a_thin_mask();
    let config = LiftConfig {
        plane_min_points: 100,
        ..LiftConfig::default()
    };
    assert_eq!(config.min_points, 10, "the default this test is about");
    let out = scene.lift_with(&config).expect("the scene lifts");
    assert_eq!(
        names(&out),
        ["box_0", "box_1"],
        "the other objects are kept"
    );
    let dropped = &out.artifact.dropped;
    assert_eq!(dropped.len(), 1, "{dropped:?}");
    assert_eq!(
        (dropped[0].instance.as_str(), dropped[0].mask_id),
        ("pen_0", 3)
    );
    let kept = dropped[0].points_kept;
    assert!(kept < 9, "{kept}");
    let warning = out
        .warnings
        .iter()
        .find(|w| w.contains("dropped"))
        .expect("a warning");
    assert_mentions(
        warning,
        &[
            "pen_0",
            "instance id 3",
            &format!("keeps {kept} points"),
            "[lift] min_points = 10",
            "lower [lift] min_points",
            "input/masks.png",
        ],
    );
    // The warning and lift.json's reason name the masks within the scene folder, not where
    // the dataset is: a copy elsewhere (another node's mount) writes the same bytes.
    let location = scene.dir.path().to_string_lossy().into_owned();
    assert!(!warning.contains(&location), "{warning}");
    assert!(
        !dropped[0].reason.contains(&location),
        "{}",
        dropped[0].reason
    );
    assert!(
        dropped[0].reason.contains("input/masks.png"),
        "{}",
        dropped[0].reason
    );
    // The controls: the scene without the thin mask keeps both boxes and drops nothing, and a
    // solid mask of the pen over the same pixels keeps enough points to be lifted (so it is
    // the thinness that drops it, not the place or the label).
    let out = Scene::new().lift_with(&config).expect("the scene lifts");
    assert_eq!(names(&out), ["box_0", "box_1"]);
    assert!(out.artifact.dropped.is_empty());
    assert!(!out.warnings.iter().any(|w| w.contains("dropped")));
    let out = scene_with_a_pen_mask(true)
        .lift_with(&config)
        .expect("the scene lifts");
    assert_eq!(names(&out), ["box_0", "box_1", "pen_0"]);
    assert!(
        out.artifact.dropped.is_empty(),
        "{:?}",
        out.artifact.dropped
    );
}

#[test]
fn a_scene_whose_every_object_is_dropped_fails_naming_the_setting() {
    // Only the thin mask is an object; the boxes are left to the background.
    let scene = scene_with_a_thin_mask();
    let (_, labels) = render();
    let thin = image::open(scene.path("masks.png"))
        .expect("masks")
        .to_luma8();
    let only_thin: Vec<u8> = thin
        .as_raw()
        .iter()
        .zip(&labels)
        .map(|(&now, &boxes)| if boxes == 0 { now } else { 0 })
        .collect();
    GrayImage::from_raw(W, H, only_thin)
        .expect("labels")
        .save(scene.path("masks.png"))
        .expect("save");
    scene.json(
        "instances.json",
        &json!({"instances": [{"id": 3, "label": "pen", "description": "a thin pen"}]}),
    );
    let config = LiftConfig {
        plane_min_points: 100,
        ..LiftConfig::default()
    };
    let message = match scene.lift_with(&config) {
        Ok(out) => panic!("expected a failure, got {:?}", names(&out)),
        Err(e) => e.to_string(),
    };
    assert_mentions(
        &message,
        &[
            "masks.png",
            "every object keeps too few points",
            "pen_0 keeps",
            "[lift] min_points = 10",
            "fix:",
        ],
    );
}

/// A PNG of only a header (IHDR, an empty IDAT, IEND) claiming `width`×`height` 16-bit gray
/// pixels: a 77-byte file a decoder would allocate gigabytes for.
fn png_header_only(width: u32, height: u32) -> Vec<u8> {
    fn crc32(bytes: &[u8]) -> u32 {
        let mut crc = !0u32;
        for b in bytes {
            crc ^= u32::from(*b);
            for _ in 0..8 {
                crc = if crc & 1 == 1 {
                    (crc >> 1) ^ 0xEDB8_8320
                } else {
                    crc >> 1
                };
            }
        }
        !crc
    }
    fn chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
        out.extend((data.len() as u32).to_be_bytes());
        let mut body = kind.to_vec();
        body.extend(data);
        out.extend(&body);
        out.extend(crc32(&body).to_be_bytes());
    }
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = width.to_be_bytes().to_vec();
    ihdr.extend(height.to_be_bytes());
    ihdr.extend([16, 0, 0, 0, 0]);
    chunk(&mut out, b"IHDR", &ihdr);
    // An empty zlib stream: decoders read up to the first IDAT for the header.
    chunk(
        &mut out,
        b"IDAT",
        &[0x78, 0x9c, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01],
    );
    chunk(&mut out, b"IEND", &[]);
    out
}

#[test]
fn an_oversized_png_is_refused_on_its_header() {
    // The depth map: over max_image_pixels, named with the key and the fix.
    let scene = Scene::new();
    std::fs::write(scene.path("depth.png"), png_header_only(100_000, 100_000)).expect("write");
    let message = scene.error();
    assert_mentions(
        &message,
        &[
            "depth.png",
            "is 100000×100000 = 10000000000 pixels, more than [lift] max_image_pixels = 100000000",
            "downscale the image",
        ],
    );
    assert!(!message.contains("Memory limit"), "{message}");

    // A mask: its size is compared with the depth map's before it is decoded.
    let scene = Scene::new();
    std::fs::write(scene.path("masks.png"), png_header_only(100_000, 100_000)).expect("write");
    assert_mentions(
        &scene.error(),
        &["masks.png", "is 100000×100000 but the depth map is 96×72"],
    );

    // Control: the same header with the depth map's size passes the size check and fails
    // only in decoding (it has no pixels); and the intact scene fails once the limit is set
    // just below its own size.
    let scene = Scene::new();
    std::fs::write(scene.path("masks.png"), png_header_only(W, H)).expect("write");
    assert_mentions(&scene.error(), &["masks.png", "cannot decode the image"]);
    let scene = Scene::new();
    scene.lift().expect("the intact scene lifts");
    let tight = LiftConfig {
        plane_min_points: 100,
        min_points: 5,
        max_image_pixels: u64::from(W * H) - 1,
        ..LiftConfig::default()
    };
    match scene.lift_with(&tight) {
        Err(e) => assert_mentions(
            &e.to_string(),
            &["more than [lift] max_image_pixels = 6911"],
        ),
        Ok(_) => panic!("a depth map above the limit must fail"),
    }
}

#[test]
fn an_rle_mask_of_another_size_is_refused_before_its_runs_are_read() {
    let scene = Scene::new();
    std::fs::remove_file(scene.path("masks.png")).expect("rm");
    // Counts that do not decode: the size is what the message is about.
    let instances = |size: [u32; 2]| {
        json!({"instances": [{"id": 1, "label": "box",
            "rle": {"size": size, "counts": ["not", "numbers"]}}]})
    };
    scene.json("instances.json", &instances([10_000, 10_000]));
    assert_mentions(
        &scene.error(),
        &[
            "instances.json",
            "is 10000×10000 but the depth map is 96×72",
        ],
    );
    // Control: at the depth map's size the counts are read, and refused.
    scene.json("instances.json", &instances([H, W]));
    let message = scene.error();
    assert_mentions(&message, &["instances[0].rle"]);
    assert!(!message.contains("but the depth map is"), "{message}");
}
