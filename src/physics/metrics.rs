//! Measurements of a state that do not feed back into it: energy, speed and the exact
//! penetration measured with parry's contact query (not the solver's estimate).

use super::body::{Body, Shape};
use super::contact::near;
use super::environment::Environment;
use crate::math::Vec3;
use parry3d::query;

/// Total kinetic energy, summed in the given (id) order from +0 (`Iterator::sum` of floats
/// starts at −0, and an empty scene printed `kinetic energy -0.0000 J`).
pub fn kinetic_energy<'a>(bodies: impl IntoIterator<Item = &'a Body>) -> f64 {
    bodies
        .into_iter()
        .fold(0.0, |sum, b| sum + b.kinetic_energy() as f64)
}

/// Potential energy relative to height 0 under `gravity`.
pub fn potential_energy<'a>(bodies: impl IntoIterator<Item = &'a Body>, gravity: Vec3) -> f64 {
    bodies.into_iter().fold(0.0, |sum, b| {
        sum - (b.mass() * gravity.dot(&b.position)) as f64
    })
}

/// Largest linear speed.
pub fn max_speed<'a>(bodies: impl IntoIterator<Item = &'a Body>) -> f32 {
    bodies
        .into_iter()
        .map(|b| b.linvel.norm())
        .fold(0.0, f32::max)
}

/// Exact penetration depth of body `b` into the static environment (0 if none).
pub fn environment_penetration(b: &Body, env: &Environment) -> f32 {
    let mut deepest = 0.0f32;
    for plane in &env.planes {
        let lowest = match b.shape() {
            Shape::Ball { radius } => plane.normal.dot(&b.position) - radius,
            Shape::Cuboid { .. } => b
                .shape()
                .vertices()
                .iter()
                .map(|v| plane.normal.dot(&(b.position + b.rotation * v)))
                .fold(f32::INFINITY, f32::min),
        } - plane.offset;
        deepest = deepest.max(-lowest);
    }
    for c in &env.cuboids {
        let sc = parry3d::shape::Cuboid::new(c.half_extents);
        let sb = b.shape().parry();
        if let Ok(Some(ct)) = query::contact(&b.pose(), sb.as_dyn(), &c.pose, &sc, 0.0) {
            deepest = deepest.max(-ct.dist);
        }
    }
    deepest
}

/// Exact penetration depth between two bodies (0 if apart).
pub fn pair_penetration(a: &Body, b: &Body) -> f32 {
    if !near(a, b, 0.0) {
        return 0.0;
    }
    let (sa, sb) = (a.shape().parry(), b.shape().parry());
    match query::contact(&a.pose(), sa.as_dyn(), &b.pose(), sb.as_dyn(), 0.0) {
        Ok(Some(c)) => (-c.dist).max(0.0),
        _ => 0.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn energies_of_no_bodies_are_positive_zero() {
        let none: [Body; 0] = [];
        let k = kinetic_energy(none.iter());
        let p = potential_energy(none.iter(), Vec3::new(0.0, -9.81, 0.0));
        assert!(k == 0.0 && k.is_sign_positive(), "kinetic {k}");
        assert!(p == 0.0 && p.is_sign_positive(), "potential {p}");
    }
}
