//! The global-fog LUTs of a basis sky (issue 13; `lut::fog` has the
//! mappings): the Fog LUT and the Shadowed Fog LUT, one slice per sun
//! elevation of the sky's time mapping (`render::fog`: the air below the
//! bake's ceiling scattering toward the camera, to the ceiling or the
//! ground); the Attenuation LUT (no Monte Carlo); and the depth falloff's
//! (a, p), fitted to reference fog renders (`lut::fog_falloff`). With
//! `--method deterministic` the slices come from the sky's own solution
//! (`solver::render_strips`) and the falloff's references from the solver
//! too; with `monte-carlo` both from the path tracer.
//!
//! Slices are cached like the sky's (the key is the view, which names the
//! fog, and the method), the falloff and the Attenuation table under a key
//! of their own, so a re-run renders nothing and a stopped bake resumes at
//! the slice it was on. The path tracer's slices render through the bake's
//! session (the embedded worker or `sky worker` daemons), one farm job a
//! slice, after the sky's slices; the falloff's references and the
//! Attenuation table on this process.

use super::cache::{slice_key, RenderedSlice, SliceCache};
use super::file::{BasisSky, FogSettings, Quality, Sampling};
use super::run::{slice_of_image, Method, BAKE_SEED};
use super::slices::deterministic_tag;
use super::BakeError;
use crate::atmosphere::Atmosphere;
use crate::bake::fog_falloff::{fit, study, study_views_of, ErrorSummary};
use crate::directions::mapping;
use crate::lut::fog::{fog_texel_view, AttenuationTable, Falloff, FogGeometry};
use crate::render::fog::Fog;
use crate::render::{Scene, SpectralSettings, View};
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// The suns of the falloff's reference renders, zenith angles in degrees.
pub const FALLOFF_SUN_ZENITHS_DEG: [f64; 3] = [30.0, 60.0, 85.0];

/// Samples per direction of the falloff's reference renders: each render
/// is of 3 directions, so these cost seconds (at 32 samples the references'
/// noise doubled the cloudy fit's error; see the README).
pub fn falloff_spp(quality: Quality) -> u32 {
    match quality {
        Quality::Draft => 256,
        Quality::Final => 1024,
    }
}

/// What a basis sky's fog needs besides its slices: the falloff and its
/// error, and the Attenuation table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FogExtras {
    pub falloff: Falloff,
    pub fit_error: ErrorSummary,
    pub depth_free_error: ErrorSummary,
    pub attenuation: AttenuationTable,
}

/// The fog LUTs of one basis sky.
#[derive(Debug, Clone)]
pub struct SkyFog {
    pub settings: FogSettings,
    pub geometry: FogGeometry,
    /// By slice index: the Fog LUT (`lit`) and the Shadowed Fog LUT, CIE
    /// XYZ per texel (row-major, v rows from the horizon up, u columns from
    /// the sun's azimuth to the opposite one).
    pub lit: Vec<RenderedSlice>,
    pub shadowed: Vec<RenderedSlice>,
    pub extras: FogExtras,
    pub rendered: usize,
    pub cached: usize,
    /// Of the slices rendered now.
    pub core_seconds: f64,
}

/// The view of fog slice `index` of `sky` (the Shadowed Fog's if
/// `shadowed`): the Fog LUT's texel directions, the slice's sun, the fog
/// to the ceiling.
pub fn fog_view(
    sky: &BasisSky,
    fog: &FogSettings,
    s: &Sampling,
    index: usize,
    radius_km: f64,
    top_km: f64,
    shadowed: bool,
) -> View {
    let sun_zenith_deg = mapping::slice_sun_zenith_deg(index, radius_km, top_km);
    View { max_rel_error: s.max_rel_error, ..fog_view_at(sky, fog, s.spp, sun_zenith_deg, shadowed) }
}

/// The Fog LUT's texel directions (`fog`'s size) at any sun, fixed at
/// `spp` samples: a fog slice's view, and the benchmark's.
pub fn fog_view_at(sky: &BasisSky, fog: &FogSettings, spp: u32, sun_zenith_deg: f64, shadowed: bool) -> View {
    let (w, h) = (fog.width, fog.height);
    let dirs = (0..h)
        .flat_map(|j| {
            (0..w).map(move |i| {
                let (elevation, azimuth) = fog_texel_view(i, j, w, h);
                (90.0 - elevation, azimuth)
            })
        })
        .collect();
    let fog = Fog { max_distance_km: f64::INFINITY, ceiling_km: Some(fog.ceiling_km), shadowed };
    // A w x h grid of directions (the camera reads pixel y * w + x).
    View {
        width: w,
        height: h,
        fog: Some(fog),
        ..View::directions(dirs, sun_zenith_deg, sky.altitude_m, spp, BAKE_SEED)
    }
}

