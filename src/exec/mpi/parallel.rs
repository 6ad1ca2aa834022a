//! A rank's worlds on several threads between two GVT rounds (`--threads T` under MPI,
//! SPEC.md §14): the rank's main thread and `T − 1` helpers take turns acting on the rank's
//! worlds, each world behind its own lock, the one with messages waiting and then the
//! smallest LVT first (the single-threaded rank's order, and the threaded executor's laggard
//! first). Messages to worlds of the rank go straight into their inboxes; messages to other
//! ranks wait in one outbox that only the main thread sends from, and only the main thread
//! receives: MPI is called from one thread (`MPI_THREAD_FUNNELED`).
//!
//! Interleavings only change when messages arrive, never what is committed: every world is
//! the kernel's Time Warp world, whose committed steps are the reference's under any order
//! of actions and deliveries (SPEC.md §K7).

use super::PlantedTransportBug;
use crate::exec::load::LoadMeter;
use crate::exec::sync::panic_message;
use crate::kernel::message::Message;
use crate::kernel::world::World;
use crate::model::{CellModel, Step};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, MutexGuard};

/// One world of the rank and its load meter, behind one lock.
struct Slot<M: CellModel> {
    world: World<M>,
    meter: LoadMeter,
}

/// The rank's worlds shared by its threads for one work phase.
pub(super) struct Pool<'a, M: CellModel> {
    slots: Vec<Mutex<Slot<M>>>,
    /// World id → index in `slots`, for the rank's worlds.
    local: &'a [Option<usize>],
    /// World id → rank.
    owner: &'a [usize],
    /// Messages for each other rank, sent by the main thread.
    outbox: Mutex<Vec<Vec<Message<M::State>>>>,
    gvt: Step,
    /// Actions left in this phase.
    budget: AtomicUsize,
    /// Threads looking for or doing work: a thread that finds nothing to do while no other
    /// is busy ends its part of the phase.
    busy: AtomicUsize,
    /// The first failure: a world's panic, as the message the rank aborts with.
    failure: Mutex<Option<String>>,
    planted: PlantedTransportBug,
    me: usize,
}

/// The order in which worlds are picked: messages waiting first (`false` sorts first), then
/// the smallest LVT, then the lowest index.
type PickKey = (bool, Step, usize);

/// What a work phase left: the worlds and meters (in their order) and the first failure.
pub(super) struct PhaseEnd<M: CellModel> {
    pub(super) worlds: Vec<World<M>>,
    pub(super) meters: Vec<LoadMeter>,
    pub(super) failure: Option<String>,
}

/// What one turn of a thread did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Turn {
    /// It acted on a world.
    Acted,
    /// Nothing to do now, but another thread is busy (work may come).
    Wait,
    /// The phase is over for this thread: the budget is spent, or nothing can act.
    Done,
}

