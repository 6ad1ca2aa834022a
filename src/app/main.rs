//! The command line of [`main_with`]: parsing (clap) and dispatch to [`super::commands`].

use super::commands;
use super::numbers::{count_from, entity_count, whole};
use super::registry::{ModelSize, Registry};
use super::usage::{exit_status, usage};
use crate::kernel::{KernelConfig, PartitionKind, RollbackMode};
use crate::sim::{ExecutorKind, RunOptions};
use crate::verify::VerifyOptions;
use anyhow::{anyhow, Result};
use clap::{Args, Parser, Subcommand};
use std::process::ExitCode;

/// A simulation built on SODA: deterministic optimistic (Time Warp) parallel runs of the
/// registered models, bit-identical on every executor.
#[derive(Debug, Parser)]
#[command(arg_required_else_help = true)]
pub struct ModelCli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// List the registered models.
    Models,
    /// Run a model on an executor and print a summary ending with the final hash.
    #[command(allow_negative_numbers = true)]
    Run(RunArgs),
    /// Continue a run from its checkpoint (`run --checkpoint FILE`) to the same final hash as
    /// the uninterrupted run.
    #[command(allow_negative_numbers = true)]
    Resume(ResumeArgs),
    /// Check that the virtual and threaded executors commit the reference's bits, with the
    /// contract checker and a diagnosis.
    #[command(allow_negative_numbers = true)]
    Verify(VerifyArgs),
    /// Rollback granularity: cell against world rollback per optimism window (CSV).
    #[command(allow_negative_numbers = true)]
    Experiment(ExperimentArgs),
    /// Draw a trace written by `run --trace` (space-time diagram, territory map, rollback
    /// heat map, SVG).
    Plot(PlotArgs),
}

#[derive(Debug, Args)]
struct PlotArgs {
    /// A trace written by `run --trace FILE`.
    #[arg(value_name = "TRACE")]
    trace: std::path::PathBuf,
    /// Directory for the charts (created if missing).
    #[arg(long, value_name = "DIR", default_value = ".")]
    out: std::path::PathBuf,
}

/// Which model, its size and seed.
#[derive(Debug, Args, Clone)]
pub struct ModelArgs {
    /// The registered model (see `models`).
    #[arg(long, value_name = "NAME")]
    pub model: String,
    /// Entities at step 0 [default: the model's].
    #[arg(long, value_name = "N", value_parser = entity_count)]
    pub entities: Option<usize>,
    /// Seed of the initial states and the model's randomness.
    #[arg(long, value_name = "S", default_value_t = 1, value_parser = whole(0, u64::MAX))]
    pub seed: u64,
}

/// The kernel's options (optional, so that a run on the reference executor, which has no
/// worlds, can refuse them when given).
#[derive(Debug, Args, Clone)]
pub struct KernelArgs {
    /// Worlds [default: 8].
    #[arg(long, value_name = "N", value_parser = whole(1, 4096))]
    pub worlds: Option<u64>,
    /// Optimism window: W steps, or `auto` (`auto:W`): each world adapts its own up to 64 (W)
    /// by its rollbacks [default: 16].
    #[arg(long, value_name = "W")]
    pub window: Option<crate::kernel::WindowSpec>,
    /// Partitioner: blocks, equal-blocks, kmeans or random [default: blocks].
    #[arg(long, value_name = "P")]
    pub partition: Option<String>,
}

impl KernelArgs {
    fn config(&self) -> Result<KernelConfig> {
        let partition: PartitionKind = match &self.partition {
            None => PartitionKind::Blocks,
            Some(p) => p.parse().map_err(|_| {
                usage(format!(
                    "--partition {p}: use blocks, equal-blocks, kmeans or random"
                ))
            })?,
        };
        let window = self.window.unwrap_or(crate::kernel::WindowSpec::Fixed(16));
        Ok(window
            .apply(KernelConfig::new(self.worlds.unwrap_or(8) as usize))
            .partition(partition))
    }

    /// The first kernel option given on the command line, if any.
    fn given(&self) -> Option<&'static str> {
        [
            ("--worlds", self.worlds.is_some()),
            ("--window", self.window.is_some()),
            ("--partition", self.partition.is_some()),
        ]
        .into_iter()
        .find(|f| f.1)
        .map(|f| f.0)
    }
}

