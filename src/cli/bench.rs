//! `sky bench`: timings reported in the README.

use anyhow::{Context, Result};
use serde_json::json;
use sky::atmosphere::Atmosphere;
use sky::atmosphere::RefractiveIndex;
use sky::directions::camera::Camera;
use sky::mie::{self, phase, LogNormal};
use sky::render::tracer::Estimator;
use sky::render::{self as rend, Scene, Settings, SingleScatter, SpectralSettings, View, WavelengthSampling};
use sky::table::Table;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

#[derive(clap::Subcommand)]
pub enum BenchCommand {
    /// Mie tables of a coarse water mode (r 4 um, sigma 0.55) over 400-800 nm every 5 nm,
    /// with the 601-angle phase tables, computed without the cache
    Mie {
        /// Water refractive index table (wavelength_nm,n,k); a constant 1.33-1e-7i if absent
        #[arg(long, default_value = "atmospheres/data/water_hale_querry_1973.csv")]
        water: PathBuf,
        /// Worker threads (default: all cores)
        #[arg(long)]
        threads: Option<usize>,
        /// Wavelength step in nm
        #[arg(long, default_value_t = 5.0)]
        step_nm: f64,
        /// Machine-readable output
        #[arg(long)]
        json: bool,
    },
    /// The denoiser's error against a converged render: a 48x24 view toward
    /// a sun 5 degrees high, rendered at --spp and at --reference-spp
    Denoise {
        #[arg(long, default_value = "atmospheres/clear.toml")]
        atmosphere: PathBuf,
        #[arg(long, default_value_t = 32)]
        spp: u32,
        #[arg(long, default_value_t = 8192)]
        reference_spp: u32,
    },
    /// Colour noise per second of the wavelength-sampling strategies
    /// (luminance, tristimulus, hero), measured in one run over 8 sky
    /// directions: mean over directions of the summed squared relative
    /// standard errors of X, Y and Z, times the render time (lower is better)
    Spectral {
        #[arg(long, default_value = "atmospheres/clear.toml")]
        atmosphere: PathBuf,
        #[arg(long, default_value_t = 20_000)]
        spp: u32,
    },
    /// The path tracer's efficiency: the time to reach 1 % relative RMSE over a
    /// fixed set of sky directions at 550 nm, for the naive estimator (analog
    /// tracking, one wavelength, no next-event estimation) and the shipped one,
    /// measured in one run; reports their ratio
    Render {
        /// Atmosphere to render
        #[arg(long, default_value = "atmospheres/clear.toml")]
        atmosphere: PathBuf,
        /// Samples per direction for the shipped estimator
        #[arg(long, default_value_t = 20_000)]
        spp: u32,
        /// Samples per direction for the naive estimator
        #[arg(long, default_value_t = 2_000_000)]
        naive_spp: u32,
        /// Machine-readable output
        #[arg(long)]
        json: bool,
    },
    /// Time to 1 % relative RMSE against DISORT on the plane-parallel
    /// Rayleigh slab of the validation (tests/reference/disort.json: sun at
    /// 60 deg, diffuse radiance at the ground at 450, 550 and 650 nm over
    /// its grid of view directions), spectral lines only (no XYZ), on
    /// --threads cores
    Disort {
        /// The committed DISORT reference
        #[arg(long, default_value = "tests/reference/disort.json")]
        reference: PathBuf,
        /// Which of its atmospheres (by file name)
        #[arg(long, default_value = "disort_rayleigh.toml")]
        case: String,
        /// Samples per direction
        #[arg(long, default_value_t = 20_000)]
        spp: u32,
        /// Worker threads
        #[arg(long, default_value_t = 1)]
        threads: usize,
        /// Machine-readable output
        #[arg(long)]
        json: bool,
    },
    /// The bias of adaptive sampling on heavy-tailed pixels (the hazed sky
    /// next to the sun, a cloudy sky, hazy twilight): many independent
    /// pixels looking the same way, each rendered with fixed samples, with
    /// the two-stage rule `--max-rel-error` ships, and with the rule it
    /// replaced (stop once the running standard error meets the target,
    /// checked every 16 samples: emulated exactly, since a pixel's first k
    /// samples do not depend on how many it takes); reports each mean's
    /// difference from an independent fixed-sample reference in standard
    /// errors
    Adaptive {
        /// Pixels per case
        #[arg(long, default_value_t = 100)]
        pixels: usize,
        /// The relative standard error asked for
        #[arg(long, default_value_t = 0.1)]
        target: f64,
        /// Most samples a pixel may take (and the fixed-sample count)
        #[arg(long, default_value_t = 512)]
        spp: u32,
    },
    /// The projected cost of a final bake, per basis sky and estimator of
    /// single scattering, in one run: a few slices of each basis sky at a
    /// subset of their texels, the per-sample noise of Y measured against a
    /// converged reference, priced at the measured time per path to 1 %
    /// per texel and summed over the 64 slices
    Bake(super::bench_bake::BenchBakeArgs),
    /// The GPU preview's passes timed by wall clock, the LUT sky pass against a plain textured full-screen pass round by round, and the sky pass against the CPU decoder
    Preview(super::bench_preview::BenchPreviewArgs),
    /// The farm's overhead and scaling, in one run: a plain local render (no
    /// coordinator) against the embedded worker and against one `sky worker`
    /// process on the same cores; then two single-thread workers against one.
    /// Workers are warmed on the job first, so only rendering is timed
    Farm {
        #[arg(long, default_value = "atmospheres/clear.toml")]
        atmosphere: PathBuf,
        /// Image size (equirect)
        #[arg(long, default_value = "96x48")]
        size: String,
        #[arg(long, default_value_t = 128)]
        spp: u32,
        /// Threads for the overhead comparison (default: all cores)
        #[arg(long)]
        threads: Option<usize>,
        /// Rounds of the comparison (the fastest time of each contender counts)
        #[arg(long, default_value_t = 3)]
        rounds: usize,
        /// Machine-readable output
        #[arg(long)]
        json: bool,
    },
}

