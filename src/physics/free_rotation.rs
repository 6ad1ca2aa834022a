//! A body's rotation over one substep without torque: its angular momentum `L = I·ω` stays
//! fixed in the world while the body turns, so a body whose principal moments differ changes
//! its angular velocity as it turns (it precesses, and one spun about its intermediate axis
//! flips over, the tennis-racket effect). Keeping `ω` fixed instead turned the momentum with
//! the body: a brick spun at 4 rad/s about a tilted axis turned its `L` by 13° in 10 s.
//!
//! The step, in the body's frame (`L` the body-frame momentum at the start, `I` the principal
//! inertia): find the angular velocity `w` with
//!
//! `w = I⁻¹·(L + L′)/2`, where `L′ = Rot(−h·w)·L`,
//!
//! then turn the body by the whole `h·w` about `w` and take `L′` as its new body-frame
//! momentum. The world momentum `R·Rot(h·w)·L′ = R·L` is kept by construction. Both
//! `|L|` and the energy `½·Lᵀ·I⁻¹·L` are kept too: a rotation about `w` moves `L` at right
//! angles to `w`, and `H(L′) − H(L) = (L′ − L)·I⁻¹·(L + L′)/2 = (L′ − L)·w = 0` (the implicit
//! midpoint rule, with the exact rotation in place of its Cayley approximation so a body
//! spinning about a principal axis turns by the whole `|ω|·h`). The equation is solved by
//! Newton's method with the small-angle Jacobian `1 − (h/2)·I⁻¹·[L′]×` (never singular: `I⁻¹·[L′]×` is
//! similar to a skew matrix), from the explicit midpoint; a substep whose solve does not
//! converge is cut into pieces. A body whose principal moments are equal (a ball, a cube)
//! keeps `ω` exactly and takes the same path as before, bit for bit.
//!
//! The per-body solve turns a body this way in free flight (no contact set); with contacts it
//! still keeps `ω` through a substep's motion (SPEC.md §5.3, "The per-body solve").

use super::rotation::{integrate_rotation, rotation_vector_quaternion};
use crate::math::{Quat, Vec3};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};

/// Newton iterations at most per solve. The Jacobian is the small-angle one, so each
/// iteration shrinks the error by a factor that grows with `h·|ω|` and with the spread of
/// the principal moments; the first guess (the explicit midpoint) is `O(h²)` off.
const MAX_NEWTON_ITERATIONS: u32 = 8;

/// A solve has converged once a Newton step changes `w` by less than this fraction of it:
/// far below `f32`'s resolution, which the result is rounded to (a brick tumbling at 4 rad/s
/// needs 3 iterations).
const NEWTON_TOLERANCE: f64 = 1e-10;

/// Most pieces a substep is cut into when a solve does not converge (it is cut in halves until
/// every piece converges): a fast spin of a body whose moments differ widely.
const MAX_PIECES: u32 = 256;

/// The state of a rotation after one torque-free substep.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct FreeTurn {
    /// The orientation at the end of the substep.
    pub rotation: Quat,
    /// The world-frame angular velocity at the end of the substep.
    pub angvel: Vec3,
}

