//! Computing and recomputing: a cell's computation, building the states of the next step
//! from outputs and migrations, marking the cells that read a changed state dirty, and
//! Rollback-and-Propagate's re-execution with early cut-off (SPEC.md §K4, §K5).

use super::chunked::Chunked;
use super::index::{cells_around, OwnCell};
use super::keys::MigrationIn;
use super::log::{same_allocation, share, view, Out, Shared};
use super::World;
use crate::frame::{Event, LeftGrid};
use crate::kernel::config::{PlantedBug, RollbackMode};
use crate::kernel::message::{EntityEdit, Homed, Message};
use crate::kernel::partition::WorldId;
use crate::kernel::SharedStates;
use crate::model::{BodyId, CellModel, Step};
use std::collections::BTreeSet;

/// The entities that differ between two id-sorted states of one cell: both versions of an
/// entity whose bits changed, and every entity present on one side only.
fn changed_entities<'a, M: CellModel>(
    old: &'a [M::State],
    new: &'a [M::State],
) -> Vec<&'a M::State> {
    let (mut i, mut j) = (0, 0);
    let mut changed = Vec::new();
    while i < old.len() || j < new.len() {
        match (old.get(i), new.get(j)) {
            (Some(a), Some(b)) if M::id(a) == M::id(b) => {
                if !M::same_bits(a, b) {
                    changed.extend([a, b]);
                }
                i += 1;
                j += 1;
            }
            (Some(a), Some(b)) if M::id(a) > M::id(b) => {
                changed.push(b);
                j += 1;
            }
            (Some(a), _) => {
                changed.push(a);
                i += 1;
            }
            (None, Some(b)) => {
                changed.push(b);
                j += 1;
            }
            (None, None) => unreachable!("the loop runs while one side has entities"),
        }
    }
    changed
}

impl<M: CellModel> World<M> {
    /// Computes own cell `x` at step `s` from the states and ghosts held for `s`.
    pub(super) fn compute(&mut self, x: OwnCell, s: Step) -> Out<M::State, M::Event> {
        let cell = self.cells[x];
        let grid = &*self.grid;
        let slot = &self.slots[self.si(s)];
        let c = grid.coord(cell as usize);
        let nbrs = &self.nbrs[x];
        // From the prepared copy of the step's states if there is one (consecutive slices,
        // the same states), else from the log and the views.
        let (nb, from_copy) = self.prepared.neighbourhood(slot, c, nbrs, s);
        debug_assert!(
            !from_copy
                || (0..27).all(|k| {
                    let (copy, log) = (nb.cells[k], slot.neighbour(nbrs[k]));
                    copy.len() == log.len() && copy.iter().zip(log).all(|(a, b)| M::same_bits(a, b))
                }),
            "the prepared copy holds the step's states, bit for bit"
        );
        let mut events = Vec::new();
        self.scratch.clear();
        self.model
            .step_cell(s, grid, &nb, &mut self.scratch, &mut events);
        if !self.scratch.is_sorted_by_key(|b| M::id(b)) {
            self.scratch.sort_by_key(|b| M::id(b));
        }
        // Each body's home cell at s + 1 (`u32::MAX`: it left the domain).
        let homes = &mut self.homes_scratch;
        homes.clear();
        let mut stays = true;
        for b in &self.scratch {
            match grid.cell_of(M::position(b)) {
                Some(d) => {
                    assert!(
                        d.chebyshev(c) <= 1,
                        "locality contract violated: body {} moved from cell {c:?} to {d:?} in one step",
                        M::id(b)
                    );
                    let d = grid.index(d) as u32;
                    stays &= d == cell;
                    homes.push(d);
                }
                None => {
                    stays = false;
                    homes.push(u32::MAX);
                    events.push(Event {
                        step: s,
                        body: M::id(b),
                        kind: LeftGrid.into(),
                    });
                }
            }
        }
        self.counters.cells_computed += 1;
        if stays {
            // An output bit-identical to the cell's state (bodies at rest, an unchanged cell)
            // is that state's allocation: the log holds an unchanged cell once, whatever the
            // number of steps (SPEC.md §K3).
            let state = &self.slots[self.si(s)].states[x];
            if events.is_empty() && Self::same_states(&self.scratch, view(state)) {
                let bodies = state.clone();
                self.scratch.clear();
                return Out::new(cell, bodies, Vec::new(), events, true);
            }
            // The common case: one allocation, written once, shared with the next state.
            let bodies = (!self.scratch.is_empty())
                .then(|| SharedStates::from_exact(self.scratch.drain(..)));
            return Out::new(cell, bodies, Vec::new(), events, true);
        }
        // Sorted by (home cell, id), without the bodies that left the domain.
        let mut order: Vec<usize> = (0..homes.len()).filter(|&k| homes[k] != u32::MAX).collect();
        let scratch = &self.scratch;
        order.sort_by_key(|&k| (homes[k], M::id(&scratch[k])));
        let mut out_homes: Vec<u32> = order.iter().map(|&k| homes[k]).collect();
        if out_homes.iter().all(|&d| d == cell) {
            out_homes.clear();
        }
        let bodies = (!order.is_empty())
            .then(|| SharedStates::from_exact(order.iter().map(|&k| scratch[k].clone())));
        self.scratch.clear();
        Out::new(cell, bodies, out_homes, events, true)
    }

