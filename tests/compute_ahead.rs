//! Computing the interior ahead (SPEC.md §K5, item 4): a world computes the cells of its head
//! step that read no foreign view before it advances, and a change of an own state at that
//! step (a migration, a repair reaching the head) drops the outputs that read it. Under
//! random schedules, with every world computing ahead after each action, every committed
//! frame equals the reference's, outputs computed ahead are used and some are dropped, and
//! the counters keep their identity.

mod kernel_support;

use kernel_support::{compare, reference};
use soda::exec::virtual_exec::VirtualOptions;
use soda::kernel::{GhostPolicy, KernelConfig, PartitionKind, RollbackMode};
use soda::scene::builtin::builtin;

#[test]
fn computing_ahead_commits_the_reference_bits_and_drops_outputs_a_straggler_changes() {
    let (mut ahead, mut dropped) = (0, 0);
    for (name, bodies, steps) in [("falling-cubes", 300, 60), ("sparse-gas", 300, 60)] {
        let scene = builtin(name, Some(bodies), 1).expect("scene");
        let (model, grid, init) = (scene.model(), scene.grid(), scene.initial_bodies());
        let expected = reference(&model, &grid, &init, steps);
        for (mode, ghosts, partition) in [
            (
                RollbackMode::Cell,
                GhostPolicy::Delta,
                PartitionKind::Blocks,
            ),
            (RollbackMode::Cell, GhostPolicy::Full, PartitionKind::KMeans),
            (
                RollbackMode::World,
                GhostPolicy::Delta,
                PartitionKind::Blocks,
            ),
        ] {
            for seed in 0..2 {
                let config = KernelConfig::new(4)
                    .mode(mode)
                    .window(8)
                    .ghosts(ghosts)
                    .partition(partition.clone());
                let options = VirtualOptions::seeded(seed).compute_ahead(true);
                let c = compare(&model, &grid, &init, &config, &options, &expected)
                    .unwrap_or_else(|e| panic!("{name}: {e}"));
                let t = &c.total;
                assert_eq!(
                    t.cells_computed,
                    t.cells_committed + t.cells_rolled_back,
                    "{name} {mode:?} seed {seed}: computed = committed + rolled back"
                );
                assert!(t.cells_ahead_dropped <= t.cells_ahead);
                ahead += t.cells_ahead;
                dropped += t.cells_ahead_dropped;
            }
        }
    }
    assert!(ahead > 0, "no world computed ahead");
    assert!(
        dropped > 0,
        "no output computed ahead was dropped: the straggler path is not exercised"
    );
}

#[test]
fn without_computing_ahead_no_cell_is_computed_ahead() {
    let scene = builtin("falling-cubes", Some(200), 2).expect("scene");
    let (model, grid, init) = (scene.model(), scene.grid(), scene.initial_bodies());
    let expected = reference(&model, &grid, &init, 30);
    let config = KernelConfig::new(3).window(4);
    let c = compare(
        &model,
        &grid,
        &init,
        &config,
        &VirtualOptions::seeded(7),
        &expected,
    )
    .expect("the run commits the reference's frames");
    assert_eq!(c.total.cells_ahead, 0);
}

/// With two worlds on a wide scene the interior computed ahead outnumbers the border, so
/// each advance computes the border without preparing the territory again, reading each
/// border cell's rest from its neighbourhood (SPEC.md §K5 item 4); as the cubes land and
/// fall asleep, border cells are kept at rest that way. Every committed frame is still the
/// reference's.
#[test]
fn a_border_computed_after_the_interior_without_preparing_again_commits_the_reference_bits() {
    let scene = builtin("falling-cubes", Some(1000), 3).expect("scene");
    let (model, grid, init) = (scene.model(), scene.grid(), scene.initial_bodies());
    let steps = 240;
    let expected = reference(&model, &grid, &init, steps);
    let mut ahead = 0;
    for seed in 0..3 {
        let config = KernelConfig::new(2)
            .mode(RollbackMode::Cell)
            .window(8)
            .partition(PartitionKind::Blocks);
        let options = VirtualOptions::seeded(seed).compute_ahead(true);
        let c = compare(&model, &grid, &init, &config, &options, &expected)
            .unwrap_or_else(|e| panic!("seed {seed}: {e}"));
        let t = &c.total;
        assert_eq!(t.cells_computed, t.cells_committed + t.cells_rolled_back);
        ahead += t.cells_ahead;
    }
    assert!(ahead > 0, "no world computed ahead");
}
