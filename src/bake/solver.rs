//! The bake's sky slices by the transport solver (`--method
//! deterministic`): each basis sky's slices to render as one
//! strip ([`Camera::LutStrip`](crate::directions::Camera::LutStrip)), whose
//! slices share one solution per wavelength (`transport::render`: the
//! columns of every sun of the strip solved once), on this process's
//! cores. No farm and no journal: a sky's strip takes minutes, and a bake
//! stopped between skies finds the finished skies' slices in the cache.
//!
//! The sky's fog slices (their Shadowed Fog; `fog`) are views of the same
//! render: the same suns, each wavelength solved once for both.
//!
//! Progress: the strip's texels in proportion to the wavelengths solved;
//! the ETA from the "solver's pilots" (`render_strips`).

use super::cache::SliceCache;
use super::plan::Plan;
use super::queue::StripOutcome;
use super::references::ReferenceViews;
use super::slices::{deterministic_tag, strip_view};
use super::tracker::{QueueJob, Tracker};
use super::{BakeError, BakeEvent, Quality, Sampling};
use crate::render::Image;
use crate::render::View;
use crate::session::Session;
use crate::transport::render::{Resolution, SolvedWavelength, Staged, WavelengthId};
use crate::transport::spherical::Detail;
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

/// The solver's resolutions for a bake of `quality`.
///
/// Final: the defaults (`transport::render::Resolution`: 16 streams, the
/// sun-angle columns 1° apart), the multiply scattered light solved at
/// bands 20 nm apart and interpolated between, the diffuse light's table
/// at `BAKE_VIEW_GRID`. Measured on a fisheye by `examples/spectral_nodes`
/// against every 5 nm band solved (clear.toml at sun 60°, hazed.toml at
/// 85°): 20 nm apart, Y within 0.06 % and CIEDE2000 within 0.28.
///
/// Draft: 8 streams, bands 80 nm apart, a table of 64 x 32 views, the
/// twilight iteration's draft settings (`spherical::Settings::draft`),
/// layers twice as thick (`Grading::coarser`).
/// Measured against the final on `bakes/demo.toml`'s clear sky
/// (`examples/draft_error`, 2026-12-07; the draft preset's 20 nm bands
/// against the final's 5 nm; docs/bakes.md "The method"): slices 0 to 36
/// (suns 0 to 87.5°, with 96 x 40 views) Y median 0.53 %, p99 1.58 %, 13
/// times faster; slices 40 to 58 (suns 88.5 to 94.4°, the full twilight
/// iteration) median 0.5 to 1.4 % a slice, p99 under 2.1 %; slice 58 with
/// the draft iteration 1.49 % and 3.1 %, 35 times faster; slice 63 (sun
/// 100°) 21 % (the multiply scattered light between spectral nodes, nearly
/// all the light there, is no power law in wavelength). The coarser
/// layers: slices 0, 16, 32 Y median 0.59 % against 0.53 %, 2.4 times less
/// time; slice 58 1.21 % against 1.49 %. Columns 2° apart
/// would halve the daytime cost but miss twilight by 8 to 14 % (the
/// sources are interpolated in the local sun angle).
///
/// A preset's `streams` replaces either default.
pub fn resolution(quality: Quality, sampling: &Sampling) -> Resolution {
    let default = Resolution::default();
    let (streams, ms_step_nm, view_grid, twilight) = match quality {
        Quality::Draft => (8, 80.0, crate::transport::render::DRAFT_VIEW_GRID, Detail::Draft),
        Quality::Final => (default.streams, 20.0, crate::transport::render::BAKE_VIEW_GRID, Detail::Full),
    };
    let grading = match quality {
        Quality::Draft => default.grading.coarser(),
        Quality::Final => default.grading,
    };
    // Every view from the view nodes' table (the LUT slices always are;
    // `sky lut verify`'s references as they).
    Resolution {
        ms_step_nm,
        streams: sampling.streams.unwrap_or(streams),
        view_grid,
        twilight,
        grading,
        pixel_rays: 0,
        ..default
    }
}

