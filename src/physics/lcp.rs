//! The exact normal impulses of a few simultaneous contact points (SPEC.md §5.3, "Exact
//! compression"): the linear complementarity problem that a plastic compression of up to eight
//! points poses, solved by trying the points' active sets.
//!
//! Sequential impulses converge slowly where the points are strongly coupled (the corners of
//! a face against another face: their rows are nearly dependent), and a compression left
//! unconverged is not complementary: a point keeps an impulse while it separates. Poisson
//! restitution then pushes it again, and an elastic pair of cubes gained up to 2 % of its
//! energy in one impact. A pair runs its sweeps first and comes here only if they did not
//! converge, so every converged pair keeps its bits; restitution's compression in the
//! per-body solve (a rare event: a set that bounces) always comes here first.

use nalgebra::{SMatrix, SVector};
use smallvec::SmallVec;

/// A contact matrix is regularised by this fraction of its largest diagonal before it is
/// solved (here and in the per-body solve's face block): positive definite, with the
/// least-norm solution for a singular matrix (a face pushed evenly).
pub(crate) const REGULARISATION: f64 = 1e-6;

/// A problem's coupled inverse-mass matrix (the first `m` rows and columns used).
pub(crate) type LcpMatrix = SMatrix<f64, MAX_POINTS, MAX_POINTS>;

/// A problem's normal velocities or impulses (the first `m` entries used).
pub(crate) type LcpVector = SVector<f64, MAX_POINTS>;

/// The most points solved at once.
pub(crate) const MAX_POINTS: usize = 8;

/// A constraint holds within this fraction of the problem's scale: the largest approach
/// speed for the velocities, the largest impulse for the impulses.
const TOLERANCE: f64 = 1e-7;

/// The normal impulses `λ ≥ 0` of `m ≤ 8` points with normal velocities `u` (negative:
/// approaching) and coupled inverse-mass matrix `k` (`k[(a, c)]`: the change of point `a`'s
/// normal velocity per unit impulse at point `c`) such that no point approaches afterwards
/// (`w = u + k·λ ≥ 0`) and only points that end at rest push (`λ_a·w_a = 0`).
///
/// `k` is regularised by 1e-6 of its largest diagonal, which makes it positive definite: the
/// problem then has exactly one solution, and the solution for a singular `k` (the four
/// corners of a face constrain only three degrees of freedom) is the one of least norm, so
/// a face is pushed evenly. The active sets are tried from the largest down (all points,
/// then each set of `m − 1`, ...; at most 255 sets), in a fixed order, each solved in f64 by
/// Cholesky. `None` if `m` is 0 or more than eight, or if no set passes within the tolerance
/// (rounding).
pub(crate) fn contact_impulses(
    k: &LcpMatrix,
    u: &LcpVector,
    m: usize,
) -> Option<[f64; MAX_POINTS]> {
    if m == 0 || m > MAX_POINTS {
        return None;
    }
    let largest = (0..m).map(|a| k[(a, a)]).fold(0.0f64, f64::max);
    if largest.is_nan() || largest <= 0.0 || (0..m).any(|a| !u[a].is_finite()) {
        return None;
    }
    let speed_scale = (0..m).map(|a| u[a].abs()).fold(0.0f64, f64::max);
    if (0..m).all(|a| u[a] >= 0.0) {
        return Some([0.0; MAX_POINTS]);
    }
    let regularised = {
        let mut r = *k;
        for a in 0..m {
            r[(a, a)] += REGULARISATION * largest;
        }
        r
    };
    for size in (1..=m).rev() {
        for mask in 1u32..(1 << m) {
            if mask.count_ones() as usize != size {
                continue;
            }
            let active = |a: usize| mask & (1 << a) != 0;
            // The active rows of the regularised matrix, identity elsewhere: the inactive
            // points get λ = 0.
            let mut sub = LcpMatrix::identity();
            let mut rhs = LcpVector::zeros();
            for a in (0..m).filter(|&a| active(a)) {
                rhs[a] = -u[a];
                for c in (0..m).filter(|&c| active(c)) {
                    sub[(a, c)] = regularised[(a, c)];
                }
            }
            let Some(chol) = sub.cholesky() else {
                continue;
            };
            let lambda = chol.solve(&rhs);
            let impulse_scale = (0..m).map(|a| lambda[a].abs()).fold(0.0f64, f64::max);
            let pushes = (0..m).all(|a| !active(a) || lambda[a] >= -TOLERANCE * impulse_scale);
            if !pushes {
                continue;
            }
            let mut out = [0.0f64; MAX_POINTS];
            for a in (0..m).filter(|&a| active(a)) {
                out[a] = lambda[a].max(0.0);
            }
            let separates = (0..m).filter(|&a| !active(a)).all(|a| {
                let w = u[a] + (0..m).map(|c| k[(a, c)] * out[c]).sum::<f64>();
                w >= -TOLERANCE * speed_scale
            });
            if separates && out.iter().all(|l| l.is_finite()) {
                return Some(out);
            }
        }
    }
    None
}

