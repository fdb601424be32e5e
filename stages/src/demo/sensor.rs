//! The camera of a demo photo, and what a depth sensor or a depth estimator makes of the true
//! depth: noise that grows with distance, holes, mixed ("flying") pixels at depth edges.

use rand::{Rng, RngCore};

use super::scene::Table;
use crate::mesh::{Aabb, Affine3};
use crate::raster::PinholeCamera;

/// The camera of a scene.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct CameraSetup {
    pub intrinsics: PinholeCamera,
    /// Camera frame (OpenCV) to table frame, metres.
    pub table_from_camera: Affine3,
    pub pitch_deg: f64,
    /// Whether `camera.json` gives intrinsics (else only the FOV).
    pub intrinsics_in_json: bool,
}

const RESOLUTIONS: [(u32, u32); 4] = [(640, 480), (640, 480), (512, 512), (720, 540)];

/// A frontal camera looking down at the table (no yaw, no roll), far enough for the whole
/// top and every object to be in view with a margin.
pub(crate) fn choose_camera(
    table: &Table,
    objects: &[Aabb],
    intrinsics_in_json: bool,
    rng: &mut impl RngCore,
) -> CameraSetup {
    let (width, height) = RESOLUTIONS[rng.random_range(0..RESOLUTIONS.len())];
    let fov_x_deg: f64 = rng.random_range(52.0..66.0);
    let mut intrinsics = PinholeCamera::from_fov_x_deg(width, height, fov_x_deg);
    if intrinsics_in_json {
        intrinsics.fy *= 1.0 + rng.random_range(-0.002..0.002);
        intrinsics.cx += rng.random_range(-6.0..6.0);
        intrinsics.cy += rng.random_range(-6.0..6.0);
    }
    let pitch_deg: f64 = rng.random_range(36.0..54.0);
    let p = pitch_deg.to_radians();
    let (w, d) = (table.width_m, table.depth_m);
    let target = [
        w / 2.0 + rng.random_range(-0.03..0.03),
        d * rng.random_range(0.42..0.52),
        0.0,
    ];
    let forward = [0.0, p.cos(), -p.sin()];
    let down = [0.0, -p.sin(), -p.cos()];
    let linear = [
        [1.0, down[0], forward[0]],
        [0.0, down[1], forward[1]],
        [0.0, down[2], forward[2]],
    ];
    let pose = |distance: f64| Affine3 {
        linear,
        translation: [
            target[0] - distance * forward[0],
            target[1] - distance * forward[1],
            target[2] - distance * forward[2],
        ],
    };
    let mut points: Vec<[f64; 3]> =
        vec![[0.0, 0.0, 0.0], [w, 0.0, 0.0], [0.0, d, 0.0], [w, d, 0.0]];
    for b in objects {
        points.extend_from_slice(&b.corners());
    }
    let margin = 0.04;
    let fits = |distance: f64| {
        let Some(camera_from_table) = pose(distance).inverse() else {
            return false;
        };
        points.iter().all(|p| {
            let c = camera_from_table.apply_point(*p);
            match intrinsics.project(c) {
                Some([u, v]) if c[2] > 0.05 => {
                    let (fw, fh) = (width as f64, height as f64);
                    u >= margin * fw
                        && u <= (1.0 - margin) * fw
                        && v >= margin * fh
                        && v <= (1.0 - margin) * fh
                }
                _ => false,
            }
        })
    };
    let (mut lo, mut hi) = (0.2, 15.0);
    for _ in 0..50 {
        let mid = (lo + hi) / 2.0;
        if fits(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    let distance = hi * (1.0 + rng.random_range(0.02..0.15));
    CameraSetup {
        intrinsics,
        table_from_camera: pose(distance),
        pitch_deg,
        intrinsics_in_json,
    }
}

/// A standard normal draw (Box–Muller; deterministic given the generator).
fn normal(rng: &mut impl RngCore) -> f64 {
    let u1: f64 = rng.random_range(f64::EPSILON..1.0);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Parameters and statistics of a noisy depth map.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct DepthStats {
    pub model: &'static str,
    pub scale: f64,
    pub sigma_constant_m: f64,
    pub sigma_linear: f64,
    pub sigma_quadratic_per_m: f64,
    pub smooth_error_relative: f64,
    pub quantization_m: f64,
    pub valid_px: u64,
    pub invalid_px: u64,
    pub mixed_px: u64,
}

/// Whether each pixel lies on a depth edge, and if so the nearer neighbour's depth (the
/// pixel itself being on the far side).
fn far_side_edges(clean: &[f32], width: usize, height: usize) -> Vec<Option<f32>> {
    let mut out = vec![None; clean.len()];
    for y in 0..height {
        for x in 0..width {
            let i = y * width + x;
            let d = clean[i];
            if !d.is_finite() {
                continue;
            }
            let mut nearest: Option<f32> = None;
            let mut consider = |j: usize| {
                let n = clean[j];
                if n.is_finite() && d - n > 0.02 + 0.02 * d && nearest.is_none_or(|m| n < m) {
                    nearest = Some(n);
                }
            };
            if x > 0 {
                consider(i - 1);
            }
            if x + 1 < width {
                consider(i + 1);
            }
            if y > 0 {
                consider(i - width);
            }
            if y + 1 < height {
                consider(i + width);
            }
            out[i] = nearest;
        }
    }
    out
}

/// A structured-light sensor's 16-bit millimetre depth: noise σ(d) = 1.2 mm + 1.9 mm/m ·
/// (d − 0.4 m)² (a Kinect-style model), holes (dark or shiny patches, projector shadows
/// beside foreground edges, a sprinkle of dropouts, beyond 4.5 m), and mixed pixels on the
/// far side of depth edges. 0 means no measurement.
pub(crate) fn sensor_depth(
    clean: &[f32],
    width: usize,
    height: usize,
    noise: bool,
    rng: &mut impl RngCore,
) -> (Vec<u16>, DepthStats) {
    let (c0, q) = if noise { (0.0012, 0.0019) } else { (0.0, 0.0) };
    let mut out: Vec<f64> = clean
        .iter()
        .map(|&d| {
            if !d.is_finite() || d as f64 > 4.5 {
                return 0.0;
            }
            let d = d as f64;
            d + (c0 + q * (d - 0.4).powi(2)) * if noise { normal(rng) } else { 0.0 }
        })
        .collect();
    let mut is_mixed = vec![false; clean.len()];
    if noise {
        let edges = far_side_edges(clean, width, height);
        for (i, e) in edges.iter().enumerate() {
            let Some(near) = e else { continue };
            let roll: f64 = rng.random();
            if roll < 0.5 {
                let t: f64 = rng.random_range(0.15..0.85);
                out[i] = *near as f64 + t * (clean[i] as f64 - *near as f64);
                is_mixed[i] = true;
            } else if roll < 0.8 {
                out[i] = 0.0;
            }
        }
        // Projector shadows: a band of background just left of a foreground edge.
        for y in 0..height {
            for x in 0..width.saturating_sub(1) {
                let i = y * width + x;
                if edges[i].is_none() || clean[i + 1] + 0.02 >= clean[i] || !rng.random_bool(0.6) {
                    continue;
                }
                let band = rng.random_range(1..=3usize);
                for k in 0..band.min(x + 1) {
                    if clean[i - k] >= clean[i] - 0.01 {
                        out[i - k] = 0.0;
                    }
                }
            }
        }
        // Dark or shiny patches without a return.
        let patches = rng.random_range(2..=6);
        for _ in 0..patches {
            let cx = rng.random_range(0.0..width as f64);
            let cy = rng.random_range(0.0..height as f64);
            let (rx, ry) = (
                rng.random_range(2.0..10.0f64),
                rng.random_range(2.0..8.0f64),
            );
            let (x0, x1) = (
                (cx - rx).floor().max(0.0) as usize,
                ((cx + rx).ceil() as usize).min(width - 1),
            );
            let (y0, y1) = (
                (cy - ry).floor().max(0.0) as usize,
                ((cy + ry).ceil() as usize).min(height - 1),
            );
            for y in y0..=y1 {
                for x in x0..=x1 {
                    let (dx, dy) = ((x as f64 - cx) / rx, (y as f64 - cy) / ry);
                    if dx * dx + dy * dy <= 1.0 {
                        out[y * width + x] = 0.0;
                    }
                }
            }
        }
        for v in out.iter_mut() {
            if rng.random_bool(0.002) {
                *v = 0.0;
            }
        }
    }
    let mm: Vec<u16> = out
        .iter()
        .map(|&d| {
            if d <= 0.0 {
                0
            } else {
                (d * 1000.0).round().clamp(1.0, 65535.0) as u16
            }
        })
        .collect();
    let invalid = mm.iter().filter(|&&v| v == 0).count() as u64;
    let mixed = mm
        .iter()
        .zip(&is_mixed)
        .filter(|(v, m)| **v > 0 && **m)
        .count() as u64;
    let stats = DepthStats {
        model: "sensor",
        scale: 1.0,
        sigma_constant_m: c0,
        sigma_linear: 0.0,
        sigma_quadratic_per_m: q,
        smooth_error_relative: 0.0,
        quantization_m: 0.001,
        valid_px: mm.len() as u64 - invalid,
        invalid_px: invalid,
        mixed_px: mixed,
    };
    (mm, stats)
}

/// A metric monocular estimator's float32 depth in metres: a global scale error, a smooth
/// low-frequency error of up to 0.4 % of the depth, per-pixel noise σ(d) = 1 mm + 0.2 % · d,
/// edges blurred across objects (mixed pixels), NaN where nothing was seen, and a handful of
/// invalid values (NaN, ±inf, 0, negative) as real outputs have.
pub(crate) fn estimator_depth(
    clean: &[f32],
    width: usize,
    height: usize,
    noise: bool,
    rng: &mut impl RngCore,
) -> (Vec<f32>, DepthStats) {
    let scale = if noise {
        1.0 + (0.012 * normal(rng)).clamp(-0.03, 0.03)
    } else {
        1.0
    };
    let smooth_amp = if noise { 0.004 } else { 0.0 };
    let (sc, sl) = if noise { (0.001, 0.002) } else { (0.0, 0.0) };
    // Three sinusoids over the image, normalised so their sum stays within [-1, 1].
    let waves: Vec<(f64, f64, f64, f64)> = (0..3)
        .map(|_| {
            let angle = rng.random_range(0.0..std::f64::consts::TAU);
            let freq =
                rng.random_range(0.6..2.2) * std::f64::consts::TAU / width.max(height) as f64;
            (
                angle.cos() * freq,
                angle.sin() * freq,
                rng.random_range(0.0..std::f64::consts::TAU),
                rng.random_range(0.5..1.0),
            )
        })
        .collect();
    let total_amp: f64 = waves.iter().map(|w| w.3).sum();
    let field = |x: usize, y: usize| -> f64 {
        waves
            .iter()
            .map(|(kx, ky, phase, a)| a * (kx * x as f64 + ky * y as f64 + phase).sin())
            .sum::<f64>()
            / total_amp
    };
    let mut out: Vec<f32> = Vec::with_capacity(clean.len());
    for y in 0..height {
        for x in 0..width {
            let d = clean[y * width + x];
            if !d.is_finite() {
                out.push(f32::NAN);
                continue;
            }
            let d = d as f64;
            let noisy = d * scale * (1.0 + smooth_amp * field(x, y))
                + (sc + sl * d) * if noise { normal(rng) } else { 0.0 };
            out.push(noisy as f32);
        }
    }
    let mut is_mixed = vec![false; clean.len()];
    if noise {
        // Blur across depth edges: within a pixel of an edge (either side), the 5×5 mean of
        // the scaled true depth.
        let edges = far_side_edges(clean, width, height);
        let mut near_edge = vec![false; clean.len()];
        for y in 0..height {
            for x in 0..width {
                if edges[y * width + x].is_some() {
                    for dy in -1i64..=1 {
                        for dx in -1i64..=1 {
                            let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                            if nx >= 0 && ny >= 0 && (nx as usize) < width && (ny as usize) < height
                            {
                                near_edge[ny as usize * width + nx as usize] = true;
                            }
                        }
                    }
                }
            }
        }
        for y in 0..height {
            for x in 0..width {
                let i = y * width + x;
                if !near_edge[i] || !clean[i].is_finite() {
                    continue;
                }
                let (mut sum, mut n) = (0.0f64, 0u32);
                for dy in -2i64..=2 {
                    for dx in -2i64..=2 {
                        let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                        if nx >= 0 && ny >= 0 && (nx as usize) < width && (ny as usize) < height {
                            let v = clean[ny as usize * width + nx as usize];
                            if v.is_finite() {
                                sum += v as f64;
                                n += 1;
                            }
                        }
                    }
                }
                if n > 0 {
                    out[i] = (sum / n as f64 * scale) as f32;
                    is_mixed[i] = true;
                }
            }
        }
        let bad = [f32::NAN, f32::INFINITY, 0.0, -1.0, f32::NEG_INFINITY];
        let count = (clean.len() / 5000).max(5);
        for k in 0..count {
            let i = rng.random_range(0..clean.len());
            out[i] = bad[k % bad.len()];
        }
    }
    let valid = |v: &f32| v.is_finite() && *v > 0.0;
    let invalid = out.iter().filter(|v| !valid(v)).count() as u64;
    let mixed = out
        .iter()
        .zip(&is_mixed)
        .filter(|(v, m)| valid(v) && **m)
        .count() as u64;
    let stats = DepthStats {
        model: "estimator",
        scale,
        sigma_constant_m: sc,
        sigma_linear: sl,
        sigma_quadratic_per_m: 0.0,
        smooth_error_relative: smooth_amp,
        quantization_m: 0.0,
        valid_px: out.len() as u64 - invalid,
        invalid_px: invalid,
        mixed_px: mixed,
    };
    (out, stats)
}

/// Grows a binary mask by `radius` pixels (square neighbourhood).
pub(crate) fn dilate(mask: &[bool], width: usize, height: usize, radius: usize) -> Vec<bool> {
    if radius == 0 {
        return mask.to_vec();
    }
    let mut out = vec![false; mask.len()];
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

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn step_scene() -> (Vec<f32>, usize, usize) {
        // Left half at 1 m, right half at 2 m.
        let (w, h) = (64, 48);
        let d = (0..w * h)
            .map(|i| if i % w < w / 2 { 1.0 } else { 2.0 })
            .collect();
        (d, w, h)
    }

    #[test]
    fn sensor_noise_matches_its_model_away_from_edges() {
        let (clean, w, h) = step_scene();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let (mm, stats) = sensor_depth(&clean, w, h, true, &mut rng);
        assert!(stats.invalid_px > 0 && stats.mixed_px > 0);
        let sigma =
            |d: f64| stats.sigma_constant_m + stats.sigma_quadratic_per_m * (d - 0.4).powi(2);
        let mut residuals = Vec::new();
        for y in 0..h {
            for x in 2..w / 2 - 2 {
                let v = mm[y * w + x];
                if v > 0 {
                    residuals.push((v as f64 / 1000.0 - 1.0) / sigma(1.0));
                }
            }
        }
        let n = residuals.len() as f64;
        let mean = residuals.iter().sum::<f64>() / n;
        let sd = (residuals.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / n).sqrt();
        assert!(mean.abs() < 0.2, "mean {mean}");
        assert!((sd - 1.0).abs() < 0.25, "sd {sd}");
        // Mixed pixels lie between the two depths.
        let between = mm.iter().filter(|&&v| v > 1010 && v < 1990).count();
        assert!(between > 0);
    }

    #[test]
    fn without_noise_the_depth_is_the_truth() {
        let (clean, w, h) = step_scene();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let (mm, stats) = sensor_depth(&clean, w, h, false, &mut rng);
        assert_eq!(stats.invalid_px, 0);
        assert!(mm.iter().zip(&clean).all(|(&v, &d)| v as f32 == d * 1000.0));
        let (m, stats) = estimator_depth(&clean, w, h, false, &mut rng);
        assert_eq!(stats.invalid_px, 0);
        assert_eq!(m, clean);
    }

    #[test]
    fn estimator_depth_is_scaled_smooth_and_has_invalid_values() {
        let (clean, w, h) = step_scene();
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let (m, stats) = estimator_depth(&clean, w, h, true, &mut rng);
        assert!(
            m.iter().any(|v| v.is_nan())
                && m.iter().any(|v| v.is_infinite())
                && m.iter().any(|v| *v < 0.0)
        );
        let mut ok = 0;
        let mut total = 0;
        for y in 0..h {
            for x in 3..w / 2 - 3 {
                let v = m[y * w + x] as f64;
                if !v.is_finite() || v <= 0.0 {
                    continue;
                }
                total += 1;
                let bound = 4.0 * (stats.sigma_constant_m + stats.sigma_linear)
                    + stats.smooth_error_relative * stats.scale;
                if (v - stats.scale).abs() <= bound {
                    ok += 1;
                }
            }
        }
        assert!(ok as f64 >= 0.99 * total as f64, "{ok}/{total}");
    }

    #[test]
    fn dilation_grows_by_the_radius() {
        let (w, h) = (5, 5);
        let mut m = vec![false; 25];
        m[12] = true;
        let d = dilate(&m, w, h, 1);
        assert_eq!(d.iter().filter(|v| **v).count(), 9);
    }
}
