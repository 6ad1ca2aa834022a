//! An agent-based SIR epidemic among flocking agents, with births and deaths: an example of
//! a model whose entities are created and destroyed by `step_cell`, with model-defined
//! events, seeded per-agent randomness and a precise `may_affect`.
//!
//! Every step an agent steers towards its neighbours' mean heading and away from those too
//! close (within [`Epidemic::sight`]), moves at most [`Epidemic::max_speed`] (less than one
//! cell), and bounces off the grid's faces. A susceptible agent with `k` infected agents
//! within [`Epidemic::contact_radius`] is infected with probability `1 − (1 − β)^k`; an
//! infected agent recovers after [`Epidemic::recovery_steps`] or dies with probability
//! [`Epidemic::death_rate`] per step; a healthy agent gives birth with probability
//! [`Epidemic::birth_rate`] per step (the child appears beside it, susceptible).
//!
//! Ids stay unique without any shared counter: each agent owns a range of unused ids and a
//! birth hands the upper half of it to the child; an agent whose range is spent has no more
//! children.

use super::random::entity_rng;
use crate::frame::{Event, LeftGrid};
use crate::grid::Grid;
use crate::hash::StateHash;
use crate::math::Vec3;
use crate::model::{exact_f32, BodyId, CellModel, Neighbourhood, Step};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// An agent's health.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Health {
    /// Can be infected.
    Susceptible,
    /// Infects its contacts.
    Infected,
    /// Immune.
    Recovered,
}

/// One agent.
#[derive(Clone, Debug, PartialEq)]
pub struct Agent {
    /// Id.
    pub id: BodyId,
    /// Position, m.
    pub pos: [f32; 3],
    /// Velocity, m per step.
    pub vel: [f32; 3],
    /// Health.
    pub health: Health,
    /// Steps since the health last changed.
    pub since: u32,
    /// The ids `next..end` are this agent's to give to its children.
    pub next_id: u64,
    /// End (exclusive) of the agent's id range.
    pub end_id: u64,
}

/// What happened to an agent.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum EpidemicEvent {
    /// It was infected.
    Infected,
    /// It recovered.
    Recovered,
    /// It died (and was removed).
    Died,
    /// It was born (the event names the child).
    Born,
    /// It left the grid (cannot happen: agents bounce off the faces).
    LeftGrid,
}

impl From<LeftGrid> for EpidemicEvent {
    fn from(_: LeftGrid) -> Self {
        EpidemicEvent::LeftGrid
    }
}

/// The epidemic's parameters (static data of the model).
#[derive(Clone, Debug, PartialEq)]
pub struct Epidemic {
    /// Seed of every agent's per-step randomness.
    pub seed: u64,
    /// Distance within which agents flock, m (at most the cell edge).
    pub sight: f32,
    /// Distance within which an infected agent infects, m (at most `sight`).
    pub contact_radius: f32,
    /// Infection probability per infected contact and step.
    pub beta: f32,
    /// Steps an infected agent takes to recover.
    pub recovery_steps: u32,
    /// Probability per step that an infected agent dies.
    pub death_rate: f32,
    /// Probability per step that a healthy agent gives birth.
    pub birth_rate: f32,
    /// Largest displacement per step, m (below the cell edge, which is `sight`, so an agent
    /// moves at most one cell per step).
    pub max_speed: f32,
}

impl Default for Epidemic {
    fn default() -> Self {
        Epidemic {
            seed: 1,
            sight: 1.0,
            contact_radius: 0.6,
            beta: 0.08,
            recovery_steps: 40,
            death_rate: 0.004,
            birth_rate: 0.002,
            max_speed: 0.25,
        }
    }
}

