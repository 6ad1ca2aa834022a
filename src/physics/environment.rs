//! The static environment: half-spaces (ground, walls, ceiling) and static cuboids.

use crate::math::{Pose, Vec3};

/// A half-space: points `p` with `normal · p >= offset` are free space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    /// Unit normal pointing into free space.
    pub normal: Vec3,
    /// Signed distance of the surface from the origin along `normal`.
    pub offset: f32,
}

/// A fixed box.
#[derive(Clone, Debug, PartialEq)]
pub struct StaticCuboid {
    /// Pose of the box's centre.
    pub pose: Pose,
    /// Half extents in the box's frame.
    pub half_extents: Vec3,
}

/// Everything that never moves, with one surface material.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Environment {
    /// Half-spaces.
    pub planes: Vec<Plane>,
    /// Static boxes.
    pub cuboids: Vec<StaticCuboid>,
    /// Friction of static surfaces.
    pub friction: f32,
    /// Restitution of static surfaces.
    pub restitution: f32,
}

/// The declared domain of a scene, `[min, max)` on every axis: a body whose centre is not
/// in it after a step is removed (SPEC.md §3).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DomainBox {
    /// Lower corner (inside).
    pub min: Vec3,
    /// Upper corner (outside, as for the scene's initial positions).
    pub max: Vec3,
}

impl DomainBox {
    /// Whether `p` lies in the domain: `min <= p < max` on every axis.
    pub fn contains(&self, p: &Vec3) -> bool {
        (0..3).all(|k| p[k] >= self.min[k] && p[k] < self.max[k])
    }
}
