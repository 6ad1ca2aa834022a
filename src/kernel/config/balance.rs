//! Dynamic load balancing's settings (SPEC.md §K13) and their validation.

use serde::{Deserialize, Serialize};

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
    pub fn validate(&self) -> Result<(), BalanceConfigError> {
        let ok = self.underloaded > 0.0
            && self.underloaded <= 1.0
            && self.high >= 1.0
            && self.overloaded >= self.high;
        if !ok {
            return Err(BalanceConfigError::Thresholds {
                underloaded: self.underloaded,
                high: self.high,
                overloaded: self.overloaded,
            });
        }
        if !(self.smoothing > 0.0 && self.smoothing <= 1.0) {
            return Err(BalanceConfigError::Smoothing(self.smoothing));
        }
        if self.period == 0 {
            return Err(BalanceConfigError::Period);
        }
        if self.max_cells == 0 {
            return Err(BalanceConfigError::MaxCells);
        }
        Ok(())
    }
}

/// A [`BalanceConfig`] whose settings are out of range; the message names the field.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum BalanceConfigError {
    /// The load levels are not ordered `0 < underloaded ≤ 1 ≤ high ≤ overloaded`.
    #[error(
        "balance thresholds must satisfy 0 < underloaded <= 1 <= high <= overloaded \
         (got underloaded {underloaded}, high {high}, overloaded {overloaded})"
    )]
    Thresholds {
        /// [`BalanceConfig::underloaded`].
        underloaded: f64,
        /// [`BalanceConfig::high`].
        high: f64,
        /// [`BalanceConfig::overloaded`].
        overloaded: f64,
    },
    /// [`BalanceConfig::smoothing`] is not in (0, 1].
    #[error("balance smoothing must be in (0, 1] (got {0})")]
    Smoothing(f64),
    /// [`BalanceConfig::period`] is 0.
    #[error("balance period must be at least 1 step")]
    Period,
    /// [`BalanceConfig::max_cells`] is 0.
    #[error("balance max_cells must be at least 1")]
    MaxCells,
}
