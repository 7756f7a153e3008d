//! Atmosphere files: every shipped file loads; a corpus of broken files
//! (`tests/bad_atmospheres/`, each stating the line and message it expects)
//! gets located errors; and random mutations of the shipped files never
//! panic the loader and always get errors that name a line.

use crate::common::SplitMix64 as Rng;
use sky::atmosphere::Atmosphere;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn shipped() -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(root().join("atmospheres"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    v.sort();
    v
}

#[test]
fn shipped_atmospheres_load() {
    let files = shipped();
    for name in ["clear", "hazed", "cloudy0", "cloudy1", "cloudy2", "cloudy3", "cloudy4", "cloudy5", "case-study"] {
        assert!(files.iter().any(|f| f.file_stem().unwrap() == name), "atmospheres/{name}.toml is missing");
    }
    for f in &files {
        let a = Atmosphere::load(f).unwrap_or_else(|e| panic!("{e}"));
        assert!(a.air.is_some(), "{}: no air", f.display());
        assert_eq!(a.content_hash.len(), 64);
    }
}

#[test]
fn content_hash_follows_referenced_data() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    std::fs::create_dir(&data).unwrap();
    let src = root().join("atmospheres/data/astm_g173_etr.csv");
    std::fs::copy(&src, data.join("sun.csv")).unwrap();
    let text = "[planet]\n[sun]\nspectrum = \"data/sun.csv\"\n";
    let f = dir.path().join("a.toml");
    std::fs::write(&f, text).unwrap();
    let h1 = Atmosphere::load(&f).unwrap().content_hash;
    let mut sun = std::fs::read_to_string(&src).unwrap();
    sun = sun.replacen("\n280,", "\n280.0,", 1);
    std::fs::write(data.join("sun.csv"), sun).unwrap();
    let h2 = Atmosphere::load(&f).unwrap().content_hash;
    assert_ne!(h1, h2, "changing a referenced data file must change the hash");
}

#[test]
fn broken_files_get_located_errors() {
    let dir = root().join("tests/bad_atmospheres");
    let mut n = 0;
    let mut entries: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    entries.sort();
    for f in entries {
        let text = std::fs::read_to_string(&f).unwrap();
        let header = text.lines().next().unwrap();
        let rest = header.strip_prefix("# expect line ").unwrap_or_else(|| panic!("{}: no expect header", f.display()));
        let (line, msg) = rest.split_once(": ").unwrap();
        let line: usize = line.parse().unwrap();
        let err = Atmosphere::load(&f).expect_err(&format!("{} should fail", f.display()));
        let hit = err.errors.iter().find(|e| e.message.contains(msg));
        let e = hit.unwrap_or_else(|| panic!("{}: no error containing {msg:?}; got:\n{err}", f.display()));
        assert_eq!(
            e.line,
            Some(line),
            "{}: {msg:?} reported at {:?}, expected line {line}\n{err}",
            f.display(),
            e.line
        );
        assert_eq!(e.path, f);
        let shown = e.to_string();
        assert!(shown.starts_with(&format!("{}:{line}: ", f.display())), "{shown}");
        n += 1;
    }
    assert!(n >= 25, "corpus has only {n} files");
}

fn mutate(text: &str, rng: &mut Rng) -> String {
    let mut b: Vec<u8> = text.as_bytes().to_vec();
    const TOKENS: [&str; 14] =
        ["=", "[", "]", "{", "}", "\"", ",", "-", "1e400", "nan", "\n", "[[aerosol]]\n", "0", "name = \"x\"\n"];
    for _ in 0..1 + rng.below(3) {
        let at = rng.below(b.len());
        match rng.below(5) {
            0 => {
                let len = 1 + rng.below(20);
                b.drain(at..(at + len).min(b.len()));
            }
            1 => {
                let t = TOKENS[rng.below(TOKENS.len())];
                b.splice(at..at, t.bytes());
            }
            2 => {
                // Replace a digit by another character.
                if let Some(p) = (at..b.len()).find(|&i| b[i].is_ascii_digit()) {
                    b[p] = b"9-.e0x"[rng.below(6)];
                }
            }
            3 => {
                // Duplicate a line.
                let start = b[..at].iter().rposition(|&c| c == b'\n').map(|i| i + 1).unwrap_or(0);
                let end = b[at..].iter().position(|&c| c == b'\n').map(|i| at + i + 1).unwrap_or(b.len());
                let line: Vec<u8> = b[start..end].to_vec();
                b.splice(end..end, line);
            }
            _ => {
                b[at] = rng.below(256) as u8;
            }
        }
    }
    String::from_utf8_lossy(&b).into_owned()
}

#[test]
fn mutated_files_never_panic_and_errors_are_located() {
    let mut rng = Rng(0x5eed);
    let mut failures = 0;
    for f in shipped() {
        let text = std::fs::read_to_string(&f).unwrap();
        for _ in 0..150 {
            let m = mutate(&text, &mut rng);
            let path: &Path = &f;
            let r = std::panic::catch_unwind(|| Atmosphere::from_str(path, &m));
            let r = r.unwrap_or_else(|_| panic!("loader panicked on a mutation of {}:\n{m}", f.display()));
            if let Err(e) = r {
                failures += 1;
                assert!(!e.errors.is_empty());
                for err in &e.errors {
                    assert!(err.line.is_some(), "unlocated error for a mutation of {}: {err}\n---\n{m}", f.display());
                    assert!(!err.message.is_empty());
                }
            }
        }
    }
    assert!(failures > 100, "mutations should mostly break files ({failures})");
}

/// An atmosphere without a `[sun]` table gets the shipped sun: the ASTM
/// G173-03 spectrum of atmospheres/data/astm_g173_etr.csv and a 0.533°
/// disk, and a content hash of its own.
#[test]
fn a_file_without_a_sun_gets_the_shipped_one() {
    let path = root().join("tests/atmospheres/disort_rayleigh.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let cut = text.find("[sun]").expect("the test file has a [sun] table");
    let without = Atmosphere::from_str(&path, &text[..cut]).unwrap_or_else(|e| panic!("{e}"));
    let with = Atmosphere::load(&root().join("atmospheres/clear.toml")).unwrap();
    assert_eq!(without.sun.angular_diameter_deg, 0.533);
    for l in [300.0, 450.0, 550.0, 700.0, 1000.0] {
        assert_eq!(without.sun.irradiance_w_m2_nm.eval(l), with.sun.irradiance_w_m2_nm.eval(l), "{l} nm");
    }
    assert_ne!(without.content_hash, Atmosphere::load(&path).unwrap().content_hash);
}
