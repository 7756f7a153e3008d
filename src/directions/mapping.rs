//! The talk's adaptive LUT mappings ("Adaptive Mapping of LUT (time
//! component)", "Adaptive Mapping of LUT (spherical direction)", "Detail of
//! Adaptive Mapping" and its "Concept Code").
//!
//! Time: 64 slices of sun zenith angle θ_z. The 48 upper ones are spaced
//! evenly in d, the distance from the ground to the top of the atmosphere
//! along the sun's direction, from d_min (vertical) to d_max (horizontal):
//! d_i = lerp(d_min, d_max, i / 47). The 16 lower ones are
//! θ_z = lerp(90°, 100°, ((i − 48) / 15)²).
//!
//! Direction: a slice is a (u, v) ∈ [0, 1]² texture of one half of the sky
//! (the sky is mirror-symmetric about the sun's vertical plane). While the
//! sun is above the threshold, v measures the angle from the sun, normalised
//! so that the horizon is the line v' = 0.5 (the "normalization"), after a
//! nonlinear transform of v that gives more texels around the sun and just
//! above the horizon; u is the heading around the sun. Below the threshold,
//! a latitude-longitude mapping with its own nonlinear transform.
//!
//! Frame: z is the zenith and the sun lies in the x-z plane at +x (azimuth 0);
//! u covers the half with y ≥ 0. Around the sun, heading φ = u π is measured
//! from the tangent that points from the sun down toward the horizon below
//! it (the frame the concept code's `edge` formula implies: at φ = 0 the
//! horizon lies π/2 − θ_sun away). Below the threshold, the concept code's
//! azimuth u π + π/2 is in its own frame; here u π is the azimuth from the
//! sun's, so u = 0 still faces the sun.

use glam::DVec3;
use std::f64::consts::PI;

/// Slices in the upper region (sun above the horizon).
pub const UPPER_SLICES: usize = 48;
/// Slices in the lower region (sun 0 to 10° below the horizon).
pub const LOWER_SLICES: usize = 16;
/// All slices of a basis sky.
pub const SLICES: usize = UPPER_SLICES + LOWER_SLICES;
/// The lowest sun of the lower region: 100° zenith (10° below the horizon).
pub const LOWEST_SUN_ZENITH_DEG: f64 = 100.0;

// The concept code's constants of the nonlinear v transform (upper region).
/// The concept code's "nonlinear transformations" of v (upper region):
/// knots a, b and their images c, d (b → d = 0.5 puts the horizon at v = b).
pub const A: f64 = 0.50;
pub const B: f64 = 0.80;
pub const C: f64 = 0.25;
pub const D: f64 = 0.50;
/// The concept code's exponent p of the first two arcs.
pub const P: f64 = 2.0;

/// The sun zenith angle of time slice `index` (0..64), degrees, for a planet
/// of `radius_km` with its atmosphere's top at `top_km`.
pub fn slice_sun_zenith_deg(index: usize, radius_km: f64, top_km: f64) -> f64 {
    if index < UPPER_SLICES {
        let (d_min, d_max) = (top_km, horizontal_distance_km(radius_km, top_km));
        let d = d_min + (d_max - d_min) * index as f64 / (UPPER_SLICES - 1) as f64;
        zenith_for_distance_deg(d, radius_km, top_km)
    } else {
        let f = (index - UPPER_SLICES) as f64 / (LOWER_SLICES - 1) as f64;
        90.0 + (LOWEST_SUN_ZENITH_DEG - 90.0) * f * f
    }
}

/// The continuous slice coordinate (0 … 63) of a sun zenith angle: the
/// inverse of [`slice_sun_zenith_deg`], for interpolating between slices.
/// Suns lower than 100° clamp to the last slice.
pub fn slice_coordinate(sun_zenith_deg: f64, radius_km: f64, top_km: f64) -> f64 {
    let z = sun_zenith_deg.clamp(0.0, LOWEST_SUN_ZENITH_DEG);
    if z <= 90.0 {
        let (d_min, d_max) = (top_km, horizontal_distance_km(radius_km, top_km));
        let d = distance_to_top_km(z, radius_km, top_km);
        ((d - d_min) / (d_max - d_min) * (UPPER_SLICES - 1) as f64).clamp(0.0, (UPPER_SLICES - 1) as f64)
    } else {
        let f = ((z - 90.0) / (LOWEST_SUN_ZENITH_DEG - 90.0)).sqrt();
        UPPER_SLICES as f64 + f * (LOWER_SLICES - 1) as f64
    }
}

/// d_max: the distance from the ground to the top along the horizon.
pub fn horizontal_distance_km(radius_km: f64, top_km: f64) -> f64 {
    let r_top = radius_km + top_km;
    (r_top * r_top - radius_km * radius_km).sqrt()
}

