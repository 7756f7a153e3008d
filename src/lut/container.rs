//! The texture formats and containers a bake's files come in, and the one
//! place that writes and reads them.
//!
//! Texture formats (the basis skies' arrays; the transmittance, fog and
//! ambient files are always RGBA16F, which the ambient's signed harmonics
//! need and the small tables can afford):
//!
//! | name        | Vulkan (KTX2 vkFormat)             | Direct3D (DDS dxgiFormat)               | bytes a texel |
//! |-------------|------------------------------------|-----------------------------------------|---------------|
//! | `r11g11b10` | B10G11R11_UFLOAT_PACK32 (122)      | DXGI_FORMAT_R11G11B10_FLOAT (26)        | 4 |
//! | `rgba16f`   | R16G16B16A16_SFLOAT (97)           | DXGI_FORMAT_R16G16B16A16_FLOAT (10)     | 8 |
//!
//! Containers: `ktx2` ([`super::ktx2`], with the file's manifest entry in
//! its key/value data) and `dds` ([`super::dds`], DX10 header, no
//! metadata: the manifest says everything). Both hold one level of a 2-D
//! array in the same texel order ([`super::texels`]).
//!
//! Reading: KTX2 with the `ktx2` crate (independent of our writer); DDS
//! with the few lines of [`read_dds`] below, checked in the tests against
//! the `ddsfile` crate's reading of the same files.

use super::ktx2::{self, ArrayTexture, VK_FORMAT_B10G11R11_UFLOAT_PACK32, VK_FORMAT_R16G16B16A16_SFLOAT};
use super::texels::Texels;
use super::{dds, r11g11b10, rgba16f};
use std::path::Path;

/// The basis skies' texel format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TextureFormat {
    /// Packed unsigned floats, 4 bytes (the talk's format, the default).
    #[default]
    R11g11b10,
    /// Four halves, 8 bytes: for engines that cannot load R11G11B10 arrays.
    Rgba16f,
}

impl TextureFormat {
    pub const ALL: [TextureFormat; 2] = [TextureFormat::R11g11b10, TextureFormat::Rgba16f];

    /// The name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            TextureFormat::R11g11b10 => "r11g11b10",
            TextureFormat::Rgba16f => "rgba16f",
        }
    }

    /// The Vulkan format's name as the manifest records it.
    pub fn vulkan_name(self) -> &'static str {
        match self {
            TextureFormat::R11g11b10 => "B10G11R11_UFLOAT_PACK32",
            TextureFormat::Rgba16f => "R16G16B16A16_SFLOAT",
        }
    }

    /// Bytes of one texel.
    pub fn texel_bytes(self) -> usize {
        match self {
            TextureFormat::R11g11b10 => 4,
            TextureFormat::Rgba16f => 8,
        }
    }

    pub fn vk_format(self) -> u32 {
        match self {
            TextureFormat::R11g11b10 => VK_FORMAT_B10G11R11_UFLOAT_PACK32,
            TextureFormat::Rgba16f => VK_FORMAT_R16G16B16A16_SFLOAT,
        }
    }

    /// The format of a Vulkan format number, if it is one of ours.
    pub fn of_vk_format(vk_format: u32) -> Option<TextureFormat> {
        TextureFormat::ALL.into_iter().find(|f| f.vk_format() == vk_format)
    }
}

impl std::str::FromStr for TextureFormat {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        TextureFormat::ALL
            .into_iter()
            .find(|f| f.name() == s)
            .ok_or_else(|| format!("unknown texture format {s:?}: use r11g11b10 or rgba16f"))
    }
}

/// The file container of every texture of a bake.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Container {
    #[default]
    Ktx2,
    Dds,
}

impl Container {
    pub const ALL: [Container; 2] = [Container::Ktx2, Container::Dds];

    /// The name on the command line and in the manifest, and the files'
    /// extension.
    pub fn name(self) -> &'static str {
        match self {
            Container::Ktx2 => "ktx2",
            Container::Dds => "dds",
        }
    }

    /// `stem.ktx2` or `stem.dds`.
    pub fn file_name(self, stem: &str) -> String {
        format!("{stem}.{}", self.name())
    }

    /// The container a manifest names (absent: KTX2, the only one before
    /// the field was added).
    pub fn of_manifest(name: Option<&str>) -> Result<Container, String> {
        match name {
            None => Ok(Container::Ktx2),
            Some(n) => n.parse(),
        }
    }
}

impl std::str::FromStr for Container {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Container::ALL
            .into_iter()
            .find(|c| c.name() == s)
            .ok_or_else(|| format!("unknown container {s:?}: use ktx2 or dds"))
    }
}

/// How a bake stores its textures: the skies' format and every file's
/// container (the defaults: R11G11B10F in KTX2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Encoding {
    pub texture_format: TextureFormat,
    pub container: Container,
}

