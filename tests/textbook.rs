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
        assert!(
            b.linvel.norm() < 1e-3 && b.angvel.norm() < 1e-3,
            "brick {} still moves: v {:?}, ω {:?}",
            b.id(),
            b.linvel,
            b.angvel
        );
    }
}
