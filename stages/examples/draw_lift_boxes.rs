//! Draws the boxes of a scene's `coarse/lift.json` over its photo, for a quick look:
//! `cargo run --release -p mesa-stages --example draw_lift_boxes -- SCENE_DIR OUT.png`.
//!
//! Each box's 8 corners go from the table frame back to the camera (the inverse of
//! `table_from_camera`) and through the intrinsics; edges are drawn in the box's colour.

use image::{Rgb, RgbImage};
use mesa_schemas::artifacts::LiftArtifact;
use nalgebra::{Matrix4, Vector4};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let [_, scene, out] = args.as_slice() else {
        eprintln!("usage: draw_lift_boxes SCENE_DIR OUT.png");
        std::process::exit(2);
    };
    let scene = std::path::Path::new(scene);
    let lift: LiftArtifact =
        serde_json::from_slice(&std::fs::read(scene.join("coarse/lift.json"))?)?;
    let mut image = image::open(scene.join("input/image.png"))?.into_rgb8();
    let m = lift.table_from_camera;
    let table_from_camera = Matrix4::from_fn(|r, c| m[r][c]);
    let camera_from_table = table_from_camera
        .try_inverse()
        .ok_or("table_from_camera is not invertible")?;
    let k = &lift.camera;
    let project = |p: [f64; 3]| -> Option<(f64, f64)> {
        let c = camera_from_table * Vector4::new(p[0], p[1], p[2], 1.0);
        (c.z > 1e-3).then(|| (k.fx * c.x / c.z + k.cx, k.fy * c.y / c.z + k.cy))
    };
    for (i, instance) in lift.instances.iter().enumerate() {
        let colour = Rgb([
            (80 + i * 67 % 176) as u8,
            (255 - i * 41 % 200) as u8,
            (60 + i * 97 % 196) as u8,
        ]);
        let (c, s) = (instance.center_cm.0, instance.size_cm.0);
        let corner = |bits: usize| -> [f64; 3] {
            std::array::from_fn(|a| {
                let sign = if bits >> a & 1 == 1 { 0.5 } else { -0.5 };
                (c[a] + sign * s[a]) / 100.0
            })
        };
        for a in 0..8usize {
            for axis in 0..3 {
                let b = a | 1 << axis;
                if b == a {
                    continue;
                }
                if let (Some(p), Some(q)) = (project(corner(a)), project(corner(b))) {
                    line(&mut image, p, q, colour);
                }
            }
        }
    }
    image.save(out)?;
    Ok(())
}

fn line(image: &mut RgbImage, p: (f64, f64), q: (f64, f64), colour: Rgb<u8>) {
    let steps = ((q.0 - p.0).abs().max((q.1 - p.1).abs()).ceil() as usize).clamp(1, 20_000);
    for i in 0..=steps {
        let t = i as f64 / steps as f64;
        let (x, y) = (p.0 + (q.0 - p.0) * t, p.1 + (q.1 - p.1) * t);
        for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            let (px, py) = (x as i64 + dx, y as i64 + dy);
            if px >= 0 && py >= 0 && (px as u32) < image.width() && (py as u32) < image.height() {
                image.put_pixel(px as u32, py as u32, colour);
            }
        }
    }
}
