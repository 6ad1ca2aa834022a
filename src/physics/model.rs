//! [`RigidBodyModel`]: the rigid-body implementation of [`CellModel`].

use super::body::{Body, Shape};
use super::contact::{
    environment_contacts, keep_distance, near, pair_manifold, speculative_distance, view,
    ContactSet, PairManifold,
};
use super::environment::Environment;
use super::event::EventKind;
use super::params::SolverParams;
use super::solver::solve_body;
use crate::frame::Event;
use crate::grid::Grid;
use crate::hash::StateHash;
use crate::math::Vec3;
use crate::model::{BodyId, CellModel, Neighbourhood, Step};
use std::cell::OnceCell;

/// Cosine of the largest angle between a contact normal and the vertical for which the
/// contact counts as support (shock propagation, SPEC.md §Physics): 45°.
pub const SUPPORT_COSINE: f32 = std::f32::consts::FRAC_1_SQRT_2;

/// The rigid-body cell model: static data shared by every cell computation.
#[derive(Clone, Debug, PartialEq)]
pub struct RigidBodyModel {
    /// Seconds per step.
    pub dt: f32,
    /// Gravity, m/s².
    pub gravity: Vec3,
    /// Solver parameters.
    pub params: SolverParams,
    /// The static environment.
    pub environment: Environment,
}

impl RigidBodyModel {
    /// Largest displacement of a body's centre in one step (the speed cap times `dt`).
    pub fn max_displacement(&self) -> f32 {
        self.params.max_speed * self.dt
    }

    /// Distance at which contact points are generated at step `t`: the margin plus the
    /// largest closing motion of two bodies in one step.
    pub fn prediction(&self) -> f32 {
        self.params.margin + 2.0 * self.max_displacement()
    }

    /// The cell edge that makes the locality contract hold for bodies of bounding radius up
    /// to `max_radius`: largest extent + margin + twice the displacement allowance.
    pub fn required_cell_edge(&self, max_radius: f32) -> f32 {
        2.0 * max_radius + self.prediction()
    }

    /// Contact sets of body `own` against the neighbourhood and the environment, in
    /// ascending partner id then static.
    ///
    /// Also returns whether every body partner with contact points (those ignored by shock
    /// propagation included) was quiet at step `t` (sleeping, SPEC.md §5.4).
    fn contact_sets(
        &self,
        own: &Candidate<'_>,
        candidates: &[Candidate<'_>],
        cache: &mut Vec<(BodyId, BodyId, Option<PairManifold>)>,
    ) -> (Vec<ContactSet>, bool) {
        let mut partners_quiet = true;
        let cap = self.prediction();
        let (g, margin) = (self.gravity.norm(), self.params.margin);
        let slack = self.filter_slack();
        let mut sets = Vec::new();
        let up = if g > 0.0 {
            -self.gravity / g
        } else {
            Vec3::zeros()
        };
        for c in candidates {
            if c.body.id == own.body.id
                || !own.may_touch(c, slack)
                || !own.boxes_within(c, own.motion + c.motion + slack)
            {
                continue;
            }
            let j = c.body;
            let (a, b) = if own.body.id < j.id {
                (own.body, j)
            } else {
                (j, own.body)
            };
            let reach = speculative_distance(a, Some(b), self.dt, g, margin, cap);
            if !near(a, b, reach) || !own.boxes_within(c, reach + slack) {
                continue;
            }
            let m = match cache.binary_search_by_key(&(a.id, b.id), |e| (e.0, e.1)) {
                Ok(pos) => cache[pos].2.clone(),
                Err(pos) => {
                    let keep = keep_distance(
                        reach,
                        a.shape.bounding_radius(),
                        b.shape.bounding_radius(),
                        cap,
                    );
                    let m = pair_manifold(a, b, reach, keep);
                    cache.insert(pos, (a.id, b.id, m.clone()));
                    m
                }
            };
            if let Some(m) = m {
                partners_quiet &= j.is_quiet(self.params.sleep_speed);
                let mut set = view(own.body, j, &m);
                // Shock propagation: a partner resting on `own` (normal pointing down
                // towards `own`) is ignored; a partner `own` rests on is treated as immovable.
                let up = set.points[0].normal.dot(&up);
                if up < -SUPPORT_COSINE {
                    continue;
                }
                if up > SUPPORT_COSINE {
                    for p in &mut set.points {
                        p.partner_inv_mass = 0.0;
                    }
                }
                sets.push(set);
            }
        }
        sets.sort_unstable_by_key(|s| s.partner);
        let reach = speculative_distance(own.body, None, self.dt, g, margin, cap);
        let radius = own.body.shape.bounding_radius();
        if let Some(env) = environment_contacts(
            own.body,
            &self.environment,
            reach,
            keep_distance(reach, radius, radius, cap),
        ) {
            sets.push(env);
        }
        (sets, partners_quiet)
    }

    /// Slack added to the broad-phase filters so that they stay supersets of the exact
    /// speculative-distance test whatever the rounding (1 mm plus one step of gravity).
    fn filter_slack(&self) -> f32 {
        1e-3 + self.params.margin + self.gravity.norm() * self.dt * self.dt
    }

    /// Whether sleeping is on (`sleep_steps > 0`).
    fn sleeping(&self) -> bool {
        self.params.sleep_steps > 0
    }

    /// Whether `b` is asleep at step `t` (its rest counter reached `sleep_steps`).
    pub fn is_asleep(&self, b: &Body) -> bool {
        self.sleeping() && b.rest_steps >= self.params.sleep_steps
    }

    /// Whether bodies `i` and `k` can interact during this step (bounding spheres within the
    /// pair's speculative distance, SPEC.md §5.2): the test for contacts and for waking.
    fn can_reach(&self, i: &Body, k: &Body) -> bool {
        let (a, b) = if i.id < k.id { (i, k) } else { (k, i) };
        let cap = self.prediction();
        let reach = speculative_distance(
            a,
            Some(b),
            self.dt,
            self.gravity.norm(),
            self.params.margin,
            cap,
        );
        near(a, b, reach)
    }

    /// Applies the speed, displacement and spin caps, raising `SpeedCapped` if any bit.
    fn cap(&self, before: &Body, after: &mut Body, step: Step, events: &mut Vec<Event<EventKind>>) {
        let mut capped = false;
        let max_disp = self.max_displacement();
        let d = after.position - before.position;
        if d.norm() > max_disp {
            after.position = before.position + d * (max_disp / d.norm());
            capped = true;
        }
        if after.linvel.norm() > self.params.max_speed {
            after.linvel *= self.params.max_speed / after.linvel.norm();
            capped = true;
        }
        if after.angvel.norm() > self.params.max_angular_speed {
            after.angvel *= self.params.max_angular_speed / after.angvel.norm();
            capped = true;
        }
        if capped {
            events.push(Event {
                step,
                body: after.id,
                kind: EventKind::SpeedCapped,
            });
        }
    }
}

/// A body as a broad-phase candidate: its bounding sphere grown by how far its surface can
/// move in one step.
struct Candidate<'a> {
    body: &'a Body,
    /// `dt·(|v| + |ω|·r)` (the farthest any surface point moves in the step), at most the
    /// prediction.
    motion: f32,
    /// Bounding radius plus `motion`.
    sweep: f32,
    /// Half extents of the world axis-aligned box around the shape, computed on first use.
    half_box: OnceCell<Vec3>,
}

