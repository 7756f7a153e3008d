//! The sky pass: the basis-sky arrays of a bake decoded on the GPU for a
//! list of directions (`shaders/sky_decode.wgsl`), in two steps: the
//! composition decodes the bake into one frame sky texture (the weather's
//! skies and the sun's two slices blended, at [`FRAME_SKY_OVERSAMPLING`]
//! times the largest sky's resolution, in the mapping of the actual sun),
//! the same decode as the CPU reference
//! decoder's [`Luts::sample`] at each texel centre, whenever the sun's
//! elevation or the weather changes; the sky pass then reads that texture
//! once per direction with the sampler's filtering, and draws the sun.
//!
//! The arrays go to the GPU as the bake stores them: 2-D array textures of
//! 64 layers, one per basis sky, R11G11B10F (wgpu's `Rg11b10Ufloat`,
//! Vulkan's `B10G11R11_UFLOAT_PACK32`, vkFormat 122) or RGBA16F
//! (`Rgba16Float`, vkFormat 97), their codes rebuilt from the loaded
//! texels. The weather rule, the slice pair and the slices' scales are
//! worked out per frame on the CPU by the very functions the CPU decoder
//! uses. Directions come from the CPU cameras (`directions::camera`): one
//! definition of the cameras for the renderer, the CPU decoder and the
//! preview.

use super::frame::{Frame, Rendered};
use super::gpu::{array_entry, buffer_entry, Gpu};
use super::PreviewError;
use crate::directions::mapping;
use crate::lut::container::TextureFormat;
use crate::lut::decode::Texture;
use crate::lut::decode::{slice_pair, Luts};
use crate::lut::manifest::SkyEntry;
use crate::lut::r11g11b10::{self, PackError};
use crate::lut::rgba16f;
use crate::lut::weather::{basis_weights, BASIS};
use glam::DVec3;
use std::cell::RefCell;
use std::rc::Rc;

/// At most this many basis skies have weight at once (the weather rule's
/// bound, `basis_weights`).
pub const ACTIVE_SKIES: usize = 3;

/// The sun and the weather of one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Weather {
    pub sun_elevation_deg: f64,
    pub sun_azimuth_deg: f64,
    pub haziness: f64,
    pub cloudiness: f64,
    /// Draw the sun's disk (from the bake's sunlight, `Luts::sun`): its
    /// radiance where it covers a direction, as `Luts::decode_image` does.
    pub sun_disk: bool,
}

/// A basis sky's array in the bake's own texel format, its codes rebuilt
/// from the loaded texels (each format round-trips every code exactly:
/// `lut::r11g11b10` and `lut::rgba16f` test it).
fn texels_as_stored(entry: &SkyEntry, texture: &Texture) -> Result<(wgpu::TextureFormat, Vec<u8>), PreviewError> {
    let fail = |e: PackError| PreviewError::Bake(format!("{}: a texel does not pack: {e}", entry.name));
    let texels = texture.layers.iter().flatten().map(|t| t.map(f64::from));
    match TextureFormat::of_vk_format(entry.vk_format) {
        Some(TextureFormat::R11g11b10) => {
            let mut bytes = Vec::with_capacity(4 * entry.width * entry.height * entry.layers);
            for t in texels {
                bytes.extend_from_slice(&r11g11b10::pack(t).map_err(fail)?.to_le_bytes());
            }
            Ok((wgpu::TextureFormat::Rg11b10Ufloat, bytes))
        }
        Some(TextureFormat::Rgba16f) => {
            let mut bytes = Vec::with_capacity(8 * entry.width * entry.height * entry.layers);
            for t in texels {
                rgba16f::pack(t).map_err(fail)?.iter().for_each(|h| bytes.extend_from_slice(&h.to_le_bytes()));
            }
            Ok((wgpu::TextureFormat::Rgba16Float, bytes))
        }
        None => Err(PreviewError::Bake(format!("{}: vkFormat {} is not a sky format", entry.name, entry.vk_format))),
    }
}

/// A bake's sky arrays on the GPU, the frame sky texture composed from
/// them, and the two pipelines (see `shaders/sky_decode.wgsl`).
pub struct SkyPass {
    textures: Vec<wgpu::TextureView>,
    frame_sky: wgpu::TextureView,
    sampler: wgpu::Sampler,
    compose_layout: wgpu::BindGroupLayout,
    compose: wgpu::ComputePipeline,
    sky_layout: wgpu::BindGroupLayout,
    /// The sky pass for the latitude-longitude frame texture, and for the
    /// sun-centred one.
    sky: [wgpu::ComputePipeline; 2],
    /// The composition in the frame sky texture (its parameters' bits), or
    /// None before the first: a frame composes only when this changes.
    composed: Rc<RefCell<Option<Vec<u32>>>>,
}

