//! Studies of the LUTs: how far a bake's decode is from direct renders
//! (`sky lut verify`: [`verify`], [`verify_fog`]), what the mappings lose by
//! interpolating on a noise-free sky ([`interpolation`], with pictures of the
//! error in [`error_map`]), and what a bake costs ([`bench`],
//! [`bench_coarse`]). They stand between the bake, whose files and renders
//! they measure, and the command line; nothing below imports them.

pub mod bench;
pub mod bench_coarse;
pub mod error_map;
pub mod interpolation;
pub mod verify;
pub mod verify_fog;
