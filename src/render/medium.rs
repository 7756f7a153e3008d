//! The atmosphere as the path tracer sees it: every component's density
//! rasterised on a 10 m altitude grid (linear between nodes), piecewise-
//! constant majorants on altitude shells (250 m up to 20 km, 1 km to 40 km,
//! 5 km above, where there is next to nothing) for delta and ratio
//! tracking (Novák et al. 2014; Novák et al. 2018, §5), and per wavelength
//! the cross-section, albedo and phase function of each component.

use crate::atmosphere::optics::{self, rayleigh_cross_section_cm2, rayleigh_depolarization};
use crate::atmosphere::{AerosolOptics, AnalyticPhase, Atmosphere, Geometry};
use crate::mie::{phase, MieCache, PhaseTable};
use std::sync::Arc;

/// Altitude step of the density rasters, km.
pub const GRID_STEP_KM: f64 = 0.01;
/// The majorant shells' boundaries, km, up to `top_km`.
fn shell_edges(top_km: f64) -> Vec<f64> {
    let mut e = vec![0.0];
    let mut z = 0.0f64;
    while z < top_km - 1e-9 {
        let step = if z < 20.0 - 1e-9 { 0.25 } else if z < 40.0 - 1e-9 { 1.0 } else { 5.0 };
        z = (z + step).min(top_km);
        e.push(z);
    }
    e
}

/// What scatters or absorbs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ComponentKind {
    Rayleigh,
    Absorber,
    Aerosol,
}

/// The wavelength-independent part: geometry and density rasters.
#[derive(Debug, Clone)]
pub struct Medium {
    pub geometry: Geometry,
    pub radius_km: f64,
    pub top_km: f64,
    pub names: Vec<String>,
    pub kinds: Vec<ComponentKind>,
    /// `density[i][k]`: density of component i (its profile's units) at k·GRID_STEP_KM.
    density: Vec<Vec<f64>>,
    /// `shell_max[i][s]`: the maximum of `density[i]` over shell s.
    shell_max: Vec<Vec<f64>>,
    /// Shell boundaries, km (shells + 1 of them).
    pub shell_edges_km: Vec<f64>,
}

/// A phase function at one wavelength.
#[derive(Debug, Clone)]
pub enum Phase {
    /// No scattering (a pure absorber).
    None,
    Rayleigh { depolarization: f64 },
    HenyeyGreenstein { g: f64 },
    CornetteShanks { g: f64 },
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
#[derive(Debug, Clone)]
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
    pub fn new(atm: &Atmosphere, cache: &MieCache) -> Medium {
        let top = atm.planet.top_km;
        let n = (top / GRID_STEP_KM).ceil() as usize + 1;
        let zs: Vec<f64> = (0..n).map(|k| (k as f64 * GRID_STEP_KM).min(top)).collect();
        let mut names = Vec::new();
        let mut kinds = Vec::new();
        let mut density = Vec::new();
        let raster = |scale: f64, profile: usize| -> Vec<f64> { zs.iter().map(|&z| scale * atm.profiles[profile].density(z)).collect() };
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
            let _ = cache;
            density.push(raster(1.0, a.profile));
        }
        let edges = shell_edges(top);
        let shell_max = density
            .iter()
            .map(|d| {
                edges
                    .windows(2)
                    .map(|w| {
                        let lo = ((w[0] / GRID_STEP_KM).floor() as usize).min(d.len() - 1);
                        let hi = ((w[1] / GRID_STEP_KM).ceil() as usize).min(d.len() - 1);
                        d[lo..=hi].iter().cloned().fold(0.0, f64::max)
                    })
                    .collect()
            })
            .collect();
        Medium { geometry: atm.planet.geometry, radius_km: atm.planet.radius_km, top_km: top, names, kinds, density, shell_max, shell_edges_km: edges }
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
    pub fn spectral(&self, atm: &Atmosphere, wavelength_nm: f64, sun_irradiance: f64, ground_albedo: f64, cache: &MieCache) -> Spectral {
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
                AerosolOptics::Analytic { phase: AnalyticPhase::HenyeyGreenstein, g, .. } => Phase::HenyeyGreenstein { g: *g },
                AerosolOptics::Analytic { phase: AnalyticPhase::CornetteShanks, g, .. } => Phase::CornetteShanks { g: *g },
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
