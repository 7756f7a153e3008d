//! `sky render --method deterministic`: a view's pixels from the transport
//! solver instead of the path tracer, with the same scene (bands, spectral
//! lines, optics) and the same outputs, so that the two can be compared
//! direction by direction.
//!
//! A pixel looking up is the single scattering by the renderer's own
//! quadrature (`render::single`, the path tracer's first vertex) plus the
//! light scattered twice or more from the sun-angle columns (`columns`); a pixel
//! looking down sees the Lambertian ground, (A/π) E with E the ground's
//! irradiance; the sun's disk, where the view shows it, is the direct beam
//! F₀ e^{−τ/μ₀} spread over the disk's solid angle, times the part of the
//! pixel that sees it (`disk_coverage`).
//!
//! The diffuse light is integrated along the rays of [`VIEW_NODES`] view
//! cosines, μ_k = (k / K)², k = 1..K, dense toward the horizon where the
//! light changes fastest, at [`AZIMUTH_INTERVALS`] + 1 azimuths from 0 to
//! π, and interpolated between them by Catmull-Rom in √μ and in azimuth
//! (the test below bounds what that costs against each pixel's own ray).
//!
//! So far: seen from the ground, without fog, any sun (twilight by the
//! columns, whose limits `columns` states). The rest is refused with the
//! reason.

use super::columns::{self, Columns};
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
pub const VIEW_NODES: usize = 128;

/// How many intervals of azimuth, 0 to π, the diffuse light is solved at.
pub const AZIMUTH_INTERVALS: usize = 64;

/// The solver's resolutions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Resolution {
    /// Discrete-ordinate streams a hemisphere.
    pub streams: usize,
    pub grading: Grading,
    /// The spacing of the sun-angle columns, degrees (`columns`).
    pub column_step_deg: f64,
    /// Whether the columns' sources are made spherical (`spherical`): the
    /// light carried sideways between them, which twilight needs (always
    /// from `SPHERICAL_FROM_SUN_ZENITH_DEG` on).
    pub spherical: bool,
}

impl Default for Resolution {
    /// 16 streams a hemisphere: within 0.05 % of DISORT on the clear and
    /// hazed slabs (tests/transport.rs); the cloud slabs need 32.
    fn default() -> Resolution {
        Resolution { streams: 16, grading: Grading::default(), column_step_deg: 1.0, spherical: false }
    }
}

/// What the deterministic solver cannot render yet.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Unsupported {
    #[error(
        "the deterministic solver is judged at twilight down to a sun {MAX_SUN_ZENITH_DEG} deg from the zenith, \
         not {0} deg (docs/rendering.md); deeper twilight renders with --method monte-carlo"
    )]
    Twilight(f64),
    #[error("the deterministic solver sees from the ground so far (--altitude-m 0), not from {0} m")]
    Altitude(f64),
    #[error("the deterministic solver renders no fog yet; fog renders with --method monte-carlo")]
    Fog,
}

/// The lowest sun `sky render --method deterministic` accepts in spherical
/// shells: the lowest its twilight judge reaches (`tests/transport.rs`,
/// the path tracer's reference at 91, 93, 96 and 99°). `render` itself
/// renders any sun.
pub const MAX_SUN_ZENITH_DEG: f64 = 99.0;

/// From this sun zenith angle on, in spherical shells, the columns'
/// sources are made spherical (`spherical`) whatever
/// `Resolution::spherical` says: lower, the columns alone miss the light
/// carried sideways into the Earth's shadow (−0.1 to −6.8 % at 91°, −58 to
/// −99.9 % at 99° before `spherical`), higher they are within about 1 %
/// at ten times less cost.
pub const SPHERICAL_FROM_SUN_ZENITH_DEG: f64 = 88.0;

/// Why `sky render` refuses `view` of an atmosphere of this geometry with
/// the deterministic method, if it does: what `render` cannot do, and
/// twilight, which it does too poorly.
pub fn check_for_users(geometry: Geometry, view: &View) -> Result<(), Unsupported> {
    let twilight = view.parts().iter().map(|(_, p)| p.sun_zenith_deg).find(|&z| z > MAX_SUN_ZENITH_DEG);
    if let (Geometry::Spherical, Some(z)) = (geometry, twilight) {
        return Err(Unsupported::Twilight(z));
    }
    check(view)
}

