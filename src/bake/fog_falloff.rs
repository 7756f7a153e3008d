//! The fit of the talk's fog falloff to reference fog renders ("a and p
//! are fitted using the reference fog results"): the path tracer's global
//! fog (`render::fog`) toward a set of directions, at normalised depths x
//! from 0.002 to 1 of `depth_max`, at several sun elevations; the falloff's
//! (a, p) fitted to the ratios Y(x) / Y(1) (`fog::Falloff::fit`), and its
//! error next to that of the depth-free alternative (the Fog LUT's value
//! at every depth, the talk's first attempt).

use crate::lut::fog::{falloff_theta, Falloff, FalloffSample, FogGeometry};
use crate::render::fog::Fog;
use crate::render::{render, Image, RenderError, Scene, View};
use serde::{Deserialize, Serialize};
use std::sync::atomic::AtomicBool;

/// View elevations of the study, degrees: the horizon's neighbourhood,
/// where terrain is, densely; the zenith sparsely.
pub const ELEVATIONS_DEG: [f64; 7] = [0.5, 2.0, 5.0, 10.0, 20.0, 45.0, 80.0];
/// View azimuths from the sun, degrees.
pub const AZIMUTHS_DEG: [f64; 3] = [0.0, 90.0, 180.0];
/// Normalised depths below 1 (1 itself is each curve's reference).
pub const DEPTHS_X: [f64; 7] = [0.002, 0.005, 0.02, 0.05, 0.15, 0.4, 0.7];

/// One reference fog curve: Y at each of [`DEPTHS_X`] over Y at x = 1.
#[derive(Debug, Clone, Serialize)]
pub struct FogCurve {
    pub sun_zenith_deg: f64,
    pub elevation_deg: f64,
    pub azimuth_from_sun_deg: f64,
    /// Y of the fog at full depth (x = 1), cd m⁻².
    pub full_y: f64,
    pub ratios: Vec<f64>,
}

/// Median and 99th percentile of relative errors.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ErrorSummary {
    pub median: f64,
    pub p99: f64,
}

impl ErrorSummary {
    pub fn of(mut e: Vec<f64>) -> ErrorSummary {
        e.sort_by(f64::total_cmp);
        let at = |q: f64| {
            if e.is_empty() {
                f64::NAN
            } else {
                e[((q * (e.len() - 1) as f64).round() as usize).min(e.len() - 1)]
            }
        };
        ErrorSummary { median: at(0.5), p99: at(0.99) }
    }
}

/// The fit and what it misses.
#[derive(Debug, Clone, Serialize)]
pub struct FalloffStudy {
    pub geometry: FogGeometry,
    pub falloff: Falloff,
    pub curves: Vec<FogCurve>,
    /// Relative error of the fitted falloff over every (curve, depth).
    pub fit_error: ErrorSummary,
    /// The same of the depth-free alternative (fraction 1 at every depth).
    pub depth_free_error: ErrorSummary,
    /// Samples per direction of the reference renders.
    pub spp: u32,
}

impl FalloffStudy {
    /// The samples the fit was made from.
    pub fn samples(&self) -> Vec<FalloffSample> {
        self.curves
            .iter()
            .flat_map(|c| {
                DEPTHS_X.iter().zip(&c.ratios).map(|(&x, &ratio)| FalloffSample {
                    x,
                    theta: falloff_theta(c.elevation_deg),
                    ratio,
                })
            })
            .collect()
    }
}

/// Renders the reference fog of `scene` under `geometry` at each sun
/// zenith angle (sun at azimuth 0) by the path tracer and fits the
/// falloff. `on_view` is called after each of the (suns × elevations ×
/// (depths + 1)) renders.
pub fn study(
    scene: &Scene,
    geometry: FogGeometry,
    sun_zenith_degs: &[f64],
    spp: u32,
    seed: u64,
    cancel: &AtomicBool,
    on_view: &(dyn Fn() + Sync),
) -> Result<FalloffStudy, RenderError> {
    let views = study_views_of(geometry, sun_zenith_degs, spp, seed);
    let images = views
        .iter()
        .map(|view| {
            let image = render(scene, view, cancel, &|| {})?;
            on_view();
            Ok(image)
        })
        .collect::<Result<Vec<Image>, RenderError>>()?;
    Ok(fit(geometry, sun_zenith_degs, spp, &images))
}

