//! The GLB reader on small hand-built files, one feature or one defect each.

use approx::assert_abs_diff_eq;
use proptest::prelude::*;
use serde_json::{json, Value};

use super::*;

/// A GLB from a JSON document and a BIN chunk (both padded as the format requires).
fn glb(json: &Value, bin: &[u8]) -> Vec<u8> {
    let mut text = serde_json::to_vec(json).expect("json");
    while text.len() % 4 != 0 {
        text.push(b' ');
    }
    let mut bin = bin.to_vec();
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let mut out = b"glTF".to_vec();
    out.extend_from_slice(&2u32.to_le_bytes());
    let total = 12 + 8 + text.len() + if bin.is_empty() { 0 } else { 8 + bin.len() };
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(text.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&text);
    if !bin.is_empty() {
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&bin);
    }
    out
}

/// Accumulates buffer data and the bufferViews / accessors that read it.
#[derive(Default)]
struct Builder {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Builder {
    fn view(&mut self, bytes: &[u8], stride: Option<usize>) -> usize {
        while self.bin.len() % 4 != 0 {
            self.bin.push(0);
        }
        let mut view =
            json!({"buffer": 0, "byteOffset": self.bin.len(), "byteLength": bytes.len()});
        if let Some(stride) = stride {
            view["byteStride"] = json!(stride);
        }
        self.bin.extend_from_slice(bytes);
        self.views.push(view);
        self.views.len() - 1
    }

    fn accessor(&mut self, accessor: Value) -> usize {
        self.accessors.push(accessor);
        self.accessors.len() - 1
    }

    fn positions(&mut self, points: &[[f32; 3]]) -> usize {
        let bytes: Vec<u8> = points
            .iter()
            .flatten()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let view = self.view(&bytes, None);
        let mut accessor = json!({"bufferView": view, "componentType": 5126, "count": points.len(), "type": "VEC3"});
        if points.iter().flatten().all(|v| v.is_finite()) {
            let fold = |f: fn(f32, f32) -> f32, start: f32| {
                (0..3)
                    .map(|k| points.iter().map(|p| p[k]).fold(start, f))
                    .collect::<Vec<f32>>()
            };
            accessor["min"] = json!(fold(f32::min, f32::INFINITY));
            accessor["max"] = json!(fold(f32::max, f32::NEG_INFINITY));
        }
        self.accessor(accessor)
    }

    fn indices_u16(&mut self, indices: &[u16]) -> usize {
        let bytes: Vec<u8> = indices.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.view(&bytes, None);
        self.accessor(json!({"bufferView": view, "componentType": 5123, "count": indices.len(), "type": "SCALAR"}))
    }

    /// The document with these buffers, views and accessors, plus `rest`.
    fn document(&self, rest: Value) -> Value {
        let mut doc = json!({
            "asset": {"version": "2.0"},
            "buffers": [{"byteLength": self.bin.len()}],
            "bufferViews": self.views,
            "accessors": self.accessors,
        });
        if let (Some(doc), Some(rest)) = (doc.as_object_mut(), rest.as_object()) {
            for (k, v) in rest {
                doc.insert(k.clone(), v.clone());
            }
        }
        doc
    }

    fn glb(&self, rest: Value) -> Vec<u8> {
        glb(&self.document(rest), &self.bin)
    }
}

const QUAD: [[f32; 3]; 4] = [
    [0.0, 0.0, 0.0],
    [1.0, 0.0, 0.0],
    [1.0, 1.0, 0.0],
    [0.0, 1.0, 0.0],
];

fn one_mesh(primitive: Value, node: Value) -> Value {
    json!({
        "meshes": [{"primitives": [primitive]}],
        "nodes": [node],
        "scenes": [{"nodes": [0]}],
        "scene": 0
    })
}

fn bounds(mesh: &GlbMesh) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in &mesh.positions_m {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, hi)
}

fn error_of(bytes: &[u8]) -> GlbError {
    match read_glb(bytes) {
        Ok(mesh) => panic!("expected an error, read {} triangles", mesh.triangles.len()),
        Err(e) => e,
    }
}

