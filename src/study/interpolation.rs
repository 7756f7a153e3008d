//! How much a LUT loses by interpolating, measured on a sky without noise.
//!
//! A bake's error has four sources: Monte Carlo noise, R11G11B10F
//! quantisation, bilinear interpolation between texels (direction) and
//! linear interpolation between time slices. The first two are measured
//! from the bake itself (`bake::verify`); the last two are properties of the
//! mappings and of the sky's structure, which noise would hide. Here a
//! noise-free sky (single scattering of sunlight by quadrature,
//! `render::single`, which carries the sharpest structure of a real sky:
//! the aureole, the horizon, the Earth's shadow) is "baked" in memory
//! through the same mappings and decoded by the reference decoder's own
//! functions (`decode::sample_sky`), then compared with the sky itself:
//! - direction interpolation: at a slice's own sun, the decoded slice
//!   against the sky, with either direction mapping forced;
//! - slice interpolation: at suns between slices, the decoded pair against
//!   the sky, minus nothing (the direction error is part of it; at a slice
//!   centre the slice error is zero, so the difference between the two is
//!   what slice interpolation adds).
//!
//! Light scattered more than once is smoother in direction and time than
//! single scattering, so these errors bound those of the whole sky from
//! above, as far as interpolation goes.

use crate::directions::camera::direction_deg;
use crate::directions::mapping::{self, DirectionMapping};
use crate::lut::decode::{sample_sky, Texture};
use crate::lut::manifest::{SkyEntry, SliceEntry};
use crate::render::single::SingleScattering;
use crate::render::Scene;
use crate::stats::percentile;
use glam::DVec3;
use rayon::prelude::*;

/// A sky without noise: CIE XYZ toward `dir` (world frame, z up, the sun
/// at azimuth 0) for a sun at `sun_zenith_deg`.
pub trait SkyModel: Sync {
    fn xyz(&self, sun_zenith_deg: f64, dir: DVec3) -> [f64; 3];
}

/// Single scattering of a prepared scene's bands at an observer altitude.
pub struct SingleScatteringSky<'a> {
    pub scene: &'a Scene,
    pub altitude_km: f64,
}

impl SkyModel for SingleScatteringSky<'_> {
    fn xyz(&self, sun_zenith_deg: f64, dir: DVec3) -> [f64; 3] {
        SingleScattering::bands(self.scene, direction_deg(sun_zenith_deg, 0.0), self.altitude_km)
            .xyz(&self.scene.bands.weight, dir)
    }
}

/// The relative luminance errors of a decoded sky over a set of
/// directions, the aureole (within [`AUREOLE_DEG`] of the sun) apart.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct Errors {
    pub median: f64,
    pub p99: f64,
    pub aureole_median: Option<f64>,
    pub aureole_p99: Option<f64>,
}

/// Directions this close to the sun are the aureole, reported apart.
pub const AUREOLE_DEG: f64 = 5.0;

/// Directions in the aureole measured in each case, spread evenly in
/// solid angle over the ring from the sun disk's edge to [`AUREOLE_DEG`].
pub const AUREOLE_DIRECTIONS: usize = 200;

/// A Fibonacci spiral of `n` directions between 0.27° (the disk's edge)
/// and [`AUREOLE_DEG`] from `sun`, those at least 0.5° above the horizon
/// (as the sky lattice's).
pub fn aureole_lattice(sun: DVec3, n: usize) -> Vec<DVec3> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let (c0, c1) = (0.27f64.to_radians().cos(), AUREOLE_DEG.to_radians().cos());
    let t = if sun.z.abs() < 0.9 { DVec3::Z.cross(sun).normalize() } else { DVec3::X.cross(sun).normalize() };
    let b = sun.cross(t);
    (0..n)
        .map(|i| {
            let c = c0 + (c1 - c0) * (i as f64 + 0.5) / n as f64;
            let s = (1.0 - c * c).max(0.0).sqrt();
            let a = i as f64 * golden;
            sun * c + (t * libm::cos(a) + b * libm::sin(a)) * s
        })
        .filter(|d| d.z >= libm::sin(0.5f64.to_radians()))
        .collect()
}

