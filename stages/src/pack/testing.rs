//! Fixtures of the pack and ingest tests: small assets (plain, textured, a node hierarchy), a
//! layout placing them, its pack, and edits of a GLB's JSON as an annotator's tool makes them.

use std::collections::BTreeMap;

use mesa_schemas::layout::{DatasetLayout, LayoutObject, Provenance, LAYOUT_SCHEMA};
use mesa_schemas::rotation::quat_xyzw_from_yaw_deg;
use mesa_schemas::units::{PositionCm, QuatXyzw, ScaleFactor, SizeCm, ZoneCm};

use super::snapshot::Photo;
use super::{pack_scene, AssetSource, PackConfig, PackOutput, PackRequest};
use crate::glb_write::{GlbBuilder, MaterialSpec, NodeSpec};
use crate::mesh::{Affine3, TriMesh};

/// A plain box asset standing on y = 0 (glTF frame).
pub fn box_asset(size: [f64; 3], rgb: [f32; 3]) -> Vec<u8> {
    let mut b = GlbBuilder::new("test");
    let m = b.add_material(&MaterialSpec::plain("paint", rgb, 0.5));
    let mesh =
        TriMesh::cuboid(size).transformed(&Affine3::from_translation([0.0, size[1] / 2.0, 0.0]));
    let mesh = b.add_mesh("box", &[(&mesh, m)]).expect("mesh");
    let node = b
        .add_node(NodeSpec::new("box").with_mesh(mesh))
        .expect("node");
    b.set_scene("scene", vec![node]);
    b.finish().expect("glb")
}

/// A textured mug-like asset: a cylinder with a texture and a box handle of another material.
pub fn textured_asset() -> Vec<u8> {
    let mut b = GlbBuilder::new("test");
    let png = crate::image_io::encode_rgba8(2, 2, &[200, 30, 30, 255].repeat(4)).expect("png");
    let texture = b.add_png_texture("red", &png).expect("texture");
    let mut textured = MaterialSpec::plain("glaze", [1.0; 3], 0.3);
    textured.base_color_texture = Some(texture);
    let glaze = b.add_material(&textured);
    let handle = b.add_material(&MaterialSpec::plain("handle", [0.1, 0.1, 0.1], 0.6));
    let body = TriMesh::cylinder(0.04, 0.10, 16);
    let grip = TriMesh::cuboid([0.01, 0.05, 0.03])
        .transformed(&Affine3::from_translation([0.05, 0.05, 0.0]));
    let mesh = b
        .add_mesh("mug", &[(&body, glaze), (&grip, handle)])
        .expect("mesh");
    let node = b
        .add_node(NodeSpec::new("mug").with_mesh(mesh))
        .expect("node");
    b.set_scene("scene", vec![node]);
    b.finish().expect("glb")
}

/// A lamp: a base node holding an arm node turned 30° about Z and a head node scaled by 0.5,
/// under a root scaled by 2 (the hierarchy the pack bakes).
pub fn hierarchy_asset() -> Vec<u8> {
    let mut b = GlbBuilder::new("test");
    let metal = b.add_material(&MaterialSpec::plain("metal", [0.6, 0.6, 0.6], 0.2));
    let base = b
        .add_mesh("base", &[(&TriMesh::cylinder(0.05, 0.01, 12), metal)])
        .expect("mesh");
    let arm = b
        .add_mesh(
            "arm",
            &[(
                &TriMesh::cuboid([0.01, 0.12, 0.01])
                    .transformed(&Affine3::from_translation([0.0, 0.06, 0.0])),
                metal,
            )],
        )
        .expect("mesh");
    let head = b
        .add_mesh("head", &[(&TriMesh::uv_sphere(0.03, 12, 6), metal)])
        .expect("mesh");
    let head_node = b
        .add_node(
            NodeSpec::new("head")
                .with_mesh(head)
                .with_translation([0.0, 0.12, 0.0])
                .with_scale([0.5, 0.5, 0.5]),
        )
        .expect("node");
    let arm_node = b
        .add_node(
            NodeSpec::new("arm")
                .with_mesh(arm)
                .with_translation([0.0, 0.01, 0.0])
                .with_rotation_xyzw(crate::mesh::quat_from_axis_angle(
                    [0.0, 0.0, 1.0],
                    30f64.to_radians(),
                ))
                .with_children(vec![head_node]),
        )
        .expect("node");
    let base_node = b
        .add_node(
            NodeSpec::new("base")
                .with_mesh(base)
                .with_children(vec![arm_node]),
        )
        .expect("node");
    let root = b
        .add_node(
            NodeSpec::new("root")
                .with_scale([2.0, 2.0, 2.0])
                .with_children(vec![base_node]),
        )
        .expect("node");
    b.set_scene("scene", vec![root]);
    b.finish().expect("glb")
}

