//! Textbook scenes a physicist checks a rigid-body engine with, each against its closed-form
//! answer: a ball rolling down an incline onto flat ground, a frictionless rod falling from
//! nearly upright, a heavy rolling ball striking a light one elastically, and a pyramid of
//! bricks that must stand. (Found passing by a battery of such scenes on 2026-11-29; the
//! ones that failed are in `docs/open-defects/`, §12–§14.) The scenes are in
//! `tests/textbook/`; `soda run --scene tests/textbook/NAME.json --record out.csv` shows them.

use soda::math::Vec3;
use soda::physics::metrics::{kinetic_energy, potential_energy};
use soda::physics::Shape;
use soda::scene::load_scene_file;
use soda::sim::Simulation;
use soda::{Body, RigidBodyModel, Scene};

/// The scene `tests/textbook/{name}.json`.
fn scene(name: &str) -> Scene {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/textbook")
        .join(format!("{name}.json"));
    load_scene_file(&path).unwrap()
}

/// The radius of a ball.
fn radius(shape: Shape) -> f64 {
    match shape {
        Shape::Ball { radius } => radius as f64,
        Shape::Cuboid { .. } => panic!("not a ball: {shape:?}"),
    }
}

/// The bodies after every step, steps `1..=steps`, sorted by id.
fn run(scene: Scene, steps: u32) -> Vec<Vec<Body>> {
    let mut sim = Simulation::new(scene);
    (0..steps)
        .map(|_| {
            sim.step();
            sim.state()
                .sorted::<RigidBodyModel>()
                .into_iter()
                .cloned()
                .collect()
        })
        .collect()
}

/// Panics unless every body moves slower than 1 mm/s and turns slower than 1 mrad/s.
fn assert_at_rest(bodies: &[Body]) {
    for b in bodies {
        assert!(
            b.linvel.norm() < 1e-3 && b.angvel.norm() < 1e-3,
            "body {} still moves: v {:?}, ω {:?}",
            b.id(),
            b.linvel,
            b.angvel
        );
    }
}

/// Mechanical energy (kinetic + potential under `gravity`), J.
fn mechanical_energy(b: &Body, gravity: [f32; 3]) -> f64 {
    kinetic_energy([b]) + potential_energy([b], Vec3::from(gravity))
}

#[test]
fn a_ball_rolling_down_an_incline_rolls_on_the_flat_at_the_speed_angular_momentum_gives() {
    // A ball of radius r starts at rest on a 0.2 rad incline, its centre at y0. Rolling
    // without slipping, it reaches the foot at v = √(10/7·g·(y0 − r)) along the slope with
    // spin v/r; the ground takes the normal part, and friction brings it to rolling at the
    // speed that keeps its angular momentum about the contact point: v·(5·cos θ + 2)/7.
    let s = scene("incline_roll");
    let g = -s.gravity[1] as f64;
    // The incline is the scene's one static box, tilted about z.
    let theta = s.environment.cuboids[0].rotation[2].abs() as f64;
    let r = radius(s.bodies[0].shape);
    let y0 = s.bodies[0].position[1] as f64;
    let along = (10.0 / 7.0 * g * (y0 - r)).sqrt();
    let expected = along * (5.0 * theta.cos() + 2.0) / 7.0;
    let states = run(s, 240);
    let last = &states.last().unwrap()[0];
    assert!(
        (last.position.y as f64 - r).abs() < 1e-3,
        "not on the flat: y {}",
        last.position.y
    );
    let speed = last.linvel.norm() as f64;
    let surface = (last.angvel.norm() as f64) * r;
    assert!(
        (speed - expected).abs() < 0.01 * expected,
        "rolls at {speed} m/s on the flat, expected {expected}"
    );
    assert!(
        (speed - surface).abs() < 1e-3,
        "not rolling: {speed} m/s against a surface speed of {surface}"
    );
}

