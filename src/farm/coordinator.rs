//! The coordinator: splits an image into pixel columns, hands batches of
//! adjacent columns to workers (sized by each worker's measured speed),
//! and gathers their tiles, surviving workers that vanish, stall, pause or
//! send garbage.
//!
//! - A task whose worker sends nothing for a lease (heartbeats come every
//!   second) goes back to the queue; so does a task whose worker fails or
//!   pauses.
//! - Once the queue is empty, an idle worker duplicates the oldest task in
//!   flight; the first valid tile wins and the other runner is cancelled.
//! - Every tile is checked (job hash, columns, size, finite non-negative
//!   values) before it is accepted, and accepted columns go to the journal.
//! - `verify_fraction` of the columns are rendered again on a different
//!   worker and compared bit for bit; on a mismatch a third worker decides,
//!   and the one that disagrees with the other two is quarantined and every
//!   column it produced rendered again (with no third worker, the second
//!   is trusted over the first).
//! - Thresholds (the defaults farm managers ship): a column that fails on
//!   3 different workers fails the render with a report; a worker that
//!   fails 3 tasks, or refuses the job (versions, token), is quarantined.
//!
//! The embedded local worker goes through the same scheduler, so a local
//! render and a farm render are the same code path and bit-identical.

use super::events::{self, EventSink, FarmEvent, Progress};
pub use super::job::FarmJob;
use super::journal::Journal;
use super::proto::worker_client::WorkerClient;
use super::proto::{self, render_event::Event, WorkerState};
use super::protocol::{classify, TaskError};
use super::{tile, MAX_MESSAGE_BYTES, PROTOCOL_VERSION};
use crate::render::{self, PixelResult};
use prost::Message;
use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet, VecDeque};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::sync::{watch, Notify};
use tonic::transport::{Channel, ClientTlsConfig, Endpoint};

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
    /// Fault injection for tests: SIGKILL this process once the journal
    /// holds at least this many columns.
    pub fault_kill_after_columns: Option<u32>,
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
            fault_kill_after_columns: None,
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum FarmError {
    #[error("render cancelled")]
    Cancelled,
    #[error("column {column} failed on {workers} different workers, so the render stops:\n{report}")]
    ColumnFailed { column: u32, workers: usize, report: String },
    #[error("no worker left to render on:\n{report}")]
    NoWorkers { report: String },
    #[error("journal: {0}")]
    Journal(#[from] super::journal::JournalError),
    #[error("cannot start the farm's runtime: {0}")]
    Runtime(std::io::Error),
}

/// One worker's figures.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct WorkerStats {
    pub name: String,
    /// HOST:PORT, or "local" for the embedded worker.
    pub address: String,
    pub state: String,
    pub tasks_done: u64,
    pub columns_done: u64,
    pub columns_per_s: f64,
    pub failures: usize,
    pub quarantined: Option<String>,
    /// Connections and Hellos made, and what was sent, in this render.
    pub connects: u64,
    pub hellos: u64,
    pub requests: u64,
    pub request_bytes: u64,
    pub optics_sent: u64,
    pub optics_bytes: u64,
}

/// What a render did.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct Stats {
    pub columns_total: u32,
    /// Columns taken from the journal of an earlier run.
    pub columns_resumed: u32,
    /// Columns accepted from workers in this run (each counted once).
    pub columns_rendered: u32,
    /// Path samples in those columns (each pixel's count, summed).
    pub samples_rendered: u64,
    pub tasks: u64,
    /// Tasks started a second time on an idle worker.
    pub duplicates: u64,
    /// Tasks that went back to the queue (failure, lease, pause).
    pub requeued: u64,
    pub columns_verified: u32,
    pub verify_mismatches: u32,
    /// Columns picked for verification that no second worker could take.
    pub columns_unverified: u32,
    pub workers: Vec<WorkerStats>,
}

/// The gathered columns (each top to bottom) and the figures.
pub struct Outcome {
    pub columns: Vec<Vec<PixelResult>>,
    pub stats: Stats,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Render,
    /// A second (or third) rendering of a column: an entry of `checks`.
    Verify {
        check: u64,
    },
}

/// A column to render again on another worker and compare bit for bit.
#[derive(Debug, Clone)]
struct Check {
    column: u32,
    producer: usize,
    /// Workers that may not take it (the producer, a disputing verifier).
    excluded: Vec<usize>,
    /// A verifier whose result differed from the producer's, and its
    /// result: a third worker decides which of the two is wrong.
    disputed: Option<(usize, Vec<PixelResult>)>,
}

struct Task {
    first: u32,
    count: u32,
    kind: Kind,
    runners: Vec<(usize, Instant)>,
    cancel: watch::Sender<bool>,
}

#[derive(Clone)]
struct Assignment {
    id: u64,
    first: u32,
    count: u32,
    cancel: watch::Receiver<bool>,
}

