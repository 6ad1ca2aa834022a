//! Throughput of the reference step on `falling-cubes` (1,000 cubes, seed 0), in body-steps
//! per second (criterion's "elements").
//!
//! - `fall_steps_0_to_90`: one iteration = steps 0..90 (1.5 simulated s: the lattice falls and
//!   its top layer lands) from the fresh scene; throughput = 1,000 × 90 body-steps.
//! - `settled_one_step`: one iteration = one step from the state after 300 steps (5 simulated
//!   s), advanced once outside the timing; throughput = 1,000 body-steps.
//!
//! Every iteration starts from its own `ReferenceRun` built (outside the timing) from a copy
//! of the bodies. All of a body's state lives in `Body` (contact history included, if the
//! model carries any), so this continues the run exactly; only the step counter restarts at
//! 0, which affects event labels, not physics. Before timing, the bench prints what the
//! states it times look like (bodies, max speed, exact penetration), so a "settled" pile
//! that is not settled shows.
//!
//! Run: `cargo bench --bench reference_step`. Sample counts are small (the whole bench takes
//! about a minute on 2 cores); the machine is shared, so expect noise of several percent.

use criterion::{criterion_group, criterion_main, BatchSize, Criterion, SamplingMode, Throughput};
use soda::physics::{Body, RigidBodyModel};
use soda::scene::builtin::builtin;
use soda::scene::Scene;
use soda::ReferenceRun;
use std::hint::black_box;
use std::time::Duration;

const CUBES: usize = 1000;

/// `(fall steps, settle steps)`: the real ones when cargo benchmarks (it passes `--bench`),
/// a few steps when `cargo test --benches` or `cargo bench -- --test` only checks that the
/// bench runs.
fn steps() -> (usize, usize) {
    let args: Vec<String> = std::env::args().collect();
    if args.iter().any(|a| a == "--bench") && !args.iter().any(|a| a == "--test") {
        (90, 300)
    } else {
        (3, 5)
    }
}

fn run_from(scene: &Scene, bodies: Vec<Body>) -> ReferenceRun<RigidBodyModel> {
    ReferenceRun::new(scene.model(), scene.grid(), bodies).0
}

fn bodies_of(run: &ReferenceRun<RigidBodyModel>) -> Vec<Body> {
    run.state()
        .sorted::<RigidBodyModel>()
        .into_iter()
        .cloned()
        .collect()
}

fn describe(label: &str, run: &ReferenceRun<RigidBodyModel>, step: usize) {
    let r = soda::sim::measure(run);
    eprintln!(
        "reference_step: {label} state (step {step}): {} bodies, max speed {:.4} m/s, \
         exact max penetration {:.5} m, highest centre {:.3} m, hash {}{}",
        r.bodies,
        r.max_speed,
        r.max_penetration,
        r.max_height,
        r.hash,
        if r.max_speed > 0.2 {
            " (NOT at rest: max speed above 0.2 m/s)"
        } else {
            ""
        }
    );
}

fn reference_step(c: &mut Criterion) {
    let (fall_steps, settle_steps) = steps();
    let scene = builtin("falling-cubes", Some(CUBES), 0).expect("falling-cubes builds");
    let fresh = scene.initial_bodies();

    // The settled state, advanced once outside the timing.
    let mut run = run_from(&scene, fresh.clone());
    for step in 0..settle_steps {
        if step == fall_steps {
            describe("end of fall", &run, step);
        }
        run.advance();
    }
    describe("settled", &run, settle_steps);
    let settled = bodies_of(&run);

    let mut g = c.benchmark_group(format!("reference_step/falling-cubes-{CUBES}"));
    g.sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .sampling_mode(SamplingMode::Flat);

    // Ten iterations of 90 steps take ~20 s at the time of writing; the target only keeps
    // criterion from warning, it still runs the 10 samples whatever it is.
    g.measurement_time(Duration::from_secs(20));

    g.throughput(Throughput::Elements((fresh.len() * fall_steps) as u64));
    g.bench_function(format!("fall_steps_0_to_{fall_steps}"), |b| {
        b.iter_batched(
            || run_from(&scene, fresh.clone()),
            |mut run| {
                for _ in 0..fall_steps {
                    black_box(run.advance());
                }
                run
            },
            BatchSize::PerIteration,
        )
    });

    g.throughput(Throughput::Elements(settled.len() as u64));
    g.measurement_time(Duration::from_secs(5));
    g.bench_function(format!("settled_one_step_after_{settle_steps}"), |b| {
        b.iter_batched(
            || run_from(&scene, settled.clone()),
            |mut run| {
                black_box(run.advance());
                run
            },
            BatchSize::LargeInput,
        )
    });
    g.finish();
}

criterion_group!(benches, reference_step);
criterion_main!(benches);
