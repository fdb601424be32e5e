//! The artifacts of `mesa annotate assets`: the rejected model replies
//! (`assets/annotate/rejects.jsonl`) and the run summary (`assets/annotate/summary.json`).

use std::collections::BTreeMap;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// The schema id of a rejected asset annotation reply.
pub const ANNOTATE_REJECT_SCHEMA: &str = "mesa.annotate-reject/1";
/// The schema id of the annotate summary.
pub const ANNOTATE_SUMMARY_SCHEMA: &str = "mesa.annotate-summary/1";

/// One line of `assets/annotate/rejects.jsonl`: a model reply for an asset that failed
/// validation, kept with why.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct AnnotateReject {
    /// `mesa.annotate-reject/1`.
    pub schema: String,
    /// The asset uid.
    pub uid: String,
    /// The attempt, from 0 (each attempt sends the request with the seed plus the attempt).
    pub attempt: u32,
    /// `llm:<model>`.
    pub source: String,
    /// SHA-256 of the request body (the reply cache key).
    pub request_sha256: String,
    /// Every reason the reply was rejected, each naming its field.
    pub reasons: Vec<String>,
    /// The reply text as received, except that the API key, when the reply held it, is
    /// replaced by `<redacted>`.
    pub reply: String,
    /// Present and true when the reply held the API key.
    #[serde(default, skip_serializing_if = "is_false")]
    pub redacted: bool,
}

fn is_false(value: &bool) -> bool {
    !*value
}

/// `assets/annotate/summary.json`: what the last `mesa annotate assets` run did, and where the
/// annotations of `assets/annotations.json` came from.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct AnnotateSummary {
    /// `mesa.annotate-summary/1`.
    pub schema: String,
    /// `offline` or `llm:<model>`.
    pub source: String,
    /// Valid assets of the index considered (after `--uids`).
    pub assets: u64,
    /// Assets that needed annotating (a field missing, or a placeholder a model replaces, or
    /// `--force`).
    pub targets: u64,
    /// Assets annotated by this run.
    pub annotated: Vec<String>,
    /// Assets waiting for a batch reply (offline batches).
    pub pending: Vec<String>,
    /// Assets whose every attempt was rejected, or whose request failed, with why.
    pub failed: BTreeMap<String, String>,
    /// Replies rejected (kept in assets/annotate/rejects.jsonl).
    pub rejected_replies: u64,
    /// Requests made (each attempt of each target; cached replies included).
    pub requests: u64,
    /// Text tokens of the prompts sent, estimated as characters / 4 (the four images come on
    /// top: see docs/annotation.md).
    pub prompt_text_tokens: u64,
    /// Annotated fields of the whole annotations file by source: `person` (no recorded
    /// source), `offline`, `llm:<model>`.
    pub fields_by_source: BTreeMap<String, u64>,
    /// Assets of the annotations file holding a placeholder field.
    pub placeholder_assets: u64,
}
