//! skysim's successor: the full-spectrum path tracer behind `sky render`.
//!
//! Spectral model: the visible range 360–830 nm is split into bands (5 nm
//! by default). Optics are evaluated at each band's centre; the sun's
//! spectrum and the colour matching functions are integrated exactly within
//! the band at 1 nm, so the radiance solved per unit solar irradiance is
//! weighted by W_b = 683 Σ_{λ∈b} E(λ) (x̄, ȳ, z̄)(λ) · 1 nm. By default each
//! sample carries four bands (hero wavelengths, see `hero`); the single-band
//! alternatives pick one band in proportion to its luminance W_b.y (the
//! talk's "wavelengths using spectral luminous efficiency") or to
//! W_b.x + W_b.y + W_b.z (`sky bench spectral` compares the three).
//! X, Y, Z are CIE 1931 tristimulus values of the sky radiance scaled by
//! 683 lm/W, so Y is luminance in cd m⁻²; spectral channels are radiance in
//! W m⁻² sr⁻¹ nm⁻¹.

pub mod adaptive;
pub mod bands;
pub mod camera;
#[cfg(test)]
mod chi2;
pub mod denoise;
pub mod fog;
pub mod guide;
pub mod hero;
pub mod kernel;
pub mod medium;
pub mod output;
pub mod rng;
pub mod sampling;
pub mod segments;
pub mod single;
pub mod sky_guide;
pub mod tracer;

use crate::atmosphere::Atmosphere;
use crate::mie::MieCache;
pub use adaptive::{adaptive_samples, Moments, ADAPTIVE_MIN_SPP, ADAPTIVE_PILOT_SPP};
pub use bands::{Bands, HeroSet, HERO_N};
use camera::Camera;
use fog::Fog;
use glam::DVec3;
use kernel::{Kernel, Scratch};
use medium::{ColumnTable, Medium, Spectral};
use rng::Rng;
use std::sync::atomic::{AtomicBool, Ordering};
use tracer::{Estimator, Tracer};

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
/// [`Scene::new`], so that one prepared scene serves any number of views.
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
    /// [`ADAPTIVE_PILOT_SPP`] says it needs for a standard error of its Y
    /// (or of its first spectral channel when XYZ is off) of this fraction
    /// of its value (see [`adaptive_samples`]); `spp` is then the most a
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
                        (k * w, View { camera, width: w, sun_zenith_deg: m.sun_zenith_deg, sun_azimuth_deg: *sun_azimuth_deg, ..self.clone() })
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

/// A pixel's running sums.
struct Accumulator {
    xyz: [Moments; 3],
    direct: [f64; 3],
    lines: Vec<Moments>,
    taken: u32,
    pilot: u32,
    cut: u32,
    any: bool,
}

impl Accumulator {
    fn new(lines: usize) -> Accumulator {
        Accumulator { xyz: [Moments::default(); 3], direct: [0.0; 3], lines: vec![Moments::default(); lines], taken: 0, pilot: 0, cut: 0, any: false }
    }
}

impl Settings {
    /// Spectral radiance at the ground toward a list of (zenith, azimuth)
    /// directions in degrees, with the sun at azimuth 0 and its disk hidden
    /// unless `sun_disk`: the setting of validations and benchmarks.
    pub fn directions(dirs: Vec<(f64, f64)>, sun_zenith_deg: f64, spectral_nm: Vec<f64>, spp: u32, seed: u64, sun_disk: bool) -> Settings {
        Settings {
            spectral: SpectralSettings { band_nm: 5.0, wavelength_sampling: WavelengthSampling::Luminance, spectral_nm, xyz: false },
            view: View { sun_disk, ..View::directions(dirs, sun_zenith_deg, 0.0, spp, seed) },
        }
    }
}

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
        Scene { medium, columns, bands, band_optics, line_optics, sun_angular_diameter_deg: atm.sun.angular_diameter_deg, spectral: s.clone() }
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

/// Roberts (2018) R1 and R2 sequence increments: 1/φ and (1/g, 1/g²) with
/// g the plastic number.
const R1_A: f64 = 0.618_033_988_749_894_9;
const R2_A1: f64 = 0.754_877_666_246_692_8;
const R2_A2: f64 = 0.569_840_290_998_053_2;

