//! `retrieve`: one asset per lifted instance by text and size (SPEC 5.2), MesaTask's recipe:
//!
//! 1. text score = cosine of the instance's query and each asset's text (encoder: the built-in
//!    [`lexical`] one, or precomputed sentence embeddings, [`features`]);
//! 2. keep the `text_top_k` (20) assets of highest text score (ties by uid);
//! 3. size score = cosine of the target `[w, d, h]` (the lifted box) and the asset's
//!    `[bbox.x, bbox.z, bbox.y]` (its annotation bbox, glTF frame; for want of one, the mesh's
//!    extents from the asset index, and the candidate says so);
//! 4. final = `text_weight`·text + `size_weight`·size (0.9 / 0.1); sort by final (ties by text
//!    rank) and keep the top `final_top_k` (5);
//! 5. drop assets with `onTable == false`, `mark_deletion` or `is_composite` (MesaTask's filter),
//!    and assets mesa cannot place (no annotation, no GLB, an invalid GLB); choose the first
//!    left.
//!
//! Unlike MesaTask's code, which gives the instance no asset when the filter empties the top
//! `final_top_k`, the **fallback** goes on: the rest of the top `text_top_k` in final order,
//! then the next `text_top_k` by text score, again in final order, and so on, until an asset
//! passes; the instance records that it fell back.

pub mod features;
pub mod lexical;
pub mod npy;

use std::path::{Path, PathBuf};

use mesa_schemas::artifacts::{
    AssetIndexArtifact, InstancesJson, LiftArtifact, LiftedInstance, RetrievalArtifact,
    RetrievalCandidate, RetrievalRecipe, RetrievedInstance, RETRIEVAL_SCHEMA,
};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::annotations::Annotations;
use crate::text::LEXICAL_ENCODER;
use features::FeatureMatrix;
use lexical::LexicalIndex;

/// The text encoder of retrieval.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Encoder {
    /// The built-in deterministic lexical encoder (words, a tabletop thesaurus, character
    /// trigrams, TF-IDF; see `mesa_stages::text`): no model files, runs offline.
    Lexical,
    /// Precomputed embeddings: `assets/text_features.npy` + `assets/text_uids.json`, and per
    /// instance an `"embedding"` in `input/instances.json` or a row of
    /// `input/query_features.npy` (one row per entry of `instances.json`, in its order).
    Features,
}

/// The `[retrieve]` section of `mesa.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct RetrieveConfig {
    /// Text encoder: "lexical" (built in, the default) or "features" (precomputed sentence
    /// embeddings, e.g. SBERT all-mpnet-base-v2 as MesaTask uses).
    pub encoder: Encoder,
    /// Candidates kept by text score (MesaTask: 20).
    pub text_top_k: u32,
    /// Candidates kept by final score, the first unfiltered one is chosen (MesaTask: 5).
    pub final_top_k: u32,
    /// Weight of the text score in the final score (MesaTask: 0.9).
    pub text_weight: f64,
    /// Weight of the size score in the final score (MesaTask: 0.1).
    pub size_weight: f64,
    /// When the filters reject the whole top final_top_k, go on down the ranking instead of
    /// leaving the instance without an asset (MesaTask's code gives up).
    pub fallback: bool,
    /// The lexical encoder's query is the instance's label, then its description (the
    /// official query is the description alone).
    pub query_includes_label: bool,
}

impl Default for RetrieveConfig {
    fn default() -> Self {
        Self {
            encoder: Encoder::Lexical,
            text_top_k: 20,
            final_top_k: 5,
            text_weight: 0.9,
            size_weight: 0.1,
            fallback: true,
            query_includes_label: true,
        }
    }
}

impl RetrieveConfig {
    /// Checks the values; the message names the key.
    pub fn check(&self) -> Result<(), RetrieveConfigError> {
        if self.text_top_k == 0 || self.final_top_k == 0 {
            return Err(RetrieveConfigError::TopKZero);
        }
        if self.final_top_k > self.text_top_k {
            return Err(RetrieveConfigError::FinalTopKExceedsText {
                final_top_k: self.final_top_k,
                text_top_k: self.text_top_k,
            });
        }
        if !(self.text_weight.is_finite() && self.size_weight.is_finite()) {
            return Err(RetrieveConfigError::WeightsNotFinite);
        }
        Ok(())
    }
}

