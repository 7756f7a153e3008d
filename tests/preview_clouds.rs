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
            assert!(seam < 1.5 * inside + 1e-3, "{name}-frequency noise does not tile along axis {axis}: {seam} across the wrap, {inside} inside");
        }
    }
    let again = CloudNoise::new(&gpu, 7).unwrap();
    assert_eq!(CloudNoise::read(&gpu, &again.low).unwrap(), low, "the same seed built a different texture");
}