    /// Whether two outputs are the same (early cut-off and lazy cancellation compare
    /// entities with [`World::same_entity`]).
    pub(super) fn same_out(
        &self,
        a: &Out<M::State, M::Event>,
        b: &Out<M::State, M::Event>,
    ) -> bool {
        let (x, y) = (view(&a.bodies), view(&b.bodies));
        a.events() == b.events()
            && a.homes() == b.homes()
            && x.len() == y.len()
            && x.iter().zip(y).all(|(p, q)| self.same_entity(p, q))
    }

    /// Whether two messages' bodies are the same: the same home cells and, by
    /// [`World::same_entity`], the same states.
    pub(super) fn same_bodies(&self, a: &[Homed<M::State>], b: &[Homed<M::State>]) -> bool {
        a.len() == b.len()
            && a.iter()
                .zip(b)
                .all(|(x, y)| x.cell == y.cell && self.same_entity(&x.state, &y.state))
    }

    /// Bit equality of two entity states — or, under the planted bug
    /// [`PlantedBug::CutoffByIdsOnly`], equality of their ids only.
    pub(super) fn same_entity(&self, a: &M::State, b: &M::State) -> bool {
        if self.bug == PlantedBug::CutoffByIdsOnly {
            M::id(a) == M::id(b)
        } else {
            M::same_bits(a, b)
        }
    }

    pub(super) fn same_states(a: &[M::State], b: &[M::State]) -> bool {
        // Unchanged states share one allocation (K3): then there is nothing to compare.
        a.len() == b.len()
            && (std::ptr::eq(a.as_ptr(), b.as_ptr())
                || a.iter().zip(b).all(|(x, y)| M::same_bits(x, y)))
    }

    /// Rebuilds the state of own cell `d` at `t ≥ base + 1` from the outputs at `t − 1` of the
    /// own cells around it and the migrations into it. Returns the previous state if it
    /// changed.
    pub(super) fn rebuild_state(&mut self, d: u32, t: Step) -> Option<Shared<M::State>> {
        let grid = &*self.grid;
        let i = self.si(t);
        let (prev, cur) = (&self.slots[i - 1], &self.slots[i]);
        let mut v: Vec<M::State> = Vec::new();
        for n in cells_around(grid, d) {
            if self.is_own(n) {
                if let Some(o) = &prev.outs[self.own(n)] {
                    v.extend(o.landing_in(d).iter().cloned());
                }
            }
        }
        for bs in cur
            .foreign_in
            .range(MigrationIn::into_cell(d))
            .map(|(_, bs)| bs)
        {
            v.extend(bs.iter().cloned());
        }
        if !cur.inputs.is_empty() {
            for EntityEdit { id, edit } in cur.inputs.values().flat_map(|i| i.edits.iter()) {
                if let Some(b) = v.iter_mut().find(|b| M::id(b) == *id) {
                    let edited = edit.apply(b);
                    let home = grid
                        .cell_of(M::position(&edited))
                        .map(|c| grid.index(c) as u32);
                    assert!(
                        home == Some(d),
                        "an input at step {t} edits entity {id} out of its home cell: an edit \
                         must keep the entity in its cell (replace the state to move it)"
                    );
                    *b = edited;
                }
            }
            let removed: BTreeSet<BodyId> = cur
                .inputs
                .values()
                .flat_map(|i| i.removes.iter().copied())
                .collect();
            v.retain(|b| !removed.contains(&M::id(b)));
            for input in cur.inputs.values() {
                v.extend(
                    input
                        .adds
                        .iter()
                        .filter(|h| h.cell == d)
                        .map(|h| h.state.clone()),
                );
            }
        }
        v.sort_by_key(|b| M::id(b));
        let x = self.own(d);
        if Self::same_states(&v, self.slots[i].state(x)) {
            return None;
        }
        // Unchanged since the step before: share that state's allocation (SPEC.md §K3).
        let new = if Self::same_states(&v, self.slots[i - 1].state(x)) {
            self.slots[i - 1].states[x].clone()
        } else {
            share(v)
        };
        Some(std::mem::replace(&mut self.slots[i].states[x], new))
    }

