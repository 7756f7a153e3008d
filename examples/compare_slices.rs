//! Compares the sky slices of two slice caches that rendered the same
//! slices two ways (a preset with `ms_grid` and the same without it, see
//! README "Multiple scattering from a coarser grid"):
//!
//!   cargo run --release --example compare_slices -- CACHE_A CACHE_B [--blocks] [--resample]
//!
//! `--resample`: a slice of A smaller than B's at the same sun is resampled
//! to B's size as a Shadowed Fog rendered at a size of its own is
//! (`sky::bake::fog_resample::resample_shadowed`; README "The fog's multiple
//! scattering at a smaller size").
//!
//! Slices are paired by sun zenith and size, and among those by the smaller
//! median relative difference of Y (two basis skies at one sun differ by far
//! more than their noise). For each pair: the mean and RMS relative
//! difference of Y, the RMS of the two standard errors together, the RMS
//! beyond them (what the noise does not explain), and each slice's cost.
//! `--blocks` adds a map of the pair's z-scores summed over blocks of 4 x 8
//! texels over √32 (u across, v down): about ±1 where the two agree and the
//! noise is independent from texel to texel; a grid's nodes share their
//! noise among the texels around them, so there a coherent block of ±3 is
//! still noise, and a region of ±5 and beyond is a difference.

use sky::bake::cache::SliceCache;
use sky::bake::RenderedSlice;
use std::path::Path;

fn load(dir: &str) -> Result<Vec<RenderedSlice>, String> {
    if !Path::new(dir).is_dir() {
        return Err(format!("{dir}: not a folder"));
    }
    let cache = SliceCache::open(Path::new(dir)).map_err(|e| format!("{dir}: {e}"))?;
    let entries = std::fs::read_dir(dir).map_err(|e| format!("{dir}: {e}"))?;
    let mut slices = Vec::new();
    for entry in entries.flatten() {
        let path = entry.path();
        if path.extension().and_then(|x| x.to_str()) != Some("slice") {
            continue;
        }
        if let Some(s) = path.file_stem().and_then(|s| s.to_str()).and_then(|key| cache.get(key)) {
            slices.push(s);
        }
    }
    slices.sort_by(|a, b| a.sun_zenith_deg.total_cmp(&b.sun_zenith_deg));
    Ok(slices)
}

fn median_rel(a: &RenderedSlice, b: &RenderedSlice) -> f64 {
    let mut d: Vec<f64> =
        a.xyz.iter().zip(&b.xyz).map(|(x, y)| ((x[1] - y[1]) / y[1]).abs()).filter(|d| d.is_finite()).collect();
    d.sort_by(f64::total_cmp);
    d.get(d.len() / 2).copied().unwrap_or(f64::INFINITY)
}

fn compare(a: &RenderedSlice, b: &RenderedSlice, blocks: bool) {
    let (mut n, mut mean, mut sq, mut noise) = (0.0, 0.0, 0.0, 0.0);
    for i in 0..a.xyz.len() {
        let (ya, yb) = (a.xyz[i][1], b.xyz[i][1]);
        if yb <= 0.0 {
            continue;
        }
        let rel = (ya - yb) / yb;
        n += 1.0;
        mean += rel;
        sq += rel * rel;
        noise += (a.xyz_stderr[i][1].powi(2) + b.xyz_stderr[i][1].powi(2)) / (yb * yb);
    }
    let (mean, rms, noise) = (mean / n, (sq / n).sqrt(), (noise / n).sqrt());
    println!(
        "sun zenith {:.2}°, {} x {}, B's mean Y {:.4e}: mean relative difference of Y {:+.2} %, RMS {:.2} % against a noise of {:.2} %, beyond it {:.2} %; core-seconds {:.1} and {:.1} ({:.1}x)",
        a.sun_zenith_deg,
        a.width,
        a.height,
        b.xyz.iter().map(|p| p[1]).sum::<f64>() / b.xyz.len().max(1) as f64,
        100.0 * mean,
        100.0 * rms,
        100.0 * noise,
        100.0 * (rms * rms - noise * noise).max(0.0).sqrt(),
        a.core_seconds,
        b.core_seconds,
        b.core_seconds / a.core_seconds
    );
    if blocks {
        let (w, h) = (a.width, a.height);
        for by in (0..h).step_by(8) {
            let mut line = format!("  v {by:3}");
            for bx in (0..w).step_by(4) {
                let (mut z, mut k) = (0.0f64, 0.0f64);
                for i in (by..(by + 8).min(h)).flat_map(|y| (bx..(bx + 4).min(w)).map(move |x| y * w + x)) {
                    let s = (a.xyz_stderr[i][1].powi(2) + b.xyz_stderr[i][1].powi(2)).sqrt();
                    if s > 0.0 {
                        z += (a.xyz[i][1] - b.xyz[i][1]) / s;
                        k += 1.0;
                    }
                }
                line += &format!(" {:+5.1}", z / k.max(1.0).sqrt());
            }
            println!("{line}");
        }
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let blocks = args.iter().any(|a| a == "--blocks");
    let resample = args.iter().any(|a| a == "--resample");
    let dirs: Vec<&String> = args.iter().filter(|a| !a.starts_with("--")).collect();
    let [a, b] = dirs[..] else {
        eprintln!("usage: compare_slices CACHE_A CACHE_B [--blocks] [--resample]");
        std::process::exit(2);
    };
    let (sa, sb) = match (load(a), load(b)) {
        (Ok(x), Ok(y)) => (x, y),
        (Err(e), _) | (_, Err(e)) => {
            eprintln!("compare_slices: {e}");
            std::process::exit(1);
        }
    };
    for x in &sa {
        // B's sizes at this sun that x is (or, resampled, becomes).
        let sizes: Vec<(usize, usize)> = sb
            .iter()
            .filter(|y| (y.sun_zenith_deg - x.sun_zenith_deg).abs() < 1e-9)
            .map(|y| (y.width, y.height))
            .filter(|&(w, h)| (w, h) == (x.width, x.height) || (resample && w >= x.width && h >= x.height))
            .collect();
        let Some(&(w, h)) = sizes.iter().min() else { continue };
        if (w, h) != (x.width, x.height) {
            println!("(A's slice resampled from {} x {})", x.width, x.height);
        }
        let x = &sky::bake::fog_resample::resample_shadowed(x, w, h);
        let partner = sb
            .iter()
            .filter(|y| (y.sun_zenith_deg - x.sun_zenith_deg).abs() < 1e-9 && (y.width, y.height) == (w, h))
            .min_by(|p, q| median_rel(x, p).total_cmp(&median_rel(x, q)));
        if let Some(y) = partner {
            compare(x, y, blocks);
        }
    }
}