/// The view of fog slice `index`'s render (its Shadowed Fog) and its cache
/// key (by the transport solver, its resolution's).
#[allow(clippy::too_many_arguments)]
fn shadowed_view_and_key(
    sky: &BasisSky,
    fog: &FogSettings,
    s: &Sampling,
    index: usize,
    radius_km: f64,
    top_km: f64,
    atmosphere_hash: &str,
    spectral: &SpectralSettings,
    (quality, method): (Quality, Method),
) -> (View, String) {
    let view = fog_view(sky, &shadowed_settings(fog, s), s, index, radius_km, top_km, true);
    let key = fog_slice_key(atmosphere_hash, spectral, &view, (quality, method), s);
    (view, key)
}

/// The cache key of a fog slice's render `view` (its Shadowed Fog): by the
/// transport solver, naming its resolution.
pub fn fog_slice_key(
    atmosphere_hash: &str,
    spectral: &SpectralSettings,
    view: &View,
    (quality, method): (Quality, Method),
    sampling: &Sampling,
) -> String {
    match method {
        Method::MonteCarlo => slice_key(atmosphere_hash, spectral, view, quality.name()),
        Method::Deterministic => slice_key(atmosphere_hash, spectral, view, &deterministic_tag(quality, sampling)),
    }
}

/// The Fog LUT settings the Shadowed Fog of sampling `s` is rendered at:
/// its `fog_ms_size` where set (then resampled by
/// [`super::fog_resample::resample_shadowed`]), else the LUT's own.
fn shadowed_settings(fog: &FogSettings, s: &Sampling) -> FogSettings {
    match s.fog_ms_size {
        Some([width, height]) => FogSettings { width, height, ..*fog },
        None => *fog,
    }
}

/// A fog slice a bake will render: its index, its render's view (the
/// Shadowed Fog's) and cache key.
pub struct FogTodo {
    pub index: usize,
    pub view: View,
    pub key: String,
}

/// The fog slices of `sky` that [`bake_fog`] will render: those not in
/// `cache`, each view once (two slices with the same sun share a render:
/// the second finds the first's in the cache).
pub fn to_render(
    sky: &super::SkySlices,
    fog: &FogSettings,
    cache: &SliceCache,
    quality: (Quality, Method),
) -> Vec<FogTodo> {
    let mut todo: Vec<FogTodo> = Vec::new();
    for index in 0..sky.sky.slices {
        let (view, key) = shadowed_view_and_key(
            &sky.sky,
            fog,
            &sky.sampling,
            index,
            sky.radius_km,
            sky.top_km,
            &sky.atmosphere_hash,
            &sky.spectral,
            quality,
        );
        if !todo.iter().any(|t| t.key == key) && cache.get(&key).is_none() {
            todo.push(FogTodo { index, view, key });
        }
    }
    todo
}

/// Core-seconds of the quadrature that turns a render of the Shadowed Fog
/// view `view` into the Fog (see [`lit_of_shadowed`]), timed on this
/// process's threads: the forecast's share of a fog slice beside its render.
pub fn time_quadrature(scene: &Scene, view: &View) -> f64 {
    let lit = View { fog: view.fog.map(|f| Fog { shadowed: false, ..f }), ..view.clone() };
    let start = Instant::now();
    std::hint::black_box(crate::render::single_per_pixel(scene, &lit));
    start.elapsed().as_secs_f64() * rayon::current_num_threads() as f64
}

/// The cache key of a basis sky's [`FogExtras`].
fn extras_key(
    atmosphere_hash: &str,
    spectral: &SpectralSettings,
    geometry: &FogGeometry,
    (quality, method): (Quality, Method),
    sampling: &Sampling,
) -> String {
    // The path tracer's key as before; the solver's names its resolution.
    let solver = match method {
        Method::MonteCarlo => serde_json::Value::Null,
        Method::Deterministic => deterministic_tag(quality, sampling).into(),
    };
    let key = serde_json::json!({
        "fog_extras": 1,
        "atmosphere": atmosphere_hash,
        "spectral": spectral,
        "geometry": geometry,
        "suns": FALLOFF_SUN_ZENITHS_DEG,
        "spp": falloff_spp(quality),
        "seed": BAKE_SEED,
        "build": crate::VERSION,
        "render_source": crate::RENDER_SOURCE,
    });
    let key = match solver {
        serde_json::Value::Null => key,
        tag => serde_json::json!({ "extras": key, "solver": tag }),
    };
    blake3::hash(key.to_string().as_bytes()).to_hex().to_string()
}

/// Where a sky's fog is rendered from.
pub struct FogJob<'a> {
    pub sky: &'a BasisSky,
    pub atmosphere: &'a Atmosphere,
    pub scene: &'a Scene,
    pub sampling: &'a Sampling,
    pub settings: FogSettings,
    pub quality: Quality,
    pub method: Method,
}

