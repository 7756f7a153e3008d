//! Tabulated phase functions: the angle grid that resolves a coarse-mode
//! forward peak, inverse-CDF tables for importance sampling, and the
//! analytic approximations the talk compares against (Henyey–Greenstein,
//! Cornette–Shanks).

use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// The scattering-angle grid (degrees) of phase tables: 0.02° steps to 2°,
/// 0.1° to 20°, 0.5° to 180° — 601 angles. The diffraction peak of a sphere
/// is about 1/x rad wide, so 0.02° resolves it up to x ≈ 3000 over a
/// distribution (a 4 µm coarse mode at 400 nm has x ≈ 63).
pub fn phase_grid_deg() -> Vec<f64> {
    let mut a = Vec::with_capacity(601);
    for i in 0..100 {
        a.push(i as f64 * 0.02);
    }
    for i in 0..180 {
        a.push(2.0 + i as f64 * 0.1);
    }
    for i in 0..=320 {
        a.push(20.0 + i as f64 * 0.5);
    }
    a
}

/// A phase function tabulated on scattering angles, used by the renderer
/// both to evaluate and to sample: between table angles it is linear in
/// μ = cos θ, so its integral over each interval is exact, sampling inverts a
/// quadratic, and the sampling density equals the evaluated function (the
/// path weight after sampling is exactly 1).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PhaseTable {
    /// Cosines of the table angles, increasing (θ from 180° down to 0°).
    pub mu: Vec<f64>,
    /// p at those cosines divided by `integral`, sr⁻¹ (normalised to 1).
    pub p_sr_inv: Vec<f64>,
    /// Cumulative probability at each `mu` (0 at μ = −1, 1 at μ = 1).
    pub cdf: Vec<f64>,
    /// The integral over the sphere of the input table (1 up to the
    /// discretisation of the input).
    pub integral: f64,
}

impl PhaseTable {
    /// From p(θ) at increasing angles in degrees (must span 0 to 180).
    pub fn new(angles_deg: &[f64], p_sr_inv: &[f64]) -> PhaseTable {
        assert_eq!(angles_deg.len(), p_sr_inv.len());
        assert!(angles_deg.len() >= 2 && angles_deg[0] == 0.0 && *angles_deg.last().unwrap() == 180.0);
        let mut mu: Vec<f64> = angles_deg.iter().rev().map(|a| a.to_radians().cos()).collect();
        mu[0] = -1.0;
        *mu.last_mut().unwrap() = 1.0;
        let p: Vec<f64> = p_sr_inv.iter().rev().map(|v| v.max(0.0)).collect();
        let mut cdf = vec![0.0; mu.len()];
        for i in 1..mu.len() {
            cdf[i] = cdf[i - 1] + 2.0 * PI * 0.5 * (p[i - 1] + p[i]) * (mu[i] - mu[i - 1]);
        }
        let integral = *cdf.last().unwrap();
        let p_sr_inv = p.iter().map(|v| v / integral).collect();
        for c in &mut cdf {
            *c /= integral;
        }
        PhaseTable { mu, p_sr_inv, cdf, integral }
    }

    /// p(μ), sr⁻¹, normalised.
    pub fn eval_mu(&self, mu: f64) -> f64 {
        crate::table::interp_linear(&self.mu, &self.p_sr_inv, mu)
    }

    /// p(θ), sr⁻¹, normalised.
    pub fn eval(&self, theta_rad: f64) -> f64 {
        self.eval_mu(theta_rad.cos())
    }

    /// Samples μ = cos θ from u ∈ [0, 1) with density exactly
    /// 2π [`eval_mu`](Self::eval_mu)(μ).
    pub fn sample_mu(&self, u: f64) -> f64 {
        let n = self.cdf.len();
        let i = self.cdf.partition_point(|&c| c <= u).clamp(1, n - 1);
        let (c0, c1) = (self.cdf[i - 1], self.cdf[i]);
        let (m0, m1) = (self.mu[i - 1], self.mu[i]);
        let (p0, p1) = (self.p_sr_inv[i - 1], self.p_sr_inv[i]);
        if c1 <= c0 {
            return m0;
        }
        // Within the interval the density is linear in t = (μ − m0)/(m1 − m0):
        // F(t) = (p0 t + (p1 − p0) t²/2) / ((p0 + p1)/2); solve F(t) = r.
        let r = ((u - c0) / (c1 - c0)).clamp(0.0, 1.0);
        let a = 0.5 * (p1 - p0);
        let b = p0;
        let c = -r * 0.5 * (p0 + p1);
        let t = if a.abs() < 1e-12 * (p0 + p1) {
            r
        } else {
            // Stable root of a t² + b t + c = 0 in [0, 1].
            let disc = (b * b - 4.0 * a * c).max(0.0).sqrt();
            (2.0 * -c / (b + disc)).clamp(0.0, 1.0)
        };
        m0 + t * (m1 - m0)
    }

    /// Samples a scattering angle in radians.
    pub fn sample_theta(&self, u: f64) -> f64 {
        self.sample_mu(u).clamp(-1.0, 1.0).acos()
    }

    /// Asymmetry parameter ⟨cos θ⟩ (exact for the piecewise-linear function).
    pub fn mean_cosine(&self) -> f64 {
        let mut s = 0.0;
        for i in 1..self.mu.len() {
            let (m0, m1) = (self.mu[i - 1], self.mu[i]);
            let (p0, p1) = (self.p_sr_inv[i - 1], self.p_sr_inv[i]);
            // ∫ μ (p0 + (p1 − p0) t) dμ over the interval, exactly.
            let h = m1 - m0;
            s += 2.0 * PI * h * (p0 * (2.0 * m0 + m1) + p1 * (m0 + 2.0 * m1)) / 6.0;
        }
        s
    }
}