/// Turns a body of principal inverse inertia `inv_inertia` (body frame, all positive) at
/// orientation `q` and world angular velocity `angvel` through `h` seconds without torque.
/// `isotropic` (equal principal moments) keeps `angvel` and turns by exactly `angvel·h`.
///
/// The solve runs in `f64` (IEEE basic operations only, so every machine gets the same
/// bits) and rounds to `f32` once: carried through `f32`, the trip between the body's frame
/// and the world's drifted the energy of a tumbling brick by +3e-4 in 10 s.
pub(crate) fn free_rotation(
    q: &Quat,
    angvel: &Vec3,
    inv_inertia: &Vec3,
    isotropic: bool,
    h: f32,
) -> FreeTurn {
    if isotropic || *angvel == Vec3::zeros() {
        return FreeTurn {
            rotation: integrate_rotation(q, angvel, h),
            angvel: *angvel,
        };
    }
    let q64 = UnitQuaternion::new_normalize(q.quaternion().cast::<f64>());
    let inv = inv_inertia.cast::<f64>();
    let h = f64::from(h);
    let start_w = q64.inverse_transform_vector(&angvel.cast::<f64>());
    let momentum = start_w.component_div(&inv);
    // Cut the substep in halves until every piece's solve converges (one piece but for fast
    // spins); each piece keeps the world momentum exactly whether or not it converged.
    let mut pieces = 1u32;
    let (rotation, mut end_momentum) = loop {
        let piece = h / f64::from(pieces);
        let mut rotation = q64;
        let mut l = momentum;
        let mut converged = true;
        for _ in 0..pieces {
            let solved = midpoint_spin(&l, &inv, piece);
            converged &= solved.converged;
            if !converged && pieces < MAX_PIECES {
                break;
            }
            // The body turns by `piece·w`; its momentum, seen from the body, by the inverse
            // (`rotation_vector_quaternion(−θ)` is the conjugate of `(θ)` bit for bit, so
            // this is `turn(−piece·w, l)` without building the quaternion twice).
            let body_turn =
                UnitQuaternion::new_normalize(rotation_vector_quaternion(&(solved.w * piece)));
            l = body_turn.inverse_transform_vector(&l);
            rotation *= body_turn;
        }
        if converged || pieces >= MAX_PIECES {
            break (rotation, l);
        }
        pieces *= 2;
    };
    // An unconverged solve must not create energy: the momentum is shrunk to the starting
    // energy (|L| shrinks by as much).
    let start_energy = momentum.dot(&start_w);
    let end_energy = end_momentum.dot(&end_momentum.component_mul(&inv));
    if end_energy > start_energy {
        end_momentum *= (start_energy / end_energy).sqrt();
    }
    let end_w = rotation.transform_vector(&end_momentum.component_mul(&inv));
    FreeTurn {
        rotation: Quat::new_normalize(rotation.quaternion().cast::<f32>()),
        angvel: end_w.cast::<f32>(),
    }
}

/// The body-frame angular velocity of one torque-free piece of `h` seconds.
struct MidpointSpin {
    /// `w` with `w = I⁻¹·(L + Rot(−h·w)·L)/2`, as far as solved.
    w: Vector3<f64>,
    /// Whether the last Newton step was below [`NEWTON_TOLERANCE`].
    converged: bool,
}

/// Solves `w = I⁻¹·(L + L′)/2`, `L′ = Rot(−h·w)·L` for body-frame momentum `momentum` and
/// principal inverse inertia `inv` by Newton's method from the explicit midpoint.
fn midpoint_spin(momentum: &Vector3<f64>, inv: &Vector3<f64>, h: f64) -> MidpointSpin {
    let start_w = momentum.component_mul(inv);
    // First guess: the explicit midpoint, `L + (h/2)·L × w` (the body-frame Euler equation).
    let mut w = (momentum + momentum.cross(&start_w) * (0.5 * h)).component_mul(inv);
    for _ in 0..MAX_NEWTON_ITERATIONS {
        let turned = turn(&(w * -h), momentum);
        let residual = w - ((momentum + turned) * 0.5).component_mul(inv);
        // d(turned)/dw ≈ h·[turned]×, so dF/dw ≈ 1 − (h/2)·diag(I⁻¹)·[turned]×.
        let jacobian =
            Matrix3::identity() - Matrix3::from_diagonal(inv) * turned.cross_matrix() * (0.5 * h);
        let Some(step) = jacobian.lu().solve(&residual) else {
            break;
        };
        w -= step;
        let bound = NEWTON_TOLERANCE * w.norm();
        if step.norm_squared() <= bound * bound {
            return MidpointSpin { w, converged: true };
        }
    }
    MidpointSpin {
        w,
        converged: false,
    }
}