/// An unusable `[retrieve]` section; the text names the keys.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RetrieveConfigError {
    /// `text_top_k` or `final_top_k` is 0.
    #[error("[retrieve] text_top_k and final_top_k must be at least 1")]
    TopKZero,
    /// `final_top_k` > `text_top_k`.
    #[error(
        "[retrieve] final_top_k {final_top_k} exceeds text_top_k {text_top_k} (expected \
         final_top_k <= text_top_k)"
    )]
    FinalTopKExceedsText {
        /// `final_top_k`.
        final_top_k: u32,
        /// `text_top_k`.
        text_top_k: u32,
    },
    /// A weight is NaN or infinite.
    #[error("[retrieve] text_weight and size_weight must be finite")]
    WeightsNotFinite,
}

/// Why a scene cannot be retrieved.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RetrieveError {
    /// A file is missing or wrong.
    #[error("{}: {problem}", path.display())]
    File {
        /// The file.
        path: PathBuf,
        /// What is wrong, and the fix.
        problem: String,
    },
    /// An instance cannot be queried.
    #[error("{instance}: {problem}")]
    Instance {
        /// The instance.
        instance: String,
        /// What is wrong, and the fix.
        problem: String,
    },
    /// Nothing to retrieve from.
    #[error("no candidate asset: {0}")]
    NoAssets(String),
    /// The `[retrieve]` configuration is unusable.
    #[error("{0}")]
    Config(String),
}

impl RetrieveError {
    /// A problem with a file.
    pub fn file(path: &Path, problem: impl Into<String>) -> Self {
        Self::File {
            path: path.to_owned(),
            problem: problem.into(),
        }
    }
}

/// The text side of retrieval: asset vectors of one encoder.
#[derive(Debug, Clone)]
pub enum TextScorer {
    /// The lexical encoder's index.
    Lexical(LexicalIndex),
    /// Precomputed embeddings.
    Features(FeatureMatrix),
}

/// One instance's query.
#[derive(Debug, Clone, PartialEq)]
pub enum Query {
    /// A text, for the lexical encoder.
    Text(String),
    /// An embedding, for the features encoder.
    Embedding(Vec<f32>),
}

impl TextScorer {
    /// The uid of each asset, in the order of the scorer's indices.
    pub fn uids(&self) -> &[String] {
        match self {
            Self::Lexical(index) => index.uids(),
            Self::Features(matrix) => matrix.uids(),
        }
    }

    /// The encoder's name in artifacts.
    pub fn name(&self) -> String {
        match self {
            Self::Lexical(_) => LEXICAL_ENCODER.to_owned(),
            Self::Features(matrix) => format!("features/{}", matrix.dim()),
        }
    }

    /// For each query, the `k` assets of highest text score, sorted by (score descending, uid
    /// ascending). Queries must suit the encoder ([`Self::check_query`]).
    pub fn top_k(&self, queries: &[&Query], k: usize) -> Vec<Vec<(usize, f64)>> {
        match self {
            Self::Lexical(index) => {
                let texts: Vec<&str> = queries
                    .iter()
                    .map(|q| match q {
                        Query::Text(t) => t.as_str(),
                        Query::Embedding(_) => "",
                    })
                    .collect();
                index.top_k(&texts, k)
            }
            Self::Features(matrix) => {
                let vectors: Vec<&[f32]> = queries
                    .iter()
                    .map(|q| match q {
                        Query::Embedding(v) => v.as_slice(),
                        Query::Text(_) => &[],
                    })
                    .collect();
                matrix.top_k(&vectors, k)
            }
        }
    }

    /// Why `query` cannot be scored by this encoder, if it cannot.
    pub fn check_query(&self, query: &Query) -> Option<String> {
        match (self, query) {
            (Self::Lexical(_), Query::Text(_)) => None,
            (Self::Features(m), Query::Embedding(v)) if v.len() != m.dim() => Some(format!(
                "the query embedding has {} components, the asset features {} (expected \
                 embeddings of the same model)",
                v.len(),
                m.dim()
            )),
            (Self::Features(_), Query::Embedding(v)) => {
                let norm = v.iter().map(|x| f64::from(*x).powi(2)).sum::<f64>();
                (!(norm.is_finite() && norm > 0.0))
                    .then(|| "the query embedding is zero or not finite".to_owned())
            }
            (Self::Lexical(_), Query::Embedding(_)) => {
                Some("an embedding was given to the lexical encoder".to_owned())
            }
            (Self::Features(_), Query::Text(_)) => {
                Some("a text was given to the features encoder".to_owned())
            }
        }
    }
}

