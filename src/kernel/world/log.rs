//! The per-step log of a world: for every step held, each own cell's state and output, the
//! views of the margin cells, the migrations in, the inputs, and the messages received and
//! sent (SPEC.md §K3); reading committed steps and fossil collection.

use super::chunked::Chunked;
use super::index::{MarginCell, OwnCell, PerOwnCell};
use super::keys::{MigrationIn, RecvKey, SentKey};
use super::territory::{Nb, NbKind};
use super::World;
use crate::frame::Event;
use crate::kernel::message::{Bodies, EntityEdit, Homed};
use crate::kernel::SharedStates;
use crate::model::{BodyId, CellModel, Step};
use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

/// Id-sorted states in one shared allocation (`None`: empty, nothing allocated). A cell's
/// output and its state at the next step are the same allocation when every body stays in
/// the cell and nothing else lands there — the common case, which then copies nothing.
pub(super) type Shared<S> = Option<SharedStates<S>>;

/// The states of `s` as a slice.
#[inline]
pub(super) fn view<S>(s: &Shared<S>) -> &[S] {
    s.as_deref().unwrap_or(&[])
}

/// `v` as shared states (`None` when empty).
pub(super) fn share<S>(v: Vec<S>) -> Shared<S> {
    (!v.is_empty()).then(|| SharedStates::from_vec(v))
}

/// The output of one cell computation: the bodies it homes at the next step, sorted by
/// (home cell, id), their home cells, and the events it raised. Home cells and events are
/// rare (most outputs stay in their cell and raise nothing) and live out of line: an output
/// takes 24 bytes in the log's per-cell header (a thin pointer to its bodies), not 72.
#[derive(Clone, Debug)]
pub(super) struct Out<S, E> {
    /// The cell computed (global).
    pub(super) cell: u32,
    /// Whether a cell computation produced it (an empty cell's output is not computed).
    pub(super) computed: bool,
    /// The bodies it homes at the next step, sorted by (home cell, id).
    pub(super) bodies: Shared<S>,
    /// Its home cells and events, if either is not empty.
    rare: Option<Box<Rare<E>>>,
}

/// The rare parts of an [`Out`].
#[derive(Clone, Debug)]
struct Rare<E> {
    /// The home cell (global) of each body; empty exactly when every body stays in the cell.
    homes: Vec<u32>,
    /// The events the computation raised.
    events: Vec<Event<E>>,
}

impl<S, E> Out<S, E> {
    /// The output of cell `cell`: `bodies` with their home cells `homes` (empty exactly when
    /// every body stays in `cell`) and `events`.
    pub(super) fn new(
        cell: u32,
        bodies: Shared<S>,
        homes: Vec<u32>,
        events: Vec<Event<E>>,
        computed: bool,
    ) -> Self {
        let rare =
            (!homes.is_empty() || !events.is_empty()).then(|| Box::new(Rare { homes, events }));
        Out {
            cell,
            computed,
            bodies,
            rare,
        }
    }

    /// The output of empty cell `cell`: nothing, not computed.
    #[inline]
    pub(super) fn empty(cell: u32) -> Self {
        Out {
            cell,
            computed: false,
            bodies: None,
            rare: None,
        }
    }

    /// The home cell (global) of each of `bodies`; empty exactly when every body stays in
    /// the cell computed.
    pub(super) fn homes(&self) -> &[u32] {
        self.rare.as_ref().map_or(&[][..], |r| &r.homes)
    }

    /// The events the computation raised.
    pub(super) fn events(&self) -> &[Event<E>] {
        self.rare.as_ref().map_or(&[][..], |r| &r.events)
    }

    /// Bytes held out of line for its home cells and events.
    fn rare_bytes(&self) -> usize {
        self.rare.as_ref().map_or(0, |r| {
            std::mem::size_of::<Rare<E>>()
                + r.homes.len() * 4
                + r.events.len() * std::mem::size_of::<Event<E>>()
        })
    }

    /// Whether it is `other` allocation for allocation: the same cell, computed alike, the
    /// same bodies' allocation, and neither has home cells or events.
    pub(super) fn same_allocation(&self, other: &Self) -> bool {
        self.cell == other.cell
            && self.computed == other.computed
            && self.rare.is_none()
            && other.rare.is_none()
            && same_allocation(&self.bodies, &other.bodies)
    }

