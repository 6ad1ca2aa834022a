//! `soda verify`: run the reference, the virtual executor under K schedule seeds and the
//! threaded executor several times, per rollback mode; compare every committed step's hash
//! with the reference's and, on a mismatch, report the first step, body, field and cell that
//! differ with the command that reproduces it. Exits non-zero on any divergence.

use super::exec_args::{default_threads, GhostsArg, ModeArg, PartitionArg, PlantedBugArg};
use super::numbers::whole;
use super::output::print;
use super::source::SceneArgs;
use anyhow::{bail, Context, Result};
use clap::Args;
use soda::divergence::{first_difference, Divergence};
use soda::frame::StatesWanted;
use soda::kernel::{KernelConfig, PartitionKind, PlantedBug, RollbackMode, ScheduleSpec};
use soda::scene::SceneFormat;
use soda::sim::{run_scene, ExecutorKind, RunOptions};
use soda::{Body, RigidBodyModel, Scene};
use std::path::Path;
use std::sync::Arc;

/// Examples shown after `soda verify --help`.
pub const AFTER_HELP: &str = "\
Examples:
  soda verify                                        125 falling cubes, 8 worlds, all modes
  soda verify --scene sparse-gas --worlds 16 --schedules 50
  soda verify --scene chain --modes cell,world --threads 4 --repeats 10

Every line names one run and whether each of its committed steps hashed like the
reference's. A divergence names the first step, body, field and cell that differ and
prints the `soda run` command that reproduces it (virtual runs replay exactly from their
schedule seed). The exit status is 1 if any run diverged.";

/// The help of `--objects` under `soda verify`, whose built-ins default to
/// [`VERIFY_OBJECTS`] bodies.
pub const OBJECTS_HELP: &str = "Number of bodies of a built-in scene [default: 125, small \
    enough for a quick check; `soda run` uses the scene's own]. Not allowed with a scene file.";

/// Options of `soda verify`.
#[derive(Debug, Args)]
pub struct VerifyArgs {
    #[command(flatten)]
    pub scene: SceneArgs,

    /// Committed steps to compare per run.
    #[arg(long, value_name = "N", default_value_t = 60, help_heading = "Run",
          value_parser = whole(1, u64::MAX))]
    pub steps: u64,

    /// Number of worlds.
    #[arg(long, value_name = "N", default_value_t = 8, help_heading = "Run",
          value_parser = whole(1, 4096))]
    pub worlds: u64,

    /// Threads of the threaded runs [default: the available cores].
    #[arg(long, value_name = "T", help_heading = "Run",
          value_parser = whole(1, 256))]
    pub threads: Option<u64>,

    /// Rollback modes to check: `all` or a comma-separated list of cell, world, conservative.
    #[arg(long, value_name = "LIST", default_value = "all", help_heading = "Run")]
    pub modes: String,

    /// Virtual-executor schedule seeds per mode (seeds FIRST..FIRST+K; `--schedules 0
    /// --repeats 0` is an error, nothing to check).
    #[arg(long, value_name = "K", default_value_t = 8, help_heading = "Run",
          value_parser = whole(0, u64::MAX))]
    pub schedules: u64,

    /// The first schedule seed (a long soak continues where the last one stopped).
    #[arg(long, value_name = "FIRST", default_value_t = 0, help_heading = "Run",
          value_parser = whole(0, u64::MAX))]
    pub first_schedule: u64,

    /// Threaded runs per mode.
    #[arg(long, value_name = "R", default_value_t = 3, help_heading = "Run",
          value_parser = whole(0, u64::MAX))]
    pub repeats: u64,

    /// Optimism window.
    #[arg(long, value_name = "W", default_value_t = 16, help_heading = "Run",
          value_parser = whole(1, 1_000_000))]
    pub window: u64,

    /// How cells are assigned to worlds.
    #[arg(long, value_enum, default_value = "blocks", help_heading = "Run")]
    pub partition: PartitionArg,

    /// Seed of the kmeans and random partitioners [default: 0]. With --partition kmeans or
    /// random only.
    #[arg(long, value_name = "S", help_heading = "Run", value_parser = whole(0, u64::MAX))]
    pub partition_seed: Option<u64>,

    /// Ghost policy of the optimistic modes (see `soda run --help`).
    #[arg(long, value_enum, default_value = "delta", help_heading = "Run")]
    pub ghosts: GhostsArg,

    /// A deliberate kernel bug, to show that verify catches it (never for real runs).
    #[arg(long, value_enum, hide = true)]
    pub planted_bug: Option<PlantedBugArg>,
}

