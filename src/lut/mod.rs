//! Look-up tables for real-time engines: the weather rule, the manifest and
//! reference decoder, and the texture formats and files the tables are
//! stored in. The talk's adaptive mappings (time slices and sky directions)
//! live on the ground floor, in [`crate::directions::mapping`].

pub mod ambient;
pub mod container;
pub mod dds;
pub mod decode;
pub mod decode_fog;
pub mod fog;
pub mod integrity;
pub mod ktx2;
pub mod landscape;
pub mod manifest;
pub mod minifloat;
pub mod r11g11b10;
pub mod rgba16f;
pub mod texels;
pub mod transmittance;
pub mod weather;
