//! The threaded executor: T OS threads run the kernel's worlds as tasks. Ready worlds wait
//! in one shared set ordered critical path first (the laggard first; among worlds at the
//! same step, the one whose last computation took longest); worlds that had to wait
//! (postponed behind a laggard, or running elsewhere) go to a crossbeam-deque [`Injector`]
//! that threads take from when nothing is ready, until a message or a GVT advance moves
//! them back into the ready set. A world runs on at most one thread at a
//! time (its lock); a world that cannot act (window full, conservative dependency) simply is
//! not rescheduled until a message or a GVT advance gives it something to do, so its thread
//! serves other worlds.
//!
//! GVT (SPEC.md §K7, §10) without stopping the world: every world publishes a lower bound of
//! its `bound()` after each turn, every inbox a lower bound of its messages' `affects`; a
//! message moves from its sender's bound to an inbox (pushed before the sender publishes a
//! higher bound) and from an inbox to its receiver's bound (lowered before the inbox is
//! emptied). Every write that can raise a published value first bumps a version counter; a
//! GVT reader takes the minimum of all published values and accepts it only if the version
//! did not change meanwhile, so it never misses a message in transit between two of them.
//! After GVT advances, each world hands its states of the new committed steps to a frame
//! assembly on its next turn and fossil-collects; a frame is finished (all worlds merged,
//! sorted, hashed — by the output stage on the calling thread) only once every world has
//! contributed, and queued in step order. A frame is never torn or speculative.
//!
//! This is the only module that starts threads, and it does so through [`Facade`].

use super::clock::thread_cpu_seconds;
use super::control::RunControl;
pub use super::error::ExecError;
use super::error::InputError;
use super::live::{LiveStatus, WorldStatus};
use super::load::LoadMeter;
use super::schedule::Schedule;
use super::sync::{panic_message, Facade, FacadeAtomic, FacadeMutex, StdFacade};
use crate::frame::{Event, Frame, StatesWanted};
use crate::grid::Grid;
use crate::kernel::balance::{imbalance, Balancer, RoundRecord};
use crate::kernel::counters::Counters;
use crate::kernel::message::{Input, Message};
use crate::kernel::partition::WorldId;
use crate::kernel::trace::{GvtSample, RunTrace};
use crate::kernel::world::{ActionKind, World};
use crate::kernel::KernelConfig;
use crate::model::{CellModel, Step};
use crossbeam_deque::{Injector, Steal};
use std::cmp::Reverse;
use std::collections::{BTreeMap, VecDeque};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::Arc;
use std::time::Instant;

/// Time spent by the worker threads, summed over threads (wall-clock, for statistics only:
/// nothing here reaches a hash).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct ThreadTimes {
    /// Seconds inside world turns that computed something.
    pub busy_seconds: f64,
    /// Of the busy time, seconds in actions applying an inbox (message exchange).
    pub receive_seconds: f64,
    /// Of the busy time, seconds in actions re-executing dirty steps (rollback).
    pub rollback_seconds: f64,
    /// Of the busy time, seconds in actions computing forward.
    pub compute_seconds: f64,
    /// Seconds inside GVT rounds (reading the published bounds).
    pub gvt_seconds: f64,
    /// Seconds with no task, or in turns that computed nothing.
    pub idle_seconds: f64,
    /// Number of world actions.
    pub actions: u64,
    /// Tasks of a world that another thread ran last (migrations between threads).
    pub steals: u64,
}

/// The result of a threaded run.
#[derive(Clone, Debug)]
pub struct ThreadedReport<E> {
    /// Committed frames in step order (empty when the setup did not keep them,
    /// [`ThreadedSetup::keep_frames`]).
    pub frames: Vec<Frame<E>>,
    /// Kernel counters per world and in total.
    pub counters: Counters,
    /// Thread time statistics.
    pub times: ThreadTimes,
    /// Wall time of the run, s.
    pub wall_seconds: f64,
    /// Threads used.
    pub threads: usize,
    /// `LeftDomain` events of initial states outside the grid.
    pub initial_events: Vec<Event<E>>,
    /// The run trace, if `KernelConfig::trace` was on (times: seconds since the start).
    pub trace: Option<RunTrace>,
    /// The load balancing rounds (empty when balancing is off).
    pub balance: Vec<RoundRecord>,
}

/// Where a threaded run (or its current epoch) is. Stored in an atomic as its `u64`, so
/// the workers and the output stage read it without a lock.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum RunStatus {
    /// The workers run worlds.
    Running = 0,
    /// The epoch's last step is committed, or the sink stopped the run: the workers return.
    Done = 1,
    /// A world panicked or the run stalled (the error is in `SharedRun::error`).
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

/// The `spins` the output stage passes to [`Facade::pause`]: it polls at a slow pace.
const OUTPUT_PAUSE: u32 = u32::MAX;

