//! Adaptive optimism (`KernelConfig::window_auto`, SPEC.md §K14): a world's own window,
//! tuned by hill climbing on its recent rollback rate, as adaptive Time Warp schemes do.
//!
//! The world starts at [`START`] steps (or the configured window, if narrower). Every
//! [`EPOCH`] GVT advances it divides the steps it rolled back in the epoch by the steps it
//! computed. Above [`HIGH`] the window halves. Below [`LOW`], if the world reached its window
//! during the epoch (a window it never reaches holds nothing back), it tries one step more:
//! the wider window is *on trial* until the next epoch ends, and the trial fails at the first
//! GVT advance where the steps rolled back since the widening exceed the narrower window's
//! rate times the steps computed since. A failed trial goes back to the narrower window and
//! waits 1, 2, 4 … [`MAX_BACKOFF`] epochs (doubling with each failure in a row) before the
//! next widening; a trial that lasts its epoch keeps the wider window and resets the
//! back-off. Only how far the world speculates changes, never what it commits (K7).

use crate::kernel::config::{KernelConfig, RollbackMode};
use crate::kernel::counters::WorldCounters;
use crate::model::Step;

/// The window a throttled world starts with, at most the ceiling.
pub(super) const START: Step = 1;

/// GVT advances per epoch.
pub(super) const EPOCH: u32 = 8;

/// Rolled-back steps per computed step above which the window halves.
pub(super) const HIGH: f64 = 0.10;

/// Rolled-back steps per computed step below which the world tries a wider window.
pub(super) const LOW: f64 = 0.02;

/// The longest wait after failed widenings, in epochs.
pub(super) const MAX_BACKOFF: u32 = 16;

/// A world's adaptive window state.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Throttle {
    /// The configured window: the adaptive one never exceeds it.
    pub(super) ceiling: Step,
    /// The GVT the world last saw.
    seen_gvt: Step,
    /// GVT advances seen in this epoch.
    advances: u32,
    /// The world's steps computed and rolled back (its counters) when the epoch began.
    computed_at_start: u64,
    rolled_back_at_start: u64,
    /// Whether the world reached its window during this epoch.
    held: bool,
    /// While a widening is on trial (it began this epoch): the rollback rate measured at the
    /// narrower window.
    trial: Option<f64>,
    /// The epochs to wait after the next failed trial (or halving).
    backoff: u32,
    /// The epochs left to wait before the next widening.
    wait: u32,
}

impl Throttle {
    /// The throttle of a world run with `config`: `None` for a fixed window, and in
    /// conservative mode, which never rolls back.
    pub(super) fn of(config: &KernelConfig) -> Option<Throttle> {
        (config.window_auto && config.mode != RollbackMode::Conservative).then(|| Throttle {
            ceiling: config.window.max(1),
            seen_gvt: 0,
            advances: 0,
            computed_at_start: 0,
            rolled_back_at_start: 0,
            held: false,
            trial: None,
            backoff: 1,
            wait: 0,
        })
    }

    /// The window a world run with `config` starts with.
    pub(super) fn initial_window(config: &KernelConfig) -> Step {
        let ceiling = config.window.max(1);
        match Self::of(config) {
            Some(_) => START.min(ceiling),
            None => ceiling,
        }
    }

    /// Notes that the world reached its window: it may compute nothing more before GVT
    /// advances.
    pub(super) fn held_back(&mut self) {
        self.held = true;
    }

