use serde_json::json;

use super::offline::{hollowness, name_words, placeholder_fields};
use super::*;
use crate::glb_read::GlbMesh;

fn input() -> AssetInput {
    AssetInput {
        uid: "mug".into(),
        names: vec!["coffee_mug".into(), "mug_body".into()],
        // 9 x 10 (height) x 12 cm: 1.08 litres of box.
        gltf_extents_m: [0.09, 0.10, 0.12],
        views: Vec::new(),
    }
}

const GOOD: &str = r#"{"category": "Coffee Mug", "description": "A white ceramic coffee mug with a round handle.",
  "onTable": true, "mass": 0.35, "frontView": 1, "isContainer": true, "materials": ["ceramic"]}"#;

#[test]
fn a_good_reply_gives_every_field_in_mesatask_form() {
    let config = AnnotationsConfig::default();
    let fields = validate_asset_reply(GOOD, &input(), &[], &config).expect("valid");
    assert_eq!(fields["category"], "coffee_mug");
    assert_eq!(fields["frontView"], 1);
    assert_eq!(fields.len(), FIELDS.len());
    // A code fence is accepted.
    let fenced = format!("```json\n{GOOD}\n```");
    assert!(validate_asset_reply(&fenced, &input(), &[], &config).is_ok());
}

#[test]
fn bad_replies_are_rejected_with_the_field_and_the_reason() {
    let config = AnnotationsConfig::default();
    let with = |key: &str, value: Value| {
        let mut v: Value = serde_json::from_str(GOOD).expect("json");
        v[key] = value;
        validate_asset_reply(&v.to_string(), &input(), &[], &config).expect_err("rejected")
    };
    let reasons = with("mass", json!("heavy"));
    assert!(
        reasons[0].starts_with("mass: ") && reasons[0].contains("string"),
        "{reasons:?}"
    );
    let reasons = with("mass", json!(500.0));
    assert!(reasons[0].contains("implausible"), "{reasons:?}");
    let reasons = with("mass", json!(0));
    assert!(reasons[0].contains("expected > 0 kg"), "{reasons:?}");
    let reasons = with("frontView", json!(4));
    assert!(reasons[0].contains("one of the 4 views"), "{reasons:?}");
    let reasons = with("onTable", json!("yes"));
    assert!(reasons[0].starts_with("onTable:"), "{reasons:?}");
    let reasons = validate_asset_reply("{\"category\": ", &input(), &[], &config).expect_err("x");
    assert!(reasons[0].contains("not valid JSON"), "{reasons:?}");
    let reasons = validate_asset_reply("[1]", &input(), &[], &config).expect_err("x");
    assert!(reasons[0].contains("expected a JSON object"), "{reasons:?}");
    // The taxonomy: a category outside it is rejected, inside it accepted.
    let taxonomy = parse_taxonomy("# kitchen\ncup\nCoffee mug\n");
    assert_eq!(taxonomy, ["cup", "coffee_mug"]);
    assert!(validate_asset_reply(GOOD, &input(), &taxonomy, &config).is_ok());
    let reasons =
        validate_asset_reply(GOOD, &input(), &["cup".to_owned()], &config).expect_err("x");
    assert!(reasons[0].contains("not in the taxonomy"), "{reasons:?}");
}

#[test]
fn the_merge_keeps_a_persons_fields_and_records_its_own() {
    let person = json!({"category": "mug", "mass": 0.3, "bbox": {"x": 0.09, "y": 0.1, "z": 0.12}});
    let fields = fields_to_annotate(Some(&person), "offline", false);
    assert_eq!(
        fields,
        [
            "description",
            "onTable",
            "frontView",
            "isContainer",
            "materials"
        ]
    );
    let offline = placeholder_fields(
        &["coffee_mug".into()],
        &["white_glaze".into()],
        [0.09, 0.1, 0.12],
        0.8,
        &[],
    );
    let merged = merge_entry(
        Some(&person),
        &offline,
        &fields,
        "offline",
        [0.09, 0.1, 0.12],
    );
    assert_eq!(merged["category"], "mug", "a person's field stays");
    assert_eq!(merged["mass"], 0.3);
    assert_eq!(merged["isContainer"], true);
    assert_eq!(merged[SOURCES_KEY]["description"], "offline");
    assert!(merged[SOURCES_KEY].get("category").is_none());
    assert_eq!(merged[PLACEHOLDER_KEY], true);
    // Nothing left for the offline backend; a model replaces the placeholder fields only.
    assert!(fields_to_annotate(Some(&merged), "offline", false).is_empty());
    let model_fields = fields_to_annotate(Some(&merged), "llm:m", false);
    assert_eq!(model_fields, fields);
    let good =
        validate_asset_reply(GOOD, &input(), &[], &AnnotationsConfig::default()).expect("valid");
    let by_model = merge_entry(Some(&merged), &good, &model_fields, "llm:m", [0.0; 3]);
    assert_eq!(by_model["category"], "mug");
    assert_eq!(by_model["frontView"], 1);
    assert!(
        by_model.get(PLACEHOLDER_KEY).is_none(),
        "no placeholder left"
    );
    let (counts, placeholders) = count_sources(&json!({"a": by_model, "b": merged}));
    assert_eq!(placeholders, 1);
    assert_eq!(counts["llm:m"], 5);
    assert_eq!(counts["offline"], 5);
    assert_eq!(counts["person"], 4);
    // A new asset gets a bbox from the mesh.
    let fresh = merge_entry(None, &offline, &FIELDS, "offline", [0.09, 0.1, 0.12]);
    assert_eq!(fresh["bbox"], json!({"x": 0.09, "y": 0.1, "z": 0.12}));
    assert_eq!(fresh[SOURCES_KEY]["bbox"], "mesh");
}

