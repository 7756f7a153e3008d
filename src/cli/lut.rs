//! `sky lut sample` and `sky lut decode`: the reference decoder
//! (`sky::lut::decode`) on the command line.

use super::{usage, EXIT_INVALID};
use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use sky::lut::decode::Luts;
use sky::render::camera::{direction_deg, Camera};
use sky::render::{output, Image, PixelResult};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Subcommand, Debug)]
pub enum LutCommand {
    /// The decoded sky toward one direction: XYZ and RGB
    #[command(after_help = "Example:\n  sky lut sample luts/manifest.json --sun-elevation-deg 12 --haziness 0.3 --cloudiness 0 --direction 60,180")]
    Sample(SampleArgs),
    /// A whole sky decoded from the LUTs, to OpenEXR (XYZ) and PNG
    #[command(after_help = "Example:\n  sky lut decode luts/manifest.json --sun-elevation-deg 12 --camera fisheye --size 256x256 --out sky.exr --png sky.png")]
    Decode(DecodeArgs),
}

/// The weather and the sun, as a runtime gives them.
#[derive(Args, Debug, Clone)]
pub struct Conditions {
    /// Sun elevation above the horizon, degrees (-90 to 90; below -10 the last slice holds)
    #[arg(long, value_name = "DEG", allow_negative_numbers = true)]
    sun_elevation_deg: f64,
    /// Sun azimuth, degrees
    #[arg(long, value_name = "DEG", default_value_t = 0.0, allow_negative_numbers = true)]
    sun_azimuth_deg: f64,
    /// 0 = the clear basis sky, 1 = hazed
    #[arg(long, default_value_t = 0.0)]
    haziness: f64,
    /// 0 = sunny; 1/6 = cloudy0, ..., 1 = cloudy5 (the manifest's weather rule)
    #[arg(long, default_value_t = 0.0)]
    cloudiness: f64,
}

#[derive(Args, Debug)]
pub struct SampleArgs {
    /// The bake's manifest.json
    manifest: PathBuf,
    #[command(flatten)]
    conditions: Conditions,
    /// View direction: zenith angle and azimuth, degrees
    #[arg(long, value_name = "ZENITH,AZIMUTH", value_parser = parse_pair, allow_negative_numbers = true)]
    direction: (f64, f64),
    /// Print JSON
    #[arg(long)]
    json: bool,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug)]
enum CameraKind {
    Fisheye,
    Equirect,
    Pinhole,
}

#[derive(Args, Debug)]
pub struct DecodeArgs {
    /// The bake's manifest.json
    manifest: PathBuf,
    #[command(flatten)]
    conditions: Conditions,
    #[arg(long, value_enum, default_value = "fisheye")]
    camera: CameraKind,
    /// Image size WIDTHxHEIGHT
    #[arg(long, value_parser = parse_size, default_value = "256x256")]
    size: (usize, usize),
    /// Pinhole: view azimuth, degrees
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    look_azimuth_deg: f64,
    /// Pinhole: view elevation, degrees
    #[arg(long, default_value_t = 10.0, allow_negative_numbers = true)]
    look_elevation_deg: f64,
    /// Pinhole: horizontal field of view, degrees
    #[arg(long, default_value_t = 90.0)]
    fov_deg: f64,
    /// The OpenEXR to write (X, Y, Z; Y in cd/m^2)
    #[arg(long, value_name = "FILE.exr")]
    out: PathBuf,
    /// Also a tonemapped PNG
    #[arg(long, value_name = "FILE.png")]
    png: Option<PathBuf>,
    /// PNG exposure, stops
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    exposure_ev: f64,
}

fn parse_pair(s: &str) -> Result<(f64, f64), String> {
    let (a, b) = s.split_once(',').ok_or_else(|| format!("`{s}`: expected ZENITH,AZIMUTH in degrees, e.g. 60,180"))?;
    let a: f64 = a.trim().parse().map_err(|_| format!("`{s}`: bad zenith angle"))?;
    let b: f64 = b.trim().parse().map_err(|_| format!("`{s}`: bad azimuth"))?;
    if !(0.0..=180.0).contains(&a) || !b.is_finite() {
        return Err(format!("`{s}`: the zenith angle must be from 0 to 180 degrees"));
    }
    Ok((a, b))
}

fn parse_size(s: &str) -> Result<(usize, usize), String> {
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(|| format!("`{s}`: expected WIDTHxHEIGHT, e.g. 256x256"))?;
    let w: usize = w.trim().parse().map_err(|_| format!("`{s}`: bad width"))?;
    let h: usize = h.trim().parse().map_err(|_| format!("`{s}`: bad height"))?;
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        return Err(format!("`{s}`: width and height must be from 1 to 16384"));
    }
    Ok((w, h))
}

