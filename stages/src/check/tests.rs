//! Hand-built scenes with known answers: objects made as library assets are (a synthetic mesh,
//! its collision shapes from `mesa assets`' decomposition), placed by layout poses.

use std::sync::Arc;

use approx::assert_abs_diff_eq;

use super::*;
use crate::assets::shapes::collision_shapes;
use crate::assets::synthetic::Mesh;
use crate::assets::{table_aligned_from_gltf, AssetsConfig};
use crate::check::geometry::Bounds;
use crate::check::settle::{settle, SettleConfig};
use crate::check::solid::AssetMesh;
use crate::mesh::quat_from_axis_angle;

/// An asset's collision shape as `mesa assets` makes it from a mesh in the glTF frame.
fn shape(uid: &str, mesh: &Mesh) -> Arc<AssetShape> {
    let aligned: Vec<[f64; 3]> = mesh
        .positions
        .iter()
        .map(|p| table_aligned_from_gltf(*p, 0.0))
        .collect();
    let shapes =
        collision_shapes(&aligned, &mesh.triangles, &AssetsConfig::default()).expect("shapes");
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in &aligned {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let c: [f64; 3] = std::array::from_fn(|k| 0.5 * (lo[k] + hi[k]));
    let parts = shapes
        .parts
        .iter()
        .map(|part| {
            part.points_m
                .iter()
                .map(|p| [p[0] - c[0], p[1] - c[1], p[2] - c[2]])
                .collect()
        })
        .collect();
    let centred: Vec<[f64; 3]> = aligned
        .iter()
        .map(|p| [p[0] - c[0], p[1] - c[1], p[2] - c[2]])
        .collect();
    Arc::new(
        AssetShape::from_parts(uid, parts, std::array::from_fn(|k| hi[k] - lo[k]))
            .with_mesh(AssetMesh::new(centred, mesh.triangles.clone())),
    )
}

/// A box of `size` (table x, y, z), metres.
fn cuboid(size: [f64; 3]) -> Arc<AssetShape> {
    // glTF (X, Y, Z) = table (x, z, -y).
    shape("box", &Mesh::cuboid([size[0], size[2], size[1]]))
}

/// A ball of radius `r`.
fn ball(r: f64) -> Arc<AssetShape> {
    let n = 16;
    let profile: Vec<[f64; 2]> = (0..=n)
        .map(|i| {
            let t = std::f64::consts::PI * i as f64 / n as f64;
            [
                if i == 0 || i == n { 0.0 } else { r * t.sin() },
                r - r * t.cos(),
            ]
        })
        .collect();
    shape("ball", &Mesh::lathe(&profile, 32))
}

/// A bowl 16 cm wide and 6 cm tall: 6 mm wall, 8 mm floor (its inside floor at 8 mm).
fn bowl() -> Arc<AssetShape> {
    shape("bowl", &Mesh::vessel(0.08, 0.06, 0.006, 0.008))
}

struct Item {
    name: &'static str,
    shape: Arc<AssetShape>,
    pose: Pose,
}

fn at(name: &'static str, shape: &Arc<AssetShape>, position_m: [f64; 3]) -> Item {
    Item {
        name,
        shape: Arc::clone(shape),
        pose: Pose {
            position_m,
            rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
            scale: [1.0; 3],
        },
    }
}

fn scene(items: &[Item]) -> PhysicsScene {
    PhysicsScene {
        zone_m: [0.0, 1.0, 0.0, 0.6],
        restricted_zone_m: None,
        objects: items
            .iter()
            .map(|item| PlacedObject {
                instance: item.name.to_owned(),
                reach_m: item.shape.reach_at(&item.pose),
                body: Body::of_shape(&item.shape, &item.pose).ok_or_else(|| "empty".to_owned()),
            })
            .collect(),
    }
}

fn check(items: &[Item]) -> (PhysicsScene, Findings) {
    let s = scene(items);
    let f = check_scene(&s, &Tolerances::default());
    (s, f)
}

#[test]
fn two_interpenetrating_boxes_collide_by_their_overlap() {
    let cube = cuboid([0.1, 0.1, 0.1]);
    // 7 mm of overlap along x (the least way out); 3 cm in y and the full height in z.
    let (_, f) = check(&[
        at("a", &cube, [0.3, 0.3, 0.05]),
        at("b", &cube, [0.393, 0.33, 0.05]),
    ]);
    assert_eq!(f.collisions.len(), 1);
    assert_abs_diff_eq!(f.collisions[0].depth_m, 0.007, epsilon = 1e-5);
    assert_abs_diff_eq!(f.collision_rate(), 1.0);
    assert!(f.floating.is_empty());
}

#[test]
fn a_thin_object_buried_inside_another_collides_by_the_way_out() {
    // A 1.7 mm phone inside a 6 cm thick towel stack, its middle 27 mm below the top: thinner
    // than the tolerance along z, yet 27 mm deep (the way out is up, through the top).
    let towel = cuboid([0.3, 0.2, 0.06]);
    let phone = cuboid([0.15, 0.07, 0.0017]);
    let (_, f) = check(&[
        at("towel_0", &towel, [0.5, 0.3, 0.03]),
        at("phone_0", &phone, [0.5, 0.3, 0.06 - 0.027]),
    ]);
    assert_eq!(f.collisions.len(), 1, "{:?}", f.collisions);
    let depth = f.collisions[0].depth_m;
    // The least way out: up by 27 mm + half the phone (0.85 mm).
    assert_abs_diff_eq!(depth, 0.027 + 0.00085, epsilon = 1e-4);
    // Control: the phone lying on the towel is no collision.
    let (_, f) = check(&[
        at("towel_0", &towel, [0.5, 0.3, 0.03]),
        at("phone_0", &phone, [0.5, 0.3, 0.06 + 0.00085]),
    ]);
    assert!(f.collisions.is_empty(), "{:?}", f.collisions);
}

#[test]
fn the_depth_of_parts_whose_boxes_nest_is_measured_not_pruned() {
    // Part boxes that nest along x (a 1 mm slab across a 10 cm cube): the overlap length along
    // x (1 mm) is under the tolerance, the way out is not.
    let cube = cuboid([0.1, 0.1, 0.1]);
    let slab = cuboid([0.001, 0.06, 0.06]);
    let contact = pair_contact_deeper_than(
        &Body::new(cube.place(&at("a", &cube, [0.3, 0.3, 0.05]).pose)).expect("body"),
        &Body::new(slab.place(&at("b", &slab, [0.3, 0.3, 0.05]).pose)).expect("body"),
        0.0,
        0.002,
    )
    .expect("contact");
    // Centred: the way out is 5 cm + 0.5 mm along x, or 5 cm + 3 cm along y and z.
    assert_abs_diff_eq!(contact.depth_m, 0.0505, epsilon = 1e-4);
}

#[test]
fn touching_boxes_do_not_collide() {
    let cube = cuboid([0.1, 0.1, 0.1]);
    for gap in [0.0, 0.0005, -0.001] {
        let (_, f) = check(&[
            at("a", &cube, [0.3, 0.3, 0.05]),
            at("b", &cube, [0.4 + gap, 0.3, 0.05]),
            // Stacked on the first, touching it.
            at("c", &cube, [0.3, 0.3, 0.15 + gap.max(0.0)]),
        ]);
        assert!(f.collisions.is_empty(), "gap {gap}: {:?}", f.collisions);
        assert!(f.floating.is_empty(), "gap {gap}: {:?}", f.floating);
        assert_eq!(f.pairs_total, 3);
    }
}

#[test]
fn an_apple_resting_in_a_bowl_is_not_a_collision_and_one_sunk_into_the_wall_is() {
    let (bowl, apple) = (bowl(), ball(0.03));
    // The bowl's centre is 3 cm up; its inside floor at 8 mm above the table. The apple rests
    // on the floor, 0.5 mm of clearance.
    let resting = [0.3, 0.3, 0.008 + 0.03 + 0.0005];
    let (_, f) = check(&[
        at("bowl_0", &bowl, [0.3, 0.3, 0.03]),
        at("apple_0", &apple, resting),
    ]);
    assert!(f.collisions.is_empty(), "{:?}", f.collisions);
    assert!(f.floating.is_empty(), "{:?}", f.floating);
    // Sunk 1 cm into the wall: the inside wall is 7.4 cm from the axis; the apple's side
    // reaches 8.4 cm.
    let sunk = [0.3 + 0.074 - 0.03 + 0.01, 0.3, 0.008 + 0.03 + 0.0005 + 0.01];
    let (_, f) = check(&[
        at("bowl_0", &bowl, [0.3, 0.3, 0.03]),
        at("apple_0", &apple, sunk),
    ]);
    assert_eq!(f.collisions.len(), 1, "{:?}", f.collisions);
    let depth = f.collisions[0].depth_m;
    assert!((0.008..0.012).contains(&depth), "depth {depth}");
}

#[test]
fn a_book_a_centimetre_above_the_table_floats() {
    let book = cuboid([0.2, 0.15, 0.03]);
    let (s, f) = check(&[at("book_0", &book, [0.5, 0.3, 0.015 + 0.01])]);
    assert_eq!(f.floating.len(), 1);
    assert_abs_diff_eq!(f.floating[0].gap_m, 0.01, epsilon = 1e-6);
    assert_eq!(f.floating[0].over, Support::Table);
    let schema = f.to_schema(&s);
    assert_eq!(schema.floating[0].over, "table");
    assert_abs_diff_eq!(schema.floating[0].gap_mm, 10.0, epsilon = 1e-3);
    // 1 mm up is within the tolerance.
    let (_, f) = check(&[at("book_0", &book, [0.5, 0.3, 0.015 + 0.001])]);
    assert!(f.floating.is_empty());
}

#[test]
fn a_book_above_another_floats_over_it_and_rests_once_dropped() {
    let book = cuboid([0.2, 0.15, 0.03]);
    let (_, f) = check(&[
        at("book_0", &book, [0.5, 0.3, 0.015]),
        at("book_1", &book, [0.52, 0.3, 0.045 + 0.02]),
    ]);
    assert_eq!(f.floating.len(), 1);
    assert_eq!(f.floating[0].object, 1);
    assert_eq!(f.floating[0].over, Support::Object(0));
    assert_abs_diff_eq!(f.floating[0].gap_m, 0.02, epsilon = 1e-6);
}

/// A book 1 cm over the table with another standing on it, touching or sunk into its top by
/// up to 1.5 mm: the upper book presses the lower one down and holds nothing up, so the
/// lower one floats 1 cm over the table and the upper one rests on it. Before, the upper
/// book's parts, met by the lower book's parts raised by the contact tolerance (or points
/// inside it), counted as holding the lower one up.
#[test]
fn an_object_standing_on_a_floating_one_does_not_hold_it_up() {
    let book = cuboid([0.2, 0.15, 0.03]);
    for sunk in [0.0, 0.0005, 0.0015] {
        let (_, f) = check(&[
            at("book_0", &book, [0.5, 0.3, 0.015 + 0.01]),
            at("book_1", &book, [0.52, 0.3, 0.045 + 0.01 - sunk]),
        ]);
        let floating: Vec<(usize, Support)> =
            f.floating.iter().map(|x| (x.object, x.over)).collect();
        assert_eq!(
            floating,
            vec![(0, Support::Table)],
            "sunk {sunk} m: {:?}",
            f.falls
        );
        assert_abs_diff_eq!(f.floating[0].gap_m, 0.01, epsilon = 1e-6);
    }
    // Control: with the lower book on the table, both rest.
    let (_, f) = check(&[
        at("book_0", &book, [0.5, 0.3, 0.015]),
        at("book_1", &book, [0.52, 0.3, 0.045]),
    ]);
    assert!(f.floating.is_empty(), "{:?}", f.floating);
}

/// The same on the meshes: a ball 3 mm over the loose pencil's mesh, with a book standing on
/// the ball; the ball still floats over the pencil, and the book rests on the ball.
#[test]
fn an_object_standing_on_a_floating_one_does_not_hold_it_up_on_the_meshes() {
    let mut items = loose_pencil_scene(true);
    let book = cuboid([0.2, 0.15, 0.03]);
    // Ball 1 is 2 cm across with its centre at 0.043 m: its top at 0.053 m.
    items.push(at("book_1", &book, [0.6, 0.3, 0.053 + 0.015]));
    let (_, f) = check(&items);
    let floating: Vec<(usize, Support)> = f.floating.iter().map(|x| (x.object, x.over)).collect();
    assert_eq!(floating, vec![(3, Support::Object(0))], "{:?}", f.falls);
    assert_abs_diff_eq!(f.floating[0].gap_m, 0.003, epsilon = 2e-4);
}

#[test]
fn a_turned_slim_object_beside_another_does_not_collide() {
    // A 30 × 2 × 2 cm stick turned 45°: its bounding box is 22.6 cm square. A 6 cm cube in
    // that box's corner, clear of the stick.
    let stick = cuboid([0.3, 0.02, 0.02]);
    let cube = cuboid([0.06, 0.06, 0.06]);
    let turn = quat_from_axis_angle([0.0, 0.0, 1.0], std::f64::consts::FRAC_PI_4);
    let mut slim = at("stick_0", &stick, [0.5, 0.3, 0.01]);
    slim.pose.rotation_xyzw = turn;
    let items = [slim, at("cube_0", &cube, [0.5 + 0.07, 0.3 - 0.07, 0.03])];
    let (s, f) = check(&items);
    let (a, b) = (
        s.objects[0].body.as_ref().expect("body"),
        s.objects[1].body.as_ref().expect("body"),
    );
    assert!(
        a.bounds.overlaps(&b.bounds, 0.0),
        "the boxes should overlap"
    );
    assert!(f.collisions.is_empty(), "{:?}", f.collisions);
    // The same cube on the stick's diagonal does collide.
    let (_, f) = check(&[
        items[0].clone_item(),
        at("cube_0", &cube, [0.5 + 0.04, 0.3 + 0.04, 0.03]),
    ]);
    assert_eq!(f.collisions.len(), 1);
}

impl Item {
    fn clone_item(&self) -> Item {
        Item {
            name: self.name,
            shape: Arc::clone(&self.shape),
            pose: self.pose,
        }
    }
}

#[test]
fn a_non_uniform_scale_stretches_a_turned_object_along_its_own_axis() {
    // The stick doubled along its own length and turned 90°: 60 cm along the table's y.
    let stick = cuboid([0.3, 0.02, 0.02]);
    let mut item = at("stick_0", &stick, [0.5, 0.3, 0.01]);
    item.pose.rotation_xyzw = quat_from_axis_angle([0.0, 0.0, 1.0], std::f64::consts::FRAC_PI_2);
    item.pose.scale = [2.0, 1.0, 1.0];
    let (s, f) = check(&[item]);
    let b = s.objects[0].body.as_ref().expect("body").bounds;
    assert_abs_diff_eq!(b.max[1] - b.min[1], 0.6, epsilon = 1e-6);
    assert_abs_diff_eq!(b.max[0] - b.min[0], 0.02, epsilon = 1e-6);
    // It reaches from y = 0 to 0.6, the zone's depth: inside.
    assert!(f.violations.is_empty(), "{:?}", f.violations);
}

#[test]
fn zones_and_the_table_top_are_enforced() {
    let cube = cuboid([0.1, 0.1, 0.1]);
    let mut s = scene(&[
        // 3 cm beyond the right edge (x = 1).
        at("out_0", &cube, [0.98, 0.3, 0.05]),
        // 4 mm beyond: within the 5 mm tolerance.
        at("edge_0", &cube, [0.054 - 0.004 - 0.004, 0.5, 0.05]),
        // Sunk 1 cm into the table.
        at("sunk_0", &cube, [0.5, 0.1, 0.04]),
        // Reaching 2 cm into the sink.
        at("wet_0", &cube, [0.25, 0.45, 0.05]),
    ]);
    s.restricted_zone_m = Some([0.28, 0.6, 0.3, 0.6]);
    let f = check_scene(&s, &Tolerances::default());
    let found: Vec<(usize, ViolationKind, f64)> = f.violations.clone();
    assert_eq!(found.len(), 3, "{found:?}");
    assert_eq!((found[0].0, found[0].1), (0, ViolationKind::OutsideZone));
    assert_abs_diff_eq!(found[0].2, 0.03, epsilon = 1e-6);
    assert_eq!((found[1].0, found[1].1), (2, ViolationKind::BelowTable));
    assert_abs_diff_eq!(found[1].2, 0.01, epsilon = 1e-6);
    assert_eq!(
        (found[2].0, found[2].1),
        (3, ViolationKind::InRestrictedZone)
    );
    assert_abs_diff_eq!(found[2].2, 0.02, epsilon = 1e-5);
}

#[test]
fn mesatasks_rule_counts_pairs_closer_than_five_centimetres() {
    let cube = cuboid([0.1, 0.1, 0.1]);
    let (s, f) = check(&[
        at("a", &cube, [0.2, 0.3, 0.05]),
        // 3 cm from a: a MesaTask "collision", not ours.
        at("b", &cube, [0.33, 0.3, 0.05]),
        // 6 cm from b.
        at("c", &cube, [0.49, 0.3, 0.05]),
    ]);
    assert!(f.collisions.is_empty());
    assert_eq!(f.mesatask_rule_pairs, 1);
    assert_eq!(f.pairs_total, 3);
    let schema = f.to_schema(&s);
    assert!(schema.clean);
    assert_eq!(schema.collision_rate, 0.0);
}

#[test]
fn objects_without_shapes_are_listed_and_make_no_pair() {
    let cube = cuboid([0.1, 0.1, 0.1]);
    let mut s = scene(&[
        at("a", &cube, [0.2, 0.3, 0.05]),
        at("b", &cube, [0.5, 0.3, 0.05]),
    ]);
    s.objects.push(PlacedObject {
        instance: "ghost_0".to_owned(),
        reach_m: 0.0,
        body: Err("no retrieved_uid".to_owned()),
    });
    let f = check_scene(&s, &Tolerances::default());
    assert_eq!(f.pairs_total, 1);
    assert_eq!(f.unchecked, 1);
    assert!(!f.clean());
}

#[test]
fn a_dataset_layout_places_each_asset_by_its_object() {
    let text = r#"{"item_placement_zone": [0, 100, 0, 60], "objects": [
        {"instance": "box_0", "retrieved_uid": "box", "position": [30, 30, 5],
         "rotation": [0, 0, 0, 1], "size": [10, 10, 10], "scale_factor": [1, 1, 1]},
        {"instance": "box_1", "retrieved_uid": "box", "position": [39.3, 30, 5],
         "rotation": [0, 0, 0, 1], "size": [10, 10, 10], "scale_factor": [1, 1, 1]},
        {"instance": "box_2", "retrieved_uid": "missing", "position": [80, 30, 5],
         "rotation": [0, 0, 0, 1], "size": [10, 10, 10], "scale_factor": [1, 1, 1]}]}"#;
    let layout: DatasetLayout = serde_json::from_str(text).expect("layout");
    let cube = cuboid([0.1, 0.1, 0.1]);
    let s = PhysicsScene::from_layout(&layout, |o| match o.retrieved_uid.as_str() {
        "box" => Ok(Arc::clone(&cube)),
        other => Err(format!("asset {other} is not in the index")),
    });
    let f = check_scene(&s, &Tolerances::default());
    assert_eq!(f.collisions.len(), 1);
    assert_abs_diff_eq!(f.collisions[0].depth_m, 0.007, epsilon = 1e-5);
    assert_eq!(f.unchecked, 1);
    let schema = f.to_schema(&s);
    assert_eq!(schema.collisions[0].a, "box_0");
    assert_eq!(schema.collisions[0].b, "box_1");
    assert_abs_diff_eq!(schema.collisions[0].depth_mm, 7.0, epsilon = 1e-2);
}

