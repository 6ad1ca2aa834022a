//! `soda experiment NAME`: the thesis's §4.2 experiments as commands. Each writes
//! `DIR/NAME.csv` (one row per run: the run's configuration, wall time, hash and every
//! counter, plus the experiment's own columns) and `DIR/NAME.svg` (a chart), with a progress
//! bar. `--quick` runs a small version in well under a minute (used by the tests).

mod cluster;
mod peak;
mod peak_display;

use super::table::{csv_line, run_row};
use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use soda::app::charts;
use soda::app::output::counted;
use soda::exec::reference::ReferenceRun;
use soda::exec::virtual_exec::ScheduleSpec;
use soda::frame::StatesWanted;
use soda::kernel::trace::RunTrace;
use soda::kernel::{KernelConfig, Partition, PartitionKind, RollbackMode};
use soda::scaling;
use soda::scene::builtin::builtin;
use soda::scene::Scene;
use soda::sim::{run_scene, ExecutorKind, RunOptions, RunReport};
use std::path::{Path, PathBuf};

/// Examples shown after `soda experiment --help`.
pub const AFTER_HELP: &str = "\
Examples:
  soda experiment rp-efficiency --quick --out results
  soda experiment scalability --out results     results/scalability.csv and .svg
  soda experiment sync-share
  soda experiment peak-resistance --out results  also peak-resistance-gaps.svg and -cost.csv/.svg
  soda experiment raw-performance
  soda experiment peak-display --quick           the peak with a display draining the buffer
  soda experiment cluster-model                  a MODEL of 16-256 MPI ranks on a cluster";

/// The experiments.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ExperimentName {
    /// Speed-up of the threaded executor over the reference for 1..cores threads and
    /// several world counts (falling-cubes).
    Scalability,
    /// The largest number of falling cubes simulated at 24 committed steps per wall-clock
    /// second over the first 120 steps (2 simulated seconds: the fall and the first
    /// landings), per executor.
    RawPerformance,
    /// Share of thread time spent computing, rolling back, exchanging messages, in GVT and
    /// idle, per rollback mode (threaded executor).
    SyncShare,
    /// Fraction of a territory's cell-steps recomputed per rollback, cell against world
    /// against conservative, on a sparse and a dense scene (virtual executor, seeded
    /// schedules).
    RpEfficiency,
    /// A computational peak (a block of cubes landing on one quadrant of the `peak` scene),
    /// costed as collisions during it over collisions before, against the optimism window
    /// (threaded executor, W = 1..64): wall time, gaps between committed frames, rollbacks.
    PeakResistance,
    /// The same peak with a display in the loop, as `soda view` shows a run: committed
    /// frames drained at 24 and 60 frames per second from a buffer of B frames (filled
    /// before playing); per window and buffer, whether the display starves during the peak.
    PeakDisplay,
    /// A MODEL of the MPI executor on 16, 64 and 256 ranks of a cluster (InfiniBand and
    /// 10 GbE), from cell costs, occupancy and wire costs measured here on falling-cubes and
    /// sparse-gas at several sizes: predicted speed-up, bytes per step, and the size from which it pays.
    ClusterModel,
}

impl ExperimentName {
    fn file_stem(self) -> &'static str {
        match self {
            Self::Scalability => "scalability",
            Self::RawPerformance => "raw-performance",
            Self::SyncShare => "sync-share",
            Self::RpEfficiency => "rp-efficiency",
            Self::PeakResistance => "peak-resistance",
            Self::PeakDisplay => "peak-display",
            Self::ClusterModel => "cluster-model",
        }
    }
}

/// Options of `soda experiment`.
#[derive(Debug, Args)]
pub struct ExperimentArgs {
    /// Which experiment.
    #[arg(value_enum)]
    pub name: ExperimentName,
    /// A small version (well under a minute).
    #[arg(long)]
    pub quick: bool,
    /// Directory for the CSV and the chart (created if missing).
    #[arg(long, value_name = "DIR", default_value = "results")]
    pub out: PathBuf,
}

