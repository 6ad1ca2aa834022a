//! The whole domain's state at one step, kept per cell: each cell holds the entities homed
//! in it, sorted by id.

use crate::frame::{Event, LeftGrid};
use crate::grid::{CellCoord, Grid};
use crate::hash::StateHash;
use crate::model::{CellModel, Hint, Neighbourhood, Step};

/// Per-cell entity lists over a grid, each sorted by id.
///
/// Stored flat: every entity in one vector, cell after cell in linear cell order, and each
/// cell's range in it. A million entities are one allocation instead of one per occupied
/// cell, and neighbouring cells along x are neighbours in memory.
#[derive(Clone, Debug, PartialEq)]
pub struct CellStates<S> {
    /// The entities, grouped by cell in linear cell order, each group sorted by id.
    entities: Vec<S>,
    /// Cell `i` holds `entities[starts[i]..starts[i + 1]]`; one more than the cell count.
    starts: Vec<u32>,
}

impl<S: Clone> CellStates<S> {
    /// An empty state for `grid`.
    pub fn empty(grid: &Grid) -> Self {
        CellStates {
            entities: Vec::new(),
            starts: vec![0; grid.cell_count() + 1],
        }
    }

    /// Bins `states` by home cell. Entities outside the grid are returned as [`LeftGrid`]
    /// events at `step` and dropped.
    ///
    /// Each cell holds its entities in the order given, then stably sorted by id. Linear in
    /// the number of entities and cells (a counting sort by cell, moved in place).
    ///
    /// # Panics
    /// With more than `u32::MAX` entities.
    pub fn binned<M: CellModel<State = S>>(
        grid: &Grid,
        states: impl IntoIterator<Item = S>,
        step: Step,
        events: &mut Vec<Event<M::Event>>,
    ) -> Self {
        // Collecting a vector reuses its allocation.
        let states = states.into_iter().collect();
        Self::bin::<M>(grid, states, Vec::new(), &mut Vec::new(), step, events)
    }

    /// Replaces this state by `states` binned as [`CellStates::binned`] does (the same
    /// cells in the same order, the same events), reusing this state's allocations (the
    /// binned entities are copied into its previous entity vector), and returns the vector
    /// `states` came in, emptied (its capacity kept), for the caller to fill with the next
    /// states: stepping a million entities then allocates no new memory.
    ///
    /// # Panics
    /// With more than `u32::MAX` entities.
    pub fn rebin<M: CellModel<State = S>>(
        &mut self,
        grid: &Grid,
        states: Vec<S>,
        step: Step,
        events: &mut Vec<Event<M::Event>>,
    ) -> Vec<S> {
        self.rebin_with::<M>(grid, states, step, events, &mut Scratch::default())
    }

    /// [`CellStates::rebin`] with the binning's working memory taken from `scratch` (the
    /// same result): a run that keeps its scratch from step to step allocates nothing here.
    ///
    /// # Panics
    /// With more than `u32::MAX` entities.
    pub fn rebin_with<M: CellModel<State = S>>(
        &mut self,
        grid: &Grid,
        states: Vec<S>,
        step: Step,
        events: &mut Vec<Event<M::Event>>,
        scratch: &mut Scratch,
    ) -> Vec<S> {
        let starts = std::mem::take(&mut self.starts);
        let old = std::mem::take(&mut self.entities);
        let (binned, mut spare) =
            Self::bin_into::<M>(grid, states, old, starts, &mut scratch.target, step, events);
        *self = binned;
        spare.clear();
        spare
    }

    /// [`CellStates::bin`] with the binned entities copied into `into` (its contents are
    /// overwritten, its allocation reused) instead of moved in place: one copy of each
    /// entity to its index, no chains of swaps. Returns the state and the vector `states`
    /// came in (for the caller to reuse).
    fn bin_into<M: CellModel<State = S>>(
        grid: &Grid,
        mut states: Vec<S>,
        mut into: Vec<S>,
        starts: Vec<u32>,
        target: &mut Vec<u32>,
        step: Step,
        events: &mut Vec<Event<M::Event>>,
    ) -> (Self, Vec<S>) {
        let starts = Self::targets::<M>(grid, &mut states, starts, target, step, events);
        // Any entities, as many as `states`, then each overwritten by the one it receives.
        into.truncate(states.len());
        let short = states.len() - into.len();
        into.extend_from_slice(&states[..short]);
        for (s, &t) in states.iter().zip(target.iter()) {
            into[t as usize] = s.clone();
        }
        Self::sort_cells::<M>(&mut into, &starts);
        (
            CellStates {
                entities: into,
                starts,
            },
            states,
        )
    }

