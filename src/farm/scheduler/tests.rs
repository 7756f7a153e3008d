//! The scheduler driven by hand: no network, no clock, every time an
//! argument. Column c's honest rendering has the value c in every pixel; a
//! liar adds 0.5.

use super::*;
use crate::farm::events::EventSink;
use std::sync::Mutex;

const HEIGHT: u32 = 2;

fn px(v: f64) -> PixelResult {
    PixelResult {
        xyz: [v; 3],
        xyz_direct: [0.0; 3],
        xyz_stderr: [0.0; 3],
        spectral: vec![],
        spectral_stderr: vec![],
        samples: 4,
        paths_cut: 0,
    }
}

/// Columns `first..first + count` as a worker that adds `lie` renders them.
fn cols(first: u32, count: u32, lie: f64) -> Vec<Vec<PixelResult>> {
    (first..first + count).map(|c| vec![px(c as f64 + lie); HEIGHT as usize]).collect()
}

fn honest(a: &Assignment) -> Vec<Vec<PixelResult>> {
    cols(a.first, a.count, 0.0)
}

fn part(hash: &str, columns: Vec<Option<Vec<PixelResult>>>) -> PartInit {
    PartInit { job_hash: hash.into(), height: HEIGHT, lines: 0, columns, journal: None }
}

fn sched_with(columns: Vec<Option<Vec<PixelResult>>>, workers: usize, opts: Options) -> Sched {
    let ws = (0..workers).map(|i| WState::new(format!("w{i}"), format!("h:{i}"), None)).collect();
    Sched::new(vec![part("job", columns)], ws, opts)
}

fn sched(width: usize, workers: usize, opts: Options) -> Sched {
    sched_with(vec![None; width], workers, opts)
}

fn t(s: f64) -> Duration {
    Duration::from_secs_f64(s)
}

fn task(a: Assign) -> Assignment {
    match a {
        Assign::Task(t) => t,
        Assign::Wait => panic!("Wait, not a task"),
        Assign::Done => panic!("Done, not a task"),
    }
}

fn is_wait(a: &Assign) -> bool {
    matches!(a, Assign::Wait)
}

fn is_done(a: &Assign) -> bool {
    matches!(a, Assign::Done)
}

fn value(s: &Sched, c: usize) -> f64 {
    s.columns[c].as_ref().expect("rendered")[0].xyz[0]
}

/// Events as `(kind, worker)`.
fn recorder() -> (EventSink, Arc<Mutex<Vec<(String, String)>>>) {
    let log = Arc::new(Mutex::new(Vec::new()));
    let l = log.clone();
    let sink = EventSink::new(move |e| {
        let entry = match e {
            FarmEvent::Quarantined { worker, .. } => ("quarantined".to_string(), worker.clone()),
            FarmEvent::TaskFailed { worker, .. } => ("task_failed".to_string(), worker.clone()),
            FarmEvent::Progress(_) => return,
        };
        l.lock().unwrap().push(entry);
    });
    (sink, log)
}

#[test]
fn batches_follow_the_measured_speed_the_share_left_and_the_limit() {
    let mut s = sched(100, 2, Options::default());
    // Speed unknown: one column.
    let a = task(s.assign(0, t(0.0)));
    assert_eq!((a.first, a.count), (0, 1));
    // 1 column in 0.1 s: 10 columns/s, 50 in the 5 s a task should take,
    // but no more than a quarter of the 99 left (half of them per worker
    // of two).
    s.finish(0, a.id, honest(&a), t(0.1));
    assert!((s.workers[0].speed.unwrap() - 10.0).abs() < 1e-9);
    let b = task(s.assign(0, t(0.1)));
    assert_eq!((b.first, b.count), (1, 25));
    // The other worker, speed unknown, starts after that batch.
    let c = task(s.assign(1, t(0.1)));
    assert_eq!((c.first, c.count), (26, 1));
    assert_eq!(s.stats.tasks, 3);
    // max_batch caps a fast worker.
    let mut s = sched(1000, 1, Options { max_batch: 8, ..Options::default() });
    let a = task(s.assign(0, t(0.0)));
    s.finish(0, a.id, honest(&a), t(0.01));
    assert_eq!(task(s.assign(0, t(0.01))).count, 8);
}

