//! The per-body solve (SPEC.md §5.3). Body `i` advances its own state through `substeps`
//! substeps; every partner is held on its step-`t` trajectory (its contact point moving at
//! its step-`t` velocity), so the result reads only step-`t` states.
//!
//! Each substep: a plastic impact pass at velocity level (sequential impulses over the
//! body's points, so a landing stops the approach without bouncing or spinning), a
//! position pass that removes what penetration is left, and a velocity pass (sequential
//! impulses: approach stop, separation cap and Coulomb friction; then torsional friction).
//! The body's world inverse inertia is a 3×3 matrix computed once per pass, and rotations
//! inside a pass are linearised (`r + δθ × r`).

use super::body::Body;
use super::body::Shape;
use super::contact::{ContactPoint, ContactSet, SetRole};
use super::frame::Frame;
use super::friction::{coulomb, Tangent, Traction};
use super::lcp;
use super::load::LoadEffect;
use super::pair::PairEffect;
use super::params::SolverParams;
use super::rotation::integrate_rotation;
use crate::math::{Quat, Vec3};
use nalgebra::Matrix3;

/// The impact and velocity passes stop their sweeps once no point's velocity changed by more
/// than this in one sweep, m/s.
const SWEEP_TOLERANCE: f32 = 1e-4;

/// One point's row of the velocity pass, for a substep (at the corrected pose).
#[derive(Clone, Copy, Default)]
struct VelocityRow {
    /// Normal impulse of the substep before this pass (impact, restitution, position
    /// impulse / h); the point takes part only if it is positive.
    pushed: f32,
    /// `r × n`.
    rn: Vec3,
    /// `I⁻¹ (r × n)`.
    irn: Vec3,
    /// Generalised inverse mass along the normal, the partner's included.
    w: f32,
    /// The tangent plane (unused in a carried or paired set).
    tangent: Tangent,
    /// Normal impulse accumulated by this pass (negative where a separation is capped).
    normal: f32,
    /// Tangential impulse accumulated by this pass.
    friction: Traction,
    /// The change of the partner point's normal velocity that the point's normal impulses
    /// imply (its share): the partner applies it in its own solve.
    partner_vn: f32,
    /// The separating speed a capped set keeps, m/s: `max_separation_speed`, or the
    /// separation the point had at the substep's start because its partner moves away, if
    /// larger (`min(u₀, −n·v_j)`). Removed, a ball that two still balls held was pulled after
    /// a box tumbling away beneath it every substep, and gained 0.12 J in four steps; a
    /// separation of the body's own (a corner rocking up off a still support) is removed.
    kept_separation: f32,
}

impl VelocityRow {
    /// The point's whole normal impulse of the substep so far, `≥ 0`.
    fn normal_impulse(&self) -> f32 {
        (self.pushed + self.normal).max(0.0)
    }
}

/// Per-point scratch kept across one substep.
#[derive(Clone, Copy, Default)]
struct PointScratch {
    /// Normal impulse accumulated by the impact pass (N·s).
    impulse: f32,
    /// Normal position impulse (mass-weighted, m·kg) applied by the position pass.
    lambda: f32,
    /// Normal velocity of the point relative to the partner at the start of the substep.
    approach: f32,
    /// Normal impulse of restitution applied after the impact pass (N·s): negative where
    /// the impact pass pushed the point harder than the set's simultaneous compression does
    /// (the point's impulse over the substep, `impulse + bounce = (1 + e)·full`, is `≥ 0`).
    bounce: f32,
}

/// One point's row of the position pass, fixed for a substep (at the predicted pose).
#[derive(Clone, Copy, Default)]
struct PositionRow {
    /// The point's offset from the centre at the predicted pose.
    offset: Vec3,
    /// `I⁻¹ (r × n)`: the rotation a unit normal position impulse adds.
    irn: Vec3,
    /// Position impulse per metre of overlap: the inverse of the generalised inverse mass
    /// along the normal, partner included; for a pile contact the body's share of the
    /// overlap over its own generalised inverse mass (`s / w_i`, [`pile_share`]).
    inv_w: f32,
    /// Gap at the predicted pose to the partner's point at the end of the substep
    /// ([`partner_at`]), m.
    gap: f32,
}

/// One Gauss–Seidel sweep of the position pass over `points` (their `rows`): each point
/// with a gap below 0 after the correction so far (`dx`, `dtheta`) takes the position
/// impulse `−gap·inv_w`, added to the correction and to its row of `scratch` (`lambda`).
/// Returns whether any point corrected.
fn position_sweep(
    points: &[ContactPoint],
    rows: &[PositionRow],
    scratch: &mut [PointScratch],
    inv_mass: f32,
    dx: &mut Vec3,
    dtheta: &mut Vec3,
) -> bool {
    let mut touched = false;
    for ((cp, row), sc) in points.iter().zip(rows).zip(scratch) {
        let gap = row.gap + cp.normal.dot(&(*dx + dtheta.cross(&row.offset)));
        if gap < 0.0 {
            let dl = -gap * row.inv_w;
            *dx += cp.normal * (dl * inv_mass);
            *dtheta += row.irn * dl;
            sc.lambda += dl;
            touched = true;
        }
    }
    touched
}

/// One point's row of the impact pass, fixed for a substep.
#[derive(Clone, Copy, Default)]
struct ImpactRow {
    /// `r × n`: the angular part of the normal direction.
    rn: Vec3,
    /// `I⁻¹ (r × n)`: the spin a unit normal impulse adds.
    irn: Vec3,
    /// Closing speed the gap allows within the substep, m/s ([`closing_allowance`]).
    gap_speed: f32,
    /// The partner point's speed towards the body, `n·v_j` (0 against the environment and a
    /// support), m/s.
    towards: f32,
    /// A pile contact's split (SPEC.md §5.3): the share of the start's deficit the body
    /// removes itself ([`pile_share`]); 1 for other sets.
    share: f32,
    /// The body's own normal velocity `n·(v + ω × r)` at the start of the step (with the
    /// substep's offset `r`), from which a pile contact's target is measured; unused for
    /// other sets.
    start_vn: f32,
    /// Generalised inverse mass along the normal of the row's impulses: the body's own for a
    /// pile contact (only this body moves in its solve), partner included otherwise.
    w: f32,
    /// `1 / w`.
    inv_w: f32,
}