#[test]
fn a_frictionless_rod_falling_from_nearly_upright_keeps_its_centre_on_the_vertical_and_lands_flat()
{
    // No horizontal force acts on a rod on frictionless ground: its centre of mass falls
    // straight down. It lands flat, and its mechanical energy never grows.
    let s = scene("rod_fall");
    let x0 = s.bodies[0].position[0];
    let Shape::Cuboid { half_extents } = s.bodies[0].shape else {
        panic!("the rod is a box");
    };
    // Lying flat on the ground, its centre is at its smallest half extent.
    let flat = half_extents.into_iter().fold(f32::INFINITY, f32::min);
    let gravity = s.gravity;
    let first = mechanical_energy(&s.initial_bodies()[0], gravity);
    let states = run(s, 180);
    for (step, bodies) in states.iter().enumerate() {
        let rod = &bodies[0];
        assert!(
            (rod.position.x - x0).abs() < 1e-5 && rod.position.z.abs() < 1e-5,
            "step {}: the centre moved sideways to ({}, {})",
            step + 1,
            rod.position.x,
            rod.position.z
        );
        let energy = mechanical_energy(rod, gravity);
        assert!(
            energy <= first * (1.0 + 1e-5),
            "step {}: mechanical energy {energy} J above the initial {first} J",
            step + 1
        );
    }
    let rod = &states.last().unwrap()[0];
    assert!(
        (rod.position.y - flat).abs() < 1e-3,
        "not lying flat: centre at y {}",
        rod.position.y
    );
}

#[test]
fn a_heavy_rolling_ball_strikes_a_light_one_elastically_and_both_end_rolling() {
    // A ball M/m = 8 times as heavy rolls at v into a resting ball of the same size
    // (restitution 1, no friction between the balls): they leave at (M − m)/(M + m)·v and
    // 2M/(M + m)·v, keeping their spins; then the ground's friction brings each to rolling
    // at (5·u + 2·(surface speed))/7, which keeps its angular momentum about its contact
    // point: here the heavy one at 1.6825 m/s and the light one at 2.5397.
    let s = scene("heavy_light");
    let (striker, struck) = (&s.bodies[0], &s.bodies[1]);
    let r = radius(striker.shape);
    assert_eq!(r, radius(struck.shape), "the formula is for equal balls");
    let ratio = (striker.material.density / struck.material.density) as f64;
    let v = striker.velocity[0] as f64;
    let surface = -(striker.angular_velocity[2] as f64) * r;
    let heavy = (5.0 * (ratio - 1.0) / (ratio + 1.0) * v + 2.0 * surface) / 7.0;
    let light = 5.0 * 2.0 * ratio / (ratio + 1.0) * v / 7.0;
    let states = run(s, 240);
    let last = states.last().unwrap();
    for (body, expected) in [(&last[0], heavy), (&last[1], light)] {
        let speed = body.linvel.x as f64;
        assert!(
            (speed - expected).abs() < 0.005 * expected,
            "ball {} rolls at {speed} m/s, expected {expected}",
            body.id()
        );
        let surface = -(body.angvel.z as f64) * r;
        assert!(
            (speed - surface).abs() < 1e-3,
            "ball {} is not rolling: {speed} m/s against a surface speed of {surface}",
            body.id()
        );
    }
}

#[test]
fn a_pyramid_of_bricks_stands_still() {
    // Three bricks on the ground, two on them, one on top, 1 mm apart: nothing moves beyond
    // closing those gaps.
    let s = scene("pyramid");
    let initial: Vec<[f32; 3]> = s.bodies.iter().map(|b| b.position).collect();
    let states = run(s, 120);
    let last = states.last().unwrap();
    for (b, p0) in last.iter().zip(&initial) {
        let moved = ((b.position.x - p0[0]).powi(2)
            + (b.position.y - p0[1]).powi(2)
            + (b.position.z - p0[2]).powi(2))
        .sqrt();
        assert!(moved < 1e-3, "brick {} moved {moved} m", b.id());
    }
    assert_at_rest(last);
}

/// A body's mass, kg.
fn mass(b: &soda::scene::BodySpec) -> f64 {
    let volume = match b.shape {
        Shape::Ball { radius } => 4.0 / 3.0 * std::f64::consts::PI * (radius as f64).powi(3),
        Shape::Cuboid { half_extents } => half_extents.iter().map(|&h| 2.0 * h as f64).product(),
    };
    b.material.density as f64 * volume
}

