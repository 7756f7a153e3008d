//! One frame of the preview on the GPU: the view directions, the buffers
//! the passes share, one command encoder, and the GPU's time per pass.
//!
//! A frame works on a list of directions (one per pixel; `None` outside the
//! camera's view), so that the cameras stay the CPU's (`directions::camera`)
//! and every pass can be read back and checked against the CPU decoder
//! direction by direction. The buffers, one `vec4<f32>` per direction:
//! - `directions`: the unit vector (world frame, z up), w = 1 where the
//!   pixel sees something, 0 outside the view;
//! - `surface`: what the terrain pass finds (the lit surface's RGB, w = its
//!   depth in km; w = 0 where the view meets no terrain);
//! - `radiance`: the picture so far, linear RGB.
//!
//! Each pass is a compute dispatch of one invocation per direction. Where
//! the device has timestamp queries each pass's GPU time is measured
//! (`Rendered::passes`); the wall time of the whole frame always is.

use super::gpu::{f32_bytes, Gpu};
use super::PreviewError;
use glam::DVec3;
use std::time::Instant;
use wgpu::util::DeviceExt;

/// Invocations per workgroup of every per-direction pass (the shaders'
/// `@workgroup_size`).
pub const WORKGROUP: u32 = 64;
/// The most passes a frame times.
const MAX_TIMED: u32 = 16;

/// A frame being recorded.
pub struct Frame<'g> {
    gpu: &'g Gpu,
    pub directions: wgpu::Buffer,
    pub surface: wgpu::Buffer,
    pub radiance: wgpu::Buffer,
    count: usize,
    encoder: wgpu::CommandEncoder,
    queries: Option<wgpu::QuerySet>,
    passes: Vec<&'static str>,
    start: Instant,
    undo: Undo,
}

/// What to undo if a frame is dropped before its commands are submitted
/// (an error on the way): state that a pass recorded as done, such as a
/// composition the next frames would reuse.
#[derive(Default)]
struct Undo(Vec<Box<dyn FnOnce()>>);

impl Drop for Undo {
    fn drop(&mut self) {
        for undo in self.0.drain(..) {
            undo();
        }
    }
}

