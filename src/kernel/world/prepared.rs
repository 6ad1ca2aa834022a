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
use super::territory::Nb;
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
    /// model gives none.
    hints: Vec<Hint>,
    /// Per own cell, where its hints start in `hints`.
    own_start: Vec<u32>,
    /// Per margin cell, where its hints start in `hints`.
    margin_start: Vec<u32>,
    /// Per own cell, whether every entity it holds is at rest (an empty cell is).
    own_rest: Vec<bool>,
    /// Per margin cell, whether every entity it holds is at rest.
    margin_rest: Vec<bool>,
    /// Per own cell, whether its whole neighbourhood is at rest: it keeps its state.
    own_keeps: Vec<bool>,
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
        self.own_start.clear();
        self.margin_start.clear();
        self.own_rest.clear();
        self.margin_rest.clear();
        self.own_keeps.clear();
        // Where each cell's hints would start, and whether it is at rest.
        let mut total = 0u32;
        let (mut x, mut m) = (0, 0);
        while x < cells.len() || m < margin.len() {
            let own = m == margin.len() || (x < cells.len() && cells[x] < margin[m]);
            let states = if own {
                slot.state(OwnCell::from_local(x as u32))
            } else {
                slot.ghost(MarginCell::at(m))
            };
            let rest = states.iter().all(|s| model.at_rest(s));
            if own {
                self.own_start.push(total);
                self.own_rest.push(rest);
                x += 1;
            } else {
                self.margin_start.push(total);
                self.margin_rest.push(rest);
                m += 1;
            }
            total += states.len() as u32;
        }
        let (mut own_entities, mut computed) = (0, 0);
        for (x, n) in nbrs.iter().enumerate() {
            let len = slot.state(OwnCell::from_local(x as u32)).len();
            own_entities += len;
            // An empty cell is not computed anyway.
            let keeps = len > 0 && self.neighbourhood_at_rest(n);
            self.own_keeps.push(keeps);
            if !keeps {
                computed += len;
            }
        }
        if computed == 0 || computed * 2 < own_entities {
            return;
        }
        let first = (0..cells.len())
            .map(|x| slot.state(OwnCell::from_local(x as u32)))
            .find_map(|s| s.first());
        if first.is_none_or(|s| model.hint(s).is_none()) {
            return;
        }
        self.hints.reserve(total as usize);
        let (mut x, mut m) = (0, 0);
        while x < cells.len() || m < margin.len() {
            let own = m == margin.len() || (x < cells.len() && cells[x] < margin[m]);
            let states = if own {
                x += 1;
                slot.state(OwnCell::from_local(x as u32 - 1))
            } else {
                m += 1;
                slot.ghost(MarginCell::at(m - 1))
            };
            for s in states {
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

    /// Forgets what it holds (the states it describes may change).
    pub(super) fn clear(&mut self) {
        self.step = None;
    }

    /// Whether own cell `x`'s whole neighbourhood is at rest at step `step`: by the
    /// model's promise it keeps its state (`false` if that step is not prepared).
    pub(super) fn keeps(&self, x: OwnCell, step: Step) -> bool {
        self.step == Some(step) && self.own_keeps[x.index()]
    }

    /// Whether every entity of the neighbourhood `nbrs` is at rest.
    fn neighbourhood_at_rest(&self, nbrs: &[Nb; 27]) -> bool {
        nbrs.iter().all(|n| match *n {
            Nb::Outside => true,
            Nb::Own(x) => self.own_rest[x.index()],
            Nb::Margin(m) => self.margin_rest[m.index()],
        })
    }

    /// `nb` (the neighbourhood `nbrs` resolves at step `step`) with the hints of its
    /// entities, if those of `step` are held.
    pub(super) fn attach<'a, S>(
        &'a self,
        mut nb: Neighbourhood<'a, S>,
        nbrs: &[Nb; 27],
        step: Step,
    ) -> Neighbourhood<'a, S> {
        if self.step != Some(step) || self.hints.is_empty() {
            return nb;
        }
        for r in 0..9 {
            let row = 3 * r..3 * r + 3;
            let mut span: Option<(usize, usize)> = None;
            for k in row {
                let start = match nbrs[k] {
                    Nb::Outside => continue,
                    Nb::Own(x) => self.own_start[x.index()],
                    Nb::Margin(m) => self.margin_start[m.index()],
                } as usize;
                let end = start + nb.cells[k].len();
                debug_assert!(span.is_none_or(|(_, e)| e == start), "a row is contiguous");
                span = Some(span.map_or((start, end), |(s, _)| (s, end)));
            }
            if let Some((s, e)) = span {
                nb.hints[r] = &self.hints[s..e];
            }
        }
        nb
    }
}
