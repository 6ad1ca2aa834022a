//! `soda run`: run a scene and print a summary (or the report as JSON).

use super::output::print;
use super::record::Recorder;
use super::source::{Origin, SceneArgs};
use anyhow::{Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use soda::{RunReport, Simulation};
use std::io::IsTerminal;
use std::path::PathBuf;

/// Examples shown after `soda run --help`.
pub const AFTER_HELP: &str = "\
Examples:
  soda run                                     falling-cubes: 1,000 cubes, 600 steps (10 s)
  soda run --objects 8000 --steps 300          a bigger pile, 5 simulated seconds
  soda run --scene sparse-gas --seed 3 --json  the report as JSON
  soda run --scene scenes/ramp.toml --record ramp.csv --record-every 10

The summary's last line is `hash` and the final state hash (16 hex digits): two runs of
the same scene and options always print the same hash.";

/// Options of `soda run`.
#[derive(Debug, Args)]
pub struct RunArgs {
    #[command(flatten)]
    pub scene: SceneArgs,

    /// Number of steps to compute (600 steps of 1/60 s = 10 simulated seconds).
    #[arg(long, value_name = "N", default_value_t = 600, help_heading = "Run")]
    pub steps: u64,

    // Executor options (--executor, --worlds, --threads, --mode, --window, --partition,
    // --schedule-seed) go here as a flattened `ExecutorArgs` with its own help heading.
    #[command(flatten)]
    pub output: OutputArgs,
}

/// Options about what a run writes.
#[derive(Debug, Args)]
#[command(next_help_heading = "Output")]
pub struct OutputArgs {
    /// Write committed frames to FILE as CSV (header
    /// `step,id,x,y,z,qw,qx,qy,qz,vx,vy,vz,wx,wy,wz`, one row per body per recorded step, in
    /// id order; see README.md, "Recording format").
    #[arg(long, value_name = "FILE")]
    pub record: Option<PathBuf>,

    /// With --record: record the initial state, every K-th step and the last step.
    #[arg(long, value_name = "K", default_value_t = 1, requires = "record",
          value_parser = clap::value_parser!(u64).range(1..))]
    pub record_every: u64,

    /// Print the run report as JSON on stdout (with the final `hash`) instead of the summary.
    #[arg(long)]
    pub json: bool,
}

/// Runs the command.
pub fn run(args: &RunArgs) -> Result<()> {
    let (scene, origin) = args.scene.load()?;
    let initial_bodies = scene.bodies.len();
    let mut sim = Simulation::new(scene);
    let first = sim.reference().step_number();
    let last = first.saturating_add(args.steps);
    let mut recorder = match &args.output.record {
        Some(path) => Some(Recorder::create(path, args.output.record_every, last)?),
        None => None,
    };
    if let Some(r) = recorder.as_mut() {
        r.frame_always(first, sim.state());
    }
    let progress = progress_bar(args, initial_bodies);
    let report = sim.run(args.steps, |frame, state| {
        if let Some(r) = recorder.as_mut() {
            r.frame(frame.step, state);
        }
        progress.inc(1);
    });
    progress.finish_and_clear();
    let recorded = recorder.map(Recorder::finish).transpose()?;
    if args.output.json {
        let text = serde_json::to_string_pretty(&report).context("cannot format the report")?;
        print(&(text + "\n"))
    } else {
        let recorded =
            recorded.map(|(path, frames)| format!("{frames} frames to {}", path.display()));
        print(&summary(
            &report,
            &origin,
            initial_bodies,
            recorded.as_deref(),
        ))
    }
}

/// A progress bar on stderr when stderr is a terminal, the output is not JSON and the run is
/// long enough to be worth one; otherwise a hidden bar.
fn progress_bar(args: &RunArgs, bodies: usize) -> ProgressBar {
    let work = args.steps.saturating_mul(bodies.max(1) as u64);
    if args.output.json || work < 200_000 || !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::with_draw_target(Some(args.steps), ProgressDrawTarget::stderr());
    if let Ok(style) =
        ProgressStyle::with_template("{bar:40} step {pos}/{len}  {elapsed} elapsed, eta {eta}")
    {
        bar.set_style(style);
    }
    bar
}

/// A number for humans: fixed point when moderate, scientific when tiny or huge.
fn num(x: f64) -> String {
    let a = x.abs();
    if x == 0.0 || (1e-3..1e6).contains(&a) {
        format!("{x:.4}")
    } else {
        format!("{x:.3e}")
    }
}

/// The human summary. Its last line is `hash <16 hex digits>`.
fn summary(
    r: &RunReport,
    origin: &Origin,
    initial_bodies: usize,
    recorded: Option<&str>,
) -> String {
    let mut lines = vec![
        ("scene", format!("{} ({origin})", r.scene)),
        (
            "bodies",
            format!(
                "{initial_bodies} at the start, {} at the end",
                r.last.bodies
            ),
        ),
        (
            "steps",
            format!(
                "{} of {} s = {} simulated s ({} executor)",
                r.steps,
                num(r.dt as f64),
                num(r.steps as f64 * r.dt as f64),
                r.executor
            ),
        ),
        (
            "grid",
            format!(
                "cell edge {} m, {} x {} x {} cells",
                num(r.cell_edge as f64),
                r.grid[0],
                r.grid[1],
                r.grid[2]
            ),
        ),
        ("wall time", format!("{} s", num(r.wall_seconds))),
        ("steps/s", format!("{:.1}", r.steps_per_second)),
        ("body-steps/s", format!("{:.0}", r.body_steps_per_second)),
        (
            "kinetic energy",
            format!("{} J", num(r.last.kinetic_energy)),
        ),
        (
            "max penetration",
            format!("{} m", num(r.last.max_penetration as f64)),
        ),
        ("max speed", format!("{} m/s", num(r.last.max_speed as f64))),
        (
            "events",
            format!(
                "{} speed capped, {} left domain",
                r.speed_capped_events, r.left_domain_events
            ),
        ),
    ];
    if let Some(rec) = recorded {
        lines.push(("recorded", rec.to_string()));
    }
    lines.push(("hash", r.hash.clone()));
    lines
        .iter()
        .map(|(k, v)| format!("{k:<16} {v}\n"))
        .collect()
}
