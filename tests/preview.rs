//! The GPU preview's sky pass against the CPU reference decoder (issue
//! 14), by readback, on whatever adapter the environment gives (`make
//! test`: Mesa's lavapipe through Vulkan, `WGPU_BACKEND=vulkan`, so a
//! missing driver fails here instead of falling back to GL).
#![cfg(feature = "preview")]

use glam::DVec3;
use sky::directions::camera::direction_deg;
use sky::lut::decode::Luts;
use sky::preview::gpu::Gpu;
use sky::preview::sky_pass::{SkyPass, Weather};
use std::path::PathBuf;
use std::process::Command;
use std::sync::{Mutex, OnceLock};

/// The tests take the device one at a time.
static GPU: Mutex<()> = Mutex::new(());

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A draft bake of `tests/bakes/preview.toml` (clear, hazed, cloudy0 and
/// cloudy1), made once for the tests of this file.
fn bake() -> &'static Luts {
    &shared_bake().1
}

/// The shared bake's folder and LUTs.
fn shared_bake() -> &'static (tempfile::TempDir, Luts) {
    static BAKE: OnceLock<(tempfile::TempDir, Luts)> = OnceLock::new();
    BAKE.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let luts = bake_into(&dir.path().join("luts"));
        (dir, luts)
    })
}