impl Epidemic {
    /// The model with `seed`, a grid of `dims` cells of edge [`sight`](Self::sight) from the
    /// origin, and `n` agents placed at random (seeded), `infected` of them infected.
    pub fn scene(
        self,
        n: usize,
        infected: usize,
        dims: [i32; 3],
        seed: u64,
    ) -> (Self, Grid, Vec<Agent>) {
        let grid = Grid {
            min: Vec3::zeros(),
            edge: self.sight,
            dims,
        };
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let span = u64::MAX / (n.max(1) as u64 + 1);
        let agents = (0..n as u64)
            .map(|i| {
                let id = i * span;
                Agent {
                    id,
                    pos: [0, 1, 2]
                        .map(|a| rng.random_range(0.0..dims[a] as f32 * self.sight * 0.999)),
                    vel: [0, 1, 2].map(|_| rng.random_range(-0.1f32..0.1)),
                    health: if (i as usize) < infected {
                        Health::Infected
                    } else {
                        Health::Susceptible
                    },
                    since: 0,
                    next_id: id + 1,
                    end_id: id + span,
                }
            })
            .collect();
        (
            Epidemic {
                seed: seed ^ 0xe91d,
                ..self
            },
            grid,
            agents,
        )
    }

    fn distance2(a: &[f32; 3], b: &[f32; 3]) -> f32 {
        (0..3).map(|k| (a[k] - b[k]) * (a[k] - b[k])).sum()
    }

    /// Flocking: the new velocity of `me` from the neighbours within sight (visited in
    /// ascending id).
    fn steer(&self, me: &Agent, near: &[&Agent]) -> [f32; 3] {
        let mut v = me.vel;
        let (mut heading, mut push, mut n) = ([0.0f32; 3], [0.0f32; 3], 0u32);
        for o in near {
            let d2 = Self::distance2(&me.pos, &o.pos);
            if o.id == me.id || d2 > self.sight * self.sight {
                continue;
            }
            n += 1;
            for k in 0..3 {
                heading[k] += o.vel[k];
                if d2 < 0.25 * self.sight * self.sight && d2 > 0.0 {
                    push[k] += (me.pos[k] - o.pos[k]) / d2;
                }
            }
        }
        if n > 0 {
            for k in 0..3 {
                v[k] += 0.05 * (heading[k] / n as f32 - v[k]) + 0.002 * push[k];
            }
        }
        let speed = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        if speed > self.max_speed {
            v = v.map(|c| c * (self.max_speed / speed));
        }
        v
    }
}

impl CellModel for Epidemic {
    type State = Agent;
    type Event = EpidemicEvent;

    fn id(a: &Agent) -> BodyId {
        a.id
    }

    fn position(a: &Agent) -> [f32; 3] {
        a.pos
    }

