//! Ingest on the pack fixture: no edits give the baseline back byte for byte; each kind of
//! edit an annotator makes is recovered; damaged and hostile files are clear errors.

use approx::assert_abs_diff_eq;
use serde_json::{json, Value};

use super::*;
use crate::pack::testing::{edit_glb, fixture, node_at, pack, Fixture};
use crate::pack::PackConfig;

struct Packed {
    fixture: Fixture,
    glb: Vec<u8>,
    index: PackIndexArtifact,
}

fn packed() -> Packed {
    let fixture = fixture();
    let out = pack(&fixture, &PackConfig::default());
    Packed {
        glb: out.files["office_table_0001.glb"].clone(),
        index: out.index,
        fixture,
    }
}

fn ingest(p: &Packed, refined: &[u8], config: &IngestConfig) -> Result<IngestOutput, IngestError> {
    ingest_scene(
        &IngestRequest {
            scene_id: "office_table_0001",
            refined_glb: refined,
            refined_rel: "refined/office_table_0001.glb",
            pack_glb: &p.glb,
            index: &p.index,
            baseline: &p.fixture.layout,
        },
        config,
    )
}

fn ok(p: &Packed, refined: &[u8]) -> IngestOutput {
    ingest(p, refined, &IngestConfig::default()).expect("ingests")
}

fn err(p: &Packed, refined: &[u8]) -> String {
    match ingest(p, refined, &IngestConfig::default()) {
        Ok(_) => panic!("expected an error"),
        Err(e) => e.to_string(),
    }
}

fn object<'a>(layout: &'a DatasetLayout, instance: &str) -> &'a LayoutObject {
    layout
        .objects
        .iter()
        .find(|o| o.instance == instance)
        .unwrap_or_else(|| panic!("no {instance}"))
}

/// Blender's rotation about its +Z (the table's up) by `deg`, applied after `q` (glTF
/// quaternions: a turn about glTF +Y).
fn turned(q: &Value, deg: f64) -> Value {
    let q: Vec<f64> = q
        .as_array()
        .map(|a| a.iter().map(|v| v.as_f64().expect("number")).collect())
        .unwrap_or_else(|| vec![0.0, 0.0, 0.0, 1.0]);
    let h = deg.to_radians() / 2.0;
    let r = [0.0, h.sin(), 0.0, h.cos()];
    let p = crate::mesh::quat_mul(r, [q[0], q[1], q[2], q[3]]);
    json!(p)
}

fn strip_extras(json: &mut Value) {
    for node in json["nodes"].as_array_mut().expect("nodes") {
        node.as_object_mut().expect("node").remove("extras");
    }
}

#[test]
fn no_edits_give_the_baseline_back_byte_for_byte() {
    let p = packed();
    let out = ok(&p, &p.glb);
    assert_eq!(out.layout, p.fixture.layout);
    assert_eq!(
        mesa_schemas::json::to_sorted_pretty(&out.layout).expect("json"),
        p.fixture.layout_bytes
    );
    assert!(out.diff.moved.is_empty() && out.diff.added.is_empty() && out.diff.removed.is_empty());
    assert!(out.diff.objects.iter().all(|o| o.status == "unchanged"));
    assert!(!out.diff.table.resized);
    assert_eq!(out.diff.h1.rescaled_by, None);
    // Without extras (Blender's default export) it is the same.
    let plain = edit_glb(&p.glb, |j, _| strip_extras(j));
    assert_eq!(ok(&p, &plain).layout, p.fixture.layout);
}

