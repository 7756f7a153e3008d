//! A KTX 2.0 writer for one uncompressed 2-D array texture with one mip
//! level: the container of a basis sky's LUT (64 slices, one per layer).
//!
//! Formats: VK_FORMAT_B10G11R11_UFLOAT_PACK32 (vkFormat 122, typeSize 4,
//! [`super::r11g11b10`]) and VK_FORMAT_R16G16B16A16_SFLOAT (vkFormat 97,
//! typeSize 2, [`super::rgba16f`]).
//!
//! File layout ([KTX2] "File Structure"), all little-endian:
//!
//! | bytes                 | content                                                   |
//! |-----------------------|-----------------------------------------------------------|
//! | 0–11                  | identifier «KTX 20»\r\n\x1A\n                               |
//! | 12–79                 | header: vkFormat, typeSize, pixelWidth, pixelHeight, pixelDepth = 0, layerCount = N, faceCount = 1, levelCount = 1, supercompressionScheme = 0, then the index (dfd/kvd offsets and lengths, sgd offset and length 0) |
//! | 80–103                | level index: byteOffset, byteLength, uncompressedByteLength (u64) of level 0 |
//! | 104–                  | data format descriptor: dfdTotalSize, one Basic block ([KDFS] "Khronos Basic Data Format Descriptor Block") |
//! | after the DFD         | key/value data, sorted by key, each entry padded to 4 bytes |
//! | aligned               | zero padding to a multiple of lcm(texel size, 4) ([KTX2] mipPadding) |
//! | level 0               | the texels                                                |
//!
//! Texel order within level 0 ([KTX2] "Level Images"): layers one after
//! another, each layer its rows one after another (row y = 0 first), each
//! row its texels left to right: [`super::texels`], which also says how
//! that maps to the LUT's (u, v). Row y = 0 is the "top" row of
//! KTXorientation "rd", which the file states.
//!
//! Key/value data ([KTX2] "Key/Value Data"): `KTXorientation` = "rd", `KTXwriter` =
//! `sky <version>`, and `sky` = the caller's JSON (the manifest entry of the
//! file), each value a NUL-terminated UTF-8 string, the entries sorted by
//! the bytes of their keys as the specification requires.
//!
//! Data format descriptor ([KDFS] Basic block fields): the descriptor
//! KTX-Software's `vk2dfd` builds (lib/dfdutils/createdfd.c, `writeSample`:
//! UFLOAT samples have the FLOAT qualifier, lower 0.0f and upper 1.0f;
//! SFLOAT samples FLOAT and SIGNED, −1.0f and 1.0f), byte-equal in the tests
//! to the `ktx2` crate's `dfd::Basic::from_format_with` for the same
//! primaries: vendor 0 (Khronos), descriptor type 0 (basic), version 2,
//! colour model RGBSDA (1), colour primaries from the texture's colour
//! space (BT709 = 1, BT2020 = 4, ACEScc/AP1 = 7, CIEXYZ = 5), transfer
//! function linear (1), flags 0 (straight alpha), texel block 1×1×1×1,
//! bytesPlane0 = the texel size; then one sample per channel, in bit order:
//!
//! | format     | sample | bitOffset | bitLength | channel | qualifiers       | sampleLower      | sampleUpper      |
//! |------------|--------|-----------|-----------|---------|------------------|------------------|------------------|
//! | B10G11R11  | R      | 0         | 11        | 0       | FLOAT            | 0                | 0x3F800000 (1.0) |
//! |            | G      | 11        | 11        | 1       | FLOAT            | 0                | 0x3F800000       |
//! |            | B      | 22        | 10        | 2       | FLOAT            | 0                | 0x3F800000       |
//! | RGBA16F    | R G B A| 0 16 32 48| 16        | 0 1 2 15| FLOAT, SIGNED    | 0xBF800000 (−1.0)| 0x3F800000       |
//!
//! (Float samples give their range as f32 bits, [KDFS] sampleLower/sampleUpper; for unsigned
//! floats the lower bound is 0.)
//!
//! Files are written to a temporary file in the destination's folder and
//! renamed over the destination, so no reader ever sees half a file.
//!
//! [KTX2]: https://registry.khronos.org/KTX/specs/2.0/ktxspec.v2.html
//! [KDFS]: https://registry.khronos.org/DataFormat/specs/1.3/dataformat.1.3.html

