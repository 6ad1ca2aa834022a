//! A cell's states in one shared, immutable allocation behind a thin pointer.
//!
//! The logs hold, per step, a header per cell that points at the cell's states (SPEC.md §K3);
//! outputs, next states, ghost views, the log of what was sent and received messages share
//! one allocation. `Arc<[S]>` is a fat pointer (16 bytes); [`SharedStates`] keeps the length
//! in the allocation, beside the count, so a header takes 8 bytes and `Option` of it too.

use std::ops::Deref;
use triomphe::ThinArc;

/// Id-sorted states of one cell, shared (cloning copies a pointer, never a state).
pub struct SharedStates<S>(ThinArc<(), S>);

impl<S> SharedStates<S> {
    /// The states of `v`, moved into one new allocation.
    pub fn from_vec(v: Vec<S>) -> Self {
        SharedStates::from_exact(v.into_iter())
    }

    /// The states of `items`, written straight into one new allocation.
    pub fn from_exact(items: impl ExactSizeIterator<Item = S>) -> Self {
        SharedStates(ThinArc::from_header_and_iter((), items))
    }

    /// Whether `a` and `b` are the same allocation.
    pub fn ptr_eq(a: &Self, b: &Self) -> bool {
        a.0.ptr() == b.0.ptr()
    }

    /// How many holders share the allocation.
    pub fn strong_count(a: &Self) -> usize {
        ThinArc::strong_count(&a.0)
    }

    /// Bytes of the allocation: the count and the length (16), then the states.
    pub fn allocation_bytes(&self) -> usize {
        16 + self.len() * std::mem::size_of::<S>()
    }
}

impl<S> Clone for SharedStates<S> {
    fn clone(&self) -> Self {
        SharedStates(self.0.clone())
    }
}

impl<S> Deref for SharedStates<S> {
    type Target = [S];

    fn deref(&self) -> &[S] {
        &self.0.slice
    }
}

impl<S: std::fmt::Debug> std::fmt::Debug for SharedStates<S> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.iter()).finish()
    }
}

impl<S: Clone> From<&[S]> for SharedStates<S> {
    fn from(s: &[S]) -> Self {
        SharedStates::from_exact(s.iter().cloned())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_shared_cell_state_is_one_thin_pointer_and_clones_share_it() {
        assert_eq!(std::mem::size_of::<Option<SharedStates<[u8; 72]>>>(), 8);
        let a = SharedStates::from_vec(vec![1u64, 2, 3]);
        let b = a.clone();
        assert!(SharedStates::ptr_eq(&a, &b));
        assert_eq!(SharedStates::strong_count(&a), 2);
        assert_eq!(&*b, &[1, 2, 3]);
        assert_eq!(a.allocation_bytes(), 16 + 3 * 8);
        let c = SharedStates::from(&[1u64, 2, 3][..]);
        assert!(!SharedStates::ptr_eq(&a, &c));
        assert_eq!(&*a, &*c);
        drop(b);
        assert_eq!(SharedStates::strong_count(&a), 1);
    }
}
