//! A builder for scenes in code.

use super::validate::validate;
use super::{BodySpec, Domain, EnvironmentSpec, Scene, SceneError, StaticCuboidSpec};
use crate::physics::{Material, Shape, SolverParams};
use std::collections::BTreeMap;

/// Builds a [`Scene`] step by step; [`SceneBuilder::build`] validates it.
///
/// Adding a body and setting a velocity take (amortised) constant or logarithmic time, so
/// building a scene of a million bodies is linear in its size.
#[derive(Clone, Debug)]
pub struct SceneBuilder {
    scene: Scene,
    /// Where bodies are found by id: [`Ids::Positions`] while every body's id is its index
    /// (what [`SceneBuilder::body`] assigns), else an index of each id's first body.
    ids: Ids,
}

/// How [`SceneBuilder`] finds a body by id.
#[derive(Clone, Debug)]
enum Ids {
    /// Every body's id equals its index in the body list.
    Positions,
    /// Each id's first index in the body list (ordered, so nothing depends on hashing).
    Index(BTreeMap<u64, usize>),
}

impl SceneBuilder {
    /// A scene over the box `[min, max]` with a ground at y = 0, gravity −9.81 m/s² and
    /// dt = 1/60 s.
    pub fn new(min: [f32; 3], max: [f32; 3]) -> Self {
        SceneBuilder {
            scene: Scene {
                name: "scene".into(),
                seed: 0,
                dt: 1.0 / 60.0,
                gravity: [0.0, -9.81, 0.0],
                domain: Domain { min, max },
                cell_edge: None,
                environment: EnvironmentSpec::default(),
                solver: SolverParams::default(),
                bodies: Vec::new(),
            },
            ids: Ids::Positions,
        }
    }

    /// Sets the name.
    pub fn name(mut self, name: &str) -> Self {
        self.scene.name = name.into();
        self
    }

    /// Sets the seed.
    pub fn seed(mut self, seed: u64) -> Self {
        self.scene.seed = seed;
        self
    }

    /// Sets seconds per step.
    pub fn dt(mut self, dt: f32) -> Self {
        self.scene.dt = dt;
        self
    }

    /// Sets gravity.
    pub fn gravity(mut self, g: [f32; 3]) -> Self {
        self.scene.gravity = g;
        self
    }

    /// Sets (or removes) the ground height.
    pub fn ground(mut self, y: Option<f32>) -> Self {
        self.scene.environment.ground = y;
        self
    }

    /// Closes the domain's vertical faces with walls, and its top if `ceiling`.
    pub fn walls(mut self, walls: bool, ceiling: bool) -> Self {
        self.scene.environment.walls = walls;
        self.scene.environment.ceiling = ceiling;
        self
    }

    /// Sets the static surfaces' friction and restitution.
    pub fn environment_material(mut self, friction: f32, restitution: f32) -> Self {
        self.scene.environment.friction = friction;
        self.scene.environment.restitution = restitution;
        self
    }

    /// Adds a static box.
    pub fn static_cuboid(
        mut self,
        position: [f32; 3],
        half_extents: [f32; 3],
        rotation: [f32; 3],
    ) -> Self {
        self.scene.environment.cuboids.push(StaticCuboidSpec {
            position,
            half_extents,
            rotation,
        });
        self
    }

    /// Sets the solver parameters.
    pub fn solver(mut self, params: SolverParams) -> Self {
        self.scene.solver = params;
        self
    }

    /// Makes room for `additional` more bodies (what a builder of a known size calls first,
    /// so that a million bodies are not copied each time the list doubles).
    pub fn reserve(&mut self, additional: usize) {
        self.scene.bodies.reserve_exact(additional);
    }

    /// Adds a body at rest with id = number of bodies added so far; returns its id.
    pub fn body(
        &mut self,
        shape: Shape,
        material: Material,
        position: [f32; 3],
        rotation: [f32; 3],
    ) -> u64 {
        let id = self.scene.bodies.len() as u64;
        self.push(BodySpec {
            id,
            shape,
            material,
            position,
            rotation,
            velocity: [0.0; 3],
            angular_velocity: [0.0; 3],
        });
        id
    }

    /// Adds a fully specified body.
    pub fn body_spec(mut self, spec: BodySpec) -> Self {
        self.push(spec);
        self
    }

