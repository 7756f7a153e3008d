//! `sky worker`: the render-farm daemon for idle studio PCs.

use super::{usage, EXIT_INVALID};
use anyhow::{Context, Result};
use sky::farm::config::read_token;
use sky::farm::worker::{self, Config, Shared};
use sky::mie::MieCache;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Duration;

#[derive(clap::Args)]
#[command(after_help = "The token: --token-file FILE (its first line) or the SKY_FARM_TOKEN environment variable; \
coordinators must present the same one. Pause and resume: SIGUSR1 and SIGUSR2, or the Control RPC. \
On start the worker prints `listening on ADDRESS` on stdout.\n\nExample:\n  sky worker --listen 0.0.0.0:7878 \
--threads 6 --token-file /etc/sky/farm.token --schedule 19:00-07:00")]
pub struct WorkerArgs {
    /// Address to listen on, HOST:PORT (port 0 picks a free one)
    #[arg(long, default_value = "127.0.0.1:7878")]
    listen: String,
    /// Render threads (default: all cores but one, to leave the owner some)
    #[arg(long)]
    threads: Option<usize>,
    /// File whose first line is the farm's shared token (default: $SKY_FARM_TOKEN)
    #[arg(long)]
    token_file: Option<PathBuf>,
    /// Name shown on the coordinator's progress lines (default: the host name)
    #[arg(long)]
    name: Option<String>,
    /// Scheduling priority, as `nice` (0 normal, 19 lowest)
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(i32).range(0..=19))]
    nice: i32,
    /// Work only in these local-time windows, comma-separated HH:MM-HH:MM (e.g. 19:00-07:00)
    #[arg(long, value_delimiter = ',', value_parser = parse_window)]
    schedule: Vec<(u32, u32)>,
    /// Pause while the owner's own programs use more than this fraction of all cores (Linux; 1 turns it off)
    #[arg(long, default_value_t = 0.5)]
    owner_load_limit: f64,
    /// TLS certificate chain (PEM); with --tls-key the worker speaks TLS
    #[arg(long, requires = "tls_key")]
    tls_cert: Option<PathBuf>,
    /// TLS private key (PEM)
    #[arg(long, requires = "tls_cert")]
    tls_key: Option<PathBuf>,
    /// Directory for cached Mie tables (default: $SKY_CACHE_DIR or the user cache)
    #[arg(long)]
    cache_dir: Option<PathBuf>,
    /// Memory for prepared optics, MiB: the worker keeps the optics of recent atmospheres by hash (about 20 MB each for the clear sky) and evicts the least recently used beyond this
    #[arg(long, default_value_t = sky::lru::DEFAULT_BUDGET_BYTES >> 20, value_parser = clap::value_parser!(u64).range(1..))]
    optics_cache_mib: u64,
    /// Fault injection for the farm's tests: stall forever after N tasks
    #[arg(long, hide = true)]
    fault_stall_after: Option<u64>,
    /// Fault injection: send tiles containing NaN
    #[arg(long, hide = true)]
    fault_corrupt: bool,
    /// Fault injection: send tiles off by one ulp
    #[arg(long, hide = true)]
    fault_perturb: bool,
    /// Fault injection: claim another protocol version
    #[arg(long, hide = true)]
    fault_protocol: Option<u32>,
    /// Fault injection: SIGKILL itself during task N (from 0)
    #[arg(long, hide = true)]
    fault_sigkill_on_task: Option<u64>,
    /// Fault injection: take this many milliseconds more to unpack optics
    #[arg(long, hide = true)]
    fault_slow_unpack_ms: Option<u64>,
}

fn parse_window(s: &str) -> Result<(u32, u32), String> {
    let hm = |t: &str| -> Result<u32, String> {
        let (h, m) = t.trim().split_once(':').ok_or_else(|| format!("`{t}`: expected HH:MM"))?;
        let (h, m): (u32, u32) =
            (h.parse().map_err(|_| format!("`{t}`: bad hour"))?, m.parse().map_err(|_| format!("`{t}`: bad minute"))?);
        if h > 23 || m > 59 {
            return Err(format!("`{t}`: not a time of day"));
        }
        Ok(h * 60 + m)
    };
    let (a, b) = s.split_once('-').ok_or_else(|| format!("`{s}`: expected HH:MM-HH:MM"))?;
    Ok((hm(a)?, hm(b)?))
}

/// Whether minute-of-day `now` falls in a window (windows may wrap midnight).
fn in_windows(windows: &[(u32, u32)], now: u32) -> bool {
    windows.iter().any(|&(a, b)| if a <= b { now >= a && now < b } else { now >= a || now < b })
}