/// The uids of the fixture assets.
pub const MUG: &str = "0000mug0000000000000000000000000";
/// A book (a plain box).
pub const BOOK: &str = "0000book000000000000000000000000";
/// A lamp (a hierarchy).
pub const LAMP: &str = "0000lamp000000000000000000000000";
/// A pen (a thin box).
pub const PEN: &str = "0000pen0000000000000000000000000";

/// Everything a fixture scene is packed from.
pub struct Fixture {
    /// The layout.
    pub layout: DatasetLayout,
    /// Its bytes.
    pub layout_bytes: Vec<u8>,
    /// The asset GLBs by uid.
    pub assets: BTreeMap<String, Vec<u8>>,
}

fn object(
    instance: &str,
    uid: &str,
    position_cm: [f64; 3],
    yaw_deg: f64,
    size_cm: [f64; 3],
    scale: f64,
    mask: u32,
) -> LayoutObject {
    LayoutObject {
        instance: instance.to_owned(),
        retrieved_uid: uid.to_owned(),
        position_cm: PositionCm(position_cm),
        rotation: QuatXyzw(quat_xyzw_from_yaw_deg(yaw_deg)),
        size_cm: SizeCm(size_cm),
        scale_factor: ScaleFactor([scale; 3]),
        category: Some(mesa_schemas::convert::category_of_instance(instance).to_owned()),
        description: Some(format!("a {instance}")),
        z_rotation_deg: Some(yaw_deg),
        provenance: Some(Provenance {
            stage: "place".to_owned(),
            source_instance: Some(mask),
            notes: vec!["on the table".to_owned()],
        }),
        extra: Default::default(),
    }
}

/// Six objects: two mugs of one asset, a book, a turned lamp, `pen_1` and `pen_10` (names
/// that share a prefix).
pub fn fixture() -> Fixture {
    let mut assets = BTreeMap::new();
    assets.insert(MUG.to_owned(), textured_asset());
    assets.insert(
        BOOK.to_owned(),
        box_asset([0.15, 0.03, 0.22], [0.2, 0.3, 0.7]),
    );
    assets.insert(LAMP.to_owned(), hierarchy_asset());
    assets.insert(
        PEN.to_owned(),
        box_asset([0.14, 0.01, 0.01], [0.1, 0.1, 0.8]),
    );
    let sizes: BTreeMap<String, [f64; 3]> = assets
        .iter()
        .map(|(uid, glb)| {
            let baked = super::bake::bake_asset(glb, 0.0).expect("bakes");
            (uid.clone(), baked.size_m)
        })
        .collect();
    let size = |uid: &str, s: f64| sizes[uid].map(|v| v * s * 100.0);
    let mut layout = DatasetLayout {
        schema: LAYOUT_SCHEMA.to_owned(),
        zone_cm: ZoneCm([0.0, 120.0, 0.0, 60.0]),
        restricted_zone_cm: Some(ZoneCm([80.0, 110.0, 30.0, 55.0])),
        objects: vec![
            object("mug_0", MUG, [20.0, 15.0, 5.0], 0.0, size(MUG, 1.0), 1.0, 1),
            object(
                "mug_1",
                MUG,
                [35.0, 20.0, 6.0],
                45.0,
                size(MUG, 1.2),
                1.2,
                2,
            ),
            object(
                "book_0",
                BOOK,
                [60.0, 30.0, 1.5],
                -20.0,
                size(BOOK, 1.0),
                1.0,
                3,
            ),
            object(
                "lamp_0",
                LAMP,
                [10.0, 45.0, 14.0],
                30.0,
                size(LAMP, 1.0),
                1.0,
                4,
            ),
            object(
                "pen_1",
                PEN,
                [70.0, 10.0, 0.5],
                90.0,
                size(PEN, 1.0),
                1.0,
                5,
            ),
            object(
                "pen_10",
                PEN,
                [75.0, 12.0, 0.5],
                80.0,
                size(PEN, 1.1),
                1.1,
                6,
            ),
        ],
        extra: Default::default(),
    };
    layout.sort_objects();
    let layout_bytes = mesa_schemas::json::to_sorted_pretty(&layout).expect("json");
    Fixture {
        layout,
        layout_bytes,
        assets,
    }
}