    /// Sets the velocity of the first body added with `id` (no effect if absent).
    pub fn velocity(&mut self, id: u64, v: [f32; 3]) {
        if let Some(i) = self.index_of(id) {
            self.scene.bodies[i].velocity = v;
        }
    }

    /// Appends `spec` and keeps `ids` up to date.
    fn push(&mut self, spec: BodySpec) {
        let index = self.scene.bodies.len();
        self.scene.bodies.push(spec);
        match &mut self.ids {
            Ids::Positions if spec.id == index as u64 => {}
            Ids::Positions => {
                let mut map = BTreeMap::new();
                for (i, b) in self.scene.bodies.iter().enumerate() {
                    map.entry(b.id).or_insert(i);
                }
                self.ids = Ids::Index(map);
            }
            Ids::Index(map) => {
                map.entry(spec.id).or_insert(index);
            }
        }
    }

    /// The index of the first body with `id`, if any.
    fn index_of(&self, id: u64) -> Option<usize> {
        match &self.ids {
            Ids::Positions => usize::try_from(id)
                .ok()
                .filter(|&i| i < self.scene.bodies.len()),
            Ids::Index(map) => map.get(&id).copied(),
        }
    }

    /// Validates and returns the scene.
    pub fn build(self) -> Result<Scene, SceneError> {
        validate(&self.scene, "<builder>")?;
        Ok(self.scene)
    }
}

#[cfg(test)]
mod tests {
    use super::SceneBuilder;
    use crate::physics::{Material, Shape};
    use crate::scene::BodySpec;

    fn ball(id: u64, x: f32) -> BodySpec {
        BodySpec {
            id,
            shape: Shape::Ball { radius: 0.1 },
            material: Material::default(),
            position: [x, 1.0, 0.0],
            rotation: [0.0; 3],
            velocity: [0.0; 3],
            angular_velocity: [0.0; 3],
        }
    }

    #[test]
    fn velocities_land_on_their_ids_among_a_hundred_thousand_bodies_set_in_any_order() {
        let n = 100_000u64;
        let side = 50;
        let mut b = SceneBuilder::new([0.0; 3], [side as f32; 3]).ground(None);
        for k in 0..n {
            let c = [k % side, (k / side) % side, k / (side * side)];
            let id = b.body(
                Shape::Ball { radius: 0.2 },
                Material::default(),
                c.map(|c| c as f32 + 0.5),
                [0.0; 3],
            );
            assert_eq!(id, k);
        }
        // Descending, so a search from either end of the list would be quadratic.
        for id in (0..n).rev() {
            b.velocity(id, [id as f32 * 1e-5, 0.0, 0.0]);
        }
        b.velocity(n, [9.0; 3]);
        let scene = b.build().unwrap();
        assert_eq!(scene.bodies.len(), n as usize);
        for (k, body) in scene.bodies.iter().enumerate() {
            assert_eq!(body.id, k as u64);
            assert_eq!(body.velocity, [k as f32 * 1e-5, 0.0, 0.0]);
        }
    }

    #[test]
    fn velocities_land_on_the_first_body_of_an_id_whatever_ids_were_added() {
        let mut b = SceneBuilder::new([-10.0; 3], [10.0; 3])
            .body_spec(ball(0, 0.0))
            .body_spec(ball(7, 1.0))
            .body_spec(ball(5, 2.0));
        // `body` takes the next index as id: 3, which nothing else has.
        let three = b.body(
            Shape::Ball { radius: 0.1 },
            Material::default(),
            [3.0, 1.0, 0.0],
            [0.0; 3],
        );
        assert_eq!(three, 3);
        let mut b = b.body_spec(ball(7, 4.0));
        b.velocity(7, [1.0, 0.0, 0.0]);
        b.velocity(5, [2.0, 0.0, 0.0]);
        b.velocity(3, [3.0, 0.0, 0.0]);
        b.velocity(0, [4.0, 0.0, 0.0]);
        b.velocity(1, [5.0, 0.0, 0.0]); // no such body
        let v: Vec<(u64, f32)> = b
            .scene
            .bodies
            .iter()
            .map(|s| (s.id, s.velocity[0]))
            .collect();
        assert_eq!(v, [(0, 4.0), (7, 1.0), (5, 2.0), (3, 3.0), (7, 0.0)]);
    }
}