/// The frame sky texture's texels per LUT texel, in each direction. Its
/// texels are the CPU decoder's values at their centres, and the sky pass
/// filters them bilinearly: a bilinear of the slices' bilinears, which
/// departs from the CPU decoder's value by the resampling error. Measured
/// against the CPU decoder on `make demo`'s draft bake (16 x 64 sunny, 8 x
/// 32 cloudy; 14 suns from 63 to -10 degrees, 6 weathers, 2 928
/// directions), luminance: 1 texel a texel, median 0.05 %, 99th percentile
/// 4.1 %; 2, 0.04 % and 1.8 %; 4, 0.036 % and 0.54 % (the median is the
/// half float's rounding). The composition's cost grows with the texel
/// count, the sky pass's (one filtered read) does not.
pub const FRAME_SKY_OVERSAMPLING: usize = 4;

/// The frame sky texture's texel format: half floats, filterable and
/// writable by a compute shader on every WebGPU device.
const FRAME_SKY_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;

impl SkyPass {
    /// Uploads every basis sky's array of `luts`, makes the frame sky
    /// texture ([`FRAME_SKY_OVERSAMPLING`] times the largest sky's width and
    /// height) and builds the
    /// pipelines.
    pub fn new(gpu: &Gpu, luts: &Luts) -> Result<SkyPass, PreviewError> {
        let mut textures = Vec::new();
        for (entry, texture) in luts.manifest.skies.iter().zip(&luts.textures) {
            let (format, bytes) = texels_as_stored(entry, texture)?;
            textures.push(gpu.array_texture(&entry.name, format, entry.width, entry.height, entry.layers, &bytes)?);
        }
        let skies = &luts.manifest.skies;
        let (Some(width), Some(height)) = (skies.iter().map(|s| s.width).max(), skies.iter().map(|s| s.height).max())
        else {
            return Err(PreviewError::Bake("the bake has no basis sky".into()));
        };
        let (width, height) = (width * FRAME_SKY_OVERSAMPLING, height * FRAME_SKY_OVERSAMPLING);
        let frame_sky = gpu.checked("frame sky texture", || {
            gpu.device
                .create_texture(&wgpu::TextureDescriptor {
                    label: Some("frame sky"),
                    size: wgpu::Extent3d { width: width as u32, height: height as u32, depth_or_array_layers: 1 },
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format: FRAME_SKY_FORMAT,
                    usage: wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::TEXTURE_BINDING,
                    view_formats: &[],
                })
                .create_view(&Default::default())
        })?;
        let sampler = gpu.device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("frame sky"),
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });
        use wgpu::BufferBindingType::{Storage, Uniform};
        let stage = wgpu::ShaderStages::COMPUTE;
        let frame_out = wgpu::BindGroupLayoutEntry {
            binding: 6,
            visibility: stage,
            ty: wgpu::BindingType::StorageTexture {
                access: wgpu::StorageTextureAccess::WriteOnly,
                format: FRAME_SKY_FORMAT,
                view_dimension: wgpu::TextureViewDimension::D2,
            },
            count: None,
        };
        let compose_entries = [buffer_entry(0, Uniform), array_entry(3), array_entry(4), array_entry(5), frame_out];
        let (compose_layout, compose) =
            gpu.compute_pipeline("sky composition", super::shaders::SKY_DECODE, "compose", &compose_entries)?;
        let frame_in = wgpu::BindGroupLayoutEntry {
            binding: 7,
            visibility: stage,
            ty: wgpu::BindingType::Texture {
                sample_type: wgpu::TextureSampleType::Float { filterable: true },
                view_dimension: wgpu::TextureViewDimension::D2,
                multisampled: false,
            },
            count: None,
        };
        let linear = wgpu::BindGroupLayoutEntry {
            binding: 8,
            visibility: stage,
            ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
            count: None,
        };
        let sky_entries = [
            buffer_entry(0, Uniform),
            buffer_entry(1, Storage { read_only: true }),
            buffer_entry(2, Storage { read_only: false }),
            frame_in,
            linear,
        ];
        let sky_of = |centred: f64| {
            let constants = [("SKY_SUN_CENTRED", centred)];
            gpu.compute_pipeline_with("sky", super::shaders::SKY_DECODE, "sky", &sky_entries, &constants)
        };
        let ((sky_layout, lat_long), (_, centred)) = (sky_of(0.0)?, sky_of(1.0)?);
        let sky = [lat_long, centred];
        let composed = Rc::new(RefCell::new(None));
        Ok(SkyPass { textures, frame_sky, sampler, compose_layout, compose, sky_layout, sky, composed })
    }

    /// The frame sky texture's width and height (texels).
    pub fn frame_size(&self) -> (usize, usize) {
        let size = self.frame_sky.texture().size();
        (size.width as usize, size.height as usize)
    }

    /// The GPU array of the manifest's sky `index`.
    pub fn array(&self, index: usize) -> Option<&wgpu::TextureView> {
        self.textures.get(index)
    }

    /// Records the composition of the frame sky texture for `weather` into
    /// `frame` (timed as "sky composition"), whether or not the texture
    /// already holds it. The frames after take the texture as composed,
    /// unless this one is dropped before it is submitted.
    pub fn compose(&self, gpu: &Gpu, frame: &mut Frame, luts: &Luts, weather: &Weather) -> Result<(), PreviewError> {
        let (mut params, active) = frame_params(luts, weather)?;
        let key = composition_key(&params, &active);
        params.extend([0.0; 4]); // `point`, which the composition does not read
        let bind = gpu.checked("sky composition bind group", || {
            let uniform = frame.uniform("sky params", &params);
            // Unused texture slots hold any array: their weight is 0 and the shader never reads them.
            let view =
                |k: usize| wgpu::BindingResource::TextureView(&self.textures[active.get(k).copied().unwrap_or(0)]);
            gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("sky composition"),
                layout: &self.compose_layout,
                entries: &[
                    wgpu::BindGroupEntry { binding: 0, resource: uniform.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 3, resource: view(0) },
                    wgpu::BindGroupEntry { binding: 4, resource: view(1) },
                    wgpu::BindGroupEntry { binding: 5, resource: view(2) },
                    wgpu::BindGroupEntry { binding: 6, resource: wgpu::BindingResource::TextureView(&self.frame_sky) },
                ],
            })
        })?;
        let (width, height) = self.frame_size();
        let groups = [(width as u32).div_ceil(8), (height as u32).div_ceil(8), 1];
        frame.dispatch_groups("sky composition", &self.compose, &bind, groups);
        *self.composed.borrow_mut() = Some(key);
        let composed = Rc::clone(&self.composed);
        frame.on_abandoned(move || *composed.borrow_mut() = None);
        Ok(())
    }

    /// Records the sky pass into `frame`: linear RGB toward each direction
    /// under `weather` into the frame's radiance buffer, after the
    /// composition where the sun's elevation or the weather changed.
    pub fn encode(&self, gpu: &Gpu, frame: &mut Frame, luts: &Luts, weather: &Weather) -> Result<(), PreviewError> {
        self.encode_with_sun_pixel(gpu, frame, luts, weather, None)
    }

    /// [`SkyPass::encode`] with a sun smaller than a pixel put into one
    /// (`sun_pixel`: the direction's index and the radiance to add, from
    /// [`sun_pixel`]).
    pub fn encode_with_sun_pixel(
        &self,
        gpu: &Gpu,
        frame: &mut Frame,
        luts: &Luts,
        weather: &Weather,
        sun_pixel: Option<(usize, [f64; 3])>,
    ) -> Result<(), PreviewError> {
        let (mut params, active) = frame_params(luts, weather)?;
        if self.composed.borrow().as_deref() != Some(&composition_key(&params, &active)[..]) {
            self.compose(gpu, frame, luts, weather)?;
        }
        match sun_pixel {
            // The index travels as the bits of an f32 (the shader bitcasts it back), plus one: 0 is none.
            Some((i, rgb)) if weather.sun_disk && i < u32::MAX as usize => {
                params.extend(rgb.map(|x| x as f32).into_iter().chain([f32::from_bits(i as u32 + 1)]))
            }
            _ => params.extend([0.0; 4]),
        }
        let bind = gpu.checked("sky bind group", || {
            let uniform = frame.uniform("sky params", &params);
            gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("sky"),
                layout: &self.sky_layout,
                entries: &[
                    wgpu::BindGroupEntry { binding: 0, resource: uniform.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 1, resource: frame.directions.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 2, resource: frame.radiance.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 7, resource: wgpu::BindingResource::TextureView(&self.frame_sky) },
                    wgpu::BindGroupEntry { binding: 8, resource: wgpu::BindingResource::Sampler(&self.sampler) },
                ],
            })
        })?;
        let centred = params[FRAME_CENTRED] > 0.5;
        frame.dispatch("sky", &self.sky[usize::from(centred)], &bind);
        Ok(())
    }

    /// Linear RGB toward each of `dirs` (world frame, z up; None: no
    /// direction, black) under `weather`, decoded on the GPU: a frame of
    /// the sky pass alone.
    pub fn decode(
        &self,
        gpu: &Gpu,
        luts: &Luts,
        weather: &Weather,
        dirs: &[Option<DVec3>],
    ) -> Result<Rendered, PreviewError> {
        let mut frame = Frame::new(gpu, dirs)?;
        self.encode(gpu, &mut frame, luts, weather)?;
        frame.finish()
    }
}