/// x^(3/2) as x √x: the square root is correctly rounded (IEEE 754), so this
/// is as reproducible as `pow` and a quarter of a thick cloud's path cost
/// cheaper (the phase functions are evaluated several times per vertex).
#[inline]
fn pow_three_halves(x: f64) -> f64 {
    x * x.sqrt()
}

/// Henyey–Greenstein phase function (sr⁻¹): (1 − g²) / (4π (1 + g² − 2g cos θ)^{3/2}).
pub fn henyey_greenstein(cos_theta: f64, g: f64) -> f64 {
    (1.0 - g * g) / (4.0 * PI * pow_three_halves(1.0 + g * g - 2.0 * g * cos_theta))
}

/// Cornette–Shanks phase function (sr⁻¹), Cornette and Shanks (1992), as on
/// the talk's slide: 3(1 − g²) / (2(2 + g²)) (1 + cos²θ) / (4π (1 + g² − 2g cos θ)^{3/2}).
pub fn cornette_shanks(cos_theta: f64, g: f64) -> f64 {
    3.0 * (1.0 - g * g) / (2.0 * (2.0 + g * g)) * (1.0 + cos_theta * cos_theta)
        / (4.0 * PI * pow_three_halves(1.0 + g * g - 2.0 * g * cos_theta))
}

/// The Henyey–Greenstein g that best fits a tabulated phase function in the
/// least-squares sense on log p (the comparison on the talk's log-scale
/// plots), by golden-section search over g ∈ [−0.5, 0.995].
pub fn fit_henyey_greenstein(angles_deg: &[f64], p_sr_inv: &[f64]) -> f64 {
    let cost = |g: f64| -> f64 {
        angles_deg
            .iter()
            .zip(p_sr_inv)
            .filter(|(_, &p)| p > 0.0)
            .map(|(a, p)| (p.ln() - henyey_greenstein(a.to_radians().cos(), g).ln()).powi(2))
            .sum()
    };
    let (mut a, mut b) = (-0.5f64, 0.995f64);
    let r = (5f64.sqrt() - 1.0) / 2.0;
    let mut c = b - r * (b - a);
    let mut d = a + r * (b - a);
    let (mut fc, mut fd) = (cost(c), cost(d));
    for _ in 0..80 {
        if fc < fd {
            b = d;
            d = c;
            fd = fc;
            c = b - r * (b - a);
            fc = cost(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + r * (b - a);
            fd = cost(d);
        }
    }
    0.5 * (a + b)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn analytic_phases_are_normalised() {
        for g in [0.0, 0.5, 0.8] {
            for f in [henyey_greenstein as fn(f64, f64) -> f64, cornette_shanks] {
                let n = 200_000;
                let s: f64 = (0..n).map(|i| f(-1.0 + (i as f64 + 0.5) * 2.0 / n as f64, g) * 2.0 / n as f64).sum();
                assert!((s * 2.0 * PI - 1.0).abs() < 1e-4, "g {g}: {}", s * 2.0 * PI);
            }
        }
    }

    #[test]
    fn table_sampling_follows_the_phase_function() {
        let grid = phase_grid_deg();
        let p: Vec<f64> = grid.iter().map(|a| henyey_greenstein(a.to_radians().cos(), 0.7)).collect();
        let t = PhaseTable::new(&grid, &p);
        assert!((t.integral - 1.0).abs() < 1e-3, "{}", t.integral);
        assert!((t.mean_cosine() - 0.7).abs() < 2e-3, "{}", t.mean_cosine());
        // Evaluation and the sampling density agree: a histogram in μ of
        // samples matches ∫ 2π p dμ of the table over each bin.
        for theta in [0.0f64, 0.3, 1.0, 2.0, 3.0] {
            let e = henyey_greenstein(theta.cos(), 0.7);
            assert!((t.eval(theta) / e - 1.0).abs() < 2e-3, "{theta}: {} vs {e}", t.eval(theta));
        }
        // Histogram of samples in cos θ against the exact HG probabilities.
        let bins = 20;
        let mut h = vec![0usize; bins];
        let n = 200_000;
        for i in 0..n {
            let u = (i as f64 + 0.5) / n as f64;
            let mu = t.sample_mu(u);
            h[(((mu + 1.0) / 2.0 * bins as f64) as usize).min(bins - 1)] += 1;
        }
        // Exact HG CDF in μ: P(μ) = (1 − g²)/(2g) [1/√(1+g²−2gμ) − 1/(1+g)].
        let g: f64 = 0.7;
        let cdf = |mu: f64| (1.0 - g * g) / (2.0 * g) * (1.0 / (1.0 + g * g - 2.0 * g * mu).sqrt() - 1.0 / (1.0 + g));
        for b in 0..bins {
            let lo = -1.0 + 2.0 * b as f64 / bins as f64;
            let hi = lo + 2.0 / bins as f64;
            let expect = (cdf(hi) - cdf(lo)) * n as f64;
            let got = h[b] as f64;
            assert!((got - expect).abs() < 0.01 * expect + 30.0, "bin {b}: {got} vs {expect}");
        }
    }

    #[test]
    fn hg_fit_recovers_g() {
        let grid = phase_grid_deg();
        let p: Vec<f64> = grid.iter().map(|a| henyey_greenstein(a.to_radians().cos(), 0.63)).collect();
        assert!((fit_henyey_greenstein(&grid, &p) - 0.63).abs() < 1e-4);
    }
}
