//! External inputs (spawn, remove, replace, edit) at a step: committed states equal a reference
//! that applies the same inputs to its state at that step, whatever the mode, partition and
//! schedule — scripted before the run, and injected during the run (then they arrive as
//! stragglers in the optimistic modes).
//!
//! The reference counterpart (restarting a `ReferenceRun` from the edited state) is built
//! here because `ReferenceRun` has no input API; the synthetic model uses the step number only
//! for event labels, so hashes and body counts are compared, not events.

use soda::exec::virtual_exec::{VirtualOptions, VirtualRun};
use soda::kernel::synthetic::{Particle, Particles};
use soda::kernel::{Edit, Input, KernelConfig, PartitionKind, RollbackMode};
use soda::prelude::{ExecError, InputError, RunOptions, Runner};
use soda::{Grid, ReferenceRun};

/// At one step all edits apply first (each to the state its entity has), then all removals,
/// then all additions (the kernel's rule).
fn apply(bodies: &mut Vec<Particle>, inputs: &[&Input<Particle>]) {
    for i in inputs {
        if let Input::Edit(id, edit) = i {
            if let Some(b) = bodies.iter_mut().find(|b| b.id == *id) {
                *b = edit.apply(b);
            }
        }
    }
    for i in inputs {
        match i {
            Input::Remove(id) => bodies.retain(|b| b.id != *id),
            Input::Replace(s) => bodies.retain(|b| b.id != s.id),
            Input::Spawn(_) | Input::Edit(..) => {}
        }
    }
    for i in inputs {
        match i {
            Input::Spawn(s) | Input::Replace(s) => bodies.push(s.clone()),
            Input::Remove(_) | Input::Edit(..) => {}
        }
    }
}

/// An edit that turns a particle around and slows it (its position, hence its cell, kept).
fn reverse() -> Edit<Particle> {
    Edit::new(|p: &Particle| Particle {
        vel: [-0.5 * p.vel[0], -0.5 * p.vel[1], p.vel[2] + 0.05],
        ..p.clone()
    })
}

fn reference_with_inputs(
    m: &Particles,
    g: &Grid,
    init: &[Particle],
    inputs: &[(u64, Input<Particle>)],
    steps: u64,
) -> Vec<(u64, usize)> {
    let (mut r, _) = ReferenceRun::new(m.clone(), g.clone(), init.to_vec());
    let mut out = Vec::new();
    for t in 1..=steps {
        let f = r.advance();
        let here: Vec<&Input<Particle>> = inputs
            .iter()
            .filter(|(s, _)| *s == t)
            .map(|(_, i)| i)
            .collect();
        if here.is_empty() {
            out.push((f.hash, f.bodies));
        } else {
            let mut bodies: Vec<Particle> = r
                .state()
                .sorted::<Particles>()
                .into_iter()
                .cloned()
                .collect();
            apply(&mut bodies, &here);
            r = ReferenceRun::new(m.clone(), g.clone(), bodies).0;
            out.push((r.state().hash::<Particles>(), r.state().len()));
        }
    }
    out
}

fn p(id: u64, pos: [f32; 3], vel: [f32; 3]) -> Particle {
    Particle { id, pos, vel }
}

fn script() -> Vec<(u64, Input<Particle>)> {
    vec![
        (3, Input::Spawn(p(1000, [1.5, 1.5, 1.5], [0.1, 0.0, 0.0]))),
        (3, Input::Spawn(p(1001, [3.2, 0.4, 1.1], [0.0, 0.2, 0.0]))),
        (5, Input::Edit(2, reverse())),
        (6, Input::Remove(4)),
        (6, Input::Edit(4, reverse())),
        (9, Input::Replace(p(7, [2.5, 1.0, 0.5], [-0.2, 0.1, 0.0]))),
        (9, Input::Edit(9, reverse())),
        (11, Input::Edit(1000, reverse())),
        (11, Input::Edit(9, reverse())),
        (14, Input::Remove(1000)),
        (17, Input::Replace(p(11, [0.5, 0.5, 1.5], [0.25, 0.0, 0.0]))),
    ]
}

fn modes() -> [RollbackMode; 3] {
    [
        RollbackMode::Cell,
        RollbackMode::World,
        RollbackMode::Conservative,
    ]
}

#[test]
fn scripted_inputs_commit_like_the_reference_applying_them() {
    let (m, g, b) = Particles::scene(40, [4, 2, 2], false, 21);
    let inputs = script();
    let exp = reference_with_inputs(&m, &g, &b, &inputs, 25);
    for mode in modes() {
        for seed in 0..12 {
            let cfg = KernelConfig::new(2 + seed as usize % 6)
                .mode(mode)
                .window(1 + seed % 7)
                .partition(if seed % 2 == 0 {
                    PartitionKind::Random
                } else {
                    PartitionKind::Blocks
                })
                .partition_seed(seed);
            let options = VirtualOptions::seeded(seed).compute_ahead(seed % 2 == 1);
            let (mut run, _) = VirtualRun::new(m.clone(), g.clone(), b.clone(), &cfg, &options);
            for (t, i) in &inputs {
                run.add_input(*t, i.clone());
            }
            let got: Vec<(u64, usize)> = run.run(25).iter().map(|f| (f.hash, f.bodies)).collect();
            assert_eq!(got, exp, "{mode:?} seed {seed}\n{}", run.schedule_string());
        }
    }
}