impl<'a> Candidate<'a> {
    fn new(body: &'a Body, dt: f32, prediction: f32) -> Candidate<'a> {
        let r = body.shape.bounding_radius();
        let motion = dt * (body.linvel.norm() + body.angvel.norm() * r);
        let motion = motion.min(prediction);
        Candidate {
            body,
            motion,
            sweep: r + motion,
            half_box: OnceCell::new(),
        }
    }

    /// Half extents of the world axis-aligned box around the shape.
    fn half_box(&self) -> Vec3 {
        *self.half_box.get_or_init(|| match self.body.shape {
            Shape::Ball { radius } => Vec3::repeat(radius),
            Shape::Cuboid { half_extents } => {
                let m = self.body.rotation.to_rotation_matrix().into_inner().abs();
                m * Vec3::from(half_extents)
            }
        })
    }

    /// Whether the two swept spheres (plus `slack`) overlap: a superset of the pairs whose
    /// bounding spheres lie within their speculative distance (SPEC.md §5.2).
    fn may_touch(&self, other: &Candidate<'_>, slack: f32) -> bool {
        let reach = self.sweep + other.sweep + slack;
        (self.body.position - other.body.position).norm_squared() <= reach * reach
    }

    /// Whether the world boxes, grown by `distance`, overlap (a pair farther apart than
    /// `distance` has no contact point within it).
    fn boxes_within(&self, other: &Candidate<'_>, distance: f32) -> bool {
        let d = (self.body.position - other.body.position).abs();
        let limit = self.half_box() + other.half_box();
        (0..3).all(|k| d[k] <= limit[k] + distance)
    }
}

/// A sleeping body's next state: the same pose and rest counter, zero velocities.
fn frozen(b: &Body) -> Body {
    let mut next = b.clone();
    next.linvel = Vec3::zeros();
    next.angvel = Vec3::zeros();
    next
}

impl CellModel for RigidBodyModel {
    type State = Body;
    type Event = EventKind;

    fn id(state: &Body) -> BodyId {
        state.id
    }

    fn position(state: &Body) -> [f32; 3] {
        state.position.into()
    }

