//! Writing renders: OpenEXR (X, Y, Z, their standard errors, spectral
//! channels, metadata) and a tonemapped PNG for people. Files are written
//! to a temporary file in the target directory and renamed into place.

use super::Image;
use exr::prelude::*;
use std::path::Path;

/// Metadata stored as text attributes in the EXR header.
pub type Metadata = Vec<(String, String)>;

/// Writes the image as a single-layer OpenEXR with f32 channels.
/// With `noisy`, X, Y, Z are the denoised values and the image before
/// denoising is kept in `noisy.X`, `noisy.Y`, `noisy.Z`. Without `xyz`
/// (a render of spectral lines only) there are no X, Y, Z channels.
pub fn write_exr(
    path: &Path,
    img: &Image,
    noisy: Option<&Image>,
    xyz: bool,
    spectral_nm: &[f64],
    metadata: &Metadata,
) -> std::io::Result<()> {
    let (w, h) = (img.width, img.height);
    let chan = |name: String, f: &dyn Fn(&super::PixelResult) -> f64| {
        AnyChannel::new(name.as_str(), FlatSamples::F32(img.pixels.iter().map(|p| f(p) as f32).collect()))
    };
    let mut list: Vec<AnyChannel<FlatSamples>> = Vec::new();
    for (c, name) in ["X", "Y", "Z"].iter().enumerate().filter(|_| xyz) {
        list.push(chan(name.to_string(), &move |p| p.xyz[c]));
        list.push(chan(format!("stderr.{name}"), &move |p| p.xyz_stderr[c]));
    }
    list.push(chan("samples".to_string(), &|p| p.samples as f64));
    if let Some(raw) = noisy {
        for (c, name) in ["X", "Y", "Z"].iter().enumerate() {
            list.push(AnyChannel::new(
                format!("noisy.{name}").as_str(),
                FlatSamples::F32(raw.pixels.iter().map(|p| p.xyz[c] as f32).collect()),
            ));
        }
    }
    for (j, l) in spectral_nm.iter().enumerate() {
        list.push(chan(format!("spectral.{l}nm"), &move |p| p.spectral[j]));
        list.push(chan(format!("stderr.spectral.{l}nm"), &move |p| p.spectral_stderr[j]));
    }
    // One text attribute holding the metadata as JSON with sorted keys: the
    // header's other attributes live in a hash map whose order varies from
    // run to run, and renders must be byte-identical.
    let mut attrs = LayerAttributes::named("sky");
    let sorted: std::collections::BTreeMap<&str, &str> =
        metadata.iter().map(|(k, v)| (k.as_str(), v.as_str())).collect();
    let json = serde_json::to_string(&sorted).expect("serialisable");
    attrs.other.insert(Text::from("sky.metadata"), AttributeValue::Text(Text::from(json.as_str())));
    let layer = Layer::new((w, h), attrs, Encoding::FAST_LOSSLESS, AnyChannels::sort(SmallVec::from_vec(list)));
    let image = exr::image::Image::from_layer(layer);
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let tmp = tempfile::NamedTempFile::new_in(dir)?;
    image.write().to_file(tmp.path()).map_err(|e| std::io::Error::other(e.to_string()))?;
    tmp.as_file().sync_all()?;
    tmp.persist(path).map_err(|e| e.error)?;
    Ok(())
}

/// XYZ → linear sRGB (IEC 61966-2-1, D65; the matrix colour-science uses).
pub fn xyz_to_linear_srgb(xyz: [f64; 3]) -> [f64; 3] {
    const XYZ_TO_SRGB: crate::colour::Mat3 =
        [[3.2404542, -1.5371385, -0.4985314], [-0.9692660, 1.8760108, 0.0415560], [0.0556434, -0.2040259, 1.0572252]];
    crate::colour::apply(&XYZ_TO_SRGB, xyz)
}

