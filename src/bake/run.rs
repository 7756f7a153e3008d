//! Rendering a bake's slices: for every basis sky, its 64 sun elevations
//! (`lut::mapping::slice_sun_zenith_deg`) through the LUT camera with the
//! sun disk hidden, each slice taken from the cache when it is there and
//! rendered through a [`Session`] (optics prepared once per basis sky) when
//! it is not.
//!
//! The slices a basis sky has to render make one farm job, a strip of
//! slices side by side ([`Camera::LutStrip`]), followed by its fog slices
//! (the Shadowed Fog's renders, a job each), and the jobs of every basis
//! sky go to one farm (its workers greeted once, each sky's optics sent to
//! each worker once) as one queue of columns ([`SharedFarm::render_parts`]):
//! workers go from slice to slice and from sky to sky and wait only at the
//! end of the bake's rendering, not at the end of every slice or sky. Each
//! job's columns are journaled in the cache folder, so a bake killed
//! anywhere resumes from the columns it had; the slices go into the cache
//! once the queue is done.

use super::cache::{slice_key, RenderedSlice, SliceCache};
use super::file::{BakeFile, BasisSky, Quality, Sampling};
use super::fog::FogTodo;
use super::lighting::{lighting_key, SkyLighting};
use super::ms_grid::MsGrid;
use super::tracker::{farm_options, QueueJob, Tracker};
use super::{BakeError, BakeEvent, BakeSink};
use crate::atmosphere::Atmosphere;
use crate::farm::coordinator::{FarmError, FarmPart, Options, WorkerSpec};
use crate::farm::journal::{Header, Journal};
use crate::lut::mapping::{self, DirectionMapping};
use crate::mie::MieCache;
use crate::render::camera::Camera;
use crate::render::segments::Standpoint;
use crate::render::tracer::Estimator;
use crate::render::{adaptive, Image, Scene, SingleScatter, SpectralSettings, View, WavelengthSampling, ADAPTIVE_PILOT_SPP};
use crate::session::{OpticsCache, Session, SharedFarm};
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

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
        let (sky, index) = s.rsplit_once(':').ok_or_else(|| format!("{s:?}: expected NAME:INDEX or NAME:fog:INDEX, e.g. clear:12"))?;
        let index: usize = index.parse().map_err(|_| format!("{s:?}: the slice index must be a whole number from 0 to {}", mapping::SLICES - 1))?;
        let (sky, fog) = match sky.strip_suffix(":fog") {
            Some(sky) => (sky, true),
            None => (sky, false),
        };
        if index >= mapping::SLICES || sky.is_empty() {
            return Err(format!("{s:?}: expected NAME:INDEX or NAME:fog:INDEX with INDEX from 0 to {}", mapping::SLICES - 1));
        }
        Ok(SliceId { sky: sky.to_string(), index, fog })
    }
}

impl std::fmt::Display for SliceId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}:{}{}", self.sky, if self.fog { "fog:" } else { "" }, self.index)
    }
}

