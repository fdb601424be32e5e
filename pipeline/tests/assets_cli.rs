//! `mesa assets`, `mesa retrieve` and `mesa place` end to end: the real GLBs of
//! ../shared/realdata/glb as a library, synthetic assets, a synthetic scene lifted by `mesa
//! lift`, incremental reruns, and the coarse layout accepted by `mesa validate`.

mod common;

use std::path::Path;

use common::{mesa, shared};
use mesa_stages::assets::synthetic::Mesh;
use serde_json::{json, Value};

fn read_json(path: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(path).expect("read")).expect("json")
}

fn write_json(path: &Path, value: &Value) {
    std::fs::create_dir_all(path.parent().expect("parent")).expect("mkdir");
    std::fs::write(path, serde_json::to_vec_pretty(value).expect("json")).expect("write");
}

/// A dataset whose library holds every top-level GLB of realdata/glb.
fn real_library() -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("temp dir");
    let library = dir.path().join("assets/library");
    std::fs::create_dir_all(&library).expect("mkdir");
    let source = shared().join("realdata/glb");
    for entry in std::fs::read_dir(&source).expect("realdata/glb") {
        let path = entry.expect("entry").path();
        if path.extension().is_some_and(|e| e == "glb") {
            let name = path.file_name().expect("name");
            std::fs::write(library.join(name), std::fs::read(&path).expect("read")).expect("copy");
        }
    }
    dir
}

#[test]
fn the_real_library_is_indexed_with_a_verdict_for_every_glb() {
    let dir = real_library();
    let output = mesa()
        .args(["assets", "--progress", "off"])
        .arg(dir.path())
        .output()
        .expect("run");
    assert_eq!(output.status.code(), Some(0));
    let stderr = String::from_utf8(output.stderr).expect("utf-8");
    assert!(
        stderr.starts_with("assets: 28 GLBs: 23 valid, 5 invalid (28 indexed, 0 unchanged)"),
        "{stderr}"
    );
    let index = read_json(&dir.path().join("assets/index/assets.json"));
    assert_eq!(index["schema"], "mesa.asset-index/1");
    let assets = index["assets"].as_object().expect("assets");
    assert_eq!(assets.len(), 28);
    let invalid: Vec<(&str, &str)> = assets
        .iter()
        .filter(|(_, r)| r["valid"] == false)
        .map(|(uid, r)| (uid.as_str(), r["reason_code"].as_str().expect("code")))
        .collect();
    assert_eq!(
        invalid,
        [
            ("BoxMeshopt", "unsupported_extension"),
            ("box-textured-binary-separate", "external_uri"),
            ("box-textured-binary_gltf1", "GLB_INVALID_VERSION"),
            ("empty_nodes", "no_mesh"),
            ("quad_skin", "zero_size_axis"),
        ]
    );
    for (uid, record) in assets {
        if record["valid"] == true {
            let shapes = dir
                .path()
                .join(record["shapes"]["file"].as_str().expect("shapes"));
            let shapes_json = read_json(&shapes);
            assert_eq!(shapes_json["uid"], uid.as_str());
            assert!(record["geometry"]["size_m"]
                .as_array()
                .expect("size")
                .iter()
                .all(|v| v.as_f64().expect("f") > 0.0));
        } else {
            assert!(
                record["reason"]
                    .as_str()
                    .is_some_and(|r| r.contains("fix") || r.contains("expected")),
                "{uid}: {record}"
            );
        }
    }
    // Draco assets are decoded: the laptop's 89,011 triangles and the box's 12.
    assert_eq!(
        assets["laptop_blender_draco"]["geometry"]["triangles"],
        89_011
    );
    assert_eq!(assets["laptop_blender_draco"]["geometry"]["draco"], true);
    assert_eq!(
        assets["Box_Draco"]["geometry"]["size_m"],
        json!([1.0, 1.0, 1.0])
    );
    // The index files pass `mesa validate`.
    mesa()
        .arg("validate")
        .arg(dir.path().join("assets/index"))
        .assert()
        .success();
    // --strict fails on the 5 invalid assets.
    mesa()
        .args(["assets", "--strict", "--progress", "off"])
        .arg(dir.path())
        .assert()
        .code(1);
}

