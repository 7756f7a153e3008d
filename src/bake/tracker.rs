//! A bake's progress and ETA: the farm's progress of the bake's one queue
//! of jobs turned into the bake's, against the pilots' (or probes')
//! forecast of every slice's core-seconds.
//!
//! Columns taken from the journals of a stopped bake count as done before
//! this run began: the forecast of their texels is not work the farm did
//! at this run's pace (counted in, a resumed bake's first ETA was the
//! journaled share too short, and drifted up as the pace settled).

use super::run::BakeOptions;
use super::{BakeEvent, BakeProgress, BakeSink};
use crate::session::farm::Options;
use crate::session::farm::{EventSink, FarmEvent};
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// Bake-wide progress, updated from the farm's progress of each slice.
pub(super) struct Tracker {
    pub(super) start: Instant,
    pub(super) texels_total: u64,
    pub(super) texels_before: u64,
    pub(super) slices_total: usize,
    pub(super) slices_done: usize,
    /// The slice being rendered (or planned).
    pub(super) current: (String, usize),
    /// The slices being rendered in one queue (one farm render).
    pub(super) job: Option<QueueJob>,
    /// Seconds spent preparing optics and rendering pilots (not the
    /// slices), left out of the rate.
    pub(super) prep_s: f64,
    /// With adaptive sampling, the pilots' forecast: core-seconds of every
    /// slice to render, of those done, and of the current slice.
    pub(super) forecast_total: Option<f64>,
    pub(super) forecast_done: f64,
    pub(super) cores: usize,
    /// Whether `cores` is known: from the start with the embedded worker
    /// alone, else once a farm worker said its threads in its Hello.
    pub(super) cores_known: bool,
    /// Rendering pilots: the farm's progress is not the bake's.
    pub(super) planning: bool,
    /// Texels of the queue taken from the journals of a stopped bake, and
    /// their forecast core-seconds: done before this run began.
    pub(super) resumed_texels: u64,
    pub(super) resumed_forecast: f64,
    pub(super) sink: Option<BakeSink>,
}

impl Tracker {
    /// A bake of `texels_total` texels to render in `slices_total` slices,
    /// `slices_cached` of them in the cache, on `cores` (known from the
    /// start, or from the farm workers' Hello), reporting to `sink`.
    pub(super) fn new(
        (texels_total, slices_total, slices_cached): (u64, usize, usize),
        (cores, cores_known): (usize, bool),
        sink: Option<BakeSink>,
    ) -> Tracker {
        Tracker {
            start: Instant::now(),
            texels_total,
            texels_before: 0,
            slices_total,
            slices_done: slices_cached,
            current: (String::new(), 0),
            job: None,
            prep_s: 0.0,
            forecast_total: None,
            forecast_done: 0.0,
            cores,
            cores_known,
            planning: false,
            resumed_texels: 0,
            resumed_forecast: 0.0,
            sink,
        }
    }

    pub(super) fn emit(&self, e: BakeEvent) {
        if let Some(s) = &self.sink {
            s.emit(&e);
        }
    }

    /// Planning is over (it began at `start`): the forecast of `total`
    /// core-seconds and `samples`, from "pilots" or "probes", `saved` of
    /// them from the cache folder, is the ETA's.
    pub(super) fn forecast(&mut self, from: &'static str, start: Instant, (total, samples): (f64, u64), saved: usize) {
        let planning_s = start.elapsed().as_secs_f64();
        self.prep_s += planning_s;
        self.planning = false;
        self.forecast_total = Some(total);
        // Pilots and probes render on this process's threads.
        self.emit(BakeEvent::Forecast {
            from,
            core_seconds: total,
            samples,
            planning_core_seconds: planning_s * rayon::current_num_threads() as f64,
            saved,
        });
    }

    /// One more pilot or probe (`from`) rendered, of slice `index` of
    /// `sky` (a fog slice's if `fog`): `done` of `total`, planning having
    /// begun at `start`; a pilot's `forecast` of its slice's core-seconds.
    pub(super) fn planned_one(
        &self,
        from: &'static str,
        start: Instant,
        (sky, index, fog): (&str, usize, bool),
        (done, total): (usize, usize),
        forecast: Option<f64>,
    ) {
        let elapsed_s = start.elapsed().as_secs_f64();
        let eta_s = elapsed_s * total.saturating_sub(done) as f64 / done.max(1) as f64;
        self.emit(BakeEvent::Planning {
            from,
            sky: sky.to_string(),
            index,
            fog,
            done,
            total,
            elapsed_s,
            eta_s,
            forecast_core_seconds: forecast,
        });
    }

