//! `sky bench preview`: the preview's GPU passes timed by wall clock over
//! a few rounds, the LUT sky pass beside a plain textured full-screen pass
//! in the same rounds, reported as medians and a ratio; and the cloud
//! G-buffer, at once and per amortised frame.
//!
//! Wall clock, not the GPU's timestamp queries: on lavapipe (Mesa 22, the
//! machine this project measures on) the timestamps around a pass did not
//! hold its work: a frame of four plain passes took 200 ms more than an
//! empty one while its passes' timestamps added up to 40 ms.

use anyhow::Result;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(clap::Args)]
pub struct BenchPreviewArgs {
    /// The bake's manifest.json
    pub manifest: PathBuf,
    /// Picture size WIDTHxHEIGHT (a pinhole of 90 degrees looking 10 degrees up: sky and landscape)
    #[arg(long, value_parser = super::render::parse_size, default_value = "1920x1080")]
    pub size: (usize, usize),
    /// Rounds timed (after one to warm up), each a frame per pass with the pass recorded several times; the medians are reported
    #[arg(long, default_value_t = 10)]
    pub frames: usize,
    /// Machine-readable output
    #[arg(long)]
    pub json: bool,
}

/// The passes the benchmark times.
#[cfg(feature = "preview")]
#[derive(Clone, Copy, PartialEq)]
enum Pass {
    Plain,
    Composition,
    Sky,
    CloudLighting,
    Landscape,
}

/// The passes, their names in the report, and the times each is recorded
/// in its timed frame (enough for the frame's own cost, about 0.3 s at
/// 1920 x 1080 on lavapipe, to cancel: the empty frame's spread is 10 %).
#[cfg(feature = "preview")]
const PASSES: [(Pass, &str, usize); 5] = [
    (Pass::Plain, "plain texture", 32),
    (Pass::Composition, "sky composition", 64),
    (Pass::Sky, "sky", 32),
    (Pass::CloudLighting, "cloud lighting", 4),
    (Pass::Landscape, "terrain and fog", 2),
];

#[cfg(not(feature = "preview"))]
pub fn run(_a: BenchPreviewArgs) -> Result<ExitCode> {
    eprintln!("sky bench preview: this sky was built without the GPU preview (the `preview` feature); build it with `make build`");
    Ok(ExitCode::from(super::EXIT_USAGE))
}

