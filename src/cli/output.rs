//! What the commands write to the terminal: stdout without panicking when the reader goes
//! away (`soda ... | head`), and progress bars on stderr.

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

/// A progress bar over `runs` runs on stderr (`run 3/40  12s elapsed  <message>`), hidden when
/// stderr is not a terminal. Shared by `soda verify` and `soda experiment`.
pub fn runs_bar(runs: u64) -> indicatif::ProgressBar {
    use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
    use std::io::IsTerminal;
    if !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::with_draw_target(Some(runs), ProgressDrawTarget::stderr());
    if let Ok(style) =
        ProgressStyle::with_template("{bar:40} run {pos}/{len}  {elapsed} elapsed  {msg}")
    {
        bar.set_style(style);
    }
    bar
}
