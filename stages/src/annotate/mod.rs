//! `mesa annotate`: asset annotations (MesaTask's `Asset_annotation.json` fields: category,
//! description, onTable, mass, frontView, isContainer, materials) from a vision-language
//! model shown four renders of each asset, or from the offline placeholder ([`offline`]), and
//! their merge into `assets/annotations.json` with the source of every field.
//!
//! Pure functions: the prompt, the request body, the validation of a reply, the merge. The
//! pipeline crate renders the views, talks to the chat backend and writes the files.
//!
//! Provenance: every field mesa writes is listed in the entry's `mesa_sources` object
//! (`field → source`: `llm:<model>`, `offline`, `mesh`); a field present without a source
//! there was set by a person (or another tool) and is never changed. An entry holding an
//! offline field also says `"mesa_placeholder": true`, so a placeholder is never mistaken for
//! a model's annotation. Readers of the MesaTask format ignore both keys.

pub mod instances;
pub mod offline;

use std::collections::{BTreeMap, BTreeSet};

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::{json, Map, Value};

use crate::tasks::chat::{build_request, CallKind, ChatRequest, View};
use crate::tasks::prompts::{PromptError, PromptTemplate};
use crate::tasks::LlmConfig;

/// The built-in prompt of an asset (`data/prompts/annotate_asset.txt`).
pub const ASSET_PROMPT: &str = include_str!("../../../data/prompts/annotate_asset.txt");
/// The prompt's file name in `[annotations] prompts_dir`.
pub const ASSET_PROMPT_FILE: &str = "annotate_asset.txt";
/// The placeholders the asset prompt may use.
pub const ASSET_PLACEHOLDERS: [&str; 4] = ["names", "size_cm", "views", "categories"];
/// The fields a model (or the placeholder) annotates, in the reply's order.
pub const FIELDS: [&str; 7] = [
    "category",
    "description",
    "onTable",
    "mass",
    "frontView",
    "isContainer",
    "materials",
];
/// The key of the per-field sources in an annotation entry.
pub const SOURCES_KEY: &str = "mesa_sources";
/// The key that marks an entry holding placeholder fields.
pub const PLACEHOLDER_KEY: &str = "mesa_placeholder";
/// The source of the offline placeholder.
pub const OFFLINE_SOURCE: &str = "offline";
/// The source of a bbox measured from the mesh.
pub const MESH_SOURCE: &str = "mesh";
/// The azimuths (degrees) of the four views sent, objathor's 0°, 90°, 180°, 270°: view k is
/// `frontView` k.
pub const VIEW_AZIMUTHS_DEG: [u32; 4] = [0, 90, 180, 270];

/// Who annotates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum AnnotateBackend {
    /// The placeholder from the asset's own names and geometry (no model; every field it
    /// writes is marked `offline`).
    Offline,
    /// The chat endpoint of `[annotations.llm]` (live, or offline batches).
    Llm,
}

/// The `[annotations]` section of `mesa.toml` (`mesa annotate`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct AnnotationsConfig {
    /// "offline" (a placeholder from the asset's node, mesh and material names and its
    /// geometry, marked as such; the default) or "llm" (the chat endpoint of
    /// [annotations.llm], shown four renders of each asset). `--backend` overrides it.
    pub backend: AnnotateBackend,
    /// A folder holding an edited annotate_asset.txt, relative to the dataset folder; "" uses
    /// the built-in copy of data/prompts/annotate_asset.txt.
    pub prompts_dir: String,
    /// A category taxonomy: a text file (relative to the dataset folder), one category per
    /// line ('#' starts a comment). A model's category must be one of them, and the offline
    /// placeholder picks the one its names match best. "" accepts free text.
    pub categories: String,
    /// Attempts per asset: a reply that fails validation is kept in
    /// assets/annotate/rejects.jsonl and the request is sent again with the seed plus the
    /// attempt number.
    pub max_attempts: u32,
    /// The lightest plausible mass per bounding-box volume, kg/m³ (a mass below it is
    /// rejected: too light for the asset's size).
    pub min_density_kg_m3: f64,
    /// The heaviest plausible mass per bounding-box volume, kg/m³ (8000: the box full of
    /// steel; a mass above it is rejected).
    pub max_density_kg_m3: f64,
    /// The chat endpoint of the "llm" backend (as [tasks.llm]; its own cache entries, since
    /// requests differ).
    pub llm: LlmConfig,
}

impl Default for AnnotationsConfig {
    fn default() -> Self {
        Self {
            backend: AnnotateBackend::Offline,
            prompts_dir: String::new(),
            categories: String::new(),
            max_attempts: 3,
            min_density_kg_m3: 1.0,
            max_density_kg_m3: 8000.0,
            llm: LlmConfig {
                model: "gpt-4o-mini".to_owned(),
                max_tokens: 512,
                temperature: 0.2,
                ..LlmConfig::default()
            },
        }
    }
}

