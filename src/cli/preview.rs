//! `sky preview`: a bake's sky decoded on the GPU (wgpu; a real GPU or
//! Mesa's lavapipe), with the landscape through its global fog and
//! ray-marched cumulus clouds, written as linear XYZ OpenEXR and a
//! tonemapped PNG.
//! Without the `preview` feature the command says how to get it.

use super::lut::ViewArgs;
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Args, Debug)]
#[command(group(clap::ArgGroup::new("sun").required(true).args(["sun_elevation_deg", "time", "timeline"])))]
pub struct PreviewArgs {
    /// The bake's manifest.json
    manifest: PathBuf,
    /// Sun elevation above the horizon, degrees (-90 to 90)
    #[arg(long, value_name = "DEG", allow_negative_numbers = true)]
    sun_elevation_deg: Option<f64>,
    /// Sun azimuth, degrees, from +x (east) toward +y (north)
    #[arg(long, value_name = "DEG", default_value_t = 0.0, allow_negative_numbers = true, conflicts_with_all = ["time", "timeline"])]
    sun_azimuth_deg: f64,
    /// Local solar time HH:MM: the sun from --latitude-deg and --day instead of its angles
    #[arg(long, value_name = "HH:MM", value_parser = sky::look::solar::parse_time)]
    time: Option<f64>,
    /// With --time: latitude, degrees north
    #[arg(long, default_value_t = 35.0, allow_negative_numbers = true, requires = "time")]
    latitude_deg: f64,
    /// With --time: day of the year (1-366)
    #[arg(long, default_value_t = 172, requires = "time")]
    day: u32,
    /// A timeline of time, weather, cumulus cover and wind (TOML; see the README): one picture per frame
    #[arg(long, value_name = "FILE.toml", conflicts_with_all = ["frames", "haziness", "cloudiness", "cumulus_cover", "wind_offset_km"])]
    timeline: Option<PathBuf>,
    /// 0 = the clear basis sky, 1 = hazed
    #[arg(long, default_value_t = 0.0)]
    haziness: f64,
    /// 0 = sunny; 1/6 = cloudy0, ..., 1 = cloudy5 (the manifest's weather rule)
    #[arg(long, default_value_t = 0.0)]
    cloudiness: f64,
    /// Frames of the same state (the amortised cloud G-buffer goes on converging and swapping)
    #[arg(long, default_value_t = 1)]
    frames: usize,
    #[command(flatten)]
    view: ViewArgs,
    /// Image size WIDTHxHEIGHT
    #[arg(long, value_parser = super::render::parse_size, default_value = "512x512")]
    size: (usize, usize),
    /// Output folder: sky.exr (CIE XYZ, Y in cd/m^2) and sky.png (tonemapped); sky.NNNN.exr and .png for several frames
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// PNG exposure, stops (0: the median luminance maps to a quarter of white, then Reinhard); with --ev100, stops over it
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    exposure_ev: f64,
    /// PNG exposure fixed as a camera's EV100 (1.2 x 2^EV100 cd/m^2 maps to half of white after Reinhard; e.g. 15 for a sunny day, 9 at sunset) instead of each frame's own median: a sequence keeps the day's brightness changes
    #[arg(long, allow_negative_numbers = true)]
    ev100: Option<f64>,
    /// Leave out the sun's disk (drawn by default from the bake's sunlight where it covers pixel centres)
    #[arg(long)]
    no_sun_disk: bool,
    /// Leave out the landscape: ridges of mountains at 2 to 100 km, lit by the decoded sun and sky and seen through the global fog (drawn by default where the bake has fog LUTs)
    #[arg(long)]
    no_landscape: bool,
    /// Without clouds (--cumulus-cover 0): how much clouds shade the air in front of the landscape, 0 (the Fog LUT) to 1 (the Shadowed Fog LUT); with clouds their occlusion grid decides
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
    /// Jittered ray marches per G-buffer texel (per G-buffer, when amortised over frames)
    #[arg(long, default_value_t = 4)]
    cloud_samples: u32,
    /// Frames one march of every G-buffer texel is spread over (8x8 tiles; divides 64; the talk: 32 on PS5, 64 on PS4)
    #[arg(long, default_value_t = 8)]
    frames_per_sample: u32,
    /// The coverage texture, a 256x128 RGBA PNG painted with height upward (R height modulation, G low- and B mid-frequency noise weights, A ambient share); default: generated
    #[arg(long, value_name = "FILE.png")]
    coverage: Option<PathBuf>,
    /// Also write the cloud G-buffer (gbuffer.exr: opacity, distance km, sun and ambient in-scatter) and the generated coverage (coverage.png)
    #[arg(long)]
    gbuffer: bool,
    /// Machine-readable summary on stdout (adapter, files, states, wall and per-pass GPU times per frame)
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