#[test]
fn a_silent_runner_loses_its_lease_and_its_task_goes_back_to_the_queue() {
    let (sink, log) = recorder();
    let mut s = sched(4, 2, Options { lease: t(10.0), events: Some(sink), ..Options::default() });
    let a = task(s.assign(0, t(0.0)));
    assert_eq!((a.first, a.count), (0, 1));
    // Heard at 8 s: its lease runs to 18 s.
    s.heard(0, a.id, t(8.0));
    assert!(s.expire(t(17.9)).is_empty());
    assert_eq!(*a.stop.borrow(), Stop::Run);
    assert_eq!(s.expire(t(18.1)), vec![0]);
    assert_eq!(*a.stop.borrow(), Stop::Expired, "the runner is told");
    assert_eq!(s.stats.requeued, 1);
    assert_eq!(s.workers[0].failures, 1, "silence counts against the worker");
    assert!(s.workers[0].quarantined.is_none());
    assert_eq!(*log.lock().unwrap(), vec![("task_failed".to_string(), "w0".to_string())]);
    // Column 0 is pending again: the other worker gets it.
    let b = task(s.assign(1, t(18.2)));
    assert_eq!((b.first, b.count), (0, 1));
    // The expired runner's late tile counts for nothing...
    s.finish(0, a.id, cols(0, 1, 0.5), t(19.0));
    assert_eq!(s.workers[0].tasks_done, 0);
    assert!(s.columns[0].is_none());
    // ...and expiring again does not double-count.
    assert!(s.expire(t(19.0)).is_empty());
    s.finish(1, b.id, honest(&b), t(19.0));
    assert_eq!(value(&s, 0), 0.0);
    assert_eq!(s.stats.columns_rendered, 1);
}

#[test]
fn an_idle_worker_duplicates_the_oldest_task_and_the_first_tile_wins() {
    let mut s = sched(3, 2, Options::default());
    let a = task(s.assign(0, t(0.0)));
    let b = task(s.assign(1, t(1.0)));
    let c = task(s.assign(1, t(1.5)));
    assert_eq!((a.first, b.first, c.first), (0, 1, 2));
    s.finish(1, b.id, honest(&b), t(2.0));
    s.finish(1, c.id, honest(&c), t(2.5));
    // Nothing pending: worker 1 duplicates the oldest task running on
    // someone else, worker 0's column 0.
    let dup = task(s.assign(1, t(3.0)));
    assert_eq!((dup.id, dup.first, dup.count), (a.id, 0, 1));
    assert_eq!(s.stats.duplicates, 1);
    // Worker 0 has nothing to duplicate (the only task runs on it already).
    assert!(is_wait(&s.assign(0, t(3.0))));
    // The duplicate delivers first: the original runner is told it lost.
    s.finish(1, dup.id, honest(&dup), t(4.0));
    assert_eq!(*a.stop.borrow(), Stop::Lost);
    assert!(s.complete());
    // Its tile, arriving later, is dropped: each column counts once.
    s.finish(0, a.id, cols(0, 1, 0.5), t(5.0));
    assert_eq!(s.stats.columns_rendered, 3);
    assert_eq!(value(&s, 0), 0.0);
    assert_eq!(s.workers[0].tasks_done, 0);
    // A lost runner's release is no re-queue.
    s.release(0, a.id, true);
    assert_eq!(s.stats.requeued, 0);
    assert!(is_done(&s.assign(0, t(5.0))) && is_done(&s.assign(1, t(5.0))));
}

#[test]
fn verification_renders_a_column_again_on_another_worker_before_the_render_completes() {
    let mut s = sched(2, 2, Options { verify_fraction: 1.0, ..Options::default() });
    let a = task(s.assign(0, t(0.0)));
    s.finish(0, a.id, honest(&a), t(0.1));
    // Worker 0 may not verify its own column: it renders the next one.
    let b = task(s.assign(0, t(0.1)));
    assert_eq!((b.first, b.count), (1, 1));
    s.finish(0, b.id, honest(&b), t(0.2));
    assert!(!s.complete(), "every column is rendered but not yet verified");
    assert!(is_wait(&s.assign(0, t(0.2))));
    // Worker 1 verifies both, one column at a time, bit for bit equal.
    for c in 0..2 {
        let v = task(s.assign(1, t(0.3)));
        assert_eq!((v.first, v.count), (c, 1));
        assert!(!s.is_render(v.id));
        s.finish(1, v.id, honest(&v), t(0.4));
    }
    assert_eq!((s.stats.columns_verified, s.stats.verify_mismatches), (2, 0));
    assert!(s.complete());
    assert!(is_done(&s.assign(1, t(0.5))));
}

