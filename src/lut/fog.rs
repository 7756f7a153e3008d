//! The global-fog LUTs of a basis sky (the talk's "Look-up Table for Global
//! Fog" and "Global Fog Approximation"): their mappings, the Attenuation
//! table, and the depth falloff that replaces the Fog LUT's depth axis.
//!
//! The low atmosphere: the air between the ground and a ceiling (the cloud
//! base of the cloudy basis skies; "only low-altitude atmosphere affects
//! our global fog"), seen from the bake's observer. Along a view ray the
//! fog ends at an object at depth `depth` km; `depth_max` is where the ray
//! leaves the low atmosphere through the ceiling (the talk: "depth_max =
//! distance to atmosphere boundary"), 195 km along the horizon under a 3 km
//! ceiling, 3 km straight up.
//!
//! Directions: both LUTs cover the upper hemisphere, with texels packed
//! toward the horizon, where fog changes fastest and the terrain is:
//!
//!   v = (elevation / 90°)^(1/2),
//!
//! the talk's v = (θ / θ_max)^(1/2) with θ measured from the horizon (our
//! choice: the talk does not say from where; from the zenith the square
//! root would crowd texels at the zenith instead). A view below the horizon
//! (a camera above the terrain looking down at it) reads the horizon row:
//! from a camera near the ground, the air along a ray to nearby terrain is
//! about that of a level ray of the same length. The Fog LUT's u is the
//! azimuth from the sun, 0 to 180° (the sky is mirror-symmetric about the
//! sun's vertical plane), in 32 texels of 5.8°; the Attenuation LUT has no
//! azimuth (the air is horizontally uniform): its u is the depth,
//!
//!   u = (depth / depth_max)^(1/3)    (the talk's),
//!
//! which packs texels near the camera, where fog matters most. Texel i of
//! n holds x = i / (n − 1) (centres on both ends, as in `transmittance`).
//!
//! The falloff (the talk's formula): with x = depth / depth_max and θ the
//! view's elevation over 90° (at least 0.5°: 1 at the zenith),
//!
//!   Fog(dir, x) = LUT(dir) · (1 − e^(−a θ^p x)) / (1 − e^(−a θ^p)),
//!
//! a and p fitted to reference fog renders ([`Falloff::fit`],
//! `fog_falloff`). The talk does not say from where θ is measured; we
//! measured it both ways on the clear sky (`sky lut fog-falloff`, sun 60°,
//! 16 samples): from the zenith the fit's median error was 15 %, from the
//! horizon 10 %. The fitted p is then negative: the rate a θ^p is largest
//! along the horizon, whose long low path saturates within its first
//! kilometres, and smaller upward, whose short path to the ceiling fills
//! more evenly. θ is held at 0.5° and above so that the rate stays finite
//! at the horizon itself.

use crate::colour::Mat3;
use serde::{Deserialize, Serialize};

/// The Fog and Shadowed Fog LUTs' texels: the talk's 32 × 32 per slice.
pub const FOG_WIDTH: usize = 32;
pub const FOG_HEIGHT: usize = 32;
/// The Attenuation LUT's texels: the talk's 64 × 64.
pub const ATTENUATION_SIZE: usize = 64;

/// The low atmosphere that fog comes from, seen from the bake's observer.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FogGeometry {
    pub planet_radius_km: f64,
    pub observer_altitude_km: f64,
    /// The ceiling: only the air below it makes fog.
    pub ceiling_km: f64,
}

impl FogGeometry {
    /// `depth_max`: the distance from the observer along a view of
    /// `elevation_deg` (clamped to the upper hemisphere) to the ceiling.
    pub fn depth_max_km(&self, elevation_deg: f64) -> f64 {
        let s = elevation_deg.clamp(0.0, 90.0).to_radians().sin();
        let (r0, rc) = (self.planet_radius_km + self.observer_altitude_km, self.planet_radius_km + self.ceiling_km);
        -r0 * s + (r0 * r0 * s * s + rc * rc - r0 * r0).max(0.0).sqrt()
    }
}

/// The position x = i / (n − 1) of texel i of n.
pub fn texel_position(i: usize, n: usize) -> f64 {
    i as f64 / (n - 1).max(1) as f64
}

/// The view elevation of v (see the module's mapping), degrees.
pub fn elevation_of_v(v: f64) -> f64 {
    90.0 * v.clamp(0.0, 1.0).powi(2)
}

/// v of a view elevation (below the horizon: the horizon's).
pub fn v_of_elevation(elevation_deg: f64) -> f64 {
    (elevation_deg.clamp(0.0, 90.0) / 90.0).sqrt()
}

