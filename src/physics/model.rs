//! [`RigidBodyModel`]: the rigid-body implementation of [`CellModel`].

use super::body::Body;
use super::contact::{
    environment_contacts, near, pair_manifold, speculative_distance, view, ContactSet, PairManifold,
};
use super::environment::Environment;
use super::params::SolverParams;
use super::solver::solve_body;
use crate::frame::{Event, EventKind};
use crate::grid::Grid;
use crate::hash::StateHash;
use crate::math::Vec3;
use crate::model::{BodyId, CellModel, Neighbourhood, Step};

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
    fn contact_sets(
        &self,
        own: &Body,
        partners: &[&Body],
        cache: &mut Vec<(BodyId, BodyId, Option<PairManifold>)>,
    ) -> Vec<ContactSet> {
        let cap = self.prediction();
        let (g, margin) = (self.gravity.norm(), self.params.margin);
        let mut sets = Vec::new();
        let up = if g > 0.0 {
            -self.gravity / g
        } else {
            Vec3::zeros()
        };
        for &j in partners {
            if j.id == own.id || !near(own, j, cap) {
                continue;
            }
            let (a, b) = if own.id < j.id { (own, j) } else { (j, own) };
            let reach = speculative_distance(a, Some(b), self.dt, g, margin, cap);
            if !near(a, b, reach) {
                continue;
            }
            let m = match cache.binary_search_by_key(&(a.id, b.id), |e| (e.0, e.1)) {
                Ok(pos) => cache[pos].2.clone(),
                Err(pos) => {
                    let m = pair_manifold(a, b, reach);
                    cache.insert(pos, (a.id, b.id, m.clone()));
                    m
                }
            };
            if let Some(m) = m {
                let mut set = view(own, j, &m);
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
        let reach = speculative_distance(own, None, self.dt, g, margin, cap);
        if let Some(env) = environment_contacts(own, &self.environment, reach) {
            sets.push(env);
        }
        sets
    }

    /// Applies the speed, displacement and spin caps, raising `SpeedCapped` if any bit.
    fn cap(&self, before: &Body, after: &mut Body, step: Step, events: &mut Vec<Event>) {
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

impl CellModel for RigidBodyModel {
    type State = Body;

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
        events: &mut Vec<Event>,
    ) {
        let mut partners: Vec<&Body> = nb.iter().collect();
        partners.sort_by_key(|b| b.id);
        let mut cache = Vec::new();
        for own in nb.own() {
            let sets = self.contact_sets(own, &partners, &mut cache);
            let mut next = solve_body(own, &sets, self.gravity, self.dt, &self.params);
            self.cap(own, &mut next, step, events);
            out.push(next);
        }
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
        out
    }
}
