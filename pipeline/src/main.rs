//! The `mesa` binary: parse, dispatch, print the error chain, exit 0/1/2.

use std::process::ExitCode;

use clap::Parser;
use mesa_pipeline::app::{self, UsageError, EXIT_FAILED, EXIT_USAGE};
use mesa_pipeline::cli::Cli;

fn main() -> ExitCode {
    let cli = Cli::parse();
    init_logging(cli.verbose, cli.quiet);
    quiet_caught_geometry_panics();
    match app::run(cli) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("mesa: error: {e:#}");
            // Usage and configuration errors are 2; anything else stopped the work: 1.
            if e.downcast_ref::<UsageError>().is_some() {
                ExitCode::from(EXIT_USAGE)
            } else {
                ExitCode::from(EXIT_FAILED)
            }
        }
    }
}

fn init_logging(verbose: u8, quiet: bool) {
    let default = match (quiet, verbose) {
        (true, _) => "error",
        (false, 0) => "warn",
        (false, 1) => "debug",
        (false, _) => "trace",
    };
    let filter = tracing_subscriber::EnvFilter::try_from_env("MESA_LOG")
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_target(false)
        .without_time()
        .init();
}

/// parry3d's V-HACD panics on some degenerate voxel sets; `mesa assets` catches that and retries
/// with other parameters (`mesa_stages::assets::shapes`), so the default hook's message would
/// only alarm: it goes to the debug log. Every other panic prints as usual.
fn quiet_caught_geometry_panics() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if info
            .location()
            .is_some_and(|l| l.file().contains("parry3d"))
        {
            tracing::debug!("caught and retried: {info}");
        } else {
            default(info);
        }
    }));
}
