//! The geometry of the atmosphere's majorant shells: altitude and the local
//! vertical (sphere or plane), distances to a shell's boundary, and one
//! iterator over the shells a ray crosses, each with what lies beyond it (a
//! typed [`Boundary`]: the next shell, the ground or space). Delta tracking,
//! ratio tracking, forced collisions and the first-collision guide all walk
//! rays through it (pbrt-v4's `SampleT_maj` over a majorant iterator is the
//! model: piecewise-constant majorants, one segment at a time).

use super::medium::Medium;
use crate::atmosphere::Geometry;
use glam::DVec3;

/// The lowest observer: 1 mm above the ground.
pub const MIN_OBSERVER_KM: f64 = 1e-6;

/// Where an observer stands over the planet (as [`Medium::observer`] places
/// it, at least [`MIN_OBSERVER_KM`] up): its horizon, and how far its rays
/// below the horizon travel to the ground.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Standpoint {
    pub geometry: Geometry,
    pub radius_km: f64,
    pub altitude_km: f64,
}

impl Standpoint {
    pub fn new(geometry: Geometry, radius_km: f64, altitude_km: f64) -> Standpoint {
        Standpoint { geometry, radius_km, altitude_km: altitude_km.max(MIN_OBSERVER_KM) }
    }

    /// The zenith angle of the horizon, degrees: beyond it rays meet the
    /// ground. 90° over a plane; over a sphere of radius R, 90° plus the dip
    /// acos(R / (R + h)), 0.001° for the lowest observer.
    pub fn horizon_zenith_deg(&self) -> f64 {
        match self.geometry {
            Geometry::PlaneParallel => 90.0,
            Geometry::Spherical => 90.0 + libm::acos(self.radius_km / (self.radius_km + self.altitude_km)).to_degrees(),
        }
    }

    /// The distance to the ground along the ray at `zenith_deg`, km; `None`
    /// for a ray that misses it. Over a sphere, with r = R + h and α the
    /// angle from the nadir, the near root of |p + t d| = R:
    /// t = r cos α − √(r² cos² α − h (2R + h)), computed as
    /// h (2R + h) / (r cos α + √(…)) (the roots' product over the far one)
    /// so that a low observer's few metres are not the difference of two
    /// thousands of kilometres.
    pub fn ground_distance_km(&self, zenith_deg: f64) -> Option<f64> {
        let cos_nadir = -zenith_deg.to_radians().cos();
        let h = self.altitude_km;
        match self.geometry {
            Geometry::PlaneParallel => (cos_nadir > 0.0).then(|| h / cos_nadir),
            Geometry::Spherical => {
                let r = self.radius_km + h;
                let c = h * (2.0 * self.radius_km + h);
                let disc = (r * cos_nadir).powi(2) - c;
                (cos_nadir > 0.0 && disc >= 0.0).then(|| c / (r * cos_nadir + disc.sqrt()))
            }
        }
    }

    /// The zenith angle, degrees, of the ray that meets the ground
    /// `distance_km` away (from the altitude at the nadir to the horizon's
    /// distance): the inverse of [`Standpoint::ground_distance_km`]. Over a
    /// sphere, by the law of cosines: cos α = (r² + t² − R²) / (2 r t).
    pub fn zenith_for_ground_distance_deg(&self, distance_km: f64) -> f64 {
        let h = self.altitude_km;
        let t = distance_km.max(h);
        let cos_nadir = match self.geometry {
            Geometry::PlaneParallel => h / t,
            Geometry::Spherical => (h * (2.0 * self.radius_km + h) + t * t) / (2.0 * (self.radius_km + h) * t),
        };
        180.0 - libm::acos(cos_nadir.clamp(-1.0, 1.0)).to_degrees()
    }
}

/// Nudge past a boundary, km.
pub(crate) const EPS_KM: f64 = 1e-9;
/// The most shells one ray may cross (a guard against rounding loops: a ray
/// through the whole spherical atmosphere crosses about 2 × 110).
const MAX_SEGMENTS: u32 = 1_000_000;