/// One run of an experiment and its extra columns.
struct Row {
    report: RunReport,
    bodies: usize,
    extra: Vec<(String, String)>,
}

/// Runs the command.
pub fn experiment(args: &ExperimentArgs) -> Result<()> {
    let mut plan = soda::app::plan::OutputPlan::new();
    plan.dir("--out", &args.out)?;
    let stem = args.name.file_stem();
    let csv = args.out.join(format!("{stem}.csv"));
    let svg = args.out.join(format!("{stem}.svg"));
    // Every file the experiment writes into --out, checked before it runs (a directory in
    // the way of one failed the rename after the whole experiment).
    let extra: &[&str] = match args.name {
        ExperimentName::Scalability => &["scalability-model.csv", "scalability-model.svg"],
        ExperimentName::PeakResistance => &[
            "peak-resistance-cost.csv",
            "peak-resistance-cost.svg",
            "peak-resistance-model.csv",
            "peak-resistance-gaps.svg",
        ],
        _ => &[],
    };
    for path in [csv.clone(), svg.clone()]
        .into_iter()
        .chain(extra.iter().map(|name| args.out.join(name)))
    {
        plan.file("--out", &path)?;
    }
    let rows = match args.name {
        ExperimentName::Scalability => scalability(args.quick, &svg)?,
        ExperimentName::RawPerformance => raw_performance(args.quick, &svg)?,
        ExperimentName::SyncShare => sync_share(args.quick, &svg)?,
        ExperimentName::RpEfficiency => rp_efficiency(args.quick, &svg)?,
        ExperimentName::PeakResistance => peak::peak_resistance(args.quick, &svg)?,
        ExperimentName::PeakDisplay => peak_display::peak_display(args.quick, &svg)?,
        // A model, not runs: it writes its own table.
        ExperimentName::ClusterModel => return cluster::cluster_model(args.quick, &csv, &svg),
    };
    write_csv(&csv, &rows)?;
    super::output::print_line(format_args!("wrote {}", csv.display()))?;
    super::output::print_line(format_args!("wrote {}", svg.display()))?;
    Ok(())
}

fn write_csv(path: &Path, rows: &[Row]) -> Result<()> {
    let mut text = String::new();
    for (i, r) in rows.iter().enumerate() {
        let mut cols = run_row(&r.report, r.bodies);
        cols.extend(r.extra.iter().cloned());
        if i == 0 {
            text.push_str(&csv_line(cols.iter().map(|c| &c.0)));
        }
        text.push_str(&csv_line(cols.iter().map(|c| &c.1)));
    }
    soda::app::atomic::write(path, text.as_bytes())
}

fn scene(name: &str, bodies: usize, seed: u64) -> Result<Scene> {
    builtin(name, Some(bodies), seed).map_err(|e| anyhow::anyhow!("{e}"))
}

fn run(scene: &Scene, options: &RunOptions, steps: u64) -> Result<RunReport> {
    run_scene(scene, options, steps, &StatesWanted::none(), |_, _| {})
        .with_context(|| format!("the {} executor failed", options.executor.name()))
}

fn reference() -> RunOptions {
    RunOptions::default()
}

fn threaded(worlds: usize, threads: usize, mode: RollbackMode) -> RunOptions {
    RunOptions {
        executor: ExecutorKind::Threaded,
        kernel: KernelConfig::new(worlds).mode(mode),
        threads,
        ..RunOptions::default()
    }
}

fn cores() -> usize {
    std::thread::available_parallelism().map_or(2, |n| n.get())
}

fn f(x: f64) -> String {
    format!("{x:.6}")
}