#[test]
fn the_reach_of_parts_grows_with_the_scale_a_layout_applies() {
    // A pencil-like asset whose one part reaches 0.5 mm outside its mesh: within a 2 mm
    // tolerance as it is, 10.5 mm outside once a layout scales it ×21 (and only then named).
    let text = r#"{"item_placement_zone": [0, 400, 0, 60], "objects": [
        {"instance": "pencil_0", "retrieved_uid": "pencil", "position": [30, 30, 0.4],
         "rotation": [0, 0, 0, 1], "size": [17.5, 0.75, 0.75], "scale_factor": [1, 1, 1]},
        {"instance": "pencil_1", "retrieved_uid": "pencil", "position": [200, 30, 8],
         "rotation": [0, 0, 0, 1], "size": [367.5, 15.75, 15.75],
         "scale_factor": [21, 21, 21]}]}"#;
    let layout: DatasetLayout = serde_json::from_str(text).expect("layout");
    let with_mesh = AssetShape::clone(&cuboid([0.175, 0.0075, 0.0075])).with_reach_m(0.0005);
    let without_mesh = AssetShape::from_parts(
        "pencil",
        with_mesh.parts().iter().map(|(p, _)| p.to_vec()).collect(),
        with_mesh.size_m,
    )
    .with_reach_m(0.0005);
    let config = CheckConfig::default();
    let source = super::scene::LayoutSource {
        layout: &layout,
        file: "coarse/layout.json",
        sha256: "0",
        scene_id: "office_table_0001",
    };
    // With its mesh, the scaled pencil is judged on it: nothing to warn about.
    let with_mesh = Arc::new(with_mesh);
    let checked = super::check_layout(
        source,
        |_| Ok(Arc::clone(&with_mesh)),
        &[false, false],
        &crate::graph::GraphOptions::default(),
        &config,
        false,
    );
    assert!(
        !checked.warnings.iter().any(|w| w.contains("reach outside")),
        "{:?}",
        checked.warnings
    );
    let pencil = Arc::new(without_mesh);
    let s = PhysicsScene::from_layout(&layout, |_| Ok(Arc::clone(&pencil)));
    assert_abs_diff_eq!(s.objects[0].reach_m, 0.0005, epsilon = 1e-12);
    assert_abs_diff_eq!(s.objects[1].reach_m, 0.0105, epsilon = 1e-12);
    let checked = super::check_layout(
        source,
        |_| Ok(Arc::clone(&pencil)),
        &[false, false],
        &crate::graph::GraphOptions::default(),
        &config,
        false,
    );
    let named: Vec<&String> = checked
        .warnings
        .iter()
        .filter(|w| w.contains("reach outside their meshes"))
        .collect();
    assert_eq!(named.len(), 1, "{:?}", checked.warnings);
    // This pencil has no mesh to be judged on: it is named, with why.
    assert!(
        named[0].contains("pencil_1 (10.5 mm: no mesh given)"),
        "{}",
        named[0]
    );
    assert!(!named[0].contains("pencil_0"), "{}", named[0]);
}

