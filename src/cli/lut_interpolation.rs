//! `sky lut interpolation`: what the LUT mappings lose by interpolating,
//! measured on the noise-free single-scattering sky of an atmosphere
//! (`sky::study::interpolation`).

use super::{usage, EXIT_INVALID};
use anyhow::Context;
use anyhow::Result;
use clap::Args;
use sky::atmosphere::Atmosphere;
use sky::directions::mapping::{self, DirectionMapping};
use sky::lut::decode::{sample_sky, Texture};
use sky::mie::MieCache;
use sky::render::{Scene, SpectralSettings, WavelengthSampling};
use sky::study::error_map::{error_fisheye, ramp_bar, sky_fisheye, slice_image, write_rgb_png};
use sky::study::interpolation::{
    in_memory_bake, measure, slice_texels, slices_read, Errors, Report, SingleScatteringSky, SkyModel,
};
use sky::study::verify::BETWEEN_SLICES_DEG;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Args, Debug)]
pub struct InterpolationArgs {
    /// The atmosphere file
    atmosphere: PathBuf,
    /// Slice size WIDTHxHEIGHT (the talk's: 32x128 sunny, 16x64 cloudy)
    #[arg(long, value_parser = super::render::parse_size, default_value = "32x128")]
    size: (usize, usize),
    /// Observer altitude, metres
    #[arg(long, default_value_t = 0.0)]
    altitude_m: f64,
    /// Width of the wavelength bands, nm
    #[arg(long, default_value_t = 20.0)]
    band_nm: f64,
    /// Directions of the lattice above the horizon
    #[arg(long, default_value_t = 2000)]
    directions: usize,
    /// Decode with this sun-zenith threshold between the mappings (default: the measured one)
    #[arg(long, value_name = "DEG")]
    threshold_deg: Option<f64>,
    /// Pictures into this folder: error fisheyes between slices and of both mappings past the threshold, slices as stored and decoded
    #[arg(long, value_name = "DIR")]
    plot: Option<PathBuf>,
    /// Print JSON
    #[arg(long)]
    json: bool,
}

fn pct(x: f64) -> String {
    format!("{:.2} %", 100.0 * x)
}

fn aureole(e: &Errors) -> String {
    match (e.aureole_median, e.aureole_p99) {
        (Some(m), Some(p)) => format!("aureole median {} p99 {}", pct(m), pct(p)),
        _ => String::new(),
    }
}

pub fn run(a: InterpolationArgs) -> Result<ExitCode> {
    let (w, h) = a.size;
    if a.directions == 0 || !(a.band_nm > 0.0) || !(0.0..=20000.0).contains(&a.altitude_m) {
        return usage("--directions must be at least 1, --band-nm positive and --altitude-m from 0 to 20000");
    }
    if let Some(t) = a.threshold_deg {
        if !(0.0..=90.0).contains(&t) {
            return usage(format!("--threshold-deg must be from 0 to 90, got {t}"));
        }
    }
    let atm = match Atmosphere::load(&a.atmosphere) {
        Ok(x) => x,
        Err(e) => {
            eprintln!("{e}");
            return Ok(ExitCode::from(EXIT_INVALID));
        }
    };
    eprintln!("sky lut interpolation: preparing the optics of {}", a.atmosphere.display());
    let spectral = SpectralSettings {
        band_nm: a.band_nm,
        wavelength_sampling: WavelengthSampling::Hero,
        spectral_nm: Vec::new(),
        xyz: true,
    };
    let scene = Scene::new(&atm, &spectral, &MieCache::from_env(), &|| {});
    let model = SingleScatteringSky { scene: &scene, altitude_km: a.altitude_m / 1000.0 };
    eprintln!("sky lut interpolation: single scattering at {w}x{h}, {} directions (a minute or two)", a.directions);
    let r = measure(
        &model,
        w,
        h,
        atm.planet.radius_km,
        atm.planet.top_km,
        a.directions,
        &BETWEEN_SLICES_DEG,
        a.threshold_deg,
    );
    if let Some(dir) = &a.plot {
        plot(dir, &model, &r, atm.planet.radius_km, atm.planet.top_km)?;
    }
    if a.json {
        outln!("{}", serde_json::to_string(&r)?);
        return Ok(ExitCode::SUCCESS);
    }
    outln!("{} at {w}x{h}: relative luminance error of the noise-free single-scattering sky, {} directions above the horizon (the aureole, within 5 deg of the sun, apart)", atm.name, a.directions);
    outln!("direction interpolation at each slice's own sun, in both mappings (median / p99):");
    outln!("  slice  sun zenith   sun-centred: sky          aureole            latitude-longitude: sky   aureole");
    let au = |e: &Errors| {
        format!("{:>7} / {:>7}", pct(e.aureole_median.unwrap_or(f64::NAN)), pct(e.aureole_p99.unwrap_or(f64::NAN)))
    };
    for s in &r.regions {
        outln!(
            "  {:>5}  {:>8.3} deg  {:>7} / {:>7}  {}   {:>7} / {:>7}  {}{}",
            s.index,
            s.sun_zenith_deg,
            pct(s.sun_centred.median),
            pct(s.sun_centred.p99),
            au(&s.sun_centred),
            pct(s.latitude_longitude.median),
            pct(s.latitude_longitude.p99),
            au(&s.latitude_longitude),
            if s.sun_zenith_deg <= r.threshold_deg { "  <- sun-centred" } else { "" }
        );
    }
    outln!(
        "measured threshold: {:.3} deg (the last slice up to which the sun-centred mapping's larger p99, sky or aureole, is the smaller); decoded with {:.3} deg",
        r.measured_threshold_deg,
        r.threshold_deg
    );
    outln!("between slices (decoded: direction and slice interpolation together; direction only: the two slices at their own suns):");
    for b in &r.between {
        outln!(
            "  sun {:>5.1} deg (slices {}, {}): decoded median {} p99 {}; direction only median {} p99 {}  {}",
            b.sun_elevation_deg,
            b.slices[0],
            b.slices[1],
            pct(b.decoded.median),
            pct(b.decoded.p99),
            pct(b.direction_only_median),
            pct(b.direction_only_p99),
            aureole(&b.decoded)
        );
    }
    outln!("twilight (sun 0 to -10 deg, 0.1 deg steps): largest change of log Y per step {:.4} decoded, {:.4} in the sky itself", r.twilight_step_decoded, r.twilight_step_model);
    Ok(ExitCode::SUCCESS)
}

