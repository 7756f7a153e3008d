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

/// A phase function tabulated on increasing angles, with the cumulative
/// distribution over the sphere for sampling.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PhaseTable {
    pub angles_rad: Vec<f64>,
    /// p(θ), sr⁻¹.
    pub p_sr_inv: Vec<f64>,
    /// CDF at each angle: ∫₀^θ p 2π sin θ' dθ' (trapezoid), scaled to end at 1.
    pub cdf: Vec<f64>,
    /// The unscaled end value of the CDF (1 up to discretisation error).
    pub integral: f64,
}

impl PhaseTable {
    pub fn new(angles_deg: &[f64], p_sr_inv: &[f64]) -> PhaseTable {
        assert_eq!(angles_deg.len(), p_sr_inv.len());
        let angles_rad: Vec<f64> = angles_deg.iter().map(|a| a.to_radians()).collect();
        let mut cdf = vec![0.0; angles_rad.len()];
        for i in 1..angles_rad.len() {
            let (t0, t1) = (angles_rad[i - 1], angles_rad[i]);
            let f0 = p_sr_inv[i - 1] * t0.sin();
            let f1 = p_sr_inv[i] * t1.sin();
            cdf[i] = cdf[i - 1] + 2.0 * PI * 0.5 * (f0 + f1) * (t1 - t0);
        }
        let integral = *cdf.last().unwrap();
        for c in &mut cdf {
            *c /= integral;
        }
        PhaseTable { angles_rad, p_sr_inv: p_sr_inv.to_vec(), cdf, integral }
    }

    /// p(θ), linear between table angles.
    pub fn eval(&self, theta_rad: f64) -> f64 {
        crate::table::interp_linear(&self.angles_rad, &self.p_sr_inv, theta_rad)
    }

    /// Samples a scattering angle (radians) from u ∈ [0, 1) by inverting the
    /// tabulated CDF; within a table interval θ is linear in the CDF.
    pub fn sample_theta(&self, u: f64) -> f64 {
        let i = self.cdf.partition_point(|&c| c <= u).clamp(1, self.cdf.len() - 1);
        let (c0, c1) = (self.cdf[i - 1], self.cdf[i]);
        let t = if c1 > c0 { (u - c0) / (c1 - c0) } else { 0.5 };
        self.angles_rad[i - 1] + t * (self.angles_rad[i] - self.angles_rad[i - 1])
    }

    /// The density (per steradian) with which [`sample_theta`] picks θ.
    pub fn sample_pdf_sr_inv(&self, theta_rad: f64) -> f64 {
        let i = self.angles_rad.partition_point(|&a| a <= theta_rad).clamp(1, self.angles_rad.len() - 1);
        let dt = self.angles_rad[i] - self.angles_rad[i - 1];
        let dc = self.cdf[i] - self.cdf[i - 1];
        let s = theta_rad.sin().max(1e-12);
        dc / dt / (2.0 * PI * s)
    }

    /// Asymmetry parameter ⟨cos θ⟩ of the tabulated function.
    pub fn mean_cosine(&self) -> f64 {
        let mut s = 0.0;
        for i in 1..self.angles_rad.len() {
            let (t0, t1) = (self.angles_rad[i - 1], self.angles_rad[i]);
            let f0 = self.p_sr_inv[i - 1] * t0.sin() * t0.cos();
            let f1 = self.p_sr_inv[i] * t1.sin() * t1.cos();
            s += 2.0 * PI * 0.5 * (f0 + f1) * (t1 - t0);
        }
        s / self.integral
    }
}

/// Henyey–Greenstein phase function (sr⁻¹): (1 − g²) / (4π (1 + g² − 2g cos θ)^{3/2}).
pub fn henyey_greenstein(cos_theta: f64, g: f64) -> f64 {
    (1.0 - g * g) / (4.0 * PI * (1.0 + g * g - 2.0 * g * cos_theta).powf(1.5))
}

/// Cornette–Shanks phase function (sr⁻¹), Cornette and Shanks (1992), as on
/// the talk's slide: 3(1 − g²) / (2(2 + g²)) (1 + cos²θ) / (4π (1 + g² − 2g cos θ)^{3/2}).
pub fn cornette_shanks(cos_theta: f64, g: f64) -> f64 {
    3.0 * (1.0 - g * g) / (2.0 * (2.0 + g * g)) * (1.0 + cos_theta * cos_theta)
        / (4.0 * PI * (1.0 + g * g - 2.0 * g * cos_theta).powf(1.5))
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
        // Histogram of samples in cos θ against the exact HG probabilities.
        let bins = 20;
        let mut h = vec![0usize; bins];
        let n = 200_000;
        for i in 0..n {
            let u = (i as f64 + 0.5) / n as f64;
            let mu = t.sample_theta(u).cos();
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
