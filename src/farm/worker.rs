//! `sky worker`: the gRPC service that renders column tasks with the same
//! code as a local render, and the policies that put the PC's owner first
//! (a thread limit, low priority, pause and resume by signal or RPC, a
//! time-of-day schedule, and pausing while the owner's programs keep the
//! CPU busy). A paused worker fails its running task with UNAVAILABLE
//! "paused", so the coordinator re-queues it at once.

use super::proto::worker_server::{Worker, WorkerServer};
use super::proto::{self, ControlAction, WorkerState};
use super::{job, tile, MAX_MESSAGE_BYTES, PROTOCOL_VERSION};
use crate::lru::MemoryLru;
use crate::mie::MieCache;
use crate::render::{self, Scene, SpectralSettings, View};
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::sync::{mpsc, watch};
use tokio_stream::Stream;
use tonic::{Request, Response, Status};

/// What a worker has to say to its owner: the library prints nothing, the
/// CLI (`sky worker`) prints these as log lines.
#[derive(Debug, Clone, PartialEq)]
pub enum WorkerEvent {
    Paused {
        reason: String,
    },
    Resumed,
    /// A coordinator of another protocol said Hello.
    RefusedCoordinator {
        coordinator: String,
        theirs: u32,
        ours: u32,
    },
    /// A call with the wrong token.
    WrongToken {
        peer: String,
    },
    /// A task failed (not cancelled) on this worker.
    TaskFailed {
        peer: String,
        message: String,
    },
    /// A test fault was committed (only under `SKY_FAULT_INJECTION=1`).
    Fault {
        what: String,
    },
}

impl std::fmt::Display for WorkerEvent {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            WorkerEvent::Paused { reason } => write!(f, "paused ({reason})"),
            WorkerEvent::Resumed => write!(f, "resumed"),
            WorkerEvent::RefusedCoordinator { coordinator, theirs, ours } => {
                write!(f, "refused coordinator {coordinator:?}: it speaks farm protocol {theirs}, this worker {ours}")
            }
            WorkerEvent::WrongToken { peer } => write!(f, "refused {peer}: wrong token"),
            WorkerEvent::TaskFailed { peer, message } => write!(f, "task from {peer}: {message}"),
            WorkerEvent::Fault { what } => write!(f, "{what} (fault injection)"),
        }
    }
}

/// Where a worker's events go.
pub type Log = Arc<dyn Fn(&WorkerEvent) + Send + Sync>;

/// Why a worker is paused (any of them pauses it).
#[derive(Debug, Clone, Default)]
pub struct PauseState {
    /// By signal or RPC.
    pub manual: Option<String>,
    /// Outside its schedule.
    pub schedule: bool,
    /// The owner's programs keep the CPU busy.
    pub load: bool,
}

impl PauseState {
    pub fn reason(&self) -> Option<String> {
        if let Some(m) = &self.manual {
            return Some(m.clone());
        }
        if self.schedule {
            return Some("schedule".into());
        }
        if self.load {
            return Some("load".into());
        }
        None
    }
}

/// A worker's configuration.
pub struct Config {
    pub name: String,
    pub threads: usize,
    /// The shared token every call must carry.
    pub token: String,
    pub cache: MieCache,
    /// The most bytes of prepared optics kept (least recently used evicted
    /// first; optics a running task uses never).
    pub optics_budget: u64,
    /// Where the worker's events go (the CLI prints them).
    pub log: Log,
    /// Faults to commit, for the farm's tests.
    pub faults: super::faults::WorkerFaults,
}

/// The worker's shared state.
pub struct Shared {
    pub config: Config,
    pool: rayon::ThreadPool,
    /// Prepared optics by optics hash, bounded by `config.optics_budget`.
    optics: MemoryLru<Scene>,
    /// Optics being unpacked, by optics hash: a task that arrives without
    /// them meanwhile (its coordinator sent them with an earlier task, now
    /// cancelled) waits for them instead of asking for them again.
    unpacking: Mutex<std::collections::HashMap<String, watch::Receiver<Option<Unpacked>>>>,
    pause: Mutex<PauseState>,
    /// True while paused; running tasks watch it.
    paused_tx: watch::Sender<bool>,
    /// One task renders at a time; others wait their turn (heartbeating).
    turn: tokio::sync::Mutex<()>,
    busy: AtomicBool,
    tasks_started: AtomicU64,
    pub tasks_done: AtomicU64,
    pub columns_done: AtomicU64,
}

