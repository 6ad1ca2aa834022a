//! The commands every registered model gets: run, verify, and the rollback-granularity
//! experiment. They print to stdout and return `anyhow` errors naming the fix.

use super::output::counted;
use super::registry::{ModelSize, RegisteredModel};
use crate::exec::virtual_exec::ScheduleSpec;
use crate::kernel::{KernelConfig, RollbackMode};
use crate::sim::{ModelReport, RunOptions};
use crate::verify::{RunOutcome, VerifyOptions};
use anyhow::{bail, Result};
use std::path::Path;

/// `run --model NAME`: runs the model and prints a summary ending with its hash (or the
/// report as JSON).
pub fn run(
    model: &dyn RegisteredModel,
    size: &ModelSize,
    options: &RunOptions,
    steps: u64,
    json: bool,
    trace: Option<&Path>,
    checkpoint: Option<&super::checkpoint::CheckpointPlan>,
) -> Result<ModelReport> {
    if trace.is_some() && options.executor == crate::sim::ExecutorKind::Reference {
        return Err(super::usage(
            "--trace records the Time Warp worlds, and the reference executor has none: add \
             --executor virtual or --executor threaded",
        ));
    }
    // Every output checked before the run, not after it: its directory, a regular file (not
    // a FIFO, a device or a directory, which renaming into place would replace), and no two
    // outputs naming one file (a trace written over the checkpoint destroyed it).
    let mut plan = super::plan::OutputPlan::new();
    if let Some(c) = checkpoint {
        plan.file("--checkpoint", &c.path)?;
    }
    let trace = match trace {
        Some(path) => Some(plan.file("--trace", path)?),
        None => None,
    };
    let trace = trace.as_deref();
    let mut options = options.clone();
    options.kernel.trace = trace.is_some();
    if let Err(e) = super::interrupt::install() {
        eprintln!("warning: Ctrl-C will not stop the run cleanly: {e}");
    }
    // An MPI run: every rank runs this, only rank 0 writes and prints.
    let (_session, root) = mpi_role(options.executor == crate::sim::ExecutorKind::Mpi)?;
    let checkpoint = checkpoint.filter(|_| root);
    let (report, written) = model.run_from(size, &options, None, steps, checkpoint)?;
    if !root {
        return Ok(report);
    }
    interrupted(&report, checkpoint.map(|c| c.path.as_path()), written);
    let notes: Vec<String> = match (checkpoint, written) {
        (Some(plan), Some(step)) => vec![format!(
            "checkpoint       {} at step {step}",
            plan.path.display()
        )],
        _ => Vec::new(),
    };
    // The summary and hash first: a trace that cannot be written (a full disk) does not
    // lose them.
    print_report(model, &report, json, &notes)?;
    if let (Some(path), Some(t)) = (trace, &report.trace) {
        super::atomic::write(path, serde_json::to_string(t)?.as_bytes())?;
        eprintln!(
            "wrote the trace to {} (draw it with `{} plot {}`)",
            path.display(),
            program(),
            path.display()
        );
    }
    Ok(report)
}

/// A run stopped by Ctrl-C or SIGTERM (`report.stopped_at`): discards the temporary output
/// files, prints where it stopped, the hash there and the checkpoint to resume from, and
/// exits with 130 (143 for SIGTERM). Returns if the run was not interrupted.
pub fn interrupted(
    report: &ModelReport,
    checkpoint: Option<&Path>,
    written: Option<crate::model::Step>,
) {
    let Some(step) = report.stopped_at else {
        return;
    };
    super::atomic::discard_all();
    let resume = match (checkpoint, written) {
        (Some(path), Some(at)) => {
            format!(
                "; `{} resume {}` continues from step {at}",
                program(),
                path.display()
            )
        }
        (Some(_), None) => "; no checkpoint was written yet".to_string(),
        _ => String::new(),
    };
    eprintln!(
        "interrupted at step {step}, hash {}{resume}; no other output written",
        report.hash
    );
    std::process::exit(i32::from(super::interrupt::exit_status()));
}

