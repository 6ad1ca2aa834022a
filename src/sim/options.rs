//! How to run a model: the executor, the kernel configuration and each executor's settings.

use crate::exec::virtual_exec::{ScheduleSpec, VirtualOptions};
use crate::kernel::KernelConfig;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// Which executor runs a model (SPEC.md §8, §9, §10): all three commit the same bits.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ExecutorKind {
    /// One thread, no worlds: the oracle.
    #[default]
    Reference,
    /// One thread runs the worlds under a seeded, replayable schedule.
    Virtual,
    /// OS threads run the worlds as tasks, the laggard (at equal step the heaviest) first.
    Threaded,
    /// The worlds spread over the ranks of an MPI job (cargo feature `mpi`; run under
    /// `mpirun`; SPEC.md §14). Not in [`ExecutorKind::ALL`]: it needs MPI.
    Mpi,
}

impl ExecutorKind {
    /// Every executor, reference first.
    pub const ALL: [ExecutorKind; 3] = [Self::Reference, Self::Virtual, Self::Threaded];

    /// Its name (what [`FromStr`] reads): `reference`, `virtual` or `threaded`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Reference => "reference",
            Self::Virtual => "virtual",
            Self::Threaded => "threaded",
            Self::Mpi => "mpi",
        }
    }
}

impl fmt::Display for ExecutorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// An executor name that is none of `reference`, `virtual`, `threaded`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("`{0}` is not an executor: use reference, virtual, threaded or mpi")]
pub struct UnknownExecutor(pub String);

impl FromStr for ExecutorKind {
    type Err = UnknownExecutor;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "reference" => Ok(Self::Reference),
            "virtual" => Ok(Self::Virtual),
            "threaded" => Ok(Self::Threaded),
            "mpi" => Ok(Self::Mpi),
            other => Err(UnknownExecutor(other.to_string())),
        }
    }
}

/// How to run a model: the executor, the kernel configuration (ignored by the reference)
/// and the settings of the executor that runs it: the thread count and lead (threaded), the
/// schedule and its recording (virtual).
///
/// It is written into checkpoints. A document written when the schedule and its recording
/// were part of the kernel configuration (`kernel.schedule`, `kernel.record_schedule`)
/// reads back with them here, so a resumed virtual run keeps its schedule.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(from = "stored::StoredRunOptions")]
pub struct RunOptions {
    /// The executor.
    pub executor: ExecutorKind,
    /// Worlds, mode, window, partition, ghosts, balancing.
    pub kernel: KernelConfig,
    /// OS threads of the threaded executor (at least 1).
    pub threads: usize,
    /// The threaded executor's laggard lead ([`ThreadedOptions::lead`]; 0 by default, and in
    /// checkpoints written before it moved here).
    ///
    /// [`ThreadedOptions::lead`]: crate::exec::threaded::ThreadedOptions::lead
    pub lead: u64,
    /// The virtual executor's schedule ([`VirtualOptions::schedule`]; seed 0 by default).
    pub schedule: ScheduleSpec,
    /// Whether the virtual executor records its decisions, so the report carries a replay
    /// string ([`VirtualOptions::record_schedule`]; on by default).
    pub record_schedule: bool,
}

impl Default for RunOptions {
    /// The reference executor; for the others, the default kernel configuration, one thread,
    /// lead 0, schedule seed 0 recorded.
    fn default() -> Self {
        let virtual_options = VirtualOptions::default();
        RunOptions {
            executor: ExecutorKind::default(),
            kernel: KernelConfig::default(),
            threads: 0,
            lead: 0,
            schedule: virtual_options.schedule,
            record_schedule: virtual_options.record_schedule,
        }
    }
}

impl RunOptions {
    /// The reference executor.
    pub fn reference() -> Self {
        Self::default()
    }

    /// The virtual executor with `kernel` (schedule seed 0, decisions recorded).
    pub fn virtual_exec(kernel: KernelConfig) -> Self {
        RunOptions {
            executor: ExecutorKind::Virtual,
            kernel,
            threads: 1,
            ..Self::default()
        }
    }

