//! Directions toward the lit air, for vertices in the Earth's shadow.
//!
//! At twilight a vertex in the Earth's shadow is lit only by air the sun
//! still reaches: above the shadow, and toward the sun just over the
//! vertex's horizon (the twilight arch). `Kernel::skylight_along` estimates
//! that light along the direction the path continues in, which the local
//! phase function draws without regard to where the lit air is; the arch
//! is a small solid angle, so a few paths carry most of the estimate (with
//! the sun 6° below the horizon, the top 0.1 % of paths carried a third of
//! the clear sky's zenith radiance, and the skylight estimate 94 % of it).
//!
//! This guide tabulates, once per render, the single-scattering radiance
//! arriving at points above the observer, by altitude (bins below) and
//! direction (16 × 16 cells equal in cos θ and in azimuth from the sun's
//! vertical, 0 to π, the other half mirrored), each the line integral of
//! σ_s p T T_sun along the cell's central direction by the midpoint rule
//! on 32 steps to the ground or the top of the atmosphere, plus 1 % of the
//! bin's mean so no direction is left out. The medium is spherically
//! symmetric, so a vertex elsewhere uses the table of its altitude in its
//! own local frame; the sun's elevation differs there by the angle between
//! the verticals (a degree per 111 km), which only makes the guide less
//! apt, never the estimate biased: the kernel combines the guide's
//! directions with the phase function's by multiple importance sampling.

use super::guide::{phases_to_sun_into, single_scattering};
use super::rng::Rng;
use super::tracer::Tracer;
use glam::DVec3;
use std::f64::consts::PI;

/// Altitude bin edges, km (the last bin reaches the top).
const Z_EDGES_KM: [f64; 10] = [0.0, 1.0, 2.5, 5.0, 10.0, 15.0, 20.0, 30.0, 45.0, 70.0];
const N_MU: usize = 16;
const N_PHI: usize = 16;
const STEPS: usize = 32;

/// See the module's note.
#[derive(Debug, Clone)]
pub struct SkylightGuide {
    sun: DVec3,
    /// Per altitude bin, the cumulative probability over its cells
    /// (index `i_mu * N_PHI + i_phi`), N_MU · N_PHI + 1 entries from 0 to 1.
    cdf: Vec<Vec<f64>>,
}

impl SkylightGuide {
    /// The guide for `tracer`'s medium and sun (which needs a column
    /// table); None when the sun is less than 2° below the horizon, or no
    /// cell sees lit air.
    pub fn build(tracer: &Tracer) -> Option<SkylightGuide> {
        tracer.columns?;
        let medium = tracer.medium;
        let sun = tracer.sun_dir;
        // Only with the sun at least 2° below the horizon
        // (`sky bench bake --skies clear,hazed --methods quadrature`,
        // efficiency = 1 / (variance × time per path), with / without:
        // clear 0.7× at 91°, 1.4× at 93°, 4.9× at 96°, 1.0× at 99°; hazed
        // 0.45× at 91°, 0.6× at 93°, 2.8× at 96°, 1.8× at 99°: where the
        // shadow is shallow the sun estimate already finds the light and
        // the guided estimate only costs time).
        if medium.up(medium.observer(0.0)).dot(sun) > -libm::sin(2f64.to_radians()) {
            return None;
        }
        let mut phases = Vec::new();
        let components = tracer.spectral.extinction.len();
        let mut cdf = Vec::with_capacity(Z_EDGES_KM.len());
        for (k, &z0) in Z_EDGES_KM.iter().enumerate() {
            let z1 = Z_EDGES_KM.get(k + 1).copied().unwrap_or(medium.top_km);
            let x = medium.observer(0.5 * (z0 + z1).min(medium.top_km - 1e-3));
            let (up, h, e2) = frame(medium.up(x), sun);
            let mut values = vec![0.0; N_MU * N_PHI];
            for i_mu in 0..N_MU {
                let mu = -1.0 + 2.0 * (i_mu as f64 + 0.5) / N_MU as f64;
                let s = (1.0 - mu * mu).max(0.0).sqrt();
                for i_phi in 0..N_PHI {
                    let phi = PI * (i_phi as f64 + 0.5) / N_PHI as f64;
                    let w = up * mu + (h * phi.cos() + e2 * phi.sin()) * s;
                    let Some(end) = medium.ray_end(x, w) else { continue };
                    phases_to_sun_into(&[tracer], w, &mut phases);
                    let dt = end / STEPS as f64;
                    values[i_mu * N_PHI + i_phi] = (0..STEPS)
                        .map(|j| single_scattering(&[tracer], &phases, components, x, w, (j as f64 + 0.5) * dt))
                        .sum::<f64>()
                        * dt;
                }
            }
            let mean = values.iter().sum::<f64>() / values.len() as f64;
            if !(mean > 0.0) || !mean.is_finite() {
                return None;
            }
            let mut c = Vec::with_capacity(values.len() + 1);
            let mut acc = 0.0;
            c.push(0.0);
            for v in &values {
                acc += v + 0.01 * mean;
                c.push(acc);
            }
            for v in &mut c {
                *v /= acc;
            }
            cdf.push(c);
        }
        Some(SkylightGuide { sun, cdf })
    }

