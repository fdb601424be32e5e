//! `check`: mesh-level physics QA of a scene layout (SPEC 5.6), and settling.
//!
//! Every object is its asset's collision shape — the convex decomposition `mesa assets` caches
//! in `assets/index/shapes/` (a bowl's or a cup's cavity stays empty) — placed by the layout
//! ([`shapes`]: position, full rotation, scale along the asset's own axes). Then:
//!
//! - **collisions**: two objects collide when some convex part of one overlaps some part of
//!   the other deeper than `penetration_tolerance_mm` (the depth is the length of the shortest
//!   translation that separates the two parts: parry3d's GJK and EPA). Touching is not
//!   colliding; an apple resting in a bowl touches only the bowl's floor part.
//! - **floating**: an object floats when it could fall farther than `floating_tolerance_mm`
//!   straight down before touching the table top (z = 0) or another object (a shape cast of
//!   each part against the parts under it); contacts side by side do not hold anything up.
//! - **zone violations**: a shape reaching beyond the item placement zone, over the
//!   restricted zone (the sink), or into the table top.
//! - the paper's **collision rate** = colliding pairs / all pairs, and for comparison the pairs
//!   MesaTask's released code would call colliding (closer than 5 cm: it counts touching and
//!   nearby objects).
//!
//! Convex parts reach a little outside the mesh they cover, and a layout's scale multiplies
//! that reach. An object whose parts may reach past its mesh by more than
//! [`shapes::LOOSE_REACH_M`] at its scale is *loose*: its collisions, falls, table contact and
//! zone are judged on its own triangle mesh ([`solid`]), and a collision the parts find between
//! any two objects is at least as deep as the deepest point of one mesh inside the other.
//!
//! [`settle`] moves objects by the least motion that removes collisions and floating while
//! keeping the scene graph's `in` and `above` relations.

pub mod geometry;
pub mod scene;
pub mod settle;
pub mod shapes;
pub mod simulate;
pub mod solid;

use std::sync::Arc;

use mesa_schemas::artifacts::{CheckFindings, CollisionPair, FloatingObject, ZoneViolation};
use mesa_schemas::{DatasetLayout, LayoutObject};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use self::geometry::{fall_distance, proximity, Bounds, Hull};
pub use self::scene::{check_layout, LayoutSource as CheckedLayout, SceneCheck, SETTLED_LAYOUT};
pub use self::shapes::{AssetShape, Body, HullMesh, PartMesh, Pose, ShapeError};

/// Which layout of a scene `mesa check` reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum LayoutSource {
    /// `refined/layout.json`, the annotator's layout after `mesa ingest`.
    Refined,
    /// `coarse/layout.json`, the layout of `mesa place` (before the annotator).
    Coarse,
}

impl LayoutSource {
    /// The layout file, relative to the scene folder.
    pub fn file(self) -> &'static str {
        match self {
            Self::Refined => crate::paths::scene::REFINED_LAYOUT,
            Self::Coarse => crate::paths::scene::COARSE_LAYOUT,
        }
    }
}

/// The `[check]` section of `mesa.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct CheckConfig {
    /// The layout checked: "refined" (refined/layout.json, written by `mesa ingest`; scenes
    /// without one are reported and left unchecked) or "coarse" (coarse/layout.json, the
    /// layout of `mesa place`). `--layout` overrides it.
    pub layout: LayoutSource,
    /// Two objects collide when they interpenetrate deeper than this, mm.
    pub penetration_tolerance_mm: f64,
    /// An object floats when it could fall farther than this before touching the table or
    /// another object, mm.
    pub floating_tolerance_mm: f64,
    /// An object may reach beyond the placement zone, or over the restricted zone, by this
    /// much before it is a violation, mm.
    pub zone_tolerance_mm: f64,
    /// MesaTask's released rule, reported for comparison only: pairs closer than this are
    /// "colliding", cm.
    pub mesatask_rule_distance_cm: f64,
    /// Settle every checked scene (as `--settle`): move objects by the least motion that
    /// removes collisions and floating, and write qa/layout.json, which later stages read.
    pub settle: bool,
    /// Settling.
    pub settling: settle::SettleConfig,
}