#[test]
fn indexed_triangles_with_a_trs_node() {
    let mut b = Builder::default();
    let pos = b.positions(&QUAD);
    let idx = b.indices_u16(&[0, 1, 2, 0, 2, 3]);
    let bytes = b.glb(one_mesh(
        json!({"attributes": {"POSITION": pos}, "indices": idx}),
        json!({"mesh": 0, "translation": [1.0, 2.0, 3.0], "scale": [2.0, 2.0, 2.0]}),
    ));
    let mesh = read_glb(&bytes).expect("reads");
    assert_eq!(mesh.triangles, vec![[0, 1, 2], [0, 2, 3]]);
    let (lo, hi) = bounds(&mesh);
    assert_eq!(lo, [1.0, 2.0, 3.0]);
    assert_eq!(hi, [3.0, 4.0, 3.0]);
    assert_eq!(mesh.info.mesh_instances, 1);
    assert!(mesh.warnings.is_empty(), "{:?}", mesh.warnings);
}

#[test]
fn a_column_major_matrix_and_a_rotation_in_a_hierarchy() {
    let mut b = Builder::default();
    let pos = b.positions(&[[1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]);
    // Parent: a matrix translating by (0, 5, 0) (column-major: translation in the last column).
    // Child: a quarter turn about +Y, taking +X to -Z.
    let s = std::f32::consts::FRAC_1_SQRT_2;
    let doc = json!({
        "meshes": [{"primitives": [{"attributes": {"POSITION": pos}}]}],
        "nodes": [
            {"children": [1], "matrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,5,0,1]},
            {"mesh": 0, "rotation": [0.0, s, 0.0, s]}
        ],
        "scenes": [{"nodes": [0]}]
    });
    let mesh = read_glb(&b.glb(doc)).expect("reads");
    let p = mesh.positions_m[0];
    assert_abs_diff_eq!(p[0], 0.0, epsilon = 1e-6);
    assert_abs_diff_eq!(p[1], 5.0, epsilon = 1e-6);
    assert_abs_diff_eq!(p[2], -1.0, epsilon = 1e-6);
    // No indices: the vertices in order.
    assert_eq!(mesh.triangles, vec![[0, 1, 2]]);
}

#[test]
fn a_mesh_used_by_two_nodes_is_placed_twice() {
    let mut b = Builder::default();
    let pos = b.positions(&QUAD[..3]);
    let doc = json!({
        "meshes": [{"primitives": [{"attributes": {"POSITION": pos}}]}],
        "nodes": [{"mesh": 0}, {"mesh": 0, "translation": [10.0, 0.0, 0.0]}],
        "scenes": [{"nodes": [0, 1]}]
    });
    let mesh = read_glb(&b.glb(doc)).expect("reads");
    assert_eq!(mesh.triangles, vec![[0, 1, 2], [3, 4, 5]]);
    assert_eq!(mesh.info.mesh_instances, 2);
    assert_eq!(bounds(&mesh).1[0], 11.0);
}

#[test]
fn u8_and_u32_indices_strips_and_fans() {
    for (component, bytes_per) in [(5121u32, 1usize), (5125, 4)] {
        for (mode, expected) in [
            (4, vec![[0, 1, 2], [0, 2, 3]]),
            (5, vec![[0, 1, 3], [1, 2, 3]]),
            (6, vec![[0, 1, 2], [0, 2, 3]]),
        ] {
            let order: &[u32] = if mode == 4 {
                &[0, 1, 2, 0, 2, 3]
            } else if mode == 5 {
                &[0, 1, 3, 2]
            } else {
                &[0, 1, 2, 3]
            };
            let mut b = Builder::default();
            let pos = b.positions(&QUAD);
            let raw: Vec<u8> = order
                .iter()
                .flat_map(|i| i.to_le_bytes()[..bytes_per].to_vec())
                .collect();
            let view = b.view(&raw, None);
            let idx = b.accessor(json!({"bufferView": view, "componentType": component, "count": order.len(), "type": "SCALAR"}));
            let bytes = b.glb(one_mesh(
                json!({"attributes": {"POSITION": pos}, "indices": idx, "mode": mode}),
                json!({"mesh": 0}),
            ));
            let mesh = read_glb(&bytes).expect("reads");
            assert_eq!(
                mesh.triangles, expected,
                "component {component} mode {mode}"
            );
        }
    }
}

#[test]
fn interleaved_positions_with_a_byte_stride() {
    let mut b = Builder::default();
    // POSITION then a 3-float normal per vertex: stride 24.
    let mut raw = Vec::new();
    for p in &QUAD[..3] {
        for v in p.iter().chain(&[9.0f32, 9.0, 9.0]) {
            raw.extend_from_slice(&v.to_le_bytes());
        }
    }
    let view = b.view(&raw, Some(24));
    let pos =
        b.accessor(json!({"bufferView": view, "componentType": 5126, "count": 3, "type": "VEC3"}));
    let mesh = read_glb(&b.glb(one_mesh(
        json!({"attributes": {"POSITION": pos}}),
        json!({"mesh": 0}),
    )))
    .expect("reads");
    assert_eq!(
        mesh.positions_m,
        vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]]
    );
}