/// GVT stays within this many optimism windows (of at least 8 steps) of the last step the
/// sink was handed: committed frames the sink has not taken are held in memory, so a slow
/// sink must slow the run, not grow it (SPEC.md §K7).
const UNDELIVERED_WINDOWS: Step = 4;

/// The state of a threaded run that the worker threads and the output stage share.
struct SharedRun<M: CellModel + 'static, F: Facade> {
    /// The worlds, each under its own lock (a world runs on one thread at a time).
    worlds: Vec<F::Mutex<ThreadedWorld<M>>>,
    /// Per world, the messages sent to it and not yet received.
    inboxes: Vec<F::Mutex<Vec<Message<M::State>>>>,
    /// Per world, a lower bound of its `bound()` (written only under the world's lock).
    published: Vec<F::Atomic>,
    /// Per inbox, a lower bound of the `affects` of the messages in it (`u64::MAX`: none).
    inbox_min: Vec<F::Atomic>,
    /// Bumped before every write that can raise a `published` or `inbox_min` value, so a
    /// GVT reader can tell whether its snapshot is consistent (SPEC.md §K7).
    version: F::Atomic,
    /// The ready set and where every world's task is.
    sched: F::Mutex<Schedule>,
    /// Per world, nanoseconds of its last forward computation (for the ready set's order only).
    cost: Vec<F::Atomic>,
    /// Per world, the thread that last ran an action of it (to count migrations).
    home: Vec<F::Atomic>,
    /// Tokens of worlds that had to wait (postponed behind a laggard, or running elsewhere):
    /// any thread takes them when nothing is ready, so a waiting world never sits behind a
    /// busy thread's work. A token is live only while the schedule still holds it.
    waiting: Injector<(usize, u64)>,
    /// The current GVT.
    gvt: F::Atomic,
    /// The last step whose frame went to the output stage (0 before any).
    committed: F::Atomic,
    /// The last step the sink has been handed (0 before any).
    delivered: F::Atomic,
    /// How far GVT may run ahead of the sink: a sink that takes its time (a display
    /// showing frames in real time, a slow disk) holds the run back instead of letting
    /// undelivered frames pile up in memory ([`UNDELIVERED_WINDOWS`] optimism windows).
    undelivered: Step,
    /// 1 while a thread computes GVT or posts an input (they exclude each other).
    gvt_round: F::Atomic,
    /// A [`RunStatus`] as its `u64`.
    status: F::Atomic,
    /// The last step of the current epoch: the run's last step, or the next balancing
    /// round's (the worlds stop there so every state at it is final when cells move).
    target: F::Atomic,
    /// Whether the mode is optimistic (not conservative).
    optimistic: bool,
    /// How many steps a world may compute ahead of its slowest neighbour world before it
    /// lets laggards run first (optimistic modes; [`ThreadedOptions::lead`]).
    lead: Step,
    /// Committed steps being assembled from the worlds' contributions.
    assembly: F::Mutex<Assembly<M>>,
    /// Whole committed steps waiting for the output stage, and the run's statistics.
    out: F::Mutex<Output<M>>,
    /// The first error of the run (a world panicked, the run stalled).
    error: F::Mutex<Option<ExecError>>,
    /// The inputs posted so far: their number (the next input's sequence number) and one
    /// copy of each (re-posted to the worlds after a balancing round that moved cells).
    inputs: F::Mutex<InputLog<M::State>>,
    /// The grid (to check inputs).
    grid: Arc<Grid>,
    /// 1 once the sink stopped the run.
    stop: F::Atomic,
    /// Whether worlds record a trace (`KernelConfig::trace`).
    trace: bool,
    /// When the run started (trace times count from it).
    started: Instant,
}

/// A world as the threaded executor holds it, under the world's lock.
struct ThreadedWorld<M: CellModel> {
    /// The world.
    world: World<M>,
    /// The last step it has handed to the frame assembly.
    contributed: Step,
    /// What the next balancing round measures of it (busy CPU time, lead over GVT).
    meter: LoadMeter,
}

/// The inputs posted so far.
struct InputLog<S> {
    /// Their number (the last input's sequence number).
    count: u32,
    /// One copy of each, in posting order (re-posted after a balancing round that moved
    /// cells).
    posted: Vec<Message<S>>,
}

/// Committed steps being assembled from the worlds' contributions.
struct Assembly<M: CellModel> {
    /// The steps some worlds have contributed to, by step.
    partial: BTreeMap<Step, Partial<M>>,
    /// The next step to go to the output stage (when every world has contributed it).
    next: Step,
}

/// One committed step's contributions so far.
struct Partial<M: CellModel> {
    /// How many worlds contributed.
    worlds: usize,
    /// The contributing worlds' cells' states (any order), shared with their logs.
    states: Vec<Arc<[M::State]>>,
    /// The events of their cells' computations of the step before.
    events: Vec<Event<M::Event>>,
}

