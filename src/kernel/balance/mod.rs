//! Dynamic load balancing by cell cession (thesis §3.3; SPEC.md §K13).
//!
//! Pure and deterministic: a [`Balancer`] is handed, at a step every world has committed,
//! each world's load over the last period and the body count of every cell, and returns the
//! new owner map. It reads no clock: executors measure (or, to replay exactly, count) the
//! loads. Committed results never depend on its decisions, because a cell only changes owner
//! where its state is final and any partition computes the same bits (the locality
//! contract).
//!
//! A round: smooth the loads (exponential), classify each world (underloaded, normal, high,
//! overloaded against the mean), let every high or overloaded world give cells to
//! less-loaded face neighbours (cells chosen by the thesis's criteria), then let every
//! world still underloaded and unable to get work from its neighbours fight famine: hand its
//! territory to its neighbours and take a connected part of the most loaded world's.

mod plan;
pub mod territory;

use super::config::{BalanceConfig, LoadSource, MAX_BACKOFF};
use super::counters::BalanceCounters;
use super::partition::{Partition, WorldId};
use crate::grid::Grid;
use crate::model::Step;
use plan::Plan;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

/// A world's load level against the mean (thesis §3.3.1).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum LoadLevel {
    /// Below `underloaded × mean`: asks its neighbours for cells.
    Underloaded,
    /// Between the thresholds.
    Normal,
    /// Above `high × mean`: gives cells to underloaded neighbours.
    High,
    /// Above `overloaded × mean`: gives cells to any less-loaded neighbour.
    Overloaded,
}

/// What one balancing round saw and did.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RoundRecord {
    /// The committed step at which the cells changed owner.
    pub step: Step,
    /// Each world's measured load per committed step over the period.
    pub loads: Vec<f64>,
    /// Max over mean of `loads` (1 when nothing was measured).
    pub imbalance: f64,
    /// Each world's mean advance over GVT (LVT − GVT after its actions) during the period:
    /// the world holding GVT back has the smallest. Observed, not used in decisions.
    pub leads: Vec<f64>,
    /// Each world's bodies at the round's step, before cells moved.
    pub bodies: Vec<u64>,
    /// Each world's level from its smoothed load (its worker share's when worlds share
    /// workers, SPEC.md §K13), before cells moved.
    pub levels: Vec<LoadLevel>,
    /// Cells that changed owner.
    pub cells_moved: u64,
    /// Worlds that fought famine.
    pub famines: u64,
    /// Which worlds fought famine, in the order they did.
    pub famished: Vec<WorldId>,
    /// The owner of every cell after the round (in memory only: not serialised).
    #[serde(skip)]
    pub owners: Vec<WorldId>,
}

/// The balancing state of a run: smoothed loads, per-cell cooldowns, history.
#[derive(Clone, Debug)]
pub struct Balancer {
    config: BalanceConfig,
    smoothed: Option<Vec<f64>>,
    moved_round: Vec<u64>,
    round: u64,
    history: Vec<RoundRecord>,
    /// Steps from the last round to the next ([`BalanceConfig::backoff`]).
    interval: u64,
}

/// `max / mean` of `loads` (1 if the mean is not positive).
pub fn imbalance(loads: &[f64]) -> f64 {
    let mean = loads.iter().sum::<f64>() / loads.len().max(1) as f64;
    let max = loads.iter().copied().fold(0.0, f64::max);
    if mean > 0.0 {
        max / mean
    } else {
        1.0
    }
}

impl Balancer {
    /// A balancer over a grid of `cells` cells.
    pub fn new(config: &BalanceConfig, cells: usize) -> Self {
        Balancer {
            config: config.clone(),
            smoothed: None,
            moved_round: vec![u64::MAX; cells],
            round: 0,
            history: Vec::new(),
            interval: config.period,
        }
    }

    /// Whether balancing is on.
    pub fn enabled(&self) -> bool {
        self.config.enabled
    }

    /// Whether an opening round is due at step 0 (balancing on, with
    /// [`BalanceConfig::opening`]).
    pub fn opens(&self) -> bool {
        self.config.enabled && self.config.opening
    }

    /// The next committed step at which a round happens after `step`.
    pub fn next_round_after(&self, step: Step) -> Step {
        if !self.config.enabled {
            return Step::MAX;
        }
        match self.history.last() {
            Some(last) if self.config.backoff => (last.step + self.interval).max(step + 1),
            _ => (step / self.config.period + 1) * self.config.period,
        }
    }

