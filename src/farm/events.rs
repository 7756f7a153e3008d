//! What a render reports while it runs: periodic progress (with an ETA, and
//! why nothing is moving when every worker is paused or quarantined) and
//! the things that happen to workers. The library only emits these events;
//! the CLI decides whether they become bars on a terminal, plain lines in a
//! pipeline's log or JSON lines.

use super::coordinator::WorkerStats;
use std::sync::Arc;

/// One event of a running render.
#[derive(Debug, Clone, serde::Serialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum FarmEvent {
    Progress(Progress),
    /// A worker is excluded from the rest of this render.
    Quarantined {
        worker: String,
        why: String,
    },
    /// A worker's task failed (it will be retried elsewhere).
    TaskFailed {
        worker: String,
        message: String,
    },
}

/// A periodic report.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Progress {
    pub elapsed_s: f64,
    pub samples_per_s: f64,
    pub pixels_done: u64,
    pub pixels_total: u64,
    pub columns_done: u32,
    pub columns_total: u32,
    /// From the workers' measured speeds; None until one is known.
    pub eta_s: Option<f64>,
    pub workers: Vec<WorkerStats>,
    /// Why nothing is being rendered, when no worker can render: each
    /// worker's name and state ("paused (owner load)", "quarantined", ...).
    pub stalled: Option<String>,
}

/// Where a render sends its events (called from the farm's tasks).
#[derive(Clone)]
pub struct EventSink(pub Arc<dyn Fn(&FarmEvent) + Send + Sync>);

impl EventSink {
    pub fn new(f: impl Fn(&FarmEvent) + Send + Sync + 'static) -> EventSink {
        EventSink(Arc::new(f))
    }

    pub fn emit(&self, e: &FarmEvent) {
        (self.0)(e)
    }
}

impl std::fmt::Debug for EventSink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("EventSink")
    }
}

/// Why no worker renders, if none can: every one is paused, quarantined or
/// unreachable (None while one renders, connects or waits for work).
pub fn stalled(workers: &[WorkerStats]) -> Option<String> {
    let blocked =
        |w: &WorkerStats| w.quarantined.is_some() || w.state.starts_with("paused") || w.state == "unreachable";
    if workers.is_empty() || !workers.iter().all(blocked) {
        return None;
    }
    let why: Vec<String> = workers
        .iter()
        .map(|w| {
            format!("{}: {}", w.name, w.quarantined.as_ref().map_or(w.state.clone(), |q| format!("quarantined ({q})")))
        })
        .collect();
    Some(format!("no worker can render: {}", why.join("; ")))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn worker(name: &str, state: &str, quarantined: Option<&str>) -> WorkerStats {
        WorkerStats {
            name: name.into(),
            address: "h:1".into(),
            state: state.into(),
            quarantined: quarantined.map(String::from),
            ..Default::default()
        }
    }

    #[test]
    fn a_render_says_why_it_waits() {
        assert_eq!(stalled(&[worker("a", "rendering", None), worker("b", "paused (owner load)", None)]), None);
        let s = stalled(&[
            worker("a", "quarantined", Some("differed bit for bit")),
            worker("b", "paused (schedule)", None),
        ])
        .unwrap();
        assert!(s.contains("a: quarantined (differed bit for bit)") && s.contains("b: paused (schedule)"), "{s}");
        assert_eq!(stalled(&[]), None);
    }

    #[test]
    fn progress_serialises_as_one_tagged_line() {
        let p = FarmEvent::Progress(Progress {
            elapsed_s: 1.0,
            samples_per_s: 2.0,
            pixels_done: 3,
            pixels_total: 4,
            columns_done: 1,
            columns_total: 2,
            eta_s: None,
            workers: vec![],
            stalled: None,
        });
        let v: serde_json::Value = serde_json::to_value(&p).unwrap();
        assert_eq!(v["event"], "progress");
        assert_eq!(v["pixels_done"], 3);
        let q = serde_json::to_value(FarmEvent::Quarantined { worker: "a".into(), why: "x".into() }).unwrap();
        assert_eq!(q["event"], "quarantined");
    }
}