    /// The own cells around `cell` whose computation at `s` must be redone because the state
    /// of `cell` at `s` changed from `old` to `new`: `cell` itself if it is own and can produce
    /// something (occupied now, or produced something before); every other own neighbour
    /// that can produce something — in cell mode, only if one of its entities may read a
    /// changed entity (`CellModel::may_affect`, SPEC.md §K4) or it is empty but produced
    /// something before.
    pub(super) fn cells_reading(
        &self,
        cell: u32,
        s: Step,
        old: &[M::State],
        new: &[M::State],
    ) -> Vec<OwnCell> {
        let i = self.si(s);
        let slot = &self.slots[i];
        let filter = self.mode == RollbackMode::Cell;
        let changed = if filter {
            changed_entities::<M>(old, new)
        } else {
            Vec::new()
        };
        let mut reading = Vec::new();
        for n in cells_around(&self.grid, cell) {
            if !self.is_own(n) {
                continue;
            }
            let x = self.own(n);
            let state = slot.state(x);
            let produced = slot.outs[x].as_ref().is_some_and(|o| !o.is_empty());
            let reads = if !filter || n == cell {
                !state.is_empty() || produced
            } else {
                (state.is_empty() && produced)
                    || state
                        .iter()
                        .any(|r| changed.iter().any(|c| self.model.may_affect(r, c)))
            };
            if reads {
                reading.push(x);
            }
        }
        reading
    }

    /// Marks the own `cells` dirty at step `s < head`. Returns whether there were any.
    pub(super) fn mark_dirty(&mut self, s: Step, cells: Vec<OwnCell>) -> bool {
        if cells.is_empty() {
            return false;
        }
        self.dirty.entry(s).or_default().extend(cells);
        true
    }

    /// The state of own cell `d` at `t ≤ head` changed from `old`: re-send its ghost, and if
    /// step `t` was computed, dirty the cells reading it. Returns whether something became
    /// dirty.
    pub(super) fn on_state_change(&mut self, d: u32, t: Step, old: Shared<M::State>) -> bool {
        self.drop_ahead_reading(d, t);
        let x = self.own(d);
        self.ghost_due.insert((t, x));
        if self.delta() {
            // The ghosts of `t + 1` and `t + 2` depend on whether the state changed at `t`
            // and at `t + 1`.
            for u in t + 1..=(t + 2).min(self.head) {
                self.ghost_due.insert((u, x));
            }
        }
        if t >= self.head {
            return false;
        }
        let i = self.si(t);
        let cells = self.cells_reading(d, t, view(&old), self.slots[i].state(x));
        self.mark_dirty(t, cells)
    }

