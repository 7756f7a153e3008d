//! `sky lut verify` of the global-fog LUTs (issue 13): the decoded fog of
//! each basis sky against direct renders of the same fog (`render::fog`)
//! in front of objects at depths from 100 m to 50 km, toward views from
//! the horizon up and around the sun, with suns between slices; the
//! Shadowed Fog likewise (cloud occlusion 1); and the decoded attenuation
//! against the quadrature's transmittance of the same rays. Each is
//! summarised by the median and 99th percentile relative error of Y.

use crate::directions::camera::direction_deg;
use crate::lut::decode::Luts;
use crate::render::Image;
use crate::session::Session;
use crate::stats::percentile;

pub use crate::bake::references::{
    fog_directions, FOG_DEPTHS_KM, FOG_SUN_ELEVATIONS_DEG, FOG_VIEW_AZIMUTHS_DEG, FOG_VIEW_ELEVATIONS_DEG,
};

/// Median and 99th percentile of a relative error.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct Spread {
    pub median: f64,
    pub p99: f64,
    pub count: usize,
}

impl Spread {
    fn of(mut v: Vec<f64>) -> Spread {
        Spread { median: percentile(&mut v.clone(), 0.5), p99: percentile(&mut v, 0.99), count: v.len() }
    }
}

/// One basis sky's fog against its references.
#[derive(Debug, Clone, serde::Serialize)]
pub struct FogVerification {
    /// The decoded fog (cloud occlusion 0) against rendered fog, Y.
    pub fog: Spread,
    /// The decoded Shadowed Fog (occlusion 1) against rendered Shadowed Fog.
    pub shadowed: Spread,
    /// The decoded attenuation's Y-channel against the quadrature's.
    pub attenuation: Spread,
    /// The references' median relative standard error of Y.
    pub reference_noise: f64,
    /// The fog's errors by depth (median, in the order of [`FOG_DEPTHS_KM`]).
    pub fog_median_by_depth: Vec<f64>,
}

/// Verifies the fog of the basis sky `name` against `images`, the renders
/// of its fog's reference views (`bake::references::ReferenceViews::fog`;
/// None if the bake has no fog for it).
pub fn fog_errors(luts: &Luts, name: &str, session: &Session, images: &[Image]) -> Option<FogVerification> {
    let entry = luts.manifest.fog.as_ref()?;
    let f = entry.skies.iter().find(|s| s.name == name)?;
    let geometry = crate::lut::decode_fog::geometry_of(f, entry.ceiling_km);
    let dirs = fog_directions();
    let y = |rgb: [f64; 3]| crate::colour::apply(&luts.manifest.colour.xyz_from_rgb, rgb)[1];
    let (mut lit, mut shadowed, mut noise) = (Vec::new(), Vec::new(), Vec::new());
    let mut by_depth = vec![Vec::new(); FOG_DEPTHS_KM.len()];
    let mut images = images.iter();
    for &sun_elevation in &FOG_SUN_ELEVATIONS_DEG {
        for (k, &depth) in FOG_DEPTHS_KM.iter().enumerate() {
            for shadow in [false, true] {
                let image = images.next().expect("an image per reference view");
                for (p, &(z, a)) in image.pixels.iter().zip(&dirs) {
                    let want = p.xyz[1];
                    if !(want > 0.0) {
                        continue;
                    }
                    noise.push(p.xyz_stderr[1] / want);
                    let occlusion = if shadow { 1.0 } else { 0.0 };
                    let Some(got) = luts.fog_of_sky(name, sun_elevation, 0.0, direction_deg(z, a), depth, occlusion)
                    else {
                        continue;
                    };
                    let e = (y(got.inscatter_rgb) - want).abs() / want;
                    if shadow {
                        shadowed.push(e);
                    } else {
                        lit.push(e);
                        by_depth[k].push(e);
                    }
                }
            }
        }
    }
    let m = luts.manifest.colour.rgb_from_xyz;
    let mut attenuation = Vec::new();
    for &elevation in &FOG_VIEW_ELEVATIONS_DEG {
        for &depth in &FOG_DEPTHS_KM {
            let want = y(crate::bake::tables::direct_attenuation_rgb(&session.scene, &geometry, depth, elevation, &m));
            let Some(got) = luts.fog_of_sky(name, 30.0, 0.0, direction_deg(90.0 - elevation, 0.0), depth, 0.0) else {
                continue;
            };
            if want > 1e-3 {
                attenuation.push((y(got.attenuation_rgb) - want).abs() / want);
            }
        }
    }
    Some(FogVerification {
        fog: Spread::of(lit),
        shadowed: Spread::of(shadowed),
        attenuation: Spread::of(attenuation),
        reference_noise: percentile(&mut noise, 0.5),
        fog_median_by_depth: by_depth.into_iter().map(|mut v| percentile(&mut v, 0.5)).collect(),
    })
}