#[test]
fn a_lying_worker_is_convicted_by_a_third_opinion_and_its_columns_rendered_again() {
    let (sink, log) = recorder();
    let mut s = sched(2, 3, Options { verify_fraction: 1.0, events: Some(sink), ..Options::default() });
    // w0 lies about column 0; w1 renders column 1 honestly.
    let a = task(s.assign(0, t(0.0)));
    let b = task(s.assign(1, t(0.0)));
    assert_eq!((a.first, b.first), (0, 1));
    s.finish(0, a.id, cols(0, 1, 0.5), t(0.1));
    s.finish(1, b.id, honest(&b), t(0.1));
    // w2 verifies column 0 (the oldest check): it differs from w0's.
    let v = task(s.assign(2, t(0.2)));
    assert_eq!(v.first, 0);
    s.finish(2, v.id, honest(&v), t(0.3));
    assert_eq!(s.stats.verify_mismatches, 1);
    assert!(s.workers[0].quarantined.is_none(), "one disagreement convicts nobody while a third worker can decide");
    // The dispute goes first, to the one worker that is neither party.
    let x = task(s.assign(0, t(0.3)));
    assert_eq!((x.first, s.is_render(x.id)), (1, false), "w0 may verify w1's column 1");
    let d = task(s.assign(1, t(0.3)));
    assert_eq!((d.first, d.count), (0, 1));
    s.finish(1, d.id, honest(&d), t(0.4));
    // w1 agrees with w2: w0 is convicted, and column 0 is pending again.
    let q = s.workers[0].quarantined.clone().expect("convicted");
    assert!(q.contains("differed bit for bit from those of w2 and w1"), "{q}");
    assert!(log.lock().unwrap().contains(&("quarantined".to_string(), "w0".to_string())));
    assert!(s.columns[0].is_none() && s.pending.contains(&0));
    assert_eq!(s.stats.columns_rendered, 1);
    assert!(is_done(&s.assign(0, t(0.5))), "a quarantined worker gets no more work");
    // Its driver hands back the verification it was running; w1 and w2
    // render column 0 again and verify what is left, honestly.
    s.release(0, x.id, true);
    for round in 0.. {
        assert!(round < 10, "the render does not complete");
        if s.complete() {
            break;
        }
        for w in [1, 2] {
            if let Assign::Task(x) = s.assign(w, t(0.7)) {
                s.finish(w, x.id, honest(&x), t(0.8));
            }
        }
    }
    assert_eq!((value(&s, 0), value(&s, 1)), (0.0, 1.0));
    assert!(matches!(s.producer[0], Some(1 | 2)), "column 0 is no longer w0's: {:?}", s.producer[0]);
    assert_eq!(s.stats.verify_mismatches, 1);
    // With no third worker, the verifier is trusted over the producer.
    let mut s = sched(1, 2, Options { verify_fraction: 1.0, ..Options::default() });
    let a = task(s.assign(0, t(0.0)));
    s.finish(0, a.id, cols(0, 1, 0.5), t(0.1));
    let v = task(s.assign(1, t(0.1)));
    s.finish(1, v.id, honest(&v), t(0.2));
    assert!(s.workers[0].quarantined.as_deref().unwrap().contains("no third worker to decide"));
    assert!(s.columns[0].is_none());
}