/// The local time of day in minutes.
fn local_minute_of_day() -> u32 {
    // SAFETY: time(NULL) and localtime_r with valid pointers.
    unsafe {
        let t = libc::time(std::ptr::null_mut());
        let mut tm: libc::tm = std::mem::zeroed();
        if libc::localtime_r(&t, &mut tm).is_null() {
            return 0;
        }
        (tm.tm_hour * 60 + tm.tm_min) as u32
    }
}

/// CPU time of all processes but this one, as a fraction of all cores, from
/// /proc/stat and /proc/self/stat (Linux).
struct OwnerLoad {
    last: Option<(u64, u64, u64)>,
}

impl OwnerLoad {
    fn read() -> Option<(u64, u64, u64)> {
        let stat = std::fs::read_to_string("/proc/stat").ok()?;
        let cpu: Vec<u64> = stat.lines().next()?.split_whitespace().skip(1).filter_map(|v| v.parse().ok()).collect();
        let total: u64 = cpu.iter().sum();
        let idle = cpu.get(3).copied().unwrap_or(0) + cpu.get(4).copied().unwrap_or(0);
        let me = std::fs::read_to_string("/proc/self/stat").ok()?;
        // Fields after the command name (which may contain spaces).
        let rest = &me[me.rfind(')')? + 2..];
        let f: Vec<&str> = rest.split_whitespace().collect();
        let own = f.get(11)?.parse::<u64>().ok()? + f.get(12)?.parse::<u64>().ok()?;
        Some((total, total - idle, own))
    }

    /// The owner's share since the last call.
    fn sample(&mut self) -> Option<f64> {
        let now = OwnerLoad::read()?;
        let prev = self.last.replace(now)?;
        let dt = now.0.saturating_sub(prev.0) as f64;
        if dt <= 0.0 {
            return None;
        }
        let busy = now.1.saturating_sub(prev.1) as f64;
        let own = now.2.saturating_sub(prev.2) as f64;
        Some(((busy - own) / dt).max(0.0))
    }
}

pub fn run(a: WorkerArgs) -> Result<ExitCode> {
    let addr: SocketAddr = match a.listen.parse() {
        Ok(x) => x,
        Err(_) => {
            return usage(format!("--listen {}: expected HOST:PORT with a numeric host, e.g. 0.0.0.0:7878", a.listen))
        }
    };
    super::faults_allowed(
        a.fault_stall_after.is_some()
            || a.fault_corrupt
            || a.fault_perturb
            || a.fault_protocol.is_some()
            || a.fault_sigkill_on_task.is_some()
            || a.fault_slow_unpack_ms.is_some(),
    )?;
    if !(a.owner_load_limit > 0.0 && a.owner_load_limit <= 1.0) {
        return usage(format!("--owner-load-limit must be in (0, 1], got {}", a.owner_load_limit));
    }
    let token = match &a.token_file {
        Some(p) => match read_token(p) {
            Ok(t) => t,
            Err(e) => {
                eprintln!("sky worker: {e}");
                return Ok(ExitCode::from(EXIT_INVALID));
            }
        },
        None => match std::env::var("SKY_FARM_TOKEN") {
            Ok(t) if !t.trim().is_empty() => t.trim().to_string(),
            _ => return usage("a worker needs the farm's token: --token-file FILE or SKY_FARM_TOKEN"),
        },
    };
    let cores = std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1);
    let threads = a.threads.filter(|&t| t > 0).unwrap_or((cores - 1).max(1));
    let name = a.name.clone().unwrap_or_else(|| {
        std::fs::read_to_string("/etc/hostname")
            .ok()
            .map(|h| h.trim().to_string())
            .filter(|h| !h.is_empty())
            .unwrap_or_else(|| "worker".into())
    });
    // Lower our priority before any thread starts: threads inherit it.
    // SAFETY: setpriority on our own process.
    #[cfg(unix)]
    unsafe {
        libc::setpriority(libc::PRIO_PROCESS, 0, a.nice);
    }
    let tls = match (&a.tls_cert, &a.tls_key) {
        (Some(c), Some(k)) => {
            let cert = std::fs::read(c).with_context(|| format!("--tls-cert {}", c.display()))?;
            let key = std::fs::read(k).with_context(|| format!("--tls-key {}", k.display()))?;
            Some(tonic::transport::ServerTlsConfig::new().identity(tonic::transport::Identity::from_pem(cert, key)))
        }
        _ => None,
    };
    let cache = match &a.cache_dir {
        Some(d) => MieCache::new(Some(d.clone())),
        None => MieCache::from_env(),
    };
    let log: worker::Log = {
        let name = name.clone();
        std::sync::Arc::new(move |e: &worker::WorkerEvent| eprintln!("sky worker {name}: {e}"))
    };
    let shared = Shared::new(Config {
        name: name.clone(),
        threads,
        token,
        cache,
        optics_budget: a.optics_cache_mib << 20,
        log,
        faults: sky::farm::faults::WorkerFaults {
            stall_after_tasks: a.fault_stall_after,
            corrupt_tiles: a.fault_corrupt,
            perturb_tiles: a.fault_perturb,
            protocol_version: a.fault_protocol,
            sigkill_on_task: a.fault_sigkill_on_task,
            slow_unpack: a.fault_slow_unpack_ms.map(std::time::Duration::from_millis),
        },
    })?;
    let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build()?;
    rt.block_on(serve(shared, addr, tls, a.schedule.clone(), a.owner_load_limit))
}

