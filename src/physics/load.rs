//! The load a body puts on the body it rests on (SPEC.md §5.2, "Load").
//!
//! Shock propagation lets an upper body treat the body it rests on as immovable, so the
//! lower body never feels the weight it carries: a lever did not tip, a ball balanced on a
//! ball on frictionless ground rolled off a lower ball that never moved, and a box thrown
//! under another felt neither its weight nor its friction. Where the two bodies form a small
//! system of their own — in the cells both bodies' cells contain, the lower body touches no
//! other body but those it rests on and bodies resting on it alone, and those upper bodies
//! touch no other body — the system is
//! solved together for one step, as a pure function of the step-`t` states that both cells
//! compute alike: each upper body then sees the lower body move as the load moves it, and
//! the lower body receives the impulse each upper body puts on it, as a force spread over its
//! own solve's substeps.

use super::body::Body;
use super::contact::{ContactSet, PairManifold};
use crate::math::Vec3;
use smallvec::SmallVec;

/// Sweeps of the joint solve at most (it stops earlier once converged).
const LOAD_SWEEPS: u32 = 24;

/// The sweeps stop once no row's velocity changed by more than this, m/s.
const LOAD_TOLERANCE: f32 = 1e-6;

/// Sweeps of each one-body solve that starts the joint solve
/// (`start_from_shock_propagation`).
const START_SWEEPS: u32 = 8;

/// Slip speeds at or below this are left alone (no direction can be taken from them), m/s.
const SLIP_EPSILON: f32 = 1e-9;

/// One upper body of a load system: a body resting on the lower one and touching no other
/// body in the cells the system is read from (the static environment it may touch).
pub(crate) struct Upper<'a> {
    /// The body.
    pub body: &'a Body,
    /// Its manifold with the lower body (canonical order, lower id first).
    pub manifold: PairManifold,
    /// Its contacts with the static environment, if any.
    pub environment: Option<ContactSet>,
}

/// A load system: the lower body, what holds it (the static environment and the bodies it
/// rests on, as it sees them in its own solve: immovable), and the bodies resting on it
/// alone, ascending id.
pub(crate) struct LoadSystem<'a> {
    /// The lower body.
    pub lower: &'a Body,
    /// The lower body's sets against what holds it: its supports' views and the
    /// environment's, partner velocities as its own solve sees them.
    pub holds: Vec<ContactSet>,
    /// The upper bodies, ascending id.
    pub uppers: Vec<Upper<'a>>,
}

/// What one upper body takes from the joint solve, and gives.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct UpperLoad {
    /// The upper body's id.
    pub id: crate::model::BodyId,
    /// The lower body's velocity change from this upper body's impulses over the step, to
    /// be spread over its solve.
    pub lower: LoadEffect,
    /// What the upper body sees its support move at, at each point of its manifold (in
    /// manifold order): the lower body's linear velocity at the end of the joint solve, with
    /// its normal part that of the lower body's point there, spin included. (The spin's
    /// tangential part is left out, as in every view: `docs/open-defects/` §13.)
    pub point_velocities: SmallVec<[Vec3; 4]>,
}

/// What the bodies resting on a lower body give it over one step (SPEC.md §5.2, "Load"): a
/// velocity change its solve spreads over its substeps, like a force.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct LoadEffect {
    /// Change of linear velocity over the step, m/s.
    pub dv: Vec3,
    /// Change of angular velocity over the step, rad/s.
    pub dw: Vec3,
}

impl LoadEffect {
    /// Sums two loads.
    pub fn add(&mut self, o: &LoadEffect) {
        self.dv += o.dv;
        self.dw += o.dw;
    }

    /// Whether there is no load at all.
    pub fn is_none(&self) -> bool {
        self.dv == Vec3::zeros() && self.dw == Vec3::zeros()
    }
}