/// How to run a bake.
#[derive(Debug, Clone)]
pub struct BakeOptions {
    pub quality: Quality,
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
    SpectralSettings { band_nm: s.band_nm, wavelength_sampling: WavelengthSampling::Hero, spectral_nm: Vec::new(), xyz: true }
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
/// scattering on a grid of its own (`ms_grid`), the grid's too.
pub fn sky_slice_key(atmosphere_hash: &str, spectral: &SpectralSettings, view: &View, quality: Quality, sampling: &Sampling) -> String {
    match sampling.ms_grid {
        None => slice_key(atmosphere_hash, spectral, view, quality.name()),
        // The grid's layout and resampling named by their source.
        Some([rows, cols]) => slice_key(atmosphere_hash, spectral, view, &format!("{} ms_grid {rows}x{cols} {}", quality.name(), env!("SKY_MS_GRID_SOURCE"))),
    }
}

/// The pilot of an adaptively sampled view: the same view at the pilot's
/// sample count, fixed; None when the view does not sample adaptively.
/// A pixel's samples depend only on (seed, pixel, sample), so its pixels
/// draw the very samples the adaptive render's pilot draws, and the counts
/// [`planned_samples`] derives from it are the ones the render will take.
pub fn pilot_view(view: &View) -> Option<View> {
    view.max_rel_error?;
    (view.spp > ADAPTIVE_PILOT_SPP).then(|| View { spp: ADAPTIVE_PILOT_SPP, max_rel_error: None, ..view.clone() })
}

/// The samples each texel of `view` will take, its pilot's included, from
/// the render of [`pilot_view`].
pub fn planned_samples(view: &View, pilot: &Image) -> Vec<u32> {
    let target = view.max_rel_error.unwrap_or(0.0);
    let left = view.spp.saturating_sub(ADAPTIVE_PILOT_SPP);
    pilot.pixels.iter().map(|p| if p.samples == 0 { 0 } else { ADAPTIVE_PILOT_SPP + adaptive::samples_for(p.xyz[1], p.xyz_stderr[1], p.samples as f64, target, left) }).collect()
}

/// The slices a draft's forecast times: day, low sun, sunset, the horizon,
/// twilight.
const PROBE_SLICES: [usize; 5] = [8, 24, 40, 48, 58];
/// A probe renders every `PROBE_STRIDE`-th texel of its slice in both axes.
const PROBE_STRIDE: usize = 4;
/// Fewer slices to render (a farm manager's task renders one) are not worth
/// probing: the ETA is then the texel rate.
const MIN_SLICES_TO_PROBE: usize = 16;

/// The value at `x` of the piecewise-linear function through `points`
/// (sorted by x), constant beyond the first and the last.
fn interpolate(points: &[(usize, f64)], x: usize) -> f64 {
    match points.iter().position(|&(px, _)| px >= x) {
        None => points.last().map_or(0.0, |p| p.1),
        Some(0) => points[0].1,
        Some(i) => {
            let ((x0, y0), (x1, y1)) = (points[i - 1], points[i]);
            y0 + (y1 - y0) * (x - x0) as f64 / (x1 - x0) as f64
        }
    }
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
    View { camera: Camera::LutStrip { mappings, sun_azimuth_deg: first.sun_azimuth_deg }, width: first.width * views.len(), ..first }
}

/// Renders (or finds in the cache) every slice the options ask for, basis
/// sky after basis sky.
pub fn render_slices(bake: &BakeFile, opts: &BakeOptions, mie: &MieCache, cancel: Arc<AtomicBool>) -> Result<Vec<SkySlices>, BakeError> {
    if let Some(only) = &opts.only {
        for id in only {
            if !bake.skies.iter().any(|s| s.name == id.sky && id.index < s.slices) {
                return Err(BakeError::NoSuchSlice(id.to_string()));
            }
        }
    }
    // First the plan: every slice's key, and which the cache holds.
    struct Planned {
        atm: Atmosphere,
        bundle: crate::atmosphere::Bundle,
        out: SkySlices,
        views: Vec<Option<(View, String)>>,
        /// Multiple scattering on a grid of its own (`ms_grid`): each slice
        /// is then rendered as its grid's nodes and resampled.
        grid: Option<MsGrid>,
        /// What the queue renders of each slice in `views`: its view, or
        /// its grid's.
        jobs: Vec<Option<View>>,
        /// For a slice whose view an earlier one to render has too (47 and
        /// 48 are both the horizon in the talk's layout): that slice.
        same_as: Vec<Option<usize>>,
    }
    let mut plan: Vec<Planned> = Vec::new();
    for sky in &bake.skies {
        let (atm, bundle) = Atmosphere::load_bundle(&sky.atmosphere).map_err(|error| BakeError::Atmosphere { sky: sky.name.clone(), error })?;
        let sampling = sky.sampling(opts.quality).clone();
        let spectral = spectral_settings(&sampling);
        let (radius_km, top_km) = (atm.planet.radius_km, atm.planet.top_km);
        let threshold_deg = sky.threshold_deg;
        let mut views: Vec<Option<(View, String)>> = Vec::new();
        let mut same_as = Vec::new();
        let mut slices = Vec::new();
        let mut cached = 0;
        for index in 0..sky.slices {
            let wanted = opts.only.as_ref().is_none_or(|o| o.iter().any(|id| !id.fog && id.sky == sky.name && id.index == index));
            if !wanted {
                views.push(None);
                same_as.push(None);
                slices.push(None);
                continue;
            }
            let view = slice_view(sky, &sampling, index, radius_km, top_km, threshold_deg);
            let key = sky_slice_key(&atm.content_hash, &spectral, &view, opts.quality, &sampling);
            let hit = opts.cache.get(&key);
            cached += hit.is_some() as usize;
            same_as.push(if hit.is_some() { None } else { views.iter().position(|v| v.as_ref().is_some_and(|(_, k)| *k == key)) });
            views.push(if hit.is_some() { None } else { Some((view, key)) });
            slices.push(hit);
        }
        let grid = sampling.ms_grid.map(|g| MsGrid::new(g, Standpoint::new(atm.planet.geometry, radius_km, sky.altitude_m / 1000.0)));
        let out = SkySlices {
            sky: sky.clone(),
            atmosphere_name: bundle.name.clone(),
            atmosphere_hash: atm.content_hash.clone(),
            radius_km,
            top_km,
            threshold_deg,
            spectral,
            sampling,
            slices,
            rendered: 0,
            cached,
            columns_resumed: 0,
            lighting: None,
            fog: None,
            fog_rendered: Vec::new(),
        };
        let jobs = views.iter().map(|v| v.as_ref().map(|(v, _)| grid.map_or_else(|| v.clone(), |g| g.view(v)))).collect();
        plan.push(Planned { atm, bundle, out, views, grid, jobs, same_as });
    }
    // The fog slices to render: a whole bake's, or those `only` names.
    let fog_plan: Vec<Vec<FogTodo>> = plan
        .iter()
        .map(|p| {
            let mut todo = super::fog::to_render(&p.out, &bake.fog, &opts.cache, opts.quality);
            if let Some(only) = &opts.only {
                todo.retain(|f| only.iter().any(|id| id.fog && id.sky == p.out.sky.name && id.index == f.index));
            }
            todo
        })
        .collect();
    if opts.pack_only {
        let sky_missing = plan.iter().flat_map(|p| p.views.iter().enumerate().filter(|(_, v)| v.is_some()).map(|(i, _)| format!("{}:{i}", p.out.sky.name)));
        let fog_missing = plan.iter().zip(&fog_plan).flat_map(|(p, f)| f.iter().map(|f| format!("{}:fog:{}", p.out.sky.name, f.index)));
        let missing: Vec<String> = sky_missing.chain(fog_missing).collect();
        if !missing.is_empty() {
            return Err(BakeError::NotInCache { cache: opts.cache.dir().to_path_buf(), missing });
        }
    }
    let fog_slices = fog_plan.iter().map(Vec::len).sum::<usize>();
    let fog_texels: u64 = fog_plan.iter().flatten().map(|f| (f.view.width * f.view.height) as u64).sum();
    // Of the fog, a whole bake's slices; those not rendered count as cached
    // (a slice that shares its sun with an earlier one among them).
    let fog_total: usize = match &opts.only {
        Some(only) => only.iter().filter(|id| id.fog).count(),
        None => plan.iter().map(|p| p.out.sky.slices).sum(),
    };
    let slices_total: usize = plan.iter().map(|p| p.out.slices.iter().filter(|s| s.is_some()).count() + p.views.iter().filter(|v| v.is_some()).count()).sum::<usize>() + fog_total;
    let slices_cached: usize = plan.iter().map(|p| p.out.cached).sum::<usize>() + fog_total.saturating_sub(fog_slices);
    // A slice's texels, or with a grid its nodes: what the queue renders.
    let job_texels = |p: &Planned| -> Vec<u64> { p.jobs.iter().map(|v| v.as_ref().map_or(0, |v| (v.width * v.height) as u64)).collect() };
    let texels_to_render: u64 = plan.iter().map(|p| job_texels(p).iter().sum::<u64>()).sum::<u64>() + fog_texels;
    let cores_known = opts.workers.iter().all(|w| matches!(w, WorkerSpec::Local { .. }));
    let tracker = Arc::new(Mutex::new(Tracker::new((texels_to_render, slices_total, slices_cached), (opts.cores, cores_known), opts.events.clone())));
    tracker.lock().unwrap().emit(BakeEvent::Planned { skies: plan.len(), slices_total, slices_cached, fog_slices, texels_to_render });

    let optics = OpticsCache::default();
    // One farm for the whole bake: its workers are greeted once and get
    // each basis sky's optics once.
    let farm = SharedFarm::new(opts.workers.clone(), farm_options(opts, &tracker));
    // Every basis sky's session first (optics prepared once), then, where
    // the quality samples adaptively, every slice's pilot: the forecast
    // behind the ETA, before the first slice is rendered.
    let mut sessions: Vec<Option<Session>> = Vec::new();
    for (p, fog) in plan.iter().zip(&fog_plan) {
        if !p.views.iter().any(Option::is_some) && fog.is_empty() {
            sessions.push(None);
            continue;
        }
        tracker.lock().unwrap().emit(BakeEvent::Preparing { sky: p.out.sky.name.clone() });
        let prep = Instant::now();
        let session = Session::on_farm(p.atm.clone(), p.bundle.clone(), p.out.spectral.clone(), &optics, mie, farm.clone(), &|| {});
        tracker.lock().unwrap().prep_s += prep.elapsed().as_secs_f64();
        sessions.push(Some(session));
    }
    // What the pilots say each slice will cost, core-seconds, by slice
    // index: the sky's and the fog's, in the queue; and of the work on this
    // process after the queue (single scattering by quadrature: a grid's
    // resampling, the Fog from its Shadowed Fog), the sky's and the fog's.
    let mut forecasts: Vec<Vec<f64>> = plan.iter().map(|p| vec![0.0; p.views.len()]).collect();
    let mut fog_forecasts = forecasts.clone();
    let mut after_queue = forecasts.clone();
    let mut fog_after_queue = forecasts.clone();
    // Every view to render once, with whether it is a fog slice's.
    let to_forecast = |k: usize| {
        let p = &plan[k];
        let sky = p.jobs.iter().enumerate().filter(|&(i, _)| p.same_as[i].is_none()).filter_map(|(i, v)| v.as_ref().map(|v| (i, v, false)));
        sky.chain(fog_plan[k].iter().map(|f| (f.index, &f.view, true)))
    };
    if (0..plan.len()).flat_map(to_forecast).any(|(_, v, _)| pilot_view(v).is_some()) {
        let start = Instant::now();
        tracker.lock().unwrap().planning = true;
        let (mut total, mut samples) = (0.0, 0u64);
        let pilots = (0..plan.len()).filter(|&k| sessions[k].is_some()).flat_map(to_forecast).filter(|(_, v, _)| pilot_view(v).is_some()).count();
        let (mut piloted, mut pilots_saved) = (0, 0);
        for (k, p) in plan.iter().enumerate() {
            let Some(session) = &sessions[k] else { continue };
            for (index, view, fog) in to_forecast(k) {
                let Some(pilot) = pilot_view(view) else { continue };
                if cancel.load(Ordering::SeqCst) {
                    return Err(BakeError::Cancelled);
                }
                tracker.lock().unwrap().current = (p.out.sky.name.clone(), index);
                // What the pilot's quadrature times: a grid slice's own view,
                // or the Fog LUT's size.
                let grid_slice = p.grid.filter(|_| !fog).map(|_| &p.views[index].as_ref().expect("to render").0);
                let key = pilot_key(&session.job(&pilot).hash, &serde_json::json!({ "grid_slice": grid_slice, "fog_lut": fog.then_some([bake.fog.width, bake.fog.height]) }));
                let saved = opts.cache.get_value::<PilotForecast>(&key, "pilot");
                pilots_saved += saved.is_some() as usize;
                let forecast = match saved {
                    Some(saved) => saved,
                    None => {
                        let after = match (fog, p.grid, grid_slice) {
                            (true, ..) => AfterQueue::Fog { lut_texels: bake.fog.width * bake.fog.height },
                            (false, Some(grid), Some(slice)) => AfterQueue::Grid(grid, slice),
                            _ => AfterQueue::Nothing,
                        };
                        let forecast = pilot_forecast(&session.scene, view, &pilot, after, &cancel)?;
                        opts.cache.put_value(&key, "pilot", &forecast)?;
                        forecast
                    }
                };
                let (f, after) = if fog { (&mut fog_forecasts[k][index], &mut fog_after_queue[k][index]) } else { (&mut forecasts[k][index], &mut after_queue[k][index]) };
                *f = forecast.queue_core_seconds;
                *after = forecast.after_queue_core_seconds;
                total += *f + *after;
                samples += forecast.samples;
                piloted += 1;
                tracker.lock().unwrap().planned_one("pilots", start, (&p.out.sky.name, index, fog), (piloted, pilots), Some(*f + *after));
            }
        }
        tracker.lock().unwrap().forecast("pilots", start, (total, samples), pilots_saved);
    } else if (0..plan.len()).flat_map(to_forecast).count() >= MIN_SLICES_TO_PROBE {
        // A fixed sample count (a draft): every texel takes the same
        // samples, but a texel's cost differs from sky to sky (a cloudy
        // texel costs 6 times a clear one) and with the sun (twilight paths
        // are longer). Probes of a few slices at a sixteenth of their texels
        // time it; the other slices' cost per texel is interpolated in the
        // slice index.
        let start = Instant::now();
        tracker.lock().unwrap().planning = true;
        let (mut total, mut samples) = (0.0, 0u64);
        // The probes to render: a sky's, and its fog's, at each of
        // PROBE_SLICES that it has.
        let has_probes = |k: usize, fog: bool| if fog { !fog_plan[k].is_empty() } else { plan[k].views.iter().any(Option::is_some) };
        let probes: usize = (0..plan.len())
            .filter(|&k| sessions[k].is_some())
            .map(|k| [false, true].into_iter().filter(|&fog| has_probes(k, fog)).count() * PROBE_SLICES.iter().filter(|&&i| i < plan[k].out.sky.slices).count())
            .sum();
        let mut probed = 0;
        for (k, p) in plan.iter().enumerate() {
            let Some(session) = &sessions[k] else { continue };
            let sky = &p.out.sky;
            // The sky's probes, then the fog's: a fog slice's probe is the
            // Fog LUT's directions at a quarter of its size each way, and
            // its texels' cost adds the quadrature's.
            for fog in [false, true] {
                if !has_probes(k, fog) {
                    continue;
                }
                let (mut per_texel, mut per_slice_fixed): (Vec<(usize, f64)>, Vec<(usize, f64)>) = (Vec::new(), Vec::new());
                // The quadrature after the queue, core-seconds per slice.
                let mut per_slice_after: Vec<(usize, f64)> = Vec::new();
                for &index in PROBE_SLICES.iter().filter(|&&i| i < sky.slices) {
                    if cancel.load(Ordering::SeqCst) {
                        return Err(BakeError::Cancelled);
                    }
                    tracker.lock().unwrap().current = (sky.name.clone(), index);
                    // A slice from a grid: every PROBE_STRIDE²-th node, and the
                    // quadrature at every texel, timed on a quarter of them.
                    let mut grid_quadrature = 0.0;
                    let probe = if fog {
                        let f = &bake.fog;
                        let smaller = super::file::FogSettings { width: (f.width / PROBE_STRIDE).max(1), height: (f.height / PROBE_STRIDE).max(1), ..*f };
                        super::fog::fog_view(sky, &smaller, &p.out.sampling, index, p.out.radius_km, p.out.top_km, true)
                    } else {
                        let full = slice_view(sky, &p.out.sampling, index, p.out.radius_km, p.out.top_km, p.out.threshold_deg);
                        let smaller = View { width: (full.width / PROBE_STRIDE).max(1), height: (full.height / PROBE_STRIDE).max(1), ..full.clone() };
                        match p.grid {
                            Some(g) => {
                                // (the texels' quadrature timed on the probe's
                                // texels, the nodes' on the slice's own)
                                let texels_quadrature = super::ms_grid::time_single(&session.scene, &smaller) * (full.width * full.height) as f64 / (smaller.width * smaller.height) as f64;
                                grid_quadrature = texels_quadrature + g.time_nodes_quadrature(&session.scene, &full);
                                g.probe_view(&full, PROBE_STRIDE * PROBE_STRIDE)
                            }
                            None => smaller,
                        }
                    };
                    // Rendered here, on this process's threads, in one piece: on
                    // the farm a probe's few columns would go out as several
                    // small tasks, each preparing the tracers and guides of its
                    // sun again, a cost the slices' large tasks spread thin (the
                    // forecast came out 43 % high). The rest of a render's cost
                    // per render, not per texel, a one-texel render of the same
                    // view measures.
                    let timed = |v: &View| timed_here(&session.scene, v, &cancel).map(|(_, core_s, _)| core_s);
                    let fixed = timed(&View { width: 1, height: 1, ..probe.clone() })?;
                    let texels = (probe.width * probe.height) as f64;
                    let whole = timed(&probe)?;
                    // A fog slice's quadrature, timed on its probe, for the
                    // whole slice (every fog slice has the Fog LUT's size).
                    let fog_quadrature = if fog { super::fog::time_quadrature(&session.scene, &probe) * (bake.fog.width * bake.fog.height) as f64 / texels } else { 0.0 };
                    per_slice_fixed.push((index, fixed));
                    per_slice_after.push((index, grid_quadrature + fog_quadrature));
                    per_texel.push((index, ((whole - fixed) / (texels - 1.0).max(1.0)).max(0.0)));
                    probed += 1;
                    tracker.lock().unwrap().planned_one("probes", start, (&sky.name, index, fog), (probed, probes), None);
                }
                for (index, view, is_fog) in to_forecast(k).filter(|v| v.2 == fog) {
                    let texels = (view.width * view.height) as f64;
                    let (f, after) = if is_fog { (&mut fog_forecasts[k][index], &mut fog_after_queue[k][index]) } else { (&mut forecasts[k][index], &mut after_queue[k][index]) };
                    *f = interpolate(&per_slice_fixed, index) + texels * interpolate(&per_texel, index);
                    *after = interpolate(&per_slice_after, index);
                    total += *f + *after;
                    samples += texels as u64 * view.spp as u64;
                }
            }
        }
        tracker.lock().unwrap().forecast("probes", start, (total, samples), 0);
    }
    // Every basis sky's slices to render, in one queue: each sky's strip
    // is one farm job, and a worker done with one sky's columns goes on to
    // the next sky's without waiting for the slowest column of the first.
    let to_render: Vec<Vec<usize>> = plan.iter().map(|p| (0..p.views.len()).filter(|&i| p.views[i].is_some() && p.same_as[i].is_none()).collect()).collect();
    // A sky with a grid of multiple scattering renders each slice's nodes
    // instead, a job each. The fog slices to render follow their sky's
    // slices, a job each.
    let mut strips: Vec<Option<StripOutcome>> = (0..plan.len()).map(|_| None).collect();
    let mut grid_rendered: Vec<BTreeMap<usize, StripOutcome>> = (0..plan.len()).map(|_| BTreeMap::new()).collect();
    let mut fog_rendered: Vec<Mutex<BTreeMap<String, (Image, f64)>>> = (0..plan.len()).map(|_| Mutex::default()).collect();
    let mut queued: Vec<QueuedJob> = Vec::new();
    let mut parts = Vec::new();
    for (k, p) in plan.iter().enumerate() {
        let Some(session) = &sessions[k] else { continue };
        let sky = p.out.sky.name.clone();
        if p.grid.is_some() {
            for &i in &to_render[k] {
                let view = p.jobs[i].clone().expect("to render");
                let (part, journal, resumed) = journaled_part(session, &view, &opts.cache)?;
                parts.push(part);
                queued.push(QueuedJob { k, sky: sky.clone(), kind: JobKind::Grid(i), slices: vec![(i, forecasts[k][i])], slice_width: view.width, view, journal, resumed });
            }
        } else if !to_render[k].is_empty() {
            let slice_views: Vec<&View> = to_render[k].iter().map(|&i| &p.views[i].as_ref().expect("to render").0).collect();
            let strip = strip_view(&slice_views);
            let (part, journal, resumed) = journaled_part(session, &strip, &opts.cache)?;
            parts.push(part);
            let slices = to_render[k].iter().map(|&i| (i, forecasts[k][i])).collect();
            queued.push(QueuedJob { k, sky: sky.clone(), kind: JobKind::Strip, slices, slice_width: slice_views[0].width, view: strip, journal, resumed });
        }
        for f in &fog_plan[k] {
            let (part, journal, resumed) = journaled_part(session, &f.view, &opts.cache)?;
            parts.push(part);
            let slices = vec![(f.index, fog_forecasts[k][f.index])];
            queued.push(QueuedJob { k, sky: format!("{sky} (fog)"), kind: JobKind::Fog(f.key.clone()), slices, slice_width: f.view.width, view: f.view.clone(), journal, resumed });
        }
    }
    if !parts.is_empty() {
        if cancel.load(Ordering::SeqCst) {
            return Err(BakeError::Cancelled);
        }
        {
            let slices: Vec<(String, usize, u64)> = queued.iter().flat_map(|q| q.slices.iter().map(|&(i, _)| (q.sky.clone(), i, (q.slice_width * q.view.height) as u64))).collect();
            let slice_forecasts: Vec<f64> = queued.iter().flat_map(|q| q.slices.iter().map(|s| s.1)).collect();
            let resumed_texels = queued.iter().map(|q| q.resumed as u64 * q.view.height as u64).sum();
            tracker.lock().unwrap().start_queue(QueueJob::new(slices, &slice_forecasts), resumed_texels);
        }
        let start = Instant::now();
        let outcome = farm.render_parts(parts, cancel.clone()).map_err(|source| queue_error(&queued, source))?;
        // The farm's threads, from its workers' Hello (the embedded worker's
        // own where there is no farm).
        let threads = if outcome.stats.threads > 0 { outcome.stats.threads } else { opts.cores };
        let core_seconds = start.elapsed().as_secs_f64() * threads as f64;
        for q in &queued {
            let _ = std::fs::remove_file(&q.journal);
        }
        // The render's cost shared by the jobs in proportion to the time
        // their tasks took on the workers (a cloudy column costs several
        // clear ones).
        let busy_total: f64 = outcome.busy_core_s.iter().sum();
        for ((q, columns), busy) in queued.iter().zip(&outcome.parts).zip(&outcome.busy_core_s) {
            let image = crate::session::image_of_columns(columns, q.view.width, q.view.height);
            let cost = if busy_total > 0.0 { core_seconds * busy / busy_total } else { 0.0 };
            match &q.kind {
                JobKind::Strip => strips[q.k] = Some(StripOutcome { image, core_seconds: cost, resumed: q.resumed }),
                JobKind::Grid(index) => {
                    grid_rendered[q.k].insert(*index, StripOutcome { image, core_seconds: cost, resumed: q.resumed });
                }
                JobKind::Fog(key) => {
                    fog_rendered[q.k].get_mut().unwrap().insert(key.clone(), (image, cost));
                }
            }
        }
        // The queue's texels and forecast are done; what is left is the
        // work after it, slice by slice, below.
        let mut t = tracker.lock().unwrap();
        t.texels_before += queued.iter().map(|q| (q.view.width * q.view.height) as u64).sum::<u64>();
        t.forecast_done += queued.iter().flat_map(|q| q.slices.iter().map(|s| s.1)).sum::<f64>();
        t.job = None;
    }
    let mut done = Vec::new();
    let atms: Vec<Atmosphere> = plan.iter().map(|p| p.atm.clone()).collect();
    drop(sessions);
    for (k, p) in plan.into_iter().enumerate() {
        let texels_of_job = job_texels(&p);
        let Planned { mut out, views, same_as, grid, .. } = p;
        let name = out.sky.name.clone();
        for (index, s) in out.slices.iter().enumerate() {
            if let Some(s) = s {
                tracker.lock().unwrap().emit(cached_slice(&name, index, s));
            }
        }
        let mut sky_core_seconds = 0.0;
        // The slices rendered now: from the sky's strip, or each from its grid.
        let mut rendered: Vec<(usize, RenderedSlice)> = Vec::new();
        if let Some(StripOutcome { image, core_seconds, resumed }) = strips[k].take() {
            let todo = &to_render[k];
            let (w, h) = (out.sky.width, out.sky.height);
            out.columns_resumed += resumed;
            sky_core_seconds += core_seconds;
            // The strip's cost shared by the slices in proportion to their samples.
            let samples: Vec<u64> = (0..todo.len()).map(|j| (0..h).flat_map(|y| &image.pixels[y * image.width + j * w..y * image.width + (j + 1) * w]).map(|p| p.samples as u64).sum()).collect();
            let all_samples = samples.iter().sum::<u64>().max(1) as f64;
            for (j, &index) in todo.iter().enumerate() {
                let (view, _) = views[index].as_ref().expect("to render");
                rendered.push((index, slice_of_strip(&image, j * w, view, &name, index, core_seconds * samples[j] as f64 / all_samples)?));
            }
        }
        if let Some(g) = grid.filter(|_| !grid_rendered[k].is_empty()) {
            // Each texel its single scattering plus the nodes' multiple
            // scattering, on this process's threads (timed into the slice's cost).
            let scene = optics.get(&atms[k], &out.spectral, mie, &|| {});
            let threads = rayon::current_num_threads() as f64;
            for (index, StripOutcome { image, core_seconds, resumed }) in std::mem::take(&mut grid_rendered[k]) {
                let (view, _) = views[index].as_ref().expect("to render");
                let start = Instant::now();
                let texels = g.resample(&image, &scene, view);
                let cost = core_seconds + start.elapsed().as_secs_f64() * threads;
                out.columns_resumed += resumed;
                sky_core_seconds += cost;
                rendered.push((index, slice_of_image(&texels, view, &name, index, cost)?));
            }
        }
        if !rendered.is_empty() {
            for (index, slice) in rendered {
                let (view, key) = views[index].as_ref().expect("to render");
                opts.cache.put(key, &slice)?;
                let mut t = tracker.lock().unwrap();
                t.slices_done += 1;
                t.forecast_done += after_queue[k][index];
                let forecast = forecasts[k][index] + after_queue[k][index];
                let forecast_core_seconds = t.forecast_total.map(|_| forecast);
                t.emit(BakeEvent::Slice {
                    sky: name.clone(),
                    index,
                    sun_zenith_deg: view.sun_zenith_deg,
                    cached: false,
                    core_seconds: slice.core_seconds,
                    forecast_core_seconds,
                    mean_samples: slice.mean_samples(),
                });
                drop(t);
                out.slices[index] = Some(slice);
                out.rendered += 1;
            }
        }
        // The same view as an earlier slice: rendered once.
        for (index, first) in same_as.iter().enumerate() {
            let Some(first) = *first else { continue };
            let slice = out.slices[first].clone();
            let mut t = tracker.lock().unwrap();
            t.texels_before += texels_of_job[index];
            t.slices_done += 1;
            if let Some(s) = &slice {
                t.emit(cached_slice(&name, index, s));
            }
            drop(t);
            out.slices[index] = slice;
            out.cached += 1;
        }
        if out.rendered > 0 {
            let mut t = tracker.lock().unwrap();
            let p = t.progress(0, None);
            t.emit(BakeEvent::Progress(p));
        }
        if opts.only.is_none() {
            // The sun's transmittance and sunlight, from the cache or from
            // the sky's optics (prepared now if no slice needed them).
            let zeniths: Vec<f64> = (0..out.sky.slices).map(|i| mapping::slice_sun_zenith_deg(i, out.radius_km, out.top_km)).collect();
            let key = lighting_key(&out.atmosphere_hash, &out.spectral, out.sky.altitude_m, &zeniths);
            out.lighting = match opts.cache.get_lighting(&key) {
                Some(l) => Some(l),
                None => {
                    let scene = optics.get(&atms[k], &out.spectral, mie, &|| {});
                    let l = SkyLighting::compute(&scene, out.sky.altitude_m, &zeniths);
                    opts.cache.put_lighting(&key, &l)?;
                    Some(l)
                }
            };
        }
        if opts.only.is_none() || !fog_plan[k].is_empty() {
            // The global-fog LUTs from their slices rendered in the queue
            // (or cached): a whole bake's, or the fog slices `only` names,
            // into the cache.
            let scene = optics.get(&atms[k], &out.spectral, mie, &|| {});
            let job = super::fog::FogJob { sky: &out.sky, atmosphere: &atms[k], scene: &scene, sampling: &out.sampling, settings: bake.fog, quality: opts.quality };
            let on_slice = |done: usize, total: usize| tracker.lock().unwrap().emit(BakeEvent::FogSlice { sky: name.clone(), done, total });
            // The slice as the queue rendered it (every fog slice not in the
            // cache was queued; a second slice of the same view, with the
            // cache off, gets the image at no cost). One that is neither
            // left the cache during the bake: an error.
            let render = |view: &View, index: usize| -> Result<(Image, f64), BakeError> {
                let key = slice_key(&out.atmosphere_hash, &out.spectral, view, opts.quality.name());
                let queued = fog_rendered[k].lock().unwrap().get_mut(&key).map(|(image, cost)| (image.clone(), std::mem::take(cost)));
                let (image, cost) = queued.ok_or_else(|| BakeError::FogSliceLost { sky: name.clone(), index, cache: opts.cache.dir().to_path_buf() })?;
                let mut t = tracker.lock().unwrap();
                t.slices_done += 1;
                t.forecast_done += fog_after_queue[k][index];
                let p = t.progress(0, None);
                t.emit(BakeEvent::Progress(p));
                Ok((image, cost))
            };
            if opts.only.is_some() {
                for (j, f) in fog_plan[k].iter().enumerate() {
                    let (image, cost) = render(&f.view, f.index)?;
                    let slice = slice_of_image(&image, &f.view, &format!("{name} (shadowed fog)"), f.index, cost)?;
                    opts.cache.put(&f.key, &slice)?;
                    out.fog_rendered.push((f.index, slice));
                    on_slice(j + 1, fog_plan[k].len());
                }
            } else {
                let fog = super::fog::bake_fog(&job, &opts.cache, &cancel, &render, &on_slice)?;
                tracker.lock().unwrap().emit(BakeEvent::FogDone {
                    sky: name.clone(),
                    slices_rendered: fog.rendered,
                    slices_cached: fog.cached,
                    core_seconds: fog.core_seconds,
                    falloff_a: fog.extras.falloff.a,
                    falloff_p: fog.extras.falloff.p,
                    fit_median: fog.extras.fit_error.median,
                    fit_p99: fog.extras.fit_error.p99,
                });
                out.fog = Some(fog);
            }
        }
        if out.slices.iter().any(Option::is_some) {
            tracker.lock().unwrap().emit(BakeEvent::SkyDone { sky: name, slices_rendered: out.rendered, slices_cached: out.cached, core_seconds: sky_core_seconds });
        }
        done.push(out);
    }
    Ok(done)
}

/// The samples `planned` for each texel, each weighed by the texel's share
/// of the pilot's sampling time: its time in the pilot (`pilot_s`) less
/// its time in a one-sample render (`one_s`), over all texels' (an even
/// share where no time was measured). With every texel at one cost this is
/// the mean of `planned`; the forecast is this times the sampling's
/// core-seconds a sample of every texel.
fn sample_weighted(planned: &[u32], pilot_s: &[f64], one_s: &[f64]) -> f64 {
    let share: Vec<f64> = pilot_s.iter().zip(one_s).map(|(p, o)| (p - o).max(0.0)).collect();
    let all: f64 = share.iter().sum();
    if all > 0.0 {
        planned.iter().zip(&share).map(|(&n, s)| n as f64 * s / all).sum()
    } else {
        planned.iter().map(|&n| n as f64).sum::<f64>() / planned.len().max(1) as f64
    }
}

/// A pilot's forecast of a view to render, kept in the cache folder
/// ([`pilot_key`]) so that a bake stopped and run again plans from it
/// instead of rendering every pilot again (the sunny skies' final bake:
/// 252 pilots, 9 minutes on this project's 2-core machine).
#[derive(Debug, Clone, Copy, serde::Serialize, serde::Deserialize)]
struct PilotForecast {
    /// Core-seconds of the view's render in the bake's queue.
    queue_core_seconds: f64,
    /// Core-seconds of the quadrature after the queue (a grid slice's or
    /// a fog slice's single scattering).
    after_queue_core_seconds: f64,
    /// Samples the view's texels will take.
    samples: u64,
}

/// What follows a view's render in the bake, at every texel of its slice:
/// single scattering by quadrature, for a fog slice's Fog (at the LUT's
/// size, whatever size its Shadowed Fog renders at) or a slice from a
/// grid of multiple scattering.
enum AfterQueue<'a> {
    Nothing,
    Fog { lut_texels: usize },
    Grid(MsGrid, &'a View),
}

/// The cache key of a pilot's forecast: the pilot's farm job (optics,
/// renderer source, view), what its quadrature times, the source of the
/// forecast's code, and this machine, its name and threads: the times are
/// this machine's (another machine, or another thread count, plans again).
fn pilot_key(pilot_job_hash: &str, quadrature_of: &serde_json::Value) -> String {
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname").or_else(|_| std::env::var("COMPUTERNAME")).unwrap_or_default();
    let key = serde_json::json!({
        "pilot": pilot_job_hash,
        "quadrature": quadrature_of,
        "forecast_source": env!("SKY_FORECAST_SOURCE"),
        "host": host.trim(),
        "threads": rayon::current_num_threads(),
    });
    blake3::hash(key.to_string().as_bytes()).to_hex().to_string()
}

/// The forecast of `view`'s adaptive render from its `pilot` rendered and
/// timed here, with the quadrature `after` it.
fn pilot_forecast(scene: &Scene, view: &View, pilot: &View, after: AfterQueue, cancel: &AtomicBool) -> Result<PilotForecast, BakeError> {
    // A render's cost is a part per render and per texel (the job, the
    // first-collision guide, single scattering) and a part per sample: the
    // pilot and a one-sample render of the same view tell them apart.
    // Rendered here in one piece, as the probes are ([`timed_here`]; a
    // grid's pilot, up to 316 nodes of 32 samples, is of the size of a farm
    // task's preparation); its pixels are the very ones the farm would
    // return.
    let (image, pilot_core_s, pilot_pixel_s) = timed_here(scene, pilot, cancel)?;
    let (_, one_core_s, one_pixel_s) = timed_here(scene, &View { spp: 1, ..pilot.clone() }, cancel)?;
    let planned = planned_samples(view, &image);
    // The pilot's samples past the first, core-seconds, shared among the
    // texels by their own time on their threads: a texel whose paths are
    // long (toward the horizon at twilight) costs more a sample, and it is
    // the noisy one that takes many. One mean cost a sample, as before,
    // forecast twilight grid slices 18 to 27 % low (README).
    let sampling_core_s = (pilot_core_s - one_core_s).max(0.0);
    let planned_cost = sample_weighted(&planned, &pilot_pixel_s, &one_pixel_s) * sampling_core_s / (ADAPTIVE_PILOT_SPP - 1) as f64;
    let fixed = (one_core_s - sampling_core_s / (ADAPTIVE_PILOT_SPP - 1) as f64).max(0.0);
    let after_queue_core_seconds = match after {
        AfterQueue::Fog { lut_texels } => super::fog::time_quadrature(scene, view) * lut_texels as f64 / (view.width * view.height) as f64,
        AfterQueue::Grid(grid, slice) => grid.time_quadrature(scene, slice),
        AfterQueue::Nothing => 0.0,
    };
    Ok(PilotForecast { queue_core_seconds: fixed + planned_cost, after_queue_core_seconds, samples: planned.iter().map(|&n| n as u64).sum() })
}

/// Renders `view` on this process's threads in one piece: its image, its
/// cost in core-seconds (the wall time times the threads) and each pixel's
/// seconds on its thread. How pilots and probes are timed: on a farm a
/// small view's few columns would go out as several small tasks, each
/// preparing its sun's tracers and guides again.
fn timed_here(scene: &Scene, view: &View, cancel: &AtomicBool) -> Result<(Image, f64, Vec<f64>), BakeError> {
    let start = Instant::now();
    let (image, pixel_s) = crate::render::render_timed(scene, view, cancel, &|| {}).map_err(|_| BakeError::Cancelled)?;
    Ok((image, start.elapsed().as_secs_f64() * rayon::current_num_threads() as f64, pixel_s))
}

/// The event of a slice found in the cache (or the same as an earlier one).
fn cached_slice(sky: &str, index: usize, s: &RenderedSlice) -> BakeEvent {
    BakeEvent::Slice { sky: sky.to_string(), index, sun_zenith_deg: s.sun_zenith_deg, cached: true, core_seconds: s.core_seconds, forecast_core_seconds: None, mean_samples: s.mean_samples() }
}

/// What a job of the bake's queue renders.
enum JobKind {
    /// A basis sky's strip of slices.
    Strip,
    /// The grid of multiple scattering of the sky's slice of this index.
    Grid(usize),
    /// A fog slice, by its cache key.
    Fog(String),
}

/// A job in the bake's queue: a basis sky's strip of slices (or a slice's
/// grid), or one of its fog slices.
struct QueuedJob {
    /// The sky's place in the bake, and its name ("NAME (fog)" for fog).
    k: usize,
    sky: String,
    kind: JobKind,
    /// The slices, by index, with their forecast core-seconds.
    slices: Vec<(usize, f64)>,
    slice_width: usize,
    view: View,
    journal: std::path::PathBuf,
    /// Columns taken from the journal of a bake that was stopped.
    resumed: u32,
}

/// A basis sky's strip, rendered: the image, its share of the queue's
/// cost in core-seconds, and the columns taken from a journal.
struct StripOutcome {
    image: Image,
    core_seconds: f64,
    resumed: u32,
}

/// A strip of slices (or a fog slice) as one job of the bake's queue, with its journal in
/// the cache folder: a bake killed mid-strip resumes from the columns it
/// had (the journal goes once the queue is done). Returns the part, the
/// journal's path and the columns taken from it.
fn journaled_part(session: &Session, view: &View, cache: &SliceCache) -> Result<(FarmPart, std::path::PathBuf, u32), BakeError> {
    let job = session.job(view);
    let path = cache.dir().join(format!("{}.journal", job.hash));
    let header = Header { job_hash: job.hash.clone(), width: view.width as u32, height: view.height as u32 };
    // A journal that cannot be read back (torn header, another job) is started again.
    let (journal, resumed) = match path.exists().then(|| Journal::resume(&path, &header)) {
        Some(Ok((j, columns))) => (j, columns),
        _ => (Journal::create(&path, &header).map_err(BakeError::Journal)?, BTreeMap::new()),
    };
    let resumed_columns = resumed.len() as u32;
    Ok((FarmPart { job, resumed, journal: Some(journal) }, path, resumed_columns))
}

/// The bake's error for a failed queue: a column that failed names its
/// basis sky and slice; anything else names the slices of the one job
/// queued, or every sky queued.
fn queue_error(queued: &[QueuedJob], source: FarmError) -> BakeError {
    if let FarmError::ColumnFailed { part, column, .. } = &source {
        if let Some(q) = queued.get(*part) {
            let index = q.slices[(*column as usize / q.slice_width.max(1)).min(q.slices.len() - 1)].0;
            return BakeError::Render { sky: q.sky.clone(), index, source };
        }
    }
    match queued {
        [q] => {
            let (first, last) = (q.slices[0].0, q.slices.last().expect("a job has slices").0);
            if first == last {
                BakeError::Render { sky: q.sky.clone(), index: first, source }
            } else {
                BakeError::RenderSlices { sky: q.sky.clone(), first, last, source }
            }
        }
        _ => {
            let mut skies: Vec<&str> = queued.iter().map(|q| q.sky.as_str()).collect();
            skies.dedup();
            BakeError::RenderQueue { skies: skies.join(", "), source }
        }
    }
}

/// Slice `index` of `sky`, the columns of `image` from `x0` on; a texel
/// that is not finite is an error naming it.
/// A whole image as one slice (see `slice_of_strip`).
pub(crate) fn slice_of_image(image: &Image, view: &View, sky: &str, index: usize, core_seconds: f64) -> Result<RenderedSlice, BakeError> {
    slice_of_strip(image, 0, view, sky, index, core_seconds)
}

fn slice_of_strip(image: &Image, x0: usize, view: &View, sky: &str, index: usize, core_seconds: f64) -> Result<RenderedSlice, BakeError> {
    let (w, h) = (view.width, view.height);
    let px: Vec<&crate::render::PixelResult> = (0..h).flat_map(|y| &image.pixels[y * image.width + x0..y * image.width + x0 + w]).collect();
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::{render, PixelResult, Scene};

    /// The DISORT Rayleigh + HG slab as a basis sky of `width` × `height`
    /// texels sampled as `sampling`, with its prepared optics.
    pub(super) fn test_sky(width: usize, height: usize, sampling: &Sampling) -> (Atmosphere, Scene, BasisSky) {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/atmospheres/disort_rayleigh_hg.toml");
        let atm = Atmosphere::load(&path).unwrap();
        let scene = Scene::new(&atm, &spectral_settings(sampling), &MieCache::new(None), &|| {});
        let sky = BasisSky { name: "t".into(), atmosphere: path, width, height, slices: 64, altitude_m: 0.0, threshold_deg: 87.5, line: 1, draft: sampling.clone(), final_: sampling.clone() };
        (atm, scene, sky)
    }

    /// `--slice` names a sky slice as NAME:INDEX and a fog slice as
    /// NAME:fog:INDEX, and writes them back the same way.
    #[test]
    fn slice_ids_name_sky_and_fog_slices() {
        let fog: SliceId = "clear:fog:12".parse().unwrap();
        assert_eq!(fog, SliceId { sky: "clear".into(), index: 12, fog: true });
        assert_eq!(fog.to_string(), "clear:fog:12");
        let sky: SliceId = "clear:12".parse().unwrap();
        assert_eq!((sky.fog, sky.to_string().as_str()), (false, "clear:12"));
        for bad in ["clear:fog:64", ":fog:3", "clear:fog", "clear"] {
            assert!(bad.parse::<SliceId>().is_err(), "{bad}");
        }
    }

    /// The forecast weighs each texel's planned samples by its own share
    /// of the pilot's sampling time: at one cost for all, the mean count;
    /// a texel three times as dear counts three times; no time measured
    /// (a strip's pixels), the mean again.
    #[test]
    fn planned_samples_are_weighed_by_each_texels_time() {
        let planned = [100, 300];
        assert_eq!(sample_weighted(&planned, &[2.0, 2.0], &[1.0, 1.0]), 200.0);
        // Shares 1/4 and 3/4 of the sampling time: (100 + 3 × 300) / 4.
        assert_eq!(sample_weighted(&planned, &[1.5, 2.5], &[1.0, 1.0]), 250.0);
        assert_eq!(sample_weighted(&planned, &[0.0, 0.0], &[0.0, 0.0]), 200.0);
        // A one-sample render slower than the pilot (timing noise) counts nothing.
        assert_eq!(sample_weighted(&planned, &[1.0, 2.0], &[1.5, 1.0]), 300.0);
    }

    /// The forecast's core: a slice's pilot, rendered on its own, plans
    /// exactly the samples each texel of the adaptive render then takes.
    #[test]
    fn pilots_plan_every_texels_samples_exactly() {
        let sampling = Sampling { band_nm: 40.0, spp: 400, max_rel_error: Some(0.05), ms_grid: None, fog_ms_size: None };
        let (atm, scene, sky) = test_sky(4, 16, &sampling);
        let cancel = AtomicBool::new(false);
        let mut total = 0u64;
        for index in [10, 40, 50] {
            let view = slice_view(&sky, &sampling, index, atm.planet.radius_km, atm.planet.top_km, sky.threshold_deg);
            let pilot = render(&scene, &pilot_view(&view).unwrap(), &cancel, &|| {}).unwrap();
            let planned = planned_samples(&view, &pilot);
            let rendered = render(&scene, &view, &cancel, &|| {}).unwrap();
            let taken: Vec<u32> = rendered.pixels.iter().map(|p| p.samples).collect();
            assert_eq!(planned, taken, "slice {index}");
            total += taken.iter().map(|&n| n as u64).sum::<u64>();
        }
        // Not every texel at the floor or the cap: the plan has something to predict.
        assert!(total > 3 * 64 * 64 && total < 3 * 64 * 400, "{total}");
        assert!(pilot_view(&View { max_rel_error: None, ..slice_view(&sky, &sampling, 0, 6371.0, 100.0, 87.5) }).is_none());
    }

    /// A slice renders the nodes of its grid that its texels take, each
    /// direction once (the zenith's, the nadir's and the sun's rows are
    /// one each): at the talk's 32 x 128 texels fewer as the sun sets, the
    /// sun patch's cells that reach below the horizon left out (all of
    /// them with the sun 6° below it); every texel's nodes among them.
    #[test]
    fn a_slice_renders_only_the_grid_nodes_its_texels_take() {
        let sampling = Sampling { band_nm: 40.0, spp: 16, max_rel_error: None, ms_grid: Some([16, 13]), fog_ms_size: None };
        let (atm, _, sky) = test_sky(32, 128, &sampling);
        let grid = MsGrid::new([16, 13], Standpoint::new(atm.planet.geometry, atm.planet.radius_km, 0.0));
        let patch = super::super::ms_grid::SUN_PATCH_ROWS * super::super::ms_grid::SUN_PATCH_COLS;
        let mut counts = Vec::new();
        for index in [4, 28, 45, 53, 60] {
            let view = View { sun_azimuth_deg: 25.0, ..slice_view(&sky, &sampling, index, atm.planet.radius_km, atm.planet.top_km, sky.threshold_deg) };
            let r = grid.rendered_nodes(&view);
            let sun = (view.sun_zenith_deg, view.sun_azimuth_deg);
            let direction = |k: usize| {
                let (z, a) = grid.node_deg(k, sun);
                crate::render::camera::direction_deg(z, a)
            };
            // Ascending, distinct directions, each node at its own pixel.
            assert!(r.nodes.windows(2).all(|w| w[0] < w[1]));
            for (i, &k) in r.nodes.iter().enumerate() {
                assert_eq!(r.at[k], Some(i));
                assert!(r.nodes[..i].iter().all(|&j| direction(j).distance(direction(k)) > 1e-9), "slice {index}: node {k} twice");
            }
            // Every texel's nodes of positive weight are rendered, and a node
            // shares a pixel only with its own direction.
            for i in 0..view.width * view.height {
                let d = view.camera.direction((i % view.width) as f64 + 0.5, (i / view.width) as f64 + 0.5, view.width, view.height).unwrap();
                for (k, w) in grid.weights(d, sun) {
                    if w > 0.0 {
                        let at = r.at[k].unwrap_or_else(|| panic!("slice {index}: texel {i} takes node {k}, not rendered"));
                        assert!(direction(r.nodes[at]).distance(direction(k)) < 1e-9);
                    }
                }
            }
            let patch_rendered = r.nodes.iter().filter(|&&k| k >= grid.nodes() - patch).count();
            eprintln!("slice {index} (sun zenith {:.1}°): {} of {} nodes, {patch_rendered} of the patch's", view.sun_zenith_deg, r.nodes.len(), grid.nodes());
            counts.push((r.nodes.len(), patch_rendered));
        }
        // Fewer nodes as the sun sets (measured: 238, 236, 217, 207, 194),
        // the patch's among them (40, 37, 23, 13, 0): by day fewer than the
        // 30 copies of the zenith's, nadir's and sun's rows alone leave out,
        // none of the patch with the sun 6° below the horizon.
        assert!(counts[0].0 < grid.nodes() - 30 && counts[0].1 > 0 && counts[4].1 == 0, "{counts:?}");
        assert!(counts.windows(2).all(|w| w[0].0 >= w[1].0), "{counts:?}");
    }

    /// Nodes of one direction share one noise in a texel's standard error:
    /// with every rendered node's standard error 1, a texel's is the root of
    /// the sum over rendered pixels of its weights on each, squared, which
    /// for a texel by the zenith (its cell's two upper nodes one pixel) is
    /// more than the sum of the squared weights node by node.
    #[test]
    fn nodes_of_one_direction_share_their_noise() {
        let sampling = Sampling { band_nm: 40.0, spp: 16, max_rel_error: None, ms_grid: Some([16, 13]), fog_ms_size: None };
        let (atm, scene, sky) = test_sky(8, 32, &sampling);
        let grid = MsGrid::new([16, 13], Standpoint::new(atm.planet.geometry, atm.planet.radius_km, 0.0));
        let view = slice_view(&sky, &sampling, 4, atm.planet.radius_km, atm.planet.top_km, sky.threshold_deg);
        let nodes_view = grid.view(&view);
        let single = crate::render::single_per_pixel(&scene, &nodes_view);
        let pixels = single.iter().map(|&xyz| PixelResult { xyz_stderr: [1.0; 3], samples: 1, ..PixelResult::from_xyz(xyz) }).collect();
        let resampled = grid.resample(&Image { width: nodes_view.width, height: 1, pixels }, &scene, &view);
        let at = grid.rendered_nodes(&view).at;
        let mut merged_somewhere = false;
        for (i, texel) in resampled.pixels.iter().enumerate() {
            let d = view.camera.direction((i % view.width) as f64 + 0.5, (i / view.width) as f64 + 0.5, view.width, view.height).unwrap();
            let weights: Vec<(usize, f64)> = grid.weights(d, (view.sun_zenith_deg, view.sun_azimuth_deg)).into_iter().filter(|w| w.1 > 0.0).collect();
            let mut by_pixel = std::collections::BTreeMap::new();
            for &(k, w) in &weights {
                *by_pixel.entry(at[k].unwrap()).or_insert(0.0) += w;
            }
            let shared: f64 = by_pixel.values().map(|w| w * w).sum();
            let apart: f64 = weights.iter().map(|(_, w)| w * w).sum();
            merged_somewhere |= shared > apart + 1e-9;
            assert!((texel.xyz_stderr[1] - shared.sqrt()).abs() < 1e-12, "texel {i}: {} against {}", texel.xyz_stderr[1], shared.sqrt());
        }
        assert!(merged_somewhere, "no texel took two nodes of one direction");
    }

    /// A slice from its grid of multiple scattering (`ms_grid`) agrees with
    /// the slice rendered texel by texel: each texel's difference within
    /// the Sidak threshold for a family-wise false alarm of 1e-3 over every
    /// texel of both slices (z = 4.47 for 128; Gaussian means of 512
    /// samples), its standard error the two renders' together plus an
    /// allowance of 2 % of Y for the interpolation (the worst the bench
    /// measured for a 16 x 13 grid: 1.7 %, hazed at a sun zenith of 85°); and
    /// the mean relative difference over each slice within its own
    /// standard error times 3.48 (Sidak, 1e-3 over the two slices) plus
    /// 0.5 %. That standard error is the grid's nodes' (the texels share
    /// them: each node weighs in the mean by its weights over the texels)
    /// and the whole slice's texels' together, from their own standard
    /// errors, which at 512 samples of heavy-tailed paths run small: over
    /// 30 seeds the grid's mean scattered by 1.9 % at slice 20 where that
    /// estimate said at most 1.5 %, so it is taken 1.5 times. Leaving out the single
    /// scattering, or mirroring the grid the wrong way, misses by far more.
    #[test]
    fn a_slice_from_its_grid_agrees_with_the_slice_rendered_whole() {
        let sampling = Sampling { band_nm: 40.0, spp: 512, max_rel_error: None, ms_grid: Some([16, 13]), fog_ms_size: None };
        let (atm, scene, sky) = test_sky(4, 16, &sampling);
        let cancel = AtomicBool::new(false);
        let grid = MsGrid::new([16, 13], Standpoint::new(atm.planet.geometry, atm.planet.radius_km, 0.0));
        let z_crit = 4.47;
        for index in [4, 20] {
            let view = View { sun_azimuth_deg: 25.0, ..slice_view(&sky, &sampling, index, atm.planet.radius_km, atm.planet.top_km, sky.threshold_deg) };
            let nodes = render(&scene, &grid.view(&view), &cancel, &|| {}).unwrap();
            let from_grid = grid.resample(&nodes, &scene, &view);
            let whole = render(&scene, &view, &cancel, &|| {}).unwrap();
            let n = whole.pixels.len() as f64;
            let at = grid.rendered_nodes(&view).at;
            // Each node's weight in the slice's mean relative difference.
            let mut in_mean = vec![0.0; nodes.pixels.len()];
            let (mut worst, mut mean, mut whole_var) = (0.0f64, 0.0, 0.0);
            for (i, (g, w)) in from_grid.pixels.iter().zip(&whole.pixels).enumerate() {
                let (a, b) = (g.xyz[1], w.xyz[1]);
                let sigma = (g.xyz_stderr[1].powi(2) + w.xyz_stderr[1].powi(2) + (0.02 * b).powi(2)).sqrt();
                worst = worst.max((a - b).abs() / sigma);
                mean += (a - b) / b / n;
                whole_var += (a / b * w.xyz_stderr[1] / b / n).powi(2);
                assert!(g.samples > 0 && g.samples <= 512, "{}", g.samples);
                let d = view.camera.direction((i % view.width) as f64 + 0.5, (i / view.width) as f64 + 0.5, view.width, view.height).unwrap();
                for (k, wk) in grid.weights(d, (view.sun_zenith_deg, view.sun_azimuth_deg)).into_iter().filter(|&(_, wk)| wk > 0.0) {
                    in_mean[at[k].unwrap()] += wk / b / n;
                }
            }
            let grid_var: f64 = in_mean.iter().zip(&nodes.pixels).map(|(c, p)| (c * p.xyz_stderr[1]).powi(2)).sum();
            let se = 1.5 * (grid_var + whole_var).sqrt();
            eprintln!("slice {index}: worst z {worst:.2}, mean relative difference {:.3} % (standard error {:.3} %)", 100.0 * mean, 100.0 * se);
            assert!(worst < z_crit, "slice {index}: a texel {worst:.2} standard errors off");
            assert!(mean.abs() < 3.48 * se + 0.005, "slice {index}: mean relative difference {mean}, standard error {se}");
        }
    }

    /// A strip of slices (one farm job) renders each slice's texels bit for
    /// bit as the slice rendered alone, also in a task that crosses from one
    /// slice into the next, and with an adaptive sample count.
    #[test]
    fn a_strip_renders_each_slice_as_it_renders_alone() {
        let sampling = Sampling { band_nm: 40.0, spp: 128, max_rel_error: Some(0.3), ms_grid: None, fog_ms_size: None };
        let (atm, scene, sky) = test_sky(3, 8, &sampling);
        let cancel = AtomicBool::new(false);
        // Day, the sun-centred mapping's last slices, twilight.
        let views: Vec<View> = [20, 47, 52, 60].iter().map(|&i| slice_view(&sky, &sampling, i, atm.planet.radius_km, atm.planet.top_km, sky.threshold_deg)).collect();
        let strip = strip_view(&views.iter().collect::<Vec<_>>());
        assert_eq!((strip.width, strip.height), (12, 8));
        assert!(strip.check().is_ok());
        assert!(View { width: 13, ..strip.clone() }.check().is_err());
        let whole = render(&scene, &strip, &cancel, &|| {}).unwrap();
        // Columns 2 to 7: the end of slice 0, all of slice 1, the start of slice 2.
        let task = crate::render::render_columns(&scene, &strip, 2, 6, &cancel, &|| {}).unwrap();
        for (k, v) in views.iter().enumerate() {
            let alone = render(&scene, v, &cancel, &|| {}).unwrap();
            for y in 0..8 {
                for x in 0..3 {
                    let (a, b) = (&alone.pixels[y * 3 + x], &whole.pixels[y * 12 + k * 3 + x]);
                    assert!(a.xyz.iter().zip(&b.xyz).all(|(p, q)| p.to_bits() == q.to_bits()) && a.samples == b.samples, "slice {k}, texel ({x}, {y})");
                    if let Some(col) = (k * 3 + x).checked_sub(2).and_then(|c| task.get(c)) {
                        assert_eq!(col[y].xyz.map(f64::to_bits), a.xyz.map(f64::to_bits), "task column {}", k * 3 + x);
                    }
                }
            }
        }
        // The texels took different sample counts (adaptive sampling), each as in its own slice.
        let counts: std::collections::BTreeSet<u32> = whole.pixels.iter().map(|p| p.samples).collect();
        assert!(counts.len() > 1, "{counts:?}");
    }
}
