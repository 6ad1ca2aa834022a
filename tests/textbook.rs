//! Textbook scenes a physicist checks a rigid-body engine with, each against its closed-form
//! answer: a ball rolling down an incline onto flat ground, a frictionless rod falling from
//! nearly upright, a heavy rolling ball striking a light one elastically, and a pyramid of
//! bricks that must stand. (Found passing by a battery of such scenes on 2026-11-29; the
//! ones that failed are in `docs/open-defects/`, §12–§14.) The scenes are in
//! `tests/textbook/`; `soda run --scene tests/textbook/NAME.json --record out.csv` shows them.

use soda::math::Vec3;
use soda::physics::metrics::{kinetic_energy, potential_energy};
use soda::scene::{parse_scene, SceneFormat};
use soda::sim::Simulation;
use soda::{Body, RigidBodyModel, Scene};

/// The scene `tests/textbook/{name}.json`.
fn scene(name: &str) -> Scene {
    let path = format!("{}/tests/textbook/{name}.json", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).unwrap();
    parse_scene(&text, SceneFormat::Json, &path).unwrap()
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

/// Mechanical energy (kinetic + potential, gravity along −y), J.
fn mechanical_energy(b: &Body) -> f64 {
    kinetic_energy([b]) + potential_energy([b], Vec3::new(0.0, -9.81, 0.0))
}

#[test]
fn a_ball_rolling_down_an_incline_rolls_on_the_flat_at_the_speed_angular_momentum_gives() {
    // A ball of radius r starts at rest on a 0.2 rad incline, its centre at y0. Rolling
    // without slipping, it reaches the foot at v = √(10/7·g·(y0 − r)) along the slope with
    // spin v/r; the ground takes the normal part, and friction brings it to rolling at the
    // speed that keeps its angular momentum about the contact point: v·(5·cos θ + 2)/7.
    let s = scene("incline_roll");
    let g = 9.81f64;
    let (theta, r) = (0.2f64, 0.2f64);
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
    let first = Simulation::new(s.clone())
        .state()
        .sorted::<RigidBodyModel>()
        .into_iter()
        .map(mechanical_energy)
        .sum::<f64>();
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
        let energy = mechanical_energy(rod);
        assert!(
            energy <= first * (1.0 + 1e-5),
            "step {}: mechanical energy {energy} J above the initial {first} J",
            step + 1
        );
    }
    let rod = &states.last().unwrap()[0];
    assert!(
        (rod.position.y - 0.02).abs() < 1e-3,
        "not lying flat: centre at y {}",
        rod.position.y
    );
}

#[test]
fn a_heavy_rolling_ball_strikes_a_light_one_elastically_and_both_end_rolling() {
    // A ball 8 times as heavy rolls at 2 m/s into a resting ball of the same size
    // (restitution 1, no friction between the balls): they leave at 7/9·2 and 16/9·2 m/s,
    // then the ground's friction brings each to rolling at (5·v + 2·(surface speed))/7:
    // the heavy one at (5·14/9 + 2·2)/7 = 1.6825 m/s, the light one at 5·32/9/7 = 2.5397.
    let states = run(scene("heavy_light"), 240);
    let last = states.last().unwrap();
    let heavy = (5.0 * 14.0 / 9.0 + 4.0) / 7.0;
    let light = 5.0 * 32.0 / 9.0 / 7.0;
    for (body, expected) in [(&last[0], heavy), (&last[1], light)] {
        let speed = body.linvel.x as f64;
        assert!(
            (speed - expected).abs() < 0.005 * expected,
            "ball {} rolls at {speed} m/s, expected {expected}",
            body.id()
        );
        let surface = -(body.angvel.z as f64) * 0.2;
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
