//! End-to-end tests of the `sky` binary: exit codes, JSON output, plots.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn sky(args: &[&str], cache: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sky")).args(args).current_dir(root()).env("SKY_CACHE_DIR", cache).output().unwrap()
}

fn text(o: &Output) -> (String, String) {
    (String::from_utf8_lossy(&o.stdout).into_owned(), String::from_utf8_lossy(&o.stderr).into_owned())
}

#[test]
fn help_lists_every_command() {
    let c = tempfile::tempdir().unwrap();
    let o = sky(&["--help"], c.path());
    assert!(o.status.success());
    let (out, _) = text(&o);
    for cmd in ["render", "worker", "bake-luts", "lut", "preview", "atmosphere", "mie"] {
        assert!(out.contains(cmd), "--help lacks {cmd}:\n{out}");
    }
}

/// `sky preview` of a file that is not a bake's manifest is an error naming
/// it (exit 1); a build without the `preview` feature says so instead (exit
/// 2); either way nothing is written.
#[test]
fn preview_refuses_what_is_not_a_bake() {
    let c = tempfile::tempdir().unwrap();
    let out = c.path().join("preview");
    let o = sky(
        &["preview", "atmospheres/clear.toml", "--sun-elevation-deg", "10", "--out", out.to_str().unwrap()],
        c.path(),
    );
    if cfg!(feature = "preview") {
        assert_eq!(o.status.code(), Some(1), "{}", text(&o).1);
        assert!(text(&o).1.contains("clear.toml"), "{}", text(&o).1);
    } else {
        assert_eq!(o.status.code(), Some(2));
        assert!(text(&o).1.contains("built without the GPU preview"), "{}", text(&o).1);
    }
    assert!(!out.exists());
    // A bad flag value is a usage error naming the flag (exit 2).
    let o = sky(
        &[
            "preview",
            "atmospheres/clear.toml",
            "--sun-elevation-deg",
            "10",
            "--camera",
            "pinhole",
            "--fov-deg",
            "200",
            "--out",
            out.to_str().unwrap(),
        ],
        c.path(),
    );
    assert_eq!(o.status.code(), Some(2));
    if cfg!(feature = "preview") {
        assert!(text(&o).1.contains("--fov-deg"), "{}", text(&o).1);
    }
    assert!(!out.exists());
}

#[test]
fn check_reports_good_and_bad_files() {
    let c = tempfile::tempdir().unwrap();
    let o = sky(&["atmosphere", "check", "atmospheres/clear.toml", "atmospheres/hazed.toml"], c.path());
    assert_eq!(o.status.code(), Some(0), "{:?}", text(&o));
    let o =
        sky(&["atmosphere", "check", "atmospheres/clear.toml", "tests/bad_atmospheres/negative_sigma.toml"], c.path());
    assert_eq!(o.status.code(), Some(1));
    let (_, err) = text(&o);
    assert!(err.contains("tests/bad_atmospheres/negative_sigma.toml:"), "{err}");
    assert!(err.contains("sigma is ln(GSD)"), "{err}");
    let o = sky(&["atmosphere", "check", "no/such/file.toml"], c.path());
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).1.contains("no/such/file.toml"));
}

#[test]
fn inspect_json_has_documented_keys() {
    let c = tempfile::tempdir().unwrap();
    let o = sky(&["atmosphere", "inspect", "atmospheres/clear.toml", "--wavelengths", "450,550", "--json"], c.path());
    assert!(o.status.success(), "{:?}", text(&o));
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["content_hash"].as_str().unwrap().len(), 64);
    let s = &v["spectral"][1];
    assert_eq!(s["wavelength_nm"], 550.0);
    let tau_r = s["rayleigh_optical_depth"].as_f64().unwrap();
    assert!((tau_r - 0.0971).abs() < 0.001, "{tau_r}");
    let aod = s["aerosol_optical_depth"].as_f64().unwrap();
    assert!((aod - 0.05).abs() < 0.002, "clear.toml asks for AOD 0.05 at 550 nm: {aod}");
    for c in s["components"].as_array().unwrap().iter().chain([&s["total"]]) {
        for k in [
            "name",
            "kind",
            "optical_depth",
            "scattering_optical_depth",
            "absorption_optical_depth",
            "single_scattering_albedo",
            "asymmetry",
            "extinction_ground_per_km",
        ] {
            assert!(!c[k].is_null(), "missing {k} in {c}");
        }
    }
    let xy = v["sun"]["chromaticity_xy"].as_array().unwrap();
    assert!((xy[0].as_f64().unwrap() - 0.3224).abs() < 0.005);
    // Bad flags name the flag and exit 2.
    let o = sky(&["atmosphere", "inspect", "atmospheres/clear.toml", "--wavelengths", "-5"], c.path());
    assert_eq!(o.status.code(), Some(2));
    assert!(text(&o).1.contains("--wavelengths"));
}

