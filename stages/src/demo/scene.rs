//! Composing a tabletop scene: a table of one of the six types, then groups of objects placed
//! on it (single objects, stacks, containers with contents), each object dropped vertically
//! until it rests on the table or on what is under it (see [`super::settle`]).
//!
//! Everything is in the table frame (SPEC section 2), metres: origin at the proximal-left
//! corner of the placement zone on the table surface, x right, y away from the observer, z up.

use rand::{Rng, RngCore};

use super::assets::{DemoAsset, Library, Region, Surface, YawRule};
use super::settle::{lift_to_clear, VerticalMesh};
use super::textures::Srgb;
use crate::mesh::{quat_from_axis_angle, quat_mul, Affine3, TriMesh};

/// The six table types of MesaTask-10K, in the order scenes cycle through them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) enum TableType {
    OfficeTable,
    DiningTable,
    KitchenCounter,
    CoffeeTable,
    DressingTable,
    BathroomVanity,
}

impl TableType {
    pub(crate) const ALL: [TableType; 6] = [
        TableType::OfficeTable,
        TableType::DiningTable,
        TableType::KitchenCounter,
        TableType::CoffeeTable,
        TableType::DressingTable,
        TableType::BathroomVanity,
    ];

    /// The dataset's name of the type (`office_table`, ...).
    pub(crate) fn name(self) -> &'static str {
        match self {
            TableType::OfficeTable => "office_table",
            TableType::DiningTable => "dining_table",
            TableType::KitchenCounter => "kitchen_counter",
            TableType::CoffeeTable => "coffee_table",
            TableType::DressingTable => "dressing_table",
            TableType::BathroomVanity => "bathroom_vanity",
        }
    }
}

/// What the table top is made of.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum TopFinish {
    Wood { light: Srgb, dark: Srgb, salt: u64 },
    Stone { base: Srgb, vein: Srgb, salt: u64 },
    Laminate(Srgb),
}

/// What holds the top up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum TableBase {
    Legs,
    Cabinet,
}

/// A sink cut into a bathroom vanity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Sink {
    /// The restricted zone [x_min, x_max, y_min, y_max], metres.
    pub zone_m: [f64; 4],
    /// The basin opening inside it, metres.
    pub basin_m: [f64; 4],
    /// Basin depth below the top, metres.
    pub depth_m: f64,
}

/// The table of a scene.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Table {
    pub kind: TableType,
    /// Placement zone extent along x, metres (the whole top).
    pub width_m: f64,
    /// Placement zone extent along y, metres.
    pub depth_m: f64,
    /// Height of the top surface above the floor, metres.
    pub height_m: f64,
    /// Thickness of the top, metres.
    pub thickness_m: f64,
    pub sink: Option<Sink>,
    pub finish: TopFinish,
    pub base: TableBase,
    pub base_srgb: Srgb,
    /// Distance from the table's back edge to the wall, metres.
    pub wall_gap_m: f64,
    /// What a vision-language model would call it.
    pub label: &'static str,
    /// How it would describe it.
    pub description: String,
}

/// An object placed in the scene.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Placed {
    /// Index into the library.
    pub asset: usize,
    /// Isotropic scale of the asset.
    pub scale: f64,
    /// Rotation of the object frame in the table frame, `[x, y, z, w]`.
    pub rotation_xyzw: [f64; 4],
    /// Centre of the object's bounding box (object frame), table frame, metres.
    pub position_m: [f64; 3],
    /// The object it rests on: the one it touches from above (`None`: the table).
    pub support: Option<usize>,
    /// The photo-style description of this instance.
    pub description: String,
}

impl Placed {
    /// The map from the asset's table-axes coordinates (its baked meshes) to the table frame:
    /// translate the bounding-box centre to the origin, scale, rotate, move to `position_m`.
    pub(crate) fn world_from_asset(&self, asset: &DemoAsset) -> Affine3 {
        world_from_asset(asset, self.scale, self.rotation_xyzw, self.position_m)
    }
}

fn world_from_asset(
    asset: &DemoAsset,
    scale: f64,
    rotation_xyzw: [f64; 4],
    position_m: [f64; 3],
) -> Affine3 {
    let c = asset.bounds_table_axes.center();
    Affine3::from_trs(position_m, rotation_xyzw, [scale; 3])
        .mul(&Affine3::from_translation([-c[0], -c[1], -c[2]]))
}

/// Gap left between a stacked object and what it rests on, metres (well under the physics
/// check's tolerances, so it reads as contact).
pub(crate) const REST_CLEARANCE_M: f64 = 5e-4;
/// Space kept between groups standing on the table, metres.
const GROUP_GAP_M: f64 = 0.012;
/// Space kept between the table edge and objects, metres.
const EDGE_MARGIN_M: f64 = 0.015;

// ---------------------------------------------------------------------------------------------
// Recipes.

