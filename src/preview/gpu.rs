//! The wgpu device a preview runs on, headless. The backend follows
//! `WGPU_BACKEND` (`vulkan` in the tests and CI: on the GL fallback some
//! formats are missing and 2-D arrays read back as zeros, see
//! `../shared/TOOLCHAIN.md`), the adapter `WGPU_ADAPTER_NAME`.

use super::PreviewError;

/// An adapter, its device and queue.
pub struct Gpu {
    pub adapter: wgpu::Adapter,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
}

impl Gpu {
    /// Opens the adapter the environment names, or the default one.
    pub fn new() -> Result<Gpu, PreviewError> {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = pollster::block_on(wgpu::util::initialize_adapter_from_env_or_default(&instance, None))
            .map_err(|e| PreviewError::NoAdapter(e.to_string()))?;
        // Timestamp queries where the adapter has them (lavapipe does), for
        // per-pass GPU times; nothing else beyond the defaults.
        let wanted = wgpu::Features::TIMESTAMP_QUERY;
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("sky preview"),
            required_features: adapter.features() & wanted,
            required_limits: wgpu::Limits::default(),
            ..Default::default()
        }))
        .map_err(|e| PreviewError::Device(e.to_string()))?;
        Ok(Gpu { adapter, device, queue })
    }

    /// The adapter's name and backend, for reports.
    pub fn describe(&self) -> String {
        let info = self.adapter.get_info();
        format!("{} ({:?}, {:?})", info.name, info.backend, info.device_type)
    }

    /// Whether the device writes timestamps (per-pass GPU times).
    pub fn has_timestamps(&self) -> bool {
        self.device.features().contains(wgpu::Features::TIMESTAMP_QUERY)
    }

    /// A 2-D array texture of `format` made from `bytes` (layer after
    /// layer, rows of texels), as a view for `textureLoad`.
    pub fn array_texture(
        &self,
        label: &str,
        format: wgpu::TextureFormat,
        width: usize,
        height: usize,
        layers: usize,
        bytes: &[u8],
    ) -> Result<wgpu::TextureView, PreviewError> {
        use wgpu::util::DeviceExt;
        let size = wgpu::Extent3d { width: width as u32, height: height as u32, depth_or_array_layers: layers as u32 };
        let texture = self.checked("texture upload", || {
            self.device.create_texture_with_data(
                &self.queue,
                &wgpu::TextureDescriptor {
                    label: Some(label),
                    size,
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format,
                    usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                    view_formats: &[],
                },
                wgpu::util::TextureDataOrder::LayerMajor,
                bytes,
            )
        })?;
        Ok(texture.create_view(&wgpu::TextureViewDescriptor {
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        }))
    }

    /// A compute pipeline of `entry` in the WGSL `source`, with one bind
    /// group of `entries`.
    pub fn compute_pipeline(
        &self,
        label: &'static str,
        source: &str,
        entry: &str,
        entries: &[wgpu::BindGroupLayoutEntry],
    ) -> Result<(wgpu::BindGroupLayout, wgpu::ComputePipeline), PreviewError> {
        self.compute_pipeline_with(label, source, entry, entries, &[])
    }

    /// [`Gpu::compute_pipeline`] with the shader's `override` constants set
    /// (name, value): a variant compiled without the branches it does not
    /// take.
    pub fn compute_pipeline_with(
        &self,
        label: &'static str,
        source: &str,
        entry: &str,
        entries: &[wgpu::BindGroupLayoutEntry],
        constants: &[(&str, f64)],
    ) -> Result<(wgpu::BindGroupLayout, wgpu::ComputePipeline), PreviewError> {
        self.checked(label, || {
            let layout =
                self.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(label), entries });
            let module = self.device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(label),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            });
            let pipeline_layout = self.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some(label),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
            let pipeline = self.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(label),
                layout: Some(&pipeline_layout),
                module: &module,
                entry_point: Some(entry),
                compilation_options: wgpu::PipelineCompilationOptions { constants, ..Default::default() },
                cache: None,
            });
            (layout, pipeline)
        })
    }

    /// A compute pipeline of `entry` in `source` whose bind group layout
    /// wgpu derives from the shader (`pipeline.get_bind_group_layout(0)`):
    /// for modules of several entry points, each using some of the
    /// bindings.
    pub fn compute_pipeline_auto(
        &self,
        label: &'static str,
        module: &wgpu::ShaderModule,
        entry: &str,
    ) -> Result<wgpu::ComputePipeline, PreviewError> {
        self.checked(label, || {
            self.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(label),
                layout: None,
                module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            })
        })
    }

    /// A uniform buffer holding `values`.
    pub fn uniform(&self, label: &'static str, values: &[f32]) -> wgpu::Buffer {
        use wgpu::util::DeviceExt;
        self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: &f32_bytes(values),
            usage: wgpu::BufferUsages::UNIFORM,
        })
    }

    /// The shader module of WGSL `source`.
    pub fn module(&self, label: &'static str, source: &str) -> Result<wgpu::ShaderModule, PreviewError> {
        self.checked(label, || {
            self.device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(label),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            })
        })
    }

    /// Submits `encoder` and reads `texture` (RGBA16F, one mip) back as
    /// RGBA f32 texels, layer after layer, row after row.
    pub fn read_rgba16f(
        &self,
        mut encoder: wgpu::CommandEncoder,
        texture: &wgpu::Texture,
    ) -> Result<Vec<[f32; 4]>, PreviewError> {
        let size = texture.size();
        let depth = match texture.dimension() {
            wgpu::TextureDimension::D3 => size.depth_or_array_layers,
            _ => size.depth_or_array_layers.max(1),
        };
        let row = (8 * size.width).div_ceil(256) * 256;
        let bytes = u64::from(row) * u64::from(size.height) * u64::from(depth);
        let buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("texture readback"),
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        encoder.copy_texture_to_buffer(
            texture.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(row),
                    rows_per_image: Some(size.height),
                },
            },
            wgpu::Extent3d { width: size.width, height: size.height, depth_or_array_layers: depth },
        );
        self.checked("texture readback", || self.queue.submit([encoder.finish()]))?;
        let data = super::frame::map(self, &buffer)?;
        let mut out = Vec::with_capacity((size.width * size.height * depth) as usize);
        for r in 0..(size.height * depth) as usize {
            let line = &data[r * row as usize..];
            for x in 0..size.width as usize {
                let h: [u16; 4] =
                    std::array::from_fn(|c| u16::from_le_bytes([line[8 * x + 2 * c], line[8 * x + 2 * c + 1]]));
                out.push(crate::lut::rgba16f::unpack(h));
            }
        }
        Ok(out)
    }

    /// Runs `f` and turns a validation error it caused into a
    /// [`PreviewError::Validation`] naming `what`.
    pub fn checked<T>(&self, what: &'static str, f: impl FnOnce() -> T) -> Result<T, PreviewError> {
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let value = f();
        match pollster::block_on(scope.pop()) {
            Some(e) => Err(PreviewError::Validation { what, message: e.to_string() }),
            None => Ok(value),
        }
    }
}

/// A compute shader's buffer binding: uniform, or storage read-only or not.
pub fn buffer_entry(binding: u32, ty: wgpu::BufferBindingType) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer { ty, has_dynamic_offset: false, min_binding_size: None },
        count: None,
    }
}

/// A compute shader's 2-D array texture binding, read by `textureLoad`
/// (filtering is done by hand, in f32, as the CPU decoder does it).
pub fn array_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable: false },
            view_dimension: wgpu::TextureViewDimension::D2Array,
            multisampled: false,
        },
        count: None,
    }
}

/// The bytes of `values`, little-endian, for a uniform or storage buffer.
pub fn f32_bytes(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|x| x.to_le_bytes()).collect()
}
