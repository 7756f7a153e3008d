//! The transmittance LUT (the talk's "Other Look-up Tables": "Transmittance
//! function"): the sun's transmittance from any altitude of the atmosphere
//! along any direction that does not meet the ground, to the top, per
//! colour channel, so a runtime can light anything at any height and sun
//! with the sunlight that reaches it.
//!
//! Mapping: Bruneton's (E. Bruneton, "Precomputed Atmospheric Scattering: a
//! New Implementation", 2017, `functions.glsl`,
//! `GetTransmittanceTextureUvFromRMu`), a 256 × 64 table over (μ, r). With
//! R the planet's radius, R_top the top's, H = √(R_top² − R²) the distance
//! to the top along the horizon ray from the ground, ρ = √(r² − R²) the
//! same from radius r, and d the distance to the top along μ:
//!
//!   x_r = ρ / H,  x_μ = (d − d_min) / (d_max − d_min),  d_min = R_top − r,  d_max = ρ + H,
//!
//! so x_μ = 0 is straight up and x_μ = 1 the ray that grazes the ground
//! (μ = −ρ / r), which resolves the horizon, where transmittance changes
//! fastest. Texel i of n holds x = i / (n − 1) (texel centres on both ends:
//! the texture coordinate is 0.5 / n + x (1 − 1 / n)). Directions below the
//! grazing ray meet the ground: their transmittance is 0.
//!
//! Per channel: the transmittance of the sun's own spectrum, T_c =
//! (M Σ_b W_b T_b)_c / (M Σ_b W_b)_c, W_b the XYZ of the sun's irradiance in
//! band b and M the colour space's matrix from XYZ, so that the sun's
//! irradiance at a point, in any channel, is its irradiance at the top
//! times T_c exactly. T_b = exp(−Σ_i e_i,b C_i(z, μ)) from the column table
//! (exact optical depth up to the table's interpolation).

use crate::colour::Mat3;
use serde::{Deserialize, Serialize};

/// Texels along μ (x) and r (y): Bruneton's sizes.
pub const WIDTH: usize = 256;
pub const HEIGHT: usize = 64;

/// The (μ, r) ↔ texture mapping of one atmosphere.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TransmittanceMapping {
    pub bottom_radius_km: f64,
    pub top_radius_km: f64,
}

/// The distance from radius `r` along cosine `mu` to the sphere of radius
/// `top` (r ≤ top).
pub fn distance_to_top_km(r: f64, mu: f64, top: f64) -> f64 {
    (-r * mu + (r * r * (mu * mu - 1.0) + top * top).max(0.0).sqrt()).max(0.0)
}

impl TransmittanceMapping {
    pub fn new(planet_radius_km: f64, top_km: f64) -> TransmittanceMapping {
        TransmittanceMapping { bottom_radius_km: planet_radius_km, top_radius_km: planet_radius_km + top_km }
    }

    /// H: the distance to the top along the horizon ray from the ground.
    fn h(&self) -> f64 {
        (self.top_radius_km.powi(2) - self.bottom_radius_km.powi(2)).sqrt()
    }

    /// The cosine of the ray from radius `r` that grazes the ground: rays
    /// below it meet the ground.
    pub fn mu_horizon(&self, r: f64) -> f64 {
        -(r * r - self.bottom_radius_km.powi(2)).max(0.0).sqrt() / r
    }

    /// (x_μ, x_r) in [0, 1]² of radius `r` and cosine `mu` (at or above the grazing ray).
    pub fn unit(&self, r: f64, mu: f64) -> (f64, f64) {
        let (h, top) = (self.h(), self.top_radius_km);
        let r = r.clamp(self.bottom_radius_km, top);
        let rho = (r * r - self.bottom_radius_km.powi(2)).max(0.0).sqrt();
        let d = distance_to_top_km(r, mu, top);
        let (d_min, d_max) = (top - r, rho + h);
        let x_mu = if d_max > d_min { (d - d_min) / (d_max - d_min) } else { 0.0 };
        (x_mu.clamp(0.0, 1.0), (rho / h).clamp(0.0, 1.0))
    }