/// A 64×48 photo with a 10×8 mask per object.
pub fn photo_and_masks(layout: &DatasetLayout) -> (Vec<u8>, Photo, BTreeMap<String, Vec<u32>>) {
    let (w, h) = (64usize, 48usize);
    let rgb: Vec<[u8; 3]> = (0..w * h)
        .map(|i| [(i % 251) as u8, (i % 17 * 10) as u8, 90])
        .collect();
    let flat: Vec<u8> = rgb.iter().flatten().copied().collect();
    let png = crate::image_io::encode_rgb8(w as u32, h as u32, &flat).expect("png");
    let mut masks = BTreeMap::new();
    for (k, o) in layout.objects.iter().enumerate() {
        let (u0, v0) = ((k * 9) % 50, (k * 7) % 36);
        let pixels = (v0..v0 + 8)
            .flat_map(|v| (u0..u0 + 10).map(move |u| (v * w + u) as u32))
            .collect();
        masks.insert(o.instance.clone(), pixels);
    }
    (
        png,
        Photo {
            width: w,
            height: h,
            rgb,
        },
        masks,
    )
}

/// Packs a fixture (with its photo and masks).
pub fn pack(f: &Fixture, config: &PackConfig) -> PackOutput {
    let assets = AssetSource::facing_front(&f.assets);
    let (png, photo, masks) = photo_and_masks(&f.layout);
    pack_scene(
        &PackRequest {
            scene_id: "office_table_0001",
            table_type: "office_table",
            layout: &f.layout,
            layout_rel: "coarse/layout.json",
            layout_bytes: &f.layout_bytes,
            assets: &assets,
            photo: Some((&png, &photo)),
            masks: &masks,
        },
        config,
    )
    .expect("packs")
}

/// The JSON and BIN chunks of a GLB.
pub fn split_glb(glb: &[u8]) -> (gltf_json::Root, Vec<u8>) {
    let json_len = u32::from_le_bytes(glb[12..16].try_into().expect("4")) as usize;
    let root: gltf_json::Root = serde_json::from_slice(&glb[20..20 + json_len]).expect("json");
    let bin_at = 20 + json_len;
    let bin = if bin_at + 8 <= glb.len() {
        glb[bin_at + 8..].to_vec()
    } else {
        Vec::new()
    };
    (root, bin)
}

/// A GLB from a JSON document (any serialisable value) and a BIN chunk.
pub fn join_glb(json: &[u8], bin: &[u8]) -> Vec<u8> {
    let mut json = json.to_vec();
    while json.len() % 4 != 0 {
        json.push(b' ');
    }
    let mut out = b"glTF".to_vec();
    out.extend_from_slice(&2u32.to_le_bytes());
    let total = 12 + 8 + json.len() + if bin.is_empty() { 0 } else { 8 + bin.len() };
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    if !bin.is_empty() {
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(bin);
    }
    out
}

/// The GLB with its JSON and BIN chunk edited by `edit`.
pub fn edit_glb(glb: &[u8], edit: impl FnOnce(&mut serde_json::Value, &mut Vec<u8>)) -> Vec<u8> {
    let json_len = u32::from_le_bytes(glb[12..16].try_into().expect("4")) as usize;
    let mut json: serde_json::Value =
        serde_json::from_slice(&glb[20..20 + json_len]).expect("json");
    let (_, mut bin) = split_glb(glb);
    edit(&mut json, &mut bin);
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    if let Some(buffer) = json.pointer_mut("/buffers/0/byteLength") {
        if buffer.as_u64().is_some_and(|n| n as usize <= bin.len()) {
            *buffer = serde_json::json!(bin.len());
        }
    }
    join_glb(&serde_json::to_vec(&json).expect("json"), &bin)
}

/// The index of the node named `name` in a JSON document.
pub fn node_at(json: &serde_json::Value, name: &str) -> usize {
    json["nodes"]
        .as_array()
        .expect("nodes")
        .iter()
        .position(|n| n["name"] == name)
        .unwrap_or_else(|| panic!("no node {name}"))
}

/// The index of the node named `name`.
pub fn node(root: &gltf_json::Root, name: &str) -> usize {
    root.nodes
        .iter()
        .position(|n| n.name.as_deref() == Some(name))
        .unwrap_or_else(|| panic!("no node {name}"))
}
