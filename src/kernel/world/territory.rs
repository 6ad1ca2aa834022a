//! A world's territory: its own cells, the foreign cells next to them (its margin), each own
//! cell's neighbourhood resolved once, and the worlds it exchanges ghosts with (SPEC.md §K2).

use super::log::{share, Slot};
use super::World;
use crate::grid::Grid;
use crate::kernel::config::KernelConfig;
use crate::kernel::counters::WorldCounters;
use crate::kernel::partition::{Partition, WorldId};
use crate::model::{CellModel, Neighbourhood, Step};
use crate::state::CellStates;
use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::sync::Arc;

/// Where the state of one neighbour of an own cell is held.
#[derive(Clone, Copy, Debug)]
pub(super) enum Nb {
    /// Outside the grid: always empty.
    Outside,
    /// An own cell (its local index).
    Own(u32),
    /// A margin cell (its index in `World::margin`).
    Margin(u32),
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
        let cells = part.cells_of(id).to_vec();
        let targets: Vec<Vec<WorldId>> = cells
            .iter()
            .map(|&c| {
                let mut t: Vec<WorldId> = grid
                    .neighbours(grid.coord(c as usize))
                    .map(|n| part.owner_of(&grid, n))
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
            .flat_map(|&c| grid.neighbours(grid.coord(c as usize)))
            .map(|n| grid.index(n) as u32)
            .filter(|&n| part.owner(n) != id)
            .collect();
        margin.sort_unstable();
        margin.dedup();
        let nbrs: Vec<[Nb; 27]> = cells
            .iter()
            .map(|&cell| {
                let c = grid.coord(cell as usize);
                std::array::from_fn(|k| {
                    let n = c.offset(Neighbourhood::<M::State>::offset(k));
                    if !grid.contains(n) {
                        return Nb::Outside;
                    }
                    let ni = grid.index(n) as u32;
                    if part.owner(ni) == id {
                        Nb::Own(part.local(ni))
                    } else {
                        Nb::Margin(margin.binary_search(&ni).expect("a neighbour") as u32)
                    }
                })
            })
            .collect();
        let mut slot = Slot::new(cells.len(), margin.len());
        for (x, &c) in cells.iter().enumerate() {
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
            window: config.window.max(1),
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
            next: vec![step; n],
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
            record: None,
            origin: step,
            ghost_due: BTreeSet::new(),
        }
    }

    pub(super) fn is_own(&self, cell: u32) -> bool {
        self.part.owner(cell) == self.id
    }

    /// The index in `margin` of foreign cell `cell`, which must be next to an own cell (a
    /// ghost comes only from such a cell: its sender targets the owners of its neighbours).
    pub(super) fn margin_index(&self, cell: u32) -> usize {
        self.margin
            .binary_search(&cell)
            .unwrap_or_else(|_| panic!("cell {cell} is not next to world {}", self.id))
    }
}
