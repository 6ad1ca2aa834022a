//! Cells at rest are not computed (`CellModel::at_rest`, SPEC.md §4.1 rule 7, §8): the
//! reference keeps the state of a cell whose whole neighbourhood is at rest and the hash of a
//! step in which no cell changed. These tests pin that this changes no committed bit: the
//! frames equal those of a reference that computes every cell (the contract checker's run)
//! and those of the Time Warp executors, on an asleep pile and on one woken by a new body.

use soda::kernel::{Input, KernelConfig, PartitionKind, RollbackMode};
use soda::math::{Quat, Vec3};
use soda::physics::{Body, Material, RigidBodyModel, Shape};
use soda::scene::builtin::builtin;
use soda::sim::{RunOptions, Runner};
use soda::{EventKind, Frame, ReferenceRun, Scene, Step};

fn pile() -> Scene {
    builtin("falling-cubes", Some(27), 7).expect("falling-cubes builds")
}

fn all_at_rest(run: &ReferenceRun<RigidBodyModel>) -> bool {
    let model = run.model();
    run.state()
        .sorted::<RigidBodyModel>()
        .iter()
        .all(|b| soda::CellModel::at_rest(model, *b))
}

/// A cube dropped onto the pile's top at `step` (the pile is asleep by then).
fn dropped_cube() -> Input<Body> {
    let cube = Body::new(
        1000,
        Shape::Cuboid {
            half_extents: [0.5; 3],
        },
        Material::default(),
        Vec3::new(0.3, 6.0, 0.2),
        Quat::identity(),
    );
    Input::Spawn(cube)
}

const DROP: Step = 130;
const STEPS: u64 = 260;

#[test]
fn an_all_asleep_step_computes_no_cell_and_commits_the_hash_of_computing_every_cell() {
    let scene = pile();
    let (mut fast, _) = ReferenceRun::new(scene.model(), scene.grid(), scene.initial_bodies());
    let (mut whole, _) = ReferenceRun::new(scene.model(), scene.grid(), scene.initial_bodies());
    // The contract checker computes every occupied cell, at rest or not.
    whole.check_contract(true).unwrap();
    fast.record_costs(true);
    let mut asleep_steps = 0;
    for _ in 0..150 {
        let at_rest = all_at_rest(&fast);
        let (f, w) = (fast.advance(), whole.advance());
        assert_eq!(f, w, "step {}", f.step);
        let computed = fast.take_costs().len();
        if at_rest {
            asleep_steps += 1;
            assert_eq!(
                computed, 0,
                "step {}: an all-asleep step computed cells",
                f.step
            );
        } else {
            assert!(
                computed > 0,
                "step {}: nothing computed in an awake pile",
                f.step
            );
        }
    }
    assert!(
        asleep_steps >= 30,
        "only {asleep_steps} all-asleep steps were covered"
    );
    assert_eq!(fast.state(), whole.state());
}

#[test]
fn a_cube_dropped_on_an_asleep_pile_commits_the_same_frames_with_and_without_skipping_cells() {
    let scene = pile();
    let (mut fast, _) = ReferenceRun::new(scene.model(), scene.grid(), scene.initial_bodies());
    let (mut whole, _) = ReferenceRun::new(scene.model(), scene.grid(), scene.initial_bodies());
    whole.check_contract(true).unwrap();
    fast.add_input(DROP, dropped_cube()).unwrap();
    whole.add_input(DROP, dropped_cube()).unwrap();
    fast.record_costs(true);
    let mut partial = 0;
    for _ in 0..STEPS {
        if fast.step_number() + 1 == DROP {
            assert!(all_at_rest(&fast), "the pile is not asleep before the drop");
        }
        let (f, w) = (fast.advance(), whole.advance());
        assert_eq!(f, w, "step {}", f.step);
        let computed = fast.take_costs().len();
        if computed > 0 && computed < fast.state().occupied().count() {
            partial += 1;
        }
    }
    // While the cube falls, only the cells around it are computed.
    assert!(
        partial > 10,
        "only {partial} steps computed part of the cells"
    );
    assert_eq!(fast.state().len(), 28);
}

fn frames(options: RunOptions) -> Vec<Frame<EventKind>> {
    let scene = pile();
    let mut out = Vec::new();
    Runner::new(scene.model(), scene.grid(), scene.initial_bodies())
        .options(options)
        .input(DROP, dropped_cube())
        .run(STEPS, |f, _, _| out.push(f.clone()))
        .unwrap();
    out
}

#[test]
fn asleep_and_woken_piles_commit_the_reference_frames_on_every_executor() {
    let reference = frames(RunOptions::reference());
    assert_eq!(reference.len(), STEPS as usize);
    for mode in [
        RollbackMode::Cell,
        RollbackMode::World,
        RollbackMode::Conservative,
    ] {
        let kernel = KernelConfig::new(4).mode(mode).window(8);
        assert_eq!(
            frames(RunOptions::virtual_exec(kernel.clone())),
            reference,
            "virtual, {mode:?}"
        );
        assert_eq!(
            frames(RunOptions::threaded(kernel, 2)),
            reference,
            "threaded, {mode:?}"
        );
    }
}

/// The logs of an asleep pile hold each cell's state once, whatever the steps they hold
/// (SPEC.md §K3): a cell whose output is bit-identical to its state logs that state's
/// allocation, not a copy, so states and outputs together stay within one copy of the bodies
/// (plus each cell's allocation header) over a full window of 64 steps.
#[test]
fn unchanged_cells_share_their_logged_states() {
    let scene = pile();
    let (mut reference, _) = ReferenceRun::new(scene.model(), scene.grid(), scene.initial_bodies());
    // Two worlds of equal numbers of cells, under which schedule 5 leaves a world far enough
    // ahead that the logs hold most of the window (checked below).
    let cfg = KernelConfig::new(2)
        .mode(RollbackMode::Cell)
        .window(64)
        .partition(PartitionKind::EqualBlocks);
    let options = soda::exec::virtual_exec::VirtualOptions::new(
        soda::exec::virtual_exec::ScheduleSpec::Seeded(5),
    );
    let (mut run, _) = soda::exec::virtual_exec::VirtualRun::new(
        scene.model(),
        scene.grid(),
        scene.initial_bodies(),
        &cfg,
        &options,
    );
    let end = 260;
    run.set_horizon(end + 64);
    run.run(end);
    for _ in 0..end - 64 {
        reference.advance();
    }
    // Every step the logs can hold (GVT − 2 on) is asleep.
    for _ in 0..64 {
        assert!(
            all_at_rest(&reference),
            "the pile is awake at {}",
            reference.step_number()
        );
        reference.advance();
    }
    let held = run.steps_held();
    assert!(held >= 48, "the logs hold only {held} world-steps");
    let b = run.log_breakdown();
    let cells = reference.state().occupied().count() as u64;
    // One copy of every body, plus each cell's allocation header (an `Arc`'s two counts).
    let bodies = scene.initial_bodies().len() as u64;
    let header = 2 * std::mem::size_of::<usize>() as u64;
    let once = bodies * std::mem::size_of::<Body>() as u64 + header * cells;
    assert!(
        b.states + b.outputs <= once,
        "{held} world-steps asleep hold {} B of states and outputs; one copy is {once} B",
        b.states + b.outputs
    );
}
