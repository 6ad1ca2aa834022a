//! A **model** of scalability beyond the cores we have (SPEC.md §12): from the measured cost
//! of every cell computation of a reference run and the locality dependencies between cells,
//! predict the wall time of P worlds on P workers. Two predictions:
//!
//! - `bulk_synchronous`: the thesis's measure (§4.2): per step, the slowest world's time;
//!   summed over steps (every world waits for every other at each step).
//! - `dataflow`: each world is one worker computing its whole territory one step at a time
//!   (as `World::advance` does); world `w` starts step `t` once it has finished `t − 1` and
//!   every neighbouring world (owning a cell next to one of `w`'s) has finished `t − 1` (its
//!   ghosts are then sent). No messages cost, no rollbacks: an optimistic executor's ideal.
//!
//! Both ignore memory bandwidth, caches and messaging overhead: they are models, labelled as
//! such wherever they are printed, and checked against a measured run at P = 2.
//!
//! [`WindowedRun`] models N worlds on fewer workers with ideal optimism and a window W (the
//! `peak-resistance` experiment): what the window could absorb if worlds ran ahead.

pub mod cluster;

use crate::exec::reference::CellCost;
use crate::grid::Grid;
use crate::kernel::Partition;
use std::collections::BTreeSet;

/// Predicted times of one partition.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prediction {
    /// Worlds (= workers).
    pub worlds: usize,
    /// Sum of all cell costs: the sequential time, s.
    pub sequential_seconds: f64,
    /// Σ over steps of the slowest world's time that step, s.
    pub bulk_synchronous_seconds: f64,
    /// The dataflow schedule's makespan, s.
    pub dataflow_seconds: f64,
}

impl Prediction {
    /// Sequential time over the bulk-synchronous time.
    pub fn bulk_synchronous_speedup(&self) -> f64 {
        self.sequential_seconds / self.bulk_synchronous_seconds.max(1e-12)
    }

    /// Sequential time over the dataflow time.
    pub fn dataflow_speedup(&self) -> f64 {
        self.sequential_seconds / self.dataflow_seconds.max(1e-12)
    }
}

/// Predicts the run of `costs` (steps `0..steps`) on the worlds of `partition`.
pub fn predict(grid: &Grid, partition: &Partition, costs: &[CellCost], steps: u64) -> Prediction {
    let n = partition.worlds();
    let mut per_step = vec![vec![0.0f64; n]; steps as usize];
    let mut sequential = 0.0;
    // Sums in (step, cell) order so the prediction does not depend on how costs were listed.
    let mut sorted: Vec<&CellCost> = costs.iter().filter(|c| c.step < steps).collect();
    sorted.sort_by_key(|c| (c.step, c.cell));
    for c in sorted {
        per_step[c.step as usize][partition.owner(c.cell) as usize] += c.seconds;
        sequential += c.seconds;
    }
    let neighbours: Vec<Vec<usize>> = (0..n)
        .map(|w| {
            let mut set = BTreeSet::new();
            for &c in partition.cells_of(w as u32) {
                for nb in grid.neighbours(grid.coord(c as usize)) {
                    let v = partition.owner(grid.index(nb) as u32) as usize;
                    if v != w {
                        set.insert(v);
                    }
                }
            }
            set.into_iter().collect()
        })
        .collect();
    let mut bsp = 0.0;
    let mut finish = vec![0.0f64; n];
    for step in &per_step {
        bsp += step.iter().copied().fold(0.0, f64::max);
        let prev = finish.clone();
        for w in 0..n {
            let ready = neighbours[w]
                .iter()
                .map(|&v| prev[v])
                .fold(prev[w], f64::max);
            finish[w] = ready + step[w];
        }
    }
    Prediction {
        worlds: n,
        sequential_seconds: sequential,
        bulk_synchronous_seconds: bsp,
        dataflow_seconds: finish.iter().copied().fold(0.0, f64::max),
    }
}

/// A **model** of N worlds on `workers` workers with ideal optimism: every speculation is
/// right (no rollback, no message cost), so a world's only constraints are its own previous
/// step and the window — it may start step `s` once `s < G + window`, `G` being the fewest
/// steps any world has finished (the GVT). A free worker takes the ready world with the
/// smallest next step (laggards first, lowest id on ties). `per_step[t][w]` is world `w`'s
/// cost of step `t`, s.
#[derive(Clone, Debug, PartialEq)]
pub struct WindowedRun {
    /// When the last step finished, s.
    pub makespan: f64,
    /// When each step was committed (every world finished it), s.
    pub commit_times: Vec<f64>,
}