enum Assign {
    Task(Assignment),
    Wait,
    Done,
}

struct WState {
    name: String,
    address: String,
    state: String,
    failures: usize,
    tasks_done: u64,
    columns_done: u64,
    /// Columns per second, smoothed.
    speed: Option<f64>,
    quarantined: Option<String>,
    /// Pixels of the current task finished so far (from heartbeats).
    inflight_pixels: Arc<AtomicU64>,
    /// Whether the worker is still preparing the job's optics.
    preparing: Arc<AtomicBool>,
    traffic: Arc<Traffic>,
}

struct Sched {
    width: u32,
    height: u32,
    lines: u32,
    job_hash: String,
    columns: Vec<Option<Vec<PixelResult>>>,
    producer: Vec<Option<usize>>,
    pending: BTreeSet<u32>,
    tasks: BTreeMap<u64, Task>,
    verify_queue: VecDeque<u64>,
    checks: BTreeMap<u64, Check>,
    next_check: u64,
    column_failures: HashMap<u32, BTreeMap<usize, String>>,
    workers: Vec<WState>,
    next_id: u64,
    fatal: Option<FarmError>,
    journal: Option<Journal>,
    stats: Stats,
    opts: Options,
}

impl Sched {
    fn live_workers(&self) -> usize {
        self.workers.iter().filter(|w| w.quarantined.is_none()).count()
    }

    fn complete(&self) -> bool {
        self.pending.is_empty() && self.tasks.is_empty() && self.verify_queue.is_empty() && self.columns.iter().all(Option::is_some)
    }

    fn report(&self) -> String {
        let mut s = String::new();
        for w in &self.workers {
            s.push_str(&format!("  {}: {} ({} failures{})\n", w.name, w.state, w.failures, w.quarantined.as_ref().map(|q| format!("; quarantined: {q}")).unwrap_or_default()));
        }
        s
    }

    /// Columns a worker should take at once: about `task_seconds` of its
    /// measured speed, and no more than its share of what is left.
    fn batch(&self, w: usize) -> u32 {
        let by_speed = match self.workers[w].speed {
            None => 1.0,
            Some(v) => (v * self.opts.task_seconds).round().max(1.0),
        };
        let share = (self.pending.len() as f64 / (2.0 * self.live_workers().max(1) as f64)).ceil().max(1.0);
        by_speed.min(share).min(self.opts.max_batch as f64).max(1.0) as u32
    }

    fn new_task(&mut self, w: usize, first: u32, count: u32, kind: Kind) -> Assign {
        let id = self.next_id;
        self.next_id += 1;
        let (tx, rx) = watch::channel(false);
        self.tasks.insert(id, Task { first, count, kind, runners: vec![(w, Instant::now())], cancel: tx });
        self.stats.tasks += 1;
        self.workers[w].inflight_pixels.store(0, Ordering::Relaxed);
        Assign::Task(Assignment { id, first, count, cancel: rx })
    }

    fn assign(&mut self, w: usize) -> Assign {
        if self.fatal.is_some() || self.workers[w].quarantined.is_some() {
            return Assign::Done;
        }
        // Verifications no live worker but the producer could take are dropped.
        let live: Vec<usize> = (0..self.workers.len()).filter(|&i| self.workers[i].quarantined.is_none()).collect();
        let before = self.verify_queue.len();
        let checks = &self.checks;
        let mut unresolved = Vec::new();
        self.verify_queue.retain(|id| {
            let c = &checks[id];
            let ok = live.iter().any(|i| !c.excluded.contains(i));
            if !ok {
                unresolved.push(*id);
            }
            ok
        });
        self.stats.columns_unverified += (before - self.verify_queue.len()) as u32;
        for id in unresolved {
            // A dispute no third worker can settle: trust the verifier over
            // the producer (the column is rendered again by someone else).
            let c = self.checks.remove(&id).unwrap();
            if let Some((v, _)) = c.disputed {
                let why = format!("column {} differed bit for bit from {}'s, and no third worker could decide", c.column, self.workers[v].name);
                self.convict(c.producer, why);
            }
        }
        if self.complete() {
            return Assign::Done;
        }
        if let Some(pos) = self.verify_queue.iter().position(|id| !self.checks[id].excluded.contains(&w)) {
            let id = self.verify_queue.remove(pos).unwrap();
            let column = self.checks[&id].column;
            return self.new_task(w, column, 1, Kind::Verify { check: id });
        }
        if let Some(&start) = self.pending.iter().next() {
            let n = self.batch(w);
            let mut count = 0;
            while count < n && self.pending.contains(&(start + count)) {
                self.pending.remove(&(start + count));
                count += 1;
            }
            return self.new_task(w, start, count, Kind::Render);
        }
        // Nothing new: duplicate the oldest task running on someone else.
        let oldest = self.tasks.iter().filter(|(_, t)| t.kind == Kind::Render && t.runners.len() == 1 && t.runners[0].0 != w).min_by_key(|(_, t)| t.runners[0].1).map(|(&id, _)| id);
        if let Some(id) = oldest {
            let t = self.tasks.get_mut(&id).unwrap();
            t.runners.push((w, Instant::now()));
            let a = Assignment { id, first: t.first, count: t.count, cancel: t.cancel.subscribe() };
            self.stats.duplicates += 1;
            self.workers[w].inflight_pixels.store(0, Ordering::Relaxed);
            return Assign::Task(a);
        }
        Assign::Wait
    }

