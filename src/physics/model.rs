//! [`RigidBodyModel`]: the rigid-body implementation of [`CellModel`].

use super::body::{Body, Shape, LEAVING};
use super::contact::{
    environment_contacts, inv_mass_at, keep_distance, near, pair_manifold, speculative_distance,
    view, ContactSet, PairManifold, SetRole,
};
use super::environment::{DomainBox, Environment};
use super::event::EventKind;
use super::load;
use super::pair::{Edge, PairContact, PairEffect};
use super::params::SolverParams;
use super::rotation::integrate_rotation;
use super::solver::{approaches, solve_body, SolveRows};
use crate::frame::Event;
use crate::grid::Grid;
use crate::hash::StateHash;
use crate::math::Vec3;
use crate::model::{BodyId, CellModel, Hint, Neighbourhood, Step};
use std::cell::OnceCell;

/// Cosine of the largest angle between a contact normal and the vertical for which the
/// contact counts as support (shock propagation, SPEC.md §5.2): 75°. A ball in a pile rests
/// in grooves whose contacts lie up to ~70° from the vertical; with 45° most of them were
/// symmetric pairs solved by one Jacobi pass per step and the pile sank into itself. Side
/// contacts of boxes tilted by less than 15° stay symmetric.
pub const SUPPORT_COSINE: f32 = 0.258_819_04; // cos 75°

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
    /// The declared domain: a body whose centre leaves it after a step is removed, with a
    /// `LeftDomain` event (SPEC.md §3).
    pub domain: DomainBox,
    /// Largest bounding radius of any body (the pair matching reads two contacts deep and a
    /// load system three,
    /// [`CellModel::may_affect`]).
    pub max_radius: f32,
}

/// A body partner whose contact is solved as a symmetric pair (SPEC.md §5.3).
struct PairEntry<'a> {
    /// The partner.
    partner: &'a Body,
    /// The partner's cell relative to the centre cell.
    offset: [i32; 3],
    /// The pair at step `t`, in canonical order.
    contact: PairContact,
    /// Their manifold (canonical order), for the [`SetRole::Paired`] set.
    manifold: PairManifold,
}