    /// The queue `job` starts, its first `resumed_texels` taken from the
    /// journals of a stopped bake (the farm hands out and journals columns
    /// from the queue's start, so those are mostly its first texels).
    pub(super) fn start_queue(&mut self, job: QueueJob, resumed_texels: u64) {
        self.current = job.slice_at(0);
        self.resumed_texels = resumed_texels;
        self.resumed_forecast = job.forecast_at(resumed_texels);
        self.job = Some(job);
    }

    /// Progress with `in_job` texels of the current queue done; the slice
    /// they reach becomes the current one.
    pub(super) fn progress(&mut self, in_job: u64, stalled: Option<String>) -> BakeProgress {
        let elapsed_s = self.start.elapsed().as_secs_f64();
        let texels_done = (self.texels_before + in_job).min(self.texels_total);
        let in_forecast = match &self.job {
            Some(j) => {
                self.current = j.slice_at(in_job);
                j.forecast_at(in_job)
            }
            None => 0.0,
        };
        let (sky, index) = self.current.clone();
        // The time this run has rendered (optics preparation and planning
        // left out), and the work it rendered in it: not the journaled.
        let render_s = (elapsed_s - self.prep_s).max(1e-3);
        let eta_s = match self.forecast_total {
            // The forecast's core-seconds still to go, over the cores, and
            // at the pace measured against the forecast so far, the latter
            // trusted in proportion to the share of this run's work done
            // (the pilots time each slice on this machine; the measured
            // pace takes over what they got wrong).
            // (none before the farm's threads are known: the forecast over
            // the one core assumed until then was twice the ETA of a
            // two-worker farm)
            Some(_) if !self.cores_known => None,
            Some(total) if total > 0.0 => {
                let done = (self.forecast_done + in_forecast).min(total);
                let left = total - done;
                let to_render = (total - self.resumed_forecast).max(1e-9);
                let rendered = (done - self.resumed_forecast).max(0.0);
                let share = (rendered / to_render).min(1.0);
                let measured = if rendered > 0.0 { render_s / rendered } else { 0.0 };
                Some(left * ((1.0 - share) / self.cores.max(1) as f64 + share * measured))
            }
            // No forecast: the texel rate, once a hundredth of this run's
            // texels gives it meaning.
            _ => {
                let rendered = texels_done.saturating_sub(self.resumed_texels);
                let to_render = self.texels_total.saturating_sub(self.resumed_texels);
                (rendered * 100 >= to_render && rendered > 0)
                    .then(|| render_s * (self.texels_total - texels_done) as f64 / rendered as f64)
            }
        };
        BakeProgress {
            elapsed_s,
            texels_done,
            texels_total: self.texels_total,
            slices_done: self.slices_done,
            slices_total: self.slices_total,
            eta_s,
            sky,
            index,
            stalled,
        }
    }
}

/// Slices rendered in one queue, in its order: the strips of several basis
/// skies (each strip one farm job), or one fog slice.
pub(super) struct QueueJob {
    /// Each slice's basis sky, index and texels.
    slices: Vec<(String, usize, u64)>,
    /// Texels of the slices before each one, `slices.len() + 1` values.
    cumulative_texels: Vec<u64>,
    /// The forecast of the slices before each one (core-seconds), `slices.len() + 1` values.
    cumulative_forecast: Vec<f64>,
}

impl QueueJob {
    /// The queue of `slices` with their forecast core-seconds.
    pub(super) fn new(slices: Vec<(String, usize, u64)>, forecasts: &[f64]) -> QueueJob {
        let mut cumulative_texels = vec![0];
        let mut cumulative_forecast = vec![0.0];
        for (s, f) in slices.iter().zip(forecasts) {
            cumulative_texels.push(cumulative_texels.last().unwrap() + s.2);
            cumulative_forecast.push(cumulative_forecast.last().unwrap() + f);
        }
        QueueJob { slices, cumulative_texels, cumulative_forecast }
    }

    /// Where `texels` done put the farm in the queue, in slices: the farm
    /// hands out columns from the start, so the texels done are mostly the
    /// first ones (those in flight make this approximate).
    fn position(&self, texels: u64) -> f64 {
        let c = &self.cumulative_texels;
        let k = c.partition_point(|&t| t <= texels).saturating_sub(1).min(self.slices.len() - 1);
        (k as f64 + (texels - c[k].min(texels)) as f64 / self.slices[k].2.max(1) as f64).min(self.slices.len() as f64)
    }

