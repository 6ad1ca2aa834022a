//! The symmetric response of a body pair (SPEC.md §5.3, pair contacts).
//!
//! A pair contact is solved as an isolated two-body collision, as a pure function of the two
//! bodies' step-`t` states and their manifold computed in canonical order (lower id first).
//! Both cells that step the two bodies compute it from the same inputs in the same order, so
//! they get the same bits: body `a` receives exactly the negated linear impulse of body `b`,
//! and momentum is conserved up to the rounding of `impulse / mass`.

use super::body::{Body, Shape};
use super::contact::PairManifold;
use super::lcp;
use crate::math::{Quat, Vec3};
use nalgebra::Matrix3;
use smallvec::SmallVec;

/// Sequential-impulse sweeps of a pair's compression phase (a pair has at most a handful of
/// points; the sweeps stop earlier once converged).
const PAIR_ITERATIONS: u32 = 16;

/// The compression sweeps stop once no point's normal velocity changed by more than this,
/// m/s.
const PAIR_TOLERANCE: f32 = 1e-6;

/// Sweeps of the friction phase.
const FRICTION_SWEEPS: u32 = 2;

/// Slip speeds at or below this are left alone (no direction can be taken from them), m/s.
const SLIP_EPSILON: f32 = 1e-9;

/// One point of a pair's manifold at step `t`, world frame.
#[derive(Clone, Copy, Debug)]
struct PairPoint {
    /// Offset of the point from `a`'s centre.
    ra: Vec3,
    /// Offset of the point from `b`'s centre.
    rb: Vec3,
    /// Signed distance along the normal (negative: penetration), m.
    gap: f32,
    /// Normal velocity of `b`'s point relative to `a`'s at step `t` (negative: closing), m/s.
    speed: f32,
}

/// A body's part of a pair contact: what its state at `t + 1` takes from the pair.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct PairEffect {
    /// Change of linear velocity, m/s.
    pub dv: Vec3,
    /// Change of angular velocity, rad/s.
    pub dw: Vec3,
    /// Displacement added to the position at the end of the step, m.
    pub dx: Vec3,
    /// Rotation vector added to the orientation at the end of the step, rad.
    pub dtheta: Vec3,
}

impl PairEffect {
    /// Sums two effects.
    pub fn add(&mut self, o: &PairEffect) {
        self.dv += o.dv;
        self.dw += o.dw;
        self.dx += o.dx;
        self.dtheta += o.dtheta;
    }
}

/// A closing pair as the matching and the mass splitting see it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Edge {
    /// Time of impact, then the two ids: the order of the matching.
    pub key: (f32, u64, u64),
    /// Whether the pair approaches faster than the resting speed (an impact, which takes
    /// part in the matching) rather than resting (resolved in every step with split masses).
    pub impact: bool,
    /// The fastest closing point's approach speed, m/s.
    pub fastest: f32,
}

/// A body pair in contact at step `t`, seen in canonical order (`a.id < b.id`).
#[derive(Clone, Debug)]
pub(crate) struct PairContact {
    a: Side,
    b: Side,
    /// Unit normal from `a` towards `b`.
    normal: Vec3,
    points: SmallVec<[PairPoint; 4]>,
    /// Combined friction and restitution (SPEC.md §5.1).
    friction: f32,
    restitution: f32,
    /// Time of impact within the step, s: the earliest moment a closing point closes its
    /// gap (0 for points already penetrating); `None` if no point closes within the step.
    toi: Option<f32>,
}

/// The part of a body's state a pair solve reads.
#[derive(Clone, Copy, Debug)]
struct Side {
    id: u64,
    inv_mass: f32,
    inv_inertia: Matrix3<f32>,
    v: Vec3,
    w: Vec3,
}

impl Side {
    fn of(b: &Body) -> Side {
        Side {
            id: b.id(),
            inv_mass: b.inv_mass(),
            inv_inertia: b.world_inv_inertia(&b.rotation),
            v: b.linvel,
            w: b.angvel,
        }
    }

    /// One of `count` equal sub-bodies of this body: the same velocities, `count` times the
    /// inverse mass and inverse inertia.
    fn split(&self, count: u32) -> Side {
        let c = count.max(1) as f32;
        Side {
            inv_mass: self.inv_mass * c,
            inv_inertia: self.inv_inertia * c,
            ..*self
        }
    }

    /// Generalised inverse mass for a unit impulse along `d` at offset `r`.
    fn inv_mass_at(&self, r: &Vec3, d: &Vec3) -> f32 {
        let rd = r.cross(d);
        self.inv_mass + rd.dot(&(self.inv_inertia * rd))
    }
}

