//! One scene's check, end to end: a dataset layout and its assets' shapes in, `check.json` and
//! (when settling) the settled layout out.

use std::collections::BTreeMap;
use std::sync::Arc;

use mesa_schemas::artifacts::{
    CheckArtifact, Displacement, SettleReport, SettleStatus, SimulationReport, UncheckedObject,
    CHECK_SCHEMA,
};
use mesa_schemas::units::PositionCm;
use mesa_schemas::{DatasetLayout, LayoutObject, Provenance};

use super::settle::settle;
use super::simulate::{simulate, table_boxes, SimObject, Simulation};
use super::simulate::{SINK_DEPTH_M, TABLE_MARGIN_M, TABLE_THICKNESS_M};
use super::{
    check_scene, pair_contact, round_to, AssetShape, CheckConfig, Findings, PhysicsScene, Pose,
};
use crate::graph::{extract_graph, GraphOptions, GraphScene, Relation};
use crate::mesh::{quat_mul, quat_normalize};

/// The settled layout's file, relative to the scene folder.
pub use crate::paths::scene::SETTLED_LAYOUT;

/// What a scene's check gives.
#[derive(Debug, Clone)]
pub struct SceneCheck {
    /// `qa/check.json`.
    pub artifact: CheckArtifact,
    /// The settled layout (`qa/layout.json`), when settling succeeded.
    pub settled: Option<DatasetLayout>,
    /// Things worth a warning in the run summary.
    pub warnings: Vec<String>,
}

/// The scene's layout as the check reads it.
#[derive(Debug, Clone, Copy)]
pub struct LayoutSource<'a> {
    /// The scene id.
    pub scene_id: &'a str,
    /// The layout file, relative to the scene folder.
    pub file: &'a str,
    /// SHA-256 of its bytes.
    pub sha256: &'a str,
    /// The layout.
    pub layout: &'a DatasetLayout,
}

/// The `in` and `above` edges of a layout's scene graph, as (subject, relation, object).
fn holding_edges(
    layout: &DatasetLayout,
    containers: &[bool],
    options: &GraphOptions,
) -> Result<Vec<(String, &'static str, String)>, String> {
    let scene = GraphScene::from_dataset(layout);
    let graph = extract_graph(&scene, containers, options).map_err(|e| e.to_string())?;
    Ok(graph
        .edges
        .iter()
        .filter(|e| matches!(e.relation, Relation::In | Relation::Above))
        .map(|e| {
            (
                e.subject.to_owned(),
                e.relation.label(),
                e.object.to_owned(),
            )
        })
        .collect())
}

/// Checks one scene's layout; with `settle`, also settles it.
///
/// `shape_of` gives an object's collision shape (or why it has none); `containers` is the
/// container flag of each object in layout order (as `mesa graph` decides it), for the scene
/// graph whose `in` and `above` relations settling keeps.
pub fn check_layout(
    source: LayoutSource<'_>,
    shape_of: impl Fn(&LayoutObject) -> Result<Arc<AssetShape>, String>,
    containers: &[bool],
    graph_options: &GraphOptions,
    config: &CheckConfig,
    settle_scene: bool,
) -> SceneCheck {
    let layout = source.layout;
    let tolerances = config.tolerances();
    let scene = PhysicsScene::from_layout(layout, &shape_of);
    let findings = check_scene(&scene, &tolerances);
    let unchecked: Vec<UncheckedObject> = scene
        .objects
        .iter()
        .filter_map(|o| {
            o.body.as_ref().err().map(|reason| UncheckedObject {
                instance: o.instance.clone(),
                reason: reason.clone(),
            })
        })
        .collect();
    let mut warnings = Vec::new();
    if !unchecked.is_empty() {
        let names: Vec<&str> = unchecked.iter().map(|u| u.instance.as_str()).collect();
        warnings.push(format!(
            "{}: not checked (no collision shape): {}",
            source.file,
            names.join(", ")
        ));
    }
    // Loose objects (parts reaching past their mesh at this scale) are judged on their meshes;
    // one whose mesh cannot be read is judged on its parts, uncertain by their reach.
    let unjudged: Vec<String> = scene
        .objects
        .iter()
        .filter_map(|o| {
            let body = o.body.as_ref().ok().filter(|b| b.loose())?;
            let why = match body.solid() {
                Some(Ok(_)) => return None,
                Some(Err(e)) => e.to_owned(),
                None => "no mesh given".to_owned(),
            };
            Some(format!(
                "{} ({:.1} mm: {why})",
                o.instance,
                o.reach_m * 1000.0
            ))
        })
        .collect();
    if !unjudged.is_empty() {
        warnings.push(format!(
            "{}: the collision parts of {} reach outside their meshes at the layout's scale and \
             their meshes could not be read: their depths and contacts are uncertain by that \
             much (rerun `mesa assets`)",
            source.file,
            unjudged.join(", ")
        ));
    }
    let before = findings.to_schema(&scene);
    let settle_report = settle_scene.then(|| {
        settle_layout(
            layout,
            &shape_of,
            &scene,
            &findings,
            containers,
            graph_options,
            config,
            &mut warnings,
        )
    });
    let (settle_report, settled) = match settle_report {
        Some((report, settled)) => (Some(report), settled),
        None => (None, None),
    };
    let artifact = CheckArtifact {
        schema: CHECK_SCHEMA.to_owned(),
        scene_id: source.scene_id.to_owned(),
        layout: source.file.to_owned(),
        layout_sha256: source.sha256.to_owned(),
        penetration_tolerance_mm: config.penetration_tolerance_mm,
        floating_tolerance_mm: config.floating_tolerance_mm,
        zone_tolerance_mm: config.zone_tolerance_mm,
        mesatask_rule_distance_cm: config.mesatask_rule_distance_cm,
        objects: layout.objects.len() as u64,
        unchecked,
        collisions: before.collisions,
        floating: before.floating,
        zone_violations: before.zone_violations,
        pairs_total: before.pairs_total,
        collision_rate: before.collision_rate,
        mesatask_rule_pairs: before.mesatask_rule_pairs,
        clean: before.clean,
        settle: settle_report,
    };
    SceneCheck {
        artifact,
        settled,
        warnings,
    }
}