    fn slice_at(&self, texels: u64) -> (String, usize) {
        let (sky, index, _) = &self.slices[(self.position(texels) as usize).min(self.slices.len() - 1)];
        (sky.clone(), *index)
    }

    /// The forecast core-seconds of the queue's texels done.
    fn forecast_at(&self, texels: u64) -> f64 {
        let x = self.position(texels);
        let k = (x as usize).min(self.slices.len() - 1);
        let c = &self.cumulative_forecast;
        c[k] + (x - k as f64) * (c[k + 1] - c[k])
    }
}

/// The farm options of a bake: the caller's, with the farm's events turned
/// into the bake's (progress over the whole bake; the rest tagged with the
/// slice).
pub(super) fn farm_options(opts: &BakeOptions, tracker: &Arc<Mutex<Tracker>>) -> Options {
    let mut farm = opts.farm.clone();
    let t = tracker.clone();
    farm.events = Some(EventSink::new(move |e| {
        let mut t = t.lock().unwrap();
        match e {
            FarmEvent::Progress(_) if t.planning => {}
            FarmEvent::Progress(p) => {
                // The farm's threads, once a worker said its own: what the
                // forecast's core-seconds are shared among, a worker yet to
                // say counted at the others' mean.
                let serving: Vec<usize> =
                    p.workers.iter().filter(|w| w.quarantined.is_none()).map(|w| w.threads).collect();
                let known: Vec<usize> = serving.iter().copied().filter(|&n| n > 0).collect();
                if !known.is_empty() {
                    let sum: usize = known.iter().sum();
                    t.cores = sum + ((serving.len() - known.len()) * sum).div_ceil(known.len());
                    t.cores_known = true;
                }
                let p = t.progress(p.pixels_done, p.stalled.clone());
                t.emit(BakeEvent::Progress(p));
            }
            other => {
                let (sky, index) = t.current.clone();
                t.emit(BakeEvent::Farm { sky, index, farm: other.clone() })
            }
        }
    }));
    farm
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two slices of 100 texels forecast at 50 core-seconds each, on two
    /// cores, the first slice's texels taken from a stopped bake's
    /// journals: `start` and `prep_s` as the bake left them.
    fn resumed_bake(resumed_texels: u64) -> Tracker {
        let mut t = Tracker::new((200, 2, 0), (2, true), None);
        t.forecast_total = Some(100.0);
        t.start_queue(
            QueueJob::new(vec![("clear".into(), 0, 100), ("clear".into(), 1, 100)], &[50.0, 50.0]),
            resumed_texels,
        );
        t
    }

    /// The journaled half of a resumed bake is done before the run began:
    /// its first ETA is the other half's forecast over the cores, not that
    /// shortened by a pace of "50 core-seconds in no time" (12.5 s, half
    /// the 25 s the slice takes on two cores, before the fix).
    #[test]
    fn journaled_columns_are_not_this_runs_pace() {
        let mut t = resumed_bake(100);
        let eta_s = t.progress(100, None).eta_s.unwrap();
        assert!((eta_s - 25.0).abs() < 0.1, "first ETA of a resumed bake {eta_s} s, the forecast 25 s");
        // Half of this run's work, 25 core-seconds, rendered in 25 s: half
        // the forecast's pace on two cores. The other half at the
        // forecast's pace and the measured one, trusted half each:
        // 25 × (0.5 / 2 + 0.5 × 25 / 25) = 18.75 s.
        t.prep_s = t.start.elapsed().as_secs_f64() - 25.0;
        let eta_s = t.progress(150, None).eta_s.unwrap();
        assert!((eta_s - 18.75).abs() < 0.1, "{eta_s}");
        // With nothing journaled the same texels are half the bake.
        let mut fresh = resumed_bake(0);
        fresh.prep_s = fresh.start.elapsed().as_secs_f64() - 25.0;
        let eta_s = fresh.progress(100, None).eta_s.unwrap();
        assert!((eta_s - 50.0 * (0.5 / 2.0 + 0.5 * 0.5)).abs() < 0.1, "{eta_s}");
    }

    /// Without a forecast the ETA is the texel rate of this run alone.
    #[test]
    fn a_resumed_bake_without_a_forecast_counts_its_own_texel_rate() {
        let mut t = resumed_bake(100);
        t.forecast_total = None;
        assert_eq!(t.progress(100, None).eta_s, None, "no texel rendered yet, no rate");
        t.prep_s = t.start.elapsed().as_secs_f64() - 10.0;
        let eta_s = t.progress(150, None).eta_s.unwrap();
        assert!((eta_s - 10.0).abs() < 0.1, "50 texels in 10 s, 50 to go: {eta_s}");
    }
}
