//! Throughput of the reference step on `falling-cubes` (1,000 cubes, seed 0), in body-steps
//! per second (criterion's "elements").
//!
//! - `fall_steps_0_to_90`: one iteration = steps 0..90 (1.5 simulated s: the lattice falls and
//!   its top layer lands) from the fresh scene; throughput = 1,000 × 90 body-steps.
//! - `settled_one_step`: one iteration = one step from the state after 300 steps (5 simulated
//!   s), advanced once outside the timing; throughput = 1,000 body-steps.
//!
//! - `falling-cubes-8000-asleep/all_asleep_one_step`: one iteration = one step of a run of
//!   8,000 cubes (seed 0) advanced until every body is asleep with zero velocities (checked
//!   on the state; typically 400-500 steps, ~1 minute outside the timing, only when the
//!   filter selects this case). Iterations continue the same run step after step, so each
//!   step follows an all-asleep step as in a real run; throughput = 8,000 body-steps.
//!   `cargo bench --bench reference_step -- asleep` runs this case alone.
//!
//! Every iteration of the first two starts from its own `ReferenceRun` built (outside the timing) from a copy
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

    let asleep_cubes = if steps().0 == 90 { 8000 } else { 27 };
    let mut g = c.benchmark_group(format!(
        "reference_step/falling-cubes-{asleep_cubes}-asleep"
    ));
    g.sample_size(50)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(3))
        .throughput(Throughput::Elements(asleep_cubes as u64));
    // Built once, and only when the filter selects this case (criterion calls the closure
    // for the warm-up and again for the measurement).
    let mut asleep: Option<ReferenceRun<RigidBodyModel>> = None;
    g.bench_function("all_asleep_one_step", |b| {
        let run = asleep.get_or_insert_with(|| asleep_run(asleep_cubes));
        b.iter(|| black_box(run.advance()));
        assert!(all_at_rest(run), "the pile woke up during the timing");
    });
    g.finish();
}

/// Whether every body is asleep and still (velocities exactly zero): what a frozen
/// neighbourhood keeps (SPEC.md §5.4).
fn all_at_rest(run: &ReferenceRun<RigidBodyModel>) -> bool {
    let model = run.model();
    run.state().sorted::<RigidBodyModel>().iter().all(|b| {
        model.is_asleep(b)
            && b.linvel
                .iter()
                .chain(b.angvel.iter())
                .all(|v| v.to_bits() == 0)
    })
}

/// A run of `cubes` falling cubes advanced until every body is at rest.
fn asleep_run(cubes: usize) -> ReferenceRun<RigidBodyModel> {
    let scene = builtin("falling-cubes", Some(cubes), 0).expect("falling-cubes builds");
    let mut run = run_from(&scene, scene.initial_bodies());
    while !all_at_rest(&run) {
        assert!(
            run.step_number() < 3000,
            "{cubes} cubes not asleep after 3,000 steps"
        );
        run.advance();
    }
    describe("all asleep", &run, run.step_number() as usize);
    assert_eq!(
        run.state().len(),
        cubes,
        "bodies lost before the pile slept"
    );
    run
}

criterion_group!(benches, reference_step);
criterion_main!(benches);
