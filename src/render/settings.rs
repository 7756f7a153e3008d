//! What a render is asked for besides the atmosphere: the spectral
//! settings the optics are prepared for ([`SpectralSettings`]), the view
//! of the prepared scene ([`View`]: camera, sun, observer, sampling) with
//! its validation, and the two together ([`Settings`]).

use super::fog::Fog;
use super::tracer::Estimator;
use crate::directions::camera::{self, Camera};
use glam::DVec3;

/// Maximum luminous efficacy, lm/W (CIE).
pub const KM_LM_PER_W: f64 = 683.0;

/// How each sample picks its wavelength band.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum WavelengthSampling {
    /// ∝ the sun's luminance in the band (ȳ E): the talk's choice.
    Luminance,
    /// ∝ (x̄ + ȳ + z̄) E: less noise in X and Z.
    Tristimulus,
    /// Hero wavelengths (Wilkie et al. 2014): four bands drawn ∝ (x̄ + ȳ +
    /// z̄) E at stratified offsets (see `bands`), one of them the hero,
    /// combined by spectral multiple importance sampling.
    Hero,
}

/// How the sunlight scattered once on its way to the camera (or reflected
/// once by the ground) is estimated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum SingleScatter {
    /// By the path's next-event estimate toward the sun at its first vertex.
    MonteCarlo,
    /// By deterministic quadrature along the pixel's ray over every band
    /// (`single::SingleScattering`), once per pixel, where a pixel is one
    /// direction (the `lut` and `directions` cameras); paths then estimate
    /// only light scattered twice or more. Cameras that jitter within a
    /// pixel, and the naive estimator, keep Monte Carlo.
    #[default]
    Quadrature,
}

/// What the optics depend on besides the atmosphere: the input of
/// [`Scene::new`](super::Scene::new), so that one prepared scene serves any number of views.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SpectralSettings {
    /// Width of the spectral bands of the XYZ estimate, nm.
    pub band_nm: f64,
    pub wavelength_sampling: WavelengthSampling,
    /// Extra channels: spectral radiance at these wavelengths.
    pub spectral_nm: Vec<f64>,
    /// Whether to estimate XYZ at all (validation runs may want only spectral channels).
    pub xyz: bool,
}

/// What one view of a prepared scene adds: camera, sun, observer, sampling.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct View {
    pub camera: Camera,
    pub width: usize,
    pub height: usize,
    pub sun_zenith_deg: f64,
    pub sun_azimuth_deg: f64,
    pub altitude_m: f64,
    pub spp: u32,
    pub seed: u64,
    pub estimator: Estimator,
    /// Whether camera rays see the sun's disk (off for comparisons with
    /// codes that report only diffuse radiance).
    pub sun_disk: bool,
    /// Adaptive sampling: each pixel takes the samples a pilot of
    /// [`ADAPTIVE_PILOT_SPP`](super::ADAPTIVE_PILOT_SPP) says it needs for a standard error of its Y
    /// (or of its first spectral channel when XYZ is off) of this fraction
    /// of its value (see [`adaptive_samples`](super::adaptive_samples)); `spp` is then the most a
    /// pixel may take, pilot included.
    pub max_rel_error: Option<f64>,
    /// How single scattering is estimated (see [`SingleScatter`]).
    #[serde(default)]
    pub single_scatter: SingleScatter,
    /// Global fog in front of an object instead of the sky (see `fog`);
    /// the sun's disk is then never seen.
    #[serde(default)]
    pub fog: Option<Fog>,
}

impl View {
    /// One row of (zenith, azimuth) directions in degrees from an observer
    /// at `altitude_m`, the sun at azimuth 0 and its disk hidden, the full
    /// estimator at a fixed sample count: the reference renders of
    /// validations and verifiers (the fields are public to change).
    pub fn directions(dirs: Vec<(f64, f64)>, sun_zenith_deg: f64, altitude_m: f64, spp: u32, seed: u64) -> View {
        View {
            width: dirs.len(),
            height: 1,
            camera: Camera::Directions(dirs),
            sun_zenith_deg,
            sun_azimuth_deg: 0.0,
            altitude_m,
            spp,
            seed,
            estimator: Estimator::Full,
            sun_disk: false,
            max_rel_error: None,
            single_scatter: SingleScatter::default(),
            fog: None,
        }
    }

    /// Unit vector toward the sun.
    pub fn sun_direction(&self) -> DVec3 {
        camera::direction_deg(self.sun_zenith_deg, self.sun_azimuth_deg)
    }

    /// Whether single scattering is computed by quadrature in this view
    /// (see [`SingleScatter::Quadrature`]).
    pub fn single_by_quadrature(&self) -> bool {
        self.single_scatter == SingleScatter::Quadrature && self.estimator == Estimator::Full && !self.camera.jitters()
    }

    /// The views this one renders as: itself, or for a strip of LUT slices
    /// ([`Camera::LutStrip`]) each slice's own view (its width, its sun),
    /// each with the image column where it starts.
    pub fn parts(&self) -> Vec<(usize, View)> {
        match &self.camera {
            Camera::LutStrip { mappings, sun_azimuth_deg } => {
                let w = self.width / mappings.len().max(1);
                mappings
                    .iter()
                    .enumerate()
                    .map(|(k, m)| {
                        let camera = Camera::Lut { mapping: *m, sun_azimuth_deg: *sun_azimuth_deg };
                        (
                            k * w,
                            View {
                                camera,
                                width: w,
                                sun_zenith_deg: m.sun_zenith_deg,
                                sun_azimuth_deg: *sun_azimuth_deg,
                                ..self.clone()
                            },
                        )
                    })
                    .collect()
            }
            _ => vec![(0, self.clone())],
        }
    }

    /// Why a view cannot be rendered, if it cannot: an empty image, or a
    /// strip whose width is not a whole number of equal slices.
    pub fn check(&self) -> Result<(), String> {
        if self.width == 0 || self.height == 0 || self.spp == 0 {
            return Err(format!("empty image {}x{} at {} spp", self.width, self.height, self.spp));
        }
        if let Camera::LutStrip { mappings, .. } = &self.camera {
            if mappings.is_empty() || !self.width.is_multiple_of(mappings.len()) {
                return Err(format!("a strip of {} LUT slices cannot be {} columns wide", mappings.len(), self.width));
            }
        }
        if let Some(fog) = &self.fog {
            if self.estimator == Estimator::Naive {
                return Err("the naive estimator cannot render fog".into());
            }
            fog.check(self.altitude_m / 1000.0)?;
        }
        Ok(())
    }
}

/// Everything that defines a render besides the atmosphere (serialised
/// into farm jobs): the optics' input and the view.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Settings {
    pub spectral: SpectralSettings,
    pub view: View,
}

impl Settings {
    /// Spectral radiance at the ground toward a list of (zenith, azimuth)
    /// directions in degrees, with the sun at azimuth 0 and its disk hidden
    /// unless `sun_disk`: the setting of validations and benchmarks.
    pub fn directions(
        dirs: Vec<(f64, f64)>,
        sun_zenith_deg: f64,
        spectral_nm: Vec<f64>,
        spp: u32,
        seed: u64,
        sun_disk: bool,
    ) -> Settings {
        Settings {
            spectral: SpectralSettings {
                band_nm: 5.0,
                wavelength_sampling: WavelengthSampling::Luminance,
                spectral_nm,
                xyz: false,
            },
            view: View { sun_disk, ..View::directions(dirs, sun_zenith_deg, 0.0, spp, seed) },
        }
    }
}
