//! The published MesaTask records: validation, conversion round trips, output parsing.

mod common;

use mesa_schemas::convert::{dataset_from_llm, llm_from_dataset};
use mesa_schemas::json::to_sorted_pretty;
use mesa_schemas::output::{compose_model_output, parse_model_output, FINAL_ANSWER_MARKER};
use mesa_schemas::{validate_text, DatasetLayout, GalleryRecord, Kind, LlmLayout};

fn records() -> Vec<(String, GalleryRecord)> {
    common::gallery_records()
        .into_iter()
        .map(|(name, text)| {
            let record = serde_json::from_str(&text).unwrap_or_else(|e| panic!("{name}: {e}"));
            (name, record)
        })
        .collect()
}

#[test]
fn published_records_are_valid_gallery_records() {
    let kind = Kind::by_name("gallery-record");
    for (name, text) in common::gallery_records() {
        let problems = validate_text(&text, kind, false);
        assert!(problems.is_empty(), "{name}: {problems:?}");
    }
}

#[test]
fn every_published_layout_round_trips_llm_dataset_llm() {
    let mut objects = 0;
    for (name, record) in records() {
        let llm: LlmLayout = record.scene_layout_json.resolve().expect("layout");
        let dataset = dataset_from_llm(&llm).layout;
        // Through the file form too: what we write must read back the same.
        let bytes = to_sorted_pretty(&dataset).expect("serialise");
        let reread: DatasetLayout = serde_json::from_slice(&bytes).expect("reread");
        let problems = validate_text(std::str::from_utf8(&bytes).expect("utf8"), None, false);
        assert!(problems.is_empty(), "{name}: {problems:?}");
        let back = llm_from_dataset(&reread);
        assert!(
            back.warnings.iter().all(|w| !w.contains("tilted")),
            "{name}"
        );
        assert_eq!(back.layout.objects.len(), llm.objects.len(), "{name}");
        assert_eq!(back.layout.sink_zone_cm, llm.sink_zone_cm, "{name}");
        // Conversions keep the order; sorting (as `mesa convert` does) must keep every value.
        assert_eq!(
            back.layout.objects, llm.objects,
            "{name}: order or values changed"
        );
        let mut sorted = back.layout.clone();
        sorted.sort_objects();
        for original in &llm.objects {
            let round = sorted
                .objects
                .iter()
                .find(|o| o.instance == original.instance)
                .unwrap_or_else(|| panic!("{name}: {} lost", original.instance));
            for axis in 0..3 {
                assert!((round.size_cm.0[axis] - original.size_cm.0[axis]).abs() <= 1e-6);
                assert!((round.position_cm.0[axis] - original.position_cm.0[axis]).abs() <= 1e-6);
            }
            assert!(
                (round.z_rotation_deg - original.z_rotation_deg).abs() <= 1e-6,
                "{name}"
            );
            assert_eq!(round.description, original.description);
            objects += 1;
        }
    }
    assert_eq!(objects, 12 + 7 + 11 + 12 + 9 + 12 + 9);
}

#[test]
fn yaw_survives_without_the_z_rotation_field() {
    // The released MesaTask-10K files carry only the quaternion.
    for (name, record) in records() {
        let llm: LlmLayout = record.scene_layout_json.resolve().expect("layout");
        let mut dataset = dataset_from_llm(&llm).layout;
        for object in &mut dataset.objects {
            object.z_rotation_deg = None;
        }
        let back = llm_from_dataset(&dataset).layout;
        for (a, b) in back.objects.iter().zip(&llm.objects) {
            let diff = mesa_schemas::rotation::normalize_deg(a.z_rotation_deg - b.z_rotation_deg);
            assert!(diff.abs() < 1e-9, "{name}: {} {a:?} vs {b:?}", a.instance);
        }
    }
}

#[test]
fn assembled_gallery_outputs_parse_as_successes() {
    for (name, record) in records() {
        let layout: LlmLayout = record.scene_layout_json.resolve().expect("layout");
        let lines = record.scene_graph.lines();
        let text =
            compose_model_output(&record.reasoning_paragraph, &lines, &layout).expect("compose");
        assert_eq!(text.matches(FINAL_ANSWER_MARKER).count(), 1);
        for variant in [
            text.clone(),
            format!("{text}<|im_end|>"),
            text.replacen(
                FINAL_ANSWER_MARKER,
                &format!("{FINAL_ANSWER_MARKER}```json\n"),
                1,
            ) + "\n```",
        ] {
            let parsed = parse_model_output(&variant).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(parsed.layout, layout, "{name}");
            assert_eq!(parsed.graph_lines, lines, "{name}");
            assert_eq!(
                parsed.reasoning,
                record.reasoning_paragraph.trim_end(),
                "{name}"
            );
            assert!(parsed.dropped_objects.is_empty());
        }
    }
}
