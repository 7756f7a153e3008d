//! `sky`: a physically based spectral sky renderer and LUT baker, rebuilding
//! the "skysim" pipeline of Polyphony Digital's GDC 2023 talk "Realistic
//! Real-time Sky Dome Rendering in Gran Turismo 7".
//!
//! - [`atmosphere`]: the measured atmosphere model (`atmospheres/*.toml`) and
//!   its optical properties;
//! - [`mie`]: Mie theory (BHMIE), log-normal size distributions, phase tables;
//! - [`render`]: the spectral path tracer behind `sky render`;
//! - [`farm`]: the render farm (`sky worker` and the distributed `sky render`);
//! - [`bake`]: `sky bake-luts`, the basis-sky LUTs rendered, cached and packed;
//! - [`lut`]: the talk's adaptive LUT mappings, the weather rule and the reference decoder;
//! - [`look`]: the sun at a time of day and preview timelines;
//! - `preview` (feature `preview`): the LUTs, fog and clouds on a GPU through wgpu;
//! - [`spectrum`]: colour matching functions and the solar spectrum;
//! - [`session`]: prepared optics by hash, and views rendered with them;
//! - [`lru`]: the memory-bounded cache that keeps prepared optics;
//! - [`table`]: the tabulated data files of `atmospheres/data/`;
//! - [`plot`]: PNG plots for people.

pub mod atmosphere;
pub mod bake;
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
pub mod table;

/// Version of this build, recorded in outputs.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

/// The renderer's source: a hash of every file a rendered pixel depends on
/// (see build.rs). Cached slices, prepared optics and farm workers are
/// matched on it as well as on [`VERSION`], so a change to the physics
/// under the same version is never mixed with results of the old one.
pub const RENDER_SOURCE: &str = env!("SKY_RENDER_SOURCE");
