//! Scene validation: every rule names the field, the value and what is allowed.

use super::show::{number, shape_size, vector};
use super::{BodySpec, Scene, SceneError};
use crate::grid::Grid;
use crate::physics::metrics::{environment_penetration, pair_penetration};
use crate::physics::{Body, Environment, RigidBodyModel, Shape, SolverParams};
use crate::state::CellStates;

pub use crate::physics::MAX_ANGULAR_SPEED_CAP;

/// The strongest gravity a scene may set, m/s² (about 100,000 g): far below where a step's
/// velocity and displacement overflow f32 (a pull of 3e38 m/s² left the bodies hovering).
pub const MAX_GRAVITY: f32 = 1e6;

/// The largest `solver.max_speed` a scene may set, m/s: far below where a step's impulses
/// and energies overflow f32 (two balls at 1e29 m/s made a velocity NaN in their first
/// collision, and one at 1e29 m/s was capped to about nothing).
pub const MAX_SPEED_CAP: f32 = 1e6;

/// Initial overlap tolerated between bodies (and with static geometry), in metres.
pub const OVERLAP_TOLERANCE: f32 = 1e-3;

struct Checker<'a> {
    origin: &'a str,
}

/// A field's name in a message, made only when a check fails.
trait FieldName {
    fn name(self) -> String;
}

impl FieldName for &str {
    fn name(self) -> String {
        self.to_string()
    }
}

impl FieldName for &String {
    fn name(self) -> String {
        self.clone()
    }
}

/// A field name formatted on failure only: a million valid bodies format none.
struct Lazy<F>(F);

impl<F: FnOnce() -> String> FieldName for Lazy<F> {
    fn name(self) -> String {
        (self.0)()
    }
}

/// A value in a message, written as in a scene file (see [`super::show`]).
trait Shown {
    fn shown(&self) -> String;
}

impl Shown for f32 {
    fn shown(&self) -> String {
        number(*self)
    }
}

impl Shown for [f32; 3] {
    fn shown(&self) -> String {
        vector(*self)
    }
}

impl Shown for &[f32] {
    fn shown(&self) -> String {
        let items: Vec<String> = self.iter().map(|&x| number(x)).collect();
        format!("[{}]", items.join(", "))
    }
}

/// Whole numbers and text are shown as they print.
macro_rules! shown_as_printed {
    ($($t:ty),*) => {
        $(impl Shown for $t {
            fn shown(&self) -> String {
                self.to_string()
            }
        })*
    };
}

shown_as_printed!(u16, u32, u64, String);

impl Checker<'_> {
    fn fail(&self, field: impl Into<String>, value: impl Shown, allowed: &str) -> SceneError {
        SceneError::Invalid {
            origin: self.origin.to_string(),
            field: field.into(),
            value: value.shown(),
            allowed: allowed.to_string(),
        }
    }

    fn finite(&self, field: impl FieldName, v: &[f32]) -> Result<(), SceneError> {
        if v.iter().all(|x| x.is_finite()) {
            Ok(())
        } else {
            Err(self.fail(
                field.name(),
                v,
                "every component must be a finite number (no NaN or infinity)",
            ))
        }
    }

    fn range(
        &self,
        field: impl FieldName,
        v: f32,
        lo: f32,
        hi: f32,
        allowed: &str,
    ) -> Result<(), SceneError> {
        if v.is_finite() && v >= lo && v <= hi {
            Ok(())
        } else {
            Err(self.fail(field.name(), v, allowed))
        }
    }

    fn positive(&self, field: impl FieldName, v: f32) -> Result<(), SceneError> {
        if v.is_finite() && v > 0.0 {
            Ok(())
        } else {
            Err(self.fail(field.name(), v, "must be a finite number greater than 0"))
        }
    }
}