/// Texels packed in one format, owned.
#[derive(Debug, Clone)]
pub enum Packed {
    B10G11R11(Vec<u32>),
    Rgba16f(Vec<[u16; 4]>),
}

impl Packed {
    pub fn texels(&self) -> Texels<'_> {
        match self {
            Packed::B10G11R11(w) => Texels::B10G11R11(w),
            Packed::Rgba16f(h) => Texels::Rgba16f(h),
        }
    }
}

/// Packs non-negative linear RGB in `format`, each channel rounded once
/// from f64 (the same rounding rule in both, `super::minifloat`).
pub fn pack_array(
    format: TextureFormat,
    rgb: &[[f64; 3]],
) -> Result<(Packed, r11g11b10::PackStats), r11g11b10::PackArrayError> {
    Ok(match format {
        TextureFormat::R11g11b10 => {
            let (w, s) = r11g11b10::pack_array(rgb)?;
            (Packed::B10G11R11(w), s)
        }
        TextureFormat::Rgba16f => {
            let (h, s) = rgba16f::pack_array(rgb)?;
            (Packed::Rgba16f(h), s)
        }
    })
}

/// Writes `tex` to `path` in `container` (atomically: a temporary file
/// renamed); returns the file's size. DDS keeps no `sky_json`.
pub fn write(container: Container, path: &Path, tex: &ArrayTexture<'_>) -> Result<u64, String> {
    match container {
        Container::Ktx2 => ktx2::write(path, tex).map_err(|e| e.to_string()),
        Container::Dds => dds::write(path, tex.width, tex.height, tex.layers, &tex.texels).map_err(|e| e.to_string()),
    }
}

/// Level 0 of a 2-D array texture file, as stored.
#[derive(Debug, Clone, PartialEq)]
pub struct Level {
    pub vk_format: u32,
    pub width: usize,
    pub height: usize,
    pub layers: usize,
    pub data: Vec<u8>,
}

impl Level {
    /// The RGB of every texel, layer by layer (A dropped).
    pub fn rgb_layers(&self) -> Result<Vec<Vec<[f32; 3]>>, String> {
        let texels: Vec<[f32; 3]> = match TextureFormat::of_vk_format(self.vk_format) {
            Some(TextureFormat::R11g11b10) => self
                .data
                .chunks_exact(4)
                .map(|b| r11g11b10::unpack(u32::from_le_bytes([b[0], b[1], b[2], b[3]])))
                .collect(),
            Some(TextureFormat::Rgba16f) => self
                .data
                .chunks_exact(8)
                .map(|b| {
                    let v = rgba16f::unpack([0, 2, 4, 6].map(|i| u16::from_le_bytes([b[i], b[i + 1]])));
                    [v[0], v[1], v[2]]
                })
                .collect(),
            None => return Err(format!("vkFormat {} is not one this build reads (122 or 97)", self.vk_format)),
        };
        Ok(texels.chunks(self.width * self.height).map(<[[f32; 3]]>::to_vec).collect())
    }
}

/// Reads level 0 of the file at `path` in `container`; an error is the
/// message alone (the caller names the file).
pub fn read(container: Container, path: &Path) -> Result<Level, String> {
    let bytes = std::fs::read(path).map_err(|e| e.to_string())?;
    let level = match container {
        Container::Ktx2 => read_ktx2(&bytes)?,
        Container::Dds => read_dds(&bytes)?,
    };
    let format = TextureFormat::of_vk_format(level.vk_format)
        .ok_or_else(|| format!("vkFormat {} is not one this build reads (122 or 97)", level.vk_format))?;
    let expected = format.texel_bytes() * level.width * level.height * level.layers;
    if level.data.len() != expected {
        return Err(format!("level 0 holds {} bytes, not {expected}", level.data.len()));
    }
    Ok(level)
}

fn read_ktx2(bytes: &[u8]) -> Result<Level, String> {
    let r = ::ktx2::Reader::new(bytes).map_err(|e| format!("not a KTX2 file: {e:?}"))?;
    let h = r.header();
    let level = r.levels().next().ok_or("no level 0")?;
    Ok(Level {
        vk_format: h.format.map(|f| f.value()).unwrap_or(0),
        width: h.pixel_width as usize,
        height: h.pixel_height.max(1) as usize,
        layers: h.layer_count.max(1) as usize,
        data: level.data.to_vec(),
    })
}

