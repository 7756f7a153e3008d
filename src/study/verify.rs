//! `sky lut verify`: the reference decoder against direct renders of the
//! same atmospheres, at sun elevations between slices and at slice
//! centres, and the error split into its sources.
//!
//! - Directions: a Fibonacci lattice over the sky above the horizon
//!   (elevation 0.5° to 90°), in the frame with the sun at azimuth 0; the
//!   sun disk is hidden in the bake and the reference alike, and
//!   directions within 5° of the sun (the aureole) are reported apart.
//! - Luminance error: |Y_decoded − Y_reference| / Y_reference, median and
//!   99th percentile.
//! - Colour error: CIEDE2000 (Sharma, Wu and Dalal 2005) between the two
//!   in CIELAB, both scaled by the same white: D65 chromaticity at the
//!   reference's 99th-percentile luminance (a sky has no diffuse white;
//!   this one makes the brightest part of the sky L* ≈ 100).
//! - PSNR: 10 log10(peak² / mean squared error of Y), peak the reference's
//!   largest Y, over the directions outside the aureole (the measure of
//!   Bruneton 2017's comparison of his precomputed model to its reference).
//! - Sources: Monte Carlo noise is the bake's own median relative standard
//!   error of Y per texel (from the manifest) and the reference's;
//!   quantisation is R11G11B10F rounding, measured on the cached slices
//!   (stored texel against rendered value, the largest channel error over
//!   the texel's largest channel, over the texels in the normal range); direction interpolation is the
//!   error at slice centres; slice interpolation what the between-slice
//!   elevations add to it.

use crate::atmosphere::Atmosphere;
use crate::bake::cache::SliceCache;
use crate::bake::file::BakeFile;
use crate::bake::run::spectral_settings;
use crate::bake::slices::deterministic_tag;
use crate::bake::BakeError;
use crate::colour::error as colour_error;
use crate::colour::ColourSpace;
use crate::directions::camera::{direction_deg, Camera};
use crate::lut::decode::Luts;
use crate::mie::MieCache;
use crate::render::tracer::Estimator;
use crate::render::{Image, SingleScatter, View};
use crate::session::farm::{Options, WorkerSpec};
use crate::session::{OpticsCache, Session};
use crate::stats::{percentile, sky_lattice};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use crate::bake::references::{self, ReferenceViews};
pub use crate::bake::references::{BETWEEN_SLICES_DEG, REFERENCE_SEED};

#[derive(Debug, Clone)]
pub struct VerifyOptions {
    /// Directions of the lattice above the horizon.
    pub directions: usize,
    /// Samples per reference direction.
    pub spp: u32,
    /// Samples per direction of the fog's references (`verify_fog`).
    pub fog_spp: u32,
    /// Slice-centre elevations are taken from these slice indices.
    pub centre_slices: Vec<usize>,
    /// How the sky's references are rendered: the transport solver at the
    /// bake's resolution (`bake::solver::resolution`; all the elevations
    /// of a basis sky at once) or the path tracer at `spp`.
    pub reference: crate::bake::Method,
    pub workers: Vec<WorkerSpec>,
}

impl Default for VerifyOptions {
    fn default() -> VerifyOptions {
        VerifyOptions {
            directions: references::DIRECTIONS,
            spp: 256,
            fog_spp: 4096,
            centre_slices: references::CENTRE_SLICES.to_vec(),
            reference: crate::bake::Method::Deterministic,
            workers: Vec::new(),
        }
    }
}

