//! Coulomb friction at one contact point of a body's solve (SPEC.md §5.3): the point's
//! tangent plane, fixed for a pass, and one sequential-impulse update of the tangential
//! impulse within the friction cone.
//!
//! The impulse opposes the point's slip relative to its partner (Coulomb's law: friction
//! opposes the sliding velocity), with the magnitude that would stop the slip, and the
//! impulse accumulated over the substep stays within `μ·N`. Updates are cheap once the row is
//! built: the slip and the body's response are dot products with precomputed vectors.

use super::body::Body;
use super::frame::Frame;
use crate::math::Vec3;

/// Two unit tangents completing `n` to a right-handed orthonormal basis; a function of `n`
/// alone, so the basis does not depend on the body's pose or on the order of the points.
fn tangents(n: &Vec3) -> [Vec3; 2] {
    let t1 = if n.x.abs() > 0.577_350_3 {
        Vec3::new(n.y, -n.x, 0.0)
    } else {
        Vec3::new(0.0, n.z, -n.y)
    }
    .normalize();
    [t1, n.cross(&t1)]
}

/// A contact point's tangent plane for one pass of the solve: the tangents, their angular
/// parts, and the tangential inverse-mass matrix (a 2×2 symmetric matrix).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Tangent {
    /// The two tangents.
    t: [Vec3; 2],
    /// `r × t_a`: the angular part of each tangent at offset `r`.
    rt: [Vec3; 2],
    /// `I⁻¹ (r × t_a)`: the spin a unit impulse along `t_a` adds.
    irt: [Vec3; 2],
    /// `K_ab = t_a·K·t_b` with `K` the point's inverse-mass matrix, the partner's
    /// `partner_inv_mass` (its generalised inverse mass along the normal, taken for every
    /// direction) on the diagonal: `[K_11, K_12, K_22]`.
    k: [f32; 3],
    /// The partner point's inverse mass (0 for an immovable partner).
    partner_inv_mass: f32,
    /// The body's inverse mass.
    inv_mass: f32,
}

/// The tangential impulse accumulated at a point over a pass, tangent coordinates, and the
/// change of the partner point's slip velocity that it implies (the partner's share, which
/// it applies in its own solve).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Traction {
    impulse: [f32; 2],
    partner_slip: [f32; 2],
}

impl Traction {
    /// The tangential impulse accumulated so far, tangent coordinates.
    pub(super) fn impulse(&self) -> [f32; 2] {
        self.impulse
    }
}

impl Tangent {
    /// The tangent plane of a point with normal `n` at offset `r` of a body in frame `f`;
    /// the partner's point yields with
    /// inverse mass `partner_inv_mass` (0 for an immovable partner).
    pub(super) fn new(f: &Frame, r: &Vec3, n: &Vec3, partner_inv_mass: f32) -> Tangent {
        let t = tangents(n);
        let rt = [r.cross(&t[0]), r.cross(&t[1])];
        let irt = [f.spin(&rt[0]), f.spin(&rt[1])];
        let diagonal = f.inv_mass + partner_inv_mass;
        Tangent {
            t,
            rt,
            irt,
            k: [
                diagonal + rt[0].dot(&irt[0]),
                rt[0].dot(&irt[1]),
                diagonal + rt[1].dot(&irt[1]),
            ],
            partner_inv_mass,
            inv_mass: f.inv_mass,
        }
    }

    /// The world vector of a tangential impulse `x` given in tangent coordinates.
    pub(super) fn world(&self, x: &[f32; 2]) -> Vec3 {
        self.t[0] * x[0] + self.t[1] * x[1]
    }

    /// The change of the body's linear velocity that tangential impulse `x` makes.
    pub(super) fn linear_change(&self, x: &[f32; 2]) -> Vec3 {
        self.world(x) * self.inv_mass
    }

    /// `K·x` for a tangential impulse `x`: the change of the point's slip velocity.
    fn times_k(&self, x: &[f32; 2]) -> [f32; 2] {
        [
            self.k[0] * x[0] + self.k[1] * x[1],
            self.k[1] * x[0] + self.k[2] * x[1],
        ]
    }

    /// The slip of the point relative to a partner point moving at `partner_velocity`, in
    /// tangent coordinates.
    fn slip(&self, linvel: &Vec3, angvel: &Vec3, partner_velocity: &Vec3) -> [f32; 2] {
        let v = linvel - partner_velocity;
        [
            self.t[0].dot(&v) + angvel.dot(&self.rt[0]),
            self.t[1].dot(&v) + angvel.dot(&self.rt[1]),
        ]
    }
}