fn synthetic_library(dir: &Path) {
    let library = dir.join("assets/library");
    std::fs::create_dir_all(&library).expect("mkdir");
    let assets = [
        ("mug_white", Mesh::vessel(0.04, 0.095, 0.004, 0.007)),
        ("bowl_blue", Mesh::vessel(0.075, 0.06, 0.004, 0.006)),
        ("book_red", Mesh::cuboid([0.15, 0.03, 0.22])),
        ("vase_tall", Mesh::vessel(0.05, 0.3, 0.004, 0.01)),
        ("lamp_old", Mesh::cuboid([0.2, 0.4, 0.2])),
    ];
    for (uid, mesh) in &assets {
        std::fs::write(library.join(format!("{uid}.glb")), mesh.to_glb(1.0)).expect("write");
    }
    write_json(
        &dir.join("assets/annotations.json"),
        &json!({
            "mug_white": {"category": "mug", "description": "A white porcelain cup with a handle.", "isContainer": true},
            "bowl_blue": {"category": "bowl", "description": "A pale blue ceramic bowl.", "receptacle": true},
            "book_red": {"category": "book", "description": "A red hardcover book.", "bbox": {"x": 0.15, "y": 0.03, "z": 0.22}},
            "vase_tall": {"category": "vase", "description": "A tall ceramic vase."},
            "lamp_old": {"category": "lamp", "description": "An old desk lamp.", "mark_deletion": true}
        }),
    );
}

#[test]
fn reruns_reindex_only_what_changed() {
    let dir = tempfile::tempdir().expect("temp dir");
    synthetic_library(dir.path());
    let run = |args: &[&str]| {
        let output = mesa()
            .arg("assets")
            .args(args)
            .args(["--progress", "off"])
            .arg(dir.path())
            .output()
            .expect("run");
        assert!(output.status.success());
        String::from_utf8(output.stderr).expect("utf-8")
    };
    let index_path = dir.path().join("assets/index/assets.json");
    let first = run(&["--jobs", "2"]);
    assert!(
        first.starts_with("assets: 5 GLBs: 5 valid, 0 invalid (5 indexed, 0 unchanged)"),
        "{first}"
    );
    let bytes = std::fs::read(&index_path).expect("index");
    let shapes =
        std::fs::read(dir.path().join("assets/index/shapes/bowl_blue.json")).expect("shapes");

    let second = run(&["--jobs", "1"]);
    assert!(
        second.starts_with("assets: 5 GLBs: 5 valid, 0 invalid (0 indexed, 5 unchanged)"),
        "{second}"
    );
    assert_eq!(std::fs::read(&index_path).expect("index"), bytes);

    // --force re-indexes, with the same bytes whatever the thread count.
    let forced = run(&["--force", "--jobs", "1"]);
    assert!(forced.contains("(5 indexed, 0 unchanged)"), "{forced}");
    assert_eq!(std::fs::read(&index_path).expect("index"), bytes);
    assert_eq!(
        std::fs::read(dir.path().join("assets/index/shapes/bowl_blue.json")).expect("shapes"),
        shapes
    );

    // One GLB changes, one is removed, one annotation changes.
    let library = dir.path().join("assets/library");
    std::fs::write(
        library.join("book_red.glb"),
        Mesh::cuboid([0.16, 0.03, 0.22]).to_glb(1.0),
    )
    .expect("write");
    std::fs::remove_file(library.join("vase_tall.glb")).expect("remove");
    let mut annotations = read_json(&dir.path().join("assets/annotations.json"));
    annotations["mug_white"]["description"] = json!("A white mug.");
    write_json(&dir.path().join("assets/annotations.json"), &annotations);
    let third = run(&[]);
    assert!(
        third.starts_with("assets: 4 GLBs: 4 valid, 0 invalid (2 indexed, 2 unchanged)"),
        "{third}"
    );
    assert!(
        third.contains("annotated but no GLB in the library: vase_tall"),
        "{third}"
    );
    assert!(!dir
        .path()
        .join("assets/index/shapes/vase_tall.json")
        .exists());
    let index = read_json(&index_path);
    let width = index["assets"]["book_red"]["geometry"]["size_m"][0]
        .as_f64()
        .expect("w");
    assert!((width - 0.16).abs() < 1e-6, "{width}");
    let text = read_json(&dir.path().join("assets/index/text.json"));
    assert_eq!(text["documents"]["mug_white"]["text"], "mug. A white mug.");

    // A change of [assets] re-indexes everything.
    std::fs::write(
        dir.path().join("mesa.toml"),
        "[assets]\nvhacd_max_parts = 8\n",
    )
    .expect("write");
    let fourth = run(&[]);
    assert!(fourth.contains("(4 indexed, 0 unchanged)"), "{fourth}");
}