/// Mean and standard error of one pixel's channels.
#[derive(Debug, Clone, PartialEq)]
pub struct PixelResult {
    pub xyz: [f64; 3],
    /// The part of `xyz` that is the sun's disk seen directly.
    pub xyz_direct: [f64; 3],
    pub xyz_stderr: [f64; 3],
    pub spectral: Vec<f64>,
    pub spectral_stderr: Vec<f64>,
    /// Samples taken (fewer than `spp` where adaptive sampling stopped early).
    pub samples: u32,
    /// Paths cut at the vertex limit (`tracer::MAX_VERTICES`), over every
    /// estimate of the pixel (XYZ and spectral lines): 0 unless a medium
    /// traps light for longer than any basis sky does.
    pub paths_cut: u32,
}

impl PixelResult {
    /// A pixel known exactly (a decoded or computed sky, not an estimate):
    /// XYZ alone, no error, one sample.
    pub fn from_xyz(xyz: [f64; 3]) -> PixelResult {
        PixelResult { xyz, xyz_direct: [0.0; 3], xyz_stderr: [0.0; 3], spectral: Vec::new(), spectral_stderr: Vec::new(), samples: 1, paths_cut: 0 }
    }
}

/// What every pixel of a render shares, built once per render: one tracer
/// per band and per spectral line, and the observer.
pub struct PixelTracers<'a> {
    band: Vec<Tracer<'a>>,
    line: Vec<Tracer<'a>>,
    origin: Option<DVec3>,
    /// Directions toward the lit air for paths in the Earth's shadow, from
    /// the band that weighs most in luminance (see `sky_guide`).
    sky_guide: Option<sky_guide::SkylightGuide>,
}

impl<'a> PixelTracers<'a> {
    pub fn new(scene: &'a Scene, s: &View) -> PixelTracers<'a> {
        let sun = s.sun_direction();
        // The first vertex leaves single scattering to the quadrature, or
        // out altogether for a Shadowed Fog.
        let skip_single = s.single_by_quadrature() || s.fog.is_some_and(|f| f.shadowed);
        let make = |o: &'a Spectral| {
            Tracer::new(&scene.medium, o, sun, scene.sun_angular_diameter_deg, s.estimator)
                .with_sun_disk(s.sun_disk && s.fog.is_none())
                .with_columns(&scene.columns)
                .with_single_skipped(skip_single)
                .with_fog(s.fog)
        };
        let band: Vec<Tracer> = scene.band_optics.iter().map(make).collect();
        let line: Vec<Tracer> = scene.line_optics.iter().map(make).collect();
        let origin = band.first().or(line.first()).map(|t| t.observer(s.altitude_m / 1000.0));
        let mut tracers = PixelTracers { band, line, origin, sky_guide: None };
        if s.estimator == Estimator::Full {
            tracers.sky_guide = tracers.reference(scene).and_then(sky_guide::SkylightGuide::build);
        }
        tracers
    }

    /// The band that weighs most in luminance (or the first spectral line):
    /// the guides are built with its optics.
    fn reference(&self, scene: &Scene) -> Option<&Tracer<'a>> {
        self.band.iter().zip(&scene.bands.weight).max_by(|a, b| a.1[1].total_cmp(&b.1[1])).map(|(t, _)| t).or(self.line.first())
    }
}

/// The single scattering of sunlight toward the camera along `dir` by
/// deterministic quadrature over every band and spectral line
/// (`single::SingleScattering`), as view `s` sees it: the sky's, or with a
/// fog the light scattered once by the fog's air. What
/// [`render_pixel`] adds to every sample where
/// [`View::single_by_quadrature`] holds; so a Fog LUT texel is its Shadowed
/// Fog texel (the same paths, which skip the first vertex's sun) plus this.
pub fn single_by_quadrature(scene: &Scene, s: &View, dir: DVec3) -> ([f64; 3], Vec<f64>) {
    let (sun, alt_km) = (s.sun_direction(), s.altitude_m / 1000.0);
    let nl = scene.line_optics.len();
    let (bands, lines) = (single::SingleScattering::bands(scene, sun, alt_km), single::SingleScattering::new(&scene.medium, &scene.columns, &scene.line_optics, sun, alt_km));
    let w = &scene.bands.weight;
    match s.fog {
        Some(f) => (
            if scene.spectral.xyz { bands.fog_xyz(w, dir, f.max_distance_km, f.ceiling_km) } else { [0.0; 3] },
            if nl > 0 { lines.radiance_to(dir, f.max_distance_km, f.ceiling_km) } else { Vec::new() },
        ),
        None => (if scene.spectral.xyz { bands.xyz(w, dir) } else { [0.0; 3] }, if nl > 0 { lines.radiance(dir) } else { Vec::new() }),
    }
}