fn srgb_oetf(v: f64) -> f64 {
    let v = v.clamp(0.0, 1.0);
    if v <= 0.0031308 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// Writes a tonemapped PNG: exposure set so the median luminance of the
/// pixels in view maps to 0.25 (times 2^exposure_ev), then a Reinhard
/// curve per channel and the sRGB transfer function. The image is
/// white-balanced by dividing by the sun's own XYZ chromaticity when given,
/// so sunlight looks white.
pub fn write_png(path: &Path, img: &Image, exposure_ev: f64, white_xyz: Option<[f64; 3]>) -> std::io::Result<()> {
    let mut lum: Vec<f64> = img.pixels.iter().map(|p| p.xyz[1]).filter(|y| *y > 0.0 && y.is_finite()).collect();
    lum.sort_by(f64::total_cmp);
    let median = lum.get(lum.len() / 2).copied().unwrap_or(1.0);
    write_png_scaled(path, img, 0.25 / median * 2f64.powf(exposure_ev), white_xyz)
}

/// The luminance (cd/m²) that a camera exposed at `ev100` saturates at:
/// L_max = 1.2 · 2^EV100 (the saturation-based sensitivity of ISO 12232
/// with S = 100, K = 12.5 and lens attenuation q = 0.65; Lagarde and de
/// Rousiers 2014, "Moving Frostbite to Physically Based Rendering", eq. 12).
pub fn saturation_luminance(ev100: f64) -> f64 {
    1.2 * 2f64.powf(ev100)
}

/// [`write_png`] with a fixed exposure: linear sRGB times `scale`, then
/// Reinhard and the sRGB transfer (a sequence at one exposure keeps the
/// brightness changes between its frames).
pub fn write_png_scaled(path: &Path, img: &Image, scale: f64, white_xyz: Option<[f64; 3]>) -> std::io::Result<()> {
    let balance = match white_xyz {
        Some(wh) => {
            let rgb = xyz_to_linear_srgb(wh);
            let m = rgb[1].max(1e-30);
            [m / rgb[0].max(1e-30), 1.0, m / rgb[2].max(1e-30)]
        }
        None => [1.0; 3],
    };
    let mut buf = Vec::with_capacity(img.width * img.height * 3);
    for p in &img.pixels {
        let rgb = xyz_to_linear_srgb(p.xyz);
        for c in 0..3 {
            let v = (rgb[c] * balance[c] * scale).max(0.0);
            buf.push((srgb_oetf(v / (1.0 + v)) * 255.0 + 0.5) as u8);
        }
    }
    let im = image::RgbImage::from_raw(img.width as u32, img.height as u32, buf)
        .ok_or_else(|| std::io::Error::other("image size"))?;
    let mut png = Vec::new();
    im.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .map_err(|e| std::io::Error::other(e.to_string()))?;
    crate::mie::cache::write_atomic(path, &png)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::PixelResult;

    /// A fixed exposure maps the saturation luminance of its EV100 to half
    /// of white before the sRGB transfer (Reinhard: 1 / (1 + 1)), whatever
    /// the rest of the image, and a luminance four times lower to 1/5.
    #[test]
    fn a_fixed_exposure_puts_the_saturation_luminance_at_half_of_white() {
        // D65 white (x, y = 0.3127, 0.3290) of luminance y: linear sRGB (y, y, y) to 4 digits.
        let grey = |y: f64| PixelResult::from_xyz([0.3127 / 0.3290 * y, y, (1.0 - 0.3127 - 0.3290) / 0.3290 * y]);
        let ev100 = 13.0;
        let l = saturation_luminance(ev100);
        assert!((l - 9830.4).abs() < 1e-9, "{l}");
        let image = Image { width: 3, height: 1, pixels: vec![grey(l), grey(l / 4.0), grey(1e6)] };
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("fixed.png");
        write_png_scaled(&path, &image, 1.0 / l, None).unwrap();
        let png = image::open(&path).unwrap().to_rgb8();
        let code = |v: f64| (srgb_oetf(v) * 255.0 + 0.5) as u8;
        for c in 0..3 {
            assert!(png.get_pixel(0, 0)[c].abs_diff(code(0.5)) <= 1, "{:?}", png.get_pixel(0, 0));
            assert!(png.get_pixel(1, 0)[c].abs_diff(code(0.2)) <= 1, "{:?}", png.get_pixel(1, 0));
        }
    }
}