/// What one body touches at step `t`.
struct Contacts<'a> {
    /// Contact sets of the per-body solve, ascending partner id, the environment last: the
    /// bodies it rests on and pile contacts (SPEC.md §5.2, §5.3).
    sets: Vec<ContactSet>,
    /// Awake bodies resting on this one, with their manifolds, ascending id: each becomes a
    /// carried set if the body approaches it at the start or at the end of its solve
    /// (SPEC.md §5.2).
    carried: Vec<(&'a Body, PairManifold, [i32; 3])>,
    /// Awake bodies this one rests on (supports), with their cells, ascending id: each may
    /// form a load system with it (SPEC.md §5.2, "Load").
    supports: Vec<(&'a Body, [i32; 3])>,
    /// Every body it touches, in the order met: what rejects a load system before its
    /// cells are read.
    touches: smallvec::SmallVec<[Touch; 8]>,
    /// Symmetric pair contacts, ascending partner id.
    pairs: Vec<PairEntry<'a>>,
    /// Whether every body partner with contact points was quiet at step `t` (SPEC.md §5.4).
    partners_quiet: bool,
    /// Whether the body has contact points with a body or the environment at step `t`: a
    /// body touching nothing is in free flight and never falls asleep while it moves
    /// (SPEC.md §5.4).
    touching: bool,
    /// Whether a body an input removes at this step (SPEC.md §5.4) can reach this one: what
    /// it rested on may be gone, so it wakes.
    disturbed: bool,
    /// The body's support depth after this step (SPEC.md §5.2).
    support_depth: u32,
}

/// A body that one body touches at step `t` (SPEC.md §5.2, "Load").
struct Touch {
    /// The body.
    id: BodyId,
    /// Its cell relative to the centre cell.
    offset: [i32; 3],
    /// Whether, seen from the body touching it as the lower body of a load system, it may be
    /// part of one: a body it rests on, or an awake body resting on it.
    in_load: bool,
}

/// Whether cell `o` (relative to the centre cell) is within one cell of both `a` and `b`.
fn shared_by(o: [i32; 3], a: [i32; 3], b: [i32; 3]) -> bool {
    (0..3).all(|k| (o[k] - a[k]).abs() <= 1 && (o[k] - b[k]).abs() <= 1)
}

/// Manifolds of the pairs computed for one cell, keyed by (lower id, higher id).
type ManifoldCache = Vec<(BodyId, BodyId, Option<PairManifold>)>;

/// Load systems solved for one cell whose bodies are all in it, keyed by the lower body's
/// id; `None` where it forms none.
type SolvedLoads = Vec<(BodyId, Option<std::rc::Rc<Vec<load::UpperLoad>>>)>;

/// An upper body resting on a lower one as a support, each with its cell relative to the
/// centre cell: what a load system is asked for.
#[derive(Clone, Copy)]
struct LoadPair<'a> {
    /// The body resting on `lower`.
    upper: &'a Body,
    /// `upper`'s cell.
    upper_offset: [i32; 3],
    /// The support, resting on the static environment.
    lower: &'a Body,
    /// `lower`'s cell.
    lower_offset: [i32; 3],
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

    /// Contacts of body `own` against the neighbourhood and the environment: the sets of
    /// the per-body solve (ascending partner id, static last) and the symmetric pairs.
    fn contacts<'a>(
        &self,
        own: &Candidate<'a>,
        candidates: &[Candidate<'a>],
        cache: &mut ManifoldCache,
    ) -> Contacts<'a> {
        let mut partners_quiet = true;
        let mut touching = false;
        let mut disturbed = false;
        let mut support_depth = u32::MAX;
        let slack = self.filter_slack();
        let mut sets = Vec::new();
        let mut pairs = Vec::new();
        let mut carried = Vec::new();
        let mut supports = Vec::new();
        let mut touches = smallvec::SmallVec::new();
        for c in candidates {
            if c.body.id() == own.body.id() || !own.may_touch(c, slack) {
                continue;
            }
            if c.body.is_leaving() {
                // The candidates that `may_touch` keeps hold every body that can reach `own`
                // (a superset of the speculative-distance test of bounding spheres; the box
                // test below is not one for cuboids, whose boxes are smaller than their
                // spheres).
                disturbed |= self.can_reach(own.body, c.body);
                continue;
            }
            if !own.boxes_within(c, own.motion + c.motion + slack) {
                continue;
            }
            let j = c.body;
            let (a, b) = canonical(own.body, j);
            let reach = self.reach(a, Some(b));
            if !near(a, b, reach) || !own.boxes_within(c, reach + slack) {
                continue;
            }
            let Some(m) = self.manifold(a, b, reach, cache) else {
                continue;
            };
            partners_quiet &= j.is_quiet(self.params.sleep_speed);
            touching = true;
            let support = self.support(a, b, &m);
            touches.push(Touch {
                id: j.id(),
                offset: c.offset,
                in_load: match support {
                    Some(lower) if lower == own.body.id() => !self.is_asleep(j),
                    Some(_) => true,
                    None => false,
                },
            });
            match support {
                // Shock propagation: `own` does not carry the weight of a partner resting on
                // it, but stops its own approach to it (a carried set); a sleeping partner is a
                // pile contact (a frozen body does not move out of the way, so a woken lower
                // body must not move into it); a partner `own` rests on is immovable.
                Some(lower) if lower == own.body.id() => {
                    if self.is_asleep(j) {
                        sets.push(pile_contact(own.body, j, &m));
                    } else {
                        carried.push((j, m, c.offset));
                    }
                }
                Some(_) => {
                    support_depth = support_depth.min(u32::from(j.support_depth) + 1);
                    sets.push(support_contact(own.body, j, &m));
                    if !self.is_asleep(j) && !self.is_asleep(own.body) {
                        supports.push((j, c.offset));
                    }
                }
                None => {
                    let contact = self.pair_contact(a, b, &m);
                    if self.in_pile(a, b, contact.edge(self.rest_speed())) {
                        // A resting contact in a supported pile: both bodies' own solves
                        // share it (SPEC.md §5.3). It does not bounce. Kept when both bodies
                        // sleep: it only moves `own`, and a sleeping body that something woke
                        // must not roll into a sleeping neighbour.
                        sets.push(pile_contact(own.body, j, &m));
                    } else if self.is_asleep(a) && self.is_asleep(b) {
                        // Two sleeping bodies form no pair: a frozen body must not be moved.
                    } else {
                        pairs.push(PairEntry {
                            partner: j,
                            offset: c.offset,
                            contact,
                            manifold: m,
                        })
                    }
                }
            }
        }
        sets.sort_unstable_by_key(|s| s.partner);
        pairs.sort_unstable_by_key(|p| p.partner.id());
        carried.sort_unstable_by_key(|c| c.0.id());
        supports.sort_unstable_by_key(|c| c.0.id());
        if let Some(env) = self.environment_set(own.body) {
            if let Some(up) = self.up() {
                if env
                    .points
                    .iter()
                    .any(|p| p.normal.dot(&up) > SUPPORT_COSINE)
                {
                    support_depth = 1;
                }
            }
            sets.push(env);
            touching = true;
        }
        if support_depth == u32::MAX {
            if let Some(depth) = self.landing_depth(own, candidates) {
                support_depth = depth;
            }
        }
        Contacts {
            sets,
            pairs,
            carried,
            supports,
            touches,
            partners_quiet,
            touching,
            disturbed,
            support_depth: if support_depth == u32::MAX {
                0
            } else {
                support_depth
            },
        }
    }

    /// The support depth of a body that rests on no support at step `t` but is landing on
    /// one (SPEC.md §5.2): within twice its speculative distance (the reach of the next step,
    /// at step-`t` velocities) of an environment point whose normal is within 75° of `up`
    /// (depth 1), or of a body with depth `k > 0` that would carry it as a support (depth
    /// `k + 1`, the least such). `None` without gravity or if there is no such partner.
    fn landing_depth(&self, own: &Candidate<'_>, candidates: &[Candidate<'_>]) -> Option<u32> {
        self.up()?; // No landing without gravity.
        let cap = self.prediction();
        let slack = self.filter_slack();
        let reach = self.reach(own.body, None);
        let ahead = (2.0 * reach).min(cap);
        if self.rests_on_environment(own.body, ahead) {
            return Some(1);
        }
        let mut depth = u32::MAX;
        for c in candidates {
            let j = c.body;
            if j.id() == own.body.id()
                || j.support_depth == 0
                || j.is_leaving()
                || u32::from(j.support_depth) + 1 >= depth
                || !own.may_touch(c, own.motion + c.motion + 2.0 * slack)
                || !own.boxes_within(c, 2.0 * (own.motion + c.motion + slack))
            {
                continue;
            }
            let (a, b) = canonical(own.body, j);
            let reach = self.reach(a, Some(b));
            let ahead = (2.0 * reach).min(cap);
            if !near(a, b, ahead) {
                continue;
            }
            let keep = keep_distance(ahead, a.bounding_radius(), b.bounding_radius(), cap);
            let Some(m) = pair_manifold(a, b, ahead, keep) else {
                continue;
            };
            if self.support(a, b, &m) == Some(j.id()) {
                depth = u32::from(j.support_depth) + 1;
            }
        }
        (depth != u32::MAX).then_some(depth)
    }

    /// Whether the environment offers `body` a support within `distance`: a contact point whose
    /// normal is within 75° of up (SPEC.md §5.2). Never without gravity.
    pub(crate) fn rests_on_environment(&self, body: &Body, distance: f32) -> bool {
        let Some(up) = self.up() else {
            return false;
        };
        let radius = body.bounding_radius();
        let keep = keep_distance(distance, radius, radius, self.prediction());
        environment_contacts(body, &self.environment, distance, keep).is_some_and(|env| {
            env.points
                .iter()
                .any(|p| p.normal.dot(&up) > SUPPORT_COSINE)
        })
    }

    /// The manifold of `a` (lower id) and `b` within `reach`, computed once per cell.
    fn manifold(
        &self,
        a: &Body,
        b: &Body,
        reach: f32,
        cache: &mut ManifoldCache,
    ) -> Option<PairManifold> {
        match cache.binary_search_by_key(&(a.id(), b.id()), |e| (e.0, e.1)) {
            Ok(pos) => cache[pos].2.clone(),
            Err(pos) => {
                let keep = keep_distance(
                    reach,
                    a.bounding_radius(),
                    b.bounding_radius(),
                    self.prediction(),
                );
                let m = pair_manifold(a, b, reach, keep);
                cache.insert(pos, (a.id(), b.id(), m.clone()));
                m
            }
        }
    }

    /// The pair contact of `a` (lower id) and `b` with the combined material.
    fn pair_contact(&self, a: &Body, b: &Body, m: &PairManifold) -> PairContact {
        PairContact::new(
            a,
            b,
            m,
            0.5 * (a.friction() + b.friction()),
            0.5 * (a.restitution() + b.restitution()),
            self.dt,
            self.rest_speed(),
        )
    }

    /// The unit vector against gravity, if there is gravity.
    pub(crate) fn up(&self) -> Option<Vec3> {
        let g = self.gravity.norm();
        (g > 0.0).then(|| -self.gravity / g)
    }

    /// Shock propagation (SPEC.md §5.2): if the pair of `a` (lower id) and `b` is a support —
    /// with gravity, a normal within 75° of the vertical, and the lower body resting on a
    /// support chain at step `t` (support depth > 0) — the lower body's id. Every other body
    /// contact, in particular two bodies colliding in flight, is a symmetric pair. A pure
    /// function of the pair's step-`t` states, so both bodies classify it alike.
    fn support(&self, a: &Body, b: &Body, m: &PairManifold) -> Option<BodyId> {
        let up = self.up()?;
        let c = m.normal_ab.dot(&up);
        let lower = if c > SUPPORT_COSINE {
            a
        } else if c < -SUPPORT_COSINE {
            b
        } else {
            return None;
        };
        (lower.support_depth > 0).then_some(lower.id())
    }

    /// Whether the symmetric contact of `a` and `b` is a *pile contact* (SPEC.md §5.3): with
    /// gravity, not an impact, and one of the two resting on a support chain (support depth
    /// above 0). It is then solved in each body's own solve, with the partner's inverse mass,
    /// together with its supports: solved apart from them, by one split-mass pass per step
    /// and an overlap projection that changed no velocity, a pile's resting contacts kept an
    /// approach that never turned into motion, and ball piles never came to rest. Two bodies
    /// in flight (both at depth 0) and every impact stay pairs, whose momentum is exact. A
    /// pure function of the pair's step-`t` states, so both bodies classify it alike.
    /// `edge`: the pair's [`PairContact::edge`] at the resting speed.
    fn in_pile(&self, a: &Body, b: &Body, edge: Option<Edge>) -> bool {
        !self.matched()
            && (a.support_depth > 0 || b.support_depth > 0)
            && !edge.is_some_and(|e| e.impact)
    }

    /// Whether a deferred impact is only projected (without gravity, SPEC.md §5.3): it keeps
    /// its velocities, which only impulses change; under gravity it would gain `g·dt` of
    /// approach per step while its position is held, so it is resolved with split masses.
    fn matched(&self) -> bool {
        self.gravity == Vec3::zeros()
    }

    /// Whether a deferred impact under gravity is only projected, as without gravity (SPEC.md
    /// §5.3): its approach is more than gravity adds in a step on top of the resting speed, so
    /// it is a collision of its own that comes again, first in the matching, in a later step,
    /// not a resting contact that gravity drives on while it waits. (Resolved with split
    /// masses in the same step as the impact that came first, a ball struck at 8 m/s into a
    /// resting row, which it reached through its neighbour, took both impulses: the row's
    /// kinetic energy grew 1.9-fold.)
    fn beyond_gravity(&self, edge: Edge) -> bool {
        edge.fastest > self.gravity.norm() * self.dt + self.rest_speed()
    }

    /// Approaches slower than this are plastic (restitution 0): two substeps of gravity.
    fn rest_speed(&self) -> f32 {
        2.0 * self.gravity.norm() * self.dt / self.params.substeps.max(1) as f32
    }

    /// The closing symmetric pair of `x` and `y`, if they form one: the same tests, in the
    /// same arithmetic, as [`Self::contacts`].
    fn edge(&self, x: &Body, y: &Body, cache: &mut ManifoldCache) -> Option<Edge> {
        let (a, b) = canonical(x, y);
        if self.is_asleep(a) && self.is_asleep(b) {
            return None;
        }
        let reach = self.reach(a, Some(b));
        if !near(a, b, reach) {
            return None;
        }
        let m = self.manifold(a, b, reach, cache)?;
        if self.support(a, b, &m).is_some() {
            return None;
        }
        let edge = self.pair_contact(a, b, &m).edge(self.rest_speed());
        if self.in_pile(a, b, edge) {
            return None;
        }
        edge
    }

    /// What `own`'s pair with `entry` (closing, as `edge`) meets among the closing symmetric
    /// pairs of its two bodies whose partner lies in a cell both bodies' cells see (both cells
    /// survey the same set, so they agree, SPEC.md §5.3): the mass-splitting counts of `own`
    /// and of the partner (1 plus their other closing pairs), and whether an impact of either
    /// body comes first in the matching.
    fn survey(
        &self,
        own: &Body,
        entry: &PairEntry<'_>,
        edge: Edge,
        pairs: &[PairEntry<'_>],
        nb: &Neighbourhood<'_, Body>,
        cache: &mut ManifoldCache,
    ) -> (u32, u32, bool) {
        let ob = entry.offset;
        let shared = |o: [i32; 3]| (0..3).all(|k| (o[k] - ob[k]).abs() <= 1);
        let rest = self.rest_speed();
        let beats = |e: &Edge| e.impact && e.key < edge.key;
        let mut beaten = false;
        let mut mine = 1;
        for p in pairs {
            if p.partner.id() != entry.partner.id() && shared(p.offset) {
                if let Some(e) = p.contact.edge(rest) {
                    mine += 1;
                    beaten |= beats(&e);
                }
            }
        }
        let mut theirs = 1;
        for (slot, cell) in nb.cells.iter().enumerate() {
            if !shared(Neighbourhood::<Body>::offset(slot)) {
                continue;
            }
            for k in cell.iter() {
                if k.id() == own.id() || k.id() == entry.partner.id() || k.is_leaving() {
                    continue;
                }
                if let Some(e) = self.edge(entry.partner, k, cache) {
                    theirs += 1;
                    beaten |= beats(&e);
                }
            }
        }
        (mine, theirs, beaten)
    }

    /// The speculative distance (SPEC.md §5.2) of `a` and partner `b`, or of `a` and the
    /// static environment (`None`), capped at the prediction.
    fn reach(&self, a: &Body, b: Option<&Body>) -> f32 {
        speculative_distance(
            a,
            b,
            self.dt,
            self.gravity.norm(),
            self.params.margin,
            self.prediction(),
        )
    }

    /// Whether `x` and `y` touch at step `t` (a manifold within their speculative distance,
    /// the test of [`Self::contacts`]); the manifold in canonical order if so.
    fn touching(&self, x: &Body, y: &Body, cache: &mut ManifoldCache) -> Option<PairManifold> {
        // No pair's speculative distance exceeds the cap: bodies farther apart never touch.
        if !near(x, y, self.prediction()) {
            return None;
        }
        let (a, b) = canonical(x, y);
        let reach = self.reach(a, Some(b));
        // The world boxes grown by the reach, as in `Self::contacts` (a superset of the
        // manifold's test, with the same slack against rounding): most bodies beside a cube
        // within its bounding sphere's reach are dropped here, before parry.
        if !near(a, b, reach) || !world_boxes_within(a, b, reach + self.filter_slack()) {
            return None;
        }
        self.manifold(a, b, reach, cache)
    }

    /// The environment contacts of `body` at step `t`, as its own solve finds them.
    fn environment_set(&self, body: &Body) -> Option<ContactSet> {
        let cap = self.prediction();
        let reach = self.reach(body, None);
        let radius = body.bounding_radius();
        environment_contacts(
            body,
            &self.environment,
            reach,
            keep_distance(reach, radius, radius, cap),
        )
    }

    /// The solved load system of `pair` ([`Self::load_system`], [`load::solve_load`]),
    /// computed once per cell and lower body when both bodies are in the centre cell.
    fn solved_load<'a>(
        &self,
        pair: &LoadPair<'a>,
        nb: &Neighbourhood<'a, Body>,
        cache: &mut ManifoldCache,
        solved: &mut SolvedLoads,
    ) -> Option<std::rc::Rc<Vec<load::UpperLoad>>> {
        // Both in the centre cell: the system is read from the whole neighbourhood and holds
        // every awake body resting on `lower` (or is `None` for each of them), so it is one
        // per lower body, whichever upper body asks.
        let own_pair = pair.upper_offset == [0; 3] && pair.lower_offset == [0; 3];
        let key = pair.lower.id();
        if own_pair {
            if let Ok(at) = solved.binary_search_by_key(&key, |e| e.0) {
                return solved[at].1.clone();
            }
        }
        let loads = self
            .load_system(pair, nb, cache)
            .map(|system| std::rc::Rc::new(load::solve_load(&system, self.gravity, self.dt)));
        if own_pair {
            let at = solved.partition_point(|e| e.0 < key);
            solved.insert(at, (key, loads.clone()));
        }
        loads
    }

    /// The load system (SPEC.md §5.2, "Load") of `pair.upper` resting on `pair.lower` (both
    /// awake, the contact a support), read from the cells both bodies' cells contain, so
    /// that both cells build
    /// the same one: `lower`, the bodies it rests on and the environment as what holds it,
    /// and every awake body resting on it (`upper` among them). `None` — shock propagation
    /// alone — if `lower` touches any other body there, if an upper body touches a body other
    /// than `lower` there, or if nothing found there holds `lower` up.
    fn load_system<'a>(
        &self,
        pair: &LoadPair<'a>,
        nb: &Neighbourhood<'a, Body>,
        cache: &mut ManifoldCache,
    ) -> Option<load::LoadSystem<'a>> {
        let &LoadPair {
            upper,
            upper_offset,
            lower,
            lower_offset,
        } = pair;
        let up = self.up()?;
        // Only a lower body that rests on the static environment itself: there the load's
        // path ends within the system. (Deeper in a chain, every body of a column would build
        // and solve one, 3 times the cost of a 1,000-cube pile, measured 2026-11-29.)
        if lower.support_depth != 1 {
            return None;
        }
        let shared = |o: [i32; 3]| shared_by(o, upper_offset, lower_offset);
        let region = || {
            nb.cells
                .iter()
                .enumerate()
                .filter(move |(slot, _)| shared(Neighbourhood::<Body>::offset(*slot)))
                .flat_map(|(_, cell)| cell.iter())
                .filter(|k| !k.is_leaving())
        };
        // The upper body touches no other body there: checked first, as it rejects most (in
        // a column it carries the body above it).
        let alone = |k: &Body, cache: &mut ManifoldCache| {
            region().all(|j| {
                j.id() == k.id() || j.id() == lower.id() || self.touching(k, j, cache).is_none()
            })
        };
        if !alone(upper, cache) {
            return None;
        }
        let mut holds: Vec<ContactSet> = Vec::new();
        let mut uppers: Vec<(&'a Body, PairManifold)> = Vec::new();
        let mut held_up = false;
        for k in region() {
            if k.id() == lower.id() {
                continue;
            }
            let Some(m) = self.touching(lower, k, cache) else {
                continue;
            };
            let (a, b) = canonical(lower, k);
            match self.support(a, b, &m) {
                Some(id) if id == k.id() => {
                    held_up = true;
                    holds.push(support_contact(lower, k, &m));
                }
                Some(_) if !self.is_asleep(k) => uppers.push((k, m)),
                _ => return None,
            }
        }
        if !uppers.iter().any(|(k, _)| k.id() == upper.id()) {
            return None;
        }
        // Every other upper body touches no other body there either.
        for (k, _) in &uppers {
            if k.id() != upper.id() && !alone(k, cache) {
                return None;
            }
        }
        // Ascending id (the region is read slot by slot), the environment last.
        holds.sort_unstable_by_key(|set| set.partner);
        uppers.sort_unstable_by_key(|(k, _)| k.id());
        if let Some(env) = self.environment_set(lower) {
            held_up |= env
                .points
                .iter()
                .any(|p| p.normal.dot(&up) > SUPPORT_COSINE);
            holds.push(env);
        }
        if !held_up {
            return None;
        }
        let system = load::LoadSystem {
            lower,
            holds,
            uppers: uppers
                .into_iter()
                .map(|(k, manifold)| load::Upper {
                    body: k,
                    manifold,
                    environment: self.environment_set(k),
                })
                .collect(),
        };
        Some(system)
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
        self.sleeping() && b.rest_steps >= self.params.sleep_limit() && !b.is_leaving()
    }

    /// Whether bodies `i` and `k` can interact during this step (bounding spheres within the
    /// pair's speculative distance, SPEC.md §5.2): the test for contacts and for waking.
    fn can_reach(&self, i: &Body, k: &Body) -> bool {
        let (a, b) = if i.id() < k.id() { (i, k) } else { (k, i) };
        let reach = self.reach(a, Some(b));
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
        let spin_cap = self.params.spin_cap(after.bounding_radius());
        if after.angvel.norm() > spin_cap {
            after.angvel *= spin_cap / after.angvel.norm();
            capped = true;
        }
        if capped {
            events.push(Event {
                step,
                body: after.id(),
                kind: EventKind::SpeedCapped,
            });
        }
    }
}

