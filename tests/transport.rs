//! The deterministic solver (`sky::transport`) against DISORT: the same
//! references the path tracer meets (`tests/reference/disort.json`,
//! Rayleigh and Rayleigh + HG slabs over a ground of 0.3;
//! `tests/reference/disort_clouds.json`, an HG cloud of optical depth 1, 9
//! or 60 in Rayleigh air over a ground of 0.1; PythonicDISORT at 128
//! streams, sun at 60°, diffuse radiance at the ground, 450/550/650 nm;
//! `tests/reference/disort_horizon.json`, the slabs at views 85 to 89°).
//! No noise on either side, so the bound is plain: every view more than 5°
//! from the sun within 0.5 % (issue 37).

use crate::common::Family;
use serde_json::Value;
use sky::atmosphere::Atmosphere;
use sky::mie::MieCache;
use sky::render::medium::Medium;
use sky::render::{Scene, Settings, SpectralSettings, WavelengthSampling};
use sky::transport::adding::{ground_radiance, View};
use sky::transport::layers::{Grading, Layers};
use sky::transport::render::{render, render_views, Resolution};
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A reference case's views more than 5° from the sun, as (zenith,
/// azimuth from the sun) in degrees, each with DISORT's radiance.
fn views_beyond_5_degrees(case: &Value) -> Vec<((f64, f64), f64)> {
    let numbers =
        |key: &str| -> Vec<f64> { case[key].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect() };
    let sun = sky::directions::camera::direction_deg(case["sun_zenith_deg"].as_f64().unwrap(), 0.0);
    let mut out = Vec::new();
    for (i, z) in numbers("view_zenith_deg").iter().enumerate() {
        for (j, a) in numbers("relative_azimuth_deg").iter().enumerate() {
            let d = sky::directions::camera::direction_deg(*z, *a);
            if d.dot(sun).clamp(-1.0, 1.0).acos().to_degrees() > 5.0 {
                out.push(((*z, *a), case["radiance_sr_inv"][i][j].as_f64().unwrap()));
            }
        }
    }
    out
}

/// The largest relative error over every case and view beyond 5° of the
/// sun, printing each case's worst, at `streams` a hemisphere.
fn worst_against(reference: &str, streams: usize, grading: &Grading) -> f64 {
    let r: Value = serde_json::from_str(&std::fs::read_to_string(root().join(reference)).unwrap()).unwrap();
    let cache = MieCache::shared_by_tests();
    let mut worst = 0.0f64;
    for case in r["cases"].as_array().unwrap() {
        let atm = Atmosphere::load(&root().join(case["atmosphere"].as_str().unwrap())).unwrap();
        let medium = Medium::new(&atm);
        let nm = case["wavelength_nm"].as_f64().unwrap();
        let spectral = medium.spectral(&atm, nm, 1.0, case["ground_albedo"].as_f64().unwrap(), &cache);
        let layers = Layers::new(&medium, &spectral, 2 * streams, grading);
        let sun_zenith_deg = case["sun_zenith_deg"].as_f64().unwrap();
        let (views, want): (Vec<View>, Vec<f64>) = views_beyond_5_degrees(case)
            .into_iter()
            .map(|((z, a), w)| (View { mu: z.to_radians().cos(), azimuth_from_sun_rad: a.to_radians() }, w))
            .unzip();
        let got = ground_radiance(&layers, streams, sun_zenith_deg.to_radians().cos(), &views);
        let mut case_worst = (0.0f64, 0usize);
        for (k, (g, w)) in got.iter().zip(&want).enumerate() {
            let rel = (g - w).abs() / w;
            if rel > case_worst.0 {
                case_worst = (rel, k);
            }
        }
        let v = views[case_worst.1];
        eprintln!(
            "{} at {nm} nm, {} layers, {streams} streams: worst {:.3} % at view zenith {:.1}°, azimuth {:.0}° ({:.5e} against {:.5e})",
            atm.name,
            layers.layers.len(),
            100.0 * case_worst.0,
            v.mu.acos().to_degrees(),
            v.azimuth_from_sun_rad.to_degrees(),
            got[case_worst.1],
            want[case_worst.1]
        );
        worst = worst.max(case_worst.0);
    }
    worst
}