impl Errors {
    /// What the threshold between the mappings is chosen by: the larger of
    /// the sky's and the aureole's 99th percentiles (each mapping fails in
    /// one of them: the sun-centred one squeezes the sky near the horizon,
    /// the latitude-longitude one blurs the aureole).
    pub fn score(&self) -> f64 {
        self.p99.max(self.aureole_p99.unwrap_or(0.0))
    }

    /// From the errors over the sky lattice (the aureole's directions
    /// left out) and over the aureole lattice.
    fn of(sun: DVec3, dirs: &[DVec3], rel: &[f64], aureole: &[f64]) -> Errors {
        let cos_aureole = AUREOLE_DEG.to_radians().cos();
        let mut sky: Vec<f64> =
            dirs.iter().zip(rel).filter(|(d, _)| d.dot(sun) <= cos_aureole).map(|(_, e)| *e).collect();
        let a = (!aureole.is_empty())
            .then(|| (percentile(&mut aureole.to_vec(), 0.5), percentile(&mut aureole.to_vec(), 0.99)));
        Errors {
            median: percentile(&mut sky.clone(), 0.5),
            p99: percentile(&mut sky, 0.99),
            aureole_median: a.map(|a| a.0),
            aureole_p99: a.map(|a| a.1),
        }
    }
}

/// One slice of `model` at texel centres, XYZ, rows of v top to bottom.
pub fn slice_texels(
    model: &dyn SkyModel,
    m: &DirectionMapping,
    sun_centred: bool,
    width: usize,
    height: usize,
) -> Vec<[f32; 3]> {
    let forced = DirectionMapping::new(m.sun_zenith_deg, if sun_centred { 180.0 } else { -1.0 });
    (0..width * height)
        .into_par_iter()
        .map(|i| {
            let (x, y) = (i % width, i / width);
            let d = forced.direction((x as f64 + 0.5) / width as f64, (y as f64 + 0.5) / height as f64);
            model.xyz(m.sun_zenith_deg, d).map(|v| v as f32)
        })
        .collect()
}

fn rel_y(decoded: f64, truth: f64) -> f64 {
    if truth > 0.0 {
        (decoded - truth).abs() / truth
    } else {
        0.0
    }
}

/// Direction interpolation alone: the slice of a sun at `sun_zenith_deg`
/// in one region's mapping, decoded bilinearly at `dirs` (above the
/// horizon), against the model.
pub fn direction_error(
    model: &dyn SkyModel,
    sun_zenith_deg: f64,
    sun_centred: bool,
    width: usize,
    height: usize,
    dirs: &[DVec3],
) -> Errors {
    let m = DirectionMapping::new(sun_zenith_deg, 0.0);
    let tex = Texture { width, height, layers: vec![slice_texels(model, &m, sun_centred, width, height)] };
    let err = |d: &DVec3| {
        let (u, v) = m.uv_in_region(*d, sun_centred);
        rel_y(tex.bilinear(0, u, v)[1], model.xyz(sun_zenith_deg, *d)[1])
    };
    let sun = direction_deg(sun_zenith_deg, 0.0);
    let rel: Vec<f64> = dirs.par_iter().map(err).collect();
    let aureole: Vec<f64> = aureole_lattice(sun, AUREOLE_DIRECTIONS).par_iter().map(err).collect();
    Errors::of(sun, dirs, &rel, &aureole)
}

/// A basis sky of `model` baked in memory (XYZ, no scale, no
/// quantisation), holding only the slices in `layers` (the others are
/// black); the entry the decoder reads.
pub fn in_memory_bake(
    model: &dyn SkyModel,
    width: usize,
    height: usize,
    radius_km: f64,
    top_km: f64,
    threshold_deg: f64,
    layers: &[usize],
) -> (SkyEntry, Texture) {
    let mut slices = Vec::new();
    let mut texels = Vec::new();
    for i in 0..mapping::SLICES {
        let z = mapping::slice_sun_zenith_deg(i, radius_km, top_km);
        slices.push(SliceEntry {
            index: i,
            sun_zenith_deg: z,
            scale_log2: 0,
            mean_samples: 0.0,
            median_rel_stderr_y: 0.0,
        });
        texels.push(if layers.contains(&i) {
            let m = DirectionMapping::new(z, threshold_deg);
            slice_texels(model, &m, m.sun_centred(), width, height)
        } else {
            vec![[0.0; 3]; width * height]
        });
    }
    let entry = SkyEntry {
        name: "model".into(),
        file: String::new(),
        format: String::new(),
        vk_format: 0,
        bytes: 0,
        width,
        height,
        layers: mapping::SLICES,
        atmosphere: String::new(),
        atmosphere_hash: String::new(),
        altitude_m: 0.0,
        planet_radius_km: radius_km,
        top_km,
        d_min_km: top_km,
        d_max_km: mapping::horizontal_distance_km(radius_km, top_km),
        threshold_sun_zenith_deg: threshold_deg,
        slices,
        texels_clamped: 0,
        texels_denormal: 0,
        texels_negative_rgb: 0,
        sun: None,
        ambient: None,
    };
    (entry, Texture { width, height, layers: texels })
}

