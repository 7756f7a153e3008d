//! The coordinator: splits an image into pixel columns, hands batches of
//! adjacent columns to workers (sized by each worker's measured speed),
//! and gathers their tiles, surviving workers that vanish, stall, pause or
//! send garbage. The decisions (assignment, leases, duplicates,
//! verification, quarantine) are the [`super::scheduler`]'s; the wire is
//! the [`super::transport`]'s; this module drives one loop per worker over
//! them, with the clock, and keeps the workers' connections across the
//! renders of a session ([`Farm`]).
//!
//! - Every tile is checked (job hash, columns, size, finite non-negative
//!   values) before it is accepted, and accepted columns go to the journal.
//! - Thresholds (the defaults farm managers ship): a column that fails on
//!   3 different workers fails the render with a report; a worker that
//!   fails 3 tasks, or refuses the job (versions, token), is quarantined.
//!
//! The embedded local worker goes through the same scheduler, so a local
//! render and a farm render are the same code path and bit-identical.

use super::events::{self, EventSink, FarmEvent, Progress};
pub use super::job::FarmJob;
use super::journal::Journal;
use super::proto;
use super::protocol::TaskError;
use super::scheduler::{Assign, PartInit, Sched, Stop, WState};
pub use super::scheduler::{FarmError, Outcome, PartsOutcome, Stats, Traffic, WorkerStats};
use super::tile;
use super::transport::Backend;
pub use super::transport::{connect, Auth};
use crate::render::PixelResult;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::sync::Notify;
use tonic::transport::ClientTlsConfig;

/// Where a worker is.
#[derive(Debug, Clone)]
pub enum WorkerSpec {
    /// The embedded worker: this process's cores.
    Local { threads: usize },
    /// A `sky worker` daemon at `uri` (http://host:port or https://…),
    /// named by the farm file, or (None) by the worker itself.
    Remote { name: Option<String>, uri: String },
}

impl WorkerSpec {
    pub fn name(&self) -> String {
        match self {
            WorkerSpec::Local { .. } => "local".into(),
            WorkerSpec::Remote { name, uri } => name.clone().unwrap_or_else(|| address_of(uri)),
        }
    }

    pub fn address(&self) -> String {
        match self {
            WorkerSpec::Local { .. } => "local".into(),
            WorkerSpec::Remote { uri, .. } => address_of(uri),
        }
    }
}

fn address_of(uri: &str) -> String {
    uri.trim_start_matches("http://").trim_start_matches("https://").trim_end_matches('/').to_string()
}

/// Farm policy.
#[derive(Debug, Clone)]
pub struct Options {
    /// A task whose worker sends nothing for this long is re-queued.
    pub lease: Duration,
    /// Tasks are sized to take about this long on their worker.
    pub task_seconds: f64,
    /// The most columns in one task.
    pub max_batch: u32,
    /// Fraction of columns rendered twice on different workers and compared.
    pub verify_fraction: f64,
    /// A column failed by this many different workers fails the render.
    pub max_column_failures: usize,
    /// A worker failing this many tasks is quarantined for the job.
    pub max_worker_failures: usize,
    pub token: Option<String>,
    pub tls: Option<ClientTlsConfig>,
    /// Where progress and worker events go (none: silent).
    pub events: Option<EventSink>,
    /// How often progress is reported.
    pub progress_period: Duration,
    /// Faults to commit, for the farm's tests.
    pub faults: super::faults::CoordinatorFaults,
}

impl Default for Options {
    fn default() -> Options {
        Options {
            lease: Duration::from_secs(20),
            task_seconds: 5.0,
            max_batch: 64,
            verify_fraction: 0.0,
            max_column_failures: 3,
            max_worker_failures: 3,
            token: None,
            tls: None,
            events: None,
            progress_period: Duration::from_secs(1),
            faults: Default::default(),
        }
    }
}

struct Shared {
    sched: Mutex<Sched>,
    changed: Notify,
    cancel: Arc<AtomicBool>,
    /// The render's start: the scheduler's clock reads `epoch.elapsed()`.
    epoch: Instant,
}

impl Shared {
    fn now(&self) -> Duration {
        self.epoch.elapsed()
    }
}

