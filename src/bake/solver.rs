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
//! Progress: the strip's texels in proportion to the wavelengths solved.

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
use crate::transport::render::{render_views, Resolution};
use crate::transport::spherical::Detail;
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

/// Every basis sky's strip of the slices to render (None for a sky with
/// none) and its fog slices to render, solved at the resolution of
/// `quality` and the sky's preset. With `references` (the cache and the
/// fog's ceiling), a sky that renders anything also renders `sky lut
/// verify`'s default references in the same solution into the cache
/// (`references`), unless they are there.
pub(super) fn render_strips(
    plan: &Plan,
    sessions: &[Option<Session>],
    quality: Quality,
    references: Option<(&SliceCache, f64)>,
    tracker: &Mutex<Tracker>,
    cancel: &AtomicBool,
) -> Result<(Vec<Option<StripOutcome>>, Vec<FogRenders>), BakeError> {
    let (mut strips, mut fogs) = (Vec::new(), Vec::new());
    for (k, p) in plan.skies.iter().enumerate() {
        let to_render = p.to_render();
        let fog = &plan.fog[k];
        let Some(session) = sessions[k].as_ref().filter(|_| !to_render.is_empty() || !fog.is_empty()) else {
            strips.push(None);
            fogs.push(FogRenders::new());
            continue;
        };
        if cancel.load(Ordering::SeqCst) {
            return Err(BakeError::Cancelled);
        }
        let sky = p.out.sky.name.clone();
        let views: Vec<&View> = to_render.iter().map(|&i| &p.views[i].as_ref().expect("to render").0).collect();
        let mut all: Vec<View> = if views.is_empty() { Vec::new() } else { vec![strip_view(&views)] };
        all.extend(fog.iter().map(|f| f.view.clone()));
        // `sky lut verify`'s references, if not in the cache: rendered
        // after the slices, priced in with them.
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
            super::references::cached(cache, &key, &views).is_none().then_some((cache, key, views))
        });
        let first_reference = all.len();
        if let Some((_, _, views)) = &verify {
            all.extend(views.iter().cloned());
        }
        let mut slices: Vec<(String, usize, u64)> = Vec::new();
        for (&i, v) in to_render.iter().zip(&views) {
            slices.push((sky.clone(), i, (v.width * v.height) as u64));
        }
        for f in fog {
            slices.push((format!("{sky} (fog)"), f.index, (f.view.width * f.view.height) as u64));
        }
        let texels: u64 = slices.iter().map(|s| s.2).sum();
        let n = slices.len();
        tracker.lock().unwrap().start_queue(QueueJob::new(slices, &vec![0.0; n]), 0);
        let resolution = resolution(quality, &p.out.sampling);
        let wavelengths = crate::transport::render::wavelengths_solved(&session.scene, &resolution);
        let done = AtomicUsize::new(0);
        let on_wavelength = || {
            let d = done.fetch_add(1, Ordering::SeqCst) as u64 + 1;
            let mut t = tracker.lock().unwrap();
            let progress = t.progress(texels * d / wavelengths.max(1) as u64, None);
            t.emit(BakeEvent::Progress(progress));
        };
        let start = Instant::now();
        let mut images = render_views(&session.scene, &all, &resolution, &on_wavelength)
            .map_err(|error| BakeError::Solver { sky: sky.clone(), error })?;
        if let Some((cache, key, _)) = &verify {
            super::references::store(cache, key, &images[first_reference..])?;
        }
        images.truncate(first_reference);
        let mut images = images.into_iter();
        // The cost shared by texels.
        let core_seconds = start.elapsed().as_secs_f64() * rayon::current_num_threads() as f64;
        let per_texel = core_seconds / texels.max(1) as f64;
        let strip = (!views.is_empty()).then(|| images.next().expect("the strip's image"));
        strips.push(strip.map(|image| {
            let core_seconds = per_texel * (image.width * image.height) as f64;
            StripOutcome { image, core_seconds, resumed: 0 }
        }));
        fogs.push(
            fog.iter()
                .zip(images)
                .map(|(f, image)| {
                    let cost = per_texel * (image.width * image.height) as f64;
                    (f.key.clone(), (image, cost))
                })
                .collect(),
        );
        let mut t = tracker.lock().unwrap();
        t.texels_before += texels;
        t.job = None;
    }
    Ok((strips, fogs))
}