/// The Fog LUT's (u, v) of a view (elevation, azimuth from the sun), in
/// [0, 1]²; the azimuth folds into 0..180° by the sky's mirror symmetry.
pub fn fog_uv(elevation_deg: f64, azimuth_from_sun_deg: f64) -> (f64, f64) {
    let a = azimuth_from_sun_deg.rem_euclid(360.0);
    let folded = if a > 180.0 { 360.0 - a } else { a };
    (folded / 180.0, v_of_elevation(elevation_deg))
}

/// The view direction of texel (i, j) of a `width` × `height` Fog LUT
/// with the sun at azimuth 0: (elevation, azimuth), degrees.
pub fn fog_texel_view(i: usize, j: usize, width: usize, height: usize) -> (f64, f64) {
    (elevation_of_v(texel_position(j, height)), 180.0 * texel_position(i, width))
}

/// The Attenuation LUT's (u, v) of an object at `depth_km` along a view of
/// `elevation_deg`.
pub fn attenuation_uv(g: &FogGeometry, depth_km: f64, elevation_deg: f64) -> (f64, f64) {
    let x = (depth_km / g.depth_max_km(elevation_deg)).clamp(0.0, 1.0);
    (x.cbrt(), v_of_elevation(elevation_deg))
}

/// The (depth km, elevation deg) of Attenuation LUT texel (i, j).
pub fn attenuation_texel(g: &FogGeometry, i: usize, j: usize) -> (f64, f64) {
    let elevation = elevation_of_v(texel_position(j, ATTENUATION_SIZE));
    (g.depth_max_km(elevation) * texel_position(i, ATTENUATION_SIZE).powi(3), elevation)
}

/// The lowest elevation the falloff's θ takes, degrees (see the module).
pub const FALLOFF_MIN_ELEVATION_DEG: f64 = 0.5;

/// The normalised θ of the falloff: the view's elevation over 90°, at
/// least [`FALLOFF_MIN_ELEVATION_DEG`] of it.
pub fn falloff_theta(elevation_deg: f64) -> f64 {
    elevation_deg.clamp(FALLOFF_MIN_ELEVATION_DEG, 90.0) / 90.0
}

/// The Attenuation LUT of one basis sky: the XYZ of the sun's spectrum
/// (the bands' weights) after the low atmosphere along each texel's view
/// to its depth, and before it, so that each channel's transmittance is
/// the ratio (see `transmittance` for the same convention).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AttenuationTable {
    pub geometry: FogGeometry,
    /// Row-major, ATTENUATION_SIZE²: x along depth, y along elevation.
    pub xyz: Vec<[f64; 3]>,
    pub unattenuated_xyz: [f64; 3],
}

impl AttenuationTable {
    /// Per-channel transmittance of every texel in the space of matrix
    /// `m` (XYZ → RGB), in texel order.
    pub fn channel_texels(&self, m: &Mat3) -> Vec<[f64; 3]> {
        let top = crate::colour::apply(m, self.unattenuated_xyz);
        self.xyz.iter().map(|x| super::transmittance::channel_ratio(crate::colour::apply(m, *x), top)).collect()
    }

    /// The XYZ of the sun's spectrum after `depth_km` along a view of
    /// `elevation_deg`, bilinear between texel centres.
    pub fn sample_xyz(&self, depth_km: f64, elevation_deg: f64) -> [f64; 3] {
        let (u, v) = attenuation_uv(&self.geometry, depth_km, elevation_deg);
        bilinear(&self.xyz, ATTENUATION_SIZE, ATTENUATION_SIZE, u, v)
    }
}

/// Bilinear lookup between texel centres of a row-major `w` × `h` table
/// at (u, v) in [0, 1]² (clamped), texel i of n at i / (n − 1).
pub fn bilinear(texels: &[[f64; 3]], w: usize, h: usize, u: f64, v: f64) -> [f64; 3] {
    bilinear_by(|i| texels[i], w, h, u, v)
}

/// [`bilinear`] of the texels `texel(index)` gives.
pub fn bilinear_by(texel: impl Fn(usize) -> [f64; 3], w: usize, h: usize, u: f64, v: f64) -> [f64; 3] {
    let (fx, fy) = (u.clamp(0.0, 1.0) * (w - 1) as f64, v.clamp(0.0, 1.0) * (h - 1) as f64);
    let (i, j) = ((fx as usize).min(w - 2), (fy as usize).min(h - 2));
    let (ax, ay) = (fx - i as f64, fy - j as f64);
    let at = |i: usize, j: usize| texel(j * w + i);
    let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1));
    std::array::from_fn(|k| (1.0 - ay) * ((1.0 - ax) * a[k] + ax * b[k]) + ay * ((1.0 - ax) * c[k] + ax * d[k]))
}

