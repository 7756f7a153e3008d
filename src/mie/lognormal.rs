//! Bulk optical properties of a log-normal number size distribution,
//! n(r) = N / (√(2π) σ r) exp(−(ln r − ln r_m)² / (2σ²)), σ = ln(GSD),
//! integrated over radius with the BHMIE single-sphere solution.
//!
//! The integral runs over u = ln r with the trapezoid rule on nodes whose
//! spacing is min(σ/40, max(0.5/x(u), 0.002)): fine enough everywhere to
//! resolve the distribution; up to x = 250 fine enough (Δx ≤ 0.5) to average
//! the interference ripple of Q_ext and of the phase function rather than
//! alias it; beyond, where only the tail of a distribution lives, 0.2 % steps
//! in radius. The narrow resonance ripple of large weakly absorbing spheres
//! is not resolved: it leaves errors of a few percent in the side and back
//! scattering of such distributions (see the tolerances in
//! `tests/reference_physics.rs`). The range is ln r_m − 5σ to ln r_m + 2σ² + 4σ, four standard
//! deviations beyond the median of the r²-weighted distribution that
//! extinction and scattered energy are made of, optionally truncated to a
//! radius range (OPAC's components are defined between r_min and r_max,
//! Hess et al. 1998, Table 1); truncation does not renormalise the number
//! density. The resulting accuracy (without truncation) is checked against
//! miepython 3.3.0 integrated on a converged dense grid by
//! `mie_lognormal_matches_dense_miepython_integration` in
//! `tests/reference_physics.rs` (values in `tests/reference/mie_lognormal.json`).

use super::bhmie;
use num_complex::Complex64 as C64;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// One log-normal mode of a number distribution.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LogNormal {
    /// Number median radius, µm.
    pub median_radius_um: f64,
    /// ln of the geometric standard deviation.
    pub sigma: f64,
    /// Radius range the distribution is truncated to, µm (0 and ∞: none).
    #[serde(default)]
    pub min_radius_um: f64,
    #[serde(default = "infinity")]
    pub max_radius_um: f64,
}

fn infinity() -> f64 {
    f64::INFINITY
}

impl LogNormal {
    /// The number distribution of a mode given as a volume distribution
    /// dV/dln r with volume median radius r_v: r_n = r_v exp(−3σ²)
    /// (Hatch–Choate conversion; Seinfeld and Pandis 2016, eq. 8.52).
    pub fn from_volume_median(volume_median_radius_um: f64, sigma: f64) -> LogNormal {
        LogNormal::new(volume_median_radius_um * (-3.0 * sigma * sigma).exp(), sigma)
    }

    /// An untruncated mode.
    pub fn new(median_radius_um: f64, sigma: f64) -> LogNormal {
        LogNormal { median_radius_um, sigma, min_radius_um: 0.0, max_radius_um: f64::INFINITY }
    }

    /// The same mode truncated to [min, max] µm.
    pub fn truncated(self, min_radius_um: f64, max_radius_um: f64) -> LogNormal {
        LogNormal { min_radius_um, max_radius_um, ..self }
    }

    /// Mean particle volume, µm³: (4/3)π r_n³ exp(9σ²/2).
    pub fn mean_volume_um3(&self) -> f64 {
        4.0 / 3.0 * PI * self.median_radius_um.powi(3) * (4.5 * self.sigma * self.sigma).exp()
    }

    /// Quadrature nodes (ln r) and weights for this mode at a wavelength.
    pub fn nodes(&self, wavelength_um: f64) -> Vec<(f64, f64)> {
        let mu = self.median_radius_um.ln();
        let s = self.sigma.max(1e-6);
        let mut lo = mu - 5.0 * s;
        let mut hi = mu + 2.0 * s * s + 4.0 * s;
        if self.min_radius_um > 0.0 {
            lo = lo.max(self.min_radius_um.ln());
        }
        if self.max_radius_um.is_finite() {
            hi = hi.min(self.max_radius_um.ln());
        }
        if hi <= lo {
            return Vec::new();
        }
        let k = 2.0 * PI / wavelength_um;
        let mut us = vec![lo];
        let mut u = lo;
        while u < hi {
            let x = k * u.exp();
            let h = (s / 40.0).min((0.5 / x).max(0.002));
            u = (u + h).min(hi);
            us.push(u);
        }
        let pdf = |u: f64| (-(u - mu).powi(2) / (2.0 * s * s)).exp() / ((2.0 * PI).sqrt() * s);
        let n = us.len();
        (0..n)
            .map(|i| {
                let left = if i > 0 { us[i] - us[i - 1] } else { 0.0 };
                let right = if i + 1 < n { us[i + 1] - us[i] } else { 0.0 };
                (us[i], 0.5 * (left + right) * pdf(us[i]))
            })
            .collect()
    }
}

/// Size-averaged optics of one mode, per particle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BulkOptics {
    pub wavelength_nm: f64,
    /// Mean extinction cross-section per particle, µm².
    pub c_ext_um2: f64,
    /// Mean scattering cross-section per particle, µm².
    pub c_sca_um2: f64,
    /// Asymmetry parameter of the ensemble: ∫ g C_sca n dr / ∫ C_sca n dr.
    pub g: f64,
    /// Scattering angles of `phase_sr_inv`, degrees.
    pub angles_deg: Vec<f64>,
    /// Phase function normalised to 1 over the sphere, sr⁻¹:
    /// p(θ) = ∫ ½(|S1|² + |S2|²) n dr / (k² ∫ C_sca n dr).
    pub phase_sr_inv: Vec<f64>,
    /// Number of radius nodes used.
    pub radius_nodes: usize,
}

