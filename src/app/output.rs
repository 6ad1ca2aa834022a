//! Standard output without panicking: `println!` panics when the reader has gone (`soda ... |
//! head`) or the output is full (`> /dev/full`); these return the error instead, and the
//! command line treats a closed pipe as a quiet end ([`is_broken_pipe`]).

use anyhow::{Context, Result};
use std::io::Write;

/// Writes `text` to stdout and flushes; a closed pipe or a full device becomes an error
/// (a closed pipe one [`is_broken_pipe`] recognises), never a panic.
pub fn print(text: &str) -> Result<()> {
    let mut out = std::io::stdout().lock();
    out.write_all(text.as_bytes())
        .and_then(|()| out.flush())
        .context("cannot write to standard output")
}

/// Writes `args` and a newline to stdout, as [`print!`]: `print_line(format_args!(...))?`
/// where `println!(...)` would panic.
pub fn print_line(args: std::fmt::Arguments<'_>) -> Result<()> {
    let mut out = std::io::stdout().lock();
    out.write_fmt(args)
        .and_then(|()| out.write_all(b"\n"))
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

/// Counts with their noun ([`crate::text::counted`], shared with the library's reports).
pub use crate::text::counted;