#[test]
fn moves_turns_scales_deletions_and_copies_are_recovered() {
    let p = packed();
    let refined = edit_glb(&p.glb, |j, _| {
        strip_extras(j);
        // mug_0: moved 5 cm right and 3 cm back (glTF Z = -y).
        let n = node_at(j, "mug_0");
        let t = j["nodes"][n]["translation"].clone();
        j["nodes"][n]["translation"] = json!([
            t[0].as_f64().unwrap_or(0.0) + 0.05,
            t[1],
            t[2].as_f64().unwrap_or(0.0) - 0.03
        ]);
        // book_0: turned 30° counter-clockwise seen from above.
        let n = node_at(j, "book_0");
        j["nodes"][n]["rotation"] = turned(&j["nodes"][n]["rotation"], 30.0);
        // lamp_0: scaled ×1.5 along its width only (non-uniform).
        let n = node_at(j, "lamp_0");
        let s = j["nodes"][n]
            .get("scale")
            .cloned()
            .unwrap_or(json!([1.0, 1.0, 1.0]));
        let sx = s[0].as_f64().expect("x");
        j["nodes"][n]["scale"] = json!([sx * 1.5, s[1], s[2]]);
        // pen_1 deleted (pen_10 stays: names never match by prefix).
        let n = node_at(j, "pen_1");
        j["nodes"].as_array_mut().expect("nodes").remove(n);
        let roots: Vec<Value> = j["scenes"][0]["nodes"]
            .as_array()
            .expect("roots")
            .iter()
            .filter(|r| r.as_u64() != Some(n as u64))
            .map(|r| {
                let r = r.as_u64().expect("index");
                json!(if r > n as u64 { r - 1 } else { r })
            })
            .collect();
        j["scenes"][0]["nodes"] = json!(roots);
        // mug_1 duplicated (Shift+D: `mug_1.001`), the copy moved 10 cm left.
        let n = node_at(j, "mug_1");
        let mut copy = j["nodes"][n].clone();
        copy["name"] = json!("mug_1.001");
        let t = copy["translation"].clone();
        copy["translation"] = json!([t[0].as_f64().unwrap_or(0.0) - 0.10, t[1], t[2]]);
        let nodes = j["nodes"].as_array_mut().expect("nodes");
        nodes.push(copy);
        let k = nodes.len() - 1;
        j["scenes"][0]["nodes"]
            .as_array_mut()
            .expect("roots")
            .push(json!(k));
    });
    let out = ok(&p, &refined);
    let base = &p.fixture.layout;
    let layout = &out.layout;
    // mug_0 moved, nothing else about it changed.
    let (before, after) = (object(base, "mug_0"), object(layout, "mug_0"));
    assert_abs_diff_eq!(
        after.position_cm.0[0],
        before.position_cm.0[0] + 5.0,
        epsilon = 1e-4
    );
    assert_abs_diff_eq!(
        after.position_cm.0[1],
        before.position_cm.0[1] + 3.0,
        epsilon = 1e-4
    );
    assert_eq!(after.position_cm.0[2], before.position_cm.0[2]);
    assert_eq!(after.rotation, before.rotation);
    assert_eq!(after.size_cm, before.size_cm);
    // book_0 turned by 30°.
    let (before, after) = (object(base, "book_0"), object(layout, "book_0"));
    assert_abs_diff_eq!(
        after.z_rotation_deg.expect("a yaw"),
        before.z_rotation_deg.expect("a yaw") + 30.0,
        epsilon = 1e-4
    );
    assert_eq!(after.position_cm, before.position_cm);
    // lamp_0 1.5 times wider, as deep and as tall; its scale factor follows.
    let (before, after) = (object(base, "lamp_0"), object(layout, "lamp_0"));
    assert_abs_diff_eq!(
        after.size_cm.0[0],
        before.size_cm.0[0] * 1.5,
        epsilon = 1e-4
    );
    assert_abs_diff_eq!(after.size_cm.0[1], before.size_cm.0[1], epsilon = 1e-4);
    assert_abs_diff_eq!(after.size_cm.0[2], before.size_cm.0[2], epsilon = 1e-4);
    assert_abs_diff_eq!(after.scale_factor.0[0], 1.5, epsilon = 1e-5);
    assert_abs_diff_eq!(after.scale_factor.0[1], 1.0, epsilon = 1e-5);
    // pen_1 removed, pen_10 kept as it was.
    assert!(layout.objects.iter().all(|o| o.instance != "pen_1"));
    assert_eq!(object(layout, "pen_10"), object(base, "pen_10"));
    // The copy of mug_1 is mug_2, of the same asset, 10 cm to the left.
    let copy = object(layout, "mug_2");
    let source = object(base, "mug_1");
    assert_eq!(copy.retrieved_uid, source.retrieved_uid);
    assert_abs_diff_eq!(
        copy.position_cm.0[0],
        source.position_cm.0[0] - 10.0,
        epsilon = 1e-4
    );
    assert_abs_diff_eq!(copy.size_cm.0[2], source.size_cm.0[2], epsilon = 1e-4);
    assert!(copy.provenance.as_ref().expect("provenance").notes[0].contains("mug_1.001"));
    // The diff says all of it.
    let d = &out.diff;
    assert_eq!(d.moved, vec!["mug_0"]);
    assert_eq!(d.rotated, vec!["book_0"]);
    assert_eq!(d.scaled, vec!["lamp_0"]);
    assert_eq!(d.removed, vec!["pen_1"]);
    assert_eq!(d.added, vec!["mug_2"]);
    let change = d
        .objects
        .iter()
        .find(|c| c.instance == "mug_2")
        .expect("the copy");
    assert_eq!(change.duplicate_of.as_deref(), Some("mug_1"));
    assert_eq!(change.node.as_deref(), Some("mug_1.001"));
    let book = d
        .objects
        .iter()
        .find(|c| c.instance == "book_0")
        .expect("book");
    assert_abs_diff_eq!(book.yaw_change_deg.expect("yaw"), 30.0, epsilon = 1e-4);
    // The layout is valid and sorted by footprint.
    assert!(layout.problems().is_empty(), "{:?}", layout.problems());
    let mut sorted = layout.clone();
    assert!(!sorted.sort_objects());
}

