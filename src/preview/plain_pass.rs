//! The baseline of the sky pass's benchmark (`sky bench preview`): a plain
//! textured full-screen pass (`shaders/plain_texture.wgsl`), one filtered
//! sample of one sky array per direction. Its time is what drawing a sky
//! from a single ready texture costs, so the sky pass's time over it is
//! the price of decoding the LUTs (mappings, slices, weather blend).

use super::frame::Frame;
use super::gpu::{buffer_entry, Gpu};
use super::PreviewError;

/// The pipeline, the array it samples and its sampler.
pub struct PlainPass {
    texture: wgpu::TextureView,
    sampler: wgpu::Sampler,
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
}

impl PlainPass {
    /// A pass sampling `texture` (a 2-D array of a filterable format).
    pub fn new(gpu: &Gpu, texture: wgpu::TextureView) -> Result<PlainPass, PreviewError> {
        use wgpu::BufferBindingType::Storage;
        let entries = [
            buffer_entry(0, Storage { read_only: true }),
            buffer_entry(1, Storage { read_only: false }),
            wgpu::BindGroupLayoutEntry {
                binding: 2,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Float { filterable: true },
                    view_dimension: wgpu::TextureViewDimension::D2Array,
                    multisampled: false,
                },
                count: None,
            },
            wgpu::BindGroupLayoutEntry {
                binding: 3,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                count: None,
            },
        ];
        let (layout, pipeline) =
            gpu.compute_pipeline("plain texture", super::shaders::PLAIN_TEXTURE, "plain", &entries)?;
        let sampler = gpu.device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("linear"),
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });
        Ok(PlainPass { texture, sampler, layout, pipeline })
    }

    /// Records the pass into `frame` (it writes the frame's radiance).
    pub fn encode(&self, gpu: &Gpu, frame: &mut Frame) -> Result<(), PreviewError> {
        let bind = gpu.checked("plain texture bind group", || {
            gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("plain texture"),
                layout: &self.layout,
                entries: &[
                    wgpu::BindGroupEntry { binding: 0, resource: frame.directions.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 1, resource: frame.radiance.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::TextureView(&self.texture) },
                    wgpu::BindGroupEntry { binding: 3, resource: wgpu::BindingResource::Sampler(&self.sampler) },
                ],
            })
        })?;
        frame.dispatch("plain texture", &self.pipeline, &bind);
        Ok(())
    }
}
