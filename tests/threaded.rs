//! The threaded executor commits exactly the reference's frames, whatever the thread count,
//! world count, partition and rollback mode, and fails cleanly when a world panics.

use soda::exec::reference::ReferenceRun;
use soda::exec::sync::StdFacade;
use soda::exec::threaded::{
    run_threaded, run_threaded_with, ExecError, ThreadedOptions, ThreadedSetup,
};
use soda::frame::Event;
use soda::grid::Grid;
use soda::hash::StateHash;
use soda::kernel::{KernelConfig, PartitionKind, RollbackMode};
use soda::model::{BodyId, CellModel, Neighbourhood, Step};
use soda::scene::builtin::{builtin, BUILTINS};

fn small(name: &str) -> usize {
    match name {
        "chain" => 12,
        "dense-pile" => 32,
        _ => 27,
    }
}

fn reference_hashes(scene: &soda::Scene, steps: u64) -> Vec<u64> {
    let (mut run, _) = ReferenceRun::new(scene.model(), scene.grid(), scene.initial_bodies());
    (0..steps).map(|_| run.advance().hash).collect()
}

#[test]
fn threaded_run_matches_reference_bitwise_for_every_builtin_thread_count_world_count_and_mode() {
    let steps = 40;
    for b in BUILTINS {
        let scene = builtin(b.name, Some(small(b.name)), 1).unwrap();
        let expected = reference_hashes(&scene, steps);
        for (k, &threads) in [1usize, 2, 4].iter().enumerate() {
            for (j, &worlds) in [1usize, 3, 8, 16].iter().enumerate() {
                let mode = [
                    RollbackMode::Cell,
                    RollbackMode::World,
                    RollbackMode::Conservative,
                ][(k + j + b.name.len()) % 3];
                let partition = if (k + j) % 2 == 0 {
                    PartitionKind::Blocks
                } else {
                    PartitionKind::KMeans
                };
                let config = KernelConfig::new(worlds)
                    .mode(mode)
                    .window(1 + (j as u64 * 7) % 20)
                    .partition(partition.clone());
                let report = run_threaded(
                    scene.model(),
                    scene.grid(),
                    scene.initial_bodies(),
                    &config,
                    threads,
                    steps,
                )
                .unwrap_or_else(|e| panic!("{}: {e}", b.name));
                let got: Vec<u64> = report.frames.iter().map(|f| f.hash).collect();
                assert_eq!(
                    got, expected,
                    "{} threads={threads} worlds={worlds} mode={mode:?} partition={partition:?}",
                    b.name
                );
            }
        }
    }
}

#[test]
fn repeated_threaded_runs_in_every_mode_match_the_reference() {
    let scene = builtin("sparse-gas", Some(64), 5).unwrap();
    let expected = reference_hashes(&scene, 60);
    for mode in [
        RollbackMode::Cell,
        RollbackMode::World,
        RollbackMode::Conservative,
    ] {
        for _ in 0..3 {
            let config = KernelConfig::new(8)
                .mode(mode)
                .window(16)
                .partition(PartitionKind::Random);
            let report = run_threaded(
                scene.model(),
                scene.grid(),
                scene.initial_bodies(),
                &config,
                2,
                60,
            )
            .unwrap();
            assert_eq!(
                report.frames.iter().map(|f| f.hash).collect::<Vec<_>>(),
                expected,
                "mode {mode:?}"
            );
            let c = &report.counters.total;
            assert!(report.frames.len() == 60);
            if mode == RollbackMode::Conservative {
                assert_eq!(c.steps_rolled_back, 0, "conservative rolled back");
            }
        }
    }
}

/// A planted body: id, position, the steps it has lived, and the count at which its hash
/// panics (0: never).
type PlantedBody = (BodyId, [f32; 3], u32, u32);

/// The grid and bodies of the planted-panic tests: an 8 m cube of 1 m cells and 64 bodies,
/// one per cell of its bottom layer, whose hash panics once they have lived
/// `unhashable_at` steps (0: never).
fn planted_lattice(unhashable_at: u32) -> (Grid, Vec<PlantedBody>) {
    let grid = Grid::covering(
        soda::math::Vec3::zeros(),
        soda::math::Vec3::new(8.0, 8.0, 8.0),
        1.0,
    );
    let bodies = (0..64)
        .map(|i| {
            let at = [0.5 + (i % 8) as f32, 0.5 + (i / 8) as f32, 0.5];
            (i, at, 0, unhashable_at)
        })
        .collect();
    (grid, bodies)
}

/// A synthetic model with planted panics (the test-only hooks): its step panics at
/// `step_panics_at`, and hashing a body panics at the count the body carries (met while a
/// committed frame is finished, not in a world's step; `hash_state` has no `self`).
#[derive(Clone)]
struct Planted {
    step_panics_at: Option<Step>,
}