#[test]
fn sparse_positions_replace_their_base() {
    let mut b = Builder::default();
    let base = b.view(
        &QUAD[..3]
            .iter()
            .flatten()
            .flat_map(|v| v.to_le_bytes())
            .collect::<Vec<u8>>(),
        None,
    );
    let indices = b.view(&[2u8, 0, 0, 0], None);
    let values = b.view(
        &[7.0f32, 8.0, 9.0]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect::<Vec<u8>>(),
        None,
    );
    let pos = b.accessor(json!({
        "bufferView": base, "componentType": 5126, "count": 3, "type": "VEC3",
        "sparse": {"count": 1, "indices": {"bufferView": indices, "componentType": 5121},
                   "values": {"bufferView": values}}
    }));
    let mesh = read_glb(&b.glb(one_mesh(
        json!({"attributes": {"POSITION": pos}}),
        json!({"mesh": 0}),
    )))
    .expect("reads");
    assert_eq!(mesh.positions_m[2], [7.0, 8.0, 9.0]);
    assert_eq!(mesh.positions_m[1], [1.0, 0.0, 0.0]);

    // Sparse values over an accessor without bufferView (zeros).
    let mut b = Builder::default();
    let indices = b.view(&[1u8, 0, 0, 0], None);
    let values = b.view(
        &[1.0f32, 1.0, 1.0]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect::<Vec<u8>>(),
        None,
    );
    let pos = b.accessor(json!({
        "componentType": 5126, "count": 3, "type": "VEC3",
        "sparse": {"count": 1, "indices": {"bufferView": indices, "componentType": 5121},
                   "values": {"bufferView": values}}
    }));
    let mesh = read_glb(&b.glb(one_mesh(
        json!({"attributes": {"POSITION": pos}}),
        json!({"mesh": 0}),
    )))
    .expect("reads");
    assert_eq!(mesh.positions_m, vec![[0.0; 3], [1.0; 3], [0.0; 3]]);
}

#[test]
fn quantized_normalized_positions() {
    // KHR_mesh_quantization: i16 normalized positions, scaled back by the node.
    let mut b = Builder::default();
    // Three VEC3 of i16 every 8 bytes (2 bytes of padding each).
    let raw: Vec<u8> = [32767i16, 0, 0, 0, 0, 0, -32767, 0, 0, 32767, 0, 0]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let view = b.view(&raw, Some(8));
    let pos = b.accessor(json!({"bufferView": view, "componentType": 5122, "normalized": true, "count": 3, "type": "VEC3"}));
    let mut doc = one_mesh(
        json!({"attributes": {"POSITION": pos}}),
        json!({"mesh": 0, "scale": [0.5, 0.5, 0.5]}),
    );
    doc["extensionsUsed"] = json!(["KHR_mesh_quantization"]);
    doc["extensionsRequired"] = json!(["KHR_mesh_quantization"]);
    let mesh = read_glb(&b.glb(doc)).expect("reads");
    assert_abs_diff_eq!(mesh.positions_m[0][0], 0.5, epsilon = 1e-9);
    assert_abs_diff_eq!(mesh.positions_m[1][2], -0.5, epsilon = 1e-9);
    assert_abs_diff_eq!(mesh.positions_m[2][1], 0.5, epsilon = 1e-9);
    assert_eq!(mesh.info.extensions_required, ["KHR_mesh_quantization"]);
}

