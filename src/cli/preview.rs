//! `sky preview`: a bake's sky decoded on the GPU (wgpu; a real GPU or
//! Mesa's lavapipe), written as linear XYZ OpenEXR and a tonemapped PNG.
//! Without the `preview` feature the command says how to get it.

use super::lut::{Conditions, ViewArgs};
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Args, Debug)]
pub struct PreviewArgs {
    /// The bake's manifest.json
    manifest: PathBuf,
    #[command(flatten)]
    conditions: Conditions,
    #[command(flatten)]
    view: ViewArgs,
    /// Image size WIDTHxHEIGHT
    #[arg(long, value_parser = super::render::parse_size, default_value = "512x512")]
    size: (usize, usize),
    /// Output folder: sky.exr (CIE XYZ, Y in cd/m^2) and sky.png (tonemapped)
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// PNG exposure, stops (0: the median luminance maps to a quarter of white, then Reinhard)
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    exposure_ev: f64,
    /// Leave out the sun's disk (drawn by default from the bake's sunlight where it covers pixel centres)
    #[arg(long)]
    no_sun_disk: bool,
    /// Leave out the landscape: ridges of mountains at 2 to 100 km, lit by the decoded sun and sky and seen through the global fog (drawn by default where the bake has fog LUTs)
    #[arg(long)]
    no_landscape: bool,
    /// How much clouds shade the air in front of the landscape, 0 (the Fog LUT) to 1 (the Shadowed Fog LUT)
    #[arg(long, default_value_t = 0.0)]
    cloud_occlusion: f64,
    /// The ridges' albedo
    #[arg(long, default_value_t = 0.15)]
    albedo: f64,
    /// Cumulus cover, 0 (no clouds) to 1: ray-marched clouds in a cloud G-buffer, lit by the decoded sun and sky
    #[arg(long, default_value_t = 0.4)]
    cumulus_cover: f64,
    /// How far the wind has carried the clouds, km east,north
    #[arg(long, value_parser = parse_km_pair, default_value = "0,0", allow_hyphen_values = true)]
    wind_offset_km: (f64, f64),
    /// The cloud G-buffer's texels per side (the talk: 768 on PS4, 1024 on PS5)
    #[arg(long, default_value_t = 256)]
    gbuffer_size: u32,
    /// Jittered ray marches averaged per G-buffer texel
    #[arg(long, default_value_t = 4)]
    cloud_samples: u32,
    /// The coverage texture, a 256x128 RGBA PNG painted with height upward (R height modulation, G low- and B mid-frequency noise weights, A ambient share); default: generated
    #[arg(long, value_name = "FILE.png")]
    coverage: Option<PathBuf>,
    /// Also write the cloud G-buffer (gbuffer.exr: opacity, distance km, sun and ambient in-scatter) and the generated coverage (coverage.png)
    #[arg(long)]
    gbuffer: bool,
    /// Machine-readable summary on stdout (adapter, files, wall and per-pass GPU times)
    #[arg(long)]
    json: bool,
}

fn parse_km_pair(s: &str) -> Result<(f64, f64), String> {
    let (a, b) = s.split_once(',').ok_or_else(|| format!("`{s}`: expected EAST,NORTH in km, e.g. 12,-3"))?;
    match (a.trim().parse::<f64>(), b.trim().parse::<f64>()) {
        (Ok(x), Ok(y)) if x.is_finite() && y.is_finite() => Ok((x, y)),
        _ => Err(format!("`{s}`: expected two numbers of km")),
    }
}

#[cfg(not(feature = "preview"))]
pub fn run(_a: PreviewArgs) -> Result<ExitCode> {
    use super::EXIT_USAGE;
    eprintln!("sky preview: this sky was built without the GPU preview (the `preview` feature, wgpu); build it with `make build` or `cargo build --release --features preview`; no output was written");
    Ok(ExitCode::from(EXIT_USAGE))
}