    fn picked_for_verification(&self, column: u32) -> bool {
        if self.opts.verify_fraction <= 0.0 {
            return false;
        }
        let h = blake3::hash(format!("{}:{column}", self.job_hash).as_bytes());
        let u = u64::from_le_bytes(h.as_bytes()[..8].try_into().unwrap()) as f64 / u64::MAX as f64;
        u < self.opts.verify_fraction
    }

    fn quarantine(&mut self, w: usize, why: String) {
        if self.workers[w].quarantined.is_some() {
            return;
        }
        if let Some(e) = &self.opts.events {
            e.emit(&FarmEvent::Quarantined { worker: self.workers[w].name.clone(), why: why.clone() });
        }
        self.workers[w].quarantined = Some(why);
        self.workers[w].state = "quarantined".into();
        if self.live_workers() == 0 && !self.complete() && self.fatal.is_none() {
            self.fatal = Some(FarmError::NoWorkers { report: self.report() });
        }
    }

    fn finish(&mut self, w: usize, id: u64, columns: Vec<Vec<PixelResult>>, started: Instant) {
        let Some(task) = self.tasks.get(&id) else { return };
        if !task.runners.iter().any(|r| r.0 == w) {
            return;
        }
        let task = self.tasks.remove(&id).unwrap();
        task.cancel.send_replace(true);
        let ws = &mut self.workers[w];
        ws.tasks_done += 1;
        ws.columns_done += task.count as u64;
        let rate = task.count as f64 / started.elapsed().as_secs_f64().max(1e-3);
        ws.speed = Some(match ws.speed {
            None => rate,
            Some(v) => 0.5 * v + 0.5 * rate,
        });
        match task.kind {
            Kind::Render => {
                let mut accepted = Vec::new();
                for (i, col) in columns.into_iter().enumerate() {
                    let c = task.first + i as u32;
                    if self.columns[c as usize].is_some() {
                        continue;
                    }
                    accepted.push(tile::encode(&self.job_hash, 0, c, self.height, self.lines as usize, std::slice::from_ref(&col)));
                    self.stats.samples_rendered += col.iter().map(|p| p.samples as u64).sum::<u64>();
                    self.columns[c as usize] = Some(col);
                    self.producer[c as usize] = Some(w);
                    self.stats.columns_rendered += 1;
                    if self.picked_for_verification(c) {
                        self.add_check(Check { column: c, producer: w, excluded: vec![w], disputed: None }, false);
                    }
                }
                if let Some(j) = &mut self.journal {
                    if let Err(e) = j.append_columns(&accepted) {
                        self.fatal = Some(e.into());
                    }
                }
                if let Some(n) = self.opts.fault_kill_after_columns {
                    if self.stats.columns_resumed + self.stats.columns_rendered >= n {
                        eprintln!("sky render: killing itself after {n} columns (fault injection)");
                        // SAFETY: sending a signal to our own process.
                        #[cfg(unix)]
                        unsafe {
                            libc::kill(libc::getpid(), libc::SIGKILL);
                        }
                    }
                }
            }
            Kind::Verify { check } => {
                let Some(chk) = self.checks.remove(&check) else { return };
                let c = chk.column;
                // The producer may have been caught meanwhile (its columns
                // are being rendered again): nothing left to check.
                if self.producer[c as usize] != Some(chk.producer) {
                    return;
                }
                let Some(mine) = columns.into_iter().next() else { return };
                let stored = self.columns[c as usize].clone().expect("a produced column");
                match chk.disputed {
                    None if bitwise_equal(&stored, &mine) => self.stats.columns_verified += 1,
                    None => {
                        self.stats.verify_mismatches += 1;
                        let third = (0..self.workers.len()).any(|i| self.workers[i].quarantined.is_none() && i != chk.producer && i != w);
                        if third {
                            // Two opinions differ: a third worker decides.
                            self.add_check(Check { column: c, producer: chk.producer, excluded: vec![chk.producer, w], disputed: Some((w, mine)) }, true);
                        } else {
                            let why = format!("column {c} differed bit for bit when {} rendered it again (no third worker to decide)", self.workers[w].name);
                            self.convict(chk.producer, why);
                        }
                    }
                    Some((v, theirs)) => {
                        let name = self.workers[w].name.clone();
                        if bitwise_equal(&stored, &mine) {
                            self.stats.columns_verified += 1;
                            let why = format!("its rendering of column {c} differed bit for bit from those of {} and {name}", self.workers[chk.producer].name);
                            self.convict(v, why);
                        } else if bitwise_equal(&theirs, &mine) {
                            let why = format!("its column {c} differed bit for bit from those of {} and {name}", self.workers[v].name);
                            self.convict(chk.producer, why);
                        } else {
                            let why = format!("three different renderings of column {c} ({name} was the third)");
                            self.convict(chk.producer, why.clone());
                            self.convict(v, why);
                        }
                    }
                }
            }
        }
    }

