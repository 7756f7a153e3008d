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
//! The light of each wavelength, solved once for the suns of every part of
//! the view (the slices of a bake's strip), comes from `light`.
//!
//! The talk's global fog (`render::fog`: a view with `fog` set) is the same
//! sum stopped where the fog's reach along each ray ends (the object, or
//! the ceiling): the single scattering by the same quadrature stopped
//! there (none for the Shadowed Fog), the multiply scattered light along
//! each pixel's own ray to its reach (`Columns::rays_to`), nothing from the
//! ground or the sun's disk (black, the engine draws them).
//!
//! So far: seen from the ground, any sun (twilight by the columns, whose
//! limits `columns` states). The rest is refused with the reason.

use super::layers::Grading;
use super::light::{between_nodes, spectral_nodes, transpose, PixelRay, Solved, Wavelength, PIXEL_RAYS};
use crate::atmosphere::Geometry;
use crate::directions::Camera;
use crate::render::single::{xyz_of, SingleScattering};
use crate::render::{Image, PixelResult, Scene, View};
use glam::DVec3;
use rayon::prelude::*;
use std::f64::consts::PI;

mod price;

/// The solver's resolutions.
pub use super::light::{wavelengths_solved, AZIMUTH_INTERVALS, BAKE_VIEW_GRID, DRAFT_VIEW_GRID, VIEW_NODES};

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
    /// The bands whose multiply scattered light is solved are this many nm
    /// apart at least (the first and the last always); the light of the
    /// bands between is interpolated, a power law in wavelength between
    /// the two nearest (`spectral_nodes`). 0: every band. Spectral lines
    /// are always solved.
    pub ms_step_nm: f64,
    /// The diffuse light's table for views of many pixels: view cosines
    /// and intervals of azimuth from 0 to π (`light`).
    pub view_grid: (usize, usize),
    /// The spherical source iteration's settings (`spherical::Detail`).
    pub twilight: super::spherical::Detail,
    /// A view (other than a LUT slice or fog) with at most this many
    /// pixels looking up has each pixel's own ray instead of the table of
    /// view nodes ([`PIXEL_RAYS`]). The bake's resolutions set 0
    /// (`bake::solver::resolution`): `sky lut verify`'s references at 13
    /// suns then share the table's rays (one view node's ray serves every
    /// sun) instead of a ray a direction and sun.
    pub pixel_rays: usize,
}

impl Default for Resolution {
    /// 16 streams a hemisphere: within 0.05 % of DISORT on the clear and
    /// hazed slabs (tests/transport.rs); the cloud slabs need 32.
    fn default() -> Resolution {
        Resolution {
            streams: 16,
            grading: Grading::default(),
            column_step_deg: 1.0,
            spherical: false,
            ms_step_nm: 0.0,
            view_grid: (VIEW_NODES, AZIMUTH_INTERVALS),
            twilight: super::spherical::Detail::Full,
            pixel_rays: PIXEL_RAYS,
        }
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
    Ok(render_views(scene, std::slice::from_ref(view), resolution, on_wavelength)?.remove(0))
}

/// `render` for several views at once (`sky lut verify`'s references at
/// its sun elevations): each wavelength solved once for the suns of all
/// of them. Each image is the one `render` gives its view alone, bit for
/// bit, while no sun is beyond `MAX_SUN_ZENITH_DEG` (such a sun widens the
/// twilight's grid of columns for all: about 1e-9 of the twilight's light).
pub fn render_views(
    scene: &Scene,
    views: &[View],
    resolution: &Resolution,
    on_wavelength: &(dyn Fn() + Sync),
) -> Result<Vec<Image>, Unsupported> {
    let staged = Staged::new(scene, views, resolution)?;
    let solved: Vec<(WavelengthId, SolvedWavelength)> = staged
        .wavelengths()
        .into_par_iter()
        .map(|id| {
            let w = staged.solve(id);
            on_wavelength();
            (id, w)
        })
        .collect();
    Ok(staged.finish(solved))
}

/// One wavelength `render_views` solves: a band node (its index among the
/// scene's bands; `spectral_nodes`) or a spectral line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum WavelengthId {
    Band(usize),
    Line(usize),
}

