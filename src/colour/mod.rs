//! The colour space a LUT is stored in: CIE 1931 XYZ (what the renderer
//! writes) to linear RGB in Rec.709, Rec.2020 or ACEScg, or XYZ itself.
//!
//! Each RGB space is defined by its primaries and white point, and its
//! matrix is derived from them in f64 (the normalised primary matrix,
//! RP177): with P the matrix whose columns are the primaries' XYZ
//! (x/y, 1, (1 − x − y)/y) and W the white's XYZ (Y = 1), S = P⁻¹ W and
//! RGB → XYZ = P diag(S), so the white has R = G = B = 1.
//!
//! - Rec.709: BT709 primaries R (0.640, 0.330), G (0.300, 0.600),
//!   B (0.150, 0.060), reference white D65 (0.3127, 0.3290). The primaries
//!   and white of sRGB, but derived here, not IEC 61966-2-1's rounded
//!   matrix (the two differ by about 2e-4; `render::output` uses the latter
//!   for previews).
//! - Rec.2020: BT2020 (system colorimetry) primaries R (0.708, 0.292), G (0.170, 0.797),
//!   B (0.131, 0.046), white D65 (0.3127, 0.3290).
//! - ACEScg: S-2014-004 AP1 primaries R (0.713, 0.293), G (0.165,
//!   0.830), B (0.128, 0.044), the ACES white (0.32168, 0.33767), near but
//!   not D60.
//!
//! White. The renderer's XYZ is absolute (cd/m²-scaled CIE 1931 XYZ) under no
//! particular white. All spaces here take the adapted white of the data to
//! be D65, the white of Rec.709 and Rec.2020, so those two need no
//! adaptation (D65 light maps to R = G = B). For ACEScg, whose white is not
//! D65, XYZ is first adapted from D65 to the ACES white with the linear
//! Bradford transform (Lam85; the von Kries form M⁻¹ diag(ρ_ACES / ρ_D65) M
//! of colour-science's `matrix_chromatic_adaptation_VonKries(...,
//! transform="Bradford")`), the convention of the ACES transforms (aces-dev's
//! D60↔D65 CATs are Bradford) and of OCIO's ACES configs for linear Rec.709 →
//! ACEScg. So the same D65-white sky is neutral in every space, and an
//! ACEScg LUT equals the Rec.709 LUT put through a studio's standard
//! Rec.709 → ACEScg transform. (CAT02, colour-science's default, differs
//! from Bradford by about 1e-3 in the matrix.) The matrix actually used is
//! recorded in the manifest, so a decoder can invert it exactly.
//!
//! Negative RGB (colours outside the space's gamut) is clamped to 0 and
//! counted.
//!
//! References:
//! - RP177: SMPTE RP 177-1993, "Derivation of Basic Television Color Equations".
//! - BT709: ITU-R BT.709-6, <https://www.itu.int/rec/R-REC-BT.709-6-201506-I>.
//! - BT2020: ITU-R BT.2020-2, <https://www.itu.int/rec/R-REC-BT.2020-2-201510-I>.
//! - S-2014-004: Academy S-2014-004, "ACEScg — A Working Space for CGI Render
//!   and Compositing", <https://docs.acescentral.com/specifications/acescg/>.
//! - Lam85: K. M. Lam, "Metamerism and Colour Constancy", PhD thesis,
//!   University of Bradford, 1985; the matrix as in colour-science's
//!   `CAT_BRADFORD`.

pub mod error;

use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// A 3×3 matrix, row-major: `out[i] = Σ_j m[i][j] · in[j]`.
pub type Mat3 = [[f64; 3]; 3];

/// CIE 1931 xy of D65 as BT709 and BT2020 give it.
pub const D65_XY: [f64; 2] = [0.3127, 0.3290];
/// CIE 1931 xy of the ACES white (S-2014-004).
pub const ACES_WHITE_XY: [f64; 2] = [0.32168, 0.33767];

/// The linear Bradford cone-response matrix (XYZ → ρ, γ, β) (Lam85).
pub const BRADFORD: Mat3 = [[0.8951, 0.2664, -0.1614], [-0.7502, 1.7135, 0.0367], [0.0389, -0.0685, 1.0296]];

/// The colour space of a LUT's texels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ColourSpace {
    /// Linear Rec.709 (sRGB primaries), D65.
    #[default]
    Rec709,
    /// Linear Rec.2020, D65.
    Rec2020,
    /// ACEScg (AP1 primaries, ACES white), Bradford-adapted from D65.
    AcesCg,
    /// CIE 1931 XYZ itself (the identity).
    Xyz,
}

