//! Gauss-Legendre quadrature, the normalised associated Legendre functions
//! of the azimuthal (Fourier) expansion of a phase function, and a phase
//! function's Legendre moments.
//!
//! Conventions (those of DISORT, Stamnes et al. 1988, and of
//! `scripts/regen_disort.py`): a phase function p in sr⁻¹, normalised to 1
//! over the sphere, is
//!
//!   p(cos Θ) = (1 / 4π) Σ_l (2l + 1) χ_l P_l(cos Θ),   χ_l = 2π ∫₋₁¹ p(μ) P_l(μ) dμ,
//!
//! so χ₀ = 1 and Henyey-Greenstein has χ_l = g^l. With the normalised
//! associated functions Λ_l^m = √((l − m)! / (l + m)!) P_l^m (no
//! Condon-Shortley phase: only products Λ_l^m(u) Λ_l^m(u′) appear), the
//! addition theorem reads
//!
//!   P_l(cos Θ) = Σ_{m=0}^{l} (2 − δ_m0) Λ_l^m(u) Λ_l^m(u′) cos m(φ − φ′).

use crate::render::medium::Phase;
use std::f64::consts::PI;

/// The `n` nodes and weights of Gauss-Legendre quadrature on [−1, 1],
/// nodes increasing (Newton's method on P_n from the Tricomi estimates of
/// its roots; Abramowitz and Stegun 25.4.29).
pub fn gauss_legendre(n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut x = vec![0.0; n];
    let mut w = vec![0.0; n];
    for i in 0..n.div_ceil(2) {
        let mut z = (PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        let mut dp = 1.0;
        for _ in 0..100 {
            let (p, d) = legendre_and_derivative(n, z);
            dp = d;
            let dz = p / d;
            z -= dz;
            if dz.abs() < 1e-16 {
                break;
            }
        }
        let (_, d) = legendre_and_derivative(n, z);
        dp = if d != 0.0 { d } else { dp };
        let wi = 2.0 / ((1.0 - z * z) * dp * dp);
        x[i] = -z;
        x[n - 1 - i] = z;
        w[i] = wi;
        w[n - 1 - i] = wi;
    }
    (x, w)
}

/// P_n(z) and P_n′(z) by the three-term recurrence.
fn legendre_and_derivative(n: usize, z: f64) -> (f64, f64) {
    let (mut p0, mut p1) = (1.0, z);
    if n == 0 {
        return (1.0, 0.0);
    }
    for k in 2..=n {
        let p2 = ((2 * k - 1) as f64 * z * p1 - (k - 1) as f64 * p0) / k as f64;
        p0 = p1;
        p1 = p2;
    }
    (p1, n as f64 * (z * p1 - p0) / (z * z - 1.0))
}

/// Gauss-Legendre on [0, 1] (one hemisphere of cosines: the "double Gauss"
/// of Sykes 1951, which integrates each hemisphere apart and so keeps the
/// kink of the radiance at the horizontal out of the quadrature).
pub fn half_range(n: usize) -> (Vec<f64>, Vec<f64>) {
    let (x, w) = gauss_legendre(n);
    (x.iter().map(|x| 0.5 * (x + 1.0)).collect(), w.iter().map(|w| 0.5 * w).collect())
}

/// Λ_l^m(μ) for l = 0 ..= `lmax` (zero for l < m), by the recurrences
///
///   Λ_m^m = Λ_{m−1}^{m−1} √((2m − 1) / 2m) √(1 − μ²),   Λ_{m+1}^m = √(2m + 1) μ Λ_m^m,
///   √(l² − m²) Λ_l^m = (2l − 1) μ Λ_{l−1}^m − √((l − 1)² − m²) Λ_{l−2}^m,
///
/// which follow from those of P_l^m (Abramowitz and Stegun 8.5.3) and are
/// stable upward in l.
pub fn normalised_associated(lmax: usize, m: usize, mu: f64) -> Vec<f64> {
    let mut out = vec![0.0; lmax + 1];
    if m > lmax {
        return out;
    }
    let s = (1.0 - mu * mu).max(0.0).sqrt();
    let mut mm = 1.0;
    for k in 1..=m {
        mm *= ((2 * k - 1) as f64 / (2 * k) as f64).sqrt() * s;
    }
    out[m] = mm;
    if m < lmax {
        out[m + 1] = ((2 * m + 1) as f64).sqrt() * mu * mm;
    }
    for l in m + 2..=lmax {
        let a = (2 * l - 1) as f64 * mu * out[l - 1];
        let b = (((l - 1) * (l - 1) - m * m) as f64).sqrt() * out[l - 2];
        out[l] = (a - b) / ((l * l - m * m) as f64).sqrt();
    }
    out
}

/// P_l(μ) for l = 0 ..= lmax.
pub(super) fn legendre_all(lmax: usize, mu: f64) -> Vec<f64> {
    let mut p = vec![0.0; lmax + 1];
    p[0] = 1.0;
    if lmax >= 1 {
        p[1] = mu;
    }
    for l in 2..=lmax {
        p[l] = ((2 * l - 1) as f64 * mu * p[l - 1] - (l - 1) as f64 * p[l - 2]) / l as f64;
    }
    p
}

/// The Legendre moments χ₀ ..= χ_lmax of a phase function (see the module
/// documentation). Henyey-Greenstein's are g^l exactly; Rayleigh's and
/// Cornette-Shanks's are integrated by Gauss-Legendre on 8 panels of μ; a
/// table, linear in μ between its nodes, on each of its intervals with
/// enough nodes to integrate P_l times a line exactly.
pub fn moments(phase: &Phase, lmax: usize) -> Vec<f64> {
    match phase {
        Phase::None => vec![0.0; lmax + 1],
        Phase::HenyeyGreenstein { g } => (0..=lmax).map(|l| g.powi(l as i32)).collect(),
        Phase::Table(t) => {
            let (x, w) = gauss_legendre(lmax / 2 + 2);
            let mut chi = vec![0.0; lmax + 1];
            for k in 1..t.mu.len() {
                let (a, b) = (t.mu[k - 1], t.mu[k]);
                if b <= a {
                    continue;
                }
                for (xi, wi) in x.iter().zip(&w) {
                    let mu = 0.5 * (a + b) + 0.5 * (b - a) * xi;
                    let f = 2.0 * PI * 0.5 * (b - a) * wi * t.eval_mu(mu);
                    for (c, p) in chi.iter_mut().zip(legendre_all(lmax, mu)) {
                        *c += f * p;
                    }
                }
            }
            chi
        }
        _ => {
            // Smooth on [−1, 1]: 8 panels of a rule exact to degree 2·40 − 1.
            let (x, w) = gauss_legendre(40.max(lmax / 2 + 2));
            let mut chi = vec![0.0; lmax + 1];
            for panel in 0..8 {
                let (a, b) = (-1.0 + 0.25 * panel as f64, -0.75 + 0.25 * panel as f64);
                for (xi, wi) in x.iter().zip(&w) {
                    let mu = 0.5 * (a + b) + 0.5 * (b - a) * xi;
                    let f = 2.0 * PI * 0.5 * (b - a) * wi * phase.eval(mu);
                    for (c, p) in chi.iter_mut().zip(legendre_all(lmax, mu)) {
                        *c += f * p;
                    }
                }
            }
            chi
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gauss_legendre_integrates_polynomials_exactly() {
        let (x, w) = gauss_legendre(7);
        // Exact for degree 13: ∫ x¹² = 2/13, ∫ x¹³ = 0.
        let even: f64 = x.iter().zip(&w).map(|(x, w)| w * x.powi(12)).sum();
        let odd: f64 = x.iter().zip(&w).map(|(x, w)| w * x.powi(13)).sum();
        assert!((even - 2.0 / 13.0).abs() < 1e-14 && odd.abs() < 1e-14, "{even} {odd}");
        let (h, hw) = half_range(8);
        assert!((hw.iter().sum::<f64>() - 1.0).abs() < 1e-14 && h.iter().all(|&m| m > 0.0 && m < 1.0));
    }

    /// The addition theorem (module documentation) at a few angles: the
    /// normalised associated functions sum to P_l(cos Θ).
    #[test]
    fn associated_functions_satisfy_the_addition_theorem() {
        let lmax = 40;
        for (u, v, dphi) in [(0.3f64, -0.8f64, 1.1f64), (0.95, 0.97, 0.2), (-0.1, 0.5, 2.9)] {
            let cos_t = u * v + (1.0 - u * u).sqrt() * (1.0 - v * v).sqrt() * dphi.cos();
            let p = legendre_all(lmax, cos_t);
            let mut sum = vec![0.0; lmax + 1];
            for m in 0..=lmax {
                let (a, b) = (normalised_associated(lmax, m, u), normalised_associated(lmax, m, v));
                for l in m..=lmax {
                    sum[l] += if m == 0 { 1.0 } else { 2.0 } * a[l] * b[l] * (m as f64 * dphi).cos();
                }
            }
            for l in 0..=lmax {
                assert!((sum[l] - p[l]).abs() < 1e-12, "l {l}: {} against {}", sum[l], p[l]);
            }
        }
    }

    #[test]
    fn moments_of_known_phase_functions() {
        // Rayleigh without depolarisation: χ = (1, 0, 1/10, 0, ...).
        let r = moments(&Phase::Rayleigh { depolarization: 0.0 }, 6);
        for (l, want) in [1.0, 0.0, 0.1, 0.0, 0.0, 0.0, 0.0].iter().enumerate() {
            assert!((r[l] - want).abs() < 1e-13, "Rayleigh χ_{l} = {}", r[l]);
        }
        // A table of Henyey-Greenstein on the Mie angle grid: its moments
        // are g^l up to the table's linear interpolation in μ (2.5e-4 of
        // χ_32 on this grid).
        let grid = crate::mie::phase::phase_grid_deg();
        let g = 0.85;
        let p: Vec<f64> =
            grid.iter().map(|a: &f64| crate::mie::phase::henyey_greenstein(a.to_radians().cos(), g)).collect();
        let t = Phase::Table(std::sync::Arc::new(crate::mie::PhaseTable::new(&grid, &p)));
        let chi = moments(&t, 64);
        for l in [0usize, 1, 2, 10, 32, 64] {
            let want = g.powi(l as i32);
            assert!((chi[l] - want).abs() < 1e-3 * want.max(1e-3), "table χ_{l} = {} against {want}", chi[l]);
        }
    }
}