    let Some(states) = frame_states(&a)? else { return Ok(ExitCode::from(EXIT_INVALID)) };
    check_flags(&a)?;
    let camera = a.view.camera()?;
    let (w, h) = a.size;
    if w == 0 || h == 0 {
        return super::usage("--size must be at least 1x1");
    }
    let Some(luts) = super::lut::load(&a.manifest) else { return Ok(ExitCode::from(EXIT_INVALID)) };
    let Some(mut session) = start_session(&a, &luts, &states)? else { return Ok(ExitCode::from(EXIT_INVALID)) };
    let adapter = session.gpu.describe();
    let reports = render_frames(&a, &mut session, &luts, &states, &camera, &adapter)?;
    if a.json {
        outln!("{}", serde_json::json!({ "adapter": adapter, "width": w, "height": h, "frames": reports }));
    }
    Ok(ExitCode::SUCCESS)
}

/// The states of the frames: the --timeline's, or --frames of one state
/// from the flags (checked). `None`: the timeline did not load (said on stderr).
#[cfg(feature = "preview")]
fn frame_states(a: &PreviewArgs) -> Result<Option<Vec<sky::look::timeline::FrameState>>> {
    use super::lut::Conditions;
    use sky::look::timeline::{self, FrameState};

    Ok(Some(match &a.timeline {
        Some(path) => match timeline::load(path) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("sky preview: --timeline {e}");
                return Ok(None);
            }
        },
        None => {
            let (sun_elevation_deg, sun_azimuth_deg) = match (a.sun_elevation_deg, a.time) {
                (Some(e), _) => (e, a.sun_azimuth_deg),
                (None, Some(h)) => {
                    if !(-90.0..=90.0).contains(&a.latitude_deg) || !(1..=366).contains(&a.day) {
                        return super::usage("--latitude-deg must be from -90 to 90 and --day from 1 to 366");
                    }
                    sky::look::solar::sun_position_deg(a.latitude_deg, a.day, h)
                }
                (None, None) => return super::usage("give --sun-elevation-deg, --time or --timeline"),
            };
            let c = Conditions { sun_elevation_deg, sun_azimuth_deg, haziness: a.haziness, cloudiness: a.cloudiness };
            super::lut::check(&c)?;
            if !(0.0..=1.0).contains(&a.cumulus_cover) {
                return super::usage(format!("--cumulus-cover must be from 0 to 1, got {}", a.cumulus_cover));
            }
            if a.frames == 0 {
                return super::usage("--frames must be at least 1");
            }
            let state = FrameState {
                frame: 0,
                hours: a.time,
                sun_elevation_deg,
                sun_azimuth_deg,
                haziness: a.haziness,
                cloudiness: a.cloudiness,
                cumulus_cover: a.cumulus_cover,
                wind_offset_km: [a.wind_offset_km.0, a.wind_offset_km.1],
            };
            (0..a.frames).map(|frame| FrameState { frame, ..state.clone() }).collect()
        }
    }))
}

/// The flags of the picture and the clouds: their ranges.
#[cfg(feature = "preview")]
fn check_flags(a: &PreviewArgs) -> Result<()> {
    if !a.exposure_ev.is_finite() || a.ev100.is_some_and(|e| !(-20.0..=30.0).contains(&e)) {
        return super::usage("--exposure-ev must be a number and --ev100 from -20 to 30");
    }
    if !(0.0..=1.0).contains(&a.cloud_occlusion) {
        return super::usage(format!("--cloud-occlusion must be from 0 to 1, got {}", a.cloud_occlusion));
    }
    if !(0.0..=1.0).contains(&a.albedo) {
        return super::usage(format!("--albedo must be from 0 to 1, got {}", a.albedo));
    }
    if !(1..=4096).contains(&a.gbuffer_size) || !(1..=1024).contains(&a.cloud_samples) {
        return super::usage("--gbuffer-size must be from 1 to 4096 and --cloud-samples from 1 to 1024");
    }
    if a.frames_per_sample == 0 || 64 % a.frames_per_sample != 0 {
        return super::usage(format!(
            "--frames-per-sample must divide 64 (1, 2, 4, 8, 16, 32 or 64), got {}",
            a.frames_per_sample
        ));
    }
    Ok(())
}