/// What a ray meets when it leaves a shell.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Boundary {
    /// It goes on into this shell.
    Shell(usize),
    /// It meets the ground.
    Ground,
    /// It leaves the atmosphere (or runs parallel to a plane-parallel
    /// atmosphere's layers for ever).
    Space,
}

/// One shell crossed by a ray: from `start_km` to `end_km` along it (the end
/// is infinite for a ray parallel to a plane-parallel atmosphere), in shell
/// `shell`, followed by `next`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    pub start_km: f64,
    pub end_km: f64,
    pub shell: usize,
    pub next: Boundary,
}

/// A shell segment with its majorant: what forced collisions and guides use.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MajorantSegment {
    pub start_km: f64,
    pub end_km: f64,
    pub majorant_per_km: f64,
}

/// The shells along a ray, from its origin outward (see [`Medium::walk`]).
pub struct ShellWalk<'a> {
    medium: &'a Medium,
    dir: DVec3,
    /// Where the next segment starts.
    p: DVec3,
    t_km: f64,
    done: bool,
    left: u32,
}

impl Iterator for ShellWalk<'_> {
    type Item = Segment;

    fn next(&mut self) -> Option<Segment> {
        if self.done {
            return None;
        }
        self.left -= 1;
        let (shell, t_exit, next) = self.medium.shell_exit(self.p, self.dir);
        if !t_exit.is_finite() {
            // A ray that never leaves its shell: from a point above the top
            // (rounding puts a vertex there), where the medium is empty and
            // the ray never comes back, or parallel to a plane-parallel
            // atmosphere's layers (a set of measure zero). It crosses
            // nothing: an endless segment had tracking draw null
            // collisions forever.
            self.done = true;
            return None;
        }
        let start_km = self.t_km;
        match next {
            Boundary::Shell(_) if self.left > 0 => {
                self.p += self.dir * t_exit;
                self.p += self.dir * EPS_KM;
                self.t_km = start_km + t_exit + EPS_KM;
            }
            _ => self.done = true,
        }
        Some(Segment { start_km, end_km: start_km + t_exit, shell, next })
    }
}

impl Medium {
    /// Altitude above the ground, km.
    #[inline]
    pub fn altitude(&self, p: DVec3) -> f64 {
        match self.geometry {
            Geometry::Spherical => p.length() - self.radius_km,
            Geometry::PlaneParallel => p.z,
        }
    }

    /// A point at `altitude_km` above the origin of the horizontal plane
    /// (at least [`MIN_OBSERVER_KM`], as its [`Standpoint`] has it, so rays
    /// looking down meet the ground ahead of them).
    pub fn observer(&self, altitude_km: f64) -> DVec3 {
        let altitude_km = self.standpoint(altitude_km).altitude_km;
        match self.geometry {
            Geometry::Spherical => DVec3::new(0.0, 0.0, self.radius_km + altitude_km),
            Geometry::PlaneParallel => DVec3::new(0.0, 0.0, altitude_km),
        }
    }

    /// The [`Standpoint`] of an observer at `altitude_km` over this medium's planet.
    pub fn standpoint(&self, altitude_km: f64) -> Standpoint {
        Standpoint::new(self.geometry, self.radius_km, altitude_km)
    }

    /// The local vertical at `p`.
    #[inline]
    pub fn up(&self, p: DVec3) -> DVec3 {
        match self.geometry {
            Geometry::Spherical => p.normalize(),
            Geometry::PlaneParallel => DVec3::Z,
        }
    }

    /// Distance along `d` from `p` to the altitude `z_km` boundary (sphere
    /// or plane), if the ray reaches it; `upward` picks the far root.
    pub(crate) fn distance_to_altitude(&self, p: DVec3, d: DVec3, z_km: f64, upward: bool) -> Option<f64> {
        match self.geometry {
            Geometry::PlaneParallel => {
                let t = (z_km - p.z) / d.z;
                (t > 0.0 && t.is_finite()).then_some(t)
            }
            Geometry::Spherical => {
                let r = self.radius_km + z_km;
                let b = p.dot(d);
                let c = p.length_squared() - r * r;
                let disc = b * b - c;
                if disc < 0.0 {
                    return None;
                }
                let s = disc.sqrt();
                // The far root leaving upward; else the nearer one, only if
                // the sphere is ahead.
                let t = if upward { -b + s } else { -b - s };
                (t > 0.0).then_some(t)
            }
        }
    }

