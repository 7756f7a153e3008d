//! The GPU preview's clouds (issue 14): the noise textures, the cumulus
//! map and the cloud G-buffer, on whatever adapter the environment gives
//! (`make test`: lavapipe through Vulkan).
#![cfg(feature = "preview")]

use sky::preview::cloud_noise::{CloudNoise, HIGH_SIZE, LOW_SIZE};
use sky::preview::gpu::Gpu;
use std::sync::Mutex;

/// The tests take the device one at a time.
static GPU: Mutex<()> = Mutex::new(());

/// Mean absolute difference between neighbours along `axis` of an n³
/// volume (x fastest), inside (between texels i and i + 1 < n) and across
/// the wrap (between texels n - 1 and 0).
fn neighbour_differences(v: &[f32], n: usize, axis: usize) -> (f64, f64) {
    let at = |p: [usize; 3]| v[p[0] + n * (p[1] + n * p[2])] as f64;
    let (mut inside, mut seam) = (0.0, 0.0);
    for a in 0..n {
        for b in 0..n {
            for i in 0..n {
                let mut p = [0; 3];
                p[axis] = i;
                p[(axis + 1) % 3] = a;
                p[(axis + 2) % 3] = b;
                let mut q = p;
                q[axis] = (i + 1) % n;
                let d = (at(p) - at(q)).abs();
                if i + 1 < n {
                    inside += d / (n - 1) as f64;
                } else {
                    seam += d;
                }
            }
        }
    }
    let planes = (n * n) as f64;
    (inside / planes, seam / planes)
}

/// The noise textures: the low frequency has a zero mean (the talk's
/// normalisation) and spreads, the high frequency lies in [0, 1]; both
/// tile (across each wrap neighbours differ as much as inside the volume,
/// where a noise that did not tile would jump by about its spread); and a
/// second build from the same seed is bit-identical.
#[test]
fn the_noise_textures_tile_and_the_low_one_has_zero_mean() {
    let _device = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let gpu = Gpu::new().expect("a GPU adapter (make test installs lavapipe)");
    let noise = CloudNoise::new(&gpu, 7).unwrap();
    let low = CloudNoise::read(&gpu, &noise.low).unwrap();
    let high = CloudNoise::read(&gpu, &noise.high).unwrap();
    assert_eq!(low.len(), (LOW_SIZE as usize).pow(3));
    assert_eq!(high.len(), (HIGH_SIZE as usize).pow(3));
    assert!(low.iter().chain(&high).all(|v| v.is_finite()));
    let n = low.len() as f64;
    let mean = low.iter().map(|&v| v as f64).sum::<f64>() / n;
    let spread = (low.iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / n).sqrt();
    eprintln!("low frequency: mean {mean:.2e}, standard deviation {spread:.3}");
    // Half floats round each value by up to 2^-11 of it, independently: the mean moves by far less than 1e-4.
    assert!(mean.abs() < 1e-4, "the low-frequency noise's mean is {mean}");
    assert!(spread > 0.05, "the low-frequency noise hardly varies ({spread})");
    assert!(high.iter().all(|&v| (0.0..=1.0).contains(&v)), "high-frequency noise outside [0, 1]");
    let high_mean = high.iter().map(|&v| v as f64).sum::<f64>() / high.len() as f64;
    let high_spread = (high.iter().map(|&v| (v as f64 - high_mean).powi(2)).sum::<f64>() / high.len() as f64).sqrt();
    assert!(high_spread > 0.05, "the high-frequency noise hardly varies ({high_spread})");
    for (name, v, size) in [("low", &low, LOW_SIZE as usize), ("high", &high, HIGH_SIZE as usize)] {
        for axis in 0..3 {
            let (inside, seam) = neighbour_differences(v, size, axis);
            eprintln!("{name}, axis {axis}: neighbours differ by {inside:.4} inside, {seam:.4} across the wrap");
            assert!(
                seam < 1.5 * inside + 1e-3,
                "{name}-frequency noise does not tile along axis {axis}: {seam} across the wrap, {inside} inside"
            );
        }
    }
    let again = CloudNoise::new(&gpu, 7).unwrap();
    assert_eq!(CloudNoise::read(&gpu, &again.low).unwrap(), low, "the same seed built a different texture");
}