#[derive(Debug, Args)]
struct RunArgs {
    #[command(flatten)]
    model: ModelArgs,
    /// Steps to run.
    #[arg(long, value_name = "N", default_value_t = 300, value_parser = whole(0, u64::MAX))]
    steps: u64,
    /// Executor: reference, virtual or threaded.
    #[arg(long, value_name = "E", default_value = "reference")]
    executor: String,
    /// Rollback mode: cell, world or conservative [default: cell].
    #[arg(long, value_name = "M")]
    mode: Option<String>,
    /// Threads of the threaded executor [default: the available cores].
    #[arg(long, value_name = "T", value_parser = count_from(1))]
    threads: Option<usize>,
    #[command(flatten)]
    kernel: KernelArgs,
    /// Print the report as JSON.
    #[arg(long)]
    json: bool,
    /// Write the run's trace (LVT, rollbacks, GVT; virtual and threaded executors) as JSON,
    /// for `plot`.
    #[arg(long, value_name = "FILE")]
    trace: Option<std::path::PathBuf>,
    /// Write a checkpoint (the committed states, exact, and the run's settings) to FILE every
    /// --checkpoint-every steps and at the last step; `resume FILE` continues from it.
    #[arg(long, value_name = "FILE")]
    checkpoint: Option<std::path::PathBuf>,
    /// With --checkpoint: steps between checkpoints.
    #[arg(long, value_name = "N", default_value_t = 100, requires = "checkpoint",
          value_parser = whole(1, u64::MAX))]
    checkpoint_every: u64,
}

#[derive(Debug, Args)]
struct ResumeArgs {
    /// The checkpoint `run --checkpoint FILE` wrote.
    #[arg(value_name = "FILE")]
    file: std::path::PathBuf,
    /// The step to reach [default: the checkpointed run's --steps].
    #[arg(long, value_name = "N", value_parser = whole(0, u64::MAX))]
    steps: Option<u64>,
    /// Executor: reference, virtual or threaded [default: the checkpointed run's, with its
    /// kernel options].
    #[arg(long, value_name = "E")]
    executor: Option<String>,
    /// Threads of the threaded executor [default: the checkpointed run's].
    #[arg(long, value_name = "T", value_parser = count_from(1))]
    threads: Option<usize>,
    /// Print the report as JSON.
    #[arg(long)]
    json: bool,
}

#[derive(Debug, Args)]
struct VerifyArgs {
    #[command(flatten)]
    model: ModelArgs,
    /// Steps compared per run.
    #[arg(long, value_name = "N", default_value_t = 60, value_parser = whole(0, u64::MAX))]
    steps: u64,
    /// Modes: all, or a comma-separated list of cell, world, conservative.
    #[arg(long, value_name = "LIST", default_value = "all")]
    modes: String,
    /// Virtual-executor schedule seeds per mode.
    #[arg(long, value_name = "K", default_value_t = 8, value_parser = whole(0, u64::MAX))]
    schedules: u64,
    /// Threaded runs per mode.
    #[arg(long, value_name = "R", default_value_t = 3, value_parser = whole(0, u64::MAX))]
    repeats: u64,
    /// MPI runs per mode, across the processes of the MPI job this runs in (`mpirun -np R
    /// BINARY verify --mpi-repeats K`, built with the `mpi` feature); rank 0 prints.
    #[arg(long, value_name = "K", default_value_t = 0, value_parser = whole(0, u64::MAX))]
    mpi_repeats: u64,
    /// Threads of the threaded runs [default: the available cores].
    #[arg(long, value_name = "T", value_parser = count_from(1))]
    threads: Option<usize>,
    #[command(flatten)]
    kernel: KernelArgs,
}

#[derive(Debug, Args)]
struct ExperimentArgs {
    /// The experiment: `granularity`.
    #[arg(value_name = "EXPERIMENT")]
    name: String,
    #[command(flatten)]
    model: ModelArgs,
    /// Optimism windows, comma-separated.
    #[arg(long, value_name = "LIST", default_value = "4,16,64")]
    windows: String,
    /// Schedule seeds averaged per point.
    #[arg(long, value_name = "K", default_value_t = 3, value_parser = whole(0, u64::MAX))]
    seeds: u64,
    /// Steps per run.
    #[arg(long, value_name = "N", default_value_t = 100, value_parser = whole(0, u64::MAX))]
    steps: u64,
    #[command(flatten)]
    kernel: KernelArgs,
}

fn threads(t: Option<usize>) -> usize {
    t.unwrap_or_else(|| std::thread::available_parallelism().map_or(2, |n| n.get()))
        .max(1)
}

/// Parses a rollback mode name.
pub(crate) fn parse_mode(s: &str) -> Result<RollbackMode> {
    match s.trim() {
        "cell" => Ok(RollbackMode::Cell),
        "world" => Ok(RollbackMode::World),
        "conservative" => Ok(RollbackMode::Conservative),
        other => Err(usage(format!(
            "`{other}` is not a rollback mode: use cell, world or conservative"
        ))),
    }
}