/// Committed steps waiting for the output stage (the calling thread), whole (every world
/// contributed) but not yet sorted and hashed: the output stage finishes the frames, off the
/// workers' critical path.
struct Output<M: CellModel> {
    /// Whole committed steps, in step order.
    pending: VecDeque<(Step, Partial<M>)>,
    /// How many times GVT advanced.
    gvt_advances: u64,
    /// The worker threads' times, summed as they finish.
    times: ThreadTimes,
    /// GVT over time (with a trace).
    gvt_samples: Vec<GvtSample>,
}

impl<M: CellModel> Default for Output<M> {
    fn default() -> Self {
        Output {
            pending: VecDeque::new(),
            gvt_advances: 0,
            times: ThreadTimes::default(),
            gvt_samples: Vec::new(),
        }
    }
}

/// Consecutive idle pauses after which a thread checks, under the full cut, whether the run
/// has stalled (a kernel bug) rather than waiting for ever.
const STALL_CHECK_SPINS: u32 = 20_000;

impl<M: CellModel + 'static, F: Facade> SharedRun<M, F> {
    /// The run's status now.
    fn status(&self) -> RunStatus {
        RunStatus::from_u64(self.status.load())
    }

    /// Sets the run's status.
    fn set_status(&self, status: RunStatus) {
        self.status.store(status as u64);
    }

    /// Queues world `w` in the ready set unless it is already queued or taken. A waiting
    /// world moves to the ready set (its token goes stale): what woke it (a message, a GVT
    /// advance) may let it act, and it must not wait behind worlds that are still blocked.
    fn schedule(&self, w: usize) {
        let key = (self.published[w].load(), Reverse(self.cost[w].load()), w);
        self.sched.lock().wake(key);
    }

    /// Sends world `w`'s task to the waiting queue: taken by a thread that found it running
    /// elsewhere, or postponed by its own turn (then its task is idle, unless a message
    /// queued it meanwhile: a ready task stays ready).
    fn wait(&self, w: usize) {
        let token = self.sched.lock().wait(w);
        if let Some(token) = token {
            self.waiting.push((w, token));
        }
    }

    fn fail(&self, e: ExecError) {
        let mut first = self.error.lock();
        if first.is_none() {
            *first = Some(e);
        }
        self.set_status(RunStatus::Failed);
    }

    /// Sends `m`: into its receiver's inbox, lowering that inbox's published minimum.
    fn send(&self, m: Message<M::State>) {
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
    fn post_input(&self, step: Step, input: Input<M::State>) -> Result<(), InputError> {
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
        let checked = super::check_input::<M>(&self.grid, floor, step, &input);
        if checked.is_ok() {
            let mut log = self.inputs.lock();
            log.count += 1;
            let msg = super::input_message::<M>(&self.grid, step, input, log.count);
            log.posted.push(msg.clone());
            drop(log);
            for m in super::to_every_world(&msg, self.worlds.len()) {
                self.send(m);
            }
        }
        drop(locked);
        self.gvt_round.store(0);
        checked
    }

    fn lower(&self, a: &F::Atomic, v: u64) {
        if v < a.load() {
            a.store(v);
        }
    }

    /// One turn of world `w`: receive its inbox, hand its newly committed steps to the frame
    /// assembly and fossil-collect, act if it wants to, route the output, publish its bound.
    /// Returns whether it acted.
    fn run_world(&self, w: usize, me: usize, times: &mut ThreadTimes) -> bool {
        // A world another thread is running is not waited for: its task goes to the
        // waiting queue (still counted as queued, so the running thread does not queue a
        // second copy), and this thread serves another world — e.g. its own, which may
        // speculate ahead (`lead`) instead of blocking until the neighbour's step is done.
        let Some(mut held) = self.worlds[w].try_lock() else {
            self.wait(w);
            return false;
        };
        self.sched.lock().locked(w);
        {
            let mut inbox = self.inboxes[w].lock();
            if !inbox.is_empty() {
                let incoming = std::mem::take(&mut *inbox);
                let least = incoming
                    .iter()
                    .map(|m| m.affects())
                    .min()
                    .unwrap_or(u64::MAX);
                // The messages move from the inbox's bound to the world's: lower the world's
                // first, then (a raise) empty the inbox's.
                self.lower(&self.published[w], least);
                self.version.fetch_add(1);
                self.inbox_min[w].store(u64::MAX);
                drop(inbox);
                for m in incoming {
                    held.world.receive(m);
                }
            }
        }
        let gvt = self.gvt.load();
        self.contribute(&mut held, gvt);
        let ThreadedWorld { world, meter, .. } = &mut *held;
        if self.postpone(world) {
            self.published[w].store(world.bound());
            // Still under the world's lock: a message that arrives after this is seen
            // waiting and wakes the world into the ready set.
            self.wait(w);
            return false;
        }
        let acted = if world.wants_to_act(gvt) {
            let lvt = world.lvt();
            if self.trace {
                world.trace_time(self.started.elapsed().as_secs_f64());
            }
            let kind = world.next_action();
            let a0 = Instant::now();
            let c0 = thread_cpu_seconds();
            let acted = catch_unwind(AssertUnwindSafe(|| world.act(gvt)));
            let spent = a0.elapsed().as_secs_f64();
            if kind == ActionKind::Compute {
                self.cost[w].store((spent * 1e9) as u64);
            }
            meter.add_busy(thread_cpu_seconds() - c0);
            meter.note_action(world.lvt(), gvt);
            *match kind {
                ActionKind::Receive => &mut times.receive_seconds,
                ActionKind::Repair => &mut times.rollback_seconds,
                ActionKind::Compute => &mut times.compute_seconds,
            } += spent;
            match acted {
                Ok(out) => {
                    for m in out {
                        self.send(m);
                    }
                    true
                }
                Err(p) => {
                    self.fail(ExecError::WorldPanicked {
                        world: w as WorldId,
                        step: lvt,
                        message: panic_message(&*p),
                    });
                    return false;
                }
            }
        } else {
            false
        };
        let bound = world.bound();
        if bound > self.published[w].load() {
            self.version.fetch_add(1);
        }
        self.published[w].store(bound);
        if acted {
            // The world's home follows the thread that computes it.
            self.home[w].store(me as u64);
            if world.wants_to_act(self.gvt.load()) {
                self.schedule(w);
            }
        }
        acted
    }

    /// Whether world `w` should let laggards run first: in the optimistic modes, a world
    /// that would only compute forward while it is more than `lead` steps ahead of the
    /// slowest of its neighbour worlds (those it exchanges ghosts with) would compute with
    /// borders that are probably still to change. Worlds that are not neighbours do not hold
    /// it back. The slowest world of the run is never postponed, so the run always
    /// progresses. The caller sends the task to the waiting queue.
    fn postpone(&self, world: &World<M>) -> bool {
        if !self.optimistic || !world.only_advances() {
            return false;
        }
        let slowest = world
            .neighbours()
            .iter()
            .map(|&v| self.published[v as usize].load())
            .min()
            .unwrap_or(Step::MAX);
        world.lvt() + 1 > slowest.saturating_add(self.lead)
    }

    /// Hands the world's states of the steps below `gvt` not yet handed over to the frame
    /// assembly, then fossil-collects its logs.
    fn contribute(&self, held: &mut ThreadedWorld<M>, gvt: Step) {
        let last = (gvt - 1).min(self.target.load());
        if held.contributed >= last {
            return;
        }
        for t in held.contributed + 1..=last {
            held.world.note_committed(t);
        }
        // The cells' states are handed over as shared references, not copied: a copy of a
        // heavy world's ~1,000 states into fresh memory took ~3 ms now and then (page faults
        // on memory the allocator had returned), holding up the world and its neighbours.
        // The output stage flattens them when it sorts and hashes the frame.
        let mut assembly = self.assembly.lock();
        for t in held.contributed + 1..=last {
            let part = assembly.partial.entry(t).or_insert_with(|| Partial {
                worlds: 0,
                states: Vec::new(),
                events: Vec::new(),
            });
            part.worlds += 1;
            part.states.extend(held.world.shared_states_at(t));
            part.events.extend(held.world.events_at(t - 1).cloned());
        }
        held.contributed = last;
        held.world.sample_log_bytes();
        held.world.fossil_collect(last);
        let n = self.worlds.len();
        let mut done = Vec::new();
        loop {
            let next = assembly.next;
            match assembly.partial.get(&next) {
                Some(p) if p.worlds == n => {
                    let p = assembly.partial.remove(&next).expect("present");
                    done.push((next, p));
                    assembly.next += 1;
                }
                _ => break,
            }
        }
        if done.is_empty() {
            return;
        }
        // Whole steps are queued under the assembly lock, so they reach the output stage in
        // step order whichever thread completes them; the output stage sorts and hashes.
        let last_step = done.last().map_or(0, |d| d.0);
        self.out.lock().pending.extend(done);
        // Still under the assembly lock, so `committed` only grows: a thread that finished
        // earlier frames cannot overwrite a later step after the lock is released (the
        // balancing epochs read it to decide whether the run is over).
        self.committed.store(last_step);
        if last_step >= self.target.load() {
            self.set_status(RunStatus::Done);
        }
        drop(assembly);
    }

    /// A GVT round from the published bounds, without stopping any world: a snapshot is
    /// accepted only if no bound was raised while it was read (SPEC.md §K7). Returns whether
    /// GVT advanced (every world is then scheduled, to commit and fossil-collect).
    fn gvt_round(&self) -> bool {
        if self.gvt_round.swap(1) == 1 {
            return false;
        }
        let mut advanced = false;
        for _ in 0..4 {
            let before = self.version.load();
            let mut least =
                (self.target.load() + 1).min(self.delivered.load() + 1 + self.undelivered);
            for w in 0..self.worlds.len() {
                least = least
                    .min(self.published[w].load())
                    .min(self.inbox_min[w].load());
            }
            if self.version.load() != before {
                continue;
            }
            let old = self.gvt.load();
            if least > old {
                self.gvt.store(least);
                let mut out = self.out.lock();
                out.gvt_advances += 1;
                if self.trace {
                    out.gvt_samples.push(GvtSample {
                        time: self.started.elapsed().as_secs_f64(),
                        gvt: least,
                    });
                }
                drop(out);
                advanced = true;
            }
            break;
        }
        self.gvt_round.store(0);
        if advanced {
            for w in 0..self.worlds.len() {
                self.schedule(w);
            }
        }
        advanced
    }

    /// Under the full cut (every world lock, then every inbox lock): fails the run if no
    /// world can act, no message is pending and frames are missing (a kernel bug).
    fn check_stall(&self) {
        let worlds: Vec<_> = self.worlds.iter().map(|m| m.lock()).collect();
        let inboxes: Vec<_> = self.inboxes.iter().map(|m| m.lock()).collect();
        let gvt = self.gvt.load();
        let pending = inboxes.iter().any(|i| !i.is_empty());
        let can_act = worlds.iter().any(|s| s.world.wants_to_act(gvt));
        let to_commit = worlds
            .iter()
            .any(|s| s.contributed < (gvt - 1).min(self.target.load()));
        let bounds = worlds
            .iter()
            .map(|s| s.world.bound())
            .min()
            .unwrap_or(Step::MAX);
        if !pending
            && !can_act
            && !to_commit
            && bounds <= gvt
            && self.committed.load() < self.target.load()
        {
            drop(inboxes);
            drop(worlds);
            self.fail(ExecError::Stalled { gvt });
        }
    }

    /// The next world task for thread `me`: the best ready world, else a waiting one.
    /// Counts in `steals` the tasks of worlds another thread ran last.
    /// Stale waiting tokens (of worlds woken since) are dropped on the way.
    fn find_task(&self, me: usize, steals: &mut u64) -> Option<usize> {
        let first = self.sched.lock().take_ready();
        let task = first.or_else(|| loop {
            match self.waiting.steal() {
                Steal::Success((w, token)) => {
                    if self.sched.lock().take_waiting(w, token) {
                        break Some(w);
                    }
                }
                Steal::Retry => {}
                Steal::Empty => break None,
            }
        });
        if let Some(w) = task {
            *steals += (self.home[w].load() != me as u64) as u64;
        }
        task
    }

    fn worker_loop(&self, me: usize) {
        let mut times = ThreadTimes::default();
        let mut spins = 0u32;
        while self.status() == RunStatus::Running {
            let t0 = Instant::now();
            match self.find_task(me, &mut times.steals) {
                Some(w) => {
                    let acted = self.run_world(w, me, &mut times);
                    if acted {
                        spins = 0;
                        times.actions += 1;
                        times.busy_seconds += t0.elapsed().as_secs_f64();
                    } else {
                        // A turn that did nothing (the world was postponed, running
                        // elsewhere, or had nothing to do): unless a world is ready, back
                        // off like an idle thread, so a thread waiting for a laggard does
                        // not spin at full speed.
                        if !self.sched.lock().any_ready() {
                            F::pause(spins);
                            spins = spins.saturating_add(1);
                        }
                        times.idle_seconds += t0.elapsed().as_secs_f64();
                    }
                    let g0 = Instant::now();
                    self.gvt_round();
                    times.gvt_seconds += g0.elapsed().as_secs_f64();
                }
                None => {
                    let g0 = Instant::now();
                    let advanced = self.gvt_round();
                    times.gvt_seconds += g0.elapsed().as_secs_f64();
                    if !advanced {
                        let i0 = Instant::now();
                        F::pause(spins);
                        spins = spins.saturating_add(1);
                        if spins % STALL_CHECK_SPINS == 0 {
                            self.check_stall();
                        }
                        times.idle_seconds += i0.elapsed().as_secs_f64();
                    }
                }
            }
        }
        let mut out = self.out.lock();
        out.times.busy_seconds += times.busy_seconds;
        out.times.receive_seconds += times.receive_seconds;
        out.times.rollback_seconds += times.rollback_seconds;
        out.times.compute_seconds += times.compute_seconds;
        out.times.gvt_seconds += times.gvt_seconds;
        out.times.idle_seconds += times.idle_seconds;
        out.times.actions += times.actions;
        out.times.steals += times.steals;
    }
}

