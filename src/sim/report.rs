//! What a finished run reports, for any model.

use crate::exec::threaded::ThreadTimes;
use crate::kernel::{Counters, RunTrace};
use crate::model::Step;
use serde::Serialize;
use std::collections::BTreeMap;

/// What a run of any model reports ([`crate::sim::Runner`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ModelReport {
    /// Executor used.
    pub executor: String,
    /// Steps committed and handed to the sink.
    pub steps: u64,
    /// The last committed step, if the sink stopped the run before the steps asked for.
    pub stopped_at: Option<Step>,
    /// Wall time of the stepping, s.
    pub wall_seconds: f64,
    /// Steps per wall-clock second.
    pub steps_per_second: f64,
    /// Entity-steps (entities at step `t`, summed over the steps computed) per wall-clock
    /// second.
    pub entity_steps_per_second: f64,
    /// Canonical hash of the last committed state (16 hex digits).
    pub hash: String,
    /// Entities in the last committed state.
    pub entities: usize,
    /// Events over the run (including entities of the initial state outside the grid),
    /// counted by [`crate::CellModel::event_name`].
    pub events: BTreeMap<String, u64>,
    /// The Time Warp side of the run (virtual and threaded executors only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub kernel: Option<KernelReport>,
    /// The run trace, when the kernel configuration's `trace` was on (virtual and threaded
    /// executors); never part of the report's JSON.
    #[serde(skip)]
    pub trace: Option<RunTrace>,
}

/// The kernel's statistics of a virtual or threaded run.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct KernelReport {
    /// Worlds (logical processes).
    pub worlds: usize,
    /// OS threads (1 for the virtual executor).
    pub threads: usize,
    /// Rollback mode.
    pub mode: crate::kernel::RollbackMode,
    /// Optimism window (the ceiling of an adaptive one).
    pub window: u64,
    /// Whether each world adapted its window by its rollbacks (`--window auto`).
    pub window_auto: bool,
    /// Partitioner.
    pub partition: crate::kernel::PartitionKind,
    /// The virtual executor's schedule as a replay string (`None` for threaded runs, which
    /// are not replayable, or when recording was off).
    pub schedule: Option<String>,
    /// `cells_committed / cells_computed` over all worlds.
    pub efficiency: f64,
    /// Counters per world and in total.
    pub counters: Counters,
    /// Busy, GVT and idle time of the threads (threaded executor only).
    pub thread_times: Option<ThreadTimes>,
    /// Load balancing configuration.
    pub balance: crate::kernel::BalanceConfig,
    /// The balancing rounds: step, loads, imbalance, cells moved, famines (owner maps are
    /// kept in memory for charts, not written to JSON).
    pub balance_rounds: Vec<crate::kernel::RoundRecord>,
    /// Transport and GVT statistics of an MPI run (absent for the other executors).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mpi: Option<MpiStats>,
}

/// What an MPI run's ranks sent each other and what its GVT rounds cost (SPEC.md §14),
/// summed over ranks.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct MpiStats {
    /// Ranks of the job.
    pub ranks: usize,
    /// GVT rounds (each one or more all-gathers, until every batch sent was received).
    pub gvt_rounds: u64,
    /// All-gathers of the GVT rounds.
    pub reductions: u64,
    /// Batches of kernel messages sent between ranks.
    pub batches_sent: u64,
    /// Kernel messages in them (ghosts, migrations, anti- and null messages).
    pub messages_sent: u64,
    /// Their bytes.
    pub bytes_sent: u64,
    /// Bytes of committed states and events sent to rank 0.
    pub commit_bytes: u64,
    /// Wall time in GVT rounds, s (the slowest rank's).
    pub gvt_seconds: f64,
}

impl KernelReport {
    /// The run's window as the command lines write it: `16`, or `auto:64` when each world
    /// adapted its own (SPEC.md §K14).
    pub fn window_spec(&self) -> crate::kernel::WindowSpec {
        crate::kernel::WindowSpec::new(self.window, self.window_auto)
    }
}