fn model<'a>(
    registry: &'a Registry,
    args: &ModelArgs,
) -> Result<(&'a dyn super::RegisteredModel, ModelSize)> {
    let m = registry.get(&args.model).ok_or_else(|| {
        let names: Vec<&str> = registry.models().map(|m| m.name()).collect();
        usage(format!(
            "--model {}: no such model; registered: {}",
            args.model,
            names.join(", ")
        ))
    })?;
    Ok((
        m,
        ModelSize {
            entities: args.entities,
            seed: args.seed,
        },
    ))
}

fn dispatch(registry: &Registry, cli: ModelCli) -> Result<()> {
    match cli.command {
        Command::Models => {
            for m in registry.models() {
                crate::app::output::print_line(format_args!("{:<16} {}", m.name(), m.about()))?;
            }
            Ok(())
        }
        Command::Run(a) => {
            let (m, size) = model(registry, &a.model)?;
            let executor: ExecutorKind = a
                .executor
                .parse()
                .map_err(|e| usage(format!("--executor: {e}")))?;
            // As for the rigid-body runs: options of parts the executor lacks are refused,
            // not silently ignored.
            let kernel_flag = a
                .mode
                .as_ref()
                .map(|_| "--mode")
                .or_else(|| a.kernel.given());
            check_executor_options(executor, kernel_flag, a.threads.is_some())?;
            let options = RunOptions {
                executor,
                kernel: a
                    .kernel
                    .config()?
                    .mode(parse_mode(a.mode.as_deref().unwrap_or("cell"))?),
                threads: threads(a.threads),
                ..RunOptions::default()
            };
            check_checkpoint_has_a_step(a.steps, a.checkpoint.is_some(), false)?;
            let checkpoint = match &a.checkpoint {
                Some(path) => Some(super::checkpoint::CheckpointPlan::checked(
                    path,
                    a.checkpoint_every,
                )?),
                None => None,
            };
            commands::run(
                m,
                &size,
                &options,
                a.steps,
                a.json,
                a.trace.as_deref(),
                checkpoint.as_ref(),
            )
            .map(|_| ())
        }
        Command::Resume(a) => {
            let options = resume_options(&a.file, a.executor.as_deref(), a.threads)?;
            super::checkpoint::resume(registry, &a.file, a.steps, options, a.json)
        }
        Command::Verify(a) => {
            let (m, size) = model(registry, &a.model)?;
            let options = VerifyOptions {
                steps: a.steps,
                kernel: a.kernel.config()?,
                modes: parse_modes(&a.modes)?,
                schedules: a.schedules,
                repeats: a.repeats,
                mpi_repeats: a.mpi_repeats,
                threads: threads(a.threads),
                ..VerifyOptions::default()
            };
            commands::verify(m, &size, &options)
        }
        Command::Plot(a) => commands::plot(&a.trace, &a.out),
        Command::Experiment(a) => {
            if a.name != "granularity" {
                return Err(usage(format!(
                    "experiment `{}`: the experiment for any model is `granularity`",
                    a.name
                )));
            }
            let (m, size) = model(registry, &a.model)?;
            let windows = a
                .windows
                .split(',')
                .map(|w| {
                    w.trim()
                        .parse::<u64>()
                        .ok()
                        .filter(|&w| w >= 1)
                        .ok_or_else(|| {
                            usage(format!(
                                "--windows {}: `{w}` is not a window of 1 or more",
                                a.windows
                            ))
                        })
                })
                .collect::<Result<Vec<u64>>>()?;
            commands::granularity(m, &size, &a.kernel.config()?, &windows, a.seeds, a.steps)
        }
    }
}

/// The options `resume` overrides: none (the checkpoint's), or the checkpoint's kernel
/// configuration on `--executor` and `--threads`.
fn resume_options(
    file: &std::path::Path,
    executor: Option<&str>,
    threads: Option<usize>,
) -> Result<Option<RunOptions>> {
    if executor.is_none() && threads.is_none() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(file)
        .map_err(|e| anyhow!("cannot read the checkpoint {}: {e}", file.display()))?;
    let name = crate::checkpoint::model_of(&text)?;
    let c = crate::checkpoint::Checkpoint::<super::checkpoint::AppRun>::from_text(&text, &name)?;
    let mut options = c.run.options;
    if let Some(e) = executor {
        options.executor = e
            .parse()
            .map_err(|why| usage(format!("--executor: {why}")))?;
    }
    if let Some(t) = threads {
        options.threads = t.max(1);
    }
    Ok(Some(options))
}

/// Parses `all` or a comma-separated list of rollback modes.
pub(crate) fn parse_modes(s: &str) -> Result<Vec<RollbackMode>> {
    if s == "all" {
        return Ok(vec![
            RollbackMode::Cell,
            RollbackMode::World,
            RollbackMode::Conservative,
        ]);
    }
    s.split(',').map(parse_mode).collect()
}

