//! `sky render`'s last phase: the image denoised if asked, written as
//! OpenEXR (with the render's metadata) and PNG, and the summary (JSON, a
//! JSON progress line or a line on stderr).

use anyhow::{Context, Result};
use serde_json::json;
use sky::atmosphere::Atmosphere;
use sky::directions::camera::Camera;
use sky::render::{self, output, Settings};
use sky::session::Rendered;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

/// What a render writes, from its flags (checked: `out` ends in .exr, and
/// `png` and `denoise` come with X, Y, Z).
pub(super) struct Outputs {
    /// --out: the OpenEXR file
    pub out: Option<PathBuf>,
    /// --png: the tonemapped PNG
    pub png: Option<PathBuf>,
    /// --exposure-ev of the PNG
    pub exposure_ev: f64,
    /// --json: the summary on stdout
    pub json: bool,
    /// --json-progress: a last progress line on stdout
    pub json_progress: bool,
    /// --denoise
    pub denoise: bool,
    /// --method (and --streams), as the outputs record it
    pub method: String,
}

/// Writes the outputs of a finished render (its journal, at
/// `journal_path`, goes once the OpenEXR is written) and reports it.
pub(super) fn finish(
    a: &Outputs,
    settings: &Settings,
    atm: &Atmosphere,
    rendered: Rendered,
    prep_s: f64,
    t0: Instant,
    journal_path: Option<PathBuf>,
) -> Result<ExitCode> {
    let (width, height) = (settings.view.width, settings.view.height);
    let n = width * height;
    let image = rendered.image;
    let farm_stats = rendered.stats;
    let render_s = t0.elapsed().as_secs_f64();
    let taken: f64 = image.pixels.iter().map(|p| p.samples as f64).sum();
    let paths_cut: u64 = image.pixels.iter().map(|p| p.paths_cut as u64).sum();
    let samples = taken * (1 + settings.spectral.spectral_nm.len()) as f64;
    let metadata = metadata(a, settings, atm);
    let (image, noisy) = if a.denoise {
        let d = render::denoise::Denoise::default().apply(&image);
        (d, Some(image))
    } else {
        (image, None)
    };
    if let Some(o) = &a.out {
        output::write_exr(o, &image, noisy.as_ref(), settings.spectral.xyz, &settings.spectral.spectral_nm, &metadata)
            .with_context(|| format!("writing {}", o.display()))?;
        if let Some(j) = &journal_path {
            let _ = std::fs::remove_file(j);
        }
    }
    if let Some(p) = &a.png {
        let sun_xyz = sky::spectrum::spectrum_to_xyz(&atm.sun.irradiance_w_m2_nm);
        output::write_png(p, &image, a.exposure_ev, Some(sun_xyz))
            .with_context(|| format!("writing {}", p.display()))?;
    }
    if a.json {
        let mut v = json!({
            "atmosphere": atm.path.display().to_string(),
            "atmosphere_hash": atm.content_hash,
            "method": a.method,
            "width": width, "height": height, "spp": settings.view.spp, "seed": settings.view.seed,
            "mean_samples_per_pixel": taken / n as f64,
            "sun_zenith_deg": settings.view.sun_zenith_deg, "sun_azimuth_deg": settings.view.sun_azimuth_deg,
            "prepare_seconds": prep_s, "render_seconds": render_s,
            "paths_per_second": samples / render_s.max(1e-9),
            "paths_cut": paths_cut,
            "y_relative_stderr": relative_stderr_summary(&image),
            "spectral_nm": settings.spectral.spectral_nm,
            "farm": farm_stats,
        });
        if let Camera::Directions(list) = &settings.view.camera {
            v["directions"] = json!(list
                .iter()
                .zip(&image.pixels)
                .map(|((z, az), p)| json!({
                    "zenith_deg": z, "azimuth_deg": az,
                    "xyz": p.xyz, "xyz_stderr": p.xyz_stderr,
                    "radiance_w_m2_sr_nm": p.spectral, "radiance_stderr_w_m2_sr_nm": p.spectral_stderr,
                }))
                .collect::<Vec<_>>());
        }
        outln!("{}", serde_json::to_string_pretty(&v)?);
    } else if a.json_progress {
        outln!("{}", json!({"event": "done", "render_seconds": render_s, "farm": farm_stats}));
    } else if a.method != "monte-carlo" {
        eprintln!("rendered {width}x{height} by the {} solver in {render_s:.1} s (optics {prep_s:.1} s)", a.method);
    } else {
        eprintln!(
            "rendered {}x{} at {:.1} spp in {:.1} s ({:.0} paths/s; optics {:.1} s)",
            width,
            height,
            taken / n as f64,
            render_s,
            samples / render_s.max(1e-9),
            prep_s
        );
    }
    if paths_cut > 0 && !a.json {
        eprintln!("sky render: warning: {paths_cut} paths were cut at the limit of {} vertices (the image is biased low where they were)", render::tracer::MAX_VERTICES);
    }
    Ok(ExitCode::SUCCESS)
}

