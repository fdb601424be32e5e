//! A synthetic scene for benchmarks and tests: boxes standing on a table, seen by a camera
//! above its front edge, ray-cast exactly (no noise). Written in the input layout of SPEC
//! section 3 so that any tool can read it.

use std::path::Path;

use image::{GrayImage, ImageBuffer, Luma, RgbImage};
use nalgebra::{Matrix3, Vector3};

/// The scene's parameters.
#[derive(Debug, Clone)]
pub struct SyntheticScene {
    /// Image width and height in pixels.
    pub size_px: u32,
    /// Number of boxes (instances 1..=n; the table is instance n + 1, the support).
    pub boxes: usize,
    /// Horizontal field of view, degrees.
    pub fov_x_deg: f64,
}

impl Default for SyntheticScene {
    fn default() -> Self {
        Self {
            size_px: 1024,
            boxes: 15,
            fov_x_deg: 60.0,
        }
    }
}

/// A box in the table frame (metres): centre of its footprint and half extents, height.
#[derive(Debug, Clone, Copy)]
pub struct SyntheticBox {
    /// Footprint centre (x, y) in metres.
    pub center_m: [f64; 2],
    /// Half width and half depth, metres.
    pub half_m: [f64; 2],
    /// Height, metres.
    pub height_m: f64,
}

impl SyntheticScene {
    /// The boxes: a grid over a 1.2 m × 0.6 m table, sizes varying deterministically.
    pub fn boxes(&self) -> Vec<SyntheticBox> {
        let columns = self.boxes.div_ceil(3).max(1);
        (0..self.boxes)
            .map(|k| {
                let (row, col) = (k / columns, k % columns);
                // Rows are staggered and grow taller toward the back, so every box is seen.
                let x = 0.1 + (col as f64 + 0.25 + 0.25 * row as f64) * (1.0 / columns as f64);
                let y = 0.1 + (row as f64 + 0.5) * 0.15;
                let half = 0.015 + 0.01 * ((k * 7) % 4) as f64;
                SyntheticBox {
                    center_m: [x, y],
                    half_m: [half, half * (1.0 + 0.3 * ((k % 3) as f64))],
                    height_m: 0.03 + 0.04 * row as f64 + 0.01 * ((k * 5) % 3) as f64,
                }
            })
            .collect()
    }

    /// Camera pose: `table_from_camera` rotation and the camera centre in the table frame.
    pub fn camera(&self) -> (Matrix3<f64>, Vector3<f64>) {
        // Above and behind the front edge, looking 45° down at the table.
        let pitch = 45f64.to_radians();
        let x = Vector3::new(1.0, 0.0, 0.0);
        let forward = Vector3::new(0.0, pitch.cos(), -pitch.sin());
        let down = forward.cross(&x);
        // Columns: the camera axes (x right, y down, z forward) in table coordinates.
        let rotation = Matrix3::from_columns(&[x, down, forward]);
        (rotation, Vector3::new(0.6, -0.55, 0.75))
    }

    /// Renders depth (metres, row-major) and labels (0 = nothing, i = box i, n + 1 = table).
    pub fn render(&self) -> (Vec<f32>, Vec<u16>) {
        let n = self.size_px as usize;
        let f = (n as f64 / 2.0) / (self.fov_x_deg.to_radians() / 2.0).tan();
        let c = n as f64 / 2.0;
        let (rotation, eye) = self.camera();
        let boxes = self.boxes();
        let table_id = (boxes.len() + 1) as u16;
        let mut depth = vec![0f32; n * n];
        let mut labels = vec![0u16; n * n];
        for v in 0..n {
            for u in 0..n {
                let ray_cam = Vector3::new((u as f64 - c) / f, (v as f64 - c) / f, 1.0);
                let ray = rotation * ray_cam;
                let mut best = (f64::INFINITY, 0u16);
                if ray.z < 0.0 {
                    let t = -eye.z / ray.z;
                    let hit = eye + ray * t;
                    if (0.0..=1.2).contains(&hit.x) && (0.0..=0.6).contains(&hit.y) {
                        best = (t, table_id);
                    }
                }
                for (k, b) in boxes.iter().enumerate() {
                    let lo = [
                        b.center_m[0] - b.half_m[0],
                        b.center_m[1] - b.half_m[1],
                        0.0,
                    ];
                    let hi = [
                        b.center_m[0] + b.half_m[0],
                        b.center_m[1] + b.half_m[1],
                        b.height_m,
                    ];
                    let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
                    for a in 0..3 {
                        let inv = 1.0 / ray[a];
                        let (mut ta, mut tb) = ((lo[a] - eye[a]) * inv, (hi[a] - eye[a]) * inv);
                        if ta > tb {
                            std::mem::swap(&mut ta, &mut tb);
                        }
                        t0 = t0.max(ta);
                        t1 = t1.min(tb);
                    }
                    if t0 <= t1 && t0 < best.0 {
                        best = (t0, (k + 1) as u16);
                    }
                }
                if best.0.is_finite() {
                    // Depth is the z of the camera frame: t times the ray's camera z (1).
                    depth[v * n + u] = best.0 as f32;
                    labels[v * n + u] = best.1;
                }
            }
        }
        (depth, labels)
    }

    /// Writes the scene's `input/` files into `dir`.
    pub fn write(&self, dir: &Path) -> std::io::Result<()> {
        std::fs::create_dir_all(dir)?;
        let n = self.size_px;
        let (depth, labels) = self.render();
        let mm: Vec<u16> = depth.iter().map(|d| (d * 1000.0).round() as u16).collect();
        let err = |e: image::ImageError| std::io::Error::other(e.to_string());
        ImageBuffer::<Luma<u16>, _>::from_raw(n, n, mm)
            .ok_or_else(|| std::io::Error::other("depth size"))?
            .save(dir.join("depth.png"))
            .map_err(err)?;
        let label8: Vec<u8> = labels.iter().map(|l| *l as u8).collect();
        GrayImage::from_raw(n, n, label8)
            .ok_or_else(|| std::io::Error::other("label size"))?
            .save(dir.join("masks.png"))
            .map_err(err)?;
        let rgb: Vec<u8> = labels
            .iter()
            .flat_map(|l| {
                let l = *l as u32;
                [
                    (l * 53 % 256) as u8,
                    (l * 97 % 256) as u8,
                    (l * 193 % 256) as u8,
                ]
            })
            .collect();
        RgbImage::from_raw(n, n, rgb)
            .ok_or_else(|| std::io::Error::other("image size"))?
            .save(dir.join("image.png"))
            .map_err(err)?;
        let f = (f64::from(n) / 2.0) / (self.fov_x_deg.to_radians() / 2.0).tan();
        let camera = serde_json::json!({"width": n, "height": n, "fx": f, "fy": f,
            "cx": f64::from(n) / 2.0, "cy": f64::from(n) / 2.0});
        let mut instances: Vec<serde_json::Value> = (1..=self.boxes)
            .map(
                |k| serde_json::json!({"id": k, "label": "box", "description": format!("box {k}")}),
            )
            .collect();
        instances
            .push(serde_json::json!({"id": self.boxes + 1, "label": "table", "support": true}));
        std::fs::write(dir.join("camera.json"), camera.to_string())?;
        std::fs::write(
            dir.join("instances.json"),
            serde_json::json!({ "instances": instances }).to_string(),
        )?;
        Ok(())
    }
}
