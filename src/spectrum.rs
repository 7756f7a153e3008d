//! Spectra and colorimetry: the CIE 1931 2-degree observer, spectrum to XYZ,
//! and the sun's disk radiance.
//!
//! The colour matching functions are embedded from
//! `atmospheres/data/cie1931_2deg_cmf.csv` (CIE 015 table, 360 to 830 nm every
//! 1 nm; see that file's header for its source and licence).

use crate::table::{interp_linear, Table, Tabulated};
use std::path::Path;
use std::sync::OnceLock;

/// Shortest and longest wavelengths of the visible range we integrate over.
pub const VISIBLE_MIN_NM: f64 = 360.0;
pub const VISIBLE_MAX_NM: f64 = 830.0;

const CMF_CSV: &str = include_str!("../atmospheres/data/cie1931_2deg_cmf.csv");

/// CIE 1931 2-degree colour matching functions on a 1 nm grid.
#[derive(Debug, Clone)]
pub struct Cmf {
    pub wavelength_nm: Vec<f64>,
    pub x_bar: Vec<f64>,
    pub y_bar: Vec<f64>,
    pub z_bar: Vec<f64>,
}

impl Cmf {
    /// The embedded CIE 1931 2-degree standard observer.
    pub fn cie1931() -> &'static Cmf {
        static CMF: OnceLock<Cmf> = OnceLock::new();
        CMF.get_or_init(|| {
            let t = Table::parse(Path::new("atmospheres/data/cie1931_2deg_cmf.csv"), CMF_CSV)
                .expect("embedded CMF table is valid");
            Cmf {
                wavelength_nm: t.column("wavelength_nm").unwrap().to_vec(),
                x_bar: t.column("x_bar").unwrap().to_vec(),
                y_bar: t.column("y_bar").unwrap().to_vec(),
                z_bar: t.column("z_bar").unwrap().to_vec(),
            }
        })
    }

    /// (x̄, ȳ, z̄) at a wavelength, linearly interpolated, zero outside 360-830 nm.
    pub fn at(&self, wavelength_nm: f64) -> [f64; 3] {
        if !(VISIBLE_MIN_NM..=VISIBLE_MAX_NM).contains(&wavelength_nm) {
            return [0.0; 3];
        }
        let w = &self.wavelength_nm;
        [
            interp_linear(w, &self.x_bar, wavelength_nm),
            interp_linear(w, &self.y_bar, wavelength_nm),
            interp_linear(w, &self.z_bar, wavelength_nm),
        ]
    }

    /// ∫ S(λ) x̄(λ) dλ etc. as a plain sum over the table's 1 nm grid
    /// (the CIE 015 "integration" with Δλ = 1 nm), S linearly interpolated.
    pub fn integrate(&self, spectrum: impl Fn(f64) -> f64) -> [f64; 3] {
        let mut xyz = [0.0; 3];
        for i in 0..self.wavelength_nm.len() {
            let s = spectrum(self.wavelength_nm[i]);
            xyz[0] += s * self.x_bar[i];
            xyz[1] += s * self.y_bar[i];
            xyz[2] += s * self.z_bar[i];
        }
        xyz
    }
}

/// CIE 1931 xy chromaticity of an XYZ triple.
pub fn chromaticity(xyz: [f64; 3]) -> [f64; 2] {
    let s = xyz[0] + xyz[1] + xyz[2];
    [xyz[0] / s, xyz[1] / s]
}

/// XYZ of a tabulated spectrum, integrated at 1 nm over 360-830 nm.
pub fn spectrum_to_xyz(s: &Tabulated) -> [f64; 3] {
    Cmf::cie1931().integrate(|l| s.eval(l))
}

/// Solid angle (sr) of a disk of the given full angular diameter:
/// Ω = 2π (1 − cos(α/2)).
pub fn disk_solid_angle_sr(angular_diameter_deg: f64) -> f64 {
    let half = 0.5 * angular_diameter_deg.to_radians();
    2.0 * std::f64::consts::PI * (1.0 - half.cos())
}

/// Average radiance (W m⁻² sr⁻¹ nm⁻¹) of a uniform sun disk whose spectral
/// irradiance at normal incidence is `irradiance_w_m2_nm` — the talk's
/// "convert them to average radiance since they are given as irradiance".
/// For a small uniform disk E = L Ω (the cosine over the disk differs from 1
/// by less than 1e-5 for the sun).
pub fn sun_disk_radiance(irradiance_w_m2_nm: f64, angular_diameter_deg: f64) -> f64 {
    irradiance_w_m2_nm / disk_solid_angle_sr(angular_diameter_deg)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cmf_table_is_complete() {
        let c = Cmf::cie1931();
        assert_eq!(c.wavelength_nm.first(), Some(&360.0));
        assert_eq!(c.wavelength_nm.last(), Some(&830.0));
        assert_eq!(c.wavelength_nm.len(), 471);
        // ȳ peaks at 555 nm with value 1 (the photopic luminous efficiency).
        let [_, y, _] = c.at(555.0);
        assert!((y - 1.0).abs() < 1e-4, "{y}");
    }

    #[test]
    fn equal_energy_is_near_one_third() {
        let xy = chromaticity(Cmf::cie1931().integrate(|_| 1.0));
        assert!((xy[0] - 1.0 / 3.0).abs() < 2e-4 && (xy[1] - 1.0 / 3.0).abs() < 2e-4, "{xy:?}");
    }

    #[test]
    fn sun_solid_angle() {
        // 0.533 degree disk: 6.8e-5 sr.
        let o = disk_solid_angle_sr(0.533);
        assert!((o - 6.80e-5).abs() < 0.01e-5, "{o}");
    }
}
