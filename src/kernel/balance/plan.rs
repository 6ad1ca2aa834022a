//! One balancing round's plan: the owner map being edited, the estimated loads and cell
//! costs, and the two moves of thesis §3.3.5 — cession to neighbours and the fight against
//! famine (SPEC.md §K13).

use super::territory::{
    border_distance, cut_change, face_neighbours, foreign_neighbours, neighbour_worlds,
    removal_keeps_whole,
};
use super::{Balancer, LoadLevel};
use crate::grid::Grid;
use crate::kernel::partition::{Partition, WorldId};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::BTreeSet;

/// One round's working state: the owner map being edited and the estimated loads.
/// Each cell's weight, the share of its world's load a plan assigns it: its bodies times one
/// plus the bodies in its 26 neighbour cells (a body's cost grows with the contacts it may
/// have).
pub(super) fn cell_weights(grid: &Grid, bodies: &[u32]) -> Vec<f64> {
    (0..grid.cell_count())
        .map(|c| {
            let own = bodies[c] as f64;
            let around: f64 = grid
                .neighbours(grid.coord(c))
                .map(|x| bodies[grid.index(x)] as f64)
                .sum();
            own * (1.0 + around)
        })
        .collect()
}

/// Packs the worlds into `workers` shares, most loaded world first into the least loaded
/// share (longest processing time first, as the threaded executor's ready set runs the
/// longest computation first): the load each worker will carry. With at least as many
/// workers as worlds each world is its own share.
pub(super) fn pack(est: &[f64], workers: usize, tie: &[u32]) -> Vec<usize> {
    if workers >= est.len() {
        return (0..est.len()).collect();
    }
    let mut order: Vec<usize> = (0..est.len()).collect();
    order.sort_by(|&a, &b| est[b].total_cmp(&est[a]).then(tie[a].cmp(&tie[b])));
    let mut load = vec![0.0f64; workers];
    let mut worker = vec![0; est.len()];
    for w in order {
        let k = (0..workers)
            .min_by(|&x, &y| load[x].total_cmp(&load[y]).then(x.cmp(&y)))
            .expect("at least one worker");
        worker[w] = k;
        load[k] += est[w];
    }
    worker
}

pub(super) struct Plan<'a> {
    balancer: &'a Balancer,
    grid: &'a Grid,
    pub(super) owner: Vec<WorldId>,
    pub(super) est: Vec<f64>,
    /// The worker share each world is packed into ([`pack`]); each world is its own share
    /// when there are as many workers as worlds.
    worker: Vec<usize>,
    /// Each worker share's load: the sum of its worlds' `est`.
    worker_load: Vec<f64>,
    cost: Vec<f64>,
    tie: Vec<u32>,
    world_tie: Vec<u32>,
    pub(super) mean: f64,
    pub(super) famished: Vec<WorldId>,
}

impl<'a> Plan<'a> {
    pub(super) fn new(
        balancer: &'a Balancer,
        grid: &'a Grid,
        part: &Partition,
        est: Vec<f64>,
        bodies: &[u32],
    ) -> Self {
        let owner = part.owners().to_vec();
        let cells = owner.len();
        let mut rng = ChaCha8Rng::seed_from_u64(
            balancer.config.seed ^ balancer.round.wrapping_mul(0x2545_F491_4F6C_DD1D),
        );
        let tie: Vec<u32> = (0..cells).map(|_| rng.random()).collect();
        let world_tie: Vec<u32> = (0..est.len()).map(|_| rng.random()).collect();
        // A cell's computing cost: its bodies times the bodies around it (the pairs its
        // broad phase checks), scaled so a world's cells sum to the world's load.
        let weight = cell_weights(grid, bodies);
        let mut sum = vec![0.0; est.len()];
        let mut count = vec![0usize; est.len()];
        for c in 0..cells {
            sum[owner[c] as usize] += weight[c];
            count[owner[c] as usize] += 1;
        }
        let cost = (0..cells)
            .map(|c| {
                let w = owner[c] as usize;
                if sum[w] > 0.0 {
                    est[w] * weight[c] / sum[w]
                } else {
                    est[w] / count[w] as f64
                }
            })
            .collect();
        let sharers = balancer.sharers(est.len());
        let mean = est.iter().sum::<f64>() / sharers as f64;
        let worker = pack(&est, sharers, &world_tie);
        let mut worker_load = vec![0.0; sharers];
        for (w, &k) in worker.iter().enumerate() {
            worker_load[k] += est[w];
        }
        Plan {
            balancer,
            grid,
            owner,
            est,
            worker,
            worker_load,
            cost,
            tie,
            world_tie,
            mean,
            famished: Vec::new(),
        }
    }

    /// World `w`'s level: that of its worker share's load.
    fn level(&self, w: WorldId) -> LoadLevel {
        self.balancer.level(self.share_load(w), self.mean)
    }