impl Shared {
    pub fn new(config: Config) -> Result<Arc<Shared>, rayon::ThreadPoolBuildError> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(config.threads)
            .thread_name(|i| format!("sky-worker-{i}"))
            .build()?;
        let (paused_tx, _) = watch::channel(false);
        Ok(Arc::new(Shared {
            optics: MemoryLru::new(config.optics_budget),
            unpacking: Mutex::new(Default::default()),
            config,
            pool,
            pause: Mutex::new(PauseState::default()),
            paused_tx,
            turn: tokio::sync::Mutex::new(()),
            busy: AtomicBool::new(false),
            tasks_started: AtomicU64::new(0),
            tasks_done: AtomicU64::new(0),
            columns_done: AtomicU64::new(0),
        }))
    }

    /// Changes the pause state and tells running tasks.
    pub fn update_pause(&self, f: impl FnOnce(&mut PauseState)) -> Option<String> {
        let mut p = self.pause.lock().unwrap();
        let before = p.reason();
        f(&mut p);
        let after = p.reason();
        if before != after {
            match &after {
                Some(r) => (self.config.log)(&WorkerEvent::Paused { reason: r.clone() }),
                None => (self.config.log)(&WorkerEvent::Resumed),
            }
        }
        self.paused_tx.send_replace(after.is_some());
        after
    }

    pub fn paused_reason(&self) -> Option<String> {
        self.pause.lock().unwrap().reason()
    }

    fn state(&self) -> WorkerState {
        if self.paused_reason().is_some() {
            WorkerState::Paused
        } else if self.busy.load(Ordering::Relaxed) {
            WorkerState::Busy
        } else {
            WorkerState::Idle
        }
    }

    fn protocol_version(&self) -> u32 {
        if let Some(v) = self.config.faults.protocol_version {
            return v;
        }
        PROTOCOL_VERSION
    }

    /// The optics hashes held now, most recently used first, then those
    /// being unpacked (a coordinator need not send them again).
    pub fn optics_held(&self) -> Vec<String> {
        let unpacking = self.unpacking.lock().unwrap();
        let held = self.optics.keys();
        let arriving: Vec<String> = unpacking.keys().filter(|h| !held.contains(h)).cloned().collect();
        [held, arriving].concat()
    }

    /// The prepared optics `hash`: held, being unpacked, or else unpacked
    /// from `carried` (the optics the task brought); None if none of these.
    /// All under the unpacking lock, which an unpacking takes to unlist
    /// itself only after it has put its optics in the cache: no moment when
    /// arriving optics are in neither place, and no optics unpacked twice.
    fn optics_for(
        self: &Arc<Self>,
        hash: &str,
        carried: Option<proto::Optics>,
    ) -> Option<Result<Arc<Scene>, Unpacking>> {
        let mut unpacking = self.unpacking.lock().unwrap();
        if let Some(p) = self.optics.get(hash) {
            return Some(Ok(p));
        }
        let Some(rx) = unpacking.get(hash) else {
            let carried = carried?;
            let (done, rx) = watch::channel(None);
            unpacking.insert(hash.to_string(), rx);
            return Some(Err(unpack(self, carried, hash.to_string(), done)));
        };
        let mut rx = rx.clone();
        Some(Err(tokio::spawn(async move {
            loop {
                if let Some(r) = rx.borrow_and_update().clone() {
                    return r;
                }
                if rx.changed().await.is_err() {
                    return Err(Status::internal("unpacking the optics ended without a result"));
                }
            }
        })))
    }

    /// Bytes of prepared optics held now.
    pub fn optics_bytes(&self) -> u64 {
        self.optics.bytes()
    }
}

/// The gRPC service.
#[derive(Clone)]
pub struct Service {
    pub shared: Arc<Shared>,
}

type EventStream = Pin<Box<dyn Stream<Item = Result<proto::RenderEvent, Status>> + Send>>;

fn heartbeat(pixels_done: u64, preparing: bool) -> proto::RenderEvent {
    proto::RenderEvent {
        event: Some(proto::render_event::Event::Heartbeat(proto::Heartbeat { pixels_done, preparing })),
    }
}