/// The distance from the ground to the top of the atmosphere along zenith
/// angle θ: the positive root of d² + 2 R d cos θ − ((R + H)² − R²) = 0.
fn distance_to_top_km(zenith_deg: f64, radius_km: f64, top_km: f64) -> f64 {
    let mu = libm::cos(zenith_deg.to_radians());
    let r = radius_km;
    let h2 = (r + top_km) * (r + top_km) - r * r;
    -r * mu + (r * r * mu * mu + h2).sqrt()
}

/// The zenith angle whose distance to the top is `d_km` (the same relation
/// solved for cos θ = (h² − d²) / (2 R d), with h² = (R + H)² − R²).
fn zenith_for_distance_deg(d_km: f64, radius_km: f64, top_km: f64) -> f64 {
    let r = radius_km;
    let h2 = (r + top_km) * (r + top_km) - r * r;
    let mu = ((h2 - d_km * d_km) / (2.0 * r * d_km)).clamp(-1.0, 1.0);
    libm::acos(mu).to_degrees()
}

/// The sun zenith angle below which (θ_sun greater than this) the mapping
/// switches to latitude-longitude, for a `width` × `height` slice.
///
/// The talk leaves `threshold_theta_sun_deg()` unspecified. As the sun
/// nears the horizon, the normalised mapping squeezes the whole upper sky
/// into the headings around φ = 90°, and one texel step there grows without
/// bound. We switch where the largest angle between neighbouring texels
/// above the horizon first exceeds 90°: beyond that a texel cannot
/// represent anything (87.5° for the talk's 32 × 128). Scanned in 0.1°
/// steps from 60°.
pub fn default_threshold_deg(width: usize, height: usize) -> f64 {
    let mut z = 60.0;
    while z < 90.0 {
        if largest_texel_step_deg(z, width, height) > 90.0 {
            return z - 0.1;
        }
        z += 0.1;
    }
    90.0
}

/// The largest angle between neighbouring texel centres (degrees) among
/// texels above the horizon, with the upper-region mapping forced.
pub fn largest_texel_step_deg(sun_zenith_deg: f64, width: usize, height: usize) -> f64 {
    let theta_sun = sun_zenith_deg.to_radians();
    let at = |i: usize, j: usize| {
        upper_uv_to_direction((i as f64 + 0.5) / width as f64, (j as f64 + 0.5) / height as f64, theta_sun)
    };
    let mut worst: f64 = 0.0;
    for j in 0..height {
        for i in 0..width {
            let p = at(i, j);
            if p.z < 0.0 {
                continue;
            }
            if i + 1 < width {
                worst = worst.max(angle(p, at(i + 1, j)));
            }
            if j + 1 < height {
                worst = worst.max(angle(p, at(i, j + 1)));
            }
        }
    }
    worst.to_degrees()
}

fn angle(a: DVec3, b: DVec3) -> f64 {
    libm::acos(a.dot(b).clamp(-1.0, 1.0))
}

/// The mapping of one slice: sun zenith angle and the switch threshold.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DirectionMapping {
    pub sun_zenith_deg: f64,
    pub threshold_deg: f64,
}

impl DirectionMapping {
    pub fn new(sun_zenith_deg: f64, threshold_deg: f64) -> DirectionMapping {
        DirectionMapping { sun_zenith_deg, threshold_deg }
    }

    /// Whether the sun-centred (normalised) mapping is in use.
    pub fn sun_centred(&self) -> bool {
        self.sun_zenith_deg <= self.threshold_deg
    }

    /// The direction of texture position (u, v) ∈ [0, 1]², in the frame
    /// with the sun at azimuth 0 (the concept code's uvToWorldSpaceDirection).
    pub fn direction(&self, u: f64, v: f64) -> DVec3 {
        let theta_sun = self.sun_zenith_deg.to_radians();
        if self.sun_centred() {
            upper_uv_to_direction(u, v, theta_sun)
        } else {
            lower_uv_to_direction(u, v, theta_sun)
        }
    }

    /// The texture position of direction `d` (any length; its mirror image
    /// when y < 0): the inverse of [`direction`](Self::direction).
    pub fn uv(&self, d: DVec3) -> (f64, f64) {
        self.uv_in_region(d, self.sun_centred())
    }

