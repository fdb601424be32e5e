//! Synthetic assets for tests and benchmarks: closed triangle meshes (boxes, solids and
//! vessels of revolution) written as minimal GLB files, modelled as library assets are
//! (metres, +Y up, front toward +Z).

use serde_json::json;

/// A triangle mesh in the glTF frame.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Mesh {
    /// Vertex positions, metres.
    pub positions: Vec<[f64; 3]>,
    /// Triangles as vertex indices.
    pub triangles: Vec<[u32; 3]>,
}

impl Mesh {
    /// An axis-aligned box standing on y = 0, centred on the Y axis: `size` = (X, Y, Z) extents.
    pub fn cuboid(size: [f64; 3]) -> Self {
        let [hx, h, hz] = [size[0] / 2.0, size[1], size[2] / 2.0];
        let positions = vec![
            [-hx, 0.0, -hz],
            [hx, 0.0, -hz],
            [hx, 0.0, hz],
            [-hx, 0.0, hz],
            [-hx, h, -hz],
            [hx, h, -hz],
            [hx, h, hz],
            [-hx, h, hz],
        ];
        let triangles = vec![
            [0, 1, 2],
            [0, 2, 3],
            [4, 6, 5],
            [4, 7, 6],
            [0, 4, 5],
            [0, 5, 1],
            [1, 5, 6],
            [1, 6, 2],
            [2, 6, 7],
            [2, 7, 3],
            [3, 7, 4],
            [3, 4, 0],
        ];
        Self {
            positions,
            triangles,
        }
    }

    /// A surface of revolution about +Y of a profile of (radius, height) points that starts
    /// and ends on the axis (radius 0), so the surface is closed.
    pub fn lathe(profile: &[[f64; 2]], segments: usize) -> Self {
        let mut mesh = Self::default();
        let mut rings: Vec<Vec<u32>> = Vec::with_capacity(profile.len());
        for [r, y] in profile {
            let ring = if *r == 0.0 {
                mesh.positions.push([0.0, *y, 0.0]);
                vec![(mesh.positions.len() - 1) as u32]
            } else {
                (0..segments)
                    .map(|s| {
                        let a = std::f64::consts::TAU * s as f64 / segments as f64;
                        mesh.positions.push([r * a.cos(), *y, -r * a.sin()]);
                        (mesh.positions.len() - 1) as u32
                    })
                    .collect()
            };
            rings.push(ring);
        }
        for pair in rings.windows(2) {
            let (a, b) = (&pair[0], &pair[1]);
            for s in 0..segments {
                let t = (s + 1) % segments;
                match (a.len(), b.len()) {
                    (1, 1) => {}
                    (1, _) => mesh.triangles.push([a[0], b[t], b[s]]),
                    (_, 1) => mesh.triangles.push([a[s], a[t], b[0]]),
                    _ => {
                        mesh.triangles.push([a[s], a[t], b[t]]);
                        mesh.triangles.push([a[s], b[t], b[s]]);
                    }
                }
            }
        }
        mesh
    }

    /// An open vessel (a bowl, a cup): outer wall from the base up to the rim, then the inner
    /// wall down to a floor `floor_m` thick; its inside is a cavity open at the top.
    pub fn vessel(radius_m: f64, height_m: f64, wall_m: f64, floor_m: f64) -> Self {
        let inner = radius_m - wall_m;
        Self::lathe(
            &[
                [0.0, 0.0],
                [radius_m * 0.8, 0.0],
                [radius_m, height_m * 0.2],
                [radius_m, height_m],
                [inner, height_m],
                [inner, floor_m + height_m * 0.2],
                [inner * 0.8, floor_m],
                [0.0, floor_m],
            ],
            32,
        )
    }

    /// A UV sphere of `radius_m` resting on y = 0 with `rings` × `segments` quads (about
    /// 2 · rings · segments triangles), closed.
    pub fn sphere(radius_m: f64, rings: usize, segments: usize) -> Self {
        let profile: Vec<[f64; 2]> = (0..=rings)
            .map(|i| {
                let a = std::f64::consts::PI * i as f64 / rings as f64;
                let r = if i == 0 || i == rings {
                    0.0
                } else {
                    radius_m * a.sin()
                };
                [r, radius_m * (1.0 - a.cos())]
            })
            .collect();
        Self::lathe(&profile, segments)
    }

    /// This mesh moved by `offset`.
    pub fn translated(mut self, offset: [f64; 3]) -> Self {
        for p in &mut self.positions {
            for k in 0..3 {
                p[k] += offset[k];
            }
        }
        self
    }

    /// This mesh and another as one.
    pub fn merged(mut self, other: &Mesh) -> Self {
        let base = self.positions.len() as u32;
        self.positions.extend_from_slice(&other.positions);
        self.triangles
            .extend(other.triangles.iter().map(|t| t.map(|i| i + base)));
        self
    }

    /// A GLB holding this mesh in one node with the given scale (1 for a model in metres,
    /// 0.01 for one in centimetres).
    pub fn to_glb(&self, node_scale: f64) -> Vec<u8> {
        let nodes = json!([{"mesh": 0, "scale": [node_scale, node_scale, node_scale]}]);
        self.glb_with_nodes(nodes, json!([0]))
    }

    /// A GLB placing this mesh (stored once) by one node per translation: GPU-free
    /// instancing, as a scene of many copies is exported.
    pub fn to_instanced_glb(&self, translations: &[[f64; 3]]) -> Vec<u8> {
        let nodes: Vec<serde_json::Value> = translations
            .iter()
            .map(|t| json!({"mesh": 0, "translation": t}))
            .collect();
        let roots: Vec<usize> = (0..translations.len()).collect();
        self.glb_with_nodes(json!(nodes), json!(roots))
    }

    fn glb_with_nodes(&self, nodes: serde_json::Value, roots: serde_json::Value) -> Vec<u8> {
        let mut bin: Vec<u8> = Vec::new();
        for p in &self.positions {
            for v in p {
                bin.extend_from_slice(&(*v as f32).to_le_bytes());
            }
        }
        let positions_len = bin.len();
        for t in &self.triangles {
            for i in t {
                bin.extend_from_slice(&i.to_le_bytes());
            }
        }
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in &self.positions {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k] as f32);
                hi[k] = hi[k].max(p[k] as f32);
            }
        }
        let document = json!({
            "asset": {"version": "2.0", "generator": "mesa synthetic"},
            "buffers": [{"byteLength": bin.len()}],
            "bufferViews": [
                {"buffer": 0, "byteOffset": 0, "byteLength": positions_len},
                {"buffer": 0, "byteOffset": positions_len, "byteLength": bin.len() - positions_len}
            ],
            "accessors": [
                {"bufferView": 0, "componentType": 5126, "count": self.positions.len(),
                 "type": "VEC3", "min": lo, "max": hi},
                {"bufferView": 1, "componentType": 5125, "count": self.triangles.len() * 3,
                 "type": "SCALAR"}
            ],
            "materials": [{"name": "surface"}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}],
            "nodes": nodes,
            "scenes": [{"nodes": roots}],
            "scene": 0
        });
        // Serialising a json! value cannot fail.
        let mut text = serde_json::to_vec(&document).unwrap_or_default();
        while text.len() % 4 != 0 {
            text.push(b' ');
        }
        while bin.len() % 4 != 0 {
            bin.push(0);
        }
        let total = 12 + 8 + text.len() + 8 + bin.len();
        let mut out = Vec::with_capacity(total);
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(text.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&text);
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&bin);
        out
    }
}