/// Offset from a body's centre to its contact point: through the centre along the normal for
/// a ball (its surface normal always points at the centre, whatever its orientation), the
/// manifold's body-frame point rotated to the world otherwise.
pub(crate) fn contact_offset(shape: &Shape, rot: &Quat, local: &Vec3, outward: &Vec3) -> Vec3 {
    match *shape {
        Shape::Ball { radius } => outward * radius,
        Shape::Cuboid { .. } => rot * local,
    }
}

/// Relative normal velocity of `b`'s point over `a`'s.
fn normal_speed(n: &Vec3, p: &PairPoint, va: &Vec3, wa: &Vec3, vb: &Vec3, wb: &Vec3) -> f32 {
    n.dot(&(vb + wb.cross(&p.rb) - va - wa.cross(&p.ra)))
}

/// The compression impulses of a pair's closing points, solved together
/// ([`lcp::contact_impulses`]): per point of `points`, 0 where not closing. `None` if more
/// than eight points close or the exact solve fails (the sweeps' impulses stand).
fn exact_compression(
    a: &Side,
    b: &Side,
    n: &Vec3,
    points: &[PairPoint],
    closing: &[bool],
    rows: &[(Vec3, Vec3, f32)],
) -> Option<SmallVec<[f32; lcp::MAX_POINTS]>> {
    let at: SmallVec<[usize; 8]> = (0..points.len()).filter(|&k| closing[k]).collect();
    let coupling = |i: usize, j: usize| {
        let (ia, ib, _) = rows[j];
        f64::from(a.inv_mass)
            + f64::from(b.inv_mass)
            + points[i].ra.cross(n).cast::<f64>().dot(&ia.cast::<f64>())
            + points[i].rb.cross(n).cast::<f64>().dot(&ib.cast::<f64>())
    };
    let speed = |i: usize| f64::from(points[i].speed);
    lcp::impulses_at(&at, points.len(), coupling, speed, |_| 0.0)
}

/// For two balls that are apart at step `t` and approach each other: the line of centres at
/// the moment they touch, the earliest `τ ≥ 0` with `|Δx + Δv·τ| = r_a + r_b` (a quadratic,
/// solved in f64 in the form that does not cancel), or, if they pass each other, at their
/// closest approach (`τ = −Δx·Δv / |Δv|²`, across the relative motion: not closing). Along
/// it, the gap closes at the speed that brings the balls together exactly at `τ`. The
/// manifold's normal is the line of centres of the step's start, a speculative contact up to
/// a step's travel away: along it an oblique impact sent a struck ball off at −28.6° instead
/// of −30°, and its gap closed within the step where the balls did not touch. `None` for any
/// other pair, or balls touching already or not approaching (the manifold's normal stands).
fn impact_normal(a: &Body, b: &Body) -> Option<Vec3> {
    let (Shape::Ball { radius: ra }, Shape::Ball { radius: rb }) = (a.shape(), b.shape()) else {
        return None;
    };
    let dx = (b.position - a.position).cast::<f64>();
    let dv = (b.linvel - a.linvel).cast::<f64>();
    let reach = f64::from(ra) + f64::from(rb);
    // |dx + dv·τ|² − reach² = qa·τ² + 2·qb·τ + qc.
    let (qa, qb, qc) = (
        dv.norm_squared(),
        dx.dot(&dv),
        dx.norm_squared() - reach * reach,
    );
    if qc <= 0.0 || qb >= 0.0 {
        return None;
    }
    let disc = qb * qb - qa * qc;
    let tau = if disc >= 0.0 {
        // The smaller root, −(qb + √disc)/qa, written as qc / (−qb + √disc): no cancellation.
        qc / (-qb + disc.sqrt())
    } else {
        -qb / qa
    };
    let at = dx + dv * tau;
    let len = at.norm();
    (len > 0.0).then(|| (at / len).cast::<f32>())
}