/// Prints a run's report: JSON, or the summary ending with the `hash` line (`notes`, such
/// as where a checkpoint was written, go just before it).
pub fn print_report(
    model: &dyn RegisteredModel,
    report: &ModelReport,
    json: bool,
    notes: &[String],
) -> Result<()> {
    if json {
        crate::app::output::print_line(format_args!("{}", serde_json::to_string_pretty(&report)?))?;
        return Ok(());
    }
    crate::app::output::print_line(format_args!(
        "model            {} ({})",
        model.name(),
        model.about()
    ))?;
    crate::app::output::print_line(format_args!(
        "executor         {}{}",
        report.executor,
        report.kernel.as_ref().map_or(String::new(), |k| format!(
            ", {}, {}, mode {}, window {}",
            counted(k.worlds, "world", "worlds"),
            counted(k.threads, "thread", "threads"),
            k.mode.name(),
            k.window_spec()
        ))
    ))?;
    crate::app::output::print_line(format_args!(
        "steps            {}  ({:.3} s, {:.0} steps/s, {:.0} entity-steps/s)",
        report.steps, report.wall_seconds, report.steps_per_second, report.entity_steps_per_second
    ))?;
    crate::app::output::print_line(format_args!("entities         {}", report.entities))?;
    let events: Vec<String> = report
        .events
        .iter()
        .map(|(k, v)| format!("{k} {v}"))
        .collect();
    crate::app::output::print_line(format_args!(
        "events           {}",
        if events.is_empty() {
            "none".to_string()
        } else {
            events.join(", ")
        }
    ))?;
    if let Some(k) = &report.kernel {
        crate::app::output::print_line(format_args!(
            "kernel           {}, efficiency {:.3}, {} re-executed, {}",
            counted(k.counters.total.rollbacks(), "rollback", "rollbacks"),
            k.efficiency,
            counted(k.counters.total.cells_recomputed, "cell", "cells"),
            counted(
                k.counters.total.messages_sent + k.counters.total.anti_messages_sent,
                "message",
                "messages"
            )
        ))?;
    }
    for note in notes {
        crate::app::output::print_line(format_args!("{note}"))?;
    }
    crate::app::output::print_line(format_args!("hash             {}", report.hash))?;
    Ok(())
}

/// `verify --model NAME`: every check of `options`, one line per run, the diagnosis; an
/// error if anything diverged or the model broke its contract.
pub fn verify(
    model: &dyn RegisteredModel,
    size: &ModelSize,
    options: &VerifyOptions,
) -> Result<()> {
    // MPI runs: every rank runs this, only rank 0 checks and prints.
    let (_session, root) = mpi_role(options.mpi_repeats > 0)?;
    if !root {
        model.verify(size, options, &mut |_| {});
        return Ok(());
    }
    crate::app::output::print_line(format_args!(
        "verify           {} ({}), {}, {}, window {}, {}",
        model.name(),
        model.about(),
        counted(options.steps, "step", "steps"),
        counted(options.kernel.worlds, "world", "worlds"),
        options.kernel.window,
        counted(options.threads, "thread", "threads")
    ))?;
    // Each check is printed as it finishes; the first write that fails (a closed pipe) is
    // kept, the rest skipped, and it ends the command once the runs are done.
    let mut unwritten: Option<anyhow::Error> = None;
    let report = model.verify(size, options, &mut |check| {
        if unwritten.is_some() {
            return;
        }
        let mut written = crate::app::output::print_line(format_args!("{check}"));
        if let (Ok(()), RunOutcome::Diverged(_), Some(replay)) =
            (&written, &check.outcome, &check.replay)
        {
            written =
                crate::app::output::print_line(format_args!("         replay schedule: {replay}"));
        }
        unwritten = written.err();
    });
    if let Some(e) = unwritten {
        return Err(e);
    }
    crate::app::output::print_line(format_args!(
        "reference        hash {}",
        report.reference_hash()
    ))?;
    let diagnosis = report.diagnosis();
    for d in &diagnosis {
        crate::app::output::print_line(format_args!("diagnosis: {d}"))?;
    }
    if !report.passed() {
        bail!(
            "{} of {} diverged or the model broke its contract (see above)",
            report.failures().count(),
            counted(report.runs.len(), "run", "runs")
        );
    }
    crate::app::output::print_line(format_args!(
        "{} the reference's {}",
        match report.runs.len() {
            1 => "the 1 run committed".to_string(),
            n => format!("all {n} runs committed"),
        },
        counted(options.steps, "hash", "hashes")
    ))?;
    Ok(())
}