fn bake_into(out: &std::path::Path) -> Luts {
    let o = Command::new(env!("CARGO_BIN_EXE_sky"))
        .args([
            "bake-luts",
            "--method",
            "monte-carlo",
            root().join("tests/bakes/preview.toml").to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .env("SKY_CACHE_DIR", sky::mie::MieCache::test_dir())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    Luts::load(&out.join("manifest.json")).unwrap()
}

/// The CPU decoder's RGB at the frame sky texture's texel centres that the
/// sky pass's filtered read blends toward `d` (world frame): the four
/// around the direction's (u, v) in the frame's mapping
/// (`sky_pass::frame_mapping`, `frame` texels), clamped to the edge. The
/// composition decodes each centre as the CPU decoder does, and the
/// sampler's weights are a convex combination of the four, so the sky
/// pass's value lies within their range (to the half float's rounding).
/// With `spread`, also the centres around the four directions 2e-6 rad
/// from `d`, and the CPU decoder's values 2e-6 rad from each centre: where
/// the mapping is steep, f32 may place the read one cell over (the first
/// test's reason), and where a slice's texel is 0 the blend between slices
/// jumps from geometric to linear, so a composed texel next to a zero may
/// be either.
fn composed_texels(luts: &Luts, w: &Weather, frame: (usize, usize), d: DVec3, spread: bool) -> Vec<[f64; 3]> {
    let m = sky::preview::sky_pass::frame_mapping(luts, w).expect("an active sky");
    let (c, s) = (w.sun_azimuth_deg.to_radians().cos(), w.sun_azimuth_deg.to_radians().sin());
    let step_deg = 2e-6f64.to_degrees();
    let (zenith, azimuth) = (d.z.clamp(-1.0, 1.0).acos().to_degrees(), d.y.atan2(d.x).to_degrees());
    let around = [(0.0, 0.0), (step_deg, 0.0), (-step_deg, 0.0), (0.0, step_deg), (0.0, -step_deg)];
    let mut centres = Vec::new();
    for &(dz, da) in &around[..if spread { 5 } else { 1 }] {
        let p = if (dz, da) == (0.0, 0.0) { d } else { direction_deg(zenith + dz, azimuth + da) };
        // decode::rotate_to_sun_frame.
        let (u, v) = m.uv(DVec3::new(c * p.x + s * p.y, -s * p.x + c * p.y, p.z));
        let cell = |t: f64, n: usize| {
            let i0 = ((t * n as f64 - 0.5).floor().max(0.0) as usize).min(n - 1);
            [i0, (i0 + 1).min(n - 1)]
        };
        for i in cell(u, frame.0) {
            for j in cell(v, frame.1) {
                if !centres.contains(&(i, j)) {
                    centres.push((i, j));
                }
            }
        }
    }
    let sample = |q: DVec3| luts.sample(w.sun_elevation_deg, w.sun_azimuth_deg, w.haziness, w.cloudiness, q);
    let mut texels = Vec::new();
    for (i, j) in centres {
        let q = m.direction((i as f64 + 0.5) / frame.0 as f64, (j as f64 + 0.5) / frame.1 as f64);
        let world = DVec3::new(c * q.x - s * q.y, s * q.x + c * q.y, q.z);
        texels.push(sample(world));
        if spread {
            let (zenith, azimuth) = (world.z.clamp(-1.0, 1.0).acos().to_degrees(), world.y.atan2(world.x).to_degrees());
            texels.extend(around[1..].iter().map(|&(dz, da)| sample(direction_deg(zenith + dz, azimuth + da))));
        }
    }
    texels
}

/// Whether `g`, less `extra` (what the CPU decoder adds beyond the sky:
/// the sun's disk), lies within the range of `texels` (each mapped by
/// `to`), widened by 1e-3 of itself (the frame texture's half floats round
/// to 2^-11; the rest is f32 arithmetic) and 1e-6 of `brightest`.
fn within_texels(
    g: [f64; 3],
    extra: [f64; 3],
    texels: &[[f64; 3]],
    to: impl Fn([f64; 3]) -> [f64; 3],
    brightest: f64,
) -> bool {
    let mapped: Vec<[f64; 3]> = texels.iter().map(|&t| to(t)).collect();
    (0..3).all(|k| {
        let lo = mapped.iter().map(|t| t[k]).fold(f64::INFINITY, f64::min);
        let hi = mapped.iter().map(|t| t[k]).fold(f64::NEG_INFINITY, f64::max);
        let x = g[k] - extra[k];
        x >= lo - 1e-3 * lo.abs() - 1e-6 * brightest && x <= hi + 1e-3 * hi.abs() + 1e-6 * brightest
    })
}

/// The GPU's decode equals the CPU decoder's on a grid of directions (every
/// 7.5 degrees of zenith angle, ground included, and 15 of azimuth) for
/// suns between slices and at slice centres, through twilight and across
/// the switch between the two direction mappings (sun zenith 87.5 degrees
/// here), and for haziness and cloudiness that blend one to three basis
/// skies, sunny and cloudy; each sun's last weather once more with the sun
/// turned 90 degrees, which reuses the frame's composition.
///
/// The bound (stated anew when the sky pass became a composition and one
/// filtered read, issue 38): the GPU's value lies within the range of the
/// CPU decoder's values at the four texel centres of the frame sky texture
/// around the direction, widened by 1e-3 of the value and 1e-6 of the
/// frame's brightest. The composition decodes each texel centre as the
/// CPU decoder does, in f32 (the textures are the same words on both
/// sides, filtered by hand), into half floats (rounding 2^-11, under the
/// 1e-3); the sampler's bilinear weights are non-negative and sum to 1
/// whatever their precision (Vulkan lets them be as coarse as 4 bits), so
/// the read is a convex combination of the four. Against the CPU decoder's
/// value at the direction itself the GPU adds the resampling error, which
/// this test prints and `sky bench preview` measures on a real bake (the
/// test bake's 4 x 16 texels of Monte Carlo noise make it large here).
///
/// Where the mapping is steep the range is taken over the directions 2e-6
/// rad around (about ten f32 roundings of an angle near π/2), and around
/// each texel centre: at the horizon the talk's v transform has an
/// unbounded slope (v − 0.8 ∝ √(0.5 − v') at the knot where the horizon
/// sits), so the f32 rounding of the angle from the sun moves the sample
/// by up to 1e-3 of a texel step; at the poles of the latitude-longitude
/// mapping every u is the same direction; with the sun a few degrees up in
/// the sun-centred mapping tan(θ_sun) amplifies rounding near the horizon;
/// and where a slice's texel is 0 the blend between slices jumps from
/// geometric to linear. Fewer than 2 % of the directions may need it. A
/// difference of method (a texel, a slice, a mirror, a region off) lands
/// outside the range by far.
#[test]
fn the_gpu_sky_pass_decodes_what_the_cpu_decoder_does() {
    let elevations = [63.1, 41.7, 23.3, 8.2, 3.1, 2.6, 2.4, 0.4, -0.9, -2.7, -7.5, -9.95];
    let weathers = [(0.0, 0.0), (1.0, 0.0), (0.3, 0.1), (0.6, 0.25), (0.0, 0.3)];
    gpu_decodes_as_cpu(bake(), &elevations, &weathers);
}

/// The same with the skies in RGBA16F (`--texture-format rgba16f`, packed
/// from the shared bake's cache): the GPU gets `Rgba16Float` arrays and
/// decodes them as the CPU decoder does, to the same tolerance.
#[test]
fn the_gpu_sky_pass_decodes_rgba16f_skies_as_the_cpu_does() {
    let (dir, _) = shared_bake();
    let out = dir.path().join("rgba16f");
    let o = Command::new(env!("CARGO_BIN_EXE_sky"))
        .args(["bake-luts", "--method", "monte-carlo", "--texture-format", "rgba16f", "--pack-only", "--cache"])
        .arg(dir.path().join("luts/cache"))
        .arg(root().join("tests/bakes/preview.toml"))
        .arg("--out")
        .arg(&out)
        .env("SKY_CACHE_DIR", sky::mie::MieCache::test_dir())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let luts = Luts::load(&out.join("manifest.json")).unwrap();
    assert!(luts.manifest.skies.iter().all(|s| s.vk_format == 97));
    gpu_decodes_as_cpu(&luts, &[41.7, 3.1, -2.7], &[(0.0, 0.0), (0.6, 0.25)]);
}

fn gpu_decodes_as_cpu(luts: &Luts, elevations: &[f64], weathers: &[(f64, f64)]) {
    let _device = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let gpu = Gpu::new().expect("a GPU adapter (make test installs lavapipe)");
    eprintln!("adapter: {}", gpu.describe());
    let pass = SkyPass::new(&gpu, luts).unwrap();
    let frame = pass.frame_size();
    let dirs: Vec<Option<glam::DVec3>> = (0..=24)
        .flat_map(|i| (0..24).map(move |j| Some(direction_deg(7.5 * i as f64, 15.0 * j as f64))))
        .chain([None])
        .collect();
    let (mut compared, mut steep) = (0, 0);
    let mut relative = Vec::new();
    for &e in elevations {
        // The last weather once more with the sun turned: the composition
        // is reused (it is in the sun's frame).
        let turned = weathers.last().map(|&(h, c)| (h, c, 97.0));
        for (haziness, cloudiness, az) in weathers.iter().map(|&(h, c)| (h, c, 7.0)).chain(turned) {
            let weather = Weather { sun_elevation_deg: e, sun_azimuth_deg: az, haziness, cloudiness, sun_disk: false };
            let gpu_rgb = pass.decode(&gpu, luts, &weather, &dirs).unwrap().rgb;
            let cpu: Vec<[f64; 3]> =
                dirs.iter().map(|d| d.map_or([0.0; 3], |d| luts.sample(e, az, haziness, cloudiness, d))).collect();
            let brightest = cpu.iter().flatten().fold(0.0f64, |m, &x| m.max(x));
            assert!(brightest > 0.0, "sun {e}, h {haziness}, c {cloudiness}: a black sky");
            for (i, (g, c)) in gpu_rgb.iter().zip(&cpu).enumerate() {
                let g = g.map(f64::from);
                let Some(d) = dirs[i] else {
                    assert_eq!(g, [0.0; 3], "outside the view");
                    continue;
                };
                let id = |t: [f64; 3]| t;
                if !within_texels(g, [0.0; 3], &composed_texels(luts, &weather, frame, d, false), id, brightest) {
                    let wider = composed_texels(luts, &weather, frame, d, true);
                    assert!(
                        within_texels(g, [0.0; 3], &wider, id, brightest),
                        "sun {e}, h {haziness}, c {cloudiness}, direction {i} ({d:?}): GPU {g:?} outside the CPU decoder's values {wider:?} at the frame texture's texels around it (CPU at the direction itself {c:?})"
                    );
                    steep += 1;
                }
                compared += 1;
                for k in 0..3 {
                    if c[k] > 1e-3 * brightest {
                        relative.push((g[k] - c[k]).abs() / c[k]);
                    }
                }
            }
        }
    }
    relative.sort_by(f64::total_cmp);
    let at = |q: f64| relative[((relative.len() - 1) as f64 * q) as usize];
    eprintln!(
        "{compared} directions compared, {steep} of them where the mapping is steep; against the CPU decoder at the direction itself: median {:.2e}, 99th percentile {:.2e}, largest {:.2e} of the value",
        at(0.5),
        at(0.99),
        at(1.0)
    );
    // Where the mapping is that steep is a thin set of directions: a
    // difference of method (a texel, a slice, a mirror off) would be
    // everywhere.
    assert!(steep * 50 < compared, "{steep} of {compared} directions needed the mapping's own change");
}

/// The sun's disk: through a pinhole 2 degrees wide centred on the sun
/// (48 x 48 pixels, the disk about 13 across), high and low, the GPU's
/// image is the CPU decoder's `decode_image` with its disk (CIE XYZ): the
/// sky as in the first test (within the CPU decoder's values at the frame
/// texture's texels around the pixel), the disk's radiance on top, except
/// on the disk's rim, where a pixel centre within 1e-5 rad of it may fall
/// on either side in f32.
#[test]
fn the_gpu_draws_the_sun_disk_the_cpu_decoder_draws() {
    use sky::colour::apply as mat_mul;
    use sky::directions::camera::Camera;
    use sky::lut::decode::pixel_directions;
    let luts = bake();
    let _device = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let gpu = Gpu::new().expect("a GPU adapter (make test installs lavapipe)");
    let pass = SkyPass::new(&gpu, luts).unwrap();
    let frame = pass.frame_size();
    let m = luts.manifest.colour.xyz_from_rgb;
    for (e, az) in [(20.0, 30.0), (3.0, 200.0)] {
        let weather =
            Weather { sun_elevation_deg: e, sun_azimuth_deg: az, haziness: 0.3, cloudiness: 0.0, sun_disk: true };
        let camera = Camera::Pinhole { azimuth_deg: az, elevation_deg: e, fov_deg: 2.0 };
        let (w, h) = (48, 48);
        let dirs = pixel_directions(&camera, w, h);
        let gpu_rgb = pass.decode(&gpu, luts, &weather, &dirs).unwrap().rgb;
        let cpu = luts.decode_image(&camera, w, h, e, az, 0.3, 0.0, true).unwrap();
        let sun = luts.sun(e, 0.3, 0.0).unwrap();
        let radius = 0.5 * sun.angular_diameter_deg.to_radians();
        let toward = direction_deg(90.0 - e, az);
        let brightest = cpu.iter().flatten().fold(0.0f64, |a, &x| a.max(x));
        let mut inside = 0;
        for (i, d) in dirs.iter().enumerate() {
            let d = d.unwrap();
            let angle = d.angle_between(toward);
            if (angle - radius).abs() < 1e-5 {
                continue;
            }
            inside += (angle < radius) as usize;
            let g = mat_mul(&m, gpu_rgb[i].map(f64::from));
            // What decode_image adds to the sky: the disk's radiance.
            let sky = luts.sample_xyz(e, az, 0.3, 0.0, d);
            let disk: [f64; 3] = std::array::from_fn(|k| cpu[i][k] - sky[k]);
            let xyz = |t: [f64; 3]| mat_mul(&m, t);
            assert!(
                within_texels(g, disk, &composed_texels(luts, &weather, frame, d, true), xyz, brightest),
                "sun {e} up at {az}, pixel {i} ({angle} rad from the sun's centre): GPU {g:?} against CPU {:?}",
                cpu[i]
            );
        }
        assert!(inside > 50, "sun {e}: only {inside} pixels inside the disk");
    }
}

/// The landscape: the GPU's terrain and fog passes (after its sky pass)
/// give the CPU reference `lut::landscape::landscape_toward`, toward a grid
/// of directions from 6 degrees below the horizon to 4 above (every
/// quarter degree, and every 3 degrees of azimuth: the five rows of ridges
/// at 2 to 100 km and the sky above them), for suns high, low, at the
/// horizon and below it, in weathers of one to three basis skies, with the
/// air sunlit, half and wholly shaded by clouds.
///
/// Both sides see a ridge in the same directions, except within 1e-3
/// degrees of a ridge's top (the profile's sines in f32 against f64), which
/// are left out. On the ridges the tolerance is the sky pass's, 1e-3 of the
/// value plus 1e-6 of the frame's brightest: the fog and attenuation are
/// the same half floats on both sides, filtered by hand, and what differs
/// is f32 arithmetic (the falloff's exponentials, the cube root of the
/// depth, the geometric blend between slices); a texel, slice or depth
/// mapping off misses by percents. The sky above the ridges is the sky
/// pass's, tested above.
#[test]
fn the_gpu_landscape_is_the_cpu_decoders() {
    use sky::lut::landscape::{landscape_toward, top_elevation_deg, RIDGES};
    use sky::preview::frame::Frame;
    use sky::preview::landscape::{Ground, LandscapePass};
    let luts = bake();
    let _device = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let gpu = Gpu::new().expect("a GPU adapter (make test installs lavapipe)");
    let (sky_pass, landscape) = (SkyPass::new(&gpu, luts).unwrap(), LandscapePass::new(&gpu, luts).unwrap());
    let m = luts.manifest.colour.xyz_from_rgb;
    let dirs: Vec<Option<DVec3>> = (0..=40)
        .flat_map(|i| (0..120).map(move |j| Some(direction_deg(96.0 - 0.25 * i as f64, 3.0 * j as f64 + 0.7))))
        .collect();
    let marginal = |d: &DVec3| {
        let (elevation, azimuth) = (d.z.asin().to_degrees(), d.y.atan2(d.x).to_degrees());
        RIDGES.iter().any(|r| (elevation - top_elevation_deg(r, azimuth)).abs() < 1e-3)
    };
    let suns = [(35.0, 40.0), (8.0, 200.0), (0.5, 100.0), (-3.0, 300.0)];
    let weathers = [(0.0, 0.0), (0.6, 0.25), (0.0, 0.3)];
    let (mut compared, mut worst) = (0, 0.0f64);
    for (n, &(e, az)) in suns.iter().enumerate() {
        for (k, &(haziness, cloudiness)) in weathers.iter().enumerate() {
            let cloud_occlusion = [0.0, 0.5, 1.0][(n + k) % 3];
            let weather = Weather { sun_elevation_deg: e, sun_azimuth_deg: az, haziness, cloudiness, sun_disk: false };
            let ground = Ground { albedo: 0.15, cloud_occlusion };
            let mut frame = Frame::new(&gpu, &dirs).unwrap();
            sky_pass.encode(&gpu, &mut frame, luts, &weather).unwrap();
            landscape.encode(&gpu, &mut frame, luts, &weather, &ground, None).unwrap();
            let rendered = frame.finish().unwrap();
            let cpu = landscape_toward(luts, &dirs, e, az, haziness, cloudiness, cloud_occlusion, 0.15).unwrap();
            let brightest = cpu.iter().flatten().fold(0.0f64, |a, &x| a.max(x));
            let mut ridges = 0;
            for (i, d) in dirs.iter().enumerate() {
                let d = d.unwrap();
                if marginal(&d) {
                    continue;
                }
                let (elevation, azimuth) = (d.z.asin().to_degrees(), d.y.atan2(d.x).to_degrees());
                let cpu_ridge = sky::lut::landscape::ridge_depth_km(elevation, azimuth);
                let gpu_depth = rendered.surface[i][3];
                assert_eq!(
                    cpu_ridge.is_some(),
                    gpu_depth > 0.0,
                    "sun {e} at {az}: direction {i} ({elevation} deg up, {azimuth} round): the CPU sees a ridge at {cpu_ridge:?} km, the GPU at {gpu_depth} km"
                );
                if cpu_ridge.is_none() {
                    continue;
                }
                ridges += 1;
                let g = sky::colour::apply(&m, rendered.rgb[i].map(f64::from));
                for c in 0..3 {
                    let diff = (g[c] - cpu[i][c]).abs();
                    assert!(
                        diff <= 1e-3 * cpu[i][c].abs() + 1e-6 * brightest,
                        "sun {e} at {az}, h {haziness}, c {cloudiness}, occlusion {cloud_occlusion}: direction {i} ({elevation} deg up, {azimuth} round), channel {c}: GPU {} against CPU {}",
                        g[c],
                        cpu[i][c]
                    );
                    worst = worst.max(diff / (cpu[i][c].abs() + 1e-6 * brightest));
                    compared += 1;
                }
            }
            assert!(ridges > 1000, "only {ridges} directions meet a ridge");
        }
    }
    eprintln!("{compared} landscape values compared; largest difference {worst:.2e} of the value");
}

/// Switching the amortised cloud G-buffer is blended: with the wind moving
/// the clouds 3 km between G-buffers, the picture (a 64 x 64 fisheye of
/// sky and clouds, lit from the bake) changes from frame to frame by at
/// most 1.5 times the whole switch's change over the blend's 8 frames (a
/// linear blend changes it by exactly one eighth a frame; the margin is
/// for half-float rounding), where a switch without the blend would change
/// it all at once; and the whole switch does change it (by more than 1 %
/// of the mean luminance), so the bound is not met by clouds that stood
/// still.
#[test]
fn a_cloud_gbuffer_switch_is_blended_over_frames() {
    use sky::directions::camera::Camera;
    use sky::lut::decode::pixel_directions;
    use sky::preview::cloud_coverage::default_coverage;
    use sky::preview::clouds::{Amortisation, CloudSettings, Clouds};
    use sky::preview::frame::Frame;
    let luts = bake();
    let _device = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let gpu = Gpu::new().expect("a GPU adapter (make test installs lavapipe)");
    let sky_pass = SkyPass::new(&gpu, luts).unwrap();
    let mut clouds = Clouds::new(&gpu, &default_coverage(), 32, 1).unwrap();
    let dirs = pixel_directions(&Camera::Fisheye, 64, 64);
    let weather =
        Weather { sun_elevation_deg: 35.0, sun_azimuth_deg: 60.0, haziness: 0.2, cloudiness: 0.0, sun_disk: false };
    let schedule = Amortisation { frames_per_sample: 2, blend_frames: 8 };
    let mut pictures: Vec<Vec<f64>> = Vec::new();
    let mut swaps = Vec::new();
    for frame in 0..40u32 {
        // 8 frames a G-buffer (4 marches a texel, each over 2 frames); the wind moves on at each cycle's start.
        let settings = CloudSettings {
            cover: 0.5,
            samples: 4,
            steps: 24,
            wind_offset_km: [3.0 * f64::from(frame / 8), 0.0],
            ..CloudSettings::default()
        };
        let report = clouds.step(&gpu, &weather, &settings, &schedule).unwrap();
        if report.swapped {
            swaps.push(frame);
        }
        let mut f = Frame::new(&gpu, &dirs).unwrap();
        sky_pass.encode(&gpu, &mut f, luts, &weather).unwrap();
        clouds.encode_lighting(&gpu, &mut f, luts, &weather).unwrap();
        let rendered = f.finish().unwrap();
        pictures.push(rendered.rgb.iter().map(|c| (c[0] + c[1] + c[2]) as f64).collect());
    }
    assert_eq!(swaps, vec![7, 15, 23, 31, 39]);
    let change = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum::<f64>() / a.len() as f64;
    // The switch at frame 23: the picture at 23 shows the previous G-buffer alone, at 31 the new one alone.
    let whole = change(&pictures[23], &pictures[31]);
    let mean = pictures[23].iter().sum::<f64>() / pictures[23].len() as f64;
    assert!(whole > 0.01 * mean, "the clouds did not move: a change of {whole} on a mean of {mean}");
    for frame in 24..=31 {
        let step = change(&pictures[frame - 1], &pictures[frame]);
        eprintln!(
            "frame {frame}: changed by {:.3} % of the mean (the whole switch: {:.3} %)",
            100.0 * step / mean,
            100.0 * whole / mean
        );
        assert!(step <= 1.5 * whole / 8.0, "frame {frame}: the picture changed by {step}, the whole switch by {whole}");
    }
}

/// `sky preview --timeline`: a numbered picture (EXR and PNG) and G-buffer
/// per frame, the states of the timeline in the JSON summary (the sun from
/// the time, the wind's offset growing), per-pass GPU times where the
/// adapter has timestamps; a bad timeline is an error naming its file and
/// what is wrong (exit 1), before any GPU work.
#[test]
fn sky_preview_renders_a_timeline_frame_by_frame() {
    shared_bake();
    let manifest = shared_bake().0.path().join("luts/manifest.json");
    let dir = tempfile::tempdir().unwrap();
    let timeline = dir.path().join("day.toml");
    std::fs::write(
        &timeline,
        "frames = 3\nlatitude_deg = 35.0\nday = 172\n[[key]]\nframe = 0\ntime = \"08:00\"\nhaziness = 0.0\ncloudiness = 0.0\ncumulus_cover = 0.5\nwind_km_h = [60.0, 0.0]\n[[key]]\nframe = 2\ntime = \"10:00\"\nhaziness = 0.4\ncloudiness = 0.1\ncumulus_cover = 0.5\nwind_km_h = [60.0, 0.0]\n",
    )
    .unwrap();
    let out = dir.path().join("frames");
    let _device = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let run = |timeline: &std::path::Path| {
        Command::new(env!("CARGO_BIN_EXE_sky"))
            .args([
                "preview",
                manifest.to_str().unwrap(),
                "--timeline",
                timeline.to_str().unwrap(),
                "--size",
                "32x32",
                "--gbuffer-size",
                "32",
                "--cloud-samples",
                "1",
                "--frames-per-sample",
                "1",
                "--gbuffer",
                "--json",
                "--out",
                out.to_str().unwrap(),
            ])
            .output()
            .unwrap()
    };
    let o = run(&timeline);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let frames = summary["frames"].as_array().unwrap();
    assert_eq!(frames.len(), 3);
    for (k, f) in frames.iter().enumerate() {
        for stem in ["sky", "gbuffer"] {
            assert!(out.join(format!("{stem}.{k:04}.exr")).is_file(), "{stem} {k}");
        }
        assert!(out.join(format!("sky.{k:04}.png")).is_file());
        let (e, a) = sky::look::solar::sun_position_deg(35.0, 172, 8.0 + k as f64);
        assert!(
            (f["state"]["sun_elevation_deg"].as_f64().unwrap() - e).abs() < 1e-9
                && (f["state"]["sun_azimuth_deg"].as_f64().unwrap() - a).abs() < 1e-9
        );
        assert!((f["state"]["wind_offset_km"][0].as_f64().unwrap() - 60.0 * k as f64).abs() < 1e-9, "{f}");
    }
    assert!(out.join("coverage.png").is_file());
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "frames = 3\n[[key]]\nframe = 0\nsun_elevation_deg = 100.0\nsun_azimuth_deg = 0.0\nhaziness = 0.0\ncloudiness = 0.0\n").unwrap();
    let o = run(&bad);
    assert_eq!(o.status.code(), Some(1));
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("bad.toml") && e.contains("key 1 (frame 0)") && e.contains("sun_elevation_deg"), "{e}");
}

