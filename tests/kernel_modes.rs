//! Properties of the rollback modes and of the virtual executor's schedules, on built-in
//! scenes: conservative never rolls back; cell recomputes fewer cell-steps than world on the
//! same schedules of sparse-gas; the virtual executor reproduces the reference snapshots of
//! every built-in scene; a printed schedule replays exactly; fuzz bytes drive the scheduler;
//! delta ghosts make a resting border cost no message.

mod kernel_support;

use kernel_support::{compare, reference};
use soda::exec::virtual_exec::{
    parse_schedule, run_virtual, ScheduleSpec, VirtualOptions, VirtualRun,
};
use soda::hash::hex;
use soda::kernel::synthetic::Particles;
use soda::kernel::{GhostPolicy, KernelConfig, PartitionKind, RollbackMode};
use soda::scene::builtin::builtin;

#[test]
fn conservative_never_rolls_back() {
    let s = builtin("sparse-gas", Some(27), 3).unwrap();
    let (m, g, b) = (s.model(), s.grid(), s.initial_bodies());
    let exp = reference(&m, &g, &b, 40);
    for (worlds, part) in [
        (2, PartitionKind::Blocks),
        (5, PartitionKind::KMeans),
        (9, PartitionKind::Random),
    ] {
        for seed in 0..4 {
            for window in [1, 4, 64] {
                let cfg = KernelConfig::new(worlds)
                    .mode(RollbackMode::Conservative)
                    .partition(part.clone())
                    .window(window);
                let c = compare(&m, &g, &b, &cfg, &VirtualOptions::seeded(seed), &exp).unwrap();
                assert_eq!(c.total.rollbacks(), 0);
                assert_eq!(c.total.cells_recomputed, 0);
                assert_eq!(c.total.anti_messages_sent, 0);
                assert_eq!(c.total.efficiency(), 1.0);
            }
        }
    }
}

#[test]
fn an_adaptive_window_commits_the_reference_bits_and_wastes_less_than_its_ceiling() {
    let s = builtin("falling-cubes", Some(200), 2).unwrap();
    let (m, g, b) = (s.model(), s.grid(), s.initial_bodies());
    let exp = reference(&m, &g, &b, 80);
    let (mut auto_waste, mut fixed_waste) = (0, 0);
    for mode in [RollbackMode::Cell, RollbackMode::World] {
        for seed in 0..3 {
            let cfg = KernelConfig::new(6).mode(mode).window(64);
            let options = VirtualOptions::seeded(seed);
            let auto = compare(&m, &g, &b, &cfg.clone().window_auto(true), &options, &exp)
                .unwrap_or_else(|e| panic!("{mode:?} seed {seed}: {e}"));
            let fixed = compare(&m, &g, &b, &cfg, &options, &exp).unwrap();
            auto_waste += auto.total.steps_rolled_back;
            fixed_waste += fixed.total.steps_rolled_back;
        }
    }
    assert!(fixed_waste > 0, "the schedules produced rollbacks");
    assert!(
        auto_waste < fixed_waste,
        "the adaptive window rolled back {auto_waste} steps, its fixed ceiling {fixed_waste}"
    );
}

/// Balancing rounds rebuild a world's territory (K13) while its window adapts (K14): the
/// world keeps its window and throttle across the rebuild, and the committed bits stay the
/// reference's.
#[test]
fn an_adaptive_window_across_balancing_rounds_commits_the_reference_bits() {
    let s = builtin("falling-cubes", Some(200), 2).unwrap();
    let (m, g, b) = (s.model(), s.grid(), s.initial_bodies());
    let exp = reference(&m, &g, &b, 80);
    for seed in 0..3 {
        let balance = soda::kernel::BalanceConfig {
            period: 10,
            backoff: false,
            load: soda::kernel::LoadSource::Seeded(seed),
            seed,
            ..soda::kernel::BalanceConfig::on()
        };
        let cfg = KernelConfig::new(6)
            .window(64)
            .window_auto(true)
            .balance(balance);
        let run = compare(&m, &g, &b, &cfg, &VirtualOptions::seeded(seed), &exp)
            .unwrap_or_else(|e| panic!("seed {seed}: {e}"));
        assert!(run.balance.rounds > 0, "seed {seed}: no balancing round");
    }
}

#[test]
fn cell_recomputes_fewer_cell_steps_than_world_on_the_same_schedules_of_sparse_gas() {
    let s = builtin("sparse-gas", Some(64), 1).unwrap();
    let (m, g, b) = (s.model(), s.grid(), s.initial_bodies());
    let exp = reference(&m, &g, &b, 60);
    let (mut cell, mut world) = (0, 0);
    for seed in 0..4 {
        let cfg = |mode| KernelConfig::new(8).mode(mode).window(16);
        let options = VirtualOptions::seeded(seed);
        let c = compare(&m, &g, &b, &cfg(RollbackMode::Cell), &options, &exp).unwrap();
        let w = compare(&m, &g, &b, &cfg(RollbackMode::World), &options, &exp).unwrap();
        cell += c.total.cells_recomputed;
        world += w.total.cells_recomputed;
    }
    assert!(world > 0, "the schedules produced rollbacks");
    assert!(
        cell < world,
        "cell recomputed {cell} cell-steps, world {world}"
    );
}

