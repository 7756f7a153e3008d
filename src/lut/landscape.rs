//! A procedural landscape to look at the global fog with (the talk's "blue
//! mountains"): rows of ridges at 2 to 100 km, the profile of each a sum of
//! two sines in azimuth, seen from the bake's observer; each ridge
//! is a grey Lambertian surface lit by the decoded sun and sky, seen
//! through the decoded fog at its depth (`decode_fog`): object ×
//! attenuation + fog. Only for pictures: nothing is measured on it.

use super::decode::Luts;
use crate::directions::camera::Camera;
use glam::DVec3;
use std::f64::consts::PI;

/// A ridge: distance from the observer, the mean elevation of its top as
/// seen from the observer, and a phase that sets its profile apart.
pub struct Ridge {
    pub distance_km: f64,
    pub elevation_deg: f64,
    pub phase: f64,
}

/// Nearer ridges lower, so that every row shows above the one before it.
pub const RIDGES: [Ridge; 5] = [
    Ridge { distance_km: 2.0, elevation_deg: 0.6, phase: 0.3 },
    Ridge { distance_km: 6.0, elevation_deg: 1.3, phase: 1.9 },
    Ridge { distance_km: 15.0, elevation_deg: 2.0, phase: 3.4 },
    Ridge { distance_km: 40.0, elevation_deg: 2.7, phase: 4.8 },
    Ridge { distance_km: 100.0, elevation_deg: 3.3, phase: 0.9 },
];

/// The elevation of a ridge's top toward `azimuth_deg`, degrees.
pub fn top_elevation_deg(r: &Ridge, azimuth_deg: f64) -> f64 {
    let a = azimuth_deg.to_radians();
    r.elevation_deg * (0.65 + 0.25 * (17.0 * a + r.phase).sin() + 0.1 * (43.0 * a + 2.0 * r.phase).sin())
}

/// The depth of the nearest ridge a view of (elevation, azimuth) meets, km.
pub fn ridge_depth_km(elevation_deg: f64, azimuth_deg: f64) -> Option<f64> {
    RIDGES
        .iter()
        .find(|r| elevation_deg <= top_elevation_deg(r, azimuth_deg))
        .map(|r| r.distance_km / elevation_deg.to_radians().cos().max(1e-3))
}

/// The normal of the ridge a view `d` meets: the slope facing the camera,
/// tilted 30 degrees up.
pub fn slope_normal(d: DVec3) -> DVec3 {
    let back = DVec3::new(-d.x, -d.y, 0.0).normalize_or_zero();
    (back * 30f64.to_radians().cos() + DVec3::Z * 30f64.to_radians().sin()).normalize()
}

/// The landscape through `camera`, CIE XYZ per pixel (row-major; 0 outside
/// the camera's view), for the sun at (`sun_elevation_deg`,
/// `sun_azimuth_deg`), the weather, and the clouds' occlusion of the air;
/// the ridges' albedo `albedo`. None for a bake without fog or sun.
#[allow(clippy::too_many_arguments)]
pub fn decode_landscape(
    luts: &Luts,
    camera: &Camera,
    width: usize,
    height: usize,
    sun_elevation_deg: f64,
    sun_azimuth_deg: f64,
    haziness: f64,
    cloudiness: f64,
    cloud_occlusion: f64,
    albedo: f64,
) -> Option<Vec<[f64; 3]>> {
    let dirs = super::decode::pixel_directions(camera, width, height);
    landscape_toward(luts, &dirs, sun_elevation_deg, sun_azimuth_deg, haziness, cloudiness, cloud_occlusion, albedo)
}

/// [`decode_landscape`] toward each of `dirs` (world frame, z up; None:
/// black).
#[allow(clippy::too_many_arguments)]
pub fn landscape_toward(
    luts: &Luts,
    dirs: &[Option<DVec3>],
    sun_elevation_deg: f64,
    sun_azimuth_deg: f64,
    haziness: f64,
    cloudiness: f64,
    cloud_occlusion: f64,
    albedo: f64,
) -> Option<Vec<[f64; 3]>> {
    luts.manifest.fog.as_ref()?;
    let sun = luts.sun(sun_elevation_deg, haziness, cloudiness)?;
    let ambient = luts.ambient(sun_elevation_deg, haziness, cloudiness)?;
    let to_sun = crate::directions::camera::direction_deg(90.0 - sun_elevation_deg, sun_azimuth_deg);
    let to_xyz = |rgb: [f64; 3]| crate::colour::apply(&luts.manifest.colour.xyz_from_rgb, rgb);
    let mut out = Vec::with_capacity(dirs.len());
    for &d in dirs {
        let Some(d) = d else {
            out.push([0.0; 3]);
            continue;
        };
        let elevation = d.z.clamp(-1.0, 1.0).asin().to_degrees();
        let azimuth = d.y.atan2(d.x).to_degrees();
        let Some(depth) = ridge_depth_km(elevation, azimuth) else {
            out.push(luts.sample_xyz(sun_elevation_deg, sun_azimuth_deg, haziness, cloudiness, d));
            continue;
        };
        let cos_sun = slope_normal(d).dot(to_sun).max(0.0);
        let object: [f64; 3] =
            std::array::from_fn(|c| albedo / PI * (sun.irradiance_rgb[c] * cos_sun + ambient.irradiance_up[c]));
        let fog = luts.fog(sun_elevation_deg, sun_azimuth_deg, haziness, cloudiness, d, depth, cloud_occlusion)?;
        out.push(to_xyz(std::array::from_fn(|c| object[c] * fog.attenuation_rgb[c] + fog.inscatter_rgb[c])));
    }
    Some(out)
}