impl AnnotationsConfig {
    /// What is wrong with the values, one line each (checked when mesa.toml is read).
    pub fn problems(&self) -> Vec<String> {
        let mut problems = Vec::new();
        if self.max_attempts == 0 {
            problems.push("[annotations] max_attempts is 0 (expected at least 1)".to_owned());
        }
        let densities = [
            ("min_density_kg_m3", self.min_density_kg_m3),
            ("max_density_kg_m3", self.max_density_kg_m3),
        ];
        for (name, value) in densities {
            if !value.is_finite() || value <= 0.0 {
                problems.push(format!(
                    "[annotations] {name} is {value} (expected a finite number > 0)"
                ));
            }
        }
        if self.min_density_kg_m3 > self.max_density_kg_m3 {
            problems.push(format!(
                "[annotations] min_density_kg_m3 ({}) is above max_density_kg_m3 ({}) (expected \
                 min <= max)",
                self.min_density_kg_m3, self.max_density_kg_m3
            ));
        }
        problems.extend(
            self.llm
                .problems("annotations.llm", self.backend == AnnotateBackend::Llm),
        );
        problems
    }

    /// The source name of fields this configuration's backend writes: `offline` or
    /// `llm:<model>`.
    pub fn source(&self) -> String {
        match self.backend {
            AnnotateBackend::Offline => OFFLINE_SOURCE.to_owned(),
            AnnotateBackend::Llm => format!("llm:{}", self.llm.model),
        }
    }
}

/// The asset prompt: the built-in one, or `annotate_asset.txt` of `text`'s file.
pub fn asset_prompt(source: &str, text: &str) -> Result<PromptTemplate, PromptError> {
    PromptTemplate::parse(source, text, &ASSET_PLACEHOLDERS)
}

/// A category taxonomy read from its text (one per line, `#` comments, blank lines skipped),
/// normalised ([`normalize_category`]).
pub fn parse_taxonomy(text: &str) -> Vec<String> {
    let mut seen = BTreeSet::new();
    text.lines()
        .map(|l| l.split('#').next().unwrap_or("").trim())
        .filter(|l| !l.is_empty())
        .map(normalize_category)
        .filter(|c| seen.insert(c.clone()))
        .collect()
}

/// A category in the form annotations use: lower case, words joined by `_`.
pub fn normalize_category(text: &str) -> String {
    text.split(|c: char| !c.is_alphanumeric())
        .filter(|w| !w.is_empty())
        .map(str::to_lowercase)
        .collect::<Vec<_>>()
        .join("_")
}

/// What the request of one asset is made from.
#[derive(Debug, Clone, PartialEq)]
pub struct AssetInput {
    /// The asset uid.
    pub uid: String,
    /// Its names: scene, node, mesh and material names, in file order, deduplicated.
    pub names: Vec<String>,
    /// glTF-frame extents (x, y up, z), metres.
    pub gltf_extents_m: [f64; 3],
    /// The four views (0°, 90°, 180°, 270°) as PNGs; empty for the offline backend.
    pub views: Vec<View>,
}

impl AssetInput {
    /// The bounding-box volume, m³.
    pub fn volume_m3(&self) -> f64 {
        self.gltf_extents_m.iter().product()
    }
}

/// The request of one asset: the prompt filled, the four views as data URLs, JSON mode.
pub fn asset_request(
    template: &PromptTemplate,
    config: &AnnotationsConfig,
    taxonomy: &[String],
    input: &AssetInput,
    attempt: u32,
) -> Result<ChatRequest, PromptError> {
    let [x, y, z] = input.gltf_extents_m;
    let mut values = BTreeMap::new();
    values.insert("names", input.names.join(", "));
    // Table frame [width, depth, height] = glTF [x, z, y].
    values.insert(
        "size_cm",
        format!("{:.1} x {:.1} x {:.1}", x * 100.0, z * 100.0, y * 100.0),
    );
    values.insert(
        "views",
        format!(
            "The {} pictures show the asset from the front side of its file and turned by \
             90°, 180° and 270° about the vertical, in that order (pictures 0 to 3).",
            input.views.len()
        ),
    );
    values.insert(
        "categories",
        if taxonomy.is_empty() {
            "any category".to_owned()
        } else {
            format!("one of: {}", taxonomy.join(", "))
        },
    );
    let prompt = template.render(&values)?;
    // The call kind is a label the pipeline never sends; the description call is the one of
    // the tasks library that carries images.
    Ok(build_request(
        CallKind::Description,
        &config.llm,
        &prompt,
        &input.views,
        true,
        attempt,
    ))
}

/// The validated fields of a reply, in MesaTask's names and forms.
pub type AssetFields = Map<String, Value>;

