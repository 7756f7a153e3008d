//! The cumulus clouds of the preview (`shaders/clouds.wgsl`, lit by
//! `shaders/cloud_lighting.wgsl`): the cumulus map, the distant-cloud
//! shadow volume and the cloud G-buffer over the upper hemisphere from the
//! world's centre, in the talk's square-to-disk mapping, RGBA16F: opacity to
//! the sky, distance to the clouds (km), sun in-scatter (per unit of sun
//! irradiance) and ambient in-scatter (per unit of the sky's mean
//! radiance). The G-buffer holds no light: the lighting pass multiplies it
//! by the frame's sun and sky from the LUTs, so these can change every
//! frame while the G-buffer is being computed.
//!
//! Two ways to compute it: at once ([`Clouds::compute`], a still), or
//! amortised as the talk does ([`Clouds::step`]): one march per texel
//! spread over `frames_per_sample` frames in 8 × 8 tiles, `samples`
//! marches per texel accumulated into a back buffer while the display
//! shows the previous two, then swapped in and blended over
//! `blend_frames` frames.

use super::cloud_coverage::{COVERAGE_HEIGHT, COVERAGE_WIDTH};
use super::cloud_noise::CloudNoise;
use super::frame::Frame;
use super::gpu::{buffer_entry, Gpu};
use super::sky_pass::Weather;
use super::PreviewError;
use crate::lut::decode::Luts;
use wgpu::util::DeviceExt;

/// The cumulus map's texels per side (the talk's 256) and the world it
/// covers, km (the talk's 240).
pub const CUMULUS_SIZE: u32 = 256;
pub const CUMULUS_SPAN_KM: f64 = 240.0;
/// The distant-cloud shadow volume's cells: x, y over the map, z from
/// the ground to the cloud top.
const SHADOW_CELLS: [u32; 3] = [64, 64, 16];
/// The cloud-occlusion grid of the fog's air: x, y over the map, z from
/// the ground to the cloud base.
pub const OCCLUSION_CELLS: [u32; 3] = [64, 64, 4];
/// The G-buffer's tiles (the talk: "one tile corresponds to one wavefront").
pub const TILE: u32 = 8;

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
    /// Jittered marches averaged per texel (per G-buffer, when amortised),
    /// and steps per march.
    pub samples: u32,
    pub steps: u32,
    pub seed: u32,
}

impl Default for CloudSettings {
    fn default() -> Self {
        CloudSettings {
            cover: 0.4,
            wind_offset_km: [0.0, 0.0],
            planet_radius_km: 6371.0,
            base_km: 1.5,
            top_km: 5.0,
            extinction_per_km: 40.0,
            samples: 4,
            steps: 48,
            seed: 1,
        }
    }
}

/// How the amortised G-buffer spreads its work.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Amortisation {
    /// Frames one march of every texel is spread over (the talk: 64 on
    /// PS4, 32 on PS5); it divides 64, the texels of a tile.
    pub frames_per_sample: u32,
    /// Frames over which the display moves from one G-buffer to the next.
    pub blend_frames: u32,
}

/// The Wrenninge et al. 2013 octaves: attenuation a, contribution b,
/// eccentricity c per octave; a <= b (Hillaire 2016: so that energy is
/// conserved).
const OCTAVES_ABC: [f32; 3] = [0.5, 0.5, 0.5];

/// The clouds' textures, pipelines and the amortised G-buffer's state.
pub struct Clouds {
    pub noise: CloudNoise,
    coverage: wgpu::TextureView,
    cumulus: wgpu::Texture,
    shadow: wgpu::Texture,
    occlusion: wgpu::Texture,
    /// The G-buffers: displayed previous, displayed current, being computed.
    buffers: [wgpu::Texture; 3],
    /// The amortised marches' sums and counts, two vec4 a texel.
    accum: wgpu::Buffer,
    clamped: wgpu::Sampler,
    repeating: wgpu::Sampler,
    pipelines: Pipelines,
    /// Where the amortised G-buffer is: frame within the cycle, cycles
    /// done, and how far the display has moved to the current buffer.
    frame_in_cycle: u32,
    cycles: u32,
    blend: f64,
}

/// The clouds shader's entry points.
#[derive(Clone, Copy)]
enum Pass {
    Cumulus,
    Shadow,
    Occlusion,
    Whole,
    Tiles,
    Resolve,
}

