//! `soda run`: run a scene and print a summary (or the report as JSON).

use super::checkpoint::{
    CheckpointArgs, CheckpointWriter, EventTotals, RunDescription, SceneSource,
};
use super::exec_args::ExecutorArgs;
use super::output::print;
use super::record::Recorder;
use super::source::{Origin, SceneArgs};
use anyhow::{bail, Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use soda::app::atomic::{self, AtomicFile};
use soda::app::interrupt;
use soda::app::output::counted;
use soda::app::plan::OutputPlan;
use soda::app::usage;
use soda::frame::StatesWanted;
use soda::scene::{parse_inputs, InputScript};
use soda::sim::{run_scene_from, ExecutorKind, ResumeFrom, RunOptions, RunReport};
use soda::{Body, Frame, RigidBodyModel, Scene};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};

/// Examples shown after `soda run --help`.
pub const AFTER_HELP: &str = "\
Examples:
  soda run                                     falling-cubes: 1,000 cubes, 600 steps (10 s)
  soda run --objects 8000 --steps 300          a bigger pile, 5 simulated seconds
  soda run --scene sparse-gas --seed 3 --json  the report as JSON
  soda run --scene scenes/ramp.toml --record ramp.csv --record-every 10
  soda run --executor virtual --worlds 8 --mode cell --schedule-seed 3
  soda run --executor threaded --threads 2 --worlds 8 --objects 8000

The summary's last line is `hash` and the final state hash (16 hex digits): two runs of
the same scene and options always print the same hash.

Every output path is checked before step 1. Files are written under a temporary name
and renamed into place, so each is the old file or a whole new one (--csv appends its row
under a lock and cuts the table back if the append fails). Ctrl-C stops at the
next committed step, keeps the --record file (whole frames so far), prints
`interrupted at step N, hash H` and exits with 130. With --checkpoint FILE, `soda resume
FILE` continues an interrupted (or killed) run to the same final hash.";

/// Options of `soda run`.
#[derive(Debug, Args)]
pub struct RunArgs {
    #[command(flatten)]
    pub scene: SceneArgs,

    /// The model: `rigid-bodies` (the scenes) or a registered example model (`soda models`:
    /// epidemic, phold), which takes --entities, --seed, --steps and the kernel options.
    #[arg(long, value_name = "NAME", default_value = super::RIGID_BODIES)]
    pub model: String,

    /// Number of steps to compute (600 steps of 1/60 s = 10 simulated seconds).
    #[arg(long, value_name = "N", default_value_t = 600, help_heading = "Run",
          value_parser = super::numbers::whole(0, u64::MAX))]
    pub steps: u64,

    /// Apply the scripted inputs of FILE (.toml or .json): at given steps spawn a body,
    /// remove one, push one or set its velocity (docs/formats.md, "Input scripts"). Every
    /// executor applies them with the same bits.
    #[arg(long, value_name = "FILE", help_heading = "Run")]
    pub inputs: Option<PathBuf>,

    #[command(flatten)]
    pub executor: ExecutorArgs,

    #[command(flatten)]
    pub output: OutputArgs,

    #[command(flatten)]
    pub checkpoint: CheckpointArgs,
}

/// Options about what a run writes.
#[derive(Debug, Args)]
#[command(next_help_heading = "Output")]
pub struct OutputArgs {
    /// Write committed frames to FILE as CSV (header
    /// `step,id,x,y,z,qw,qx,qy,qz,vx,vy,vz,wx,wy,wz`, one row per body per recorded step, in
    /// id order; see docs/formats.md, "Recording format"). About 120 bytes per body per recorded
    /// step: 1,000 bodies over 600 steps make 70 MB (a warning above 1 GB). Written to a
    /// temporary file and renamed into place at the end or on Ctrl-C.
    #[arg(long, value_name = "FILE")]
    pub record: Option<PathBuf>,

