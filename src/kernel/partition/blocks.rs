//! The blocks partitioner: recursive coordinate bisection of the grid into axis-aligned
//! boxes of cells, each cut placed where it shares the bodies most evenly (SPEC.md §K2).
//!
//! A world's step takes about as long as its bodies take, and in a lockstep-like optimistic
//! run the slowest territory sets the pace: cutting the grid into equal numbers of cells
//! leaves a scene whose bodies sit off the domain's centre (the built-in `falling-cubes` at
//! 27,000 bodies: 15,300 against 11,700 in two worlds) with one world idle a quarter of
//! the time. Cuts stay on cell boundaries, so a territory is still a box of whole cells.

use super::{Partition, WorldId};
use crate::grid::Grid;

/// A box of cells: `lo[a]..hi[a]` along each axis `a` (cell coordinates).
#[derive(Clone, Copy, Debug)]
struct CellBox {
    lo: [usize; 3],
    hi: [usize; 3],
}

impl CellBox {
    fn size(&self, axis: usize) -> usize {
        self.hi[axis] - self.lo[axis]
    }

    /// Every cell of the box as (coordinates, linear index), z slowest.
    fn cells<'g>(&self, dims: [usize; 3]) -> impl Iterator<Item = ([usize; 3], usize)> + 'g {
        let b = *self;
        (b.lo[2]..b.hi[2]).flat_map(move |z| {
            (b.lo[1]..b.hi[1]).flat_map(move |y| {
                (b.lo[0]..b.hi[0]).map(move |x| ([x, y, z], x + dims[0] * (y + dims[1] * z)))
            })
        })
    }
}

/// The prime factors of `n`, largest first.
fn prime_factors_largest_first(mut n: usize) -> Vec<usize> {
    let mut factors = Vec::new();
    let mut p = 2;
    while n > 1 {
        while n % p == 0 {
            factors.push(p);
            n /= p;
        }
        p += 1;
    }
    factors.reverse();
    factors
}

impl Partition {
    /// Axis-aligned blocks of equal numbers of cells, whatever the bodies (`equal-blocks`,
    /// the partitioner `blocks` was before it followed the bodies): the prime factors of
    /// `worlds`, largest first, are given one by one to the axis with the most cells per
    /// block (the lowest axis on ties); cell `x` of an axis of `n` cells split in `f` goes
    /// to block `⌊x·f/n⌋`, and block `(bx, by, bz)` is world `bx + fx·(by + fy·bz)`.
    pub fn blocks(grid: &Grid, worlds: usize) -> Partition {
        let mut f = [1usize; 3];
        for p in prime_factors_largest_first(worlds.max(1)) {
            let axis = (0..3)
                .max_by(|&a, &b| {
                    let ra = grid.dims[a] as f64 / f[a] as f64;
                    let rb = grid.dims[b] as f64 / f[b] as f64;
                    ra.total_cmp(&rb).then(b.cmp(&a))
                })
                .unwrap_or(0);
            f[axis] *= p;
        }
        let owner = (0..grid.cell_count())
            .map(|i| {
                let c = grid.coord(i);
                let b = |v: i32, a: usize| (v as usize * f[a]) / grid.dims[a] as usize;
                (b(c.x, 0) + f[0] * (b(c.y, 1) + f[1] * b(c.z, 2))) as WorldId
            })
            .collect();
        Self::from_owners(grid, worlds.max(1), owner)
    }

    /// Axis-aligned blocks by recursive bisection: the prime factors of `worlds`, largest
    /// first, split the grid one at a time; a factor `p` cuts each box along its longest
    /// axis (the lowest axis on ties) into `p` slabs of whole cell layers, each cut placed
    /// where the bodies before it come closest to their share (the earliest such layer on
    /// ties), every slab at least one layer thick. A box holding no body, or with fewer
    /// layers than `p`, is cut into equal numbers of layers (layer `x` of `L` to slab
    /// `⌊x·p/L⌋`). Slab `i` of a box holding worlds `w0..w0 + m` gets worlds
    /// `w0 + i·m/p ..`: neighbouring territories have nearby ids. `positions` outside the
    /// grid are not counted (nor simulated).
    pub fn blocks_by_bodies(grid: &Grid, worlds: usize, positions: &[[f32; 3]]) -> Partition {
        let worlds = worlds.max(1);
        let dims = grid.dims.map(|d| d as usize);
        let mut bodies = vec![0u64; grid.cell_count()];
        for p in positions {
            if let Some(c) = grid.cell_of(*p) {
                bodies[grid.index(c)] += 1;
            }
        }
        let mut owner = vec![0 as WorldId; grid.cell_count()];
        let whole = CellBox {
            lo: [0; 3],
            hi: dims,
        };
        let factors = prime_factors_largest_first(worlds);
        split(&mut owner, &bodies, dims, whole, 0, &factors);
        Self::from_owners(grid, worlds, owner)
    }
}

