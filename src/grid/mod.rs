//! The uniform grid over the bounded domain: cell edge, cell coordinates, home cells and the
//! fixed topological order of cells (ascending linear index: x fastest, then y, then z).

use crate::math::Vec3;
use serde::{Deserialize, Serialize};

/// Integer coordinates of a cell.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct CellCoord {
    /// Column along x.
    pub x: i32,
    /// Row along y.
    pub y: i32,
    /// Layer along z.
    pub z: i32,
}

impl CellCoord {
    /// A cell coordinate.
    pub const fn new(x: i32, y: i32, z: i32) -> Self {
        CellCoord { x, y, z }
    }

    /// This cell moved by `d`.
    pub fn offset(self, d: [i32; 3]) -> Self {
        CellCoord::new(self.x + d[0], self.y + d[1], self.z + d[2])
    }

    /// Chebyshev distance: 1 for the 26 neighbours, 0 for the cell itself.
    pub fn chebyshev(self, o: CellCoord) -> i32 {
        (self.x - o.x)
            .abs()
            .max((self.y - o.y).abs())
            .max((self.z - o.z).abs())
    }
}

/// A uniform grid of cubic cells of edge `edge` covering the box `[min, min + dims * edge)`.
#[derive(Clone, Debug, PartialEq)]
pub struct Grid {
    /// Lower corner of the domain.
    pub min: Vec3,
    /// Cell edge in metres.
    pub edge: f32,
    /// Number of cells along x, y, z.
    pub dims: [i32; 3],
}

impl Grid {
    /// Largest number of cells a grid may have (keeps per-cell tables in memory).
    pub const MAX_CELLS: usize = 1 << 22;

    /// The grid whose cells of edge `edge` cover the box `[min, max]`.
    pub fn covering(min: Vec3, max: Vec3, edge: f32) -> Grid {
        let n = |a: f32, b: f32| (((b - a) / edge).ceil() as i32).max(1);
        Grid {
            min,
            edge,
            dims: [n(min.x, max.x), n(min.y, max.y), n(min.z, max.z)],
        }
    }

    /// Total number of cells.
    pub fn cell_count(&self) -> usize {
        self.dims.iter().map(|&d| d as usize).product()
    }

    /// Upper corner of the gridded box.
    pub fn max(&self) -> Vec3 {
        self.min
            + Vec3::new(
                self.dims[0] as f32 * self.edge,
                self.dims[1] as f32 * self.edge,
                self.dims[2] as f32 * self.edge,
            )
    }

    /// The cell holding point `p`, or `None` if `p` is outside the grid (or not finite).
    pub fn cell_of(&self, p: [f32; 3]) -> Option<CellCoord> {
        // `floor(q)` is finite, at least 0 and below `d` exactly when `q` is at least 0
        // and below `d` (an integer, exact as an `f32`: `d` < 2^24), and then it is
        // `q`'s truncation: no call to `floor` (a library call on the baseline x86-64).
        let c = |v: f32, m: f32, d: i32| -> Option<i32> {
            let q = (v - m) / self.edge;
            if q >= 0.0 && q < d as f32 {
                Some(q as i32)
            } else {
                None
            }
        };
        Some(CellCoord::new(
            c(p[0], self.min.x, self.dims[0])?,
            c(p[1], self.min.y, self.dims[1])?,
            c(p[2], self.min.z, self.dims[2])?,
        ))
    }

    /// Whether `c` lies inside the grid.
    pub fn contains(&self, c: CellCoord) -> bool {
        c.x >= 0
            && c.y >= 0
            && c.z >= 0
            && c.x < self.dims[0]
            && c.y < self.dims[1]
            && c.z < self.dims[2]
    }

    /// Linear index of a cell (its position in the topological order).
    pub fn index(&self, c: CellCoord) -> usize {
        debug_assert!(self.contains(c));
        (c.x + self.dims[0] * (c.y + self.dims[1] * c.z)) as usize
    }

    /// The cell at a linear index.
    pub fn coord(&self, i: usize) -> CellCoord {
        let i = i as i32;
        let (nx, ny) = (self.dims[0], self.dims[1]);
        CellCoord::new(i % nx, (i / nx) % ny, i / (nx * ny))
    }

    /// Cells of the 27-neighbourhood of `c` that exist in the grid, in slot order.
    pub fn neighbours(&self, c: CellCoord) -> impl Iterator<Item = CellCoord> + '_ {
        (0..27i32).filter_map(move |k| {
            let n = c.offset([k % 3 - 1, (k / 3) % 3 - 1, k / 9 - 1]);
            self.contains(n).then_some(n)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cell_of_is_the_floor_of_the_scaled_offset_inside_the_grid() {
        let g = Grid::covering(Vec3::new(-1.0, 0.0, -2.0), Vec3::new(3.0, 2.0, 2.0), 0.5);
        let by_floor = |p: [f32; 3]| -> Option<CellCoord> {
            let c = |v: f32, m: f32, d: i32| {
                let f = ((v - m) / g.edge).floor();
                (f.is_finite() && f >= 0.0 && f < d as f32).then_some(f as i32)
            };
            Some(CellCoord::new(
                c(p[0], g.min.x, g.dims[0])?,
                c(p[1], g.min.y, g.dims[1])?,
                c(p[2], g.min.z, g.dims[2])?,
            ))
        };
        let mut values = vec![
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MAX,
            f32::MIN,
            -0.0,
            0.0,
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
        ];
        for k in -100..=100 {
            let v = k as f32 * 0.05;
            values.extend([v, v.next_up(), v.next_down()]);
        }
        for &x in &values {
            for &y in &[0.3f32, -0.0, 1.999_999_9, 2.0] {
                for &z in &[-2.0f32, -2.000_000_2, 1.999_999_9, 0.25] {
                    let p = [x, y, z];
                    assert_eq!(g.cell_of(p), by_floor(p), "{p:?}");
                    let q = [y, x, z];
                    assert_eq!(g.cell_of(q), by_floor(q), "{q:?}");
                    let r = [z, y, x];
                    assert_eq!(g.cell_of(r), by_floor(r), "{r:?}");
                }
            }
        }
    }

    #[test]
    fn index_and_coord_are_inverse() {
        let g = Grid::covering(Vec3::new(-1.0, 0.0, -2.0), Vec3::new(3.0, 2.0, 2.0), 0.5);
        for i in 0..g.cell_count() {
            assert_eq!(g.index(g.coord(i)), i);
        }
        assert_eq!(g.dims, [8, 4, 8]);
    }

    #[test]
    fn points_outside_or_nan_have_no_home_cell() {
        let g = Grid::covering(Vec3::zeros(), Vec3::new(1.0, 1.0, 1.0), 0.5);
        assert_eq!(g.cell_of([0.75, 0.1, 0.6]), Some(CellCoord::new(1, 0, 1)));
        assert_eq!(g.cell_of([-0.01, 0.1, 0.6]), None);
        assert_eq!(g.cell_of([f32::NAN, 0.1, 0.6]), None);
        assert_eq!(g.cell_of([1.0, 0.1, 0.6]), None);
    }
}
