//! Territory geometry on an owner map (one world id per cell): face neighbours, connected
//! components, the cut a cell's move changes, distance to the scene border. Pure helpers
//! for the balancer's criteria (thesis §3.3.4–3.3.5).

use crate::grid::Grid;
use crate::kernel::partition::WorldId;
use std::collections::VecDeque;

/// The six face offsets.
const FACES: [[i32; 3]; 6] = [
    [-1, 0, 0],
    [1, 0, 0],
    [0, -1, 0],
    [0, 1, 0],
    [0, 0, -1],
    [0, 0, 1],
];

/// The cells sharing a face with `cell` (linear indices).
pub fn face_neighbours(grid: &Grid, cell: u32) -> impl Iterator<Item = u32> + '_ {
    let c = grid.coord(cell as usize);
    FACES.iter().filter_map(move |&d| {
        let n = c.offset(d);
        grid.contains(n).then(|| grid.index(n) as u32)
    })
}

/// How many of the 26 cells around `cell` another world than `owner[cell]` owns: the
/// thesis's "foreign neighbours", the cells a cell makes its world synchronise with.
pub fn foreign_neighbours(grid: &Grid, owner: &[WorldId], cell: u32) -> usize {
    let w = owner[cell as usize];
    grid.neighbours(grid.coord(cell as usize))
        .filter(|&n| owner[grid.index(n)] != w)
        .count()
}

/// The change in the number of faces between different worlds (the summed perimeter of
/// all territories) if `cell` moved to world `to`.
pub fn cut_change(grid: &Grid, owner: &[WorldId], cell: u32, to: WorldId) -> i64 {
    let from = owner[cell as usize];
    face_neighbours(grid, cell)
        .map(|n| {
            let o = owner[n as usize];
            (o != to) as i64 - (o != from) as i64
        })
        .sum()
}

/// Cells between `cell` and the nearest face of the domain (0 on the border).
pub fn border_distance(grid: &Grid, cell: u32) -> i32 {
    let c = grid.coord(cell as usize);
    let d = grid.dims;
    [
        c.x,
        c.y,
        c.z,
        d[0] - 1 - c.x,
        d[1] - 1 - c.y,
        d[2] - 1 - c.z,
    ]
    .into_iter()
    .min()
    .unwrap_or(0)
}

/// Number of face-connected components of world `w`'s territory, ignoring `without`.
pub fn components(grid: &Grid, owner: &[WorldId], w: WorldId, without: Option<u32>) -> usize {
    let mut seen = vec![false; owner.len()];
    let mut count = 0;
    let mut queue = VecDeque::new();
    for start in 0..owner.len() as u32 {
        if owner[start as usize] != w || seen[start as usize] || Some(start) == without {
            continue;
        }
        count += 1;
        seen[start as usize] = true;
        queue.push_back(start);
        while let Some(c) = queue.pop_front() {
            for n in face_neighbours(grid, c) {
                if owner[n as usize] == w && !seen[n as usize] && Some(n) != without {
                    seen[n as usize] = true;
                    queue.push_back(n);
                }
            }
        }
    }
    count
}

/// Whether giving cell `c` away leaves its owner's territory in no more pieces than before
/// (and not empty) — the same answer as comparing [`components`] with and without `c`, found
/// by one search that stops as soon as the owner's face neighbours of `c` are known to stay
/// connected to each other without `c` (usually a few cells away).
pub fn removal_keeps_whole(grid: &Grid, owner: &[WorldId], c: u32) -> bool {
    let w = owner[c as usize];
    let near: Vec<u32> = face_neighbours(grid, c)
        .filter(|&n| owner[n as usize] == w)
        .collect();
    let Some(&first) = near.first() else {
        // An isolated piece: removing it leaves one piece fewer, if any cell remains.
        return owner.iter().filter(|&&o| o == w).nth(1).is_some();
    };
    let mut seen = vec![false; owner.len()];
    seen[c as usize] = true;
    seen[first as usize] = true;
    let mut missing = near.len() - 1;
    let mut queue = VecDeque::from([first]);
    while let Some(x) = queue.pop_front() {
        if missing == 0 {
            return true;
        }
        for n in face_neighbours(grid, x) {
            if owner[n as usize] == w && !seen[n as usize] {
                seen[n as usize] = true;
                missing -= near.contains(&n) as usize;
                queue.push_back(n);
            }
        }
    }
    missing == 0
}

/// The worlds owning a cell that shares a face with world `w`'s territory, ascending.
pub fn neighbour_worlds(grid: &Grid, owner: &[WorldId], w: WorldId) -> Vec<WorldId> {
    let mut out: Vec<WorldId> = (0..owner.len() as u32)
        .filter(|&c| owner[c as usize] == w)
        .flat_map(|c| face_neighbours(grid, c).map(|n| owner[n as usize]))
        .filter(|&o| o != w)
        .collect();
    out.sort_unstable();
    out.dedup();
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Vec3;

    fn grid() -> Grid {
        Grid::covering(Vec3::zeros(), Vec3::new(4.0, 1.0, 1.0), 1.0)
    }

    #[test]
    fn removing_a_middle_cell_splits_a_row() {
        let g = grid();
        let owner = vec![0; g.cell_count()];
        assert_eq!(components(&g, &owner, 0, None), 1);
        assert_eq!(components(&g, &owner, 0, Some(1)), 2);
        assert_eq!(components(&g, &owner, 0, Some(0)), 1);
    }

    #[test]
    fn removal_keeps_whole_agrees_with_counting_components_on_random_maps() {
        use rand::{Rng, SeedableRng};
        let g = Grid::covering(Vec3::zeros(), Vec3::new(6.0, 3.0, 5.0), 1.0);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for _ in 0..200 {
            let worlds = rng.random_range(1..4u32);
            let owner: Vec<WorldId> = (0..g.cell_count())
                .map(|_| rng.random_range(0..worlds))
                .collect();
            for c in 0..g.cell_count() as u32 {
                let w = owner[c as usize];
                let before = components(&g, &owner, w, None);
                let cells = owner.iter().filter(|&&o| o == w).count();
                let expected = cells > 1 && components(&g, &owner, w, Some(c)) <= before.max(1);
                assert_eq!(removal_keeps_whole(&g, &owner, c), expected, "cell {c}");
            }
        }
    }

    #[test]
    fn moving_a_border_cell_shortens_the_cut() {
        let g = grid();
        let n = g.dims[0];
        let owner: Vec<WorldId> = (0..g.cell_count())
            .map(|i| (g.coord(i).x >= n / 2) as WorldId)
            .collect();
        let border = g.index(crate::grid::CellCoord::new(n / 2, 0, 0)) as u32;
        assert!(cut_change(&g, &owner, border, 0) <= 0);
        assert_eq!(neighbour_worlds(&g, &owner, 0), vec![1]);
        assert_eq!(border_distance(&g, 0), 0);
    }
}