    /// Whether it homes no body and raised no event.
    pub(super) fn is_empty(&self) -> bool {
        self.bodies.is_none() && self.events().is_empty()
    }

    /// Whether every body it homes stays in the cell computed.
    pub(super) fn stays(&self) -> bool {
        self.homes().is_empty()
    }

    /// `(home cell, state)` of every body, sorted by (cell, id).
    pub(super) fn pairs(&self) -> impl Iterator<Item = (u32, &S)> + '_ {
        view(&self.bodies)
            .iter()
            .enumerate()
            .map(|(k, b)| (self.homes().get(k).copied().unwrap_or(self.cell), b))
    }

    /// The bodies homed in `cell`.
    pub(super) fn landing_in(&self, cell: u32) -> &[S] {
        let all = view(&self.bodies);
        if self.stays() {
            return if cell == self.cell { all } else { &[] };
        }
        let lo = self.homes().partition_point(|c| *c < cell);
        let hi = self.homes().partition_point(|c| *c <= cell);
        &all[lo..hi]
    }
}

/// One received positive version of a message identity.
#[derive(Debug)]
pub(super) struct Version<S> {
    /// Its sequence number: the highest live one is effective.
    pub(super) seq: u32,
    /// What it carries.
    pub(super) content: Carried<S>,
    /// Delta ghosts: its `follows` flag (a ghost of the next step is on its way).
    pub(super) follows: bool,
}

/// What a received version carries.
#[derive(Debug)]
pub(super) enum Carried<S> {
    /// A migration's bodies with their home cells.
    Bodies(Bodies<S>),
    /// A ghost, as the view of its cell (`None`: empty) that the slots take — shared, not
    /// copied — while it is effective; within a process, the sender's logged state itself.
    View(Shared<S>),
}

impl<S> Version<S> {
    /// A migration's bodies (none for a ghost).
    pub(super) fn bodies(&self) -> &[Homed<S>] {
        match &self.content {
            Carried::Bodies(b) => b,
            Carried::View(_) => &[],
        }
    }
}

/// What a world has received under one identity (kind, step, source cell).
#[derive(Debug)]
pub(super) struct Recv<S> {
    /// Live positive versions.
    pub(super) positives: Vec<Version<S>>,
    /// Anti-messages that arrived before their positive twin.
    pub(super) antis: Vec<u32>,
}

impl<S> Default for Recv<S> {
    fn default() -> Self {
        Recv {
            positives: Vec::new(),
            antis: Vec::new(),
        }
    }
}

impl<S> Recv<S> {
    /// The effective version: the live positive with the highest sequence number.
    pub(super) fn effective(&self) -> Option<&Version<S>> {
        self.positives.iter().max_by_key(|p| p.seq)
    }
}

/// The last version sent under one identity (kind, step, source cell, destination world).
#[derive(Debug)]
pub(super) struct Sent<S> {
    /// The sequence number of the last version sent.
    pub(super) seq: u32,
    /// The content of the live version (`None`: cancelled, or nothing sent).
    pub(super) live: Option<Live<S>>,
    /// The live version's `follows` flag.
    pub(super) follows: bool,
}

/// The content of a message sent.
#[derive(Clone, Debug)]
pub(super) enum Live<S> {
    /// A migration's bodies, shared with the messages and the receivers' logs.
    Bodies(Bodies<S>),
    /// A ghost: the state of its cell, shared with the cell's log (the message itself
    /// carries a copy that its receivers turn into their views).
    State(Shared<S>),
}

