//! A preview session: the bake's LUTs and the clouds on the GPU, rendered
//! frame after frame for a sequence of states (a still is one frame). The
//! pipeline of `sky preview` in the library; the CLI only reads arguments
//! and writes files.
//!
//! Each frame: the sky pass, the clouds' lighting (their G-buffer, computed
//! at once for the first frame, then amortised over the frames as the
//! talk's), the terrain and the global fog.

use super::clouds::{Amortisation, CloudSettings, Clouds, CUMULUS_SPAN_KM};
use super::frame::{Frame, Rendered};
use super::gpu::Gpu;
use super::landscape::{Ground, LandscapePass, OcclusionGrid};
use super::sky_pass::{sun_pixel, SkyPass, Weather};
use super::PreviewError;
use crate::directions::camera::Camera;
use crate::look::timeline::FrameState;
use crate::lut::decode::{pixel_directions, Luts};
use glam::DVec3;

/// How the clouds are made.
#[derive(Debug, Clone)]
pub struct CloudOptions {
    /// The coverage texture (`cloud_coverage`).
    pub coverage: Vec<[u8; 4]>,
    pub gbuffer_size: u32,
    /// Marches a texel per G-buffer, and frames per march of every texel.
    pub samples: u32,
    pub schedule: Amortisation,
}

/// What a session draws.
#[derive(Debug, Clone)]
pub struct PreviewOptions {
    pub sun_disk: bool,
    /// The landscape and its fog (None: the sky alone).
    pub ground: Option<Ground>,
    /// The clouds (None: none).
    pub clouds: Option<CloudOptions>,
}

/// A rendered frame.
pub struct FrameOutput {
    pub rendered: Rendered,
    /// Wall time of this frame's cloud work (the whole G-buffer for the
    /// first, one amortised step after), seconds.
    pub cloud_seconds: f64,
    /// A new G-buffer was swapped in at this frame.
    pub gbuffer_swapped: bool,
}

/// The passes of a bake on a device.
pub struct PreviewSession<'l> {
    pub gpu: Gpu,
    luts: &'l Luts,
    options: PreviewOptions,
    sky: SkyPass,
    landscape: Option<LandscapePass>,
    clouds: Option<Clouds>,
    frames: usize,
    /// The last view and its pixels' directions.
    view: Option<((Camera, usize, usize), Vec<Option<DVec3>>)>,
}

impl<'l> PreviewSession<'l> {
    /// Uploads the bake and builds what `options` ask for.
    pub fn new(gpu: Gpu, luts: &'l Luts, options: PreviewOptions) -> Result<PreviewSession<'l>, PreviewError> {
        let sky = SkyPass::new(&gpu, luts)?;
        let landscape = match options.ground {
            Some(_) => Some(LandscapePass::new(&gpu, luts)?),
            None => None,
        };
        let clouds = match &options.clouds {
            Some(c) => Some(Clouds::new(&gpu, &c.coverage, c.gbuffer_size, CloudSettings::default().seed)?),
            None => None,
        };
        Ok(PreviewSession { gpu, luts, options, sky, landscape, clouds, frames: 0, view: None })
    }

    /// The clouds, for reading their G-buffer.
    pub fn clouds(&self) -> Option<&Clouds> {
        self.clouds.as_ref()
    }

    /// The next frame, for `state`, through `camera` at `width` x `height`.
    pub fn render(
        &mut self,
        state: &FrameState,
        camera: &Camera,
        width: usize,
        height: usize,
    ) -> Result<FrameOutput, PreviewError> {
        let key = (camera.clone(), width, height);
        if self.view.as_ref().is_none_or(|v| v.0 != key) {
            self.view = Some((key, pixel_directions(camera, width, height)));
        }
        let dirs = &self.view.as_ref().expect("just set").1;
        let weather = Weather {
            sun_elevation_deg: state.sun_elevation_deg,
            sun_azimuth_deg: state.sun_azimuth_deg,
            haziness: state.haziness,
            cloudiness: state.cloudiness,
            sun_disk: self.options.sun_disk,
        };
        let (mut cloud_seconds, mut gbuffer_swapped) = (0.0, false);
        if let (Some(clouds), Some(o)) = (self.clouds.as_mut(), &self.options.clouds) {
            let settings = CloudSettings {
                cover: state.cumulus_cover,
                wind_offset_km: state.wind_offset_km,
                samples: o.samples,
                ..CloudSettings::default()
            };
            if self.frames == 0 {
                cloud_seconds = clouds.compute(&self.gpu, &weather, &settings, u32::MAX / 2)?;
            } else {
                let start = std::time::Instant::now();
                gbuffer_swapped = clouds.step(&self.gpu, &weather, &settings, &o.schedule)?.swapped;
                cloud_seconds = start.elapsed().as_secs_f64();
            }
        }
        let mut frame = Frame::new(&self.gpu, dirs)?;
        let sun_pixel = sun_pixel(self.luts, &weather, camera, width, height, dirs);
        self.sky.encode_with_sun_pixel(&self.gpu, &mut frame, self.luts, &weather, sun_pixel)?;
        if let Some(clouds) = &self.clouds {
            clouds.encode_lighting(&self.gpu, &mut frame, self.luts, &weather)?;
        }
        if let (Some(landscape), Some(ground)) = (&self.landscape, &self.options.ground) {
            let view = self.clouds.as_ref().map(|c| c.occlusion_grid());
            let defaults = CloudSettings::default();
            let grid = view.as_ref().map(|view| OcclusionGrid {
                view,
                half_span_km: 0.5 * CUMULUS_SPAN_KM,
                top_km: defaults.base_km,
                planet_radius_km: defaults.planet_radius_km,
            });
            landscape.encode(&self.gpu, &mut frame, self.luts, &weather, ground, grid.as_ref())?;
        }
        let rendered = frame.finish()?;
        self.frames += 1;
        Ok(FrameOutput { rendered, cloud_seconds, gbuffer_swapped })
    }
}