#[test]
fn a_copy_of_a_deleted_object_takes_its_place() {
    // The annotator deleted mug_0 and kept its copy mug_0.001: that is mug_0, moved.
    let p = packed();
    let refined = edit_glb(&p.glb, |j, _| {
        let n = node_at(j, "mug_0");
        j["nodes"][n]["name"] = json!("mug_0.001");
        j["nodes"][n]["translation"][0] = json!(0.5);
    });
    let out = ok(&p, &refined);
    assert_abs_diff_eq!(
        object(&out.layout, "mug_0").position_cm.0[0],
        50.0,
        epsilon = 1e-4
    );
    assert!(out.diff.added.is_empty() && out.diff.removed.is_empty());
}

#[test]
fn the_table_frame_moves_and_resizes_with_the_table() {
    let p = packed();
    // The table moved 10 cm right and 5 cm back: everything else stayed, so every object is
    // 10 cm left of and 5 cm nearer to the table's corner than before.
    let refined = edit_glb(&p.glb, |j, _| {
        let n = node_at(j, "table");
        let t = j["nodes"][n]["translation"].clone();
        j["nodes"][n]["translation"] = json!([
            t[0].as_f64().expect("x") + 0.10,
            t[1],
            t[2].as_f64().expect("z") - 0.05
        ]);
    });
    let out = ok(&p, &refined);
    for (before, after) in p.fixture.layout.objects.iter().zip(&out.layout.objects) {
        assert_eq!(before.instance, after.instance);
        assert_abs_diff_eq!(
            after.position_cm.0[0],
            before.position_cm.0[0] - 10.0,
            epsilon = 1e-4
        );
        assert_abs_diff_eq!(
            after.position_cm.0[1],
            before.position_cm.0[1] - 5.0,
            epsilon = 1e-4
        );
        assert_eq!(after.rotation, before.rotation);
    }
    assert_abs_diff_eq!(out.diff.table.moved_cm[0], 10.0, epsilon = 1e-4);
    assert_abs_diff_eq!(out.diff.table.moved_cm[1], 5.0, epsilon = 1e-4);
    assert!(!out.diff.table.resized);
    assert_eq!(out.layout.zone_cm, p.fixture.layout.zone_cm);

    // Scaled to 150 cm wide about its left edge (moved by half the growth): a new zone, the
    // objects where they were.
    let refined = edit_glb(&p.glb, |j, _| {
        let n = node_at(j, "table");
        j["nodes"][n]["scale"] = json!([1.25, 1.0, 1.0]);
        j["nodes"][n]["translation"][0] = json!(0.75);
    });
    let out = ok(&p, &refined);
    assert_abs_diff_eq!(out.layout.zone_cm.0[1], 150.0, epsilon = 1e-4);
    assert_eq!(out.layout.zone_cm.0[3], 60.0);
    assert!(out.diff.table.resized);
    for (before, after) in p.fixture.layout.objects.iter().zip(&out.layout.objects) {
        assert_eq!(before, after);
    }
    // A turned table turns the frame: an object is read in the table's axes.
    let refined = edit_glb(&p.glb, |j, _| {
        let n = node_at(j, "table");
        j["nodes"][n]["rotation"] = turned(&Value::Null, 90.0);
    });
    let out = ok(&p, &refined);
    assert_abs_diff_eq!(out.diff.table.rotated_deg, 90.0, epsilon = 1e-4);
    let (before, after) = (
        object(&p.fixture.layout, "book_0"),
        object(&out.layout, "book_0"),
    );
    assert_abs_diff_eq!(
        after.z_rotation_deg.expect("yaw"),
        before.z_rotation_deg.expect("yaw") - 90.0,
        epsilon = 1e-4
    );
}

