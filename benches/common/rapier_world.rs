//! rapier3d's world for `falling-cubes`, shared by the benches that compare with Rapier: the
//! newest release (rapier3d 0.36, the `rapier3d_new` dev-dependency, built with its
//! `parallel` feature), the same bodies as SODA's scene, a fixed ground cuboid whose top is
//! the scene's ground, Rapier's default integration parameters with the scene's `dt`.
//! Rapier runs on the rayon pool it is stepped in: a one-thread pool for single-threaded
//! comparisons.

use crate::common::{Footprint, PileBody};
use rapier3d_new::math::{Pose, Rotation, Vector};
use rapier3d_new::prelude::{ColliderBuilder, PhysicsWorld, RigidBodyBuilder, RigidBodyHandle};
use soda::physics::{Body, Shape};
use soda::scene::Scene;

/// A Rapier world built from a SODA scene.
pub struct RapierWorld {
    world: PhysicsWorld,
    handles: Vec<RigidBodyHandle>,
}

fn v(x: soda::math::Vec3) -> Vector {
    Vector::new(x.x, x.y, x.z)
}

/// Inserts SODA's body `b` into `world` as a dynamic Rapier body with the same pose,
/// velocities, shape, mass, friction and restitution; returns its handle.
pub fn insert_body(world: &mut PhysicsWorld, b: &Body) -> RigidBodyHandle {
    let q = b.rotation.quaternion();
    let rb = RigidBodyBuilder::dynamic()
        .pose(Pose::from_parts(
            v(b.position),
            Rotation::from_xyzw(q.i, q.j, q.k, q.w),
        ))
        .linvel(v(b.linvel))
        .angvel(v(b.angvel));
    let shape = match b.shape() {
        Shape::Cuboid { half_extents: e } => ColliderBuilder::cuboid(e[0], e[1], e[2]),
        Shape::Ball { radius } => ColliderBuilder::ball(radius),
    };
    world
        .insert(
            rb,
            shape
                .density(b.mass() / b.shape().volume())
                .friction(b.friction())
                .restitution(b.restitution()),
        )
        .0
}

impl RapierWorld {
    /// The scene's bodies and ground in Rapier.
    pub fn new(scene: &Scene, initial: &[Body], footprint: &Footprint) -> Self {
        let mut world = PhysicsWorld::new();
        world.gravity = Vector::new(scene.gravity[0], scene.gravity[1], scene.gravity[2]);
        world.integration_parameters.dt = scene.dt;
        let ground_y = scene
            .environment
            .ground
            .expect("falling-cubes has a ground");
        let half = 50.0f32
            .max(2.0 * footprint.max[0].abs())
            .max(2.0 * footprint.min[0].abs())
            .max(2.0 * footprint.max[1].abs())
            .max(2.0 * footprint.min[1].abs());
        world.insert_collider(
            ColliderBuilder::cuboid(half, 1.0, half)
                .translation(Vector::new(0.0, ground_y - 1.0, 0.0))
                .friction(scene.environment.friction)
                .restitution(scene.environment.restitution),
            None,
        );
        let handles = initial.iter().map(|b| insert_body(&mut world, b)).collect();
        RapierWorld { world, handles }
    }

    /// One step.
    pub fn step(&mut self) {
        self.world.step();
    }

    /// FNV-1a over the bits of every body's translation and rotation, in insertion order.
    pub fn hash(&self) -> u64 {
        let mut h = 0xcbf2_9ce4_8422_2325u64;
        for &hd in &self.handles {
            let rb = &self.world.bodies[hd];
            let (t, q) = (rb.translation(), *rb.rotation());
            for x in [t.x, t.y, t.z, q.x, q.y, q.z, q.w] {
                for byte in x.to_bits().to_le_bytes() {
                    h = (h ^ byte as u64).wrapping_mul(0x0100_0000_01b3);
                }
            }
        }
        h
    }

    /// The final pile, for the shared measurements.
    pub fn pile(&self, initial: &[Body]) -> Vec<PileBody> {
        self.handles
            .iter()
            .zip(initial)
            .map(|(&hd, b)| {
                let rb = &self.world.bodies[hd];
                let (t, q, lv) = (rb.translation(), *rb.rotation(), rb.linvel());
                PileBody {
                    shape: b.shape(),
                    position: soda::math::Vec3::new(t.x, t.y, t.z),
                    rotation: soda::math::Quat::from_quaternion(nalgebra::Quaternion::new(
                        q.w, q.x, q.y, q.z,
                    )),
                    linvel: soda::math::Vec3::new(lv.x, lv.y, lv.z),
                }
            })
            .collect()
    }

    /// Bodies asleep.
    pub fn asleep(&self) -> usize {
        self.handles
            .iter()
            .filter(|&&h| self.world.bodies[h].is_sleeping())
            .count()
    }
}