/// The scene, size and seed named in a snapshot's first line, and its `step … hash …` lines.
fn snapshot(name: &str) -> (usize, u64, Vec<String>) {
    let path = format!(
        "{}/tests/snapshots/snapshots__{name}.snap",
        env!("CARGO_MANIFEST_DIR")
    );
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    let mut lines = text.lines().skip_while(|l| !l.starts_with("scene "));
    let head: Vec<&str> = lines.next().expect("header").split_whitespace().collect();
    let objects = head[3].parse().unwrap();
    let seed = head[5].parse().unwrap();
    (
        objects,
        seed,
        lines
            .filter(|l| l.starts_with("step"))
            .map(String::from)
            .collect(),
    )
}

#[test]
fn virtual_executor_reproduces_the_reference_snapshots_of_every_builtin_scene() {
    for b in soda::scene::builtin::BUILTINS {
        let (objects, seed, expected) = snapshot(b.name);
        let s = builtin(b.name, Some(objects), seed).unwrap();
        let steps = 150;
        let cfg = KernelConfig::new(4)
            .window(8)
            .partition(PartitionKind::KMeans);
        let options = VirtualOptions::seeded(11);
        let r = run_virtual(
            s.model(),
            s.grid(),
            s.initial_bodies(),
            &cfg,
            &options,
            steps,
        );
        let got: Vec<String> = r
            .frames
            .iter()
            .filter(|f| f.step % 10 == 0 || f.step == steps)
            .map(|f| {
                format!(
                    "step {:4} bodies {:3} hash {}",
                    f.step,
                    f.bodies,
                    hex(f.hash)
                )
            })
            .collect();
        assert_eq!(got, expected, "{}", b.name);
    }
}

#[test]
fn a_printed_schedule_replays_exactly() {
    let (m, g, b) = Particles::scene(40, [4, 3, 2], true, 5);
    let cfg = KernelConfig::new(6)
        .window(6)
        .partition(PartitionKind::Random);
    let options = VirtualOptions::seeded(99);
    let first = run_virtual(m.clone(), g.clone(), b.clone(), &cfg, &options, 30);
    assert!(first.counters.total.rollbacks() > 0);
    let replay = options.schedule(parse_schedule(&first.schedule).unwrap());
    let second = run_virtual(m, g, b, &cfg, &replay, 30);
    assert_eq!(first.frames, second.frames);
    assert_eq!(first.counters, second.counters);
    assert_eq!(first.schedule, second.schedule);
}

#[test]
fn fuzz_bytes_drive_the_scheduler_deterministically_and_correctly() {
    let (m, g, b) = Particles::scene(30, [4, 2, 2], false, 8);
    let exp = reference(&m, &g, &b, 25);
    let cfg = KernelConfig::new(4).window(5);
    for k in 0..8u8 {
        let bytes: Vec<u8> = (0..600u32)
            .map(|i| (i.wrapping_mul(97) as u8) ^ k.wrapping_mul(31))
            .collect();
        let run = |bytes: &[u8]| {
            let (mut r, _) = VirtualRun::from_bytes(m.clone(), g.clone(), b.clone(), &cfg, bytes);
            let f = r.run(25);
            (f, r.counters())
        };
        let (f1, c1) = run(&bytes);
        let (f2, c2) = run(&bytes);
        assert_eq!(f1, exp);
        assert_eq!((f1, c1), (f2, c2));
    }
}

#[test]
fn a_late_migration_across_a_border_commits_like_the_reference_under_any_schedule() {
    // The row scene of the targeted tests, but run by the executor under many schedules.
    let (m, g, _) = Particles::scene(0, [6, 1, 1], false, 0);
    let b = vec![
        soda::kernel::synthetic::Particle {
            id: 0,
            pos: [2.9, 0.5, 0.5],
            vel: [0.0; 3],
        },
        soda::kernel::synthetic::Particle {
            id: 1,
            pos: [3.02, 0.5, 0.5],
            vel: [-0.01, 0.0, 0.0],
        },
    ];
    let exp = reference(&m, &g, &b, 20);
    for mode in [
        RollbackMode::Cell,
        RollbackMode::World,
        RollbackMode::Conservative,
    ] {
        for seed in 0..40 {
            let cfg = KernelConfig::new(2)
                .mode(mode)
                .window(1 + seed % 9)
                .partition(PartitionKind::Explicit(vec![0, 0, 0, 1, 1, 1]));
            compare(&m, &g, &b, &cfg, &VirtualOptions::seeded(seed), &exp).unwrap();
        }
    }
}

#[test]
fn fifo_schedule_applies_all_news_before_computing_so_never_rolls_back() {
    let s = builtin("falling-cubes", Some(200), 0).unwrap();
    let (m, g, b) = (s.model(), s.grid(), s.initial_bodies());
    let exp = reference(&m, &g, &b, 40);
    for mode in [RollbackMode::Cell, RollbackMode::World] {
        let cfg = KernelConfig::new(8).mode(mode).window(16);
        let fifo = VirtualOptions::new(ScheduleSpec::Fifo);
        let c = compare(&m, &g, &b, &cfg, &fifo, &exp).unwrap();
        assert_eq!(c.total.rollbacks(), 0);
        assert_eq!(c.total.cells_recomputed, 0);
    }
}

