//! The bake's third room: finishing each basis sky once the queue is done.
//! Its slices cut from the strip the queue rendered (or resampled from
//! their grids), put into the cache and reported; the slices that repeat
//! an earlier view copied; the sun's transmittance and sunlight; the
//! global-fog LUTs from the fog slices the queue rendered.

use super::cache::RenderedSlice;
use super::file::BakeFile;
use super::fog::FogTodo;
use super::forecast::Forecasts;
use super::lighting::{lighting_key, SkyLighting};
use super::ms_grid::MsGrid;
use super::plan::Planned;
use super::queue::{Rendered, StripOutcome};
use super::slices::{cached_slice, slice_of_image, slice_of_strip, BakeOptions, SkySlices};
use super::tracker::Tracker;
use super::{BakeError, BakeEvent};
use crate::atmosphere::Atmosphere;
use crate::directions::mapping;
use crate::mie::MieCache;
use crate::render::{Image, View};
use crate::session::OpticsCache;
use std::collections::BTreeMap;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// What finishing a basis sky needs of the bake around it.
pub(super) struct Finisher<'a> {
    pub(super) bake: &'a BakeFile,
    pub(super) opts: &'a BakeOptions,
    pub(super) mie: &'a MieCache,
    pub(super) optics: &'a OpticsCache,
    pub(super) tracker: &'a Mutex<Tracker>,
    pub(super) forecasts: &'a Forecasts,
    pub(super) cancel: &'a Arc<AtomicBool>,
}

/// A basis sky's views, by slice index: the view and cache key of each
/// slice the queue rendered.
type Views = [Option<(View, String)>];