    /// Every world's level, before anything moves.
    pub(super) fn levels(&self) -> Vec<LoadLevel> {
        (0..self.est.len() as WorldId)
            .map(|w| self.level(w))
            .collect()
    }

    /// The load of world `w`'s worker share.
    fn share_load(&self, w: WorldId) -> f64 {
        self.worker_load[self.worker[w as usize]]
    }

    /// Whether worlds share workers (fewer workers than worlds, SPEC.md §K13).
    fn packing(&self) -> bool {
        self.worker_load.len() < self.est.len()
    }

    fn cooling(&self, c: u32) -> bool {
        let r = self.balancer.moved_round[c as usize];
        r != u64::MAX && self.balancer.round < r + self.balancer.config.cooldown
    }

    fn give(&mut self, c: u32, to: WorldId) {
        let from = self.owner[c as usize];
        let cost = self.cost[c as usize];
        self.est[from as usize] -= cost;
        self.est[to as usize] += cost;
        self.worker_load[self.worker[from as usize]] -= cost;
        self.worker_load[self.worker[to as usize]] += cost;
        self.owner[c as usize] = to;
    }

    fn cells_of(&self, w: WorldId) -> usize {
        self.owner.iter().filter(|&&o| o == w).count()
    }

    /// Moving `c` away from its owner keeps the owner's territory in as few pieces and
    /// non-empty.
    fn keeps_owner_whole(&self, c: u32) -> bool {
        removal_keeps_whole(self.grid, &self.owner, c)
    }

    /// Cession (§3.3.5): every high or overloaded world, most loaded first, gives cells to
    /// its less-loaded face neighbours. When worlds share workers, levels are those of the
    /// worker shares, a world gives only to worlds of another share, and a high share gives
    /// to any share below the mean (with two shares, one 10 % above the mean has the other
    /// 10 % below it: never underloaded, yet the run waits for the heavier).
    pub(super) fn cede(&mut self) {
        let n = self.est.len() as WorldId;
        let mut givers: Vec<WorldId> = (0..n)
            .filter(|&w| self.level(w) >= LoadLevel::High)
            .collect();
        givers.sort_by(|&a, &b| {
            self.est[b as usize]
                .total_cmp(&self.est[a as usize])
                .then(self.world_tie[a as usize].cmp(&self.world_tie[b as usize]))
        });
        for g in givers {
            let level = self.level(g);
            if level < LoadLevel::High {
                continue;
            }
            let mut recipients: Vec<(usize, f64, usize, u32, WorldId)> =
                neighbour_worlds(self.grid, &self.owner, g)
                    .into_iter()
                    .filter(|&r| {
                        self.worker[r as usize] != self.worker[g as usize]
                            && self.share_load(r) < self.mean
                            && (level == LoadLevel::Overloaded
                                || self.packing()
                                || self.level(r) == LoadLevel::Underloaded)
                    })
                    .map(|r| {
                        (
                            neighbour_worlds(self.grid, &self.owner, r).len(),
                            self.est[r as usize],
                            self.cells_of(r),
                            self.world_tie[r as usize],
                            r,
                        )
                    })
                    .collect();
            recipients.sort_by(|a, b| {
                a.0.cmp(&b.0)
                    .then(a.1.total_cmp(&b.1))
                    .then(a.2.cmp(&b.2))
                    .then(a.3.cmp(&b.3))
            });
            for &(.., r) in &recipients {
                self.give_to(g, r);
            }
        }
    }

    /// Gives cells of `g` face-adjacent to `r`'s territory, best first, until `r` reaches
    /// the mean, `g` falls to it, or `max_cells` moved.
    fn give_to(&mut self, g: WorldId, r: WorldId) {
        // The candidates: `g`'s cells on its border with `r`, in ascending order. Only the
        // given cell's face neighbours can join it, so it is kept up to date instead of
        // scanning the grid for every cell given (a round moving ~250 of 4,608 cells took
        // ~10 ms that way, with every worker waiting).
        let mut frontier: BTreeSet<u32> = (0..self.owner.len() as u32)
            .filter(|&c| self.owner[c as usize] == g && self.touches(c, r))
            .collect();
        for _ in 0..self.balancer.config.max_cells {
            let (eg, er) = (self.share_load(g), self.share_load(r));
            if eg - self.mean <= 0.0 || self.mean - er <= 0.0 {
                return;
            }
            // Never so much that the recipient ends above the giver (no bouncing back).
            let fits = (eg - er) / 2.0;
            let mut candidates: Vec<(usize, i64, f64, i32, u32, u32)> = frontier
                .iter()
                .copied()
                .filter(|&c| !self.cooling(c) && self.cost[c as usize] <= fits)
                .map(|c| {
                    (
                        foreign_neighbours(self.grid, &self.owner, c),
                        cut_change(self.grid, &self.owner, c, r),
                        self.cost[c as usize],
                        border_distance(self.grid, c),
                        self.tie[c as usize],
                        c,
                    )
                })
                .collect();
            // Most foreign neighbours, then the smallest perimeter of both territories, the
            // most cost given, the nearest to the scene border, the seeded tie-break.
            candidates.sort_by(|a, b| {
                b.0.cmp(&a.0)
                    .then(a.1.cmp(&b.1))
                    .then(b.2.total_cmp(&a.2))
                    .then(a.3.cmp(&b.3))
                    .then(a.4.cmp(&b.4))
            });
            let Some(c) = candidates
                .iter()
                .map(|x| x.5)
                .find(|&c| self.keeps_owner_whole(c))
            else {
                return;
            };
            self.give(c, r);
            frontier.remove(&c);
            frontier.extend(face_neighbours(self.grid, c).filter(|&x| self.owner[x as usize] == g));
        }
    }

