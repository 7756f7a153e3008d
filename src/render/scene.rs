//! The prepared scene: the medium, its column table and the optics of
//! every band and spectral line, computed once for any number of views.

use super::bands::Bands;
use super::medium::{ColumnTable, Medium, Spectral};
use super::settings::SpectralSettings;
use crate::atmosphere::Atmosphere;
use crate::mie::MieCache;

/// The prepared scene: medium, per-band and per-line optics. It travels in
/// farm jobs (postcard-encoded), so every worker renders with the very same
/// numbers whatever its platform's maths library.
#[derive(serde::Serialize, serde::Deserialize)]
pub struct Scene {
    pub medium: Medium,
    pub columns: ColumnTable,
    pub bands: Bands,
    pub band_optics: Vec<Spectral>,
    pub line_optics: Vec<Spectral>,
    pub sun_angular_diameter_deg: f64,
    /// What the optics were prepared for.
    pub spectral: SpectralSettings,
}

impl Scene {
    /// Computes the optics (Mie tables come from `cache`); `on_step` is
    /// called after each wavelength, for progress.
    pub fn new(atm: &Atmosphere, s: &SpectralSettings, cache: &MieCache, on_step: &(dyn Fn() + Sync)) -> Scene {
        let medium = Medium::new(atm);
        // Beside the Mie tables: `SKY_CACHE_DIR/columns`.
        let columns = ColumnTable::cached(&medium, cache.dir().and_then(std::path::Path::parent));
        let bands = Bands::new(atm, s.band_nm, s.wavelength_sampling);
        let band_optics = if s.xyz {
            (0..bands.len())
                .map(|b| {
                    let o = medium.spectral(atm, bands.centre_nm[b], 1.0, bands.ground_albedo[b], cache);
                    on_step();
                    o
                })
                .collect()
        } else {
            Vec::new()
        };
        let line_optics = s
            .spectral_nm
            .iter()
            .map(|&l| {
                let o = medium.spectral(atm, l, atm.sun.irradiance_w_m2_nm.eval(l), atm.ground_albedo.eval(l), cache);
                on_step();
                o
            })
            .collect();
        Scene {
            medium,
            columns,
            bands,
            band_optics,
            line_optics,
            sun_angular_diameter_deg: atm.sun.angular_diameter_deg,
            spectral: s.clone(),
        }
    }

    /// The size of the encoded scene, bytes: what it weighs on the wire, and
    /// about what it holds in memory (its tables are `f64`s either way).
    pub fn encoded_bytes(&self) -> u64 {
        struct Count(u64);
        impl Extend<u8> for Count {
            fn extend<I: IntoIterator<Item = u8>>(&mut self, bytes: I) {
                self.0 += bytes.into_iter().count() as u64;
            }
        }
        postcard::to_extend(self, Count(0)).map(|c| c.0).expect("scenes serialise")
    }

    /// How many wavelengths `new` evaluates (for a progress bar).
    pub fn steps(atm: &Atmosphere, s: &SpectralSettings) -> usize {
        let b = if s.xyz { Bands::new(atm, s.band_nm, s.wavelength_sampling).len() } else { 0 };
        b + s.spectral_nm.len()
    }
}
