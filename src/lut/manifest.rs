//! The manifest of a bake (`manifest.json`): what a runtime needs to use
//! the LUT files without reading this code. Versioned: a reader refuses a
//! major version it does not know; fields are only added within one.
//! Documented in the README ("The LUT manifest").

use serde::{Deserialize, Serialize};

/// The manifest's format name and version. Version 2: between slices the
/// decoder interpolates geometrically where both values are positive, at
/// the fraction of the way in sun zenith angle (version 1: linearly, at the
/// fraction of the slice coordinate), see `decode::between_slices`.
pub const FORMAT: &str = "sky-lut-manifest";
pub const VERSION: u32 = 2;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub format: String,
    pub version: u32,
    /// "sky 0.1.0".
    pub generator: String,
    /// "draft" or "final".
    pub quality: String,
    /// How the sky slices' light was computed: "deterministic" (the
    /// transport solver) or "monte-carlo" (the path tracer). Added within
    /// version 2; absent from bakes made before it, all "monte-carlo".
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub method: Option<String>,
    /// The texture files' container: "ktx2" or "dds" (`lut::container`;
    /// added within version 2, absent: "ktx2").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub container: Option<String>,
    /// What a decoded texel means.
    pub units: Units,
    pub colour: Colour,
    pub time_mapping: TimeMapping,
    pub direction_mapping: DirectionMappingInfo,
    pub weather: Weather,
    /// The basis skies in the talk's order.
    pub skies: Vec<SkyEntry>,
    /// The sun's transmittance table of every basis sky (added in version
    /// 2; absent from bakes made before it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub transmittance: Option<TransmittanceEntry>,
    /// The global-fog LUTs of every basis sky (added within version 2;
    /// absent from bakes made before them).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fog: Option<FogEntry>,
    /// The skies' ambient light per slice as a texture (added within
    /// version 2; the same numbers as each sky's `ambient`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ambient_file: Option<AmbientFileEntry>,
    /// Every file the manifest names, with its size and SHA-256 (added
    /// within version 2; `lut::integrity` checks them before a bake is
    /// used).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub files: Option<Vec<FileEntry>>,
    /// The SHA-256 of this manifest's own text with these 64 hex digits
    /// written as zeros (`lut::integrity::seal`); the last field. Added
    /// within version 2, with `files`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub manifest_sha256: Option<String>,
}

/// A file of the bake: its name (relative to the manifest), size and
/// SHA-256 (lower-case hex, as `sha256sum` prints it).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct FileEntry {
    pub file: String,
    pub bytes: u64,
    pub sha256: String,
}

impl Manifest {
    /// Every file this manifest names, in the order it names them.
    pub fn named_files(&self) -> Vec<&str> {
        let mut names: Vec<&str> = self.skies.iter().map(|s| s.file.as_str()).collect();
        names.extend(self.transmittance.iter().map(|t| t.file.as_str()));
        if let Some(f) = &self.fog {
            names.extend([f.file.as_str(), f.attenuation.file.as_str()]);
        }
        names.extend(self.ambient_file.iter().map(|a| a.file.as_str()));
        names
    }
}

/// `ambient.ktx2`: per basis sky a layer of 64 columns (slices) by 11 rows
/// (irradiance on an upward surface, mean radiance of the upper
/// hemisphere, and the nine spherical-harmonic coefficients L00, L1-1,
/// L10, L11, L2-2, L2-1, L20, L21, L22), RGBA16F with signed halves.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AmbientFileEntry {
    pub file: String,
    pub format: String,
    pub vk_format: u32,
    pub bytes: u64,
    pub width: usize,
    pub height: usize,
    /// The basis sky of each layer.
    pub layers: Vec<String>,
    pub rows: Vec<String>,
    /// Per layer: value = stored * 2^-scale_log2.
    pub scale_log2: Vec<i32>,
}

