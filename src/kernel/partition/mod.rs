//! Territories: a map from every cell of the grid to the world that owns it.
//!
//! Partitioners: axis-aligned blocks cut where the bodies balance or of equal cells
//! (blocks.rs), the thesis's equal-size k-means (§3.2.4), uniformly random cells
//! (fragmented territories, for tests) and explicit maps. All are deterministic for their
//! inputs and seed. A world may own no cell at all.

use super::config::PartitionKind;
use crate::grid::{CellCoord, Grid};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

mod blocks;

/// A world's index, `0..worlds`.
pub type WorldId = u32;

/// The owner of every cell, and each cell's index in its owner's list of cells.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Partition {
    worlds: usize,
    owner: Vec<WorldId>,
    local: Vec<u32>,
    cells: Vec<Vec<u32>>,
}

impl Partition {
    /// A partition from an explicit owner per cell (linear index order).
    ///
    /// # Panics
    /// If `owner` does not have one entry per cell or names a world `>= worlds`.
    pub fn from_owners(grid: &Grid, worlds: usize, owner: Vec<WorldId>) -> Partition {
        assert!(worlds >= 1, "at least one world");
        assert_eq!(owner.len(), grid.cell_count(), "one owner per cell");
        let mut cells = vec![Vec::new(); worlds];
        let mut local = vec![0; owner.len()];
        for (i, &w) in owner.iter().enumerate() {
            assert!((w as usize) < worlds, "cell {i} owned by unknown world {w}");
            local[i] = cells[w as usize].len() as u32;
            cells[w as usize].push(i as u32);
        }
        Partition {
            worlds,
            owner,
            local,
            cells,
        }
    }

    /// Builds the partition `kind` of `grid` into `worlds` worlds; `positions` are the bodies'
    /// initial positions (blocks cut where they balance them; k-means clusters them).
    pub fn build(
        kind: &PartitionKind,
        grid: &Grid,
        worlds: usize,
        positions: &[[f32; 3]],
        seed: u64,
    ) -> Partition {
        match kind {
            PartitionKind::Blocks => Self::blocks_by_bodies(grid, worlds, positions),
            PartitionKind::EqualBlocks => Self::blocks(grid, worlds),
            PartitionKind::KMeans => Self::kmeans(grid, worlds, positions, seed),
            PartitionKind::Random => Self::random(grid, worlds, seed),
            PartitionKind::Explicit(o) => Self::from_owners(grid, worlds, o.clone()),
        }
    }

    /// Every cell to a uniformly random world.
    pub fn random(grid: &Grid, worlds: usize, seed: u64) -> Partition {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let owner = (0..grid.cell_count())
            .map(|_| rng.random_range(0..worlds.max(1)) as WorldId)
            .collect();
        Self::from_owners(grid, worlds.max(1), owner)
    }

