//! Fuzzing the two places where `sky` reads input it did not write: the
//! atmosphere loader (mutations of the shipped and the broken atmosphere
//! files) and a worker's decoding and checking of farm messages (random
//! and mutated optics, views, tasks and tiles). No case may panic; every atmosphere
//! error names a line of its file, every farm error is a typed error.
//!
//! `make fuzz` runs the long versions (`--ignored`); the short ones run
//! with the rest of the tests. Each case draws from its own SplitMix64
//! stream, seeded by (SEED, case index), so a failure printed as
//! "seed S case N" reproduces alone.

use prost::Message;
use sky::atmosphere::{Atmosphere, Bundle};
use sky::farm::{job, proto, tile, worker};
use sky::render::{PixelResult, Settings};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::common::SplitMix64 as Rng;

const SEED: u64 = 0x5EED_F022;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Cases run, cases that were refused with an error, and the failures
/// (panics, unlocated or unnamed errors), each with its seed and case.
#[derive(Default)]
struct Tally {
    cases: u64,
    errors: u64,
    failures: Vec<String>,
}

impl Tally {
    /// Runs one case: Ok(true) if it was refused, Ok(false) if accepted,
    /// Err(why) if the error it got is not acceptable.
    fn run(&mut self, what: &str, case: u64, f: impl FnOnce() -> Result<bool, String>) {
        self.cases += 1;
        match catch_unwind(AssertUnwindSafe(f)) {
            Ok(Ok(refused)) => self.errors += refused as u64,
            Ok(Err(why)) => self.failures.push(format!("{what}: seed {SEED:#x} case {case}: {why}")),
            Err(p) => {
                let msg = p
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default();
                self.failures.push(format!("{what}: seed {SEED:#x} case {case}: PANIC {msg}"));
            }
        }
    }

    fn report(&self, what: &str, started: Instant) {
        println!(
            "fuzz {what}: {} cases ({} refused with errors), {} failures, {:.1} s, seed {SEED:#x}",
            self.cases,
            self.errors,
            self.failures.len(),
            started.elapsed().as_secs_f64()
        );
        for f in self.failures.iter().take(20) {
            println!("  {f}");
        }
        assert!(self.failures.is_empty(), "{} failing {what} cases (first: {})", self.failures.len(), self.failures[0]);
    }
}

// ---------------------------------------------------------------- mutations

const NUMBERS: [&str; 22] = [
    "nan",
    "NaN",
    "-nan",
    "inf",
    "-inf",
    "+inf",
    "-1",
    "-0.0",
    "0",
    "0.0",
    "1e308",
    "1e400",
    "-1e400",
    "1e-320",
    "99999999999999999999",
    "-9223372036854775809",
    "1e9",
    "1e15",
    "0x10",
    "1_000",
    "5e-324",
    "3.",
];
const KEYS: [&str; 24] = [
    "name",
    "kind",
    "profile",
    "units",
    "radius_km",
    "top_km",
    "geometry",
    "scale_height_km",
    "max_km",
    "min_km",
    "file",
    "interpolation",
    "refractive_index",
    "modes",
    "median_radius_um",
    "sigma",
    "weight",
    "optical_depth",
    "number_density_cm3",
    "cross_section",
    "spectrum",
    "angular_diameter_deg",
    "radius_range_um",
    "zz_unknown",
];
const TOKENS: [&str; 20] = [
    "=",
    "[",
    "]",
    "[[",
    "]]",
    "{",
    "}",
    "\"",
    "'''",
    ",",
    "#",
    "\n",
    "[[aerosol]]\n",
    "[[profile]]\n",
    "[planet]\n",
    "name = \"x\"\n",
    "profile = \"nope\"\n",
    "é",
    "💥",
    "\\u{0}",
];

fn line_bounds(b: &[u8], at: usize) -> (usize, usize) {
    let at = at.min(b.len());
    let start = b[..at].iter().rposition(|&c| c == b'\n').map(|i| i + 1).unwrap_or(0);
    let end = b[at..].iter().position(|&c| c == b'\n').map(|i| at + i + 1).unwrap_or(b.len());
    (start, end)
}

