//! The deterministic solver (`sky::transport`) against DISORT: the same
//! references the path tracer meets (`tests/reference/disort.json`,
//! Rayleigh and Rayleigh + HG slabs over a ground of 0.3;
//! `tests/reference/disort_clouds.json`, an HG cloud of optical depth 1, 9
//! or 60 in Rayleigh air over a ground of 0.1; PythonicDISORT at 128
//! streams, sun at 60°, diffuse radiance at the ground, 450/550/650 nm).
//! No noise on either side, so the bound is plain: every view more than 5°
//! from the sun within 0.5 % (issue 37).

use serde_json::Value;
use sky::atmosphere::Atmosphere;
use sky::mie::MieCache;
use sky::render::medium::Medium;
use sky::transport::layers::{Grading, Layers};
use sky::transport::plane_parallel::{ground_radiance, View};
use std::path::PathBuf;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
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
        let zen: Vec<f64> = case["view_zenith_deg"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        let az: Vec<f64> =
            case["relative_azimuth_deg"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        let (mut views, mut want) = (Vec::new(), Vec::new());
        for (i, z) in zen.iter().enumerate() {
            for (j, a) in az.iter().enumerate() {
                let (zr, ar, sr) = (z.to_radians(), a.to_radians(), sun_zenith_deg.to_radians());
                let cos_from_sun = zr.cos() * sr.cos() + zr.sin() * sr.sin() * ar.cos();
                if cos_from_sun.clamp(-1.0, 1.0).acos().to_degrees() <= 5.0 {
                    continue;
                }
                views.push(View { mu: zr.cos(), azimuth_from_sun_rad: ar });
                want.push(case["radiance_sr_inv"][i][j].as_f64().unwrap());
            }
        }
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
    assert!(clear < 0.005 && clouds < 0.005, "worst relative error: clear slabs {clear:e}, clouds {clouds:e}");
}
