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
use super::forecast::{forecast, Forecasts};
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
use crate::render::{Image, SingleScatter, SpectralSettings, View, WavelengthSampling};
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
    let Forecasts { sky: forecasts, fog: fog_forecasts, sky_after: after_queue, fog_after: fog_after_queue } = forecast(&plan, &fog_plan, &sessions, bake, (&opts.cache, &tracker), &cancel)?;
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

/// The event of a slice found in the cache (or the same as an earlier one).
fn cached_slice(sky: &str, index: usize, s: &RenderedSlice) -> BakeEvent {
    BakeEvent::Slice { sky: sky.to_string(), index, sun_zenith_deg: s.sun_zenith_deg, cached: true, core_seconds: s.core_seconds, forecast_core_seconds: None, mean_samples: s.mean_samples() }
}

/// A basis sky in a bake's plan: its slices' views, and which the cache
/// holds.
pub(super) struct Planned {
    pub(super) atm: Atmosphere,
    pub(super) bundle: crate::atmosphere::Bundle,
    pub(super) out: SkySlices,
    pub(super) views: Vec<Option<(View, String)>>,
    /// Multiple scattering on a grid of its own (`ms_grid`): each slice
    /// is then rendered as its grid's nodes and resampled.
    pub(super) grid: Option<MsGrid>,
    /// What the queue renders of each slice in `views`: its view, or
    /// its grid's.
    pub(super) jobs: Vec<Option<View>>,
    /// For a slice whose view an earlier one to render has too (47 and
    /// 48 are both the horizon in the talk's layout): that slice.
    pub(super) same_as: Vec<Option<usize>>,
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
pub(super) mod tests {
    use super::*;
    use crate::render::{render, PixelResult, Scene};

    /// The DISORT Rayleigh + HG slab as a basis sky of `width` × `height`
    /// texels sampled as `sampling`, with its prepared optics.
    pub(in crate::bake) fn test_sky(width: usize, height: usize, sampling: &Sampling) -> (Atmosphere, Scene, BasisSky) {
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