/// One to four edits of a text: lines deleted, duplicated or swapped,
/// bits flipped, bytes or tokens inserted, numbers made NaN, infinite,
/// negative, huge or zero, keys changed, the end cut off, invalid UTF-8.
fn mutate(text: &[u8], rng: &mut Rng) -> Vec<u8> {
    let mut b = text.to_vec();
    for _ in 0..1 + rng.below(4) {
        let at = rng.below(b.len() + 1);
        match rng.below(12) {
            0 => {
                let (s, e) = line_bounds(&b, at);
                b.drain(s..e);
            }
            1 => {
                let (s, e) = line_bounds(&b, at);
                let line = b[s..e].to_vec();
                b.splice(e..e, line);
            }
            2 => {
                let (s1, e1) = line_bounds(&b, at);
                let (s2, e2) = line_bounds(&b, rng.below(b.len() + 1));
                if e1 <= s2 {
                    let (l1, l2) = (b[s1..e1].to_vec(), b[s2..e2].to_vec());
                    b.splice(s2..e2, l1);
                    b.splice(s1..e1, l2);
                }
            }
            3 if !b.is_empty() => {
                let i = at.min(b.len() - 1);
                b[i] ^= 1 << rng.below(8);
            }
            4 => {
                let ins = rng.bytes(5);
                b.splice(at..at, ins);
            }
            5 | 6 => {
                // A number (the next run of digits, signs, dots and exponents) replaced.
                if let Some(s) = (at..b.len()).find(|&i| b[i].is_ascii_digit()) {
                    let s = (0..s).rev().take_while(|&i| b"+-.".contains(&b[i])).last().unwrap_or(s);
                    let e = (s..b.len())
                        .find(|&i| !(b[i].is_ascii_digit() || b"+-.eE_".contains(&b[i])))
                        .unwrap_or(b.len());
                    b.splice(s..e, rng.pick(&NUMBERS).bytes());
                }
            }
            7 => {
                // A key replaced by another.
                let (s, e) = line_bounds(&b, at);
                if let Some(eq) = b[s..e].iter().position(|&c| c == b'=') {
                    let k = (s..s + eq).find(|&i| !b[i].is_ascii_whitespace()).unwrap_or(s);
                    let ke = (k..s + eq).find(|&i| b[i].is_ascii_whitespace()).unwrap_or(s + eq);
                    b.splice(k..ke, rng.pick(&KEYS).bytes());
                }
            }
            8 => b.truncate(at),
            9 => {
                let bad: [&[u8]; 5] = [b"\xff", b"\xc3", b"\xed\xa0\x80", b"\xf4\x90\x80\x80", b"\xe2\x82"];
                b.splice(at..at, rng.pick(&bad).iter().copied());
            }
            _ => {
                b.splice(at..at, rng.pick(&TOKENS).bytes());
            }
        }
    }
    b
}

// ------------------------------------------------------- the atmosphere loader

struct Corpus {
    /// (path, text, data files of its bundle when it loads).
    files: Vec<(PathBuf, Vec<u8>, Option<Bundle>)>,
}

fn corpus() -> Corpus {
    let mut files = Vec::new();
    for dir in ["atmospheres", "tests/bad_atmospheres", "tests/atmospheres"] {
        let mut v: Vec<PathBuf> = std::fs::read_dir(root().join(dir))
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "toml"))
            .collect();
        v.sort();
        for p in v {
            let text = std::fs::read(&p).unwrap();
            let bundle = Atmosphere::load_bundle(&p).ok().map(|(_, b)| b);
            files.push((p, text, bundle));
        }
    }
    assert!(files.len() >= 40, "{} files", files.len());
    Corpus { files }
}

/// Every error names the file it is about and a line of it.
fn check_located(path: &Path, r: Result<Atmosphere, sky::atmosphere::LoadError>) -> Result<bool, String> {
    let Err(e) = r else { return Ok(false) };
    if e.errors.is_empty() {
        return Err("an error with no messages".into());
    }
    for err in &e.errors {
        if err.path != path || err.line.is_none() || err.message.trim().is_empty() {
            return Err(format!("unlocated error: {err:?}"));
        }
    }
    Ok(true)
}