/// Everything a world holds about one step.
#[derive(Debug)]
pub(super) struct Slot<S, E> {
    /// The state of each own cell at this step (chunks equal to the step before's are
    /// shared with it).
    pub(super) states: Chunked<OwnCell, Shared<S>>,
    /// The output of each own cell's computation at this step (`None`: not computed yet;
    /// chunks equal to the step before's are shared with it).
    pub(super) outs: Chunked<OwnCell, Option<Out<S, E>>>,
    /// Conservative mode: whether each own cell's state at this step is known (final).
    pub(super) known: PerOwnCell<bool>,
    /// The view of each margin cell (indexed by [`MarginCell`]) at this step (K4: the
    /// effective ghost of the step, else — optimistic modes — the view of the step before;
    /// `None`: empty). Shared, not copied, between the steps that inherit it, and (within a
    /// process) with the sender's log; chunk by chunk with the step before's.
    pub(super) ghosts: Chunked<MarginCell, Shared<S>>,
    /// Conservative mode: the foreign cells (global) whose ghost of this step has arrived.
    pub(super) ghost_known: BTreeSet<u32>,
    /// The bodies migrating in at this step, by own destination cell and foreign source
    /// cell.
    pub(super) foreign_in: BTreeMap<MigrationIn, Vec<S>>,
    /// Conservative mode: the foreign cells (global) whose migrations into this step are
    /// known (arrived, or known to be none).
    pub(super) migrate_known: BTreeSet<u32>,
    /// What it received about this step, by kind and source cell.
    pub(super) recv: BTreeMap<RecvKey, Recv<S>>,
    /// What it sent about this step, by kind, source cell and destination world.
    pub(super) sent: BTreeMap<SentKey, Sent<S>>,
    /// The inputs at this step, by sequence number.
    pub(super) inputs: BTreeMap<u32, InputEntry<S>>,
}

/// An input applied to a slot: the entities it edits, the ids it removes and the (home cell,
/// state) pairs it adds.
#[derive(Debug)]
pub(super) struct InputEntry<S> {
    /// Edits, applied first, each to the state its entity has at the step.
    pub(super) edits: Vec<EntityEdit<S>>,
    /// Ids removed (or replaced) next.
    pub(super) removes: Vec<BodyId>,
    /// States added last, with their home cells.
    pub(super) adds: Bodies<S>,
}

impl<S> InputEntry<S> {
    /// The parts of input message `msg`.
    pub(super) fn of(msg: crate::kernel::Message<S>) -> Self {
        InputEntry {
            edits: msg.edits,
            removes: msg.removes,
            adds: msg.bodies,
        }
    }
}

impl<S: Clone, E: Clone> Slot<S, E> {
    /// The state of own cell `x`.
    #[inline]
    pub(super) fn state(&self, x: OwnCell) -> &[S] {
        view(&self.states[x])
    }

    /// The view of margin cell `m` (empty if none).
    #[inline]
    pub(super) fn ghost(&self, m: MarginCell) -> &[S] {
        view(&self.ghosts[m])
    }

    /// The states it holds for neighbour `n`: an own cell's state, a margin cell's view,
    /// nothing outside the grid.
    #[inline(always)]
    pub(super) fn neighbour(&self, n: Nb) -> &[S] {
        match n.kind() {
            NbKind::Outside => &[],
            NbKind::Own(x) => self.state(x),
            NbKind::Margin(m) => self.ghost(m),
        }
    }

    /// An empty slot for `own` own cells and `margin` margin cells.
    pub(super) fn new(own: usize, margin: usize) -> Self {
        Slot {
            states: Chunked::new(own),
            outs: Chunked::new(own),
            known: vec![false; own].into(),
            ghosts: Chunked::new(margin),
            ghost_known: BTreeSet::new(),
            foreign_in: BTreeMap::new(),
            migrate_known: BTreeSet::new(),
            recv: BTreeMap::new(),
            sent: BTreeMap::new(),
            inputs: BTreeMap::new(),
        }
    }