/// Renders `job` across `workers` once: a [`Farm`] for one render.
pub async fn run(
    job: Arc<FarmJob>,
    workers: Vec<WorkerSpec>,
    resumed: BTreeMap<u32, proto::Tile>,
    journal: Option<Journal>,
    opts: Options,
    cancel: Arc<AtomicBool>,
) -> Result<Outcome, FarmError> {
    Farm::new(workers).render(job, resumed, journal, &opts, cancel).await
}

/// A coordinator's workers, kept across the renders (views) of a session:
/// the connections (greeted once, polled again only while paused), the
/// optics each worker holds as far as the coordinator knows, names from
/// the workers' Hello, the embedded worker's threads, and quarantines (a
/// worker quarantined in one view stays out of the later ones).
pub struct Farm {
    slots: Vec<Slot>,
}

struct Slot {
    spec: WorkerSpec,
    /// None until the first render, and while a render holds it.
    backend: Option<Backend>,
    name: String,
    quarantined: Option<String>,
}

impl Farm {
    pub fn new(workers: Vec<WorkerSpec>) -> Farm {
        Farm {
            slots: workers
                .into_iter()
                .map(|spec| Slot { name: spec.name(), spec, backend: None, quarantined: None })
                .collect(),
        }
    }

    /// Renders `job` (the embedded worker renders with the job's prepared
    /// scene, remote ones get its optics when they lack them); `resumed`
    /// holds columns from a journal; `journal`, if any, receives every
    /// newly accepted column. `cancel` stops the render (the journal stays).
    pub async fn render(
        &mut self,
        job: Arc<FarmJob>,
        resumed: BTreeMap<u32, proto::Tile>,
        journal: Option<Journal>,
        opts: &Options,
        cancel: Arc<AtomicBool>,
    ) -> Result<Outcome, FarmError> {
        let mut out = self.render_parts(vec![FarmPart { job, resumed, journal }], opts, cancel).await?;
        Ok(Outcome { columns: out.parts.pop().expect("one part"), stats: out.stats })
    }

    /// Renders several jobs (each its own optics and view) in one queue of
    /// columns, in their order: a worker done with the columns of one job
    /// goes on to the next without waiting for the slowest column of the
    /// first, and gets each job's optics only if it lacks them.
    pub async fn render_parts(
        &mut self,
        parts: Vec<FarmPart>,
        opts: &Options,
        cancel: Arc<AtomicBool>,
    ) -> Result<PartsOutcome, FarmError> {
        let jobs: Vec<Arc<FarmJob>> = parts.iter().map(|p| p.job.clone()).collect();
        let inits = parts
            .into_iter()
            .map(|FarmPart { job, resumed, journal }| {
                let s = &job.settings;
                let (width, height) = (s.view.width as u32, s.view.height as u32);
                let lines = s.spectral.spectral_nm.len() as u32;
                let mut columns: Vec<Option<Vec<PixelResult>>> = vec![None; width as usize];
                for (c, t) in &resumed {
                    let want = tile::Expect {
                        job_hash: &job.hash,
                        task_id: t.task_id,
                        first_column: *c,
                        columns: 1,
                        height,
                        lines,
                        spp: s.view.spp,
                    };
                    if let Ok(mut cols) = tile::decode(t, &want) {
                        if (*c as usize) < columns.len() {
                            columns[*c as usize] = cols.pop();
                        }
                    }
                }
                PartInit { job_hash: job.hash.clone(), height, lines, columns, journal }
            })
            .collect();
        // Backends made on first use; one that cannot be made quarantines its worker.
        for slot in &mut self.slots {
            if slot.backend.is_none() && slot.quarantined.is_none() {
                match Backend::new(&slot.spec) {
                    Ok(b) => slot.backend = Some(b),
                    Err(e) => slot.quarantined = Some(e),
                }
            }
        }
        let wstates = self
            .slots
            .iter()
            .map(|slot| WState::new(slot.name.clone(), slot.spec.address(), slot.quarantined.clone()))
            .collect();
        let shared = Arc::new(Shared {
            sched: Mutex::new(Sched::new(inits, wstates, opts.clone())),
            changed: Notify::new(),
            cancel: cancel.clone(),
            epoch: Instant::now(),
        });
        let leases = tokio::spawn(watch_leases(shared.clone(), opts.lease));
        let progress = tokio::spawn(report_progress(shared.clone(), opts.events.clone(), opts.progress_period));
        let mut drivers = Vec::new();
        for (w, slot) in self.slots.iter_mut().enumerate() {
            if slot.quarantined.is_some() {
                continue;
            }
            let Some(backend) = slot.backend.take() else { continue };
            let named = matches!(&slot.spec, WorkerSpec::Local { .. } | WorkerSpec::Remote { name: Some(_), .. });
            let (shared, jobs, opts) = (shared.clone(), jobs.clone(), opts.clone());
            drivers.push((w, tokio::spawn(async move { drive(w, backend, named, shared, jobs, opts).await })));
        }
        for (w, d) in drivers {
            // A driver that panicked loses its backend: the next render makes a new one.
            if let Ok(b) = d.await {
                self.slots[w].backend = Some(b);
            }
        }
        progress.abort();
        leases.abort();
        let _ = progress.await;
        let _ = leases.await;
        let mut sched = shared.sched.lock().unwrap();
        for (slot, ws) in self.slots.iter_mut().zip(&sched.workers) {
            slot.name = ws.name.clone();
            slot.quarantined = ws.quarantined.clone();
        }
        if cancel.load(Ordering::Relaxed) {
            return Err(FarmError::Cancelled);
        }
        if let Some(e) = sched.fatal.take() {
            return Err(e);
        }
        let stats = sched.snapshot();
        let busy_core_s = sched.busy_core_s();
        match sched.take_columns() {
            Some(parts) => Ok(PartsOutcome { parts, busy_core_s, stats }),
            None => Err(FarmError::NoWorkers { report: sched.report() }),
        }
    }
}

