//! A tiny, cheap, non-physics cell model: soft repelling particles in a box. It exists to
//! show the kernel does not know physics, and to make property tests, benches and fuzz
//! targets affordable. It honours the locality contract with cell edge 1: particles
//! interact within distance 0.5 and move at most 0.3 per step.

use crate::frame::{Event, LeftGrid};
use crate::grid::Grid;
use crate::hash::StateHash;
use crate::math::Vec3;
use crate::model::{BodyId, CellModel, Neighbourhood, Step};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// One particle.
#[derive(Clone, Debug, PartialEq)]
pub struct Particle {
    /// Id.
    pub id: BodyId,
    /// Position.
    pub pos: [f32; 3],
    /// Velocity per step.
    pub vel: [f32; 3],
}

/// The particle model: repulsion within `RADIUS`, speed capped at `MAX_SPEED` per step
/// (a `SpeedCapped` event), walls reflect unless `open` (then particles leave the domain).
#[derive(Clone, Debug, PartialEq)]
pub struct Particles {
    /// Domain size in cells (cell edge 1, lower corner at the origin).
    pub dims: [i32; 3],
    /// Whether the domain's x faces let particles out.
    pub open: bool,
}

impl Particles {
    /// Interaction radius.
    pub const RADIUS: f32 = 0.5;
    /// Largest displacement per step.
    pub const MAX_SPEED: f32 = 0.3;
    /// Repulsion stiffness.
    pub const STIFFNESS: f32 = 0.08;

    /// A model, its grid and `n` particles placed at random (seeded) in a `dims` box.
    pub fn scene(n: usize, dims: [i32; 3], open: bool, seed: u64) -> (Self, Grid, Vec<Particle>) {
        let grid = Grid {
            min: Vec3::zeros(),
            edge: 1.0,
            dims,
        };
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let bodies = (0..n as u64)
            .map(|id| Particle {
                id,
                pos: [0, 1, 2].map(|a| rng.random_range(0.0..dims[a] as f32 * 0.999)),
                vel: [0, 1, 2].map(|_| rng.random_range(-0.2f32..0.2)),
            })
            .collect();
        (Particles { dims, open }, grid, bodies)
    }
}

/// The synthetic model's events.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum ParticleEvent {
    /// The particle's speed was capped at [`Particles::MAX_SPEED`].
    SpeedCapped,
    /// The particle left the grid (an open face) and was removed.
    LeftGrid,
}

impl From<LeftGrid> for ParticleEvent {
    fn from(_: LeftGrid) -> Self {
        ParticleEvent::LeftGrid
    }
}

impl CellModel for Particles {
    type State = Particle;
    type Event = ParticleEvent;

    fn id(s: &Particle) -> BodyId {
        s.id
    }

    fn position(s: &Particle) -> [f32; 3] {
        s.pos
    }

    fn step_cell(
        &self,
        step: Step,
        _grid: &Grid,
        nb: &Neighbourhood<'_, Particle>,
        out: &mut Vec<Particle>,
        events: &mut Vec<Event<ParticleEvent>>,
    ) {
        let mut others: Vec<&Particle> = nb.iter().collect();
        others.sort_by_key(|p| p.id);
        for p in nb.own() {
            let mut v = p.vel;
            for q in &others {
                if q.id == p.id {
                    continue;
                }
                let d = [0, 1, 2].map(|a| p.pos[a] - q.pos[a]);
                let dist = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                if dist < Self::RADIUS && dist > 1e-6 {
                    let f = Self::STIFFNESS * (Self::RADIUS - dist) / dist;
                    for a in 0..3 {
                        v[a] += f * d[a];
                    }
                }
            }
            let speed = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            if speed > Self::MAX_SPEED {
                let s = Self::MAX_SPEED / speed;
                v = v.map(|c| c * s);
                events.push(Event {
                    step,
                    body: p.id,
                    kind: ParticleEvent::SpeedCapped,
                });
            }
            let mut pos = [0, 1, 2].map(|a| p.pos[a] + v[a]);
            for a in 0..3 {
                let hi = self.dims[a] as f32;
                if self.open && a == 0 {
                    continue;
                }
                if pos[a] < 0.0 {
                    pos[a] = -pos[a];
                    v[a] = -v[a];
                }
                if pos[a] >= hi {
                    pos[a] = (2.0 * hi - pos[a]).min(hi * 0.9999);
                    v[a] = -v[a];
                }
            }
            out.push(Particle {
                id: p.id,
                pos,
                vel: v,
            });
        }
    }

    /// The same distance test, in the same arithmetic, as `step_cell`'s repulsion.
    fn may_affect(&self, reader: &Particle, other: &Particle) -> bool {
        let d = [0, 1, 2].map(|a| reader.pos[a] - other.pos[a]);
        let dist = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        dist < Self::RADIUS
    }

    fn hash_state(s: &Particle, h: &mut StateHash) {
        for a in 0..3 {
            h.f32(s.pos[a]);
        }
        for a in 0..3 {
            h.f32(s.vel[a]);
        }
    }
}
