//! `sky lut fog-falloff`: the talk's fog falloff fitted to reference fog
//! renders of one atmosphere (`sky::bake::fog_falloff`), its error next to
//! the depth-free alternative's, and a plot of the fit against the
//! references.

use super::progress::{fmt_duration, Style};
use super::{usage, EXIT_INVALID};
use anyhow::Result;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use sky::atmosphere::Atmosphere;
use sky::bake::fog_falloff::{study, study_views, FalloffStudy, DEPTHS_X};
use sky::lut::fog::FogGeometry;
use sky::mie::MieCache;
use sky::plot::{line_plot, Axes, Scale, Series};
use sky::render::{Scene, SpectralSettings, WavelengthSampling};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

#[derive(Args, Debug)]
pub struct FogFalloffArgs {
    /// The atmosphere file
    atmosphere: PathBuf,
    /// Only the air below this altitude makes fog (the cloud base: 3 km in the cloudy basis skies)
    #[arg(long, default_value_t = 3.0)]
    ceiling_km: f64,
    /// Observer altitude, metres (below the ceiling)
    #[arg(long, default_value_t = 0.0)]
    altitude_m: f64,
    /// Sun zenith angles of the reference renders, degrees
    #[arg(long, value_delimiter = ',', default_value = "30,60,85")]
    sun_zenith_deg: Vec<f64>,
    /// Samples per direction of the reference renders (each is 3 directions: cheap)
    #[arg(long, default_value_t = 1024)]
    spp: u32,
    /// Width of the wavelength bands, nm
    #[arg(long, default_value_t = 20.0)]
    band_nm: f64,
    /// Write falloff.png (the fitted falloff against the references) into this folder
    #[arg(long, value_name = "DIR")]
    plot: Option<PathBuf>,
    /// Print JSON (the fit, its error and every reference curve)
    #[arg(long)]
    json: bool,
}

fn pct(x: f64) -> String {
    format!("{:.1} %", 100.0 * x)
}