/// Checks every rule of SPEC.md §Scenes. `origin` names the file in messages.
pub fn validate(scene: &Scene, origin: &str) -> Result<(), SceneError> {
    let c = Checker { origin };
    c.range(
        "dt",
        scene.dt,
        1e-5,
        0.1,
        "must be between 0.00001 and 0.1 seconds",
    )?;
    c.finite("gravity", &scene.gravity)?;
    if length(scene.gravity) > f64::from(MAX_GRAVITY) {
        return Err(c.fail(
            "gravity",
            scene.gravity,
            &format!("must be at most {MAX_GRAVITY:e} m/s² long (about 100,000 g); a stronger pull overflows a step's f32 arithmetic"),
        ));
    }
    c.finite("domain.min", &scene.domain.min)?;
    c.finite("domain.max", &scene.domain.max)?;
    for k in 0..3 {
        if scene.domain.max[k] <= scene.domain.min[k] {
            return Err(c.fail(
                format!("domain.max[{k}]"),
                scene.domain.max[k],
                &format!(
                    "must be greater than domain.min[{k}] = {}",
                    number(scene.domain.min[k])
                ),
            ));
        }
    }
    let s = &scene.solver;
    if !(1..=1000).contains(&s.substeps) {
        return Err(c.fail("solver.substeps", s.substeps, "must be between 1 and 1000"));
    }
    if !(1..=100).contains(&s.sweeps) {
        return Err(c.fail("solver.sweeps", s.sweeps, "must be between 1 and 100"));
    }
    if s.impact_iterations > 100 {
        return Err(c.fail(
            "solver.impact_iterations",
            s.impact_iterations,
            "must be between 0 (no impact pass) and 100",
        ));
    }
    if !(1..=100).contains(&s.velocity_iterations) {
        return Err(c.fail(
            "solver.velocity_iterations",
            s.velocity_iterations,
            "must be between 1 and 100",
        ));
    }
    c.range(
        "solver.landing_speed",
        s.landing_speed,
        0.0,
        100.0,
        "must be between 0 and 100 m/s",
    )?;
    c.range(
        "solver.relaxation",
        s.relaxation,
        0.01,
        2.0,
        "must be between 0.01 and 2",
    )?;
    c.range(
        "solver.margin",
        s.margin,
        0.0,
        10.0,
        "must be between 0 and 10 metres",
    )?;
    c.positive("solver.max_speed", s.max_speed)?;
    if s.max_speed > MAX_SPEED_CAP {
        return Err(c.fail(
            "solver.max_speed",
            s.max_speed,
            &format!("must be at most {MAX_SPEED_CAP:e} m/s"),
        ));
    }
    // Beyond these the f32 arithmetic of one step overflows: a spin of 1e22 rad/s turned the
    // orientation's update to infinity and the rotation to NaN.
    if !(s.max_angular_speed > 0.0 && s.max_angular_speed <= MAX_ANGULAR_SPEED_CAP) {
        return Err(c.fail(
            "solver.max_angular_speed",
            s.max_angular_speed,
            &format!("must be greater than 0 and at most {MAX_ANGULAR_SPEED_CAP:e} rad/s"),
        ));
    }
    c.range(
        "solver.max_separation_speed",
        s.max_separation_speed,
        0.0,
        100.0,
        "must be between 0 and 100 m/s",
    )?;
    c.range(
        "solver.patch_radius",
        s.patch_radius,
        0.0,
        10.0,
        "must be between 0 (no torsional friction) and 10 metres",
    )?;
    c.range(
        "solver.sleep_speed",
        s.sleep_speed,
        0.0,
        100.0,
        "must be between 0 and 100 m/s",
    )?;
    if s.sleep_steps > crate::physics::MAX_SLEEP_STEPS {
        return Err(c.fail(
            "solver.sleep_steps",
            s.sleep_steps,
            "must be between 0 (no sleeping) and 65535 (18 minutes at 60 steps per second)",
        ));
    }
    if let Some(e) = scene.cell_edge {
        c.positive("cell_edge", e)?;
    }
    let env = &scene.environment;
    if let Some(g) = env.ground {
        c.range(
            "environment.ground",
            g,
            scene.domain.min[1],
            scene.domain.max[1],
            &format!(
                "must lie between domain.min[1] = {} and domain.max[1] = {}",
                number(scene.domain.min[1]),
                number(scene.domain.max[1])
            ),
        )?;
    }
    c.range(
        "environment.friction",
        env.friction,
        0.0,
        10.0,
        "must be between 0 and 10",
    )?;
    c.range(
        "environment.restitution",
        env.restitution,
        0.0,
        1.0,
        "must be between 0 and 1",
    )?;
    let body_reach = f64::from(scene.max_radius()) + f64::from(scene.solver.margin);
    for (i, sc) in env.cuboids.iter().enumerate() {
        c.finite(&format!("environment.cuboids[{i}].position"), &sc.position)?;
        c.finite(&format!("environment.cuboids[{i}].rotation"), &sc.rotation)?;
        for (k, &h) in sc.half_extents.iter().enumerate() {
            c.positive(&format!("environment.cuboids[{i}].half_extents[{k}]"), h)?;
        }
        // Wholly out of reach (a body's centre stays in the domain, its surface up to the
        // largest body's radius and the contact margin beyond): most likely a coordinate
        // mistyped.
        let outside: f64 = (0..3)
            .map(|k| {
                let x = f64::from(sc.position[k]);
                let gap = (f64::from(scene.domain.min[k]) - x)
                    .max(x - f64::from(scene.domain.max[k]))
                    .max(0.0);
                gap * gap
            })
            .sum::<f64>()
            .sqrt();
        let reach = length(sc.half_extents) + body_reach;
        if outside > reach {
            return Err(c.fail(
                format!("environment.cuboids[{i}].position"),
                sc.position,
                &format!(
                    "the static box lies outside the domain ({} to {}) beyond any body's reach: move it inside or remove it",
                    vector(scene.domain.min),
                    vector(scene.domain.max)
                ),
            ));
        }
    }

    let extent = [0, 1, 2].map(|k| scene.domain.max[k] - scene.domain.min[k]);
    let smallest = extent.iter().cloned().fold(f32::INFINITY, f32::min);
    let mut ids: Vec<(u64, usize)> = Vec::with_capacity(scene.bodies.len());
    for (i, b) in scene.bodies.iter().enumerate() {
        let f = |name: &str| format!("bodies[{i}].{name}");
        check_body(&c, scene, b, &f, smallest)?;
        ids.push((b.id, i));
    }
    ids.sort();
    for w in ids.windows(2) {
        if w[0].0 == w[1].0 {
            return Err(c.fail(
                format!("bodies[{}].id", w[1].1),
                w[1].0,
                &format!("ids must be unique; bodies[{}] has the same id", w[0].1),
            ));
        }
    }
    let edge = scene.cell_edge();
    if !edge.is_finite() {
        return Err(c.fail(
            "solver.max_speed",
            s.max_speed,
            &format!("the cell edge derived from it (largest body + solver.margin + 2 * max_speed * dt) must be finite, got {}: lower solver.max_speed", number(edge)),
        ));
    }
    // Counted in f64 so that a huge domain cannot overflow the count (Grid::cell_count is
    // a usize product).
    let cells: f64 = (0..3)
        .map(|k| ((extent[k] as f64 / edge as f64).ceil()).max(1.0))
        .product();
    if cells > Grid::MAX_CELLS as f64 {
        return Err(c.fail(
            "domain",
            format!(
                "min = {}, max = {}",
                vector(scene.domain.min),
                vector(scene.domain.max)
            ),
            &format!("the grid would have {cells:.3e} cells of edge {} m; at most {} are allowed: shrink the domain or raise cell_edge", number(edge), Grid::MAX_CELLS),
        ));
    }
    let grid = scene.grid();
    check_overlaps(scene, &grid, &c)
}