/// The command line for the models of `registry`: parses the process's arguments, runs the
/// command, prints any error with its cause and returns exit status 1, or 2 for usage errors
/// (clap's and [`super::UsageError`]s).
pub fn main_with(registry: Registry) -> ExitCode {
    super::allocator::configure();
    let cli = ModelCli::parse();
    match dispatch(&registry, cli) {
        Ok(()) => ExitCode::SUCCESS,
        // The reader went away (`... | head`): nothing left to say.
        Err(e) if super::output::is_broken_pipe(&e) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(exit_status(&e))
        }
    }
}

/// Refuses options of parts `executor` lacks, for every command line that runs one, with a
/// [`super::UsageError`]: `kernel_flag`, the first Time Warp option given (`--mode`,
/// `--worlds`, ...), with the reference executor (it has no worlds), and `--threads`
/// (`threads_given`) with any but the threaded and MPI executors.
pub fn check_executor_options(
    executor: ExecutorKind,
    kernel_flag: Option<&str>,
    threads_given: bool,
) -> Result<()> {
    if let (ExecutorKind::Reference, Some(flag)) = (executor, kernel_flag) {
        return Err(usage(format!(
            "{flag} configures the Time Warp worlds, which the reference executor does not \
             have: add `--executor virtual` or `--executor threaded`"
        )));
    }
    if threads_given && executor != ExecutorKind::Threaded && executor != ExecutorKind::Mpi {
        return Err(usage(
            "--threads applies to the threaded and MPI executors only: add `--executor \
             threaded` (or, under mpirun, `--executor mpi`)",
        ));
    }
    Ok(())
}

/// The warning for a Time Warp run of `options` with more worlds than `grid` has cells, or
/// `None`. Such a run is valid (a world may own no cell) but leaves worlds with nothing to
/// do. `advice` (may be empty) ends it: how this model gets more, smaller cells.
pub fn worlds_beyond_cells_warning(
    options: &RunOptions,
    grid: &crate::grid::Grid,
    advice: &str,
) -> Option<String> {
    let cells = grid.cell_count();
    let worlds = options.kernel.worlds;
    if options.executor == ExecutorKind::Reference || worlds <= cells {
        return None;
    }
    let [x, y, z] = grid.dims;
    let advice = if advice.is_empty() {
        String::new()
    } else {
        format!(" ({advice})")
    };
    Some(format!(
        "warning: {worlds} worlds on a grid of {cells} cell{} ({x} x {y} x {z}, edge {:.4}): at \
         least {} of them own no cell and have nothing to do; give --worlds {cells} or \
         fewer{advice}",
        if cells == 1 { "" } else { "s" },
        grid.edge,
        worlds - cells,
    ))
}

/// Refuses `--partition-seed` (`seed_given`) with a partitioner that has nothing random (a
/// [`super::UsageError`]).
pub fn check_partition_seed(partition: &PartitionKind, seed_given: bool) -> Result<()> {
    if seed_given && !partition.is_seeded() {
        return Err(usage(format!(
            "--partition-seed seeds the kmeans and random partitioners, and {} has nothing \
             random: add `--partition kmeans` or `--partition random`, or drop it",
            partition.name()
        )));
    }
    Ok(())
}

/// Refuses `--checkpoint` (`checkpoint_given`) on a fresh run (`resumed` false) whose last
/// step is 0 (a [`super::UsageError`]): it computes no step, so no checkpoint would be written. A resumed run at its
/// last step already has its checkpoint: the file it resumed from.
pub fn check_checkpoint_has_a_step(
    last_step: u64,
    checkpoint_given: bool,
    resumed: bool,
) -> Result<()> {
    if last_step == 0 && checkpoint_given && !resumed {
        return Err(usage(
            "--checkpoint: the run computes no step (--steps 0), so no checkpoint would be \
             written: give --steps 1 or more",
        ));
    }
    Ok(())
}

/// Runs one parsed command line against `registry` (for a binary that has its own parser
/// and hands `--model` commands over). A usage error comes back as the [`clap::Error`]
/// itself (`e.downcast_ref::<clap::Error>()`), which prints clap's message and exits with its
/// status 2 through `clap::Error::exit`.
pub fn run_with(
    registry: &Registry,
    args: impl IntoIterator<Item = std::ffi::OsString>,
) -> Result<()> {
    match ModelCli::try_parse_from(args) {
        Ok(cli) => dispatch(registry, cli),
        Err(e) if !e.use_stderr() => {
            // --help or --version: print it, and that is a success.
            e.print()?;
            Ok(())
        }
        Err(e) => Err(e.into()),
    }
}