/// The slices the decoder reads for a sun at `sun_zenith_deg`.
pub fn slices_read(sun_zenith_deg: f64, radius_km: f64, top_km: f64) -> [usize; 2] {
    let s = mapping::slice_coordinate(sun_zenith_deg, radius_km, top_km);
    let i0 = (s.floor() as usize).min(mapping::SLICES - 2);
    [i0, i0 + 1]
}

/// Direction and slice interpolation together: the decoder's sky for a
/// sun at `sun_zenith_deg` (between slices or not) against the model.
pub fn decoded_error(
    model: &dyn SkyModel,
    entry: &SkyEntry,
    texture: &Texture,
    sun_zenith_deg: f64,
    dirs: &[DVec3],
) -> Errors {
    let err =
        |d: &DVec3| rel_y(sample_sky(entry, texture, sun_zenith_deg, 0.0, *d)[1], model.xyz(sun_zenith_deg, *d)[1]);
    let sun = direction_deg(sun_zenith_deg, 0.0);
    let rel: Vec<f64> = dirs.par_iter().map(err).collect();
    let aureole: Vec<f64> = aureole_lattice(sun, AUREOLE_DIRECTIONS).par_iter().map(err).collect();
    Errors::of(sun, dirs, &rel, &aureole)
}

/// The twilight of a decoded sky and of the model itself: the largest
/// change of log Y per 0.1° of sun elevation, the sun from 0 to −10° in
/// 0.1° steps, toward the zenith and the horizon (1° up) toward and away
/// from the sun: (decoded, model).
pub fn twilight_steps(model: &dyn SkyModel, entry: &SkyEntry, texture: &Texture) -> (f64, f64) {
    let dirs = [direction_deg(0.0, 0.0), direction_deg(89.0, 0.0), direction_deg(89.0, 180.0)];
    let curves: Vec<[[f64; 3]; 2]> = (0..=100)
        .into_par_iter()
        .map(|k| {
            let z = 90.0 + 0.1 * k as f64;
            [dirs.map(|d| sample_sky(entry, texture, z, 0.0, d)[1]), dirs.map(|d| model.xyz(z, d)[1])]
        })
        .collect();
    let step = |which: usize| {
        let mut worst: f64 = 0.0;
        for w in curves.windows(2) {
            for c in 0..3 {
                let (a, b) = (w[0][which][c], w[1][which][c]);
                if a > 0.0 && b > 0.0 {
                    worst = worst.max((b / a).ln().abs());
                }
            }
        }
        worst
    };
    (step(0), step(1))
}

/// The directions of a Fibonacci lattice above the horizon (see
/// `stats::sky_lattice`).
pub fn lattice(n: usize) -> Vec<DVec3> {
    crate::stats::sky_lattice(n).into_iter().map(|(z, a)| direction_deg(z, a)).collect()
}

/// Direction interpolation at one slice's sun in both mappings.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SliceRegions {
    pub index: usize,
    pub sun_zenith_deg: f64,
    pub sun_centred: Errors,
    pub latitude_longitude: Errors,
}

/// Slice interpolation at a sun between slices: the decoded sky's error,
/// and the direction error of the two slices it reads at their own suns.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Between {
    pub sun_elevation_deg: f64,
    pub decoded: Errors,
    pub slices: [usize; 2],
    pub direction_only_median: f64,
    pub direction_only_p99: f64,
}

