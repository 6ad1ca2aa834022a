//! Shared helpers of the kernel tests: reference frames, comparison with the kernel's
//! committed frames, and the random cases of the equivalence property.
#![allow(dead_code)]

use proptest::prelude::*;
use soda::exec::virtual_exec::{VirtualOptions, VirtualRun};
use soda::kernel::synthetic::{Particle, Particles};
use soda::kernel::{Counters, GhostPolicy, KernelConfig, PartitionKind, PlantedBug, RollbackMode};
use soda::scene::builtin::builtin;
use soda::{Body, CellModel, Frame, Grid, ReferenceRun, RigidBodyModel};

/// The reference frames 1..=steps.
pub fn reference<M: CellModel + Clone>(
    model: &M,
    grid: &Grid,
    init: &[M::State],
    steps: u64,
) -> Vec<Frame<M::Event>> {
    let (mut r, _) = ReferenceRun::new(model.clone(), grid.clone(), init.to_vec());
    (0..steps).map(|_| r.advance()).collect()
}

/// Runs the kernel and compares every committed frame with `expected`; on a mismatch,
/// returns a message naming the first differing step, the configuration and the replay
/// schedule.
pub fn compare<M: CellModel + Clone>(
    model: &M,
    grid: &Grid,
    init: &[M::State],
    config: &KernelConfig,
    options: &VirtualOptions,
    expected: &[Frame<M::Event>],
) -> Result<Counters, String> {
    let (mut run, _) = VirtualRun::new(model.clone(), grid.clone(), init.to_vec(), config, options);
    let frames = run.run(expected.len() as u64);
    if frames.len() != expected.len() {
        return Err(format!(
            "{} frames, expected {}",
            frames.len(),
            expected.len()
        ));
    }
    for (a, b) in frames.iter().zip(expected) {
        if a != b {
            return Err(format!(
                "first divergence at step {}: kernel hash {:016x} ({} bodies, {} events) vs \
                 reference {:016x} ({} bodies, {} events)\nconfig: {config:?}\noptions: {options:?}\n\
                 replay with ScheduleSpec::Replay(parse_schedule(..)): {}",
                b.step,
                a.hash,
                a.bodies,
                a.events.len(),
                b.hash,
                b.bodies,
                b.events.len(),
                run.schedule_string()
            ));
        }
    }
    Ok(run.counters())
}

/// A small scene of either model.
#[derive(Clone, Debug)]
pub enum SceneCase {
    /// Synthetic particles: count, grid dims, open x faces, seed.
    Particles(usize, [i32; 3], bool, u64),
    /// A built-in rigid-body scene: name, bodies, seed.
    Builtin(&'static str, usize, u64),
}

/// One case of the equivalence property.
#[derive(Clone, Debug)]
pub struct Case {
    pub scene: SceneCase,
    pub steps: u64,
    pub worlds: usize,
    pub mode: RollbackMode,
    pub window: u64,
    pub partition: PartitionKind,
    pub partition_seed: u64,
    pub schedule_seed: u64,
    pub ghosts: GhostPolicy,
    /// Worlds compute their interior ahead after each action (`VirtualOptions::compute_ahead`).
    pub compute_ahead: bool,
}

impl Case {
    pub fn config(&self, bug: PlantedBug) -> KernelConfig {
        let mut c = KernelConfig::new(self.worlds)
            .mode(self.mode)
            .window(self.window)
            .partition(self.partition.clone())
            .partition_seed(self.partition_seed)
            .ghosts(self.ghosts);
        c.planted_bug = bug;
        c
    }

