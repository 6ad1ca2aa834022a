//! Computing the interior ahead (SPEC.md §K5, item 4): while an executor holds a world back
//! (its neighbour world is behind, and advancing now would speculate on borders still to
//! change), the world may already compute the cells of its head step whose whole
//! neighbourhood is its own. Those outputs read no view of a foreign cell, so no ghost can
//! change them; the advance then computes only the rest. A change of an own state at the
//! head step (a migration, an input, a repair reaching the head) drops the outputs computed
//! ahead that read it, and the advance computes those cells again: the committed bits are
//! those of computing every cell at the advance.

use super::index::{cells_around, OwnCell};
use super::log::Out;
use super::World;
use crate::kernel::config::RollbackMode;
use crate::model::{CellModel, Step};

impl<M: CellModel> World<M> {
    /// Computes ahead the occupied interior cells of its head step (those whose 27
    /// neighbours are all its own, or outside the grid), if it could advance now at GVT
    /// `gvt` were it not held back: an optimistic mode, nothing to apply or repair, a step
    /// left and room in the window. Once per head step. Returns the number of cells it
    /// computed (or kept at rest), which count as computations (K9).
    pub fn compute_interior_ahead(&mut self, gvt: Step) -> u64 {
        let h = self.head;
        // The adaptive window as an action at this GVT would see it (idempotent per GVT).
        if let Some(t) = &mut self.throttle {
            self.window = t.on_gvt(gvt, self.window, &self.counters);
        }
        let able = self.mode != RollbackMode::Conservative
            && self.only_advances()
            && self.may_advance(gvt);
        if !able || self.early == Some(h) {
            return 0;
        }
        self.early = Some(h);
        let i = self.si(h);
        self.prepare(h);
        let (mut done, mut left) = (0, 0);
        for x in OwnCell::all(self.cells.len()) {
            if self.slots[i].state(x).is_empty() {
                continue;
            }
            if !self.targets[x].is_empty() {
                left += 1;
                continue;
            }
            debug_assert!(
                self.slots[i].outs[x].is_none(),
                "the head step is not computed"
            );
            let o = self.compute_or_keep(x, h);
            self.slots[i].outs[x] = Some(o);
            done += 1;
        }
        self.counters.cells_ahead += done;
        // Few cells left (the border): the advance computes them without preparing again.
        self.prepare_after_ahead = left >= done;
        if done == 0 {
            // Nothing computed: the advance prepares again anyway.
            self.prepared.clear();
        }
        done
    }

    /// Whether the interior of its head step was computed ahead already (computing ahead
    /// again does nothing until it advances).
    pub fn interior_computed_ahead(&self) -> bool {
        self.early == Some(self.head)
    }

    /// The output of own cell `x` at the head step `h` if it was computed ahead (taken out
    /// of the log: the advance stores it back).
    pub(super) fn take_ahead(&mut self, x: OwnCell, h: Step) -> Option<Out<M::State, M::Event>> {
        if self.early != Some(h) {
            return None;
        }
        let i = self.si(h);
        // Read first: taking through a shared chunk would copy it.
        self.slots[i].outs[x].as_ref()?;
        self.slots[i].outs[x].take()
    }

    /// The state of own cell `d` at step `t` changed: outputs computed ahead at `t` (the
    /// head step) that read it are dropped, counted as rolled back (K9); the advance
    /// computes those cells again.
    pub(super) fn drop_ahead_reading(&mut self, d: u32, t: Step) {
        if self.early != Some(t) {
            return;
        }
        let i = self.si(t);
        for n in cells_around(&self.grid, d) {
            if !self.is_own(n) {
                continue;
            }
            let x = self.own(n);
            if self.slots[i].outs[x].is_none() {
                continue;
            }
            if let Some(o) = self.slots[i].outs[x].take() {
                self.counters.cells_rolled_back += u64::from(o.computed);
                self.counters.cells_ahead_dropped += 1;
            }
        }
    }
}
