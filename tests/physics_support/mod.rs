//! Random settling scenes (issue 23): piles and ball gases, shared by the physics-law tests
//! (`tests/physics_laws.rs`) and the quality bench (`benches/quality.rs`), so that both
//! measure the same scenes.

use soda::physics::{Material, Shape};
use soda::scene::BodySpec;
use soda::{Scene, SceneBuilder};

/// What [`lattice_pile`] draws for one body after its position: shape, material, rotation.
pub type DrawBody = fn(&mut rand_chacha::ChaCha8Rng) -> (Shape, Material, [f32; 3]);

/// `count` bodies dropped from a lattice of 5 × 5 per layer, 0.8 m apart, into a walled
/// 4 m × 4 m box under gravity (static friction 0.5, restitution 0.3). Per body, in this
/// order: the x and z jitter (within ±`jitter`), what `draw` draws, a velocity within ±1 m/s
/// per axis.
pub fn lattice_pile(seed: u64, count: u64, jitter: f32, draw: DrawBody) -> Scene {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut b = SceneBuilder::new([0.0; 3], [4.0, 8.0, 4.0])
        .walls(true, false)
        .environment_material(0.5, 0.3);
    for k in 0..count {
        let c = [k % 5, k / 25, (k / 5) % 5].map(|c| c as f32);
        let mut jitter = || rng.random_range(-jitter..jitter);
        let position = [
            0.4 + 0.8 * c[0] + jitter(),
            0.5 + 0.8 * c[1],
            0.4 + 0.8 * c[2] + jitter(),
        ];
        let (shape, material, rotation) = draw(&mut rng);
        b = b.body_spec(BodySpec {
            id: k,
            shape,
            material,
            position,
            rotation,
            velocity: [0, 1, 2].map(|_| rng.random_range(-1.0f32..1.0)),
            angular_velocity: [0.0; 3],
        });
    }
    b.build().unwrap()
}

/// 225 balls of random radii (0.2–0.35 m) and densities, dropped from a 9-layer lattice
/// into a walled 4 m × 4 m box under gravity (friction 0.5, restitution 0.3).
pub fn ball_pile(seed: u64) -> Scene {
    use rand::Rng;
    lattice_pile(seed, 225, 0.05, |rng| {
        let shape = Shape::Ball {
            radius: rng.random_range(0.2f32..0.35),
        };
        let material = Material {
            density: rng.random_range(0.5f32..2.0),
            friction: 0.5,
            restitution: 0.3,
        };
        (shape, material, [0.0; 3])
    })
}

/// 150 balls and boxes of random sizes, densities, frictions (0.2–0.8), restitutions (0–0.6)
/// and orientations, dropped in a walled 4 m box from a lattice.
pub fn mixed_pile(seed: u64) -> Scene {
    use rand::Rng;
    lattice_pile(seed, 150, 0.015, |rng| {
        let shape = if rng.random_bool(0.5) {
            Shape::Ball {
                radius: rng.random_range(0.15f32..0.35),
            }
        } else {
            Shape::Cuboid {
                half_extents: [0, 1, 2].map(|_| rng.random_range(0.12f32..0.21)),
            }
        };
        let material = Material {
            density: rng.random_range(0.5f32..2.0),
            friction: rng.random_range(0.2f32..0.8),
            restitution: rng.random_range(0.0f32..0.6),
        };
        (
            shape,
            material,
            [0, 1, 2].map(|_| rng.random_range(-3.0f32..3.0)),
        )
    })
}

/// 512 balls of radius 0.3 m (density 1) on a lattice 1 m apart, jittered by up to 0.1 m per
/// axis, in a walled and closed 8 m box, each with a velocity within ±3 m/s per axis; under
/// gravity unless `gravity` is false. The quality bench's ball gases.
pub fn ball_box(seed: u64, restitution: f32, friction: f32, gravity: bool) -> Scene {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut b = SceneBuilder::new([0.0; 3], [8.0; 3])
        .walls(true, true)
        .environment_material(friction, restitution);
    if !gravity {
        b = b.gravity([0.0; 3]);
    }
    for k in 0..512u64 {
        let c = [k % 8, (k / 8) % 8, k / 64].map(|c| c as f32 + 0.5);
        let mut jit = || rng.random_range(-0.1f32..=0.1);
        let position = [c[0] + jit(), c[1] + jit(), c[2] + jit()];
        b = b.body_spec(BodySpec {
            id: k,
            shape: Shape::Ball { radius: 0.3 },
            material: Material {
                density: 1.0,
                friction,
                restitution,
            },
            position,
            rotation: [0.0; 3],
            velocity: [0, 1, 2].map(|_| rng.random_range(-3.0f32..=3.0)),
            angular_velocity: [0.0; 3],
        });
    }
    b.build().unwrap()
}
