//! Cell mode's repair waits for announced ghosts (SPEC.md §K5): a dirty cell next to a
//! margin cell whose view at its step a delta ghost announced to change (`follows`) is not
//! re-executed until that ghost arrives, since its arrival would dirty the cell again.

use super::index::OwnCell;
use super::keys::RecvKey;
use super::territory::NbKind;
use super::World;
use crate::kernel::config::RollbackMode;
use crate::kernel::message::MessageKind;
use crate::model::{CellModel, Step};
use std::collections::BTreeSet;

impl<M: CellModel> World<M> {
    /// Cell mode with delta ghosts: removes from the dirty cells of step `s` those that wait
    /// (occupied, next to a margin cell whose view at `s` is announced to change: the
    /// effective ghost of `s − 1` `follows` and none of `s` is effective yet) and returns
    /// them; the empty set otherwise (K5).
    pub(super) fn take_waiting(&mut self, s: Step) -> BTreeSet<OwnCell> {
        if self.mode != RollbackMode::Cell || !self.delta() {
            return BTreeSet::new();
        }
        let i = self.si(s);
        if i == 0 {
            return BTreeSet::new();
        }
        let Some(dirty) = self.dirty.get(&s) else {
            return BTreeSet::new();
        };
        let waiting: BTreeSet<OwnCell> = dirty
            .iter()
            .copied()
            .filter(|&x| {
                !self.slots[i].state(x).is_empty()
                    && self.nbrs[x].iter().any(|nb| match nb.kind() {
                        NbKind::Margin(m) => self.announced(self.margin[m.index()], i),
                        _ => false,
                    })
            })
            .collect();
        if !waiting.is_empty() {
            let dirty = self.dirty.get_mut(&s).expect("dirty step");
            dirty.retain(|x| !waiting.contains(x));
            if dirty.is_empty() {
                self.dirty.remove(&s);
            }
        }
        waiting
    }

    /// Whether the view of foreign cell `src` at slot `i ≥ 1` is announced to change: the
    /// effective ghost of the step before `follows` and no ghost of this step is effective.
    fn announced(&self, src: u32, i: usize) -> bool {
        let key = RecvKey {
            kind: MessageKind::Ghost,
            src_cell: src,
        };
        self.slots[i - 1]
            .recv
            .get(&key)
            .and_then(|r| r.effective())
            .is_some_and(|e| e.follows)
            && self.slots[i]
                .recv
                .get(&key)
                .is_none_or(|r| r.effective().is_none())
    }
}