/// The preview on the GPU: the landscape where the bake has fog LUTs, the
/// clouds where a state has cumulus cover (their generated coverage written
/// with --gbuffer), the output folder created. `None`: no GPU, or the
/// --coverage did not load (said on stderr).
#[cfg(feature = "preview")]
fn start_session<'l>(
    a: &PreviewArgs,
    luts: &'l sky::lut::decode::Luts,
    states: &[sky::look::timeline::FrameState],
) -> Result<Option<sky::preview::session::PreviewSession<'l>>> {
    use anyhow::Context;
    use sky::preview::cloud_coverage;
    use sky::preview::clouds::Amortisation;
    use sky::preview::gpu::Gpu;
    use sky::preview::landscape::Ground;
    use sky::preview::session::{CloudOptions, PreviewOptions, PreviewSession};

    let gpu = match Gpu::new() {
        Ok(g) => g,
        Err(e) => {
            eprintln!("sky preview: {e}");
            return Ok(None);
        }
    };
    let ground = match (a.no_landscape, luts.manifest.fog.is_some()) {
        (true, _) => None,
        (false, true) => Some(Ground { albedo: a.albedo, cloud_occlusion: a.cloud_occlusion }),
        (false, false) => {
            eprintln!(
                "sky preview: {} has no fog LUTs (baked before them): the sky alone, without the landscape",
                a.manifest.display()
            );
            None
        }
    };
    let any_clouds = states.iter().any(|s| s.cumulus_cover > 0.0);
    let coverage = match (&a.coverage, any_clouds) {
        (_, false) => None,
        (Some(path), true) => match cloud_coverage::coverage_from_png(path) {
            Ok(c) => Some(c),
            Err(e) => {
                eprintln!("sky preview: --coverage {e}");
                return Ok(None);
            }
        },
        (None, true) => Some(cloud_coverage::default_coverage()),
    };
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    if let (true, None, Some(c)) = (a.gbuffer, &a.coverage, &coverage) {
        cloud_coverage::write_coverage_png(&a.out.join("coverage.png"), c)?;
    }
    let schedule =
        Amortisation { frames_per_sample: a.frames_per_sample, blend_frames: a.frames_per_sample * a.cloud_samples };
    let clouds = coverage.map(|coverage| CloudOptions {
        coverage,
        gbuffer_size: a.gbuffer_size,
        samples: a.cloud_samples,
        schedule,
    });
    let options = PreviewOptions { sun_disk: !a.no_sun_disk, ground, clouds };
    let session = PreviewSession::new(gpu, luts, options).context("preparing the preview on the GPU")?;
    Ok(Some(session))
}

