//! Options choosing the executor and the Time Warp kernel's configuration, shared by the
//! commands that run a scene.

use super::numbers::whole;
use anyhow::{bail, Result};
use clap::{Args, ValueEnum};
use soda::app::output::counted;
use soda::app::usage;
use soda::exec::virtual_exec::{parse_schedule, ScheduleSpec};
use soda::kernel::{
    BalanceConfig, GhostPolicy, KernelConfig, PartitionKind, PlantedBug, RollbackMode, WindowSpec,
};
use soda::sim::{ExecutorKind, RunOptions};

/// `--executor` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ExecutorArg {
    /// One thread, no worlds: the oracle every other executor is compared with.
    Reference,
    /// One thread runs the worlds under a seeded, replayable schedule.
    Virtual,
    /// OS threads run the worlds, the laggard (at equal step the heaviest) first.
    Threaded,
    /// The worlds spread over the ranks of an MPI job: `mpirun -np R soda run --executor mpi
    /// --worlds W` (a soda built with `--features mpi`).
    Mpi,
}

/// `--mode` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ModeArg {
    /// Rollback-and-Propagate: recompute only the cells a straggler affects.
    Cell,
    /// Classic Time Warp: recompute the whole territory.
    World,
    /// No speculation (null messages); never rolls back.
    Conservative,
}

impl From<ModeArg> for RollbackMode {
    fn from(m: ModeArg) -> Self {
        match m {
            ModeArg::Cell => RollbackMode::Cell,
            ModeArg::World => RollbackMode::World,
            ModeArg::Conservative => RollbackMode::Conservative,
        }
    }
}

/// `--ghosts` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum GhostsArg {
    /// A ghost only when a border cell changed since the step before (no ghost: unchanged).
    Delta,
    /// A ghost of every non-empty border cell every step (no ghost: empty).
    Full,
}

impl From<GhostsArg> for GhostPolicy {
    fn from(g: GhostsArg) -> Self {
        match g {
            GhostsArg::Delta => GhostPolicy::Delta,
            GhostsArg::Full => GhostPolicy::Full,
        }
    }
}

/// `--partition` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum PartitionArg {
    /// Axis-aligned boxes, cut where the bodies balance (recursive bisection).
    Blocks,
    /// Axis-aligned boxes of equal numbers of cells, whatever the bodies (classic static
    /// territories).
    EqualBlocks,
    /// The thesis's equal-size k-means over body positions (seeded).
    Kmeans,
    /// Every cell to a random world, the most fragmented territories (seeded).
    Random,
}

impl From<PartitionArg> for PartitionKind {
    fn from(p: PartitionArg) -> Self {
        match p {
            PartitionArg::Blocks => PartitionKind::Blocks,
            PartitionArg::EqualBlocks => PartitionKind::EqualBlocks,
            PartitionArg::Kmeans => PartitionKind::KMeans,
            PartitionArg::Random => PartitionKind::Random,
        }
    }
}

