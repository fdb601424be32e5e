//! `lift`: depth maps and instance masks → point clouds, the table frame, and object boxes
//! (SPEC 5.1, frames of SPEC section 2).
//!
//! 1. Read the inputs ([`inputs`]): depth in metres, camera intrinsics, masks, photo.
//! 2. Fit the table plane with RANSAC on the support instance's pixels (the table), or on the
//!    background when no instance is marked `"support": true`; refine it by least squares on
//!    the inliers; orient its normal toward the camera.
//! 3. Build the table frame: z = the normal, x = the camera's x axis projected on the plane,
//!    y = z × x; the origin and the placement zone come from the table's edges (below).
//! 4. Per instance: erode the mask (drops the flying pixels at depth edges), back-project,
//!    remove outliers, transform to the table frame, take the axis-aligned box (below) with its
//!    bottom clamped to the table (z ≥ 0).
//!
//! ## The zone
//! Each table pixel stands for a patch of the top whose area grows with the cube of its depth,
//! so the points, weighted by depth³, are a uniform sample of the visible top. Along x and
//! along y the weighted distribution is flat near each edge of the rectangle; at each side the
//! weighted quantiles at `zone_percentile` % and three times that give the local density, and
//! the edge is where that density, carried outward, leaves the first share behind. Sensor noise
//! blurs an edge symmetrically without moving it, and objects hiding part of the top further
//! in do not matter. (Plain percentiles put the edges a share of the width inside; a depth
//! estimator's global scale error, which no single depth map reveals, scales the zone and every
//! box with it.)
//!
//! ## The box
//! The extremes of the kept points along each table axis, with three corrections, each a key of
//! `[lift]`: `restore_px` pixels of width are given back at the left and right (the image's x
//! is the table's x, a pixel there is depth / fx wide) and at the far side (the far edge of a
//! top face, foreshortened by the view's elevation), since erosion took `erode_px` off the
//! silhouette and segmenters' masks spill about one pixel past the object; the top is the
//! `top_trim` quantile of the heights (the noise of a flat top face spreads it by a few
//! millimetres); a bottom within `bottom_snap_m` of the table is set on it.
//!
//! ## Outlier rule
//! Statistical outlier removal as Open3D's `remove_statistical_outlier` does it — a point is an
//! outlier when its mean distance to its neighbours exceeds the mean of that statistic over the
//! instance by more than `outlier_std_ratio` standard deviations — with the neighbours taken
//! from the depth image's pixel grid (the valid pixels of the eroded mask within
//! `outlier_window_px`) instead of a k-d tree, since the cloud is organised. Distances are
//! divided by the pixel footprint at the point's depth (depth / fx), so that near and far parts
//! of one object are judged alike. A point with no neighbour at all is an outlier.
//!
//! Before that, a connectivity rule removes what a local statistic cannot: a band of mask
//! pixels that bled onto the background is dense in itself. The eroded mask's pixels are split
//! into components, neighbouring pixels (4-connected) joining when their depths differ by at
//! most `max(component_jump_m, component_jump_relative · depth)`; the largest component is kept
//! with every component at least `component_min_fraction` of its size (an object split in two
//! by an occluder keeps both halves).

mod depth_png;
pub mod inputs;
pub mod ply;
pub mod rle;
pub mod synthetic;

use std::path::{Path, PathBuf};

use mesa_schemas::artifacts::{
    DroppedInstance, LiftArtifact, LiftStats, LiftedInstance, PlaneFit, ResolvedCamera, LIFT_SCHEMA,
};
use mesa_schemas::units::{PositionCm, SizeCm, ZoneCm};
use nalgebra::{Matrix3, Vector3};
use rand::{Rng, SeedableRng};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use strength_reduce::StrengthReducedU32;

use inputs::{
    read_camera, read_depth, read_instances, read_masks, read_photo, DepthMap, Intrinsics,
};

/// The `[lift]` section of `mesa.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct LiftConfig {
    /// Metres per unit of a 16-bit depth.png (0.001: millimetres; 0.0001 for YCB-Video).
    pub depth_png_scale_m: f64,
    /// Horizontal field of view in degrees used when camera.json has neither intrinsics nor
    /// fov_x_deg (generated photos); 0 makes such a camera an error.
    pub default_fov_x_deg: f64,
    /// Radius in pixels of the square mask erosion that drops flying pixels at depth edges.
    pub erode_px: u32,
    /// Pixels of width given back to each box at its left and right after the erosion: the
    /// erosion takes `erode_px` off the silhouette, but masks from segmenters spill about one
    /// pixel past the object, so the default gives back one less (see docs/stages.md, lift).
    pub restore_px: f64,
    /// Share of an instance's points left out at the top (the noise of a flat top face; see
    /// the module docs, "The box").
    pub top_trim: f64,
    /// A box whose bottom is at most this many metres above the table rests on it: its bottom
    /// is set to the table (the erosion and the sensor noise lift it a little).
    pub bottom_snap_m: f64,
    /// Radius in pixels of the neighbourhood of the outlier rule.
    pub outlier_window_px: u32,
    /// Neighbouring pixels belong to one surface when their depths differ by at most this many
    /// metres (or the relative jump below, whichever is larger).
    pub component_jump_m: f64,
    /// The same limit relative to the depth.
    pub component_jump_relative: f64,
    /// Components smaller than this fraction of the largest are dropped as bleed.
    pub component_min_fraction: f64,
    /// A point is an outlier when its mean neighbour distance exceeds the instance's mean by
    /// this many standard deviations.
    pub outlier_std_ratio: f64,
    /// RANSAC inlier distance to the table plane, metres.
    pub plane_threshold_m: f64,
    /// RANSAC iterations.
    pub plane_iterations: u32,
    /// Points sampled (evenly over the pixels) for RANSAC.
    pub plane_max_points: u32,
    /// The first plane fitted must explain at least this fraction of the table's points (else
    /// there is no table plane). A plane fitted after a cabinet front was set aside needs
    /// `plane_min_points` inliers instead: a far counter top may be a small share of the rest.
    pub plane_min_inlier_fraction: f64,
    /// For that share a point counts as on the plane within plane_threshold_m times
    /// max(1, (depth / plane_share_depth_m)²): depth noise grows with the square of the
    /// distance (structured light, stereo, time of flight), so a far counter top seen at a
    /// grazing angle is still recognised as a plane. 0 keeps plane_threshold_m at every depth.
    pub plane_share_depth_m: f64,
    /// Fewest table (or background) points with valid depth to fit a plane on.
    pub plane_min_points: u32,
    /// The table is the plane with at least this fraction of the objects' points on its camera
    /// side (objects stand on it); other planes (a cabinet front) are set aside.
    pub plane_min_objects_above: f64,
    /// Percent (0-16) of the table's visible area, at each side, over which the local density
    /// is measured to place the zone's edge (see the module docs, "The zone").
    pub zone_percentile: f64,
    /// Fewest points an instance may keep after filtering.
    pub min_points: u32,
    /// The most pixels an input image (depth map, photo) may have; its header is checked
    /// before it is decoded.
    pub max_image_pixels: u64,
}

impl Default for LiftConfig {
    fn default() -> Self {
        Self {
            depth_png_scale_m: 0.001,
            default_fov_x_deg: 60.0,
            erode_px: 2,
            restore_px: 1.0,
            top_trim: 0.005,
            bottom_snap_m: 0.01,
            outlier_window_px: 2,
            component_jump_m: 0.01,
            component_jump_relative: 0.02,
            component_min_fraction: 0.1,
            outlier_std_ratio: 2.0,
            plane_threshold_m: 0.005,
            plane_iterations: 400,
            plane_max_points: 20_000,
            plane_min_inlier_fraction: 0.3,
            plane_share_depth_m: 1.5,
            plane_min_points: 500,
            plane_min_objects_above: 0.8,
            zone_percentile: 1.0,
            min_points: 10,
            max_image_pixels: 100_000_000,
        }
    }
}

/// Why a scene cannot be lifted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LiftError {
    /// An input file is wrong.
    #[error("{}: {field}: {problem} (fix: {fix})", file.display())]
    Input {
        /// The file.
        file: PathBuf,
        /// The field or part of it.
        field: String,
        /// What is wrong.
        problem: String,
        /// How to fix it.
        fix: String,
    },
    /// No table plane could be found.
    #[error("no table plane: {0}")]
    NoPlane(String),
}

impl LiftError {
    /// An input problem.
    pub fn input(
        file: &Path,
        field: &str,
        problem: impl Into<String>,
        fix: impl Into<String>,
    ) -> Self {
        Self::Input {
            file: file.to_owned(),
            field: field.to_owned(),
            problem: problem.into(),
            fix: fix.into(),
        }
    }
}

/// What lifting a scene produces.
#[derive(Debug, Clone)]
pub struct LiftOutput {
    /// `coarse/lift.json`.
    pub artifact: LiftArtifact,
    /// `coarse/points/<instance>.ply` contents, by instance.
    pub clouds: Vec<(String, Vec<u8>)>,
    /// Warnings about the scene.
    pub warnings: Vec<String>,
}