/// A fog slice's render by cache key: the image and its cost in
/// core-seconds.
pub(super) type FogRenders = BTreeMap<String, (Image, f64)>;

/// One basis sky's views to solve: its strip (if any slice is to render),
/// its fog slices, and `sky lut verify`'s references if they are to
/// render (the cache and their key), and the queue's slices.
struct SkyJob<'a> {
    sky: String,
    all: Vec<View>,
    strip: bool,
    first_reference: usize,
    verify: Option<(&'a SliceCache, String)>,
    slices: Vec<(String, usize, u64)>,
    resolution: Resolution,
}

impl SkyJob<'_> {
    fn texels(&self) -> u64 {
        self.slices.iter().map(|s| s.2).sum()
    }
}

/// The views of basis sky `k` of `plan` to solve, None with none.
fn sky_job<'a>(
    plan: &Plan,
    k: usize,
    quality: Quality,
    references: Option<(&'a SliceCache, f64)>,
) -> Option<SkyJob<'a>> {
    let p = &plan.skies[k];
    let (to_render, fog) = (p.to_render(), &plan.fog[k]);
    if to_render.is_empty() && fog.is_empty() {
        return None;
    }
    let sky = p.out.sky.name.clone();
    let views: Vec<&View> = to_render.iter().map(|&i| &p.views[i].as_ref().expect("to render").0).collect();
    let mut all: Vec<View> = if views.is_empty() { Vec::new() } else { vec![strip_view(&views)] };
    all.extend(fog.iter().map(|f| f.view.clone()));
    // `sky lut verify`'s references, if not in the cache: rendered after
    // the slices, priced in with them.
    let first_reference = all.len();
    let verify = references.and_then(|(cache, ceiling_km)| {
        let o = &p.out;
        let refs = ReferenceViews::new(
            (o.radius_km, o.top_km, o.sky.altitude_m),
            (super::references::DIRECTIONS, &super::references::CENTRE_SLICES),
            (1, 1),
            Some(ceiling_km),
        );
        let key = refs.key(&o.atmosphere_hash, &o.spectral, &deterministic_tag(quality, &o.sampling));
        let views = refs.all();
        super::references::cached(cache, &key, &views).is_none().then(|| {
            all.extend(views);
            (cache, key)
        })
    });
    let mut slices: Vec<(String, usize, u64)> = Vec::new();
    for (&i, v) in to_render.iter().zip(&views) {
        slices.push((sky.clone(), i, (v.width * v.height) as u64));
    }
    for f in fog {
        slices.push((format!("{sky} (fog)"), f.index, (f.view.width * f.view.height) as u64));
    }
    let resolution = resolution(quality, &p.out.sampling);
    Some(SkyJob { sky, all, strip: !views.is_empty(), first_reference, verify, slices, resolution })
}

/// What `render_strips` rendered: per basis sky its strip, its fog
/// slices, and the forecast of each fog slice's quadrature after them
/// ((index, core-seconds)).
pub(super) struct Strips {
    pub strips: Vec<Option<StripOutcome>>,
    pub fogs: Vec<FogRenders>,
    pub fog_after: Vec<Vec<(usize, f64)>>,
}

/// One part in this many of a sky's views is finished to price the
/// finish: about 1 % of the bake's time spent on the forecast.
const FINISH_PRICE_STRIDE: usize = 8;

