//! The configuration of a Time Warp run's worlds: number of worlds, rollback mode, optimism
//! window, partitioner, ghost policy and load balancing. How an executor runs them (the
//! virtual executor's schedule, the threaded executor's threads and lead) is the executor's
//! own options (`crate::exec::virtual_exec::VirtualOptions`,
//! `crate::exec::threaded::ThreadedOptions`).

mod balance;
mod names;
mod window;

pub use balance::{BalanceConfig, BalanceConfigError, LoadSource, MAX_BACKOFF};
pub use names::{UnknownGhostPolicy, UnknownMode, UnknownPartition};
pub use window::WindowSpec;

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

/// How cells are assigned to worlds (see [`crate::kernel::partition`]).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum PartitionKind {
    /// Axis-aligned boxes by recursive bisection, each cut where the bodies' initial
    /// positions balance (SPEC.md §K2).
    #[default]
    Blocks,
    /// Axis-aligned boxes of equal numbers of cells, whatever the bodies (the classic static
    /// territories: a skewed scene starts unbalanced, as load-balancing studies want).
    EqualBlocks,
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
    /// Adaptive optimism (SPEC.md §K14): each world throttles its own window within
    /// `1..=window` by its recent rollback rate (halved above 10 % over an epoch of 8 GVT
    /// advances; one step wider on trial below 2 %, given up at the first extra rollback,
    /// with an exponential back-off). Off: every world uses `window`. Only how far worlds
    /// speculate changes, never the committed bits.
    #[serde(default)]
    pub window_auto: bool,
    /// Partitioner.
    pub partition: PartitionKind,
    /// Seed of the k-means and random partitioners.
    pub partition_seed: u64,
    /// Record a run trace (LVT over time, rollbacks, GVT advances, messages per step).
    /// Observation only: the committed bits are the same either way.
    pub trace: bool,
    /// Dynamic load balancing (off by default).
    #[serde(default)]
    pub balance: BalanceConfig,
    /// Ghost policy of the optimistic modes.
    #[serde(default)]
    pub ghosts: GhostPolicy,
    /// A deliberate bug, for tests and `soda verify --planted-bug` that prove the checks can
    /// fire. A verification hook, not part of a run's description: it is never serialised
    /// (checkpoints do not hold it, a resumed run has none) and reads back as
    /// [`PlantedBug::None`].
    #[doc(hidden)]
    #[serde(skip)]
    pub planted_bug: PlantedBug,
}

impl Default for KernelConfig {
    fn default() -> Self {
        KernelConfig {
            worlds: 4,
            mode: RollbackMode::Cell,
            window: 16,
            window_auto: false,
            partition: PartitionKind::Blocks,
            partition_seed: 0,
            trace: false,
            balance: BalanceConfig::default(),
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

    /// Makes the window adaptive, with `window` as its ceiling (SPEC.md §K14).
    pub fn window_auto(mut self, on: bool) -> Self {
        self.window_auto = on;
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
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_planted_bug_is_not_serialised_and_old_documents_still_read() {
        // (Older documents also carry `lead`, `schedule` and `record_schedule`, now executor
        // settings: ignored here; `RunOptions` reads the last two back into its own fields.)
        let config = KernelConfig {
            planted_bug: PlantedBug::DropLoneAnti,
            ..KernelConfig::new(3)
        };
        let json = serde_json::to_string(&config).unwrap();
        assert!(!json.contains("planted_bug"), "{json}");
        let back: KernelConfig = serde_json::from_str(&json).unwrap();
        assert_eq!(back, KernelConfig::new(3));
        // Checkpoints written before carry the field: it is ignored.
        let mut old: serde_json::Value = serde_json::from_str(&json).unwrap();
        old["planted_bug"] = "DropLoneAnti".into();
        old["lead"] = 3.into();
        old["schedule"] = serde_json::json!({"seeded": 5});
        old["record_schedule"] = false.into();
        let back: KernelConfig = serde_json::from_value(old).unwrap();
        assert_eq!(back.planted_bug, PlantedBug::None);
        assert_eq!(back, KernelConfig::new(3));
    }
}