/// A lifted scene with a mug, a bowl, a book and a vase.
fn scene(dir: &Path) -> std::path::PathBuf {
    let input = dir.join("scenes/office_table/office_table_0001/input");
    mesa_stages::lift::synthetic::SyntheticScene {
        size_px: 256,
        boxes: 4,
        ..Default::default()
    }
    .write(&input)
    .expect("synthetic scene");
    let mut instances = read_json(&input.join("instances.json"));
    let described = [
        ("mug", "white ceramic coffee mug"),
        ("bowl", "blue bowl"),
        ("book", "red book"),
        ("vase", "ceramic vase with a long neck"),
    ];
    for (entry, (label, description)) in instances["instances"]
        .as_array_mut()
        .expect("instances")
        .iter_mut()
        .zip(described)
    {
        entry["label"] = json!(label);
        entry["description"] = json!(description);
    }
    write_json(&input.join("instances.json"), &instances);
    input
}

#[test]
fn retrieve_and_place_write_a_coarse_layout_that_validates() {
    let dir = tempfile::tempdir().expect("temp dir");
    synthetic_library(dir.path());
    scene(dir.path());
    let status = mesa()
        .args(["run", "--progress", "off"])
        .arg(dir.path())
        .output()
        .expect("run");
    let stderr = String::from_utf8(status.stderr).expect("utf-8");
    // graph runs too; every stage is done.
    assert!(stderr.contains("retrieve: 1 scenes: 1 done"), "{stderr}");
    assert!(stderr.contains("place: 1 scenes: 1 done"), "{stderr}");
    let coarse = dir
        .path()
        .join("scenes/office_table/office_table_0001/coarse");
    let retrieval = read_json(&coarse.join("retrieval.json"));
    assert_eq!(retrieval["encoder"], "lexical/1");
    let chosen: Vec<(&str, &str)> = retrieval["instances"]
        .as_array()
        .expect("instances")
        .iter()
        .map(|i| {
            (
                i["instance"].as_str().expect("i"),
                i["chosen"].as_str().expect("chosen"),
            )
        })
        .collect();
    assert_eq!(
        chosen,
        [
            ("mug_0", "mug_white"),
            ("bowl_0", "bowl_blue"),
            ("book_0", "book_red"),
            ("vase_0", "vase_tall")
        ]
    );
    let layout_path = coarse.join("layout.json");
    mesa().arg("validate").arg(&layout_path).assert().success();
    let layout = read_json(&layout_path);
    assert_eq!(layout["schema"], "mesa.layout/1");
    for object in layout["objects"].as_array().expect("objects") {
        assert!(object["retrieved_uid"]
            .as_str()
            .is_some_and(|u| !u.is_empty()));
        assert_eq!(object["scale_factor"].as_array().map(Vec::len), Some(3));
        assert_eq!(object["rotation"], json!([0.0, 0.0, 0.0, 1.0]));
        let bottom = object["position"][2].as_f64().expect("z")
            - object["size"][2].as_f64().expect("h") / 2.0;
        assert!(bottom.abs() < 1e-9, "{object}");
    }
    // A rerun skips both stages; a new asset index makes both redo their scene.
    let again = mesa()
        .args(["run", "--progress", "off"])
        .arg(dir.path())
        .output()
        .expect("run");
    let stderr = String::from_utf8(again.stderr).expect("utf-8");
    assert!(
        stderr.contains("retrieve: 1 scenes: 0 done, 1 skipped"),
        "{stderr}"
    );
    assert!(
        stderr.contains("place: 1 scenes: 0 done, 1 skipped"),
        "{stderr}"
    );
    let mut annotations = read_json(&dir.path().join("assets/annotations.json"));
    annotations["vase_tall"]["onTable"] = json!(false);
    write_json(&dir.path().join("assets/annotations.json"), &annotations);
    let third = mesa()
        .args(["run", "--progress", "off"])
        .arg(dir.path())
        .output()
        .expect("run");
    let stderr = String::from_utf8(third.stderr).expect("utf-8");
    assert!(stderr.contains("retrieve: 1 scenes: 1 done"), "{stderr}");
    let retrieval = read_json(&coarse.join("retrieval.json"));
    assert_ne!(retrieval["instances"][3]["chosen"], "vase_tall");
}