/// The OpenEXR's metadata: what was rendered, how, and in which units.
fn metadata(a: &Outputs, settings: &Settings, atm: &Atmosphere) -> Vec<(String, String)> {
    let v = &settings.view;
    let camera_desc = match &settings.view.camera {
        Camera::Equirect => "equirect".to_string(),
        Camera::Fisheye => "fisheye".to_string(),
        Camera::Pinhole { azimuth_deg, elevation_deg, fov_deg } => format!("pinhole azimuth {azimuth_deg} deg, elevation {elevation_deg} deg, fov {fov_deg} deg"),
        Camera::Directions(_) => "directions".to_string(),
        Camera::Lut { mapping, .. } => format!(
            "lut ({} mapping, threshold sun zenith {:.1} deg; u = heading/azimuth from the sun over pi, v as in the talk's uvToWorldSpaceDirection)",
            if mapping.sun_centred() { "sun-centred" } else { "latitude-longitude" },
            mapping.threshold_deg
        ),
        Camera::LutStrip { mappings, .. } => format!("a strip of {} lut slices", mappings.len()),
    };
    let mut m = vec![
        ("version".to_string(), sky::VERSION.to_string()),
        ("camera".to_string(), camera_desc),
        ("atmosphere".to_string(), atm.path.display().to_string()),
        ("atmosphere_hash".to_string(), atm.content_hash.clone()),
        ("sun_zenith_deg".to_string(), v.sun_zenith_deg.to_string()),
        ("sun_azimuth_deg".to_string(), v.sun_azimuth_deg.to_string()),
        ("altitude_m".to_string(), v.altitude_m.to_string()),
        ("spp".to_string(), v.spp.to_string()),
        ("max_rel_error".to_string(), v.max_rel_error.map(|e| e.to_string()).unwrap_or_else(|| "none".to_string())),
        ("seed".to_string(), v.seed.to_string()),
        ("band_nm".to_string(), settings.spectral.band_nm.to_string()),
        ("denoised".to_string(), a.denoise.to_string()),
        ("units".to_string(), "XYZ: CIE 1931 x 683 lm/W (Y in cd/m^2); spectral: W m^-2 sr^-1 nm^-1".to_string()),
    ];
    // Only where it is not the path tracer, so that its files stay as they were.
    if a.method != "monte-carlo" {
        m.insert(2, ("method".to_string(), a.method.clone()));
    }
    m
}

/// Median, 90th percentile and maximum over the lit pixels of the relative
/// standard error of Y (of the first spectral line without XYZ), and the
/// largest Y: how converged a render is, at a glance.
fn relative_stderr_summary(image: &render::Image) -> serde_json::Value {
    let mut rel: Vec<f64> = Vec::new();
    let mut y_max: f64 = 0.0;
    for p in &image.pixels {
        let (v, se) = if p.xyz[1] > 0.0 {
            (p.xyz[1], p.xyz_stderr[1])
        } else {
            (p.spectral.first().copied().unwrap_or(0.0), p.spectral_stderr.first().copied().unwrap_or(0.0))
        };
        if v > 0.0 {
            rel.push(se / v);
            y_max = y_max.max(v);
        }
    }
    if rel.is_empty() {
        return serde_json::Value::Null;
    }
    rel.sort_by(f64::total_cmp);
    let at = |q: f64| rel[((rel.len() - 1) as f64 * q).round() as usize];
    json!({ "median": at(0.5), "p90": at(0.9), "max": at(1.0), "largest_value": y_max })
}
