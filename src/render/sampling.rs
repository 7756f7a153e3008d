//! The direction samplers of the path tracer, each with the density it
//! samples: phase functions about a direction (Rayleigh with depolarization,
//! Henyey–Greenstein, Cornette–Shanks, tabulated Mie), the choice of a
//! scatterer in proportion to its scattering coefficient, and the
//! cosine-weighted hemisphere of the Lambertian ground. The chi-square tests
//! in `chi2.rs` check every one against its own density.

use super::medium::Phase;
use super::rng::Rng;
use glam::DVec3;
use std::f64::consts::PI;

/// A direction drawn from `phase` about the direction of travel `d`: its
/// density over the sphere is `phase.eval(w · d)` (a phase function is
/// normalised to 1 over 4π sr). `Phase::None` returns `d`.
pub fn sample_phase(phase: &Phase, d: DVec3, rng: &mut Rng) -> DVec3 {
    let mu = match phase {
        Phase::None => 1.0,
        Phase::Table(t) => t.sample_mu(rng.uniform()),
        Phase::HenyeyGreenstein { g } => sample_hg(*g, rng.uniform()),
        Phase::CornetteShanks { g } => loop {
            // Rejection from HG: p_CS / p_HG ∝ (1 + μ²) / 2 ≤ 1.
            let mu = sample_hg(*g, rng.uniform());
            if rng.uniform() * 2.0 < 1.0 + mu * mu {
                break mu;
            }
        },
        Phase::Rayleigh { depolarization } => {
            // p ∝ (1 + 3γ) + (1 − γ) μ² with γ = ρ / (2 − ρ) (Chandrasekhar
            // 1950; the form of Bucholtz 1995, eq. 12): rejection from the
            // uniform μ, accepted with probability p / p_max.
            let gamma = depolarization / (2.0 - depolarization);
            let (a, b) = (1.0 + 3.0 * gamma, 1.0 - gamma);
            loop {
                let mu = 2.0 * rng.uniform() - 1.0;
                if rng.uniform() * (a + b) < a + b * mu * mu {
                    break mu;
                }
            }
        }
    };
    let phi = 2.0 * PI * rng.uniform();
    around(d, mu, phi)
}

/// Henyey–Greenstein sampling of μ (Henyey and Greenstein 1941; pbrt-v4's
/// SampleHenyeyGreenstein, written for μ = cos θ between the directions of
/// travel).
#[inline]
pub fn sample_hg(g: f64, u: f64) -> f64 {
    if g.abs() < 1e-3 {
        return 1.0 - 2.0 * u;
    }
    let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u);
    ((1.0 + g * g - s * s) / (2.0 * g)).clamp(-1.0, 1.0)
}

/// The direction at angle acos(μ) from `d`, rotated by φ about it.
#[inline]
pub fn around(d: DVec3, mu: f64, phi: f64) -> DVec3 {
    let (t, b) = d.any_orthonormal_pair();
    let s = (1.0 - mu * mu).max(0.0).sqrt();
    (t * (s * libm::cos(phi)) + b * (s * libm::sin(phi)) + d * mu).normalize()
}

/// A cosine-weighted direction about the normal `n` (Malley's method in
/// closed form: μ = √u), density [`cosine_hemisphere_pdf`].
#[inline]
pub fn cosine_hemisphere(n: DVec3, rng: &mut Rng) -> DVec3 {
    let u1 = rng.uniform();
    let phi = 2.0 * PI * rng.uniform();
    around(n, u1.sqrt(), phi)
}

/// The density of [`cosine_hemisphere`], max(0, n · w) / π sr⁻¹.
#[inline]
pub fn cosine_hemisphere_pdf(n: DVec3, w: DVec3) -> f64 {
    n.dot(w).max(0.0) / PI
}

/// The index i of `0..n` chosen with probability weight(i) / Σ weight,
/// given `x` = u · Σ weight for a uniform u (the last index with a
/// positive weight when rounding leaves `x` past the end).
#[inline]
pub fn pick_weighted(mut x: f64, n: usize, weight: impl Fn(usize) -> f64) -> usize {
    let mut last = n.saturating_sub(1);
    for i in 0..n {
        let w = weight(i);
        if w > 0.0 {
            if x < w {
                return i;
            }
            last = i;
            x -= w;
        }
    }
    last
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hg_sampling_mean_is_g() {
        let n = 200_000;
        let g = 0.7;
        let m: f64 = (0..n).map(|i| sample_hg(g, (i as f64 + 0.5) / n as f64)).sum::<f64>() / n as f64;
        assert!((m - g).abs() < 1e-3, "{m}");
    }

    #[test]
    fn a_pick_never_lands_on_a_zero_weight() {
        let w = [0.0, 2.0, 0.0, 1.0, 0.0];
        assert_eq!(pick_weighted(0.0, 5, |i| w[i]), 1);
        assert_eq!(pick_weighted(1.999, 5, |i| w[i]), 1);
        assert_eq!(pick_weighted(2.5, 5, |i| w[i]), 3);
        assert_eq!(pick_weighted(3.0 + 1e-12, 5, |i| w[i]), 3);
    }
}
