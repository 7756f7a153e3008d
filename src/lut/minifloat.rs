//! Exact rounding of an f64 into a small unsigned float with a 5-bit
//! exponent (bias 15) and `m` mantissa bits: the channels of R11G11B10
//! (m = 6 for R and G, m = 5 for B) and the magnitude of IEEE binary16
//! (m = 10).
//!
//! The formats ([Vulkan] "Unsigned 11-Bit Floating-Point Numbers" and
//! "Unsigned 10-Bit Floating-Point Numbers"; binary16 is [IEEE 754-2008]
//! §3.6): with exponent field E and mantissa field M,
//!
//! - E = 0:        value = 2^-14 · M / 2^m            (denormal, or zero)
//! - 0 < E < 31:   value = 2^(E − 15) · (1 + M / 2^m)  (normal)
//! - E = 31:       infinity (M = 0) or NaN (M ≠ 0)
//!
//! The largest finite value is 2^15 · (2 − 2^-m): 65024 for m = 6, 64512
//! for m = 5, 65504 for m = 10.
//!
//! Rounding. Vulkan leaves the rounding of conversions into these formats
//! to the implementation. Direct3D ([D3D11], "Floating-point rules", the
//! 11-bit and 10-bit and 16-bit rules) asks for results within 0.5 ULP and
//! keeps denormals; OpenGL ([OpenGL 4.6] "Unsigned 11-Bit" and "Unsigned
//! 10-Bit Floating-Point Numbers", from EXT_packed_float) rounds finite
//! values to the closest representable finite value (allowing rounding
//! toward zero), converts finite values above the maximum to the maximum
//! and negative values to 0. This module gives the correctly rounded result
//! within those rules, with IEEE 754's default tie rule: round to nearest,
//! ties to even, from the f64 value directly (one rounding, so no double
//! rounding through f32), denormals kept, finite values above the largest
//! clamped to it, negative values and −0 to +0. NaN and ±infinity are reported to the caller (`None`), never
//! encoded.
//!
//! [Vulkan]: https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#fundamentals-fp11
//! [D3D11]: https://learn.microsoft.com/en-us/windows/win32/direct3d11/floating-point-rules
//! [OpenGL 4.6]: https://registry.khronos.org/OpenGL/specs/gl/glspec46.core.pdf
//! [IEEE 754-2008]: https://doi.org/10.1109/IEEESTD.2008.4610935

/// Bits of the exponent field.
pub const EXPONENT_BITS: u32 = 5;
/// Exponent bias.
pub const BIAS: i32 = 15;
/// The exponent of the smallest normal value, 2^-14.
const MIN_NORMAL_EXP: i32 = 1 - BIAS;

/// What rounding did to one value, for the bake's statistics.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rounding {
    /// A positive finite value, stored as a normal number.
    Normal,
    /// A positive value stored as a nonzero denormal (below 2^-14).
    Denormal,
    /// +0 stored as 0.
    Zero,
    /// A positive value too small for the smallest denormal: rounded to 0.
    Underflow,
    /// A negative value or −0: stored as 0.
    Negative,
    /// A finite value above the largest finite one: stored as the largest.
    Clamped,
}

/// The largest finite value with `mantissa_bits` bits: 2^15 (2 − 2^-m).
pub fn max_finite(mantissa_bits: u32) -> f64 {
    (2.0 - (-(mantissa_bits as f64)).exp2()) * 32768.0
}

/// The code of the largest finite value: exponent field 30, mantissa all ones.
pub fn max_code(mantissa_bits: u32) -> u32 {
    (31 << mantissa_bits) - 1
}