    /// Bins `entities` into a state whose cell starts reuse the allocation of `starts`;
    /// `target` is working memory (its contents are overwritten, its capacity reused).
    fn bin<M: CellModel<State = S>>(
        grid: &Grid,
        mut entities: Vec<S>,
        starts: Vec<u32>,
        target: &mut Vec<u32>,
        step: Step,
        events: &mut Vec<Event<M::Event>>,
    ) -> Self {
        let starts = Self::targets::<M>(grid, &mut entities, starts, target, step, events);
        // Moves every entity to its index, one cycle of the permutation at a time.
        for i in 0..entities.len() {
            while target[i] as usize != i {
                let j = target[i] as usize;
                entities.swap(i, j);
                target.swap(i, j);
            }
        }
        Self::sort_cells::<M>(&mut entities, &starts);
        CellStates { entities, starts }
    }

    /// Sorts each cell's entities by id (`starts` as in a state).
    fn sort_cells<M: CellModel<State = S>>(entities: &mut [S], starts: &[u32]) {
        for w in starts.windows(2) {
            if w[1] - w[0] > 1 {
                entities[w[0] as usize..w[1] as usize].sort_by_key(|s| M::id(s));
            }
        }
    }

    /// Drops the entities outside the grid (a [`LeftGrid`] event each, in the order given)
    /// and sets `target` to each remaining entity's index in the binned state (cell by
    /// cell in linear order, each cell in the order given); returns the cell starts, in the
    /// allocation of `starts`.
    fn targets<M: CellModel<State = S>>(
        grid: &Grid,
        entities: &mut Vec<S>,
        mut starts: Vec<u32>,
        target: &mut Vec<u32>,
        step: Step,
        events: &mut Vec<Event<M::Event>>,
    ) -> Vec<u32> {
        u32::try_from(entities.len()).expect("more than u32::MAX entities");
        // Each entity's cell, then (below) its index in the result.
        target.clear();
        target.reserve(entities.len());
        entities.retain(|s| match grid.cell_of(M::position(s)) {
            Some(c) => {
                target.push(grid.index(c) as u32);
                true
            }
            None => {
                events.push(Event {
                    step,
                    body: M::id(s),
                    kind: LeftGrid.into(),
                });
                false
            }
        });
        // Counts at `c + 2`, summed: `starts[c + 1]` is where cell `c` begins. Handing out
        // indices from it leaves there where cell `c` ends (where `c + 1` begins): the
        // starts, with one entry too many at the end.
        starts.clear();
        starts.resize(grid.cell_count() + 2, 0);
        for &c in target.iter() {
            starts[c as usize + 2] += 1;
        }
        let mut sum = 0u32;
        for s in &mut starts {
            sum += *s;
            *s = sum;
        }
        // In the order given, so a cell keeps that order.
        for t in target.iter_mut() {
            let slot = &mut starts[*t as usize + 1];
            *t = *slot;
            *slot += 1;
        }
        starts.pop();
        starts
    }

    /// The entities homed in cell `c` (sorted by id); empty outside the grid.
    pub fn cell(&self, grid: &Grid, c: CellCoord) -> &[S] {
        if grid.contains(c) {
            self.cell_at(grid.index(c))
        } else {
            &[]
        }
    }

    /// The entities of cell with linear index `i`.
    pub fn cell_at(&self, i: usize) -> &[S] {
        &self.entities[self.starts[i] as usize..self.starts[i + 1] as usize]
    }

    /// Number of entities.
    pub fn len(&self) -> usize {
        self.entities.len()
    }

    /// Whether there are no entities.
    pub fn is_empty(&self) -> bool {
        self.entities.is_empty()
    }

