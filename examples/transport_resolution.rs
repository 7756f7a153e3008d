//! How much the deterministic solver's answer moves when its resolutions
//! are doubled (issue 37: "the solver's resolutions doubled change nothing
//! by more than 0.3 %"): Y toward a few directions at the default layers
//! and streams, with the layers graded twice as finely, with twice the
//! streams, and with the sun-angle columns twice as dense.
//!
//! cargo run --release --example transport_resolution -- ATMOSPHERE SUN_ZENITH_DEG [STREAMS]

use sky::atmosphere::Atmosphere;
use sky::mie::MieCache;
use sky::render::{Scene, Settings, SpectralSettings, WavelengthSampling};
use sky::transport::render::{render, Resolution};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        eprintln!("usage: transport_resolution ATMOSPHERE SUN_ZENITH_DEG [STREAMS]");
        std::process::exit(2);
    }
    let atm = Atmosphere::load(std::path::Path::new(&args[1])).unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(1)
    });
    let sun: f64 = args[2].parse().expect("a sun zenith angle in degrees");
    let streams: usize = args.get(3).map_or(16, |s| s.parse().expect("a number of streams"));
    let dirs: Vec<(f64, f64)> =
        [(0.0, 0.0), (30.0, 90.0), (60.0, 180.0), (80.0, 10.0), (80.0, 90.0), (88.0, 45.0), (88.0, 180.0)].to_vec();
    let mut settings = Settings::directions(dirs.clone(), sun, vec![], 1, 1, false);
    settings.spectral = SpectralSettings {
        band_nm: 10.0,
        wavelength_sampling: WavelengthSampling::Hero,
        spectral_nm: vec![],
        xyz: true,
    };
    let scene = Scene::new(&atm, &settings.spectral, &MieCache::from_env(), &|| {});
    let base = Resolution { streams, ..Default::default() };
    let variants = [
        ("default", base),
        ("layers / 2", Resolution { grading: base.grading.finer(), ..base }),
        ("streams x 2", Resolution { streams: 2 * streams, ..base }),
        ("columns / 2", Resolution { column_step_deg: 0.5 * base.column_step_deg, ..base }),
    ];
    let images: Vec<_> = variants
        .iter()
        .map(|(name, r)| {
            let t0 = std::time::Instant::now();
            let image = render(&scene, &settings.view, r, &|| {}).expect("a view the solver renders");
            eprintln!("{name}: {:.1} s", t0.elapsed().as_secs_f64());
            image
        })
        .collect();
    println!("{:>16} {:>12} {:>12} {:>12} {:>12}", "view", "Y", "layers / 2", "streams x 2", "columns / 2");
    for (k, d) in dirs.iter().enumerate() {
        let y = images[0].pixels[k].xyz[1];
        let rel = |i: usize| 100.0 * (images[i].pixels[k].xyz[1] / y - 1.0);
        println!("{:>16} {:>12.5e} {:>+11.3}% {:>+11.3}% {:>+11.3}%", format!("{d:?}"), y, rel(1), rel(2), rel(3));
    }
}
