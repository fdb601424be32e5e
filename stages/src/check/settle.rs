//! Settling: the least motion that removes collisions, floating and zone violations while
//! keeping what holds what.
//!
//! Every object belongs to a tree: what it is `in` or `above` in the scene graph holds it (its
//! parent); an object with no parent stands on the table (a root). A move of an object moves
//! everything it holds, so stacked stays stacked and contained stays contained. Rounds of
//! three passes repeat until a check finds nothing (or `max_rounds` run out):
//!
//! 1. **push apart** each colliding pair, deepest first, by its penetration depth plus a
//!    clearance: an object held by the other moves out along the contact normal (an apple
//!    sunk into its bowl's wall moves inward, one sunk into the floor moves up); two trees
//!    standing on the table slide apart in the plane, each by half (or, overlapping one above
//!    the other with its centre over the lower's footprint, the upper one is lifted onto the
//!    lower, where it lies flat; lifted onto the lower's end it would lie tilted, held by
//!    friction alone, so such a pair slides apart); two objects held by the same
//!    object move apart by half each;
//! 2. **zones**: a tree reaching beyond the placement zone, or over the restricted zone,
//!    slides back in (out) by the shortest way;
//! 3. **drop**: from the bottom up, an object sunk into the table top rises onto it, and a
//!    floating one falls straight down onto what is under it (parry3d's shape cast).
//!
//! Rotations and sizes never change. The goal is a scene at rest (no collision, nothing
//! floating or sunk into the table); a zone violation that cannot be helped (an object larger
//! than the zone) stays, reported. A scene that does not come to rest within `max_rounds`, or
//! that would need an object moved farther than `max_displacement_cm`, is reported unsettled,
//! not forced.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::geometry::Bounds;
use super::{
    check_scene, fall_of, pair_contact, Findings, PhysicsScene, Tolerances, ViolationKind,
};

/// The `[check.settling]` section of `mesa.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct SettleConfig {
    /// Rounds of push-apart, zone and drop passes before a scene is given up.
    pub max_rounds: u32,
    /// Gap left between objects pushed apart, mm.
    pub clearance_mm: f64,
    /// A scene needing an object moved farther than this is left unsettled, cm.
    pub max_displacement_cm: f64,
    /// After the least-motion moves, simulate the scene under gravity (rapier3d, on the
    /// objects' convex parts) so that it comes to rest where it would stay, and verify that
    /// it does (`docs/check.md`).
    pub simulate: bool,
    /// Simulated time, seconds (at least).
    pub simulated_s: f64,
    /// While something still moves after `simulated_s`, the simulation goes on, a rest
    /// window at a time, up to this, seconds.
    pub max_simulated_s: f64,
    /// Fixed simulation steps per simulated second.
    pub steps_per_second: u32,
    /// The last part of the simulation over which no object may move farther than
    /// `rest_motion_mm`, seconds.
    pub rest_window_s: f64,
    /// Motion below this is no motion, mm: an object the simulation moves less keeps its
    /// pose; one that moves more over the rest window is not at rest.
    pub rest_motion_mm: f64,
    /// Density of the objects' parts in the simulation, kg/m³ (as `[export] density_kg_m3`).
    pub density_kg_m3: f64,
    /// Friction coefficient of every contact in the simulation: half of `[export]
    /// friction_sliding` by default, a margin. A rest found at this friction holds at any higher
    /// one, and the simulators the scenes go to hold less than their coefficient says (MuJoCo's
    /// soft contacts creep on a slope, PyBullet rolls fruit out of shallow wells): settled at
    /// the export's own 0.8, 5 of 338 demo objects moved in PyBullet; at 0.4, none
    /// (`docs/check.md`).
    pub friction: f64,
    /// A scene with more convex parts than this is not simulated (and left unsettled, with
    /// the reason): the simulation's time grows with its parts.
    pub max_simulated_parts: usize,
}

impl Default for SettleConfig {
    fn default() -> Self {
        Self {
            max_rounds: 40,
            clearance_mm: 0.5,
            max_displacement_cm: 30.0,
            simulate: true,
            simulated_s: 2.0,
            max_simulated_s: 6.0,
            steps_per_second: 240,
            rest_window_s: 0.5,
            rest_motion_mm: 1.0,
            density_kg_m3: 500.0,
            friction: 0.4,
            max_simulated_parts: 20_000,
        }
    }
}

