//! Rayleigh scattering by air molecules.
//!
//! Cross-sections from Bodhaine, Wood, Dutton and Slusser (1999), "On
//! Rayleigh optical depth calculations", J. Atmos. Oceanic Technol. 16,
//! 1854–1861 (refractive index of Peck and Reeves 1972 with the CO2
//! correction, and the King factor of N2, O2, Ar and CO2), or the power-law
//! fit of Bucholtz (1995), "Rayleigh-scattering calculations for the
//! terrestrial atmosphere", Appl. Opt. 34, 2765–2773.

use std::f64::consts::PI;

/// CO2 mixing ratio (parts per volume) of Bodhaine et al.'s tables.
pub const CO2_PPV: f64 = 360e-6;
/// Molecular number density of standard air (288.15 K, 1013.25 hPa), cm⁻³,
/// as used in Bodhaine et al. 1999 eq. 29.
const N_S_CM3: f64 = 2.546899e19;

/// (n_s − 1) of standard air at 300 ppm CO2, Peck and Reeves (1972) as
/// quoted in Bodhaine et al. 1999 eq. 18; λ in µm.
fn refractivity_300ppm(wavelength_um: f64) -> f64 {
    let s = 1.0 / (wavelength_um * wavelength_um);
    (8060.51 + 2_480_990.0 / (132.274 - s) + 17_455.7 / (39.32957 - s)) * 1e-8
}

/// (n − 1) at a CO2 mixing ratio (parts per volume), Bodhaine eq. 19.
pub fn refractivity(wavelength_um: f64, co2_ppv: f64) -> f64 {
    refractivity_300ppm(wavelength_um) * (1.0 + 0.54 * (co2_ppv - 0.0003))
}

/// King correction factor of air, Bodhaine eq. 23 with eqs. 5 and 6
/// (N2, O2), F(Ar) = 1, F(CO2) = 1.15; volume percentages 78.084, 20.946,
/// 0.934 and the CO2 percentage.
pub fn king_factor_air(wavelength_um: f64, co2_ppv: f64) -> f64 {
    let s = 1.0 / (wavelength_um * wavelength_um);
    let f_n2 = 1.034 + 3.17e-4 * s;
    let f_o2 = 1.096 + 1.385e-3 * s + 1.448e-4 * s * s;
    let c = co2_ppv * 100.0;
    (78.084 * f_n2 + 20.946 * f_o2 + 0.934 * 1.0 + c * 1.15) / (78.084 + 20.946 + 0.934 + c)
}

/// Depolarization ratio ρ from a King factor F = (6 + 3ρ)/(6 − 7ρ).
pub fn depolarization_from_king(f: f64) -> f64 {
    6.0 * (f - 1.0) / (3.0 + 7.0 * f)
}

/// Rayleigh scattering cross-section per molecule, cm², Bodhaine eq. 29:
/// σ = 24π³ (n² − 1)² / (λ⁴ N_s² (n² + 2)²) F_air.
pub fn cross_section_bodhaine_cm2(wavelength_nm: f64) -> f64 {
    let l_um = wavelength_nm * 1e-3;
    let l_cm = wavelength_nm * 1e-7;
    let n = 1.0 + refractivity(l_um, CO2_PPV);
    let n2 = n * n;
    24.0 * PI.powi(3) * (n2 - 1.0).powi(2) / (l_cm.powi(4) * N_S_CM3 * N_S_CM3 * (n2 + 2.0).powi(2))
        * king_factor_air(l_um, CO2_PPV)
}

/// Rayleigh cross-section per molecule, cm², Bucholtz 1995 eq. 8 with the
/// Table 3 coefficients: σ = A λ^−(B + Cλ + D/λ), λ in µm.
pub fn cross_section_bucholtz_cm2(wavelength_nm: f64) -> f64 {
    let l = wavelength_nm * 1e-3;
    let (a, b, c, d) =
        if l < 0.5 { (3.01577e-28, 3.55212, 1.35579, 0.11563) } else { (4.01061e-28, 3.99668, 1.10298e-3, 2.71393e-2) };
    a * l.powf(-(b + c * l + d / l))
}

/// The physical depolarization ratio of air at a wavelength, from the
/// Bodhaine King factor.
pub fn physical_depolarization(wavelength_nm: f64) -> f64 {
    depolarization_from_king(king_factor_air(wavelength_nm * 1e-3, CO2_PPV))
}

/// Rayleigh phase function (sr⁻¹) with depolarization ratio ρ, Chandrasekhar
/// (1950), as in Bucholtz 1995 eqs. 12–13:
/// p(θ) = 3 / (16π (1 + 2γ)) [(1 + 3γ) + (1 − γ) cos²θ], γ = ρ / (2 − ρ).
/// ρ = 0 gives the textbook 3/(16π)(1 + cos²θ).
pub fn phase_sr_inv(cos_theta: f64, depolarization: f64) -> f64 {
    let gamma = depolarization / (2.0 - depolarization);
    3.0 / (16.0 * PI * (1.0 + 2.0 * gamma)) * ((1.0 + 3.0 * gamma) + (1.0 - gamma) * cos_theta * cos_theta)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn phase_is_normalised() {
        for rho in [0.0, 0.0279, 0.1] {
            let n = 20000;
            let mut s = 0.0;
            for i in 0..n {
                let mu = -1.0 + (i as f64 + 0.5) * 2.0 / n as f64;
                s += phase_sr_inv(mu, rho) * 2.0 / n as f64;
            }
            assert!((s * 2.0 * PI - 1.0).abs() < 1e-6, "rho {rho}: {s}");
        }
        assert!((phase_sr_inv(1.0, 0.0) - 6.0 / (16.0 * PI)).abs() < 1e-15);
    }

    #[test]
    fn bodhaine_and_bucholtz_agree_closely() {
        for l in [400.0, 450.0, 550.0, 650.0, 800.0] {
            let a = cross_section_bodhaine_cm2(l);
            let b = cross_section_bucholtz_cm2(l);
            assert!((a / b - 1.0).abs() < 0.01, "{l}: {a} {b}");
        }
        // Bodhaine Table 2 order of magnitude: 4.5e-27 cm² at 550 nm.
        let s = cross_section_bodhaine_cm2(550.0);
        assert!(s > 4.3e-27 && s < 4.7e-27, "{s}");
    }

    #[test]
    fn depolarization_near_published() {
        // Bodhaine 1999 / Bucholtz 1995: ρ ≈ 0.0279 near 550 nm.
        let r = physical_depolarization(550.0);
        assert!((r - 0.0279).abs() < 0.001, "{r}");
    }
}
