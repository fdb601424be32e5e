//! mesa-stages: the pipeline stages as pure library functions of their inputs (SPEC section 5).
//!
//! - [`graph`]: the rule-based scene graph (SPEC 5.7, `SCENE_GRAPH.md`).
//! - [`annotations`]: the asset annotations (`assets/annotations.json`, SPEC 5.2).
//!
//! No function here takes CLI types or touches global state; the `mesa` binary (crate
//! `mesa-pipeline`) reads files, runs these, and writes their results.

pub mod annotations;
pub mod graph;