#[test]
fn a_scaled_h1_figure_rescales_the_scene_about_the_table_origin() {
    let p = packed();
    let refined = edit_glb(&p.glb, |j, _| {
        let n = node_at(j, "H1_reference");
        j["nodes"][n]["scale"] = json!([1.1, 1.1, 1.1]);
    });
    let out = ok(&p, &refined);
    let f = 1.0 / 1.1;
    assert_abs_diff_eq!(
        out.diff.h1.height_cm.expect("height"),
        187.0,
        epsilon = 1e-3
    );
    assert_abs_diff_eq!(
        out.diff.h1.rescaled_by.expect("rescaled"),
        f,
        epsilon = 1e-6
    );
    assert_abs_diff_eq!(out.layout.zone_cm.0[1], 120.0 * f, epsilon = 1e-4);
    for (before, after) in p.fixture.layout.objects.iter().zip(&out.layout.objects) {
        for i in 0..3 {
            assert_abs_diff_eq!(
                after.position_cm.0[i],
                before.position_cm.0[i] * f,
                epsilon = 1e-4
            );
            assert_abs_diff_eq!(after.size_cm.0[i], before.size_cm.0[i] * f, epsilon = 1e-4);
        }
    }
    assert!(out.diff.warnings.iter().any(|w| w.contains("rescaled")));
    // Deleted, it is reported and nothing is rescaled.
    let refined = edit_glb(&p.glb, |j, _| {
        let n = node_at(j, "H1_reference");
        j["nodes"][n]["name"] = json!("H1_reference_gone");
    });
    let out = ingest(
        &p,
        &refined,
        &IngestConfig {
            allow_unknown_nodes: true,
            ..IngestConfig::default()
        },
    )
    .expect("ingests");
    assert!(!out.diff.h1.present);
    assert_eq!(out.diff.ignored_nodes, vec!["H1_reference_gone"]);
    assert_eq!(out.layout, p.fixture.layout);
}

#[test]
fn tilted_objects_are_reported_and_lose_their_z_rotation() {
    let p = packed();
    let refined = edit_glb(&p.glb, |j, _| {
        let n = node_at(j, "mug_0");
        // 20° about the table's x axis (glTF X).
        let h = 20f64.to_radians() / 2.0;
        j["nodes"][n]["rotation"] = json!([h.sin(), 0.0, 0.0, h.cos()]);
    });
    let out = ok(&p, &refined);
    assert_eq!(out.diff.tilted, vec!["mug_0"]);
    let mug = object(&out.layout, "mug_0");
    assert_eq!(mug.z_rotation_deg, None);
    assert_abs_diff_eq!(
        mesa_schemas::rotation::tilt_deg_from_quat_xyzw(mug.rotation.0),
        20.0,
        epsilon = 1e-4
    );
}

/// Replaces the POSITION data of the mesh of `name` by `f` of it (a new accessor; the other
/// attributes are kept).
fn with_new_positions(glb: &[u8], name: &str, f: impl Fn(usize, [f32; 3]) -> [f32; 3]) -> Vec<u8> {
    let document = crate::glb_read::open_glb(glb).expect("reads");
    let n = crate::pack::testing::node(document.root(), name);
    let mesh = document.root().nodes[n].mesh.expect("mesh").value();
    let primitives = document.mesh_primitives(mesh, false).expect("mesh");
    drop(document);
    edit_glb(glb, |j, bin| {
        let mut new_mesh = j["meshes"][mesh].clone();
        new_mesh["name"] = json!(format!("{name}_edited"));
        let mut k = 0usize;
        for (p, primitive) in primitives.iter().enumerate() {
            let offset = bin.len();
            let mut min = [f32::INFINITY; 3];
            let mut max = [f32::NEG_INFINITY; 3];
            for v in &primitive.positions {
                let q = f(k, [v[0] as f32, v[1] as f32, v[2] as f32]);
                k += 1;
                for c in 0..3 {
                    bin.extend_from_slice(&q[c].to_le_bytes());
                    min[c] = min[c].min(q[c]);
                    max[c] = max[c].max(q[c]);
                }
            }
            let views = j["bufferViews"].as_array_mut().expect("views");
            views
                .push(json!({"buffer": 0, "byteOffset": offset, "byteLength": bin.len() - offset}));
            let view = views.len() - 1;
            let accessors = j["accessors"].as_array_mut().expect("accessors");
            accessors.push(json!({
                "bufferView": view, "componentType": 5126, "count": primitive.positions.len(),
                "type": "VEC3", "min": min, "max": max
            }));
            new_mesh["primitives"][p]["attributes"]["POSITION"] = json!(accessors.len() - 1);
        }
        let meshes = j["meshes"].as_array_mut().expect("meshes");
        meshes.push(new_mesh);
        let m = meshes.len() - 1;
        let n = node_at(j, name);
        j["nodes"][n]["mesh"] = json!(m);
    })
}

