//! Wavefront OBJ text and the fixed number formats of every exported file (the same inputs
//! give the same bytes).

use std::fmt::Write as _;

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
