//! `sky bake-luts`: the talk's basis-sky LUTs. A bake file ([`file`]) names
//! the basis skies; [`run`] renders each one's 64 time slices through the
//! LUT camera (sun disk hidden) into a content-addressed [`cache`], on the
//! embedded worker or the farm, reporting [`BakeEvent`]s; the packing into
//! texture arrays and the manifest follow.

pub mod cache;
pub mod file;
mod finish;
pub mod fog;
pub mod fog_falloff;
pub mod fog_resample;
mod forecast;
pub mod lighting;
pub mod ms_grid;
pub mod openjd;
pub mod pack;
pub mod pack_ambient;
pub mod pack_fog;
mod plan;
mod queue;
pub mod references;
pub mod run;
pub mod slices;
pub mod solver;
pub mod tables;
mod tracker;

pub use cache::{RenderedSlice, SliceCache};
pub use file::{BakeFile, BakeFileError, BasisSky, Quality, Sampling};
pub use run::{render_slices, BakeOptions, Method, SkySlices, SliceId};

use crate::session::farm::FarmEvent;
use std::sync::Arc;

/// What a bake reports while it runs. The library only emits these; the
/// CLI shows them as a bar, plain lines or JSON lines.
#[derive(Debug, Clone, serde::Serialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum BakeEvent {
    /// The bake's work, once the cache has been consulted: slices of the
    /// sky LUTs and fog slices (each a render of the Shadowed Fog, from
    /// which the Fog follows), `fog_slices` of the latter to render.
    Planned { skies: usize, slices_total: usize, slices_cached: usize, fog_slices: usize, texels_to_render: u64 },
    /// A basis sky's optics are being prepared.
    Preparing { sky: String },
    /// What the bake will take, before its first slice: with adaptive
    /// sampling from the slices' pilots (rendered first, 32 samples a
    /// texel: every texel's sample count exactly, and core-seconds at the
    /// pilots' pace); with a fixed sample count from probes (a few slices
    /// at a sixteenth of their texels, timed). `from`: "pilots" or "probes".
    /// `saved`: pilots whose forecast was in the cache folder, saved by a
    /// run of the same bake on this machine that was stopped.
    Forecast { from: &'static str, core_seconds: f64, samples: u64, planning_core_seconds: f64, saved: usize },
    /// Planning's progress: one more pilot (or probe) of the forecast is
    /// rendered, `done` of `total`, the last of slice `index` of `sky` (a
    /// fog slice's if `fog`); `eta_s` for the rest of planning at its pace
    /// so far; a pilot's `forecast_core_seconds` of its slice (its
    /// render in the queue and the quadrature after it).
    Planning {
        from: &'static str,
        sky: String,
        index: usize,
        fog: bool,
        done: usize,
        total: usize,
        elapsed_s: f64,
        eta_s: f64,
        forecast_core_seconds: Option<f64>,
    },
    /// One slice is done (rendered now, or found in the cache), with what
    /// it cost and, rendered now after a forecast, what was forecast.
    Slice {
        sky: String,
        index: usize,
        sun_zenith_deg: f64,
        cached: bool,
        core_seconds: f64,
        forecast_core_seconds: Option<f64>,
        mean_samples: f64,
    },
    /// Every slice of a basis sky is done.
    SkyDone { sky: String, slices_rendered: usize, slices_cached: usize, core_seconds: f64 },
    /// A fog slice of a basis sky is done: its Fog and Shadowed Fog
    /// (`done` of `total`, rendered now or found in the cache).
    FogSlice { sky: String, done: usize, total: usize },
    /// Every fog slice of a basis sky is done, with the falloff's fit.
    FogDone {
        sky: String,
        slices_rendered: usize,
        slices_cached: usize,
        core_seconds: f64,
        falloff_a: f64,
        falloff_p: f64,
        fit_median: f64,
        fit_p99: f64,
    },
    /// Periodic progress over the whole bake.
    Progress(BakeProgress),
    /// A farm event of the slice being rendered (worker quarantined, task
    /// failed); its progress events become [`BakeEvent::Progress`].
    Farm { sky: String, index: usize, farm: FarmEvent },
}

