//! The GLB reader on every file of `realdata/glb/` (see `realdata/SOURCES.md` part B): each is
//! read or rejected with a precise reason, as a table says; the Khronos validator's test files
//! are rejected exactly when the validator reports an error, with one of its codes; geometry is
//! cross-checked against the `gltf` crate's own importer, and the Draco box against its
//! uncompressed twin.
//!
//! Files are read from `$MESA_SHARED/realdata/glb` (default `../../shared` from this crate).

use std::collections::BTreeMap;
use std::path::PathBuf;

use mesa_stages::glb_read::{read_glb, GlbMesh};
use serde_json::Value;

fn glb_dir() -> PathBuf {
    let shared = std::env::var_os("MESA_SHARED")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared"));
    let dir = shared.join("realdata/glb");
    assert!(
        dir.is_dir(),
        "{} is missing (../shared beside the repository, or MESA_SHARED)",
        dir.display()
    );
    dir
}

fn files_in(dir: &std::path::Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .expect("list")
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".glb"))
        .collect();
    names.sort();
    names
}

/// What the reader must make of a file.
#[derive(Debug)]
enum Verdict {
    /// Read: the number of triangles placed, and whether Draco / skinning were involved.
    Read {
        triangles: usize,
        draco: bool,
        skinned: bool,
    },
    /// Rejected with this code, the message containing this text.
    Rejected {
        code: &'static str,
        says: &'static str,
    },
}

fn read(triangles: usize) -> Verdict {
    Verdict::Read {
        triangles,
        draco: false,
        skinned: false,
    }
}

fn expected() -> BTreeMap<&'static str, Verdict> {
    use Verdict::*;
    BTreeMap::from([
        ("2CylinderEngine.glb", read(121_496)),
        ("AlphaBlendModeTest.glb", read(61)),
        ("Box.glb", read(12)),
        ("BoxBadNormals.glb", read(12)),
        ("BoxInterleaved.glb", read(12)),
        (
            "BoxMeshopt.glb",
            Rejected {
                code: "unsupported_extension",
                says: "EXT_meshopt_compression, which mesa does not read (fix: decompress it",
            },
        ),
        ("BoxTextured.glb", read(12)),
        ("BoxVertexColors.glb", read(12)),
        (
            "Box_Draco.glb",
            Read {
                triangles: 12,
                draco: true,
                skinned: false,
            },
        ),
        ("CesiumMilkTruck.glb", read(3_624)),
        ("CornellBox.glb", read(36)),
        // KHR_lights_punctual is required, and does not change the geometry.
        ("Cubes.glb", read(36)),
        ("Duck.glb", read(4_212)),
        ("Faces.glb", read(2_077)),
        (
            "Fox.glb",
            Read {
                triangles: 576,
                draco: false,
                skinned: true,
            },
        ),
        ("GolfBall.glb", read(356)),
        ("ShapeCollection.glb", read(3_542)),
        (
            "box-textured-binary-separate.glb",
            Rejected {
                code: "external_uri",
                says: "images[0] refers to the external file \"cesium.png\": the asset is not \
                       self-contained",
            },
        ),
        (
            "box-textured-binary_gltf1.glb",
            Rejected {
                code: "GLB_INVALID_VERSION",
                says: "GLB_INVALID_VERSION at byte 4: GLB version 1 is glTF 1.0 \
                       (KHR_binary_glTF): mesa reads glTF 2.0 (fix: convert it with gltf-pipeline",
            },
        ),
        ("cakeBirthday.glb", read(1_332)),
        (
            "empty_nodes.glb",
            Rejected {
                code: "no_mesh",
                says: "no triangle mesh: the file has no mesh",
            },
        ),
        ("laptop_blender16.glb", read(1_632)),
        (
            "laptop_blender_draco.glb",
            Read {
                triangles: 89_011,
                draco: true,
                skinned: false,
            },
        ),
        ("monkey.glb", read(968)),
        ("mug_tinkercad.glb", read(1_144)),
        ("nested.glb", read(36)),
        (
            "quad_skin.glb",
            Read {
                triangles: 2,
                draco: false,
                skinned: true,
            },
        ),
        ("table_tinkercad.glb", read(4_234)),
    ])
}

