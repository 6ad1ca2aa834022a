//! What a balancing round measures of each world (SPEC.md §K13), kept the same way by the
//! virtual and the threaded executor: the world's load per committed step since the last
//! round, and how far ahead of GVT it ran on average.

use crate::kernel::config::LoadSource;
use crate::model::Step;

/// One world's measurements since the last balancing round (or the start).
#[derive(Clone, Debug, Default)]
pub(crate) struct LoadMeter {
    /// CPU seconds its actions took (the threaded executor measures them; the virtual
    /// executor, which must replay exactly, leaves this at 0).
    busy_seconds: f64,
    /// Its `cells_computed` counter at the last round.
    cells_computed_at_round: u64,
    /// The sum, over its actions, of LVT − GVT right after the action.
    lead_sum: f64,
    /// The number of actions summed in `lead_sum`.
    actions: u64,
}

impl LoadMeter {
    /// Adds the CPU seconds of one action.
    pub(crate) fn add_busy(&mut self, seconds: f64) {
        self.busy_seconds += seconds;
    }

    /// Records how far ahead of `gvt` the world is (`lvt`) right after one of its actions.
    pub(crate) fn note_action(&mut self, lvt: Step, gvt: Step) {
        self.lead_sum += lvt.saturating_sub(gvt) as f64;
        self.actions += 1;
    }

    /// The CPU seconds of its actions since the last round.
    pub(crate) fn busy_seconds(&self) -> f64 {
        self.busy_seconds
    }

    /// Its load per committed step over the `span` steps since the last round: cell
    /// computations (`cells_computed` is the world's counter now) with
    /// [`LoadSource::CellsComputed`], busy CPU seconds otherwise (a seeded source ignores it).
    pub(crate) fn load(&self, source: LoadSource, cells_computed: u64, span: f64) -> f64 {
        match source {
            LoadSource::CellsComputed => {
                (cells_computed - self.cells_computed_at_round) as f64 / span
            }
            _ => self.busy_seconds / span,
        }
    }

    /// Its mean LVT − GVT after its actions since the last round (0 without actions).
    pub(crate) fn mean_lead(&self) -> f64 {
        self.lead_sum / self.actions.max(1) as f64
    }

    /// Starts measuring the next round, the world's `cells_computed` counter being
    /// `cells_computed` now.
    pub(crate) fn restart(&mut self, cells_computed: u64) {
        *self = LoadMeter {
            cells_computed_at_round: cells_computed,
            ..LoadMeter::default()
        };
    }
}
