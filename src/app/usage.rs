//! Usage errors: a command line the command cannot take. They exit with status 2, clap's
//! status for the usage errors it finds itself (`--steps -1`, an unknown option), whether
//! clap or the command finds them; every other error (a run that failed, a file that cannot
//! be read, written or parsed) exits with status 1.

use std::fmt;

/// A command line the command cannot take: an option's value it does not accept (`--scene
/// no-such-scene`, `--objects 0`, `--modes fast`), or options that do not go together
/// (`--worlds` on the reference executor, `--objects` with a scene file). The message says
/// what to give instead. [`exit_status`] makes it status 2.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UsageError(pub String);

impl fmt::Display for UsageError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for UsageError {}

/// A [`UsageError`] saying `message`, as an [`anyhow::Error`]: `return Err(usage(...))`
/// where `bail!(...)` would make a runtime error of it.
pub fn usage(message: impl Into<String>) -> anyhow::Error {
    UsageError(message.into()).into()
}

/// Whether `e` is a usage error: a [`UsageError`] anywhere in it, as its cause or as
/// context added to another error (`.context(UsageError(...))`).
pub fn is_usage(e: &anyhow::Error) -> bool {
    e.downcast_ref::<UsageError>().is_some() || e.chain().any(|cause| cause.is::<UsageError>())
}

/// The exit status of a command that failed with `e`: 2 for a usage error (the status of
/// clap's own), 1 for any other.
pub fn exit_status(e: &anyhow::Error) -> u8 {
    if is_usage(e) {
        2
    } else {
        1
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use anyhow::Context;

    #[test]
    fn a_usage_error_is_status_2_as_cause_or_context_and_anything_else_status_1() {
        assert_eq!(exit_status(&usage("--worlds 0")), 2);
        let under_context = Err::<(), _>(usage("--objects 0"))
            .context("cannot build the scene")
            .unwrap_err();
        assert_eq!(exit_status(&under_context), 2);
        let as_context = Err::<(), _>(std::io::Error::other("no such scene"))
            .context(UsageError("--scene nope".into()))
            .context("outer")
            .unwrap_err();
        assert_eq!(exit_status(&as_context), 2);
        assert_eq!(exit_status(&anyhow::anyhow!("the run failed")), 1);
        assert_eq!(
            exit_status(&anyhow::Error::new(std::io::Error::other("x")).context("y")),
            1
        );
    }
}