/// Renders every state on the GPU and writes its pictures (and cloud
/// G-buffers with --gbuffer), a line per frame on stderr without --json;
/// returns the frames' JSON reports.
#[cfg(feature = "preview")]
fn render_frames(
    a: &PreviewArgs,
    session: &mut sky::preview::session::PreviewSession,
    luts: &sky::lut::decode::Luts,
    states: &[sky::look::timeline::FrameState],
    camera: &sky::directions::camera::Camera,
    adapter: &str,
) -> Result<Vec<serde_json::Value>> {
    use super::lut::Conditions;
    use anyhow::Context;
    use sky::colour::apply as mat_mul;
    use sky::render::{output, Image, PixelResult};

    let (w, h) = a.size;
    let m = luts.manifest.colour.xyz_from_rgb;
    let numbered = states.len() > 1;
    let name = |stem: &str, frame: usize, ext: &str| {
        if numbered {
            a.out.join(format!("{stem}.{frame:04}.{ext}"))
        } else {
            a.out.join(format!("{stem}.{ext}"))
        }
    };
    let started = std::time::Instant::now();
    let mut reports = Vec::new();
    for (k, state) in states.iter().enumerate() {
        let out = session.render(state, camera, w, h).with_context(|| format!("rendering frame {k} on the GPU"))?;
        let pixels =
            out.rendered.rgb.iter().map(|rgb| PixelResult::from_xyz(mat_mul(&m, rgb.map(f64::from)))).collect();
        let image = Image { width: w, height: h, pixels };
        let (exr, png) = (name("sky", k, "exr"), name("sky", k, "png"));
        let c = Conditions {
            sun_elevation_deg: state.sun_elevation_deg,
            sun_azimuth_deg: state.sun_azimuth_deg,
            haziness: state.haziness,
            cloudiness: state.cloudiness,
        };
        let mut metadata =
            super::lut::decoded_metadata(format!("sky {} preview ({adapter})", sky::VERSION), &a.manifest, &c);
        metadata.push(("cumulus_cover".into(), state.cumulus_cover.to_string()));
        metadata.push(("frame".into(), k.to_string()));
        output::write_exr(&exr, &image, None, true, &[], &metadata)
            .with_context(|| format!("writing {}", exr.display()))?;
        match a.ev100 {
            Some(ev) => output::write_png_scaled(
                &png,
                &image,
                2f64.powf(a.exposure_ev) / output::saturation_luminance(ev),
                None,
            ),
            None => output::write_png(&png, &image, a.exposure_ev, None),
        }
        .with_context(|| format!("writing {}", png.display()))?;
        let mut files = vec![exr, png];
        if a.gbuffer {
            if let Some(clouds) = session.clouds() {
                let path = name("gbuffer", k, "exr");
                write_gbuffer(&session.gpu, clouds, &path)?;
                files.push(path);
            }
        }
        let passes: serde_json::Map<String, serde_json::Value> =
            out.rendered.passes.iter().map(|(n, s)| (n.to_string(), serde_json::json!(s))).collect();
        if !a.json {
            let gpu_ms: Vec<String> =
                out.rendered.passes.iter().map(|(n, s)| format!("{n} {:.2} ms", 1e3 * s)).collect();
            let gpu_ms = if gpu_ms.is_empty() { String::new() } else { format!("; GPU: {}", gpu_ms.join(", ")) };
            let clock = state.hours.map_or(String::new(), |h| {
                format!(" {:02}:{:02},", h as u32, ((h.fract() * 60.0).round() as u32).min(59))
            });
            let done = k + 1;
            let eta = started.elapsed().as_secs_f64() / done as f64 * (states.len() - done) as f64;
            let eta = if done < states.len() { format!(", ETA {eta:.0} s") } else { String::new() };
            eprintln!(
                "sky preview: frame {done}/{}{clock} sun {:.1} deg up, clouds {:.2} s, picture {:.1} ms{gpu_ms}{eta}: {}",
                states.len(),
                state.sun_elevation_deg,
                out.cloud_seconds,
                1e3 * out.rendered.seconds,
                files[1].display()
            );
        }
        reports.push(serde_json::json!({
            "frame": k,
            "state": state,
            "files": files,
            "wall_seconds": out.rendered.seconds,
            "cloud_seconds": out.cloud_seconds,
            "gbuffer_swapped": out.gbuffer_swapped,
            "gpu_pass_seconds": passes,
        }));
    }
    Ok(reports)
}

/// The cloud G-buffer as an OpenEXR of four float channels: opacity,
/// distance_km, sun_inscatter, ambient_inscatter.
#[cfg(feature = "preview")]
fn write_gbuffer(
    gpu: &sky::preview::gpu::Gpu,
    clouds: &sky::preview::clouds::Clouds,
    path: &std::path::Path,
) -> Result<()> {
    use anyhow::Context;
    let texels = clouds.read_gbuffer(gpu)?;
    let n = clouds.gbuffer_size() as usize;
    let channels = exr::prelude::SpecificChannels::build()
        .with_channel("opacity")
        .with_channel("distance_km")
        .with_channel("sun_inscatter")
        .with_channel("ambient_inscatter")
        .with_pixel_fn(|p: exr::math::Vec2<usize>| {
            let t = texels[p.y() * n + p.x()];
            (t[0], t[1], t[2], t[3])
        });
    let image = exr::prelude::Image::from_channels((n, n), channels);
    let mut bytes = std::io::Cursor::new(Vec::new());
    exr::prelude::WritableImage::write(&image)
        .to_buffered(&mut bytes)
        .with_context(|| format!("encoding {}", path.display()))?;
    sky::atomic::write_atomically(path, bytes.get_ref()).with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}
