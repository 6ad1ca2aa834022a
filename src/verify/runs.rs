//! The runs `verify` makes and how each is compared with the reference.

use super::report::{Mismatch, RunCheck, RunOutcome, VerifyReport};
use crate::divergence::first_difference;
use crate::exec::error::ExecError;
use crate::exec::virtual_exec::ScheduleSpec;
use crate::frame::StatesWanted;
use crate::grid::Grid;
use crate::kernel::{GhostPolicy, Input, KernelConfig, PartitionKind, RollbackMode};
use crate::model::{CellModel, Step};
use crate::sim::{ExecutorKind, RunOptions, Runner};
use std::sync::Arc;

/// What `verify` runs: a model, its grid, its initial states and the inputs scheduled
/// before the run. The model is cloned for every run.
#[derive(Clone)]
pub struct VerifySetup<M: CellModel> {
    /// The model.
    pub model: M,
    /// The grid.
    pub grid: Grid,
    /// The states at step 0.
    pub initial: Vec<M::State>,
    /// Inputs scheduled before the run (step, input).
    pub inputs: Vec<(Step, Input<M::State>)>,
}

impl<M: CellModel + Clone + 'static> VerifySetup<M> {
    /// A setup without inputs.
    pub fn new(model: M, grid: Grid, initial: Vec<M::State>) -> Self {
        VerifySetup {
            model,
            grid,
            initial,
            inputs: Vec::new(),
        }
    }

    /// The same setup with inputs.
    pub fn with_inputs(mut self, inputs: Vec<(Step, Input<M::State>)>) -> Self {
        self.inputs = inputs;
        self
    }

    fn runner(&self) -> Runner<M> {
        Runner::new(self.model.clone(), self.grid.clone(), self.initial.clone())
            .inputs(self.inputs.iter().cloned())
    }
}

/// Which runs `verify` makes.
#[derive(Clone, Debug)]
pub struct VerifyOptions {
    /// Committed steps compared per run.
    pub steps: u64,
    /// The kernel configuration of every run (worlds, window, partition, ghosts, balance…);
    /// its mode and schedule are set per run.
    pub kernel: KernelConfig,
    /// Rollback modes to check.
    pub modes: Vec<RollbackMode>,
    /// The first virtual-executor schedule seed.
    pub first_schedule: u64,
    /// Virtual-executor schedule seeds per mode (seeds `first_schedule..` onwards).
    pub schedules: u64,
    /// Threaded runs per mode.
    pub repeats: u64,
    /// Threads of the threaded runs.
    pub threads: usize,
    /// MPI runs per mode, on the MPI job this process belongs to (`mpirun -np R`, cargo
    /// feature `mpi`; SPEC.md §14): every rank calls [`verify`] with the same options, every
    /// rank takes part in these runs, rank 0 alone compares them with the reference and makes
    /// the other checks. 0: none, and MPI is not touched.
    pub mpi_repeats: u64,
    /// Run the contract checker over the reference (about the cost of one more reference
    /// run).
    pub check_contract: bool,
}

impl Default for VerifyOptions {
    fn default() -> Self {
        VerifyOptions {
            steps: 60,
            kernel: KernelConfig::new(8)
                .window(16)
                .partition(PartitionKind::Blocks)
                .ghosts(GhostPolicy::Delta),
            modes: vec![
                RollbackMode::Cell,
                RollbackMode::World,
                RollbackMode::Conservative,
            ],
            first_schedule: 0,
            schedules: 8,
            repeats: 3,
            threads: std::thread::available_parallelism().map_or(2, |n| n.get()),
            mpi_repeats: 0,
            check_contract: true,
        }
    }
}

/// Runs every check of `options` on `setup` ([module docs](super)).
pub fn verify<M: CellModel + Clone + 'static>(
    setup: &VerifySetup<M>,
    options: &VerifyOptions,
) -> VerifyReport {
    verify_with_progress(setup, options, |_| {})
}