/// Lifts one scene whose inputs are in `input_dir` (the scene's `input/` folder).
pub fn lift_scene(
    input_dir: &Path,
    scene_id: &str,
    seed: u64,
    config: &LiftConfig,
) -> Result<LiftOutput, LiftError> {
    let mut warnings = Vec::new();
    let camera_path = input_dir.join("camera.json");
    let camera = read_camera(&camera_path, config)?;
    let k = camera.intrinsics;
    if k.source == "fov" && !has_fov(&camera_path) {
        warnings.push(format!(
            "camera.json has no intrinsics and no fov_x_deg: used [lift] default_fov_x_deg = {}",
            config.default_fov_x_deg
        ));
    }
    let instances = read_instances(&input_dir.join("instances.json"))?;
    let (depth, depth_path) = read_depth(input_dir, &camera, config)?;
    if (depth.width, depth.height) != (k.width, k.height) {
        return Err(LiftError::input(
            &camera_path,
            "width",
            format!(
                "says {}×{} but {} is {}×{}",
                k.width,
                k.height,
                depth_path.display(),
                depth.width,
                depth.height
            ),
            "the camera's width and height must be the depth map's",
        ));
    }
    let masks = read_masks(input_dir, &instances, depth.width, depth.height)?;
    let photo = read_photo(input_dir, depth.width, depth.height)?;
    if photo.is_none() {
        warnings.push("no input/image.png: point clouds are grey".to_owned());
    }

    // The table plane.
    // The big lists are made at their final size (or a bound of it, [`collect_within`]).
    let pixels_of = |support: bool| {
        let lists = || {
            instances
                .iter()
                .filter(move |i| i.support == support)
                .map(|i| &masks.pixels[&i.id])
        };
        let mut all = Vec::with_capacity(lists().map(Vec::len).sum());
        lists().for_each(|list| all.extend_from_slice(list));
        all
    };
    let support: Vec<u32> = pixels_of(true);
    // The plane and the zone's percentiles need a few hundred thousand points at most: every
    // step-th pixel of the support (or background), the step the smallest that leaves at most
    // this many.
    const PLANE_PIXELS: usize = 200_000;
    let (plane_pixels, source) = if support.is_empty() {
        (masks.background_sample(PLANE_PIXELS), "background")
    } else {
        let mut s = support;
        s.sort_unstable();
        s.dedup();
        let step = s.len().div_ceil(PLANE_PIXELS).max(1);
        (s.into_iter().step_by(step).collect(), "support")
    };
    let columns = Columns::new(depth.width);
    let plane_points: Vec<Vector3<f64>> = collect_within(
        plane_pixels.len(),
        plane_pixels
            .iter()
            .filter_map(|&p| back_project_at(&depth, &k, columns.uv(p))),
    );
    let object_pixels: Vec<u32> = pixels_of(false);
    let object_points: Vec<Vector3<f64>> = object_pixels
        .iter()
        .step_by(object_pixels.len().div_ceil(20_000).max(1))
        .filter_map(|&p| back_project_at(&depth, &k, columns.uv(p)))
        .collect();
    let plane = fit_plane(
        &plane_points,
        &object_points,
        scene_id,
        seed,
        config,
        source,
    )?;
    let frame = TableFrame::new(&plane, &plane_points, config)?;

    let mut lifted = Vec::new();
    let mut dropped = Vec::new();
    let mut window_rows = Vec::new();
    let mut clouds = Vec::new();
    let mut label_counts = std::collections::BTreeMap::<String, usize>::new();
    let masks_file = PathBuf::from(&masks.source);
    // What lift.json and the warnings say of the masks names them within the scene folder
    // (`input/masks.png`): the same bytes wherever the dataset is (a copy, another node's mount).
    let scene_dir = input_dir.parent().unwrap_or(input_dir);
    let masks_in_scene = masks_file.strip_prefix(scene_dir).unwrap_or(&masks_file);
    for entry in instances.iter().filter(|i| !i.support) {
        let label = sanitize_label(&entry.label);
        let index = label_counts.entry(label.clone()).or_insert(0);
        let instance = format!("{label}_{index}");
        *index += 1;
        let pixels = &masks.pixels[&entry.id];
        let valid: Vec<u32> = collect_within(
            pixels.len(),
            pixels
                .iter()
                .copied()
                .filter(|&p| depth.depth_m[p as usize].is_finite()),
        );
        if valid.is_empty() {
            return Err(LiftError::input(
                &masks_file,
                &format!("id {}", entry.id),
                format!(
                    "none of the {} pixels of instance {} (\"{}\") has a valid depth in {}",
                    pixels.len(),
                    entry.id,
                    entry.label,
                    depth_path.display()
                ),
                "check that the mask and the depth map are registered, or drop the instance",
            ));
        }
        let mut kept = erode(pixels, depth.width, depth.height, config.erode_px as usize);
        kept.retain(|&p| depth.depth_m[p as usize].is_finite());
        if kept.len() < config.min_points as usize {
            warnings.push(format!(
                "{instance}: the mask is too thin for a {} px erosion ({} pixels left); used it \
                 unchanged",
                config.erode_px,
                kept.len()
            ));
            kept = valid.clone();
        }
        let eroded_px = kept.len();
        let (points, removed) = remove_outliers(&depth, &k, &kept, config, &mut window_rows);
        if points.len() < config.min_points.min(valid.len() as u32) as usize || points.is_empty() {
            // One thin or noisy mask must not cost the scene its other objects: this one is
            // left out, and said so (in the warnings and in lift.json's `dropped`).
            let reason = format!(
                "keeps {} points after filtering, fewer than [lift] min_points = {} (check its \
                 mask and depth in {}, or lower [lift] min_points to keep it)",
                points.len(),
                config.min_points,
                masks_in_scene.display()
            );
            warnings.push(format!(
                "{instance} (instance id {}, \"{}\") dropped: {reason}",
                entry.id, entry.label
            ));
            dropped.push(DroppedInstance {
                instance,
                mask_id: entry.id,
                label: entry.label.clone(),
                points_kept: points.len() as u64,
                reason,
            });
            continue;
        }
        // One pass over the points: each in the table frame, its bytes in the point file, and
        // the sides of the box at the extremes of the axes (the top at a quantile), each with
        // the camera-frame point there ([`Extremes`]). The trimmed top is selected among the
        // heights alone: the value at a rank of a total order is the same whatever else the
        // items hold.
        let points_file = format!("coarse/points/{instance}.ply");
        let mut ply = ply::PlyWriter::new(
            points.len(),
            &format!("mesa lift: {scene_id} {instance}, table frame, metres"),
        );
        let mut heights = Vec::with_capacity(points.len());
        let mut extremes = Extremes::new(frame.to_table(points[0].1), points[0].1);
        for &(pixel, point) in &points {
            let t = frame.to_table(point);
            extremes.take(t, point);
            heights.push(t.z);
            let rgb = photo.as_ref().map_or([128, 128, 128], |p| p.rgb(pixel));
            ply.push([t[0] as f32, t[1] as f32, t[2] as f32], rgb);
        }
        let top_trim = ((heights.len() as f64 * config.top_trim).floor() as usize)
            .min((heights.len() - 1) / 2);
        let Extremes {
            lo_x,
            hi_x,
            hi_y,
            lo_y,
            lo_z,
        } = extremes;
        let mut min = [lo_x.0.x, lo_y.y, lo_z];
        let mut max = [hi_x.0.x, hi_y.0.y, 0.0];
        let edges = [lo_x.1, hi_x.1, hi_y.1];
        let rank = heights.len() - 1 - top_trim;
        let (_, top, _) = heights.select_nth_unstable_by(rank, f64::total_cmp);
        max[2] = *top;
        if eroded_px < valid.len() {
            // The image's x is the table's x: a pixel there is depth / fx wide.
            min[0] -= config.restore_px * edges[0].z / k.fx;
            max[0] += config.restore_px * edges[1].z / k.fx;
            // The far side is the far edge of a top face, foreshortened by the elevation of
            // the view there.
            let far = edges[2];
            let elevation = (plane.normal.dot(&far).abs() / far.norm()).max(0.2);
            max[1] += config.restore_px * far.z / k.fy / elevation;
        }
        // Objects rest on the table or above it.
        min[2] = min[2].max(0.0);
        if min[2] <= config.bottom_snap_m {
            min[2] = 0.0;
        }
        max[2] = max[2].max(min[2] + 1e-3);
        let center_cm = PositionCm(std::array::from_fn(|a| (min[a] + max[a]) * 50.0));
        let size_cm = SizeCm(std::array::from_fn(|a| {
            ((max[a] - min[a]) * 100.0).max(0.1)
        }));
        clouds.push((instance.clone(), ply.finish()));
        lifted.push(LiftedInstance {
            instance,
            mask_id: entry.id,
            label: entry.label.clone(),
            description: entry.description.clone(),
            center_cm,
            size_cm,
            yaw_deg: None,
            points: points_file,
            stats: LiftStats {
                mask_px: pixels.len() as u64,
                valid_depth_px: valid.len() as u64,
                valid_depth_fraction: valid.len() as f64 / pixels.len() as f64,
                eroded_px: eroded_px as u64,
                points_removed_outliers: removed as u64,
                points_kept: points.len() as u64,
            },
        });
    }
    if lifted.is_empty() && !dropped.is_empty() {
        let counts: Vec<String> = dropped
            .iter()
            .map(|d| format!("{} keeps {}", d.instance, d.points_kept))
            .collect();
        return Err(LiftError::input(
            &masks_file,
            "instances",
            format!(
                "every object keeps too few points after filtering ({}; [lift] min_points = {}): \
                 the scene would have no object",
                counts.join(", "),
                config.min_points
            ),
            "check that the masks and the depth map are registered, or lower [lift] min_points",
        ));
    }
    let artifact = LiftArtifact {
        schema: LIFT_SCHEMA.to_owned(),
        scene_id: scene_id.to_owned(),
        camera: ResolvedCamera {
            width: k.width as u32,
            height: k.height as u32,
            fx: k.fx,
            fy: k.fy,
            cx: k.cx,
            cy: k.cy,
            source: k.source.to_owned(),
        },
        table_from_camera: frame.table_from_camera(),
        plane: PlaneFit {
            normal_in_camera: [plane.normal.x, plane.normal.y, plane.normal.z],
            offset_m: plane.offset_m,
            source: source.to_owned(),
            inliers: plane.inliers as u64,
            inlier_fraction: plane.inlier_fraction,
            rmse_m: plane.rmse_m,
        },
        zone_cm: ZoneCm([0.0, frame.zone_m[0] * 100.0, 0.0, frame.zone_m[1] * 100.0]),
        instances: lifted,
        dropped,
    };
    Ok(LiftOutput {
        artifact,
        clouds,
        warnings,
    })
}

fn has_fov(camera_path: &Path) -> bool {
    inputs::read_json(camera_path).is_ok_and(|v| v.get("fov_x_deg").is_some())
}

/// `Coffee Mug` → `coffee_mug`: lowercase ASCII, runs of other characters become one `_`, at
/// most 58 characters, so that `<label>_<index>` follows the instance-name rule
/// (`mesa_schemas::validate::instance_name_problem`).
pub fn sanitize_label(label: &str) -> String {
    let mut out = String::new();
    for c in label.trim().chars() {
        if c.is_ascii_alphanumeric() {
            out.push(c.to_ascii_lowercase());
        } else if !out.ends_with('_') && !out.is_empty() {
            out.push('_');
        }
    }
    let out: String = out.chars().take(58).collect();
    let out = out.trim_end_matches('_').to_owned();
    if out.is_empty() {
        "object".to_owned()
    } else {
        out
    }
}

/// Back-projects pixel index `p` (SPEC section 2): `((u - cx) d / fx, (v - cy) d / fy, d)`.
pub fn back_project(depth: &DepthMap, k: &Intrinsics, p: u32) -> Option<Vector3<f64>> {
    back_project_at(depth, k, Columns::new(depth.width).uv(p))
}

/// [`back_project`] of the pixel at column `u`, row `v`.
fn back_project_at(
    depth: &DepthMap,
    k: &Intrinsics,
    (u, v): (usize, usize),
) -> Option<Vector3<f64>> {
    let d = f64::from(depth.at(u, v)?);
    Some(Vector3::new(
        (u as f64 - k.cx) * d / k.fx,
        (v as f64 - k.cy) * d / k.fy,
        d,
    ))
}

/// A table-frame point with the camera-frame point it came from.
type FramedPoint = (Vector3<f64>, Vector3<f64>);

