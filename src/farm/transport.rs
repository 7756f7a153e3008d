//! The coordinator's transport: one backend per worker, the embedded one
//! (this process's cores) or a `sky worker` over gRPC. A backend connects,
//! greets (Hello: versions, pause state, the optics the worker holds),
//! sends a task with the optics only when the worker lacks them, relays
//! heartbeats and returns the checked tile. When to give up on a silent
//! worker is the scheduler's decision (its lease), told through the
//! assignment's stop signal.

use super::coordinator::{FarmJob, Options, WorkerSpec};
use super::proto::worker_client::WorkerClient;
use super::proto::{self, render_event::Event, WorkerState};
use super::protocol::{classify, TaskError};
use super::scheduler::{Assignment, Stop, Traffic};
use super::{tile, MAX_MESSAGE_BYTES, PROTOCOL_VERSION};
use crate::render::{self, PixelResult};
use prost::Message;
use std::collections::HashSet;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;
use tonic::transport::{Channel, ClientTlsConfig, Endpoint};

// One backend per worker, a handful per render: the size difference of the
// variants does not matter.
#[allow(clippy::large_enum_variant)]
pub(crate) enum Backend {
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
        /// Render threads, from its Hello.
        hello_threads: Option<usize>,
        greeted: bool,
    },
}

