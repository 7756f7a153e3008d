//! The landscape and its global fog on the GPU: the terrain pass
//! (`shaders/terrain.wgsl`) finds the ridges of `lut::landscape` along
//! each view and lights them with the bake's sunlight and ambient LUTs
//! (a depth buffer and the surfaces' radiance); the fog pass
//! (`shaders/fog.wgsl`) puts the Fog, Shadowed Fog and Attenuation LUTs in
//! front of them. Together: `lut::landscape::decode_landscape`, the CPU
//! reference, on the GPU.
//!
//! The fog file's layers go up as they are stored (RGBA16F, the same
//! halves), but as two 64-layer arrays per basis sky, its Fog and its
//! Shadowed Fog, rather than the file's one array of every sky (1 024
//! layers for eight skies, past the 256 that WebGPU's default limits
//! promise). Per frame, the CPU works out what the whole frame shares as
//! the CPU decoder does (the weather rule's weights over the skies that
//! have fog, each sky's slice pair, the slices' scales, the falloff, the
//! geometry) and the shaders do the per-direction work.

use super::frame::Frame;
use super::gpu::{array_entry, buffer_entry, Gpu};
use super::sky_pass::{active_skies, Weather, ACTIVE_SKIES};
use super::PreviewError;
use crate::lut::decode::{slice_pair, Luts};
use crate::lut::landscape::RIDGES;
use crate::lut::manifest::FogSkyEntry;
use crate::lut::rgba16f;

/// What the landscape shows besides the weather.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ground {
    /// The ridges' albedo.
    pub albedo: f64,
    /// How much clouds shade the air: 0 (the Fog LUT) to 1 (the Shadowed
    /// Fog LUT).
    pub cloud_occlusion: f64,
}

/// The clouds' occlusion grid (`Clouds::occlusion_grid`) and where it lies.
pub struct OcclusionGrid<'a> {
    pub view: &'a wgpu::TextureView,
    /// Half its horizontal span (x and y), and its top, km.
    pub half_span_km: f64,
    pub top_km: f64,
    pub planet_radius_km: f64,
}

/// A basis sky's fog arrays on the GPU.
struct SkyFog {
    lit: wgpu::TextureView,
    shadowed: wgpu::TextureView,
}

/// The fog arrays of a bake and the two pipelines.
pub struct LandscapePass {
    /// Per manifest sky (None: no fog for it).
    fog: Vec<Option<SkyFog>>,
    attenuation: wgpu::TextureView,
    /// Bound where there is no occlusion grid (never read then).
    no_grid: wgpu::TextureView,
    clamped: wgpu::Sampler,
    terrain_layout: wgpu::BindGroupLayout,
    terrain: wgpu::ComputePipeline,
    fog_layout: wgpu::BindGroupLayout,
    fog_pipeline: wgpu::ComputePipeline,
}

/// RGBA16F bytes of stored RGB texels (alpha 1).
fn halves(texels: &[[f32; 3]], what: &str) -> Result<Vec<u8>, PreviewError> {
    let mut bytes = Vec::with_capacity(8 * texels.len());
    for t in texels {
        let h = rgba16f::pack(t.map(f64::from))
            .map_err(|e| PreviewError::Bake(format!("{what}: a texel does not pack: {e}")))?;
        bytes.extend(h.iter().flat_map(|x| x.to_le_bytes()));
    }
    Ok(bytes)
}

