//! Packing the global-fog LUTs of a bake (`bake::fog`): `fog.ktx2`, the Fog
//! and Shadowed Fog LUTs of every basis sky as one RGBA16F 2-D array, and
//! `attenuation.ktx2`, the Attenuation LUT of every basis sky, a layer each.
//!
//! RGBA16F, not R11G11B10F: the Attenuation LUT is a transmittance the
//! decoder multiplies an object's radiance by, where R11G11B10F's 6-bit
//! mantissa (a rounding error up to 0.8 %) would show on every object; the
//! fog slices share its file format so that one loader reads both, and are
//! scaled per slice by a power of two as the sky's are (the largest channel
//! into (2^14, 2^15]; `pack::slice_scale_log2`), so twilight fog keeps its
//! precision.

use super::pack::slice_scale_log2;
use super::run::SkySlices;
use super::BakeError;
use crate::colour::ColourSpace;
use crate::lut::container::{self, Container};
use crate::lut::fog::ATTENUATION_SIZE;
use crate::lut::ktx2::{ArrayTexture, VK_FORMAT_R16G16B16A16_SFLOAT};
use crate::lut::manifest::{AttenuationEntry, FogEntry, FogSkyEntry};
use crate::lut::rgba16f;
use crate::lut::texels::Texels;
use std::path::Path;

/// What packing the fog produced, in memory.
pub struct PackedFog {
    entry: FogEntry,
    fog: Vec<[u16; 4]>,
    attenuation: Vec<[u16; 4]>,
}

/// The manifest's description of the Fog LUT's mapping.
pub const FOG_MAPPING: &str = "u = azimuth of the view from the sun's / 180 deg (the sky is mirror-symmetric about the sun's vertical plane: fold azimuths past 180), v = (elevation / 90 deg)^(1/2); views below the horizon read v = 0; texel i of n holds u or v = i / (n - 1)";

