//! A rigid body's shape, material and dynamic state.

use super::props::{BodyProps, PropsId};
use crate::math::{pose, Pose, Quat, Vec3};
use crate::model::BodyId;
use parry3d::shape::{Ball, Cuboid, Shape as ParryShape};
use serde::{Deserialize, Serialize};

/// A body's collision shape (its own frame: centred on the centre of mass).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Shape {
    /// A sphere.
    Ball {
        /// Radius in metres.
        radius: f32,
    },
    /// A box.
    Cuboid {
        /// Half extents along the body's x, y, z axes, in metres.
        half_extents: [f32; 3],
    },
}

/// A parry3d shape built on the stack from a [`Shape`].
pub(crate) enum Parry {
    Ball(Ball),
    Cuboid(Cuboid),
}

impl Parry {
    pub(crate) fn as_dyn(&self) -> &dyn ParryShape {
        match self {
            Parry::Ball(b) => b,
            Parry::Cuboid(c) => c,
        }
    }
}

/// The largest gain of speed in one step, m/s, along the body's direction of motion, that
/// still counts as coming to rest (SPEC.md §5.4): a body gathering speed faster than this
/// per step (0.03 m/s² at 60 steps per second) never falls asleep. With 1e-4 m/s (the
/// velocity pass's tolerance) balls in a settled gas kept creeping awake.
pub const SPEEDING_UP_TOLERANCE: f32 = 5e-4;

impl Shape {
    /// Radius of the smallest sphere about the centre that holds the shape.
    pub fn bounding_radius(&self) -> f32 {
        match *self {
            Shape::Ball { radius } => radius,
            Shape::Cuboid { half_extents: h } => Vec3::from(h).norm(),
        }
    }

    /// Volume in m³.
    pub fn volume(&self) -> f32 {
        match *self {
            Shape::Ball { radius } => 4.0 / 3.0 * std::f32::consts::PI * radius.powi(3),
            Shape::Cuboid { half_extents: h } => 8.0 * h[0] * h[1] * h[2],
        }
    }

    /// Principal moments of inertia per unit mass, in the body frame.
    pub fn unit_inertia(&self) -> Vec3 {
        match *self {
            Shape::Ball { radius } => Vec3::repeat(0.4 * radius * radius),
            Shape::Cuboid { half_extents: h } => {
                let (x2, y2, z2) = (h[0] * h[0], h[1] * h[1], h[2] * h[2]);
                Vec3::new(y2 + z2, x2 + z2, x2 + y2) / 3.0
            }
        }
    }

    pub(crate) fn parry(&self) -> Parry {
        match *self {
            Shape::Ball { radius } => Parry::Ball(Ball::new(radius)),
            Shape::Cuboid { half_extents: h } => Parry::Cuboid(Cuboid::new(Vec3::from(h))),
        }
    }

    /// The shape's vertices in its own frame (empty for a ball).
    pub fn vertices(&self) -> Vec<Vec3> {
        match *self {
            Shape::Ball { .. } => Vec::new(),
            Shape::Cuboid { half_extents: h } => (0..8)
                .map(|k| {
                    Vec3::new(
                        if k & 1 == 0 { -h[0] } else { h[0] },
                        if k & 2 == 0 { -h[1] } else { h[1] },
                        if k & 4 == 0 { -h[2] } else { h[2] },
                    )
                })
                .collect(),
        }
    }
}

/// Bulk and surface properties of a body.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Material {
    /// Density in kg/m³.
    pub density: f32,
    /// Coulomb friction coefficient (static and dynamic).
    pub friction: f32,
    /// Coefficient of restitution, 0 (plastic) to 1 (elastic).
    pub restitution: f32,
}

impl Default for Material {
    fn default() -> Self {
        Material {
            density: 1.0,
            friction: 0.5,
            restitution: 0.0,
        }
    }
}

/// The [`Body::support_depth`] of a body an input removes ([`Body::mark_leaving`]): the body
/// is in the state of the removal's step, touches nothing in the step after it and is not
/// in the next state, and every body it could touch wakes (SPEC.md §5.4). A computed depth
/// saturates one below it.
pub const LEAVING: u16 = u16::MAX;

