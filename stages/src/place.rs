//! `place`: each retrieved asset scaled isometrically into its lifted box (SPEC 5.3), written
//! as the coarse `layout.json` in the dataset form.
//!
//! For an asset of size d = (w, d, h) in its table-aligned frame (the asset index) and a target
//! box d' = (w', d', h'): k = the index of the **smallest** asset dimension, s = d'_k / d_k,
//! placed size = s·d (the aspect ratio is the asset's: single-view boxes are unreliable, the
//! smallest dimension the least). The placed size's k-th dimension is d'_k exactly.
//!
//! Position: the box centre in x and y; in z the object's bottom rests on its support:
//! - the **table** when its lifted bottom is within `table_snap_cm` of the table, or when
//!   nothing lies under it (then it is dropped, and a warning says by how much);
//! - **in** a container (an asset annotated `isContainer` / `receptacle`) whose lifted box
//!   holds its lifted bottom: the bottom keeps its relative height in the container's box
//!   (a fruit on a bowl's floor stays on the floor when the bowl is rescaled);
//! - **on** the objects under it otherwise: the bottom is the highest top among the placed
//!   objects under it (objects are placed from the lowest bottom up, so those are final).
//!
//! "Under" means: the other object's lifted bottom is lower, and the footprints overlap both as
//! lifted (the photo's evidence that one stands on the other) and as placed (so that the
//! placed object does rest on it).
//! Rotation: identity, or the lift's yaw when it estimated one (the box is then taken as
//! oriented by that yaw).

use mesa_schemas::artifacts::{AssetIndexArtifact, LiftArtifact, RetrievalArtifact};
use mesa_schemas::layout::{DatasetLayout, LayoutObject, Provenance, LAYOUT_SCHEMA};
use mesa_schemas::rotation::quat_xyzw_from_yaw_deg;
use mesa_schemas::units::{PositionCm, QuatXyzw, ScaleFactor, SizeCm};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::annotations::Annotations;

/// The `[place]` section of `mesa.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct PlaceConfig {
    /// An object whose lifted bottom is within this many cm of the table stands on the table.
    pub table_snap_cm: f64,
}

impl Default for PlaceConfig {
    fn default() -> Self {
        Self { table_snap_cm: 1.0 }
    }
}

/// One object to place, in metres in the table frame.
#[derive(Debug, Clone, PartialEq)]
pub struct PlacementInput {
    /// The instance name.
    pub instance: String,
    /// Centre of the lifted box.
    pub target_center_m: [f64; 3],
    /// Size of the lifted box [w, d, h] (in the object's frame when `yaw_deg` is set).
    pub target_size_m: [f64; 3],
    /// Size of the asset [w, d, h] in its table-aligned frame.
    pub asset_size_m: [f64; 3],
    /// The lift's yaw estimate, degrees.
    pub yaw_deg: Option<f64>,
    /// Whether other objects can be inside it.
    pub container: bool,
}

/// What an object rests on.
#[derive(Debug, Clone, PartialEq)]
pub enum Support {
    /// The table, where it was lifted.
    Table,
    /// The table, dropped from this lifted height (m): nothing was under it.
    Dropped(f64),
    /// On top of the objects under it; the index is the one whose top it rests on.
    On(usize),
    /// Inside this container.
    In(usize),
}

/// Where an object is placed.
#[derive(Debug, Clone, PartialEq)]
pub struct Placement {
    /// Box centre, metres, table frame.
    pub center_m: [f64; 3],
    /// Placed size [w, d, h] in the object frame, metres.
    pub size_m: [f64; 3],
    /// The isometric scale s.
    pub scale: f64,
    /// What it rests on.
    pub support: Support,
}

/// The isometric scale of an asset into a box: (s, placed size, k). The placed size's k-th
/// dimension is the target's exactly.
pub fn isometric(asset_m: [f64; 3], target_m: [f64; 3]) -> (f64, [f64; 3], usize) {
    let mut k = 0;
    for i in 1..3 {
        if asset_m[i] < asset_m[k] {
            k = i;
        }
    }
    let s = target_m[k] / asset_m[k];
    let mut size = asset_m.map(|d| s * d);
    size[k] = target_m[k];
    (s, size, k)
}