/// Settles a dataset layout of the given shapes (`containers[i]`: object i holds things).
fn settle_text(
    text: &str,
    shapes: &[(&str, Arc<AssetShape>)],
    containers: &[bool],
    simulate: bool,
) -> (SceneCheck, DatasetLayout) {
    let mut config = CheckConfig::default();
    config.settling.simulate = simulate;
    settle_with(text, shapes, containers, &config)
}

fn settle_with(
    text: &str,
    shapes: &[(&str, Arc<AssetShape>)],
    containers: &[bool],
    config: &CheckConfig,
) -> (SceneCheck, DatasetLayout) {
    let layout: DatasetLayout = serde_json::from_str(text).expect("layout");
    let source = super::scene::LayoutSource {
        layout: &layout,
        file: "refined/layout.json",
        sha256: "0",
        scene_id: "office_table_0001",
    };
    let checked = super::check_layout(
        source,
        |o| {
            shapes
                .iter()
                .find(|(uid, _)| *uid == o.retrieved_uid)
                .map(|(_, s)| Arc::clone(s))
                .ok_or_else(|| "no shape".to_owned())
        },
        containers,
        &crate::graph::GraphOptions::default(),
        config,
        true,
    );
    (checked, layout)
}

#[test]
fn a_stick_leaning_on_its_end_lies_down_when_settled_and_stands_without_the_simulation() {
    // A 30 cm stick, 1 cm thick, standing on its end tilted 4° about x, a little above the
    // table: the least-motion moves drop it onto its edge, where nothing overlaps and nothing
    // floats; only the simulation lets it fall.
    let half = 2f64.to_radians();
    let text = format!(
        r#"{{"item_placement_zone": [0, 100, 0, 100], "objects": [
        {{"instance": "stick_0", "retrieved_uid": "stick", "position": [50, 50, 16],
         "rotation": [{}, 0, 0, {}], "size": [1, 1, 30], "scale_factor": [1, 1, 1]}}]}}"#,
        half.sin(),
        half.cos()
    );
    let stick = cuboid([0.01, 0.01, 0.30]);
    let shapes = [("stick", stick)];
    let (with, _) = settle_text(&text, &shapes, &[false], true);
    let report = with.artifact.settle.as_ref().expect("settle report");
    let settled = with
        .settled
        .as_ref()
        .unwrap_or_else(|| panic!("not settled: {report:?}"));
    assert_eq!(report.method, "least_motion+simulation");
    let d = &report.displacements[0];
    assert!(d.simulated, "{d:?}");
    assert!(d.turned_deg.expect("turned") > 60.0, "{d:?}");
    // Lying on the table: its centre half its thickness up.
    let z = settled.objects[0].position_cm.0[2];
    assert!((0.3..1.0).contains(&z), "z = {z} cm; {report:?}");
    assert!(
        crate::mesh::quat_to_matrix(settled.objects[0].rotation.0)[2][2].abs() < 0.5,
        "not lying: {:?}",
        settled.objects[0].rotation
    );
    assert!(report.after.clean, "{:?}", report.after);
    let sim = report.simulation.as_ref().expect("simulation");
    assert_eq!(sim.objects_moved, 1);
    assert!(
        sim.still_moving.is_empty() && sim.fell.is_empty(),
        "{sim:?}"
    );
    // The control: without the simulation, the least-motion moves leave it standing.
    let (without, layout) = settle_text(&text, &shapes, &[false], false);
    let report = without.artifact.settle.as_ref().expect("settle report");
    let kept = without.settled.as_ref().expect("settled");
    assert_eq!(report.method, "least_motion");
    assert!(report.simulation.is_none());
    assert_eq!(kept.objects[0].rotation, layout.objects[0].rotation);
    assert!(
        kept.objects[0].position_cm.0[2] > 14.0,
        "{:?}",
        kept.objects[0]
    );
}

