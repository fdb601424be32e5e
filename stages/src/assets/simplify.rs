//! Decimation by vertex clustering: the vertices in each cell of a uniform grid become one
//! vertex (their mean), and a triangle whose corners fall into three different cells is kept
//! (once). Linear in the triangles and memory-light, which is what an asset over its budget
//! needs; the price is detail below a cell, measured afterwards as the reach of the collision
//! shape outside the original mesh ([`super::reach`]).

use std::collections::HashMap;

/// A decimated mesh.
#[derive(Debug, Clone, PartialEq)]
pub struct Simplified {
    /// Vertex positions, metres.
    pub positions: Vec<[f64; 3]>,
    /// Triangles as vertex indices.
    pub triangles: Vec<[u32; 3]>,
    /// The grid's cell size, metres.
    pub cell_m: f64,
}

/// One clustering on a grid of `cells` cells along the longest side of the bounds.
fn cluster(positions: &[[f64; 3]], triangles: &[[u32; 3]], lo: [f64; 3], cell: f64) -> Simplified {
    let mut ids: HashMap<[i64; 3], u32> = HashMap::new();
    let mut sums: Vec<([f64; 3], u32)> = Vec::new();
    let remap: Vec<u32> = positions
        .iter()
        .map(|p| {
            let key: [i64; 3] = std::array::from_fn(|k| ((p[k] - lo[k]) / cell).floor() as i64);
            let id = *ids.entry(key).or_insert_with(|| {
                sums.push(([0.0; 3], 0));
                (sums.len() - 1) as u32
            });
            let (sum, n) = &mut sums[id as usize];
            for k in 0..3 {
                sum[k] += p[k];
            }
            *n += 1;
            id
        })
        .collect();
    let positions: Vec<[f64; 3]> = sums
        .iter()
        .map(|(sum, n)| sum.map(|v| v / f64::from(*n)))
        .collect();
    let mut seen: std::collections::HashSet<[u32; 3]> = std::collections::HashSet::new();
    let triangles: Vec<[u32; 3]> = triangles
        .iter()
        .map(|t| t.map(|i| remap[i as usize]))
        .filter(|&[a, b, c]| a != b && b != c && a != c)
        .filter(|t| {
            let mut key = *t;
            key.sort_unstable();
            seen.insert(key)
        })
        .collect();
    Simplified {
        positions,
        triangles,
        cell_m: cell,
    }
}

/// The mesh decimated to at most `max_triangles` triangles: clustered on a grid fine enough
/// for about that many, then coarser until it fits.
pub fn decimate(positions: &[[f64; 3]], triangles: &[[u32; 3]], max_triangles: u64) -> Simplified {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in positions {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let longest = (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max);
    // A closed surface clustered on n cells a side keeps about 4 n² triangles (a sphere's:
    // about 2π n²): start there.
    let mut cells = ((max_triangles.max(8) as f64 / 4.0).sqrt()).max(2.0);
    loop {
        let cell = (longest / cells).max(1e-9);
        let simplified = cluster(positions, triangles, lo, cell);
        if simplified.triangles.len() as u64 <= max_triangles || cells <= 2.0 {
            return simplified;
        }
        cells = (cells * 0.8).max(2.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::assets::synthetic::Mesh;

    #[test]
    fn a_fine_sphere_is_decimated_under_the_target() {
        let profile: Vec<[f64; 2]> = (0..=200)
            .map(|i| {
                let a = std::f64::consts::PI * f64::from(i) / 200.0;
                [0.05 * a.sin().abs(), -0.05 * a.cos()]
            })
            .map(|[r, y]| [if r < 1e-12 { 0.0 } else { r }, y])
            .collect();
        let sphere = Mesh::lathe(&profile, 200);
        assert!(sphere.triangles.len() > 70_000);
        let simplified = decimate(&sphere.positions, &sphere.triangles, 5_000);
        assert!(simplified.triangles.len() <= 5_000);
        assert!(simplified.triangles.len() > 1_000);
        // Cluster means stay within a cell of the surface.
        for p in &simplified.positions {
            let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
            assert!((r - 0.05).abs() <= simplified.cell_m * 3f64.sqrt());
        }
    }
}