fn fuzz_atmospheres(cases: u64) {
    let corpus = corpus();
    let tmp = tempfile::tempdir().unwrap();
    let mut tally = Tally::default();
    let started = Instant::now();
    for case in 0..cases {
        let mut rng = Rng::case(SEED, case);
        let (path, text, bundle) = &corpus.files[rng.below(corpus.files.len())];
        let m = mutate(text, &mut rng);
        let how = rng.below(4);
        tally.run("atmosphere", case, || match String::from_utf8(m.clone()) {
            // Not UTF-8: through the file, as `sky atmosphere check` reads it.
            Err(_) => {
                let p = tmp.path().join(format!("case{case}.toml"));
                std::fs::write(&p, &m).unwrap();
                let r = Atmosphere::load(&p);
                let _ = std::fs::remove_file(&p);
                check_located(&p, r)
            }
            Ok(t) => match (how, bundle) {
                // As a farm job carries it, data files from the bundle; one
                // of them mutated in half of these.
                (0 | 1, Some(b)) => {
                    let mut b = Bundle { text: t, ..b.clone() };
                    if how == 1 && !b.files.is_empty() {
                        let k = b.files.keys().nth(case as usize % b.files.len()).unwrap().clone();
                        let d = mutate(&b.files[&k], &mut Rng::case(SEED ^ 1, case));
                        b.files.insert(k, d);
                    }
                    check_located(&PathBuf::from(format!("job:{}", b.name)), Atmosphere::from_bundle(&b))
                }
                // As text at its own path, data files from the disk.
                _ => check_located(path, Atmosphere::from_str(path, &t)),
            },
        });
    }
    tally.report("atmosphere", started);
    assert!(tally.errors > cases / 4, "mutations should mostly break files ({} of {cases})", tally.errors);
}

#[test]
fn atmosphere_loader_survives_mutations_short() {
    fuzz_atmospheres(500);
}

#[test]
#[ignore = "long: make fuzz"]
fn atmosphere_loader_survives_mutations() {
    fuzz_atmospheres(50_000);
}

/// Found while writing this fuzzing: a file that is not UTF-8 got an error with no
/// line ("cannot read: stream did not contain valid UTF-8"); now the line
/// and column of the first bad byte.
#[test]
fn text_that_is_not_utf8_is_located() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("bad.toml");
    std::fs::write(&p, b"[planet]\nradius_km = 6371.0\nname = \"caf\xe9\"\n").unwrap();
    let e = Atmosphere::load(&p).unwrap_err();
    assert_eq!(e.errors.len(), 1, "{e}");
    assert_eq!(e.errors[0].line, Some(3), "{e}");
    assert!(e.to_string().starts_with(&format!("{}:3: not UTF-8 text: byte 0xe9 at column 12", p.display())), "{e}");
}

// --------------------------------------------------------- farm messages

struct Valid {
    optics: proto::Optics,
    task: proto::RenderTask,
    tile: proto::Tile,
    height: u32,
    lines: u32,
    spp: u32,
}

fn valid() -> Valid {
    let (atm, bundle) = Atmosphere::load_bundle(&root().join("atmospheres/clear.toml")).unwrap();
    let settings =
        Settings::directions(vec![(10.0, 20.0), (60.0, 0.0), (80.0, 90.0)], 60.0, vec![450.0, 550.0], 8, 7, false);
    let optics = job::message(&bundle, &settings.spectral, None);
    let optics_hash = sky::farm::job::optics_hash(&atm, &settings.spectral);
    let view_json = serde_json::to_string(&settings.view).unwrap();
    let hash = job::job_hash(&optics_hash, &view_json);
    let task = proto::RenderTask {
        protocol_version: sky::farm::PROTOCOL_VERSION,
        build_version: sky::farm::build_version(),
        job_hash: hash.clone(),
        task_id: 4,
        first_column: 1,
        columns: 2,
        optics_hash,
        optics: Some(optics.clone()),
        view_json,
    };
    let px = |v: f64| PixelResult {
        xyz: [v, v, v],
        xyz_direct: [0.0; 3],
        xyz_stderr: [0.1; 3],
        spectral: vec![v, v],
        spectral_stderr: vec![0.01, 0.01],
        samples: 8,
        paths_cut: 0,
    };
    let tile = tile::encode(&hash, 4, 1, 1, 2, &[vec![px(1.0)], vec![px(2.0)]]);
    Valid { optics, task, tile, height: 1, lines: 2, spp: 8 }
}

