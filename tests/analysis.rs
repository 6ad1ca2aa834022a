//! The numbers researchers analyse: the counters add up (committed + rolled back = computed,
//! per world and in total, in every mode and on both kernel executors), and tracing observes
//! without changing a single committed bit; the trace agrees with the counters.

use soda::exec::threaded::run_threaded;
use soda::exec::virtual_exec::{VirtualOptions, VirtualRun};
use soda::kernel::trace::RollbackCause;
use soda::kernel::{Counters, KernelConfig, RollbackMode, WorldCounters};
use soda::scene::builtin::builtin;
use soda::scene::Scene;

const MODES: [RollbackMode; 3] = [
    RollbackMode::Cell,
    RollbackMode::World,
    RollbackMode::Conservative,
];

fn scenes() -> Vec<Scene> {
    vec![
        builtin("sparse-gas", Some(80), 2).unwrap(),
        builtin("falling-cubes", Some(64), 0).unwrap(),
    ]
}

fn assert_adds_up(c: &WorldCounters, what: &str) {
    assert_eq!(
        c.cells_computed,
        c.cells_committed + c.cells_rolled_back,
        "{what}: cells computed = committed + rolled back ({c:?})"
    );
    assert_eq!(
        c.steps_computed,
        c.steps_committed + c.steps_reexecuted,
        "{what}: steps computed = committed + re-executed ({c:?})"
    );
    assert!(c.cells_recomputed <= c.cells_rolled_back + c.cells_computed);
}

fn assert_counters(c: &Counters, what: &str) {
    for (w, wc) in c.worlds.iter().enumerate() {
        assert_adds_up(wc, &format!("{what}, world {w}"));
    }
    assert_adds_up(&c.total, &format!("{what}, total"));
}

/// A virtual run of `scene` under `cfg` with schedule seed `seed`: its committed hashes and
/// the run.
fn virtual_run(
    scene: &Scene,
    cfg: &KernelConfig,
    seed: u64,
    steps: u64,
) -> (Vec<u64>, VirtualRun<soda::RigidBodyModel>) {
    let options = VirtualOptions::seeded(seed);
    let (mut run, _) = VirtualRun::new(
        scene.model(),
        scene.grid(),
        scene.initial_bodies(),
        cfg,
        &options,
    );
    let hashes = run.run(steps).iter().map(|f| f.hash).collect();
    (hashes, run)
}

#[test]
fn committed_plus_rolled_back_equals_computed_on_the_virtual_executor() {
    let mut rolled_back = 0;
    for scene in scenes() {
        for mode in MODES {
            for seed in 0..3 {
                let cfg = KernelConfig::new(6).mode(mode).window(8);
                let (_, run) = virtual_run(&scene, &cfg, seed, 40);
                let c = run.counters();
                assert_counters(&c, &format!("{} {mode:?} seed {seed}", scene.name));
                assert_eq!(c.total.steps_committed, 40 * c.worlds.len() as u64);
                rolled_back += c.total.cells_rolled_back;
            }
        }
    }
    assert!(rolled_back > 0, "the schedules produced rollbacks");
}

#[test]
fn committed_plus_rolled_back_equals_computed_on_the_threaded_executor() {
    for scene in scenes() {
        for mode in MODES {
            let cfg = KernelConfig::new(4).mode(mode).window(8);
            let r = run_threaded(
                scene.model(),
                scene.grid(),
                scene.initial_bodies(),
                &cfg,
                2,
                40,
            )
            .unwrap();
            assert_counters(&r.counters, &format!("{} {mode:?} threaded", scene.name));
        }
    }
}

#[test]
fn tracing_does_not_change_the_committed_hashes() {
    for scene in scenes() {
        for mode in MODES {
            let cfg = KernelConfig::new(5).mode(mode).window(6);
            let (plain, _) = virtual_run(&scene, &cfg, 11, 40);
            let (traced, _) = virtual_run(&scene, &cfg.clone().trace(true), 11, 40);
            assert_eq!(plain, traced, "{} {mode:?} virtual", scene.name);
            let threaded = |cfg: &KernelConfig| {
                run_threaded(
                    scene.model(),
                    scene.grid(),
                    scene.initial_bodies(),
                    cfg,
                    2,
                    40,
                )
                .unwrap()
                .frames
                .iter()
                .map(|f| f.hash)
                .collect::<Vec<_>>()
            };
            assert_eq!(threaded(&cfg), plain, "{} {mode:?} threaded", scene.name);
            assert_eq!(
                threaded(&cfg.clone().trace(true)),
                plain,
                "{} {mode:?} threaded, traced",
                scene.name
            );
        }
    }
}

#[test]
fn the_trace_agrees_with_the_counters() {
    let scene = builtin("sparse-gas", Some(80), 2).unwrap();
    let cfg = KernelConfig::new(6)
        .mode(RollbackMode::Cell)
        .window(8)
        .trace(true);
    let (_, mut run) = virtual_run(&scene, &cfg, 4, 60);
    let c = run.counters();
    let t = run.take_trace();
    assert!(c.total.rollbacks() > 0, "the schedule produced rollbacks");
    assert_eq!(t.worlds, 6);
    assert_eq!(t.owners.len(), scene.grid().cell_count());
    assert_eq!(t.rollbacks.len() as u64, c.total.rollbacks());
    let primary = t
        .rollbacks
        .iter()
        .filter(|r| r.cause == RollbackCause::Straggler)
        .count() as u64;
    assert_eq!(primary, c.total.rollbacks_primary);
    let lengths: u64 = t.rollbacks.iter().map(|r| r.length).sum();
    assert_eq!(lengths, c.total.steps_rolled_back);
    let recomputed: u64 = t.rollbacks.iter().map(|r| r.cells_recomputed).sum();
    assert_eq!(recomputed, c.total.cells_recomputed);
    let per_cell: u64 = t.recomputed_cells.iter().map(|p| p.1).sum();
    assert_eq!(per_cell, c.total.cells_recomputed);
    let positive: u64 = t.messages.iter().map(|m| m.positive).sum();
    let anti: u64 = t.messages.iter().map(|m| m.anti).sum();
    assert_eq!(positive, c.total.messages_sent);
    assert_eq!(anti, c.total.anti_messages_sent);
    assert_eq!(t.gvt.len() as u64, c.gvt_advances);
    assert!(t
        .gvt
        .windows(2)
        .all(|w| w[0].gvt < w[1].gvt && w[0].time <= w[1].time));
    for w in 0..6u32 {
        let lvts: Vec<_> = t.lvt.iter().filter(|s| s.world == w).collect();
        assert!(!lvts.is_empty(), "world {w} has LVT samples");
        assert_eq!(
            lvts.last().unwrap().lvt,
            60,
            "world {w} ends at the last step"
        );
    }
}
