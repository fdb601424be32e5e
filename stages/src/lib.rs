//! mesa-stages: the stages of the mesa pipeline as pure library functions (no CLI types, no
//! global state, every random choice seeded from the scene id and the configured seed), and
//! the shared pieces they need.
//!
//! - [`lift`]: depth and masks to point clouds, the table frame and boxes (SPEC 5.1).
//! - [`annotations`]: the asset annotations (`assets/annotations.json`, SPEC 5.2).
//! - [`graph`]: the rule-based scene graph (SPEC 5.7, `SCENE_GRAPH.md`).
//! - [`tasks`]: task instructions and reasoning texts, from a chat model or the built-in
//!   template writer (SPEC 5.8).
//! - [`records`]: SFT and DPO training records, the corruptions, the split (SPEC 5.9).
//! - [`seeding`]: seeded random generators per scene and purpose.

pub mod annotations;
pub mod graph;
pub mod lift;
pub mod records;
pub mod seeding;
pub mod tasks;
