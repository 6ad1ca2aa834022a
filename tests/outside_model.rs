//! The framework as an outside crate sees it: only the public API (the prelude and the
//! example models), no crate internals. An example model runs bit-identically on all three
//! executors, with scripted and injected inputs, and passes `verify`.

use soda::models::epidemic::{Agent, Epidemic, EpidemicEvent, Health};
use soda::models::phold::{Phold, PholdParams};
use soda::prelude::*;

fn epidemic() -> (Epidemic, Grid, Vec<Agent>) {
    Epidemic {
        birth_rate: 0.02,
        death_rate: 0.01,
        ..Epidemic::default()
    }
    .scene(300, 20, [6, 3, 6], 11)
}

fn options() -> Vec<RunOptions> {
    let kernel = KernelConfig::new(6).window(8);
    vec![
        RunOptions::reference(),
        RunOptions::virtual_exec(kernel.clone()),
        RunOptions::virtual_exec(kernel.clone().mode(RollbackMode::World)),
        RunOptions::virtual_exec(kernel.clone().mode(RollbackMode::Conservative)),
        RunOptions::threaded(kernel.clone(), 2),
        RunOptions::threaded(kernel.mode(RollbackMode::Conservative), 3),
    ]
}

/// Runs `options` and returns every committed hash.
fn hashes(options: &RunOptions, inputs: Vec<(Step, Input<Agent>)>, steps: u64) -> Vec<u64> {
    let (model, grid, initial) = epidemic();
    let mut hashes = Vec::new();
    Runner::new(model, grid, initial)
        .options(options.clone())
        .inputs(inputs)
        .run(steps, |f, _, _| hashes.push(f.hash))
        .expect("the run succeeds");
    hashes
}

#[test]
fn epidemic_commits_the_same_hashes_on_every_executor() {
    let expected = hashes(&RunOptions::reference(), Vec::new(), 60);
    for o in options() {
        assert_eq!(hashes(&o, Vec::new(), 60), expected, "{:?}", o.executor);
    }
}

#[test]
fn epidemic_births_deaths_and_infections_are_counted_by_name() {
    let (model, grid, initial) = epidemic();
    let report = Runner::new(model, grid, initial).run_quiet(80).unwrap();
    for name in ["infected", "born", "died"] {
        assert!(
            report.events.get(name).copied().unwrap_or(0) > 0,
            "{name}: {:?}",
            report.events
        );
    }
    assert_ne!(
        report.entities, 300,
        "births and deaths change the population"
    );
}

fn spawned(id: u64) -> Agent {
    Agent {
        id,
        pos: [2.5, 1.5, 2.5],
        vel: [0.1, 0.0, 0.0],
        health: Health::Infected,
        since: 0,
        next_id: id,
        end_id: id,
    }
}

#[test]
fn scripted_inputs_commit_the_same_hashes_on_every_executor() {
    let (_, _, initial) = epidemic();
    let mut replaced = initial[7].clone();
    replaced.vel = [0.0, 0.2, 0.0];
    let script = vec![
        (5, Input::Spawn(spawned(u64::MAX - 1))),
        (9, Input::Remove(initial[3].id)),
        (9, Input::Replace(replaced)),
        (30, Input::Spawn(spawned(u64::MAX - 2))),
    ];
    let expected = hashes(&RunOptions::reference(), script.clone(), 40);
    assert_ne!(expected, hashes(&RunOptions::reference(), Vec::new(), 40));
    for o in options() {
        assert_eq!(hashes(&o, script.clone(), 40), expected, "{:?}", o.executor);
    }
}

#[test]
fn inputs_injected_during_the_run_equal_the_same_inputs_scripted() {
    for o in options() {
        let (model, grid, initial) = epidemic();
        let mut got = Vec::new();
        // Step 25, or the earliest step still open when the sink sees step 10 (how far the
        // worlds ran ahead of the sink is timing, not part of the contract).
        let mut stamped = None;
        Runner::new(model, grid, initial)
            .options(o.clone())
            .run(60, |f, _, control| {
                got.push(f.hash);
                if f.step == 10 {
                    // The earliest open step is a snapshot (and in conservative mode a
                    // lower bound): a refused step names the one to retry at.
                    let mut step = control.earliest_input_step().max(25);
                    loop {
                        assert!(step < 60, "the run is still open at step 10");
                        match control.input(step, Input::Spawn(spawned(u64::MAX - 5))) {
                            Ok(()) => break,
                            Err(InputError::TooLate { earliest, .. }) => {
                                assert!(earliest > step, "a refusal names a later step");
                                step = earliest;
                            }
                            Err(e) => panic!("{e}"),
                        }
                    }
                    stamped = Some(step);
                }
            })
            .unwrap();
        let step = stamped.expect("the sink saw step 10");
        let script = vec![(step, Input::Spawn(spawned(u64::MAX - 5)))];
        let expected = hashes(&RunOptions::reference(), script.clone(), 60);
        assert_ne!(expected, hashes(&RunOptions::reference(), Vec::new(), 60));
        assert_eq!(got, expected, "{:?}, input at step {step}", o.executor);
    }
}