/// The sides of an object's box, taken point by point: the least and greatest table x and the
/// greatest table y, each with its camera-frame point (the box is widened there by the
/// restored pixels), and the least table y and z. Equal values are chosen as
/// `Iterator::min_by` and `max_by` by `total_cmp` choose them (what this replaced): the first
/// of equal minima, the last of equal maxima.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Extremes {
    lo_x: FramedPoint,
    hi_x: FramedPoint,
    hi_y: FramedPoint,
    lo_y: Vector3<f64>,
    lo_z: f64,
}

impl Extremes {
    /// The extremes of one point.
    fn new(t: Vector3<f64>, point: Vector3<f64>) -> Self {
        Self {
            lo_x: (t, point),
            hi_x: (t, point),
            hi_y: (t, point),
            lo_y: t,
            lo_z: t.z,
        }
    }

    /// Takes in the next point: a minimum is replaced by a smaller value only, a maximum by
    /// one not smaller.
    #[inline]
    fn take(&mut self, t: Vector3<f64>, point: Vector3<f64>) {
        if t.x.total_cmp(&self.lo_x.0.x).is_lt() {
            self.lo_x = (t, point);
        }
        if t.x.total_cmp(&self.hi_x.0.x).is_ge() {
            self.hi_x = (t, point);
        }
        if t.y.total_cmp(&self.hi_y.0.y).is_ge() {
            self.hi_y = (t, point);
        }
        if t.y.total_cmp(&self.lo_y.y).is_lt() {
            self.lo_y = t;
        }
        if t.z.total_cmp(&self.lo_z).is_lt() {
            self.lo_z = t.z;
        }
    }
}

/// The column and row of row-major pixel indices of an image `width` pixels wide, by a
/// multiplication and a shift (`strength_reduce`, after Lemire, Kaser and Kurz, "Faster
/// remainder by direct computation", 2019) instead of a division: a scene's lift splits about
/// 700,000 indices (the table's sample, each object's pixels for its erosion, box and points),
/// and a 32-bit division takes 6 to 10 cycles where the multiplication takes one or two.
#[derive(Debug, Clone, Copy)]
struct Columns {
    width: StrengthReducedU32,
}

impl Columns {
    /// For an image `width` pixels wide (pixel indices are `u32`: so is any width with pixels;
    /// a width of 0, which has none, is taken as 1).
    fn new(width: usize) -> Self {
        let width = u32::try_from(width.max(1)).unwrap_or(u32::MAX);
        Self {
            width: StrengthReducedU32::new(width),
        }
    }

    /// `(p % width, p / width)`.
    #[inline]
    fn uv(self, p: u32) -> (usize, usize) {
        let (v, u) = StrengthReducedU32::div_rem(p, self.width);
        (u as usize, v as usize)
    }
}

/// Square erosion of a set of pixels (sorted row-major indices): a pixel stays when every
/// pixel within `radius` (Chebyshev) is in the set and inside the image.
pub fn erode(pixels: &[u32], width: usize, height: usize, radius: usize) -> Vec<u32> {
    if radius == 0 || pixels.is_empty() {
        return pixels.to_vec();
    }
    let columns = Columns::new(width);
    let (mut u0, mut v0, mut u1, mut v1) = (usize::MAX, usize::MAX, 0, 0);
    for &p in pixels {
        let (u, v) = columns.uv(p);
        u0 = u0.min(u);
        v0 = v0.min(v);
        u1 = u1.max(u);
        v1 = v1.max(v);
    }
    let (bw, bh) = (u1 - u0 + 1, v1 - v0 + 1);
    let mut inside = vec![false; bw * bh];
    for &p in pixels {
        let (u, v) = columns.uv(p);
        inside[(v - v0) * bw + (u - u0)] = true;
    }
    // Separable min filter: rows, then columns. Outside the box (and the image) counts as out.
    let run_filter = |src: &[bool], len: usize, count: usize, stride: usize, step: usize| {
        let mut dst = vec![false; src.len()];
        let mut runs = vec![0usize; len];
        for line in 0..count {
            let base = line * stride;
            let mut run = 0usize;
            for i in 0..len {
                run = if src[base + i * step] { run + 1 } else { 0 };
                runs[i] = run;
            }
            // A pixel survives when the run ending `radius` past it covers 2·radius + 1.
            for i in 0..len {
                let end = i + radius;
                dst[base + i * step] = end < len && runs[end] > 2 * radius;
            }
        }
        dst
    };
    let rows = run_filter(&inside, bw, bh, bw, 1);
    let both = run_filter(&rows, bh, bw, 1, bw);
    // What survives is some of the mask's pixels.
    let mut out = Vec::with_capacity(pixels.len());
    for v in 0..bh {
        for u in 0..bw {
            let (gu, gv) = (u + u0, v + v0);
            // Pixels closer than `radius` to the image border cannot have a full window.
            if both[v * bw + u]
                && gu >= radius
                && gv >= radius
                && gu + radius < width
                && gv + radius < height
            {
                out.push((gv * width + gu) as u32);
            }
        }
    }
    out
}

/// The organised statistical outlier rule (module docs). Returns the kept (pixel, point) pairs
/// and how many were removed. `rows`: [`window_scores`]' working rows, kept across a scene's
/// objects.
fn remove_outliers(
    depth: &DepthMap,
    k: &Intrinsics,
    pixels: &[u32],
    config: &LiftConfig,
    rows: &mut Vec<Vec<f64>>,
) -> (Vec<(u32, Vector3<f64>)>, usize) {
    let columns = Columns::new(depth.width);
    let points: Vec<(u32, Vector3<f64>)> = collect_within(
        pixels.len(),
        pixels
            .iter()
            .filter_map(|&p| back_project_at(depth, k, columns.uv(p)).map(|x| (p, x))),
    );
    if points.is_empty() {
        return (points, 0);
    }
    // A dense grid over the instance's bounding box: pixel → index into `points`.
    let (mut u0, mut v0, mut u1, mut v1) = (usize::MAX, usize::MAX, 0, 0);
    for (p, _) in &points {
        let (u, v) = columns.uv(*p);
        u0 = u0.min(u);
        v0 = v0.min(v);
        u1 = u1.max(u);
        v1 = v1.max(v);
    }
    let (bw, bh) = (u1 - u0 + 1, v1 - v0 + 1);
    let mut grid = vec![u32::MAX; bw * bh];
    for (i, (p, _)) in points.iter().enumerate() {
        let (u, v) = columns.uv(*p);
        let (u, v) = (u - u0, v - v0);
        grid[v * bw + u] = i as u32;
    }
    let (points, grid, bled) = keep_main_components(points, grid, bw, config);
    let scores = window_scores(
        &points,
        &grid,
        (bw, bh),
        config.outlier_window_px as usize,
        |x| (x.z / k.fx).max(1e-9),
        rows,
    );
    let finite: Vec<f64> = collect_within(
        scores.len(),
        scores.iter().copied().filter(|s| s.is_finite()),
    );
    if finite.is_empty() {
        return (Vec::new(), points.len() + bled);
    }
    let mean = finite.iter().sum::<f64>() / finite.len() as f64;
    let var = finite.iter().map(|s| (s - mean).powi(2)).sum::<f64>() / finite.len() as f64;
    let limit = mean + config.outlier_std_ratio * var.sqrt();
    let kept: Vec<(u32, Vector3<f64>)> = collect_within(
        points.len(),
        points
            .iter()
            .zip(&scores)
            .filter(|(_, s)| **s <= limit)
            .map(|(p, _)| *p),
    );
    let removed = points.len() - kept.len() + bled;
    (kept, removed)
}

/// The outlier rule's statistic of every point: its mean distance to the points of the
/// window of radius `r` around its pixel (the centre left out), divided by its `footprint`;
/// infinite for a point with no neighbour. `grid` maps the cells of the `bw` × `bh` box to
/// indices into `points` (`u32::MAX`: no point).
///
/// The window is walked offset by offset over the whole box, not point by point: the points
/// are laid out on their pixels as three planes of coordinates with a margin of `r` cells all
/// round (NaN where there is no point), and for each offset of the window, in the window's
/// row-major order, one pass over the box adds every cell's distance to the cell at that
/// offset. Those passes are straight loops over contiguous memory that the compiler
/// vectorises. Each point still adds its distances in the window's row-major order, so its sum
/// is bit for bit the per-point loop's (adding 0.0 for a missing neighbour leaves a sum of
/// non-negative distances, which starts at +0.0, unchanged).
///
/// A distance is worked out once for its two cells: the distance from a cell to the one at
/// offset −o is the distance from that one to the cell at +o. So, a block of cells at a time
/// (kept small enough to stay in cache), the distances at the offsets after the centre are
/// worked out over the block and the `o` cells before it, and the passes, in the window's
/// order, read them: the offsets before the centre at their mirror's distances shifted back by
/// `o` cells. Half the square roots, and the same bits: `q − p` is exactly `−(p − q)`, so the
/// squares, their sum and its root are the same in either direction.
///
/// On a CPU with AVX2 the function runs compiled for it (`multiversion`): four lanes a vector
/// instead of the x86-64 baseline's two, and the same bits, since the compiler reorders no
/// floating-point arithmetic and fuses no multiply-add unless asked to, and each lane's
/// square root, products and sums are the exactly rounded IEEE operations.
#[multiversion::multiversion(targets("x86_64+avx2"))]
fn window_scores(
    points: &[PixelPoint],
    grid: &[u32],
    (bw, bh): (usize, usize),
    r: usize,
    footprint: impl Fn(&Vector3<f64>) -> f64,
    rows: &mut Vec<Vec<f64>>,
) -> Vec<f64> {
    let side = 2 * r + 1;
    let (pw, ph) = (bw + 2 * r, bh + 2 * r);
    let mut planes = [
        vec![f64::NAN; pw * ph],
        vec![f64::NAN; pw * ph],
        vec![f64::NAN; pw * ph],
    ];
    laid_out_cells(grid, bw, pw, r, |i, at| {
        let x = points[i].1;
        for (plane, value) in planes.iter_mut().zip([x.x, x.y, x.z]) {
            plane[at] = value;
        }
    });
    let [xs, ys, zs] = &planes;
    // The cells whose every window offset stays inside the padded box: the box's rows, from
    // the r-th cell of the first to the r-th last of the last (the margin columns between are
    // computed and never read).
    let (lo, hi) = (r * pw + r, (r + bh) * pw - r);
    // The offsets after the centre, in the window's row-major order (increasing); those
    // before it are their mirrors, in the reverse order.
    let after: Vec<usize> = (r * side + r + 1..side * side)
        .map(|k| (k / side) * pw + k % side - r * pw - r)
        .collect();
    let mut sums = vec![0.0f64; hi - lo];
    let mut counts = vec![0u32; hi - lo];
    const BLOCK: usize = 4096;
    // For the block from cell `a`, distances[j][t] is the distance from cell `a − o + t` to
    // cell `a + t` (o = after[j]), NaN when either holds no point.
    // The rows (one per offset after the centre, twelve for the default window) are the
    // caller's, kept from one object to the next: each is refilled before it is read, so only
    // their growth is zeroed, not every object's rows (that zeroing was 2 % of lift). A box
    // smaller than a block needs rows of its own size only.
    let block = BLOCK.min(hi - lo);
    if rows.len() < after.len() {
        rows.resize_with(after.len(), Vec::new);
    }
    for (row, &o) in rows.iter_mut().zip(&after) {
        if row.len() < block + o {
            row.resize(block + o, 0.0);
        }
    }
    let distances = &mut rows[..after.len()];
    for a in (lo..hi).step_by(BLOCK) {
        let b = (a + BLOCK).min(hi);
        for (row, &o) in distances.iter_mut().zip(&after) {
            let (from, len) = (a - o, b - a + o);
            let cells = xs[from..from + len]
                .iter()
                .zip(&ys[from..from + len])
                .zip(&zs[from..from + len]);
            let (to, end) = (from + o, from + o + len);
            let neighbours = xs[to..end].iter().zip(&ys[to..end]).zip(&zs[to..end]);
            for (d, (((x, y), z), ((qx, qy), qz))) in
                row[..len].iter_mut().zip(cells.zip(neighbours))
            {
                let (dx, dy, dz) = (qx - x, qy - y, qz - z);
                *d = (dx * dx + dy * dy + dz * dz).sqrt();
            }
        }
        let sums = &mut sums[a - lo..b - lo];
        let counts = &mut counts[a - lo..b - lo];
        let mut add = |found: &[f64]| {
            for ((sum, count), &d) in sums.iter_mut().zip(counts.iter_mut()).zip(found) {
                // A missing neighbour is NaN (so is every distance of an empty cell).
                let found = !d.is_nan();
                *sum += if found { d } else { 0.0 };
                *count += u32::from(found);
            }
        };
        // Before the centre: cell `a + t` and the cell `o` before it, distances[j][t].
        for row in distances.iter().rev() {
            add(&row[..b - a]);
        }
        // After it: cell `a + t` and the cell `o` after it, distances[j][t + o].
        for (row, &o) in distances.iter().zip(&after) {
            add(&row[o..o + b - a]);
        }
    }
    let mut scores = vec![f64::INFINITY; points.len()];
    laid_out_cells(grid, bw, pw, r, |i, at| {
        let count = counts[at - lo];
        if count > 0 {
            scores[i] = sums[at - lo] / f64::from(count) / footprint(&points[i].1);
        }
    });
    scores
}