#[derive(Debug, Clone, Copy)]
enum Group {
    /// One object, one of these keys.
    One(&'static [&'static str]),
    /// A pile of `min..=max` objects from `keys` (the same key throughout when `same`),
    /// largest at the bottom.
    Stack {
        keys: &'static [&'static str],
        min: usize,
        max: usize,
        same: bool,
    },
    /// A container with `min..=max` things in it; `upright` stands them up leaning (pens in
    /// a cup).
    Fill {
        holder: &'static [&'static str],
        contents: &'static [&'static str],
        min: usize,
        max: usize,
        upright: bool,
    },
    /// One thing on top of another.
    OnTop {
        base: &'static [&'static str],
        top: &'static [&'static str],
    },
}

impl Group {
    fn max_objects(&self) -> usize {
        match self {
            Group::One(_) => 1,
            Group::Stack { max, .. } => *max,
            Group::Fill { max, .. } => 1 + max,
            Group::OnTop { .. } => 2,
        }
    }
}

#[derive(Debug, Clone, Copy)]
struct Entry {
    group: Group,
    weight: f64,
    max_per_scene: usize,
}

const fn e(group: Group, weight: f64, max_per_scene: usize) -> Entry {
    Entry {
        group,
        weight,
        max_per_scene,
    }
}

const MUGS: &[&str] = &["mug_white", "mug_striped"];
const CUPS: &[&str] = &["cup_paper", "cup_glass"];
const BOOKS: &[&str] = &["book_red", "book_blue", "book_green_large"];
const FRUIT: &[&str] = &["apple_red", "orange_citrus"];
const PENS: &[&str] = &["pen_blue", "pencil_yellow"];

