//! The cameras of the rendered views.
//!
//! Scene views follow MesaTask's own renderer (`dataset/reconstruct_blender.py`,
//! `render_four_views`): the scene box is the item placement zone in x and y and runs from the
//! table top to the highest object in z; each camera looks at the box centre from the
//! direction of its view vector, at `distance_factor` (1.5) × the box's largest side, with a
//! 50 mm lens on a 36 mm sensor (a horizontal field of view of 39.6°); unlike MesaTask's, a
//! camera backs away until the whole box is in the picture (MesaTask's cuts the front corners
//! of long tables and much of the perspective view). The view vectors are
//! MesaTask's `front` (0, −1, 0.6) and `perspective` (−0.7, −0.7, 0.7); for QA, `back`, `left`
//! and `right` are `front` turned about z (`left` and `right` at MesaTask's `left` elevation,
//! (∓1, 0, 0.3)).
//!
//! Asset views circle one asset: view k looks from azimuth 45·k° counter-clockwise about +z
//! from the front (view 0 looks from −y, the observer's side, at the asset's front; view 2
//! from +x), at a fixed elevation, far enough for the asset's bounding sphere to fill
//! `asset_fill` of the frame.
//!
//! Cameras are OpenCV (x right, y down, z forward), pixel `(u, v)` sampled at integer
//! coordinates (SPEC 2), with the principal point at the image centre `((W − 1) / 2,
//! (H − 1) / 2)` so the look-at point falls on the middle of the picture.

use crate::mesh::{add3, cross3, norm3, normalize3, scale3, sub3, Aabb, Affine3};
use crate::raster::PinholeCamera;

/// A rendered scene view.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum SceneView {
    /// From the observer's side (−y), looking slightly down: the multimodal prompts' front view.
    Front,
    /// From behind (+y).
    Back,
    /// From the left (−x).
    Left,
    /// From the right (+x).
    Right,
    /// From the front left, above: the multimodal prompts' perspective view.
    Perspective,
}

impl SceneView {
    /// Every scene view, in file order.
    pub const ALL: [SceneView; 5] = [
        SceneView::Front,
        SceneView::Back,
        SceneView::Left,
        SceneView::Right,
        SceneView::Perspective,
    ];

    /// The view's name: its file is `render/<name>.png`.
    pub fn name(self) -> &'static str {
        match self {
            SceneView::Front => "front",
            SceneView::Back => "back",
            SceneView::Left => "left",
            SceneView::Right => "right",
            SceneView::Perspective => "perspective",
        }
    }

    /// The direction from the scene centre toward the camera (not normalised).
    pub fn direction(self) -> [f64; 3] {
        match self {
            SceneView::Front => [0.0, -1.0, 0.6],
            SceneView::Back => [0.0, 1.0, 0.6],
            SceneView::Left => [-1.0, 0.0, 0.3],
            SceneView::Right => [1.0, 0.0, 0.3],
            SceneView::Perspective => [-0.7, -0.7, 0.7],
        }
    }
}

/// A camera of a rendered view: intrinsics and pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewCamera {
    /// Intrinsics (OpenCV).
    pub intrinsics: PinholeCamera,
    /// Camera frame (OpenCV, metres) to table frame (metres).
    pub table_from_camera: Affine3,
    /// The point the camera looks at, table frame, metres.
    pub look_at_m: [f64; 3],
}

/// Square pixels, the principal point at the image centre, and the horizontal field of view.
pub fn centred_intrinsics(width: u32, height: u32, fov_x_deg: f64) -> PinholeCamera {
    let f = f64::from(width) / 2.0 / (fov_x_deg.to_radians() / 2.0).tan();
    PinholeCamera {
        width,
        height,
        fx: f,
        fy: f,
        cx: (f64::from(width) - 1.0) / 2.0,
        cy: (f64::from(height) - 1.0) / 2.0,
    }
}