/// Fisheye size of the pictures, pixels.
const PICTURE: usize = 192;

/// The pictures of `--plot` (see its help).
fn plot(dir: &std::path::Path, model: &SingleScatteringSky, r: &Report, radius_km: f64, top_km: f64) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let (w, h) = (r.width, r.height);
    let nearest = |elev: f64| {
        (0..mapping::UPPER_SLICES)
            .min_by(|&i, &j| {
                (mapping::slice_sun_zenith_deg(i, radius_km, top_km) - (90.0 - elev))
                    .abs()
                    .total_cmp(&(mapping::slice_sun_zenith_deg(j, radius_km, top_km) - (90.0 - elev)).abs())
            })
            .unwrap_or(0)
    };
    let shown = [nearest(30.0), nearest(10.0)];
    let mut layers: Vec<usize> = r
        .between
        .iter()
        .filter(|b| b.sun_elevation_deg >= 0.0)
        .flat_map(|b| slices_read(90.0 - b.sun_elevation_deg, radius_km, top_km))
        .collect();
    layers.extend(shown);
    let (entry, texture) = in_memory_bake(model, w, h, radius_km, top_km, r.threshold_deg, &layers);
    let png = |name: String, rgb: Vec<u8>, side: usize| {
        write_rgb_png(&dir.join(&name), side, side, rgb).with_context(|| format!("writing {name}"))
    };
    for b in r.between.iter().filter(|b| b.sun_elevation_deg >= 0.0) {
        let z = 90.0 - b.sun_elevation_deg;
        png(
            format!("error_sun_{:.1}.png", b.sun_elevation_deg),
            error_fisheye(PICTURE, &|d| sample_sky(&entry, &texture, z, 0.0, d)[1], &|d| model.xyz(z, d)[1]),
            PICTURE,
        )?;
    }
    for i in shown {
        let z = entry.slices[i].sun_zenith_deg;
        let stored = dir.join(format!("slice_{i}_stored.png"));
        sky::render::output::write_png(&stored, &slice_image(&texture, i, 3), 0.0, None)
            .with_context(|| format!("writing {}", stored.display()))?;
        let decoded = dir.join(format!("slice_{i}_decoded.png"));
        sky::render::output::write_png(
            &decoded,
            &sky_fisheye(PICTURE, &|d| sample_sky(&entry, &texture, z, 0.0, d)),
            0.0,
            None,
        )
        .with_context(|| format!("writing {}", decoded.display()))?;
    }
    // Both mappings at the first slice past the threshold.
    if let Some(s) = r.regions.iter().find(|s| s.sun_zenith_deg > r.threshold_deg) {
        for (sun_centred, name) in [(true, "sun_centred"), (false, "latitude_longitude")] {
            let m = DirectionMapping::new(s.sun_zenith_deg, 0.0);
            let t = Texture { width: w, height: h, layers: vec![slice_texels(model, &m, sun_centred, w, h)] };
            let decoded = |d| {
                let (u, v) = m.uv_in_region(d, sun_centred);
                t.bilinear(0, u, v)[1]
            };
            png(
                format!("mapping_{}_{name}.png", s.index),
                error_fisheye(PICTURE, &decoded, &|d| model.xyz(s.sun_zenith_deg, d)[1]),
                PICTURE,
            )?;
        }
    }
    write_rgb_png(&dir.join("ramp.png"), 256, 16, ramp_bar(256, 16)).context("writing ramp.png")?;
    eprintln!("sky lut interpolation: pictures in {} (error fisheyes: black 0.01 %, blue 0.1 %, green 1 %, yellow 5 %, red 10 %, white 100 %; ramp.png)", dir.display());
    Ok(())
}