/// One wavelength's light for every part of a [`Staged`] render.
pub struct SolvedWavelength {
    light: Vec<Wavelength>,
}

/// `render_views` in stages, for a caller that orders the wavelengths'
/// solutions itself (a deterministic bake solves one of every basis sky
/// first, for its forecast): `new`, `solve` each of `wavelengths` in any
/// order and on any thread, `finish` with all of them. The images are
/// `render_views`' own.
pub struct Staged<'a> {
    scene: &'a Scene,
    views: &'a [View],
    resolution: Resolution,
    /// (view, first column, part) of every part of every view.
    parts: Vec<(usize, usize, View)>,
    suns_rad: Vec<f64>,
    rays: Vec<Vec<PixelRay>>,
    /// Whether each part takes its pixels' own rays (else the table).
    own_rays: Vec<bool>,
    band_nodes: Vec<usize>,
}

impl<'a> Staged<'a> {
    pub fn new(scene: &'a Scene, views: &'a [View], resolution: &Resolution) -> Result<Staged<'a>, Unsupported> {
        views.iter().try_for_each(check)?;
        let parts: Vec<(usize, usize, View)> = views
            .iter()
            .enumerate()
            .flat_map(|(v, view)| view.parts().into_iter().map(move |(x, p)| (v, x, p)))
            .collect();
        let suns_rad: Vec<f64> = parts.iter().map(|(_, _, p)| sun_zenith_rad(p)).collect();
        let rays: Vec<Vec<PixelRay>> = parts.iter().map(|(_, _, p)| rays_up(scene, p)).collect();
        // A LUT slice always takes the tables: a bake's strip makes them for
        // all its slices at once (`Columns::rays_for_suns`), cheaper there
        // than each texel's own ray even for the demo's 8 x 32 cloudy slices
        // (a cloudy draft's tables 9 s a wavelength against 14 s), and a
        // slice is then the same bytes rendered alone or in a strip. Fog
        // always takes each pixel's own ray, to its own reach.
        let own_rays = parts
            .iter()
            .zip(&rays)
            .map(|((_, _, p), r)| {
                p.fog.is_some() || (r.len() <= resolution.pixel_rays && !matches!(p.camera, Camera::Lut { .. }))
            })
            .collect();
        let band_nodes = spectral_nodes(&scene.band_optics, resolution.ms_step_nm);
        Ok(Staged { scene, views, resolution: *resolution, parts, suns_rad, rays, own_rays, band_nodes })
    }

    /// The wavelengths to solve: the bands' nodes, then every spectral line.
    pub fn wavelengths(&self) -> Vec<WavelengthId> {
        let bands = self.band_nodes.iter().map(|&i| WavelengthId::Band(i));
        bands.chain((0..self.scene.line_optics.len()).map(WavelengthId::Line)).collect()
    }

    /// One wavelength solved once for the suns of every part (the slices
    /// of a strip share their columns) and read for each part's pixels.
    pub fn solve(&self, id: WavelengthId) -> SolvedWavelength {
        let optics = match id {
            WavelengthId::Band(i) => &self.scene.band_optics[i],
            WavelengthId::Line(i) => &self.scene.line_optics[i],
        };
        let pixel_rays: Vec<Option<&[PixelRay]>> =
            self.rays.iter().zip(&self.own_rays).map(|(r, &own)| own.then_some(&r[..])).collect();
        let light =
            Solved::new(self.scene, optics, &self.suns_rad, &self.resolution).wavelengths(&self.suns_rad, &pixel_rays);
        SolvedWavelength { light }
    }

    /// The images from every wavelength of `wavelengths` solved.
    pub fn finish(&self, mut solved: Vec<(WavelengthId, SolvedWavelength)>) -> Vec<Image> {
        solved.sort_by_key(|s| s.0);
        let (bands, lines): (Vec<_>, Vec<_>) = solved.into_iter().partition(|s| matches!(s.0, WavelengthId::Band(_)));
        assert_eq!(bands.len(), self.band_nodes.len(), "every band node solved");
        assert_eq!(lines.len(), self.scene.line_optics.len(), "every spectral line solved");
        let (scene, suns, parts) = (self.scene, &self.suns_rad, self.parts.len());
        let light = |s: Vec<(WavelengthId, SolvedWavelength)>| s.into_iter().map(|s| s.1.light).collect();
        let every_line: Vec<usize> = (0..scene.line_optics.len()).collect();
        let bands = between_nodes(scene, &scene.band_optics, &self.band_nodes, light(bands), suns, &self.resolution);
        let lines = between_nodes(scene, &scene.line_optics, &every_line, light(lines), suns, &self.resolution);
        let (bands, lines) = (transpose(bands, parts), transpose(lines, parts));
        let views = self.views;
        let mut pixels: Vec<Vec<Option<PixelResult>>> = views.iter().map(|v| vec![None; v.width * v.height]).collect();
        for (((v, first, part), bands), lines) in self.parts.iter().zip(bands).zip(lines) {
            let part_pixels = render_part(scene, part, &bands, &lines);
            for (i, p) in part_pixels.into_iter().enumerate() {
                let (x, y) = (first + i % part.width, i / part.width);
                pixels[*v][y * views[*v].width + x] = Some(p);
            }
        }
        views
            .iter()
            .zip(pixels)
            .map(|(view, pixels)| Image {
                width: view.width,
                height: view.height,
                pixels: pixels.into_iter().map(|p| p.expect("the parts cover the view")).collect(),
            })
            .collect()
    }
}

