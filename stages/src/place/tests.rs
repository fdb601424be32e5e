//! Isometric placement and supports, with property tests on whole coarse layouts.

use std::collections::BTreeMap;

use mesa_schemas::artifacts::{
    AssetGeometry, AssetRecord, RetrievalRecipe, RetrievedInstance, ASSET_INDEX_SCHEMA,
    RETRIEVAL_SCHEMA,
};
use proptest::prelude::*;

use super::*;
use crate::retrieve::tests::{lift_of, lifted};

fn item(instance: &str, center: [f64; 3], size: [f64; 3], asset: [f64; 3]) -> PlacementInput {
    PlacementInput {
        instance: instance.to_owned(),
        target_center_m: center,
        target_size_m: size,
        asset_size_m: asset,
        yaw_deg: None,
        container: false,
    }
}

fn bottom(p: &Placement) -> f64 {
    p.center_m[2] - p.size_m[2] / 2.0
}

fn top(p: &Placement) -> f64 {
    p.center_m[2] + p.size_m[2] / 2.0
}

#[test]
fn the_smallest_asset_dimension_sets_the_scale() {
    // Asset 10 × 10 × 2 cm (a flat box); target 30 × 12 × 4 cm: k = height, s = 2.
    let (s, size, k) = isometric([0.10, 0.10, 0.02], [0.30, 0.12, 0.04]);
    assert_eq!(k, 2);
    assert_eq!(s, 2.0);
    assert_eq!(size, [0.2, 0.2, 0.04]);
}

#[test]
fn a_stack_rests_on_what_is_under_it() {
    // A book lifted 4 cm thick, its asset scaled to 3 cm; a mug lifted on top of it at 4 cm.
    let items = [
        item(
            "book_0",
            [0.3, 0.3, 0.02],
            [0.20, 0.15, 0.04],
            [0.20, 0.30, 0.03],
        ),
        item(
            "mug_0",
            [0.3, 0.3, 0.09],
            [0.08, 0.08, 0.10],
            [0.10, 0.08, 0.12],
        ),
    ];
    let p = place_objects(&items, &PlaceConfig::default());
    assert_eq!(p[0].support, Support::Table);
    assert_eq!(bottom(&p[0]), 0.0);
    // The book's smallest asset dimension is its height: 4 cm exactly.
    assert!((top(&p[0]) - 0.04).abs() < 1e-15);
    assert_eq!(p[1].support, Support::On(0));
    assert!((bottom(&p[1]) - top(&p[0])).abs() < 1e-15);
}

#[test]
fn an_object_in_a_container_keeps_its_height_in_it() {
    let mut bowl = item(
        "bowl_0",
        [0.5, 0.4, 0.04],
        [0.16, 0.16, 0.08],
        [0.15, 0.15, 0.06],
    );
    bowl.container = true;
    // An apple whose lifted bottom is a quarter of the way up the bowl's box.
    let apple = item(
        "apple_0",
        [0.5, 0.4, 0.06],
        [0.06, 0.06, 0.08],
        [0.07, 0.07, 0.07],
    );
    let p = place_objects(&[apple, bowl], &PlaceConfig::default());
    assert_eq!(p[0].support, Support::In(1));
    // The bowl: smallest dimension 6 cm → height 8 cm, s = 4/3.
    let expected = bottom(&p[1]) + 0.25 * p[1].size_m[2];
    assert!((bottom(&p[0]) - expected).abs() < 1e-12);
}

#[test]
fn an_object_with_nothing_under_it_drops_to_the_table() {
    let items = [item(
        "lamp_0",
        [0.2, 0.2, 0.25],
        [0.1, 0.1, 0.3],
        [0.1, 0.1, 0.3],
    )];
    let p = place_objects(&items, &PlaceConfig::default());
    assert_eq!(bottom(&p[0]), 0.0);
    match p[0].support {
        Support::Dropped(h) => assert!((h - 0.10).abs() < 1e-12),
        ref other => panic!("{other:?}"),
    }
}