    fn add_check(&mut self, c: Check, urgent: bool) {
        let id = self.next_check;
        self.next_check += 1;
        self.checks.insert(id, c);
        if urgent {
            self.verify_queue.push_front(id);
        } else {
            self.verify_queue.push_back(id);
        }
    }

    /// Quarantines a worker caught with a wrong result and renders again
    /// every column it produced.
    fn convict(&mut self, w: usize, why: String) {
        self.quarantine(w, why);
        let mine: Vec<u32> = (0..self.width).filter(|&i| self.producer[i as usize] == Some(w)).collect();
        for i in mine {
            self.columns[i as usize] = None;
            self.producer[i as usize] = None;
            self.pending.insert(i);
            self.stats.columns_rendered -= 1;
            if let Some(j) = &mut self.journal {
                if let Err(e) = j.retract(i) {
                    self.fatal = Some(e.into());
                }
            }
        }
        let checks = &self.checks;
        self.verify_queue.retain(|id| checks[id].producer != w);
        self.checks.retain(|_, c| c.producer != w);
    }

    /// Takes worker `w` off task `id`; the last runner to leave puts the
    /// task back in the queue.
    fn release(&mut self, w: usize, id: u64, cancelled: bool) {
        let Some(task) = self.tasks.get_mut(&id) else { return };
        task.runners.retain(|r| r.0 != w);
        if !task.runners.is_empty() {
            return;
        }
        let task = self.tasks.remove(&id).unwrap();
        match task.kind {
            Kind::Render => {
                for c in task.first..task.first + task.count {
                    if self.columns[c as usize].is_none() {
                        self.pending.insert(c);
                    }
                }
            }
            Kind::Verify { check } => {
                if self.checks.contains_key(&check) {
                    self.verify_queue.push_front(check);
                }
            }
        }
        if !cancelled {
            self.stats.requeued += 1;
        }
    }

    /// Counts a failure against a worker (and the columns it was on).
    fn blame(&mut self, w: usize, err: TaskError, columns: Option<(u32, u32)>) {
        let err = match err {
            TaskError::OpticsMissing => TaskError::Failed("the worker lost the task's optics".into()),
            e => e,
        };
        match err {
            TaskError::Cancelled => {}
            TaskError::Paused(reason) => self.workers[w].state = format!("paused ({reason})"),
            TaskError::Refused(msg) => self.quarantine(w, msg),
            TaskError::OpticsMissing => unreachable!("made a failure above"),
            TaskError::Failed(msg) => {
                if let Some(e) = &self.opts.events {
                    e.emit(&FarmEvent::TaskFailed { worker: self.workers[w].name.clone(), message: msg.clone() });
                }
                self.workers[w].failures += 1;
                if let Some((first, count)) = columns {
                    for c in first..first + count {
                        let f = self.column_failures.entry(c).or_default();
                        f.insert(w, msg.clone());
                        if f.len() >= self.opts.max_column_failures && self.fatal.is_none() {
                            let report = f.iter().map(|(&i, m)| format!("  {}: {m}\n", self.workers[i].name)).collect::<String>();
                            self.fatal = Some(FarmError::ColumnFailed { column: c, workers: f.len(), report });
                        }
                    }
                }
                if self.workers[w].failures >= self.opts.max_worker_failures {
                    let n = self.workers[w].failures;
                    self.quarantine(w, format!("{n} failures; the last: {msg}"));
                }
            }
        }
    }

    fn snapshot(&self) -> Stats {
        let mut s = self.stats.clone();
        s.columns_total = self.width;
        s.workers = self
            .workers
            .iter()
            .map(|w| WorkerStats {
                name: w.name.clone(),
                address: w.address.clone(),
                state: if w.state == "rendering" && w.preparing.load(Ordering::Relaxed) { "preparing job".into() } else { w.state.clone() },
                tasks_done: w.tasks_done,
                columns_done: w.columns_done,
                columns_per_s: w.speed.unwrap_or(0.0),
                failures: w.failures,
                quarantined: w.quarantined.clone(),
                connects: w.traffic.connects.load(Ordering::Relaxed),
                hellos: w.traffic.hellos.load(Ordering::Relaxed),
                requests: w.traffic.requests.load(Ordering::Relaxed),
                request_bytes: w.traffic.request_bytes.load(Ordering::Relaxed),
                optics_sent: w.traffic.optics_sent.load(Ordering::Relaxed),
                optics_bytes: w.traffic.optics_bytes.load(Ordering::Relaxed),
            })
            .collect();
        s
    }