/// The fog under clouds: with the clouds' occlusion grid bound, the fog
/// pass shades each view by the grid averaged along it (the talk's "cloud
/// occlusion computed separately on the 3D grid that covers the world"),
/// and what it draws is the CPU decoder's landscape at that occlusion, to
/// the first landscape test's tolerance. The occlusion lies in [0, 1], is 0
/// everywhere without cover, grows with the cover, and varies across the
/// view under broken cloud (the light shafts the talk shows).
#[test]
fn the_fog_under_clouds_takes_its_occlusion_from_the_grid() {
    use sky::lut::landscape::{landscape_toward, ridge_depth_km, top_elevation_deg, RIDGES};
    use sky::preview::cloud_coverage::default_coverage;
    use sky::preview::clouds::{CloudSettings, Clouds, CUMULUS_SPAN_KM};
    use sky::preview::frame::Frame;
    use sky::preview::landscape::{Ground, LandscapePass, OcclusionGrid};
    let luts = bake();
    let _device = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let gpu = Gpu::new().expect("a GPU adapter (make test installs lavapipe)");
    let (sky_pass, landscape) = (SkyPass::new(&gpu, luts).unwrap(), LandscapePass::new(&gpu, luts).unwrap());
    let mut clouds = Clouds::new(&gpu, &default_coverage(), 32, 1).unwrap();
    let m = luts.manifest.colour.xyz_from_rgb;
    let dirs: Vec<Option<DVec3>> = (0..=20)
        .flat_map(|i| (0..60).map(move |j| Some(direction_deg(96.0 - 0.5 * i as f64, 6.0 * j as f64 + 0.7))))
        .collect();
    let (e, az, haziness, cloudiness) = (50.0, 30.0, 0.3, 0.1);
    let weather = Weather { sun_elevation_deg: e, sun_azimuth_deg: az, haziness, cloudiness, sun_disk: false };
    let mut means = Vec::new();
    for cover in [0.0, 0.5, 0.9] {
        let settings = CloudSettings { cover, samples: 1, steps: 16, ..CloudSettings::default() };
        clouds.compute(&gpu, &weather, &settings, 0).unwrap();
        let view = clouds.occlusion_grid();
        let grid = OcclusionGrid {
            view: &view,
            half_span_km: 0.5 * CUMULUS_SPAN_KM,
            top_km: settings.base_km,
            planet_radius_km: settings.planet_radius_km,
        };
        let mut frame = Frame::new(&gpu, &dirs).unwrap();
        sky_pass.encode(&gpu, &mut frame, luts, &weather).unwrap();
        landscape
            .encode(&gpu, &mut frame, luts, &weather, &Ground { albedo: 0.15, cloud_occlusion: 0.0 }, Some(&grid))
            .unwrap();
        let rendered = frame.finish().unwrap();
        let mut occlusions = Vec::new();
        for (i, d) in dirs.iter().enumerate() {
            let d = d.unwrap();
            let (elevation, azimuth) = (d.z.asin().to_degrees(), d.y.atan2(d.x).to_degrees());
            if ridge_depth_km(elevation, azimuth).is_none()
                || RIDGES.iter().any(|r| (elevation - top_elevation_deg(r, azimuth)).abs() < 1e-3)
            {
                continue;
            }
            let occlusion = rendered.alpha[i];
            assert!((0.0..=1.0).contains(&occlusion), "cover {cover}, direction {i}: occlusion {occlusion}");
            occlusions.push(occlusion as f64);
            let cpu =
                landscape_toward(luts, &[Some(d)], e, az, haziness, cloudiness, occlusion as f64, 0.15).unwrap()[0];
            let g = sky::colour::apply(&m, rendered.rgb[i].map(f64::from));
            for c in 0..3 {
                assert!(
                    (g[c] - cpu[c]).abs() <= 1e-3 * cpu[c].abs() + 1e-6 * cpu[1].abs().max(1e-9),
                    "cover {cover}, direction {i} (occlusion {occlusion}), channel {c}: GPU {} against CPU {}",
                    g[c],
                    cpu[c]
                );
            }
        }
        let mean = occlusions.iter().sum::<f64>() / occlusions.len() as f64;
        let (low, high) = occlusions.iter().fold((1.0f64, 0.0f64), |(l, h), &x| (l.min(x), h.max(x)));
        eprintln!(
            "cover {cover}: {} terrain views, occlusion mean {mean:.3}, from {low:.3} to {high:.3}",
            occlusions.len()
        );
        if cover == 0.0 {
            assert_eq!(high, 0.0, "occlusion without clouds");
        }
        if cover == 0.5 {
            assert!(high - low > 0.1, "broken cloud shades every view alike: {low} to {high}");
        }
        means.push(mean);
    }
    assert!(means.windows(2).all(|w| w[0] < w[1]), "occlusion by cover 0, 0.5, 0.9: {means:?}");
}

