//! Exit codes and the one error that maps to code 2.
//!
//! - 0: every scene (or file) done / valid;
//! - 1: some scenes failed, some files are invalid, or the work stopped on an error (I/O, a
//!   broken dataset file): the error chain is printed;
//! - 2: bad usage or configuration, found before any work starts ([`UsageError`]).

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
}