/// A name that is no colour space.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown colour space {0:?} (expected rec709, rec2020, acescg or xyz)")]
pub struct UnknownColourSpace(pub String);

impl ColourSpace {
    pub const ALL: [ColourSpace; 4] =
        [ColourSpace::Rec709, ColourSpace::Rec2020, ColourSpace::AcesCg, ColourSpace::Xyz];

    /// The name used on the command line and in the manifest.
    pub const fn name(self) -> &'static str {
        match self {
            ColourSpace::Rec709 => "rec709",
            ColourSpace::Rec2020 => "rec2020",
            ColourSpace::AcesCg => "acescg",
            ColourSpace::Xyz => "xyz",
        }
    }

    /// The CIE 1931 xy of the R, G and B primaries; None for XYZ.
    pub const fn primaries_xy(self) -> Option<[[f64; 2]; 3]> {
        match self {
            ColourSpace::Rec709 => Some([[0.640, 0.330], [0.300, 0.600], [0.150, 0.060]]),
            ColourSpace::Rec2020 => Some([[0.708, 0.292], [0.170, 0.797], [0.131, 0.046]]),
            ColourSpace::AcesCg => Some([[0.713, 0.293], [0.165, 0.830], [0.128, 0.044]]),
            ColourSpace::Xyz => None,
        }
    }

    /// The CIE 1931 xy of the space's white (R = G = B); None for XYZ.
    pub const fn white_xy(self) -> Option<[f64; 2]> {
        match self {
            ColourSpace::Rec709 | ColourSpace::Rec2020 => Some(D65_XY),
            ColourSpace::AcesCg => Some(ACES_WHITE_XY),
            ColourSpace::Xyz => None,
        }
    }

    /// The chromatic adaptation applied to XYZ before the space's own
    /// matrix: Bradford from D65 to the space's white (the identity for
    /// Rec.709, Rec.2020 and XYZ).
    pub fn adaptation(self) -> Mat3 {
        match self.white_xy() {
            Some(w) if w != D65_XY => bradford(xy_to_xyz(D65_XY), xy_to_xyz(w)),
            _ => IDENTITY,
        }
    }

    /// The matrix taking the renderer's XYZ to this space's linear RGB
    /// (the adaptation included): the one the manifest records.
    pub fn xyz_to_rgb(self) -> Mat3 {
        match self.primaries_xy().zip(self.white_xy()) {
            Some((p, w)) => {
                mul(&invert(&normalised_primary_matrix(p, w)).expect("primaries are independent"), &self.adaptation())
            }
            None => IDENTITY,
        }
    }

    /// The inverse of [`ColourSpace::xyz_to_rgb`]: linear RGB back to the
    /// renderer's XYZ (undoing the adaptation), for decoders.
    pub fn rgb_to_xyz(self) -> Mat3 {
        invert(&self.xyz_to_rgb()).expect("the matrix is invertible")
    }

    /// XYZ → RGB without clamping.
    pub fn convert(self, xyz: [f64; 3]) -> [f64; 3] {
        apply(&self.xyz_to_rgb(), xyz)
    }

    /// Converts an array of XYZ texels, clamping negative channels to 0,
    /// and counts the texels that had one. NaN passes through unchanged (the
    /// packer reports it with its place).
    pub fn convert_array(self, xyz: &[[f64; 3]]) -> (Vec<[f64; 3]>, ClampStats) {
        let m = self.xyz_to_rgb();
        let mut stats = ClampStats::default();
        let rgb = xyz
            .iter()
            .map(|&v| {
                let mut c = apply(&m, v);
                let mut clamped = false;
                for i in 0..3 {
                    if c[i] < 0.0 {
                        c[i] = 0.0;
                        stats.negative_per_channel[i] += 1;
                        clamped = true;
                    }
                }
                stats.texels += 1;
                stats.negative_texels += clamped as u64;
                c
            })
            .collect();
        (rgb, stats)
    }
}

impl fmt::Display for ColourSpace {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for ColourSpace {
    type Err = UnknownColourSpace;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        ColourSpace::ALL
            .into_iter()
            .find(|c| c.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| UnknownColourSpace(s.to_string()))
    }
}

/// The texels whose RGB went negative in [`ColourSpace::convert_array`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct ClampStats {
    /// Texels converted.
    pub texels: u64,
    /// Texels with at least one negative channel (clamped to 0).
    pub negative_texels: u64,
    /// Negative channels, per channel (R, G, B).
    pub negative_per_channel: [u64; 3],
}

