//! The configuration of a Time Warp run: number of worlds, rollback mode, optimism window,
//! partitioner and the virtual executor's schedule.

use serde::{Deserialize, Serialize};

/// How a world repairs a straggler (SPEC.md §Rollback modes).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum RollbackMode {
    /// Rollback-and-Propagate: recompute only the cells whose inputs changed, compare their
    /// outputs with the log, propagate only what changed, stop when nothing changed.
    #[default]
    Cell,
    /// Classic Time Warp: recompute every cell of the world from the straggler's step on.
    World,
    /// No speculation: a cell computes step `t` only once its 27 neighbours are known at
    /// `t` (null messages for empty borders). Never rolls back.
    Conservative,
}

/// What a ghost carries and what its absence means in the optimistic modes (SPEC.md §K4).
/// Conservative mode always sends every ghost (null messages).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum GhostPolicy {
    /// A ghost only when a border cell's state differs from the step before; no ghost means
    /// unchanged, so a world running ahead predicts resting neighbours exactly and a resting
    /// border costs no message.
    #[default]
    Delta,
    /// A ghost of every non-empty border cell at every step; no ghost means empty, so a world
    /// running ahead predicts empty neighbours (classic; every late ghost of a step is a
    /// straggler of that step only).
    Full,
}

impl RollbackMode {
    /// Parses `cell`, `world` or `conservative`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "cell" => Some(Self::Cell),
            "world" => Some(Self::World),
            "conservative" => Some(Self::Conservative),
            _ => None,
        }
    }

    /// The name `parse` accepts.
    pub fn name(self) -> &'static str {
        match self {
            Self::Cell => "cell",
            Self::World => "world",
            Self::Conservative => "conservative",
        }
    }
}

/// How cells are assigned to worlds (see [`crate::kernel::partition`]).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum PartitionKind {
    /// Axis-aligned blocks: the world count factored over the three axes.
    #[default]
    Blocks,
    /// The thesis's setup (§3.2.4): equal-size k-means over body positions (seeded by
    /// `KernelConfig::partition_seed`), each cell to the world with most bodies in it, empty
    /// cells to the nearest centroid.
    KMeans,
    /// Every cell to a uniformly random world (seeded by `partition_seed`): the most
    /// fragmented territories, for tests.
    Random,
    /// An explicit owner per cell (linear cell index order).
    Explicit(Vec<u32>),
}

impl PartitionKind {
    /// Parses `blocks`, `kmeans` or `random`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "blocks" => Some(Self::Blocks),
            "kmeans" => Some(Self::KMeans),
            "random" => Some(Self::Random),
            _ => None,
        }
    }

    /// The name [`parse`](Self::parse) accepts (`explicit` for an explicit owner list).
    pub fn name(&self) -> &'static str {
        match self {
            Self::Blocks => "blocks",
            Self::KMeans => "kmeans",
            Self::Random => "random",
            Self::Explicit(_) => "explicit",
        }
    }
}

/// Who decides, in the virtual executor, which world acts next and which in-flight message
/// is delivered next.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ScheduleSpec {
    /// A ChaCha8 generator with this seed. Replays exactly from the seed.
    Seeded(u64),
    /// The recorded decisions of an earlier run (see `VirtualRun::schedule_string`), then the
    /// deterministic fallback.
    Replay(Vec<u32>),
    /// Fuzz bytes: each decision consumes one or two bytes, then the deterministic fallback.
    Bytes(Vec<u8>),
    /// The deterministic fallback only: deliver the oldest in-flight message first, else let
    /// a world with a non-empty inbox apply it, else let the world with the smallest LVT
    /// compute (lowest id on ties). Worlds then advance in lockstep with no straggler: the
    /// overhead of the kernel alone.
    Fifo,
}

impl Default for ScheduleSpec {
    fn default() -> Self {
        ScheduleSpec::Seeded(0)
    }
}

/// Deliberate bugs, for proving that the determinism tests can fail. Never use them.
#[doc(hidden)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum PlantedBug {
    /// No bug.
    #[default]
    None,
    /// Lazy cancellation compares re-executed outputs by body ids only, so a straggler that
    /// changes values but not membership is not propagated.
    CutoffByIdsOnly,
    /// An anti-message that would leave nothing in its place (the output became empty) is
    /// not sent.
    DropLoneAnti,
}

