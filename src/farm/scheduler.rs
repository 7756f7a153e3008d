//! The farm's scheduler: which worker renders which columns, leases,
//! duplicates of slow tasks, verification and quarantine. It does no I/O
//! but the journal's and reads no clock: time enters as `now` (time since
//! the render began), heartbeats as calls, so the tests below drive it
//! deterministically. The coordinator ([`super::coordinator`]) runs it over
//! the transport.
//!
//! - A task whose runner is not heard from for a lease goes back to the
//!   queue ([`Sched::expire`]); so does a task whose worker fails or
//!   pauses ([`Sched::release`], [`Sched::blame`]).
//! - Once the queue is empty, an idle worker duplicates the oldest task in
//!   flight; the first valid tile wins and the other runner is stopped.
//! - `verify_fraction` of the columns are rendered again on a different
//!   worker and compared bit for bit; on a mismatch a third worker decides,
//!   and the one that disagrees with the other two is quarantined and every
//!   column it produced rendered again (with no third worker, the second
//!   is trusted over the first).
//! - A column that fails on `max_column_failures` different workers fails
//!   the render with a report; a worker that fails `max_worker_failures`
//!   tasks, or refuses the job (versions, token), is quarantined.

use super::coordinator::Options;
use super::events::FarmEvent;
use super::journal::Journal;
use super::protocol::TaskError;
pub use super::stats::{FarmError, Outcome, PartsOutcome, Stats, Traffic, WorkerStats};
use super::tile;
use crate::render::PixelResult;
use std::collections::{BTreeMap, BTreeSet, HashMap, VecDeque};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::watch;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Kind {
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

/// Why a runner should stop (what its [`Assignment::stop`] says).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Stop {
    Run,
    /// Another runner delivered the task first (or the render ended).
    Lost,
    /// Not heard from for a lease: the task went back to the queue and the
    /// failure is counted already.
    Expired,
}

struct Runner {
    worker: usize,
    started: Duration,
    heard: Duration,
    stop: watch::Sender<Stop>,
}

struct Task {
    first: u32,
    count: u32,
    kind: Kind,
    runners: Vec<Runner>,
}

/// A task as one runner gets it: columns of one part (job) of the render.
#[derive(Clone)]
pub(crate) struct Assignment {
    pub id: u64,
    /// The part whose columns these are, and the first of them in the
    /// part's own numbering (what the worker renders).
    pub part: usize,
    pub first: u32,
    /// The first column in the render's numbering, over all its parts.
    pub start: u32,
    pub count: u32,
    pub stop: watch::Receiver<Stop>,
}

pub(crate) enum Assign {
    Task(Assignment),
    Wait,
    Done,
}

/// One worker as the scheduler sees it.
pub(crate) struct WState {
    pub name: String,
    pub address: String,
    pub state: String,
    pub failures: usize,
    pub tasks_done: u64,
    pub columns_done: u64,
    /// Columns per second, smoothed.
    pub speed: Option<f64>,
    /// Its render threads, once known (the embedded worker's, a remote's
    /// Hello); 0 before.
    pub threads: usize,
    pub quarantined: Option<String>,
    /// Pixels of the current task finished so far (from heartbeats).
    pub inflight_pixels: Arc<AtomicU64>,
    /// Whether the worker is still preparing the job's optics.
    pub preparing: Arc<AtomicBool>,
    pub traffic: Arc<Traffic>,
}

impl WState {
    /// A worker about to connect, or quarantined (by an earlier view).
    pub fn new(name: String, address: String, quarantined: Option<String>) -> WState {
        WState {
            name,
            address,
            state: if quarantined.is_some() { "quarantined".into() } else { "connecting".into() },
            failures: 0,
            tasks_done: 0,
            columns_done: 0,
            speed: None,
            threads: 0,
            quarantined,
            inflight_pixels: Arc::new(AtomicU64::new(0)),
            preparing: Arc::new(AtomicBool::new(false)),
            traffic: Arc::new(Traffic::default()),
        }
    }
}

/// One job of a render as the scheduler starts it: its columns (those of
/// an earlier run from a journal, the rest None) and where the accepted
/// ones go.
pub(crate) struct PartInit {
    pub job_hash: String,
    pub height: u32,
    pub lines: u32,
    pub columns: Vec<Option<Vec<PixelResult>>>,
    pub journal: Option<Journal>,
}