#[test]
fn plane_parallel_skies_match_disort_beyond_5_degrees_of_the_sun() {
    let grading = Grading::default();
    let clear = worst_against("tests/reference/disort.json", 16, &grading);
    let clouds = worst_against("tests/reference/disort_clouds.json", 32, &grading);
    // The same slabs at 85, 88 and 89° from the zenith: long, nearly horizontal paths.
    let horizon = worst_against("tests/reference/disort_horizon.json", 16, &grading);
    assert!(
        clear < 0.005 && clouds < 0.005 && horizon < 0.005,
        "worst relative error: clear slabs {clear:e}, clouds {clouds:e}, near the horizon {horizon:e}"
    );
}

/// `sky render --method deterministic`'s pixels (the render's spectral
/// lines, its single scattering by the path tracer's own quadrature, the
/// diffuse light interpolated on the view grid) against DISORT in the clear
/// and hazed slabs: every view beyond 5° of the sun within 0.5 %.
#[test]
fn deterministic_renders_match_disort_beyond_5_degrees_of_the_sun() {
    let r: Value =
        serde_json::from_str(&std::fs::read_to_string(root().join("tests/reference/disort.json")).unwrap()).unwrap();
    let cache = MieCache::shared_by_tests();
    let mut worst = (0.0f64, String::new());
    for case in r["cases"].as_array().unwrap() {
        let atm = Atmosphere::load(&root().join(case["atmosphere"].as_str().unwrap())).unwrap();
        let nm = case["wavelength_nm"].as_f64().unwrap();
        let sun_zenith_deg = case["sun_zenith_deg"].as_f64().unwrap();
        let (dirs, want): (Vec<(f64, f64)>, Vec<f64>) = views_beyond_5_degrees(case).into_iter().unzip();
        let settings = Settings::directions(dirs.clone(), sun_zenith_deg, vec![nm], 1, 1, false);
        let scene = Scene::new(&atm, &settings.spectral, &cache, &|| {});
        let image = render(&scene, &settings.view, &Resolution::default(), &|| {}).unwrap();
        let e_sun = atm.sun.irradiance_w_m2_nm.eval(nm);
        for ((p, w), d) in image.pixels.iter().zip(&want).zip(&dirs) {
            assert_eq!(p.spectral_stderr, vec![0.0]);
            let rel = (p.spectral[0] / e_sun - w).abs() / w;
            if rel > worst.0 {
                worst =
                    (rel, format!("{} {nm} nm view {d:?}: {:.5e} against {w:.5e}", atm.name, p.spectral[0] / e_sun));
            }
        }
    }
    eprintln!("worst: {:.3} % ({})", 100.0 * worst.0, worst.1);
    assert!(worst.0 < 0.005, "{worst:?}");
}

