//! skysim's successor: the full-spectrum path tracer behind `sky render`.
//!
//! Spectral model: the visible range 360–830 nm is split into bands (5 nm
//! by default). Optics are evaluated at each band's centre; the sun's
//! spectrum and the colour matching functions are integrated exactly within
//! the band at 1 nm, so the radiance solved per unit solar irradiance is
//! weighted by W_b = 683 Σ_{λ∈b} E(λ) (x̄, ȳ, z̄)(λ) · 1 nm. By default each
//! sample carries four bands (hero wavelengths, see `hero`); the single-band
//! alternatives pick one band in proportion to its luminance W_b.y (the
//! talk's "wavelengths using spectral luminous efficiency") or to
//! W_b.x + W_b.y + W_b.z (`sky bench spectral` compares the three).
//! X, Y, Z are CIE 1931 tristimulus values of the sky radiance scaled by
//! 683 lm/W, so Y is luminance in cd m⁻²; spectral channels are radiance in
//! W m⁻² sr⁻¹ nm⁻¹.
//!
//! The renderer's front door, by concern: `settings` (what a render is
//! asked for: [`SpectralSettings`], [`View`] and its validation,
//! [`Settings`]), `scene` (the prepared optics, [`Scene`]), `pixel` (the
//! per-pixel estimator, [`render_pixel`]), and `driver` (the parallel loop
//! over a view's pixels or a farm task's columns, [`render`]). Below them:
//! `tracer` and `kernel` (the path tracer; `flight` and `next_event` hold
//! the kernel's flights and light estimates), `medium` and `columns` (the
//! atmosphere as the tracer sees it), and the guides and samplers.

pub mod adaptive;
pub mod bands;
#[cfg(test)]
mod chi2;
mod columns;
pub mod denoise;
mod driver;
mod flight;
pub mod fog;
pub mod guide;
pub mod hero;
pub mod kernel;
pub mod medium;
mod next_event;
pub mod output;
mod pixel;
pub mod rng;
pub mod sampling;
mod scene;
pub mod segments;
mod settings;
pub mod single;
pub mod sky_guide;
pub mod tracer;

pub use adaptive::{adaptive_samples, Moments, ADAPTIVE_MIN_SPP, ADAPTIVE_PILOT_SPP};
pub use bands::{Bands, HeroSet, HERO_N};
pub use driver::{render, render_columns, render_timed, single_per_pixel, Image, RenderError};
pub use pixel::{
    render_pixel, render_pixel_cancellable, render_pixel_with, single_by_quadrature, PixelResult, PixelTracers,
};
pub use scene::Scene;
pub use settings::{Settings, SingleScatter, SpectralSettings, View, WavelengthSampling, KM_LM_PER_W};