    fn pixels_done(&self) -> u64 {
        let done = self.columns.iter().filter(|c| c.is_some()).count() as u64 * self.height as u64;
        let running: u64 = self.tasks.values().filter(|t| t.kind == Kind::Render).map(|t| t.runners.iter().map(|r| self.workers[r.0].inflight_pixels.load(Ordering::Relaxed)).max().unwrap_or(0)).sum();
        done + running
    }
}

fn bitwise_equal(a: &[PixelResult], b: &[PixelResult]) -> bool {
    let bits = |p: &PixelResult| -> Vec<u64> {
        p.xyz.iter().chain(&p.xyz_direct).chain(&p.xyz_stderr).chain(&p.spectral).chain(&p.spectral_stderr).map(|v| v.to_bits()).chain(std::iter::once(p.samples as u64)).collect()
    };
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| bits(x) == bits(y))
}

struct Shared {
    sched: Mutex<Sched>,
    changed: Notify,
    cancel: Arc<AtomicBool>,
}

/// Renders `job` across `workers` once: a [`Farm`] for one render.
pub async fn run(job: Arc<FarmJob>, workers: Vec<WorkerSpec>, resumed: BTreeMap<u32, proto::Tile>, journal: Option<Journal>, opts: Options, cancel: Arc<AtomicBool>) -> Result<Outcome, FarmError> {
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
        Farm { slots: workers.into_iter().map(|spec| Slot { name: spec.name(), spec, backend: None, quarantined: None }).collect() }
    }

    /// Renders `job` (the embedded worker renders with the job's prepared
    /// scene, remote ones get its optics when they lack them); `resumed`
    /// holds columns from a journal; `journal`, if any, receives every
    /// newly accepted column. `cancel` stops the render (the journal stays).
    pub async fn render(&mut self, job: Arc<FarmJob>, resumed: BTreeMap<u32, proto::Tile>, journal: Option<Journal>, opts: &Options, cancel: Arc<AtomicBool>) -> Result<Outcome, FarmError> {
        let s = &job.settings;
        let (width, height) = (s.view.width as u32, s.view.height as u32);
        let lines = s.spectral.spectral_nm.len() as u32;
        let mut columns: Vec<Option<Vec<PixelResult>>> = vec![None; width as usize];
        let mut stats = Stats { columns_total: width, ..Default::default() };
        for (c, t) in &resumed {
            let want = tile::Expect { job_hash: &job.hash, task_id: t.task_id, first_column: *c, columns: 1, height, lines, spp: s.view.spp };
            if let Ok(mut cols) = tile::decode(t, &want) {
                if (*c as usize) < columns.len() {
                    columns[*c as usize] = cols.pop();
                    stats.columns_resumed += 1;
                }
            }
        }
        let pending: BTreeSet<u32> = (0..width).filter(|&c| columns[c as usize].is_none()).collect();
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
            .map(|slot| WState {
                name: slot.name.clone(),
                address: slot.spec.address(),
                state: if slot.quarantined.is_some() { "quarantined".into() } else { "connecting".into() },
                failures: 0,
                tasks_done: 0,
                columns_done: 0,
                speed: None,
                quarantined: slot.quarantined.clone(),
                inflight_pixels: Arc::new(AtomicU64::new(0)),
                preparing: Arc::new(AtomicBool::new(false)),
                traffic: Arc::new(Traffic::default()),
            })
            .collect();
        let shared = Arc::new(Shared {
            sched: Mutex::new(Sched {
                width,
                height,
                lines,
                job_hash: job.hash.clone(),
                columns,
                producer: vec![None; width as usize],
                pending,
                tasks: BTreeMap::new(),
                verify_queue: VecDeque::new(),
                checks: BTreeMap::new(),
                next_check: 1,
                column_failures: HashMap::new(),
                workers: wstates,
                next_id: 1,
                fatal: None,
                journal,
                stats,
                opts: opts.clone(),
            }),
            changed: Notify::new(),
            cancel: cancel.clone(),
        });
        {
            let mut sched = shared.sched.lock().unwrap();
            if sched.live_workers() == 0 && !sched.complete() {
                sched.fatal = Some(FarmError::NoWorkers { report: sched.report() });
            }
        }
        let progress = tokio::spawn(report_progress(shared.clone(), opts.events.clone(), opts.progress_period, width as u64 * height as u64));
        let mut drivers = Vec::new();
        for (w, slot) in self.slots.iter_mut().enumerate() {
            if slot.quarantined.is_some() {
                continue;
            }
            let Some(backend) = slot.backend.take() else { continue };
            let named = matches!(&slot.spec, WorkerSpec::Local { .. } | WorkerSpec::Remote { name: Some(_), .. });
            let (shared, job, opts) = (shared.clone(), job.clone(), opts.clone());
            drivers.push((w, tokio::spawn(async move { drive(w, backend, named, shared, job, opts).await })));
        }
        for (w, d) in drivers {
            // A driver that panicked loses its backend: the next render makes a new one.
            if let Ok(b) = d.await {
                self.slots[w].backend = Some(b);
            }
        }
        progress.abort();
        let _ = progress.await;
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
        if !sched.complete() {
            return Err(FarmError::NoWorkers { report: sched.report() });
        }
        let stats = sched.snapshot();
        let columns = std::mem::take(&mut sched.columns).into_iter().map(|c| c.expect("complete")).collect();
        Ok(Outcome { columns, stats })
    }
}

