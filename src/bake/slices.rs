//! The bake's vocabulary: what a slice is called (`--slice clear:12`), how
//! a bake is run ([`BakeOptions`]), what it gives back per basis sky
//! ([`SkySlices`]), a slice's view, key and seed, and a rendered image cut
//! into slices. The rooms of a bake ([`super::plan`], [`super::queue`],
//! [`super::finish`]) all speak it.

use super::cache::{slice_key, RenderedSlice, SliceCache};
use super::file::{BasisSky, Quality, Sampling};
use super::lighting::SkyLighting;
use super::{BakeError, BakeEvent, BakeSink};
use crate::directions::camera::Camera;
use crate::directions::mapping::{self, DirectionMapping};
use crate::render::tracer::Estimator;
use crate::render::{Image, SingleScatter, SpectralSettings, View, WavelengthSampling};
use crate::session::farm::{Options, WorkerSpec};

/// The seed of every slice. One seed for all slices of a basis sky makes
/// their noise correlated (common random numbers), so the sky does not
/// flicker as a runtime interpolates from one slice to the next.
pub const BAKE_SEED: u64 = 0x5eed_5107;

/// One slice of a bake: `NAME:INDEX` (`--slice clear:12`), or a fog
/// slice, `NAME:fog:INDEX` (its render: the Shadowed Fog's).
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct SliceId {
    pub sky: String,
    pub index: usize,
    pub fog: bool,
}

impl std::str::FromStr for SliceId {
    type Err = String;
    fn from_str(s: &str) -> Result<SliceId, String> {
        let (sky, index) =
            s.rsplit_once(':').ok_or_else(|| format!("{s:?}: expected NAME:INDEX or NAME:fog:INDEX, e.g. clear:12"))?;
        let index: usize = index
            .parse()
            .map_err(|_| format!("{s:?}: the slice index must be a whole number from 0 to {}", mapping::SLICES - 1))?;
        let (sky, fog) = match sky.strip_suffix(":fog") {
            Some(sky) => (sky, true),
            None => (sky, false),
        };
        if index >= mapping::SLICES || sky.is_empty() {
            return Err(format!(
                "{s:?}: expected NAME:INDEX or NAME:fog:INDEX with INDEX from 0 to {}",
                mapping::SLICES - 1
            ));
        }
        Ok(SliceId { sky: sky.to_string(), index, fog })
    }
}

impl std::fmt::Display for SliceId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}:{}{}", self.sky, if self.fog { "fog:" } else { "" }, self.index)
    }
}

/// How a bake computes the light of its sky slices.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Method {
    /// The transport solver (`transport`): no noise; the slices of a basis
    /// sky share one solution per wavelength, on this process's cores.
    #[default]
    Deterministic,
    /// The path tracer (the talk's way, and the referee), on the embedded
    /// worker or the farm.
    MonteCarlo,
}

impl Method {
    /// The name in the bake's flags and manifest.
    pub fn name(self) -> &'static str {
        match self {
            Method::Deterministic => "deterministic",
            Method::MonteCarlo => "monte-carlo",
        }
    }
}

/// How to run a bake.
#[derive(Debug, Clone)]
pub struct BakeOptions {
    pub quality: Quality,
    /// How the sky slices are computed (the fog's by the path tracer
    /// either way, so far).
    pub method: Method,
    pub cache: SliceCache,
    /// The workers (the embedded one: `WorkerSpec::Local`).
    pub workers: Vec<WorkerSpec>,
    pub farm: Options,
    /// The cores the workers have in all, for the cost in core-seconds,
    /// as far as known before the farm's workers say theirs in their Hello
    /// (which then counts).
    pub cores: usize,
    /// Only these slices (none: every slice of every basis sky).
    pub only: Option<Vec<SliceId>>,
    /// Render nothing: every slice must be in the cache (a farm manager's
    /// pack step, after its render tasks), or the bake fails naming those
    /// that are not.
    pub pack_only: bool,
    pub events: Option<BakeSink>,
}

/// The rendered slices of one basis sky, with what packing needs to know.
#[derive(Debug, Clone)]
pub struct SkySlices {
    pub sky: BasisSky,
    pub atmosphere_name: String,
    pub atmosphere_hash: String,
    pub radius_km: f64,
    pub top_km: f64,
    /// The sun zenith angle beyond which a slice is latitude-longitude.
    pub threshold_deg: f64,
    pub spectral: SpectralSettings,
    pub sampling: Sampling,
    /// By slice index; None where `only` left a slice out.
    pub slices: Vec<Option<RenderedSlice>>,
    /// The sun's transmittance and sunlight (None with `only`: a part of a
    /// bake packs nothing).
    pub lighting: Option<SkyLighting>,
    pub rendered: usize,
    pub cached: usize,
    /// Columns of this sky's strip taken from the journal of a bake that
    /// was stopped (the rest of the strip was rendered now).
    pub columns_resumed: u32,
    /// The sky's global-fog LUTs (None with `only`, like `lighting`).
    pub fog: Option<super::fog::SkyFog>,
    /// With `only`: the fog slices rendered now (their Shadowed Fog), by
    /// slice index, for the summary.
    pub fog_rendered: Vec<(usize, RenderedSlice)>,
}

