//! Table frame ↔ glTF node transforms (SPEC section 2), shared by `pack`, `ingest` and the
//! simulated annotator.
//!
//! glTF is metres, +Y up, front +Z; the table frame is x right, y away from the observer, z
//! up. Points and quaternion vector parts convert as `X = x, Y = z, Z = -y`; an object's
//! per-axis scale `[sx, sy, sz]` (object frame: width, depth, height) is the glTF node scale
//! `[sx, sz, sy]`, because an object's local glTF axes are its own x, z and -y. Blender's
//! importer applies the inverse conversion, so in Blender the table frame is the world frame.

/// A table-frame point or vector (metres) in glTF coordinates.
pub fn gltf_from_table_point(p: [f64; 3]) -> [f64; 3] {
    [p[0], p[2], -p[1]]
}

/// A glTF point or vector in table-frame coordinates.
pub fn table_from_gltf_point(p: [f64; 3]) -> [f64; 3] {
    [p[0], -p[2], p[1]]
}

/// A table-frame rotation `[x, y, z, w]` as a glTF rotation `[x, y, z, w]`.
pub fn gltf_from_table_quat(q: [f64; 4]) -> [f64; 4] {
    [q[0], q[2], -q[1], q[3]]
}

/// A glTF rotation `[x, y, z, w]` as a table-frame rotation `[x, y, z, w]`.
pub fn table_from_gltf_quat(q: [f64; 4]) -> [f64; 4] {
    [q[0], -q[2], q[1], q[3]]
}

/// Object-frame extents or scale `[width, depth, height]` as glTF local-axis values
/// `[X, Y, Z]`.
pub fn gltf_from_object_axes(v: [f64; 3]) -> [f64; 3] {
    [v[0], v[2], v[1]]
}

/// glTF local-axis extents or scale `[X, Y, Z]` as object-frame `[width, depth, height]`.
pub fn object_from_gltf_axes(v: [f64; 3]) -> [f64; 3] {
    [v[0], v[2], v[1]]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::{quat_from_axis_angle, quat_to_matrix, table_from_gltf, Affine3};
    use approx::assert_abs_diff_eq;

    #[test]
    fn the_worked_examples_of_the_conventions_page() {
        // A mug at table (0.30, 0.20, 0.05) m is at glTF (0.30, 0.05, -0.20).
        assert_eq!(
            gltf_from_table_point([0.30, 0.20, 0.05]),
            [0.30, 0.05, -0.20]
        );
        // A yaw of 90° in the table frame is a quarter turn about glTF +Y.
        let h = std::f64::consts::FRAC_1_SQRT_2;
        assert_eq!(gltf_from_table_quat([0.0, 0.0, h, h]), [0.0, h, 0.0, h]);
    }

    #[test]
    fn conversions_invert_each_other_and_agree_with_the_rotation_matrix() {
        let p = [0.3, -1.2, 2.5];
        assert_eq!(table_from_gltf_point(gltf_from_table_point(p)), p);
        let q = quat_from_axis_angle([0.3, -0.4, 0.8], 1.1);
        let back = table_from_gltf_quat(gltf_from_table_quat(q));
        for i in 0..4 {
            assert_abs_diff_eq!(back[i], q[i], epsilon = 1e-15);
        }
        // R_table = C · R_gltf · C⁻¹ with C = table_from_gltf.
        let q_gltf = gltf_from_table_quat(q);
        let c = table_from_gltf();
        let via = c
            .mul(&Affine3::from_quat_xyzw(q_gltf))
            .mul(&c.inverse().expect("invertible"));
        let direct = quat_to_matrix(q);
        for (row_via, row) in via.linear.iter().zip(&direct) {
            for (a, b) in row_via.iter().zip(row) {
                assert_abs_diff_eq!(a, b, epsilon = 1e-12);
            }
        }
    }
}
