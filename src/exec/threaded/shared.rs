//! The state of a threaded run that the worker threads and the output stage share, and its
//! basic operations: the run status, queueing a world, sending a message, posting an input.

use super::output::{Assembly, FinishedFrame, Output};
use crate::exec::error::{ExecError, InputError};
use crate::exec::load::LoadMeter;
use crate::exec::schedule::Schedule;
use crate::exec::sync::{Facade, FacadeAtomic, FacadeMutex, SLOW_POLL};
use crate::exec::LastFrame;
use crate::frame::StatesWanted;
use crate::grid::Grid;
use crate::kernel::message::{Input, Message};
use crate::kernel::world::World;
use crate::model::{CellModel, Step};
use crossbeam_deque::Injector;
use std::cmp::Reverse;
use std::collections::VecDeque;
use std::sync::Arc;
use std::time::Instant;

/// Where a threaded run (or its current epoch) is. Stored in an atomic as its `u64`, so
/// the workers and the output stage read it without a lock.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum RunStatus {
    /// The workers run worlds.
    Running = 0,
    /// The epoch's last step is committed, or the sink stopped the run: the workers return.
    Done = 1,
    /// A world panicked or the run stalled (the error is in `SharedRun::error`), or a worker
    /// unwound (its panic comes back with its join).
    Failed = 2,
}

impl RunStatus {
    /// The status stored as `v` (`RunStatus as u64`).
    fn from_u64(v: u64) -> RunStatus {
        match v {
            0 => RunStatus::Running,
            1 => RunStatus::Done,
            2 => RunStatus::Failed,
            _ => unreachable!("run status {v} was never stored"),
        }
    }
}

/// When a worker first found GVT at its cap over the last frame delivered, and which frame
/// that was ([`SharedRun::paced_by_output`]).
#[derive(Clone, Copy, Debug)]
pub(super) struct CapSeen {
    /// The last frame delivered then.
    delivered: Step,
    /// When.
    since: Instant,
}

/// GVT stays within this many optimism windows (of at least 8 steps) of the last step the
/// sink was handed: committed frames the sink has not taken are held in memory, so a slow
/// sink must slow the run, not grow it (SPEC.md §K7).
pub(super) const UNDELIVERED_WINDOWS: Step = 4;

/// The state of a threaded run that the worker threads and the output stage share.
pub(super) struct SharedRun<M: CellModel + 'static, F: Facade> {
    /// The worlds, each under its own lock (a world runs on one thread at a time).
    pub(super) worlds: Vec<F::Mutex<ThreadedWorld<M>>>,
    /// Per world, the messages sent to it and not yet received.
    pub(super) inboxes: Vec<F::Mutex<Vec<Message<M::State>>>>,
    /// Per world, a lower bound of its `bound()` (written only under the world's lock).
    pub(super) published: Vec<F::Atomic>,
    /// Per inbox, a lower bound of the `affects` of the messages in it (`u64::MAX`: none).
    pub(super) inbox_min: Vec<F::Atomic>,
    /// Bumped before every write that can raise a `published` or `inbox_min` value, so a
    /// GVT reader can tell whether its snapshot is consistent (SPEC.md §K7).
    pub(super) version: F::Atomic,
    /// The ready set and where every world's task is.
    pub(super) sched: F::Mutex<Schedule>,
    /// Per world, nanoseconds of its last forward computation (for the ready set's order only).
    pub(super) cost: Vec<F::Atomic>,
    /// Per world, the thread that last ran an action of it (to count migrations).
    pub(super) home: Vec<F::Atomic>,
    /// Whether a thread prefers, among equally critical ready worlds, one it ran last: with
    /// no more worlds than threads each world then stays on one core (its cache warm);
    /// with more, the heaviest world first matters more.
    pub(super) stay_home: bool,
    /// Per thread, 1 while it backs off for want of a task: with `stay_home`, a world whose
    /// home thread is idle is left to that thread, which takes it on its next look.
    pub(super) idle: Vec<F::Atomic>,
    /// Tokens of worlds that had to wait (postponed behind a laggard, or running elsewhere):
    /// any thread takes them when nothing is ready, so a waiting world never sits behind a
    /// busy thread's work. A token is live only while the schedule still holds it.
    pub(super) waiting: Injector<(usize, u64)>,
    /// The current GVT.
    pub(super) gvt: F::Atomic,
    /// The last step queued for finishing (0 before any).
    pub(super) committed: F::Atomic,
    /// The last step the sink has been handed (0 before any).
    pub(super) delivered: F::Atomic,
    /// How far GVT may run ahead of the sink: a sink that takes its time (a display
    /// showing frames in real time, a slow disk) holds the run back instead of letting
    /// undelivered frames pile up in memory ([`UNDELIVERED_WINDOWS`] optimism windows).
    pub(super) undelivered: Step,
    /// 1 while a thread computes GVT or posts an input (they exclude each other).
    pub(super) gvt_round: F::Atomic,
    /// A [`RunStatus`] as its `u64`.
    pub(super) status: F::Atomic,
    /// The last step of the current epoch: the run's last step, or the next balancing
    /// round's (the worlds stop there so every state at it is final when cells move).
    pub(super) target: F::Atomic,
    /// Whether the mode is optimistic (not conservative).
    pub(super) optimistic: bool,
    /// How many steps a world may compute ahead of its slowest neighbour world before it
    /// lets laggards run first (optimistic modes;
    /// [`ThreadedOptions::lead`](super::ThreadedOptions::lead)).
    pub(super) lead: Step,
    /// Whether a postponed world computes its interior ahead
    /// ([`ThreadedOptions::compute_ahead`](super::ThreadedOptions::compute_ahead)).
    pub(super) compute_ahead: bool,
    /// Committed steps being assembled from the worlds' contributions.
    pub(super) assembly: F::Mutex<Assembly<M>>,
    /// Whole committed steps waiting to be finished, and the run's statistics.
    pub(super) out: F::Mutex<Output<M>>,
    /// Frames sorted and hashed, in step order, waiting for the output stage
    /// (the calling thread, which hands them to the sink).
    pub(super) finished: F::Mutex<VecDeque<FinishedFrame<M>>>,
    /// What the one thread finishing frames at a time holds
    /// ([`SharedRun::finish_pending`]; only ever try-locked).
    pub(super) finishing: F::Mutex<Finishing>,
    /// What the sink wants of each frame's states.
    pub(super) wanted: StatesWanted,
    /// The first error of the run (a world panicked, the run stalled).
    pub(super) error: F::Mutex<Option<ExecError>>,
    /// The inputs posted so far: their number (the next input's sequence number) and one
    /// copy of each (re-posted to the worlds after a balancing round that moved cells).
    pub(super) inputs: F::Mutex<InputLog<M::State>>,
    /// The grid (to check inputs).
    pub(super) grid: Arc<Grid>,
    /// 1 once the sink stopped the run.
    pub(super) stop: F::Atomic,
    /// Whether worlds record a trace (`KernelConfig::trace`).
    pub(super) trace: bool,
    /// When the run started (trace times count from it).
    pub(super) started: Instant,
}