impl CellModel for Planted {
    type State = PlantedBody;
    type Event = soda::LeftGrid;
    fn id(s: &Self::State) -> BodyId {
        s.0
    }
    fn position(s: &Self::State) -> [f32; 3] {
        s.1
    }
    fn step_cell(
        &self,
        step: Step,
        _grid: &Grid,
        nb: &Neighbourhood<'_, Self::State>,
        out: &mut Vec<Self::State>,
        _events: &mut Vec<Event<soda::LeftGrid>>,
    ) {
        if Some(step) == self.step_panics_at {
            panic!("planted panic at step {step}");
        }
        out.extend(nb.own().iter().map(|&(id, p, n, bad)| (id, p, n + 1, bad)));
    }
    fn hash_state(s: &Self::State, h: &mut StateHash) {
        assert!(s.3 == 0 || s.2 != s.3, "planted hash panic");
        h.u32(s.2);
    }
}

/// The step whose states the hash test cannot hash.
const UNHASHABLE_STEP: u32 = 5;

#[test]
fn a_panic_while_hashing_a_frame_ends_the_run_with_an_error_naming_the_step() {
    let (grid, bodies) = planted_lattice(UNHASHABLE_STEP);
    // With balancing every 5 steps the panic meets the end of an epoch: the failure must
    // not be lost when the next epoch starts.
    let balancing = soda::kernel::BalanceConfig {
        period: u64::from(UNHASHABLE_STEP),
        backoff: false,
        ..soda::kernel::BalanceConfig::on()
    };
    for threads in [1, 2] {
        for config in [
            KernelConfig::new(2).window(8),
            KernelConfig::new(2).window(8).balance(balancing.clone()),
        ] {
            // The sink never gets a frame after the one that failed: the steps it is
            // handed run 1, 2, … without a gap, and stop before the unhashable step.
            let mut handed = Vec::new();
            let err = run_threaded_with::<_, StdFacade>(
                ThreadedSetup::new(
                    Planted {
                        step_panics_at: None,
                    },
                    grid.clone(),
                    bodies.clone(),
                ),
                &ThreadedOptions::new(&config, threads, 40),
                |f, _| handed.push(f.step),
            )
            .unwrap_err();
            let contiguous: Vec<u64> = (1..=handed.len() as u64).collect();
            assert_eq!(handed, contiguous, "frames handed to the sink");
            assert!(
                handed.len() < UNHASHABLE_STEP as usize,
                "a frame at or after the unhashable step reached the sink: {handed:?}"
            );
            let text = err.to_string();
            assert!(matches!(err, ExecError::Thread(_)), "{text}");
            assert!(
                text.contains("finishing the frame of step 5 panicked"),
                "{text}"
            );
            assert!(text.contains("planted hash panic"), "{text}");
        }
    }
}

#[test]
fn a_panicking_world_ends_the_run_with_an_error_naming_world_and_step() {
    let (grid, bodies) = planted_lattice(0);
    for threads in [1, 2, 4] {
        let config = KernelConfig::new(4).window(8);
        let err = run_threaded(
            Planted {
                step_panics_at: Some(5),
            },
            grid.clone(),
            bodies.clone(),
            &config,
            threads,
            20,
        )
        .unwrap_err();
        match &err {
            ExecError::WorldPanicked {
                step,
                message,
                world,
            } => {
                assert!(*world < 4);
                assert_eq!(*step, 5, "{err}");
                assert!(message.contains("planted panic"), "{err}");
            }
            other => panic!("unexpected error {other}"),
        }
        assert!(err.to_string().contains("world"));
    }
}

#[test]
fn threaded_runs_with_balancing_on_match_the_reference_bitwise() {
    use soda::kernel::{BalanceConfig, LoadSource};
    let steps = 60;
    for (name, n) in [("skewed", 64), ("sparse-gas", 48), ("falling-cubes", 27)] {
        let scene = builtin(name, Some(n), 2).unwrap();
        let expected = reference_hashes(&scene, steps);
        for (k, load) in [
            LoadSource::Measured,
            LoadSource::CellsComputed,
            LoadSource::Seeded(k_seed(name)),
        ]
        .into_iter()
        .enumerate()
        {
            for threads in [1usize, 2, 3] {
                let mode = [
                    RollbackMode::Cell,
                    RollbackMode::World,
                    RollbackMode::Conservative,
                ][(k + threads) % 3];
                // Seeded (random) loads are shared between all 8 worlds so they force moves;
                // the others share between the threads (the threaded default).
                let workers = if matches!(load, LoadSource::Seeded(_)) {
                    8
                } else {
                    0
                };
                // Every other case backs off while balanced (the default).
                let backoff = k % 2 == 1;
                // Every other run opens with a round at step 0 (the default).
                let opening = threads % 2 == 1;
                let balance = BalanceConfig {
                    period: 3 + k as u64 * 4,
                    backoff,
                    opening,
                    load,
                    workers,
                    ..BalanceConfig::on()
                };
                let config = KernelConfig::new(8).mode(mode).window(8).balance(balance);
                let report = run_threaded(
                    scene.model(),
                    scene.grid(),
                    scene.initial_bodies(),
                    &config,
                    threads,
                    steps,
                )
                .unwrap_or_else(|e| panic!("{name}: {e}"));
                let got: Vec<u64> = report.frames.iter().map(|f| f.hash).collect();
                assert_eq!(got, expected, "{name} {load:?} threads={threads} {mode:?}");
                let b = &report.counters.balance;
                let every_period = (steps - 1) / (3 + k as u64 * 4) + opening as u64;
                if backoff {
                    assert!(
                        (1..=every_period).contains(&b.rounds),
                        "{name} {load:?}: {} rounds with backoff",
                        b.rounds
                    );
                } else {
                    assert_eq!(b.rounds, every_period, "{name} {load:?}");
                }
                if matches!(load, LoadSource::Seeded(_)) {
                    assert!(b.cells_moved > 0, "{name}: seeded loads moved no cell");
                }
            }
        }
    }
}