fn record(size: [f64; 3]) -> AssetRecord {
    AssetRecord {
        file: String::new(),
        glb_bytes: 0,
        glb_sha256: String::new(),
        inputs_sha256: String::new(),
        valid: true,
        reason: None,
        reason_code: None,
        annotated: true,
        geometry: Some(AssetGeometry {
            front_yaw_deg: 0.0,
            bounds_min_m: [-size[0] / 2.0, -size[1] / 2.0, 0.0],
            bounds_max_m: [size[0] / 2.0, size[1] / 2.0, size[2]],
            size_m: size,
            gltf_extents_m: [size[0], size[2], size[1]],
            triangles: 12,
            vertices: 8,
            primitives: 1,
            mesh_instances: 1,
            materials: vec![],
            textured_materials: 0,
            textures: 0,
            images: vec![],
            generator: None,
            draco: false,
            skinned: false,
            extensions_required: vec![],
        }),
        shapes: None,
        warnings: vec![],
    }
}

fn retrieval_of(lift: &LiftArtifact, chosen: &[Option<&str>]) -> RetrievalArtifact {
    RetrievalArtifact {
        schema: RETRIEVAL_SCHEMA.to_owned(),
        scene_id: lift.scene_id.clone(),
        encoder: "lexical/1".to_owned(),
        recipe: RetrievalRecipe {
            text_top_k: 20,
            final_top_k: 5,
            text_weight: 0.9,
            size_weight: 0.1,
            fallback: true,
        },
        candidate_assets: 3,
        instances: lift
            .instances
            .iter()
            .zip(chosen)
            .map(|(l, c)| RetrievedInstance {
                instance: l.instance.clone(),
                mask_id: l.mask_id,
                label: l.label.clone(),
                query: l.description.clone(),
                target_size_cm: l.size_cm,
                candidates: vec![],
                chosen: c.map(str::to_owned),
                fallback: false,
            })
            .collect(),
    }
}

fn index_of(assets: &[(&str, [f64; 3])]) -> AssetIndexArtifact {
    AssetIndexArtifact {
        schema: ASSET_INDEX_SCHEMA.to_owned(),
        config_digest: String::new(),
        assets: assets
            .iter()
            .map(|(uid, size)| ((*uid).to_owned(), record(*size)))
            .collect(),
        annotated_without_glb: vec![],
    }
}

#[test]
fn a_coarse_layout_is_a_valid_dataset_layout() {
    let mut lift = lift_of(vec![
        lifted("book_0", 1, "a red book", [20.0, 15.0, 4.0]),
        lifted("mug_0", 2, "a white mug", [8.0, 8.0, 10.0]),
        lifted("vase_0", 3, "a vase", [10.0, 10.0, 30.0]),
    ]);
    lift.instances[0].center_cm = PositionCm([30.0, 30.0, 2.0]);
    lift.instances[1].center_cm = PositionCm([30.0, 30.0, 9.0]);
    lift.instances[2].center_cm = PositionCm([80.0, 50.0, 15.0]);
    let retrieval = retrieval_of(&lift, &[Some("book_red"), Some("mug_white"), None]);
    let index = index_of(&[
        ("book_red", [0.2, 0.3, 0.03]),
        ("mug_white", [0.1, 0.08, 0.12]),
    ]);
    let annotations = Annotations::parse(
        r#"{"book_red": {"category": "book"}, "mug_white": {"category": "mug", "isContainer": true}}"#,
    )
    .expect("annotations");
    let out = place_scene(
        &lift,
        &retrieval,
        &index,
        &annotations,
        &PlaceConfig::default(),
    )
    .expect("places");
    assert_eq!(
        out.warnings,
        ["vase_0: left out: retrieval found no asset for it"]
    );
    let layout = &out.layout;
    // By descending footprint: the book first.
    let names: Vec<&str> = layout.objects.iter().map(|o| o.instance.as_str()).collect();
    assert_eq!(names, ["book_0", "mug_0"]);
    let book = &layout.objects[0];
    assert_eq!(book.retrieved_uid, "book_red");
    // The book's smallest asset dimension is its 3 cm height, lifted 4 cm: s = 0.04 / 0.03.
    assert_eq!(book.scale_factor.0, [0.04 / 0.03; 3]);
    assert_eq!(book.rotation.0, [0.0, 0.0, 0.0, 1.0]);
    assert_eq!(book.category.as_deref(), Some("book"));
    assert_eq!(book.z_rotation_deg, Some(0.0));
    assert_eq!(
        book.provenance.as_ref().map(|p| p.notes.clone()),
        Some(vec!["on the table".to_owned()])
    );
    let mug = &layout.objects[1];
    assert_eq!(
        mug.provenance.as_ref().map(|p| p.notes.clone()),
        Some(vec!["on book_0".to_owned()])
    );
    // The layout passes `mesa validate`, and every object has what the official reader needs.
    let text = String::from_utf8(mesa_schemas::json::to_sorted_pretty(layout).expect("json"))
        .expect("utf-8");
    let problems = mesa_schemas::validate_text(&text, None, false);
    assert!(problems.is_empty(), "{problems:?}");
    let value: serde_json::Value = serde_json::from_str(&text).expect("json");
    for object in value["objects"].as_array().expect("objects") {
        assert!(object["retrieved_uid"]
            .as_str()
            .is_some_and(|u| !u.is_empty()));
        let scale = object["scale_factor"].as_array().expect("scale_factor");
        assert_eq!(scale.len(), 3);
        assert!(scale.iter().all(|v| v.as_f64().is_some()));
        assert_eq!(object["rotation"].as_array().map(Vec::len), Some(4));
        assert_eq!(object["size"].as_array().map(Vec::len), Some(3));
        assert_eq!(object["position"].as_array().map(Vec::len), Some(3));
    }
}