impl Default for CheckConfig {
    fn default() -> Self {
        Self {
            layout: LayoutSource::Refined,
            penetration_tolerance_mm: 2.0,
            floating_tolerance_mm: 2.0,
            zone_tolerance_mm: 5.0,
            mesatask_rule_distance_cm: 5.0,
            settle: false,
            settling: settle::SettleConfig::default(),
        }
    }
}

impl CheckConfig {
    /// What is wrong with the values, one line each.
    pub fn problems(&self) -> Vec<String> {
        let mut problems = Vec::new();
        for (name, value) in [
            ("penetration_tolerance_mm", self.penetration_tolerance_mm),
            ("floating_tolerance_mm", self.floating_tolerance_mm),
            ("zone_tolerance_mm", self.zone_tolerance_mm),
            ("mesatask_rule_distance_cm", self.mesatask_rule_distance_cm),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                problems.push(format!(
                    "[check] {name} is {value} (expected a number >= 0)"
                ));
            }
        }
        problems.extend(self.settling.problems());
        problems
    }

    /// The tolerances in metres.
    pub fn tolerances(&self) -> Tolerances {
        Tolerances {
            penetration_m: self.penetration_tolerance_mm / 1000.0,
            floating_m: self.floating_tolerance_mm / 1000.0,
            zone_m: self.zone_tolerance_mm / 1000.0,
            mesatask_m: self.mesatask_rule_distance_cm / 100.0,
        }
    }
}

/// The check's thresholds, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tolerances {
    /// Deeper overlaps collide.
    pub penetration_m: f64,
    /// Larger falls float.
    pub floating_m: f64,
    /// Larger reaches beyond the zones are violations.
    pub zone_m: f64,
    /// MesaTask's distance rule.
    pub mesatask_m: f64,
}

impl Default for Tolerances {
    fn default() -> Self {
        CheckConfig::default().tolerances()
    }
}

/// An object of a scene, placed, or why it could not be.
#[derive(Debug, Clone)]
pub struct PlacedObject {
    /// The instance.
    pub instance: String,
    /// Its shape in the table frame, or why there is none.
    pub body: Result<Body, String>,
    /// How far its parts may reach outside its mesh at the layout's scale, metres (see
    /// [`AssetShape::reach_at`]; 0 without a shape).
    pub reach_m: f64,
}

/// A scene ready to check: the zones and the placed objects, in layout order.
#[derive(Debug, Clone)]
pub struct PhysicsScene {
    /// The item placement zone `[x_min, x_max, y_min, y_max]`, metres.
    pub zone_m: [f64; 4],
    /// The restricted zone, metres.
    pub restricted_zone_m: Option<[f64; 4]>,
    /// The objects.
    pub objects: Vec<PlacedObject>,
}

impl PhysicsScene {
    /// A dataset layout placed with the shapes `shape_of` gives for each object (or the reason
    /// it has none).
    pub fn from_layout(
        layout: &DatasetLayout,
        shape_of: impl Fn(&LayoutObject) -> Result<Arc<AssetShape>, String>,
    ) -> Self {
        let objects = layout
            .objects
            .iter()
            .map(|object| {
                let pose = Pose::of_object(object);
                let shape = shape_of(object);
                PlacedObject {
                    instance: object.instance.clone(),
                    reach_m: shape.as_ref().map_or(0.0, |s| s.reach_at(&pose)),
                    body: shape.and_then(|shape| {
                        Body::of_shape(&shape, &pose)
                            .ok_or_else(|| format!("asset {}: no convex part", shape.uid))
                    }),
                }
            })
            .collect();
        Self {
            zone_m: layout.zone_cm.0.map(|v| v / 100.0),
            restricted_zone_m: layout.restricted_zone_cm.map(|z| z.0.map(|v| v / 100.0)),
            objects,
        }
    }

    fn body(&self, i: usize) -> Option<&Body> {
        self.objects[i].body.as_ref().ok()
    }

    /// Indices of the objects that have a body.
    pub fn checked(&self) -> Vec<usize> {
        (0..self.objects.len())
            .filter(|i| self.objects[*i].body.is_ok())
            .collect()
    }
}