/// What the composition depends on: which skies are active (their
/// manifest indices) and, among `frame_params`' values (their bits), the
/// sun's zenith, the active skies' count and rows, the frame and mapping
/// rows; not the sun's azimuth (the texture is in the sun's frame) nor its
/// disk.
fn composition_key(params: &[f32], active: &[usize]) -> Vec<u32> {
    let rows = params[..PARAMS_BEFORE_SUN].iter().enumerate().filter(|(i, _)| !matches!(i, 1 | 2));
    active.iter().map(|&i| i as u32).chain(rows.map(|(_, x)| x.to_bits())).collect()
}

/// Where in `Params` the frame row's first value lies: 1 for the
/// sun-centred region, 0 for the latitude-longitude one.
const FRAME_CENTRED: usize = 4;

/// The floats of `Params` before its `sun` row: header, frame, mapping,
/// six sky rows.
const PARAMS_BEFORE_SUN: usize = 4 * (3 + 2 * ACTIVE_SKIES);

/// Where a sun smaller than a pixel goes for `camera` at `width` x
/// `height` (directions `dirs`): none if the disk covers a pixel centre
/// (the shader draws it there) or lies off the image; else the pixel
/// nearest it and the radiance that puts the sun's irradiance into it, as
/// the CPU decoder's `decode_image` does (`Luts::sub_pixel_sun`).
pub fn sun_pixel(
    luts: &Luts,
    weather: &Weather,
    camera: &crate::directions::camera::Camera,
    width: usize,
    height: usize,
    dirs: &[Option<DVec3>],
) -> Option<(usize, [f64; 3])> {
    if !weather.sun_disk {
        return None;
    }
    let sun = luts.sun(weather.sun_elevation_deg, weather.haziness, weather.cloudiness)?;
    let toward = crate::directions::camera::direction_deg(90.0 - weather.sun_elevation_deg, weather.sun_azimuth_deg);
    let cos_radius = libm::cos(0.5 * sun.angular_diameter_deg.to_radians());
    if dirs.iter().flatten().any(|d| d.dot(toward) >= cos_radius) {
        return None;
    }
    luts.sub_pixel_sun(camera, width, height, dirs, toward, sun.irradiance_rgb)
}

