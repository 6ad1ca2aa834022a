//! How to run a model: the executor, the kernel configuration and the thread count.

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
/// and the thread count (threaded executor only).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RunOptions {
    /// The executor.
    pub executor: ExecutorKind,
    /// Worlds, mode, window, partition, schedule.
    pub kernel: KernelConfig,
    /// OS threads of the threaded executor (at least 1).
    pub threads: usize,
    /// The threaded executor's laggard lead ([`ThreadedOptions::lead`]; 0 by default, and in
    /// checkpoints written before it moved here).
    ///
    /// [`ThreadedOptions::lead`]: crate::exec::threaded::ThreadedOptions::lead
    #[serde(default)]
    pub lead: u64,
}

impl RunOptions {
    /// The reference executor.
    pub fn reference() -> Self {
        Self::default()
    }

    /// The virtual executor with `kernel`.
    pub fn virtual_exec(kernel: KernelConfig) -> Self {
        RunOptions {
            executor: ExecutorKind::Virtual,
            kernel,
            threads: 1,
            lead: 0,
        }
    }

    /// The threaded executor with `kernel` on `threads` threads.
    pub fn threaded(kernel: KernelConfig, threads: usize) -> Self {
        RunOptions {
            executor: ExecutorKind::Threaded,
            kernel,
            threads,
            lead: 0,
        }
    }

    /// The same options with the threaded executor's laggard lead `lead`.
    pub fn lead(mut self, lead: u64) -> Self {
        self.lead = lead;
        self
    }
}
