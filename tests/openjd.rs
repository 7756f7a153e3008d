//! `sky bake-luts --plan openjd` through Open Job Description's own CLI
//! (openjd-cli 0.8.0, pinned in scripts/requirements-openjd.txt): the
//! template passes `openjd check`, and `openjd run TEMPLATE --step Pack
//! --run-dependencies` (every render task, then the pack step) bakes files
//! byte-identical to a direct `sky bake-luts` of the same bake.
//!
//! Needs `.venv-openjd/bin/openjd` (or `SKY_OPENJD` naming another), which
//! `make test` installs. Without it the test fails, on purpose: CI must not
//! skip it.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn openjd() -> PathBuf {
    let p = std::env::var_os("SKY_OPENJD").map(PathBuf::from).unwrap_or_else(|| root().join(".venv-openjd/bin/openjd"));
    assert!(p.exists(), "{} is not installed: run `make openjd` (as `make test` does), or set SKY_OPENJD", p.display());
    p
}

fn run(cmd: &mut Command) -> Output {
    let o = cmd.env("SKY_CACHE_DIR", sky::mie::MieCache::test_dir()).output().unwrap();
    assert!(
        o.status.success(),
        "{:?} failed:\n{}\n{}",
        cmd,
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    o
}

fn sky(args: &[&str]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_sky"));
    c.args(args);
    c
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn an_openjd_job_bakes_the_same_bytes_as_a_direct_bake() {
    let tmp = tempfile::tempdir().unwrap();
    let bake = root().join("tests/bakes/tiny.toml");
    let job = tmp.path().join("job");
    let plan = run(&mut sky(&[
        "bake-luts",
        "--method",
        "monte-carlo",
        s(&bake),
        "--out",
        s(&job),
        "--plan",
        "openjd",
        "--json",
    ]));
    let summary: serde_json::Value = serde_json::from_slice(&plan.stdout).unwrap();
    // Each sky's 64 slices and 64 fog slices.
    assert_eq!(summary["render_tasks"], 256);
    let template = job.join("bake.openjd.yaml");
    let params = job.join("bake.openjd.params.json");
    // The plan renders nothing.
    assert!(!job.join("manifest.json").exists());
    let text = std::fs::read_to_string(&template).unwrap();
    assert!(
        text.contains("\"clear:0\"") && text.contains("\"hazed:63\"") && text.contains("\"hazed:fog:63\""),
        "{text}"
    );

    run(Command::new(openjd()).arg("check").arg(&template));
    let log = run(Command::new(openjd())
        .arg("run")
        .arg(&template)
        .arg("-p")
        .arg(format!("file://{}", s(&params)))
        .args(["--step", "Pack", "--run-dependencies"]));
    let log = String::from_utf8_lossy(&log.stdout);
    assert!(log.contains("Chunks run: 257"), "256 render tasks and the pack step:\n{log}");

    let direct = tmp.path().join("direct");
    run(&mut sky(&["bake-luts", "--method", "monte-carlo", s(&bake), "--out", s(&direct)]));
    for f in ["clear.ktx2", "hazed.ktx2", "transmittance.ktx2", "fog.ktx2", "attenuation.ktx2", "manifest.json"] {
        let (a, b) = (std::fs::read(direct.join(f)).unwrap(), std::fs::read(job.join(f)).unwrap());
        assert!(a == b, "{f}: the job's file differs from the direct bake's");
    }

    // The pack step renders nothing: a sky slice lost from the cache is an
    // error that names it, and nothing is written; so is a fog slice.
    let cache = job.join("cache");
    let cached = sky::bake::SliceCache::open(&cache).unwrap();
    let first = std::fs::read_dir(&cache)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "slice"))
        .find(|p| cached.get(p.file_stem().unwrap().to_str().unwrap()).is_some_and(|s| s.width == 4))
        .unwrap();
    std::fs::remove_file(first).unwrap();
    let again = tmp.path().join("again");
    let o = sky(&[
        "bake-luts",
        "--method",
        "monte-carlo",
        s(&bake),
        "--out",
        s(&again),
        "--cache",
        s(&cache),
        "--pack-only",
    ])
    .env("SKY_CACHE_DIR", sky::mie::MieCache::test_dir())
    .output()
    .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    // Slices 47 and 48 are both the horizon (the talk's two ranges meet
    // there), so they share a cache entry: losing it loses both.
    assert!(
        err.contains("lacks 1 of the bake's slices")
            || err.contains("lacks 2 of the bake's slices (clear:47, clear:48)")
            || err.contains("lacks 2 of the bake's slices (hazed:47, hazed:48)"),
        "{err}"
    );
    assert!(!again.join("manifest.json").exists());
    for p in std::fs::read_dir(&cache)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "slice"))
    {
        if cached.get(p.file_stem().unwrap().to_str().unwrap()).is_some_and(|s| s.width == 8) {
            std::fs::remove_file(p).unwrap();
        }
    }
    let o = sky(&[
        "bake-luts",
        "--method",
        "monte-carlo",
        s(&bake),
        "--out",
        s(&again),
        "--cache",
        s(&cache),
        "--pack-only",
    ])
    .env("SKY_CACHE_DIR", sky::mie::MieCache::test_dir())
    .output()
    .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("clear:fog:0, clear:fog:1"), "{err}");
    assert!(!again.join("manifest.json").exists());
}

#[test]
fn a_plan_takes_no_farm_and_no_slice() {
    let tmp = tempfile::tempdir().unwrap();
    let bake = root().join("tests/bakes/tiny.toml");
    let out = tmp.path().join("job");
    for extra in [&["--workers", "127.0.0.1:1"][..], &["--slice", "clear:3"], &["--pack-only"]] {
        let mut args = vec!["bake-luts", "--method", "monte-carlo", s(&bake), "--out", s(&out), "--plan", "openjd"];
        args.extend_from_slice(extra);
        let o = sky(&args).output().unwrap();
        assert_eq!(o.status.code(), Some(2), "{extra:?}: {}", String::from_utf8_lossy(&o.stderr));
    }
    let o = sky(&["bake-luts", "--method", "monte-carlo", s(&bake), "--out", s(&out), "--sky-executable", "sky"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "--sky-executable without --plan");
}
