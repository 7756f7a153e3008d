//! `sky bench preview`: the preview's GPU passes timed by timestamp
//! queries over a few frames, the LUT sky pass beside a plain textured
//! full-screen pass in the same frames, reported as medians and a ratio;
//! and the cloud G-buffer, at once and per amortised frame.

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
    /// Frames timed (after one to warm up); the medians are reported
    #[arg(long, default_value_t = 20)]
    pub frames: usize,
    /// Machine-readable output
    #[arg(long)]
    pub json: bool,
}

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
        Ok(g) if g.has_timestamps() => g,
        Ok(g) => {
            eprintln!(
                "sky bench preview: {} has no timestamp queries, which the benchmark times passes by",
                g.describe()
            );
            return Ok(ExitCode::from(EXIT_INVALID));
        }
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
    let mut times: Vec<Vec<(&'static str, f64)>> = Vec::new();
    let mut steps = Vec::new();
    for _ in 0..=a.frames {
        let start = std::time::Instant::now();
        clouds.step(&gpu, &weather, &settings, &schedule)?;
        steps.push(start.elapsed().as_secs_f64());
        let mut frame = Frame::new(&gpu, &dirs)?;
        plain.encode(&gpu, &mut frame)?;
        sky.encode(&gpu, &mut frame, &luts, &weather)?;
        clouds.encode_lighting(&gpu, &mut frame, &luts, &weather)?;
        if let Some(l) = &landscape {
            l.encode(&gpu, &mut frame, &luts, &weather, &ground, None)?;
        }
        times.push(frame.finish()?.passes);
    }
    let names: Vec<&'static str> = times[0].iter().map(|p| p.0).collect();
    let median = |k: usize| {
        let mut v: Vec<f64> = times[1..].iter().map(|t| t[k].1).collect();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let medians: Vec<(&str, f64)> = names.iter().enumerate().map(|(k, n)| (*n, median(k))).collect();
    let of = |name: &str| medians.iter().find(|m| m.0 == name).map_or(f64::NAN, |m| m.1);
    let ratio = of("sky") / of("plain texture");
    steps.remove(0);
    steps.sort_by(f64::total_cmp);
    let step = steps[steps.len() / 2];
    if a.json {
        let passes: serde_json::Map<String, serde_json::Value> =
            medians.iter().map(|(n, s)| (n.to_string(), serde_json::json!(s))).collect();
        outln!(
            "{}",
            serde_json::json!({ "adapter": gpu.describe(), "width": w, "height": h, "frames": a.frames, "median_pass_seconds": passes, "sky_over_plain": ratio, "cloud_gbuffer_whole_seconds": whole, "cloud_gbuffer_step_seconds": step })
        );
    } else {
        outln!("{w}x{h} on {}, median of {} frames (GPU timestamps):", gpu.describe(), a.frames);
        for (n, s) in &medians {
            outln!("  {n:<14} {:>8.2} ms", 1e3 * s);
        }
        outln!("  the LUT sky pass takes {ratio:.2} times the plain textured pass");
        outln!("cloud G-buffer 256x256, 4 marches a texel: {:.2} s at once; amortised over 8 frames a march, {:.1} ms a frame (wall time, median)", whole, 1e3 * step);
    }
    Ok(ExitCode::SUCCESS)
}