/// The error at one sun elevation.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ElevationError {
    pub sun_elevation_deg: f64,
    /// True at a slice centre (direction interpolation only).
    pub slice_centre: bool,
    pub median_rel_y: f64,
    pub p99_rel_y: f64,
    pub aureole_median_rel_y: Option<f64>,
    pub aureole_p99_rel_y: Option<f64>,
    pub median_de2000: f64,
    pub p99_de2000: f64,
    pub psnr_db: f64,
    /// The reference's own median relative standard error of Y.
    pub reference_median_rel_stderr_y: f64,
    /// The interpolation part of the error, measured on the atmosphere's
    /// noise-free single-scattering sky baked in memory at this bake's
    /// size and threshold (`lut::interpolation`): direction and slice
    /// interpolation together, and direction interpolation alone (the
    /// slices read, each at its own sun); the difference is what slice
    /// interpolation adds. None below the horizon: there the single-
    /// scattering sky is no proxy (the Earth's shadow gives it sharp edges
    /// that light scattered more than once fills in).
    pub interpolation: Option<InterpolationSplit>,
    /// The decoded sun (top irradiance times the transmittance file) against
    /// the sun's irradiance at the observer straight from the optics' column
    /// table, what the renderer's direct sun uses: |ΔY| / Y (None with the
    /// sun below the horizon or a bake without a transmittance file).
    pub sun_rel_y: Option<f64>,
    /// The sun's transmittance to the observer below what the
    /// transmittance file's RGBA16F holds (2^-24, its smallest subnormal;
    /// behind thick cloud or at the horizon), decoded as 0: then
    /// `sun_rel_y` is None (it would read 100 %) and this is true.
    pub sun_below_format_floor: bool,
    /// The decoded ambient irradiance on an upward surface against a direct
    /// integration of the reference render over its lattice (uniform in
    /// solid angle above 0.5° elevation): |ΔY| / Y (None without ambient
    /// data or a lit reference).
    pub ambient_rel_y: Option<f64>,
}

/// See [`ElevationError::interpolation`].
#[derive(Debug, Clone, serde::Serialize)]
pub struct InterpolationSplit {
    pub median_rel_y: f64,
    pub p99_rel_y: f64,
    pub aureole_median_rel_y: Option<f64>,
    pub direction_only_median_rel_y: f64,
    pub direction_only_p99_rel_y: f64,
    /// The median over the directions of the single-scattering sky's Y over
    /// the reference's: how much of the sky the proxy is (it says little
    /// where it is a small part, as under thick clouds).
    pub single_scattering_fraction: f64,
}

/// One basis sky's verification.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SkyVerification {
    pub sky: String,
    pub elevations: Vec<ElevationError>,
    /// The bake's median relative standard error of Y per texel (median over slices).
    pub bake_median_rel_stderr_y: f64,
    /// R11G11B10F rounding: median and 99th percentile of the stored
    /// texels' largest channel error against the rendered ones, over the
    /// texel's largest channel (None without the cache).
    pub quantisation_median_rel: Option<f64>,
    pub quantisation_p99_rel: Option<f64>,
    /// The global-fog LUTs against direct renders (None for a bake
    /// without them).
    pub fog: Option<super::verify_fog::FogVerification>,
}

/// The references of one basis sky: its sky views' images where the
/// solver renders them (None: the path tracer renders each in turn, after
/// its progress line) and its fog views' images. The solver's come from
/// `cache` when a deterministic bake left them there under `key`
/// (`bake::references`), else it renders all of them at once (each
/// wavelength solved once) at the bake's resolution, and leaves them there;
/// `solving` is called before it does.
fn render_references(
    (session, sky, solving): (&Session, &str, &dyn Fn()),
    refs: &ReferenceViews,
    method: crate::bake::Method,
    (quality, sampling): (crate::bake::Quality, &crate::bake::Sampling),
    cache: Option<(&SliceCache, String)>,
    cancel: &Arc<AtomicBool>,
) -> Result<(Vec<Option<Image>>, Vec<Image>), BakeError> {
    let n = refs.sky.len();
    match method {
        crate::bake::Method::Deterministic => {
            let all = refs.all();
            let cached = cache.as_ref().and_then(|(c, key)| references::cached(c, key, &all));
            let mut images = match cached {
                Some(images) => images,
                None => {
                    solving();
                    let resolution = crate::bake::solver::resolution(quality, sampling);
                    let images = crate::transport::render::render_views(&session.scene, &all, &resolution, &|| {})
                        .map_err(|error| BakeError::Solver { sky: sky.to_string(), error })?;
                    if let Some((c, key)) = &cache {
                        references::store(c, key, &images)?;
                    }
                    images
                }
            };
            let fog = images.split_off(n);
            Ok((images.into_iter().map(Some).collect(), fog))
        }
        crate::bake::Method::MonteCarlo => {
            let fog = refs
                .fog
                .iter()
                .map(|view| {
                    let r = session.render_view(view, cancel.clone()).map_err(|source| BakeError::Render {
                        sky: format!("{sky} (fog reference)"),
                        index: usize::MAX,
                        source,
                    })?;
                    Ok(r.image)
                })
                .collect::<Result<Vec<Image>, BakeError>>()?;
            Ok((vec![None; n], fog))
        }
    }
}