fn recipe(kind: TableType) -> &'static [Entry] {
    use Group::*;
    match kind {
        TableType::OfficeTable => {
            const {
                &[
                    e(One(&["laptop_silver"]), 3.0, 1),
                    e(One(&["keyboard_black"]), 1.5, 1),
                    e(One(&["mouse_grey"]), 1.5, 1),
                    e(One(MUGS), 2.0, 2),
                    e(One(CUPS), 1.0, 1),
                    e(
                        Stack {
                            keys: BOOKS,
                            min: 2,
                            max: 3,
                            same: false,
                        },
                        1.5,
                        1,
                    ),
                    e(One(BOOKS), 1.5, 2),
                    e(One(&["notebook_spiral"]), 1.5, 1),
                    e(One(PENS), 2.0, 3),
                    e(
                        Fill {
                            holder: &["pen_holder"],
                            contents: PENS,
                            min: 1,
                            max: 3,
                            upright: true,
                        },
                        2.0,
                        1,
                    ),
                    e(One(&["desk_lamp"]), 2.0, 1),
                    e(One(&["potted_plant"]), 1.0, 1),
                    e(One(&["bottle_water"]), 1.0, 1),
                    e(One(&["phone_black"]), 1.0, 1),
                    e(One(&["tissue_box"]), 0.5, 1),
                    e(
                        OnTop {
                            base: BOOKS,
                            top: MUGS,
                        },
                        0.7,
                        1,
                    ),
                    e(One(FRUIT), 0.5, 2),
                ]
            }
        }
        TableType::DiningTable => {
            const {
                &[
                    e(One(&["plate_dinner", "plate_patterned"]), 3.0, 4),
                    e(
                        Stack {
                            keys: &["plate_dinner"],
                            min: 2,
                            max: 3,
                            same: true,
                        },
                        1.5,
                        1,
                    ),
                    e(
                        Stack {
                            keys: &["plate_patterned"],
                            min: 2,
                            max: 3,
                            same: true,
                        },
                        1.0,
                        1,
                    ),
                    e(One(&["bowl_ceramic"]), 2.0, 3),
                    e(
                        Fill {
                            holder: &["bowl_wooden", "bowl_ceramic"],
                            contents: FRUIT,
                            min: 2,
                            max: 4,
                            upright: false,
                        },
                        2.0,
                        1,
                    ),
                    e(
                        OnTop {
                            base: &["plate_dinner"],
                            top: &["apple_red", "orange_citrus", "bowl_ceramic"],
                        },
                        1.5,
                        2,
                    ),
                    e(One(&["cup_glass"]), 2.0, 4),
                    e(One(MUGS), 1.0, 2),
                    e(One(&["bottle_wine"]), 1.5, 1),
                    e(One(&["bottle_water"]), 1.0, 1),
                    e(One(&["vase_ceramic"]), 1.0, 1),
                    e(One(&["candle_pillar"]), 1.0, 2),
                    e(
                        Fill {
                            holder: &["tray_wooden"],
                            contents: &["cup_glass", "mug_white", "candle_pillar", "bowl_ceramic"],
                            min: 1,
                            max: 3,
                            upright: false,
                        },
                        1.0,
                        1,
                    ),
                    e(One(&["jar_glass"]), 0.5, 1),
                    e(One(FRUIT), 1.0, 3),
                ]
            }
        }
        TableType::KitchenCounter => {
            const {
                &[
                    e(One(&["cutting_board"]), 2.0, 1),
                    e(
                        Fill {
                            holder: &["cutting_board"],
                            contents: FRUIT,
                            min: 1,
                            max: 3,
                            upright: false,
                        },
                        1.5,
                        1,
                    ),
                    e(One(&["kettle_steel"]), 2.0, 1),
                    e(One(&["jar_glass"]), 2.0, 3),
                    e(One(&["bottle_wine", "bottle_water"]), 1.5, 2),
                    e(
                        Fill {
                            holder: &["bowl_wooden"],
                            contents: FRUIT,
                            min: 2,
                            max: 5,
                            upright: false,
                        },
                        2.0,
                        1,
                    ),
                    e(
                        Stack {
                            keys: &["plate_dinner"],
                            min: 2,
                            max: 3,
                            same: true,
                        },
                        1.5,
                        1,
                    ),
                    e(One(MUGS), 1.5, 2),
                    e(One(CUPS), 1.0, 2),
                    e(One(&["bowl_ceramic"]), 1.0, 2),
                    e(One(FRUIT), 1.5, 3),
                    e(One(&["tray_wooden"]), 0.5, 1),
                    e(One(&["potted_plant"]), 0.5, 1),
                ]
            }
        }
        TableType::CoffeeTable => {
            const {
                &[
                    e(
                        Fill {
                            holder: &["tray_wooden"],
                            contents: &[
                                "mug_white",
                                "mug_striped",
                                "cup_glass",
                                "candle_pillar",
                                "apple_red",
                                "orange_citrus",
                            ],
                            min: 1,
                            max: 3,
                            upright: false,
                        },
                        2.0,
                        1,
                    ),
                    e(
                        Stack {
                            keys: BOOKS,
                            min: 2,
                            max: 3,
                            same: false,
                        },
                        2.0,
                        2,
                    ),
                    e(One(BOOKS), 1.5, 2),
                    e(One(&["remote_control"]), 2.0, 2),
                    e(One(&["vase_ceramic"]), 1.0, 1),
                    e(One(&["candle_pillar"]), 1.0, 3),
                    e(One(MUGS), 1.5, 2),
                    e(One(CUPS), 1.0, 2),
                    e(
                        Fill {
                            holder: &["bowl_wooden", "bowl_ceramic"],
                            contents: FRUIT,
                            min: 2,
                            max: 4,
                            upright: false,
                        },
                        1.0,
                        1,
                    ),
                    e(One(&["potted_plant"]), 1.0, 1),
                    e(One(&["tissue_box"]), 0.5, 1),
                    e(One(&["phone_black"]), 1.0, 1),
                    e(
                        OnTop {
                            base: BOOKS,
                            top: &["mug_white", "mug_striped", "candle_pillar", "cup_glass"],
                        },
                        1.0,
                        1,
                    ),
                    e(One(&["laptop_silver"]), 0.3, 1),
                ]
            }
        }
        TableType::DressingTable => {
            const {
                &[
                    e(One(&["perfume_bottle"]), 2.0, 3),
                    e(One(&["lotion_bottle"]), 2.0, 2),
                    e(One(&["jewelry_box"]), 1.5, 1),
                    e(One(&["tissue_box"]), 1.0, 1),
                    e(One(&["vase_ceramic"]), 1.0, 1),
                    e(One(&["candle_pillar"]), 1.0, 2),
                    e(One(&["potted_plant"]), 1.0, 1),
                    e(One(&["cup_glass", "mug_white"]), 0.5, 1),
                    e(One(BOOKS), 0.7, 1),
                    e(One(&["phone_black"]), 0.7, 1),
                    e(
                        Fill {
                            holder: &["tray_wooden"],
                            contents: &["perfume_bottle", "lotion_bottle", "candle_pillar"],
                            min: 1,
                            max: 3,
                            upright: false,
                        },
                        1.0,
                        1,
                    ),
                    e(One(&["towel_folded"]), 0.5, 1),
                ]
            }
        }
        TableType::BathroomVanity => {
            const {
                &[
                    e(One(&["soap_dispenser"]), 2.0, 2),
                    e(
                        Fill {
                            holder: &["toothbrush_cup"],
                            contents: &["toothbrush"],
                            min: 1,
                            max: 3,
                            upright: true,
                        },
                        2.0,
                        1,
                    ),
                    e(One(&["lotion_bottle"]), 2.0, 3),
                    e(One(&["towel_folded"]), 1.5, 2),
                    e(
                        OnTop {
                            base: &["towel_folded"],
                            top: &["soap_dispenser", "lotion_bottle", "perfume_bottle"],
                        },
                        1.0,
                        1,
                    ),
                    e(One(&["tissue_box"]), 1.0, 1),
                    e(One(&["potted_plant"]), 1.0, 1),
                    e(One(&["cup_glass"]), 1.0, 2),
                    e(One(&["candle_pillar"]), 1.0, 2),
                    e(One(&["perfume_bottle"]), 1.0, 2),
                    e(
                        Fill {
                            holder: &["tray_wooden"],
                            contents: &[
                                "soap_dispenser",
                                "lotion_bottle",
                                "perfume_bottle",
                                "candle_pillar",
                            ],
                            min: 1,
                            max: 3,
                            upright: false,
                        },
                        0.7,
                        1,
                    ),
                ]
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// The table.

fn pick<'a, T, R: RngCore + ?Sized>(rng: &mut R, items: &'a [T]) -> &'a T {
    &items[rng.random_range(0..items.len())]
}

pub(crate) fn make_table(kind: TableType, rng: &mut impl RngCore) -> Table {
    let woods: [(Srgb, Srgb, &str); 3] = [
        ([206, 160, 110], [150, 104, 64], "light oak"),
        ([132, 86, 56], [86, 52, 32], "walnut"),
        ([222, 196, 160], [180, 150, 112], "birch"),
    ];
    let stones: [(Srgb, Srgb, &str); 3] = [
        ([236, 234, 230], [170, 170, 176], "white marble"),
        ([120, 120, 124], [70, 70, 74], "grey granite"),
        ([214, 204, 186], [160, 146, 124], "beige quartz"),
    ];
    let laminates: [(Srgb, &str); 2] = [([238, 238, 234], "white"), ([60, 60, 64], "black")];
    let salt = rng.random_range(0..1000u64);
    let wood = |rng: &mut dyn RngCore| {
        let (light, dark, name) = *pick(rng, &woods);
        (TopFinish::Wood { light, dark, salt }, name)
    };
    let stone = |rng: &mut dyn RngCore| {
        let (base, vein, name) = *pick(rng, &stones);
        (TopFinish::Stone { base, vein, salt }, name)
    };
    let laminate = |rng: &mut dyn RngCore| {
        let (c, name) = *pick(rng, &laminates);
        (TopFinish::Laminate(c), name)
    };
    let (w, d, h, base, label, noun, wall_gap) = match kind {
        TableType::OfficeTable => (
            rng.random_range(1.1..1.6),
            rng.random_range(0.6..0.8),
            0.74,
            TableBase::Legs,
            "desk",
            "office desk",
            rng.random_range(0.15..0.8),
        ),
        TableType::DiningTable => (
            rng.random_range(1.3..2.0),
            rng.random_range(0.8..1.0),
            0.75,
            TableBase::Legs,
            "dining table",
            "dining table",
            rng.random_range(0.6..1.5),
        ),
        TableType::KitchenCounter => (
            rng.random_range(1.2..2.2),
            rng.random_range(0.55..0.65),
            0.9,
            TableBase::Cabinet,
            "kitchen counter",
            "kitchen counter",
            0.0,
        ),
        TableType::CoffeeTable => (
            rng.random_range(0.9..1.3),
            rng.random_range(0.5..0.7),
            0.45,
            TableBase::Legs,
            "coffee table",
            "coffee table",
            rng.random_range(0.8..1.6),
        ),
        TableType::DressingTable => (
            rng.random_range(0.9..1.3),
            rng.random_range(0.4..0.55),
            0.76,
            TableBase::Legs,
            "dressing table",
            "dressing table",
            0.0,
        ),
        TableType::BathroomVanity => (
            rng.random_range(1.0..1.8),
            rng.random_range(0.48..0.6),
            0.86,
            TableBase::Cabinet,
            "bathroom vanity",
            "bathroom vanity top",
            0.0,
        ),
    };
    let (finish, finish_name) = match kind {
        TableType::KitchenCounter | TableType::BathroomVanity => stone(rng),
        TableType::DressingTable if rng.random_bool(0.6) => laminate(rng),
        TableType::OfficeTable | TableType::CoffeeTable if rng.random_bool(0.3) => laminate(rng),
        _ => wood(rng),
    };
    let sink = (kind == TableType::BathroomVanity).then(|| {
        let sink_w = rng.random_range(0.45..0.6f64).min(w * 0.5);
        let centre = if w > 1.4 && rng.random_bool(0.5) {
            // Off-centre on a long vanity, as often.
            if rng.random_bool(0.5) {
                w * 0.3
            } else {
                w * 0.7
            }
        } else {
            w / 2.0
        };
        let y0 = rng.random_range(0.05..0.08);
        let y1 = d - rng.random_range(0.04..0.07);
        let zone = [centre - sink_w / 2.0, centre + sink_w / 2.0, y0, y1];
        Sink {
            zone_m: zone,
            basin_m: [
                zone[0] + 0.035,
                zone[1] - 0.035,
                zone[2] + 0.03,
                zone[3] - 0.1,
            ],
            depth_m: 0.14,
        }
    });
    let base_srgb = match base {
        TableBase::Cabinet => *pick(rng, &[[236u8, 234, 228], [70, 80, 96], [150, 120, 90]]),
        TableBase::Legs => match &finish {
            TopFinish::Wood { dark, .. } => *dark,
            TopFinish::Laminate(_) => [40, 40, 44],
            TopFinish::Stone { .. } => [60, 60, 64],
        },
    };
    Table {
        kind,
        width_m: w,
        depth_m: d,
        height_m: h,
        thickness_m: rng.random_range(0.025..0.04),
        sink,
        finish,
        base,
        base_srgb,
        wall_gap_m: wall_gap,
        label,
        description: format!("{finish_name} {noun}"),
    }
}

// ---------------------------------------------------------------------------------------------
// Composing.

/// Why a group could not be placed (the composer tries something else).
struct NoRoom;

struct Composer<'a, R: RngCore> {
    lib: &'a Library,
    rng: &'a mut R,
    table: &'a Table,
    objects: Vec<Placed>,
    /// Each object's placed mesh, for vertical queries.
    meshes: Vec<VerticalMesh>,
    /// Footprints `[x_min, x_max, y_min, y_max]` of the groups standing on the table.
    footprints: Vec<[f64; 4]>,
}