impl SettleConfig {
    /// What is wrong with the values, one line each.
    pub fn problems(&self) -> Vec<String> {
        let mut problems = Vec::new();
        if self.max_rounds == 0 {
            problems.push("[check.settling] max_rounds is 0 (expected at least 1)".to_owned());
        }
        for (name, value) in [
            ("clearance_mm", self.clearance_mm),
            ("max_displacement_cm", self.max_displacement_cm),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                problems.push(format!(
                    "[check.settling] {name} is {value} (expected a number >= 0)"
                ));
            }
        }
        if !(self.simulated_s.is_finite() && self.simulated_s > 0.0 && self.simulated_s <= 60.0) {
            problems.push(format!(
                "[check.settling] simulated_s is {} (expected a number of seconds in (0, 60])",
                self.simulated_s
            ));
        }
        if !(self.max_simulated_s.is_finite()
            && self.max_simulated_s >= self.simulated_s
            && self.max_simulated_s <= 600.0)
        {
            problems.push(format!(
                "[check.settling] max_simulated_s is {} (expected seconds from simulated_s = {} \
                 to 600)",
                self.max_simulated_s, self.simulated_s
            ));
        }
        if self.max_simulated_parts == 0 {
            problems
                .push("[check.settling] max_simulated_parts is 0 (expected at least 1)".to_owned());
        }
        if !(30..=10_000).contains(&self.steps_per_second) {
            problems.push(format!(
                "[check.settling] steps_per_second is {} (expected 30 to 10000)",
                self.steps_per_second
            ));
        }
        if !(self.rest_window_s.is_finite()
            && self.rest_window_s > 0.0
            && self.rest_window_s <= self.simulated_s)
        {
            problems.push(format!(
                "[check.settling] rest_window_s is {} (expected a number of seconds > 0 and at \
                 most simulated_s = {})",
                self.rest_window_s, self.simulated_s
            ));
        }
        for (name, value, floor_open) in [
            ("rest_motion_mm", self.rest_motion_mm, false),
            ("density_kg_m3", self.density_kg_m3, true),
            ("friction", self.friction, false),
        ] {
            let ok = value.is_finite()
                && if floor_open {
                    value > 0.0
                } else {
                    value >= 0.0
                };
            if !ok {
                let bound = if floor_open { "> 0" } else { ">= 0" };
                problems.push(format!(
                    "[check.settling] {name} is {value} (expected a number {bound})"
                ));
            }
        }
        problems
    }

    /// The simulation's settings.
    pub fn simulation(&self) -> super::simulate::SimulationConfig {
        super::simulate::SimulationConfig {
            simulated_s: self.simulated_s,
            max_simulated_s: self.max_simulated_s,
            steps_per_second: self.steps_per_second,
            rest_window_s: self.rest_window_s,
            rest_motion_m: self.rest_motion_mm / 1000.0,
            density_kg_m3: self.density_kg_m3,
            friction: self.friction,
        }
    }
}

/// What settling arrived at.
#[derive(Debug, Clone)]
pub struct Settled {
    /// The scene, moved.
    pub scene: PhysicsScene,
    /// How far each object moved, metres.
    pub offsets_m: Vec<[f64; 3]>,
    /// Rounds run.
    pub rounds: u32,
    /// The check of the moved scene.
    pub findings: Findings,
}

/// The trees of a scene: each object's parent, its children, its root.
struct Forest {
    parents: Vec<Option<usize>>,
    children: Vec<Vec<usize>>,
}

impl Forest {
    /// The forest of `parents`; a parent link that would close a loop is dropped.
    fn new(parents: &[Option<usize>]) -> Self {
        let n = parents.len();
        let mut kept: Vec<Option<usize>> = vec![None; n];
        for i in 0..n {
            let Some(p) = parents[i].filter(|p| *p < n && *p != i) else {
                continue;
            };
            // Following the kept links up from p must not come back to i.
            let mut at = Some(p);
            let mut steps = 0;
            let mut loops = false;
            while let Some(a) = at {
                if a == i {
                    loops = true;
                    break;
                }
                at = kept[a];
                steps += 1;
                if steps > n {
                    loops = true;
                    break;
                }
            }
            if !loops {
                kept[i] = Some(p);
            }
        }
        let mut children = vec![Vec::new(); n];
        for (i, p) in kept.iter().enumerate() {
            if let Some(p) = p {
                children[*p].push(i);
            }
        }
        Self {
            parents: kept,
            children,
        }
    }

