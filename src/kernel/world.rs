//! A world: one logical process owning a territory of cells (SPEC.md §World).
//!
//! Pure and single-threaded. An executor hands it messages ([`World::receive`]), lets it act
//! ([`World::act`], which returns the messages it sends), asks for its GVT bound
//! ([`World::bound`]), reads committed states and events, and fossil-collects.
//!
//! The unit of everything is *the state of a cell at a step*: the id-sorted states of the
//! entities homed in that cell at that step. A world keeps, for every step from GVT − 1
//! (GVT − 2 with delta ghosts) to its head, one slot holding, per own cell: its state, and
//! the output of its computation (the bodies it homes at the next step, with their home
//! cells, and its events); per foreign neighbour cell: its view (the ghost state received,
//! or with delta ghosts the view of the step before); per (own destination cell, foreign
//! source cell): the bodies migrating in; and the logs of messages received and sent.
//!
//! The state of own cell `d` at `t + 1` is rebuilt, whenever one of its inputs changes, as the
//! id-sorted union of the outputs at `t` of the own cells around it that land in `d` and the
//! migrations into `d` at `t + 1`. A change of a state at step `t` re-sends its ghost (lazily)
//! and, if the world has already computed step `t`, makes the own cells around it dirty at
//! `t` — that is a rollback. Re-executing a dirty cell compares the new output with the log;
//! only a different output changes states at `t + 1` (early cut-off) and re-sends migrations.

use super::config::{GhostPolicy, KernelConfig, PlantedBug, RollbackMode};
use super::counters::WorldCounters;
use super::message::{Bodies, Message, MessageKey, MessageKind, Sign};
use super::partition::{Partition, WorldId};
use super::trace::WorldTrace;
use crate::frame::{Event, LeftGrid};
use crate::grid::Grid;
use crate::model::{BodyId, CellModel, Neighbourhood, Step};
use crate::state::CellStates;
use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::sync::Arc;

/// Id-sorted states in one shared allocation (`None`: empty, nothing allocated). A cell's
/// output and its state at the next step are the same allocation when every body stays in
/// the cell and nothing else lands there — the common case, which then copies nothing.
type Shared<S> = Option<Arc<[S]>>;

/// The states of `s` as a slice.
fn view<S>(s: &Shared<S>) -> &[S] {
    s.as_deref().unwrap_or(&[])
}

/// `v` as shared states (`None` when empty).
fn share<S>(v: Vec<S>) -> Shared<S> {
    (!v.is_empty()).then(|| Arc::from(v))
}

/// The output of one cell computation: the bodies it homes at the next step, sorted by
/// (home cell, id), their home cells, and the events it raised.
#[derive(Clone, Debug)]
struct Out<S, E> {
    /// The cell computed.
    cell: u32,
    bodies: Shared<S>,
    /// The home cell of each of `bodies`; empty exactly when every body stays in `cell`.
    homes: Vec<u32>,
    events: Vec<Event<E>>,
    /// Whether a cell computation produced it (an empty cell's output is not computed).
    computed: bool,
}

impl<S, E> Out<S, E> {
    fn empty(cell: u32) -> Self {
        Out {
            cell,
            bodies: None,
            homes: Vec::new(),
            events: Vec::new(),
            computed: false,
        }
    }

    fn is_empty(&self) -> bool {
        self.bodies.is_none() && self.events.is_empty()
    }

    /// Whether every body it homes stays in the cell computed.
    fn stays(&self) -> bool {
        self.homes.is_empty()
    }

    /// `(home cell, state)` of every body, sorted by (cell, id).
    fn pairs(&self) -> impl Iterator<Item = (u32, &S)> + '_ {
        view(&self.bodies)
            .iter()
            .enumerate()
            .map(|(k, b)| (self.homes.get(k).copied().unwrap_or(self.cell), b))
    }

    /// The bodies homed in `cell`.
    fn landing_in(&self, cell: u32) -> &[S] {
        let all = view(&self.bodies);
        if self.stays() {
            return if cell == self.cell { all } else { &[] };
        }
        let lo = self.homes.partition_point(|c| *c < cell);
        let hi = self.homes.partition_point(|c| *c <= cell);
        &all[lo..hi]
    }
}

/// One received positive version: (sequence number, bodies, follows).
type Version<S> = (u32, Bodies<S>, bool);

/// What a world has received under one identity (kind, step, source cell).
#[derive(Debug)]
struct Recv<S> {
    /// Live positive versions.
    positives: Vec<Version<S>>,
    /// Anti-messages that arrived before their positive twin.
    antis: Vec<u32>,
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
    fn effective(&self) -> Option<&Version<S>> {
        self.positives.iter().max_by_key(|p| p.0)
    }
}

/// The last version sent under one identity (kind, step, source cell, destination world).
#[derive(Debug)]
struct Sent<S> {
    seq: u32,
    live: Option<Bodies<S>>,
    /// The live version's `follows` flag.
    follows: bool,
}

/// Everything a world holds about one step.
#[derive(Debug)]
struct Slot<S, E> {
    states: Vec<Shared<S>>,
    outs: Vec<Option<Out<S, E>>>,
    known: Vec<bool>,
    /// The view of each margin cell (indexed like `World::margin`) at this step (K4: the
    /// effective ghost of the step, else — optimistic modes — the view of the step before;
    /// `None`: empty). Shared, not copied, between the steps that inherit it.
    ghosts: Vec<Option<Arc<Vec<S>>>>,
    ghost_known: BTreeSet<u32>,
    foreign_in: BTreeMap<(u32, u32), Vec<S>>,
    migrate_known: BTreeSet<u32>,
    recv: BTreeMap<(MessageKind, u32), Recv<S>>,
    sent: BTreeMap<(MessageKind, u32, WorldId), Sent<S>>,
    inputs: BTreeMap<u32, InputEntry<S>>,
}

/// An input applied to a slot: the ids it removes and the (home cell, state) it adds.
type InputEntry<S> = (Vec<BodyId>, Bodies<S>);

impl<S: Clone, E: Clone> Slot<S, E> {
    /// The state of own cell `x` (index in `World::cells`).
    fn state(&self, x: usize) -> &[S] {
        view(&self.states[x])
    }

    /// An empty slot for `n` own cells and `m` margin cells.
    fn new(n: usize, m: usize) -> Self {
        Slot {
            states: vec![None; n],
            outs: (0..n).map(|_| None).collect(),
            known: vec![false; n],
            ghosts: vec![None; m],
            ghost_known: BTreeSet::new(),
            foreign_in: BTreeMap::new(),
            migrate_known: BTreeSet::new(),
            recv: BTreeMap::new(),
            sent: BTreeMap::new(),
            inputs: BTreeMap::new(),
        }
    }