/// [`contact_impulses`] for the points `at` of a caller's `len` points (their indices, at
/// most [`MAX_POINTS`]): `coupling(i, j)` and `speed(i)` give the matrix entries and normal
/// velocities by the caller's indices, and `applied(j)` the impulses already contained in
/// `speed`, taken back out (`u_i = speed(i) − Σ_j coupling(i, j)·applied(j)`, in `at`'s
/// order). Returns an impulse per caller point, 0 for those not in `at`; `None` if `at` is
/// empty or too long, or the solve fails.
pub(crate) fn impulses_at(
    at: &[usize],
    len: usize,
    coupling: impl Fn(usize, usize) -> f64,
    speed: impl Fn(usize) -> f64,
    applied: impl Fn(usize) -> f64,
) -> Option<SmallVec<[f32; MAX_POINTS]>> {
    if at.is_empty() || at.len() > MAX_POINTS {
        return None;
    }
    let mut k = LcpMatrix::zeros();
    let mut u = LcpVector::zeros();
    for (x, &i) in at.iter().enumerate() {
        for (y, &j) in at.iter().enumerate() {
            k[(x, y)] = coupling(i, j);
        }
        u[x] = speed(i);
    }
    for x in 0..at.len() {
        for (y, &j) in at.iter().enumerate() {
            let already = applied(j);
            if already != 0.0 {
                u[x] -= k[(x, y)] * already;
            }
        }
    }
    let lambda = contact_impulses(&k, &u, at.len())?;
    let mut out: SmallVec<[f32; MAX_POINTS]> = smallvec::smallvec![0.0; len];
    for (x, &i) in at.iter().enumerate() {
        out[i] = lambda[x] as f32;
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The vector with `v` first and zeros after.
    fn vector(v: &[f64]) -> LcpVector {
        let mut out = LcpVector::zeros();
        for (k, x) in v.iter().enumerate() {
            out[k] = *x;
        }
        out
    }

    /// `u + k·λ` for the first `m` points.
    fn after(k: &LcpMatrix, u: &LcpVector, l: &[f64; MAX_POINTS], m: usize) -> Vec<f64> {
        (0..m)
            .map(|a| u[a] + (0..m).map(|c| k[(a, c)] * l[c]).sum::<f64>())
            .collect()
    }

    #[test]
    fn a_single_point_gets_the_impulse_that_stops_it() {
        let mut k = LcpMatrix::zeros();
        k[(0, 0)] = 2.0;
        let u = vector(&[-3.0, 0.0, 0.0, 0.0]);
        let l = contact_impulses(&k, &u, 1).unwrap();
        assert!((l[0] - 1.5).abs() < 1e-5, "{l:?}");
    }

    #[test]
    fn a_point_lifted_by_its_neighbours_does_not_push() {
        // Point 1 approaches slowly, point 0 fast; pushing point 0 lifts point 1 (positive
        // coupling), so the complementary solution pushes point 0 only.
        let mut k = LcpMatrix::zeros();
        k[(0, 0)] = 1.0;
        k[(1, 1)] = 1.0;
        k[(0, 1)] = 0.5;
        k[(1, 0)] = 0.5;
        let u = vector(&[-4.0, -1.0, 0.0, 0.0]);
        let l = contact_impulses(&k, &u, 2).unwrap();
        assert!(l[1] == 0.0 && (l[0] - 4.0).abs() < 1e-4, "{l:?}");
        let w = after(&k, &u, &l, 2);
        assert!(w[0].abs() < 1e-4 && w[1] > 0.0, "{w:?}");
    }

    #[test]
    fn the_corners_of_a_face_are_pushed_evenly_on_a_singular_matrix() {
        // Four corners of a unit-mass square face, half-width 1, unit inertia: rows
        // n·(1/m) + (r × n)·I⁻¹(r × n), rank 3.
        let corners = [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)];
        let mut k = LcpMatrix::zeros();
        for (a, ra) in corners.iter().enumerate() {
            for (c, rc) in corners.iter().enumerate() {
                k[(a, c)] = 1.0 + ra.0 * rc.0 + ra.1 * rc.1;
            }
        }
        let u = vector(&[-2.0, -2.0, -2.0, -2.0]);
        let l = contact_impulses(&k, &u, 4).unwrap();
        for a in 0..4 {
            assert!((l[a] - 0.5).abs() < 1e-4, "{l:?}");
        }
        for w in after(&k, &u, &l, 4) {
            assert!(w.abs() < 1e-4, "{w}");
        }
    }

    #[test]
    fn separating_points_get_no_impulse() {
        let mut k = LcpMatrix::identity();
        k[(0, 1)] = 0.2;
        k[(1, 0)] = 0.2;
        let u = vector(&[1.0, 0.5, 0.0, 0.0]);
        assert_eq!(contact_impulses(&k, &u, 2), Some([0.0; MAX_POINTS]));
    }

    #[test]
    fn impulses_at_takes_back_what_was_applied_and_scatters_to_the_callers_points() {
        // Points 0 and 2 of three, uncoupled, unit matrix: point 0 approaches at 1 m/s after
        // an impulse of 0.5 was applied (so 1.5 before it), point 2 at 2 m/s.
        let coupling = |i: usize, j: usize| if i == j { 1.0 } else { 0.0 };
        let speed = |i: usize| if i == 0 { -1.0 } else { -2.0 };
        let applied = |j: usize| if j == 0 { 0.5 } else { 0.0 };
        let l = impulses_at(&[0, 2], 3, coupling, speed, applied).unwrap();
        assert_eq!(l.len(), 3);
        assert!(
            (l[0] - 1.5).abs() < 1e-5 && l[1] == 0.0 && (l[2] - 2.0).abs() < 1e-5,
            "{l:?}"
        );
        assert_eq!(impulses_at(&[], 3, coupling, speed, applied), None);
    }

    #[test]
    fn more_than_eight_points_or_none_are_left_to_the_sweeps() {
        let k = LcpMatrix::identity();
        let u = vector(&[-1.0, 0.0, 0.0, 0.0]);
        assert_eq!(contact_impulses(&k, &u, 0), None);
        assert_eq!(contact_impulses(&k, &u, 9), None);
    }
}