impl BulkOptics {
    pub fn single_scattering_albedo(&self) -> f64 {
        if self.c_ext_um2 > 0.0 {
            self.c_sca_um2 / self.c_ext_um2
        } else {
            0.0
        }
    }
}

struct Partial {
    c_ext: f64,
    c_sca: f64,
    g_c_sca: f64,
    intensity: Vec<f64>,
}

/// Integrates the mode at one wavelength; `angles_deg` may be empty.
/// Deterministic for any number of threads (fixed chunks, summed in order).
pub fn bulk_optics(m: C64, mode: &LogNormal, wavelength_nm: f64, angles_deg: &[f64]) -> BulkOptics {
    let l_um = wavelength_nm * 1e-3;
    let k = 2.0 * PI / l_um;
    let nodes = mode.nodes(l_um);
    let mus: Vec<f64> = angles_deg.iter().map(|a| a.to_radians().cos()).collect();
    const CHUNK: usize = 16;
    let partials: Vec<Partial> = nodes
        .par_chunks(CHUNK)
        .map(|chunk| {
            let mut p = Partial { c_ext: 0.0, c_sca: 0.0, g_c_sca: 0.0, intensity: vec![0.0; mus.len()] };
            for &(u, w) in chunk {
                let r = u.exp();
                let x = k * r;
                let (a, b) = bhmie::coefficients(m, x);
                let (q_ext, q_sca, g) = bhmie::efficiencies(&a, &b, x);
                let area = PI * r * r;
                p.c_ext += w * q_ext * area;
                p.c_sca += w * q_sca * area;
                p.g_c_sca += w * g * q_sca * area;
                if !mus.is_empty() {
                    bhmie::accumulate_intensity(&a, &b, &mus, w, &mut p.intensity);
                }
            }
            p
        })
        .collect();
    let mut c_ext = 0.0;
    let mut c_sca = 0.0;
    let mut g_c_sca = 0.0;
    let mut intensity = vec![0.0; mus.len()];
    for p in &partials {
        c_ext += p.c_ext;
        c_sca += p.c_sca;
        g_c_sca += p.g_c_sca;
        for (a, b) in intensity.iter_mut().zip(&p.intensity) {
            *a += b;
        }
    }
    let phase_sr_inv = intensity.iter().map(|i| if c_sca > 0.0 { i / (k * k * c_sca) } else { 0.0 }).collect();
    BulkOptics {
        wavelength_nm,
        c_ext_um2: c_ext,
        c_sca_um2: c_sca,
        g: if c_sca > 0.0 { g_c_sca / c_sca } else { 0.0 },
        angles_deg: angles_deg.to_vec(),
        phase_sr_inv,
        radius_nodes: nodes.len(),
    }
}

/// Combines modes with number fractions `weights` (normalised here) into
/// the optics of the mixture: cross-sections add with the weights, g and the
/// phase function are averaged with weight × C_sca.
pub fn mix(parts: &[(f64, BulkOptics)]) -> BulkOptics {
    let total_w: f64 = parts.iter().map(|p| p.0).sum();
    let first = &parts[0].1;
    let mut out = BulkOptics {
        wavelength_nm: first.wavelength_nm,
        c_ext_um2: 0.0,
        c_sca_um2: 0.0,
        g: 0.0,
        angles_deg: first.angles_deg.clone(),
        phase_sr_inv: vec![0.0; first.phase_sr_inv.len()],
        radius_nodes: 0,
    };
    for (w, b) in parts {
        let w = w / total_w;
        out.c_ext_um2 += w * b.c_ext_um2;
        out.c_sca_um2 += w * b.c_sca_um2;
        out.g += w * b.c_sca_um2 * b.g;
        for (o, p) in out.phase_sr_inv.iter_mut().zip(&b.phase_sr_inv) {
            *o += w * b.c_sca_um2 * p;
        }
        out.radius_nodes += b.radius_nodes;
    }
    if out.c_sca_um2 > 0.0 {
        out.g /= out.c_sca_um2;
        for o in &mut out.phase_sr_inv {
            *o /= out.c_sca_um2;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_integrate_to_one() {
        let m = LogNormal::new(1.0, 0.5);
        let s: f64 = m.nodes(0.55).iter().map(|n| n.1).sum();
        assert!((s - 1.0).abs() < 1e-5, "{s}");
    }

    #[test]
    fn narrow_distribution_tends_to_single_sphere() {
        let m = C64::new(1.33, 1e-7);
        let mode = LogNormal::new(0.3, 0.001);
        let b = bulk_optics(m, &mode, 550.0, &[0.0, 90.0]);
        let x = 2.0 * PI * 0.3 / 0.55;
        let r = bhmie::bhmie(m, x, &[1.0, 0.0]);
        let area = PI * 0.09;
        assert!((b.c_ext_um2 / (r.q_ext * area) - 1.0).abs() < 1e-3);
        let k = 2.0 * PI / 0.55;
        let p90 = 0.5 * (r.s1[1].norm_sqr() + r.s2[1].norm_sqr()) / (k * k * r.q_sca * area);
        assert!((b.phase_sr_inv[1] / p90 - 1.0).abs() < 2e-3);
    }

    #[test]
    fn volume_conversion_roundtrip() {
        let m = LogNormal::from_volume_median(4.0, 0.55);
        assert!((m.median_radius_um * (3.0f64 * 0.55 * 0.55).exp() - 4.0).abs() < 1e-12);
    }
}