/// One job of a render: its columns follow those of the parts before it
/// in the render's numbering, from `offset` on.
struct Part {
    job_hash: String,
    height: u32,
    lines: u32,
    offset: u32,
    width: u32,
    journal: Option<Journal>,
    /// Core-seconds its winning tasks took on their workers, in all: each
    /// task's seconds times its worker's threads.
    busy_core_s: f64,
}

/// One render's scheduling state: the columns of one or more jobs (parts)
/// in one queue, so that workers go from one job to the next without
/// waiting for the slowest column of each. A task never spans two parts.
pub(crate) struct Sched {
    width: u32,
    parts: Vec<Part>,
    columns: Vec<Option<Vec<PixelResult>>>,
    producer: Vec<Option<usize>>,
    pending: BTreeSet<u32>,
    tasks: BTreeMap<u64, Task>,
    verify_queue: VecDeque<u64>,
    checks: BTreeMap<u64, Check>,
    next_check: u64,
    column_failures: HashMap<u32, BTreeMap<usize, String>>,
    pub workers: Vec<WState>,
    next_id: u64,
    /// Why the render failed, once it has.
    pub fatal: Option<FarmError>,
    pub stats: Stats,
    opts: Options,
}

impl Sched {
    /// A render of `parts`, each its own job (columns of its height and
    /// spectral lines, named by its hash), in one queue, in their order.
    pub fn new(parts: Vec<PartInit>, workers: Vec<WState>, opts: Options) -> Sched {
        let mut columns = Vec::new();
        let parts: Vec<Part> = parts
            .into_iter()
            .map(|p| {
                let offset = columns.len() as u32;
                let width = p.columns.len() as u32;
                columns.extend(p.columns);
                Part {
                    job_hash: p.job_hash,
                    height: p.height,
                    lines: p.lines,
                    offset,
                    width,
                    journal: p.journal,
                    busy_core_s: 0.0,
                }
            })
            .collect();
        let width = columns.len() as u32;
        let resumed = columns.iter().filter(|c| c.is_some()).count() as u32;
        let pending = (0..width).filter(|&c| columns[c as usize].is_none()).collect();
        let mut s = Sched {
            width,
            parts,
            columns,
            producer: vec![None; width as usize],
            pending,
            tasks: BTreeMap::new(),
            verify_queue: VecDeque::new(),
            checks: BTreeMap::new(),
            next_check: 1,
            column_failures: HashMap::new(),
            workers,
            next_id: 1,
            fatal: None,
            stats: Stats { columns_total: width, columns_resumed: resumed, ..Default::default() },
            opts,
        };
        if s.live_workers() == 0 && !s.complete() {
            s.fatal = Some(FarmError::NoWorkers { report: s.report() });
        }
        s
    }

    /// The part column `c` (in the render's numbering) belongs to.
    fn part_of(&self, c: u32) -> usize {
        self.parts.partition_point(|p| p.offset + p.width <= c)
    }

    pub fn live_workers(&self) -> usize {
        self.workers.iter().filter(|w| w.quarantined.is_none()).count()
    }