/// The kinds of zone violation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum ViolationKind {
    /// Beyond the item placement zone.
    OutsideZone,
    /// Over the restricted zone.
    InRestrictedZone,
    /// Into the table top.
    BelowTable,
}

impl ViolationKind {
    /// The name in `check.json`.
    pub fn name(self) -> &'static str {
        match self {
            Self::OutsideZone => "outside_zone",
            Self::InRestrictedZone => "in_restricted_zone",
            Self::BelowTable => "below_table",
        }
    }
}

/// A colliding pair, by object index.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Collision {
    /// The first object (the smaller index).
    pub a: usize,
    /// The second object.
    pub b: usize,
    /// Penetration depth, metres.
    pub depth_m: f64,
    /// The direction from `a` toward `b` along which the deepest parts separate fastest.
    pub normal: [f64; 3],
}

/// What supports an object: the table or another object.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Support {
    /// The table top.
    Table,
    /// Another object.
    Object(usize),
}

/// How far an object could fall, and onto what.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fall {
    /// The object.
    pub object: usize,
    /// The fall, metres (0 when it rests on or sinks into what is under it).
    pub gap_m: f64,
    /// What it would land on.
    pub over: Support,
}

/// Everything a check finds, by object index, in metres.
#[derive(Debug, Clone, PartialEq)]
pub struct Findings {
    /// Colliding pairs.
    pub collisions: Vec<Collision>,
    /// The fall of every checked object (floating or not).
    pub falls: Vec<Fall>,
    /// The floating objects (falls beyond the tolerance).
    pub floating: Vec<Fall>,
    /// Zone violations: object, kind, amount (metres).
    pub violations: Vec<(usize, ViolationKind, f64)>,
    /// Pairs of checked objects.
    pub pairs_total: u64,
    /// Pairs closer than MesaTask's distance.
    pub mesatask_rule_pairs: u64,
    /// Objects without a body.
    pub unchecked: usize,
}

impl Findings {
    /// Colliding pairs / all pairs (0 without pairs).
    pub fn collision_rate(&self) -> f64 {
        if self.pairs_total == 0 {
            0.0
        } else {
            self.collisions.len() as f64 / self.pairs_total as f64
        }
    }

    /// At rest: every object checked, no collision, nothing floating or sunk into the table
    /// (what settling must reach; zone violations may remain when an object cannot fit).
    pub fn physical(&self) -> bool {
        self.collisions.is_empty()
            && self.floating.is_empty()
            && self.unchecked == 0
            && !self
                .violations
                .iter()
                .any(|(_, kind, _)| *kind == ViolationKind::BelowTable)
    }

    /// No collision, no floating, no violation, every object checked.
    pub fn clean(&self) -> bool {
        self.collisions.is_empty()
            && self.floating.is_empty()
            && self.violations.is_empty()
            && self.unchecked == 0
    }

    /// The findings as `check.json` states them (names, mm and cm, sorted).
    pub fn to_schema(&self, scene: &PhysicsScene) -> CheckFindings {
        let name = |i: usize| scene.objects[i].instance.clone();
        let mut collisions: Vec<CollisionPair> = self
            .collisions
            .iter()
            .map(|c| {
                let (a, b) = (name(c.a), name(c.b));
                let (a, b) = if a <= b { (a, b) } else { (b, a) };
                CollisionPair {
                    a,
                    b,
                    depth_mm: round_to(c.depth_m * 1000.0, 3),
                }
            })
            .collect();
        collisions.sort_by(|x, y| (&x.a, &x.b).cmp(&(&y.a, &y.b)));
        let mut floating: Vec<FloatingObject> = self
            .floating
            .iter()
            .map(|f| FloatingObject {
                instance: name(f.object),
                gap_mm: round_to(f.gap_m * 1000.0, 3),
                over: match f.over {
                    Support::Table => "table".to_owned(),
                    Support::Object(j) => name(j),
                },
            })
            .collect();
        floating.sort_by(|x, y| x.instance.cmp(&y.instance));
        let mut zone_violations: Vec<ZoneViolation> = self
            .violations
            .iter()
            .map(|(i, kind, amount)| ZoneViolation {
                instance: name(*i),
                kind: kind.name().to_owned(),
                amount_cm: round_to(amount * 100.0, 4),
            })
            .collect();
        zone_violations.sort_by(|x, y| (&x.instance, &x.kind).cmp(&(&y.instance, &y.kind)));
        CheckFindings {
            collision_rate: self.collision_rate(),
            collisions,
            floating,
            zone_violations,
            pairs_total: self.pairs_total,
            mesatask_rule_pairs: self.mesatask_rule_pairs,
            clean: self.clean(),
        }
    }
}