#[test]
fn front_views_compose_with_an_earlier_turn() {
    assert_eq!(front_view_of_file(1, 0.0), 1);
    assert_eq!(front_view_of_file(1, -90.0), 2);
    assert_eq!(front_view_of_file(3, -180.0), 1);
}

#[test]
fn names_split_into_words() {
    assert_eq!(name_words("CoffeeMug_01.001"), ["coffee", "mug"]);
    assert_eq!(name_words("Mesh_0 defaultMaterial"), Vec::<String>::new());
}

fn open_box(with_top: bool) -> GlbMesh {
    // A 10 cm cube: floor, four walls, and a lid when `with_top`.
    let p = |x: f64, y: f64, z: f64| [x * 0.1, y * 0.1, z * 0.1];
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    let mut quad = |a: [f64; 3], b: [f64; 3], c: [f64; 3], d: [f64; 3]| {
        let n = positions.len() as u32;
        positions.extend([a, b, c, d]);
        triangles.extend([[n, n + 1, n + 2], [n, n + 2, n + 3]]);
    };
    quad(p(0., 0., 0.), p(1., 0., 0.), p(1., 0., 1.), p(0., 0., 1.));
    // Walls 5 mm thick seen from above: thin rings at full height.
    for (x0, x1, z0, z1) in [
        (0.0, 1.0, 0.0, 0.05),
        (0.0, 1.0, 0.95, 1.0),
        (0.0, 0.05, 0.0, 1.0),
        (0.95, 1.0, 0.0, 1.0),
    ] {
        quad(p(x0, 1., z0), p(x1, 1., z0), p(x1, 1., z1), p(x0, 1., z1));
    }
    if with_top {
        quad(p(0., 1., 0.), p(1., 1., 0.), p(1., 1., 1.), p(0., 1., 1.));
    }
    GlbMesh {
        positions_m: positions,
        triangles,
        ..GlbMesh::default()
    }
}

#[test]
fn an_open_box_is_hollow_and_a_closed_one_is_not() {
    assert!(hollowness(&open_box(false)) > 0.9);
    assert!(hollowness(&open_box(true)) < 0.1);
}

#[test]
fn the_placeholder_is_valid_and_follows_the_taxonomy() {
    let config = AnnotationsConfig::default();
    let names = ["CoffeeMug".to_owned(), "handle".to_owned()];
    let fields = placeholder_fields(&names, &[], [0.09, 0.1, 0.12], 0.0, &[]);
    assert_eq!(fields["category"], "coffee_mug");
    // What the placeholder writes passes the model's validation.
    let text = serde_json::to_string(&fields).expect("json");
    validate_asset_reply(&text, &input(), &[], &config).expect("valid placeholder");
    let taxonomy = parse_taxonomy("cup\nmug\ncoffee_table\n");
    let fields = placeholder_fields(&names, &[], [0.09, 0.1, 0.12], 0.0, &taxonomy);
    assert_eq!(fields["category"], "mug");
}

#[test]
fn the_merge_keeps_what_retrieval_reads_in_every_bbox_form() {
    use crate::annotations::AssetAnnotation;
    let entries = [
        json!({"category": "lamp", "mark_deletion": true, "receptacle": true,
               "min_point": [-0.1, 0.0, -0.1], "max_point": [0.1, 0.4, 0.1]}),
        json!({"onTable": false, "bbox": {"min": {"x": 0, "y": 0, "z": 0},
                                          "max": {"x": 1, "y": 2, "z": 3}}}),
        json!({"is_composite": "True", "bbox": {"size": {"x": 0.2, "y": 0.1, "z": 0.3}}}),
    ];
    let offline = placeholder_fields(&["thing".into()], &[], [0.5, 0.5, 0.5], 0.0, &[]);
    for entry in entries {
        let before = AssetAnnotation::from_value("uid", &entry).expect("reads");
        let fields = fields_to_annotate(Some(&entry), OFFLINE_SOURCE, false);
        let merged = merge_entry(Some(&entry), &offline, &fields, OFFLINE_SOURCE, [0.5; 3]);
        let after = AssetAnnotation::from_value("uid", &merged).expect("reads");
        assert_eq!(after.bbox, before.bbox, "{entry}");
        assert_eq!(after.rejection(), before.rejection(), "{entry}");
        // A person's objathor `receptacle` is their isContainer: not overridden.
        assert_eq!(
            after.is_container,
            before.is_container.or(Some(false)),
            "{entry}"
        );
        // Every field the entry had is there unchanged.
        for (key, value) in entry.as_object().expect("object") {
            assert_eq!(&merged[key], value, "{key}");
        }
    }
}