use super::texels::Texels;
use crate::atomic::write_atomically;
use crate::colour::ColourSpace;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The KTX 2.0 file identifier.
pub const IDENTIFIER: [u8; 12] = [0xAB, 0x4B, 0x54, 0x58, 0x20, 0x32, 0x30, 0xBB, 0x0D, 0x0A, 0x1A, 0x0A];
/// VK_FORMAT_B10G11R11_UFLOAT_PACK32.
pub const VK_FORMAT_B10G11R11_UFLOAT_PACK32: u32 = 122;
/// VK_FORMAT_R16G16B16A16_SFLOAT.
pub const VK_FORMAT_R16G16B16A16_SFLOAT: u32 = 97;
/// The key of the caller's JSON.
pub const SKY_KEY: &str = "sky";

const HEADER_BYTES: usize = 80;
const LEVEL_INDEX_BYTES: usize = 24;

/// The format's vkFormat: 122 or 97.
pub fn vk_format(texels: &Texels<'_>) -> u32 {
    match texels {
        Texels::B10G11R11(_) => VK_FORMAT_B10G11R11_UFLOAT_PACK32,
        Texels::Rgba16f(_) => VK_FORMAT_R16G16B16A16_SFLOAT,
    }
}

/// The header's typeSize: the packed word for PACK32 formats, one
/// component otherwise (the KTX2 specification's "typeSize").
pub fn type_size(texels: &Texels<'_>) -> u32 {
    match texels {
        Texels::B10G11R11(_) => 4,
        Texels::Rgba16f(_) => 2,
    }
}

/// One 2-D array texture of `layers` layers of `width` × `height` texels.
#[derive(Debug, Clone, Copy)]
pub struct ArrayTexture<'a> {
    pub width: u32,
    pub height: u32,
    pub layers: u32,
    /// What the RGB channels hold; sets the DFD's colour primaries.
    pub colour_space: ColourSpace,
    pub texels: Texels<'a>,
    /// JSON text stored under the `sky` key (the manifest entry).
    pub sky_json: &'a str,
}

