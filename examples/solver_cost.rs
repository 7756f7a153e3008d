//! Where one wavelength of a deterministic bake's time goes: the layers,
//! the daytime columns (every sun 0 to 88°), the spherical twilight
//! columns (88 to 100°), and the diffuse light's table of one slice.
//!
//! cargo run --release --example solver_cost -- ATMOSPHERE [WAVELENGTH_NM] [STREAMS] [draft|full] [KEY=VALUE ...]
//!
//! `draft`: the twilight iteration's draft settings (`spherical::Settings::draft`);
//! KEY=VALUE: a setting of the iteration changed (stop_tau, levels=full|draft,
//! modes, azimuths, cosines, tolerance, passes, accelerate=0|1,
//! spacing=KM: the stops' spacing, KM + KM/4 times the altitude; 0: every interface).

use sky::atmosphere::Atmosphere;
use sky::mie::MieCache;
use sky::render::medium::Medium;
use sky::transport::columns::{grid_for_suns, Columns};
use sky::transport::layers::{Grading, Layers};
use sky::transport::spherical::{solve, Settings};
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let Some(path) = args.get(1) else {
        eprintln!("usage: solver_cost ATMOSPHERE [WAVELENGTH_NM] [STREAMS] [draft|full] [KEY=VALUE ...]");
        std::process::exit(2);
    };
    let atm = Atmosphere::load(std::path::Path::new(path)).unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(1)
    });
    let wavelength_nm: f64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(550.0);
    let streams: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(16);
    let medium = Medium::new(&atm);
    let optics = medium.spectral(&atm, wavelength_nm, 1.0, 0.3, &MieCache::from_env());
    let t = Instant::now();
    let layers = Layers::new(&medium, &optics, 2 * streams, &Grading::default());
    println!("layers: {} ({:.3} s)", layers.layers.len(), t.elapsed().as_secs_f64());
    let step = 1f64.to_radians();
    let day: Vec<f64> = (0..88).map(|d| (d as f64).to_radians()).collect();
    let t = Instant::now();
    let grid = grid_for_suns(&layers, &day, step, 1.0);
    let n = grid.len();
    let columns = Columns::solve(&layers, streams, grid);
    println!("day columns: {n} ({:.3} s)", t.elapsed().as_secs_f64());
    let t = Instant::now();
    let phis: Vec<f64> = (0..=64).map(|p| p as f64 * std::f64::consts::PI / 64.0).collect();
    for k in 1..=128 {
        let mu = (k as f64 / 128.0).powi(2);
        std::hint::black_box(columns.rays(60f64.to_radians(), mu, &phis));
    }
    println!("one slice's table, 128 x 65 rays ({:.3} s)", t.elapsed().as_secs_f64());
    let t = Instant::now();
    let suns: Vec<(f64, &[f64])> = day.iter().step_by(2).map(|&z| (z, &phis[..])).collect();
    for k in 1..=128 {
        let mu = (k as f64 / 128.0).powi(2);
        std::hint::black_box(columns.rays_for_suns(&suns, mu));
    }
    println!("{} slices' tables at once ({:.3} s)", suns.len(), t.elapsed().as_secs_f64());
    let twilight: Vec<f64> = [88.0f64, 100.0].iter().map(|d| d.to_radians()).collect();
    let grid = grid_for_suns(&layers, &twilight, step, 2.0);
    let n = grid.len();
    let t = Instant::now();
    let mut settings =
        if args.get(4).map(String::as_str) == Some("draft") { Settings::draft() } else { Settings::default() };
    for spec in args.iter().skip(5) {
        let (key, value) = spec.split_once('=').unwrap_or_else(|| panic!("{spec}: want key=value"));
        let number = || -> f64 { value.parse().unwrap_or_else(|_| panic!("{spec}: want a number")) };
        match key {
            "stop_tau" => settings.stop_tau = number(),
            "levels" => {
                settings.levels_km = if value == "full" { Settings::default() } else { Settings::draft() }.levels_km
            }
            "modes" => settings.modes = number() as usize,
            "azimuths" => settings.azimuth_intervals = number() as usize,
            "cosines" => settings.table_cosines = number() as usize,
            "tolerance" => settings.tolerance = number(),
            "passes" => settings.max_passes = number() as usize,
            "accelerate" => settings.accelerate = number() != 0.0,
            "spacing" => settings.stop_spacing = (number(), settings.stop_spacing.1 * number() / 0.5),
            _ => panic!(
                "{key}: stop_tau, levels=full|draft, modes, azimuths, cosines, tolerance, passes, accelerate, spacing"
            ),
        }
    }
    let (twilight_columns, report) = solve(&layers, streams, grid, &settings);
    println!(
        "twilight columns: {n}, {} passes ({:.3} s); moves {:?}",
        report.moves.len(),
        t.elapsed().as_secs_f64(),
        report.moves
    );
    // The answer, to compare settings: the ground's irradiance and the
    // diffuse radiance at the zenith and 5.7° above the horizon toward and
    // away from the sun, per unit solar irradiance (every digit: a change
    // meant to leave the answer as it was can be checked bit for bit).
    for sun_deg in [90.0f64, 93.0, 96.0, 99.0] {
        let sun = sun_deg.to_radians();
        let zenith = twilight_columns.rays(sun, 1.0, &[0.0])[0];
        let low = twilight_columns.rays(sun, 0.1, &[0.0, std::f64::consts::PI]);
        println!(
            "sun {sun_deg}: ground irradiance {:?}, zenith {:?}, low toward {:?} away {:?}",
            twilight_columns.ground_irradiance_at(sun),
            zenith,
            low[0],
            low[1]
        );
    }
}
