//! A deterministic solver of the radiative transfer equation (issue 37):
//! the sky's light without Monte Carlo noise, judged by the path tracer and
//! by DISORT.
//!
//! So far: the sky seen from the ground, in plane-parallel atmospheres and
//! in spherical shells, by day and at twilight. `layers` cuts an
//! atmosphere into homogeneous layers at one wavelength (the optical depths
//! the path tracer integrates); `operator` turns one layer into its
//! reflection, transmission and beam sources per Fourier mode (diamond
//! start and doubling); `adding` adds them into the diffuse field of a
//! column (pseudo-spherical in shells), with the single scattering exact;
//! `columns` solves such columns for a range of local sun angles and reads
//! the multiply scattered light's source along each view where the sun
//! stands as it does over the ground the view crosses; `spherical` makes
//! their sources spherical at twilight (source iteration along rays
//! through the shells, `shell_rays`). `render` turns that
//! into a view's pixels for `sky render --method deterministic`.
//! `legendre` and `linalg` are their arithmetic.

mod accelerate;
pub mod adding;
pub mod columns;
pub mod layers;
pub mod legendre;
mod light;
pub mod linalg;
pub mod operator;
pub mod render;
pub mod shell_rays;
pub mod spherical;
mod spherical_table;