    /// Bytes this slot holds. A ghost view shared with the slot before (`prev`, the same
    /// `Arc`) is counted there only; inputs count their states and removed ids.
    fn bytes(&self, prev: Option<&Slot<S, E>>) -> usize {
        let s = std::mem::size_of::<S>();
        let p = std::mem::size_of::<(u32, S)>();
        let v = std::mem::size_of::<Vec<S>>();
        let h = std::mem::size_of::<Shared<S>>();
        let mut b = self.states.len() * (h + std::mem::size_of::<Option<Out<S, E>>>() + 1);
        // A cell's states shared by its output and the next step's state count half at each.
        let held = |a: &Arc<[S]>| (16 + a.len() * s) / Arc::strong_count(a);
        b += self.states.iter().flatten().map(held).sum::<usize>();
        for o in self.outs.iter().flatten() {
            b += o.bodies.as_ref().map_or(0, held)
                + o.homes.len() * 4
                + o.events.len() * std::mem::size_of::<Event<E>>();
        }
        b += self.ghosts.len() * std::mem::size_of::<Option<Arc<Vec<S>>>>();
        for (k, g) in self.ghosts.iter().enumerate() {
            let Some(g) = g else { continue };
            let shared = prev
                .and_then(|p| p.ghosts[k].as_ref())
                .is_some_and(|h| Arc::ptr_eq(g, h));
            b += if shared { 0 } else { 16 + v + g.len() * s };
        }
        for (removes, adds) in self.inputs.values() {
            b += 8 + removes.len() * 8 + adds.len() * p;
        }
        b += self
            .foreign_in
            .values()
            .map(|g| v + 8 + g.len() * s)
            .sum::<usize>();
        // Message bodies are shared between the sender's log, the messages and the
        // receivers' logs: each holder counts its share.
        let share = |l: &Bodies<S>| (v + l.len() * p) / Arc::strong_count(l);
        for r in self.recv.values() {
            b += 16 + r.antis.len() * 4;
            b += r.positives.iter().map(|x| 8 + share(&x.1)).sum::<usize>();
        }
        for x in self.sent.values() {
            b += 24 + x.live.as_ref().map_or(0, share);
        }
        b + (self.ghost_known.len() + self.migrate_known.len()) * 8
    }
}

/// [`World::sample_log_bytes`] measures the logs at every this many calls (and when they
/// hold more steps than ever before).
const LOG_SAMPLE_EVERY: u64 = 16;

/// The kinds of a world's actions (SPEC.md §K5), for time accounting.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ActionKind {
    /// Apply the inbox (message exchange).
    Receive,
    /// Re-execute dirty steps (rollback).
    Repair,
    /// Compute forward (conservative mode: every action that is not a receive).
    Compute,
}

/// One logical process (see the module doc).
pub struct World<M: CellModel> {
    id: WorldId,
    model: Arc<M>,
    grid: Arc<Grid>,
    part: Arc<Partition>,
    mode: RollbackMode,
    window: Step,
    bug: PlantedBug,
    ghosts: GhostPolicy,
    cells: Vec<u32>,
    /// The foreign cells next to an own cell (ascending): the cells whose ghosts it keeps.
    margin: Vec<u32>,
    /// Per own cell, its 27-neighbourhood resolved once: where each neighbour's state is.
    nbrs: Vec<[Nb; 27]>,
    targets: Vec<Vec<WorldId>>,
    /// The other worlds owning a cell next to one of its own (ascending): the worlds it
    /// exchanges ghosts with.
    neighbours: Vec<WorldId>,
    base: Step,
    head: Step,
    end: Step,
    next: Vec<Step>,
    next_min: Step,
    idle_at: Option<Step>,
    slots: VecDeque<Slot<M::State, M::Event>>,
    dirty: BTreeMap<Step, BTreeSet<u32>>,
    inbox: BTreeMap<MessageKey, Message<M::State>>,
    counters: WorldCounters,
    /// Calls of [`World::sample_log_bytes`] so far, and the most steps held at one of them
    /// (the log size is measured at every [`LOG_SAMPLE_EVERY`]-th call, and whenever the
    /// logs hold more steps than ever before).
    log_samples: u64,
    most_held: u64,
    scratch: Vec<M::State>,
    /// Scratch for `compute`: the home cell of each body it produced.
    homes_scratch: Vec<u32>,
    record: Option<WorldTrace>,
    /// The step the world started from (0, or its last reterritory): ghosts of this step
    /// carry the whole state; later ones only changes (K4, delta ghosts).
    origin: Step,
    /// Ghosts to (re)evaluate at the end of the current action, as (step, own cell index).
    ghost_due: BTreeSet<(Step, usize)>,
}

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

/// Where the state of one neighbour of an own cell is held.
#[derive(Clone, Copy, Debug)]
enum Nb {
    /// Outside the grid: always empty.
    Outside,
    /// An own cell (its local index).
    Own(u32),
    /// A margin cell (its index in `World::margin`).
    Margin(u32),
}

impl<M: CellModel> World<M> {
    /// World `id` of `part`, starting at step 0 from `initial` (binned over `grid`).
    pub fn new(
        id: WorldId,
        model: Arc<M>,
        grid: Arc<Grid>,
        part: Arc<Partition>,
        config: &KernelConfig,
        initial: &CellStates<M::State>,
    ) -> Self {
        Self::at_step(id, model, grid, part, config, initial, 0)
    }

