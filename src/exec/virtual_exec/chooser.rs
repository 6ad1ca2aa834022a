//! The virtual executor's scheduler: turns a [`ScheduleSpec`] into one decision per turn.

use super::options::ScheduleSpec;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// The source of the virtual executor's decisions, built from a [`ScheduleSpec`].
pub(super) enum Chooser {
    /// A seeded generator.
    Seeded(Box<ChaCha8Rng>),
    /// Fuzz bytes and the next byte to read.
    Bytes(Vec<u8>, usize),
    /// Recorded decisions and the next one to take.
    Replay(Vec<u32>, usize),
    /// The deterministic fallback only.
    Fifo,
}

impl Chooser {
    /// The chooser of `spec`, at its first decision.
    pub(super) fn new(spec: &ScheduleSpec) -> Self {
        match spec {
            ScheduleSpec::Seeded(s) => Chooser::Seeded(Box::new(ChaCha8Rng::seed_from_u64(*s))),
            ScheduleSpec::Bytes(b) => Chooser::Bytes(b.clone(), 0),
            ScheduleSpec::Replay(d) => Chooser::Replay(d.clone(), 0),
            ScheduleSpec::Fifo => Chooser::Fifo,
        }
    }

    /// Index into `acts` enabled worlds followed by `msgs` in-flight messages.
    /// `laggard` is the index (among the acts) of the first enabled world with a non-empty
    /// inbox, or else of the enabled world with the smallest LVT.
    pub(super) fn choose(&mut self, acts: usize, msgs: usize, laggard: usize) -> usize {
        let total = acts + msgs;
        let fifo = |_: ()| if msgs > 0 { acts } else { laggard };
        match self {
            Chooser::Seeded(rng) => {
                if rng.random_range(0..total) >= acts {
                    // Mostly near the oldest (geometric), sometimes anywhere: deliveries are
                    // reordered and some are delayed for long, but delays stay bounded in
                    // expectation (uniform picks from a large pool make Time Warp thrash).
                    let k = if rng.random_bool(0.8) {
                        (rng.random::<u32>().trailing_zeros() as usize).min(msgs - 1)
                    } else {
                        rng.random_range(0..msgs)
                    };
                    acts + k
                } else {
                    rng.random_range(0..acts)
                }
            }
            Chooser::Bytes(b, pos) => {
                let need = if total > 256 { 2 } else { 1 };
                if *pos + need > b.len() {
                    return fifo(());
                }
                let mut v = b[*pos] as usize;
                if need == 2 {
                    v = v << 8 | b[*pos + 1] as usize;
                }
                *pos += need;
                v % total
            }
            Chooser::Replay(d, pos) => match d.get(*pos) {
                Some(&i) if (i as usize) < total => {
                    *pos += 1;
                    i as usize
                }
                _ => {
                    *pos = usize::MAX / 2;
                    fifo(())
                }
            },
            Chooser::Fifo => fifo(()),
        }
    }
}