#[test]
fn every_glb_is_read_or_rejected_as_the_table_says() {
    let dir = glb_dir();
    let table = expected();
    let present = files_in(&dir);
    let listed: Vec<String> = table.keys().map(|k| (*k).to_owned()).collect();
    assert_eq!(
        present, listed,
        "the table must list exactly the files present"
    );
    for (name, verdict) in &table {
        let bytes = std::fs::read(dir.join(name)).expect("read");
        match (read_glb(&bytes), verdict) {
            (
                Ok(mesh),
                Verdict::Read {
                    triangles,
                    draco,
                    skinned,
                },
            ) => {
                assert_eq!(mesh.triangles.len(), *triangles, "{name}");
                assert_eq!(mesh.info.draco, *draco, "{name}");
                assert_eq!(mesh.info.skinned, *skinned, "{name}");
                assert!(
                    mesh.positions_m.iter().flatten().all(|v| v.is_finite()),
                    "{name}"
                );
                let n = mesh.positions_m.len() as u32;
                assert!(mesh.triangles.iter().flatten().all(|i| *i < n), "{name}");
            }
            (Err(e), Verdict::Rejected { code, says }) => {
                assert_eq!(e.code(), *code, "{name}: {e}");
                assert!(e.to_string().contains(says), "{name}: {e}");
            }
            (Ok(mesh), Verdict::Rejected { code, .. }) => panic!(
                "{name}: read {} triangles, expected a rejection ({code})",
                mesh.triangles.len()
            ),
            (Err(e), Verdict::Read { .. }) => panic!("{name}: rejected: {e}"),
        }
    }
}

/// The Khronos glTF-Validator's test files: the reader rejects a file for a container or
/// document problem exactly when the validator reports an error, and says which (one of the
/// validator's error codes is in the message). Files the validator finds valid hold no mesh,
/// so they are rejected for that and nothing else.
#[test]
fn the_validator_test_files_are_judged_as_the_validator_does() {
    let dir = glb_dir().join("validator");
    let names = files_in(&dir);
    assert_eq!(names.len(), 25, "{names:?}");
    for name in names {
        let bytes = std::fs::read(dir.join(&name)).expect("read");
        let report: Value = serde_json::from_slice(
            &std::fs::read(dir.join(format!("{name}.report.json"))).expect("report"),
        )
        .expect("report json");
        let errors: Vec<&str> = report["issues"]["messages"]
            .as_array()
            .expect("messages")
            .iter()
            .filter(|m| m["severity"] == 0)
            .filter_map(|m| m["code"].as_str())
            .collect();
        let e = match read_glb(&bytes) {
            Ok(mesh) => panic!("{name}: read {} triangles", mesh.triangles.len()),
            Err(e) => e,
        };
        if errors.is_empty() {
            assert_eq!(e.code(), "no_mesh", "{name}: {e}");
        } else if errors.iter().any(|code| code.starts_with("GLB_")) {
            // A container problem: the code itself is one of the validator's.
            assert!(
                errors.contains(&e.code()),
                "{name}: code {} is none of the validator's errors {errors:?} ({e})",
                e.code()
            );
            assert!(e.to_string().contains(e.code()), "{name}: {e}");
        } else {
            let message = e.to_string();
            assert!(
                errors.iter().any(|code| message.contains(code)),
                "{name}: \"{message}\" names none of the validator's errors {errors:?}"
            );
        }
    }
}

fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("workspace root")
        .to_path_buf()
}

/// A GLB of `chunks` (length, type, bytes); `total` overrides the declared length.
fn crafted_glb(version: u32, total: Option<usize>, chunks: &[(usize, u32, &[u8])]) -> Vec<u8> {
    let mut body = Vec::new();
    for (length, kind, data) in chunks {
        body.extend_from_slice(&(*length as u32).to_le_bytes());
        body.extend_from_slice(&kind.to_le_bytes());
        body.extend_from_slice(data);
    }
    let mut out = b"glTF".to_vec();
    out.extend_from_slice(&version.to_le_bytes());
    out.extend_from_slice(&(total.unwrap_or(12 + body.len()) as u32).to_le_bytes());
    out.extend_from_slice(&body);
    out
}