/// The global-fog LUTs (`lut::fog`, `bake::fog`): the Fog and Shadowed Fog
/// LUTs of every basis sky in one RGBA16F 2-D array, and the Attenuation
/// LUTs in another.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FogEntry {
    pub file: String,
    /// "R16G16B16A16_SFLOAT" (vkFormat 97).
    pub format: String,
    pub vk_format: u32,
    pub bytes: u64,
    pub width: usize,
    pub height: usize,
    pub layers: usize,
    /// Which layer holds what.
    pub layer_order: String,
    /// Only the air below this altitude makes fog, km.
    pub ceiling_km: f64,
    /// How a texel's (u, v) maps to a view direction.
    pub mapping: String,
    /// What a texel holds and how to apply it at a depth.
    pub channels: String,
    pub falloff: String,
    pub attenuation: AttenuationEntry,
    /// In the order of `skies`.
    pub skies: Vec<FogSkyEntry>,
}

/// The Attenuation LUT file: a layer per basis sky.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AttenuationEntry {
    pub file: String,
    pub format: String,
    pub vk_format: u32,
    pub bytes: u64,
    pub width: usize,
    pub height: usize,
    /// The basis sky of each layer.
    pub layers: Vec<String>,
    pub mapping: String,
    pub channels: String,
}

/// One basis sky's fog.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FogSkyEntry {
    pub name: String,
    /// Its Fog LUT's slice 0; the Shadowed Fog LUT's slice 0 is
    /// `first_layer + slices`.
    pub first_layer: usize,
    pub slices: usize,
    pub observer_altitude_km: f64,
    pub planet_radius_km: f64,
    pub falloff_a: f64,
    pub falloff_p: f64,
    /// The falloff's relative error against its reference fog renders.
    pub falloff_error_median: f64,
    pub falloff_error_p99: f64,
    /// The same of the depth-free alternative (the LUT at every depth).
    pub depth_free_error_median: f64,
    pub depth_free_error_p99: f64,
    /// Per slice: stored = value * 2^scale_log2.
    pub fog_scale_log2: Vec<i32>,
    pub shadowed_scale_log2: Vec<i32>,
    /// Sun zenith angle of each slice, degrees (the sky's time mapping).
    pub sun_zenith_deg: Vec<f64>,
    pub attenuation_layer: usize,
}

/// The transmittance LUT file: one RGBA16F 2-D array, a layer per basis
/// sky (`lut::transmittance`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TransmittanceEntry {
    pub file: String,
    /// "R16G16B16A16_SFLOAT" (vkFormat 97).
    pub format: String,
    pub vk_format: u32,
    pub bytes: u64,
    pub width: usize,
    pub height: usize,
    /// The basis sky of each layer.
    pub layers: Vec<String>,
    /// How a texel's (u, v) maps to (radius, cosine of the zenith angle).
    pub mapping: String,
    /// What the channels hold.
    pub channels: String,
}

