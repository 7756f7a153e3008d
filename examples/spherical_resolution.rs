//! How much the spherical source iteration (`sky::transport::spherical`)
//! moves when each of its resolutions is doubled (issue 37: "the solver's
//! resolutions doubled change nothing by more than 0.3 %"): the multiply
//! scattered radiance at one wavelength toward a few directions, with the
//! default settings, then with the node levels, Fourier modes, azimuths,
//! table cosines, stops, sun-angle columns and streams each doubled (and
//! the stopping tolerance tightened tenfold), one at a time.
//!
//! cargo run --release --example spherical_resolution -- ATMOSPHERE SUN_ZENITH_DEG [WAVELENGTH_NM] [STREAMS] [VARIANTS]
//!
//! VARIANTS, a comma-separated list of the variants' names (`streams x 2`,
//! `streams x 4`, `levels x 2`, ...), runs only those beside the default.

use sky::atmosphere::Atmosphere;
use sky::mie::MieCache;
use sky::render::medium::Medium;
use sky::transport::columns::grid_reaches;
use sky::transport::layers::{Grading, Layers};
use sky::transport::spherical::{solve, Settings};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        eprintln!("usage: spherical_resolution ATMOSPHERE SUN_ZENITH_DEG [WAVELENGTH_NM] [STREAMS] [VARIANTS]");
        std::process::exit(2);
    }
    let number = |i: usize, default: f64, what: &str| -> f64 {
        args.get(i).map_or(default, |s| {
            s.parse().unwrap_or_else(|_| {
                eprintln!("argument {i}: expected {what}, found {s:?}");
                std::process::exit(2)
            })
        })
    };
    let atm = Atmosphere::load(std::path::Path::new(&args[1])).unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(1)
    });
    let sun_deg = number(2, 0.0, "a sun zenith angle in degrees");
    let wavelength_nm = number(3, 550.0, "a wavelength in nm");
    let streams = number(4, 16.0, "a number of streams") as usize;
    let medium = Medium::new(&atm);
    let optics = medium.spectral(&atm, wavelength_nm, 1.0, 0.3, &MieCache::from_env());
    let lmax = 2 * streams;
    let layers = Layers::new(&medium, &optics, lmax, &Grading::default());
    let layers_of = |n: usize| Layers::new(&medium, &optics, 2 * n, &Grading::default());
    let sun = sun_deg.to_radians();
    let base = Settings::default();
    let mut finer_levels = base.levels_km.clone();
    finer_levels.extend(base.levels_km.windows(2).filter(|w| w[1] < 1e3).map(|w| 0.5 * (w[0] + w[1])));
    let mut variants: Vec<(&str, Settings, f64, usize)> = vec![
        ("default", base.clone(), 1.0, streams),
        ("levels x 2", Settings { levels_km: finer_levels, ..base.clone() }, 1.0, streams),
        ("modes x 2", Settings { modes: 2 * base.modes, ..base.clone() }, 1.0, streams),
        ("azimuths x 2", Settings { azimuth_intervals: 2 * base.azimuth_intervals, ..base.clone() }, 1.0, streams),
        ("cosines x 2", Settings { table_cosines: 2 * base.table_cosines - 1, ..base.clone() }, 1.0, streams),
        (
            "stops x 2",
            Settings { stop_spacing: (0.5 * base.stop_spacing.0, 0.5 * base.stop_spacing.1), ..base.clone() },
            1.0,
            streams,
        ),
        ("tolerance / 10", Settings { tolerance: 0.1 * base.tolerance, max_passes: 30, ..base.clone() }, 1.0, streams),
        ("columns / 2", base.clone(), 0.5, streams),
        ("streams x 2", base.clone(), 1.0, 2 * streams),
        ("streams x 4", base.clone(), 1.0, 4 * streams),
    ];
    match args.get(5) {
        Some(list) => {
            let wanted: Vec<&str> = list.split(',').map(str::trim).collect();
            variants.retain(|v| v.0 == "default" || wanted.contains(&v.0));
        }
        None => variants.retain(|v| v.0 != "streams x 4"),
    }
    let phis = [0.0, 0.5 * std::f64::consts::PI, std::f64::consts::PI];
    let mus = [1.0, 0.5, 0.17, 0.035];
    let mut answers: Vec<Vec<f64>> = Vec::new();
    for (name, settings, step_deg, n) in &variants {
        let other;
        let l = if *n == streams {
            &layers
        } else {
            other = layers_of(*n);
            &other
        };
        let t0 = std::time::Instant::now();
        let zenith = grid_reaches(l, sun, step_deg.to_radians(), 2.0);
        let (columns, report) = solve(l, *n, zenith, settings);
        let seconds = t0.elapsed().as_secs_f64();
        let passes = report.moves.len();
        eprintln!("{name}: {seconds:.1} s, {passes} passes, last move {:.1e}", report.moves.last().unwrap_or(&0.0));
        answers.push(mus.iter().flat_map(|&mu| columns.rays(sun, mu, &phis)).collect());
    }
    println!("multiply scattered radiance, {} at sun {sun_deg} deg, {wavelength_nm} nm, {streams} streams", args[1]);
    print!("{:>18}", "view (mu, phi)");
    variants.iter().skip(1).for_each(|v| print!(" {:>14}", v.0));
    println!();
    let mut worst = vec![0.0f64; variants.len()];
    for (q, (mu, phi)) in mus.iter().flat_map(|&mu| phis.iter().map(move |&p| (mu, p))).enumerate() {
        print!("{:>18}", format!("({mu}, {:.0})", phi.to_degrees()));
        for v in 1..variants.len() {
            let rel = 100.0 * (answers[v][q] / answers[0][q] - 1.0);
            worst[v] = worst[v].max(rel.abs());
            print!(" {:>+13.3}%", rel);
        }
        println!();
    }
    print!("{:>18}", "largest");
    worst.iter().skip(1).for_each(|w| print!(" {:>13.3}%", w));
    println!();
}
