//! Exit codes and the one error that maps to code 2.
//!
//! - 0: every scene (or file) done / valid;
//! - 1: some scenes failed, some files are invalid, or the work stopped on an error (I/O, a
//!   broken dataset file): the error chain is printed;
//! - 2: bad usage or configuration, found before any work starts ([`UsageError`]).
//!
//! A closed standard output (`mesa graph --layout F | head -1`) ends the command quietly with
//! 1 ([`is_broken_pipe`]): not all of the output was delivered, which a `set -o pipefail`
//! script should see, but the reader stopped on purpose, so no message. A full disk or any
//! other write error is an error like any other: a message and 1.

use std::process::ExitCode;

/// Exit code: every scene done / the files are valid.
pub const EXIT_OK: u8 = 0;
/// Exit code: some scenes failed / some files are invalid / the work stopped on an error.
pub const EXIT_FAILED: u8 = 1;
/// Exit code: bad usage or configuration.
pub const EXIT_USAGE: u8 = 2;

/// A usage or configuration error (exit code 2), as opposed to failed scenes or an I/O error
/// (exit code 1).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct UsageError(pub String);

impl UsageError {
    /// A usage error with this message.
    pub fn new(message: impl Into<String>) -> Self {
        Self(message.into())
    }
}

/// The usage error of `message`, as an [`anyhow::Error`] (for `?` in command functions).
pub fn usage(message: impl Into<String>) -> anyhow::Error {
    UsageError(message.into()).into()
}

/// Exit code 0 when `ok`, else 1.
pub fn code(ok: bool) -> ExitCode {
    ExitCode::from(if ok { EXIT_OK } else { EXIT_FAILED })
}

/// The exit code of an error that stopped a command: 2 for usage and configuration, else 1.
pub fn code_of(error: &anyhow::Error) -> ExitCode {
    if error.downcast_ref::<UsageError>().is_some() {
        ExitCode::from(EXIT_USAGE)
    } else {
        ExitCode::from(EXIT_FAILED)
    }
}

/// Whether `error` comes from writing to a closed pipe (the reader went away).
pub fn is_broken_pipe(error: &anyhow::Error) -> bool {
    error.chain().any(|cause| {
        cause
            .downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_usage_errors_exit_with_2() {
        assert_eq!(code_of(&usage("bad flag")), ExitCode::from(EXIT_USAGE));
        let io = anyhow::Error::from(std::io::Error::other("disk full")).context("writing x");
        assert_eq!(code_of(&io), ExitCode::from(EXIT_FAILED));
        // Context on top of a usage error keeps it a usage error.
        let wrapped = usage("bad flag").context("resolving");
        assert_eq!(code_of(&wrapped), ExitCode::from(EXIT_USAGE));
    }

    #[test]
    fn a_closed_pipe_is_recognised_under_context() {
        let pipe = anyhow::Error::from(std::io::Error::from(std::io::ErrorKind::BrokenPipe))
            .context("standard output: cannot write");
        assert!(is_broken_pipe(&pipe));
        let full = anyhow::Error::from(std::io::Error::other("no space")).context("x");
        assert!(!is_broken_pipe(&full));
    }
}