#[test]
fn inputs_injected_during_the_run_are_stragglers_that_roll_back_and_commit_correctly() {
    let (m, g, b) = Particles::scene(40, [4, 2, 2], false, 22);
    let mut rolled_back = 0;
    for mode in modes() {
        for seed in 0..10 {
            let cfg = KernelConfig::new(4)
                .mode(mode)
                .window(8)
                .partition(PartitionKind::Random)
                .partition_seed(seed);
            let options = VirtualOptions::seeded(seed).compute_ahead(seed % 2 == 1);
            let (mut run, _) = VirtualRun::new(m.clone(), g.clone(), b.clone(), &cfg, &options);
            run.set_horizon(30);
            let mut got: Vec<(u64, usize)> =
                run.run(10).iter().map(|f| (f.hash, f.bodies)).collect();
            let before = run.counters().total.rollbacks();
            let at = if mode == RollbackMode::Conservative {
                run.gvt() + 8
            } else {
                run.gvt()
            };
            let inputs = vec![
                (at, Input::Spawn(p(500, [2.5, 1.5, 0.5], [0.0, -0.1, 0.0]))),
                (at + 1, Input::Edit(6, reverse())),
                (at + 2, Input::Remove(3)),
            ];
            for (t, i) in &inputs {
                run.add_input(*t, i.clone());
            }
            got.extend(run.run(20).iter().map(|f| (f.hash, f.bodies)));
            let exp = reference_with_inputs(&m, &g, &b, &inputs, 30);
            let first = got.iter().zip(&exp).position(|(a, b)| a != b);
            assert_eq!(
                got,
                exp,
                "{mode:?} seed {seed}: input at {at}, first divergent step {:?}",
                first.map(|k| k + 1)
            );
            let c = run.counters().total;
            if mode != RollbackMode::Conservative {
                rolled_back += c.rollbacks() - before;
            } else {
                assert_eq!(c.rollbacks(), 0);
            }
        }
    }
    assert!(rolled_back > 0, "late inputs caused rollbacks");
}

/// Edits (functions of the entity's state at their step) commit the same bits on every
/// executor, scripted before the run.
#[test]
fn edits_commit_the_same_bits_on_every_executor() {
    let (m, g, b) = Particles::scene(60, [4, 2, 2], false, 31);
    let inputs: Vec<(u64, Input<Particle>)> = (1..12)
        .map(|k| (2 * k, Input::Edit((5 * k) % 60, reverse())))
        .collect();
    let run = |options: RunOptions| {
        Runner::new(m.clone(), g.clone(), b.clone())
            .options(options)
            .inputs(inputs.clone())
            .run_quiet(30)
            .unwrap()
            .hash
    };
    let reference = run(RunOptions::reference());
    let unedited = Runner::new(m.clone(), g.clone(), b.clone())
        .run_quiet(30)
        .unwrap()
        .hash;
    assert_ne!(reference, unedited, "the edits changed the run");
    for mode in modes() {
        let cfg = KernelConfig::new(3).mode(mode).window(6);
        assert_eq!(
            run(RunOptions::virtual_exec(cfg.clone())),
            reference,
            "{mode:?}"
        );
        assert_eq!(run(RunOptions::threaded(cfg, 2)), reference, "{mode:?}");
    }
}

/// An edit that moves its entity to another cell is refused: an input error on the
/// reference, a world's failure on the Time Warp executors — never a silently misplaced
/// entity.
#[test]
fn an_edit_that_moves_its_entity_out_of_its_cell_is_an_error() {
    let (m, g, b) = Particles::scene(30, [4, 2, 2], false, 32);
    let id = b[0].id;
    let teleport = Edit::new(|p: &Particle| Particle {
        pos: [p.pos[0] + 2.0, p.pos[1], p.pos[2]],
        ..p.clone()
    });
    let run = |options: RunOptions| {
        Runner::new(m.clone(), g.clone(), b.clone())
            .options(options)
            .input(1, Input::Edit(id, teleport.clone()))
            .run_quiet(5)
    };
    match run(RunOptions::reference()) {
        Err(ExecError::Input(InputError::EditLeftCell { step: 1, id: got })) => assert_eq!(got, id),
        other => panic!("expected EditLeftCell, got {other:?}"),
    }
    for options in [
        RunOptions::virtual_exec(KernelConfig::new(2)),
        RunOptions::threaded(KernelConfig::new(2), 2),
    ] {
        let err = run(options).expect_err("an edit out of its cell is an error");
        assert!(err.to_string().contains("out of its home cell"), "{err}");
    }
}
