//! What a render reports: its figures, each worker's (with what the
//! coordinator sent it), and why it failed when it did.

use crate::render::PixelResult;
use std::sync::atomic::{AtomicU64, Ordering};

#[derive(Debug, thiserror::Error)]
pub enum FarmError {
    #[error("render cancelled")]
    Cancelled,
    /// `column` of the render's part (job) `part`, in the part's numbering.
    #[error("column {column} failed on {workers} different workers, so the render stops:\n{report}")]
    ColumnFailed { part: usize, column: u32, workers: usize, report: String },
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
    /// Render threads (0 while unknown: a remote worker before its Hello).
    pub threads: usize,
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
    /// Core-seconds of the tasks the workers delivered: each task's seconds
    /// on its worker times that worker's threads (a farm's cost, without
    /// the coordinator's own work; lost and stopped tasks not counted).
    pub busy_core_s: f64,
    /// Render threads of the workers not quarantined, as far as known.
    pub threads: usize,
    pub workers: Vec<WorkerStats>,
}

/// The gathered columns (each top to bottom) and the figures.
pub struct Outcome {
    pub columns: Vec<Vec<PixelResult>>,
    pub stats: Stats,
}

/// The gathered columns of a render of several jobs (parts), by part, and
/// the figures of the whole.
pub struct PartsOutcome {
    pub parts: Vec<Vec<Vec<PixelResult>>>,
    /// Core-seconds each part's accepted tasks took on their workers, in
    /// all: what its share of the render's cost is measured by.
    pub busy_core_s: Vec<f64>,
    pub stats: Stats,
}

/// What a coordinator sent one worker in one render (counted by the
/// transport).
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
    pub fn add(n: &AtomicU64, v: u64) {
        n.fetch_add(v, Ordering::Relaxed);
    }
}