/// Progress over the whole bake, in texels still to render (cached slices
/// are not counted).
#[derive(Debug, Clone, serde::Serialize)]
pub struct BakeProgress {
    pub elapsed_s: f64,
    pub texels_done: u64,
    pub texels_total: u64,
    pub slices_done: usize,
    pub slices_total: usize,
    /// The remaining texels at the rate so far; None before one is known.
    pub eta_s: Option<f64>,
    /// The basis sky and slice being rendered.
    pub sky: String,
    pub index: usize,
    /// Why nothing is rendering, when no farm worker can.
    pub stalled: Option<String>,
}

/// Where a bake sends its events.
#[derive(Clone)]
pub struct BakeSink(pub Arc<dyn Fn(&BakeEvent) + Send + Sync>);

impl BakeSink {
    pub fn new(f: impl Fn(&BakeEvent) + Send + Sync + 'static) -> BakeSink {
        BakeSink(Arc::new(f))
    }

    pub fn emit(&self, e: &BakeEvent) {
        (self.0)(e)
    }
}

impl std::fmt::Debug for BakeSink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("BakeSink")
    }
}

/// Why a bake failed.
#[derive(Debug, thiserror::Error)]
pub enum BakeError {
    #[error("{0}")]
    File(#[from] BakeFileError),
    #[error("basis sky {sky}: {error}")]
    Atmosphere { sky: String, error: crate::atmosphere::LoadError },
    #[error("{0}")]
    Cache(#[from] cache::CacheError),
    #[error("basis sky {sky}, slice {index}: {source}")]
    Render { sky: String, index: usize, source: crate::session::farm::FarmError },
    #[error("basis sky {sky}, slices {first} to {last}: {source}")]
    RenderSlices { sky: String, first: usize, last: usize, source: crate::session::farm::FarmError },
    #[error("the slices of basis skies {skies}: {source}")]
    RenderQueue { skies: String, source: crate::session::farm::FarmError },
    #[error("the bake's journal: {0}")]
    Journal(crate::session::farm::JournalError),
    #[error("--slice {0}: no such basis sky or slice (NAME:INDEX, INDEX from 0 to 63)")]
    NoSuchSlice(String),
    #[error("basis sky {sky}, slice {index}, texel (u {u}, v {v}): {what} is not finite")]
    NotFinite { sky: String, index: usize, u: usize, v: usize, what: &'static str },
    #[error("cannot write the bake: {0}")]
    Write(String),
    #[error("--pack-only: the cache {} lacks {} of the bake's slices ({}{}); render them first (--slice NAME:INDEX or NAME:fog:INDEX, or a bake without --pack-only)", cache.display(), missing.len(), missing.iter().take(8).cloned().collect::<Vec<_>>().join(", "), if missing.len() > 8 { ", ..." } else { "" })]
    NotInCache { cache: std::path::PathBuf, missing: Vec<String> },
    #[error("fog slice {sky}:fog:{index} was neither rendered in this bake nor found in the cache {}: did something clear the cache during the bake? Run the bake again", cache.display())]
    FogSliceLost { sky: String, index: usize, cache: std::path::PathBuf },
    #[error("basis sky {sky}: {error} (--method monte-carlo bakes it with the path tracer)")]
    Solver { sky: String, error: crate::transport::render::Unsupported },
    #[error("bake cancelled")]
    Cancelled,
}

impl BakeError {
    /// Whether the bake was stopped (Ctrl-C) rather than failed.
    pub fn is_cancelled(&self) -> bool {
        use crate::session::farm::FarmError;
        matches!(
            self,
            BakeError::Cancelled
                | BakeError::Render { source: FarmError::Cancelled, .. }
                | BakeError::RenderSlices { source: FarmError::Cancelled, .. }
                | BakeError::RenderQueue { source: FarmError::Cancelled, .. }
        )
    }
}
