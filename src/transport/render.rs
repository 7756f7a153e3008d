//! `sky render --method deterministic`: a view's pixels from the transport
//! solver instead of the path tracer, with the same scene (bands, spectral
//! lines, optics) and the same outputs, so that the two can be compared
//! direction by direction.
//!
//! A pixel looking up is the single scattering by the renderer's own
//! quadrature (`render::single`, the path tracer's first vertex) plus the
//! light scattered twice or more from `adding::Diffuse`; a pixel
//! looking down sees the Lambertian ground, (A/π) E with E the ground's
//! irradiance; the sun's disk, where the view shows it, is the direct beam
//! F₀ e^{−τ/μ₀} spread over the disk's solid angle, times the part of the
//! pixel that sees it (`disk_coverage`).
//!
//! The diffuse light's Fourier modes are solved at [`VIEW_NODES`] view
//! cosines, μ_k = (k / K)², k = 1..K, dense toward the horizon where the
//! light changes fastest, and interpolated between them by Catmull-Rom in
//! √μ (the test below bounds what that costs against solving at each
//! pixel's own cosine).
//!
//! So far: seen from the ground, without fog, suns above the horizon; in
//! spherical shells the pseudo-spherical solution of `adding`. The
//! rest is refused with the reason.

use super::adding::Diffuse;
use super::layers::{Grading, Layers};
use crate::atmosphere::Geometry;
use crate::render::medium::Spectral;
use crate::render::single::{xyz_of, SingleScattering};
use crate::render::{Image, PixelResult, Scene, View};
use glam::DVec3;
use rayon::prelude::*;
use std::f64::consts::PI;

/// How many view cosines the diffuse light is solved at (see the module
/// documentation).
pub const VIEW_NODES: usize = 256;

/// The lowest sun the pseudo-spherical solution renders in spherical shells
/// (a plane-parallel atmosphere is simply dark below its horizon).
/// TRANSPORT.md's sasktran2 figures: within 0.4 to 1.3 % of a spherical
/// solution to 88°, 3.2 % at 90 to 92°, failing beyond; twilight needs the
/// spherical source.
pub const MAX_SUN_ZENITH_DEG: f64 = 90.0;

/// The solver's resolutions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Resolution {
    /// Discrete-ordinate streams a hemisphere.
    pub streams: usize,
    pub grading: Grading,
}

impl Default for Resolution {
    /// 16 streams a hemisphere: within 0.05 % of DISORT on the clear and
    /// hazed slabs (tests/transport.rs); the cloud slabs need 32.
    fn default() -> Resolution {
        Resolution { streams: 16, grading: Grading::default() }
    }
}

/// What the deterministic solver cannot render yet.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Unsupported {
    #[error(
        "the deterministic solver has no twilight yet: in spherical shells it renders suns up to 90 deg from the \
         zenith, not {0} deg; twilight renders with --method monte-carlo"
    )]
    Twilight(f64),
    #[error("the deterministic solver sees from the ground so far (--altitude-m 0), not from {0} m")]
    Altitude(f64),
    #[error("the deterministic solver renders no fog yet; fog renders with --method monte-carlo")]
    Fog,
}

/// Why `view` of an atmosphere of this geometry cannot be rendered
/// deterministically, if it cannot.
pub fn check(geometry: Geometry, view: &View) -> Result<(), Unsupported> {
    let twilight = view.parts().iter().map(|(_, p)| p.sun_zenith_deg).find(|&z| z > MAX_SUN_ZENITH_DEG);
    if let (Geometry::Spherical, Some(z)) = (geometry, twilight) {
        return Err(Unsupported::Twilight(z));
    }
    if view.altitude_m != 0.0 {
        return Err(Unsupported::Altitude(view.altitude_m));
    }
    if view.fog.is_some() {
        return Err(Unsupported::Fog);
    }
    Ok(())
}