/// `value` rounded to `decimals` (never `-0`).
pub fn round_to(value: f64, decimals: i32) -> f64 {
    let scale = 10f64.powi(decimals);
    (value * scale).round() / scale + 0.0
}

/// How two bodies relate: the deepest overlap of their parts, and whether they are closer than
/// `near_m`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PairContact {
    /// The deepest overlap of a part of the first with a part of the second, metres (0 when no
    /// parts overlap).
    pub depth_m: f64,
    /// The direction from the first toward the second for that overlap.
    pub normal: [f64; 3],
    /// Whether some parts are closer than `near_m`.
    pub near: bool,
}

/// The contact of two bodies (and whether they are within `near_m`).
pub fn pair_contact(a: &Body, b: &Body, near_m: f64) -> Option<PairContact> {
    pair_contact_deeper_than(a, b, near_m, 0.0)
}

/// [`pair_contact`] for a caller that needs the depth only where it exceeds `floor_m`: a pair
/// of parts whose boxes overlap by no more than `floor_m` along some axis cannot be deeper (a
/// part's box has the part's own extent along each axis, so separating the boxes along that
/// axis separates the parts), and its depth is not measured. `depth_m` is then exact above
/// `floor_m` and at most `floor_m` otherwise. Most touching objects (a mug on the table beside
/// a book, a fruit on a plate) are settled by the boxes alone.
pub fn pair_contact_deeper_than(
    a: &Body,
    b: &Body,
    near_m: f64,
    floor_m: f64,
) -> Option<PairContact> {
    if a.bounds.distance(&b.bounds) >= near_m.max(0.0) && !a.bounds.overlaps(&b.bounds, 0.0) {
        return None;
    }
    let mut contact = PairContact {
        depth_m: 0.0,
        normal: [0.0, 0.0, 1.0],
        near: false,
    };
    let mut deferred: Vec<(&Hull, &Hull)> = Vec::new();
    for ha in &a.hulls {
        for hb in &b.hulls {
            if ha.bounds.overlaps(&hb.bounds, 0.0) {
                if box_overlap(&ha.bounds, &hb.bounds) <= floor_m {
                    deferred.push((ha, hb));
                    continue;
                }
                let p = proximity(ha, hb);
                if -p.signed_distance_m > contact.depth_m {
                    contact.depth_m = -p.signed_distance_m;
                    contact.normal = p.normal;
                }
                if p.signed_distance_m < near_m {
                    contact.near = true;
                }
            } else if ha.bounds.distance(&hb.bounds) < near_m {
                deferred.push((ha, hb));
            }
        }
    }
    if !contact.near {
        contact.near = deferred
            .into_iter()
            .any(|(ha, hb)| proximity(ha, hb).signed_distance_m < near_m);
    }
    Some(contact)
}

/// The least translation along one of the three axes that separates two overlapping boxes:
/// an upper bound of the penetration depth of anything inside them (moving one box that far
/// moves its content out of the other's). Along an axis the way out is the shorter of pushing
/// one box past the other's far side or its near side, `min(a.max − b.min, b.max − a.min)`:
/// the overlap length when the intervals partly overlap, but more when one lies inside the
/// other (a 1.7 mm phone buried 27 mm deep in a towel overlaps it by 1.7 mm in height, yet
/// must move about 27 mm to get out).
fn box_overlap(a: &Bounds, b: &Bounds) -> f64 {
    (0..3)
        .map(|k| (a.max[k] - b.min[k]).min(b.max[k] - a.min[k]))
        .fold(f64::INFINITY, f64::min)
}