/// Finishes committed step `t` from every world's contribution ([`super::whole_frame`]) and,
/// if `wanted` asks for them, clones its sorted states.
fn finish_frame<M: CellModel>(
    t: Step,
    p: Partial<M>,
    wanted: &StatesWanted,
) -> (Frame<M::Event>, Option<Vec<M::State>>) {
    let (frame, sorted) =
        super::whole_frame::<M>(t, p.states.iter().flat_map(|c| c.iter()), p.events);
    let states = wanted
        .wants(t, frame.hash)
        .then(|| sorted.into_iter().cloned().collect());
    (frame, states)
}

/// Runs `model` from `initial` for `steps` committed steps on `threads` OS threads.
pub fn run_threaded<M: CellModel + 'static>(
    model: M,
    grid: Grid,
    initial: Vec<M::State>,
    config: &KernelConfig,
    threads: usize,
    steps: u64,
) -> Result<ThreadedReport<M::Event>, ExecError> {
    run_threaded_with::<M, StdFacade>(
        ThreadedSetup::new(model, grid, initial),
        &ThreadedOptions::new(config, threads, steps),
        |_, _| {},
    )
}

/// How a threaded run runs: the kernel configuration, the threads, the steps to commit and
/// the committed states its sink wants.
#[derive(Clone, Debug)]
pub struct ThreadedOptions<'a> {
    /// The kernel configuration (worlds, mode, window, balancing, …).
    pub config: &'a KernelConfig,
    /// The number of OS threads (at least 1 is used).
    pub threads: usize,
    /// The number of steps to commit.
    pub steps: u64,
    /// The steps whose committed states (sorted by id) the sink gets.
    pub wanted: StatesWanted,
    /// Optimistic modes: how many steps a world may compute ahead of the slowest of its
    /// neighbour worlds before it lets laggards run first (SPEC.md §10). 0 runs the worlds
    /// nearly in lockstep (few rollbacks); more lets a world speculate past a slower
    /// neighbour, up to the window. Pacing only: the committed bits never depend on it.
    pub lead: u64,
}