/// [`single_by_quadrature`] toward the centre of every pixel of `s` (a
/// camera that does not jitter), CIE XYZ, row-major; in parallel. Zero where
/// the camera sees nothing.
pub fn single_per_pixel(scene: &Scene, s: &View) -> Vec<[f64; 3]> {
    use rayon::prelude::*;
    let (w, h) = (s.width, s.height);
    (0..w * h)
        .into_par_iter()
        .map(|i| {
            let dir = s.camera.direction((i % w) as f64 + 0.5, (i / w) as f64 + 0.5, w, h);
            dir.map_or([0.0; 3], |d| single_by_quadrature(scene, s, d).0)
        })
        .collect()
}

/// Renders one pixel (index y·width + x). A pure function of the scene,
/// the settings and the index: the farm and the local renderer share it.
pub fn render_pixel(scene: &Scene, s: &View, pixel: usize) -> PixelResult {
    render_pixel_cancellable(scene, s, pixel, &AtomicBool::new(false))
}

/// [`render_pixel`] that stops early (with a partial, discarded result)
/// when `cancel` is set, so Ctrl-C does not wait for long pixels.
pub fn render_pixel_cancellable(scene: &Scene, s: &View, pixel: usize, cancel: &AtomicBool) -> PixelResult {
    let (x, y) = (pixel % s.width, pixel / s.width);
    let parts = s.parts();
    let (first, part) = parts.iter().rev().find(|(first, _)| *first <= x).expect("a view's parts start at column 0");
    render_pixel_with(&PixelTracers::new(scene, part), scene, part, y * part.width + x - first, cancel)
}

