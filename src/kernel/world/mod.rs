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

mod chunked;
mod conservative;
mod early;
mod index;
mod keys;
mod log;
mod prepared;
mod receive;
mod recompute;
mod repair;
mod send;
mod territory;
mod throttle;

use self::index::{OwnCell, PerOwnCell};
pub use self::log::LogBytes;
use self::log::Slot;
use self::territory::Nb;
use self::throttle::Throttle;
use super::config::{GhostPolicy, KernelConfig, PlantedBug, RollbackMode};
use super::counters::WorldCounters;
use super::message::{Message, MessageKey, MessageKind};
use super::partition::{Partition, WorldId};
use super::trace::WorldTrace;
use crate::grid::Grid;
use crate::model::{CellModel, Step};
use crate::state::CellStates;
use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::sync::Arc;

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

/// The per-own-cell buffers `advance` fills each step, kept between steps.
struct AdvanceScratch<S, E> {
    /// How many own cells' outputs land in each own cell.
    landings: PerOwnCell<u32>,
    /// The outputs, before they become the slot's table.
    outs: Vec<Option<log::Out<S, E>>>,
    /// The states of the next step, before they become the slot's table.
    states: Vec<log::Shared<S>>,
}

impl<S, E> Default for AdvanceScratch<S, E> {
    fn default() -> Self {
        AdvanceScratch {
            landings: PerOwnCell::default(),
            outs: Vec::new(),
            states: Vec::new(),
        }
    }
}

/// One logical process (see the module doc).
pub struct World<M: CellModel> {
    /// Its id.
    id: WorldId,
    /// The model every cell computation runs.
    model: Arc<M>,
    /// The grid of the whole domain.
    grid: Arc<Grid>,
    /// Who owns each cell of the grid.
    part: Arc<Partition>,
    /// Its rollback mode (or conservative).
    mode: RollbackMode,
    /// The window: it computes a step `s` only when `s + 1 < GVT + window`. Adaptive
    /// (`throttle`), it moves within `1..=` the configured window.
    window: Step,
    /// The adaptive window's state, if the window adapts (SPEC.md §K14).
    throttle: Option<Throttle>,
    /// The planted bug it runs with (verification only).
    bug: PlantedBug,
    /// Full or delta ghosts (optimistic modes).
    ghosts: GhostPolicy,
    /// The global index of each own cell (ascending).
    cells: PerOwnCell<u32>,
    /// The foreign cells next to an own cell (global indices, ascending; a [`MarginCell`]
    /// indexes it): the cells whose ghosts it keeps.
    ///
    /// [`MarginCell`]: index::MarginCell
    margin: Vec<u32>,
    /// Per own cell, its 27-neighbourhood resolved once: where each neighbour's state is.
    nbrs: PerOwnCell<[Nb; 27]>,
    /// Per own cell, the other worlds owning one of its neighbours (ascending): the worlds
    /// its ghosts go to.
    targets: PerOwnCell<Vec<WorldId>>,
    /// The other worlds owning a cell next to one of its own (ascending): the worlds it
    /// exchanges ghosts with.
    neighbours: Vec<WorldId>,
    /// The first step its logs hold (one slot per step from here).
    base: Step,
    /// Optimistic modes: its states exist up to this step.
    head: Step,
    /// It computes states up to this step (see [`World::set_end`]).
    end: Step,
    /// Conservative mode: per own cell, the next step it computes.
    next: PerOwnCell<Step>,
    /// Per own cell, its computations re-executed so far: what a live display flashes
    /// (observation only; a reterritory keeps the counts of the cells the world keeps).
    recomputes: PerOwnCell<u64>,
    /// Conservative mode: the smallest of `next`.
    next_min: Step,
    /// Conservative mode: the GVT at its last action that could compute nothing.
    idle_at: Option<Step>,
    /// The log: one slot per step from `base`.
    slots: VecDeque<Slot<M::State, M::Event>>,
    /// Optimistic modes: the own cells to re-execute, per step.
    dirty: BTreeMap<Step, BTreeSet<OwnCell>>,
    /// Messages received and not applied yet, in the order they are applied.
    inbox: BTreeMap<MessageKey, Message<M::State>>,
    /// What it has done so far (SPEC.md §K9).
    counters: WorldCounters,
    /// Calls of [`World::sample_log_bytes`] so far, and the most steps held at one of them
    /// (the log size is measured at every [`log::LOG_SAMPLE_EVERY`]-th call, and whenever the
    /// logs hold more steps than ever before).
    log_samples: u64,
    most_held: u64,
    /// Scratch for `compute`: the bodies a cell's computation produced.
    scratch: Vec<M::State>,
    /// Scratch for `compute`: the home cell of each body it produced.
    homes_scratch: Vec<u32>,
    /// Scratch for `advance`: its per-cell tables, kept between steps (a step of a large,
    /// mostly empty territory would otherwise allocate and zero them afresh).
    advance_scratch: AdvanceScratch<M::State, M::Event>,
    /// The hints, cells at rest and (in a sparse territory) copy of the states of the step
    /// being advanced (`advance`, `compute`).
    prepared: prepared::Prepared<M::State>,
    /// Its part of the run trace, when recording.
    record: Option<WorldTrace>,
    /// The step the world started from (0, or its last reterritory): ghosts of this step
    /// carry the whole state; later ones only changes (K4, delta ghosts).
    origin: Step,
    /// Ghosts to (re)evaluate at the end of the current action, as (step, own cell).
    ghost_due: BTreeSet<(Step, OwnCell)>,
    /// The head step whose interior cells were computed ahead, if any
    /// ([`World::compute_interior_ahead`]): their outputs are in the log.
    early: Option<Step>,
    /// Whether the advance of the head step computed ahead prepares its states again:
    /// `true` when the occupied cells left to compute are at least as many as those
    /// computed ahead; `false` otherwise, and it computes what is left without
    /// [`prepared::Prepared`], reading each left cell's rest from its neighbourhood, so a
    /// few border cells do not pay for preparing the whole territory twice.
    prepare_after_ahead: bool,
    /// Cell mode with delta ghosts: its repair stopped at a step whose remaining dirty
    /// cells read a view a ghost announced to change (K5); it waits for news (cleared by
    /// [`World::receive`]).
    waiting: bool,
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

