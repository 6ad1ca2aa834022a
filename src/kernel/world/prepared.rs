//! What a world computes once about the states of a step it advances from, before its cells'
//! computations read them: the model's hints ([`CellModel::hint`]), handed to each
//! computation row by row ([`Neighbourhood::hints`]) as the reference executor hands them,
//! and which cells hold only entities at rest ([`CellModel::at_rest`]), so that a cell
//! whose whole neighbourhood is at rest keeps its state without being computed (SPEC.md
//! §4.1 rule 7, §K3). Without hints a model recomputes what it needs of each neighbour in
//! each of the up to 27 computations that read it. Neither changes an output: a
//! computation without them (a re-execution, conservative mode) commits the same bits.

use super::index::{MarginCell, OwnCell};
use super::log::Slot;
use super::territory::{Nb, NbKind};
use crate::model::{CellModel, Hint, Neighbourhood, Step};

/// The prepared facts about one step's states of a world's own and margin cells, laid out
/// in ascending global cell order: the cells of one neighbourhood row (consecutive along
/// x, so consecutive in the grid's order, and all own or margin cells) are then
/// consecutive, and so are their hints.
#[derive(Debug, Default)]
pub(super) struct Prepared {
    /// The step whose states they describe (`None`: nothing held).
    step: Option<Step>,
    /// The hints of every entity, cell after cell in ascending global order; empty if the
    /// model gives none (or they are not worth computing this step).
    hints: Vec<Hint>,
    /// Per own cell, its facts.
    own: Vec<CellFacts>,
    /// Per margin cell, its facts.
    margin: Vec<CellFacts>,
    /// Per own cell, whether its whole neighbourhood is at rest: it keeps its state.
    own_keeps: Vec<bool>,
}

/// What is prepared about one own or margin cell.
#[derive(Clone, Copy, Debug)]
struct CellFacts {
    /// Where its entities' hints start in [`Prepared::hints`].
    start: u32,
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

impl Prepared {
    /// Prepares the states of step `step` held in `slot`: `cells` are the world's own
    /// cells and `margin` its margin cells (global indices, each ascending), `nbrs` each
    /// own cell's neighbourhood. Hints are computed when most entities of the own cells are
    /// in cells to compute (each is read by every computed neighbourhood that holds it),
    /// not for a territory mostly at rest, as the reference decides.
    pub(super) fn prepare<M: CellModel>(
        &mut self,
        model: &M,
        slot: &Slot<M::State, M::Event>,
        cells: &[u32],
        margin: &[u32],
        nbrs: &[[Nb; 27]],
        step: Step,
    ) {
        debug_assert!(cells.is_sorted() && margin.is_sorted());
        self.step = Some(step);
        self.hints.clear();
        self.own.clear();
        self.margin.clear();
        self.own_keeps.clear();
        // Where each cell's hints would start, and whether it is at rest.
        let mut total = 0u32;
        for n in in_global_order(cells, margin) {
            let states = slot.neighbour(n);
            let facts = CellFacts {
                start: total,
                rest: states.iter().all(|s| model.at_rest(s)),
            };
            match n.kind() {
                NbKind::Own(_) => self.own.push(facts),
                _ => self.margin.push(facts),
            }
            total += states.len() as u32;
        }
        let (mut own_entities, mut computed) = (0, 0);
        for (x, n) in nbrs.iter().enumerate() {
            let len = slot.state(OwnCell::from_local(x as u32)).len();
            own_entities += len;
            // An empty cell is not computed anyway.
            let keeps = len > 0 && n.iter().all(|&k| self.facts(k).is_none_or(|f| f.rest));
            self.own_keeps.push(keeps);
            if !keeps {
                computed += len;
            }
        }
        if computed == 0 || computed * 2 < own_entities {
            return;
        }
        self.hints.reserve(total as usize);
        for n in in_global_order(cells, margin) {
            for s in slot.neighbour(n) {
                match model.hint(s) {
                    Some(h) => self.hints.push(h),
                    None => {
                        // A model gives hints for all its states or for none.
                        self.hints.clear();
                        return;
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
    fn facts(&self, n: Nb) -> Option<&CellFacts> {
        match n.kind() {
            NbKind::Outside => None,
            NbKind::Own(x) => Some(&self.own[x.index()]),
            NbKind::Margin(m) => Some(&self.margin[m.index()]),
        }
    }

    /// Gives `nb` (the neighbourhood `nbrs` resolves at step `step`) the hints of its
    /// entities, if those of `step` are held (in place: a neighbourhood is some 600 bytes).
    pub(super) fn attach<'a, S>(
        &'a self,
        nb: &mut Neighbourhood<'a, S>,
        nbrs: &[Nb; 27],
        step: Step,
    ) {
        if self.step != Some(step) || self.hints.is_empty() {
            return;
        }
        for (r, row) in nbrs.chunks_exact(3).enumerate() {
            // A row's cells are consecutive in the global order, so are their hints: the
            // row's first cell inside the grid starts them, the row's entities count them.
            let len: usize = nb.cells[3 * r..3 * r + 3].iter().map(|c| c.len()).sum();
            if len == 0 {
                continue;
            }
            let Some(first) = row.iter().find_map(|&n| self.facts(n)) else {
                continue;
            };
            debug_assert!(
                {
                    let mut end = first.start as usize;
                    row.iter().zip(&nb.cells[3 * r..3 * r + 3]).all(|(&n, c)| {
                        self.facts(n).is_none_or(|f| {
                            let contiguous = f.start as usize == end;
                            end += c.len();
                            contiguous
                        })
                    })
                },
                "a row is contiguous"
            );
            let start = first.start as usize;
            nb.hints[r] = &self.hints[start..start + len];
        }
    }
}