/// The sun of one basis sky: what the sky texture leaves out.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SunEntry {
    /// Full angular diameter of the disk, degrees.
    pub angular_diameter_deg: f64,
    /// Solid angle of the disk, sr: disk radiance = irradiance / this.
    pub solid_angle_sr: f64,
    /// The sun's irradiance above the atmosphere on a surface facing it:
    /// CIE XYZ (lux) and linear RGB of the manifest's colour space.
    pub top_irradiance_xyz: [f64; 3],
    pub top_irradiance_rgb: [f64; 3],
    /// The layer of the transmittance file that is this sky's.
    pub transmittance_layer: usize,
    /// Per slice: the irradiance at the observer (XYZ in lux, and RGB),
    /// 0 once the sun is below the horizon.
    pub irradiance_xyz: Vec<[f64; 3]>,
    pub irradiance_rgb: Vec<[f64; 3]>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Units {
    /// "cd/m^2": Y of CIE 1931 XYZ times 683 lm/W.
    pub luminance: String,
    /// How a stored texel becomes a value: value = stored * 2^-scale_log2 of its slice,
    /// applied to each slice before slices are interpolated.
    pub scale: String,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Colour {
    /// "rec709", "rec2020", "acescg" or "xyz".
    pub space: String,
    /// Linear RGB = matrix · XYZ, rows R, G, B.
    pub rgb_from_xyz: [[f64; 3]; 3],
    pub xyz_from_rgb: [[f64; 3]; 3],
    pub note: String,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TimeMapping {
    pub slices: usize,
    pub upper_slices: usize,
    pub lower_slices: usize,
    /// Upper region: d_i = lerp(d_min, d_max, i / (upper_slices - 1)), the sun
    /// zenith angle the one whose path from the ground to the top is d_i.
    pub upper: String,
    /// Lower region: θ_z = lerp(90°, lowest, ((i - upper_slices) / (lower_slices - 1))^2).
    pub lower: String,
    pub lowest_sun_zenith_deg: f64,
    /// What a decoder does for a sun lower than the lowest slice.
    pub below_lowest: String,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DirectionMappingInfo {
    /// Texel (x, y) of a layer is the cell centred on (u, v) = ((x + 0.5) / width, (y + 0.5) / height).
    pub texels: String,
    /// The frame: z the zenith, the sun at azimuth 0 in the x-z plane.
    pub frame: String,
    /// u covers the half y ≥ 0; a direction with y < 0 reads its mirror image.
    pub u_mirror: bool,
    /// The sun-centred mapping's nonlinear v transform: knots a, b and their images c, d, exponent p.
    pub a: f64,
    pub b: f64,
    pub c: f64,
    pub d: f64,
    pub p: f64,
    pub upper: String,
    pub lower: String,
    /// What a decoder does between two slices.
    pub interpolation: String,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Weather {
    pub basis_order: Vec<String>,
    pub rule: String,
    pub cloudy_step: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SkyEntry {
    pub name: String,
    /// The LUT file, relative to the manifest.
    pub file: String,
    /// "B10G11R11_UFLOAT_PACK32" (vkFormat 122).
    pub format: String,
    pub vk_format: u32,
    pub bytes: u64,
    pub width: usize,
    pub height: usize,
    pub layers: usize,
    pub atmosphere: String,
    pub atmosphere_hash: String,
    pub altitude_m: f64,
    pub planet_radius_km: f64,
    pub top_km: f64,
    pub d_min_km: f64,
    pub d_max_km: f64,
    /// The sun zenith angle beyond which a slice is latitude-longitude.
    pub threshold_sun_zenith_deg: f64,
    pub slices: Vec<SliceEntry>,
    pub texels_clamped: u64,
    pub texels_denormal: u64,
    pub texels_negative_rgb: u64,
    /// The sun (added in version 2; absent from bakes made before it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sun: Option<SunEntry>,
    /// Per slice, ambient light from the sky in the manifest's colour
    /// space: irradiance on an upward surface, mean radiance of the upper
    /// hemisphere, order-2 spherical harmonics of the whole sphere
    /// (`lut::ambient`; added in version 2).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ambient: Option<Vec<super::ambient::Ambient>>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SliceEntry {
    pub index: usize,
    pub sun_zenith_deg: f64,
    /// Stored = value * 2^scale_log2.
    pub scale_log2: i32,
    pub mean_samples: f64,
    /// Median over the slice of the standard error of Y over Y.
    pub median_rel_stderr_y: f64,
}

/// The manifest's fixed descriptions, shared by the writer and the docs.
pub fn time_mapping() -> TimeMapping {
    use crate::directions::mapping::*;
    TimeMapping {
        slices: SLICES,
        upper_slices: UPPER_SLICES,
        lower_slices: LOWER_SLICES,
        upper: "d_i = lerp(d_min, d_max, i / 47): d_min = top_km (the vertical path), d_max = sqrt((R + top)^2 - R^2) (the horizontal one); the slice's sun zenith angle is the one whose path from the ground to the top is d_i: cos(theta) = (h^2 - d_i^2) / (2 R d_i), h^2 = (R + top)^2 - R^2".into(),
        lower: "theta_z = lerp(90 deg, 100 deg, ((i - 48) / 15)^2)".into(),
        lowest_sun_zenith_deg: LOWEST_SUN_ZENITH_DEG,
        below_lowest: "clamp to the last slice".into(),
    }
}

pub fn direction_mapping() -> DirectionMappingInfo {
    use crate::directions::mapping::*;
    DirectionMappingInfo {
        texels: "texel (x, y) of a layer covers the cell centred on (u, v) = ((x + 0.5) / width, (y + 0.5) / height); row y = 0 is first in memory (KTXorientation \"rd\")".into(),
        frame: "z is the zenith; the sun lies in the x-z plane at azimuth 0; azimuth runs from +x toward +y".into(),
        u_mirror: true,
        a: A,
        b: B,
        c: C,
        d: D,
        p: P,
        upper: "sun zenith <= threshold: the talk's uvToWorldSpaceDirection, sun-centred branch: phi = u pi, the heading about the sun from the tangent pointing down toward the horizon below it; v' = the nonlinear transform of v (a, b, c, d, p); edge = pi/2 - atan(sin(pi/2 - phi) tan(theta_sun)); theta = v'/0.5 edge for v' <= 0.5, else (v'/0.5 - 1)(pi - edge) + edge; the horizon is the line v = b".into(),
        lower: "sun zenith > threshold: latitude-longitude, zenith angle = pi v'' with v'' = the two-arc transform about K = min(0.5, theta_sun / pi), azimuth from the sun = u pi".into(),
        interpolation: "the direction's (u, v) from the mapping of the actual sun zenith angle (in each slice's own region), bilinear at texel centres with clamp-to-edge (which is the mirror at u = 0 and 1), each slice times 2^-scale_log2, then between the two slices around it (from the slice coordinate: slices floor(s) and floor(s) + 1) at the fraction f of the way between their sun zenith angles, per RGB channel: geometric, a^(1-f) b^f, where both a and b are positive, else linear, (1-f) a + f b".into(),
    }
}

pub fn weather() -> Weather {
    use super::weather::*;
    Weather {
        basis_order: BASIS.iter().map(|s| s.to_string()).collect(),
        rule: "haziness h and cloudiness c in [0, 1]. c < 1/6: (1 - c/s)((1 - h) clear + h hazed) + (c/s) cloudy0, s = 1/6. c >= 1/6: p = (c - s)/s in [0, 5], the linear blend of cloudy(floor p) and cloudy(floor p + 1)".into(),
        cloudy_step: CLOUDY_STEP,
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A manifest around the given skies (for decoder tests).
    pub fn manifest_with(skies: Vec<SkyEntry>) -> Manifest {
        let i = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        Manifest {
            format: FORMAT.into(),
            version: VERSION,
            generator: format!("sky {}", crate::VERSION),
            quality: "draft".into(),
            method: None,
            container: None,
            units: Units { luminance: "cd/m^2".into(), scale: String::new() },
            colour: Colour { space: "xyz".into(), rgb_from_xyz: i, xyz_from_rgb: i, note: String::new() },
            time_mapping: time_mapping(),
            direction_mapping: direction_mapping(),
            weather: weather(),
            skies,
            transmittance: None,
            fog: None,
            ambient_file: None,
            files: None,
            manifest_sha256: None,
        }
    }

    #[test]
    fn manifests_round_trip_through_json() {
        let m = manifest_with(Vec::new());
        let text = serde_json::to_string_pretty(&m).unwrap();
        assert_eq!(serde_json::from_str::<Manifest>(&text).unwrap(), m);
    }
}