/// `v` rotated by the rotation vector `theta` (angle `|theta|` about `theta`).
fn turn(theta: &Vector3<f64>, v: &Vector3<f64>) -> Vector3<f64> {
    UnitQuaternion::new_normalize(rotation_vector_quaternion(theta)).transform_vector(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// World angular momentum `R·I·Rᵀ·ω` and twice the kinetic energy `ωᵀ·R·I·Rᵀ·ω`.
    fn momentum_and_energy(q: &Quat, w: &Vec3, inv_inertia: &Vec3) -> (Vec3, f32) {
        let local = q.inverse_transform_vector(w);
        let l = local.component_div(inv_inertia);
        (q.transform_vector(&l), l.dot(&local))
    }

    /// A brick spun about a tilted axis keeps its world angular momentum and its energy over
    /// 10 s of substeps, while its angular velocity moves (it would not without the gyroscopic
    /// change).
    #[test]
    fn a_tumbling_brick_keeps_its_angular_momentum_and_energy() {
        // Half extents 0.05 × 0.1 × 0.2 m, 1 kg: I = m·(b² + c²)/3 …
        let (a, b, c) = (0.05f32, 0.1f32, 0.2f32);
        let inertia = Vec3::new(b * b + c * c, a * a + c * c, a * a + b * b) / 3.0;
        let inv = Vec3::new(1.0 / inertia.x, 1.0 / inertia.y, 1.0 / inertia.z);
        let mut q = Quat::from_euler_angles(0.3, 0.2, 0.1);
        let mut w = Vec3::new(0.2, 4.0, 0.3);
        let (l0, e0) = momentum_and_energy(&q, &w, &inv);
        let w0 = w;
        for _ in 0..1200 {
            let next = free_rotation(&q, &w, &inv, false, 1.0 / 120.0);
            q = next.rotation;
            w = next.angvel;
            let (_, e) = momentum_and_energy(&q, &w, &inv);
            let (l, _) = momentum_and_energy(&q, &w, &inv);
            assert!((e - e0).abs() <= 1e-5 * e0, "energy {e} from {e0}");
            assert!((l - l0).norm() <= 1e-5 * l0.norm(), "L {l:?} from {l0:?}");
        }
        assert!((w - w0).norm() > 0.1, "ω did not move: {w:?}");
    }

    /// The tennis-racket theorem: spun about its intermediate axis (with a 1 % wobble) a
    /// brick flips over, the spin's body-frame component reversing; spun about its largest
    /// or smallest axis it keeps spinning about it.
    #[test]
    fn a_brick_spun_about_its_intermediate_axis_flips_and_about_the_others_does_not() {
        let (a, b, c) = (0.05f32, 0.1f32, 0.2f32);
        // Moments about x (largest), y (intermediate), z (smallest).
        let inertia = Vec3::new(b * b + c * c, a * a + c * c, a * a + b * b) / 3.0;
        let inv = Vec3::new(1.0 / inertia.x, 1.0 / inertia.y, 1.0 / inertia.z);
        for axis in 0..3 {
            let mut w = Vec3::repeat(0.05);
            w[axis] = 5.0;
            let mut q = Quat::identity();
            let mut least = f32::INFINITY;
            for _ in 0..1200 {
                let next = free_rotation(&q, &w, &inv, false, 1.0 / 120.0);
                q = next.rotation;
                w = next.angvel;
                least = least.min(q.inverse_transform_vector(&w)[axis]);
            }
            if axis == 1 {
                assert!(least < -4.0, "the intermediate axis never flipped: {least}");
            } else {
                assert!(least > 4.5, "axis {axis} left its spin: {least}");
            }
        }
    }

    /// A small, flat box spun fast about a tilted axis (630 rad/s, near its spin cap of 655, with one
    /// substep of 1/60 s) keeps its momentum and energy too: the substep is cut into pieces
    /// until each piece's solve converges.
    #[test]
    fn a_fast_spin_keeps_momentum_and_energy_in_pieces() {
        let (a, b, c) = (0.01f32, 0.02f32, 0.04f32);
        let inertia = Vec3::new(b * b + c * c, a * a + c * c, a * a + b * b) / 3.0;
        let inv = Vec3::new(1.0 / inertia.x, 1.0 / inertia.y, 1.0 / inertia.z);
        let mut q = Quat::from_euler_angles(0.4, -0.3, 1.1);
        let mut w = Vec3::new(300.0, 500.0, -250.0);
        let (l0, e0) = momentum_and_energy(&q, &w, &inv);
        for _ in 0..120 {
            let next = free_rotation(&q, &w, &inv, false, 1.0 / 60.0);
            q = next.rotation;
            w = next.angvel;
            let (l, e) = momentum_and_energy(&q, &w, &inv);
            assert!((e - e0).abs() <= 1e-5 * e0, "energy {e} from {e0}");
            assert!((l - l0).norm() <= 1e-5 * l0.norm(), "L {l:?} from {l0:?}");
        }
    }

    /// Equal principal moments: the same bits as turning by `ω·h` with `ω` kept.
    #[test]
    fn an_isotropic_body_keeps_its_angular_velocity_bit_for_bit() {
        let q = Quat::from_euler_angles(0.3, -1.2, 2.0);
        let w = Vec3::new(3.0, -7.0, 0.5);
        let inv = Vec3::repeat(6.0);
        let next = free_rotation(&q, &w, &inv, true, 1.0 / 120.0);
        assert_eq!(next.angvel, w);
        assert_eq!(next.rotation, integrate_rotation(&q, &w, 1.0 / 120.0));
    }
}