impl<'a> ThreadedOptions<'a> {
    /// `steps` steps on `threads` threads under `config`, no states wanted.
    pub fn new(config: &'a KernelConfig, threads: usize, steps: u64) -> Self {
        ThreadedOptions {
            config,
            threads,
            steps,
            wanted: StatesWanted::none(),
            lead: 0,
        }
    }

    /// The same options with the laggard lead `lead` (see [`ThreadedOptions::lead`]).
    pub fn lead(mut self, lead: u64) -> Self {
        self.lead = lead;
        self
    }

    /// The same options, handing the sink the committed states of the steps `wanted` asks
    /// for.
    pub fn wanted(mut self, wanted: StatesWanted) -> Self {
        self.wanted = wanted;
        self
    }
}

/// [`run_threaded`] over any [`Facade`] (shuttle tests pass their own), handing every
/// committed frame, in step order, to `sink` on the calling thread (the output stage),
/// with the committed states (sorted by id) of the steps `options.wanted` asks for.
///
/// With balancing on (`config.balance`), the run is cut into epochs of `period` steps: the
/// worlds stop at the epoch's last step, the threads finish and are joined (GVT is then
/// that step + 1, every state at it final), a balancing round moves cells between the
/// worlds from their busy time per committed step, and the next epoch starts new threads.
pub fn run_threaded_with<M: CellModel + 'static, F: Facade>(
    setup: ThreadedSetup<M>,
    options: &ThreadedOptions<'_>,
    mut sink: impl FnMut(&Frame<M::Event>, Option<&[&M::State]>),
) -> Result<ThreadedReport<M::Event>, ExecError> {
    run_threaded_controlled::<M, F>(setup, options, |f, s, _| sink(f, s))
}