/// Gives the cells of `region` to worlds `first_world ..` (as many as the product of
/// `factors`), cutting by the first factor and recursing with the rest.
fn split(
    owner: &mut [WorldId],
    bodies: &[u64],
    dims: [usize; 3],
    region: CellBox,
    first_world: usize,
    factors: &[usize],
) {
    let Some((&p, rest)) = factors.split_first() else {
        for (_, i) in region.cells(dims) {
            owner[i] = first_world as WorldId;
        }
        return;
    };
    let axis = (0..3)
        .max_by(|&a, &b| region.size(a).cmp(&region.size(b)).then(b.cmp(&a)))
        .unwrap_or(0);
    let mut per_layer = vec![0u64; region.size(axis)];
    for (c, i) in region.cells(dims) {
        per_layer[c[axis] - region.lo[axis]] += bodies[i];
    }
    let bounds = slab_bounds(&per_layer, p);
    let worlds_per_slab: usize = rest.iter().product();
    for s in 0..p {
        let mut slab = region;
        slab.lo[axis] = region.lo[axis] + bounds[s];
        slab.hi[axis] = region.lo[axis] + bounds[s + 1];
        split(
            owner,
            bodies,
            dims,
            slab,
            first_world + s * worlds_per_slab,
            rest,
        );
    }
}

/// The `p + 1` layer boundaries (`0 = b0 ≤ b1 ≤ … ≤ bp = layers`) cutting layers of the
/// given body counts into `p` slabs; see [`Partition::blocks_by_bodies`].
fn slab_bounds(per_layer: &[u64], p: usize) -> Vec<usize> {
    let layers = per_layer.len();
    let total: u64 = per_layer.iter().sum();
    let mut bounds = vec![0; p + 1];
    bounds[p] = layers;
    if total == 0 || layers < p {
        for (i, b) in bounds.iter_mut().enumerate().take(p).skip(1) {
            *b = (i * layers).div_ceil(p);
        }
        return bounds;
    }
    let mut before = vec![0u64; layers + 1];
    for (l, &n) in per_layer.iter().enumerate() {
        before[l + 1] = before[l] + n;
    }
    for i in 1..p {
        // Bodies before boundary b against the share of the first i slabs, both × p.
        let miss = |b: usize| (before[b] as u128 * p as u128).abs_diff(i as u128 * total as u128);
        let earliest = bounds[i - 1] + 1;
        let latest = layers - (p - i);
        bounds[i] = (earliest..=latest)
            .min_by_key(|&b| (miss(b), b))
            .unwrap_or(earliest);
    }
    bounds
}

#[cfg(test)]
mod tests {
    use super::super::tests::grid;
    use super::*;
    use proptest::prelude::*;

    /// How many of `pts` (all inside the grid) lie in world `w`'s territory.
    fn bodies_of(g: &Grid, part: &Partition, pts: &[[f32; 3]], w: WorldId) -> usize {
        pts.iter()
            .filter(|q| g.cell_of(**q).is_some_and(|c| part.owner_of(g, c) == w))
            .count()
    }

    /// The smallest box of cells holding all of `cells` (linear indices), as its volume.
    fn box_volume(g: &Grid, cells: &[u32]) -> usize {
        let coords: Vec<[i32; 3]> = cells
            .iter()
            .map(|&c| {
                let c = g.coord(c as usize);
                [c.x, c.y, c.z]
            })
            .collect();
        (0..3)
            .map(|a| {
                let lo = coords.iter().map(|c| c[a]).min().unwrap_or(0);
                let hi = coords.iter().map(|c| c[a]).max().unwrap_or(-1);
                (hi - lo + 1) as usize
            })
            .product()
    }