    /// The 27-cell neighbourhood of `c`.
    pub fn neighbourhood(&self, grid: &Grid, c: CellCoord) -> Neighbourhood<'_, S> {
        self.neighbourhood_hinted(grid, c, &[])
    }

    /// The 27-cell neighbourhood of `c`, with the hints of its entities taken from `hints`
    /// (one per entity of this state, in its order: [`CellStates::hints`]), or none if
    /// `hints` is empty.
    pub fn neighbourhood_hinted<'a>(
        &'a self,
        grid: &Grid,
        c: CellCoord,
        hints: &'a [Hint],
    ) -> Neighbourhood<'a, S> {
        let mut cells: [&[S]; 27] = [&[]; 27];
        let mut row_hints: [&[Hint]; 9] = [&[]; 9];
        let hinted = !hints.is_empty();
        debug_assert!(!hinted || hints.len() == self.entities.len());
        let [nx, ny, nz] = grid.dims;
        // The x range of the neighbourhood inside the grid (empty for a centre far outside).
        let (x0, x1) = ((c.x - 1).max(0), (c.x + 1).min(nx - 1));
        if x0 > x1 {
            return Neighbourhood {
                centre: c,
                cells,
                hints: row_hints,
            };
        }
        // Row by row along x (slot = 9·(dz + 1) + 3·(dy + 1) + dx + 1): a row's cells are
        // consecutive in the grid's linear order, and so are their entities; one slice of
        // the starts gives the row's cells.
        let first_slot = (x0 - (c.x - 1)) as usize;
        for dz in -1..=1 {
            let z = c.z + dz;
            if z < 0 || z >= nz {
                continue;
            }
            for dy in -1..=1 {
                let y = c.y + dy;
                if y < 0 || y >= ny {
                    continue;
                }
                let row = ((dz + 1) * 9 + (dy + 1) * 3) as usize + first_slot;
                let first = grid.index(CellCoord::new(x0, y, z));
                let starts = &self.starts[first..first + (x1 - x0) as usize + 2];
                let (from, to) = (starts[0] as usize, starts[starts.len() - 1] as usize);
                if hinted {
                    row_hints[(row - first_slot) / 3] = &hints[from..to];
                }
                let mut entities = &self.entities[from..to];
                for (k, w) in starts.windows(2).enumerate() {
                    let (cell, more) = entities.split_at((w[1] - w[0]) as usize);
                    cells[row + k] = cell;
                    entities = more;
                }
            }
        }
        Neighbourhood {
            centre: c,
            cells,
            hints: row_hints,
        }
    }

    /// The model's [`CellModel::hint`] of every entity, in this state's order, into `out`
    /// (emptied first); `out` stays empty if the model gives no hints.
    pub fn hints<M: CellModel<State = S>>(&self, model: &M, out: &mut Vec<Hint>) {
        out.clear();
        let Some(first) = self.entities.first() else {
            return;
        };
        if model.hint(first).is_none() {
            return;
        }
        out.reserve(self.entities.len());
        for s in &self.entities {
            match model.hint(s) {
                Some(h) => out.push(h),
                None => {
                    out.clear();
                    return;
                }
            }
        }
    }

    /// Replaces the cells `computed` (linear indices, ascending) by `outputs`: the result
    /// is what [`CellStates::rebin`] gives for the entities of every other cell followed by
    /// `outputs` (each entity binned to the cell its position lies in, every cell sorted by
    /// id, [`LeftGrid`] events for entities outside the grid). Returns an entity
    /// vector to fill next, emptied, as `rebin` does.
    ///
    /// The kept entities are appended to `outputs` (its capacity reused, no new vector):
    /// a cell's entities have unique ids and end sorted by id, so the order they are given
    /// in changes no cell; only the order of the `LeftGrid` events can differ, and no kept
    /// entity raises one (it stays in its cell, inside the grid).
    pub(crate) fn replace_cells<M: CellModel<State = S>>(
        &mut self,
        grid: &Grid,
        computed: &[usize],
        mut outputs: Vec<S>,
        step: Step,
        events: &mut Vec<Event<M::Event>>,
        scratch: &mut Scratch,
    ) -> Vec<S> {
        let mut next_computed = computed.iter().copied().peekable();
        let mut from = 0usize;
        for i in 0..self.cell_count() {
            if next_computed.peek() == Some(&i) {
                next_computed.next();
                outputs.extend_from_slice(&self.entities[from..self.starts[i] as usize]);
                from = self.starts[i + 1] as usize;
            }
        }
        outputs.extend_from_slice(&self.entities[from..]);
        self.rebin_with::<M>(grid, outputs, step, events, scratch)
    }

    /// Number of cells (the grid's).
    pub fn cell_count(&self) -> usize {
        self.starts.len() - 1
    }

    /// Linear indices of the non-empty cells, ascending.
    pub fn occupied(&self) -> impl Iterator<Item = usize> + '_ {
        self.starts
            .windows(2)
            .enumerate()
            .filter(|(_, w)| w[0] != w[1])
            .map(|(i, _)| i)
    }

    /// All entities, sorted by id.
    pub fn sorted<M: CellModel<State = S>>(&self) -> Vec<&S> {
        sorted_by_id::<M>(&self.entities)
    }

    /// The canonical state hash (SPEC.md §Hash).
    pub fn hash<M: CellModel<State = S>>(&self) -> u64 {
        self.hash_with::<M>(&mut Scratch::default())
    }

    /// [`CellStates::hash`] (the same value) with the id sort's working memory taken from
    /// `scratch`.
    pub fn hash_with<M: CellModel<State = S>>(&self, scratch: &mut Scratch) -> u64 {
        let keys = &mut scratch.keys;
        keys.clear();
        keys.extend(
            self.entities
                .iter()
                .enumerate()
                .map(|(i, s)| (M::id(s), i as u32)),
        );
        if !place_by_id(keys, &mut scratch.buffer) {
            sort_by_id_with(keys, &mut scratch.buffer);
        }
        canonical_hash::<M>(keys.iter().map(|&(_, i)| &self.entities[i as usize]))
    }
}