#[tonic::async_trait]
impl Worker for Service {
    async fn hello(&self, request: Request<proto::HelloRequest>) -> Result<Response<proto::HelloReply>, Status> {
        let r = request.into_inner();
        let s = &self.shared;
        if r.protocol_version != s.protocol_version() {
            (s.config.log)(&WorkerEvent::RefusedCoordinator {
                coordinator: r.coordinator.clone(),
                theirs: r.protocol_version,
                ours: s.protocol_version(),
            });
        }
        Ok(Response::new(proto::HelloReply {
            protocol_version: s.protocol_version(),
            build_version: super::build_version(),
            name: s.config.name.clone(),
            threads: s.config.threads as u32,
            state: s.state() as i32,
            paused_reason: s.paused_reason().unwrap_or_default(),
            optics_held: s.optics_held(),
        }))
    }

    async fn control(&self, request: Request<proto::ControlRequest>) -> Result<Response<proto::ControlReply>, Status> {
        let s = &self.shared;
        match ControlAction::try_from(request.into_inner().action).unwrap_or(ControlAction::Unspecified) {
            ControlAction::Pause => {
                s.update_pause(|p| p.manual = Some("rpc".into()));
            }
            ControlAction::Resume => {
                s.update_pause(|p| p.manual = None);
            }
            ControlAction::Unspecified => {}
        }
        Ok(Response::new(proto::ControlReply {
            state: s.state() as i32,
            paused_reason: s.paused_reason().unwrap_or_default(),
            tasks_done: s.tasks_done.load(Ordering::Relaxed),
            columns_done: s.columns_done.load(Ordering::Relaxed),
        }))
    }

    type RenderStream = EventStream;

    async fn render(&self, request: Request<proto::RenderTask>) -> Result<Response<EventStream>, Status> {
        let peer = request.remote_addr().map(|a| a.to_string()).unwrap_or_else(|| "?".into());
        let mut task = request.into_inner();
        let s = self.shared.clone();
        check_task(&task, s.protocol_version())?;
        if let Some(reason) = s.paused_reason() {
            return Err(super::protocol::paused_status(&reason));
        }
        let _started = s.tasks_started.fetch_add(1, Ordering::Relaxed);
        if s.config.faults.stalls(_started) {
            (s.config.log)(&WorkerEvent::Fault { what: format!("stalling on task {}", task.task_id) });
            return Ok(Response::new(Box::pin(tokio_stream::pending())));
        }
        // The view travels with every task; the optics are held already or
        // carried by the task.
        let view = open_view(&task.view_json)?;
        task_columns(&task, view.width)?;
        let Some(optics) = s.optics_for(&task.optics_hash, task.optics.take()) else {
            return Err(super::protocol::optics_missing_status(&task.optics_hash));
        };
        if s.config.faults.sigkill_on_task == Some(_started) {
            (s.config.log)(&WorkerEvent::Fault { what: "killing itself mid-task".into() });
            s.config.faults.maybe_kill_during(_started);
        }
        let (tx, rx) = mpsc::channel::<Result<proto::RenderEvent, Status>>(8);
        tokio::spawn(async move {
            let result = run_task(&s, task, view, optics, &tx).await;
            match result {
                Ok(t) => {
                    let _ = tx.send(Ok(proto::RenderEvent { event: Some(proto::render_event::Event::Tile(t)) })).await;
                }
                Err(status) => {
                    if status.code() != tonic::Code::Cancelled {
                        (s.config.log)(&WorkerEvent::TaskFailed { peer, message: status.message().to_string() });
                    }
                    let _ = tx.send(Err(status)).await;
                }
            }
        });
        Ok(Response::new(Box::pin(tokio_stream::wrappers::ReceiverStream::new(rx))))
    }
}

/// The checks a task passes before a worker takes it: the farm protocol
/// (`protocol_version`, this worker's), the build, and the job hash it
/// claims (of its optics hash and view).
pub fn check_task(task: &proto::RenderTask, protocol_version: u32) -> Result<(), Status> {
    if task.protocol_version != protocol_version {
        return Err(Status::failed_precondition(format!(
            "this worker speaks farm protocol {protocol_version}, the task protocol {}",
            task.protocol_version
        )));
    }
    if task.build_version != super::build_version() {
        return Err(Status::failed_precondition(format!(
            "this worker is sky {}, the task is from sky {}: only the same build renders bit-identically",
            super::build_version(),
            task.build_version
        )));
    }
    let h = job::job_hash(&task.optics_hash, &task.view_json);
    if h != task.job_hash {
        return Err(Status::invalid_argument(format!(
            "the task's optics and view hash to {h}, not the job {} it claims",
            task.job_hash
        )));
    }
    Ok(())
}

