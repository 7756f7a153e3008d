//! The per-pixel estimator: what the pixels of a render share
//! ([`PixelTracers`]), the single scattering by quadrature, and one
//! pixel's samples ([`render_pixel_with`]) in phases: the pixel's setup
//! (`PixelSampler::new`), its sample schedule (fixed or adaptive,
//! `PixelSampler::take_samples`), one sample of XYZ and of the spectral
//! lines (`PixelSampler::sample`), and the pixel's means and errors
//! (`Accumulator::finish`).

use super::adaptive::{adaptive_samples, Moments, ADAPTIVE_PILOT_SPP};
use super::bands::HERO_N;
use super::kernel::{Kernel, Scratch};
use super::medium::Spectral;
use super::rng::Rng;
use super::scene::Scene;
use super::settings::{View, WavelengthSampling};
use super::tracer::{Estimator, Tracer};
use super::{guide, hero, single, sky_guide, tracer};
use glam::DVec3;
use std::sync::atomic::{AtomicBool, Ordering};

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
        PixelResult {
            xyz,
            xyz_direct: [0.0; 3],
            xyz_stderr: [0.0; 3],
            spectral: Vec::new(),
            spectral_stderr: Vec::new(),
            samples: 1,
            paths_cut: 0,
        }
    }

    /// A pixel that sees nothing: every channel 0, no sample.
    fn empty(nl: usize) -> PixelResult {
        PixelResult {
            xyz: [0.0; 3],
            xyz_direct: [0.0; 3],
            xyz_stderr: [0.0; 3],
            spectral: vec![0.0; nl],
            spectral_stderr: vec![0.0; nl],
            samples: 0,
            paths_cut: 0,
        }
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
        self.band
            .iter()
            .zip(&scene.bands.weight)
            .max_by(|a, b| a.1[1].total_cmp(&b.1[1]))
            .map(|(t, _)| t)
            .or(self.line.first())
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
    let (bands, lines) = (
        single::SingleScattering::bands(scene, sun, alt_km),
        single::SingleScattering::new(&scene.medium, &scene.columns, &scene.line_optics, sun, alt_km),
    );
    let w = &scene.bands.weight;
    match s.fog {
        Some(f) => (
            if scene.spectral.xyz { bands.fog_xyz(w, dir, f.max_distance_km, f.ceiling_km) } else { [0.0; 3] },
            if nl > 0 { lines.radiance_to(dir, f.max_distance_km, f.ceiling_km) } else { Vec::new() },
        ),
        None => (
            if scene.spectral.xyz { bands.xyz(w, dir) } else { [0.0; 3] },
            if nl > 0 { lines.radiance(dir) } else { Vec::new() },
        ),
    }
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
pub fn render_pixel_with(
    tracers: &PixelTracers,
    scene: &Scene,
    s: &View,
    pixel: usize,
    cancel: &AtomicBool,
) -> PixelResult {
    match PixelSampler::new(tracers, scene, s, pixel) {
        Some(mut sampler) => sampler.take_samples(cancel).finish(),
        None => PixelResult::empty(scene.line_optics.len()),
    }
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
        Accumulator {
            xyz: [Moments::default(); 3],
            direct: [0.0; 3],
            lines: vec![Moments::default(); lines],
            taken: 0,
            pilot: 0,
            cut: 0,
            any: false,
        }
    }

    /// The pixel's means and standard errors from its sums (an empty pixel
    /// if no sample saw anything).
    fn finish(self) -> PixelResult {
        let nl = self.lines.len();
        let mut empty = PixelResult::empty(nl);
        let Accumulator { xyz, direct, lines, taken, pilot, cut, any } = self;
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
}

/// One pixel's samples: what they share (the pixel, its guide, its single
/// scattering by quadrature, its sequences' shifts) and the buffers they
/// reuse.
struct PixelSampler<'a, 't> {
    tracers: &'a PixelTracers<'t>,
    scene: &'a Scene,
    s: &'a View,
    pixel: usize,
    x: usize,
    y: usize,
    jitter: bool,
    origin: DVec3,
    /// The first-collision guide of the pixel's central ray.
    guide: Option<guide::RayGuide>,
    /// Single scattering by quadrature, added to every sample.
    single_xyz: [f64; 3],
    single_lines: Vec<f64>,
    /// The random shifts of the band choice's R1 and the jitter's R2
    /// sequences.
    s_band: f64,
    s_x: f64,
    s_y: f64,
    /// The shared majorant of the current hero set (reused, not reallocated).
    majorant: Vec<f64>,
    scratch: Scratch,
}

impl<'a, 't> PixelSampler<'a, 't> {
    /// The pixel's setup; None where it sees nothing (no direction at its
    /// centre and no jitter, or no observer).
    fn new(tracers: &'a PixelTracers<'t>, scene: &'a Scene, s: &'a View, pixel: usize) -> Option<Self> {
        let (x, y) = (pixel % s.width, pixel / s.width);
        let nl = scene.line_optics.len();
        let jitter = s.camera.jitters();
        let centre = s.camera.direction(x as f64 + 0.5, y as f64 + 0.5, s.width, s.height);
        if centre.is_none() && !jitter {
            return None;
        }
        let origin = tracers.origin?;
        // The first-collision guide, from the pixel's central ray at the band
        // that weighs most in luminance (see guide.rs).
        let guide = match (centre, s.estimator) {
            (Some(c), tracer::Estimator::Full) => {
                tracers.reference(scene).and_then(|t| guide::RayGuide::build(t, origin, c))
            }
            _ => None,
        };
        // Single scattering by quadrature (see `SingleScatter`): the same for
        // every sample of the pixel, so it is added to each, and the moments
        // measure the noise of the rest.
        let (single_xyz, single_lines) = match centre {
            Some(c) if s.single_by_quadrature() && !s.fog.is_some_and(|f| f.shadowed) => {
                single_by_quadrature(scene, s, c)
            }
            _ => ([0.0; 3], vec![0.0; nl]),
        };
        // Band choice and pixel jitter follow low-discrepancy sequences over the
        // sample index (Roberts' R1 and R2 sequences), randomly shifted per pixel
        // (Cranley–Patterson rotation): still a function of (seed, pixel, sample)
        // only, with far less colour noise than independent choices.
        let mut shift = Rng::new(s.seed, pixel as u64, u64::MAX);
        let (s_band, s_x, s_y) = (shift.uniform(), shift.uniform(), shift.uniform());
        Some(PixelSampler {
            tracers,
            scene,
            s,
            pixel,
            x,
            y,
            jitter,
            origin,
            guide,
            single_xyz,
            single_lines,
            s_band,
            s_x,
            s_y,
            majorant: Vec::new(),
            scratch: Scratch::default(),
        })
    }

    /// The pixel's samples: `spp` of them, or with adaptive sampling a
    /// pilot that chooses how many more; stops early when `cancel` is set.
    fn take_samples(&mut self, cancel: &AtomicBool) -> Accumulator {
        let (scene, s) = (self.scene, self.s);
        let nl = scene.line_optics.len();
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
                    self.sample(k, &mut pilot);
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
                    self.sample(k, &mut acc);
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
                    self.sample(k, &mut acc);
                }
            }
        }
        acc
    }

    /// Sample k of the pixel, added to `acc`.
    fn sample(&mut self, k: u64, acc: &mut Accumulator) {
        acc.taken += 1;
        if self.scene.spectral.xyz {
            self.sample_xyz(k, acc);
        }
        self.sample_lines(k, acc);
    }

    /// Sample k of the pixel's XYZ: one path at one band, or at a hero set.
    fn sample_xyz(&mut self, k: u64, acc: &mut Accumulator) {
        let (tracers, scene, s, pixel, origin) = (self.tracers, self.scene, self.s, self.pixel, self.origin);
        let (xyz, direct) = (&mut acc.xyz, &mut acc.direct);
        let (x, y, jitter, single_xyz) = (self.x, self.y, self.jitter, self.single_xyz);
        let (s_band, s_x, s_y) = (self.s_band, self.s_x, self.s_y);
        let tracers_band = &tracers.band;
        let guide = self.guide.as_ref();
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
                hero::shared_majorant_into(
                    std::array::from_fn(|j| ts[j].spectral.majorant.as_slice()),
                    &mut self.majorant,
                );
                let path = hero::HeroTracer::new(ts, &self.majorant)
                    .with_sky_guide(tracers.sky_guide.as_ref())
                    .radiance(origin, d, guide, &mut self.scratch, &mut rng);
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
                let path = Kernel::single(&tracers_band[b]).with_sky_guide(tracers.sky_guide.as_ref()).radiance(
                    origin,
                    d,
                    guide,
                    &mut self.scratch,
                    &mut rng,
                );
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

    /// Sample k of the pixel's spectral lines: one path per line.
    fn sample_lines(&mut self, k: u64, acc: &mut Accumulator) {
        let (tracers, s, pixel, origin) = (self.tracers, self.s, self.pixel, self.origin);
        let (x, y, jitter) = (self.x, self.y, self.jitter);
        let (tracers_line, single_lines, lines) = (&tracers.line, &self.single_lines, &mut acc.lines);
        let guide = self.guide.as_ref();
        for (j, t) in tracers_line.iter().enumerate() {
            let mut rng = Rng::new(s.seed ^ ((j as u64 + 1) << 48), pixel as u64, k);
            let (jx, jy) = if jitter { (rng.uniform(), rng.uniform()) } else { (0.5, 0.5) };
            match s.camera.direction(x as f64 + jx, y as f64 + jy, s.width, s.height) {
                Some(d) => {
                    acc.any = true;
                    let path = Kernel::single(t).with_sky_guide(tracers.sky_guide.as_ref()).radiance(
                        origin,
                        d,
                        guide,
                        &mut self.scratch,
                        &mut rng,
                    );
                    acc.cut += path.cut as u32;
                    lines[j].add(single_lines[j] + path.direct[0] + path.scattered[0]);
                }
                None => lines[j].add(0.0),
            }
        }
    }
}
