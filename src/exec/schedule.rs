//! Where every world's task is in the threaded executor (SPEC.md §10): the ready set,
//! ordered critical path first, and each world's [`Task`] place. Pure bookkeeping, kept
//! under one lock by the executor so a task is never lost or queued twice when a waiting
//! world is woken; the waiting queue itself (a crossbeam `Injector` of tokens) lives in the
//! executor, and a token is live only while its world's place still holds it.

use crate::model::Step;
use std::cmp::Reverse;
use std::collections::BTreeSet;

/// The order of ready worlds: (published bound, longest last computation first, world).
pub(crate) type ReadyKey = (Step, Reverse<u64>, usize);

/// Where a world's task is. At most one live copy of a task exists: in the ready set, as a
/// live waiting token, or taken by a thread that has not yet locked the world.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Task {
    /// Not queued: a message or a GVT advance queues it.
    Idle,
    /// In the ready set.
    Ready,
    /// Waiting under this token; tokens handed out before it are stale.
    Waiting(u64),
    /// Taken by a thread, about to be locked.
    Taken,
}

/// The ready set and every world's [`Task`].
#[derive(Debug)]
pub(crate) struct Schedule {
    /// The worlds ready to act, best first ([`ReadyKey`]): the laggard (lowest published
    /// bound) first and, among worlds at the same step, the one whose last computation took
    /// longest — the critical path of a near-lockstep run — then by id.
    ready: BTreeSet<ReadyKey>,
    task: Vec<Task>,
    /// The last waiting token handed out.
    tokens: u64,
}

impl Schedule {
    /// `worlds` idle worlds.
    pub(crate) fn new(worlds: usize) -> Self {
        Schedule {
            ready: BTreeSet::new(),
            task: vec![Task::Idle; worlds],
            tokens: 0,
        }
    }

    /// Forgets every task (a new epoch queues every world again); waiting tokens go stale.
    pub(crate) fn reset(&mut self) {
        self.ready.clear();
        self.task.fill(Task::Idle);
    }

    /// Queues world `key.2` in the ready set unless it is already ready or taken. A waiting
    /// world moves to the ready set (its token goes stale): what woke it (a message, a GVT
    /// advance) may let it act, and it must not wait behind worlds that are still blocked.
    pub(crate) fn wake(&mut self, key: ReadyKey) {
        let w = key.2;
        if matches!(self.task[w], Task::Idle | Task::Waiting(_)) {
            self.task[w] = Task::Ready;
            self.ready.insert(key);
        }
    }

    /// Sends world `w` to the waiting queue: returns the fresh token to push, or `None` if
    /// the world is ready (a message queued it while its turn decided to wait: it stays
    /// ready, to run again).
    pub(crate) fn wait(&mut self, w: usize) -> Option<u64> {
        if self.task[w] == Task::Ready {
            return None;
        }
        self.tokens += 1;
        self.task[w] = Task::Waiting(self.tokens);
        Some(self.tokens)
    }

    /// Takes a ready world: among those at the lowest published bound (the laggards, all
    /// equally behind), the best one for which `prefer` holds (the threaded executor
    /// prefers a world the taking thread ran last: its states are in that core's cache),
    /// else the best ready world. Worlds for which `leave` holds are not taken (another
    /// thread is about to take them).
    pub(crate) fn take_ready_preferring(
        &mut self,
        prefer: impl Fn(usize) -> bool,
        leave: impl Fn(usize) -> bool,
    ) -> Option<usize> {
        let mut takeable = self.ready.iter().filter(|k| !leave(k.2));
        let best = *takeable.next()?;
        let key = std::iter::once(&best)
            .chain(takeable.take_while(|k| k.0 == best.0))
            .find(|k| prefer(k.2))
            .copied()
            .unwrap_or(best);
        self.ready.remove(&key);
        let w = key.2;
        self.task[w] = Task::Taken;
        Some(w)
    }

    /// Takes world `w` from the waiting queue if `token` is still its live token; `false`
    /// for a stale token (the world was woken since), which the caller drops.
    pub(crate) fn take_waiting(&mut self, w: usize, token: u64) -> bool {
        let live = self.task[w] == Task::Waiting(token);
        if live {
            self.task[w] = Task::Taken;
        }
        live
    }

