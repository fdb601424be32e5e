//! `mesa run`: every step of [`super::pipeline`] in order. Every stage's settings are checked
//! first (bad settings of later stages fail now, not after hours of earlier ones); with
//! `--shard`, the dataset-level stages are left to one run before and after the shards.

use std::process::ExitCode;

use anyhow::Context as _;
use clap::Args as ClapArgs;

use super::pipeline::{pipeline, Step};
use crate::cli::{Global, SceneArgs};
use crate::config::annotated_toml;
use crate::fsio::write_atomic;
use crate::runner::dataset::run_and_report_dataset;
use crate::runner::run_and_report;
use mesa_stages::paths::dataset::RESOLVED_CONFIG;

/// `mesa run`.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// The runner flags.
    #[command(flatten)]
    pub stage: SceneArgs,
    /// Print the resolved configuration (every key, documented) and exit.
    #[arg(long)]
    pub print_config: bool,
}

/// Runs `mesa run`.
pub fn run(args: Args, global: Global) -> anyhow::Result<ExitCode> {
    let resolved = args.stage.resolve(global)?;
    if args.print_config {
        print!("{}", annotated_toml(&resolved.config)?);
        return Ok(ExitCode::SUCCESS);
    }
    let ctx = resolved.ctx();
    let steps = pipeline(&resolved.config);
    for step in &steps {
        match step {
            Step::Scene(stage) => stage.preflight(&ctx)?,
            Step::Dataset(stage) => stage.preflight(&ctx)?,
        }
    }
    // The resolved configuration of the last run, for the record.
    let resolved_toml = annotated_toml(&resolved.config)?;
    write_atomic(
        &resolved.dataset.join(RESOLVED_CONFIG),
        resolved_toml.as_bytes(),
    )
    .with_context(|| format!("{}: cannot write .mesa/", resolved.dataset.display()))?;
    let sharded = resolved.options.shard.count > 1;
    let mut failed = false;
    let mut scenes_begun = false;
    for step in &steps {
        let code = match step {
            Step::Scene(stage) => {
                scenes_begun = true;
                run_and_report(stage.as_ref(), &ctx, &resolved.options)?
            }
            // A dataset-level stage covers every scene: with shards, each shard has only its
            // part, and every shard would do the same work at once.
            Step::Dataset(stage) if sharded && stage.skipped_by_run(&ctx).is_none() => {
                eprintln!(
                    "{name}: not run by a shard (it covers the whole dataset); run `mesa {name} \
                     {}` once {}",
                    resolved.dataset.display(),
                    if scenes_begun {
                        "every shard is done"
                    } else {
                        "before the shards"
                    },
                    name = stage.name(),
                );
                continue;
            }
            Step::Dataset(stage) => match stage.skipped_by_run(&ctx) {
                Some(why) => {
                    eprintln!("{}: {why}", stage.name());
                    continue;
                }
                None => run_and_report_dataset(stage.as_ref(), &ctx, &resolved.options)?,
            },
        };
        failed |= code != ExitCode::SUCCESS;
    }
    Ok(crate::exit::code(!failed))
}
