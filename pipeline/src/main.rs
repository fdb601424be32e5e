//! The `mesa` binary: parse, dispatch, print the error chain, exit 0/1/2.

use std::process::ExitCode;

use clap::Parser;
use mesa_pipeline::cli::Global;
use mesa_pipeline::commands::Cli;
use mesa_pipeline::exit::{code_of, is_broken_pipe, EXIT_FAILED};

/// mimalloc instead of the system allocator: the stages allocate and free image-sized buffers
/// (a 1024² depth map, its masks, the photo, the render targets) for every scene, and glibc
/// gives those back to the kernel each time, so every scene paid its page faults and zeroing
/// again (an eighth of `mesa lift`). mimalloc keeps them for the next scene: `mesa lift` 27 → 24
/// ms a scene, `mesa graph` 0.25 → 0.20 ms a scene (README, "Speed"). Outputs
/// do not depend on the allocator (the demo tree is byte-identical either way).
///
/// Its version 2 (the crate's `v2` feature), not 3: version 3 placed the next scene's buffers
/// in memory never touched before instead of the blocks just freed, so `mesa lift` over 20
/// scenes of 1024² touched 80 MB of fresh pages (110 MB resident) against 27 MB (47 MB) with
/// version 2, and on a virtual machine a fresh page costs about a millisecond a megabyte the
/// first time it is touched. `mesa records` over 1,000 scenes: 55 MB resident against 65 MB.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() -> ExitCode {
    let cli = Cli::parse();
    init_logging(cli.verbose, cli.quiet);
    quiet_worker_panics();
    match cli.command.run(Global { quiet: cli.quiet }) {
        Ok(code) => code,
        // The reader of standard output went away: nothing to tell it (see exit.rs).
        Err(e) if is_broken_pipe(&e) => ExitCode::from(EXIT_FAILED),
        Err(e) => {
            eprintln!("mesa: error: {e:#}");
            // Usage and configuration errors are 2; anything else stopped the work: 1.
            code_of(&e)
        }
    }
}

/// Panics on mesa's worker threads (named `mesa-...`) are caught where they happen and
/// reported with the scene or asset they concern (a failed marker, a warning); printing them
/// again through the default hook, with a backtrace, only buries that report. Other threads
/// keep the default hook; `MESA_PANIC_TRACE=1` restores it everywhere.
fn quiet_worker_panics() {
    if std::env::var_os("MESA_PANIC_TRACE").is_some() {
        return;
    }
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let worker = std::thread::current()
            .name()
            .is_some_and(|name| name.starts_with("mesa-"));
        if worker {
            tracing::debug!("caught panic on a worker: {info}");
        } else {
            default(info);
        }
    }));
}

fn init_logging(verbose: u8, quiet: bool) {
    let default = match (quiet, verbose) {
        (true, _) => "error",
        (false, 0) => "warn",
        (false, 1) => "debug",
        (false, _) => "trace",
    };
    let from_env = tracing_subscriber::EnvFilter::try_from_env("MESA_LOG").ok();
    // Only a filter that may reach trace needs the cap below (at the default level a
    // directive would switch the client's debug lines on).
    let may_trace = from_env.is_some() || verbose >= 2;
    let mut filter = from_env.unwrap_or_else(|| tracing_subscriber::EnvFilter::new(default));
    // The HTTP client's trace level writes the wire unredacted, the API key included (its
    // debug level redacts it): never below debug, whatever MESA_LOG says.
    let caps: &[&str] = if may_trace {
        &["ureq=debug", "ureq_proto=debug"]
    } else {
        &[]
    };
    for directive in caps {
        if let Ok(directive) = directive.parse() {
            filter = filter.add_directive(directive);
        }
    }
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        // Colour codes only for a person at a terminal: a redirected log stays plain text.
        .with_ansi(mesa_pipeline::progress::colour_on_stderr())
        .with_writer(std::io::stderr)
        .with_target(false)
        .without_time()
        .init();
}
