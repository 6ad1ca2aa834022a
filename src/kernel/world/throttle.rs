//! Adaptive optimism (`KernelConfig::window_auto`, SPEC.md §K14): a world's own window,
//! throttled by its recent rollback rate, as adaptive Time Warp schemes do. Every
//! [`EPOCH`] GVT advances the world sees, it compares the steps it rolled back in that epoch
//! with the steps it computed: above [`HIGH`] it halves its window (its speculation was
//! mostly wasted), below [`LOW`] it widens it by one step, up to the configured window. A
//! world starts at [`START`] steps (or the configured window, if narrower). Only how far the
//! world speculates changes, never what it commits (K7).

use crate::kernel::config::{KernelConfig, RollbackMode};
use crate::model::Step;

/// The window a throttled world starts with, at most the ceiling.
pub(super) const START: Step = 1;

/// GVT advances per epoch.
pub(super) const EPOCH: u32 = 8;

/// Rolled-back steps per computed step above which the window halves.
pub(super) const HIGH: f64 = 0.10;

/// Rolled-back steps per computed step below which the window widens.
pub(super) const LOW: f64 = 0.02;

/// A world's adaptive window state.
#[derive(Clone, Debug, PartialEq, Eq)]
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

    /// The window after the world sees GVT `gvt`, given its steps `computed` and
    /// `rolled_back` so far (its counters): changed at the end of an epoch by the epoch's
    /// rollback rate.
    pub(super) fn on_gvt(
        &mut self,
        gvt: Step,
        window: Step,
        computed: u64,
        rolled_back: u64,
    ) -> Step {
        if gvt <= self.seen_gvt {
            return window;
        }
        self.seen_gvt = gvt;
        self.advances += 1;
        if self.advances < EPOCH {
            return window;
        }
        let done = computed.saturating_sub(self.computed_at_start);
        let wasted = rolled_back.saturating_sub(self.rolled_back_at_start);
        self.advances = 0;
        self.computed_at_start = computed;
        self.rolled_back_at_start = rolled_back;
        if done == 0 {
            return window;
        }
        let rate = wasted as f64 / done as f64;
        if rate > HIGH {
            (window / 2).max(1)
        } else if rate < LOW {
            (window + 1).min(self.ceiling)
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

    /// Runs one epoch of GVT advances from `gvt`, computing `done` steps of which `wasted`
    /// were rolled back, and returns the window after it.
    fn epoch(
        t: &mut Throttle,
        gvt: &mut Step,
        w: Step,
        c: &mut (u64, u64),
        done: u64,
        wasted: u64,
    ) -> Step {
        let mut w = w;
        for k in 0..EPOCH {
            *gvt += 1;
            if k + 1 == EPOCH {
                c.0 += done;
                c.1 += wasted;
            }
            let before = w;
            w = t.on_gvt(*gvt, w, c.0, c.1);
            if k + 1 < EPOCH {
                assert_eq!(w, before, "the window changes only at the end of an epoch");
            }
            // A repeated GVT is no advance.
            assert_eq!(t.on_gvt(*gvt, w, c.0, c.1), w);
        }
        w
    }

    #[test]
    fn the_window_halves_when_rollbacks_waste_much_widens_when_they_waste_little() {
        let mut t = Throttle::of(&auto(3)).unwrap();
        let mut w = Throttle::initial_window(&auto(3));
        assert_eq!(w, START.min(3));
        let (mut gvt, mut c) = (0, (0u64, 0u64));
        for want in [2, 3, 3] {
            w = epoch(&mut t, &mut gvt, w, &mut c, 100, 1); // 1 % wasted: wider
            assert_eq!(w, want, "widening up to the ceiling");
        }
        w = epoch(&mut t, &mut gvt, w, &mut c, 100, 5); // 5 %: kept
        assert_eq!(w, 3);
        w = epoch(&mut t, &mut gvt, w, &mut c, 100, 30); // 30 %: halved
        assert_eq!(w, 1);
        w = epoch(&mut t, &mut gvt, w, &mut c, 100, 50);
        assert_eq!(w, 1, "never below 1");
    }
}