/// A body as a broad-phase candidate: its bounding sphere grown by how far its surface can
/// move in one step.
struct Candidate<'a> {
    body: &'a Body,
    /// The body's cell relative to the centre cell.
    offset: [i32; 3],
    /// `dt·(|v| + |ω|·r)` (the farthest any surface point moves in the step), at most the
    /// prediction.
    motion: f32,
    /// Bounding radius plus `motion`.
    sweep: f32,
    /// Half extents of the world axis-aligned box around the shape, computed on first use.
    half_box: OnceCell<Vec3>,
}

impl<'a> Candidate<'a> {
    fn new(body: &'a Body, offset: [i32; 3], dt: f32, prediction: f32) -> Candidate<'a> {
        let r = body.bounding_radius();
        let motion = dt * (body.linvel.norm() + body.angvel.norm() * r);
        let motion = motion.min(prediction);
        Candidate {
            body,
            offset,
            motion,
            sweep: r + motion,
            half_box: OnceCell::new(),
        }
    }

    /// Half extents of the world axis-aligned box around the shape.
    fn half_box(&self) -> Vec3 {
        *self.half_box.get_or_init(|| world_half_box(self.body))
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

/// Half extents of `b`'s world-aligned bounding box.
fn world_half_box(b: &Body) -> Vec3 {
    match b.shape() {
        Shape::Ball { radius } => Vec3::repeat(radius),
        Shape::Cuboid { half_extents } => {
            b.rotation.to_rotation_matrix().into_inner().abs() * Vec3::from(half_extents)
        }
    }
}

/// Whether the world boxes of `a` and `b` lie within `distance` of each other on every axis.
fn world_boxes_within(a: &Body, b: &Body, distance: f32) -> bool {
    let d = (a.position - b.position).abs();
    let limit = world_half_box(a) + world_half_box(b);
    (0..3).all(|k| d[k] <= limit[k] + distance)
}

/// Inserts `set` into `sets` (ascending partner id, the static environment last) at its place.
fn insert_by_partner(sets: &mut Vec<ContactSet>, set: ContactSet) {
    let partner = set.partner;
    let at = sets.partition_point(|s| s.partner.is_some() && s.partner < partner);
    sets.insert(at, set);
}

/// Body `i`'s contact set for a pile contact with `j` (SPEC.md §5.3): the partner's inverse
/// mass, restitution 0 (a resting contact does not bounce), and a position correction added
/// whole.
fn pile_contact(i: &Body, j: &Body, m: &PairManifold) -> ContactSet {
    resting_view(i, j, m, SetRole::Pile)
}

/// Body `i`'s view of its contact with the movable partner `j` in `role`, with `j`'s inverse
/// mass and restitution 0 (a resting contact does not bounce).
fn resting_view(i: &Body, j: &Body, m: &PairManifold, role: SetRole) -> ContactSet {
    let mut set = view(i, j, m);
    set.restitution = 0.0;
    set.role = role;
    set
}

/// Body `i`'s contact set for a support `j` it rests on (SPEC.md §5.2): `j` is immovable
/// (inverse mass 0), and where `j` moves into `i` at a point, `i` sees it approach only at
/// the speed the two would share after a plastic collision were `i` at rest along the
/// normal, `n·v_j · w_i / (w_i + w_j)` (`w` the generalised inverse masses along the normal
/// at the point). Seeing the whole of it, a
/// heavy upper body was driven as if the light body under it were infinitely heavy: a ball
/// pushed at 2 m/s under a ball five times its density leaning on a wall lifted it with
/// 26 mJ more than the 67 mJ of kinetic energy the scene had.
fn support_contact(i: &Body, j: &Body, m: &PairManifold) -> ContactSet {
    let mut set = view(i, j, m);
    for p in &mut set.points {
        let approach = p.normal.dot(&p.partner_velocity);
        if approach > 0.0 {
            let w = inv_mass_at(i, &i.rotation, &(i.rotation * p.anchor), &p.normal);
            let kept = w / (w + p.partner_inv_mass);
            p.partner_velocity -= p.normal * (approach * (1.0 - kept));
        }
        p.partner_inv_mass = 0.0;
    }
    set
}

/// Body `i`'s contact set for a partner `j` that rests on it (SPEC.md §5.2, the lower body of
/// a support): restitution 0, `j`'s velocity only where it moves away from `i`, and `j`
/// immovable (inverse mass 0) — `j`'s fall onto `i` is `j`'s to stop, but `i` pushing into `j`
/// is stopped here, whole: shock propagation keeps `j`'s weight from `i`, and that weight is
/// what would hold `i` back. Without the set a lower body that slid sideways into a body it
/// carried pushed it as if infinitely heavy and wedged it upwards: potential energy created
/// (0.03–1.09 J in random 150-body piles, measured 2026-11-26). With `j`'s inverse mass in it,
/// `i` stopped only its share of the approach in the velocity pass and kept sliding under
/// `j`: a ball rolling off the ball under it lifted the column it carried by 0.3–0.5 mm per
/// step, 0.29 J in one pile of 225 balls (measured 2026-11-27).
fn carried_contact(i: &Body, j: &Body, m: &PairManifold) -> ContactSet {
    approach_only_view(i, j, m, SetRole::Carried)
}

/// Body `i`'s contact set for the partner of a symmetric pair that rests on a support chain
/// (SPEC.md §5.3), `after` being the partner with its velocities after the pair's response:
/// restitution 0, `after`'s velocity only where it moves away from `i` (a partner driven into
/// `i` by the pair has given `i` its share already) and `after` immovable (inverse mass 0),
/// so that `i`'s solve stops any approach it gains towards the partner beyond the partner's
/// own motion away. Without it the
/// solve accelerated a ball rolling on the ball under it into a light box beside it on the
/// ground, every step, and only the pair's position correction held it there: the ball
/// kept spinning at 1.1 rad/s in place, each step an "impact" whose impulse the light box
/// passed on to the ground (a mixed pile, measured 2026-11-28).
fn paired_contact(i: &Body, after: &Body, m: &PairManifold) -> ContactSet {
    approach_only_view(i, after, m, SetRole::Paired)
}

/// Body `i`'s view of `j` in a set that only stops `i`'s approach (`role`: carried or
/// paired): restitution 0, `j`'s velocity only where it moves away from `i`, and `j`
/// immovable (inverse mass 0).
fn approach_only_view(i: &Body, j: &Body, m: &PairManifold, role: SetRole) -> ContactSet {
    let mut set = resting_view(i, j, m, role);
    for p in &mut set.points {
        let away = p.normal.dot(&p.partner_velocity).min(0.0);
        p.partner_velocity = p.normal * away;
        p.partner_inv_mass = 0.0;
    }
    set
}

/// The pair in canonical order: lower id first.
fn canonical<'a>(x: &'a Body, y: &'a Body) -> (&'a Body, &'a Body) {
    if x.id() < y.id() {
        (x, y)
    } else {
        (y, x)
    }
}

/// Panics if a component of `b`'s state is not finite: a NaN or an infinity is a model
/// defect, never a reason to drop the body silently (SPEC.md §5.3).
fn assert_finite(b: &Body, step: Step) {
    let q = b.rotation.quaternion();
    let fields: [(&str, [f32; 4], &[&str]); 4] = [
        (
            "linear velocity",
            [b.linvel.x, b.linvel.y, b.linvel.z, 0.0],
            &["x", "y", "z"],
        ),
        (
            "angular velocity",
            [b.angvel.x, b.angvel.y, b.angvel.z, 0.0],
            &["x", "y", "z"],
        ),
        (
            "position",
            [b.position.x, b.position.y, b.position.z, 0.0],
            &["x", "y", "z"],
        ),
        ("orientation", [q.w, q.i, q.j, q.k], &["w", "x", "y", "z"]),
    ];
    for (name, values, axes) in fields {
        for (axis, v) in axes.iter().zip(values) {
            if !v.is_finite() {
                panic!(
                    "body {} at step {step}: {name} {axis} is {v:?} (0x{:08x}) after computing step {step} -> {}",
                    b.id(),
                    v.to_bits(),
                    step + 1
                );
            }
        }
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
        state.id()
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
        // (The centre cell's bodies first: in a gas the first of them is awake.)
        if nb.own().iter().all(|b| self.is_asleep(b)) && nb.iter().all(|b| self.is_asleep(b)) {
            out.extend(nb.own().iter().map(frozen));
            return;
        }
        let mut candidates: Vec<Candidate<'_>> = Vec::new();
        let mut cache = Vec::new();
        let mut solved = SolvedLoads::new();
        let mut rows = SolveRows::default();
        for own in nb.own() {
            // Removed by an input at this step (SPEC.md §5.4): not in the next state.
            if own.is_leaving() {
                continue;
            }
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
                // Grown once more by the motions for the landing test's look-ahead
                // (`landing_depth`, twice the speculative distance).
                let (lo, hi, own_sweep, own_motion) = nb.own().iter().fold(
                    (
                        Vec3::repeat(f32::MAX),
                        Vec3::repeat(f32::MIN),
                        0.0f32,
                        0.0f32,
                    ),
                    |(lo, hi, w, m), b| {
                        let c = Candidate::new(b, [0; 3], self.dt, self.prediction());
                        (
                            lo.inf(&b.position),
                            hi.sup(&b.position),
                            w.max(c.sweep),
                            m.max(c.motion),
                        )
                    },
                );
                let grow = own_sweep + own_motion + 2.0 * self.filter_slack();
                // Sized for the whole neighbourhood up front: a filtered collect grows by
                // reallocation (4, 8, 16, ... candidates), a measurable share of a step.
                candidates.reserve_exact(nb.cells.iter().map(|c| c.len()).sum());
                // All six comparisons, then one branch: which of them fails first is
                // unpredictable in a gas (the same comparisons of the same numbers).
                let within = |p: [f32; 3], r: f32| {
                    (0..3).fold(true, |ok, k| {
                        ok & (p[k] >= lo[k] - grow - r) & (p[k] <= hi[k] + grow + r)
                    })
                };
                for row in 0..9 {
                    let slots = &nb.cells[3 * row..3 * row + 3];
                    if let Some(hints) = nb.row_hints(row) {
                        // The same test on the same numbers, read from the hints: a body
                        // left out is not loaded at all. Same order: slot by slot.
                        let (l0, l1) = (slots[0].len(), slots[0].len() + slots[1].len());
                        for (i, h) in hints.iter().enumerate() {
                            if within([h[0], h[1], h[2]], h[3]) {
                                let (k, b) = if i < l0 {
                                    (0, &slots[0][i])
                                } else if i < l1 {
                                    (1, &slots[1][i - l0])
                                } else {
                                    (2, &slots[2][i - l1])
                                };
                                let offset = Neighbourhood::<Body>::offset(3 * row + k);
                                let c = Candidate::new(b, offset, self.dt, self.prediction());
                                candidates.push(c);
                            }
                        }
                        continue;
                    }
                    for (k, cell) in slots.iter().enumerate() {
                        if cell.is_empty() {
                            continue;
                        }
                        let offset = Neighbourhood::<Body>::offset(3 * row + k);
                        candidates.extend(
                            cell.iter()
                                .map(|b| Candidate::new(b, offset, self.dt, self.prediction()))
                                .filter(|c| {
                                    let r = c.sweep + c.motion;
                                    within(c.body.position.into(), r)
                                }),
                        );
                    }
                }
            }
            let me = Candidate::new(own, [0; 3], self.dt, self.prediction());
            let mut found = self.contacts(&me, &candidates, &mut cache);
            // Load systems (SPEC.md §5.2, "Load"): as an upper body, `own` sees each support
            // that forms one with it move as the joint solve moves it; as a lower body, it
            // takes each upper body's impulses, spread over its solve as a force.
            for (lower, offset) in &found.supports {
                // Rejected at once (the test the load system makes, on what `own` touches):
                // `own` touches another body in the cells both cells contain.
                if found
                    .touches
                    .iter()
                    .any(|t| t.id != lower.id() && shared_by(t.offset, [0; 3], *offset))
                {
                    continue;
                }
                let Some(loads) = self.solved_load(
                    &LoadPair {
                        upper: own,
                        upper_offset: [0; 3],
                        lower,
                        lower_offset: *offset,
                    },
                    nb,
                    &mut cache,
                    &mut solved,
                ) else {
                    continue;
                };
                let Some(mine) = loads.iter().find(|l| l.id == own.id()) else {
                    continue;
                };
                if let Some(set) = found
                    .sets
                    .iter_mut()
                    .find(|s| s.partner == Some(lower.id()))
                {
                    set.role = SetRole::Loaded;
                    for (p, v) in set.points.iter_mut().zip(&mine.point_velocities) {
                        p.partner_velocity = *v;
                    }
                }
            }
            let mut load = load::LoadEffect::default();
            // The upper bodies whose load `own` takes (ascending id): their weight and inertia
            // hold `own` back, so they need no carried set.
            let mut loading: Vec<BodyId> = Vec::new();
            if !self.is_asleep(own) {
                for (upper, _, offset) in &found.carried {
                    // Rejected at once: `own` touches, in the cells both cells contain, a body
                    // that is neither its support nor an awake body resting on it.
                    if found
                        .touches
                        .iter()
                        .any(|t| !t.in_load && shared_by(t.offset, *offset, [0; 3]))
                    {
                        continue;
                    }
                    let Some(loads) = self.solved_load(
                        &LoadPair {
                            upper,
                            upper_offset: *offset,
                            lower: own,
                            lower_offset: [0; 3],
                        },
                        nb,
                        &mut cache,
                        &mut solved,
                    ) else {
                        continue;
                    };
                    if let Some(theirs) = loads.iter().find(|l| l.id == upper.id()) {
                        load.add(&theirs.lower);
                        loading.push(upper.id());
                    }
                }
            }
            // Symmetric pairs first (SPEC.md §5.3), each with its bodies' mass-splitting
            // counts, summed in ascending partner id.
            let mut effect = PairEffect::default();
            let rest = self.rest_speed();
            // Partners on a support chain after the pair's response: `own` stops what it
            // gains towards them within its solve (a `Paired` set, SPEC.md §5.3).
            let mut paired: Vec<ContactSet> = Vec::new();
            for entry in &found.pairs {
                // An impact first in both bodies' matching: full mass. A deferred impact:
                // only projected without gravity, split masses with gravity. Resting
                // pairs: split masses.
                let (resolve, counts) = match entry.contact.edge(rest) {
                    None => (false, (1, 1)),
                    Some(edge) => {
                        let (mine, theirs, beaten) =
                            self.survey(own, entry, edge, &found.pairs, nb, &mut cache);
                        if edge.impact && !beaten {
                            (true, (1, 1))
                        } else if edge.impact && (self.matched() || self.beyond_gravity(edge)) {
                            (false, (1, 1))
                        } else if own.id() < entry.partner.id() {
                            (true, (mine, theirs))
                        } else {
                            (true, (theirs, mine))
                        }
                    }
                };
                effect.add(
                    &entry
                        .contact
                        .effect(own.id(), resolve, counts, self.dt, rest),
                );
                let j = entry.partner;
                if j.support_depth > 0 {
                    let theirs = entry.contact.effect(j.id(), resolve, counts, self.dt, rest);
                    // The set reads the partner's linear velocity only (as every view does).
                    let mut after = j.clone();
                    after.linvel += theirs.dv;
                    paired.push(paired_contact(own, &after, &entry.manifold));
                }
            }
            let mut start = own.clone();
            start.linvel += effect.dv;
            start.angvel += effect.dw;
            // A carried or paired set acts only if the body approaches its partner (SPEC.md
            // §5.2, §5.3): with its pairs' impulses at the start of its solve, or else at the end
            // of it (it slid into it within the step), in which case the body is solved again
            // with it. Building only those saves the work of every resting column. Inserted
            // in ascending partner id, before the environment.
            let mut left_out = Vec::new();
            let carried = found
                .carried
                .iter()
                .filter(|(j, _, _)| loading.binary_search(&j.id()).is_err())
                .map(|(j, m, _)| carried_contact(&start, j, m));
            for set in carried.chain(paired) {
                if approaches(&start, &set) {
                    insert_by_partner(&mut found.sets, set);
                } else {
                    left_out.push(set);
                }
            }
            let solve = |sets: &[ContactSet], rows: &mut SolveRows| {
                solve_body(
                    &start,
                    &effect,
                    &load,
                    sets,
                    self.gravity,
                    self.dt,
                    &self.params,
                    rows,
                )
            };
            let mut next = solve(&found.sets, &mut rows);
            if !left_out.is_empty() {
                // The start pose (the sets' points) with the end velocities.
                let mut at_end = start.clone();
                at_end.linvel = next.linvel;
                at_end.angvel = next.angvel;
                let mut resolve = false;
                for set in left_out {
                    if approaches(&at_end, &set) {
                        insert_by_partner(&mut found.sets, set);
                        resolve = true;
                    }
                }
                if resolve {
                    next = solve(&found.sets, &mut rows);
                }
            }
            next.position += effect.dx;
            if effect.dtheta != Vec3::zeros() {
                let before = next.rotation;
                next.rotation = integrate_rotation(&next.rotation, &effect.dtheta, 1.0);
                // The time-of-impact correction turns a box back by `−Δω·τ`: its angular
                // velocity turns along, so the spin keeps its body-frame axis and the
                // rotational energy the pair's impulses left it (SPEC.md §5.3). Turning the
                // body alone changed `½ωᵀIω` (+13 % in one step for a box spinning at
                // 47 rad/s struck by a ball). A body whose principal inertias are equal
                // (a ball, a cube) has the same energy in every orientation: its spin is
                // left as it is, and so is its angular momentum.
                next.angvel = next.carry_spin(&before, &next.rotation, next.angvel);
            }
            assert_finite(&next, step);
            self.cap(own, &mut next, step, events);
            // Saturating below `LEAVING`: a column deeper than 65,534 bodies counts as that deep.
            next.support_depth = found.support_depth.min(u32::from(LEAVING) - 1) as u16;
            let quiet = |b: &Body| b.is_quiet(self.params.sleep_speed);
            // A body in free flight keeps its momentum: it counts towards sleep only while it
            // touches something, or if it does not move at all (then freezing it is exact).
            let held = found.touching || (own.is_still() && next.is_still());
            // A body that a removed one could touch wakes (`disturbed`): what it rested on
            // may be gone.
            next.rest_steps = if self.sleeping()
                && held
                && found.partners_quiet
                && quiet(own)
                && quiet(&next)
                && !found.disturbed
                // A body gathering speed is not coming to rest, however slow it still is: a
                // box starting to slide down a slope a little steeper than its friction angle
                // (0.09 m/s²) fell asleep at 0.046 m/s and stayed there. Below the floor a
                // speed's rise is the solver's noise in a resting pile, and a body gathering
                // speed passes the floor within half the sleep window. (Last: computed only
                // for a body that is otherwise quiet.)
                && !(next.speeds_up_from(own)
                    && next.linvel.norm() > self.params.speeding_up_floor())
            {
                own.rest_steps
                    .saturating_add(1)
                    .min(self.params.sleep_limit())
            } else {
                0
            };
            if !self.domain.contains(&next.position) {
                events.push(Event {
                    step,
                    body: next.id(),
                    kind: EventKind::LeftDomain,
                });
                continue;
            }
            out.push(next);
        }
    }

    /// A body's step reads a neighbour through `can_reach` (contacts and waking), for the
    /// matching of its symmetric pairs the partners of its partners (two contacts:
    /// `r_i + r_k + 2·(r_max + prediction)` between centres), and with gravity, for a load
    /// system (SPEC.md §5.2), the partners of the other bodies resting on its support (three
    /// contacts: `r_i + r_k + 4·r_max + 3·prediction`). An all-asleep neighbourhood freezes
    /// exactly the bodies no awake body reaches.
    fn may_affect(&self, reader: &Body, other: &Body) -> bool {
        if self.can_reach(reader, other) {
            return true;
        }
        let contacts = if self.up().is_some() { 3.0 } else { 2.0 };
        let within = reader.bounding_radius()
            + other.bounding_radius()
            + 2.0 * (contacts - 1.0) * self.max_radius
            + contacts * self.prediction();
        (reader.position - other.position).norm_squared() <= within * within
    }
    /// Asleep, with both velocities exactly `+0.0`: an all-asleep neighbourhood gives every
    /// body of the centre cell its frozen copy (same pose and counter, zero velocities,
    /// SPEC.md §5.4), which is then the body itself, bit for bit, and raises no event.
    fn at_rest(&self, b: &Body) -> bool {
        self.is_asleep(b)
            && b.linvel
                .iter()
                .chain(b.angvel.iter())
                .all(|v| v.to_bits() == 0)
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
        h.u32(u32::from(b.rest_steps));
        h.u32(u32::from(b.support_depth));
    }

    /// Bit equality of every field (every hashed field is an `f32`/`u32` compared here by
    /// its bits; the constant properties by their handle, equal exactly when their bits are).
    fn same_bits(a: &Body, b: &Body) -> bool {
        let bits = |v: &Vec3| [v.x.to_bits(), v.y.to_bits(), v.z.to_bits()];
        let quat = |b: &Body| {
            let q = b.rotation.quaternion();
            [q.w.to_bits(), q.i.to_bits(), q.j.to_bits(), q.k.to_bits()]
        };
        a.id() == b.id()
            && a.rest_steps == b.rest_steps
            && a.support_depth == b.support_depth
            && bits(&a.position) == bits(&b.position)
            && bits(&a.linvel) == bits(&b.linvel)
            && bits(&a.angvel) == bits(&b.angvel)
            && quat(a) == quat(b)
            && a.props_id() == b.props_id()
    }

    /// The body's position and the reach of the candidate filter of
    /// [`step_cell`](CellModel::step_cell), `sweep + motion` of its broad-phase
    /// `Candidate`: computed once per body and step instead of once per neighbourhood
    /// that holds it.
    fn hint(&self, b: &Body) -> Option<Hint> {
        let c = Candidate::new(b, [0; 3], self.dt, self.prediction());
        let p = b.position;
        Some([p.x, p.y, p.z, c.sweep + c.motion])
    }

    fn event_name(kind: &EventKind) -> String {
        kind.name().to_string()
    }

    fn wire() -> Option<crate::model::Wire<Body, EventKind>> {
        Some(crate::checkpoint::exact_wire(
            |e| match e {
                EventKind::SpeedCapped => 0,
                EventKind::LeftDomain => 1,
            },
            |w| match w {
                0 => Some(EventKind::SpeedCapped),
                1 => Some(EventKind::LeftDomain),
                _ => None,
            },
        ))
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
        out.push(("support_depth".to_string(), b.support_depth.to_string()));
        out
    }
}