/// The reference views of [`study`], in the order [`fit`] reads their
/// images: by sun, view elevation, then the full depth (x = 1) and each of
/// [`DEPTHS_X`]; each of the [`AZIMUTHS_DEG`] at `spp` samples (for the
/// path tracer).
pub fn study_views_of(geometry: FogGeometry, sun_zenith_degs: &[f64], spp: u32, seed: u64) -> Vec<View> {
    let mut views = Vec::new();
    for &sun_zenith_deg in sun_zenith_degs {
        for &elevation_deg in &ELEVATIONS_DEG {
            let depth_max = geometry.depth_max_km(elevation_deg);
            let dirs: Vec<(f64, f64)> = AZIMUTHS_DEG.iter().map(|&a| (90.0 - elevation_deg, a)).collect();
            for x in std::iter::once(1.0).chain(DEPTHS_X) {
                let fog = Fog::lit(x * depth_max, Some(geometry.ceiling_km));
                views.push(View {
                    fog: Some(fog),
                    ..View::directions(dirs.clone(), sun_zenith_deg, geometry.observer_altitude_km * 1000.0, spp, seed)
                });
            }
        }
    }
    views
}

/// The falloff fitted to `images`, the renders of [`study_views_of`]
/// (`spp` recorded as the references' samples).
pub fn fit(geometry: FogGeometry, sun_zenith_degs: &[f64], spp: u32, images: &[Image]) -> FalloffStudy {
    let y = |image: &Image| -> Vec<f64> { image.pixels.iter().map(|p| p.xyz[1]).collect() };
    let mut curves = Vec::new();
    let mut images = images.iter();
    for &sun_zenith_deg in sun_zenith_degs {
        for &elevation_deg in &ELEVATIONS_DEG {
            let full = y(images.next().expect("an image per view"));
            let partial: Vec<Vec<f64>> =
                DEPTHS_X.iter().map(|_| y(images.next().expect("an image per view"))).collect();
            for (k, &azimuth_from_sun_deg) in AZIMUTHS_DEG.iter().enumerate() {
                let ratios = partial.iter().map(|ys| if full[k] > 0.0 { ys[k] / full[k] } else { f64::NAN }).collect();
                curves.push(FogCurve { sun_zenith_deg, elevation_deg, azimuth_from_sun_deg, full_y: full[k], ratios });
            }
        }
    }
    let mut s = FalloffStudy {
        geometry,
        falloff: Falloff { a: 0.0, p: 0.0 },
        curves,
        fit_error: ErrorSummary { median: 0.0, p99: 0.0 },
        depth_free_error: ErrorSummary { median: 0.0, p99: 0.0 },
        spp,
    };
    let samples = s.samples();
    s.falloff = Falloff::fit(&samples);
    s.fit_error = ErrorSummary::of(s.falloff.errors(&samples));
    s.depth_free_error = ErrorSummary::of(
        samples.iter().filter(|x| x.ratio > 0.0 && x.ratio.is_finite()).map(|x| (1.0 / x.ratio - 1.0).abs()).collect(),
    );
    s
}

/// How many renders [`study`] makes for `suns` sun elevations.
pub fn study_views(suns: usize) -> usize {
    suns * ELEVATIONS_DEG.len() * (DEPTHS_X.len() + 1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::atmosphere::Atmosphere;
    use crate::mie::MieCache;
    use crate::render::{SpectralSettings, WavelengthSampling};

    /// On the clear sky (3 km ceiling, sun 60°, 16 samples), the fitted
    /// falloff follows the reference fog far better than the depth-free
    /// LUT: its median relative error is under 15 %, and under a fifth of
    /// the depth-free one (which is at least 100 %: the fog within a few
    /// per cent of depth_max is a small part of the whole). The fog grows
    /// with depth in every curve (within the renders' noise).
    #[test]
    fn the_fitted_falloff_beats_the_depth_free_lut() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let atm = Atmosphere::load(&root.join("atmospheres/clear.toml")).unwrap();
        let spectral = SpectralSettings {
            band_nm: 40.0,
            wavelength_sampling: WavelengthSampling::Hero,
            spectral_nm: vec![],
            xyz: true,
        };
        let scene = Scene::new(&atm, &spectral, &MieCache::shared_by_tests(), &|| {});
        let g = FogGeometry { planet_radius_km: scene.medium.radius_km, observer_altitude_km: 0.0, ceiling_km: 3.0 };
        let s = study(&scene, g, &[60.0], 16, 1, &AtomicBool::new(false), &|| {}).unwrap();
        eprintln!("{:?}: fit {:?}, depth-free {:?}", s.falloff, s.fit_error, s.depth_free_error);
        for c in &s.curves {
            for w in c.ratios.windows(2) {
                assert!(w[1] > 0.9 * w[0], "{c:?}");
            }
        }
        assert!(s.fit_error.median < 0.15, "{:?}", s.fit_error);
        assert!(
            s.depth_free_error.median > 1.0 && s.fit_error.median < 0.2 * s.depth_free_error.median,
            "{:?} vs {:?}",
            s.fit_error,
            s.depth_free_error
        );
    }
}