    fn bin(&self, z_km: f64) -> usize {
        (Z_EDGES_KM.partition_point(|&e| e <= z_km).max(1) - 1).min(self.cdf.len() - 1)
    }

    /// A direction at a vertex `x` at altitude `z_km` with local vertical
    /// `up`, and its density (sr⁻¹).
    pub fn sample(&self, up: DVec3, z_km: f64, rng: &mut Rng) -> (DVec3, f64) {
        let c = &self.cdf[self.bin(z_km)];
        let u = rng.uniform();
        let cell = (c.partition_point(|&v| v <= u).max(1) - 1).min(N_MU * N_PHI - 1);
        let (i_mu, i_phi) = (cell / N_PHI, cell % N_PHI);
        let mu = -1.0 + 2.0 * (i_mu as f64 + rng.uniform()) / N_MU as f64;
        let mut phi = PI * (i_phi as f64 + rng.uniform()) / N_PHI as f64;
        if rng.uniform() < 0.5 {
            phi = -phi;
        }
        let (up, h, e2) = frame(up, self.sun);
        let s = (1.0 - mu * mu).max(0.0).sqrt();
        let w = (up * mu + (h * phi.cos() + e2 * phi.sin()) * s).normalize();
        (w, self.cell_pdf(c, cell))
    }

    /// The density of direction `w` at a vertex at altitude `z_km` with
    /// local vertical `up`, sr⁻¹.
    pub fn pdf(&self, up: DVec3, z_km: f64, w: DVec3) -> f64 {
        let c = &self.cdf[self.bin(z_km)];
        let (up, h, e2) = frame(up, self.sun);
        let mu = w.dot(up).clamp(-1.0, 1.0);
        let phi = libm::atan2(w.dot(e2).abs(), w.dot(h));
        let i_mu = (((mu + 1.0) * 0.5 * N_MU as f64) as usize).min(N_MU - 1);
        let i_phi = ((phi / PI * N_PHI as f64) as usize).min(N_PHI - 1);
        self.cell_pdf(c, i_mu * N_PHI + i_phi)
    }

    /// A cell's probability over its solid angle, both mirror halves:
    /// Δμ = 2 / N_MU, Δφ = π / N_PHI, twice.
    fn cell_pdf(&self, c: &[f64], cell: usize) -> f64 {
        let p = c[cell + 1] - c[cell];
        p / (2.0 * (2.0 / N_MU as f64) * (PI / N_PHI as f64))
    }
}