/// The spectral settings of a preset: hero-wavelength sampling, XYZ only.
pub fn spectral_settings(s: &Sampling) -> SpectralSettings {
    SpectralSettings {
        band_nm: s.band_nm,
        wavelength_sampling: WavelengthSampling::Hero,
        spectral_nm: Vec::new(),
        xyz: true,
    }
}

/// The view of slice `index` of `sky`.
pub fn slice_view(sky: &BasisSky, s: &Sampling, index: usize, radius_km: f64, top_km: f64, threshold_deg: f64) -> View {
    let sun_zenith_deg = mapping::slice_sun_zenith_deg(index, radius_km, top_km);
    View {
        camera: Camera::Lut { mapping: DirectionMapping::new(sun_zenith_deg, threshold_deg), sun_azimuth_deg: 0.0 },
        width: sky.width,
        height: sky.height,
        sun_zenith_deg,
        sun_azimuth_deg: 0.0,
        altitude_m: sky.altitude_m,
        spp: s.spp,
        seed: BAKE_SEED,
        estimator: Estimator::Full,
        // The disk belongs in the sunlight LUT, not in a texture that tops out at 65024.
        sun_disk: false,
        single_scatter: SingleScatter::default(),
        fog: None,
        max_rel_error: s.max_rel_error,
    }
}

/// The cache key of a basis sky's slice: its view's, and with multiple
/// scattering on a grid of its own (`ms_grid`), the grid's too; by the
/// transport solver, its resolution and source instead (it takes no grid).
pub fn sky_slice_key(
    atmosphere_hash: &str,
    spectral: &SpectralSettings,
    view: &View,
    (quality, method): (Quality, Method),
    sampling: &Sampling,
) -> String {
    match (method, sampling.ms_grid) {
        (Method::Deterministic, _) => slice_key(atmosphere_hash, spectral, view, &deterministic_tag(quality, sampling)),
        (Method::MonteCarlo, None) => slice_key(atmosphere_hash, spectral, view, quality.name()),
        // The grid's layout and resampling named by their source.
        (Method::MonteCarlo, Some([rows, cols])) => slice_key(
            atmosphere_hash,
            spectral,
            view,
            &format!("{} ms_grid {rows}x{cols} {}", quality.name(), env!("SKY_MS_GRID_SOURCE")),
        ),
    }
}

/// What names a slice rendered by the transport solver in its cache key
/// (sky and fog): the quality, the solver's resolution and its source.
pub fn deterministic_tag(quality: Quality, sampling: &Sampling) -> String {
    format!(
        "{} deterministic {:?} {}",
        quality.name(),
        super::solver::resolution(quality, sampling),
        env!("SKY_TRANSPORT_SOURCE")
    )
}

/// The strip of `views` (LUT slices of one basis sky, same size and
/// sampling) side by side: one farm job (see [`Camera::LutStrip`]). A
/// single view is its own strip.
pub fn strip_view(views: &[&View]) -> View {
    let first = views[0].clone();
    if views.len() == 1 {
        return first;
    }
    let mappings = views
        .iter()
        .map(|v| match &v.camera {
            Camera::Lut { mapping, .. } => *mapping,
            other => panic!("a strip of LUT slices got a {other:?} camera"),
        })
        .collect();
    View {
        camera: Camera::LutStrip { mappings, sun_azimuth_deg: first.sun_azimuth_deg },
        width: first.width * views.len(),
        ..first
    }
}

/// The event of a slice found in the cache (or the same as an earlier one).
pub(super) fn cached_slice(sky: &str, index: usize, s: &RenderedSlice) -> BakeEvent {
    BakeEvent::Slice {
        sky: sky.to_string(),
        index,
        sun_zenith_deg: s.sun_zenith_deg,
        cached: true,
        core_seconds: s.core_seconds,
        forecast_core_seconds: None,
        mean_samples: s.mean_samples(),
    }
}

/// A whole image as one slice (see `slice_of_strip`).
pub(crate) fn slice_of_image(
    image: &Image,
    view: &View,
    sky: &str,
    index: usize,
    core_seconds: f64,
) -> Result<RenderedSlice, BakeError> {
    slice_of_strip(image, 0, view, sky, index, core_seconds)
}

/// Slice `index` of `sky`, the columns of `image` from `x0` on; a texel
/// that is not finite is an error naming it.
pub(super) fn slice_of_strip(
    image: &Image,
    x0: usize,
    view: &View,
    sky: &str,
    index: usize,
    core_seconds: f64,
) -> Result<RenderedSlice, BakeError> {
    let (w, h) = (view.width, view.height);
    let px: Vec<&crate::render::PixelResult> =
        (0..h).flat_map(|y| &image.pixels[y * image.width + x0..y * image.width + x0 + w]).collect();
    for (i, p) in px.iter().enumerate() {
        for (what, v) in [("X", p.xyz[0]), ("Y", p.xyz[1]), ("Z", p.xyz[2])] {
            if !v.is_finite() {
                return Err(BakeError::NotFinite { sky: sky.to_string(), index, u: i % w, v: i / w, what });
            }
        }
    }
    Ok(RenderedSlice {
        width: w,
        height: h,
        sun_zenith_deg: view.sun_zenith_deg,
        xyz: px.iter().map(|p| p.xyz).collect(),
        xyz_stderr: px.iter().map(|p| p.xyz_stderr).collect(),
        samples: px.iter().map(|p| p.samples).collect(),
        core_seconds,
    })
}