    /// The object and everything it holds.
    fn subtree(&self, i: usize) -> Vec<usize> {
        let mut out = vec![i];
        let mut k = 0;
        while k < out.len() {
            out.extend(self.children[out[k]].iter().copied());
            k += 1;
        }
        out
    }

    fn ancestors(&self, i: usize) -> Vec<usize> {
        let mut out = Vec::new();
        let mut at = self.parents[i];
        while let Some(a) = at {
            out.push(a);
            at = self.parents[a];
        }
        out
    }

    fn is_ancestor(&self, a: usize, of: usize) -> bool {
        self.ancestors(of).contains(&a)
    }

    /// The object's ancestor (or itself) just below the lowest ancestor it shares with
    /// `other`: the branch that moves when the two must part.
    fn branch(&self, i: usize, other: usize) -> usize {
        let theirs = self.ancestors(other);
        let mut branch = i;
        for a in self.ancestors(i) {
            if theirs.contains(&a) {
                break;
            }
            branch = a;
        }
        branch
    }

    /// Depth in the tree (roots 0).
    fn depth(&self, i: usize) -> usize {
        self.ancestors(i).len()
    }
}

struct Mover<'a> {
    scene: PhysicsScene,
    offsets: Vec<[f64; 3]>,
    forest: &'a Forest,
}

impl Mover<'_> {
    fn shift(&mut self, i: usize, t: [f64; 3]) {
        if t.iter().all(|v| *v == 0.0) {
            return;
        }
        for j in self.forest.subtree(i) {
            if let Ok(body) = &mut self.scene.objects[j].body {
                body.translate(t);
            }
            for (o, v) in self.offsets[j].iter_mut().zip(t) {
                *o += v;
            }
        }
    }

    fn bounds_of_tree(&self, i: usize) -> Bounds {
        self.forest
            .subtree(i)
            .into_iter()
            .filter_map(|j| self.scene.objects[j].body.as_ref().ok())
            .fold(Bounds::empty(), |b, body| b.union(&body.bounds))
    }

    fn center(&self, i: usize) -> [f64; 3] {
        self.scene.objects[i]
            .body
            .as_ref()
            .map(|b| b.bounds.center())
            .unwrap_or([0.0; 3])
    }
}

/// Settles a scene: `parents[i]` is what holds object i (its `in` or `above` object), if
/// anything.
pub fn settle(
    scene: &PhysicsScene,
    parents: &[Option<usize>],
    tolerances: &Tolerances,
    config: &SettleConfig,
) -> Settled {
    let forest = Forest::new(parents);
    let clearance = config.clearance_mm / 1000.0;
    let mut mover = Mover {
        scene: scene.clone(),
        offsets: vec![[0.0; 3]; scene.objects.len()],
        forest: &forest,
    };
    // Parents before children; among equals, the lower first.
    let mut order: Vec<usize> = mover.scene.checked();
    let mut rounds = 0;
    let mut findings = check_scene(&mover.scene, tolerances);
    // Rounds each pair has been colliding in a row.
    let mut stuck: std::collections::BTreeMap<(usize, usize), u32> = Default::default();
    while !findings.clean() && rounds < config.max_rounds {
        rounds += 1;
        let colliding: std::collections::BTreeSet<(usize, usize)> =
            findings.collisions.iter().map(|c| (c.a, c.b)).collect();
        stuck.retain(|pair, _| colliding.contains(pair));
        for pair in &colliding {
            *stuck.entry(*pair).or_default() += 1;
        }
        // Pushes that keep undoing each other (a jam of neighbours): the smaller tree of a pair
        // stuck for a few rounds moves to the nearest free spot instead.
        let jammed: Vec<(usize, usize)> = stuck
            .iter()
            .filter(|(_, n)| **n >= JAM_ROUNDS)
            .map(|(pair, _)| *pair)
            .collect();
        for (a, b) in jammed {
            let (ra, rb) = (forest.branch(a, b), forest.branch(b, a));
            if forest.parents[ra].is_none() && forest.parents[rb].is_none() {
                let group = if footprint(&mover, ra) <= footprint(&mover, rb) {
                    ra
                } else {
                    rb
                };
                if relocate(&mut mover, group, tolerances, config, clearance) {
                    stuck.remove(&(a, b));
                }
            }
        }
        push_apart(&mut mover, &findings, tolerances, clearance);
        let before = mover.offsets.clone();
        fit_zones(&mut mover, tolerances, clearance);
        // At rest, and the zones cannot be helped (an object larger than the zone): done.
        if findings.physical() && mover.offsets == before {
            break;
        }
        order.sort_by(|a, b| {
            let za = mover.scene.objects[*a]
                .body
                .as_ref()
                .map_or(0.0, |b| b.bounds.min[2]);
            let zb = mover.scene.objects[*b]
                .body
                .as_ref()
                .map_or(0.0, |b| b.bounds.min[2]);
            forest
                .depth(*a)
                .cmp(&forest.depth(*b))
                .then(za.total_cmp(&zb))
                .then(a.cmp(b))
        });
        drop_all(&mut mover, &order);
        findings = check_scene(&mover.scene, tolerances);
    }
    Settled {
        scene: mover.scene,
        offsets_m: mover.offsets,
        rounds,
        findings,
    }
}