/// Renders (or finds in `cache`) the fog LUTs of one basis sky: each slice
/// not in the cache by `render(view, slice index)`, which returns the image
/// and its cost in core-seconds (the bake renders them in its queue,
/// before); `on_slice(done, total)` after each slice.
pub fn bake_fog(
    job: &FogJob,
    cache: &SliceCache,
    cancel: &AtomicBool,
    render: &dyn Fn(&View, usize) -> Result<(crate::render::Image, f64), BakeError>,
    on_slice: &dyn Fn(usize, usize),
) -> Result<SkyFog, BakeError> {
    let (sky, atm, scene) = (job.sky, job.atmosphere, job.scene);
    let spectral = &scene.spectral;
    let (radius_km, top_km) = (atm.planet.radius_km, atm.planet.top_km);
    let geometry = FogGeometry {
        planet_radius_km: radius_km,
        observer_altitude_km: sky.altitude_m / 1000.0,
        ceiling_km: job.settings.ceiling_km,
    };
    let mut fog = SkyFog {
        settings: job.settings,
        geometry,
        lit: Vec::new(),
        shadowed: Vec::new(),
        extras: extras(job, geometry, cache, cancel)?,
        rendered: 0,
        cached: 0,
        core_seconds: 0.0,
    };
    let total = sky.slices;
    for index in 0..sky.slices {
        if cancel.load(Ordering::SeqCst) {
            return Err(BakeError::Cancelled);
        }
        // The Shadowed Fog is the slice's only Monte Carlo; the Fog adds its
        // single scattering by quadrature (see `lit_of_shadowed`).
        let (view, key) = shadowed_view_and_key(
            sky,
            &job.settings,
            job.sampling,
            index,
            radius_km,
            top_km,
            &atm.content_hash,
            spectral,
            (job.quality, job.method),
        );
        let shadowed = match cache.get(&key) {
            Some(s) => {
                fog.cached += 1;
                s
            }
            None => {
                let (image, core_seconds) = render(&view, index)?;
                let slice =
                    slice_of_image(&image, &view, &format!("{} (shadowed fog)", sky.name), index, core_seconds)?;
                cache.put(&key, &slice)?;
                fog.rendered += 1;
                fog.core_seconds += slice.core_seconds;
                slice
            }
        };
        let shadowed = super::fog_resample::resample_shadowed(&shadowed, job.settings.width, job.settings.height);
        let lit_view = fog_view(sky, &job.settings, job.sampling, index, radius_km, top_km, false);
        // The Fog's key names the size its Shadowed Fog was rendered at and
        // the resampling's source.
        let lit_key = match job.sampling.fog_ms_size {
            None => slice_key(&atm.content_hash, spectral, &lit_view, job.quality.name()),
            Some([w, h]) => slice_key(
                &atm.content_hash,
                spectral,
                &lit_view,
                &format!("{} fog_ms_size {w}x{h} {}", job.quality.name(), env!("SKY_FOG_RESAMPLE_SOURCE")),
            ),
        };
        let lit = match cache.get(&lit_key) {
            Some(s) => s,
            None => {
                let slice = lit_of_shadowed(scene, &lit_view, &shadowed);
                cache.put(&lit_key, &slice)?;
                fog.core_seconds += slice.core_seconds;
                slice
            }
        };
        fog.lit.push(lit);
        fog.shadowed.push(shadowed);
        on_slice(fog.lit.len(), total);
    }
    Ok(fog)
}

/// The Fog slice of `lit_view` from the Shadowed Fog slice of the same
/// directions and sun: the two are drawn from the same paths (with single
/// scattering by quadrature the Fog's paths skip the first vertex's sun, as
/// the Shadowed Fog's do), so the Fog is the Shadowed Fog plus the
/// quadrature's single scattering of sunlight, texel by texel, with the
/// same standard error and samples. One render instead of two: at a fixed
/// sample count the result equals a render of `lit_view` to rounding
/// (tested); with adaptive sampling the Shadowed Fog's own error decides
/// the samples, which the Fog's smaller relative error only improves. Its
/// `core_seconds` are the quadrature's, on this process's threads.
pub fn lit_of_shadowed(scene: &Scene, lit_view: &View, shadowed: &RenderedSlice) -> RenderedSlice {
    let start = Instant::now();
    let single = crate::render::single_per_pixel(scene, lit_view);
    let xyz = shadowed.xyz.iter().zip(&single).map(|(s, q)| std::array::from_fn(|c| s[c] + q[c])).collect();
    RenderedSlice {
        xyz,
        core_seconds: start.elapsed().as_secs_f64() * rayon::current_num_threads() as f64,
        ..shadowed.clone()
    }
}