/// A book overlapping the end of a remote control, both on the table (MesaTask's coarse
/// layouts have such pairs). Lifted onto the remote, it would lie on it at one side and on the
/// table at the other, tilted; so it is slid apart from it and stays flat. Over the remote's
/// middle (the control), it is lifted onto it as before.
#[test]
fn a_book_over_the_end_of_a_remote_slides_off_it_and_one_over_its_middle_is_lifted() {
    let layout = |book_y: f64| {
        format!(
            r#"{{"item_placement_zone": [0, 100, 0, 100], "objects": [
            {{"instance": "remote_control_0", "retrieved_uid": "remote", "position": [50, 40, 1.4],
             "rotation": [0, 0, 0, 1], "size": [7, 27, 2.8], "scale_factor": [1, 1, 1]}},
            {{"instance": "book_0", "retrieved_uid": "book", "position": [50, {book_y}, 1.75],
             "rotation": [0, 0, 0, 1], "size": [25, 33, 3.5], "scale_factor": [1, 1, 1]}}]}}"#
        )
    };
    let shapes = [
        ("remote", cuboid([0.07, 0.27, 0.028])),
        ("book", cuboid([0.25, 0.33, 0.035])),
    ];
    let settled_z = |text: &str, simulate: bool| {
        let (checked, _) = settle_text(text, &shapes, &[false, false], simulate);
        let report = checked.artifact.settle.clone().expect("settle report");
        let settled = checked
            .settled
            .unwrap_or_else(|| panic!("not settled: {report:?}"));
        assert!(report.after.clean, "{:?}", report.after);
        (settled.objects[1].position_cm.0, report)
    };
    // Over the remote's end (its centre 6.5 cm past the remote's): slid, not lifted.
    let (book, _) = settled_z(&layout(60.0), false);
    assert!((book[2] - 1.75).abs() < 0.05, "lifted: {book:?}");
    // With the simulation it stays flat on the table.
    let (book, report) = settled_z(&layout(60.0), true);
    assert!((book[2] - 1.75).abs() < 0.05, "{book:?}");
    let moved = report
        .displacements
        .iter()
        .find(|d| d.instance == "book_0")
        .expect("book_0");
    assert!(moved.turned_deg.unwrap_or(0.0) < 0.5, "{moved:?}");
    // Control: over the remote's middle, lifted onto it.
    let (book, _) = settled_z(&layout(45.0), false);
    assert!(book[2] > 1.75 + 2.7, "not lifted: {book:?}");
}

