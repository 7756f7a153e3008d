//! Sunlight scattered exactly once on its way to the observer, by
//! deterministic quadrature instead of Monte Carlo: the single-scattering
//! term of the radiative transfer equation (Chandrasekhar 1960, ch. I;
//! Bruneton & Neyret 2008, eq. 3),
//!
//!   L₁(o, ω) = ∫₀^s_end T(o, x_s) Σ_i σ_s,i(z_s) p_i(ω·ω_sun) T_sun(x_s) E_sun ds
//!            + T(o, x_g) (ρ / π) max(0, n_g·ω_sun) T_sun(x_g) E_sun   (if the ray meets the ground),
//!
//! with x_s = o + s ω, T the transmittance along the view ray, T_sun the
//! transmittance from a point to space toward the sun (exact from the
//! column table, zero in the Earth's shadow) and ρ the ground's albedo.
//! The sun is a parallel light (its disk's extent is left out).
//!
//! It has no noise, so it measures what depends only on the angular and
//! temporal structure of a sky (the aureole, the horizon, the Earth's
//! shadow): how well a LUT's direction and slice interpolation reproduce it
//! (`lut::interpolation`). It is not the whole sky: light scattered two or
//! more times is left out, which makes skies of thick media far too dark.
//!
//! Quadrature: the midpoint rule on steps whose rise is at most 20 m plus
//! 2 % of the altitude, and at most 2 km long (or 1 % of the distance
//! travelled, far along near-horizontal rays), ending where the view ray's
//! optical depth passes 40; the view transmittance is accumulated along
//! the same steps. `tests` check it against the closed
//! form of a plane-parallel Rayleigh slab to 0.1 %.

use super::medium::{ColumnTable, Medium, Spectral};
use super::Scene;
use glam::DVec3;
use std::f64::consts::PI;

/// The longest quadrature step, km (until 1 % of the distance is longer).
const MAX_STEP_KM: f64 = 2.0;
/// Optical depth beyond which the view ray is dark: e^−40 ≈ 4e−18.
const OPAQUE_TAU: f64 = 40.0;

/// Single scattering along view rays of one observer and one sun, for a
/// set of wavelengths (each `Spectral` carries its own solar irradiance).
pub struct SingleScattering<'a> {
    medium: &'a Medium,
    columns: &'a ColumnTable,
    optics: &'a [Spectral],
    sun: DVec3,
    origin: DVec3,
}

