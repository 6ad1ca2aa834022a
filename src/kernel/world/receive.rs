//! Receiving (optimistic modes): applying the inbox in key order, annihilating
//! anti-messages, and the effect of each message kind on the log (SPEC.md §K4).

use super::index::OwnCell;
use super::keys::{MigrationIn, RecvKey};
use super::log::{view, Carried, Shared, Version};
use super::World;
use crate::kernel::config::RollbackMode;
use crate::kernel::message::{Bodies, Message, MessageKind, Sign};
use crate::kernel::SharedStates;
use crate::model::{CellModel, Step};
use std::collections::BTreeSet;
use std::sync::Arc;

impl<M: CellModel> World<M> {
    pub(super) fn drain_inbox(&mut self) {
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
                let all: BTreeSet<OwnCell> = OwnCell::all(self.cells.len()).collect();
                for s in s0..self.head {
                    self.dirty.insert(s, all.clone());
                }
            }
        }
    }

    /// Applies one message (optimistic modes). Returns the step at which it made cells dirty,
    /// if it did.
    pub(super) fn apply(&mut self, msg: Message<M::State>) -> Option<Step> {
        let step = msg.step;
        self.ensure_slot(step);
        let i = self.si(step);
        let src = msg.src_cell;
        let kind = msg.kind;
        if kind == MessageKind::Input {
            return self.apply_input(msg);
        }
        let delta = self.delta();
        let r = self.slots[i]
            .recv
            .entry(RecvKey {
                kind,
                src_cell: src,
            })
            .or_default();
        let before = r.effective().map(|e| e.seq);
        // The cells the effective migration landed in (ghosts do not need them).
        let old_cells: Vec<u32> = match r.effective() {
            Some(e) if kind == MessageKind::Migrate => e.bodies().iter().map(|h| h.cell).collect(),
            _ => Vec::new(),
        };
        match msg.sign {
            Sign::Positive => {
                if let Some(k) = r.antis.iter().position(|&a| a == msg.seq) {
                    r.antis.swap_remove(k);
                    self.counters.annihilated += 1;
                } else {
                    // A ghost is kept as the view it gives (the message's copy is dropped:
                    // moved out when this world holds its only reference).
                    let (seq, follows) = (msg.seq, msg.follows);
                    let content = if kind == MessageKind::Ghost {
                        Carried::View(Self::ghost_view(msg))
                    } else {
                        Carried::Bodies(msg.bodies)
                    };
                    r.positives.push(Version {
                        seq,
                        content,
                        follows,
                    });
                }
            }
            Sign::Anti => {
                if let Some(k) = r.positives.iter().position(|p| p.seq == msg.seq) {
                    r.positives.swap_remove(k);
                    self.counters.annihilated += 1;
                } else {
                    r.antis.push(msg.seq);
                }
            }
        }
        let after = r.effective().map(|e| e.seq);
        if before == after {
            return None;
        }
        if kind == MessageKind::Ghost {
            // The view of `src` at `step`: the effective ghost, else the view of the step
            // before (K4, delta ghosts).
            let (view, follows) = match r.effective() {
                Some(Version {
                    content: Carried::View(v),
                    follows,
                    ..
                }) => (v.clone(), *follows),
                Some(_) => unreachable!("a ghost's version carries a view"),
                None if i > 0 && delta => {
                    let m = self.margin_cell(src);
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
        let new: Bodies<M::State> = match r.effective().map(|e| &e.content) {
            Some(Carried::Bodies(b)) => b.clone(),
            _ => Bodies::default(),
        };
        match kind {
            MessageKind::Input => unreachable!("inputs are applied by apply_input"),
            MessageKind::Ghost => unreachable!("ghosts are applied above"),
            MessageKind::Migrate => {
                let mut dsts: Vec<u32> = old_cells;
                dsts.extend(new.iter().map(|h| h.cell));
                dsts.sort_unstable();
                dsts.dedup();
                for &d in &dsts {
                    assert!(
                        self.is_own(d),
                        "migration into a cell this world does not own"
                    );
                    let bodies: Vec<M::State> = new
                        .iter()
                        .filter(|h| h.cell == d)
                        .map(|h| h.state.clone())
                        .collect();
                    let slot = &mut self.slots[i];
                    let key = MigrationIn {
                        dst_cell: d,
                        src_cell: src,
                    };
                    if bodies.is_empty() {
                        slot.foreign_in.remove(&key);
                    } else {
                        slot.foreign_in.insert(key, bodies);
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

    /// The view a ghost gives (`None`: empty): the sender's state itself when the message
    /// carries it (within a process), else its bodies' states.
    pub(super) fn ghost_view(msg: Message<M::State>) -> Shared<M::State> {
        if msg.bodies.is_empty() {
            return None;
        }
        match msg.view {
            Some(v) if v.len() == msg.bodies.len() => Some(v),
            _ => Some(SharedStates::from_exact(
                Arc::unwrap_or_clone(msg.bodies)
                    .into_iter()
                    .map(|h| h.state),
            )),
        }
    }

    /// Sets the view of foreign cell `src` at `t` to `view` (`None`: empty) and, with delta
    /// ghosts, carries it forward to the later steps that inherit it (up to the next step
    /// with an effective ghost of its own) — unless the ghost `follows` (a ghost of `t + 1`
    /// is on its way: the later views are left as they are, as the computations used them,
    /// until it arrives). At each computed step (below the head) whose view changed, the own
    /// cells that read the change become dirty. Returns the first step made dirty, if any.
    pub(super) fn set_ghost_view(
        &mut self,
        src: u32,
        t: Step,
        view: Shared<M::State>,
        follows: bool,
    ) -> Option<Step> {
        let carry = self.delta() && !follows;
        let m = self.margin_cell(src);
        let mut first = None;
        let mut u = t;
        while let Some(slot) = self.slots.get_mut(self.si(u)) {
            // Later steps take the view only if they inherit it: no ghost of their own.
            let own_ghost = || {
                slot.recv
                    .get(&RecvKey {
                        kind: MessageKind::Ghost,
                        src_cell: src,
                    })
                    .is_some_and(|r| r.effective().is_some())
            };
            if u > t && (!carry || own_ghost()) {
                break;
            }
            let old = std::mem::replace(&mut slot.ghosts[m], view.clone());
            let unchanged = match (&old, &view) {
                (None, None) => true,
                (Some(a), Some(b)) => SharedStates::ptr_eq(a, b) || Self::same_states(a, b),
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

    /// Applies an input (optimistic modes): stored in its step's slot; if that step's states
    /// exist, the own cells holding a removed entity or receiving an added one are rebuilt.
    pub(super) fn apply_input(&mut self, msg: Message<M::State>) -> Option<Step> {
        let step = msg.step;
        assert!(step >= 1, "inputs apply to steps from 1 on");
        let i = self.si(step);
        let mut cells: BTreeSet<u32> = msg
            .bodies
            .iter()
            .map(|h| h.cell)
            .filter(|&c| self.is_own(c))
            .collect();
        if step <= self.head {
            for (x, st) in OwnCell::all(self.cells.len()).zip(self.slots[i].states.iter()) {
                let touched = |b: &M::State| {
                    let id = M::id(b);
                    msg.removes.contains(&id) || msg.edits.iter().any(|e| e.id == id)
                };
                if view(st).iter().any(touched) {
                    cells.insert(self.cells[x]);
                }
            }
        }
        let seq = msg.seq;
        self.slots[i]
            .inputs
            .insert(seq, super::log::InputEntry::of(msg));
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
}