#[test]
fn inspect_writes_plots() {
    let c = tempfile::tempdir().unwrap();
    let dir = c.path().join("plots");
    let o = sky(
        &[
            "atmosphere",
            "inspect",
            "atmospheres/analytic-hg.toml",
            "--wavelengths",
            "550",
            "--plot",
            dir.to_str().unwrap(),
        ],
        c.path(),
    );
    assert!(o.status.success(), "{:?}", text(&o));
    for f in ["profiles.png", "extinction_550nm.png", "optical_depth.png", "phase_hg-haze.png"] {
        let bytes = std::fs::read(dir.join(f)).unwrap_or_else(|_| panic!("{f} not written"));
        assert!(bytes.starts_with(b"\x89PNG\r\n\x1a\n") && bytes.len() > 10_000, "{f}");
    }
    // No temporary files left behind.
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 4);
}

#[test]
fn mie_json_and_sign_convention() {
    let c = tempfile::tempdir().unwrap();
    let a = sky(&["mie", "--m", "1.33-1e-7i", "--x", "10", "--json"], c.path());
    let b = sky(&["mie", "--m", "1.33+1e-7i", "--x", "10", "--json"], c.path());
    assert!(a.status.success(), "{:?}", text(&a));
    assert_eq!(a.stdout, b.stdout, "both signs mean the same absorbing sphere");
    let v: Value = serde_json::from_slice(&a.stdout).unwrap();
    assert!((v["q_ext"].as_f64().unwrap() - 2.2065).abs() < 1e-3);
    for k in ["q_sca", "q_abs", "q_back", "g", "angles_deg", "s1_re", "s1_im", "s2_re", "s2_im", "phase_sr_inv"] {
        assert!(!v[k].is_null(), "missing {k}");
    }
    let o = sky(
        &[
            "mie",
            "--m",
            "1.33-1e-7i",
            "--lognormal",
            "4.0,0.55",
            "--wavelength-nm",
            "650",
            "--angles-deg",
            "0,90",
            "--json",
        ],
        c.path(),
    );
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(v["c_ext_um2"].as_f64().unwrap() > 100.0);
    assert_eq!(v["phase_sr_inv"].as_array().unwrap().len(), 2);
    let o = sky(&["mie", "--m", "1.5", "--radius-um", "0.2", "--wavelength-nm", "500", "--json"], c.path());
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!((v["x"].as_f64().unwrap() - 2.0 * std::f64::consts::PI * 0.2 / 0.5).abs() < 1e-12);
}

#[test]
fn mie_bad_flags_exit_2_naming_the_flag() {
    let c = tempfile::tempdir().unwrap();
    for (args, flag) in [
        (vec!["mie", "--m", "abc", "--x", "1"], "--m"),
        (vec!["mie", "--m", "1.33", "--x", "-1"], "--x"),
        (vec!["mie", "--m", "1.33", "--radius-um", "1"], "--wavelength-nm"),
        (vec!["mie", "--m", "1.33", "--lognormal", "1", "--wavelength-nm", "500"], "--lognormal"),
        (vec!["mie", "--m", "1.33", "--x", "1", "--angles-deg", "200"], "--angles-deg"),
        (vec!["mie", "--m", "1.33"], "--x"),
    ] {
        let o = sky(&args, c.path());
        assert_eq!(o.status.code(), Some(2), "{args:?}: {:?}", text(&o));
        assert!(text(&o).1.contains(flag), "{args:?}: {}", text(&o).1);
    }
}

