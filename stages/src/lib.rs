//! mesa-stages: the stages of the mesa pipeline as pure library functions (no CLI types, no
//! global state, every random choice seeded from the scene id and the configured seed), and
//! the shared pieces they need.
//!
//! - [`lift`]: depth and masks to point clouds, the table frame and boxes (SPEC 5.1).
//! - [`annotations`]: the asset annotations (`assets/annotations.json`, SPEC 5.2).
//! - [`graph`]: the rule-based scene graph (SPEC 5.7, `SCENE_GRAPH.md`).
//! - [`demo`]: `mesa demo`, a synthetic dataset workspace with ground truth.
//! - [`mesh`]: triangle meshes, transforms, bounds and frame conversions.
//! - [`glb_write`]: writing GLB files (embedded PNG textures, materials, node hierarchies).
//! - [`raster`]: a CPU z-buffer rasterizer (depth in metres, instance ids, shaded colour).
//! - [`image_io`]: PNG encoding and decoding.

pub mod annotations;
pub mod demo;
pub mod glb_write;
pub mod graph;
pub mod image_io;
pub mod lift;
pub mod mesh;
pub mod raster;
