//! `validate_text` catches each kind of problem, all of them in one pass, with one line each.

use mesa_schemas::convert::dataset_from_llm;
use mesa_schemas::json::to_sorted_pretty;
use mesa_schemas::units::{PositionCm, SizeCm, ZoneCm};
use mesa_schemas::{validate_text, Kind, LlmLayout, LlmObject};
use serde_json::Value;

fn good_layout() -> Value {
    let llm = LlmLayout {
        zone_cm: ZoneCm([0.0, 120.0, 0.0, 60.0]),
        sink_zone_cm: None,
        objects: (0..6)
            .map(|i| LlmObject {
                instance: format!("book_{i}"),
                size_cm: SizeCm([20.0 + f64::from(i), 15.0, 3.0]),
                position_cm: PositionCm([10.0 + 15.0 * f64::from(i), 20.0, 1.5]),
                z_rotation_deg: 0.0,
                description: "a book".into(),
            })
            .collect(),
    };
    let bytes = to_sorted_pretty(&dataset_from_llm(&llm).layout).expect("ser");
    serde_json::from_slice(&bytes).expect("value")
}

fn lines(text: &str, kind: Option<&str>) -> Vec<String> {
    validate_text(text, kind.and_then(Kind::by_name), false)
        .into_iter()
        .map(|l| l.problem.to_string())
        .collect()
}

#[test]
fn a_good_layout_is_valid() {
    assert_eq!(
        lines(&good_layout().to_string(), None),
        Vec::<String>::new()
    );
}

#[test]
fn every_problem_of_a_file_is_reported_once() {
    let mut v = good_layout();
    v["objects"][0]["position"] = Value::from("abc");
    v["objects"][1]
        .as_object_mut()
        .expect("obj")
        .remove("rotation");
    v["objects"][2]["size"] = serde_json::json!([1.0, 2.0]);
    v["objects"][4]["size"][1] = Value::from(-3.0);
    let text = v.to_string().replacen("15.0", "NaN", 1);
    let found = lines(&text, None);
    let expect = [
        "$.objects[0].position: is a string \"abc\" (expected an array",
        "$.objects[1].rotation: missing required key \"rotation\" (expected ",
        "$.objects[2].size: has 2 items (expected exactly 3 items",
        "$.objects[4].size[1]: is -3 (expected a number > 0)",
        ": is NaN (expected a finite number)",
    ];
    for e in expect {
        assert_eq!(
            found.iter().filter(|l| l.contains(e)).count(),
            1,
            "{e} in {found:#?}"
        );
    }
    assert_eq!(found.len(), expect.len(), "{found:#?}");
}

#[test]
fn unknown_and_unsupported_schemas_are_named() {
    let mut v = good_layout();
    v["schema"] = Value::from("mesa.nonsense/1");
    let found = lines(&v.to_string(), None);
    assert_eq!(found.len(), 1);
    assert!(found[0].starts_with(
        "$.schema: unknown schema \"mesa.nonsense/1\" (expected one of mesa.layout/1"
    ));
    v["schema"] = Value::from("mesa.layout/9");
    let found = lines(&v.to_string(), None);
    assert!(
        found[0].contains("unsupported version \"mesa.layout/9\""),
        "{found:?}"
    );
    v.as_object_mut().expect("obj").remove("schema");
    let found = lines(&v.to_string(), None);
    assert!(found[0].contains("has no \"schema\" field"), "{found:?}");
    // Official files carry no schema field: --kind says what they are.
    assert!(lines(&v.to_string(), Some("layout")).is_empty());
}

#[test]
fn semantic_problems_follow_a_sound_structure() {
    let mut v = good_layout();
    v["objects"][1]["instance"] = v["objects"][0]["instance"].clone();
    v["objects"][2]["rotation"] = serde_json::json!([0.0, 0.0, 0.0, 2.0]);
    v["item_placement_zone"] = serde_json::json!([0.0, -5.0, 0.0, 60.0]);
    let found = lines(&v.to_string(), None);
    assert_eq!(found.len(), 3, "{found:#?}");
    assert!(found.iter().any(|l| l.contains("duplicate instance")));
    assert!(found.iter().any(|l| l.contains("norm 2.000000")));
    assert!(found.iter().any(|l| l.contains("empty zone")));
}

