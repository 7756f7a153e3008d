//! The parallel driver: every pixel of a view ([`render`],
//! [`render_timed`]) or a range of its columns (a farm task,
//! [`render_columns`]) on the current rayon pool, through one loop
//! ([`par_pixels`]); and the single-scattering quadrature per pixel
//! ([`single_per_pixel`]).

use super::pixel::{render_pixel_with, single_by_quadrature, PixelResult, PixelTracers};
use super::scene::Scene;
use super::settings::View;
use std::sync::atomic::{AtomicBool, Ordering};

/// [`single_by_quadrature`] toward the centre of every pixel of `s` (a
/// camera that does not jitter), CIE XYZ, row-major; in parallel. Zero where
/// the camera sees nothing.
pub fn single_per_pixel(scene: &Scene, s: &View) -> Vec<[f64; 3]> {
    use rayon::prelude::*;
    let (w, h) = (s.width, s.height);
    (0..w * h)
        .into_par_iter()
        .map(|i| {
            let dir = s.camera.direction((i % w) as f64 + 0.5, (i / w) as f64 + 0.5, w, h);
            dir.map_or([0.0; 3], |d| single_by_quadrature(scene, s, d).0)
        })
        .collect()
}

/// The one parallel loop over pixels: pixel `i` of `0..n` is `pixel(i)`,
/// on the current rayon pool, returned in index order with the seconds it
/// took on its thread. `on_pixel` is called after each pixel; None if
/// `cancel` was set. Each pixel is a pure function of its index, so the
/// result does not depend on the pool.
fn par_pixels(
    n: usize,
    cancel: &AtomicBool,
    on_pixel: &(dyn Fn() + Sync),
    pixel: impl Fn(usize) -> PixelResult + Sync,
) -> Option<Vec<(PixelResult, f64)>> {
    use rayon::prelude::*;
    let pixels: Vec<Option<(PixelResult, f64)>> = (0..n)
        .into_par_iter()
        .map(|i| {
            if cancel.load(Ordering::Relaxed) {
                return None;
            }
            let start = std::time::Instant::now();
            let r = pixel(i);
            let seconds = start.elapsed().as_secs_f64();
            if cancel.load(Ordering::Relaxed) {
                return None;
            }
            on_pixel();
            Some((r, seconds))
        })
        .collect();
    if cancel.load(Ordering::Relaxed) {
        return None;
    }
    pixels.into_iter().collect()
}

/// Renders `count` pixel columns from `first` (each top to bottom) on the
/// current rayon pool: a farm task. `on_pixel` is called after each pixel;
/// None if `cancel` was set. Pixels are the same pure function of (scene,
/// settings, pixel) as in [`render`], so a column is bit-identical wherever
/// it is rendered.
pub fn render_columns(
    scene: &Scene,
    s: &View,
    first: usize,
    count: usize,
    cancel: &AtomicBool,
    on_pixel: &(dyn Fn() + Sync),
) -> Option<Vec<Vec<PixelResult>>> {
    let h = s.height;
    // The parts of the view (one, or the slices of a strip) that the
    // columns cross, with their tracers; one parallel loop over them all.
    let parts: Vec<(usize, View, PixelTracers)> = s
        .parts()
        .into_iter()
        .filter(|(start, v)| *start < first + count && start + v.width > first)
        .map(|(start, v)| {
            let t = PixelTracers::new(scene, &v);
            (start, v, t)
        })
        .collect();
    // Column-major: pixel i is row i % h of column first + i / h.
    let flat = par_pixels(count * h, cancel, on_pixel, |i| {
        let (c, row) = (first + i / h, i % h);
        let (start, v, tracers) = parts.iter().rev().find(|(start, _, _)| *start <= c).expect("the columns' parts");
        render_pixel_with(tracers, scene, v, row * v.width + c - start, cancel)
    })?;
    let flat: Vec<PixelResult> = flat.into_iter().map(|(r, _)| r).collect();
    Some(flat.chunks(h).map(|c| c.to_vec()).collect())
}

/// A rendered image, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    pub width: usize,
    pub height: usize,
    pub pixels: Vec<PixelResult>,
}

/// Why a render stopped early.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error("render cancelled")]
    Cancelled,
}

/// Renders every pixel on the current rayon pool. `on_pixel` is called after
/// each pixel (for progress); `cancel` stops the render.
pub fn render(
    scene: &Scene,
    s: &View,
    cancel: &AtomicBool,
    on_pixel: &(dyn Fn() + Sync),
) -> Result<Image, RenderError> {
    render_timed(scene, s, cancel, on_pixel).map(|(image, _)| image)
}

/// [`render`], with the seconds each pixel took on its thread (what a
/// bake's forecast weighs each texel's samples by); 0 for every pixel of a
/// view of several parts (a strip), which renders by columns.
pub fn render_timed(
    scene: &Scene,
    s: &View,
    cancel: &AtomicBool,
    on_pixel: &(dyn Fn() + Sync),
) -> Result<(Image, Vec<f64>), RenderError> {
    let n = s.width * s.height;
    if s.parts().len() > 1 {
        let columns = render_columns(scene, s, 0, s.width, cancel, on_pixel).ok_or(RenderError::Cancelled)?;
        let pixels = (0..s.height).flat_map(|y| columns.iter().map(move |c| c[y].clone())).collect();
        return Ok((Image { width: s.width, height: s.height, pixels }, vec![0.0; n]));
    }
    let tracers = PixelTracers::new(scene, s);
    // Row-major: pixel i is the view's pixel i.
    let pixels = par_pixels(n, cancel, on_pixel, |i| render_pixel_with(&tracers, scene, s, i, cancel))
        .ok_or(RenderError::Cancelled)?;
    let (pixels, seconds) = pixels.into_iter().unzip();
    Ok((Image { width: s.width, height: s.height, pixels }, seconds))
}