    /// With --record: record the initial state, every K-th step and the last step.
    #[arg(long, value_name = "K", default_value_t = 1, requires = "record",
          value_parser = super::numbers::whole(1, u64::MAX))]
    pub record_every: u64,

    /// Print the run report as JSON on stdout (with the final `hash`) instead of the summary.
    #[arg(long)]
    pub json: bool,

    /// Write the run report with every kernel counter (per world and in total) as JSON to
    /// FILE (the same document as --json, which prints it instead).
    #[arg(long, value_name = "FILE")]
    pub counters: Option<PathBuf>,

    /// Append one row for this run to the CSV file FILE (a header first if the file is new):
    /// scene, executor, worlds, threads, mode, window, partition, steps, wall time, hash and
    /// every kernel counter (SPEC.md §K9).
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,

    /// Record a trace (each world's LVT over wall time, every rollback, GVT advances,
    /// messages per step) and write it as JSON to FILE; `soda plot FILE` draws it.
    /// Virtual and threaded executors only.
    #[arg(long, value_name = "FILE")]
    pub trace: Option<PathBuf>,

    /// Draw the territories' evolution into DIR (created if missing): territory-STEP.svg
    /// for the initial partition and after every balancing round (top view, majority owner
    /// of each column), and imbalance.svg (max/mean load per round). Virtual and threaded
    /// executors only.
    #[arg(long, value_name = "DIR")]
    pub territories: Option<PathBuf>,
}

impl OutputArgs {
    /// No output at all (an MPI run's ranks other than 0).
    fn none() -> Self {
        OutputArgs {
            record: None,
            record_every: 1,
            json: false,
            counters: None,
            csv: None,
            trace: None,
            territories: None,
        }
    }
}

/// The output files of a run, checked (and the streamed or held ones opened under their
/// temporary names) before step 1.
struct Outputs {
    record: Option<Recorder>,
    counters: Option<AtomicFile>,
    trace: Option<AtomicFile>,
    csv: Option<PathBuf>,
    territories: Option<PathBuf>,
}

impl Outputs {
    /// Checks every output path of `out` (and the checkpoint file, if any) against each
    /// other and the scene file, and opens what can be opened; nothing is computed yet.
    fn plan(
        out: &OutputArgs,
        [scene_file, script_file]: [Option<&Path>; 2],
        checkpoint: Option<&Path>,
        last_step: u64,
    ) -> Result<(Outputs, Option<PathBuf>)> {
        let mut plan = OutputPlan::new();
        if let Some(scene) = scene_file {
            plan.input("the scene file", scene);
        }
        if let Some(script) = script_file {
            plan.input("the input script", script);
        }
        let checkpoint = match checkpoint {
            Some(path) => Some(plan.file("--checkpoint", path)?),
            None => None,
        };
        let record = match &out.record {
            Some(path) => {
                let target = plan.file("--record", path)?;
                Some(Recorder::create(&target, out.record_every, last_step)?)
            }
            None => None,
        };
        let counters = match &out.counters {
            Some(path) => Some(AtomicFile::create(&plan.file("--counters", path)?)?),
            None => None,
        };
        let trace = match &out.trace {
            Some(path) => Some(AtomicFile::create(&plan.file("--trace", path)?)?),
            None => None,
        };
        let csv = match &out.csv {
            Some(path) => {
                let target = plan.file("--csv", path)?;
                super::table::check_table(&target)?;
                Some(target)
            }
            None => None,
        };
        let territories = match &out.territories {
            Some(dir) => Some(plan.dir("--territories", dir)?),
            None => None,
        };
        let outputs = Outputs {
            record,
            counters,
            trace,
            csv,
            territories,
        };
        Ok((outputs, checkpoint))
    }
}

/// One run of a scene, fresh (`soda run`) or resumed from a checkpoint (`soda resume`).
pub(super) struct Job<'a> {
    /// The scene (its model and grid; its bodies unless `from` is given).
    pub scene: Scene,
    /// Where the scene came from, for the summary.
    pub origin: Origin,
    /// How to rebuild the scene, for checkpoints.
    pub source: SceneSource,
    /// The scene file to protect from being overwritten, if the scene is a file.
    pub scene_file: Option<PathBuf>,
    /// The scripted inputs (all of them, also those before `from`'s step).
    pub script: InputScript,
    /// Where the script came from, for messages, and the file to protect, if any.
    pub script_origin: (String, Option<PathBuf>),
    /// Executor and kernel options.
    pub options: RunOptions,
    /// The committed bodies to start from (a resume), or `None` for the scene's bodies.
    pub from: Option<ResumeFrom>,
    /// Events of the steps before `from` (a resume).
    pub events_before: EventTotals,
    /// The step to reach.
    pub last_step: u64,
    /// What to write.
    pub output: &'a OutputArgs,
    /// Checkpoints: the file and the steps between them.
    pub checkpoint: Option<(PathBuf, u64)>,
    /// The checkpoint this run resumed from, for the summary.
    pub resumed_from: Option<PathBuf>,
}