/// A row of the joint solve: one contact point between body `a` and either body `b` or
/// something immovable moving at `partner_velocity`.
struct Row {
    /// Index of the body pushed along `normal`.
    a: usize,
    /// Index of the other body, if movable.
    b: Option<usize>,
    /// Offsets of the point from the two centres.
    ra: Vec3,
    rb: Vec3,
    /// Unit normal from `b` (or the immovable partner) towards `a`.
    normal: Vec3,
    /// The immovable partner's velocity (unused with `b`).
    partner_velocity: Vec3,
    /// Gap along the normal at `t` (negative: overlap), m.
    gap: f32,
    /// Friction coefficient.
    friction: f32,
    /// Accumulated normal impulse, N·s.
    normal_impulse: f32,
    /// Accumulated friction impulse, N·s.
    friction_impulse: Vec3,
}

/// A body's velocities and its response in the joint solve.
struct Motion {
    linvel: Vec3,
    angvel: Vec3,
    inv_mass: f32,
    inv_inertia: nalgebra::Matrix3<f32>,
}

impl Motion {
    fn of(b: &Body) -> Motion {
        Motion {
            linvel: b.linvel,
            angvel: b.angvel,
            inv_mass: b.inv_mass(),
            inv_inertia: b.world_inv_inertia(&b.rotation),
        }
    }

    fn point_velocity(&self, r: &Vec3) -> Vec3 {
        self.linvel + self.angvel.cross(r)
    }

    fn inv_mass_along(&self, r: &Vec3, d: &Vec3) -> f32 {
        let rd = r.cross(d);
        self.inv_mass + rd.dot(&(self.inv_inertia * rd))
    }

    fn apply(&mut self, r: &Vec3, impulse: &Vec3) {
        self.linvel += impulse * self.inv_mass;
        self.angvel += self.inv_inertia * r.cross(impulse);
    }
}

impl Row {
    /// The impulse the row has put on its partner so far (its own, negated).
    fn on_partner(&self) -> Vec3 {
        -(self.normal * self.normal_impulse + self.friction_impulse)
    }
}

fn relative_velocity(row: &Row, bodies: &[Motion]) -> Vec3 {
    let va = bodies[row.a].point_velocity(&row.ra);
    let vb = match row.b {
        Some(b) => bodies[b].point_velocity(&row.rb),
        None => row.partner_velocity,
    };
    va - vb
}

fn inv_mass_along(row: &Row, bodies: &[Motion], d: &Vec3) -> f32 {
    bodies[row.a].inv_mass_along(&row.ra, d)
        + row.b.map_or(0.0, |b| bodies[b].inv_mass_along(&row.rb, d))
}

fn push(row: &Row, bodies: &mut [Motion], impulse: &Vec3) {
    bodies[row.a].apply(&row.ra, impulse);
    if let Some(b) = row.b {
        bodies[b].apply(&row.rb, &-impulse);
    }
}

/// Rows of body `index` against an immovable set (its holds, or the environment).
fn immovable_rows(rows: &mut Vec<Row>, index: usize, body: &Body, set: &ContactSet) {
    for cp in &set.points {
        let ra = body.rotation * cp.anchor;
        rows.push(Row {
            a: index,
            b: None,
            ra,
            rb: Vec3::zeros(),
            normal: cp.normal,
            partner_velocity: cp.partner_velocity,
            gap: cp.normal.dot(&(body.position + ra - cp.partner_point)),
            friction: set.friction,
            normal_impulse: 0.0,
            friction_impulse: Vec3::zeros(),
        });
    }
}

/// Whether a row's movable partner takes its share of the row's impulses.
#[derive(Clone, Copy, PartialEq)]
enum Partner {
    /// Both bodies move (the joint solve).
    Moves,
    /// The partner is held at its current velocity (shock propagation's view).
    Held,
}

