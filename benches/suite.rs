//! The benchmark suite in one criterion run (issue: research instrument, item 5), at sizes
//! that make the whole suite take a few minutes on 2 cores. Compare numbers within one run:
//!
//! - `reference_step`: the reference executor, falling-cubes 1,000, 30 steps from the start;
//! - `executors`: the same run on the reference, the virtual executor (8 worlds, FIFO
//!   schedule: Time Warp overhead without rollbacks) and the threaded executor on 1 and 2
//!   threads (one world per thread);
//! - `modes`: virtual executor, 8 worlds, W 16, seeded schedule 3, sparse-gas 1,000, 30
//!   steps, cell against world against conservative;
//! - `rapier`: rapier3d (its defaults, one thread) on the same falling-cubes run.
//!
//! `cargo bench --bench suite`; `cargo bench --bench suite -- --test` runs each once.
//! Bigger, side-by-side measurements with medians: the `vs_rapier`, `timewarp` and
//! `threaded` benches and `soda experiment`.

#[allow(dead_code)]
mod common;
#[allow(dead_code)]
#[path = "common/rapier_world.rs"]
mod rapier_world;

use common::Footprint;
use criterion::measurement::WallTime;
use criterion::{
    criterion_group, criterion_main, BenchmarkGroup, Criterion, SamplingMode, Throughput,
};
use rapier_world::RapierWorld;
use soda::exec::virtual_exec::ScheduleSpec;
use soda::frame::StatesWanted;
use soda::kernel::{KernelConfig, RollbackMode};
use soda::scene::builtin::builtin;
use soda::scene::Scene;
use soda::sim::{run_scene, ExecutorKind, RunOptions};
use std::hint::black_box;
use std::time::Duration;

const CUBES: usize = 1000;
const STEPS: u64 = 30;

fn run(scene: &Scene, options: &RunOptions) -> String {
    run_scene(scene, options, STEPS, &StatesWanted::none(), |_, _| {})
        .expect("the run succeeds")
        .hash
}

fn options(executor: ExecutorKind, kernel: KernelConfig, threads: usize) -> RunOptions {
    RunOptions {
        executor,
        kernel,
        threads,
        ..RunOptions::default()
    }
}

/// A group of whole runs: flat sampling, 10 samples, throughput in body-steps.
fn group<'a>(c: &'a mut Criterion, name: &str) -> BenchmarkGroup<'a, WallTime> {
    let mut g = c.benchmark_group(name);
    g.sampling_mode(SamplingMode::Flat)
        .sample_size(10)
        .measurement_time(Duration::from_secs(5))
        .throughput(Throughput::Elements(CUBES as u64 * STEPS));
    g
}

fn suite(c: &mut Criterion) {
    let cubes = builtin("falling-cubes", Some(CUBES), 0).unwrap();
    let gas = builtin("sparse-gas", Some(CUBES), 1).unwrap();
    let reference = RunOptions::default();
    let expected = run(&cubes, &reference);

    let mut g = group(c, "reference_step");
    g.bench_function("falling_cubes_1000_30_steps", |b| {
        b.iter(|| black_box(run(&cubes, &reference)))
    });
    g.finish();

    let mut g = group(c, "executors");
    let fifo = KernelConfig::new(8);
    let runs = [
        ("reference", reference.clone()),
        (
            "virtual_8_worlds_fifo",
            options(ExecutorKind::Virtual, fifo, 1).schedule(ScheduleSpec::Fifo),
        ),
        (
            "threaded_1_thread",
            options(ExecutorKind::Threaded, KernelConfig::new(1), 1),
        ),
        (
            "threaded_2_threads",
            options(ExecutorKind::Threaded, KernelConfig::new(2), 2),
        ),
    ];
    for (name, o) in &runs {
        assert_eq!(
            run(&cubes, o),
            expected,
            "{name} commits the reference's bits"
        );
        g.bench_function(*name, |b| b.iter(|| black_box(run(&cubes, o))));
    }
    g.finish();

    let mut g = group(c, "modes");
    for mode in [
        RollbackMode::Cell,
        RollbackMode::World,
        RollbackMode::Conservative,
    ] {
        let k = KernelConfig::new(8).mode(mode).window(16);
        let o = options(ExecutorKind::Virtual, k, 1)
            .schedule(ScheduleSpec::Seeded(3))
            .record_schedule(false);
        g.bench_function(mode.name(), |b| b.iter(|| black_box(run(&gas, &o))));
    }
    g.finish();

    let mut g = group(c, "rapier");
    let initial = cubes.initial_bodies();
    let footprint = Footprint::of(&initial);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a one-thread pool");
    g.bench_function("rapier3d_1_thread_falling_cubes_1000_30_steps", |b| {
        b.iter(|| {
            pool.install(|| {
                let mut w = RapierWorld::new(&cubes, &initial, &footprint);
                for _ in 0..STEPS {
                    w.step();
                }
                black_box(w.hash())
            })
        })
    });
    g.finish();
}

criterion_group!(benches, suite);
criterion_main!(benches);