impl Finisher<'_> {
    /// Basis sky `k` of the plan, finished: every slice it asked for, its
    /// lighting and fog (a whole bake's), with events as it goes.
    pub(super) fn finish_sky(
        &self,
        k: usize,
        p: Planned,
        fog_plan: &[FogTodo],
        rendered: &mut Rendered,
    ) -> Result<SkySlices, BakeError> {
        let texels_of_job = p.job_texels();
        let todo = p.to_render();
        let Planned { mut out, views, same_as, grid, atm, .. } = p;
        let name = out.sky.name.clone();
        for (index, s) in out.slices.iter().enumerate() {
            if let Some(s) = s {
                self.tracker.lock().unwrap().emit(cached_slice(&name, index, s));
            }
        }
        let mut sky_core_seconds = 0.0;
        // The slices rendered now: from the sky's strip, or each from its grid.
        let mut now: Vec<(usize, RenderedSlice)> = Vec::new();
        if let Some(strip) = rendered.strips[k].take() {
            sky_core_seconds += slices_of_strip(strip, &todo, &mut out, &views, &mut now)?;
        }
        if let Some(g) = grid.filter(|_| !rendered.grids[k].is_empty()) {
            let grids = std::mem::take(&mut rendered.grids[k]);
            sky_core_seconds += self.slices_of_grids(&g, grids, &atm, &mut out, &views, &mut now)?;
        }
        if !now.is_empty() {
            self.store(k, now, &mut out, &views)?;
        }
        self.copy_repeats(&same_as, &texels_of_job, &mut out);
        if out.rendered > 0 {
            let mut t = self.tracker.lock().unwrap();
            let p = t.progress(0, None);
            t.emit(BakeEvent::Progress(p));
        }
        if self.opts.only.is_none() {
            out.lighting = Some(self.lighting(&out, &atm)?);
        }
        if self.opts.only.is_none() || !fog_plan.is_empty() {
            self.fog(k, &mut out, &atm, fog_plan, &rendered.fog[k])?;
        }
        if out.slices.iter().any(Option::is_some) {
            self.tracker.lock().unwrap().emit(BakeEvent::SkyDone {
                sky: name,
                slices_rendered: out.rendered,
                slices_cached: out.cached,
                core_seconds: sky_core_seconds,
            });
        }
        Ok(out)
    }

    /// Each texel its single scattering plus the nodes' multiple
    /// scattering, on this process's threads (timed into the slice's
    /// cost). Returns the core-seconds.
    fn slices_of_grids(
        &self,
        g: &MsGrid,
        grids: BTreeMap<usize, StripOutcome>,
        atm: &Atmosphere,
        out: &mut SkySlices,
        views: &Views,
        now: &mut Vec<(usize, RenderedSlice)>,
    ) -> Result<f64, BakeError> {
        let name = out.sky.name.clone();
        let mut sky_core_seconds = 0.0;
        let scene = self.optics.get(atm, &out.spectral, self.mie, &|| {});
        let threads = rayon::current_num_threads() as f64;
        for (index, StripOutcome { image, core_seconds, resumed }) in grids {
            let (view, _) = views[index].as_ref().expect("to render");
            let start = Instant::now();
            let texels = g.resample(&image, &scene, view);
            let cost = core_seconds + start.elapsed().as_secs_f64() * threads;
            out.columns_resumed += resumed;
            sky_core_seconds += cost;
            now.push((index, slice_of_image(&texels, view, &name, index, cost)?));
        }
        Ok(sky_core_seconds)
    }

    /// The slices rendered now into the cache and the sky, each reported.
    fn store(
        &self,
        k: usize,
        now: Vec<(usize, RenderedSlice)>,
        out: &mut SkySlices,
        views: &Views,
    ) -> Result<(), BakeError> {
        let (forecasts, after_queue) = (&self.forecasts.sky, &self.forecasts.sky_after);
        for (index, slice) in now {
            let (view, key) = views[index].as_ref().expect("to render");
            self.opts.cache.put(key, &slice)?;
            let mut t = self.tracker.lock().unwrap();
            t.slices_done += 1;
            t.forecast_done += after_queue[k][index];
            let forecast = forecasts[k][index] + after_queue[k][index];
            let forecast_core_seconds = t.forecast_total.map(|_| forecast);
            t.emit(BakeEvent::Slice {
                sky: out.sky.name.clone(),
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
        Ok(())
    }

    /// The same view as an earlier slice: rendered once, copied here.
    fn copy_repeats(&self, same_as: &[Option<usize>], texels_of_job: &[u64], out: &mut SkySlices) {
        for (index, first) in same_as.iter().enumerate() {
            let Some(first) = *first else { continue };
            let slice = out.slices[first].clone();
            let mut t = self.tracker.lock().unwrap();
            t.texels_before += texels_of_job[index];
            t.slices_done += 1;
            if let Some(s) = &slice {
                t.emit(cached_slice(&out.sky.name, index, s));
            }
            drop(t);
            out.slices[index] = slice;
            out.cached += 1;
        }
    }

    /// The sun's transmittance and sunlight, from the cache or from the
    /// sky's optics (prepared now if no slice needed them).
    fn lighting(&self, out: &SkySlices, atm: &Atmosphere) -> Result<SkyLighting, BakeError> {
        let zeniths: Vec<f64> =
            (0..out.sky.slices).map(|i| mapping::slice_sun_zenith_deg(i, out.radius_km, out.top_km)).collect();
        let key = lighting_key(&out.atmosphere_hash, &out.spectral, out.sky.altitude_m, &zeniths);
        Ok(match self.opts.cache.get_lighting(&key) {
            Some(l) => l,
            None => {
                let scene = self.optics.get(atm, &out.spectral, self.mie, &|| {});
                let l = SkyLighting::compute(&scene, out.sky.altitude_m, &zeniths);
                self.opts.cache.put_lighting(&key, &l)?;
                l
            }
        })
    }

    /// The global-fog LUTs from their slices rendered in the queue (or
    /// cached): a whole bake's, or the fog slices `only` names, into the
    /// cache.
    fn fog(
        &self,
        k: usize,
        out: &mut SkySlices,
        atm: &Atmosphere,
        fog_plan: &[FogTodo],
        queued_fog: &Mutex<BTreeMap<String, (Image, f64)>>,
    ) -> Result<(), BakeError> {
        let (opts, tracker, name) = (self.opts, self.tracker, out.sky.name.clone());
        let scene = self.optics.get(atm, &out.spectral, self.mie, &|| {});
        let on_slice = |done: usize, total: usize| {
            tracker.lock().unwrap().emit(BakeEvent::FogSlice { sky: name.clone(), done, total })
        };
        let fog_after_queue = &self.forecasts.fog_after;
        let (atmosphere_hash, spectral) = (out.atmosphere_hash.clone(), out.spectral.clone());
        let sampling = out.sampling.clone();
        // The slice as the queue rendered it (every fog slice not in the
        // cache was queued; a second slice of the same view, with the
        // cache off, gets the image at no cost). One that is neither
        // left the cache during the bake: an error.
        let render = |view: &View, index: usize| -> Result<(Image, f64), BakeError> {
            let key =
                super::fog::fog_slice_key(&atmosphere_hash, &spectral, view, (opts.quality, opts.method), &sampling);
            let queued =
                queued_fog.lock().unwrap().get_mut(&key).map(|(image, cost)| (image.clone(), std::mem::take(cost)));
            let (image, cost) = queued.ok_or_else(|| BakeError::FogSliceLost {
                sky: name.clone(),
                index,
                cache: opts.cache.dir().to_path_buf(),
            })?;
            let mut t = tracker.lock().unwrap();
            t.slices_done += 1;
            t.forecast_done += fog_after_queue[k][index];
            let p = t.progress(0, None);
            t.emit(BakeEvent::Progress(p));
            Ok((image, cost))
        };
        if opts.only.is_some() {
            for (j, f) in fog_plan.iter().enumerate() {
                let (image, cost) = render(&f.view, f.index)?;
                let slice = slice_of_image(&image, &f.view, &format!("{name} (shadowed fog)"), f.index, cost)?;
                opts.cache.put(&f.key, &slice)?;
                out.fog_rendered.push((f.index, slice));
                on_slice(j + 1, fog_plan.len());
            }
        } else {
            let job = super::fog::FogJob {
                sky: &out.sky,
                atmosphere: atm,
                scene: &scene,
                sampling: &out.sampling,
                settings: self.bake.fog,
                quality: opts.quality,
                method: opts.method,
            };
            let fog = super::fog::bake_fog(&job, &opts.cache, self.cancel, &render, &on_slice)?;
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
        Ok(())
    }
}

/// The slices `todo` cut from the sky's strip, the strip's cost shared by
/// the slices in proportion to their samples. Returns the core-seconds.
fn slices_of_strip(
    StripOutcome { image, core_seconds, resumed }: StripOutcome,
    todo: &[usize],
    out: &mut SkySlices,
    views: &Views,
    now: &mut Vec<(usize, RenderedSlice)>,
) -> Result<f64, BakeError> {
    let (w, h) = (out.sky.width, out.sky.height);
    out.columns_resumed += resumed;
    let samples: Vec<u64> = (0..todo.len())
        .map(|j| {
            (0..h)
                .flat_map(|y| &image.pixels[y * image.width + j * w..y * image.width + (j + 1) * w])
                .map(|p| p.samples as u64)
                .sum()
        })
        .collect();
    let all_samples = samples.iter().sum::<u64>().max(1) as f64;
    for (j, &index) in todo.iter().enumerate() {
        let (view, _) = views[index].as_ref().expect("to render");
        let cost = core_seconds * samples[j] as f64 / all_samples;
        now.push((index, slice_of_strip(&image, j * w, view, &out.sky.name, index, cost)?));
    }
    Ok(core_seconds)
}
