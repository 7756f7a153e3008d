//! What a draft deterministic bake loses against a final one, and what it
//! saves: one basis sky's slices rendered as the bake renders them (one
//! strip, `transport::render`) at the final preset's bands and solver
//! resolution (`sky::bake::solver::resolution`), then at the draft's, or at
//! resolutions given on the command line; for each, the time and the
//! relative error of Y and the CIEDE2000 difference against the final
//! (white: the brightest texel of the final slice), median, 99th
//! percentile and largest, over all slices and per slice.
//!
//! cargo run --release --example draft_error -- BAKE.toml SKY [SLICES] [SPEC ...]
//!
//! SLICES: comma-separated slice indices (default every eighth, and the
//! last); SPEC: the draft preset's bands and solver resolution with some
//! changed, e.g. `streams=8,step=2,nodes=80,views=64x32,twilight=full,
//! grading=coarse,band=5` (default: the draft preset as the bake uses it).
//! $DRAFT_ERROR_CACHE: a folder that keeps the final render between runs.

use sky::bake::slices::{slice_view, spectral_settings, strip_view};
use sky::bake::{BakeFile, Quality};
use sky::colour::error::{delta_e2000, lab};
use sky::mie::MieCache;
use sky::render::{Scene, View};
use sky::transport::render::{render, Resolution};
use std::time::Instant;

/// The resolution `spec` makes of `r`, and its band width (nm) if it sets one.
fn parse_spec(spec: &str, mut r: Resolution) -> (Resolution, Option<f64>) {
    let mut band_nm = None;
    for part in spec.split(',').filter(|p| !p.is_empty()) {
        let (key, value) = part.split_once('=').unwrap_or_else(|| panic!("{part}: want key=value"));
        match key {
            "grading" => {
                r.grading = match value {
                    "default" => sky::transport::layers::Grading::default(),
                    "coarse" => sky::transport::layers::Grading::default().coarser(),
                    _ => panic!("grading: default or coarse"),
                }
            }
            "band" => band_nm = Some(value.parse().expect("band: nm")),
            "streams" => r.streams = value.parse().expect("streams: an integer"),
            "step" => r.column_step_deg = value.parse().expect("step: degrees"),
            "nodes" => r.ms_step_nm = value.parse().expect("nodes: nm"),
            "views" => {
                let (a, b) = value.split_once('x').expect("views: NxM");
                r.view_grid = (a.parse().expect("views"), b.parse().expect("views"));
            }
            "twilight" => {
                r.twilight = match value {
                    "full" => sky::transport::spherical::Detail::Full,
                    "draft" => sky::transport::spherical::Detail::Draft,
                    _ => panic!("twilight: full or draft"),
                }
            }
            other => panic!("unknown key {other} (streams, step, nodes, views, twilight, grading, band)"),
        }
    }
    (r, band_nm)
}

