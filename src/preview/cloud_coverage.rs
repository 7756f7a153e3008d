//! The coverage texture of the clouds (the talk's "Coverage Texture"):
//! 256 × 128 RGBA, x the cumulus map's density, y the height in the cloud
//! layer; R height modulation, G and B the low- and mid-frequency noises'
//! weights, A the share of the sky's ambient light. Generated here
//! ([`default_coverage`]) or painted by an artist as a PNG
//! ([`coverage_from_png`]; [`write_coverage_png`] writes the generated one
//! as a starting point).

use super::PreviewError;
use std::path::Path;

/// The coverage texture's size (the talk's 256 × 128).
pub const COVERAGE_WIDTH: u32 = 256;
pub const COVERAGE_HEIGHT: u32 = 128;

/// The generated coverage texture, RGBA8 rows from the cloud base (row 0)
/// up: R height modulation (a cumulus profile whose top rises with the
/// map's density: base at 0, top at 0.15 + 0.85 d of the layer, rounded
/// above and flat below), G and B the low- and mid-frequency noises'
/// weights (more erosion toward the top), A the share of the sky's ambient
/// light (0.3 at the base to 1 at the top).
pub fn default_coverage() -> Vec<[u8; 4]> {
    let mut out = Vec::with_capacity((COVERAGE_WIDTH * COVERAGE_HEIGHT) as usize);
    let smooth = |e0: f64, e1: f64, x: f64| {
        let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
        t * t * (3.0 - 2.0 * t)
    };
    for j in 0..COVERAGE_HEIGHT {
        let h = (j as f64 + 0.5) / COVERAGE_HEIGHT as f64;
        for i in 0..COVERAGE_WIDTH {
            let d = i as f64 / (COVERAGE_WIDTH - 1) as f64;
            let top = 0.15 + 0.85 * d;
            let profile = smooth(0.0, 0.05, h) * (1.0 - smooth(0.55 * top, top, h));
            let r = (1.3 * d).min(1.0) * profile;
            let g = 0.35 + 0.4 * h;
            let b = 0.2 + 0.2 * h;
            let a = 0.3 + 0.7 * h;
            out.push([r, g, b, a].map(|x| (x.clamp(0.0, 1.0) * 255.0).round() as u8));
        }
    }
    out
}

/// An artist's coverage texture: a 256 × 128 RGBA PNG, row 0 at the top
/// of the image being the cloud top (as it is painted, height upward).
pub fn coverage_from_png(path: &Path) -> Result<Vec<[u8; 4]>, PreviewError> {
    let image = image::open(path).map_err(|e| PreviewError::Bake(format!("{}: {e}", path.display())))?.to_rgba8();
    if image.width() != COVERAGE_WIDTH || image.height() != COVERAGE_HEIGHT {
        return Err(PreviewError::Bake(format!(
            "{}: a coverage texture is {COVERAGE_WIDTH} x {COVERAGE_HEIGHT}, this is {} x {}",
            path.display(),
            image.width(),
            image.height()
        )));
    }
    let mut out = Vec::with_capacity((COVERAGE_WIDTH * COVERAGE_HEIGHT) as usize);
    for j in (0..COVERAGE_HEIGHT).rev() {
        for i in 0..COVERAGE_WIDTH {
            out.push(image.get_pixel(i, j).0);
        }
    }
    Ok(out)
}

/// The coverage as a PNG as an artist paints it (height upward), for a
/// starting point.
pub fn write_coverage_png(path: &Path, coverage: &[[u8; 4]]) -> Result<(), PreviewError> {
    let mut image = image::RgbaImage::new(COVERAGE_WIDTH, COVERAGE_HEIGHT);
    for (k, px) in coverage.iter().enumerate() {
        let (i, j) = (k as u32 % COVERAGE_WIDTH, k as u32 / COVERAGE_WIDTH);
        image.put_pixel(i, COVERAGE_HEIGHT - 1 - j, image::Rgba(*px));
    }
    image.save(path).map_err(|e| PreviewError::Bake(format!("{}: {e}", path.display())))
}
