//! Optical properties of an atmosphere at a wavelength: per component
//! (air, each absorber, each aerosol) the zenith optical depth, single
//! scattering albedo, asymmetry and extinction at the ground.

use super::*;
use crate::mie::{lognormal, BulkOptics, MieCache};
use serde::Serialize;

/// One component's optics at one wavelength.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ComponentOptics {
    pub name: String,
    /// "rayleigh", "absorber", "aerosol" or "total".
    pub kind: String,
    /// Zenith optical depth from the ground to the top of the atmosphere.
    pub optical_depth: f64,
    pub scattering_optical_depth: f64,
    pub absorption_optical_depth: f64,
    pub single_scattering_albedo: f64,
    /// ⟨cos θ⟩ of the phase function (for "total": weighted by scattering optical depth).
    pub asymmetry: f64,
    /// Extinction coefficient at 0 km, km⁻¹.
    pub extinction_ground_per_km: f64,
}

/// Everything at one wavelength.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SpectralOptics {
    pub wavelength_nm: f64,
    pub rayleigh_optical_depth: f64,
    pub absorber_optical_depth: f64,
    pub aerosol_optical_depth: f64,
    pub components: Vec<ComponentOptics>,
    pub total: ComponentOptics,
}

/// Rayleigh cross-section per molecule (cm²) of this air.
pub fn rayleigh_cross_section_cm2(air: &Air, wavelength_nm: f64) -> f64 {
    match &air.cross_section {
        CrossSection::Bodhaine1999 => rayleigh::cross_section_bodhaine_cm2(wavelength_nm),
        CrossSection::Bucholtz1995 => rayleigh::cross_section_bucholtz_cm2(wavelength_nm),
        CrossSection::Table(t) => t.eval(wavelength_nm),
    }
}

/// The depolarization ratio to use in the Rayleigh phase function.
pub fn rayleigh_depolarization(air: &Air, wavelength_nm: f64) -> f64 {
    match air.depolarization {
        Depolarization::Physical => rayleigh::physical_depolarization(wavelength_nm),
        Depolarization::Fixed(r) => r,
    }
}

/// Per-particle Mie optics of a Mie aerosol at a wavelength (modes mixed),
/// with the phase function at `angles_deg` (may be empty).
pub fn mie_particle_optics(
    aerosol: &Aerosol,
    wavelength_nm: f64,
    angles_deg: &[f64],
    cache: &MieCache,
) -> Option<BulkOptics> {
    let AerosolOptics::Mie { refractive_index, modes } = &aerosol.optics else { return None };
    let m = refractive_index.at(wavelength_nm);
    let parts: Vec<(f64, BulkOptics)> =
        modes.iter().map(|(w, mode)| (*w, cache.bulk_optics(m, mode, wavelength_nm, angles_deg))).collect();
    Some(lognormal::mix(&parts))
}

/// An aerosol at one wavelength: extinction coefficient (m⁻¹) per unit of
/// its profile, single-scattering albedo and asymmetry.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AerosolScale {
    pub extinction_per_density_m: f64,
    pub single_scattering_albedo: f64,
    pub g: f64,
}

/// See [`AerosolScale`].
pub fn aerosol_scale(atm: &Atmosphere, aerosol: &Aerosol, wavelength_nm: f64, cache: &MieCache) -> AerosolScale {
    let column_m = atm.profiles[aerosol.profile].column_km(atm.planet.top_km) * 1000.0;
    match &aerosol.optics {
        AerosolOptics::Analytic { g, single_scattering_albedo, angstrom_exponent, .. } => {
            let Amount::OpticalDepth { optical_depth, wavelength_nm: l0 } = aerosol.amount else {
                unreachable!("validated: analytic aerosols are normalised by optical depth")
            };
            // Ångström's law: τ(λ) = τ(λ0) (λ/λ0)^−α.
            let tau = optical_depth * (wavelength_nm / l0).powf(-angstrom_exponent);
            AerosolScale {
                extinction_per_density_m: tau / column_m,
                single_scattering_albedo: *single_scattering_albedo,
                g: *g,
            }
        }
        AerosolOptics::Mie { .. } => {
            let b = mie_particle_optics(aerosol, wavelength_nm, &[], cache).unwrap();
            let c_ext_m2 = b.c_ext_um2 * 1e-12;
            let number_scale = match aerosol.amount {
                Amount::NumberDensityM3(n) => n,
                Amount::Profile => 1.0,
                Amount::OpticalDepth { optical_depth, wavelength_nm: l0 } => {
                    let b0 = if l0 == wavelength_nm {
                        b.clone()
                    } else {
                        mie_particle_optics(aerosol, l0, &[], cache).unwrap()
                    };
                    optical_depth / (b0.c_ext_um2 * 1e-12 * column_m)
                }
            };
            AerosolScale {
                extinction_per_density_m: number_scale * c_ext_m2,
                single_scattering_albedo: b.single_scattering_albedo(),
                g: b.g,
            }
        }
    }
}

