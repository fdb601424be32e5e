//! The demo's asset library: procedural tabletop objects at real sizes, modelled as library
//! assets are (metres, +Y up, front facing +Z), written as GLB files with their
//! MesaTask/objathor annotations.
//!
//! Some assets are textured (embedded PNG), some plain; some are one node with several
//! primitives, some a hierarchy of nodes with their own transforms, one is modelled in
//! centimetres under a root node scaled by 0.01. A few are not meant for tabletop scenes
//! (`onTable: false`), are marked for deletion or are composites, so that retrieval's filters
//! have something to filter.

use std::collections::BTreeMap;
use std::f64::consts::PI;
use std::sync::Arc;

use serde_json::{json, Value};
use sha2::{Digest, Sha256};

use super::shapes::{
    band, block, dish, dish_inner_height, ellipsoid, rod_along_x, smooth_shell, smooth_solid,
    vessel,
};
use super::textures::{self, Srgb};
use crate::glb_write::{GlbBuilder, GlbWriteError, MaterialSpec, NodeSpec};
use crate::mesh::{quat_from_axis_angle, table_from_gltf, Aabb, Affine3, LatheOptions, TriMesh};
use crate::raster::{srgb_u8_to_linear, SurfaceMaterial, Texture};

/// A material of an asset.
#[derive(Debug, Clone)]
pub(crate) struct MaterialDef {
    pub name: &'static str,
    /// Base colour (sRGB); white when a texture carries the colour.
    pub srgb: Srgb,
    pub roughness: f32,
    pub metallic: f32,
    pub texture: Option<Arc<Texture>>,
}

/// One node of an asset: its primitives (mesh, material index) and its transform relative to
/// its parent (another part, or the asset's root node).
#[derive(Debug, Clone)]
pub(crate) struct PartDef {
    pub name: &'static str,
    pub primitives: Vec<(TriMesh, usize)>,
    pub translation: [f64; 3],
    pub rotation_xyzw: [f64; 4],
    pub parent: Option<usize>,
}

/// How a scene may turn an object about the vertical.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum YawRule {
    /// Facing the observer, within ± the given degrees.
    Front(f64),
    /// Any yaw.
    Any,
}

/// Where on the table an object prefers to stand.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Region {
    Front,
    Back,
    Anywhere,
}

/// A surface other objects can be put on or in, in the asset's glTF frame (centred on the
/// asset's origin in X and Z).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Surface {
    /// Inside a circle of this radius (a bowl's or a cup's inside, a plate's flat centre).
    Round { radius_m: f64 },
    /// Inside a rectangle of these half extents along X and Z (a tray, a book's cover).
    Rect { half_x_m: f64, half_z_m: f64 },
}

/// How the annotation states the bounding box (MesaTask's reader accepts all of them).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum BboxForm {
    Extents,
    Size,
    MinMax,
    MinMaxPoint,
}

/// Everything that defines one asset.
#[derive(Debug, Clone)]
pub(crate) struct AssetDef {
    /// Stable key (the uid is derived from it).
    pub key: &'static str,
    pub category: &'static str,
    /// What a vision-language model would call it (the instance label).
    pub label: &'static str,
    /// The annotation's description (the library's wording).
    pub description: &'static str,
    /// Descriptions of the object as seen in a photo (a different wording).
    pub instance_descriptions: &'static [&'static str],
    pub materials: Vec<MaterialDef>,
    pub parts: Vec<PartDef>,
    /// Scale of the root node (0.01 for an asset modelled in centimetres).
    pub root_scale: f64,
    pub on_table: bool,
    pub mark_deletion: bool,
    pub is_composite: bool,
    pub is_container: bool,
    /// Write the objathor key `receptacle` instead of `isContainer`.
    pub receptacle_key: bool,
    pub material_names: &'static [&'static str],
    pub mass_kg: f64,
    pub bbox_form: BboxForm,
    pub yaw: YawRule,
    pub region: Region,
    /// Where other objects can go on or in it.
    pub surface: Option<Surface>,
    /// Height of that surface above the asset's origin, metres (glTF Y), at its centre.
    pub surface_height_m: f64,
    /// Whether scenes use it.
    pub in_scenes: bool,
}

/// An asset ready to use: its uid, its geometry baked into the asset frame, and its GLB.
#[derive(Debug, Clone)]
pub(crate) struct DemoAsset {
    pub def: AssetDef,
    /// 32 hexadecimal characters, like Objaverse uids.
    pub uid: String,
    /// The same triangles in table axes (x right, y back, z up), same origin.
    pub baked_table_axes: Vec<(TriMesh, usize)>,
    /// Bounds in the asset's glTF frame.
    pub bounds_gltf: Aabb,
    /// Bounds in table axes.
    pub bounds_table_axes: Aabb,
    /// Materials for the rasterizer (linear colours).
    pub surface_materials: Vec<SurfaceMaterial>,
    /// The GLB file.
    pub glb: Vec<u8>,
}

fn uid_of(key: &str) -> String {
    let digest = Sha256::digest(format!("mesa-demo-asset/{key}").as_bytes());
    digest[..16].iter().map(|b| format!("{b:02x}")).collect()
}

fn linear(srgb: Srgb) -> [f32; 3] {
    srgb.map(srgb_u8_to_linear)
}

impl DemoAsset {
    fn build(def: AssetDef) -> Result<Self, GlbWriteError> {
        let uid = uid_of(def.key);
        // Each part's transform in the asset frame.
        let root = Affine3::from_scale([def.root_scale; 3]);
        let mut frames: Vec<Affine3> = Vec::with_capacity(def.parts.len());
        for part in &def.parts {
            let local = Affine3::from_trs(part.translation, part.rotation_xyzw, [1.0; 3]);
            let parent = part.parent.map(|p| frames[p]).unwrap_or(root);
            frames.push(parent.mul(&local));
        }
        let baked: Vec<(TriMesh, usize)> = def
            .parts
            .iter()
            .zip(&frames)
            .flat_map(|(part, frame)| {
                part.primitives
                    .iter()
                    .map(move |(mesh, material)| (mesh.transformed(frame), *material))
            })
            .collect();
        let to_table = table_from_gltf();
        let baked_table_axes: Vec<(TriMesh, usize)> = baked
            .iter()
            .map(|(m, i)| (m.transformed(&to_table), *i))
            .collect();
        let union = |meshes: &[(TriMesh, usize)]| {
            meshes
                .iter()
                .filter_map(|(m, _)| m.bounds())
                .reduce(|a, b| a.union(&b))
                .unwrap_or(Aabb::from_point([0.0; 3]))
        };
        let bounds_gltf = union(&baked);
        let bounds_table_axes = union(&baked_table_axes);
        let surface_materials = def
            .materials
            .iter()
            .map(|m| SurfaceMaterial {
                base_color: linear(m.srgb),
                texture: m.texture.clone(),
                roughness: m.roughness,
            })
            .collect();
        let glb = write_glb(&def, &uid)?;
        Ok(Self {
            def,
            uid,
            baked_table_axes,
            bounds_gltf,
            bounds_table_axes,
            surface_materials,
            glb,
        })
    }

    /// The annotation entry (MesaTask `Asset_annotation.json` / objathor form).
    pub(crate) fn annotation(&self) -> Value {
        let d = &self.def;
        let b = &self.bounds_gltf;
        let r4 = |v: f64| (v * 1e4).round() / 1e4;
        let size = b.size().map(r4);
        let extents = json!({"x": size[0], "y": size[1], "z": size[2]});
        let corner = |p: [f64; 3]| json!({"x": r4(p[0]), "y": r4(p[1]), "z": r4(p[2])});
        let mut entry = BTreeMap::new();
        let bbox = match d.bbox_form {
            BboxForm::Extents => extents,
            BboxForm::Size => json!({ "size": extents }),
            BboxForm::MinMax => json!({"min": corner(b.min), "max": corner(b.max)}),
            BboxForm::MinMaxPoint => {
                entry.insert("min_point", json!(b.min.map(r4)));
                entry.insert("max_point", json!(b.max.map(r4)));
                Value::Null
            }
        };
        if !bbox.is_null() {
            entry.insert("bbox", bbox);
        }
        entry.insert("category", json!(d.category));
        entry.insert("description", json!(d.description));
        entry.insert("onTable", json!(d.on_table));
        entry.insert(
            if d.receptacle_key {
                "receptacle"
            } else {
                "isContainer"
            },
            json!(d.is_container),
        );
        entry.insert("frontView", json!(0));
        entry.insert("materials", json!(d.material_names));
        entry.insert("mass", json!(d.mass_kg));
        if d.mark_deletion {
            entry.insert("mark_deletion", json!(true));
        }
        if d.is_composite {
            entry.insert("is_composite", json!(true));
        }
        json!(entry)
    }
}