fn check_overlaps(scene: &Scene, grid: &Grid, c: &Checker) -> Result<(), SceneError> {
    let model = scene.model();
    let bodies = scene.initial_bodies();
    let index_of = |id: u64| scene.bodies.iter().position(|b| b.id == id).unwrap_or(0);
    for b in &bodies {
        if let Some(why) = into_environment(b, &model.environment) {
            return Err(c.fail(
                format!("bodies[{}].position", index_of(b.id())),
                scene.bodies[index_of(b.id())].position,
                &why,
            ));
        }
    }
    let mut events = Vec::new();
    let state = CellStates::binned::<RigidBodyModel>(grid, bodies, 0, &mut events);
    let mut walk = state.walk(grid, &[]);
    for i in state.occupied() {
        let nb = walk.at(i);
        for a in nb.own() {
            for b in nb.iter().filter(|b| b.id() > a.id()) {
                let p = pair_penetration(a, b);
                if p > OVERLAP_TOLERANCE {
                    return Err(c.fail(
                        format!("bodies[{}].position", index_of(b.id())),
                        scene.bodies[index_of(b.id())].position,
                        &format!("body {} overlaps body {} by {p:.4} m (at most {} m allowed): move them apart", b.id(), a.id(), number(OVERLAP_TOLERANCE)),
                    ));
                }
            }
        }
    }
    Ok(())
}