#[test]
fn applied_transforms_are_read_exactly_and_edited_meshes_reported() {
    let p = packed();
    // mug_1 (scaled ×1.2) with its scale applied (Ctrl+A): vertices × node scale, node
    // scale 1.
    let (root, _) = crate::pack::testing::split_glb(&p.glb);
    let n = crate::pack::testing::node(&root, "mug_1");
    let s = root.nodes[n].scale.expect("a scale");
    let refined = with_new_positions(&p.glb, "mug_1", |_, v| {
        [v[0] * s[0], v[1] * s[1], v[2] * s[2]]
    });
    let refined = edit_glb(&refined, |j, _| {
        let n = node_at(j, "mug_1");
        j["nodes"][n].as_object_mut().expect("node").remove("scale");
    });
    let out = ok(&p, &refined);
    assert_eq!(out.diff.mesh_changed, vec!["mug_1"]);
    let change = out
        .diff
        .objects
        .iter()
        .find(|c| c.instance == "mug_1")
        .expect("mug");
    assert_eq!(change.mesh.as_deref(), Some("transform_applied"));
    let (before, after) = (
        object(&p.fixture.layout, "mug_1"),
        object(&out.layout, "mug_1"),
    );
    assert_eq!(before.position_cm, after.position_cm);
    for i in 0..3 {
        assert_abs_diff_eq!(after.size_cm.0[i], before.size_cm.0[i], epsilon = 1e-3);
    }
    // One vertex of the lamp pulled 5 cm up: reported as edited, read from its box.
    let refined = with_new_positions(&p.glb, "lamp_0", |k, v| {
        if k == 0 {
            [v[0], v[1] + 0.05, v[2]]
        } else {
            v
        }
    });
    let out = ok(&p, &refined);
    let change = out
        .diff
        .objects
        .iter()
        .find(|c| c.instance == "lamp_0")
        .expect("lamp");
    assert_eq!(change.mesh.as_deref(), Some("edited"));
    assert!(out
        .diff
        .warnings
        .iter()
        .any(|w| w.contains("lamp_0") && w.contains("edited")));
}

#[test]
fn unknown_nodes_are_errors_unless_allowed() {
    let p = packed();
    let refined = edit_glb(&p.glb, |j, _| {
        let n = node_at(j, "mug_0");
        j["nodes"][n]["name"] = json!("cup");
        let nodes = j["nodes"].as_array_mut().expect("nodes");
        nodes.push(json!({"name": "Camera"}));
        let k = nodes.len() - 1;
        j["scenes"][0]["nodes"]
            .as_array_mut()
            .expect("roots")
            .push(json!(k));
    });
    let e = err(&p, &refined);
    assert!(e.contains("cup, Camera"), "{e}");
    assert!(e.contains("\"cup\" was mug_0"), "{e}");
    assert!(e.contains("--allow-unknown-nodes"), "{e}");
    let out = ingest(
        &p,
        &refined,
        &IngestConfig {
            allow_unknown_nodes: true,
            ..IngestConfig::default()
        },
    )
    .expect("allowed");
    assert_eq!(out.diff.ignored_nodes, vec!["cup", "Camera"]);
    assert_eq!(out.diff.removed, vec!["mug_0"]);
}