/// Runs the command.
pub fn run(args: &RunArgs) -> Result<()> {
    let options = args.executor.options()?;
    let (scene, origin, source) = args.scene.load_with_source()?;
    let script = match &args.inputs {
        Some(path) => read_script(path)?,
        None => InputScript::default(),
    };
    execute(Job {
        scene,
        origin,
        source,
        scene_file: args.scene.file().map(Path::to_path_buf),
        script,
        script_origin: (
            args.inputs
                .as_ref()
                .map_or(String::new(), |p| p.display().to_string()),
            args.inputs.clone(),
        ),
        options,
        from: None,
        events_before: EventTotals::default(),
        last_step: args.steps,
        output: &args.output,
        checkpoint: args
            .checkpoint
            .checkpoint
            .clone()
            .map(|p| (p, args.checkpoint.checkpoint_every)),
        resumed_from: None,
    })
}

/// Reads and parses an input script (validated against the scene by `execute`).
pub(super) fn read_script(path: &Path) -> Result<InputScript> {
    let Some(format) = soda::scene::SceneFormat::from_path(path) else {
        return Err(usage(format!(
            "--inputs `{}`: an input script's name must end in .toml or .json",
            path.display()
        )));
    };
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read the input script `{}`", path.display()))?;
    parse_inputs(&text, format, &path.display().to_string())
        .with_context(|| format!("cannot load the input script `{}`", path.display()))
}