/// Number density of particles (m⁻³) per unit of a Mie aerosol's profile.
pub fn aerosol_number_scale(atm: &Atmosphere, aerosol: &Aerosol, cache: &MieCache) -> Option<f64> {
    match aerosol.amount {
        Amount::NumberDensityM3(n) => Some(n),
        Amount::Profile => Some(1.0),
        Amount::OpticalDepth { wavelength_nm, .. } => {
            let b = mie_particle_optics(aerosol, wavelength_nm, &[], cache)?;
            Some(aerosol_scale(atm, aerosol, wavelength_nm, cache).extinction_per_density_m / (b.c_ext_um2 * 1e-12))
        }
    }
}

/// The optics of every component and their total at one wavelength.
pub fn spectral_optics(atm: &Atmosphere, wavelength_nm: f64, cache: &MieCache) -> SpectralOptics {
    let top = atm.planet.top_km;
    let mut components = Vec::new();
    let mut push = |name: &str, kind: &str, tau_ext: f64, tau_sca: f64, g: f64, ext0: f64| {
        components.push(ComponentOptics {
            name: name.to_string(),
            kind: kind.to_string(),
            optical_depth: tau_ext,
            scattering_optical_depth: tau_sca,
            absorption_optical_depth: tau_ext - tau_sca,
            single_scattering_albedo: if tau_ext > 0.0 { tau_sca / tau_ext } else { 0.0 },
            asymmetry: g,
            extinction_ground_per_km: ext0,
        });
    };
    let mut rayleigh_tau = 0.0;
    if let Some(air) = &atm.air {
        let p = &atm.profiles[air.profile];
        let sigma_m2 = rayleigh_cross_section_cm2(air, wavelength_nm) * 1e-4;
        let tau = sigma_m2 * air.scale * p.column_km(top) * 1000.0;
        rayleigh_tau = tau;
        push("air", "rayleigh", tau, tau, 0.0, sigma_m2 * air.scale * p.density(0.0) * 1000.0);
    }
    let mut absorber_tau = 0.0;
    for a in &atm.absorbers {
        let p = &atm.profiles[a.profile];
        let sigma_m2 = a.cross_section_cm2.eval(wavelength_nm) * 1e-4;
        let tau = sigma_m2 * a.scale * p.column_km(top) * 1000.0;
        absorber_tau += tau;
        push(&a.name, "absorber", tau, 0.0, 0.0, sigma_m2 * a.scale * p.density(0.0) * 1000.0);
    }
    let mut aerosol_tau = 0.0;
    for a in &atm.aerosols {
        let p = &atm.profiles[a.profile];
        let s = aerosol_scale(atm, a, wavelength_nm, cache);
        let tau = s.extinction_per_density_m * p.column_km(top) * 1000.0;
        aerosol_tau += tau;
        push(
            &a.name,
            "aerosol",
            tau,
            tau * s.single_scattering_albedo,
            s.g,
            s.extinction_per_density_m * p.density(0.0) * 1000.0,
        );
    }
    let tau: f64 = components.iter().map(|c| c.optical_depth).sum();
    let tau_sca: f64 = components.iter().map(|c| c.scattering_optical_depth).sum();
    let g_w: f64 = components.iter().map(|c| c.asymmetry * c.scattering_optical_depth).sum();
    let ext0: f64 = components.iter().map(|c| c.extinction_ground_per_km).sum();
    let total = ComponentOptics {
        name: "total".into(),
        kind: "total".into(),
        optical_depth: tau,
        scattering_optical_depth: tau_sca,
        absorption_optical_depth: tau - tau_sca,
        single_scattering_albedo: if tau > 0.0 { tau_sca / tau } else { 0.0 },
        asymmetry: if tau_sca > 0.0 { g_w / tau_sca } else { 0.0 },
        extinction_ground_per_km: ext0,
    };
    SpectralOptics {
        wavelength_nm,
        rayleigh_optical_depth: rayleigh_tau,
        absorber_optical_depth: absorber_tau,
        aerosol_optical_depth: aerosol_tau,
        components,
        total,
    }
}