fn write_glb(def: &AssetDef, uid: &str) -> Result<Vec<u8>, GlbWriteError> {
    let mut b = GlbBuilder::new(concat!("mesa demo ", env!("CARGO_PKG_VERSION")));
    let mut materials = Vec::with_capacity(def.materials.len());
    for m in &def.materials {
        let texture = match &m.texture {
            Some(t) => {
                let png =
                    crate::image_io::encode_rgba8(t.width, t.height, &t.rgba).map_err(|e| {
                        GlbWriteError::NotPng {
                            name: format!("{} ({e})", m.name),
                        }
                    })?;
                Some(b.add_png_texture(m.name, &png)?)
            }
            None => None,
        };
        let c = linear(m.srgb);
        materials.push(b.add_material(&MaterialSpec {
            name: m.name.to_owned(),
            base_color_factor: [c[0], c[1], c[2], 1.0],
            base_color_texture: texture,
            metallic: m.metallic,
            roughness: m.roughness,
            ..MaterialSpec::plain(m.name, [1.0; 3], 1.0)
        }));
    }
    // Children before parents: parts are listed parents first, so go backwards.
    let mut nodes = vec![None; def.parts.len()];
    for i in (0..def.parts.len()).rev() {
        let part = &def.parts[i];
        let prims: Vec<(&TriMesh, _)> = part
            .primitives
            .iter()
            .map(|(m, k)| (m, materials[*k]))
            .collect();
        let mut spec = NodeSpec::new(part.name)
            .with_translation(part.translation)
            .with_rotation_xyzw(part.rotation_xyzw);
        if !prims.is_empty() {
            spec = spec.with_mesh(b.add_mesh(part.name, &prims)?);
        }
        let children: Vec<_> = (i + 1..def.parts.len())
            .filter(|&c| def.parts[c].parent == Some(i))
            .filter_map(|c| nodes[c])
            .collect();
        nodes[i] = Some(b.add_node(spec.with_children(children))?);
    }
    let top: Vec<_> = (0..def.parts.len())
        .filter(|&i| def.parts[i].parent.is_none())
        .filter_map(|i| nodes[i])
        .collect();
    let root = b.add_node(
        NodeSpec::new(def.key)
            .with_scale([def.root_scale; 3])
            .with_children(top)
            .with_extras(json!({"uid": uid})),
    )?;
    b.set_scene(def.key, vec![root]);
    b.finish()
}

// ---------------------------------------------------------------------------------------------
// A small builder for the catalogue.

struct Builder {
    materials: Vec<MaterialDef>,
    parts: Vec<PartDef>,
}

impl Builder {
    fn new() -> Self {
        Self {
            materials: Vec::new(),
            parts: Vec::new(),
        }
    }

    fn plain(&mut self, name: &'static str, srgb: Srgb, roughness: f32, metallic: f32) -> usize {
        self.materials.push(MaterialDef {
            name,
            srgb,
            roughness,
            metallic,
            texture: None,
        });
        self.materials.len() - 1
    }

    fn textured(&mut self, name: &'static str, texture: Texture, roughness: f32) -> usize {
        self.materials.push(MaterialDef {
            name,
            srgb: [255, 255, 255],
            roughness,
            metallic: 0.0,
            texture: Some(Arc::new(texture)),
        });
        self.materials.len() - 1
    }

    fn part(&mut self, name: &'static str, primitives: Vec<(TriMesh, usize)>) -> usize {
        self.part_at(name, primitives, [0.0; 3], [0.0, 0.0, 0.0, 1.0], None)
    }

    fn part_at(
        &mut self,
        name: &'static str,
        primitives: Vec<(TriMesh, usize)>,
        translation: [f64; 3],
        rotation_xyzw: [f64; 4],
        parent: Option<usize>,
    ) -> usize {
        self.parts.push(PartDef {
            name,
            primitives,
            translation,
            rotation_xyzw,
            parent,
        });
        self.parts.len() - 1
    }

    #[allow(clippy::too_many_arguments)]
    fn finish(
        self,
        key: &'static str,
        category: &'static str,
        label: &'static str,
        description: &'static str,
        instance_descriptions: &'static [&'static str],
        material_names: &'static [&'static str],
        mass_kg: f64,
    ) -> AssetDef {
        AssetDef {
            key,
            category,
            label,
            description,
            instance_descriptions,
            materials: self.materials,
            parts: self.parts,
            root_scale: 1.0,
            on_table: true,
            mark_deletion: false,
            is_composite: false,
            is_container: false,
            receptacle_key: false,
            material_names,
            mass_kg,
            bbox_form: BboxForm::Extents,
            yaw: YawRule::Any,
            region: Region::Anywhere,
            surface: None,
            surface_height_m: 0.0,
            in_scenes: true,
        }
    }
}

impl AssetDef {
    fn container(mut self, surface: Surface, floor_m: f64) -> Self {
        self.is_container = true;
        self.surface = Some(surface);
        self.surface_height_m = floor_m;
        self
    }
    fn support(mut self, surface: Surface, top_m: f64) -> Self {
        self.surface = Some(surface);
        self.surface_height_m = top_m;
        self
    }
    fn yaw(mut self, yaw: YawRule) -> Self {
        self.yaw = yaw;
        self
    }
    fn region(mut self, region: Region) -> Self {
        self.region = region;
        self
    }
    fn bbox_form(mut self, form: BboxForm) -> Self {
        self.bbox_form = form;
        self
    }
    fn receptacle(mut self) -> Self {
        self.receptacle_key = true;
        self
    }
}

fn rot_x(deg: f64) -> [f64; 4] {
    quat_from_axis_angle([1.0, 0.0, 0.0], deg.to_radians())
}

// ---------------------------------------------------------------------------------------------
// Drinkware.

/// A mug handle on +X: a tube along an arc whose ends sink into a wall of outer radius
/// `r_wall` and thickness `wall`.
fn mug_handle(r_wall: f64, wall: f64, y_center: f64, arc_radius: f64, tube: f64) -> TriMesh {
    let centre_x = r_wall + arc_radius * 0.2;
    let end_x = r_wall - wall * 0.55;
    let theta = ((end_x - centre_x) / arc_radius).clamp(-1.0, 1.0).acos();
    TriMesh::tube_arc(arc_radius, tube, -theta, theta, 20, 12)
        .transformed(&Affine3::from_translation([centre_x, y_center, 0.0]))
}

fn mug_white() -> AssetDef {
    let mut b = Builder::new();
    let glaze = b.plain("white_glaze", [238, 237, 232], 0.25, 0.0);
    let mut body = vessel(0.041, 0.041, 0.095, 0.0035, 0.007, 0.003, 48);
    body.append(&mug_handle(0.041, 0.0035, 0.05, 0.03, 0.0062));
    b.part("mug", vec![(body, glaze)]);
    b.finish(
        "mug_white",
        "mug",
        "mug",
        "A white ceramic coffee mug with a cylindrical body and a looped handle on one side.",
        &[
            "white ceramic mug with a handle",
            "plain white coffee mug",
            "glossy white mug, cylindrical, curved handle",
        ],
        &["ceramic"],
        0.32,
    )
    .container(Surface::Round { radius_m: 0.0375 }, 0.007)
}

fn mug_striped() -> AssetDef {
    let mut b = Builder::new();
    let stripes = b.textured(
        "navy_stripes",
        textures::bands(&[[245, 244, 238], [32, 52, 98]], 5),
        0.3,
    );
    let navy = b.plain("navy_glaze", [32, 52, 98], 0.3, 0.0);
    let body = vessel(0.04, 0.04, 0.09, 0.0035, 0.007, 0.003, 48);
    let handle = mug_handle(0.04, 0.0035, 0.047, 0.028, 0.006);
    b.part("mug_striped", vec![(body, stripes), (handle, navy)]);
    b.finish(
        "mug_striped",
        "mug",
        "mug",
        "Ceramic mug decorated with horizontal navy and white stripes and a navy handle.",
        &[
            "blue and white striped mug",
            "striped ceramic cup with handle",
            "mug with navy horizontal stripes",
        ],
        &["ceramic"],
        0.3,
    )
    .container(Surface::Round { radius_m: 0.0365 }, 0.007)
}

fn mug_old() -> AssetDef {
    let mut b = Builder::new();
    let glaze = b.plain("beige_glaze", [214, 196, 160], 0.45, 0.0);
    let mut body = vessel(0.042, 0.044, 0.1, 0.004, 0.008, 0.003, 40);
    body.append(&mug_handle(0.043, 0.004, 0.052, 0.03, 0.0065));
    b.part("mug_old", vec![(body, glaze)]);
    let mut def = b.finish(
        "mug_chipped",
        "mug",
        "mug",
        "Beige ceramic mug with a handle and a slightly chipped rim.",
        &["beige mug"],
        &["ceramic"],
        0.34,
    );
    def.mark_deletion = true;
    def.in_scenes = false;
    def.is_container = true;
    def
}

fn cup_paper() -> AssetDef {
    let mut b = Builder::new();
    let paper = b.plain("white_paper", [246, 245, 240], 0.7, 0.0);
    let sleeve = b.textured(
        "kraft_sleeve",
        textures::bands(
            &[[168, 126, 84], [150, 110, 72], [168, 126, 84], [90, 60, 40]],
            2,
        ),
        0.85,
    );
    let (rb, rt, h) = (0.028, 0.04, 0.11);
    let body = vessel(rb, rt, h, 0.0012, 0.004, 0.001, 48);
    let r_at = |y: f64| rb + (rt - rb) * y / h;
    let ring = band(r_at, 0.035, 0.075, 0.0002, 0.0016, 48);
    b.part("cup_paper", vec![(body, paper), (ring, sleeve)]);
    b.finish(
        "cup_paper",
        "cup",
        "cup",
        "Disposable paper coffee cup, white, with a brown cardboard sleeve around the middle.",
        &[
            "paper coffee cup with brown sleeve",
            "white takeaway cup with cardboard sleeve",
            "disposable coffee cup",
        ],
        &["paper", "cardboard"],
        0.012,
    )
    .container(Surface::Round { radius_m: 0.026 }, 0.004)
}

