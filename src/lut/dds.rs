//! A DDS writer for one uncompressed 2-D array texture with one mip level,
//! for engines and tools that take DDS rather than KTX2:
//! DXGI_FORMAT_R11G11B10_FLOAT (26) or DXGI_FORMAT_R16G16B16A16_FLOAT (10),
//! always with the DX10 extension header (the legacy header has no
//! R11G11B10 and no arrays).
//!
//! File layout ([DDS] "DDS File Layout", [DDS_HEADER], [DDS_HEADER_DXT10]),
//! all little-endian u32:
//!
//! | bytes   | content |
//! |---------|---------|
//! | 0–3     | "DDS " |
//! | 4–127   | DDS_HEADER: dwSize 124, dwFlags CAPS \| HEIGHT \| WIDTH \| PITCH \| PIXELFORMAT \| MIPMAPCOUNT (0x2100F), dwHeight, dwWidth, dwPitchOrLinearSize = width × texel bytes, dwDepth 0, dwMipMapCount 1, 11 reserved; DDS_PIXELFORMAT {32, DDPF_FOURCC (4), "DX10", 0, 0, 0, 0, 0}; dwCaps DDSCAPS_TEXTURE (0x1000), plus DDSCAPS_COMPLEX (0x8) when there is more than one layer; dwCaps2..4 and reserved 0 |
//! | 128–147 | DDS_HEADER_DXT10: dxgiFormat, resourceDimension TEXTURE2D (3), miscFlag 0, arraySize = layers, miscFlags2 0 (alpha mode unknown) |
//! | 148–    | the texels: each layer's one level after the other, rows top down |
//!
//! The texel order is [`super::texels`]'s, the same as in the KTX2 files:
//! Direct3D's row 0 is at texture coordinate v = 0.
//!
//! DDS has no place for metadata: the manifest names the file, its format,
//! and its colour space.
//!
//! [DDS]: https://learn.microsoft.com/en-us/windows/win32/direct3ddds/dx-graphics-dds-pguide
//! [DDS_HEADER]: https://learn.microsoft.com/en-us/windows/win32/direct3ddds/dds-header
//! [DDS_HEADER_DXT10]: https://learn.microsoft.com/en-us/windows/win32/direct3ddds/dds-header-dxt10

use super::texels::Texels;
use crate::atomic::write_atomically;
use std::path::{Path, PathBuf};

/// DXGI_FORMAT_R11G11B10_FLOAT.
pub const DXGI_FORMAT_R11G11B10_FLOAT: u32 = 26;
/// DXGI_FORMAT_R16G16B16A16_FLOAT.
pub const DXGI_FORMAT_R16G16B16A16_FLOAT: u32 = 10;
/// The bytes before the texels: magic, DDS_HEADER, DDS_HEADER_DXT10.
pub const HEADER_BYTES: usize = 4 + 124 + 20;

const DDSD_CAPS: u32 = 0x1;
const DDSD_HEIGHT: u32 = 0x2;
const DDSD_WIDTH: u32 = 0x4;
const DDSD_PITCH: u32 = 0x8;
const DDSD_PIXELFORMAT: u32 = 0x1000;
const DDSD_MIPMAPCOUNT: u32 = 0x20000;
const DDPF_FOURCC: u32 = 0x4;
const DDSCAPS_COMPLEX: u32 = 0x8;
const DDSCAPS_TEXTURE: u32 = 0x1000;
const D3D10_RESOURCE_DIMENSION_TEXTURE2D: u32 = 3;