#[cfg(feature = "preview")]
pub fn run(a: PreviewArgs) -> Result<ExitCode> {
    use super::EXIT_INVALID;
    use anyhow::Context;
    use sky::lut::decode::{mat_mul, pixel_directions};
    use sky::preview::cloud_coverage;
    use sky::preview::clouds::{CloudSettings, Clouds};
    use sky::preview::frame::Frame;
    use sky::preview::gpu::Gpu;
    use sky::preview::landscape::{Ground, LandscapePass};
    use sky::preview::sky_pass::{SkyPass, Weather};
    use sky::render::{output, Image, PixelResult};

    super::lut::check(&a.conditions)?;
    if !(0.0..=1.0).contains(&a.cloud_occlusion) {
        return super::usage(format!("--cloud-occlusion must be from 0 to 1, got {}", a.cloud_occlusion));
    }
    if !(0.0..=1.0).contains(&a.cumulus_cover) {
        return super::usage(format!("--cumulus-cover must be from 0 to 1, got {}", a.cumulus_cover));
    }
    if !(1..=4096).contains(&a.gbuffer_size) || !(1..=1024).contains(&a.cloud_samples) {
        return super::usage("--gbuffer-size must be from 1 to 4096 and --cloud-samples from 1 to 1024");
    }
    if !(0.0..=1.0).contains(&a.albedo) {
        return super::usage(format!("--albedo must be from 0 to 1, got {}", a.albedo));
    }
    let camera = a.view.camera()?;
    let (w, h) = a.size;
    if w == 0 || h == 0 {
        return super::usage("--size must be at least 1x1");
    }
    let Some(luts) = super::lut::load(&a.manifest) else { return Ok(ExitCode::from(EXIT_INVALID)) };
    let gpu = match Gpu::new() {
        Ok(g) => g,
        Err(e) => {
            eprintln!("sky preview: {e}");
            return Ok(ExitCode::from(EXIT_INVALID));
        }
    };
    let pass = SkyPass::new(&gpu, &luts).context("preparing the sky pass")?;
    let landscape = match (a.no_landscape, luts.manifest.fog.is_some()) {
        (true, _) => None,
        (false, true) => Some(LandscapePass::new(&gpu, &luts).context("preparing the landscape")?),
        (false, false) => {
            eprintln!("sky preview: {} has no fog LUTs (baked before them): the sky alone, without the landscape", a.manifest.display());
            None
        }
    };
    let c = &a.conditions;
    let dirs = pixel_directions(&camera, w, h);
    let weather = Weather { sun_elevation_deg: c.sun_elevation_deg, sun_azimuth_deg: c.sun_azimuth_deg, haziness: c.haziness, cloudiness: c.cloudiness, sun_disk: !a.no_sun_disk };
    let ground = Ground { albedo: a.albedo, cloud_occlusion: a.cloud_occlusion };
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let clouds = match a.cumulus_cover > 0.0 {
        true => {
            let coverage = match &a.coverage {
                Some(path) => match cloud_coverage::coverage_from_png(path) {
                    Ok(c) => c,
                    Err(e) => {
                        eprintln!("sky preview: --coverage {e}");
                        return Ok(ExitCode::from(EXIT_INVALID));
                    }
                },
                None => cloud_coverage::default_coverage(),
            };
            let settings = CloudSettings { cover: a.cumulus_cover, wind_offset_km: [a.wind_offset_km.0, a.wind_offset_km.1], samples: a.cloud_samples, ..CloudSettings::default() };
            let mut c = Clouds::new(&gpu, &coverage, a.gbuffer_size, settings.seed).context("preparing the clouds")?;
            let seconds = c.compute(&gpu, &weather, &settings, 0).context("ray-marching the cloud G-buffer")?;
            if a.gbuffer {
                write_gbuffer(&gpu, &c, &a.out.join("gbuffer.exr"))?;
                if a.coverage.is_none() {
                    cloud_coverage::write_coverage_png(&a.out.join("coverage.png"), &coverage)?;
                }
            }
            Some((c, seconds))
        }
        false => None,
    };
    let mut frame = Frame::new(&gpu, &dirs)?;
    pass.encode(&gpu, &mut frame, &luts, &weather).context("decoding the sky on the GPU")?;
    if let Some((c, _)) = &clouds {
        c.encode_lighting(&gpu, &mut frame, &luts, &weather).context("lighting the clouds")?;
    }
    if let Some(l) = &landscape {
        l.encode(&gpu, &mut frame, &luts, &weather, &ground).context("drawing the landscape on the GPU")?;
    }
    let decoded = frame.finish().context("rendering on the GPU")?;
    let m = luts.manifest.colour.xyz_from_rgb;
    let pixels = decoded.rgb.iter().map(|rgb| PixelResult::from_xyz(mat_mul(&m, rgb.map(f64::from)))).collect();
    let image = Image { width: w, height: h, pixels };
    let (exr, png) = (a.out.join("sky.exr"), a.out.join("sky.png"));
    let metadata = super::lut::decoded_metadata(format!("sky {} preview ({})", sky::VERSION, gpu.describe()), &a.manifest, c);
    output::write_exr(&exr, &image, None, true, &[], &metadata).with_context(|| format!("writing {}", exr.display()))?;
    output::write_png(&png, &image, a.exposure_ev, None).with_context(|| format!("writing {}", png.display()))?;
    if a.json {
        let summary = serde_json::json!({
            "adapter": gpu.describe(),
            "files": [exr, png],
            "width": w,
            "height": h,
            "landscape": landscape.is_some(),
            "cloud_gbuffer_seconds": clouds.as_ref().map(|c| c.1),
            "wall_seconds": decoded.seconds,
            "gpu_pass_seconds": decoded.passes.iter().map(|(name, s)| (name.to_string(), serde_json::json!(s))).collect::<serde_json::Map<_, _>>(),
        });
        outln!("{summary}");
    } else {
        let passes: Vec<String> = decoded.passes.iter().map(|(name, s)| format!("{name} {:.2} ms", 1e3 * s)).collect();
        let passes = if passes.is_empty() { String::new() } else { format!(" (GPU: {})", passes.join(", ")) };
        if let Some((_, s)) = &clouds {
            eprintln!("sky preview: cloud G-buffer {0}x{0}, {1} marches a texel, in {s:.2} s", a.gbuffer_size, a.cloud_samples);
        }
        eprintln!("sky preview: {w}x{h} on {} in {:.1} ms{passes}, written to {} and {}", gpu.describe(), 1e3 * decoded.seconds, exr.display(), png.display());
    }
    Ok(ExitCode::SUCCESS)
}

/// The cloud G-buffer as an OpenEXR of four float channels: opacity,
/// distance_km, sun_inscatter, ambient_inscatter.
#[cfg(feature = "preview")]
fn write_gbuffer(gpu: &sky::preview::gpu::Gpu, clouds: &sky::preview::clouds::Clouds, path: &std::path::Path) -> Result<()> {
    use anyhow::Context;
    let texels = clouds.read_gbuffer(gpu)?;
    let n = clouds.gbuffer_size() as usize;
    let channels = exr::prelude::SpecificChannels::build().with_channel("opacity").with_channel("distance_km").with_channel("sun_inscatter").with_channel("ambient_inscatter").with_pixel_fn(
        |p: exr::math::Vec2<usize>| {
            let t = texels[p.y() * n + p.x()];
            (t[0], t[1], t[2], t[3])
        },
    );
    let image = exr::prelude::Image::from_channels((n, n), channels);
    let mut bytes = std::io::Cursor::new(Vec::new());
    exr::prelude::WritableImage::write(&image).to_buffered(&mut bytes).with_context(|| format!("encoding {}", path.display()))?;
    sky::lut::atomic::write_atomically(path, bytes.get_ref()).with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}