    /// Every column rendered (and verified, where picked), nothing running.
    pub fn complete(&self) -> bool {
        self.pending.is_empty()
            && self.tasks.is_empty()
            && self.verify_queue.is_empty()
            && self.columns.iter().all(Option::is_some)
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

    fn runner(&mut self, w: usize, now: Duration) -> (Runner, watch::Receiver<Stop>) {
        let (tx, rx) = watch::channel(Stop::Run);
        self.workers[w].inflight_pixels.store(0, Ordering::Relaxed);
        (Runner { worker: w, started: now, heard: now, stop: tx }, rx)
    }

    fn new_task(&mut self, w: usize, first: u32, count: u32, kind: Kind, now: Duration) -> Assign {
        let id = self.next_id;
        self.next_id += 1;
        let (runner, stop) = self.runner(w, now);
        self.tasks.insert(id, Task { first, count, kind, runners: vec![runner] });
        self.stats.tasks += 1;
        Assign::Task(self.assignment(id, first, count, stop))
    }

    fn assignment(&self, id: u64, start: u32, count: u32, stop: watch::Receiver<Stop>) -> Assignment {
        let part = self.part_of(start);
        Assignment { id, part, first: start - self.parts[part].offset, start, count, stop }
    }

    /// Work for worker `w` at `now`: a verification it may take, else a
    /// batch of pending columns, else a duplicate of the oldest task
    /// running on another worker; Wait if none, Done once the render is
    /// over for it.
    pub fn assign(&mut self, w: usize, now: Duration) -> Assign {
        if self.fatal.is_some() || self.workers[w].quarantined.is_some() {
            return Assign::Done;
        }
        self.drop_unverifiable();
        if self.complete() {
            return Assign::Done;
        }
        if let Some(pos) = self.verify_queue.iter().position(|id| !self.checks[id].excluded.contains(&w)) {
            let id = self.verify_queue.remove(pos).unwrap();
            let column = self.checks[&id].column;
            return self.new_task(w, column, 1, Kind::Verify { check: id }, now);
        }
        if let Some(&start) = self.pending.iter().next() {
            // Not past the end of the part.
            let part = &self.parts[self.part_of(start)];
            let end = part.offset + part.width;
            let n = self.batch(w).min(end - start);
            let mut count = 0;
            while count < n && self.pending.contains(&(start + count)) {
                self.pending.remove(&(start + count));
                count += 1;
            }
            return self.new_task(w, start, count, Kind::Render, now);
        }
        // Nothing new: duplicate the oldest task running on someone else.
        let oldest = self
            .tasks
            .iter()
            .filter(|(_, t)| t.kind == Kind::Render && t.runners.len() == 1 && t.runners[0].worker != w)
            .min_by_key(|(_, t)| t.runners[0].started)
            .map(|(&id, _)| id);
        if let Some(id) = oldest {
            let (runner, stop) = self.runner(w, now);
            let t = self.tasks.get_mut(&id).unwrap();
            t.runners.push(runner);
            let (first, count) = (t.first, t.count);
            let a = self.assignment(id, first, count, stop);
            self.stats.duplicates += 1;
            return Assign::Task(a);
        }
        Assign::Wait
    }

    pub fn quarantine(&mut self, w: usize, why: String) {
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

    /// Worker `w` sent a heartbeat (or any message) for task `id` at `now`.
    pub fn heard(&mut self, w: usize, id: u64, now: Duration) {
        if let Some(r) = self.tasks.get_mut(&id).and_then(|t| t.runners.iter_mut().find(|r| r.worker == w)) {
            r.heard = r.heard.max(now);
        }
    }

    /// Takes off their tasks the runners not heard from for a lease at
    /// `now` (each counted as a failure of its worker; a task left without
    /// runners goes back to the queue), tells them to stop, and returns
    /// their workers.
    pub fn expire(&mut self, now: Duration) -> Vec<usize> {
        let lease = self.opts.lease;
        let late: Vec<(u64, usize)> = self
            .tasks
            .iter()
            .flat_map(|(&id, t)| {
                t.runners.iter().filter(|r| now.saturating_sub(r.heard) > lease).map(move |r| (id, r.worker))
            })
            .collect();
        for &(id, w) in &late {
            let t = &self.tasks[&id];
            let (first, count, render) = (t.first, t.count, t.kind == Kind::Render);
            if let Some(r) = t.runners.iter().find(|r| r.worker == w) {
                r.stop.send_replace(Stop::Expired);
            }
            self.release(w, id, false);
            self.blame(
                w,
                TaskError::Failed(format!("silent for the lease of {lease:?} (stalled or gone)")),
                render.then_some((first, count)),
            );
        }
        late.into_iter().map(|(_, w)| w).collect()
    }

    /// Whether task `id` renders columns (not a verification); true for a
    /// task no longer running.
    pub fn is_render(&self, id: u64) -> bool {
        self.tasks.get(&id).is_none_or(|t| t.kind == Kind::Render)
    }

    /// Worker `w` delivered task `id` at `now` (its tile already checked):
    /// the first runner to deliver wins, the others are stopped.
    pub fn finish(&mut self, w: usize, id: u64, columns: Vec<Vec<PixelResult>>, now: Duration) {
        let Some(task) = self.tasks.get(&id) else { return };
        let Some(started) = task.runners.iter().find(|r| r.worker == w).map(|r| r.started) else { return };
        let task = self.tasks.remove(&id).unwrap();
        for r in &task.runners {
            r.stop.send_replace(Stop::Lost);
        }
        let ws = &mut self.workers[w];
        let task_core_s = now.saturating_sub(started).as_secs_f64() * ws.threads.max(1) as f64;
        self.stats.busy_core_s += task_core_s;
        ws.tasks_done += 1;
        ws.columns_done += task.count as u64;
        let rate = task.count as f64 / now.saturating_sub(started).as_secs_f64().max(1e-3);
        ws.speed = Some(match ws.speed {
            None => rate,
            Some(v) => 0.5 * v + 0.5 * rate,
        });
        match task.kind {
            Kind::Render => {
                let k = self.part_of(task.first);
                self.parts[k].busy_core_s += task_core_s;
                let mut accepted = Vec::new();
                for (i, col) in columns.into_iter().enumerate() {
                    let c = task.first + i as u32;
                    if self.columns[c as usize].is_some() {
                        continue;
                    }
                    let p = &self.parts[k];
                    accepted.push(tile::encode(
                        &p.job_hash,
                        0,
                        c - p.offset,
                        p.height,
                        p.lines as usize,
                        std::slice::from_ref(&col),
                    ));
                    self.stats.samples_rendered += col.iter().map(|p| p.samples as u64).sum::<u64>();
                    self.columns[c as usize] = Some(col);
                    self.producer[c as usize] = Some(w);
                    self.stats.columns_rendered += 1;
                    if self.picked_for_verification(c) {
                        self.add_check(Check { column: c, producer: w, excluded: vec![w], disputed: None }, false);
                    }
                }
                if let Some(j) = &mut self.parts[k].journal {
                    if let Err(e) = j.append_columns(&accepted) {
                        self.fatal = Some(e.into());
                    }
                }
            }
            Kind::Verify { check } => self.finish_verify(w, check, columns),
        }
    }

    /// Takes worker `w` off task `id`; the last runner to leave puts the
    /// task back in the queue.
    pub fn release(&mut self, w: usize, id: u64, cancelled: bool) {
        let Some(task) = self.tasks.get_mut(&id) else { return };
        task.runners.retain(|r| r.worker != w);
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
    pub fn blame(&mut self, w: usize, err: TaskError, columns: Option<(u32, u32)>) {
        let msg = match err {
            TaskError::Cancelled => return,
            TaskError::Paused(reason) => {
                self.workers[w].state = format!("paused ({reason})");
                return;
            }
            TaskError::Refused(msg) => {
                self.quarantine(w, msg);
                return;
            }
            TaskError::OpticsMissing => "the worker lost the task's optics".to_string(),
            TaskError::Failed(msg) => msg,
        };
        if let Some(e) = &self.opts.events {
            e.emit(&FarmEvent::TaskFailed { worker: self.workers[w].name.clone(), message: msg.clone() });
        }
        self.workers[w].failures += 1;
        if let Some((first, count)) = columns {
            let parts: Vec<(usize, u32)> = (first..first + count).map(|c| (self.part_of(c), c)).collect();
            for (part, c) in parts {
                let f = self.column_failures.entry(c).or_default();
                f.insert(w, msg.clone());
                if f.len() >= self.opts.max_column_failures && self.fatal.is_none() {
                    let report =
                        f.iter().map(|(&i, m)| format!("  {}: {m}\n", self.workers[i].name)).collect::<String>();
                    self.fatal = Some(FarmError::ColumnFailed {
                        part,
                        column: c - self.parts[part].offset,
                        workers: f.len(),
                        report,
                    });
                }
            }
        }
        if self.workers[w].failures >= self.opts.max_worker_failures {
            let n = self.workers[w].failures;
            self.quarantine(w, format!("{n} failures; the last: {msg}"));
        }
    }

    /// The columns of a complete render, each top to bottom, by part.
    pub fn take_columns(&mut self) -> Option<Vec<Vec<Vec<PixelResult>>>> {
        if !self.complete() {
            return None;
        }
        let mut all = std::mem::take(&mut self.columns).into_iter().map(|c| c.expect("complete"));
        Some(self.parts.iter().map(|p| all.by_ref().take(p.width as usize).collect()).collect())
    }
}

mod progress;
mod verify;

#[cfg(test)]
mod tests;
