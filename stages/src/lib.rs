//! mesa-stages: the pipeline stages as pure library functions, and the shared pieces they
//! need.
//!
//! - [`mesh`]: triangle meshes, transforms, bounds and frame conversions.
//! - [`glb_write`]: writing GLB files (embedded PNG textures, materials, node hierarchies).
//! - [`raster`]: a CPU z-buffer rasterizer (depth in metres, instance ids, shaded colour).
//! - [`image_io`]: PNG encoding and decoding.
//! - [`demo`]: `mesa demo`, a synthetic dataset workspace with ground truth.

pub mod demo;
pub mod glb_write;
pub mod image_io;
pub mod mesh;
pub mod raster;
