//! The frame of one pass of a body's solve: its orientation's matrix and inverse masses,
//! computed once per pass (SPEC.md §5.3).

use super::body::Body;
use crate::math::{Quat, Vec3};
use nalgebra::Matrix3;

/// A body's orientation matrix and world inverse inertia at one pose.
pub(super) struct Frame {
    /// The orientation as a rotation matrix.
    pub(super) rot: Matrix3<f32>,
    /// The world inverse inertia `R · diag(I⁻¹) · Rᵀ`.
    inv_inertia: Matrix3<f32>,
    /// Inverse mass, 1/kg.
    pub(super) inv_mass: f32,
}

impl Frame {
    /// The frame of `body` at orientation `q`.
    pub(super) fn new(body: &Body, q: &Quat) -> Frame {
        Frame {
            rot: q.to_rotation_matrix().into_inner(),
            inv_inertia: body.world_inv_inertia(q),
            inv_mass: body.inv_mass(),
        }
    }

    /// `I⁻¹ v`: the spin an angular impulse `v` adds.
    pub(super) fn spin(&self, v: &Vec3) -> Vec3 {
        self.inv_inertia * v
    }
}
