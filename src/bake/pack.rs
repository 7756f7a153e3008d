//! Packing a bake: each basis sky's 64 rendered XYZ slices become one
//! R11G11B10F 2-D array texture (KTX2, vkFormat 122) in the chosen linear
//! RGB space, and the bake's `manifest.json` says how to read them.
//!
//! Scale: one power of two per slice, recorded in the manifest as
//! `scale_log2` (stored = value · 2^scale_log2), chosen so that the slice's
//! largest channel lands in (2^14, 2^15]. Sky luminance spans 1e-3 cd/m²
//! (the sun 10° below the horizon) to beyond 1e5 (the aureole), more than
//! the format's normal range (2^-14 to 65024) with room to spare at either
//! end; per slice, the range left is the slice's own (rarely above 1e6),
//! so nearly nothing falls into denormals and nothing clamps. A power of
//! two changes no mantissa: scaling is exact, and the decoder undoes it per
//! slice before it interpolates between slices.
//!
//! The files depend only on the rendered texels (never on timings or
//! paths), so a bake from the cache, a resumed bake and a fresh one write
//! the same bytes.

use super::lighting::SkyLighting;
use super::run::SkySlices;
use super::BakeError;
use crate::colour::ColourSpace;
use crate::directions::mapping;
use crate::lut::ambient::{self, Ambient};
use crate::lut::container::{self, Container, Encoding, Packed, TextureFormat};
use crate::lut::ktx2::{self, ArrayTexture};
use crate::lut::manifest::{self, Manifest, SkyEntry, SliceEntry, SunEntry, TransmittanceEntry};
use crate::lut::r11g11b10::PackStats;
use crate::lut::texels::Texels;
use crate::lut::{integrity, rgba16f, transmittance};
use std::path::Path;

/// The largest channel of a slice is scaled into (2^(TOP - 1), 2^TOP].
const TOP_LOG2: i32 = 15;

/// The exponent k with max · 2^k in (2^14, 2^15] (0 for a black slice).
pub fn slice_scale_log2(max_value: f64) -> i32 {
    if !(max_value > 0.0) || !max_value.is_finite() {
        return 0;
    }
    let k = TOP_LOG2 - max_value.log2().ceil() as i32;
    k.clamp(-60, 60)
}