    /// The threaded executor with `kernel` on `threads` threads.
    pub fn threaded(kernel: KernelConfig, threads: usize) -> Self {
        RunOptions {
            executor: ExecutorKind::Threaded,
            kernel,
            threads,
            ..Self::default()
        }
    }

    /// The MPI executor with `kernel`: the worlds spread over the ranks of the MPI job this
    /// process belongs to (cargo feature `mpi`; without it the run fails saying so).
    pub fn mpi(kernel: KernelConfig) -> Self {
        RunOptions {
            executor: ExecutorKind::Mpi,
            kernel,
            threads: 1,
            ..Self::default()
        }
    }

    /// The same options with the threaded executor's laggard lead `lead`.
    pub fn lead(mut self, lead: u64) -> Self {
        self.lead = lead;
        self
    }

    /// The same options with the virtual executor's schedule `schedule`.
    pub fn schedule(mut self, schedule: ScheduleSpec) -> Self {
        self.schedule = schedule;
        self
    }

    /// The same options with the virtual executor's decision recording on or off.
    pub fn record_schedule(mut self, on: bool) -> Self {
        self.record_schedule = on;
        self
    }

    /// The virtual executor's options these say.
    pub fn virtual_options(&self) -> VirtualOptions {
        VirtualOptions::new(self.schedule.clone()).record_schedule(self.record_schedule)
    }
}

/// `RunOptions` as documents hold them, older layouts included.
mod stored {
    use super::{ExecutorKind, RunOptions, ScheduleSpec, VirtualOptions};
    use crate::kernel::KernelConfig;
    use serde::Deserialize;

    /// A `RunOptions` document: the schedule and its recording at the top level, or, in a
    /// document written before they left the kernel configuration, inside `kernel`.
    #[derive(Deserialize)]
    pub(super) struct StoredRunOptions {
        executor: ExecutorKind,
        kernel: StoredKernel,
        threads: usize,
        #[serde(default)]
        lead: u64,
        #[serde(default)]
        schedule: Option<ScheduleSpec>,
        #[serde(default)]
        record_schedule: Option<bool>,
    }

    /// A kernel configuration, with the virtual executor's settings an older document
    /// kept in it.
    #[derive(Deserialize)]
    struct StoredKernel {
        #[serde(flatten)]
        config: KernelConfig,
        #[serde(default)]
        schedule: Option<ScheduleSpec>,
        #[serde(default)]
        record_schedule: Option<bool>,
    }

    impl From<StoredRunOptions> for RunOptions {
        fn from(s: StoredRunOptions) -> Self {
            let defaults = VirtualOptions::default();
            RunOptions {
                executor: s.executor,
                kernel: s.kernel.config,
                threads: s.threads,
                lead: s.lead,
                schedule: s
                    .schedule
                    .or(s.kernel.schedule)
                    .unwrap_or(defaults.schedule),
                record_schedule: s
                    .record_schedule
                    .or(s.kernel.record_schedule)
                    .unwrap_or(defaults.record_schedule),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn options_round_trip_and_an_older_document_keeps_its_schedule() {
        let options = RunOptions::virtual_exec(KernelConfig::new(3).window(5))
            .schedule(ScheduleSpec::Replay(vec![3, 1, 4]))
            .record_schedule(false);
        let json = serde_json::to_value(&options).unwrap();
        assert!(json["kernel"].get("schedule").is_none(), "{json}");
        let back: RunOptions = serde_json::from_value(json.clone()).unwrap();
        assert_eq!(back, options);
        // Written before the schedule left the kernel configuration (and before `lead`
        // left it too): the schedule and its recording are read from `kernel`.
        let mut old = json;
        let top = old.as_object_mut().unwrap();
        let schedule = top.remove("schedule").unwrap();
        let record = top.remove("record_schedule").unwrap();
        top.remove("lead");
        old["kernel"]["schedule"] = schedule;
        old["kernel"]["record_schedule"] = record;
        old["kernel"]["lead"] = 2.into();
        let back: RunOptions = serde_json::from_value(old).unwrap();
        assert_eq!(back, options);
    }
}
