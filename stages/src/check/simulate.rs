//! Settling's last step: a rigid-body simulation that lets a scene come to rest, and verifies
//! that it stays there.
//!
//! The least-motion moves ([`super::settle`]) leave a scene without overlaps or gaps, which is
//! not the same as stable: a pen balanced on a mug's rim, a toothbrush standing upright in a
//! cup, fruit piled in a bowl all pass those moves and then fall in a simulator. So the moved
//! scene is simulated with gravity for `simulated_s` seconds (rapier3d, the Rust physics engine
//! of the parry3d line the check already uses): every object is a dynamic body made of its
//! asset's convex parts at the layout's scale (the same parts `mesa export` writes as
//! colliders), the table is the same static boxes `mesa export` writes (the top over the zone
//! with a margin, a vanity's sink a hole with a basin floor). An object that moves further than
//! `rest_motion_mm` in the simulation takes its simulated pose (position and rotation); the
//! others keep their pose. Over the last `rest_window_s` seconds nothing may move further than
//! `rest_motion_mm`: an object that still does is not at rest, and one that ends under the
//! table top has fallen (off the table, or into the sink).
//!
//! Determinism: rapier runs on one thread with a fixed step and its `enhanced-determinism`
//! feature (IEEE-exact maths through libm), bodies and colliders are inserted in layout order,
//! so the same scene gives the same bits on every machine and at every thread count of the run.

use mesa_schemas::DatasetLayout;
use rapier3d::parry::shape::ConvexPolyhedron;
use rapier3d::prelude::*;

/// How far the table reaches beyond the item placement zone on each side, metres (also the
/// default of `[export] table_margin_m`).
pub const TABLE_MARGIN_M: f64 = 0.05;
/// Thickness of the table, metres (also the default of `[export] table_thickness_m`).
pub const TABLE_THICKNESS_M: f64 = 0.05;
/// Depth of a vanity's sink basin under the table top, metres (also the default of
/// `[export] sink_depth_m`).
pub const SINK_DEPTH_M: f64 = 0.15;
/// Thickness given to a convex part that is a flat polygon (a simulator needs a volume),
/// metres (also the default of `[export] flat_part_thickness_m`).
pub const FLAT_PART_THICKNESS_M: f64 = 0.0005;

/// Faces smaller than this get no support pieces ([`support_pieces`]), m².
const SUPPORT_MIN_AREA_M2: Real = 2.5e-5;
/// How far ahead contacts are predicted for a fast body (rapier's soft CCD), metres.
const SOFT_CCD_M: Real = 0.005;

/// Angular damping of every body, 1/s.
const ANGULAR_DAMPING: Real = 2.0;
/// Linear damping of every body, 1/s.
const LINEAR_DAMPING: Real = 0.5;

/// An object whose top ends further than this under the table top has fallen, metres.
const FELL_BELOW_M: f64 = 0.005;

/// A static box of the table, in the table frame: centre and half sizes, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TableBox {
    /// Name of the box.
    pub name: &'static str,
    /// Centre, metres.
    pub center_m: [f64; 3],
    /// Half sizes, metres.
    pub half_size_m: [f64; 3],
}