/// Renders every pixel of `view`; `on_wavelength` is called after each
/// band's and spectral line's solution (for progress). The result is a
/// pure function of the scene, the view and the resolution.
pub fn render(
    scene: &Scene,
    view: &View,
    resolution: &Resolution,
    on_wavelength: &(dyn Fn() + Sync),
) -> Result<Image, Unsupported> {
    check(scene.medium.geometry, view)?;
    let (width, height) = (view.width, view.height);
    let mut pixels = vec![None; width * height];
    for (first, part) in view.parts() {
        let part_pixels = render_part(scene, &part, resolution, on_wavelength);
        for (i, p) in part_pixels.into_iter().enumerate() {
            let (x, y) = (first + i % part.width, i / part.width);
            pixels[y * width + x] = Some(p);
        }
    }
    let pixels = pixels.into_iter().map(|p| p.expect("the parts cover the view")).collect();
    Ok(Image { width, height, pixels })
}

/// The light of one wavelength (a band or a spectral line), per unit solar
/// irradiance: the diffuse light, the beam's transmittance to the ground,
/// the ground's albedo.
struct Wavelength {
    diffuse: Diffuse,
    sun_transmittance: f64,
    ground_albedo: f64,
}

impl Wavelength {
    fn solve(scene: &Scene, optics: &Spectral, mu0: f64, resolution: &Resolution, nodes: &[f64]) -> Wavelength {
        let layers = Layers::new(&scene.medium, optics, 2 * resolution.streams, &resolution.grading);
        let diffuse = Diffuse::solve(&layers, resolution.streams, mu0, nodes.to_vec());
        let sun_transmittance = super::adding::sun_transmittance(&layers, mu0);
        Wavelength { diffuse, sun_transmittance, ground_albedo: layers.ground_albedo }
    }

    /// The diffuse radiance toward a pixel looking up at cosine `mu`,
    /// azimuth `phi` from the sun.
    fn diffuse_radiance(&self, mu: f64, phi: f64) -> f64 {
        // Node k (1-based) sits at s = k; between nodes k and k + 1 with
        // their neighbours, clamped at the ends (and below the first node).
        let last = VIEW_NODES as isize;
        let s = (mu.max(0.0).sqrt() * VIEW_NODES as f64).clamp(1.0, last as f64);
        let k = (s.floor() as isize).min(last - 1);
        let w = catmull_rom(s - k as f64);
        let idx = [k - 1, k, k + 1, k + 2].map(|i| (i.clamp(1, last) - 1) as usize);
        (0..4).map(|i| w[i] * self.diffuse.at_node(idx[i], phi)).sum()
    }

    /// The radiance of the Lambertian ground.
    fn ground_radiance(&self) -> f64 {
        self.ground_albedo / PI * self.diffuse.ground_irradiance
    }
}

/// Catmull-Rom weights of the four nodes around a point a fraction `t` of
/// the way from the second to the third.
fn catmull_rom(t: f64) -> [f64; 4] {
    let (t2, t3) = (t * t, t * t * t);
    [0.5 * (-t3 + 2.0 * t2 - t), 0.5 * (3.0 * t3 - 5.0 * t2 + 2.0), 0.5 * (-3.0 * t3 + 4.0 * t2 + t), 0.5 * (t3 - t2)]
}

/// The view cosines the diffuse light is solved at.
fn view_nodes() -> Vec<f64> {
    (1..=VIEW_NODES).map(|k| (k as f64 / VIEW_NODES as f64).powi(2)).collect()
}