/// The configuration of a kernel run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct KernelConfig {
    /// Number of worlds (logical processes), at least 1.
    pub worlds: usize,
    /// Rollback mode.
    pub mode: RollbackMode,
    /// Optimism window `W` ≥ 1: after computing a step, a world holds at most `W`
    /// uncommitted states (no world computes past GVT + W − 1).
    pub window: u64,
    /// Partitioner.
    pub partition: PartitionKind,
    /// Seed of the k-means and random partitioners.
    pub partition_seed: u64,
    /// The virtual executor's schedule.
    pub schedule: ScheduleSpec,
    /// Record the virtual executor's decisions so the run can print a replay string
    /// (costs four bytes per decision).
    pub record_schedule: bool,
    /// Record a run trace (LVT over time, rollbacks, GVT advances, messages per step).
    /// Observation only: the committed bits are the same either way.
    pub trace: bool,
    /// Dynamic load balancing (off by default).
    #[serde(default)]
    pub balance: BalanceConfig,
    /// Threaded executor, optimistic modes: how many steps a world may compute ahead of the
    /// slowest of its neighbour worlds before it lets laggards run first (SPEC.md §10). 0 runs the
    /// worlds nearly in lockstep (few rollbacks); more lets a world speculate past a slower
    /// neighbour, up to the window.
    #[serde(default)]
    pub lead: u64,
    /// Ghost policy of the optimistic modes.
    #[serde(default)]
    pub ghosts: GhostPolicy,
    /// A deliberate bug, for tests that prove the checks can fire.
    #[doc(hidden)]
    pub planted_bug: PlantedBug,
}

impl Default for KernelConfig {
    fn default() -> Self {
        KernelConfig {
            worlds: 4,
            mode: RollbackMode::Cell,
            window: 16,
            partition: PartitionKind::Blocks,
            partition_seed: 0,
            schedule: ScheduleSpec::Seeded(0),
            record_schedule: true,
            trace: false,
            balance: BalanceConfig::default(),
            lead: 0,
            ghosts: GhostPolicy::Delta,
            planted_bug: PlantedBug::None,
        }
    }
}

impl KernelConfig {
    /// The default configuration with `worlds` worlds.
    pub fn new(worlds: usize) -> Self {
        KernelConfig {
            worlds,
            ..Self::default()
        }
    }

    /// Sets the rollback mode.
    pub fn mode(mut self, mode: RollbackMode) -> Self {
        self.mode = mode;
        self
    }

    /// Sets the optimism window.
    pub fn window(mut self, window: u64) -> Self {
        self.window = window;
        self
    }

    /// Sets the partitioner.
    pub fn partition(mut self, partition: PartitionKind) -> Self {
        self.partition = partition;
        self
    }

    /// Sets the partitioner's seed.
    pub fn partition_seed(mut self, seed: u64) -> Self {
        self.partition_seed = seed;
        self
    }

    /// Sets the schedule.
    pub fn schedule(mut self, schedule: ScheduleSpec) -> Self {
        self.schedule = schedule;
        self
    }

    /// Turns trace recording on or off.
    pub fn trace(mut self, on: bool) -> Self {
        self.trace = on;
        self
    }

    /// Sets the load balancing configuration.
    pub fn balance(mut self, balance: BalanceConfig) -> Self {
        self.balance = balance;
        self
    }

    /// Sets the ghost policy of the optimistic modes.
    pub fn ghosts(mut self, ghosts: GhostPolicy) -> Self {
        self.ghosts = ghosts;
        self
    }

    /// Sets the threaded executor's laggard lead (see [`KernelConfig::lead`]).
    pub fn lead(mut self, lead: u64) -> Self {
        self.lead = lead;
        self
    }

    /// Turns decision recording on or off.
    pub fn record_schedule(mut self, on: bool) -> Self {
        self.record_schedule = on;
        self
    }
}

/// Where a balancing round reads each world's load (SPEC.md §K13). Whatever the
/// source, balancing only moves cells at a step every world has committed, so the committed
/// bits never depend on it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum LoadSource {
    /// Busy wall-clock time per committed step (threaded executor; the virtual executor,
    /// which must replay exactly, uses [`LoadSource::CellsComputed`] instead).
    #[default]
    Measured,
    /// Cell computations per committed step (rollbacks included): a deterministic cost
    /// proxy, so decisions replay from the schedule.
    CellsComputed,
    /// Random loads from ChaCha8 seeded with this value and the round number: random but
    /// replayable decisions, for tests that force cessions and famine.
    Seeded(u64),
}

