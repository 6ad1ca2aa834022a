//! Contact generation at step-`t` poses. A pair's manifold is computed with the lower id as
//! the first shape, so both bodies of a pair see the same geometry whichever cell computes it.

use super::body::{Body, Shape};
use super::environment::Environment;
use crate::math::Vec3;
use crate::model::BodyId;
use parry3d::query::{ContactManifold, DefaultQueryDispatcher, PersistentQueryDispatcher};
use smallvec::SmallVec;

/// One contact point as seen by the body being solved (`i`), fixed for the whole step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactPoint {
    /// The point on body `i`, in `i`'s own frame.
    pub anchor: Vec3,
    /// The partner's surface point at step `t`, world frame.
    pub partner_point: Vec3,
    /// The velocity of the partner's point at step `t` (zero for static surfaces); for a load
    /// system's support, its velocity at the end of the joint solve (SPEC.md §5.2).
    pub partner_velocity: Vec3,
    /// Unit normal from the partner towards `i`, world frame.
    pub normal: Vec3,
    /// The partner's generalised inverse mass along `normal` at the point (0 if static).
    pub partner_inv_mass: f32,
}

/// The contact points between body `i` and one partner.
#[derive(Clone, Debug, PartialEq)]
pub struct ContactSet {
    /// The partner body, or `None` for the static environment.
    pub partner: Option<BodyId>,
    /// Combined friction coefficient.
    pub friction: f32,
    /// Combined restitution.
    pub restitution: f32,
    /// The points.
    pub points: SmallVec<[ContactPoint; 4]>,
    /// How `i`'s solve treats the partner (SPEC.md §5.2, §5.3).
    pub role: SetRole,
}

/// How body `i`'s own solve treats a contact set's partner (SPEC.md §5.2, §5.3).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SetRole {
    /// `i` does the whole job against the partner's step-`t` motion: the static environment,
    /// and a body `i` rests on (a support, whose inverse mass counts as 0).
    #[default]
    Whole,
    /// A pile contact: the partner is a movable body resting against `i` in a supported pile.
    /// Each of the two bodies removes its share of the approach and of the overlap (by the
    /// two inverse masses and its mobility against its supports, SPEC.md §5.3); its position
    /// correction is added whole rather than averaged with the other partners'.
    Pile,
    /// The partner rests on `i` (a support whose lower body is `i`). Its weight is not `i`'s
    /// to carry (shock propagation), but `i` must not push into it for free: `i`'s whole own
    /// approach is stopped (the partner counts as immovable, as its weight would hold `i`),
    /// with no position correction, friction or bounce. The partner's velocity counts only
    /// when it moves away from `i`.
    Carried,
    /// The partner of a symmetric pair (SPEC.md §5.3) that rests on a support chain. The
    /// pair's response took their collision from step-`t` velocities before `i`'s solve; what
    /// `i` gains towards `j` within its own solve (gravity, its supports, friction) the
    /// partner cannot see, and it is `i`'s to stop: `i` may not approach `j` faster than `j`
    /// moves after the pair's response (`j` immovable, inverse mass 0), with no position
    /// correction (the pair corrects the overlap), friction or bounce (both the pair's).
    Paired,
    /// A support in a load system (SPEC.md §5.2, "Load"): immovable, with position
    /// correction, friction and bounce, as [`SetRole::Whole`]; but its points move as the
    /// joint solve of the load moves the support, and `i` follows them through the whole step
    /// with the closing allowance of a movable partner (relative to the partner's motion),
    /// not only through its first substep.
    Loaded,
}

impl SetRole {
    /// Whether `i`'s solve only stops its approach to the partner: no position correction,
    /// friction or bounce ([`SetRole::Carried`], [`SetRole::Paired`]).
    pub fn stops_approach_only(self) -> bool {
        matches!(self, SetRole::Carried | SetRole::Paired)
    }
}

