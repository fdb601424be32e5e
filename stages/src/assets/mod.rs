//! `assets`: what `mesa assets` learns from one library asset (SPEC 5.2), as pure functions.
//! The runner in `mesa-pipeline` lists the library, runs [`index_asset`] in parallel, skips
//! unchanged assets and writes `assets/index/`.
//!
//! Per asset:
//! 1. read the GLB ([`crate::glb_read`]); a file that cannot be read is invalid, with the
//!    reader's reason;
//! 2. turn its vertices into the asset's **table-aligned frame**: the glTF → table conversion
//!    of SPEC 2 (`x = X, y = -Z, z = Y`, so the asset's front, +Z in glTF, faces the observer at
//!    -y), then the front alignment yaw ([`FrontAlignment`]);
//! 3. its bounding box, size, counts, materials and textures; an asset thinner than
//!    `min_extent_m` along some axis is invalid (`zero_size_axis`: it cannot be scaled into a
//!    box); implausible sizes and an annotation bbox that disagrees with the mesh are warnings;
//! 4. its collision shapes ([`shapes`]).
//!
//! Before step 1 expands any mesh, its cost is judged from the GLB's JSON ([`budget`]): an
//! asset over `[assets.budget]` gets its collision shape from a decimated mesh
//! ([`simplify`], vertex clustering) with the reach that costs measured ([`reach`]) and
//! reported; one over the hard cap is rejected with the reason; the decomposition stops at
//! the time budget. No asset stalls the run.
//!
//! [`build_text_index`] makes the text index of the lexical encoder from the annotations.

pub mod budget;
pub mod decompose;
mod near;
pub mod reach;
pub mod shapes;
pub mod simplify;
pub mod synthetic;

use std::time::{Duration, Instant};

use mesa_schemas::artifacts::{AssetGeometry, ShapesArtifact, TextDocument, TextIndexArtifact};
use mesa_schemas::artifacts::{Simplification, SHAPES_SCHEMA, TEXT_INDEX_SCHEMA};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::annotations::{Annotations, AssetAnnotation};
use crate::glb_read::{open_glb, read_glb};
use crate::text::{document_frequency, features, LEXICAL_ENCODER};
use budget::{glb_cost, AssetBudget, Verdict};

/// Bumped when the indexing of an unchanged asset would give another record: every asset is
/// then re-indexed.
pub const INDEX_VERSION: u32 = 4;

/// How an asset's front is brought to face the observer (-y in the table frame).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum FrontAlignment {
    /// The glTF convention alone: the front faces +Z in the GLB (MesaTask's assets are stored
    /// so, and its Blender scripts apply no other rotation).
    Gltf,
    /// objathor's rule on top: an annotation `frontView` k (one of the 4 views rendered at 0°,
    /// 90°, 180°, 270°) turns the asset by -90·k degrees about the vertical
    /// (`pose_z_rot_angle = -deg2rad(angles[frontView])`).
    FrontView,
}

/// How an asset's collision shape is cut into convex parts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum DecompositionMethod {
    /// Parts within `decomposition_tolerance_m` of the mesh (a piece's hull is cut in two
    /// until it reaches no farther outside the object): what `mesa check` needs, so that an
    /// apple resting in a bowl does not overlap the bowl's parts.
    Adaptive,
    /// parry3d's V-HACD (`vhacd_*` keys): fewer parts, but a part may bridge millimetres of a
    /// cavity.
    Vhacd,
}