fn cup_glass() -> AssetDef {
    let mut b = Builder::new();
    let glass = b.plain("clear_glass", [196, 214, 218], 0.06, 0.0);
    let body = vessel(0.031, 0.036, 0.1, 0.003, 0.011, 0.002, 48);
    b.part("tumbler", vec![(body, glass)]);
    b.finish(
        "cup_glass",
        "cup",
        "drinking glass",
        "A clear drinking glass tumbler with a thick base and slightly flared sides.",
        &[
            "clear glass tumbler",
            "drinking glass, transparent, tapered",
            "short water glass",
        ],
        &["glass"],
        0.25,
    )
    .container(Surface::Round { radius_m: 0.027 }, 0.011)
    .bbox_form(BboxForm::Size)
}

// ---------------------------------------------------------------------------------------------
// Tableware.

fn bowl_ceramic() -> AssetDef {
    let mut b = Builder::new();
    let glaze = b.plain("pale_blue_glaze", [200, 218, 232], 0.3, 0.0);
    let body = dish(0.075, 0.06, 0.004, 0.03, 1.6, 48);
    b.part("bowl", vec![(body, glaze)]);
    b.finish(
        "bowl_ceramic",
        "bowl",
        "bowl",
        "Small ceramic bowl with a pale blue glaze and a rounded profile.",
        &[
            "small light blue bowl",
            "ceramic bowl, pale blue, round",
            "blue-grey rice bowl",
        ],
        &["ceramic"],
        0.28,
    )
    .container(Surface::Round { radius_m: 0.045 }, 0.004)
}

fn bowl_wooden() -> AssetDef {
    let mut b = Builder::new();
    let wood = b.textured(
        "turned_wood",
        textures::wood([186, 132, 84], [128, 84, 48], 21),
        0.55,
    );
    let body = dish(0.13, 0.085, 0.007, 0.05, 1.8, 56);
    b.part("bowl_wooden", vec![(body, wood)]);
    b.finish(
        "bowl_wooden",
        "bowl",
        "bowl",
        "Large turned wooden salad bowl with visible grain and a wide flat base.",
        &[
            "large wooden bowl",
            "brown wooden fruit bowl",
            "round wooden serving bowl with grain",
        ],
        &["wood"],
        0.7,
    )
    .container(Surface::Round { radius_m: 0.075 }, 0.007)
    .receptacle()
}

pub(crate) const PLATE_DINNER: (f64, f64, f64, f64, f64) = (0.135, 0.022, 0.0035, 0.085, 2.2);

fn plate_dinner() -> AssetDef {
    let mut b = Builder::new();
    let porcelain = b.plain("white_porcelain", [244, 244, 240], 0.2, 0.0);
    let (r, h, w, base, e) = PLATE_DINNER;
    b.part("plate", vec![(dish(r, h, w, base, e, 64), porcelain)]);
    b.finish(
        "plate_dinner",
        "plate",
        "plate",
        "White porcelain dinner plate, round, with a shallow raised rim.",
        &[
            "white dinner plate",
            "round white plate",
            "large white ceramic plate",
        ],
        &["porcelain"],
        0.55,
    )
    .support(
        Surface::Round { radius_m: 0.08 },
        dish_inner_height(0.0, r, h, w, base, e),
    )
}

fn plate_patterned() -> AssetDef {
    let mut b = Builder::new();
    let pattern = b.textured(
        "blue_border",
        textures::rim_pattern([244, 243, 236], [40, 70, 150]),
        0.2,
    );
    let (r, h, w, base, e) = (0.105, 0.018, 0.003, 0.065, 2.0);
    b.part("side_plate", vec![(dish(r, h, w, base, e, 56), pattern)]);
    b.finish(
        "plate_patterned",
        "plate",
        "plate",
        "Side plate in white porcelain with a blue geometric border.",
        &[
            "small plate with blue pattern",
            "white side plate, blue rim decoration",
            "patterned dessert plate",
        ],
        &["porcelain"],
        0.35,
    )
    .support(
        Surface::Round { radius_m: 0.06 },
        dish_inner_height(0.0, r, h, w, base, e),
    )
    .bbox_form(BboxForm::MinMax)
}

fn tray_wooden() -> AssetDef {
    let mut b = Builder::new();
    let wood = b.textured(
        "tray_wood",
        textures::wood([214, 170, 118], [160, 116, 72], 5),
        0.5,
    );
    let (w, d, t, rim_h) = (0.45, 0.30, 0.012, 0.04);
    let base = block([w, t, d], 0.0, 0.0, 0.0);
    let mut rim = block([w, rim_h - t, t], 0.0, t, d / 2.0 - t / 2.0);
    rim.append(&block([w, rim_h - t, t], 0.0, t, -d / 2.0 + t / 2.0));
    rim.append(&block(
        [t, rim_h - t, d - 2.0 * t],
        w / 2.0 - t / 2.0,
        t,
        0.0,
    ));
    rim.append(&block(
        [t, rim_h - t, d - 2.0 * t],
        -w / 2.0 + t / 2.0,
        t,
        0.0,
    ));
    b.part("tray_base", vec![(base, wood)]);
    b.part("tray_rim", vec![(rim, wood)]);
    b.finish(
        "tray_wooden",
        "tray",
        "tray",
        "Rectangular wooden serving tray with low raised edges.",
        &[
            "wooden tray",
            "rectangular serving tray, light wood",
            "flat wooden tray with rim",
        ],
        &["wood"],
        1.1,
    )
    .container(
        Surface::Rect {
            half_x_m: w / 2.0 - t,
            half_z_m: d / 2.0 - t,
        },
        t,
    )
    .yaw(YawRule::Front(12.0))
}

fn cutting_board() -> AssetDef {
    let mut b = Builder::new();
    let wood = b.textured(
        "board_wood",
        textures::wood([222, 184, 132], [176, 132, 84], 9),
        0.6,
    );
    let board = block([0.38, 0.018, 0.25], 0.0, 0.0, 0.0);
    b.part("cutting_board", vec![(board, wood)]);
    b.finish(
        "cutting_board",
        "cutting_board",
        "cutting board",
        "Rectangular wooden chopping board with a fine end-grain pattern.",
        &[
            "wooden cutting board",
            "chopping board, light wood",
            "rectangular wood board",
        ],
        &["wood"],
        1.2,
    )
    .support(
        Surface::Rect {
            half_x_m: 0.17,
            half_z_m: 0.11,
        },
        0.018,
    )
    .yaw(YawRule::Front(25.0))
}

// ---------------------------------------------------------------------------------------------
// Books and paper.

/// What distinguishes one book from another.
struct BookSpec {
    key: &'static str,
    /// Width, thickness, depth (glTF X, Y, Z), metres.
    size: [f64; 3],
    cover: Srgb,
    accent: Srgb,
    salt: u64,
    description: &'static str,
    instance_descriptions: &'static [&'static str],
    mass_kg: f64,
}

fn book(spec: BookSpec) -> AssetDef {
    let mut b = Builder::new();
    let cover_m = b.textured(
        spec.key,
        textures::book_cover(spec.cover, spec.accent, spec.salt),
        0.6,
    );
    let pages_m = b.plain("pages", [238, 232, 214], 0.9, 0.0);
    let [w, h, d] = spec.size;
    let board = 0.003;
    let mut covers = block([w, board, d], 0.0, 0.0, 0.0);
    covers.append(&block([w, board, d], 0.0, h - board, 0.0));
    covers.append(&block([board, h, d], -w / 2.0 + board / 2.0, 0.0, 0.0));
    let pages = block([w - 0.005, h - 2.0 * board, d - 0.006], 0.002, board, 0.0);
    b.part("book", vec![(covers, cover_m), (pages, pages_m)]);
    b.finish(
        spec.key,
        "book",
        "book",
        spec.description,
        spec.instance_descriptions,
        &["paper", "cardboard"],
        spec.mass_kg,
    )
    .support(
        Surface::Rect {
            half_x_m: w / 2.0 - 0.01,
            half_z_m: d / 2.0 - 0.01,
        },
        h,
    )
}