/// Verifies every basis sky of `luts` that `bake` names (the bake file
/// gives the atmospheres and the quality's spectral settings);
/// `on_reference(sky, sun elevation)` is called before each reference
/// render, for progress (the elevation NaN before the solver's references
/// of a whole sky, unless they come from the bake's cache).
#[allow(clippy::too_many_arguments)]
pub fn verify(
    luts: &Luts,
    bake: &BakeFile,
    cache: Option<&SliceCache>,
    opts: &VerifyOptions,
    optics: &OpticsCache,
    mie: &MieCache,
    on_reference: &dyn Fn(&str, f64),
    cancel: Arc<AtomicBool>,
) -> Result<Vec<SkyVerification>, BakeError> {
    let quality =
        if luts.manifest.quality == "final" { crate::bake::Quality::Final } else { crate::bake::Quality::Draft };
    let dirs = sky_lattice(opts.directions);
    let mut out = Vec::new();
    for (entry, texture) in luts.manifest.skies.iter().zip(&luts.textures) {
        let Some(sky) = bake.skies.iter().find(|s| s.name == entry.name) else { continue };
        let (atm, bundle) = Atmosphere::load_bundle(&sky.atmosphere)
            .map_err(|error| BakeError::Atmosphere { sky: sky.name.clone(), error })?;
        let sampling = sky.sampling(quality).clone();
        let spectral = spectral_settings(&sampling);
        let atm_hash = atm.content_hash.clone();
        let session =
            Session::new(atm, bundle, spectral.clone(), optics, mie, opts.workers.clone(), Options::default(), &|| {});
        let fog_ceiling_km =
            luts.manifest.fog.as_ref().filter(|f| f.skies.iter().any(|s| s.name == entry.name)).map(|f| f.ceiling_km);
        let refs = ReferenceViews::new(
            (entry.planet_radius_km, entry.top_km, sky.altitude_m),
            (opts.directions, &opts.centre_slices),
            (opts.spp, opts.fog_spp),
            fog_ceiling_km,
        );
        let elevations = refs.elevations.clone();
        // The interpolation part of the error, without noise.
        let model = crate::study::interpolation::SingleScatteringSky {
            scene: &session.scene,
            altitude_km: sky.altitude_m / 1000.0,
        };
        let lattice: Vec<glam::DVec3> = dirs.iter().map(|&(z, a)| direction_deg(z, a)).collect();
        let elevs: Vec<f64> = elevations.iter().map(|e| e.0.max(0.0)).collect();
        let split = crate::study::interpolation::split(&model, entry, &elevs, &lattice);
        use crate::study::interpolation::SkyModel;
        let solver_cache = cache.map(|c| (c, refs.key(&atm_hash, &spectral, &deterministic_tag(quality, &sampling))));
        let solving = || on_reference(&sky.name, f64::NAN);
        let (mut solved, fog_images) = render_references(
            (&session, &sky.name, &solving),
            &refs,
            opts.reference,
            (quality, &sampling),
            solver_cache,
            &cancel,
        )?;
        let views = &refs.sky;
        let mut errors = Vec::new();
        for (k, ((elev, centre), (both, direction))) in elevations.into_iter().zip(split).enumerate() {
            let image = match solved[k].take() {
                Some(image) => image,
                None => {
                    on_reference(&sky.name, elev);
                    let r = session.render_view(&views[k], cancel.clone()).map_err(|source| BakeError::Render {
                        sky: sky.name.clone(),
                        index: usize::MAX,
                        source,
                    })?;
                    r.image
                }
            };
            let sun = direction_deg(90.0 - elev, 0.0);
            let reference: Vec<[f64; 3]> = image.pixels.iter().map(|p| p.xyz).collect();
            let decoded: Vec<[f64; 3]> =
                dirs.iter().map(|&(z, a)| luts.sample_xyz_of(entry, texture, elev, direction_deg(z, a))).collect();
            let white_y = {
                let mut y: Vec<f64> = reference.iter().map(|x| x[1]).collect();
                percentile(&mut y, 0.99).max(1e-30)
            };
            let (mut rel, mut aureole, mut de) = (Vec::new(), Vec::new(), Vec::new());
            let (mut se, mut peak) = (0.0, 0.0f64);
            for (k, &(z, a)) in dirs.iter().enumerate() {
                let (d, x) = (decoded[k], reference[k]);
                if !(x[1] > 0.0) {
                    continue;
                }
                let e = (d[1] - x[1]).abs() / x[1];
                let near_sun = direction_deg(z, a).dot(sun) > libm::cos(5f64.to_radians());
                if near_sun {
                    aureole.push(e);
                    continue;
                }
                rel.push(e);
                de.push(colour_error::delta_e2000(colour_error::lab(x, white_y), colour_error::lab(d, white_y)));
                se += (d[1] - x[1]) * (d[1] - x[1]);
                peak = peak.max(x[1]);
            }
            let n = rel.len().max(1) as f64;
            let (sun_rel_y, sun_below_format_floor) = match sun_error(luts, entry, &session, sky.altitude_m, elev) {
                Some(SunError::BelowFloor) => (None, true),
                Some(SunError::Relative(e)) => (Some(e), false),
                None => (None, false),
            };
            let ambient_rel_y = ambient_error(luts, entry, &dirs, &reference, elev);
            let mut ref_rel: Vec<f64> =
                image.pixels.iter().filter(|p| p.xyz[1] > 0.0).map(|p| p.xyz_stderr[1] / p.xyz[1]).collect();
            errors.push(ElevationError {
                sun_elevation_deg: elev,
                slice_centre: centre,
                median_rel_y: percentile(&mut rel.clone(), 0.5),
                p99_rel_y: percentile(&mut rel, 0.99),
                aureole_median_rel_y: (!aureole.is_empty()).then(|| percentile(&mut aureole.clone(), 0.5)),
                aureole_p99_rel_y: (!aureole.is_empty()).then(|| percentile(&mut aureole, 0.99)),
                median_de2000: percentile(&mut de.clone(), 0.5),
                p99_de2000: percentile(&mut de, 0.99),
                psnr_db: 10.0 * (peak * peak / (se / n).max(1e-300)).log10(),
                reference_median_rel_stderr_y: percentile(&mut ref_rel, 0.5),
                interpolation: (elev >= 0.0).then(|| InterpolationSplit {
                    single_scattering_fraction: {
                        let mut f: Vec<f64> = dirs
                            .iter()
                            .zip(&reference)
                            .filter(|(_, x)| x[1] > 0.0)
                            .map(|(&(z, a), x)| model.xyz(90.0 - elev, direction_deg(z, a))[1] / x[1])
                            .collect();
                        percentile(&mut f, 0.5)
                    },
                    median_rel_y: both.median,
                    p99_rel_y: both.p99,
                    aureole_median_rel_y: both.aureole_median,
                    direction_only_median_rel_y: direction.median,
                    direction_only_p99_rel_y: direction.p99,
                }),
                sun_rel_y,
                sun_below_format_floor,
                ambient_rel_y,
            });
        }
        let mut noise: Vec<f64> = entry.slices.iter().map(|s| s.median_rel_stderr_y).collect();
        let (qm, qp) = match cache.map(|c| quantisation(c, luts, entry, texture, &session, &sampling, quality)) {
            Some(Some((m, p))) => (Some(m), Some(p)),
            _ => (None, None),
        };
        let fog = super::verify_fog::fog_errors(luts, &entry.name, &session, &fog_images);
        out.push(SkyVerification {
            sky: entry.name.clone(),
            elevations: errors,
            bake_median_rel_stderr_y: percentile(&mut noise, 0.5),
            quantisation_median_rel: qm,
            quantisation_p99_rel: qp,
            fog,
        });
    }
    Ok(out)
}

