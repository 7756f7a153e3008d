//! The atmosphere as the path tracer sees it: every component's density
//! rasterised on a 10 m altitude grid (linear between nodes), piecewise-
//! constant majorants on altitude shells (250 m up to 20 km, 1 km to 40 km,
//! 5 km above, where there is next to nothing) for delta and ratio
//! tracking (Novák et al. 2014; Novák et al. 2018, §5), and per wavelength
//! the cross-section, albedo and phase function of each component. The
//! column table built from the rasters lives in `columns`.

use crate::atmosphere::optics::{self, rayleigh_cross_section_cm2, rayleigh_depolarization};
use crate::atmosphere::{AerosolOptics, AnalyticPhase, Atmosphere, Geometry};
use crate::mie::{phase, MieCache, PhaseTable};
use std::sync::Arc;

pub use super::columns::{depth_of_columns, ColumnNode, ColumnPath, ColumnTable};

/// Altitude step of the density rasters, km.
pub const GRID_STEP_KM: f64 = 0.01;
/// The majorant shells' boundaries, km, up to `top_km`: every 250 m up to
/// 20 km, every km to 40 km, every 5 km above, plus `kinks_km` (the
/// raster's sharp bends: a cloud layer's base and top). A shell's majorant
/// is its densest point, so a shell that held both clear air and the
/// first metres of a cloud would carry the cloud's extinction over all of
/// its 250 m: delta tracking would take hundreds of null collisions there,
/// and the forced first collision, drawn from the majorant's free path,
/// would land in the clear air almost always and carry weights of
/// e^(τ_majorant − τ) ~ 10³ on the rare draws that reach the cloud (the
/// fireflies under an overcast sky).
fn shell_edges(top_km: f64, kinks_km: &[f64]) -> Vec<f64> {
    let mut e = vec![0.0];
    let mut z = 0.0f64;
    while z < top_km - 1e-9 {
        let step = if z < 20.0 - 1e-9 {
            0.25
        } else if z < 40.0 - 1e-9 {
            1.0
        } else {
            5.0
        };
        z = (z + step).min(top_km);
        e.push(z);
    }
    e.extend(kinks_km.iter().filter(|&&k| k > 0.0 && k < top_km));
    e.sort_by(f64::total_cmp);
    e.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    e
}

/// What scatters or absorbs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum ComponentKind {
    Rayleigh,
    Absorber,
    Aerosol,
}

/// The wavelength-independent part: geometry and density rasters.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Medium {
    pub geometry: Geometry,
    pub radius_km: f64,
    pub top_km: f64,
    pub names: Vec<String>,
    pub kinds: Vec<ComponentKind>,
    /// `density[i][k]`: density of component i (its profile's units) at k·GRID_STEP_KM.
    pub(super) density: Vec<Vec<f64>>,
    /// `shell_max[i][s]`: the maximum of `density[i]` over shell s.
    shell_max: Vec<Vec<f64>>,
    /// Shell boundaries, km (shells + 1 of them).
    pub shell_edges_km: Vec<f64>,
    /// Raster altitudes where some density bends sharply (second
    /// difference above 0.1 % of its largest value), km, ascending.
    #[serde(default)]
    pub kinks_km: Vec<f64>,
}

/// A phase function at one wavelength.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub enum Phase {
    /// No scattering (a pure absorber).
    None,
    Rayleigh {
        depolarization: f64,
    },
    HenyeyGreenstein {
        g: f64,
    },
    CornetteShanks {
        g: f64,
    },
    Table(Arc<PhaseTable>),
}

impl Phase {
    /// p(μ), sr⁻¹.
    pub fn eval(&self, mu: f64) -> f64 {
        match self {
            Phase::None => 0.0,
            Phase::Rayleigh { depolarization } => crate::atmosphere::rayleigh::phase_sr_inv(mu, *depolarization),
            Phase::HenyeyGreenstein { g } => phase::henyey_greenstein(mu, *g),
            Phase::CornetteShanks { g } => phase::cornette_shanks(mu, *g),
            Phase::Table(t) => t.eval_mu(mu),
        }
    }
}

/// The optics of every component at one wavelength.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Spectral {
    pub wavelength_nm: f64,
    /// Extinction coefficient per unit of the component's profile, km⁻¹.
    pub extinction: Vec<f64>,
    pub albedo: Vec<f64>,
    pub phase: Vec<Phase>,
    /// Majorant extinction of each shell, km⁻¹.
    pub majorant: Vec<f64>,
    /// Solar irradiance normal to the beam, W m⁻² nm⁻¹.
    pub sun_irradiance: f64,
    pub ground_albedo: f64,
}