    /// [`uv`](Self::uv) in a chosen region: a decoder that blends a slice
    /// of each region (the sun between the two slices around the threshold)
    /// reads each slice in the region it was rendered in.
    pub fn uv_in_region(&self, d: DVec3, sun_centred: bool) -> (f64, f64) {
        let d = DVec3::new(d.x, d.y.abs(), d.z).normalize();
        let theta_sun = self.sun_zenith_deg.to_radians();
        if sun_centred {
            let (s, t, b) = sun_frame(theta_sun);
            let theta = angle(d, s);
            let (x, y) = (d.dot(t), d.dot(b));
            let phi = if x == 0.0 && y == 0.0 { 0.0 } else { libm::atan2(y, x) };
            let phi = phi.clamp(0.0, PI);
            let edge = horizon_edge(phi, theta_sun);
            let vp = if theta <= edge { 0.5 * theta / edge } else { 0.5 + 0.5 * (theta - edge) / (PI - edge) };
            (phi / PI, upper_v_inverse(vp.clamp(0.0, 1.0)))
        } else {
            let theta = libm::acos(d.z.clamp(-1.0, 1.0));
            let phi = libm::atan2(d.y, d.x).clamp(0.0, PI);
            (phi / PI, lower_v_inverse(theta / PI, theta_sun))
        }
    }
}

/// The sun, the tangent from it down toward the horizon below it, and the
/// binormal (+y): the frame of the sun-centred mapping.
fn sun_frame(theta_sun: f64) -> (DVec3, DVec3, DVec3) {
    let (st, ct) = (libm::sin(theta_sun), libm::cos(theta_sun));
    (DVec3::new(st, 0.0, ct), DVec3::new(ct, 0.0, -st), DVec3::Y)
}

/// The angle from the sun to the horizon along heading φ (the concept
/// code's `edge`): π/2 − atan(cos φ tan θ_sun).
fn horizon_edge(phi: f64, theta_sun: f64) -> f64 {
    PI / 2.0 - libm::atan(libm::sin(PI / 2.0 - phi) * libm::tan(theta_sun))
}

/// The concept code's nonlinear transform of v (upper region, p = 2).
fn upper_v(v: f64) -> f64 {
    if v <= A {
        let k = v / A;
        C - C * (1.0 - k * k)
    } else if v <= B {
        let k = (v - B) / (B - A);
        C + (D - C) * (1.0 - k * k)
    } else {
        let k = (v - B) / (1.0 - B);
        1.0 - (1.0 - D) * (1.0 - k * k).max(0.0).sqrt()
    }
}

/// The inverse of [`upper_v`].
fn upper_v_inverse(vp: f64) -> f64 {
    if vp <= C {
        A * (vp / C).max(0.0).sqrt()
    } else if vp <= D {
        let k2 = (1.0 - (vp - C) / (D - C)).max(0.0);
        B - k2.sqrt() * (B - A)
    } else {
        let s = (1.0 - vp) / (1.0 - D);
        B + (1.0 - s * s).max(0.0).sqrt() * (1.0 - B)
    }
}

fn upper_uv_to_direction(u: f64, v: f64, theta_sun: f64) -> DVec3 {
    let phi = u * PI;
    let vp = upper_v(v);
    let edge = horizon_edge(phi, theta_sun);
    let theta = if vp <= 0.5 { vp / 0.5 * edge } else { (vp / 0.5 - 1.0) * (PI - edge) + edge };
    let (s, t, b) = sun_frame(theta_sun);
    let (st, ct) = (libm::sin(theta), libm::cos(theta));
    (s * ct + (t * libm::cos(phi) + b * libm::sin(phi)) * st).normalize()
}

/// The lower region's transform: two circular arcs meeting at K = min(0.5,
/// θ_sun / π) with zero slope, so texels crowd around the sun's altitude
/// (the horizon, for a sun below it).
fn lower_v(v: f64, theta_sun: f64) -> f64 {
    let k = (theta_sun / PI).min(0.5);
    if v <= k {
        (k * k - (v - k) * (v - k)).max(0.0).sqrt()
    } else {
        1.0 - ((1.0 - k) * (1.0 - k) - (v - k) * (v - k)).max(0.0).sqrt()
    }
}

fn lower_v_inverse(vp: f64, theta_sun: f64) -> f64 {
    let k = (theta_sun / PI).min(0.5);
    if vp <= k {
        k - (k * k - vp * vp).max(0.0).sqrt()
    } else {
        k + ((1.0 - k) * (1.0 - k) - (1.0 - vp) * (1.0 - vp)).max(0.0).sqrt()
    }
}

fn lower_uv_to_direction(u: f64, v: f64, theta_sun: f64) -> DVec3 {
    let theta = lower_v(v, theta_sun) * PI;
    let phi = u * PI;
    let st = libm::sin(theta);
    DVec3::new(st * libm::cos(phi), st * libm::sin(phi), libm::cos(theta))
}

#[cfg(test)]
mod tests {
    use super::*;

    const R: f64 = 6360.0;
    const H: f64 = 100.0;

