//! Statistics on the ground floor: percentiles and a lattice of sky
//! directions for error summaries, and the multiple-comparison family that
//! the tests comparing many Monte Carlo estimates against references share
//! (a Šidák threshold per comparison plus an aggregate bias check, so that
//! an unbiased estimator does not fail by chance and a biased one cannot
//! hide below "3 sigma each").

/// The `p` quantile (nearest rank) of `v`, which it sorts; NaN if empty.
pub fn percentile(v: &mut [f64], p: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * p).round() as usize]
}

/// A Fibonacci lattice of `n` directions above the horizon: (zenith,
/// azimuth) in degrees, elevation from 0.5° up, even in solid angle.
pub fn sky_lattice(n: usize) -> Vec<(f64, f64)> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let mu_min = libm::sin(0.5f64.to_radians());
    (0..n)
        .map(|i| {
            let mu = mu_min + (1.0 - mu_min) * (i as f64 + 0.5) / n as f64;
            let az = (i as f64 * golden).to_degrees().rem_euclid(360.0);
            (libm::acos(mu).to_degrees(), az)
        })
        .collect()
}

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
        let mut out: Vec<String> = self
            .labels
            .iter()
            .zip(&self.z)
            .filter(|(_, z)| z.abs() > z_max)
            .map(|(l, z)| format!("{l}: z {z:+.2} beyond {z_max:.2}"))
            .collect();
        let aggregate = self.aggregate();
        let z_agg = sidak_z(1, alpha);
        if aggregate.abs() > z_agg {
            out.push(format!(
                "aggregate of {m}: Σz/√m = {aggregate:+.2} beyond {z_agg:.2} (a bias common to the family)"
            ));
        }
        out
    }

    pub fn aggregate(&self) -> f64 {
        self.z.iter().sum::<f64>() / (self.z.len().max(1) as f64).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sidak_threshold_matches_the_table() {
        // 72 comparisons at 1 %: z ~ 3.8 (the figure); 1 comparison: 2.576.
        assert!((sidak_z(1, 0.01) - 2.5758).abs() < 1e-3);
        assert!((sidak_z(72, 0.01) - 3.80).abs() < 0.02, "{}", sidak_z(72, 0.01));
    }
}