#[test]
fn a_scene_over_the_part_budget_is_not_simulated_and_says_so() {
    let text = r#"{"item_placement_zone": [0, 100, 0, 100], "objects": [
        {"instance": "box_0", "retrieved_uid": "box", "position": [30, 50, 5],
         "rotation": [0, 0, 0, 1], "size": [10, 10, 10], "scale_factor": [1, 1, 1]},
        {"instance": "box_1", "retrieved_uid": "box", "position": [70, 50, 5],
         "rotation": [0, 0, 0, 1], "size": [10, 10, 10], "scale_factor": [1, 1, 1]}]}"#;
    let shapes = [("box", cuboid([0.1, 0.1, 0.1]))];
    let parts = 2 * shapes[0].1.part_count();
    let mut config = CheckConfig::default();
    config.settling.simulate = true;
    config.settling.max_simulated_parts = parts - 1;
    let (over, _) = settle_with(text, &shapes, &[false, false], &config);
    let report = over.artifact.settle.as_ref().expect("settle report");
    assert!(over.settled.is_none(), "{report:?}");
    assert!(report.simulation.is_none());
    let reason = report.reason.as_deref().unwrap_or_default();
    assert!(
        reason.contains(&format!("has {parts} convex parts"))
            && reason.contains("max_simulated_parts"),
        "{reason}"
    );
    // The control: at the budget, it is simulated and settles.
    config.settling.max_simulated_parts = parts;
    let (within, _) = settle_with(text, &shapes, &[false, false], &config);
    let report = within.artifact.settle.as_ref().expect("settle report");
    assert!(within.settled.is_some(), "{report:?}");
    assert!(report.simulation.is_some());
}