    /// The virtual executor's options: the case's schedule seed.
    pub fn options(&self) -> VirtualOptions {
        VirtualOptions::seeded(self.schedule_seed).compute_ahead(self.compute_ahead)
    }
}

pub fn mode() -> impl Strategy<Value = RollbackMode> {
    prop_oneof![
        Just(RollbackMode::Cell),
        Just(RollbackMode::World),
        Just(RollbackMode::Conservative)
    ]
}

pub fn partition() -> impl Strategy<Value = PartitionKind> {
    prop_oneof![
        Just(PartitionKind::Blocks),
        Just(PartitionKind::EqualBlocks),
        Just(PartitionKind::KMeans),
        Just(PartitionKind::Random)
    ]
}

pub fn window() -> impl Strategy<Value = u64> {
    prop_oneof![Just(1u64), Just(2), 3u64..8, Just(64)]
}

/// Synthetic-particle scenes: up to 60 particles in up to 6×4×4 cells.
pub fn particle_scene() -> impl Strategy<Value = SceneCase> {
    (
        2usize..60,
        2i32..7,
        1i32..5,
        1i32..5,
        any::<bool>(),
        any::<u64>(),
    )
        .prop_map(|(n, x, y, z, open, seed)| SceneCase::Particles(n, [x, y, z], open, seed))
}

/// Small built-in rigid-body scenes.
pub fn rigid_scene() -> impl Strategy<Value = SceneCase> {
    prop_oneof![
        (8usize..28, 0u64..1000).prop_map(|(n, s)| SceneCase::Builtin("sparse-gas", n, s)),
        (4usize..20, 0u64..1000).prop_map(|(n, s)| SceneCase::Builtin("falling-cubes", n, s)),
        (4usize..12, 0u64..1000).prop_map(|(n, s)| SceneCase::Builtin("chain", n, s)),
        (4usize..16, 0u64..1000).prop_map(|(n, s)| SceneCase::Builtin("dense-pile", n, s)),
    ]
}

pub fn case(
    scene: impl Strategy<Value = SceneCase>,
    steps: std::ops::Range<u64>,
) -> impl Strategy<Value = Case> {
    (
        scene,
        steps,
        2usize..=16,
        mode(),
        window(),
        partition(),
        any::<u64>(),
        any::<u64>(),
        prop_oneof![Just(GhostPolicy::Delta), Just(GhostPolicy::Full)],
        any::<bool>(),
    )
        .prop_map(
            |(
                scene,
                steps,
                worlds,
                mode,
                window,
                partition,
                partition_seed,
                schedule_seed,
                ghosts,
                compute_ahead,
            )| Case {
                scene,
                steps,
                worlds,
                mode,
                window,
                partition,
                partition_seed,
                schedule_seed,
                ghosts,
                compute_ahead,
            },
        )
}

/// The equivalence property: every committed frame equals the reference's.
///
/// With `KERNEL_TRACE` set, prints every case with its wall time, cell computations and
/// scheduler decisions (to find slow or stuck cases).
pub fn property(case: &Case, bug: PlantedBug) -> Result<Counters, String> {
    let t0 = std::time::Instant::now();
    if std::env::var("KERNEL_TRACE").is_ok() {
        eprintln!("start {:?}", case);
    }
    let r = property_inner(case, bug);
    if std::env::var("KERNEL_TRACE").is_ok() {
        eprintln!(
            "{:?} {:.3}s {:?}",
            case,
            t0.elapsed().as_secs_f64(),
            r.as_ref().map(|c| (c.total.cells_computed, c.decisions))
        );
    }
    r
}

fn property_inner(case: &Case, bug: PlantedBug) -> Result<Counters, String> {
    property_with(case, &case.config(bug), &case.options())
}

/// The equivalence property for `case`'s scene and steps under an explicit configuration
/// and schedule.
pub fn property_with(
    case: &Case,
    config: &KernelConfig,
    options: &VirtualOptions,
) -> Result<Counters, String> {
    match case.scene {
        SceneCase::Particles(n, dims, open, seed) => {
            let (m, g, b): (Particles, Grid, Vec<Particle>) = Particles::scene(n, dims, open, seed);
            let exp = reference(&m, &g, &b, case.steps);
            compare(&m, &g, &b, config, options, &exp)
        }
        SceneCase::Builtin(name, n, seed) => {
            let s = builtin(name, Some(n), seed).expect("built-in scene");
            let (m, g, b): (RigidBodyModel, Grid, Vec<Body>) =
                (s.model(), s.grid(), s.initial_bodies());
            let exp = reference(&m, &g, &b, case.steps);
            compare(&m, &g, &b, config, options, &exp)
        }
    }
}
