//! The locality contract, tested directly: computing the cells of a step in any order and
//! over any partition into groups — each group working only from a copy of its own
//! 27-cell neighbourhood — gives states bit-identical to the reference.

use proptest::prelude::*;
use soda::exec::reference::ReferenceRun;
use soda::physics::{Body, Material, Shape};
use soda::state::CellStates;
use soda::{CellModel, Grid, RigidBodyModel, SceneBuilder};

/// One step computed group by group from copies of each group's neighbourhood.
fn partitioned_step(
    model: &RigidBodyModel,
    grid: &Grid,
    state: &CellStates<Body>,
    step: u64,
    order: &[usize],
    groups: &[usize],
) -> Vec<Body> {
    let occupied: Vec<usize> = state.occupied().collect();
    let n_groups = groups.iter().copied().max().unwrap_or(0) + 1;
    let mut out = Vec::new();
    for g in 0..n_groups {
        let mine: Vec<usize> = order
            .iter()
            .map(|&k| occupied[k])
            .filter(|&c| groups[c % groups.len()] == g)
            .collect();
        // The group's private copy: only the bodies of its cells' neighbourhoods.
        let mut copy_cells: Vec<usize> = mine
            .iter()
            .flat_map(|&c| {
                grid.neighbours(grid.coord(c))
                    .map(|n| grid.index(n))
                    .collect::<Vec<_>>()
            })
            .collect();
        copy_cells.sort();
        copy_cells.dedup();
        let copied: Vec<Body> = copy_cells
            .iter()
            .flat_map(|&c| state.cell_at(c).to_vec())
            .collect();
        let mut ev = Vec::new();
        let private = CellStates::binned::<RigidBodyModel>(grid, copied, step, &mut ev);
        for &c in &mine {
            let nb = private.neighbourhood(grid, grid.coord(c));
            let mut events = Vec::new();
            model.step_cell(step, grid, &nb, &mut out, &mut events);
        }
    }
    out.sort_by_key(|b| b.id());
    out
}

fn bits(b: &Body) -> Vec<u32> {
    let q = b.rotation.quaternion();
    let mut v: Vec<u32> = [b.position, b.linvel, b.angvel]
        .iter()
        .flat_map(|x| x.iter().map(|c| c.to_bits()))
        .collect();
    v.extend([q.w, q.i, q.j, q.k].iter().map(|c| c.to_bits()));
    v.push(u32::from(b.rest_steps));
    v
}

prop_compose! {
    fn small_scene()(
        slots in proptest::collection::vec((any::<bool>(), -2.0f32..2.0, -2.0f32..2.0, -2.0f32..2.0, 0.0f32..1.0), 4..40),
        seed in 0u64..1000,
    ) -> soda::Scene {
        let mut b = SceneBuilder::new([-6.0, -1.0, -6.0], [6.0, 8.0, 6.0]).walls(true, false).seed(seed);
        for (k, (cube, vx, vy, vz, skip)) in slots.into_iter().enumerate() {
            if skip < 0.15 { continue; }
            let (i, j, l) = (k % 4, (k / 4) % 4, k / 16);
            let pos = [-4.5 + 2.5 * i as f32, 0.6 + 1.6 * l as f32, -4.5 + 2.5 * j as f32];
            let shape = if cube { Shape::Cuboid { half_extents: [0.5, 0.4, 0.3] } } else { Shape::Ball { radius: 0.45 } };
            let id = b.body(shape, Material { density: 1.0, friction: 0.5, restitution: 0.3 }, pos, [0.1 * vx, 0.2 * vy, 0.0]);
            b.velocity(id, [3.0 * vx, vy, 3.0 * vz]);
        }
        b.build().expect("generated scene is valid")
    }
}

