//! Support depths of a scene's initial state (SPEC.md §5.2): a stack placed at rest must stand
//! from its first step.
//!
//! In a run, a body's support depth after a step is one more than the least depth of the
//! bodies it rests on at step `t` (1 on the ground), so it spreads up a stack one body per
//! step. A scene's bodies start at depth 0; a column of 15 unit cubes placed touching at rest
//! had its layers stopped one step after the one below, the layers above fell meanwhile, and
//! at step 14 the cubes overlapped by 29 cm. Computing the resting depths of the initial state
//! to their fixed point (a breadth-first search from the bodies that rest on the environment,
//! over the same support test as a step) starts such a stack as it would be after it had
//! stood for as many steps as it is high. Landing depths (a body just above a support, within
//! twice its reach but not touching) are left to the first step, as in a run.

use super::body::{Body, LEAVING};
use super::contact::{keep_distance, near, pair_manifold, speculative_distance};
use super::model::{RigidBodyModel, SUPPORT_COSINE};
use crate::math::Vec3;

/// The cell of a point in a uniform hash of edge `edge`.
fn cell_of(p: &Vec3, edge: f32) -> [i64; 3] {
    [
        (p.x / edge).floor() as i64,
        (p.y / edge).floor() as i64,
        (p.z / edge).floor() as i64,
    ]
}

impl RigidBodyModel {
    /// Sets every body's support depth to its fixed point in `bodies` (any order): 1 for a
    /// body whose environment contacts include a support (a normal within 75° of up), `k + 1`
    /// for a body that rests on a body of depth `k` (the pair's normal within 75° of the
    /// vertical, the lower body at depth > 0), the least such; 0 otherwise. Without gravity
    /// nothing rests on anything and the depths are left as they are. A pure function of the
    /// bodies (their order does not matter), so every executor starts from the same bits.
    pub fn set_initial_support_depths(&self, bodies: &mut [Body]) {
        let Some(up) = self.up().filter(|_| !bodies.is_empty()) else {
            return;
        };
        let g = self.gravity.norm();
        let cap = self.prediction();
        let margin = self.params.margin;
        // Candidate pairs from a uniform hash whose edge covers any two touching bodies.
        let largest = bodies
            .iter()
            .map(Body::bounding_radius)
            .fold(0.0f32, f32::max);
        // (Padded by a thousandth: two bodies at exactly the largest contact distance must not
        // fall two cells apart by rounding.)
        let edge = (2.0 * largest + cap) * 1.001;
        let mut keyed: Vec<([i64; 3], usize)> = bodies
            .iter()
            .enumerate()
            .map(|(k, b)| (cell_of(&b.position, edge), k))
            .collect();
        keyed.sort_unstable();
        // `above[k]`: the bodies that would rest on body `k` if it were supported.
        let mut above: Vec<Vec<usize>> = vec![Vec::new(); bodies.len()];
        let mut depth: Vec<u32> = vec![0; bodies.len()];
        let mut frontier: Vec<usize> = Vec::new();
        for (k, own) in bodies.iter().enumerate() {
            if own.is_leaving() {
                continue;
            }
            let reach = speculative_distance(own, None, self.dt, g, margin, cap);
            if self.rests_on_environment(own, reach) {
                depth[k] = 1;
                frontier.push(k);
            }
            let c = cell_of(&own.position, edge);
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        let key = [
                            c[0].saturating_add(dx),
                            c[1].saturating_add(dy),
                            c[2].saturating_add(dz),
                        ];
                        let start = keyed.partition_point(|e| e.0 < key);
                        for &(kk, j) in &keyed[start..] {
                            if kk != key {
                                break;
                            }
                            let other = &bodies[j];
                            // Each unordered pair once, from its lower id.
                            if other.id() <= own.id() || other.is_leaving() {
                                continue;
                            }
                            let (a, b) = (own, other);
                            let reach = speculative_distance(a, Some(b), self.dt, g, margin, cap);
                            if !near(a, b, reach) {
                                continue;
                            }
                            let keep =
                                keep_distance(reach, a.bounding_radius(), b.bounding_radius(), cap);
                            let Some(m) = pair_manifold(a, b, reach, keep) else {
                                continue;
                            };
                            let cos = m.normal_ab.dot(&up);
                            if cos > SUPPORT_COSINE {
                                above[k].push(j);
                            } else if cos < -SUPPORT_COSINE {
                                above[j].push(k);
                            }
                        }
                    }
                }
            }
        }
        // Breadth first from the bodies on the environment: each body's least depth.
        let limit = u32::from(LEAVING) - 1;
        let mut next = Vec::new();
        while !frontier.is_empty() {
            frontier.sort_unstable();
            for &k in &frontier {
                for &j in &above[k] {
                    if depth[j] == 0 {
                        depth[j] = (depth[k] + 1).min(limit);
                        next.push(j);
                    }
                }
            }
            frontier = std::mem::take(&mut next);
        }
        for (b, d) in bodies.iter_mut().zip(depth) {
            if !b.is_leaving() {
                b.support_depth = d as u16;
            }
        }
    }
}