#[test]
fn render_writes_exr_png_and_json() {
    let c = tempfile::tempdir().unwrap();
    let exr_path = c.path().join("sky.exr");
    let png_path = c.path().join("sky.png");
    let args = [
        "render",
        "atmospheres/analytic-hg.toml",
        "--camera",
        "fisheye",
        "--size",
        "12x10",
        "--sun-zenith-deg",
        "70",
        "--spp",
        "4",
        "--band-nm",
        "47",
        "--spectral-nm",
        "550",
        "--out",
        exr_path.to_str().unwrap(),
        "--png",
        png_path.to_str().unwrap(),
        "--json",
    ];
    let o = sky(&args, c.path());
    assert!(o.status.success(), "{:?}", text(&o));
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["width"], 12);
    // stderr is not a terminal here: progress comes as plain lines.
    let err = text(&o).1;
    assert!(
        err.lines().any(|l| l.starts_with("sky render: ") && l.contains(" px), ") && l.contains("ETA")),
        "no progress line: {err}"
    );
    assert!(std::fs::read(&png_path).unwrap().starts_with(b"\x89PNG"));
    use exr::prelude::*;
    let img = read_all_flat_layers_from_file(&exr_path).unwrap();
    let layer = &img.layer_data[0];
    assert_eq!(layer.size, Vec2(12, 10));
    let names: Vec<String> = layer.channel_data.list.iter().map(|c| c.name.to_string()).collect();
    for n in ["X", "Y", "Z", "stderr.Y", "spectral.550nm", "stderr.spectral.550nm"] {
        assert!(names.iter().any(|x| x == n), "missing channel {n}: {names:?}");
    }
    let meta = match layer.attributes.other.get(&Text::from("sky.metadata")) {
        Some(AttributeValue::Text(t)) => t.to_string(),
        other => panic!("no sky.metadata attribute: {other:?}"),
    };
    let meta: Value = serde_json::from_str(&meta).unwrap();
    for k in ["atmosphere_hash", "sun_zenith_deg", "spp", "seed", "version"] {
        assert!(!meta[k].is_null(), "missing metadata {k}: {meta}");
    }
    // The same seed gives the same file, byte for byte.
    let again = c.path().join("again.exr");
    let mut args2 = args.to_vec();
    let pos = args2.iter().position(|a| *a == exr_path.to_str().unwrap()).unwrap();
    args2[pos] = again.to_str().unwrap();
    let o = sky(&args2, c.path());
    assert!(o.status.success());
    assert!(std::fs::read(&exr_path).unwrap() == std::fs::read(&again).unwrap(), "two renders with one seed differ");
}

#[test]
fn spectral_lines_render_without_xyz() {
    let c = tempfile::tempdir().unwrap();
    let exr_path = c.path().join("lines.exr");
    let args = [
        "render",
        "atmospheres/analytic-hg.toml",
        "--camera",
        "fisheye",
        "--size",
        "6x6",
        "--sun-zenith-deg",
        "40",
        "--spp",
        "4",
        "--spectral-nm",
        "450,650",
        "--no-xyz",
        "--out",
        exr_path.to_str().unwrap(),
        "--json",
    ];
    let o = sky(&args, c.path());
    assert!(o.status.success(), "{:?}", text(&o));
    use exr::prelude::*;
    let img = read_all_flat_layers_from_file(&exr_path).unwrap();
    let names: Vec<String> = img.layer_data[0].channel_data.list.iter().map(|c| c.name.to_string()).collect();
    assert!(names.iter().any(|x| x == "spectral.450nm") && names.iter().any(|x| x == "spectral.650nm"), "{names:?}");
    assert!(!names.iter().any(|x| x == "Y" || x == "X" || x == "Z"), "XYZ written without being estimated: {names:?}");
    // Without lines there is nothing to render; with a PNG there is nothing to tonemap.
    for (extra, flag) in
        [(vec![] as Vec<&str>, "--spectral-nm"), (vec!["--spectral-nm", "550", "--png", "x.png"], "--png")]
    {
        let mut a = vec!["render", "atmospheres/clear.toml", "--sun-zenith-deg", "30", "--no-xyz", "--out", "x.exr"];
        a.extend(extra);
        let o = sky(&a, c.path());
        assert_eq!(o.status.code(), Some(2), "{a:?}: {:?}", text(&o));
        assert!(text(&o).1.contains(flag), "{a:?}: {}", text(&o).1);
    }
}