/// One part of a view (a whole view, or one slice of a LUT strip), row-major.
fn render_part(
    scene: &Scene,
    view: &View,
    resolution: &Resolution,
    on_wavelength: &(dyn Fn() + Sync),
) -> Vec<PixelResult> {
    let sun = view.sun_direction();
    let mu0 = sun.z;
    let nodes = view_nodes();
    let solve = |optics: &[Spectral]| -> Vec<Wavelength> {
        optics
            .par_iter()
            .map(|o| {
                let w = Wavelength::solve(scene, o, mu0, resolution, &nodes);
                on_wavelength();
                w
            })
            .collect()
    };
    let (bands, lines) = (solve(&scene.band_optics), solve(&scene.line_optics));
    let single_bands = SingleScattering::bands(scene, sun, 0.0);
    let single_lines = SingleScattering::new(&scene.medium, &scene.columns, &scene.line_optics, sun, 0.0);
    let cos_half = (0.5 * scene.sun_angular_diameter_deg.to_radians()).cos();
    let disk_per_sr = 1.0 / (2.0 * PI * (1.0 - cos_half));
    let (w, h) = (view.width, view.height);
    (0..w * h)
        .into_par_iter()
        .map(|i| {
            let Some(dir) = view.camera.direction((i % w) as f64 + 0.5, (i / w) as f64 + 0.5, w, h) else {
                return nothing(scene.line_optics.len());
            };
            let disk = if view.sun_disk && mu0 > 0.0 { disk_coverage(view, i, sun, cos_half) } else { 0.0 };
            let radiance = |waves: &[Wavelength], single: &SingleScattering, scale: &dyn Fn(usize) -> f64| {
                let direct: Vec<f64> = waves
                    .iter()
                    .enumerate()
                    .map(|(b, wl)| disk * scale(b) * wl.sun_transmittance * disk_per_sr)
                    .collect();
                let total: Vec<f64> = if dir.z > 0.0 {
                    let phi = azimuth_between(dir, sun);
                    let once = if waves.is_empty() { Vec::new() } else { single.radiance(dir) };
                    waves
                        .iter()
                        .enumerate()
                        .map(|(b, wl)| once[b] + scale(b) * wl.diffuse_radiance(dir.z, phi) + direct[b])
                        .collect()
                } else {
                    waves.iter().enumerate().map(|(b, wl)| scale(b) * wl.ground_radiance() + direct[b]).collect()
                };
                (total, direct)
            };
            let weight = &scene.bands.weight;
            let (band_l, band_direct) = radiance(&bands, &single_bands, &|_| 1.0);
            let (line_l, _) = radiance(&lines, &single_lines, &|k| scene.line_optics[k].sun_irradiance);
            PixelResult {
                xyz: xyz_of(weight, &band_l),
                xyz_direct: xyz_of(weight, &band_direct),
                xyz_stderr: [0.0; 3],
                spectral_stderr: vec![0.0; line_l.len()],
                spectral: line_l,
                samples: 1,
                paths_cut: 0,
            }
        })
        .collect()
}

/// Sub-pixel positions a side where a pixel may see the sun's disk.
const DISK_SUBPIXELS: usize = 16;

/// The fraction of pixel `i` that sees the sun's disk: what the path
/// tracer's jittered samples average to, by a 16 x 16 grid of sub-pixel
/// positions wherever the disk may touch the pixel (its corners' angular
/// distance from its centre tells). A camera that does not jitter
/// (directions, LUT texels) sees the disk at the pixel's centre or not at
/// all, as the path tracer does.
fn disk_coverage(view: &View, i: usize, sun: DVec3, cos_half: f64) -> f64 {
    let (w, h) = (view.width, view.height);
    let (x, y) = ((i % w) as f64, (i / w) as f64);
    let at = |u: f64, v: f64| view.camera.direction(x + u, y + v, w, h);
    let Some(centre) = at(0.5, 0.5) else { return 0.0 };
    if !view.camera.jitters() {
        return if centre.dot(sun) >= cos_half { 1.0 } else { 0.0 };
    }
    let angle = |a: DVec3, b: DVec3| a.dot(b).clamp(-1.0, 1.0).acos();
    let reach = [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)]
        .iter()
        .filter_map(|&(u, v)| at(u, v))
        .map(|c| angle(c, centre))
        .fold(0.0, f64::max);
    if angle(centre, sun) > reach + cos_half.acos() {
        return 0.0;
    }
    let n = DISK_SUBPIXELS;
    let inside = (0..n * n)
        .filter(|k| {
            let (u, v) = (((k % n) as f64 + 0.5) / n as f64, ((k / n) as f64 + 0.5) / n as f64);
            at(u, v).is_some_and(|d| d.dot(sun) >= cos_half)
        })
        .count();
    inside as f64 / (n * n) as f64
}