/// Why `view` cannot be rendered deterministically, if it cannot.
pub fn check(view: &View) -> Result<(), Unsupported> {
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
    check(view)?;
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
/// irradiance: the diffuse light reaching the ground on a grid of view
/// cosines and azimuths, the ground's irradiance, the beam's transmittance
/// to the ground, the ground's albedo.
struct Wavelength {
    diffuse: DiffuseLight,
    ground_irradiance: f64,
    sun_transmittance: f64,
    ground_albedo: f64,
}

/// The light scattered twice or more that reaches the ground.
enum DiffuseLight {
    /// `[k][p]`: at view cosine node k and azimuth node p.
    Table(Vec<Vec<f64>>),
    /// Along each pixel's own ray (views of few pixels looking up).
    Pixels(Vec<f64>),
}

/// Views with at most this many pixels looking up have the diffuse light
/// integrated along each pixel's own ray instead of the nodes' table (a
/// pixel's ray costs about half a view node's, which integrates 65
/// azimuths at once: the table of 128 nodes costs about 256 pixels' rays).
pub const PIXEL_RAYS: usize = 256;

impl Wavelength {
    /// `pixel_rays`: (zenith cosine, azimuth from the sun) of each pixel
    /// looking up, where there are few enough of them.
    fn solve(
        scene: &Scene,
        optics: &Spectral,
        sun_zenith_rad: f64,
        resolution: &Resolution,
        pixel_rays: Option<&[(usize, f64, f64)]>,
    ) -> Wavelength {
        let layers = Layers::new(&scene.medium, optics, 2 * resolution.streams, &resolution.grading);
        let step_rad = resolution.column_step_deg.to_radians();
        let twilight = sun_zenith_rad >= SPHERICAL_FROM_SUN_ZENITH_DEG.to_radians();
        let columns = if layers.shell_radius_km.is_some() && (resolution.spherical || twilight) {
            // The node rays reach a ray's travel beyond the view's.
            let grid = columns::grid_reaches(&layers, sun_zenith_rad, step_rad, 2.0);
            super::spherical::solve(&layers, resolution.streams, grid, &super::spherical::Settings::default()).0
        } else {
            Columns::solve(&layers, resolution.streams, columns::grid(&layers, sun_zenith_rad, step_rad))
        };
        let diffuse = match pixel_rays {
            Some(rays) => {
                let mut pixels = vec![0.0; rays.iter().map(|r| r.0 + 1).max().unwrap_or(0)];
                for &(i, mu, phi) in rays {
                    pixels[i] = columns.rays(sun_zenith_rad, mu, &[phi])[0];
                }
                DiffuseLight::Pixels(pixels)
            }
            None => {
                let phis = azimuth_nodes();
                DiffuseLight::Table(view_nodes().iter().map(|&mu| columns.rays(sun_zenith_rad, mu, &phis)).collect())
            }
        };
        Wavelength {
            diffuse,
            ground_irradiance: columns.ground_irradiance_at(sun_zenith_rad),
            sun_transmittance: super::adding::sun_transmittance(&layers, sun_zenith_rad.cos()),
            ground_albedo: layers.ground_albedo,
        }
    }

    /// The diffuse radiance toward a pixel looking up at cosine `mu`,
    /// azimuth `phi` from the sun: Catmull-Rom in √μ between the view
    /// nodes (clamped at the ends, and below the first node), and in
    /// azimuth between the azimuth nodes (mirrored about 0 and π, where
    /// the sky is symmetric).
    fn diffuse_radiance(&self, pixel: usize, mu: f64, phi: f64) -> f64 {
        let table = match &self.diffuse {
            DiffuseLight::Pixels(p) => return p[pixel],
            DiffuseLight::Table(t) => t,
        };
        let last = VIEW_NODES as isize;
        let s = (mu.max(0.0).sqrt() * VIEW_NODES as f64).clamp(1.0, last as f64);
        let k = (s.floor() as isize).min(last - 1);
        let wk = catmull_rom(s - k as f64);
        let ks = [k - 1, k, k + 1, k + 2].map(|i| (i.clamp(1, last) - 1) as usize);
        let folded = libm::atan2(phi.sin(), phi.cos()).abs();
        let t = folded / PI * AZIMUTH_INTERVALS as f64;
        let p = (t.floor() as isize).min(AZIMUTH_INTERVALS as isize - 1);
        let wp = catmull_rom(t - p as f64);
        let ps = [p - 1, p, p + 1, p + 2].map(|i| {
            let n = AZIMUTH_INTERVALS as isize;
            (if i < 0 {
                -i
            } else if i > n {
                2 * n - i
            } else {
                i
            }) as usize
        });
        (0..4).map(|a| wk[a] * (0..4).map(|b| wp[b] * table[ks[a]][ps[b]]).sum::<f64>()).sum()
    }

    /// The radiance of the Lambertian ground.
    fn ground_radiance(&self) -> f64 {
        self.ground_albedo / PI * self.ground_irradiance
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

/// The azimuths from the sun's the diffuse light is solved at, 0 to π.
fn azimuth_nodes() -> Vec<f64> {
    (0..=AZIMUTH_INTERVALS).map(|p| p as f64 * PI / AZIMUTH_INTERVALS as f64).collect()
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
    let sun_zenith_rad = mu0.clamp(-1.0, 1.0).acos();
    let (w, h) = (view.width, view.height);
    let up: Vec<(usize, f64, f64)> = (0..w * h)
        .filter_map(|i| {
            let dir = view.camera.direction((i % w) as f64 + 0.5, (i / w) as f64 + 0.5, w, h)?;
            (dir.z > 0.0).then(|| (i, dir.z, azimuth_between(dir, sun)))
        })
        .collect();
    let pixel_rays = (up.len() <= PIXEL_RAYS).then_some(&up[..]);
    let solve = |optics: &[Spectral]| -> Vec<Wavelength> {
        optics
            .par_iter()
            .map(|o| {
                let w = Wavelength::solve(scene, o, sun_zenith_rad, resolution, pixel_rays);
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
                        .map(|(b, wl)| once[b] + scale(b) * wl.diffuse_radiance(i, dir.z, phi) + direct[b])
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

    /// What the grids of view cosines and azimuths cost: the diffuse light
    /// interpolated between the nodes against the same light solved along
    /// each ray, in the hazed slab (the aerosol's forward lobe makes the
    /// most structure in azimuth) and in the clear sky in shells, for a
    /// high and a low sun, from the zenith to 0.1° above the horizon, at
    /// azimuths between the nodes. Bound: 1e-4 of the radiance (measured:
    /// 7.8e-6, the hazed slab, sun 25°; 6.2e-6 with 256 view nodes, 8.4e-5
    /// with 40 azimuth intervals).
    #[test]
    fn the_view_grid_interpolates_the_diffuse_light_within_1e_4() {
        let mus: Vec<f64> = (0..40)
            .map(|i| (0.1f64.to_radians()).sin().max(1e-3) + (i as f64 / 39.0).powi(3))
            .map(|m| m.min(1.0))
            .collect();
        let phis: Vec<f64> =
            [0.3, 1.0, 1.5, 2.2, 3.0].iter().map(|p| p + 0.37 * PI / AZIMUTH_INTERVALS as f64).collect();
        let mut worst = (0.0f64, "", 0.0, 0.0, 0.0);
        for file in ["tests/atmospheres/disort_rayleigh_hg.toml", "atmospheres/clear.toml"] {
            let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(file);
            let atm = Atmosphere::load(&path).unwrap();
            let medium = Medium::new(&atm);
            let optics = medium.spectral(&atm, 450.0, 1.0, 0.3, &MieCache::shared_by_tests());
            let layers = Layers::new(&medium, &optics, 32, &Grading::default());
            for sun in [25f64.to_radians(), 81f64.to_radians()] {
                let columns = Columns::solve(&layers, 16, columns::grid(&layers, sun, 1f64.to_radians()));
                let phi_nodes = azimuth_nodes();
                let grid = Wavelength {
                    diffuse: DiffuseLight::Table(
                        view_nodes().iter().map(|&mu| columns.rays(sun, mu, &phi_nodes)).collect(),
                    ),
                    ground_irradiance: 0.0,
                    sun_transmittance: 0.0,
                    ground_albedo: 0.3,
                };
                for &mu in &mus {
                    for (want, &phi) in columns.rays(sun, mu, &phis).iter().zip(&phis) {
                        let rel = (grid.diffuse_radiance(0, mu, phi) - want).abs() / want;
                        if rel > worst.0 {
                            worst = (rel, file, sun.to_degrees(), mu, phi);
                        }
                    }
                }
            }
        }
        eprintln!(
            "worst interpolation error {:.2e} ({}, sun {:.0} deg, view cosine {:.4}, azimuth {:.2})",
            worst.0, worst.1, worst.2, worst.3, worst.4
        );
        assert!(worst.0 < 1e-4, "{worst:?}");
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
