//! The threaded executor: T OS threads run the kernel's worlds as tasks on crossbeam-deque
//! work stealing (an [`Injector`], one [`Worker`] per thread, [`Stealer`]s). A world runs on
//! at most one thread at a time (its lock); a world that cannot act (window full,
//! conservative dependency) simply is not rescheduled until a message or a GVT advance gives
//! it something to do, so its thread serves other worlds.
//!
//! GVT (SPEC.md §Threaded executor): a consistent cut. The thread that runs a GVT round takes
//! every world's lock in ascending id order, then every inbox lock. A world sends only while
//! holding its own lock, so with all world locks held no message is in transit: each is in
//! an inbox or already received. GVT is then the minimum of the worlds' bounds and of the
//! `affects` step of every inbox message — exactly the virtual executor's rule. The round
//! commits the steps below the new GVT (frames assembled from all worlds while the cut is
//! held, so a frame is never torn or speculative), fossil-collects, and releases. Lock order
//! (worlds ascending, then inboxes; a worker holds one world and at most one inbox) makes
//! deadlock impossible.
//!
//! This is the only module that starts threads, and it does so through [`Facade`].

use super::sync::{panic_message, Facade, FacadeAtomic, FacadeMutex, StdFacade};
use crate::frame::{Event, Frame, StatesWanted};
use crate::grid::Grid;
use crate::kernel::counters::Counters;
use crate::kernel::message::Message;
use crate::kernel::partition::{Partition, WorldId};
use crate::kernel::world::World;
use crate::kernel::KernelConfig;
use crate::model::{CellModel, Step};
use crate::state::{canonical_hash, CellStates};
use crossbeam_deque::{Injector, Steal, Stealer, Worker};
use std::collections::VecDeque;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::Arc;
use std::time::Instant;
use thiserror::Error;

/// Why a threaded run stopped early. All are fatal for the run.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
pub enum ExecError {
    /// A world's step panicked; the other threads were stopped.
    #[error("world {world} panicked while computing from step {step}: {message}")]
    WorldPanicked {
        /// The world.
        world: WorldId,
        /// Its local virtual time when it panicked.
        step: Step,
        /// The panic message.
        message: String,
    },
    /// No world could act, no message was pending and GVT could not advance (a kernel bug).
    #[error("kernel stalled at GVT {gvt}: no world can act and no message is pending")]
    Stalled {
        /// GVT at the stall.
        gvt: Step,
    },
    /// A worker thread died outside a world's step.
    #[error("worker thread failed: {0}")]
    Thread(String),
}

/// Time spent by the worker threads, summed over threads (wall-clock, for statistics only:
/// nothing here reaches a hash).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct ThreadTimes {
    /// Seconds inside world actions.
    pub busy_seconds: f64,
    /// Seconds inside GVT rounds (including waiting for the cut).
    pub gvt_seconds: f64,
    /// Seconds with no task (waiting for work).
    pub idle_seconds: f64,
    /// Number of world actions.
    pub actions: u64,
    /// Tasks taken from another thread's queue.
    pub steals: u64,
}

/// The result of a threaded run.
#[derive(Clone, Debug)]
pub struct ThreadedReport {
    /// Committed frames in step order.
    pub frames: Vec<Frame>,
    /// Kernel counters per world and in total.
    pub counters: Counters,
    /// Thread time statistics.
    pub times: ThreadTimes,
    /// Wall time of the run, s.
    pub wall_seconds: f64,
    /// Threads used.
    pub threads: usize,
    /// `LeftDomain` events of initial states outside the grid.
    pub initial_events: Vec<Event>,
}

const RUNNING: u64 = 0;
const DONE: u64 = 1;
const FAILED: u64 = 2;

/// The `spins` the output stage passes to [`Facade::pause`]: it polls at a slow pace.
const OUTPUT_PAUSE: u32 = u32::MAX;