    fn step_cell(
        &self,
        step: Step,
        _grid: &Grid,
        nb: &Neighbourhood<'_, Body>,
        out: &mut Vec<Body>,
        events: &mut Vec<Event<EventKind>>,
    ) {
        // Sleeping (SPEC.md §5.4): a sleeping body that no awake body can reach keeps its
        // pose and has zero velocity; if the whole neighbourhood sleeps, nothing else is done.
        if nb.iter().all(|b| self.is_asleep(b)) {
            out.extend(nb.own().iter().map(frozen));
            return;
        }
        let mut candidates: Vec<Candidate<'_>> = Vec::new();
        let mut cache = Vec::new();
        for own in nb.own() {
            if self.is_asleep(own)
                && !nb
                    .iter()
                    .any(|k| !self.is_asleep(k) && self.can_reach(own, k))
            {
                out.push(frozen(own));
                continue;
            }
            if candidates.is_empty() {
                // Only bodies whose swept sphere can reach the box around the centre cell's
                // swept bodies; slot order (the sets are put in ascending partner id later).
                let (lo, hi, own_sweep) = nb.own().iter().fold(
                    (Vec3::repeat(f32::MAX), Vec3::repeat(f32::MIN), 0.0f32),
                    |(lo, hi, w), b| {
                        let c = Candidate::new(b, self.dt, self.prediction());
                        (lo.inf(&b.position), hi.sup(&b.position), w.max(c.sweep))
                    },
                );
                let grow = own_sweep + self.filter_slack();
                // Sized for the whole neighbourhood up front: a filtered collect grows by
                // reallocation (4, 8, 16, ... candidates), a measurable share of a step.
                candidates.reserve_exact(nb.cells.iter().map(|c| c.len()).sum());
                candidates.extend(
                    nb.iter()
                        .map(|b| Candidate::new(b, self.dt, self.prediction()))
                        .filter(|c| {
                            let p = c.body.position;
                            (0..3).all(|k| {
                                p[k] >= lo[k] - grow - c.sweep && p[k] <= hi[k] + grow + c.sweep
                            })
                        }),
                );
            }
            let me = Candidate::new(own, self.dt, self.prediction());
            let (sets, partners_quiet) = self.contact_sets(&me, &candidates, &mut cache);
            let mut next = solve_body(own, &sets, self.gravity, self.dt, &self.params);
            self.cap(own, &mut next, step, events);
            let quiet = |b: &Body| b.is_quiet(self.params.sleep_speed);
            next.rest_steps = if self.sleeping() && partners_quiet && quiet(own) && quiet(&next) {
                (own.rest_steps + 1).min(self.params.sleep_steps)
            } else {
                0
            };
            out.push(next);
        }
    }

    /// A body's step reads a neighbour only through `can_reach` (contacts and waking); an
    /// all-asleep neighbourhood freezes exactly the bodies no awake body reaches.
    fn may_affect(&self, reader: &Body, other: &Body) -> bool {
        self.can_reach(reader, other)
    }

    fn hash_state(b: &Body, h: &mut StateHash) {
        for v in [&b.position, &b.linvel, &b.angvel] {
            for k in 0..3 {
                h.f32(v[k]);
            }
        }
        let q = b.rotation.quaternion();
        for c in [q.w, q.i, q.j, q.k] {
            h.f32(c);
        }
        h.u32(b.rest_steps);
    }

    /// Bit equality of every field (a `Body` compares equal exactly when its fields do, and
    /// every hashed field is an `f32`/`u32` compared here by its bits).
    fn same_bits(a: &Body, b: &Body) -> bool {
        let bits = |v: &Vec3| [v.x.to_bits(), v.y.to_bits(), v.z.to_bits()];
        let quat = |b: &Body| {
            let q = b.rotation.quaternion();
            [q.w.to_bits(), q.i.to_bits(), q.j.to_bits(), q.k.to_bits()]
        };
        a.id == b.id
            && a.rest_steps == b.rest_steps
            && bits(&a.position) == bits(&b.position)
            && bits(&a.linvel) == bits(&b.linvel)
            && bits(&a.angvel) == bits(&b.angvel)
            && quat(a) == quat(b)
            && a.inv_mass.to_bits() == b.inv_mass.to_bits()
            && bits(&a.inv_inertia) == bits(&b.inv_inertia)
            && a.friction.to_bits() == b.friction.to_bits()
            && a.restitution.to_bits() == b.restitution.to_bits()
            && a.shape == b.shape
    }

    fn event_name(kind: &EventKind) -> String {
        kind.name().to_string()
    }

    fn fields(b: &Body) -> Vec<(String, String)> {
        let q = b.rotation.quaternion();
        let named = [
            (
                "position",
                [b.position.x, b.position.y, b.position.z].to_vec(),
            ),
            ("linvel", [b.linvel.x, b.linvel.y, b.linvel.z].to_vec()),
            ("angvel", [b.angvel.x, b.angvel.y, b.angvel.z].to_vec()),
            ("rotation", [q.w, q.i, q.j, q.k].to_vec()),
        ];
        let mut out = Vec::new();
        for (name, values) in named {
            let axes: &[&str] = if values.len() == 4 {
                &["w", "x", "y", "z"]
            } else {
                &["x", "y", "z"]
            };
            for (axis, v) in axes.iter().zip(values) {
                out.push((format!("{name}.{axis}"), crate::model::exact_f32(v)));
            }
        }
        out.push(("rest_steps".to_string(), b.rest_steps.to_string()));
        out
    }
}
