//! A look at a Time Warp run while it goes on, for live displays (`soda view`): GVT, each
//! world's LVT, its territory and its rollbacks so far. Observing never changes what the
//! worlds compute.

use crate::kernel::World;
use crate::model::{CellModel, Step};

/// The state of a Time Warp run at one moment, as a frame sink sees it through
/// [`RunControl::live_status`](super::control::RunControl::live_status).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LiveStatus {
    /// Global virtual time: every step below it is committed.
    pub gvt: Step,
    /// The worlds, in id order.
    pub worlds: Vec<WorldStatus>,
}

/// One world's progress and territory.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct WorldStatus {
    /// Local virtual time: the next step the world would compute.
    pub lvt: Step,
    /// The cells it owns (grid index order).
    pub cells: Vec<u32>,
    /// Rollbacks so far (primary and secondary).
    pub rollbacks: u64,
    /// Cell computations re-executed so far.
    pub cells_recomputed: u64,
    /// Per cell of `cells` (same order), its computations re-executed so far: where the
    /// rollbacks reached (a cell that changes owner starts again from 0 in its new world).
    pub cell_recomputes: Vec<u64>,
}

impl WorldStatus {
    /// What `world` shows now.
    pub(crate) fn of<M: CellModel>(world: &World<M>) -> WorldStatus {
        let c = world.counters();
        WorldStatus {
            lvt: world.lvt(),
            cells: world.cells().to_vec(),
            rollbacks: c.rollbacks_primary + c.rollbacks_secondary,
            cells_recomputed: c.cells_recomputed,
            cell_recomputes: world.cell_recomputes().to_vec(),
        }
    }
}

impl LiveStatus {
    /// The owner world of every cell of a grid of `cells` cells (`u32::MAX` where no world
    /// owns the cell, which a complete partition never leaves).
    pub fn owners(&self, cells: usize) -> Vec<u32> {
        let mut owner = vec![u32::MAX; cells];
        for (w, status) in self.worlds.iter().enumerate() {
            for &c in &status.cells {
                if let Some(o) = owner.get_mut(c as usize) {
                    *o = w as u32;
                }
            }
        }
        owner
    }

    /// The computations re-executed so far of every cell of a grid of `cells` cells, as its
    /// owner world counts them (0 where no world owns the cell).
    pub fn recomputes(&self, cells: usize) -> Vec<u64> {
        let mut counts = vec![0; cells];
        for status in &self.worlds {
            for (&c, &n) in status.cells.iter().zip(&status.cell_recomputes) {
                if let Some(slot) = counts.get_mut(c as usize) {
                    *slot = n;
                }
            }
        }
        counts
    }
}
