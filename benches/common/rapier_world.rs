//! rapier3d's world for `falling-cubes`, shared by the benches that compare with Rapier:
//! the same bodies as SODA's scene, a fixed ground cuboid whose top is the scene's ground,
//! Rapier's default integration parameters with the scene's `dt`.

use crate::common::{Footprint, PileBody};
use rapier3d::prelude::*;
use soda::physics::{Body, Shape};
use soda::scene::Scene;

/// A Rapier world built from a SODA scene.
pub struct RapierWorld {
    gravity: Vector<Real>,
    params: IntegrationParameters,
    pipeline: PhysicsPipeline,
    islands: IslandManager,
    broad_phase: DefaultBroadPhase,
    narrow_phase: NarrowPhase,
    bodies: RigidBodySet,
    colliders: ColliderSet,
    impulse_joints: ImpulseJointSet,
    multibody_joints: MultibodyJointSet,
    ccd: CCDSolver,
    handles: Vec<RigidBodyHandle>,
}

impl RapierWorld {
    /// The scene's bodies and ground in Rapier.
    pub fn new(scene: &Scene, initial: &[Body], footprint: &Footprint) -> Self {
        let mut bodies = RigidBodySet::new();
        let mut colliders = ColliderSet::new();
        let ground_y = scene
            .environment
            .ground
            .expect("falling-cubes has a ground");
        let half = 50.0f32
            .max(2.0 * footprint.max[0].abs())
            .max(2.0 * footprint.min[0].abs())
            .max(2.0 * footprint.max[1].abs())
            .max(2.0 * footprint.min[1].abs());
        colliders.insert(
            ColliderBuilder::cuboid(half, 1.0, half)
                .translation(vector![0.0, ground_y - 1.0, 0.0])
                .friction(scene.environment.friction)
                .restitution(scene.environment.restitution),
        );
        let mut handles = Vec::with_capacity(initial.len());
        for b in initial {
            let rb = RigidBodyBuilder::dynamic()
                .pose(Isometry::from_parts(b.position.into(), b.rotation))
                .linvel(b.linvel)
                .angvel(b.angvel);
            let h = bodies.insert(rb);
            let shape = match b.shape {
                Shape::Cuboid { half_extents: e } => ColliderBuilder::cuboid(e[0], e[1], e[2]),
                Shape::Ball { radius } => ColliderBuilder::ball(radius),
            };
            colliders.insert_with_parent(
                shape
                    .density(b.mass() / b.shape.volume())
                    .friction(b.friction)
                    .restitution(b.restitution),
                h,
                &mut bodies,
            );
            handles.push(h);
        }
        let params = IntegrationParameters {
            dt: scene.dt,
            ..IntegrationParameters::default()
        };
        RapierWorld {
            gravity: Vector::from(scene.gravity),
            params,
            pipeline: PhysicsPipeline::new(),
            islands: IslandManager::new(),
            broad_phase: DefaultBroadPhase::new(),
            narrow_phase: NarrowPhase::new(),
            bodies,
            colliders,
            impulse_joints: ImpulseJointSet::new(),
            multibody_joints: MultibodyJointSet::new(),
            ccd: CCDSolver::new(),
            handles,
        }
    }

    /// One step.
    pub fn step(&mut self) {
        self.pipeline.step(
            &self.gravity,
            &self.params,
            &mut self.islands,
            &mut self.broad_phase,
            &mut self.narrow_phase,
            &mut self.bodies,
            &mut self.colliders,
            &mut self.impulse_joints,
            &mut self.multibody_joints,
            &mut self.ccd,
            &(),
            &(),
        );
    }

    /// FNV-1a over the bits of every body's translation and rotation, in insertion order.
    pub fn hash(&self) -> u64 {
        let mut h = 0xcbf2_9ce4_8422_2325u64;
        for &hd in &self.handles {
            let p = self.bodies[hd].position();
            let t = p.translation.vector;
            let q = p.rotation.coords;
            for v in [t.x, t.y, t.z, q.x, q.y, q.z, q.w] {
                for byte in v.to_bits().to_le_bytes() {
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
                let rb = &self.bodies[hd];
                PileBody {
                    shape: b.shape,
                    position: rb.position().translation.vector,
                    rotation: rb.position().rotation,
                    linvel: *rb.linvel(),
                }
            })
            .collect()
    }
}

impl RapierWorld {
    /// Bodies asleep.
    pub fn asleep(&self) -> usize {
        self.handles
            .iter()
            .filter(|&&h| self.bodies[h].is_sleeping())
            .count()
    }
}