/// A world as the threaded executor holds it, under the world's lock.
pub(super) struct ThreadedWorld<M: CellModel> {
    /// The world.
    pub(super) world: World<M>,
    /// The last step it has handed to the frame assembly.
    pub(super) contributed: Step,
    /// What the next balancing round measures of it (busy CPU time, lead over GVT).
    pub(super) meter: LoadMeter,
}

/// The state carried from one finished frame to the next.
#[derive(Default)]
pub(super) struct Finishing {
    /// The last frame finished (a step no world changed keeps its hash).
    pub(super) last: Option<LastFrame>,
    /// Whether finishing a frame panicked: no later step is finished, so the sink never
    /// gets a frame after a gap, whatever the run's status says meanwhile.
    pub(super) failed: bool,
}

/// The inputs posted so far.
pub(super) struct InputLog<S> {
    /// Their number (the last input's sequence number).
    pub(super) count: u32,
    /// One copy of each, in posting order (re-posted after a balancing round that moved
    /// cells).
    pub(super) posted: Vec<Message<S>>,
}

/// Ends the run if the thread holding it leaves by unwinding, so that no other thread waits
/// for it: the calling thread when the sink panics ([`EndOnUnwind::stopping`]), a worker
/// when a panic escapes the computations whose panics are caught ([`EndOnUnwind::failing`]:
/// a kernel bug, or a model's `Clone` or `Drop` of a state or event).
pub(super) struct EndOnUnwind<'a, M: CellModel + 'static, F: Facade> {
    run: &'a SharedRun<M, F>,
    ending: RunStatus,
}

impl<'a, M: CellModel + 'static, F: Facade> EndOnUnwind<'a, M, F> {
    /// Stops the run (the workers return, unfinished frames are dropped): the panic goes on
    /// unwinding out of the run.
    pub(super) fn stopping(run: &'a SharedRun<M, F>) -> Self {
        EndOnUnwind {
            run,
            ending: RunStatus::Done,
        }
    }

    /// Fails the run: the panic's message reaches the caller through the thread's join
    /// ([`ExecError::Thread`]).
    pub(super) fn failing(run: &'a SharedRun<M, F>) -> Self {
        EndOnUnwind {
            run,
            ending: RunStatus::Failed,
        }
    }
}

impl<M: CellModel + 'static, F: Facade> Drop for EndOnUnwind<'_, M, F> {
    fn drop(&mut self) {
        if std::thread::panicking() {
            if self.ending == RunStatus::Done {
                self.run.stop.store(1);
            }
            self.run.set_status(self.ending);
        }
    }
}