/// Offset of contact point `cp` from the body's centre at orientation `rot` (a ball's is
/// along the normal whatever its orientation: a normal force on a ball has no torque).
fn offset(body: &Body, rot: &Matrix3<f32>, cp: &ContactPoint) -> Vec3 {
    match body.shape() {
        Shape::Ball { radius } => -cp.normal * radius,
        Shape::Cuboid { .. } => rot * cp.anchor,
    }
}

/// Whether some point of `set` approaches its partner at `body`'s velocities (relative to the
/// point's partner velocity): a carried set (SPEC.md §5.2) or a paired set (§5.3) acts only
/// then.
pub(crate) fn approaches(body: &Body, set: &ContactSet) -> bool {
    let rot = body.rotation.to_rotation_matrix().into_inner();
    set.points.iter().any(|cp| {
        let r = offset(body, &rot, cp);
        let v = body.linvel + body.angvel.cross(&r);
        cp.normal.dot(&(v - cp.partner_velocity)) < 0.0
    })
}

/// The part of the spin change `dw` (from a position correction) that only cancels spin:
/// `dw` scaled by the largest `s ∈ [0, 1]` with `(ω + s·dω)ᵀ I (ω + s·dω) ≤ ωᵀ I ω` for the
/// half-way bound `s ≤ −⟨ω, dω⟩_I / ⟨dω, dω⟩_I` (as the linear cap), `I` the world inertia at
/// orientation `q`; then at most `allowance` rad/s more along `dω`.
fn cancelling_spin(body: &Body, q: &Quat, w: &Vec3, dw: &Vec3, allowance: f32) -> Vec3 {
    let len = dw.norm();
    if len == 0.0 {
        return Vec3::zeros();
    }
    let d = body.inv_inertia();
    let inertia = |a: &Vec3, b: &Vec3| {
        let (la, lb) = (q.inverse_transform_vector(a), q.inverse_transform_vector(b));
        (0..3).map(|k| la[k] * lb[k] / d[k]).sum::<f32>()
    };
    let dd = inertia(dw, dw);
    let s = if dd > 0.0 {
        (-inertia(w, dw) / dd).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let extra = ((1.0 - s) * len).min(allowance);
    dw * s + dw * (extra / len)
}

/// The spin change of torsional friction at a point with normal `n` (SPEC.md §5.3): the
/// angular impulse about `n` that stops the spin `ω·n`, bounded by `cap` (μ·N·patch radius),
/// as `I⁻¹·n·L`; zero if there is no spin about `n`. It only removes rotational energy: the
/// spin about `n` moves towards 0 and never past it. A full stop computes `ω·n − k·(ω·n / k)`,
/// which rounding can leave an ulp on the other side of zero (0.061 → −1.9e-9 rad/s): then
/// the impulse is shortened by two ulps, and if even that crosses, dropped.
fn torsional_impulse(f: &Frame, w: &Vec3, n: &Vec3, cap: f32) -> Vec3 {
    let spin = w.dot(n);
    let i_n = f.spin(n);
    let k = n.dot(&i_n);
    if spin == 0.0 || k <= 0.0 || cap <= 0.0 {
        return Vec3::zeros();
    }
    let dw = i_n * (spin / k).clamp(-cap, cap);
    // By signs, not by the product's: `1e-31 · 1e-24` underflows to −0.
    let crosses = |dw: &Vec3| {
        let after = (w - dw).dot(n);
        after != 0.0 && (after < 0.0) != (spin < 0.0)
    };
    if !crosses(&dw) {
        return dw;
    }
    let short = dw * (1.0 - 2.0 * f32::EPSILON);
    if crosses(&short) {
        Vec3::zeros()
    } else {
        short
    }
}

/// How freely the body can move along `n` against its immovable contacts (`Whole` sets: the
/// environment and the bodies it rests on): the product over those sets of `1 − (m·n)²` for
/// the set's most opposing normal `m` (`m·n < 0`, a push along `n` drives the body into
/// it). 1 on flat ground pushed sideways, 0 against a wall pushed into it, in between for a
/// slope or a groove it would have to climb.
fn mobility(sets: &[ContactSet], n: &Vec3) -> f32 {
    let mut f = 1.0f32;
    for set in sets {
        if !matches!(set.role, SetRole::Whole | SetRole::Loaded) {
            continue;
        }
        let most = set
            .points
            .iter()
            .map(|cp| cp.normal.dot(n))
            .fold(0.0f32, f32::min);
        if most < 0.0 {
            f *= (1.0 - most * most).max(0.0);
        }
    }
    f
}

/// Pile contacts let pass the approach the body's pairs gave it at the start of the step
/// (SPEC.md §5.3): the partner of each pile point is taken to move away from the body along
/// the normal as fast as the pairs drove the body towards it (`n·v_j + min(n·(Δv + Δω × r),
/// 0)`), in every pass. That approach is the next step's, between the two bodies as a pair
/// or a pile contact, which conserves momentum; the partner, solving from step-`t` states,
/// cannot see it. (Stopped in the body's solve, it went to the ground: a ball struck into a
/// resting row stopped, and a ball rolling at 2 m/s into five resting balls stopped dead.)
/// `None` if no pile point is driven towards its partner (the sets are used as they are).
fn passing_pile_sets(
    body: &Body,
    pairs: &PairEffect,
    sets: &[ContactSet],
) -> Option<Vec<ContactSet>> {
    if pairs.dv == Vec3::zeros() && pairs.dw == Vec3::zeros() {
        return None;
    }
    let rot = body.rotation.to_rotation_matrix().into_inner();
    let passed = |cp: &ContactPoint| {
        let r = offset(body, &rot, cp);
        cp.normal.dot(&(pairs.dv + pairs.dw.cross(&r))).min(0.0)
    };
    let driven = sets
        .iter()
        .any(|set| set.role == SetRole::Pile && set.points.iter().any(|cp| passed(cp) < 0.0));
    if !driven {
        return None;
    }
    Some(
        sets.iter()
            .map(|set| {
                let mut set = set.clone();
                if set.role == SetRole::Pile {
                    for cp in &mut set.points {
                        cp.partner_velocity += cp.normal * passed(cp);
                    }
                }
                set
            })
            .collect(),
    )
}

/// Where body `i`'s solve holds a partner's point at the end of substep `through` (counted
/// from 1; SPEC.md §5.3, "The per-body solve"). A support (other than a load system's) or the static environment: its
/// step-`t` point advanced by one substep of its step-`t` velocity, whatever the substep (a
/// support's downward velocity may be stopped in its own solve; holding it keeps `i` from
/// following it into the ground). A movable partner beside `i` (pile, carried and paired
/// sets, and a load system's support, [`SetRole::Loaded`]): advanced by `through` substeps,
/// so `i` can follow a partner that moves on through
/// the step (held after the first substep, a ball pushed along with its neighbour at
/// 0.5 m/s was stopped against it every step and kept only 0.325 m/s; a cube, 0).
fn partner_at(role: SetRole, cp: &ContactPoint, h: f32, through: u32) -> Vec3 {
    match role {
        SetRole::Whole => cp.partner_point + cp.partner_velocity * h,
        SetRole::Pile | SetRole::Carried | SetRole::Paired | SetRole::Loaded => {
            cp.partner_point + cp.partner_velocity * (h * through as f32)
        }
    }
}

/// How fast body `i` may close a contact point's gap within a substep, and how fast the
/// partner's point moves towards `i` (`n·v_j`); the impact pass's target for `i`'s normal
/// velocity is `min(towards − allowance, 0)` (`allowance` at most `landing_speed` for a held
/// set). Against the static environment and a support (other than a load system's): `towards = 0` and the allowance closes
/// the gap `gap0` at the end of the substep (the partner where [`partner_at`] holds it). Beside
/// a movable partner the allowance is relative to the partner: the gap at the start of the
/// substep, never less than 0, so `i` follows a partner that moves away (at most as fast as
/// it), an overlap is the position pass's to remove, and a partner's approach is the partner's
/// to stop. (Absolute, a ball touching a neighbour that moved away at 0.5 m/s was held to
/// the landing speed, 0.3 m/s, in every step and moved on at 0.45 m/s beside the neighbour's
/// 0.5 m/s.)
fn closing_allowance(role: SetRole, cp: &ContactPoint, gap0: f32, h: f32) -> (f32, f32) {
    match role {
        SetRole::Whole => (0.0, gap0.max(0.0) / h),
        SetRole::Pile | SetRole::Carried | SetRole::Paired | SetRole::Loaded => {
            let towards = cp.normal.dot(&cp.partner_velocity);
            let gap_start = gap0 + towards * h;
            (towards, gap_start.max(0.0) / h)
        }
    }
}

/// The share of a pile contact's approach (or overlap) that the body removes itself (SPEC.md
/// §5.3): `f·w / (f·w + w_j)` with `w` and `w_j` the two generalised inverse masses along
/// the normal and `f` the body's [`mobility`] along it. The partner removes its own share in
/// its own solve; with `f = 1` on both sides the two shares sum to 1, with less they sum to
/// less and the rest is left to later steps. A body its supports hold in place leaves the
/// contact to its partner instead of being wedged up its supports.
fn pile_share(mobility: f32, w_own: f32, w_partner: f32) -> f32 {
    let yielding = mobility * w_own;
    if yielding + w_partner > 0.0 {
        yielding / (yielding + w_partner)
    } else {
        1.0
    }
}

/// One contact point's row for [`face_impulses`].
struct FaceRow {
    normal: Vec3,
    /// `r × n`.
    rn: Vec3,
    /// `I⁻¹ (r × n)`.
    irn: Vec3,
    /// The change of the point's normal velocity wanted, m/s (`> 0`).
    deficit: f32,
}

/// Keeps, of more than four points with a deficit, the four with the largest (the earlier
/// point first on a tie), in their order: a fast box's reach takes in the far face's corners
/// too (a rod 0.4 m long at 28 m/s has all eight within one substep's travel), and stopping
/// the near face, the face that meets the surface, leaves the far one its gap.
fn nearest_face(
    at: &mut smallvec::SmallVec<[usize; 4]>,
    rows: &mut smallvec::SmallVec<[FaceRow; 4]>,
) {
    if rows.len() <= 4 {
        return;
    }
    let mut order: smallvec::SmallVec<[usize; 8]> = (0..rows.len()).collect();
    order.sort_by(|&x, &y| rows[y].deficit.total_cmp(&rows[x].deficit).then(x.cmp(&y)));
    let mut keep: smallvec::SmallVec<[bool; 16]> = smallvec::smallvec![false; rows.len()];
    for &o in order.iter().take(4) {
        keep[o] = true;
    }
    let mut m = 0;
    at.retain(|_| {
        m += 1;
        keep[m - 1]
    });
    let mut m = 0;
    rows.retain(|_| {
        m += 1;
        keep[m - 1]
    });
}

/// The normal impulses that give 2 to 4 points of one body against the static environment
/// their wanted velocity changes at once (SPEC.md §5.3): `K·λ = deficit`, `K` the points'
/// coupled inverse-mass matrix, solved in f64 by Cholesky with `K` regularised by 1e-6 of its
/// largest diagonal (the points of a face constrain only three degrees of freedom, so `K` is
/// singular and the regularised solution is the least-squares one of least norm: a face
/// parallel to the wall is pushed evenly). `None` if any impulse would be negative (then the
/// point-by-point sweeps decide which points push). Solved point after point, a face's
/// corners at the end of a long thin body couple almost one for one: the sweeps gave one
/// corner nearly all the impulse, turned the body, and a rod arriving end-on rebounded.
fn face_impulses(inv_mass: f32, rows: &[FaceRow]) -> Option<[f32; 4]> {
    let m = rows.len();
    if !(2..=4).contains(&m) {
        return None;
    }
    let mut k = nalgebra::Matrix4::<f64>::identity();
    let mut rhs = nalgebra::Vector4::<f64>::zeros();
    let mut largest = 0.0f64;
    for (a, ra) in rows.iter().enumerate() {
        rhs[a] = f64::from(ra.deficit);
        for (c, rc) in rows.iter().enumerate() {
            k[(a, c)] = f64::from(ra.normal.dot(&rc.normal)) * f64::from(inv_mass)
                + ra.rn.cast::<f64>().dot(&rc.irn.cast::<f64>());
        }
        largest = largest.max(k[(a, a)]);
    }
    for a in 0..m {
        k[(a, a)] += lcp::REGULARISATION * largest;
    }
    let lambda = k.cholesky()?.solve(&rhs);
    let mut out = [0.0f32; 4];
    for a in 0..m {
        if lambda[a].is_nan() || lambda[a] < 0.0 {
            return None;
        }
        out[a] = lambda[a] as f32;
    }
    Some(out)
}

/// The whole compression impulses of a set's pushed points (those with an impact impulse,
/// at most eight: `None` otherwise, or if the exact solve fails), solved exactly
/// ([`lcp::contact_impulses`]) at the impact pass's rows from the velocities `v`, `w` after
/// the impact pass with the impact impulses taken back out. 0 for the other points. Each
/// row's partner takes no part: the sweeps give the partner's inverse mass only to the step
/// size, not to the solution they converge to.
fn exact_compression(
    points: &[ContactPoint],
    scratch: &[PointScratch],
    rows: &[ImpactRow],
    inv_mass: f32,
    v: &Vec3,
    w: &Vec3,
) -> Option<smallvec::SmallVec<[f32; lcp::MAX_POINTS]>> {
    let at: smallvec::SmallVec<[usize; 8]> = (0..points.len())
        .filter(|&m| scratch[m].impulse > 0.0)
        .collect();
    let coupling = |i: usize, j: usize| {
        points[i]
            .normal
            .cast::<f64>()
            .dot(&points[j].normal.cast::<f64>())
            * f64::from(inv_mass)
            + rows[i].rn.cast::<f64>().dot(&rows[j].irn.cast::<f64>())
    };
    let speed = |i: usize| f64::from(points[i].normal.dot(v) + w.dot(&rows[i].rn));
    // The velocities before the impact impulses.
    let applied = |j: usize| f64::from(scratch[j].impulse);
    lcp::impulses_at(&at, points.len(), coupling, speed, applied)
}

/// The face block (SPEC.md §5.3, step 3) of a box against the static environment: `row(k,
/// cp, b)` gives point `k`'s row if it has a deficit at the body's current velocities; the
/// points with one (the four largest, [`nearest_face`]) are solved together
/// ([`face_impulses`]) and their impulses applied to `b`. Returns each point's impulse, for the
/// caller's accumulator (empty if the block was not applied).
fn face_block(
    b: &mut Body,
    sets: &[ContactSet],
    inv_mass: f32,
    row: impl Fn(usize, &ContactPoint, &Body) -> Option<FaceRow>,
) -> smallvec::SmallVec<[(usize, f32); 4]> {
    let mut pushed = smallvec::SmallVec::new();
    let mut k = 0;
    for set in sets {
        let start = k;
        k += set.points.len();
        if set.partner.is_some() {
            continue;
        }
        let mut at: smallvec::SmallVec<[usize; 4]> = smallvec::SmallVec::new();
        let mut rows: smallvec::SmallVec<[FaceRow; 4]> = smallvec::SmallVec::new();
        for (kk, cp) in (start..k).zip(&set.points) {
            if let Some(r) = row(kk, cp, b) {
                at.push(kk);
                rows.push(r);
            }
        }
        nearest_face(&mut at, &mut rows);
        if let Some(lambda) = face_impulses(inv_mass, &rows) {
            for ((&kk, r), l) in at.iter().zip(&rows).zip(lambda) {
                b.linvel += r.normal * (l * inv_mass);
                b.angvel += r.irn * l;
                pushed.push((kk, l));
            }
        }
    }
    pushed
}

/// The per-point and per-set rows of one body's solve, kept between solves so a cell's
/// bodies reuse one allocation (a solve starts them afresh: `reset`).
#[derive(Default)]
pub(crate) struct SolveRows {
    scratch: Vec<PointScratch>,
    offsets: Vec<Vec3>,
    impact: Vec<ImpactRow>,
    position: Vec<PositionRow>,
    velocity: Vec<VelocityRow>,
    /// Per set, whether the impact pass holds its points to `landing_speed` (a point would
    /// touch within the substep, and the set is not the static environment).
    held_sets: Vec<bool>,
    bounced_sets: Vec<bool>,
}

impl SolveRows {
    /// Rows for `points` contact points in `sets` sets, every one at its default, as a
    /// fresh allocation would hold them.
    fn reset(&mut self, points: usize, sets: usize) {
        fn fresh<T: Clone>(v: &mut Vec<T>, len: usize, value: T) {
            v.clear();
            v.resize(len, value);
        }
        fresh(&mut self.scratch, points, PointScratch::default());
        fresh(&mut self.offsets, points, Vec3::zeros());
        fresh(&mut self.impact, points, ImpactRow::default());
        fresh(&mut self.position, points, PositionRow::default());
        fresh(&mut self.velocity, points, VelocityRow::default());
        fresh(&mut self.held_sets, sets, false);
        fresh(&mut self.bounced_sets, sets, false);
    }
}

/// Advances `body` by one step of `dt` seconds against the contact sets (ascending partner
/// id, static environment last). `body` carries its symmetric pairs' velocity changes,
/// `pairs` (SPEC.md §5.3); a pile contact lets their approach towards its partner pass (the
/// partner taken to move away as fast, [`passing_pile_sets`]). `load`: the velocity change
/// (linear, angular) the bodies resting on it give it over the step (SPEC.md §5.2, "Load"),
/// spread over the substeps like a force. Returns the new state (velocities and pose).
#[allow(clippy::too_many_arguments)]
pub(crate) fn solve_body(
    body: &Body,
    pairs: &PairEffect,
    load: &LoadEffect,
    sets: &[ContactSet],
    gravity: Vec3,
    dt: f32,
    p: &SolverParams,
    rows: &mut SolveRows,
) -> Body {
    let n_sub = p.substeps.max(1);
    let h = dt / n_sub as f32;
    // The load of the bodies resting on this one (SPEC.md §5.2, "Load"): their impulses over
    // the step, spread over the substeps like a force.
    let share = 1.0 / n_sub as f32;
    let loaded = !load.is_none();
    let mut b = body.clone();
    if sets.is_empty() {
        // Free flight: no contact can act within the step.
        for _ in 0..n_sub {
            b.linvel += gravity * h;
            if loaded {
                b.linvel += load.dv * share;
                b.angvel += load.dw * share;
            }
            b.position += b.linvel * h;
            let turned = b.free_rotation(h);
            b.rotation = turned.rotation;
            b.angvel = turned.angvel;
        }
        return b;
    }
    let passing = passing_pile_sets(body, pairs, sets);
    let sets: &[ContactSet] = passing.as_deref().unwrap_or(sets);
    let count: usize = sets.iter().map(|s| s.points.len()).sum();
    rows.reset(count, sets.len());
    let SolveRows {
        scratch,
        offsets,
        impact,
        position,
        velocity,
        held_sets,
        bounced_sets,
    } = rows;
    let rest_threshold = 2.0 * gravity.norm() * h;
    let ball = matches!(body.shape(), Shape::Ball { .. });
    // Each pile point's mobility along its normal (the normals are fixed for the step); read
    // only at pile points, so left empty without a pile set.
    let mobilities: Vec<f32> = if sets.iter().any(|s| s.role == SetRole::Pile) {
        sets.iter()
            .flat_map(|set| {
                set.points.iter().map(move |cp| {
                    if set.role == SetRole::Pile {
                        mobility(sets, &cp.normal)
                    } else {
                        1.0
                    }
                })
            })
            .collect()
    } else {
        Vec::new()
    };

    for sub in 0..n_sub {
        // Start of the substep: offsets, approach speeds (for restitution).
        let f0 = Frame::new(&b, &b.rotation);
        let mut k = 0;
        for set in sets {
            for cp in &set.points {
                let r = offset(&b, &f0.rot, cp);
                let vi = b.linvel + b.angvel.cross(&r);
                offsets[k] = r;
                scratch[k] = PointScratch {
                    impulse: 0.0,
                    lambda: 0.0,
                    approach: cp.normal.dot(&(vi - cp.partner_velocity)),
                    bounce: 0.0,
                };
                k += 1;
            }
        }
        b.linvel += gravity * h;
        if loaded {
            b.linvel += load.dv * share;
            b.angvel += load.dw * share;
        }

        // Impact pass: sequential impulses so that no point closes more than its current
        // gap within the substep (plastic: an approach is stopped, never reflected here).
        // Once a point of a partner's manifold would touch within the substep, the other
        // points of that manifold may approach at most `landing_speed`: a tilted face lands
        // as a face, not corner first (which would turn the fall into spin). Against the
        // static environment (walls, ground, static boxes: one set) no body is held back: it
        // touches the surface in the substep it reaches it, instead of stopping short by up
        // to its travel in a substep (a 20 cm cube at 29 m/s stopped 17 cm short); a box's
        // face is solved as one block first (`face_impulses`), which lands it square.
        let mut k = 0;
        for (s, set) in sets.iter().enumerate() {
            let mut engaged = false;
            for cp in &set.points {
                let r = offsets[k];
                let pj = partner_at(set.role, cp, h, sub + 1);
                let gap0 = cp.normal.dot(&(b.position + r - pj));
                let vn = cp.normal.dot(&(b.linvel + b.angvel.cross(&r)));
                engaged |= gap0 + vn * h < 0.0;
                let rn = r.cross(&cp.normal);
                let irn = f0.spin(&rn);
                let w_own = f0.inv_mass + rn.dot(&irn);
                let pile = set.role == SetRole::Pile;
                let (towards, gap_speed) = closing_allowance(set.role, cp, gap0, h);
                let w = if pile {
                    w_own
                } else {
                    w_own + cp.partner_inv_mass
                };
                impact[k] = ImpactRow {
                    rn,
                    irn,
                    w,
                    inv_w: 1.0 / w,
                    towards,
                    gap_speed,
                    share: if pile {
                        pile_share(mobilities[k], w_own, cp.partner_inv_mass)
                    } else {
                        1.0
                    },
                    start_vn: cp.normal.dot(&(body.linvel + body.angvel.cross(&r))),
                };
                k += 1;
            }
            held_sets[s] = engaged && set.partner.is_some();
        }
        // A box's face against the static environment: the points that approach faster than
        // their gaps allow, solved together first (the sweeps below then refine).
        if !ball {
            let pushed = face_block(&mut b, sets, f0.inv_mass, |k, cp, b| {
                let row = &impact[k];
                let vn = cp.normal.dot(&b.linvel) + b.angvel.dot(&row.rn);
                let deficit = -row.gap_speed - vn;
                (deficit > 0.0).then_some(FaceRow {
                    normal: cp.normal,
                    rn: row.rn,
                    irn: row.irn,
                    deficit,
                })
            });
            for (k, l) in pushed {
                scratch[k].impulse += l;
            }
        }
        for _ in 0..p.impact_iterations {
            let mut largest_change = 0.0f32;
            let mut k = 0;
            for (s, set) in sets.iter().enumerate() {
                let limit = if held_sets[s] {
                    p.landing_speed
                } else {
                    f32::INFINITY
                };
                for cp in &set.points {
                    let row = &impact[k];
                    // n·(v + ω × r) = n·v + ω·(r × n).
                    let vn = cp.normal.dot(&b.linvel) + b.angvel.dot(&row.rn);
                    let target = (row.towards - row.gap_speed.min(limit)).min(0.0);
                    // A pile contact: the partner, solving the same contact in its own solve
                    // from the same step-`t` states, removes its share of the approach the
                    // two had at the start of the step; the approach this body gains within
                    // its solve (gravity, its supports), which the partner cannot see, is
                    // this body's to stop. Target: its share of the start's deficit. (Each
                    // body stopping all of it, the pair's approach was removed twice and the
                    // two rebounded from each other every other step.)
                    let target = if row.share < 1.0 {
                        row.start_vn + (target - row.start_vn) * row.share
                    } else {
                        target
                    };
                    let acc = scratch[k].impulse;
                    let next = (acc + (target - vn) * row.inv_w).max(0.0);
                    if next != acc {
                        let d = next - acc;
                        b.linvel += cp.normal * (d * f0.inv_mass);
                        b.angvel += row.irn * d;
                        scratch[k].impulse = next;
                        largest_change = largest_change.max(d.abs() * row.w);
                    }
                    k += 1;
                }
            }
            // Converged: no point's velocity changed by more than 0.1 mm/s.
            if largest_change < SWEEP_TOLERANCE {
                break;
            }
        }

        // Restitution (Poisson, as for pairs, SPEC.md §5.3): per set whose fastest approach
        // at the start of the substep exceeds the resting speed, each point the impact pass
        // pushed receives, once the body has moved to contact, the rest of its compression
        // impulse (the impulse that stops its approach entirely: the impact pass's,
        // continued to a zero approach) and `e` times all of it. Unlike a per-point target
        // speed (`−e·v_n` at each point, which added energy to spinning cubes hitting a wall
        // on two corners), this never adds energy for `e ≤ 1`.
        let mut k = 0;
        for (s, set) in sets.iter().enumerate() {
            let n_pts = set.points.len();
            let range = k..k + n_pts;
            k += n_pts;
            bounced_sets[s] = false;
            let fastest = scratch[range.clone()]
                .iter()
                .map(|sc| -sc.approach)
                .fold(0.0f32, f32::max);
            if set.restitution <= 0.0
                || fastest <= rest_threshold
                || scratch[range.clone()].iter().all(|sc| sc.impulse <= 0.0)
            {
                continue;
            }
            // The full compression impulses, on a copy of the velocities (only sets with
            // restitution reach here: never a pile, carried or paired set, so every row's `w` has the
            // partner's inverse mass in it).
            let (mut v, mut w) = (b.linvel, b.angvel);
            let mut full: smallvec::SmallVec<[f32; 8]> =
                scratch[range.clone()].iter().map(|sc| sc.impulse).collect();
            // Up to eight points: solved exactly. The sweeps stop at a tolerance of 0.1 mm/s,
            // and a compression left that far from complementary let an elastic box landing
            // flat on a wall gain 1.4e-5 of its energy.
            let exact = exact_compression(
                &set.points,
                &scratch[range.clone()],
                &impact[range.clone()],
                f0.inv_mass,
                &b.linvel,
                &b.angvel,
            );
            let sweeps = if let Some(exact) = exact {
                full.copy_from_slice(&exact[..n_pts]);
                0
            } else {
                p.impact_iterations.max(1)
            };
            for _ in 0..sweeps {
                let mut largest_change = 0.0f32;
                for (m, (kk, cp)) in range.clone().zip(&set.points).enumerate() {
                    if scratch[kk].impulse <= 0.0 {
                        continue;
                    }
                    let row = &impact[kk];
                    let vn = cp.normal.dot(&v) + w.dot(&row.rn);
                    let next = (full[m] - vn * row.inv_w).max(0.0);
                    if next != full[m] {
                        let d = next - full[m];
                        v += cp.normal * (d * f0.inv_mass);
                        w += row.irn * d;
                        full[m] = next;
                        largest_change = largest_change.max(d.abs() * row.w);
                    }
                }
                if largest_change < SWEEP_TOLERANCE {
                    break;
                }
            }
            // Applied at the end of the substep's motion (below): the rest of the
            // compression, which the impact pass left to the gap, and `e` times all of it,
            // so each point's impulse over the substep is `(1 + e)` times its share of the
            // simultaneous compression. That rest is negative at a point the impact pass
            // pushed harder than the compression does (its gap closed first, but the other
            // points' impulses lift it): dropping the negative part left that point its
            // impact impulse on top, and a spinning elastic cube whose two corners reached a
            // ceiling in one substep gained 5 % of its energy in one step.
            for (m, kk) in range.enumerate() {
                let j = (full[m] - scratch[kk].impulse) + set.restitution * full[m];
                if j != 0.0 {
                    scratch[kk].bounce = j;
                    bounced_sets[s] = true;
                }
            }
        }

        // Predict.
        let xp = b.position + b.linvel * h;
        // With contacts the spin is kept through the substep's motion (a rotation about `ω`
        // keeps `½ωᵀIω`); the torque-free turn of the angular momentum is for free flight
        // only (SPEC.md §5.3, "The per-body solve").
        let qp = integrate_rotation(&b.rotation, &b.angvel, h);
        let fp = Frame::new(&b, &qp);

        // Position pass: each partner separately from the predicted pose (Gauss–Seidel over
        // its points, rotation linearised), corrections averaged over the partners that
        // corrected anything; the pile contacts together (below), their correction added
        // whole.
        let mut sum_dx = Vec3::zeros();
        let mut sum_dtheta = Vec3::zeros();
        let mut active = 0u32;
        // Pile contacts (`SetRole::Pile`): the body's share of each overlap.
        let mut shared_dx = Vec3::zeros();
        let mut shared_dtheta = Vec3::zeros();
        let mut any_pile = false;
        let mut k = 0;
        for set in sets {
            let mut dx = Vec3::zeros();
            let mut dtheta = Vec3::zeros();
            let mut touched = false;
            if set.role.stops_approach_only() {
                // Not `i`'s overlap to remove: the partner rests on `i` and corrects it, or
                // the pair's response does.
                k += set.points.len();
                continue;
            }
            for (m, cp) in set.points.iter().enumerate() {
                let r0 = offset(&b, &fp.rot, cp);
                let rn = r0.cross(&cp.normal);
                let irn = fp.spin(&rn);
                let pj = partner_at(set.role, cp, h, sub + 1);
                position[k + m] = PositionRow {
                    offset: r0,
                    irn,
                    // Own share of the overlap (`share · gap / w_own`); the pair's for others.
                    inv_w: if set.role == SetRole::Pile {
                        let w_own = fp.inv_mass + rn.dot(&irn);
                        pile_share(mobilities[k + m], w_own, cp.partner_inv_mass) / w_own
                    } else {
                        1.0 / (fp.inv_mass + rn.dot(&irn) + cp.partner_inv_mass)
                    },
                    gap: cp.normal.dot(&(xp + r0 - pj)),
                };
            }
            let first = k;
            k += set.points.len();
            if set.role == SetRole::Pile {
                // Corrected below, with the other pile contacts.
                any_pile = true;
                continue;
            }
            let rows = first..k;
            for _ in 0..p.sweeps.max(1) {
                touched |= position_sweep(
                    &set.points,
                    &position[rows.clone()],
                    &mut scratch[rows.clone()],
                    fp.inv_mass,
                    &mut dx,
                    &mut dtheta,
                );
            }
            if touched {
                active += 1;
                sum_dx += dx;
                sum_dtheta += dtheta;
            }
        }
        // The pile contacts' shares, in Gauss–Seidel sweeps over all their points together,
        // so each point sees what the others' corrections already did. (Each partner's share
        // computed apart and added whole, two partners on one side of a small ball pushed it
        // 2.4 cm into the partner on its other side, which pushed it back in the next
        // substep: caged by four neighbours, the ball climbed 4 mm a step, 13 cm in all, and
        // lifted the balls above it; docs/open-defects §4.)
        if any_pile {
            for _ in 0..p.sweeps.max(1) {
                let mut k = 0;
                for set in sets {
                    let rows = k..k + set.points.len();
                    if set.role == SetRole::Pile {
                        position_sweep(
                            &set.points,
                            &position[rows.clone()],
                            &mut scratch[rows.clone()],
                            fp.inv_mass,
                            &mut shared_dx,
                            &mut shared_dtheta,
                        );
                    }
                    k = rows.end;
                }
            }
        }
        let shared = shared_dx != Vec3::zeros() || shared_dtheta != Vec3::zeros();
        let (x1, q1, dtheta) = if active > 0 || shared {
            let scale = p.relaxation / active.max(1) as f32;
            let sum_dx = sum_dx + shared_dx * active.max(1) as f32;
            let sum_dtheta = sum_dtheta + shared_dtheta * active.max(1) as f32;
            let dtheta = sum_dtheta * scale;
            (
                xp + sum_dx * scale,
                integrate_rotation(&qp, &dtheta, 1.0),
                dtheta,
            )
        } else {
            (xp, qp, Vec3::zeros())
        };
        // The motion of the substep: what friction's change is measured against (below).
        let v_moved = b.linvel;
        // The restitution impulses, at the impact pass's rows (orientation at the start),
        // before the correction's velocity is capped: the cap measures against the velocity
        // the correction is added to. (Capped against the velocity before the bounce, a
        // correction that cancelled some of a corner's approach was added to its rebound
        // instead, and a spinning elastic cube gained 0.5 % of its energy on a wall.)
        // The spin they add is computed at the start's orientation and turned with the body
        // through the substep's predicted rotation (as a pair's time-of-impact correction
        // turns a box's spin), so it keeps the rotational energy it was computed to give: at
        // the turned orientation, an elastic brick's rebound gained 0.2 %. (A body whose
        // principal inertias are equal has the same energy in every orientation: left as
        // it is.)
        let isotropic = body.props().isotropic();
        let (mut v_pred, mut w_pred) = (b.linvel, b.angvel);
        let mut bounce_dw = Vec3::zeros();
        let mut k = 0;
        for set in sets {
            for cp in &set.points {
                let j = scratch[k].bounce;
                if j != 0.0 {
                    v_pred += cp.normal * (j * f0.inv_mass);
                    bounce_dw += impact[k].irn * j;
                }
                k += 1;
            }
        }
        if bounce_dw != Vec3::zeros() {
            w_pred += body.carry_spin(&b.rotation, &qp, bounce_dw);
        }
        // The velocity a correction adds may cancel the approach but never add kinetic
        // energy (split impulse: the positions take the whole correction, the velocities
        // only what cancels motion against it). Linear: along its own direction it is
        // capped at the velocity it opposes (`|v + dv| ≤ |v|`), plus the separation
        // allowance (0 by default). Angular, in the inertia metric: at most the spin it
        // opposes (`(ω + dω)ᵀI(ω + dω) ≤ ωᵀIω`), plus the allowance over the bounding
        // radius.
        let mut dv = (x1 - xp) / h;
        let dv_len = dv.norm();
        if dv_len > 0.0 {
            let dv_cap = (-v_pred.dot(&dv) / dv_len).max(0.0) + p.max_separation_speed;
            if dv_len > dv_cap {
                dv *= dv_cap / dv_len;
            }
        }
        // A body whose principal inertias differ: the correction's turn (`q1` from `qp`)
        // turns its spin along, so the spin keeps its body-frame axis and the rotational
        // energy the substep left it (turned alone, an elastic brick bouncing in a box gained
        // 1.9e-5 of its energy at a corner's correction); the cap is measured at `qp`,
        // before that turn. Equal inertias: the energy is the same in every orientation,
        // and the spin is left as it is (and the cap measured at `q1`, as before the turn
        // was added: the same value, and the same bits).
        let dw = cancelling_spin(
            body,
            if isotropic || dtheta == Vec3::zeros() {
                &q1
            } else {
                &qp
            },
            &w_pred,
            &(dtheta / h),
            p.max_separation_speed / body.bounding_radius(),
        );
        b.position = x1;
        b.rotation = q1;
        b.linvel = v_pred + dv;
        b.angvel = w_pred + dw;
        if dtheta != Vec3::zeros() {
            b.angvel = body.carry_spin(&qp, &q1, b.angvel);
        }

        // Velocity pass: per point that pushed in this substep, remove approach velocity
        // (or keep restitution's separation) and apply Coulomb friction within `μ` times the
        // point's whole normal impulse of the substep, this pass's included: sequential
        // impulses over the points, repeated (at most `velocity_iterations` sweeps) until no
        // point's velocity changes by more than 0.1 mm/s. (One sweep with friction bounded
        // without this pass's normal impulses, which balance friction's tipping moment,
        // braked a sliding cube at 0.8 μg, turned it and let a box on a 35° slope slide 35 %
        // too fast.) Each point carries a virtual partner that takes its share of the
        // point's impulses (by the partner's inverse mass), so the sweeps leave the body its
        // share of the pair's change, as a single application does.
        // Friction then acts as if before the substep's motion (below).
        let f1 = Frame::new(&b, &q1);
        let mut any = false;
        let mut k = 0;
        for set in sets {
            for cp in &set.points {
                let sc = scratch[k];
                let pushed = sc.impulse + sc.bounce + sc.lambda / h;
                velocity[k] = if pushed > 0.0 {
                    any = true;
                    let r = offset(&b, &f1.rot, cp);
                    let rn = r.cross(&cp.normal);
                    let irn = f1.spin(&rn);
                    let w_own = f1.inv_mass + rn.dot(&irn);
                    let away = -cp.normal.dot(&cp.partner_velocity);
                    VelocityRow {
                        pushed,
                        rn,
                        irn,
                        kept_separation: p.max_separation_speed.max(away.min(sc.approach)),
                        w: w_own + cp.partner_inv_mass,
                        tangent: if set.role.stops_approach_only() {
                            Tangent::default()
                        } else {
                            Tangent::new(&f1, &r, &cp.normal, cp.partner_inv_mass)
                        },
                        ..VelocityRow::default()
                    }
                } else {
                    VelocityRow::default()
                };
                k += 1;
            }
        }
        // A box's face against the static environment: the approaching points stopped
        // together first, as in the impact pass.
        if any && !ball {
            let pushed = face_block(&mut b, sets, f1.inv_mass, |k, cp, b| {
                let row = &velocity[k];
                let vn = cp.normal.dot(&b.linvel) + b.angvel.dot(&row.rn);
                (row.pushed > 0.0 && vn < 0.0).then_some(FaceRow {
                    normal: cp.normal,
                    rn: row.rn,
                    irn: row.irn,
                    deficit: -vn,
                })
            });
            for (k, l) in pushed {
                velocity[k].normal += l;
            }
        }
        let sweeps = if any { p.velocity_iterations } else { 0 };
        for _ in 0..sweeps {
            let mut largest_change = 0.0f32;
            let mut k = 0;
            for (s, set) in sets.iter().enumerate() {
                let approach_only = set.role.stops_approach_only();
                // Only an approach is removed in a set that bounced (restitution's separation
                // is kept) or only stops an approach (carried, paired); elsewhere depenetration
                // must not fling bodies, and a separating speed above the row's
                // `kept_separation` is removed too.
                let capped = !bounced_sets[s] && !approach_only;
                for cp in &set.points {
                    let row = &mut velocity[k];
                    k += 1;
                    if row.pushed <= 0.0 {
                        continue;
                    }
                    let wj = cp.partner_inv_mass;
                    let vn = cp.normal.dot(&(b.linvel - cp.partner_velocity))
                        + b.angvel.dot(&row.rn)
                        - row.partner_vn;
                    let target = if vn < 0.0 {
                        0.0
                    } else if capped {
                        vn.min(row.kept_separation)
                    } else {
                        vn
                    };
                    // The point's normal impulse over the substep stays ≥ 0: a separation is
                    // removed only as far as the point pushed (no adhesion), and where only
                    // an approach is removed, this pass only pushes.
                    // (`pushed` includes the position impulse / h, of which the velocities
                    // took only the part that cancels motion.)
                    let floor = if capped { -row.pushed } else { 0.0 };
                    let next = (row.normal + (target - vn) / row.w).max(floor);
                    if next != row.normal {
                        let d = next - row.normal;
                        b.linvel += cp.normal * (d * f1.inv_mass);
                        b.angvel += row.irn * d;
                        row.partner_vn -= d * wj;
                        row.normal = next;
                        largest_change = largest_change.max(d.abs() * row.w);
                    }
                    if approach_only {
                        continue;
                    }
                    let bound = set.friction * row.normal_impulse();
                    let change = coulomb(
                        &row.tangent,
                        &mut b,
                        &cp.partner_velocity,
                        bound,
                        &mut row.friction,
                    );
                    largest_change = largest_change.max(change);
                }
            }
            if largest_change < SWEEP_TOLERANCE {
                break;
            }
        }
        // Friction's change of linear velocity `Δv_f` as if applied before the motion: only
        // its part against the substep's own motion, at most all of it (a retreat along the
        // path the body just moved), so a box on a slope that holds it stays where it is
        // (applied only after the motion, it crept `g·sin θ·h²` down every substep: 8.6
        // mm/s on 3° with one substep; moved by the whole `h·Δv_f`, bodies in piles were
        // pushed into their neighbours and piles of balls gained up to 0.26 J after landing).
        let friction_dv: Vec3 = velocity
            .iter()
            .map(|row| row.tangent.linear_change(&row.friction.impulse()))
            .sum();
        let path = v_moved * h;
        let len_sq = path.norm_squared();
        if len_sq > 0.0 {
            let back = (-(friction_dv * h).dot(&path) / len_sq).clamp(0.0, 1.0);
            b.position -= path * back;
        }
        // Torsional friction, once the point's normal impulse is known.
        let mut k = 0;
        for set in sets {
            for cp in &set.points {
                let row = &velocity[k];
                k += 1;
                if row.pushed <= 0.0 || set.role.stops_approach_only() {
                    continue;
                }
                let bound = set.friction * row.normal_impulse();
                b.angvel -= torsional_impulse(&f1, &b.angvel, &cp.normal, bound * p.patch_radius);
            }
        }
    }
    b
}