/// The table of a layout as static boxes: the top over the item placement zone grown by
/// `margin_m` (split around the sink's hole when the layout has a restricted zone) and the
/// sink's floor `sink_depth_m` under the top.
pub fn table_boxes(
    layout: &DatasetLayout,
    margin_m: f64,
    thickness_m: f64,
    sink_depth_m: f64,
) -> Vec<TableBox> {
    let m = margin_m;
    let z = layout.zone_cm.0.map(|v| v / 100.0);
    let (x0, x1, y0, y1) = (z[0] - m, z[1] + m, z[2] - m, z[3] + m);
    let t = thickness_m;
    let slab = |name, a: f64, b: f64, c: f64, d: f64, top: f64, thick: f64| TableBox {
        name,
        center_m: [0.5 * (a + b), 0.5 * (c + d), top - 0.5 * thick],
        half_size_m: [0.5 * (b - a), 0.5 * (d - c), 0.5 * thick],
    };
    let Some(sink) = layout.restricted_zone_cm.as_ref() else {
        return vec![slab("table_top", x0, x1, y0, y1, 0.0, t)];
    };
    // The hole, clipped to the table.
    let r = sink.0.map(|v| v / 100.0);
    let (rx0, rx1) = (r[0].clamp(x0, x1), r[1].clamp(x0, x1));
    let (ry0, ry1) = (r[2].clamp(y0, y1), r[3].clamp(y0, y1));
    let mut out = Vec::new();
    let mut push = |b: TableBox| {
        if b.half_size_m.iter().all(|h| *h > 1e-6) {
            out.push(b);
        }
    };
    push(slab("table_top_left", x0, rx0, y0, y1, 0.0, t));
    push(slab("table_top_right", rx1, x1, y0, y1, 0.0, t));
    push(slab("table_top_front", rx0, rx1, y0, ry0, 0.0, t));
    push(slab("table_top_back", rx0, rx1, ry1, y1, 0.0, t));
    push(slab("sink_floor", rx0, rx1, ry0, ry1, -sink_depth_m, t));
    out
}

/// The simulation's settings (part of `[check.settling]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimulationConfig {
    /// Simulated time, seconds.
    pub simulated_s: f64,
    /// Simulated time at most while something still moves, seconds.
    pub max_simulated_s: f64,
    /// Fixed steps per simulated second.
    pub steps_per_second: u32,
    /// The last part of the simulation over which nothing may move, seconds.
    pub rest_window_s: f64,
    /// Motion below this is no motion, metres.
    pub rest_motion_m: f64,
    /// Density of every object's parts, kg/m³.
    pub density_kg_m3: f64,
    /// Friction coefficient of every contact.
    pub friction: f64,
}

/// An object to simulate: its convex parts placed by the layout's rotation and scale, relative
/// to its position (so the body starts unrotated at `position_m`).
#[derive(Debug, Clone)]
pub struct SimObject {
    /// The position, table frame, metres.
    pub position_m: [f64; 3],
    /// Each part's points, relative to `position_m`, table axes, metres.
    pub parts: Vec<Vec<[f64; 3]>>,
}

/// What the simulation did to one object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimMotion {
    /// Where the object's position ended, metres.
    pub position_m: [f64; 3],
    /// The rotation the simulation applied, quaternion `[x, y, z, w]` (to compose before the
    /// layout's own rotation).
    pub turn_xyzw: [f64; 4],
    /// The angle of that rotation, degrees.
    pub turn_deg: f64,
    /// How far the object moved over the whole simulation: the largest displacement of a
    /// corner of its box, metres.
    pub moved_m: f64,
    /// The same over the rest window.
    pub window_motion_m: f64,
    /// Whether it ended under the table top, its top more than 5 mm below it (off the table,
    /// or into the sink).
    pub fell: bool,
}

/// The outcome of a simulation.
#[derive(Debug, Clone, PartialEq)]
pub struct Simulation {
    /// Per object, in the order given; `None` for an object that had no usable part.
    pub motions: Vec<Option<SimMotion>>,
    /// Steps run.
    pub steps: u32,
}

/// Points of a flat polygon given a thickness along its normal, so that a convex hull of them
/// has a volume; `None` for points on a line.
fn thickened(points: &[Point<Real>], thickness: Real) -> Option<Vec<Point<Real>>> {
    let p0 = *points.first()?;
    let p1 = *points.iter().max_by(|a, b| {
        (**a - p0)
            .norm_squared()
            .total_cmp(&(**b - p0).norm_squared())
    })?;
    let axis = p1 - p0;
    let p2 = *points.iter().max_by(|a, b| {
        axis.cross(&(**a - p0))
            .norm_squared()
            .total_cmp(&axis.cross(&(**b - p0)).norm_squared())
    })?;
    let normal = axis.cross(&(p2 - p0));
    if normal.norm() <= Real::EPSILON * axis.norm_squared().max(Real::MIN_POSITIVE) {
        return None;
    }
    let offset = normal.normalize() * (0.5 * thickness);
    Some(
        points
            .iter()
            .flat_map(|p| [*p + offset, *p - offset])
            .collect(),
    )
}