struct Pipelines {
    cumulus: wgpu::ComputePipeline,
    shadow: wgpu::ComputePipeline,
    occlusion: wgpu::ComputePipeline,
    gbuffer: wgpu::ComputePipeline,
    tiles: wgpu::ComputePipeline,
    resolve: wgpu::ComputePipeline,
    light_layout: wgpu::BindGroupLayout,
    light: wgpu::ComputePipeline,
}

/// What one amortised step did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepReport {
    /// A G-buffer was finished and swapped in this step.
    pub swapped: bool,
    /// Frames into the cycle after this step, and the display's blend.
    pub frame_in_cycle: u32,
    pub blend: f64,
}

fn storage_texture(
    gpu: &Gpu,
    label: &'static str,
    size: [u32; 3],
    dimension: wgpu::TextureDimension,
) -> Result<wgpu::Texture, PreviewError> {
    gpu.checked(label, || {
        gpu.device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d { width: size[0], height: size[1], depth_or_array_layers: size[2] },
            mip_level_count: 1,
            sample_count: 1,
            dimension,
            format: wgpu::TextureFormat::Rgba16Float,
            usage: wgpu::TextureUsages::STORAGE_BINDING
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC
                | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        })
    })
}

/// The clouds shader's `Params`.
fn params(
    settings: &CloudSettings,
    weather: &Weather,
    gbuffer_size: u32,
    first_sample: u32,
    tiles: [f64; 4],
) -> Vec<f32> {
    let to_sun = crate::directions::camera::direction_deg(90.0 - weather.sun_elevation_deg, weather.sun_azimuth_deg);
    let [a, b, c] = OCTAVES_ABC.map(f64::from);
    [
        [settings.planet_radius_km, settings.base_km, settings.top_km, 0.5 * CUMULUS_SPAN_KM],
        [to_sun.x, to_sun.y, to_sun.z, settings.cover.clamp(0.0, 1.0)],
        [
            settings.wind_offset_km[0],
            settings.wind_offset_km[1],
            f64::from(gbuffer_size),
            f64::from(settings.samples.max(1)),
        ],
        [settings.extinction_per_km, a, b, c],
        [f64::from(first_sample), f64::from(settings.seed), f64::from(settings.steps.max(1)), 0.0],
        tiles,
    ]
    .iter()
    .flatten()
    .map(|&x| x as f32)
    .collect()
}

impl Clouds {
    /// Builds the noise, uploads `coverage` (256 × 128, rows from the base
    /// up, `cloud_coverage`) and makes the pipelines and G-buffers of
    /// `gbuffer_size`² texels.
    pub fn new(gpu: &Gpu, coverage: &[[u8; 4]], gbuffer_size: u32, seed: u32) -> Result<Clouds, PreviewError> {
        if coverage.len() != (COVERAGE_WIDTH * COVERAGE_HEIGHT) as usize || gbuffer_size == 0 {
            return Err(PreviewError::Bake(
                "the coverage texture must be 256 x 128 and the G-buffer at least 1 texel".into(),
            ));
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
        let occlusion = storage_texture(gpu, "cloud occlusion", OCCLUSION_CELLS, wgpu::TextureDimension::D3)?;
        let g = [gbuffer_size, gbuffer_size, 1];
        let buffers = [
            storage_texture(gpu, "cloud G-buffer", g, d2)?,
            storage_texture(gpu, "cloud G-buffer", g, d2)?,
            storage_texture(gpu, "cloud G-buffer", g, d2)?,
        ];
        let texels = u64::from(gbuffer_size) * u64::from(gbuffer_size);
        let accum = gpu.checked("G-buffer sums", || {
            gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("G-buffer sums"),
                size: 32 * texels,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        })?;
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
        let (clamped, repeating) =
            (sampler("clamped", wgpu::AddressMode::ClampToEdge), sampler("repeating", wgpu::AddressMode::Repeat));
        let module = gpu.module("clouds.wgsl", super::shaders::CLOUDS)?;
        use wgpu::BufferBindingType::{Storage, Uniform};
        let sampled = |binding| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Texture {
                sample_type: wgpu::TextureSampleType::Float { filterable: true },
                view_dimension: wgpu::TextureViewDimension::D2,
                multisampled: false,
            },
            count: None,
        };
        let light_entries = [
            buffer_entry(0, Uniform),
            buffer_entry(1, Storage { read_only: true }),
            buffer_entry(2, Storage { read_only: false }),
            sampled(3),
            wgpu::BindGroupLayoutEntry {
                binding: 4,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                count: None,
            },
            sampled(5),
        ];
        let (light_layout, light) =
            gpu.compute_pipeline("cloud lighting", super::shaders::CLOUD_LIGHTING, "light", &light_entries)?;
        let pipelines = Pipelines {
            cumulus: gpu.compute_pipeline_auto("cumulus map", &module, "cumulus_map")?,
            shadow: gpu.compute_pipeline_auto("distant-cloud shadow", &module, "shadow_volume")?,
            occlusion: gpu.compute_pipeline_auto("cloud occlusion", &module, "occlusion_volume")?,
            gbuffer: gpu.compute_pipeline_auto("cloud G-buffer", &module, "gbuffer")?,
            tiles: gpu.compute_pipeline_auto("cloud G-buffer tiles", &module, "gbuffer_tiles")?,
            resolve: gpu.compute_pipeline_auto("cloud G-buffer resolve", &module, "resolve")?,
            light_layout,
            light,
        };
        let clouds = Clouds {
            noise,
            coverage: coverage.create_view(&Default::default()),
            cumulus,
            shadow,
            occlusion,
            buffers,
            accum,
            clamped,
            repeating,
            pipelines,
            frame_in_cycle: 0,
            cycles: 0,
            blend: 1.0,
        };
        clouds.clear_sums(gpu)?;
        Ok(clouds)
    }

