//! The whole domain's state at one step, kept per cell: each cell holds the entities homed
//! in it, sorted by id.

use crate::frame::{Event, EventKind};
use crate::grid::{CellCoord, Grid};
use crate::hash::StateHash;
use crate::model::{CellModel, Neighbourhood, Step};

/// Per-cell entity lists over a grid, each sorted by id.
#[derive(Clone, Debug, PartialEq)]
pub struct CellStates<S> {
    cells: Vec<Vec<S>>,
    count: usize,
}

impl<S: Clone> CellStates<S> {
    /// An empty state for `grid`.
    pub fn empty(grid: &Grid) -> Self {
        CellStates {
            cells: vec![Vec::new(); grid.cell_count()],
            count: 0,
        }
    }

    /// Bins `states` by home cell. Entities outside the grid are returned as `LeftDomain`
    /// events at `step` and dropped.
    pub fn binned<M: CellModel<State = S>>(
        grid: &Grid,
        states: impl IntoIterator<Item = S>,
        step: Step,
        events: &mut Vec<Event>,
    ) -> Self {
        let mut me = Self::empty(grid);
        for s in states {
            match grid.cell_of(M::position(&s)) {
                Some(c) => {
                    me.cells[grid.index(c)].push(s);
                    me.count += 1;
                }
                None => events.push(Event {
                    step,
                    body: M::id(&s),
                    kind: EventKind::LeftDomain,
                }),
            }
        }
        for c in &mut me.cells {
            c.sort_by_key(|s| M::id(s));
        }
        me
    }

    /// The entities homed in cell `c` (sorted by id); empty outside the grid.
    pub fn cell(&self, grid: &Grid, c: CellCoord) -> &[S] {
        if grid.contains(c) {
            &self.cells[grid.index(c)]
        } else {
            &[]
        }
    }

    /// The entities of cell with linear index `i`.
    pub fn cell_at(&self, i: usize) -> &[S] {
        &self.cells[i]
    }

    /// Number of entities.
    pub fn len(&self) -> usize {
        self.count
    }

    /// Whether there are no entities.
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// The 27-cell neighbourhood of `c`.
    pub fn neighbourhood(&self, grid: &Grid, c: CellCoord) -> Neighbourhood<'_, S> {
        let cells =
            std::array::from_fn(|k| self.cell(grid, c.offset(Neighbourhood::<S>::offset(k))));
        Neighbourhood { centre: c, cells }
    }

    /// Linear indices of the non-empty cells, ascending.
    pub fn occupied(&self) -> impl Iterator<Item = usize> + '_ {
        self.cells
            .iter()
            .enumerate()
            .filter(|(_, c)| !c.is_empty())
            .map(|(i, _)| i)
    }

    /// All entities, sorted by id.
    pub fn sorted<M: CellModel<State = S>>(&self) -> Vec<&S> {
        let mut all: Vec<&S> = self.cells.iter().flatten().collect();
        all.sort_by_key(|s| M::id(s));
        all
    }

    /// The canonical state hash (SPEC.md §Hash).
    pub fn hash<M: CellModel<State = S>>(&self) -> u64 {
        canonical_hash::<M>(self.sorted::<M>())
    }
}

/// The canonical hash of a set of entity states given in ascending id order.
pub fn canonical_hash<'a, M: CellModel>(sorted: impl IntoIterator<Item = &'a M::State>) -> u64 {
    let mut h = StateHash::new();
    for s in sorted {
        h.u64(M::id(s));
        M::hash_state(s, &mut h);
    }
    h.finish()
}
