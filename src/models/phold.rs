//! A PHOLD-like synthetic workload for rollback-granularity studies: the knobs PDES
//! researchers know, mapped onto cells.
//!
//! PHOLD (Fujimoto, 1990) keeps a fixed population of jobs; processing a job costs a
//! configurable grain of computation and schedules it at a random logical process, a
//! *remote* one with a given probability. Here a logical process is a cell, a job is an
//! entity, and every step processes every job once:
//!
//! - **entities per cell** ([`PholdParams::per_cell`]): the population's density;
//! - **remote fraction** ([`PholdParams::remote`]): the probability that a job moves to a
//!   random neighbouring cell this step (else it stays in its cell) — migration between
//!   cells, hence messages between worlds when the cells belong to different ones;
//! - **compute grain** ([`PholdParams::grain`]): rounds of integer mixing per job and step;
//! - **coupling** ([`PholdParams::coupling`]): a job's new value mixes in the values of the
//!   jobs within this distance (0: jobs are independent, as in PHOLD; up to one cell edge:
//!   a straggler's change spreads through the neighbourhood, as in a physical model).
//!
//! Unlike PHOLD, whose events are instantaneous and asynchronous, every job here is
//! processed at every step (a time-stepped workload): one committed entity-step is the
//! counterpart of one committed PHOLD event.

use super::random::entity_rng;
use crate::frame::{Event, LeftGrid};
use crate::grid::Grid;
use crate::hash::StateHash;
use crate::math::Vec3;
use crate::model::{exact_f32, BodyId, CellModel, Neighbourhood, Step};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// One job.
#[derive(Clone, Debug, PartialEq)]
pub struct Job {
    /// Id.
    pub id: BodyId,
    /// Position (cell edge 1).
    pub pos: [f32; 3],
    /// The job's value, mixed every step.
    pub value: u64,
}

/// The model's knobs.
#[derive(Clone, Debug, PartialEq)]
pub struct PholdParams {
    /// Grid size in cells (cell edge 1 m).
    pub dims: [i32; 3],
    /// Jobs per cell at step 0.
    pub per_cell: usize,
    /// Probability per step that a job moves to a random neighbouring cell.
    pub remote: f32,
    /// Rounds of integer mixing per job and step.
    pub grain: u32,
    /// Distance within which jobs read each other's values (0 to 1).
    pub coupling: f32,
    /// Seed of the initial placement and of every job's per-step randomness.
    pub seed: u64,
}

impl Default for PholdParams {
    fn default() -> Self {
        PholdParams {
            dims: [16, 16, 4],
            per_cell: 4,
            remote: 0.1,
            grain: 64,
            coupling: 0.5,
            seed: 1,
        }
    }
}

/// The PHOLD-like model ([module docs](self)).
#[derive(Clone, Debug, PartialEq)]
pub struct Phold {
    /// Its knobs.
    pub params: PholdParams,
}

/// PHOLD raises no events of its own; jobs never leave the grid.
pub type PholdEvent = LeftGrid;

impl Phold {
    /// The model, its grid and `per_cell` jobs in every cell at random (seeded) positions.
    pub fn scene(params: PholdParams) -> (Self, Grid, Vec<Job>) {
        let grid = Grid {
            min: Vec3::zeros(),
            edge: 1.0,
            dims: params.dims,
        };
        let mut rng = ChaCha8Rng::seed_from_u64(params.seed);
        let mut jobs = Vec::with_capacity(grid.cell_count() * params.per_cell);
        for cell in 0..grid.cell_count() {
            let c = grid.coord(cell);
            for _ in 0..params.per_cell {
                let id = jobs.len() as u64;
                let at = [c.x, c.y, c.z].map(|v| v as f32 + rng.random_range(0.05f32..0.95));
                jobs.push(Job {
                    id,
                    pos: at,
                    value: rng.random(),
                });
            }
        }
        (Phold { params }, grid, jobs)
    }

    fn mix(mut x: u64, rounds: u32) -> u64 {
        for _ in 0..rounds {
            x ^= x >> 33;
            x = x.wrapping_mul(0xff51_afd7_ed55_8ccd);
            x ^= x >> 29;
        }
        x
    }
}

impl CellModel for Phold {
    type State = Job;
    type Event = PholdEvent;

    fn id(j: &Job) -> BodyId {
        j.id
    }

    fn position(j: &Job) -> [f32; 3] {
        j.pos
    }

    fn wire() -> Option<crate::model::Wire<Job, PholdEvent>> {
        Some(crate::checkpoint::exact_wire(
            |_| 0,
            |w| (w == 0).then_some(crate::frame::LeftGrid),
        ))
    }

    fn step_cell(
        &self,
        step: Step,
        grid: &Grid,
        nb: &Neighbourhood<'_, Job>,
        out: &mut Vec<Job>,
        _events: &mut Vec<Event<PholdEvent>>,
    ) {
        let p = &self.params;
        let c = nb.centre;
        let r2 = p.coupling * p.coupling;
        for me in nb.own() {
            let mut value = me.value;
            if p.coupling > 0.0 {
                // Slots in order, each sorted by id: a fixed order whatever computes the cell.
                for o in nb.iter() {
                    let d2: f32 = (0..3).map(|k| (me.pos[k] - o.pos[k]).powi(2)).sum();
                    if o.id != me.id && d2 <= r2 {
                        value = value.rotate_left(7) ^ o.value;
                    }
                }
            }
            value = Self::mix(value ^ step, p.grain);
            let mut rng = entity_rng(p.seed, me.id, step);
            let mut cell = [c.x, c.y, c.z];
            if rng.random::<f32>() < p.remote {
                let k = rng.random_range(0..26usize);
                let k = if k >= 13 { k + 1 } else { k };
                let off = Neighbourhood::<Job>::offset(k);
                for a in 0..3 {
                    // Off the grid's faces, the job stays on that axis.
                    let to = cell[a] + off[a];
                    if to >= 0 && to < grid.dims[a] {
                        cell[a] = to;
                    }
                }
            }
            let pos = cell.map(|v| v as f32 + rng.random_range(0.05f32..0.95));
            out.push(Job {
                id: me.id,
                pos,
                value,
            });
        }
    }

    fn may_affect(&self, reader: &Job, other: &Job) -> bool {
        let d2: f32 = (0..3).map(|k| (reader.pos[k] - other.pos[k]).powi(2)).sum();
        self.params.coupling > 0.0 && d2 <= self.params.coupling * self.params.coupling
    }

    fn hash_state(j: &Job, h: &mut StateHash) {
        h.u64(j.id);
        for v in j.pos {
            h.f32(v);
        }
        h.u64(j.value);
    }

    fn fields(j: &Job) -> Vec<(String, String)> {
        vec![
            ("pos.x".into(), exact_f32(j.pos[0])),
            ("pos.y".into(), exact_f32(j.pos[1])),
            ("pos.z".into(), exact_f32(j.pos[2])),
            ("value".into(), format!("0x{:016x}", j.value)),
        ]
    }
}
