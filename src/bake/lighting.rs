//! What a bake computes for each basis sky besides its sky slices, from
//! the same optics and without Monte Carlo: the sun's transmittance table
//! (`lut::transmittance`) and the sunlight at the observer for each slice
//! (the talk's "Sunlight (parallel light source) intensity": the disk that
//! the sky texture leaves out). Kept in the slice cache under a key of its
//! own, so a re-run with nothing changed prepares no optics.

use super::tables::{sun_xyz_at, transmittance_table};
use crate::lut::transmittance::TransmittanceTable;
use crate::render::Scene;
use serde::{Deserialize, Serialize};

/// Bumped when [`SkyLighting`]'s encoding or meaning changes.
const FORMAT: u32 = 1;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SkyLighting {
    pub transmittance: TransmittanceTable,
    /// The sun's full angular diameter, degrees.
    pub sun_angular_diameter_deg: f64,
    /// Per slice: CIE XYZ of the sun's irradiance at the observer on a
    /// surface facing it (lux; 0 once the sun is below the horizon).
    pub irradiance_xyz: Vec<[f64; 3]>,
}

impl SkyLighting {
    /// From a basis sky's optics, for the observer at `altitude_m` and the
    /// slices' sun zenith angles.
    pub fn compute(scene: &Scene, altitude_m: f64, sun_zenith_deg: &[f64]) -> SkyLighting {
        let z_km = altitude_m / 1000.0;
        SkyLighting {
            transmittance: transmittance_table(scene),
            sun_angular_diameter_deg: scene.sun_angular_diameter_deg,
            irradiance_xyz: sun_zenith_deg
                .iter()
                .map(|&z| sun_xyz_at(scene, z_km, libm::cos(z.to_radians())))
                .collect(),
        }
    }

    /// The solid angle of the sun's disk, sr: 2π (1 − cos(diameter / 2)).
    pub fn sun_solid_angle_sr(&self) -> f64 {
        2.0 * std::f64::consts::PI * (1.0 - libm::cos(0.5 * self.sun_angular_diameter_deg.to_radians()))
    }
}

/// The cache key of a basis sky's lighting.
pub fn lighting_key(
    atmosphere_hash: &str,
    spectral: &crate::render::SpectralSettings,
    altitude_m: f64,
    sun_zenith_deg: &[f64],
) -> String {
    let key = serde_json::json!({
        "what": "lighting",
        "atmosphere": atmosphere_hash,
        "spectral": spectral,
        "altitude_m": altitude_m,
        "sun_zenith_deg": sun_zenith_deg,
        "build": crate::VERSION,
        "render_source": crate::RENDER_SOURCE,
        "format": FORMAT,
    });
    blake3::hash(key.to_string().as_bytes()).to_hex().to_string()
}