/// A finished frame, read back.
pub struct Rendered {
    /// Linear RGB per direction (0 outside the view).
    pub rgb: Vec<[f32; 3]>,
    /// The picture's fourth channel: on the terrain the cloud occlusion the
    /// fog pass used, elsewhere 1 (0 outside the view).
    pub alpha: Vec<f32>,
    /// The surface buffer: the terrain's lit RGB and depth (km; 0: none).
    pub surface: Vec<[f32; 4]>,
    /// Wall time from the first upload to the readback, seconds.
    pub seconds: f64,
    /// Each pass's GPU time, seconds, in the order recorded; empty where
    /// the device has no timestamp queries.
    pub passes: Vec<(&'static str, f64)>,
}

impl<'g> Frame<'g> {
    /// A frame over `dirs`.
    pub fn new(gpu: &'g Gpu, dirs: &[Option<DVec3>]) -> Result<Frame<'g>, PreviewError> {
        let start = Instant::now();
        let count = dirs.len();
        let mut data: Vec<f32> =
            dirs.iter().flat_map(|d| d.map_or([0.0; 4], |d| [d.x as f32, d.y as f32, d.z as f32, 1.0])).collect();
        if data.is_empty() {
            data = vec![0.0; 4];
        }
        let size = 4 * data.len() as u64;
        let (directions, surface, radiance, queries) = gpu.checked("frame buffers", || {
            let directions = gpu.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("directions"),
                contents: &f32_bytes(&data),
                usage: wgpu::BufferUsages::STORAGE,
            });
            let storage = |label| {
                gpu.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size,
                    usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                })
            };
            let queries = gpu.has_timestamps().then(|| {
                gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
                    label: Some("pass times"),
                    ty: wgpu::QueryType::Timestamp,
                    count: 2 * MAX_TIMED,
                })
            });
            (directions, storage("surface"), storage("radiance"), queries)
        })?;
        let encoder =
            gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("preview frame") });
        let (passes, undo) = (Vec::new(), Undo::default());
        Ok(Frame { gpu, directions, surface, radiance, count, encoder, queries, passes, start, undo })
    }

    /// The number of directions.
    pub fn count(&self) -> usize {
        self.count
    }

    /// Records a per-direction pass: `pipeline` with `bind` over every
    /// direction, timed as `name`.
    pub fn dispatch(&mut self, name: &'static str, pipeline: &wgpu::ComputePipeline, bind: &wgpu::BindGroup) {
        self.dispatch_groups(name, pipeline, bind, [(self.count.max(1) as u32).div_ceil(WORKGROUP), 1, 1]);
    }

    /// Records a pass of `groups` workgroups (a pass over something other
    /// than the directions), timed as `name`.
    pub fn dispatch_groups(
        &mut self,
        name: &'static str,
        pipeline: &wgpu::ComputePipeline,
        bind: &wgpu::BindGroup,
        groups: [u32; 3],
    ) {
        let index = self.passes.len() as u32;
        let timestamp_writes =
            self.queries.as_ref().filter(|_| index < MAX_TIMED).map(|q| wgpu::ComputePassTimestampWrites {
                query_set: q,
                beginning_of_pass_write_index: Some(2 * index),
                end_of_pass_write_index: Some(2 * index + 1),
            });
        let mut pass =
            self.encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some(name), timestamp_writes });
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, bind, &[]);
        pass.dispatch_workgroups(groups[0], groups[1], groups[2]);
        drop(pass);
        self.passes.push(name);
    }

    /// Runs `undo` if the frame is dropped before it is submitted.
    pub fn on_abandoned(&mut self, undo: impl FnOnce() + 'static) {
        self.undo.0.push(Box::new(undo));
    }

    /// A uniform buffer holding `values`.
    pub fn uniform(&self, label: &'static str, values: &[f32]) -> wgpu::Buffer {
        self.gpu.uniform(label, values)
    }

    /// Submits the frame, waits for it and reads back the picture, the
    /// surface buffer and the pass times.
    pub fn finish(mut self) -> Result<Rendered, PreviewError> {
        let gpu = self.gpu;
        let size = self.radiance.size();
        let timed = (self.passes.len() as u32).min(MAX_TIMED);
        let readback = |label| {
            gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        let (rgb_back, surface_back) = (readback("radiance readback"), readback("surface readback"));
        self.encoder.copy_buffer_to_buffer(&self.radiance, 0, &rgb_back, 0, size);
        self.encoder.copy_buffer_to_buffer(&self.surface, 0, &surface_back, 0, size);
        let times_back = match (&self.queries, timed) {
            (Some(q), 1..) => {
                let bytes = 16 * timed as u64;
                let resolve = gpu.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("pass times"),
                    size: bytes,
                    usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                });
                let back = gpu.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("pass times readback"),
                    size: bytes,
                    usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                });
                self.encoder.resolve_query_set(q, 0..2 * timed, &resolve, 0);
                self.encoder.copy_buffer_to_buffer(&resolve, 0, &back, 0, bytes);
                Some(back)
            }
            _ => None,
        };
        let encoder = self.encoder;
        gpu.checked("preview frame", || gpu.queue.submit([encoder.finish()]))?;
        self.undo.0.clear();
        let rgb_bytes = map(gpu, &rgb_back)?;
        let surface_bytes = map(gpu, &surface_back)?;
        let seconds = self.start.elapsed().as_secs_f64();
        let floats = |b: &[u8]| {
            b.chunks_exact(16)
                .take(self.count)
                .map(|c| {
                    std::array::from_fn(|k| f32::from_le_bytes([c[4 * k], c[4 * k + 1], c[4 * k + 2], c[4 * k + 3]]))
                })
                .collect::<Vec<[f32; 4]>>()
        };
        let picture = floats(&rgb_bytes);
        let rgb = picture.iter().map(|v| [v[0], v[1], v[2]]).collect();
        let alpha = picture.iter().map(|v| v[3]).collect();
        let surface = floats(&surface_bytes);
        let mut passes = Vec::new();
        if let Some(back) = times_back {
            let ticks: Vec<u64> =
                map(gpu, &back)?.chunks_exact(8).map(|c| u64::from_le_bytes(c.try_into().expect("8 bytes"))).collect();
            let period_s = f64::from(gpu.queue.get_timestamp_period()) * 1e-9;
            for (k, name) in self.passes.iter().take(timed as usize).enumerate() {
                passes.push((*name, ticks[2 * k + 1].saturating_sub(ticks[2 * k]) as f64 * period_s));
            }
        }
        Ok(Rendered { rgb, alpha, surface, seconds, passes })
    }
}

/// Waits for `buffer` to map and copies its bytes out.
pub(crate) fn map(gpu: &Gpu, buffer: &wgpu::Buffer) -> Result<Vec<u8>, PreviewError> {
    let slice = buffer.slice(..);
    let (tx, rx) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    gpu.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| PreviewError::Readback(e.to_string()))?;
    rx.recv().map_err(|e| PreviewError::Readback(e.to_string()))?.map_err(|e| PreviewError::Readback(e.to_string()))?;
    let data = slice.get_mapped_range().map_err(|e| PreviewError::Readback(e.to_string()))?;
    Ok(data.to_vec())
}

/// Copies `buffer` (with COPY_SRC) to a mappable one and reads its bytes.
pub(crate) fn read_buffer(gpu: &Gpu, buffer: &wgpu::Buffer) -> Result<Vec<u8>, PreviewError> {
    let back = gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size: buffer.size(),
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("readback") });
    encoder.copy_buffer_to_buffer(buffer, 0, &back, 0, buffer.size());
    gpu.checked("readback", || gpu.queue.submit([encoder.finish()]))?;
    map(gpu, &back)
}