/// [`verify`], handing every run's check to `progress` as soon as it is done.
pub fn verify_with_progress<M: CellModel + Clone + 'static>(
    setup: &VerifySetup<M>,
    options: &VerifyOptions,
    mut progress: impl FnMut(&RunCheck),
) -> VerifyReport {
    let steps = options.steps;
    let job = match MpiJob::join(options.mpi_repeats) {
        Ok(job) => job,
        Err(e) => {
            // MPI could not start: every MPI run fails with the reason.
            let mut report = verify_here(setup, options, None, &mut progress);
            for &mode in &options.modes {
                for _ in 0..options.mpi_repeats {
                    let check = failed_mpi(mode, e.clone());
                    progress(&check);
                    report.runs.push(check);
                }
            }
            return report;
        }
    };
    if let Some(job) = job.as_ref().filter(|j| !j.root) {
        // A follower: the MPI runs, in rank 0's order, and nothing else.
        for &mode in &options.modes {
            for _ in 0..options.mpi_repeats {
                let run = RunOptions::mpi(options.kernel.clone().mode(mode));
                // Rank 0 reports how the run went, errors included.
                let _ = setup.runner().options(run).run_quiet(steps);
            }
        }
        let _ = job;
        return VerifyReport {
            steps,
            reference_hashes: Vec::new(),
            reference_repeat: None,
            reference_error: None,
            contract: None,
            runs: Vec::new(),
            follower: true,
        };
    }
    verify_here(setup, options, job.as_ref(), &mut progress)
}

/// Every check made in this process: the reference twice, the MPI runs (rank 0 of `job`),
/// the contract, the virtual and the threaded runs.
fn verify_here<M: CellModel + Clone + 'static>(
    setup: &VerifySetup<M>,
    options: &VerifyOptions,
    job: Option<&MpiJob>,
    progress: &mut impl FnMut(&RunCheck),
) -> VerifyReport {
    let steps = options.steps;
    let mut expected = Vec::with_capacity(steps as usize);
    let reference = setup.runner().run(steps, |f, _, _| expected.push(f.hash));
    let mut report = VerifyReport {
        steps,
        reference_hashes: expected,
        reference_repeat: None,
        reference_error: reference.err(),
        contract: None,
        runs: Vec::new(),
        follower: false,
    };
    // A second reference run must commit the same hashes.
    let expected = Arc::new(report.reference_hashes.clone());
    report.reference_repeat = compare_run(setup, &RunOptions::reference(), steps, &expected)
        .1
        .and_then(|o| match o {
            RunOutcome::Diverged(m) => Some(m),
            _ => None,
        });
    if let Some(job) = job {
        // First, so that the other ranks are done soonest.
        for &mode in &options.modes {
            for _ in 0..options.mpi_repeats {
                let run = RunOptions::mpi(options.kernel.clone().mode(mode));
                let mut check = check_run(setup, &run, mode, None, steps, &expected);
                check.ranks = Some(job.ranks);
                progress(&check);
                report.runs.push(check);
            }
        }
    }
    if options.check_contract {
        let checked = setup.runner().check_contract(true).run_quiet(steps);
        if let Err(ExecError::Contract(v)) = checked {
            report.contract = Some(v);
        }
    }
    for &mode in &options.modes {
        let kernel = options.kernel.clone().mode(mode);
        let first = options.first_schedule;
        for seed in first..first.saturating_add(options.schedules) {
            let run = RunOptions::virtual_exec(kernel.clone())
                .schedule(ScheduleSpec::Seeded(seed))
                .record_schedule(true);
            let check = check_run(setup, &run, mode, Some(seed), steps, &expected);
            progress(&check);
            report.runs.push(check);
        }
        for _ in 0..options.repeats {
            let run = RunOptions::threaded(kernel.clone(), options.threads.max(1));
            let check = check_run(setup, &run, mode, None, steps, &expected);
            progress(&check);
            report.runs.push(check);
        }
    }
    report
}

/// This process's place in the MPI job of the MPI runs, held for all of them (MPI starts
/// once per process).
struct MpiJob {
    /// Ranks of the job.
    ranks: usize,
    /// Whether this is rank 0, which compares.
    root: bool,
    #[cfg(feature = "mpi")]
    _session: crate::exec::mpi::Session,
}

impl MpiJob {
    /// Joins the MPI job if there are MPI runs (`None` if not).
    fn join(repeats: u64) -> Result<Option<MpiJob>, ExecError> {
        if repeats == 0 {
            return Ok(None);
        }
        #[cfg(feature = "mpi")]
        {
            let session = crate::exec::mpi::Session::init()?;
            Ok(Some(MpiJob {
                ranks: session.size(),
                root: session.is_root(),
                _session: session,
            }))
        }
        #[cfg(not(feature = "mpi"))]
        Err(crate::exec::error::MpiError::NotBuilt.into())
    }
}