/// The sun's zenith angle over the observer of `view`, radians.
fn sun_zenith_rad(view: &View) -> f64 {
    view.sun_direction().z.clamp(-1.0, 1.0).acos()
}

/// (pixel, zenith cosine, azimuth from the sun, reach km) of each pixel
/// of `view` looking up; the reach is infinite but in fog.
fn rays_up(scene: &Scene, view: &View) -> Vec<PixelRay> {
    let sun = view.sun_direction();
    let (w, h) = (view.width, view.height);
    let observer = scene.medium.observer(view.altitude_m / 1000.0);
    (0..w * h)
        .filter_map(|i| {
            let dir = view.camera.direction((i % w) as f64 + 0.5, (i / w) as f64 + 0.5, w, h)?;
            let reach_km = view.fog.map_or(f64::INFINITY, |f| f.reach_km(&scene.medium, observer, dir));
            looks_up(view, dir).then(|| (i, dir.z.max(0.0), azimuth_between(dir, sun), reach_km))
        })
        .collect()
}

/// Whether a pixel of `view` toward `dir` sees the sky (or the fog)
/// rather than the ground: above the horizon, and for fog the level
/// directions too (the Fog LUT's horizon row: in spherical shells a level
/// ray from the ground rises).
fn looks_up(view: &View, dir: DVec3) -> bool {
    dir.z > 0.0 || (view.fog.is_some() && dir.z >= 0.0)
}

