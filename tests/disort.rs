//! The path tracer against DISORT (PythonicDISORT 1.8): plane-parallel
//! slabs, sun at 60°, diffuse sky radiance at the ground at 450, 550 and
//! 650 nm, relative to the solar irradiance. `tests/reference/disort.json`
//! (`scripts/regen_disort.py`): Rayleigh and Rayleigh + HG aerosol over a
//! Lambertian ground of albedo 0.3; `tests/reference/disort_clouds.json`
//! (`scripts/regen_disort_clouds.py`): Rayleigh air with an HG cloud
//! (g 0.85) of optical depth 1, 9 or 60 at 3-5 km over a ground of 0.1.
//! Acceptance: every z-score within the Šidák threshold of its family at a
//! 1 % family-wise false-alarm rate (about 3.7 for 72 comparisons) and the
//! family's aggregate Σz/√m within 2.58 (see `common`), and within 1 %
//! (clear slabs) or 2 % (clouds) wherever the standard error is below a
//! third of that.
//!
//! The CI test checks a subset of the view directions at a sample count
//! that keeps it to a few minutes on two cores; `cargo test --release --test
//! disort -- --ignored` runs the whole grid with more samples.

use crate::common::Family;
use serde_json::Value;
use sky::atmosphere::Atmosphere;
use sky::mie::MieCache;
use sky::render::{self, Scene, Settings};
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

struct Stats {
    family: Family,
    beyond_tolerance_precise: Vec<String>,
    precise: usize,
    /// Core-seconds of rendering per case label, and the largest relative
    /// standard error of its directions.
    seconds: Vec<(String, f64, f64)>,
}