/// What a threaded run starts from: the model, the grid, the initial states and the inputs
/// scripted before the run (step, input), applied in this order at each step.
pub struct ThreadedSetup<M: CellModel> {
    /// The model.
    pub model: M,
    /// The grid.
    pub grid: Grid,
    /// The states at step 0.
    pub initial: Vec<M::State>,
    /// Inputs scheduled before the run starts.
    pub inputs: Vec<(Step, Input<M::State>)>,
    /// Whether the report keeps every committed frame (`ThreadedReport::frames`; about 50
    /// bytes per step, so a long run that hands frames to a sink should not).
    pub keep_frames: bool,
}

impl<M: CellModel> ThreadedSetup<M> {
    /// `model` on `grid` from `initial`, no scripted inputs, every frame kept.
    pub fn new(model: M, grid: Grid, initial: Vec<M::State>) -> Self {
        ThreadedSetup {
            model,
            grid,
            initial,
            inputs: Vec::new(),
            keep_frames: true,
        }
    }
}

/// [`run_threaded_with`] with scripted inputs, and a sink that also gets a [`RunControl`]
/// to schedule inputs during the run (checked against GVT at that moment) or stop it after
/// the current frame. Stopping ends the run early: the report holds the frames delivered.
pub fn run_threaded_controlled<M: CellModel + 'static, F: Facade>(
    setup: ThreadedSetup<M>,
    options: &ThreadedOptions<'_>,
    mut sink: impl FnMut(&Frame<M::Event>, Option<&[&M::State]>, &mut RunControl<'_, M::State>),
) -> Result<ThreadedReport<M::Event>, ExecError> {
    let ThreadedOptions {
        config,
        threads,
        steps,
        ref wanted,
        lead,
    } = *options;
    let ThreadedSetup {
        model,
        grid,
        initial,
        inputs: scripted,
        keep_frames,
    } = setup;
    let start = Instant::now();
    let threads = threads.max(1);
    let super::Worlds {
        mut worlds,
        events: initial_events,
        grid,
        mut partition,
    } = super::build_worlds(model, grid, initial, config);
    let n = worlds.len();
    // Balancing shares the load between the threads unless told otherwise.
    let mut balance = config.balance.clone();
    if balance.workers == 0 {
        balance.workers = threads;
    }
    let mut balancer = Balancer::new(&balance, grid.cell_count());
    if balancer.opens() {
        if let Some(p) = super::opening_round(&mut balancer, &grid, &partition, worlds.iter_mut()) {
            partition = p;
        }
    }
    let mut epoch_end = steps.min(balancer.next_round_after(0));
    let mut inboxes: Vec<Vec<Message<M::State>>> = (0..n).map(|_| Vec::new()).collect();
    for w in &mut worlds {
        w.set_end(epoch_end);
        for m in w.start() {
            inboxes[m.dst_world as usize].push(m);
        }
    }
    let published = worlds.iter().map(|w| F::Atomic::new(w.bound())).collect();
    let inbox_min = inboxes
        .iter()
        .map(|i| F::Atomic::new(i.iter().map(|m| m.affects()).min().unwrap_or(u64::MAX)))
        .collect();
    let shared = Arc::new(SharedRun::<M, F> {
        worlds: worlds
            .into_iter()
            .map(|world| {
                F::Mutex::new(ThreadedWorld {
                    world,
                    contributed: 0,
                    meter: LoadMeter::default(),
                })
            })
            .collect(),
        inboxes: inboxes.into_iter().map(F::Mutex::new).collect(),
        published,
        inbox_min,
        version: F::Atomic::new(0),
        sched: F::Mutex::new(Schedule::new(n)),
        cost: (0..n).map(|_| F::Atomic::new(0)).collect(),
        home: (0..n)
            .map(|w| F::Atomic::new((w % threads) as u64))
            .collect(),
        waiting: Injector::new(),
        gvt: F::Atomic::new(1),
        committed: F::Atomic::new(0),
        delivered: F::Atomic::new(0),
        undelivered: UNDELIVERED_WINDOWS * config.window.max(8),
        gvt_round: F::Atomic::new(0),
        status: F::Atomic::new(if steps == 0 {
            RunStatus::Done as u64
        } else {
            RunStatus::Running as u64
        }),
        target: F::Atomic::new(epoch_end),
        optimistic: config.mode != crate::kernel::RollbackMode::Conservative,
        lead,
        assembly: F::Mutex::new(Assembly {
            partial: BTreeMap::new(),
            next: 1,
        }),
        out: F::Mutex::new(Output::default()),
        error: F::Mutex::new(None),
        inputs: F::Mutex::new(InputLog {
            count: 0,
            posted: Vec::new(),
        }),
        grid: grid.clone(),
        stop: F::Atomic::new(0),
        trace: config.trace,
        started: start,
    });
    // The output stage: hand committed frames to the sink while the workers run.
    for (step, input) in scripted {
        shared.post_input(step, input)?;
    }
    let mut frames = Vec::new();
    let mut delivered = 0u64;
    let mut stopped = false;
    let poster = shared.clone();
    let mut deliver = |batch: VecDeque<(Step, Partial<M>)>| {
        for (t, partial) in batch {
            let (frame, states) = finish_frame::<M>(t, partial, wanted);
            if delivered < steps && !stopped {
                delivered += 1;
                let refs: Option<Vec<&M::State>> = states.as_ref().map(|v| v.iter().collect());
                let mut post = |step: Step, input: Input<M::State>| poster.post_input(step, input);
                let mut probe = || LiveStatus {
                    gvt: poster.gvt.load(),
                    worlds: poster
                        .worlds
                        .iter()
                        .map(|w| WorldStatus::of(&w.lock().world))
                        .collect(),
                };
                let mut control =
                    RunControl::new(poster.gvt.load(), &mut post).with_probe(&mut probe);
                sink(&frame, refs.as_deref(), &mut control);
                poster.delivered.store(t);
                if control.stopped() {
                    stopped = true;
                    poster.stop.store(1);
                    poster.set_status(RunStatus::Done);
                }
                if keep_frames {
                    frames.push(frame);
                }
            }
        }
    };
    let mut busy_total = vec![0.0f64; n];
    let mut last_round: Step = 0;
    loop {
        run_epoch(&shared, threads, &mut deliver)?;
        let committed = shared.committed.load();
        if committed >= steps || steps == 0 || shared.stop.load() == 1 {
            break;
        }
        // A balancing round at the epoch's last step: every world has contributed it, so
        // GVT = committed + 1 and every state at `committed` is final.
        let mut locked: Vec<_> = shared.worlds.iter().map(|w| w.lock()).collect();
        let span = (committed - last_round).max(1) as f64;
        let loads: Vec<f64> = locked
            .iter()
            .map(|s| {
                let computed = s.world.counters().cells_computed;
                s.meter.load(config.balance.load, computed, span)
            })
            .collect();
        let leads: Vec<f64> = locked.iter().map(|s| s.meter.mean_lead()).collect();
        for (w, s) in locked.iter_mut().enumerate() {
            busy_total[w] += s.meter.busy_seconds();
            let computed = s.world.counters().cells_computed;
            s.meter.restart(computed);
        }
        let moved = super::balance_round(
            &mut balancer,
            &grid,
            &partition,
            locked.iter_mut().map(|s| &mut s.world),
            &loads,
            &leads,
            committed,
        );
        last_round = committed;
        epoch_end = steps.min(balancer.next_round_after(committed));
        if let Some(p) = moved {
            partition = p;
            // Messages in transit belong to the old owner map: the worlds start again.
            for (w, inbox) in shared.inboxes.iter().enumerate() {
                inbox.lock().clear();
                shared.inbox_min[w].store(u64::MAX);
            }
            let pending: Vec<Message<M::State>> = shared
                .inputs
                .lock()
                .posted
                .iter()
                .filter(|m| m.step > committed)
                .cloned()
                .collect();
            let reposted = pending.iter().flat_map(|m| super::to_every_world(m, n));
            let started: Vec<Message<M::State>> =
                locked.iter_mut().flat_map(|s| s.world.start()).collect();
            for m in started.into_iter().chain(reposted) {
                let d = m.dst_world as usize;
                let affects = m.affects();
                shared.inboxes[d].lock().push(m);
                shared.lower(&shared.inbox_min[d], affects);
            }
        }
        for (w, s) in locked.iter_mut().enumerate() {
            s.world.set_end(epoch_end);
            shared.published[w].store(s.world.bound());
        }
        drop(locked);
        shared.target.store(epoch_end);
        shared.set_status(RunStatus::Running);
    }
    let mut out = std::mem::take(&mut *shared.out.lock());
    deliver(std::mem::take(&mut out.pending));
    let mut locked: Vec<_> = shared.worlds.iter().map(|w| w.lock()).collect();
    for (w, s) in locked.iter_mut().enumerate() {
        busy_total[w] += s.meter.busy_seconds();
    }
    let world_counters = locked.iter().map(|s| s.world.counters().clone()).collect();
    let trace = config.trace.then(|| {
        let mut worlds: Vec<&mut World<M>> = locked.iter_mut().map(|s| &mut s.world).collect();
        super::collect_trace(&grid, &partition, &mut worlds, out.gvt_samples)
    });
    drop(locked);
    let mut counters = Counters::from_worlds(world_counters, out.gvt_advances, shared.gvt.load());
    counters.balance = balancer.counters(imbalance(&busy_total));
    Ok(ThreadedReport {
        frames,
        counters,
        times: out.times,
        wall_seconds: start.elapsed().as_secs_f64(),
        threads,
        initial_events,
        trace,
        balance: balancer.history().to_vec(),
    })
}