/// Unpacks optics a task carries: the atmosphere (from their own files),
/// the spectral settings and the prepared scene if they have it, checked
/// against the optics hash the task names.
pub fn open_optics(
    o: &proto::Optics,
    optics_hash: &str,
) -> Result<(crate::atmosphere::Atmosphere, SpectralSettings, Option<Scene>), Status> {
    job::open_optics(o, optics_hash).map_err(|e| Status::invalid_argument(e.to_string()))
}

/// Unpacks the view a task carries.
pub fn open_view(view_json: &str) -> Result<View, Status> {
    job::open_view(view_json).map_err(|e| Status::invalid_argument(e.to_string()))
}

/// The task's columns, checked against the view's width.
pub fn task_columns(task: &proto::RenderTask, width: usize) -> Result<(usize, usize), Status> {
    let (first, count) = (task.first_column as usize, task.columns as usize);
    if count == 0 || first + count > width {
        return Err(Status::invalid_argument(format!(
            "columns {first}+{count} are outside the view's {width} columns"
        )));
    }
    Ok((first, count))
}

/// Optics a task brought, being unpacked (or prepared) into the cache.
type Unpacking = tokio::task::JoinHandle<Result<Arc<Scene>, Status>>;
/// What an unpacking ends with.
type Unpacked = Result<Arc<Scene>, Status>;

/// Unpacks optics a task carries into the cache, on a blocking thread that
/// runs to the end whatever becomes of the task: once a coordinator has
/// sent them, the worker holds them (it counts them as sent). Tasks that
/// arrive meanwhile follow it through `done` (`Shared::optics_for`, which
/// lists it).
fn unpack(s: &Arc<Shared>, o: proto::Optics, hash: String, done: watch::Sender<Option<Unpacked>>) -> Unpacking {
    let shared = s.clone();
    tokio::task::spawn_blocking(move || -> Unpacked {
        // Unlisted however the unpacking ends (a panic included: the
        // followers then see the channel close).
        struct Unlist<'a>(&'a Shared, &'a str);
        impl Drop for Unlist<'_> {
            fn drop(&mut self) {
                self.0.unpacking.lock().unwrap().remove(self.1);
            }
        }
        let _unlist = Unlist(&shared, &hash);
        let result = (|| {
            shared.config.faults.unpacking();
            let (atm, spectral, scene) = open_optics(&o, &hash)?;
            let (scene, bytes) = match scene {
                Some(s) => (s, o.scene.len() as u64),
                None => {
                    let s = shared.pool.install(|| Scene::new(&atm, &spectral, &shared.config.cache, &|| {}));
                    let bytes = s.encoded_bytes();
                    (s, bytes)
                }
            };
            Ok(shared.optics.insert(hash.clone(), Arc::new(scene), bytes))
        })();
        done.send_replace(Some(result.clone()));
        result
    })
}

/// Runs one task to its tile, heartbeating through `tx`.
async fn run_task(
    s: &Arc<Shared>,
    task: proto::RenderTask,
    view: View,
    optics: Result<Arc<Scene>, Unpacking>,
    tx: &mpsc::Sender<Result<proto::RenderEvent, Status>>,
) -> Result<proto::Tile, Status> {
    let mut paused = s.paused_tx.subscribe();
    let cancel = Arc::new(AtomicBool::new(false));
    let pixels = Arc::new(AtomicU64::new(0));
    // Wait for our turn, heartbeating.
    let _turn = loop {
        tokio::select! {
            t = s.turn.lock() => break t,
            _ = tokio::time::sleep(Duration::from_millis(500)) => {
                if tx.send(Ok(heartbeat(0, false))).await.is_err() {
                    return Err(Status::cancelled("the coordinator went away"));
                }
            }
        }
    };
    s.busy.store(true, Ordering::Relaxed);
    struct NotBusy<'a>(&'a Shared);
    impl Drop for NotBusy<'_> {
        fn drop(&mut self) {
            self.0.busy.store(false, Ordering::Relaxed);
        }
    }
    let _not_busy = NotBusy(s);
    // The optics: held, or being unpacked since the task arrived.
    let scene = match optics {
        Ok(p) => p,
        Err(work) => match watch_blocking(work, tx, &mut paused, &cancel, || heartbeat(0, true), s).await? {
            Ok(r) => r?,
            Err(e) => return Err(Status::internal(format!("preparing the optics panicked: {e}"))),
        },
    };
    let (first, count) = task_columns(&task, view.width)?;
    let lines = scene.spectral.spectral_nm.len();
    let height = view.height as u32;
    let work = {
        let (s2, scene, cancel, pixels) = (s.clone(), scene.clone(), cancel.clone(), pixels.clone());
        tokio::task::spawn_blocking(move || {
            s2.pool.install(|| {
                render::render_columns(&scene, &view, first, count, &cancel, &|| {
                    pixels.fetch_add(1, Ordering::Relaxed);
                })
            })
        })
    };
    let pixels_hb = pixels.clone();
    let columns =
        watch_blocking(work, tx, &mut paused, &cancel, move || heartbeat(pixels_hb.load(Ordering::Relaxed), false), s)
            .await?
            .map_err(|e| Status::internal(format!("render task panicked: {e}")))?;
    let Some(columns) = columns else {
        return Err(Status::cancelled("cancelled"));
    };
    #[allow(unused_mut)]
    let mut t = tile::encode(&task.job_hash, task.task_id, task.first_column, height, lines, &columns);
    s.config.faults.spoil(&mut t);
    s.tasks_done.fetch_add(1, Ordering::Relaxed);
    s.columns_done.fetch_add(count as u64, Ordering::Relaxed);
    Ok(t)
}