/// Working memory a run keeps from step to step for binning ([`CellStates::rebin_with`])
/// and hashing ([`CellStates::hash_with`]) its states: stepping a million entities then
/// allocates no new pages (which the kernel would zero) for them each step. Its contents
/// never matter, only its capacity.
#[derive(Debug, Default)]
pub struct Scratch {
    /// Each entity's cell, then its index, while binning.
    target: Vec<u32>,
    /// (id, index in the flat vector) of every entity, sorted by id for the hash.
    keys: Vec<(u64, u32)>,
    /// The radix sort's second buffer for `keys`.
    buffer: Vec<(u64, u32)>,
}

/// Sorts `(id, item)` pairs by id (ids unique, so the order is the one id order): a stable
/// least-significant-digit radix sort over the id bytes that differ between the items.
/// Every committed frame sorts all its entities by id; on thousands of ids this is several
/// times cheaper than a comparison sort (few passes, no data-dependent branches).
pub fn sort_by_id<T: Copy>(items: &mut Vec<(u64, T)>) {
    sort_by_id_with(items, &mut Vec::new());
}

/// Sorts `items` by id as [`sort_by_id`] does when the ids are dense (all within twice
/// their number of each other, as a scene's ids 0, 1, 2 … are): each item goes straight to
/// the slot of its id in `buffer`, one pass instead of one per id byte. Returns `false`,
/// leaving `items` as given (in some order), when the ids are not dense or two are equal.
fn place_by_id<T: Copy>(items: &mut Vec<(u64, T)>, buffer: &mut Vec<(u64, T)>) -> bool {
    let Some(&first) = items.first() else {
        return true;
    };
    let (lo, hi) = items
        .iter()
        .fold((u64::MAX, 0), |(lo, hi), p| (lo.min(p.0), hi.max(p.0)));
    let span = hi - lo;
    if items.len() < 64 || span >= 2 * items.len() as u64 {
        return false;
    }
    // Every slot starts out holding an id that is not its own (`lo + 1` at slot 0, `lo`
    // elsewhere), so a slot is taken exactly when it holds its id.
    let empty = |slot: usize| (lo.wrapping_add(u64::from(slot == 0)), first.1);
    buffer.clear();
    buffer.extend((0..=span as usize).map(empty));
    for &p in items.iter() {
        let slot = (p.0 - lo) as usize;
        if buffer[slot].0 == p.0 {
            return false;
        }
        buffer[slot] = p;
    }
    let n = items.len();
    items.clear();
    items.extend(
        buffer
            .iter()
            .enumerate()
            .filter(|&(slot, p)| p.0 == lo + slot as u64)
            .map(|(_, p)| *p),
    );
    debug_assert_eq!(items.len(), n);
    true
}