    /// Re-executes the dirty cells of step `s` (optimistic modes).
    pub(super) fn reexecute(&mut self, s: Step, out: &mut Vec<Message<M::State>>) {
        let cells = self.dirty.remove(&s).unwrap_or_default();
        self.counters.steps_computed += 1;
        self.counters.steps_reexecuted += 1;
        let i = self.si(s);
        let mut changed_dst: BTreeSet<u32> = BTreeSet::new();
        let mut changed_mig: BTreeSet<(OwnCell, WorldId)> = BTreeSet::new();
        for x in cells {
            let new = if self.slots[i].state(x).is_empty() {
                Out::empty(self.cells[x])
            } else {
                self.counters.cells_recomputed += 1;
                self.recomputes[x] += 1;
                if let Some(r) = &mut self.record {
                    r.recomputed(s, self.cells[x]);
                }
                self.compute(x, s)
            };
            let mut old = self.slots[i].outs[x]
                .take()
                .unwrap_or_else(|| Out::empty(self.cells[x]));
            // The earlier computation of this cell-step is superseded (its result is kept
            // only if equal, and then it stands for the new computation).
            self.counters.cells_rolled_back += old.computed as u64;
            if self.same_out(&old, &new) {
                old.computed = new.computed;
                self.slots[i].outs[x] = Some(old);
                continue;
            }
            for (d, _) in old.pairs().chain(new.pairs()) {
                if self.is_own(d) {
                    changed_dst.insert(d);
                } else {
                    changed_mig.insert((x, self.part.owner(d)));
                }
            }
            self.slots[i].outs[x] = Some(new);
        }
        for d in changed_dst {
            if let Some(old) = self.rebuild_state(d, s + 1) {
                self.on_state_change(d, s + 1, old);
            }
        }
        for (x, w) in changed_mig {
            self.send_migrate(x, s, w, out);
        }
    }

    /// Prepares the states and views of step `h` for the cells computed at `h` (their hints
    /// and rest flags, SPEC.md §K5).
    pub(super) fn prepare(&mut self, h: Step) {
        let i = self.si(h);
        self.prepared.prepare(
            &*self.model,
            &self.slots[i],
            self.cells.as_slice(),
            &self.margin,
            self.nbrs.as_slice(),
            h,
        );
    }

    /// Whether every entity in the 27 cells around own cell `x` at step `h` is at rest
    /// ([`CellModel::at_rest`]), read from the states themselves: what [`Prepared`] works
    /// out for every cell at once, for the few cells an advance computes after the interior
    /// was computed ahead.
    ///
    /// [`Prepared`]: super::prepared::Prepared
    fn neighbourhood_at_rest(&self, x: OwnCell, h: Step) -> bool {
        let slot = &self.slots[self.si(h)];
        let model = &*self.model;
        self.nbrs[x]
            .iter()
            .all(|&n| slot.neighbour(n).iter().all(|s| model.at_rest(s)))
    }

    /// The output of occupied own cell `x` at step `h`: its state if its whole
    /// neighbourhood is at rest, else its computation (the rest flags prepared for `h`, or
    /// read from the states if `h` is not prepared). (Both callers skip empty cells, whose
    /// output is [`Out::empty`].)
    pub(super) fn compute_or_keep(&mut self, x: OwnCell, h: Step) -> Out<M::State, M::Event> {
        let i = self.si(h);
        debug_assert!(!self.slots[i].state(x).is_empty(), "an occupied cell");
        let keeps = if self.prepared.is_prepared(h) {
            self.prepared.keeps(x, h)
        } else {
            self.neighbourhood_at_rest(x, h)
        };
        if keeps {
            // The model's promise (`CellModel::at_rest`, SPEC.md §4.1 rule 7): the output
            // is the cell's state, bit for bit, and no event. Counted as a computation,
            // which it stands for.
            self.counters.cells_computed += 1;
            let state = self.slots[i].states[x].clone();
            Out::new(self.cells[x], state, Vec::new(), Vec::new(), true)
        } else {
            self.compute(x, h)
        }
    }

