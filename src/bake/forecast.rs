//! A bake's forecast of its cost, before the first slice renders: what
//! its ETA rests on. With adaptive sampling, every slice's pilot (its
//! texels at the pilot's 32 samples) plans the samples each texel will
//! take, and its time with that of a one-sample render, the cost; each
//! pilot's forecast is saved in the cache folder for a bake run again.
//! With a fixed sample count (a draft), a few probe slices at a sixteenth
//! of their texels are timed and the rest interpolated.

use super::cache::SliceCache;
use super::file::BakeFile;
use super::fog::FogTodo;
use super::ms_grid::MsGrid;
use super::run::{slice_view, Planned};
use super::tracker::Tracker;
use super::BakeError;
use crate::render::{adaptive, Image, Scene, View, ADAPTIVE_PILOT_SPP};
use crate::session::Session;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;
use std::time::Instant;

/// What each slice will cost, core-seconds, by basis sky and slice index:
/// its render in the bake's queue, the sky's and the fog's, and the work
/// on the bake's own machine after the queue (single scattering by
/// quadrature: a grid's resampling, the Fog from its Shadowed Fog).
pub(super) struct Forecasts {
    pub(super) sky: Vec<Vec<f64>>,
    pub(super) fog: Vec<Vec<f64>>,
    pub(super) sky_after: Vec<Vec<f64>>,
    pub(super) fog_after: Vec<Vec<f64>>,
}

impl Forecasts {
    /// All zero: no slice of `plan` forecast yet.
    pub(super) fn zero(plan: &[Planned]) -> Forecasts {
        let zero: Vec<Vec<f64>> = plan.iter().map(|p| vec![0.0; p.views.len()]).collect();
        Forecasts { sky: zero.clone(), fog: zero.clone(), sky_after: zero.clone(), fog_after: zero }
    }

    /// The forecasts of slice `index` of basis sky `k`, core-seconds, in the
    /// queue and after it: its fog slice's with `fog`, else the sky's.
    fn slice_mut(&mut self, k: usize, index: usize, fog: bool) -> (&mut f64, &mut f64) {
        if fog {
            (&mut self.fog[k][index], &mut self.fog_after[k][index])
        } else {
            (&mut self.sky[k][index], &mut self.sky_after[k][index])
        }
    }
}

/// What the phases of [`forecast`] read: the plan of every basis sky, sky
/// and fog, the sessions they render through, the bake, the cache folder
/// of saved pilots, the tracker of planning's progress, and whether the
/// bake was cancelled.
struct Inputs<'a> {
    plan: &'a [Planned],
    fog_plan: &'a [Vec<FogTodo>],
    sessions: &'a [Option<Session>],
    bake: &'a BakeFile,
    cache: &'a SliceCache,
    tracker: &'a Mutex<Tracker>,
    cancel: &'a AtomicBool,
}