/// What a coordinator sent one worker in one render.
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
pub async fn connect(
    uri: &str,
    token: Option<&str>,
    tls: Option<ClientTlsConfig>,
    timeout: Duration,
) -> Result<Client, String> {
    let mut ep = Endpoint::from_shared(uri.to_string())
        .map_err(|e| format!("bad worker address {uri}: {e}"))?
        .connect_timeout(timeout)
        .tcp_nodelay(true);
    if let Some(tls) = tls {
        ep = ep.tls_config(tls).map_err(|e| format!("TLS for {uri}: {e}"))?;
    }
    let channel = ep.connect().await.map_err(|e| format!("cannot connect to {uri}: {}", error_chain(&e)))?;
    let auth = match token {
        Some(t) => Some(
            format!("Bearer {t}")
                .parse()
                .map_err(|_| "the farm token has characters not allowed in a header".to_string())?,
        ),
        None => None,
    };
    Ok(WorkerClient::with_interceptor(channel, Auth(auth))
        .max_decoding_message_size(MAX_MESSAGE_BYTES)
        .max_encoding_message_size(MAX_MESSAGE_BYTES))
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
    pub fn new(spec: &WorkerSpec) -> Result<Backend, String> {
        Ok(match spec {
            WorkerSpec::Local { threads } => {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(*threads)
                    .build()
                    .map_err(|e| format!("cannot start {threads} threads: {e}"))?;
                Backend::Local { pool: Arc::new(pool) }
            }
            WorkerSpec::Remote { uri, .. } => Backend::Remote {
                uri: uri.clone(),
                client: None,
                held: HashSet::new(),
                hello_name: None,
                hello_threads: None,
                greeted: false,
            },
        })
    }

    /// Ok(None) when ready, Ok(Some(reason)) when paused. Connects and says
    /// Hello only when not connected and greeted already.
    pub async fn ready(&mut self, opts: &Options, traffic: &Traffic) -> Result<Option<String>, TaskError> {
        let Backend::Remote { uri, client, held, hello_name, hello_threads, greeted } = self else { return Ok(None) };
        if client.is_some() && *greeted {
            return Ok(None);
        }
        if client.is_none() {
            let c = connect(uri, opts.token.as_deref(), opts.tls.clone(), Duration::from_secs(5))
                .await
                .map_err(TaskError::Failed)?;
            Traffic::add(&traffic.connects, 1);
            *client = Some(c);
        }
        let c = client.as_mut().unwrap();
        Traffic::add(&traffic.hellos, 1);
        let hello = proto::HelloRequest {
            protocol_version: PROTOCOL_VERSION,
            build_version: super::build_version(),
            coordinator: "sky render".into(),
        };
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
        *hello_threads = Some(reply.threads as usize);
        *held = reply.optics_held.iter().cloned().collect();
        if reply.protocol_version != PROTOCOL_VERSION {
            return Err(TaskError::Refused(format!(
                "worker {} at {uri} speaks farm protocol {}, this coordinator {PROTOCOL_VERSION}",
                reply.name, reply.protocol_version
            )));
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
    pub fn unready(&mut self) {
        if let Backend::Remote { greeted, .. } = self {
            *greeted = false;
        }
    }

    /// Drops the connection, so the next task reconnects (and learns from
    /// the worker's Hello which optics it holds).
    pub fn forget(&mut self) {
        if let Backend::Remote { client, held, greeted, .. } = self {
            *client = None;
            held.clear();
            *greeted = false;
        }
    }

    /// The worker's name from its Hello, if it said one.
    pub fn hello_name(&self) -> Option<&str> {
        match self {
            Backend::Remote { hello_name, .. } => hello_name.as_deref(),
            Backend::Local { .. } => None,
        }
    }

    /// The threads it renders on: the embedded worker's pool, a remote
    /// worker's Hello (None before it).
    pub fn threads(&self) -> Option<usize> {
        match self {
            Backend::Remote { hello_threads, .. } => *hello_threads,
            Backend::Local { pool } => Some(pool.current_num_threads()),
        }
    }

    /// Runs task `t` to its checked columns: `beat` is called for every
    /// sign of life (the embedded worker's ticks, a remote's heartbeats);
    /// the task ends Cancelled when its stop signal or `stop_all` says so
    /// (a task carrying optics only once they are uploaded, within `lease`).
    pub async fn run(
        &mut self,
        t: &Assignment,
        job: &FarmJob,
        (inflight, preparing): (&Arc<AtomicU64>, &AtomicBool),
        traffic: &Traffic,
        lease: Duration,
        beat: &(dyn Fn() + Send + Sync),
        stop_all: &AtomicBool,
    ) -> Result<Vec<Vec<PixelResult>>, TaskError> {
        let stopped =
            |rx: &tokio::sync::watch::Receiver<Stop>| *rx.borrow() != Stop::Run || stop_all.load(Ordering::Relaxed);
        let s = &job.settings;
        let want = tile::Expect {
            job_hash: &job.hash,
            task_id: t.id,
            first_column: t.first,
            columns: t.count,
            height: s.view.height as u32,
            lines: s.spectral.spectral_nm.len() as u32,
            spp: s.view.spp,
        };
        match self {
            Backend::Local { pool } => {
                let flag = Arc::new(AtomicBool::new(false));
                let work = {
                    let (pool, scene, flag, inflight, job_settings) =
                        (pool.clone(), job.optics.scene.clone(), flag.clone(), inflight.clone(), s.clone());
                    let (first, count) = (t.first as usize, t.count as usize);
                    tokio::task::spawn_blocking(move || {
                        pool.install(|| {
                            render::render_columns(&scene, &job_settings.view, first, count, &flag, &|| {
                                inflight.fetch_add(1, Ordering::Relaxed);
                            })
                        })
                    })
                };
                let mut rx = t.stop.clone();
                let mut work = work;
                let mut tick = tokio::time::interval(Duration::from_millis(100));
                let cols = loop {
                    tokio::select! {
                        r = &mut work => break r.map_err(|e| TaskError::Failed(format!("render task panicked: {e}")))?,
                        _ = rx.changed() => flag.store(true, Ordering::Relaxed),
                        _ = tick.tick() => {
                            beat();
                            if stopped(&rx) {
                                flag.store(true, Ordering::Relaxed);
                            }
                        }
                    }
                };
                let Some(cols) = cols else { return Err(TaskError::Cancelled) };
                // Through the wire format and its checks, like a remote tile.
                let tile =
                    tile::encode(&job.hash, t.id, t.first, s.view.height as u32, s.spectral.spectral_nm.len(), &cols);
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
                    let mut rx = t.stop.clone();
                    let call = if send_optics {
                        // Optics are not abandoned halfway (the worker keeps
                        // what arrives whole, and counts as holding it),
                        // however long the upload: no more than a lease.
                        match tokio::time::timeout(lease, c.render(task)).await {
                            Err(_) => {
                                return Err(TaskError::Failed(format!(
                                    "{uri}: the task with its optics took longer than the lease of {lease:?}"
                                )))
                            }
                            Ok(r) => r,
                        }
                    } else {
                        tokio::select! {
                            r = c.render(task) => r,
                            _ = rx.changed() => return Err(TaskError::Cancelled),
                        }
                    };
                    match call {
                        Err(status) => match classify(&status) {
                            // Evicted since its Hello: send them.
                            TaskError::OpticsMissing if !send_optics => {
                                held.remove(optics_hash);
                                send_optics = true;
                            }
                            TaskError::OpticsMissing => {
                                return Err(TaskError::Failed(format!("{uri}: asked for the optics it was just sent")))
                            }
                            e => return Err(e),
                        },
                        Ok(r) => break r.into_inner(),
                    }
                };
                held.insert(optics_hash.clone());
                beat();
                let mut rx = t.stop.clone();
                let mut tick = tokio::time::interval(Duration::from_millis(250));
                loop {
                    if stopped(&rx) {
                        return Err(TaskError::Cancelled);
                    }
                    tokio::select! {
                        _ = rx.changed() => {}
                        _ = tick.tick() => {}
                        m = stream.message() => match m {
                            Err(status) => return Err(classify(&status)),
                            Ok(None) => return Err(TaskError::Failed(format!("{uri}: the task's stream ended without a tile"))),
                            Ok(Some(ev)) => match ev.event {
                                Some(Event::Heartbeat(h)) => {
                                    beat();
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
