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

use super::colour::Mat3;
use crate::render::Scene;
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
    /// Computes the table from a scene's band optics and column table.
    pub fn compute(scene: &Scene) -> TransmittanceTable {
        let m = &scene.medium;
        let mapping = TransmittanceMapping::new(m.radius_km, m.top_km);
        let mut xyz = Vec::with_capacity(WIDTH * HEIGHT);
        for j in 0..HEIGHT {
            for i in 0..WIDTH {
                let (r, mu) = mapping.r_mu(i as f64 / (WIDTH - 1) as f64, j as f64 / (HEIGHT - 1) as f64);
                xyz.push(sun_xyz_at(scene, r - m.radius_km, mu));
            }
        }
        let top_xyz = scene.bands.weight.iter().fold([0.0; 3], |a, w| [a[0] + w[0], a[1] + w[1], a[2] + w[2]]);
        TransmittanceTable { mapping, xyz, top_xyz }
    }

    /// Per-channel transmittance of every texel in the space of matrix
    /// `m` (XYZ → RGB), in texel order.
    pub fn channel_texels(&self, m: &Mat3) -> Vec<[f64; 3]> {
        let top = mul(m, self.top_xyz);
        self.xyz.iter().map(|x| channel_ratio(mul(m, *x), top)).collect()
    }

    /// XYZ of the sun's irradiance at altitude `z_km` along cosine `mu`,
    /// bilinear between texel centres (0 below the grazing ray).
    pub fn sample_xyz(&self, z_km: f64, mu: f64) -> [f64; 3] {
        sample(&self.mapping, |i| self.xyz[i], z_km, mu)
    }
}

/// XYZ of the sun's irradiance reaching altitude `z_km` along cosine `mu`
/// (to space), directly from the scene's column table: Σ_b W_b T_b.
pub fn sun_xyz_at(scene: &Scene, z_km: f64, mu: f64) -> [f64; 3] {
    let mut xyz = [0.0; 3];
    for (w, o) in scene.bands.weight.iter().zip(&scene.band_optics) {
        let tau = scene.columns.optical_depth(z_km.max(0.0), mu, &o.extinction);
        let t = if tau.is_finite() { libm::exp(-tau) } else { 0.0 };
        for c in 0..3 {
            xyz[c] += w[c] * t;
        }
    }
    xyz
}

/// `value / top` per channel (0 where the top's channel is not positive).
pub fn channel_ratio(value: [f64; 3], top: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|c| if top[c] > 0.0 { value[c] / top[c] } else { 0.0 })
}

