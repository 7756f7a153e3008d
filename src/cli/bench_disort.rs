//! `sky bench disort`: the path tracer's time to 1 % relative RMSE against
//! the committed DISORT reference.

use anyhow::{Context, Result};
use serde_json::json;
use sky::atmosphere::Atmosphere;
use sky::render::{self as rend, Scene, Settings};
use std::process::ExitCode;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

/// `sky bench disort`: the relative RMSE of the rendered radiances against
/// DISORT's, over every direction and wavelength of the case, is
/// √(mean bias² + mean relative variance / n); the time to 1 % is the time
/// for n = mean relative variance / 1e-4 samples per direction at the
/// measured rate (the noise part; the run also reports the measured RMSE
/// and what of it is left once the noise is taken out).
pub fn run(reference: &std::path::Path, case: &str, spp: u32, threads: usize, json: bool) -> Result<ExitCode> {
    if spp < 2 {
        return super::usage("--spp must be at least 2");
    }
    if threads == 0 {
        return super::usage("--threads must be at least 1");
    }
    let text = std::fs::read_to_string(reference).with_context(|| format!("reading {}", reference.display()))?;
    let r: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("{}: not JSON", reference.display()))?;
    let cases: Vec<&serde_json::Value> = r["cases"]
        .as_array()
        .map(|a| a.iter().filter(|c| c["atmosphere"].as_str().is_some_and(|p| p.ends_with(case))).collect())
        .unwrap_or_default();
    if cases.is_empty() {
        return super::usage(format!("--case {case}: no case of {} uses that atmosphere", reference.display()));
    }
    let root =
        reference.parent().and_then(|p| p.parent()).and_then(|p| p.parent()).unwrap_or(std::path::Path::new("."));
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
    let cache = sky::mie::MieCache::from_env();
    let (mut seconds, mut rel_var, mut rel_err2, mut rows) = (0.0, Vec::new(), Vec::new(), Vec::new());
    let mut directions = 0;
    for (k, c) in cases.iter().enumerate() {
        let path = root.join(c["atmosphere"].as_str().unwrap_or_default());
        let atm = Atmosphere::load(&path).map_err(anyhow::Error::new).with_context(|| format!("{}", path.display()))?;
        let l = c["wavelength_nm"].as_f64().context("wavelength_nm")?;
        let num = |v: &serde_json::Value| v.as_f64().context("a number in the reference");
        let vz: Vec<f64> =
            c["view_zenith_deg"].as_array().context("view_zenith_deg")?.iter().map(num).collect::<Result<_>>()?;
        let ra: Vec<f64> = c["relative_azimuth_deg"]
            .as_array()
            .context("relative_azimuth_deg")?
            .iter()
            .map(num)
            .collect::<Result<_>>()?;
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
        let img = pool
            .install(|| rend::render(&scene, &settings.view, &AtomicBool::new(false), &|| {}))
            .expect("not cancelled");
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
        outln!(
            "  render {seconds:.2} s; relative RMSE {:.3} % (noise {:.3} %, beyond the noise {:.3} %)",
            100.0 * rmse,
            100.0 * noise,
            100.0 * floor
        );
        outln!("  time to 1 % relative RMSE (noise): {to_one_percent:.2} s");
    }
    Ok(ExitCode::SUCCESS)
}
