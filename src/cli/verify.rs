//! `soda verify`: run the reference, the virtual executor under K schedule seeds and the
//! threaded executor several times, per rollback mode; compare every committed step's hash
//! with the reference's and, on a mismatch, report the first step, body, field and cell that
//! differ with the command that reproduces it. Exits non-zero on any divergence.

use super::exec_args::{default_threads, GhostsArg, ModeArg, PartitionArg, PlantedBugArg};
use super::numbers::whole;
use super::output::print;
use super::source::SceneArgs;
use anyhow::{bail, Result};
use clap::Args;
use soda::app::output::counted;
use soda::kernel::{KernelConfig, PartitionKind, PlantedBug, RollbackMode, WindowSpec};
use soda::scene::SceneFormat;
use soda::sim::ExecutorKind;
use soda::verify::{verify_with_progress, RunOutcome, VerifyOptions, VerifySetup};
use std::path::Path;

/// Examples shown after `soda verify --help`.
pub const AFTER_HELP: &str = "\
Examples:
  soda verify                                        125 falling cubes, 8 worlds, all modes
  soda verify --scene sparse-gas --worlds 16 --schedules 50
  soda verify --scene chain --modes cell,world --threads 4 --repeats 10
  mpirun -np 3 soda verify --mpi-repeats 2           also across 3 processes (--features mpi)

Every line names one run and whether each of its committed steps hashed like the
reference's. A divergence names the first step, body, field and cell that differ and
prints the `soda run` command that reproduces it (virtual runs replay exactly from their
schedule seed, with the same number of steps). The exit status is 1 if any run diverged.";

/// The help of `--objects` under `soda verify`, whose built-ins default to
/// [`VERIFY_OBJECTS`] bodies.
pub const OBJECTS_HELP: &str = "Number of bodies of a built-in scene [default: 125, small \
    enough for a quick check; `soda run` uses the scene's own]. Not allowed with a scene file.";

/// Options of `soda verify`.
#[derive(Debug, Args)]
pub struct VerifyArgs {
    #[command(flatten)]
    pub scene: SceneArgs,

    /// The model: `rigid-bodies` (the scenes) or a registered example model (`soda models`:
    /// epidemic, phold), which takes --entities, --seed, --steps and the kernel options.
    #[arg(long, value_name = "NAME", default_value = super::RIGID_BODIES)]
    pub model: String,

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

    /// MPI runs per mode, across the processes of the MPI job this runs in: `mpirun -np R
    /// soda verify --mpi-repeats K` (a soda built with `--features mpi`). Every rank runs the
    /// same command; rank 0 runs every other check and prints.
    #[arg(long, value_name = "K", default_value_t = 0, help_heading = "Run",
          value_parser = whole(0, u64::MAX))]
    pub mpi_repeats: u64,

    /// Optimism window: W steps, or `auto` (`auto:W`), a window each world adapts by its
    /// rollbacks up to 64 (W).
    #[arg(long, value_name = "W", default_value = "16", help_heading = "Run")]
    pub window: WindowSpec,

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

/// One executor run to compare with the reference (for the reproduce command).
struct Check {
    executor: ExecutorKind,
    mode: RollbackMode,
    seed: Option<u64>,
    /// Ranks of an MPI run.
    ranks: Option<usize>,
}