/// Compares every case of `reference` (a JSON file under tests/reference)
/// at the directions in `view_zeniths` x `azimuths`, with `spp_for(name)`
/// samples; a comparison is precise when its standard error is below a
/// third of `tolerance` (relative), and must then be within it.
fn run(
    reference: &str,
    view_zeniths: &[f64],
    azimuths: &[f64],
    spp_for: &dyn Fn(&str) -> Option<u32>,
    tolerance: f64,
) -> Stats {
    let r: Value = serde_json::from_str(&std::fs::read_to_string(root().join(reference)).unwrap()).unwrap();
    let mut st = Stats { family: Family::default(), beyond_tolerance_precise: vec![], precise: 0, seconds: vec![] };
    for (case_index, case) in r["cases"].as_array().unwrap().iter().enumerate() {
        let atm = Atmosphere::load(&root().join(case["atmosphere"].as_str().unwrap())).unwrap();
        // None: this slab is not part of the run.
        let Some(spp) = spp_for(&atm.name) else { continue };
        let l = case["wavelength_nm"].as_f64().unwrap();
        let vz: Vec<f64> = case["view_zenith_deg"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        let ra: Vec<f64> =
            case["relative_azimuth_deg"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        let mut dirs = Vec::new();
        let mut expect = Vec::new();
        for (i, z) in vz.iter().enumerate() {
            for (j, a) in ra.iter().enumerate() {
                if view_zeniths.contains(z) && azimuths.contains(a) {
                    dirs.push((*z, *a));
                    expect.push(case["radiance_sr_inv"][i][j].as_f64().unwrap());
                }
            }
        }
        // A seed per case, so the cases' errors are independent.
        let seed_base: u64 = std::env::var("SKY_TEST_SEED").ok().and_then(|v| v.parse().ok()).unwrap_or(2023);
        let settings = Settings::directions(
            dirs.clone(),
            case["sun_zenith_deg"].as_f64().unwrap(),
            vec![l],
            spp,
            seed_base + case_index as u64,
            false,
        );
        let cache = MieCache::shared_by_tests();
        let scene = Scene::new(&atm, &settings.spectral, &cache, &|| {});
        let t0 = std::time::Instant::now();
        let img = render::render(&scene, &settings.view, &AtomicBool::new(false), &|| {}).unwrap();
        let core_s = t0.elapsed().as_secs_f64() * rayon::current_num_threads() as f64;
        let e_sun = atm.sun.irradiance_w_m2_nm.eval(l);
        let worst =
            img.pixels.iter().zip(&expect).map(|(px, want)| px.spectral_stderr[0] / e_sun / want).fold(0.0, f64::max);
        st.seconds.push((format!("{} {l} nm", atm.name), core_s, worst));
        for (k, px) in img.pixels.iter().enumerate() {
            let ours = px.spectral[0] / e_sun;
            let se = px.spectral_stderr[0] / e_sun;
            let want = expect[k];
            let z = (ours - want) / se.max(1e-300);
            let rel = (ours - want).abs() / want;
            let label = format!(
                "{} {l} nm view ({}, {}): ours {ours:.6e} ± {se:.1e}, DISORT {want:.6e} ({z:+.2} se, {:.2} %)",
                atm.name,
                dirs[k].0,
                dirs[k].1,
                100.0 * rel
            );
            if se / want < tolerance / 3.0 {
                st.precise += 1;
                if rel > tolerance {
                    st.beyond_tolerance_precise.push(label.clone());
                }
            }
            eprintln!("{label}");
            st.family.push(label, z);
        }
    }
    st
}

fn check(st: &Stats, compared: usize, min_precise: usize, tolerance: f64) {
    eprintln!(
        "{} compared, aggregate Σz/√m {:+.2}, {} with se < {:.2} %",
        st.family.z.len(),
        st.family.aggregate(),
        st.precise,
        100.0 * tolerance / 3.0
    );
    // The variance falls as 1/n, so the worst direction reaches a relative
    // standard error of tolerance / 2 (a 2-sigma interval within the
    // tolerance) after (worst / (tolerance / 2))² times the samples.
    for (label, s, worst) in &st.seconds {
        let to_tolerance = s * (worst / (tolerance / 2.0)).powi(2);
        eprintln!("  {label}: {s:.1} core-seconds, worst relative standard error {:.2} %: {to_tolerance:.0} core-seconds for {:.1} % on every direction", 100.0 * worst, 100.0 * tolerance / 2.0);
    }
    assert_eq!(st.family.z.len(), compared);
    assert!(st.precise >= min_precise, "too few precise comparisons to test the {} % criterion", 100.0 * tolerance);
    let failures = st.family.failures(0.01);
    assert!(failures.is_empty(), "disagreements with DISORT:\n{}", failures.join("\n"));
    assert!(
        st.beyond_tolerance_precise.is_empty(),
        "beyond {} % where converged:\n{}",
        100.0 * tolerance,
        st.beyond_tolerance_precise.join("\n")
    );
}

#[test]
fn path_tracer_agrees_with_disort() {
    // The Rayleigh slab with enough samples that many standard errors fall
    // below 0.33 %, so the 1 % criterion is exercised; the aerosol slab is
    // noisier per sample and is held mostly to the z-score criteria.
    let st = run(
        "tests/reference/disort.json",
        &[0.0, 40.0, 70.0, 85.0],
        &[0.0, 90.0, 180.0],
        &|name| Some(if name == "disort-rayleigh" { 80_000 } else { 20_000 }),
        0.01,
    );
    check(&st, 2 * 3 * 12, 10, 0.01);
}

#[test]
#[ignore = "the full DISORT grid: minutes of rendering (make validate)"]
fn path_tracer_agrees_with_disort_full_grid() {
    let zs = [0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0, 85.0];
    let az = [0.0, 30.0, 60.0, 90.0, 120.0, 150.0, 180.0];
    let st = run("tests/reference/disort.json", &zs, &az, &|_| Some(100_000), 0.01);
    check(&st, 2 * 3 * 70, 100, 0.01);
}

/// Samples per direction of the cloud test, per slab. The thick slabs'
/// estimates are heavy-tailed (a few paths that reach the cloud top carry
/// much of the mean), so a mean over few samples is more often below the
/// truth than above it and the z-scores lean negative: at 8 000 and 4 000
/// samples the family's aggregate ran between -2.3 and -3.5 with the seed,
/// at ten times that -1.9. These counts keep the test at about 20 seconds.
fn cloud_spp(name: &str) -> Option<u32> {
    let scale: u32 = std::env::var("SKY_TEST_SPP_SCALE").ok().and_then(|v| v.parse().ok()).unwrap_or(1);
    Some(
        scale
            * match name {
                "disort-cloud-tau1" => 40_000,
                "disort-cloud-tau9" => 32_000,
                _ => 24_000,
            },
    )
}

#[test]
fn path_tracer_agrees_with_disort_under_clouds() {
    let st = run("tests/reference/disort_clouds.json", &[0.0, 40.0, 70.0, 85.0], &[0.0, 180.0], &cloud_spp, 0.02);
    check(&st, 3 * 3 * 8, 0, 0.02);
}

#[test]
#[ignore = "the full DISORT cloud grid at 2 % on every direction: long (make validate)"]
fn path_tracer_agrees_with_disort_under_clouds_full_grid() {
    let zs = [0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0, 85.0];
    let az = [0.0, 30.0, 60.0, 90.0, 120.0, 150.0, 180.0];
    let st = run("tests/reference/disort_clouds.json", &zs, &az, &|name| cloud_spp(name).map(|n| 4 * n), 0.02);
    check(&st, 3 * 3 * 70, 100, 0.02);
}

/// The 2 % criterion where it can be reached in minutes: the optical depth
/// 1 and 9 slabs at the CI test's directions, with samples for standard
/// errors near 0.5 % (about 25 core-minutes on this project's machine).
#[test]
#[ignore = "the thin and middle cloud slabs converged to test the 2 % criterion: long (make validate)"]
fn path_tracer_is_within_two_percent_of_disort_under_thin_clouds() {
    let spp = |name: &str| match name {
        "disort-cloud-tau1" => Some(640_000),
        "disort-cloud-tau9" => Some(1_000_000),
        _ => None,
    };
    let st = run("tests/reference/disort_clouds.json", &[0.0, 40.0, 70.0, 85.0], &[0.0, 180.0], &spp, 0.02);
    check(&st, 2 * 3 * 8, 30, 0.02);
}

/// The 2 % criterion under the optical depth 60 slab: the CI test's
/// directions at 4 000 000 samples each, for standard errors near 0.5 %
/// (about 3 000 core-seconds on this project's machine; `make validate`).
#[test]
#[ignore = "the thick cloud slab converged to test the 2 % criterion: long (make validate)"]
fn path_tracer_is_within_two_percent_of_disort_under_a_thick_cloud() {
    let spp = |name: &str| (name == "disort-cloud-tau60").then_some(4_000_000);
    let st = run("tests/reference/disort_clouds.json", &[0.0, 40.0, 70.0, 85.0], &[0.0, 180.0], &spp, 0.02);
    check(&st, 3 * 8, 16, 0.02);
}
