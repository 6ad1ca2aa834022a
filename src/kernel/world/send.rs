//! Sending: ghosts of border cells and migrations, lazily (an anti-message and a new version
//! only when the content changed; SPEC.md §K4, "Lazy cancellation").

use super::index::OwnCell;
use super::keys::SentKey;
use super::log::{view, Live, Sent};
use super::World;
use crate::kernel::config::{PlantedBug, RollbackMode};
use crate::kernel::message::{Bodies, Homed, Message, MessageKind, Sign};
use crate::kernel::partition::WorldId;
use crate::model::{CellModel, Step};
use std::sync::Arc;

impl<M: CellModel> World<M> {
    /// Sends the message `key` of step `step` (its kind, own source cell and destination
    /// world) with `content` (`None`: no message) and the `follows` flag: in conservative
    /// mode always (an empty content is a null message); otherwise lazily — nothing if the
    /// live version sent before has the same content and flag (or there is none and
    /// `content` is `None`), else an anti-message for it (if any) and the new version (if
    /// any). `homed`: the copy of a state content's bodies with their cell that a message
    /// carries, built on first use and shared by every destination of one ghost.
    pub(super) fn send(
        &mut self,
        step: Step,
        key: SentKey,
        content: Option<Live<M::State>>,
        follows: bool,
        homed: &mut Option<Bodies<M::State>>,
        out: &mut Vec<Message<M::State>>,
    ) {
        let SentKey {
            kind,
            src_cell: cell,
            dst_world: w,
        } = key;
        let conservative = self.mode == RollbackMode::Conservative;
        let i = self.si(step);
        let sent = self.slots[i].sent.get(&key);
        let live = sent.and_then(|s| s.live.as_ref());
        let live_follows = sent.is_some_and(|s| s.follows);
        if !conservative {
            let same = match (live, &content) {
                (None, None) => true,
                (Some(a), Some(b)) => live_follows == follows && self.same_live(a, b),
                _ => false,
            };
            if same {
                return;
            }
        }
        let entry = self.slots[i].sent.entry(key).or_insert(Sent {
            seq: 0,
            live: None,
            follows: false,
        });
        let me = self.id;
        let bug = self.bug;
        let msg = |sign, seq, bodies, view| Message {
            edits: Vec::new(),
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
            view,
        };
        if entry.live.take().is_some() {
            let dropped = bug == PlantedBug::DropLoneAnti && content.is_none();
            if !conservative && !dropped {
                out.push(msg(Sign::Anti, entry.seq, Bodies::default(), None));
                self.counters.anti_messages_sent += 1;
            }
        }
        if let Some(content) = content {
            entry.seq += 1;
            entry.follows = follows;
            // A ghost's message carries a copy of the state with its cell (one copy for all
            // its destinations) and, within a process, the state itself for the receiver's
            // view; the log keeps the state (shared with the cell's log).
            let (bodies, shared): (Bodies<M::State>, _) = match &content {
                Live::Bodies(b) => (b.clone(), None),
                Live::State(st) => {
                    let copy = homed.get_or_insert_with(|| {
                        Arc::new(
                            view(st)
                                .iter()
                                .map(|b| Homed {
                                    cell,
                                    state: b.clone(),
                                })
                                .collect(),
                        )
                    });
                    (copy.clone(), st.clone())
                }
            };
            entry.live = Some(content);
            // Null messages are conservative mode's; an empty delta ghost (a border cell that
            // emptied) is news, counted as a ghost only.
            if conservative && bodies.is_empty() {
                self.counters.null_messages_sent += 1;
            }
            out.push(msg(Sign::Positive, entry.seq, bodies, shared));
            self.counters.messages_sent += 1;
            match kind {
                MessageKind::Ghost => self.counters.ghosts_sent += 1,
                MessageKind::Migrate => self.counters.migrates_sent += 1,
                MessageKind::Input => {}
            }
        }
    }

    /// Whether two contents sent under one identity are the same (by
    /// [`World::same_entity`]).
    fn same_live(&self, a: &Live<M::State>, b: &Live<M::State>) -> bool {
        match (a, b) {
            (Live::Bodies(a), Live::Bodies(b)) => self.same_bodies(a, b),
            (Live::State(a), Live::State(b)) => {
                let (a, b) = (view(a), view(b));
                a.len() == b.len() && a.iter().zip(b).all(|(p, q)| self.same_entity(p, q))
            }
            _ => false,
        }
    }

    /// Whether the state of own cell `x` at `u` differs from its state at `u − 1` (at the
    /// origin step: whether it is not empty).
    pub(super) fn changed(&self, x: OwnCell, u: Step) -> bool {
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
    pub(super) fn send_ghost(&mut self, x: OwnCell, t: Step, out: &mut Vec<Message<M::State>>) {
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
        let content = send.then(|| Live::State(self.slots[self.si(t)].states[x].clone()));
        let mut homed = None;
        for k in 0..self.targets[x].len() {
            let w = self.targets[x][k];
            let key = SentKey {
                kind: MessageKind::Ghost,
                src_cell: cell,
                dst_world: w,
            };
            self.send(t, key, content.clone(), follows, &mut homed, out);
        }
    }

    /// (Re)sends the bodies the computation of own cell `x` at `s` homes in world `w`'s cells.
    pub(super) fn send_migrate(
        &mut self,
        x: OwnCell,
        s: Step,
        w: WorldId,
        out: &mut Vec<Message<M::State>>,
    ) {
        let i = self.si(s);
        let part = &*self.part;
        let content: Vec<Homed<M::State>> = self.slots[i].outs[x]
            .as_ref()
            .map(|o| {
                o.pairs()
                    .filter(|(d, _)| part.owner(*d) == w)
                    .map(|(d, b)| Homed {
                        cell: d,
                        state: b.clone(),
                    })
                    .collect()
            })
            .unwrap_or_default();
        let content = (self.mode == RollbackMode::Conservative || !content.is_empty())
            .then(|| Live::Bodies(Arc::new(content)));
        let key = SentKey {
            kind: MessageKind::Migrate,
            src_cell: self.cells[x],
            dst_world: w,
        };
        self.send(s + 1, key, content, false, &mut None, out);
    }

    /// Sends the ghosts due (`ghost_due`) in (step, cell) order: at the end of an action, so a
    /// state changed several times within it is sent once.
    pub(super) fn flush_ghosts(&mut self, out: &mut Vec<Message<M::State>>) {
        for (t, x) in std::mem::take(&mut self.ghost_due) {
            self.send_ghost(x, t, out);
        }
    }
}