/// The rules of one body of `scene` (shape, material, mass, position inside the domain,
/// speed); `f` names a field of it in messages, `smallest` is the domain's smallest extent.
fn check_body(
    c: &Checker,
    scene: &Scene,
    b: &BodySpec,
    f: &dyn Fn(&str) -> String,
    smallest: f32,
) -> Result<(), SceneError> {
    let s = &scene.solver;
    match b.shape {
        Shape::Ball { radius } => c.positive(Lazy(|| f("shape.radius")), radius)?,
        Shape::Cuboid { half_extents } => {
            for (k, &h) in half_extents.iter().enumerate() {
                c.positive(Lazy(|| f(&format!("shape.half_extents[{k}]"))), h)?;
            }
        }
    }
    let (size_field, size, kind) = shape_size(&b.shape);
    let diameter = 2.0 * b.shape.bounding_radius();
    if diameter >= smallest {
        let diameter = match b.shape {
            Shape::Ball { .. } => format!("its diameter, {} m,", number(diameter)),
            Shape::Cuboid { .. } => format!("its diagonal, {} m,", number(diameter)),
        };
        return Err(c.fail(
            f(size_field),
            size,
            &format!(
                "the {kind} is too big for the domain: {diameter} must be smaller than the domain's smallest extent ({} m)",
                number(smallest)
            ),
        ));
    }
    c.positive(Lazy(|| f("material.density")), b.material.density)?;
    // Mass and inertia derived in f32 must be finite and non-zero: a radius of 1e-38 m
    // passes the checks above but its inertia underflows, and the solver would turn the
    // infinite inverse into NaN (a hard error at the first step, SPEC.md §5.3).
    // (Computed without interning: a rejected body leaves nothing in the table.)
    let probe = crate::physics::BodyProps::new(b.shape, b.material);
    let inverse = [
        probe.inv_mass(),
        probe.inv_inertia().x,
        probe.inv_inertia().y,
        probe.inv_inertia().z,
    ];
    if !inverse.iter().all(|v| v.is_finite() && *v > 0.0) {
        let message = format!(
            "the mass ({} kg) and moments of inertia derived from the size and density must be finite and non-zero in f32 (the body is too small or too large, or its density too extreme)",
            number(b.material.density * b.shape.volume())
        );
        // The density is to blame when it is far outside any material's (air's ~1 kg/m³ to
        // osmium's 22,600); otherwise the size.
        return Err(if (1e-3..=1e5).contains(&b.material.density) {
            c.fail(f(size_field), size, &message)
        } else {
            c.fail(f("material.density"), b.material.density, &message)
        });
    }
    c.range(
        Lazy(|| f("material.friction")),
        b.material.friction,
        0.0,
        10.0,
        "must be between 0 and 10",
    )?;
    c.range(
        Lazy(|| f("material.restitution")),
        b.material.restitution,
        0.0,
        1.0,
        "must be between 0 and 1",
    )?;
    c.finite(Lazy(|| f("position")), &b.position)?;
    c.finite(Lazy(|| f("rotation")), &b.rotation)?;
    c.finite(Lazy(|| f("velocity")), &b.velocity)?;
    c.finite(Lazy(|| f("angular_velocity")), &b.angular_velocity)?;
    for k in 0..3 {
        if b.position[k] < scene.domain.min[k] || b.position[k] >= scene.domain.max[k] {
            return Err(c.fail(
                f("position"),
                b.position,
                &format!(
                    "the centre must lie inside the domain: domain.min = {} <= position < domain.max = {} on every axis",
                    vector(scene.domain.min),
                    vector(scene.domain.max)
                ),
            ));
        }
    }
    if let Some(why) = over_speed_cap(b.velocity, s) {
        return Err(c.fail(f("velocity"), b.velocity, &why));
    }
    if let Some(why) = over_spin_cap(b.angular_velocity, &b.shape, s) {
        return Err(c.fail(f("angular_velocity"), b.angular_velocity, &why));
    }
    Ok(())
}