/// The pose of a camera at `eye` looking at `target`, the table's +z up in the picture.
pub fn look_at(eye: [f64; 3], target: [f64; 3]) -> Affine3 {
    let forward = normalize3(sub3(target, eye));
    // Looking straight down, +y (away from the observer) is up in the picture.
    let up = if cross3(forward, [0.0, 0.0, 1.0])
        .iter()
        .all(|c| c.abs() < 1e-9)
    {
        [0.0, 1.0, 0.0]
    } else {
        [0.0, 0.0, 1.0]
    };
    let right = normalize3(cross3(forward, up));
    let down = cross3(forward, right);
    Affine3 {
        linear: [
            [right[0], down[0], forward[0]],
            [right[1], down[1], forward[1]],
            [right[2], down[2], forward[2]],
        ],
        translation: eye,
    }
}

/// The box scene views frame: the zone in x and y, from the table top (z = 0) to `top_m`.
pub fn scene_box(zone_m: [f64; 4], top_m: f64) -> Aabb {
    Aabb {
        min: [zone_m[0], zone_m[2], 0.0],
        max: [zone_m[1], zone_m[3], top_m.max(0.0)],
    }
}

/// Whether every corner of `scene` projects inside the picture, `margin_px` from its edges.
fn frames(camera: &ViewCamera, scene: &Aabb, margin_px: f64) -> bool {
    let Some(camera_from_table) = camera.table_from_camera.inverse() else {
        return false;
    };
    let k = &camera.intrinsics;
    scene.corners().iter().all(|corner| {
        k.project(camera_from_table.apply_point(*corner))
            .is_some_and(|[u, v]| {
                u >= margin_px
                    && v >= margin_px
                    && u <= f64::from(k.width) - 1.0 - margin_px
                    && v <= f64::from(k.height) - 1.0 - margin_px
            })
    })
}

/// The camera of a scene view framing `scene` (see the module documentation): MesaTask's
/// distance, or farther (by steps of 2 %) when the scene box would be cut at the picture's
/// edges.
pub fn scene_camera(
    view: SceneView,
    scene: &Aabb,
    width: u32,
    height: u32,
    fov_x_deg: f64,
    distance_factor: f64,
) -> ViewCamera {
    let centre = scene.center();
    let size = scene.size();
    let largest = size[0].max(size[1]).max(size[2]).max(0.05);
    let direction = normalize3(view.direction());
    let intrinsics = centred_intrinsics(width, height, fov_x_deg);
    let at = |distance: f64| ViewCamera {
        intrinsics,
        table_from_camera: look_at(add3(centre, scale3(direction, distance)), centre),
        look_at_m: centre,
    };
    let margin_px = 0.01 * f64::from(width.min(height));
    let mut distance = largest * distance_factor;
    for _ in 0..200 {
        if frames(&at(distance), scene, margin_px) {
            break;
        }
        distance *= 1.02;
    }
    at(distance)
}

/// Number of asset views around z.
pub const ASSET_VIEWS: usize = 8;

/// The azimuth of asset view `k`, degrees counter-clockwise about +z from the front.
pub fn asset_view_azimuth_deg(k: usize) -> f64 {
    45.0 * k as f64
}

