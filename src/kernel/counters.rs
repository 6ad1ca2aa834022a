//! Counters per world and in total (SPEC.md §Counters).
//!
//! Formulas:
//! - `efficiency = cells_committed / cells_computed` — of all cell computations (first
//!   computations and re-executions), the share whose result was committed;
//! - `step_efficiency = steps_committed / steps_computed` — the same per world-step
//!   (a re-executed step counts once however many of its cells were recomputed);
//! - at the end of a run: `cells_computed = cells_committed + cells_rolled_back` and
//!   `steps_computed = steps_committed + steps_reexecuted` (per world and in total);
//! - rollback length = LVT − the straggler's step, in steps.

use serde::Serialize;
use std::ops::AddAssign;

/// One world's counters (or their sum).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct WorldCounters {
    /// Steps computed forward (advancing LVT) plus steps re-executed.
    pub steps_computed: u64,
    /// Steps committed (frames committed while this world existed).
    pub steps_committed: u64,
    /// Sum of rollback lengths, in steps.
    pub steps_rolled_back: u64,
    /// Cell computations (`step_cell` calls), first and re-executed.
    pub cells_computed: u64,
    /// Cell computations that were re-executions.
    pub cells_recomputed: u64,
    /// Cell computations whose results were committed.
    pub cells_committed: u64,
    /// Cell computations superseded by a re-execution of the same cell-step (never
    /// committed). At the end of a run `cells_computed = cells_committed + cells_rolled_back`.
    pub cells_rolled_back: u64,
    /// Cell computations done ahead: a held-back world's interior cells computed before
    /// its advance (SPEC.md §K5; included in `cells_computed`).
    pub cells_ahead: u64,
    /// Of those, the ones dropped because a state they read changed before the advance
    /// (included in `cells_rolled_back`).
    pub cells_ahead_dropped: u64,
    /// Steps re-executed (one per dirty step repaired). At the end of a run
    /// `steps_computed = steps_committed + steps_reexecuted`.
    pub steps_reexecuted: u64,
    /// Rollbacks caused by a positive straggler.
    pub rollbacks_primary: u64,
    /// Rollbacks caused only by anti-messages.
    pub rollbacks_secondary: u64,
    /// Sum of primary rollback lengths.
    pub rollback_length_primary: u64,
    /// Sum of secondary rollback lengths.
    pub rollback_length_secondary: u64,
    /// Longest rollback.
    pub rollback_length_max: u64,
    /// Straggler messages that changed nothing already computed (absorbed without rollback).
    pub stragglers_absorbed: u64,
    /// Positive messages sent (ghosts + migrates, null messages included).
    pub messages_sent: u64,
    /// Of which ghosts.
    pub ghosts_sent: u64,
    /// Of which migrates.
    pub migrates_sent: u64,
    /// Of which null messages (conservative mode; empty content).
    pub null_messages_sent: u64,
    /// Anti-messages sent.
    pub anti_messages_sent: u64,
    /// Messages received (positive and anti).
    pub messages_received: u64,
    /// Positive/anti pairs annihilated on receipt.
    pub annihilated: u64,
    /// Actions that found nothing to do.
    pub idle_acts: u64,
    /// Largest log footprint seen, bytes (states, outputs, ghosts, sent and received logs).
    pub peak_log_bytes: u64,
}

impl WorldCounters {
    /// `cells_committed / cells_computed` (1 if nothing was computed).
    pub fn efficiency(&self) -> f64 {
        if self.cells_computed == 0 {
            1.0
        } else {
            self.cells_committed as f64 / self.cells_computed as f64
        }
    }

    /// `steps_committed / steps_computed` (1 if nothing was computed).
    pub fn step_efficiency(&self) -> f64 {
        if self.steps_computed == 0 {
            1.0
        } else {
            self.steps_committed as f64 / self.steps_computed as f64
        }
    }

    /// Number of rollbacks.
    pub fn rollbacks(&self) -> u64 {
        self.rollbacks_primary + self.rollbacks_secondary
    }
}

impl AddAssign<&WorldCounters> for WorldCounters {
    fn add_assign(&mut self, o: &WorldCounters) {
        self.steps_computed += o.steps_computed;
        self.steps_committed += o.steps_committed;
        self.steps_rolled_back += o.steps_rolled_back;
        self.cells_computed += o.cells_computed;
        self.cells_recomputed += o.cells_recomputed;
        self.cells_committed += o.cells_committed;
        self.cells_rolled_back += o.cells_rolled_back;
        self.cells_ahead += o.cells_ahead;
        self.cells_ahead_dropped += o.cells_ahead_dropped;
        self.steps_reexecuted += o.steps_reexecuted;
        self.rollbacks_primary += o.rollbacks_primary;
        self.rollbacks_secondary += o.rollbacks_secondary;
        self.rollback_length_primary += o.rollback_length_primary;
        self.rollback_length_secondary += o.rollback_length_secondary;
        self.rollback_length_max = self.rollback_length_max.max(o.rollback_length_max);
        self.stragglers_absorbed += o.stragglers_absorbed;
        self.messages_sent += o.messages_sent;
        self.ghosts_sent += o.ghosts_sent;
        self.migrates_sent += o.migrates_sent;
        self.null_messages_sent += o.null_messages_sent;
        self.anti_messages_sent += o.anti_messages_sent;
        self.messages_received += o.messages_received;
        self.annihilated += o.annihilated;
        self.idle_acts += o.idle_acts;
        self.peak_log_bytes += o.peak_log_bytes;
    }
}

/// Counters of a run: per world, their total, and run-wide values.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Counters {
    /// One entry per world.
    pub worlds: Vec<WorldCounters>,
    /// The sum over worlds (`peak_log_bytes` is the sum of per-world peaks).
    pub total: WorldCounters,
    /// Number of times GVT advanced.
    pub gvt_advances: u64,
    /// Current GVT.
    pub gvt: u64,
    /// Scheduler decisions taken (virtual executor).
    pub decisions: u64,
    /// Load balancing (all zero when it is off).
    pub balance: BalanceCounters,
}

/// What load balancing did over a run (SPEC.md §K13).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct BalanceCounters {
    /// Balancing rounds held (one per period, at a committed step).
    pub rounds: u64,
    /// Cells that changed owner, summed over rounds.
    pub cells_moved: u64,
    /// Worlds that fought famine (handed their territory over and took part of the most
    /// loaded world's), summed over rounds.
    pub famines: u64,
    /// Max over mean of the worlds' load summed over the run (CPU seconds of their actions
    /// in threaded runs, cell computations in virtual runs); 1 is perfect balance.
    pub imbalance: f64,
}

impl Counters {
    /// Builds the totals from per-world counters.
    pub fn from_worlds(worlds: Vec<WorldCounters>, gvt_advances: u64, gvt: u64) -> Self {
        let mut total = WorldCounters::default();
        for w in &worlds {
            total += w;
        }
        Counters {
            worlds,
            total,
            gvt_advances,
            gvt,
            decisions: 0,
            balance: BalanceCounters::default(),
        }
    }
}