/// A short account of what a check still finds.
fn remaining(findings: &Findings, scene: &PhysicsScene) -> String {
    let schema = findings.to_schema(scene);
    let mut parts = Vec::new();
    if let Some(c) = schema.collisions.first() {
        parts.push(format!(
            "{} colliding pairs (first {} × {}, {:.1} mm)",
            schema.collisions.len(),
            c.a,
            c.b,
            c.depth_mm
        ));
    }
    if let Some(f) = schema.floating.first() {
        parts.push(format!(
            "{} floating (first {}, {:.1} mm over {})",
            schema.floating.len(),
            f.instance,
            f.gap_mm,
            f.over
        ));
    }
    if let Some(v) = schema.zone_violations.first() {
        parts.push(format!(
            "{} zone violations (first {} {}, {:.1} cm)",
            schema.zone_violations.len(),
            v.instance,
            v.kind,
            v.amount_cm
        ));
    }
    parts.join(", ")
}

fn median(values: &mut [f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n % 2 == 1 {
        values[n / 2]
    } else {
        0.5 * (values[n / 2 - 1] + values[n / 2])
    }
}

/// The objects of a layout as the simulation takes them: each one's parts turned and scaled
/// by the layout, relative to its position.
fn sim_objects(
    layout: &DatasetLayout,
    shape_of: &dyn Fn(&LayoutObject) -> Result<Arc<AssetShape>, String>,
) -> Vec<SimObject> {
    layout
        .objects
        .iter()
        .map(|object| {
            let pose = Pose::of_object(object);
            let parts = shape_of(object)
                .map(|shape| {
                    let at_origin = Pose {
                        position_m: [0.0; 3],
                        ..pose
                    };
                    shape.place(&at_origin).iter().map(|h| h.points()).collect()
                })
                .unwrap_or_default();
            SimObject {
                position_m: pose.position_m,
                parts,
            }
        })
        .collect()
}

/// Records in an object's provenance that settling moved it.
fn note_settled(object: &mut LayoutObject, note: String) {
    let provenance = object.provenance.get_or_insert_with(|| Provenance {
        stage: String::new(),
        source_instance: None,
        notes: Vec::new(),
    });
    provenance.stage = "check".to_owned();
    provenance.notes.push(note);
}

/// Moves every object by its offset (metres), rounded as layouts are, with a provenance note
/// (`what`: "settled: moved by …").
fn apply_moves(layout: &mut DatasetLayout, offsets_m: &[[f64; 3]], what: &str) {
    for (object, t) in layout.objects.iter_mut().zip(offsets_m) {
        if t.iter().all(|v| *v == 0.0) {
            continue;
        }
        let offset_cm = t.map(|v| round_to(v * 100.0, 4));
        let p = object.position_cm.0;
        object.position_cm = PositionCm(std::array::from_fn(|k| round_to(p[k] + offset_cm[k], 4)));
        note_settled(
            object,
            format!(
                "{what}: moved by ({:.2}, {:.2}, {:.2}) cm",
                offset_cm[0], offset_cm[1], offset_cm[2]
            ),
        );
    }
}

/// After a simulation in which everything came to rest and nothing fell: when the layout it
/// leaves is not at rest by the check (a tilted glass whose mesh dips a few millimetres under
/// the table top while its parts stand on it; two objects the solver left slightly
/// interpenetrating), the least-motion moves are made once more, on the simulated poses (no
/// second simulation), and kept only when they bring the scene to rest. What the check then
/// finds is the verdict, as without this pass.
pub(super) fn tidy_after_simulation(
    moved: &mut DatasetLayout,
    simulation: &Simulation,
    parents: &[Option<usize>],
    config: &CheckConfig,
    shape_of: &dyn Fn(&LayoutObject) -> Result<Arc<AssetShape>, String>,
) {
    let rest_m = config.settling.rest_motion_mm / 1000.0;
    let calm = simulation
        .motions
        .iter()
        .flatten()
        .all(|m| !m.fell && m.window_motion_m <= rest_m);
    if !calm {
        return;
    }
    let tolerances = config.tolerances();
    let placed = PhysicsScene::from_layout(moved, shape_of);
    if check_scene(&placed, &tolerances).physical() {
        return;
    }
    let tidy = settle(&placed, parents, &tolerances, &config.settling);
    if tidy.findings.physical() {
        apply_moves(moved, &tidy.offsets_m, "settled after the simulation");
    }
}

/// Applies a simulation to the objects it moved further than `rest_motion_m`: their position
/// and rotation become the simulation's (rounded as layouts are), with a provenance note.
fn apply_simulation(layout: &mut DatasetLayout, simulation: &Simulation, rest_motion_m: f64) {
    for (object, motion) in layout.objects.iter_mut().zip(&simulation.motions) {
        let Some(m) = motion.filter(|m| m.moved_m > rest_motion_m) else {
            continue;
        };
        object.position_cm = PositionCm(m.position_m.map(|v| round_to(v * 100.0, 4)));
        let q = quat_normalize(quat_mul(m.turn_xyzw, quat_normalize(object.rotation.0)));
        // One sign for the same rotation, then rounded.
        let q = if q[3] < 0.0 { q.map(|c| -c) } else { q };
        object.rotation.0 = quat_normalize(q.map(|c| round_to(c, 9))).map(|c| round_to(c, 12));
        if object.z_rotation_deg.is_some() {
            object.z_rotation_deg = Some(round_to(
                mesa_schemas::rotation::yaw_deg_from_quat_xyzw(object.rotation.0),
                4,
            ));
        }
        note_settled(
            object,
            format!(
                "settled: the simulation moved it {:.2} cm and turned it {:.1}°",
                m.moved_m * 100.0,
                m.turn_deg
            ),
        );
    }
}

#[allow(clippy::too_many_arguments)]
fn settle_layout(
    layout: &DatasetLayout,
    shape_of: &dyn Fn(&LayoutObject) -> Result<Arc<AssetShape>, String>,
    scene: &PhysicsScene,
    findings: &Findings,
    containers: &[bool],
    graph_options: &GraphOptions,
    config: &CheckConfig,
    warnings: &mut Vec<String>,
) -> (SettleReport, Option<DatasetLayout>) {
    let tolerances = config.tolerances();
    let index: BTreeMap<&str, usize> = layout
        .objects
        .iter()
        .enumerate()
        .map(|(i, o)| (o.instance.as_str(), i))
        .collect();
    let edges = match holding_edges(layout, containers, graph_options) {
        Ok(edges) => Some(edges),
        Err(e) => {
            warnings.push(format!("no scene graph ({e}): settling keeps no relation"));
            None
        }
    };
    let mut parents = vec![None; layout.objects.len()];
    for (subject, _, object) in edges.iter().flatten() {
        if let (Some(&s), Some(&o)) = (index.get(subject.as_str()), index.get(object.as_str())) {
            parents[s] = Some(o);
        }
    }
    let unchecked = findings.unchecked;
    let settled = if unchecked == 0 {
        Some(settle(scene, &parents, &tolerances, &config.settling))
    } else {
        None
    };
    // The least-motion moves, rounded as layouts are.
    let mut moved = layout.clone();
    if let Some(s) = &settled {
        apply_moves(&mut moved, &s.offsets_m, "settled");
    }
    // Then the simulation, on a scene the moves brought to rest.
    let mut too_many_parts: Option<usize> = None;
    let simulation: Option<Simulation> = match &settled {
        Some(s) if config.settling.simulate && s.findings.physical() => {
            let objects = sim_objects(&moved, shape_of);
            let parts: usize = objects.iter().map(|o| o.parts.len()).sum();
            if parts > config.settling.max_simulated_parts {
                // Not simulated, and so not settled (below).
                too_many_parts = Some(parts);
                None
            } else {
                let table = table_boxes(layout, TABLE_MARGIN_M, TABLE_THICKNESS_M, SINK_DEPTH_M);
                let simulation = simulate(&objects, &table, &config.settling.simulation());
                apply_simulation(
                    &mut moved,
                    &simulation,
                    config.settling.rest_motion_mm / 1000.0,
                );
                tidy_after_simulation(&mut moved, &simulation, &parents, config, shape_of);
                Some(simulation)
            }
        }
        _ => None,
    };
    // The scene as settled, placed anew from the layout as written: a simulation turns objects,
    // and rounding positions to a micrometre can break a contact the moves left exactly
    // touching (a toothbrush leaning on another, a knife edge the written layout must hold).
    let (final_scene, final_findings) = match &settled {
        Some(_) => {
            let placed = PhysicsScene::from_layout(&moved, shape_of);
            let found = check_scene(&placed, &tolerances);
            (Some(placed), Some(found))
        }
        None => (None, None),
    };
    let displacements: Vec<Displacement> = layout
        .objects
        .iter()
        .zip(&moved.objects)
        .enumerate()
        .map(|(i, (before, after))| {
            let offset_cm: [f64; 3] = std::array::from_fn(|k| {
                round_to(after.position_cm.0[k] - before.position_cm.0[k], 4)
            });
            let motion = simulation.as_ref().and_then(|s| s.motions[i]);
            let simulated =
                motion.is_some_and(|m| m.moved_m * 1000.0 > config.settling.rest_motion_mm);
            Displacement {
                instance: before.instance.clone(),
                offset_cm,
                distance_cm: round_to(offset_cm.iter().map(|v| v * v).sum::<f64>().sqrt(), 4),
                simulated,
                simulation_cm: motion.map(|m| round_to(m.moved_m * 100.0, 4)),
                turned_deg: motion.map(|m| {
                    if simulated {
                        round_to(m.turn_deg, 3)
                    } else {
                        0.0
                    }
                }),
            }
        })
        .collect();
    let mut distances: Vec<f64> = displacements.iter().map(|d| d.distance_cm).collect();
    let max_displacement_cm = distances.iter().copied().fold(0.0, f64::max);
    let median_displacement_cm = median(&mut distances);
    let simulation_report = simulation.as_ref().map(|s| {
        let name = |i: usize| layout.objects[i].instance.clone();
        let rest_m = config.settling.rest_motion_mm / 1000.0;
        let motions: Vec<(usize, &super::simulate::SimMotion)> = s
            .motions
            .iter()
            .enumerate()
            .filter_map(|(i, m)| m.as_ref().map(|m| (i, m)))
            .collect();
        SimulationReport {
            engine: "rapier3d 0.26".to_owned(),
            simulated_s: round_to(
                f64::from(s.steps) / f64::from(config.settling.steps_per_second),
                4,
            ),
            steps: s.steps,
            rest_window_s: config.settling.rest_window_s,
            rest_motion_mm: config.settling.rest_motion_mm,
            objects_moved: motions.iter().filter(|(_, m)| m.moved_m > rest_m).count() as u64,
            max_motion_cm: round_to(
                motions.iter().map(|(_, m)| m.moved_m).fold(0.0, f64::max) * 100.0,
                4,
            ),
            still_moving: motions
                .iter()
                .filter(|(_, m)| m.window_motion_m > rest_m && !m.fell)
                .map(|(i, _)| name(*i))
                .collect(),
            fell: motions
                .iter()
                .filter(|(_, m)| m.fell)
                .map(|(i, _)| name(*i))
                .collect(),
        }
    });
    // The relations the settled layout would lose: an object held by another (in it, or
    // above it) must still rest on it, or on something it holds (a fruit dropped onto the
    // fruits in a bowl is still in the bowl). The box rules of the scene graph cannot tell an
    // apple resting in a plate's dish from one beside it, so touching is the test.
    let held_by = |holder: usize| -> Vec<usize> {
        let mut out = vec![holder];
        let mut k = 0;
        while k < out.len() {
            let at = out[k];
            let next: Vec<usize> = (0..parents.len())
                .filter(|i| parents[*i] == Some(at) && !out.contains(i))
                .collect();
            out.extend(next);
            k += 1;
        }
        out
    };
    let relations_lost: Vec<String> = match (&edges, &final_scene) {
        (Some(edges), Some(placed)) => edges
            .iter()
            .filter(|(subject, _, object)| {
                let (Some(&i), Some(&j)) =
                    (index.get(subject.as_str()), index.get(object.as_str()))
                else {
                    return false;
                };
                let Ok(a) = &placed.objects[i].body else {
                    return false;
                };
                let touches = |k: usize| match &placed.objects[k].body {
                    Ok(b) if k != i => pair_contact(a, b, tolerances.floating_m)
                        .is_some_and(|c| c.near || c.depth_m > 0.0),
                    _ => false,
                };
                !held_by(j).into_iter().any(touches)
            })
            .map(|(s, r, o)| format!("({s}, {r}, {o})"))
            .collect(),
        _ => Vec::new(),
    };
    let (after, rounds, reason) = match (&settled, &final_scene, &final_findings) {
        (Some(s), Some(placed), Some(found)) => {
            let after = found.to_schema(placed);
            let reason = if !s.findings.physical() {
                Some(format!(
                    "still not at rest after {} rounds: {}",
                    s.rounds,
                    remaining(&s.findings, &s.scene)
                ))
            } else if let Some(parts) = too_many_parts {
                Some(format!(
                    "not simulated: the scene has {parts} convex parts, more than \
                     [check.settling] max_simulated_parts = {}",
                    config.settling.max_simulated_parts
                ))
            } else if let Some(fell) = simulation_report
                .as_ref()
                .filter(|r| !r.fell.is_empty())
                .map(|r| r.fell.join(", "))
            {
                Some(format!(
                    "in the simulation, {fell} fell under the table top (off the table or into \
                     the sink)"
                ))
            } else if let Some(moving) = simulation_report
                .as_ref()
                .filter(|r| !r.still_moving.is_empty())
                .map(|r| r.still_moving.join(", "))
            {
                Some(format!(
                    "not at rest: {moving} still moved more than rest_motion_mm = {} mm in the \
                     last {} s of the simulation",
                    config.settling.rest_motion_mm, config.settling.rest_window_s
                ))
            } else if !found.physical() {
                Some(format!(
                    "{}, the check of the layout as written finds {}",
                    if simulation.is_some() {
                        "after the simulation"
                    } else {
                        "after the moves"
                    },
                    remaining(found, placed)
                ))
            } else if max_displacement_cm > config.settling.max_displacement_cm {
                let worst = displacements
                    .iter()
                    .max_by(|a, b| a.distance_cm.total_cmp(&b.distance_cm))
                    .map(|d| d.instance.as_str())
                    .unwrap_or("");
                Some(format!(
                    "{worst} would move {max_displacement_cm:.1} cm (more than \
                     max_displacement_cm = {} cm)",
                    config.settling.max_displacement_cm
                ))
            } else if !relations_lost.is_empty() {
                Some(format!(
                    "the settled layout would lose {}",
                    relations_lost.join(", ")
                ))
            } else {
                None
            };
            (after, s.rounds, reason)
        }
        _ => (
            findings.to_schema(scene),
            0,
            Some(format!(
                "{unchecked} objects have no collision shape: a scene cannot be settled around \
                 objects it cannot see"
            )),
        ),
    };
    let status = if reason.is_none() {
        SettleStatus::Settled
    } else {
        SettleStatus::Unsettled
    };
    let report = SettleReport {
        status,
        method: if simulation.is_some() {
            "least_motion+simulation"
        } else {
            "least_motion"
        }
        .to_owned(),
        layout: (status == SettleStatus::Settled).then(|| SETTLED_LAYOUT.to_owned()),
        reason,
        iterations: rounds,
        displacements,
        max_displacement_cm,
        median_displacement_cm,
        relations_lost,
        after,
        simulation: simulation_report,
    };
    let settled = (status == SettleStatus::Settled).then_some(moved);
    (report, settled)
}
