//! Per-cell tables of a slot, shared between steps chunk by chunk (copy on write).
//!
//! A slot holds, per own cell, a state and an output, and per margin cell a view. In a
//! territory that does not change (a pile at rest, cells far from anything moving) these
//! entries are the same allocations step after step. [`Chunked`] keeps them in chunks of
//! [`CHUNK`] entries behind `Arc`s: a slot whose chunk holds the same entries as the step
//! before shares that chunk instead of holding its own copy, and writing an entry of a
//! shared chunk copies that chunk only ([`Arc::make_mut`]). So the log's per-cell headers
//! cost about nothing for cells that did not change (SPEC.md §K3, §K9), and creating a slot
//! that inherits the views of the step before costs one `Arc` per chunk, not one per cell.

use super::index::{MarginCell, OwnCell};
use std::ops::{Index, IndexMut};
use std::sync::Arc;

/// Entries per chunk.
pub(super) const CHUNK: usize = 16;

/// A key of a [`Chunked`] table: its position.
pub(super) trait Position: Copy {
    /// Its position in the table.
    fn position(self) -> usize;
}

impl Position for OwnCell {
    fn position(self) -> usize {
        self.index()
    }
}

impl Position for MarginCell {
    fn position(self) -> usize {
        self.index()
    }
}

/// `len` entries of type `T`, indexed by `K`, in chunks shared copy-on-write (module doc).
#[derive(Debug)]
pub(super) struct Chunked<K, T> {
    /// The chunks; every one holds [`CHUNK`] entries (the last one's tail past `len` is
    /// padding, never read).
    chunks: Vec<Arc<[T; CHUNK]>>,
    /// Number of entries.
    len: usize,
    key: std::marker::PhantomData<K>,
}

impl<K, T: Clone> Clone for Chunked<K, T> {
    /// Shares every chunk.
    fn clone(&self) -> Self {
        Chunked {
            chunks: self.chunks.clone(),
            len: self.len,
            key: std::marker::PhantomData,
        }
    }
}

impl<K: Position, T: Clone + Default> Chunked<K, T> {
    /// `len` default entries (one shared blank chunk until written).
    pub(super) fn new(len: usize) -> Self {
        let blank: Arc<[T; CHUNK]> = Arc::new(std::array::from_fn(|_| T::default()));
        Chunked {
            chunks: vec![blank; len.div_ceil(CHUNK)],
            len,
            key: std::marker::PhantomData,
        }
    }

    /// The entries of `values`, in position order (each chunk written once, owned alone).
    #[cfg(test)]
    pub(super) fn from_vec(mut values: Vec<T>) -> Self {
        Self::drain_from(&mut values)
    }

    /// The entries of `values`, in position order (each chunk written once, owned alone),
    /// drained: `values` keeps its capacity for the next table (a world builds one per step).
    pub(super) fn drain_from(values: &mut Vec<T>) -> Self {
        let len = values.len();
        let mut it = values.drain(..);
        let chunks = (0..len.div_ceil(CHUNK))
            .map(|_| Arc::new(std::array::from_fn(|_| it.next().unwrap_or_default())))
            .collect();
        Chunked {
            chunks,
            len,
            key: std::marker::PhantomData,
        }
    }

