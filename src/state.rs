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
        starts: Vec<u32>,
        target: &mut Vec<u32>,
        step: Step,
        events: &mut Vec<Event<M::Event>>,
    ) -> Vec<u32> {
        Self::targets_visiting::<M>(grid, entities, starts, target, step, events, |_, _, _| {})
    }

    /// [`CellStates::targets`], calling `visit(k, entity, cell)` for each remaining entity
    /// in the order given, `k` its index among them and `cell` its cell (linear index).
    fn targets_visiting<M: CellModel<State = S>>(
        grid: &Grid,
        entities: &mut Vec<S>,
        mut starts: Vec<u32>,
        target: &mut Vec<u32>,
        step: Step,
        events: &mut Vec<Event<M::Event>>,
        mut visit: impl FnMut(usize, &S, usize),
    ) -> Vec<u32> {
        u32::try_from(entities.len()).expect("more than u32::MAX entities");
        // Each entity's cell, then (below) its index in the result.
        target.clear();
        target.reserve(entities.len());
        entities.retain(|s| match grid.cell_of(M::position(s)) {
            Some(c) => {
                let cell = grid.index(c);
                visit(target.len(), s, cell);
                target.push(cell as u32);
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
        let hinted = !hints.is_empty();
        debug_assert!(!hinted || hints.len() == self.entities.len());
        let mut nb = Neighbourhood::new(c, [&[]; 27]);
        let [nx, ny, nz] = grid.dims;
        // A row of slots (slot = 9·(dz + 1) + 3·(dy + 1) + dx + 1) holds the cells x − 1,
        // x and x + 1 of one grid row: consecutive in the linear order, and so are their
        // entities. Cell `x` of the row starting at linear index `r` spans
        // `starts[r + x]..starts[r + x + 1]`; clamping the four bounds' x to `0..=nx`
        // makes the cells outside the grid empty (a bound clamped to 0 equals the next,
        // one clamped to `nx` the previous).
        let xs = [c.x - 1, c.x, c.x + 1, c.x + 2].map(|x| x.clamp(0, nx) as usize);
        for row in 0..9 {
            let (y, z) = (c.y + row as i32 % 3 - 1, c.z + row as i32 / 3 - 1);
            if y < 0 || y >= ny || z < 0 || z >= nz {
                continue;
            }
            let r = (nx * (y + ny * z)) as usize;
            let b = xs.map(|x| self.starts[r + x] as usize);
            for (k, slot) in nb.cells[3 * row..3 * row + 3].iter_mut().enumerate() {
                *slot = &self.entities[b[k]..b[k + 1]];
            }
            if hinted {
                nb.hints[row] = &hints[b[0]..b[3]];
            }
        }
        nb
    }

    /// A walk over the neighbourhoods of this state's cells in ascending linear order
    /// ([`NeighbourhoodWalk::at`]), with hints from `hints` as
    /// [`CellStates::neighbourhood_hinted`] takes them.
    pub fn walk<'a>(&'a self, grid: &Grid, hints: &'a [Hint]) -> NeighbourhoodWalk<'a, S> {
        debug_assert!(hints.is_empty() || hints.len() == self.entities.len());
        NeighbourhoodWalk {
            entities: &self.entities,
            starts: &self.starts,
            hints,
            dims: grid.dims,
            nb: Neighbourhood::new(CellCoord::new(0, 0, 0), [&[]; 27]),
            at: None,
            rows: [None; 9],
            bounds: [[0; 4]; 9],
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
    /// id, [`LeftGrid`] events for entities outside the grid), with what
    /// [`CellStates::rebin_derived`] derives from it. Returns an entity vector to fill
    /// next, emptied, as `rebin` does, and the new state's hash.
    ///
    /// The kept entities are appended to `outputs` (its capacity reused, no new vector):
    /// a cell's entities have unique ids and end sorted by id, so the order they are given
    /// in changes no cell; only the order of the `LeftGrid` events can differ, and no kept
    /// entity raises one (it stays in its cell, inside the grid).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn replace_cells<M: CellModel<State = S>>(
        &mut self,
        grid: &Grid,
        model: &M,
        computed: &[usize],
        mut outputs: Vec<S>,
        step: Step,
        events: &mut Vec<Event<M::Event>>,
        scratch: &mut Scratch,
        derived: Derived<'_>,
    ) -> (Vec<S>, u64) {
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
        self.rebin_derived(grid, model, outputs, step, events, scratch, derived)
    }

    /// [`CellStates::rebin_with`] (the same state, the same events) that also returns the
    /// new state's hash ([`CellStates::hash`], the same value) and fills what `derived`
    /// asks for, all in the passes binning makes anyway: each entity's id is read when its
    /// cell is, its at-rest flag too, its hint when it is copied to its place, and the
    /// hash's serial chain (FNV-1a, byte by byte) runs in the loop that copies the
    /// entities, whose independent work the processor overlaps with it. Returns the
    /// emptied vector `states` came in and the hash.
    ///
    /// # Panics
    /// With more than `u32::MAX` entities.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn rebin_derived<M: CellModel<State = S>>(
        &mut self,
        grid: &Grid,
        model: &M,
        mut states: Vec<S>,
        step: Step,
        events: &mut Vec<Event<M::Event>>,
        scratch: &mut Scratch,
        derived: Derived<'_>,
    ) -> (Vec<S>, u64) {
        let Derived { hints, mut rest } = derived;
        let Scratch {
            target,
            keys,
            buffer,
        } = scratch;
        if let Some(rest) = rest.as_deref_mut() {
            rest.clear();
            rest.resize(grid.cell_count(), true);
        }
        keys.clear();
        keys.reserve(states.len());
        let starts = std::mem::take(&mut self.starts);
        let starts = Self::targets_visiting::<M>(
            grid,
            &mut states,
            starts,
            target,
            step,
            events,
            |k, s, cell| {
                keys.push((M::id(s), k as u32));
                if let Some(rest) = rest.as_deref_mut() {
                    rest[cell] &= model.at_rest(s);
                }
            },
        );
        // Dense unique ids (every built-in scene's): the hash's order is the ids' alone,
        // read from `states`; otherwise it is hashed the usual way once binned.
        let dense = place_by_id(keys, buffer);
        let n = states.len();
        let mut into = std::mem::take(&mut self.entities);
        into.truncate(n);
        let short = n - into.len();
        into.extend_from_slice(&states[..short]);
        // Hints in the binned order, if the model gives one for every entity.
        let mut hints = hints;
        if let Some(h) = hints.as_deref_mut() {
            h.clear();
        }
        let mut hints = hints.filter(|_| states.first().is_some_and(|s| model.hint(s).is_some()));
        if let Some(h) = hints.as_deref_mut() {
            h.resize(n, [0.0; 4]);
        }
        let mut every_hint = true;
        let mut hash = StateHash::new();
        for (k, (s, &t)) in states.iter().zip(target.iter()).enumerate() {
            into[t as usize] = s.clone();
            if let Some(h) = hints.as_deref_mut() {
                match model.hint(s) {
                    Some(hint) => h[t as usize] = hint,
                    None => every_hint = false,
                }
            }
            if dense {
                let e = &states[keys[k].1 as usize];
                hash.u64(M::id(e));
                M::hash_state(e, &mut hash);
            }
        }
        // Each cell sorted by id; the hints of a sorted cell follow its entities.
        for w in starts.windows(2) {
            let (a, b) = (w[0] as usize, w[1] as usize);
            if b - a > 1 {
                into[a..b].sort_by_key(|s| M::id(s));
                if let Some(h) = hints.as_deref_mut() {
                    for (h, s) in h[a..b].iter_mut().zip(&into[a..b]) {
                        *h = model.hint(s).unwrap_or_default();
                    }
                }
            }
        }
        if let Some(h) = hints {
            if !every_hint {
                h.clear();
            }
        }
        *self = CellStates {
            entities: into,
            starts,
        };
        let hash = if dense {
            hash.finish()
        } else {
            self.hash_with::<M>(scratch)
        };
        states.clear();
        (states, hash)
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

/// The neighbourhoods of a state's cells visited in ascending linear order
/// ([`CellStates::walk`]): the same slices and hints as
/// [`CellStates::neighbourhood_hinted`], from one neighbourhood kept and moved along x from
/// each cell to the next one on the same grid row (its slots shifted, only the cells that
/// come into view read from the cell starts), built anew on another row. Building each of
/// a million neighbourhoods from scratch was a tenth of a step.
pub struct NeighbourhoodWalk<'a, S> {
    entities: &'a [S],
    starts: &'a [u32],
    hints: &'a [Hint],
    dims: [i32; 3],
    /// The neighbourhood of the last cell visited.
    nb: Neighbourhood<'a, S>,
    /// The linear index of the last cell visited.
    at: Option<usize>,
    /// Per row of slots, the linear index of its grid row's first cell (x = 0), `None`
    /// for a row outside the grid (its slots and hints stay empty).
    rows: [Option<usize>; 9],
    /// Per row of slots inside the grid, where the cells x − 1, x and x + 1 begin and
    /// where x + 1 ends in the entities (`starts` at x − 1 … x + 2, each x clamped to
    /// `0..=nx`: a cell outside the grid is empty).
    bounds: [[usize; 4]; 9],
}

impl<'a, S> NeighbourhoodWalk<'a, S> {
    /// The neighbourhood of the cell with linear index `i`. Any cell may be asked for;
    /// asking in ascending order, along rows, is what makes it cheap.
    ///
    /// # Panics
    /// If `i` is not a cell of the grid.
    pub fn at(&mut self, i: usize) -> &Neighbourhood<'a, S> {
        let [nx, ny, nz] = self.dims;
        let (starts, entities) = (self.starts, self.entities);
        let clamped = |x: i32| x.clamp(0, nx) as usize;
        let along = match self.at {
            Some(p) if i > p && i - p < (nx - self.nb.centre.x) as usize => Some(i - p),
            _ => None,
        };
        self.at = Some(i);
        if let Some(d) = along {
            // The same grid row: the same rows of slots inside the grid, moved by `d`.
            let x = self.nb.centre.x + d as i32;
            self.nb.centre.x = x;
            for row in 0..9 {
                let Some(r) = self.rows[row] else {
                    continue;
                };
                let b = &mut self.bounds[row];
                let cells = &mut self.nb.cells[3 * row..3 * row + 3];
                match d {
                    1 => {
                        *b = [b[1], b[2], b[3], starts[r + clamped(x + 2)] as usize];
                        cells[0] = cells[1];
                        cells[1] = cells[2];
                        cells[2] = &entities[b[2]..b[3]];
                    }
                    2 => {
                        let (b2, b3) = (starts[r + clamped(x + 1)], starts[r + clamped(x + 2)]);
                        *b = [b[2], b[3], b2 as usize, b3 as usize];
                        cells[0] = cells[2];
                        cells[1] = &entities[b[1]..b[2]];
                        cells[2] = &entities[b[2]..b[3]];
                    }
                    _ => {
                        *b = [x - 1, x, x + 1, x + 2].map(|x| starts[r + clamped(x)] as usize);
                        for (k, cell) in cells.iter_mut().enumerate() {
                            *cell = &entities[b[k]..b[k + 1]];
                        }
                    }
                }
                if !self.hints.is_empty() {
                    self.nb.hints[row] = &self.hints[b[0]..b[3]];
                }
            }
            return &self.nb;
        }
        let i32_index = i32::try_from(i).ok().filter(|&i| i < nx * ny * nz);
        let i = i32_index.unwrap_or_else(|| panic!("cell {i} is not in the grid"));
        let c = CellCoord::new(i % nx, (i / nx) % ny, i / (nx * ny));
        self.nb.centre = c;
        for row in 0..9 {
            let (y, z) = (c.y + row as i32 % 3 - 1, c.z + row as i32 / 3 - 1);
            let cells = &mut self.nb.cells[3 * row..3 * row + 3];
            if y < 0 || y >= ny || z < 0 || z >= nz {
                self.rows[row] = None;
                cells.fill(&[]);
                self.nb.hints[row] = &[];
                continue;
            }
            let r = (nx * (y + ny * z)) as usize;
            self.rows[row] = Some(r);
            let b = [c.x - 1, c.x, c.x + 1, c.x + 2].map(|x| starts[r + clamped(x)] as usize);
            self.bounds[row] = b;
            for (k, cell) in cells.iter_mut().enumerate() {
                *cell = &entities[b[k]..b[k + 1]];
            }
            self.nb.hints[row] = if self.hints.is_empty() {
                &[]
            } else {
                &self.hints[b[0]..b[3]]
            };
        }
        &self.nb
    }
}

/// What [`CellStates::rebin_derived`] computes from the new state besides binning it.
#[derive(Default)]
pub(crate) struct Derived<'a> {
    /// Set to the model's hint of every entity, in the state's order
    /// ([`CellStates::hints`], the same values), or emptied if the model gives none.
    pub hints: Option<&'a mut Vec<Hint>>,
    /// Set to each cell's at-rest flag: whether every entity of the cell is at rest
    /// ([`CellModel::at_rest`]; an empty cell is).
    pub rest: Option<&'a mut Vec<bool>>,
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

    /// A ball of radius 0.1 with id `id` at `p`, at rest.
    fn ball(id: u64, p: Vec3) -> Body {
        Body::new(
            id,
            Shape::Ball { radius: 0.1 },
            Material::default(),
            p,
            Quat::identity(),
        )
    }

    /// Binning as it was done with one vector per cell: push in the given order, then a
    /// stable sort by id per cell.
    fn binned_cell_by_cell(grid: &Grid, bodies: &[Body]) -> (Vec<Vec<Body>>, Vec<u64>) {
        let mut cells = vec![Vec::new(); grid.cell_count()];
        let mut outside = Vec::new();
        for b in bodies {
            match grid.cell_of(b.position.into()) {
                Some(c) => cells[grid.index(c)].push(b.clone()),
                None => outside.push(b.id()),
            }
        }
        for c in &mut cells {
            c.sort_by_key(|b| b.id());
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
                    ball(id, p)
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
                ball(i, p)
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
    fn a_walk_gives_the_neighbourhoods_of_its_cells_hints_included() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        for (size, n) in [
            ([1.0, 1.0, 1.0], 3),
            ([2.0, 1.0, 3.0], 10),
            ([7.0, 3.0, 4.0], 60),
            ([9.0, 5.0, 2.0], 400),
        ] {
            let grid = Grid::covering(Vec3::zeros(), Vec3::new(size[0], size[1], size[2]), 1.0);
            let bodies: Vec<Body> = (0..n)
                .map(|id| {
                    let p = Vec3::new(
                        rng.random_range(0.0..size[0]),
                        rng.random_range(0.0..size[1]),
                        rng.random_range(0.0..size[2]),
                    );
                    ball(id, p)
                })
                .collect();
            let state = CellStates::binned::<RigidBodyModel>(&grid, bodies, 0, &mut Vec::new());
            let hints: Vec<crate::model::Hint> = (0..state.len()).map(|k| [k as f32; 4]).collect();
            // Every cell; every cell with a chance of 1/2, 1/4 (gaps of every length along
            // a row and across rows); the occupied cells.
            let mut walks: Vec<Vec<usize>> = [1.0, 0.5, 0.25]
                .iter()
                .map(|&p| {
                    (0..grid.cell_count())
                        .filter(|_| rng.random_bool(p))
                        .collect()
                })
                .collect();
            walks.push(state.occupied().collect());
            for cells in &walks {
                for hints in [&hints[..], &[]] {
                    let mut walk = state.walk(&grid, hints);
                    for &i in cells {
                        let c = grid.coord(i);
                        let expected = state.neighbourhood_hinted(&grid, c, hints);
                        let nb = walk.at(i);
                        assert_eq!(nb.centre, c);
                        for k in 0..27 {
                            assert_eq!(nb.cells[k], expected.cells[k], "slot {k} of {c:?}");
                            if !expected.cells[k].is_empty() {
                                assert_eq!(nb.cells[k].as_ptr(), expected.cells[k].as_ptr());
                            }
                        }
                        assert_eq!(nb.hints, expected.hints, "hints of {c:?}");
                        for r in 0..9 {
                            assert_eq!(nb.row_hints(r), expected.row_hints(r));
                            if !expected.hints[r].is_empty() {
                                assert_eq!(nb.hints[r].as_ptr(), expected.hints[r].as_ptr());
                            }
                        }
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