/// One sequential-impulse update of Coulomb friction at a point with tangent plane `row`:
/// the tangential impulse accumulated in `acc` moves by the impulse along the slip
/// (relative to the partner point, moving at `partner_velocity` plus its share of `acc`)
/// that stops it, and is kept within `cap` (`μ` times the point's normal impulse so far; an
/// accumulated impulse beyond a smaller cap is shortened; a change shortened onto the cone
/// never adds energy). The change is applied to `b`'s velocities. Returns how much the
/// point's slip velocity changed (`|K·Δ|`), m/s.
#[inline]
pub(super) fn coulomb(
    row: &Tangent,
    b: &mut Body,
    partner_velocity: &Vec3,
    cap: f32,
    acc: &mut Traction,
) -> f32 {
    if cap <= 0.0 && acc.impulse == [0.0; 2] {
        return 0.0;
    }
    let own = row.slip(&b.linvel, &b.angvel, partner_velocity);
    let s = [own[0] - acc.partner_slip[0], own[1] - acc.partner_slip[1]];
    let slip_sq = s[0] * s[0] + s[1] * s[1];
    let mut next = acc.impulse;
    // A slip whose squared length underflows (subnormal components) has no direction
    // (issue 23): then only the bound is enforced.
    if slip_sq > 0.0 {
        let len = slip_sq.sqrt();
        let d = [s[0] / len, s[1] / len];
        // The generalised inverse mass along the slip: `dᵀ K d`.
        let kd = row.times_k(&d);
        let stop = len / (d[0] * kd[0] + d[1] * kd[1]);
        next = [next[0] - d[0] * stop, next[1] - d[1] * stop];
    }
    let cap = cap.max(0.0);
    let len_sq = next[0] * next[0] + next[1] * next[1];
    let d = if len_sq > cap * cap {
        let scale = cap / len_sq.sqrt();
        let d = [
            next[0] * scale - acc.impulse[0],
            next[1] * scale - acc.impulse[1],
        ];
        // Shortened onto the cone, the change is no longer along the slip, and where `K`
        // is anisotropic it could add energy: `ΔE = s·Δ + ½ΔᵀKΔ`. Then (if the impulse held
        // so far is within the cone, so that a shorter change stays within it) it is
        // scaled to the most dissipative length along its direction, `−s·Δ / ΔᵀKΔ`.
        let held = acc.impulse[0] * acc.impulse[0] + acc.impulse[1] * acc.impulse[1];
        let along = s[0] * d[0] + s[1] * d[1];
        let kd = row.times_k(&d);
        let curvature = d[0] * kd[0] + d[1] * kd[1];
        if held <= cap * cap && along + 0.5 * curvature > 0.0 {
            let scale = if along < 0.0 && curvature > 0.0 {
                -along / curvature
            } else {
                0.0
            };
            [d[0] * scale, d[1] * scale]
        } else {
            d
        }
    } else {
        [next[0] - acc.impulse[0], next[1] - acc.impulse[1]]
    };
    if d == [0.0; 2] {
        return 0.0;
    }
    b.linvel += row.linear_change(&d);
    b.angvel += row.irt[0] * d[0] + row.irt[1] * d[1];
    let wj = row.partner_inv_mass;
    acc.partner_slip = [
        acc.partner_slip[0] - d[0] * wj,
        acc.partner_slip[1] - d[1] * wj,
    ];
    acc.impulse = [acc.impulse[0] + d[0], acc.impulse[1] + d[1]];
    // The change of the point's slip velocity, `K·Δ`.
    let kd = row.times_k(&d);
    (kd[0] * kd[0] + kd[1] * kd[1]).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_tangents_complete_any_normal_to_an_orthonormal_basis() {
        for n in [
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, -1.0),
            Vec3::new(0.6, -0.48, 0.64),
            Vec3::new(-0.577, 0.577, 0.5783),
        ] {
            let n = n.normalize();
            let [t1, t2] = tangents(&n);
            for (a, b) in [(t1, t2), (t1, n), (t2, n)] {
                assert!(a.dot(&b).abs() < 1e-6, "{a:?} · {b:?} for n = {n:?}");
            }
            assert!((t1.norm() - 1.0).abs() < 1e-6 && (t2.norm() - 1.0).abs() < 1e-6);
            assert!(
                (t1.cross(&t2) - n).norm() < 1e-6,
                "left-handed for n = {n:?}"
            );
        }
    }
}