struct Shared<M: CellModel + 'static, F: Facade> {
    worlds: Vec<F::Mutex<World<M>>>,
    inboxes: Vec<F::Mutex<Vec<Message<M::State>>>>,
    scheduled: Vec<F::Atomic>,
    injector: Injector<usize>,
    gvt: F::Atomic,
    committed: F::Atomic,
    gvt_round: F::Atomic,
    status: F::Atomic,
    target: Step,
    wanted: StatesWanted,
    out: F::Mutex<Output<M::State>>,
    error: F::Mutex<Option<ExecError>>,
}

/// Committed frames waiting for the output stage (the calling thread), with the states the
/// sink asked for.
struct Output<S> {
    pending: VecDeque<(Frame, Option<Vec<S>>)>,
    gvt_advances: u64,
    times: ThreadTimes,
}

impl<S> Default for Output<S> {
    fn default() -> Self {
        Output {
            pending: VecDeque::new(),
            gvt_advances: 0,
            times: ThreadTimes::default(),
        }
    }
}

impl<M: CellModel + 'static, F: Facade> Shared<M, F> {
    fn schedule(&self, w: usize, local: &Worker<usize>) {
        if self.scheduled[w].swap(1) == 0 {
            local.push(w);
        }
    }

    fn fail(&self, e: ExecError) {
        let mut slot = self.error.lock();
        if slot.is_none() {
            *slot = Some(e);
        }
        self.status.store(FAILED);
    }

    /// One action of world `w`: receive its inbox, act if it wants to, route the output.
    fn run_world(&self, w: usize, local: &Worker<usize>) -> bool {
        let mut world = self.worlds[w].lock();
        self.scheduled[w].store(0);
        let incoming: Vec<Message<M::State>> = std::mem::take(&mut *self.inboxes[w].lock());
        for m in incoming {
            world.receive(m);
        }
        let gvt = self.gvt.load();
        if !world.wants_to_act(gvt) {
            return false;
        }
        let lvt = world.lvt();
        match catch_unwind(AssertUnwindSafe(|| world.act(gvt))) {
            Ok(out) => {
                for m in out {
                    let d = m.dst_world as usize;
                    self.inboxes[d].lock().push(m);
                    self.schedule(d, local);
                }
                if world.wants_to_act(self.gvt.load()) {
                    self.schedule(w, local);
                }
                true
            }
            Err(p) => {
                self.fail(ExecError::WorldPanicked {
                    world: w as WorldId,
                    step: lvt,
                    message: panic_message(&*p),
                });
                false
            }
        }
    }

    /// A GVT round over a consistent cut; returns whether GVT advanced. Only one thread runs
    /// a round at a time; others skip.
    fn gvt_round(&self, local: &Worker<usize>) -> bool {
        if self.gvt_round.swap(1) == 1 {
            return false;
        }
        let advanced = self.gvt_round_locked(local);
        self.gvt_round.store(0);
        advanced
    }

    fn gvt_round_locked(&self, local: &Worker<usize>) -> bool {
        let mut worlds: Vec<_> = self.worlds.iter().map(|m| m.lock()).collect();
        let inboxes: Vec<_> = self.inboxes.iter().map(|m| m.lock()).collect();
        let old = self.gvt.load();
        let end = self.target + 1;
        let new = worlds
            .iter()
            .map(|w| w.bound())
            .chain(inboxes.iter().flat_map(|i| i.iter().map(|m| m.affects())))
            .min()
            .unwrap_or(end)
            .min(end);
        if new <= old {
            let pending = inboxes.iter().any(|i| !i.is_empty());
            let can_act = worlds.iter().any(|w| w.wants_to_act(old));
            if !pending && !can_act && self.committed.load() < self.target {
                drop(inboxes);
                drop(worlds);
                self.fail(ExecError::Stalled { gvt: old });
            }
            return false;
        }
        let mut out = self.out.lock();
        let mut committed = self.committed.load();
        while committed + 1 < new {
            let t = committed + 1;
            let mut all: Vec<&M::State> = worlds.iter().flat_map(|w| w.state_at(t)).collect();
            all.sort_by_key(|s| M::id(s));
            let mut events: Vec<Event> = worlds
                .iter()
                .flat_map(|w| w.events_at(t - 1))
                .copied()
                .collect();
            events.sort();
            let frame = Frame {
                step: t,
                hash: canonical_hash::<M>(all.iter().copied()),
                bodies: all.len(),
                events,
            };
            let states = self
                .wanted
                .wants(t, frame.hash)
                .then(|| all.iter().map(|s| (*s).clone()).collect());
            drop(all);
            for w in worlds.iter_mut() {
                w.note_committed(t);
            }
            committed = t;
            out.pending.push_back((frame, states));
        }
        out.gvt_advances += 1;
        for w in worlds.iter_mut() {
            w.sample_log_bytes();
            w.fossil_collect(new - 1);
        }
        self.gvt.store(new);
        self.committed.store(committed);
        if committed >= self.target {
            self.status.store(DONE);
        }
        drop(out);
        drop(inboxes);
        drop(worlds);
        for w in 0..self.worlds.len() {
            self.schedule(w, local);
        }
        true
    }

    fn find_task(
        &self,
        local: &Worker<usize>,
        stealers: &[Stealer<usize>],
        me: usize,
        steals: &mut u64,
    ) -> Option<usize> {
        if let Some(t) = local.pop() {
            return Some(t);
        }
        loop {
            let mut retry = false;
            match self.injector.steal_batch_and_pop(local) {
                Steal::Success(t) => return Some(t),
                Steal::Retry => retry = true,
                Steal::Empty => {}
            }
            for (k, s) in stealers.iter().enumerate() {
                if k == me {
                    continue;
                }
                match s.steal() {
                    Steal::Success(t) => {
                        *steals += 1;
                        return Some(t);
                    }
                    Steal::Retry => retry = true,
                    Steal::Empty => {}
                }
            }
            if !retry {
                return None;
            }
        }
    }

    fn worker_loop(&self, me: usize, local: Worker<usize>, stealers: Arc<Vec<Stealer<usize>>>) {
        let mut times = ThreadTimes::default();
        let mut spins = 0u32;
        let gvt_every = (2 * self.worlds.len()).max(4) as u64;
        while self.status.load() == RUNNING {
            let t0 = Instant::now();
            match self.find_task(&local, &stealers, me, &mut times.steals) {
                Some(w) => {
                    spins = 0;
                    if self.run_world(w, &local) {
                        times.actions += 1;
                        times.busy_seconds += t0.elapsed().as_secs_f64();
                        if times.actions % gvt_every == 0 {
                            let g0 = Instant::now();
                            self.gvt_round(&local);
                            times.gvt_seconds += g0.elapsed().as_secs_f64();
                        }
                    } else {
                        times.idle_seconds += t0.elapsed().as_secs_f64();
                    }
                }
                None => {
                    let g0 = Instant::now();
                    let advanced = self.gvt_round(&local);
                    times.gvt_seconds += g0.elapsed().as_secs_f64();
                    if !advanced {
                        let i0 = Instant::now();
                        F::pause(spins);
                        spins = spins.saturating_add(1);
                        times.idle_seconds += i0.elapsed().as_secs_f64();
                    }
                }
            }
        }
        let mut out = self.out.lock();
        out.times.busy_seconds += times.busy_seconds;
        out.times.gvt_seconds += times.gvt_seconds;
        out.times.idle_seconds += times.idle_seconds;
        out.times.actions += times.actions;
        out.times.steals += times.steals;
    }
}