/// The deterministic render against the path tracer, in XYZ: views from
/// the zenith to 85° at three azimuths, the sun's own direction (its disk
/// on) and the ground. Each difference in units of the path tracer's
/// standard error goes into `family`; the largest relative difference is
/// returned. Both renders share the scene, so 20 nm bands (half the cost of
/// 10) compare like with like.
fn agree_in_xyz(atmosphere: &str, sun_zenith_deg: f64, spp: u32, seed: u64, family: &mut Family) -> f64 {
    let atm = Atmosphere::load(&root().join(atmosphere)).unwrap();
    let mut dirs = vec![(sun_zenith_deg, 0.0), (120.0, 30.0)];
    for z in [0.0, 30.0, 60.0, 75.0, 85.0] {
        for a in [20.0, 90.0, 180.0] {
            dirs.push((z, a));
        }
    }
    let mut settings = Settings::directions(dirs.clone(), sun_zenith_deg, vec![], spp, seed, true);
    settings.spectral = SpectralSettings {
        band_nm: 20.0,
        wavelength_sampling: WavelengthSampling::Hero,
        spectral_nm: vec![],
        xyz: true,
    };
    let scene = Scene::new(&atm, &settings.spectral, &MieCache::shared_by_tests(), &|| {});
    let mc = sky::render::render(&scene, &settings.view, &AtomicBool::new(false), &|| {}).unwrap();
    let det = render(&scene, &settings.view, &Resolution::default(), &|| {}).unwrap();
    let mut worst = 0.0f64;
    for ((m, d), dir) in mc.pixels.iter().zip(&det.pixels).zip(&dirs) {
        for c in 0..3 {
            let z = (d.xyz[c] - m.xyz[c]) / m.xyz_stderr[c];
            let rel = d.xyz[c] / m.xyz[c] - 1.0;
            let label = format!(
                "{} sun {sun_zenith_deg}, view {dir:?} channel {c}: deterministic {:.5e}, path tracer {:.5e} ± {:.1e} ({:+.2} %)",
                atm.name,
                d.xyz[c],
                m.xyz[c],
                m.xyz_stderr[c],
                100.0 * rel
            );
            eprintln!("{label}: z {z:+.2}");
            family.push(label, z);
            worst = worst.max(rel.abs());
        }
        assert_eq!(d.xyz_stderr, [0.0; 3]);
    }
    worst
}

/// The deterministic render against the path tracer in the hazed slab
/// (plane-parallel, sun at 50°) and, pseudo-spherical, in the clear and
/// hazed basis atmospheres (suns at 60° and 80°): every z-score against
/// the Šidák threshold of the family at a false-alarm rate of 1 %, with
/// the aggregate Σz/√m against a bias common to all (`stats::Family`).
#[test]
fn deterministic_and_monte_carlo_renders_agree_in_xyz() {
    let mut family = Family::default();
    for (atmosphere, sun, seed) in [
        ("tests/atmospheres/disort_rayleigh_hg.toml", 50.0, 37),
        ("atmospheres/clear.toml", 60.0, 38),
        ("atmospheres/hazed.toml", 80.0, 39),
    ] {
        let worst = agree_in_xyz(atmosphere, sun, 4096, seed, &mut family);
        eprintln!("{atmosphere}, sun {sun}: largest difference {:.2} %", 100.0 * worst);
    }
    let failures = family.failures(0.01);
    assert!(failures.is_empty(), "{failures:#?}");
}