/// Every basis sky's strip of the slices to render (None for a sky with
/// none) and its fog slices to render, solved at the resolution of
/// `quality` and the sky's preset. With `references` (the cache and the
/// fog's ceiling), a sky that renders anything also renders `sky lut
/// verify`'s default references in the same solution into the cache
/// (`references`), unless they are there.
///
/// The forecast: first one wavelength of every sky (its middle band
/// node), timed (the "solver's pilots"); each sky's other wavelengths are
/// forecast to cost what its pilot did, and the per-texel work after them
/// (`Staged::finish`) what an eighth of it costs with the pilot's light
/// (`Staged::price_finish`). Then sky after sky the rest, its pilot's
/// light kept. The Fog's quadrature after the solutions is priced on an
/// eighth of the fog slices too.
pub(super) fn render_strips(
    plan: &Plan,
    sessions: &[Option<Session>],
    quality: Quality,
    references: Option<(&SliceCache, f64)>,
    tracker: &Mutex<Tracker>,
    cancel: &AtomicBool,
) -> Result<Strips, BakeError> {
    let jobs: Vec<Option<SkyJob>> = (0..plan.skies.len())
        .map(|k| sessions[k].as_ref().and_then(|_| sky_job(plan, k, quality, references)))
        .collect();
    let mut staged = Vec::new();
    for (job, session) in jobs.iter().zip(sessions) {
        staged.push(match (job, session) {
            (Some(j), Some(s)) => Some(
                Staged::new(&s.scene, &j.all, &j.resolution)
                    .map_err(|error| BakeError::Solver { sky: j.sky.clone(), error })?,
            ),
            _ => None,
        });
    }
    let threads = rayon::current_num_threads() as f64;
    // The pilots.
    let start = Instant::now();
    tracker.lock().unwrap().planning = true;
    let count = staged.iter().flatten().count();
    let mut pilots: Vec<Option<(WavelengthId, SolvedWavelength, (f64, f64))>> = Vec::new();
    let mut fog_after: Vec<Vec<(usize, f64)>> = vec![Vec::new(); jobs.len()];
    for (k, (job, stage)) in jobs.iter().zip(&staged).enumerate() {
        let (Some(job), Some(stage), Some(session)) = (job, stage, &sessions[k]) else {
            pilots.push(None);
            continue;
        };
        if cancel.load(Ordering::SeqCst) {
            return Err(BakeError::Cancelled);
        }
        let ids = stage.wavelengths();
        let id = ids[ids.len() / 2];
        let t0 = Instant::now();
        let light = stage.solve(id);
        let core_seconds = t0.elapsed().as_secs_f64() * threads;
        // The other wavelengths at the pilot's cost (within 15 % of it
        // for clear.toml and cloudy3.toml's draft nodes, 400 to 720 nm),
        // and the per-texel work after them, priced on an eighth of it.
        let finish = stage.price_finish(&light, FINISH_PRICE_STRIDE);
        let forecast = core_seconds * (ids.len() - 1) as f64 + finish;
        pilots.push(Some((id, light, (forecast, core_seconds))));
        // The Fog's single scattering, added by quadrature after the
        // solutions (a whole bake's: not a part's), timed on an eighth of
        // the fog slices.
        if references.is_some() {
            fog_after[k] = price_fog_quadrature(&session.scene, &plan.fog[k]);
        }
        let sky_total = forecast + fog_after[k].iter().map(|f| f.1).sum::<f64>();
        let done = pilots.iter().flatten().count();
        let t = tracker.lock().unwrap();
        t.planned_one("solver's pilots", start, (&job.sky, 0, false), (done, count), Some(sky_total));
    }
    let total: f64 =
        pilots.iter().flatten().map(|p| p.2 .0).sum::<f64>() + fog_after.iter().flatten().map(|f| f.1).sum::<f64>();
    tracker.lock().unwrap().forecast("solver's pilots", start, (total, 0), 0);
    let (mut strips, mut fogs) = (Vec::new(), Vec::new());
    for (k, ((job, stage), pilot)) in jobs.iter().zip(&staged).zip(pilots).enumerate() {
        let (Some(job), Some(stage), Some((pilot, pilot_light, forecast))) = (job, stage, pilot) else {
            strips.push(None);
            fogs.push(FogRenders::new());
            continue;
        };
        if cancel.load(Ordering::SeqCst) {
            return Err(BakeError::Cancelled);
        }
        let (strip, fog) = render_sky(job, stage, (pilot, pilot_light, forecast), &plan.fog[k], tracker)?;
        strips.push(strip);
        fogs.push(fog);
    }
    Ok(Strips { strips, fogs, fog_after })
}

