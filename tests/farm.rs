//! The render farm on loopback, with real `sky worker` processes: renders
//! across workers are bit-identical to a local render whatever happens to
//! the workers (killed, stalled, sending garbage or wrong results) or to
//! the coordinator (killed and resumed); bad calls (a wrong token, another
//! protocol, garbage bytes, an oversized message) get clear errors while
//! the workers keep serving.

use sky::farm::coordinator::connect;
use sky::farm::proto;
use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

const SKY: &str = env!("CARGO_BIN_EXE_sky");

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A small render: the analytic-HG atmosphere needs no Mie tables, so the
/// workers prepare it in a moment.
fn render_args(out: &Path) -> Vec<String> {
    let atm = root().join("atmospheres/analytic-hg.toml");
    [
        "render",
        atm.to_str().unwrap(),
        "--camera",
        "equirect",
        "--size",
        "32x6",
        "--spp",
        "12",
        "--sun-zenith-deg",
        "70",
        "--seed",
        "5",
        "--out",
        out.to_str().unwrap(),
    ]
    .iter()
    .map(|s| s.to_string())
    .collect()
}

struct Worker {
    child: Child,
    addr: String,
}

impl Drop for Worker {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

struct Farm {
    dir: tempfile::TempDir,
    workers: Vec<Worker>,
}

impl Farm {
    fn new() -> Farm {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("token"), "s3cret-farm-token\n").unwrap();
        std::fs::write(dir.path().join("wrong-token"), "not-the-token\n").unwrap();
        Farm { dir, workers: Vec::new() }
    }

    fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }

    /// Starts a worker with extra (fault) flags; returns its index. Its
    /// load policy is off: the other workers of a test would be its "owner".
    fn start(&mut self, name: &str, extra: &[&str]) -> usize {
        self.spawn(&[&["--owner-load-limit", "1", "--name", name], extra].concat())
    }

    /// Starts `sky worker` with these flags besides the listen address,
    /// threads, priority and token.
    fn spawn(&mut self, flags: &[&str]) -> usize {
        let mut child = Command::new(SKY)
            .args(["worker", "--listen", "127.0.0.1:0", "--threads", "1", "--nice", "0"])
            .arg("--token-file")
            .arg(self.path("token"))
            .args(flags)
            .env("SKY_CACHE_DIR", "off")
            .env("SKY_FAULT_INJECTION", "1")
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap()).read_line(&mut line).unwrap();
        let addr =
            line.trim().strip_prefix("listening on ").unwrap_or_else(|| panic!("worker said {line:?}")).to_string();
        self.workers.push(Worker { child, addr });
        self.workers.len() - 1
    }

    fn list(&self, which: &[usize]) -> String {
        which.iter().map(|&i| self.workers[i].addr.clone()).collect::<Vec<_>>().join(",")
    }

    /// `sky render` across the given workers with extra flags.
    fn render(&self, out: &str, which: &[usize], extra: &[&str]) -> Output {
        let mut args = render_args(&self.path(out));
        args.extend([
            "--workers".to_string(),
            self.list(which),
            "--token-file".to_string(),
            self.path("token").to_str().unwrap().to_string(),
        ]);
        args.extend(extra.iter().map(|s| s.to_string()));
        Command::new(SKY)
            .args(&args)
            .env("SKY_CACHE_DIR", sky::mie::MieCache::test_dir())
            .env("SKY_FAULT_INJECTION", "1")
            .output()
            .unwrap()
    }

    /// The local render with the embedded worker, as reference.
    fn local(&self, out: &str) -> Vec<u8> {
        let o = Command::new(SKY)
            .args(render_args(&self.path(out)))
            .env("SKY_CACHE_DIR", sky::mie::MieCache::test_dir())
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        std::fs::read(self.path(out)).unwrap()
    }

    fn alive(&mut self, i: usize) -> bool {
        self.workers[i].child.try_wait().unwrap().is_none()
    }
}