/// The `[assets]` section of `mesa.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct AssetsConfig {
    /// How an asset's front is found: "gltf" (front toward +Z in the GLB, MesaTask's
    /// convention) or "front_view" (also turn by objathor's annotation frontView).
    pub front_alignment: FrontAlignment,
    /// An asset thinner than this along some axis, in metres, is invalid (a flat asset
    /// cannot be scaled into a box).
    pub min_extent_m: f64,
    /// Warn when an asset's largest dimension exceeds this, in metres (often a model in
    /// centimetres without its 0.01 scale).
    pub max_plausible_extent_m: f64,
    /// Warn when an annotation bbox differs from the mesh by more than this fraction on
    /// some axis (retrieval scores sizes from the annotation).
    pub bbox_tolerance: f64,
    /// The convex decomposition: "adaptive" (parts within decomposition_tolerance_m of the
    /// mesh) or "vhacd" (parry3d's V-HACD).
    pub decomposition: DecompositionMethod,
    /// Adaptive decomposition: the most a convex part may reach outside the object, metres.
    pub decomposition_tolerance_m: f64,
    /// Adaptive decomposition: the first part budget of an asset. It doubles, up to
    /// decomposition_most_parts, as long as two doublings lower the largest reach outside the
    /// mesh by at least a quarter: a box stays at 1 part, a detailed asset gets what its
    /// detail needs.
    pub decomposition_max_parts: u32,
    /// Adaptive decomposition: the most the part budget may grow to (default 128, the first
    /// budget: no growth, since more parts cost time and the `[assets.budget] seconds` cut-off
    /// makes the output depend on the machine; 1024 suits detailed real assets). An asset
    /// still beyond decomposition_tolerance_m there is kept with its measured reach, the
    /// reason in the index (`decomposition.over_tolerance`) and a warning.
    pub decomposition_most_parts: u32,
    /// V-HACD voxel resolution (voxels along the longest axis) of the convex decomposition.
    pub vhacd_resolution: u32,
    /// V-HACD maximum concavity of a part (lower: more, tighter parts).
    pub vhacd_concavity: f64,
    /// Most convex parts per asset.
    pub vhacd_max_parts: u32,
    /// Collision shape coordinates are rounded to this, in metres (keeps files small; well
    /// below the collision tolerance of `mesa check`).
    pub shape_precision_m: f64,
    /// The lexical encoder's asset text starts with the annotation's category.
    pub text_includes_category: bool,
    /// What indexing one asset may cost (`[assets.budget]`): above it the collision shape is
    /// made from a decimated mesh, far above it the asset is rejected.
    pub budget: AssetBudget,
}

impl Default for AssetsConfig {
    fn default() -> Self {
        Self {
            front_alignment: FrontAlignment::Gltf,
            min_extent_m: 1e-4,
            max_plausible_extent_m: 5.0,
            bbox_tolerance: 0.05,
            decomposition: DecompositionMethod::Adaptive,
            decomposition_tolerance_m: 0.001,
            decomposition_max_parts: 128,
            decomposition_most_parts: 128,
            vhacd_resolution: 64,
            vhacd_concavity: 0.01,
            vhacd_max_parts: 32,
            shape_precision_m: 1e-4,
            text_includes_category: true,
            budget: AssetBudget::default(),
        }
    }
}

/// What indexing one asset gives.
#[derive(Debug, Clone, PartialEq)]
pub struct IndexedAsset {
    /// The geometry, when the GLB was read.
    pub geometry: Option<AssetGeometry>,
    /// Why the asset is invalid: (code, reason with the fix).
    pub invalid: Option<(String, String)>,
    /// Collision shapes (valid assets).
    pub shapes: Option<ShapesArtifact>,
    /// Things that do not make the asset invalid.
    pub warnings: Vec<String>,
}

/// The front alignment yaw of an asset, degrees, and a warning when the annotation cannot be
/// used.
pub fn front_yaw_deg(
    annotation: Option<&AssetAnnotation>,
    alignment: FrontAlignment,
) -> (f64, Option<String>) {
    match (alignment, annotation.and_then(|a| a.front_view)) {
        (FrontAlignment::Gltf, _) | (FrontAlignment::FrontView, None) => (0.0, None),
        (FrontAlignment::FrontView, Some(view)) if view < 4 => (-90.0 * f64::from(view), None),
        (FrontAlignment::FrontView, Some(view)) => (
            0.0,
            Some(format!(
                "frontView {view} is not one of objathor's 4 views (0-3): no front alignment \
                 applied"
            )),
        ),
    }
}

/// A glTF-frame point in the table-aligned frame: `(X, -Z, Y)`, then turned by `yaw_deg`
/// about +z.
pub fn table_aligned_from_gltf(p: [f64; 3], yaw_deg: f64) -> [f64; 3] {
    let (x, y, z) = (p[0], -p[2], p[1]);
    if yaw_deg == 0.0 {
        return [x, y, z];
    }
    let (s, c) = yaw_deg.to_radians().sin_cos();
    [c * x - s * y, s * x + c * y, z]
}