    /// The thesis's setup (§3.2.4): equal-size k-means over body positions (centroids
    /// seeded from `seed`, ten rounds of capacity-bounded greedy assignment), each occupied
    /// cell to the cluster with most bodies in it (lowest world on ties), every empty cell to
    /// the nearest centroid (lowest world on ties). Falls back to blocks without bodies.
    pub fn kmeans(grid: &Grid, worlds: usize, positions: &[[f32; 3]], seed: u64) -> Partition {
        let k = worlds.max(1);
        let pts: Vec<[f64; 3]> = positions
            .iter()
            .filter(|p| grid.cell_of(**p).is_some())
            .map(|p| p.map(|v| v as f64))
            .collect();
        if pts.is_empty() {
            return Self::blocks(grid, worlds);
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut cent: Vec<[f64; 3]> = (0..k)
            .map(|_| pts[rng.random_range(0..pts.len())])
            .collect();
        let d2 = |a: &[f64; 3], b: &[f64; 3]| {
            (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)
        };
        let cap = pts.len().div_ceil(k);
        let mut assign = vec![0usize; pts.len()];
        for _ in 0..10 {
            // Greedy equal-size assignment: all (distance, point, cluster) triples in
            // ascending order, each point to the first cluster with room.
            let mut pairs: Vec<(f64, usize, usize)> = Vec::with_capacity(pts.len() * k);
            for (i, p) in pts.iter().enumerate() {
                for (j, c) in cent.iter().enumerate() {
                    pairs.push((d2(p, c), i, j));
                }
            }
            pairs.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
            let mut done = vec![false; pts.len()];
            let mut size = vec![0usize; k];
            for (_, i, j) in pairs {
                if !done[i] && size[j] < cap {
                    done[i] = true;
                    size[j] += 1;
                    assign[i] = j;
                }
            }
            let mut sum = vec![[0.0f64; 3]; k];
            for (i, p) in pts.iter().enumerate() {
                for a in 0..3 {
                    sum[assign[i]][a] += p[a];
                }
            }
            for j in 0..k {
                if size[j] > 0 {
                    cent[j] = sum[j].map(|s| s / size[j] as f64);
                }
            }
        }
        let mut counts = vec![vec![0u32; k]; grid.cell_count()];
        for (i, p) in pts.iter().enumerate() {
            let c = grid
                .cell_of(p.map(|v| v as f32))
                .expect("filtered to the grid");
            counts[grid.index(c)][assign[i]] += 1;
        }
        let owner = (0..grid.cell_count())
            .map(|i| {
                let best = counts[i]
                    .iter()
                    .enumerate()
                    .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(&a.0)))
                    .filter(|(_, &n)| n > 0);
                match best {
                    Some((w, _)) => w as WorldId,
                    None => {
                        let c = grid.coord(i);
                        let centre = [
                            grid.min.x as f64 + (c.x as f64 + 0.5) * grid.edge as f64,
                            grid.min.y as f64 + (c.y as f64 + 0.5) * grid.edge as f64,
                            grid.min.z as f64 + (c.z as f64 + 0.5) * grid.edge as f64,
                        ];
                        (0..k)
                            .min_by(|&a, &b| {
                                d2(&centre, &cent[a])
                                    .total_cmp(&d2(&centre, &cent[b]))
                                    .then(a.cmp(&b))
                            })
                            .unwrap_or(0) as WorldId
                    }
                }
            })
            .collect();
        Self::from_owners(grid, k, owner)
    }

    /// Number of worlds.
    pub fn worlds(&self) -> usize {
        self.worlds
    }

    /// The owner of the cell with linear index `cell`.
    pub fn owner(&self, cell: u32) -> WorldId {
        self.owner[cell as usize]
    }

    /// The index of `cell` in its owner's list of cells.
    pub fn local(&self, cell: u32) -> u32 {
        self.local[cell as usize]
    }

    /// The cells of world `w`, ascending.
    pub fn cells_of(&self, w: WorldId) -> &[u32] {
        &self.cells[w as usize]
    }

    /// The owner of a cell given by coordinates.
    pub fn owner_of(&self, grid: &Grid, c: CellCoord) -> WorldId {
        self.owner[grid.index(c)]
    }

    /// The owner of every cell, in linear index order.
    pub fn owners(&self) -> &[WorldId] {
        &self.owner
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Vec3;

    /// 8 × 4 × 6 cells of 1 m (also the blocks tests' grid).
    pub(super) fn grid() -> Grid {
        Grid::covering(Vec3::zeros(), Vec3::new(8.0, 4.0, 6.0), 1.0)
    }

    #[test]
    fn kmeans_is_deterministic_and_total() {
        let g = grid();
        let pts: Vec<[f32; 3]> = (0..50)
            .map(|i| {
                [
                    (i % 8) as f32 + 0.5,
                    (i % 3) as f32 + 0.2,
                    (i % 5) as f32 + 0.7,
                ]
            })
            .collect();
        let a = Partition::kmeans(&g, 4, &pts, 7);
        let b = Partition::kmeans(&g, 4, &pts, 7);
        assert_eq!(a, b);
        let total: usize = (0..4).map(|w| a.cells_of(w).len()).sum();
        assert_eq!(total, g.cell_count());
    }
}
