//! Rotations of the table frame (SPEC section 2): yaw about +z in degrees, counter-clockwise
//! seen from above, 0 = facing the observer (-y); quaternions in **xyzw** order.

/// The quaternion (xyzw) of a pure yaw of `yaw_deg` degrees about +z.
pub fn quat_xyzw_from_yaw_deg(yaw_deg: f64) -> [f64; 4] {
    let half = yaw_deg.to_radians() / 2.0;
    [0.0, 0.0, half.sin(), half.cos()]
}

/// The yaw (twist about +z) of a quaternion (xyzw), in degrees in (-180, 180].
///
/// For a pure yaw this inverts [`quat_xyzw_from_yaw_deg`]; for a tilted rotation it is the
/// twist part of the swing-twist decomposition about +z (the heading of the object's front).
pub fn yaw_deg_from_quat_xyzw(q: [f64; 4]) -> f64 {
    let [_, _, z, w] = q;
    if z == 0.0 && w == 0.0 {
        // A half turn about a horizontal axis: the twist is undefined; call it no yaw.
        return 0.0;
    }
    normalize_deg(2.0 * z.atan2(w).to_degrees())
}

/// The tilt of a rotation: the angle in degrees between the rotated +z axis and +z.
pub fn tilt_deg_from_quat_xyzw(q: [f64; 4]) -> f64 {
    let [x, y, z, w] = q;
    let norm2 = x * x + y * y + z * z + w * w;
    if norm2 == 0.0 {
        return 0.0;
    }
    let cos_tilt = 1.0 - 2.0 * (x * x + y * y) / norm2;
    cos_tilt.clamp(-1.0, 1.0).acos().to_degrees()
}

/// Maps an angle in degrees to (-180, 180].
pub fn normalize_deg(angle_deg: f64) -> f64 {
    let a = angle_deg.rem_euclid(360.0);
    if a > 180.0 {
        a - 360.0
    } else {
        a
    }
}

/// The facing vector (sin θ, -cos θ, 0) of a yaw θ in degrees.
pub fn facing_from_yaw_deg(yaw_deg: f64) -> [f64; 3] {
    let t = yaw_deg.to_radians();
    [t.sin(), -t.cos(), 0.0]
}

/// Euclidean norm of a quaternion.
pub fn quat_norm(q: [f64; 4]) -> f64 {
    q.iter().map(|c| c * c).sum::<f64>().sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;
    use proptest::prelude::*;

    #[test]
    fn yaw_90_faces_right() {
        let f = facing_from_yaw_deg(90.0);
        assert_abs_diff_eq!(f[0], 1.0, epsilon = 1e-12);
        assert_abs_diff_eq!(f[1], 0.0, epsilon = 1e-12);
        assert_eq!(quat_xyzw_from_yaw_deg(0.0), [0.0, 0.0, 0.0, 1.0]);
    }

    #[test]
    fn tilt_of_a_quarter_roll_is_90() {
        let h = std::f64::consts::FRAC_1_SQRT_2;
        assert_abs_diff_eq!(
            tilt_deg_from_quat_xyzw([h, 0.0, 0.0, h]),
            90.0,
            epsilon = 1e-9
        );
        assert_abs_diff_eq!(tilt_deg_from_quat_xyzw(quat_xyzw_from_yaw_deg(33.0)), 0.0);
    }

    proptest! {
        #[test]
        fn yaw_round_trips(yaw in -180.0f64..180.0) {
            let back = yaw_deg_from_quat_xyzw(quat_xyzw_from_yaw_deg(yaw));
            let diff = normalize_deg(back - yaw).abs();
            prop_assert!(diff < 1e-9, "{yaw} -> {back}");
        }
    }
}