/// Checks a body added to `scene` during a run (an input): the rules of a scene's body, an
/// id not in `in_use`, and no bigger than the scene's largest body (the grid's cell edge was
/// sized for that one, SPEC.md §3). `field` names the body in messages (`inputs[3].body`);
/// `largest` is the scene's [`Scene::max_radius`] and `environment` its static environment
/// (`scene.model().environment`), passed in so that checking many added bodies against a
/// large scene does not measure it or build them each time. An added body must not overlap
/// the environment by more than [`OVERLAP_TOLERANCE`].
pub fn validate_added_body(
    scene: &Scene,
    b: &BodySpec,
    origin: &str,
    field: &str,
    largest: f32,
    environment: &Environment,
) -> Result<(), SceneError> {
    let c = Checker { origin };
    let extent = [0, 1, 2].map(|k| scene.domain.max[k] - scene.domain.min[k]);
    let smallest = extent.iter().cloned().fold(f32::INFINITY, f32::min);
    let f = |name: &str| format!("{field}.{name}");
    check_body(&c, scene, b, &f, smallest)?;
    if b.shape.bounding_radius() > largest {
        let (size_field, size, kind) = shape_size(&b.shape);
        return Err(c.fail(
            f(size_field),
            size,
            &format!(
                "an added body must be no bigger than the scene's largest (bounding radius {} m), and this {kind}'s bounding radius is {} m: the grid's cells were sized for the largest; add a body that big to the scene, or set the scene's cell_edge",
                number(largest),
                number(b.shape.bounding_radius())
            ),
        ));
    }
    // As for a scene's bodies: not into the static environment (the other bodies' places at
    // that step are not known before the run; the solver separates those).
    if let Some(why) = into_environment(&b.to_body(), environment) {
        return Err(c.fail(f("position"), b.position, &why));
    }
    Ok(())
}

/// Why body `b` may not start where it is, if it overlaps the static environment by more
/// than [`OVERLAP_TOLERANCE`] (the rule of a scene's bodies and of added ones alike).
fn into_environment(b: &Body, environment: &Environment) -> Option<String> {
    let p = environment_penetration(b, environment);
    (p > OVERLAP_TOLERANCE).then(|| {
        format!(
            "the body overlaps the static environment by {p:.4} m (at most {} m allowed): move it clear",
            number(OVERLAP_TOLERANCE)
        )
    })
}

/// Why `velocity` breaks `solver.max_speed`, if it does (scene bodies and inputs alike).
pub(crate) fn over_speed_cap(velocity: [f32; 3], s: &SolverParams) -> Option<String> {
    (length(velocity) > f64::from(s.max_speed)).then(|| {
        format!(
            "speed must not exceed solver.max_speed = {} m/s",
            number(s.max_speed)
        )
    })
}

/// Why `angular_velocity` breaks the spin cap of a body of shape `shape`
/// (`SolverParams::spin_cap`), if it does.
pub(crate) fn over_spin_cap(
    angular_velocity: [f32; 3],
    shape: &Shape,
    s: &SolverParams,
) -> Option<String> {
    let radius = shape.bounding_radius();
    let cap = s.spin_cap(radius);
    (length(angular_velocity) > f64::from(cap)).then(|| {
        format!(
            "angular speed must not exceed {} rad/s for this body: the larger of solver.max_angular_speed = {} rad/s and solver.max_speed / bounding radius = {} / {} m",
            number(cap),
            number(s.max_angular_speed),
            number(s.max_speed),
            number(radius)
        )
    })
}

/// The length of `v`, in f64: an f32 norm of a finite vector overflows from about 1.8e19 on
/// (its square is beyond f32), and a check against a cap must not see infinity there.
pub(crate) fn length(v: [f32; 3]) -> f64 {
    v.iter()
        .map(|&x| f64::from(x) * f64::from(x))
        .sum::<f64>()
        .sqrt()
}

#[cfg(test)]
mod tests {
    use super::length;

    #[test]
    fn a_length_checked_against_a_cap_does_not_overflow_where_an_f32_norm_would() {
        assert!(nalgebra::Vector3::new(1e20f32, 0.0, 0.0)
            .norm()
            .is_infinite());
        assert_eq!(length([1e20, 0.0, 0.0]), 1e20f32 as f64);
        assert_eq!(length([3.0, 4.0, 0.0]), 5.0);
        assert!(length([f32::MAX, f32::MAX, f32::MAX]).is_finite());
    }
}
