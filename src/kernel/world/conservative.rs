//! Conservative mode: a world never speculates; a cell computes a step once every state it
//! reads is known, and sends null messages so its neighbours know what it will not send
//! (SPEC.md §K5).

use super::index::{cells_around, OwnCell};
use super::keys::MigrationIn;
use super::log::Out;
use super::World;
use crate::kernel::message::{Message, MessageKind};
use crate::model::{CellModel, Step};
use std::sync::Arc;

impl<M: CellModel> World<M> {
    /// One conservative action: apply the whole inbox if it is not empty (making known what
    /// it completes), else compute every own cell that can.
    pub(super) fn act_conservative(&mut self, gvt: Step, out: &mut Vec<Message<M::State>>) {
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
                    let seq = msg.seq;
                    self.slots[i]
                        .inputs
                        .insert(seq, super::log::InputEntry::of(msg));
                }
                MessageKind::Ghost => {
                    let slot = &mut self.slots[i];
                    slot.ghost_known.insert(src);
                    if !msg.bodies.is_empty() {
                        let m = self.margin_cell(src);
                        self.slots[i].ghosts[m] = Self::ghost_view(msg);
                    } else {
                        // An empty cell at `step` migrates nothing at `step + 1`.
                        self.ensure_slot(step + 1);
                        let j = self.si(step + 1);
                        self.slots[j].migrate_known.insert(src);
                        let grid = self.grid.clone();
                        for n in cells_around(&grid, src) {
                            if self.is_own(n) {
                                self.try_know(n, step + 1, out);
                            }
                        }
                    }
                }
                MessageKind::Migrate => {
                    let slot = &mut self.slots[i];
                    slot.migrate_known.insert(src);
                    for h in Arc::unwrap_or_clone(msg.bodies) {
                        slot.foreign_in
                            .entry(MigrationIn {
                                dst_cell: h.cell,
                                src_cell: src,
                            })
                            .or_default()
                            .push(h.state);
                    }
                    let grid = self.grid.clone();
                    for n in cells_around(&grid, src) {
                        if self.is_own(n) {
                            self.try_know(n, step, out);
                        }
                    }
                }
            }
        }
        if drain {
            return;
        }
        let mut progressed = false;
        for x in OwnCell::all(self.cells.len()) {
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

    /// Whether the state of global cell `cell` at `s` (own) or its ghost (foreign) is known.
    pub(super) fn known(&self, cell: u32, s: Step) -> bool {
        let slot = &self.slots[self.si(s)];
        if self.is_own(cell) {
            slot.known[self.own(cell)]
        } else {
            slot.ghost_known.contains(&cell)
        }
    }

    /// Computes own cell `x` at its next step if the window allows and every state it reads
    /// is known; then sends its migrations and makes known what it completes. Returns
    /// whether it computed.
    pub(super) fn try_compute(
        &mut self,
        x: OwnCell,
        gvt: Step,
        out: &mut Vec<Message<M::State>>,
    ) -> bool {
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
            let ready = cells_around(&self.grid, cell).all(|n| self.known(n, s));
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
        for n in cells_around(&grid, cell) {
            if self.is_own(n) {
                self.try_know(n, s + 1, out);
            }
        }
        true
    }

    /// Conservative: makes the state of own cell `d` at `t` known once every cell around it
    /// has produced its output at `t − 1`; then sends its ghost (a null message if empty).
    pub(super) fn try_know(&mut self, d: u32, t: Step, out: &mut Vec<Message<M::State>>) {
        if t < self.base + 1 {
            return;
        }
        self.ensure_slot(t);
        let x = self.own(d);
        let (ip, i) = (self.si(t - 1), self.si(t));
        if self.slots[i].known[x] {
            return;
        }
        let ready = cells_around(&self.grid, d).all(|n| {
            if self.is_own(n) {
                self.slots[ip].outs[self.own(n)].is_some()
            } else {
                self.slots[i].migrate_known.contains(&n)
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
