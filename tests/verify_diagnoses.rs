//! `verify` and the contract checker catch the classic model bugs and name them: each test
//! plants one bug in a wrapper around the PHOLD-like example model (through the public
//! `CellModel` seam only) and checks the diagnosis.

use soda::models::phold::{Job, Phold, PholdEvent, PholdParams};
use soda::prelude::*;
use soda::verify::Diagnosis;
use std::collections::HashSet;
use std::sync::atomic::{AtomicU64, Ordering};

#[derive(Clone, Copy, Debug, PartialEq)]
enum Bug {
    None,
    HiddenGlobalState,
    HasherRandomness,
    TwoCellJump,
    TooSmallMayAffect,
    DuplicateId,
    PanicAtStep(Step),
    FalseAtRest,
}

static CALLS: AtomicU64 = AtomicU64::new(0);

#[derive(Clone)]
struct Planted {
    inner: Phold,
    bug: Bug,
}

impl CellModel for Planted {
    type State = Job;
    type Event = PholdEvent;

    fn id(j: &Job) -> BodyId {
        j.id
    }

    fn position(j: &Job) -> [f32; 3] {
        j.pos
    }

    fn step_cell(
        &self,
        step: Step,
        grid: &Grid,
        nb: &Neighbourhood<'_, Job>,
        out: &mut Vec<Job>,
        events: &mut Vec<Event<PholdEvent>>,
    ) {
        let first = out.len();
        self.inner.step_cell(step, grid, nb, out, events);
        let mine = &mut out[first..];
        match self.bug {
            Bug::None | Bug::TooSmallMayAffect | Bug::FalseAtRest => {}
            Bug::HiddenGlobalState => {
                let n = CALLS.fetch_add(1, Ordering::Relaxed);
                if let Some(j) = mine.first_mut() {
                    j.value ^= n;
                }
            }
            Bug::HasherRandomness => {
                let ids: HashSet<u64> = nb.iter().map(|j| j.id).collect();
                let folded = ids.iter().fold(0u64, |acc, id| acc.rotate_left(5) ^ id);
                if let Some(j) = mine.first_mut() {
                    j.value ^= folded;
                }
            }
            Bug::TwoCellJump => {
                for j in mine.iter_mut() {
                    if step == 3 && j.id % 7 == 0 && j.pos[0] + 2.0 < grid.dims[0] as f32 {
                        j.pos[0] += 2.0;
                    }
                }
            }
            Bug::DuplicateId => {
                if step == 2 {
                    if let Some(j) = mine.first().cloned() {
                        out.push(j);
                    }
                }
            }
            Bug::PanicAtStep(s) => {
                if step == s {
                    panic!("planted panic at step {step}");
                }
            }
        }
    }

    fn may_affect(&self, reader: &Job, other: &Job) -> bool {
        self.bug != Bug::TooSmallMayAffect && self.inner.may_affect(reader, other)
    }

    fn at_rest(&self, _: &Job) -> bool {
        // PHOLD mixes every job's value at every step: nothing is ever at rest.
        self.bug == Bug::FalseAtRest
    }

    fn hash_state(j: &Job, h: &mut StateHash) {
        Phold::hash_state(j, h)
    }

    fn fields(j: &Job) -> Vec<(String, String)> {
        Phold::fields(j)
    }
}

fn setup(bug: Bug) -> VerifySetup<Planted> {
    let (inner, grid, initial) = Phold::scene(PholdParams {
        dims: [6, 4, 2],
        per_cell: 3,
        remote: 0.3,
        grain: 4,
        coupling: 0.9,
        seed: 3,
    });
    VerifySetup::new(Planted { inner, bug }, grid, initial)
}

fn options() -> VerifyOptions {
    VerifyOptions {
        steps: 20,
        schedules: 4,
        repeats: 1,
        threads: 2,
        kernel: KernelConfig::new(6).window(8),
        ..VerifyOptions::default()
    }
}

#[test]
fn a_correct_model_passes_with_no_diagnosis() {
    let report = verify(&setup(Bug::None), &options());
    assert!(report.passed(), "{}", report.summary());
    assert!(report.diagnosis().is_empty());
}

#[test]
fn hidden_global_state_is_diagnosed_as_a_reference_that_is_not_reproducible() {
    let report = verify(&setup(Bug::HiddenGlobalState), &options());
    let d = report.diagnosis();
    assert!(
        matches!(d.first(), Some(Diagnosis::ReferenceNotReproducible(_))),
        "{}",
        report.summary()
    );
    assert!(d[0].to_string().contains("not reproducible"));
}

