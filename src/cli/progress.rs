//! How `sky render` shows the farm's events: bars on a terminal, a plain
//! line every few seconds when stderr is not one (a pipeline's log needs
//! lines, not a bar), or JSON lines on stdout with `--json-progress`.

use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use sky::farm::events::{EventSink, FarmEvent, Progress};
use std::io::IsTerminal;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Seconds between plain progress lines.
const LINE_PERIOD: Duration = Duration::from_secs(5);

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Style {
    Bars,
    Lines,
    Json,
}

impl Style {
    /// JSON when asked for, else bars on a terminal and lines elsewhere.
    pub fn choose(json: bool) -> Style {
        if json {
            Style::Json
        } else if std::io::stderr().is_terminal() {
            Style::Bars
        } else {
            Style::Lines
        }
    }
}

struct Bars {
    multi: MultiProgress,
    main: ProgressBar,
    lines: Vec<ProgressBar>,
}

/// The sink, and what to call when the render ends (clears the bars).
pub struct View {
    pub sink: EventSink,
    bars: Arc<Mutex<Option<Bars>>>,
}

impl View {
    pub fn new(style: Style) -> View {
        let bars: Arc<Mutex<Option<Bars>>> = Arc::new(Mutex::new(None));
        let held = bars.clone();
        let last_line: Mutex<Option<Instant>> = Mutex::new(None);
        let last_stall: Mutex<Option<String>> = Mutex::new(None);
        let sink = EventSink::new(move |e| match style {
            Style::Json => {
                if let Ok(s) = serde_json::to_string(e) {
                    outln!("{s}");
                }
            }
            Style::Bars => {
                let mut b = held.lock().unwrap();
                match e {
                    FarmEvent::Progress(p) => show_bars(&mut b, p),
                    other => {
                        let text = describe(other);
                        match b.as_ref() {
                            Some(bars) => {
                                let _ = bars.multi.println(text);
                            }
                            None => eprintln!("{text}"),
                        }
                    }
                }
            }
            Style::Lines => match e {
                FarmEvent::Progress(p) => {
                    // A stall is said once when it starts (and when its reason changes).
                    let mut stall = last_stall.lock().unwrap();
                    if p.stalled != *stall {
                        if let Some(why) = &p.stalled {
                            eprintln!("sky render: waiting: {why}");
                        }
                        *stall = p.stalled.clone();
                    }
                    let mut last = last_line.lock().unwrap();
                    if last.is_none_or(|t| t.elapsed() >= LINE_PERIOD) {
                        *last = Some(Instant::now());
                        eprintln!("{}", progress_line(p));
                    }
                }
                other => eprintln!("{}", describe(other)),
            },
        });
        View { sink, bars }
    }

    /// Clears the bars, if any.
    pub fn finish(&self) {
        if let Some(b) = self.bars.lock().unwrap().take() {
            for l in &b.lines {
                l.finish_and_clear();
            }
            b.main.finish_and_clear();
        }
    }
}

fn show_bars(b: &mut Option<Bars>, p: &Progress) {
    let bars = b.get_or_insert_with(|| {
        let multi = MultiProgress::new();
        let main = multi.add(ProgressBar::new(p.pixels_total));
        main.set_style(ProgressStyle::with_template("{bar:40} {percent:>3}% {pos}/{len} px  {msg}").unwrap());
        // A line per worker when there is more than the embedded one.
        let lines = if p.workers.len() > 1 || p.workers.iter().any(|w| w.name != "local") {
            p.workers
                .iter()
                .map(|_| {
                    let l = multi.add(ProgressBar::new_spinner());
                    l.set_style(ProgressStyle::with_template("  {msg}").unwrap());
                    l
                })
                .collect()
        } else {
            Vec::new()
        };
        Bars { multi, main, lines }
    });
    bars.main.set_position(p.pixels_done);
    bars.main.set_message(match (&p.stalled, p.eta_s) {
        (Some(why), _) => format!("waiting: {why}"),
        (None, Some(e)) => format!("{} samples/s  ETA {}", fmt_rate(p.samples_per_s), fmt_duration(e)),
        (None, None) => "ETA …".into(),
    });
    for (l, w) in bars.lines.iter().zip(&p.workers) {
        l.set_message(format!(
            "{:<16} {:<21} {:<14} {:>4} tasks {:>5} columns {:>7.2} col/s",
            w.name, w.address, w.state, w.tasks_done, w.columns_done, w.columns_per_s
        ));
        l.tick();
    }
}

/// One plain line: done, rate, elapsed, ETA. The rate is in pixels (which
/// count the columns still being rendered), not samples (which count only
/// finished columns, and so start near 0).
pub fn progress_line(p: &Progress) -> String {
    let pct = if p.pixels_total > 0 { 100.0 * p.pixels_done as f64 / p.pixels_total as f64 } else { 100.0 };
    let eta = p.eta_s.map_or("unknown".to_string(), fmt_duration);
    let px_per_s = p.pixels_done as f64 / p.elapsed_s.max(1e-3);
    format!(
        "sky render: {pct:.0} % ({}/{} px), {} px/s, elapsed {}, ETA {eta}",
        p.pixels_done,
        p.pixels_total,
        fmt_rate(px_per_s),
        fmt_duration(p.elapsed_s)
    )
}

fn describe(e: &FarmEvent) -> String {
    match e {
        FarmEvent::Quarantined { worker, why } => {
            format!("sky render: worker {worker} quarantined for this job: {why}")
        }
        FarmEvent::TaskFailed { worker, message } => format!("sky render: worker {worker}: {message}"),
        FarmEvent::Progress(p) => progress_line(p),
    }
}

pub fn fmt_rate(r: f64) -> String {
    if r >= 1e6 {
        format!("{:.1}M", r / 1e6)
    } else if r >= 1e3 {
        format!("{:.0}k", r / 1e3)
    } else {
        format!("{r:.0}")
    }
}

pub fn fmt_duration(s: f64) -> String {
    let s = s.round() as u64;
    if s >= 3600 {
        format!("{}h{:02}m", s / 3600, s % 3600 / 60)
    } else if s >= 60 {
        format!("{}m{:02}s", s / 60, s % 60)
    } else {
        format!("{s}s")
    }
}