/// A pair manifold between bodies `a` (lower id) and `b`, in world frame.
#[derive(Clone, Debug)]
pub(crate) struct PairManifold {
    /// (point on a, point on b) in each body's frame.
    pub local: SmallVec<[(Vec3, Vec3); 4]>,
    /// Unit normal from `a` towards `b`.
    pub normal_ab: Vec3,
}

/// Generalised inverse mass of `body` for a unit impulse along `n` at world offset `r`.
pub(crate) fn inv_mass_at(body: &Body, rot: &crate::math::Quat, r: &Vec3, n: &Vec3) -> f32 {
    let rn = r.cross(n);
    body.inv_mass() + rn.dot(&body.world_inv_inertia_times(rot, &rn))
}

/// How far apart (surface to surface) a body may be from a partner at step `t` and still
/// reach it during the step: the margin plus the largest closing motion the step-`t`
/// velocities allow (relative linear speed, the spin of each surface, one step of gravity and
/// the separation-speed allowance), never more than `cap`.
pub(crate) fn speculative_distance(
    a: &Body,
    b: Option<&Body>,
    dt: f32,
    g: f32,
    margin: f32,
    cap: f32,
) -> f32 {
    let (vb, spin_b) = match b {
        Some(b) => (b.linvel, b.angvel.norm() * b.bounding_radius()),
        None => (Vec3::zeros(), 0.0),
    };
    let closing = (a.linvel - vb).norm() + a.angvel.norm() * a.bounding_radius() + spin_b + g * dt;
    (margin + closing * dt).min(cap)
}

/// Fraction of the summed bounding radii by which a touching pair's points are kept beyond
/// its speculative distance: faces tilted by up to about 0.1 rad against each other keep all
/// their corners (SPEC.md §5.2).
pub const FACE_DEPTH_FRACTION: f32 = 0.1;

/// How far a touching pair's contact points are kept: the speculative distance `reach` plus
/// [`FACE_DEPTH_FRACTION`] of the radii `ra + rb`, never more than `cap`.
pub(crate) fn keep_distance(reach: f32, ra: f32, rb: f32, cap: f32) -> f32 {
    (reach + FACE_DEPTH_FRACTION * (ra + rb))
        .min(cap)
        .max(reach)
}

/// Whether two bodies' bounding spheres are within `distance` of each other.
pub(crate) fn near(a: &Body, b: &Body, distance: f32) -> bool {
    let reach = a.bounding_radius() + b.bounding_radius() + distance;
    (a.position - b.position).norm_squared() <= reach * reach
}

/// The manifold of `a` (lower id) and `b` at their step-`t` poses, or `None` if no point
/// lies within `reach`. When some point does, every point within `keep` (≥ `reach`) is
/// kept, so a tilted face lands on all its corners, not only on those already within reach.
pub(crate) fn pair_manifold(a: &Body, b: &Body, reach: f32, keep: f32) -> Option<PairManifold> {
    debug_assert!(a.id() < b.id());
    let (pa, pb) = (a.pose(), b.pose());
    let pos12 = pa.inv_mul(&pb);
    let (sa, sb) = (a.shape().parry(), b.shape().parry());
    let mut m: ContactManifold<(), ()> = ContactManifold::new();
    let keep = keep.max(reach);
    DefaultQueryDispatcher
        .contact_manifold_convex_convex(&pos12, sa.as_dyn(), sb.as_dyn(), None, None, keep, &mut m)
        .ok()?;
    if !m.points.iter().any(|p| p.dist <= reach) {
        return None;
    }
    let normal_ab = pa.rotation * m.local_n1;
    let local = m
        .points
        .iter()
        .filter(|p| p.dist <= keep)
        .map(|p| (p.local_p1.coords, p.local_p2.coords))
        .collect::<SmallVec<_>>();
    Some(PairManifold { local, normal_ab })
}