fn notebook() -> AssetDef {
    let mut b = Builder::new();
    let paper = b.textured("ruled_paper", textures::ruled_paper(), 0.85);
    let back = b.plain("cardboard_back", [120, 100, 80], 0.9, 0.0);
    let wire = b.plain("spiral_wire", [170, 170, 175], 0.3, 0.8);
    let (w, h, d) = (0.15, 0.012, 0.21);
    let pad = block([w, h - 0.002, d], 0.0, 0.002, 0.0);
    let backing = block([w, 0.002, d], 0.0, 0.0, 0.0);
    let mut spiral = TriMesh::default();
    for k in 0..14 {
        let z = -d / 2.0 + 0.012 + k as f64 * (d - 0.024) / 13.0;
        let ring = TriMesh::tube_arc(0.007, 0.0008, -PI / 2.0, PI, 12, 6);
        // Rings in the XY plane around the left edge, stacked along Z.
        spiral.append(&ring.transformed(&Affine3::from_translation([
            -w / 2.0 + 0.004,
            h / 2.0,
            z,
        ])));
    }
    b.part(
        "notepad",
        vec![(pad, paper), (backing, back), (spiral, wire)],
    );
    b.finish(
        "notebook_spiral",
        "notebook",
        "notebook",
        "Spiral-bound notepad with ruled pages and a red margin line.",
        &[
            "spiral notebook",
            "lined notepad",
            "open notepad with blue lines",
        ],
        &["paper", "metal"],
        0.18,
    )
    .region(Region::Front)
    .support(
        Surface::Rect {
            half_x_m: 0.06,
            half_z_m: 0.09,
        },
        h,
    )
}

// ---------------------------------------------------------------------------------------------
// Electronics.

fn laptop() -> AssetDef {
    let mut b = Builder::new();
    let aluminium = b.plain("aluminium", [196, 198, 202], 0.35, 0.7);
    let keys = b.textured(
        "keyboard_keys",
        textures::keys([40, 40, 44], [70, 70, 76]),
        0.6,
    );
    let pad = b.plain("touchpad", [170, 172, 176], 0.4, 0.3);
    let display = b.textured(
        "display",
        textures::screen([40, 90, 170], [120, 60, 150], [235, 236, 240]),
        0.15,
    );
    let bezel = b.plain("bezel", [30, 30, 34], 0.3, 0.0);
    let (w, h, d) = (0.32, 0.016, 0.22);
    let base_body = block([w, h, d], 0.0, 0.0, 0.0);
    let deck = block([0.28, 0.0008, 0.11], 0.0, h, -0.03);
    let touch = block([0.1, 0.0006, 0.06], 0.0, h, 0.065);
    let base = b.part(
        "laptop_base",
        vec![(base_body, aluminium), (deck, keys), (touch, pad)],
    );
    // The lid, hinged at the back edge and opened 110° (tilted back 20° from upright).
    let (lid_h, lid_t) = (0.21, 0.006);
    let lid_shell = block([w, lid_h, lid_t], 0.0, 0.0, 0.0);
    let panel = block([w - 0.02, lid_h - 0.025, 0.0006], 0.0, 0.012, lid_t / 2.0);
    let frame = block([w - 0.004, lid_h - 0.004, 0.0004], 0.0, 0.002, lid_t / 2.0);
    b.part_at(
        "laptop_lid",
        vec![(lid_shell, aluminium), (frame, bezel), (panel, display)],
        [0.0, h, -d / 2.0 + lid_t / 2.0],
        rot_x(-20.0),
        Some(base),
    );
    b.finish(
        "laptop_silver",
        "laptop",
        "laptop",
        "Open silver laptop with a black keyboard and a lit screen showing a desktop.",
        &[
            "open silver laptop",
            "laptop computer, screen on",
            "thin grey laptop with keyboard",
        ],
        &["aluminium", "plastic", "glass"],
        1.4,
    )
    .yaw(YawRule::Front(15.0))
}

fn keyboard() -> AssetDef {
    // Modelled in centimetres under a root scaled by 0.01, as some exporters do.
    let mut b = Builder::new();
    let body_m = b.plain("keyboard_body", [34, 34, 38], 0.5, 0.0);
    let keys = b.textured(
        "keycaps",
        textures::keys([34, 34, 38], [150, 152, 158]),
        0.55,
    );
    let body = block([44.0, 2.0, 13.0], 0.0, 0.0, 0.0);
    let keycaps = block([42.0, 0.4, 11.5], 0.0, 2.0, 0.0);
    b.part("keyboard", vec![(body, body_m), (keycaps, keys)]);
    let mut def = b
        .finish(
            "keyboard_black",
            "keyboard",
            "keyboard",
            "Full-size black wireless keyboard with light grey keys.",
            &[
                "black computer keyboard",
                "wireless keyboard, dark with grey keys",
                "full-size keyboard",
            ],
            &["plastic"],
            0.6,
        )
        .yaw(YawRule::Front(8.0))
        .region(Region::Front)
        .bbox_form(BboxForm::MinMaxPoint);
    def.root_scale = 0.01;
    def
}

fn mouse() -> AssetDef {
    let mut b = Builder::new();
    let shell = b.plain("mouse_shell", [120, 122, 128], 0.45, 0.0);
    let wheel_m = b.plain("scroll_wheel", [25, 25, 28], 0.6, 0.0);
    let dome = TriMesh::lathe(
        &[
            [0.0, 0.0],
            [0.96, 0.0],
            [1.0, 0.12],
            [0.92, 0.5],
            [0.7, 0.82],
            [0.38, 0.97],
            [0.0, 1.0],
        ],
        LatheOptions::default()
            .with_segments(32)
            .with_smooth_angle_deg(60.0),
    )
    .transformed(&Affine3::from_scale([0.031, 0.036, 0.056]));
    let wheel = TriMesh::cylinder(0.009, 0.006, 16).transformed(&Affine3::from_trs(
        [-0.003, 0.03, 0.025],
        quat_from_axis_angle([0.0, 0.0, 1.0], PI / 2.0),
        [1.0; 3],
    ));
    b.part("mouse", vec![(dome, shell), (wheel, wheel_m)]);
    b.finish(
        "mouse_grey",
        "computer_mouse",
        "computer mouse",
        "Ergonomic computer mouse in matte grey with a black scroll wheel.",
        &[
            "grey computer mouse",
            "wireless mouse",
            "small grey mouse with scroll wheel",
        ],
        &["plastic"],
        0.09,
    )
    .yaw(YawRule::Front(20.0))
    .region(Region::Front)
}

fn phone() -> AssetDef {
    let mut b = Builder::new();
    let body_m = b.plain("phone_body", [28, 28, 32], 0.3, 0.2);
    let screen = b.textured("phone_screen", textures::phone_screen(), 0.1);
    let body = block([0.075, 0.008, 0.155], 0.0, 0.0, 0.0);
    let glass = block([0.069, 0.0005, 0.147], 0.0, 0.008, 0.0);
    b.part("phone", vec![(body, body_m), (glass, screen)]);
    b.finish(
        "phone_black",
        "smartphone",
        "phone",
        "Black smartphone lying flat, screen on, showing app icons.",
        &[
            "black smartphone",
            "mobile phone with screen on",
            "phone lying face up",
        ],
        &["glass", "aluminium"],
        0.19,
    )
    .region(Region::Front)
}

fn remote() -> AssetDef {
    let mut b = Builder::new();
    let body_m = b.plain("remote_body", [35, 35, 38], 0.5, 0.0);
    let buttons = b.textured("remote_buttons", textures::remote_buttons(), 0.6);
    let body = block([0.05, 0.02, 0.2], 0.0, 0.0, 0.0);
    let top = block([0.044, 0.0006, 0.19], 0.0, 0.02, 0.0);
    b.part("remote", vec![(body, body_m), (top, buttons)]);
    b.finish(
        "remote_control",
        "remote_control",
        "remote control",
        "Black TV remote control with grey rubber buttons and a red power key.",
        &[
            "TV remote",
            "black remote control",
            "remote with grey buttons",
        ],
        &["plastic", "rubber"],
        0.12,
    )
    .region(Region::Front)
}

// ---------------------------------------------------------------------------------------------
// Bottles and jars.

fn bottle_water() -> AssetDef {
    let mut b = Builder::new();
    let plastic = b.plain("bottle_plastic", [176, 208, 230], 0.12, 0.0);
    let cap_m = b.plain("blue_cap", [30, 80, 170], 0.4, 0.0);
    let body = smooth_solid(
        &[
            [0.03, 0.0],
            [0.033, 0.006],
            [0.033, 0.08],
            [0.031, 0.1],
            [0.033, 0.15],
            [0.026, 0.185],
            [0.0145, 0.2],
            [0.0145, 0.212],
        ],
        5,
        36,
    );
    let cap = TriMesh::cylinder(0.0155, 0.02, 24)
        .transformed(&Affine3::from_translation([0.0, 0.21, 0.0]));
    b.part("water_bottle", vec![(body, plastic), (cap, cap_m)]);
    b.finish(
        "bottle_water",
        "bottle",
        "bottle",
        "Plastic water bottle with a blue screw cap, about half a litre.",
        &[
            "plastic water bottle",
            "clear bottle with blue cap",
            "bottle of water",
        ],
        &["plastic"],
        0.52,
    )
    .region(Region::Back)
}

