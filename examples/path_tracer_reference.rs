//! The path tracer as the referee (issue 37, item 4): XYZ with standard
//! errors toward a fixed set of directions, for an atmosphere and a list of
//! sun zenith angles, written as JSON with the samples, seeds, cost and
//! commit that made it, for the deterministic solver's tests to read
//! (`tests/reference/path_tracer_*.json`).
//!
//! cargo run --release --example path_tracer_reference -- ATMOSPHERE SPP SEED OUT.json SUN_ZENITH_DEG...

use serde_json::json;
use sky::atmosphere::Atmosphere;
use sky::mie::MieCache;
use sky::render::{Scene, Settings, SpectralSettings, WavelengthSampling};
use std::sync::atomic::AtomicBool;
use std::time::Instant;

/// The directions (zenith, azimuth from the sun, degrees): the zenith, and
/// toward, across and away from the sun at four heights down to 2° above
/// the horizon.
const DIRECTIONS: [(f64, f64); 12] = [
    (0.0, 0.0),
    (30.0, 0.0),
    (30.0, 90.0),
    (30.0, 180.0),
    (60.0, 30.0),
    (60.0, 90.0),
    (60.0, 180.0),
    (80.0, 10.0),
    (80.0, 90.0),
    (80.0, 180.0),
    (88.0, 45.0),
    (88.0, 180.0),
];

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 6 {
        eprintln!("usage: path_tracer_reference ATMOSPHERE SPP SEED OUT.json SUN_ZENITH_DEG...");
        std::process::exit(2);
    }
    let atm = Atmosphere::load(std::path::Path::new(&args[1])).unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(1)
    });
    let spp: u32 = args[2].parse().expect("samples a direction");
    let seed: u64 = args[3].parse().expect("a seed");
    let suns: Vec<f64> = args[5..].iter().map(|s| s.parse().expect("a sun zenith angle in degrees")).collect();
    let spectral = SpectralSettings {
        band_nm: 10.0,
        wavelength_sampling: WavelengthSampling::Hero,
        spectral_nm: vec![],
        xyz: true,
    };
    let scene = Scene::new(&atm, &spectral, &MieCache::from_env(), &|| {});
    let threads = rayon::current_num_threads();
    let mut cases = Vec::new();
    for (k, &sun) in suns.iter().enumerate() {
        let mut settings = Settings::directions(DIRECTIONS.to_vec(), sun, vec![], spp, seed + k as u64, false);
        settings.spectral = spectral.clone();
        let start = Instant::now();
        let image = sky::render::render(&scene, &settings.view, &AtomicBool::new(false), &|| {}).expect("renders");
        let wall_s = start.elapsed().as_secs_f64();
        let directions: Vec<_> = DIRECTIONS
            .iter()
            .zip(&image.pixels)
            .map(|(&(zenith, azimuth), p)| {
                json!({"zenith_deg": zenith, "azimuth_from_sun_deg": azimuth, "xyz": p.xyz, "xyz_stderr": p.xyz_stderr})
            })
            .collect();
        eprintln!("sun {sun}: {wall_s:.0} s on {threads} threads");
        cases.push(json!({
            "sun_zenith_deg": sun, "spp": spp, "seed": seed + k as u64,
            "wall_s": wall_s, "threads": threads, "directions": directions,
        }));
    }
    let commit = std::process::Command::new("git")
        .args(["rev-parse", "--short", "HEAD"])
        .output()
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .unwrap_or_default();
    let out = json!({
        "generator": format!("cargo run --release --example path_tracer_reference -- {}", args[1..].join(" ")),
        "commit": commit,
        "atmosphere": args[1],
        "band_nm": 10.0,
        "wavelength_sampling": "hero",
        "cases": cases,
    });
    let tmp = format!("{}.tmp", args[4]);
    std::fs::write(&tmp, serde_json::to_string_pretty(&out).expect("serialises") + "\n").expect("writes");
    std::fs::rename(&tmp, &args[4]).expect("renames");
}
