//! Profiles and small solids the demo assets are made of (metres, glTF frame: Y up).

use std::f64::consts::PI;

use crate::mesh::{Affine3, LatheOptions, TriMesh};

/// A vessel with a flat floor and straight (possibly tapered) walls of `wall` thickness: a
/// mug, a cup, a pen holder. The outer bottom edge is bevelled by `bevel`.
pub(crate) fn vessel(
    r_bottom: f64,
    r_top: f64,
    height: f64,
    wall: f64,
    floor: f64,
    bevel: f64,
    segments: usize,
) -> TriMesh {
    let slope = (r_top - r_bottom) / height;
    let inner_at = |y: f64| r_bottom + slope * y - wall;
    let profile = [
        [0.0, 0.0],
        [r_bottom - bevel, 0.0],
        [r_bottom + slope * bevel, bevel],
        [r_top, height],
        [r_top - wall, height],
        [inner_at(floor), floor],
        [0.0, floor],
    ];
    TriMesh::lathe(&profile, LatheOptions::default().with_segments(segments))
}

/// A dish (bowl or plate): the underside is flat out to `base_radius`, then rises as
/// `((r - base) / (R - base))^exponent` to the rim; the inside is the underside raised by
/// `wall`, so identical dishes nest exactly `wall` apart.
pub(crate) fn dish(
    radius: f64,
    height: f64,
    wall: f64,
    base_radius: f64,
    exponent: f64,
    segments: usize,
) -> TriMesh {
    let n = 14;
    let outer_height = height - wall;
    let underside: Vec<[f64; 2]> = (0..=n)
        .map(|i| {
            // Cosine spacing: denser near the rim where the curve is steep.
            let t = (1.0 - (PI * i as f64 / n as f64).cos()) / 2.0;
            let r = base_radius + (radius - base_radius) * t;
            [r, outer_height * t.powf(exponent)]
        })
        .collect();
    let mut profile = vec![[0.0, 0.0]];
    profile.extend(underside.iter().copied());
    profile.push([radius, height]);
    for p in underside.iter().rev().skip(1) {
        profile.push([p[0], p[1] + wall]);
    }
    profile.push([0.0, wall]);
    TriMesh::lathe(
        &profile,
        LatheOptions::default()
            .with_segments(segments)
            .with_smooth_angle_deg(40.0),
    )
}

/// The height of a [`dish`]'s inner surface at radius `r` (for placing things in it).
pub(crate) fn dish_inner_height(
    r: f64,
    radius: f64,
    height: f64,
    wall: f64,
    base_radius: f64,
    exponent: f64,
) -> f64 {
    if r <= base_radius {
        return wall;
    }
    let t = ((r - base_radius) / (radius - base_radius)).min(1.0);
    (height - wall) * t.powf(exponent) + wall
}

/// A solid of revolution from `(radius, y)` control points, closed at the bottom and top
/// on the axis; the points are joined by a smooth Catmull-Rom curve sampled `per_span` times
/// between each pair.
pub(crate) fn smooth_solid(points: &[[f64; 2]], per_span: usize, segments: usize) -> TriMesh {
    let curve = catmull_rom(points, per_span);
    let mut profile = vec![[0.0, curve[0][1]]];
    profile.extend(curve.iter().copied());
    profile.push([0.0, curve[curve.len() - 1][1]]);
    TriMesh::lathe(
        &profile,
        LatheOptions::default()
            .with_segments(segments)
            .with_smooth_angle_deg(50.0),
    )
}

/// A smooth open shell of revolution with a wall: the outer curve through `points`, the
/// inner curve `wall` further in, a floor of thickness `floor` (a vase).
pub(crate) fn smooth_shell(
    points: &[[f64; 2]],
    wall: f64,
    floor: f64,
    per_span: usize,
    segments: usize,
) -> TriMesh {
    let outer = catmull_rom(points, per_span);
    let mut profile = vec![[0.0, outer[0][1]]];
    profile.extend(outer.iter().copied());
    let top = outer[outer.len() - 1];
    profile.push([top[0] - wall, top[1]]);
    for p in outer.iter().rev().skip(1) {
        if p[1] <= floor {
            break;
        }
        profile.push([(p[0] - wall).max(wall), p[1]]);
    }
    let floor_r = profile.last().map(|p| p[0]).unwrap_or(wall);
    profile.push([floor_r, floor]);
    profile.push([0.0, floor]);
    TriMesh::lathe(
        &profile,
        LatheOptions::default()
            .with_segments(segments)
            .with_smooth_angle_deg(50.0),
    )
}