/// Area of a planar convex polygon given in order.
fn polygon_area(points: &[Point<Real>]) -> Real {
    let mut sum = Vector::zeros();
    for i in 1..points.len().saturating_sub(1) {
        sum += (points[i] - points[0]).cross(&(points[i + 1] - points[0]));
    }
    sum.norm() / 2.0
}

/// Support pieces for the faces of a convex part that parry would stand on a sliver of.
///
/// parry 0.21's contact manifolds take at most four vertices of a polyhedron's face, and they
/// take the first four of its list (`PolygonalFeatureMap for ConvexPolyhedron`: "TODO: if there
/// are more than 4 vertices, we need to select four vertices that maximize the area"). A part
/// whose face has more (the flat bottom of a bottle, a glass, a candle: 30 to 90 vertices) then
/// touches the table only along a few neighbouring vertices at one side of that face, and the
/// object tilts and rocks where it should stand: alone on a flat table, a 90-sided prism turned
/// 15° and still moved after 6 s; a lotion bottle 14°. So for every face of more than four
/// vertices that is larger than [`SUPPORT_MIN_AREA_M2`] and not already mostly covered by its
/// first four vertices, two pyramids are added from the part's centre to four vertices spread
/// evenly around the face (offset by an eighth of a turn from each other): their bases are
/// four-vertex faces in the plane of the big one, so contacts span the whole face. They lie
/// inside the part (a convex part holds the cone from an inner point to its boundary), so they
/// change neither the shape nor, being massless, the mass. With them the prism and the bottle
/// turn less than 0.1°.
fn support_pieces(poly: &ConvexPolyhedron) -> Vec<Vec<Point<Real>>> {
    let points = poly.points();
    let count = points.len() as Real;
    let centre = points
        .iter()
        .fold(Point::origin(), |c, p| c + p.coords / count);
    let ring = poly.vertices_adj_to_face();
    let mut pieces = Vec::new();
    for face in poly.faces() {
        let n = face.num_vertices_or_edges as usize;
        if n <= 4 {
            continue;
        }
        let first = face.first_vertex_or_edge as usize;
        let polygon: Vec<Point<Real>> = ring[first..first + n]
            .iter()
            .map(|&v| points[v as usize])
            .collect();
        let area = polygon_area(&polygon);
        if area < SUPPORT_MIN_AREA_M2 || polygon_area(&polygon[..4]) >= 0.5 * area {
            continue;
        }
        for offset in [0.0, n as f64 / 8.0] {
            let mut piece = vec![centre];
            for k in 0..4 {
                let i = (offset + k as f64 * n as f64 / 4.0).round() as usize % n;
                piece.push(polygon[i]);
            }
            pieces.push(piece);
        }
    }
    pieces
}

/// The largest displacement of a corner of the box `[lo, hi]` (relative to the body origin)
/// between two poses of the body.
fn corner_motion(lo: [f64; 3], hi: [f64; 3], from: &Isometry<Real>, to: &Isometry<Real>) -> f64 {
    let mut worst: f64 = 0.0;
    for k in 0..8 {
        let c = point![
            if k & 1 == 0 { lo[0] } else { hi[0] } as Real,
            if k & 2 == 0 { lo[1] } else { hi[1] } as Real,
            if k & 4 == 0 { lo[2] } else { hi[2] } as Real
        ];
        let d = (from * c - to * c).norm() as f64;
        worst = worst.max(d);
    }
    worst
}

/// The state of a simulation.
struct World {
    parameters: IntegrationParameters,
    pipeline: PhysicsPipeline,
    islands: IslandManager,
    broad_phase: DefaultBroadPhase,
    narrow_phase: NarrowPhase,
    bodies: RigidBodySet,
    colliders: ColliderSet,
    impulse_joints: ImpulseJointSet,
    multibody_joints: MultibodyJointSet,
    ccd: CCDSolver,
}