/// [`render_pixel_cancellable`] with the render's shared tracers.
pub fn render_pixel_with(tracers: &PixelTracers, scene: &Scene, s: &View, pixel: usize, cancel: &AtomicBool) -> PixelResult {
    let (x, y) = (pixel % s.width, pixel / s.width);
    let nl = scene.line_optics.len();
    let mut empty = PixelResult { xyz: [0.0; 3], xyz_direct: [0.0; 3], xyz_stderr: [0.0; 3], spectral: vec![0.0; nl], spectral_stderr: vec![0.0; nl], samples: 0, paths_cut: 0 };
    let jitter = s.camera.jitters();
    let centre = s.camera.direction(x as f64 + 0.5, y as f64 + 0.5, s.width, s.height);
    if centre.is_none() && !jitter {
        return empty;
    }
    let (tracers_band, tracers_line) = (&tracers.band, &tracers.line);
    let Some(origin) = tracers.origin else { return empty };
    // The first-collision guide, from the pixel's central ray at the band
    // that weighs most in luminance (see guide.rs).
    let guide = match (centre, s.estimator) {
        (Some(c), tracer::Estimator::Full) => tracers.reference(scene).and_then(|t| guide::RayGuide::build(t, origin, c)),
        _ => None,
    };
    let guide = guide.as_ref();
    // Single scattering by quadrature (see `SingleScatter`): the same for
    // every sample of the pixel, so it is added to each, and the moments
    // measure the noise of the rest.
    let (single_xyz, single_lines) = match centre {
        Some(c) if s.single_by_quadrature() && !s.fog.is_some_and(|f| f.shadowed) => single_by_quadrature(scene, s, c),
        _ => ([0.0; 3], vec![0.0; nl]),
    };
    // Band choice and pixel jitter follow low-discrepancy sequences over the
    // sample index (Roberts' R1 and R2 sequences), randomly shifted per pixel
    // (Cranley–Patterson rotation): still a function of (seed, pixel, sample)
    // only, with far less colour noise than independent choices.
    let mut shift = Rng::new(s.seed, pixel as u64, u64::MAX);
    let (s_band, s_x, s_y) = (shift.uniform(), shift.uniform(), shift.uniform());
    // The shared majorant of the current hero set (reused, not reallocated).
    let mut majorant = Vec::new();
    let mut scratch = Scratch::default();
    // Sample k of the pixel, added to `acc`.
    let mut sample = |k: u64, acc: &mut Accumulator| {
        let (xyz, direct, lines) = (&mut acc.xyz, &mut acc.direct, &mut acc.lines);
        acc.taken += 1;
        if scene.spectral.xyz {
            let mut rng = Rng::new(s.seed, pixel as u64, k);
            let kf = k as f64;
            let (jx, jy) = if jitter { ((s_x + kf * R2_A1).fract(), (s_y + kf * R2_A2).fract()) } else { (0.5, 0.5) };
            let u_band = (s_band + kf * R1_A).fract();
            let dir = s.camera.direction(x as f64 + jx, y as f64 + jy, s.width, s.height);
            match (scene.spectral.wavelength_sampling, dir) {
                (WavelengthSampling::Hero, Some(d)) => {
                    acc.any = true;
                    let set = scene.bands.hero_set(u_band);
                    let ts: [&Tracer; HERO_N] = std::array::from_fn(|j| &tracers_band[set.band[j]]);
                    hero::shared_majorant_into(std::array::from_fn(|j| ts[j].spectral.majorant.as_slice()), &mut majorant);
                    let path = hero::HeroTracer::new(ts, &majorant).with_sky_guide(tracers.sky_guide.as_ref()).radiance(origin, d, guide, &mut scratch, &mut rng);
                    let (ld, ls) = (path.direct, path.scattered);
                    acc.cut += path.cut as u32;
                    for c in 0..3 {
                        let mut v = single_xyz[c];
                        for j in 0..HERO_N {
                            // Each position is distributed like one band draw.
                            let w = scene.bands.weight[set.band[j]][c] / set.pdf[j];
                            v += (ld[j] + ls[j]) * w;
                            direct[c] += ld[j] * w;
                        }
                        xyz[c].add(v);
                    }
                }
                (_, Some(d)) => {
                    acc.any = true;
                    let b = scene.bands.sample(u_band);
                    let path = Kernel::single(&tracers_band[b]).with_sky_guide(tracers.sky_guide.as_ref()).radiance(origin, d, guide, &mut scratch, &mut rng);
                    let (ld, ls) = (path.direct[0], path.scattered[0]);
                    acc.cut += path.cut as u32;
                    let w = &scene.bands.weight[b];
                    let p = scene.bands.pdf[b];
                    for c in 0..3 {
                        xyz[c].add(single_xyz[c] + (ld + ls) * w[c] / p);
                        direct[c] += ld * w[c] / p;
                    }
                }
                (_, None) => {
                    for m in xyz.iter_mut() {
                        m.add(0.0);
                    }
                }
            }
        }
        for (j, t) in tracers_line.iter().enumerate() {
            let mut rng = Rng::new(s.seed ^ ((j as u64 + 1) << 48), pixel as u64, k);
            let (jx, jy) = if jitter { (rng.uniform(), rng.uniform()) } else { (0.5, 0.5) };
            match s.camera.direction(x as f64 + jx, y as f64 + jy, s.width, s.height) {
                Some(d) => {
                    acc.any = true;
                    let path = Kernel::single(t).with_sky_guide(tracers.sky_guide.as_ref()).radiance(origin, d, guide, &mut scratch, &mut rng);
                    acc.cut += path.cut as u32;
                    lines[j].add(single_lines[j] + path.direct[0] + path.scattered[0]);
                }
                None => lines[j].add(0.0),
            }
        }
    };
    let stop = || cancel.load(Ordering::Relaxed);
    let mut acc = Accumulator::new(nl);
    match s.max_rel_error {
        Some(target) if s.spp > ADAPTIVE_PILOT_SPP => {
            // Adaptive sampling in two stages (see `adaptive_samples`): the
            // pilot's samples choose the count and are then set aside, so
            // the estimate's mean does not depend on when it stopped.
            let mut pilot = Accumulator::new(nl);
            for k in 0..ADAPTIVE_PILOT_SPP as u64 {
                if k % 64 == 0 && stop() {
                    break;
                }
                sample(k, &mut pilot);
            }
            let left = s.spp - ADAPTIVE_PILOT_SPP;
            let n = match if scene.spectral.xyz { Some(&pilot.xyz[1]) } else { pilot.lines.first() } {
                Some(m) => adaptive_samples(m, target, left),
                None => left,
            };
            for k in ADAPTIVE_PILOT_SPP as u64..(ADAPTIVE_PILOT_SPP + n) as u64 {
                if k % 64 == 0 && stop() {
                    break;
                }
                sample(k, &mut acc);
            }
            acc.any |= pilot.any;
            acc.cut += pilot.cut;
            acc.pilot = pilot.taken;
        }
        _ => {
            for k in 0..s.spp as u64 {
                if k % 64 == 0 && stop() {
                    break;
                }
                sample(k, &mut acc);
            }
        }
    }
    let Accumulator { xyz, direct, lines, taken, pilot, cut, any } = acc;
    if !any {
        return empty;
    }
    for c in 0..3 {
        empty.xyz[c] = xyz[c].mean();
        empty.xyz_direct[c] = direct[c] / taken.max(1) as f64;
        empty.xyz_stderr[c] = xyz[c].stderr();
    }
    for j in 0..nl {
        empty.spectral[j] = lines[j].mean();
        empty.spectral_stderr[j] = lines[j].stderr();
    }
    empty.samples = taken + pilot;
    empty.paths_cut = cut;
    empty
}