impl Medium {
    /// Rasterises the atmosphere's profiles.
    pub fn new(atm: &Atmosphere) -> Medium {
        let top = atm.planet.top_km;
        let n = (top / GRID_STEP_KM).ceil() as usize + 1;
        let zs: Vec<f64> = (0..n).map(|k| (k as f64 * GRID_STEP_KM).min(top)).collect();
        let mut names = Vec::new();
        let mut kinds = Vec::new();
        let mut density = Vec::new();
        let raster = |scale: f64, profile: usize| -> Vec<f64> {
            zs.iter().map(|&z| scale * atm.profiles[profile].density(z)).collect()
        };
        if let Some(air) = &atm.air {
            names.push("air".to_string());
            kinds.push(ComponentKind::Rayleigh);
            density.push(raster(air.scale, air.profile));
        }
        for a in &atm.absorbers {
            names.push(a.name.clone());
            kinds.push(ComponentKind::Absorber);
            density.push(raster(a.scale, a.profile));
        }
        for a in &atm.aerosols {
            names.push(a.name.clone());
            kinds.push(ComponentKind::Aerosol);
            // Aerosol extinction is carried per unit of the (possibly relative) profile.
            density.push(raster(1.0, a.profile));
        }
        let peaks: Vec<f64> = density.iter().map(|d| d.iter().cloned().fold(0.0, f64::max)).collect();
        let mut kinks_km = Vec::new();
        for k in 1..n.saturating_sub(1) {
            let bends = density
                .iter()
                .zip(&peaks)
                .any(|(d, &peak)| peak > 0.0 && (d[k - 1] - 2.0 * d[k] + d[k + 1]).abs() > 1e-3 * peak);
            if bends {
                kinks_km.push(zs[k]);
            }
        }
        let edges = shell_edges(top, &kinks_km);
        let shell_max = density
            .iter()
            .map(|d| {
                edges
                    .windows(2)
                    .map(|w| {
                        // The raster nodes spanning the shell; an edge on a
                        // node (up to rounding) takes only that node.
                        let lo = ((w[0] / GRID_STEP_KM + 1e-6).floor() as usize).min(d.len() - 1);
                        let hi = ((w[1] / GRID_STEP_KM - 1e-6).ceil() as usize).min(d.len() - 1);
                        d[lo..=hi].iter().cloned().fold(0.0, f64::max)
                    })
                    .collect()
            })
            .collect();
        Medium {
            geometry: atm.planet.geometry,
            radius_km: atm.planet.radius_km,
            top_km: top,
            names,
            kinds,
            density,
            shell_max,
            shell_edges_km: edges,
            kinks_km,
        }
    }

    pub fn components(&self) -> usize {
        self.density.len()
    }

    pub fn shells(&self) -> usize {
        self.shell_edges_km.len() - 1
    }

    /// The shell holding altitude `z_km` (clamped to the atmosphere).
    #[inline]
    pub fn shell_of(&self, z_km: f64) -> usize {
        let e = &self.shell_edges_km;
        (e.partition_point(|&x| x <= z_km).max(1) - 1).min(e.len() - 2)
    }

    /// Density of component `i` at altitude `z_km` (linear on the raster, 0 outside).
    #[inline]
    pub fn density(&self, i: usize, z_km: f64) -> f64 {
        if !(0.0..=self.top_km).contains(&z_km) {
            return 0.0;
        }
        let d = &self.density[i];
        let u = z_km / GRID_STEP_KM;
        let k = (u as usize).min(d.len() - 2);
        let t = u - k as f64;
        d[k] + t * (d[k + 1] - d[k])
    }

    /// The optics of every component at one wavelength. `sun_irradiance`
    /// and `ground_albedo` are passed in so a caller can use band averages.
    pub fn spectral(
        &self,
        atm: &Atmosphere,
        wavelength_nm: f64,
        sun_irradiance: f64,
        ground_albedo: f64,
        cache: &MieCache,
    ) -> Spectral {
        let mut extinction = Vec::new();
        let mut albedo = Vec::new();
        let mut phase_fns = Vec::new();
        if let Some(air) = &atm.air {
            // σ [cm²] · n [m⁻³] → km⁻¹: 1e-4 m²/cm² · 1e3 m/km.
            extinction.push(rayleigh_cross_section_cm2(air, wavelength_nm) * 0.1);
            albedo.push(1.0);
            phase_fns.push(Phase::Rayleigh { depolarization: rayleigh_depolarization(air, wavelength_nm) });
        }
        for a in &atm.absorbers {
            extinction.push(a.cross_section_cm2.eval(wavelength_nm) * 0.1);
            albedo.push(0.0);
            phase_fns.push(Phase::None);
        }
        let grid = phase::phase_grid_deg();
        for a in &atm.aerosols {
            let s = optics::aerosol_scale(atm, a, wavelength_nm, cache);
            extinction.push(s.extinction_per_density_m * 1000.0);
            albedo.push(s.single_scattering_albedo);
            phase_fns.push(match &a.optics {
                AerosolOptics::Analytic { phase: AnalyticPhase::HenyeyGreenstein, g, .. } => {
                    Phase::HenyeyGreenstein { g: *g }
                }
                AerosolOptics::Analytic { phase: AnalyticPhase::CornetteShanks, g, .. } => {
                    Phase::CornetteShanks { g: *g }
                }
                AerosolOptics::Mie { .. } => {
                    let b = optics::mie_particle_optics(a, wavelength_nm, &grid, cache).expect("Mie aerosol");
                    Phase::Table(Arc::new(PhaseTable::new(&grid, &b.phase_sr_inv)))
                }
            });
        }
        let majorant = (0..self.shells())
            .map(|s| {
                let m: f64 = (0..self.components()).map(|i| extinction[i] * self.shell_max[i][s]).sum();
                // A hair above the raster's maximum, so rounding never makes σ_t exceed it.
                m * (1.0 + 1e-9)
            })
            .collect();
        Spectral { wavelength_nm, extinction, albedo, phase: phase_fns, majorant, sun_irradiance, ground_albedo }
    }
}