impl PairContact {
    /// The pair contact of `a` (lower id) and `b` from their manifold at step `t`, with
    /// combined `friction` and `restitution`, over a step of `dt` seconds. Two balls that
    /// approach along the manifold's normal faster than `rest_speed` (an impact) take the
    /// line of centres at the touch ([`impact_normal`]); a slower, resting approach keeps the
    /// manifold's normal.
    pub fn new(
        a: &Body,
        b: &Body,
        m: &PairManifold,
        friction: f32,
        restitution: f32,
        dt: f32,
        rest_speed: f32,
    ) -> PairContact {
        debug_assert!(a.id() < b.id());
        let approach = -m.normal_ab.dot(&(b.linvel - a.linvel));
        let n = if approach > rest_speed {
            impact_normal(a, b).unwrap_or(m.normal_ab)
        } else {
            m.normal_ab
        };
        let (sa, sb) = (Side::of(a), Side::of(b));
        let mut toi: Option<f32> = None;
        let points = m
            .local
            .iter()
            .map(|(la, lb)| {
                let ra = contact_offset(&a.shape(), &a.rotation, la, &n);
                let rb = contact_offset(&b.shape(), &b.rotation, lb, &-n);
                let gap = n.dot(&((b.position + rb) - (a.position + ra)));
                let mut p = PairPoint {
                    ra,
                    rb,
                    gap,
                    speed: 0.0,
                };
                p.speed = normal_speed(&n, &p, &sa.v, &sa.w, &sb.v, &sb.w);
                if p.speed < 0.0 && gap + p.speed * dt < 0.0 {
                    let t = (gap.max(0.0) / -p.speed).min(dt);
                    toi = Some(toi.map_or(t, |old: f32| old.min(t)));
                }
                p
            })
            .collect();
        PairContact {
            a: sa,
            b: sb,
            normal: n,
            points,
            friction,
            restitution,
            toi,
        }
    }

    /// If some point closes its gap within the step (the pair is *closing*, SPEC.md §5.3):
    /// its order key (time of impact, then the ids) and whether it is an *impact* (its
    /// fastest closing point approaches faster than `rest_speed`).
    pub fn edge(&self, rest_speed: f32) -> Option<Edge> {
        let toi = self.toi?;
        let fastest = self.points.iter().map(|p| -p.speed).fold(0.0f32, f32::max);
        Some(Edge {
            key: (toi, self.a.id, self.b.id),
            impact: fastest > rest_speed,
            fastest,
        })
    }

