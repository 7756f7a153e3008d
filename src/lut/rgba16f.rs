//! RGBA16F texels (VK_FORMAT_R16G16B16A16_SFLOAT, DXGI_FORMAT_R16G16B16A16_FLOAT):
//! the fallback for engines whose importers do not load R11G11B10 arrays.
//!
//! Four IEEE binary16 values per texel, R, G, B, A at bytes 0, 2, 4, 6
//! ([IEEE 754-2008] §3.6: sign, 5-bit exponent with bias 15, 10-bit
//! mantissa, 65504 at most). RGB is rounded exactly as the R11G11B10
//! channels are ([`super::minifloat`]: from f64, to nearest with ties to
//! even, denormals kept, finite overflow clamped to 65504), and, like them,
//! negative values and −0 are stored as +0 so that both formats hold the
//! same non-negative data. A is 1.
//!
//! [IEEE 754-2008]: https://doi.org/10.1109/IEEESTD.2008.4610935

use super::minifloat;
use super::r11g11b10::{Channel, PackArrayError, PackError, PackStats};

/// Mantissa bits of binary16.
const MANTISSA_BITS: u32 = 10;
/// The largest finite binary16 value.
pub const MAX: f64 = 65504.0;
/// binary16 1.0, the alpha of every texel.
pub const ONE: u16 = 0x3C00;

/// Packs linear RGB into R, G, B, A = 1 halves, rounding each channel once.
pub fn pack(rgb: [f64; 3]) -> Result<[u16; 4], PackError> {
    pack_classified(rgb).map(|(h, _)| h)
}

fn pack_classified(rgb: [f64; 3]) -> Result<([u16; 4], [minifloat::Rounding; 3]), PackError> {
    let mut out = [0, 0, 0, ONE];
    let mut kinds = [minifloat::Rounding::Zero; 3];
    for (i, channel) in Channel::ALL.into_iter().enumerate() {
        let value = rgb[i];
        let (code, kind) = minifloat::encode(value, MANTISSA_BITS).ok_or(PackError::NotFinite { channel, value })?;
        out[i] = code as u16;
        kinds[i] = kind;
    }
    Ok((out, kinds))
}

/// Packs signed linear values into R, G, B, A = 1 halves: each channel's
/// magnitude rounded as [`pack`] rounds it, with binary16's sign bit set
/// for a negative value (spherical-harmonic coefficients are signed; the
/// sky's texels are not, and go through [`pack`]).
pub fn pack_signed(rgb: [f64; 3]) -> Result<[u16; 4], PackError> {
    let mut out = pack(rgb.map(f64::abs))?;
    for c in 0..3 {
        if rgb[c] < 0.0 && out[c] != 0 {
            out[c] |= 0x8000;
        }
    }
    Ok(out)
}

/// The four channels of a texel, exactly.
pub fn unpack(h: [u16; 4]) -> [f32; 4] {
    h.map(|v| {
        let m = minifloat::decode(u32::from(v & 0x7fff), MANTISSA_BITS);
        if v & 0x8000 != 0 {
            -m
        } else {
            m
        }
    })
}

/// Packs an array of texels, in order, and counts what rounding did (the
/// limits are binary16's: clamped above 65504, denormal below 2^-14).
pub fn pack_array(texels: &[[f64; 3]]) -> Result<(Vec<[u16; 4]>, PackStats), PackArrayError> {
    let mut out = Vec::with_capacity(texels.len());
    let mut stats = PackStats::default();
    for (texel, rgb) in texels.iter().enumerate() {
        let (h, kinds) = pack_classified(*rgb).map_err(|source| PackArrayError { texel, source })?;
        out.push(h);
        stats.add(&kinds);
    }
    Ok((out, stats))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_halves() {
        assert_eq!(pack([1.0, 0.5, 65504.0]).unwrap(), [0x3C00, 0x3800, 0x7BFF, ONE]);
        assert_eq!(pack([1e6, -3.0, 2f64.powi(-24)]).unwrap(), [0x7BFF, 0, 1, ONE]);
        assert_eq!(pack([0.1, std::f64::consts::PI, 1000.0]).unwrap(), [0x2E66, 0x4248, 0x63D0, ONE]);
        assert_eq!(unpack([0x3C00, 0x7BFF, 0x0001, 0xBC00]), [1.0, 65504.0, 2f32.powi(-24), -1.0]);
        assert!(matches!(pack([1.0, 1.0, f64::NAN]), Err(PackError::NotFinite { channel: Channel::B, .. })));
    }

    /// Signed values keep their sign and round their magnitude as `pack`.
    #[test]
    fn signed_halves() {
        assert_eq!(pack_signed([-1.0, 0.5, -0.0]).unwrap(), [0xBC00, 0x3800, 0, ONE]);
        assert_eq!(
            unpack(pack_signed([-0.1, -1e6, 3.0]).unwrap()),
            [-unpack(pack([0.1, 0.0, 0.0]).unwrap())[0], -65504.0, 3.0, 1.0]
        );
        assert!(pack_signed([f64::NAN, 0.0, 0.0]).is_err());
    }

    /// Every finite non-negative half round-trips, and midpoints tie to even.
    #[test]
    fn every_code_and_ties() {
        for k in 0u16..0x7C00 {
            let v = f64::from(unpack([k, 0, 0, 0])[0]);
            assert_eq!(pack([v, 0.0, 0.0]).unwrap()[0], k);
            if k < 0x7BFF {
                let hi = f64::from(unpack([k + 1, 0, 0, 0])[0]);
                let mid = 0.5 * (v + hi);
                assert_eq!(pack([mid, 0.0, 0.0]).unwrap()[0], if k % 2 == 0 { k } else { k + 1 }, "tie above {k:#x}");
            }
        }
    }

    #[test]
    fn array_statistics() {
        let (h, s) = pack_array(&[[7e4, 1.0, 1e-6], [1.0, 1.0, 1.0]]).unwrap();
        assert_eq!(h[1], [ONE; 4]);
        assert_eq!((s.texels, s.clamped_texels, s.denormal_texels), (2, 1, 1));
        assert_eq!(pack_array(&[[1.0; 3], [f64::INFINITY, 0.0, 0.0]]).unwrap_err().texel, 1);
    }
}