#[test]
fn syntax_errors_give_the_line() {
    let found = validate_text("{\n  \"a\": [1,\n  ]\n}", None, false);
    assert_eq!(found.len(), 1);
    assert_eq!(found[0].line, Some(3));
}

#[test]
fn json_lines_report_the_line_of_each_problem() {
    let good = serde_json::json!({"messages": [{"role": "user", "content": "x"}]}).to_string();
    let bad = serde_json::json!({"messages": [{"role": "user"}]}).to_string();
    let text = format!("{good}\n\n{bad}\n{good}\n");
    let found = validate_text(&text, Kind::by_name("trl-sft"), true);
    assert_eq!(found.len(), 1, "{found:?}");
    assert_eq!(found[0].line, Some(3));
    assert!(found[0]
        .problem
        .to_string()
        .contains("missing required key \"content\""));
}

/// The two artifacts the pipeline writes besides the stages' own: `mesa validate` knows them
/// by their `schema` field, accepts what mesa writes and names what is broken.
#[test]
fn asset_views_and_cached_chat_replies_validate() {
    use mesa_schemas::artifacts::{
        AssetViewsRecord, CachedChatReply, ASSET_VIEWS_SCHEMA, CHAT_REPLY_SCHEMA,
    };
    let views = AssetViewsRecord {
        schema: ASSET_VIEWS_SCHEMA.to_owned(),
        uid: "0a1b2c".to_owned(),
        glb_sha256: "ab".repeat(32),
        front_yaw_deg: 90.0,
        config_digest: "cd".repeat(32),
        views: (0..8).map(|k| format!("view_{k:03}")).collect(),
    };
    let reply = CachedChatReply {
        schema: CHAT_REPLY_SCHEMA.to_owned(),
        request_sha256: "ef".repeat(32),
        model: Some("gpt-4o-2024-08-06".to_owned()),
        content: "A desk with a lamp and two mugs.".to_owned(),
        finish_reason: Some("stop".to_owned()),
        redacted: false,
    };
    let views_text = String::from_utf8(to_sorted_pretty(&views).expect("ser")).expect("utf8");
    let reply_text = String::from_utf8(to_sorted_pretty(&reply).expect("ser")).expect("utf8");
    assert_eq!(lines(&views_text, None), Vec::<String>::new());
    assert_eq!(lines(&reply_text, None), Vec::<String>::new());
    // The optional fields of a reply may be absent (a server that names no model).
    let bare = CachedChatReply {
        model: None,
        finish_reason: None,
        ..reply.clone()
    };
    let bare_text = String::from_utf8(to_sorted_pretty(&bare).expect("ser")).expect("utf8");
    assert!(!bare_text.contains("model"), "{bare_text}");
    assert_eq!(lines(&bare_text, None), Vec::<String>::new());

    let mut broken: Value = serde_json::from_str(&views_text).expect("json");
    broken.as_object_mut().expect("obj").remove("glb_sha256");
    broken["front_yaw_deg"] = Value::from("east");
    let found = lines(&broken.to_string(), None);
    assert_eq!(
        found,
        [
            "$.glb_sha256: missing required key \"glb_sha256\" (expected a string: SHA-256 of its GLB)",
            "$.front_yaw_deg: is a string \"east\" (expected a number: its front alignment yaw, degrees)",
        ]
    );

    let mut broken: Value = serde_json::from_str(&reply_text).expect("json");
    broken.as_object_mut().expect("obj").remove("content");
    broken["tokens"] = Value::from(12);
    let found = lines(&broken.to_string(), None);
    assert_eq!(found.len(), 2, "{found:?}");
    assert!(
        found
            .iter()
            .any(|l| l.starts_with("$.content: missing required key")),
        "{found:?}"
    );
    assert!(
        found.iter().any(|l| l.starts_with("$.tokens:")),
        "{found:?}"
    );
}
