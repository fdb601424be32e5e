//! The readers of a scene's lift inputs on arbitrary bytes: the COCO RLE decoder, depth.npy
//! (ndarray-npy behind mesa's shape check), depth.png, masks.png, masks/<id>.png, image.png,
//! camera.json and instances.json (with its RLE masks). Every input must be read or refused
//! with an error, never a panic or an allocation the file does not justify.
//!
//! An input is a 5-byte header and a file: byte 0 picks the reader (low 3 bits; bit 7 adds a
//! disparity calibration to the depth readers), bytes 1-2 and 3-4 are the width and height
//! (u16, little-endian) the masks and the photo are checked against, the rest is the file,
//! written where the reader looks for it (the readers take paths, as lift calls them).
#![no_main]

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;
use mesa_schemas::artifacts::{CalibrationKind, DepthCalibration, InstanceEntry, InstancesJson};
use mesa_stages::lift::inputs::{
    read_camera, read_depth, read_instances, read_masks, read_photo, Camera, Intrinsics,
};
use mesa_stages::lift::rle;
use mesa_stages::lift::LiftConfig;

/// Masks of at most this many pixels are decoded: `rle::decode` accepts up to
/// `rle::MAX_PIXELS` (2^28), whose index list is 1 GiB; lift reads such a mask as well, but
/// at that size every input would take seconds and leave nothing else explored.
const FUZZ_MAX_PIXELS: u64 = 1 << 22;

/// A scene folder of this process, emptied before each input.
fn scene_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let base = if Path::new("/dev/shm").is_dir() {
            PathBuf::from("/dev/shm")
        } else {
            std::env::temp_dir()
        };
        base.join(format!("mesa-fuzz-lift-{}", std::process::id()))
    })
}

fn fresh_scene() -> &'static Path {
    let dir = scene_dir();
    let _ = std::fs::remove_dir_all(dir);
    std::fs::create_dir_all(dir).expect("the fuzz scene folder");
    dir
}

/// The instances the label-image readers are checked against: ids 1 to 8.
fn instances() -> &'static [InstanceEntry] {
    static LIST: OnceLock<Vec<InstanceEntry>> = OnceLock::new();
    LIST.get_or_init(|| {
        let list: Vec<serde_json::Value> = (1..=8)
            .map(|id| {
                serde_json::json!({
                    "id": id, "label": "mug", "description": "a mug", "support": false
                })
            })
            .collect();
        let parsed: InstancesJson =
            serde_json::from_value(serde_json::json!({ "instances": list })).expect("instances");
        parsed.instances
    })
}

fn camera(calibrated: bool) -> Camera {
    Camera {
        intrinsics: Intrinsics {
            width: 640,
            height: 480,
            fx: 525.0,
            fy: 525.0,
            cx: 320.0,
            cy: 240.0,
            source: "intrinsics",
        },
        calibration: calibrated.then_some(DepthCalibration {
            kind: CalibrationKind::Disparity,
            scale: 0.5,
            shift: 0.1,
        }),
    }
}

/// Whether every RLE in an instances.json is small enough to decode here.
fn rle_sizes_are_small(value: &serde_json::Value) -> bool {
    let small = |rle: &serde_json::Value| {
        rle.get("size")
            .and_then(|s| s.as_array())
            .and_then(|s| Some(s.first()?.as_u64()?.checked_mul(s.get(1)?.as_u64()?)?))
            .is_none_or(|n| n <= FUZZ_MAX_PIXELS)
    };
    match value.get("instances").and_then(|i| i.as_array()) {
        Some(list) => list.iter().filter_map(|i| i.get("rle")).all(small),
        None => true,
    }
}

fuzz_target!(|data: &[u8]| {
    let [selector, w0, w1, h0, h1, file @ ..] = data else {
        return;
    };
    let (width, height) = (
        usize::from(u16::from_le_bytes([*w0, *w1])),
        usize::from(u16::from_le_bytes([*h0, *h1])),
    );
    // The masks and the photo are read at this size: keep it to what FUZZ_MAX_PIXELS allows.
    if (width * height) as u64 > FUZZ_MAX_PIXELS && selector & 0x07 >= 4 {
        return;
    }
    let config = LiftConfig::default();
    let calibrated = selector & 0x80 != 0;
    match selector & 0x07 {
        0 => {
            let Ok(value) = serde_json::from_slice::<serde_json::Value>(file) else {
                return;
            };
            let value = serde_json::json!({ "instances": [{ "rle": value }] });
            if rle_sizes_are_small(&value) {
                let _ = rle::decode(&value["instances"][0]["rle"]);
            }
        }
        1 => {
            let dir = fresh_scene();
            std::fs::write(dir.join("depth.npy"), file).expect("write");
            let _ = read_depth(dir, &camera(calibrated), &config);
        }
        2 => {
            let dir = fresh_scene();
            std::fs::write(dir.join("depth.png"), file).expect("write");
            let _ = read_depth(dir, &camera(calibrated), &config);
        }
        3 => {
            let dir = fresh_scene();
            std::fs::write(dir.join("camera.json"), file).expect("write");
            let _ = read_camera(&dir.join("camera.json"), &config);
        }
        4 => {
            let small = serde_json::from_slice::<serde_json::Value>(file)
                .map_or(true, |v| rle_sizes_are_small(&v));
            if !small {
                return;
            }
            let dir = fresh_scene();
            std::fs::write(dir.join("instances.json"), file).expect("write");
            if let Ok(list) = read_instances(&dir.join("instances.json")) {
                let _ = read_masks(dir, &list, width, height);
            }
        }
        5 => {
            let dir = fresh_scene();
            std::fs::write(dir.join("masks.png"), file).expect("write");
            let _ = read_masks(dir, instances(), width, height);
        }
        6 => {
            let dir = fresh_scene();
            std::fs::create_dir_all(dir.join("masks")).expect("mkdir");
            std::fs::write(dir.join("masks/1.png"), file).expect("write");
            let _ = read_masks(dir, &instances()[..1], width, height);
        }
        _ => {
            let dir = fresh_scene();
            std::fs::write(dir.join("image.png"), file).expect("write");
            let _ = read_photo(dir, width, height);
        }
    }
});
