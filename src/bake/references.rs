//! The views `sky lut verify` compares a bake's decode with (`study::verify`
//! and `study::verify_fog`): per basis sky, a lattice of directions at sun
//! elevations between slices and at slice centres, and the global fog in
//! front of objects at five depths. A deterministic bake renders them in
//! the same solution as its slices (`solver::render_strips`: every
//! wavelength solved once for both) and caches them, so that `sky lut
//! verify` with its default reference and options reads them instead of
//! solving each sky again (the demo's verification took 6.5 minutes, most
//! of it the solutions). A view renders the same alone or with others
//! (`transport::render::render_views`), so the cached references are what
//! the verification would render (to about 1e-9 at twilight: a bake's
//! suns beyond 99° widen the spherical iteration's grid of columns).

use super::cache::{CacheError, SliceCache};
use crate::directions::mapping;
use crate::render::fog::Fog;
use crate::render::{Image, PixelResult, SpectralSettings, View};

/// Sun elevations between slices, degrees.
pub const BETWEEN_SLICES_DEG: [f64; 7] = [41.7, 23.3, 8.2, 3.1, 0.4, -2.7, -7.5];

/// Slice-centre elevations are taken from these slice indices.
pub const CENTRE_SLICES: [usize; 6] = [10, 30, 44, 47, 52, 60];

/// Directions of the lattice above the horizon (`stats::sky_lattice`).
pub const DIRECTIONS: usize = 400;

/// The seed of path-traced reference renders (not the bake's:
/// independent noise).
pub const REFERENCE_SEED: u64 = 0x0ef0_5eed;

/// Sun elevations of the fog's references, degrees: between slices (day,
/// low sun, sunset).
pub const FOG_SUN_ELEVATIONS_DEG: [f64; 3] = [41.7, 8.2, 0.4];
/// Object depths, km.
pub const FOG_DEPTHS_KM: [f64; 5] = [0.1, 1.0, 5.0, 20.0, 50.0];
/// View elevations, degrees (the terrain's neighbourhood densely).
pub const FOG_VIEW_ELEVATIONS_DEG: [f64; 5] = [0.7, 2.5, 6.0, 15.0, 40.0];
/// View azimuths from the sun, degrees.
pub const FOG_VIEW_AZIMUTHS_DEG: [f64; 3] = [20.0, 100.0, 170.0];

/// One basis sky's reference views.
#[derive(Debug, Clone)]
pub struct ReferenceViews {
    /// Each sky view's sun elevation (degrees) and whether it is a slice's
    /// centre.
    pub elevations: Vec<(f64, bool)>,
    /// The lattice at each of `elevations`.
    pub sky: Vec<View>,
    /// By sun of [`FOG_SUN_ELEVATIONS_DEG`], depth of [`FOG_DEPTHS_KM`],
    /// then the Fog and the Shadowed Fog; each of the 15 directions of
    /// [`FOG_VIEW_ELEVATIONS_DEG`] x [`FOG_VIEW_AZIMUTHS_DEG`]. None
    /// without a fog ceiling.
    pub fog: Vec<View>,
}

impl ReferenceViews {
    /// The views of a sky seen from `altitude_m` on a planet of
    /// `radius_km` whose atmosphere ends at `top_km`: `directions` of the
    /// lattice at [`BETWEEN_SLICES_DEG`] and at the centres of
    /// `centre_slices`, and the fog under `fog_ceiling_km`; `spp` and
    /// `fog_spp` samples a direction for the path tracer.
    pub fn new(
        (radius_km, top_km, altitude_m): (f64, f64, f64),
        (directions, centre_slices): (usize, &[usize]),
        (spp, fog_spp): (u32, u32),
        fog_ceiling_km: Option<f64>,
    ) -> ReferenceViews {
        let mut elevations: Vec<(f64, bool)> = BETWEEN_SLICES_DEG.iter().map(|&e| (e, false)).collect();
        for &i in centre_slices {
            elevations.push((90.0 - mapping::slice_sun_zenith_deg(i, radius_km, top_km), true));
        }
        let dirs = crate::stats::sky_lattice(directions);
        let sky = elevations
            .iter()
            .map(|&(elev, _)| View::directions(dirs.clone(), 90.0 - elev, altitude_m, spp, REFERENCE_SEED))
            .collect();
        let mut fog = Vec::new();
        if let Some(ceiling_km) = fog_ceiling_km {
            for &sun_elevation in &FOG_SUN_ELEVATIONS_DEG {
                for &depth in &FOG_DEPTHS_KM {
                    for shadowed in [false, true] {
                        let f = Fog { max_distance_km: depth, ceiling_km: Some(ceiling_km), shadowed };
                        fog.push(View {
                            fog: Some(f),
                            ..View::directions(
                                fog_directions(),
                                90.0 - sun_elevation,
                                altitude_m,
                                fog_spp,
                                REFERENCE_SEED,
                            )
                        });
                    }
                }
            }
        }
        ReferenceViews { elevations, sky, fog }
    }

    /// The sky's views, then the fog's.
    pub fn all(&self) -> Vec<View> {
        self.sky.iter().chain(&self.fog).cloned().collect()
    }

    /// The cache key of the solver's renders of these views for the
    /// atmosphere of `atmosphere_hash` at `spectral`, solved as `tag`
    /// says (`slices::deterministic_tag`). The views' samples and seed
    /// are left out: the solver has neither.
    pub fn key(&self, atmosphere_hash: &str, spectral: &SpectralSettings, tag: &str) -> String {
        let views: Vec<View> = self.all().into_iter().map(|v| View { spp: 0, seed: 0, ..v }).collect();
        let key = serde_json::json!({
            "verify_references": 1,
            "atmosphere": atmosphere_hash,
            "spectral": spectral,
            "views": views,
            "solver": tag,
            "build": crate::VERSION,
            "render_source": crate::RENDER_SOURCE,
        });
        blake3::hash(key.to_string().as_bytes()).to_hex().to_string()
    }
}

/// The fog's reference directions: (zenith, azimuth from the sun), degrees.
pub fn fog_directions() -> Vec<(f64, f64)> {
    FOG_VIEW_ELEVATIONS_DEG.iter().flat_map(|&e| FOG_VIEW_AZIMUTHS_DEG.iter().map(move |&a| (90.0 - e, a))).collect()
}

/// The cache's file extension for references.
const KIND: &str = "references";

/// The solver's renders under `key`, if the cache holds them for views of
/// these sizes.
pub fn cached(cache: &SliceCache, key: &str, views: &[View]) -> Option<Vec<Image>> {
    let xyz: Vec<Vec<[f64; 3]>> = cache.get_value(key, KIND)?;
    let sizes_match = xyz.len() == views.len() && xyz.iter().zip(views).all(|(x, v)| x.len() == v.width * v.height);
    sizes_match.then(|| {
        xyz.into_iter()
            .zip(views)
            .map(|(x, v)| Image {
                width: v.width,
                height: v.height,
                pixels: x.into_iter().map(PixelResult::from_xyz).collect(),
            })
            .collect()
    })
}

/// Stores the solver's renders under `key` (their XYZ: the solver has no
/// standard error).
pub fn store(cache: &SliceCache, key: &str, images: &[Image]) -> Result<(), CacheError> {
    let xyz: Vec<Vec<[f64; 3]>> = images.iter().map(|i| i.pixels.iter().map(|p| p.xyz).collect()).collect();
    cache.put_value(key, KIND, &xyz)
}
