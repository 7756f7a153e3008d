//! Cameras: maps from image positions to view directions. World frame: z is
//! the local zenith at the observer, azimuth φ runs from +x toward +y, and a
//! direction is (sin θ cos φ, sin θ sin φ, cos θ) for zenith angle θ.

use glam::DVec3;
use std::f64::consts::PI;

/// The direction of zenith angle θ and azimuth φ (degrees).
pub fn direction_deg(zenith_deg: f64, azimuth_deg: f64) -> DVec3 {
    let (t, p) = (zenith_deg.to_radians(), azimuth_deg.to_radians());
    DVec3::new(libm::sin(t) * libm::cos(p), libm::sin(t) * libm::sin(p), libm::cos(t))
}

/// How pixels map to directions.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum Camera {
    /// The full sphere: column → azimuth 0..360°, row → zenith angle 0..180°.
    Equirect,
    /// The upper hemisphere, equidistant: the centre is the zenith, the
    /// inscribed circle the horizon; +x to the right, +y up in the image.
    Fisheye,
    /// A perspective view toward (azimuth, elevation) with a horizontal field of view.
    Pinhole { azimuth_deg: f64, elevation_deg: f64, fov_deg: f64 },
    /// One "pixel" per (zenith, azimuth) pair in degrees, for validation.
    Directions(Vec<(f64, f64)>),
    /// A LUT slice: texel (u, v) through the talk's adaptive mapping
    /// ([`crate::directions::mapping`]), turned to the sun's azimuth. Texel centres
    /// are sampled without jitter, as a GPU's bilinear filter expects.
    Lut { mapping: crate::directions::mapping::DirectionMapping, sun_azimuth_deg: f64 },
    /// LUT slices side by side, each `width / mappings.len()` columns of
    /// the image and each with its own sun (the mapping's sun zenith angle;
    /// the view's sun is not used): the slices of a basis sky as one farm
    /// job, so that workers go from one slice to the next without waiting
    /// for the last column of each (see [`super::View::parts`]). Column x
    /// of slice k is rendered exactly as column x of that slice alone.
    LutStrip { mappings: Vec<crate::directions::mapping::DirectionMapping>, sun_azimuth_deg: f64 },
}

impl Camera {
    /// The direction through image position (x, y) in pixels (continuous,
    /// y down), or None outside the camera's view.
    pub fn direction(&self, x: f64, y: f64, width: usize, height: usize) -> Option<DVec3> {
        let (w, h) = (width as f64, height as f64);
        match self {
            Camera::Equirect => {
                let phi = 2.0 * PI * x / w;
                let theta = PI * y / h;
                Some(DVec3::new(libm::sin(theta) * libm::cos(phi), libm::sin(theta) * libm::sin(phi), libm::cos(theta)))
            }
            Camera::Fisheye => {
                let dx = 2.0 * x / w - 1.0;
                let dy = 1.0 - 2.0 * y / h;
                let r = (dx * dx + dy * dy).sqrt();
                if r > 1.0 {
                    return None;
                }
                let theta = r * PI / 2.0;
                let phi = libm::atan2(dy, dx);
                Some(DVec3::new(libm::sin(theta) * libm::cos(phi), libm::sin(theta) * libm::sin(phi), libm::cos(theta)))
            }
            Camera::Pinhole { azimuth_deg, elevation_deg, fov_deg } => {
                let forward = direction_deg(90.0 - elevation_deg, *azimuth_deg);
                let right = forward.cross(DVec3::Z).try_normalize().unwrap_or(DVec3::X);
                let up = right.cross(forward);
                let half = libm::tan(0.5 * fov_deg.to_radians());
                let sx = (2.0 * x / w - 1.0) * half;
                let sy = (1.0 - 2.0 * y / h) * half * h / w;
                Some((forward + right * sx + up * sy).normalize())
            }
            Camera::Directions(list) => {
                let i = y as usize * width + x as usize;
                list.get(i).map(|&(z, a)| direction_deg(z, a))
            }
            Camera::Lut { mapping, sun_azimuth_deg } => {
                let d = mapping.direction(x / w, y / h);
                let (s, c) = (libm::sin(sun_azimuth_deg.to_radians()), libm::cos(sun_azimuth_deg.to_radians()));
                Some(DVec3::new(c * d.x - s * d.y, s * d.x + c * d.y, d.z))
            }
            Camera::LutStrip { mappings, sun_azimuth_deg } => {
                let w = width / mappings.len().max(1);
                let k = (x as usize / w.max(1)).min(mappings.len().checked_sub(1)?);
                Camera::Lut { mapping: mappings[k], sun_azimuth_deg: *sun_azimuth_deg }.direction(
                    x - (k * w) as f64,
                    y,
                    w,
                    height,
                )
            }
        }
    }

    /// Whether pixel positions are jittered within the pixel.
    pub fn jitters(&self) -> bool {
        !matches!(self, Camera::Directions(_) | Camera::Lut { .. } | Camera::LutStrip { .. })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equirect_and_fisheye_centres() {
        let d = Camera::Equirect.direction(0.0, 0.0, 8, 4).unwrap();
        assert!((d - DVec3::Z).length() < 1e-12);
        let d = Camera::Fisheye.direction(4.0, 4.0, 8, 8).unwrap();
        assert!((d - DVec3::Z).length() < 1e-12);
        let d = Camera::Fisheye.direction(8.0, 4.0, 8, 8).unwrap();
        assert!(d.z.abs() < 1e-12 && (d.x - 1.0).abs() < 1e-12);
        assert!(Camera::Fisheye.direction(0.0, 0.0, 8, 8).is_none());
        let p = Camera::Pinhole { azimuth_deg: 90.0, elevation_deg: 10.0, fov_deg: 60.0 };
        let d = p.direction(50.0, 50.0, 100, 100).unwrap();
        assert!((d - direction_deg(80.0, 90.0)).length() < 1e-9);
    }

    #[test]
    fn lut_camera_turns_with_the_sun() {
        let mapping = crate::directions::mapping::DirectionMapping::new(60.0, 87.5);
        let cam = Camera::Lut { mapping, sun_azimuth_deg: 135.0 };
        // v = 0 is the sun itself, wherever it stands.
        let d = cam.direction(3.0, 0.0, 32, 128).unwrap();
        assert!((d - direction_deg(60.0, 135.0)).length() < 1e-9, "{d}");
    }
}