#[test]
fn std_hasher_randomness_is_diagnosed_as_a_reference_that_is_not_reproducible() {
    let report = verify(&setup(Bug::HasherRandomness), &options());
    let d = report.diagnosis();
    assert!(
        d.iter()
            .any(|d| matches!(d, Diagnosis::ReferenceNotReproducible(_))),
        "{}",
        report.summary()
    );
}

#[test]
fn a_two_cell_jump_is_named_by_the_contract_checker() {
    let report = verify(&setup(Bug::TwoCellJump), &options());
    let v = report.contract.clone().expect("the contract checker fires");
    assert_eq!((v.rule, v.step), (ContractRule::OneCellMove, 3));
    assert_eq!(v.entity % 7, 0);
    let text = report.summary();
    assert!(
        text.contains("an entity moved more than one cell"),
        "{text}"
    );
}

#[test]
fn a_false_at_rest_promise_is_named_by_the_contract_checker() {
    let report = verify(&setup(Bug::FalseAtRest), &options());
    let v = report.contract.clone().expect("the contract checker fires");
    assert_eq!((v.rule, v.step), (ContractRule::AtRest, 0));
    assert!(
        report.summary().contains("at_rest promised"),
        "{}",
        report.summary()
    );
}

#[test]
fn a_duplicated_id_is_named_by_the_contract_checker() {
    let report = verify(&setup(Bug::DuplicateId), &options());
    let v = report.contract.clone().expect("the contract checker fires");
    assert_eq!((v.rule, v.step), (ContractRule::UniqueIds, 2));
    assert!(
        report.summary().contains("duplicate id"),
        "{}",
        report.summary()
    );
}

#[test]
fn a_too_small_may_affect_is_diagnosed_as_only_cell_mode_diverging() {
    let options = VerifyOptions {
        schedules: 10,
        repeats: 0,
        ..options()
    };
    let report = verify(&setup(Bug::TooSmallMayAffect), &options);
    assert!(report.reference_repeat.is_none() && report.contract.is_none());
    assert!(
        matches!(
            report.diagnosis().first(),
            Some(Diagnosis::OnlyCellModeDiverged { .. })
        ),
        "{}",
        report.summary()
    );
    let diverged = report.failures().next().expect("a cell-mode run diverged");
    assert_eq!(diverged.mode, RollbackMode::Cell);
    assert!(
        diverged.replay.is_some(),
        "a virtual run names its replay schedule"
    );
    assert!(diverged.to_string().contains("field"), "{diverged}");
}

#[test]
fn a_model_panic_is_an_error_naming_where_on_every_executor() {
    let s = setup(Bug::PanicAtStep(4));
    let kernel = KernelConfig::new(4).window(8);
    for options in [
        RunOptions::reference(),
        RunOptions::virtual_exec(kernel.clone()),
        RunOptions::threaded(kernel, 2),
    ] {
        let err = Runner::new(s.model.clone(), s.grid.clone(), s.initial.clone())
            .options(options.clone())
            .run_quiet(10)
            .unwrap_err();
        let text = err.to_string();
        assert!(text.contains("planted panic at step 4"), "{text}");
        match err {
            ExecError::CellPanicked { step, .. } => assert_eq!(step, 4),
            ExecError::WorldPanicked { step, .. } => assert_eq!(step, 4),
            other => panic!("{:?}: unexpected {other}", options.executor),
        }
    }
}

#[test]
fn zero_schedules_and_repeats_do_not_pass() {
    let options = VerifyOptions {
        schedules: 0,
        repeats: 0,
        ..options()
    };
    let report = verify(&setup(Bug::None), &options);
    assert!(!report.passed());
    assert_eq!(report.diagnosis(), vec![Diagnosis::NothingChecked]);
}

/// Without the `mpi` feature an MPI run cannot start: each one asked for fails saying how to
/// build it, and the report does not pass (never a silent pass without the runs).
#[cfg(not(feature = "mpi"))]
#[test]
fn mpi_runs_without_the_mpi_feature_fail_saying_to_rebuild_with_it() {
    use soda::verify::RunOutcome;
    let options = VerifyOptions {
        schedules: 1,
        repeats: 0,
        mpi_repeats: 2,
        ..options()
    };
    let report = verify(&setup(Bug::None), &options);
    assert!(!report.passed(), "{}", report.summary());
    let mpi: Vec<_> = report
        .runs
        .iter()
        .filter(|r| r.executor == ExecutorKind::Mpi)
        .collect();
    assert_eq!(mpi.len(), 2 * options.modes.len());
    for r in mpi {
        match &r.outcome {
            RunOutcome::Failed(e) => assert!(e.to_string().contains("--features mpi"), "{e}"),
            other => panic!("an MPI run without MPI ended as {other:?}"),
        }
    }
}