impl<'a, M: CellModel> Pool<'a, M> {
    /// The pool of a rank's `worlds` for a phase of at most `budget` actions at `gvt`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn new(
        worlds: Vec<World<M>>,
        meters: Vec<LoadMeter>,
        local: &'a [Option<usize>],
        owner: &'a [usize],
        ranks: usize,
        gvt: Step,
        budget: usize,
        planted: PlantedTransportBug,
        me: usize,
    ) -> Self {
        Pool {
            slots: worlds
                .into_iter()
                .zip(meters)
                .map(|(world, meter)| Mutex::new(Slot { world, meter }))
                .collect(),
            local,
            owner,
            outbox: Mutex::new(vec![Vec::new(); ranks]),
            gvt,
            budget: AtomicUsize::new(budget),
            busy: AtomicUsize::new(0),
            failure: Mutex::new(None),
            planted,
            me,
        }
    }

    /// Number of worlds.
    pub(super) fn len(&self) -> usize {
        self.slots.len()
    }

    /// Locks slot `i` (a thread holds at most this one lock while it waits for a lock).
    fn lock(&self, i: usize) -> MutexGuard<'_, Slot<M>> {
        self.slots[i].lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Puts `msg` in the inbox of local world `i`.
    pub(super) fn deliver(&self, i: usize, msg: Message<M::State>) {
        self.lock(i).world.receive(msg);
    }

    /// Takes the messages waiting for other ranks.
    pub(super) fn take_outbox(&self) -> Vec<Vec<Message<M::State>>> {
        let mut out = self.outbox.lock().unwrap_or_else(|e| e.into_inner());
        let empty = vec![Vec::new(); out.len()];
        std::mem::replace(&mut *out, empty)
    }

    /// The unlocked world to act next, locked: one with messages first, then the smallest
    /// LVT, then the lowest index. Only `try_lock`s, so no thread waits for another here.
    fn pick(&self) -> Option<(usize, MutexGuard<'_, Slot<M>>)> {
        let mut best: Option<(PickKey, MutexGuard<'_, Slot<M>>)> = None;
        for (i, slot) in self.slots.iter().enumerate() {
            let Ok(guard) = slot.try_lock() else { continue };
            if !guard.world.wants_to_act(self.gvt) {
                continue;
            }
            let key = (!guard.world.has_inbox(), guard.world.lvt(), i);
            if best.as_ref().is_none_or(|(k, _)| key < *k) {
                best = Some((key, guard));
            }
        }
        best.map(|((_, _, i), guard)| (i, guard))
    }

    /// One turn of a thread: pick a world, act, route what it sent.
    pub(super) fn turn(&self) -> Turn {
        if self.budget.load(Ordering::Acquire) == 0 {
            return Turn::Done;
        }
        self.busy.fetch_add(1, Ordering::AcqRel);
        let picked = self.pick();
        let Some((_, mut slot)) = picked else {
            // Nothing to act on: done unless another thread is busy.
            let others = self.busy.fetch_sub(1, Ordering::AcqRel) - 1;
            return if others == 0 { Turn::Done } else { Turn::Wait };
        };
        if self
            .budget
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |b| b.checked_sub(1))
            .is_err()
        {
            drop(slot);
            self.busy.fetch_sub(1, Ordering::AcqRel);
            return Turn::Done;
        }
        let gvt = self.gvt;
        let (planted, me) = (self.planted, self.me);
        let lvt = slot.world.lvt();
        let id = slot.world.id();
        let acted = catch_unwind(AssertUnwindSafe(|| {
            if let PlantedTransportBug::Panic(r, s) = planted {
                if r == me && lvt >= s {
                    panic!("planted panic (SODA_MPI_PLANTED_BUG)");
                }
            }
            slot.world.act(gvt)
        }));
        let msgs = match acted {
            Ok(msgs) => {
                let lvt = slot.world.lvt();
                slot.meter.note_action(lvt, gvt);
                msgs
            }
            Err(p) => {
                let mut failure = self.failure.lock().unwrap_or_else(|e| e.into_inner());
                failure.get_or_insert_with(|| {
                    format!(
                        "world {id} panicked while computing from step {lvt}: {}",
                        panic_message(&*p)
                    )
                });
                self.budget.store(0, Ordering::Release);
                Vec::new()
            }
        };
        drop(slot);
        self.route(msgs);
        self.busy.fetch_sub(1, Ordering::AcqRel);
        Turn::Acted
    }

    /// Delivers messages a world sent: into the rank's worlds, or the outbox.
    fn route(&self, msgs: Vec<Message<M::State>>) {
        let mut remote: Vec<(usize, Message<M::State>)> = Vec::new();
        for m in msgs {
            let w = m.dst_world as usize;
            match self.local[w] {
                Some(i) => self.deliver(i, m),
                None => remote.push((self.owner[w], m)),
            }
        }
        if !remote.is_empty() {
            let mut out = self.outbox.lock().unwrap_or_else(|e| e.into_inner());
            for (rank, m) in remote {
                out[rank].push(m);
            }
        }
    }

    /// A helper thread's part of the phase: turns until it is done.
    pub(super) fn help(&self) {
        loop {
            match self.turn() {
                Turn::Acted => {}
                Turn::Wait => std::thread::yield_now(),
                Turn::Done => return,
            }
        }
    }

    /// The worlds and meters back, and the first failure.
    pub(super) fn finish(self) -> PhaseEnd<M> {
        let mut worlds = Vec::with_capacity(self.slots.len());
        let mut meters = Vec::with_capacity(self.slots.len());
        for slot in self.slots {
            let slot = slot.into_inner().unwrap_or_else(|e| e.into_inner());
            worlds.push(slot.world);
            meters.push(slot.meter);
        }
        PhaseEnd {
            worlds,
            meters,
            failure: self.failure.into_inner().unwrap_or_else(|e| e.into_inner()),
        }
    }
}