#[test]
fn render_bad_flags_exit_2() {
    let c = tempfile::tempdir().unwrap();
    for (args, flag) in [
        (vec!["render", "atmospheres/clear.toml", "--sun-zenith-deg", "130", "--out", "x.exr"], "--sun-zenith-deg"),
        (vec!["render", "atmospheres/clear.toml", "--sun-zenith-deg", "30", "--out", "x.png"], "--out"),
        (
            vec!["render", "atmospheres/clear.toml", "--sun-zenith-deg", "30", "--size", "0x5", "--out", "x.exr"],
            "--size",
        ),
        (
            vec![
                "render",
                "atmospheres/clear.toml",
                "--sun-zenith-deg",
                "30",
                "--camera",
                "directions",
                "--out",
                "x.exr",
            ],
            "--directions",
        ),
        (vec!["render", "atmospheres/clear.toml", "--sun-zenith-deg", "30", "--spp", "0", "--out", "x.exr"], "--spp"),
    ] {
        let o = sky(&args, c.path());
        assert_eq!(o.status.code(), Some(2), "{args:?}: {:?}", text(&o));
        assert!(text(&o).1.contains(flag), "{args:?}: {}", text(&o).1);
    }
    let o = sky(
        &["render", "tests/bad_atmospheres/negative_sigma.toml", "--sun-zenith-deg", "30", "--out", "x.exr"],
        c.path(),
    );
    assert_eq!(o.status.code(), Some(1));
    assert!(!root().join("x.exr").exists());
}

