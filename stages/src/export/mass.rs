//! Mass properties of a body made of convex parts: volume, centre of mass and inertia of the
//! solid parts, uniform density.

use crate::check::HullMesh;

/// Volume, first and second moments of solids at unit density.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UnitDensity {
    /// Volume, m³.
    pub volume_m3: f64,
    /// ∫ x dV, m⁴.
    first: [f64; 3],
    /// ∫ x xᵀ dV about the body origin, m⁵.
    second: [[f64; 3]; 3],
}

/// Mass, centre of mass and inertia of a body.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MassProperties {
    /// Mass, kg.
    pub mass_kg: f64,
    /// Centre of mass, body frame, metres.
    pub center_m: [f64; 3],
    /// Inertia about the centre of mass, body axes: [ixx, iyy, izz, ixy, ixz, iyz], kg·m².
    pub inertia_kg_m2: [f64; 6],
    /// Whether the parts had no volume and the inertia is that of the bounding box.
    pub fallback_box: bool,
}

/// The moments of closed convex parts (vertices and outward triangles), unit density: each
/// part is a fan of tetrahedra from its vertex mean.
pub fn unit_density(parts: &[HullMesh]) -> UnitDensity {
    let mut volume = 0.0;
    let mut first = [0.0; 3];
    let mut second = [[0.0; 3]; 3];
    for (points, triangles) in parts {
        if points.is_empty() {
            continue;
        }
        let n = points.len() as f64;
        let o: [f64; 3] = std::array::from_fn(|k| points.iter().map(|p| p[k]).sum::<f64>() / n);
        for t in triangles {
            let [a, b, c] = t.map(|i| points[i as usize]);
            let (u, v, w) = (sub(a, o), sub(b, o), sub(c, o));
            let det = u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0])
                + u[2] * (v[0] * w[1] - v[1] * w[0]);
            let vol = det / 6.0;
            volume += vol;
            let tet = [o, a, b, c];
            let sum: [f64; 3] = std::array::from_fn(|k| tet.iter().map(|p| p[k]).sum());
            for k in 0..3 {
                first[k] += vol * sum[k] / 4.0;
            }
            // ∫ x xᵀ over a tetrahedron = V/20 · (Σ pᵢ pᵢᵀ + (Σ pᵢ)(Σ pᵢ)ᵀ).
            for r in 0..3 {
                for c in 0..3 {
                    let pp: f64 = tet.iter().map(|p| p[r] * p[c]).sum();
                    second[r][c] += vol / 20.0 * (pp + sum[r] * sum[c]);
                }
            }
        }
    }
    UnitDensity {
        volume_m3: volume,
        first,
        second,
    }
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

impl UnitDensity {
    /// The properties at `mass_kg`. Without volume, the inertia of a solid box of `size_m` ×
    /// `scale` about the body origin.
    pub fn with_mass(&self, mass_kg: f64, size_m: [f64; 3], scale: [f64; 3]) -> MassProperties {
        if self.volume_m3 <= 1e-15 || !self.volume_m3.is_finite() {
            let d: [f64; 3] = std::array::from_fn(|k| (size_m[k] * scale[k]).abs().max(1e-4));
            let f = mass_kg / 12.0;
            return MassProperties {
                mass_kg,
                center_m: [0.0; 3],
                inertia_kg_m2: [
                    f * (d[1] * d[1] + d[2] * d[2]),
                    f * (d[0] * d[0] + d[2] * d[2]),
                    f * (d[0] * d[0] + d[1] * d[1]),
                    0.0,
                    0.0,
                    0.0,
                ],
                fallback_box: true,
            };
        }
        let v = self.volume_m3;
        let com: [f64; 3] = std::array::from_fn(|k| self.first[k] / v);
        // Second moment about the centre of mass, per unit volume, then × mass.
        let c: [[f64; 3]; 3] = std::array::from_fn(|r| {
            std::array::from_fn(|k| self.second[r][k] / v - com[r] * com[k])
        });
        let trace = c[0][0] + c[1][1] + c[2][2];
        let m = mass_kg;
        MassProperties {
            mass_kg,
            center_m: com,
            inertia_kg_m2: [
                m * (trace - c[0][0]),
                m * (trace - c[1][1]),
                m * (trace - c[2][2]),
                -m * c[0][1],
                -m * c[0][2],
                -m * c[1][2],
            ],
            fallback_box: false,
        }
    }
}