#[test]
fn delta_ghosts_send_nothing_for_a_resting_border_and_commit_the_same_bits() {
    // 64 cubes land and fall asleep within ~2 s; over 5 s, full ghosts re-send every
    // non-empty border cell every step, delta ghosts only the steps where a cell changed.
    let s = builtin("falling-cubes", Some(64), 0).unwrap();
    let (m, g, b) = (s.model(), s.grid(), s.initial_bodies());
    let steps = 300;
    let exp = reference(&m, &g, &b, steps);
    let mut ghosts = Vec::new();
    for policy in [GhostPolicy::Full, GhostPolicy::Delta] {
        for seed in 0..3 {
            let cfg = KernelConfig::new(4).ghosts(policy);
            let c = compare(&m, &g, &b, &cfg, &VirtualOptions::seeded(seed), &exp)
                .unwrap_or_else(|e| panic!("{policy:?} seed {seed}: {e}"));
            ghosts.push((policy, c.total.ghosts_sent));
        }
    }
    let sum = |p: GhostPolicy| -> u64 { ghosts.iter().filter(|g| g.0 == p).map(|g| g.1).sum() };
    let (full, delta) = (sum(GhostPolicy::Full), sum(GhostPolicy::Delta));
    assert!(
        delta * 2 < full,
        "delta ghosts {delta} not under half of full ghosts {full}"
    );
    // Once everything sleeps, a delta world sends no ghost at all.
    let cfg = KernelConfig::new(4);
    let fifo = VirtualOptions::new(ScheduleSpec::Fifo);
    let (mut run, _) = VirtualRun::new(m.clone(), g.clone(), b.clone(), &cfg, &fifo);
    run.run(240);
    let before = run.counters().total.ghosts_sent;
    let frames = run.run(60);
    assert_eq!(frames.last(), exp.last());
    assert_eq!(
        run.counters().total.ghosts_sent,
        before,
        "ghosts sent while the pile sleeps"
    );
}

#[test]
fn delta_ghosts_under_adversarial_schedules_of_a_landing_pile_commit_the_reference_bits() {
    // 1,000 cubes landing under a seeded schedule: ghosts change every step, worlds run far
    // ahead on predicted views, late ghosts and their successors arrive out of order and are
    // re-sent after rollbacks. World mode with schedule seed 0 caught a view carried forward
    // too little after a re-sent ghost that no longer announced a successor (it diverged
    // from step 50 on); smaller piles did not.
    let s = builtin("falling-cubes", Some(1000), 0).unwrap();
    let (m, g, b) = (s.model(), s.grid(), s.initial_bodies());
    let exp = reference(&m, &g, &b, 55);
    for mode in [RollbackMode::World, RollbackMode::Cell] {
        let cfg = KernelConfig::new(8)
            .mode(mode)
            .window(16)
            .ghosts(GhostPolicy::Delta);
        compare(&m, &g, &b, &cfg, &VirtualOptions::seeded(0), &exp)
            .unwrap_or_else(|e| panic!("{mode:?}: {e}"));
    }
}

/// A live display sees where rollbacks reached: every world's per-cell counts of
/// re-executed computations (`WorldStatus::cell_recomputes`, one per own cell) add up to its
/// `cells_recomputed`, and on a run that rolls back, some cells have non-zero counts.
#[test]
fn live_status_counts_recomputations_per_cell_summing_to_the_worlds_counts() {
    use soda::exec::live::LiveStatus;
    let s = builtin("sparse-gas", Some(64), 3).unwrap();
    let cfg = KernelConfig::new(5)
        .mode(RollbackMode::Cell)
        .partition(PartitionKind::Random)
        .window(64);
    let (mut run, _) = VirtualRun::new(
        s.model(),
        s.grid(),
        s.initial_bodies(),
        &cfg,
        &VirtualOptions::seeded(3),
    );
    let mut last: Option<LiveStatus> = None;
    run.run_controlled(40, &Default::default(), |_, _, c| {
        last = c.live_status();
    })
    .unwrap();
    let live = last.expect("the virtual executor shows its live status");
    let cells = s.grid().cell_count();
    let per_cell = live.recomputes(cells);
    let mut recomputed = 0;
    for w in &live.worlds {
        assert_eq!(w.cell_recomputes.len(), w.cells.len());
        assert_eq!(w.cell_recomputes.iter().sum::<u64>(), w.cells_recomputed);
        for (&c, &n) in w.cells.iter().zip(&w.cell_recomputes) {
            assert_eq!(per_cell[c as usize], n);
        }
        recomputed += w.cells_recomputed;
    }
    assert!(
        recomputed > 0,
        "the run rolled back no cell: pick a schedule that does"
    );
    assert_eq!(per_cell.iter().sum::<u64>(), recomputed);
}