/// The default body count of a built-in scene under `verify` (small enough for a minute).
const VERIFY_OBJECTS: usize = 125;

/// One executor run to compare with the reference.
struct Check {
    executor: ExecutorKind,
    mode: RollbackMode,
    seed: Option<u64>,
}

/// Runs the command.
pub fn verify(args: &VerifyArgs) -> Result<()> {
    let mut scene_args = args.scene.clone();
    let builtin = SceneFormat::from_path(Path::new(&scene_args.scene)).is_none();
    if builtin && scene_args.objects.is_none() {
        scene_args.objects = Some(VERIFY_OBJECTS);
    }
    let (scene, origin) = scene_args.load()?;
    let modes = parse_modes(&args.modes)?;
    if args.schedules == 0 && args.repeats == 0 {
        bail!(
            "--schedules 0 and --repeats 0 leave no run to check: give at least one schedule \
             (--schedules K) or threaded run (--repeats R)"
        );
    }
    if args.partition_seed.is_some() && args.partition == PartitionArg::Blocks {
        bail!(
            "--partition-seed seeds the kmeans and random partitioners, and blocks has \
             nothing random: add `--partition kmeans` or `--partition random`, or drop it"
        );
    }
    let threads = args.threads.map_or_else(default_threads, |t| t as usize);
    let mut checks = Vec::new();
    for &mode in &modes {
        let first = args.first_schedule;
        for seed in first..first.saturating_add(args.schedules) {
            checks.push(Check {
                executor: ExecutorKind::Virtual,
                mode,
                seed: Some(seed),
            });
        }
        for _ in 0..args.repeats {
            checks.push(Check {
                executor: ExecutorKind::Threaded,
                mode,
                seed: None,
            });
        }
    }
    let mut expected = Vec::with_capacity(args.steps as usize);
    let reference = run_scene(
        &scene,
        &RunOptions::default(),
        args.steps,
        &StatesWanted::none(),
        |f, _| expected.push(f.hash),
    )
    .context("the reference run failed")?;
    let expected = Arc::new(expected);
    let out = format!(
        "verify           {} ({origin}), {} steps, {} worlds ({} partition), window {}, {} thread{}\n\
         reference        hash {}\n",
        scene.name,
        args.steps,
        args.worlds,
        PartitionKind::from(args.partition).name(),
        args.window,
        threads,
        if threads == 1 { "" } else { "s" },
        reference.hash
    );
    print(&out)?;
    let progress = super::output::runs_bar(checks.len() as u64);
    let mut diverged = 0;
    for check in &checks {
        let line = run_check(args, &scene, &scene_args, check, threads, &expected);
        progress.inc(1);
        let text = match line {
            Ok(text) => text,
            Err(text) => {
                diverged += 1;
                text
            }
        };
        progress.suspend(|| print(&text))?;
    }
    progress.finish_and_clear();
    if diverged > 0 {
        bail!(
            "{diverged} of {} runs diverged from the reference (see the lines marked DIVERGED)",
            checks.len()
        );
    }
    print(&format!(
        "all {} runs committed the reference's {} hashes\n",
        checks.len(),
        args.steps
    ))
}

