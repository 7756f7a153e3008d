//! `sky lut sample` and `sky lut decode`: the reference decoder
//! (`sky::lut::decode`) on the command line.

use super::{usage, EXIT_INVALID};
use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use sky::directions::camera::{direction_deg, Camera};
use sky::lut::decode::Luts;
use sky::render::{output, Image, PixelResult};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Subcommand, Debug)]
pub enum LutCommand {
    /// The decoded sky toward one direction: XYZ and RGB
    #[command(
        after_help = "Example:\n  sky lut sample luts/manifest.json --sun-elevation-deg 12 --haziness 0.3 --cloudiness 0 --direction 60,180"
    )]
    Sample(SampleArgs),
    /// A whole sky decoded from the LUTs, to OpenEXR (XYZ) and PNG
    #[command(
        after_help = "Example:\n  sky lut decode luts/manifest.json --sun-elevation-deg 12 --camera fisheye --size 256x256 --out sky.exr --png sky.png"
    )]
    Decode(DecodeArgs),
    /// The decoder against direct renders: luminance and colour error, PSNR, the error's sources, the twilight curve
    #[command(
        after_help = "Example:\n  sky lut verify luts/manifest.json --bake bakes/basis-skies.toml --plot luts/verify\n\nRenders references at the sun elevations between slices 41.7, 23.3, 8.2, 3.1, 0.4, -2.7, -7.5 degrees and at six slice centres, over a lattice of directions above the horizon."
    )]
    Verify(super::lut_verify::VerifyArgs),
    /// What the LUT mappings lose by interpolating, on an atmosphere's noise-free single-scattering sky; the threshold between the two direction mappings, measured
    #[command(
        after_help = "Example:\n  sky lut interpolation atmospheres/clear.toml --size 32x128\n\nBakes the single-scattering sky (no noise) in memory through the LUT mappings and decodes it with the reference decoder: direction interpolation at every slice from 60 deg sun zenith to the horizon in both direction mappings, slice interpolation between slices, and the twilight's largest step."
    )]
    Interpolation(super::lut_interpolation::InterpolationArgs),
    /// The talk's global-fog depth falloff fitted to reference fog renders of an atmosphere: a and p, the fit's error against the depth-free LUT's, a plot
    #[command(
        after_help = "Example:\n  sky lut fog-falloff atmospheres/clear.toml --ceiling-km 3 --plot out/fog\n\nRenders the fog (the light the air below the ceiling scatters toward the camera in front of a black object) toward 7 elevations x 3 azimuths at 8 depths from 0.002 to 1 of the distance to the ceiling, for each sun, and fits Fog(x) = LUT (1 - exp(-a theta^p x)) / (1 - exp(-a theta^p)) in relative error."
    )]
    FogFalloff(super::lut_fog::FogFalloffArgs),
    /// A bake's manifest and files against the sizes and SHA-256 digests the manifest records, and nothing else: exit 0 intact, 1 with the first missing, truncated or altered file named
    #[command(
        after_help = "Example:\n  sky lut check luts/manifest.json && cp -r luts game/assets/sky\n\nPrints each file's SHA-256, name and size (the first two as sha256sum prints them). Every other sky lut command and sky preview make the same check before they read a bake."
    )]
    Check(super::lut_check::CheckArgs),
}