/// Runs a job: checks every output, runs, writes the outputs and prints the summary.
pub(super) fn execute(job: Job<'_>) -> Result<()> {
    let Job {
        scene,
        origin,
        source,
        scene_file,
        script,
        script_origin,
        mut options,
        from,
        mut events_before,
        last_step,
        output,
        checkpoint,
        resumed_from,
    } = job;
    if output.trace.is_some() {
        if options.executor == ExecutorKind::Reference {
            return Err(usage(
                "--trace records the Time Warp kernel's worlds, and the reference executor has \
                 none; add --executor virtual or --executor threaded",
            ));
        }
        options.kernel.trace = true;
    }
    if output.territories.is_some() && options.executor == ExecutorKind::Reference {
        return Err(usage(
            "--territories draws the Time Warp worlds' territories, and the reference executor \
             has none; add --executor virtual or --executor threaded",
        ));
    }
    // Before the MPI role split: every rank refuses alike.
    soda::app::check_checkpoint_has_a_step(last_step, checkpoint.is_some(), from.is_some())?;
    // Under MPI every rank runs this; only rank 0 writes outputs and prints.
    let role = super::mpi::Role::of(&options)?;
    let quiet_outputs;
    let (output, checkpoint) = if role.root() {
        (output, checkpoint)
    } else {
        quiet_outputs = OutputArgs::none();
        (&quiet_outputs, None)
    };
    let first_step = from.as_ref().map_or(0, |f| f.step);
    if last_step < first_step {
        return Err(usage(format!(
            "--steps {last_step} is before the checkpoint's step {first_step}: give --steps \
             {first_step} or more"
        )));
    }
    let steps = last_step - first_step;
    // Every entry is checked against the scene (from step 1: a resumed run's script is the
    // whole run's); those a checkpoint already holds the effect of are dropped.
    let inputs: Vec<_> = script
        .to_inputs(&scene, &script_origin.0, 1)
        .with_context(|| format!("cannot use the input script `{}`", script_origin.0))?
        .into_iter()
        .filter(|(step, _)| *step > first_step)
        .collect();
    // Entries after the last step are valid (a longer run applies them) but do nothing here.
    let late: Vec<usize> = (0..script.inputs.len())
        .filter(|&i| script.inputs[i].step > last_step)
        .collect();
    if let (Some(&first), true) = (late.first(), role.root()) {
        let last_input = late
            .iter()
            .map(|&i| script.inputs[i].step)
            .max()
            .unwrap_or(last_step);
        let at = script.inputs[first].step;
        if late.len() == 1 {
            eprintln!(
                "warning: `{}`: 1 of its inputs (inputs[{first}] at step {at}) comes after the \
                 run's last step {last_step} and does not apply; give --steps {last_input} to \
                 apply it",
                script_origin.0,
            );
        } else {
            eprintln!(
                "warning: `{}`: {} of its inputs (the first: inputs[{first}] at step {at}) come \
                 after the run's last step {last_step} and do not apply; give --steps \
                 {last_input} to apply them",
                script_origin.0,
                late.len(),
            );
        }
    }
    let grid = scene.grid();
    // More worlds than cells is valid (a world may own no cell) but leaves worlds with
    // nothing to do: say so, and why the grid is this coarse.
    let advice = "the cell edge, in metres, follows the largest body and solver.max_speed x dt: \
                  a smaller solver.max_speed gives more, smaller cells";
    if let Some(warning) = soda::app::worlds_beyond_cells_warning(&options, &grid, advice) {
        if role.root() {
            eprintln!("{warning}");
        }
    }
    // The bodies at the first step: the scene's inside the grid, or the checkpoint's.
    let mut initial: Vec<Body> = match &from {
        Some(f) => f.bodies.clone(),
        None => {
            let all = scene.initial_bodies();
            let count = all.len();
            let inside: Vec<Body> = all
                .into_iter()
                .filter(|b| {
                    grid.cell_of(<RigidBodyModel as soda::CellModel>::position(b))
                        .is_some()
                })
                .collect();
            events_before.left_domain += count - inside.len();
            inside
        }
    };
    initial.sort_by_key(|b| b.id());
    // What --territories draws the initial partition from: the bodies the run starts with.
    let start = RunStart {
        step: first_step,
        positions: match &output.territories {
            Some(_) => initial
                .iter()
                .map(<RigidBodyModel as soda::CellModel>::position)
                .collect(),
            None => Vec::new(),
        },
    };
    let initial_bodies = match &from {
        Some(f) => f.bodies.len(),
        None => scene.bodies.len(),
    };
    // Before any temporary file exists: from here Ctrl-C stops at the next committed step
    // (or, pressed twice, at once), never leaving a temporary file behind.
    if let Err(e) = interrupt::install() {
        eprintln!("warning: Ctrl-C will not stop the run cleanly: {e}");
    }
    let (outputs, checkpoint_path) = Outputs::plan(
        output,
        [scene_file.as_deref(), script_origin.1.as_deref()],
        checkpoint.as_ref().map(|c| c.0.as_path()),
        last_step,
    )?;
    let Outputs {
        mut record,
        counters,
        trace,
        csv,
        territories,
    } = outputs;
    let mut checkpoints = match (checkpoint_path, &checkpoint) {
        (Some(path), Some((_, every))) => Some(CheckpointWriter::new(
            path,
            RunDescription {
                scene: source,
                // What a resume runs on; tracing is this run's output option, not the run's.
                options: RunOptions {
                    kernel: soda::kernel::KernelConfig {
                        trace: false,
                        ..options.kernel.clone()
                    },
                    ..options.clone()
                },
                last_step,
                checkpoint_every: *every,
                events: events_before,
                inputs: script.clone(),
            },
        )),
        _ => None,
    };
    let mut wanted = StatesWanted::none();
    if let Some(r) = record.as_mut() {
        let estimate =
            super::record::estimated_bytes(initial.len() as u64, steps, output.record_every);
        if let Some(path) = &output.record {
            super::record::warn_if_large(path, estimate);
        }
        r.frame_always(first_step, &initial.iter().collect::<Vec<_>>());
        wanted = r.wanted();
    }
    if let Some(c) = &checkpoints {
        // States of the steps either output wants: every step that is a multiple of
        // both periods' greatest common divisor (each output picks its own steps).
        wanted.every = gcd(wanted.every, c.every());
        wanted.step = Some(last_step);
    }
    let progress = progress_bar(output.json || !role.root(), steps, initial.len());
    let from = from.map(|f| ResumeFrom {
        step: f.step,
        bodies: initial,
    });
    let mut checkpoint_error: Option<anyhow::Error> = None;
    let report = run_scene_from(
        &scene,
        &options,
        from,
        steps,
        &wanted,
        inputs,
        |frame, states, _control| {
            if let (Some(r), Some(states)) = (record.as_mut(), states) {
                r.frame(frame.step, states);
            }
            if let Some(c) = checkpoints.as_mut() {
                if checkpoint_error.is_none() {
                    if let Err(e) = c.frame(frame, states) {
                        checkpoint_error = Some(e);
                    }
                }
            }
            progress.inc(1);
            if interrupt::requested() {
                progress.finish_and_clear();
                interrupted(
                    frame,
                    record.take(),
                    output.record.as_deref(),
                    checkpoints.as_ref(),
                );
            }
        },
    )
    .with_context(|| format!("the {} executor failed", options.executor.name()))?;
    progress.finish_and_clear();
    if !role.root() {
        return Ok(());
    }
    // From here on a failed write does not lose the run: the summary and hash are printed
    // first, then the errors.
    let mut failures: Vec<anyhow::Error> = Vec::new();
    if let Some(e) = checkpoint_error {
        let last = checkpoints
            .as_ref()
            .and_then(CheckpointWriter::last_written);
        failures.push(
            e.context(match last {
                Some(step) => format!(
                "--checkpoint: a checkpoint was not written (the last whole one is at step {step})"
            ),
                None => "--checkpoint: a checkpoint was not written (none was written before it)"
                    .to_string(),
            }),
        );
    }
    let recorded = match record.map(Recorder::finish) {
        Some(Ok((_, frames))) => Some(frames),
        Some(Err(e)) => {
            failures.push(e);
            None
        }
        None => None,
    };
    let mut report = report;
    report.speed_capped_events += events_before.speed_capped;
    report.left_domain_events += events_before.left_domain;
    // The report as JSON, formatted once for --json and --counters.
    let report_json = if output.json || counters.is_some() {
        let text = serde_json::to_string_pretty(&report).context("cannot format the report")?;
        text + "\n"
    } else {
        String::new()
    };
    if let Some(file) = counters {
        if let Err(e) = commit_text(file, &report_json) {
            failures.push(e.context("--counters: the report was not written"));
        }
    }
    if let Some(path) = &csv {
        if let Err(e) = super::table::append_run_row(path, &report, initial_bodies) {
            failures.push(e.context("--csv: the run's row was not added"));
        }
    }
    if let (Some(file), Some(t)) = (trace, &report.trace) {
        let written = serde_json::to_string(t)
            .context("cannot format the trace")
            .and_then(|text| commit_text(file, &(text + "\n")));
        if let Err(e) = written {
            failures.push(e.context("--trace: the trace was not written"));
        }
    }
    if let Some(dir) = &territories {
        if let Err(e) = write_territories(dir, &scene, &start, &options, &report) {
            failures.push(e.context("--territories: the maps were not all written"));
        }
    }
    if output.json {
        print(&report_json)?;
    } else {
        let recorded = recorded.and_then(|frames| {
            let path = output.record.as_ref()?;
            Some(format!(
                "{} to {}",
                counted(frames, "frame", "frames"),
                path.display()
            ))
        });
        let checkpointed = checkpoints.as_ref().and_then(|c| {
            let step = c.last_written()?;
            Some(format!("{} at step {step}", c.path().display()))
        });
        let resumed = resumed_from
            .as_ref()
            .map(|p| format!("from {} at step {first_step}", p.display()));
        print(&summary(
            &report,
            &origin,
            initial_bodies,
            Extras {
                recorded: recorded.as_deref(),
                checkpoint: checkpointed.as_deref(),
                resumed: resumed.as_deref(),
                first_step,
            },
        ))?;
    }
    write_failures(failures)
}