/// Speed-up of the threaded executor over the reference.
fn scalability(quick: bool, svg: &Path) -> Result<Vec<Row>> {
    let (bodies, steps) = if quick { (300, 60) } else { (2000, 120) };
    let s = scene("falling-cubes", bodies, 0)?;
    let max_threads = cores().max(2);
    let world_factors = [1, 2, 4];
    let bar = super::output::runs_bar(1 + (max_threads * world_factors.len()) as u64);
    bar.set_message("reference");
    let base = run(&s, &reference(), steps)?;
    bar.inc(1);
    let mut rows = vec![Row {
        bodies,
        extra: vec![("speedup".into(), f(1.0))],
        report: base.clone(),
    }];
    let mut series = Vec::new();
    for factor in world_factors {
        let mut points = Vec::new();
        for threads in 1..=max_threads {
            let worlds = threads * factor;
            let what = format!(
                "{}, {}",
                counted(threads, "thread", "threads"),
                counted(worlds, "world", "worlds")
            );
            bar.set_message(what.clone());
            let r = run(&s, &threaded(worlds, threads, RollbackMode::Cell), steps)?;
            if r.hash != base.hash {
                bail!(
                    "threaded run ({what}) ended in {} but the reference in {}: a determinism \
                     bug; please report it",
                    r.hash,
                    base.hash
                );
            }
            let speedup = base.wall_seconds / r.wall_seconds;
            points.push((threads as f64, speedup));
            rows.push(Row {
                bodies,
                extra: vec![("speedup".into(), f(speedup))],
                report: r,
            });
            bar.inc(1);
        }
        series.push((format!("{factor} world(s) per thread"), points));
    }
    bar.set_message("cell costs for the model");
    model_scalability(&s, steps, &series[0].1, svg)?;
    bar.finish_and_clear();
    charts::line_chart(
        svg,
        &format!("Scalability: falling-cubes {bodies}, {steps} steps, cell mode (measured)"),
        ("threads", "speed-up over the reference"),
        &series,
    )?;
    Ok(rows)
}

/// The scalability model (`soda::scaling`) for P = 1..64 worlds on P workers, from the cell
/// costs of one timed reference run, next to the measured one-world-per-thread speed-ups.
/// Writes `scalability-model.csv` and `scalability-model.svg` beside `svg`.
fn model_scalability(s: &Scene, steps: u64, measured: &[(f64, f64)], svg: &Path) -> Result<()> {
    let (mut run, _) = ReferenceRun::new(s.model(), s.grid(), s.initial_bodies());
    run.record_costs(true);
    for _ in 0..steps {
        run.advance();
    }
    let costs = run.take_costs();
    let grid = s.grid();
    let positions: Vec<[f32; 3]> = s.bodies.iter().map(|b| b.position).collect();
    let mut text = String::from(
        "worlds,sequential_seconds,bulk_synchronous_seconds,dataflow_seconds,\
         bulk_synchronous_speedup,dataflow_speedup,measured_speedup\n",
    );
    let (mut bsp, mut flow) = (Vec::new(), Vec::new());
    for p in [1usize, 2, 4, 8, 16, 32, 64] {
        let part = Partition::build(&PartitionKind::Blocks, &grid, p, &positions, 0);
        let pr = scaling::predict(&grid, &part, &costs, steps);
        let measured_here = measured
            .iter()
            .find(|m| m.0 as usize == p)
            .map_or(String::new(), |m| f(m.1));
        text.push_str(&format!(
            "{},{},{},{},{},{},{}\n",
            pr.worlds,
            f(pr.sequential_seconds),
            f(pr.bulk_synchronous_seconds),
            f(pr.dataflow_seconds),
            f(pr.bulk_synchronous_speedup()),
            f(pr.dataflow_speedup()),
            measured_here
        ));
        bsp.push((p as f64, pr.bulk_synchronous_speedup()));
        flow.push((p as f64, pr.dataflow_speedup()));
    }
    let csv = svg.with_file_name("scalability-model.csv");
    soda::app::atomic::write(&csv, text.as_bytes())?;
    let chart = svg.with_file_name("scalability-model.svg");
    charts::line_chart(
        &chart,
        &format!(
            "MODEL of P worlds on P workers (falling-cubes {}, blocks) and the measured runs",
            s.bodies.len()
        ),
        ("worlds = workers (P)", "speed-up over sequential"),
        &[
            ("model: bulk-synchronous (thesis)".into(), bsp),
            ("model: dataflow, zero overhead".into(), flow),
            ("measured: threaded".into(), measured.to_vec()),
        ],
    )?;
    super::output::print_line(format_args!("wrote {}", csv.display()))?;
    super::output::print_line(format_args!("wrote {}", chart.display()))?;
    Ok(())
}

