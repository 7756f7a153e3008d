//! R11G11B10 unsigned float texels: VK_FORMAT_B10G11R11_UFLOAT_PACK32
//! (Vulkan), DXGI_FORMAT_R11G11B10_FLOAT (Direct3D), GL_R11F_G11F_B10F.
//!
//! One little-endian 32-bit word per texel: R in bits 0–10 and G in bits
//! 11–21 (5-bit exponent, 6-bit mantissa, 65024 at most), B in bits 22–31
//! (5-bit exponent, 5-bit mantissa, 64512 at most); exponent bias 15, no
//! sign ([Vulkan] "Unsigned 11-Bit Floating-Point Numbers", "Unsigned
//! 10-Bit Floating-Point Numbers" and the format's packed layout; [KDFS]
//! "Unsigned 11-bit floating-point numbers", "Unsigned 10-bit
//! floating-point numbers").
//!
//! Packing takes f64, the bake's precision, and rounds each channel once,
//! exactly, to nearest with ties to even ([`super::minifloat`], where the
//! rules are cited): denormals kept, finite values above the channel's
//! largest clamped to it, negative values and −0 to 0. An f32 input goes
//! through the same path (f32 → f64 is exact, so the result is the correct
//! rounding of the f32). NaN and infinity are errors, never texels.
//!
//! [Vulkan]: https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#fundamentals-fp11
//! [KDFS]: https://registry.khronos.org/DataFormat/specs/1.3/dataformat.1.3.html#11bitfp

use super::minifloat::{self, Rounding};
use serde::Serialize;

/// One of the three channels, with its place in the word.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Channel {
    R,
    G,
    B,
}

impl Channel {
    pub const ALL: [Channel; 3] = [Channel::R, Channel::G, Channel::B];

    /// Mantissa bits: 6 for R and G, 5 for B.
    pub const fn mantissa_bits(self) -> u32 {
        match self {
            Channel::R | Channel::G => 6,
            Channel::B => 5,
        }
    }

    /// The bit offset of the channel's code in the word.
    pub const fn bit_offset(self) -> u32 {
        match self {
            Channel::R => 0,
            Channel::G => 11,
            Channel::B => 22,
        }
    }

    /// Bits of the channel's code: 11, 11, 10.
    pub const fn bit_count(self) -> u32 {
        minifloat::EXPONENT_BITS + self.mantissa_bits()
    }

    /// The largest finite value: 65024 for R and G, 64512 for B.
    pub fn max_value(self) -> f64 {
        minifloat::max_finite(self.mantissa_bits())
    }

    fn index(self) -> usize {
        self as usize
    }
}

/// Largest finite value of the R and G channels (2^15 · (2 − 2^-6)).
pub const RG_MAX: f64 = 65024.0;
/// Largest finite value of the B channel (2^15 · (2 − 2^-5)).
pub const B_MAX: f64 = 64512.0;

/// A value that has no R11G11B10 texel.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum PackError {
    #[error("{channel:?} is {value}: NaN and infinity have no R11G11B10 texel")]
    NotFinite { channel: Channel, value: f64 },
}

/// A value of an array that has no R11G11B10 texel, with its place.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("texel {texel}: {source}")]
pub struct PackArrayError {
    /// Index of the texel in the array handed to [`pack_array`].
    pub texel: usize,
    pub source: PackError,
}

/// Packs linear RGB into one word, rounding each channel once from f64.
pub fn pack(rgb: [f64; 3]) -> Result<u32, PackError> {
    pack_classified(rgb).map(|(word, _)| word)
}

/// [`pack`] for f32 input (exact widening, then the same single rounding).
pub fn pack_f32(rgb: [f32; 3]) -> Result<u32, PackError> {
    pack(rgb.map(f64::from))
}

/// [`pack`], also saying what rounding did to each channel.
pub fn pack_classified(rgb: [f64; 3]) -> Result<(u32, [Rounding; 3]), PackError> {
    let mut word = 0;
    let mut kinds = [Rounding::Zero; 3];
    for channel in Channel::ALL {
        let value = rgb[channel.index()];
        let (code, kind) =
            minifloat::encode(value, channel.mantissa_bits()).ok_or(PackError::NotFinite { channel, value })?;
        word |= code << channel.bit_offset();
        kinds[channel.index()] = kind;
    }
    Ok((word, kinds))
}