/// A worker's path for a task: the checks before it is taken, its view
/// and its columns against the view's width, the optics it carries
/// unpacked (atmosphere, spectral settings, prepared scene) and checked
/// against their hash. Errors are gRPC statuses with a message.
fn worker_takes(task: &proto::RenderTask) -> Result<bool, String> {
    let status = |s: tonic::Status| -> Result<bool, String> {
        if s.message().trim().is_empty()
            || s.code() == tonic::Code::Ok
            || s.code() == tonic::Code::Unknown
            || s.code() == tonic::Code::Internal
        {
            return Err(format!("unnamed error {s:?}"));
        }
        Ok(true)
    };
    if let Err(s) = worker::check_task(task, sky::farm::PROTOCOL_VERSION) {
        return status(s);
    }
    let view = match worker::open_view(&task.view_json) {
        Err(s) => return status(s),
        Ok(v) => v,
    };
    if let Err(s) = worker::task_columns(task, view.width) {
        return status(s);
    }
    let Some(o) = &task.optics else { return Ok(false) };
    match worker::open_optics(o, &task.optics_hash) {
        Err(s) => status(s),
        Ok(_) => Ok(false),
    }
}

/// The coordinator's check of a tile for the valid task.
fn tile_accepted(t: &proto::Tile, v: &Valid) -> Result<bool, String> {
    let want = tile::Expect {
        job_hash: &v.task.job_hash,
        task_id: v.task.task_id,
        first_column: v.task.first_column,
        columns: v.task.columns,
        height: v.height,
        lines: v.lines,
        spp: v.spp,
    };
    match tile::decode(t, &want) {
        Ok(cols) if cols.len() == v.task.columns as usize => Ok(false),
        Ok(cols) => Err(format!("accepted {} columns for a {}-column task", cols.len(), v.task.columns)),
        Err(e) if e.to_string().trim().is_empty() => Err(format!("unnamed error {e:?}")),
        Err(_) => Ok(true),
    }
}

fn weird_f64(rng: &mut Rng) -> f64 {
    let any = f64::from_bits(rng.next());
    *rng.pick(&[
        f64::NAN,
        -f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        -1.0,
        -0.0,
        0.0,
        1e308,
        f64::MIN_POSITIVE,
        5e-324,
        any,
    ])
}

fn weird_u32(rng: &mut Rng) -> u32 {
    let any = rng.next() as u32;
    *rng.pick(&[0, 1, 2, 3, 4, u32::MAX, u32::MAX - 1, 1 << 31, any])
}

/// A structured mutation of a valid task: versions, hashes, the view, the
/// optics' fields (atmosphere text, data files, spectral settings JSON,
/// prepared scene), the columns. Half of the mutated tasks get their true
/// job hash, so that the worker looks inside them.
fn mutate_task(v: &Valid, rng: &mut Rng) -> proto::RenderTask {
    let mut t = v.task.clone();
    let mut j = v.optics.clone();
    for _ in 0..1 + rng.below(3) {
        match rng.below(12) {
            0 => t.protocol_version = weird_u32(rng),
            1 => t.build_version = String::from_utf8_lossy(&mutate(t.build_version.as_bytes(), rng)).into_owned(),
            2 => j.atmosphere_toml = String::from_utf8_lossy(&mutate(j.atmosphere_toml.as_bytes(), rng)).into_owned(),
            3 => j.spectral_json = String::from_utf8_lossy(&mutate(j.spectral_json.as_bytes(), rng)).into_owned(),
            10 => t.view_json = String::from_utf8_lossy(&mutate(t.view_json.as_bytes(), rng)).into_owned(),
            11 => t.optics_hash = String::from_utf8_lossy(&rng.bytes(70)).into_owned(),
            4 if !j.files.is_empty() => {
                let i = rng.below(j.files.len());
                match rng.below(3) {
                    0 => drop(j.files.remove(i)),
                    1 => {
                        j.files[i].name = String::from_utf8_lossy(&mutate(j.files[i].name.as_bytes(), rng)).into_owned()
                    }
                    _ => j.files[i].content = mutate(&j.files[i].content, rng),
                }
            }
            5 => j.scene = rng.bytes(200),
            6 => t.first_column = weird_u32(rng),
            7 => t.columns = weird_u32(rng),
            8 => t.job_hash = String::from_utf8_lossy(&rng.bytes(70)).into_owned(),
            _ => j.protocol_version = weird_u32(rng),
        }
    }
    if rng.below(2) == 0 {
        t.job_hash = job::job_hash(&t.optics_hash, &t.view_json);
    }
    t.optics = if rng.below(8) == 0 { None } else { Some(j) };
    t
}