/// A dynamic rigid body: identity, constant properties and the state at one step.
///
/// The constant properties (shape, inverse mass and inertia, friction, restitution) are
/// interned ([`BodyProps::intern`]): the body holds their 4-byte handle, so a state is 68
/// bytes instead of 112 and every copy, log entry and message carries only what moves.
#[derive(Clone, PartialEq)]
pub struct Body {
    /// Unique id ([`Body::id`]), as two 32-bit halves (low, high): with every other field
    /// 4-byte aligned, the state is 68 bytes, not 72.
    id_bits: [u32; 2],
    /// The handle of the constant properties.
    props: PropsId,
    /// Centre of mass, world frame.
    pub position: Vec3,
    /// Orientation.
    pub rotation: Quat,
    /// Linear velocity, m/s.
    pub linvel: Vec3,
    /// Angular velocity, rad/s, world frame.
    pub angvel: Vec3,
    /// Consecutive steps this body and every partner it touched were quiet (slower than
    /// `SolverParams::sleep_speed`), saturating at `SolverParams::sleep_steps`; the body is
    /// asleep when it equals `sleep_steps` (SPEC.md §5.4). Part of the hashed state.
    pub rest_steps: u16,
    /// Support depth after the body's last step (SPEC.md §5.2): 1 if it touched a static
    /// surface whose normal is within 75° of the vertical, `k + 1` if it rested on a body
    /// of depth `k` (the least such), else its landing depth if it is about to land on a
    /// static surface or such a body, 0 if it rests on no support chain (in flight, or
    /// without gravity). Only a body of depth > 0 carries another by shock propagation.
    /// [`LEAVING`] (65,535) marks a body an input removes: it is in this step's state and
    /// gone from the next (SPEC.md §5.4). Part of the hashed state.
    pub support_depth: u16,
}

/// The id and the properties themselves (not the process-local handle), then the state.
impl std::fmt::Debug for Body {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Body")
            .field("id", &self.id())
            .field("props", self.props())
            .field("position", &self.position)
            .field("rotation", &self.rotation)
            .field("linvel", &self.linvel)
            .field("angvel", &self.angvel)
            .field("rest_steps", &self.rest_steps)
            .field("support_depth", &self.support_depth)
            .finish()
    }
}

impl Body {
    /// A body at rest with mass and inertia from `material.density`.
    pub fn new(
        id: BodyId,
        shape: Shape,
        material: Material,
        position: Vec3,
        rotation: Quat,
    ) -> Body {
        Body::with_props(id, BodyProps::new(shape, material), position, rotation)
    }

    /// A body at rest with the constant properties `props` (interned here).
    pub fn with_props(id: BodyId, props: BodyProps, position: Vec3, rotation: Quat) -> Body {
        Body {
            id_bits: [id as u32, (id >> 32) as u32],
            props: props.intern(),
            position,
            rotation,
            linvel: Vec3::zeros(),
            angvel: Vec3::zeros(),
            rest_steps: 0,
            support_depth: 0,
        }
    }

    /// Unique id; the canonical order.
    #[inline]
    pub fn id(&self) -> BodyId {
        u64::from(self.id_bits[0]) | (u64::from(self.id_bits[1]) << 32)
    }

