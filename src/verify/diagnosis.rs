//! What `verify`'s failures point at.

use super::report::{Mismatch, RunOutcome, VerifyReport};
use crate::exec::error::{ContractRule, ContractViolation, ExecError};
use crate::kernel::RollbackMode;
use std::fmt;

/// A finding of `verify`, with the likely cause.
#[derive(Clone, Debug, PartialEq)]
pub enum Diagnosis {
    /// Two reference runs differ: the model's steps depend on something besides their
    /// neighbourhood (hidden state, a global counter, unseeded randomness, a hash map's
    /// iteration order).
    ReferenceNotReproducible(Mismatch),
    /// The reference run itself failed.
    ReferenceFailed(ExecError),
    /// The contract checker found a broken rule.
    Contract(ContractViolation),
    /// Only cell-mode runs diverged (world and conservative modes matched): the model's
    /// `may_affect` says `false` for a neighbour a step does read.
    OnlyCellModeDiverged {
        /// Cell-mode runs that diverged.
        runs: usize,
    },
    /// Runs diverged without a cause found in the model (a kernel bug, or a model bug the
    /// checks above cannot see).
    Diverged {
        /// Runs that diverged or failed.
        runs: usize,
        /// Runs checked.
        of: usize,
    },
    /// No executor run was checked (zero schedules and zero repeats, or no mode).
    NothingChecked,
}

impl fmt::Display for Diagnosis {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Diagnosis::ReferenceNotReproducible(m) => write!(
                f,
                "the reference is not reproducible: two reference runs differ ({m}); the \
                 model keeps hidden state or draws randomness (a static or interior-mutable \
                 counter, thread_rng, std's HashMap/HashSet iteration order): a step may read \
                 only its neighbourhood, the grid and the model's static data"
            ),
            Diagnosis::ReferenceFailed(e) => write!(f, "the reference run failed: {e}"),
            Diagnosis::Contract(v) => match v.rule {
                ContractRule::UniqueIds => write!(f, "duplicate id: {v}"),
                ContractRule::OneCellMove => write!(f, "an entity moved more than one cell: {v}"),
                _ => write!(f, "{v}"),
            },
            Diagnosis::OnlyCellModeDiverged { runs } => write!(
                f,
                "only cell mode diverged ({runs} runs; world and conservative modes matched): \
                 check may_affect — it must return true for every neighbour a step can read"
            ),
            Diagnosis::Diverged { runs, of } => write!(
                f,
                "{runs} of {of} runs diverged from the reference with no cause found in the \
                 model (see their first divergences)"
            ),
            Diagnosis::NothingChecked => {
                write!(
                    f,
                    "no executor run was checked (schedules, repeats and MPI runs are all 0)"
                )
            }
        }
    }
}

/// The diagnosis of `report`, most specific first.
pub(crate) fn diagnose(report: &VerifyReport) -> Vec<Diagnosis> {
    let mut out = Vec::new();
    if let Some(e) = &report.reference_error {
        out.push(Diagnosis::ReferenceFailed(e.clone()));
    }
    if let Some(m) = &report.reference_repeat {
        out.push(Diagnosis::ReferenceNotReproducible(m.clone()));
    }
    if let Some(v) = &report.contract {
        out.push(Diagnosis::Contract(v.clone()));
    }
    if report.runs.is_empty() {
        out.push(Diagnosis::NothingChecked);
        return out;
    }
    let failed: Vec<_> = report.runs.iter().filter(|r| !r.matched()).collect();
    if failed.is_empty() {
        return out;
    }
    let other_modes_checked = report
        .runs
        .iter()
        .any(|r| r.mode != RollbackMode::Cell && r.matched());
    let only_cell = failed.iter().all(|r| r.mode == RollbackMode::Cell)
        && other_modes_checked
        && failed
            .iter()
            .all(|r| matches!(r.outcome, RunOutcome::Diverged(_)));
    if !out.is_empty() {
        // The model's own faults above explain the divergences.
        return out;
    }
    if only_cell {
        out.push(Diagnosis::OnlyCellModeDiverged { runs: failed.len() });
    } else {
        out.push(Diagnosis::Diverged {
            runs: failed.len(),
            of: report.runs.len(),
        });
    }
    out
}
