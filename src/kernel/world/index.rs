//! The kinds of cell index a world handles, kept apart by type.
//!
//! A *global* cell is a cell's linear index in the grid (`u32`, as in messages and the
//! partition). An [`OwnCell`] is the index of one of the world's own cells in
//! `World::cells` (the partition's local index of that cell), a [`MarginCell`] the index of
//! a foreign cell next to them in `World::margin`. The per-own-cell tables of a world and of
//! its slots are [`PerOwnCell`] vectors, indexed by [`OwnCell`] only.

use crate::grid::Grid;
use std::ops::{Index, IndexMut};

/// One of a world's own cells: its index in `World::cells`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub(super) struct OwnCell(u32);

impl OwnCell {
    /// The own cell with the partition's local index `local`.
    pub(super) fn from_local(local: u32) -> Self {
        OwnCell(local)
    }

    /// Its position in a [`PerOwnCell`] vector.
    pub(super) fn index(self) -> usize {
        self.0 as usize
    }

    /// The own cells of a world owning `count` cells, ascending.
    pub(super) fn all(count: usize) -> impl Iterator<Item = OwnCell> {
        (0..count as u32).map(OwnCell)
    }
}

/// A foreign cell next to one of a world's own cells: its index in `World::margin`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub(super) struct MarginCell(u32);

impl MarginCell {
    /// The margin cell at position `position` of `World::margin`.
    pub(super) fn at(position: usize) -> Self {
        MarginCell(position as u32)
    }

    /// Its position in `World::margin` and in a slot's ghost views.
    pub(super) fn index(self) -> usize {
        self.0 as usize
    }
}

/// One value per own cell, indexed by [`OwnCell`].
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub(super) struct PerOwnCell<T>(Vec<T>);

impl<T> PerOwnCell<T> {
    /// Number of own cells.
    pub(super) fn len(&self) -> usize {
        self.0.len()
    }

    /// The values in own-cell order, as a slice.
    pub(super) fn as_slice(&self) -> &[T] {
        &self.0
    }

    /// The values in own-cell order.
    pub(super) fn iter(&self) -> std::slice::Iter<'_, T> {
        self.0.iter()
    }

    /// Sets every value to `value`, for `len` own cells (keeping the allocation).
    pub(super) fn reset(&mut self, len: usize, value: T)
    where
        T: Clone,
    {
        self.0.clear();
        self.0.resize(len, value);
    }

    /// Each own cell with its value, in own-cell order.
    pub(super) fn enumerate(&self) -> impl Iterator<Item = (OwnCell, &T)> + '_ {
        OwnCell::all(self.0.len()).zip(&self.0)
    }
}

impl<T> From<Vec<T>> for PerOwnCell<T> {
    fn from(values: Vec<T>) -> Self {
        PerOwnCell(values)
    }
}

impl<T> FromIterator<T> for PerOwnCell<T> {
    fn from_iter<I: IntoIterator<Item = T>>(values: I) -> Self {
        PerOwnCell(values.into_iter().collect())
    }
}

impl<T> Index<OwnCell> for PerOwnCell<T> {
    type Output = T;

    fn index(&self, cell: OwnCell) -> &T {
        &self.0[cell.index()]
    }
}

impl<T> IndexMut<OwnCell> for PerOwnCell<T> {
    fn index_mut(&mut self, cell: OwnCell) -> &mut T {
        &mut self.0[cell.index()]
    }
}

/// The global cells around global cell `cell` in `grid` (itself included), in the grid's
/// neighbour order.
pub(super) fn cells_around(grid: &Grid, cell: u32) -> impl Iterator<Item = u32> + '_ {
    grid.neighbours(grid.coord(cell as usize))
        .map(move |n| grid.index(n) as u32)
}