async fn serve(
    shared: Arc<Shared>,
    addr: SocketAddr,
    tls: Option<tonic::transport::ServerTlsConfig>,
    schedule: Vec<(u32, u32)>,
    load_limit: f64,
) -> Result<ExitCode> {
    let listener = match tokio::net::TcpListener::bind(addr).await {
        Ok(l) => l,
        Err(e) => {
            eprintln!("sky worker: cannot listen on {addr}: {e}");
            return Ok(ExitCode::from(EXIT_INVALID));
        }
    };
    let local = listener.local_addr()?;
    let name = shared.config.name.clone();
    // Owner-first policies.
    if !schedule.is_empty() {
        // Paused before the first call is served, not at the task's first
        // tick: under load that came after a coordinator's Hello.
        let inside = in_windows(&schedule, local_minute_of_day());
        shared.update_pause(|p| p.schedule = !inside);
        let s = shared.clone();
        tokio::spawn(async move {
            let mut tick = tokio::time::interval(Duration::from_secs(30));
            loop {
                tick.tick().await;
                let inside = in_windows(&schedule, local_minute_of_day());
                s.update_pause(|p| p.schedule = !inside);
            }
        });
    }
    if load_limit < 1.0 {
        let s = shared.clone();
        tokio::spawn(async move {
            let mut load = OwnerLoad { last: None };
            let (mut over, mut under) = (0, 0);
            let mut tick = tokio::time::interval(Duration::from_secs(5));
            loop {
                tick.tick().await;
                let Some(f) = load.sample() else { continue };
                if f > load_limit {
                    over += 1;
                    under = 0;
                } else if f < 0.5 * load_limit {
                    under += 1;
                    over = 0;
                }
                // Pause after 10 s of a busy owner, resume after 30 s of quiet.
                if over >= 2 {
                    s.update_pause(|p| p.load = true);
                } else if under >= 6 {
                    s.update_pause(|p| p.load = false);
                }
            }
        });
    }
    #[cfg(unix)]
    {
        use tokio::signal::unix::{signal, SignalKind};
        let s = shared.clone();
        let mut usr1 = signal(SignalKind::user_defined1())?;
        let mut usr2 = signal(SignalKind::user_defined2())?;
        tokio::spawn(async move {
            loop {
                tokio::select! {
                    _ = usr1.recv() => { s.update_pause(|p| p.manual = Some("signal".into())); }
                    _ = usr2.recv() => { s.update_pause(|p| p.manual = None); }
                }
            }
        });
    }
    let shutdown = async {
        #[cfg(unix)]
        {
            use tokio::signal::unix::{signal, SignalKind};
            let mut term = signal(SignalKind::terminate()).expect("SIGTERM handler");
            tokio::select! {
                _ = tokio::signal::ctrl_c() => {}
                _ = term.recv() => {}
            }
        }
        #[cfg(not(unix))]
        {
            let _ = tokio::signal::ctrl_c().await;
        }
    };
    let mut builder = tonic::transport::Server::builder().http2_keepalive_interval(Some(Duration::from_secs(10)));
    if let Some(t) = tls {
        builder = builder.tls_config(t).context("TLS configuration")?;
    }
    outln!("listening on {local}");
    eprintln!("sky worker {name}: listening on {local} with {} threads", shared.config.threads);
    use std::io::Write;
    let _ = std::io::stdout().flush();
    let incoming = tokio_stream::wrappers::TcpListenerStream::new(listener);
    builder
        .add_service(worker::server(shared))
        .serve_with_incoming_shutdown(incoming, shutdown)
        .await
        .context("serving")?;
    eprintln!("sky worker {name}: stopped");
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn schedule_windows_wrap_midnight() {
        let w = vec![parse_window("19:00-07:00").unwrap()];
        assert!(in_windows(&w, 20 * 60));
        assert!(in_windows(&w, 3 * 60));
        assert!(!in_windows(&w, 12 * 60));
        assert!(parse_window("25:00-01:00").is_err());
        assert!(parse_window("1900-0700").is_err());
    }
}