/// Rounds `v` to the nearest representable value (ties to even) and returns
/// its code (exponent and mantissa fields, `5 + mantissa_bits` bits) and
/// what happened; `None` for NaN and ±infinity.
pub fn encode(v: f64, mantissa_bits: u32) -> Option<(u32, Rounding)> {
    if !v.is_finite() {
        return None;
    }
    // `!(v > 0)` also catches −0.
    if !(v > 0.0) {
        return Some((0, if v == 0.0 && v.is_sign_positive() { Rounding::Zero } else { Rounding::Negative }));
    }
    let max = max_finite(mantissa_bits);
    if v > max {
        return Some((max_code(mantissa_bits), Rounding::Clamped));
    }
    // e = floor(log2 v) from the f64 exponent field. Every f64 below 2^-14
    // (f64 denormals included) takes the target's denormal quantum, so its
    // exact exponent is not needed.
    let e = if v >= f64::from(MIN_NORMAL_EXP).exp2() {
        ((v.to_bits() >> 52) & 0x7ff) as i32 - 1023
    } else {
        MIN_NORMAL_EXP
    };
    // The spacing of representable values in v's binade (in the denormal
    // range, the fixed spacing 2^(-14 - m)). v / q is exact: q is a power
    // of two and the quotient stays far from the f64 limits.
    let q = f64::from(e.max(MIN_NORMAL_EXP) - mantissa_bits as i32).exp2();
    // The representable values of the binade are n q for integers n (in
    // 2^m ..= 2^(m+1) for normal binades, 0 ..= 2^m below 2^-14), and the
    // parity of n is the parity of the mantissa's last bit, so rounding
    // v / q to the nearest integer, ties to even, is IEEE round-to-nearest-
    // even in the target format.
    let n = (v / q).round_ties_even() as u32;
    // Code = (biased exponent << m) + mantissa. For a normal binade with
    // biased exponent b = e + 15 that is (b << m) + (n − 2^m) =
    // ((b − 1) << m) + n; in the denormal range (b = 0, n ≤ 2^m) it is n. A
    // carry (n = 2^(m+1), or n = 2^m out of the denormals) lands on the next
    // binade's first code by the same formula.
    let code = if e < MIN_NORMAL_EXP { n } else { (((e + BIAS - 1) as u32) << mantissa_bits) + n };
    // v ≤ max rounds at most to max: no carry into the infinity code.
    debug_assert!(code <= max_code(mantissa_bits));
    let kind = if code == 0 {
        Rounding::Underflow
    } else if code < (1 << mantissa_bits) {
        Rounding::Denormal
    } else {
        Rounding::Normal
    };
    Some((code, kind))
}

/// The exact value of `code` (the low `5 + mantissa_bits` bits are used):
/// denormals, normals, +infinity for exponent 31 with mantissa 0, NaN for
/// exponent 31 otherwise. Every finite value is exact in f32.
pub fn decode(code: u32, mantissa_bits: u32) -> f32 {
    let mant = code & ((1 << mantissa_bits) - 1);
    let exp = (code >> mantissa_bits) & ((1 << EXPONENT_BITS) - 1);
    let m = mantissa_bits as i32;
    match exp {
        0 => mant as f32 * f64::from(MIN_NORMAL_EXP - m).exp2() as f32,
        31 if mant == 0 => f32::INFINITY,
        31 => f32::NAN,
        _ => ((1 << mantissa_bits) + mant) as f32 * f64::from(exp as i32 - BIAS - m).exp2() as f32,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn largest_values() {
        assert_eq!(max_finite(6), 65024.0);
        assert_eq!(max_finite(5), 64512.0);
        assert_eq!(max_finite(10), 65504.0);
        for m in [5, 6, 10] {
            assert_eq!(decode(max_code(m), m) as f64, max_finite(m));
            assert_eq!(decode(max_code(m) + 1, m), f32::INFINITY);
            assert!(decode(max_code(m) + 2, m).is_nan());
        }
    }

    #[test]
    fn specials() {
        for m in [5, 6, 10] {
            assert_eq!(encode(f64::NAN, m), None);
            assert_eq!(encode(f64::INFINITY, m), None);
            assert_eq!(encode(f64::NEG_INFINITY, m), None);
            assert_eq!(encode(0.0, m), Some((0, Rounding::Zero)));
            assert_eq!(encode(-0.0, m), Some((0, Rounding::Negative)));
            assert_eq!(encode(-1.0, m), Some((0, Rounding::Negative)));
            assert_eq!(encode(f64::MAX, m), Some((max_code(m), Rounding::Clamped)));
            assert_eq!(encode(f64::MIN_POSITIVE / 4.0, m), Some((0, Rounding::Underflow)));
        }
    }

    /// binary16 agrees with IEEE half on well-known values (m = 10).
    #[test]
    fn binary16_known_values() {
        assert_eq!(encode(1.0, 10).unwrap().0, 0x3c00);
        assert_eq!(encode(65504.0, 10).unwrap().0, 0x7bff);
        assert_eq!(encode(2f64.powi(-24), 10).unwrap().0, 0x0001);
        assert_eq!(encode(2f64.powi(-14), 10).unwrap().0, 0x0400);
        assert_eq!(encode(1.0 / 3.0, 10).unwrap().0, 0x3555);
        // 1 + 2^-11 is the tie between 0x3c00 and 0x3c01: to even.
        assert_eq!(encode(1.0 + 2f64.powi(-11), 10).unwrap().0, 0x3c00);
        assert_eq!(encode(1.0 + 3.0 * 2f64.powi(-11), 10).unwrap().0, 0x3c02);
    }
}