fn sunset_settings(spp: u32, seed: u64) -> Settings {
    Settings {
        spectral: SpectralSettings {
            spectral_nm: vec![],
            xyz: true,
            band_nm: 5.0,
            wavelength_sampling: WavelengthSampling::Tristimulus,
        },
        view: View {
            camera: Camera::Pinhole { azimuth_deg: 0.0, elevation_deg: 12.0, fov_deg: 90.0 },
            width: 48,
            height: 24,
            sun_zenith_deg: 85.0,
            sun_azimuth_deg: 0.0,
            altitude_m: 0.0,
            spp,
            seed,
            estimator: Estimator::Full,
            sun_disk: true,
            max_rel_error: None,
            single_scatter: SingleScatter::default(),
            fog: None,
        },
    }
}

/// Relative RMSE of Y, RMS chromaticity error and mean relative bias of Y
/// against a reference, over the pixels the reference has converged
/// (relative standard error of Y below 5 %; this leaves out the sun's disk).
fn image_error(img: &rend::Image, reference: &rend::Image) -> (f64, f64, f64) {
    let (mut se, mut sc, mut bias, mut n) = (0.0, 0.0, 0.0, 0.0);
    for (p, r) in img.pixels.iter().zip(&reference.pixels) {
        if r.xyz[1] <= 0.0 || r.xyz_stderr[1] > 0.05 * r.xyz[1] || p.xyz.iter().sum::<f64>() <= 0.0 {
            continue;
        }
        let rel = (p.xyz[1] - r.xyz[1]) / r.xyz[1];
        se += rel * rel;
        bias += rel;
        let a = sky::spectrum::chromaticity(p.xyz);
        let b = sky::spectrum::chromaticity(r.xyz);
        sc += (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2);
        n += 1.0;
    }
    ((se / n).sqrt(), (sc / n).sqrt(), bias / n)
}

/// The benchmark's view directions (zenith, azimuth), sun at zenith 60°, azimuth 0.
const BENCH_DIRECTIONS: [(f64, f64); 8] =
    [(0.0, 0.0), (30.0, 90.0), (45.0, 180.0), (60.0, 30.0), (70.0, 0.0), (80.0, 120.0), (85.0, 60.0), (88.0, 0.0)];

struct Measured {
    seconds: f64,
    paths: f64,
    mean: Vec<f64>,
    rel_var: Vec<f64>,
}