/// One Gauss–Seidel sweep over `rows` (normal impulse, then Coulomb friction, per row):
/// every row may close by its gap within the step and must not approach beyond it.
/// Returns the largest velocity change a row made, m/s: 0 only if no impulse changed.
fn sweep(rows: &mut [Row], bodies: &mut [Motion], dt: f32, partner: Partner) -> f32 {
    let mut largest_change = 0.0f32;
    let held = partner == Partner::Held;
    let mass_along = |row: &Row, bodies: &[Motion], d: &Vec3| {
        if held {
            bodies[row.a].inv_mass_along(&row.ra, d)
        } else {
            inv_mass_along(row, bodies, d)
        }
    };
    let apply = |row: &Row, bodies: &mut [Motion], impulse: &Vec3| {
        if held {
            bodies[row.a].apply(&row.ra, impulse);
        } else {
            push(row, bodies, impulse);
        }
    };
    // Held, the partner is where the upper body's weight goes, not a driver: the part of
    // its velocity that moves into the row is left to the joint solve, which shares it by
    // the masses (held, a light body driven under a heavy one would kick it as if it were
    // infinitely heavy).
    let relative = |row: &Row, bodies: &[Motion]| {
        let v = relative_velocity(row, bodies);
        match row.b {
            Some(b) if held => {
                let into = row.normal.dot(&bodies[b].linvel).max(0.0);
                v + row.normal * into
            }
            _ => v,
        }
    };
    for row in rows {
        let n = row.normal;
        let vn = n.dot(&relative(row, bodies));
        let target = -row.gap.max(0.0) / dt;
        let w = mass_along(row, bodies, &n);
        let next = (row.normal_impulse + (target - vn) / w).max(0.0);
        if next != row.normal_impulse {
            let d = next - row.normal_impulse;
            apply(row, bodies, &(n * d));
            row.normal_impulse = next;
            // Never 0 after a change (an underflow), so 0 means the sweep changed nothing.
            largest_change = largest_change.max(d.abs() * w).max(f32::MIN_POSITIVE);
        }
        if row.friction <= 0.0 {
            continue;
        }
        let v = relative(row, bodies);
        let slip = v - n * n.dot(&v);
        let speed = slip.norm();
        let bound = row.friction * row.normal_impulse;
        let wanted = if speed > SLIP_EPSILON {
            let t = slip / speed;
            row.friction_impulse - t * (speed / mass_along(row, bodies, &t))
        } else {
            row.friction_impulse
        };
        let wanted_len = wanted.norm();
        let next = if wanted_len > bound && wanted_len > 0.0 {
            wanted * (bound / wanted_len)
        } else {
            wanted
        };
        let d = next - row.friction_impulse;
        if d != Vec3::zeros() {
            apply(row, bodies, &d);
            row.friction_impulse = next;
            let dn = d.norm();
            largest_change = largest_change
                .max(dn * mass_along(row, bodies, &(d / dn)))
                .max(f32::MIN_POSITIVE);
        }
    }
    largest_change
}

/// Starts the joint solve where shock propagation ends, then hands the upper bodies'
/// weight down: the lower body stopped by its holds, each upper body stopped against the
/// lower one held still, the reaction of those impulses put on the lower body, and the
/// lower body stopped by its holds again. A system at rest is then at its answer, and the
/// joint sweeps correct what is left (a lever's tipping, friction). Started from no
/// impulse, the sweeps approached a body resting on a lighter one at the pace of the mass
/// ratio: a cube 100 times heavier than the one under it kept 99 % of its fall after each
/// sweep, and after the last it followed a lower body that its own solve held still, so
/// its velocity grew while its position was held: energy from nothing.
fn start_from_shock_propagation(
    system: &LoadSystem<'_>,
    rows: &mut [Row],
    bodies: &mut [Motion],
    holds: usize,
    starts: &[usize],
    dt: f32,
) {
    // `rows[..holds]` are the lower body's holds; each upper body's rows (its
    // environment's, then the lower body's) end where its manifold does.
    settle(&mut rows[..holds], bodies, dt, Partner::Moves);
    let mut from = holds;
    for (u, upper) in system.uppers.iter().enumerate() {
        let to = starts[u] + upper.manifold.local.len();
        settle(&mut rows[from..to], bodies, dt, Partner::Held);
        // The reaction on the lower body.
        for row in &rows[starts[u]..to] {
            bodies[0].apply(&row.rb, &row.on_partner());
        }
        from = to;
    }
    settle(&mut rows[..holds], bodies, dt, Partner::Moves);
}