    /// The opening round, at step 0 before anything is computed (SPEC.md §K13). Nothing has
    /// been measured yet, so each world's load is estimated from its bodies: the sum of its
    /// cells' weights (a cell's bodies times one plus its neighbourhood's, as a plan weighs
    /// cells). The estimate is not a measurement: it seeds no smoothing and starts no
    /// backoff, so the first measured round comes one period later whatever it did.
    pub fn opening_round(
        &mut self,
        grid: &Grid,
        part: &Partition,
        bodies: &[u32],
    ) -> Option<Partition> {
        let n = part.worlds();
        let mut estimate = vec![0.0; n];
        for (c, w) in plan::cell_weights(grid, bodies).into_iter().enumerate() {
            estimate[part.owner(c as u32) as usize] += w;
        }
        let moved = self.round(grid, part, &estimate, &vec![0.0; n], bodies, 0);
        self.smoothed = None;
        self.interval = self.config.period;
        moved
    }

    /// Where loads come from.
    pub fn load_source(&self) -> LoadSource {
        self.config.load
    }

    /// How many shares the total load is divided into for `worlds` worlds: the configured
    /// workers if between 1 and `worlds`, else `worlds` (the thesis's mean).
    pub fn sharers(&self, worlds: usize) -> usize {
        match self.config.workers {
            w if w >= 1 && w < worlds => w,
            _ => worlds.max(1),
        }
    }

    /// The level of `load` against `mean`.
    pub fn level(&self, load: f64, mean: f64) -> LoadLevel {
        let c = &self.config;
        if load > c.overloaded * mean {
            LoadLevel::Overloaded
        } else if load > c.high * mean {
            LoadLevel::High
        } else if load < c.underloaded * mean {
            LoadLevel::Underloaded
        } else {
            LoadLevel::Normal
        }
    }

    /// The rounds so far.
    pub fn history(&self) -> &[RoundRecord] {
        &self.history
    }

    /// Rounds, cells moved and famines so far, with `imbalance` (the executor's run-wide
    /// max/mean of the worlds' summed loads, see [`imbalance`]).
    pub fn counters(&self, imbalance: f64) -> BalanceCounters {
        BalanceCounters {
            rounds: self.history.len() as u64,
            cells_moved: self.history.iter().map(|r| r.cells_moved).sum(),
            famines: self.history.iter().map(|r| r.famines).sum(),
            imbalance,
        }
    }