/// Container damage the validator's own corpus does not hold (an unaligned chunk, a misplaced
/// BIN chunk, a bad version, a chunk too big, truncations at each place), crafted here: the
/// reader's code is the first error the Khronos validator reports, as this table says; with
/// node and `gltf-validator` installed the table itself is checked against the validator
/// (skipped without them, a failure under MESA_REQUIRE_TOOLS).
#[test]
fn crafted_container_damage_gets_the_validators_codes() {
    const JSON: u32 = 0x4E4F_534A;
    const BIN: u32 = 0x004E_4942;
    const OTHER: u32 = 0x1234_5678;
    let json: &[u8] = br#"{"asset":{"version":"2.0"}}"#;
    let mut padded = json.to_vec();
    padded.resize(json.len().div_ceil(4) * 4, b' ');
    let j = padded.as_slice();
    let n = j.len();
    let bin: &[u8] = &[0u8; 64];
    let whole = crafted_glb(2, None, &[(n, JSON, j), (64, BIN, bin)]);
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        // Controls: the same files without a defect are read up to the missing mesh.
        ("valid", crafted_glb(2, None, &[(n, JSON, j)]), "no_mesh"),
        ("valid_bin", whole.clone(), "no_mesh"),
        (
            "unaligned_json",
            crafted_glb(2, None, &[(n + 1, JSON, &[j, b" "].concat())]),
            "GLB_CHUNK_LENGTH_UNALIGNED",
        ),
        (
            "unaligned_bin",
            crafted_glb(2, None, &[(n, JSON, j), (3, BIN, b"abc")]),
            "GLB_CHUNK_LENGTH_UNALIGNED",
        ),
        (
            "bin_third",
            crafted_glb(
                2,
                None,
                &[(n, JSON, j), (4, OTHER, b"xxxx"), (4, BIN, b"abcd")],
            ),
            "GLB_UNEXPECTED_BIN_CHUNK",
        ),
        (
            "version_1",
            crafted_glb(1, None, &[(n, JSON, j)]),
            "GLB_INVALID_VERSION",
        ),
        (
            "version_3",
            crafted_glb(3, None, &[(n, JSON, j)]),
            "GLB_INVALID_VERSION",
        ),
        (
            "chunk_too_big",
            crafted_glb(2, None, &[(n + 8, JSON, j)]),
            "GLB_CHUNK_TOO_BIG",
        ),
        (
            "declared_too_short",
            crafted_glb(2, Some(16), &[(n, JSON, j)]),
            "GLB_CHUNK_TOO_BIG",
        ),
        (
            "cut_in_bin_data",
            whole[..whole.len() - 10].to_vec(),
            "GLB_UNEXPECTED_END_OF_CHUNK_DATA",
        ),
        (
            "cut_in_bin_header",
            whole[..12 + 8 + n + 4].to_vec(),
            "GLB_UNEXPECTED_END_OF_CHUNK_HEADER",
        ),
        (
            "cut_before_bin",
            whole[..12 + 8 + n].to_vec(),
            "GLB_LENGTH_MISMATCH",
        ),
        (
            "unknown_first",
            crafted_glb(2, None, &[(4, OTHER, b"xxxx"), (n, JSON, j)]),
            "GLB_UNEXPECTED_FIRST_CHUNK",
        ),
    ];
    for (name, bytes, expected) in &cases {
        let e = read_glb(bytes).expect_err(name);
        assert_eq!(e.code(), *expected, "{name}: {e}");
        if expected.starts_with("GLB_") {
            let message = e.to_string();
            assert!(message.contains(expected), "{name}: {message}");
            assert!(message.contains("(fix: "), "{name}: {message}");
        }
    }

    let node_ok = std::process::Command::new("node")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !node_ok
        || !repo_root()
            .join("scripts/node_modules/gltf-validator")
            .is_dir()
    {
        let how = "needs node and scripts/node_modules/gltf-validator: run `npm ci` in scripts/";
        assert!(
            std::env::var_os("MESA_REQUIRE_TOOLS").is_none(),
            "glTF validator missing ({how})"
        );
        eprintln!("SKIPPED: the crafted container files against the glTF validator ({how})");
        return;
    }
    let tmp = tempfile::tempdir().expect("tempdir");
    let files: Vec<PathBuf> = cases
        .iter()
        .map(|(name, bytes, _)| {
            let path = tmp.path().join(format!("{name}.glb"));
            std::fs::write(&path, bytes).expect("write");
            path
        })
        .collect();
    let out = std::process::Command::new("node")
        .arg(repo_root().join("scripts/validate_glb.cjs"))
        .args(&files)
        .output()
        .expect("node runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let lines: Vec<Value> = stdout
        .lines()
        .map(|l| serde_json::from_str(l).expect("a JSON line"))
        .collect();
    assert_eq!(lines.len(), cases.len(), "{stdout}");
    for ((name, _, expected), line) in cases.iter().zip(&lines) {
        let first_error = line["messages"]
            .as_array()
            .expect("messages")
            .iter()
            .filter_map(Value::as_str)
            .map(|m| m.split(' ').next().unwrap_or(""))
            // The script lists errors and warnings alike; these are the validator's GLB
            // warnings and infos (its ISSUES.md).
            .filter(|code| {
                !matches!(
                    *code,
                    "GLB_UNKNOWN_CHUNK_TYPE" | "GLB_EXTRA_DATA" | "GLB_EMPTY_BIN_CHUNK"
                )
            })
            .find(|code| code.starts_with("GLB_"));
        match first_error {
            // The validator finds these valid (with warnings); mesa then wants a mesh.
            None => assert_eq!(*expected, "no_mesh", "{name}: {line}"),
            Some(code) => assert_eq!(code, *expected, "{name}: {line}"),
        }
    }
}