/// Runs the command: a wrapper over the library's [`soda::verify`] for a scene.
pub fn verify(args: &VerifyArgs) -> Result<()> {
    let mut scene_args = args.scene.clone();
    let builtin = SceneFormat::from_path(Path::new(&scene_args.scene)).is_none();
    if builtin && scene_args.objects.is_none() {
        scene_args.objects = Some(VERIFY_OBJECTS);
    }
    let (scene, origin) = scene_args.load()?;
    let modes = parse_modes(&args.modes)?;
    if args.schedules == 0 && args.repeats == 0 && args.mpi_repeats == 0 {
        return Err(soda::app::usage(
            "--schedules 0 and --repeats 0 leave no run to check: give at least one schedule \
             (--schedules K), threaded run (--repeats R) or MPI run (--mpi-repeats K)",
        ));
    }
    // Under mpirun: MPI starts before anything is printed, and only rank 0 prints.
    let role = super::mpi::Role::under_mpi(args.mpi_repeats > 0)?;
    let root = role.root();
    soda::app::check_partition_seed(
        &PartitionKind::from(args.partition),
        args.partition_seed.is_some(),
    )?;
    // Seeds FIRST..FIRST+K must all exist: near u64::MAX the range was cut short silently.
    if args.first_schedule.checked_add(args.schedules).is_none() {
        return Err(soda::app::usage(format!(
            "--first-schedule {} with --schedules {} needs seeds beyond the largest, {}: \
             give a smaller --first-schedule or fewer --schedules",
            args.first_schedule,
            args.schedules,
            u64::MAX
        )));
    }
    let threads = args.threads.map_or_else(default_threads, |t| t as usize);
    let mut kernel = args
        .window
        .apply(KernelConfig::new(args.worlds as usize))
        .partition(args.partition.into())
        .partition_seed(args.partition_seed.unwrap_or(0))
        .ghosts(args.ghosts.into());
    kernel.planted_bug = args.planted_bug.map_or(PlantedBug::None, Into::into);
    let options = VerifyOptions {
        steps: args.steps,
        kernel,
        modes: modes.clone(),
        first_schedule: args.first_schedule,
        schedules: args.schedules,
        repeats: args.repeats,
        threads,
        mpi_repeats: args.mpi_repeats,
        check_contract: true,
    };
    let setup = VerifySetup::new(scene.model(), scene.grid(), scene.initial_bodies());
    if !root {
        // A follower takes part in the MPI runs; rank 0 checks and prints.
        verify_with_progress(&setup, &options, |_| {});
        return Ok(());
    }
    print(&format!(
        "verify           {} ({origin}), {}, {} ({} partition), window {}, {}\n",
        scene.name,
        counted(args.steps, "step", "steps"),
        counted(args.worlds, "world", "worlds"),
        PartitionKind::from(args.partition).name(),
        args.window,
        counted(threads, "thread", "threads"),
    ))?;
    let runs = modes.len() as u64 * (args.schedules + args.repeats + args.mpi_repeats);
    let progress = super::output::runs_bar(runs);
    let mut printed = Ok(());
    let report = verify_with_progress(&setup, &options, |check| {
        progress.inc(1);
        let mut text = format!("{check}\n");
        if !check.matched() {
            let step = match &check.outcome {
                RunOutcome::Diverged(m) => m.step,
                _ => args.steps,
            };
            let c = Check {
                executor: check.executor,
                mode: check.mode,
                seed: check.schedule_seed,
                ranks: check.ranks,
            };
            // A virtual run's schedule depends on the steps it computes (which worlds may
            // still advance), so it replays exactly only with the checked run's step count.
            let upto = if c.seed.is_some() { args.steps } else { step };
            text += &format!(
                "         reproduce: {}\n",
                reproduce(args, &scene_args, &c, upto, threads)
            );
        }
        if printed.is_ok() {
            printed = progress.suspend(|| print(&text));
        }
    });
    progress.finish_and_clear();
    printed?;
    print(&format!(
        "reference        hash {}\n",
        report.reference_hash()
    ))?;
    if let Some(e) = &report.reference_error {
        bail!("the reference run failed: {e}");
    }
    let diagnosis = report.diagnosis();
    for d in &diagnosis {
        print(&format!("diagnosis: {d}\n"))?;
    }
    let failed = report.failures().count();
    if failed > 0 {
        bail!(
            "{failed} of {} diverged from the reference (see the lines marked DIVERGED)",
            counted(report.runs.len(), "run", "runs")
        );
    }
    if !diagnosis.is_empty() {
        bail!("the model broke its contract (see the diagnosis above)");
    }
    print(&format!(
        "{} the reference's {}\n",
        match report.runs.len() {
            1 => "the 1 run committed".to_string(),
            n => format!("all {n} runs committed"),
        },
        counted(args.steps, "hash", "hashes")
    ))
}

/// The `soda run` command that reruns the diverging configuration up to `step`.
fn reproduce(
    args: &VerifyArgs,
    scene: &SceneArgs,
    check: &Check,
    step: u64,
    threads: usize,
) -> String {
    let mut cmd = match check.ranks {
        Some(r) => format!("mpirun -np {r} soda run --scene {}", scene.scene),
        None => format!("soda run --scene {}", scene.scene),
    };
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
    match (check.seed, check.ranks) {
        (Some(seed), _) => cmd += &format!(" --schedule-seed {seed}"),
        (None, None) => cmd += &format!(" --threads {threads}"),
        (None, Some(_)) => {}
    }
    if let Some(b) = args.planted_bug {
        cmd += match b {
            PlantedBugArg::CutoffByIdsOnly => " --planted-bug cutoff-by-ids-only",
            PlantedBugArg::DropLoneAnti => " --planted-bug drop-lone-anti",
        };
    }
    if check.seed.is_none() && check.ranks.is_none() {
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
            other => {
                return Err(soda::app::usage(format!(
                    "--modes `{s}`: `{other}` is not a rollback mode; use `all` or a \
                     comma-separated list of cell, world, conservative"
                )))
            }
        };
        let m = RollbackMode::from(m);
        if !modes.contains(&m) {
            modes.push(m);
        }
    }
    Ok(modes)
}
