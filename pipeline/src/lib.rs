//! mesa-pipeline: the stage runner and the `mesa` command line.
//!
//! - [`runner`]: scene discovery, sharding, skip-done markers, atomic writes, parallelism,
//!   progress and summaries, for any [`runner::SceneStage`];
//! - [`stages`]: the per-scene stages registered for `mesa run`;
//! - [`config`]: the `mesa.toml` configuration;
//! - [`cli`] (clap types) and [`app`] (what each subcommand does);
//! - [`fsio`]: atomic writes and digests; [`layouts`]: reading a layout of any form;
//! - [`chat`]: the OpenAI-compatible chat client, its reply cache and offline batches;
//! - [`progress`]: the progress display of dataset-level stages.

pub mod app;
pub mod chat;
pub mod cli;
pub mod config;
pub mod fsio;
pub mod layouts;
pub mod progress;
pub mod runner;
pub mod stages;