fn bottle_wine() -> AssetDef {
    let mut b = Builder::new();
    let glass = b.plain("green_glass", [34, 74, 44], 0.08, 0.0);
    let label_m = b.textured(
        "wine_label",
        textures::label([236, 226, 200], [110, 30, 40]),
        0.7,
    );
    let foil = b.plain("red_foil", [120, 20, 30], 0.3, 0.6);
    let body = smooth_solid(
        &[
            [0.034, 0.0],
            [0.037, 0.005],
            [0.037, 0.19],
            [0.03, 0.22],
            [0.016, 0.25],
            [0.0145, 0.3],
        ],
        5,
        40,
    );
    let label = band(|_| 0.037, 0.05, 0.14, 0.0003, 0.0006, 40);
    let capsule = TriMesh::cylinder(0.0158, 0.05, 24)
        .transformed(&Affine3::from_translation([0.0, 0.255, 0.0]));
    b.part(
        "wine_bottle",
        vec![(body, glass), (label, label_m), (capsule, foil)],
    );
    b.finish(
        "bottle_wine",
        "bottle",
        "wine bottle",
        "Dark green glass wine bottle with a cream paper label and a red foil capsule.",
        &[
            "green wine bottle with label",
            "bottle of red wine",
            "tall dark glass bottle",
        ],
        &["glass", "paper"],
        1.25,
    )
    .region(Region::Back)
    .bbox_form(BboxForm::Size)
}

fn jar() -> AssetDef {
    let mut b = Builder::new();
    let glass = b.plain("jar_glass", [192, 210, 200], 0.1, 0.0);
    let lid_m = b.plain("brushed_lid", [180, 180, 184], 0.3, 0.9);
    let body = smooth_solid(
        &[
            [0.05, 0.0],
            [0.055, 0.008],
            [0.055, 0.13],
            [0.047, 0.142],
            [0.047, 0.148],
        ],
        4,
        40,
    );
    let lid = TriMesh::cylinder(0.05, 0.02, 40)
        .transformed(&Affine3::from_translation([0.0, 0.145, 0.0]));
    b.part("jar", vec![(body, glass), (lid, lid_m)]);
    b.finish(
        "jar_glass",
        "jar",
        "jar",
        "Glass storage jar with a brushed metal screw lid.",
        &[
            "glass jar with metal lid",
            "storage jar",
            "kitchen canister, glass",
        ],
        &["glass", "metal"],
        0.6,
    )
    .region(Region::Back)
    .receptacle()
}

fn vase() -> AssetDef {
    let mut b = Builder::new();
    let glaze = b.plain("teal_glaze", [52, 124, 134], 0.25, 0.0);
    let body = smooth_shell(
        &[
            [0.042, 0.0],
            [0.058, 0.05],
            [0.061, 0.09],
            [0.045, 0.16],
            [0.028, 0.21],
            [0.034, 0.25],
        ],
        0.005,
        0.012,
        6,
        48,
    );
    b.part("vase", vec![(body, glaze)]);
    let mut def = b
        .finish(
            "vase_ceramic",
            "vase",
            "vase",
            "Tall ceramic vase in teal glaze with a rounded belly and a narrow neck.",
            &[
                "teal ceramic vase",
                "tall green-blue vase",
                "round-bellied flower vase",
            ],
            &["ceramic"],
            0.9,
        )
        .region(Region::Back)
        .receptacle();
    def.is_container = true;
    def
}

fn soap_dispenser() -> AssetDef {
    let mut b = Builder::new();
    let amber = b.plain("amber_glass", [176, 112, 48], 0.1, 0.0);
    let chrome = b.plain("chrome", [210, 212, 216], 0.15, 1.0);
    let body_mesh = smooth_solid(
        &[
            [0.032, 0.0],
            [0.035, 0.008],
            [0.035, 0.12],
            [0.026, 0.138],
            [0.013, 0.142],
        ],
        5,
        36,
    );
    let body = b.part("soap_body", vec![(body_mesh, amber)]);
    let mut pump = TriMesh::cylinder(0.015, 0.012, 24);
    pump.append(
        &TriMesh::cylinder(0.004, 0.03, 12)
            .transformed(&Affine3::from_translation([0.0, 0.012, 0.0])),
    );
    pump.append(&block([0.014, 0.012, 0.045], 0.0, 0.04, 0.012));
    b.part_at(
        "soap_pump",
        vec![(pump, chrome)],
        [0.0, 0.14, 0.0],
        [0.0, 0.0, 0.0, 1.0],
        Some(body),
    );
    b.finish(
        "soap_dispenser",
        "soap_bottle",
        "soap dispenser",
        "Liquid soap dispenser with an amber glass bottle and a chrome pump.",
        &[
            "soap dispenser with pump",
            "amber soap pump bottle",
            "hand soap bottle",
        ],
        &["glass", "metal"],
        0.45,
    )
    .yaw(YawRule::Front(30.0))
    .region(Region::Back)
}

fn lotion_bottle() -> AssetDef {
    let mut b = Builder::new();
    let pink = b.plain("pink_plastic", [236, 206, 200], 0.35, 0.0);
    let white = b.plain("white_cap", [245, 245, 245], 0.3, 0.0);
    let body = TriMesh::lathe(
        &[
            [0.0, 0.0],
            [0.94, 0.0],
            [1.0, 0.01],
            [1.0, 0.15],
            [0.72, 0.163],
            [0.0, 0.165],
        ],
        LatheOptions::default()
            .with_segments(36)
            .with_smooth_angle_deg(40.0),
    )
    .transformed(&Affine3::from_scale([0.032, 1.0, 0.021]));
    let cap = TriMesh::cylinder(0.0125, 0.025, 24)
        .transformed(&Affine3::from_translation([0.0, 0.164, 0.0]));
    b.part("lotion", vec![(body, pink), (cap, white)]);
    b.finish(
        "lotion_bottle",
        "lotion_bottle",
        "lotion bottle",
        "Oval plastic lotion bottle in pale pink with a white flip cap.",
        &[
            "pink lotion bottle",
            "body lotion bottle with white cap",
            "plastic cosmetic bottle",
        ],
        &["plastic"],
        0.28,
    )
    .yaw(YawRule::Front(25.0))
    .region(Region::Back)
}

fn perfume_bottle() -> AssetDef {
    let mut b = Builder::new();
    let glass = b.plain("perfume_glass", [232, 206, 160], 0.05, 0.0);
    let gold = b.plain("gold", [212, 170, 80], 0.2, 1.0);
    let body = block([0.055, 0.075, 0.032], 0.0, 0.0, 0.0);
    let mut cap = TriMesh::cylinder(0.005, 0.008, 12)
        .transformed(&Affine3::from_translation([0.0, 0.075, 0.0]));
    cap.append(
        &TriMesh::cylinder(0.012, 0.025, 24)
            .transformed(&Affine3::from_translation([0.0, 0.083, 0.0])),
    );
    b.part("perfume", vec![(body, glass), (cap, gold)]);
    b.finish(
        "perfume_bottle",
        "perfume_bottle",
        "perfume bottle",
        "Square glass perfume bottle with a gold cylindrical cap.",
        &[
            "glass perfume bottle",
            "square fragrance bottle with gold cap",
            "small perfume bottle",
        ],
        &["glass", "metal"],
        0.2,
    )
    .yaw(YawRule::Front(20.0))
    .region(Region::Back)
}

// ---------------------------------------------------------------------------------------------
// Desk and bathroom things.

fn desk_lamp() -> AssetDef {
    let mut b = Builder::new();
    let metal = b.plain("black_metal", [26, 26, 29], 0.4, 0.6);
    let inner = b.plain("shade_inner", [236, 228, 204], 0.6, 0.0);
    let bulb_m = b.plain("bulb", [255, 246, 214], 0.2, 0.0);
    let base_mesh = TriMesh::lathe(
        &[
            [0.0, 0.0],
            [0.075, 0.0],
            [0.075, 0.012],
            [0.06, 0.022],
            [0.0, 0.022],
        ],
        LatheOptions::default().with_segments(40),
    );
    let base = b.part("lamp_base", vec![(base_mesh, metal)]);
    let lower = b.part_at(
        "lamp_arm_lower",
        vec![(TriMesh::cylinder(0.007, 0.26, 16), metal)],
        [0.0, 0.02, -0.03],
        rot_x(-15.0),
        Some(base),
    );
    let upper = b.part_at(
        "lamp_arm_upper",
        vec![(TriMesh::cylinder(0.006, 0.2, 16), metal)],
        [0.0, 0.26, 0.0],
        rot_x(75.0),
        Some(lower),
    );
    let outer = TriMesh::lathe(
        &[
            [0.0, 0.0],
            [0.02, 0.0],
            [0.062, 0.1],
            [0.059, 0.1],
            [0.018, 0.004],
            [0.0, 0.004],
        ],
        LatheOptions::default().with_segments(36),
    );
    let lining = TriMesh::lathe(
        &[[0.0575, 0.0985], [0.0175, 0.0055], [0.0, 0.0055]],
        LatheOptions::default().with_segments(36),
    );
    let bulb = ellipsoid([0.018, 0.024, 0.018], [0.0, 0.035, 0.0], 16);
    b.part_at(
        "lamp_head",
        vec![(outer, metal), (lining, inner), (bulb, bulb_m)],
        [0.0, 0.2, 0.0],
        rot_x(65.0),
        Some(upper),
    );
    b.finish(
        "desk_lamp",
        "desk_lamp",
        "desk lamp",
        "Black adjustable desk lamp with a round weighted base, two-part arm and a cone shade.",
        &[
            "black desk lamp",
            "adjustable reading lamp with cone shade",
            "metal desk lamp, black, articulated arm",
        ],
        &["metal"],
        1.6,
    )
    .yaw(YawRule::Front(35.0))
    .region(Region::Back)
}

