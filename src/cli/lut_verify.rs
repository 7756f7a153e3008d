//! `sky lut verify`: the decoder against direct renders (`sky::study::verify`):
//! luminance and colour error, PSNR, the error's sources, the twilight curve.

use super::{usage, EXIT_INVALID};
use anyhow::{Context, Result};
use clap::Args;
use sky::bake::BakeFile;
use sky::lut::decode::Luts;
use sky::mie::MieCache;
use sky::session::OpticsCache;
use sky::study::verify::SkyVerification;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

#[derive(Args, Debug)]
pub struct VerifyArgs {
    /// The bake's manifest.json
    manifest: PathBuf,
    /// The bake file it was baked from (for the atmospheres)
    #[arg(long, value_name = "BAKE.toml")]
    bake: PathBuf,
    /// The bake's slice cache, for the quantisation error (default: next to the manifest)
    #[arg(long, value_name = "DIR")]
    cache: Option<PathBuf>,
    /// Directions of the lattice above the horizon
    #[arg(long, default_value_t = 400)]
    directions: usize,
    /// How the references are rendered: deterministic (the transport solver at the bake's own resolution, for a bake of either method: no noise, so what remains is the LUTs' own error, mapping, interpolation and quantisation) or monte-carlo (the path tracer at --spp samples: the atmosphere's answer, with the solver's error and the references' noise in it)
    #[arg(long, value_enum, default_value = "deterministic")]
    reference: super::bake::MethodArg,
    /// Samples per reference direction (--reference monte-carlo, and the twilight curves' references)
    #[arg(long, default_value_t = 256)]
    spp: u32,
    /// Samples per direction of the fog's references (15 directions x 30 renders per basis sky; fog near the camera is faint and its light scattered more than once is noisy)
    #[arg(long, default_value_t = 4096)]
    fog_spp: u32,
    /// Twilight curves (PNG, one per basis sky) into this folder
    #[arg(long, value_name = "DIR")]
    plot: Option<PathBuf>,
    /// Print JSON
    #[arg(long)]
    json: bool,
}