fn measure(atm: &Atmosphere, estimator: Estimator, spp: u32, seed: u64) -> Measured {
    let settings = {
        let mut s_ = Settings::directions(BENCH_DIRECTIONS.to_vec(), 60.0, vec![550.0], spp, seed, true);
        s_.view.estimator = estimator;
        s_
    };
    let cache = sky::mie::MieCache::from_env();
    let scene = Scene::new(atm, &settings.spectral, &cache, &|| {});
    let t = Instant::now();
    let img = rend::render(&scene, &settings.view, &AtomicBool::new(false), &|| {}).expect("not cancelled");
    let seconds = t.elapsed().as_secs_f64();
    let n = spp as f64;
    let mean: Vec<f64> = img.pixels.iter().map(|p| p.spectral[0]).collect();
    // Per-sample relative variance: (se² n) / mean².
    let rel_var = img
        .pixels
        .iter()
        .map(|p| (p.spectral_stderr[0] * p.spectral_stderr[0] * n) / (p.spectral[0] * p.spectral[0]).max(1e-300))
        .collect();
    Measured { seconds, paths: n * BENCH_DIRECTIONS.len() as f64, mean, rel_var }
}

/// Seconds to reach a relative RMSE of 1 % averaged over the directions:
/// n = mean(σ²/L²) / 1e-4 samples per direction, at the measured rate.
/// Directions the estimator never lit are left out of the mean, so for the
/// naive estimator this is a lower bound.
fn time_to_one_percent(m: &Measured) -> f64 {
    let lit: Vec<f64> = m.rel_var.iter().zip(&m.mean).filter(|(_, m)| **m > 0.0).map(|(v, _)| *v).collect();
    let mean_rel_var = lit.iter().sum::<f64>() / lit.len().max(1) as f64;
    let n = mean_rel_var / 1e-4;
    n * BENCH_DIRECTIONS.len() as f64 / (m.paths / m.seconds)
}

pub fn run(c: BenchCommand) -> Result<ExitCode> {
    match c {
        BenchCommand::Mie { water, threads, step_nm, json } => bench_mie(water, threads, step_nm, json),
        BenchCommand::Adaptive { pixels, target, spp } => adaptive(pixels, target, spp),
        BenchCommand::Disort { reference, case, spp, threads, json } => {
            super::bench_disort::run(&reference, &case, spp, threads, json)
        }
        BenchCommand::Spectral { atmosphere, spp } => spectral(atmosphere, spp),
        BenchCommand::Denoise { atmosphere, spp, reference_spp } => denoise(atmosphere, spp, reference_spp),
        BenchCommand::Render { atmosphere, spp, naive_spp, json } => {
            render_efficiency(atmosphere, spp, naive_spp, json)
        }
        BenchCommand::Bake(a) => super::bench_bake::run(a),
        BenchCommand::Preview(a) => super::bench_preview::run(a),
        BenchCommand::Farm { atmosphere, size, spp, threads, rounds, json } => {
            super::bench_farm::run(atmosphere, size, spp, threads, rounds, json)
        }
    }
}

