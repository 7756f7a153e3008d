//! What the scheduler reports: pixels and columns done, the figures of
//! a render so far, and each worker's state for an error message.

use super::{Kind, Sched};
use crate::farm::stats::{Stats, WorkerStats};
use std::sync::atomic::Ordering;

impl Sched {
    /// Pixels in all: every part's columns times its height.
    pub fn pixels_total(&self) -> u64 {
        self.parts.iter().map(|p| p.width as u64 * p.height as u64).sum()
    }

    /// Core-seconds each part's winning tasks took on their workers, in
    /// all (a basis of sharing a render's cost among its parts).
    pub fn busy_core_s(&self) -> Vec<f64> {
        self.parts.iter().map(|p| p.busy_core_s).collect()
    }

    /// Each worker's state and failures, for an error message.
    pub fn report(&self) -> String {
        let mut s = String::new();
        for w in &self.workers {
            s.push_str(&format!(
                "  {}: {} ({} failures{})\n",
                w.name,
                w.state,
                w.failures,
                w.quarantined.as_ref().map(|q| format!("; quarantined: {q}")).unwrap_or_default()
            ));
        }
        s
    }

    /// The figures so far.
    pub fn snapshot(&self) -> Stats {
        let mut s = self.stats.clone();
        s.columns_total = self.width;
        s.threads = self.workers.iter().filter(|w| w.quarantined.is_none()).map(|w| w.threads).sum();
        s.workers = self
            .workers
            .iter()
            .map(|w| WorkerStats {
                name: w.name.clone(),
                address: w.address.clone(),
                state: if w.state == "rendering" && w.preparing.load(Ordering::Relaxed) {
                    "preparing job".into()
                } else {
                    w.state.clone()
                },
                tasks_done: w.tasks_done,
                columns_done: w.columns_done,
                columns_per_s: w.speed.unwrap_or(0.0),
                threads: w.threads,
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

    /// Pixels finished: those of accepted columns and of running tasks.
    pub fn pixels_done(&self) -> u64 {
        let done: u64 = self
            .columns
            .iter()
            .zip(0..)
            .filter(|(c, _)| c.is_some())
            .map(|(_, i)| self.parts[self.part_of(i)].height as u64)
            .sum();
        let running: u64 = self
            .tasks
            .values()
            .filter(|t| t.kind == Kind::Render)
            .map(|t| {
                t.runners
                    .iter()
                    .map(|r| self.workers[r.worker].inflight_pixels.load(Ordering::Relaxed))
                    .max()
                    .unwrap_or(0)
            })
            .sum();
        done + running
    }

    /// Columns accepted so far, resumed ones included (what the test-only
    /// coordinator faults count).
    pub fn columns_done(&self) -> u32 {
        self.stats.columns_resumed + self.stats.columns_rendered
    }
}
