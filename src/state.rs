//! The whole domain's state at one step, kept per cell: each cell holds the entities homed
//! in it, sorted by id.

use crate::frame::{Event, LeftGrid};
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

    /// Bins `states` by home cell. Entities outside the grid are returned as [`LeftGrid`]
    /// events at `step` and dropped.
    pub fn binned<M: CellModel<State = S>>(
        grid: &Grid,
        states: impl IntoIterator<Item = S>,
        step: Step,
        events: &mut Vec<Event<M::Event>>,
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
                    kind: LeftGrid.into(),
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

    /// Empties cell `i`, returning its entities.
    pub(crate) fn take_cell(&mut self, i: usize) -> Vec<S> {
        let taken = std::mem::take(&mut self.cells[i]);
        self.count -= taken.len();
        taken
    }

    /// Appends `s` to cell `i` (the cell must be sorted again before it is read).
    pub(crate) fn push_unsorted(&mut self, i: usize, s: S) {
        self.cells[i].push(s);
        self.count += 1;
    }

    /// Sorts cell `i` by id.
    pub(crate) fn sort_cell<M: CellModel<State = S>>(&mut self, i: usize) {
        let cell = &mut self.cells[i];
        if !cell.is_sorted_by_key(|s| M::id(s)) {
            cell.sort_by_key(|s| M::id(s));
        }
    }

    /// Number of cells (the grid's).
    pub fn cell_count(&self) -> usize {
        self.cells.len()
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
        sorted_by_id::<M>(self.cells.iter().flatten())
    }

    /// The canonical state hash (SPEC.md §Hash).
    pub fn hash<M: CellModel<State = S>>(&self) -> u64 {
        canonical_hash::<M>(self.sorted::<M>())
    }
}

/// Sorts `(id, item)` pairs by id (ids unique, so the order is the one id order): a stable
/// least-significant-digit radix sort over the id bytes that differ between the items.
/// Every committed frame sorts all its entities by id; on thousands of ids this is several
/// times cheaper than a comparison sort (few passes, no data-dependent branches).
pub fn sort_by_id<T: Copy>(items: &mut Vec<(u64, T)>) {
    if items.len() < 64 {
        items.sort_unstable_by_key(|p| p.0);
        return;
    }
    let (mut any, mut all) = (0u64, u64::MAX);
    for p in items.iter() {
        any |= p.0;
        all &= p.0;
    }
    let varying = any ^ all;
    let mut buffer: Vec<(u64, T)> = Vec::with_capacity(items.len());
    for shift in (0..64).step_by(8) {
        if (varying >> shift) & 0xff == 0 {
            continue;
        }
        let digit = |id: u64| ((id >> shift) & 0xff) as usize;
        let mut start = [0usize; 256];
        for p in items.iter() {
            start[digit(p.0)] += 1;
        }
        let mut sum = 0;
        for c in start.iter_mut() {
            (*c, sum) = (sum, sum + *c);
        }
        buffer.clear();
        buffer.resize(items.len(), items[0]);
        for p in items.iter() {
            let d = digit(p.0);
            buffer[start[d]] = *p;
            start[d] += 1;
        }
        std::mem::swap(items, &mut buffer);
    }
}

/// `states` (any order) sorted by id, through (id, state) keys without moving the states
/// ([`sort_by_id`]): the order every frame is hashed in.
pub fn sorted_by_id<'a, M: CellModel>(
    states: impl IntoIterator<Item = &'a M::State>,
) -> Vec<&'a M::State> {
    let mut keyed: Vec<(u64, &M::State)> = states.into_iter().map(|s| (M::id(s), s)).collect();
    sort_by_id(&mut keyed);
    keyed.into_iter().map(|k| k.1).collect()
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

#[cfg(test)]
mod tests {
    use super::sort_by_id;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn radix_sort_by_id_gives_the_comparison_sort_order_for_any_ids() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for (n, bits) in [
            (0, 8),
            (5, 8),
            (63, 16),
            (64, 16),
            (1000, 13),
            (5000, 64),
            (3000, 40),
        ] {
            let mut ids: Vec<u64> = Vec::new();
            while ids.len() < n {
                let id = rng.random::<u64>() >> (64 - bits);
                if !ids.contains(&id) {
                    ids.push(id);
                }
            }
            let mut items: Vec<(u64, usize)> =
                ids.iter().enumerate().map(|(k, &id)| (id, k)).collect();
            let mut expected = items.clone();
            expected.sort_unstable_by_key(|p| p.0);
            sort_by_id(&mut items);
            assert_eq!(items, expected, "{n} ids of {bits} bits");
        }
    }
}