/// The weather and the sun, as a runtime gives them.
#[derive(Args, Debug, Clone)]
pub struct Conditions {
    /// Sun elevation above the horizon, degrees (-90 to 90; below -10 the last slice holds)
    #[arg(long, value_name = "DEG", allow_negative_numbers = true)]
    pub(super) sun_elevation_deg: f64,
    /// Sun azimuth, degrees
    #[arg(long, value_name = "DEG", default_value_t = 0.0, allow_negative_numbers = true)]
    pub(super) sun_azimuth_deg: f64,
    /// 0 = the clear basis sky, 1 = hazed
    #[arg(long, default_value_t = 0.0)]
    pub(super) haziness: f64,
    /// 0 = sunny; 1/6 = cloudy0, ..., 1 = cloudy5 (the manifest's weather rule)
    #[arg(long, default_value_t = 0.0)]
    pub(super) cloudiness: f64,
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
    /// Also the global fog in front of an object this far along the view, metres (bakes with fog LUTs)
    #[arg(long, value_name = "M")]
    depth_m: Option<f64>,
    /// With --depth-m: how much clouds shade the air, 0 (sunlit: the Fog LUT) to 1 (the Shadowed Fog LUT)
    #[arg(long, default_value_t = 0.0, requires = "depth_m")]
    cloud_occlusion: f64,
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

/// The OpenEXR header of a sky decoded from `manifest` under `c`.
pub(super) fn decoded_metadata(generator: String, manifest: &std::path::Path, c: &Conditions) -> Vec<(String, String)> {
    vec![
        ("generator".to_string(), generator),
        ("manifest".to_string(), manifest.display().to_string()),
        ("sun_elevation_deg".to_string(), c.sun_elevation_deg.to_string()),
        ("sun_azimuth_deg".to_string(), c.sun_azimuth_deg.to_string()),
        ("haziness".to_string(), c.haziness.to_string()),
        ("cloudiness".to_string(), c.cloudiness.to_string()),
        ("units".to_string(), "XYZ: CIE 1931 x 683 lm/W (Y in cd/m^2)".to_string()),
    ]
}

/// The camera of a decoded image (`sky lut decode`, `sky preview`).
#[derive(Args, Debug, Clone)]
pub(super) struct ViewArgs {
    #[arg(long, value_enum, default_value = "fisheye")]
    camera: CameraKind,
    /// Pinhole: view azimuth, degrees
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    look_azimuth_deg: f64,
    /// Pinhole: view elevation, degrees
    #[arg(long, default_value_t = 10.0, allow_negative_numbers = true)]
    look_elevation_deg: f64,
    /// Pinhole: horizontal field of view, degrees
    #[arg(long, default_value_t = 90.0)]
    fov_deg: f64,
}

impl ViewArgs {
    /// The camera, or a usage error naming the flag.
    pub(super) fn camera(&self) -> Result<Camera> {
        if !(self.fov_deg > 0.0 && self.fov_deg < 179.0) {
            return usage(format!("--fov-deg must be between 0 and 179, got {}", self.fov_deg));
        }
        Ok(match self.camera {
            CameraKind::Fisheye => Camera::Fisheye,
            CameraKind::Equirect => Camera::Equirect,
            CameraKind::Pinhole => Camera::Pinhole {
                azimuth_deg: self.look_azimuth_deg,
                elevation_deg: self.look_elevation_deg,
                fov_deg: self.fov_deg,
            },
        })
    }
}

#[derive(Args, Debug)]
pub struct DecodeArgs {
    /// The bake's manifest.json
    manifest: PathBuf,
    #[command(flatten)]
    conditions: Conditions,
    #[command(flatten)]
    view: ViewArgs,
    /// Image size WIDTHxHEIGHT
    #[arg(long, value_parser = super::render::parse_size, default_value = "256x256")]
    size: (usize, usize),
    /// The OpenEXR to write (X, Y, Z; Y in cd/m^2)
    #[arg(long, value_name = "FILE.exr")]
    out: PathBuf,
    /// Also a tonemapped PNG
    #[arg(long, value_name = "FILE.png")]
    png: Option<PathBuf>,
    /// PNG exposure, stops
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    exposure_ev: f64,
    /// Add the sun's disk from the bake's transmittance file (the sky
    /// textures leave it out): its radiance where it covers pixel centres,
    /// else its irradiance in the pixel nearest it
    #[arg(long)]
    sun_disk: bool,
    /// Put ridges of mountains at 2 to 100 km in front of the sky, lit by the decoded sun and sky and seen through the decoded global fog (the talk's blue mountains; bakes with fog LUTs)
    #[arg(long)]
    landscape: bool,
    /// With --landscape: how much clouds shade the air, 0 (the Fog LUT) to 1 (the Shadowed Fog LUT)
    #[arg(long, default_value_t = 0.0, requires = "landscape")]
    cloud_occlusion: f64,
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

pub(super) fn check(c: &Conditions) -> Result<()> {
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

pub(super) fn load(manifest: &std::path::Path) -> Option<Luts> {
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
        LutCommand::Sample(a) => sample(a),
        LutCommand::Verify(a) => super::lut_verify::run(a),
        LutCommand::Interpolation(a) => super::lut_interpolation::run(a),
        LutCommand::FogFalloff(a) => super::lut_fog::run(a),
        LutCommand::Decode(a) => decode(a),
        LutCommand::Check(a) => super::lut_check::run(a),
    }
}

/// `sky lut sample` (see its help).
fn sample(a: SampleArgs) -> Result<ExitCode> {
    check(&a.conditions)?;
    let Some(luts) = load(&a.manifest) else { return Ok(ExitCode::from(EXIT_INVALID)) };
    let c = &a.conditions;
    let d = direction_deg(a.direction.0, a.direction.1);
    let rgb = luts.sample(c.sun_elevation_deg, c.sun_azimuth_deg, c.haziness, c.cloudiness, d);
    let xyz = luts.sample_xyz(c.sun_elevation_deg, c.sun_azimuth_deg, c.haziness, c.cloudiness, d);
    let space = &luts.manifest.colour.space;
    // The sun the sky texture leaves out (bakes with a transmittance file).
    let sun = luts.sun(c.sun_elevation_deg, c.haziness, c.cloudiness);
    let ambient = luts.ambient(c.sun_elevation_deg, c.haziness, c.cloudiness);
    if let Some(depth) = a.depth_m {
        if !(depth >= 0.0 && depth.is_finite() && (0.0..=1.0).contains(&a.cloud_occlusion)) {
            return usage(format!(
                "--depth-m must be a distance of 0 m or more and --cloud-occlusion between 0 and 1, got {depth} and {}",
                a.cloud_occlusion
            ));
        }
        if luts.fog.is_none() {
            eprintln!("{}: this bake has no fog LUTs (bake it again with this version of sky)", a.manifest.display());
            return Ok(ExitCode::from(EXIT_INVALID));
        }
    }
    let fog = a.depth_m.and_then(|m| {
        luts.fog(c.sun_elevation_deg, c.sun_azimuth_deg, c.haziness, c.cloudiness, d, m / 1000.0, a.cloud_occlusion)
    });
    if a.json {
        outln!(
            "{}",
            serde_json::json!({ "xyz": xyz, "rgb": rgb, "colour_space": space, "units": "cd/m^2 (Y)", "sun": sun, "ambient": ambient, "fog": fog })
        );
    } else {
        outln!("XYZ {:.6e} {:.6e} {:.6e}  (Y in cd/m^2)", xyz[0], xyz[1], xyz[2]);
        outln!("RGB {:.6e} {:.6e} {:.6e}  (linear {space})", rgb[0], rgb[1], rgb[2]);
        if let Some(s) = sun {
            let (e, l) = (s.irradiance_rgb, s.disk_radiance_rgb);
            outln!(
                "sun irradiance RGB {:.6e} {:.6e} {:.6e}  (on a surface facing it; lux-like units)",
                e[0],
                e[1],
                e[2]
            );
            outln!(
                "sun disk radiance RGB {:.6e} {:.6e} {:.6e}  (a disk {:.4} deg across)",
                l[0],
                l[1],
                l[2],
                s.angular_diameter_deg
            );
        }
        if let Some(am) = ambient {
            let (e, l) = (am.irradiance_up, am.mean_radiance);
            outln!(
                "sky irradiance on an upward surface RGB {:.6e} {:.6e} {:.6e}; mean sky radiance {:.6e} {:.6e} {:.6e}",
                e[0],
                e[1],
                e[2],
                l[0],
                l[1],
                l[2]
            );
        }
        if let Some(f) = fog {
            let (l, t) = (f.inscatter_rgb, f.attenuation_rgb);
            outln!(
                "fog in front of an object at {} m ({:.4} of the way to the fog's ceiling): in-scattered RGB {:.6e} {:.6e} {:.6e}, attenuation RGB {:.6} {:.6} {:.6}",
                a.depth_m.unwrap_or(0.0),
                f.normalised_depth,
                l[0],
                l[1],
                l[2],
                t[0],
                t[1],
                t[2]
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// `sky lut decode` (see its help).
fn decode(a: DecodeArgs) -> Result<ExitCode> {
    check(&a.conditions)?;
    let camera = a.view.camera()?;
    let Some(luts) = load(&a.manifest) else { return Ok(ExitCode::from(EXIT_INVALID)) };
    let c = &a.conditions;
    let (w, h) = a.size;
    if a.landscape {
        if !(0.0..=1.0).contains(&a.cloud_occlusion) {
            return usage(format!("--cloud-occlusion must be between 0 and 1, got {}", a.cloud_occlusion));
        }
        if a.sun_disk {
            return usage("--landscape draws no sun disk; leave out --sun-disk");
        }
    }
    let decoded = if a.landscape {
        sky::lut::landscape::decode_landscape(
            &luts,
            &camera,
            w,
            h,
            c.sun_elevation_deg,
            c.sun_azimuth_deg,
            c.haziness,
            c.cloudiness,
            a.cloud_occlusion,
            0.15,
        )
    } else {
        luts.decode_image(&camera, w, h, c.sun_elevation_deg, c.sun_azimuth_deg, c.haziness, c.cloudiness, a.sun_disk)
    };
    if a.landscape && decoded.is_none() {
        eprintln!(
            "sky lut decode: --landscape: {} has no fog LUTs or no sun; bake it again with this version of sky",
            a.manifest.display()
        );
        return Ok(ExitCode::from(EXIT_INVALID));
    }
    let Some(xyz) = decoded else {
        eprintln!(
            "sky lut decode: --sun-disk: {} has no sun (a bake made before the transmittance file); bake it again",
            a.manifest.display()
        );
        return Ok(ExitCode::from(EXIT_INVALID));
    };
    let pixels = xyz.into_iter().map(PixelResult::from_xyz).collect();
    let image = Image { width: w, height: h, pixels };
    let metadata = decoded_metadata(format!("sky {} lut decode", sky::VERSION), &a.manifest, c);
    output::write_exr(&a.out, &image, None, true, &[], &metadata)
        .with_context(|| format!("writing {}", a.out.display()))?;
    if let Some(p) = &a.png {
        output::write_png(p, &image, a.exposure_ev, None).with_context(|| format!("writing {}", p.display()))?;
    }
    eprintln!("sky lut decode: {}x{} written to {}", w, h, a.out.display());
    Ok(ExitCode::SUCCESS)
}
