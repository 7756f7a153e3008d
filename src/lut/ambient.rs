//! The ambient LUT (the talk's "Other Look-up Tables": "Sky average ambient
//! lighting"): per basis sky and slice, the sky's irradiance on an upward
//! horizontal surface, its mean radiance over the upper hemisphere, and
//! the order-2 real spherical harmonics of its radiance over the whole
//! sphere (9 coefficients per channel) for directional ambient, all by
//! numerical integration of the slice as stored (bilinear at texel
//! centres, through the slice's own direction mapping, as the decoder
//! reads it).
//!
//! Spherical harmonics and the irradiance they give: Ramamoorthi &
//! Hanrahan, "An Efficient Representation for Irradiance Environment
//! Maps" (SIGGRAPH 2001), eqs. 3, 7 and 8. Real, orthonormal basis in the
//! order Y00, Y1−1, Y10, Y11, Y2−2, Y2−1, Y20, Y21, Y22 with z up:
//!
//!   Y00 = 0.282095;  Y1−1, Y10, Y11 = 0.488603 (y, z, x);
//!   Y2−2, Y2−1, Y21 = 1.092548 (xy, yz, xz);  Y20 = 0.315392 (3z² − 1);
//!   Y22 = 0.546274 (x² − y²);
//!
//! irradiance E(n) = Σ_lm Â_l L_lm Y_lm(n), Â0 = π, Â1 = 2π/3, Â2 = π/4.
//!
//! Quadrature: the midpoint rule on a latitude-longitude grid of
//! `ROWS` × 2 `ROWS` cells, weights sin θ Δθ Δφ (exact for the constant
//! to 2e-4 at 64 rows); in the upper hemisphere only for the irradiance and
//! the mean (the horizon is a cell edge).

use super::decode::Texture;
use crate::directions::mapping::DirectionMapping;
use glam::DVec3;
use std::f64::consts::PI;

/// Rows of the integration grid over θ in [0, π] (columns: twice as many).
pub const ROWS: usize = 64;

/// The nine real spherical harmonics at unit direction `d`.
pub fn sh9(d: DVec3) -> [f64; 9] {
    let (x, y, z) = (d.x, d.y, d.z);
    [
        0.282095,
        0.488603 * y,
        0.488603 * z,
        0.488603 * x,
        1.092548 * x * y,
        1.092548 * y * z,
        0.315392 * (3.0 * z * z - 1.0),
        1.092548 * x * z,
        0.546274 * (x * x - y * y),
    ]
}

/// Â_l of each of the nine coefficients (Ramamoorthi & Hanrahan, eq. 8).
const A_HAT: [f64; 9] =
    [PI, 2.0 * PI / 3.0, 2.0 * PI / 3.0, 2.0 * PI / 3.0, PI / 4.0, PI / 4.0, PI / 4.0, PI / 4.0, PI / 4.0];

/// What a slice gives for ambient light, per channel of whatever the
/// radiance was (XYZ or linear RGB).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Ambient {
    /// Irradiance on an upward horizontal surface from the upper hemisphere.
    pub irradiance_up: [f64; 3],
    /// Mean radiance over the upper hemisphere.
    pub mean_radiance: [f64; 3],
    /// L_lm of the radiance over the whole sphere, per channel.
    pub sh9: [[f64; 3]; 9],
}

impl Ambient {
    /// Integrates `radiance(direction)` over the sphere.
    pub fn integrate(radiance: impl Fn(DVec3) -> [f64; 3]) -> Ambient {
        let (rows, cols) = (ROWS, 2 * ROWS);
        let (dt, dp) = (PI / rows as f64, 2.0 * PI / cols as f64);
        let mut out = Ambient::zero();
        let mut upper_solid_angle = 0.0;
        for i in 0..rows {
            let theta = (i as f64 + 0.5) * dt;
            let (st, ct) = (libm::sin(theta), libm::cos(theta));
            let w = st * dt * dp;
            for j in 0..cols {
                let phi = (j as f64 + 0.5) * dp;
                let d = DVec3::new(st * libm::cos(phi), st * libm::sin(phi), ct);
                let l = radiance(d);
                let y = sh9(d);
                for (k, yk) in y.iter().enumerate() {
                    for c in 0..3 {
                        out.sh9[k][c] += l[c] * yk * w;
                    }
                }
                if ct > 0.0 {
                    upper_solid_angle += w;
                    for c in 0..3 {
                        out.irradiance_up[c] += l[c] * ct * w;
                        out.mean_radiance[c] += l[c] * w;
                    }
                }
            }
        }
        out.mean_radiance = out.mean_radiance.map(|m| m / upper_solid_angle);
        out
    }