/// A Catmull-Rom curve through `points` (ends repeated), `per_span` samples per span.
fn catmull_rom(points: &[[f64; 2]], per_span: usize) -> Vec<[f64; 2]> {
    let n = points.len();
    if n < 2 {
        return points.to_vec();
    }
    let get = |i: isize| points[i.clamp(0, n as isize - 1) as usize];
    let mut out = Vec::new();
    for i in 0..n - 1 {
        let (p0, p1, p2, p3) = (
            get(i as isize - 1),
            get(i as isize),
            get(i as isize + 1),
            get(i as isize + 2),
        );
        // Heights stay within each span's own range: the profiles rise monotonically, and
        // an overshoot below the base would leave the solid standing on a bump.
        let (y_lo, y_hi) = (p1[1].min(p2[1]), p1[1].max(p2[1]));
        for s in 0..per_span {
            let t = s as f64 / per_span as f64;
            let (t2, t3) = (t * t, t * t * t);
            let mut p: [f64; 2] = std::array::from_fn(|k| {
                0.5 * (2.0 * p1[k]
                    + (-p0[k] + p2[k]) * t
                    + (2.0 * p0[k] - 5.0 * p1[k] + 4.0 * p2[k] - p3[k]) * t2
                    + (-p0[k] + 3.0 * p1[k] - 3.0 * p2[k] + p3[k]) * t3)
            });
            p[0] = p[0].max(0.0);
            p[1] = p[1].clamp(y_lo, y_hi);
            out.push(p);
        }
    }
    out.push(points[n - 1]);
    out
}

/// A closed ring hugging a tapered wall from `y0` to `y1` (a cup sleeve or bottle label),
/// `gap` outside the wall and `thickness` thick.
pub(crate) fn band(
    r_at: impl Fn(f64) -> f64,
    y0: f64,
    y1: f64,
    gap: f64,
    thickness: f64,
    segments: usize,
) -> TriMesh {
    let (a, b) = (r_at(y0) + gap, r_at(y1) + gap);
    let profile = [
        [a, y0],
        [a + thickness, y0],
        [b + thickness, y1],
        [b, y1],
        [a, y0],
    ];
    TriMesh::lathe(
        &profile,
        LatheOptions::default()
            .with_segments(segments)
            .with_smooth_angle_deg(10.0),
    )
}

/// A box of `size` whose bottom face is at y = `bottom` and whose footprint is centred at
/// (`x`, `z`).
pub(crate) fn block(size: [f64; 3], x: f64, bottom: f64, z: f64) -> TriMesh {
    TriMesh::cuboid(size).transformed(&Affine3::from_translation([x, bottom + size[1] / 2.0, z]))
}

/// An ellipsoid with semi-axes `radii`, centred at `center`.
pub(crate) fn ellipsoid(radii: [f64; 3], center: [f64; 3], segments: usize) -> TriMesh {
    TriMesh::uv_sphere(1.0, segments, segments / 2)
        .transformed(&Affine3::from_translation(center).mul(&Affine3::from_scale(radii)))
}

/// A rod of revolution along +X (a pen or a pencil): `profile` is `(radius, x)` from the tip
/// (x = 0) to the end, then the rod is centred on x and lifted so it lies on y = 0.
pub(crate) fn rod_along_x(
    profile: &[[f64; 2]],
    segments: usize,
    lift: f64,
    length: f64,
) -> TriMesh {
    // Lathe about +Y, then turn +Y onto +X (a quarter turn about -Z).
    let rod = TriMesh::lathe(profile, LatheOptions::default().with_segments(segments));
    let turn = Affine3 {
        linear: [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
        translation: [-length / 2.0, lift, 0.0],
    };
    rod.transformed(&turn)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dishes_nest_exactly_wall_apart() {
        let (radius, height, wall, base, exponent) = (0.13, 0.022, 0.0035, 0.08, 2.2);
        let d = dish(radius, height, wall, base, exponent, 48);
        d.check().expect("valid");
        assert!(d.signed_volume() > 0.0);
        let b = d.bounds().expect("bounds");
        assert!((b.max[1] - height).abs() < 1e-6);
        assert!((b.max[0] - radius).abs() < 1e-6);
        assert!(
            (dish_inner_height(0.0, radius, height, wall, base, exponent) - wall).abs() < 1e-12
        );
        assert!(
            (dish_inner_height(radius, radius, height, wall, base, exponent) - height).abs()
                < 1e-12
        );
    }

    #[test]
    fn solids_are_valid_and_outward() {
        for m in [
            vessel(0.04, 0.042, 0.1, 0.004, 0.006, 0.003, 32),
            smooth_solid(&[[0.03, 0.0], [0.033, 0.1], [0.015, 0.2]], 6, 24),
            smooth_shell(
                &[[0.04, 0.0], [0.06, 0.08], [0.03, 0.2]],
                0.005,
                0.01,
                6,
                24,
            ),
            band(|y| 0.03 + 0.1 * y, 0.03, 0.07, 0.0002, 0.0015, 32),
            rod_along_x(
                &[[0.0, 0.0], [0.004, 0.01], [0.004, 0.14], [0.0, 0.14]],
                12,
                0.004,
                0.14,
            ),
            ellipsoid([0.03, 0.02, 0.05], [0.0, 0.02, 0.0], 16),
        ] {
            m.check().expect("valid");
            assert!(m.signed_volume() > 0.0);
        }
    }

    #[test]
    fn rods_lie_along_x_on_the_ground() {
        let rod = rod_along_x(
            &[[0.0, 0.0], [0.004, 0.01], [0.004, 0.14], [0.0, 0.14]],
            12,
            0.004,
            0.14,
        );
        let b = rod.bounds().expect("bounds");
        assert!((b.size()[0] - 0.14).abs() < 1e-6);
        assert!(b.min[1].abs() < 1e-6);
        assert!((b.center()[0]).abs() < 1e-6);
    }
}