/// The talk's depth falloff of the fog: the fraction of the fog at full
/// depth that lies within normalised depth x.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Falloff {
    pub a: f64,
    pub p: f64,
}

/// One reference value for the fit: the fog at normalised depth `x` over
/// the fog at full depth, toward a view of normalised θ `theta`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FalloffSample {
    pub x: f64,
    pub theta: f64,
    pub ratio: f64,
}

impl Falloff {
    /// (1 − e^(−k x)) / (1 − e^(−k)) with k = a θ^p: 0 at x = 0, 1 at
    /// x = 1, and x itself as k → 0 (the fog of a thin path grows
    /// linearly with its length).
    pub fn fraction(&self, x: f64, theta: f64) -> f64 {
        let k = self.a * theta.max(1e-6).powf(self.p);
        if !(k.abs() > 1e-9) {
            return x;
        }
        libm::expm1(-k * x) / libm::expm1(-k)
    }

    /// The least-squares fit of (a, p) to `samples` in relative error
    /// (each residual over its reference ratio, so that fog near the camera,
    /// a small fraction of the whole, weighs as much as fog far away): a
    /// search over log |a| in [−4, 6] for either sign of a and p in [−3,
    /// 6], refined five times around the best point to a tenth of the
    /// previous grid's extent. The fit is smooth in both, so the refinement
    /// finds the minimum to well below the fit's own error. A negative a
    /// makes the fraction convex in x: fog that gathers mostly far from the
    /// camera, as under a cloud base that lights the air below it (the
    /// talk's a is not said to be positive). Samples with a ratio that is
    /// not positive are left out.
    pub fn fit(samples: &[FalloffSample]) -> Falloff {
        let used: Vec<&FalloffSample> = samples.iter().filter(|s| s.ratio > 0.0 && s.ratio.is_finite()).collect();
        let cost = |a: f64, p: f64| -> f64 {
            let f = Falloff { a, p };
            used.iter().map(|s| (f.fraction(s.x, s.theta) / s.ratio - 1.0).powi(2)).sum()
        };
        let mut overall = (Falloff { a: 0.0, p: 0.0 }, f64::INFINITY);
        for sign in [1.0, -1.0] {
            let (mut lo_a, mut hi_a, mut lo_p, mut hi_p) = (-4.0f64, 6.0f64, -3.0f64, 6.0f64);
            let mut best = (0.0, 1.0, f64::INFINITY);
            let n = 40;
            for _ in 0..6 {
                for i in 0..=n {
                    for j in 0..=n {
                        let (ln_a, p) =
                            (lo_a + (hi_a - lo_a) * i as f64 / n as f64, lo_p + (hi_p - lo_p) * j as f64 / n as f64);
                        let c = cost(sign * ln_a.exp(), p);
                        if c < best.2 {
                            best = (ln_a, p, c);
                        }
                    }
                }
                let (wa, wp) = (0.1 * (hi_a - lo_a), 0.1 * (hi_p - lo_p));
                (lo_a, hi_a, lo_p, hi_p) = (best.0 - wa, best.0 + wa, best.1 - wp, best.1 + wp);
            }
            if best.2 < overall.1 {
                overall = (Falloff { a: sign * best.0.exp(), p: best.1 }, best.2);
            }
        }
        overall.0
    }