    /// The radius and cosine of (x_μ, x_r).
    pub fn r_mu(&self, x_mu: f64, x_r: f64) -> (f64, f64) {
        let h = self.h();
        let rho = h * x_r;
        let r = (rho * rho + self.bottom_radius_km.powi(2)).sqrt();
        let (d_min, d_max) = (self.top_radius_km - r, rho + h);
        let d = d_min + x_mu * (d_max - d_min);
        let mu = if d == 0.0 { 1.0 } else { ((h * h - rho * rho - d * d) / (2.0 * r * d)).clamp(-1.0, 1.0) };
        (r, mu)
    }
}

/// The table of one atmosphere: the XYZ of the sun's irradiance that
/// reaches each texel's (r, μ) (lux for the shipped solar spectrum), and
/// at the top.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TransmittanceTable {
    pub mapping: TransmittanceMapping,
    /// Row-major, WIDTH × HEIGHT: x along μ, y along r.
    pub xyz: Vec<[f64; 3]>,
    pub top_xyz: [f64; 3],
}

impl TransmittanceTable {
    /// Per-channel transmittance of every texel in the space of matrix
    /// `m` (XYZ → RGB), in texel order.
    pub fn channel_texels(&self, m: &Mat3) -> Vec<[f64; 3]> {
        let top = crate::colour::apply(m, self.top_xyz);
        self.xyz.iter().map(|x| channel_ratio(crate::colour::apply(m, *x), top)).collect()
    }

    /// XYZ of the sun's irradiance at altitude `z_km` along cosine `mu`,
    /// bilinear between texel centres (0 below the grazing ray).
    pub fn sample_xyz(&self, z_km: f64, mu: f64) -> [f64; 3] {
        sample(&self.mapping, |i| self.xyz[i], z_km, mu)
    }
}

/// `value / top` per channel (0 where the top's channel is not positive).
pub fn channel_ratio(value: [f64; 3], top: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|c| if top[c] > 0.0 { value[c] / top[c] } else { 0.0 })
}

/// Bilinear lookup of a WIDTH × HEIGHT table (`texel(i)` the value of
/// texel i, row-major) at altitude `z_km` and cosine `mu`, between texel
/// centres, clamped at the edges; 0 below the ray that grazes the ground.
pub fn sample(mapping: &TransmittanceMapping, texel: impl Fn(usize) -> [f64; 3], z_km: f64, mu: f64) -> [f64; 3] {
    let r = mapping.bottom_radius_km + z_km.max(0.0);
    if mu < mapping.mu_horizon(r) {
        return [0.0; 3];
    }
    let (x_mu, x_r) = mapping.unit(r, mu);
    let (fx, fy) = (x_mu * (WIDTH - 1) as f64, x_r * (HEIGHT - 1) as f64);
    let (i, j) = ((fx as usize).min(WIDTH - 2), (fy as usize).min(HEIGHT - 2));
    let (ax, ay) = (fx - i as f64, fy - j as f64);
    let at = |i: usize, j: usize| texel(j * WIDTH + i);
    let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1));
    std::array::from_fn(|k| (1.0 - ay) * ((1.0 - ax) * a[k] + ax * b[k]) + ay * ((1.0 - ax) * c[k] + ax * d[k]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_mapping_round_trips_and_spans_zenith_to_grazing() {
        let m = TransmittanceMapping::new(6371.0, 100.0);
        for k in 0..200 {
            // Below the top: there every upward ray has length 0 (x_μ = 0).
            let z = 99.0 * (k % 20) as f64 / 19.0;
            let r = 6371.0 + z;
            let lo = m.mu_horizon(r);
            let mu = lo + (1.0 - lo) * ((k * 37 % 101) as f64 / 100.0);
            let (x_mu, x_r) = m.unit(r, mu);
            let (r2, mu2) = m.r_mu(x_mu, x_r);
            assert!(
                (r2 - r).abs() < 1e-9 && (mu2 - mu).abs() < 1e-9,
                "({r}, {mu}) -> ({x_mu}, {x_r}) -> ({r2}, {mu2})"
            );
        }
        // Straight up at x_μ = 0, the grazing ray at x_μ = 1, the ground and the top at x_r = 0, 1.
        let (r, mu) = m.r_mu(0.0, 0.4);
        assert!((mu - 1.0).abs() < 1e-12, "{r} {mu}");
        let (r, mu) = m.r_mu(1.0, 0.4);
        assert!((mu - m.mu_horizon(r)).abs() < 1e-12);
        assert!((m.r_mu(0.3, 0.0).0 - 6371.0).abs() < 1e-9 && (m.r_mu(0.3, 1.0).0 - 6471.0).abs() < 1e-9);
    }
}
