//! `sky bench`: timings reported in the README.

use anyhow::{Context, Result};
use serde_json::json;
use sky::atmosphere::Atmosphere;
use sky::atmosphere::RefractiveIndex;
use sky::mie::{self, phase, LogNormal};
use sky::render::camera::Camera;
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
    /// The GPU preview's passes timed by timestamp queries, the LUT sky pass against a plain textured full-screen pass in the same frames
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

/// A `sky worker` child process for benchmarks, killed on drop.
struct BenchWorker {
    child: std::process::Child,
    uri: String,
}

impl Drop for BenchWorker {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn spawn_worker(threads: usize, token: &str, name: &str) -> Result<BenchWorker> {
    use std::io::BufRead;
    let exe = std::env::current_exe()?;
    let mut child = std::process::Command::new(exe)
        .args(["worker", "--listen", "127.0.0.1:0", "--nice", "0", "--owner-load-limit", "1", "--name", name, "--threads", &threads.to_string()])
        .env("SKY_FARM_TOKEN", token)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .context("starting a worker")?;
    let mut line = String::new();
    std::io::BufReader::new(child.stdout.take().unwrap()).read_line(&mut line)?;
    let addr = line.trim().strip_prefix("listening on ").context("worker did not start")?.to_string();
    Ok(BenchWorker { child, uri: format!("http://{addr}") })
}

/// Times one farm render of `job` on `workers` (seconds).
fn farm_seconds(rt: &tokio::runtime::Runtime, job: &std::sync::Arc<sky::farm::coordinator::FarmJob>, workers: Vec<sky::farm::coordinator::WorkerSpec>, token: &str) -> Result<f64> {
    use sky::farm::coordinator::{run, Options};
    let opts = Options { token: Some(token.to_string()), ..Options::default() };
    let t = Instant::now();
    rt.block_on(run(job.clone(), workers, Default::default(), None, opts, std::sync::Arc::new(AtomicBool::new(false))))?;
    Ok(t.elapsed().as_secs_f64())
}

fn sunset_settings(spp: u32, seed: u64) -> Settings {
    Settings {
        spectral: SpectralSettings { spectral_nm: vec![], xyz: true, band_nm: 5.0, wavelength_sampling: WavelengthSampling::Tristimulus },
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
const BENCH_DIRECTIONS: [(f64, f64); 8] = [(0.0, 0.0), (30.0, 90.0), (45.0, 180.0), (60.0, 30.0), (70.0, 0.0), (80.0, 120.0), (85.0, 60.0), (88.0, 0.0)];

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
    let rel_var = img.pixels.iter().map(|p| (p.spectral_stderr[0] * p.spectral_stderr[0] * n) / (p.spectral[0] * p.spectral[0]).max(1e-300)).collect();
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
        BenchCommand::Mie { water, threads, step_nm, json } => {
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
        BenchCommand::Adaptive { pixels, target, spp } => adaptive(pixels, target, spp),
        BenchCommand::Disort { reference, case, spp, threads, json } => disort(&reference, &case, spp, threads, json),
        BenchCommand::Spectral { atmosphere, spp } => {
            let atm = Atmosphere::load(&atmosphere).map_err(anyhow::Error::new).with_context(|| format!("{}", atmosphere.display()))?;
            let cache = sky::mie::MieCache::from_env();
            outln!("colour noise per second, {} ({} directions, sun at 60 deg, {spp} spp, {} threads)", atmosphere.display(), BENCH_DIRECTIONS.len(), rayon::current_num_threads());
            let mut results = Vec::new();
            for (name, ws) in [("luminance", WavelengthSampling::Luminance), ("tristimulus", WavelengthSampling::Tristimulus), ("hero", WavelengthSampling::Hero)] {
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
                let noise: f64 = img.pixels.iter().map(|p| (0..3).map(|c| (p.xyz_stderr[c] / p.xyz[c]).powi(2)).sum::<f64>()).sum::<f64>() / img.pixels.len() as f64;
                outln!("  {name:<12} {secs:>7.2} s   mean Σ(rel. se)² {noise:.3e}   noise x time {:.3e}", noise * secs);
                results.push((name, noise * secs));
            }
            let best = results.iter().cloned().fold(("", f64::INFINITY), |a, b| if b.1 < a.1 { b } else { a });
            for (name, v) in &results {
                outln!("  {name:<12} {:.2}x the colour noise per second of {}", v / best.1, best.0);
            }
            Ok(ExitCode::SUCCESS)
        }
        BenchCommand::Denoise { atmosphere, spp, reference_spp } => {
            let atm = Atmosphere::load(&atmosphere).map_err(anyhow::Error::new).with_context(|| format!("{}", atmosphere.display()))?;
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
            outln!("  ({used} of {} pixels compared: those where the reference's own Y standard error is below 5 %)", reference.pixels.len());
            Ok(ExitCode::SUCCESS)
        }
        BenchCommand::Render { atmosphere, spp, naive_spp, json } => {
            let atm = Atmosphere::load(&atmosphere).map_err(anyhow::Error::new).with_context(|| format!("{}", atmosphere.display()))?;
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
                outln!("render efficiency, {} ({} directions at 550 nm, sun at 60 deg, {} threads)", atmosphere.display(), BENCH_DIRECTIONS.len(), rayon::current_num_threads());
                outln!("  shipped: {:>9.0} paths/s, time to 1% RMSE {:>10.3} s", full.paths / full.seconds, t_full);
                outln!("  naive:   {:>9.0} paths/s, time to 1% RMSE {:>10.3} s", naive.paths / naive.seconds, t_naive);
                outln!(
                    "  speed-up of the shipped estimator: {:.0}x (a lower bound: the naive estimator lit {} of {} directions, through the sun's disk only)",
                    t_naive / t_full,
                    naive.mean.iter().filter(|m| **m > 0.0).count(),
                    BENCH_DIRECTIONS.len()
                );
                outln!("  {:>10} {:>10} {:>14} {:>10} {:>14} {:>10} {:>8}", "zenith", "azimuth", "shipped", "rel.se", "naive", "rel.se", "z");
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
        BenchCommand::Bake(a) => super::bench_bake::run(a),
        BenchCommand::Preview(a) => super::bench_preview::run(a),
        BenchCommand::Farm { atmosphere, size, spp, threads, rounds, json } => {
            use sky::farm::coordinator::WorkerSpec;
            use sky::farm::job::{FarmJob, Optics};
            use std::sync::Arc;
            let (w, h) = size.split_once('x').and_then(|(a, b)| Some((a.parse::<usize>().ok()?, b.parse::<usize>().ok()?))).context("--size WxH")?;
            let threads = threads.unwrap_or_else(|| std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1));
            let (atm, bundle) = Atmosphere::load_bundle(&atmosphere).map_err(anyhow::Error::new)?;
            let mut settings = Settings::directions(Vec::new(), 70.0, Vec::new(), spp, 1, true);
            settings.view.camera = Camera::Equirect;
            settings.view.width = w;
            settings.view.height = h;
            settings.spectral.xyz = true;
            settings.spectral.wavelength_sampling = WavelengthSampling::Hero;
            let cache = sky::mie::MieCache::from_env();
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
            let scene = Arc::new(pool.install(|| Scene::new(&atm, &settings.spectral, &cache, &|| {})));
            let job = Arc::new(FarmJob::new(Arc::new(Optics::new(&atm, bundle, scene.clone())), &settings.view));
            let token = format!("bench-{}", std::process::id());
            let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build()?;
            // Workers, warmed on the job (optics prepared and cached by hash).
            let big = spawn_worker(threads, &token, "bench-all-cores")?;
            let one_a = spawn_worker(1, &token, "bench-1a")?;
            let one_b = spawn_worker(1, &token, "bench-1b")?;
            let remote = |w: &BenchWorker| WorkerSpec::Remote { name: None, uri: w.uri.clone() };
            for wk in [&big, &one_a, &one_b] {
                farm_seconds(&rt, &job, vec![remote(wk)], &token)?;
            }
            // Rounds alternating the contenders; the fastest of each counts
            // (the usual robust statistic on a shared machine).
            let (mut t_plain, mut t_embedded, mut t_remote, mut t_one, mut t_two) = (f64::MAX, f64::MAX, f64::MAX, f64::MAX, f64::MAX);
            for _ in 0..rounds {
                // 1. Overhead, on the same cores.
                let t = Instant::now();
                pool.install(|| rend::render(&scene, &settings.view, &AtomicBool::new(false), &|| {})).map_err(|e| anyhow::anyhow!("{e}"))?;
                t_plain = t_plain.min(t.elapsed().as_secs_f64());
                t_embedded = t_embedded.min(farm_seconds(&rt, &job, vec![WorkerSpec::Local { threads }], &token)?);
                t_remote = t_remote.min(farm_seconds(&rt, &job, vec![remote(&big)], &token)?);
                // 2. Scaling: two single-thread workers against one.
                t_one = t_one.min(farm_seconds(&rt, &job, vec![remote(&one_a)], &token)?);
                t_two = t_two.min(farm_seconds(&rt, &job, vec![remote(&one_a), remote(&one_b)], &token)?);
            }
            drop(big);
            let v = json!({
                "benchmark": "farm", "atmosphere": atmosphere.display().to_string(), "width": w, "height": h, "spp": spp, "threads": threads, "rounds": rounds,
                "plain_local_s": t_plain, "embedded_worker_s": t_embedded, "one_remote_worker_s": t_remote,
                "embedded_overhead": t_embedded / t_plain - 1.0, "remote_overhead": t_remote / t_plain - 1.0,
                "one_single_thread_worker_s": t_one, "two_single_thread_workers_s": t_two, "scaling_2_vs_1": t_one / t_two,
            });
            if json {
                outln!("{}", serde_json::to_string_pretty(&v)?);
            } else {
                outln!("farm benchmark, {} {w}x{h} at {spp} spp, {threads} threads (one run, fastest of {rounds} rounds; workers warmed on the job)", atmosphere.display());
                outln!("  plain local render (no coordinator)   {t_plain:>8.2} s");
                outln!("  embedded worker through the farm path {t_embedded:>8.2} s  overhead {:+.1} %", 100.0 * (t_embedded / t_plain - 1.0));
                outln!("  one sky worker process over loopback  {t_remote:>8.2} s  overhead {:+.1} %", 100.0 * (t_remote / t_plain - 1.0));
                outln!("  one single-thread worker              {t_one:>8.2} s");
                outln!("  two single-thread workers             {t_two:>8.2} s  speed-up {:.2}x", t_one / t_two);
            }
            Ok(ExitCode::SUCCESS)
        }
    }
}

/// `sky bench disort`: the relative RMSE of the rendered radiances against
/// DISORT's, over every direction and wavelength of the case, is
/// √(mean bias² + mean relative variance / n); the time to 1 % is the time
/// for n = mean relative variance / 1e-4 samples per direction at the
/// measured rate (the noise part; the run also reports the measured RMSE
/// and what of it is left once the noise is taken out).
fn disort(reference: &std::path::Path, case: &str, spp: u32, threads: usize, json: bool) -> Result<ExitCode> {
    if spp < 2 {
        return super::usage("--spp must be at least 2");
    }
    if threads == 0 {
        return super::usage("--threads must be at least 1");
    }
    let text = std::fs::read_to_string(reference).with_context(|| format!("reading {}", reference.display()))?;
    let r: serde_json::Value = serde_json::from_str(&text).with_context(|| format!("{}: not JSON", reference.display()))?;
    let cases: Vec<&serde_json::Value> = r["cases"].as_array().map(|a| a.iter().filter(|c| c["atmosphere"].as_str().is_some_and(|p| p.ends_with(case))).collect()).unwrap_or_default();
    if cases.is_empty() {
        return super::usage(format!("--case {case}: no case of {} uses that atmosphere", reference.display()));
    }
    let root = reference.parent().and_then(|p| p.parent()).and_then(|p| p.parent()).unwrap_or(std::path::Path::new("."));
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
    let cache = sky::mie::MieCache::from_env();
    let (mut seconds, mut rel_var, mut rel_err2, mut rows) = (0.0, Vec::new(), Vec::new(), Vec::new());
    let mut directions = 0;
    for (k, c) in cases.iter().enumerate() {
        let path = root.join(c["atmosphere"].as_str().unwrap_or_default());
        let atm = Atmosphere::load(&path).map_err(anyhow::Error::new).with_context(|| format!("{}", path.display()))?;
        let l = c["wavelength_nm"].as_f64().context("wavelength_nm")?;
        let num = |v: &serde_json::Value| v.as_f64().context("a number in the reference");
        let vz: Vec<f64> = c["view_zenith_deg"].as_array().context("view_zenith_deg")?.iter().map(num).collect::<Result<_>>()?;
        let ra: Vec<f64> = c["relative_azimuth_deg"].as_array().context("relative_azimuth_deg")?.iter().map(num).collect::<Result<_>>()?;
        let (mut dirs, mut want) = (Vec::new(), Vec::new());
        for (i, z) in vz.iter().enumerate() {
            for (j, a) in ra.iter().enumerate() {
                // The zenith is one direction whatever its azimuth.
                if *z == 0.0 && j > 0 {
                    continue;
                }
                dirs.push((*z, *a));
                want.push(num(&c["radiance_sr_inv"][i][j])?);
            }
        }
        directions = dirs.len();
        let settings = Settings::directions(dirs, num(&c["sun_zenith_deg"])?, vec![l], spp, 2023 + k as u64, false);
        let scene = Scene::new(&atm, &settings.spectral, &cache, &|| {});
        let t = Instant::now();
        let img = pool.install(|| rend::render(&scene, &settings.view, &AtomicBool::new(false), &|| {})).expect("not cancelled");
        seconds += t.elapsed().as_secs_f64();
        let e_sun = atm.sun.irradiance_w_m2_nm.eval(l);
        for (p, w) in img.pixels.iter().zip(&want) {
            let (ours, se) = (p.spectral[0] / e_sun, p.spectral_stderr[0] / e_sun);
            rel_var.push(se * se * spp as f64 / (w * w));
            rel_err2.push(((ours - w) / w).powi(2));
        }
        rows.push((l, img.pixels.len()));
    }
    let m = rel_var.len() as f64;
    let mean_rel_var = rel_var.iter().sum::<f64>() / m;
    let rmse = (rel_err2.iter().sum::<f64>() / m).sqrt();
    let noise = (mean_rel_var / spp as f64).sqrt();
    let floor = (rmse * rmse - noise * noise).max(0.0).sqrt();
    let seconds_per_sample = seconds / (spp as f64 * rows.len() as f64);
    let to_one_percent = mean_rel_var / 1e-4 * seconds_per_sample * rows.len() as f64;
    if json {
        outln!(
            "{}",
            serde_json::to_string_pretty(&json!({
                "benchmark": "disort-rayleigh-time-to-1-percent", "reference": reference.display().to_string(), "case": case,
                "wavelengths_nm": rows.iter().map(|r| r.0).collect::<Vec<_>>(), "directions": directions, "spp": spp, "threads": threads,
                "render_seconds": seconds, "relative_rmse": rmse, "relative_rmse_noise": noise, "relative_rmse_beyond_noise": floor,
                "seconds_to_one_percent": to_one_percent,
            }))?
        );
    } else {
        outln!("{case} against DISORT: {directions} directions x {} wavelengths, {spp} spp, spectral lines only, {threads} thread(s)", rows.len());
        outln!("  render {seconds:.2} s; relative RMSE {:.3} % (noise {:.3} %, beyond the noise {:.3} %)", 100.0 * rmse, 100.0 * noise, 100.0 * floor);
        outln!("  time to 1 % relative RMSE (noise): {to_one_percent:.2} s");
    }
    Ok(ExitCode::SUCCESS)
}

/// `sky bench adaptive` (see its help).
fn adaptive(pixels: usize, target: f64, spp: u32) -> Result<ExitCode> {
    if pixels < 2 || !(target > 0.0 && target < 1.0) || spp < 2 * rend::ADAPTIVE_PILOT_SPP {
        return super::usage(format!("need --pixels >= 2, 0 < --target < 1 and --spp >= {}", 2 * rend::ADAPTIVE_PILOT_SPP));
    }
    let cache = sky::mie::MieCache::from_env();
    // (atmosphere, sun zenith, view zenith, view azimuth from the sun)
    let cases = [("atmospheres/hazed.toml", 60.0, 63.0, 0.0), ("atmospheres/cloudy3.toml", 60.0, 40.0, 0.0), ("atmospheres/hazed.toml", 94.0, 80.0, 0.0)];
    outln!("adaptive sampling on heavy-tailed pixels: {pixels} pixels per case, target {target}, at most {spp} samples; mean Y and its difference from a fixed-sample reference");
    for (path, sun, zen, az) in cases {
        let atm = Atmosphere::load(std::path::Path::new(path)).map_err(anyhow::Error::new).with_context(|| path.to_string())?;
        let base = {
            let mut s_ = Settings::directions(vec![(zen, az); pixels], sun, vec![], spp, 11, false);
            s_.spectral.xyz = true;
            s_.spectral.wavelength_sampling = WavelengthSampling::Hero;
            s_
        };
        let scene = Scene::new(&atm, &base.spectral, &cache, &|| {});
        let render = |s: &Settings| rend::render(&scene, &s.view, &AtomicBool::new(false), &|| {}).expect("not cancelled");
        // Mean over pixels, its standard error, and the mean samples taken.
        let stats = |values: &[f64], taken: f64| {
            let n = values.len() as f64;
            let mean = values.iter().sum::<f64>() / n;
            let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
            (mean, (var / n).sqrt(), taken)
        };
        let of = |img: &rend::Image| -> (Vec<f64>, f64) { (img.pixels.iter().map(|p| p.xyz[1]).collect(), img.pixels.iter().map(|p| p.samples as f64).sum::<f64>() / pixels as f64) };
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
        let old_rule = stats(&old.iter().map(|o| o.0).collect::<Vec<_>>(), old.iter().map(|o| o.1 as f64).sum::<f64>() / pixels as f64);
        outln!("  {path}, sun zenith {sun} deg, view ({zen}, {az}) deg: reference {:.5e} ± {:.1e}", reference.0, reference.1);
        for (name, (m, se, taken)) in [("fixed", fixed), ("two stages", two_stage), ("old rule", old_rule)] {
            let z = (m - reference.0) / (se * se + reference.1 * reference.1).sqrt();
            outln!("    {name:<11} {m:.5e} ± {se:.1e}  ({:+.2} %, z {z:+.2})  {taken:.0} samples per pixel", 100.0 * (m / reference.0 - 1.0));
        }
    }
    Ok(ExitCode::SUCCESS)
}
