//! Look-up tables for real-time engines: the talk's adaptive mappings
//! (time slices and sky directions).

pub mod decode;
pub mod manifest;
pub mod mapping;
pub mod weather;
