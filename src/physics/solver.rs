//! The per-body position-based solve (SPEC.md §Physics). Body `i` advances its own state
//! through `substeps` substeps; every partner is held on its step-`t` trajectory (its contact
//! point moving at its step-`t` velocity), so the result reads only step-`t` states.

use super::body::Body;
use super::contact::{inv_inertia_world, inv_mass_at, ContactSet};
use super::params::SolverParams;
use crate::math::{Quat, Vec3};
use nalgebra::Quaternion;

/// Advances `q` by angular velocity `w` over `h` seconds (first order, renormalised).
fn integrate_rotation(q: &Quat, w: &Vec3, h: f32) -> Quat {
    let dq = Quaternion::new(0.0, w.x, w.y, w.z) * q.quaternion() * (0.5 * h);
    Quat::new_normalize(q.quaternion() + dq)
}

/// Rotates `q` by the small rotation vector `theta`.
fn apply_rotation(q: &Quat, theta: &Vec3) -> Quat {
    integrate_rotation(q, theta, 1.0)
}

/// Angular velocity that takes `q0` to `q1` in `h` seconds.
fn angular_velocity(q0: &Quat, q1: &Quat, h: f32) -> Vec3 {
    let d = q1.quaternion() * q0.quaternion().conjugate();
    let w = d.imag() * (2.0 / h);
    if d.w < 0.0 {
        -w
    } else {
        w
    }
}

/// Per-point scratch kept across one substep.
#[derive(Clone, Copy, Default)]
struct PointScratch {
    /// Normal position impulse (mass-weighted, m·kg) applied this substep.
    lambda: f32,
    /// Relative normal velocity at the start of the substep.
    approach: f32,
}