impl WindowedRun {
    /// Simulates the schedule (see the type's doc).
    pub fn simulate(per_step: &[Vec<f64>], workers: usize, window: u64) -> WindowedRun {
        let steps = per_step.len();
        let n = per_step.first().map_or(0, |s| s.len());
        let window = window.max(1) as usize;
        let mut done = vec![0usize; n];
        let mut running: Vec<(f64, usize)> = Vec::new();
        let mut now = 0.0f64;
        let mut commit_times = Vec::with_capacity(steps);
        loop {
            let gvt = done.iter().copied().min().unwrap_or(steps);
            while running.len() < workers.max(1) {
                let ready = (0..n)
                    .filter(|&w| !running.iter().any(|r| r.1 == w))
                    .filter(|&w| done[w] < steps && done[w] < gvt + window)
                    .min_by_key(|&w| (done[w], w));
                let Some(w) = ready else { break };
                running.push((now + per_step[done[w]][w], w));
            }
            let Some(k) = (0..running.len()).min_by(|&a, &b| {
                let (x, y) = (running[a], running[b]);
                x.0.total_cmp(&y.0).then(x.1.cmp(&y.1))
            }) else {
                break;
            };
            let (finish, w) = running.swap_remove(k);
            now = finish;
            done[w] += 1;
            let committed = done.iter().copied().min().unwrap_or(0);
            while commit_times.len() < committed {
                commit_times.push(now);
            }
        }
        WindowedRun {
            makespan: now,
            commit_times,
        }
    }

    /// The largest time between two consecutive commits (the first from time 0), s.
    pub fn worst_gap(&self) -> f64 {
        let mut prev = 0.0;
        let mut worst = 0.0f64;
        for &t in &self.commit_times {
            worst = worst.max(t - prev);
            prev = t;
        }
        worst
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernel::PartitionKind;
    use crate::math::Vec3;

    fn costs(grid: &Grid, steps: u64, cost: impl Fn(u32, u64) -> f64) -> Vec<CellCost> {
        let mut v = Vec::new();
        for step in 0..steps {
            for cell in 0..grid.cell_count() as u32 {
                v.push(CellCost {
                    step,
                    cell,
                    seconds: cost(cell, step),
                });
            }
        }
        v
    }

    #[test]
    fn uniform_load_on_p_blocks_predicts_a_speedup_of_p() {
        let grid = Grid::covering(Vec3::zeros(), Vec3::new(8.0, 1.0, 8.0), 1.0);
        let c = costs(&grid, 10, |_, _| 1e-3);
        for p in [1, 2, 4, 8] {
            let part = Partition::build(&PartitionKind::Blocks, &grid, p, &[], 0);
            let pr = predict(&grid, &part, &c, 10);
            assert!(
                (pr.bulk_synchronous_speedup() - p as f64).abs() < 1e-9,
                "{pr:?}"
            );
            assert!((pr.dataflow_speedup() - p as f64).abs() < 1e-9, "{pr:?}");
        }
    }

    #[test]
    fn windowed_model_is_bulk_synchronous_at_window_1_and_per_world_sums_when_unbounded() {
        // Two worlds whose heavy steps alternate: 3 then 1, 1 then 3, ...
        let per_step: Vec<Vec<f64>> = (0..6)
            .map(|t| {
                if t % 2 == 0 {
                    vec![3.0, 1.0]
                } else {
                    vec![1.0, 3.0]
                }
            })
            .collect();
        let lockstep = WindowedRun::simulate(&per_step, 2, 1);
        assert_eq!(lockstep.makespan, 18.0, "Σ_t max_w = 6 × 3");
        assert_eq!(lockstep.commit_times, vec![3.0, 6.0, 9.0, 12.0, 15.0, 18.0]);
        assert_eq!(lockstep.worst_gap(), 3.0);
        let free = WindowedRun::simulate(&per_step, 2, 64);
        assert_eq!(
            free.makespan, 12.0,
            "max_w Σ_t = 12: each world on its own worker"
        );
        // One worker does all the work whatever the window.
        for w in [1, 2, 64] {
            assert_eq!(WindowedRun::simulate(&per_step, 1, w).makespan, 24.0);
        }
    }

    #[test]
    fn a_hot_world_bounds_both_predictions_and_dataflow_is_never_slower() {
        let grid = Grid::covering(Vec3::zeros(), Vec3::new(8.0, 1.0, 8.0), 1.0);
        // All the work in one cell: no parallelism to find.
        let c = costs(&grid, 10, |cell, _| if cell == 0 { 1.0 } else { 0.0 });
        let part = Partition::build(&PartitionKind::Blocks, &grid, 4, &[], 0);
        let pr = predict(&grid, &part, &c, 10);
        assert!((pr.bulk_synchronous_speedup() - 1.0).abs() < 1e-9);
        assert!((pr.dataflow_speedup() - 1.0).abs() < 1e-9);
        // Alternating hot worlds: dataflow overlaps what bulk-synchronous serialises.
        let c = costs(&grid, 10, |cell, step| {
            if (cell as u64 + step) % 2 == 0 {
                1e-3
            } else {
                3e-3
            }
        });
        let pr = predict(&grid, &part, &c, 10);
        assert!(
            pr.dataflow_seconds <= pr.bulk_synchronous_seconds + 1e-12,
            "{pr:?}"
        );
    }
}