    /// The effect on body `id` (one of the pair) over a step of `dt` seconds. `counts`: the
    /// mass-splitting counts of `a` and `b` (each body is split into that many equal
    /// sub-bodies, one per closing pair, SPEC.md §5.3). `rest_speed`: approaches slower than
    /// this are plastic (restitution 0).
    pub fn effect(
        &self,
        id: u64,
        resolve: bool,
        counts: (u32, u32),
        dt: f32,
        rest_speed: f32,
    ) -> PairEffect {
        let n = self.normal;
        let resolved = resolve && self.toi.is_some();
        // The sub-bodies: the same velocities, mass and inertia divided by the count.
        let (a, b) = (&self.a.split(counts.0), &self.b.split(counts.1));
        let (mut va, mut wa, mut vb, mut wb) = (a.v, a.w, b.v, b.w);
        let mut impulse = Vec3::zeros();
        let mut ang_a = Vec3::zeros();
        let mut ang_b = Vec3::zeros();
        let toi = self.toi.unwrap_or(0.0);
        if resolved {
            let closing: SmallVec<[bool; 4]> = self
                .points
                .iter()
                .map(|p| p.speed < 0.0 && p.gap + p.speed * dt < 0.0)
                .collect();
            // Compression: sequential impulses until no closing point approaches (a plastic
            // collision, accumulated impulses kept ≥ 0).
            let rows: SmallVec<[(Vec3, Vec3, f32); 4]> = self
                .points
                .iter()
                .map(|p| {
                    let ia = a.inv_inertia * p.ra.cross(&n);
                    let ib = b.inv_inertia * p.rb.cross(&n);
                    (ia, ib, a.inv_mass_at(&p.ra, &n) + b.inv_mass_at(&p.rb, &n))
                })
                .collect();
            let mut acc: SmallVec<[f32; 4]> = SmallVec::from_elem(0.0, self.points.len());
            let push =
                |d: f32, k: usize, va: &mut Vec3, wa: &mut Vec3, vb: &mut Vec3, wb: &mut Vec3| {
                    let (ia, ib, _) = rows[k];
                    *vb += n * (d * b.inv_mass);
                    *wb += ib * d;
                    *va -= n * (d * a.inv_mass);
                    *wa -= ia * d;
                };
            let mut converged = false;
            for _ in 0..PAIR_ITERATIONS {
                let mut largest = 0.0f32;
                for (k, p) in self.points.iter().enumerate() {
                    if !closing[k] {
                        continue;
                    }
                    let u = normal_speed(&n, p, &va, &wa, &vb, &wb);
                    let next = (acc[k] - u / rows[k].2).max(0.0);
                    let d = next - acc[k];
                    if d != 0.0 {
                        push(d, k, &mut va, &mut wa, &mut vb, &mut wb);
                        acc[k] = next;
                        largest = largest.max(d.abs() * rows[k].2);
                    }
                }
                if largest < PAIR_TOLERANCE {
                    converged = true;
                    break;
                }
            }
            // Sweeps that did not converge leave a point pushing while it separates, which
            // restitution then doubles: solved exactly instead (SPEC.md §5.3).
            if !converged {
                if let Some(exact) = exact_compression(a, b, &n, &self.points, &closing, &rows) {
                    (va, wa, vb, wb) = (a.v, a.w, b.v, b.w);
                    for (k, l) in exact.iter().enumerate() {
                        acc[k] = *l;
                        if *l != 0.0 {
                            push(*l, k, &mut va, &mut wa, &mut vb, &mut wb);
                        }
                    }
                }
            }
            // Restitution (Poisson): each point's compression impulse again, times `e`, once
            // per contact. With restitution ≤ 1 this never adds energy (SPEC.md §5.3).
            let fastest = self
                .points
                .iter()
                .zip(&closing)
                .filter(|(_, &c)| c)
                .map(|(p, _)| -p.speed)
                .fold(0.0f32, f32::max);
            let e = if fastest > rest_speed {
                self.restitution
            } else {
                0.0
            };
            let mut total: SmallVec<[f32; 4]> = SmallVec::new();
            for k in 0..self.points.len() {
                let extra = e * acc[k];
                if extra != 0.0 {
                    push(extra, k, &mut va, &mut wa, &mut vb, &mut wb);
                }
                total.push(acc[k] + extra);
            }
            // Coulomb friction: per point, the tangential impulse that stops the slip, its
            // accumulated magnitude bounded by μ times the point's normal impulse.
            let mut tangential: SmallVec<[Vec3; 4]> =
                SmallVec::from_elem(Vec3::zeros(), self.points.len());
            for _ in 0..FRICTION_SWEEPS {
                for (k, p) in self.points.iter().enumerate() {
                    let bound = self.friction * total[k];
                    if bound <= 0.0 {
                        continue;
                    }
                    let rel = vb + wb.cross(&p.rb) - va - wa.cross(&p.ra);
                    let slip = rel - n * n.dot(&rel);
                    let len = slip.norm();
                    if len <= SLIP_EPSILON {
                        continue;
                    }
                    let t = slip / len;
                    let w = a.inv_mass_at(&p.ra, &t) + b.inv_mass_at(&p.rb, &t);
                    let mut next = tangential[k] - t * (len / w);
                    let m = next.norm();
                    if m > bound {
                        next *= bound / m;
                    }
                    let d = next - tangential[k];
                    tangential[k] = next;
                    vb += d * b.inv_mass;
                    wb += b.inv_inertia * p.rb.cross(&d);
                    va -= d * a.inv_mass;
                    wa -= a.inv_inertia * p.ra.cross(&d);
                }
            }
            for (k, p) in self.points.iter().enumerate() {
                let j = n * total[k] + tangential[k];
                impulse += j;
                ang_b += p.rb.cross(&j);
                ang_a -= p.ra.cross(&j);
            }
        }
        // The velocity changes of the whole bodies: a sub-body's change averaged over its
        // body's sub-bodies, i.e. the impulse over the whole body's mass (from the accumulated
        // impulses, so that `a`'s linear impulse is exactly the negation of `b`'s).
        let (a, b) = (&self.a, &self.b);
        let (dva, dwa) = (-impulse * a.inv_mass, a.inv_inertia * ang_a);
        let (dvb, dwb) = (impulse * b.inv_mass, b.inv_inertia * ang_b);
        // The overlap left at the end of the step if the pair moved alone: with the collision
        // at its time of impact (before it at step-`t` velocities, after it at the new ones),
        // otherwise at step-`t` velocities. It is projected away by moving the two centres
        // apart along the normal, in proportion to their inverse masses: the centre of mass
        // does not move and no velocity changes.
        let mut depth = 0.0f32;
        for p in &self.points {
            let after = if resolved {
                let u1 = normal_speed(
                    &n,
                    p,
                    &(a.v + dva),
                    &(a.w + dwa),
                    &(b.v + dvb),
                    &(b.w + dwb),
                );
                p.gap + p.speed * toi + u1 * (dt - toi)
            } else {
                p.gap + p.speed * dt
            };
            depth = depth.max(-after);
        }
        // Body `x` moves `d·w_x / (w_a + w_b)`: the whole overlap, unsplit (positions only;
        // splitting it too left a ball pile under gravity sinking 0.17 m into itself).
        let share = |inv: f32| depth * (inv / (a.inv_mass + b.inv_mass));
        if id == a.id {
            PairEffect {
                dv: dva,
                dw: dwa,
                dx: -dva * toi - n * share(a.inv_mass),
                dtheta: -dwa * toi,
            }
        } else {
            debug_assert_eq!(id, b.id);
            PairEffect {
                dv: dvb,
                dw: dwb,
                dx: -dvb * toi + n * share(b.inv_mass),
                dtheta: -dwb * toi,
            }
        }
    }
}