/// The greatest common divisor, with `gcd(0, n) = n`.
fn gcd(a: u64, b: u64) -> u64 {
    if b == 0 {
        a
    } else {
        gcd(b, a % b)
    }
}

/// Writes `text` to `file` and renames it into place.
fn commit_text(mut file: AtomicFile, text: &str) -> Result<()> {
    use std::io::Write;
    file.write_all(text.as_bytes())
        .context("cannot write the temporary file")?;
    file.commit()
}

/// `Ok` if nothing failed; otherwise one error saying the run itself finished (its summary
/// and hash are above) and listing every output that was not written.
fn write_failures(mut failures: Vec<anyhow::Error>) -> Result<()> {
    match failures.len() {
        0 => Ok(()),
        1 => Err(failures.remove(0).context(
            "the run finished (its summary and hash are above), but an output was not written",
        )),
        n => {
            let list: Vec<String> = failures.iter().map(|e| format!("- {e:#}")).collect();
            bail!(
                "the run finished (its summary and hash are above), but {n} outputs were not \
                 written:\n{}",
                list.join("\n")
            )
        }
    }
}

/// Ctrl-C (or SIGTERM) reached the run after committing `frame`: rename the recording into
/// place (whole frames up to the last one recorded), discard every other output, print the
/// step and hash reached and exit with 130 (143 for SIGTERM).
fn interrupted(
    frame: &Frame<soda::EventKind>,
    record: Option<Recorder>,
    path: Option<&std::path::Path>,
    checkpoints: Option<&CheckpointWriter>,
) -> ! {
    let mut note = format!(
        "interrupted at step {}, hash {}",
        frame.step,
        soda::hash::hex(frame.hash)
    );
    if let Some(c) = checkpoints {
        note += &match c.last_written() {
            Some(step) => format!(
                "; `soda resume {}` continues from step {step}",
                c.path().display()
            ),
            None => "; no checkpoint was written yet".to_string(),
        };
    }
    if let (Some(r), Some(path)) = (record, path) {
        let last = r.last_recorded();
        match r.finish() {
            Ok((_, frames)) => {
                note += &format!(
                    "; {} holds {frames} whole frames (up to step {})",
                    path.display(),
                    last.map_or("none".into(), |s| s.to_string())
                )
            }
            Err(e) => note += &format!("; the recording was not written: {e:#}"),
        }
    }
    atomic::discard_all();
    eprintln!("{note}; no other output written");
    std::process::exit(i32::from(interrupt::exit_status()))
}