/// One part of a view (a whole view, or one slice of a LUT strip),
/// row-major, from its bands' and spectral lines' light.
fn render_part(scene: &Scene, view: &View, bands: &[Wavelength], lines: &[Wavelength]) -> Vec<PixelResult> {
    let sun = view.sun_direction();
    let mu0 = sun.z;
    let (w, h) = (view.width, view.height);
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
            let disk = if view.sun_disk && mu0 > 0.0 && view.fog.is_none() {
                disk_coverage(view, i, sun, cos_half)
            } else {
                0.0
            };
            let radiance = |waves: &[Wavelength], single: &SingleScattering, scale: &dyn Fn(usize) -> f64| {
                let direct: Vec<f64> = waves
                    .iter()
                    .enumerate()
                    .map(|(b, wl)| disk * scale(b) * wl.sun_transmittance * disk_per_sr)
                    .collect();
                let total: Vec<f64> = if looks_up(view, dir) {
                    let phi = azimuth_between(dir, sun);
                    let once = match view.fog {
                        _ if waves.is_empty() => Vec::new(),
                        None => single.radiance(dir),
                        Some(fog) if fog.shadowed => vec![0.0; waves.len()],
                        Some(fog) => single.radiance_to(dir, fog.max_distance_km, fog.ceiling_km),
                    };
                    waves
                        .iter()
                        .enumerate()
                        .map(|(b, wl)| once[b] + scale(b) * wl.diffuse_radiance(i, dir.z, phi) + direct[b])
                        .collect()
                } else if view.fog.is_some() {
                    vec![0.0; waves.len()]
                } else {
                    waves.iter().enumerate().map(|(b, wl)| scale(b) * wl.ground_radiance() + direct[b]).collect()
                };
                (total, direct)
            };
            let weight = &scene.bands.weight;
            let (band_l, band_direct) = radiance(bands, &single_bands, &|_| 1.0);
            let (line_l, _) = radiance(lines, &single_lines, &|k| scene.line_optics[k].sun_irradiance);
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

    /// A bake renders a basis sky's slices as one strip whose suns share
    /// each wavelength's solution: every slice of the strip is exactly the
    /// slice rendered alone, by day and at twilight (the spherical
    /// source's grid is the same for every twilight sun), with every band
    /// solved and with bands interpolated between spectral nodes. Coarse
    /// resolutions (4 streams, columns every 3°, 100 nm bands) keep it
    /// cheap; the property does not depend on them.
    #[test]
    fn a_strip_of_slices_renders_each_slice_as_it_renders_alone() {
        use crate::directions::camera::Camera;
        use crate::directions::mapping::DirectionMapping;
        use crate::render::{SpectralSettings, WavelengthSampling};
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("atmospheres/clear.toml");
        let atm = Atmosphere::load(&path).unwrap();
        let spectral = SpectralSettings {
            band_nm: 100.0,
            wavelength_sampling: WavelengthSampling::Hero,
            spectral_nm: vec![],
            xyz: true,
        };
        let scene = Scene::new(&atm, &spectral, &MieCache::shared_by_tests(), &|| {});
        let suns_deg = [30.0, 89.0, 95.0];
        // LUT slices take the tables, whose rays the suns share
        // (`Columns::rays_for_suns`).
        const W: usize = 20;
        const H: usize = 30;
        let slice = |sun_deg: f64| {
            let mut v = View::directions(vec![], sun_deg, 0.0, 1, 1);
            let mapping = DirectionMapping::new(sun_deg, 87.9);
            let camera = Camera::Lut { mapping, sun_azimuth_deg: 0.0 };
            (v.camera, v.width, v.height, v.sun_disk) = (camera, W, H, false);
            v
        };
        let mut strip = slice(suns_deg[0]);
        strip.camera = Camera::LutStrip {
            mappings: suns_deg.iter().map(|&z| DirectionMapping::new(z, 87.9)).collect(),
            sun_azimuth_deg: 0.0,
        };
        strip.width = W * suns_deg.len();
        for ms_step_nm in [0.0, 250.0] {
            let resolution =
                Resolution { streams: 4, column_step_deg: 3.0, ms_step_nm, view_grid: (16, 8), ..Default::default() };
            let together = render(&scene, &strip, &resolution, &|| {}).unwrap();
            for (k, &sun) in suns_deg.iter().enumerate() {
                let alone = render(&scene, &slice(sun), &resolution, &|| {}).unwrap();
                for (i, p) in alone.pixels.iter().enumerate() {
                    let q = &together.pixels[(i / W) * strip.width + W * k + i % W];
                    assert_eq!(p.xyz, q.xyz, "sun {sun}, texel {i}, ms step {ms_step_nm} nm");
                    assert!(p.xyz[1] > 0.0, "sun {sun}, texel {i}: {:?}", p.xyz);
                }
            }
        }
    }

    /// `clear.toml` in 100 nm bands: cheap scenes for properties that do
    /// not depend on the spectral resolution.
    fn clear_scene() -> Scene {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("atmospheres/clear.toml");
        let atm = Atmosphere::load(&path).unwrap();
        let spectral = crate::render::SpectralSettings {
            band_nm: 100.0,
            wavelength_sampling: crate::render::WavelengthSampling::Hero,
            spectral_nm: vec![],
            xyz: true,
        };
        Scene::new(&atm, &spectral, &MieCache::shared_by_tests(), &|| {})
    }

    /// Fog in front of nothing (infinitely far, no ceiling) is the sky
    /// (`render::fog`: "the same radiance at infinity as the sky") for
    /// views that do not meet the ground, bit for bit but for the single
    /// scattering's march; nearer, it grows with the distance and stays
    /// below the sky; the Shadowed Fog is below the lit one.
    #[test]
    fn fog_is_the_sky_stopped_at_its_distance() {
        use crate::render::fog::Fog;
        let scene = clear_scene();
        let dirs = vec![(10.0, 0.0), (60.0, 90.0), (85.0, 180.0), (89.0, 20.0)];
        let resolution = Resolution { streams: 4, column_step_deg: 3.0, ms_step_nm: 250.0, ..Default::default() };
        let y_of = |fog: Option<Fog>| -> Vec<f64> {
            let mut view = View::directions(dirs.clone(), 50.0, 0.0, 1, 1);
            view.sun_disk = false;
            view.fog = fog;
            render(&scene, &view, &resolution, &|| {}).unwrap().pixels.iter().map(|p| p.xyz[1]).collect()
        };
        let sky = y_of(None);
        let far = y_of(Some(Fog::lit(f64::INFINITY, None)));
        for (s, f) in sky.iter().zip(&far) {
            assert!((f / s - 1.0).abs() < 1e-6, "infinitely far fog {f} against the sky {s}");
        }
        let mut before = vec![0.0; dirs.len()];
        for distance_km in [0.5, 2.0, 10.0, 50.0] {
            let fog = y_of(Some(Fog::lit(distance_km, None)));
            let shadowed = y_of(Some(Fog::lit(distance_km, None).shadowed()));
            for k in 0..dirs.len() {
                assert!(
                    fog[k] > before[k] && fog[k] < sky[k],
                    "{distance_km} km, view {k}: {} after {}",
                    fog[k],
                    before[k]
                );
                assert!(shadowed[k] > 0.0 && shadowed[k] < fog[k], "{distance_km} km, view {k}");
            }
            before = fog;
        }
    }

    /// `render_views` (`sky lut verify`'s references) solves once for the
    /// suns of several views, each few enough pixels to take its own rays:
    /// each image is the view rendered alone.
    /// (And a render in stages is the same render.)
    #[test]
    fn views_rendered_together_are_each_as_rendered_alone() {
        let scene = clear_scene();
        let dirs = vec![(10.0, 0.0), (60.0, 90.0), (85.0, 180.0)];
        let views: Vec<View> = [30.0, 95.0].iter().map(|&sun| View::directions(dirs.clone(), sun, 0.0, 1, 1)).collect();
        let resolution = Resolution {
            streams: 4,
            column_step_deg: 3.0,
            ms_step_nm: 250.0,
            view_grid: (16, 8),
            ..Default::default()
        };
        let together = render_views(&scene, &views, &resolution, &|| {}).unwrap();
        for (view, image) in views.iter().zip(&together) {
            let alone = render(&scene, view, &resolution, &|| {}).unwrap();
            let xyz = |i: &Image| i.pixels.iter().map(|p| p.xyz).collect::<Vec<_>>();
            assert_eq!(xyz(&alone), xyz(image), "sun {}", view.sun_zenith_deg);
            assert!(image.pixels.iter().all(|p| p.xyz[1] > 0.0), "sun {}", view.sun_zenith_deg);
        }
        // In stages, the wavelengths solved in another order (the middle
        // one first, as a bake's pilot; a spectral line among them): the
        // same images.
        let scene = Scene::new(
            &Atmosphere::load(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("atmospheres/clear.toml"))
                .unwrap(),
            &crate::render::SpectralSettings {
                band_nm: 100.0,
                wavelength_sampling: crate::render::WavelengthSampling::Hero,
                spectral_nm: vec![550.0],
                xyz: true,
            },
            &MieCache::shared_by_tests(),
            &|| {},
        );
        let together = render_views(&scene, &views, &resolution, &|| {}).unwrap();
        let staged = Staged::new(&scene, &views, &resolution).unwrap();
        let mut ids = staged.wavelengths();
        assert!(ids.len() >= 3 && ids.contains(&WavelengthId::Line(0)), "{ids:?}");
        let middle = ids.len() / 2;
        ids.swap(0, middle);
        ids.reverse();
        let solved = ids.into_iter().map(|id| (id, staged.solve(id))).collect();
        assert_eq!(staged.finish(solved), together);
    }
}