impl<'a> Inputs<'a> {
    /// Every view of basis sky `k` to render once: its slice index, the
    /// view, and whether it is a fog slice's.
    fn to_forecast(&self, k: usize) -> impl Iterator<Item = (usize, &'a View, bool)> + 'a {
        let p = &self.plan[k];
        let sky = p
            .jobs
            .iter()
            .enumerate()
            .filter(move |&(i, _)| p.same_as[i].is_none())
            .filter_map(|(i, v)| v.as_ref().map(|v| (i, v, false)));
        sky.chain(self.fog_plan[k].iter().map(|f| (f.index, &f.view, true)))
    }

    /// Every view of every basis sky to render once (see [`Inputs::to_forecast`]).
    fn all_to_forecast(&self) -> impl Iterator<Item = (usize, &'a View, bool)> + '_ {
        (0..self.plan.len()).flat_map(|k| self.to_forecast(k))
    }
}

/// The forecast of every slice of `plan` to render, sky and fog
/// (`fog_plan`), through each basis sky's session; saved pilots taken
/// from, and new ones saved to, `cache`; planning's progress reported to
/// `tracker`. All zero where nothing is worth forecasting (fewer than
/// [`MIN_SLICES_TO_PROBE`] slices at a fixed sample count).
pub(super) fn forecast(
    plan: &[Planned],
    fog_plan: &[Vec<FogTodo>],
    sessions: &[Option<Session>],
    bake: &BakeFile,
    (cache, tracker): (&SliceCache, &Mutex<Tracker>),
    cancel: &AtomicBool,
) -> Result<Forecasts, BakeError> {
    let inputs = Inputs { plan, fog_plan, sessions, bake, cache, tracker, cancel };
    // Zero until a phase forecasts it: from pilots (adaptive sampling) or
    // from probes (a fixed sample count).
    let mut forecasts = Forecasts::zero(plan);
    if inputs.all_to_forecast().any(|(_, v, _)| pilot_view(v).is_some()) {
        forecast_from_pilots(&inputs, &mut forecasts)?;
    } else if inputs.all_to_forecast().count() >= MIN_SLICES_TO_PROBE {
        forecast_from_probes(&inputs, &mut forecasts)?;
    }
    Ok(forecasts)
}

/// Adaptive sampling: each view's forecast from its pilot, saved in the
/// cache folder, or rendered and timed here and saved there, into
/// `forecasts`.
fn forecast_from_pilots(inputs: &Inputs, forecasts: &mut Forecasts) -> Result<(), BakeError> {
    let Inputs { plan, sessions, bake, cache, tracker, cancel, .. } = *inputs;
    let start = Instant::now();
    tracker.lock().unwrap().planning = true;
    let (mut total, mut samples) = (0.0, 0u64);
    let pilots = (0..plan.len())
        .filter(|&k| sessions[k].is_some())
        .flat_map(|k| inputs.to_forecast(k))
        .filter(|(_, v, _)| pilot_view(v).is_some())
        .count();
    let (mut piloted, mut pilots_saved) = (0, 0);
    for (k, p) in plan.iter().enumerate() {
        let Some(session) = &sessions[k] else { continue };
        for (index, view, fog) in inputs.to_forecast(k) {
            let Some(pilot) = pilot_view(view) else { continue };
            if cancel.load(Ordering::SeqCst) {
                return Err(BakeError::Cancelled);
            }
            tracker.lock().unwrap().current = (p.out.sky.name.clone(), index);
            // What the pilot's quadrature times: a grid slice's own view,
            // or the Fog LUT's size.
            let grid_slice = p.grid.filter(|_| !fog).map(|_| &p.views[index].as_ref().expect("to render").0);
            let key = pilot_key(
                &session.job(&pilot).hash,
                &serde_json::json!({ "grid_slice": grid_slice, "fog_lut": fog.then_some([bake.fog.width, bake.fog.height]) }),
            );
            let saved = cache.get_value::<PilotForecast>(&key, "pilot");
            pilots_saved += saved.is_some() as usize;
            let forecast = match saved {
                Some(saved) => saved,
                None => {
                    let after = match (fog, p.grid, grid_slice) {
                        (true, ..) => AfterQueue::Fog { lut_texels: bake.fog.width * bake.fog.height },
                        (false, Some(grid), Some(slice)) => AfterQueue::Grid(grid, slice),
                        _ => AfterQueue::Nothing,
                    };
                    let forecast = pilot_forecast(&session.scene, view, &pilot, after, cancel)?;
                    cache.put_value(&key, "pilot", &forecast)?;
                    forecast
                }
            };
            let (f, after) = forecasts.slice_mut(k, index, fog);
            *f = forecast.queue_core_seconds;
            *after = forecast.after_queue_core_seconds;
            total += *f + *after;
            samples += forecast.samples;
            piloted += 1;
            tracker.lock().unwrap().planned_one(
                "pilots",
                start,
                (&p.out.sky.name, index, fog),
                (piloted, pilots),
                Some(*f + *after),
            );
        }
    }
    tracker.lock().unwrap().forecast("pilots", start, (total, samples), pilots_saved);
    Ok(())
}

/// A fixed sample count (a draft): every texel takes the same samples,
/// but a texel's cost differs from sky to sky (a cloudy texel costs 6
/// times a clear one) and with the sun (twilight paths are longer).
/// Probes of a few slices at a sixteenth of their texels time it
/// ([`probe_slice`]); the other slices' cost per texel is interpolated in
/// the slice index, into `forecasts`.
fn forecast_from_probes(inputs: &Inputs, forecasts: &mut Forecasts) -> Result<(), BakeError> {
    let Inputs { plan, fog_plan, sessions, bake, tracker, cancel, .. } = *inputs;
    let start = Instant::now();
    tracker.lock().unwrap().planning = true;
    let (mut total, mut samples) = (0.0, 0u64);
    // The probes to render: a sky's, and its fog's, at each of
    // PROBE_SLICES that it has.
    let has_probes =
        |k: usize, fog: bool| if fog { !fog_plan[k].is_empty() } else { plan[k].views.iter().any(Option::is_some) };
    let probes: usize = (0..plan.len())
        .filter(|&k| sessions[k].is_some())
        .map(|k| {
            [false, true].into_iter().filter(|&fog| has_probes(k, fog)).count()
                * PROBE_SLICES.iter().filter(|&&i| i < plan[k].out.sky.slices).count()
        })
        .sum();
    let mut probed = 0;
    for (k, p) in plan.iter().enumerate() {
        let Some(session) = &sessions[k] else { continue };
        let sky = &p.out.sky;
        // The sky's probes, then the fog's.
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
                let cost = probe_slice(&session.scene, p, bake, (index, fog), cancel)?;
                per_slice_fixed.push((index, cost.fixed_core_s));
                per_slice_after.push((index, cost.after_queue_core_s));
                per_texel.push((index, cost.per_texel_core_s));
                probed += 1;
                tracker.lock().unwrap().planned_one("probes", start, (&sky.name, index, fog), (probed, probes), None);
            }
            for (index, view, is_fog) in inputs.to_forecast(k).filter(|v| v.2 == fog) {
                let texels = (view.width * view.height) as f64;
                let (f, after) = forecasts.slice_mut(k, index, is_fog);
                *f = interpolate(&per_slice_fixed, index) + texels * interpolate(&per_texel, index);
                *after = interpolate(&per_slice_after, index);
                total += *f + *after;
                samples += texels as u64 * view.spp as u64;
            }
        }
    }
    tracker.lock().unwrap().forecast("probes", start, (total, samples), 0);
    Ok(())
}

