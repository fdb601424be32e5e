//! Times one rendered view (the render bench's scene: the front view of `dressing_table_0001`
//! of `mesa demo --seed 7`, 15 objects, 512×512, 2×2 samples at silhouettes, shadows, PNG
//! encoded, assets loaded), the mesa side of `bench/compare_blender.sh`: one warm-up, then
//! `--repeat` views timed one by one on one thread, each with its scene's shadow map (as
//! Blender's render call pays for its shadows), with the `mesa` executable's allocator
//! (mimalloc, as `mesa render` runs). Prints one JSON line: the seconds of each.
//!
//! With `--parts`, prints the minimum over the runs of each part of a view instead: the
//! shadow map, one visibility pass, the picture with the shadow map built beforehand, the
//! PNG (a profiling aid).
//!
//! With `--serve`, the timed views are asked for on standard input instead, so that a
//! comparison script can alternate them with its own (`bench/render_blender.py --alternate`):
//! after the warm-up, each line read, `N [WARM_SECONDS]`, asks for untimed views for
//! WARM_SECONDS (at least one: the caches and the core's speed back to their steady state
//! after the other side's turn), then N timed views, printed as one JSON line, `{"runs_s":
//! [...]}`. At the end of the input, the usual line is printed, its runs those served.
//!
//! `cargo run --release -p mesa-stages --example render_timing -- [--repeat 20] [--parts | --serve]`

#[path = "support/serve.rs"]
mod serve;

use std::collections::BTreeMap;
use std::convert::Infallible;
use std::error::Error;
use std::hint::black_box;
use std::time::Instant;

use mesa_schemas::DatasetLayout;
use mesa_stages::demo::{write_demo, DemoOptions};
use mesa_stages::mesh::Affine3;
use mesa_stages::raster::{visibility, ShadowMap};
use mesa_stages::render::{
    camera, draw_items, load_render_asset, place_layout, render_picture_shadowed, LayoutScene,
    RenderConfig, SceneView,
};

/// The allocator of the `mesa` executable (pipeline/src/main.rs), so that the figure is the
/// one the `render` stage gets.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn min_ms(repeat: usize, mut f: impl FnMut()) -> f64 {
    (0..repeat)
        .map(|_| {
            let start = Instant::now();
            f();
            start.elapsed().as_secs_f64() * 1e3
        })
        .fold(f64::INFINITY, f64::min)
}

fn main() -> Result<(), Box<dyn Error>> {
    let mut args = std::env::args().skip(1);
    let (mut repeat, mut parts, mut serving) = (20, false, false);
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--repeat" => repeat = args.next().ok_or("--repeat N")?.parse()?,
            "--parts" => parts = true,
            "--serve" => serving = true,
            _ => return Err("usage: render_timing [--repeat N] [--parts | --serve]".into()),
        }
    }
    if parts && serving {
        return Err("render_timing: --parts and --serve exclude each other".into());
    }
    let dir = tempfile::tempdir()?;
    write_demo(
        dir.path(),
        &DemoOptions::default().with_scenes(5).with_seed(7),
    )?;
    let scene = dir
        .path()
        .join("scenes/dressing_table/dressing_table_0001/truth/layout.json");
    let layout: DatasetLayout = serde_json::from_str(&std::fs::read_to_string(scene)?)?;
    let config = RenderConfig::default();
    let mut assets = BTreeMap::new();
    for object in &layout.objects {
        let uid = &object.retrieved_uid;
        if !assets.contains_key(uid) {
            let path = dir.path().join(format!("assets/library/{uid}.glb"));
            let asset = load_render_asset(&std::fs::read(path)?, 0.0, config.max_texture_px)?;
            assets.insert(uid.clone(), asset);
        }
    }
    let (placed, _) = place_layout(&layout, |uid| Ok(&assets[uid]))?;
    let view_once = || {
        LayoutScene::new(&layout, &placed, &config)
            .render_view(SceneView::Front, &config)
            .expect("render")
    };
    if !parts {
        black_box(view_once());
        let timed_view = || {
            let start = Instant::now();
            black_box(view_once());
            start.elapsed().as_secs_f64()
        };
        let runs: Vec<f64> = if serving {
            serve::served("runs_s", || Ok::<_, Infallible>(timed_view()))?
        } else {
            (0..repeat).map(|_| timed_view()).collect()
        };
        let triangles: usize = placed.iter().map(|p| p.asset.triangles).sum();
        println!(
            "{}",
            serde_json::json!({ "objects": placed.len(), "triangles": triangles, "runs_s": runs })
        );
        return Ok(());
    }
    let scene = LayoutScene::new(&layout, &placed, &config);
    let items = draw_items(&placed, Some(&scene.table));
    let view = camera::scene_camera(
        SceneView::Front,
        &scene.frame,
        config.width_px,
        config.height_px,
        config.fov_x_deg,
        config.distance_factor,
    );
    let camera_from_table = view
        .table_from_camera
        .inverse()
        .unwrap_or(Affine3::IDENTITY);
    let shadow = ShadowMap::of_lighting(&scene.lighting, &items);
    let picture = render_picture_shadowed(
        &items,
        &view,
        &scene.lighting,
        config.supersampling,
        shadow.as_ref(),
    );
    let parts = [
        (
            "shadow_map",
            min_ms(repeat, || {
                black_box(ShadowMap::of_lighting(&scene.lighting, &items));
            }),
        ),
        (
            "visibility_pass",
            min_ms(repeat, || {
                black_box(visibility(&view.intrinsics, &camera_from_table, &items));
            }),
        ),
        (
            "picture_without_shadow_map",
            min_ms(repeat, || {
                black_box(render_picture_shadowed(
                    &items,
                    &view,
                    &scene.lighting,
                    config.supersampling,
                    shadow.as_ref(),
                ));
            }),
        ),
        (
            "png",
            min_ms(repeat, || {
                black_box(picture.png(config.background).expect("png"));
            }),
        ),
        (
            "view_with_shadow_map",
            min_ms(repeat, || {
                black_box(view_once());
            }),
        ),
    ];
    for (name, ms) in parts {
        println!("{name:>28}: {ms:8.3} ms");
    }
    Ok(())
}