fn check(c: &Conditions) -> Result<()> {
    if !(-90.0..=90.0).contains(&c.sun_elevation_deg) {
        return usage(format!("--sun-elevation-deg must be from -90 to 90, got {}", c.sun_elevation_deg));
    }
    if !c.sun_azimuth_deg.is_finite() {
        return usage("--sun-azimuth-deg must be a number");
    }
    for (flag, v) in [("--haziness", c.haziness), ("--cloudiness", c.cloudiness)] {
        if !(0.0..=1.0).contains(&v) {
            return usage(format!("{flag} must be from 0 to 1, got {v}"));
        }
    }
    Ok(())
}

fn load(manifest: &std::path::Path) -> Option<Luts> {
    match Luts::load(manifest) {
        Ok(l) => Some(l),
        Err(e) => {
            eprintln!("sky lut: {e}");
            None
        }
    }
}

pub fn run(c: LutCommand) -> Result<ExitCode> {
    match c {
        LutCommand::Sample(a) => {
            check(&a.conditions)?;
            let Some(luts) = load(&a.manifest) else { return Ok(ExitCode::from(EXIT_INVALID)) };
            let c = &a.conditions;
            let d = direction_deg(a.direction.0, a.direction.1);
            let rgb = luts.sample(c.sun_elevation_deg, c.sun_azimuth_deg, c.haziness, c.cloudiness, d);
            let xyz = luts.sample_xyz(c.sun_elevation_deg, c.sun_azimuth_deg, c.haziness, c.cloudiness, d);
            let space = &luts.manifest.colour.space;
            if a.json {
                outln!("{}", serde_json::json!({ "xyz": xyz, "rgb": rgb, "colour_space": space, "units": "cd/m^2 (Y)" }));
            } else {
                outln!("XYZ {:.6e} {:.6e} {:.6e}  (Y in cd/m^2)", xyz[0], xyz[1], xyz[2]);
                outln!("RGB {:.6e} {:.6e} {:.6e}  (linear {space})", rgb[0], rgb[1], rgb[2]);
            }
            Ok(ExitCode::SUCCESS)
        }
        LutCommand::Decode(a) => {
            check(&a.conditions)?;
            if !(a.fov_deg > 0.0 && a.fov_deg < 179.0) {
                return usage(format!("--fov-deg must be between 0 and 179, got {}", a.fov_deg));
            }
            let Some(luts) = load(&a.manifest) else { return Ok(ExitCode::from(EXIT_INVALID)) };
            let c = &a.conditions;
            let camera = match a.camera {
                CameraKind::Fisheye => Camera::Fisheye,
                CameraKind::Equirect => Camera::Equirect,
                CameraKind::Pinhole => Camera::Pinhole { azimuth_deg: a.look_azimuth_deg, elevation_deg: a.look_elevation_deg, fov_deg: a.fov_deg },
            };
            let (w, h) = a.size;
            let pixels = (0..h)
                .flat_map(|y| (0..w).map(move |x| (x, y)))
                .map(|(x, y)| {
                    let xyz = camera.direction(x as f64 + 0.5, y as f64 + 0.5, w, h).map_or([0.0; 3], |d| luts.sample_xyz(c.sun_elevation_deg, c.sun_azimuth_deg, c.haziness, c.cloudiness, d));
                    PixelResult { xyz, xyz_direct: [0.0; 3], xyz_stderr: [0.0; 3], spectral: Vec::new(), spectral_stderr: Vec::new(), samples: 1, paths_cut: 0 }
                })
                .collect();
            let image = Image { width: w, height: h, pixels };
            let metadata = vec![
                ("generator".to_string(), format!("sky {} lut decode", sky::VERSION)),
                ("manifest".to_string(), a.manifest.display().to_string()),
                ("sun_elevation_deg".to_string(), c.sun_elevation_deg.to_string()),
                ("sun_azimuth_deg".to_string(), c.sun_azimuth_deg.to_string()),
                ("haziness".to_string(), c.haziness.to_string()),
                ("cloudiness".to_string(), c.cloudiness.to_string()),
                ("units".to_string(), "XYZ: CIE 1931 x 683 lm/W (Y in cd/m^2)".to_string()),
            ];
            output::write_exr(&a.out, &image, None, true, &[], &metadata).with_context(|| format!("writing {}", a.out.display()))?;
            if let Some(p) = &a.png {
                output::write_png(p, &image, a.exposure_ev, None).with_context(|| format!("writing {}", p.display()))?;
            }
            eprintln!("sky lut decode: {}x{} written to {}", w, h, a.out.display());
            Ok(ExitCode::SUCCESS)
        }
    }
}
