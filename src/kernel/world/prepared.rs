//! What a world computes once about the states of a step it advances from, before its cells'
//! computations read them: the model's hints ([`CellModel::hint`]), handed to each
//! computation row by row ([`Neighbourhood::hints`]) as the reference executor hands them,
//! which cells hold only entities at rest ([`CellModel::at_rest`]), so that a cell whose
//! whole neighbourhood is at rest keeps its state without being computed (SPEC.md §4.1
//! rule 7, §K3), and a copy of the states themselves in one array, so that a computation
//! reads its 27 cells as consecutive slices of it (a row's three cells side by side, as the
//! reference executor's one array holds them) instead of from 27 allocations scattered in
//! memory. Without hints a model recomputes what it needs of each neighbour in each of the
//! up to 27 computations that read it. None of this changes an output: a computation
//! without it (a re-execution, conservative mode) reads the same states and commits the
//! same bits.

use super::index::{MarginCell, OwnCell};
use super::log::Slot;
use super::territory::{Nb, NbKind};
use crate::grid::CellCoord;
use crate::model::{CellModel, Hint, Neighbourhood, Step};

/// The prepared facts about one step's states of a world's own and margin cells, laid out
/// in ascending global cell order: the cells of one neighbourhood row (consecutive along
/// x, so consecutive in the grid's order, and all own or margin cells) are then
/// consecutive, and so are their hints and their states in the copy.
#[derive(Debug)]
pub(super) struct Prepared<S> {
    /// The step whose states they describe (`None`: nothing held).
    step: Option<Step>,
    /// The hints of every entity, cell after cell in ascending global order; empty if the
    /// model gives none (or they are not worth computing this step).
    hints: Vec<Hint>,
    /// A copy of every entity's state, cell after cell in ascending global order (the
    /// order of `hints`); empty (and its memory given back) when not worth copying this
    /// step: when most entities keep their states, or the cells to compute hold more than
    /// [`SPARSE_ENTITIES_PER_CELL`] entities each on average.
    states: Vec<S>,
    /// Per own cell, its facts.
    own: Vec<CellFacts>,
    /// Per margin cell, its facts.
    margin: Vec<CellFacts>,
    /// Per own cell, whether its whole neighbourhood is at rest: it keeps its state.
    own_keeps: Vec<bool>,
}

impl<S> Default for Prepared<S> {
    fn default() -> Self {
        Prepared {
            step: None,
            hints: Vec::new(),
            states: Vec::new(),
            own: Vec::new(),
            margin: Vec::new(),
            own_keeps: Vec::new(),
        }
    }
}

/// The most entities per computed cell, on average, for which [`Prepared`] copies the
/// states of a step into one array.
const SPARSE_ENTITIES_PER_CELL: usize = 2;

/// What is prepared about one own or margin cell.
#[derive(Clone, Copy, Debug)]
struct CellFacts {
    /// Where its entities' hints and states start in [`Prepared::hints`] and
    /// [`Prepared::states`].
    start: u32,
    /// How many entities it holds.
    len: u32,
    /// Whether every entity it holds is at rest (an empty cell is).
    rest: bool,
}

/// The own and margin cells (`cells`, `margin`: global indices, each ascending) in ascending
/// global order.
fn in_global_order<'a>(cells: &'a [u32], margin: &'a [u32]) -> impl Iterator<Item = Nb> + 'a {
    let (mut x, mut m) = (0, 0);
    std::iter::from_fn(move || {
        let own = x < cells.len() && (m == margin.len() || cells[x] < margin[m]);
        if own {
            x += 1;
            Some(Nb::own(OwnCell::from_local(x as u32 - 1)))
        } else if m < margin.len() {
            m += 1;
            Some(Nb::margin(MarginCell::at(m - 1)))
        } else {
            None
        }
    })
}