    /// Computes step `head` → `head + 1` for every own cell (optimistic modes).
    pub(super) fn advance(&mut self, out: &mut Vec<Message<M::State>>) {
        let h = self.head;
        self.ensure_slot(h + 1);
        self.counters.steps_computed += 1;
        let i = self.si(h);
        let n = self.cells.len();
        // How many own cells' outputs land in each own cell (each output counted once).
        let mut scratch = std::mem::take(&mut self.advance_scratch);
        let landings = &mut scratch.landings;
        landings.reset(n, 0);
        let mut migs: BTreeSet<(OwnCell, WorldId)> = BTreeSet::new();
        // Every cell of step h reads the states of h: their hints and whether they are at
        // rest are worked out once, and again if the interior was computed ahead (views may
        // have changed since) unless what is left, the border (and any cell dropped since),
        // is the smaller part: then it is computed without hints, each cell's rest read from
        // its neighbourhood, rather than every cell prepared again for a few.
        if self.early == Some(h) && !self.prepare_after_ahead {
            self.prepared.clear();
        } else {
            self.prepare(h);
        }
        // The outputs, written into the slot at once (no copy-on-write per cell).
        let outs = &mut scratch.outs;
        debug_assert!(outs.is_empty());
        for x in OwnCell::all(n) {
            // An empty cell was not computed ahead (nor is it computed now).
            let o = if self.slots[i].state(x).is_empty() {
                Out::empty(self.cells[x])
            } else {
                match self.take_ahead(x, h) {
                    Some(o) => o,
                    None => self.compute_or_keep(x, h),
                }
            };
            if o.stays() {
                landings[x] += u32::from(o.bodies.is_some());
            } else {
                let mut last = None;
                for &d in o.homes() {
                    if last == Some(d) {
                        continue;
                    }
                    last = Some(d);
                    if self.is_own(d) {
                        landings[self.own(d)] += 1;
                    } else {
                        migs.insert((x, self.part.owner(d)));
                    }
                }
            }
            outs.push(Some(o));
        }
        self.slots[i].outs = Chunked::drain_from(outs);
        // A straggler may change the states of h: a re-execution computes them afresh.
        self.prepared.clear();
        self.early = None;
        // The state at h + 1 of a cell whose own output alone lands in it is that output (one
        // shared allocation, no copy). The other cells that something lands in, those that
        // also receive early migrations, and every cell when inputs apply at h + 1, take the
        // general rule (`rebuild_state`). Either way a state is the id-sorted union (K1).
        let part = &*self.part;
        let id = self.id;
        let next = &self.slots[i + 1];
        let mut general: BTreeSet<u32> = next
            .foreign_in
            .keys()
            .map(|k| k.dst_cell)
            .chain(
                next.inputs
                    .values()
                    .flat_map(|x| x.adds.iter().map(|h| h.cell))
                    .filter(|&c| part.owner(c) == id),
            )
            .collect();
        // Inputs at h + 1 (rare) may remove ids from any cell: every cell takes the general
        // rule then.
        let inputs = !next.inputs.is_empty();
        debug_assert!(
            next.states.iter().all(Option::is_none),
            "h + 1 is not built yet"
        );
        let states = &mut scratch.states;
        states.clear();
        states.resize(n, None);
        for (x, &k) in landings.enumerate() {
            if k == 0 {
                continue;
            }
            let alone = k == 1
                && self.slots[i].outs[x]
                    .as_ref()
                    .is_some_and(|o| o.stays() && o.bodies.is_some());
            if inputs || !alone || general.contains(&self.cells[x]) {
                general.insert(self.cells[x]);
                continue;
            }
            let bodies = self.slots[i].outs[x]
                .as_ref()
                .and_then(|o| o.bodies.clone());
            states[x.index()] = bodies;
        }
        self.slots[i + 1].states = Chunked::drain_from(states);
        self.advance_scratch = scratch;
        for d in general {
            self.rebuild_state(d, h + 1);
        }
        // Chunks of states and outputs equal to the step before's are shared with it: an
        // unchanged cell costs the log next to nothing (SPEC.md §K3).
        let states = self.slots[i].states.clone();
        self.slots[i + 1]
            .states
            .share_equal(&states, same_allocation);
        if i > 0 {
            let outs = self.slots[i - 1].outs.clone();
            self.slots[i].outs.share_equal(&outs, |a, b| match (a, b) {
                (None, None) => true,
                (Some(a), Some(b)) => a.same_allocation(b),
                _ => false,
            });
        }
        self.head = h + 1;
        for (x, w) in migs {
            self.send_migrate(x, h, w, out);
        }
        for x in OwnCell::all(n) {
            if !self.targets[x].is_empty() {
                self.send_ghost(x, h + 1, out);
            }
        }
    }
}
