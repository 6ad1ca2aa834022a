//! A threaded run: the worlds are built, the threads started for each epoch (the whole run,
//! or the steps up to the next balancing round), the output stage hands frames to the sink
//! meanwhile, and between epochs a balancing round may move cells.

use super::options::{ThreadedOptions, ThreadedSetup};
use super::output::{Assembly, FinishedFrame, Output};
use super::report::ThreadedReport;
use super::shared::{
    EndOnUnwind, Finishing, InputLog, RunStatus, SharedRun, ThreadedWorld, UNDELIVERED_WINDOWS,
};
use crate::exec::control::RunControl;
use crate::exec::error::ExecError;
use crate::exec::live::{LiveStatus, WorldStatus};
use crate::exec::load::LoadMeter;
use crate::exec::schedule::Schedule;
use crate::exec::sync::{
    Facade, FacadeAtomic, FacadeMutex, LONGEST_POLL, SLOW_POLL, SOON_POLL_SPINS,
};
use crate::frame::Frame;
use crate::kernel::balance::{imbalance, Balancer};
use crate::kernel::counters::Counters;
use crate::kernel::message::{Input, Message};
use crate::kernel::world::World;
use crate::model::{CellModel, Step};
use crossbeam_deque::Injector;
use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// The `spins` the output stage passes to [`Facade::pause`] while the workers will wait
/// for it within two slow polls but not within half of one ([`SOON_POLL_SPINS`]: a
/// quarter of a slow poll with `StdFacade`).
const OUTPUT_PAUSE_SOON: u32 = SOON_POLL_SPINS;

/// The `spins` the output stage passes to [`Facade::pause`] while the workers wait or are
/// about to wait for it (the epoch's end or the undelivered frames' cap is within half a
/// slow poll's steps, or [`AWAITED_STEPS`]): a short sleep (50 µs with `StdFacade`).
const OUTPUT_PAUSE_URGENT: u32 = 64;

/// Within this many steps of the epoch's end or the undelivered cap, the output stage
/// polls fast whatever the pace: when the epoch ends every worker idles until it notices.
const AWAITED_STEPS: Step = 2;

