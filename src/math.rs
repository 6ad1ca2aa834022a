//! Math types of the hot path: nalgebra `f32` vectors and unit quaternions, the types
//! parry3d 0.25 uses natively (no conversion per contact pair; see SPEC.md §14ath).

pub use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

/// A 3-vector of `f32`.
pub type Vec3 = Vector3<f32>;
/// A unit quaternion of `f32`.
pub type Quat = UnitQuaternion<f32>;
/// A rigid pose of `f32`.
pub type Pose = Isometry3<f32>;

/// Builds a pose from a position and a rotation.
pub fn pose(position: Vec3, rotation: Quat) -> Pose {
    Isometry3::from_parts(Translation3::from(position), rotation)
}