    #[test]
    fn time_slices_follow_the_talk() {
        // Slice 0: sun at the zenith; slice 47: on the horizon (d = d_max);
        // 48..63: 90° to 100°, quadratically.
        assert!(slice_sun_zenith_deg(0, R, H).abs() < 1e-6);
        assert!((slice_sun_zenith_deg(47, R, H) - 90.0).abs() < 1e-6);
        assert_eq!(slice_sun_zenith_deg(48, R, H), 90.0);
        assert_eq!(slice_sun_zenith_deg(63, R, H), 100.0);
        assert!((slice_sun_zenith_deg(48 + 5, R, H) - (90.0 + 10.0 * (5.0f64 / 15.0).powi(2))).abs() < 1e-12);
        // Monotonic, denser toward the horizon, and invertible.
        let z: Vec<f64> = (0..SLICES).map(|i| slice_sun_zenith_deg(i, R, H)).collect();
        for i in 1..UPPER_SLICES {
            assert!(z[i] > z[i - 1]);
            assert!((slice_coordinate(z[i], R, H) - i as f64).abs() < 1e-6, "{i}");
        }
        for i in (UPPER_SLICES + 1)..SLICES {
            assert!((slice_coordinate(z[i], R, H) - i as f64).abs() < 1e-9, "{i}");
        }
        assert!(z[47] - z[46] < z[1] - z[0]);
    }

    #[test]
    fn v_transforms_are_continuous_and_inverted() {
        for k in 0..=1000 {
            let v = k as f64 / 1000.0;
            assert!((upper_v_inverse(upper_v(v)) - v).abs() < 1e-6, "{v}");
            for ts in [1.6, 1.7, 2.0] {
                assert!((lower_v_inverse(lower_v(v, ts), ts) - v).abs() < 1e-6, "{v}");
            }
        }
        // The knots: v = a → c, v = b → d (the horizon after normalization).
        assert!((upper_v(A) - C).abs() < 1e-15 && (upper_v(B) - D).abs() < 1e-15);
    }

    #[test]
    fn the_horizon_is_a_straight_line_and_the_sun_is_v_zero() {
        // The talk: "This makes the horizon a straight line on the LUT" and
        // "Sun and horizon are aligned".
        for sun in [0.0, 30.0, 60.0, 80.0, 87.0] {
            let m = DirectionMapping::new(sun, 87.5);
            let s = m.direction(0.3, 0.0);
            assert!((s - crate::directions::camera::direction_deg(sun, 0.0)).length() < 1e-9, "{sun}");
            for k in 0..=20 {
                let u = k as f64 / 20.0;
                let h = m.direction(u, B);
                assert!(h.z.abs() < 1e-9, "sun {sun}, u {u}: {h}");
                assert!(h.y >= -1e-12);
                // Anti-sun at v = 1.
                let a = m.direction(u, 1.0);
                assert!((a + s).length() < 1e-6, "{a} {s}");
            }
        }
    }

    #[test]
    fn uv_round_trips_in_both_regions() {
        for (sun, threshold) in [(40.0, 87.5), (85.0, 87.5), (89.0, 87.5), (95.0, 87.5)] {
            let m = DirectionMapping::new(sun, threshold);
            for i in 1..32 {
                for j in 1..128 {
                    let (u, v) = (i as f64 / 32.0, j as f64 / 128.0);
                    let d = m.direction(u, v);
                    assert!((d.length() - 1.0).abs() < 1e-12);
                    let (u2, v2) = m.uv(d);
                    let d2 = m.direction(u2, v2);
                    assert!((d - d2).length() < 1e-6, "sun {sun} (u, v) = ({u}, {v}) -> {d} -> ({u2}, {v2}) -> {d2}");
                }
            }
        }
    }

    #[test]
    fn texels_cover_the_half_sphere() {
        // Every direction with y ≥ 0 has a texel within a few degrees, for
        // both regions (a coarse check that the mapping leaves no holes).
        for sun in [30.0, 86.0, 95.0] {
            let m = DirectionMapping::new(sun, 87.5);
            let texels: Vec<DVec3> = (0..64)
                .flat_map(|i| (0..256).map(move |j| (i, j)))
                .map(|(i, j)| m.direction((i as f64 + 0.5) / 64.0, (j as f64 + 0.5) / 256.0))
                .collect();
            for a in 0..=18 {
                for z in 0..=36 {
                    let d = crate::directions::camera::direction_deg(z as f64 * 5.0, a as f64 * 10.0);
                    let nearest = texels.iter().map(|t| angle(*t, d)).fold(f64::INFINITY, f64::min);
                    assert!(
                        nearest.to_degrees() < 12.0,
                        "sun {sun}: ({}, {}) is {}° from any texel",
                        z * 5,
                        a * 10,
                        nearest.to_degrees()
                    );
                }
            }
        }
    }

    #[test]
    fn default_threshold_is_where_texels_break_down() {
        let t = default_threshold_deg(32, 128);
        assert!(largest_texel_step_deg(t, 32, 128) <= 90.0);
        assert!(largest_texel_step_deg(t + 0.2, 32, 128) > 90.0);
        assert!(t > 80.0 && t < 90.0, "{t}");
    }
}