#[test]
fn inputs_for_committed_steps_or_outside_the_grid_are_refused() {
    let (model, grid, initial) = epidemic();
    let err = Runner::new(model.clone(), grid.clone(), initial.clone())
        .input(0, Input::Remove(1))
        .run_quiet(3)
        .unwrap_err();
    assert!(
        matches!(err, ExecError::Input(InputError::StepZero)),
        "{err}"
    );
    let mut outside = spawned(u64::MAX - 9);
    outside.pos = [100.0, 0.0, 0.0];
    for o in options() {
        let err = Runner::new(model.clone(), grid.clone(), initial.clone())
            .options(o.clone())
            .input(4, Input::Spawn(outside.clone()))
            .run_quiet(3)
            .unwrap_err();
        assert!(
            matches!(err, ExecError::Input(InputError::OutsideGrid { .. })),
            "{err}"
        );
        let mut refused = None;
        Runner::new(model.clone(), grid.clone(), initial.clone())
            .options(o.clone())
            .run(10, |f, _, control| {
                if f.step == 6 {
                    refused = Some(control.input(6, Input::Remove(1)));
                }
            })
            .unwrap();
        assert!(
            matches!(refused, Some(Err(InputError::TooLate { step: 6, .. }))),
            "{:?}: {refused:?}",
            o.executor
        );
    }
}

#[test]
fn a_sink_can_stop_the_run_on_every_executor() {
    for o in options() {
        let (model, grid, initial) = epidemic();
        let mut last = 0;
        let report = Runner::new(model, grid, initial)
            .options(o.clone())
            .run(50, |f, _, control| {
                last = f.step;
                if f.step == 12 {
                    control.stop();
                }
            })
            .unwrap();
        assert_eq!(
            (last, report.steps, report.stopped_at),
            (12, 12, Some(12)),
            "{:?}",
            o.executor
        );
    }
}

#[test]
fn epidemic_and_phold_pass_verify() {
    let options = VerifyOptions {
        steps: 25,
        schedules: 3,
        repeats: 2,
        threads: 2,
        kernel: KernelConfig::new(5).window(8),
        ..VerifyOptions::default()
    };
    let (model, grid, initial) = epidemic();
    let report = verify(&VerifySetup::new(model, grid, initial), &options);
    assert!(report.passed(), "{}", report.summary());
    assert_eq!(report.runs.len(), 3 * (3 + 2));
    let (model, grid, initial) = Phold::scene(PholdParams {
        dims: [6, 4, 2],
        per_cell: 3,
        remote: 0.3,
        ..PholdParams::default()
    });
    let report = verify(&VerifySetup::new(model, grid, initial), &options);
    assert!(report.passed(), "{}", report.summary());
}

#[test]
fn the_event_type_is_the_models_own() {
    let (model, grid, initial) = epidemic();
    let mut infections = 0;
    Runner::new(model, grid, initial)
        .run(30, |f, _, _| {
            infections += f
                .events
                .iter()
                .filter(|e| e.kind == EpidemicEvent::Infected)
                .count();
        })
        .unwrap();
    assert!(infections > 0);
}

#[test]
fn a_run_resumed_from_saved_states_commits_the_uninterrupted_runs_bits_on_every_executor() {
    let script = vec![(12, Input::Spawn(spawned(u64::MAX - 3)))];
    let late = vec![(30, Input::Spawn(spawned(u64::MAX - 4)))];
    let all: Vec<(Step, Input<Agent>)> = script.iter().chain(&late).cloned().collect();
    let whole = hashes(&RunOptions::reference(), all, 45);
    // The committed states of step 20 of the uninterrupted run, as a checkpoint would hold.
    let (model, grid, initial) = epidemic();
    let mut saved = Vec::new();
    Runner::new(model, grid, initial)
        .inputs(script)
        .states(StatesWanted::at(20))
        .run(20, |f, states, _| {
            if f.step == 20 {
                saved = states.unwrap().iter().map(|a| (*a).clone()).collect();
            }
        })
        .unwrap();
    for o in options() {
        let (model, grid, _) = epidemic();
        let mut got = Vec::new();
        Runner::new(model, grid, saved.clone())
            .options(o.clone())
            .start_at(20)
            .inputs(late.clone())
            .run(25, |f, _, _| got.push((f.step, f.hash)))
            .unwrap();
        let expected: Vec<(u64, u64)> = (21..=45).zip(whole[20..].iter().copied()).collect();
        assert_eq!(got, expected, "{:?}", o.executor);
    }
}