/// What retrieval knows about an asset besides its text.
#[derive(Debug, Clone, PartialEq)]
pub struct AssetFacts {
    /// `[bbox.x, bbox.z, bbox.y]` and where it came from (`annotation` or `mesh`).
    pub size: Option<([f64; 3], &'static str)>,
    /// Why it must not be chosen.
    pub rejection: Option<String>,
}

/// Facts of every asset of a scorer, in its order.
#[derive(Debug, Clone, PartialEq)]
pub struct Catalog {
    facts: Vec<AssetFacts>,
}

impl Catalog {
    /// The facts of `uids` from the annotations and the asset index.
    pub fn new(uids: &[String], annotations: &Annotations, index: &AssetIndexArtifact) -> Self {
        let facts = uids
            .iter()
            .map(|uid| {
                let annotation = annotations.get(uid);
                let record = index.assets.get(uid);
                let from_bbox = annotation
                    .and_then(|a| a.bbox)
                    .map(|b| (b.size_table_frame(), "annotation"));
                let from_mesh = record.and_then(|r| r.geometry.as_ref()).map(|g| {
                    let e = g.gltf_extents_m;
                    ([e[0], e[2], e[1]], "mesh")
                });
                let rejection = match (annotation, record) {
                    (None, _) => Some("no annotation".to_owned()),
                    (Some(a), _) if a.rejection().is_some() => a.rejection().map(str::to_owned),
                    (_, None) => Some("no GLB in the library".to_owned()),
                    (_, Some(r)) if !r.valid => Some(format!(
                        "invalid GLB: {}",
                        r.reason_code.as_deref().unwrap_or("unknown")
                    )),
                    _ => None,
                };
                AssetFacts {
                    size: from_bbox.or(from_mesh),
                    rejection,
                }
            })
            .collect();
        Self { facts }
    }

    /// Facts given directly (tests, benchmarks).
    pub fn from_facts(facts: Vec<AssetFacts>) -> Self {
        Self { facts }
    }

