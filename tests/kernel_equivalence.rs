//! The kernel's central property: for random small scenes (synthetic particles and the
//! rigid-body built-ins) × partitions (blocks, k-means, random cells; 2–16 worlds) × rollback
//! modes × optimism windows × schedule seeds, every committed frame (step, hash, body count,
//! events) equals the reference run's. A failure prints the first divergent step, the
//! configuration and the schedule string that replays it.
//!
//! And the proof that this check can fire: the same property with a planted bug fails.

mod kernel_support;

use kernel_support::{case, particle_scene, property, property_with, rigid_scene, Case};
use proptest::prelude::*;
use proptest::test_runner::TestError;
use proptest::test_runner::{Config, TestRunner};
use soda::exec::virtual_exec::parse_schedule;
use soda::kernel::PlantedBug;

proptest! {
    #![proptest_config(Config { cases: 256, max_shrink_iters: 400, ..Config::default() })]

    #[test]
    fn committed_hashes_equal_reference_for_particles(c in case(particle_scene(), 5..40)) {
        if let Err(e) = property(&c, PlantedBug::None) {
            prop_assert!(false, "{}", e);
        }
    }
}

proptest! {
    #![proptest_config(Config { cases: 64, max_shrink_iters: 100, ..Config::default() })]

    #[test]
    fn committed_hashes_equal_reference_for_rigid_bodies(c in case(rigid_scene(), 10..80)) {
        if let Err(e) = property(&c, PlantedBug::None) {
            prop_assert!(false, "{}", e);
        }
    }
}

fn planted_bug_fails(bug: PlantedBug) -> bool {
    let mut runner = TestRunner::new(Config {
        cases: 64,
        failure_persistence: None,
        max_shrink_iters: 0,
        ..Config::default()
    });
    let r = runner.run(&case(particle_scene(), 5..40), |c: Case| {
        property(&c, bug).map(|_| ()).map_err(TestCaseError::fail)
    });
    match r {
        Ok(()) => false,
        Err(TestError::Fail(reason, case)) => {
            // The failure names the divergent step and carries a replay string that
            // reproduces it.
            let msg = reason.message().to_string();
            assert!(msg.contains("first divergence at step"), "{msg}");
            let replay = msg.split("): ").last().unwrap().trim();
            let schedule = parse_schedule(replay).expect("a replay string");
            let mut replayed = case.clone();
            let cfg = case.config(bug);
            replayed.schedule_seed = 0;
            let again = property_with(&replayed, &cfg, &case.options().schedule(schedule));
            assert!(again.is_err(), "the printed schedule replays the failure");
            true
        }
        Err(e) => panic!("{e}"),
    }
}

#[test]
fn planted_bug_cutoff_by_ids_only_makes_the_equivalence_property_fail() {
    assert!(planted_bug_fails(PlantedBug::CutoffByIdsOnly));
}

#[test]
fn planted_bug_drop_lone_anti_makes_the_equivalence_property_fail() {
    assert!(planted_bug_fails(PlantedBug::DropLoneAnti));
}