/// The local vertical, the horizontal direction toward the sun, and the
/// third axis (any horizontal pair when the sun is overhead).
fn frame(up: DVec3, sun: DVec3) -> (DVec3, DVec3, DVec3) {
    let h = sun - up * sun.dot(up);
    let h = if h.length_squared() > 1e-12 { h.normalize() } else { up.any_orthonormal_vector() };
    (up, h, up.cross(h))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::atmosphere::Atmosphere;
    use crate::directions::camera::direction_deg;
    use crate::mie::MieCache;
    use crate::render::tracer::Estimator;
    use crate::render::{Scene, SpectralSettings, WavelengthSampling};

    /// The density integrates to 1 over the sphere and agrees with the
    /// sampler: directions drawn from it evaluate to the density returned.
    #[test]
    fn the_guide_is_a_density_and_its_sampler_agrees() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let atm = Atmosphere::load(&root.join("atmospheres/clear.toml")).unwrap();
        let spectral = SpectralSettings {
            band_nm: 40.0,
            wavelength_sampling: WavelengthSampling::Hero,
            spectral_nm: vec![550.0],
            xyz: false,
        };
        let scene = Scene::new(&atm, &spectral, &MieCache::shared_by_tests(), &|| {});
        let t = Tracer::new(&scene.medium, &scene.line_optics[0], direction_deg(96.0, 30.0), 0.533, Estimator::Full)
            .with_columns(&scene.columns);
        let g = SkylightGuide::build(&t).expect("a twilight guide");
        let up = DVec3::new(0.3, -0.2, 1.0).normalize();
        for z in [0.5, 12.0, 80.0] {
            // ∫ pdf dω by a fine midpoint grid in (μ, φ).
            let n = 400;
            let (up_, h, e2) = frame(up, t.sun_dir);
            let mut total = 0.0;
            for a in 0..n {
                let mu = -1.0 + 2.0 * (a as f64 + 0.5) / n as f64;
                let s = (1.0 - mu * mu).sqrt();
                for b in 0..n {
                    let phi = 2.0 * PI * (b as f64 + 0.5) / n as f64;
                    let w = up_ * mu + (h * phi.cos() + e2 * phi.sin()) * s;
                    total += g.pdf(up, z, w);
                }
            }
            total *= (2.0 / n as f64) * (2.0 * PI / n as f64);
            assert!((total - 1.0).abs() < 1e-2, "∫ pdf = {total} at {z} km");
            let mut rng = Rng::new(1, 2, 3);
            for _ in 0..1000 {
                let (w, p) = g.sample(up, z, &mut rng);
                assert!((w.length() - 1.0).abs() < 1e-9);
                assert!((g.pdf(up, z, w) / p - 1.0).abs() < 1e-9, "{p} against {}", g.pdf(up, z, w));
            }
        }
        // A sun higher than 2° below the horizon needs no guide.
        for sun_zenith_deg in [60.0, 91.0] {
            let t = Tracer::new(
                &scene.medium,
                &scene.line_optics[0],
                direction_deg(sun_zenith_deg, 0.0),
                0.533,
                Estimator::Full,
            )
            .with_columns(&scene.columns);
            assert!(SkylightGuide::build(&t).is_none());
        }
    }

    /// A shipped atmosphere's scene with one spectral line at 550 nm.
    fn line_scene(name: &str) -> Scene {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let atm = Atmosphere::load(&root.join(format!("atmospheres/{name}.toml"))).unwrap();
        let spectral = SpectralSettings {
            band_nm: 40.0,
            wavelength_sampling: WavelengthSampling::Hero,
            spectral_nm: vec![550.0],
            xyz: false,
        };
        Scene::new(&atm, &spectral, &MieCache::shared_by_tests(), &|| {})
    }

    /// The line's tracer of the sky without the sun's disk and without
    /// single scattering (what the guides act on), sun at azimuth 0.
    fn sky_tracer(scene: &Scene, sun_zenith_deg: f64) -> Tracer<'_> {
        Tracer::new(&scene.medium, &scene.line_optics[0], direction_deg(sun_zenith_deg, 0.0), 0.533, Estimator::Full)
            .with_sun_disk(false)
            .with_columns(&scene.columns)
            .with_single_skipped(true)
    }

    /// The guided skylight technique changes only the noise: at twilight
    /// (sun 96° and 93°, clear and hazed skies) paths with and without the
    /// guide agree within the Šidák threshold of the 12 directions (3.5,
    /// 0.5 % family-wise) and the sum of the z-scores within 3 √12; and
    /// with the guide the per-sample variance falls where the Earth's
    /// shadow is deep. Twilight paths are heavy-tailed: the standard errors
    /// are 3 to 15 % of the radiance, so this catches a bias of 10 % or
    /// more in aggregate; the exact checks of the density and its sampler
    /// above carry the rest.
    #[test]
    fn guided_skylight_changes_only_the_noise() {
        use crate::render::guide::RayGuide;
        use crate::render::kernel::{Kernel, Scratch};
        let (mut z_sum, mut n, mut var_off, mut var_on) = (0.0, 0, 0.0, 0.0);
        for (name, sun_zenith_deg) in [("clear", 96.0), ("hazed", 93.0)] {
            let scene = line_scene(name);
            let t = sky_tracer(&scene, sun_zenith_deg);
            let g = SkylightGuide::build(&t).unwrap();
            let origin = t.observer(0.0);
            let mut scratch = Scratch::default();
            for (j, (vz, va)) in [(0.0, 0.0), (30.0, 180.0), (60.0, 90.0), (80.0, 0.0), (88.0, 180.0), (100.0, 45.0)]
                .into_iter()
                .enumerate()
            {
                let d = direction_deg(vz, va);
                let guide = RayGuide::build(&t, origin, d);
                let k = 12_000u64;
                let run = |with: bool, scratch: &mut Scratch| -> (f64, f64) {
                    let (mut m1, mut m2) = (0.0, 0.0);
                    for i in 0..k {
                        let kernel = Kernel::single(&t).with_sky_guide(with.then_some(&g));
                        let v = kernel
                            .radiance(origin, d, guide.as_ref(), scratch, &mut Rng::new(11 + with as u64, j as u64, i))
                            .scattered[0];
                        m1 += v;
                        m2 += v * v;
                    }
                    let mean = m1 / k as f64;
                    (mean, (m2 / k as f64 - mean * mean).max(0.0))
                };
                let (a, va_) = run(false, &mut scratch);
                let (b, vb) = run(true, &mut scratch);
                let se = ((va_ + vb) / k as f64).sqrt();
                let z = (b - a) / se;
                eprintln!("{name} sun {sun_zenith_deg}, view ({vz}, {va}): without {a:.4e}, with {b:.4e} (z = {z:+.2}); relative variance per sample {:.1} -> {:.1}", va_ / a / a, vb / b / b);
                assert!(z.abs() < 3.5, "{name} sun {sun_zenith_deg}, view ({vz}, {va}): {a:e} against {b:e}, z = {z}");
                z_sum += z;
                n += 1;
                var_off += va_ / (a * a);
                var_on += vb / (b * b);
            }
        }
        assert!(z_sum.abs() < 3.0 * (n as f64).sqrt(), "aggregate: sum of z {z_sum}");
        assert!(
            var_on < 0.5 * var_off,
            "relative variance summed over the directions: {var_off:.1} without the guide, {var_on:.1} with it"
        );
    }

    /// The skylight estimates are skipped inside clouds
    /// (`SKYLIGHT_MAX_EXTINCTION_PER_KM`), which should change only the
    /// cost: under cloudy2 at twilight (sun 94°, the cloud in the Earth's
    /// shadow) and cloudy5 with the sun 2° high (where the sun's grazing
    /// path through the layer underflows to 0, so its vertices count as
    /// shadowed), paired paths with the estimates everywhere and with the
    /// limit differ within the Šidák threshold of the 6 directions (3.2 at
    /// 1 % family-wise; 3.5 is used), and the sum of the z-scores within
    /// 3 √6. This is weak: these paths are so heavy-tailed that the standard
    /// error of the difference is 20 to 50 % of the radiance, so only a
    /// gross error (a dropped or doubled estimate of the order of the
    /// radiance) fails it. Both branches are the estimators the other
    /// tests of this file and of the kernel check on their own.
    #[test]
    fn skylight_estimates_inside_clouds_change_only_the_cost() {
        use crate::render::guide::RayGuide;
        use crate::render::kernel::{Kernel, Scratch};
        let (mut z_sum, mut n) = (0.0, 0);
        for (name, sun_zenith_deg) in [("cloudy2", 94.0), ("cloudy5", 88.0)] {
            let scene = line_scene(name);
            let t = sky_tracer(&scene, sun_zenith_deg);
            // None with the sun above 2° below the horizon.
            let g = SkylightGuide::build(&t);
            let origin = t.observer(0.0);
            let mut scratch = Scratch::default();
            for (j, (vz, va)) in [(0.0, 0.0), (60.0, 0.0), (80.0, 180.0)].into_iter().enumerate() {
                let d = direction_deg(vz, va);
                let guide = RayGuide::build(&t, origin, d);
                // Paired: both variants draw the same random numbers, so
                // paths that meet no shadowed vertex inside the cloud are
                // identical and only the others enter the difference.
                let k = 4_000u64;
                let (mut m_a, mut m_d, mut m_d2) = (0.0, 0.0, 0.0);
                for i in 0..k {
                    let limited = Kernel::single(&t).with_sky_guide(g.as_ref());
                    let b = limited
                        .radiance(origin, d, guide.as_ref(), &mut scratch, &mut Rng::new(17, j as u64, i))
                        .scattered[0];
                    let everywhere = Kernel::single(&t).with_sky_guide(g.as_ref()).with_skylight_everywhere();
                    let a = everywhere
                        .radiance(origin, d, guide.as_ref(), &mut scratch, &mut Rng::new(17, j as u64, i))
                        .scattered[0];
                    m_a += a;
                    m_d += b - a;
                    m_d2 += (b - a) * (b - a);
                }
                let (a, diff) = (m_a / k as f64, m_d / k as f64);
                let se = ((m_d2 / k as f64 - diff * diff).max(0.0) / (k as f64 - 1.0)).sqrt();
                let z = if se > 0.0 { diff / se } else { 0.0 };
                eprintln!("{name} sun {sun_zenith_deg}, view ({vz}, {va}): everywhere {a:.4e}, limited minus everywhere {diff:+.3e} ± {se:.1e} (z = {z:+.2}, {:.1} % of the radiance)", 100.0 * se / a);
                assert!(
                    z.abs() < 3.5,
                    "{name} sun {sun_zenith_deg}, view ({vz}, {va}): difference {diff:e} ± {se:e}, z = {z}"
                );
                z_sum += z;
                n += 1;
            }
        }
        assert!(z_sum.abs() < 3.0 * (n as f64).sqrt(), "aggregate: sum of z {z_sum}");
    }
}
