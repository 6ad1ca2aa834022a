//! The threaded executor: T OS threads run the kernel's worlds as tasks. Ready worlds wait
//! in one shared set ordered critical path first (the laggard first; among worlds at the
//! same step, the one whose last computation took longest); worlds that had to wait
//! (postponed behind a laggard, or running elsewhere) go to a crossbeam-deque
//! [`Injector`](crossbeam_deque::Injector) that threads take from when nothing is ready,
//! until a message or a GVT advance moves them back into the ready set. A world runs on at most one thread at a
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
//! sorted, hashed — by one worker at a time, between its turns) only once every world
//! has contributed, and queued in step order for the output stage on the calling thread. A frame is never torn or speculative.
//!
//! This is the only module that starts threads, and it does so through [`Facade`].
//!
//! Its parts: the run's state the threads share (`shared`: worlds, inboxes, published
//! bounds, ready set, status), the worker loop (`worker`: take a world, run one turn of it),
//! GVT rounds and the stall check (`gvt`), the frame assembly and the output stage
//! (`output`), and the run itself (`run`: threads started per epoch, balancing between
//! epochs). The public types are re-exported here.

mod gvt;
mod options;
mod output;
mod report;
mod run;
mod shared;
mod worker;

pub use super::error::ExecError;
pub use options::{ThreadedOptions, ThreadedSetup};
pub use report::{ThreadTimes, ThreadedReport};
pub use run::run_threaded_controlled;

use super::sync::{Facade, StdFacade};
use crate::frame::Frame;
use crate::grid::Grid;
use crate::kernel::KernelConfig;
use crate::model::CellModel;

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