impl<S: Clone> Prepared<S> {
    /// Prepares the states of step `step` held in `slot`: `cells` are the world's own
    /// cells and `margin` its margin cells (global indices, each ascending), `nbrs` each
    /// own cell's neighbourhood. Hints are computed when most entities of the own cells are
    /// in cells to compute (each is read by every computed neighbourhood that holds it),
    /// not for a territory mostly at rest, as the reference decides; the states are copied
    /// under the same condition if, besides, the cells to compute hold at most
    /// [`SPARSE_ENTITIES_PER_CELL`] entities each on average (a sparse scene).
    pub(super) fn prepare<M: CellModel<State = S>>(
        &mut self,
        model: &M,
        slot: &Slot<S, M::Event>,
        cells: &[u32],
        margin: &[u32],
        nbrs: &[[Nb; 27]],
        step: Step,
    ) {
        debug_assert!(cells.is_sorted() && margin.is_sorted());
        self.step = Some(step);
        self.hints.clear();
        self.states.clear();
        self.own.clear();
        self.margin.clear();
        self.own_keeps.clear();
        // Where each cell's hints would start, and whether it is at rest.
        let mut total = 0u32;
        for n in in_global_order(cells, margin) {
            let states = slot.neighbour(n);
            let facts = CellFacts {
                start: total,
                len: states.len() as u32,
                rest: states.iter().all(|s| model.at_rest(s)),
            };
            match n.kind() {
                NbKind::Own(_) => self.own.push(facts),
                _ => self.margin.push(facts),
            }
            total += states.len() as u32;
        }
        let (mut own_entities, mut computed, mut computed_cells) = (0, 0, 0);
        for (x, n) in nbrs.iter().enumerate() {
            let len = self.own[x].len as usize;
            own_entities += len;
            // An empty cell is not computed anyway. Its own facts first: in a scene in
            // motion they decide at once, where its neighbours (many of them empty, so at
            // rest) would be read one by one until a moving one is met.
            let keeps = len > 0
                && self.own[x].rest
                && n.iter().all(|&k| self.facts(k).is_none_or(|f| f.rest));
            self.own_keeps.push(keeps);
            if !keeps {
                computed += len;
                computed_cells += usize::from(len > 0);
            }
        }
        let worth = computed > 0 && computed * 2 >= own_entities;
        // The copy pays where cells hold few entities each (a sparse scene: the 27 cells a
        // computation reads are mostly a load each); in fuller cells the physics of their
        // entities outweighs the loads, and copying them all costs more than it saves.
        let copy = worth && computed <= SPARSE_ENTITIES_PER_CELL * computed_cells;
        if !copy {
            // Scratch of one step: not held through a run's dense or resting phases.
            self.states = Vec::new();
        }
        if !worth {
            return;
        }
        self.hints.reserve(total as usize);
        if copy {
            self.states.reserve(total as usize);
        }
        let mut hinted = true;
        for n in in_global_order(cells, margin) {
            if !copy && !hinted {
                break;
            }
            let states = slot.neighbour(n);
            if copy {
                self.states.extend_from_slice(states);
            }
            if hinted {
                for s in states {
                    match model.hint(s) {
                        Some(h) => self.hints.push(h),
                        None => {
                            // A model gives hints for all its states or for none.
                            self.hints.clear();
                            hinted = false;
                            break;
                        }
                    }
                }
            }
        }
    }

    /// Whether the states of step `step` are prepared.
    pub(super) fn is_prepared(&self, step: Step) -> bool {
        self.step == Some(step)
    }

    /// Forgets what it holds (the states it describes may change).
    pub(super) fn clear(&mut self) {
        self.step = None;
    }

    /// Whether own cell `x`'s whole neighbourhood is at rest at step `step`: by the
    /// model's promise it keeps its state (`false` if that step is not prepared).
    pub(super) fn keeps(&self, x: OwnCell, step: Step) -> bool {
        self.step == Some(step) && self.own_keeps[x.index()]
    }

    /// The facts of neighbour `n` (`None` outside the grid).
    #[inline]
    fn facts(&self, n: Nb) -> Option<&CellFacts> {
        match n.kind() {
            NbKind::Outside => None,
            NbKind::Own(x) => Some(&self.own[x.index()]),
            NbKind::Margin(m) => Some(&self.margin[m.index()]),
        }
    }

    /// The neighbourhood of `centre` (its cells `nbrs`) at step `step`, whose states `slot`
    /// holds: its cells taken from the copy if the copy of `step` is held (then `true`
    /// comes with it), else from `slot`; its rows' hints if those of `step` are held.
    pub(super) fn neighbourhood<'a, E: Clone>(
        &'a self,
        slot: &'a Slot<S, E>,
        centre: CellCoord,
        nbrs: &[Nb; 27],
        step: Step,
    ) -> (Neighbourhood<'a, S>, bool) {
        let held = self.step == Some(step);
        let from_copy = held && !self.states.is_empty();
        let hinted = held && !self.hints.is_empty();
        let mut nb = if from_copy {
            Neighbourhood::new(centre, [&[][..]; 27])
        } else {
            Neighbourhood::new(centre, std::array::from_fn(|k| slot.neighbour(nbrs[k])))
        };
        if from_copy || hinted {
            self.fill_rows(&mut nb, nbrs, from_copy, hinted);
        }
        (nb, from_copy)
    }

    /// Gives `nb` (the neighbourhood `nbrs` resolves at the prepared step) its cells from
    /// the copy (`from_copy`) and its rows' hints (`hinted`), in one pass over the 27
    /// cells' facts: a row's cells are consecutive in the global order, so are their
    /// states in the copy and their hints (the row's first cell inside the grid starts
    /// them, its cells' entities count them).
    fn fill_rows<'a>(
        &'a self,
        nb: &mut Neighbourhood<'a, S>,
        nbrs: &[Nb; 27],
        from_copy: bool,
        hinted: bool,
    ) {
        for (r, row) in nbrs.chunks_exact(3).enumerate() {
            let (mut first, mut len) = (None, 0usize);
            for (j, &n) in row.iter().enumerate() {
                if let Some(f) = self.facts(n) {
                    let start = f.start as usize;
                    debug_assert!(
                        first.is_none_or(|s| s + len == start),
                        "a row is contiguous"
                    );
                    if from_copy {
                        nb.cells[3 * r + j] = &self.states[start..start + f.len as usize];
                    }
                    first.get_or_insert(start);
                    len += f.len as usize;
                }
            }
            // (An empty row's hints are an empty slice either way.)
            if let (true, Some(start)) = (hinted, first) {
                nb.hints[r] = &self.hints[start..start + len];
            }
        }
    }
}