/// One job of a render of several ([`Farm::render_parts`]), with the
/// columns an earlier run journaled and the journal for new ones.
pub struct FarmPart {
    pub job: Arc<FarmJob>,
    pub resumed: BTreeMap<u32, proto::Tile>,
    pub journal: Option<Journal>,
}

/// One worker's loop: take a task, run it, report, until the job is done;
/// gives the backend (its connection) back for the next render. `named`:
/// the farm file names the worker (else it goes by its Hello's name).
async fn drive(
    w: usize,
    mut backend: Backend,
    named: bool,
    shared: Arc<Shared>,
    jobs: Vec<Arc<FarmJob>>,
    opts: Options,
) -> Backend {
    let (inflight, preparing, traffic) = {
        let s = shared.sched.lock().unwrap();
        (s.workers[w].inflight_pixels.clone(), s.workers[w].preparing.clone(), s.workers[w].traffic.clone())
    };
    let mut backoff = Duration::from_millis(500);
    loop {
        if shared.cancel.load(Ordering::Relaxed) {
            break;
        }
        // Be connected, agree on versions and not be paused before taking work.
        let ready = backend.ready(&opts, &traffic).await;
        {
            let mut s = shared.sched.lock().unwrap();
            if let (false, Some(n)) = (named, backend.hello_name()) {
                // Unnamed in the farm file: the worker's own --name.
                s.workers[w].name = n.to_string();
            }
            if let Some(t) = backend.threads() {
                s.workers[w].threads = t;
            }
        }
        match ready {
            Ok(None) => backoff = Duration::from_millis(500),
            Ok(Some(reason)) => {
                shared.sched.lock().unwrap().workers[w].state = format!("paused ({reason})");
                if wait_or_done(&shared, w, Duration::from_secs(2)).await {
                    break;
                }
                continue;
            }
            Err(e) => {
                {
                    let mut s = shared.sched.lock().unwrap();
                    if s.complete() || s.fatal.is_some() {
                        break;
                    }
                    s.workers[w].state = "unreachable".into();
                    s.blame(w, e, None);
                }
                shared.changed.notify_waiters();
                if wait_or_done(&shared, w, backoff).await {
                    break;
                }
                backoff = (backoff * 2).min(Duration::from_secs(8));
                continue;
            }
        }
        let a = {
            let mut s = shared.sched.lock().unwrap();
            let a = s.assign(w, shared.now());
            if let Assign::Task(_) = &a {
                s.workers[w].state = "rendering".into();
            } else if s.workers[w].quarantined.is_none() {
                s.workers[w].state = "idle".into();
            }
            a
        };
        match a {
            Assign::Done => break,
            Assign::Wait => {
                if wait_or_done(&shared, w, Duration::from_millis(200)).await {
                    break;
                }
            }
            Assign::Task(t) => {
                let beat = || shared.sched.lock().unwrap().heard(w, t.id, shared.now());
                let result = backend
                    .run(&t, &jobs[t.part], (&inflight, &preparing), &traffic, opts.lease, &beat, &shared.cancel)
                    .await;
                preparing.store(false, Ordering::Relaxed);
                {
                    let mut s = shared.sched.lock().unwrap();
                    match result {
                        Ok(cols) => {
                            s.finish(w, t.id, cols, shared.now());
                            opts.faults.accepted(s.columns_done());
                        }
                        Err(e) => {
                            let render = s.is_render(t.id);
                            match &e {
                                TaskError::Failed(_) => backend.forget(),
                                // Silent for its lease (the scheduler counted it): a new connection.
                                TaskError::Cancelled if *t.stop.borrow() == Stop::Expired => backend.forget(),
                                // Poll it with Hello until it resumes.
                                TaskError::Paused(_) => backend.unready(),
                                _ => {}
                            }
                            s.release(w, t.id, matches!(e, TaskError::Cancelled));
                            s.blame(w, e, render.then_some((t.start, t.count)));
                        }
                    }
                }
                shared.changed.notify_waiters();
            }
        }
    }
    shared.changed.notify_waiters();
    backend
}