fn yaw_quat(deg: f64) -> [f64; 4] {
    quat_from_axis_angle([0.0, 0.0, 1.0], deg.to_radians())
}

fn inside(inner: &[f64; 4], outer: &[f64; 4]) -> bool {
    inner[0] >= outer[0] - 1e-9
        && inner[1] <= outer[1] + 1e-9
        && inner[2] >= outer[2] - 1e-9
        && inner[3] <= outer[3] + 1e-9
}

fn disjoint(a: &[f64; 4], b: &[f64; 4], gap: f64) -> bool {
    a[1] + gap <= b[0] || b[1] + gap <= a[0] || a[3] + gap <= b[2] || b[3] + gap <= a[2]
}

impl<'a, R: RngCore> Composer<'a, R> {
    fn asset(&self, key: &str) -> usize {
        self.lib
            .index_of(key)
            .unwrap_or_else(|| unreachable!("recipe key {key} is not in the catalogue"))
    }

    fn sample_yaw(&mut self, rule: YawRule) -> f64 {
        match rule {
            YawRule::Front(jitter) => self.rng.random_range(-jitter..=jitter),
            YawRule::Any => self.rng.random_range(-180.0..180.0),
        }
    }

    fn sample_scale(&mut self) -> f64 {
        (self.rng.random_range(0.92..1.08f64) * 1000.0).round() / 1000.0
    }

