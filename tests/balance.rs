//! Load balancing by cell cession (SPEC.md §Balancing): whatever cells move, and whenever,
//! every committed frame equals the reference's; decisions replay from the seed and the
//! schedule; territories never split; a famished world recovers.

mod kernel_support;

use kernel_support::{case, particle_scene, property_with, reference, rigid_scene, Case};
use proptest::prelude::*;
use soda::exec::virtual_exec::{parse_schedule, VirtualRun};
use soda::kernel::balance::territory::components;
use soda::kernel::synthetic::{Particle, Particles};
use soda::kernel::{
    BalanceConfig, KernelConfig, LoadSource, PartitionKind, PlantedBug, RollbackMode, ScheduleSpec,
};
use soda::Grid;

/// Balancing on, a round every `period` steps, loads drawn from `seed` (random decisions).
fn seeded(period: u64, seed: u64, cooldown: u64, max_cells: usize) -> BalanceConfig {
    BalanceConfig {
        period,
        cooldown,
        max_cells,
        load: LoadSource::Seeded(seed),
        seed,
        ..BalanceConfig::on()
    }
}

fn balanced_case() -> impl Strategy<Value = (Case, BalanceConfig)> {
    (
        prop_oneof![3 => particle_scene(), 1 => rigid_scene()],
        1u64..8,
        any::<u64>(),
        0u64..3,
        1usize..40,
    )
        .prop_flat_map(|(scene, period, seed, cooldown, max_cells)| {
            (
                case(Just(scene), 8..40),
                Just(seeded(period, seed, cooldown, max_cells)),
            )
        })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// Random balancing decisions (seeded loads: cessions and famines at random), forced
    /// through the virtual executor under random schedules, modes, windows and partitions,
    /// never change a committed hash.
    #[test]
    fn random_balancing_decisions_never_change_a_committed_hash((c, b) in balanced_case()) {
        let config = c.config(PlantedBug::None).balance(b);
        let r = property_with(&c, &config);
        prop_assert!(r.is_ok(), "{}", r.unwrap_err());
    }
}

/// 120 particles in 12×3×3 cells, all starting in the lowest x quarter.
fn crowded_corner() -> (Particles, Grid, Vec<Particle>) {
    let (m, g, mut b) = Particles::scene(120, [12, 3, 3], false, 5);
    for p in &mut b {
        p.pos[0] *= 0.25;
    }
    (m, g, b)
}

fn run_virtual(config: &KernelConfig, steps: u64) -> (VirtualRun<Particles>, Vec<soda::Frame>) {
    let (m, g, b) = crowded_corner();
    let (mut run, _) = VirtualRun::new(m, g, b, config);
    let frames = run.run(steps);
    (run, frames)
}

#[test]
fn seeded_decisions_move_cells_and_fight_famine_with_reference_hashes() {
    let (m, g, b) = crowded_corner();
    let expected = reference(&m, &g, &b, 80);
    for seed in 0..4 {
        let config = KernelConfig::new(6)
            .schedule(ScheduleSpec::Seeded(seed))
            .balance(seeded(5, seed, 1, 16));
        let (run, frames) = run_virtual(&config, 80);
        assert_eq!(frames, expected, "seed {seed}");
        let c = run.counters().balance;
        assert_eq!(c.rounds, 16, "a round every 5 steps up to step 80");
        assert!(c.cells_moved > 0, "seed {seed}: no cell moved");
        assert!(c.famines > 0, "seed {seed}: no famine");
    }
}