/// Renders `count` pixel columns from `first` (each top to bottom) on the
/// current rayon pool: a farm task. `on_pixel` is called after each pixel;
/// None if `cancel` was set. Pixels are the same pure function of (scene,
/// settings, pixel) as in [`render`], so a column is bit-identical wherever
/// it is rendered.
pub fn render_columns(scene: &Scene, s: &View, first: usize, count: usize, cancel: &AtomicBool, on_pixel: &(dyn Fn() + Sync)) -> Option<Vec<Vec<PixelResult>>> {
    use rayon::prelude::*;
    let h = s.height;
    // The parts of the view (one, or the slices of a strip) that the
    // columns cross, with their tracers; one parallel loop over them all.
    let parts: Vec<(usize, View, PixelTracers)> = s
        .parts()
        .into_iter()
        .filter(|(start, v)| *start < first + count && start + v.width > first)
        .map(|(start, v)| {
            let t = PixelTracers::new(scene, &v);
            (start, v, t)
        })
        .collect();
    let flat: Vec<Option<PixelResult>> = (0..count * h)
        .into_par_iter()
        .map(|i| {
            if cancel.load(Ordering::Relaxed) {
                return None;
            }
            let (c, row) = (first + i / h, i % h);
            let (start, v, tracers) = parts.iter().rev().find(|(start, _, _)| *start <= c).expect("the columns' parts");
            let r = render_pixel_with(tracers, scene, v, row * v.width + c - start, cancel);
            if cancel.load(Ordering::Relaxed) {
                return None;
            }
            on_pixel();
            Some(r)
        })
        .collect();
    if cancel.load(Ordering::Relaxed) {
        return None;
    }
    let flat: Option<Vec<PixelResult>> = flat.into_iter().collect();
    let flat = flat?;
    Some(flat.chunks(h).map(|c| c.to_vec()).collect())
}

/// A rendered image, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    pub width: usize,
    pub height: usize,
    pub pixels: Vec<PixelResult>,
}

/// Why a render stopped early.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error("render cancelled")]
    Cancelled,
}

/// Renders every pixel on the current rayon pool. `on_pixel` is called after
/// each pixel (for progress); `cancel` stops the render.
pub fn render(scene: &Scene, s: &View, cancel: &AtomicBool, on_pixel: &(dyn Fn() + Sync)) -> Result<Image, RenderError> {
    render_timed(scene, s, cancel, on_pixel).map(|(image, _)| image)
}

/// [`render`], with the seconds each pixel took on its thread (what a
/// bake's forecast weighs each texel's samples by); 0 for every pixel of a
/// view of several parts (a strip), which renders by columns.
pub fn render_timed(scene: &Scene, s: &View, cancel: &AtomicBool, on_pixel: &(dyn Fn() + Sync)) -> Result<(Image, Vec<f64>), RenderError> {
    use rayon::prelude::*;
    let n = s.width * s.height;
    if s.parts().len() > 1 {
        let columns = render_columns(scene, s, 0, s.width, cancel, on_pixel).ok_or(RenderError::Cancelled)?;
        let pixels = (0..s.height).flat_map(|y| columns.iter().map(move |c| c[y].clone())).collect();
        return Ok((Image { width: s.width, height: s.height, pixels }, vec![0.0; n]));
    }
    let tracers = PixelTracers::new(scene, s);
    let pixels: Vec<Option<(PixelResult, f64)>> = (0..n)
        .into_par_iter()
        .map(|i| {
            if cancel.load(Ordering::Relaxed) {
                return None;
            }
            let start = std::time::Instant::now();
            let r = render_pixel_with(&tracers, scene, s, i, cancel);
            let seconds = start.elapsed().as_secs_f64();
            if cancel.load(Ordering::Relaxed) {
                return None;
            }
            on_pixel();
            Some((r, seconds))
        })
        .collect();
    if cancel.load(Ordering::Relaxed) || pixels.iter().any(|p| p.is_none()) {
        return Err(RenderError::Cancelled);
    }
    let (pixels, seconds) = pixels.into_iter().map(Option::unwrap).unzip();
    Ok((Image { width: s.width, height: s.height, pixels }, seconds))
}