/// What a probe of one slice measured, core-seconds: the part of its
/// render per render, the part per texel, and the quadrature after the
/// queue for the whole slice.
struct ProbeCost {
    fixed_core_s: f64,
    per_texel_core_s: f64,
    after_queue_core_s: f64,
}

/// Renders and times here the probe of slice `index` of `p` (its fog
/// slice's with `fog`). A sky slice's probe is its view at a quarter of
/// its size each way, or, from a grid, every PROBE_STRIDE²-th node, with
/// the quadrature at every texel timed on a quarter of them; a fog
/// slice's is the Fog LUT's directions at a quarter of its size each
/// way, and its texels' cost adds the quadrature's.
fn probe_slice(
    scene: &Scene,
    p: &Planned,
    bake: &BakeFile,
    (index, fog): (usize, bool),
    cancel: &AtomicBool,
) -> Result<ProbeCost, BakeError> {
    let sky = &p.out.sky;
    let mut grid_quadrature = 0.0;
    let probe = if fog {
        let f = &bake.fog;
        let smaller = super::file::FogSettings {
            width: (f.width / PROBE_STRIDE).max(1),
            height: (f.height / PROBE_STRIDE).max(1),
            ..*f
        };
        super::fog::fog_view(sky, &smaller, &p.out.sampling, index, p.out.radius_km, p.out.top_km, true)
    } else {
        let full = slice_view(sky, &p.out.sampling, index, p.out.radius_km, p.out.top_km, p.out.threshold_deg);
        let smaller = View {
            width: (full.width / PROBE_STRIDE).max(1),
            height: (full.height / PROBE_STRIDE).max(1),
            ..full.clone()
        };
        match p.grid {
            Some(g) => {
                // (the texels' quadrature timed on the probe's texels, the
                // nodes' on the slice's own)
                let texels_quadrature = super::ms_grid::time_single(scene, &smaller)
                    * (full.width * full.height) as f64
                    / (smaller.width * smaller.height) as f64;
                grid_quadrature = texels_quadrature + g.time_nodes_quadrature(scene, &full);
                g.probe_view(&full, PROBE_STRIDE * PROBE_STRIDE)
            }
            None => smaller,
        }
    };
    // Rendered here, on this process's threads, in one piece: on the farm
    // a probe's few columns would go out as several small tasks, each
    // preparing the tracers and guides of its sun again, a cost the
    // slices' large tasks spread thin (the forecast came out 43 % high).
    // The rest of a render's cost per render, not per texel, a one-texel
    // render of the same view measures.
    let timed = |v: &View| timed_here(scene, v, cancel).map(|(_, core_s, _)| core_s);
    let fixed = timed(&View { width: 1, height: 1, ..probe.clone() })?;
    let texels = (probe.width * probe.height) as f64;
    let whole = timed(&probe)?;
    // A fog slice's quadrature, timed on its probe, for the whole slice
    // (every fog slice has the Fog LUT's size).
    let fog_quadrature = if fog {
        super::fog::time_quadrature(scene, &probe) * (bake.fog.width * bake.fog.height) as f64 / texels
    } else {
        0.0
    };
    Ok(ProbeCost {
        fixed_core_s: fixed,
        per_texel_core_s: ((whole - fixed) / (texels - 1.0).max(1.0)).max(0.0),
        after_queue_core_s: grid_quadrature + fog_quadrature,
    })
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
    pilot
        .pixels
        .iter()
        .map(|p| {
            if p.samples == 0 {
                0
            } else {
                ADAPTIVE_PILOT_SPP + adaptive::samples_for(p.xyz[1], p.xyz_stderr[1], p.samples as f64, target, left)
            }
        })
        .collect()
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
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .or_else(|_| std::env::var("COMPUTERNAME"))
        .unwrap_or_default();
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
fn pilot_forecast(
    scene: &Scene,
    view: &View,
    pilot: &View,
    after: AfterQueue,
    cancel: &AtomicBool,
) -> Result<PilotForecast, BakeError> {
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
    let planned_cost =
        sample_weighted(&planned, &pilot_pixel_s, &one_pixel_s) * sampling_core_s / (ADAPTIVE_PILOT_SPP - 1) as f64;
    let fixed = (one_core_s - sampling_core_s / (ADAPTIVE_PILOT_SPP - 1) as f64).max(0.0);
    let after_queue_core_seconds = match after {
        AfterQueue::Fog { lut_texels } => {
            super::fog::time_quadrature(scene, view) * lut_texels as f64 / (view.width * view.height) as f64
        }
        AfterQueue::Grid(grid, slice) => grid.time_quadrature(scene, slice),
        AfterQueue::Nothing => 0.0,
    };
    Ok(PilotForecast {
        queue_core_seconds: fixed + planned_cost,
        after_queue_core_seconds,
        samples: planned.iter().map(|&n| n as u64).sum(),
    })
}

/// Renders `view` on this process's threads in one piece: its image, its
/// cost in core-seconds (the wall time times the threads) and each pixel's
/// seconds on its thread. How pilots and probes are timed: on a farm a
/// small view's few columns would go out as several small tasks, each
/// preparing its sun's tracers and guides again.
fn timed_here(scene: &Scene, view: &View, cancel: &AtomicBool) -> Result<(Image, f64, Vec<f64>), BakeError> {
    let start = Instant::now();
    let (image, pixel_s) =
        crate::render::render_timed(scene, view, cancel, &|| {}).map_err(|_| BakeError::Cancelled)?;
    Ok((image, start.elapsed().as_secs_f64() * rayon::current_num_threads() as f64, pixel_s))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bake::file::Sampling;
    use crate::bake::run::tests::test_sky;
    use crate::render::render;

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
        let sampling = Sampling {
            band_nm: 40.0,
            spp: 400,
            max_rel_error: Some(0.05),
            ms_grid: None,
            fog_ms_size: None,
            streams: None,
        };
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
        assert!(
            pilot_view(&View { max_rel_error: None, ..slice_view(&sky, &sampling, 0, 6371.0, 100.0, 87.5) }).is_none()
        );
    }
}