pub fn run(a: VerifyArgs) -> Result<ExitCode> {
    use sky::study::verify::{verify, VerifyOptions};
    if a.directions == 0 || a.spp == 0 || a.fog_spp == 0 {
        return usage("--directions, --spp and --fog-spp must be at least 1");
    }
    let Some(luts) = super::lut::load(&a.manifest) else { return Ok(ExitCode::from(EXIT_INVALID)) };
    let Some(bake) = super::bake::load_bake(&a.bake) else { return Ok(ExitCode::from(EXIT_INVALID)) };
    let cache_dir =
        a.cache.clone().unwrap_or_else(|| a.manifest.parent().unwrap_or(std::path::Path::new(".")).join("cache"));
    let cache = cache_dir.is_dir().then(|| sky::bake::SliceCache::open(&cache_dir).ok()).flatten();
    let mie = sky::mie::MieCache::from_env();
    let cancel = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let opts = VerifyOptions {
        directions: a.directions,
        spp: a.spp,
        fog_spp: a.fog_spp,
        reference: a.reference.method(),
        ..VerifyOptions::default()
    };
    let how = match opts.reference {
        sky::bake::Method::Deterministic => "the transport solver at the bake's resolution".to_string(),
        sky::bake::Method::MonteCarlo => format!("the path tracer, {} spp", a.spp),
    };
    eprintln!(
        "sky lut verify: rendering references ({} directions, {how}) at 13 sun elevations per basis sky",
        a.directions
    );
    let optics = sky::session::OpticsCache::default();
    let started = std::time::Instant::now();
    // `elev` NaN: the solver's references of every elevation at once.
    let on_reference = |sky: &str, elev: f64| {
        let what = if elev.is_nan() {
            "solving the references".to_string()
        } else {
            format!("reference at sun elevation {elev:.2} deg")
        };
        eprintln!("sky lut verify: {sky}: {what} (elapsed {:.0} s)", started.elapsed().as_secs_f64())
    };
    let report = match verify(&luts, &bake, cache.as_ref(), &opts, &optics, &mie, &on_reference, cancel.clone()) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("sky lut verify: {e}");
            return Ok(ExitCode::from(EXIT_INVALID));
        }
    };
    let Some(twilight) = twilight(&a, &luts, &bake, &optics, &mie, &cancel)? else {
        return Ok(ExitCode::from(EXIT_INVALID));
    };
    if a.json {
        outln!("{}", serde_json::json!({ "skies": report, "twilight": twilight }));
        return Ok(ExitCode::SUCCESS);
    }
    print_elevations(&report);
    print_summaries(&report);
    outln!("interp: direction and slice interpolation together, direction: direction interpolation alone (median/p99), both measured on the atmosphere's noise-free single-scattering sky baked in memory at the bake's size (`sky lut interpolation`; ss: its share of the sky's luminance, median; n/a below the horizon, where that sky is no proxy)");
    for t in &twilight {
        outln!(
            "{} twilight: largest step of log Y per 0.1 deg decoded {:.4}, the atmosphere's own {:.4}",
            t["sky"].as_str().unwrap_or(""),
            t["largest_log_step_per_0_1_deg"].as_f64().unwrap_or(f64::NAN),
            t["reference_largest_log_step_per_0_1_deg"].as_f64().unwrap_or(f64::NAN)
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// The twilight curve of each of the bake's basis skies in the LUTs
/// (plotted with --plot), with its largest step and the atmosphere's own.
/// `None`: a reference failed (said on stderr).
fn twilight(
    a: &VerifyArgs,
    luts: &Luts,
    bake: &BakeFile,
    optics: &OpticsCache,
    mie: &MieCache,
    cancel: &Arc<AtomicBool>,
) -> Result<Option<Vec<serde_json::Value>>> {
    use sky::study::verify::{largest_log_step, reference_twilight_step, twilight_curve};
    let quality = if luts.manifest.quality == "final" { sky::bake::Quality::Final } else { sky::bake::Quality::Draft };
    let mut twilight = Vec::new();
    for (e, t) in luts.manifest.skies.iter().zip(&luts.textures) {
        if !bake.skies.iter().any(|s| s.name == e.name) {
            continue;
        }
        let curve = twilight_curve(luts, e, t);
        let decoded = largest_log_step(&curve);
        let reference =
            match reference_twilight_step(bake, &e.name, quality, a.spp, optics, mie, Vec::new(), cancel.clone()) {
                Ok(r) => r,
                Err(err) => {
                    eprintln!("sky lut verify: {err}");
                    return Ok(None);
                }
            };
        if let Some(dir) = &a.plot {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
            let series: Vec<sky::plot::Series> = ["zenith", "horizon toward the sun", "horizon away from the sun"]
                .iter()
                .enumerate()
                .map(|(c, label)| sky::plot::Series::new(*label, curve.iter().map(|p| (p[0], p[c + 1])).collect(), c))
                .collect();
            let axes = sky::plot::Axes {
                title: &format!("{}: decoded twilight luminance", e.name),
                x_label: "sun elevation (deg)",
                y_label: "Y (cd/m^2)",
                x_scale: sky::plot::Scale::Linear,
                y_scale: sky::plot::Scale::Log,
            };
            let path = dir.join(format!("twilight_{}.png", e.name));
            sky::plot::line_plot(&path, &axes, &series).map_err(anyhow::Error::msg)?;
        }
        twilight.push(serde_json::json!({ "sky": e.name, "largest_log_step_per_0_1_deg": decoded, "reference_largest_log_step_per_0_1_deg": reference, "curve": curve }));
    }
    Ok(Some(twilight))
}

/// The table of errors per sun elevation of each basis sky.
fn print_elevations(report: &[SkyVerification]) {
    for s in report {
        outln!(
            "{}: bake noise (median rel. stderr of Y) {:.2} %, quantisation median {} p99 {}",
            s.sky,
            100.0 * s.bake_median_rel_stderr_y,
            pct(s.quantisation_median_rel),
            pct(s.quantisation_p99_rel)
        );
        outln!(
            "  {:>9} {:>7} {:>9} {:>9} {:>10} {:>10} {:>8} {:>8} {:>7} {:>9} {:>23} {:>17}",
            "sun_elev",
            "where",
            "median_Y",
            "p99_Y",
            "aureole_m",
            "aureole_99",
            "dE00_m",
            "dE00_99",
            "PSNR",
            "ref_noise",
            "interp_m/99 (ss)",
            "direction_m/99"
        );
        for e in &s.elevations {
            let split = |m: f64, p: f64| format!("{:>7.2}%/{:>7.2}%", 100.0 * m, 100.0 * p);
            let (interp, direction) = match &e.interpolation {
                Some(i) => (
                    format!("{} ({:.0}%)", split(i.median_rel_y, i.p99_rel_y), 100.0 * i.single_scattering_fraction),
                    split(i.direction_only_median_rel_y, i.direction_only_p99_rel_y),
                ),
                None => ("n/a".to_string(), "n/a".to_string()),
            };
            outln!(
                "  {:>9.2} {:>7} {:>8.2}% {:>8.2}% {:>10} {:>10} {:>8.2} {:>8.2} {:>6.1}dB {:>8.2}% {:>23} {:>17}",
                e.sun_elevation_deg,
                if e.slice_centre { "slice" } else { "between" },
                100.0 * e.median_rel_y,
                100.0 * e.p99_rel_y,
                pct(e.aureole_median_rel_y),
                pct(e.aureole_p99_rel_y),
                e.median_de2000,
                e.p99_de2000,
                e.psnr_db,
                100.0 * e.reference_median_rel_stderr_y,
                interp,
                direction
            );
        }
    }
}

/// Each basis sky's sun, ambient and fog against their references.
fn print_summaries(report: &[SkyVerification]) {
    for s in report {
        let summary = |v: Vec<f64>| {
            let mut v = v;
            if v.is_empty() {
                return "n/a".to_string();
            }
            let m = sky::stats::percentile(&mut v.clone(), 0.5);
            format!(
                "median {:.3} %, p99 {:.3} % over {} elevations",
                100.0 * m,
                100.0 * sky::stats::percentile(&mut v, 0.99),
                v.len()
            )
        };
        let under = s.elevations.iter().filter(|e| e.sun_below_format_floor).count();
        outln!(
            "{} sun (decoded irradiance against the optics' column table): {}{}",
            s.sky,
            summary(s.elevations.iter().filter_map(|e| e.sun_rel_y).collect()),
            if under > 0 {
                format!("; at {under} more the transmittance is below the file's RGBA16F floor (2^-24: the direct sun under 6e-8 of its top-of-atmosphere irradiance) and decodes as 0")
            } else {
                String::new()
            }
        );
        outln!(
            "{} ambient (decoded upward irradiance against the reference render integrated over its lattice): {}",
            s.sky,
            summary(s.elevations.iter().filter_map(|e| e.ambient_rel_y).collect())
        );
        if let Some(f) = &s.fog {
            let spread = |x: &sky::study::verify_fog::Spread| {
                format!("median {:.2} %, p99 {:.2} % over {}", 100.0 * x.median, 100.0 * x.p99, x.count)
            };
            outln!(
                "{} fog (decoded against rendered fog, 100 m to 50 km, suns between slices; reference noise {:.2} %): fog {}; shadowed fog {}; attenuation {}",
                s.sky,
                100.0 * f.reference_noise,
                spread(&f.fog),
                spread(&f.shadowed),
                spread(&f.attenuation)
            );
            let by_depth: Vec<String> = sky::study::verify_fog::FOG_DEPTHS_KM
                .iter()
                .zip(&f.fog_median_by_depth)
                .map(|(d, m)| format!("{d} km {:.1} %", 100.0 * m))
                .collect();
            outln!("{} fog median by depth: {}", s.sky, by_depth.join(", "));
        }
    }
}

fn pct(v: Option<f64>) -> String {
    v.map_or("n/a".to_string(), |x| format!("{:.2}%", 100.0 * x))
}