/// One worker's loop: take a task, run it, report, until the job is done;
/// gives the backend (its connection) back for the next render. `named`:
/// the farm file names the worker (else it goes by its Hello's name).
async fn drive(w: usize, mut backend: Backend, named: bool, shared: Arc<Shared>, job: Arc<FarmJob>, opts: Options) -> Backend {
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
        if let (false, Backend::Remote { hello_name: Some(n), .. }) = (named, &backend) {
            // Unnamed in the farm file: the worker's own --name.
            shared.sched.lock().unwrap().workers[w].name = n.clone();
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
            let a = s.assign(w);
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
                let started = Instant::now();
                let result = backend.run(&t, &job, &opts, (&inflight, &preparing), &traffic, &shared.cancel).await;
                preparing.store(false, Ordering::Relaxed);
                {
                    let mut s = shared.sched.lock().unwrap();
                    match result {
                        Ok(cols) => s.finish(w, t.id, cols, started),
                        Err(e) => {
                            let render = s.tasks.get(&t.id).is_none_or(|task| task.kind == Kind::Render);
                            match &e {
                                TaskError::Failed(_) => backend.forget(),
                                // Poll it with Hello until it resumes.
                                TaskError::Paused(_) => backend.unready(),
                                _ => {}
                            }
                            s.release(w, t.id, matches!(e, TaskError::Cancelled));
                            s.blame(w, e, render.then_some((t.first, t.count)));
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
        if s.complete() || s.fatal.is_some() || s.workers[w].quarantined.is_some() || shared.cancel.load(Ordering::Relaxed) {
            return true;
        }
    }
    let _ = tokio::time::timeout(d, notified).await;
    false
}

// One backend per worker, a handful per render: the size difference of the
// variants does not matter.
#[allow(clippy::large_enum_variant)]
enum Backend {
    Local {
        pool: Arc<rayon::ThreadPool>,
    },
    /// `held`: the optics hashes the worker holds, as far as we know (from
    /// its Hello, and the optics sent to it since); `greeted`: its Hello
    /// said it is ready (asked again only after a reconnect or a pause).
    Remote {
        uri: String,
        client: Option<Client>,
        held: HashSet<String>,
        hello_name: Option<String>,
        greeted: bool,
    },
}

/// What a coordinator sent one worker in one render.
#[derive(Debug, Default)]
pub struct Traffic {
    /// Connections made.
    pub connects: AtomicU64,
    /// Hello calls made.
    pub hellos: AtomicU64,
    /// Render calls made (a task resent with its optics counts twice).
    pub requests: AtomicU64,
    /// Bytes of those calls' messages, optics included.
    pub request_bytes: AtomicU64,
    /// Times the optics went along, and their bytes.
    pub optics_sent: AtomicU64,
    pub optics_bytes: AtomicU64,
}

impl Traffic {
    fn add(n: &AtomicU64, v: u64) {
        n.fetch_add(v, Ordering::Relaxed);
    }
}

type Client = WorkerClient<tonic::service::interceptor::InterceptedService<Channel, Auth>>;

/// Adds the farm token to every call.
#[derive(Clone)]
pub struct Auth(Option<tonic::metadata::MetadataValue<tonic::metadata::Ascii>>);

impl tonic::service::Interceptor for Auth {
    fn call(&mut self, mut req: tonic::Request<()>) -> Result<tonic::Request<()>, tonic::Status> {
        if let Some(v) = &self.0 {
            req.metadata_mut().insert("authorization", v.clone());
        }
        Ok(req)
    }
}

/// Connects to a worker: a client with the token and the message limits.
pub async fn connect(uri: &str, token: Option<&str>, tls: Option<ClientTlsConfig>, timeout: Duration) -> Result<Client, String> {
    let mut ep = Endpoint::from_shared(uri.to_string()).map_err(|e| format!("bad worker address {uri}: {e}"))?.connect_timeout(timeout).tcp_nodelay(true);
    if let Some(tls) = tls {
        ep = ep.tls_config(tls).map_err(|e| format!("TLS for {uri}: {e}"))?;
    }
    let channel = ep.connect().await.map_err(|e| format!("cannot connect to {uri}: {}", error_chain(&e)))?;
    let auth = match token {
        Some(t) => Some(format!("Bearer {t}").parse().map_err(|_| "the farm token has characters not allowed in a header".to_string())?),
        None => None,
    };
    Ok(WorkerClient::with_interceptor(channel, Auth(auth)).max_decoding_message_size(MAX_MESSAGE_BYTES).max_encoding_message_size(MAX_MESSAGE_BYTES))
}

fn error_chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut cur = e.source();
    while let Some(c) = cur {
        s.push_str(": ");
        s.push_str(&c.to_string());
        cur = c.source();
    }
    s
}

impl Backend {
    fn new(spec: &WorkerSpec) -> Result<Backend, String> {
        Ok(match spec {
            WorkerSpec::Local { threads } => {
                let pool = rayon::ThreadPoolBuilder::new().num_threads(*threads).build().map_err(|e| format!("cannot start {threads} threads: {e}"))?;
                Backend::Local { pool: Arc::new(pool) }
            }
            WorkerSpec::Remote { uri, .. } => Backend::Remote { uri: uri.clone(), client: None, held: HashSet::new(), hello_name: None, greeted: false },
        })
    }

    /// Ok(None) when ready, Ok(Some(reason)) when paused. Connects and says
    /// Hello only when not connected and greeted already.
    async fn ready(&mut self, opts: &Options, traffic: &Traffic) -> Result<Option<String>, TaskError> {
        let Backend::Remote { uri, client, held, hello_name, greeted } = self else { return Ok(None) };
        if client.is_some() && *greeted {
            return Ok(None);
        }
        if client.is_none() {
            let c = connect(uri, opts.token.as_deref(), opts.tls.clone(), Duration::from_secs(5)).await.map_err(TaskError::Failed)?;
            Traffic::add(&traffic.connects, 1);
            *client = Some(c);
        }
        let c = client.as_mut().unwrap();
        Traffic::add(&traffic.hellos, 1);
        let hello = proto::HelloRequest { protocol_version: PROTOCOL_VERSION, build_version: super::build_version(), coordinator: "sky render".into() };
        let reply = match tokio::time::timeout(opts.lease, c.hello(hello)).await {
            Err(_) => {
                *client = None;
                return Err(TaskError::Failed(format!("{uri}: no answer to hello within {:?}", opts.lease)));
            }
            Ok(Err(status)) => {
                *client = None;
                return Err(match classify(&status) {
                    TaskError::Failed(m) => TaskError::Failed(format!("{uri}: {m}")),
                    other => other,
                });
            }
            Ok(Ok(r)) => r.into_inner(),
        };
        *hello_name = Some(reply.name.clone());
        *held = reply.optics_held.iter().cloned().collect();
        if reply.protocol_version != PROTOCOL_VERSION {
            return Err(TaskError::Refused(format!("worker {} at {uri} speaks farm protocol {}, this coordinator {PROTOCOL_VERSION}", reply.name, reply.protocol_version)));
        }
        if reply.build_version != super::build_version() {
            return Err(TaskError::Refused(format!(
                "worker {} at {uri} is sky {}, this coordinator sky {}: only the same build renders bit-identically",
                reply.name,
                reply.build_version,
                super::build_version()
            )));
        }
        if reply.state == WorkerState::Paused as i32 {
            return Ok(Some(reply.paused_reason));
        }
        *greeted = true;
        Ok(None)
    }

    /// The worker paused: ask its Hello again before the next task.
    fn unready(&mut self) {
        if let Backend::Remote { greeted, .. } = self {
            *greeted = false;
        }
    }

    /// Drops the connection, so the next task reconnects (and learns from
    /// the worker's Hello which optics it holds).
    fn forget(&mut self) {
        if let Backend::Remote { client, held, greeted, .. } = self {
            *client = None;
            held.clear();
            *greeted = false;
        }
    }

    async fn run(
        &mut self,
        t: &Assignment,
        job: &FarmJob,
        opts: &Options,
        (inflight, preparing): (&Arc<AtomicU64>, &AtomicBool),
        traffic: &Traffic,
        stop: &AtomicBool,
    ) -> Result<Vec<Vec<PixelResult>>, TaskError> {
        let s = &job.settings;
        let want =
            tile::Expect { job_hash: &job.hash, task_id: t.id, first_column: t.first, columns: t.count, height: s.view.height as u32, lines: s.spectral.spectral_nm.len() as u32, spp: s.view.spp };
        match self {
            Backend::Local { pool } => {
                let flag = Arc::new(AtomicBool::new(false));
                let work = {
                    let (pool, scene, flag, inflight, job_settings) = (pool.clone(), job.optics.scene.clone(), flag.clone(), inflight.clone(), s.clone());
                    let (first, count) = (t.first as usize, t.count as usize);
                    tokio::task::spawn_blocking(move || {
                        pool.install(|| {
                            render::render_columns(&scene, &job_settings.view, first, count, &flag, &|| {
                                inflight.fetch_add(1, Ordering::Relaxed);
                            })
                        })
                    })
                };
                let mut cancel = t.cancel.clone();
                let mut work = work;
                let mut tick = tokio::time::interval(Duration::from_millis(100));
                let cols = loop {
                    tokio::select! {
                        r = &mut work => break r.map_err(|e| TaskError::Failed(format!("render task panicked: {e}")))?,
                        _ = cancel.changed() => flag.store(true, Ordering::Relaxed),
                        _ = tick.tick() => if stop.load(Ordering::Relaxed) { flag.store(true, Ordering::Relaxed) },
                    }
                };
                let Some(cols) = cols else { return Err(TaskError::Cancelled) };
                // Through the wire format and its checks, like a remote tile.
                let tile = tile::encode(&job.hash, t.id, t.first, s.view.height as u32, s.spectral.spectral_nm.len(), &cols);
                tile::decode(&tile, &want).map_err(|e| TaskError::Failed(format!("invalid result: {e}")))
            }
            Backend::Remote { uri, client, held, .. } => {
                let Some(c) = client.as_mut() else { return Err(TaskError::Failed(format!("{uri}: not connected"))) };
                let optics_hash = &job.optics.hash;
                // The optics go only to a worker that lacks them.
                let mut send_optics = !held.contains(optics_hash);
                let mut stream = loop {
                    let task = proto::RenderTask {
                        protocol_version: PROTOCOL_VERSION,
                        build_version: super::build_version(),
                        job_hash: job.hash.clone(),
                        task_id: t.id,
                        first_column: t.first,
                        columns: t.count,
                        optics_hash: optics_hash.clone(),
                        optics: send_optics.then(|| job.optics.message().clone()),
                        view_json: job.view_json.clone(),
                    };
                    Traffic::add(&traffic.requests, 1);
                    Traffic::add(&traffic.request_bytes, task.encoded_len() as u64);
                    if let Some(o) = &task.optics {
                        Traffic::add(&traffic.optics_sent, 1);
                        Traffic::add(&traffic.optics_bytes, o.encoded_len() as u64);
                    }
                    match tokio::time::timeout(opts.lease, c.render(task)).await {
                        Err(_) => return Err(TaskError::Failed(format!("{uri}: no answer within the lease of {:?}", opts.lease))),
                        Ok(Err(status)) => match classify(&status) {
                            // Evicted since its Hello: send them.
                            TaskError::OpticsMissing if !send_optics => {
                                held.remove(optics_hash);
                                send_optics = true;
                            }
                            TaskError::OpticsMissing => return Err(TaskError::Failed(format!("{uri}: asked for the optics it was just sent"))),
                            e => return Err(e),
                        },
                        Ok(Ok(r)) => break r.into_inner(),
                    }
                };
                held.insert(optics_hash.clone());
                let mut cancel = t.cancel.clone();
                loop {
                    if stop.load(Ordering::Relaxed) {
                        return Err(TaskError::Cancelled);
                    }
                    tokio::select! {
                        _ = cancel.changed() => return Err(TaskError::Cancelled),
                        m = tokio::time::timeout(opts.lease, stream.message()) => match m {
                            Err(_) => return Err(TaskError::Failed(format!("{uri}: silent for the lease of {:?} (stalled or gone)", opts.lease))),
                            Ok(Err(status)) => return Err(classify(&status)),
                            Ok(Ok(None)) => return Err(TaskError::Failed(format!("{uri}: the task's stream ended without a tile"))),
                            Ok(Ok(Some(ev))) => match ev.event {
                                Some(Event::Heartbeat(h)) => {
                                    inflight.store(h.pixels_done, Ordering::Relaxed);
                                    preparing.store(h.preparing, Ordering::Relaxed);
                                }
                                Some(Event::Tile(tile)) => {
                                    return tile::decode(&tile, &want).map_err(|e| TaskError::Failed(format!("{uri}: invalid result: {e}")));
                                }
                                None => return Err(TaskError::Failed(format!("{uri}: an empty event"))),
                            },
                        },
                    }
                }
            }
        }
    }
}

/// Reports progress every `period` until aborted.
async fn report_progress(shared: Arc<Shared>, sink: Option<EventSink>, period: Duration, total_pixels: u64) {
    let Some(sink) = sink else { return };
    let started = Instant::now();
    let mut tick = tokio::time::interval(period);
    loop {
        tick.tick().await;
        let (stats, pixels, height) = {
            let s = shared.sched.lock().unwrap();
            (s.snapshot(), s.pixels_done(), s.height as f64)
        };
        // ETA from each worker's measured speed (columns per second).
        let speed: f64 = stats.workers.iter().filter(|w| w.quarantined.is_none()).map(|w| w.columns_per_s).sum::<f64>() * height;
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
