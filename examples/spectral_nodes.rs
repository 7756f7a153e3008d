//! What solving the multiply scattered light at fewer wavelengths costs
//! (`Resolution::ms_step_nm`): a fisheye of the sky by the transport
//! solver with every 5 nm band solved, against the same with the light
//! solved at bands STEP nm apart and interpolated between (a power law in
//! wavelength): the relative error of Y and the CIEDE2000 colour
//! difference (white: the brightest pixel of the reference), median, 99th
//! percentile and largest over the pixels above the horizon, and the time
//! each takes.
//!
//! cargo run --release --example spectral_nodes -- ATMOSPHERE SUN_ZENITH_DEG [STEP_NM ...]

use sky::atmosphere::Atmosphere;
use sky::colour::error::{delta_e2000, lab};
use sky::directions::camera::Camera;
use sky::mie::MieCache;
use sky::render::{Scene, SpectralSettings, View, WavelengthSampling};
use sky::transport::render::{render, Resolution};
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        eprintln!("usage: spectral_nodes ATMOSPHERE SUN_ZENITH_DEG [STEP_NM ...]");
        std::process::exit(2);
    }
    let atm = Atmosphere::load(std::path::Path::new(&args[1])).unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(1)
    });
    let sun_deg: f64 = args[2].parse().expect("a sun zenith angle in degrees");
    let steps: Vec<f64> = if args.len() > 3 {
        args[3..].iter().map(|s| s.parse().expect("a step in nm")).collect()
    } else {
        vec![20.0, 40.0, 80.0]
    };
    let spectral = SpectralSettings {
        band_nm: 5.0,
        wavelength_sampling: WavelengthSampling::Hero,
        spectral_nm: vec![],
        xyz: true,
    };
    let scene = Scene::new(&atm, &spectral, &MieCache::from_env(), &|| {});
    let mut view = View::directions(vec![], sun_deg, 0.0, 1, 1);
    (view.camera, view.width, view.height, view.sun_disk) = (Camera::Fisheye, 32, 32, false);
    let timed = |ms_step_nm: f64| {
        let start = Instant::now();
        let image = render(&scene, &view, &Resolution { ms_step_nm, ..Default::default() }, &|| {}).unwrap();
        (image, start.elapsed().as_secs_f64())
    };
    let (reference, reference_s) = timed(0.0);
    println!("{} sun {sun_deg} deg, every band: {reference_s:.1} s", args[1]);
    let white = reference.pixels.iter().map(|p| p.xyz[1]).fold(0.0, f64::max);
    for step in steps {
        let (image, s) = timed(step);
        let mut rel = Vec::new();
        let mut de = Vec::new();
        for (a, b) in image.pixels.iter().zip(&reference.pixels) {
            if b.samples == 0 || b.xyz[1] <= 0.0 {
                continue;
            }
            rel.push((a.xyz[1] / b.xyz[1] - 1.0).abs());
            de.push(delta_e2000(lab(a.xyz, white), lab(b.xyz, white)));
        }
        let summary = |v: &mut Vec<f64>| {
            v.sort_by(f64::total_cmp);
            let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
            (at(0.5), at(0.99), at(1.0))
        };
        let (y50, y99, ymax) = summary(&mut rel);
        let (e50, e99, emax) = summary(&mut de);
        println!(
            "step {step} nm: {s:.1} s; Y median {:.3} %, p99 {:.3} %, max {:.3} %; Delta E2000 median {e50:.3}, p99 {e99:.3}, max {emax:.3}",
            100.0 * y50,
            100.0 * y99,
            100.0 * ymax
        );
    }
}
