//! mesa-schemas: the serde types of every mesa artifact, their JSON Schemas, and validation.
//!
//! - [`layout`]: the dataset layout (`layout.json`, MesaTask-10K compatible).
//! - [`llm`]: the LLM layout, task info and the published MesaTask records.
//! - [`convert`]: dataset layout ↔ LLM layout.
//! - [`order`]: the object order both layout forms are written in.
//! - [`output`]: the model output text and its parser (the paper's success rule).
//! - [`annotation`]: the annotator round trip (the pack index, the ingest diff).
//! - [`artifacts`]: inputs and per-stage artifacts (lift, retrieval, check, graph, tasks,
//!   records, run markers).
//! - [`render`]: rendered views' cameras, the report's statistics, the release's annotations.
//! - [`kinds`](mod@kinds) and [`validate`]: the kind registry and a validator that reports
//!   every problem as `<json path>: <problem> (expected ...)`.
//! - [`json`]: lenient reading (`NaN` reported, not a syntax error) and sorted-key writing.
//!
//! Units live in names: `_cm`, `_deg`, `_m`, `_mm`, `_px`. Layout files are in centimetres in
//! the table frame (SPEC section 2).

pub mod annotate;
pub mod annotation;
pub mod artifacts;
pub mod convert;
mod decimal;
pub mod eval;
pub mod graph_json;
pub mod json;
pub mod kinds;
pub mod layout;
pub mod layout_file;
mod layout_plain;
pub mod llm;
pub mod order;
pub mod output;
mod pretty;
pub mod render;
pub mod rotation;
mod sorted_writer;
pub mod units;
pub mod validate;

pub use kinds::{kind_of_document, kinds, FileForm, Kind};
pub use layout::{DatasetLayout, LayoutObject, Provenance, LAYOUT_SCHEMA};
pub use llm::{GalleryRecord, LlmLayout, LlmObject, TaskInfo};
pub use validate::Problem;

/// A problem located in a file: the line for JSON Lines files, else none.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Located {
    /// 1-based line number, for JSON Lines files and syntax errors.
    pub line: Option<usize>,
    /// The problem.
    pub problem: Problem,
}

/// Validates the text of one artifact file. The kind comes from `kind` when given (for
/// official files that carry no `schema` field), else from each document's `schema` field;
/// `jsonl` says whether the file is JSON Lines (by default, from the kind).
///
/// Returns every problem found; an empty list means the file is valid.
pub fn validate_text(text: &str, kind: Option<&'static Kind>, jsonl: bool) -> Vec<Located> {
    let jsonl = jsonl || kind.is_some_and(|k| k.form == FileForm::JsonLines);
    let mut out = Vec::new();
    if jsonl {
        let mut documents = 0;
        for (i, line) in text.lines().enumerate() {
            if line.trim().is_empty() {
                continue;
            }
            documents += 1;
            for problem in validate_document(line, kind) {
                out.push(Located {
                    line: Some(problem.line.unwrap_or(0).max(1) + i),
                    problem: problem.problem,
                });
            }
        }
        if documents == 0 {
            out.push(Located {
                line: None,
                problem: Problem::new(
                    "$",
                    "the file has no JSON line",
                    "one JSON document per line",
                ),
            });
        }
    } else {
        out.extend(validate_document(text, kind));
    }
    out
}

fn validate_document(text: &str, kind: Option<&'static Kind>) -> Vec<Located> {
    if json::starts_with_bom(text) {
        return vec![Located {
            line: Some(1),
            problem: Problem::new(
                "$",
                "starts with a UTF-8 byte order mark",
                "JSON text: save the file without one",
            ),
        }];
    }
    let value = match json::parse_lenient(text) {
        Ok(value) => value,
        Err(e) => {
            return vec![Located {
                line: Some(e.line()),
                problem: Problem::new("$", format!("is not valid JSON: {e}"), "a JSON document"),
            }]
        }
    };
    let kind = match kind {
        Some(kind) => kind,
        None => match kind_of_document(&value) {
            Ok(kind) => kind,
            Err(problem) => {
                return vec![Located {
                    line: None,
                    problem,
                }]
            }
        },
    };
    kind.validate_value(&value)
        .into_iter()
        .map(|problem| Located {
            line: None,
            problem,
        })
        .collect()
}
