//! mesa-stages: the stages of the mesa pipeline as pure library functions (no CLI types, no
//! global state, every random choice seeded from the scene id and the configured seed), and
//! the shared pieces they need.
//!
//! - [`lift`]: depth and masks to point clouds, the table frame and boxes (SPEC 5.1).
//! - [`annotations`]: the asset annotations (`assets/annotations.json`, SPEC 5.2).
//! - [`graph`]: the rule-based scene graph (SPEC 5.7, `SCENE_GRAPH.md`).
//! - [`glb_read`]: library assets (GLB) read into triangles, Draco included (SPEC 5.2).

pub mod annotations;
pub mod assets;
pub mod glb_read;
pub mod graph;
pub mod lift;
pub mod place;
pub mod retrieve;
pub mod text;