/// [`run_threaded_with`](super::run_threaded_with) with scripted inputs, and a sink that also
/// gets a [`RunControl`] to schedule inputs during the run (checked against GVT at that
/// moment) or stop it after the current frame. Stopping ends the run early: the report holds the frames delivered.
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
        compute_ahead,
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
    let crate::exec::Worlds {
        mut worlds,
        events: initial_events,
        grid,
        mut partition,
    } = crate::exec::build_worlds(model, grid, initial, config);
    let n = worlds.len();
    // Balancing shares the load between the threads unless told otherwise.
    let mut balance = config.balance.clone();
    if balance.workers == 0 {
        balance.workers = threads;
    }
    let mut balancer = Balancer::new(&balance, grid.cell_count());
    if balancer.opens() {
        if let Some(p) =
            crate::exec::opening_round(&mut balancer, &grid, &partition, worlds.iter_mut())
        {
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
        stay_home: n <= threads,
        idle: (0..threads).map(|_| F::Atomic::new(0)).collect(),
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
        compute_ahead,
        assembly: F::Mutex::new(Assembly {
            partial: BTreeMap::new(),
            next: 1,
        }),
        out: F::Mutex::new(Output::default()),
        finished: F::Mutex::new(VecDeque::new()),
        finishing: F::Mutex::new(Finishing::default()),
        wanted: wanted.clone(),
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
    // A panicking sink stops the workers before it unwinds out of the run.
    let stop_on_unwind = EndOnUnwind::stopping(&shared);
    let poster = shared.clone();
    let mut deliver = |batch: VecDeque<FinishedFrame<M>>| {
        for FinishedFrame {
            step: t,
            frame,
            states,
        } in batch
        {
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
    // The steps' pace, measured across epochs (an epoch may be shorter than a slow poll).
    let mut pace = Pace::new(shared.committed.load());
    let mut last_round: Step = 0;
    // The epochs.
    let mut epochs = || -> Result<(), ExecError> {
        loop {
            run_epoch(&shared, threads, &mut pace, &mut deliver)?;
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
            let moved = crate::exec::balance_round(
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
                let restart = crate::exec::restart_worlds(
                    locked.iter_mut().map(|s| &mut s.world),
                    &shared.inputs.lock().posted,
                    committed,
                );
                let reposted = restart
                    .pending_inputs
                    .iter()
                    .flat_map(|m| crate::exec::to_every_world(m, n));
                for m in restart.started.into_iter().chain(reposted) {
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
            // The restart is decided under the error lock, which `fail` holds while it
            // marks the run failed, so a failure is never overwritten by `Running`.
            let error = shared.error.lock();
            if error.is_some() {
                break;
            }
            shared.set_status(RunStatus::Running);
            drop(error);
        }
        Ok(())
    };
    let epochs = epochs();
    drop(stop_on_unwind);
    epochs?;
    if let Some(e) = shared.error.lock().take() {
        return Err(e);
    }
    deliver(std::mem::take(&mut *shared.finished.lock()));
    let out = std::mem::take(&mut *shared.out.lock());
    let mut locked: Vec<_> = shared.worlds.iter().map(|w| w.lock()).collect();
    for (w, s) in locked.iter_mut().enumerate() {
        busy_total[w] += s.meter.busy_seconds();
    }
    let world_counters = locked.iter().map(|s| s.world.counters().clone()).collect();
    let trace = config.trace.then(|| {
        let mut worlds: Vec<&mut World<M>> = locked.iter_mut().map(|s| &mut s.world).collect();
        crate::exec::collect_trace(&grid, &partition, &mut worlds, out.gvt_samples)
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

/// How fast steps are committed, as the output stage sees it: how many one slow poll
/// ([`SLOW_POLL`]) lets through, so it polls fast early enough when steps are quick, and how
/// long one step takes, so it polls no more than about once a step when steps are slow (a
/// poll wakes a thread that takes a worker's core for a moment: at 27,000 cubes a step
/// takes ~50 ms, and polling every 2 ms was ~500 context switches a second).
struct Pace {
    /// When it last measured.
    at: Instant,
    /// The last committed step then.
    committed: Step,
    /// Steps committed per slow poll, at the last measurement ([`Step::MAX`] before one:
    /// until the pace is known the output stage polls fast).
    per_poll: Step,
    /// How long a step took at the last measurement (at least the time measured when no
    /// step was committed in it; [`SLOW_POLL`] before one).
    per_step: Duration,
}

impl Pace {
    fn new(committed: Step) -> Self {
        Pace {
            at: Instant::now(),
            committed,
            per_poll: Step::MAX,
            per_step: SLOW_POLL,
        }
    }

    /// Measures again once at least a slow poll's time has passed since the last time.
    fn observe(&mut self, committed: Step) {
        let elapsed = self.at.elapsed();
        if elapsed < SLOW_POLL {
            return;
        }
        let steps = committed.saturating_sub(self.committed);
        self.per_poll =
            (steps as f64 * SLOW_POLL.as_secs_f64() / elapsed.as_secs_f64()).ceil() as Step;
        self.per_step = elapsed / u32::try_from(steps.max(1)).unwrap_or(u32::MAX);
        self.at = Instant::now();
        self.committed = committed;
    }

    /// The slow poll's sleep: a step's time, within [`SLOW_POLL`]..=[`LONGEST_POLL`]. Used
    /// only while more than two slow polls' steps are left before anyone waits for the
    /// output stage, so at least three steps: the workers cannot reach the point where they
    /// wait for it within one step's time.
    fn slow_sleep(&self) -> Duration {
        self.per_step.clamp(SLOW_POLL, LONGEST_POLL)
    }
}

/// One epoch: every world is queued, `threads` workers run until the epoch's last step is
/// committed (or the run fails), the output stage delivers frames meanwhile.
fn run_epoch<M: CellModel + 'static, F: Facade>(
    shared: &Arc<SharedRun<M, F>>,
    threads: usize,
    pace: &mut Pace,
    deliver: &mut impl FnMut(VecDeque<FinishedFrame<M>>),
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
        let batch = std::mem::take(&mut *shared.finished.lock());
        if batch.is_empty() {
            pace.observe(shared.committed.load());
            let left = shared.steps_before_output_is_awaited();
            if left <= AWAITED_STEPS || left <= pace.per_poll / 2 {
                F::pause(OUTPUT_PAUSE_URGENT);
            } else if left <= pace.per_poll.saturating_mul(2) {
                F::pause(OUTPUT_PAUSE_SOON);
            } else {
                // Nobody waits for it: the slow poll, at the steps' pace (`Pace`).
                F::pause_for(pace.slow_sleep());
            }
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
    // Whoever queued a step finished it, or left it to the thread finishing then, which
    // looked at the queue again before it let go (stopped or failed runs drop theirs): a
    // step still queued here would be a step the sink waits for in vain.
    assert!(
        shared.out.lock().pending.is_empty() || thread_error.is_some(),
        "a committed step was queued and never finished"
    );
    if let Some(e) = shared.error.lock().take() {
        return Err(e);
    }
    if let Some(e) = thread_error {
        return Err(ExecError::Thread(e));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A pace whose last measurement was `ago` before now, at step 0.
    fn measured_since(ago: Duration) -> Pace {
        let mut p = Pace::new(0);
        p.at = Instant::now() - ago;
        p
    }

    #[test]
    fn the_slow_poll_sleeps_a_steps_time_between_two_and_sixteen_milliseconds() {
        // Before any measurement: the 2 ms slow poll.
        assert_eq!(Pace::new(0).slow_sleep(), SLOW_POLL);
        // Slow steps (~50 ms each): one poll per 16 ms at most.
        let mut slow = measured_since(Duration::from_millis(100));
        slow.observe(2);
        assert_eq!(slow.per_poll, 1);
        assert_eq!(slow.slow_sleep(), LONGEST_POLL);
        // No step at all in the time measured: as slow as that time, at least.
        let mut stuck = measured_since(Duration::from_millis(5));
        stuck.observe(0);
        assert!(stuck.per_step >= Duration::from_millis(5));
        assert!(stuck.slow_sleep() >= Duration::from_millis(5));
        assert!(stuck.slow_sleep() <= LONGEST_POLL);
        // Quick steps (1,000 in 100 ms): never faster than the slow poll.
        let mut quick = measured_since(Duration::from_millis(100));
        quick.observe(1_000);
        assert!(quick.per_poll >= 10);
        assert_eq!(quick.slow_sleep(), SLOW_POLL);
    }
}
