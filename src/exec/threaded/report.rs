//! What a threaded run reports: its frames, counters and the threads' time.

use crate::frame::{Event, Frame};
use crate::kernel::balance::RoundRecord;
use crate::kernel::counters::Counters;
use crate::kernel::trace::RunTrace;

/// Time spent by the worker threads, summed over threads (wall-clock, for statistics only:
/// nothing here reaches a hash).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct ThreadTimes {
    /// Seconds inside world turns that computed something, and finishing committed frames
    /// (sorting and hashing them).
    pub busy_seconds: f64,
    /// Of the busy time, seconds in actions applying an inbox (message exchange).
    pub receive_seconds: f64,
    /// Of the busy time, seconds in actions re-executing dirty steps (rollback).
    pub rollback_seconds: f64,
    /// Of the busy time, seconds in actions computing forward.
    pub compute_seconds: f64,
    /// Of the compute time, seconds computing a held-back world's interior ahead
    /// ([`World::compute_interior_ahead`](crate::kernel::world::World::compute_interior_ahead)).
    pub ahead_seconds: f64,
    /// Seconds inside GVT rounds (reading the published bounds).
    pub gvt_seconds: f64,
    /// Seconds with no task, or in turns that computed nothing.
    pub idle_seconds: f64,
    /// Number of world actions.
    pub actions: u64,
    /// Tasks of a world that another thread ran last (migrations between threads).
    pub steals: u64,
    /// Actions of a world on another thread than its previous action's (the world's states
    /// then leave one core's cache for another's).
    pub moves: u64,
}

/// The result of a threaded run.
#[derive(Clone, Debug)]
pub struct ThreadedReport<E> {
    /// Committed frames in step order (empty when the setup did not keep them,
    /// [`ThreadedSetup::keep_frames`](super::ThreadedSetup::keep_frames)).
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