/// Runs one check: `Ok(line)` if every committed hash matched, `Err(report)` otherwise.
fn run_check(
    args: &VerifyArgs,
    scene: &Scene,
    scene_args: &SceneArgs,
    check: &Check,
    threads: usize,
    expected: &Arc<Vec<u64>>,
) -> std::result::Result<String, String> {
    let mut kernel = KernelConfig::new(args.worlds as usize)
        .mode(check.mode)
        .window(args.window)
        .partition(args.partition.into())
        .partition_seed(args.partition_seed.unwrap_or(0))
        .schedule(ScheduleSpec::Seeded(check.seed.unwrap_or(0)))
        .ghosts(args.ghosts.into())
        .record_schedule(false);
    kernel.planted_bug = args.planted_bug.map_or(PlantedBug::None, Into::into);
    let options = RunOptions {
        executor: check.executor,
        kernel,
        threads,
    };
    let wanted = StatesWanted {
        unexpected: Some(expected.clone()),
        ..StatesWanted::none()
    };
    let mut first_bad: Option<(u64, Vec<Body>)> = None;
    let mut committed = 0u64;
    let name = match check.seed {
        Some(seed) => format!(
            "{:<9}{:<13} schedule-seed {seed}",
            check.executor.name(),
            check.mode.name()
        ),
        None => format!(
            "{:<9}{:<13} {threads} threads",
            check.executor.name(),
            check.mode.name()
        ),
    };
    let result = run_scene(scene, &options, args.steps, &wanted, |f, states| {
        committed += 1;
        if first_bad.is_none() && expected.get(f.step as usize - 1) != Some(&f.hash) {
            let bodies = states.map(|s| s.iter().map(|b| (*b).clone()).collect());
            first_bad = Some((f.step, bodies.unwrap_or_default()));
        }
    });
    let report = match result {
        Ok(r) => r,
        Err(e) => return Err(format!("DIVERGED {name}: the run failed: {e}\n")),
    };
    let Some((step, bodies)) = first_bad else {
        let k = report.kernel.as_ref().map(|k| {
            format!(
                ", {} rollbacks, efficiency {:.3}",
                k.counters.total.rollbacks(),
                k.efficiency
            )
        });
        return Ok(format!(
            "ok       {name}: {committed} steps match{}\n",
            k.unwrap_or_default()
        ));
    };
    let divergence = locate(scene, step, &bodies);
    let what = match &divergence {
        Some(d) => format!("first divergence at {d}"),
        None => format!(
            "step {step}: the hash differs but every body's fields are equal (a hashing bug)"
        ),
    };
    Err(format!(
        "DIVERGED {name}: {what}\n         reproduce: {}\n",
        reproduce(args, scene_args, check, step, threads)
    ))
}

/// The first difference between the reference's state at `step` and `got`.
fn locate(scene: &Scene, step: u64, got: &[Body]) -> Option<Divergence> {
    let mut reference: Vec<Body> = Vec::new();
    let found = run_scene(
        scene,
        &RunOptions::default(),
        step,
        &StatesWanted::at(step),
        |f, s| {
            if f.step == step {
                reference = s
                    .map(|s| s.iter().map(|b| (*b).clone()).collect())
                    .unwrap_or_default();
            }
        },
    );
    found.ok()?;
    let e: Vec<&Body> = reference.iter().collect();
    let g: Vec<&Body> = got.iter().collect();
    first_difference::<RigidBodyModel>(step, &scene.grid(), &e, &g)
}

/// The `soda run` command that reruns the diverging configuration up to `step`.
fn reproduce(
    args: &VerifyArgs,
    scene: &SceneArgs,
    check: &Check,
    step: u64,
    threads: usize,
) -> String {
    let mut cmd = format!("soda run --scene {}", scene.scene);
    if let Some(n) = scene.objects {
        cmd += &format!(" --objects {n}");
    }
    if let Some(s) = scene.seed {
        cmd += &format!(" --seed {s}");
    }
    cmd += &format!(
        " --steps {step} --executor {} --worlds {} --mode {} --window {} --partition {}",
        check.executor.name(),
        args.worlds,
        check.mode.name(),
        args.window,
        PartitionKind::from(args.partition).name()
    );
    if let Some(s) = args.partition_seed {
        cmd += &format!(" --partition-seed {s}");
    }
    if args.ghosts == GhostsArg::Full {
        cmd += " --ghosts full";
    }
    match check.seed {
        Some(seed) => cmd += &format!(" --schedule-seed {seed}"),
        None => cmd += &format!(" --threads {threads}"),
    }
    if let Some(b) = args.planted_bug {
        cmd += match b {
            PlantedBugArg::CutoffByIdsOnly => " --planted-bug cutoff-by-ids-only",
            PlantedBugArg::DropLoneAnti => " --planted-bug drop-lone-anti",
        };
    }
    if check.seed.is_none() {
        cmd += "  (a threaded interleaving may not recur: rerun a few times, or use soda verify)";
    }
    cmd
}

/// Parses `--modes`.
fn parse_modes(s: &str) -> Result<Vec<RollbackMode>> {
    if s == "all" {
        return Ok(vec![
            RollbackMode::Cell,
            RollbackMode::World,
            RollbackMode::Conservative,
        ]);
    }
    let mut modes = Vec::new();
    for part in s.split(',') {
        let m = match part.trim() {
            "cell" => ModeArg::Cell,
            "world" => ModeArg::World,
            "conservative" => ModeArg::Conservative,
            other => bail!(
                "--modes `{s}`: `{other}` is not a rollback mode; use `all` or a comma-separated \
                 list of cell, world, conservative"
            ),
        };
        let m = RollbackMode::from(m);
        if !modes.contains(&m) {
            modes.push(m);
        }
    }
    Ok(modes)
}