/// One epoch: every world is queued, `threads` workers run until the epoch's last step is
/// committed (or the run fails), the output stage delivers frames meanwhile.
fn run_epoch<M: CellModel + 'static, F: Facade>(
    shared: &Arc<SharedRun<M, F>>,
    threads: usize,
    deliver: &mut impl FnMut(VecDeque<(Step, Partial<M>)>),
) -> Result<(), ExecError> {
    // Tasks left from an earlier epoch are stale: every world is queued once again.
    shared.sched.lock().reset();
    while !shared.waiting.steal().is_empty() {}
    for w in 0..shared.worlds.len() {
        shared.schedule(w);
    }
    let handles: Vec<F::Handle> = (0..threads)
        .map(|me| {
            let shared = shared.clone();
            F::spawn(move || shared.worker_loop(me))
        })
        .collect();
    while shared.status() == RunStatus::Running {
        let batch = std::mem::take(&mut shared.out.lock().pending);
        if batch.is_empty() {
            F::pause(OUTPUT_PAUSE);
        } else {
            deliver(batch);
        }
    }
    let mut thread_error = None;
    for h in handles {
        if let Err(e) = F::join(h) {
            thread_error.get_or_insert(e);
        }
    }
    if let Some(e) = shared.error.lock().take() {
        return Err(e);
    }
    if let Some(e) = thread_error {
        return Err(ExecError::Thread(e));
    }
    Ok(())
}
