//! Load balancing by cell cession (SPEC.md §K13): whatever cells move, and whenever,
//! every committed frame equals the reference's; decisions replay from the seed and the
//! schedule; territories never split; a famished world recovers.

mod kernel_support;

use kernel_support::{case, particle_scene, property_with, reference, rigid_scene, Case};
use proptest::prelude::*;
use soda::exec::virtual_exec::{parse_schedule, VirtualOptions, VirtualRun};
use soda::kernel::balance::territory::components;
use soda::kernel::synthetic::{Particle, Particles};
use soda::kernel::{
    BalanceConfig, KernelConfig, LoadSource, PartitionKind, PlantedBug, RollbackMode,
};
use soda::Grid;

/// Balancing on, a round every `period` steps, loads drawn from `seed` (random decisions).
/// Seeded (random) balancing decisions with a round every `period` steps (no backoff).
fn seeded(period: u64, seed: u64, cooldown: u64, max_cells: usize) -> BalanceConfig {
    BalanceConfig {
        period,
        backoff: false,
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
        any::<bool>(),
        any::<bool>(),
    )
        .prop_flat_map(
            |(scene, period, seed, cooldown, max_cells, backoff, opening)| {
                (
                    case(Just(scene), 8..40),
                    Just(BalanceConfig {
                        backoff,
                        opening,
                        ..seeded(period, seed, cooldown, max_cells)
                    }),
                )
            },
        )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// Random balancing decisions (seeded loads: cessions and famines at random), forced
    /// through the virtual executor under random schedules, modes, windows and partitions,
    /// never change a committed hash.
    #[test]
    fn random_balancing_decisions_never_change_a_committed_hash((c, b) in balanced_case()) {
        let config = c.config(PlantedBug::None).balance(b);
        let r = property_with(&c, &config, &c.options());
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

fn run_virtual(
    config: &KernelConfig,
    options: &VirtualOptions,
    steps: u64,
) -> (
    VirtualRun<Particles>,
    Vec<soda::Frame<soda::kernel::synthetic::ParticleEvent>>,
) {
    let (m, g, b) = crowded_corner();
    let (mut run, _) = VirtualRun::new(m, g, b, config, options);
    let frames = run.run(steps);
    (run, frames)
}

#[test]
fn seeded_decisions_move_cells_and_fight_famine_with_reference_hashes() {
    let (m, g, b) = crowded_corner();
    let expected = reference(&m, &g, &b, 80);
    for seed in 0..4 {
        let config = KernelConfig::new(6).balance(seeded(5, seed, 1, 16));
        let (run, frames) = run_virtual(&config, &VirtualOptions::seeded(seed), 80);
        assert_eq!(frames, expected, "seed {seed}");
        let c = run.counters().balance;
        assert_eq!(
            c.rounds, 16,
            "the opening round at step 0, then one at steps 5, 10, ..., 75 (none after the last)"
        );
        assert!(c.cells_moved > 0, "seed {seed}: no cell moved");
        assert!(c.famines > 0, "seed {seed}: no famine");
    }
}

/// Particles in 16×2×2 cells, all starting in the lowest x quarter and moving +x.
fn marching_particles() -> (Particles, Grid, Vec<Particle>) {
    let (m, g, mut b) = Particles::scene(60, [16, 2, 2], false, 9);
    for p in &mut b {
        p.pos[0] *= 0.2;
        p.vel = [0.25, 0.0, 0.0];
    }
    (m, g, b)
}

fn proxy_balance(period: u64) -> BalanceConfig {
    BalanceConfig {
        period,
        smoothing: 1.0,
        load: LoadSource::CellsComputed,
        ..BalanceConfig::on()
    }
}

#[test]
fn a_world_whose_bodies_all_leave_fights_famine_and_gets_work_again() {
    let (m, g, b) = marching_particles();
    let steps = 120;
    let expected = reference(&m, &g, &b, steps);
    // Four equal slabs along x (not cut by the bodies, which all start in the first), so
    // the particles march out of world 0's territory and leave it without work.
    let config = KernelConfig::new(4)
        .partition(PartitionKind::EqualBlocks)
        .balance(proxy_balance(5));
    let (mut run, _) = VirtualRun::new(m, g, b, &config, &VirtualOptions::seeded(3));
    let frames = run.run(steps);
    assert_eq!(frames, expected);
    let rounds = run.balance_history();
    let recovered = rounds.iter().enumerate().find_map(|(i, r)| {
        r.famished.iter().find_map(|&w| {
            let starved = r.loads[w as usize] == 0.0;
            let fed = rounds[i + 1..].iter().any(|l| l.loads[w as usize] > 0.0);
            (starved && fed).then_some((r.step, w))
        })
    });
    assert!(
        recovered.is_some(),
        "no world went without work, fought famine and computed again: {:?}",
        rounds
            .iter()
            .map(|r| (r.step, r.loads.clone(), r.famished.clone()))
            .collect::<Vec<_>>()
    );
}

#[test]
fn balancing_decisions_replay_from_the_schedule_seed_and_string() {
    let config = KernelConfig::new(5)
        .partition(PartitionKind::KMeans)
        .balance(proxy_balance(4));
    let run = |options: &VirtualOptions| {
        let (m, g, b) = marching_particles();
        let (mut r, _) = VirtualRun::new(m, g, b, &config, options);
        let frames = r.run(80);
        (frames, r.balance_history().to_vec(), r.schedule_string())
    };
    let options = VirtualOptions::seeded(11);
    let (frames, rounds, schedule) = run(&options);
    assert!(rounds.iter().any(|r| r.cells_moved > 0), "no cell moved");
    let (frames2, rounds2, _) = run(&options);
    assert_eq!(
        (&frames, &rounds),
        (&frames2, &rounds2),
        "same seed, same decisions"
    );
    let owners = |rs: &[soda::kernel::RoundRecord]| -> Vec<Vec<u32>> {
        rs.iter().map(|r| r.owners.clone()).collect()
    };
    assert_eq!(owners(&rounds), owners(&rounds2));
    let replay = options.schedule(parse_schedule(&schedule).expect("schedule string"));
    let (frames3, rounds3, _) = run(&replay);
    assert_eq!(
        (&frames, &rounds),
        (&frames3, &rounds3),
        "the string replays them"
    );
    assert_eq!(owners(&rounds), owners(&rounds3));
}

#[test]
fn territories_never_split_into_more_pieces() {
    let (m, g, b) = crowded_corner();
    for (seed, mode) in [
        (1, RollbackMode::Cell),
        (2, RollbackMode::World),
        (3, RollbackMode::Conservative),
    ] {
        let config = KernelConfig::new(6)
            .mode(mode)
            .balance(seeded(4, seed, 0, 24));
        let options = VirtualOptions::seeded(seed);
        let (mut run, _) = VirtualRun::new(m.clone(), g.clone(), b.clone(), &config, &options);
        run.run(60);
        let mut before = run_initial_owners(&g, &config);
        let mut moved = 0;
        for r in run.balance_history() {
            for w in 0..6 {
                let was = components(&g, &before, w, None);
                let now = components(&g, &r.owners, w, None);
                assert!(
                    now <= was.max(1),
                    "seed {seed}: world {w} went from {was} to {now} pieces at step {}",
                    r.step
                );
            }
            moved += r.cells_moved;
            before = r.owners.clone();
        }
        assert!(moved > 0, "seed {seed}: nothing moved");
    }
}

fn run_initial_owners(g: &Grid, config: &KernelConfig) -> Vec<u32> {
    soda::kernel::Partition::build(&config.partition, g, config.worlds, &[], 0)
        .owners()
        .to_vec()
}

fn soda(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_soda"))
        .args(args)
        .output()
        .expect("soda runs")
}

fn hash_line(out: &std::process::Output) -> String {
    let text = String::from_utf8_lossy(&out.stdout);
    text.lines()
        .find(|l| l.starts_with("hash"))
        .unwrap_or_else(|| panic!("no hash line in {text}"))
        .to_string()
}

#[test]
fn cli_balance_on_keeps_the_hash_and_draws_the_territories() {
    let dir = tempfile::tempdir().expect("temp dir");
    let maps = dir.path().join("maps");
    let base = [
        "run",
        "--scene",
        "skewed",
        "--objects",
        "64",
        "--steps",
        "30",
    ];
    let reference = soda(&base);
    assert!(reference.status.success());
    let mut args = base.to_vec();
    args.extend([
        "--executor",
        "virtual",
        "--worlds",
        "6",
        "--balance",
        "on",
        "--balance-period",
        "5",
        "--territories",
        maps.to_str().expect("utf-8 path"),
    ]);
    let balanced = soda(&args);
    assert!(
        balanced.status.success(),
        "{}",
        String::from_utf8_lossy(&balanced.stderr)
    );
    assert_eq!(hash_line(&balanced), hash_line(&reference));
    let text = String::from_utf8_lossy(&balanced.stdout);
    // The opening round at step 0, then rounds from step 5 on (backing off while idle).
    assert!(text.contains("balancing        6 rounds"), "{text}");
    for f in [
        "territory-000000.svg",
        "territory-000005.svg",
        "imbalance.svg",
    ] {
        let svg = std::fs::read_to_string(maps.join(f)).expect(f);
        assert!(svg.contains("<svg"), "{f} is not an SVG");
    }
}

#[test]
fn cli_balance_options_are_checked_with_the_fix_named() {
    let out = soda(&["run", "--executor", "virtual", "--balance-period", "5"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("add `--balance on`"));
    let out = soda(&[
        "run",
        "--executor",
        "virtual",
        "--balance",
        "on",
        "--balance-thresholds",
        "1.5,1.2,0.8",
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("underloaded <= 1 <= high <= overloaded"),
        "{err}"
    );
    let out = soda(&["run", "--balance", "on"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--executor virtual"));
}