/// Waits for a change or `d`; true if the job is over (done, failed or cancelled).
async fn wait_or_done(shared: &Shared, w: usize, d: Duration) -> bool {
    let notified = shared.changed.notified();
    {
        let s = shared.sched.lock().unwrap();
        if s.complete()
            || s.fatal.is_some()
            || s.workers[w].quarantined.is_some()
            || shared.cancel.load(Ordering::Relaxed)
        {
            return true;
        }
    }
    let _ = tokio::time::timeout(d, notified).await;
    false
}

/// Expires the leases of silent runners, a few times a lease, until aborted.
async fn watch_leases(shared: Arc<Shared>, lease: Duration) {
    let mut tick = tokio::time::interval((lease / 8).clamp(Duration::from_millis(20), Duration::from_secs(1)));
    loop {
        tick.tick().await;
        let expired = shared.sched.lock().unwrap().expire(shared.now());
        if !expired.is_empty() {
            shared.changed.notify_waiters();
        }
    }
}

/// Reports progress every `period` until aborted.
async fn report_progress(shared: Arc<Shared>, sink: Option<EventSink>, period: Duration) {
    let Some(sink) = sink else { return };
    let started = Instant::now();
    let mut tick = tokio::time::interval(period);
    loop {
        tick.tick().await;
        let (stats, pixels, total_pixels) = {
            let s = shared.sched.lock().unwrap();
            (s.snapshot(), s.pixels_done(), s.pixels_total())
        };
        // Columns of several jobs may differ in height: the mean one.
        let height = total_pixels as f64 / stats.columns_total.max(1) as f64;
        // ETA from each worker's measured speed (columns per second).
        let speed: f64 =
            stats.workers.iter().filter(|w| w.quarantined.is_none()).map(|w| w.columns_per_s).sum::<f64>() * height;
        let left = total_pixels.saturating_sub(pixels) as f64;
        let elapsed_s = started.elapsed().as_secs_f64();
        sink.emit(&FarmEvent::Progress(Progress {
            elapsed_s,
            samples_per_s: stats.samples_rendered as f64 / elapsed_s.max(1e-3),
            pixels_done: pixels,
            pixels_total: total_pixels,
            columns_done: stats.columns_resumed + stats.columns_rendered,
            columns_total: stats.columns_total,
            eta_s: (speed > 0.0).then(|| left / speed),
            stalled: events::stalled(&stats.workers),
            workers: stats.workers,
        }));
    }
}