impl LandscapePass {
    /// Uploads the bake's fog LUTs and builds the pipelines; an error for a
    /// bake without fog.
    pub fn new(gpu: &Gpu, luts: &Luts) -> Result<LandscapePass, PreviewError> {
        let (Some(entry), Some(textures)) = (luts.manifest.fog.as_ref(), luts.fog.as_ref()) else {
            return Err(PreviewError::Bake("the bake has no fog LUTs (made before them): bake it again with this version of sky, or leave the landscape out".into()));
        };
        let format = wgpu::TextureFormat::Rgba16Float;
        let mut fog = Vec::new();
        for sky in &luts.manifest.skies {
            let Some(f) = entry.skies.iter().find(|f| f.name == sky.name) else {
                fog.push(None);
                continue;
            };
            let layers = |first: usize| -> Result<Vec<u8>, PreviewError> {
                let mut bytes = Vec::new();
                for layer in textures
                    .fog
                    .get(first..first + f.slices)
                    .ok_or_else(|| PreviewError::Bake(format!("{}: the fog file is short of layers", f.name)))?
                {
                    bytes.extend(halves(layer, &f.name)?);
                }
                Ok(bytes)
            };
            let lit =
                gpu.array_texture(&f.name, format, entry.width, entry.height, f.slices, &layers(f.first_layer)?)?;
            let shadowed = gpu.array_texture(
                &f.name,
                format,
                entry.width,
                entry.height,
                f.slices,
                &layers(f.first_layer + f.slices)?,
            )?;
            fog.push(Some(SkyFog { lit, shadowed }));
        }
        let mut bytes = Vec::new();
        for layer in &textures.attenuation {
            bytes.extend(halves(layer, "attenuation")?);
        }
        let attenuation = gpu.array_texture(
            "attenuation",
            format,
            entry.attenuation.width,
            entry.attenuation.height,
            textures.attenuation.len(),
            &bytes,
        )?;
        use wgpu::BufferBindingType::{Storage, Uniform};
        let read = Storage { read_only: true };
        let write = Storage { read_only: false };
        let (terrain_layout, terrain) = gpu.compute_pipeline(
            "terrain",
            super::shaders::TERRAIN,
            "terrain",
            &[buffer_entry(0, Uniform), buffer_entry(1, read), buffer_entry(2, write)],
        )?;
        let mut entries =
            vec![buffer_entry(0, Uniform), buffer_entry(1, read), buffer_entry(2, read), buffer_entry(3, write)];
        entries.extend((4..=10).map(array_entry));
        entries.push(wgpu::BindGroupLayoutEntry {
            binding: 11,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Texture {
                sample_type: wgpu::TextureSampleType::Float { filterable: true },
                view_dimension: wgpu::TextureViewDimension::D3,
                multisampled: false,
            },
            count: None,
        });
        entries.push(wgpu::BindGroupLayoutEntry {
            binding: 12,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
            count: None,
        });
        let no_grid = gpu.checked("empty occlusion grid", || {
            gpu.device.create_texture(&wgpu::TextureDescriptor {
                label: Some("no occlusion grid"),
                size: wgpu::Extent3d { width: 1, height: 1, depth_or_array_layers: 1 },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D3,
                format: wgpu::TextureFormat::Rgba16Float,
                usage: wgpu::TextureUsages::TEXTURE_BINDING,
                view_formats: &[],
            })
        })?;
        let no_grid = no_grid.create_view(&Default::default());
        let clamped = gpu.device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("clamped"),
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });
        let (fog_layout, fog_pipeline) = gpu.compute_pipeline("fog", super::shaders::FOG, "fog", &entries)?;
        Ok(LandscapePass { fog, attenuation, no_grid, clamped, terrain_layout, terrain, fog_layout, fog_pipeline })
    }

    /// Records the terrain and fog passes into `frame`, after the sky pass:
    /// where a view meets a ridge, the picture becomes the lit ridge seen
    /// through the fog, shaded by the clouds' `grid` where there is one
    /// (else by `ground.cloud_occlusion`).
    pub fn encode(
        &self,
        gpu: &Gpu,
        frame: &mut Frame,
        luts: &Luts,
        weather: &Weather,
        ground: &Ground,
        grid: Option<&OcclusionGrid>,
    ) -> Result<(), PreviewError> {
        let terrain_params = terrain_params(luts, weather, ground)?;
        let (mut fog_params, active) = fog_params(luts, weather, ground);
        fog_params.extend(match grid {
            Some(g) => [1.0, g.half_span_km as f32, g.top_km as f32, g.planet_radius_km as f32],
            None => [0.0, 1.0, 1.0, 6371.0],
        });
        let (terrain_bind, fog_bind) = gpu.checked("landscape bind groups", || {
            let uniform = frame.uniform("terrain params", &terrain_params);
            let terrain_bind = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("terrain"),
                layout: &self.terrain_layout,
                entries: &[
                    wgpu::BindGroupEntry { binding: 0, resource: uniform.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 1, resource: frame.directions.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 2, resource: frame.surface.as_entire_binding() },
                ],
            });
            let uniform = frame.uniform("fog params", &fog_params);
            // Unused slots hold any sky's arrays: their weight is 0 and the shader never reads them.
            let any = self.fog.iter().flatten().next().expect("a bake with fog has a sky with fog");
            let slot = |k: usize| active.get(k).and_then(|&i| self.fog[i].as_ref()).unwrap_or(any);
            let view = wgpu::BindingResource::TextureView;
            let fog_bind = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("fog"),
                layout: &self.fog_layout,
                entries: &[
                    wgpu::BindGroupEntry { binding: 0, resource: uniform.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 1, resource: frame.directions.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 2, resource: frame.surface.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 3, resource: frame.radiance.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 4, resource: view(&slot(0).lit) },
                    wgpu::BindGroupEntry { binding: 5, resource: view(&slot(0).shadowed) },
                    wgpu::BindGroupEntry { binding: 6, resource: view(&slot(1).lit) },
                    wgpu::BindGroupEntry { binding: 7, resource: view(&slot(1).shadowed) },
                    wgpu::BindGroupEntry { binding: 8, resource: view(&slot(2).lit) },
                    wgpu::BindGroupEntry { binding: 9, resource: view(&slot(2).shadowed) },
                    wgpu::BindGroupEntry { binding: 10, resource: view(&self.attenuation) },
                    wgpu::BindGroupEntry { binding: 11, resource: view(grid.map_or(&self.no_grid, |g| g.view)) },
                    wgpu::BindGroupEntry { binding: 12, resource: wgpu::BindingResource::Sampler(&self.clamped) },
                ],
            });
            (terrain_bind, fog_bind)
        })?;
        frame.dispatch("terrain", &self.terrain, &terrain_bind);
        frame.dispatch("fog", &self.fog_pipeline, &fog_bind);
        Ok(())
    }
}

