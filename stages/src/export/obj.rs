//! Wavefront OBJ and MTL text and the fixed number formats of every exported file (the same inputs
//! give the same bytes).

use std::fmt::Write as _;

use super::visual::MaterialMesh;
use super::VisualMesh;

/// A length or coordinate in metres: fixed, 6 decimals (a micrometre), no negative zero.
pub fn fixed(v: f64) -> String {
    let s = format!("{v:.6}");
    if s.starts_with('-') && s[1..].bytes().all(|b| b == b'0' || b == b'.') {
        s[1..].to_owned()
    } else {
        s
    }
}

/// A mass or inertia: 9 significant digits in scientific notation (inertias of small
/// objects are 1e-8 kg·m² and below).
pub fn sci(v: f64) -> String {
    if v == 0.0 {
        return "0".to_owned();
    }
    format!("{v:.8e}")
}

/// Three numbers, space-separated.
pub fn fixed3(v: [f64; 3]) -> String {
    format!("{} {} {}", fixed(v[0]), fixed(v[1]), fixed(v[2]))
}

/// An OBJ file of one mesh: `v` lines, then `f` lines (1-based).
pub fn obj_text(comment: &str, positions: &[[f64; 3]], triangles: &[[u32; 3]]) -> String {
    let mut out = String::with_capacity(40 * positions.len() + 24 * triangles.len() + 64);
    let _ = writeln!(out, "# {comment}");
    for p in positions {
        let _ = writeln!(out, "v {}", fixed3(*p));
    }
    for t in triangles {
        let _ = writeln!(out, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    out
}

/// A colour channel, clamped to [0, 1]: fixed, 4 decimals, no negative zero.
pub fn channel(v: f32) -> String {
    let v = if v.is_nan() {
        0.0
    } else {
        v.clamp(0.0, 1.0) + 0.0
    };
    format!("{v:.4}")
}

/// Four colour channels, space-separated.
pub fn rgba_text(c: [f32; 4]) -> String {
    format!(
        "{} {} {} {}",
        channel(c[0]),
        channel(c[1]),
        channel(c[2]),
        channel(c[3])
    )
}

/// The OBJ of material `k` of a visual mesh: the vertices its triangles use (renumbered, in
/// their order in the mesh), their texture coordinates when the material is textured (`vt`,
/// v flipped: OBJ's v points up the image, glTF's down), and the triangles, after `mtllib
/// <mtl_file>` and `usemtl <mtl_name>` so that OBJ readers (PyBullet, trimesh) find the colour
/// and the image.
pub fn material_obj_text(
    comment: &str,
    mesh: &VisualMesh,
    k: usize,
    mtl_file: &str,
    mtl_name: &str,
) -> String {
    let mut part = mesh.material_mesh(k);
    pad_to_four_vertices(&mut part);
    let textured = !part.uvs.is_empty();
    let mut out =
        String::with_capacity(64 * part.positions_m.len() + 32 * part.triangles.len() + 128);
    let _ = writeln!(out, "# {comment}\nmtllib {mtl_file}\nusemtl {mtl_name}");
    for p in &part.positions_m {
        let _ = writeln!(out, "v {}", fixed3(*p));
    }
    for [u, v] in &part.uvs {
        let _ = writeln!(
            out,
            "vt {} {}",
            fixed(f64::from(*u)),
            fixed(1.0 - f64::from(*v))
        );
    }
    for t in &part.triangles {
        let [a, b, c] = t.map(|i| i + 1);
        if textured {
            let _ = writeln!(out, "f {a}/{a} {b}/{b} {c}/{c}");
        } else {
            let _ = writeln!(out, "f {a} {b} {c}");
        }
    }
    out
}

/// MuJoCo refuses a mesh of fewer than 4 vertices ("at least 4 vertices required"), and with
/// it the whole model: a material drawing a single triangle gets unreferenced vertices at its
/// first triangle's centroid and edge midpoints (texture coordinates interpolated alike), which
/// draw nothing in any reader.
fn pad_to_four_vertices(part: &mut MaterialMesh) {
    let Some(&[a, b, c]) = part.triangles.first() else {
        return;
    };
    let corners = [a, b, c].map(|i| i as usize);
    let weights = [
        [1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0],
        [0.5, 0.5, 0.0],
        [0.0, 0.5, 0.5],
        [0.5, 0.0, 0.5],
    ];
    let textured = !part.uvs.is_empty();
    for w in weights {
        if part.positions_m.len() >= 4 {
            break;
        }
        let p =
            std::array::from_fn(|d| (0..3).map(|j| w[j] * part.positions_m[corners[j]][d]).sum());
        part.positions_m.push(p);
        if textured {
            let uv = std::array::from_fn(|d| {
                (0..3).map(|j| w[j] as f32 * part.uvs[corners[j]][d]).sum()
            });
            part.uvs.push(uv);
        }
    }
}

/// One material of an MTL file.
#[derive(Debug, Clone, PartialEq)]
pub struct MtlMaterial {
    /// `newmtl` name (no spaces).
    pub name: String,
    /// `Kd` and `d`: the base colour, sRGB, alpha.
    pub rgba_srgb: [f32; 4],
    /// `map_Kd`: the image, relative to the MTL file.
    pub map_kd: Option<String>,
}

/// An MTL file: per material `newmtl`, `Kd`, `d` when translucent, and `map_Kd` when textured.
pub fn mtl_text(comment: &str, materials: &[MtlMaterial]) -> String {
    let mut out = format!("# {comment}\n");
    for m in materials {
        let c = m.rgba_srgb;
        let _ = writeln!(
            out,
            "\nnewmtl {}\nKd {} {} {}",
            m.name,
            channel(c[0]),
            channel(c[1]),
            channel(c[2])
        );
        if c[3] < 1.0 {
            let _ = writeln!(out, "d {}", channel(c[3]));
        }
        if let Some(map) = &m.map_kd {
            let _ = writeln!(out, "map_Kd {map}");
        }
    }
    out
}