/// Calls `each` with every point of the `bw`-wide `grid` (a cell's point index, `u32::MAX` for
/// none) and its cell in the grid padded by `r` cells all round (`pw` wide), row by row. Plain
/// loops: the same walk as an iterator of `flat_map` and `filter` took 4 % of lift.
#[inline(always)]
fn laid_out_cells(
    grid: &[u32],
    bw: usize,
    pw: usize,
    r: usize,
    mut each: impl FnMut(usize, usize),
) {
    for (v, row) in grid.chunks_exact(bw).enumerate() {
        let start = (v + r) * pw + r;
        for (u, &i) in row.iter().enumerate() {
            if i != u32::MAX {
                each(i as usize, start + u);
            }
        }
    }
}

/// A back-projected pixel: its row-major index and its camera-frame point (metres).
type PixelPoint = (u32, Vector3<f64>);

/// The connectivity rule of the module docs: returns the kept points, their grid (same box)
/// and how many points were dropped.
///
/// The components are found over runs, not points: each row of the box is cut into runs of
/// points joined to their left neighbour, and only the joins between rows go through the
/// union-find, over the runs (two rows' overlapping runs join many times over, and a join of
/// the pair just joined is skipped). Only the partition matters to the rule (which points are
/// kept, in their order), and it is the one joining every pair of neighbours gives: the test
/// reference is that, point by point.
fn keep_main_components(
    points: Vec<PixelPoint>,
    grid: Vec<u32>,
    bw: usize,
    config: &LiftConfig,
) -> (Vec<PixelPoint>, Vec<u32>, usize) {
    let n = points.len();
    // The depth of every cell, NaN where there is none (NaN joins nothing, as below).
    let z: Vec<f64> = grid
        .iter()
        .map(|&i| {
            if i == u32::MAX {
                f64::NAN
            } else {
                points[i as usize].1.z
            }
        })
        .collect();
    let (jump, relative) = (config.component_jump_m, config.component_jump_relative);
    let joined = |a: f64, b: f64| (a - b).abs() <= jump.max(relative * a.min(b));
    const NONE: u32 = u32::MAX;
    let mut run_of = vec![NONE; grid.len()];
    let mut run_sizes: Vec<usize> = Vec::new();
    for (row, (cells, runs)) in grid
        .chunks_exact(bw)
        .zip(run_of.chunks_exact_mut(bw))
        .enumerate()
    {
        let depths = &z[row * bw..(row + 1) * bw];
        let mut current = NONE;
        for (u, (&i, run)) in cells.iter().zip(runs.iter_mut()).enumerate() {
            if i == NONE {
                current = NONE;
                continue;
            }
            if current == NONE || !joined(depths[u - 1], depths[u]) {
                current = run_sizes.len() as u32;
                run_sizes.push(0);
            }
            *run = current;
            run_sizes[current as usize] += 1;
        }
    }
    let mut parent: Vec<u32> = (0..run_sizes.len() as u32).collect();
    fn find(parent: &mut [u32], mut i: u32) -> u32 {
        while parent[i as usize] != i {
            parent[i as usize] = parent[parent[i as usize] as usize];
            i = parent[i as usize];
        }
        i
    }
    let mut last = (NONE, NONE);
    for (cell, (&a, &b)) in run_of
        .iter()
        .zip(&run_of[bw.min(run_of.len())..])
        .enumerate()
    {
        if a == NONE || b == NONE || (a, b) == last || !joined(z[cell], z[cell + bw]) {
            continue;
        }
        let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
        if ra != rb {
            parent[ra.max(rb) as usize] = ra.min(rb);
        }
        last = (a, b);
    }
    // Component sizes by root run.
    let mut sizes = vec![0usize; run_sizes.len()];
    for run in 0..run_sizes.len() as u32 {
        let root = find(&mut parent, run);
        sizes[root as usize] += run_sizes[run as usize];
    }
    let largest = sizes.iter().copied().max().unwrap_or(0);
    let minimum = (config.component_min_fraction * largest as f64).ceil() as usize;
    if sizes.iter().all(|&s| s == 0 || s >= minimum) {
        return (points, grid, 0);
    }
    let mut keep = vec![false; n];
    for (&i, &run) in grid.iter().zip(&run_of) {
        if i != NONE {
            keep[i as usize] = sizes[find(&mut parent, run) as usize] >= minimum;
        }
    }
    let mut remap = vec![u32::MAX; n];
    let mut kept = Vec::with_capacity(n);
    for (i, point) in points.into_iter().enumerate() {
        if keep[i] {
            remap[i] = kept.len() as u32;
            kept.push(point);
        }
    }
    let dropped = n - kept.len();
    let grid = grid
        .into_iter()
        .map(|i| if i == u32::MAX { i } else { remap[i as usize] })
        .collect();
    (kept, grid, dropped)
}

/// `items` collected into a vector made at `bound` (at least as many as `items` gives), not
/// grown by doubling: the big lists of a scene (hundreds of thousands of pixels or points),
/// collected through a filter whose length is not known beforehand, were copied several times
/// over as they grew.
fn collect_within<T>(bound: usize, items: impl Iterator<Item = T>) -> Vec<T> {
    let mut all = Vec::with_capacity(bound);
    all.extend(items);
    all
}

/// A fitted plane n·p + offset = 0 in the camera frame, n toward the camera.
#[derive(Debug, Clone)]
pub struct Plane {
    /// Unit normal.
    pub normal: Vector3<f64>,
    /// Offset in metres (positive: the camera is on the normal's side).
    pub offset_m: f64,
    /// Inliers among the points fitted on.
    pub inliers: usize,
    /// Inliers / points.
    pub inlier_fraction: f64,
    /// RMS distance of the inliers, metres.
    pub rmse_m: f64,
}

fn scene_rng(scene_id: &str, seed: u64) -> rand_chacha::ChaCha8Rng {
    // FNV-1a over the scene id, mixed with the seed: independent streams per scene.
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in scene_id.bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    rand_chacha::ChaCha8Rng::seed_from_u64(h ^ seed.rotate_left(17))
}

/// The table plane: RANSAC with a least-squares refinement, sequential over planes.
///
/// The table is the plane the objects stand on, so a candidate is accepted only when at least
/// `plane_min_objects_above` of the objects' points (`objects`, camera frame) lie on its camera
/// side. A table mask that also covers a cabinet front (kitchen counters, vanities) gives a
/// vertical plane first; its inliers are then set aside and the next plane is fitted, up to
/// three planes. With no objects, the first plane is the table.
pub fn fit_plane(
    points: &[Vector3<f64>],
    objects: &[Vector3<f64>],
    scene_id: &str,
    seed: u64,
    config: &LiftConfig,
    source: &str,
) -> Result<Plane, LiftError> {
    if points.len() < (config.plane_min_points as usize).max(3) {
        return Err(LiftError::NoPlane(format!(
            "only {} {source} points with valid depth (expected at least {}: mark the table as \
             an instance with \"support\": true, or check the depth map)",
            points.len(),
            config.plane_min_points
        )));
    }
    let stride = points
        .len()
        .div_ceil(config.plane_max_points.max(3) as usize);
    let mut remaining: Vec<Vector3<f64>> = points.iter().step_by(stride).copied().collect();
    let mut rng = scene_rng(scene_id, seed);
    let threshold = config.plane_threshold_m;
    let mut rejected = Vec::new();
    for attempt in 0..3 {
        let Some((n, d)) = ransac_once(&remaining, &mut rng, config) else {
            break;
        };
        let residuals: Vec<f64> = remaining
            .iter()
            .map(|p| (n.dot(p) + d).abs())
            .filter(|r| *r < threshold)
            .collect();
        let fraction = residuals.len() as f64 / remaining.len() as f64;
        // The first plane must explain a share of the support's points (is there a plane at
        // all?), counted with a tolerance that grows with the depth as the sensor's noise does.
        // A later one is what is left once a cabinet front is set aside: a far counter top seen
        // at a grazing angle may be a small share of it, so it needs enough points, and objects
        // standing on it, rather than a share.
        if attempt == 0 {
            let share = share_near_plane(&remaining, &n, d, config);
            if share < config.plane_min_inlier_fraction {
                return Err(LiftError::NoPlane(format!(
                    "the best plane explains {:.0}% of {} {source} points within {} mm and \
                     {:.0}% within the depth-scaled tolerance (plane_share_depth_m = {}; \
                     expected at least {:.0}%: check the depth scale, or mark the table with \
                     \"support\": true)",
                    fraction * 100.0,
                    remaining.len(),
                    threshold * 1000.0,
                    share * 100.0,
                    config.plane_share_depth_m,
                    config.plane_min_inlier_fraction * 100.0
                )));
            }
        }
        if residuals.len() < (config.plane_min_points as usize).max(3) {
            rejected.push(format!(
                "the next plane has {} {source} points (expected at least {})",
                residuals.len(),
                config.plane_min_points
            ));
            break;
        }
        let above = if objects.is_empty() {
            1.0
        } else {
            objects
                .iter()
                .filter(|p| n.dot(p) + d > -2.0 * threshold)
                .count() as f64
                / objects.len() as f64
        };
        if above >= config.plane_min_objects_above {
            let rmse =
                (residuals.iter().map(|r| r * r).sum::<f64>() / residuals.len() as f64).sqrt();
            return Ok(Plane {
                normal: n,
                offset_m: d,
                inliers: residuals.len(),
                inlier_fraction: fraction,
                rmse_m: rmse,
            });
        }
        rejected.push(format!(
            "a plane through {:.0}% of the {source} points has {:.0}% of the object points on \
             its camera side",
            fraction * 100.0,
            above * 100.0
        ));
        remaining.retain(|p| (n.dot(p) + d).abs() >= threshold);
        if remaining.len() < (config.plane_min_points as usize).max(3) {
            break;
        }
    }
    Err(LiftError::NoPlane(format!(
        "no plane has the objects standing on it ({}; expected at least {:.0}%: check the \
         masks of the table and the objects)",
        rejected.join("; "),
        config.plane_min_objects_above * 100.0
    )))
}