/// Y of linear RGB in the manifest's colour space.
fn y_of(luts: &Luts, rgb: [f64; 3]) -> f64 {
    crate::colour::apply(&luts.manifest.colour.xyz_from_rgb, rgb)[1]
}

/// The decoded sun against the reference: a relative error, or decoded
/// as 0 where the file cannot hold the transmittance.
enum SunError {
    Relative(f64),
    BelowFloor,
}

/// See [`ElevationError::sun_rel_y`] and `sun_below_format_floor`.
fn sun_error(
    luts: &Luts,
    entry: &crate::lut::manifest::SkyEntry,
    session: &Session,
    altitude_m: f64,
    elevation_deg: f64,
) -> Option<SunError> {
    if elevation_deg <= 0.0 {
        return None;
    }
    let i = luts.manifest.skies.iter().position(|s| s.name == entry.name)?;
    let mu = libm::sin(elevation_deg.to_radians());
    let top = entry.sun.as_ref()?.top_irradiance_rgb;
    let t = luts.sun_transmittance(i, altitude_m / 1000.0, mu)?;
    let decoded = y_of(luts, std::array::from_fn(|c| top[c] * t[c]));
    let want = crate::bake::tables::sun_xyz_at(&session.scene, altitude_m / 1000.0, mu)[1];
    if !(want > 0.0) {
        return None;
    }
    // Only a 0 where the true transmittance is under the floor counts as
    // the format's; a 0 above it stays a 100 % error.
    let floor = 2f64.powi(-24);
    if decoded == 0.0 && want < floor * y_of(luts, top) {
        return Some(SunError::BelowFloor);
    }
    Some(SunError::Relative((decoded - want).abs() / want))
}