fn k_seed(name: &str) -> u64 {
    name.len() as u64 * 7919
}

#[test]
fn threaded_runs_with_a_laggard_lead_speculate_and_still_match_the_reference_bitwise() {
    // A lead lets worlds compute past slower neighbours, predicting unchanged ghosts (delta
    // ghosts): on a moving scene some predictions are wrong and roll back, and the committed
    // bits must not care.
    for (name, n) in [("falling-cubes", 125), ("sparse-gas", 200)] {
        let scene = builtin(name, Some(n), 3).unwrap();
        let expected = reference_hashes(&scene, 40);
        let mut rolled_back = 0;
        for lead in [1, 4, 16] {
            for _ in 0..2 {
                let config = KernelConfig::new(6).window(16);
                let report = run_threaded_with::<_, StdFacade>(
                    ThreadedSetup::new(scene.model(), scene.grid(), scene.initial_bodies()),
                    &ThreadedOptions::new(&config, 2, 40).lead(lead),
                    |_, _| {},
                )
                .unwrap();
                assert_eq!(
                    report.frames.iter().map(|f| f.hash).collect::<Vec<_>>(),
                    expected,
                    "{name} lead {lead}"
                );
                rolled_back += report.counters.total.steps_rolled_back;
            }
        }
        eprintln!("{name}: {rolled_back} steps rolled back over the lead runs");
    }
}

/// An event whose clone panics when it carries `FRAGILE`: a user's event type with a
/// faulty `Clone`. Worlds clone committed events when they hand them to the frame assembly,
/// outside the computation a world's panic is caught in.
#[derive(Debug, PartialEq, Eq, PartialOrd, Ord)]
struct FragileEvent(u32);

const FRAGILE: u32 = 7;

impl Clone for FragileEvent {
    fn clone(&self) -> Self {
        assert!(self.0 != FRAGILE, "planted event clone panic");
        FragileEvent(self.0)
    }
}

impl From<soda::LeftGrid> for FragileEvent {
    fn from(_: soda::LeftGrid) -> Self {
        FragileEvent(0)
    }
}

/// [`Planted`]'s lattice, with one fragile event raised by body 0 at `step`.
#[derive(Clone)]
struct FragileEvents {
    step: Step,
}

impl CellModel for FragileEvents {
    type State = PlantedBody;
    type Event = FragileEvent;
    fn id(s: &Self::State) -> BodyId {
        s.0
    }
    fn position(s: &Self::State) -> [f32; 3] {
        s.1
    }
    fn step_cell(
        &self,
        step: Step,
        _grid: &Grid,
        nb: &Neighbourhood<'_, Self::State>,
        out: &mut Vec<Self::State>,
        events: &mut Vec<Event<FragileEvent>>,
    ) {
        for &(id, p, n, bad) in nb.own() {
            if id == 0 && step == self.step {
                events.push(Event {
                    step,
                    body: id,
                    kind: FragileEvent(FRAGILE),
                });
            }
            out.push((id, p, n + 1, bad));
        }
    }
    fn hash_state(s: &Self::State, h: &mut StateHash) {
        h.u32(s.2);
    }
}

#[test]
fn a_panic_outside_a_worlds_computation_ends_the_run_with_an_error_instead_of_hanging() {
    let (grid, bodies) = planted_lattice(0);
    for threads in [1, 2] {
        let config = KernelConfig::new(2).window(8);
        let (done, finished) = std::sync::mpsc::channel();
        let (grid, bodies) = (grid.clone(), bodies.clone());
        std::thread::spawn(move || {
            let result = run_threaded(
                FragileEvents { step: 5 },
                grid,
                bodies,
                &config,
                threads,
                30,
            );
            let _ = done.send(result.map(|r| r.frames.len()));
        });
        let result = finished
            .recv_timeout(std::time::Duration::from_secs(60))
            .unwrap_or_else(|_| panic!("the run with {threads} threads hung after a panic"));
        let err = result.expect_err("a planted panic must fail the run");
        let text = err.to_string();
        assert!(matches!(err, ExecError::Thread(_)), "{text}");
        assert!(text.contains("planted event clone panic"), "{text}");
    }
}