/// [`sort_by_id`] with its second buffer given (contents overwritten, capacity reused).
fn sort_by_id_with<T: Copy>(items: &mut Vec<(u64, T)>, buffer: &mut Vec<(u64, T)>) {
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
        std::mem::swap(items, buffer);
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
    use super::{place_by_id, sort_by_id, CellStates};
    use crate::frame::Event;
    use crate::grid::Grid;
    use crate::math::{Quat, Vec3};
    use crate::physics::{Body, EventKind, Material, RigidBodyModel, Shape};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Binning as it was done with one vector per cell: push in the given order, then a
    /// stable sort by id per cell.
    fn binned_cell_by_cell(grid: &Grid, bodies: &[Body]) -> (Vec<Vec<Body>>, Vec<u64>) {
        let mut cells = vec![Vec::new(); grid.cell_count()];
        let mut outside = Vec::new();
        for b in bodies {
            match grid.cell_of(b.position.into()) {
                Some(c) => cells[grid.index(c)].push(b.clone()),
                None => outside.push(b.id),
            }
        }
        for c in &mut cells {
            c.sort_by_key(|b| b.id);
        }
        (cells, outside)
    }

    #[test]
    fn flat_binning_gives_every_cell_the_bodies_of_per_cell_binning_in_the_same_order() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let grid = Grid::covering(Vec3::zeros(), Vec3::new(5.0, 3.0, 4.0), 1.0);
        for (n, ids) in [(0, 1), (1, 1), (40, 10), (500, 60), (3000, 1_000_000)] {
            // Some ids repeat (a contract violation binning must still order stably) and
            // some bodies lie outside the grid.
            let bodies: Vec<Body> = (0..n)
                .map(|_| {
                    let p = Vec3::new(
                        rng.random_range(-1.0f32..6.0),
                        rng.random_range(-1.0f32..4.0),
                        rng.random_range(-1.0f32..5.0),
                    );
                    let id = rng.random_range(0..ids);
                    Body::new(
                        id,
                        Shape::Ball { radius: 0.1 },
                        Material::default(),
                        p,
                        Quat::identity(),
                    )
                })
                .collect();
            let (cells, outside) = binned_cell_by_cell(&grid, &bodies);
            let mut events: Vec<Event<EventKind>> = Vec::new();
            let state = CellStates::binned::<RigidBodyModel>(&grid, bodies.clone(), 4, &mut events);
            for (i, cell) in cells.iter().enumerate() {
                assert_eq!(state.cell_at(i), &cell[..], "cell {i} of {n} bodies");
            }
            let occupied: Vec<usize> = (0..cells.len()).filter(|&i| !cells[i].is_empty()).collect();
            assert_eq!(state.occupied().collect::<Vec<_>>(), occupied);
            assert_eq!(state.len(), n - outside.len());
            let left: Vec<u64> = events.iter().map(|e| e.body).collect();
            assert_eq!(left, outside, "bodies outside the grid, in the given order");
            assert!(events.iter().all(|e| e.step == 4));
            // Rebinning over a state of other bodies gives the same state and events.
            let mut rebinned = CellStates::binned::<RigidBodyModel>(
                &grid,
                bodies.iter().rev().cloned(),
                3,
                &mut Vec::new(),
            );
            let mut again: Vec<Event<EventKind>> = Vec::new();
            let spare = rebinned.rebin::<RigidBodyModel>(&grid, bodies.clone(), 4, &mut again);
            assert!(spare.is_empty());
            assert_eq!(rebinned, state);
            assert_eq!(again, events);
        }
    }

    #[test]
    fn a_neighbourhood_holds_the_27_cells_around_its_centre_in_slot_order() {
        let grid = Grid::covering(Vec3::zeros(), Vec3::new(4.0, 3.0, 5.0), 1.0);
        let bodies: Vec<Body> = (0..grid.cell_count() as u64)
            .map(|i| {
                let c = grid.coord(i as usize);
                let p = Vec3::new(c.x as f32 + 0.5, c.y as f32 + 0.5, c.z as f32 + 0.5);
                Body::new(
                    i,
                    Shape::Ball { radius: 0.1 },
                    Material::default(),
                    p,
                    Quat::identity(),
                )
            })
            .collect();
        let state = CellStates::binned::<RigidBodyModel>(&grid, bodies, 0, &mut Vec::new());
        for x in -1..=4 {
            for y in -1..=3 {
                for z in -1..=5 {
                    let centre = crate::grid::CellCoord::new(x, y, z);
                    let nb = state.neighbourhood(&grid, centre);
                    assert_eq!(nb.centre, centre);
                    for (k, cell) in nb.cells.iter().enumerate() {
                        let at = centre.offset(crate::model::Neighbourhood::<Body>::offset(k));
                        assert_eq!(*cell, state.cell(&grid, at), "slot {k} of {centre:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn placing_dense_ids_gives_the_sort_order_and_refuses_sparse_or_equal_ids() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        for (n, base, gaps) in [(64, 0, 0), (1000, 5, 0), (3000, u64::MAX - 9000, 2)] {
            // `n` ids from `base`, one in `gaps + 1` left out, shuffled.
            let mut items: Vec<(u64, usize)> = (0..n as u64)
                .map(|k| (base + k * (gaps + 1), k as usize))
                .collect();
            for k in (1..items.len()).rev() {
                items.swap(k, rng.random_range(0..=k));
            }
            let mut expected = items.clone();
            expected.sort_unstable_by_key(|p| p.0);
            let mut buffer = Vec::new();
            let dense = place_by_id(&mut items, &mut buffer);
            assert_eq!(dense, gaps == 0, "{n} ids from {base}");
            if dense {
                assert_eq!(items, expected);
            }
        }
        let mut equal: Vec<(u64, usize)> = (0..100).map(|k| (7 + k as u64 % 99, k)).collect();
        let given = equal.clone();
        assert!(!place_by_id(&mut equal, &mut Vec::new()));
        assert_eq!(equal, given, "left as given");
    }

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
