//! Issue 38's integrity of a bake: the manifest records every file's size
//! and SHA-256 and its own digest; `sky lut check` and every command that
//! reads a bake refuse a missing, truncated or altered file (the manifest
//! included) with an error that names it, exit 1, and print no number.

use crate::common::sky;
use crate::common::SplitMix64 as Rng;
use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// How a file is damaged.
#[derive(Debug, Clone, Copy)]
enum Damage {
    /// A run of bytes overwritten with others.
    Overwrite,
    /// A run of bytes set to zero.
    Zeros,
    /// Cut to a fraction of its length.
    Truncate,
    Remove,
    /// One digit of the text changed to another (the manifest: still JSON).
    Digit,
}

fn damage(path: &Path, how: Damage, rng: &mut Rng) {
    let mut bytes = std::fs::read(path).unwrap();
    let n = bytes.len();
    match how {
        Damage::Overwrite | Damage::Zeros => {
            let at = rng.below(n - 8);
            for b in &mut bytes[at..at + 8] {
                *b = if matches!(how, Damage::Zeros) { 0 } else { *b ^ (1 + rng.below(255) as u8) };
            }
            if bytes == std::fs::read(path).unwrap() {
                bytes[at] ^= 0xff; // zeros over zeros: change one at least
            }
        }
        Damage::Truncate => bytes.truncate(rng.below(n)),
        Damage::Remove => return std::fs::remove_file(path).unwrap(),
        Damage::Digit => {
            let digits: Vec<usize> = (0..n).filter(|&i| bytes[i].is_ascii_digit()).collect();
            let at = *rng.pick(&digits);
            bytes[at] = if bytes[at] == b'9' { b'0' } else { bytes[at] + 1 };
        }
    }
    std::fs::write(path, bytes).unwrap();
}

/// A copy of the bake folder `from` in `to`.
fn copy_bake(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        if e.file_type().unwrap().is_file() {
            std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
        }
    }
}

#[test]
fn damaged_bakes_are_refused_with_the_file_named_and_no_number() {
    let tmp = tempfile::tempdir().unwrap();
    let good = tmp.path().join("good");
    let bake = root().join("tests/bakes/tiny.toml");
    let o = sky(&["bake-luts", "--method", "monte-carlo", bake.to_str().unwrap(), "--out", good.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let manifest = good.join("manifest.json");
    let m: serde_json::Value = serde_json::from_slice(&std::fs::read(&manifest).unwrap()).unwrap();
    let files: Vec<String> =
        m["files"].as_array().unwrap().iter().map(|f| f["file"].as_str().unwrap().to_string()).collect();
    // Every file the bake wrote but the manifest and the slice cache.
    let mut written: Vec<String> = std::fs::read_dir(&good)
        .unwrap()
        .map(|e| e.unwrap())
        .filter(|e| e.file_type().unwrap().is_file())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|f| f != "manifest.json")
        .collect();
    written.sort();
    let mut recorded = files.clone();
    recorded.sort();
    assert_eq!(recorded, written, "the manifest records every file the bake wrote");

    // Intact: `sky lut check` prints what sha256sum prints (coreutils, an
    // independent SHA-256), and exits 0.
    let o = sky(&["lut", "check", manifest.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let ours = String::from_utf8(o.stdout).unwrap();
    let theirs = Command::new("sha256sum").args(&files).current_dir(&good).output().unwrap();
    assert!(theirs.status.success());
    let theirs: Vec<String> = String::from_utf8(theirs.stdout).unwrap().lines().map(str::to_string).collect();
    // Ours: "SHA256  FILE  N bytes"; sha256sum's: "SHA256  FILE".
    let ours_as_sums: Vec<String> = ours.lines().map(|l| l.rsplit_once("  ").unwrap().0.to_string()).collect();
    assert_eq!(ours_as_sums, theirs, "{ours}");
    let json = sky(&["lut", "check", manifest.to_str().unwrap(), "--json"]);
    let v: serde_json::Value = serde_json::from_slice(&json.stdout).unwrap();
    assert_eq!((v["intact"].as_bool(), v["files"].as_array().map(Vec::len)), (Some(true), Some(files.len())));

    // Each kind of file, each kind of damage: refused by the check and by
    // a command that reads the bake, the file named, nothing on stdout.
    let mut rng = Rng::case(38, 0);
    let mut cases = 0;
    let kinds = [Damage::Overwrite, Damage::Zeros, Damage::Truncate, Damage::Remove];
    let targets: Vec<(String, Vec<Damage>)> = files
        .iter()
        .map(|f| (f.clone(), kinds.to_vec()))
        .chain([(
            "manifest.json".to_string(),
            vec![Damage::Digit, Damage::Digit, Damage::Digit, Damage::Truncate, Damage::Remove, Damage::Zeros],
        )])
        .collect();
    for (file, damages) in &targets {
        for &how in damages {
            let dir = tmp.path().join(format!("case{cases}"));
            copy_bake(&good, &dir);
            damage(&dir.join(file), how, &mut rng);
            let m = dir.join("manifest.json");
            for args in [
                vec!["lut", "check", m.to_str().unwrap()],
                vec!["lut", "sample", m.to_str().unwrap(), "--sun-elevation-deg", "20", "--direction", "60,90"],
            ] {
                let o = sky(&args);
                let err = String::from_utf8_lossy(&o.stderr);
                assert_eq!(o.status.code(), Some(1), "{file} {how:?}, {}: {err}", args[1]);
                assert!(err.contains(file.as_str()), "{file} {how:?}, {}: the error does not name it: {err}", args[1]);
                assert!(
                    o.stdout.is_empty(),
                    "{file} {how:?}, {}: printed {}",
                    args[1],
                    String::from_utf8_lossy(&o.stdout)
                );
            }
            std::fs::remove_dir_all(&dir).unwrap();
            cases += 1;
        }
    }
    assert_eq!(cases, files.len() * 4 + 6);
}