fn bounds(positions: impl Iterator<Item = [f64; 3]>) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in positions {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, hi)
}

/// World-space vertices of a file's default scene as the `gltf` crate imports them (skins
/// excluded: the crate does not pose them).
fn gltf_crate_vertices(bytes: &[u8]) -> (Vec<[f64; 3]>, usize) {
    let (document, buffers, _) = gltf::import_slice(bytes).expect("the gltf crate imports it");
    let scene = document
        .default_scene()
        .or_else(|| document.scenes().next())
        .expect("a scene");
    let mut vertices = Vec::new();
    let mut triangles = 0;
    let mut stack: Vec<(gltf::Node, nalgebra::Matrix4<f64>)> = scene
        .nodes()
        .map(|n| (n, nalgebra::Matrix4::identity()))
        .collect();
    while let Some((node, parent)) = stack.pop() {
        let local = node.transform().matrix();
        let local = nalgebra::Matrix4::from_fn(|r, c| f64::from(local[c][r]));
        let world = parent * local;
        if let Some(mesh) = node.mesh() {
            for primitive in mesh.primitives() {
                if primitive.mode() != gltf::mesh::Mode::Triangles {
                    continue;
                }
                let reader = primitive.reader(|b| Some(&buffers[b.index()]));
                let positions: Vec<[f32; 3]> =
                    reader.read_positions().expect("positions").collect();
                triangles += match reader.read_indices() {
                    Some(indices) => indices.into_u32().count() / 3,
                    None => positions.len() / 3,
                };
                for p in positions {
                    let v = world
                        * nalgebra::Vector4::new(
                            f64::from(p[0]),
                            f64::from(p[1]),
                            f64::from(p[2]),
                            1.0,
                        );
                    vertices.push([v[0], v[1], v[2]]);
                }
            }
        }
        for child in node.children() {
            stack.push((child, world));
        }
    }
    (vertices, triangles)
}

#[test]
fn geometry_matches_the_gltf_crates_importer() {
    let dir = glb_dir();
    for name in [
        "2CylinderEngine.glb",
        "AlphaBlendModeTest.glb",
        "Box.glb",
        "BoxInterleaved.glb",
        "BoxTextured.glb",
        "BoxVertexColors.glb",
        "CesiumMilkTruck.glb",
        "CornellBox.glb",
        "Duck.glb",
        "Faces.glb",
        "GolfBall.glb",
        "ShapeCollection.glb",
        "cakeBirthday.glb",
        "laptop_blender16.glb",
        "monkey.glb",
        "mug_tinkercad.glb",
        "nested.glb",
        "table_tinkercad.glb",
    ] {
        let bytes = std::fs::read(dir.join(name)).expect("read");
        let ours: GlbMesh = read_glb(&bytes).expect("reads");
        let (theirs, triangles) = gltf_crate_vertices(&bytes);
        assert_eq!(ours.positions_m.len(), theirs.len(), "{name}: vertices");
        assert_eq!(ours.triangles.len(), triangles, "{name}: triangles");
        let (lo, hi) = bounds(ours.positions_m.iter().copied());
        let (tlo, thi) = bounds(theirs.into_iter());
        for k in 0..3 {
            let tolerance = 1e-6 * (1.0 + thi[k].abs().max(tlo[k].abs()));
            assert!(
                (lo[k] - tlo[k]).abs() <= tolerance,
                "{name}: min {lo:?} vs {tlo:?}"
            );
            assert!(
                (hi[k] - thi[k]).abs() <= tolerance,
                "{name}: max {hi:?} vs {thi:?}"
            );
        }
    }
}

/// `Box_Draco.glb` is the Khronos box of `Box.glb` compressed by Google's encoder: the decoded
/// triangles are the box's triangles, corner for corner.
#[test]
fn the_draco_box_is_its_uncompressed_twin() {
    let dir = glb_dir();
    let soup = |mesh: &GlbMesh| {
        let mut triangles: Vec<Vec<[i64; 3]>> = mesh
            .triangles
            .iter()
            .map(|t| {
                let corners: Vec<[i64; 3]> = t
                    .iter()
                    .map(|i| mesh.positions_m[*i as usize].map(|v| (v * 1e6).round() as i64))
                    .collect();
                let first = (0..3).min_by_key(|r| corners[*r]).unwrap_or(0);
                (0..3).map(|r| corners[(first + r) % 3]).collect()
            })
            .collect();
        triangles.sort();
        triangles
    };
    let plain = read_glb(&std::fs::read(dir.join("Box.glb")).expect("read")).expect("Box.glb");
    let draco =
        read_glb(&std::fs::read(dir.join("Box_Draco.glb")).expect("read")).expect("Box_Draco.glb");
    assert_eq!(soup(&plain), soup(&draco));
}