#[test]
fn hostile_and_damaged_files_are_clear_errors() {
    let p = packed();
    // Truncated.
    let e = err(&p, &p.glb[..p.glb.len() / 2]);
    assert!(
        e.contains("GLB_UNEXPECTED_END_OF_CHUNK_DATA") && e.contains("truncated"),
        "{e}"
    );
    // A buffer whose byteLength claims more than the BIN chunk holds.
    let lying = edit_glb(&p.glb, |j, bin| {
        j["buffers"][0]["byteLength"] = json!(bin.len() + 4096);
    });
    let e = err(&p, &lying);
    assert!(e.contains("buffers[0]") && e.contains("byteLength"), "{e}");
    // An accessor reading past its buffer view.
    let (root, _) = crate::pack::testing::split_glb(&p.glb);
    let mesh = root.nodes[crate::pack::testing::node(&root, "book_0")]
        .mesh
        .expect("mesh")
        .value();
    let position = root.meshes[mesh].primitives[0]
        .attributes
        .get(&gltf_json::validation::Checked::Valid(
            gltf_json::mesh::Semantic::Positions,
        ))
        .expect("position")
        .value();
    let overrun = edit_glb(&p.glb, |j, _| {
        j["accessors"][position]["count"] = json!(1_000_000);
    });
    let e = err(&p, &overrun);
    assert!(
        e.contains(&format!("accessor {position}")) && e.contains("overrun"),
        "{e}"
    );
    // A node cycle.
    let cycle = edit_glb(&p.glb, |j, _| {
        let a = node_at(j, "mug_0");
        let b = node_at(j, "mug_1");
        j["nodes"][a]["children"] = json!([b]);
        j["nodes"][b]["children"] = json!([a]);
    });
    let e = err(&p, &cycle);
    assert!(e.contains("reached twice") || e.contains("cycle"), "{e}");
    // An image whose PNG header claims 40000 × 20000 pixels (3.2 GB decoded).
    let (root, _) = crate::pack::testing::split_glb(&p.glb);
    let view = root.images[0].buffer_view.expect("view").value();
    let offset = root.buffer_views[view].byte_offset.map_or(0, |o| o.0) as usize;
    let huge = edit_glb(&p.glb, |_, bin| {
        bin[offset + 16..offset + 20].copy_from_slice(&40_000u32.to_be_bytes());
        bin[offset + 20..offset + 24].copy_from_slice(&20_000u32.to_be_bytes());
    });
    let e = err(&p, &huge);
    assert!(
        e.contains("images[0]") && e.contains("40000 × 20000"),
        "{e}"
    );
    // A name with a path separator.
    let path = edit_glb(&p.glb, |j, _| {
        let n = node_at(j, "mug_0");
        j["nodes"][n]["name"] = json!("../../mug_0");
    });
    let e = err(&p, &path);
    assert!(
        e.contains("../../mug_0") && e.contains("path separator"),
        "{e}"
    );
    // Two nodes claiming the same instance.
    let twice = edit_glb(&p.glb, |j, _| {
        let n = node_at(j, "mug_1");
        j["nodes"][n]["name"] = json!("mug_0");
    });
    let e = err(&p, &twice);
    assert!(e.contains("both named \"mug_0\""), "{e}");
    // A duplicated table, a deleted table.
    let tables = edit_glb(&p.glb, |j, _| {
        let n = node_at(j, "table");
        let mut copy = j["nodes"][n].clone();
        copy["name"] = json!("table.001");
        let nodes = j["nodes"].as_array_mut().expect("nodes");
        nodes.push(copy);
        let k = nodes.len() - 1;
        j["scenes"][0]["nodes"]
            .as_array_mut()
            .expect("roots")
            .push(json!(k));
    });
    assert!(err(&p, &tables).contains("must not be duplicated"));
    let no_table = edit_glb(&p.glb, |j, _| {
        let n = node_at(j, "table");
        j["nodes"][n]["name"] = json!("tabletop");
    });
    let e = ingest(
        &p,
        &no_table,
        &IngestConfig {
            allow_unknown_nodes: true,
            ..IngestConfig::default()
        },
    )
    .map(|_| ())
    .expect_err("no table");
    assert!(e.to_string().contains("\"table\" node is missing"), "{e}");
}

#[test]
fn draco_compressed_meshes_are_decoded() {
    // book_0's mesh replaced by the Draco cube of ../shared/realdata (1 m, as Box.glb): its
    // size is the cube's × the node scale.
    let shared = std::env::var_os("MESA_SHARED")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| {
            std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared")
        });
    let draco = std::fs::read(shared.join("realdata/glb/Box_Draco.glb"))
        .expect("../shared/realdata/glb/Box_Draco.glb");
    let (_, draco_bin) = crate::pack::testing::split_glb(&draco);
    let p = packed();
    let refined = edit_glb(&p.glb, |j, bin| {
        let offset = bin.len();
        bin.extend_from_slice(&draco_bin[..152]);
        let views = j["bufferViews"].as_array_mut().expect("views");
        views.push(json!({"buffer": 0, "byteOffset": offset, "byteLength": 152}));
        let view = views.len() - 1;
        let accessors = j["accessors"].as_array_mut().expect("accessors");
        let base = accessors.len();
        accessors.push(json!({"componentType": 5121, "count": 36, "type": "SCALAR"}));
        accessors.push(json!({"componentType": 5126, "count": 24, "type": "VEC3",
            "min": [-0.5, -0.5, -0.5], "max": [0.5, 0.5, 0.5]}));
        accessors.push(json!({"componentType": 5126, "count": 24, "type": "VEC3"}));
        let meshes = j["meshes"].as_array_mut().expect("meshes");
        meshes.push(json!({"name": "draco_box", "primitives": [{
            "attributes": {"POSITION": base + 1, "NORMAL": base + 2},
            "indices": base, "material": 0,
            "extensions": {"KHR_draco_mesh_compression": {"bufferView": view,
                "attributes": {"NORMAL": 0, "POSITION": 1}}}}]}));
        let m = meshes.len() - 1;
        let n = node_at(j, "book_0");
        j["nodes"][n]["mesh"] = json!(m);
        j["nodes"][n]["scale"] = json!([0.1, 0.2, 0.3]);
        j["extensionsUsed"] = json!(["KHR_draco_mesh_compression"]);
        j["extensionsRequired"] = json!(["KHR_draco_mesh_compression"]);
    });
    let out = ok(&p, &refined);
    let book = object(&out.layout, "book_0");
    // glTF scale (X, Y, Z) = (0.1, 0.2, 0.3) is width 10 cm, depth 30 cm, height 20 cm.
    assert_abs_diff_eq!(book.size_cm.0[0], 10.0, epsilon = 1e-4);
    assert_abs_diff_eq!(book.size_cm.0[1], 30.0, epsilon = 1e-4);
    assert_abs_diff_eq!(book.size_cm.0[2], 20.0, epsilon = 1e-4);
    assert_eq!(out.diff.mesh_changed, vec!["book_0"]);
}