/// Packs the fog of every basis sky, or None when any sky has none (a
/// part of a bake).
pub fn pack_fog(skies: &[SkySlices], colour: ColourSpace) -> Result<Option<PackedFog>, BakeError> {
    let Some(fogs) = skies.iter().map(|s| s.fog.as_ref()).collect::<Option<Vec<_>>>() else { return Ok(None) };
    let Some(first) = fogs.first() else { return Ok(None) };
    let settings = first.settings;
    let m = colour.xyz_to_rgb();
    let (mut fog_texels, mut attenuation_texels, mut entries) = (Vec::new(), Vec::new(), Vec::new());
    let mut layer = 0;
    for (k, (s, f)) in skies.iter().zip(&fogs).enumerate() {
        let mut scales = [Vec::new(), Vec::new()];
        for (which, slices) in [&f.lit, &f.shadowed].into_iter().enumerate() {
            for (index, slice) in slices.iter().enumerate() {
                let (rgb, _) = colour.convert_array(&slice.xyz);
                let max = rgb.iter().flatten().copied().filter(|v| v.is_finite()).fold(0.0, f64::max);
                let scale_log2 = slice_scale_log2(max);
                let scale = (scale_log2 as f64).exp2();
                let scaled: Vec<[f64; 3]> = rgb.iter().map(|p| p.map(|c| c * scale)).collect();
                let what = if which == 0 { "fog RGB" } else { "shadowed fog RGB" };
                let (packed, _) = rgba16f::pack_array(&scaled).map_err(|e| BakeError::NotFinite {
                    sky: s.sky.name.clone(),
                    index,
                    u: e.texel % settings.width,
                    v: e.texel / settings.width,
                    what,
                })?;
                fog_texels.extend(packed);
                scales[which].push(scale_log2);
            }
        }
        let (packed, _) =
            rgba16f::pack_array(&f.extras.attenuation.channel_texels(&m)).map_err(|e| BakeError::NotFinite {
                sky: s.sky.name.clone(),
                index: 0,
                u: e.texel % ATTENUATION_SIZE,
                v: e.texel / ATTENUATION_SIZE,
                what: "attenuation",
            })?;
        attenuation_texels.extend(packed);
        let [fog_scale_log2, shadowed_scale_log2] = scales;
        entries.push(FogSkyEntry {
            name: s.sky.name.clone(),
            first_layer: layer,
            slices: f.lit.len(),
            observer_altitude_km: f.geometry.observer_altitude_km,
            planet_radius_km: f.geometry.planet_radius_km,
            falloff_a: f.extras.falloff.a,
            falloff_p: f.extras.falloff.p,
            falloff_error_median: f.extras.fit_error.median,
            falloff_error_p99: f.extras.fit_error.p99,
            depth_free_error_median: f.extras.depth_free_error.median,
            depth_free_error_p99: f.extras.depth_free_error.p99,
            fog_scale_log2,
            shadowed_scale_log2,
            sun_zenith_deg: f.lit.iter().map(|x| x.sun_zenith_deg).collect(),
            attenuation_layer: k,
        });
        layer += f.lit.len() + f.shadowed.len();
    }
    let entry = FogEntry {
        file: "fog.ktx2".into(),
        format: "R16G16B16A16_SFLOAT".into(),
        vk_format: VK_FORMAT_R16G16B16A16_SFLOAT,
        bytes: 0,
        width: settings.width,
        height: settings.height,
        layers: layer,
        layer_order: "per basis sky, in the order of skies: its Fog LUT's slices (first_layer + slice), then its Shadowed Fog LUT's (first_layer + slices + slice); slices follow the sky's time mapping (sun_zenith_deg)".into(),
        ceiling_km: settings.ceiling_km,
        mapping: FOG_MAPPING.into(),
        channels: "RGB: the light the air below ceiling_km scatters toward the observer along the view, to the ceiling or the ground (cd/m^2 as the sky's, value = stored * 2^-scale_log2 of the slice; the Shadowed Fog without the sunlight scattered once); A = 1. At run time: fog = mix(Fog, Shadowed Fog, cloud occlusion) * falloff(x), and the object's radiance is multiplied by the attenuation".into(),
        falloff: "fraction of the fog within depth x = depth / depth_max of the view: (1 - exp(-a theta^p x)) / (1 - exp(-a theta^p)), theta = max(elevation, 0.5 deg) / 90 deg (elevation below the horizon as 0), depth_max = the distance along the view from the observer (radius planet_radius_km + observer_altitude_km) to the sphere of radius planet_radius_km + ceiling_km".into(),
        attenuation: AttenuationEntry {
            file: "attenuation.ktx2".into(),
            format: "R16G16B16A16_SFLOAT".into(),
            vk_format: VK_FORMAT_R16G16B16A16_SFLOAT,
            bytes: 0,
            width: ATTENUATION_SIZE,
            height: ATTENUATION_SIZE,
            layers: skies.iter().map(|s| s.sky.name.clone()).collect(),
            mapping: "u = (depth / depth_max)^(1/3) (depth_max as in falloff), v = (elevation / 90 deg)^(1/2), views below the horizon read v = 0; texel i of n holds i / (n - 1)".into(),
            channels: "RGB: the transmittance of the air below the ceiling along the view to that depth, per channel of the manifest's colour space, for the sun's spectrum (no scale); A = 1".into(),
        },
        skies: entries,
    };
    Ok(Some(PackedFog { entry, fog: fog_texels, attenuation: attenuation_texels }))
}

impl PackedFog {
    /// Writes `dir/fog.ktx2` and `dir/attenuation.ktx2` (or `.dds`, each
    /// through a temporary file and a rename) and returns the manifest entry.
    pub fn write(self, (colour, container): (ColourSpace, Container), dir: &Path) -> Result<FogEntry, BakeError> {
        let mut e = self.entry;
        e.file = container.file_name("fog");
        e.attenuation.file = container.file_name("attenuation");
        let json =
            serde_json::to_string(&FogEntry { skies: Vec::new(), ..e.clone() }).expect("an entry always serialises");
        let tex = ArrayTexture {
            width: e.width as u32,
            height: e.height as u32,
            layers: e.layers as u32,
            colour_space: colour,
            texels: Texels::Rgba16f(&self.fog),
            sky_json: &json,
        };
        e.bytes = container::write(container, &dir.join(&e.file), &tex).map_err(BakeError::Write)?;
        let a = &e.attenuation;
        let json = serde_json::to_string(a).expect("an entry always serialises");
        let tex = ArrayTexture {
            width: a.width as u32,
            height: a.height as u32,
            layers: a.layers.len() as u32,
            colour_space: colour,
            texels: Texels::Rgba16f(&self.attenuation),
            sky_json: &json,
        };
        e.attenuation.bytes =
            container::write(container, &dir.join(&e.attenuation.file), &tex).map_err(BakeError::Write)?;
        Ok(e)
    }
}