/// Waits for blocking work while sending a heartbeat a second, cancelling
/// it if the coordinator goes away or the worker is paused.
async fn watch_blocking<T>(
    mut work: tokio::task::JoinHandle<T>,
    tx: &mpsc::Sender<Result<proto::RenderEvent, Status>>,
    paused: &mut watch::Receiver<bool>,
    cancel: &AtomicBool,
    beat: impl Fn() -> proto::RenderEvent,
    shared: &Shared,
) -> Result<Result<T, String>, Status> {
    let mut tick = tokio::time::interval(Duration::from_millis(1000));
    tick.tick().await;
    loop {
        tokio::select! {
            r = &mut work => return Ok(r.map_err(|e| e.to_string())),
            _ = tick.tick() => {
                if tx.send(Ok(beat())).await.is_err() {
                    cancel.store(true, Ordering::Relaxed);
                    let _ = work.await;
                    return Err(Status::cancelled("the coordinator went away"));
                }
            }
            changed = paused.changed() => {
                if changed.is_ok() && *paused.borrow() {
                    cancel.store(true, Ordering::Relaxed);
                    let _ = work.await;
                    return Err(super::protocol::paused_status(&shared.paused_reason().unwrap_or_else(|| "signal".into())));
                }
            }
        }
    }
}

/// Compares two byte strings in time independent of where they differ.
fn same_token(a: &[u8], b: &[u8]) -> bool {
    if a.len() != b.len() {
        return false;
    }
    a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// The service with its token check and message limits.
pub fn server(
    shared: Arc<Shared>,
) -> tonic::service::interceptor::InterceptedService<WorkerServer<Service>, impl tonic::service::Interceptor + Clone> {
    let token = shared.config.token.clone();
    let log = shared.config.log.clone();
    let check = move |req: Request<()>| -> Result<Request<()>, Status> {
        let got =
            req.metadata().get("authorization").and_then(|v| v.to_str().ok()).and_then(|v| v.strip_prefix("Bearer "));
        match got {
            Some(t) if same_token(t.as_bytes(), token.as_bytes()) => Ok(req),
            Some(_) => {
                let peer = req.remote_addr().map(|a| a.to_string()).unwrap_or_else(|| "?".into());
                log(&WorkerEvent::WrongToken { peer });
                Err(Status::unauthenticated("wrong farm token"))
            }
            None => Err(Status::unauthenticated("missing farm token (authorization: Bearer ...)")),
        }
    };
    let svc = WorkerServer::new(Service { shared })
        .max_decoding_message_size(MAX_MESSAGE_BYTES)
        .max_encoding_message_size(MAX_MESSAGE_BYTES);
    tonic::service::interceptor::InterceptedService::new(svc, check)
}

#[cfg(test)]
mod tests {
    #[test]
    fn tokens_compare() {
        assert!(super::same_token(b"abc", b"abc"));
        assert!(!super::same_token(b"abc", b"abd"));
        assert!(!super::same_token(b"abc", b"ab"));
    }
}