prop_compose! {
    /// Bodies resting on the ground (they fall asleep within a few steps) beside bodies
    /// thrown at them, with sleeping after `sleep_steps` quiet steps: sleeping, waking and
    /// frozen cells in one run.
    fn sleepy_scene()(
        slots in proptest::collection::vec((any::<bool>(), any::<bool>(), -2.0f32..2.0, -2.0f32..2.0, 0.0f32..1.0), 4..32),
        sleep_steps in 1u32..5,
        seed in 0u64..1000,
    ) -> soda::Scene {
        let params = soda::physics::SolverParams { sleep_steps, ..Default::default() };
        let mut b = SceneBuilder::new([-6.0, -1.0, -6.0], [6.0, 8.0, 6.0]).walls(true, false).seed(seed).solver(params);
        for (k, (cube, thrown, vx, vz, skip)) in slots.into_iter().enumerate() {
            if skip < 0.15 { continue; }
            let (i, j, l) = (k % 4, (k / 4) % 4, k / 16);
            let shape = if cube { Shape::Cuboid { half_extents: [0.5, 0.4, 0.3] } } else { Shape::Ball { radius: 0.45 } };
            let pos = [-4.5 + 2.5 * i as f32, if thrown { 2.6 + 1.2 * l as f32 } else { 0.46 + 0.92 * l as f32 }, -4.5 + 2.5 * j as f32];
            let id = b.body(shape, Material { density: 1.0, friction: 0.5, restitution: 0.3 }, pos, [0.0; 3]);
            if thrown {
                b.velocity(id, [3.0 * vx, 0.0, 3.0 * vz]);
            }
        }
        b.build().expect("generated scene is valid")
    }
}

/// Runs `steps` steps of `scene` both ways and compares every body's bits.
fn check_partitioned(
    scene: soda::Scene,
    order_seed: &[usize],
    groups: &[usize],
    steps: u64,
) -> Result<(), TestCaseError> {
    let model = scene.model();
    let grid = scene.grid();
    let (mut run, _) = ReferenceRun::new(model.clone(), grid.clone(), scene.initial_bodies());
    for step in 0..steps {
        let state = run.state().clone();
        let occupied = state.occupied().count();
        let order: Vec<usize> = order_seed
            .iter()
            .copied()
            .filter(|&k| k < occupied)
            .collect();
        let mine = partitioned_step(&model, &grid, &state, step, &order, groups);
        run.advance();
        let reference: Vec<Body> = run
            .state()
            .sorted::<RigidBodyModel>()
            .into_iter()
            .cloned()
            .collect();
        let mine: Vec<Body> = mine
            .into_iter()
            .filter(|b| grid.cell_of(RigidBodyModel::position(b)).is_some())
            .collect();
        prop_assert_eq!(
            mine.len(),
            reference.len(),
            "body count differs at step {}",
            step + 1
        );
        for (a, b) in mine.iter().zip(&reference) {
            prop_assert_eq!(a.id(), b.id());
            prop_assert_eq!(
                bits(a),
                bits(b),
                "body {} differs at step {}",
                a.id(),
                step + 1
            );
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, ..ProptestConfig::default() })]

    #[test]
    fn sleeping_does_not_break_locality(
        scene in sleepy_scene(),
        order_seed in Just((0..512usize).collect::<Vec<_>>()).prop_shuffle(),
        groups in proptest::collection::vec(0usize..5, 1..64),
    ) {
        // The run must actually sleep somewhere, or the property says nothing.
        let model = scene.model();
        let (mut run, _) = ReferenceRun::new(model.clone(), scene.grid(), scene.initial_bodies());
        for _ in 0..60 { run.advance(); }
        let slept = run.state().sorted::<RigidBodyModel>().iter().any(|b| model.is_asleep(b));
        prop_assume!(slept);
        check_partitioned(scene, &order_seed, &groups, 60)?;
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    #[test]
    fn any_cell_order_and_partition_gives_reference_bits(
        scene in small_scene(),
        order_seed in Just((0..512usize).collect::<Vec<_>>()).prop_shuffle(),
        groups in proptest::collection::vec(0usize..5, 1..64),
    ) {
        check_partitioned(scene, &order_seed, &groups, 40)?;
    }
}
