//! `ambient.ktx2`: every basis sky's ambient light per slice (`lut::ambient`:
//! upward irradiance, mean radiance, order-2 spherical harmonics) as a
//! texture a shader reads, besides the manifest's numbers (issue 13: "All of
//! them in the manifest ... and in KTX2"). RGBA16F with signed halves (the
//! harmonics are signed), a layer per basis sky of 64 columns (slices) by
//! 11 rows, one power-of-two scale per layer (its largest magnitude into
//! (2^14, 2^15], as the sky slices'), since skylight irradiance reaches
//! 10^4 to 10^5 lux and binary16 stops at 65504.

use super::pack::slice_scale_log2;
use super::BakeError;
use crate::colour::ColourSpace;
use crate::lut::container::{self, Container};
use crate::lut::ktx2::{ArrayTexture, VK_FORMAT_R16G16B16A16_SFLOAT};
use crate::lut::manifest::{AmbientFileEntry, SkyEntry};
use crate::lut::rgba16f;
use crate::lut::texels::Texels;
use std::path::Path;

/// The rows of a layer.
pub const ROWS: [&str; 11] =
    ["irradiance_up", "mean_radiance", "L00", "L1-1", "L10", "L11", "L2-2", "L2-1", "L20", "L21", "L22"];

/// Writes `dir/ambient.ktx2` (or `.dds`) from the skies' manifest entries (None when
/// a sky has no ambient light, or the skies differ in slice count).
pub fn write_ambient(
    entries: &[SkyEntry],
    (colour, container): (ColourSpace, Container),
    dir: &Path,
) -> Result<Option<AmbientFileEntry>, BakeError> {
    let Some(ambients) = entries.iter().map(|e| e.ambient.as_ref()).collect::<Option<Vec<_>>>() else {
        return Ok(None);
    };
    let Some(slices) = ambients.first().map(|a| a.len()) else { return Ok(None) };
    if slices == 0 || ambients.iter().any(|a| a.len() != slices) {
        return Ok(None);
    }
    let (mut halves, mut scales) = (Vec::new(), Vec::new());
    for (e, a) in entries.iter().zip(&ambients) {
        let rows: Vec<Vec<[f64; 3]>> = (0..ROWS.len())
            .map(|r| {
                a.iter()
                    .map(|s| match r {
                        0 => s.irradiance_up,
                        1 => s.mean_radiance,
                        k => s.sh9[k - 2],
                    })
                    .collect()
            })
            .collect();
        let max = rows.iter().flatten().flatten().map(|v| v.abs()).filter(|v| v.is_finite()).fold(0.0, f64::max);
        let k = slice_scale_log2(max);
        let scale = (k as f64).exp2();
        for (r, row) in rows.iter().enumerate() {
            for (i, v) in row.iter().enumerate() {
                let h = rgba16f::pack_signed(v.map(|c| c * scale)).map_err(|_| BakeError::NotFinite {
                    sky: e.name.clone(),
                    index: i,
                    u: i,
                    v: r,
                    what: "ambient light",
                })?;
                halves.push(h);
            }
        }
        scales.push(k);
    }
    let mut entry = AmbientFileEntry {
        file: container.file_name("ambient"),
        format: "R16G16B16A16_SFLOAT".into(),
        vk_format: VK_FORMAT_R16G16B16A16_SFLOAT,
        bytes: 0,
        width: slices,
        height: ROWS.len(),
        layers: entries.iter().map(|e| e.name.clone()).collect(),
        rows: ROWS.iter().map(|r| r.to_string()).collect(),
        scale_log2: scales,
    };
    let json = serde_json::to_string(&entry).expect("an entry always serialises");
    let tex = ArrayTexture {
        width: entry.width as u32,
        height: entry.height as u32,
        layers: entries.len() as u32,
        colour_space: colour,
        texels: Texels::Rgba16f(&halves),
        sky_json: &json,
    };
    entry.bytes = container::write(container, &dir.join(&entry.file), &tex).map_err(BakeError::Write)?;
    Ok(Some(entry))
}