impl World {
    fn step(&mut self) {
        self.pipeline.step(
            &vector![0.0, 0.0, -9.81],
            &self.parameters,
            &mut self.islands,
            &mut self.broad_phase,
            &mut self.narrow_phase,
            &mut self.bodies,
            &mut self.colliders,
            &mut self.impulse_joints,
            &mut self.multibody_joints,
            &mut self.ccd,
            None,
            &(),
            &(),
        );
    }

    /// The pose of each object's body.
    fn poses(&self, handles: &[Option<SimBody>]) -> Vec<Option<Isometry<Real>>> {
        handles
            .iter()
            .map(|h| h.map(|(body, _, _)| *self.bodies[body].position()))
            .collect()
    }

    /// Steps `config.simulated_s` seconds, then one rest window more at a time while something
    /// still moves (fruit rolling to the bottom of a bowl), up to `config.max_simulated_s`;
    /// returns the poses at the start of the last rest window and the steps run.
    fn run_to_rest(
        &mut self,
        handles: &[Option<SimBody>],
        config: &SimulationConfig,
    ) -> (Vec<Option<Isometry<Real>>>, u32) {
        let hz = f64::from(config.steps_per_second);
        let window = ((config.rest_window_s * hz).round() as u32).max(1);
        let first = ((config.simulated_s * hz).round() as u32).max(window);
        let most = ((config.max_simulated_s * hz).round() as u32).max(first);
        let mut run = 0;
        loop {
            let target = if run == 0 { first } else { run + window };
            let mut window_start = Vec::new();
            while run < target {
                if run == target - window {
                    window_start = self.poses(handles);
                }
                self.step();
                run += 1;
            }
            let end = self.poses(handles);
            let moving = handles.iter().enumerate().any(|(i, h)| {
                let (Some((_, lo, hi)), Some(from), Some(to)) = (h, &window_start[i], &end[i])
                else {
                    return false;
                };
                // What falls off the table keeps falling: it is not waited for.
                to.translation.z > -1.0 && corner_motion(*lo, *hi, from, to) > config.rest_motion_m
            });
            if !moving || run + window > most {
                return (window_start, run);
            }
        }
    }
}

/// A simulated object: its body, and the box of its points relative to the body's origin.
type SimBody = (RigidBodyHandle, [f64; 3], [f64; 3]);

/// Simulates the objects on the table under gravity for `config.simulated_s` seconds, and
/// longer while something still moves (up to `config.max_simulated_s`).
pub fn simulate(
    objects: &[SimObject],
    table: &[TableBox],
    config: &SimulationConfig,
) -> Simulation {
    simulate_with(objects, table, config, true)
}