/// What `sky lut interpolation` measures for one atmosphere and size.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Report {
    pub width: usize,
    pub height: usize,
    pub directions: usize,
    /// Every slice from 60° sun zenith to the horizon, in both mappings.
    pub regions: Vec<SliceRegions>,
    /// The largest slice zenith up to which the sun-centred mapping's score
    /// (the larger of its sky and aureole 99th percentiles) is the smaller
    /// of the two mappings', without a gap.
    pub measured_threshold_deg: f64,
    /// The threshold the errors below were decoded with.
    pub threshold_deg: f64,
    pub between: Vec<Between>,
    /// Largest change of log Y per 0.1° of twilight: decoded, and the sky's own.
    pub twilight_step_decoded: f64,
    pub twilight_step_model: f64,
}

/// Measures `model` baked at `width` × `height` (see the module
/// documentation); `threshold_deg` None decodes with the measured threshold.
pub fn measure(
    model: &dyn SkyModel,
    width: usize,
    height: usize,
    radius_km: f64,
    top_km: f64,
    directions: usize,
    between_deg: &[f64],
    threshold_deg: Option<f64>,
) -> Report {
    let dirs = lattice(directions);
    let mut regions = Vec::new();
    for index in 0..mapping::UPPER_SLICES {
        let z = mapping::slice_sun_zenith_deg(index, radius_km, top_km);
        if z < 60.0 {
            continue;
        }
        regions.push(SliceRegions {
            index,
            sun_zenith_deg: z,
            sun_centred: direction_error(model, z, true, width, height, &dirs),
            latitude_longitude: direction_error(model, z, false, width, height, &dirs),
        });
    }
    let mut measured = 60.0;
    for r in &regions {
        if r.sun_centred.score() <= r.latitude_longitude.score() {
            measured = r.sun_zenith_deg;
        } else {
            break;
        }
    }
    let threshold = threshold_deg.unwrap_or(measured);
    let mut layers: Vec<usize> = between_deg.iter().flat_map(|e| slices_read(90.0 - e, radius_km, top_km)).collect();
    layers.extend(mapping::UPPER_SLICES - 1..mapping::SLICES);
    let (entry, texture) = in_memory_bake(model, width, height, radius_km, top_km, threshold, &layers);
    let between = between_deg
        .iter()
        .map(|&e| {
            let slices = slices_read(90.0 - e, radius_km, top_km);
            let own: Vec<Errors> = slices
                .iter()
                .map(|&i| {
                    let z = entry.slices[i].sun_zenith_deg;
                    direction_error(model, z, z <= threshold, width, height, &dirs)
                })
                .collect();
            Between {
                sun_elevation_deg: e,
                decoded: decoded_error(model, &entry, &texture, 90.0 - e, &dirs),
                slices,
                direction_only_median: 0.5 * (own[0].median + own[1].median),
                direction_only_p99: own[0].p99.max(own[1].p99),
            }
        })
        .collect();
    let (twilight_step_decoded, twilight_step_model) = twilight_steps(model, &entry, &texture);
    Report {
        width,
        height,
        directions,
        regions,
        measured_threshold_deg: measured,
        threshold_deg: threshold,
        between,
        twilight_step_decoded,
        twilight_step_model,
    }
}

