//! One scene's check, end to end: a dataset layout and its assets' shapes in, `check.json` and
//! (when settling) the settled layout out.

use std::collections::BTreeMap;
use std::sync::Arc;

use mesa_schemas::artifacts::{
    CheckArtifact, Displacement, SettleReport, SettleStatus, UncheckedObject, CHECK_SCHEMA,
};
use mesa_schemas::units::PositionCm;
use mesa_schemas::{DatasetLayout, LayoutObject, Provenance};

use super::settle::settle;
use super::{check_scene, pair_contact, round_to, AssetShape, CheckConfig, Findings, PhysicsScene};
use crate::graph::{extract_graph, GraphOptions, GraphScene, Relation};

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
    let graph = extract_graph(&GraphScene::from_dataset(layout), containers, options)
        .map_err(|e| e.to_string())?;
    Ok(graph
        .edges
        .iter()
        .filter(|e| matches!(e.relation, Relation::In | Relation::Above))
        .map(|e| (e.subject.clone(), e.relation.label(), e.object.clone()))
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
    let scene = PhysicsScene::from_layout(layout, shape_of);
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
    // Parts that reach past the mesh by more than the tolerance at this scale: the depths and
    // contacts of these objects are uncertain by that much.
    let bulging: Vec<String> = scene
        .objects
        .iter()
        .filter(|o| o.reach_m > tolerances.penetration_m)
        .map(|o| format!("{} ({:.1} mm)", o.instance, o.reach_m * 1000.0))
        .collect();
    if !bulging.is_empty() {
        warnings.push(format!(
            "{}: the collision parts of {} reach outside their meshes by more than \
             penetration_tolerance_mm at the layout's scale: their depths and contacts are \
             uncertain by that much (`mesa assets --force` with a smaller \
             [assets] decomposition_tolerance_m makes finer parts)",
            source.file,
            bulging.join(", ")
        ));
    }
    let before = findings.to_schema(&scene);
    let settle_report = settle_scene.then(|| {
        settle_layout(
            layout,
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

fn settle_layout(
    layout: &DatasetLayout,
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
    let offsets = settled
        .as_ref()
        .map(|s| s.offsets_m.clone())
        .unwrap_or_else(|| vec![[0.0; 3]; layout.objects.len()]);
    let displacements: Vec<Displacement> = layout
        .objects
        .iter()
        .zip(&offsets)
        .map(|(o, t)| {
            let offset_cm = t.map(|v| round_to(v * 100.0, 4));
            Displacement {
                instance: o.instance.clone(),
                offset_cm,
                distance_cm: round_to((t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt() * 100.0, 4),
            }
        })
        .collect();
    let mut distances: Vec<f64> = displacements.iter().map(|d| d.distance_cm).collect();
    let max_displacement_cm = distances.iter().copied().fold(0.0, f64::max);
    let median_displacement_cm = median(&mut distances);
    let mut moved = layout.clone();
    for (object, d) in moved.objects.iter_mut().zip(&displacements) {
        if d.distance_cm > 0.0 {
            let p = object.position_cm.0;
            object.position_cm =
                PositionCm(std::array::from_fn(|k| round_to(p[k] + d.offset_cm[k], 4)));
            let mut provenance = object.provenance.clone().unwrap_or(Provenance {
                stage: String::new(),
                source_instance: None,
                notes: Vec::new(),
            });
            provenance.stage = "check".to_owned();
            provenance.notes.push(format!(
                "settled: moved by ({:.2}, {:.2}, {:.2}) cm",
                d.offset_cm[0], d.offset_cm[1], d.offset_cm[2]
            ));
            object.provenance = Some(provenance);
        }
    }
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
    let relations_lost: Vec<String> = match (&edges, &settled) {
        (Some(edges), Some(s)) => edges
            .iter()
            .filter(|(subject, _, object)| {
                let (Some(&i), Some(&j)) =
                    (index.get(subject.as_str()), index.get(object.as_str()))
                else {
                    return false;
                };
                let Ok(a) = &s.scene.objects[i].body else {
                    return false;
                };
                let touches = |k: usize| match &s.scene.objects[k].body {
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
    let (after, rounds, reason) = match &settled {
        None => (
            findings.to_schema(scene),
            0,
            Some(format!(
                "{unchecked} objects have no collision shape: a scene cannot be settled around \
                 objects it cannot see"
            )),
        ),
        Some(s) => {
            let after = s.findings.to_schema(&s.scene);
            let reason = if !s.findings.physical() {
                Some(format!(
                    "still not at rest after {} rounds: {}",
                    s.rounds,
                    remaining(&s.findings, &s.scene)
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
    };
    let status = if reason.is_none() {
        SettleStatus::Settled
    } else {
        SettleStatus::Unsettled
    };
    let report = SettleReport {
        status,
        method: "least_motion".to_owned(),
        layout: (status == SettleStatus::Settled).then(|| SETTLED_LAYOUT.to_owned()),
        reason,
        iterations: rounds,
        displacements,
        max_displacement_cm,
        median_displacement_cm,
        relations_lost,
        after,
    };
    let settled = (status == SettleStatus::Settled).then_some(moved);
    (report, settled)
}