/// The talk's global fog by the solver (`transport::render`: the same sums
/// stopped at each ray's reach) against the path tracer's, `clear.toml`,
/// sun 60°: in front of objects 5 and 20 km away, and at 20 km under a
/// ceiling at 1 km, lit and Shadowed. Bound: within 2 % plus four of the
/// path tracer's standard errors (a false alarm of 6e-5 a direction), not
/// 1 %: the solver's multiply scattered light near the ground is low at
/// near-horizontal views (measured 2026-12-07 at 262 144 samples, 5 km,
/// Shadowed Fog: −0.3 % at view 30°, −3.4 % at 80°, −3.8 % at 88°; at
/// infinite distance +2.0, −0.7 and −1.8 %), which the lit fog's exact
/// single scattering dilutes (5 km: −0.04 to −1.1 % at 4 096 samples).
#[test]
fn deterministic_fog_against_the_path_tracer() {
    use sky::render::fog::Fog;
    let atm = Atmosphere::load(&root().join("atmospheres/clear.toml")).unwrap();
    let dirs = vec![(30.0, 0.0), (60.0, 90.0), (80.0, 0.0), (80.0, 180.0), (88.0, 45.0)];
    let spectral = SpectralSettings {
        band_nm: 20.0,
        wavelength_sampling: WavelengthSampling::Hero,
        spectral_nm: vec![],
        xyz: true,
    };
    let scene = Scene::new(&atm, &spectral, &MieCache::shared_by_tests(), &|| {});
    let resolution = Resolution { ms_step_nm: 60.0, ..Resolution::default() };
    let mut worst = 0.0f64;
    let fogs = [Fog::lit(5.0, None), Fog::lit(20.0, None), Fog::lit(20.0, Some(1.0)), Fog::lit(5.0, None).shadowed()];
    for (k, fog) in fogs.into_iter().enumerate() {
        let mut settings = Settings::directions(dirs.clone(), 60.0, vec![], 16384, 70 + k as u64, false);
        settings.spectral = spectral.clone();
        settings.view.fog = Some(fog);
        let mc = sky::render::render(&scene, &settings.view, &AtomicBool::new(false), &|| {}).unwrap();
        let det = render(&scene, &settings.view, &resolution, &|| {}).unwrap();
        for ((m, d), dir) in mc.pixels.iter().zip(&det.pixels).zip(&dirs) {
            let (y, se) = (m.xyz[1], m.xyz_stderr[1]);
            let rel = d.xyz[1] / y - 1.0;
            eprintln!(
                "{fog:?}, view {dir:?}: Y {:.5e} against {y:.5e} ± {:.2} % ({:+.2} %)",
                d.xyz[1],
                100.0 * se / y,
                100.0 * rel
            );
            assert!(rel.abs() < 0.02 + 4.0 * se / y, "{fog:?}, view {dir:?}: {:+.2} %", 100.0 * rel);
            worst = worst.max(rel.abs());
        }
    }
    eprintln!("largest difference {:.2} %", 100.0 * worst);
}

/// The command line: `--method deterministic` renders a plane-parallel
/// atmosphere to the same outputs (zero standard errors, the method in the
/// JSON and the EXR's metadata) and refuses what it cannot render yet with
/// a usage error that says why, before any work.
#[test]
fn the_method_flag_renders_or_says_why_not() {
    let dir = tempfile::tempdir().unwrap();
    let sky = |args: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_sky"))
            .args(args)
            .current_dir(root())
            .env("SKY_CACHE_DIR", MieCache::test_dir())
            .output()
            .unwrap()
    };
    let exr = dir.path().join("pp.exr");
    let o = sky(&[
        "render",
        "tests/atmospheres/disort_rayleigh_hg.toml",
        "--method",
        "deterministic",
        "--sun-zenith-deg",
        "40",
        "--size",
        "24x12",
        "--camera",
        "equirect",
        "--band-nm",
        "20",
        "--out",
        exr.to_str().unwrap(),
        "--json",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["method"], "deterministic (16 streams a hemisphere)");
    assert_eq!(v["y_relative_stderr"]["median"], 0.0, "{v}");
    let bytes = std::fs::read(&exr).unwrap();
    assert!(bytes.windows(13).any(|w| w == b"deterministic"), "the EXR's metadata names the method");
    for (args, says) in [
        (&["atmospheres/clear.toml", "--sun-zenith-deg", "100"][..], "twilight"),
        (&["tests/atmospheres/disort_rayleigh_hg.toml", "--sun-zenith-deg", "40", "--altitude-m", "500"][..], "ground"),
        (&["tests/atmospheres/disort_rayleigh_hg.toml", "--sun-zenith-deg", "40", "--denoise"][..], "--denoise"),
    ] {
        let o = sky(&[&["render", "--method", "deterministic", "--size", "4x4", "--json"][..], args].concat());
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(says), "{args:?}: {err}");
    }
}

