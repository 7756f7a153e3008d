//! Helpers shared by the integration tests: the multiple-comparison family
//! (from `sky::stats`) and a small deterministic generator for mutations.

#![allow(dead_code)]

pub use sky::stats::Family;

/// Runs the `sky` binary with `args`, the Mie tables from the tests' shared
/// cache, and waits for its output.
pub fn sky(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_sky"))
        .args(args)
        .env("SKY_CACHE_DIR", sky::mie::MieCache::test_dir())
        .output()
        .unwrap()
}

/// A small deterministic generator for test mutations (SplitMix64, Steele,
/// Lea and Flood 2014), so a failing case reproduces from its seed.
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    /// The stream of case `case` of a run seeded with `seed`.
    pub fn case(seed: u64, case: u64) -> SplitMix64 {
        let mut r = SplitMix64(seed ^ case.wrapping_mul(0xD1B5_4A32_D192_ED03));
        r.next();
        r
    }

    pub fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in 0..n (0 when n is 0).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }

    pub fn pick<'a, T>(&mut self, xs: &'a [T]) -> &'a T {
        &xs[self.below(xs.len())]
    }

    /// Below `max` random bytes.
    pub fn bytes(&mut self, max: usize) -> Vec<u8> {
        let n = self.below(max);
        (0..n).map(|_| self.next() as u8).collect()
    }
}