    /// The irradiance the spherical harmonics give on a surface with
    /// normal `n` (Ramamoorthi & Hanrahan, eq. 7).
    pub fn sh_irradiance(&self, n: DVec3) -> [f64; 3] {
        let y = sh9(n);
        std::array::from_fn(|c| (0..9).map(|k| A_HAT[k] * self.sh9[k][c] * y[k]).sum())
    }

    /// The same quantities in another space: every one of them is linear
    /// in the radiance, so a matrix carries them over.
    pub fn transformed(&self, m: &[[f64; 3]; 3]) -> Ambient {
        let t = |v: [f64; 3]| crate::colour::apply(m, v);
        Ambient { irradiance_up: t(self.irradiance_up), mean_radiance: t(self.mean_radiance), sh9: self.sh9.map(t) }
    }

    pub fn zero() -> Ambient {
        Ambient { irradiance_up: [0.0; 3], mean_radiance: [0.0; 3], sh9: [[0.0; 3]; 9] }
    }

    /// Adds `w` times `o`, term by term.
    pub fn add_scaled(&mut self, o: &Ambient, w: f64) {
        for c in 0..3 {
            self.irradiance_up[c] += w * o.irradiance_up[c];
            self.mean_radiance[c] += w * o.mean_radiance[c];
            for k in 0..9 {
                self.sh9[k][c] += w * o.sh9[k][c];
            }
        }
    }

    /// Every term times `s`.
    pub fn scaled(&self, s: f64) -> Ambient {
        let mut out = Ambient::zero();
        out.add_scaled(self, s);
        out
    }

    /// `(1 − f) a + f b`, term by term (between two slices).
    pub fn lerp(a: &Ambient, b: &Ambient, f: f64) -> Ambient {
        let l = |x: [f64; 3], y: [f64; 3]| std::array::from_fn(|c| (1.0 - f) * x[c] + f * y[c]);
        Ambient {
            irradiance_up: l(a.irradiance_up, b.irradiance_up),
            mean_radiance: l(a.mean_radiance, b.mean_radiance),
            sh9: std::array::from_fn(|k| l(a.sh9[k], b.sh9[k])),
        }
    }
}

/// The ambient of a slice of `width` × `height` texels (row-major, any
/// three channels) rendered through `mapping` (in the region it was
/// rendered in), read as the decoder reads it.
pub fn of_slice(texels: &[[f64; 3]], width: usize, height: usize, mapping: &DirectionMapping) -> Ambient {
    let texture = Texture { width, height, layers: vec![texels.iter().map(|t| t.map(|v| v as f32)).collect()] };
    let sun_centred = mapping.sun_centred();
    Ambient::integrate(|d| {
        let (u, v) = mapping.uv_in_region(d, sun_centred);
        texture.bilinear(0, u, v)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The quadrature projects each harmonic onto itself with weight 1 and
    /// onto the others with 0 (orthonormality), to 1e-3.
    #[test]
    fn the_harmonics_are_orthonormal_under_the_quadrature() {
        for k in 0..9 {
            let a = Ambient::integrate(|d| [sh9(d)[k], 0.0, 0.0]);
            for j in 0..9 {
                let want = if j == k { 1.0 } else { 0.0 };
                assert!((a.sh9[j][0] - want).abs() < 1e-3, "Y{k} onto Y{j}: {}", a.sh9[j][0]);
            }
        }
    }

    /// A sky of radiance 1 + z (brighter toward the zenith, dark at the
    /// nadir): upward irradiance ∫ (1 + cos θ) cos θ dω = π + 2π/3 over the
    /// upper hemisphere, mean radiance 3/2; its harmonics are exact to
    /// order 1, so the irradiance they give equals the direct integral.
    #[test]
    fn a_linear_sky_integrates_to_its_closed_form() {
        let a = Ambient::integrate(|d| [1.0 + d.z, 2.0, 0.0]);
        let want = PI + 2.0 * PI / 3.0;
        assert!((a.irradiance_up[0] / want - 1.0).abs() < 1e-3, "{:?}", a.irradiance_up);
        assert!((a.irradiance_up[1] / (2.0 * PI) - 1.0).abs() < 1e-3, "{:?}", a.irradiance_up);
        assert!((a.mean_radiance[0] / 1.5 - 1.0).abs() < 1e-3 && (a.mean_radiance[1] / 2.0 - 1.0).abs() < 1e-3);
        let e = a.sh_irradiance(DVec3::Z);
        assert!((e[0] / want - 1.0).abs() < 1e-3 && (e[1] / (2.0 * PI) - 1.0).abs() < 1e-3, "{e:?}");
    }
}
