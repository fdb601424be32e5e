//! mesa-pipeline: the stage runner and the `mesa` command line.
//!
//! - [`runner`]: the stage lifecycle for per-scene stages ([`runner::SceneStage`]: scene
//!   discovery, sharding, skip-done markers, atomic writes) and dataset-level stages
//!   ([`runner::DatasetStage`]), with one thread pool and one [`progress`] display;
//! - [`commands`]: one file per subcommand (its flags, its overrides, its stage adapter) and
//!   the registry that dispatches them and says what `mesa run` runs;
//! - [`cli`]: the global flags and the flag groups shared by commands; [`exit`]: exit codes
//!   and usage errors;
//! - [`config`]: the `mesa.toml` configuration;
//! - [`layouts`]: the one reader of layout files; [`scene_docs`]: a scene's layout and graph
//!   as `tasks` and `records` read them; [`dataset_cache`]: what stages load once per dataset;
//! - [`fsio`]: atomic writes, digests and JSON reads;
//! - [`chat`]: the OpenAI-compatible chat client, its reply cache and offline batches.

pub mod chat;
pub mod cli;
pub mod commands;
pub mod config;
pub mod dataset_cache;
pub mod exit;
pub mod fsio;
pub mod layouts;
pub mod progress;
pub mod runner;
pub mod scene_docs;