/// See [`ElevationError::ambient_rel_y`].
fn ambient_error(
    luts: &Luts,
    entry: &crate::lut::manifest::SkyEntry,
    dirs: &[(f64, f64)],
    reference: &[[f64; 3]],
    elevation_deg: f64,
) -> Option<f64> {
    let a = entry.ambient.as_ref()?;
    let (i0, i1, f) = crate::lut::decode::slice_pair(entry, 90.0 - elevation_deg);
    let decoded = y_of(luts, crate::lut::ambient::Ambient::lerp(&a[i0], &a[i1], f).irradiance_up);
    // The lattice is uniform in solid angle over 2π (1 − sin 0.5°).
    let mu_min = libm::sin(0.5f64.to_radians());
    let weight = 2.0 * std::f64::consts::PI * (1.0 - mu_min) / dirs.len() as f64;
    let want: f64 = dirs.iter().zip(reference).map(|(&(z, _), x)| x[1] * libm::cos(z.to_radians()) * weight).sum();
    (want > 0.0).then(|| (decoded - want).abs() / want)
}

/// How the bake of `manifest` computed its sky slices (a manifest that
/// does not say is older than the transport solver: the path tracer).
fn method_of(manifest: &crate::lut::manifest::Manifest) -> crate::bake::Method {
    match manifest.method.as_deref() {
        Some("deterministic") => crate::bake::Method::Deterministic,
        _ => crate::bake::Method::MonteCarlo,
    }
}

/// The rounding error of the stored texels against the rendered ones, from
/// the cached slices (None if the cache lacks them).
fn quantisation(
    cache: &SliceCache,
    luts: &Luts,
    entry: &crate::lut::manifest::SkyEntry,
    texture: &crate::lut::decode::Texture,
    session: &Session,
    sampling: &crate::bake::Sampling,
    quality: crate::bake::Quality,
) -> Option<(f64, f64)> {
    let space: ColourSpace = luts.manifest.colour.space.parse().ok()?;
    let sky = crate::bake::BasisSky {
        name: entry.name.clone(),
        atmosphere: Default::default(),
        width: entry.width,
        height: entry.height,
        slices: entry.layers,
        altitude_m: entry.altitude_m,
        threshold_deg: entry.threshold_sun_zenith_deg,
        line: 0,
        draft: sampling.clone(),
        final_: sampling.clone(),
    };
    let mut rel = Vec::new();
    for (index, s) in entry.slices.iter().enumerate() {
        let view = crate::bake::run::slice_view(
            &sky,
            sampling,
            index,
            entry.planet_radius_km,
            entry.top_km,
            entry.threshold_sun_zenith_deg,
        );
        let key = crate::bake::run::sky_slice_key(
            &session.atmosphere.content_hash,
            &session.spectral,
            &view,
            (quality, method_of(&luts.manifest)),
            sampling,
        );
        let slice = cache.get(&key)?;
        let scale = (-s.scale_log2 as f64).exp2();
        for (t, x) in texture.layers[index].iter().zip(&slice.xyz) {
            let rgb = space.convert(*x).map(|c| c.max(0.0));
            let stored = t.map(|c| c as f64 * scale);
            // Relative to the texel's largest channel: Y of clamped RGB can be
            // near 0 while B is not, and B's rounding would then look huge.
            // Texels below the format's normal range (2^-14 after the slice's
            // scale) lose precision by design; the manifest counts them.
            let top = rgb.iter().copied().fold(0.0, f64::max);
            if top / scale >= (-14f64).exp2() {
                rel.push((0..3).map(|c| (stored[c] - rgb[c]).abs()).fold(0.0, f64::max) / top);
            }
        }
    }
    Some((percentile(&mut rel.clone(), 0.5), percentile(&mut rel, 0.99)))
}