    /// One round at committed step `step`: `measured` is each world's load per committed
    /// step since the last round (ignored for [`LoadSource::Seeded`]), `leads` each world's
    /// mean advance over GVT meanwhile (recorded only), `bodies` the body count of every
    /// cell at `step`. Returns the new partition if a cell moved.
    pub fn round(
        &mut self,
        grid: &Grid,
        part: &Partition,
        measured: &[f64],
        leads: &[f64],
        bodies: &[u32],
        step: Step,
    ) -> Option<Partition> {
        let n = part.worlds();
        let loads: Vec<f64> = match self.config.load {
            LoadSource::Seeded(seed) => {
                let mut rng = ChaCha8Rng::seed_from_u64(seed ^ self.round.wrapping_mul(0x9E37));
                (0..n).map(|_| rng.random::<f64>().powi(3)).collect()
            }
            _ => measured.to_vec(),
        };
        let a = self.config.smoothing;
        let est: Vec<f64> = match &self.smoothed {
            Some(s) => s
                .iter()
                .zip(&loads)
                .map(|(s, m)| a * m + (1.0 - a) * s)
                .collect(),
            None => loads.clone(),
        };
        let mut world_bodies = vec![0u64; n];
        for (c, &b) in bodies.iter().enumerate() {
            world_bodies[part.owner(c as u32) as usize] += b as u64;
        }
        let mut plan = Plan::new(self, grid, part, est, bodies);
        let levels = plan.levels();
        if plan.mean > 0.0 {
            plan.cede();
            plan.fight_famine();
        }
        let Plan {
            owner,
            est,
            famished,
            ..
        } = plan;
        let mut moved = 0;
        for (c, (&new, &old)) in owner.iter().zip(part.owners()).enumerate() {
            if new != old {
                self.moved_round[c] = self.round;
                moved += 1;
            }
        }
        // Smoothing averages measurements of one owner map. After cells moved, the next
        // measurement (of the new map) replaces the estimate instead of being averaged with
        // this round's projection: the projection cannot foresee loads that grow unevenly
        // (a pile landing in one territory while empty worlds' bookkeeping stays flat), and
        // halving every correction left the busiest world ~10 % above its share (docs/performance.md,
        // Load balancing). Moved cells still cool down, so this does not make them bounce.
        self.smoothed = (moved == 0).then_some(est);
        self.history.push(RoundRecord {
            step,
            imbalance: imbalance(&loads),
            loads,
            leads: leads.to_vec(),
            bodies: world_bodies,
            levels,
            cells_moved: moved,
            famines: famished.len() as u64,
            famished,
            owners: owner.clone(),
        });
        self.round += 1;
        let period = self.config.period;
        self.interval = if moved > 0 {
            period
        } else {
            (self.interval * 2).min(period * MAX_BACKOFF)
        };
        (moved > 0).then(|| Partition::from_owners(grid, n, owner))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Vec3;

    /// 8×1×1 cells, two worlds of four cells each, one body per cell of world 0.
    fn row() -> (Grid, Partition, Vec<u32>) {
        let g = Grid::covering(Vec3::zeros(), Vec3::new(8.0, 1.0, 1.0), 1.0);
        let p = Partition::blocks(&g, 2);
        let bodies = (0..8).map(|c| (c < 4) as u32).collect();
        (g, p, bodies)
    }

    /// A balancer with `config` after one round at `step` in which world 0 measured all the
    /// load on `row()` and gave cells away; returns it with the new partition.
    fn after_first_move(config: &BalanceConfig, step: Step) -> (Balancer, Partition) {
        let (g, p, bodies) = row();
        let mut b = Balancer::new(config, g.cell_count());
        let p1 = b
            .round(&g, &p, &[4.0, 0.0], &[0.0; 2], &bodies, step)
            .expect("cells move");
        (b, p1)
    }

    #[test]
    fn levels_follow_the_thresholds_against_the_mean() {
        let b = Balancer::new(&BalanceConfig::on(), 1);
        assert_eq!(b.level(0.5, 1.0), LoadLevel::Underloaded);
        assert_eq!(b.level(1.0, 1.0), LoadLevel::Normal);
        assert_eq!(b.level(1.3, 1.0), LoadLevel::High);
        assert_eq!(b.level(2.0, 1.0), LoadLevel::Overloaded);
    }

    #[test]
    fn an_overloaded_world_gives_its_border_cells_to_its_neighbour_without_overshooting() {
        let (g, p, bodies) = row();
        let mut b = Balancer::new(&BalanceConfig::on(), g.cell_count());
        let new = b
            .round(&g, &p, &[4.0, 0.0], &[0.0; 2], &bodies, 10)
            .expect("cells move");
        // The giver's cells next to the border go first, and the giver keeps at least as
        // much load as the recipient gets.
        assert_eq!(new.owners(), &[0, 0, 1, 1, 1, 1, 1, 1]);
        let r = &b.history()[0];
        assert_eq!((r.step, r.cells_moved, r.famines), (10, 2, 0));
        assert_eq!(r.bodies, vec![4, 0]);
        assert_eq!(
            r.levels,
            vec![LoadLevel::Overloaded, LoadLevel::Underloaded]
        );
        assert_eq!(r.imbalance, 2.0);
    }

    #[test]
    fn balanced_loads_move_nothing_and_cooldown_holds_moved_cells() {
        let (g, p, bodies) = row();
        let mut b = Balancer::new(&BalanceConfig::on(), g.cell_count());
        assert!(b
            .round(&g, &p, &[1.0, 1.1], &[0.0; 2], &bodies, 5)
            .is_none());
        let config = BalanceConfig {
            cooldown: 5,
            smoothing: 1.0,
            ..BalanceConfig::on()
        };
        let (mut b, p1) = after_first_move(&config, 5);
        // World 1 now measures all the load, but the moved cells are cooling down.
        let p2 = b.round(&g, &p1, &[0.0, 4.0], &[0.0; 2], &bodies, 10);
        let moved_back = p2.is_some_and(|p2| p2.owner(3) == 0 || p2.owner(2) == 0);
        assert!(!moved_back, "a cell bounced back during its cooldown");
    }

    #[test]
    fn after_cells_moved_the_next_round_takes_its_measurement_unsmoothed() {
        let (g, p, bodies) = row();
        let config = BalanceConfig {
            smoothing: 0.5,
            cooldown: 0,
            ..BalanceConfig::on()
        };
        let (mut b, p1) = after_first_move(&config, 10);
        // The move projects [2, 2]; the new map measures [3.2, 0.8]. Averaged with the
        // projection that would be [2.6, 1.4], merely high (above 1.05 × 2); taken as
        // measured, world 0 is overloaded (above 1.5 × 2).
        b.round(&g, &p1, &[3.2, 0.8], &[0.0; 2], &bodies, 20);
        assert_eq!(b.history()[1].levels[0], LoadLevel::Overloaded);
        // Without a move in between, measurements are smoothed as before: [2, 2] (nothing
        // moves) then [3.2, 0.8] average to [2.6, 1.4].
        let mut b = Balancer::new(&config, g.cell_count());
        assert!(b
            .round(&g, &p, &[2.0, 2.0], &[0.0; 2], &bodies, 10)
            .is_none());
        b.round(&g, &p, &[3.2, 0.8], &[0.0; 2], &bodies, 20);
        assert_eq!(b.history()[1].levels[0], LoadLevel::High, "2.6 against 2");
    }

    #[test]
    fn rounds_back_off_while_nothing_moves_and_return_to_the_period_after_a_move() {
        let (g, p, bodies) = row();
        let config = BalanceConfig {
            period: 10,
            smoothing: 1.0,
            cooldown: 0,
            ..BalanceConfig::on()
        };
        // A round with equal loads moves nothing; returns the next round's step.
        let idle = |b: &mut Balancer, step: Step| {
            assert!(b
                .round(&g, &p, &[1.0, 1.0], &[0.0; 2], &bodies, step)
                .is_none());
            b.next_round_after(step)
        };
        let mut b = Balancer::new(&config, g.cell_count());
        assert_eq!(b.next_round_after(0), 10);
        // The interval doubles after each idle round (20, 40), then stays at the cap.
        assert_eq!(idle(&mut b, 10), 30);
        assert_eq!(idle(&mut b, 30), 70);
        assert_eq!(idle(&mut b, 70), 70 + 10 * MAX_BACKOFF, "capped");
        let moved = b.round(&g, &p, &[4.0, 0.0], &[0.0; 2], &bodies, 110);
        assert!(moved.is_some(), "an overloaded world gives cells");
        assert_eq!(
            b.next_round_after(110),
            120,
            "back to the period after a move"
        );
        let fixed = BalanceConfig {
            backoff: false,
            ..config
        };
        let mut fixed = Balancer::new(&fixed, g.cell_count());
        assert_eq!(idle(&mut fixed, 10), 20, "without backoff: every period");
    }

    #[test]
    fn a_starving_world_far_from_the_load_hands_over_and_takes_part_of_it() {
        let g = Grid::covering(Vec3::zeros(), Vec3::new(9.0, 1.0, 1.0), 1.0);
        let p = Partition::blocks(&g, 3);
        let bodies: Vec<u32> = (0..9).map(|c| (c < 3) as u32 * 2).collect();
        let mut b = Balancer::new(&BalanceConfig::on(), g.cell_count());
        let new = b
            .round(&g, &p, &[3.0, 0.0, 0.0], &[0.0; 3], &bodies, 20)
            .expect("moves");
        let r = &b.history()[0];
        assert!(r.famished.contains(&2), "world 2 starves: {r:?}");
        assert!(
            new.cells_of(2).iter().all(|&c| c < 3),
            "world 2 now owns part of world 0's old, loaded territory: {:?}",
            new.owners()
        );
    }

    #[test]
    fn with_fewer_workers_than_worlds_the_load_is_shared_between_as_many_territories() {
        // The same starving-world scene, shared between 2 workers: world 0 gives its
        // neighbour part of the load, and world 2, far away, stays idle (no famine).
        let g = Grid::covering(Vec3::zeros(), Vec3::new(9.0, 1.0, 1.0), 1.0);
        let p = Partition::blocks(&g, 3);
        let bodies: Vec<u32> = (0..9).map(|c| (c < 3) as u32 * 2).collect();
        let config = BalanceConfig {
            workers: 2,
            ..BalanceConfig::on()
        };
        let mut b = Balancer::new(&config, g.cell_count());
        assert_eq!(b.sharers(3), 2);
        let new = b
            .round(&g, &p, &[3.0, 0.0, 0.0], &[0.0; 3], &bodies, 20)
            .expect("moves");
        let r = &b.history()[0];
        assert_eq!(r.famines, 0);
        assert_eq!(
            r.levels[0],
            LoadLevel::Overloaded,
            "3 against a share of 1.5"
        );
        assert!(new.cells_of(1).iter().any(|&c| c < 3), "{:?}", new.owners());
        assert_eq!(new.cells_of(2), p.cells_of(2), "world 2 stays as it was");
        // More workers than worlds, or 0, mean one share per world.
        let b = Balancer::new(&BalanceConfig::on(), g.cell_count());
        assert_eq!(b.sharers(3), 3);
    }

    #[test]
    fn worlds_pack_into_worker_shares_most_loaded_first_into_the_lightest() {
        let tie = [0, 0, 0, 0];
        assert_eq!(plan::pack(&[5.0, 4.0, 1.0, 0.1], 2, &tie), vec![0, 1, 1, 0]);
        assert_eq!(
            plan::pack(&[5.0, 4.0, 1.0], 3, &tie),
            vec![0, 1, 2],
            "own shares"
        );
        assert_eq!(plan::pack(&[5.0, 4.0], 8, &tie), vec![0, 1], "more workers");
    }

    #[test]
    fn a_share_above_the_mean_gives_to_the_other_share_though_not_underloaded() {
        // A row of 40 cells, one body each: world 0 owns 0..20, world 1 20..39, world 2
        // cell 39. Two workers pack world 0 (4.6) against worlds 1 + 2 (4.4 + 1.0 = 5.4):
        // the second share is high (above 1.05 × 5), the first only normal (0.92 × 5).
        let g = Grid::covering(Vec3::zeros(), Vec3::new(40.0, 1.0, 1.0), 1.0);
        let owners: Vec<WorldId> = (0..40)
            .map(|c| (c >= 20) as u32 + (c == 39) as u32)
            .collect();
        let p = Partition::from_owners(&g, 3, owners);
        let bodies = vec![1u32; 40];
        let config = BalanceConfig {
            workers: 2,
            smoothing: 1.0,
            ..BalanceConfig::on()
        };
        let mut b = Balancer::new(&config, g.cell_count());
        let new = b
            .round(&g, &p, &[4.6, 4.4, 1.0], &[0.0; 3], &bodies, 20)
            .expect("the high share gives");
        let r = &b.history()[0];
        assert_eq!(
            r.levels,
            vec![LoadLevel::Normal, LoadLevel::High, LoadLevel::High]
        );
        assert_eq!(new.owner(20), 0, "world 1's border cell goes to world 0");
        assert_eq!(
            r.cells_moved, 1,
            "one cell (0.23) brings the shares within 0.17 of 5"
        );
        // One share per world (the thesis's levels): world 0 is not underloaded, so world 1
        // gives it nothing (it gives to world 2, which then fights famine).
        let mut b = Balancer::new(
            &BalanceConfig {
                workers: 3,
                ..config
            },
            g.cell_count(),
        );
        let new = b.round(&g, &p, &[4.6, 4.4, 1.0], &[0.0; 3], &bodies, 20);
        assert!(new.is_none_or(|n| n.owner(20) == 1));
    }

    #[test]
    fn the_opening_round_moves_cells_by_bodies_and_neither_smooths_nor_backs_off() {
        let (g, p, bodies) = row();
        let config = BalanceConfig {
            smoothing: 0.5,
            cooldown: 0,
            ..BalanceConfig::on()
        };
        let mut b = Balancer::new(&config, g.cell_count());
        let new = b
            .opening_round(&g, &p, &bodies)
            .expect("all bodies in world 0");
        assert!(new.cells_of(1).len() > p.cells_of(1).len());
        let r = &b.history()[0];
        assert_eq!((r.step, r.levels[0]), (0, LoadLevel::Overloaded));
        assert_eq!(
            b.next_round_after(0),
            config.period,
            "the first measured round"
        );
        // The first measured round is taken as measured: [3.2, 0.8] against a mean of 2 is
        // overloaded, not averaged with the estimate (in bodies, another unit).
        b.round(&g, &new, &[3.2, 0.8], &[0.0; 2], &bodies, config.period);
        assert_eq!(b.history()[1].levels[0], LoadLevel::Overloaded);
        // Bodies spread evenly: nothing moves, and no backoff either.
        let even = vec![1u32; 8];
        let mut b = Balancer::new(&config, g.cell_count());
        assert!(b.opening_round(&g, &p, &even).is_none());
        assert_eq!(b.next_round_after(0), config.period);
    }
}