/// The cloud G-buffer's invariants, for a sun high, low and below the
/// horizon and three covers: no NaN or infinity; opacity in [0, 1];
/// where a texel is opaque at all its distance lies in the cloud layer's
/// reach (from the base overhead, 1.5 km, to the far edge of the
/// cumulus map, under 200 km); sun and ambient in-scatter not negative,
/// and the ambient no more than the opacity (it is the opacity weighted by
/// shares of at most 1). With no cover the sky is clear: opacity 0
/// everywhere; at a cover of 0.3 some texels are clouds and some are sky;
/// more cover, more cloudy texels.
#[test]
fn the_cloud_gbuffer_keeps_its_invariants() {
    use sky::preview::cloud_coverage::default_coverage;
    use sky::preview::clouds::{CloudSettings, Clouds};
    use sky::preview::sky_pass::Weather;
    let _device = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let gpu = Gpu::new().expect("a GPU adapter (make test installs lavapipe)");
    let mut clouds = Clouds::new(&gpu, &default_coverage(), 64, 1).unwrap();
    for (e, az) in [(40.0, 10.0), (3.0, 250.0), (-4.0, 90.0)] {
        let weather =
            Weather { sun_elevation_deg: e, sun_azimuth_deg: az, haziness: 0.0, cloudiness: 0.0, sun_disk: false };
        let mut cloudy_by_cover = Vec::new();
        for cover in [0.0, 0.3, 0.7] {
            let settings = CloudSettings { cover, samples: 1, steps: 32, ..CloudSettings::default() };
            clouds.compute(&gpu, &weather, &settings, 0).unwrap();
            let g = clouds.read_gbuffer(&gpu).unwrap();
            assert_eq!(g.len(), 64 * 64);
            let (mut cloudy, mut clear) = (0, 0);
            for (i, t) in g.iter().enumerate() {
                let [opacity, distance_km, sun, ambient] = *t;
                let at = format!("sun {e}, cover {cover}, texel {i}: {t:?}");
                assert!(t.iter().all(|x| x.is_finite()), "{at}: not finite");
                assert!((0.0..=1.0).contains(&opacity), "{at}: opacity outside [0, 1]");
                assert!(sun >= 0.0 && ambient >= 0.0 && ambient <= opacity + 1e-3, "{at}: in-scatter out of range");
                if opacity > 1e-3 {
                    assert!((1.4..200.0).contains(&distance_km), "{at}: distance outside the layer's reach");
                    cloudy += 1;
                } else {
                    clear += 1;
                }
            }
            if cover == 0.0 {
                assert_eq!(cloudy, 0, "sun {e}: clouds with no cover");
            }
            if cover == 0.3 {
                assert!(
                    cloudy > 100 && clear > 100,
                    "sun {e}, cover {cover}: {cloudy} cloudy and {clear} clear texels"
                );
            }
            cloudy_by_cover.push(cloudy);
        }
        assert!(
            cloudy_by_cover.windows(2).all(|w| w[0] < w[1]),
            "sun {e}: cloudy texels by cover 0, 0.3, 0.7: {cloudy_by_cover:?}"
        );
    }
}