/// The half extents along x and y of a footprint `w × d` turned by `yaw_deg`.
fn half_footprint(size: [f64; 3], yaw_deg: Option<f64>) -> [f64; 2] {
    let (w, d) = (size[0] / 2.0, size[1] / 2.0);
    match yaw_deg {
        None => [w, d],
        Some(yaw) => {
            let (s, c) = yaw.to_radians().sin_cos();
            [c.abs() * w + s.abs() * d, s.abs() * w + c.abs() * d]
        }
    }
}

/// Whether two placed footprints overlap (with a positive area).
pub fn footprints_overlap(
    a_center: [f64; 3],
    a_half: [f64; 2],
    b_center: [f64; 3],
    b_half: [f64; 2],
) -> bool {
    const EPS: f64 = 1e-9;
    (a_center[0] - b_center[0]).abs() < a_half[0] + b_half[0] - EPS
        && (a_center[1] - b_center[1]).abs() < a_half[1] + b_half[1] - EPS
}

/// Places objects; the result is in the order of `items`.
pub fn place_objects(items: &[PlacementInput], config: &PlaceConfig) -> Vec<Placement> {
    let snap = config.table_snap_cm / 100.0;
    let lifted_bottom =
        |i: usize| (items[i].target_center_m[2] - items[i].target_size_m[2] / 2.0).max(0.0);
    let lifted_top = |i: usize| items[i].target_center_m[2] + items[i].target_size_m[2] / 2.0;
    let mut order: Vec<usize> = (0..items.len()).collect();
    order.sort_by(|a, b| {
        lifted_bottom(*a)
            .total_cmp(&lifted_bottom(*b))
            .then_with(|| items[*a].instance.cmp(&items[*b].instance))
    });
    let lifted_halves: Vec<[f64; 2]> = items
        .iter()
        .map(|item| half_footprint(item.target_size_m, item.yaw_deg))
        .collect();
    let mut placed: Vec<Option<Placement>> = vec![None; items.len()];
    let mut halves = vec![[0.0; 2]; items.len()];
    for &i in &order {
        let item = &items[i];
        let (scale, size, _) = isometric(item.asset_size_m, item.target_size_m);
        halves[i] = half_footprint(size, item.yaw_deg);
        let bottom_lifted = lifted_bottom(i);
        let center = item.target_center_m;
        let under: Vec<usize> = order
            .iter()
            .copied()
            .take_while(|j| *j != i)
            .filter(|j| lifted_bottom(*j) < bottom_lifted)
            .filter(|j| {
                let other = items[*j].target_center_m;
                footprints_overlap(center, lifted_halves[i], other, lifted_halves[*j])
                    && footprints_overlap(center, halves[i], other, halves[*j])
            })
            .collect();
        let (bottom, support) = if bottom_lifted <= snap {
            (0.0, Support::Table)
        } else if under.is_empty() {
            (0.0, Support::Dropped(bottom_lifted))
        } else {
            // The innermost container whose lifted box holds this object's bottom.
            let holder = under
                .iter()
                .copied()
                .filter(|j| items[*j].container && lifted_top(*j) > bottom_lifted)
                .max_by(|a, b| lifted_bottom(*a).total_cmp(&lifted_bottom(*b)));
            match holder {
                Some(j) => {
                    let p = placed[j].as_ref().map_or((0.0, 0.0), |p| {
                        (p.center_m[2] - p.size_m[2] / 2.0, p.size_m[2])
                    });
                    let (j_bottom, j_height) = p;
                    let lifted_height = lifted_top(j) - lifted_bottom(j);
                    let ratio = if lifted_height > 0.0 {
                        ((bottom_lifted - lifted_bottom(j)) / lifted_height).clamp(0.0, 1.0)
                    } else {
                        0.0
                    };
                    (j_bottom + ratio * j_height, Support::In(j))
                }
                None => {
                    let top = |j: usize| {
                        placed[j]
                            .as_ref()
                            .map_or(0.0, |p| p.center_m[2] + p.size_m[2] / 2.0)
                    };
                    let j = under
                        .iter()
                        .copied()
                        .max_by(|a, b| top(*a).total_cmp(&top(*b)))
                        .unwrap_or(under[0]);
                    (top(j), Support::On(j))
                }
            }
        };
        placed[i] = Some(Placement {
            center_m: [center[0], center[1], bottom + size[2] / 2.0],
            size_m: size,
            scale,
            support,
        });
    }
    placed.into_iter().flatten().collect()
}

