//! Exploration noise ε ~ N(0, I_dU), seeded per episode so that a run replays bit for bit.
//! The one definition: the real-time loop and the learner's in-process rollouts both draw ε
//! here, so an episode over IPC and the same episode in process see the same noise.
//!
//! The generator of episode k of table version v (k counts the episodes run with that version,
//! from 0) is ChaCha8 seeded with [`episode_seed`]`(seed, v, k)`; ε_t is three successive
//! `StandardNormal` draws (rand_distr 0.5; dU of them) at t = 0, 1, …. Noise-free episodes draw nothing.

use crate::layout::DU;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// SplitMix64 finaliser: spreads nearby inputs over the whole u64 range.
#[inline]
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Seed of episode `k` of table version `version` under run seed `seed`.
pub fn episode_seed(seed: u64, version: u64, k: u64) -> u64 {
    mix(mix(mix(seed) ^ version) ^ k)
}

/// The seed of noise stream `stream` under run seed `seed`: `seed ⊕ stream · φ` (φ the 64-bit
/// golden ratio, wrapping), so stream 0 is `seed` itself and every other stream a distinct,
/// reproducible seed. A table's episode plan names its stream ([`crate::plan::EpisodePlan`]);
/// MDGPS's goal m draws from stream m + 1 in process and over IPC alike.
pub fn stream_seed(seed: u64, stream: u32) -> u64 {
    seed ^ u64::from(stream).wrapping_mul(0x9e37_79b9_7f4a_7c15)
}

/// The per-episode noise source. No allocation.
pub struct Noise {
    rng: ChaCha8Rng,
}

impl Noise {
    /// A source for episode `k` of `version`.
    pub fn new(seed: u64, version: u64, k: u64) -> Self {
        Self {
            rng: ChaCha8Rng::seed_from_u64(episode_seed(seed, version, k)),
        }
    }

    /// Re-seeds in place for another episode.
    pub fn reseed(&mut self, seed: u64, version: u64, k: u64) {
        self.rng = ChaCha8Rng::seed_from_u64(episode_seed(seed, version, k));
    }

    /// Next ε of the three-joint task.
    #[inline]
    pub fn next(&mut self) -> [f64; DU] {
        core::array::from_fn(|_| StandardNormal.sample(&mut self.rng))
    }

    /// Next ε of any task: `eps.len()` (dU) successive draws, so that at dU = 3 it is
    /// [`Noise::next`].
    #[inline]
    pub fn next_into(&mut self, eps: &mut [f64]) {
        for e in eps {
            *e = StandardNormal.sample(&mut self.rng);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seeds_differ_and_replay() {
        assert_ne!(episode_seed(0, 1, 0), episode_seed(0, 1, 1));
        assert_ne!(episode_seed(0, 1, 0), episode_seed(0, 2, 0));
        assert_ne!(episode_seed(0, 1, 0), episode_seed(1, 1, 0));
        let mut a = Noise::new(3, 4, 5);
        let mut b = Noise::new(0, 0, 0);
        b.reseed(3, 4, 5);
        for _ in 0..10 {
            assert_eq!(a.next(), b.next());
        }
    }
}