impl<M: CellModel + 'static, F: Facade> SharedRun<M, F> {
    /// The run's status now.
    pub(super) fn status(&self) -> RunStatus {
        RunStatus::from_u64(self.status.load())
    }

    /// Sets the run's status.
    pub(super) fn set_status(&self, status: RunStatus) {
        self.status.store(status as u64);
    }

    /// How many steps the workers can commit before they wait for the output stage (the
    /// calling thread): to the epoch's last step (the epoch ends when the output stage
    /// notices), or to the cap of GVT's lead over the last frame delivered (at the cap GVT
    /// stops), whichever comes first.
    pub(super) fn steps_before_output_is_awaited(&self) -> Step {
        let to_epoch_end = self.target.load().saturating_sub(self.committed.load());
        let cap = self.delivered.load() + 1 + self.undelivered;
        let to_cap = cap.saturating_sub(self.gvt.load());
        to_epoch_end.min(to_cap)
    }

    /// Whether GVT stands at the cap of its lead over the last frame delivered (no step can
    /// commit until the output stage takes a frame) and the output stage has taken none
    /// for at least [`SLOW_POLL`]: the run is paced by its consumer. `seen` is the calling
    /// thread's memory of when it first saw the cap at the current delivered frame.
    pub(super) fn paced_by_output(&self, seen: &mut Option<CapSeen>) -> bool {
        let delivered = self.delivered.load();
        if self.gvt.load() < delivered + 1 + self.undelivered {
            *seen = None;
            return false;
        }
        match seen {
            Some(s) if s.delivered == delivered => s.since.elapsed() >= SLOW_POLL,
            _ => {
                *seen = Some(CapSeen {
                    delivered,
                    since: Instant::now(),
                });
                false
            }
        }
    }

    /// Queues world `w` in the ready set unless it is already queued or taken. A waiting
    /// world moves to the ready set (its token goes stale): what woke it (a message, a GVT
    /// advance) may let it act, and it must not wait behind worlds that are still blocked.
    pub(super) fn schedule(&self, w: usize) {
        let key = (self.published[w].load(), Reverse(self.cost[w].load()), w);
        self.sched.lock().wake(key);
    }

    /// Sends world `w`'s task to the waiting queue: taken by a thread that found it running
    /// elsewhere, or postponed by its own turn (then its task is idle, unless a message
    /// queued it meanwhile: a ready task stays ready).
    pub(super) fn wait(&self, w: usize) {
        let token = self.sched.lock().wait(w);
        if let Some(token) = token {
            self.waiting.push((w, token));
        }
    }

    pub(super) fn fail(&self, e: ExecError) {
        let mut first = self.error.lock();
        if first.is_none() {
            *first = Some(e);
        }
        self.set_status(RunStatus::Failed);
    }

    /// Sends `m`: into its receiver's inbox, lowering that inbox's published minimum.
    pub(super) fn send(&self, m: Message<M::State>) {
        let d = m.dst_world as usize;
        let affects = m.affects();
        {
            let mut inbox = self.inboxes[d].lock();
            inbox.push(m);
            self.lower(&self.inbox_min[d], affects);
        }
        self.schedule(d);
    }

    /// Schedules an input at `step` (SPEC.md §K12): checked against the earliest step
    /// still open and broadcast to every world's inbox. It holds the GVT round's flag
    /// meanwhile, so GVT cannot pass `step` between the check and the inboxes' lowered
    /// bounds (a GVT round reads those bounds only while holding the flag).
    pub(super) fn post_input(&self, step: Step, input: Input<M::State>) -> Result<(), InputError> {
        let mut spins = 0u32;
        while self.gvt_round.swap(1) == 1 {
            F::pause(spins);
            spins = spins.saturating_add(1);
        }
        // Conservative mode: every world stays locked until the input is in its inbox, so no
        // world makes a state at the input's step known between the check and the delivery.
        let locked: Option<Vec<_>> =
            (!self.optimistic).then(|| self.worlds.iter().map(|m| m.lock()).collect());
        let floor = match &locked {
            None => self.gvt.load(),
            Some(worlds) => 1 + worlds.iter().map(|s| s.world.frontier()).max().unwrap_or(0),
        };
        let checked = crate::exec::check_input::<M>(&self.grid, floor, step, &input);
        if checked.is_ok() {
            let mut log = self.inputs.lock();
            log.count += 1;
            let msg = crate::exec::input_message::<M>(&self.grid, step, input, log.count);
            log.posted.push(msg.clone());
            drop(log);
            for m in crate::exec::to_every_world(&msg, self.worlds.len()) {
                self.send(m);
            }
        }
        drop(locked);
        self.gvt_round.store(0);
        checked
    }

    pub(super) fn lower(&self, a: &F::Atomic, v: u64) {
        if v < a.load() {
            a.store(v);
        }
    }
}
