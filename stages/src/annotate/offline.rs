//! The offline placeholder annotation: what an asset's own file says about it, without a
//! model. Its names (scene, node, mesh and material names) give the category and the words
//! of the description; its geometry gives the size, a mass estimate and whether it is hollow
//! (a container). Every field it writes is recorded with the source `offline` and the entry is
//! marked `mesa_placeholder` ([`super::merge_entry`]).

use serde_json::{json, Value};

use crate::glb_read::{open_glb, GlbError, GlbMesh};

use super::{normalize_category, AssetFields};

/// Words that name no object (exporters' defaults, parts, levels of detail).
const GENERIC: [&str; 22] = [
    "mesh",
    "node",
    "object",
    "scene",
    "root",
    "material",
    "mat",
    "default",
    "geometry",
    "primitive",
    "group",
    "model",
    "part",
    "lod",
    "lod0",
    "defaultmaterial",
    "gltf",
    "sketchfab",
    "untitled",
    "obj",
    "polysurface",
    "shape",
];

/// Density assumed for the mass estimate, kg/m³ of the bounding box (a household object is
/// mostly air in its box).
pub const PLACEHOLDER_DENSITY_KG_M3: f64 = 200.0;

/// The names of an asset's GLB, in file order (scenes, nodes, meshes, materials),
/// deduplicated: the words the placeholder is made of and the model is shown.
pub fn asset_names(glb: &[u8]) -> Result<Vec<String>, GlbError> {
    let document = open_glb(glb)?;
    let root = document.root();
    let mut names: Vec<String> = Vec::new();
    let scenes = root.scenes.iter().filter_map(|s| s.name.clone());
    let nodes = root.nodes.iter().filter_map(|n| n.name.clone());
    let meshes = root.meshes.iter().filter_map(|m| m.name.clone());
    for name in scenes.chain(nodes).chain(meshes) {
        if !names.contains(&name) {
            names.push(name);
        }
    }
    Ok(names)
}

/// The material names of an asset's GLB, in file order.
pub fn material_names(glb: &[u8]) -> Result<Vec<String>, GlbError> {
    let document = open_glb(glb)?;
    let mut names: Vec<String> = Vec::new();
    for name in document
        .root()
        .materials
        .iter()
        .filter_map(|m| m.name.clone())
    {
        if !names.contains(&name) {
            names.push(name);
        }
    }
    Ok(names)
}

/// The words of a name: split at non-letters and camelCase, lower case, without digits-only
/// and generic words.
pub fn name_words(name: &str) -> Vec<String> {
    let mut words = Vec::new();
    let mut current = String::new();
    let mut previous_lower = false;
    for c in name.chars() {
        if !c.is_alphanumeric() {
            words.push(std::mem::take(&mut current));
            previous_lower = false;
            continue;
        }
        if c.is_uppercase() && previous_lower {
            words.push(std::mem::take(&mut current));
        }
        previous_lower = c.is_lowercase();
        current.extend(c.to_lowercase());
    }
    words.push(current);
    words
        .into_iter()
        .filter(|w| w.chars().any(char::is_alphabetic) && w.len() > 1)
        .filter(|w| !GENERIC.contains(&w.as_str()))
        .collect()
}

/// How hollow an asset is, from its mesh seen from above: 0 for a solid top, towards 1 when
/// the middle of its footprint lies deep below its rim (a bowl, a mug, a vase).
pub fn hollowness(mesh: &GlbMesh) -> f64 {
    const N: usize = 24;
    let points = &mesh.positions_m;
    let Some(first) = points.first() else {
        return 0.0;
    };
    let (mut lo, mut hi) = (*first, *first);
    for p in points {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let height = hi[1] - lo[1];
    let (wx, wz) = (hi[0] - lo[0], hi[2] - lo[2]);
    if height <= 0.0 || wx <= 0.0 || wz <= 0.0 {
        return 0.0;
    }
    // The top surface over an N×N grid of the footprint (glTF: y up, footprint in x and z).
    let mut top = vec![f64::NEG_INFINITY; N * N];
    let cell = |i: usize, extent: f64, origin: f64| origin + (i as f64 + 0.5) * extent / N as f64;
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| points.get(i as usize).copied().unwrap_or(*first));
        let (min_x, max_x) = (a[0].min(b[0]).min(c[0]), a[0].max(b[0]).max(c[0]));
        let (min_z, max_z) = (a[2].min(b[2]).min(c[2]), a[2].max(b[2]).max(c[2]));
        let det = (b[2] - c[2]) * (a[0] - c[0]) + (c[0] - b[0]) * (a[2] - c[2]);
        if det.abs() < 1e-18 {
            continue;
        }
        let i0 = (((min_x - lo[0]) / wx * N as f64).floor().max(0.0)) as usize;
        let i1 = (((max_x - lo[0]) / wx * N as f64).ceil() as usize).min(N);
        let j0 = (((min_z - lo[2]) / wz * N as f64).floor().max(0.0)) as usize;
        let j1 = (((max_z - lo[2]) / wz * N as f64).ceil() as usize).min(N);
        for i in i0..i1 {
            let x = cell(i, wx, lo[0]);
            for j in j0..j1 {
                let z = cell(j, wz, lo[2]);
                let l1 = ((b[2] - c[2]) * (x - c[0]) + (c[0] - b[0]) * (z - c[2])) / det;
                let l2 = ((c[2] - a[2]) * (x - c[0]) + (a[0] - c[0]) * (z - c[2])) / det;
                let l3 = 1.0 - l1 - l2;
                if l1 < -1e-9 || l2 < -1e-9 || l3 < -1e-9 {
                    continue;
                }
                let y = l1 * a[1] + l2 * b[1] + l3 * c[1];
                let slot = &mut top[i * N + j];
                *slot = slot.max(y);
            }
        }
    }
    // The middle quarter of the footprint against the highest rim.
    let (m0, m1) = (N * 3 / 8, N * 5 / 8);
    let mut middle = Vec::new();
    let mut rim = f64::NEG_INFINITY;
    for i in 0..N {
        for j in 0..N {
            let y = top[i * N + j];
            if !y.is_finite() {
                continue;
            }
            if (m0..m1).contains(&i) && (m0..m1).contains(&j) {
                middle.push(y);
            } else {
                rim = rim.max(y);
            }
        }
    }
    if middle.is_empty() || !rim.is_finite() {
        return 0.0;
    }
    let middle_y = middle.iter().sum::<f64>() / middle.len() as f64;
    ((rim - middle_y) / height).clamp(0.0, 1.0)
}

