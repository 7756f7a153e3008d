//! The cumulus clouds of the preview (`shaders/clouds.wgsl`, lit by
//! `shaders/cloud_lighting.wgsl`): the cumulus map, the coverage texture,
//! the distant-cloud shadow volume and the cloud G-buffer over the upper
//! hemisphere from the world's centre, in the talk's square-to-disk
//! mapping, RGBA16F: opacity to the sky, distance to the clouds (km), sun
//! in-scatter (per unit of sun irradiance) and ambient in-scatter (per
//! unit of the sky's mean radiance). The G-buffer holds no light: the
//! lighting pass multiplies it by the frame's sun and sky from the LUTs.
//!
//! The coverage texture (256 × 128 RGBA, x: the cumulus map's density, y:
//! height in the layer) is generated ([`default_coverage`]) or painted by an
//! artist as a PNG ([`coverage_from_png`]).

use super::cloud_noise::CloudNoise;
use super::frame::Frame;
use super::gpu::{buffer_entry, f32_bytes, Gpu};
use super::sky_pass::Weather;
use super::PreviewError;
use crate::lut::decode::Luts;
use std::path::Path;
use wgpu::util::DeviceExt;

/// The cumulus map's texels per side (the talk's 256) and the world it
/// covers, km (the talk's 240).
pub const CUMULUS_SIZE: u32 = 256;
pub const CUMULUS_SPAN_KM: f64 = 240.0;
/// The coverage texture's size (the talk's 256 × 128).
pub const COVERAGE_WIDTH: u32 = 256;
pub const COVERAGE_HEIGHT: u32 = 128;
/// The distant-cloud shadow volume's cells: x, y over the map, z from
/// the ground to the cloud top.
const SHADOW_CELLS: [u32; 3] = [64, 64, 16];

/// What the clouds are and how finely they are computed.
#[derive(Debug, Clone, PartialEq)]
pub struct CloudSettings {
    /// How much of the sky the cumulus cover, 0 to 1.
    pub cover: f64,
    /// How far the wind has moved the clouds, km (east, north).
    pub wind_offset_km: [f64; 2],
    /// The planet's radius, km (the bake's, where the caller has one).
    pub planet_radius_km: f64,
    /// The cloud layer, km above the ground.
    pub base_km: f64,
    pub top_km: f64,
    /// Extinction of cloud of density 1, per km.
    pub extinction_per_km: f64,
    /// The G-buffer's texels per side (the talk: 768 on PS4, 1024 on PS5).
    pub gbuffer_size: u32,
    /// Jittered marches averaged per texel, and steps per march.
    pub samples: u32,
    pub steps: u32,
    pub seed: u32,
}

impl Default for CloudSettings {
    fn default() -> Self {
        CloudSettings { cover: 0.4, wind_offset_km: [0.0, 0.0], planet_radius_km: 6371.0, base_km: 1.5, top_km: 5.0, extinction_per_km: 40.0, gbuffer_size: 256, samples: 4, steps: 48, seed: 1 }
    }
}

/// The Wrenninge et al. 2013 octaves: attenuation a, contribution b,
/// eccentricity c per octave; a <= b (Hillaire 2016: so that energy is
/// conserved).
const OCTAVES_ABC: [f32; 3] = [0.5, 0.5, 0.5];

/// The generated coverage texture, RGBA8 rows from the cloud base (row 0)
/// up: R height modulation (a cumulus profile whose top rises with the
/// map's density: base at 0, top at 0.15 + 0.85 d of the layer, rounded
/// above and flat below), G and B the low- and mid-frequency noises'
/// weights (more erosion toward the top), A the share of the sky's ambient
/// light (0.3 at the base to 1 at the top).
pub fn default_coverage() -> Vec<[u8; 4]> {
    let mut out = Vec::with_capacity((COVERAGE_WIDTH * COVERAGE_HEIGHT) as usize);
    let smooth = |e0: f64, e1: f64, x: f64| {
        let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
        t * t * (3.0 - 2.0 * t)
    };
    for j in 0..COVERAGE_HEIGHT {
        let h = (j as f64 + 0.5) / COVERAGE_HEIGHT as f64;
        for i in 0..COVERAGE_WIDTH {
            let d = i as f64 / (COVERAGE_WIDTH - 1) as f64;
            let top = 0.15 + 0.85 * d;
            let profile = smooth(0.0, 0.05, h) * (1.0 - smooth(0.55 * top, top, h));
            let r = (1.3 * d).min(1.0) * profile;
            let g = 0.35 + 0.4 * h;
            let b = 0.2 + 0.2 * h;
            let a = 0.3 + 0.7 * h;
            out.push([r, g, b, a].map(|x| (x.clamp(0.0, 1.0) * 255.0).round() as u8));
        }
    }
    out
}