/// The share of `points` within the depth-scaled tolerance of the plane n·p + d = 0:
/// `plane_threshold_m · max(1, (depth / plane_share_depth_m)²)`.
fn share_near_plane(points: &[Vector3<f64>], n: &Vector3<f64>, d: f64, config: &LiftConfig) -> f64 {
    if points.is_empty() {
        return 0.0;
    }
    let threshold = config.plane_threshold_m;
    let near = points
        .iter()
        .filter(|p| {
            let scale = if config.plane_share_depth_m > 0.0 {
                (p.z.abs() / config.plane_share_depth_m).powi(2).max(1.0)
            } else {
                1.0
            };
            (n.dot(p) + d).abs() < threshold * scale
        })
        .count();
    near as f64 / points.len() as f64
}

/// One RANSAC plane with two least-squares refinements, oriented toward the camera.
fn ransac_once(
    sample: &[Vector3<f64>],
    rng: &mut rand_chacha::ChaCha8Rng,
    config: &LiftConfig,
) -> Option<(Vector3<f64>, f64)> {
    if sample.len() < 3 {
        return None;
    }
    let threshold = config.plane_threshold_m;
    // Hypotheses are scored on an evenly spread subset; the winner is refined on the sample.
    let scoring: Vec<Vector3<f64>> = sample
        .iter()
        .step_by(sample.len().div_ceil(2000))
        .copied()
        .collect();
    let mut best: Option<(usize, Vector3<f64>, f64)> = None;
    for _ in 0..config.plane_iterations {
        let i = rng.random_range(0..sample.len());
        let j = rng.random_range(0..sample.len());
        let l = rng.random_range(0..sample.len());
        let n = (sample[j] - sample[i]).cross(&(sample[l] - sample[i]));
        let norm = n.norm();
        if norm < 1e-12 {
            continue;
        }
        let n = n / norm;
        let d = -n.dot(&sample[i]);
        let count = scoring
            .iter()
            .filter(|p| (n.dot(p) + d).abs() < threshold)
            .count();
        if best.as_ref().is_none_or(|b| count > b.0) {
            best = Some((count, n, d));
        }
    }
    let (_, mut n, mut d) = best?;
    for _ in 0..2 {
        let inliers: Vec<&Vector3<f64>> = sample
            .iter()
            .filter(|p| (n.dot(p) + d).abs() < threshold)
            .collect();
        if inliers.len() < 3 {
            break;
        }
        let centroid = inliers.iter().fold(Vector3::zeros(), |a, p| a + **p) / inliers.len() as f64;
        let mut cov = Matrix3::zeros();
        for p in &inliers {
            let q = **p - centroid;
            cov += q * q.transpose();
        }
        let eigen = cov.symmetric_eigen();
        let (idx, _) = eigen
            .eigenvalues
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(b.1))
            .unwrap_or((0, &0.0));
        n = eigen.eigenvectors.column(idx).into_owned().normalize();
        d = -n.dot(&centroid);
    }
    if d < 0.0 {
        n = -n;
        d = -d;
    }
    Some((n, d))
}

/// The table frame in the camera frame.
#[derive(Debug, Clone)]
pub struct TableFrame {
    /// Rows are the table axes x, y, z in camera coordinates.
    pub rotation: Matrix3<f64>,
    /// The table origin in camera coordinates, metres.
    pub origin: Vector3<f64>,
    /// Zone width and depth, metres.
    pub zone_m: [f64; 2],
}

impl TableFrame {
    fn new(plane: &Plane, points: &[Vector3<f64>], config: &LiftConfig) -> Result<Self, LiftError> {
        let z = plane.normal;
        let camera_x = Vector3::x();
        let x = camera_x - z * camera_x.dot(&z);
        if x.norm() < 1e-6 {
            return Err(LiftError::NoPlane(
                "the table plane is perpendicular to the camera's x axis (a camera rolled by \
                 90°); rotate the images upright"
                    .to_owned(),
            ));
        }
        let x = x.normalize();
        let y = z.cross(&x);
        let threshold = config.plane_threshold_m * 2.0;
        // Each pixel stands for a patch of the table whose area grows with the cube of its
        // depth (z² for the distance, z / |n·p| for the slant, and |n·p| is the same for every
        // point of the plane): weighting by it makes the points a uniform sample of the visible
        // top, whose marginals along x and y are flat near the edges of a rectangle.
        let mut us = Vec::with_capacity(points.len());
        let mut vs = Vec::with_capacity(points.len());
        for p in points {
            if (z.dot(p) + plane.offset_m).abs() < threshold {
                let weight = p.z.abs().powi(3);
                us.push((x.dot(p), weight));
                vs.push((y.dot(p), weight));
            }
        }
        let q = config.zone_percentile.clamp(0.0, 16.0) / 100.0;
        let (u0, u1) = sharp_extent(&us, q);
        let (v0, v1) = sharp_extent(&vs, q);
        let origin = x * u0 + y * v0 - z * plane.offset_m;
        Ok(Self {
            rotation: Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()]),
            origin,
            zone_m: [u1 - u0, v1 - v0],
        })
    }

    /// A camera-frame point in the table frame (metres).
    pub fn to_table(&self, p: Vector3<f64>) -> Vector3<f64> {
        self.rotation * (p - self.origin)
    }

    /// The 4×4 rigid transform, row-major.
    pub fn table_from_camera(&self) -> [[f64; 4]; 4] {
        let t = -(self.rotation * self.origin);
        let r = &self.rotation;
        [
            [r[(0, 0)], r[(0, 1)], r[(0, 2)], t.x],
            [r[(1, 0)], r[(1, 1)], r[(1, 2)], t.y],
            [r[(2, 0)], r[(2, 1)], r[(2, 2)], t.z],
            [0.0, 0.0, 0.0, 1.0],
        ]
    }
}

/// The extent of a distribution that is flat near its two sharp edges, from weighted
/// samples: at each side, the weighted quantiles at `q` and `3q` give the local density, and
/// the edge is where that density, carried outward, leaves the `q` share behind. Symmetric
/// noise blurs an edge without moving it, and what happens further in (objects hiding part of
/// the table) does not matter.
fn sharp_extent(samples: &[(f64, f64)], q: f64) -> (f64, f64) {
    if samples.is_empty() {
        return (0.0, 0.0);
    }
    let mut quantiles = WeightedQuantiles::new(samples);
    let shares = [q, 3.0 * q, 1.0 - q, 1.0 - 3.0 * q];
    quantiles.gather_for(&shares.map(|share| share * quantiles.total));
    let mut quantile = |share: f64| quantiles.at(share * quantiles.total);
    let (lo_a, lo_b) = (quantile(q), quantile(3.0 * q));
    let (hi_a, hi_b) = (quantile(1.0 - q), quantile(1.0 - 3.0 * q));
    (lo_a - (lo_b - lo_a) / 2.0, hi_a + (hi_a - hi_b) / 2.0)
}

/// Weighted quantiles of a few hundred thousand samples without sorting them: the samples are
/// bucketed by value (value-ordered buckets), a quantile walks the buckets' weights and sorts
/// only the bucket it falls in, gathered from the samples when it is needed. The answer is the
/// sorted walk's: the first value at which the weight accumulated in value order reaches the
/// target.
///
/// The few quantiles of the zone fall in a few buckets, so gathering each from the bucket
/// numbers costs less than laying every sample out bucket by bucket (a counting sort, what
/// this did before, a third of the table frame's time). A walk that needs many buckets (the
/// accumulated weight falling short of the target by rounding, bucket after bucket) gets that
/// layout after all, once.
struct WeightedQuantiles<'a> {
    samples: &'a [(f64, f64)],
    /// The bucket of each sample.
    bucket_of: Vec<u16>,
    /// How many samples each bucket holds, and their weight.
    counts: Vec<u32>,
    weights: Vec<f64>,
    total: f64,
    max: f64,
    /// The buckets gathered so far, each with its samples in the samples' order.
    gathered: Vec<(usize, Vec<(f64, f64)>)>,
    /// Made when more than [`Self::GATHERED`] buckets were needed.
    laid_out: Option<ByBucket>,
}

/// The least and greatest values of `samples` (by `f64::min` and `f64::max`, which pass NaN
/// over), as the fold in the samples' order gives them. Four running extremes instead of one:
/// the fold's chain of dependent `min`s and `max`s took a quarter of the zone's time. The order
/// of taking extremes changes only the sign of a zero (`min(0.0, -0.0)` may be either), so an
/// extreme that is zero is found again by the fold.
fn value_range(samples: &[(f64, f64)]) -> (f64, f64) {
    let chunks = samples.chunks_exact(4);
    let (mut lo, mut hi) = value_range_in_order(chunks.remainder());
    let mut lanes = ([f64::INFINITY; 4], [f64::NEG_INFINITY; 4]);
    for chunk in chunks {
        for (lane, &(value, _)) in chunk.iter().enumerate() {
            lanes.0[lane] = lanes.0[lane].min(value);
            lanes.1[lane] = lanes.1[lane].max(value);
        }
    }
    for lane in 0..4 {
        lo = lo.min(lanes.0[lane]);
        hi = hi.max(lanes.1[lane]);
    }
    if lo == 0.0 || hi == 0.0 {
        return value_range_in_order(samples);
    }
    (lo, hi)
}

/// The least and greatest values of `samples`, by one fold in their order.
fn value_range_in_order(samples: &[(f64, f64)]) -> (f64, f64) {
    samples.iter().fold(
        (f64::INFINITY, f64::NEG_INFINITY),
        |(lo, hi), &(value, _)| (lo.min(value), hi.max(value)),
    )
}

