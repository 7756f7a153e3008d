//! Look-up tables for real-time engines: the talk's adaptive mappings
//! (time slices and sky directions), the weather rule, the manifest and
//! reference decoder, and the texture formats and files the tables are
//! stored in.

pub mod ambient;
pub mod atomic;
pub mod colour;
pub mod colour_error;
pub mod dds;
pub mod decode;
pub mod decode_fog;
pub mod error_map;
pub mod fog;
pub mod fog_falloff;
pub mod interpolation;
pub mod ktx2;
pub mod landscape;
pub mod manifest;
pub mod mapping;
pub mod minifloat;
pub mod r11g11b10;
pub mod rgba16f;
pub mod texels;
pub mod transmittance;
pub mod weather;
