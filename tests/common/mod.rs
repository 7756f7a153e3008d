//! Statistics shared by the tests that compare many Monte Carlo estimates
//! against references: a multiple-comparison threshold and an aggregate
//! bias check, so that an unbiased estimator does not fail by chance and a
//! biased one cannot hide below "3 sigma each".

#![allow(dead_code)]

/// The |z| beyond which one of `m` independent two-sided comparisons fails
/// with family-wise probability `alpha` (Šidák 1967): the standard normal
/// quantile at 1 − (1 − (1 − alpha)^(1/m)) / 2, by bisection on erfc.
pub fn sidak_z(m: usize, alpha: f64) -> f64 {
    let per = 1.0 - (1.0 - alpha).powf(1.0 / m.max(1) as f64);
    let (mut lo, mut hi) = (0.0f64, 40.0f64);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        // Two-sided tail of the standard normal: erfc(z / √2).
        if libm::erfc(mid / std::f64::consts::SQRT_2) > per {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// A family of z-scores (estimate − reference) / standard error.
#[derive(Default)]
pub struct Family {
    pub labels: Vec<String>,
    pub z: Vec<f64>,
}

impl Family {
    pub fn push(&mut self, label: String, z: f64) {
        self.labels.push(label);
        self.z.push(z);
    }

    /// The failures at a family-wise false-alarm rate `alpha`: each |z|
    /// against the Šidák threshold, and the aggregate Σz / √m (standard
    /// normal when every estimate is unbiased with honest errors) against
    /// the two-sided threshold of one more comparison at `alpha`, which a
    /// bias common to the family cannot hide from.
    pub fn failures(&self, alpha: f64) -> Vec<String> {
        let m = self.z.len();
        let z_max = sidak_z(m, alpha);
        let mut out: Vec<String> = self.labels.iter().zip(&self.z).filter(|(_, z)| z.abs() > z_max).map(|(l, z)| format!("{l}: z {z:+.2} beyond {z_max:.2}")).collect();
        let aggregate = self.aggregate();
        let z_agg = sidak_z(1, alpha);
        if aggregate.abs() > z_agg {
            out.push(format!("aggregate of {m}: Σz/√m = {aggregate:+.2} beyond {z_agg:.2} (a bias common to the family)"));
        }
        out
    }

    pub fn aggregate(&self) -> f64 {
        self.z.iter().sum::<f64>() / (self.z.len().max(1) as f64).sqrt()
    }
}

#[test]
fn sidak_threshold_matches_the_table() {
    // 72 comparisons at 1 %: z ~ 3.8 (the figure); 1 comparison: 2.576.
    assert!((sidak_z(1, 0.01) - 2.5758).abs() < 1e-3);
    assert!((sidak_z(72, 0.01) - 3.80).abs() < 0.02, "{}", sidak_z(72, 0.01));
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