/// A texture that cannot be written, or a failed write.
#[derive(Debug, thiserror::Error)]
pub enum DdsError {
    #[error("a texture needs at least one texel and one layer, got {width} x {height} x {layers}")]
    Empty { width: u32, height: u32, layers: u32 },
    #[error("{width} x {height} x {layers} layers is {expected} texels, but {got} were given")]
    TexelCount { width: u32, height: u32, layers: u32, expected: u64, got: usize },
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// The format's DXGI_FORMAT: 26 or 10.
pub fn dxgi_format(texels: &Texels<'_>) -> u32 {
    match texels {
        Texels::B10G11R11(_) => DXGI_FORMAT_R11G11B10_FLOAT,
        Texels::Rgba16f(_) => DXGI_FORMAT_R16G16B16A16_FLOAT,
    }
}

/// The whole file in memory: `layers` layers of `width` × `height` texels.
pub fn encode(width: u32, height: u32, layers: u32, texels: &Texels<'_>) -> Result<Vec<u8>, DdsError> {
    if width == 0 || height == 0 || layers == 0 {
        return Err(DdsError::Empty { width, height, layers });
    }
    let expected = u64::from(width) * u64::from(height) * u64::from(layers);
    if texels.len() as u64 != expected {
        return Err(DdsError::TexelCount { width, height, layers, expected, got: texels.len() });
    }
    let pitch = width * texels.texel_bytes() as u32;
    let caps = DDSCAPS_TEXTURE | if layers > 1 { DDSCAPS_COMPLEX } else { 0 };
    let mut words: Vec<u32> = vec![u32::from_le_bytes(*b"DDS ")];
    // DDS_HEADER
    words.extend([
        124,
        DDSD_CAPS | DDSD_HEIGHT | DDSD_WIDTH | DDSD_PITCH | DDSD_PIXELFORMAT | DDSD_MIPMAPCOUNT,
        height,
        width,
        pitch,
        0,
        1,
    ]);
    words.extend([0; 11]); // dwReserved1
    words.extend([32, DDPF_FOURCC, u32::from_le_bytes(*b"DX10"), 0, 0, 0, 0, 0]); // DDS_PIXELFORMAT
    words.extend([caps, 0, 0, 0, 0]); // dwCaps, dwCaps2, dwCaps3, dwCaps4, dwReserved2
                                      // DDS_HEADER_DXT10
    words.extend([dxgi_format(texels), D3D10_RESOURCE_DIMENSION_TEXTURE2D, 0, layers, 0]);
    let mut out = Vec::with_capacity(HEADER_BYTES + texels.len() * texels.texel_bytes());
    words.iter().for_each(|w| out.extend_from_slice(&w.to_le_bytes()));
    debug_assert_eq!(out.len(), HEADER_BYTES);
    texels.write_le(&mut out);
    Ok(out)
}

/// Writes the file atomically ([`crate::atomic`]); returns its size in bytes.
pub fn write(path: &Path, width: u32, height: u32, layers: u32, texels: &Texels<'_>) -> Result<u64, DdsError> {
    let bytes = encode(width, height, layers, texels)?;
    write_atomically(path, &bytes).map_err(|source| DdsError::Io { path: path.to_path_buf(), source })?;
    Ok(bytes.len() as u64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lut::texels::texel_index;
    use crate::lut::{r11g11b10, rgba16f};
    use ::ddsfile::{Dds, DxgiFormat};

    fn u32_at(b: &[u8], at: usize) -> u32 {
        u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
    }

    /// The header field by field, then the `ddsfile` crate (0.6) as an
    /// independent reader: format, size, layers, and every layer's texels.
    #[test]
    fn r11g11b10_array_reads_back() {
        let (w, h, l) = (16u32, 64u32, 64u32);
        let rgb: Vec<[f64; 3]> =
            (0..w * h * l).map(|i| [f64::from(i % w), f64::from((i / w) % h), f64::from(i / (w * h))]).collect();
        let (words, _) = r11g11b10::pack_array(&rgb).unwrap();
        let b = encode(w, h, l, &Texels::B10G11R11(&words)).unwrap();
        assert_eq!(&b[..4], b"DDS ");
        let header: Vec<u32> = (0..7).map(|i| u32_at(&b, 4 + 4 * i)).collect();
        assert_eq!(header, [124, 0x2100F, h, w, w * 4, 0, 1]);
        assert_eq!((u32_at(&b, 76), u32_at(&b, 80), &b[84..88]), (32, 4, &b"DX10"[..]));
        assert_eq!(u32_at(&b, 108), 0x1008);
        assert_eq!((128..148).step_by(4).map(|at| u32_at(&b, at)).collect::<Vec<_>>(), [26, 3, 0, 64, 0]);
        assert_eq!(b.len(), HEADER_BYTES + (w * h * l * 4) as usize);
        assert_eq!(b.len() - HEADER_BYTES, 256 << 10, "256 KiB per cloudy basis sky");

        let dds = Dds::read(&b[..]).unwrap();
        assert_eq!(dds.get_dxgi_format(), Some(DxgiFormat::R11G11B10_Float));
        assert_eq!(
            (dds.get_width(), dds.get_height(), dds.get_num_array_layers(), dds.get_num_mipmap_levels()),
            (w, h, l, 1)
        );
        assert_eq!(dds.get_pitch(), Some(w * 4));
        for layer in [0, 1, 37, 63] {
            let data = dds.get_data(layer).unwrap();
            assert_eq!(data.len(), (w * h * 4) as usize);
            let (x, y) = (7, 50);
            let at = 4 * texel_index(w, h, 0, x, y);
            let word = u32::from_le_bytes(data[at..at + 4].try_into().unwrap());
            assert_eq!(r11g11b10::unpack(word), [x as f32, y as f32, layer as f32]);
        }
    }

    #[test]
    fn rgba16f_reads_back() {
        let rgb: Vec<[f64; 3]> = (0..3 * 2 * 2).map(|i| [f64::from(i), 2.0, 0.5]).collect();
        let (halves, _) = rgba16f::pack_array(&rgb).unwrap();
        let b = encode(3, 2, 2, &Texels::Rgba16f(&halves)).unwrap();
        assert_eq!(u32_at(&b, 108), 0x1008);
        let dds = Dds::read(&b[..]).unwrap();
        assert_eq!(dds.get_dxgi_format(), Some(DxgiFormat::R16G16B16A16_Float));
        assert_eq!((dds.get_num_array_layers(), dds.get_pitch()), (2, Some(24)));
        let data = dds.get_data(1).unwrap();
        assert_eq!(data[..8], [0x00, 0x46, 0x00, 0x40, 0x00, 0x38, 0x00, 0x3C], "texel 6 = (6, 2, 0.5, 1)");
        // One layer: no DDSCAPS_COMPLEX.
        let one = encode(3, 2, 1, &Texels::Rgba16f(&halves[..6])).unwrap();
        assert_eq!(u32_at(&one, 108), 0x1000);
    }

    #[test]
    fn rejects_bad_textures_and_writes_atomically() {
        assert!(matches!(
            encode(2, 2, 2, &Texels::B10G11R11(&[0; 7])),
            Err(DdsError::TexelCount { expected: 8, got: 7, .. })
        ));
        assert!(matches!(encode(2, 0, 2, &Texels::B10G11R11(&[])), Err(DdsError::Empty { .. })));
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("clear.dds");
        let n = write(&path, 2, 2, 2, &Texels::B10G11R11(&[0x781E03C0; 8])).unwrap();
        assert_eq!(n, std::fs::metadata(&path).unwrap().len());
        assert_eq!(std::fs::read(&path).unwrap(), encode(2, 2, 2, &Texels::B10G11R11(&[0x781E03C0; 8])).unwrap());
    }
}