/// Options of the executor and the kernel.
#[derive(Debug, Clone, Args)]
#[command(next_help_heading = "Executor")]
pub struct ExecutorArgs {
    /// The executor: all commit bit-identical states.
    #[arg(long, value_enum, default_value = "reference")]
    pub executor: ExecutorArg,
    /// Number of worlds (logical processes) [default: the thread count for `threaded`
    /// (more worlds than threads make idle worlds race ahead and roll back), 4 for
    /// `virtual`]. Virtual and threaded only.
    #[arg(long, value_name = "N", value_parser = whole(1, 4096))]
    pub worlds: Option<u64>,
    /// OS threads of the threaded executor [default: the available cores], or of each rank
    /// under `--executor mpi` [default: 1].
    #[arg(long, value_name = "T", value_parser = whole(1, 256))]
    pub threads: Option<u64>,
    /// Rollback mode [default: cell]. Virtual and threaded only.
    #[arg(long, value_enum, value_name = "MODE")]
    pub mode: Option<ModeArg>,
    /// Optimism window: no world computes past GVT + W [default: 16]; `auto`: each world
    /// adapts its own window up to 64 by its recent rollbacks (`auto:W` up to W).
    #[arg(long, value_name = "W", value_parser = clap::value_parser!(WindowSpec))]
    pub window: Option<WindowSpec>,
    /// How cells are assigned to worlds [default: blocks]. Virtual and threaded only.
    #[arg(long, value_enum, value_name = "KIND")]
    pub partition: Option<PartitionArg>,
    /// Seed of the kmeans and random partitioners [default: 0]. With --partition kmeans or
    /// random only.
    #[arg(long, value_name = "S", value_parser = whole(0, u64::MAX))]
    pub partition_seed: Option<u64>,
    /// Seed of the virtual executor's scheduler [default: 0]: the same seed replays the
    /// same interleaving exactly.
    #[arg(long, value_name = "S", conflicts_with = "schedule", value_parser = whole(0, u64::MAX))]
    pub schedule_seed: Option<u64>,
    /// Replay a schedule string (`v1:...`), as printed by the `sync_order` fuzz target on a
    /// divergence (README.md, "Checking determinism yourself").
    #[arg(long, value_name = "STRING")]
    pub schedule: Option<String>,
    /// Ghost policy of the optimistic modes [default: delta]: `delta` sends a border cell's
    /// state only when it changed since the step before, so worlds running ahead predict
    /// unchanged neighbours; `full` sends every non-empty border cell every step (absent
    /// means empty). Virtual and threaded only; results are bit-identical either way.
    #[arg(long, value_enum, value_name = "POLICY")]
    pub ghosts: Option<GhostsArg>,
    /// Threaded executor: steps a world may compute ahead of its slowest neighbour world
    /// before it lets laggards run first [default: 0, near lockstep]. Larger values let
    /// worlds speculate past slower neighbours (up to the window) at the risk of rollbacks.
    #[arg(long, value_name = "STEPS", value_parser = whole(0, 1_000_000))]
    pub lead: Option<u64>,
    /// Dynamic load balancing by cell cession [default: off]: every --balance-period steps,
    /// at a committed step, overloaded worlds give cells to their neighbours and starving
    /// worlds take part of the most loaded one's. Results are bit-identical either way.
    #[arg(long, value_enum, value_name = "off|on")]
    pub balance: Option<BalanceArg>,
    /// Steps between balancing rounds [default: 20].
    #[arg(long, value_name = "N", value_parser = whole(1, 1_000_000))]
    pub balance_period: Option<u64>,
    /// Back off when balanced [default: on]: after a round that moves no cell the next one
    /// comes twice as many steps later (at most 4 periods); a round that moves cells brings
    /// the interval back to --balance-period. `off`: a round every period.
    #[arg(long, value_enum, value_name = "on|off")]
    pub balance_backoff: Option<SwitchArg>,
    /// An opening round at step 0 [default: on]: before anything is computed, cells move
    /// by each world's load estimated from its bodies, so a skewed scene starts balanced.
    /// `off`: the first round waits a period for measured loads.
    #[arg(long, value_enum, value_name = "on|off")]
    pub balance_opening: Option<SwitchArg>,
    /// Load level thresholds as fractions of the mean load, `UNDER,HIGH,OVER`
    /// [default: 0.8,1.05,1.5]: below UNDER a world is underloaded, above HIGH highly loaded,
    /// above OVER overloaded.
    #[arg(long, value_name = "U,H,O")]
    pub balance_thresholds: Option<String>,
    /// Weight of the newest load measurement in the exponential smoothing, in (0, 1]
    /// [default: 0.5].
    #[arg(long, value_name = "A")]
    pub balance_smoothing: Option<f64>,
    /// Rounds during which a cell that moved stays put [default: 2].
    #[arg(long, value_name = "R", value_parser = whole(0, u64::MAX))]
    pub balance_cooldown: Option<u64>,
    /// Workers the load is shared between [default: the thread count for `threaded`, the
    /// world count for `virtual`]: load levels are taken against total / workers, so with
    /// fewer threads than worlds the load gathers in as many territories as threads.
    #[arg(long, value_name = "N", value_parser = whole(1, 1_000_000))]
    pub balance_workers: Option<u64>,
    /// A deliberate kernel bug, to prove the checks can fire (never for real runs).
    #[arg(long, value_enum, hide = true)]
    pub planted_bug: Option<PlantedBugArg>,
}

