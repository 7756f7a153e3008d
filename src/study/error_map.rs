//! Pictures of a LUT's interpolation error, for people: a fisheye of the
//! relative luminance error over the sky in false colour, and a slice as
//! it is stored (the texture itself).

use crate::directions::camera::Camera;
use crate::lut::decode::Texture;
use crate::render::{Image, PixelResult};
use glam::DVec3;
use rayon::prelude::*;
use std::path::Path;

/// The false-colour ramp of [`error_fisheye`]: relative error (log10) and
/// colour at each stop; linear in log10 between stops.
pub const RAMP: [(f64, [u8; 3]); 6] = [
    (-4.0, [0, 0, 0]),      // 0.01 %
    (-3.0, [30, 40, 160]),  // 0.1 %
    (-2.0, [20, 170, 80]),  // 1 %
    (-1.3, [240, 220, 30]), // 5 %
    (-1.0, [220, 40, 30]),  // 10 %
    (0.0, [255, 255, 255]), // 100 % and above
];

/// The ramp's colour for a relative error.
pub fn ramp(rel: f64) -> [u8; 3] {
    let x = rel.max(1e-12).log10();
    if x <= RAMP[0].0 {
        return RAMP[0].1;
    }
    for w in RAMP.windows(2) {
        let ((x0, c0), (x1, c1)) = (w[0], w[1]);
        if x <= x1 {
            let t = (x - x0) / (x1 - x0);
            return [0, 1, 2].map(|k| (c0[k] as f64 + t * (c1[k] as f64 - c0[k] as f64)).round() as u8);
        }
    }
    RAMP[RAMP.len() - 1].1
}

/// A fisheye (zenith at the centre, the horizon at the rim, grey outside)
/// of |decoded / truth − 1| in Y, `size` pixels square; `decoded` and
/// `truth` give Y toward a direction (world frame, z up).
pub fn error_fisheye(
    size: usize,
    decoded: &(dyn Fn(DVec3) -> f64 + Sync),
    truth: &(dyn Fn(DVec3) -> f64 + Sync),
) -> Vec<u8> {
    (0..size * size)
        .into_par_iter()
        .flat_map_iter(|i| {
            let (x, y) = (i % size, i / size);
            let c = match Camera::Fisheye.direction(x as f64 + 0.5, y as f64 + 0.5, size, size) {
                Some(d) => {
                    let t = truth(d);
                    if t > 0.0 {
                        ramp((decoded(d) - t).abs() / t)
                    } else {
                        [90, 90, 90]
                    }
                }
                None => [90, 90, 90],
            };
            c.into_iter()
        })
        .collect()
}

/// A colour bar of the ramp, `width` × `height` pixels, 0.01 % at the left
/// to 100 % at the right.
pub fn ramp_bar(width: usize, height: usize) -> Vec<u8> {
    let row: Vec<u8> =
        (0..width).flat_map(|x| ramp(10f64.powf(-4.0 + 4.0 * (x as f64 + 0.5) / width as f64))).collect();
    (0..height).flat_map(|_| row.iter().copied()).collect()
}

/// Writes 8-bit RGB pixels as a PNG, whole or not at all.
pub fn write_rgb_png(path: &Path, width: usize, height: usize, rgb: Vec<u8>) -> std::io::Result<()> {
    let img = image::RgbImage::from_raw(width as u32, height as u32, rgb)
        .ok_or_else(|| std::io::Error::other("image size"))?;
    let mut png = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .map_err(|e| std::io::Error::other(e.to_string()))?;
    crate::atomic::write_atomically(path, &png)
}

/// A stored slice (XYZ texels, rows of v top to bottom) as an image, each
/// texel a `zoom` × `zoom` block, for `render::output::write_png`.
pub fn slice_image(texture: &Texture, layer: usize, zoom: usize) -> Image {
    let (w, h) = (texture.width * zoom, texture.height * zoom);
    let pixels = (0..w * h)
        .map(|i| {
            let (x, y) = ((i % w) / zoom, (i / w) / zoom);
            let t = texture.layers[layer][y * texture.width + x];
            PixelResult::from_xyz(t.map(f64::from))
        })
        .collect();
    Image { width: w, height: h, pixels }
}

/// A fisheye of a sky given as XYZ toward a direction, for
/// `render::output::write_png`.
pub fn sky_fisheye(size: usize, xyz: &(dyn Fn(DVec3) -> [f64; 3] + Sync)) -> Image {
    let pixels = (0..size * size)
        .into_par_iter()
        .map(|i| {
            PixelResult::from_xyz(
                Camera::Fisheye
                    .direction((i % size) as f64 + 0.5, (i / size) as f64 + 0.5, size, size)
                    .map_or([0.0; 3], xyz),
            )
        })
        .collect();
    Image { width: size, height: size, pixels }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ramp_hits_its_stops_and_a_perfect_decode_is_black() {
        for (x, c) in RAMP {
            assert_eq!(ramp(10f64.powf(x)), c);
        }
        assert_eq!(ramp(0.0), RAMP[0].1);
        assert_eq!(ramp(50.0), RAMP[5].1);
        let bar = ramp_bar(64, 2);
        assert_eq!(bar.len(), 64 * 2 * 3);
        let perfect = error_fisheye(8, &|_| 1.0, &|_| 1.0);
        assert!(perfect.chunks(3).all(|c| c == [0, 0, 0] || c == [90, 90, 90]));
    }
}