/// `terrain.wgsl`'s `Params`: the sun's direction and irradiance, the
/// sky's irradiance on an upward surface, the albedo, the ridges.
fn terrain_params(luts: &Luts, weather: &Weather, ground: &Ground) -> Result<Vec<f32>, PreviewError> {
    let (e, h, c) = (weather.sun_elevation_deg, weather.haziness, weather.cloudiness);
    let sun = luts.sun(e, h, c).ok_or_else(|| {
        PreviewError::Bake("the bake has no sunlight LUT (made before it): bake it again to light the landscape".into())
    })?;
    let ambient = luts.ambient(e, h, c).ok_or_else(|| {
        PreviewError::Bake("the bake has no ambient LUT (made before it): bake it again to light the landscape".into())
    })?;
    let to_sun = crate::directions::camera::direction_deg(90.0 - e, weather.sun_azimuth_deg);
    let mut p = vec![to_sun.x as f32, to_sun.y as f32, to_sun.z as f32, ground.albedo as f32];
    p.extend(sun.irradiance_rgb.map(|x| x as f32).into_iter().chain([0.0]));
    p.extend(ambient.irradiance_up.map(|x| x as f32).into_iter().chain([RIDGES.len() as f32]));
    for k in 0..8 {
        match RIDGES.get(k) {
            Some(r) => p.extend([r.distance_km as f32, r.elevation_deg as f32, r.phase as f32, 0.0]),
            None => p.extend([0.0; 4]),
        }
    }
    Ok(p)
}

/// `fog.wgsl`'s `Params` and the manifest indices of the active skies in
/// slot order: as `Luts::fog`, the weather rule's weights renormalised
/// over the skies with fog, each sky's slice pair and its slices' scales.
fn fog_params(luts: &Luts, weather: &Weather, ground: &Ground) -> (Vec<f32>, Vec<usize>) {
    let entry = luts.manifest.fog.as_ref().expect("LandscapePass::new checked the fog");
    let fog_of = |name: &str| entry.skies.iter().find(|f| f.name == name);
    let active: Vec<(usize, &FogSkyEntry, f64)> = active_skies(luts, weather, |name| fog_of(name).is_some())
        .into_iter()
        .filter_map(|(i, w)| fog_of(&luts.manifest.skies[i].name).map(|f| (i, f, w)))
        .collect();
    let azimuth = weather.sun_azimuth_deg.to_radians();
    let mut p =
        vec![libm::cos(azimuth) as f32, libm::sin(azimuth) as f32, active.len() as f32, ground.cloud_occlusion as f32];
    for k in 0..ACTIVE_SKIES {
        match active.get(k) {
            Some(&(i, f, weight)) => {
                let (i0, i1, t) = slice_pair(&luts.manifest.skies[i], 90.0 - weather.sun_elevation_deg);
                let s = |log2: i32| (-log2 as f64).exp2() as f32;
                p.extend([weight as f32, t as f32, i0 as f32, i1 as f32]);
                p.extend([
                    s(f.fog_scale_log2[i0]),
                    s(f.fog_scale_log2[i1]),
                    s(f.shadowed_scale_log2[i0]),
                    s(f.shadowed_scale_log2[i1]),
                ]);
                p.extend([f.falloff_a as f32, f.falloff_p as f32, f.attenuation_layer as f32, 0.0]);
                p.extend([f.planet_radius_km as f32, f.observer_altitude_km as f32, entry.ceiling_km as f32, 0.0]);
            }
            None => p.extend([0.0; 16]),
        }
    }
    (p, active.into_iter().map(|a| a.0).collect())
}