/// The camera of asset view `k` around an asset whose bounds are `bounds`.
pub fn asset_camera(
    k: usize,
    bounds: &Aabb,
    width: u32,
    height: u32,
    fov_x_deg: f64,
    elevation_deg: f64,
    fill: f64,
) -> ViewCamera {
    let centre = bounds.center();
    let radius = (norm3(bounds.size()) / 2.0).max(1e-3);
    let intrinsics = centred_intrinsics(width, height, fov_x_deg);
    // The narrower field of view decides: the sphere's image radius is
    // f · r / sqrt(d² − r²), which must be fill × half the narrower side.
    let half = f64::from(width.min(height)) / 2.0 * fill.clamp(0.05, 1.0);
    let ratio = intrinsics.fx / half;
    let distance = radius * (1.0 + ratio * ratio).sqrt();
    let (sa, ca) = asset_view_azimuth_deg(k).to_radians().sin_cos();
    let (se, ce) = elevation_deg.to_radians().sin_cos();
    let direction = [sa * ce, -ca * ce, se];
    let eye = add3(centre, scale3(direction, distance));
    ViewCamera {
        intrinsics,
        table_from_camera: look_at(eye, centre),
        look_at_m: centre,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    #[test]
    fn the_front_camera_looks_along_y_with_up_up() {
        let scene = scene_box([0.0, 1.2, 0.0, 0.6], 0.3);
        let cam = scene_camera(SceneView::Front, &scene, 512, 512, 39.6, 1.5);
        let m = cam.table_from_camera.linear;
        // Camera x (column 0) is table +x, camera y (down) has a negative z part.
        assert_abs_diff_eq!(m[0][0], 1.0, epsilon = 1e-12);
        assert!(m[2][1] < 0.0);
        // The look-at point projects to the image centre.
        let camera_from_table = cam.table_from_camera.inverse().expect("rigid");
        let p = camera_from_table.apply_point(cam.look_at_m);
        let uv = cam.intrinsics.project(p).expect("in front");
        assert_abs_diff_eq!(uv[0], 255.5, epsilon = 1e-9);
        assert_abs_diff_eq!(uv[1], 255.5, epsilon = 1e-9);
        // The eye is at least 1.5 × the largest side away, in front of and above the table.
        let eye = cam.table_from_camera.translation;
        assert!(norm3(sub3(eye, cam.look_at_m)) >= 1.8);
        assert!(eye[1] < 0.0 && eye[2] > 0.0);
        // A scene MesaTask's distance frames whole keeps that distance exactly.
        let strip = scene_box([0.0, 1.0, 0.0, 0.1], 0.02);
        let cam = scene_camera(SceneView::Front, &strip, 512, 512, 39.6, 1.5);
        let eye = cam.table_from_camera.translation;
        assert_abs_diff_eq!(norm3(sub3(eye, cam.look_at_m)), 1.5, epsilon = 1e-12);
    }

    #[test]
    fn the_whole_table_is_in_every_view() {
        let scene = scene_box([0.0, 1.2, 0.0, 0.6], 0.3);
        for view in SceneView::ALL {
            let cam = scene_camera(view, &scene, 512, 512, 39.6, 1.5);
            let camera_from_table = cam.table_from_camera.inverse().expect("rigid");
            for corner in scene.corners() {
                let uv = cam
                    .intrinsics
                    .project(camera_from_table.apply_point(corner))
                    .expect("in front");
                assert!(
                    (0.0..512.0).contains(&uv[0]) && (0.0..512.0).contains(&uv[1]),
                    "{view:?}: {corner:?} at {uv:?}"
                );
            }
        }
    }

    #[test]
    fn asset_views_circle_counter_clockwise_and_fill_the_frame() {
        let bounds = Aabb {
            min: [-0.1, -0.1, 0.0],
            max: [0.1, 0.1, 0.2],
        };
        let right = asset_camera(2, &bounds, 256, 256, 40.0, 0.0, 0.9);
        assert!(right.table_from_camera.translation[0] > 0.0);
        assert_abs_diff_eq!(right.table_from_camera.translation[1], 0.0, epsilon = 1e-12);
        let front = asset_camera(0, &bounds, 256, 256, 40.0, 0.0, 0.9);
        assert!(front.table_from_camera.translation[1] < 0.0);
        // The bounding sphere's silhouette radius is 0.9 × 128 px.
        let r = norm3(bounds.size()) / 2.0;
        let d = norm3(sub3(front.table_from_camera.translation, front.look_at_m));
        let image_radius = front.intrinsics.fx * r / (d * d - r * r).sqrt();
        assert_abs_diff_eq!(image_radius, 0.9 * 128.0, epsilon = 1e-9);
    }
}