#[test]
fn blender_suffixes_are_split_and_copies_named_by_category() {
    assert_eq!(split_blender_suffix("mug_0.001"), ("mug_0", Some(1)));
    assert_eq!(split_blender_suffix("mug_0.1000"), ("mug_0", Some(1000)));
    assert_eq!(split_blender_suffix("mug_0.01"), ("mug_0.01", None));
    assert_eq!(split_blender_suffix("pen_10"), ("pen_10", None));
    assert_eq!(split_blender_suffix(".001"), (".001", None));
    let taken: BTreeSet<String> = ["mug_0", "mug_1", "pen_1", "pen_10"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    assert_eq!(next_instance("mug_0", &taken), "mug_2");
    assert_eq!(next_instance("pen_1", &taken), "pen_11");
    assert_eq!(next_instance("tray", &taken), "tray_0");
}

/// A copy of the pack whose node `name` gets `field` = `value` (glTF JSON).
fn with_node_field(p: &Packed, name: &str, field: &str, value: Value) -> Vec<u8> {
    edit_glb(&p.glb, |j, _| {
        let n = node_at(j, name);
        j["nodes"][n][field] = value;
    })
}

#[test]
fn absurd_sizes_and_positions_are_errors_naming_the_node_the_field_and_the_fix() {
    let p = packed();
    let (root, _) = crate::pack::testing::split_glb(&p.glb);
    let mug = crate::pack::testing::node(&root, "mug_0");
    let table = crate::pack::testing::node(&root, "table");
    // A node scale of 1e30: the mug would be ~1e31 cm wide.
    let e = err(
        &p,
        &with_node_field(&p, "mug_0", "scale", json!([1e30, 1e30, 1e30])),
    );
    for expected in [
        &format!("nodes[{mug}] \"mug_0\".scale: the object is "),
        "e31 cm",
        "times the table top's longest side (120.0 cm)",
        "[ingest] max_size_over_table",
        "(fix: scale the object back",
    ] {
        assert!(e.contains(expected), "{expected}: {e}");
    }
    // Control: a plausible scale passes; a large one passes once the factor allows it.
    ok(
        &p,
        &with_node_field(&p, "mug_0", "scale", json!([1.5, 1.5, 1.5])),
    );
    let big = with_node_field(&p, "mug_0", "scale", json!([30.0, 30.0, 30.0]));
    assert!(err(&p, &big).contains("max_size_over_table"));
    let roomy = IngestConfig {
        max_size_over_table: 10.0,
        ..IngestConfig::default()
    };
    ingest(&p, &big, &roomy).expect("allowed by the configured factor");
    // A scale near zero.
    let tiny = with_node_field(&p, "mug_0", "scale", json!([1e-5, 1e-5, 1e-5]));
    let e = err(&p, &tiny);
    assert!(
        e.contains(&format!("nodes[{mug}] \"mug_0\".scale"))
            && e.contains("[ingest] min_object_side_cm")
            && e.contains("(fix: scale the object back up"),
        "{e}"
    );

    // A translation of 3e38 m: a position of 3e40 cm.
    let e = err(
        &p,
        &with_node_field(&p, "mug_0", "translation", json!([3e38, 0.0, 0.0])),
    );
    for expected in [
        &format!("nodes[{mug}] \"mug_0\".translation: the object's centre is at (3.000e40, "),
        "from the table top (x 0.0..120.0, y 0.0..60.0, z 0)",
        "[ingest] max_distance_from_table_cm",
        "(fix: move the object back onto the table",
    ] {
        assert!(e.contains(expected), "{expected}: {e}");
    }
    // Control: moved 1.5 m (50 cm past the table's edge) passes, 3.5 m (250 cm past it) does
    // not, unless configured.
    let moved = |dx: f64| {
        edit_glb(&p.glb, |j, _| {
            let n = node_at(j, "mug_0");
            let t = j["nodes"][n]["translation"].clone();
            j["nodes"][n]["translation"] = json!([t[0].as_f64().unwrap_or(0.0) + dx, t[1], t[2]]);
        })
    };
    ok(&p, &moved(1.5));
    let far = moved(3.5);
    assert!(err(&p, &far).contains("max_distance_from_table_cm"));
    let wide = IngestConfig {
        max_distance_from_table_cm: 300.0,
        ..IngestConfig::default()
    };
    ingest(&p, &far, &wide).expect("allowed by the configured distance");

    // The table scaled by 1e30.
    let e = err(
        &p,
        &with_node_field(&p, "table", "scale", json!([1e30, 1.0, 1e30])),
    );
    assert!(
        e.contains(&format!(
            "nodes[{table}] \"table\".scale: the table top is "
        )) && e.contains("[ingest] max_table_side_cm")
            && e.contains("(fix: scale the table back"),
        "{e}"
    );
    // Only what the edit made absurd counts: with a factor the packed mugs already exceed,
    // the unedited pack passes, and a mug scaled further does not.
    let strict = IngestConfig {
        max_size_over_table: 0.01,
        ..IngestConfig::default()
    };
    ingest(&p, &p.glb, &strict).expect("the baseline is left as it is");
    let scaled = with_node_field(&p, "mug_0", "scale", json!([1.5, 1.5, 1.5]));
    let e = ingest(&p, &scaled, &strict)
        .map(|_| ())
        .expect_err("scaled up");
    assert!(e.to_string().contains("\"mug_0\".scale"), "{e}");
    // Every bound is a key that a bad value of fails before any work.
    let bad = IngestConfig {
        max_size_over_table: f64::NAN,
        ..IngestConfig::default()
    };
    assert!(bad.problems()[0].contains("[ingest] max_size_over_table = NaN"));
}

#[test]
fn an_integer_position_accessor_needs_khr_mesh_quantization() {
    let p = packed();
    let (root, _) = crate::pack::testing::split_glb(&p.glb);
    let mesh = root.nodes[crate::pack::testing::node(&root, "mug_0")]
        .mesh
        .expect("mesh")
        .value();
    let position = root.meshes[mesh].primitives[0]
        .attributes
        .get(&gltf_json::validation::Checked::Valid(
            gltf_json::mesh::Semantic::Positions,
        ))
        .expect("position")
        .value();
    let retyped = |quantization: bool| {
        edit_glb(&p.glb, |j, _| {
            // The float bytes read as UNSIGNED_BYTE: values up to 255 (metres).
            j["accessors"][position]["componentType"] = json!(5121);
            j["accessors"][position]
                .as_object_mut()
                .expect("accessor")
                .remove("min");
            j["accessors"][position]
                .as_object_mut()
                .expect("accessor")
                .remove("max");
            if quantization {
                j["extensionsUsed"] = json!(["KHR_mesh_quantization"]);
                j["extensionsRequired"] = json!(["KHR_mesh_quantization"]);
            }
        })
    };
    let e = err(&p, &retyped(false));
    for expected in [
        &format!("meshes[{mesh}].primitives[0].attributes.POSITION (accessor {position})"),
        "MESH_PRIMITIVE_ATTRIBUTES_ACCESSOR_INVALID_FORMAT: componentType UNSIGNED_BYTE is not \
         allowed for it without KHR_mesh_quantization (expected FLOAT, as glTF 2.0 says)",
        "(fix: re-export the mesh with FLOAT POSITION data",
    ] {
        assert!(e.contains(expected), "{expected}: {e}");
    }
    // Control: with the extension the accessor is read as glTF says (integers, no
    // dequantization in the node): the mug is then metres wide, which the plausible ranges
    // catch.
    let e = err(&p, &retyped(true));
    assert!(
        e.contains("\"mug_") && e.contains("\".scale") && e.contains("max_size_over_table"),
        "{e}"
    );
    let quantized = retyped(true);
    let doc = crate::glb_read::open_glb(&quantized);
    assert!(doc.is_ok(), "{doc:?}");
}