/// A pixel that sees nothing.
fn nothing(lines: usize) -> PixelResult {
    PixelResult {
        samples: 0,
        spectral: vec![0.0; lines],
        spectral_stderr: vec![0.0; lines],
        ..PixelResult::from_xyz([0.0; 3])
    }
}

/// The azimuth between two directions about the vertical, radians.
fn azimuth_between(a: DVec3, b: DVec3) -> f64 {
    libm::atan2(a.y, a.x) - libm::atan2(b.y, b.x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::atmosphere::Atmosphere;
    use crate::mie::MieCache;
    use crate::render::medium::Medium;

    /// What the grid of view cosines costs: the diffuse light interpolated
    /// between the nodes against the same light solved at each cosine, in
    /// the hazed slab (the aerosol's forward lobe makes the most structure
    /// in azimuth) for a high and a low sun, from the zenith to 0.1° above
    /// the horizon. Bound: 1e-5 of the radiance (measured: 4e-7).
    #[test]
    fn the_view_grid_interpolates_the_diffuse_light_within_1e_5() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/atmospheres/disort_rayleigh_hg.toml");
        let atm = Atmosphere::load(&path).unwrap();
        let medium = Medium::new(&atm);
        let optics = medium.spectral(&atm, 450.0, 1.0, 0.3, &MieCache::shared_by_tests());
        let layers = Layers::new(&medium, &optics, 32, &Grading::default());
        let mus: Vec<f64> = (0..40)
            .map(|i| (0.1f64.to_radians()).sin().max(1e-3) + (i as f64 / 39.0).powi(3))
            .map(|m| m.min(1.0))
            .collect();
        let mut worst = (0.0f64, 0.0, 0.0, 0.0);
        for mu0 in [0.9, 0.15] {
            let grid = Wavelength {
                diffuse: Diffuse::solve(&layers, 16, mu0, view_nodes()),
                sun_transmittance: 0.0,
                ground_albedo: 0.3,
            };
            let exact = Diffuse::solve(&layers, 16, mu0, mus.clone());
            for (k, &mu) in mus.iter().enumerate() {
                for phi in [0.0, 0.3, 1.5, PI] {
                    let (got, want) = (grid.diffuse_radiance(mu, phi), exact.at_node(k, phi));
                    let rel = (got - want).abs() / want;
                    if rel > worst.0 {
                        worst = (rel, mu0, mu, phi);
                    }
                }
            }
        }
        eprintln!(
            "worst interpolation error {:.2e} (sun cosine {}, view cosine {:.4}, azimuth {:.2})",
            worst.0, worst.1, worst.2, worst.3
        );
        assert!(worst.0 < 1e-5, "{worst:?}");
    }

    /// Catmull-Rom reproduces a cubic's values at the nodes and sums to one.
    #[test]
    fn catmull_rom_weights_are_a_partition_of_unity() {
        for t in [0.0, 0.25, 0.5, 0.9] {
            let w = catmull_rom(t);
            assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            // Exact for a line: nodes at -1, 0, 1, 2.
            let line: f64 = w.iter().zip([-1.0, 0.0, 1.0, 2.0]).map(|(a, x)| a * x).sum();
            assert!((line - t).abs() < 1e-12);
        }
        assert_eq!(catmull_rom(0.0), [0.0, 1.0, 0.0, 0.0]);
    }
}