/// A synthetic mesh (glTF frame) as the check holds an asset's mesh: table-aligned, centred
/// on its box.
fn asset_mesh(mesh: &Mesh) -> AssetMesh {
    let aligned: Vec<[f64; 3]> = mesh
        .positions
        .iter()
        .map(|p| table_aligned_from_gltf(*p, 0.0))
        .collect();
    let b = aligned.iter().fold(Bounds::empty(), |b, p| {
        b.union(&Bounds { min: *p, max: *p })
    });
    let c = b.center();
    AssetMesh::new(
        aligned
            .iter()
            .map(|p| [p[0] - c[0], p[1] - c[1], p[2] - c[2]])
            .collect(),
        mesh.triangles.clone(),
    )
}

/// A box of `size` whose one part bulges past it by `bulge` on every side (measured reach
/// `bulge`), with its mesh to be judged on, or without (the control).
fn bulging_box(size: [f64; 3], bulge: f64, with_mesh: bool) -> Arc<AssetShape> {
    let outer = size.map(|v| v + 2.0 * bulge);
    let part = AssetShape::clone(&cuboid(outer)).with_reach_m(bulge);
    let part = AssetShape::from_parts(
        "pencil",
        part.parts()
            .iter()
            .map(|(points, _)| points.to_vec())
            .collect(),
        size,
    )
    .with_reach_m(bulge);
    Arc::new(if with_mesh {
        part.with_mesh(asset_mesh(&Mesh::cuboid([size[0], size[2], size[1]])))
    } else {
        part
    })
}