/// The basis skies that `weather` gives weight, in the weather rule's
/// order, as (manifest index, weight): those of the bake for which
/// `usable(name)` holds, their weights renormalised over them where the
/// bake lacks some of the rule's skies (as the CPU decoder does); at most
/// [`ACTIVE_SKIES`].
pub(crate) fn active_skies(luts: &Luts, weather: &Weather, usable: impl Fn(&str) -> bool) -> Vec<(usize, f64)> {
    let w = basis_weights(weather.haziness, weather.cloudiness);
    let present: Vec<(usize, f64)> = BASIS
        .iter()
        .enumerate()
        .filter(|&(k, name)| w[k] > 0.0 && usable(name))
        .filter_map(|(k, name)| luts.manifest.skies.iter().position(|s| s.name == *name).map(|i| (i, w[k])))
        .collect();
    let total: f64 = present.iter().map(|p| p.1).sum();
    let scale = if total > 0.0 && total < 1.0 { 1.0 / total } else { 1.0 };
    present.into_iter().take(ACTIVE_SKIES).map(|(i, w)| (i, w * scale)).collect()
}

/// The mapping of the frame sky texture under `weather`: that of the
/// actual sun (a sun below the lowest slice reads as on it), in the region
/// the first active sky's threshold gives the actual sun (where its two
/// slices straddle the switch, one of them is read across regions); None
/// without an active sky.
pub fn frame_mapping(luts: &Luts, weather: &Weather) -> Option<mapping::DirectionMapping> {
    let (first, _) = *active_skies(luts, weather, |_| true).first()?;
    Some(mapping_of(luts, weather, first))
}