fn mutate_tile(v: &Valid, rng: &mut Rng) -> proto::Tile {
    let mut t = v.tile.clone();
    for _ in 0..1 + rng.below(3) {
        match rng.below(9) {
            0 if !t.values.is_empty() => {
                let i = rng.below(t.values.len());
                t.values[i] = weird_f64(rng);
            }
            1 => {
                let n = rng.below(2 * t.values.len() + 2);
                t.values.resize(n, 1.0);
            }
            2 if !t.samples.is_empty() => {
                let i = rng.below(t.samples.len());
                t.samples[i] = weird_u32(rng);
            }
            3 => {
                let n = rng.below(5);
                t.samples.resize(n, 8);
            }
            4 => t.height = weird_u32(rng),
            5 => t.spectral_lines = weird_u32(rng),
            6 => t.columns = weird_u32(rng),
            7 => t.first_column = weird_u32(rng),
            _ => t.job_hash = String::from_utf8_lossy(&rng.bytes(70)).into_owned(),
        }
    }
    t
}

/// Bytes on the wire: random, or an encoded message with its bytes
/// flipped, inserted, cut or overwritten by long varints.
fn mutate_bytes(good: &[u8], rng: &mut Rng) -> Vec<u8> {
    if rng.below(4) == 0 {
        return rng.bytes(300);
    }
    let mut b = good.to_vec();
    for _ in 0..1 + rng.below(4) {
        let at = rng.below(b.len() + 1);
        match rng.below(5) {
            0 if !b.is_empty() => {
                let i = at.min(b.len() - 1);
                b[i] ^= 1 << rng.below(8);
            }
            1 => b.truncate(at),
            2 => {
                let ins = rng.bytes(9);
                b.splice(at..at, ins);
            }
            3 => {
                b.splice(at..at, [0xff; 10].iter().copied().chain([0x01]));
            }
            _ if !b.is_empty() => {
                let i = at.min(b.len() - 1);
                b[i] = rng.next() as u8;
            }
            _ => {}
        }
    }
    b
}

fn fuzz_farm(cases: u64) {
    let v = valid();
    assert_eq!(worker_takes(&v.task), Ok(false), "the valid task is taken");
    assert_eq!(tile_accepted(&v.tile, &v), Ok(false), "the valid tile is accepted");
    let (task_bytes, tile_bytes) = (v.task.encode_to_vec(), v.tile.encode_to_vec());
    let event_bytes =
        proto::RenderEvent { event: Some(proto::render_event::Event::Tile(v.tile.clone())) }.encode_to_vec();
    let mut tally = Tally::default();
    let started = Instant::now();
    for case in 0..cases {
        let mut rng = Rng::case(SEED, case);
        match rng.below(5) {
            0 => tally.run("farm task (structured)", case, || worker_takes(&mutate_task(&v, &mut rng))),
            1 => tally.run("farm tile (structured)", case, || tile_accepted(&mutate_tile(&v, &mut rng), &v)),
            2 => {
                let b = mutate_bytes(&task_bytes, &mut rng);
                tally.run("farm task (bytes)", case, || match proto::RenderTask::decode(b.as_slice()) {
                    Err(e) if e.to_string().is_empty() => Err("unnamed decode error".into()),
                    Err(_) => Ok(true),
                    Ok(t) => worker_takes(&t),
                })
            }
            3 => {
                let b = mutate_bytes(&tile_bytes, &mut rng);
                tally.run("farm tile (bytes)", case, || match proto::Tile::decode(b.as_slice()) {
                    Err(_) => Ok(true),
                    Ok(t) => tile_accepted(&t, &v),
                })
            }
            _ => {
                let b = mutate_bytes(&event_bytes, &mut rng);
                tally.run("farm event (bytes)", case, || match proto::RenderEvent::decode(b.as_slice()) {
                    Err(_) => Ok(true),
                    Ok(proto::RenderEvent { event: Some(proto::render_event::Event::Tile(t)) }) => {
                        tile_accepted(&t, &v)
                    }
                    Ok(_) => Ok(false),
                })
            }
        }
    }
    tally.report("farm", started);
    assert!(tally.errors > cases / 4, "mutations should mostly be refused ({} of {cases})", tally.errors);
}

#[test]
fn farm_messages_survive_mutations_short() {
    fuzz_farm(500);
}

#[test]
#[ignore = "long: make fuzz"]
fn farm_messages_survive_mutations() {
    fuzz_farm(50_000);
}