/// The depth a pair is judged at, given the deepest overlap of their parts.
///
/// A pair the parts find deeper than `penetration_m` is measured on the meshes too
/// ([`solid::deepest`]: the deepest point of one mesh inside the other):
/// - when either object is loose, that is the depth (its parts bulge past its mesh, so their
///   overlap overstates it);
/// - else the depth is the larger of the two: several parts meeting inside a solid each overlap
///   a piercing object less than the solid does. Only an object of several parts can hold a
///   point deeper than the parts' overlap (a point inside one convex part must move at least its
///   depth in that part to get out), and only a gain beyond [`DEPTH_GAIN_M`] is measured.
///
/// Without meshes, the parts' depth.
pub fn judged_depth(a: &Body, b: &Body, parts_depth_m: f64, penetration_m: f64) -> f64 {
    if parts_depth_m <= penetration_m {
        return parts_depth_m;
    }
    let loose = a.judged_solid().is_some() || b.judged_solid().is_some();
    if !loose && a.hulls.len() == 1 && b.hulls.len() == 1 {
        return parts_depth_m;
    }
    let (Some(Ok(x)), Some(Ok(y))) = (a.solid(), b.solid()) else {
        return parts_depth_m;
    };
    let floor = if loose {
        penetration_m
    } else {
        parts_depth_m + DEPTH_GAIN_M
    };
    let a_in_b = if loose || b.hulls.len() > 1 {
        solid::deepest(x, y, floor)
    } else {
        0.0
    };
    let b_in_a = if loose || a.hulls.len() > 1 {
        solid::deepest(y, x, floor)
    } else {
        0.0
    };
    let mesh = a_in_b.max(b_in_a);
    if loose {
        mesh
    } else {
        mesh.max(parts_depth_m)
    }
}

/// How much deeper than their parts' overlap two objects that are not loose must be on their
/// meshes for it to count (metres): the slack the exact-mesh reference allows a depth.
pub const DEPTH_GAIN_M: f64 = 0.001;

/// A contact holds an object up when the way out of it (from the object toward the other)
/// points down by more than this (the sine of about 3°): the other pushes back with an upward
/// component. A contact exactly side by side holds nothing.
const SUPPORT_MIN_DOWNWARD: f64 = 0.05;

/// A contact whose way out points down at least this much (the cosine of 60°) holds an object
/// up on the parts' word. A steeper one (a pen leaning on a book's edge) is judged on the
/// meshes: the vertical gap is the gap across the contact over this slope, so parts within
/// 0.5 mm of their mesh ([`shapes::LOOSE_REACH_M`]) put a flat enough contact within 1 mm
/// of the meshes' vertical gap, and a steep one up to 10 mm off.
const SUPPORT_FLAT_DOWNWARD: f64 = 0.5;

/// The two meshes when a pair is judged on them: either object loose, both meshes read.
fn on_meshes<'x>(
    body: &'x Body,
    other: &'x Body,
) -> Option<(solid::SolidAt<'x>, solid::SolidAt<'x>)> {
    if !(body.loose() || other.loose()) {
        return None;
    }
    match (body.solid(), other.solid()) {
        (Some(Ok(m)), Some(Ok(o))) => Some((m, o)),
        _ => None,
    }
}