/// `--balance` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum BalanceArg {
    /// Static territories.
    Off,
    /// Move cells between worlds as their loads change.
    On,
}

/// An on/off switch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum SwitchArg {
    /// Enabled.
    On,
    /// Disabled.
    Off,
}

/// `--planted-bug` values (hidden).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum PlantedBugArg {
    /// Lazy cancellation compares outputs by body ids only.
    CutoffByIdsOnly,
    /// Anti-messages that leave nothing in their place are not sent.
    DropLoneAnti,
}

impl From<PlantedBugArg> for PlantedBug {
    fn from(b: PlantedBugArg) -> Self {
        match b {
            PlantedBugArg::CutoffByIdsOnly => PlantedBug::CutoffByIdsOnly,
            PlantedBugArg::DropLoneAnti => PlantedBug::DropLoneAnti,
        }
    }
}

impl ExecutorArgs {
    /// The run options these flags describe, or an error naming a flag that does not apply
    /// to the chosen executor.
    pub fn options(&self) -> Result<RunOptions> {
        let kernel_flags = [
            ("--worlds", self.worlds.is_some()),
            ("--mode", self.mode.is_some()),
            ("--window", self.window.is_some()),
            ("--ghosts", self.ghosts.is_some()),
            ("--partition", self.partition.is_some()),
            ("--partition-seed", self.partition_seed.is_some()),
            ("--planted-bug", self.planted_bug.is_some()),
            ("--balance", self.balance.is_some()),
            ("--balance-period", self.balance_period.is_some()),
            ("--balance-backoff", self.balance_backoff.is_some()),
            ("--balance-opening", self.balance_opening.is_some()),
            ("--balance-thresholds", self.balance_thresholds.is_some()),
            ("--balance-smoothing", self.balance_smoothing.is_some()),
            ("--balance-cooldown", self.balance_cooldown.is_some()),
            ("--balance-workers", self.balance_workers.is_some()),
        ];
        let virtual_flags = [
            ("--schedule-seed", self.schedule_seed.is_some()),
            ("--schedule", self.schedule.is_some()),
        ];
        let executor = match self.executor {
            ExecutorArg::Reference => ExecutorKind::Reference,
            ExecutorArg::Virtual => ExecutorKind::Virtual,
            ExecutorArg::Threaded => ExecutorKind::Threaded,
            ExecutorArg::Mpi => ExecutorKind::Mpi,
        };
        if executor == ExecutorKind::Mpi && !cfg!(feature = "mpi") {
            bail!("{}", soda::exec::error::MpiError::NotBuilt);
        }
        if executor != ExecutorKind::Virtual {
            if let Some((flag, _)) = virtual_flags.iter().find(|f| f.1) {
                return Err(usage(format!(
                    "{flag} drives the virtual executor's scheduler: add `--executor virtual` \
                     (threaded runs are scheduled by the operating system)"
                )));
            }
        }
        soda::app::check_executor_options(
            executor,
            kernel_flags.iter().find(|f| f.1).map(|f| f.0),
            self.threads.is_some(),
        )?;
        if self.lead.is_some() && executor != ExecutorKind::Threaded {
            return Err(usage(
                "--lead paces the threaded executor's worlds: add `--executor threaded` (the \
                 virtual executor's pace is its schedule)",
            ));
        }
        let partition = self.partition.map_or(PartitionKind::Blocks, Into::into);
        soda::app::check_partition_seed(&partition, self.partition_seed.is_some())?;
        let schedule = match (&self.schedule, self.schedule_seed) {
            (Some(s), _) => parse_schedule(s).map_err(|e| {
                usage(format!(
                    "--schedule `{}` is not a schedule string: {e}",
                    short(s)
                ))
            })?,
            (None, seed) => ScheduleSpec::Seeded(seed.unwrap_or(0)),
        };
        // Under MPI, threads per rank: one unless asked (ranks usually match the cores).
        let threads = match (executor, self.threads) {
            (_, Some(t)) => t as usize,
            (ExecutorKind::Mpi, None) => 1,
            (_, None) => default_threads(),
        };
        let default_worlds = match executor {
            ExecutorKind::Threaded => threads,
            _ => 4,
        };
        let mut kernel = KernelConfig::new(self.worlds.map_or(default_worlds, |w| w as usize))
            .mode(self.mode.map_or(RollbackMode::Cell, Into::into))
            .window(16)
            .partition(partition)
            .partition_seed(self.partition_seed.unwrap_or(0))
            .ghosts(self.ghosts.map_or(GhostPolicy::Delta, Into::into));
        if let Some(w) = self.window {
            kernel = w.apply(kernel);
        }
        kernel.planted_bug = self.planted_bug.map_or(PlantedBug::None, Into::into);
        kernel.balance = self.balance_config()?;
        Ok(RunOptions {
            executor,
            kernel,
            threads,
            lead: self.lead.unwrap_or(0),
            schedule,
            record_schedule: false,
        })
    }
}