/// Up to [`START_SWEEPS`] sweeps over `rows`, stopping after one that changed nothing (the
/// next would change nothing either: the same rows, the same velocities).
fn settle(rows: &mut [Row], bodies: &mut [Motion], dt: f32, partner: Partner) {
    for _ in 0..START_SWEEPS {
        if sweep(rows, bodies, dt, partner) == 0.0 {
            break;
        }
    }
}

/// Solves the load system for one step of `dt` under `gravity` (velocities only: every row
/// may close by its gap within the step and must not approach beyond it; Coulomb friction
/// within `μ` times the row's normal impulse) and returns what each upper body gives and
/// takes, ascending id.
pub(crate) fn solve_load(system: &LoadSystem<'_>, gravity: Vec3, dt: f32) -> Vec<UpperLoad> {
    let lower = system.lower;
    let mut bodies: Vec<Motion> = std::iter::once(Motion::of(lower))
        .chain(system.uppers.iter().map(|u| Motion::of(u.body)))
        .collect();
    for m in &mut bodies {
        m.linvel += gravity * dt;
    }
    let mut rows: Vec<Row> = Vec::new();
    for set in &system.holds {
        immovable_rows(&mut rows, 0, lower, set);
    }
    let holds = rows.len();
    // Where each upper body's rows with the lower body start.
    let mut starts = Vec::with_capacity(system.uppers.len());
    for (u, upper) in system.uppers.iter().enumerate() {
        let index = u + 1;
        if let Some(env) = &upper.environment {
            immovable_rows(&mut rows, index, upper.body, env);
        }
        starts.push(rows.len());
        let upper_is_a = upper.body.id() < lower.id();
        let normal = if upper_is_a {
            -upper.manifold.normal_ab
        } else {
            upper.manifold.normal_ab
        };
        let friction = 0.5 * (upper.body.friction() + lower.friction());
        for &(la, lb) in &upper.manifold.local {
            let (lu, ll) = if upper_is_a { (la, lb) } else { (lb, la) };
            let ra = upper.body.rotation * lu;
            let rb = lower.rotation * ll;
            rows.push(Row {
                a: index,
                b: Some(0),
                ra,
                rb,
                normal,
                partner_velocity: Vec3::zeros(),
                gap: normal.dot(&(upper.body.position + ra - lower.position - rb)),
                friction,
                normal_impulse: 0.0,
                friction_impulse: Vec3::zeros(),
            });
        }
    }
    start_from_shock_propagation(system, &mut rows, &mut bodies, holds, &starts, dt);
    for _ in 0..LOAD_SWEEPS {
        if sweep(&mut rows, &mut bodies, dt, Partner::Moves) < LOAD_TOLERANCE {
            break;
        }
    }
    let l = &bodies[0];
    let lower_inv_inertia = l.inv_inertia;
    let loads = system
        .uppers
        .iter()
        .enumerate()
        .map(|(u, upper)| {
            let range = starts[u]..starts[u] + upper.manifold.local.len();
            let (mut dv, mut torque) = (Vec3::zeros(), Vec3::zeros());
            let mut point_velocities = SmallVec::new();
            for row in &rows[range] {
                // The impulse on the lower body: the row's, negated.
                let on_lower = row.on_partner();
                dv += on_lower;
                torque += row.rb.cross(&on_lower);
                let n = row.normal;
                let along = n.dot(&l.point_velocity(&row.rb));
                point_velocities.push(l.linvel + n * (along - n.dot(&l.linvel)));
            }
            UpperLoad {
                id: upper.body.id(),
                lower: LoadEffect {
                    dv: dv * l.inv_mass,
                    dw: lower_inv_inertia * torque,
                },
                point_velocities,
            }
        })
        .collect();
    loads
}