/// An artist's coverage texture: a 256 × 128 RGBA PNG, row 0 at the top
/// of the image being the cloud top (as it is painted, height upward).
pub fn coverage_from_png(path: &Path) -> Result<Vec<[u8; 4]>, PreviewError> {
    let image = image::open(path).map_err(|e| PreviewError::Bake(format!("{}: {e}", path.display())))?.to_rgba8();
    if image.width() != COVERAGE_WIDTH || image.height() != COVERAGE_HEIGHT {
        return Err(PreviewError::Bake(format!("{}: a coverage texture is {COVERAGE_WIDTH} x {COVERAGE_HEIGHT}, this is {} x {}", path.display(), image.width(), image.height())));
    }
    let mut out = Vec::with_capacity((COVERAGE_WIDTH * COVERAGE_HEIGHT) as usize);
    for j in (0..COVERAGE_HEIGHT).rev() {
        for i in 0..COVERAGE_WIDTH {
            out.push(image.get_pixel(i, j).0);
        }
    }
    Ok(out)
}

/// The coverage as a PNG as an artist paints it (height upward), for a
/// starting point.
pub fn write_coverage_png(path: &Path, coverage: &[[u8; 4]]) -> Result<(), PreviewError> {
    let mut image = image::RgbaImage::new(COVERAGE_WIDTH, COVERAGE_HEIGHT);
    for (k, px) in coverage.iter().enumerate() {
        let (i, j) = (k as u32 % COVERAGE_WIDTH, k as u32 / COVERAGE_WIDTH);
        image.put_pixel(i, COVERAGE_HEIGHT - 1 - j, image::Rgba(*px));
    }
    image.save(path).map_err(|e| PreviewError::Bake(format!("{}: {e}", path.display())))
}

/// The clouds' textures and pipelines.
pub struct Clouds {
    pub noise: CloudNoise,
    coverage: wgpu::TextureView,
    cumulus: wgpu::Texture,
    shadow: wgpu::Texture,
    pub gbuffer: wgpu::Texture,
    clamped: wgpu::Sampler,
    repeating: wgpu::Sampler,
    cumulus_pipeline: wgpu::ComputePipeline,
    shadow_pipeline: wgpu::ComputePipeline,
    gbuffer_pipeline: wgpu::ComputePipeline,
    light_layout: wgpu::BindGroupLayout,
    light_pipeline: wgpu::ComputePipeline,
}

fn storage_texture(gpu: &Gpu, label: &'static str, size: [u32; 3], dimension: wgpu::TextureDimension) -> Result<wgpu::Texture, PreviewError> {
    gpu.checked(label, || {
        gpu.device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d { width: size[0], height: size[1], depth_or_array_layers: size[2] },
            mip_level_count: 1,
            sample_count: 1,
            dimension,
            format: wgpu::TextureFormat::Rgba16Float,
            usage: wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        })
    })
}