    fn step_cell(
        &self,
        step: Step,
        grid: &Grid,
        nb: &Neighbourhood<'_, Agent>,
        out: &mut Vec<Agent>,
        events: &mut Vec<Event<EpidemicEvent>>,
    ) {
        let mut near: Vec<&Agent> = nb.iter().collect();
        near.sort_by_key(|a| a.id);
        let hi = grid.dims.map(|d| d as f32 * grid.edge);
        let first = out.len();
        for me in nb.own() {
            let mut rng = entity_rng(self.seed, me.id, step);
            let mut a = me.clone();
            a.since += 1;
            let event = |kind| Event {
                step,
                body: me.id,
                kind,
            };
            match me.health {
                Health::Susceptible => {
                    let r2 = self.contact_radius * self.contact_radius;
                    let k = near
                        .iter()
                        .filter(|o| {
                            o.health == Health::Infected && Self::distance2(&me.pos, &o.pos) <= r2
                        })
                        .count() as i32;
                    let p = 1.0 - (1.0 - self.beta).powi(k);
                    if k > 0 && rng.random::<f32>() < p {
                        a.health = Health::Infected;
                        a.since = 0;
                        events.push(event(EpidemicEvent::Infected));
                    }
                }
                Health::Infected => {
                    if rng.random::<f32>() < self.death_rate {
                        events.push(event(EpidemicEvent::Died));
                        continue;
                    }
                    if me.since >= self.recovery_steps {
                        a.health = Health::Recovered;
                        a.since = 0;
                        events.push(event(EpidemicEvent::Recovered));
                    }
                }
                Health::Recovered => {}
            }
            a.vel = self.steer(me, &near);
            for ((p, v), hi) in a.pos.iter_mut().zip(&mut a.vel).zip(hi) {
                *p += *v;
                if *p < 0.0 {
                    *p = -*p;
                    *v = -*v;
                }
                if *p >= hi {
                    *p = (2.0 * hi - *p).min(hi * 0.9999);
                    *v = -*v;
                }
            }
            let healthy = a.health != Health::Infected;
            if healthy && a.end_id - a.next_id >= 2 && rng.random::<f32>() < self.birth_rate {
                let mid = a.next_id + (a.end_id - a.next_id) / 2;
                let offset = [0, 1, 2].map(|_| rng.random_range(-0.05f32..0.05));
                let mut child = Agent {
                    id: mid,
                    pos: [0, 1, 2].map(|k| (a.pos[k] + offset[k]).clamp(0.0, hi[k] * 0.9999)),
                    vel: a.vel,
                    health: Health::Susceptible,
                    since: 0,
                    next_id: mid + 1,
                    end_id: a.end_id,
                };
                // The child is born where the parent was: within the parent's reach.
                if grid.cell_of(child.pos).is_none() {
                    child.pos = a.pos;
                }
                a.end_id = mid;
                events.push(Event {
                    step,
                    body: child.id,
                    kind: EpidemicEvent::Born,
                });
                out.push(child);
            }
            out.push(a);
        }
        // Children's ids lie above their parents' and below the next agent's range, but the
        // outputs must be sorted by id.
        out[first..].sort_by_key(|a| a.id);
    }

    fn may_affect(&self, reader: &Agent, other: &Agent) -> bool {
        Self::distance2(&reader.pos, &other.pos) <= self.sight * self.sight
    }

    fn hash_state(a: &Agent, h: &mut StateHash) {
        h.u64(a.id);
        for v in a.pos.iter().chain(&a.vel) {
            h.f32(*v);
        }
        h.u32(a.health as u32);
        h.u32(a.since);
        h.u64(a.next_id);
        h.u64(a.end_id);
    }

    fn fields(a: &Agent) -> Vec<(String, String)> {
        let mut f = Vec::new();
        for (name, v) in [("pos", a.pos), ("vel", a.vel)] {
            for (k, axis) in ["x", "y", "z"].iter().enumerate() {
                f.push((format!("{name}.{axis}"), exact_f32(v[k])));
            }
        }
        f.push(("health".into(), format!("{:?}", a.health)));
        f.push(("since".into(), a.since.to_string()));
        f.push(("next_id".into(), a.next_id.to_string()));
        f.push(("end_id".into(), a.end_id.to_string()));
        f
    }

    fn wire() -> Option<crate::model::Wire<Agent, EpidemicEvent>> {
        const KINDS: [EpidemicEvent; 5] = [
            EpidemicEvent::Infected,
            EpidemicEvent::Recovered,
            EpidemicEvent::Died,
            EpidemicEvent::Born,
            EpidemicEvent::LeftGrid,
        ];
        Some(crate::checkpoint::exact_wire(
            |e| KINDS.iter().position(|k| k == e).unwrap_or(KINDS.len()) as u64,
            |w| KINDS.get(usize::try_from(w).ok()?).copied(),
        ))
    }

    fn event_name(kind: &EpidemicEvent) -> String {
        match kind {
            EpidemicEvent::Infected => "infected",
            EpidemicEvent::Recovered => "recovered",
            EpidemicEvent::Died => "died",
            EpidemicEvent::Born => "born",
            EpidemicEvent::LeftGrid => "left-grid",
        }
        .into()
    }
}