/// Runs `model` from `initial` for `steps` committed steps on `threads` OS threads.
pub fn run_threaded<M: CellModel + 'static>(
    model: M,
    grid: Grid,
    initial: Vec<M::State>,
    config: &KernelConfig,
    threads: usize,
    steps: u64,
) -> Result<ThreadedReport, ExecError> {
    run_threaded_with::<M, StdFacade>(
        model,
        grid,
        initial,
        config,
        threads,
        steps,
        StatesWanted::none(),
        |_, _| {},
    )
}

/// [`run_threaded`] over any [`Facade`] (shuttle tests pass their own), handing every
/// committed frame, in step order, to `sink` on the calling thread (the output stage),
/// with the committed states (sorted by id) of the steps `wanted` asks for.
#[allow(clippy::too_many_arguments)]
pub fn run_threaded_with<M: CellModel + 'static, F: Facade>(
    model: M,
    grid: Grid,
    initial: Vec<M::State>,
    config: &KernelConfig,
    threads: usize,
    steps: u64,
    wanted: StatesWanted,
    mut sink: impl FnMut(&Frame, Option<&[&M::State]>),
) -> Result<ThreadedReport, ExecError> {
    let start = Instant::now();
    let threads = threads.max(1);
    let positions: Vec<[f32; 3]> = initial.iter().map(M::position).collect();
    let mut initial_events = Vec::new();
    let state = CellStates::binned::<M>(&grid, initial, 0, &mut initial_events);
    let partition = Arc::new(Partition::build(
        &config.partition,
        &grid,
        config.worlds.max(1),
        &positions,
        config.partition_seed,
    ));
    let model = Arc::new(model);
    let grid = Arc::new(grid);
    let n = partition.worlds();
    let mut worlds: Vec<World<M>> = (0..n as WorldId)
        .map(|w| {
            World::new(
                w,
                model.clone(),
                grid.clone(),
                partition.clone(),
                config,
                &state,
            )
        })
        .collect();
    drop(state);
    let mut inboxes: Vec<Vec<Message<M::State>>> = (0..n).map(|_| Vec::new()).collect();
    for w in &mut worlds {
        w.set_end(steps);
        for m in w.start() {
            inboxes[m.dst_world as usize].push(m);
        }
    }
    let shared = Arc::new(Shared::<M, F> {
        worlds: worlds.into_iter().map(F::Mutex::new).collect(),
        inboxes: inboxes.into_iter().map(F::Mutex::new).collect(),
        scheduled: (0..n).map(|_| F::Atomic::new(1)).collect(),
        injector: Injector::new(),
        gvt: F::Atomic::new(1),
        committed: F::Atomic::new(0),
        gvt_round: F::Atomic::new(0),
        status: F::Atomic::new(if steps == 0 { DONE } else { RUNNING }),
        target: steps,
        wanted,
        out: F::Mutex::new(Output::default()),
        error: F::Mutex::new(None),
    });
    for w in 0..n {
        shared.injector.push(w);
    }
    let locals: Vec<Worker<usize>> = (0..threads).map(|_| Worker::new_fifo()).collect();
    let stealers = Arc::new(locals.iter().map(|w| w.stealer()).collect::<Vec<_>>());
    let handles: Vec<F::Handle> = locals
        .into_iter()
        .enumerate()
        .map(|(me, local)| {
            let shared = shared.clone();
            let stealers = stealers.clone();
            F::spawn(move || shared.worker_loop(me, local, stealers))
        })
        .collect();
    // The output stage: hand committed frames to the sink while the workers run.
    let mut frames = Vec::new();
    let mut deliver = |batch: VecDeque<(Frame, Option<Vec<M::State>>)>| {
        for (frame, states) in batch {
            if frames.len() < steps as usize {
                let refs: Option<Vec<&M::State>> = states.as_ref().map(|v| v.iter().collect());
                sink(&frame, refs.as_deref());
                frames.push(frame);
            }
        }
    };
    while shared.status.load() == RUNNING {
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
    let mut out = std::mem::take(&mut *shared.out.lock());
    deliver(std::mem::take(&mut out.pending));
    let world_counters = shared
        .worlds
        .iter()
        .map(|w| w.lock().counters().clone())
        .collect();
    let counters = Counters::from_worlds(world_counters, out.gvt_advances, shared.gvt.load());
    Ok(ThreadedReport {
        frames,
        counters,
        times: out.times,
        wall_seconds: start.elapsed().as_secs_f64(),
        threads,
        initial_events,
    })
}