/// The lever's angular acceleration about the static fulcrum's right top edge with every
/// body of `s` riding on the plank rigidly: gravity's torque over the moments of inertia
/// about that edge, rad/s² (clockwise positive).
fn rigid_lever_rate(s: &Scene) -> f64 {
    let g = -s.gravity[1] as f64;
    let fulcrum = &s.environment.cuboids[0];
    let pivot = [
        (fulcrum.position[0] + fulcrum.half_extents[0]) as f64,
        (fulcrum.position[1] + fulcrum.half_extents[1]) as f64,
    ];
    let (mut torque, mut inertia) = (0.0, 0.0);
    for b in &s.bodies {
        let Shape::Cuboid { half_extents: h } = b.shape else {
            panic!("the lever's bodies are boxes");
        };
        let m = mass(b);
        let (x, y) = (
            b.position[0] as f64 - pivot[0],
            b.position[1] as f64 - pivot[1],
        );
        torque += m * g * x;
        inertia += m * ((h[0] as f64).powi(2) + (h[1] as f64).powi(2)) / 3.0 + m * (x * x + y * y);
    }
    torque / inertia
}

#[test]
fn a_seesaw_with_a_heavy_and_a_light_box_tips_at_the_rigid_rate_with_both_on_it() {
    // A 128 kg box on the right end of the balanced plank and a 32 kg box on its left end:
    // the plank turns with both boxes on it at the rigid rate (both bodies resting on it
    // load it, and neither is a wall it stops against), the light box rising with it.
    let s = scene("seesaw");
    let dt = s.dt as f64;
    let alpha = rigid_lever_rate(&s);
    let states = run(s, 20);
    for step in [10usize, 20] {
        for b in &states[step - 1] {
            assert_turns_at_rigid_rate(b, alpha, step, dt);
        }
    }
}

/// Panics unless `body`, after `steps` steps of `dt` from rest, turns (clockwise about z)
/// within 5 % of `alpha·steps·dt`, the rigid rate.
fn assert_turns_at_rigid_rate(body: &Body, alpha: f64, steps: usize, dt: f64) {
    let spin = -body.angvel.z as f64;
    let expected = alpha * steps as f64 * dt;
    assert!(
        (spin - expected).abs() < 0.05 * expected,
        "step {steps}: body {} turns at {spin} rad/s, expected {expected} (α = {alpha} rad/s²)",
        body.id()
    );
}

#[test]
fn a_box_on_the_end_of_a_balanced_plank_tips_the_lever_at_the_rigid_rate() {
    // A plank balanced on a static box, a heavy box resting on its right end: the plank
    // turns about the fulcrum's right top edge with the box on it, at α = τ/I about that
    // edge (gravity's torque on both bodies over both moments of inertia about it), until
    // its end reaches the ground; then both rest. (Before the load of SPEC.md §5.2 nothing
    // moved: the plank never felt the box.)
    let s = scene("lever");
    let dt = s.dt as f64;
    let alpha = rigid_lever_rate(&s);
    let states = run(s, 240);
    assert_turns_at_rigid_rate(&states[9][0], alpha, 10, dt);
    let plank = &states[39][0];
    let lowest = plank
        .shape()
        .vertices()
        .iter()
        .map(|v| (plank.position + plank.rotation * v).y)
        .fold(f32::INFINITY, f32::min);
    assert!(
        lowest < 0.01,
        "the plank's end is {lowest} m above the ground at step 40"
    );
    let last = states.last().unwrap();
    assert_at_rest(last);
    assert!(
        last[1].position.x > 1.0 && last[1].position.x < 1.5,
        "the box left the plank's end: x {}",
        last[1].position.x
    );
}