impl ClampStats {
    /// Sums the counts of two arrays.
    pub fn merge(&mut self, other: &ClampStats) {
        self.texels += other.texels;
        self.negative_texels += other.negative_texels;
        for i in 0..3 {
            self.negative_per_channel[i] += other.negative_per_channel[i];
        }
    }
}

const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// XYZ (Y = 1) of a chromaticity: (x/y, 1, (1 − x − y)/y).
pub fn xy_to_xyz([x, y]: [f64; 2]) -> [f64; 3] {
    [x / y, 1.0, (1.0 - x - y) / y]
}

/// RGB → XYZ of primaries `p` and white `w` (RP177).
pub fn normalised_primary_matrix(p: [[f64; 2]; 3], w: [f64; 2]) -> Mat3 {
    let cols = p.map(xy_to_xyz);
    let pm: Mat3 = std::array::from_fn(|i| std::array::from_fn(|j| cols[j][i]));
    let s = apply(&invert(&pm).expect("primaries are independent"), xy_to_xyz(w));
    std::array::from_fn(|i| std::array::from_fn(|j| pm[i][j] * s[j]))
}

/// The Bradford adaptation from white `src` to white `dst` (XYZ):
/// M⁻¹ diag(M dst / M src) M.
pub fn bradford(src: [f64; 3], dst: [f64; 3]) -> Mat3 {
    let (ls, ld) = (apply(&BRADFORD, src), apply(&BRADFORD, dst));
    let d: Mat3 = std::array::from_fn(|i| std::array::from_fn(|j| if i == j { ld[i] / ls[i] } else { 0.0 }));
    mul(&invert(&BRADFORD).expect("Bradford is invertible"), &mul(&d, &BRADFORD))
}

/// m · v.
pub fn apply(m: &Mat3, v: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2])
}