#[test]
fn a_retrieval_that_disagrees_with_the_index_is_an_error() {
    let lift = lift_of(vec![lifted("mug_0", 1, "a mug", [8.0, 8.0, 10.0])]);
    let retrieval = retrieval_of(&lift, &[Some("gone")]);
    let e = place_scene(
        &lift,
        &retrieval,
        &index_of(&[]),
        &Annotations::default(),
        &PlaceConfig::default(),
    )
    .expect_err("inconsistent");
    assert!(
        e.to_string()
            .starts_with("mug_0: its asset gone is not a valid asset"),
        "{e}"
    );
}

/// A scene of boxes on a table: some on the table, some stacked on an earlier one (their
/// lifted bottom at its lifted top, footprints overlapping), some lifted in mid-air.
fn scene() -> impl Strategy<Value = Vec<(PlacementInput, u8)>> {
    let one = (
        (0.05f64..1.0, 0.05f64..0.7),
        (0.01f64..0.4, 0.01f64..0.4, 0.005f64..0.4),
        (0.01f64..0.5, 0.01f64..0.5, 0.01f64..0.5),
        0u8..4,
        any::<bool>(),
        0.0f64..0.3,
    );
    prop::collection::vec(one, 1..12).prop_map(|raw| {
        let mut items: Vec<(PlacementInput, u8)> = Vec::new();
        for (i, ((x, y), (w, d, h), (aw, ad, ah), kind, container, lift)) in
            raw.into_iter().enumerate()
        {
            // kind 0, 1: on the table; 2: on the previous object; 3: in mid-air.
            let center = match (kind, items.last()) {
                (2, Some((prev, _))) => {
                    let c = prev.target_center_m;
                    let t = c[2] + prev.target_size_m[2] / 2.0;
                    [c[0] + w * 0.1, c[1], t + h / 2.0]
                }
                (3, _) => [x, y, lift + h / 2.0],
                _ => [x, y, h / 2.0],
            };
            let mut input = item(&format!("thing_{i}"), center, [w, d, h], [aw, ad, ah]);
            input.container = container;
            items.push((input, kind));
        }
        items
    })
}

