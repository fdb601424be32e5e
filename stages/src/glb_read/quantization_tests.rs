//! `KHR_mesh_quantization`, with and without `KHR_draco_mesh_compression`, on files made by
//! the tools that write them: a pack GLB mesa writes and a Blender export, quantized by
//! gltf-transform (`quantize`, then `draco`), read back and compared vertex by vertex with the
//! unquantized source, within the quantization step. Non-normalized integers are the same files
//! with `normalized: false` and the 1 / (2^(n-1) - 1) factor moved into the node's scale.
//!
//! gltf-transform is `scripts/node_modules/.bin/gltf-transform` (`npm ci` in scripts/), Blender
//! `MESA_BLENDER_PYTHON`; without them the tests say SKIPPED, and fail when
//! `MESA_REQUIRE_TOOLS` is set, as in CI.

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::json;

use super::*;
use crate::pack::testing::{edit_glb, fixture, pack};
use crate::pack::PackConfig;

fn require_tools() -> bool {
    std::env::var_os("MESA_REQUIRE_TOOLS").is_some()
}

fn gltf_transform() -> Option<PathBuf> {
    let tool =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/node_modules/.bin/gltf-transform");
    let works = Command::new(&tool)
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !works {
        let how =
            "needs node and scripts/node_modules/.bin/gltf-transform: run `npm ci` in scripts/";
        assert!(!require_tools(), "gltf-transform missing ({how})");
        eprintln!("SKIPPED: KHR_mesh_quantization files made by gltf-transform ({how})");
        return None;
    }
    Some(tool)
}