/// Every sample, bucket after bucket, and where each bucket starts (`starts[b]..starts[b + 1]`).
type ByBucket = (Vec<(f64, f64)>, Vec<usize>);

impl<'a> WeightedQuantiles<'a> {
    /// The most buckets gathered one by one, each by a pass over the bucket numbers.
    const GATHERED: usize = 8;

    fn new(samples: &'a [(f64, f64)]) -> Self {
        let (lo, hi) = value_range(samples);
        let buckets = (samples.len() / 32).clamp(1, 1 << 14);
        let scale = if hi > lo {
            buckets as f64 / (hi - lo)
        } else {
            0.0
        };
        // Rounding is monotone, so the bucket of a larger value is never an earlier one.
        let bucket = |value: f64| (((value - lo) * scale) as usize).min(buckets - 1);
        let mut counts = vec![0u32; buckets];
        let mut weights = vec![0.0; buckets];
        // Neighbouring samples (pixels of a row) often share a bucket: the bucket being filled
        // is held in registers and stored when the next sample leaves it, instead of each
        // sample loading what the one before it stored. Its weight is added to in the same
        // order, one sample at a time, so every sum is the same to the bit.
        let mut bucket_of = Vec::with_capacity(samples.len());
        let (mut current, mut count, mut weight_sum) = (0, counts[0], weights[0]);
        for &(value, weight) in samples {
            let b = bucket(value);
            if b != current {
                (counts[current], weights[current]) = (count, weight_sum);
                (current, count, weight_sum) = (b, counts[b], weights[b]);
            }
            count += 1;
            weight_sum += weight;
            bucket_of.push(b as u16);
        }
        (counts[current], weights[current]) = (count, weight_sum);
        Self {
            samples,
            bucket_of,
            counts,
            total: weights.iter().sum(),
            weights,
            max: hi,
            gathered: Vec::new(),
            laid_out: None,
        }
    }

    /// The samples of bucket `b`, in the samples' order.
    fn bucket(&mut self, b: usize) -> &[(f64, f64)] {
        if self.laid_out.is_none() {
            if let Some(at) = self.gathered.iter().position(|(g, _)| *g == b) {
                return &self.gathered[at].1;
            }
            if self.gathered.len() < Self::GATHERED {
                let mut found = Vec::with_capacity(self.counts[b] as usize);
                found.extend(
                    self.samples
                        .iter()
                        .zip(&self.bucket_of)
                        .filter(|(_, &of)| usize::from(of) == b)
                        .map(|(&sample, _)| sample),
                );
                self.gathered.push((b, found));
                return &self.gathered[self.gathered.len() - 1].1;
            }
        }
        let (laid, starts) = self.laid_out.get_or_insert_with(|| {
            let mut starts = vec![0usize; self.counts.len() + 1];
            for (b, &count) in self.counts.iter().enumerate() {
                starts[b + 1] = starts[b] + count as usize;
            }
            let mut next = starts.clone();
            let mut laid = vec![(0.0, 0.0); self.samples.len()];
            for (&sample, &of) in self.samples.iter().zip(&self.bucket_of) {
                laid[next[usize::from(of)]] = sample;
                next[usize::from(of)] += 1;
            }
            (laid, starts)
        });
        &laid[starts[b]..starts[b + 1]]
    }

    /// Gathers, in one pass over the samples, the bucket in which [`Self::at`] will find each
    /// of `targets` (the first whose weight, added to those before it, reaches the target), so
    /// that `at` finds them gathered: one pass for the zone's four quantiles, not one each.
    /// `at` itself is unchanged: a bucket not gathered here is gathered when it is needed.
    fn gather_for(&mut self, targets: &[f64]) {
        let mut wanted: Vec<usize> = Vec::new();
        for &target in targets {
            let first = self.walk_to(0, 0.0, target).map(|(b, _)| b);
            if let Some(b) =
                first.filter(|b| !wanted.contains(b) && !self.gathered.iter().any(|(g, _)| g == b))
            {
                wanted.push(b);
            }
        }
        wanted.truncate(Self::GATHERED.saturating_sub(self.gathered.len()));
        if self.laid_out.is_some() || wanted.is_empty() {
            return;
        }
        // Each wanted bucket's slot among the gathered lists; NONE for the others.
        const NONE: u8 = u8::MAX;
        let mut slot = vec![NONE; self.counts.len()];
        let mut found: Vec<Vec<(f64, f64)>> = Vec::with_capacity(wanted.len());
        for (k, &b) in wanted.iter().enumerate() {
            slot[b] = k as u8;
            found.push(Vec::with_capacity(self.counts[b] as usize));
        }
        for (&sample, &of) in self.samples.iter().zip(&self.bucket_of) {
            let k = slot[usize::from(of)];
            if k != NONE {
                found[usize::from(k)].push(sample);
            }
        }
        self.gathered.extend(wanted.into_iter().zip(found));
    }

    /// The first value, in value order, at which the accumulated weight reaches `target`.
    fn at(&mut self, target: f64) -> f64 {
        let (mut from, mut acc) = (0, 0.0);
        while let Some((b, before)) = self.walk_to(from, acc, target) {
            acc = before;
            let mut bucket = self.bucket(b).to_vec();
            bucket.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
            for (value, weight) in bucket {
                acc += weight;
                if acc >= target {
                    return value;
                }
            }
            from = b + 1;
        }
        self.max
    }

    /// The walk over whole buckets, from bucket `from` with `acc` accumulated: the first
    /// non-empty bucket whose weight, added to what comes before it, reaches `target`, and the
    /// weight accumulated before it. Shared by [`Self::at`] and [`Self::gather_for`], so that
    /// the buckets gathered beforehand are the ones the quantiles walk into.
    fn walk_to(&self, from: usize, mut acc: f64, target: f64) -> Option<(usize, f64)> {
        for b in from..self.weights.len() {
            if self.counts[b] == 0 {
                continue;
            }
            if acc + self.weights[b] < target {
                acc += self.weights[b];
                continue;
            }
            return Some((b, acc));
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// [`Extremes`] chooses what `min_by` and `max_by` by `total_cmp` chose over the whole
    /// list (the code it replaced, kept here word for word), on lists whose coordinates tie
    /// often (five values, both zeros among them) and whose camera-frame points all differ.
    #[test]
    fn extremes_are_those_of_min_by_and_max_by() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(23);
        let values = [-1.0, -0.0, 0.0, 1.0, 2.0];
        for case in 0..5_000 {
            let len = rng.random_range(1..24);
            let table_points: Vec<FramedPoint> = (0..len)
                .map(|i| {
                    let mut pick = || values[rng.random_range(0..values.len())];
                    let t = Vector3::new(pick(), pick(), pick());
                    (t, Vector3::new(i as f64, 0.0, 1.0 + i as f64))
                })
                .collect();
            let by_axis = |axis: usize| {
                move |a: &&FramedPoint, b: &&FramedPoint| a.0[axis].total_cmp(&b.0[axis])
            };
            let first = &table_points[0];
            let expected = Extremes {
                lo_x: *table_points.iter().min_by(by_axis(0)).unwrap_or(first),
                hi_x: *table_points.iter().max_by(by_axis(0)).unwrap_or(first),
                hi_y: *table_points.iter().max_by(by_axis(1)).unwrap_or(first),
                lo_y: table_points.iter().min_by(by_axis(1)).unwrap_or(first).0,
                lo_z: table_points.iter().min_by(by_axis(2)).unwrap_or(first).0.z,
            };
            let mut extremes = Extremes::new(first.0, first.1);
            for &(t, point) in &table_points {
                extremes.take(t, point);
            }
            // Bits, not values: -0.0 and 0.0 are told apart.
            let bits = |e: &Extremes| {
                [
                    e.lo_x.0, e.lo_x.1, e.hi_x.0, e.hi_x.1, e.hi_y.0, e.hi_y.1, e.lo_y,
                ]
                .iter()
                .flat_map(|v| v.iter().map(|c| c.to_bits()).collect::<Vec<_>>())
                .chain([e.lo_z.to_bits()])
                .collect::<Vec<_>>()
            };
            assert_eq!(
                bits(&extremes),
                bits(&expected),
                "case {case}: {table_points:?}"
            );
        }
    }

    /// `Columns::uv` is the division's quotient and remainder: widths at the edges (1, powers
    /// of two and their neighbours, the largest) with indices at the ends of rows, and random
    /// pairs.
    #[test]
    fn columns_split_indices_as_division_does() {
        let check = |width: u32, p: u32| {
            let expected = ((p % width) as usize, (p / width) as usize);
            assert_eq!(
                Columns::new(width as usize).uv(p),
                expected,
                "{p} in width {width}"
            );
        };
        let mut widths = vec![1, 2, 3, 640, 1023, 1024, 1025, 1280, u32::MAX - 1, u32::MAX];
        widths.extend((1..32).flat_map(|b| [(1u32 << b) - 1, 1 << b, (1u32 << b) + 1]));
        for &width in &widths {
            for k in [0u32, 1, 2, 719, 1024, 4_000_000] {
                let end = k.saturating_mul(width);
                for p in [end.saturating_sub(1), end, end.saturating_add(1)] {
                    check(width, p);
                }
            }
            check(width, u32::MAX);
            check(width, u32::MAX - 1);
        }
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for _ in 0..1_000_000 {
            let shift = rng.random_range(0..31);
            let width = rng.random_range(1..=u32::MAX >> shift);
            check(width, rng.random());
        }
        // A width of 0 has no pixels; it is taken as 1, not a division by zero.
        assert_eq!(Columns::new(0).uv(5), (0, 5));
    }

    /// The weighted quantile as a sorted walk: the first value at which the weight
    /// accumulated in value order reaches `target`.
    fn sorted_walk(samples: &[(f64, f64)], target: f64) -> f64 {
        let mut sorted = samples.to_vec();
        sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut acc = 0.0;
        for (value, weight) in &sorted {
            acc += weight;
            if acc >= target {
                return *value;
            }
        }
        sorted[sorted.len() - 1].0
    }

    #[test]
    fn bucket_weights_are_the_per_sample_sums_to_the_bit() {
        // Rows of a table seen in pixel order: runs of samples in one bucket, runs of samples
        // each in another, and weights whose sums round (the cube of a depth).
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut samples = Vec::new();
        for row in 0..200 {
            for column in 0..300 {
                let value = if row % 2 == 0 {
                    f64::from(row) * 0.01 + rng.random_range(0.0..1e-4)
                } else {
                    f64::from(column) * 0.003
                };
                let depth: f64 = rng.random_range(0.4..2.5);
                samples.push((value, depth.powi(3)));
            }
        }
        let quantiles = WeightedQuantiles::new(&samples);
        let buckets = quantiles.counts.len();
        let (mut counts, mut weights) = (vec![0u32; buckets], vec![0.0f64; buckets]);
        for (&(_, weight), &b) in samples.iter().zip(&quantiles.bucket_of) {
            counts[usize::from(b)] += 1;
            weights[usize::from(b)] += weight;
        }
        assert_eq!(quantiles.counts, counts);
        let bits = |w: &[f64]| w.iter().map(|w| w.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&quantiles.weights), bits(&weights));
        // Control: the same sums in another order differ in some bucket.
        let mut reordered = vec![0.0f64; buckets];
        for (&(_, weight), &b) in samples.iter().zip(&quantiles.bucket_of).rev() {
            reordered[usize::from(b)] += weight;
        }
        assert_ne!(bits(&reordered), bits(&weights));
    }