/// A golden scene: what the preview draws, and the FLIP bounds it must keep.
struct Golden {
    name: &'static str,
    state: sky::look::timeline::FrameState,
    camera: sky::directions::camera::Camera,
    clouds: bool,
    /// Mean and 99th percentile of FLIP against the stored picture.
    mean: f32,
    p99: f32,
}

/// Golden images: four scenes of the shared bake through `PreviewSession`
/// (a clear noon, a hazy sunset over the landscape, an afternoon of
/// cumulus, a cloudy twilight), tonemapped as `sky preview` writes them
/// (8-bit sRGB PNG) and compared with the pictures in `tests/golden/` by
/// NVIDIA's FLIP (its C++ reference through the `nv-flip` crate; mean and
/// 99th percentile of the error map). `make golden-update` rewrites them
/// (SKY_GOLDEN_UPDATE=1); on a failure the picture drawn and FLIP's error
/// map are written next to `target/golden/`.
///
/// The bounds, per scene: without clouds (mean 0.01, 99th percentile 0.1)
/// the picture is the sky pass's one filtered read of the composed frame
/// texture (the readback tests' range), which another adapter's sampler
/// (4 sub-texel bits, Vulkan's least, truncated) moves by at most 1/16 of
/// the step between two frame texels, a quarter
/// of a LUT texel apart, and FLIP of differences of a code or two stays
/// below these; with clouds (mean 0.05, 99th
/// percentile 0.5) the density is read through the adapter's texture
/// filtering, whose sub-texel precision Vulkan lets be as coarse as 4 bits,
/// which moves cloud edges by fractions of a G-buffer texel on another
/// GPU. Any change of method (a mapping, a blend, the march) moves these
/// pictures by far more.
#[test]
fn the_preview_draws_its_golden_scenes() {
    use sky::colour::apply as mat_mul;
    use sky::directions::camera::Camera;
    use sky::look::timeline::FrameState;
    use sky::preview::cloud_coverage::default_coverage;
    use sky::preview::clouds::Amortisation;
    use sky::preview::landscape::Ground;
    use sky::preview::session::{CloudOptions, PreviewOptions, PreviewSession};
    use sky::render::{output, Image, PixelResult};
    let luts = bake();
    let _device = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let state =
        |sun_elevation_deg: f64, sun_azimuth_deg: f64, haziness: f64, cloudiness: f64, cumulus_cover: f64| FrameState {
            frame: 0,
            hours: None,
            sun_elevation_deg,
            sun_azimuth_deg,
            haziness,
            cloudiness,
            cumulus_cover,
            wind_offset_km: [0.0, 0.0],
        };
    let pinhole = |azimuth_deg: f64, elevation_deg: f64| Camera::Pinhole { azimuth_deg, elevation_deg, fov_deg: 90.0 };
    let scenes = [
        Golden {
            name: "clear-noon",
            state: state(70.0, -90.0, 0.0, 0.0, 0.0),
            camera: Camera::Fisheye,
            clouds: false,
            mean: 0.01,
            p99: 0.1,
        },
        Golden {
            name: "hazy-sunset",
            state: state(3.0, 0.0, 0.7, 0.0, 0.0),
            camera: pinhole(0.0, 4.0),
            clouds: false,
            mean: 0.01,
            p99: 0.1,
        },
        Golden {
            name: "cumulus-afternoon",
            state: state(35.0, 120.0, 0.2, 0.0, 0.5),
            camera: pinhole(100.0, 15.0),
            clouds: true,
            mean: 0.05,
            p99: 0.5,
        },
        Golden {
            name: "cloudy-twilight",
            state: state(-3.0, 250.0, 0.3, 0.15, 0.3),
            camera: pinhole(250.0, 5.0),
            clouds: true,
            mean: 0.05,
            p99: 0.5,
        },
    ];
    let update = std::env::var_os("SKY_GOLDEN_UPDATE").is_some();
    let (w, h) = (96, 64);
    let scratch = tempfile::tempdir().unwrap();
    let mut failures = Vec::new();
    for scene in &scenes {
        let gpu = Gpu::new().expect("a GPU adapter (make test installs lavapipe)");
        let clouds = scene.clouds.then(|| CloudOptions {
            coverage: default_coverage(),
            gbuffer_size: 64,
            samples: 2,
            schedule: Amortisation { frames_per_sample: 8, blend_frames: 16 },
        });
        let options =
            PreviewOptions { sun_disk: true, ground: Some(Ground { albedo: 0.15, cloud_occlusion: 0.0 }), clouds };
        let mut session = PreviewSession::new(gpu, luts, options).unwrap();
        let out = session.render(&scene.state, &scene.camera, w, h).unwrap();
        let m = luts.manifest.colour.xyz_from_rgb;
        let image = Image {
            width: w,
            height: h,
            pixels: out.rendered.rgb.iter().map(|rgb| PixelResult::from_xyz(mat_mul(&m, rgb.map(f64::from)))).collect(),
        };
        let drawn = scratch.path().join(format!("{}.png", scene.name));
        output::write_png(&drawn, &image, 0.0, None).unwrap();
        let golden = root().join("tests/golden").join(format!("{}.png", scene.name));
        if update {
            std::fs::copy(&drawn, &golden).unwrap();
            continue;
        }
        let rgb = |path: &std::path::Path| {
            image::open(path)
                .unwrap_or_else(|e| panic!("{}: {e} (make golden-update writes it)", path.display()))
                .to_rgb8()
        };
        let (reference, test) = (rgb(&golden), rgb(&drawn));
        assert_eq!(
            (reference.width(), reference.height()),
            (w as u32, h as u32),
            "{}: the stored picture's size",
            scene.name
        );
        let error = nv_flip::flip(
            nv_flip::FlipImageRgb8::with_data(w as u32, h as u32, reference.as_raw()),
            nv_flip::FlipImageRgb8::with_data(w as u32, h as u32, test.as_raw()),
            nv_flip::DEFAULT_PIXELS_PER_DEGREE,
        );
        let mut pool = nv_flip::FlipPool::from_image(&error);
        let (mean, p99) = (pool.mean(), pool.get_percentile(0.99, false));
        eprintln!(
            "{}: FLIP mean {mean:.4} (bound {}), 99th percentile {p99:.4} (bound {})",
            scene.name, scene.mean, scene.p99
        );
        if mean > scene.mean || p99 > scene.p99 {
            let dir = root().join("target/golden");
            std::fs::create_dir_all(&dir).unwrap();
            std::fs::copy(&drawn, dir.join(format!("{}-actual.png", scene.name))).unwrap();
            let map = error.apply_color_lut(&nv_flip::magma_lut());
            image::RgbImage::from_raw(w as u32, h as u32, map.to_vec())
                .unwrap()
                .save(dir.join(format!("{}-difference.png", scene.name)))
                .unwrap();
            failures.push(format!(
                "{}: FLIP mean {mean} (bound {}), 99th percentile {p99} (bound {}); see target/golden/",
                scene.name, scene.mean, scene.p99
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// A sun smaller than a pixel (a 32 x 32 fisheye: pixels of about 6
/// degrees, the disk about half a degree): no pixel centre falls inside
/// the disk, so, as the CPU decoder's `decode_image` does, the sun's
/// irradiance goes into the pixel nearest it, over that pixel's solid
/// angle; the GPU's picture is the CPU decoder's everywhere (the sky as
/// in the first test, the sun's pixel with the same irradiance on top),
/// and that pixel outshines the sky around the sun by far (the sun is in
/// the picture).
#[test]
fn the_gpu_puts_a_sun_smaller_than_a_pixel_where_the_cpu_decoder_does() {
    use sky::colour::apply as mat_mul;
    use sky::directions::camera::Camera;
    use sky::lut::decode::pixel_directions;
    use sky::preview::frame::Frame;
    use sky::preview::sky_pass::sun_pixel;
    let luts = bake();
    let _device = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let gpu = Gpu::new().expect("a GPU adapter (make test installs lavapipe)");
    let pass = SkyPass::new(&gpu, luts).unwrap();
    let frame_size = pass.frame_size();
    let m = luts.manifest.colour.xyz_from_rgb;
    let (w, h) = (32, 32);
    let camera = Camera::Fisheye;
    let dirs = pixel_directions(&camera, w, h);
    for (e, az) in [(37.0, 20.0), (8.0, 200.0)] {
        let weather =
            Weather { sun_elevation_deg: e, sun_azimuth_deg: az, haziness: 0.2, cloudiness: 0.0, sun_disk: true };
        let point =
            sun_pixel(luts, &weather, &camera, w, h, &dirs).expect("a sun smaller than a pixel, within the image");
        let mut frame = Frame::new(&gpu, &dirs).unwrap();
        pass.encode_with_sun_pixel(&gpu, &mut frame, luts, &weather, Some(point)).unwrap();
        let gpu_rgb = frame.finish().unwrap().rgb;
        let cpu = luts.decode_image(&camera, w, h, e, az, 0.2, 0.0, true).unwrap();
        let brightest = cpu.iter().flatten().fold(0.0f64, |a, &x| a.max(x));
        for (i, d) in dirs.iter().enumerate() {
            let Some(d) = d else { continue };
            let g = mat_mul(&m, gpu_rgb[i].map(f64::from));
            // What decode_image adds to the sky: the sun's irradiance in its pixel.
            let sky = luts.sample_xyz(e, az, 0.2, 0.0, *d);
            let point: [f64; 3] = std::array::from_fn(|k| cpu[i][k] - sky[k]);
            let xyz = |t: [f64; 3]| mat_mul(&m, t);
            assert!(
                within_texels(g, point, &composed_texels(luts, &weather, frame_size, *d, true), xyz, brightest),
                "sun {e} up at {az}, pixel {i}: GPU {g:?} against CPU {:?}",
                cpu[i]
            );
        }
        let sky_near = luts.sample_xyz(e, az, 0.2, 0.0, dirs[point.0].unwrap())[1];
        assert!(
            cpu[point.0][1] > 10.0 * sky_near,
            "sun {e}: the sun's pixel {} against the sky's {sky_near}",
            cpu[point.0][1]
        );
    }
}