/// Runs `gltf-transform <args...>`.
fn run_tool(tool: &Path, args: &[&str]) {
    let out = Command::new(tool)
        .args(args)
        .output()
        .expect("gltf-transform runs");
    assert!(
        out.status.success(),
        "gltf-transform {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// One vertex as a viewer places it.
#[derive(Debug, Clone, Copy)]
struct Vertex {
    position: [f64; 3],
    normal: Option<[f64; 3]>,
    uv: Option<[f64; 2]>,
}

fn vertices(bytes: &[u8]) -> (Vec<Vertex>, usize) {
    let document = open_glb(bytes).expect("opens");
    let scene = document.placed_primitives(true).expect("reads");
    let mut out = Vec::new();
    let mut triangles = 0;
    for p in &scene.primitives {
        triangles += p.triangles.len();
        for (k, position) in p.positions_m.iter().enumerate() {
            out.push(Vertex {
                position: *position,
                normal: p.normals.as_ref().map(|n| n[k]),
                uv: p.uvs.as_ref().map(|u| u[k]),
            });
        }
    }
    (out, triangles)
}

/// The largest extent of any placed primitive's box, metres: the span a quantization grid
/// of gltf-transform's "mesh" volume covers at most.
fn largest_extent_m(bytes: &[u8]) -> f64 {
    let document = open_glb(bytes).expect("opens");
    let scene = document.placed_primitives(false).expect("reads");
    scene
        .primitives
        .iter()
        .map(|p| {
            (0..3)
                .map(|c| {
                    let lo = p
                        .positions_m
                        .iter()
                        .map(|v| v[c])
                        .fold(f64::INFINITY, f64::min);
                    let hi = p
                        .positions_m
                        .iter()
                        .map(|v| v[c])
                        .fold(f64::NEG_INFINITY, f64::max);
                    hi - lo
                })
                .fold(0.0, f64::max)
        })
        .fold(0.0, f64::max)
}

/// The worst errors of `decoded` against `source`: every decoded vertex has a source vertex
/// within `position_tol_m` whose normal and texture coordinates match; returns the worst
/// position (m), normal (degrees) and uv errors over the best matches.
fn compare(source: &[Vertex], decoded: &[Vertex], position_tol_m: f64) -> (f64, f64, f64) {
    let (mut worst_position, mut worst_normal, mut worst_uv) = (0.0f64, 0.0f64, 0.0f64);
    // Source vertices sorted by x: the candidates of a vertex are a window of that order.
    let mut by_x: Vec<&Vertex> = source.iter().collect();
    by_x.sort_by(|a, b| a.position[0].total_cmp(&b.position[0]));
    for (i, d) in decoded.iter().enumerate() {
        let mut best: Option<(f64, f64, f64)> = None;
        let start = by_x.partition_point(|s| s.position[0] < d.position[0] - position_tol_m);
        let end = by_x.partition_point(|s| s.position[0] <= d.position[0] + position_tol_m);
        for s in &by_x[start..end] {
            let dp = (0..3)
                .map(|c| (d.position[c] - s.position[c]).abs())
                .fold(0.0, f64::max);
            if dp > position_tol_m {
                continue;
            }
            let dn = match (d.normal, s.normal) {
                (Some(a), Some(b)) => {
                    let dot: f64 = (0..3).map(|c| a[c] * b[c]).sum();
                    dot.clamp(-1.0, 1.0).acos().to_degrees()
                }
                _ => 0.0,
            };
            let du = match (d.uv, s.uv) {
                (Some(a), Some(b)) => (a[0] - b[0]).abs().max((a[1] - b[1]).abs()),
                _ => 0.0,
            };
            let score = dn / 180.0 + du;
            if best.is_none_or(|(bp, bn, bu)| {
                score < bn / 180.0 + bu || (score == bn / 180.0 + bu && dp < bp)
            }) {
                best = Some((dp, dn, du));
            }
        }
        let (dp, dn, du) = best.unwrap_or_else(|| {
            panic!(
                "decoded vertex {i} at {:?} has no source vertex within {position_tol_m} m",
                d.position
            )
        });
        worst_position = worst_position.max(dp);
        worst_normal = worst_normal.max(dn);
        worst_uv = worst_uv.max(du);
    }
    (worst_position, worst_normal, worst_uv)
}

/// How many vertices of `decoded` have no vertex of `source` within `position_tol_m`.
fn unmatched(source: &[Vertex], decoded: &[Vertex], position_tol_m: f64) -> usize {
    decoded
        .iter()
        .filter(|d| {
            !source
                .iter()
                .any(|s| (0..3).all(|c| (d.position[c] - s.position[c]).abs() <= position_tol_m))
        })
        .count()
}

/// The accessor formats of a file's POSITION, NORMAL and TEXCOORD_0, as
/// `POSITION:SHORT/normalized` strings, sorted and deduplicated.
fn formats(bytes: &[u8]) -> Vec<String> {
    let document = open_glb(bytes).expect("opens");
    let root = document.root();
    let mut out: Vec<String> = root
        .meshes
        .iter()
        .flat_map(|m| &m.primitives)
        .flat_map(|p| &p.attributes)
        .filter_map(|(semantic, index)| {
            let name = semantic.to_string();
            if !["POSITION", "NORMAL", "TEXCOORD_0"].contains(&name.as_str()) {
                return None;
            }
            let accessor = &root.accessors[index.value()];
            let Checked::Valid(kind) = accessor.component_type else {
                return None;
            };
            Some(format!(
                "{name}:{}",
                format_name(kind.0, accessor.normalized)
            ))
        })
        .collect();
    out.sort();
    out.dedup();
    out
}

/// The same file with normalized integer POSITION accessors made non-normalized: each node
/// placing such a mesh (and holding no children, which the factor would scale too) gets the
/// 1 / (2^(n-1) - 1) factor in its scale, so a viewer places the same vertices. Meshes placed
/// by a node with children, or by no node, are left as they are. Without `move_factor` the
/// nodes keep their scale (a reader that ignored `normalized` would see that file). Returns the
/// file and how many accessors changed.
fn denormalized(bytes: &[u8], move_factor: bool) -> (Vec<u8>, usize) {
    let mut changed = 0;
    let out = edit_glb(bytes, |j, _| {
        let nodes = j["nodes"].as_array().cloned().unwrap_or_default();
        let meshes = j["meshes"].as_array().cloned().unwrap_or_default();
        for (m, mesh) in meshes.iter().enumerate() {
            let placing: Vec<usize> = nodes
                .iter()
                .enumerate()
                .filter(|(_, n)| n["mesh"].as_u64() == Some(m as u64))
                .map(|(k, _)| k)
                .collect();
            if placing.is_empty()
                || placing.iter().any(|k| {
                    nodes[*k].get("children").is_some() || nodes[*k].get("matrix").is_some()
                })
            {
                continue;
            }
            let positions: Vec<u64> = mesh["primitives"]
                .as_array()
                .into_iter()
                .flatten()
                .filter_map(|p| p["attributes"]["POSITION"].as_u64())
                .collect();
            let factors: Vec<f64> = positions
                .iter()
                .map(|a| {
                    let accessor = &j["accessors"][*a as usize];
                    match (
                        accessor["componentType"].as_u64(),
                        accessor["normalized"].as_bool(),
                    ) {
                        (Some(5122), Some(true)) => 1.0 / 32767.0,
                        (Some(5120), Some(true)) => 1.0 / 127.0,
                        _ => 0.0,
                    }
                })
                .collect();
            // Every primitive of the mesh must share the factor: it goes into the node.
            let Some(&factor) = factors.first() else {
                continue;
            };
            if factor == 0.0 || factors.iter().any(|f| *f != factor) {
                continue;
            }
            for a in &positions {
                let accessor = &mut j["accessors"][*a as usize];
                accessor["normalized"] = json!(false);
                // min and max are in the accessor's own units.
                for bound in ["min", "max"] {
                    if let Some(values) = accessor[bound].as_array() {
                        let scaled: Vec<f64> = values
                            .iter()
                            .map(|v| (v.as_f64().unwrap_or(0.0) / factor).round())
                            .collect();
                        accessor[bound] = json!(scaled);
                    }
                }
                changed += 1;
            }
            for k in placing.iter().filter(|_| move_factor) {
                let node = &mut j["nodes"][*k];
                let scale: Vec<f64> = node["scale"]
                    .as_array()
                    .map(|s| s.iter().map(|v| v.as_f64().unwrap_or(1.0)).collect())
                    .unwrap_or_else(|| vec![1.0; 3]);
                node["scale"] = json!(scale.iter().map(|s| s * factor).collect::<Vec<f64>>());
            }
        }
    });
    (out, changed)
}

/// Quantizes `source` with gltf-transform at `bits` (positions, normals, texture coordinates),
/// then Draco-compresses it; reads the source, both results and their non-normalized twins,
/// and checks every vertex against the source within the quantization step. Returns the lines
/// of what was measured.
fn check_quantized(tool: &Path, dir: &Path, name: &str, source: &[u8], bits: u32) -> Vec<String> {
    let src = dir.join(format!("{name}.glb"));
    std::fs::write(&src, source).expect("write");
    let quantized = dir.join(format!("{name}_q{bits}.glb"));
    let draco = dir.join(format!("{name}_q{bits}_draco.glb"));
    let b = bits.to_string();
    run_tool(
        tool,
        &[
            "quantize",
            src.to_str().expect("utf-8"),
            quantized.to_str().expect("utf-8"),
            "--quantize-position",
            &b,
            "--quantize-normal",
            &b,
            "--quantize-texcoord",
            &b,
        ],
    );
    run_tool(
        tool,
        &[
            "draco",
            quantized.to_str().expect("utf-8"),
            draco.to_str().expect("utf-8"),
        ],
    );
    let (source_vertices, source_triangles) = vertices(source);
    // The grid spans a mesh's box with 2^bits - 1 steps; the error is at most one step of
    // the largest mesh (half a step of rounding, and Draco's own prediction is lossless on
    // integers).
    let step_m = largest_extent_m(source) / f64::from((1u32 << bits) - 2);
    let uv_step = 1.0 / f64::from((1u32 << bits) - 1);
    let mut lines = Vec::new();
    let q = std::fs::read(&quantized).expect("quantized");
    let d = std::fs::read(&draco).expect("draco");
    let (dn, changed) = denormalized(&d, true);
    let (qn, changed_plain) = denormalized(&q, true);
    assert!(
        changed > 0 && changed_plain > 0,
        "{name}: no accessor to denormalize"
    );
    // Control: the comparison fails a file read without its dequantization (the integers
    // taken as they are, the factor left out).
    let (wrong, _) = denormalized(&d, false);
    let (wrong_vertices, _) = vertices(&wrong);
    assert!(
        unmatched(&source_vertices, &wrong_vertices, step_m) > 0,
        "{name}: the control file should not match"
    );
    for (label, bytes) in [
        ("quantized", &q),
        ("quantized+draco", &d),
        ("quantized, not normalized", &qn),
        ("quantized+draco, not normalized", &dn),
    ] {
        let document = open_glb(bytes).expect("opens");
        assert!(
            document
                .root()
                .extensions_used
                .iter()
                .any(|e| e == "KHR_mesh_quantization"),
            "{name} {label}: gltf-transform wrote no KHR_mesh_quantization"
        );
        let draco_used = document
            .root()
            .extensions_used
            .iter()
            .any(|e| e == "KHR_draco_mesh_compression");
        assert_eq!(draco_used, label.contains("draco"), "{name} {label}");
        let (decoded, triangles) = vertices(bytes);
        assert_eq!(triangles, source_triangles, "{name} {label}: triangles");
        let (position, normal, uv) = compare(&source_vertices, &decoded, step_m);
        // And the other way round: no source vertex is lost.
        let (back, _, _) = compare(&decoded, &source_vertices, step_m);
        assert!(position <= step_m && back <= step_m, "{name} {label}");
        // n-bit normals: the angle between two neighbouring codes, with margin.
        let normal_tol_deg = (2.0 / f64::from((1u32 << (bits - 1)) - 1)).to_degrees() * 2.0;
        assert!(
            normal <= normal_tol_deg,
            "{name} {label}: normal {normal}° > {normal_tol_deg}°"
        );
        assert!(uv <= uv_step, "{name} {label}: uv {uv} > {uv_step}");
        lines.push(format!(
            "{name} {bits}-bit {label} ({}): {} vertices, worst position {:.3} mm (step {:.3} \
             mm), normal {normal:.3}°, uv {uv:.5} (step {uv_step:.5})",
            formats(bytes).join(", "),
            decoded.len(),
            position * 1000.0,
            step_m * 1000.0
        ));
    }
    lines
}

/// Before this reader, a valid Draco GLB with KHR_mesh_quantization failed with "POSITION
/// decodes to 3 components of I16 (expected 3 floats)".
#[test]
fn khr_mesh_quantization_from_gltf_transform_reads_within_the_step_with_and_without_draco() {
    let Some(tool) = gltf_transform() else {
        return;
    };
    let dir = tempfile::tempdir().expect("tempdir");
    let source = pack(&fixture(), &PackConfig::default()).files["office_table_0001.glb"].clone();
    let mut lines = Vec::new();
    for bits in [14, 8] {
        lines.extend(check_quantized(&tool, dir.path(), "pack", &source, bits));
    }
    for line in &lines {
        eprintln!("{line}");
    }
    // The formats the files hold: 16-bit and 8-bit, normalized and not.
    let all = lines.join("\n");
    for expected in [
        "POSITION:normalized SHORT",
        "POSITION:SHORT",
        "POSITION:normalized BYTE",
        "POSITION:BYTE",
        "NORMAL:normalized SHORT",
        "NORMAL:normalized BYTE",
        "TEXCOORD_0:normalized UNSIGNED_SHORT",
        "TEXCOORD_0:normalized UNSIGNED_BYTE",
    ] {
        assert!(all.contains(expected), "{expected}:\n{all}");
    }
}

/// A Blender export (bpy 4.3: a sphere scaled and turned, a cube), quantized and
/// Draco-compressed by gltf-transform, read within the step. (The bpy wheel has no Draco
/// library, and Blender writes KHR_mesh_quantization only through gltfpack, so the quantized
/// files are gltf-transform's; Blender's own Draco output is tested on
/// `realdata/glb/laptop_blender_draco.glb`.)
#[test]
fn a_blender_export_quantized_and_draco_compressed_reads_within_the_step() {
    let python = ["MESA_BLENDER_PYTHON", "MESA_PYTHON"]
        .iter()
        .find_map(|var| {
            let python = PathBuf::from(std::env::var_os(var)?);
            Command::new(&python)
                .args(["-c", "import bpy"])
                .output()
                .is_ok_and(|o| o.status.success())
                .then_some(python)
        });
    let Some(python) = python else {
        let how = "set MESA_BLENDER_PYTHON to a Python with bpy 4.3";
        assert!(
            !require_tools(),
            "Blender is missing and MESA_REQUIRE_TOOLS is set ({how})"
        );
        eprintln!("SKIPPED: quantized Blender export ({how})");
        return;
    };
    let Some(tool) = gltf_transform() else {
        return;
    };
    let dir = tempfile::tempdir().expect("tempdir");
    let script = dir.path().join("export.py");
    let out = dir.path().join("blender.glb");
    std::fs::write(
        &script,
        r#"import sys, bpy
out = sys.argv[-1]
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16, radius=0.05, location=(0.1, 0.2, 0.05))
s = bpy.context.active_object
s.name = "mug_0"
s.scale = (1.0, 1.5, 0.8)
s.rotation_euler = (0.0, 0.0, 0.7)
bpy.ops.object.shade_smooth()
bpy.ops.mesh.primitive_cube_add(size=0.2, location=(-0.3, 0.1, 0.1))
bpy.context.active_object.name = "book_0"
bpy.ops.export_scene.gltf(filepath=out, export_format='GLB')
"#,
    )
    .expect("script");
    let result = Command::new(&python)
        .arg(&script)
        .arg("--")
        .arg(&out)
        .output()
        .expect("Blender runs");
    assert!(
        result.status.success(),
        "Blender export failed: {}",
        String::from_utf8_lossy(&result.stderr)
    );
    let source = std::fs::read(&out).expect("export");
    let generator = open_glb(&source)
        .expect("opens")
        .root()
        .asset
        .generator
        .clone()
        .unwrap_or_default();
    assert!(generator.contains("Blender"), "{generator}");
    let mut lines = Vec::new();
    for bits in [14, 8] {
        lines.extend(check_quantized(&tool, dir.path(), "blender", &source, bits));
    }
    for line in &lines {
        eprintln!("{line}");
    }
}