/// The three channels of a word, exactly (NaN or infinity where the word
/// holds those codes, which [`pack`] never writes).
pub fn unpack(word: u32) -> [f32; 3] {
    Channel::ALL.map(|c| minifloat::decode((word >> c.bit_offset()) & ((1 << c.bit_count()) - 1), c.mantissa_bits()))
}

/// What packing did to an array, for the bake's report. A texel counts once
/// in each texel total if any of its channels did that thing.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct PackStats {
    /// Texels packed.
    pub texels: u64,
    /// Texels with a channel above its largest value, stored as the largest.
    pub clamped_texels: u64,
    /// Texels with a channel stored as a nonzero denormal (below 2^-14,
    /// fewer significant bits).
    pub denormal_texels: u64,
    /// Texels with a positive channel too small for the smallest denormal
    /// (2^-20 for R and G, 2^-19 for B, halved by rounding), stored as 0.
    pub underflow_texels: u64,
    /// Texels with a negative channel (or −0), stored as 0.
    pub negative_texels: u64,
    /// Per channel (R, G, B): clamped channels.
    pub clamped_per_channel: [u64; 3],
    /// Per channel (R, G, B): channels stored as denormals.
    pub denormal_per_channel: [u64; 3],
}

impl PackStats {
    /// Counts one texel's roundings.
    pub fn add(&mut self, kinds: &[Rounding; 3]) {
        self.texels += 1;
        let any = |k: Rounding| kinds.contains(&k) as u64;
        self.clamped_texels += any(Rounding::Clamped);
        self.denormal_texels += any(Rounding::Denormal);
        self.underflow_texels += any(Rounding::Underflow);
        self.negative_texels += any(Rounding::Negative);
        for i in 0..3 {
            self.clamped_per_channel[i] += (kinds[i] == Rounding::Clamped) as u64;
            self.denormal_per_channel[i] += (kinds[i] == Rounding::Denormal) as u64;
        }
    }

    /// Sums the counts of two arrays (e.g. the slices of one basis sky).
    pub fn merge(&mut self, other: &PackStats) {
        self.texels += other.texels;
        self.clamped_texels += other.clamped_texels;
        self.denormal_texels += other.denormal_texels;
        self.underflow_texels += other.underflow_texels;
        self.negative_texels += other.negative_texels;
        for i in 0..3 {
            self.clamped_per_channel[i] += other.clamped_per_channel[i];
            self.denormal_per_channel[i] += other.denormal_per_channel[i];
        }
    }
}

