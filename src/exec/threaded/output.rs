//! Committed frames: each world hands its states of the steps below GVT to the frame
//! assembly; a step every world contributed is queued whole, in step order, and one worker
//! at a time sorts and hashes the queued steps between its turns; the output stage (the
//! calling thread) hands the finished frames to the sink.

use super::report::ThreadTimes;
use super::shared::{RunStatus, SharedRun, ThreadedWorld};
use crate::exec::error::ExecError;
use crate::exec::sync::{panic_message, Facade, FacadeAtomic, FacadeMutex, ThreadPanicked};
use crate::exec::LastFrame;
use crate::frame::{Event, Frame, StatesWanted};
use crate::kernel::trace::GvtSample;
use crate::model::{CellModel, Step};
use std::collections::{BTreeMap, VecDeque};
use std::panic::{catch_unwind, AssertUnwindSafe};

/// Committed steps being assembled from the worlds' contributions.
pub(super) struct Assembly<M: CellModel> {
    /// The steps some worlds have contributed to, by step.
    pub(super) partial: BTreeMap<Step, Partial<M>>,
    /// The next step to be queued for finishing (when every world has contributed it).
    pub(super) next: Step,
}

/// One committed step's contributions so far.
pub(super) struct Partial<M: CellModel> {
    /// How many worlds contributed.
    pub(super) worlds: usize,
    /// The contributing worlds' cells' states (any order), shared with their logs.
    pub(super) states: Vec<crate::kernel::SharedStates<M::State>>,
    /// The events of their cells' computations of the step before.
    pub(super) events: Vec<Event<M::Event>>,
    /// Whether every contributing world's cells hold the allocations of the step before
    /// ([`crate::kernel::World::unchanged_since_previous`]).
    pub(super) unchanged: bool,
}

/// Committed steps waiting to be finished, whole (every world contributed) but not yet
/// sorted and hashed ([`SharedRun::finish_pending`]).
pub(super) struct Output<M: CellModel> {
    /// Whole committed steps, in step order.
    pub(super) pending: VecDeque<(Step, Partial<M>)>,
    /// How many times GVT advanced.
    pub(super) gvt_advances: u64,
    /// The worker threads' times, summed as they finish.
    pub(super) times: ThreadTimes,
    /// GVT over time (with a trace).
    pub(super) gvt_samples: Vec<GvtSample>,
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

impl<M: CellModel + 'static, F: Facade> SharedRun<M, F> {
    /// Hands the world's states of the steps below `gvt` not yet handed over to the frame
    /// assembly, then fossil-collects its logs.
    pub(super) fn contribute(&self, held: &mut ThreadedWorld<M>, gvt: Step) {
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
        // They are flattened when the frame is sorted and hashed.
        let mut assembly = self.assembly.lock();
        for t in held.contributed + 1..=last {
            let part = assembly.partial.entry(t).or_insert_with(|| Partial {
                worlds: 0,
                states: Vec::new(),
                events: Vec::new(),
                unchanged: true,
            });
            part.worlds += 1;
            part.unchanged &= held.world.unchanged_since_previous(t);
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
        // Whole steps are queued under the assembly lock, so they are finished in step order
        // whichever thread completes them.
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
}

/// A committed step sorted and hashed: its frame, and its states if the sink
/// asked for them.
pub(super) struct FinishedFrame<M: CellModel> {
    /// The step.
    pub(super) step: Step,
    /// Its frame.
    pub(super) frame: Frame<M::Event>,
    /// Its states, sorted by id, if wanted.
    pub(super) states: Option<Vec<M::State>>,
}

impl<M: CellModel + 'static, F: Facade> SharedRun<M, F> {
    /// Finishes the committed steps pending, in step order (sorts and hashes each: the
    /// work the reference executor does at each step, [`finish_frame`]), and queues their
    /// frames for the output stage, unless another thread is finishing them now: that
    /// thread looks at the queue again after it lets go, so a step queued meanwhile is
    /// never left behind. A worker calls it after each turn of a world, without the
    /// world's lock (SPEC.md §10). Steps after the sink stopped the run, after the run
    /// failed, or after finishing a frame panicked (sticky: `Finishing::failed`), are
    /// dropped unfinished.
    pub(super) fn finish_pending(&self) {
        loop {
            let Some(mut finishing) = self.finishing.try_lock() else {
                return;
            };
            while let Some((step, partial)) = self.pop_pending() {
                if finishing.failed || self.stop.load() == 1 || self.status() == RunStatus::Failed {
                    continue;
                }
                // A model's hash panicking stops the run with an error instead of leaving
                // the workers waiting for a sink that no frame reaches.
                let finished = catch_unwind(AssertUnwindSafe(|| {
                    finish_frame::<M>(step, partial, &self.wanted, &mut finishing.last)
                }));
                match finished {
                    Ok((frame, states)) => self.finished.lock().push_back(FinishedFrame {
                        step,
                        frame,
                        states,
                    }),
                    Err(p) => {
                        finishing.failed = true;
                        self.fail(ExecError::Thread(ThreadPanicked(format!(
                            "finishing the frame of step {step} panicked: {}",
                            panic_message(&*p)
                        ))));
                    }
                }
            }
            drop(finishing);
            // A step queued while this thread let go: its queuer found the lock taken and
            // left the step to this thread.
            if self.out.lock().pending.is_empty() {
                return;
            }
        }
    }

    /// The first committed step waiting to be finished, taken from the queue.
    fn pop_pending(&self) -> Option<(Step, Partial<M>)> {
        self.out.lock().pending.pop_front()
    }
}

/// Finishes committed step `t` from every world's contribution
/// ([`crate::exec::next_frame`]: a step no world's cells changed at keeps the hash of
/// `last`, the step before) and, if `wanted` asks for them, clones its sorted states.
pub(super) fn finish_frame<M: CellModel>(
    t: Step,
    p: Partial<M>,
    wanted: &StatesWanted,
    last: &mut Option<LastFrame>,
) -> (Frame<M::Event>, Option<Vec<M::State>>) {
    let (frame, sorted) = crate::exec::next_frame::<M>(
        t,
        p.states.iter().flat_map(|c| c.iter()),
        p.events,
        p.unchanged,
        last,
        wanted,
    );
    let states = sorted.map(|s| s.into_iter().cloned().collect());
    (frame, states)
}