#[test]
fn a_skinned_mesh_is_read_at_its_rest_pose() {
    let mut b = Builder::default();
    let pos = b.positions(&QUAD[..3]);
    let joints = b.view(&[0u8, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0], None);
    let joints = b
        .accessor(json!({"bufferView": joints, "componentType": 5121, "count": 3, "type": "VEC4"}));
    let weights: Vec<u8> = [
        1.0f32, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.5, 0.5, 0.0, 0.0,
    ]
    .iter()
    .flat_map(|v| v.to_le_bytes())
    .collect();
    let weights = b.view(&weights, None);
    let weights = b.accessor(
        json!({"bufferView": weights, "componentType": 5126, "count": 3, "type": "VEC4"}),
    );
    // Inverse bind matrices: identity for both joints.
    let ibm: Vec<u8> = [[
        1.0f32, 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1.,
    ]; 2]
        .iter()
        .flatten()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let ibm = b.view(&ibm, None);
    let ibm =
        b.accessor(json!({"bufferView": ibm, "componentType": 5126, "count": 2, "type": "MAT4"}));
    let doc = json!({
        "meshes": [{"primitives": [{"attributes": {"POSITION": pos, "JOINTS_0": joints, "WEIGHTS_0": weights}}]}],
        // The skinned node's own transform is ignored (glTF 2.0 §3.7.3).
        "nodes": [
            {"mesh": 0, "skin": 0, "translation": [100.0, 0.0, 0.0]},
            {"children": [2]},
            {"translation": [0.0, 10.0, 0.0]}
        ],
        "skins": [{"joints": [1, 2], "inverseBindMatrices": ibm}],
        "scenes": [{"nodes": [0, 1]}]
    });
    let mesh = read_glb(&b.glb(doc)).expect("reads");
    assert!(mesh.info.skinned);
    assert_eq!(mesh.positions_m[0], [0.0, 0.0, 0.0]);
    assert_eq!(mesh.positions_m[1], [1.0, 10.0, 0.0]);
    assert_eq!(mesh.positions_m[2], [1.0, 6.0, 0.0]);
}

#[test]
fn morph_targets_at_their_default_weights() {
    let mut b = Builder::default();
    let pos = b.positions(&QUAD[..3]);
    let offsets = b.positions(&[[0.0, 0.0, 2.0]; 3]);
    let doc = json!({
        "meshes": [{"primitives": [{"attributes": {"POSITION": pos}, "targets": [{"POSITION": offsets}]}], "weights": [0.5]}],
        "nodes": [{"mesh": 0}],
        "scenes": [{"nodes": [0]}]
    });
    let mesh = read_glb(&b.glb(doc)).expect("reads");
    assert!(mesh.info.morph_targets);
    assert!(mesh.positions_m.iter().all(|p| p[2] == 1.0));
}