/// What packing one basis sky produced, in memory.
pub struct PackedSky {
    pub entry: SkyEntry,
    pub stats: PackStats,
    /// The array's texels, layer after layer.
    texels: Packed,
    /// The file's own manifest entry (its `sky` key).
    sky_json: String,
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Packs one basis sky (every slice present) in memory in `format`, for
/// `container`; a texel that is not finite is an error naming it.
pub fn pack_sky(
    s: &SkySlices,
    colour: ColourSpace,
    (format, container): (TextureFormat, Container),
) -> Result<PackedSky, BakeError> {
    let (w, h) = (s.sky.width, s.sky.height);
    let mut scaled = Vec::with_capacity(w * h * s.slices.len());
    let mut negative = 0;
    let mut slices = Vec::new();
    for (index, slice) in s.slices.iter().enumerate() {
        let slice = slice.as_ref().expect("pack_sky needs every slice");
        let (rgb, clamp) = colour.convert_array(&slice.xyz);
        negative += clamp.negative_texels;
        let max = rgb.iter().flatten().copied().filter(|v| v.is_finite()).fold(0.0, f64::max);
        let k = slice_scale_log2(max);
        let scale = (k as f64).exp2();
        scaled.extend(rgb.iter().map(|p| p.map(|c| c * scale)));
        let rel: Vec<f64> =
            slice.xyz.iter().zip(&slice.xyz_stderr).filter(|(x, _)| x[1] > 0.0).map(|(x, e)| e[1] / x[1]).collect();
        slices.push(SliceEntry {
            index,
            sun_zenith_deg: slice.sun_zenith_deg,
            scale_log2: k,
            mean_samples: slice.mean_samples(),
            median_rel_stderr_y: median(rel),
        });
    }
    // Ambient light of each slice, from its rendered XYZ read as the
    // decoder reads it, in the bake's colour space.
    let to_rgb = colour.xyz_to_rgb();
    let ambient: Vec<Ambient> = s
        .slices
        .iter()
        .map(|slice| {
            let slice = slice.as_ref().expect("pack_sky needs every slice");
            let m = mapping::DirectionMapping::new(slice.sun_zenith_deg, s.threshold_deg);
            ambient::of_slice(&slice.xyz, w, h, &m).transformed(&to_rgb)
        })
        .collect();
    // Every slice at once, layer after layer; a texel that is not finite
    // named by its slice and (u, v).
    let (texels, stats) = container::pack_array(format, &scaled).map_err(|e| BakeError::NotFinite {
        sky: s.sky.name.clone(),
        index: e.texel / (w * h),
        u: e.texel % w,
        v: (e.texel % (w * h)) / w,
        what: "RGB",
    })?;
    let entry = SkyEntry {
        name: s.sky.name.clone(),
        file: container.file_name(&s.sky.name),
        format: format.vulkan_name().into(),
        vk_format: format.vk_format(),
        bytes: 0,
        width: w,
        height: h,
        layers: s.slices.len(),
        atmosphere: s.atmosphere_name.clone(),
        atmosphere_hash: s.atmosphere_hash.clone(),
        altitude_m: s.sky.altitude_m,
        planet_radius_km: s.radius_km,
        top_km: s.top_km,
        d_min_km: s.top_km,
        d_max_km: mapping::horizontal_distance_km(s.radius_km, s.top_km),
        threshold_sun_zenith_deg: s.threshold_deg,
        slices,
        texels_clamped: stats.clamped_texels,
        texels_denormal: stats.denormal_texels,
        texels_negative_rgb: negative,
        sun: s.lighting.as_ref().map(|l| sun_entry(l, colour)),
        ambient: Some(ambient),
    };
    // The file carries its own manifest entry under the `sky` key, less
    // its size (which the file cannot know) and the sun and ambient light
    // (the manifest's, about 50 KB a sky: not what identifies the texels).
    let mut inner = serde_json::to_value(&entry).expect("an entry always serialises");
    let object = inner.as_object_mut().expect("an object");
    for key in ["bytes", "sun", "ambient"] {
        object.remove(key);
    }
    let sky_json = inner.to_string();
    Ok(PackedSky { entry, stats, texels, sky_json })
}

impl PackedSky {
    /// Writes its file in `dir` (through a temporary file and a rename)
    /// and records its size in the entry.
    pub fn write(&mut self, colour: ColourSpace, container: Container, dir: &Path) -> Result<(), BakeError> {
        let e = &self.entry;
        let tex = ArrayTexture {
            width: e.width as u32,
            height: e.height as u32,
            layers: e.layers as u32,
            colour_space: colour,
            texels: self.texels.texels(),
            sky_json: &self.sky_json,
        };
        self.entry.bytes = container::write(container, &dir.join(&e.file), &tex).map_err(BakeError::Write)?;
        Ok(())
    }
}

/// The sun of a basis sky's lighting, in the manifest's colour space (its
/// transmittance layer is set once the layers are known).
fn sun_entry(l: &SkyLighting, colour: ColourSpace) -> SunEntry {
    let m = colour.xyz_to_rgb();
    SunEntry {
        angular_diameter_deg: l.sun_angular_diameter_deg,
        solid_angle_sr: l.sun_solid_angle_sr(),
        top_irradiance_xyz: l.transmittance.top_xyz,
        top_irradiance_rgb: crate::colour::apply(&m, l.transmittance.top_xyz),
        transmittance_layer: 0,
        irradiance_xyz: l.irradiance_xyz.clone(),
        irradiance_rgb: l.irradiance_xyz.iter().map(|x| crate::colour::apply(&m, *x)).collect(),
    }
}

/// The transmittance file of the skies' lighting: one RGBA16F layer per
/// basis sky, in `dir`; records each sky's layer in its entry.
fn write_transmittance(
    skies: &[SkySlices],
    entries: &mut [SkyEntry],
    (colour, container): (ColourSpace, Container),
    dir: &Path,
) -> Result<Option<TransmittanceEntry>, BakeError> {
    let Some(lightings) = skies.iter().map(|s| s.lighting.as_ref()).collect::<Option<Vec<_>>>() else {
        return Ok(None);
    };
    let Some(first) = lightings.first() else { return Ok(None) };
    if let Some(k) = lightings.iter().position(|l| l.transmittance.mapping != first.transmittance.mapping) {
        return Err(BakeError::Write(format!(
            "the transmittance file is one mapping for all basis skies, but {}'s planet radius or top differ from {}'s",
            skies[k].sky.name, skies[0].sky.name
        )));
    }
    let m = colour.xyz_to_rgb();
    let mut halves = Vec::with_capacity(transmittance::WIDTH * transmittance::HEIGHT * lightings.len());
    for (k, l) in lightings.iter().enumerate() {
        let (packed, _) = rgba16f::pack_array(&l.transmittance.channel_texels(&m)).map_err(|e| {
            BakeError::Write(format!("{}: transmittance texel {}: {}", skies[k].sky.name, e.texel, e.source))
        })?;
        halves.extend(packed);
        if let Some(sun) = &mut entries[k].sun {
            sun.transmittance_layer = k;
        }
    }
    let t = &first.transmittance.mapping;
    let mut entry = TransmittanceEntry {
        file: container.file_name("transmittance"),
        format: "R16G16B16A16_SFLOAT".into(),
        vk_format: ktx2::VK_FORMAT_R16G16B16A16_SFLOAT,
        bytes: 0,
        width: transmittance::WIDTH,
        height: transmittance::HEIGHT,
        layers: skies.iter().map(|s| s.sky.name.clone()).collect(),
        mapping: format!(
            "Bruneton 2017 (GetTransmittanceTextureUvFromRMu): R = {} km, R_top = {} km, H = sqrt(R_top^2 - R^2), rho = sqrt(r^2 - R^2), d = distance to R_top along mu; x_r = rho / H, x_mu = (d - d_min) / (d_max - d_min), d_min = R_top - r, d_max = rho + H; texel i of n holds x = i / (n - 1) (u = 0.5 / n + x (1 - 1 / n)); below mu = -rho / r the ray meets the ground: 0",
            t.bottom_radius_km, t.top_radius_km
        ),
        channels: "RGB: the transmittance of the sun's own spectrum to the top of the atmosphere per channel of the manifest's colour space (irradiance = sun.top_irradiance_rgb * T); a channel the sun's colour leaves the space's gamut in (blue, with the sun within a degree or two of the horizon, in Rec.709) is 0; A = 1".into(),
    };
    let json = serde_json::to_string(&entry).expect("an entry always serialises");
    let tex = ArrayTexture {
        width: entry.width as u32,
        height: entry.height as u32,
        layers: lightings.len() as u32,
        colour_space: colour,
        texels: Texels::Rgba16f(&halves),
        sky_json: &json,
    };
    entry.bytes = container::write(container, &dir.join(&entry.file), &tex).map_err(BakeError::Write)?;
    Ok(Some(entry))
}

/// Pretty JSON with every array of plain numbers on one line (`[1.0, 2.0,
/// 3.0]`): the per-slice colours and harmonics would otherwise take a line
/// a number. Brackets inside strings are left alone.
fn compact_number_arrays(pretty: &str) -> String {
    let b = pretty.as_bytes();
    let mut out = String::with_capacity(pretty.len());
    let (mut i, mut copied, mut in_string, mut escaped) = (0, 0, false, false);
    while i < b.len() {
        let c = b[i];
        if in_string {
            (escaped, in_string) = (!escaped && c == b'\\', escaped || c != b'"');
        } else if c == b'"' {
            in_string = true;
        } else if c == b'[' {
            if let Some(len) = pretty[i + 1..].find(']') {
                let inner = &pretty[i + 1..i + 1 + len];
                if !inner.trim().is_empty() && inner.bytes().all(|c| c.is_ascii_digit() || b" \n,.-+eE".contains(&c)) {
                    out.push_str(&pretty[copied..i]);
                    out.push('[');
                    out.push_str(&inner.split(',').map(str::trim).collect::<Vec<_>>().join(", "));
                    out.push(']');
                    i += len + 2;
                    copied = i;
                    continue;
                }
            }
        }
        i += 1;
    }
    out.push_str(&pretty[copied..]);
    out
}

/// The manifest of packed skies.
pub fn manifest(quality: &str, colour: ColourSpace, skies: Vec<SkyEntry>) -> Manifest {
    Manifest {
        format: manifest::FORMAT.into(),
        version: manifest::VERSION,
        generator: format!("sky {}", crate::VERSION),
        quality: quality.into(),
        units: manifest::Units {
            luminance: "cd/m^2: Y of CIE 1931 XYZ (radiance x 683 lm/W); RGB is the colour space's linear RGB of that XYZ".into(),
            scale: "value = stored * 2^-scale_log2, with the scale_log2 of the texel's slice; applied to each slice before slices are interpolated".into(),
        },
        colour: manifest::Colour {
            space: colour.name().into(),
            rgb_from_xyz: colour.xyz_to_rgb(),
            xyz_from_rgb: colour.rgb_to_xyz(),
            note: "negative RGB (XYZ outside the space's gamut) is clamped to 0 and counted per sky in texels_negative_rgb".into(),
        },
        time_mapping: manifest::time_mapping(),
        direction_mapping: manifest::direction_mapping(),
        weather: manifest::weather(),
        skies,
        method: None,
        container: None,
        transmittance: None,
        fog: None,
        ambient_file: None,
        files: None,
        manifest_sha256: None,
    }
}

/// Packs every basis sky into `dir` and writes `dir/manifest.json` last
/// (each file through a temporary file and a rename).
pub fn write_bake(
    skies: &[SkySlices],
    (quality, method): (&str, super::Method),
    (colour, encoding): (ColourSpace, Encoding),
    dir: &Path,
) -> Result<(Manifest, Vec<PackStats>), BakeError> {
    let container = encoding.container;
    // Every sky packed before any file is written: a texel that is not
    // finite leaves no file behind.
    let mut packed = skies
        .iter()
        .map(|s| pack_sky(s, colour, (encoding.texture_format, container)))
        .collect::<Result<Vec<_>, _>>()?;
    let fog = super::pack_fog::pack_fog(skies, colour)?;
    std::fs::create_dir_all(dir).map_err(|e| BakeError::Write(format!("{}: {e}", dir.display())))?;
    // A manifest of an earlier bake here goes first: while the files are
    // replaced, none names them.
    let path = dir.join("manifest.json");
    match std::fs::remove_file(&path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
            return Err(BakeError::Write(format!("{}: {e}", path.display())))
        }
        _ => {}
    }
    let mut entries = Vec::new();
    let mut stats = Vec::new();
    for p in &mut packed {
        p.write(colour, container, dir)?;
    }
    for p in packed {
        entries.push(p.entry);
        stats.push(p.stats);
    }
    let transmittance = write_transmittance(skies, &mut entries, (colour, container), dir)?;
    let ambient_file = super::pack_ambient::write_ambient(&entries, (colour, container), dir)?;
    let mut m = manifest(quality, colour, entries);
    m.method = Some(method.name().into());
    m.container = Some(container.name().into());
    m.transmittance = transmittance;
    m.ambient_file = ambient_file;
    m.fog = match fog {
        Some(f) => Some(f.write((colour, container), dir)?),
        None => None,
    };
    // Every file's size and digest as written, then the manifest's own.
    let files = m.named_files().into_iter().map(|name| {
        integrity::file_entry(dir, name).map_err(|e| BakeError::Write(format!("{}: {e}", dir.join(name).display())))
    });
    m.files = Some(files.collect::<Result<_, _>>()?);
    m.manifest_sha256 = Some(integrity::UNSEALED.into());
    let text = compact_number_arrays(&serde_json::to_string_pretty(&m).expect("a manifest always serialises"));
    let (text, digest) = integrity::seal(&text);
    m.manifest_sha256 = Some(digest);
    crate::atomic::write_atomically(&path, text.as_bytes())
        .map_err(|e| BakeError::Write(format!("{}: {e}", path.display())))?;
    Ok((m, stats))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn number_arrays_go_on_one_line_and_strings_stay() {
        let v = serde_json::json!({ "a": [1.0, -2.5e-7, 3], "s": "in [0,1] \\\" [2,3]", "m": [[1, 2], [3, 4]], "e": [], "o": [{ "x": 1 }] });
        let text = compact_number_arrays(&serde_json::to_string_pretty(&v).unwrap());
        assert!(text.contains("\"a\": [1.0, -2.5e-7, 3]"), "{text}");
        assert!(text.contains("[1, 2]") && text.contains("[3, 4]"), "{text}");
        assert_eq!(serde_json::from_str::<serde_json::Value>(&text).unwrap(), v);
    }

    #[test]
    fn slice_scales_put_the_maximum_just_below_2_to_the_15() {
        for max in [1e-3, 0.7, 1.0, 2.0, 3.0, 32768.0, 32769.0, 1e5, 3e6] {
            let k = slice_scale_log2(max);
            let top = max * (k as f64).exp2();
            assert!(top > 16384.0 && top <= 32768.0, "{max}: k {k}, top {top}");
        }
        assert_eq!(slice_scale_log2(0.0), 0);
        assert_eq!(slice_scale_log2(f64::NAN), 0);
    }
}