#[cfg(feature = "preview")]
pub fn run(a: BenchPreviewArgs) -> Result<ExitCode> {
    use super::{usage, EXIT_INVALID};
    use anyhow::Context;
    use sky::directions::camera::Camera;
    use sky::lut::decode::pixel_directions;
    use sky::preview::cloud_coverage::default_coverage;
    use sky::preview::clouds::{Amortisation, CloudSettings, Clouds};
    use sky::preview::frame::Frame;
    use sky::preview::gpu::Gpu;
    use sky::preview::landscape::{Ground, LandscapePass};
    use sky::preview::plain_pass::PlainPass;
    use sky::preview::sky_pass::{SkyPass, Weather};

    let (w, h) = a.size;
    if w == 0 || h == 0 || a.frames == 0 {
        return usage("--size must be at least 1x1 and --frames at least 1");
    }
    let Some(luts) = super::lut::load(&a.manifest) else { return Ok(ExitCode::from(EXIT_INVALID)) };
    let gpu = match Gpu::new() {
        Ok(g) => g,
        Err(e) => {
            eprintln!("sky bench preview: {e}");
            return Ok(ExitCode::from(EXIT_INVALID));
        }
    };
    let sky = SkyPass::new(&gpu, &luts).context("preparing the sky pass")?;
    let plain = PlainPass::new(&gpu, sky.array(0).expect("SkyPass::new checked a sky").clone())
        .context("preparing the plain pass")?;
    let landscape = match luts.manifest.fog {
        Some(_) => Some(LandscapePass::new(&gpu, &luts).context("preparing the landscape")?),
        None => None,
    };
    let dirs = pixel_directions(&Camera::Pinhole { azimuth_deg: 0.0, elevation_deg: 10.0, fov_deg: 90.0 }, w, h);
    // Three basis skies blended, the most the sky pass reads.
    let weather =
        Weather { sun_elevation_deg: 20.0, sun_azimuth_deg: 30.0, haziness: 0.3, cloudiness: 0.1, sun_disk: true };
    let ground = Ground { albedo: 0.15, cloud_occlusion: 0.5 };
    // The clouds as `sky preview` makes them by default: a 256^2 G-buffer,
    // 4 marches a texel, each spread over 8 frames.
    let mut clouds = Clouds::new(&gpu, &default_coverage(), 256, 1).context("preparing the clouds")?;
    let settings = CloudSettings { cover: 0.5, ..CloudSettings::default() };
    let schedule = Amortisation { frames_per_sample: 8, blend_frames: 32 };
    let whole = clouds.compute(&gpu, &weather, &settings, 0)?;
    // Each round: an empty frame, then per pass a frame with it recorded a
    // few times; a pass's time is its frame's wall time less the empty
    // one's, over those times (the uploads, the readback and the submission
    // cancel). The composition, whose work does not depend on the picture,
    // in frames of one direction.
    let one = [None];
    let mut rounds: Vec<[f64; PASSES.len()]> = Vec::new();
    let mut steps = Vec::new();
    for _ in 0..=a.frames {
        let start = std::time::Instant::now();
        clouds.step(&gpu, &weather, &settings, &schedule)?;
        steps.push(start.elapsed().as_secs_f64());
        let wall = |pass: Option<Pass>, repeats: usize, dirs: &[Option<glam::DVec3>]| -> Result<f64> {
            let mut frame = Frame::new(&gpu, dirs)?;
            let start = std::time::Instant::now();
            for _ in 0..repeats {
                match pass {
                    Some(Pass::Plain) => plain.encode(&gpu, &mut frame)?,
                    Some(Pass::Composition) => sky.compose(&gpu, &mut frame, &luts, &weather)?,
                    Some(Pass::Sky) => sky.encode(&gpu, &mut frame, &luts, &weather)?,
                    Some(Pass::CloudLighting) => clouds.encode_lighting(&gpu, &mut frame, &luts, &weather)?,
                    Some(Pass::Landscape) => {
                        if let Some(l) = &landscape {
                            l.encode(&gpu, &mut frame, &luts, &weather, &ground, None)?
                        }
                    }
                    None => {}
                }
            }
            frame.finish()?;
            Ok(start.elapsed().as_secs_f64())
        };
        let (empty, empty_one) = (wall(None, 0, &dirs)?, wall(None, 0, &one)?);
        let mut round = [0.0; PASSES.len()];
        for (k, &(pass, _, repeats)) in PASSES.iter().enumerate() {
            round[k] = match pass {
                // A bake without fog has no landscape: nothing to time.
                Pass::Landscape if landscape.is_none() => f64::NAN,
                Pass::Composition => (wall(Some(pass), repeats, &one)? - empty_one) / repeats as f64,
                _ => (wall(Some(pass), repeats, &dirs)? - empty) / repeats as f64,
            };
        }
        rounds.push(round);
    }
    // The first round warms up.
    let median = |k: usize| {
        let mut v: Vec<f64> = rounds[1..].iter().map(|r| r[k]).collect();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let medians: Vec<(&str, f64)> = PASSES.iter().enumerate().map(|(k, p)| (p.1, median(k))).collect();

    // The ratio round by round (the two passes' frames run next to each
    // other, so a slow spell of the machine slows both), its median and
    // quartiles.
    let index = |pass: Pass| PASSES.iter().position(|p| p.0 == pass).expect("a timed pass");
    let mut ratios: Vec<f64> = rounds[1..].iter().map(|r| r[index(Pass::Sky)] / r[index(Pass::Plain)]).collect();
    ratios.sort_by(f64::total_cmp);
    let quantile = |q: f64| ratios[((ratios.len() - 1) as f64 * q).round() as usize];
    let (ratio, ratio_low, ratio_high) = (quantile(0.5), quantile(0.25), quantile(0.75));
    steps.remove(0);
    steps.sort_by(f64::total_cmp);
    let step = steps[steps.len() / 2];
    let error = composition_error(&gpu, &sky, &luts)?;
    if a.json {
        let passes: serde_json::Map<String, serde_json::Value> =
            medians.iter().filter(|m| !m.1.is_nan()).map(|(n, s)| (n.to_string(), serde_json::json!(s))).collect();
        outln!(
            "{}",
            serde_json::json!({ "adapter": gpu.describe(), "width": w, "height": h, "frames": a.frames, "median_pass_seconds": passes, "sky_over_plain": ratio, "sky_over_plain_quartiles": [ratio_low, ratio_high], "sky_against_cpu_decoder": { "values": error.count, "median": error.median, "p99": error.p99, "max": error.max }, "cloud_gbuffer_whole_seconds": whole, "cloud_gbuffer_step_seconds": step })
        );
    } else {
        outln!("{w}x{h} on {}, median of {} rounds (wall time, each pass recorded several times in a frame, less an empty frame):", gpu.describe(), a.frames);
        for (n, s) in medians.iter().filter(|m| !m.1.is_nan()) {
            outln!("  {n:<16} {:>8.2} ms", 1e3 * s);
        }
        outln!("  the LUT sky pass takes {ratio:.2} times the plain textured pass (median of the rounds' ratios; quartiles {ratio_low:.2} and {ratio_high:.2}); the composition runs once per change of sun elevation or weather");
        outln!(
            "the sky pass against the CPU decoder, luminance, {} values ({} suns from 63 to -10 degrees, {} weathers): median {:.3} %, 99th percentile {:.3} %, largest {:.1} %",
            error.count,
            ERROR_SUNS_DEG.len(),
            ERROR_WEATHERS.len(),
            100.0 * error.median,
            100.0 * error.p99,
            100.0 * error.max
        );
        outln!("cloud G-buffer 256x256, 4 marches a texel: {:.2} s at once; amortised over 8 frames a march, {:.1} ms a frame (wall time, median)", whole, 1e3 * step);
    }
    Ok(ExitCode::SUCCESS)
}

/// The suns (elevation, degrees) and weathers (haziness, cloudiness) of
/// the accuracy check: slice centres and between, through the switch of
/// mappings and twilight; one to three basis skies, sunny and cloudy.
#[cfg(feature = "preview")]
const ERROR_SUNS_DEG: [f64; 14] = [63.1, 41.7, 23.3, 8.2, 5.1, 3.1, 2.6, 2.4, 0.4, -0.9, -2.7, -4.0, -7.5, -9.95];
#[cfg(feature = "preview")]
const ERROR_WEATHERS: [(f64, f64); 6] = [(0.0, 0.0), (1.0, 0.0), (0.3, 0.1), (0.6, 0.25), (0.0, 0.3), (0.0, 0.7)];

/// The relative differences of the sky pass's luminance from the CPU
/// decoder's.
#[cfg(feature = "preview")]
struct DecodeError {
    count: usize,
    median: f64,
    p99: f64,
    max: f64,
}

/// What the composition and the one filtered read cost in accuracy: the
/// sky pass's luminance against the CPU reference decoder's
/// (`Luts::sample`) toward 61 x 48 directions (zenith angle 0.3 to 90.3
/// degrees every 1.5, the whole azimuth every 7.5) for every sun and
/// weather above.
#[cfg(feature = "preview")]
fn composition_error(
    gpu: &sky::preview::gpu::Gpu,
    sky: &sky::preview::sky_pass::SkyPass,
    luts: &sky::lut::decode::Luts,
) -> Result<DecodeError> {
    use sky::directions::camera::direction_deg;
    use sky::preview::sky_pass::Weather;
    let dirs: Vec<Option<glam::DVec3>> = (0..=60)
        .flat_map(|i| (0..48).map(move |j| Some(direction_deg(0.3 + 1.5 * i as f64, 7.5 * j as f64 + 0.1))))
        .collect();
    let luminance = |rgb: [f64; 3]| sky::colour::apply(&luts.manifest.colour.xyz_from_rgb, rgb)[1];
    let mut relative = Vec::new();
    for &e in &ERROR_SUNS_DEG {
        for &(haziness, cloudiness) in &ERROR_WEATHERS {
            let weather = Weather { sun_elevation_deg: e, sun_azimuth_deg: 7.0, haziness, cloudiness, sun_disk: false };
            let rgb = sky.decode(gpu, luts, &weather, &dirs)?.rgb;
            for (g, d) in rgb.iter().zip(dirs.iter().flatten()) {
                let cpu = luminance(luts.sample(e, 7.0, haziness, cloudiness, *d));
                if cpu > 0.0 {
                    relative.push((luminance(g.map(f64::from)) - cpu).abs() / cpu);
                }
            }
        }
    }
    relative.sort_by(f64::total_cmp);
    let at = |q: f64| relative.get(((relative.len().max(1) - 1) as f64 * q) as usize).copied().unwrap_or(f64::NAN);
    Ok(DecodeError { count: relative.len(), median: at(0.5), p99: at(0.99), max: at(1.0) })
}
