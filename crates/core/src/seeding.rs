//! One seeded generator type for the whole workspace.
//!
//! Every random number in tandem (network initialization, dropout masks, exploration noise,
//! minibatch indices, environment resets, planner populations) is drawn from [`Rng`], a ChaCha8
//! stream: portable across platforms, fast, and serializable, so a checkpoint can store and
//! restore the exact position of a stream. candle's own CPU generator cannot be seeded and is never
//! used.
//!
//! ```
//! use tandem_core::seeding::{rng_from_seed, SeedStream};
//! use rand::Rng as _;
//!
//! let mut a = rng_from_seed(7);
//! let mut b = rng_from_seed(7);
//! assert_eq!(a.random::<u64>(), b.random::<u64>());
//!
//! // Independent sub-streams for independent parts of one run.
//! let seeds = SeedStream::new(7);
//! let mut init = seeds.rng("actor-init");
//! let mut noise = seeds.rng("exploration");
//! assert_ne!(init.random::<u64>(), noise.random::<u64>());
//! ```

use rand::SeedableRng;

/// The generator every tandem component draws from.
pub type Rng = rand_chacha::ChaCha8Rng;

/// A generator seeded by `seed`.
pub fn rng_from_seed(seed: u64) -> Rng {
    Rng::seed_from_u64(seed)
}

/// Derives named, independent sub-seeds from one run seed, so that adding a random draw to one
/// component does not shift the numbers of another.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct SeedStream {
    seed: u64,
}

impl SeedStream {
    /// A stream rooted at `seed`.
    pub fn new(seed: u64) -> Self {
        Self { seed }
    }

    /// The root seed.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// A sub-seed for the component called `name` (a stable hash of seed and name).
    pub fn derive(&self, name: &str) -> u64 {
        // FNV-1a over the name, mixed with the seed through SplitMix64: stable across Rust
        // versions, unlike `std::hash`.
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for b in name.as_bytes() {
            h ^= u64::from(*b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
        splitmix64(self.seed ^ splitmix64(h))
    }

    /// A generator for the component called `name`.
    pub fn rng(&self, name: &str) -> Rng {
        rng_from_seed(self.derive(name))
    }
}

fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng as _;

    #[test]
    fn equal_seeds_equal_streams_and_names_separate_them() {
        let s = SeedStream::new(3);
        assert_eq!(s.derive("a"), SeedStream::new(3).derive("a"));
        assert_ne!(s.derive("a"), s.derive("b"));
        assert_ne!(s.derive("a"), SeedStream::new(4).derive("a"));
        let x: Vec<u32> = (0..4).map(|_| s.rng("a").random()).collect();
        assert!(x.windows(2).all(|w| w[0] == w[1]));
    }
}