/// Each fog slice's (index, core-seconds) of the quadrature that adds the
/// Fog's single scattering after the solutions: every
/// `FINISH_PRICE_STRIDE`-th slice timed, each slice priced at their mean.
fn price_fog_quadrature(scene: &crate::render::Scene, fog: &[super::fog::FogTodo]) -> Vec<(usize, f64)> {
    let timed: Vec<f64> =
        fog.iter().step_by(FINISH_PRICE_STRIDE).map(|f| super::fog::time_quadrature(scene, &f.view)).collect();
    let mean = timed.iter().sum::<f64>() / timed.len().max(1) as f64;
    fog.iter().map(|f| (f.index, mean)).collect()
}

/// One basis sky's rest of `render_strips`: its wavelengths but the
/// pilot's, solved in parallel, and its images.
fn render_sky(
    job: &SkyJob,
    stage: &Staged,
    (pilot, pilot_light, (forecast, pilot_core_seconds)): (WavelengthId, SolvedWavelength, (f64, f64)),
    fog: &[super::fog::FogTodo],
    tracker: &Mutex<Tracker>,
) -> Result<(Option<StripOutcome>, FogRenders), BakeError> {
    let texels = job.texels();
    let shares: Vec<f64> = job.slices.iter().map(|s| forecast * s.2 as f64 / texels.max(1) as f64).collect();
    tracker.lock().unwrap().start_queue(QueueJob::new(job.slices.clone(), &shares), 0);
    let rest: Vec<WavelengthId> = stage.wavelengths().into_iter().filter(|&id| id != pilot).collect();
    let done = AtomicUsize::new(0);
    let solves = pilot_core_seconds * rest.len() as f64;
    let solved_share = if forecast > solves { solves / forecast } else { 1.0 };
    let start = Instant::now();
    let mut solved: Vec<(WavelengthId, SolvedWavelength)> = rest
        .par_iter()
        .map(|&id| {
            let light = stage.solve(id);
            let d = done.fetch_add(1, Ordering::SeqCst) as f64 + 1.0;
            let mut t = tracker.lock().unwrap();
            // The solutions' share of the sky's forecast; the finish is the rest.
            let progress = t.progress((texels as f64 * solved_share * d / rest.len().max(1) as f64) as u64, None);
            t.emit(BakeEvent::Progress(progress));
            (id, light)
        })
        .collect();
    solved.push((pilot, pilot_light));
    let mut images = stage.finish(solved);
    {
        let mut t = tracker.lock().unwrap();
        let progress = t.progress(texels, None);
        t.emit(BakeEvent::Progress(progress));
    }
    if let Some((cache, key)) = &job.verify {
        super::references::store(cache, key, &images[job.first_reference..])?;
    }
    images.truncate(job.first_reference);
    let mut images = images.into_iter();
    // The cost shared by texels: the pilot's and the rest's.
    let core_seconds = start.elapsed().as_secs_f64() * rayon::current_num_threads() as f64 + pilot_core_seconds;
    let per_texel = core_seconds / texels.max(1) as f64;
    let strip = job.strip.then(|| images.next().expect("the strip's image")).map(|image| {
        let core_seconds = per_texel * (image.width * image.height) as f64;
        StripOutcome { image, core_seconds, resumed: 0 }
    });
    let fogs = fog
        .iter()
        .zip(images)
        .map(|(f, image)| {
            let cost = per_texel * (image.width * image.height) as f64;
            (f.key.clone(), (image, cost))
        })
        .collect();
    let mut t = tracker.lock().unwrap();
    t.texels_before += texels;
    t.forecast_done += forecast;
    t.job = None;
    Ok((strip, fogs))
}