impl<'a> SingleScattering<'a> {
    /// For the observer at `altitude_km` above the origin of the horizontal
    /// plane and the sun toward `sun` (world frame, z up).
    pub fn new(medium: &'a Medium, columns: &'a ColumnTable, optics: &'a [Spectral], sun: DVec3, altitude_km: f64) -> SingleScattering<'a> {
        SingleScattering { medium, columns, optics, sun: sun.normalize(), origin: medium.observer(altitude_km) }
    }

    /// The scene's bands (radiance per unit solar irradiance, sr⁻¹).
    pub fn bands(scene: &'a Scene, sun: DVec3, altitude_km: f64) -> SingleScattering<'a> {
        SingleScattering::new(&scene.medium, &scene.columns, &scene.band_optics, sun, altitude_km)
    }

    /// The transmittance from altitude `z_km`, where the sun's direction
    /// makes cosine `mu_sun` with the vertical, to space, for each optics.
    fn sun_transmittance(&self, z_km: f64, mu_sun: f64, out: &mut [f64]) {
        let node = self.columns.node(z_km, mu_sun);
        for (o, sp) in out.iter_mut().zip(self.optics) {
            let tau = self.columns.optical_depth_at(&node, &sp.extinction);
            *o = if tau.is_finite() { libm::exp(-tau) } else { 0.0 };
        }
    }

    /// L₁ toward the observer from direction `dir` (pointing away from
    /// the observer), for each optics: W m⁻² sr⁻¹ nm⁻¹ times the optics'
    /// `sun_irradiance` units (sr⁻¹ for per-unit-irradiance bands).
    pub fn radiance(&self, dir: DVec3) -> Vec<f64> {
        let m = self.medium;
        let d = dir.normalize();
        let n = self.optics.len();
        let mut out = vec![0.0; n];
        let ground = m.distance_to_altitude(self.origin, d, 0.0, false);
        let Some(end) = ground.or_else(|| m.distance_to_altitude(self.origin, d, m.top_km, true)) else { return out };
        let mu_scatter = d.dot(self.sun);
        let phases: Vec<Vec<f64>> = self.optics.iter().map(|sp| sp.phase.iter().map(|p| p.eval(mu_scatter)).collect()).collect();
        let mut tau_view = vec![0.0; n];
        let mut t_sun = vec![0.0; n];
        let mut density = vec![0.0; m.components()];
        let mut s = 0.0;
        while s < end {
            let p = self.origin + d * s;
            let z = m.altitude(p).max(0.0);
            let mu = m.up(p).dot(d).abs();
            // Far along a near-horizontal ray (in a plane-parallel medium,
            // arbitrarily long) steps grow with the distance, 1 % of it.
            let ds = ((0.02 + 0.02 * z) / mu.max(1e-9)).min(MAX_STEP_KM.max(0.01 * s)).min(end - s);
            let x = self.origin + d * (s + 0.5 * ds);
            let zx = m.altitude(x).clamp(0.0, m.top_km);
            self.sun_transmittance(zx, m.up(x).dot(self.sun), &mut t_sun);
            for (i, rho) in density.iter_mut().enumerate() {
                *rho = m.density(i, zx);
            }
            for (k, sp) in self.optics.iter().enumerate() {
                let mut sigma_t = 0.0;
                let mut scatter = 0.0;
                for i in 0..sp.extinction.len() {
                    let e = sp.extinction[i] * density[i];
                    sigma_t += e;
                    scatter += e * sp.albedo[i] * phases[k][i];
                }
                let t_mid = libm::exp(-(tau_view[k] + 0.5 * sigma_t * ds));
                out[k] += t_mid * scatter * t_sun[k] * sp.sun_irradiance * ds;
                tau_view[k] += sigma_t * ds;
            }
            s += ds;
            if tau_view.iter().all(|&t| t > OPAQUE_TAU) {
                // Nothing beyond reaches the observer (nor does the ground).
                return out;
            }
        }
        if let Some(t_g) = ground {
            let g = self.origin + d * t_g;
            let cos_sun = m.up(g).dot(self.sun);
            if cos_sun > 0.0 {
                self.sun_transmittance(0.0, cos_sun, &mut t_sun);
                for (k, sp) in self.optics.iter().enumerate() {
                    out[k] += libm::exp(-tau_view[k]) * sp.ground_albedo / PI * cos_sun * t_sun[k] * sp.sun_irradiance;
                }
            }
        }
        out
    }

    /// CIE XYZ of [`radiance`](Self::radiance) over the scene's bands,
    /// weighted as the renderer weights them (Y in cd m⁻²).
    pub fn xyz(&self, weight: &[[f64; 3]], dir: DVec3) -> [f64; 3] {
        let l = self.radiance(dir);
        let mut xyz = [0.0; 3];
        for (lb, w) in l.iter().zip(weight) {
            for c in 0..3 {
                xyz[c] += w[c] * lb;
            }
        }
        xyz
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::atmosphere::Atmosphere;
    use crate::mie::MieCache;
    use crate::render::camera::direction_deg;
    use crate::render::{SpectralSettings, WavelengthSampling};

    /// The plane-parallel pure-Rayleigh slab (exponential, 8 km scale
    /// height, n₀ = 2.5e25 m⁻³, no depolarisation) seen from its floor: a
    /// single-component medium whose optical depth τ* is known in closed
    /// form, where L₁ toward an upward direction of cosine μ with the sun at
    /// cosine μ₀ is (Liou 2002, eq. 6.2.7; Chandrasekhar 1960, ch. I)
    ///   L₁ = E p(Θ) μ₀ / (μ − μ₀) · (e^(−τ*/μ) − e^(−τ*/μ₀)),
    /// whatever the density profile (only the optical depth enters).
    /// Returns (ours, closed form) for each of `dirs` (zenith, azimuth) at
    /// wavelength `l`, the slab flat or curved around the Earth.
    fn slab(spherical: bool, l: f64, sun_zenith_deg: f64, dirs: &[(f64, f64)]) -> Vec<(f64, f64)> {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let mut atm = Atmosphere::load(&root.join("tests/atmospheres/disort_rayleigh.toml")).unwrap();
        if spherical {
            atm.planet.geometry = crate::atmosphere::Geometry::Spherical;
        }
        let spectral = SpectralSettings { band_nm: 40.0, wavelength_sampling: WavelengthSampling::Hero, spectral_nm: vec![l], xyz: false };
        let scene = Scene::new(&atm, &spectral, &MieCache::new(None), &|| {});
        let sun = direction_deg(sun_zenith_deg, 0.0);
        let ss = SingleScattering::new(&scene.medium, &scene.columns, &scene.line_optics, sun, 0.0);
        // τ* = σ(λ) n₀ H (1 − e^(−top/H)), σ in cm² → m².
        let sigma_cm2 = crate::atmosphere::optics::rayleigh_cross_section_cm2(atm.air.as_ref().unwrap(), l);
        let tau = sigma_cm2 * 1e-4 * 2.5e25 * 8000.0 * (1.0 - (-100.0f64 / 8.0).exp());
        let e = atm.sun.irradiance_w_m2_nm.eval(l);
        let mu0 = sun_zenith_deg.to_radians().cos();
        dirs.iter()
            .map(|&(vz, va)| {
                let d = direction_deg(vz, va);
                let mu = d.z;
                let p = 3.0 / (16.0 * PI) * (1.0 + d.dot(sun).powi(2));
                (ss.radiance(d)[0], e * p * mu0 / (mu - mu0) * ((-tau / mu).exp() - (-tau / mu0).exp()))
            })
            .collect()
    }

    /// The same slab curved around the Earth, seen near the zenith with a
    /// high sun, where curvature changes slant paths by well under 1 %:
    /// the spherical walk, ground intersection and sun columns agree with
    /// the flat closed form (and a wrong unit or factor would not).
    #[test]
    fn a_spherical_slab_near_the_zenith_is_nearly_flat() {
        for (ours, flat) in slab(true, 450.0, 30.0, &[(0.0, 0.0), (20.0, 90.0), (40.0, 180.0)]) {
            let rel = (ours / flat - 1.0).abs();
            assert!(rel < 5e-3, "{ours:e} against {flat:e} ({:.3} %)", 100.0 * rel);
        }
    }

    /// The flat slab against its closed form to 0.1 %.
    #[test]
    fn a_rayleigh_slab_matches_its_closed_form() {
        let mut worst: f64 = 0.0;
        for l in [450.0, 550.0, 650.0] {
            let dirs = [(0.0, 0.0), (30.0, 180.0), (45.0, 90.0), (75.0, 0.0), (85.0, 30.0), (59.0, 0.0)];
            for ((ours, want), (vz, va)) in slab(false, l, 60.0, &dirs).into_iter().zip(dirs) {
                let rel = (ours / want - 1.0).abs();
                worst = worst.max(rel);
                assert!(rel < 1e-3, "{l} nm, view ({vz}, {va}): {ours:e} against {want:e} ({:.3} %)", 100.0 * rel);
            }
        }
        eprintln!("single scattering against the closed form: worst {:.2e}", worst);
    }
}