    /// `ds`, or less: the distance along `d` from `p` to the first altitude
    /// in `kinks_km` (ascending) that the ray crosses within `ds`, so that
    /// a quadrature step never straddles a profile's edge.
    pub(crate) fn clip_at_kinks(&self, p: DVec3, d: DVec3, ds: f64, kinks_km: &[f64]) -> f64 {
        let (z0, z1) = (self.altitude(p), self.altitude(p + d * ds));
        // On a sphere the altitude along a chord can dip below both ends.
        let lo = match self.geometry {
            Geometry::Spherical => {
                let t_tangent = -p.dot(d);
                if t_tangent > 0.0 && t_tangent < ds {
                    self.altitude(p + d * t_tangent).min(z0.min(z1))
                } else {
                    z0.min(z1)
                }
            }
            Geometry::PlaneParallel => z0.min(z1),
        };
        let hi = z0.max(z1);
        let first = kinks_km.partition_point(|&z| z <= lo);
        let last = kinks_km.partition_point(|&z| z < hi);
        let mut best = ds;
        for &zk in &kinks_km[first..last] {
            for far in [false, true] {
                if let Some(t) = self.distance_to_altitude(p, d, zk, far) {
                    if t > 1e-9 && t < best {
                        best = t;
                    }
                }
            }
        }
        best
    }

    /// The distance from `p` along `d` to the ground, or else to the top of
    /// the atmosphere (None when the ray never meets either, as a ray
    /// leaving the top of the atmosphere).
    pub(crate) fn ray_end(&self, p: DVec3, d: DVec3) -> Option<f64> {
        self.distance_to_altitude(p, d, 0.0, false).or_else(|| self.distance_to_altitude(p, d, self.top_km, true))
    }

    /// The shell at `p`, the distance along `d` to its boundary (infinite
    /// if it never leaves it) and what lies beyond.
    fn shell_exit(&self, p: DVec3, d: DVec3) -> (usize, f64, Boundary) {
        let top = self.top_km;
        let z = self.altitude(p).clamp(0.0, top);
        let s = self.shell_of(z);
        let lo = self.shell_edges_km[s];
        let hi = self.shell_edges_km[s + 1];
        let t_up = self.distance_to_altitude(p, d, hi, true).unwrap_or(f64::INFINITY);
        let t_down = self.distance_to_altitude(p, d, lo, false).unwrap_or(f64::INFINITY);
        if t_down < t_up {
            (s, t_down, if s == 0 { Boundary::Ground } else { Boundary::Shell(s - 1) })
        } else if s + 1 >= self.shells() {
            (s, t_up, Boundary::Space)
        } else {
            (s, t_up, Boundary::Shell(s + 1))
        }
    }

    /// The shells the ray from `p` along `d` crosses, until it meets the
    /// ground or leaves the atmosphere. Segments are separated by gaps of
    /// [`EPS_KM`] (each starts just past the last boundary).
    pub fn walk(&self, p: DVec3, d: DVec3) -> ShellWalk<'_> {
        ShellWalk { medium: self, dir: d, p, t_km: 0.0, done: false, left: MAX_SEGMENTS }
    }

    /// The segments of the ray with their `majorant` (per shell), written
    /// into `out` (a reused buffer), and the distance to the ground if the
    /// ray meets it. A ray parallel to a plane-parallel atmosphere's layers
    /// (a set of measure zero) gets no segments.
    pub(crate) fn majorant_segments(
        &self,
        p: DVec3,
        d: DVec3,
        majorant: &[f64],
        out: &mut Vec<MajorantSegment>,
    ) -> Option<f64> {
        out.clear();
        for s in self.walk(p, d) {
            if !s.end_km.is_finite() {
                return None;
            }
            out.push(MajorantSegment { start_km: s.start_km, end_km: s.end_km, majorant_per_km: majorant[s.shell] });
            match s.next {
                Boundary::Ground => return Some(s.end_km),
                Boundary::Space => return None,
                Boundary::Shell(_) => {}
            }
        }
        None
    }
}