fn same_file(a: &[u8], path: &Path) -> bool {
    let b = std::fs::read(path).unwrap_or_default();
    blake3::hash(a) == blake3::hash(&b)
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The JSON summary line (`{"event": "done", ...}`) of a --json-progress run.
fn summary(o: &Output) -> serde_json::Value {
    let out = String::from_utf8_lossy(&o.stdout);
    let line = out
        .lines()
        .rev()
        .find(|l| l.contains("\"done\""))
        .unwrap_or_else(|| panic!("no summary in {out}\n{}", stderr(o)));
    serde_json::from_str(line).unwrap()
}

#[test]
fn three_workers_render_bit_identically_to_a_local_render() {
    let mut farm = Farm::new();
    let local = farm.local("local.exr");
    for n in ["a", "b", "c"] {
        farm.start(n, &[]);
    }
    let o = farm.render("farm.exr", &[0, 1, 2], &["--json-progress"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(same_file(&local, &farm.path("farm.exr")), "farm and local renders differ");
    let s = summary(&o);
    assert_eq!(s["farm"]["columns_rendered"], 32);
    // The image went out in several tasks, and no worker was lost. (Which
    // worker did how much depends on timing: a slow starter's first task may
    // be duplicated and won by a faster one.)
    assert!(s["farm"]["tasks"].as_u64().unwrap() >= 3, "{s}");
    let workers = s["farm"]["workers"].as_array().unwrap();
    assert_eq!(workers.len(), 3);
    // Unnamed on the command line, each worker goes by its own --name.
    let mut names: Vec<&str> = workers.iter().map(|w| w["name"].as_str().unwrap()).collect();
    names.sort();
    assert_eq!(names, ["a", "b", "c"], "{s}");
    assert!(workers.iter().all(|w| w["quarantined"].is_null()), "{s}");
    let columns: u64 = workers.iter().map(|w| w["columns_done"].as_u64().unwrap()).sum();
    assert!(columns >= 32, "{s}");
    assert!(!farm.path("farm.exr.journal").exists(), "the journal is removed after success");
}

#[test]
fn killed_stalled_and_garbage_workers_do_not_change_the_result() {
    let mut farm = Farm::new();
    let local = farm.local("local.exr");
    farm.start("good", &[]);
    farm.start("killed", &["--fault-sigkill-on-task", "0"]);
    farm.start("stalled", &["--fault-stall-after", "0"]);
    farm.start("garbage", &["--fault-corrupt"]);
    let o = farm.render("farm.exr", &[0, 1, 2, 3], &["--json-progress", "--lease-s", "5"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(same_file(&local, &farm.path("farm.exr")), "the result changed");
    assert!(!farm.alive(1), "the killed worker should be dead");
    let s = summary(&o);
    let workers = s["farm"]["workers"].as_array().unwrap();
    // The garbage worker's tiles were refused every time: quarantined.
    let g = workers.iter().find(|w| w["address"] == farm.workers[3].addr).unwrap().clone();
    assert!(g["quarantined"].is_string(), "{g}");
    assert_eq!(g["columns_done"], 0, "{g}");
    assert!(s["farm"]["requeued"].as_u64().unwrap() >= 3, "{s}");
    // With --json-progress the farm's events are JSON lines on stdout.
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.lines()
            .any(|l| l.contains("\"event\":\"quarantined\"") && l.contains("invalid result: tile value 0 is NaN")),
        "no quarantine event for the garbage worker in\n{out}"
    );
    // The stalled worker never delivered; its task was re-queued after the
    // lease or duplicated and won elsewhere.
    let st = workers.iter().find(|w| w["address"] == farm.workers[2].addr).unwrap();
    assert_eq!(st["tasks_done"], 0, "{s}");
}

#[test]
fn a_killed_coordinator_resumes_without_rendering_twice() {
    let mut farm = Farm::new();
    let local = farm.local("local.exr");
    farm.start("a", &[]);
    farm.start("b", &[]);
    let o = farm.render("farm.exr", &[0, 1], &["--fault-kill-after-columns", "10"]);
    assert!(!o.status.success());
    assert!(!farm.path("farm.exr").exists(), "a killed render must not leave an image");
    assert!(farm.path("farm.exr.journal").exists());
    let o = farm.render("farm.exr", &[0, 1], &["--resume", "--json-progress"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(same_file(&local, &farm.path("farm.exr")), "the resumed render differs");
    let s = summary(&o);
    let resumed = s["farm"]["columns_resumed"].as_u64().unwrap();
    let rendered = s["farm"]["columns_rendered"].as_u64().unwrap();
    assert!(resumed >= 10, "{s}");
    assert_eq!(resumed + rendered, 32, "columns rendered twice or lost: {s}");
    // And the workers rendered exactly the missing columns (duplicates aside).
    let dup = s["farm"]["duplicates"].as_u64().unwrap();
    let by_workers: u64 =
        s["farm"]["workers"].as_array().unwrap().iter().map(|w| w["columns_done"].as_u64().unwrap()).sum();
    assert!(by_workers >= rendered && (dup > 0 || by_workers == rendered), "{s}");
}

/// Kills and reaps a child process however the test ends (a panicking
/// assertion included).
struct Reap(Option<Child>);

impl Reap {
    /// Waits for the child and takes its output.
    fn output(mut self) -> Output {
        self.0.take().unwrap().wait_with_output().unwrap()
    }
}

impl Drop for Reap {
    fn drop(&mut self) {
        if let Some(c) = &mut self.0 {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

#[test]
fn verification_catches_a_worker_with_wrong_results() {
    use proto::{ControlAction, ControlRequest};
    let mut farm = Farm::new();
    let local = farm.local("local.exr");
    let a = farm.start("a", &[]);
    let b = farm.start("b", &[]);
    let liar = farm.start("liar", &["--fault-perturb"]);
    // First phase: the honest workers are paused, so the liar renders
    // every column there is (its tiles are wrong by one ulp in their first
    // value). Paused workers stay in the farm: the coordinator keeps the
    // liar's columns queued for verification until someone else is back.
    for w in [a, b] {
        unsafe {
            libc::kill(farm.workers[w].child.id() as i32, libc::SIGUSR1);
        }
    }
    std::thread::sleep(Duration::from_millis(300));
    let mut args = render_args(&farm.path("farm.exr"));
    args.extend([
        "--workers".to_string(),
        farm.list(&[a, b, liar]),
        "--token-file".to_string(),
        farm.path("token").to_str().unwrap().to_string(),
    ]);
    args.extend(["--json-progress", "--verify-fraction", "1"].map(String::from));
    let render = Reap(Some(
        Command::new(SKY)
            .args(&args)
            .env("SKY_CACHE_DIR", sky::mie::MieCache::test_dir())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    ));
    // Wait (via the liar's Control RPC, which with no action only reports)
    // until the liar has delivered the whole image.
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    let uri = format!("http://{}", farm.workers[liar].addr);
    let (tasks, columns) = rt.block_on(async {
        let mut c = connect(&uri, Some("s3cret-farm-token"), None, Duration::from_secs(5)).await.unwrap();
        for _ in 0..600 {
            let r = c.control(ControlRequest { action: ControlAction::Unspecified as i32 }).await.unwrap().into_inner();
            if r.columns_done >= 32 {
                return (r.tasks_done, r.columns_done);
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
        panic!("the liar did not render the image alone within a minute");
    });
    assert!(tasks >= 1 && columns >= 32, "{tasks} tasks, {columns} columns");
    // Second phase: the honest workers come back and verify.
    for w in [a, b] {
        unsafe {
            libc::kill(farm.workers[w].child.id() as i32, libc::SIGUSR2);
        }
    }
    let o = render.output();
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(same_file(&local, &farm.path("farm.exr")), "a wrong result got through");
    let s = summary(&o);
    let workers = s["farm"]["workers"].as_array().unwrap();
    let w_liar = workers.iter().find(|w| w["address"] == farm.workers[liar].addr).unwrap();
    // The liar's columns came out as mismatches when rendered again, a
    // third opinion convicted it, and the honest workers were never blamed.
    assert!(w_liar["tasks_done"].as_u64().unwrap() >= 1, "{s}");
    assert!(w_liar["quarantined"].as_str().unwrap_or("").contains("differed bit for bit"), "{s}");
    assert!(s["farm"]["verify_mismatches"].as_u64().unwrap() >= 1, "{s}");
    for honest in [a, b] {
        let w = workers.iter().find(|w| w["address"] == farm.workers[honest].addr).unwrap();
        assert!(w["quarantined"].is_null(), "{s}");
    }
    assert!(s["farm"]["columns_verified"].as_u64().unwrap() >= 1, "{s}");
}

#[test]
fn bad_calls_get_clear_errors_and_workers_keep_serving() {
    let mut farm = Farm::new();
    let good = farm.start("good", &[]);
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    let uri = format!("http://{}", farm.workers[good].addr);
    let hello = || proto::HelloRequest {
        protocol_version: sky::farm::PROTOCOL_VERSION,
        build_version: sky::farm::build_version(),
        coordinator: "test".into(),
    };
    rt.block_on(async {
        // A wrong token.
        let mut c = connect(&uri, Some("not-the-token"), None, Duration::from_secs(5)).await.unwrap();
        let e = c.hello(hello()).await.unwrap_err();
        assert_eq!(e.code(), tonic::Code::Unauthenticated);
        assert!(e.message().contains("wrong farm token"), "{e}");
        // No token.
        let mut c = connect(&uri, None, None, Duration::from_secs(5)).await.unwrap();
        let e = c.hello(hello()).await.unwrap_err();
        assert!(e.message().contains("missing farm token"), "{e}");
        // Another protocol version in a task.
        let mut c = connect(&uri, Some("s3cret-farm-token"), None, Duration::from_secs(5)).await.unwrap();
        let pv = sky::farm::PROTOCOL_VERSION;
        let task = proto::RenderTask {
            protocol_version: 99,
            build_version: sky::farm::build_version(),
            job_hash: "x".into(),
            task_id: 1,
            first_column: 0,
            columns: 1,
            ..Default::default()
        };
        let e = c.render(task).await.expect_err("refused");
        assert_eq!(e.code(), tonic::Code::FailedPrecondition);
        assert!(e.message().contains(&format!("farm protocol {pv}")) && e.message().contains("protocol 99"), "{e}");
        // An oversized message (a 70 MiB data file in the optics).
        let big = proto::Optics {
            protocol_version: pv,
            build_version: sky::farm::build_version(),
            files: vec![proto::DataFile { name: "big.csv".into(), content: vec![b'1'; 70 << 20] }],
            ..Default::default()
        };
        let task = proto::RenderTask {
            protocol_version: pv,
            build_version: sky::farm::build_version(),
            job_hash: "x".into(),
            optics: Some(big),
            task_id: 2,
            first_column: 0,
            columns: 1,
            ..Default::default()
        };
        let mut big_client = c.clone().max_encoding_message_size(usize::MAX);
        let e = big_client.render(task).await.expect_err("refused");
        assert!(
            matches!(e.code(), tonic::Code::ResourceExhausted | tonic::Code::OutOfRange | tonic::Code::InvalidArgument),
            "{e:?}"
        );
        assert!(
            e.message().to_lowercase().contains("message")
                || e.message().contains("size")
                || e.message().contains("large"),
            "{e:?}"
        );
        // A task whose optics and view do not match the job it claims.
        let task = proto::RenderTask {
            protocol_version: pv,
            build_version: sky::farm::build_version(),
            job_hash: "not-its-hash".into(),
            task_id: 3,
            first_column: 0,
            columns: 1,
            ..Default::default()
        };
        let e = c.render(task).await.expect_err("refused");
        assert_eq!(e.code(), tonic::Code::InvalidArgument);
        assert!(e.message().contains("hash to"), "{e}");
    });
    // Garbage bytes on the port: the connection is dropped...
    let mut s = std::net::TcpStream::connect(&farm.workers[good].addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    s.write_all(b"GET / HTTP/1.0\r\n\r\n\x00\x01\x02 garbage \xff\xfe").unwrap();
    let mut buf = Vec::new();
    let _ = s.read_to_end(&mut buf);
    drop(s);
    // ...and the worker still serves.
    rt.block_on(async {
        let mut c = connect(&uri, Some("s3cret-farm-token"), None, Duration::from_secs(5)).await.unwrap();
        let r = c.hello(hello()).await.unwrap().into_inner();
        assert_eq!(r.name, "good");
    });
    // A wrong token fails the render clearly.
    let mut args = render_args(&farm.path("tok.exr"));
    args.extend([
        "--workers".into(),
        farm.list(&[good]),
        "--token-file".into(),
        farm.path("wrong-token").to_str().unwrap().into(),
    ]);
    let o = Command::new(SKY).args(&args).env("SKY_CACHE_DIR", sky::mie::MieCache::test_dir()).output().unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("refused the token"), "{}", stderr(&o));
    // The worker is still alive and serving after all that.
    assert!(farm.alive(good));
    let o = farm.render("ok.exr", &[good], &[]);
    assert!(o.status.success(), "{}", stderr(&o));
}

/// A coordinator refuses a worker of another protocol (one that claims 99),
/// with a message naming both versions, and writes nothing.
#[test]
fn a_worker_of_another_protocol_is_refused() {
    let mut farm = Farm::new();
    let old = farm.start("old", &["--fault-protocol", "99"]);
    let o = farm.render("old.exr", &[old], &[]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains(&format!("speaks farm protocol 99, this coordinator {}", sky::farm::PROTOCOL_VERSION)),
        "{}",
        stderr(&o)
    );
    assert!(!farm.path("old.exr").exists());
    assert!(farm.alive(old));
}

#[test]
fn a_paused_worker_gives_its_work_back() {
    let mut farm = Farm::new();
    let local = farm.local("local.exr");
    let a = farm.start("a", &[]);
    let b = farm.start("b", &[]);
    // Pause b by signal before the render: it takes no task.
    unsafe {
        libc::kill(farm.workers[b].child.id() as i32, libc::SIGUSR1);
    }
    std::thread::sleep(Duration::from_millis(300));
    let o = farm.render("farm.exr", &[a, b], &["--json-progress"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(same_file(&local, &farm.path("farm.exr")));
    let s = summary(&o);
    let wb =
        s["farm"]["workers"].as_array().unwrap().iter().find(|w| w["address"] == farm.workers[b].addr).unwrap().clone();
    assert_eq!(wb["tasks_done"], 0, "{s}");
    assert!(wb["state"].as_str().unwrap().contains("paused"), "{s}");
}

#[test]
fn workers_speak_tls_when_given_a_certificate() {
    let mut farm = Farm::new();
    let local = farm.local("local.exr");
    // A CA and a worker certificate for "sky-farm-test".
    let ca_key = rcgen::KeyPair::generate().unwrap();
    let mut ca_params = rcgen::CertificateParams::new(Vec::<String>::new()).unwrap();
    ca_params.is_ca = rcgen::IsCa::Ca(rcgen::BasicConstraints::Unconstrained);
    let ca = ca_params.self_signed(&ca_key).unwrap();
    let key = rcgen::KeyPair::generate().unwrap();
    let issuer = rcgen::Issuer::from_params(&ca_params, &ca_key);
    let cert =
        rcgen::CertificateParams::new(vec!["sky-farm-test".to_string()]).unwrap().signed_by(&key, &issuer).unwrap();
    std::fs::write(farm.path("ca.pem"), ca.pem()).unwrap();
    std::fs::write(farm.path("cert.pem"), cert.pem()).unwrap();
    std::fs::write(farm.path("key.pem"), key.serialize_pem()).unwrap();
    let (c, k) = (farm.path("cert.pem"), farm.path("key.pem"));
    farm.start("tls", &["--tls-cert", c.to_str().unwrap(), "--tls-key", k.to_str().unwrap()]);
    // A farm file with the CA and the name in the certificate.
    let farm_toml = format!("token_file = \"token\"\n[tls]\nca = \"ca.pem\"\ndomain = \"sky-farm-test\"\n[[worker]]\nname = \"tls\"\naddress = \"{}\"\n", farm.workers[0].addr);
    std::fs::write(farm.path("farm.toml"), farm_toml).unwrap();
    let mut args = render_args(&farm.path("farm.exr"));
    args.extend(["--farm".to_string(), farm.path("farm.toml").to_str().unwrap().to_string()]);
    let o = Command::new(SKY).args(&args).env("SKY_CACHE_DIR", sky::mie::MieCache::test_dir()).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(same_file(&local, &farm.path("farm.exr")));
    // Plain text to a TLS worker fails clearly, and the worker keeps serving.
    let o = farm.render("plain.exr", &[0], &[]);
    assert_eq!(o.status.code(), Some(1));
    assert!(!farm.path("plain.exr").exists());
    assert!(farm.alive(0));
}

#[test]
fn pausing_mid_task_hands_the_task_back_and_resume_restores_work() {
    use proto::render_event::Event;
    use proto::{ControlAction, ControlRequest, WorkerState};
    let mut farm = Farm::new();
    let w = farm.start("w", &[]);
    // A long task: four directions at a million samples each.
    let (atm, bundle) = sky::atmosphere::Atmosphere::load_bundle(&root().join("atmospheres/analytic-hg.toml")).unwrap();
    let mut settings = sky::render::Settings::directions(
        vec![(60.0, 0.0), (70.0, 90.0), (80.0, 180.0), (85.0, 0.0)],
        60.0,
        vec![],
        1_000_000,
        1,
        false,
    );
    settings.spectral.xyz = true;
    // Optics without a prepared scene: the worker prepares them itself.
    let optics = sky::farm::job::message(&bundle, &settings.spectral, None);
    let optics_hash = sky::farm::job::optics_hash(&atm, &settings.spectral);
    let view_json = serde_json::to_string(&settings.view).unwrap();
    let task = |id: u64, optics: Option<proto::Optics>| proto::RenderTask {
        protocol_version: sky::farm::PROTOCOL_VERSION,
        build_version: sky::farm::build_version(),
        job_hash: sky::farm::job::job_hash(&optics_hash, &view_json),
        task_id: id,
        first_column: 0,
        columns: 4,
        optics_hash: optics_hash.clone(),
        optics,
        view_json: view_json.clone(),
    };
    let uri = format!("http://{}", farm.workers[w].addr);
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    rt.block_on(async {
        let mut c = connect(&uri, Some("s3cret-farm-token"), None, Duration::from_secs(5)).await.unwrap();
        // Optics it lacks and the task does not carry: a typed NOT_FOUND.
        let e = c.render(task(0, None)).await.expect_err("optics missing");
        assert_eq!(e.code(), tonic::Code::NotFound);
        let refusal = <proto::TaskRefusal as prost::Message>::decode(e.details()).unwrap();
        assert_eq!(refusal.missing, proto::Missing::Optics as i32, "{e:?}");
        let mut stream = c.render(task(1, Some(optics.clone()))).await.unwrap().into_inner();
        // Wait until it renders (past preparing the optics).
        loop {
            match stream.message().await.unwrap().unwrap().event {
                Some(Event::Heartbeat(h)) if !h.preparing => break,
                Some(Event::Tile(_)) => panic!("the task finished too soon to be paused"),
                _ => {}
            }
        }
        let r = c.control(ControlRequest { action: ControlAction::Pause as i32 }).await.unwrap().into_inner();
        assert_eq!(r.state, WorkerState::Paused as i32);
        assert_eq!(r.paused_reason, "rpc");
        // The running task comes back at once as "paused"...
        let e = loop {
            match stream.message().await {
                Err(e) => break e,
                Ok(Some(ev)) => assert!(!matches!(ev.event, Some(Event::Tile(_))), "a paused worker finished its task"),
                Ok(None) => panic!("the stream ended without saying why"),
            }
        };
        assert_eq!(e.code(), tonic::Code::Unavailable);
        assert!(e.message().starts_with("paused"), "{e}");
        // ...and new tasks are refused while paused.
        let e = c.render(task(2, None)).await.expect_err("refused while paused");
        assert_eq!(e.code(), tonic::Code::Unavailable);
        assert!(e.message().contains("paused (rpc)"), "{e}");
        let r = c.control(ControlRequest { action: ControlAction::Resume as i32 }).await.unwrap().into_inner();
        assert_eq!(r.state, WorkerState::Idle as i32);
        // Resumed, it takes the job again (it kept the prepared optics, and
        // says so in its Hello).
        let hello = proto::HelloRequest {
            protocol_version: sky::farm::PROTOCOL_VERSION,
            build_version: sky::farm::build_version(),
            coordinator: "test".into(),
        };
        assert_eq!(c.hello(hello).await.unwrap().into_inner().optics_held, vec![optics_hash.clone()]);
        let mut stream = c.render(task(3, None)).await.unwrap().into_inner();
        let first = stream.message().await.unwrap().unwrap();
        assert!(matches!(first.event, Some(Event::Heartbeat(_))));
    });
}

/// The owner comes first: outside its schedule a worker is paused from the
/// start, and while other programs keep the CPU busy it pauses itself.
#[test]
fn schedule_and_owner_load_pause_a_worker() {
    use proto::WorkerState;
    // A window that starts two hours from now (local time): not now.
    let now_min = unsafe {
        let t = libc::time(std::ptr::null_mut());
        let mut tm: libc::tm = std::mem::zeroed();
        libc::localtime_r(&t, &mut tm);
        (tm.tm_hour * 60 + tm.tm_min) as u32
    };
    let (a, b) = ((now_min + 120) % 1440, (now_min + 180) % 1440);
    let window = format!("{:02}:{:02}-{:02}:{:02}", a / 60, a % 60, b / 60, b % 60);
    let mut farm = Farm::new();
    let off_hours = farm.start("off-hours", &["--schedule", &window]);
    // The load policy: the other tests' workers turn it off; this one keeps it.
    let polite = farm.spawn(&["--owner-load-limit", "0.3", "--name", "polite"]);
    let polite_addr = farm.workers[polite].addr.clone();
    // The owner's programs: one busy loop per core, stopped and joined when
    // `_hogs` drops, also when an assertion below fails.
    let cores = std::thread::available_parallelism().map(|n| n.get()).unwrap_or(2);
    let _hogs = Hogs::start(cores);
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    let hello = || proto::HelloRequest {
        protocol_version: sky::farm::PROTOCOL_VERSION,
        build_version: sky::farm::build_version(),
        coordinator: "test".into(),
    };
    let result = rt.block_on(async {
        let mut c = connect(
            &format!("http://{}", farm.workers[off_hours].addr),
            Some("s3cret-farm-token"),
            None,
            Duration::from_secs(5),
        )
        .await
        .unwrap();
        let r = c.hello(hello()).await.unwrap().into_inner();
        assert_eq!((r.state, r.paused_reason.as_str()), (WorkerState::Paused as i32, "schedule"), "window {window}");
        // The load policy samples every 5 s and pauses after two busy samples.
        let mut c = connect(&format!("http://{polite_addr}"), Some("s3cret-farm-token"), None, Duration::from_secs(5))
            .await
            .unwrap();
        for _ in 0..60 {
            let r = c.hello(hello()).await.unwrap().into_inner();
            if r.state == WorkerState::Paused as i32 {
                return Ok(r.paused_reason);
            }
            tokio::time::sleep(Duration::from_millis(500)).await;
        }
        Err("the worker never paused under load")
    });
    assert_eq!(result, Ok("load".to_string()));
    // A render on the paused worker alone says why it waits, in its log
    // (stderr is not a terminal here), instead of waiting in silence.
    let mut args = render_args(&farm.path("waiting.exr"));
    args.extend([
        "--workers".to_string(),
        farm.list(&[off_hours]),
        "--token-file".to_string(),
        farm.path("token").to_str().unwrap().to_string(),
    ]);
    let mut child = Command::new(SKY)
        .args(&args)
        .env("SKY_CACHE_DIR", sky::mie::MieCache::test_dir())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let err = child.stderr.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        use std::io::BufRead;
        for line in std::io::BufReader::new(err).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    let mut said = None;
    while let Ok(line) = rx.recv_timeout(Duration::from_secs(60)) {
        if line.contains("waiting: no worker can render") {
            said = Some(line);
            break;
        }
    }
    let _ = child.kill();
    let _ = child.wait();
    let said = said.expect("the render never said why it waits");
    assert!(said.contains("off-hours: paused (schedule)"), "{said}");
}

/// Busy threads standing in for the owner's programs (the worker's load
/// policy reads the whole machine's CPU time); dropping this stops and
/// joins them, so a failing test does not leave them spinning.
struct Hogs {
    stop: Arc<AtomicBool>,
    threads: Vec<std::thread::JoinHandle<()>>,
}

impl Hogs {
    fn start(n: usize) -> Hogs {
        let stop = Arc::new(AtomicBool::new(false));
        let threads = (0..n)
            .map(|_| {
                let stop = stop.clone();
                std::thread::spawn(move || {
                    while !stop.load(Ordering::Relaxed) {
                        std::hint::spin_loop();
                    }
                })
            })
            .collect();
        Hogs { stop, threads }
    }
}

impl Drop for Hogs {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

/// The clear sky (its optics weigh about 19 MB) and a tiny equirect view
/// of it at 4 spp, hero wavelengths.
fn clear_equirect(
    width: usize,
    height: usize,
) -> (sky::atmosphere::Atmosphere, sky::atmosphere::Bundle, sky::render::Settings) {
    use sky::directions::Camera;
    use sky::render::{Settings, WavelengthSampling};
    let (atm, bundle) = sky::atmosphere::Atmosphere::load_bundle(&root().join("atmospheres/clear.toml")).unwrap();
    let mut s = Settings::directions(vec![], 60.0, vec![], 4, 3, false);
    s.spectral.xyz = true;
    s.spectral.wavelength_sampling = WavelengthSampling::Hero;
    s.view.camera = Camera::Equirect;
    (s.view.width, s.view.height) = (width, height);
    (atm, bundle, s)
}

/// A bake-shaped run: one atmosphere (the clear sky, whose optics weigh
/// about 19 MB), 64 tiny views through one session over two workers. Each
/// worker is connected and greeted once and gets the optics at most once;
/// every view is bit-identical to a direct render. Prints the bytes each
/// worker was sent against what protocol 1 sent (the job with its optics on
/// the first task of every view): `cargo test --release --test suite --
/// farm::a_bake --nocapture`.
#[test]
fn a_bake_of_64_views_sends_each_worker_the_optics_once() {
    use sky::farm::coordinator::{Options, WorkerSpec};
    use sky::session::{OpticsCache, Session};
    let mut farm = Farm::new();
    let a = farm.start("a", &[]);
    let b = farm.start("b", &[]);
    let (atm, bundle, s) = clear_equirect(4, 4);
    let workers: Vec<WorkerSpec> = [a, b]
        .iter()
        .map(|&i| WorkerSpec::Remote { name: None, uri: format!("http://{}", farm.workers[i].addr) })
        .collect();
    let opts = Options { token: Some("s3cret-farm-token".into()), ..Options::default() };
    let session = Session::new(
        atm,
        bundle,
        s.spectral.clone(),
        &OpticsCache::default(),
        &sky::mie::MieCache::shared_by_tests(),
        workers,
        opts,
        &|| {},
    );
    let job = session.job(&s.view);
    let optics_bytes = prost::Message::encoded_len(job.optics.message()) as u64;
    let protocol1_job_bytes = optics_bytes + job.view_json.len() as u64;
    assert!(optics_bytes > 10_000_000, "the clear sky's optics weigh {optics_bytes} bytes");
    // Per worker (by address): connects, hellos, optics sent, their bytes,
    // all request bytes, tasks, and the views it rendered in.
    let mut totals: std::collections::BTreeMap<String, [u64; 7]> = Default::default();
    for i in 0..64 {
        let mut view = s.view.clone();
        view.sun_zenith_deg = 1.0 + 1.4 * i as f64;
        view.sun_azimuth_deg = (37 * i % 360) as f64;
        let r =
            session.render_view(&view, Arc::new(AtomicBool::new(false))).unwrap_or_else(|e| panic!("view {i}: {e}"));
        if i % 16 == 0 {
            let want = sky::render::render(&session.scene, &view, &AtomicBool::new(false), &|| {}).unwrap();
            assert!(r.image == want, "view {i}: the farm's render differs from a direct one");
        }
        for w in &r.stats.workers {
            let t = totals.entry(w.address.clone()).or_default();
            for (k, v) in [
                w.connects,
                w.hellos,
                w.optics_sent,
                w.optics_bytes,
                w.request_bytes,
                w.tasks_done,
                (w.tasks_done > 0) as u64,
            ]
            .into_iter()
            .enumerate()
            {
                t[k] += v;
            }
        }
    }
    assert_eq!(totals.len(), 2);
    eprintln!(
        "64 views of {}x{} px, clear sky (optics {:.1} MB), 2 workers:",
        s.view.width,
        s.view.height,
        optics_bytes as f64 / 1e6
    );
    for (addr, [connects, hellos, optics_sent, sent_optics_bytes, request_bytes, tasks, views]) in &totals {
        eprintln!(
            "  worker {addr}: {tasks} tasks in {views} views; {connects} connection, {hellos} hello; optics sent {optics_sent}x ({:.1} MB); all requests {:.2} MB (protocol 1: {:.0} MB, the job on the first task of each of its {views} views)",
            *sent_optics_bytes as f64 / 1e6,
            *request_bytes as f64 / 1e6,
            (views * protocol1_job_bytes) as f64 / 1e6
        );
        assert!(*tasks > 0, "worker {addr} rendered nothing: {totals:?}");
        assert_eq!((*connects, *hellos), (1, 1), "worker {addr} was connected or greeted again across the views");
        assert_eq!(*optics_sent, 1, "worker {addr} got the optics {optics_sent} times");
        assert_eq!(*sent_optics_bytes, optics_bytes);
        // Everything but the one copy of the optics is small: views and headers.
        assert!(
            *request_bytes < optics_bytes + 2_000 * tasks,
            "worker {addr}: {request_bytes} bytes for {tasks} tasks"
        );
    }
}

/// Views of two atmospheres in one queue on one farm (what a bake does
/// with its basis skies): each comes back bit-identical to a direct render,
/// each worker is connected and greeted once and gets each atmosphere's
/// optics at most once, and the cost of the whole is measured per part.
#[test]
fn two_atmospheres_render_in_one_queue_on_one_farm() {
    use sky::farm::coordinator::{FarmPart, Options, WorkerSpec};
    use sky::session::{image_of_columns, OpticsCache, Session, SharedFarm};
    let mut farm = Farm::new();
    let a = farm.start("a", &[]);
    let b = farm.start("b", &[]);
    let workers: Vec<WorkerSpec> = [a, b]
        .iter()
        .map(|&i| WorkerSpec::Remote { name: None, uri: format!("http://{}", farm.workers[i].addr) })
        .collect();
    let shared = SharedFarm::new(
        workers,
        Options { token: Some("s3cret-farm-token".into()), max_batch: 2, ..Options::default() },
    );
    let (clear, clear_bundle, s) = clear_equirect(6, 3);
    let (hazed, hazed_bundle) =
        sky::atmosphere::Atmosphere::load_bundle(&root().join("atmospheres/hazed.toml")).unwrap();
    let (optics, mie) = (OpticsCache::default(), sky::mie::MieCache::shared_by_tests());
    let sessions = [
        Session::on_farm(clear, clear_bundle, s.spectral.clone(), &optics, &mie, shared.clone(), &|| {}),
        Session::on_farm(hazed, hazed_bundle, s.spectral.clone(), &optics, &mie, shared.clone(), &|| {}),
    ];
    assert_ne!(sessions[0].optics_hash(), sessions[1].optics_hash());
    // Two views of each, of different heights: four parts.
    let views: Vec<(usize, sky::render::View)> = [(0, 3), (1, 3), (0, 5), (1, 2)]
        .into_iter()
        .map(|(k, height)| {
            (k, sky::render::View { height, sun_zenith_deg: 40.0 + 10.0 * height as f64, ..s.view.clone() })
        })
        .collect();
    let parts = views
        .iter()
        .map(|(k, v)| FarmPart { job: sessions[*k].job(v), resumed: Default::default(), journal: None })
        .collect();
    let out = shared.render_parts(parts, Arc::new(AtomicBool::new(false))).unwrap();
    assert_eq!(out.parts.len(), 4);
    for ((k, v), columns) in views.iter().zip(&out.parts) {
        let want = sky::render::render(&sessions[*k].scene, v, &AtomicBool::new(false), &|| {}).unwrap();
        assert!(
            image_of_columns(columns, v.width, v.height) == want,
            "a part of atmosphere {k} differs from its direct render"
        );
    }
    assert!(out.busy_core_s.iter().all(|&s| s > 0.0), "{:?}", out.busy_core_s);
    assert_eq!(out.stats.columns_total, 24);
    for w in &out.stats.workers {
        assert_eq!((w.connects, w.hellos), (1, 1), "{w:?}");
        assert!(w.optics_sent <= 2, "worker {} got optics {} times for two atmospheres", w.address, w.optics_sent);
    }
    // The queue was shared: both workers took tasks.
    assert!(out.stats.workers.iter().all(|w| w.tasks_done > 0), "{:?}", out.stats.workers);
    // A second render on the same farm greets nobody again, and no worker
    // gets an atmosphere's optics a second time.
    let again = shared
        .render_parts(
            vec![FarmPart { job: sessions[1].job(&views[1].1), resumed: Default::default(), journal: None }],
            Arc::new(AtomicBool::new(false)),
        )
        .unwrap();
    for (w, before) in again.stats.workers.iter().zip(&out.stats.workers) {
        assert_eq!((w.address.as_str(), w.connects, w.hellos), (before.address.as_str(), 0, 0), "{w:?}");
        assert!(
            before.optics_sent + w.optics_sent <= 2,
            "worker {} got optics {} times for two atmospheres",
            w.address,
            before.optics_sent + w.optics_sent
        );
    }
}

/// Optics keep arriving after the task that brought them is cancelled (a
/// duplicate finished first elsewhere): a task that comes without them
/// meanwhile waits for them instead of being told they are missing (which
/// made the coordinator send the 19 MB again, a failure of the 64-view test
/// above on a loaded CI machine), and Hello counts them as held. The worker
/// takes 3 s more to unpack (a fault), so both calls land while it does.
#[test]
fn a_task_without_optics_waits_for_optics_still_unpacking() {
    use sky::session::{OpticsCache, Session};
    let mut farm = Farm::new();
    let w = farm.start("w", &["--fault-slow-unpack-ms", "3000"]);
    let (atm, bundle, s) = clear_equirect(2, 2);
    let session = Session::new(
        atm,
        bundle,
        s.spectral.clone(),
        &OpticsCache::default(),
        &sky::mie::MieCache::shared_by_tests(),
        vec![],
        Default::default(),
        &|| {},
    );
    let job = session.job(&s.view);
    let pv = sky::farm::PROTOCOL_VERSION;
    let task = |id: u64, first: u32, optics: bool| proto::RenderTask {
        protocol_version: pv,
        build_version: sky::farm::build_version(),
        job_hash: job.hash.clone(),
        task_id: id,
        first_column: first,
        columns: 1,
        optics_hash: job.optics.hash.clone(),
        optics: optics.then(|| job.optics.message().clone()),
        view_json: job.view_json.clone(),
    };
    let uri = format!("http://{}", farm.workers[w].addr);
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    rt.block_on(async {
        let mut c = connect(&uri, Some("s3cret-farm-token"), None, Duration::from_secs(5))
            .await
            .unwrap()
            .max_encoding_message_size(usize::MAX);
        // The first task brings the optics and is dropped at once.
        drop(c.render(task(1, 0, true)).await.expect("the task with the optics is taken"));
        let hello = proto::HelloRequest {
            protocol_version: pv,
            build_version: sky::farm::build_version(),
            coordinator: "test".into(),
        };
        let held = c.hello(hello).await.unwrap().into_inner().optics_held;
        assert!(held.contains(&job.optics.hash), "the optics being unpacked are not in Hello's list: {held:?}");
        // The second comes without them, and gets its tile.
        let mut stream = c
            .render(task(2, 1, false))
            .await
            .unwrap_or_else(|e| panic!("the task without optics was refused: {e}"))
            .into_inner();
        let mut tile = None;
        while let Some(ev) = stream.message().await.unwrap() {
            if let Some(proto::render_event::Event::Tile(t)) = ev.event {
                tile = Some(t);
                break;
            }
        }
        let tile = tile.expect("a tile");
        assert_eq!((tile.task_id, tile.first_column), (2, 1));
    });
}

/// `sky bake-luts` over two `sky worker` daemons: each basis sky's slices
/// go to the farm as one job (a strip of slices), the skies' strips in one
/// queue, the fog slices a job each, and the baked files are byte-identical
/// to those of the embedded worker. Its ETA is shared among the farm's
/// threads from the first: none until a worker said its threads.
#[test]
fn a_bake_through_two_workers_bakes_the_embedded_workers_bytes() {
    let mut farm = Farm::new();
    let a = farm.start("a", &[]);
    let b = farm.start("b", &[]);
    let bake = root().join("tests/bakes/tiny.toml");
    // The bake's JSON lines: its progress events, then its summary.
    let bake_to = |out: &str, farm_args: &[String]| {
        let o = Command::new(SKY)
            .args([
                "bake-luts",
                "--method",
                "monte-carlo",
                bake.to_str().unwrap(),
                "--out",
                farm.path(out).to_str().unwrap(),
                "--json",
                "--json-progress",
            ])
            .args(farm_args)
            .env("SKY_CACHE_DIR", sky::mie::MieCache::test_dir())
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
        String::from_utf8_lossy(&o.stdout)
            .lines()
            .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
            .collect::<Vec<_>>()
    };
    let events = bake_to(
        "farm",
        &[
            "--workers".to_string(),
            farm.list(&[a, b]),
            "--token-file".to_string(),
            farm.path("token").to_str().unwrap().to_string(),
        ],
    );
    let on_farm = events.last().unwrap().clone();
    // Two workers of one thread: the first ETA is about the forecast over
    // two (over one, as it was before the workers' threads were waited
    // for, it would be about the whole forecast).
    let forecast = events.iter().find(|e| e["event"] == "forecast").unwrap()["core_seconds"].as_f64().unwrap();
    let first_eta = events.iter().filter(|e| e["event"] == "progress").find_map(|e| e["eta_s"].as_f64()).unwrap();
    assert!(
        first_eta < 0.75 * forecast,
        "first ETA {first_eta} s against a forecast of {forecast} core-seconds on two threads"
    );
    bake_to("local", &[]);
    for k in on_farm["skies"].as_array().unwrap() {
        assert_eq!((k["slices_rendered"].as_u64(), k["slices_cached"].as_u64()), (Some(63), Some(1)), "{on_farm}");
    }
    // The fog LUTs' slices went to the workers too (a farm job each: the
    // Shadowed Fog's render, from which the Fog follows).
    for k in on_farm["fog"]["skies"].as_array().unwrap() {
        assert_eq!((k["slices_rendered"].as_u64(), k["slices_cached"].as_u64()), (Some(63), Some(1)), "{on_farm}");
    }
    for f in ["clear.ktx2", "hazed.ktx2", "transmittance.ktx2", "fog.ktx2", "attenuation.ktx2", "manifest.json"] {
        assert!(
            std::fs::read(farm.path("farm").join(f)).unwrap() == std::fs::read(farm.path("local").join(f)).unwrap(),
            "{f} differs between the farm's bake and the embedded worker's"
        );
    }
}
