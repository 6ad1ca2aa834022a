//! Stacks placed at rest in a scene (SPEC.md §5.2, support depths of the initial state): they
//! stand from their first step instead of falling into themselves while the support depth
//! spreads up one body per step.

use soda::physics::{Material, Shape};
use soda::sim::Simulation;
use soda::{RigidBodyModel, SceneBuilder};

/// A column of `height` unit cubes standing exactly touching on the ground, under `gravity`.
fn column(height: usize, gravity: f32) -> soda::Scene {
    let top = height as f32 + 2.0;
    let mut b =
        SceneBuilder::new([-3.0, -1.0, -3.0], [3.0, top, 3.0]).gravity([0.0, -gravity, 0.0]);
    for k in 0..height {
        b.body(
            Shape::Cuboid {
                half_extents: [0.5, 0.5, 0.5],
            },
            Material::default(),
            [0.0, 0.5 + k as f32, 0.0],
            [0.0; 3],
        );
    }
    b.build().unwrap()
}

/// The deepest overlap of two neighbouring cubes of the column (by their centres' heights).
fn deepest_overlap(sim: &Simulation) -> f32 {
    let all = sim.state().sorted::<RigidBodyModel>();
    all.windows(2)
        .map(|w| 1.0 - (w[1].position.y - w[0].position.y))
        .fold(0.0f32, f32::max)
}

#[test]
fn a_column_placed_at_rest_stands_from_its_first_step() {
    for (height, gravity) in [(15usize, 9.81f32), (25, 9.81), (5, 30.0), (5, 300.0)] {
        let mut sim = Simulation::new(column(height, gravity));
        let mut worst = 0.0f32;
        let mut fastest = 0.0f32;
        for _ in 0..120 {
            sim.step();
            worst = worst.max(deepest_overlap(&sim));
            for b in sim.state().sorted::<RigidBodyModel>() {
                fastest = fastest.max(b.linvel.norm());
            }
        }
        assert!(
            worst < 0.01,
            "{height} cubes at {gravity} m/s²: neighbours overlapped by {worst} m"
        );
        assert!(
            fastest < 0.1,
            "{height} cubes at {gravity} m/s²: a cube reached {fastest} m/s"
        );
        let all = sim.state().sorted::<RigidBodyModel>();
        let top = all.last().unwrap().position.y;
        let expected = height as f32 - 0.5;
        assert!(
            (top - expected).abs() < 0.01,
            "{height} cubes at {gravity} m/s²: the top cube's centre is at {top} m, not {expected}"
        );
    }
}