/// Where a run started: its first step and its bodies' positions then (the scene's, or a
/// resumed run's checkpoint's), which its initial partition was built from.
struct RunStart {
    step: u64,
    positions: Vec<[f32; 3]>,
}

/// Writes the territory map of the initial partition (at the run's first step) and after
/// every balancing round, and the imbalance per round, into `dir`.
fn write_territories(
    dir: &std::path::Path,
    scene: &soda::Scene,
    start: &RunStart,
    options: &soda::sim::RunOptions,
    report: &RunReport,
) -> Result<()> {
    use soda::kernel::{Partition, RunTrace, WorldTrace};
    let Some(k) = &report.kernel else {
        return Ok(());
    };
    let grid = scene.grid();
    let initial = Partition::build(
        &options.kernel.partition,
        &grid,
        k.worlds,
        &start.positions,
        options.kernel.partition_seed,
    );
    let maps = std::iter::once((start.step, initial.owners().to_vec()))
        .chain(k.balance_rounds.iter().map(|r| (r.step, r.owners.clone())));
    let mut written = 0;
    for (step, owners) in maps {
        let parts = vec![WorldTrace::default(); k.worlds];
        let trace = RunTrace::merge(grid.dims, owners, parts, Vec::new());
        let path = dir.join(format!("territory-{step:06}.svg"));
        soda::app::charts::territory_map(&trace, &path)?;
        written += 1;
    }
    let series = vec![(
        "max / mean load".to_string(),
        k.balance_rounds
            .iter()
            .map(|r| (r.step as f64, r.imbalance))
            .collect::<Vec<_>>(),
    )];
    let imbalance = dir.join("imbalance.svg");
    soda::app::charts::line_chart(
        &imbalance,
        "Load imbalance at each balancing round",
        ("committed step", "max / mean load per step"),
        &series,
    )?;
    eprintln!(
        "wrote {written} territory maps and {} to {}",
        imbalance.display(),
        dir.display()
    );
    Ok(())
}

/// A progress bar on stderr when stderr is a terminal, the output is not JSON and the run is
/// long enough to be worth one; otherwise a hidden bar.
fn progress_bar(json: bool, steps: u64, bodies: usize) -> ProgressBar {
    let work = steps.saturating_mul(bodies.max(1) as u64);
    if json || work < 200_000 || !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::with_draw_target(Some(steps), ProgressDrawTarget::stderr());
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

/// What the summary says besides the report.
struct Extras<'a> {
    /// Frames recorded and where.
    recorded: Option<&'a str>,
    /// The last checkpoint written and where.
    checkpoint: Option<&'a str>,
    /// The checkpoint the run resumed from.
    resumed: Option<&'a str>,
    /// The step the run started at (0 unless resumed).
    first_step: u64,
}