    /// The relative errors |fit / reference − 1| of the samples used.
    pub fn errors(&self, samples: &[FalloffSample]) -> Vec<f64> {
        samples
            .iter()
            .filter(|s| s.ratio > 0.0 && s.ratio.is_finite())
            .map(|s| (self.fraction(s.x, s.theta) / s.ratio - 1.0).abs())
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn geometry() -> FogGeometry {
        FogGeometry { planet_radius_km: 6371.0, observer_altitude_km: 0.0, ceiling_km: 3.0 }
    }

    /// The depth to the ceiling: 3 km straight up, √(2 R c + c²) along the
    /// horizon (195.5 km), and the chord in between from the law of cosines.
    #[test]
    fn depth_max_is_the_distance_to_the_ceiling() {
        let g = geometry();
        assert!((g.depth_max_km(90.0) - 3.0).abs() < 1e-9);
        assert!((g.depth_max_km(0.0) - (2.0 * 6371.0 * 3.0 + 9.0f64).sqrt()).abs() < 1e-9);
        assert_eq!(g.depth_max_km(-5.0), g.depth_max_km(0.0));
        for e in [1.0f64, 10.0, 45.0] {
            let t = g.depth_max_km(e);
            let (r0, s) = (6371.0f64, e.to_radians().sin());
            let r = (r0 * r0 + t * t + 2.0 * r0 * t * s).sqrt();
            assert!((r - 6374.0).abs() < 1e-9, "{e}: ends at radius {r}");
        }
    }

    /// The mappings round-trip through their texels, put the horizon at
    /// v = 0 and the zenith at v = 1, and fold the azimuth by the mirror.
    #[test]
    fn the_mappings_round_trip() {
        let g = geometry();
        for j in 0..ATTENUATION_SIZE {
            for i in 0..ATTENUATION_SIZE {
                let (depth, elevation) = attenuation_texel(&g, i, j);
                let (u, v) = attenuation_uv(&g, depth, elevation);
                assert!(
                    (u - texel_position(i, ATTENUATION_SIZE)).abs() < 1e-9
                        && (v - texel_position(j, ATTENUATION_SIZE)).abs() < 1e-9,
                    "({i}, {j})"
                );
            }
        }
        for j in 0..FOG_HEIGHT {
            for i in 0..FOG_WIDTH {
                let (e, a) = fog_texel_view(i, j, FOG_WIDTH, FOG_HEIGHT);
                let (u, v) = fog_uv(e, a);
                assert!(
                    (u - texel_position(i, FOG_WIDTH)).abs() < 1e-12
                        && (v - texel_position(j, FOG_HEIGHT)).abs() < 1e-12
                );
                for mirrored in [-a, 360.0 - a] {
                    let (um, vm) = fog_uv(e, mirrored);
                    assert!((um - u).abs() < 1e-12 && vm == v, "azimuth {mirrored}");
                }
            }
        }
        assert_eq!(fog_texel_view(0, 0, FOG_WIDTH, FOG_HEIGHT), (0.0, 0.0));
        assert_eq!(fog_texel_view(FOG_WIDTH - 1, FOG_HEIGHT - 1, FOG_WIDTH, FOG_HEIGHT), (90.0, 180.0));
        assert_eq!(fog_uv(-10.0, 30.0).1, 0.0);
    }

    /// The falloff's limits, and the fit recovers known parameters from
    /// exact samples (and lands within the noise from noisy ones).
    #[test]
    fn the_falloff_fit_recovers_known_parameters() {
        let f = Falloff { a: 12.0, p: 1.7 };
        assert_eq!(f.fraction(0.0, 0.5), 0.0);
        assert!((f.fraction(1.0, 0.5) - 1.0).abs() < 1e-12);
        assert!((Falloff { a: 0.0, p: 1.0 }.fraction(0.3, 0.5) - 0.3).abs() < 1e-12);
        let mut samples = Vec::new();
        let mut noisy = Vec::new();
        for (k, theta) in [0.05, 0.2, 0.5, 0.8, 1.0].into_iter().enumerate() {
            for (l, x) in [0.001, 0.01, 0.05, 0.2, 0.5, 0.9].into_iter().enumerate() {
                let ratio = f.fraction(x, theta);
                samples.push(FalloffSample { x, theta, ratio });
                // ±1 % alternating: noise without a bias.
                let sign = if (k + l) % 2 == 0 { 1.0 } else { -1.0 };
                noisy.push(FalloffSample { x, theta, ratio: ratio * (1.0 + 0.01 * sign) });
            }
        }
        let fit = Falloff::fit(&samples);
        assert!((fit.a / f.a - 1.0).abs() < 1e-3 && (fit.p - f.p).abs() < 1e-3, "{fit:?}");
        let worst = fit.errors(&samples).into_iter().fold(0.0, f64::max);
        assert!(worst < 1e-4, "{worst}");
        let fit = Falloff::fit(&noisy);
        let worst = fit.errors(&samples).into_iter().fold(0.0, f64::max);
        assert!(worst < 0.01, "noisy fit {fit:?}: worst {worst}");
        // Convex: fog gathered mostly far away (a < 0).
        let convex = Falloff { a: -3.0, p: 0.8 };
        assert!(convex.fraction(0.5, 0.5) < 0.5);
        let samples: Vec<FalloffSample> =
            samples.iter().map(|s| FalloffSample { ratio: convex.fraction(s.x, s.theta), ..*s }).collect();
        let fit = Falloff::fit(&samples);
        assert!((fit.a / convex.a - 1.0).abs() < 1e-3 && (fit.p - convex.p).abs() < 1e-3, "{fit:?}");
    }
}
