//! A deterministic solver of the radiative transfer equation (issue 37):
//! the sky's light without Monte Carlo noise, judged by the path tracer and
//! by DISORT.
//!
//! So far: daylight seen from the ground, in plane-parallel atmospheres and
//! (pseudo-spherical) in spherical shells. `layers` cuts an atmosphere into
//! homogeneous layers at one wavelength (the optical depths the path tracer
//! integrates); `operator` turns one layer into its reflection,
//! transmission and beam sources per Fourier mode (diamond start and
//! doubling); `adding` adds them and integrates the source of the
//! multiply scattered light along each view, with the single scattering
//! exact. `render` turns that into a view's pixels for `sky render
//! --method deterministic`. `legendre` and `linalg` are their arithmetic.

pub mod adding;
pub mod columns;
pub mod layers;
pub mod legendre;
pub mod linalg;
pub mod operator;
pub mod render;