/// `experiment granularity --model NAME`: cell against world rollback (and conservative as
/// the baseline) on the virtual executor under seeded schedules, per optimism window: the
/// cell-steps each re-executes and the efficiency, averaged over `seeds` schedules. Prints a
/// CSV table.
pub fn granularity(
    model: &dyn RegisteredModel,
    size: &ModelSize,
    kernel: &KernelConfig,
    windows: &[u64],
    seeds: u64,
    steps: u64,
) -> Result<()> {
    if windows.is_empty() || seeds == 0 {
        return Err(super::usage(
            "give at least one window (--windows 4,16) and one schedule (--seeds 1 or more)",
        ));
    }
    crate::app::output::print_line(format_args!(
        "model,mode,window,seeds,steps,cells_computed,cells_recomputed,rollbacks,efficiency,hash"
    ))?;
    for &window in windows {
        for mode in [
            RollbackMode::Cell,
            RollbackMode::World,
            RollbackMode::Conservative,
        ] {
            let (mut computed, mut recomputed, mut rollbacks, mut eff) = (0u64, 0u64, 0u64, 0.0);
            let mut hash = String::new();
            for seed in 0..seeds {
                let options = RunOptions::virtual_exec(kernel.clone().mode(mode).window(window))
                    .schedule(ScheduleSpec::Seeded(seed))
                    .record_schedule(false);
                let r = model.run(size, &options, steps)?;
                let k = r.kernel.expect("a virtual run has kernel counters");
                computed += k.counters.total.cells_computed;
                recomputed += k.counters.total.cells_recomputed;
                rollbacks += k.counters.total.rollbacks();
                eff += k.efficiency;
                hash = r.hash;
            }
            let n = seeds as f64;
            crate::app::output::print_line(format_args!(
                "{},{},{window},{seeds},{steps},{:.1},{:.1},{:.1},{:.4},{hash}",
                model.name(),
                mode.name(),
                computed as f64 / n,
                recomputed as f64 / n,
                rollbacks as f64 / n,
                eff / n
            ))?;
        }
    }
    Ok(())
}

/// Reads a trace written by `run --trace` and checks it ([`crate::kernel::RunTrace::check`]):
/// a file that is not one, or an edited one, is an error naming the file (and the field).
pub fn read_trace(path: &Path) -> Result<crate::kernel::RunTrace> {
    use anyhow::Context;
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read the trace {}", path.display()))?;
    let not_a_trace = || {
        format!(
            "{} is not a trace written by `soda run --trace` (or a model binary's `run --trace`)",
            path.display()
        )
    };
    let trace: crate::kernel::RunTrace = serde_json::from_str(&text).with_context(not_a_trace)?;
    trace.check().with_context(not_a_trace)?;
    Ok(trace)
}

/// `plot TRACE --out DIR`: the space-time diagram, the territory map and the rollback heat
/// map of a trace written by `run --trace` (any model), as SVG files.
pub fn plot(trace: &Path, out: &Path) -> Result<()> {
    use anyhow::Context;
    let t = read_trace(trace)?;
    std::fs::create_dir_all(out)
        .with_context(|| format!("cannot create the directory {}", out.display()))?;
    for (name, draw) in [
        (
            "spacetime.svg",
            super::charts::space_time as fn(&_, &Path) -> Result<()>,
        ),
        ("territory.svg", super::charts::territory_map),
        ("heatmap.svg", super::charts::rollback_heat_map),
    ] {
        let path = out.join(name);
        draw(&t, &path)?;
        crate::app::output::print_line(format_args!("wrote {}", path.display()))?;
    }
    Ok(())
}

/// This process's MPI session (held for the command) and whether it is the one that prints:
/// under `mpirun` (`mpi`) rank 0 only; otherwise always. Without the `mpi` feature there is
/// no session, and the MPI runs themselves fail saying how to build it.
#[cfg(feature = "mpi")]
fn mpi_role(mpi: bool) -> Result<(Option<crate::exec::mpi::Session>, bool)> {
    if !mpi {
        return Ok((None, true));
    }
    let session = crate::exec::mpi::Session::init()?;
    let root = session.is_root();
    Ok((Some(session), root))
}

/// Without the `mpi` feature: no session, and this process prints.
#[cfg(not(feature = "mpi"))]
fn mpi_role(_mpi: bool) -> Result<(Option<()>, bool)> {
    Ok((None, true))
}

/// The name this program was started by (`soda`, or a model binary's), for the commands
/// its messages suggest.
fn program() -> String {
    std::env::args_os()
        .next()
        .as_deref()
        .map(std::path::Path::new)
        .and_then(std::path::Path::file_name)
        .map_or_else(|| "soda".to_string(), |n| n.to_string_lossy().into_owned())
}