#[test]
fn a_failing_worker_is_blamed_then_quarantined_and_a_column_failing_everywhere_stops_the_render() {
    let mut s = sched(3, 3, Options { max_worker_failures: 2, max_column_failures: 2, ..Options::default() });
    // A pause hands the task back without blame.
    let a = task(s.assign(0, t(0.0)));
    s.release(0, a.id, false);
    s.blame(0, TaskError::Paused("rpc".into()), Some((a.first, a.count)));
    assert_eq!((s.workers[0].failures, s.workers[0].state.as_str()), (0, "paused (rpc)"));
    assert_eq!(s.stats.requeued, 1);
    // Two failures quarantine w0.
    for n in 1..=2 {
        let a = task(s.assign(0, t(n as f64)));
        assert_eq!(a.first, 0, "the failed column is first in the queue again");
        s.release(0, a.id, false);
        s.blame(0, TaskError::Failed(format!("boom {n}")), Some((a.first, a.count)));
        assert_eq!(s.workers[0].failures, n);
    }
    assert_eq!(s.workers[0].quarantined.as_deref(), Some("2 failures; the last: boom 2"));
    assert!(is_done(&s.assign(0, t(3.0))));
    assert!(s.fatal.is_none());
    // Column 0 fails on a second worker: the render stops, naming both.
    let b = task(s.assign(1, t(4.0)));
    assert_eq!(b.first, 0);
    s.release(1, b.id, false);
    s.blame(1, TaskError::Failed("bang".into()), Some((b.first, b.count)));
    match &s.fatal {
        Some(FarmError::ColumnFailed { part: 0, column: 0, workers: 2, report }) => {
            assert!(report.contains("w0: boom 2") && report.contains("w1: bang"), "{report}")
        }
        other => panic!("{other:?}"),
    }
    assert!(is_done(&s.assign(2, t(5.0))));
}

#[test]
fn refusals_quarantine_at_once_and_a_render_with_no_worker_left_fails() {
    let mut s = sched(2, 2, Options::default());
    s.blame(0, TaskError::Refused("speaks farm protocol 99".into()), None);
    assert_eq!(s.workers[0].quarantined.as_deref(), Some("speaks farm protocol 99"));
    assert!(s.fatal.is_none());
    let a = task(s.assign(1, t(0.0)));
    s.release(1, a.id, false);
    s.blame(1, TaskError::Refused("refused the token".into()), Some((a.first, a.count)));
    match &s.fatal {
        Some(FarmError::NoWorkers { report }) => {
            assert!(report.contains("w0: quarantined") && report.contains("refused the token"), "{report}")
        }
        other => panic!("{other:?}"),
    }
    // Quarantined from the start (an earlier view): the render fails at once.
    let ws = vec![WState::new("w0".into(), "h:0".into(), Some("lied".into()))];
    let s = Sched::new(vec![part("job", vec![None; 2])], ws, Options::default());
    assert!(matches!(s.fatal, Some(FarmError::NoWorkers { .. })));
}

#[test]
fn a_render_completes_with_every_column_once_and_resumed_columns_are_not_rendered_again() {
    let resumed = vec![Some(cols(0, 1, 0.0).remove(0)), None, Some(cols(2, 1, 0.0).remove(0)), None];
    let mut s = sched_with(resumed, 1, Options::default());
    assert_eq!(s.stats.columns_resumed, 2);
    assert_eq!(s.pixels_done(), 2 * HEIGHT as u64);
    // Only columns 1 and 3, one task each (they are not adjacent).
    let a = task(s.assign(0, t(0.0)));
    assert_eq!((a.first, a.count), (1, 1));
    s.workers[0].inflight_pixels.store(1, Ordering::Relaxed);
    assert_eq!(s.pixels_done(), 2 * HEIGHT as u64 + 1, "running tasks count their heartbeats' pixels");
    s.finish(0, a.id, honest(&a), t(1.0));
    let b = task(s.assign(0, t(1.0)));
    assert_eq!((b.first, b.count), (3, 1));
    assert!(s.take_columns().is_none(), "not complete yet");
    s.finish(0, b.id, honest(&b), t(2.0));
    assert!(s.complete());
    assert!(is_done(&s.assign(0, t(2.0))));
    let st = s.snapshot();
    assert_eq!((st.columns_total, st.columns_resumed, st.columns_rendered, st.tasks), (4, 2, 2, 2));
    assert_eq!(st.samples_rendered, 2 * HEIGHT as u64 * 4);
    assert_eq!((st.workers[0].tasks_done, st.workers[0].columns_done), (2, 2));
    let got: Vec<f64> = s.take_columns().unwrap()[0].iter().map(|c| c[0].xyz[0]).collect();
    assert_eq!(got, vec![0.0, 1.0, 2.0, 3.0]);
}

