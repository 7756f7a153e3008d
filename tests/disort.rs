//! The path tracer against DISORT (PythonicDISORT 1.8, via
//! `scripts/regen_disort.py` → `tests/reference/disort.json`): plane-parallel
//! slabs over a Lambertian ground (albedo 0.3), sun at 60°, diffuse sky
//! radiance at the ground at 450, 550 and 650 nm, relative to the solar
//! irradiance. Acceptance: within 3 standard errors everywhere, and within
//! 1 % wherever the standard error is below 0.3 %.
//!
//! The CI test checks a subset of the view directions at a sample count
//! that keeps it to a few minutes on two cores; `cargo test --release --test
//! disort -- --ignored` runs the whole grid with more samples.

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
    compared: usize,
    beyond_3se: Vec<String>,
    beyond_1pct_precise: Vec<String>,
    precise: usize,
    worst_z: f64,
}

fn run(view_zeniths: &[f64], azimuths: &[f64], spp_for: &dyn Fn(&str) -> u32) -> Stats {
    let r: Value = serde_json::from_str(&std::fs::read_to_string(root().join("tests/reference/disort.json")).unwrap()).unwrap();
    let mut st = Stats { compared: 0, beyond_3se: vec![], beyond_1pct_precise: vec![], precise: 0, worst_z: 0.0 };
    for (case_index, case) in r["cases"].as_array().unwrap().iter().enumerate() {
        let atm = Atmosphere::load(&root().join(case["atmosphere"].as_str().unwrap())).unwrap();
        let spp = spp_for(&atm.name);
        let l = case["wavelength_nm"].as_f64().unwrap();
        let vz: Vec<f64> = case["view_zenith_deg"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        let ra: Vec<f64> = case["relative_azimuth_deg"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
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
        let settings = Settings::directions(dirs.clone(), case["sun_zenith_deg"].as_f64().unwrap(), vec![l], spp, 2023 + case_index as u64, false);
        let cache = MieCache::new(None);
        let scene = Scene::new(&atm, &settings, &cache, &|| {});
        let img = render::render(&scene, &settings, &AtomicBool::new(false), &|| {}).unwrap();
        let e_sun = atm.sun.irradiance_w_m2_nm.eval(l);
        for (k, px) in img.pixels.iter().enumerate() {
            let ours = px.spectral[0] / e_sun;
            let se = px.spectral_stderr[0] / e_sun;
            let want = expect[k];
            let z = (ours - want).abs() / se.max(1e-300);
            let rel = (ours - want).abs() / want;
            let label = format!("{} {l} nm view ({}, {}): ours {ours:.6e} ± {se:.1e}, DISORT {want:.6e} ({z:.2} se, {:.2} %)", atm.name, dirs[k].0, dirs[k].1, 100.0 * rel);
            st.compared += 1;
            st.worst_z = st.worst_z.max(z);
            if z > 3.0 {
                st.beyond_3se.push(label.clone());
            }
            if se / want < 0.003 {
                st.precise += 1;
                if rel > 0.01 {
                    st.beyond_1pct_precise.push(label.clone());
                }
            }
            eprintln!("{label}");
        }
    }
    st
}

#[test]
fn path_tracer_agrees_with_disort() {
    // The Rayleigh slab with enough samples that many standard errors fall
    // below 0.3 %, so the 1 % criterion is exercised; the aerosol slab is
    // noisier per sample and is held to the 3-standard-error criterion.
    let st = run(&[0.0, 40.0, 70.0, 85.0], &[0.0, 90.0, 180.0], &|name| if name == "disort-rayleigh" { 80_000 } else { 20_000 });
    eprintln!("{} compared, worst {:.2} se, {} with se < 0.3 %", st.compared, st.worst_z, st.precise);
    assert_eq!(st.compared, 2 * 3 * 12);
    assert!(st.precise >= 10, "too few precise comparisons to test the 1 % criterion");
    assert!(st.beyond_3se.is_empty(), "beyond 3 standard errors:\n{}", st.beyond_3se.join("\n"));
    assert!(st.beyond_1pct_precise.is_empty(), "beyond 1 % where se < 0.3 %:\n{}", st.beyond_1pct_precise.join("\n"));
}

#[test]
#[ignore = "the full DISORT grid: minutes of rendering (make validate)"]
fn path_tracer_agrees_with_disort_full_grid() {
    let zs = [0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0, 85.0];
    let az = [0.0, 30.0, 60.0, 90.0, 120.0, 150.0, 180.0];
    let st = run(&zs, &az, &|_| 100_000);
    eprintln!("{} compared, worst {:.2} se, {} with se < 0.3 %", st.compared, st.worst_z, st.precise);
    assert!(st.beyond_3se.is_empty(), "beyond 3 standard errors:\n{}", st.beyond_3se.join("\n"));
    assert!(st.beyond_1pct_precise.is_empty(), "beyond 1 % where se < 0.3 %:\n{}", st.beyond_1pct_precise.join("\n"));
}