    fn description(&mut self, asset: usize) -> String {
        let options = self.lib.assets[asset].def.instance_descriptions;
        (*pick(self.rng, options)).to_owned()
    }

    fn vertical_mesh(
        &self,
        asset: usize,
        scale: f64,
        rotation: [f64; 4],
        position: [f64; 3],
    ) -> VerticalMesh {
        let a = &self.lib.assets[asset];
        let meshes: Vec<&TriMesh> = a.baked_table_axes.iter().map(|(m, _)| m).collect();
        VerticalMesh::new(&meshes, &world_from_asset(a, scale, rotation, position))
            .unwrap_or_else(|| unreachable!("asset {} has triangles", a.def.key))
    }

    fn push(&mut self, placed: Placed, mesh: VerticalMesh) -> usize {
        self.objects.push(placed);
        self.meshes.push(mesh);
        self.objects.len() - 1
    }

    /// Places an object standing on the table, in its preferred region, clear of the other
    /// groups and of the sink.
    fn place_on_table(&mut self, key: &str) -> Result<usize, NoRoom> {
        let asset = self.asset(key);
        let (w, d) = (self.table.width_m, self.table.depth_m);
        let def = self.lib.assets[asset].def.clone();
        for _ in 0..40 {
            let yaw = self.sample_yaw(def.yaw);
            let rotation = yaw_quat(yaw);
            let scale = self.sample_scale();
            let probe = self.vertical_mesh(asset, scale, rotation, [0.0; 3]);
            let rel = probe.footprint();
            let (x_lo, x_hi) = (EDGE_MARGIN_M - rel[0], w - EDGE_MARGIN_M - rel[1]);
            let (mut y_lo, mut y_hi) = (EDGE_MARGIN_M - rel[2], d - EDGE_MARGIN_M - rel[3]);
            if x_lo >= x_hi || y_lo >= y_hi {
                return Err(NoRoom);
            }
            let mid = d * 0.5;
            match def.region {
                Region::Front if y_lo < mid => y_hi = y_hi.min(mid.max(y_lo + 1e-3)),
                Region::Back if y_hi > mid => y_lo = y_lo.max(mid.min(y_hi - 1e-3)),
                _ => {}
            }
            let x = self.rng.random_range(x_lo..x_hi);
            let y = self.rng.random_range(y_lo..y_hi);
            let fp = [rel[0] + x, rel[1] + x, rel[2] + y, rel[3] + y];
            if self
                .footprints
                .iter()
                .any(|f| !disjoint(f, &fp, GROUP_GAP_M))
            {
                continue;
            }
            if let Some(sink) = &self.table.sink {
                if !disjoint(&sink.zone_m, &fp, 0.01) {
                    continue;
                }
            }
            // Resting on the table: the lowest point at z = 0.
            let z = -probe.bounds.min[2];
            let position = [x, y, z];
            let mesh = self.vertical_mesh(asset, scale, rotation, position);
            self.footprints.push(fp);
            let description = self.description(asset);
            return Ok(self.push(
                Placed {
                    asset,
                    scale,
                    rotation_xyzw: rotation,
                    position_m: position,
                    support: None,
                    description,
                },
                mesh,
            ));
        }
        Err(NoRoom)
    }

