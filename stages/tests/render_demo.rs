//! `render` against the demo's truth: each scene's true layout, drawn from the demo's own
//! camera with its assets read back from their GLB files, must cover the same pixels per
//! object as the demo's masks (which `stages/tests/demo.rs` checks against rays cast at the
//! placed triangles): IoU ≥ 0.9 for every object visible in the photo.
//!
//! `MESA_RENDER_DUMP=DIR` also writes the renders (truth camera and scene views) to DIR, to
//! look at.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use mesa_schemas::artifacts::{TruthInstances, TruthScene};
use mesa_schemas::DatasetLayout;
use mesa_stages::demo::{write_demo, DemoOptions};
use mesa_stages::image_io::{decode_png, PixelLayout};
use mesa_stages::mesh::Affine3;
use mesa_stages::raster::PinholeCamera;
use mesa_stages::render::{
    load_render_asset, place_layout, LayoutScene, RenderAsset, RenderConfig, SceneView, ViewCamera,
};

struct Workspace {
    _dir: tempfile::TempDir,
    path: PathBuf,
}

/// Six scenes (every table type, both mask forms), exact masks.
fn workspace() -> &'static Workspace {
    static WS: OnceLock<Workspace> = OnceLock::new();
    WS.get_or_init(|| {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("demo");
        let options = DemoOptions::default()
            .with_scenes(6)
            .with_seed(7)
            .with_depth_noise(false);
        write_demo(&path, &options).expect("demo");
        Workspace { _dir: dir, path }
    })
}

fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> T {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn scenes(ws: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for table in std::fs::read_dir(ws.join("scenes")).expect("scenes") {
        for scene in std::fs::read_dir(table.expect("entry").path()).expect("table") {
            out.push(scene.expect("entry").path());
        }
    }
    out.sort();
    out
}

fn load_assets(ws: &Path, layout: &DatasetLayout) -> BTreeMap<String, RenderAsset> {
    let mut assets = BTreeMap::new();
    for object in &layout.objects {
        let uid = &object.retrieved_uid;
        if !assets.contains_key(uid) {
            let path = ws.join("assets/library").join(format!("{uid}.glb"));
            let bytes = std::fs::read(&path).expect("glb");
            // The demo's assets face +Z in glTF: no front alignment.
            let asset = load_render_asset(&bytes, 0.0, 1024).expect("asset");
            assets.insert(uid.clone(), asset);
        }
    }
    assets
}

/// Per mask id, the pixels of its mask (label image, or one PNG per id).
fn read_masks(scene: &Path, ids: &[u32], width: u32, height: u32) -> BTreeMap<u32, Vec<bool>> {
    let n = (width * height) as usize;
    let label = scene.join("input/masks.png");
    let mut out = BTreeMap::new();
    if label.is_file() {
        let img = decode_png(&std::fs::read(&label).expect("masks")).expect("png");
        assert_eq!((img.width, img.height), (width, height));
        assert!(
            matches!(img.layout, PixelLayout::Gray8 | PixelLayout::Gray16),
            "{}: {:?}",
            label.display(),
            img.layout
        );
        let labels: Vec<u32> = img.samples.iter().map(|&v| u32::from(v)).collect();
        for &id in ids {
            out.insert(id, labels.iter().map(|&l| l == id).collect());
        }
    } else {
        for &id in ids {
            let path = scene.join(format!("input/masks/{id}.png"));
            let img = decode_png(&std::fs::read(&path).expect("mask")).expect("png");
            assert_eq!(img.samples.len(), n, "{}", path.display());
            out.insert(id, img.samples.iter().map(|&v| v > 0).collect());
        }
    }
    out
}

/// Grows a mask by `radius` pixels (a square neighbourhood), as the demo grows instance PNGs.
fn grow(mask: &[bool], width: usize, height: usize, radius: usize) -> Vec<bool> {
    let mut out = mask.to_vec();
    for y in 0..height {
        for x in 0..width {
            if !mask[y * width + x] {
                continue;
            }
            for ny in y.saturating_sub(radius)..=(y + radius).min(height - 1) {
                for nx in x.saturating_sub(radius)..=(x + radius).min(width - 1) {
                    out[ny * width + nx] = true;
                }
            }
        }
    }
    out
}

fn iou(a: &[bool], b: &[bool]) -> f64 {
    let inter = a.iter().zip(b).filter(|(x, y)| **x && **y).count();
    let union = a.iter().zip(b).filter(|(x, y)| **x || **y).count();
    if union == 0 {
        1.0
    } else {
        inter as f64 / union as f64
    }
}

fn dump_dir() -> Option<PathBuf> {
    std::env::var_os("MESA_RENDER_DUMP").map(PathBuf::from)
}

#[test]
fn renders_cover_the_demo_masks_object_by_object() {
    let ws = &workspace().path;
    let config = RenderConfig::default();
    let mut worst = (1.0f64, String::new());
    let mut checked = 0;
    let mut failures = Vec::new();
    for scene in scenes(ws) {
        let scene_id = scene
            .file_name()
            .expect("name")
            .to_string_lossy()
            .into_owned();
        let layout: DatasetLayout = read_json(&scene.join("truth/layout.json"));
        let truth: TruthScene = read_json(&scene.join("truth/scene.json"));
        let instances: TruthInstances = read_json(&scene.join("truth/instances.json"));
        let assets = load_assets(ws, &layout);
        let (placed, notes) = place_layout(&layout, |uid| Ok(&assets[uid])).expect("placed");
        assert!(notes.is_empty(), "{scene_id}: {notes:?}");
        let c = &truth.camera;
        let camera = ViewCamera {
            intrinsics: PinholeCamera {
                width: c.width,
                height: c.height,
                fx: c.fx,
                fy: c.fy,
                cx: c.cx,
                cy: c.cy,
            },
            table_from_camera: Affine3::from_rows_4x4(truth.table_from_camera),
            look_at_m: [0.0; 3],
        };
        let lit = LayoutScene::new(&layout, &placed, &config);
        let view = lit.render_from("truth", &camera, &config).expect("render");
        let (w, h) = (c.width as usize, c.height as usize);
        let objects: Vec<_> = instances.instances.iter().filter(|i| !i.support).collect();
        let ids: Vec<u32> = objects.iter().map(|i| i.id).collect();
        let masks = read_masks(&scene, &ids, c.width, c.height);
        for truth_instance in &objects {
            let name = truth_instance.instance.as_deref().expect("object instance");
            let index = layout
                .objects
                .iter()
                .position(|o| o.instance == name)
                .expect("instance in the layout");
            let drawn: Vec<bool> = view
                .picture
                .instances
                .iter()
                .map(|&i| i == index as u32 + 1)
                .collect();
            let drawn = grow(&drawn, w, h, truth.masks.dilation_px as usize);
            let value = iou(&drawn, &masks[&truth_instance.id]);
            if value < 0.9 {
                failures.push(format!(
                    "{scene_id}: {name}: IoU {value:.3} with its mask ({} visible px)",
                    truth_instance.visible_px
                ));
            }
            if value < worst.0 {
                worst = (
                    value,
                    format!("{scene_id}/{name} ({} px)", truth_instance.visible_px),
                );
            }
            checked += 1;
        }
        if let Some(dir) = dump_dir() {
            std::fs::create_dir_all(&dir).expect("dump dir");
            std::fs::write(dir.join(format!("{scene_id}_truth.png")), &view.png).expect("dump");
            for v in SceneView::ALL {
                let rendered = lit.render_view(v, &config).expect("render");
                std::fs::write(
                    dir.join(format!("{scene_id}_{}.png", v.name())),
                    &rendered.png,
                )
                .expect("dump");
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    assert!(checked > 40, "{checked} objects checked");
    eprintln!("{checked} objects: worst IoU {:.4} ({})", worst.0, worst.1);
}