fn pen() -> AssetDef {
    let mut b = Builder::new();
    let barrel_m = b.plain("blue_barrel", [30, 60, 160], 0.35, 0.0);
    let steel = b.plain("pen_steel", [190, 192, 196], 0.2, 1.0);
    let (r, len) = (0.0045, 0.14);
    let tip = rod_along_x(
        &[
            [0.0, 0.0],
            [0.0012, 0.002],
            [0.0035, 0.014],
            [0.0035, 0.016],
        ],
        16,
        r,
        len,
    );
    let barrel = rod_along_x(
        &[
            [0.0, 0.016],
            [r, 0.016],
            [r, 0.132],
            [0.003, 0.14],
            [0.0, 0.14],
        ],
        16,
        r,
        len,
    );
    let clip = block(
        [0.045, 0.0015, 0.002],
        len / 2.0 - 0.035,
        2.0 * r - 0.0002,
        0.0,
    );
    b.part("pen", vec![(barrel, barrel_m), (tip, steel), (clip, steel)]);
    b.finish(
        "pen_blue",
        "pen",
        "pen",
        "Blue ballpoint pen with a clip and a metal tip.",
        &["blue pen", "ballpoint pen, blue barrel", "plastic pen"],
        &["plastic", "metal"],
        0.012,
    )
    .region(Region::Front)
}

