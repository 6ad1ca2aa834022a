//! `soda plot`: charts of a trace written by `soda run --trace`.

use anyhow::Result;
use clap::Args;
use soda::app::charts;
use std::path::PathBuf;

/// Examples shown after `soda plot --help`.
pub const AFTER_HELP: &str = "\
Examples:
  soda run --executor virtual --worlds 8 --schedule-seed 3 --steps 120 --trace t.json
  soda plot t.json --out charts     charts/spacetime.svg, territory.svg, heatmap.svg";

/// Options of `soda plot`.
#[derive(Debug, Args)]
pub struct PlotArgs {
    /// A trace written by `soda run --trace FILE`.
    #[arg(value_name = "TRACE")]
    pub trace: PathBuf,

    /// Directory for the charts (created if missing).
    #[arg(long, value_name = "DIR", default_value = ".")]
    pub out: PathBuf,
}

/// Runs the command: reads the trace and writes the three SVG charts.
pub fn plot(args: &PlotArgs) -> Result<()> {
    let trace = soda::app::commands::read_trace(&args.trace)?;
    let mut plan = soda::app::plan::OutputPlan::new();
    plan.input("the trace", &args.trace);
    plan.dir("--out", &args.out)?;
    let spacetime = args.out.join("spacetime.svg");
    let territory = args.out.join("territory.svg");
    let heatmap = args.out.join("heatmap.svg");
    charts::space_time(&trace, &spacetime)?;
    charts::territory_map(&trace, &territory)?;
    charts::rollback_heat_map(&trace, &heatmap)?;
    for p in [spacetime, territory, heatmap] {
        super::output::print_line(format_args!("wrote {}", p.display()))?;
    }
    Ok(())
}