/// The decoded twilight of one basis sky: (sun elevation, Y at the zenith,
/// Y on the horizon toward the sun, Y on the horizon away from it), the sun
/// from 0 to −10° in 0.1° steps; the horizon read at 1° elevation.
pub fn twilight_curve(
    luts: &Luts,
    entry: &crate::lut::manifest::SkyEntry,
    texture: &crate::lut::decode::Texture,
) -> Vec<[f64; 4]> {
    (0..=100)
        .map(|k| {
            let e = -0.1 * k as f64;
            let y = |z: f64, a: f64| luts.sample_xyz_of(entry, texture, e, direction_deg(z, a))[1];
            [e, y(0.0, 0.0), y(89.0, 0.0), y(89.0, 180.0)]
        })
        .collect()
}

/// The largest change of log Y from one 0.1° step to the next along a
/// curve's three directions.
pub fn largest_log_step(curve: &[[f64; 4]]) -> f64 {
    let mut worst: f64 = 0.0;
    for w in curve.windows(2) {
        for c in 1..4 {
            if w[0][c] > 0.0 && w[1][c] > 0.0 {
                worst = worst.max((w[1][c] / w[0][c]).ln().abs());
            }
        }
    }
    worst
}

/// What the atmosphere itself does at twilight: the largest change of log Y
/// per 0.1° of sun elevation in direct renders at the curve's three
/// directions, the sun from 0 to −10° in 0.5° steps (the change over each
/// step over 5).
pub fn reference_twilight_step(
    bake: &BakeFile,
    sky_name: &str,
    quality: crate::bake::Quality,
    spp: u32,
    optics: &OpticsCache,
    mie: &MieCache,
    workers: Vec<WorkerSpec>,
    cancel: Arc<AtomicBool>,
) -> Result<f64, BakeError> {
    let sky =
        bake.skies.iter().find(|s| s.name == sky_name).ok_or_else(|| BakeError::NoSuchSlice(sky_name.to_string()))?;
    let (atm, bundle) = Atmosphere::load_bundle(&sky.atmosphere)
        .map_err(|error| BakeError::Atmosphere { sky: sky.name.clone(), error })?;
    let sampling = sky.sampling(quality).clone();
    let session =
        Session::new(atm, bundle, spectral_settings(&sampling), optics, mie, workers, Options::default(), &|| {});
    let dirs = vec![(0.0, 0.0), (89.0, 0.0), (89.0, 180.0)];
    let mut ys: Vec<[f64; 3]> = Vec::new();
    for k in 0..=20 {
        let elev = -0.5 * k as f64;
        let view = View {
            camera: Camera::Directions(dirs.clone()),
            width: 3,
            height: 1,
            sun_zenith_deg: 90.0 - elev,
            sun_azimuth_deg: 0.0,
            altitude_m: sky.altitude_m,
            spp,
            seed: REFERENCE_SEED,
            estimator: Estimator::Full,
            sun_disk: false,
            single_scatter: SingleScatter::default(),
            fog: None,
            max_rel_error: None,
        };
        let r = session.render_view(&view, cancel.clone()).map_err(|source| BakeError::Render {
            sky: sky.name.clone(),
            index: usize::MAX,
            source,
        })?;
        ys.push([r.image.pixels[0].xyz[1], r.image.pixels[1].xyz[1], r.image.pixels[2].xyz[1]]);
    }
    let mut worst: f64 = 0.0;
    for w in ys.windows(2) {
        for c in 0..3 {
            if w[0][c] > 0.0 && w[1][c] > 0.0 {
                worst = worst.max((w[1][c] / w[0][c]).ln().abs() / 5.0);
            }
        }
    }
    Ok(worst)
}