/// Body `i`'s view of a pair manifold with partner `j`.
pub(crate) fn view(i: &Body, j: &Body, m: &PairManifold) -> ContactSet {
    let i_is_a = i.id() < j.id();
    let normal = if i_is_a { -m.normal_ab } else { m.normal_ab };
    let points = m
        .local
        .iter()
        .map(|&(la, lb)| {
            let (li, lj) = if i_is_a { (la, lb) } else { (lb, la) };
            let rj = j.rotation * lj;
            ContactPoint {
                anchor: li,
                partner_point: j.position + rj,
                partner_velocity: j.linvel,
                normal,
                partner_inv_mass: inv_mass_at(j, &j.rotation, &rj, &normal),
            }
        })
        .collect();
    ContactSet {
        partner: Some(j.id()),
        friction: 0.5 * (i.friction() + j.friction()),
        restitution: 0.5 * (i.restitution() + j.restitution()),
        points,
        role: SetRole::Whole,
    }
}

/// Contacts of body `i` with the static environment, as one set: for each surface with a
/// point within `reach`, every point within `keep` (≥ `reach`; see [`pair_manifold`]).
pub(crate) fn environment_contacts(
    i: &Body,
    env: &Environment,
    reach: f32,
    keep: f32,
) -> Option<ContactSet> {
    let keep = keep.max(reach);
    let mut points: SmallVec<[ContactPoint; 4]> = SmallVec::new();
    let statik = |anchor: Vec3, partner_point: Vec3, normal: Vec3| ContactPoint {
        anchor,
        partner_point,
        partner_velocity: Vec3::zeros(),
        normal,
        partner_inv_mass: 0.0,
    };
    let radius = i.bounding_radius();
    for plane in &env.planes {
        let centre_gap = plane.normal.dot(&i.position) - plane.offset;
        if centre_gap > radius + reach {
            continue;
        }
        match i.shape() {
            Shape::Ball { radius } => {
                let gap = centre_gap - radius;
                if gap <= reach {
                    let world = -plane.normal * radius;
                    let anchor = i.rotation.inverse_transform_vector(&world);
                    let contact = i.position + world - plane.normal * gap;
                    points.push(statik(anchor, contact, plane.normal));
                }
            }
            Shape::Cuboid { .. } => {
                let mut near_plane: SmallVec<[(Vec3, Vec3, f32); 8]> = SmallVec::new();
                for v in i.shape().vertices() {
                    let w = i.position + i.rotation * v;
                    let gap = plane.normal.dot(&w) - plane.offset;
                    if gap <= keep {
                        near_plane.push((v, w, gap));
                    }
                }
                if near_plane.iter().any(|&(_, _, gap)| gap <= reach) {
                    for (v, w, gap) in near_plane {
                        points.push(statik(v, w - plane.normal * gap, plane.normal));
                    }
                }
            }
        }
    }
    for c in &env.cuboids {
        let reach_centres = radius + c.half_extents.norm() + reach;
        if (c.pose.translation.vector - i.position).norm_squared() > reach_centres * reach_centres {
            continue;
        }
        let pi = i.pose();
        let pos12 = pi.inv_mul(&c.pose);
        let si = i.shape().parry();
        let sc = parry3d::shape::Cuboid::new(c.half_extents);
        let mut m: ContactManifold<(), ()> = ContactManifold::new();
        if DefaultQueryDispatcher
            .contact_manifold_convex_convex(&pos12, si.as_dyn(), &sc, None, None, keep, &mut m)
            .is_err()
            || !m.points.iter().any(|p| p.dist <= reach)
        {
            continue;
        }
        let normal = -(pi.rotation * m.local_n1);
        for p in m.points.iter().filter(|p| p.dist <= keep) {
            points.push(statik(
                p.local_p1.coords,
                (c.pose * p.local_p2).coords,
                normal,
            ));
        }
    }
    (!points.is_empty()).then(|| ContactSet {
        partner: None,
        friction: 0.5 * (env.friction + i.friction()),
        restitution: 0.5 * (env.restitution + i.restitution()),
        points,
        role: SetRole::Whole,
    })
}