/// A DDS file with the DX10 header, one level of a 2-D texture or array
/// ([`super::dds`] describes the layout); the legacy pixel formats and
/// anything but R11G11B10_FLOAT and R16G16B16A16_FLOAT are refused.
pub fn read_dds(bytes: &[u8]) -> Result<Level, String> {
    let u32_at = |at: usize| -> u32 { u32::from_le_bytes(bytes[at..at + 4].try_into().expect("4 bytes")) };
    if bytes.len() < dds::HEADER_BYTES || &bytes[..4] != b"DDS " {
        return Err("not a DDS file (no \"DDS \" and 148-byte DX10 header)".into());
    }
    if u32_at(4) != 124 || u32_at(76) != 32 {
        return Err(format!("DDS header size {} and pixel format size {}, not 124 and 32", u32_at(4), u32_at(76)));
    }
    if &bytes[84..88] != b"DX10" {
        return Err("a DDS file without the DX10 header: only DXGI formats 26 and 10 are read".into());
    }
    let (height, width, mips) = (u32_at(12) as usize, u32_at(16) as usize, u32_at(28));
    let (dxgi, dimension, layers) = (u32_at(128), u32_at(132), u32_at(140) as usize);
    if dimension != 3 || mips > 1 || width == 0 || height == 0 || layers == 0 {
        return Err(format!(
            "a DDS {width} x {height} x {layers} texture, dimension {dimension}, {mips} levels: not one level of a 2-D array"
        ));
    }
    let vk_format = match dxgi {
        dds::DXGI_FORMAT_R11G11B10_FLOAT => VK_FORMAT_B10G11R11_UFLOAT_PACK32,
        dds::DXGI_FORMAT_R16G16B16A16_FLOAT => VK_FORMAT_R16G16B16A16_SFLOAT,
        other => return Err(format!("DXGI format {other} is not one this build reads (26 or 10)")),
    };
    Ok(Level { vk_format, width, height, layers, data: bytes[dds::HEADER_BYTES..].to_vec() })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::colour::ColourSpace;

    fn texture(format: TextureFormat) -> (Packed, Vec<[f64; 3]>) {
        let rgb: Vec<[f64; 3]> = (0..3 * 2 * 5).map(|i| [f64::from(i), 0.25, 1e-3 * f64::from(i)]).collect();
        (pack_array(format, &rgb).unwrap().0, rgb)
    }

    /// Every format in every container reads back as written, and our DDS
    /// reader agrees with the `ddsfile` crate's on the same bytes.
    #[test]
    fn every_format_in_every_container_reads_back() {
        let dir = tempfile::tempdir().unwrap();
        for format in TextureFormat::ALL {
            let (packed, rgb) = texture(format);
            for container in Container::ALL {
                let path = dir.path().join(container.file_name(format.name()));
                let tex = ArrayTexture {
                    width: 3,
                    height: 2,
                    layers: 5,
                    colour_space: ColourSpace::Rec709,
                    texels: packed.texels(),
                    sky_json: "{}",
                };
                let n = write(container, &path, &tex).unwrap();
                assert_eq!(n, std::fs::metadata(&path).unwrap().len());
                let level = read(container, &path).unwrap();
                assert_eq!((level.vk_format, level.width, level.height, level.layers), (format.vk_format(), 3, 2, 5));
                let layers = level.rgb_layers().unwrap();
                assert_eq!(layers.len(), 5);
                for (i, v) in layers.concat().iter().enumerate() {
                    for c in 0..3 {
                        let want = rgb[i][c];
                        assert!((f64::from(v[c]) - want).abs() <= want * 2f64.powi(-6), "{format:?} {container:?} {i}");
                    }
                }
                if container == Container::Dds {
                    let bytes = std::fs::read(&path).unwrap();
                    let other = ::ddsfile::Dds::read(&bytes[..]).unwrap();
                    assert_eq!(other.get_num_array_layers(), 5);
                    assert_eq!(&other.data[..], &level.data[..], "the same texels as ddsfile reads");
                }
            }
        }
    }

    #[test]
    fn bad_dds_files_are_refused_with_a_reason() {
        let (packed, _) = texture(TextureFormat::Rgba16f);
        let good = dds::encode(3, 2, 5, &packed.texels()).unwrap();
        assert!(read_dds(&good).is_ok());
        let mut legacy = good.clone();
        legacy[84..88].copy_from_slice(b"DXT5");
        assert!(read_dds(&legacy).unwrap_err().contains("DX10"));
        let mut other = good.clone();
        other[128..132].copy_from_slice(&2u32.to_le_bytes()); // R32G32B32A32_FLOAT
        assert!(read_dds(&other).unwrap_err().contains("DXGI format 2"));
        assert!(read_dds(&good[..100]).unwrap_err().contains("not a DDS"));
        let dir = tempfile::tempdir().unwrap();
        let cut = dir.path().join("cut.dds");
        std::fs::write(&cut, &good[..good.len() - 8]).unwrap();
        assert!(read(Container::Dds, &cut).unwrap_err().contains("level 0 holds"));
        assert_eq!("ktx3".parse::<Container>().unwrap_err(), "unknown container \"ktx3\": use ktx2 or dds");
        assert!("rgb9e5".parse::<TextureFormat>().is_err());
    }
}