/// Indexes one asset from its GLB bytes and its annotation (if any).
pub fn index_asset(
    uid: &str,
    glb_sha256: &str,
    bytes: &[u8],
    annotation: Option<&AssetAnnotation>,
    config: &AssetsConfig,
) -> IndexedAsset {
    let started = Instant::now();
    let mut warnings = Vec::new();
    // Judged from the JSON before any mesh is expanded; a file that cannot be opened gets
    // the reader's own error below.
    let verdict = open_glb(bytes)
        .and_then(|document| glb_cost(&document))
        .map_or(Verdict::Within, |cost| budget::judge(cost, &config.budget));
    if let Verdict::Reject(reason) = verdict {
        return IndexedAsset {
            geometry: None,
            invalid: Some(("over_budget".to_owned(), reason)),
            shapes: None,
            warnings,
        };
    }
    let mesh = match read_glb(bytes) {
        Ok(mesh) => mesh,
        Err(e) => {
            return IndexedAsset {
                geometry: None,
                invalid: Some((e.code().to_owned(), e.to_string())),
                shapes: None,
                warnings,
            }
        }
    };
    warnings.extend(mesh.warnings.iter().cloned());
    let (yaw, yaw_warning) = front_yaw_deg(annotation, config.front_alignment);
    warnings.extend(yaw_warning);

    let mut gltf_lo = [f64::INFINITY; 3];
    let mut gltf_hi = [f64::NEG_INFINITY; 3];
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    let aligned: Vec<[f64; 3]> = mesh
        .positions_m
        .iter()
        .map(|p| {
            for k in 0..3 {
                gltf_lo[k] = gltf_lo[k].min(p[k]);
                gltf_hi[k] = gltf_hi[k].max(p[k]);
            }
            let q = table_aligned_from_gltf(*p, yaw);
            for k in 0..3 {
                lo[k] = lo[k].min(q[k]);
                hi[k] = hi[k].max(q[k]);
            }
            q
        })
        .collect();
    let size = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
    let gltf_extents = [
        gltf_hi[0] - gltf_lo[0],
        gltf_hi[1] - gltf_lo[1],
        gltf_hi[2] - gltf_lo[2],
    ];
    let info = &mesh.info;
    let geometry = AssetGeometry {
        front_yaw_deg: yaw,
        bounds_min_m: lo,
        bounds_max_m: hi,
        size_m: size,
        gltf_extents_m: gltf_extents,
        triangles: mesh.triangles.len() as u64,
        vertices: mesh.positions_m.len() as u64,
        primitives: info.primitives as u64,
        mesh_instances: info.mesh_instances as u64,
        materials: info.materials.iter().map(|m| m.name.clone()).collect(),
        textured_materials: info.materials.iter().filter(|m| m.textured).count() as u64,
        textures: info.textures as u64,
        images: info.image_mime_types.clone(),
        generator: info.generator.clone(),
        draco: info.draco,
        skinned: info.skinned,
        extensions_required: info.extensions_required.clone(),
    };

    const AXES: [&str; 3] = ["x (width)", "y (depth)", "z (height)"];
    // Positions are finite, so sizes are too.
    if let Some(axis) = (0..3).find(|k| size[*k] < config.min_extent_m) {
        let reason = format!(
            "the asset is flat: its extent along {} is {:.4} mm (expected at least {} mm on \
             every axis; a flat asset cannot be scaled into a box: model it with a thickness)",
            AXES[axis],
            size[axis] * 1000.0,
            config.min_extent_m * 1000.0
        );
        return IndexedAsset {
            geometry: Some(geometry),
            invalid: Some(("zero_size_axis".to_owned(), reason)),
            shapes: None,
            warnings,
        };
    }
    let largest = size.iter().copied().fold(0.0, f64::max);
    if largest > config.max_plausible_extent_m {
        warnings.push(format!(
            "the asset is {largest:.2} m across, implausible for a tabletop object (modelled in \
             centimetres without a 0.01 scale?)"
        ));
    }
    if let Some(bbox) = annotation.and_then(|a| a.bbox) {
        let annotated = [bbox.x, bbox.y, bbox.z];
        let off: Vec<String> = (0..3)
            .filter(|k| {
                (annotated[*k] - gltf_extents[*k]).abs()
                    > config.bbox_tolerance * gltf_extents[*k].max(annotated[*k])
            })
            .map(|k| {
                format!(
                    "{} {:.4} m vs {:.4} m",
                    ["X", "Y", "Z"][k],
                    annotated[k],
                    gltf_extents[k]
                )
            })
            .collect();
        if !off.is_empty() {
            warnings.push(format!(
                "the annotation bbox differs from the mesh (glTF axes): {} (retrieval scores \
                 sizes from the annotation)",
                off.join(", ")
            ));
        }
    }

    let deadline = Duration::try_from_secs_f64(config.budget.seconds)
        .ok()
        .and_then(|d| started.checked_add(d));
    let shapes = match &verdict {
        Verdict::Simplify(why) => simplified_shapes(
            &aligned,
            &mesh.triangles,
            config,
            deadline,
            why,
            &mut warnings,
        ),
        _ => shapes::collision_shapes_until(&aligned, &mesh.triangles, config, deadline),
    };
    let shapes = match shapes {
        Some(s) => {
            warnings.extend(s.warning.clone());
            Some(ShapesArtifact {
                schema: SHAPES_SCHEMA.to_owned(),
                uid: uid.to_owned(),
                glb_sha256: glb_sha256.to_owned(),
                hull: s.hull,
                parts: s.parts,
                decomposition: s.decomposition,
            })
        }
        None => {
            return IndexedAsset {
                geometry: Some(geometry),
                invalid: Some((
                    "zero_size_axis".to_owned(),
                    "the asset's vertices span no volume (expected a solid object)".to_owned(),
                )),
                shapes: None,
                warnings,
            }
        }
    };
    IndexedAsset {
        geometry: Some(geometry),
        invalid: None,
        shapes,
        warnings,
    }
}