    /// The G-buffers' texels per side.
    pub fn gbuffer_size(&self) -> u32 {
        self.buffers[0].width()
    }

    fn clear_sums(&self, gpu: &Gpu) -> Result<(), PreviewError> {
        let mut encoder =
            gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("clear G-buffer sums") });
        encoder.clear_buffer(&self.accum, 0, None);
        gpu.checked("clear G-buffer sums", || gpu.queue.submit([encoder.finish()]))?;
        Ok(())
    }

    /// Records one pass of the clouds shader with the bindings its entry
    /// point uses (a derived layout holds exactly those, and a bind group
    /// must give exactly them); `target` is the G-buffer it writes.
    fn record(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        pass: Pass,
        uniform: &wgpu::Buffer,
        target: Option<&wgpu::Texture>,
        groups: [u32; 3],
    ) -> Result<(), PreviewError> {
        let view = |t: &wgpu::Texture| t.create_view(&Default::default());
        let (cumulus, shadow, low, high) =
            (view(&self.cumulus), view(&self.shadow), view(&self.noise.low), view(&self.noise.high));
        let occlusion = view(&self.occlusion);
        let target = target.map(view);
        use wgpu::BindingResource::{Sampler, TextureView};
        let (pipeline, wants): (&wgpu::ComputePipeline, &[u32]) = match pass {
            Pass::Cumulus => (&self.pipelines.cumulus, &[0, 1]),
            Pass::Shadow => (&self.pipelines.shadow, &[0, 2, 4, 5, 9]),
            Pass::Occlusion => (&self.pipelines.occlusion, &[0, 4, 5, 9, 12]),
            Pass::Whole => (&self.pipelines.gbuffer, &[0, 3, 4, 5, 6, 7, 8, 9, 10]),
            Pass::Tiles => (&self.pipelines.tiles, &[0, 3, 4, 5, 6, 7, 8, 9, 10, 11]),
            Pass::Resolve => (&self.pipelines.resolve, &[0, 3, 11]),
        };
        let resource = |binding: u32| -> Result<wgpu::BindingResource, PreviewError> {
            Ok(match binding {
                0 => uniform.as_entire_binding(),
                1 | 4 => TextureView(&cumulus),
                2 | 8 => TextureView(&shadow),
                3 => TextureView(
                    target.as_ref().ok_or_else(|| PreviewError::Bake("a G-buffer pass without a target".into()))?,
                ),
                5 => TextureView(&self.coverage),
                6 => TextureView(&low),
                7 => TextureView(&high),
                9 => Sampler(&self.clamped),
                10 => Sampler(&self.repeating),
                12 => TextureView(&occlusion),
                _ => self.accum.as_entire_binding(),
            })
        };
        let entries = wants
            .iter()
            .map(|&b| Ok(wgpu::BindGroupEntry { binding: b, resource: resource(b)? }))
            .collect::<Result<Vec<_>, PreviewError>>()?;
        let layout = pipeline.get_bind_group_layout(0);
        let bind = gpu.checked("cloud bind group", || {
            gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("clouds"),
                layout: &layout,
                entries: &entries,
            })
        })?;
        let mut compute =
            encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("clouds"), timestamp_writes: None });
        compute.set_pipeline(pipeline);
        compute.set_bind_group(0, &bind, &[]);
        compute.dispatch_workgroups(groups[0], groups[1], groups[2]);
        Ok(())
    }

    /// Records the cumulus map, the shadow volume and the occlusion grid
    /// for `weather`.
    fn record_environment(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        uniform: &wgpu::Buffer,
    ) -> Result<(), PreviewError> {
        self.record(gpu, encoder, Pass::Cumulus, uniform, None, [CUMULUS_SIZE / 8, CUMULUS_SIZE / 8, 1])?;
        self.record(gpu, encoder, Pass::Shadow, uniform, None, SHADOW_CELLS.map(|n| n / 4))?;
        self.record(gpu, encoder, Pass::Occlusion, uniform, None, OCCLUSION_CELLS.map(|n| n.div_ceil(4)))
    }

    /// The cloud-occlusion grid of the air below the clouds (R: 1 - the
    /// transmittance toward the sun), for the global fog: x, y over the
    /// cumulus map's 240 km, z from the ground to the cloud base.
    pub fn occlusion_grid(&self) -> wgpu::TextureView {
        self.occlusion.create_view(&Default::default())
    }

    fn submit(gpu: &Gpu, encoder: wgpu::CommandEncoder) -> Result<(), PreviewError> {
        gpu.checked("clouds", || gpu.queue.submit([encoder.finish()]))?;
        gpu.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| PreviewError::Readback(e.to_string()))?;
        Ok(())
    }

    /// The whole G-buffer at once for `weather` and `settings` (a still):
    /// `settings.samples` marches a texel numbered from `first_sample` (a
    /// different first sample: an independent G-buffer), shown at once
    /// (previous and current both this one). Returns the wall time, s.
    pub fn compute(
        &mut self,
        gpu: &Gpu,
        weather: &Weather,
        settings: &CloudSettings,
        first_sample: u32,
    ) -> Result<f64, PreviewError> {
        let start = std::time::Instant::now();
        let n = self.gbuffer_size();
        let uniform = gpu.uniform("cloud params", &params(settings, weather, n, first_sample, [0.0; 4]));
        let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("clouds") });
        self.record_environment(gpu, &mut encoder, &uniform)?;
        self.record(
            gpu,
            &mut encoder,
            Pass::Whole,
            &uniform,
            Some(&self.buffers[1]),
            [n.div_ceil(8), n.div_ceil(8), 1],
        )?;
        encoder.copy_texture_to_texture(
            self.buffers[1].as_image_copy(),
            self.buffers[0].as_image_copy(),
            self.buffers[1].size(),
        );
        Self::submit(gpu, encoder)?;
        self.blend = 1.0;
        Ok(start.elapsed().as_secs_f64())
    }

    /// One frame of the amortised G-buffer: at a cycle's start the cumulus
    /// map and shadow volume for this frame's `weather` and wind; every
    /// frame 64 / F texels of each tile marched once; after
    /// `settings.samples` × F frames the sums resolved into a G-buffer that
    /// becomes the current one, the old current the previous, and the
    /// display's blend starts again from the previous.
    pub fn step(
        &mut self,
        gpu: &Gpu,
        weather: &Weather,
        settings: &CloudSettings,
        schedule: &Amortisation,
    ) -> Result<StepReport, PreviewError> {
        let per_sample = schedule.frames_per_sample;
        if per_sample == 0 || 64 % per_sample != 0 {
            return Err(PreviewError::Bake(format!("frames per sample must divide 64, got {per_sample}")));
        }
        let n = self.gbuffer_size();
        let samples = settings.samples.max(1);
        let first = self.cycles.wrapping_mul(samples);
        let tiles = [f64::from(self.frame_in_cycle), f64::from(per_sample), f64::from(first), 1.0];
        let uniform = gpu.uniform("cloud params", &params(settings, weather, n, first, tiles));
        let mut encoder =
            gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("amortised clouds") });
        if self.frame_in_cycle == 0 {
            self.record_environment(gpu, &mut encoder, &uniform)?;
        }
        let invocations = n.div_ceil(TILE).pow(2) * (64 / per_sample);
        self.record(
            gpu,
            &mut encoder,
            Pass::Tiles,
            &uniform,
            Some(&self.buffers[2]),
            [invocations.div_ceil(64), 1, 1],
        )?;
        self.frame_in_cycle += 1;
        self.blend = (self.blend + 1.0 / f64::from(schedule.blend_frames.max(1))).min(1.0);
        let swapped = self.frame_in_cycle == samples * per_sample;
        if swapped {
            self.record(
                gpu,
                &mut encoder,
                Pass::Resolve,
                &uniform,
                Some(&self.buffers[2]),
                [n.div_ceil(8), n.div_ceil(8), 1],
            )?;
        }
        Self::submit(gpu, encoder)?;
        if swapped {
            self.buffers.rotate_left(1);
            self.frame_in_cycle = 0;
            self.cycles += 1;
            self.blend = 0.0;
        }
        Ok(StepReport { swapped, frame_in_cycle: self.frame_in_cycle, blend: self.blend })
    }

    /// What the amortised G-buffer being computed holds so far: each
    /// texel's marches of this cycle averaged (0 where none yet), without
    /// disturbing the cycle.
    pub fn read_progress(
        &self,
        gpu: &Gpu,
        settings: &CloudSettings,
    ) -> Result<(Vec<[f32; 4]>, Vec<f32>), PreviewError> {
        let n = self.gbuffer_size();
        let scratch = storage_texture(gpu, "G-buffer progress", [n, n, 1], wgpu::TextureDimension::D2)?;
        let uniform = gpu.uniform(
            "cloud params",
            &params(
                settings,
                &Weather {
                    sun_elevation_deg: 0.0,
                    sun_azimuth_deg: 0.0,
                    haziness: 0.0,
                    cloudiness: 0.0,
                    sun_disk: false,
                },
                n,
                0,
                [0.0; 4],
            ),
        );
        let mut encoder =
            gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("G-buffer progress") });
        self.record(gpu, &mut encoder, Pass::Resolve, &uniform, Some(&scratch), [n.div_ceil(8), n.div_ceil(8), 1])?;
        let texels = gpu.read_rgba16f(encoder, &scratch)?;
        let sums = super::frame::read_buffer(gpu, &self.accum)?;
        let counts = sums.chunks_exact(32).map(|c| f32::from_le_bytes([c[16], c[17], c[18], c[19]])).collect();
        Ok((texels, counts))
    }

    /// The current G-buffer's texels, row after row (see the module for
    /// the channels).
    pub fn read_gbuffer(&self, gpu: &Gpu) -> Result<Vec<[f32; 4]>, PreviewError> {
        let encoder =
            gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("G-buffer readback") });
        gpu.read_rgba16f(encoder, &self.buffers[1])
    }

    /// Records the lighting pass into `frame` (after the sky pass): the
    /// displayed G-buffer (previous and current blended) lit by the
    /// frame's sun and sky over the sky so far.
    pub fn encode_lighting(
        &self,
        gpu: &Gpu,
        frame: &mut Frame,
        luts: &Luts,
        weather: &Weather,
    ) -> Result<(), PreviewError> {
        let (e, h, c) = (weather.sun_elevation_deg, weather.haziness, weather.cloudiness);
        let sun = luts.sun(e, h, c).ok_or_else(|| {
            PreviewError::Bake(
                "the bake has no sunlight LUT (made before it): bake it again to light the clouds".into(),
            )
        })?;
        let ambient = luts.ambient(e, h, c).ok_or_else(|| {
            PreviewError::Bake("the bake has no ambient LUT (made before it): bake it again to light the clouds".into())
        })?;
        let params: Vec<f32> = sun
            .irradiance_rgb
            .iter()
            .chain(&[0.0])
            .chain(&ambient.mean_radiance)
            .chain(&[self.blend])
            .map(|&x| x as f32)
            .collect();
        let (current, previous) =
            (self.buffers[1].create_view(&Default::default()), self.buffers[0].create_view(&Default::default()));
        let bind = gpu.checked("cloud lighting bind group", || {
            let uniform = frame.uniform("cloud lighting params", &params);
            gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("cloud lighting"),
                layout: &self.pipelines.light_layout,
                entries: &[
                    wgpu::BindGroupEntry { binding: 0, resource: uniform.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 1, resource: frame.directions.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 2, resource: frame.radiance.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 3, resource: wgpu::BindingResource::TextureView(&current) },
                    wgpu::BindGroupEntry { binding: 4, resource: wgpu::BindingResource::Sampler(&self.clamped) },
                    wgpu::BindGroupEntry { binding: 5, resource: wgpu::BindingResource::TextureView(&previous) },
                ],
            })
        })?;
        frame.dispatch("cloud lighting", &self.pipelines.light, &bind);
        Ok(())
    }
}
