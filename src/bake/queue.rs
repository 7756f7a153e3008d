//! The bake's second room: the queue. Every basis sky's optics prepared
//! once (a [`Session`] each, on one farm), then every slice to render in
//! one queue of farm jobs: each sky's strip of slices (or each slice's
//! grid of multiple scattering), then its fog slices, each job journaled
//! in the cache folder so that a bake killed anywhere resumes from the
//! columns it had. Workers go from slice to slice and from sky to sky and
//! wait only at the end of the queue.

use super::cache::SliceCache;
use super::forecast::Forecasts;
use super::plan::{Plan, Planned};
use super::slices::{strip_view, BakeOptions, Method};
use super::tracker::{QueueJob, Tracker};
use super::{BakeError, BakeEvent};
use crate::mie::MieCache;
use crate::render::{Image, View};
use crate::session::farm::{FarmError, FarmPart};
use crate::session::farm::{Header, Journal};
use crate::session::{OpticsCache, Session, SharedFarm};
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// What the queue rendered, by basis sky (the index of the plan's skies).
pub(super) struct Rendered {
    /// Each sky's strip of slices.
    pub(super) strips: Vec<Option<StripOutcome>>,
    /// With a grid of multiple scattering: each slice's nodes, by slice index.
    pub(super) grids: Vec<BTreeMap<usize, StripOutcome>>,
    /// The fog slices, by cache key: the image and its cost in core-seconds
    /// (taken by the fog's bake as it asks for them).
    pub(super) fog: Vec<Mutex<BTreeMap<String, (Image, f64)>>>,
}

/// Every basis sky's session (optics prepared once, on `farm`) where it has
/// anything to render; None for a sky whose slices are all cached.
pub(super) fn prepare_sessions(
    plan: &Plan,
    optics: &OpticsCache,
    mie: &MieCache,
    farm: &Arc<SharedFarm>,
    tracker: &Mutex<Tracker>,
) -> Vec<Option<Session>> {
    let mut sessions: Vec<Option<Session>> = Vec::new();
    for (p, fog) in plan.skies.iter().zip(&plan.fog) {
        if !p.views.iter().any(Option::is_some) && fog.is_empty() {
            sessions.push(None);
            continue;
        }
        tracker.lock().unwrap().emit(BakeEvent::Preparing { sky: p.out.sky.name.clone() });
        let prep = Instant::now();
        let session = Session::on_farm(
            p.atm.clone(),
            p.bundle.clone(),
            p.out.spectral.clone(),
            optics,
            mie,
            farm.clone(),
            &|| {},
        );
        tracker.lock().unwrap().prep_s += prep.elapsed().as_secs_f64();
        sessions.push(Some(session));
    }
    sessions
}

/// Renders every slice of `plan` that is neither cached nor a repeat, in
/// one queue on `farm`: each sky's strip is one farm job, and a worker done
/// with one sky's columns goes on to the next sky's without waiting for the
/// slowest column of the first.
pub(super) fn render_queue(
    plan: &Plan,
    sessions: &[Option<Session>],
    forecasts: &Forecasts,
    farm: &Arc<SharedFarm>,
    opts: &BakeOptions,
    tracker: &Mutex<Tracker>,
    cancel: &Arc<AtomicBool>,
) -> Result<Rendered, BakeError> {
    let n = plan.skies.len();
    let mut rendered = Rendered {
        strips: (0..n).map(|_| None).collect(),
        grids: (0..n).map(|_| BTreeMap::new()).collect(),
        fog: (0..n).map(|_| Mutex::default()).collect(),
    };
    let (queued, parts) = queue_jobs(plan, sessions, forecasts, (&opts.cache, opts.method))?;
    if parts.is_empty() {
        return Ok(rendered);
    }
    if cancel.load(Ordering::SeqCst) {
        return Err(BakeError::Cancelled);
    }
    {
        let slices: Vec<(String, usize, u64)> = queued
            .iter()
            .flat_map(|q| q.slices.iter().map(|&(i, _)| (q.sky.clone(), i, (q.slice_width * q.view.height) as u64)))
            .collect();
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
            JobKind::Strip => {
                rendered.strips[q.k] = Some(StripOutcome { image, core_seconds: cost, resumed: q.resumed })
            }
            JobKind::Grid(index) => {
                rendered.grids[q.k].insert(*index, StripOutcome { image, core_seconds: cost, resumed: q.resumed });
            }
            JobKind::Fog(key) => {
                rendered.fog[q.k].get_mut().unwrap().insert(key.clone(), (image, cost));
            }
        }
    }
    // The queue's texels and forecast are done; what is left is the
    // work after it, slice by slice, below.
    let mut t = tracker.lock().unwrap();
    t.texels_before += queued.iter().map(|q| (q.view.width * q.view.height) as u64).sum::<u64>();
    t.forecast_done += queued.iter().flat_map(|q| q.slices.iter().map(|s| s.1)).sum::<f64>();
    t.job = None;
    drop(t);
    Ok(rendered)
}