/// The falloff and the Attenuation table, from the cache or computed.
fn extras(
    job: &FogJob,
    geometry: FogGeometry,
    cache: &SliceCache,
    cancel: &AtomicBool,
) -> Result<FogExtras, BakeError> {
    let key = extras_key(
        &job.atmosphere.content_hash,
        &job.scene.spectral,
        &geometry,
        (job.quality, job.method),
        job.sampling,
    );
    if let Some(e) = cache.get_value::<FogExtras>(&key, "fog") {
        return Ok(e);
    }
    let (suns, spp) = (&FALLOFF_SUN_ZENITHS_DEG, falloff_spp(job.quality));
    let s = match job.method {
        Method::MonteCarlo => {
            study(job.scene, geometry, suns, spp, BAKE_SEED, cancel, &|| {}).map_err(|_| BakeError::Cancelled)?
        }
        // The references by the solver at the bake's resolution: the
        // falloff's suns (30 to 85°) are day, so a few seconds.
        Method::Deterministic => {
            let views = study_views_of(geometry, suns, spp, BAKE_SEED);
            let resolution = super::solver::resolution(job.quality, job.sampling);
            let images = crate::transport::render::render_views(job.scene, &views, &resolution, &|| {})
                .map_err(|error| BakeError::Solver { sky: job.sky.name.clone(), error })?;
            fit(geometry, suns, 0, &images)
        }
    };
    let e = FogExtras {
        falloff: s.falloff,
        fit_error: s.fit_error,
        depth_free_error: s.depth_free_error,
        attenuation: super::tables::attenuation_table(job.scene, geometry),
    };
    cache.put_value(&key, "fog", &e)?;
    Ok(e)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mie::MieCache;
    use crate::render::{render, SingleScatter};

    /// The Fog slice derived from the Shadowed Fog's render is what a
    /// render of the Fog's own view gives at the same fixed sample count:
    /// the same mean to rounding, the same noise and samples. So the bake
    /// renders each fog slice once. In a slab with a forward-peaked aerosol
    /// (Henyey–Greenstein) and Rayleigh air, under a 2 km ceiling, rays up,
    /// level and down, the sun high and low.
    #[test]
    fn the_fog_is_its_shadowed_fog_plus_the_quadratures_single_scattering() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/atmospheres/disort_rayleigh_hg.toml");
        let atm = Atmosphere::load(&path).unwrap();
        let spectral = crate::bake::run::spectral_settings(&Sampling {
            band_nm: 10.0,
            spp: 16,
            max_rel_error: None,
            ms_grid: None,
            fog_ms_size: None,
            streams: None,
        });
        let scene = Scene::new(&atm, &spectral, &MieCache::shared_by_tests(), &|| {});
        let cancel = AtomicBool::new(false);
        let dirs = vec![(30.0, 0.0), (60.0, 90.0), (88.0, 180.0), (90.0, 10.0), (93.0, 0.0), (120.0, 45.0)];
        for sun_zenith_deg in [40.0, 86.0] {
            let view = |shadowed| View {
                width: 3,
                height: 2,
                fog: Some(Fog { max_distance_km: f64::INFINITY, ceiling_km: Some(2.0), shadowed }),
                single_scatter: SingleScatter::Quadrature,
                ..View::directions(dirs.clone(), sun_zenith_deg, 0.0, 16, 7)
            };
            let (lit_view, shadowed_view) = (view(false), view(true));
            let shadowed =
                slice_of_image(&render(&scene, &shadowed_view, &cancel, &|| {}).unwrap(), &shadowed_view, "t", 0, 0.0)
                    .unwrap();
            let derived = lit_of_shadowed(&scene, &lit_view, &shadowed);
            let direct =
                slice_of_image(&render(&scene, &lit_view, &cancel, &|| {}).unwrap(), &lit_view, "t", 0, 0.0).unwrap();
            assert_eq!(derived.samples, direct.samples);
            for i in 0..6 {
                let (d, r) = (derived.xyz[i], direct.xyz[i]);
                assert!(
                    r[1] > shadowed.xyz[i][1] && shadowed.xyz[i][1] > 0.0,
                    "texel {i}: the sun's single scattering adds light ({r:?}, {:?})",
                    shadowed.xyz[i]
                );
                for c in 0..3 {
                    assert!(
                        (d[c] - r[c]).abs() <= 1e-9 * r[c],
                        "sun zenith {sun_zenith_deg}, texel {i}, channel {c}: derived {d:?}, rendered {r:?}"
                    );
                    let (ds, rs) = (derived.xyz_stderr[i][c], direct.xyz_stderr[i][c]);
                    assert!((ds - rs).abs() <= 1e-6 * rs + 1e-12 * r[c], "texel {i}: standard error {ds} against {rs}");
                }
            }
        }
    }
}