    /// Load balancing's handover (SPEC.md §K13): the world takes the territory `part`
    /// gives it at step `step`, which every world has committed (GVT = `step` + 1, so every
    /// state at `step` is final and nothing later was committed). Its logs restart at `step`
    /// from `states`, the whole domain's final states there, exactly as a world started at
    /// `step` would hold them: the final state of a cell is its whole log at GVT, and it
    /// moves with the cell. Speculative states, messages, dirty steps and the inbox are
    /// dropped; [`World::start`] then sends the ghosts of `step` under the new owner map.
    /// Counters, the trace and the (adaptive) window carry on; the end is reset to `step` (raise it with
    /// [`World::set_end`]).
    pub fn reterritory(&mut self, part: Arc<Partition>, states: &CellStates<M::State>, step: Step) {
        let config = KernelConfig {
            mode: self.mode,
            window: self.throttle.as_ref().map_or(self.window, |t| t.ceiling),
            window_auto: self.throttle.is_some(),
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
        // The adaptive window carries on with the counters its epochs are measured against.
        fresh.window = self.window;
        fresh.throttle = self.throttle.take();
        for (x, &c) in fresh.cells.enumerate() {
            if let Ok(old) = self.cells.as_slice().binary_search(&c) {
                fresh.recomputes[x] = self.recomputes.as_slice()[old];
            }
        }
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
        self.cells.as_slice()
    }

    /// Per own cell (in the order of [`World::cells`]), its computations re-executed so far:
    /// where the rollbacks reached. Only for observing a run (live displays); a reterritory
    /// keeps the counts of the cells the world keeps, new cells start at 0.
    pub fn cell_recomputes(&self) -> &[u64] {
        self.recomputes.as_slice()
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
        for x in OwnCell::all(self.cells.len()) {
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
            Some(&MessageKey { step: s, kind, .. }) => {
                let non_ghost = kind == MessageKind::Input
                    || self
                        .inbox
                        .range(MessageKey::first_of(s, MessageKind::Migrate)..)
                        .next()
                        .is_some_and(|(k, _)| k.step == s);
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
        self.waiting = false;
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
    /// want to act again until it receives a message or GVT changes. Likewise a cell-mode
    /// repair that stopped to wait for announced ghosts (SPEC.md §K5) waits for a message,
    /// or for GVT to reach its LVT + 1.
    pub fn wants_to_act(&self, gvt: Step) -> bool {
        if !self.inbox.is_empty() {
            return true;
        }
        let lvt = self.lvt();
        if self.mode == RollbackMode::Conservative {
            // After an action that could not compute anything, only news (a message) or a
            // wider window (a new GVT) can unblock a cell.
            self.idle_at != Some(gvt) && lvt < self.end && lvt + 1 < gvt + self.window
        } else if self.dirty.is_empty() {
            self.may_advance(gvt)
        } else {
            // A repair waiting for announced ghosts resumes when news arrives, or when the
            // world holds GVT back (K5).
            !self.waiting || self.lvt() < gvt
        }
    }

    /// Whether an optimistic world may compute its next step at GVT `gvt`: it has one left
    /// and its window allows it (no world computes past GVT + W − 1, K3).
    fn may_advance(&self, gvt: Step) -> bool {
        self.head < self.end && self.head + 1 < gvt + self.window
    }

    /// One action: apply the whole inbox in key order if it is not empty; otherwise
    /// re-execute the dirty steps up to the head (Rollback and Propagate), or compute the next
    /// step if the window allows. Returns the messages sent. (Receiving and computing are
    /// separate actions, so a schedule can let every world apply its news before anyone
    /// computes.)
    pub fn act(&mut self, gvt: Step) -> Vec<Message<M::State>> {
        if let Some(t) = &mut self.throttle {
            self.window = t.on_gvt(gvt, self.window, &self.counters);
        }
        let mut out = Vec::new();
        if self.mode == RollbackMode::Conservative {
            self.act_conservative(gvt, &mut out);
        } else {
            self.act_optimistic(gvt, &mut out);
            self.flush_ghosts(&mut out);
            let held_back = self.head < self.end && !self.may_advance(gvt);
            if let Some(t) = &mut self.throttle {
                if held_back {
                    t.held_back();
                }
            }
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
            self.waiting = false;
            // Rollback and Propagate runs to the head in one action (thesis Algorithm 2), so
            // other worlds see the repaired outputs as early as possible — up to the first
            // step with cells that wait for an announced ghost (cell mode, delta ghosts).
            while let Some(&s) = self.dirty.keys().next() {
                // A world that holds GVT back (its LVT + 1 = GVT) does not wait (K5).
                let waiting = if s + 1 > gvt {
                    self.take_waiting(s)
                } else {
                    BTreeSet::new()
                };
                if !waiting.is_empty() {
                    // Repair what does not wait, then wait for the announced ghosts: their
                    // arrival would dirty these cells again (K5).
                    if self.dirty.contains_key(&s) {
                        self.reexecute(s, out);
                    }
                    self.dirty.insert(s, waiting);
                    self.waiting = true;
                    break;
                }
                self.reexecute(s, out);
            }
            // A repair that waits is finished later, still attributed to the same rollback
            // (or to a later one).
            if let (Some(r), false) = (&mut self.record, self.waiting) {
                r.repaired();
            }
        } else if self.may_advance(gvt) {
            self.advance(out);
        } else {
            self.counters.idle_acts += 1;
        }
    }
}
