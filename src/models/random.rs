//! Per-entity, per-step randomness for models: a ChaCha8 generator seeded from the model's
//! seed, the entity and the step, so a draw depends on nothing but those (never on the
//! order cells are computed in, or on which world computes them).

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// SplitMix64's finaliser: spreads the bits of `x`.
fn mix(mut x: u64) -> u64 {
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^ (x >> 31)
}

/// The generator of entity `id` at step `step` under the model seed `seed`.
pub(crate) fn entity_rng(seed: u64, id: u64, step: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(mix(seed ^ mix(id ^ mix(step))))
}