    /// Assets that can be chosen.
    pub fn choosable(&self) -> usize {
        self.facts.iter().filter(|f| f.rejection.is_none()).count()
    }
}

/// The cosine of two sizes (0 when either is zero).
pub fn size_cosine(a: [f64; 3], b: [f64; 3]) -> f64 {
    let dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let na = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    let nb = (b[0] * b[0] + b[1] * b[1] + b[2] * b[2]).sqrt();
    if na > 0.0 && nb > 0.0 {
        dot / (na * nb)
    } else {
        0.0
    }
}

/// The query text of an instance for the lexical encoder.
pub fn query_text(instance: &LiftedInstance, config: &RetrieveConfig) -> String {
    if config.query_includes_label && !instance.label.trim().is_empty() {
        format!(
            "{}. {}",
            instance.label.replace('_', " "),
            instance.description
        )
    } else {
        instance.description.clone()
    }
}

/// The query embedding of every lifted instance: its `"embedding"` in `instances.json`, or
/// its row of the sidecar `query_features.npy` (rows in the order of `instances.json`).
pub fn query_embeddings(
    instances_path: &Path,
    sidecar: Option<&Path>,
    lift: &LiftArtifact,
) -> Result<Vec<Vec<f32>>, RetrieveError> {
    let text = std::fs::read_to_string(instances_path)
        .map_err(|e| RetrieveError::file(instances_path, format!("cannot read: {e}")))?;
    let instances: InstancesJson = serde_json::from_str(&text).map_err(|e| {
        RetrieveError::file(instances_path, format!("is not an instances file: {e}"))
    })?;
    mesa_schemas::json::check_unique_keys(&text)
        .map_err(|e| RetrieveError::file(instances_path, e.to_string()))?;
    let rows = match sidecar {
        Some(path) => {
            if let Some(entry) = instances.instances.iter().find(|e| e.embedding.is_some()) {
                return Err(RetrieveError::file(
                    instances_path,
                    format!(
                        "instance id {} has an \"embedding\" while {} also gives the query \
                         embeddings (keep one of the two)",
                        entry.id,
                        path.display()
                    ),
                ));
            }
            let m = npy::read_matrix(path).map_err(|p| RetrieveError::file(path, p.to_string()))?;
            if m.rows != instances.instances.len() {
                return Err(RetrieveError::file(
                    path,
                    format!(
                        "{} rows for the {} entries of {} (expected one row per entry, in its \
                         order)",
                        m.rows,
                        instances.instances.len(),
                        instances_path.display()
                    ),
                ));
            }
            Some(m)
        }
        None => None,
    };
    lift.instances
        .iter()
        .map(|lifted| {
            let position = instances
                .instances
                .iter()
                .position(|e| e.id == lifted.mask_id)
                .ok_or_else(|| {
                    RetrieveError::file(
                        instances_path,
                        format!(
                            "has no instance id {} (lifted as {}): lift.json and instances.json \
                             disagree (rerun `mesa lift`)",
                            lifted.mask_id, lifted.instance
                        ),
                    )
                })?;
            match &rows {
                Some(m) => Ok(m.data[position * m.cols..(position + 1) * m.cols].to_vec()),
                None => instances.instances[position]
                    .embedding
                    .clone()
                    .ok_or_else(|| RetrieveError::Instance {
                        instance: lifted.instance.clone(),
                        problem: format!(
                            "no query embedding: the features encoder needs an \"embedding\" \
                             for instance id {} in {} or an input/query_features.npy",
                            lifted.mask_id,
                            instances_path.display()
                        ),
                    }),
            }
        })
        .collect()
}

/// What retrieving a scene gives.
#[derive(Debug, Clone, PartialEq)]
pub struct RetrievalOutput {
    /// `coarse/retrieval.json`.
    pub artifact: RetrievalArtifact,
    /// Warnings (instances without an asset, fallbacks).
    pub warnings: Vec<String>,
}

fn candidate(
    asset: usize,
    text_rank: usize,
    text_score: f64,
    target: [f64; 3],
    uids: &[String],
    catalog: &Catalog,
    config: &RetrieveConfig,
) -> RetrievalCandidate {
    let facts = &catalog.facts[asset];
    let (size_score, size_source) = match facts.size {
        Some((size, source)) => (size_cosine(target, size), source),
        None => (0.0, "none"),
    };
    RetrievalCandidate {
        uid: uids[asset].clone(),
        text_rank: text_rank as u64,
        text_score,
        size_score,
        size_source: size_source.to_owned(),
        final_score: config.text_weight * text_score + config.size_weight * size_score,
        rejected: facts.rejection.clone(),
    }
}

/// Sorts candidates by final score, ties by text rank.
fn by_final(candidates: &mut [RetrievalCandidate]) {
    candidates.sort_by(|a, b| {
        b.final_score
            .total_cmp(&a.final_score)
            .then_with(|| a.text_rank.cmp(&b.text_rank))
    });
}

/// Retrieves an asset for every instance, MesaTask's recipe (the module's steps 1 to 5 and the
/// fallback); `queries[i]` is the query of `instances[i]`, whose `size_cm` is the target size.
/// Only `instance`, `mask_id`, `label`, `description` and `size_cm` of an instance are read
/// (`mesa eval` retrieves for a model's layout objects this way). Returns the instances in
/// order and the warnings.
pub fn retrieve_instances(
    instances: &[LiftedInstance],
    queries: &[Query],
    scorer: &TextScorer,
    catalog: &Catalog,
    config: &RetrieveConfig,
) -> Result<(Vec<RetrievedInstance>, Vec<String>), RetrieveError> {
    config
        .check()
        .map_err(|e| RetrieveError::Config(e.to_string()))?;
    let uids = scorer.uids();
    if uids.is_empty() {
        return Err(RetrieveError::NoAssets(
            "the text index is empty (annotate assets with a description, then run `mesa \
             assets`)"
                .to_owned(),
        ));
    }
    if queries.len() != instances.len() {
        return Err(RetrieveError::Config(format!(
            "internal error: {} queries for {} instances",
            queries.len(),
            instances.len()
        )));
    }
    for (instance, query) in instances.iter().zip(queries) {
        if let Some(problem) = scorer.check_query(query) {
            return Err(RetrieveError::Instance {
                instance: instance.instance.clone(),
                problem,
            });
        }
    }
    let k = config.text_top_k as usize;
    let refs: Vec<&Query> = queries.iter().collect();
    let ranked = scorer.top_k(&refs, k);
    let mut warnings = Vec::new();
    let mut out = Vec::with_capacity(instances.len());
    for ((instance, query), top) in instances.iter().zip(queries).zip(ranked) {
        let target = instance.size_cm.0;
        let mut candidates: Vec<RetrievalCandidate> = top
            .iter()
            .enumerate()
            .map(|(rank, (asset, score))| {
                candidate(*asset, rank, *score, target, uids, catalog, config)
            })
            .collect();
        by_final(&mut candidates);
        let head = (config.final_top_k as usize).min(candidates.len());
        let mut chosen = candidates[..head]
            .iter()
            .find(|c| c.rejected.is_none())
            .map(|c| c.uid.clone());
        let mut fell_back = false;
        if chosen.is_none() && config.fallback {
            chosen = candidates[head..]
                .iter()
                .find(|c| c.rejected.is_none())
                .map(|c| c.uid.clone());
            // Then further windows of `text_top_k` by text score.
            let mut seen = candidates.len();
            while chosen.is_none() && seen < uids.len() {
                let wider = scorer.top_k(&[query], (seen + k).min(uids.len()));
                let mut window: Vec<RetrievalCandidate> = wider[0][seen..]
                    .iter()
                    .enumerate()
                    .map(|(i, (asset, score))| {
                        candidate(*asset, seen + i, *score, target, uids, catalog, config)
                    })
                    .collect();
                by_final(&mut window);
                seen += window.len();
                // Record what was examined, up to the chosen one.
                for c in window {
                    let pass = c.rejected.is_none();
                    let uid = c.uid.clone();
                    candidates.push(c);
                    if pass {
                        chosen = Some(uid);
                        break;
                    }
                }
            }
            fell_back = chosen.is_some();
        }
        match (&chosen, fell_back) {
            (None, _) => warnings.push(format!(
                "{}: no asset passes the filters (\"{}\"): the instance gets none and `mesa \
                 place` leaves it out",
                instance.instance, instance.description
            )),
            (Some(uid), true) => warnings.push(format!(
                "{}: the top {} candidates were all filtered out: fell back to {uid}",
                instance.instance, config.final_top_k
            )),
            _ => {}
        }
        out.push(RetrievedInstance {
            instance: instance.instance.clone(),
            mask_id: instance.mask_id,
            label: instance.label.clone(),
            query: match query {
                Query::Text(t) => t.clone(),
                Query::Embedding(_) => instance.description.clone(),
            },
            target_size_cm: instance.size_cm,
            candidates,
            chosen,
            fallback: fell_back,
        });
    }
    Ok((out, warnings))
}

/// Retrieves every lifted instance of a scene; `queries[i]` is the query of
/// `lift.instances[i]`.
pub fn retrieve_scene(
    lift: &LiftArtifact,
    queries: &[Query],
    scorer: &TextScorer,
    catalog: &Catalog,
    config: &RetrieveConfig,
) -> Result<RetrievalOutput, RetrieveError> {
    let (out, warnings) = retrieve_instances(&lift.instances, queries, scorer, catalog, config)?;
    let uids = scorer.uids();
    Ok(RetrievalOutput {
        artifact: RetrievalArtifact {
            schema: RETRIEVAL_SCHEMA.to_owned(),
            scene_id: lift.scene_id.clone(),
            encoder: scorer.name(),
            recipe: RetrievalRecipe {
                text_top_k: config.text_top_k,
                final_top_k: config.final_top_k,
                text_weight: config.text_weight,
                size_weight: config.size_weight,
                fallback: config.fallback,
            },
            candidate_assets: uids.len() as u64,
            instances: out,
        },
        warnings,
    })
}

#[cfg(test)]
pub(crate) mod tests;