    /// The constant properties.
    #[inline]
    pub fn props(&self) -> &'static BodyProps {
        self.props.get()
    }

    /// The handle of the constant properties (equal exactly when the properties' bits are).
    #[inline]
    pub fn props_id(&self) -> PropsId {
        self.props
    }

    /// Collision shape.
    #[inline]
    pub fn shape(&self) -> Shape {
        self.props().shape()
    }

    /// 1 / mass.
    #[inline]
    pub fn inv_mass(&self) -> f32 {
        self.props().inv_mass()
    }

    /// Inverse principal moments of inertia, body frame.
    #[inline]
    pub fn inv_inertia(&self) -> Vec3 {
        self.props().inv_inertia()
    }

    /// Coulomb friction coefficient.
    #[inline]
    pub fn friction(&self) -> f32 {
        self.props().friction()
    }

    /// Restitution coefficient.
    #[inline]
    pub fn restitution(&self) -> f32 {
        self.props().restitution()
    }

    /// Radius of the smallest sphere about the centre that holds the shape.
    #[inline]
    pub fn bounding_radius(&self) -> f32 {
        self.props().bounding_radius()
    }

    /// The body's pose.
    pub fn pose(&self) -> Pose {
        pose(self.position, self.rotation)
    }

    /// Whether the body and its surface are slower than `speed`: `|v| <= speed` and
    /// `|ω|·r <= speed` with `r` the bounding radius.
    pub fn is_quiet(&self, speed: f32) -> bool {
        self.linvel.norm_squared() <= speed * speed
            && self.angvel.norm() * self.bounding_radius() <= speed
    }

    /// Whether this state moves faster than `before` (the same body a step earlier) along
    /// `before`'s direction of motion, by more than [`SPEEDING_UP_TOLERANCE`]: then it is
    /// not coming to rest (SPEC.md §5.4). A velocity turning back and forth (a ball rocking
    /// in a groove) does not count; a body at rest a step earlier does not either.
    pub fn speeds_up_from(&self, before: &Body) -> bool {
        let then = before.linvel.norm();
        then > 0.0 && self.linvel.dot(&before.linvel) > then * (then + SPEEDING_UP_TOLERANCE)
    }

    /// Whether an input removes this body at the current step ([`LEAVING`]).
    #[inline]
    pub fn is_leaving(&self) -> bool {
        self.support_depth == LEAVING
    }

    /// Marks the body as removed at the current step ([`LEAVING`]): a removal that wakes
    /// every body it could touch, where the kernel's `Input::Remove` wakes nothing.
    pub fn mark_leaving(&mut self) {
        self.support_depth = LEAVING;
    }

    /// Whether both velocities are exactly zero in every component (either sign): the body
    /// does not move at all, so freezing it changes nothing (SPEC.md §5.4).
    pub fn is_still(&self) -> bool {
        self.linvel
            .iter()
            .chain(self.angvel.iter())
            .all(|&c| c == 0.0)
    }

    /// The world-frame inverse inertia at orientation `q`, `R · diag(I⁻¹) · Rᵀ`; exactly
    /// `I⁻¹` times the identity for a body whose principal inverse inertias are equal (a ball,
    /// a cube), whose inertia does not depend on its orientation. Rounding the product made a
    /// ball's tangential friction impulse spin it about the contact normal (1e-24 rad/s from
    /// rest), which torsional friction must then stop (SPEC.md §5.3).
    pub fn world_inv_inertia(&self, q: &Quat) -> nalgebra::Matrix3<f32> {
        let p = self.props();
        let d = p.inv_inertia();
        if p.isotropic() {
            return nalgebra::Matrix3::from_diagonal_element(d.x);
        }
        let r = q.to_rotation_matrix().into_inner();
        r * nalgebra::Matrix3::from_diagonal(&d) * r.transpose()
    }

    /// `I⁻¹ v` in world frame at orientation `q` (exactly `I⁻¹ v` for equal principal inverse
    /// inertias, as [`Body::world_inv_inertia`]).
    pub fn world_inv_inertia_times(&self, q: &Quat, v: &Vec3) -> Vec3 {
        let p = self.props();
        let d = p.inv_inertia();
        if p.isotropic() {
            return v * d.x;
        }
        let local = q.inverse_transform_vector(v);
        q.transform_vector(&local.component_mul(&d))
    }

    /// Orientation and world angular velocity after `h` seconds turning without torque,
    /// angular momentum kept ([`free_rotation`](super::free_rotation), SPEC.md §5.3).
    pub(crate) fn free_rotation(&self, h: f32) -> super::free_rotation::FreeTurn {
        let p = self.props();
        super::free_rotation::free_rotation(
            &self.rotation,
            &self.angvel,
            &p.inv_inertia(),
            p.isotropic(),
            h,
        )
    }

    /// Spin `w` carried along when the body is turned from `from` to `to` by something other
    /// than its own rotation (a correction of its pose): turned by `to·from⁻¹`, so it keeps its
    /// body-frame axis and the rotational energy `½ωᵀIω` it had at `from` (turning the body
    /// alone changes that energy, SPEC.md §5.3). A body whose principal inertias are equal
    /// has the same energy in every orientation: its spin is returned as it is (same bits,
    /// and its angular momentum is kept).
    pub(crate) fn carry_spin(&self, from: &Quat, to: &Quat, w: Vec3) -> Vec3 {
        if self.props().isotropic() {
            w
        } else {
            (to * from.inverse()) * w
        }
    }

    /// Mass in kg.
    pub fn mass(&self) -> f32 {
        1.0 / self.inv_mass()
    }

    /// Angular momentum about the centre of mass in the world frame, `R·I·Rᵀ·ω`, kg·m²/s:
    /// what a body in free flight keeps (SPEC.md §5.3, the torque-free rotation).
    pub fn angular_momentum(&self) -> Vec3 {
        let local = self.rotation.inverse() * self.angvel;
        self.rotation * local.component_div(&self.inv_inertia())
    }

    /// Kinetic energy (translation + rotation), J.
    pub fn kinetic_energy(&self) -> f32 {
        let w = self.rotation.inverse() * self.angvel;
        let rot: f32 = (0..3).map(|k| w[k] * w[k] / self.inv_inertia()[k]).sum();
        0.5 * self.mass() * self.linvel.norm_squared() + 0.5 * rot
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::UnitQuaternion;

    /// A 0.2 × 0.4 × 0.8 m box of 1,000 kg/m³ (64 kg) spinning at 2 rad/s about its long
    /// axis, turned by 90° about x so that axis points along world −y: its angular momentum is
    /// `I_z·ω` along the spin, whatever the orientation, with
    /// `I_z = m·(0.1² + 0.2²)/3 = 1.0667 kg·m²`.
    #[test]
    fn angular_momentum_is_the_principal_moment_times_the_spin_in_the_world_frame() {
        let material = Material {
            density: 1000.0,
            friction: 0.5,
            restitution: 0.0,
        };
        let shape = Shape::Cuboid {
            half_extents: [0.1, 0.2, 0.4],
        };
        let turned = UnitQuaternion::from_euler_angles(std::f32::consts::FRAC_PI_2, 0.0, 0.0);
        let mut b = Body::new(1, shape, material, Vec3::zeros(), turned);
        let long_axis = turned * Vec3::z();
        b.angvel = long_axis * 2.0;
        let expected = 64.0 * (0.01 + 0.04) / 3.0 * 2.0;
        let l = b.angular_momentum();
        assert!(
            (l - long_axis * expected).norm() <= 1e-5 * expected,
            "L {l:?}, expected {expected} along {long_axis:?}"
        );
        // A generic orientation and a spin off every principal axis, against `R·I·Rᵀ·ω`
        // built from the rotation matrix (a turn of 90° about a principal axis cannot tell
        // `R·I·Rᵀ` from `Rᵀ·I·R`).
        let generic = UnitQuaternion::from_euler_angles(0.3, -0.7, 1.1);
        let mut b = Body::new(2, shape, material, Vec3::zeros(), generic);
        b.angvel = Vec3::new(1.0, -2.0, 0.5);
        let (x, y, z) = (0.1f32 * 0.1, 0.2f32 * 0.2, 0.4f32 * 0.4);
        let inertia =
            nalgebra::Matrix3::from_diagonal(&(Vec3::new(y + z, x + z, x + y) * (64.0 / 3.0)));
        let r = generic.to_rotation_matrix().into_inner();
        let direct = r * inertia * r.transpose() * b.angvel;
        let l = b.angular_momentum();
        assert!(
            (l - direct).norm() <= 1e-5 * direct.norm(),
            "L {l:?}, R·I·Rᵀ·ω {direct:?}"
        );
    }
}