/// The human summary. Its last line is `hash <16 hex digits>`.
fn summary(r: &RunReport, origin: &Origin, initial_bodies: usize, extras: Extras<'_>) -> String {
    let start = if extras.first_step == 0 {
        "at the start".to_string()
    } else {
        format!("at step {}", extras.first_step)
    };
    let steps = if extras.first_step == 0 {
        format!("{}", r.steps)
    } else if r.steps == 0 {
        format!("none after step {}", extras.first_step)
    } else {
        format!(
            "{} to {}",
            extras.first_step + 1,
            extras.first_step + r.steps
        )
    };
    let mut lines = vec![
        ("scene", format!("{} ({origin})", r.scene)),
        (
            "bodies",
            format!("{initial_bodies} {start}, {} at the end", r.last.bodies),
        ),
        (
            "steps",
            format!(
                "{steps} of {} s = {} simulated s ({} executor)",
                num(r.dt as f64),
                num(r.steps as f64 * r.dt as f64),
                r.executor
            ),
        ),
        (
            "grid",
            format!(
                "cell edge {} m, {} x {} x {} {}",
                num(r.cell_edge as f64),
                r.grid[0],
                r.grid[1],
                r.grid[2],
                if r.grid.iter().all(|&n| n == 1) {
                    "cell"
                } else {
                    "cells"
                }
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
    if let Some(k) = &r.kernel {
        let c = &k.counters.total;
        lines.push((
            "worlds",
            format!(
                "{} ({} partition), mode {}, window {}, {} thread{}{}",
                k.worlds,
                k.partition.name(),
                k.mode.name(),
                k.window_spec(),
                k.threads,
                if k.threads == 1 { "" } else { "s" },
                k.mpi.as_ref().map_or(String::new(), |m| format!(
                    " per rank, {}",
                    counted(m.ranks, "rank", "ranks")
                ))
            ),
        ));
        lines.push((
            "efficiency",
            format!(
                "{:.4} ({} of {} cell computations committed)",
                k.efficiency, c.cells_committed, c.cells_computed
            ),
        ));
        lines.push((
            "rollbacks",
            format!(
                "{} ({} primary, {} secondary), {} rolled back, {} recomputed",
                c.rollbacks(),
                c.rollbacks_primary,
                c.rollbacks_secondary,
                counted(c.steps_rolled_back, "step", "steps"),
                counted(c.cells_recomputed, "cell", "cells")
            ),
        ));
        lines.push((
            "messages",
            format!(
                "{} sent ({} ghost, {} migrate, {} null), {}",
                c.messages_sent,
                c.ghosts_sent,
                c.migrates_sent,
                c.null_messages_sent,
                counted(c.anti_messages_sent, "anti-message", "anti-messages")
            ),
        ));
        lines.push((
            "gvt",
            format!(
                "{}, peak log {}",
                counted(k.counters.gvt_advances, "advance", "advances"),
                counted(c.peak_log_bytes, "byte", "bytes")
            ),
        ));
        if k.balance.enabled {
            let b = &k.counters.balance;
            lines.push((
                "balancing",
                format!(
                    "{}, {} moved, {}, imbalance {:.3} (max/mean load)",
                    counted(b.rounds, "round", "rounds"),
                    counted(b.cells_moved, "cell", "cells"),
                    counted(b.famines, "famine", "famines"),
                    b.imbalance
                ),
            ));
        }
        if let Some(t) = &k.thread_times {
            lines.push((
                "thread time",
                format!(
                    "busy {} s (of which {} s computing ahead), gvt {} s, idle {} s (summed over threads), {}, {}",
                    num(t.busy_seconds),
                    num(t.ahead_seconds),
                    num(t.gvt_seconds),
                    num(t.idle_seconds),
                    counted(t.steals, "steal", "steals"),
                    counted(t.moves, "move", "moves")
                ),
            ));
        }
    }
    if let Some(resumed) = extras.resumed {
        lines.push(("resumed", resumed.to_string()));
    }
    if let Some(rec) = extras.recorded {
        lines.push(("recorded", rec.to_string()));
    }
    if let Some(c) = extras.checkpoint {
        lines.push(("checkpoint", c.to_string()));
    }
    lines.push(("hash", r.hash.clone()));
    lines
        .iter()
        .map(|(k, v)| format!("{k:<16} {v}\n"))
        .collect()
}