    /// Bytes this slot holds, by part. An allocation of states shared by several holders
    /// (a cell's state, its output, the next step's state, the sent log, the views of the
    /// steps that inherit them, received versions) counts `1/n` at each of its `n` holders;
    /// inputs count their states and removed ids.
    pub(super) fn bytes(&self) -> LogBytes {
        let s = std::mem::size_of::<S>();
        let p = std::mem::size_of::<Homed<S>>();
        let v = std::mem::size_of::<Vec<S>>();
        let mut b = LogBytes {
            slots: (self.states.header_bytes()
                + self.outs.header_bytes()
                + self.known.len()
                + self.ghosts.header_bytes()
                + (self.ghost_known.len() + self.migrate_known.len()) * 8)
                as u64,
            ..LogBytes::default()
        };
        // Each holder of a shared allocation counts its share; an entry of a chunk shared
        // by `n` slots is held once by all of them.
        let held = |a: &SharedStates<S>| a.allocation_bytes() / SharedStates::strong_count(a);
        let per_chunk = |(e, n): (&Shared<S>, usize)| e.as_ref().map_or(0, held) / n;
        b.states += self.states.iter_shared().map(per_chunk).sum::<usize>() as u64;
        for (o, n) in self.outs.iter_shared() {
            if let Some(o) = o {
                b.outputs += ((o.bodies.as_ref().map_or(0, held) + o.rare_bytes()) / n) as u64;
            }
        }
        b.ghosts += self.ghosts.iter_shared().map(per_chunk).sum::<usize>() as u64;
        for input in self.inputs.values() {
            b.inputs +=
                (8 + input.edits.len() * 16 + input.removes.len() * 8 + input.adds.len() * p)
                    as u64;
        }
        b.migrations += self
            .foreign_in
            .values()
            .map(|g| v + 8 + g.len() * s)
            .sum::<usize>() as u64;
        // Message bodies are shared between the sender's log, the messages and the
        // receivers' logs: each holder counts its share.
        let share = |l: &Bodies<S>| (v + l.len() * p) / Arc::strong_count(l);
        for r in self.recv.values() {
            b.received += (16 + r.antis.len() * 4) as u64;
            for x in &r.positives {
                b.received += 8 + match &x.content {
                    Carried::Bodies(l) => share(l),
                    Carried::View(g) => g.as_ref().map_or(0, held),
                } as u64;
            }
        }
        for x in self.sent.values() {
            b.sent += 24
                + match &x.live {
                    None => 0,
                    Some(Live::Bodies(l)) => share(l),
                    Some(Live::State(st)) => st.as_ref().map_or(0, held),
                } as u64;
        }
        b
    }
}

/// Bytes held by logs, by part (SPEC.md §K9: how they are counted). [`LogBytes::total`] is
/// what `peak_log_bytes` samples.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LogBytes {
    /// Own cells' states (the per-cell checkpoint log).
    pub states: u64,
    /// Own cells' outputs: bodies, home cells and events.
    pub outputs: u64,
    /// Views of margin cells (ghosts received).
    pub ghosts: u64,
    /// Bodies migrating in from foreign cells.
    pub migrations: u64,
    /// Inputs applied.
    pub inputs: u64,
    /// Messages received (versions and early anti-messages).
    pub received: u64,
    /// The log of what was sent.
    pub sent: u64,
    /// Fixed per slot: per-cell headers and the sets of known cells.
    pub slots: u64,
}

impl LogBytes {
    /// The sum of every part.
    pub fn total(&self) -> u64 {
        self.states
            + self.outputs
            + self.ghosts
            + self.migrations
            + self.inputs
            + self.received
            + self.sent
            + self.slots
    }
}

impl std::ops::AddAssign for LogBytes {
    fn add_assign(&mut self, o: LogBytes) {
        self.states += o.states;
        self.outputs += o.outputs;
        self.ghosts += o.ghosts;
        self.migrations += o.migrations;
        self.inputs += o.inputs;
        self.received += o.received;
        self.sent += o.sent;
        self.slots += o.slots;
    }
}

/// [`World::sample_log_bytes`] measures the logs at every this many calls (and when they
/// hold more steps than ever before).
pub(super) const LOG_SAMPLE_EVERY: u64 = 16;

