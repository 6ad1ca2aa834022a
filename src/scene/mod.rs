//! Scene description: the serde data model of scene files, validation with errors that name
//! the field, the value and what is allowed, the builder API and the built-in scenes.

mod builder;
pub mod builtin;
mod error;
mod file;
pub mod inputs;
mod shape;
mod show;
mod validate;

pub use builder::SceneBuilder;
pub use error::SceneError;
pub use file::{load_scene_file, parse_scene, SceneFormat};
pub use inputs::{parse_inputs, InputAction, InputScript, ScriptedInput};

use crate::grid::Grid;
use crate::math::{Quat, Vec3};
use crate::physics::{
    Body, DomainBox, Environment, Material, Plane, RigidBodyModel, Shape, SolverParams,
    StaticCuboid,
};
use serde::{Deserialize, Serialize};

/// A complete scene: physics constants, domain, static environment and bodies.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// A name for reports.
    #[serde(default = "default_name")]
    pub name: String,
    /// Seed for anything random derived from the scene.
    #[serde(default)]
    pub seed: u64,
    /// Seconds per step.
    #[serde(default = "default_dt")]
    pub dt: f32,
    /// Gravity, m/s².
    #[serde(default = "default_gravity")]
    pub gravity: [f32; 3],
    /// The bounded domain: bodies whose centre leaves it are removed (a `left-domain` event).
    pub domain: Domain,
    /// Override of the derived cell edge (must be at least the derived one).
    #[serde(default)]
    pub cell_edge: Option<f32>,
    /// Static environment.
    #[serde(default)]
    pub environment: EnvironmentSpec,
    /// Solver parameters.
    #[serde(default)]
    pub solver: SolverParams,
    /// The dynamic bodies.
    #[serde(default)]
    pub bodies: Vec<BodySpec>,
}

fn default_name() -> String {
    "scene".into()
}
fn default_dt() -> f32 {
    1.0 / 60.0
}
fn default_gravity() -> [f32; 3] {
    [0.0, -9.81, 0.0]
}

/// The axis-aligned box bodies live in.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Domain {
    /// Lower corner.
    pub min: [f32; 3],
    /// Upper corner.
    pub max: [f32; 3],
}

/// The static environment as written in a scene.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EnvironmentSpec {
    /// Height of a ground plane (normal +y), if any.
    pub ground: Option<f32>,
    /// Walls on the domain's four vertical faces.
    pub walls: bool,
    /// A ceiling on the domain's top face.
    pub ceiling: bool,
    /// Friction of static surfaces.
    pub friction: f32,
    /// Restitution of static surfaces.
    pub restitution: f32,
    /// Static boxes.
    pub cuboids: Vec<StaticCuboidSpec>,
}

impl Default for EnvironmentSpec {
    fn default() -> Self {
        EnvironmentSpec {
            ground: Some(0.0),
            walls: false,
            ceiling: false,
            friction: 0.5,
            restitution: 0.0,
            cuboids: Vec::new(),
        }
    }
}

/// A static box as written in a scene.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StaticCuboidSpec {
    /// Centre.
    pub position: [f32; 3],
    /// Half extents.
    pub half_extents: [f32; 3],
    /// Rotation as intrinsic roll, pitch, yaw (radians about x, y, z).
    #[serde(default)]
    pub rotation: [f32; 3],
}

/// A dynamic body as written in a scene.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BodySpec {
    /// Unique id.
    pub id: u64,
    /// Shape.
    #[serde(deserialize_with = "shape::deserialize")]
    pub shape: Shape,
    /// Material.
    #[serde(default)]
    pub material: Material,
    /// Centre.
    pub position: [f32; 3],
    /// Rotation as roll, pitch, yaw (radians about x, y, z).
    #[serde(default)]
    pub rotation: [f32; 3],
    /// Linear velocity.
    #[serde(default)]
    pub velocity: [f32; 3],
    /// Angular velocity.
    #[serde(default)]
    pub angular_velocity: [f32; 3],
}

fn euler(r: [f32; 3]) -> Quat {
    Quat::from_euler_angles(r[0], r[1], r[2])
}

impl BodySpec {
    /// The body this spec describes, with its velocities.
    pub fn to_body(&self) -> Body {
        let mut b = Body::new(
            self.id,
            self.shape,
            self.material,
            self.position.into(),
            euler(self.rotation),
        );
        b.linvel = self.velocity.into();
        b.angvel = self.angular_velocity.into();
        b
    }
}

impl Scene {
    /// The cell model of this scene.
    pub fn model(&self) -> RigidBodyModel {
        let env = &self.environment;
        let (lo, hi) = (Vec3::from(self.domain.min), Vec3::from(self.domain.max));
        let mut planes = Vec::new();
        if let Some(y) = env.ground {
            planes.push(Plane {
                normal: Vec3::y(),
                offset: y,
            });
        }
        if env.walls {
            planes.push(Plane {
                normal: Vec3::x(),
                offset: lo.x,
            });
            planes.push(Plane {
                normal: -Vec3::x(),
                offset: -hi.x,
            });
            planes.push(Plane {
                normal: Vec3::z(),
                offset: lo.z,
            });
            planes.push(Plane {
                normal: -Vec3::z(),
                offset: -hi.z,
            });
        }
        if env.ceiling {
            planes.push(Plane {
                normal: -Vec3::y(),
                offset: -hi.y,
            });
        }
        let cuboids = env
            .cuboids
            .iter()
            .map(|c| StaticCuboid {
                pose: crate::math::pose(c.position.into(), euler(c.rotation)),
                half_extents: c.half_extents.into(),
            })
            .collect();
        RigidBodyModel {
            dt: self.dt,
            gravity: self.gravity.into(),
            params: self.solver,
            environment: Environment {
                planes,
                cuboids,
                friction: env.friction,
                restitution: env.restitution,
            },
            domain: DomainBox { min: lo, max: hi },
            max_radius: self.max_radius().max(0.05),
        }
    }

    /// Largest bounding radius of any body (0 if none).
    pub fn max_radius(&self) -> f32 {
        self.bodies
            .iter()
            .map(|b| b.shape.bounding_radius())
            .fold(0.0, f32::max)
    }

    /// The cell edge the locality contract requires (SPEC.md §Grid), or the override.
    pub fn cell_edge(&self) -> f32 {
        let derived = self.model().required_cell_edge(self.max_radius().max(0.05));
        self.cell_edge.unwrap_or(derived).max(derived)
    }

    /// The grid over the domain.
    pub fn grid(&self) -> Grid {
        Grid::covering(
            self.domain.min.into(),
            self.domain.max.into(),
            self.cell_edge(),
        )
    }

    /// The bodies' initial states, sorted by id, with the support depths of bodies placed
    /// resting on the environment or on each other (SPEC.md §5.2): a stack placed at rest
    /// stands from its first step.
    pub fn initial_bodies(&self) -> Vec<Body> {
        let mut v: Vec<Body> = self.bodies.iter().map(BodySpec::to_body).collect();
        v.sort_by_key(|b| b.id());
        self.model().set_initial_support_depths(&mut v);
        v
    }
}