/// [`frame_mapping`] with the first active sky known (manifest index).
fn mapping_of(luts: &Luts, weather: &Weather, first: usize) -> mapping::DirectionMapping {
    let sun_zenith_deg = (90.0 - weather.sun_elevation_deg).clamp(0.0, mapping::LOWEST_SUN_ZENITH_DEG);
    mapping::DirectionMapping::new(sun_zenith_deg, luts.manifest.skies[first].threshold_sun_zenith_deg)
}

/// The shader's `Params` for `weather` (see `sky_decode.wgsl`) and the
/// manifest indices of the active skies, in slot order: the weather rule's
/// weights renormalised over the skies the bake has (as [`Luts::sample`]
/// does), each active sky's slice pair ([`slice_pair`]), the slices'
/// scales and regions; the frame sky texture's region and scale; the
/// sun's disk. An error if the disk is asked of a bake without a sun.
pub fn frame_params(luts: &Luts, weather: &Weather) -> Result<(Vec<f32>, Vec<usize>), PreviewError> {
    let sun_zenith_deg = 90.0 - weather.sun_elevation_deg;
    // The mappings' sun (a sun below the lowest slice reads as on it).
    let theta_sun = sun_zenith_deg.clamp(0.0, mapping::LOWEST_SUN_ZENITH_DEG).to_radians();
    let active = active_skies(luts, weather, |_| true);
    let azimuth = weather.sun_azimuth_deg.to_radians();
    let mut params = vec![theta_sun as f32, libm::cos(azimuth) as f32, libm::sin(azimuth) as f32, active.len() as f32];
    let mut rows = Vec::with_capacity(8 * ACTIVE_SKIES);
    let mut frame_scale = 0.0f32;
    for k in 0..ACTIVE_SKIES {
        match active.get(k) {
            Some(&(i, weight)) => {
                let entry = &luts.manifest.skies[i];
                let (i0, i1, f) = slice_pair(entry, sun_zenith_deg);
                let slice_scale = |s: usize| (-entry.slices[s].scale_log2 as f64).exp2() as f32;
                let centred =
                    |s: usize| if entry.slices[s].sun_zenith_deg <= entry.threshold_sun_zenith_deg { 1.0 } else { 0.0 };
                rows.extend([weight as f32, f as f32, i0 as f32, i1 as f32]);
                rows.extend([slice_scale(i0), slice_scale(i1), centred(i0), centred(i1)]);
                frame_scale = frame_scale.max(slice_scale(i0)).max(slice_scale(i1));
            }
            None => rows.extend([0.0; 8]),
        }
    }
    // The frame sky texture's values over the largest slice scale, so that
    // what the slices store (up to 2^15) stays within a half float's range.
    let frame_centred = active.first().is_some_and(|&(first, _)| mapping_of(luts, weather, first).sun_centred());
    let frame_scale = if frame_scale > 0.0 { frame_scale } else { 1.0 };
    params.extend([if frame_centred { 1.0 } else { 0.0 }, frame_scale, 1.0 / frame_scale, 0.0]);
    params.extend([libm::sin(theta_sun), libm::cos(theta_sun), libm::tan(theta_sun), theta_sun].map(|x| x as f32));
    params.extend(rows);
    let toward = crate::directions::camera::direction_deg(sun_zenith_deg, weather.sun_azimuth_deg);
    match weather.sun_disk {
        true => {
            let sun = luts.sun(weather.sun_elevation_deg, weather.haziness, weather.cloudiness).ok_or_else(|| {
                PreviewError::Bake(
                    "the bake has no sun (made before its transmittance file): bake it again, or leave the disk out"
                        .into(),
                )
            })?;
            let sin_radius = libm::sin(0.5 * sun.angular_diameter_deg.to_radians());
            params.extend([toward.x as f32, toward.y as f32, toward.z as f32, sin_radius as f32]);
            params.extend(sun.disk_radiance_rgb.map(|x| x as f32).into_iter().chain([1.0]));
        }
        false => params.extend([0.0; 8]),
    }
    Ok((params, active.into_iter().map(|p| p.0).collect()))
}