    /// The surface of `support` and the table-frame point at its centre.
    fn surface_frame(&self, support: usize) -> Option<(Surface, [f64; 3])> {
        let s = &self.objects[support];
        let a = &self.lib.assets[s.asset];
        let surface = a.def.surface?;
        let world_from = s.world_from_asset(a);
        let centre = world_from.apply_point([0.0, 0.0, a.def.surface_height_m]);
        Some((surface, centre))
    }

    /// Places `key` on or in `support`: dropped from above at a sampled spot until it rests.
    fn place_on(
        &mut self,
        support: usize,
        key: &str,
        mode: ChildMode,
        stack_of: Option<usize>,
    ) -> Result<usize, NoRoom> {
        let asset = self.asset(key);
        let (surface, centre) = self.surface_frame(support).ok_or(NoRoom)?;
        let group_fp = self.group_footprint(support);
        let support_top = self.meshes[support].bounds.max[2];
        let def = self.lib.assets[asset].def.clone();
        let support_yaw_deg = crate::mesh::quat_to_matrix(self.objects[support].rotation_xyzw);
        let support_yaw = support_yaw_deg[1][0]
            .atan2(support_yaw_deg[0][0])
            .to_degrees();
        for attempt in 0..30 {
            let scale = match stack_of {
                Some(base) => self.objects[base].scale,
                None => self.sample_scale(),
            };
            let (rotation, offset) = match mode {
                ChildMode::Stack {
                    jitter_m,
                    yaw_jitter_deg,
                } => {
                    let yaw = support_yaw + self.rng.random_range(-yaw_jitter_deg..=yaw_jitter_deg);
                    let dx = self.rng.random_range(-jitter_m..=jitter_m);
                    let dy = self.rng.random_range(-jitter_m..=jitter_m);
                    (yaw_quat(yaw), [dx, dy])
                }
                ChildMode::Inside => {
                    let yaw = self.sample_yaw(def.yaw);
                    (
                        yaw_quat(yaw),
                        self.sample_in_surface(&surface, support, 0.8),
                    )
                }
                ChildMode::Upright { index, count } => {
                    // Stand the object's long axis (asset x) up, lean it outward by a few
                    // degrees, its foot a little off the centre toward the lean, the
                    // objects spread around the centre so that they do not cross.
                    let jitter = if attempt > 0 {
                        self.rng.random_range(-0.5..0.5)
                    } else {
                        0.0
                    };
                    let phi = (index as f64 + jitter) * std::f64::consts::TAU / count as f64;
                    let lean = self.rng.random_range(4.0f64..8.0).to_radians();
                    let stand = quat_from_axis_angle([0.0, 1.0, 0.0], -std::f64::consts::FRAC_PI_2);
                    let spin = quat_from_axis_angle(
                        [0.0, 0.0, 1.0],
                        self.rng
                            .random_range(-std::f64::consts::PI..std::f64::consts::PI),
                    );
                    let tilt = quat_from_axis_angle([-phi.sin(), phi.cos(), 0.0], lean);
                    let rotation = quat_mul(tilt, quat_mul(spin, stand));
                    let foot = match surface {
                        Surface::Round { radius_m } => {
                            radius_m * self.objects[support].scale * 0.35
                        }
                        Surface::Rect { .. } => 0.0,
                    };
                    let half_length =
                        self.lib.assets[asset].bounds_table_axes.size()[0] * scale / 2.0;
                    let r = foot + half_length * lean.sin();
                    (rotation, [r * phi.cos(), r * phi.sin()])
                }
            };
            let probe = self.vertical_mesh(
                asset,
                scale,
                rotation,
                [centre[0] + offset[0], centre[1] + offset[1], 0.0],
            );
            let fp = probe.footprint();
            if !inside(&fp, &group_fp) {
                continue;
            }
            // Drop: lift above everything under it.
            // It rests on whatever needs the largest lift: that is what it touches.
            let mut lift = f64::NEG_INFINITY;
            let mut rests_on = None;
            for (i, m) in self.meshes.iter().enumerate() {
                if let Some(l) = lift_to_clear(&probe, m) {
                    if l > lift {
                        lift = l;
                        rests_on = Some(i);
                    }
                }
            }
            let rests_on_object = rests_on.is_some();
            let table_lift = -probe.bounds.min[2];
            let (dz, rests_on) = if rests_on_object && lift + REST_CLEARANCE_M > table_lift {
                (lift + REST_CLEARANCE_M, rests_on)
            } else {
                (table_lift, None)
            };
            let bottom = probe.bounds.min[2] + dz;
            let accepted = match mode {
                ChildMode::Stack { .. } => (bottom - centre[2]).abs() <= 0.004,
                ChildMode::Upright { .. } => (bottom - centre[2]).abs() <= 0.004,
                ChildMode::Inside => bottom <= support_top - 0.01 && bottom >= centre[2] - 0.002,
            };
            if !accepted {
                continue;
            }
            let position = [centre[0] + offset[0], centre[1] + offset[1], dz];
            let mesh = self.vertical_mesh(asset, scale, rotation, position);
            let description = self.description(asset);
            return Ok(self.push(
                Placed {
                    asset,
                    scale,
                    rotation_xyzw: rotation,
                    position_m: position,
                    support: rests_on,
                    description,
                },
                mesh,
            ));
        }
        Err(NoRoom)
    }

