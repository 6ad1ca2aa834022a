//! A builder for scenes in code.

use super::validate::validate;
use super::{BodySpec, Domain, EnvironmentSpec, Scene, SceneError, StaticCuboidSpec};
use crate::physics::{Material, Shape, SolverParams};

/// Builds a [`Scene`] step by step; [`SceneBuilder::build`] validates it.
#[derive(Clone, Debug)]
pub struct SceneBuilder {
    scene: Scene,
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

    /// Adds a body at rest with id = number of bodies added so far; returns its id.
    pub fn body(
        &mut self,
        shape: Shape,
        material: Material,
        position: [f32; 3],
        rotation: [f32; 3],
    ) -> u64 {
        let id = self.scene.bodies.len() as u64;
        self.scene.bodies.push(BodySpec {
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
        self.scene.bodies.push(spec);
        self
    }

    /// Sets the velocity of the body with `id` (no effect if absent).
    pub fn velocity(&mut self, id: u64, v: [f32; 3]) {
        if let Some(b) = self.scene.bodies.iter_mut().find(|b| b.id == id) {
            b.velocity = v;
        }
    }

    /// Validates and returns the scene.
    pub fn build(self) -> Result<Scene, SceneError> {
        validate(&self.scene, "<builder>")?;
        Ok(self.scene)
    }
}