/// Reads and checks a model's reply for one asset: every field of [`FIELDS`], with its type
/// and range. The reasons say what is wrong with each field.
pub fn validate_asset_reply(
    content: &str,
    input: &AssetInput,
    taxonomy: &[String],
    config: &AnnotationsConfig,
) -> Result<AssetFields, Vec<String>> {
    let text = strip_fence(content.trim());
    let value: Value = serde_json::from_str(text)
        .map_err(|e| vec![format!("not valid JSON ({e}); expected one JSON object")])?;
    let Some(object) = value.as_object() else {
        return Err(vec![format!(
            "the reply is {} (expected a JSON object with the keys {})",
            mesa_schemas::validate::describe(&value),
            FIELDS.join(", ")
        )]);
    };
    let mut reasons = Vec::new();
    let mut fields = Map::new();
    let mut field =
        |name: &str, check: &dyn Fn(&Value) -> Result<Value, String>| match object.get(name) {
            None => reasons.push(format!("{name}: missing")),
            Some(v) => match check(v) {
                Ok(v) => {
                    fields.insert(name.to_owned(), v);
                }
                Err(why) => reasons.push(format!("{name}: {why}")),
            },
        };
    field("category", &|v| {
        let text = v
            .as_str()
            .ok_or_else(|| format!("{} (expected a string)", describe(v)))?;
        let category = normalize_category(text);
        if category.is_empty() || category.len() > 64 {
            return Err(format!(
                "\"{text}\" (expected one to three words, at most 64 characters)"
            ));
        }
        if !taxonomy.is_empty() && !taxonomy.contains(&category) {
            return Err(format!(
                "\"{category}\" is not in the taxonomy ([annotations] categories)"
            ));
        }
        Ok(json!(category))
    });
    field("description", &|v| {
        let text = v
            .as_str()
            .ok_or_else(|| format!("{} (expected a string)", describe(v)))?
            .trim();
        let words = text.split_whitespace().count();
        if words < 3 || text.chars().count() > 1200 {
            return Err(format!(
                "{words} words, {} characters (expected a sentence of at least 3 words, at most \
                 1200 characters)",
                text.chars().count()
            ));
        }
        Ok(json!(text))
    });
    for name in ["onTable", "isContainer"] {
        field(name, &|v| match v {
            Value::Bool(_) => Ok(v.clone()),
            _ => Err(format!("{} (expected true or false)", describe(v))),
        });
    }
    let volume = input.volume_m3();
    field("mass", &|v| {
        let mass = v
            .as_f64()
            .ok_or_else(|| format!("{} (expected a number of kilograms)", describe(v)))?;
        if !(mass.is_finite() && mass > 0.0) {
            return Err(format!("{mass} kg (expected > 0 kg)"));
        }
        let (low, high) = (
            config.min_density_kg_m3 * volume,
            config.max_density_kg_m3 * volume,
        );
        if volume > 0.0 && !(low..=high).contains(&mass) {
            return Err(format!(
                "{mass} kg is implausible for a {:.1} x {:.1} x {:.1} cm box (expected {low:.3} \
                 to {high:.3} kg: [annotations] min_density_kg_m3 to max_density_kg_m3 times the \
                 box volume)",
                input.gltf_extents_m[0] * 100.0,
                input.gltf_extents_m[2] * 100.0,
                input.gltf_extents_m[1] * 100.0
            ));
        }
        Ok(v.clone())
    });
    field("frontView", &|v| match v.as_u64() {
        Some(k) if k < 4 => Ok(json!(k)),
        _ => Err(format!(
            "{} (expected one of the 4 views: 0, 1, 2 or 3)",
            describe(v)
        )),
    });
    field("materials", &|v| {
        let items = v
            .as_array()
            .ok_or_else(|| format!("{} (expected a list of strings)", describe(v)))?;
        let mut out = Vec::new();
        for (i, item) in items.iter().enumerate() {
            match item.as_str() {
                Some(s) if !s.trim().is_empty() => out.push(json!(s.trim())),
                _ => {
                    return Err(format!(
                        "[{i}] is {} (expected a non-empty string)",
                        describe(item)
                    ))
                }
            }
        }
        Ok(Value::Array(out))
    });
    if reasons.is_empty() {
        Ok(fields)
    } else {
        Err(reasons)
    }
}

fn describe(value: &Value) -> String {
    mesa_schemas::validate::describe(value)
}

/// The text inside a ```` ```json ```` fence, or the text.
fn strip_fence(text: &str) -> &str {
    let Some(rest) = text.strip_prefix("```") else {
        return text;
    };
    let rest = rest.strip_prefix("json").unwrap_or(rest);
    rest.trim_end().strip_suffix("```").unwrap_or(rest).trim()
}

