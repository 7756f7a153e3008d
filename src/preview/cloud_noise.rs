//! The clouds' noise textures, built on the GPU by the compute shaders of
//! `shaders/cloud_noise.wgsl` (see there): the low-frequency
//! Perlin-inverted Worley noise, 128³ over about 5 km and shifted to a zero
//! mean, and the high-frequency Worley noise, 32³ over about 1.2 km. Both
//! RGBA16F 3-D textures (the value in R), tileable, sampled with a
//! repeating linear sampler.

use super::gpu::{f32_bytes, Gpu};
use super::PreviewError;
use wgpu::util::DeviceExt;

/// Texels per side of the low-frequency noise (the talk's 128).
pub const LOW_SIZE: u32 = 128;
/// Texels per side of the high-frequency noise (the talk's 32).
pub const HIGH_SIZE: u32 = 32;
/// What one tile of the low-frequency noise spans, km (the talk: "about
/// 5 km scale"); the middle frequency reads it at [`MID_TILE_KM`].
pub const LOW_TILE_KM: f64 = 5.0;
/// The middle frequency: the low texture again, over about 2 km.
pub const MID_TILE_KM: f64 = 2.0;
/// One tile of the high-frequency noise, km: cells of about 300 m (its
/// first octave has 4 across).
pub const HIGH_TILE_KM: f64 = 1.2;
/// Values per partial sum of the mean.
const CHUNK: u32 = 2048;

/// The two noise textures.
pub struct CloudNoise {
    pub low: wgpu::Texture,
    pub high: wgpu::Texture,
}

impl CloudNoise {
    /// Builds both textures from `seed`.
    pub fn new(gpu: &Gpu, seed: u32) -> Result<CloudNoise, PreviewError> {
        let module = gpu.module("cloud_noise.wgsl", super::shaders::CLOUD_NOISE)?;
        let texture = |label, size| {
            gpu.checked("noise texture", || {
                gpu.device.create_texture(&wgpu::TextureDescriptor {
                    label: Some(label),
                    size: wgpu::Extent3d { width: size, height: size, depth_or_array_layers: size },
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D3,
                    format: wgpu::TextureFormat::Rgba16Float,
                    usage: wgpu::TextureUsages::STORAGE_BINDING
                        | wgpu::TextureUsages::TEXTURE_BINDING
                        | wgpu::TextureUsages::COPY_SRC,
                    view_formats: &[],
                })
            })
        };
        let (low, high) = (texture("low-frequency noise", LOW_SIZE)?, texture("high-frequency noise", HIGH_SIZE)?);
        let count = LOW_SIZE.pow(3);
        let params = |size: u32| [size, seed, CHUNK, size.pow(3)];
        let uniform = |p: [u32; 4]| {
            gpu.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("noise params"),
                contents: &p.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>(),
                usage: wgpu::BufferUsages::UNIFORM,
            })
        };
        let storage = |label, n: u32| {
            gpu.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: &f32_bytes(&vec![0.0; n as usize]),
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let (low_params, high_params) = (uniform(params(LOW_SIZE)), uniform(params(HIGH_SIZE)));
        let (values, partial) = (storage("noise values", count), storage("noise partial sums", count / CHUNK));
        let (low_view, high_view) = (low.create_view(&Default::default()), high.create_view(&Default::default()));
        let mut encoder =
            gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("cloud noise") });
        let cube = |n: u32| [n / 4, n / 4, n / 4];
        let passes: [(&'static str, &wgpu::Buffer, Option<&wgpu::TextureView>, [u32; 3]); 5] = [
            ("low_values", &low_params, None, cube(LOW_SIZE)),
            ("partial_sums", &low_params, None, [(count / CHUNK).div_ceil(64), 1, 1]),
            ("mean", &low_params, None, [1, 1, 1]),
            ("store_low", &low_params, Some(&low_view), cube(LOW_SIZE)),
            ("high", &high_params, Some(&high_view), cube(HIGH_SIZE)),
        ];
        for (entry, params, target, groups) in passes {
            let pipeline = gpu.compute_pipeline_auto("cloud noise", &module, entry)?;
            let layout = pipeline.get_bind_group_layout(0);
            // Each entry point binds what it uses (the derived layout has no other bindings).
            let mut entries = vec![wgpu::BindGroupEntry { binding: 0, resource: params.as_entire_binding() }];
            match entry {
                "low_values" => entries.push(wgpu::BindGroupEntry { binding: 1, resource: values.as_entire_binding() }),
                "partial_sums" => {
                    entries.push(wgpu::BindGroupEntry { binding: 1, resource: values.as_entire_binding() });
                    entries.push(wgpu::BindGroupEntry { binding: 2, resource: partial.as_entire_binding() });
                }
                "mean" => entries.push(wgpu::BindGroupEntry { binding: 2, resource: partial.as_entire_binding() }),
                "store_low" => {
                    entries.push(wgpu::BindGroupEntry { binding: 1, resource: values.as_entire_binding() });
                    entries.push(wgpu::BindGroupEntry { binding: 2, resource: partial.as_entire_binding() });
                }
                _ => {}
            }
            if let Some(view) = target {
                entries.push(wgpu::BindGroupEntry { binding: 3, resource: wgpu::BindingResource::TextureView(view) });
            }
            let bind = gpu.checked("cloud noise bind group", || {
                gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some(entry),
                    layout: &layout,
                    entries: &entries,
                })
            })?;
            let mut pass =
                encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some(entry), timestamp_writes: None });
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &bind, &[]);
            pass.dispatch_workgroups(groups[0], groups[1], groups[2]);
        }
        gpu.checked("cloud noise", || gpu.queue.submit([encoder.finish()]))?;
        Ok(CloudNoise { low, high })
    }

    /// One texture's values (R), x fastest, then y, then z.
    pub fn read(gpu: &Gpu, texture: &wgpu::Texture) -> Result<Vec<f32>, PreviewError> {
        let encoder =
            gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("noise readback") });
        Ok(gpu.read_rgba16f(encoder, texture)?.into_iter().map(|t| t[0]).collect())
    }
}