#[test]
fn the_features_encoder_reads_embeddings() {
    let dir = tempfile::tempdir().expect("temp dir");
    synthetic_library(dir.path());
    let input = scene(dir.path());
    // One-hot embeddings: asset i is e_i; the instances point at mug, bowl, book, vase.
    let uids = [
        "mug_white",
        "bowl_blue",
        "book_red",
        "vase_tall",
        "lamp_old",
    ];
    let rows = mesa_stages::retrieve::npy::Matrix {
        rows: 5,
        cols: 5,
        data: (0..25)
            .map(|i| if i % 6 == 0 { 1.0 } else { 0.0 })
            .collect(),
    };
    std::fs::write(
        dir.path().join("assets/text_features.npy"),
        mesa_stages::retrieve::npy::write_matrix(&rows, true),
    )
    .expect("write");
    write_json(&dir.path().join("assets/text_uids.json"), &json!(uids));
    let mut instances = read_json(&input.join("instances.json"));
    for (i, entry) in instances["instances"]
        .as_array_mut()
        .expect("instances")
        .iter_mut()
        .take(4)
        .enumerate()
    {
        let mut e = vec![0.1f32; 5];
        e[i] = 1.0;
        entry["embedding"] = json!(e);
    }
    write_json(&input.join("instances.json"), &instances);
    std::fs::write(
        dir.path().join("mesa.toml"),
        "[retrieve]\nencoder = \"features\"\n",
    )
    .expect("write");
    for stage in ["lift", "assets", "retrieve", "place"] {
        mesa()
            .args([stage, "--progress", "off"])
            .arg(dir.path())
            .assert()
            .success();
    }
    let retrieval = read_json(
        &dir.path()
            .join("scenes/office_table/office_table_0001/coarse/retrieval.json"),
    );
    assert_eq!(retrieval["encoder"], "features/5");
    let chosen: Vec<&str> = retrieval["instances"]
        .as_array()
        .expect("i")
        .iter()
        .map(|i| i["chosen"].as_str().expect("c"))
        .collect();
    assert_eq!(chosen, ["mug_white", "bowl_blue", "book_red", "vase_tall"]);

    // An instance without an embedding fails the scene with the instance named.
    instances["instances"][0]
        .as_object_mut()
        .expect("obj")
        .remove("embedding");
    write_json(&input.join("instances.json"), &instances);
    let output = mesa()
        .args(["retrieve", "--progress", "off"])
        .arg(dir.path())
        .output()
        .expect("run");
    assert_eq!(output.status.code(), Some(1));
    let stderr = String::from_utf8(output.stderr).expect("utf-8");
    assert!(stderr.contains("mug_0: no query embedding"), "{stderr}");
}

#[test]
fn retrieve_without_an_index_says_what_to_run() {
    let dir = tempfile::tempdir().expect("temp dir");
    scene(dir.path());
    mesa()
        .args(["lift", "--progress", "off"])
        .arg(dir.path())
        .assert()
        .success();
    let output = mesa()
        .args(["retrieve", "--progress", "off"])
        .arg(dir.path())
        .output()
        .expect("run");
    assert_eq!(output.status.code(), Some(1));
    let stderr = String::from_utf8(output.stderr).expect("utf-8");
    assert!(
        stderr.contains("assets/index/assets.json: missing input of `mesa retrieve`"),
        "{stderr}"
    );
    // A bad recipe is a configuration error, before any work.
    std::fs::write(
        dir.path().join("mesa.toml"),
        "[retrieve]\nfinal_top_k = 50\n",
    )
    .expect("write");
    mesa().args(["retrieve"]).arg(dir.path()).assert().code(2);
}