    fn sample_in_surface(&mut self, surface: &Surface, support: usize, fraction: f64) -> [f64; 2] {
        let s = &self.objects[support];
        let scale = s.scale;
        let m = crate::mesh::quat_to_matrix(s.rotation_xyzw);
        match *surface {
            Surface::Round { radius_m } => {
                let r = radius_m * scale * fraction * self.rng.random::<f64>().sqrt();
                let t = self.rng.random_range(0.0..std::f64::consts::TAU);
                [r * t.cos(), r * t.sin()]
            }
            Surface::Rect { half_x_m, half_z_m } => {
                let lx = self.rng.random_range(-1.0..1.0) * half_x_m * scale * fraction;
                let ly = self.rng.random_range(-1.0..1.0) * half_z_m * scale * fraction;
                [m[0][0] * lx + m[0][1] * ly, m[1][0] * lx + m[1][1] * ly]
            }
        }
    }

    /// The footprint of the table-standing group `object` belongs to.
    fn group_footprint(&self, object: usize) -> [f64; 4] {
        let mut root = object;
        while let Some(s) = self.objects[root].support {
            root = s;
        }
        // Roots were pushed with their footprints in order.
        let nth = self.objects[..=root]
            .iter()
            .filter(|o| o.support.is_none())
            .count()
            - 1;
        self.footprints[nth]
    }

    /// Places one group; on failure everything it placed is taken back.
    fn place_group(&mut self, group: &Group) -> Result<(), NoRoom> {
        let (n_objects, n_footprints) = (self.objects.len(), self.footprints.len());
        let result = self.try_group(group);
        if result.is_err() {
            self.objects.truncate(n_objects);
            self.meshes.truncate(n_objects);
            self.footprints.truncate(n_footprints);
        }
        result
    }

    fn try_group(&mut self, group: &Group) -> Result<(), NoRoom> {
        match *group {
            Group::One(keys) => {
                let key = *pick(self.rng, keys);
                self.place_on_table(key)?;
            }
            Group::Stack {
                keys,
                min,
                max,
                same,
            } => {
                let n = self.rng.random_range(min..=max);
                let mut chosen: Vec<&str> = if same {
                    vec![*pick(self.rng, keys); n]
                } else {
                    (0..n).map(|_| *pick(self.rng, keys)).collect()
                };
                // Largest footprint at the bottom.
                chosen.sort_by(|a, b| {
                    let area = |k: &str| {
                        let s = self.lib.assets[self.asset(k)].bounds_table_axes.size();
                        s[0] * s[1]
                    };
                    area(b).total_cmp(&area(a))
                });
                let mut below = self.place_on_table(chosen[0])?;
                let base = below;
                for key in &chosen[1..] {
                    let mode = if same {
                        ChildMode::Stack {
                            jitter_m: 0.003,
                            yaw_jitter_deg: 180.0,
                        }
                    } else {
                        ChildMode::Stack {
                            jitter_m: 0.012,
                            yaw_jitter_deg: 12.0,
                        }
                    };
                    below = self.place_on(below, key, mode, same.then_some(base))?;
                }
            }
            Group::Fill {
                holder,
                contents,
                min,
                max,
                upright,
            } => {
                let key = *pick(self.rng, holder);
                let holder = self.place_on_table(key)?;
                let n = self.rng.random_range(min..=max);
                let mut placed = 0;
                for index in 0..n {
                    let key = *pick(self.rng, contents);
                    let mode = if upright {
                        ChildMode::Upright { index, count: n }
                    } else {
                        ChildMode::Inside
                    };
                    if self.place_on(holder, key, mode, None).is_ok() {
                        placed += 1;
                    }
                }
                if placed == 0 {
                    return Err(NoRoom);
                }
            }
            Group::OnTop { base, top } => {
                let key = *pick(self.rng, base);
                let base = self.place_on_table(key)?;
                let key = *pick(self.rng, top);
                self.place_on(
                    base,
                    key,
                    ChildMode::Stack {
                        jitter_m: 0.02,
                        yaw_jitter_deg: 180.0,
                    },
                    None,
                )?;
            }
        }
        Ok(())
    }
}