/// The queue's jobs and their farm parts, in order: each basis sky's strip
/// (or its slices' grids, a job each; none by the transport solver, which
/// renders them on this process), then its fog slices, a job each.
fn queue_jobs(
    plan: &Plan,
    sessions: &[Option<Session>],
    forecasts: &Forecasts,
    (cache, method): (&SliceCache, Method),
) -> Result<(Vec<QueuedJob>, Vec<FarmPart>), BakeError> {
    let mut queued: Vec<QueuedJob> = Vec::new();
    let mut parts = Vec::new();
    for (k, p) in plan.skies.iter().enumerate() {
        let Some(session) = &sessions[k] else { continue };
        let sky = p.out.sky.name.clone();
        let to_render = if method == Method::MonteCarlo { p.to_render() } else { Vec::new() };
        if p.grid.is_some() {
            for &i in &to_render {
                let view = p.jobs[i].clone().expect("to render");
                let (part, journal, resumed) = journaled_part(session, &view, cache)?;
                parts.push(part);
                queued.push(QueuedJob {
                    k,
                    sky: sky.clone(),
                    kind: JobKind::Grid(i),
                    slices: vec![(i, forecasts.sky[k][i])],
                    slice_width: view.width,
                    view,
                    journal,
                    resumed,
                });
            }
        } else if !to_render.is_empty() {
            queue_strip(k, p, session, &to_render, &forecasts.sky[k], cache, (&mut queued, &mut parts))?;
        }
        for f in &plan.fog[k] {
            let (part, journal, resumed) = journaled_part(session, &f.view, cache)?;
            parts.push(part);
            let slices = vec![(f.index, forecasts.fog[k][f.index])];
            queued.push(QueuedJob {
                k,
                sky: format!("{sky} (fog)"),
                kind: JobKind::Fog(f.key.clone()),
                slices,
                slice_width: f.view.width,
                view: f.view.clone(),
                journal,
                resumed,
            });
        }
    }
    Ok((queued, parts))
}

/// Queues the strip of the slices `to_render` of sky `k` as one job.
fn queue_strip(
    k: usize,
    p: &Planned,
    session: &Session,
    to_render: &[usize],
    forecasts: &[f64],
    cache: &SliceCache,
    (queued, parts): (&mut Vec<QueuedJob>, &mut Vec<FarmPart>),
) -> Result<(), BakeError> {
    let slice_views: Vec<&View> = to_render.iter().map(|&i| &p.views[i].as_ref().expect("to render").0).collect();
    let strip = strip_view(&slice_views);
    let (part, journal, resumed) = journaled_part(session, &strip, cache)?;
    parts.push(part);
    let slices = to_render.iter().map(|&i| (i, forecasts[i])).collect();
    queued.push(QueuedJob {
        k,
        sky: p.out.sky.name.clone(),
        kind: JobKind::Strip,
        slices,
        slice_width: slice_views[0].width,
        view: strip,
        journal,
        resumed,
    });
    Ok(())
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
pub(super) struct StripOutcome {
    pub(super) image: Image,
    pub(super) core_seconds: f64,
    pub(super) resumed: u32,
}

/// A strip of slices (or a fog slice) as one job of the bake's queue, with its journal in
/// the cache folder: a bake killed mid-strip resumes from the columns it
/// had (the journal goes once the queue is done). Returns the part, the
/// journal's path and the columns taken from it.
fn journaled_part(
    session: &Session,
    view: &View,
    cache: &SliceCache,
) -> Result<(FarmPart, std::path::PathBuf, u32), BakeError> {
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