/// `sky bench mie` (see its help).
fn bench_mie(water: PathBuf, threads: Option<usize>, step_nm: f64, json: bool) -> Result<ExitCode> {
    if !(step_nm > 0.0 && step_nm.is_finite()) {
        return super::usage("--step-nm must be positive");
    }
    let index = match Table::read(&water) {
        Ok(t) => RefractiveIndex::Table { n: t.function("n")?, k: t.function("k")? },
        Err(_) => RefractiveIndex::Constant(num_complex::Complex64::new(1.33, 1e-7)),
    };
    let threads = threads.unwrap_or_else(rayon::current_num_threads);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
    let mode = LogNormal::new(4.0, 0.55);
    let grid = phase::phase_grid_deg();
    let n = ((800.0 - 400.0) / step_nm).floor() as usize + 1;
    let wavelengths: Vec<f64> = (0..n).map(|i| 400.0 + step_nm * i as f64).collect();
    let bar = indicatif::ProgressBar::new(n as u64);
    let start = Instant::now();
    let mut nodes = 0;
    pool.install(|| {
        for &w in &wavelengths {
            let b = mie::bulk_optics(index.at(w), &mode, w, &grid);
            let _table = phase::PhaseTable::new(&grid, &b.phase_sr_inv);
            nodes += b.radius_nodes;
            bar.inc(1);
        }
    });
    bar.finish_and_clear();
    let secs = start.elapsed().as_secs_f64();
    if json {
        outln!(
            "{}",
            serde_json::to_string_pretty(&json!({
                "benchmark": "mie-coarse-water", "wavelengths": n, "angles": grid.len(),
                "radius_nodes": nodes, "threads": threads, "seconds": secs,
                "seconds_per_wavelength": secs / n as f64,
            }))?
        );
    } else {
        outln!(
            "mie coarse water mode (r_median 4 um, sigma 0.55), {n} wavelengths 400-800 nm, {} angles: {secs:.2} s on {threads} threads ({:.3} s per wavelength, {nodes} radius nodes in all)",
            grid.len(),
            secs / n as f64
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// `sky bench spectral` (see its help).
fn spectral(atmosphere: PathBuf, spp: u32) -> Result<ExitCode> {
    let atm = Atmosphere::load(&atmosphere)
        .map_err(anyhow::Error::new)
        .with_context(|| format!("{}", atmosphere.display()))?;
    let cache = sky::mie::MieCache::from_env();
    outln!(
        "colour noise per second, {} ({} directions, sun at 60 deg, {spp} spp, {} threads)",
        atmosphere.display(),
        BENCH_DIRECTIONS.len(),
        rayon::current_num_threads()
    );
    let mut results = Vec::new();
    for (name, ws) in [
        ("luminance", WavelengthSampling::Luminance),
        ("tristimulus", WavelengthSampling::Tristimulus),
        ("hero", WavelengthSampling::Hero),
    ] {
        let settings = {
            let mut s_ = Settings::directions(BENCH_DIRECTIONS.to_vec(), 60.0, vec![], spp, 7, false);
            s_.spectral.xyz = true;
            s_.spectral.spectral_nm = vec![];
            s_.spectral.wavelength_sampling = ws;
            s_
        };
        let scene = Scene::new(&atm, &settings.spectral, &cache, &|| {});
        let t = Instant::now();
        let img = rend::render(&scene, &settings.view, &AtomicBool::new(false), &|| {}).expect("not cancelled");
        let secs = t.elapsed().as_secs_f64();
        let noise: f64 =
            img.pixels.iter().map(|p| (0..3).map(|c| (p.xyz_stderr[c] / p.xyz[c]).powi(2)).sum::<f64>()).sum::<f64>()
                / img.pixels.len() as f64;
        outln!("  {name:<12} {secs:>7.2} s   mean Σ(rel. se)² {noise:.3e}   noise x time {:.3e}", noise * secs);
        results.push((name, noise * secs));
    }
    let best = results.iter().cloned().fold(("", f64::INFINITY), |a, b| if b.1 < a.1 { b } else { a });
    for (name, v) in &results {
        outln!("  {name:<12} {:.2}x the colour noise per second of {}", v / best.1, best.0);
    }
    Ok(ExitCode::SUCCESS)
}

/// `sky bench denoise` (see its help).
fn denoise(atmosphere: PathBuf, spp: u32, reference_spp: u32) -> Result<ExitCode> {
    let atm = Atmosphere::load(&atmosphere)
        .map_err(anyhow::Error::new)
        .with_context(|| format!("{}", atmosphere.display()))?;
    let cache = sky::mie::MieCache::from_env();
    let low = sunset_settings(spp, 1);
    let high = sunset_settings(reference_spp, 2);
    let scene = Scene::new(&atm, &low.spectral, &cache, &|| {});
    let cancel = AtomicBool::new(false);
    let noisy = rend::render(&scene, &low.view, &cancel, &|| {}).expect("not cancelled");
    let reference = rend::render(&scene, &high.view, &cancel, &|| {}).expect("not cancelled");
    let den = rend::denoise::Denoise::default().apply(&noisy);
    let (e_raw, c_raw, b_raw) = image_error(&noisy, &reference);
    let (e_den, c_den, b_den) = image_error(&den, &reference);
    outln!("denoiser, {} at {spp} spp against {reference_spp} spp (48x24, sun 5 deg high):", atmosphere.display());
    outln!("  noisy:    Y relative RMSE {:.4}, chromaticity RMS error {:.5}, mean Y bias {:+.4}", e_raw, c_raw, b_raw);
    outln!("  denoised: Y relative RMSE {:.4}, chromaticity RMS error {:.5}, mean Y bias {:+.4}", e_den, c_den, b_den);
    let used = reference.pixels.iter().filter(|r| r.xyz[1] > 0.0 && r.xyz_stderr[1] <= 0.05 * r.xyz[1]).count();
    outln!(
        "  ({used} of {} pixels compared: those where the reference's own Y standard error is below 5 %)",
        reference.pixels.len()
    );
    Ok(ExitCode::SUCCESS)
}

/// `sky bench render` (see its help).
fn render_efficiency(atmosphere: PathBuf, spp: u32, naive_spp: u32, json: bool) -> Result<ExitCode> {
    let atm = Atmosphere::load(&atmosphere)
        .map_err(anyhow::Error::new)
        .with_context(|| format!("{}", atmosphere.display()))?;
    let full = measure(&atm, Estimator::Full, spp, 1);
    let naive = measure(&atm, Estimator::Naive, naive_spp, 2);
    let t_full = time_to_one_percent(&full);
    let t_naive = time_to_one_percent(&naive);
    // Agreement of the two estimators, in combined standard errors.
    let z: Vec<f64> = (0..BENCH_DIRECTIONS.len())
        .map(|i| {
            let se_f = (full.rel_var[i] / spp as f64).sqrt() * full.mean[i];
            let se_n = (naive.rel_var[i] / naive_spp as f64).sqrt() * naive.mean[i];
            (full.mean[i] - naive.mean[i]) / (se_f * se_f + se_n * se_n).sqrt().max(1e-300)
        })
        .collect();
    if json {
        outln!(
            "{}",
            serde_json::to_string_pretty(&json!({
                "benchmark": "render-efficiency", "atmosphere": atmosphere.display().to_string(),
                "directions": BENCH_DIRECTIONS.len(), "wavelength_nm": 550.0, "threads": rayon::current_num_threads(),
                "shipped": { "paths_per_second": full.paths / full.seconds, "relative_variance_per_sample": full.rel_var, "seconds_to_1pct_rmse": t_full },
                "naive": { "paths_per_second": naive.paths / naive.seconds, "relative_variance_per_sample": naive.rel_var, "seconds_to_1pct_rmse": t_naive },
                "speedup": t_naive / t_full,
                "agreement_z": z,
            }))?
        );
    } else {
        outln!(
            "render efficiency, {} ({} directions at 550 nm, sun at 60 deg, {} threads)",
            atmosphere.display(),
            BENCH_DIRECTIONS.len(),
            rayon::current_num_threads()
        );
        outln!("  shipped: {:>9.0} paths/s, time to 1% RMSE {:>10.3} s", full.paths / full.seconds, t_full);
        outln!("  naive:   {:>9.0} paths/s, time to 1% RMSE {:>10.3} s", naive.paths / naive.seconds, t_naive);
        outln!(
            "  speed-up of the shipped estimator: {:.0}x (a lower bound: the naive estimator lit {} of {} directions, through the sun's disk only)",
            t_naive / t_full,
            naive.mean.iter().filter(|m| **m > 0.0).count(),
            BENCH_DIRECTIONS.len()
        );
        outln!(
            "  {:>10} {:>10} {:>14} {:>10} {:>14} {:>10} {:>8}",
            "zenith",
            "azimuth",
            "shipped",
            "rel.se",
            "naive",
            "rel.se",
            "z"
        );
        for (i, (zen, az)) in BENCH_DIRECTIONS.iter().enumerate() {
            outln!(
                "  {:>10} {:>10} {:>14.6e} {:>10.4} {:>14.6e} {:>10.4} {:>8.2}",
                zen,
                az,
                full.mean[i],
                (full.rel_var[i] / spp as f64).sqrt(),
                naive.mean[i],
                (naive.rel_var[i] / naive_spp as f64).sqrt(),
                z[i]
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// `sky bench adaptive` (see its help).
fn adaptive(pixels: usize, target: f64, spp: u32) -> Result<ExitCode> {
    if pixels < 2 || !(target > 0.0 && target < 1.0) || spp < 2 * rend::ADAPTIVE_PILOT_SPP {
        return super::usage(format!(
            "need --pixels >= 2, 0 < --target < 1 and --spp >= {}",
            2 * rend::ADAPTIVE_PILOT_SPP
        ));
    }
    let cache = sky::mie::MieCache::from_env();
    // (atmosphere, sun zenith, view zenith, view azimuth from the sun)
    let cases = [
        ("atmospheres/hazed.toml", 60.0, 63.0, 0.0),
        ("atmospheres/cloudy3.toml", 60.0, 40.0, 0.0),
        ("atmospheres/hazed.toml", 94.0, 80.0, 0.0),
    ];
    outln!("adaptive sampling on heavy-tailed pixels: {pixels} pixels per case, target {target}, at most {spp} samples; mean Y and its difference from a fixed-sample reference");
    for (path, sun, zen, az) in cases {
        let atm = Atmosphere::load(std::path::Path::new(path))
            .map_err(anyhow::Error::new)
            .with_context(|| path.to_string())?;
        let base = {
            let mut s_ = Settings::directions(vec![(zen, az); pixels], sun, vec![], spp, 11, false);
            s_.spectral.xyz = true;
            s_.spectral.wavelength_sampling = WavelengthSampling::Hero;
            s_
        };
        let scene = Scene::new(&atm, &base.spectral, &cache, &|| {});
        let render =
            |s: &Settings| rend::render(&scene, &s.view, &AtomicBool::new(false), &|| {}).expect("not cancelled");
        // Mean over pixels, its standard error, and the mean samples taken.
        let stats = |values: &[f64], taken: f64| {
            let n = values.len() as f64;
            let mean = values.iter().sum::<f64>() / n;
            let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
            (mean, (var / n).sqrt(), taken)
        };
        let of = |img: &rend::Image| -> (Vec<f64>, f64) {
            (
                img.pixels.iter().map(|p| p.xyz[1]).collect(),
                img.pixels.iter().map(|p| p.samples as f64).sum::<f64>() / pixels as f64,
            )
        };
        let (v, t) = of(&render(&{
            let mut s_ = base.clone();
            s_.view.seed = 1011;
            s_
        }));
        let reference = stats(&v, t);
        let (v, t) = of(&render(&base));
        let fixed = stats(&v, t);
        let (v, t) = of(&render(&{
            let mut s_ = base.clone();
            s_.view.max_rel_error = Some(target);
            s_
        }));
        let two_stage = stats(&v, t);
        // The old rule: a pixel's estimate after its first k samples is the
        // fixed render at k samples; it stopped at the first k (from 32,
        // every 16) whose running error met the target.
        let mut old: Vec<Option<(f64, u32)>> = vec![None; pixels];
        let mut k = 32;
        while k < spp && old.iter().any(|o| o.is_none()) {
            let img = render(&{
                let mut s_ = base.clone();
                s_.view.spp = k;
                s_
            });
            for (o, p) in old.iter_mut().zip(&img.pixels) {
                if o.is_none() && (p.xyz[1] <= 0.0 || p.xyz_stderr[1] <= target * p.xyz[1]) {
                    *o = Some((p.xyz[1], k));
                }
            }
            k += 16;
        }
        let full = render(&base);
        let old: Vec<(f64, u32)> = old.iter().zip(&full.pixels).map(|(o, p)| o.unwrap_or((p.xyz[1], spp))).collect();
        let old_rule = stats(
            &old.iter().map(|o| o.0).collect::<Vec<_>>(),
            old.iter().map(|o| o.1 as f64).sum::<f64>() / pixels as f64,
        );
        outln!(
            "  {path}, sun zenith {sun} deg, view ({zen}, {az}) deg: reference {:.5e} ± {:.1e}",
            reference.0,
            reference.1
        );
        for (name, (m, se, taken)) in [("fixed", fixed), ("two stages", two_stage), ("old rule", old_rule)] {
            let z = (m - reference.0) / (se * se + reference.1 * reference.1).sqrt();
            outln!(
                "    {name:<11} {m:.5e} ± {se:.1e}  ({:+.2} %, z {z:+.2})  {taken:.0} samples per pixel",
                100.0 * (m / reference.0 - 1.0)
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}