    /// The entries in position order.
    pub(super) fn iter(&self) -> impl Iterator<Item = &T> + '_ {
        self.chunks.iter().flat_map(|c| c.iter()).take(self.len)
    }

    /// The entries in position order, each with the number of slots sharing its chunk:
    /// for counting bytes once (an entry held by `n` slots counts `1/n` at each).
    pub(super) fn iter_shared(&self) -> impl Iterator<Item = (&T, usize)> + '_ {
        self.chunks
            .iter()
            .flat_map(|c| {
                let n = Arc::strong_count(c);
                c.iter().map(move |e| (e, n))
            })
            .take(self.len)
    }

    /// Bytes of the chunks themselves, each chunk counted `1/n` at each of the `n` tables
    /// sharing it.
    pub(super) fn header_bytes(&self) -> usize {
        self.chunks
            .iter()
            .map(|c| (16 + std::mem::size_of::<[T; CHUNK]>()) / Arc::strong_count(c))
            .sum()
    }

    /// Shares each chunk of `other` (a table of the same length) whose entries are all
    /// `same` as this table's, instead of holding an equal copy.
    pub(super) fn share_equal(&mut self, other: &Self, same: impl Fn(&T, &T) -> bool) {
        debug_assert_eq!(self.len, other.len);
        for (mine, theirs) in self.chunks.iter_mut().zip(&other.chunks) {
            if !Arc::ptr_eq(mine, theirs) && mine.iter().zip(theirs.iter()).all(|(a, b)| same(a, b))
            {
                *mine = theirs.clone();
            }
        }
    }

    /// Whether every entry is `same` as `other`'s (tables of the same length): shared
    /// chunks are not compared.
    pub(super) fn all_same(&self, other: &Self, same: impl Fn(&T, &T) -> bool) -> bool {
        self.len == other.len
            && self
                .chunks
                .iter()
                .zip(&other.chunks)
                .all(|(a, b)| Arc::ptr_eq(a, b) || a.iter().zip(b.iter()).all(|(x, y)| same(x, y)))
    }
}

impl<K: Position, T> Index<K> for Chunked<K, T> {
    type Output = T;

    #[inline]
    fn index(&self, key: K) -> &T {
        let p = key.position();
        // Past `len` within the last chunk is padding; beyond it the chunk index panics.
        debug_assert!(p < self.len, "position {p} out of {} entries", self.len);
        &self.chunks[p / CHUNK][p % CHUNK]
    }
}

impl<K: Position, T: Clone> IndexMut<K> for Chunked<K, T> {
    /// The entry, its chunk first copied if another slot shares it.
    fn index_mut(&mut self, key: K) -> &mut T {
        let p = key.position();
        assert!(p < self.len, "position {p} out of {} entries", self.len);
        &mut Arc::make_mut(&mut self.chunks[p / CHUNK])[p % CHUNK]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn own(i: usize) -> OwnCell {
        OwnCell::from_local(i as u32)
    }

    #[test]
    fn writing_a_shared_chunk_copies_it_and_leaves_the_other_table_unchanged() {
        let mut a: Chunked<OwnCell, Option<u32>> = Chunked::new(70);
        for i in 0..70 {
            a[own(i)] = Some(i as u32);
        }
        let mut b = a.clone();
        assert!(a.all_same(&b, |x, y| x == y));
        b[own(33)] = Some(1000);
        assert_eq!(a[own(33)], Some(33));
        assert_eq!(b[own(33)], Some(1000));
        assert_eq!(b.iter().count(), 70);
        let c: Chunked<OwnCell, Option<u32>> = Chunked::from_vec((0..70).map(Some).collect());
        assert!(a.all_same(&c, |x, y| x == y));
        assert!(!a.all_same(&b, |x, y| x == y));
        // The chunk holding entry 33 was copied (entry 40 shares it); the others are shared.
        let shared: Vec<usize> = b.iter_shared().map(|(_, n)| n).collect();
        assert_eq!(shared[0], 2);
        assert_eq!(shared[40], 1);
        assert_eq!(shared[69], 2);
    }

    #[test]
    fn equal_chunks_are_shared_and_counted_once() {
        let mut a: Chunked<MarginCell, Option<u64>> = Chunked::new(40);
        let mut b: Chunked<MarginCell, Option<u64>> = Chunked::new(40);
        for i in 0..40 {
            a[MarginCell::at(i)] = Some(i as u64);
            b[MarginCell::at(i)] = Some(if i == 39 { 7 } else { i as u64 });
        }
        let alone = a.header_bytes() + b.header_bytes();
        b.share_equal(&a, |x, y| x == y);
        assert!(a.header_bytes() + b.header_bytes() < alone);
        assert_eq!(b[MarginCell::at(39)], Some(7));
        assert_eq!(b[MarginCell::at(3)], Some(3));
        assert_eq!(a.iter_shared().next().map(|(_, n)| n), Some(2));
    }
}