fn scaled(mut item: Item, scale: f64) -> Item {
    item.pose.scale = [scale; 3];
    item
}

/// A pencil whose part bulges 1 mm past its mesh, scaled ×4 (4 mm at that scale), lying on the
/// table; a book 1 mm beside its mesh, a ball on it, a ball 3 mm over it.
fn loose_pencil_scene(with_mesh: bool) -> Vec<Item> {
    let pencil = bulging_box([0.175, 0.0075, 0.0075], 0.001, with_mesh);
    let book = cuboid([0.2, 0.15, 0.03]);
    let ball = ball(0.01);
    vec![
        // The mesh is 0.7 × 0.03 × 0.03 at ×4, its bottom on the table.
        scaled(at("pencil_0", &pencil, [0.5, 0.3, 0.015]), 4.0),
        at("book_0", &book, [0.5, 0.3 + 0.015 + 0.001 + 0.075, 0.015]),
        at("ball_0", &ball, [0.4, 0.3, 0.03 + 0.01]),
        at("ball_1", &ball, [0.6, 0.3, 0.03 + 0.003 + 0.01]),
    ]
}

#[test]
fn a_loose_object_is_judged_on_its_mesh() {
    let (s, f) = check(&loose_pencil_scene(true));
    assert!(s.objects[0].body.as_ref().expect("body").loose());
    assert!(f.collisions.is_empty(), "{:?}", f.collisions);
    assert!(f.violations.is_empty(), "{:?}", f.violations);
    // Ball 0 rests on the pencil's mesh; ball 1 floats 3 mm over it.
    let floating: Vec<usize> = f.floating.iter().map(|x| x.object).collect();
    assert_eq!(floating, vec![3], "{:?}", f.falls);
    assert_abs_diff_eq!(f.floating[0].gap_m, 0.003, epsilon = 2e-4);
    assert_eq!(f.floating[0].over, Support::Object(0));
    // Control: judged on its bulging part, the pencil sinks 4 mm into the table, collides with
    // the book (3 mm) and the ball (4 mm), and holds the upper ball up.
    let (_, f) = check(&loose_pencil_scene(false));
    let pairs: Vec<(usize, usize)> = f.collisions.iter().map(|c| (c.a, c.b)).collect();
    assert_eq!(pairs, vec![(0, 1), (0, 2)], "{:?}", f.collisions);
    assert!(
        f.violations
            .iter()
            .any(|(i, kind, _)| *i == 0 && *kind == ViolationKind::BelowTable),
        "{:?}",
        f.violations
    );
    assert!(f.floating.is_empty(), "{:?}", f.floating);
}

#[test]
fn a_loose_object_settles_onto_its_mesh() {
    // The pencil's mesh 5 mm over the table, its part (4 mm bigger at ×4) 1 mm over it:
    // settling drops it by what its mesh can fall.
    let run = |with_mesh: bool| {
        let pencil = bulging_box([0.175, 0.0075, 0.0075], 0.001, with_mesh);
        let s = scene(&[scaled(at("pencil_0", &pencil, [0.5, 0.3, 0.02]), 4.0)]);
        let settled = settle(
            &s,
            &[None],
            &Tolerances::default(),
            &SettleConfig::default(),
        );
        assert!(settled.findings.clean(), "{:?}", settled.findings);
        settled.offsets_m[0][2]
    };
    assert_abs_diff_eq!(run(true), -0.005, epsilon = 1e-4);
    // Control: on the part, it already rests (1 mm is within the floating tolerance).
    assert_abs_diff_eq!(run(false), 0.0, epsilon = 1e-9);
}