#[test]
fn a_box_thrown_under_a_resting_box_brakes_at_three_mu_g_and_drags_it_at_mu_g() {
    // Two equal boxes stacked on the ground, friction μ everywhere. Stack one: the lower box
    // is thrown at 3 m/s under the upper one: the ground brakes it with μ·2mg and the upper
    // box with μ·mg, so it decelerates at 3μg while the upper one speeds up at μg, until
    // they move together. Stack two: the upper box is thrown at 2 m/s over the lower one:
    // it decelerates at μg, and the lower one, whose ground friction can hold up to μ·2mg,
    // stays put. Neither pair's momentum ever grows (only the ground takes it).
    let s = scene("stack_slide");
    let mu = s.bodies[0].material.friction as f64; // the ground's is the same
    let g = -s.gravity[1] as f64;
    let dt = s.dt as f64;
    let v0 = [
        s.bodies[0].velocity[0] as f64,
        s.bodies[3].velocity[0] as f64,
    ];
    let states = run(s, 60);
    let at = |step: usize, id: usize| states[step - 1][id].linvel.x as f64;
    let steps = 6.0;
    let lower = (v0[0] - at(6, 0)) / (steps * dt);
    let dragged = at(6, 1) / (steps * dt);
    let braked = (v0[1] - at(6, 3)) / (steps * dt);
    for (what, value, expected) in [
        ("the thrown lower box's deceleration", lower, 3.0 * mu * g),
        ("the upper box's acceleration", dragged, mu * g),
        ("the thrown upper box's deceleration", braked, mu * g),
    ] {
        assert!(
            (value - expected).abs() < 0.03 * expected,
            "{what}: {value} m/s², expected {expected}"
        );
    }
    let mut momentum = [v0[0], v0[1]];
    for (step, bodies) in states.iter().enumerate() {
        assert!(
            bodies[2].linvel.norm() < 1e-3,
            "step {}: the lower box of stack two moves at {:?}",
            step + 1,
            bodies[2].linvel
        );
        for (k, pair) in [(0, [0, 1]), (1, [2, 3])] {
            let p = pair.iter().map(|&i| bodies[i].linvel.x as f64).sum::<f64>();
            assert!(
                p <= momentum[k] + 1e-3,
                "step {}: stack {}'s momentum rose from {} to {p} (per unit mass)",
                step + 1,
                k + 1,
                momentum[k]
            );
            momentum[k] = p;
        }
    }
}

#[test]
fn a_frictionless_ball_rolling_off_another_pushes_it_away() {
    // A ball balanced 1 mm off the top of an equal ball, nothing with friction: the two
    // push each other apart, so their horizontal momentum stays 0 while they touch; they
    // part at cos θ = 0.732 with 0.620 m/s each. (Before the load of SPEC.md §5.2 the lower
    // ball never moved and the upper one left at 1.108 m/s.) Measured: −0.612 and +0.673 m/s;
    // the momentum's rest is 9.5 % of one ball's, from the step the two part.
    let s = scene("ball_on_ball");
    let states = run(s, 120);
    let last = states.last().unwrap();
    let (a, b) = (last[0].linvel.x, last[1].linvel.x);
    assert!(
        a < -0.55 && b > 0.55,
        "the balls move apart at {a} and {b} m/s, expected about ∓0.62"
    );
    for (step, bodies) in states.iter().enumerate() {
        let (a, b) = (bodies[0].linvel.x, bodies[1].linvel.x);
        assert!(
            (a + b).abs() <= 0.15 * a.abs().max(b.abs()) + 1e-4,
            "step {}: the pair's horizontal momentum is {} per unit mass, the balls {a} and {b} m/s",
            step + 1,
            a + b
        );
    }
}

#[test]
fn load_systems_commit_the_reference_bits_on_every_executor_and_rollback_mode() {
    // Twelve load systems (SPEC.md §5.2) spread over 7 × 2 × 5 cells — levers on static
    // fulcrums, boxes thrown under boxes with a ball on top, balls rolling off balls — so
    // that systems span cells and worlds: every schedule, thread interleaving and rollback
    // mode commits the reference's hash at every step (a load system is read from the cells
    // both bodies' cells contain, and `may_affect` covers its three contacts).
    use soda::prelude::*;
    let s = scene("load_mix");
    let setup = VerifySetup::new(s.model(), s.grid(), s.initial_bodies());
    let options = VerifyOptions {
        steps: 120,
        schedules: 4,
        repeats: 1,
        threads: 2,
        kernel: KernelConfig::new(6).window(16),
        ..VerifyOptions::default()
    };
    let report = soda::verify::verify(&setup, &options);
    assert!(report.passed(), "{}", report.summary());
}