/// Rounds a pair may collide in a row before it counts as jammed.
const JAM_ROUNDS: u32 = 4;

/// Moves a tree standing on the table to the nearest spot (rings of growing radius, 16
/// directions each) where it collides with nothing and stays in the zone; false when there
/// is none within `max_displacement_cm`.
fn relocate(
    mover: &mut Mover<'_>,
    group: usize,
    tolerances: &Tolerances,
    config: &SettleConfig,
    clearance: f64,
) -> bool {
    let members = mover.forest.subtree(group);
    let zone = mover.scene.zone_m;
    let free = |mover: &Mover<'_>| {
        members.iter().all(|&i| {
            let Ok(body) = &mover.scene.objects[i].body else {
                return true;
            };
            let others_clear = mover.scene.objects.iter().enumerate().all(|(j, o)| {
                members.contains(&j)
                    || o.body.as_ref().map_or(true, |other| {
                        pair_contact(body, other, 0.0)
                            .is_none_or(|c| c.depth_m <= tolerances.penetration_m / 2.0)
                    })
            });
            let inside = body.bounds.min[0] >= zone[0] - tolerances.zone_m
                && body.bounds.max[0] <= zone[1] + tolerances.zone_m
                && body.bounds.min[1] >= zone[2] - tolerances.zone_m
                && body.bounds.max[1] <= zone[3] + tolerances.zone_m;
            others_clear && inside
        })
    };
    let step = (0.005f64).max(clearance);
    let max = config.max_displacement_cm / 100.0;
    let mut r = step;
    while r <= max {
        for k in 0..16 {
            let angle = std::f64::consts::TAU * f64::from(k) / 16.0;
            let t = [r * angle.cos(), r * angle.sin(), 0.0];
            mover.shift(group, t);
            if free(mover) {
                return true;
            }
            mover.shift(group, t.map(|v| -v));
        }
        r += step;
    }
    false
}

/// The deepest overlap of two objects' parts now, metres.
fn depth_between(mover: &Mover<'_>, a: usize, b: usize) -> f64 {
    match (&mover.scene.objects[a].body, &mover.scene.objects[b].body) {
        (Ok(x), Ok(y)) => pair_contact(x, y, 0.0).map_or(0.0, |c| c.depth_m),
        _ => 0.0,
    }
}

/// The unit direction from `a`'s centre to `b`'s in the table plane ((1, 0) when they share
/// a centre).
fn apart_xy(mover: &Mover<'_>, a: usize, b: usize) -> [f64; 2] {
    let (ca, cb) = (mover.center(a), mover.center(b));
    let d = [cb[0] - ca[0], cb[1] - ca[1]];
    let len = d[0].hypot(d[1]);
    if len < 1e-9 {
        [1.0, 0.0]
    } else {
        [d[0] / len, d[1] / len]
    }
}

/// Moves `group_a` by `-t·share_a` and `group_b` by `t·(1 - share_a)` when that makes the
/// overlap of `a` and `b` shallower; else tries the opposite way (EPA's direction can come out
/// either way for a thin part passing through another); else leaves them and says so.
#[allow(clippy::too_many_arguments)]
fn part_if_better(
    mover: &mut Mover<'_>,
    group_a: Option<usize>,
    group_b: Option<usize>,
    share_a: f64,
    t: [f64; 3],
    a: usize,
    b: usize,
) -> bool {
    let before = depth_between(mover, a, b);
    let apply = |mover: &mut Mover<'_>, sign: f64| {
        if let Some(g) = group_a {
            mover.shift(g, t.map(|v| -v * share_a * sign));
        }
        if let Some(g) = group_b {
            mover.shift(g, t.map(|v| v * (1.0 - share_a) * sign));
        }
    };
    apply(mover, 1.0);
    if depth_between(mover, a, b) < before - 1e-6 {
        return true;
    }
    apply(mover, -2.0);
    if depth_between(mover, a, b) < before - 1e-6 {
        return true;
    }
    apply(mover, 1.0);
    false
}

