//! Shared by the benches: engine-independent measurements of a pile of bodies.
//!
//! The same code measures SODA's and Rapier's final states, so the two columns of the
//! comparison are computed identically. Penetration is *exact*: parry3d's `query::contact`
//! (GJK/EPA) between every pair of bodies whose bounding spheres overlap, and the lowest
//! vertex (or the sphere's bottom) against the ground plane — never a solver's own manifold
//! depths (SPEC.md §5.4, measured behaviour: penetration is measured exactly, not read off a
//! solver).

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use parry3d::query;
use parry3d::shape::{Ball, Cuboid, Shape as ParryShape};
use serde::Serialize;
use soda::physics::{Body, Shape};
use std::collections::HashMap;

/// One body of a final state, whatever engine produced it.
#[derive(Clone, Debug)]
pub struct PileBody {
    /// Collision shape.
    pub shape: Shape,
    /// Centre of mass, world frame.
    pub position: Vector3<f32>,
    /// Orientation.
    pub rotation: UnitQuaternion<f32>,
    /// Linear velocity, m/s.
    pub linvel: Vector3<f32>,
}

impl PileBody {
    /// The measured part of a SODA body.
    pub fn from_soda(b: &Body) -> Self {
        PileBody {
            shape: b.shape(),
            position: b.position,
            rotation: b.rotation,
            linvel: b.linvel,
        }
    }

    fn pose(&self) -> Isometry3<f32> {
        Isometry3::from_parts(Translation3::from(self.position), self.rotation)
    }

    fn lowest_point(&self) -> f32 {
        match self.shape {
            Shape::Ball { radius } => self.position.y - radius,
            Shape::Cuboid { .. } => self
                .shape
                .vertices()
                .iter()
                .map(|v| (self.position + self.rotation * v).y)
                .fold(f32::INFINITY, f32::min),
        }
    }
}

/// The x/z rectangle spanned by the initial body centres.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Footprint {
    /// Smallest initial x and z.
    pub min: [f32; 2],
    /// Largest initial x and z.
    pub max: [f32; 2],
}

impl Footprint {
    /// The footprint of `bodies` (their centres' min/max in x and z).
    pub fn of(bodies: &[Body]) -> Self {
        let mut f = Footprint {
            min: [f32::INFINITY; 2],
            max: [f32::NEG_INFINITY; 2],
        };
        for b in bodies {
            for (k, v) in [b.position.x, b.position.z].into_iter().enumerate() {
                f.min[k] = f.min[k].min(v);
                f.max[k] = f.max[k].max(v);
            }
        }
        f
    }

    /// Euclidean x/z distance of `p` from the rectangle (0 inside).
    pub fn outside(&self, p: &Vector3<f32>) -> f32 {
        let d = |v: f32, k: usize| (self.min[k] - v).max(v - self.max[k]).max(0.0);
        let (dx, dz) = (d(p.x, 0), d(p.z, 1));
        (dx * dx + dz * dz).sqrt()
    }
}

/// Measurements of a pile at one instant.
#[derive(Clone, Debug, Serialize)]
pub struct PileMetrics {
    /// Bodies present.
    pub bodies: usize,
    /// Largest exact penetration, body–body or body–ground, m.
    pub max_penetration: f32,
    /// Largest exact body–body penetration, m.
    pub max_pair_penetration: f32,
    /// Largest depth of a vertex below the ground top, m.
    pub max_ground_penetration: f32,
    /// Pairs whose bounding spheres overlap (the ones given to `query::contact`).
    pub pairs_checked: usize,
    /// Largest linear speed, m/s.
    pub max_speed: f32,
    /// Highest body centre, m.
    pub highest_centre: f32,
    /// Lowest body centre, m.
    pub lowest_centre: f32,
    /// Largest x/z distance of a body centre outside the initial footprint, m.
    pub max_outside_footprint: f32,
    /// Bodies whose centre is more than 2 m outside the initial footprint (issue 3's bound).
    pub bodies_more_than_2m_outside: usize,
}

fn parry_shape(s: &Shape) -> Box<dyn ParryShape> {
    match *s {
        Shape::Ball { radius } => Box::new(Ball::new(radius)),
        Shape::Cuboid { half_extents: h } => Box::new(Cuboid::new(Vector3::from(h))),
    }
}

/// Measures `bodies` over a ground plane whose top is `ground_y`.
pub fn measure_pile(bodies: &[PileBody], ground_y: f32, footprint: &Footprint) -> PileMetrics {
    let radius = bodies
        .iter()
        .map(|b| b.shape.bounding_radius())
        .fold(0.0f32, f32::max);
    let edge = (2.0 * radius).max(1e-3);
    let key = |p: &Vector3<f32>| {
        [
            (p.x / edge).floor() as i64,
            (p.y / edge).floor() as i64,
            (p.z / edge).floor() as i64,
        ]
    };
    // Only looked up, never iterated: the result does not depend on the map's order.
    let mut bins: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
    for (i, b) in bodies.iter().enumerate() {
        bins.entry(key(&b.position)).or_default().push(i);
    }
    let shapes: Vec<Box<dyn ParryShape>> = bodies.iter().map(|b| parry_shape(&b.shape)).collect();
    let poses: Vec<Isometry3<f32>> = bodies.iter().map(PileBody::pose).collect();
    let (mut pair_pen, mut pairs) = (0.0f32, 0usize);
    for (i, a) in bodies.iter().enumerate() {
        let k = key(&a.position);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(cell) = bins.get(&[k[0] + dx, k[1] + dy, k[2] + dz]) else {
                        continue;
                    };
                    for &j in cell.iter().filter(|&&j| j > i) {
                        let b = &bodies[j];
                        let reach = a.shape.bounding_radius() + b.shape.bounding_radius();
                        if (a.position - b.position).norm_squared() > reach * reach {
                            continue;
                        }
                        pairs += 1;
                        if let Ok(Some(c)) = query::contact(
                            &poses[i],
                            shapes[i].as_ref(),
                            &poses[j],
                            shapes[j].as_ref(),
                            0.0,
                        ) {
                            pair_pen = pair_pen.max(-c.dist);
                        }
                    }
                }
            }
        }
    }
    let ground_pen = bodies
        .iter()
        .map(|b| ground_y - b.lowest_point())
        .fold(0.0f32, f32::max);
    let fold_max = |f: &dyn Fn(&PileBody) -> f32| bodies.iter().map(f).fold(0.0f32, f32::max);
    PileMetrics {
        bodies: bodies.len(),
        max_penetration: pair_pen.max(ground_pen),
        max_pair_penetration: pair_pen,
        max_ground_penetration: ground_pen,
        pairs_checked: pairs,
        max_speed: fold_max(&|b| b.linvel.norm()),
        highest_centre: bodies
            .iter()
            .map(|b| b.position.y)
            .fold(f32::NEG_INFINITY, f32::max),
        lowest_centre: bodies
            .iter()
            .map(|b| b.position.y)
            .fold(f32::INFINITY, f32::min),
        max_outside_footprint: fold_max(&|b| footprint.outside(&b.position)),
        bodies_more_than_2m_outside: bodies
            .iter()
            .filter(|b| footprint.outside(&b.position) > 2.0)
            .count(),
    }
}

/// The bodies of a SODA state, in id order, as pile bodies.
pub fn soda_pile(state: &soda::state::CellStates<Body>) -> Vec<PileBody> {
    state
        .sorted::<soda::physics::RigidBodyModel>()
        .into_iter()
        .map(PileBody::from_soda)
        .collect()
}
