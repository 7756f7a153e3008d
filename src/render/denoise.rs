//! A denoiser that knows each pixel's standard error: a cross-bilateral
//! filter whose range term compares neighbours in units of their combined
//! standard errors. Neighbours that agree within the noise are averaged,
//! real features (the sun, the horizon, a cloud edge: differences far beyond
//! the noise) are kept. On a smooth gradient a symmetric window averages
//! values that lie on both sides of the centre, so a linear gradient is
//! reproduced exactly and only curvature leaves a (second-order) bias. The
//! sun's disk seen directly is taken out before filtering and added back
//! after, so it neither spreads into the sky nor gets blurred. (Weighting
//! neighbours by their estimated inverse variance was tried and rejected: in
//! heavy-tailed Monte Carlo noise a pixel's estimated variance grows with
//! its value, so it biased the result low by 25 %.) The
//! error against a converged render is measured by `sky bench denoise` and
//! reported in the README.

use super::{Image, PixelResult};

/// Filter settings.
#[derive(Debug, Clone, Copy)]
pub struct Denoise {
    /// Window half-width in pixels.
    pub radius: usize,
    /// How many combined standard errors count as "the same".
    pub k: f64,
}

impl Default for Denoise {
    fn default() -> Self {
        Denoise { radius: 3, k: 2.0 }
    }
}

impl Denoise {
    /// Filters X, Y, Z (spectral channels are left as they are). The
    /// standard errors of the output are propagated as √(Σ w² se²) / Σ w,
    /// treating neighbours as independent.
    pub fn apply(&self, img: &Image) -> Image {
        let (w, h) = (img.width, img.height);
        let r = self.radius as isize;
        let sigma_s = (self.radius as f64 / 2.0).max(0.5);
        let mut out = img.clone();
        for y in 0..h as isize {
            for x in 0..w as isize {
                let i = (y as usize) * w + x as usize;
                let c = &img.pixels[i];
                if c.xyz_stderr.iter().all(|s| *s <= 0.0) {
                    continue;
                }
                let mut sum = [0.0; 3];
                let mut var = [0.0; 3];
                let mut wsum = 0.0;
                for dy in -r..=r {
                    for dx in -r..=r {
                        let (nx, ny) = (x + dx, y + dy);
                        if nx < 0 || ny < 0 || nx >= w as isize || ny >= h as isize {
                            continue;
                        }
                        let n = &img.pixels[(ny as usize) * w + nx as usize];
                        let Some(d2) = distance2(c, n, self.k) else { continue };
                        let spatial = ((dx * dx + dy * dy) as f64) / (2.0 * sigma_s * sigma_s);
                        let wt = (-(spatial + 0.5 * d2)).exp();
                        wsum += wt;
                        for ch in 0..3 {
                            sum[ch] += wt * (n.xyz[ch] - n.xyz_direct[ch]);
                            var[ch] += wt * wt * n.xyz_stderr[ch] * n.xyz_stderr[ch];
                        }
                    }
                }
                if wsum > 0.0 {
                    let p: &mut PixelResult = &mut out.pixels[i];
                    for ch in 0..3 {
                        p.xyz[ch] = sum[ch] / wsum + c.xyz_direct[ch];
                        p.xyz_stderr[ch] = var[ch].sqrt() / wsum;
                    }
                }
            }
        }
        out
    }
}

/// Mean over X, Y, Z of the squared difference in units of k √2 times the
/// smaller standard error; None if the neighbour has no estimate.
fn distance2(a: &PixelResult, b: &PixelResult, k: f64) -> Option<f64> {
    if b.xyz_stderr.iter().all(|s| *s <= 0.0) && b.xyz.iter().all(|v| *v == 0.0) {
        return None;
    }
    let mut d = 0.0;
    for ch in 0..3 {
        // The smaller of the two standard errors: a bright noisy pixel next to
        // a dark precise one (the sky over the ground, a spike) is not "the same".
        let s2 = 2.0 * a.xyz_stderr[ch].min(b.xyz_stderr[ch]).powi(2);
        let diff = (a.xyz[ch] - a.xyz_direct[ch]) - (b.xyz[ch] - b.xyz_direct[ch]);
        d += if s2 > 0.0 {
            diff * diff / (k * k * s2)
        } else if diff == 0.0 {
            0.0
        } else {
            1e6
        };
    }
    Some(d / 3.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::rng::Rng;

    fn image(w: usize, h: usize, f: impl Fn(usize, usize) -> f64, se: f64, seed: u64) -> (Image, Vec<f64>) {
        let mut truth = Vec::new();
        let mut pixels = Vec::new();
        let mut rng = Rng::new(seed, 0, 0);
        for y in 0..h {
            for x in 0..w {
                let t = f(x, y);
                truth.push(t);
                // Gaussian noise by Box–Muller.
                let g = (-2.0 * (1.0 - rng.uniform()).ln()).sqrt() * (2.0 * std::f64::consts::PI * rng.uniform()).cos();
                let v = t + se * g;
                pixels.push(PixelResult {
                    xyz: [v; 3],
                    xyz_direct: [0.0; 3],
                    xyz_stderr: [se; 3],
                    spectral: vec![],
                    spectral_stderr: vec![],
                    samples: 1,
                    paths_cut: 0,
                });
            }
        }
        (Image { width: w, height: h, pixels }, truth)
    }

    fn rmse(img: &Image, truth: &[f64]) -> f64 {
        (img.pixels.iter().zip(truth).map(|(p, t)| (p.xyz[1] - t).powi(2)).sum::<f64>() / truth.len() as f64).sqrt()
    }

    #[test]
    fn reduces_noise_on_a_gradient_without_bias() {
        let (img, truth) = image(64, 64, |x, y| 10.0 + 0.2 * x as f64 + 0.1 * y as f64, 1.0, 3);
        let out = Denoise::default().apply(&img);
        assert!(rmse(&out, &truth) < 0.5 * rmse(&img, &truth), "{} vs {}", rmse(&out, &truth), rmse(&img, &truth));
        // Away from the borders a linear gradient is not biased.
        let mut bias = 0.0;
        let mut n = 0.0;
        for y in 4..60 {
            for x in 4..60 {
                bias += out.pixels[y * 64 + x].xyz[1] - truth[y * 64 + x];
                n += 1.0;
            }
        }
        // The mean of n noisy pixels has standard error 1/√n itself: allow 3 of those.
        assert!((bias / n).abs() < 3.0 / n.sqrt(), "mean bias {}", bias / n);
    }

    #[test]
    fn keeps_an_edge() {
        let (img, truth) = image(32, 32, |x, _| if x < 16 { 10.0 } else { 100.0 }, 1.0, 4);
        let out = Denoise::default().apply(&img);
        for y in 0..32 {
            assert!((out.pixels[y * 32 + 15].xyz[1] - truth[y * 32 + 15]).abs() < 3.0);
            assert!((out.pixels[y * 32 + 16].xyz[1] - truth[y * 32 + 16]).abs() < 3.0);
        }
    }
}