/// The longest interval between balancing rounds with [`BalanceConfig::backoff`], in periods.
pub const MAX_BACKOFF: u64 = 4;

/// Dynamic load balancing by cell cession (thesis §3.3; SPEC.md §K13).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct BalanceConfig {
    /// Balancing on or off (`--balance on|off`).
    pub enabled: bool,
    /// Steps between balancing rounds (each round happens at a committed step).
    pub period: u64,
    /// Back off when balanced (`--balance-backoff`): after a round that moves no cell the
    /// next round comes twice as many steps later (at most [`MAX_BACKOFF`] periods); a round
    /// that moves cells brings the interval back to `period`. Each round is a barrier for
    /// the threaded executor, so rounds that find nothing to do are not free.
    pub backoff: bool,
    /// An opening round at step 0 (`--balance-opening`), before anything is computed, with
    /// each world's load estimated from its bodies (SPEC.md §K13): a skewed scene starts
    /// balanced instead of waiting a period for the first measurement.
    pub opening: bool,
    /// A world whose smoothed load is below this fraction of the mean is underloaded.
    pub underloaded: f64,
    /// Above this multiple of the mean a world is highly loaded (it gives cells to
    /// underloaded neighbours).
    pub high: f64,
    /// Above this multiple of the mean a world is overloaded (it gives cells to any less
    /// loaded neighbour on its own initiative).
    pub overloaded: f64,
    /// Weight of the newest measurement in the exponential smoothing of loads, in (0, 1].
    /// Smoothing spans rounds that move no cell: after a round that moved cells, the next
    /// round takes its measurement of the new map as it is (SPEC.md §K13).
    pub smoothing: f64,
    /// Rounds during which a cell that moved cannot move again (hysteresis).
    pub cooldown: u64,
    /// Most cells one world gives one neighbour in one round.
    pub max_cells: usize,
    /// Where loads come from.
    pub load: LoadSource,
    /// Seed of the tie-breaks between equal candidates.
    pub seed: u64,
    /// How many workers the load is shared between (SPEC.md §K13): the load levels are
    /// taken against `total / workers` instead of the mean over the worlds, so with fewer
    /// workers than worlds the load gathers in as many territories as there are workers
    /// (fewer borders) and the other worlds may stay idle (no famine then). 0: the
    /// executor's own — the thread count for the threaded executor, the world count (the
    /// thesis's mean) for the virtual one.
    #[serde(default)]
    pub workers: usize,
}

impl Default for BalanceConfig {
    fn default() -> Self {
        BalanceConfig {
            enabled: false,
            period: 20,
            backoff: true,
            opening: true,
            underloaded: 0.8,
            high: 1.05,
            overloaded: 1.5,
            smoothing: 0.5,
            cooldown: 2,
            max_cells: 512,
            load: LoadSource::Measured,
            seed: 0,
            workers: 0,
        }
    }
}

impl BalanceConfig {
    /// Balancing on with the default thresholds.
    pub fn on() -> Self {
        BalanceConfig {
            enabled: true,
            ..Self::default()
        }
    }

    /// Checks the thresholds: `0 < underloaded ≤ 1 ≤ high ≤ overloaded`,
    /// `0 < smoothing ≤ 1`, `period ≥ 1`, `max_cells ≥ 1`. The error names the field.
    pub fn validate(&self) -> Result<(), String> {
        let ok = self.underloaded > 0.0
            && self.underloaded <= 1.0
            && self.high >= 1.0
            && self.overloaded >= self.high;
        if !ok {
            return Err(format!(
                "balance thresholds must satisfy 0 < underloaded <= 1 <= high <= overloaded \
                 (got underloaded {}, high {}, overloaded {})",
                self.underloaded, self.high, self.overloaded
            ));
        }
        if !(self.smoothing > 0.0 && self.smoothing <= 1.0) {
            return Err(format!(
                "balance smoothing must be in (0, 1] (got {})",
                self.smoothing
            ));
        }
        if self.period == 0 {
            return Err("balance period must be at least 1 step".into());
        }
        if self.max_cells == 0 {
            return Err("balance max_cells must be at least 1".into());
        }
        Ok(())
    }
}