    /// World `id` of `part`, starting at step `step` from the final states `states` (the
    /// whole domain's, binned over `grid`): its logs hold step `step` only.
    fn at_step(
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

    /// Load balancing's handover (SPEC.md §K13): the world takes the territory `part`
    /// gives it at step `step`, which every world has committed (GVT = `step` + 1, so every
    /// state at `step` is final and nothing later was committed). Its logs restart at `step`
    /// from `states`, the whole domain's final states there, exactly as a world started at
    /// `step` would hold them: the final state of a cell is its whole log at GVT, and it
    /// moves with the cell. Speculative states, messages, dirty steps and the inbox are
    /// dropped; [`World::start`] then sends the ghosts of `step` under the new owner map.
    /// Counters and the trace carry on; the end is reset to `step` (raise it with
    /// [`World::set_end`]).
    pub fn reterritory(&mut self, part: Arc<Partition>, states: &CellStates<M::State>, step: Step) {
        let config = KernelConfig {
            mode: self.mode,
            window: self.window,
            planted_bug: self.bug,
            ghosts: self.ghosts,
            ..KernelConfig::default()
        };
        let mut fresh = Self::at_step(
            self.id,
            self.model.clone(),
            self.grid.clone(),
            part,
            &config,
            states,
            step,
        );
        fresh.counters = std::mem::take(&mut self.counters);
        fresh.record = self.record.take();
        *self = fresh;
    }

    /// Starts (or stops) recording this world's part of a run trace ([`WorldTrace`]).
    pub fn set_recording(&mut self, on: bool) {
        self.record = on.then(WorldTrace::default);
    }

    /// Sets the time stamped on what the trace records next (seconds since the run started).
    pub fn trace_time(&mut self, now: f64) {
        if let Some(r) = &mut self.record {
            r.set_time(now);
        }
    }

    /// The trace recorded so far (empty if recording is off); recording continues.
    pub fn take_record(&mut self) -> WorldTrace {
        self.record.as_mut().map(std::mem::take).unwrap_or_default()
    }

    /// This world's head: its states exist up to this step (optimistic modes).
    pub fn head(&self) -> Step {
        self.head
    }

    /// This world's id.
    pub fn id(&self) -> WorldId {
        self.id
    }

    /// The cells it owns (linear indices, ascending).
    pub fn cells(&self) -> &[u32] {
        &self.cells
    }

    /// The other worlds owning a cell next to one of its own (ascending): those it exchanges
    /// ghosts with, so the only ones whose progress its own computations wait for.
    pub fn neighbours(&self) -> &[WorldId] {
        &self.neighbours
    }

    /// Whether its ghosts are deltas (optimistic modes with [`GhostPolicy::Delta`]): no
    /// ghost means unchanged, views are inherited from the step before (K4).
    fn delta(&self) -> bool {
        self.mode != RollbackMode::Conservative && self.ghosts == GhostPolicy::Delta
    }

    /// Its counters.
    pub fn counters(&self) -> &WorldCounters {
        &self.counters
    }

    /// Lets the world compute up to (not including) step `end`, i.e. produce states up to
    /// `end`.
    pub fn set_end(&mut self, end: Step) {
        self.end = self.end.max(end);
    }

    /// The initial messages: ghosts of the border cells at the starting step (0, or the
    /// step of the last [`World::reterritory`]).
    pub fn start(&mut self) -> Vec<Message<M::State>> {
        let mut out = Vec::new();
        let step = self.base;
        for x in 0..self.cells.len() {
            self.send_ghost(x, step, &mut out);
        }
        if let Some(r) = &mut self.record {
            for m in &out {
                r.sent(m.step, m.is_anti());
            }
        }
        out
    }

    /// Local virtual time: the next step this world will (re)compute (optimistic modes), or
    /// the smallest next step over its cells (conservative).
    pub fn lvt(&self) -> Step {
        if self.mode == RollbackMode::Conservative {
            self.next_min
        } else {
            let d = self.dirty.keys().next().copied().unwrap_or(Step::MAX);
            self.head.min(d)
        }
    }

    /// The highest step any of its states may have reached: its head (optimistic modes), or
    /// the largest next step of its cells (conservative; no state beyond it is known yet).
    pub fn frontier(&self) -> Step {
        if self.mode == RollbackMode::Conservative {
            self.next.iter().copied().max().unwrap_or(0)
        } else {
            self.head
        }
    }

    /// Its GVT bound (see [`crate::kernel::gvt`]): `lvt() + 1` and the `affects` step of every
    /// unprocessed message.
    pub fn bound(&self) -> Step {
        // The smallest `affects` in the inbox: its first key has the smallest step `s`; a
        // ghost of `s` affects `s + 1`, anything else of `s` affects `s`.
        let inbox = match self.inbox.keys().next() {
            None => Step::MAX,
            Some(&(s, kind, ..)) => {
                let non_ghost = kind == MessageKind::Input
                    || self
                        .inbox
                        .range((s, MessageKind::Migrate, 0, 0, Sign::Anti)..)
                        .next()
                        .is_some_and(|(k, _)| k.0 == s);
                if non_ghost {
                    s
                } else {
                    s + 1
                }
            }
        };
        debug_assert_eq!(
            inbox,
            self.inbox
                .values()
                .map(|m| m.affects())
                .min()
                .unwrap_or(Step::MAX)
        );
        self.lvt().saturating_add(1).min(inbox)
    }

    /// Puts a message in the inbox. It is applied at the next [`World::act`], in the total
    /// order of [`MessageKey`].
    pub fn receive(&mut self, msg: Message<M::State>) {
        debug_assert_eq!(msg.dst_world, self.id);
        self.idle_at = None;
        let prev = self.inbox.insert(msg.key(), msg);
        debug_assert!(prev.is_none(), "duplicate message");
    }

    /// Whether messages wait in the inbox.
    pub fn has_inbox(&self) -> bool {
        !self.inbox.is_empty()
    }

    /// Whether its next action would only compute forward (no message to apply, no cell to
    /// re-execute): the speculative kind of work an executor may postpone.
    pub fn only_advances(&self) -> bool {
        self.inbox.is_empty() && self.dirty.is_empty()
    }

    /// What the next [`act`](Self::act) will do: apply the inbox, repair dirty steps
    /// (Rollback and Propagate) or compute forward.
    pub fn next_action(&self) -> ActionKind {
        if !self.inbox.is_empty() {
            ActionKind::Receive
        } else if !self.dirty.is_empty() {
            ActionKind::Repair
        } else {
            ActionKind::Compute
        }
    }

    /// Whether acting now may do something. In conservative mode an action may still find
    /// every cell waiting for its neighbours; after such an idle action the world does not
    /// want to act again until it receives a message or GVT changes.
    pub fn wants_to_act(&self, gvt: Step) -> bool {
        if !self.inbox.is_empty() {
            return true;
        }
        let lvt = self.lvt();
        if self.mode == RollbackMode::Conservative {
            // After an action that could not compute anything, only news (a message) or a
            // wider window (a new GVT) can unblock a cell.
            self.idle_at != Some(gvt) && lvt < self.end && lvt + 1 < gvt + self.window
        } else {
            !self.dirty.is_empty() || (self.head < self.end && self.head + 1 < gvt + self.window)
        }
    }

    /// One action: apply the whole inbox in key order if it is not empty; otherwise
    /// re-execute the dirty steps up to the head (Rollback and Propagate), or compute the next
    /// step if the window allows. Returns the messages sent. (Receiving and computing are
    /// separate actions, so a schedule can let every world apply its news before anyone
    /// computes.)
    pub fn act(&mut self, gvt: Step) -> Vec<Message<M::State>> {
        let mut out = Vec::new();
        if self.mode == RollbackMode::Conservative {
            self.act_conservative(gvt, &mut out);
        } else {
            self.act_optimistic(gvt, &mut out);
            self.flush_ghosts(&mut out);
        }
        if self.record.is_some() {
            let lvt = self.lvt();
            if let Some(r) = &mut self.record {
                for m in &out {
                    r.sent(m.step, m.is_anti());
                }
                r.sample_lvt(self.id, lvt);
            }
        }
        out
    }

    fn act_optimistic(&mut self, gvt: Step, out: &mut Vec<Message<M::State>>) {
        if !self.inbox.is_empty() {
            self.drain_inbox();
        } else if !self.dirty.is_empty() {
            // Rollback and Propagate runs to the head in one action (thesis Algorithm 2), so
            // other worlds see the repaired outputs as early as possible.
            while let Some(&s) = self.dirty.keys().next() {
                self.reexecute(s, out);
            }
            if let Some(r) = &mut self.record {
                r.repaired();
            }
        } else if self.head < self.end && self.head + 1 < gvt + self.window {
            self.advance(out);
        } else {
            self.counters.idle_acts += 1;
        }
    }

    /// The bodies of its cells at committed step `t` (any order).
    pub fn state_at(&self, t: Step) -> impl Iterator<Item = &M::State> + '_ {
        self.slot(t)
            .into_iter()
            .flat_map(|s| s.states.iter().flat_map(view))
    }

