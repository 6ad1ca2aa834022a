//! Writing to stdout without panicking when the reader goes away (`soda ... | head`).

use anyhow::{Context, Result};
use std::io::Write;

/// Writes `text` to stdout and flushes; a closed pipe becomes an error that
/// [`is_broken_pipe`] recognises, never a panic.
pub fn print(text: &str) -> Result<()> {
    let mut out = std::io::stdout().lock();
    out.write_all(text.as_bytes())
        .and_then(|()| out.flush())
        .context("cannot write to standard output")
}

/// Whether `e` was caused by writing to a closed pipe (not worth an error message).
pub fn is_broken_pipe(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
    })
}