impl Clouds {
    /// Builds the noise, uploads `coverage` (256 × 128, rows from the base
    /// up) and makes the pipelines and a G-buffer of `gbuffer_size`².
    pub fn new(gpu: &Gpu, coverage: &[[u8; 4]], gbuffer_size: u32, seed: u32) -> Result<Clouds, PreviewError> {
        if coverage.len() != (COVERAGE_WIDTH * COVERAGE_HEIGHT) as usize || gbuffer_size == 0 {
            return Err(PreviewError::Bake("the coverage texture must be 256 x 128 and the G-buffer at least 1 texel".into()));
        }
        let noise = CloudNoise::new(gpu, seed)?;
        let bytes: Vec<u8> = coverage.iter().flatten().copied().collect();
        let coverage = gpu.checked("coverage texture", || {
            gpu.device.create_texture_with_data(
                &gpu.queue,
                &wgpu::TextureDescriptor {
                    label: Some("coverage"),
                    size: wgpu::Extent3d { width: COVERAGE_WIDTH, height: COVERAGE_HEIGHT, depth_or_array_layers: 1 },
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format: wgpu::TextureFormat::Rgba8Unorm,
                    usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                    view_formats: &[],
                },
                wgpu::util::TextureDataOrder::LayerMajor,
                &bytes,
            )
        })?;
        let d2 = wgpu::TextureDimension::D2;
        let cumulus = storage_texture(gpu, "cumulus map", [CUMULUS_SIZE, CUMULUS_SIZE, 1], d2)?;
        let shadow = storage_texture(gpu, "distant-cloud shadow", SHADOW_CELLS, wgpu::TextureDimension::D3)?;
        let gbuffer = storage_texture(gpu, "cloud G-buffer", [gbuffer_size, gbuffer_size, 1], d2)?;
        let sampler = |label, mode| {
            gpu.device.create_sampler(&wgpu::SamplerDescriptor {
                label: Some(label),
                address_mode_u: mode,
                address_mode_v: mode,
                address_mode_w: mode,
                mag_filter: wgpu::FilterMode::Linear,
                min_filter: wgpu::FilterMode::Linear,
                ..Default::default()
            })
        };
        let (clamped, repeating) = (sampler("clamped", wgpu::AddressMode::ClampToEdge), sampler("repeating", wgpu::AddressMode::Repeat));
        let module = gpu.module("clouds.wgsl", super::shaders::CLOUDS)?;
        let cumulus_pipeline = gpu.compute_pipeline_auto("cumulus map", &module, "cumulus_map")?;
        let shadow_pipeline = gpu.compute_pipeline_auto("distant-cloud shadow", &module, "shadow_volume")?;
        let gbuffer_pipeline = gpu.compute_pipeline_auto("cloud G-buffer", &module, "gbuffer")?;
        use wgpu::BufferBindingType::{Storage, Uniform};
        let light_entries = [
            buffer_entry(0, Uniform),
            buffer_entry(1, Storage { read_only: true }),
            buffer_entry(2, Storage { read_only: false }),
            wgpu::BindGroupLayoutEntry {
                binding: 3,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::Texture { sample_type: wgpu::TextureSampleType::Float { filterable: true }, view_dimension: wgpu::TextureViewDimension::D2, multisampled: false },
                count: None,
            },
            wgpu::BindGroupLayoutEntry { binding: 4, visibility: wgpu::ShaderStages::COMPUTE, ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering), count: None },
        ];
        let (light_layout, light_pipeline) = gpu.compute_pipeline("cloud lighting", super::shaders::CLOUD_LIGHTING, "light", &light_entries)?;
        let coverage = coverage.create_view(&Default::default());
        Ok(Clouds { noise, coverage, cumulus, shadow, gbuffer, clamped, repeating, cumulus_pipeline, shadow_pipeline, gbuffer_pipeline, light_layout, light_pipeline })
    }

    /// Computes the cumulus map, the shadow volume and the whole G-buffer
    /// for the sun of `weather` and `settings`, `first_sample` numbering
    /// the G-buffer's jittered marches (a different first sample: an
    /// independent G-buffer). Returns the GPU wall time, seconds.
    pub fn compute(&self, gpu: &Gpu, weather: &Weather, settings: &CloudSettings, first_sample: u32) -> Result<f64, PreviewError> {
        let start = std::time::Instant::now();
        let to_sun = crate::render::camera::direction_deg(90.0 - weather.sun_elevation_deg, weather.sun_azimuth_deg);
        let [a, b, c] = OCTAVES_ABC;
        let params: Vec<f32> = [
            [settings.planet_radius_km, settings.base_km, settings.top_km, 0.5 * CUMULUS_SPAN_KM],
            [to_sun.x, to_sun.y, to_sun.z, settings.cover.clamp(0.0, 1.0)],
            [settings.wind_offset_km[0], settings.wind_offset_km[1], f64::from(self.gbuffer.width()), f64::from(settings.samples.max(1))],
            [settings.extinction_per_km, f64::from(a), f64::from(b), f64::from(c)],
            [f64::from(first_sample), f64::from(settings.seed), f64::from(settings.steps.max(1)), 0.0],
        ]
        .iter()
        .flatten()
        .map(|&x| x as f32)
        .collect();
        let uniform = gpu.device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some("cloud params"), contents: &f32_bytes(&params), usage: wgpu::BufferUsages::UNIFORM });
        let view = |t: &wgpu::Texture| t.create_view(&Default::default());
        let (cumulus, shadow, gbuffer, low, high) = (view(&self.cumulus), view(&self.shadow), view(&self.gbuffer), view(&self.noise.low), view(&self.noise.high));
        use wgpu::BindingResource::{Sampler, TextureView};
        let entry = |binding, resource| wgpu::BindGroupEntry { binding, resource };
        let params_entry = || entry(0, uniform.as_entire_binding());
        let passes: [(&wgpu::ComputePipeline, Vec<wgpu::BindGroupEntry>, [u32; 3]); 3] = [
            (&self.cumulus_pipeline, vec![params_entry(), entry(1, TextureView(&cumulus))], [CUMULUS_SIZE / 8, CUMULUS_SIZE / 8, 1]),
            (
                &self.shadow_pipeline,
                vec![params_entry(), entry(2, TextureView(&shadow)), entry(4, TextureView(&cumulus)), entry(5, TextureView(&self.coverage)), entry(9, Sampler(&self.clamped))],
                SHADOW_CELLS.map(|n| n / 4),
            ),
            (
                &self.gbuffer_pipeline,
                vec![
                    params_entry(),
                    entry(3, TextureView(&gbuffer)),
                    entry(4, TextureView(&cumulus)),
                    entry(5, TextureView(&self.coverage)),
                    entry(6, TextureView(&low)),
                    entry(7, TextureView(&high)),
                    entry(8, TextureView(&shadow)),
                    entry(9, Sampler(&self.clamped)),
                    entry(10, Sampler(&self.repeating)),
                ],
                [self.gbuffer.width().div_ceil(8), self.gbuffer.width().div_ceil(8), 1],
            ),
        ];
        let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("clouds") });
        for (pipeline, entries, groups) in passes {
            let layout = pipeline.get_bind_group_layout(0);
            let bind = gpu.checked("cloud bind group", || gpu.device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some("clouds"), layout: &layout, entries: &entries }))?;
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("clouds"), timestamp_writes: None });
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, &bind, &[]);
            pass.dispatch_workgroups(groups[0], groups[1], groups[2]);
        }
        gpu.checked("clouds", || gpu.queue.submit([encoder.finish()]))?;
        gpu.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| PreviewError::Readback(e.to_string()))?;
        Ok(start.elapsed().as_secs_f64())
    }

    /// The G-buffer's texels, row after row (see the module for the
    /// channels).
    pub fn read_gbuffer(&self, gpu: &Gpu) -> Result<Vec<[f32; 4]>, PreviewError> {
        let encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("G-buffer readback") });
        gpu.read_rgba16f(encoder, &self.gbuffer)
    }

    /// Records the lighting pass into `frame` (after the sky pass): the
    /// G-buffer lit by the frame's sun and sky over the sky so far.
    pub fn encode_lighting(&self, gpu: &Gpu, frame: &mut Frame, luts: &Luts, weather: &Weather) -> Result<(), PreviewError> {
        let (e, h, c) = (weather.sun_elevation_deg, weather.haziness, weather.cloudiness);
        let sun = luts.sun(e, h, c).ok_or_else(|| PreviewError::Bake("the bake has no sunlight LUT (made before it): bake it again to light the clouds".into()))?;
        let ambient = luts.ambient(e, h, c).ok_or_else(|| PreviewError::Bake("the bake has no ambient LUT (made before it): bake it again to light the clouds".into()))?;
        let params: Vec<f32> = sun.irradiance_rgb.iter().chain(&[0.0]).chain(&ambient.mean_radiance).chain(&[0.0]).map(|&x| x as f32).collect();
        let view = self.gbuffer.create_view(&Default::default());
        let bind = gpu.checked("cloud lighting bind group", || {
            let uniform = frame.uniform("cloud lighting params", &params);
            gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("cloud lighting"),
                layout: &self.light_layout,
                entries: &[
                    wgpu::BindGroupEntry { binding: 0, resource: uniform.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 1, resource: frame.directions.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 2, resource: frame.radiance.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 3, resource: wgpu::BindingResource::TextureView(&view) },
                    wgpu::BindGroupEntry { binding: 4, resource: wgpu::BindingResource::Sampler(&self.clamped) },
                ],
            })
        })?;
        frame.dispatch("cloud lighting", &self.light_pipeline, &bind);
        Ok(())
    }
}