/// Several jobs in one queue: a worker finishing the columns of one goes
/// on to the next at once (no waiting for the first job's last column),
/// no task spans two jobs, each task names its job and the job's own
/// column numbers, and the columns come back by job.
#[test]
fn parts_share_one_queue_and_no_task_spans_two() {
    let ws = (0..2).map(|i| WState::new(format!("w{i}"), format!("h:{i}"), None)).collect();
    let opts = Options { max_batch: 3, ..Options::default() };
    let mut s = Sched::new(vec![part("a", vec![None; 5]), part("b", vec![None; 4])], ws, opts);
    assert_eq!(s.pixels_total(), 9 * HEIGHT as u64);
    let mut seen = Vec::new();
    let mut clock = 0.0;
    // Worker 0 takes a slow task at the start of job a and holds it; worker
    // 1 renders everything else, crossing into job b while it runs.
    let held = task(s.assign(0, t(0.0)));
    assert_eq!((held.part, held.first, held.start, held.count), (0, 0, 0, 1));
    loop {
        clock += 1.0;
        let a = match s.assign(1, t(clock)) {
            Assign::Task(a) => a,
            _ => break,
        };
        if a.id == held.id {
            // Nothing new left: a duplicate of the held task.
            break;
        }
        let p = &s.parts[a.part];
        assert!(
            a.start >= p.offset && a.start + a.count <= p.offset + p.width,
            "a task spans two parts: {} + {}",
            a.start,
            a.count
        );
        assert_eq!(a.start - p.offset, a.first);
        seen.push((a.part, a.first, a.count));
        let c = cols(a.start, a.count, 0.0);
        s.finish(1, a.id, c, t(clock + 0.5));
    }
    // Job b was reached and finished while job a's first column was still out.
    assert!(seen.iter().any(|&(p, _, _)| p == 1), "{seen:?}");
    assert_eq!(seen.iter().filter(|&&(p, _, _)| p == 1).map(|&(_, _, n)| n).sum::<u32>(), 4, "{seen:?}");
    s.finish(0, held.id, cols(0, 1, 0.0), t(clock + 1.0));
    assert!(s.complete());
    let busy = s.busy_core_s();
    assert!(busy[0] > busy[1] && busy[1] > 0.0, "{busy:?}");
    let parts = s.take_columns().unwrap();
    assert_eq!(parts.iter().map(Vec::len).collect::<Vec<_>>(), vec![5, 4]);
    // Job b's columns are its own 0..4: the render's columns 5..9.
    assert_eq!(parts[1][0][0].xyz[0], 5.0);
}

/// A column that fails on enough workers is named by its job and its
/// column there.
#[test]
fn a_failed_column_is_named_in_its_part() {
    let ws = (0..2).map(|i| WState::new(format!("w{i}"), format!("h:{i}"), None)).collect();
    let opts = Options { max_column_failures: 2, ..Options::default() };
    let mut s =
        Sched::new(vec![part("a", vec![Some(vec![px(0.0); HEIGHT as usize]); 3]), part("b", vec![None; 2])], ws, opts);
    for w in 0..2 {
        let a = task(s.assign(w, t(0.0)));
        assert_eq!((a.part, a.first), (1, 0));
        s.release(w, a.id, false);
        s.blame(w, TaskError::Failed("boom".into()), Some((a.start, 1)));
    }
    match &s.fatal {
        Some(FarmError::ColumnFailed { part: 1, column: 0, workers: 2, .. }) => {}
        other => panic!("{other:?}"),
    }
}

/// A task's cost is its seconds times its worker's threads: the same
/// seconds on a 4-thread worker cost four times a 1-thread worker's, and
/// the render's threads are those of the workers not quarantined.
#[test]
fn busy_core_seconds_weigh_tasks_by_their_workers_threads() {
    let opts = Options { max_batch: 1, verify_fraction: 0.0, ..Options::default() };
    let mut s = sched(2, 2, opts);
    s.workers[0].threads = 4;
    s.workers[1].threads = 1;
    let a = task(s.assign(0, t(0.0)));
    let b = task(s.assign(1, t(0.0)));
    s.finish(0, a.id, honest(&a), t(2.0));
    s.finish(1, b.id, honest(&b), t(2.0));
    assert!(s.complete());
    assert!((s.busy_core_s()[0] - 10.0).abs() < 1e-9, "{:?}", s.busy_core_s());
    let stats = s.snapshot();
    assert!((stats.busy_core_s - 10.0).abs() < 1e-9, "{}", stats.busy_core_s);
    assert_eq!(stats.threads, 5);
    assert_eq!(stats.workers.iter().map(|w| w.threads).collect::<Vec<_>>(), vec![4, 1]);
    s.quarantine(1, "test".into());
    assert_eq!(s.snapshot().threads, 4);
}