impl ExecutorArgs {
    /// The balancing configuration the `--balance*` flags describe.
    fn balance_config(&self) -> Result<BalanceConfig> {
        let mut b = BalanceConfig {
            enabled: self.balance == Some(BalanceArg::On),
            ..BalanceConfig::default()
        };
        let tuning = self.balance_period.is_some()
            || self.balance_backoff.is_some()
            || self.balance_opening.is_some()
            || self.balance_thresholds.is_some()
            || self.balance_smoothing.is_some()
            || self.balance_cooldown.is_some()
            || self.balance_workers.is_some();
        if tuning && !b.enabled {
            return Err(usage(
                "the --balance-* options tune load balancing, which is off: add `--balance on`",
            ));
        }
        if let Some(p) = self.balance_period {
            b.period = p;
        }
        if let Some(backoff) = self.balance_backoff {
            b.backoff = backoff == SwitchArg::On;
        }
        if let Some(opening) = self.balance_opening {
            b.opening = opening == SwitchArg::On;
        }
        if let Some(t) = &self.balance_thresholds {
            let v: Vec<f64> = t
                .split(',')
                .map(|x| x.trim().parse::<f64>())
                .collect::<Result<_, _>>()
                .map_err(|_| {
                    usage(format!(
                        "--balance-thresholds `{}` is not three numbers `UNDER,HIGH,OVER` \
                         (for example 0.8,1.2,1.5)",
                        short(t)
                    ))
                })?;
            let [u, h, o] = v[..] else {
                return Err(usage(format!(
                    "--balance-thresholds `{}` has {}; give three, `UNDER,HIGH,OVER` (for \
                     example 0.8,1.2,1.5)",
                    short(t),
                    counted(v.len(), "number", "numbers")
                )));
            };
            (b.underloaded, b.high, b.overloaded) = (u, h, o);
        }
        if let Some(a) = self.balance_smoothing {
            b.smoothing = a;
        }
        if let Some(c) = self.balance_cooldown {
            b.cooldown = c;
        }
        if let Some(w) = self.balance_workers {
            b.workers = w as usize;
        }
        b.validate()
            .map_err(|e| usage(format!("--balance options: {e}")))?;
        Ok(b)
    }
}

/// The available cores (1 if unknown).
pub fn default_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

fn short(s: &str) -> String {
    if s.chars().count() > 40 {
        format!("{}…", s.chars().take(40).collect::<String>())
    } else {
        s.to_string()
    }
}