    #[test]
    fn blocks_cover_every_world_when_axes_allow() {
        let g = grid();
        for w in [1, 2, 3, 4, 6, 8, 12, 16] {
            let p = Partition::blocks(&g, w);
            for i in 0..w as u32 {
                assert!(!p.cells_of(i).is_empty(), "{w} worlds: world {i} empty");
            }
        }
    }

    #[test]
    fn equal_blocks_number_worlds_x_fastest() {
        // 8 × 4 × 6 cells, 4 worlds: x split in two, then z in two; x varies fastest.
        let g = grid();
        let p = Partition::blocks(&g, 4);
        let at = |x, y, z| p.owner_of(&g, crate::grid::CellCoord::new(x, y, z));
        assert_eq!(
            [at(0, 0, 0), at(7, 0, 0), at(0, 3, 5), at(7, 3, 5)],
            [0, 1, 2, 3]
        );
    }

    #[test]
    fn blocks_without_bodies_cut_equal_layers() {
        assert_eq!(slab_bounds(&[0; 21], 2), vec![0, 11, 21]);
        assert_eq!(slab_bounds(&[0; 21], 4), vec![0, 6, 11, 16, 21]);
        assert_eq!(slab_bounds(&[0; 2], 3), vec![0, 1, 2, 2]);
    }

    #[test]
    fn blocks_cut_where_the_bodies_balance() {
        // Bodies crowd the low layers: an equal-cell cut would give 98 against 2.
        let layers = [40, 30, 20, 5, 3, 2, 0, 0, 0, 0];
        assert_eq!(slab_bounds(&layers, 2), vec![0, 1, 10]);
        assert_eq!(slab_bounds(&[10, 10, 10, 10, 10, 10], 3), vec![0, 2, 4, 6]);
        // Empty layers before the bodies go to the first slab.
        assert_eq!(slab_bounds(&[0, 0, 0, 5, 5, 0], 2), vec![0, 4, 6]);
    }

    #[test]
    fn blocks_balance_an_off_centre_pile_in_two_worlds() {
        let g = grid();
        // 60 bodies in the lowest two x columns, 20 spread over the rest.
        let mut pts = Vec::new();
        for i in 0..60 {
            pts.push([
                0.5 + (i % 2) as f32,
                0.5 + (i % 4) as f32,
                0.5 + (i % 6) as f32,
            ]);
        }
        for i in 0..20 {
            pts.push([2.5 + (i % 6) as f32, 0.5, 0.5]);
        }
        let p = Partition::blocks_by_bodies(&g, 2, &pts);
        assert_eq!(
            (bodies_of(&g, &p, &pts, 0), bodies_of(&g, &p, &pts, 1)),
            (30, 50),
            "cut after x column 0"
        );
        let equal = Partition::blocks(&g, 2);
        assert_eq!(
            bodies_of(&g, &equal, &pts, 0),
            68,
            "equal cells: 4 of 8 columns"
        );
    }

    proptest! {
        #[test]
        fn blocks_are_boxes_that_tile_the_grid_and_beat_equal_cells(
            worlds in 1usize..13,
            pts in proptest::collection::vec((0.0f32..8.0, 0.0f32..4.0, 0.0f32..6.0), 0..200),
        ) {
            let g = grid();
            let pts: Vec<[f32; 3]> = pts.into_iter().map(|(x, y, z)| [x, y, z]).collect();
            let p = Partition::blocks_by_bodies(&g, worlds, &pts);
            prop_assert_eq!(p.worlds(), worlds);
            let cells: usize = (0..worlds as WorldId).map(|w| p.cells_of(w).len()).sum();
            prop_assert_eq!(cells, g.cell_count());
            // Each non-empty territory is exactly the box spanned by its cells.
            for w in 0..worlds as WorldId {
                let cells = p.cells_of(w);
                if cells.is_empty() { continue; }
                prop_assert_eq!(box_volume(&g, cells), cells.len(), "world {} is not a box", w);
            }
            // Two worlds: the cut is the best single cut along the split axis.
            if worlds == 2 && !pts.is_empty() {
                let gap = |part: &Partition| bodies_of(&g, part, &pts, 0).abs_diff(bodies_of(&g, part, &pts, 1));
                prop_assert!(gap(&p) <= gap(&Partition::blocks(&g, 2)));
            }
            prop_assert_eq!(p.clone(), Partition::blocks_by_bodies(&g, worlds, &pts));
        }
    }
}
