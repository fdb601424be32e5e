//! Mesh boxes, and whether an edited scene's mesh is still the pack's.

use std::collections::HashMap;

/// The bounding box `(min, max)` of points; `None` when there is none.
pub fn bounds(points: &[[f64; 3]]) -> Option<([f64; 3], [f64; 3])> {
    let first = *points.first()?;
    let mut min = first;
    let mut max = first;
    for p in points {
        for i in 0..3 {
            min[i] = min[i].min(p[i]);
            max[i] = max[i].max(p[i]);
        }
    }
    Some((min, max))
}

/// The eight corners of a box.
pub fn corners(min: [f64; 3], max: [f64; 3]) -> [[f64; 3]; 8] {
    let mut out = [[0.0; 3]; 8];
    for (k, corner) in out.iter_mut().enumerate() {
        for i in 0..3 {
            corner[i] = if k >> i & 1 == 0 { min[i] } else { max[i] };
        }
    }
    out
}

/// How an edited scene's mesh relates to the pack's.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MeshComparison {
    /// Every vertex is a vertex of the pack's mesh.
    Unchanged,
    /// The vertices are the pack's, scaled per axis and moved: scale or location applied
    /// (Ctrl+A); the box still gives the right size and position.
    TransformApplied,
    /// Anything else: vertices edited, a rotation applied, another mesh.
    Edited,
}

impl MeshComparison {
    /// The name written in `diff.json`.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Unchanged => "unchanged",
            Self::TransformApplied => "transform_applied",
            Self::Edited => "edited",
        }
    }
}

/// A hash grid of points for "is there a point within `tolerance`" queries.
struct Grid {
    cell: f64,
    cells: HashMap<[i64; 3], Vec<[f64; 3]>>,
    tolerance: f64,
}

impl Grid {
    fn new(points: &[[f64; 3]], tolerance: f64) -> Self {
        let cell = tolerance * 4.0;
        let mut cells: HashMap<[i64; 3], Vec<[f64; 3]>> = HashMap::new();
        for p in points {
            cells.entry(Self::key(cell, *p)).or_default().push(*p);
        }
        Self {
            cell,
            cells,
            tolerance,
        }
    }

    fn key(cell: f64, p: [f64; 3]) -> [i64; 3] {
        p.map(|v| (v / cell).floor() as i64)
    }

    fn contains(&self, p: [f64; 3]) -> bool {
        let k = Self::key(self.cell, p);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    // Saturating: a far-away vertex (a hostile file) must not overflow.
                    let cell = [
                        k[0].saturating_add(dx),
                        k[1].saturating_add(dy),
                        k[2].saturating_add(dz),
                    ];
                    let Some(points) = self.cells.get(&cell) else {
                        continue;
                    };
                    if points
                        .iter()
                        .any(|q| (0..3).all(|i| (q[i] - p[i]).abs() <= self.tolerance))
                    {
                        return true;
                    }
                }
            }
        }
        false
    }
}

/// Compares an edited mesh's local vertices with the pack's. The tolerance allows for Draco
/// quantization (14 bits over the mesh's extent) and float noise.
pub fn compare_meshes(pack: &[[f64; 3]], edited: &[[f64; 3]]) -> MeshComparison {
    let (Some((pmin, pmax)), Some((emin, emax))) = (bounds(pack), bounds(edited)) else {
        return MeshComparison::Edited;
    };
    let extent = (0..3).map(|i| pmax[i] - pmin[i]).fold(0.0, f64::max);
    let tolerance = 1e-6 + 1e-4 * extent;
    let grid = Grid::new(pack, tolerance);
    if edited.iter().all(|p| grid.contains(*p)) {
        return MeshComparison::Unchanged;
    }
    // A per-axis scale and offset taking the pack's box to the edited one.
    let mut a = [1.0; 3];
    let mut b = [0.0; 3];
    for i in 0..3 {
        let pe = pmax[i] - pmin[i];
        let ee = emax[i] - emin[i];
        if pe <= 0.0 || ee <= 0.0 {
            return MeshComparison::Edited;
        }
        a[i] = ee / pe;
        b[i] = emin[i] - a[i] * pmin[i];
    }
    let back = |p: &[f64; 3]| [0, 1, 2].map(|i| (p[i] - b[i]) / a[i]);
    if edited.iter().all(|p| grid.contains(back(p))) {
        MeshComparison::TransformApplied
    } else {
        MeshComparison::Edited
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cube() -> Vec<[f64; 3]> {
        corners([-0.1, -0.2, -0.05], [0.1, 0.2, 0.05]).to_vec()
    }

    #[test]
    fn far_away_vertices_do_not_overflow_the_grid() {
        let far = vec![[1e300, -1e300, 1e300], [f64::MAX, 0.0, f64::MIN]];
        assert_eq!(compare_meshes(&cube(), &far), MeshComparison::Edited);
        // (A pack mesh is ours, so never this far; it must not panic either.)
        let _ = compare_meshes(&far, &cube());
    }

    #[test]
    fn the_same_vertices_in_another_order_are_unchanged() {
        let mut edited = cube();
        edited.reverse();
        edited.push(edited[0]);
        assert_eq!(compare_meshes(&cube(), &edited), MeshComparison::Unchanged);
    }

    #[test]
    fn applied_scale_and_location_are_told_from_edits() {
        let scaled: Vec<[f64; 3]> = cube()
            .iter()
            .map(|p| [p[0] * 2.0 + 0.3, p[1] * 0.5, p[2] * 1.5 - 0.1])
            .collect();
        assert_eq!(
            compare_meshes(&cube(), &scaled),
            MeshComparison::TransformApplied
        );
        // A quarter turn applied about Y: the box changes shape, the vertices are not a
        // per-axis scaling of the pack's.
        let mut with_extra = cube();
        with_extra.push([0.0, 0.0, 0.0]);
        let turned: Vec<[f64; 3]> = with_extra
            .iter()
            .map(|p| [p[2], p[1], -p[0] + 0.01 * p[1]])
            .collect();
        assert_eq!(compare_meshes(&with_extra, &turned), MeshComparison::Edited);
        let mut moved_vertex = cube();
        moved_vertex[3][0] += 0.01;
        moved_vertex.push([0.0, 0.0, 0.0]);
        assert_eq!(
            compare_meshes(&cube(), &moved_vertex),
            MeshComparison::Edited
        );
    }
}