/// How far `body` could fall before touching the table top or one of `others` (index,
/// body), and onto what; 0 when it already rests on something.
///
/// Only the others that reach below its lowest point can hold it up: one standing on it, or
/// sunk into its top, presses it down.
///
/// It rests on the table when its lowest point is within `touch_m` of the table top (or below
/// it), and on another object when some part of it is within `touch_m` of a part of the other
/// in a direction pointing down (a fruit leaning on another fruit's side rests on it). Else it
/// falls straight down: see [`fall_distance`] (measured from `touch_m` higher, so that a part
/// sunk into what carries it by less than that lands on it).
///
/// A loose body's lowest point is its mesh's, and a pair with a loose body is judged on the
/// two meshes ([`solid::fall_onto`]: vertical rays between them; resting within `touch_m`), as
/// is a pair whose only support is a steep contact (`SUPPORT_FLAT_DOWNWARD`).
pub fn fall_of<'a>(
    body: &Body,
    others: impl Iterator<Item = (usize, &'a Body)> + Clone,
    touch_m: f64,
) -> (f64, Support) {
    let lowest = body.judged_bounds().min[2];
    let mut gap = lowest.max(0.0);
    if gap <= touch_m {
        return (0.0, Support::Table);
    }
    // Without this, parts raised by `touch_m` into an object standing on the body, or points
    // inside it, counted as resting on it.
    let others = others.filter(move |(_, other)| other.judged_bounds().min[2] < lowest);
    // Pairs with a loose object are judged on their meshes.
    let mut over = Support::Table;
    let mut steep_on_meshes: Vec<usize> = Vec::new();
    for (j, other) in others.clone() {
        let Some((m, o)) = on_meshes(body, other) else {
            continue;
        };
        if let Some(d) = solid::fall_onto(m, o, touch_m, gap) {
            if d <= touch_m {
                return (0.0, Support::Object(j));
            }
            if d < gap {
                gap = d;
                over = Support::Object(j);
            }
        }
    }
    for (j, other) in others.clone() {
        if body.bounds.distance(&other.bounds) > touch_m
            || other.bounds.min[2] >= body.bounds.max[2]
            || on_meshes(body, other).is_some()
        {
            continue;
        }
        let mut steep = false;
        for hm in &body.hulls {
            for hf in &other.hulls {
                if hm.bounds.distance(&hf.bounds) > touch_m {
                    continue;
                }
                let p = proximity(hm, hf);
                if p.signed_distance_m <= touch_m && p.normal[2] < -SUPPORT_MIN_DOWNWARD {
                    if p.normal[2] <= -SUPPORT_FLAT_DOWNWARD {
                        return (0.0, Support::Object(j));
                    }
                    steep = true;
                }
            }
        }
        if steep {
            // Held only on a steep contact: the vertical gap is the parts' gap over the slope,
            // so their reach counts several times over; judged on the meshes when they can be.
            match (body.solid(), other.solid()) {
                (Some(Ok(m)), Some(Ok(o))) => {
                    steep_on_meshes.push(j);
                    if let Some(d) = solid::fall_onto(m, o, touch_m, gap) {
                        if d <= touch_m {
                            return (0.0, Support::Object(j));
                        }
                        if d < gap {
                            gap = d;
                            over = Support::Object(j);
                        }
                    }
                }
                _ => return (0.0, Support::Object(j)),
            }
        }
    }
    for (j, other) in others {
        if !body.bounds.overlaps_xy(&other.bounds, 0.0)
            || other.bounds.min[2] >= body.bounds.max[2] + touch_m
            || body.bounds.min[2] - other.bounds.max[2] >= gap
            || on_meshes(body, other).is_some()
            || steep_on_meshes.contains(&j)
        {
            continue;
        }
        for hm in &body.hulls {
            for hf in &other.hulls {
                if !hm.bounds.overlaps_xy(&hf.bounds, 0.0)
                    || hf.bounds.min[2] >= hm.bounds.max[2] + touch_m
                    || hm.bounds.min[2] - hf.bounds.max[2] >= gap
                {
                    continue;
                }
                if let Some(d) = fall_distance(hm, hf, touch_m, gap) {
                    if d < gap {
                        gap = d;
                        over = Support::Object(j);
                    }
                }
            }
        }
    }
    (gap, over)
}

/// How far the parts of `body` reach over the restricted zone (a tall box over it), metres.
fn restricted_reach(body: &Body, zone: &[f64; 4]) -> f64 {
    let column = Bounds {
        min: [zone[0], zone[2], -10.0],
        max: [zone[1], zone[3], 10.0],
    };
    if !body.bounds.overlaps(&column, 0.0) {
        return 0.0;
    }
    let mut corners = Vec::with_capacity(8);
    for x in [column.min[0], column.max[0]] {
        for y in [column.min[1], column.max[1]] {
            for z in [column.min[2], column.max[2]] {
                corners.push([x, y, z]);
            }
        }
    }
    let Some(column_hull) = Hull::new(&corners) else {
        return 0.0;
    };
    body.hulls
        .iter()
        .filter(|h| h.bounds.overlaps(&column, 0.0))
        .map(|h| -proximity(h, &column_hull).signed_distance_m)
        .fold(0.0, f64::max)
}