pub(crate) fn mul(m: &Mat3, v: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|r| m[r][0] * v[0] + m[r][1] * v[1] + m[r][2] * v[2])
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
    use crate::atmosphere::Atmosphere;
    use crate::mie::MieCache;
    use crate::render::{SpectralSettings, WavelengthSampling};

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
            assert!((r2 - r).abs() < 1e-9 && (mu2 - mu).abs() < 1e-9, "({r}, {mu}) -> ({x_mu}, {x_r}) -> ({r2}, {mu2})");
        }
        // Straight up at x_μ = 0, the grazing ray at x_μ = 1, the ground and the top at x_r = 0, 1.
        let (r, mu) = m.r_mu(0.0, 0.4);
        assert!((mu - 1.0).abs() < 1e-12, "{r} {mu}");
        let (r, mu) = m.r_mu(1.0, 0.4);
        assert!((mu - m.mu_horizon(r)).abs() < 1e-12);
        assert!((m.r_mu(0.3, 0.0).0 - 6371.0).abs() < 1e-9 && (m.r_mu(0.3, 1.0).0 - 6471.0).abs() < 1e-9);
    }

    /// The table's bilinear decode against the column table's own
    /// transmittance at points between texel centres, the clear sky from 0
    /// to 12 km: within 0.2 % of the sun's Y wherever the sun is more than
    /// half a degree above the grazing ray (measured: 0.11 %, at the top of
    /// the aerosols' boundary layer at 2 km, whose kink falls between rows
    /// about 0.45 km apart there; 0.05 % elsewhere), and the sun's colour
    /// goes red toward the horizon.
    #[test]
    fn the_table_decodes_the_column_tables_transmittance() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let atm = Atmosphere::load(&root.join("atmospheres/clear.toml")).unwrap();
        let spectral = SpectralSettings { band_nm: 20.0, wavelength_sampling: WavelengthSampling::Hero, spectral_nm: Vec::new(), xyz: true };
        let scene = Scene::new(&atm, &spectral, &MieCache::new(None), &|| {});
        let table = TransmittanceTable::compute(&scene);
        let top_y = table.top_xyz[1];
        let mut worst: f64 = 0.0;
        for k in 0..400 {
            let z = 12.0 * ((k * 7919) % 400) as f64 / 400.0;
            let r = table.mapping.bottom_radius_km + z;
            let lo = table.mapping.mu_horizon(r).acos().to_degrees() - 0.5;
            let zenith_deg = lo * ((k * 104729) % 1000) as f64 / 1000.0;
            let mu = zenith_deg.to_radians().cos();
            let exact = sun_xyz_at(&scene, z, mu)[1];
            let decoded = table.sample_xyz(z, mu)[1];
            worst = worst.max((decoded - exact).abs() / top_y);
        }
        assert!(worst < 2e-3, "worst error {worst:e} of the sun's Y");
        let rgb = table.channel_texels(&crate::lut::colour::ColourSpace::Rec709.xyz_to_rgb());
        let noon = rgb[0];
        let low = rgb[WIDTH - 8];
        assert!(noon.iter().all(|&t| t > 0.5 && t < 1.0), "{noon:?}");
        assert!(low[0] > low[1] && low[1] > low[2], "{low:?}");
        // Below the grazing ray: nothing.
        assert_eq!(table.sample_xyz(0.0, -0.05), [0.0; 3]);
    }

    /// The column table (what the LUT is made from) against an independent
    /// quadrature of the optical depth along the curved ray for the
    /// exponential Rayleigh slab of the DISORT tests, made spherical:
    /// σ(z) = σ₀ e^(−z/8 km) integrated by the midpoint rule on 20 000
    /// steps, at sun zeniths up to 89°, from 0 and 5 km.
    #[test]
    fn the_column_tables_transmittance_matches_quadrature() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let mut atm = Atmosphere::load(&root.join("tests/atmospheres/disort_rayleigh.toml")).unwrap();
        atm.planet.geometry = crate::atmosphere::Geometry::Spherical;
        let spectral = SpectralSettings { band_nm: 40.0, wavelength_sampling: WavelengthSampling::Hero, spectral_nm: Vec::new(), xyz: true };
        let scene = Scene::new(&atm, &spectral, &MieCache::new(None), &|| {});
        let (rad, top) = (scene.medium.radius_km, scene.medium.top_km);
        let o = &scene.band_optics[0];
        let sigma0: f64 = o.extinction[0] * scene.medium.density(0, 0.0);
        for z0 in [0.0, 5.0] {
            for deg in [0.0, 45.0, 75.0, 85.0, 89.0] {
                let mu = f64::to_radians(deg).cos();
                let r0 = rad + z0;
                let len = distance_to_top_km(r0, mu, rad + top);
                let n = 20_000;
                let ds = len / n as f64;
                let tau: f64 = (0..n)
                    .map(|k| {
                        let s = (k as f64 + 0.5) * ds;
                        let r = (r0 * r0 + s * s + 2.0 * r0 * s * mu).sqrt();
                        sigma0 * (-(r - rad) / 8.0).exp() * ds
                    })
                    .sum();
                let ours = scene.columns.optical_depth(z0, mu, &o.extinction);
                assert!((ours / tau - 1.0).abs() < 2e-3, "{z0} km, {deg} deg: column {ours}, quadrature {tau}");
            }
        }
    }
}