/// The deterministic render toward the directions of a committed path
/// tracer reference (`examples/path_tracer_reference.rs`), every case:
/// per direction, the relative difference in Y and its z against the
/// reference's standard error, pushed into `family`; the labels of those
/// beyond `bound` where the reference's relative standard error is below
/// `bound` / 3 (where it can tell).
fn against_path_tracer(file: &str, resolution: &Resolution, bound: f64, family: &mut Family) -> Vec<String> {
    let reference: Value = serde_json::from_str(&std::fs::read_to_string(root().join(file)).unwrap()).unwrap();
    let atm = Atmosphere::load(&root().join(reference["atmosphere"].as_str().unwrap())).unwrap();
    let spectral = SpectralSettings {
        band_nm: reference["band_nm"].as_f64().unwrap(),
        wavelength_sampling: WavelengthSampling::Hero,
        spectral_nm: vec![],
        xyz: true,
    };
    let scene = Scene::new(&atm, &spectral, &MieCache::shared_by_tests(), &|| {});
    let cases = reference["cases"].as_array().unwrap();
    let directions = |case: &Value| -> Vec<(f64, f64)> {
        case["directions"]
            .as_array()
            .unwrap()
            .iter()
            .map(|d| (d["zenith_deg"].as_f64().unwrap(), d["azimuth_from_sun_deg"].as_f64().unwrap()))
            .collect()
    };
    // Every case's sun in one solution (each image is the one its view
    // alone gives, bit for bit): the twilight suns share one spherical
    // iteration a wavelength.
    let views: Vec<sky::render::View> = cases
        .iter()
        .map(|case| {
            let sun = case["sun_zenith_deg"].as_f64().unwrap();
            Settings::directions(directions(case), sun, vec![], 1, 1, false).view
        })
        .collect();
    let images = render_views(&scene, &views, resolution, &|| {}).unwrap();
    let mut beyond = Vec::new();
    for (case, det) in cases.iter().zip(images) {
        let sun = case["sun_zenith_deg"].as_f64().unwrap();
        let dirs = directions(case);
        for ((d, m), dir) in det.pixels.iter().zip(case["directions"].as_array().unwrap()).zip(&dirs) {
            let (y, se) = (m["xyz"][1].as_f64().unwrap(), m["xyz_stderr"][1].as_f64().unwrap());
            let (rel, z) = (d.xyz[1] / y - 1.0, (d.xyz[1] - y) / se);
            let label = format!(
                "{file}: sun {sun}, view {dir:?}: Y {:.5e} against {y:.5e} ± {:.2} % ({:+.2} %)",
                d.xyz[1],
                100.0 * se / y,
                100.0 * rel
            );
            eprintln!("{label}: z {z:+.1}");
            if rel.abs() > bound && se / y < bound / 3.0 {
                beyond.push(label.clone());
            }
            family.push(label, z);
        }
    }
    beyond
}

/// Issue 37's judge of the spherical skies by day, for `make validate`:
/// the deterministic render (32 streams a hemisphere) against the path
/// tracer at 65 536 samples on 12 directions (standard errors 0.05 to
/// 0.3 % in `clear.toml`, 0.1 to 1.3 % in `hazed.toml`), the sun at 20°,
/// 60° and 85° from the zenith
/// (`tests/reference/path_tracer_{clear,hazed}_day.json`); every
/// direction within the Šidák threshold of the family at a false-alarm
/// rate of 1 % and within 1 % where the reference can tell (standard error
/// below 0.33 %), and no common bias (the aggregate z of the 72 within ±4,
/// a false alarm of 6e-5).
#[test]
#[ignore = "32 streams on 36 directions: minutes (make validate)"]
fn deterministic_daylight_against_a_converged_path_tracer() {
    let mut family = Family::default();
    let resolution = Resolution { streams: 32, ..Default::default() };
    let mut beyond = Vec::new();
    for sky in ["clear", "hazed"] {
        let file = format!("tests/reference/path_tracer_{sky}_day.json");
        beyond.extend(against_path_tracer(&file, &resolution, 0.01, &mut family));
    }
    let failures = family.failures(0.01);
    let aggregate = family.aggregate();
    eprintln!("aggregate z {aggregate:+.2}");
    assert!(failures.is_empty() && beyond.is_empty(), "beyond 1 %: {beyond:#?}\nbeyond the threshold: {failures:#?}");
    assert!(aggregate.abs() < 4.0, "a common bias: aggregate z {aggregate:+.2}");
}