/// The interpolation part of a bake's error at sun elevations, for a bake
/// of `model` with the size, planet and threshold of `entry`: for each
/// elevation, (direction and slice interpolation together, direction
/// interpolation alone: the worse of the two slices read, each at its own
/// sun).
pub fn split(model: &dyn SkyModel, entry: &SkyEntry, elevations_deg: &[f64], dirs: &[DVec3]) -> Vec<(Errors, Errors)> {
    let (r, top) = (entry.planet_radius_km, entry.top_km);
    let layers: Vec<usize> = elevations_deg.iter().flat_map(|e| slices_read(90.0 - e, r, top)).collect();
    let (bake, texture) =
        in_memory_bake(model, entry.width, entry.height, r, top, entry.threshold_sun_zenith_deg, &layers);
    elevations_deg
        .iter()
        .map(|&e| {
            let both = decoded_error(model, &bake, &texture, 90.0 - e, dirs);
            // At a slice's own sun only that slice is read.
            let read = slices_read(90.0 - e, r, top);
            let at_centre = (bake.slices[read[0]].sun_zenith_deg - (90.0 - e)).abs() < 1e-9;
            let own = read
                .iter()
                .take(if at_centre { 1 } else { 2 })
                .map(|&i| decoded_error(model, &bake, &texture, bake.slices[i].sun_zenith_deg, dirs));
            let worse = own.reduce(|a, b| if a.p99 >= b.p99 { a } else { b }).expect("one slice at least");
            (both, worse)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth sky: brighter toward the sun and the horizon.
    struct Smooth;
    impl SkyModel for Smooth {
        fn xyz(&self, sun_zenith_deg: f64, d: DVec3) -> [f64; 3] {
            let c = d.dot(direction_deg(sun_zenith_deg, 0.0));
            let y = 1.0 + 0.6 * c + 0.3 * c * c + 0.4 * (1.0 - d.z.abs());
            [y, y, y]
        }
    }

    /// The same with a sharp aureole: 1000 × e^(−(angle / 1°)²) on top.
    struct Peaked;
    impl SkyModel for Peaked {
        fn xyz(&self, sun_zenith_deg: f64, d: DVec3) -> [f64; 3] {
            let a = libm::acos(d.dot(direction_deg(sun_zenith_deg, 0.0)).clamp(-1.0, 1.0)).to_degrees();
            Smooth.xyz(sun_zenith_deg, d).map(|y| y + 1000.0 * (-(a * a)).exp())
        }
    }

    /// Twilight as the atmosphere does it: luminance falling exponentially
    /// with the sun's depression, 1.3 e-folds per degree (about what the
    /// clear sky's zenith does near −6°), faster toward the anti-sun side.
    struct Dusk;
    impl SkyModel for Dusk {
        fn xyz(&self, sun_zenith_deg: f64, d: DVec3) -> [f64; 3] {
            let depression = (sun_zenith_deg - 90.0).max(0.0);
            let k = 1.3 - 0.3 * d.x;
            Smooth.xyz(sun_zenith_deg, d).map(|y| 1000.0 * y * (-k * depression).exp())
        }
    }

    /// The twilight test: decoded along the sun from 0 to −10° in
    /// 0.1° steps, the luminance's consecutive ratios stay within what the
    /// sky itself does. (With linear interpolation between slices, 1.1°
    /// apart near −7°, the decoded log Y bends at each slice, its steepest
    /// step 2.7 times the sky's: this test fails.)
    #[test]
    fn twilight_decodes_without_steps() {
        let layers: Vec<usize> = (mapping::UPPER_SLICES - 1..mapping::SLICES).collect();
        let (entry, texture) = in_memory_bake(&Dusk, 16, 64, 6371.0, 100.0, 87.5, &layers);
        let (decoded, model) = twilight_steps(&Dusk, &entry, &texture);
        assert!(model > 0.1 && model < 0.2, "{model}");
        assert!(
            decoded <= model * 1.01,
            "decoded twilight steps up to {decoded:.4} in log Y per 0.1°, the sky's own {model:.4}"
        );
    }

    #[test]
    fn a_smooth_sky_interpolates_closely_and_a_sharp_aureole_does_not() {
        let dirs = lattice(300);
        let smooth = direction_error(&Smooth, 40.0, true, 32, 128, &dirs);
        assert!(smooth.p99 < 2e-3 && smooth.aureole_p99.unwrap() < 2e-3, "{smooth:?}");
        // The sun-centred mapping resolves the aureole; latitude-longitude,
        // with texels of several degrees there, cannot.
        let centred = direction_error(&Peaked, 40.0, true, 32, 128, &dirs);
        let latlong = direction_error(&Peaked, 40.0, false, 32, 128, &dirs);
        assert!(latlong.aureole_median.unwrap() > 10.0 * centred.aureole_median.unwrap(), "{centred:?} {latlong:?}");
        // Between slices, the decoder's sky of the in-memory bake.
        let z = 90.0 - 23.3;
        let (entry, texture) = in_memory_bake(&Smooth, 32, 128, 6371.0, 100.0, 87.5, &slices_read(z, 6371.0, 100.0));
        let between = decoded_error(&Smooth, &entry, &texture, z, &dirs);
        assert!(between.p99 < 2e-2 && between.median < 5e-3, "{between:?}");
    }
}