/// Packs an array of texels, in order, and counts what rounding did. The
/// first NaN or infinity stops it with the texel's index.
pub fn pack_array(texels: &[[f64; 3]]) -> Result<(Vec<u32>, PackStats), PackArrayError> {
    let mut words = Vec::with_capacity(texels.len());
    let mut stats = PackStats::default();
    for (texel, rgb) in texels.iter().enumerate() {
        let (word, kinds) = pack_classified(*rgb).map_err(|source| PackArrayError { texel, source })?;
        words.push(word);
        stats.add(&kinds);
    }
    Ok((words, stats))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn code(word: u32, c: Channel) -> u32 {
        (word >> c.bit_offset()) & ((1 << c.bit_count()) - 1)
    }

    fn single(c: Channel, v: f64) -> u32 {
        let mut rgb = [0.0; 3];
        rgb[c.index()] = v;
        code(pack(rgb).unwrap(), c)
    }

    fn value(c: Channel, code: u32) -> f64 {
        f64::from(unpack(code << c.bit_offset())[c.index()])
    }

    /// The vectors (R, G, B) → word.
    #[test]
    fn test_vectors() {
        let cases: [([f64; 3], u32); 5] = [
            ([1.0, 1.0, 1.0], 0x781E03C0),
            // 129 and 131 lie halfway between codes (spacing 2 at 128..256):
            // ties to even give 128 and 132; 1 + 1/64 is halfway in B
            // (spacing 1/32): to 1.
            ([129.0, 131.0, 1.0 + 1.0 / 64.0], 0x782C1580),
            // 2^-20 is the smallest R denormal; 0.75 · 2^-20 rounds up to it;
            // 2^-15 is a B denormal (16 · 2^-19).
            ([2f64.powi(-20), 0.75 * 2f64.powi(-20), 2f64.powi(-15)], 0x04000801),
            ([65024.0, 70000.0, 64512.0], 0xF7FDFFBF),
            ([0.1, std::f64::consts::PI, 1000.0], 0xC7A12AE6),
        ];
        for (rgb, word) in cases {
            assert_eq!(pack(rgb).unwrap(), word, "{rgb:?}: {:#010X} vs {word:#010X}", pack(rgb).unwrap());
            assert_eq!(pack_f32(rgb.map(|v| v as f32)).unwrap(), word, "{rgb:?} as f32");
        }
        assert_eq!(unpack(0x781E03C0), [1.0, 1.0, 1.0]);
        assert_eq!(unpack(0xF7FDFFBF), [65024.0, 65024.0, 64512.0]);
        assert_eq!(unpack(0x782C1580), [128.0, 132.0, 1.0]);
    }

    #[test]
    fn layout_and_limits() {
        assert_eq!(Channel::R.max_value(), RG_MAX);
        assert_eq!(Channel::G.max_value(), RG_MAX);
        assert_eq!(Channel::B.max_value(), B_MAX);
        assert_eq!(Channel::ALL.map(|c| (c.bit_offset(), c.bit_count())), [(0, 11), (11, 11), (22, 10)]);
        assert_eq!(pack([1.0, 0.0, 0.0]).unwrap(), 0x3C0);
        assert_eq!(pack([0.0, 1.0, 0.0]).unwrap(), 0x3C0 << 11);
        assert_eq!(pack([0.0, 0.0, 1.0]).unwrap(), 0x1E0 << 22);
    }

    #[test]
    fn negatives_and_specials() {
        assert_eq!(pack([-1.0, -0.0, -1e30]).unwrap(), 0);
        let (_, kinds) = pack_classified([-1.0, -0.0, 0.0]).unwrap();
        assert_eq!(kinds, [Rounding::Negative, Rounding::Negative, Rounding::Zero]);
        assert!(matches!(pack([1.0, f64::NAN, 1.0]), Err(PackError::NotFinite { channel: Channel::G, .. })));
        assert!(matches!(pack([1.0, 1.0, f64::INFINITY]), Err(PackError::NotFinite { channel: Channel::B, .. })));
        assert!(matches!(pack([f64::NEG_INFINITY, 1.0, 1.0]), Err(PackError::NotFinite { channel: Channel::R, .. })));
        assert!(matches!(pack_f32([f32::NAN, 1.0, 1.0]), Err(PackError::NotFinite { channel: Channel::R, .. })));
        // Clamping is to the largest finite code, never to infinity.
        assert_eq!(unpack(pack([1e300, 65024.0 + 1e-9, 64513.0]).unwrap()), [65024.0, 65024.0, 64512.0]);
    }

    /// Every finite code of every channel decodes to a value that packs back
    /// to the same code (2047 − 63 finite R and G codes are 1984, B 992; the
    /// codes with exponent 31 are infinity and NaN).
    #[test]
    fn round_trip_every_code() {
        for c in Channel::ALL {
            let m = c.mantissa_bits();
            let mut finite = 0;
            for k in 0..(1u32 << c.bit_count()) {
                let v = value(c, k);
                if k >> m == 31 {
                    assert!(!v.is_finite(), "{c:?} code {k:#x}");
                    continue;
                }
                finite += 1;
                assert_eq!(single(c, v), k, "{c:?} code {k:#x} = {v}");
                // The other channels stay zero.
                assert_eq!(pack_f32(unpack(k << c.bit_offset())).unwrap(), k << c.bit_offset());
            }
            assert_eq!(finite, 31 << m);
        }
    }

    /// Between consecutive codes a and a + 1: the midpoint goes to the even
    /// one, anything nearer a (the midpoint less one f64 ulp) to a, anything
    /// nearer a + 1 to a + 1. This covers the denormal range, the carry into
    /// the next binade and the last step below the largest value.
    #[test]
    fn rounds_to_nearest_even() {
        for c in Channel::ALL {
            let max = (31u32 << c.mantissa_bits()) - 1;
            for a in 0..max {
                let (lo, hi) = (value(c, a), value(c, a + 1));
                let mid = 0.5 * (lo + hi); // exact in f64
                let even = if a % 2 == 0 { a } else { a + 1 };
                assert_eq!(single(c, mid), even, "{c:?}: midpoint {mid} of codes {a:#x}, {:#x}", a + 1);
                assert_eq!(single(c, mid.next_down()), a, "{c:?}: just below {mid}");
                assert_eq!(single(c, mid.next_up()), a + 1, "{c:?}: just above {mid}");
            }
            // Above the largest: clamped, however close.
            let top = value(c, max);
            assert_eq!(single(c, top.next_up()), max);
            assert_eq!(single(c, top * 2.0), max);
            // Below half the smallest denormal: 0; the half itself ties to 0.
            let tiny = value(c, 1);
            assert_eq!(single(c, 0.5 * tiny), 0);
            assert_eq!(single(c, (0.5 * tiny).next_up()), 1);
        }
    }

    /// Against a brute-force oracle that shares no arithmetic with the
    /// packer: the nearest of all finite codes by exhaustive search (ties to
    /// the even code, above the largest the largest), for log-uniform values
    /// from 2^-24 to 2^17 and for values near every code.
    #[test]
    fn matches_exhaustive_nearest_code() {
        for c in Channel::ALL {
            let codes: Vec<(u32, f64)> = (0..31u32 << c.mantissa_bits()).map(|k| (k, value(c, k))).collect();
            let oracle = |v: f64| {
                let mut best = (0u32, f64::INFINITY);
                for &(k, x) in &codes {
                    let d = (x - v).abs();
                    if d < best.1 || (d == best.1 && k % 2 == 0) {
                        best = (k, d);
                    }
                }
                best.0
            };
            let mut state = 0x9E37_79B9_7F4A_7C15u64 ^ c.bit_offset() as u64;
            let mut next = || {
                // SplitMix64.
                state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
                let mut z = state;
                z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
                z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
                (z ^ (z >> 31)) as f64 / u64::MAX as f64
            };
            for _ in 0..20_000 {
                let v = (next() * 41.0 - 24.0).exp2();
                assert_eq!(single(c, v), oracle(v), "{c:?} {v:e}");
            }
            for &(_, x) in codes.iter().step_by(7) {
                for v in [x * (1.0 + 1e-3), x * (1.0 - 1e-3), x + 1e-12, (x - 1e-12).max(0.0)] {
                    assert_eq!(single(c, v), oracle(v), "{c:?} {v:e}");
                }
            }
        }
    }

    #[test]
    fn array_statistics() {
        let texels = [
            [1.0, 1.0, 1.0],
            [7e4, 1.0, 1.0],              // R clamped
            [7e4, 7e4, 7e4],              // all clamped
            [2f64.powi(-16), 1.0, 0.0],   // R denormal
            [1e-9, 2f64.powi(-17), -1.0], // R underflows, G denormal, B negative
            [0.0, 0.0, 2f64.powi(-15)],   // B denormal
        ];
        let (words, stats) = pack_array(&texels).unwrap();
        assert_eq!(words.len(), texels.len());
        assert_eq!(words[0], 0x781E03C0);
        assert_eq!(
            stats,
            PackStats {
                texels: 6,
                clamped_texels: 2,
                denormal_texels: 3,
                underflow_texels: 1,
                negative_texels: 1,
                clamped_per_channel: [2, 1, 1],
                denormal_per_channel: [1, 1, 1]
            }
        );
        let mut twice = stats;
        twice.merge(&stats);
        assert_eq!(twice.texels, 12);
        assert_eq!(twice.denormal_per_channel, [2, 2, 2]);
        let err = pack_array(&[[1.0; 3], [1.0; 3], [1.0, 1.0, f64::NAN]]).unwrap_err();
        assert_eq!(err.texel, 2);
        assert!(matches!(err.source, PackError::NotFinite { channel: Channel::B, .. }));
        assert!(err.to_string().starts_with("texel 2: B is NaN"), "{err}");
    }
}
