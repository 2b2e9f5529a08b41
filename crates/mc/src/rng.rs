//! Counter-based random numbers: every path owns a stream keyed by (seed, batch, path), so
//! results are bitwise identical for any number of threads.

/// SplitMix64's finaliser: a bijective 64-bit mix with full avalanche.
#[inline]
fn mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The random stream of one path: uniform numbers are `mix(key + counter·γ)`, the
/// SplitMix64 construction evaluated at a counter instead of a running state.
#[derive(Debug, Clone)]
pub struct PathRng {
    key: u64,
    counter: u64,
}

impl PathRng {
    /// The stream of path `path` in batch `batch` of a run seeded with `seed`.
    pub fn new(seed: u64, batch: u64, path: u64) -> Self {
        Self {
            key: mix(mix(seed ^ 0x6A09_E667_F3BC_C909).wrapping_add(batch))
                .wrapping_add(mix(path.wrapping_add(0x3C6E_F372_FE94_F82B))),
            counter: 0,
        }
    }

    /// A uniform number in [0, 1) with 53 random bits.
    #[inline]
    pub fn uniform(&mut self) -> f64 {
        self.counter = self.counter.wrapping_add(1);
        let bits = mix(self
            .key
            .wrapping_add(self.counter.wrapping_mul(0x9E37_79B9_7F4A_7C15)));
        (bits >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Two uniform numbers.
    #[inline]
    pub fn uniform2(&mut self) -> [f64; 2] {
        [self.uniform(), self.uniform()]
    }
}