/// The placeholder fields of an asset: category from its names (the taxonomy entry its words
/// match best, else its first name), a description of its name words and size, `onTable`
/// when its longest side is at most 1 m, a mass of [`PLACEHOLDER_DENSITY_KG_M3`] times its box volume, `frontView` 0 (the
/// glTF convention), `isContainer` when [`hollowness`] is at least one half, its material
/// names.
pub fn placeholder_fields(
    names: &[String],
    materials: &[String],
    gltf_extents_m: [f64; 3],
    hollow: f64,
    taxonomy: &[String],
) -> AssetFields {
    let words: Vec<String> = {
        let mut seen = Vec::new();
        for word in names.iter().flat_map(|n| name_words(n)) {
            if !seen.contains(&word) {
                seen.push(word);
            }
        }
        seen
    };
    let category = if taxonomy.is_empty() {
        names
            .iter()
            .map(|n| name_words(n).join("_"))
            .find(|c| !c.is_empty())
            .unwrap_or_else(|| "object".to_owned())
    } else {
        best_taxonomy_match(&words, taxonomy).unwrap_or_else(|| "object".to_owned())
    };
    let [x, y, z] = gltf_extents_m;
    let container = hollow >= 0.5;
    let volume = x * y * z;
    let r3 = |v: f64| (v * 1e3).round() / 1e3;
    let mass = r3((PLACEHOLDER_DENSITY_KG_M3 * volume).max(0.001));
    let material_words: Vec<String> = materials
        .iter()
        .map(|m| name_words(m).join(" "))
        .filter(|m| !m.is_empty())
        .collect();
    let description = format!(
        "{}{}, about {:.0} x {:.0} x {:.0} cm{} (placeholder from the asset's names, no model)",
        words.join(" "),
        if material_words.is_empty() {
            String::new()
        } else {
            format!(" of {}", material_words.join(", "))
        },
        x * 100.0,
        z * 100.0,
        y * 100.0,
        if container { ", hollow" } else { "" }
    );
    let mut fields = AssetFields::new();
    fields.insert("category".into(), json!(normalize_category(&category)));
    fields.insert("description".into(), json!(description.trim_start()));
    fields.insert("onTable".into(), json!(x.max(y).max(z) <= 1.0));
    fields.insert("mass".into(), json!(mass));
    fields.insert("frontView".into(), json!(0));
    fields.insert("isContainer".into(), json!(container));
    fields.insert(
        "materials".into(),
        Value::Array(materials.iter().map(|m| json!(m)).collect()),
    );
    fields
}

/// The taxonomy entry whose words the name words cover best: most entry words found (all of
/// them first), then the longer entry, then taxonomy order.
fn best_taxonomy_match(words: &[String], taxonomy: &[String]) -> Option<String> {
    let mut best: Option<(usize, bool, usize, &String)> = None;
    for entry in taxonomy {
        let parts: Vec<&str> = entry.split('_').filter(|p| !p.is_empty()).collect();
        let found = parts
            .iter()
            .filter(|p| words.iter().any(|w| w == *p))
            .count();
        if found == 0 {
            continue;
        }
        let key = (found, found == parts.len(), parts.len(), entry);
        let better = match &best {
            None => true,
            Some((f, all, len, _)) => (key.1, key.0, key.2) > (*all, *f, *len),
        };
        if better {
            best = Some(key);
        }
    }
    best.map(|(_, _, _, entry)| entry.clone())
}