/// Why a scene cannot be placed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlaceError {
    /// The retrieval and the lift or the index disagree.
    #[error("{instance}: {problem}")]
    Inconsistent {
        /// The instance.
        instance: String,
        /// What disagrees, and the fix.
        problem: String,
    },
}

/// What placing a scene gives.
#[derive(Debug, Clone, PartialEq)]
pub struct PlaceOutput {
    /// `coarse/layout.json`.
    pub layout: DatasetLayout,
    /// Warnings (instances left out, objects dropped to the table).
    pub warnings: Vec<String>,
}

/// Places the retrieved assets of a scene.
pub fn place_scene(
    lift: &LiftArtifact,
    retrieval: &RetrievalArtifact,
    index: &AssetIndexArtifact,
    annotations: &Annotations,
    config: &PlaceConfig,
) -> Result<PlaceOutput, PlaceError> {
    let mut warnings = Vec::new();
    let mut items = Vec::new();
    let mut chosen = Vec::new();
    for lifted in &lift.instances {
        let Some(retrieved) = retrieval
            .instances
            .iter()
            .find(|r| r.instance == lifted.instance)
        else {
            return Err(PlaceError::Inconsistent {
                instance: lifted.instance.clone(),
                problem: "lifted but not in retrieval.json (rerun `mesa retrieve`)".to_owned(),
            });
        };
        let Some(uid) = &retrieved.chosen else {
            warnings.push(format!(
                "{}: left out: retrieval found no asset for it",
                lifted.instance
            ));
            continue;
        };
        let geometry = index
            .assets
            .get(uid)
            .filter(|r| r.valid)
            .and_then(|r| r.geometry.as_ref())
            .ok_or_else(|| PlaceError::Inconsistent {
                instance: lifted.instance.clone(),
                problem: format!(
                    "its asset {uid} is not a valid asset of the index (the index changed \
                     since retrieval: rerun `mesa retrieve`)"
                ),
            })?;
        let annotation = annotations.get(uid);
        items.push(PlacementInput {
            instance: lifted.instance.clone(),
            target_center_m: lifted.center_cm.0.map(|v| v / 100.0),
            target_size_m: lifted.size_cm.0.map(|v| v / 100.0),
            asset_size_m: geometry.size_m,
            yaw_deg: lifted.yaw_deg,
            container: annotation.and_then(|a| a.is_container).unwrap_or(false),
        });
        chosen.push((
            lifted,
            uid.clone(),
            annotation.and_then(|a| a.category.clone()),
        ));
    }
    let placements = place_objects(&items, config);
    let mut objects = Vec::with_capacity(items.len());
    for ((item, placement), (lifted, uid, category)) in items.iter().zip(&placements).zip(chosen) {
        let note = match placement.support {
            Support::Table => "on the table".to_owned(),
            Support::Dropped(height_m) => {
                warnings.push(format!(
                    "{}: nothing under it: dropped {:.1} cm onto the table",
                    item.instance,
                    height_m * 100.0
                ));
                format!(
                    "dropped {:.1} cm onto the table: nothing under it",
                    height_m * 100.0
                )
            }
            Support::On(j) => format!("on {}", items[j].instance),
            Support::In(j) => format!("in {}", items[j].instance),
        };
        let yaw = item.yaw_deg.unwrap_or(0.0);
        objects.push(LayoutObject {
            instance: item.instance.clone(),
            retrieved_uid: uid,
            position_cm: PositionCm(placement.center_m.map(|v| v * 100.0)),
            rotation: QuatXyzw(quat_xyzw_from_yaw_deg(yaw)),
            size_cm: SizeCm(placement.size_m.map(|v| v * 100.0)),
            scale_factor: ScaleFactor([placement.scale; 3]),
            category: Some(category.unwrap_or_else(|| lifted.label.clone())),
            description: Some(lifted.description.clone()).filter(|d| !d.is_empty()),
            z_rotation_deg: Some(yaw),
            provenance: Some(Provenance {
                stage: "place".to_owned(),
                source_instance: Some(lifted.mask_id),
                notes: vec![note],
            }),
            extra: Default::default(),
        });
    }
    let mut layout = DatasetLayout {
        schema: LAYOUT_SCHEMA.to_owned(),
        zone_cm: lift.zone_cm,
        restricted_zone_cm: None,
        objects,
        extra: Default::default(),
    };
    layout.sort_objects();
    Ok(PlaceOutput { layout, warnings })
}

#[cfg(test)]
mod tests;