fn summary(v: &mut [f64]) -> (f64, f64, f64) {
    v.sort_by(f64::total_cmp);
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    (at(0.5), at(0.99), at(1.0))
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        eprintln!("usage: draft_error BAKE.toml SKY [SLICES] [SPEC ...]");
        std::process::exit(2);
    }
    let bake = BakeFile::load(std::path::Path::new(&args[1])).unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(1)
    });
    let sky = bake.skies.iter().find(|s| s.name == args[2]).unwrap_or_else(|| {
        eprintln!("{}: no sky {}", args[1], args[2]);
        std::process::exit(1)
    });
    let slices: Vec<usize> = match args.get(3) {
        Some(list) => list.split(',').map(|s| s.parse().expect("a slice index")).collect(),
        None => (0..sky.slices).step_by(8).chain([sky.slices - 1]).collect(),
    };
    let atm = sky::atmosphere::Atmosphere::load(&sky.atmosphere).unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(1)
    });
    let cache = MieCache::from_env();
    let (radius_km, top_km) = (atm.planet.radius_km, atm.planet.top_km);
    let views: Vec<View> = slices
        .iter()
        .map(|&i| slice_view(sky, sky.sampling(Quality::Draft), i, radius_km, top_km, sky.threshold_deg))
        .collect();
    // The strip's XYZ (row by row, slices side by side) and the seconds taken.
    let run = |quality: Quality, resolution: &Resolution, band_nm: Option<f64>| -> (Vec<[f64; 3]>, f64) {
        let mut spectral = spectral_settings(sky.sampling(quality));
        spectral.band_nm = band_nm.unwrap_or(spectral.band_nm);
        let scene = Scene::new(&atm, &spectral, &cache, &|| {});
        let strip = strip_view(&views.iter().collect::<Vec<_>>());
        let start = Instant::now();
        let image = render(&scene, &strip, resolution, &|| {}).unwrap_or_else(|e| panic!("{e}"));
        (image.pixels.iter().map(|p| p.xyz).collect(), start.elapsed().as_secs_f64())
    };
    let final_resolution = sky::bake::solver::resolution(Quality::Final, sky.sampling(Quality::Final));
    // $DRAFT_ERROR_CACHE: a folder where the final render is kept between runs.
    let kept = std::env::var_os("DRAFT_ERROR_CACHE").map(|dir| {
        let list: Vec<String> = slices.iter().map(|i| i.to_string()).collect();
        std::path::PathBuf::from(dir).join(format!("{}_{}.json", sky.name, list.join("-")))
    });
    let key = format!("{final_resolution:?} {sky:?} {}", env!("SKY_TRANSPORT_SOURCE"));
    let from_cache = kept.as_ref().and_then(|p| std::fs::read(p).ok()).and_then(|b| {
        let (k, xyz, s): (String, Vec<[f64; 3]>, f64) = serde_json::from_slice(&b).ok()?;
        (k == key).then_some((xyz, s))
    });
    let (reference, reference_s) = from_cache.unwrap_or_else(|| {
        let (xyz, s) = run(Quality::Final, &final_resolution, None);
        if let Some(p) = &kept {
            std::fs::write(p, serde_json::to_vec(&(&key, &xyz, s)).expect("JSON")).expect("the cache folder");
        }
        (xyz, s)
    });
    println!("{} {}: final {final_resolution:?}: {reference_s:.1} s", args[1], sky.name);
    let draft_default = sky::bake::solver::resolution(Quality::Draft, sky.sampling(Quality::Draft));
    let specs: Vec<String> = if args.len() > 4 { args[4..].to_vec() } else { vec![String::new()] };
    let slice_texels = sky.width * sky.height;
    for spec in specs {
        let (resolution, band_nm) = parse_spec(&spec, draft_default);
        let (image, s) = run(Quality::Draft, &resolution, band_nm);
        println!("draft {resolution:?}, bands {band_nm:?} nm: {s:.1} s ({:.1} times faster)", reference_s / s);
        let (mut all_y, mut all_e) = (Vec::new(), Vec::new());
        for (k, view) in views.iter().enumerate() {
            let strip_width = view.width * views.len();
            let texels = |img: &[[f64; 3]]| -> Vec<[f64; 3]> {
                (0..view.height)
                    .flat_map(|y| (0..view.width).map(move |x| (y, x)))
                    .map(|(y, x)| img[y * strip_width + k * view.width + x])
                    .collect()
            };
            let (a, b) = (texels(&image), texels(&reference));
            let white = b.iter().map(|p| p[1]).fold(0.0, f64::max);
            let darkest = b.iter().map(|p| p[1]).fold(f64::INFINITY, f64::min);
            let (mut y, mut e) = (Vec::with_capacity(slice_texels), Vec::with_capacity(slice_texels));
            for (p, q) in a.iter().zip(&b) {
                if q[1] > 0.0 {
                    y.push((p[1] / q[1] - 1.0).abs());
                    e.push(delta_e2000(lab(*p, white), lab(*q, white)));
                }
            }
            all_y.extend_from_slice(&y);
            all_e.extend_from_slice(&e);
            let ((y50, y99, ymax), (e50, e99, _)) = (summary(&mut y), summary(&mut e));
            println!(
                "  slice {:2} (sun {:6.2} deg, Y {darkest:.3e} to {white:.3e}): Y median {:.2} %, p99 {:.2} %, max {:.2} %; dE median {e50:.2}, p99 {e99:.2}",
                slices[k],
                view.sun_zenith_deg,
                100.0 * y50,
                100.0 * y99,
                100.0 * ymax
            );
        }
        let ((y50, y99, ymax), (e50, e99, emax)) = (summary(&mut all_y), summary(&mut all_e));
        println!(
            "  all: Y median {:.2} %, p99 {:.2} %, max {:.2} %; dE median {e50:.2}, p99 {e99:.2}, max {emax:.2}",
            100.0 * y50,
            100.0 * y99,
            100.0 * ymax
        );
    }
}