    /// Its own cells' states at step `t` (the non-empty cells, any order), shared with the
    /// log rather than copied: for handing committed states to another thread.
    pub fn shared_states_at(&self, t: Step) -> impl Iterator<Item = Arc<[M::State]>> + '_ {
        self.slot(t)
            .into_iter()
            .flat_map(|s| s.states.iter().flatten().cloned())
    }

    /// Its view of the state of own cell `cell` at step `t`, if held.
    pub fn cell_state(&self, cell: u32, t: Step) -> Option<&[M::State]> {
        if !self.is_own(cell) {
            return None;
        }
        self.slot(t)
            .map(|s| s.state(self.part.local(cell) as usize))
    }

    fn slot(&self, t: Step) -> Option<&Slot<M::State, M::Event>> {
        t.checked_sub(self.base)
            .and_then(|i| self.slots.get(i as usize))
    }

    /// The events of its cells' computations at step `s` (any order).
    pub fn events_at(&self, s: Step) -> impl Iterator<Item = &Event<M::Event>> + '_ {
        self.slot(s)
            .into_iter()
            .flat_map(|s| s.outs.iter().flatten().flat_map(|o| o.events.iter()))
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
        let mut prev = None;
        let mut b = 0;
        for s in &self.slots {
            b += s.bytes(prev);
            prev = Some(s);
        }
        b as u64
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

    fn si(&self, t: Step) -> usize {
        debug_assert!(t >= self.base, "step {t} below base {}", self.base);
        (t - self.base) as usize
    }

    /// Creates the slots up to `t`. In the optimistic modes a new slot inherits the ghost
    /// views of the step before (K4: no ghost means no change).
    fn ensure_slot(&mut self, t: Step) {
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

    fn is_own(&self, cell: u32) -> bool {
        self.part.owner(cell) == self.id
    }

    /// The index in `margin` of foreign cell `cell`, which must be next to an own cell (a
    /// ghost comes only from such a cell: its sender targets the owners of its neighbours).
    fn margin_index(&self, cell: u32) -> usize {
        self.margin
            .binary_search(&cell)
            .unwrap_or_else(|_| panic!("cell {cell} is not next to world {}", self.id))
    }

    /// Computes own cell `x` at step `s` from the states and ghosts held for `s`.
    fn compute(&mut self, x: usize, s: Step) -> Out<M::State, M::Event> {
        let cell = self.cells[x];
        let grid = &*self.grid;
        let slot = &self.slots[(s - self.base) as usize];
        let c = grid.coord(cell as usize);
        let nbrs = &self.nbrs[x];
        let cells: [&[M::State]; 27] = std::array::from_fn(|k| match nbrs[k] {
            Nb::Outside => &[][..],
            Nb::Own(l) => slot.state(l as usize),
            Nb::Margin(m) => slot.ghosts[m as usize].as_ref().map_or(&[][..], |v| &v[..]),
        });
        let nb = Neighbourhood { centre: c, cells };
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
            // The common case: one allocation, written once, shared with the next state.
            let bodies = (!self.scratch.is_empty()).then(|| self.scratch.drain(..).collect());
            return Out {
                cell,
                bodies,
                homes: Vec::new(),
                events,
                computed: true,
            };
        }
        // Sorted by (home cell, id), without the bodies that left the domain.
        let mut order: Vec<usize> = (0..homes.len()).filter(|&k| homes[k] != u32::MAX).collect();
        let scratch = &self.scratch;
        order.sort_by_key(|&k| (homes[k], M::id(&scratch[k])));
        let mut out_homes: Vec<u32> = order.iter().map(|&k| homes[k]).collect();
        if out_homes.iter().all(|&d| d == cell) {
            out_homes.clear();
        }
        let bodies =
            (!order.is_empty()).then(|| order.iter().map(|&k| scratch[k].clone()).collect());
        self.scratch.clear();
        Out {
            cell,
            bodies,
            homes: out_homes,
            events,
            computed: true,
        }
    }

    /// Whether two outputs are the same (early cut-off and lazy cancellation compare
    /// entities with [`World::same_entity`]).
    fn same_out(&self, a: &Out<M::State, M::Event>, b: &Out<M::State, M::Event>) -> bool {
        let (x, y) = (view(&a.bodies), view(&b.bodies));
        a.events == b.events
            && a.homes == b.homes
            && x.len() == y.len()
            && x.iter().zip(y).all(|(p, q)| self.same_entity(p, q))
    }

    fn same_pairs(&self, a: &[(u32, M::State)], b: &[(u32, M::State)]) -> bool {
        a.len() == b.len()
            && a.iter()
                .zip(b)
                .all(|(x, y)| x.0 == y.0 && self.same_entity(&x.1, &y.1))
    }

    /// Bit equality of two entity states — or, under the planted bug
    /// [`PlantedBug::CutoffByIdsOnly`], equality of their ids only.
    fn same_entity(&self, a: &M::State, b: &M::State) -> bool {
        if self.bug == PlantedBug::CutoffByIdsOnly {
            M::id(a) == M::id(b)
        } else {
            M::same_bits(a, b)
        }
    }

    fn same_states(a: &[M::State], b: &[M::State]) -> bool {
        a.len() == b.len() && a.iter().zip(b).all(|(x, y)| M::same_bits(x, y))
    }

    /// Sends `(kind, step, cell)` to world `w` with `content` (`None`: no message) and the
    /// `follows` flag: in conservative mode always (an empty content is a null message);
    /// otherwise lazily — nothing if the live version sent before has the same content and
    /// flag (or there is none and `content` is `None`), else an anti-message for it (if any)
    /// and the new version (if any).
    fn send(
        &mut self,
        (kind, step, cell, w): (MessageKind, Step, u32, WorldId),
        content: Option<Bodies<M::State>>,
        follows: bool,
        out: &mut Vec<Message<M::State>>,
    ) {
        let conservative = self.mode == RollbackMode::Conservative;
        let i = self.si(step);
        let sent = self.slots[i].sent.get(&(kind, cell, w));
        let live = sent.and_then(|s| s.live.as_ref());
        let live_follows = sent.is_some_and(|s| s.follows);
        if !conservative {
            let same = match (live, &content) {
                (None, None) => true,
                (Some(a), Some(b)) => live_follows == follows && self.same_pairs(a, b),
                _ => false,
            };
            if same {
                return;
            }
        }
        let entry = self.slots[i].sent.entry((kind, cell, w)).or_insert(Sent {
            seq: 0,
            live: None,
            follows: false,
        });
        let me = self.id;
        let bug = self.bug;
        let msg = |sign, seq, bodies| Message {
            step,
            kind,
            sign,
            src_world: me,
            dst_world: w,
            src_cell: cell,
            seq,
            bodies,
            removes: Vec::new(),
            follows: sign == Sign::Positive && follows,
        };
        if entry.live.take().is_some() {
            let dropped = bug == PlantedBug::DropLoneAnti && content.is_none();
            if !conservative && !dropped {
                out.push(msg(Sign::Anti, entry.seq, Bodies::default()));
                self.counters.anti_messages_sent += 1;
            }
        }
        if let Some(content) = content {
            entry.seq += 1;
            entry.live = Some(content.clone());
            entry.follows = follows;
            // Null messages are conservative mode's; an empty delta ghost (a border cell that
            // emptied) is news, counted as a ghost only.
            if conservative && content.is_empty() {
                self.counters.null_messages_sent += 1;
            }
            out.push(msg(Sign::Positive, entry.seq, content));
            self.counters.messages_sent += 1;
            match kind {
                MessageKind::Ghost => self.counters.ghosts_sent += 1,
                MessageKind::Migrate => self.counters.migrates_sent += 1,
                MessageKind::Input => {}
            }
        }
    }

    /// Whether the state of own cell `x` at `u` differs from its state at `u − 1` (at the
    /// origin step: whether it is not empty).
    fn changed(&self, x: usize, u: Step) -> bool {
        let i = self.si(u);
        let cur = self.slots[i].state(x);
        if u == self.origin {
            return !cur.is_empty();
        }
        assert!(
            i > 0,
            "ghost of step {u} evaluated without the state of step {}",
            u - 1
        );
        !Self::same_states(self.slots[i - 1].state(x), cur)
    }

    /// (Re)sends the ghost of own cell `x` at step `t` to every world owning a neighbour.
    /// Conservative mode: the whole state, always (possibly a null message). Full ghosts:
    /// the state if not empty. Delta ghosts (K4): the state if it changed at `t` or at
    /// `t − 1` (so a change is always followed by the next step's ghost, which its `follows`
    /// flag announces), else no ghost. Lazily: a re-evaluation that changes nothing sends
    /// nothing.
    fn send_ghost(&mut self, x: usize, t: Step, out: &mut Vec<Message<M::State>>) {
        if self.targets[x].is_empty() {
            return;
        }
        let cell = self.cells[x];
        let (send, follows) = if self.mode == RollbackMode::Conservative {
            (true, false)
        } else if !self.delta() {
            (!self.slots[self.si(t)].state(x).is_empty(), false)
        } else {
            let now = self.changed(x, t);
            (now || (t > self.origin && self.changed(x, t - 1)), now)
        };
        let cur = self.slots[self.si(t)].state(x);
        let content: Option<Bodies<M::State>> =
            send.then(|| Arc::new(cur.iter().map(|b| (cell, b.clone())).collect()));
        for k in 0..self.targets[x].len() {
            let w = self.targets[x][k];
            self.send(
                (MessageKind::Ghost, t, cell, w),
                content.clone(),
                follows,
                out,
            );
        }
    }

    /// (Re)sends the bodies the computation of own cell `x` at `s` homes in world `w`'s cells.
    fn send_migrate(&mut self, x: usize, s: Step, w: WorldId, out: &mut Vec<Message<M::State>>) {
        let i = self.si(s);
        let part = &*self.part;
        let content: Vec<(u32, M::State)> = self.slots[i].outs[x]
            .as_ref()
            .map(|o| {
                o.pairs()
                    .filter(|(d, _)| part.owner(*d) == w)
                    .map(|(d, b)| (d, b.clone()))
                    .collect()
            })
            .unwrap_or_default();
        let content = (self.mode == RollbackMode::Conservative || !content.is_empty())
            .then(|| Arc::new(content));
        let id = (MessageKind::Migrate, s + 1, self.cells[x], w);
        self.send(id, content, false, out);
    }

    /// Rebuilds the state of own cell `d` at `t ≥ base + 1` from the outputs at `t − 1` of the
    /// own cells around it and the migrations into it. Returns the previous state if it
    /// changed.
    fn rebuild_state(&mut self, d: u32, t: Step) -> Option<Shared<M::State>> {
        let grid = &*self.grid;
        let part = &*self.part;
        let prev = &self.slots[(t - 1 - self.base) as usize];
        let cur = &self.slots[(t - self.base) as usize];
        let mut v: Vec<M::State> = Vec::new();
        for n in grid.neighbours(grid.coord(d as usize)) {
            let ni = grid.index(n) as u32;
            if part.owner(ni) == self.id {
                if let Some(o) = &prev.outs[part.local(ni) as usize] {
                    v.extend(o.landing_in(d).iter().cloned());
                }
            }
        }
        for (_, bs) in cur.foreign_in.range((d, 0)..=(d, u32::MAX)) {
            v.extend(bs.iter().cloned());
        }
        if !cur.inputs.is_empty() {
            let removed: BTreeSet<BodyId> = cur
                .inputs
                .values()
                .flat_map(|i| i.0.iter().copied())
                .collect();
            v.retain(|b| !removed.contains(&M::id(b)));
            for (_, adds) in cur.inputs.values() {
                v.extend(adds.iter().filter(|p| p.0 == d).map(|p| p.1.clone()));
            }
        }
        v.sort_by_key(|b| M::id(b));
        let ld = part.local(d) as usize;
        let i = (t - self.base) as usize;
        if Self::same_states(&v, self.slots[i].state(ld)) {
            return None;
        }
        Some(std::mem::replace(&mut self.slots[i].states[ld], share(v)))
    }

    /// The own cells around `cell` whose computation at `s` must be redone because the state
    /// of `cell` at `s` changed from `old` to `new`: `cell` itself if it is own and can produce
    /// something (occupied now, or produced something before); every other own neighbour
    /// that can produce something — in cell mode, only if one of its entities may read a
    /// changed entity (`CellModel::may_affect`, SPEC.md §K4) or it is empty but produced
    /// something before.
    fn cells_reading(&self, cell: u32, s: Step, old: &[M::State], new: &[M::State]) -> Vec<u32> {
        let i = self.si(s);
        let slot = &self.slots[i];
        let filter = self.mode == RollbackMode::Cell;
        let changed = if filter {
            changed_entities::<M>(old, new)
        } else {
            Vec::new()
        };
        let mut reading = Vec::new();
        for n in self.grid.neighbours(self.grid.coord(cell as usize)) {
            let ni = self.grid.index(n) as u32;
            if !self.is_own(ni) {
                continue;
            }
            let x = self.part.local(ni) as usize;
            let state = slot.state(x);
            let produced = slot.outs[x].as_ref().is_some_and(|o| !o.is_empty());
            let reads = if !filter || ni == cell {
                !state.is_empty() || produced
            } else {
                (state.is_empty() && produced)
                    || state
                        .iter()
                        .any(|r| changed.iter().any(|c| self.model.may_affect(r, c)))
            };
            if reads {
                reading.push(x as u32);
            }
        }
        reading
    }

    /// Marks the own `cells` dirty at step `s < head`. Returns whether there were any.
    fn mark_dirty(&mut self, s: Step, cells: Vec<u32>) -> bool {
        if cells.is_empty() {
            return false;
        }
        self.dirty.entry(s).or_default().extend(cells);
        true
    }

    /// The state of own cell `d` at `t ≤ head` changed from `old`: re-send its ghost, and if
    /// step `t` was computed, dirty the cells reading it. Returns whether something became
    /// dirty.
    fn on_state_change(&mut self, d: u32, t: Step, old: Shared<M::State>) -> bool {
        let x = self.part.local(d) as usize;
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

    fn drain_inbox(&mut self) {
        let mut straggle: Option<(Step, bool)> = None;
        while let Some((_, msg)) = self.inbox.pop_first() {
            self.counters.messages_received += 1;
            let positive = !msg.is_anti();
            if let Some(s) = self.apply(msg) {
                straggle = Some(match straggle {
                    None => (s, positive),
                    Some((s0, p)) => (s0.min(s), p || positive),
                });
            }
        }
        if let Some((s0, primary)) = straggle {
            let len = self.head - s0;
            let c = &mut self.counters;
            if primary {
                c.rollbacks_primary += 1;
                c.rollback_length_primary += len;
            } else {
                c.rollbacks_secondary += 1;
                c.rollback_length_secondary += len;
            }
            c.steps_rolled_back += len;
            c.rollback_length_max = c.rollback_length_max.max(len);
            if let Some(r) = &mut self.record {
                r.rollback(self.id, s0, len, primary);
            }
            if self.mode == RollbackMode::World {
                let all: BTreeSet<u32> = (0..self.cells.len() as u32).collect();
                for s in s0..self.head {
                    self.dirty.insert(s, all.clone());
                }
            }
        }
    }

    /// Applies one message (optimistic modes). Returns the step at which it made cells dirty,
    /// if it did.
    fn apply(&mut self, msg: Message<M::State>) -> Option<Step> {
        let step = msg.step;
        self.ensure_slot(step);
        let i = self.si(step);
        let src = msg.src_cell;
        let kind = msg.kind;
        if kind == MessageKind::Input {
            return self.apply_input(msg);
        }
        let delta = self.delta();
        let r = self.slots[i].recv.entry((kind, src)).or_default();
        let before = r.effective().map(|e| e.0);
        // The cells the effective migration landed in (ghosts do not need them).
        let old_cells: Vec<u32> = match r.effective() {
            Some(e) if kind == MessageKind::Migrate => e.1.iter().map(|p| p.0).collect(),
            _ => Vec::new(),
        };
        match msg.sign {
            Sign::Positive => {
                if let Some(k) = r.antis.iter().position(|&a| a == msg.seq) {
                    r.antis.swap_remove(k);
                    self.counters.annihilated += 1;
                } else {
                    r.positives.push((msg.seq, msg.bodies, msg.follows));
                }
            }
            Sign::Anti => {
                if let Some(k) = r.positives.iter().position(|p| p.0 == msg.seq) {
                    r.positives.swap_remove(k);
                    self.counters.annihilated += 1;
                } else {
                    r.antis.push(msg.seq);
                }
            }
        }
        let after = r.effective().map(|e| e.0);
        if before == after {
            return None;
        }
        if kind == MessageKind::Ghost {
            // The view of `src` at `step`: the effective ghost, else the view of the step
            // before (K4, delta ghosts).
            let (view, follows) = match r.effective() {
                Some(e) if e.1.is_empty() => (None, e.2),
                Some(e) => (
                    Some(Arc::new(e.1.iter().map(|p| p.1.clone()).collect())),
                    e.2,
                ),
                None if i > 0 && delta => {
                    let m = self.margin_index(src);
                    (self.slots[i - 1].ghosts[m].clone(), false)
                }
                None => {
                    // Empty is the view before the origin; a delta ghost's step is always
                    // above `base` otherwise (GVT argument, K7).
                    debug_assert!(!delta || step == self.origin);
                    (None, false)
                }
            };
            let dirtied = self.set_ghost_view(src, step, view, follows);
            if step < self.head && dirtied.is_none() {
                self.counters.stragglers_absorbed += 1;
            }
            return dirtied;
        }
        let new: Bodies<M::State> = r.effective().map(|e| e.1.clone()).unwrap_or_default();
        match kind {
            MessageKind::Input => unreachable!("inputs are applied by apply_input"),
            MessageKind::Ghost => unreachable!("ghosts are applied above"),
            MessageKind::Migrate => {
                let mut dsts: Vec<u32> = old_cells;
                dsts.extend(new.iter().map(|p| p.0));
                dsts.sort_unstable();
                dsts.dedup();
                for &d in &dsts {
                    assert!(
                        self.is_own(d),
                        "migration into a cell this world does not own"
                    );
                    let bodies: Vec<M::State> = new
                        .iter()
                        .filter(|p| p.0 == d)
                        .map(|p| p.1.clone())
                        .collect();
                    let slot = &mut self.slots[i];
                    if bodies.is_empty() {
                        slot.foreign_in.remove(&(d, src));
                    } else {
                        slot.foreign_in.insert((d, src), bodies);
                    }
                }
                let mut dirtied = false;
                if step <= self.head {
                    for &d in &dsts {
                        if let Some(old) = self.rebuild_state(d, step) {
                            dirtied |= self.on_state_change(d, step, old);
                        }
                    }
                    if step < self.head && !dirtied {
                        self.counters.stragglers_absorbed += 1;
                    }
                }
                dirtied.then_some(step)
            }
        }
    }

    /// Sets the view of foreign cell `src` at `t` to `view` (`None`: empty) and, with delta
    /// ghosts, carries it forward to the later steps that inherit it (up to the next step
    /// with an effective ghost of its own) — unless the ghost `follows` (a ghost of `t + 1`
    /// is on its way: the later views are left as they are, as the computations used them,
    /// until it arrives). At each computed step (below the head) whose view changed, the own
    /// cells that read the change become dirty. Returns the first step made dirty, if any.
    fn set_ghost_view(
        &mut self,
        src: u32,
        t: Step,
        view: Option<Arc<Vec<M::State>>>,
        follows: bool,
    ) -> Option<Step> {
        let carry = self.delta() && !follows;
        let m = self.margin_index(src);
        let mut first = None;
        let mut u = t;
        while let Some(slot) = self.slots.get_mut((u - self.base) as usize) {
            // Later steps take the view only if they inherit it: no ghost of their own.
            let own_ghost = || {
                slot.recv
                    .get(&(MessageKind::Ghost, src))
                    .is_some_and(|r| r.effective().is_some())
            };
            if u > t && (!carry || own_ghost()) {
                break;
            }
            let old = std::mem::replace(&mut slot.ghosts[m], view.clone());
            let unchanged = match (&old, &view) {
                (None, None) => true,
                (Some(a), Some(b)) => Arc::ptr_eq(a, b) || Self::same_states(a, b),
                _ => false,
            };
            // An unchanged step does not end the walk: the steps after a ghost that
            // announced a successor may still hold views from before it.
            if !unchanged && u < self.head {
                let old: &[M::State] = old.as_ref().map_or(&[][..], |v| &v[..]);
                let new: &[M::State] = view.as_ref().map_or(&[][..], |v| &v[..]);
                let cells = self.cells_reading(src, u, old, new);
                if self.mark_dirty(u, cells) {
                    first.get_or_insert(u);
                }
            }
            u += 1;
        }
        first
    }

    /// Sends the ghosts due (`ghost_due`) in (step, cell) order: at the end of an action, so a
    /// state changed several times within it is sent once.
    fn flush_ghosts(&mut self, out: &mut Vec<Message<M::State>>) {
        for (t, x) in std::mem::take(&mut self.ghost_due) {
            self.send_ghost(x, t, out);
        }
    }

    /// Applies an input (optimistic modes): stored in its step's slot; if that step's states
    /// exist, the own cells holding a removed entity or receiving an added one are rebuilt.
    fn apply_input(&mut self, msg: Message<M::State>) -> Option<Step> {
        let step = msg.step;
        assert!(step >= 1, "inputs apply to steps from 1 on");
        let i = self.si(step);
        let mut cells: BTreeSet<u32> = msg
            .bodies
            .iter()
            .map(|p| p.0)
            .filter(|&c| self.is_own(c))
            .collect();
        if step <= self.head {
            for (x, st) in self.slots[i].states.iter().enumerate() {
                if view(st).iter().any(|b| msg.removes.contains(&M::id(b))) {
                    cells.insert(self.cells[x]);
                }
            }
        }
        self.slots[i]
            .inputs
            .insert(msg.seq, (msg.removes, msg.bodies));
        let mut dirtied = false;
        if step <= self.head {
            for d in cells {
                if let Some(old) = self.rebuild_state(d, step) {
                    dirtied |= self.on_state_change(d, step, old);
                }
            }
        }
        dirtied.then_some(step)
    }

    /// Re-executes the dirty cells of step `s` (optimistic modes).
    fn reexecute(&mut self, s: Step, out: &mut Vec<Message<M::State>>) {
        let cells = self.dirty.remove(&s).unwrap_or_default();
        self.counters.steps_computed += 1;
        self.counters.steps_reexecuted += 1;
        let i = self.si(s);
        let mut changed_dst: BTreeSet<u32> = BTreeSet::new();
        let mut changed_mig: BTreeSet<(usize, WorldId)> = BTreeSet::new();
        for x in cells {
            let x = x as usize;
            let new = if self.slots[i].state(x).is_empty() {
                Out::empty(self.cells[x])
            } else {
                self.counters.cells_recomputed += 1;
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

    /// Computes step `head` → `head + 1` for every own cell (optimistic modes).
    fn advance(&mut self, out: &mut Vec<Message<M::State>>) {
        let h = self.head;
        self.ensure_slot(h + 1);
        self.counters.steps_computed += 1;
        let i = self.si(h);
        let n = self.cells.len();
        // How many own cells' outputs land in each own cell (each output counted once).
        let mut landings = vec![0u32; n];
        let mut migs: BTreeSet<(usize, WorldId)> = BTreeSet::new();
        for x in 0..n {
            let o = if self.slots[i].state(x).is_empty() {
                Out::empty(self.cells[x])
            } else {
                self.compute(x, h)
            };
            if o.stays() {
                landings[x] += o.bodies.is_some() as u32;
            } else {
                let mut last = None;
                for &d in &o.homes {
                    if last == Some(d) {
                        continue;
                    }
                    last = Some(d);
                    if self.is_own(d) {
                        landings[self.part.local(d) as usize] += 1;
                    } else {
                        migs.insert((x, self.part.owner(d)));
                    }
                }
            }
            self.slots[i].outs[x] = Some(o);
        }
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
            .map(|k| k.0)
            .chain(
                next.inputs
                    .values()
                    .flat_map(|x| x.1.iter().map(|p| p.0))
                    .filter(|&c| part.owner(c) == id),
            )
            .collect();
        // Inputs at h + 1 (rare) may remove ids from any cell: every cell takes the general
        // rule then.
        let inputs = !next.inputs.is_empty();
        for (x, &k) in landings.iter().enumerate() {
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
            debug_assert!(self.slots[i + 1].states[x].is_none());
            let bodies = self.slots[i].outs[x]
                .as_ref()
                .and_then(|o| o.bodies.clone());
            self.slots[i + 1].states[x] = bodies;
        }
        for d in general {
            self.rebuild_state(d, h + 1);
        }
        self.head = h + 1;
        for (x, w) in migs {
            self.send_migrate(x, h, w, out);
        }
        for x in 0..n {
            if !self.targets[x].is_empty() {
                self.send_ghost(x, h + 1, out);
            }
        }
    }

    // ---- conservative mode ----

    fn act_conservative(&mut self, gvt: Step, out: &mut Vec<Message<M::State>>) {
        let lvt_before = self.lvt();
        let drain = !self.inbox.is_empty();
        while let Some((_, msg)) = self.inbox.pop_first() {
            self.counters.messages_received += 1;
            debug_assert!(!msg.is_anti(), "conservative worlds never cancel");
            let step = msg.step;
            self.ensure_slot(step);
            let i = self.si(step);
            let src = msg.src_cell;
            match msg.kind {
                MessageKind::Input => {
                    self.slots[i]
                        .inputs
                        .insert(msg.seq, (msg.removes, msg.bodies));
                }
                MessageKind::Ghost => {
                    let slot = &mut self.slots[i];
                    slot.ghost_known.insert(src);
                    if !msg.bodies.is_empty() {
                        let view = Arc::unwrap_or_clone(msg.bodies)
                            .into_iter()
                            .map(|p| p.1)
                            .collect();
                        let m = self.margin_index(src);
                        self.slots[i].ghosts[m] = Some(Arc::new(view));
                    } else {
                        // An empty cell at `step` migrates nothing at `step + 1`.
                        self.ensure_slot(step + 1);
                        let j = self.si(step + 1);
                        self.slots[j].migrate_known.insert(src);
                        let grid = self.grid.clone();
                        for n in grid.neighbours(grid.coord(src as usize)) {
                            let ni = grid.index(n) as u32;
                            if self.is_own(ni) {
                                self.try_know(ni, step + 1, out);
                            }
                        }
                    }
                }
                MessageKind::Migrate => {
                    let slot = &mut self.slots[i];
                    slot.migrate_known.insert(src);
                    for (d, b) in Arc::unwrap_or_clone(msg.bodies) {
                        slot.foreign_in.entry((d, src)).or_default().push(b);
                    }
                    let grid = self.grid.clone();
                    for n in grid.neighbours(grid.coord(src as usize)) {
                        let ni = grid.index(n) as u32;
                        if self.is_own(ni) {
                            self.try_know(ni, step, out);
                        }
                    }
                }
            }
        }
        if drain {
            return;
        }
        let mut progressed = false;
        for x in 0..self.cells.len() {
            progressed |= self.try_compute(x, gvt, out);
        }
        self.next_min = self.next.iter().copied().min().unwrap_or(Step::MAX);
        let lvt = self.lvt();
        self.counters.steps_computed += lvt.min(self.end) - lvt_before.min(self.end);
        if !progressed {
            self.counters.idle_acts += 1;
            self.idle_at = Some(gvt);
        } else {
            self.idle_at = None;
        }
    }

    /// Whether the state of own cell `ni` (or the ghost of foreign cell `ni`) at `s` is known.
    fn known(&self, ni: u32, s: Step) -> bool {
        let slot = &self.slots[self.si(s)];
        if self.is_own(ni) {
            slot.known[self.part.local(ni) as usize]
        } else {
            slot.ghost_known.contains(&ni)
        }
    }

    fn try_compute(&mut self, x: usize, gvt: Step, out: &mut Vec<Message<M::State>>) -> bool {
        let s = self.next[x];
        if s >= self.end || s + 1 >= gvt + self.window {
            return false;
        }
        let i = self.si(s);
        if !self.slots[i].known[x] {
            return false;
        }
        let cell = self.cells[x];
        let occupied = !self.slots[i].state(x).is_empty();
        if occupied {
            let c = self.grid.coord(cell as usize);
            let ready = self
                .grid
                .neighbours(c)
                .all(|n| self.known(self.grid.index(n) as u32, s));
            if !ready {
                return false;
            }
        }
        let o = if occupied {
            self.compute(x, s)
        } else {
            Out::empty(cell)
        };
        self.ensure_slot(s + 1);
        self.slots[i].outs[x] = Some(o);
        self.next[x] = s + 1;
        // An empty cell produces nothing, and its (null) ghost of `s` already told every
        // neighbouring world so: no null migration is needed.
        if occupied {
            for k in 0..self.targets[x].len() {
                let w = self.targets[x][k];
                self.send_migrate(x, s, w, out);
            }
        }
        let grid = self.grid.clone();
        for n in grid.neighbours(grid.coord(cell as usize)) {
            let ni = grid.index(n) as u32;
            if self.is_own(ni) {
                self.try_know(ni, s + 1, out);
            }
        }
        true
    }

    /// Conservative: makes the state of own cell `d` at `t` known once every cell around it
    /// has produced its output at `t − 1`; then sends its ghost (a null message if empty).
    fn try_know(&mut self, d: u32, t: Step, out: &mut Vec<Message<M::State>>) {
        if t < self.base + 1 {
            return;
        }
        self.ensure_slot(t);
        let x = self.part.local(d) as usize;
        let (ip, i) = (self.si(t - 1), self.si(t));
        if self.slots[i].known[x] {
            return;
        }
        let ready = self.grid.neighbours(self.grid.coord(d as usize)).all(|n| {
            let ni = self.grid.index(n) as u32;
            if self.is_own(ni) {
                self.slots[ip].outs[self.part.local(ni) as usize].is_some()
            } else {
                self.slots[i].migrate_known.contains(&ni)
            }
        });
        if !ready {
            return;
        }
        self.rebuild_state(d, t);
        self.slots[i].known[x] = true;
        self.send_ghost(x, t, out);
    }
}