/// The amortised G-buffer (48 x 48 texels, 6 x 6 tiles; a march of every
/// texel spread over F = 4 frames; 16 marches a texel per G-buffer):
/// - its work is spread evenly: after j frames every texel has been
///   marched j / F times, rounded down or up, 16 texels of each tile more
///   per frame, and after the first frame those 16 form the lattice of every
///   other texel in both axes;
/// - it converges: after 1, 4 and 16 marches a texel (4, 16 and 64
///   frames) its estimate comes closer to a G-buffer of 64 marches made at
///   once, the RMS difference of opacity and sun in-scatter falling by at
///   least a quarter with each fourfold number of marches (1/sqrt would
///   halve it; the reference's own noise and the sun in-scatter's rare
///   bright marches, near the phase function's forward peak, keep it from
///   halving exactly: measured 0.48 to 0.64; a G-buffer that did not
///   converge would stay near 1);
/// - after 64 frames it is finished and swapped in (and not before), and
///   the current G-buffer is that estimate.
#[test]
fn the_amortised_gbuffer_spreads_its_work_and_converges() {
    use sky::preview::cloud_coverage::default_coverage;
    use sky::preview::clouds::{Amortisation, CloudSettings, Clouds};
    use sky::preview::sky_pass::Weather;
    let _device = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let gpu = Gpu::new().expect("a GPU adapter (make test installs lavapipe)");
    let n = 48;
    let mut clouds = Clouds::new(&gpu, &default_coverage(), n as u32, 1).unwrap();
    let weather =
        Weather { sun_elevation_deg: 30.0, sun_azimuth_deg: 0.0, haziness: 0.0, cloudiness: 0.0, sun_disk: false };
    let settings = CloudSettings { cover: 0.5, samples: 64, steps: 32, ..CloudSettings::default() };
    clouds.compute(&gpu, &weather, &settings, 1_000_000).unwrap();
    let reference = clouds.read_gbuffer(&gpu).unwrap();
    let rms = |g: &[[f32; 4]], c: usize| {
        (g.iter().zip(&reference).map(|(a, b)| ((a[c] - b[c]) as f64).powi(2)).sum::<f64>() / g.len() as f64).sqrt()
    };
    let settings = CloudSettings { samples: 16, ..settings };
    let schedule = Amortisation { frames_per_sample: 4, blend_frames: 8 };
    let mut previous: Option<[f64; 2]> = None;
    for frame in 1..=64u32 {
        let report = clouds.step(&gpu, &weather, &settings, &schedule).unwrap();
        assert_eq!(report.swapped, frame == 64, "frame {frame}: {report:?}");
        if frame == 64 {
            break;
        }
        let (estimate, counts) = clouds.read_progress(&gpu, &settings).unwrap();
        let (low, high) = ((frame / 4) as f32, (frame / 4 + u32::from(frame % 4 != 0)) as f32);
        assert!(
            counts.iter().all(|&c| c == low || c == high),
            "frame {frame}: marches per texel outside {low}..{high}"
        );
        assert_eq!(
            counts.iter().sum::<f32>(),
            (frame * 16 * 36) as f32,
            "frame {frame}: not 16 marches a tile a frame"
        );
        if frame == 1 {
            for (i, &c) in counts.iter().enumerate() {
                let (x, y) = (i % n, i / n);
                assert_eq!(c == 1.0, x % 2 == 0 && y % 2 == 0, "frame 1: texel ({x}, {y}) marched {c} times");
            }
        }
        if [4, 16].contains(&frame) || frame == 63 {
            let now = [rms(&estimate, 0), rms(&estimate, 2)];
            eprintln!(
                "frame {frame}: RMS difference to 64 marches at once, opacity {:.4}, sun in-scatter {:.5}",
                now[0], now[1]
            );
            if frame != 63 {
                if let Some(p) = previous {
                    assert!(now[0] < 0.75 * p[0] && now[1] < 0.75 * p[1], "frame {frame}: {now:?} against {p:?}");
                }
                previous = Some(now);
            }
        }
    }
    let done = clouds.read_gbuffer(&gpu).unwrap();
    let last = [rms(&done, 0), rms(&done, 2)];
    let p = previous.expect("measured at 16 frames");
    eprintln!("swapped in: RMS difference opacity {:.4}, sun in-scatter {:.5}", last[0], last[1]);
    assert!(last[0] < 0.75 * p[0] && last[1] < 0.75 * p[1], "the finished G-buffer {last:?} against 4 marches' {p:?}");
}