/// Whether the centre of `upper`'s tree lies over the footprint of `lower`'s tree (its bounds
/// in the table plane). Lifted onto a lower object that it does not lie over, an object rests
/// on it at one side and on the table at the other: tilted, held by friction alone (a book
/// lifted onto the end of a remote control lay 6.5° tilted, and MuJoCo's soft contacts let the
/// books stacked on it creep 2.5 cm down that slope). Such a pair is slid apart instead.
fn over(mover: &Mover<'_>, upper: usize, lower: usize) -> bool {
    let (u, l) = (mover.bounds_of_tree(upper), mover.bounds_of_tree(lower));
    let c = u.center();
    (l.min[0]..=l.max[0]).contains(&c[0]) && (l.min[1]..=l.max[1]).contains(&c[1])
}

/// The footprint area of an object's bounds, square metres.
fn footprint(mover: &Mover<'_>, i: usize) -> f64 {
    mover.scene.objects[i].body.as_ref().map_or(0.0, |b| {
        (b.bounds.max[0] - b.bounds.min[0]) * (b.bounds.max[1] - b.bounds.min[1])
    })
}

fn push_apart(mover: &mut Mover<'_>, findings: &Findings, tolerances: &Tolerances, clearance: f64) {
    let mut collisions = findings.collisions.clone();
    collisions.sort_by(|x, y| {
        y.depth_m
            .total_cmp(&x.depth_m)
            .then((x.a, x.b).cmp(&(y.a, y.b)))
    });
    for c in collisions {
        // Earlier pushes may have moved either: measure again.
        let (Ok(a), Ok(b)) = (
            &mover.scene.objects[c.a].body,
            &mover.scene.objects[c.b].body,
        ) else {
            continue;
        };
        let Some(contact) = pair_contact(a, b, 0.0) else {
            continue;
        };
        if contact.depth_m <= tolerances.penetration_m / 2.0 {
            continue;
        }
        let amount = contact.depth_m + clearance;
        let n = contact.normal;
        let forest = mover.forest;
        if forest.is_ancestor(c.a, c.b) {
            if !part_if_better(mover, None, Some(c.b), 0.0, n.map(|v| v * amount), c.a, c.b) {
                // Out the way it came in: up.
                mover.shift(c.b, [0.0, 0.0, amount]);
            }
            continue;
        }
        if forest.is_ancestor(c.b, c.a) {
            if !part_if_better(mover, Some(c.a), None, 1.0, n.map(|v| v * amount), c.a, c.b) {
                mover.shift(c.a, [0.0, 0.0, amount]);
            }
            continue;
        }
        let (ra, rb) = (forest.branch(c.a, c.b), forest.branch(c.b, c.a));
        let on_table = forest.parents[ra].is_none() && forest.parents[rb].is_none();
        let (upper, lower) = if mover.center(c.b)[2] >= mover.center(c.a)[2] {
            (rb, ra)
        } else {
            (ra, rb)
        };
        if on_table && n[2].abs() > 0.7 && over(mover, upper, lower) {
            // One over the other, its centre over the lower's footprint: lift the upper onto
            // the lower, where it lies as flat as it lay.
            mover.shift(upper, [0.0, 0.0, amount / n[2].abs()]);
            continue;
        }
        // Apart in the plane along the contact normal (or, when it is nearly vertical, the
        // line between the centres): sliding that way separates them by about
        // depth / (n · dir). The smaller moves the more, so that a large object is not pushed
        // into all its neighbours.
        let mut dir = [n[0], n[1]];
        let mut len = dir[0].hypot(dir[1]);
        if len < 0.3 {
            dir = apart_xy(mover, c.a, c.b);
            len = 1.0;
        }
        let dir = [dir[0] / len, dir[1] / len];
        let along = (n[0] * dir[0] + n[1] * dir[1]).abs().max(0.3);
        let (fa, fb) = (footprint(mover, ra), footprint(mover, rb));
        let share_a = if fa + fb > 0.0 { fb / (fa + fb) } else { 0.5 };
        let push = amount / along;
        let parted = part_if_better(
            mover,
            Some(ra),
            Some(rb),
            share_a,
            [dir[0] * push, dir[1] * push, 0.0],
            c.a,
            c.b,
        );
        if !parted {
            // Neither way along the normal helps (another pair of parts goes deeper): apart
            // along the line between the centres, which always ends it.
            let d = apart_xy(mover, c.a, c.b);
            mover.shift(
                ra,
                [-d[0] * amount * share_a, -d[1] * amount * share_a, 0.0],
            );
            let share_b = 1.0 - share_a;
            mover.shift(rb, [d[0] * amount * share_b, d[1] * amount * share_b, 0.0]);
        }
    }
}