fn pencil() -> AssetDef {
    let mut b = Builder::new();
    let yellow = b.plain("pencil_paint", [240, 196, 40], 0.45, 0.0);
    let wood = b.plain("pencil_wood", [222, 186, 140], 0.8, 0.0);
    let graphite = b.plain("graphite", [50, 50, 55], 0.5, 0.3);
    let ferrule = b.plain("ferrule", [196, 196, 190], 0.25, 1.0);
    let eraser = b.plain("eraser", [236, 140, 150], 0.9, 0.0);
    let (r, len) = (0.0037, 0.175);
    let hex = LatheOptions::default()
        .with_segments(6)
        .with_smooth_angle_deg(10.0);
    let lathe_x = |profile: &[[f64; 2]], options: LatheOptions| {
        let rod = TriMesh::lathe(profile, options);
        let turn = Affine3 {
            linear: [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
            translation: [-len / 2.0, r, 0.0],
        };
        rod.transformed(&turn)
    };
    let round = LatheOptions::default().with_segments(16);
    let point = lathe_x(&[[0.0, 0.0], [0.0011, 0.004], [0.0011, 0.0045]], round);
    let cone = lathe_x(
        &[[0.0011, 0.004], [r * 0.95, 0.02], [r * 0.95, 0.0205]],
        round,
    );
    let body = lathe_x(
        &[[r * 0.95, 0.0205], [r, 0.021], [r, 0.155], [0.0, 0.155]],
        hex,
    );
    let band_m = lathe_x(
        &[
            [0.0, 0.155],
            [r * 1.02, 0.155],
            [r * 1.02, 0.165],
            [0.0, 0.165],
        ],
        round,
    );
    let rubber = lathe_x(
        &[
            [0.0, 0.165],
            [r * 0.97, 0.165],
            [r * 0.97, 0.174],
            [0.0, 0.175],
        ],
        round,
    );
    b.part(
        "pencil",
        vec![
            (body, yellow),
            (cone, wood),
            (point, graphite),
            (band_m, ferrule),
            (rubber, eraser),
        ],
    );
    b.finish(
        "pencil_yellow",
        "pencil",
        "pencil",
        "Yellow wooden pencil, sharpened, with a pink eraser in a metal ferrule.",
        &[
            "yellow pencil",
            "sharpened pencil with eraser",
            "wooden pencil, yellow",
        ],
        &["wood", "graphite", "rubber"],
        0.006,
    )
    .region(Region::Front)
}

fn pen_holder() -> AssetDef {
    let mut b = Builder::new();
    let mesh_m = b.plain("black_mesh_metal", [38, 38, 42], 0.55, 0.7);
    let body = vessel(0.04, 0.04, 0.1, 0.002, 0.004, 0.001, 40);
    b.part("pen_holder", vec![(body, mesh_m)]);
    b.finish(
        "pen_holder",
        "pen_holder",
        "pen holder",
        "Cylindrical black metal mesh pen holder.",
        &[
            "black pen holder",
            "metal pencil cup",
            "desk organizer cup for pens",
        ],
        &["metal"],
        0.2,
    )
    .container(Surface::Round { radius_m: 0.038 }, 0.004)
    .region(Region::Back)
}

fn tissue_box() -> AssetDef {
    let mut b = Builder::new();
    let print = b.textured(
        "floral_dots",
        textures::dots([236, 232, 220], [210, 120, 140], 16),
        0.8,
    );
    let tissue_m = b.plain("tissue", [250, 250, 250], 0.95, 0.0);
    let body = block([0.24, 0.09, 0.12], 0.0, 0.0, 0.0);
    let puff = ellipsoid([0.045, 0.028, 0.03], [0.0, 0.088, 0.0], 20);
    b.part("tissue_box", vec![(body, print), (puff, tissue_m)]);
    b.finish(
        "tissue_box",
        "tissue_box",
        "tissue box",
        "Rectangular tissue box with a floral dot print and a tissue pulled up through the slot.",
        &[
            "tissue box",
            "box of tissues with dotted pattern",
            "rectangular tissue box, white tissue sticking out",
        ],
        &["cardboard", "paper"],
        0.2,
    )
    .yaw(YawRule::Front(25.0))
}

fn toothbrush_cup() -> AssetDef {
    let mut b = Builder::new();
    let glaze = b.plain("mint_glaze", [168, 214, 198], 0.3, 0.0);
    let body = vessel(0.036, 0.039, 0.105, 0.004, 0.008, 0.003, 40);
    b.part("toothbrush_cup", vec![(body, glaze)]);
    b.finish(
        "toothbrush_cup",
        "toothbrush_cup",
        "toothbrush cup",
        "Ceramic bathroom tumbler in mint green for holding toothbrushes.",
        &[
            "toothbrush holder cup",
            "mint green bathroom cup",
            "ceramic cup holding toothbrushes",
        ],
        &["ceramic"],
        0.25,
    )
    .container(Surface::Round { radius_m: 0.032 }, 0.008)
    .region(Region::Back)
}

fn toothbrush() -> AssetDef {
    let mut b = Builder::new();
    let handle_m = b.plain("teal_plastic", [30, 150, 160], 0.35, 0.0);
    let bristle_m = b.plain("bristles", [240, 244, 248], 0.9, 0.0);
    let len = 0.19;
    let mut handle = block([0.125, 0.012, 0.014], -len / 2.0 + 0.0625, 0.0, 0.0);
    handle.append(&block([0.04, 0.008, 0.009], -len / 2.0 + 0.145, 0.002, 0.0));
    handle.append(&block(
        [0.027, 0.006, 0.012],
        len / 2.0 - 0.0135,
        0.002,
        0.0,
    ));
    let bristles = block([0.024, 0.011, 0.01], len / 2.0 - 0.0135, 0.008, 0.0);
    b.part(
        "toothbrush",
        vec![(handle, handle_m), (bristles, bristle_m)],
    );
    b.finish(
        "toothbrush",
        "toothbrush",
        "toothbrush",
        "Manual toothbrush with a teal plastic handle and white bristles.",
        &[
            "toothbrush",
            "teal toothbrush",
            "plastic toothbrush with white bristles",
        ],
        &["plastic", "nylon"],
        0.02,
    )
}

fn candle() -> AssetDef {
    let mut b = Builder::new();
    let wax = b.plain("ivory_wax", [240, 232, 212], 0.6, 0.0);
    let wick_m = b.plain("wick", [30, 26, 22], 0.9, 0.0);
    let body = TriMesh::lathe(
        &[
            [0.0, 0.0],
            [0.035, 0.0],
            [0.035, 0.1],
            [0.031, 0.097],
            [0.0, 0.095],
        ],
        LatheOptions::default().with_segments(40),
    );
    let wick = TriMesh::cylinder(0.0012, 0.013, 8)
        .transformed(&Affine3::from_translation([0.0, 0.094, 0.0]));
    b.part("candle", vec![(body, wax), (wick, wick_m)]);
    b.finish(
        "candle_pillar",
        "candle",
        "candle",
        "Ivory pillar candle with a short black wick.",
        &["white pillar candle", "cream candle", "thick round candle"],
        &["wax"],
        0.4,
    )
}

fn potted_plant() -> AssetDef {
    let mut b = Builder::new();
    let clay = b.plain("terracotta", [186, 98, 62], 0.8, 0.0);
    let soil_m = b.plain("soil", [60, 42, 30], 1.0, 0.0);
    let leaf_m = b.plain("leaf_green", [56, 128, 56], 0.5, 0.0);
    let pot = vessel(0.048, 0.062, 0.11, 0.006, 0.012, 0.002, 40);
    let soil = TriMesh::cylinder(0.056, 0.006, 32)
        .transformed(&Affine3::from_translation([0.0, 0.094, 0.0]));
    let mut leaves = TriMesh::default();
    for k in 0..7 {
        let phi = k as f64 * 2.0 * PI / 7.0 + 0.3;
        let lean = 0.35 + 0.12 * ((k * 3) % 4) as f64;
        let length = 0.08 + 0.012 * ((k * 5) % 3) as f64;
        let leaf = ellipsoid([0.012, length, 0.004], [0.0, length, 0.0], 12);
        let tilt = quat_from_axis_angle([phi.cos(), 0.0, -phi.sin()], lean);
        leaves.append(&leaf.transformed(&Affine3::from_trs([0.0, 0.097, 0.0], tilt, [1.0; 3])));
    }
    b.part("plant", vec![(pot, clay), (soil, soil_m), (leaves, leaf_m)]);
    b.finish(
        "potted_plant",
        "plant",
        "potted plant",
        "Small potted plant with long green leaves in a terracotta pot.",
        &[
            "potted plant",
            "green plant in terracotta pot",
            "small houseplant",
        ],
        &["ceramic", "plant"],
        1.1,
    )
    .region(Region::Back)
}

fn towel() -> AssetDef {
    let mut b = Builder::new();
    let stripes = b.textured(
        "towel_stripes",
        textures::stripes_u(&[[244, 244, 240], [244, 244, 240], [150, 156, 164]], 12),
        0.95,
    );
    let body = block([0.26, 0.055, 0.18], 0.0, 0.0, 0.0);
    b.part("towel", vec![(body, stripes)]);
    b.finish(
        "towel_folded",
        "towel",
        "towel",
        "Folded cotton hand towel with white and grey stripes.",
        &[
            "folded towel",
            "striped hand towel",
            "grey and white towel, folded",
        ],
        &["cotton"],
        0.3,
    )
    .yaw(YawRule::Front(20.0))
    .support(
        Surface::Rect {
            half_x_m: 0.11,
            half_z_m: 0.075,
        },
        0.055,
    )
}

fn jewelry_box() -> AssetDef {
    let mut b = Builder::new();
    let velvet = b.plain("red_velvet", [128, 28, 48], 0.95, 0.0);
    let lid_m = b.textured(
        "lid_wood",
        textures::wood([150, 96, 58], [96, 58, 32], 33),
        0.4,
    );
    let brass = b.plain("brass", [200, 160, 70], 0.25, 1.0);
    let body_mesh = block([0.16, 0.05, 0.11], 0.0, 0.0, 0.0);
    let body = b.part("box_body", vec![(body_mesh, velvet)]);
    // The lid carries both the wood and the brass clasp.
    let lid_wood = block([0.164, 0.02, 0.114], 0.0, 0.0, 0.0);
    let clasp = block([0.016, 0.012, 0.003], 0.0, -0.006, 0.0585);
    b.part_at(
        "box_lid",
        vec![(lid_wood, lid_m), (clasp, brass)],
        [0.0, 0.05, 0.0],
        [0.0, 0.0, 0.0, 1.0],
        Some(body),
    );
    b.finish(
        "jewelry_box",
        "jewelry_box",
        "jewelry box",
        "Small wooden jewellery box with a red velvet-covered body and a brass clasp.",
        &[
            "small jewelry box",
            "wooden box with red sides",
            "jewelry case",
        ],
        &["wood", "velvet", "brass"],
        0.5,
    )
    .yaw(YawRule::Front(20.0))
}

fn kettle() -> AssetDef {
    let mut b = Builder::new();
    let steel = b.plain("stainless", [200, 202, 206], 0.22, 1.0);
    let black = b.plain("black_bakelite", [22, 22, 24], 0.5, 0.0);
    let body_mesh = smooth_solid(
        &[
            [0.08, 0.0],
            [0.086, 0.01],
            [0.085, 0.09],
            [0.072, 0.15],
            [0.05, 0.175],
            [0.04, 0.18],
        ],
        5,
        48,
    );
    let body = b.part("kettle_body", vec![(body_mesh, steel)]);
    let knob = ellipsoid([0.014, 0.01, 0.014], [0.0, 0.183, 0.0], 14);
    b.part_at(
        "kettle_knob",
        vec![(knob, black)],
        [0.0; 3],
        [0.0, 0.0, 0.0, 1.0],
        Some(body),
    );
    // The handle arcs over the back half, in the YZ plane.
    let handle =
        TriMesh::tube_arc(0.075, 0.009, 0.35, PI - 0.35, 24, 12).transformed(&Affine3::from_trs(
            [0.0, 0.13, -0.005],
            quat_from_axis_angle([0.0, 1.0, 0.0], PI / 2.0),
            [1.0; 3],
        ));
    b.part_at(
        "kettle_handle",
        vec![(handle, black)],
        [0.0; 3],
        [0.0, 0.0, 0.0, 1.0],
        Some(body),
    );
    // The spout leaves the body toward the front (+Z), rising at 45°.
    let spout = TriMesh::lathe(
        &[[0.0, 0.0], [0.016, 0.0], [0.009, 0.11], [0.0, 0.11]],
        LatheOptions::default().with_segments(20),
    );
    b.part_at(
        "kettle_spout",
        vec![(spout, steel)],
        [0.0, 0.05, 0.05],
        rot_x(45.0),
        Some(body),
    );
    b.finish(
        "kettle_steel",
        "kettle",
        "kettle",
        "Stainless steel stovetop kettle with a black handle and curved spout.",
        &[
            "steel kettle",
            "silver kettle with black handle",
            "metal tea kettle",
        ],
        &["steel", "plastic"],
        1.3,
    )
    .yaw(YawRule::Front(40.0))
    .region(Region::Back)
}

fn apple() -> AssetDef {
    let mut b = Builder::new();
    let skin = b.plain("red_skin", [176, 28, 34], 0.35, 0.0);
    let stem_m = b.plain("stem", [96, 66, 36], 0.8, 0.0);
    let body = TriMesh::lathe(
        &[
            [0.0, 0.005],
            [0.012, 0.001],
            [0.022, 0.0],
            [0.034, 0.01],
            [0.04, 0.032],
            [0.037, 0.056],
            [0.024, 0.07],
            [0.008, 0.068],
            [0.0, 0.062],
        ],
        LatheOptions::default()
            .with_segments(32)
            .with_smooth_angle_deg(70.0),
    );
    let stem = TriMesh::cylinder(0.0018, 0.016, 8).transformed(&Affine3::from_trs(
        [0.0, 0.061, 0.0],
        quat_from_axis_angle([1.0, 0.0, 0.3], 0.25),
        [1.0; 3],
    ));
    b.part("apple", vec![(body, skin), (stem, stem_m)]);
    b.finish(
        "apple_red",
        "fruit",
        "apple",
        "A shiny red apple with a short brown stem.",
        &["red apple", "shiny red apple with stem", "fresh apple, red"],
        &["organic"],
        0.18,
    )
}

fn orange() -> AssetDef {
    let mut b = Builder::new();
    let peel = b.textured(
        "orange_peel",
        textures::dots([236, 128, 28], [222, 116, 22], 6),
        0.55,
    );
    let stem_m = b.plain("calyx", [90, 110, 40], 0.8, 0.0);
    let body = ellipsoid([0.037, 0.0345, 0.037], [0.0, 0.0345, 0.0], 32);
    let calyx = TriMesh::cylinder(0.004, 0.003, 8)
        .transformed(&Affine3::from_translation([0.0, 0.0675, 0.0]));
    b.part("orange", vec![(body, peel), (calyx, stem_m)]);
    b.finish(
        "orange_citrus",
        "fruit",
        "orange",
        "Round orange citrus fruit with a dimpled peel.",
        &[
            "orange",
            "round orange fruit",
            "a ripe orange with textured peel",
        ],
        &["organic"],
        0.2,
    )
    .bbox_form(BboxForm::MinMax)
}

// ---------------------------------------------------------------------------------------------
// Assets that retrieval must filter out.

fn floor_lamp() -> AssetDef {
    let mut b = Builder::new();
    let metal = b.plain("floor_lamp_metal", [26, 26, 29], 0.4, 0.6);
    let fabric = b.plain("drum_shade", [232, 224, 206], 0.9, 0.0);
    let mut stand = TriMesh::cylinder(0.15, 0.025, 40);
    stand.append(
        &TriMesh::cylinder(0.012, 1.5, 16)
            .transformed(&Affine3::from_translation([0.0, 0.025, 0.0])),
    );
    let shade = TriMesh::lathe(
        &[[0.0, 1.45], [0.2, 1.45], [0.18, 1.7], [0.0, 1.7]],
        LatheOptions::default().with_segments(40),
    );
    b.part("floor_lamp", vec![(stand, metal), (shade, fabric)]);
    let mut def = b.finish(
        "floor_lamp",
        "floor_lamp",
        "lamp",
        "Tall black floor lamp with a round base and a fabric drum shade.",
        &["floor lamp"],
        &["metal", "fabric"],
        6.5,
    );
    def.on_table = false;
    def.in_scenes = false;
    def
}

fn wall_clock() -> AssetDef {
    let mut b = Builder::new();
    let rim = b.plain("clock_rim", [30, 30, 32], 0.4, 0.3);
    let face = b.textured(
        "clock_face",
        textures::dots([246, 246, 240], [30, 30, 32], 32),
        0.5,
    );
    let body = TriMesh::cylinder(0.15, 0.04, 48).transformed(&Affine3::from_trs(
        [0.0, 0.15, -0.02],
        rot_x(90.0),
        [1.0; 3],
    ));
    let dial = TriMesh::cylinder(0.14, 0.001, 48).transformed(&Affine3::from_trs(
        [0.0, 0.15, 0.0201],
        rot_x(90.0),
        [1.0; 3],
    ));
    b.part("wall_clock", vec![(body, rim), (dial, face)]);
    let mut def = b.finish(
        "wall_clock",
        "clock",
        "clock",
        "Round wall clock with a black rim and a white dial.",
        &["wall clock"],
        &["plastic", "glass"],
        0.9,
    );
    def.on_table = false;
    def.in_scenes = false;
    def
}

fn dinnerware_set() -> AssetDef {
    let mut b = Builder::new();
    let porcelain = b.plain("set_porcelain", [244, 244, 240], 0.2, 0.0);
    let (r, h, w, base, e) = PLATE_DINNER;
    let plate = b.part("set_plate", vec![(dish(r, h, w, base, e, 48), porcelain)]);
    let bowl_y = dish_inner_height(0.0, r, h, w, base, e);
    b.part_at(
        "set_bowl",
        vec![(dish(0.075, 0.06, 0.004, 0.03, 1.6, 40), porcelain)],
        [0.0, bowl_y, 0.0],
        [0.0, 0.0, 0.0, 1.0],
        Some(plate),
    );
    b.part_at(
        "set_cup",
        vec![(
            vessel(0.036, 0.04, 0.085, 0.003, 0.006, 0.002, 32),
            porcelain,
        )],
        [0.19, 0.0, 0.02],
        [0.0, 0.0, 0.0, 1.0],
        None,
    );
    let mut def = b.finish(
        "dinnerware_set",
        "dinnerware_set",
        "dinnerware",
        "Set of white porcelain dinnerware: a dinner plate with a bowl on it and a cup beside.",
        &["dinnerware set"],
        &["porcelain"],
        1.4,
    );
    def.is_composite = true;
    def.in_scenes = false;
    def
}

/// Every asset definition, in a fixed order.
pub(crate) fn catalogue() -> Vec<AssetDef> {
    vec![
        mug_white(),
        mug_striped(),
        cup_paper(),
        cup_glass(),
        bowl_ceramic(),
        bowl_wooden(),
        plate_dinner(),
        plate_patterned(),
        tray_wooden(),
        cutting_board(),
        book(BookSpec {
            key: "book_red",
            size: [0.16, 0.035, 0.24],
            cover: [150, 30, 36],
            accent: [222, 184, 96],
            salt: 1,
            description: "Red hardcover book with a gold title band on the front cover.",
            instance_descriptions: &[
                "red hardcover book",
                "closed red book lying flat",
                "book with red cover and gold lettering",
            ],
            mass_kg: 0.6,
        }),
        book(BookSpec {
            key: "book_blue",
            size: [0.13, 0.025, 0.2],
            cover: [40, 70, 140],
            accent: [240, 240, 236],
            salt: 2,
            description: "Blue paperback novel with a white band across the cover.",
            instance_descriptions: &[
                "blue paperback book",
                "small blue book",
                "paperback with blue cover",
            ],
            mass_kg: 0.3,
        }),
        book(BookSpec {
            key: "book_green_large",
            size: [0.21, 0.03, 0.28],
            cover: [46, 96, 62],
            accent: [236, 226, 196],
            salt: 3,
            description: "Large green hardcover art book with a cream title panel.",
            instance_descriptions: &[
                "large green book",
                "big hardcover book, dark green",
                "green coffee table book",
            ],
            mass_kg: 1.1,
        }),
        notebook(),
        laptop(),
        keyboard(),
        mouse(),
        phone(),
        remote(),
        bottle_water(),
        bottle_wine(),
        jar(),
        vase(),
        soap_dispenser(),
        lotion_bottle(),
        perfume_bottle(),
        desk_lamp(),
        pen(),
        pencil(),
        pen_holder(),
        tissue_box(),
        toothbrush_cup(),
        toothbrush(),
        candle(),
        potted_plant(),
        towel(),
        jewelry_box(),
        kettle(),
        apple(),
        orange(),
        mug_old(),
        floor_lamp(),
        wall_clock(),
        dinnerware_set(),
    ]
}

/// The asset library, built (in parallel) and indexed by key.
#[derive(Debug)]
pub(crate) struct Library {
    pub assets: Vec<DemoAsset>,
}

impl Library {
    /// Builds every asset; an error names the asset.
    pub(crate) fn build() -> Result<Self, (&'static str, GlbWriteError)> {
        use rayon::prelude::*;
        let assets = catalogue()
            .into_par_iter()
            .map(|def| {
                let key = def.key;
                DemoAsset::build(def).map_err(|e| (key, e))
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self { assets })
    }

    /// The asset with this key.
    pub(crate) fn index_of(&self, key: &str) -> Option<usize> {
        self.assets.iter().position(|a| a.def.key == key)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeSet;

    #[test]
    fn the_catalogue_meets_the_library_requirements() {
        let lib = Library::build().expect("library");
        let scene_assets: Vec<_> = lib.assets.iter().filter(|a| a.def.in_scenes).collect();
        assert!(
            scene_assets.len() >= 25,
            "{} scene assets",
            scene_assets.len()
        );
        let categories: BTreeSet<_> = scene_assets.iter().map(|a| a.def.category).collect();
        assert!(categories.len() >= 15, "{categories:?}");
        assert!(lib.assets.iter().any(|a| !a.def.on_table));
        assert!(lib.assets.iter().any(|a| a.def.mark_deletion));
        assert!(lib.assets.iter().any(|a| a.def.is_composite));
        assert!(lib
            .assets
            .iter()
            .any(|a| a.def.materials.iter().any(|m| m.texture.is_some())));
        assert!(lib
            .assets
            .iter()
            .any(|a| a.def.materials.iter().all(|m| m.texture.is_none())));
        assert!(lib.assets.iter().any(|a| a.def.parts.len() > 1));
        assert!(lib
            .assets
            .iter()
            .any(|a| a.def.parts.iter().any(|p| p.primitives.len() > 1)));
        assert!(lib.assets.iter().any(|a| a.def.root_scale != 1.0));
        let uids: BTreeSet<_> = lib.assets.iter().map(|a| a.uid.clone()).collect();
        assert_eq!(uids.len(), lib.assets.len());
        for a in &lib.assets {
            assert_eq!(a.uid.len(), 32);
            assert_ne!(
                a.def.description, a.def.instance_descriptions[0],
                "{}: the instance wording must differ from the library's",
                a.def.key
            );
            for (m, _) in &a.baked_table_axes {
                m.check().unwrap_or_else(|e| panic!("{}: {e}", a.def.key));
            }
        }
    }

    #[test]
    fn assets_have_real_sizes_and_stand_on_their_origin() {
        let lib = Library::build().expect("library");
        let size_cm = |key: &str| {
            let a = &lib.assets[lib.index_of(key).expect(key)];
            a.bounds_table_axes.size().map(|v| v * 100.0)
        };
        // [width, depth, height] in cm, in table axes.
        let mug = size_cm("mug_white");
        // A mug with its handle is about 12 cm wide, 8 cm deep, 9.5 cm tall.
        assert!(
            (11.0..13.5).contains(&mug[0]) && (7.5..9.0).contains(&mug[1]),
            "{mug:?}"
        );
        assert!((9.0..10.0).contains(&mug[2]), "{mug:?}");
        let laptop = size_cm("laptop_silver");
        assert!(
            (30.0..34.0).contains(&laptop[0]) && (18.0..25.0).contains(&laptop[2]),
            "{laptop:?}"
        );
        let keyboard = size_cm("keyboard_black");
        assert!((43.0..45.0).contains(&keyboard[0]), "{keyboard:?}");
        let lamp = size_cm("desk_lamp");
        assert!((30.0..55.0).contains(&lamp[2]), "{lamp:?}");
        for a in lib.assets.iter().filter(|a| a.def.in_scenes) {
            // Resting on the origin plane: the lowest point is at height 0.
            assert!(
                a.bounds_gltf.min[1].abs() < 2e-3,
                "{} min y {}",
                a.def.key,
                a.bounds_gltf.min[1]
            );
        }
    }

    #[test]
    fn annotations_use_the_declared_bbox_forms() {
        let lib = Library::build().expect("library");
        let mut forms = BTreeSet::new();
        for a in &lib.assets {
            let v = a.annotation();
            let form = if v.get("min_point").is_some() {
                "min_point"
            } else if v["bbox"].get("size").is_some() {
                "size"
            } else if v["bbox"].get("min").is_some() {
                "min"
            } else {
                assert!(v["bbox"]["x"].as_f64().expect("x") > 0.0);
                "xyz"
            };
            forms.insert(form);
            assert!(v.get("isContainer").is_some() || v.get("receptacle").is_some());
        }
        assert_eq!(forms.len(), 4);
    }
}