/// The zone violations of one body: (kind, amount in metres), beyond the tolerance.
pub fn violations_of(
    body: &Body,
    zone: &[f64; 4],
    restricted: Option<&[f64; 4]>,
    tolerances: &Tolerances,
) -> Vec<(ViolationKind, f64)> {
    let mut out = Vec::new();
    let b = &body.judged_bounds();
    let beyond = [
        zone[0] - b.min[0],
        b.max[0] - zone[1],
        zone[2] - b.min[1],
        b.max[1] - zone[3],
    ]
    .into_iter()
    .fold(0.0, f64::max);
    if beyond > tolerances.zone_m {
        out.push((ViolationKind::OutsideZone, beyond));
    }
    if let Some(r) = restricted {
        let reach = restricted_reach(body, r);
        if reach > tolerances.zone_m {
            out.push((ViolationKind::InRestrictedZone, reach));
        }
    }
    if -b.min[2] > tolerances.penetration_m {
        out.push((ViolationKind::BelowTable, -b.min[2]));
    }
    out
}

/// The colliding pairs of a placed scene only (deeper than `penetration_m`).
pub fn collisions_of(scene: &PhysicsScene, penetration_m: f64) -> Vec<Collision> {
    let checked = scene.checked();
    let mut out = Vec::new();
    for (x, &i) in checked.iter().enumerate() {
        let Some(a) = scene.body(i) else { continue };
        for &j in &checked[x + 1..] {
            let Some(b) = scene.body(j) else { continue };
            if let Some(contact) = pair_contact_deeper_than(a, b, 0.0, penetration_m) {
                let depth_m = judged_depth(a, b, contact.depth_m, penetration_m);
                if depth_m > penetration_m {
                    out.push(Collision {
                        a: i,
                        b: j,
                        depth_m,
                        normal: contact.normal,
                    });
                }
            }
        }
    }
    out
}

/// Checks a placed scene.
pub fn check_scene(scene: &PhysicsScene, tolerances: &Tolerances) -> Findings {
    let checked = scene.checked();
    let n = checked.len() as u64;
    let mut findings = Findings {
        collisions: Vec::new(),
        falls: Vec::new(),
        floating: Vec::new(),
        violations: Vec::new(),
        pairs_total: n * n.saturating_sub(1) / 2,
        mesatask_rule_pairs: 0,
        unchecked: scene.objects.len() - checked.len(),
    };
    for (x, &i) in checked.iter().enumerate() {
        let Some(a) = scene.body(i) else { continue };
        for &j in &checked[x + 1..] {
            let Some(b) = scene.body(j) else { continue };
            let Some(contact) =
                pair_contact_deeper_than(a, b, tolerances.mesatask_m, tolerances.penetration_m)
            else {
                continue;
            };
            if contact.near {
                findings.mesatask_rule_pairs += 1;
            }
            let depth_m = judged_depth(a, b, contact.depth_m, tolerances.penetration_m);
            if depth_m > tolerances.penetration_m {
                findings.collisions.push(Collision {
                    a: i,
                    b: j,
                    depth_m,
                    normal: contact.normal,
                });
            }
        }
    }
    for &i in &checked {
        let Some(body) = scene.body(i) else { continue };
        let others = checked
            .iter()
            .filter(|&&j| j != i)
            .filter_map(|&j| scene.body(j).map(|b| (j, b)));
        let (gap_m, over) = fall_of(body, others, tolerances.floating_m);
        let fall = Fall {
            object: i,
            gap_m,
            over,
        };
        findings.falls.push(fall);
        if gap_m > tolerances.floating_m {
            findings.floating.push(fall);
        }
        for (kind, amount) in violations_of(
            body,
            &scene.zone_m,
            scene.restricted_zone_m.as_ref(),
            tolerances,
        ) {
            findings.violations.push((i, kind, amount));
        }
    }
    findings
}

#[cfg(test)]
mod tests;
