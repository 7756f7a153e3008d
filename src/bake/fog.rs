//! The global-fog LUTs of a basis sky (issue 13; `lut::fog` has the
//! mappings): the Fog LUT and the Shadowed Fog LUT, one slice per sun
//! elevation of the sky's time mapping, rendered by the path tracer
//! (`render::fog`: the air below the bake's ceiling scattering toward the
//! camera, to the ceiling or the ground); the Attenuation LUT (no Monte
//! Carlo); and the depth falloff's (a, p), fitted to reference fog renders
//! (`lut::fog_falloff`).
//!
//! Slices are cached like the sky's (the key is the view, which names the
//! fog), the falloff and the Attenuation table under a key of their own, so
//! a re-run renders nothing and a stopped bake resumes at the slice it was
//! on. The slices render through the bake's session (the embedded worker or
//! `sky worker` daemons), one farm job a slice, after the sky's slices; the
//! falloff's references and the Attenuation table on this process.

use super::cache::{slice_key, RenderedSlice, SliceCache};
use super::file::{BasisSky, FogSettings, Quality, Sampling};
use super::run::{slice_of_image, BAKE_SEED};
use super::BakeError;
use crate::atmosphere::Atmosphere;
use crate::lut::fog::{fog_texel_view, AttenuationTable, Falloff, FogGeometry};
use crate::lut::fog_falloff::{study, ErrorSummary};
use crate::lut::mapping;
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
pub fn fog_view(sky: &BasisSky, fog: &FogSettings, s: &Sampling, index: usize, radius_km: f64, top_km: f64, shadowed: bool) -> View {
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
    let sun_zenith_deg = mapping::slice_sun_zenith_deg(index, radius_km, top_km);
    // A w x h grid of directions (the camera reads pixel y * w + x).
    View { width: w, height: h, max_rel_error: s.max_rel_error, fog: Some(fog), ..View::directions(dirs, sun_zenith_deg, sky.altitude_m, s.spp, BAKE_SEED) }
}

/// The cache key of a basis sky's [`FogExtras`].
fn extras_key(atmosphere_hash: &str, spectral: &SpectralSettings, geometry: &FogGeometry, quality: Quality) -> String {
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
}

/// Renders (or finds in `cache`) the fog LUTs of one basis sky: each slice
/// not in the cache by `render(view, slice index)` (the bake's session:
/// the embedded worker or the farm); `on_slice(done, total)` after each
/// slice. A slice's cost is its render's wall time on the bake's cores.
pub fn bake_fog(
    job: &FogJob,
    cache: &SliceCache,
    cancel: &AtomicBool,
    render: &dyn Fn(&View, usize) -> Result<crate::render::Image, BakeError>,
    on_slice: &dyn Fn(usize, usize),
) -> Result<SkyFog, BakeError> {
    let (sky, atm, scene) = (job.sky, job.atmosphere, job.scene);
    let spectral = &scene.spectral;
    let (radius_km, top_km) = (atm.planet.radius_km, atm.planet.top_km);
    let geometry = FogGeometry { planet_radius_km: radius_km, observer_altitude_km: sky.altitude_m / 1000.0, ceiling_km: job.settings.ceiling_km };
    let mut fog = SkyFog { settings: job.settings, geometry, lit: Vec::new(), shadowed: Vec::new(), extras: extras(job, geometry, cache, cancel)?, rendered: 0, cached: 0, core_seconds: 0.0 };
    let total = 2 * sky.slices;
    let threads = rayon::current_num_threads() as f64;
    for index in 0..sky.slices {
        for shadowed in [false, true] {
            if cancel.load(Ordering::SeqCst) {
                return Err(BakeError::Cancelled);
            }
            let view = fog_view(sky, &job.settings, job.sampling, index, radius_km, top_km, shadowed);
            let key = slice_key(&atm.content_hash, spectral, &view, job.quality.name());
            let slice = match cache.get(&key) {
                Some(s) => {
                    fog.cached += 1;
                    s
                }
                None => {
                    let start = Instant::now();
                    let image = render(&view, index)?;
                    let what = if shadowed { "shadowed fog" } else { "fog" };
                    let slice = slice_of_image(&image, &view, &format!("{} ({what})", sky.name), index, start.elapsed().as_secs_f64() * threads)?;
                    cache.put(&key, &slice)?;
                    fog.rendered += 1;
                    fog.core_seconds += slice.core_seconds;
                    slice
                }
            };
            if shadowed {
                fog.shadowed.push(slice);
            } else {
                fog.lit.push(slice);
            }
            on_slice(fog.lit.len() + fog.shadowed.len(), total);
        }
    }
    Ok(fog)
}

/// The falloff and the Attenuation table, from the cache or computed.
fn extras(job: &FogJob, geometry: FogGeometry, cache: &SliceCache, cancel: &AtomicBool) -> Result<FogExtras, BakeError> {
    let key = extras_key(&job.atmosphere.content_hash, &job.scene.spectral, &geometry, job.quality);
    if let Some(e) = cache.get_value::<FogExtras>(&key, "fog") {
        return Ok(e);
    }
    let s = study(job.scene, geometry, &FALLOFF_SUN_ZENITHS_DEG, falloff_spp(job.quality), BAKE_SEED, cancel, &|| {}).map_err(|_| BakeError::Cancelled)?;
    let e = FogExtras { falloff: s.falloff, fit_error: s.fit_error, depth_free_error: s.depth_free_error, attenuation: AttenuationTable::compute(job.scene, geometry) };
    cache.put_value(&key, "fog", &e)?;
    Ok(e)
}