fn fit_zones(mover: &mut Mover<'_>, tolerances: &Tolerances, clearance: f64) {
    let zone = mover.scene.zone_m;
    let restricted = mover.scene.restricted_zone_m;
    let roots: Vec<usize> = mover
        .scene
        .checked()
        .into_iter()
        .filter(|i| mover.forest.parents[*i].is_none())
        .collect();
    for r in roots {
        let b = mover.bounds_of_tree(r);
        let mut t = [0.0; 3];
        for axis in 0..2 {
            let (lo, hi) = (zone[2 * axis], zone[2 * axis + 1]);
            let (below, above) = (lo - b.min[axis], b.max[axis] - hi);
            if below > tolerances.zone_m && above < -below {
                t[axis] = below + clearance;
            } else if above > tolerances.zone_m && below < -above {
                t[axis] = -(above + clearance);
            }
        }
        mover.shift(r, t);
        if let Some(rz) = restricted {
            let b = mover.bounds_of_tree(r);
            let reaches = mover
                .forest
                .subtree(r)
                .into_iter()
                .filter_map(|j| mover.scene.objects[j].body.as_ref().ok())
                .any(|body| {
                    super::violations_of(body, &zone, Some(&rz), tolerances)
                        .iter()
                        .any(|(kind, _)| *kind == ViolationKind::InRestrictedZone)
                });
            if reaches {
                // The shortest way out of the rectangle, by the tree's bounds.
                let options = [
                    ([-(b.max[0] - rz[0] + clearance), 0.0]),
                    ([rz[1] - b.min[0] + clearance, 0.0]),
                    ([0.0, -(b.max[1] - rz[2] + clearance)]),
                    ([0.0, rz[3] - b.min[1] + clearance]),
                ];
                let best = options
                    .into_iter()
                    .min_by(|x, y| (x[0].abs() + x[1].abs()).total_cmp(&(y[0].abs() + y[1].abs())))
                    .unwrap_or([0.0, 0.0]);
                mover.shift(r, [best[0], best[1], 0.0]);
            }
        }
    }
}

fn drop_all(mover: &mut Mover<'_>, order: &[usize]) {
    for &i in order {
        let Ok(body) = &mover.scene.objects[i].body else {
            continue;
        };
        let lowest = body.judged_bounds().min[2];
        if lowest < 0.0 {
            let up = -lowest;
            mover.shift(i, [0.0, 0.0, up]);
            continue;
        }
        let held = mover.forest.subtree(i);
        let others = mover
            .scene
            .objects
            .iter()
            .enumerate()
            .filter(|(j, _)| !held.contains(j))
            .filter_map(|(j, o)| o.body.as_ref().ok().map(|b| (j, b)));
        // Falls to touching (a hair of overlap is allowed: the contact tolerance covers it).
        let (gap, _) = fall_of(body, others, 1e-5);
        if gap > 0.0 {
            mover.shift(i, [0.0, 0.0, -gap]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_loop_of_parents_is_broken() {
        let forest = Forest::new(&[Some(1), Some(0), Some(1), None]);
        assert_eq!(forest.parents, vec![Some(1), None, Some(1), None]);
        assert_eq!(forest.subtree(1), vec![1, 0, 2]);
        assert_eq!(forest.branch(0, 2), 0);
        assert!(forest.is_ancestor(1, 2));
    }

    /// Settling's simulation keeps a margin of friction under the export's: what it leaves at
    /// rest must hold where contacts grip less (the slope test in `simulate.rs` shows a rest
    /// that needs more than the settling friction is not kept).
    #[test]
    fn settling_simulates_at_half_the_exported_friction() {
        let settle = SettleConfig::default().friction;
        let export = crate::export::ExportConfig::default().friction_sliding;
        assert!(
            settle > 0.0 && settle <= 0.5 * export,
            "{settle} vs {export}"
        );
    }
}