/// The collision shapes of an asset over its budget: made from its decimated mesh, with how
/// far they reach outside the original measured, recorded and warned about.
fn simplified_shapes(
    aligned: &[[f64; 3]],
    triangles: &[[u32; 3]],
    config: &AssetsConfig,
    deadline: Option<Instant>,
    why: &str,
    warnings: &mut Vec<String>,
) -> Option<shapes::Shapes> {
    let simplified = simplify::decimate(aligned, triangles, config.budget.simplified_triangles);
    let mut shapes = shapes::collision_shapes_until(
        &simplified.positions,
        &simplified.triangles,
        config,
        deadline,
    )?;
    let parts: Vec<Vec<[f64; 3]>> = shapes.parts.iter().map(|p| p.points_m.clone()).collect();
    let reach_m = reach::reach_outside(aligned, triangles, &parts);
    warnings.push(format!(
        "the asset is {why}: its collision shape was made from a decimated mesh (vertex \
         clustering on a {:.1} mm grid, {} of its {} triangles); its {} convex parts reach up to \
         {:.1} mm outside the original mesh",
        simplified.cell_m * 1000.0,
        simplified.triangles.len(),
        triangles.len(),
        shapes.parts.len(),
        reach_m * 1000.0
    ));
    shapes.decomposition.simplified = Some(Simplification {
        method: "vertex_clustering".to_owned(),
        cell_m: shapes::round_m(simplified.cell_m, config.shape_precision_m / 10.0),
        triangles: triangles.len() as u64,
        simplified_triangles: simplified.triangles.len() as u64,
        reach_m: shapes::round_m(reach_m, config.shape_precision_m / 10.0),
    });
    Some(shapes)
}

/// The text the lexical encoder sees for an asset: its category (underscores as spaces), then
/// its description; `None` when it has neither.
pub fn asset_text(annotation: &AssetAnnotation, include_category: bool) -> Option<String> {
    let category = annotation
        .category
        .as_deref()
        .filter(|_| include_category)
        .map(|c| c.replace('_', " "));
    let parts: Vec<String> = category
        .into_iter()
        .chain(annotation.description.clone())
        .filter(|t| !t.trim().is_empty())
        .collect();
    (!parts.is_empty()).then(|| parts.join(". "))
}

/// The text index of every annotated asset that has a text.
pub fn build_text_index(annotations: &Annotations, config: &AssetsConfig) -> TextIndexArtifact {
    let documents: std::collections::BTreeMap<String, TextDocument> = annotations
        .iter()
        .filter_map(|(uid, a)| {
            let text = asset_text(a, config.text_includes_category)?;
            let features = features(&text);
            Some((uid.to_owned(), TextDocument { text, features }))
        })
        .collect();
    let document_frequency = document_frequency(documents.values().map(|d| &d.features));
    TextIndexArtifact {
        schema: TEXT_INDEX_SCHEMA.to_owned(),
        encoder: LEXICAL_ENCODER.to_owned(),
        documents,
        document_frequency,
    }
}

#[cfg(test)]
mod tests;