pub fn run(a: FogFalloffArgs) -> Result<ExitCode> {
    if a.spp == 0 || !(a.band_nm > 0.0) {
        return usage("--spp and --band-nm must be positive");
    }
    if !(a.altitude_m >= 0.0 && a.altitude_m / 1000.0 < a.ceiling_km) {
        return usage(format!(
            "--altitude-m ({} m) must be at or above the ground and below --ceiling-km ({} km)",
            a.altitude_m, a.ceiling_km
        ));
    }
    if let Some(z) = a.sun_zenith_deg.iter().find(|z| !(0.0..=120.0).contains(*z)) {
        return usage(format!("--sun-zenith-deg must be between 0 and 120, got {z}"));
    }
    let atm = match Atmosphere::load(&a.atmosphere) {
        Ok(x) => x,
        Err(e) => {
            eprintln!("{e}");
            return Ok(ExitCode::from(EXIT_INVALID));
        }
    };
    let spectral = SpectralSettings {
        band_nm: a.band_nm,
        wavelength_sampling: WavelengthSampling::Hero,
        spectral_nm: vec![],
        xyz: true,
    };
    let scene = Scene::new(&atm, &spectral, &MieCache::from_env(), &|| {});
    let geometry = FogGeometry {
        planet_radius_km: scene.medium.radius_km,
        observer_altitude_km: a.altitude_m / 1000.0,
        ceiling_km: a.ceiling_km,
    };
    let total = study_views(a.sun_zenith_deg.len());
    let cancel = Arc::new(AtomicBool::new(false));
    {
        let c = cancel.clone();
        let _ = ctrlc::set_handler(move || c.store(true, Ordering::SeqCst));
    }
    let (done, start, last) = (AtomicUsize::new(0), Instant::now(), Mutex::new(Instant::now()));
    let style = Style::choose(a.json);
    let bar = (style == Style::Bars).then(|| {
        let b = ProgressBar::new(total as u64);
        b.set_style(ProgressStyle::with_template("{bar:40} {pos}/{len} renders  ETA {eta}").unwrap());
        b
    });
    let on_view = || {
        let n = done.fetch_add(1, Ordering::Relaxed) + 1;
        match &bar {
            Some(b) => b.set_position(n as u64),
            None if style == Style::Lines => {
                let mut l = last.lock().unwrap();
                if l.elapsed() >= Duration::from_secs(5) || n == total {
                    *l = Instant::now();
                    let elapsed = start.elapsed().as_secs_f64();
                    eprintln!(
                        "sky lut fog-falloff: {n}/{total} renders, {} elapsed, ETA {}",
                        fmt_duration(elapsed),
                        fmt_duration(elapsed * (total - n) as f64 / n as f64)
                    );
                }
            }
            None => {}
        }
    };
    let result = study(&scene, geometry, &a.sun_zenith_deg, a.spp, 1, &cancel, &on_view);
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    let Ok(s) = result else {
        eprintln!("sky lut fog-falloff: stopped");
        return Ok(ExitCode::from(130));
    };
    if let Some(dir) = &a.plot {
        std::fs::create_dir_all(dir)?;
        let path = dir.join("falloff.png");
        if let Err(e) = plot(&s, &path, &atm.name) {
            eprintln!("{}: {e}", path.display());
            return Ok(ExitCode::from(EXIT_INVALID));
        }
    }
    if a.json {
        outln!("{}", serde_json::to_string_pretty(&s)?);
    } else {
        outln!(
            "{}: fog under {} km, from {} m, suns at {:?} deg, {} samples per direction",
            atm.name,
            a.ceiling_km,
            a.altitude_m,
            a.sun_zenith_deg,
            a.spp
        );
        outln!("  falloff: a = {:.4}, p = {:.4}   (Fog(x) = LUT (1 - exp(-a theta^p x)) / (1 - exp(-a theta^p)), theta = elevation / 90 deg, at least 0.5 deg)", s.falloff.a, s.falloff.p);
        outln!(
            "  fitted falloff: median {} p99 {} relative error over {} depths x {} curves",
            pct(s.fit_error.median),
            pct(s.fit_error.p99),
            DEPTHS_X.len(),
            s.curves.len()
        );
        outln!("  depth-free LUT: median {} p99 {}", pct(s.depth_free_error.median), pct(s.depth_free_error.p99));
        if let Some(dir) = &a.plot {
            outln!("  plot: {}", dir.join("falloff.png").display());
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// The fraction of the full-depth fog against normalised depth: the
/// references (solid) and the fit (dashed) for the first sun, azimuth 90°
/// from it, at four elevations.
fn plot(s: &FalloffStudy, path: &std::path::Path, name: &str) -> Result<(), String> {
    let first_sun = s.curves.first().map_or(0.0, |c| c.sun_zenith_deg);
    let mut series = Vec::new();
    let picked: Vec<_> = s
        .curves
        .iter()
        .filter(|c| {
            c.sun_zenith_deg == first_sun
                && c.azimuth_from_sun_deg == 90.0
                && [0.5, 5.0, 20.0, 80.0].contains(&c.elevation_deg)
        })
        .collect();
    for (k, c) in picked.iter().enumerate() {
        let mut reference: Vec<(f64, f64)> =
            DEPTHS_X.iter().zip(&c.ratios).filter(|(_, r)| **r > 0.0).map(|(&x, &r)| (x, r)).collect();
        reference.push((1.0, 1.0));
        series.push(Series::new(format!("{}° up: reference", c.elevation_deg), reference, k));
        let theta = sky::lut::fog::falloff_theta(c.elevation_deg);
        let fit: Vec<(f64, f64)> = (0..=60)
            .map(|i| 10f64.powf(-3.0 + 3.0 * i as f64 / 60.0))
            .map(|x| (x, s.falloff.fraction(x, theta)))
            .collect();
        series.push(Series::new(format!("{}° up: fit", c.elevation_deg), fit, k).dashed());
    }
    let title = format!("{name}: fog within depth x of depth_max, sun zenith {first_sun}°, 90° from the sun");
    let axes = Axes {
        title: &title,
        x_label: "x = depth / depth_max",
        y_label: "Fog(x) / Fog(1)",
        x_scale: Scale::Log,
        y_scale: Scale::Log,
    };
    line_plot(path, &axes, &series)
}