    #[test]
    fn buckets_gathered_in_one_pass_are_the_ones_the_quantiles_need() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(23);
        for case in 0..20 {
            let samples: Vec<(f64, f64)> = (0..5_000 + 3_000 * case)
                .map(|_| {
                    let value: f64 = rng.random_range(-0.7..0.9);
                    let depth: f64 = rng.random_range(0.4..2.5);
                    (value, depth.powi(3))
                })
                .collect();
            let q = 0.002 * f64::from(case as u32 + 1);
            let shares = [q, 3.0 * q, 1.0 - q, 1.0 - 3.0 * q];
            let mut one_by_one = WeightedQuantiles::new(&samples);
            let mut prepared = WeightedQuantiles::new(&samples);
            let targets = shares.map(|share| share * prepared.total);
            prepared.gather_for(&targets);
            let gathered = prepared.gathered.len();
            assert!((1..=4).contains(&gathered), "{gathered}");
            for target in targets {
                assert_eq!(
                    prepared.at(target).to_bits(),
                    one_by_one.at(target).to_bits()
                );
            }
            // Every bucket the walks needed was gathered beforehand, with the same samples.
            assert_eq!(prepared.gathered.len(), gathered, "case {case}");
            for (b, list) in &prepared.gathered {
                let (_, same) = one_by_one
                    .gathered
                    .iter()
                    .find(|(g, _)| g == b)
                    .expect("the same bucket");
                assert_eq!(list, same);
            }
        }
    }

    #[test]
    fn bucketed_quantiles_are_the_sorted_walks() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        // A table's flat marginal with noisy edges, ties, and small weights (integer weights
        // keep the sums exact, so any order of adding gives the sorted walk's answer).
        let mut samples: Vec<(f64, f64)> = (0..50_000)
            .map(|_| {
                let value: f64 = rng.random_range(-0.4..0.6);
                let weight = f64::from(rng.random_range(1u32..20));
                ((value * 512.0).round() / 512.0, weight)
            })
            .collect();
        samples.push((-3.0, 1.0));
        let mut quantiles = WeightedQuantiles::new(&samples);
        for share in [0.0, 0.01, 0.03, 0.5, 0.97, 0.99, 1.0] {
            let target = share * quantiles.total;
            assert_eq!(
                quantiles.at(target),
                sorted_walk(&samples, target),
                "{share}"
            );
        }
        // The zone's quantiles gather their buckets one by one; past a few buckets every
        // sample is laid out by bucket once, and the answers stay the sorted walk's.
        assert!(quantiles.laid_out.is_none());
        for i in 0..=40 {
            let target = f64::from(i) / 40.0 * quantiles.total;
            assert_eq!(quantiles.at(target), sorted_walk(&samples, target), "{i}");
        }
        assert!(quantiles.laid_out.is_some());
        // Control: the walk in the samples' own order (unsorted) gives other answers.
        let unsorted = |target: f64| {
            let mut acc = 0.0;
            samples
                .iter()
                .find(|s| {
                    acc += s.1;
                    acc >= target
                })
                .map_or(f64::NAN, |s| s.0)
        };
        let target = 0.03 * quantiles.total;
        assert_ne!(unsorted(target), sorted_walk(&samples, target));
        // One value: every quantile is it.
        let mut one = WeightedQuantiles::new(&[(2.5, 1.0), (2.5, 3.0)]);
        assert_eq!((one.at(0.0), one.at(4.0), one.at(9.0)), (2.5, 2.5, 2.5));
    }

    /// `value_range` is the fold in the samples' order bit for bit (`to_bits`), on random
    /// values with NaNs, ties, infinities and zeros of both signs, at every length up to 40.
    /// Control: the zero extremes, where the order changes the sign, are taken again by the
    /// fold in some cases and not in others, so both paths are compared; with that second fold
    /// removed, the comparison fails on a zero's sign (tried on 2026-11-28).
    #[test]
    fn value_range_is_the_fold_bit_for_bit() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let picks = [
            0.0,
            -0.0,
            1.5,
            -2.25,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            1e-300,
        ];
        let (mut zero_extremes, mut others) = (0, 0);
        for _ in 0..4000 {
            let len = rng.random_range(0..=40usize);
            let samples: Vec<(f64, f64)> = (0..len)
                .map(|_| {
                    let value = if rng.random_bool(0.5) {
                        picks[rng.random_range(0..picks.len())]
                    } else {
                        rng.random_range(-1.0..1.0)
                    };
                    (value, 1.0)
                })
                .collect();
            let fold = value_range_in_order(&samples);
            let range = value_range(&samples);
            assert_eq!(
                (range.0.to_bits(), range.1.to_bits()),
                (fold.0.to_bits(), fold.1.to_bits()),
                "{samples:?}"
            );
            if fold.0 == 0.0 || fold.1 == 0.0 {
                zero_extremes += 1;
            } else {
                others += 1;
            }
        }
        assert!(
            zero_extremes > 50 && others > 50,
            "{zero_extremes} {others}"
        );
    }

    /// The outlier statistic the obvious way, point by point (the loop `window_scores`
    /// replaced): each point walks its window in row-major order. `column_major` walks it
    /// column by column instead, for the control.
    fn per_point_scores(
        points: &[PixelPoint],
        grid: &[u32],
        bw: usize,
        r: usize,
        column_major: bool,
    ) -> Vec<f64> {
        let bh = grid.len() / bw;
        let at = |u: isize, v: isize| -> Option<Vector3<f64>> {
            let inside = (0..bw as isize).contains(&u) && (0..bh as isize).contains(&v);
            let i = if inside {
                grid[v as usize * bw + u as usize]
            } else {
                u32::MAX
            };
            (i != u32::MAX).then(|| points[i as usize].1)
        };
        let mut scores = vec![f64::NAN; points.len()];
        for (cell, &i) in grid.iter().enumerate() {
            if i == u32::MAX {
                continue;
            }
            let (u, v) = ((cell % bw) as isize, (cell / bw) as isize);
            let x = points[i as usize].1;
            let (mut sum, mut count) = (0.0, 0usize);
            let r = r as isize;
            for a in -r..=r {
                for b in -r..=r {
                    let (du, dv) = if column_major { (a, b) } else { (b, a) };
                    if (du, dv) == (0, 0) {
                        continue;
                    }
                    if let Some(q) = at(u + du, v + dv) {
                        sum += (q - x).norm();
                        count += 1;
                    }
                }
            }
            scores[i as usize] = if count == 0 {
                f64::INFINITY
            } else {
                sum / count as f64 / (x.z / 600.0).max(1e-9)
            };
        }
        scores
    }

    #[test]
    fn window_scores_are_the_per_point_loop_bit_for_bit() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut order_matters = 0;
        // One set of working rows for every case, as for a scene's objects: each case's rows
        // hold the distances of the case before until they are refilled.
        let mut rows = Vec::new();
        for case in 0..200 {
            // One case in five over several of window_scores' blocks of cells.
            let (bw, bh) = if case % 5 == 0 {
                (
                    rng.random_range(60..200usize),
                    rng.random_range(30..70usize),
                )
            } else {
                (rng.random_range(1..40usize), rng.random_range(1..40usize))
            };
            let r = [0, 1, 2, 3][case % 4];
            let fill: f64 = rng.random_range(0.05..1.0);
            let mut points = Vec::new();
            let mut grid = vec![u32::MAX; bw * bh];
            for (cell, slot) in grid.iter_mut().enumerate() {
                if rng.random::<f64>() < fill {
                    *slot = points.len() as u32;
                    // Depths of a surface with steps and noise: the sums are not exact, so the
                    // order of adding shows in the last bits.
                    let z = 0.6 + 0.001 * (cell % bw) as f64 + rng.random_range(-0.01..0.01);
                    let x = Vector3::new(z * rng.random_range(-0.5..0.5), rng.random(), z);
                    points.push((cell as u32, x));
                }
            }
            let fast = window_scores(
                &points,
                &grid,
                (bw, bh),
                r,
                |x| (x.z / 600.0).max(1e-9),
                &mut rows,
            );
            let slow = per_point_scores(&points, &grid, bw, r, false);
            let bits = |v: &[f64]| v.iter().map(|s| s.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&fast), bits(&slow), "case {case}: {bw}x{bh}, r = {r}");
            if bits(&per_point_scores(&points, &grid, bw, r, true)) != bits(&slow) {
                order_matters += 1;
            }
        }
        // Control: walking the window in another order changes the last bits in many cases,
        // so the comparison above does check the order of adding.
        assert!(order_matters > 50, "{order_matters}");
    }

    /// The connectivity rule as it was first written: a union-find over the points, every
    /// pair of neighbours joined.
    fn components_point_by_point(
        points: Vec<PixelPoint>,
        grid: Vec<u32>,
        bw: usize,
        config: &LiftConfig,
    ) -> (Vec<PixelPoint>, Vec<u32>, usize) {
        let n = points.len();
        let mut parent: Vec<u32> = (0..n as u32).collect();
        fn find(parent: &mut [u32], mut i: u32) -> u32 {
            while parent[i as usize] != i {
                parent[i as usize] = parent[parent[i as usize] as usize];
                i = parent[i as usize];
            }
            i
        }
        let joined = |a: &Vector3<f64>, b: &Vector3<f64>| {
            let limit = config
                .component_jump_m
                .max(config.component_jump_relative * a.z.min(b.z));
            (a.z - b.z).abs() <= limit
        };
        for (cell, &i) in grid.iter().enumerate() {
            if i == u32::MAX {
                continue;
            }
            let right = (cell % bw + 1 < bw).then(|| grid[cell + 1]);
            let down = grid.get(cell + bw).copied();
            for j in [right, down].into_iter().flatten() {
                if j != u32::MAX && joined(&points[i as usize].1, &points[j as usize].1) {
                    let (a, b) = (find(&mut parent, i), find(&mut parent, j));
                    if a != b {
                        // The smaller root wins, so the result does not depend on visiting order.
                        let (lo, hi) = (a.min(b), a.max(b));
                        parent[hi as usize] = lo;
                    }
                }
            }
        }
        let roots: Vec<u32> = (0..n as u32).map(|i| find(&mut parent, i)).collect();
        // Component sizes by root (a root is a point's index): a count per point, zero for
        // non-roots.
        let mut sizes = vec![0usize; n];
        for &r in &roots {
            sizes[r as usize] += 1;
        }
        let largest = sizes.iter().copied().max().unwrap_or(0);
        let minimum = (config.component_min_fraction * largest as f64).ceil() as usize;
        if sizes.iter().all(|&s| s == 0 || s >= minimum) {
            return (points, grid, 0);
        }
        let mut remap = vec![u32::MAX; n];
        let mut kept = Vec::with_capacity(n);
        for (i, point) in points.into_iter().enumerate() {
            if sizes[roots[i] as usize] >= minimum {
                remap[i] = kept.len() as u32;
                kept.push(point);
            }
        }
        let dropped = n - kept.len();
        let grid = grid
            .into_iter()
            .map(|i| if i == u32::MAX { i } else { remap[i as usize] })
            .collect();
        (kept, grid, dropped)
    }

    #[test]
    fn components_by_runs_are_the_point_by_point_union_find() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
        let config = LiftConfig::default();
        let (mut dropping, mut several) = (0, 0);
        for case in 0..400 {
            let (bw, bh) = (rng.random_range(1..60usize), rng.random_range(1..50usize));
            let fill: f64 = rng.random_range(0.3..1.0);
            // A surface of a few depth levels in bands across and down the box (steps beyond
            // the jump split it), noise within, and some cells a little off it: those join
            // some of their neighbours and not others, so two runs can meet in joined and
            // unjoined cells.
            let levels: Vec<f64> = (0..rng.random_range(1..5))
                .map(|_| rng.random_range(0.4..1.2))
                .collect();
            let off: f64 = rng.random_range(0.0..0.3);
            let (mut points, mut grid) = (Vec::new(), vec![u32::MAX; bw * bh]);
            for (cell, slot) in grid.iter_mut().enumerate() {
                if rng.random::<f64>() < fill {
                    let band = ((cell % bw) * levels.len() / bw + cell / bw / 7) % levels.len();
                    let noise = if rng.random::<f64>() < off {
                        0.016
                    } else {
                        0.003
                    };
                    let z = levels[band] + rng.random_range(-noise..noise);
                    *slot = points.len() as u32;
                    points.push((cell as u32, Vector3::new(0.0, 0.0, z)));
                }
            }
            let fast = keep_main_components(points.clone(), grid.clone(), bw, &config);
            let slow = components_point_by_point(points, grid, bw, &config);
            let pixels = |kept: &[PixelPoint]| kept.iter().map(|p| p.0).collect::<Vec<_>>();
            assert_eq!(pixels(&fast.0), pixels(&slow.0), "case {case}: {bw}x{bh}");
            assert_eq!((&fast.1, fast.2), (&slow.1, slow.2), "case {case}");
            dropping += usize::from(slow.2 > 0);
            several += usize::from(levels.len() > 1);
        }
        // Controls: many cases drop points (the rule acts), others keep every point.
        assert!(dropping > 40 && dropping < 360, "{dropping} of 400");
        assert!(several > 200, "{several}");
    }

    /// [`erode`] against its definition, pixel by pixel: random masks (blobs, noise, lines
    /// one pixel wide, masks at the image's border) and radii from 0 to 4.
    #[test]
    fn erosion_keeps_the_pixels_whose_whole_window_is_in_the_mask() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
        for case in 0..300 {
            let (w, h) = (rng.random_range(1..40usize), rng.random_range(1..40usize));
            let density = [0.3, 0.7, 0.95, 1.0][case % 4];
            let (cu, cv) = (rng.random_range(0..w) as f64, rng.random_range(0..h) as f64);
            let r2 = rng.random_range(1.0..400.0);
            let set: Vec<bool> = (0..w * h)
                .map(|p| {
                    let (u, v) = ((p % w) as f64, (p / w) as f64);
                    let blob = (u - cu).powi(2) + (v - cv).powi(2) <= r2;
                    match case % 3 {
                        0 => blob && rng.random_bool(density),
                        1 => rng.random_bool(density),
                        _ => blob || (p / w) % 7 == 3,
                    }
                })
                .collect();
            let pixels: Vec<u32> = (0..w * h).filter(|&p| set[p]).map(|p| p as u32).collect();
            let radius = rng.random_range(0..5usize);
            let expected: Vec<u32> = pixels
                .iter()
                .copied()
                .filter(|&p| {
                    let (u, v) = ((p as usize % w) as i64, (p as usize / w) as i64);
                    let r = radius as i64;
                    (-r..=r).all(|dv| {
                        (-r..=r).all(|du| {
                            let (x, y) = (u + du, v + dv);
                            x >= 0
                                && y >= 0
                                && (x as usize) < w
                                && (y as usize) < h
                                && set[y as usize * w + x as usize]
                        })
                    })
                })
                .collect();
            assert_eq!(
                erode(&pixels, w, h, radius),
                expected,
                "case {case}: {w}×{h}, radius {radius}"
            );
        }
    }

    #[test]
    fn erosion_removes_a_border_of_radius_pixels() {
        let (w, h) = (20, 12);
        let square: Vec<u32> = (2..10)
            .flat_map(|v| (3..13).map(move |u| (v * w + u) as u32))
            .collect();
        let eroded = erode(&square, w, h, 2);
        let expected: Vec<u32> = (4..8)
            .flat_map(|v| (5..11).map(move |u| (v * w + u) as u32))
            .collect();
        assert_eq!(eroded, expected);
        assert_eq!(erode(&square, w, h, 0), square);
        assert!(erode(&square, w, h, 5).is_empty());
    }

    #[test]
    fn labels_become_instance_stems() {
        assert_eq!(sanitize_label("Coffee Mug"), "coffee_mug");
        assert_eq!(sanitize_label("  desk-lamp "), "desk_lamp");
        assert_eq!(sanitize_label("!!"), "object");
        assert_eq!(sanitize_label("Café mug"), "caf_mug");
        let long = sanitize_label(&"word ".repeat(40));
        assert!(long.len() <= 58 && !long.ends_with('_'), "{long}");
        let instance = format!("{long}_12345");
        assert_eq!(
            mesa_schemas::validate::instance_name_problem(&instance),
            None
        );
    }

    #[test]
    fn ransac_finds_a_noisy_plane_among_clutter() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let n = Vector3::new(0.0, -0.8, -0.6).normalize();
        let d = 0.9;
        let mut points = Vec::new();
        for _ in 0..3000 {
            let a: f64 = rng.random_range(-0.5..0.5);
            let b: f64 = rng.random_range(-0.5..0.5);
            let base = -n * d + Vector3::new(a, b * 0.6, -b * 0.8);
            points.push(base + n * rng.random_range(-0.002..0.002));
        }
        for _ in 0..1000 {
            points.push(Vector3::new(
                rng.random_range(-0.5..0.5),
                rng.random_range(-0.5..0.5),
                rng.random_range(0.5..1.5),
            ));
        }
        let plane =
            fit_plane(&points, &[], "s", 0, &LiftConfig::default(), "support").expect("plane");
        assert!(plane.normal.dot(&n) > 0.9999, "{:?}", plane.normal);
        assert!((plane.offset_m - d).abs() < 1e-3);
        assert!(plane.inlier_fraction > 0.7);
    }

    /// A counter top 3.5-6 m away under a structured-light sensor's noise (σ = 1.2 mm +
    /// 1.9 mm/m · (d - 0.4)², as the demo's sensor): fewer than 30% of its points lie within the
    /// 5 mm inlier distance, yet it is a plane. The depth-scaled share finds it; with the share
    /// counted at a fixed 5 mm (`plane_share_depth_m = 0`) it is refused with both shares.
    #[test]
    fn a_far_counter_top_under_depth_noise_is_a_plane() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let n = Vector3::new(0.0, -0.68, -0.73).normalize();
        let d = 1.9;
        let mut points = Vec::new();
        while points.len() < 6000 {
            let ray: Vector3<f64> = Vector3::new(
                rng.random_range(-0.5..0.5),
                rng.random_range(-0.6..-0.27),
                1.0,
            );
            let p = ray * (-d / n.dot(&ray));
            let sigma = 0.0012 + 0.0019 * (p.z - 0.4).powi(2);
            // Box-Muller.
            let (u1, u2): (f64, f64) = (rng.random_range(1e-12..1.0), rng.random_range(0.0..1.0));
            let noise = sigma * (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
            points.push(p * ((p.z + noise) / p.z));
        }
        let config = LiftConfig::default();
        let plane = fit_plane(&points, &[], "s", 0, &config, "support").expect("plane");
        assert!(plane.normal.dot(&n) > 0.999, "{:?}", plane.normal);
        assert!(
            plane.inlier_fraction < config.plane_min_inlier_fraction,
            "the fixed 5 mm share is {}: the scene is not hard enough",
            plane.inlier_fraction
        );
        let fixed = LiftConfig {
            plane_share_depth_m: 0.0,
            ..LiftConfig::default()
        };
        match fit_plane(&points, &[], "s", 0, &fixed, "support") {
            Err(LiftError::NoPlane(message)) => {
                assert!(message.contains("within 5 mm and"), "{message}");
                assert!(
                    message.contains("within the depth-scaled tolerance"),
                    "{message}"
                );
                assert!(message.contains("expected at least 30%"), "{message}");
            }
            other => panic!("expected no plane at a fixed tolerance, got {other:?}"),
        }
    }

    /// A long counter seen from afar: its mask covers the cabinet front (the largest plane) and
    /// the top, a quarter of what is left once the front is set aside. The top is found.
    #[test]
    fn a_far_counter_top_behind_its_cabinet_front_is_the_table() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut points = Vec::new();
        // Camera frame: x right, y down, z forward. The front at z = 1.5 below the top's edge.
        for _ in 0..6000 {
            points.push(Vector3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(0.3..0.9),
                1.5 + rng.random_range(-0.001..0.001),
            ));
        }
        // The top at y = 0.3 (0.3 m below the camera), 60 cm deep.
        for _ in 0..1200 {
            points.push(Vector3::new(
                rng.random_range(-1.0..1.0),
                0.3 + rng.random_range(-0.001..0.001),
                rng.random_range(1.5..2.1),
            ));
        }
        for _ in 0..3500 {
            points.push(Vector3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-0.5..0.9),
                rng.random_range(1.0..2.5),
            ));
        }
        let objects: Vec<Vector3<f64>> = (0..200)
            .map(|_| {
                Vector3::new(
                    rng.random_range(-0.8..0.8),
                    rng.random_range(0.15..0.29),
                    rng.random_range(1.6..2.0),
                )
            })
            .collect();
        let config = LiftConfig::default();
        let plane = fit_plane(&points, &objects, "s", 0, &config, "support").expect("plane");
        assert!(
            plane.normal.dot(&Vector3::new(0.0, -1.0, 0.0)) > 0.999,
            "{:?}",
            plane.normal
        );
        assert!((plane.offset_m - 0.3).abs() < 2e-3, "{}", plane.offset_m);
        assert!(plane.inlier_fraction < config.plane_min_inlier_fraction);
    }
}
