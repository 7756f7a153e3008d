//! The reference decoder of the global-fog LUTs (`bake::pack_fog`): what
//! a runtime does, on the CPU, to put fog in front of an object at some
//! depth along a view. Per basis sky the weather rule weights: the Fog and
//! Shadowed Fog LUTs read at the view's (u, v) (`lut::fog`'s mapping,
//! bilinear between texel centres), each slice's scale undone, the two
//! blended by the cloud occlusion (the talk: "interpolated with Fog LUT
//! using the cloud occlusion"), the two slices of the sun interpolated as
//! the sky's are (`decode::slice_pair`, `decode::between_slices`), times
//! the falloff of the object's normalised depth; and the Attenuation LUT at
//! (depth, elevation). Then the basis skies are blended.
//!
//! The object's radiance as seen is `object * attenuation + fog`.

use super::decode::{between_slices, slice_pair, Luts};
use super::fog::{attenuation_uv, bilinear_by, falloff_theta, fog_uv, Falloff, FogGeometry};
use super::manifest::FogSkyEntry;
use super::weather::{basis_weights, BASIS};
use glam::DVec3;

/// The fog files' layers, as stored (before the slices' scales).
#[derive(Debug, Clone)]
pub struct FogTextures {
    /// `fog.ktx2`: every basis sky's Fog, then Shadowed Fog slices.
    pub fog: Vec<Vec<[f32; 3]>>,
    /// `attenuation.ktx2`: a layer per basis sky.
    pub attenuation: Vec<Vec<[f32; 3]>>,
}

/// Fog in front of an object, decoded: linear RGB of the manifest's space.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct FogSample {
    /// The light the air adds in front of the object (cd/m² as the sky's).
    pub inscatter_rgb: [f64; 3],
    /// What the object's own radiance is multiplied by.
    pub attenuation_rgb: [f64; 3],
    /// The object's depth over the distance to the fog's ceiling along the view.
    pub normalised_depth: f64,
}

impl Luts {
    /// The fog toward `dir` (world frame, z up) in front of an object at
    /// `depth_km`, for a sun at `sun_elevation_deg` and `sun_azimuth_deg`,
    /// haziness and cloudiness in [0, 1], and cloud occlusion in [0, 1] (0:
    /// the air is sunlit, 1: clouds shade it); None for a bake without fog.
    #[allow(clippy::too_many_arguments)]
    pub fn fog(
        &self,
        sun_elevation_deg: f64,
        sun_azimuth_deg: f64,
        haziness: f64,
        cloudiness: f64,
        dir: DVec3,
        depth_km: f64,
        cloud_occlusion: f64,
    ) -> Option<FogSample> {
        self.manifest.fog.as_ref()?;
        let w = basis_weights(haziness, cloudiness);
        let (mut inscatter, mut attenuation, mut present, mut x) = ([0.0; 3], [0.0; 3], 0.0, 0.0);
        for (k, name) in BASIS.iter().enumerate() {
            if w[k] == 0.0 {
                continue;
            }
            let Some(f) = self.fog_of_sky(name, sun_elevation_deg, sun_azimuth_deg, dir, depth_km, cloud_occlusion)
            else {
                continue;
            };
            present += w[k];
            x = f.normalised_depth;
            for c in 0..3 {
                inscatter[c] += w[k] * f.inscatter_rgb[c];
                attenuation[c] += w[k] * f.attenuation_rgb[c];
            }
        }
        if present > 0.0 && present < 1.0 {
            inscatter = inscatter.map(|v| v / present);
            attenuation = attenuation.map(|v| v / present);
        }
        Some(FogSample { inscatter_rgb: inscatter, attenuation_rgb: attenuation, normalised_depth: x })
    }

    /// [`Luts::fog`] of one basis sky alone (None if the bake has no fog
    /// for a sky of that name).
    pub fn fog_of_sky(
        &self,
        name: &str,
        sun_elevation_deg: f64,
        sun_azimuth_deg: f64,
        dir: DVec3,
        depth_km: f64,
        cloud_occlusion: f64,
    ) -> Option<FogSample> {
        let (entry, textures) = (self.manifest.fog.as_ref()?, self.fog.as_ref()?);
        let sky = self.manifest.skies.iter().find(|s| s.name == name)?;
        let f = entry.skies.iter().find(|s| s.name == name)?;
        let d = dir.normalize();
        let elevation_deg = libm::asin(d.z.clamp(-1.0, 1.0)).to_degrees();
        let (u, v) = fog_uv(elevation_deg, libm::atan2(d.y, d.x).to_degrees() - sun_azimuth_deg);
        let occlusion = cloud_occlusion.clamp(0.0, 1.0);
        let read = |layer: usize, scale_log2: i32| -> [f64; 3] {
            let texels = &textures.fog[layer];
            let s = (-scale_log2 as f64).exp2();
            bilinear_by(|i| texels[i].map(f64::from), entry.width, entry.height, u, v).map(|c| c * s)
        };
        let slice = |i: usize| -> [f64; 3] {
            let lit = read(f.first_layer + i, f.fog_scale_log2[i]);
            let shadowed = read(f.first_layer + f.slices + i, f.shadowed_scale_log2[i]);
            std::array::from_fn(|c| (1.0 - occlusion) * lit[c] + occlusion * shadowed[c])
        };
        let (i0, i1, t) = slice_pair(sky, 90.0 - sun_elevation_deg);
        let (a, b) = (slice(i0), slice(i1));
        let geometry = geometry_of(f, entry.ceiling_km);
        let x = (depth_km / geometry.depth_max_km(elevation_deg)).clamp(0.0, 1.0);
        let fraction = Falloff { a: f.falloff_a, p: f.falloff_p }.fraction(x, falloff_theta(elevation_deg));
        let (ua, va) = attenuation_uv(&geometry, depth_km, elevation_deg);
        let layer = &textures.attenuation[f.attenuation_layer];
        let attenuation_rgb =
            bilinear_by(|i| layer[i].map(f64::from), entry.attenuation.width, entry.attenuation.height, ua, va);
        let inscatter_rgb = std::array::from_fn(|c| between_slices(a[c], b[c], t) * fraction);
        Some(FogSample { inscatter_rgb, attenuation_rgb, normalised_depth: x })
    }
}

/// The geometry a sky's fog entry describes.
pub fn geometry_of(f: &FogSkyEntry, ceiling_km: f64) -> FogGeometry {
    FogGeometry { planet_radius_km: f.planet_radius_km, observer_altitude_km: f.observer_altitude_km, ceiling_km }
}