/// Largest cube count at 24 committed steps per second, per executor.
fn raw_performance(quick: bool, svg: &Path) -> Result<Vec<Row>> {
    let (steps, start, rounds) = if quick { (6, 100, 3) } else { (120, 500, 6) };
    const TARGET: f64 = 24.0;
    let threads = cores().max(2);
    let executors = [
        ("reference".to_string(), reference()),
        (
            format!("threaded {threads}x{threads}"),
            threaded(threads, threads, RollbackMode::Cell),
        ),
    ];
    let bar = super::output::runs_bar((executors.len() * (rounds + 6)) as u64);
    let mut rows = Vec::new();
    let mut best = Vec::new();
    for (name, options) in &executors {
        let probe = |n: usize, rows: &mut Vec<Row>| -> Result<f64> {
            bar.set_message(format!("{name}: {n} cubes"));
            let r = run(&scene("falling-cubes", n, 0)?, options, steps)?;
            let rate = r.steps_per_second;
            rows.push(Row {
                bodies: n,
                extra: vec![
                    ("probe_executor".into(), name.clone()),
                    ("meets_24_fps".into(), (rate >= TARGET).to_string()),
                ],
                report: r,
            });
            bar.inc(1);
            Ok(rate)
        };
        // Grow until too slow, then bisect.
        let (mut lo, mut hi) = (0usize, start);
        for _ in 0..6 {
            if probe(hi, &mut rows)? >= TARGET {
                lo = hi;
                hi *= 2;
            } else {
                break;
            }
        }
        for _ in 0..rounds {
            let mid = (lo + hi) / 2;
            if mid == lo {
                break;
            }
            if probe(mid, &mut rows)? >= TARGET {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        best.push(lo as f64);
    }
    bar.finish_and_clear();
    let names: Vec<String> = executors.iter().map(|e| e.0.clone()).collect();
    charts::bar_chart(
        svg,
        &format!("Raw performance: most falling cubes at {TARGET} steps/s ({steps}-step runs)"),
        "cubes",
        &names,
        &[("largest cube count".into(), best)],
    )?;
    Ok(rows)
}

/// Thread time split per rollback mode.
fn sync_share(quick: bool, svg: &Path) -> Result<Vec<Row>> {
    let (bodies, steps) = if quick { (300, 60) } else { (2000, 120) };
    let s = scene("falling-cubes", bodies, 0)?;
    let threads = cores().max(2);
    let worlds = 2 * threads;
    let modes = [
        RollbackMode::Cell,
        RollbackMode::World,
        RollbackMode::Conservative,
    ];
    let bar = super::output::runs_bar(modes.len() as u64);
    let parts = ["compute", "rollback", "messages", "gvt", "idle"];
    let mut shares: Vec<Vec<f64>> = vec![Vec::new(); parts.len()];
    let mut rows = Vec::new();
    for mode in modes {
        bar.set_message(mode.name());
        let r = run(&s, &threaded(worlds, threads, mode), steps)?;
        let t = r
            .kernel
            .as_ref()
            .and_then(|k| k.thread_times.clone())
            .unwrap_or_default();
        let other = t.busy_seconds - t.compute_seconds - t.rollback_seconds - t.receive_seconds;
        let values = [
            t.compute_seconds + other.max(0.0),
            t.rollback_seconds,
            t.receive_seconds,
            t.gvt_seconds,
            t.idle_seconds,
        ];
        let total: f64 = values.iter().sum::<f64>().max(1e-12);
        let mut extra = Vec::new();
        for (k, v) in values.iter().enumerate() {
            shares[k].push(v / total);
            extra.push((format!("share_{}", parts[k]), f(v / total)));
        }
        rows.push(Row {
            bodies,
            extra,
            report: r,
        });
        bar.inc(1);
    }
    bar.finish_and_clear();
    let names: Vec<String> = modes.iter().map(|m| m.name().to_string()).collect();
    let series: Vec<(String, Vec<f64>)> = parts
        .iter()
        .zip(shares)
        .map(|(p, v)| (p.to_string(), v))
        .collect();
    charts::bar_chart(
        svg,
        &format!(
            "Share of thread time: falling-cubes {bodies}, {} on {}",
            counted(worlds, "world", "worlds"),
            counted(threads, "thread", "threads")
        ),
        "share of thread time",
        &names,
        &series,
    )?;
    Ok(rows)
}

/// Mean fraction of the territory's cell-steps recomputed per rollback.
fn territory_fraction(trace: &RunTrace) -> f64 {
    let mut size = vec![0u64; trace.worlds];
    for &w in &trace.owners {
        size[w as usize] += 1;
    }
    let fractions: Vec<f64> = trace
        .rollbacks
        .iter()
        .filter(|r| r.length > 0)
        .map(|r| r.cells_recomputed as f64 / (size[r.world as usize] * r.length).max(1) as f64)
        .collect();
    if fractions.is_empty() {
        0.0
    } else {
        fractions.iter().sum::<f64>() / fractions.len() as f64
    }
}

/// Fraction of a territory recomputed per rollback, per mode, sparse and dense.
fn rp_efficiency(quick: bool, svg: &Path) -> Result<Vec<Row>> {
    let (sparse_n, dense_n, steps, seeds) = if quick {
        (300, 200, 60, 1)
    } else {
        (1000, 1000, 120, 3)
    };
    let scenes = [
        scene("sparse-gas", sparse_n, 1)?,
        scene("falling-cubes", dense_n, 0)?,
    ];
    let modes = [
        RollbackMode::Cell,
        RollbackMode::World,
        RollbackMode::Conservative,
    ];
    let bar = super::output::runs_bar((scenes.len() * modes.len()) as u64 * seeds);
    let mut rows = Vec::new();
    let mut series: Vec<(String, Vec<f64>)> = modes
        .iter()
        .map(|m| (m.name().to_string(), Vec::new()))
        .collect();
    for s in &scenes {
        for (k, mode) in modes.iter().enumerate() {
            let mut sum = 0.0;
            for seed in 0..seeds {
                bar.set_message(format!("{} {} seed {seed}", s.name, mode.name()));
                let options = RunOptions::virtual_exec(
                    KernelConfig::new(8).mode(*mode).window(16).trace(true),
                )
                .schedule(ScheduleSpec::Seeded(seed))
                .record_schedule(false);
                let r = run(s, &options, steps)?;
                let fraction = r.trace.as_ref().map_or(0.0, territory_fraction);
                sum += fraction;
                rows.push(Row {
                    bodies: s.bodies.len(),
                    extra: vec![
                        ("schedule_seed".into(), seed.to_string()),
                        ("territory_fraction_per_rollback".into(), f(fraction)),
                    ],
                    report: r,
                });
                bar.inc(1);
            }
            series[k].1.push(sum / seeds as f64);
        }
    }
    bar.finish_and_clear();
    let names: Vec<String> = scenes
        .iter()
        .map(|s| format!("{} {}", s.name, s.bodies.len()))
        .collect();
    charts::bar_chart(
        svg,
        "Rollback-and-Propagate: share of a territory's cell-steps recomputed per rollback",
        "fraction of territory x rollback length",
        &names,
        &series,
    )?;
    Ok(rows)
}

/// The median of `v` (the mean of the middle two for an even count).
pub(super) fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    match n {
        0 => 0.0,
        _ if n % 2 == 1 => v[n / 2],
        _ => (v[n / 2 - 1] + v[n / 2]) / 2.0,
    }
}