/// Advances `body` by one step of `dt` seconds against the contact sets (ascending partner
/// id, static environment last). Returns the new state (velocities and pose).
pub(crate) fn solve_body(
    body: &Body,
    sets: &[ContactSet],
    gravity: Vec3,
    dt: f32,
    p: &SolverParams,
) -> Body {
    let n_sub = p.substeps.max(1);
    let h = dt / n_sub as f32;
    let mut b = body.clone();
    let count: usize = sets.iter().map(|s| s.points.len()).sum();
    let mut scratch = vec![PointScratch::default(); count];
    let rest_threshold = 2.0 * gravity.norm() * h;

    for _ in 0..n_sub {
        // Relative normal velocity before the substep (for restitution).
        let mut k = 0;
        for set in sets {
            for cp in &set.points {
                let r = b.rotation * cp.anchor;
                let vi = b.linvel + b.angvel.cross(&r);
                scratch[k] = PointScratch {
                    lambda: 0.0,
                    approach: cp.normal.dot(&(vi - cp.partner_velocity)),
                };
                k += 1;
            }
        }
        // Predict.
        let x0 = b.position;
        let q0 = b.rotation;
        b.linvel += gravity * h;
        let xp = x0 + b.linvel * h;
        let qp = integrate_rotation(&q0, &b.angvel, h);

        // Position pass: each partner separately from the predicted pose (Gauss–Seidel over
        // its points), corrections averaged over the partners that corrected anything.
        let mut sum_dx = Vec3::zeros();
        let mut sum_dtheta = Vec3::zeros();
        let mut active = 0u32;
        let mut k = 0;
        for set in sets {
            let mut x = xp;
            let mut q = qp;
            let mut touched = false;
            for _ in 0..p.sweeps.max(1) {
                for (m, cp) in set.points.iter().enumerate() {
                    let r = q * cp.anchor;
                    let pi = x + r;
                    let pj = cp.partner_point + cp.partner_velocity * h;
                    let gap = cp.normal.dot(&(pi - pj));
                    if gap < 0.0 {
                        let w = inv_mass_at(&b, &q, &r, &cp.normal) + cp.partner_inv_mass;
                        let dl = -gap / w;
                        let imp = cp.normal * dl;
                        x += imp * b.inv_mass;
                        q = apply_rotation(&q, &inv_inertia_world(&b, &q, &r.cross(&imp)));
                        scratch[k + m].lambda += dl;
                        touched = true;
                    }
                }
            }
            k += set.points.len();
            if touched {
                active += 1;
                sum_dx += x - xp;
                sum_dtheta += angular_velocity(&qp, &q, 1.0);
            }
        }
        let (x1, q1) = if active > 0 {
            let scale = p.relaxation / active as f32;
            (
                xp + sum_dx * scale,
                apply_rotation(&qp, &(sum_dtheta * scale)),
            )
        } else {
            (xp, qp)
        };
        // The velocity a correction adds may cancel the approach but not fling the body:
        // along its own direction it is capped at the predicted velocity it opposes plus the
        // separation allowance, so a correction never turns a fall into sideways or upward
        // speed (spin: the predicted speed plus the allowance, over the bounding radius).
        let v_pred = b.linvel;
        let w_pred = b.angvel;
        let mut dv = (x1 - xp) / h;
        let dv_len = dv.norm();
        if dv_len > 0.0 {
            let dv_cap = (-v_pred.dot(&dv) / dv_len).max(0.0) + p.max_separation_speed;
            if dv_len > dv_cap {
                dv *= dv_cap / dv_len;
            }
        }
        let speed_cap = v_pred.norm() + p.max_separation_speed;
        let mut dw = angular_velocity(&qp, &q1, h);
        let dw_cap = w_pred.norm() + speed_cap / body.shape.bounding_radius();
        if dw.norm() > dw_cap {
            dw *= dw_cap / dw.norm();
        }
        b.position = x1;
        b.rotation = q1;
        b.linvel = v_pred + dv;
        b.angvel = w_pred + dw;

        // Velocity pass: per active point, remove approach velocity (or reflect it with the
        // restitution) and apply Coulomb friction bounded by the normal impulse.
        let mut k = 0;
        for set in sets {
            for cp in &set.points {
                let sc = scratch[k];
                k += 1;
                if sc.lambda <= 0.0 {
                    continue;
                }
                let r = b.rotation * cp.anchor;
                let vrel = b.linvel + b.angvel.cross(&r) - cp.partner_velocity;
                let vn = cp.normal.dot(&vrel);
                let vt = vrel - cp.normal * vn;
                let mut dv = Vec3::zeros();
                let target = if -sc.approach > rest_threshold {
                    -set.restitution * sc.approach
                } else {
                    0.0
                };
                if vn < target {
                    dv += cp.normal * (target - vn);
                } else if vn > target.max(p.max_separation_speed) {
                    // Depenetration must not fling bodies: the separating speed a position
                    // correction produced is capped (the whole excess is removed on i's side).
                    let excess = vn - target.max(p.max_separation_speed);
                    let w_i = inv_mass_at(&b, &b.rotation, &r, &cp.normal);
                    let imp = -cp.normal * (excess / w_i);
                    b.linvel += imp * b.inv_mass;
                    b.angvel += inv_inertia_world(&b, &b.rotation, &r.cross(&imp));
                }
                let vt_len = vt.norm();
                if vt_len > 0.0 {
                    let cap = set.friction * sc.lambda / h;
                    let w_t = inv_mass_at(&b, &b.rotation, &r, &(vt / vt_len));
                    let wt_total = w_t + cp.partner_inv_mass;
                    // Velocity change that would stop slip, limited by the friction cone.
                    let stop = vt_len;
                    let limit = cap * wt_total;
                    dv -= vt / vt_len * stop.min(limit);
                }
                if dv != Vec3::zeros() {
                    let dir_len = dv.norm();
                    let dir = dv / dir_len;
                    let w = inv_mass_at(&b, &b.rotation, &r, &dir) + cp.partner_inv_mass;
                    let imp = dir * (dir_len / w);
                    b.linvel += imp * b.inv_mass;
                    b.angvel += inv_inertia_world(&b, &b.rotation, &r.cross(&imp));
                }
            }
        }
    }
    b
}