proptest! {
    #[test]
    fn placed_objects_keep_their_aspect_and_rest_on_something(items in scene()) {
        let inputs: Vec<PlacementInput> = items.into_iter().map(|(i, _)| i).collect();
        let placed = place_objects(&inputs, &PlaceConfig::default());
        prop_assert_eq!(placed.len(), inputs.len());
        for (i, (input, p)) in inputs.iter().zip(&placed).enumerate() {
            let a = input.asset_size_m;
            // The aspect ratio is the asset's.
            for (u, v) in [(0, 1), (0, 2), (1, 2)] {
                let ratio = p.size_m[u] / p.size_m[v];
                let expected = a[u] / a[v];
                prop_assert!((ratio - expected).abs() <= 1e-12 * expected, "{} {} vs {}", i, ratio, expected);
            }
            // The smallest asset dimension matches the target exactly.
            let (_, _, k) = isometric(a, input.target_size_m);
            prop_assert!(a.iter().all(|d| *d >= a[k]));
            prop_assert_eq!(p.size_m[k], input.target_size_m[k]);
            // Nothing below the table; the bottom on the table or on/in an object under it.
            let b = bottom(p);
            prop_assert!(b >= 0.0, "{} below the table: {}", i, b);
            if b > 0.0 {
                let half = half_footprint(p.size_m, None);
                let rests = placed.iter().enumerate().any(|(j, q)| {
                    j != i
                        && footprints_overlap(p.center_m, half, q.center_m, half_footprint(q.size_m, None))
                        && bottom(q) - 1e-12 <= b
                        && b <= top(q) + 1e-12
                });
                prop_assert!(rests, "{} floats at {} ({:?})", i, b, p.support);
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    #[test]
    fn coarse_layouts_validate_and_rest(items in scene()) {
        let n = items.len();
        let mut lift = lift_of(
            (0..n)
                .map(|i| lifted(&format!("thing_{i}"), i as u32 + 1, "a thing", [1.0; 3]))
                .collect(),
        );
        let mut assets = Vec::new();
        let mut annotations = BTreeMap::new();
        for (i, (input, _)) in items.iter().enumerate() {
            lift.instances[i].center_cm = PositionCm(input.target_center_m.map(|v| v * 100.0));
            lift.instances[i].size_cm = SizeCm(input.target_size_m.map(|v| v * 100.0));
            assets.push((format!("asset_{i}"), input.asset_size_m));
            annotations.insert(format!("asset_{i}"), serde_json::json!({"isContainer": input.container}));
        }
        let uids: Vec<String> = assets.iter().map(|(u, _)| u.clone()).collect();
        let chosen: Vec<Option<&str>> = uids.iter().map(|u| Some(u.as_str())).collect();
        let retrieval = retrieval_of(&lift, &chosen);
        let index = index_of(&assets.iter().map(|(u, s)| (u.as_str(), *s)).collect::<Vec<_>>());
        let annotations = Annotations::from_value(&serde_json::json!(annotations)).expect("annotations");
        let out = place_scene(&lift, &retrieval, &index, &annotations, &PlaceConfig::default())
            .expect("places");
        let text = String::from_utf8(mesa_schemas::json::to_sorted_pretty(&out.layout).expect("json"))
            .expect("utf-8");
        let problems = mesa_schemas::validate_text(&text, None, false);
        prop_assert!(problems.is_empty(), "{:?}", problems);
        let objects = &out.layout.objects;
        prop_assert_eq!(objects.len(), n);
        for o in objects {
            let b = o.position_cm.0[2] - o.size_cm.0[2] / 2.0;
            prop_assert!(b >= -1e-9, "{} below the table: {}", &o.instance, b);
            if b > 1e-9 {
                let rests = objects.iter().any(|q| {
                    let qb = q.position_cm.0[2] - q.size_cm.0[2] / 2.0;
                    let qt = q.position_cm.0[2] + q.size_cm.0[2] / 2.0;
                    q.instance != o.instance
                        && footprints_overlap(
                            o.position_cm.0,
                            [o.size_cm.0[0] / 2.0, o.size_cm.0[1] / 2.0],
                            q.position_cm.0,
                            [q.size_cm.0[0] / 2.0, q.size_cm.0[1] / 2.0],
                        )
                        && qb - 1e-9 <= b
                        && b <= qt + 1e-9
                });
                prop_assert!(rests, "{} floats at {} cm", &o.instance, b);
            }
        }
    }
}