/// A texture that cannot be written, or a failed write.
#[derive(Debug, thiserror::Error)]
pub enum Ktx2Error {
    #[error("a texture needs at least one texel and one layer, got {width} x {height} x {layers}")]
    Empty { width: u32, height: u32, layers: u32 },
    #[error("{width} x {height} x {layers} layers is {expected} texels, but {got} were given")]
    TexelCount { width: u32, height: u32, layers: u32, expected: u64, got: usize },
    #[error("the `sky` value is not JSON: {0}")]
    NotJson(#[source] serde_json::Error),
    #[error("the file would exceed the KTX2 index's 32-bit offsets")]
    TooLarge,
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// `sky <version>`, the `KTXwriter` value.
pub fn writer_name() -> String {
    format!("sky {}", env!("CARGO_PKG_VERSION"))
}

/// The KDFS colour primaries of a colour space.
pub fn dfd_primaries(space: ColourSpace) -> u8 {
    match space {
        ColourSpace::Rec709 => 1,
        ColourSpace::Rec2020 => 4,
        ColourSpace::Xyz => 5,
        ColourSpace::AcesCg => 7,
    }
}

/// The data format descriptor (dfdTotalSize and one Basic block).
pub fn data_format_descriptor(texels: &Texels<'_>, space: ColourSpace) -> Vec<u8> {
    // (bitOffset, bitLength, channel id) per sample, in bit order.
    let (samples, qualifiers, lower): (&[(u16, u8, u8)], u8, u32) = match texels {
        // FLOAT = 0x80 (bit 7 of the channel byte, [KDFS] channelType qualifiers).
        Texels::B10G11R11(_) => (&[(0, 11, 0), (11, 11, 1), (22, 10, 2)], 0x80, 0),
        // FLOAT | SIGNED = 0x80 | 0x40; lower = −1.0f.
        Texels::Rgba16f(_) => (&[(0, 16, 0), (16, 16, 1), (32, 16, 2), (48, 16, 15)], 0xC0, 0xBF80_0000),
    };
    let block_size = 24 + 16 * samples.len();
    let mut d = Vec::with_capacity(4 + block_size);
    d.extend_from_slice(&((4 + block_size) as u32).to_le_bytes()); // dfdTotalSize
    d.extend_from_slice(&0u32.to_le_bytes()); // vendorId 0 (17 bits) | descriptorType 0 (15 bits)
    d.extend_from_slice(&2u16.to_le_bytes()); // versionNumber: KDFS 1.3
    d.extend_from_slice(&(block_size as u16).to_le_bytes()); // descriptorBlockSize
    d.extend_from_slice(&[1, dfd_primaries(space), 1, 0]); // RGBSDA, primaries, linear, straight alpha
    d.extend_from_slice(&[0, 0, 0, 0]); // texelBlockDimension − 1
    d.extend_from_slice(&[texels.texel_bytes() as u8, 0, 0, 0, 0, 0, 0, 0]); // bytesPlane0..7
    for &(offset, bits, channel) in samples {
        d.extend_from_slice(&offset.to_le_bytes());
        d.push(bits - 1);
        d.push(channel | qualifiers);
        d.extend_from_slice(&[0, 0, 0, 0]); // samplePosition0..3
        d.extend_from_slice(&lower.to_le_bytes());
        d.extend_from_slice(&1.0f32.to_bits().to_le_bytes());
    }
    d
}

/// The key/value data: entries sorted by key, each padded to 4 bytes.
fn key_value_data(entries: &BTreeMap<&str, Vec<u8>>) -> Vec<u8> {
    let mut kvd = Vec::new();
    // BTreeMap<&str> iterates in byte order of the keys: the order KTX2 requires.
    for (key, value) in entries {
        let length = key.len() + 1 + value.len();
        kvd.extend_from_slice(&(length as u32).to_le_bytes());
        kvd.extend_from_slice(key.as_bytes());
        kvd.push(0);
        kvd.extend_from_slice(value);
        kvd.resize(kvd.len().next_multiple_of(4), 0); // valuePadding
    }
    kvd
}

fn nul_terminated(s: &str) -> Vec<u8> {
    let mut v = s.as_bytes().to_vec();
    v.push(0);
    v
}

/// The whole file in memory.
pub fn encode(tex: &ArrayTexture<'_>) -> Result<Vec<u8>, Ktx2Error> {
    let (width, height, layers) = (tex.width, tex.height, tex.layers);
    if width == 0 || height == 0 || layers == 0 {
        return Err(Ktx2Error::Empty { width, height, layers });
    }
    let expected = u64::from(width) * u64::from(height) * u64::from(layers);
    if tex.texels.len() as u64 != expected {
        return Err(Ktx2Error::TexelCount { width, height, layers, expected, got: tex.texels.len() });
    }
    // Valid JSON has no raw NUL (control characters in strings must be
    // escaped), so the value's NUL terminator is unambiguous.
    serde_json::from_str::<serde::de::IgnoredAny>(tex.sky_json).map_err(Ktx2Error::NotJson)?;

    let dfd = data_format_descriptor(&tex.texels, tex.colour_space);
    let entries = BTreeMap::from([
        ("KTXorientation", nul_terminated("rd")),
        ("KTXwriter", nul_terminated(&writer_name())),
        (SKY_KEY, nul_terminated(tex.sky_json)),
    ]);
    let kvd = key_value_data(&entries);

    let dfd_offset = HEADER_BYTES + LEVEL_INDEX_BYTES;
    let kvd_offset = dfd_offset + dfd.len();
    // Level data starts at a multiple of lcm(texel size, 4) ([KTX2] mipPadding):
    // 4 for R11G11B10, 8 for RGBA16F.
    let align = tex.texels.texel_bytes().max(4);
    let level_offset = (kvd_offset + kvd.len()).next_multiple_of(align);
    let level_bytes = tex.texels.len() * tex.texels.texel_bytes();
    if u32::try_from(kvd_offset + kvd.len()).is_err() {
        return Err(Ktx2Error::TooLarge);
    }

    let mut out = Vec::with_capacity(level_offset + level_bytes);
    out.extend_from_slice(&IDENTIFIER);
    for v in [vk_format(&tex.texels), type_size(&tex.texels), width, height, 0, layers, 1, 1, 0] {
        // vkFormat, typeSize, pixelWidth, pixelHeight, pixelDepth, layerCount,
        // faceCount, levelCount, supercompressionScheme.
        out.extend_from_slice(&v.to_le_bytes());
    }
    for v in [dfd_offset, dfd.len(), kvd_offset, kvd.len()] {
        out.extend_from_slice(&(v as u32).to_le_bytes());
    }
    out.extend_from_slice(&0u64.to_le_bytes()); // sgdByteOffset
    out.extend_from_slice(&0u64.to_le_bytes()); // sgdByteLength
    for v in [level_offset, level_bytes, level_bytes] {
        // byteOffset, byteLength, uncompressedByteLength
        out.extend_from_slice(&(v as u64).to_le_bytes());
    }
    debug_assert_eq!(out.len(), dfd_offset);
    out.extend_from_slice(&dfd);
    out.extend_from_slice(&kvd);
    out.resize(level_offset, 0); // mipPadding
    tex.texels.write_le(&mut out);
    Ok(out)
}

/// Writes the file atomically (a temporary file in the same folder, then a
/// rename). Returns the file's size in bytes.
pub fn write(path: &Path, tex: &ArrayTexture<'_>) -> Result<u64, Ktx2Error> {
    let bytes = encode(tex)?;
    write_atomically(path, &bytes).map_err(|source| Ktx2Error::Io { path: path.to_path_buf(), source })?;
    Ok(bytes.len() as u64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lut::texels::texel_index;
    use crate::lut::{r11g11b10, rgba16f};

    fn u32_at(b: &[u8], at: usize) -> u32 {
        u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
    }

    fn u64_at(b: &[u8], at: usize) -> u64 {
        u64::from_le_bytes(b[at..at + 8].try_into().unwrap())
    }

    /// A 32 × 128 × 64 R11G11B10 array whose texel values encode their place.
    fn words(w: u32, h: u32, l: u32) -> Vec<u32> {
        let mut t = vec![0; (w * h * l) as usize];
        for layer in 0..l {
            for y in 0..h {
                for x in 0..w {
                    t[texel_index(w, h, layer, x, y)] =
                        r11g11b10::pack([f64::from(x), f64::from(y), f64::from(layer)]).unwrap();
                }
            }
        }
        t
    }

    const JSON: &str = r#"{"basis": "clear", "slices": 64, "units": "kcd/m^2"}"#;

    fn lut(t: &[u32]) -> ArrayTexture<'_> {
        ArrayTexture {
            width: 32,
            height: 128,
            layers: 64,
            colour_space: ColourSpace::Rec709,
            texels: Texels::B10G11R11(t),
            sky_json: JSON,
        }
    }

    /// Our own reading of every field the KTX2 rules fix, independent of
    /// any crate: header, index, alignment, DFD bytes, sorted keys,
    /// padding, texel order, and the size (the talk's budget: 32·128·64·4 B).
    #[test]
    fn layout_by_hand() {
        let t = words(32, 128, 64);
        let b = encode(&lut(&t)).unwrap();
        assert_eq!(b[..12], IDENTIFIER);
        let header: Vec<u32> = (0..9).map(|i| u32_at(&b, 12 + 4 * i)).collect();
        assert_eq!(header, [122, 4, 32, 128, 0, 64, 1, 1, 0]);
        let (dfd_off, dfd_len, kvd_off, kvd_len) =
            (u32_at(&b, 48) as usize, u32_at(&b, 52) as usize, u32_at(&b, 56) as usize, u32_at(&b, 60) as usize);
        assert_eq!((u64_at(&b, 64), u64_at(&b, 72)), (0, 0), "no supercompression global data");
        assert_eq!(dfd_off, 104);
        assert_eq!(dfd_len, 76);
        assert_eq!(u32_at(&b, dfd_off), 76, "dfdTotalSize counts itself");
        assert_eq!(kvd_off, dfd_off + dfd_len);
        assert_eq!(kvd_len % 4, 0);
        let (lvl_off, lvl_len, lvl_unc) = (u64_at(&b, 80) as usize, u64_at(&b, 88) as usize, u64_at(&b, 96) as usize);
        assert_eq!((lvl_len, lvl_unc), (32 * 128 * 64 * 4, 32 * 128 * 64 * 4));
        assert_eq!(lvl_off % 4, 0);
        assert!(lvl_off >= kvd_off + kvd_len && lvl_off - (kvd_off + kvd_len) < 4, "padding only to alignment");
        assert!(b[kvd_off + kvd_len..lvl_off].iter().all(|&x| x == 0));
        assert_eq!(b.len(), lvl_off + lvl_len);
        assert_eq!(lvl_len, 1 << 20, "1 MiB per sunny basis sky");

        // The DFD, byte by byte (KDFS 1.3 Basic block; the table in the module docs).
        let mut want = vec![76, 0, 0, 0, 0, 0, 0, 0, 2, 0, 72, 0, 1, 1, 1, 0, 0, 0, 0, 0, 4, 0, 0, 0, 0, 0, 0, 0];
        for (off, bits, ch) in [(0u16, 11u8, 0u8), (11, 11, 1), (22, 10, 2)] {
            want.extend_from_slice(&off.to_le_bytes());
            want.extend_from_slice(&[bits - 1, 0x80 | ch, 0, 0, 0, 0, 0, 0, 0, 0, 0x00, 0x00, 0x80, 0x3F]);
        }
        assert_eq!(b[dfd_off..dfd_off + dfd_len], want[..]);

        // Key/value entries: lengths, NULs, padding, and byte-sorted keys.
        let mut at = kvd_off;
        let mut keys = Vec::new();
        while at < kvd_off + kvd_len {
            let n = u32_at(&b, at) as usize;
            let kv = &b[at + 4..at + 4 + n];
            let nul = kv.iter().position(|&c| c == 0).unwrap();
            let (key, value) = (std::str::from_utf8(&kv[..nul]).unwrap(), &kv[nul + 1..]);
            assert_eq!(value.last(), Some(&0), "{key}: NUL-terminated");
            let value = std::str::from_utf8(&value[..value.len() - 1]).unwrap();
            match key {
                "KTXorientation" => assert_eq!(value, "rd"),
                "KTXwriter" => assert_eq!(value, format!("sky {}", env!("CARGO_PKG_VERSION"))),
                "sky" => assert_eq!(value, JSON),
                _ => panic!("unexpected key {key}"),
            }
            keys.push(key.to_string());
            let padded = (4 + n).next_multiple_of(4);
            assert!(b[at + 4 + n..at + padded].iter().all(|&x| x == 0));
            at += padded;
        }
        assert_eq!(at, kvd_off + kvd_len);
        assert_eq!(keys, ["KTXorientation", "KTXwriter", "sky"]);
        assert!(keys.windows(2).all(|k| k[0].as_bytes() < k[1].as_bytes()));

        // Texel (x, y) of layer l is at (l h + y) w + x: row 0 first.
        for (l, y, x) in [(0, 0, 0), (0, 0, 31), (0, 1, 0), (5, 77, 13), (63, 127, 31)] {
            let at = lvl_off + 4 * texel_index(32, 128, l, x, y);
            assert_eq!(r11g11b10::unpack(u32_at(&b, at)), [x as f32, y as f32, l as f32]);
        }
    }

    /// The first independent reader: the `ktx2` crate (0.5), plus its DFD
    /// builder (the table KTX-Software's vk2dfd uses) byte for byte.
    #[test]
    fn ktx2_crate_reads_it_back() {
        let t = words(32, 128, 64);
        let b = encode(&lut(&t)).unwrap();
        let r = ::ktx2::Reader::new(&b[..]).unwrap();
        let h = r.header();
        assert_eq!(h.format, Some(::ktx2::Format::B10G11R11_UFLOAT_PACK32));
        assert_eq!(
            (h.type_size, h.pixel_width, h.pixel_height, h.pixel_depth, h.layer_count, h.face_count, h.level_count),
            (4, 32, 128, 0, 64, 1, 1)
        );
        assert_eq!(h.supercompression_scheme, None);
        let levels: Vec<_> = r.levels().collect();
        assert_eq!(levels.len(), 1);
        assert_eq!(levels[0].data.len(), t.len() * 4);
        assert_eq!(levels[0].uncompressed_byte_length, (t.len() * 4) as u64);
        let back: Vec<u32> =
            levels[0].data.chunks_exact(4).map(|c| u32::from_le_bytes(c.try_into().unwrap())).collect();
        assert_eq!(back, t);
        assert_eq!(r.writer(), Some(format!("sky {}\0", env!("CARGO_PKG_VERSION")).as_str()));
        let keys: Vec<_> = r.key_value_data().map(|(k, _)| k).collect();
        assert_eq!(keys, ["KTXorientation", "KTXwriter", "sky"]);
        let sky = r.key_value_data().find(|(k, _)| *k == "sky").unwrap().1;
        assert_eq!(sky, format!("{JSON}\0").as_bytes());
        assert_eq!(r.transfer_function(), Some(::ktx2::TransferFunction::Linear));
        assert_eq!(r.color_primaries(), Some(::ktx2::ColorPrimaries::BT709));
        let dfd = r.basic_dfd().unwrap();
        assert_eq!(dfd.sample_information.len(), 3);

        for (texels, format) in [
            (Texels::B10G11R11(&[]), ::ktx2::Format::B10G11R11_UFLOAT_PACK32),
            (Texels::Rgba16f(&[]), ::ktx2::Format::R16G16B16A16_SFLOAT),
        ] {
            for (space, primaries) in [
                (ColourSpace::Rec709, ::ktx2::ColorPrimaries::BT709),
                (ColourSpace::Rec2020, ::ktx2::ColorPrimaries::BT2020),
                (ColourSpace::AcesCg, ::ktx2::ColorPrimaries::ACESCC),
                (ColourSpace::Xyz, ::ktx2::ColorPrimaries::CIEXYZ),
            ] {
                let (basic, crate_type_size) = ::ktx2::dfd::Basic::from_format_with(
                    format,
                    false,
                    Some(::ktx2::TransferFunction::Linear),
                    Some(primaries),
                    None,
                )
                .unwrap();
                assert_eq!(crate_type_size, type_size(&texels), "{format:?}");
                let block = ::ktx2::dfd::Block::Basic(basic).to_vec();
                let ours = data_format_descriptor(&texels, space);
                assert_eq!(u32_at(&ours, 0) as usize, 4 + block.len());
                assert_eq!(ours[4..], block[..], "{format:?} {space}");
            }
        }
    }

    #[test]
    fn rgba16f_file() {
        let rgb: Vec<[f64; 3]> = (0..4 * 2 * 3).map(|i| [i as f64, 0.5, 1e5]).collect();
        let (h, _) = rgba16f::pack_array(&rgb).unwrap();
        let tex = ArrayTexture {
            width: 4,
            height: 2,
            layers: 3,
            colour_space: ColourSpace::AcesCg,
            texels: Texels::Rgba16f(&h),
            sky_json: "{}",
        };
        let b = encode(&tex).unwrap();
        let r = ::ktx2::Reader::new(&b[..]).unwrap();
        let hd = r.header();
        assert_eq!((hd.format, hd.type_size, hd.layer_count), (Some(::ktx2::Format::R16G16B16A16_SFLOAT), 2, 3));
        assert_eq!(u64_at(&b, 80) % 8, 0, "level data aligned to the 8-byte texel");
        let data = r.levels().next().unwrap().data;
        assert_eq!(data.len(), 24 * 8);
        let t = texel_index(4, 2, 2, 3, 1);
        let texel: [u16; 4] =
            std::array::from_fn(|c| u16::from_le_bytes([data[8 * t + 2 * c], data[8 * t + 2 * c + 1]]));
        assert_eq!(rgba16f::unpack(texel), [t as f32, 0.5, 65504.0, 1.0]);
    }

    #[test]
    fn rejects_bad_textures() {
        let t = words(2, 2, 2);
        let base = ArrayTexture {
            width: 2,
            height: 2,
            layers: 2,
            colour_space: ColourSpace::Rec709,
            texels: Texels::B10G11R11(&t),
            sky_json: "{}",
        };
        assert!(encode(&base).is_ok());
        assert!(matches!(
            encode(&ArrayTexture { layers: 3, ..base }),
            Err(Ktx2Error::TexelCount { expected: 12, got: 8, .. })
        ));
        assert!(matches!(encode(&ArrayTexture { width: 0, ..base }), Err(Ktx2Error::Empty { .. })));
        assert!(matches!(encode(&ArrayTexture { sky_json: "{not json", ..base }), Err(Ktx2Error::NotJson(_))));
        assert!(encode(&ArrayTexture { sky_json: "\"a\\u0000b\"", ..base }).is_ok(), "an escaped NUL is fine");
        assert!(
            matches!(encode(&ArrayTexture { sky_json: "\"a\0b\"", ..base }), Err(Ktx2Error::NotJson(_))),
            "a raw NUL is not JSON"
        );
    }

    #[test]
    fn writes_atomically() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("clear.ktx2");
        let t = words(2, 2, 2);
        let tex = ArrayTexture {
            width: 2,
            height: 2,
            layers: 2,
            colour_space: ColourSpace::Rec709,
            texels: Texels::B10G11R11(&t),
            sky_json: "{}",
        };
        std::fs::write(&path, b"old").unwrap();
        let n = write(&path, &tex).unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), encode(&tex).unwrap());
        assert_eq!(n, std::fs::metadata(&path).unwrap().len());
        // Only the file itself is left: no temporary files.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
        // A failed encode leaves the old file alone.
        assert!(write(&path, &ArrayTexture { layers: 9, ..tex }).is_err());
        assert_eq!(std::fs::read(&path).unwrap(), encode(&tex).unwrap());
        let err = write(&dir.path().join("missing/x.ktx2"), &tex).unwrap_err();
        assert!(err.to_string().contains("missing/x.ktx2"), "{err}");
    }
}