impl Spectral {
    /// Extinction coefficient (km⁻¹) at an altitude.
    #[inline]
    pub fn sigma_t(&self, medium: &Medium, z_km: f64) -> f64 {
        (0..self.extinction.len()).map(|i| self.extinction[i] * medium.density(i, z_km)).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A ray from a point just above the top of a spherical atmosphere (a
    /// path's vertex can end up there by rounding) never re-enters it: its
    /// walk has no segment, where it had one of infinite length, along
    /// which delta and ratio tracking drew null collisions forever (a
    /// `sky lut verify` of the hazed sky with the sun on the horizon hung).
    #[test]
    fn a_ray_from_above_the_top_has_no_endless_segment() {
        use glam::DVec3;
        let atm = crate::atmosphere::Atmosphere::load(
            &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("atmospheres/analytic-hg.toml"),
        )
        .unwrap();
        let m = Medium::new(&atm);
        for (above_km, d) in
            [(1e-9, DVec3::X), (1e-7, DVec3::new(0.3, 0.0, 1.0).normalize()), (0.0, DVec3::Y), (-1e-9, DVec3::X)]
        {
            let p = DVec3::new(0.0, 0.0, m.radius_km + m.top_km + above_km);
            let segs: Vec<_> = m.walk(p, d).collect();
            assert!(segs.iter().all(|s| s.end_km.is_finite()), "{above_km} km above the top along {d}: {segs:?}");
        }
    }

    /// A cloud layer with sharp edges (the shipped cloudy skies' tables:
    /// density 1 from 3 to 5 km, which the raster ramps to 0 over the 10 m
    /// outside each edge) gets shell edges at its base and top, so no shell
    /// holds both clear air and cloud: every shell's majorant exceeds the
    /// extinction by at most 0.2 of vertical optical depth (the 10 m ramps,
    /// 0.15 each at 30 km⁻¹). With 250 m shells alone the shells below the
    /// base and above the top exceeded it by 7.4: the forced first
    /// collision of a ray toward the cloud carried weights of e^7.4 when it
    /// reached the cloud (fireflies under cloudy5; per-sample relative
    /// variance 41 000 at the zenith, 5 600 with the edges).
    #[test]
    fn a_cloud_layer_has_shells_of_its_own() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let path = root.join("tests/atmospheres/disort_cloud_tau60.toml");
        let text = std::fs::read_to_string(&path)
            .unwrap()
            .replace("altitude_km = [3.0, 3.01, 4.99, 5.0]", "altitude_km = [3.0, 5.0]")
            .replace("density = [0.0, 1.0, 1.0, 0.0]", "density = [1.0, 1.0]");
        let atm = crate::atmosphere::Atmosphere::from_str(&path, &text).unwrap();
        let m = Medium::new(&atm);
        for edge in [2.99, 3.0, 5.0, 5.01] {
            assert!(
                m.shell_edges_km.iter().any(|e| (e - edge).abs() < 1e-9),
                "no shell edge at {edge} km: {:?}",
                m.shell_edges_km
            );
        }
        let sp = m.spectral(&atm, 550.0, 1.0, 0.1, &MieCache::shared_by_tests());
        let mut worst = (0.0f64, 0);
        for s in 0..m.shells() {
            let (a, b) = (m.shell_edges_km[s], m.shell_edges_km[s + 1]);
            let steps = 1000;
            let dz = (b - a) / steps as f64;
            let excess: f64 =
                (0..steps).map(|k| (sp.majorant[s] - sp.sigma_t(&m, a + (k as f64 + 0.5) * dz)) * dz).sum();
            assert!(
                sp.majorant[s] >= sp.sigma_t(&m, a) && sp.majorant[s] >= sp.sigma_t(&m, b),
                "shell {s} ({a}-{b} km): majorant below the extinction"
            );
            if excess > worst.0 {
                worst = (excess, s);
            }
        }
        let s = worst.1;
        assert!(
            worst.0 < 0.2,
            "shell {s} ({}-{} km): majorant exceeds the extinction by {:.2} of optical depth",
            m.shell_edges_km[s],
            m.shell_edges_km[s + 1],
            worst.0
        );
    }
}