/// [`simulate`], with or without the support pieces of [`support_pieces`] (the tests' control).
fn simulate_with(
    objects: &[SimObject],
    table: &[TableBox],
    config: &SimulationConfig,
    supported: bool,
) -> Simulation {
    let mut bodies = RigidBodySet::new();
    let mut colliders = ColliderSet::new();
    let ground = bodies.insert(RigidBodyBuilder::fixed().build());
    for b in table {
        let c = b.center_m;
        let h = b.half_size_m;
        colliders.insert_with_parent(
            ColliderBuilder::cuboid(h[0] as Real, h[1] as Real, h[2] as Real)
                .translation(vector![c[0] as Real, c[1] as Real, c[2] as Real])
                .friction(config.friction as Real)
                .build(),
            ground,
            &mut bodies,
        );
    }
    // Each object: its body handle and the box of its points (relative to its origin).
    let mut handles: Vec<Option<SimBody>> = Vec::new();
    for object in objects {
        let mut shapes = Vec::new();
        let mut supports = Vec::new();
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for part in &object.parts {
            let points: Vec<Point<Real>> = part
                .iter()
                .map(|p| point![p[0] as Real, p[1] as Real, p[2] as Real])
                .collect();
            let shape =
                SharedShape::convex_hull(&points).filter(|s| s.mass_properties(1.0).mass() > 1e-12);
            let shape = match shape {
                Some(s) => Some(s),
                None => thickened(&points, FLAT_PART_THICKNESS_M as Real)
                    .and_then(|p| SharedShape::convex_hull(&p)),
            };
            let Some(shape) = shape else {
                continue;
            };
            for p in part {
                for k in 0..3 {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k]);
                }
            }
            if supported {
                if let Some(poly) = shape.as_convex_polyhedron() {
                    supports.extend(
                        support_pieces(poly)
                            .iter()
                            .filter_map(|piece| SharedShape::convex_hull(piece)),
                    );
                }
            }
            shapes.push(shape);
        }
        if shapes.is_empty() {
            handles.push(None);
            continue;
        }
        let t = object.position_m;
        let body = bodies.insert(
            RigidBodyBuilder::dynamic()
                .translation(vector![t[0] as Real, t[1] as Real, t[2] as Real])
                // A thin part (a sheet, a pen) falling fast must not pass through what is under
                // it in one step: contacts are predicted this far ahead. Full CCD would be
                // exact but made the simulation of a scene 7 times slower on compound bodies,
                // and settling drops nothing from high.
                .soft_ccd_prediction(SOFT_CCD_M)
                // Without rolling resistance a ball rocks in a bowl for ever; damping makes
                // it come to rest sooner, and does not change where things can rest.
                .angular_damping(ANGULAR_DAMPING)
                .linear_damping(LINEAR_DAMPING)
                .build(),
        );
        // One compound collider per body: its parts never meet each other in the broad phase,
        // and only the parts near another body are tested against it. The mass is the parts'
        // alone (the support pieces lie inside them).
        let density = config.density_kg_m3 as Real;
        let mass: MassProperties = shapes.iter().map(|s| s.mass_properties(density)).sum();
        let parts: Vec<(Isometry<Real>, SharedShape)> = shapes
            .into_iter()
            .chain(supports)
            .map(|s| (Isometry::identity(), s))
            .collect();
        colliders.insert_with_parent(
            ColliderBuilder::compound(parts)
                .mass_properties(mass)
                .friction(config.friction as Real)
                .build(),
            body,
            &mut bodies,
        );
        handles.push(Some((body, lo, hi)));
    }

    let mut world = World {
        parameters: IntegrationParameters {
            dt: 1.0 / config.steps_per_second.max(1) as Real,
            // Small objects (a pen is 1 cm thick): rapier's default 1 mm of tolerated overlap
            // would be a tenth of one; 0.2 mm keeps resting contacts well under the check's
            // tolerance.
            normalized_allowed_linear_error: 0.0002,
            ..IntegrationParameters::default()
        },
        pipeline: PhysicsPipeline::new(),
        islands: IslandManager::new(),
        broad_phase: DefaultBroadPhase::new(),
        narrow_phase: NarrowPhase::new(),
        bodies,
        colliders,
        impulse_joints: ImpulseJointSet::new(),
        multibody_joints: MultibodyJointSet::new(),
        ccd: CCDSolver::new(),
    };
    let start = world.poses(&handles);
    let (window_start, steps) = world.run_to_rest(&handles, config);
    let bodies = &world.bodies;
    let motions = handles
        .iter()
        .zip(start.iter().zip(&window_start))
        .map(|(h, (from, mid))| {
            let ((body, lo, hi), from, mid) = (h.as_ref()?, from.as_ref()?, mid.as_ref()?);
            let end = bodies[*body].position();
            let q = end.rotation.quaternion().coords;
            let t = end.translation.vector;
            // The top of the body's box in the end pose (its highest corner).
            let top = (0..8)
                .map(|k| {
                    let c = point![
                        if k & 1 == 0 { lo[0] } else { hi[0] } as Real,
                        if k & 2 == 0 { lo[1] } else { hi[1] } as Real,
                        if k & 4 == 0 { lo[2] } else { hi[2] } as Real
                    ];
                    (end * c).z as f64
                })
                .fold(f64::NEG_INFINITY, f64::max);
            Some(SimMotion {
                position_m: [t.x as f64, t.y as f64, t.z as f64],
                turn_xyzw: [q[0] as f64, q[1] as f64, q[2] as f64, q[3] as f64],
                turn_deg: (end.rotation.angle() as f64).to_degrees(),
                moved_m: corner_motion(*lo, *hi, from, end),
                window_motion_m: corner_motion(*lo, *hi, mid, end),
                fell: top < -FELL_BELOW_M,
            })
        })
        .collect();
    Simulation { motions, steps }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config() -> SimulationConfig {
        SimulationConfig {
            simulated_s: 1.5,
            max_simulated_s: 4.0,
            steps_per_second: 240,
            rest_window_s: 0.5,
            rest_motion_m: 0.001,
            density_kg_m3: 500.0,
            friction: 0.8,
        }
    }

    fn cube(half: [f64; 3]) -> Vec<[f64; 3]> {
        let mut out = Vec::new();
        for k in 0..8 {
            out.push([
                if k & 1 == 0 { -half[0] } else { half[0] },
                if k & 2 == 0 { -half[1] } else { half[1] },
                if k & 4 == 0 { -half[2] } else { half[2] },
            ]);
        }
        out
    }

    fn table() -> Vec<TableBox> {
        vec![TableBox {
            name: "table_top",
            center_m: [0.5, 0.5, -0.025],
            half_size_m: [0.5, 0.5, 0.025],
        }]
    }

    #[test]
    fn a_box_on_the_table_stays_and_one_in_the_air_falls_onto_it() {
        let resting = SimObject {
            position_m: [0.3, 0.3, 0.05],
            parts: vec![cube([0.05, 0.05, 0.05])],
        };
        let high = SimObject {
            position_m: [0.7, 0.7, 0.25],
            parts: vec![cube([0.05, 0.05, 0.05])],
        };
        let sim = simulate(&[resting, high], &table(), &config());
        let a = sim.motions[0].expect("body");
        let b = sim.motions[1].expect("body");
        assert!(a.moved_m < 0.001, "{a:?}");
        assert!(b.moved_m > 0.19, "{b:?}");
        assert!((b.position_m[2] - 0.05).abs() < 0.002, "{b:?}");
        assert!(b.window_motion_m < 0.001, "{b:?}");
        assert!(!a.fell && !b.fell);
    }

    /// An upright 90-sided prism (a bottle's flat bottom): parry's manifolds stand it on four
    /// neighbouring vertices of its base, so without support pieces it tilts; with them it
    /// stays upright.
    #[test]
    fn a_prism_of_many_sides_stands_still_on_its_base() {
        let n = 90;
        let prism: Vec<[f64; 3]> = (0..n)
            .flat_map(|i| {
                let a = std::f64::consts::TAU * i as f64 / n as f64;
                [0.0, 0.16].map(|z| [0.03 * a.cos(), 0.02 * a.sin(), z])
            })
            .collect();
        let object = SimObject {
            position_m: [0.5, 0.5, 0.0],
            parts: vec![prism],
        };
        let objects = [object];
        let supported = simulate(&objects, &table(), &config());
        let a = supported.motions[0].expect("body");
        assert!(a.turn_deg < 0.1 && a.moved_m < 0.001, "{a:?}");
        assert!(a.window_motion_m < 0.0001, "{a:?}");
        // Control: the same prism on parry's four vertices alone.
        let bare = simulate_with(&objects, &table(), &config(), false);
        let b = bare.motions[0].expect("body");
        assert!(b.turn_deg > 1.0, "{b:?}");
    }

    /// A small box on a 30° slope (tan 30° = 0.58): friction 0.8 holds it, 0.4 lets it slide
    /// down; settling at the lower one leaves no rest that needs more grip than it has.
    #[test]
    fn a_box_on_a_30_degree_slope_holds_at_friction_0_8_and_slides_at_0_4() {
        let slope = 30f64.to_radians();
        let (half, h) = (0.1, 0.2 * slope.tan());
        let wedge: Vec<[f64; 3]> = [-half, half]
            .into_iter()
            .flat_map(|y| [[-half, y, 0.0], [half, y, 0.0], [half, y, h]])
            .collect();
        // The box's bottom face on the slope, halfway up: its axes turned -30° about y.
        let (s, c) = ((-slope).sin(), (-slope).cos());
        let b = 0.02;
        let normal = [-slope.sin(), 0.0, slope.cos()];
        let on_slope = cube([b, b, b])
            .into_iter()
            .map(|p| [p[0] * c + p[2] * s, p[1], -p[0] * s + p[2] * c])
            .collect();
        let objects = [
            SimObject {
                position_m: [0.5, 0.5, 0.0],
                parts: vec![wedge],
            },
            SimObject {
                position_m: [0.5 + b * normal[0], 0.5, 0.5 * h + b * normal[2] + 0.0002],
                parts: vec![on_slope],
            },
        ];
        let grip = |friction| {
            let sim = simulate(
                &objects,
                &table(),
                &SimulationConfig {
                    friction,
                    ..config()
                },
            );
            (sim.motions[0].expect("wedge"), sim.motions[1].expect("box"))
        };
        let (wedge_held, held) = grip(0.8);
        assert!(
            held.moved_m < 0.002 && wedge_held.moved_m < 0.001,
            "{held:?}"
        );
        let (_, slid) = grip(0.4);
        assert!(slid.moved_m > 0.03, "{slid:?}");
    }

    #[test]
    fn a_stick_balanced_on_its_end_topples_and_one_off_the_table_falls() {
        // A 30 cm stick, 1 cm thick, standing on its end, tilted 3° by its points.
        let tilt = 3f64.to_radians();
        let stick: Vec<[f64; 3]> = cube([0.005, 0.005, 0.15])
            .into_iter()
            .map(|p| [p[0] + p[2] * tilt.sin(), p[1], p[2] * tilt.cos()])
            .collect();
        let standing = SimObject {
            position_m: [0.5, 0.5, 0.15],
            parts: vec![stick],
        };
        let off = SimObject {
            position_m: [1.3, 0.5, 0.05],
            parts: vec![cube([0.05, 0.05, 0.05])],
        };
        let sim = simulate(&[standing, off], &table(), &config());
        let s = sim.motions[0].expect("body");
        assert!(s.turn_deg > 45.0, "{s:?}");
        assert!(!s.fell, "{s:?}");
        let o = sim.motions[1].expect("body");
        assert!(o.fell, "{o:?}");
    }

    #[test]
    fn a_flat_part_gets_a_thickness_and_a_segment_is_no_body() {
        let flat = SimObject {
            position_m: [0.5, 0.5, 0.01],
            parts: vec![vec![
                [-0.05, -0.05, 0.0],
                [0.05, -0.05, 0.0],
                [0.05, 0.05, 0.0],
                [-0.05, 0.05, 0.0],
            ]],
        };
        let segment = SimObject {
            position_m: [0.2, 0.2, 0.01],
            parts: vec![vec![[0.0, 0.0, 0.0], [0.1, 0.0, 0.0]]],
        };
        let sim = simulate(&[flat, segment], &table(), &config());
        let f = sim.motions[0].expect("a flat part is a thin body");
        // Resting on the table: its centre half the given thickness up. Dropped 1 cm, it lands
        // within 1 mm of that (0.6 mm deep with the soft CCD's prediction; the check tolerates 2).
        assert!((f.position_m[2] - 0.00025).abs() < 0.001, "{f:?}");
        assert!(f.window_motion_m < 0.0001, "{f:?}");
        assert!(!f.fell, "{f:?}");
        assert!(sim.motions[1].is_none());
    }

    #[test]
    fn the_same_scene_gives_the_same_bits() {
        let objects: Vec<SimObject> = (0..6)
            .map(|i| SimObject {
                position_m: [0.3 + 0.02 * i as f64, 0.5, 0.06 + 0.11 * i as f64],
                parts: vec![cube([0.05, 0.04, 0.05])],
            })
            .collect();
        let a = simulate(&objects, &table(), &config());
        let b = simulate(&objects, &table(), &config());
        assert_eq!(a, b);
    }
}
