//! The worker threads: each takes a world task (the best ready world, else a waiting one),
//! runs one turn of it (receive its inbox, hand committed steps to the frame assembly, act,
//! route the output, publish its bound) and takes part in GVT rounds between turns.

use super::report::ThreadTimes;
use super::shared::{EndOnUnwind, RunStatus, SharedRun, ThreadedWorld};
use crate::exec::clock::thread_cpu_seconds;
use crate::exec::error::ExecError;
use crate::exec::sync::{panic_message, Facade, FacadeAtomic, FacadeMutex};
use crate::kernel::partition::WorldId;
use crate::kernel::world::{ActionKind, World};
use crate::model::{CellModel, Step};
use crossbeam_deque::Steal;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::time::Instant;

/// Consecutive idle pauses after which a thread checks, under the full cut, whether the run
/// has stalled (a kernel bug) rather than waiting for ever.
const STALL_CHECK_SPINS: u32 = 20_000;

impl<M: CellModel + 'static, F: Facade> SharedRun<M, F> {
    pub(super) fn worker_loop(&self, me: usize) {
        let _fail_on_unwind = EndOnUnwind::failing(self);
        let mut times = ThreadTimes::default();
        let mut spins = 0u32;
        let mut cap_seen = None;
        while self.status() == RunStatus::Running {
            let t0 = Instant::now();
            let task = self.find_task(me, &mut times.steals);
            self.idle[me].store(u64::from(task.is_none()));
            match task {
                Some(w) => {
                    let ahead_before = times.ahead_seconds;
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
                        // Computing ahead in a held-back turn is busy time.
                        let ahead = times.ahead_seconds - ahead_before;
                        times.busy_seconds += ahead;
                        times.idle_seconds += t0.elapsed().as_secs_f64() - ahead;
                    }
                    let g0 = Instant::now();
                    self.gvt_round();
                    times.gvt_seconds += g0.elapsed().as_secs_f64();
                    // The turn may have queued committed steps: they are finished now, in
                    // step order, without the world's lock (SPEC.md §10). Busy time.
                    let f0 = Instant::now();
                    self.finish_pending();
                    times.busy_seconds += f0.elapsed().as_secs_f64();
                }
                None => {
                    let g0 = Instant::now();
                    let advanced = self.gvt_round();
                    times.gvt_seconds += g0.elapsed().as_secs_f64();
                    if !advanced {
                        let i0 = Instant::now();
                        // At the cap of frames not yet delivered, only the output stage can
                        // let GVT move. Once it has taken no frame for a slow poll's time
                        // (a consumer paced by a display: one frame every 16 ms), nap as
                        // its slow poll does rather than wake every 50 µs, leaving the
                        // cores to it; an output stage that only stalled briefly keeps the
                        // short pauses.
                        let nap = if self.paced_by_output(&mut cap_seen) {
                            u32::MAX
                        } else {
                            spins
                        };
                        F::pause(nap);
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
        out.times.ahead_seconds += times.ahead_seconds;
        out.times.gvt_seconds += times.gvt_seconds;
        out.times.idle_seconds += times.idle_seconds;
        out.times.actions += times.actions;
        out.times.steals += times.steals;
        out.times.moves += times.moves;
    }

    /// The next world task for thread `me`: the best ready world, else a waiting one.
    /// Counts in `steals` the tasks of worlds another thread ran last.
    /// Stale waiting tokens (of worlds woken since) are dropped on the way.
    fn find_task(&self, me: usize, steals: &mut u64) -> Option<usize> {
        // With no more worlds than threads, among equally critical worlds the one this
        // thread ran last (its cache is warm): in a near-lockstep run each world then stays
        // on one core.
        // A world whose home is another, idle, thread is left to it.
        let home = |w: usize| self.home[w].load() as usize;
        let leave = |w: usize| self.stay_home && home(w) != me && self.idle[home(w)].load() == 1;
        let first = self
            .sched
            .lock()
            .take_ready_preferring(|w| self.stay_home && home(w) == me, leave);
        // Tokens left to their idle home thread go back to the queue afterwards, so this
        // thread still reaches the tokens behind them.
        let mut left = Vec::new();
        let task = first.or_else(|| loop {
            match self.waiting.steal() {
                Steal::Success((w, token)) if leave(w) => left.push((w, token)),
                Steal::Success((w, token)) => {
                    if self.sched.lock().take_waiting(w, token) {
                        break Some(w);
                    }
                }
                Steal::Retry => {}
                Steal::Empty => break None,
            }
        });
        for t in left {
            self.waiting.push(t);
        }
        if let Some(w) = task {
            *steals += (self.home[w].load() != me as u64) as u64;
        }
        task
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
            // Held back, the world computes ahead the cells no foreign view reaches: the
            // wait for its neighbour is spent on work the advance then skips (SPEC.md §K5).
            if self.compute_ahead && !world.interior_computed_ahead() {
                let a0 = Instant::now();
                let c0 = thread_cpu_seconds();
                match catch_unwind(AssertUnwindSafe(|| world.compute_interior_ahead(gvt))) {
                    Ok(0) => {}
                    Ok(_) => {
                        let spent = a0.elapsed().as_secs_f64();
                        meter.add_busy(thread_cpu_seconds() - c0);
                        times.compute_seconds += spent;
                        times.ahead_seconds += spent;
                    }
                    Err(p) => {
                        self.fail(ExecError::WorldPanicked {
                            world: w as WorldId,
                            step: world.lvt(),
                            message: panic_message(&*p),
                        });
                        return false;
                    }
                }
            }
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
            times.moves += u64::from(self.home[w].load() != me as u64);
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
}