#[test]
fn a_data_uri_buffer_is_read() {
    let data: Vec<u8> = QUAD[..3]
        .iter()
        .flatten()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let uri = format!(
        "data:application/octet-stream;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(&data)
    );
    let doc = json!({
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": data.len(), "uri": uri}],
        "bufferViews": [{"buffer": 0, "byteLength": data.len()}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "nodes": [{"mesh": 0}],
        "scenes": [{"nodes": [0]}]
    });
    let mesh = read_glb(&glb(&doc, &[])).expect("reads");
    assert_eq!(mesh.triangles.len(), 1);
}

#[test]
fn points_and_lines_are_skipped_and_counted() {
    let mut b = Builder::default();
    let pos = b.positions(&QUAD[..3]);
    let doc = json!({
        "meshes": [{"primitives": [{"attributes": {"POSITION": pos}}, {"attributes": {"POSITION": pos}, "mode": 1}]}],
        "nodes": [{"mesh": 0}],
        "scenes": [{"nodes": [0]}]
    });
    let mesh = read_glb(&b.glb(doc)).expect("reads");
    assert_eq!(mesh.info.skipped_primitives, 1);
    assert!(
        mesh.warnings.iter().any(|w| w.contains("point or line")),
        "{:?}",
        mesh.warnings
    );

    let mut b = Builder::default();
    let pos = b.positions(&QUAD[..3]);
    let only_points = b.glb(one_mesh(
        json!({"attributes": {"POSITION": pos}, "mode": 0}),
        json!({"mesh": 0}),
    ));
    let e = error_of(&only_points);
    assert_eq!(e.code(), "no_mesh");
    assert!(e.to_string().contains("points or lines"), "{e}");
}

#[test]
fn a_scene_without_mesh_nodes_has_no_mesh() {
    let mut b = Builder::default();
    let pos = b.positions(&QUAD[..3]);
    let doc = json!({
        "meshes": [{"primitives": [{"attributes": {"POSITION": pos}}]}],
        "nodes": [{"name": "empty"}],
        "scenes": [{"nodes": [0]}]
    });
    let e = error_of(&b.glb(doc));
    assert!(
        e.to_string()
            .starts_with("no triangle mesh: no node of the scene places any of its 1 meshes"),
        "{e}"
    );
}

#[test]
fn out_of_range_data_is_an_error_with_its_path() {
    let mut b = Builder::default();
    let pos = b.positions(&QUAD[..3]);
    let idx = b.indices_u16(&[0, 1, 7]);
    let e = error_of(&b.glb(one_mesh(
        json!({"attributes": {"POSITION": pos}, "indices": idx}),
        json!({"mesh": 0}),
    )));
    assert_eq!(
        e.to_string(),
        "meshes[0].primitives[0].indices: index 7 is out of range of the 3 vertices"
    );

    // An accessor that reads past its bufferView.
    let mut b = Builder::default();
    let view = b.view(&[0u8; 24], None);
    let pos =
        b.accessor(json!({"bufferView": view, "componentType": 5126, "count": 3, "type": "VEC3"}));
    let e = error_of(&b.glb(one_mesh(
        json!({"attributes": {"POSITION": pos}}),
        json!({"mesh": 0}),
    )));
    assert_eq!(e.code(), "data");
    assert!(
        e.to_string().contains("overrun the bufferView (24 bytes)"),
        "{e}"
    );

    // A buffer shorter than it says.
    let mut b = Builder::default();
    let pos = b.positions(&QUAD[..3]);
    let mut doc = b.document(one_mesh(
        json!({"attributes": {"POSITION": pos}}),
        json!({"mesh": 0}),
    ));
    doc["buffers"][0]["byteLength"] = json!(4096);
    let e = error_of(&glb(&doc, &b.bin));
    assert!(
        e.to_string()
            .starts_with("buffers[0]: byteLength is 4096 but only"),
        "{e}"
    );
}

#[test]
fn non_finite_positions_are_an_error() {
    let mut b = Builder::default();
    let pos = b.positions(&[[0.0, 0.0, 0.0], [f32::NAN, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let e = error_of(&b.glb(one_mesh(
        json!({"attributes": {"POSITION": pos}}),
        json!({"mesh": 0}),
    )));
    assert_eq!(
        e.to_string(),
        "meshes[0].primitives[0].attributes.POSITION: has a non-finite value"
    );
}

#[test]
fn a_cycle_in_the_hierarchy_is_an_error() {
    let mut b = Builder::default();
    let pos = b.positions(&QUAD[..3]);
    let doc = json!({
        "meshes": [{"primitives": [{"attributes": {"POSITION": pos}}]}],
        "nodes": [{"mesh": 0, "children": [1]}, {"children": [0]}],
        "scenes": [{"nodes": [0]}]
    });
    assert_eq!(error_of(&b.glb(doc)).code(), "invalid_gltf");
}

#[test]
fn references_out_of_range_are_reported_with_their_json_path() {
    let mut b = Builder::default();
    let pos = b.positions(&QUAD[..3]);
    let doc = json!({
        "meshes": [{"primitives": [{"attributes": {"POSITION": pos}, "material": 4}]}],
        "nodes": [{"mesh": 0}],
        "scenes": [{"nodes": [0]}]
    });
    let e = error_of(&b.glb(doc));
    assert_eq!(
        e.to_string(),
        "invalid glTF: meshes[0].primitives[0].material: Index out of bounds"
    );
}

#[test]
fn extensions_that_change_geometry_are_rejected_with_a_fix() {
    for (extension, expected) in [
        ("EXT_meshopt_compression", "gltfpack"),
        ("EXT_mesh_gpu_instancing", "Make Instances Real"),
        ("EXT_something_new", "without this extension"),
    ] {
        let mut b = Builder::default();
        let pos = b.positions(&QUAD[..3]);
        let mut doc = one_mesh(json!({"attributes": {"POSITION": pos}}), json!({"mesh": 0}));
        doc["extensionsUsed"] = json!([extension]);
        doc["extensionsRequired"] = json!([extension]);
        let e = error_of(&b.glb(doc));
        assert_eq!(e.code(), "unsupported_extension");
        assert!(e.to_string().contains(expected), "{e}");
    }
    // Lights and materials do not change the geometry.
    let mut b = Builder::default();
    let pos = b.positions(&QUAD[..3]);
    let mut doc = one_mesh(json!({"attributes": {"POSITION": pos}}), json!({"mesh": 0}));
    doc["extensionsUsed"] = json!(["KHR_lights_punctual", "KHR_materials_clearcoat"]);
    doc["extensionsRequired"] = json!(["KHR_lights_punctual", "KHR_materials_clearcoat"]);
    assert!(read_glb(&b.glb(doc)).is_ok());
}

#[test]
fn external_buffers_are_rejected() {
    let doc = json!({
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": 36, "uri": "mesh.bin"}],
    });
    let e = error_of(&glb(&doc, &[]));
    assert_eq!(e.code(), "external_uri");
    assert!(
        e.to_string()
            .starts_with("buffers[0] refers to the external file \"mesh.bin\""),
        "{e}"
    );
}

#[test]
fn the_version_is_checked_before_the_document() {
    let e = error_of(&glb(
        &json!({"asset": {"version": "1.0"}, "meshes": {"m": {}}}),
        &[],
    ));
    assert_eq!(e, GlbError::Gltf1);
    let e = error_of(&glb(&json!({"asset": {"version": "3.0"}}), &[]));
    assert_eq!(e.code(), "version");
    let e = error_of(&glb(
        &json!({"asset": {"version": "2.0", "minVersion": "2.1"}}),
        &[],
    ));
    assert_eq!(e.code(), "version");
}

#[test]
fn materials_textures_and_images_are_described() {
    let mut b = Builder::default();
    let pos = b.positions(&QUAD[..3]);
    let png = b.view(&[0x89, b'P', b'N', b'G'], None);
    let mut doc = one_mesh(
        json!({"attributes": {"POSITION": pos}, "material": 0}),
        json!({"mesh": 0}),
    );
    doc["materials"] = json!([
        {"name": "glaze", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}},
        {}
    ]);
    doc["textures"] = json!([{"source": 0}]);
    doc["images"] = json!([{"bufferView": png, "mimeType": "image/png"}]);
    let mesh = read_glb(&b.glb(doc)).expect("reads");
    assert_eq!(
        mesh.info.materials,
        vec![
            MaterialInfo {
                name: "glaze".to_owned(),
                textured: true
            },
            MaterialInfo {
                name: "material_1".to_owned(),
                textured: false
            },
        ]
    );
    assert_eq!(mesh.info.textures, 1);
    assert_eq!(mesh.info.image_mime_types, ["image/png"]);
}

/// A small file using indices, sparse values, a hierarchy and a skin: something for damage to
/// hit.
fn rich_fixture() -> Vec<u8> {
    let mut b = Builder::default();
    let pos = b.positions(&QUAD);
    let idx = b.indices_u16(&[0, 1, 2, 0, 2, 3]);
    let indices = b.view(&[1u8, 0, 0, 0], None);
    let values = b.view(
        &[0.5f32, 0.5, 0.5]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect::<Vec<u8>>(),
        None,
    );
    let sparse = b.accessor(json!({
        "componentType": 5126, "count": 4, "type": "VEC3",
        "sparse": {"count": 1, "indices": {"bufferView": indices, "componentType": 5121},
                   "values": {"bufferView": values}}
    }));
    b.glb(json!({
        "meshes": [{"primitives": [
            {"attributes": {"POSITION": pos}, "indices": idx},
            {"attributes": {"POSITION": pos}, "targets": [{"POSITION": sparse}]}
        ], "weights": [1.0]}],
        "nodes": [{"children": [1], "rotation": [0.0, 0.6, 0.0, 0.8]}, {"mesh": 0, "scale": [2.0, 1.0, 1.0]}],
        "scenes": [{"nodes": [0]}]
    }))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]
    /// Damaged files (bytes changed, the end cut off) are read or rejected, never a panic and
    /// never an out-of-range index.
    #[test]
    fn damaged_files_are_read_or_rejected(
        flips in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..6),
        keep in 0.0f64..=1.0,
    ) {
        let mut bytes = rich_fixture();
        for (at, value) in flips {
            let i = at.index(bytes.len());
            bytes[i] = value;
        }
        let len = ((bytes.len() as f64) * keep).round() as usize;
        bytes.truncate(len.max(1));
        if let Ok(mesh) = read_glb(&bytes) {
            let n = mesh.positions_m.len() as u32;
            prop_assert!(mesh.triangles.iter().flatten().all(|i| *i < n));
            prop_assert!(mesh.positions_m.iter().flatten().all(|v| v.is_finite()));
        }
    }
}

#[test]
fn the_rich_fixture_reads() {
    let mesh = read_glb(&rich_fixture()).expect("reads");
    // Two from the indexed quad; the unindexed primitive's 4 vertices make one, and one left.
    assert_eq!(mesh.triangles.len(), 3);
    assert!(mesh.info.morph_targets);
    assert!(
        mesh.warnings
            .iter()
            .any(|w| w.contains("4 indices is not a multiple of 3")),
        "{:?}",
        mesh.warnings
    );
}

/// Found by fuzzing (`fuzz/`): gltf-json's validation indexed the accessor list with a
/// POSITION index without checking it, and panicked.
#[test]
fn a_position_naming_no_accessor_is_an_error_not_a_panic() {
    let mut doc = one_mesh(json!({"attributes": {"POSITION": 3}}), json!({"mesh": 0}));
    doc["asset"] = json!({"version": "2.0"});
    let e = error_of(&glb(&doc, &[]));
    assert_eq!(e.code(), "invalid_gltf", "{e}");
    assert!(e.to_string().contains("POSITION"), "{e}");
    let e = open_glb(&glb(&doc, &[])).map(|_| ()).expect_err("invalid");
    assert_eq!(e.code(), "invalid_gltf");
}

#[test]
fn a_zero_quaternion_is_named_as_such() {
    let mut b = Builder::default();
    let pos = b.positions(&QUAD[..3]);
    let e = error_of(&b.glb(one_mesh(
        json!({"attributes": {"POSITION": pos}}),
        json!({"mesh": 0, "rotation": [0.0, 0.0, 0.0, 0.0]}),
    )));
    let e = e.to_string();
    assert!(
        e.starts_with(
            "nodes[0].rotation: is the zero quaternion [0.0, 0.0, 0.0, 0.0], not a rotation"
        ),
        "{e}"
    );
    assert!(!e.contains("non-finite"), "{e}");
}

/// The old path of `parse_root`: every document through a `Value`, the version checked there.
fn root_through_a_value(bytes: &[u8]) -> Result<Root, GlbError> {
    let mut warnings = Vec::new();
    let chunks = container::split(bytes, &mut warnings)?;
    let end = chunks
        .json
        .iter()
        .rposition(|b| !matches!(b, b' ' | b'\t' | b'\r' | b'\n' | 0))
        .map_or(0, |i| i + 1);
    let value: Value = serde_json::from_slice(&chunks.json[..end]).map_err(|e| GlbError::Json {
        problem: e.to_string(),
    })?;
    serde_json::from_value(value).map_err(|e| GlbError::Json {
        problem: e.to_string(),
    })
}

/// `parse_root` reads a glTF 2.0 document straight into its types: the same root as through a
/// `Value`, for real files of other tools (../shared/realdata: Khronos samples, Draco,
/// meshopt, textures, vertex colours, a hierarchy) and the rich fixture; a repeated key, which
/// the typed read refuses, still reads as before (its last value); other versions are still
/// named. Control: a document the typed read takes but whose root differs (another
/// generator) is told apart by the comparison.
#[test]
fn the_document_is_read_the_same_straight_or_through_a_value() {
    let root_of = |bytes: &[u8]| {
        let mut warnings = Vec::new();
        let chunks = container::split(bytes, &mut warnings).expect("chunks");
        parse_root(chunks.json, &mut warnings)
    };
    let same = |bytes: &[u8], what: &str| {
        let straight = serde_json::to_value(root_of(bytes).expect(what)).expect("json");
        let through = serde_json::to_value(root_through_a_value(bytes).expect(what)).expect("json");
        assert_eq!(straight, through, "{what}");
        straight
    };
    for name in [
        "2CylinderEngine.glb",
        "AlphaBlendModeTest.glb",
        "Box.glb",
        "BoxBadNormals.glb",
        "BoxInterleaved.glb",
        "BoxMeshopt.glb",
        "BoxTextured.glb",
        "BoxVertexColors.glb",
        "Box_Draco.glb",
        "CesiumMilkTruck.glb",
        "CornellBox.glb",
        "Cubes.glb",
        "Duck.glb",
        "Faces.glb",
        "Fox.glb",
        "GolfBall.glb",
        "ShapeCollection.glb",
        "box-textured-binary-separate.glb",
        "cakeBirthday.glb",
        "empty_nodes.glb",
        "laptop_blender16.glb",
        "laptop_blender_draco.glb",
        "monkey.glb",
        "mug_tinkercad.glb",
        "nested.glb",
        "quad_skin.glb",
        "table_tinkercad.glb",
    ] {
        same(&crate::shared_glb(name), name);
    }

    let rich = same(&rich_fixture(), "rich fixture");
    // A repeated key: the last value, as through a Value.
    let repeated = br#"{"asset": {"version": "2.0", "generator": "a", "generator": "b"}}"#;
    assert!(serde_json::from_slice::<Root>(repeated).is_err());
    let doubled = {
        // The JSON chunk holding the text as written, key repeated, padded to 4 bytes.
        let mut json = repeated.to_vec();
        while json.len() % 4 != 0 {
            json.push(b' ');
        }
        let mut out = Vec::new();
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(12 + 8 + json.len() as u32).to_le_bytes());
        out.extend_from_slice(&(json.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&json);
        out
    };
    let root = same(&doubled, "a repeated key");
    assert_eq!(root["asset"]["generator"], "b");
    // Other versions.
    let error = |document: Value| root_of(&glb(&document, &[])).expect_err("refused");
    assert_eq!(error(json!({"asset": {"version": "1.0"}})), GlbError::Gltf1);
    assert_eq!(
        error(json!({"asset": {"version": "3.0"}})).code(),
        "version"
    );
    assert_eq!(
        error(json!({"asset": {"version": "2.0", "minVersion": "2.1"}})).code(),
        "version"
    );
    // Control.
    let mut other = rich.clone();
    other["asset"]["generator"] = json!("another");
    assert_ne!(
        serde_json::to_value(root_of(&glb(&other, &[])).expect("reads")).expect("json"),
        rich
    );
}
