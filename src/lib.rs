//! `sky`: a physically based spectral sky renderer and LUT baker, rebuilding
//! the "skysim" pipeline of Polyphony Digital's GDC 2023 talk "Realistic
//! Real-time Sky Dome Rendering in Gran Turismo 7".
//!
//! The modules by layer, each importing only from the layers below it:
//!
//! - ground floor: [`directions`] (the world frame, cameras, the talk's LUT
//!   mappings), [`colour`] (colour spaces and 3x3 matrices), [`stats`]
//!   (percentiles, the Šidák family of the tests), [`atomic`] (whole-file
//!   writes), [`lru`], [`table`] (the data files of `atmospheres/data/`),
//!   [`spectrum`] (colour matching functions and the solar spectrum),
//!   [`plot`] (PNG plots for people);
//! - physics: [`mie`] (BHMIE, log-normal size distributions, phase tables),
//!   [`atmosphere`] (the measured atmosphere model and its optics);
//! - [`render`]: the spectral path tracer behind `sky render`;
//! - [`farm`]: the render farm (`sky worker` and the distributed `sky render`);
//!   [`session`]: prepared optics by hash, and views rendered with them,
//!   locally or on the farm;
//! - [`lut`]: the runtime contract an engine port reads: the manifest, the
//!   weather rule, the reference decoder, the texture codecs;
//! - [`bake`]: `sky bake-luts`, the basis-sky LUTs rendered, cached and packed;
//! - [`study`]: the LUTs measured: `sky lut verify`, interpolation studies,
//!   error pictures, the bake's benchmarks;
//! - [`look`]: the sun at a time of day and preview timelines; `preview`
//!   (feature `preview`): the LUTs, fog and clouds on a GPU through wgpu.

pub mod atmosphere;
pub mod atomic;
pub mod bake;
pub mod colour;
pub mod directions;
pub mod farm;
pub mod look;
pub mod lru;
pub mod lut;
pub mod mie;
pub mod plot;
#[cfg(feature = "preview")]
pub mod preview;
pub mod render;
pub mod session;
pub mod spectrum;
pub mod stats;
pub mod study;
pub mod table;
pub mod transport;

/// Version of this build, recorded in outputs.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

/// The renderer's source: a hash of every file a rendered pixel depends on
/// (see build.rs). Cached slices, prepared optics and farm workers are
/// matched on it as well as on [`VERSION`], so a change to the physics
/// under the same version is never mixed with results of the old one.
pub const RENDER_SOURCE: &str = env!("SKY_RENDER_SOURCE");
