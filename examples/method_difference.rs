//! The path tracer and the deterministic solver side by side (issue 37,
//! item 6): one fisheye view rendered by each, and their difference in Y
//! in units of the path tracer's standard error, as three PNGs at one
//! exposure, with a line of figures (the share of pixels beyond the Šidák
//! threshold of the image at 1 %, the mean z, the median relative
//! difference, each render's seconds).
//!
//! cargo run --release --example method_difference -- ATMOSPHERE SUN_ZENITH_DEG SPP SIZE OUT_PREFIX
//!
//! writes OUT_PREFIX_path_tracer.png, OUT_PREFIX_solver.png and
//! OUT_PREFIX_z.png (blue: the solver darker, red: brighter, white at 0,
//! full colour at |z| = 4; grey outside the horizon).

use sky::atmosphere::Atmosphere;
use sky::directions::camera::Camera;
use sky::mie::MieCache;
use sky::render::output::write_png_scaled;
use sky::render::{Image, Scene, SpectralSettings, View, WavelengthSampling};
use sky::transport::render::Resolution;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() != 6 {
        eprintln!("usage: method_difference ATMOSPHERE SUN_ZENITH_DEG SPP SIZE OUT_PREFIX");
        std::process::exit(2);
    }
    let parse = |i: usize, what: &str| -> f64 {
        args[i].parse().unwrap_or_else(|_| {
            eprintln!("argument {i}: expected {what}, found {:?}", args[i]);
            std::process::exit(2)
        })
    };
    let atm = Atmosphere::load(std::path::Path::new(&args[1])).unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(1)
    });
    let (sun_deg, spp, size) = (parse(2, "degrees"), parse(3, "samples a pixel") as u32, parse(4, "pixels") as usize);
    let spectral = SpectralSettings {
        band_nm: 10.0,
        wavelength_sampling: WavelengthSampling::Hero,
        spectral_nm: vec![],
        xyz: true,
    };
    let scene = Scene::new(&atm, &spectral, &MieCache::from_env(), &|| {});
    let mut view = View::directions(vec![], sun_deg, 0.0, spp, 1);
    (view.camera, view.width, view.height, view.sun_disk) = (Camera::Fisheye, size, size, true);
    let t0 = Instant::now();
    let traced = sky::render::render(&scene, &view, &AtomicBool::new(false), &|| {}).expect("the path tracer renders");
    let traced_s = t0.elapsed().as_secs_f64();
    let t0 = Instant::now();
    let solved = sky::transport::render::render(&scene, &view, &Resolution::default(), &|| {})
        .unwrap_or_else(|e| panic!("the solver renders this view: {e}"));
    let solved_s = t0.elapsed().as_secs_f64();
    // One exposure for both: the path tracer's median Y.
    let mut y: Vec<f64> = traced.pixels.iter().map(|p| p.xyz[1]).filter(|y| *y > 0.0).collect();
    y.sort_by(f64::total_cmp);
    let scale = 0.25 / y.get(y.len() / 2).copied().unwrap_or(1.0);
    let prefix = &args[5];
    let write = |path: String, image: &Image| {
        write_png_scaled(std::path::Path::new(&path), image, scale, None).unwrap_or_else(|e| {
            eprintln!("{path}: {e}");
            std::process::exit(1)
        })
    };
    write(format!("{prefix}_path_tracer.png"), &traced);
    write(format!("{prefix}_solver.png"), &solved);
    // z per pixel inside the horizon; the Šidák threshold for them all.
    let mut rgb = Vec::with_capacity(size * size * 3);
    let (mut zs, mut rel) = (Vec::new(), Vec::new());
    for (t, s) in traced.pixels.iter().zip(&solved.pixels) {
        let (a, b, se) = (t.xyz[1], s.xyz[1], t.xyz_stderr[1]);
        if a <= 0.0 || se <= 0.0 {
            rgb.extend([96u8, 96, 96]);
            continue;
        }
        let z = (b - a) / se;
        zs.push(z);
        rel.push((b / a - 1.0).abs());
        let f = (z.abs() / 4.0).min(1.0);
        let fade = (255.0 * (1.0 - f)) as u8;
        rgb.extend(if z > 0.0 { [255, fade, fade] } else { [fade, fade, 255] });
    }
    let im = image::RgbImage::from_raw(size as u32, size as u32, rgb).expect("the image's size");
    im.save(format!("{prefix}_z.png")).unwrap_or_else(|e| {
        eprintln!("{prefix}_z.png: {e}");
        std::process::exit(1)
    });
    let m = zs.len() as f64;
    // Two-sided Šidák threshold at a family-wise 1 %: per pixel 1 − 0.99^(1/m).
    let alpha = 1.0 - 0.99f64.powf(1.0 / m);
    let threshold = normal_quantile(1.0 - 0.5 * alpha);
    let beyond = zs.iter().filter(|z| z.abs() > threshold).count();
    rel.sort_by(f64::total_cmp);
    println!(
        "{} sun {sun_deg}: {} pixels, {beyond} beyond |z| {threshold:.2}, mean z {:+.2}, aggregate Σz/√m {:+.1}, \
         median |ΔY/Y| {:.2} %; path tracer {spp} spp {traced_s:.0} s, solver {solved_s:.0} s",
        args[1],
        zs.len(),
        zs.iter().sum::<f64>() / m,
        zs.iter().sum::<f64>() / m.sqrt(),
        100.0 * rel.get(rel.len() / 2).copied().unwrap_or(0.0),
    );
}

/// The standard normal quantile by bisection on erfc (libm).
fn normal_quantile(p: f64) -> f64 {
    let (mut lo, mut hi) = (-10.0, 10.0);
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if 0.5 * libm::erfc(-mid / std::f64::consts::SQRT_2) < p {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}