/// Issue 37's twilight judge, for `make validate`: the deterministic
/// render (16 streams, columns every 1°, their sources made spherical by
/// `transport::spherical`) against the path tracer at 65 536
/// samples on 12 directions (`tests/reference/path_tracer_clear_twilight.json`,
/// `clear.toml`, the sun 91°, 93°, 96° and 99° from the zenith; the
/// samples' cost is in the file): every direction within the Šidák
/// threshold of the family at a false-alarm rate of 1 % and within 1 %
/// where the reference's standard error can tell (below 0.33 %), and no
/// common bias (aggregate z within ±4). Measured (2026-12-06, 2 cores,
/// 1 738 s): all 48 within the threshold (|z| ≤ 3.1), aggregate −2.1; the
/// columns alone failed it at −0.1 to −99.9 % (aggregate −92).
#[test]
#[ignore = "the twilight judge: half an hour (make validate)"]
fn deterministic_twilight_against_the_path_tracer() {
    let mut family = Family::default();
    let beyond = against_path_tracer(
        "tests/reference/path_tracer_clear_twilight.json",
        &Resolution { spherical: true, ..Resolution::default() },
        0.01,
        &mut family,
    );
    let failures = family.failures(0.01);
    let aggregate = family.aggregate();
    eprintln!("aggregate z {aggregate:+.2}");
    let told: Vec<&String> =
        beyond.iter().filter(|l| l.contains("± 0.0") || l.contains("± 0.1") || l.contains("± 0.2")).collect();
    assert!(failures.is_empty() && told.is_empty(), "beyond 1 %: {told:#?}\nbeyond the threshold: {failures:#?}");
    assert!(aggregate.abs() < 4.0, "a common bias: aggregate z {aggregate:+.2}");
}

/// Reciprocity of the whole solution (issue 37, item 4): for a slab that is
/// homogeneous in optical depth (the Rayleigh + HG test slab: air and
/// aerosol share one profile) over a black ground, the diffuse transmission
/// t(μ, μ₀) = π I / (μ₀ F₀) is symmetric in the view and the sun
/// (Chandrasekhar 1960, §44): I(μ_a; μ₀ = μ_b) / μ_b = I(μ_b; μ₀ = μ_a) / μ_a
/// at the same relative azimuth. The sun's beam is exact in each layer and
/// the view's source is linear across it, so the two sides differ by the
/// layers' discretisation, which falls as the square of their thickness:
/// worst 8.9e-4 with layers twice as thick as the default, 2.2e-4 with the
/// default layers, 7.5e-5 with layers half as thick (at μ 0.15). Bound 3e-4.
#[test]
fn sun_and_view_swapped_give_the_same_transmission() {
    let atm = Atmosphere::load(&root().join("tests/atmospheres/disort_rayleigh_hg.toml")).unwrap();
    let medium = Medium::new(&atm);
    let optics = medium.spectral(&atm, 550.0, 1.0, 0.0, &MieCache::shared_by_tests());
    let mut layers = Layers::new(&medium, &optics, 32, &Grading::default());
    layers.ground_albedo = 0.0;
    let cosines = [0.95, 0.7, 0.4, 0.15];
    let mut worst = 0.0f64;
    for (i, &a) in cosines.iter().enumerate() {
        for &b in &cosines[i + 1..] {
            for phi in [0.0f64, 1.0, 2.5] {
                let view = |mu| [View { mu, azimuth_from_sun_rad: phi }];
                let ab = ground_radiance(&layers, 16, b, &view(a))[0] / b;
                let ba = ground_radiance(&layers, 16, a, &view(b))[0] / a;
                let rel = (ab - ba).abs() / ab.max(ba);
                eprintln!("μ {a} and {b}, φ {phi}: {ab:.6e} against {ba:.6e} ({rel:.1e})");
                worst = worst.max(rel);
            }
        }
    }
    assert!(worst < 3e-4, "reciprocity broken by {worst:e}");
}
