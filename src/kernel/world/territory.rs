//! A world's territory: its own cells, the foreign cells next to them (its margin), each own
//! cell's neighbourhood resolved once, and the worlds it exchanges ghosts with (SPEC.md §K2).

use super::index::{cells_around, MarginCell, OwnCell, PerOwnCell};
use super::log::{share, Slot};
use super::throttle::Throttle;
use super::World;
use crate::grid::Grid;
use crate::kernel::config::KernelConfig;
use crate::kernel::counters::WorldCounters;
use crate::kernel::partition::{Partition, WorldId};
use crate::model::{CellModel, Neighbourhood, Step};
use crate::state::CellStates;
use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::sync::Arc;

/// Where the state of one neighbour of an own cell is held, packed in 4 bytes: every cell
/// computation reads its 27 from the world's table, which for a large territory is larger
/// than a core's cache (see [`NbKind`] for what it says).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Nb(u32);

/// What an [`Nb`] says.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum NbKind {
    /// Outside the grid: always empty.
    Outside,
    /// An own cell.
    Own(OwnCell),
    /// A margin cell.
    Margin(MarginCell),
}

impl Nb {
    /// The bit that marks a margin cell.
    const MARGIN: u32 = 1 << 31;

    /// Outside the grid.
    pub(super) const OUTSIDE: Nb = Nb(u32::MAX);

    /// Own cell `x`.
    pub(super) fn own(x: OwnCell) -> Nb {
        let i = u32::try_from(x.index()).expect("fewer than 2^31 own cells");
        assert!(i < Self::MARGIN, "fewer than 2^31 own cells");
        Nb(i)
    }

    /// Margin cell `m`.
    pub(super) fn margin(m: MarginCell) -> Nb {
        let i = u32::try_from(m.index()).expect("fewer than 2^31 - 1 margin cells");
        assert!(i < Self::MARGIN - 1, "fewer than 2^31 - 1 margin cells");
        Nb(Self::MARGIN | i)
    }

    /// What it says.
    #[inline(always)]
    pub(super) fn kind(self) -> NbKind {
        if self.0 < Self::MARGIN {
            NbKind::Own(OwnCell::from_local(self.0))
        } else if self == Self::OUTSIDE {
            NbKind::Outside
        } else {
            NbKind::Margin(MarginCell::at((self.0 & !Self::MARGIN) as usize))
        }
    }
}

impl<M: CellModel> World<M> {
    /// World `id` of `part`, starting at step `step` from the final states `states` (the
    /// whole domain's, binned over `grid`): its logs hold step `step` only.
    pub(super) fn at_step(
        id: WorldId,
        model: Arc<M>,
        grid: Arc<Grid>,
        part: Arc<Partition>,
        config: &KernelConfig,
        states: &CellStates<M::State>,
        step: Step,
    ) -> Self {
        let cells: PerOwnCell<u32> = part.cells_of(id).iter().copied().collect();
        let targets: PerOwnCell<Vec<WorldId>> = cells
            .iter()
            .map(|&c| {
                let mut t: Vec<WorldId> = cells_around(&grid, c)
                    .map(|n| part.owner(n))
                    .filter(|&w| w != id)
                    .collect();
                t.sort_unstable();
                t.dedup();
                t
            })
            .collect();
        let mut neighbours: Vec<WorldId> = targets.iter().flatten().copied().collect();
        neighbours.sort_unstable();
        neighbours.dedup();
        let mut margin: Vec<u32> = cells
            .iter()
            .flat_map(|&c| cells_around(&grid, c))
            .filter(|&n| part.owner(n) != id)
            .collect();
        margin.sort_unstable();
        margin.dedup();
        let nbrs: PerOwnCell<[Nb; 27]> = cells
            .iter()
            .map(|&cell| {
                let c = grid.coord(cell as usize);
                std::array::from_fn(|k| {
                    let n = c.offset(Neighbourhood::<M::State>::offset(k));
                    if !grid.contains(n) {
                        return Nb::OUTSIDE;
                    }
                    let ni = grid.index(n) as u32;
                    if part.owner(ni) == id {
                        Nb::own(OwnCell::from_local(part.local(ni)))
                    } else {
                        Nb::margin(MarginCell::at(
                            margin.binary_search(&ni).expect("a neighbour"),
                        ))
                    }
                })
            })
            .collect();
        let mut slot = Slot::new(cells.len(), margin.len());
        for (x, &c) in cells.enumerate() {
            slot.states[x] = share(states.cell_at(c as usize).to_vec());
            slot.known[x] = true;
        }
        let n = cells.len();
        World {
            id,
            model,
            grid,
            part,
            mode: config.mode,
            window: Throttle::initial_window(config),
            throttle: Throttle::of(config),
            bug: config.planted_bug,
            ghosts: config.ghosts,
            cells,
            margin,
            nbrs,
            targets,
            neighbours,
            base: step,
            head: step,
            end: step,
            next: vec![step; n].into(),
            recomputes: vec![0; n].into(),
            next_min: if n == 0 { Step::MAX } else { step },
            idle_at: None,
            slots: VecDeque::from([slot]),
            dirty: BTreeMap::new(),
            inbox: BTreeMap::new(),
            counters: WorldCounters::default(),
            log_samples: 0,
            most_held: 0,
            scratch: Vec::new(),
            homes_scratch: Vec::new(),
            advance_scratch: Default::default(),
            prepared: Default::default(),
            record: None,
            origin: step,
            ghost_due: BTreeSet::new(),
            early: None,
            prepare_after_ahead: true,
            waiting: false,
        }
    }

    /// Whether it owns global cell `cell`.
    pub(super) fn is_own(&self, cell: u32) -> bool {
        self.part.owner(cell) == self.id
    }

    /// Global cell `cell`, which it owns, as an own cell.
    pub(super) fn own(&self, cell: u32) -> OwnCell {
        debug_assert!(self.is_own(cell), "cell {cell} is not world {}'s", self.id);
        OwnCell::from_local(self.part.local(cell))
    }

    /// Foreign global cell `cell` as a margin cell; it must be next to an own cell (a ghost
    /// comes only from such a cell: its sender targets the owners of its neighbours).
    pub(super) fn margin_cell(&self, cell: u32) -> MarginCell {
        let position = self
            .margin
            .binary_search(&cell)
            .unwrap_or_else(|_| panic!("cell {cell} is not next to world {}", self.id));
        MarginCell::at(position)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_packed_neighbour_says_what_it_was_built_from() {
        for i in [0u32, 1, 77, (1 << 31) - 1] {
            let x = OwnCell::from_local(i);
            assert_eq!(Nb::own(x).kind(), NbKind::Own(x));
        }
        for i in [0usize, 1, 77, (1 << 31) - 2] {
            let m = MarginCell::at(i);
            assert_eq!(Nb::margin(m).kind(), NbKind::Margin(m));
        }
        assert_eq!(Nb::OUTSIDE.kind(), NbKind::Outside);
        assert_eq!(std::mem::size_of::<Nb>(), 4);
    }
}