#[derive(Debug, Clone, Copy)]
enum ChildMode {
    /// On a flat or dished top, near its centre.
    Stack { jitter_m: f64, yaw_jitter_deg: f64 },
    /// Anywhere inside a container.
    Inside,
    /// Standing up, leaning, `index` of `count` around the centre.
    Upright { index: usize, count: usize },
}

/// How many objects a scene on `table` aims for.
fn target_count(table: &Table, rng: &mut impl RngCore) -> usize {
    let area = table.width_m * table.depth_m;
    let busy = if rng.random_bool(0.2) { 6.0 } else { 0.0 };
    let n = rng.random_range(5.0..12.0) + area * 5.0 + busy;
    (n.round() as usize).clamp(5, 25)
}

/// Composes the objects of a scene on `table`. Returns `None` when fewer than `min_objects`
/// could be placed (the caller draws a new scene).
pub(crate) fn compose(
    lib: &Library,
    table: &Table,
    rng: &mut impl RngCore,
    min_objects: usize,
) -> Option<Vec<Placed>> {
    let target = target_count(table, rng);
    let entries = recipe(table.kind);
    let mut used = vec![0usize; entries.len()];
    let mut composer = Composer {
        lib,
        rng,
        table,
        objects: Vec::new(),
        meshes: Vec::new(),
        footprints: Vec::new(),
    };
    let mut failures = 0;
    while composer.objects.len() < target && failures < 30 {
        let room = 25 - composer.objects.len();
        let candidates: Vec<usize> = (0..entries.len())
            .filter(|&i| {
                used[i] < entries[i].max_per_scene && entries[i].group.max_objects() <= room
            })
            .collect();
        if candidates.is_empty() {
            break;
        }
        let total: f64 = candidates.iter().map(|&i| entries[i].weight).sum();
        let mut ticket = composer.rng.random_range(0.0..total);
        let mut chosen = candidates[candidates.len() - 1];
        for &i in &candidates {
            if ticket < entries[i].weight {
                chosen = i;
                break;
            }
            ticket -= entries[i].weight;
        }
        match composer.place_group(&entries[chosen].group) {
            Ok(()) => used[chosen] += 1,
            Err(NoRoom) => failures += 1,
        }
    }
    (composer.objects.len() >= min_objects).then_some(composer.objects)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn every_recipe_key_is_in_the_catalogue_and_used_somewhere() {
        let lib = Library::build().expect("library");
        let mut used = std::collections::BTreeSet::new();
        for kind in TableType::ALL {
            for entry in recipe(kind) {
                let keys: Vec<&str> = match entry.group {
                    Group::One(k) => k.to_vec(),
                    Group::Stack { keys, .. } => keys.to_vec(),
                    Group::Fill {
                        holder, contents, ..
                    } => holder.iter().chain(contents).copied().collect(),
                    Group::OnTop { base, top } => base.iter().chain(top).copied().collect(),
                };
                for k in keys {
                    assert!(lib.index_of(k).is_some(), "{k}");
                    used.insert(k);
                }
            }
        }
        for a in lib.assets.iter().filter(|a| a.def.in_scenes) {
            assert!(used.contains(a.def.key), "{} is in no recipe", a.def.key);
        }
    }

    #[test]
    fn composed_objects_stay_on_the_table_and_out_of_the_sink() {
        let lib = Library::build().expect("library");
        for (i, kind) in TableType::ALL.iter().enumerate() {
            let mut rng = ChaCha8Rng::seed_from_u64(100 + i as u64);
            let table = make_table(*kind, &mut rng);
            let objects = compose(&lib, &table, &mut rng, 5).expect("a scene");
            assert!(
                (5..=25).contains(&objects.len()),
                "{} objects",
                objects.len()
            );
            for o in &objects {
                let a = &lib.assets[o.asset];
                let b = a
                    .baked_table_axes
                    .iter()
                    .filter_map(|(m, _)| m.transformed(&o.world_from_asset(a)).bounds())
                    .reduce(|x, y| x.union(&y))
                    .expect("bounds");
                assert!(
                    b.min[0] >= -1e-9 && b.max[0] <= table.width_m + 1e-9,
                    "{:?}",
                    b
                );
                assert!(
                    b.min[1] >= -1e-9 && b.max[1] <= table.depth_m + 1e-9,
                    "{:?}",
                    b
                );
                assert!(b.min[2] >= -1e-9, "{:?}", b);
                if let Some(sink) = &table.sink {
                    let fp = [b.min[0], b.max[0], b.min[1], b.max[1]];
                    assert!(disjoint(&sink.zone_m, &fp, 0.0));
                }
            }
        }
    }
}
