//! The crate's seeded random numbers: the SplitMix64 generator and its one-step mixers.
//!
//! Owns: [`SplitMix64`] (the stream every seeded draw in the crate comes from — racks, shots, PHYRE
//! actions, I-PHYRE clicks, scatter layouts, annealing, island sampling), the bare mixing functions
//! ([`splitmix64`], [`finalize`]) that seed derivations and retry jitter use, and [`keyed_stream`],
//! the generator of item `index`, sample `sample` of a seeded dataset.
//!
//! Guarantee: **the streams are part of the output format.** A seed names the same racks, shots,
//! actions and tables in every version; a change to any function here changes datasets and
//! fingerprints, so the tests below pin known values. Not cryptographic; for hashes of content see
//! [`crate::digest`].
//!
//! Does not own: what the draws mean (each environment's sampler), nor SHA-256-based seed mixing of
//! strings and word lists ([`crate::digest::sha256_u64`]).

/// The golden-ratio increment of SplitMix64 (2⁶⁴/φ, odd).
pub const GOLDEN: u64 = 0x9E37_79B9_7F4A_7C15;

/// SplitMix64's output function (Stafford's "Mix13" variant): mixes `z` into 64 well-spread bits
/// without the increment. [`splitmix64`] is `finalize(z + GOLDEN)`.
pub fn finalize(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// One SplitMix64 step as a pure function: the first output of a generator seeded with `x`
/// (`SplitMix64::new(x).next_u64()`).
pub fn splitmix64(x: u64) -> u64 {
    finalize(x.wrapping_add(GOLDEN))
}

/// 53 random bits of `bits` as a float uniform in [0, 1) (the top 53, scaled by 2⁻⁵³, exactly).
pub fn unit_f64(bits: u64) -> f64 {
    (bits >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// SplitMix64: tiny, seedable, good enough for layouts and random shots.
#[derive(Debug, Clone)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    /// A generator seeded with `seed`.
    pub fn new(seed: u64) -> Self {
        SplitMix64(seed)
    }
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(GOLDEN);
        finalize(self.0)
    }
    /// Uniform in [0, 1).
    pub fn next_f64(&mut self) -> f64 {
        unit_f64(self.next_u64())
    }
    /// Uniform in [lo, hi).
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next_f64()
    }
    /// Uniform in 0..n (0 when n = 0).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_f64() * n as f64) as usize % n.max(1)
    }
}

/// The generator of sample `sample` of item `index` in a dataset whose seed, xor-ed with the
/// environment's `salt`, is `salted_seed`. It depends on nothing else, so a dataset is the same
/// whatever its sharding or thread count. (PHYRE actions and I-PHYRE click sets; the billiards
/// environment derives its racks and shots differently, see `envs::pool::rack`.)
pub fn keyed_stream(salted_seed: u64, index: u64, sample: u64) -> SplitMix64 {
    let a = splitmix64(salted_seed);
    SplitMix64::new(a ^ index.wrapping_mul(GOLDEN) ^ sample.wrapping_mul(0xD1B5_4A32_D192_ED03))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The reference outputs of SplitMix64 seeded with 0 and 1234567 (from the published C code);
    /// changing them changes every seeded dataset.
    #[test]
    fn streams_match_the_reference_generator() {
        let mut r = SplitMix64::new(0);
        assert_eq!(r.next_u64(), 0xE220_A839_7B1D_CDAF);
        assert_eq!(r.next_u64(), 0x6E78_9E6A_A1B9_65F4);
        let mut r = SplitMix64::new(1_234_567);
        let want = [
            6_457_827_717_110_365_317u64,
            3_203_168_211_198_807_973,
            9_817_491_932_198_370_423,
            4_593_380_528_125_082_431,
            16_408_922_859_458_223_821,
        ];
        for w in want {
            assert_eq!(r.next_u64(), w);
        }
    }

    #[test]
    fn mixers_are_steps_of_the_generator() {
        for x in [0u64, 1, 42, u64::MAX, GOLDEN] {
            assert_eq!(splitmix64(x), SplitMix64::new(x).next_u64());
            assert_eq!(finalize(x.wrapping_add(GOLDEN)), splitmix64(x));
        }
        assert_ne!(finalize(7), splitmix64(7));
    }

    #[test]
    fn floats_are_in_the_unit_interval_and_below_is_in_range() {
        assert_eq!(unit_f64(0), 0.0);
        assert!(unit_f64(u64::MAX) < 1.0);
        let mut r = SplitMix64::new(9);
        for n in [1usize, 2, 7, 100] {
            for _ in 0..200 {
                assert!(r.below(n) < n);
                let u = r.uniform(-2.0, 3.0);
                assert!((-2.0..3.0).contains(&u));
            }
        }
        assert_eq!(r.below(0), 0);
    }

    #[test]
    fn keyed_streams_differ_by_index_and_sample_and_repeat() {
        let a = keyed_stream(5, 1, 2).next_u64();
        assert_eq!(a, keyed_stream(5, 1, 2).next_u64());
        assert_ne!(a, keyed_stream(5, 2, 1).next_u64());
        assert_ne!(a, keyed_stream(6, 1, 2).next_u64());
    }
}
