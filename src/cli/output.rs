//! What the commands write to the terminal: stdout without panicking when the reader goes
//! away (`soda ... | head`; the library's [`soda::app::output`]), and progress bars on stderr.

pub use soda::app::output::{is_broken_pipe, print, print_line};

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