#[test]
fn a_collision_is_as_deep_as_the_deepest_point_of_one_mesh_inside_the_other() {
    // A towel of two parts meeting at x = 0.5; a 2 cm wide phone buried 27 mm under its top
    // across that seam. Each part overlaps the phone by 1 cm along x (the way out of a part),
    // but the phone is 27.85 mm deep in the towel.
    let size = [0.3, 0.2, 0.06];
    let half = cuboid([0.15, 0.2, 0.06]);
    let shift = |dx: f64| -> Vec<[f64; 3]> {
        half.parts()[0]
            .0
            .iter()
            .map(|p| [p[0] + dx, p[1], p[2]])
            .collect()
    };
    let parts = AssetShape::from_parts("towel", vec![shift(-0.075), shift(0.075)], size);
    let phone = cuboid([0.02, 0.07, 0.0017]);
    let items = |towel: &Arc<AssetShape>| {
        vec![
            at("towel_0", towel, [0.5, 0.3, 0.03]),
            at("phone_0", &phone, [0.5, 0.3, 0.06 - 0.027]),
        ]
    };
    let phone_mesh =
        AssetShape::clone(&phone).with_mesh(asset_mesh(&Mesh::cuboid([0.02, 0.0017, 0.07])));
    let phone_judged = Arc::new(phone_mesh);
    let towel = Arc::new(
        parts
            .clone()
            .with_mesh(asset_mesh(&Mesh::cuboid([size[0], size[2], size[1]]))),
    );
    let mut with_meshes = items(&towel);
    with_meshes[1].shape = phone_judged;
    let (_, f) = check(&with_meshes);
    assert_eq!(f.collisions.len(), 1, "{:?}", f.collisions);
    assert_abs_diff_eq!(f.collisions[0].depth_m, 0.027 + 0.00085, epsilon = 2e-4);
    // Control: on the parts alone, the depth is the 1 cm way out of one part.
    let (_, f) = check(&items(&Arc::new(parts)));
    assert_eq!(f.collisions.len(), 1, "{:?}", f.collisions);
    assert_abs_diff_eq!(f.collisions[0].depth_m, 0.01, epsilon = 2e-4);
}

#[test]
fn a_steep_contact_is_judged_on_the_meshes() {
    // A ball 1.5 mm from a box's top edge, the contact 70° from vertical: its parts are within
    // the touch distance in a direction pointing down, but straight down it misses the box
    // (its lowest point over the box's top is beyond the edge) and could fall 37 mm.
    let bx = cuboid([0.1, 0.1, 0.05]);
    let ball_with_mesh = ball(0.02);
    let (s, c) = (70f64.to_radians().sin(), 70f64.to_radians().cos());
    let centre = [0.35 + 0.0215 * s, 0.3, 0.05 + 0.0215 * c];
    let items = |ball: &Arc<AssetShape>| {
        vec![
            at("box_0", &bx, [0.3, 0.3, 0.025]),
            at("ball_0", ball, centre),
        ]
    };
    let (scene, f) = check(&items(&ball_with_mesh));
    // Neither is loose: the steep contact alone sends the pair to the meshes.
    assert!(scene
        .objects
        .iter()
        .all(|o| !o.body.as_ref().expect("body").loose()));
    let floating: Vec<usize> = f.floating.iter().map(|x| x.object).collect();
    assert_eq!(floating, vec![1], "{:?}", f.falls);
    assert_abs_diff_eq!(f.floating[0].gap_m, centre[2] - 0.02, epsilon = 5e-4);
    // Control: without meshes, the parts' word stands: it rests on the box.
    let parts_only = Arc::new(AssetShape::from_parts(
        "ball",
        ball_with_mesh
            .parts()
            .iter()
            .map(|(p, _)| p.to_vec())
            .collect(),
        ball_with_mesh.size_m,
    ));
    let (_, f) = check(&items(&parts_only));
    assert!(f.floating.is_empty(), "{:?}", f.falls);
    assert_eq!(f.falls[1].over, Support::Object(0));
}

/// After a simulation in which everything came to rest, a layout the check does not find at
/// rest (here a box sunk 5 mm into the table, as a tilted glass's mesh ends) gets the
/// least-motion moves once more; not after one in which something still moves (the control).
#[test]
fn a_calm_simulation_is_tidied_by_the_least_motion_moves() {
    use super::simulate::{SimMotion, Simulation};
    let text = r#"{"item_placement_zone": [0, 100, 0, 100], "objects": [
        {"instance": "box_0", "retrieved_uid": "box", "position": [50, 50, 4.5],
         "rotation": [0, 0, 0, 1], "size": [10, 10, 10], "scale_factor": [1, 1, 1]}]}"#;
    let layout: DatasetLayout = serde_json::from_str(text).expect("layout");
    let box_shape = cuboid([0.1, 0.1, 0.1]);
    let shape_of = |_: &mesa_schemas::LayoutObject| Ok(Arc::clone(&box_shape));
    let config = CheckConfig::default();
    let motion = |window_motion_m: f64| Simulation {
        motions: vec![Some(SimMotion {
            position_m: [0.5, 0.5, 0.045],
            turn_xyzw: [0.0, 0.0, 0.0, 1.0],
            turn_deg: 0.0,
            moved_m: 0.0,
            window_motion_m,
            fell: false,
        })],
        steps: 1,
    };
    let mut tidied = layout.clone();
    super::scene::tidy_after_simulation(&mut tidied, &motion(0.0), &[None], &config, &shape_of);
    let z = tidied.objects[0].position_cm.0[2];
    assert!((4.95..=5.1).contains(&z), "z = {z} cm");
    let notes = &tidied.objects[0].provenance.as_ref().expect("a note").notes;
    assert!(
        notes
            .iter()
            .any(|n| n.starts_with("settled after the simulation")),
        "{notes:?}"
    );
    // The control: something still moved over the rest window: left as the simulation left it.
    let mut kept = layout.clone();
    super::scene::tidy_after_simulation(&mut kept, &motion(0.01), &[None], &config, &shape_of);
    assert_eq!(kept, layout);
}