    /// Whether cell `c` has a face neighbour owned by `r`.
    fn touches(&self, c: u32, r: WorldId) -> bool {
        face_neighbours(self.grid, c).any(|x| self.owner[x as usize] == r)
    }

    /// Famine (§3.3.5): every world still underloaded after cession, least loaded first,
    /// hands its territory to its neighbours and takes a connected part of the most loaded
    /// world's.
    pub(super) fn fight_famine(&mut self) {
        if self.balancer.sharers(self.est.len()) < self.est.len() {
            // Fewer workers than worlds: idle worlds are expected, not starving.
            return;
        }
        let n = self.est.len() as WorldId;
        let mut hungry: Vec<WorldId> = (0..n)
            .filter(|&w| self.level(w) == LoadLevel::Underloaded)
            .collect();
        hungry.sort_by(|&a, &b| {
            self.est[a as usize]
                .total_cmp(&self.est[b as usize])
                .then(self.world_tie[a as usize].cmp(&self.world_tie[b as usize]))
        });
        for w in hungry {
            if self.level(w) != LoadLevel::Underloaded {
                continue;
            }
            let richest = (0..n).filter(|&m| m != w).max_by(|&a, &b| {
                self.est[a as usize]
                    .total_cmp(&self.est[b as usize])
                    .then(b.cmp(&a))
            });
            let Some(m) = richest.filter(|&m| self.level(m) >= LoadLevel::High) else {
                return;
            };
            let target = self.mean.min(self.est[m as usize] - self.mean);
            if self.hand_over(w) {
                self.take_part(w, m, target);
                self.famished.push(w);
            }
        }
    }

    /// Gives every cell of `w` to a face-neighbouring world (the least loaded), in waves
    /// from its border inwards. Returns false (and changes nothing) if `w` has no neighbour.
    fn hand_over(&mut self, w: WorldId) -> bool {
        let mine: Vec<u32> = (0..self.owner.len() as u32)
            .filter(|&c| self.owner[c as usize] == w)
            .collect();
        if !mine.is_empty() && neighbour_worlds(self.grid, &self.owner, w).is_empty() {
            return false;
        }
        loop {
            let mut progress = false;
            for &c in &mine {
                if self.owner[c as usize] != w {
                    continue;
                }
                let to = face_neighbours(self.grid, c)
                    .map(|x| self.owner[x as usize])
                    .filter(|&o| o != w)
                    .min_by(|&a, &b| {
                        self.est[a as usize]
                            .total_cmp(&self.est[b as usize])
                            .then(a.cmp(&b))
                    });
                if let Some(to) = to {
                    self.give(c, to);
                    progress = true;
                }
            }
            if !progress {
                return true;
            }
        }
    }

    /// `w` takes a face-connected region of `m`'s cells, costliest first, keeping `m` in
    /// as few pieces, until it holds `target` of cost or `max_cells` cells.
    fn take_part(&mut self, w: WorldId, m: WorldId, target: f64) {
        let mut taken = 0.0;
        let mut region: Vec<u32> = Vec::new();
        while taken < target && region.len() < self.balancer.config.max_cells {
            let mut candidates: Vec<(f64, i32, u32, u32)> = (0..self.owner.len() as u32)
                .filter(|&c| {
                    self.owner[c as usize] == m
                        && !self.cooling(c)
                        && (region.is_empty()
                            || face_neighbours(self.grid, c).any(|x| self.owner[x as usize] == w))
                })
                .map(|c| {
                    (
                        self.cost[c as usize],
                        border_distance(self.grid, c),
                        self.tie[c as usize],
                        c,
                    )
                })
                .collect();
            candidates.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
            let Some(c) = candidates
                .iter()
                .map(|x| x.3)
                .find(|&c| self.keeps_owner_whole(c))
            else {
                return;
            };
            taken += self.cost[c as usize];
            self.give(c, w);
            region.push(c);
        }
    }
}
