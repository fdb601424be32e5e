//! mesa-stages: the stages of the mesa pipeline as pure library functions (no CLI types, no
//! global state, every random choice seeded from the scene id and the configured seed), and
//! the shared pieces they need.

pub mod lift;