/// An MPI run that could not start.
fn failed_mpi(mode: RollbackMode, e: ExecError) -> RunCheck {
    RunCheck {
        executor: ExecutorKind::Mpi,
        mode,
        schedule_seed: None,
        threads: 1,
        ranks: None,
        counters: None,
        replay: None,
        steps_matched: 0,
        outcome: RunOutcome::Failed(e),
    }
}

/// One executor run compared with the reference.
fn check_run<M: CellModel + Clone + 'static>(
    setup: &VerifySetup<M>,
    options: &RunOptions,
    mode: RollbackMode,
    seed: Option<u64>,
    steps: u64,
    expected: &Arc<Vec<u64>>,
) -> RunCheck {
    let (report, outcome, matched) = {
        let (report, outcome) = compare_run(setup, options, steps, expected);
        let matched = match &report {
            Ok(r) => r.steps,
            Err(_) => 0,
        };
        (report, outcome, matched)
    };
    let kernel = report.as_ref().ok().and_then(|r| r.kernel.clone());
    let (steps_matched, outcome) = match (outcome, report) {
        (Some(o @ RunOutcome::Diverged(_)), _) => {
            let at = match &o {
                RunOutcome::Diverged(m) => m.step - 1,
                _ => 0,
            };
            (at, o)
        }
        (_, Err(e)) => (0, RunOutcome::Failed(e)),
        _ => (matched, RunOutcome::Matched),
    };
    RunCheck {
        executor: options.executor,
        mode,
        schedule_seed: seed,
        threads: if options.executor == ExecutorKind::Threaded {
            options.threads
        } else {
            1
        },
        ranks: None,
        counters: kernel.as_ref().map(|k| k.counters.clone()),
        replay: kernel.and_then(|k| k.schedule),
        steps_matched,
        outcome,
    }
}

/// Runs `options` and returns its report and, at the first committed hash that differs
/// from `expected`, the mismatch with the first differing entity.
fn compare_run<M: CellModel + Clone + 'static>(
    setup: &VerifySetup<M>,
    options: &RunOptions,
    steps: u64,
    expected: &Arc<Vec<u64>>,
) -> (
    Result<crate::sim::ModelReport, ExecError>,
    Option<RunOutcome>,
) {
    let wanted = StatesWanted {
        unexpected: Some(expected.clone()),
        ..StatesWanted::none()
    };
    let mut first_bad: Option<(Step, u64, Vec<M::State>)> = None;
    let report =
        setup
            .runner()
            .options(options.clone())
            .states(wanted)
            .run(steps, |f, states, control| {
                let want = expected.get(f.step as usize - 1);
                if first_bad.is_none() && want != Some(&f.hash) {
                    let got = states.map(|s| s.iter().map(|b| (*b).clone()).collect());
                    first_bad = Some((f.step, f.hash, got.unwrap_or_default()));
                    control.stop();
                }
            });
    let outcome = first_bad.map(|(step, got_hash, got)| {
        let expected_hash = expected.get(step as usize - 1).copied().unwrap_or(0);
        RunOutcome::Diverged(Mismatch {
            step,
            expected_hash,
            got_hash,
            difference: locate(setup, step, &got),
        })
    });
    (report, outcome)
}

/// The first difference between the reference's state at `step` and `got`.
fn locate<M: CellModel + Clone + 'static>(
    setup: &VerifySetup<M>,
    step: Step,
    got: &[M::State],
) -> Option<crate::divergence::Divergence> {
    let mut reference: Vec<M::State> = Vec::new();
    setup
        .runner()
        .states(StatesWanted::at(step))
        .run(step, |f, s, _| {
            if f.step == step {
                reference = s
                    .map(|s| s.iter().map(|b| (*b).clone()).collect())
                    .unwrap_or_default();
            }
        })
        .ok()?;
    let e: Vec<&M::State> = reference.iter().collect();
    let g: Vec<&M::State> = got.iter().collect();
    first_difference::<M>(step, &setup.grid, &e, &g)
}