    /// World `w` is locked by the thread that took it: its task is idle again, so a message
    /// arriving from now on queues it anew.
    pub(crate) fn locked(&mut self, w: usize) {
        self.task[w] = Task::Idle;
    }

    /// Whether any world is ready.
    pub(crate) fn any_ready(&self) -> bool {
        !self.ready.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The best ready world, no preference.
    fn best(s: &mut Schedule) -> Option<usize> {
        s.take_ready_preferring(|_| false, |_| false)
    }

    fn key(bound: Step, w: usize) -> ReadyKey {
        (bound, Reverse(0), w)
    }

    #[test]
    fn a_preferred_world_is_taken_first_only_among_the_laggards() {
        let mut s = Schedule::new(3);
        s.wake((5, Reverse(9), 0));
        s.wake((5, Reverse(1), 1));
        s.wake((7, Reverse(1), 2));
        assert_eq!(
            s.take_ready_preferring(|w| w == 2, |_| false),
            Some(0),
            "world 2 is ahead"
        );
        assert_eq!(s.take_ready_preferring(|w| w == 2, |_| false), Some(1));
        s.locked(0);
        s.locked(1);
        s.wake((5, Reverse(9), 0));
        s.wake((5, Reverse(1), 1));
        assert_eq!(
            s.take_ready_preferring(|w| w == 1, |_| false),
            Some(1),
            "equally behind: preferred"
        );
        assert_eq!(
            s.take_ready_preferring(|_| false, |w| w == 0),
            Some(2),
            "0 is left"
        );
        assert_eq!(s.take_ready_preferring(|_| false, |w| w == 0), None);
        assert_eq!(best(&mut s), Some(0));
        assert_eq!(s.take_ready_preferring(|_| true, |_| false), None);
    }

    #[test]
    fn waking_a_waiting_world_makes_it_ready_and_its_token_stale() {
        let mut s = Schedule::new(2);
        s.wake(key(1, 0));
        assert_eq!(best(&mut s), Some(0));
        s.locked(0);
        let token = s.wait(0).expect("an idle world waits");
        s.wake(key(1, 0));
        assert_eq!(best(&mut s), Some(0), "woken into the ready set");
        assert!(!s.take_waiting(0, token), "the old token is stale");
    }

    #[test]
    fn a_world_is_queued_at_most_once() {
        let mut s = Schedule::new(2);
        s.wake(key(3, 1));
        s.wake(key(2, 1));
        assert_eq!(best(&mut s), Some(1));
        assert_eq!(best(&mut s), None, "the second wake queued no copy");
        // Taken (not yet locked): a wake adds no copy either; the taker will see the news.
        s.wake(key(2, 1));
        assert!(!s.any_ready());
    }

    #[test]
    fn a_world_woken_during_its_turn_stays_ready_instead_of_waiting() {
        let mut s = Schedule::new(1);
        s.wake(key(1, 0));
        assert_eq!(best(&mut s), Some(0));
        s.locked(0);
        s.wake(key(1, 0));
        assert_eq!(s.wait(0), None);
        assert_eq!(best(&mut s), Some(0));
    }

    #[test]
    fn the_laggard_is_taken_first_then_the_longest_computation() {
        let mut s = Schedule::new(3);
        s.wake((5, Reverse(10), 0));
        s.wake((4, Reverse(1), 1));
        s.wake((5, Reverse(90), 2));
        let order: Vec<_> = std::iter::from_fn(|| best(&mut s)).collect();
        assert_eq!(order, vec![1, 2, 0]);
    }

    #[test]
    fn only_the_latest_token_of_a_waiting_world_is_live() {
        let mut s = Schedule::new(1);
        let first = s.wait(0).expect("idle");
        assert!(s.take_waiting(0, first));
        s.locked(0);
        let second = s.wait(0).expect("idle");
        assert!(!s.take_waiting(0, first), "stale");
        assert!(s.take_waiting(0, second));
        assert!(!s.take_waiting(0, second), "taken once");
    }
}