/// a · b.
pub fn mul(a: &Mat3, b: &Mat3) -> Mat3 {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

/// The inverse by cofactors; None when singular.
pub fn invert(m: &Mat3) -> Option<Mat3> {
    let c = |i: usize, j: usize| {
        let (r0, r1) = ((i + 1) % 3, (i + 2) % 3);
        let (c0, c1) = ((j + 1) % 3, (j + 2) % 3);
        m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0]
    };
    let det = m[0][0] * c(0, 0) + m[0][1] * c(0, 1) + m[0][2] * c(0, 2);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    // inverse[i][j] = cofactor[j][i] / det (the cyclic index form carries the signs).
    Some(std::array::from_fn(|i| std::array::from_fn(|j| c(j, i) / det)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::Value;

    fn reference() -> Value {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/reference/colour_spaces.json");
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display())))
            .unwrap()
    }

    fn mat(v: &Value) -> Mat3 {
        std::array::from_fn(|i| std::array::from_fn(|j| v[i][j].as_f64().unwrap()))
    }

    fn vec3(v: &Value) -> [f64; 3] {
        std::array::from_fn(|i| v[i].as_f64().unwrap())
    }

    fn max_diff(a: &Mat3, b: &Mat3) -> f64 {
        (0..9).map(|k| (a[k / 3][k % 3] - b[k / 3][k % 3]).abs()).fold(0.0, f64::max)
    }

    #[test]
    fn names_parse_and_print() {
        for c in ColourSpace::ALL {
            assert_eq!(c.name().parse::<ColourSpace>(), Ok(c));
            assert_eq!(c.to_string(), c.name());
            assert_eq!(serde_json::to_string(&c).unwrap(), format!("\"{}\"", c.name()));
        }
        assert_eq!("ACEScg".parse::<ColourSpace>(), Ok(ColourSpace::AcesCg));
        assert_eq!(ColourSpace::default(), ColourSpace::Rec709);
        assert!("srgb".parse::<ColourSpace>().unwrap_err().to_string().contains("rec709, rec2020, acescg or xyz"));
    }

    /// Our matrices against colour-science 0.4.7 (tests/reference/colour_spaces.json,
    /// scripts/regen_colour_spaces.py): the primaries and whites, the matrix
    /// with the adaptation, the adaptation on its own, and the conversion
    /// of test colours through `colour.XYZ_to_RGB`, to 1e-12.
    #[test]
    fn matches_colour_science() {
        let r = reference();
        for c in [ColourSpace::Rec709, ColourSpace::Rec2020, ColourSpace::AcesCg] {
            let s = &r["spaces"][c.name()];
            let p = c.primaries_xy().unwrap();
            for i in 0..3 {
                for j in 0..2 {
                    assert_eq!(p[i][j], s["primaries_xy"][i][j].as_f64().unwrap(), "{c} primaries");
                }
            }
            assert_eq!(
                c.white_xy().unwrap().to_vec(),
                s["whitepoint_xy"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect::<Vec<_>>()
            );
            let d = max_diff(&c.xyz_to_rgb(), &mat(&s["matrix_XYZ_to_RGB_bradford_from_d65"]));
            assert!(d < 1e-12, "{c}: XYZ→RGB differs by {d:e}");
            let d = max_diff(&c.adaptation(), &mat(&s["cat_bradford_d65_to_white"]));
            assert!(d < 1e-12, "{c}: Bradford differs by {d:e}");
            let npm = c.primaries_xy().zip(c.white_xy()).map(|(p, w)| normalised_primary_matrix(p, w)).unwrap();
            let d = max_diff(&npm, &mat(&s["normalised_primary_matrix"]));
            assert!(d < 1e-12, "{c}: NPM differs by {d:e}");
            for (name, col) in s["colours"].as_object().unwrap() {
                let (xyz, want) = (vec3(&col["XYZ"]), vec3(&col["RGB_bradford_from_d65"]));
                let got = c.convert(xyz);
                let scale = want.iter().fold(1.0f64, |a, v| a.max(v.abs()));
                for i in 0..3 {
                    assert!((got[i] - want[i]).abs() <= 1e-12 * scale, "{c} {name}: {got:?} vs {want:?}");
                }
            }
        }
    }

    /// The XYZ → AP1 matrix published with the ACEScg specification (10
    /// decimals) is the unadapted one; the Bradford step is the documented
    /// difference.
    #[test]
    fn acescg_matches_the_published_matrix() {
        let published: Mat3 = [
            [1.6410233797, -0.3248032942, -0.2364246952],
            [-0.6636628587, 1.6153315917, 0.0167563477],
            [0.0117218943, -0.0082844420, 0.9883948585],
        ];
        let c = ColourSpace::AcesCg;
        let unadapted = invert(&normalised_primary_matrix(c.primaries_xy().unwrap(), c.white_xy().unwrap())).unwrap();
        assert!(max_diff(&unadapted, &published) < 1e-9, "{unadapted:?}");
        assert!(max_diff(&c.xyz_to_rgb(), &mul(&published, &c.adaptation())) < 1e-9);
        // The adaptation is not negligible: ~2 % on the diagonal.
        assert!(max_diff(&c.adaptation(), &IDENTITY) > 0.01);
    }

    #[test]
    fn whites_are_neutral_and_inverses_invert() {
        let d65 = xy_to_xyz(D65_XY);
        for c in [ColourSpace::Rec709, ColourSpace::Rec2020, ColourSpace::AcesCg] {
            let rgb = c.convert(d65);
            for v in rgb {
                assert!((v - 1.0).abs() < 1e-12, "{c}: D65 → {rgb:?}");
            }
        }
        for c in ColourSpace::ALL {
            let d = max_diff(&mul(&c.rgb_to_xyz(), &c.xyz_to_rgb()), &IDENTITY);
            assert!(d < 1e-14, "{c}: {d:e}");
        }
        assert_eq!(ColourSpace::Xyz.xyz_to_rgb(), IDENTITY);
        assert_eq!(ColourSpace::Xyz.convert([1.0, -2.0, 3.0]), [1.0, -2.0, 3.0]);
    }

    #[test]
    fn negatives_are_clamped_and_counted() {
        // 520 nm (CMF values): outside Rec.709's gamut in R and B.
        let spectral = [0.06327, 0.71, 0.07825];
        let xyz = [xy_to_xyz(D65_XY), spectral, [0.0; 3], [f64::NAN, 1.0, 1.0]];
        let (rgb, stats) = ColourSpace::Rec709.convert_array(&xyz);
        assert_eq!(stats, ClampStats { texels: 4, negative_texels: 1, negative_per_channel: [1, 0, 1] });
        assert!(rgb[1][0] == 0.0 && rgb[1][2] == 0.0 && rgb[1][1] > 1.0, "{:?}", rgb[1]);
        assert!(rgb[3][0].is_nan(), "NaN must reach the packer");
        let (_, wide) = ColourSpace::Rec2020.convert_array(&[[0.2, 0.3, 0.4]]);
        assert_eq!(wide.negative_texels, 0);
        let (raw, none) = ColourSpace::Xyz.convert_array(&[[1.0, -1.0, 0.5]]);
        assert_eq!((raw[0], none.negative_per_channel), ([1.0, 0.0, 0.5], [0, 1, 0]));
        let mut sum = stats;
        sum.merge(&stats);
        assert_eq!(sum.negative_texels, 2);
    }
}