#[test]
fn ctrl_c_stops_a_render_and_writes_nothing() {
    let c = tempfile::tempdir().unwrap();
    let out = c.path().join("big.exr");
    let mut child = Command::new(env!("CARGO_BIN_EXE_sky"))
        .args([
            "render",
            "atmospheres/analytic-hg.toml",
            "--camera",
            "equirect",
            "--size",
            "512x256",
            "--sun-zenith-deg",
            "60",
            "--spp",
            "100000",
            "--band-nm",
            "47",
            "--out",
        ])
        .arg(&out)
        .current_dir(root())
        .env("SKY_CACHE_DIR", c.path())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1500));
    // SIGINT, as Ctrl-C sends.
    let _ = Command::new("kill").args(["-INT", &child.id().to_string()]).status();
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(130));
    assert!(!out.exists());
    // The journal stays, for --resume.
    assert!(c.path().join("big.exr.journal").exists());
    let leftovers: Vec<_> = std::fs::read_dir(c.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .filter(|n| n.to_string_lossy().starts_with(".sky-tmp"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

#[test]
fn farm_flags_and_files_are_checked() {
    let c = tempfile::tempdir().unwrap();
    let out = c.path().join("sky.exr");
    let out_s = out.to_str().unwrap();
    let base = [
        "render",
        "atmospheres/analytic-hg.toml",
        "--sun-zenith-deg",
        "60",
        "--size",
        "4x4",
        "--spp",
        "2",
        "--out",
        out_s,
    ];
    // A worker without a token refuses to start, naming the ways to give one.
    let o = Command::new(env!("CARGO_BIN_EXE_sky"))
        .args(["worker", "--listen", "127.0.0.1:0"])
        .env_remove("SKY_FARM_TOKEN")
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(text(&o).1.contains("--token-file"), "{}", text(&o).1);
    let o = sky(&["worker", "--listen", "not-an-address", "--token-file", "x"], c.path());
    assert_eq!(o.status.code(), Some(2));
    assert!(text(&o).1.contains("--listen not-an-address"), "{}", text(&o).1);
    // A farm render without a token.
    let mut args: Vec<&str> = base.to_vec();
    args.extend(["--workers", "127.0.0.1:9"]);
    let o = Command::new(env!("CARGO_BIN_EXE_sky"))
        .args(&args)
        .current_dir(root())
        .env_remove("SKY_FARM_TOKEN")
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(text(&o).1.contains("token"), "{}", text(&o).1);
    // A broken farm file: the error names the file and the line.
    let farm = c.path().join("farm.toml");
    std::fs::write(&farm, "token_file = \"t\"\n[[worker]]\naddress = \"a:1\"\nthreads = 4\n").unwrap();
    let mut args: Vec<&str> = base.to_vec();
    args.extend(["--farm", farm.to_str().unwrap()]);
    let o = sky(&args, c.path());
    assert_eq!(o.status.code(), Some(1));
    let err = text(&o).1;
    assert!(err.contains("farm.toml") && err.contains("line 4") && err.contains("threads"), "{err}");
    // --resume needs --out; --verify-fraction is a fraction.
    let o = sky(&["render", "atmospheres/analytic-hg.toml", "--sun-zenith-deg", "60", "--json", "--resume"], c.path());
    assert_eq!(o.status.code(), Some(2));
    let mut args: Vec<&str> = base.to_vec();
    args.extend(["--verify-fraction", "1.5"]);
    let o = sky(&args, c.path());
    assert_eq!(o.status.code(), Some(2));
    assert!(text(&o).1.contains("--verify-fraction"), "{}", text(&o).1);
    // An unreachable worker fails the render clearly and writes nothing.
    let mut args: Vec<&str> = base.to_vec();
    args.extend(["--workers", "127.0.0.1:9", "--lease-s", "1"]);
    let o = Command::new(env!("CARGO_BIN_EXE_sky"))
        .args(&args)
        .current_dir(root())
        .env("SKY_FARM_TOKEN", "t")
        .env("SKY_CACHE_DIR", c.path())
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let err = text(&o).1;
    assert!(err.contains("no worker left") && err.contains("127.0.0.1:9"), "{err}");
    assert!(!out.exists());
}

/// A reader that goes away (`sky mie ... | head -2`) ends the program
/// quietly with exit code 0, as ripgrep does, instead of a panic (101).
/// The pipe is closed before the child writes its first line.
#[test]
fn closed_stdout_exits_quietly() {
    use std::process::Stdio;
    let c = tempfile::tempdir().unwrap();
    for args in [
        &["mie", "--m", "1.33-1e-7i", "--x", "10", "--angles-deg", "0,1,2,3,4,5,10,20,30,60,90,120,150,180"][..],
        &["atmosphere", "inspect", "atmospheres/clear.toml"][..],
    ] {
        let mut child = Command::new(env!("CARGO_BIN_EXE_sky"))
            .args(args)
            .current_dir(root())
            .env("SKY_CACHE_DIR", c.path())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        drop(child.stdout.take());
        let o = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(0), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
}

/// The hidden `--fault-*` flags are refused with a usage error unless
/// `SKY_FAULT_INJECTION=1` is set: a stray one in a user's script does not
/// make a worker misbehave.
#[test]
fn fault_flags_need_the_test_switch() {
    let c = tempfile::tempdir().unwrap();
    let exr = c.path().join("x.exr");
    for args in [
        &["worker", "--listen", "127.0.0.1:0", "--token-file", "/nonexistent", "--fault-corrupt"][..],
        &["worker", "--listen", "127.0.0.1:0", "--fault-sigkill-on-task", "0"][..],
        &[
            "render",
            "atmospheres/clear.toml",
            "--sun-zenith-deg",
            "30",
            "--size",
            "4x2",
            "--out",
            exr.to_str().unwrap(),
            "--fault-kill-after-columns",
            "3",
        ][..],
    ] {
        let o = sky(args, c.path());
        let err = text(&o).1;
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains("SKY_FAULT_INJECTION=1"), "{args:?}: {err}");
    }
    assert!(!exr.exists());
}