/// The `frontView` to record when the views were rendered with the asset already turned by
/// the index's front yaw (`yaw_deg`, a multiple of -90° from an earlier frontView): the
/// model's view `k` of the turned asset, composed with that turn.
pub fn front_view_of_file(k: u64, yaw_deg: f64) -> u64 {
    let turned = (-yaw_deg / 90.0).round().rem_euclid(4.0) as u64;
    (k + turned) % 4
}

/// Which annotated fields an entry lacks or holds from a source `source` may replace
/// (with `force`, every field mesa wrote); empty when the asset needs no annotation.
pub fn fields_to_annotate(entry: Option<&Value>, source: &str, force: bool) -> Vec<&'static str> {
    let Some(object) = entry.and_then(Value::as_object) else {
        return FIELDS.to_vec();
    };
    let sources = object.get(SOURCES_KEY).and_then(Value::as_object);
    FIELDS
        .iter()
        .copied()
        .filter(|field| {
            // objathor's `receptacle` is a person's isContainer (readers take either).
            let alias = (*field == "isContainer")
                .then(|| object.get("receptacle"))
                .flatten()
                .filter(|v| !v.is_null());
            if alias.is_some() && object.get(*field).is_none() {
                return false;
            }
            let Some(_) = object.get(*field).filter(|v| !v.is_null()) else {
                return true;
            };
            match sources.and_then(|s| s.get(*field)).and_then(Value::as_str) {
                // A person's field.
                None => false,
                Some(old) => force || replaces(source, old),
            }
        })
        .collect()
}

/// Whether fields from `new` replace fields from `old` without `--force`: a model's
/// annotation replaces the offline placeholder, never the other way round.
fn replaces(new: &str, old: &str) -> bool {
    old == OFFLINE_SOURCE && new != OFFLINE_SOURCE
}

/// Merges annotated fields into an entry: only the `fields` listed (from
/// [`fields_to_annotate`]) are written, each recorded under `mesa_sources` with `source`; a
/// bbox is added from the mesh when the entry has none (any of MesaTask's forms). Returns the
/// new entry.
pub fn merge_entry(
    entry: Option<&Value>,
    annotated: &AssetFields,
    fields: &[&str],
    source: &str,
    gltf_extents_m: [f64; 3],
) -> Value {
    let mut object = entry
        .and_then(Value::as_object)
        .cloned()
        .unwrap_or_default();
    let mut sources = object
        .get(SOURCES_KEY)
        .and_then(Value::as_object)
        .cloned()
        .unwrap_or_default();
    for field in fields {
        if let Some(value) = annotated.get(*field) {
            object.insert((*field).to_owned(), value.clone());
            sources.insert((*field).to_owned(), json!(source));
        }
    }
    let has_bbox = ["bbox", "min_point", "max_point"]
        .iter()
        .any(|k| object.contains_key(*k));
    if !has_bbox {
        let r4 = |v: f64| (v * 1e4).round() / 1e4;
        let [x, y, z] = gltf_extents_m.map(r4);
        object.insert("bbox".to_owned(), json!({"x": x, "y": y, "z": z}));
        sources.insert("bbox".to_owned(), json!(MESH_SOURCE));
    }
    let placeholder = sources.values().any(|s| s == OFFLINE_SOURCE);
    if placeholder {
        object.insert(PLACEHOLDER_KEY.to_owned(), json!(true));
    } else {
        object.remove(PLACEHOLDER_KEY);
    }
    if !sources.is_empty() {
        object.insert(SOURCES_KEY.to_owned(), Value::Object(sources));
    }
    Value::Object(object)
}

/// Counts of annotated fields by source over an annotations document: `source → fields`,
/// `person` for fields without a recorded source; and assets holding a placeholder.
pub fn count_sources(document: &Value) -> (BTreeMap<String, u64>, u64) {
    let mut counts = BTreeMap::new();
    let mut placeholders = 0;
    for entry in document.as_object().into_iter().flat_map(|m| m.values()) {
        let Some(object) = entry.as_object() else {
            continue;
        };
        let sources = object.get(SOURCES_KEY).and_then(Value::as_object);
        for field in FIELDS {
            // objathor's `receptacle` stands for isContainer.
            let key = if field == "isContainer" && !object.contains_key(field) {
                "receptacle"
            } else {
                field
            };
            if object.get(key).is_none_or(Value::is_null) {
                continue;
            }
            let source = sources
                .and_then(|s| s.get(field))
                .and_then(Value::as_str)
                .unwrap_or("person");
            *counts.entry(source.to_owned()).or_insert(0) += 1;
        }
        if object.get(PLACEHOLDER_KEY) == Some(&json!(true)) {
            placeholders += 1;
        }
    }
    (counts, placeholders)
}

#[cfg(test)]
mod tests;
