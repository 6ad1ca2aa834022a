//! What `verify` found: one line per run, and the report over all of them.

use super::diagnosis::Diagnosis;
use crate::divergence::Divergence;
use crate::exec::error::{ContractViolation, ExecError};
use crate::kernel::{Counters, RollbackMode};
use crate::model::Step;
use crate::sim::ExecutorKind;
use crate::text::counted;
use std::fmt;

/// One checked run: its configuration, counters, replay schedule and outcome.
#[derive(Clone, Debug)]
pub struct RunCheck {
    /// The executor.
    pub executor: ExecutorKind,
    /// The rollback mode.
    pub mode: RollbackMode,
    /// The virtual executor's schedule seed (`None` for threaded runs).
    pub schedule_seed: Option<u64>,
    /// Threads (threaded runs; 1 otherwise).
    pub threads: usize,
    /// Ranks of the MPI job (MPI runs; `None` otherwise).
    pub ranks: Option<usize>,
    /// The kernel's counters of the run (`None` if it failed).
    pub counters: Option<Counters>,
    /// The virtual executor's replay string of the run (`None` for threaded runs).
    pub replay: Option<String>,
    /// Committed steps whose hash equalled the reference's.
    pub steps_matched: u64,
    /// What happened.
    pub outcome: RunOutcome,
}

/// How a checked run ended.
#[derive(Clone, Debug)]
pub enum RunOutcome {
    /// Every committed hash equalled the reference's.
    Matched,
    /// A committed hash differed.
    Diverged(Mismatch),
    /// The run stopped with an error (a model panic, a kernel check).
    Failed(ExecError),
}

/// The first committed step whose hash differs from the reference's, and the first
/// difference found in its state.
#[derive(Clone, Debug, PartialEq)]
pub struct Mismatch {
    /// The step.
    pub step: Step,
    /// The reference's hash there.
    pub expected_hash: u64,
    /// The run's hash there.
    pub got_hash: u64,
    /// The first entity and field that differ (`None` if every field is equal: then the
    /// hashes differ on bits the fields do not show).
    pub difference: Option<Divergence>,
}

impl fmt::Display for Mismatch {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.difference {
            Some(d) => write!(f, "first divergence at {d}"),
            None => write!(
                f,
                "step {}: hash {:016x} instead of {:016x}, but every entity's fields are equal",
                self.step, self.got_hash, self.expected_hash
            ),
        }
    }
}

impl RunCheck {
    /// The run's configuration in one line.
    pub fn name(&self) -> String {
        if let Some(ranks) = self.ranks {
            return format!(
                "{:<9}{:<13} {ranks} ranks",
                self.executor.name(),
                self.mode.name()
            );
        }
        match self.schedule_seed {
            Some(seed) => format!(
                "{:<9}{:<13} schedule-seed {seed}",
                self.executor.name(),
                self.mode.name()
            ),
            None => format!(
                "{:<9}{:<13} {} threads",
                self.executor.name(),
                self.mode.name(),
                self.threads
            ),
        }
    }

    /// Whether the run committed the reference's hashes.
    pub fn matched(&self) -> bool {
        matches!(self.outcome, RunOutcome::Matched)
    }
}

impl fmt::Display for RunCheck {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.outcome {
            RunOutcome::Matched => {
                let steps = counted(self.steps_matched, "step matches", "steps match");
                write!(f, "ok       {}: {steps}", self.name())?;
                if let Some(c) = &self.counters {
                    let rollbacks = counted(c.total.rollbacks(), "rollback", "rollbacks");
                    write!(f, ", {rollbacks}, efficiency {:.3}", c.total.efficiency())?;
                }
                Ok(())
            }
            RunOutcome::Diverged(m) => write!(f, "DIVERGED {}: {m}", self.name()),
            RunOutcome::Failed(e) => write!(f, "DIVERGED {}: the run failed: {e}", self.name()),
        }
    }
}

/// Everything `verify` found.
#[derive(Clone, Debug)]
pub struct VerifyReport {
    /// Steps compared per run.
    pub steps: u64,
    /// The reference's committed hashes, steps 1..=N.
    pub reference_hashes: Vec<u64>,
    /// Where a second reference run first differed from the first (a model that is not
    /// reproducible), if it did.
    pub reference_repeat: Option<Mismatch>,
    /// The reference run failed (the model panicked).
    pub reference_error: Option<ExecError>,
    /// What the contract checker found, if anything.
    pub contract: Option<ContractViolation>,
    /// Every executor run, in the order they ran.
    pub runs: Vec<RunCheck>,
    /// This process is a rank other than 0 of the MPI job of the MPI runs
    /// ([`VerifyOptions::mpi_repeats`](super::VerifyOptions::mpi_repeats)): it took part in
    /// them and checked nothing. Rank 0's report is the result; this one passes.
    pub follower: bool,
}

impl VerifyReport {
    /// The reference's final hash (16 hex digits; empty if it failed at once).
    pub fn reference_hash(&self) -> String {
        self.reference_hashes
            .last()
            .map(|h| crate::hash::hex(*h))
            .unwrap_or_default()
    }

    /// Whether everything held: the reference reproducible, the contract kept, every run
    /// matched, and at least one run was checked.
    pub fn passed(&self) -> bool {
        self.follower || (self.diagnosis().is_empty() && !self.runs.is_empty())
    }

    /// The runs that did not match.
    pub fn failures(&self) -> impl Iterator<Item = &RunCheck> {
        self.runs.iter().filter(|r| !r.matched())
    }

    /// What the failures point at, most specific first (empty when everything held).
    pub fn diagnosis(&self) -> Vec<Diagnosis> {
        super::diagnosis::diagnose(self)
    }

    /// A multi-line summary: the reference, every run, the diagnosis.
    pub fn summary(&self) -> String {
        let mut s = format!("reference        hash {}\n", self.reference_hash());
        for r in &self.runs {
            s += &format!("{r}\n");
        }
        for d in self.diagnosis() {
            s += &format!("diagnosis: {d}\n");
        }
        s
    }
}