    /// The window after the world sees GVT `gvt`, given its counters `c` so far: a trial
    /// may fail at any GVT advance, and the window changes otherwise at the end of an epoch
    /// by the epoch's rollback rate.
    pub(super) fn on_gvt(&mut self, gvt: Step, window: Step, c: &WorldCounters) -> Step {
        if gvt <= self.seen_gvt {
            return window;
        }
        self.seen_gvt = gvt;
        self.advances += 1;
        let done = c.steps_computed.saturating_sub(self.computed_at_start);
        let wasted = c
            .steps_rolled_back
            .saturating_sub(self.rolled_back_at_start);
        let failed = self
            .trial
            .is_some_and(|before| wasted as f64 > before * done as f64);
        if !failed && self.advances < EPOCH {
            return window;
        }
        self.advances = 0;
        self.computed_at_start = c.steps_computed;
        self.rolled_back_at_start = c.steps_rolled_back;
        let held = std::mem::take(&mut self.held);
        if failed {
            self.trial = None;
            self.wait = self.backoff;
            self.backoff = (self.backoff * 2).min(MAX_BACKOFF);
            return (window - 1).max(1);
        }
        if done == 0 {
            return window;
        }
        if self.trial.take().is_some() {
            // The wider window lasted its epoch without more rollbacks: keep it.
            self.backoff = 1;
        }
        let rate = wasted as f64 / done as f64;
        if rate > HIGH {
            self.wait = self.backoff;
            (window / 2).max(1)
        } else if self.wait > 0 {
            self.wait -= 1;
            window
        } else if rate < LOW && held && window < self.ceiling {
            self.trial = Some(rate);
            window + 1
        } else {
            window
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn auto(window: u64) -> KernelConfig {
        KernelConfig::new(2).window(window).window_auto(true)
    }

    #[test]
    fn a_fixed_window_or_conservative_mode_has_no_throttle() {
        assert_eq!(Throttle::of(&KernelConfig::new(2).window(16)), None);
        assert_eq!(
            Throttle::initial_window(&KernelConfig::new(2).window(16)),
            16
        );
        let conservative = auto(16).mode(RollbackMode::Conservative);
        assert_eq!(Throttle::of(&conservative), None);
        assert_eq!(Throttle::initial_window(&conservative), 16);
    }

    /// A world under test: its throttle, window, GVT and counters.
    struct Run {
        t: Throttle,
        w: Step,
        gvt: Step,
        c: WorldCounters,
    }

    impl Run {
        fn new(ceiling: Step) -> Run {
            Run {
                t: Throttle::of(&auto(ceiling)).unwrap(),
                w: Throttle::initial_window(&auto(ceiling)),
                gvt: 0,
                c: WorldCounters::default(),
            }
        }

        /// One GVT advance during which the world computes `done` steps, rolls back
        /// `wasted` and, if `held`, reaches its window. Returns the window after it.
        fn advance(&mut self, done: u64, wasted: u64, held: bool) -> Step {
            self.c.steps_computed += done;
            self.c.steps_rolled_back += wasted;
            if held {
                self.t.held_back();
            }
            self.gvt += 1;
            self.w = self.t.on_gvt(self.gvt, self.w, &self.c);
            // A repeated GVT is no advance.
            assert_eq!(self.t.on_gvt(self.gvt, self.w, &self.c), self.w);
            self.w
        }

        /// One epoch: `done` steps computed and `wasted` rolled back at its last advance,
        /// the window reached at every advance if `held`. Returns the window after it,
        /// checking that it changed only at the end.
        fn epoch(&mut self, done: u64, wasted: u64, held: bool) -> Step {
            let before = self.w;
            for _ in 1..EPOCH {
                assert_eq!(
                    self.advance(0, 0, held),
                    before,
                    "changed before the epoch's end"
                );
            }
            self.advance(done, wasted, held)
        }
    }

    #[test]
    fn the_window_halves_when_rollbacks_waste_much_and_widens_while_widening_costs_nothing() {
        let mut r = Run::new(3);
        assert_eq!(r.w, START.min(3));
        for want in [2, 3, 3] {
            assert_eq!(
                r.epoch(100, 1, true),
                want,
                "1 % wasted: wider, up to the ceiling"
            );
        }
        assert_eq!(r.epoch(100, 5, true), 3, "5 %: kept");
        assert_eq!(r.epoch(100, 30, true), 1, "30 %: halved");
        assert_eq!(r.epoch(100, 50, true), 1, "never below 1");
    }

    #[test]
    fn a_world_that_never_reaches_its_window_keeps_it() {
        let mut r = Run::new(8);
        for _ in 0..4 {
            assert_eq!(r.epoch(100, 0, false), 1);
        }
        assert_eq!(r.epoch(100, 0, true), 2);
    }

    #[test]
    fn a_widening_that_costs_rollbacks_is_undone_at_once_and_retried_after_a_growing_wait() {
        let mut r = Run::new(8);
        let mut waits = Vec::new();
        for _ in 0..4 {
            // Clean epochs until the world tries 2 steps.
            let mut waited = 0;
            while r.epoch(100, 0, true) == 1 {
                waited += 1;
            }
            waits.push(waited);
            // The first rollback at the wider window ends the trial, mid-epoch.
            assert_eq!(r.advance(0, 0, true), 2);
            assert_eq!(r.advance(10, 1, true), 1, "the trial failed at once");
        }
        assert_eq!(waits, [0, 1, 2, 4], "1, 2, 4 … epochs between trials");
        // A trial that lasts its epoch keeps the wider window and resets the back-off.
        let mut waited = 0;
        while r.epoch(100, 0, true) == 1 {
            waited += 1;
        }
        assert_eq!(waited, 8);
        assert_eq!(
            r.epoch(100, 0, true),
            3,
            "kept, and the next step is tried at once"
        );
    }

    #[test]
    fn the_back_off_is_bounded_and_a_halving_also_waits() {
        let mut r = Run::new(4);
        for _ in 0..10 {
            while r.epoch(100, 0, true) == 1 {}
            r.advance(10, 1, true);
        }
        let mut waited = 0;
        while r.epoch(100, 0, true) == 1 {
            waited += 1;
        }
        assert_eq!(waited, MAX_BACKOFF);
        // Climb to the ceiling (each trial lasts its epoch), then halve: no widening for
        // one epoch.
        assert_eq!(r.epoch(100, 0, true), 3);
        assert_eq!(r.epoch(100, 0, true), 4);
        assert_eq!(r.epoch(100, 0, true), 4, "the ceiling");
        assert_eq!(r.epoch(100, 20, true), 2, "20 %: halved");
        assert_eq!(r.epoch(100, 0, true), 2, "waits one epoch");
        assert_eq!(r.epoch(100, 0, true), 3);
    }
}
