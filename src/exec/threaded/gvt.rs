//! GVT without stopping the world (SPEC.md §K7): a round takes the minimum of the published
//! bounds and accepts it only if no bound was raised meanwhile; the stall check looks at the
//! full cut when nothing has moved for long.

use super::shared::SharedRun;
use crate::exec::error::ExecError;
use crate::exec::sync::{Facade, FacadeAtomic, FacadeMutex};
use crate::kernel::trace::GvtSample;
use crate::model::{CellModel, Step};

impl<M: CellModel + 'static, F: Facade> SharedRun<M, F> {
    /// A GVT round from the published bounds, without stopping any world: a snapshot is
    /// accepted only if no bound was raised while it was read (SPEC.md §K7). Returns whether
    /// GVT advanced (every world is then scheduled, to commit and fossil-collect).
    pub(super) fn gvt_round(&self) -> bool {
        if self.gvt_round.swap(1) == 1 {
            return false;
        }
        let mut advanced = false;
        for _ in 0..4 {
            let before = self.version.load();
            let mut least =
                (self.target.load() + 1).min(self.delivered.load() + 1 + self.undelivered);
            for w in 0..self.worlds.len() {
                least = least
                    .min(self.published[w].load())
                    .min(self.inbox_min[w].load());
            }
            if self.version.load() != before {
                continue;
            }
            let old = self.gvt.load();
            if least > old {
                self.gvt.store(least);
                let mut out = self.out.lock();
                out.gvt_advances += 1;
                if self.trace {
                    out.gvt_samples.push(GvtSample {
                        time: self.started.elapsed().as_secs_f64(),
                        gvt: least,
                    });
                }
                drop(out);
                advanced = true;
            }
            break;
        }
        self.gvt_round.store(0);
        if advanced {
            for w in 0..self.worlds.len() {
                self.schedule(w);
            }
        }
        advanced
    }

    /// Under the full cut (every world lock, then every inbox lock): fails the run if no
    /// world can act, no message is pending and frames are missing (a kernel bug).
    pub(super) fn check_stall(&self) {
        let worlds: Vec<_> = self.worlds.iter().map(|m| m.lock()).collect();
        let inboxes: Vec<_> = self.inboxes.iter().map(|m| m.lock()).collect();
        let gvt = self.gvt.load();
        let pending = inboxes.iter().any(|i| !i.is_empty());
        let can_act = worlds.iter().any(|s| s.world.wants_to_act(gvt));
        let to_commit = worlds
            .iter()
            .any(|s| s.contributed < (gvt - 1).min(self.target.load()));
        let bounds = worlds
            .iter()
            .map(|s| s.world.bound())
            .min()
            .unwrap_or(Step::MAX);
        if !pending
            && !can_act
            && !to_commit
            && bounds <= gvt
            && self.committed.load() < self.target.load()
        {
            drop(inboxes);
            drop(worlds);
            self.fail(ExecError::Stalled { gvt });
        }
    }
}