impl<M: CellModel> World<M> {
    /// The bodies of its cells at committed step `t` (any order).
    pub fn state_at(&self, t: Step) -> impl Iterator<Item = &M::State> + '_ {
        self.slot(t)
            .into_iter()
            .flat_map(|s| s.states.iter().flat_map(view))
    }

    /// Its own cells' states at step `t` (the non-empty cells, any order), shared with the
    /// log rather than copied: for handing committed states to another thread.
    pub fn shared_states_at(&self, t: Step) -> impl Iterator<Item = SharedStates<M::State>> + '_ {
        self.slot(t)
            .into_iter()
            .flat_map(|s| s.states.iter().flatten().cloned())
    }

    /// Its view of the state of own cell `cell` at step `t`, if held.
    pub fn cell_state(&self, cell: u32, t: Step) -> Option<&[M::State]> {
        if !self.is_own(cell) {
            return None;
        }
        self.slot(t).map(|s| s.state(self.own(cell)))
    }

    /// Whether its own cells' states at step `t` are those at `t − 1`, allocation for
    /// allocation (an unchanged cell shares its allocation, SPEC.md §K3), so that its part of
    /// the committed state did not change. `false` when either step is not held.
    pub fn unchanged_since_previous(&self, t: Step) -> bool {
        let (Some(prev), Some(cur)) = (t.checked_sub(1).and_then(|p| self.slot(p)), self.slot(t))
        else {
            return false;
        };
        prev.states.all_same(&cur.states, same_allocation)
    }

    /// Its slot of step `t`, if held.
    pub(super) fn slot(&self, t: Step) -> Option<&Slot<M::State, M::Event>> {
        t.checked_sub(self.base)
            .and_then(|i| self.slots.get(i as usize))
    }

    /// The events of its cells' computations at step `s` (any order).
    pub fn events_at(&self, s: Step) -> impl Iterator<Item = &Event<M::Event>> + '_ {
        self.slot(s)
            .into_iter()
            .flat_map(|s| s.outs.iter().flatten().flat_map(|o| o.events().iter()))
    }

    /// Records that step `t` was committed (counts the committed cell computations at
    /// `t − 1`).
    pub fn note_committed(&mut self, t: Step) {
        self.counters.steps_committed += 1;
        if let Some(slot) = t.checked_sub(1).and_then(|p| self.slot(p)) {
            self.counters.cells_committed +=
                slot.states.iter().filter(|c| c.is_some()).count() as u64;
        }
    }

    /// Bytes held by the logs now.
    pub fn log_bytes(&self) -> u64 {
        self.log_breakdown().total()
    }

    /// Bytes held by the logs now, by part.
    pub fn log_breakdown(&self) -> LogBytes {
        let mut b = LogBytes::default();
        for s in &self.slots {
            b += s.bytes();
        }
        b
    }

    /// Number of steps the logs hold now.
    pub fn steps_held(&self) -> u64 {
        self.slots.len() as u64
    }

    /// Samples the log size into `peak_log_bytes` (SPEC.md §K9): measured at every
    /// `LOG_SAMPLE_EVERY`-th call and whenever the logs hold more steps than at any call
    /// before — the size grows with the steps held, and measuring every time cost ~1 % of a
    /// run.
    pub fn sample_log_bytes(&mut self) {
        let held = self.steps_held();
        let due = self.log_samples % LOG_SAMPLE_EVERY == 0 || held > self.most_held;
        self.log_samples += 1;
        self.most_held = self.most_held.max(held);
        if due {
            let b = self.log_bytes();
            self.counters.peak_log_bytes = self.counters.peak_log_bytes.max(b);
        }
    }

    /// Drops everything about steps before `keep_from` (pass GVT − 1: the states at GVT − 1
    /// are final but computations at GVT − 1 may still be redone); with delta ghosts one
    /// step more is kept (GVT − 2).
    pub fn fossil_collect(&mut self, keep_from: Step) {
        // Delta ghosts compare the states two steps before a ghost's step (K4): one more
        // final step is kept.
        let keep_from = if self.delta() {
            keep_from.saturating_sub(1)
        } else {
            keep_from
        };
        let keep_from = keep_from.min(self.base + self.slots.len() as Step - 1);
        while self.base < keep_from {
            self.slots.pop_front();
            self.base += 1;
        }
    }

    /// The position of step `t`'s slot in `World::slots` (`t` must be held or next).
    pub(super) fn si(&self, t: Step) -> usize {
        debug_assert!(t >= self.base, "step {t} below base {}", self.base);
        (t - self.base) as usize
    }

    /// Creates the slots up to `t`. In the optimistic modes a new slot inherits the ghost
    /// views of the step before (K4: no ghost means no change).
    pub(super) fn ensure_slot(&mut self, t: Step) {
        while self.base + (self.slots.len() as Step) <= t {
            let mut slot = Slot::new(self.cells.len(), self.margin.len());
            if self.delta() {
                if let Some(last) = self.slots.back() {
                    slot.ghosts = last.ghosts.clone();
                }
            }
            self.slots.push_back(slot);
        }
    }
}

/// Whether two shared states are the same allocation (or both empty).
pub(super) fn same_allocation<S>(a: &Shared<S>, b: &Shared<S>) -> bool {
    match (a, b) {
        (None, None) => true,
        (Some(a), Some(b)) => SharedStates::ptr_eq(a, b),
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn per_cell_log_headers_are_8_bytes_for_states_and_24_for_outputs() {
        type S = [u32; 17];
        assert_eq!(std::mem::size_of::<Shared<S>>(), 8);
        assert_eq!(std::mem::size_of::<Option<Out<S, u8>>>(), 24);
    }
}
