//! The integration tests, as modules of one test binary (`cargo test --test suite`):
//! one link of the library, tonic and wgpu instead of one per file. Run one
//! file's tests with its module as the filter, e.g. `cargo test --release --test
//! suite -- bake::`. Most of them run the `sky` binary itself.

mod common;

mod atmosphere_files;
mod bake;
mod cli;
mod disort;
mod engine_formats;
mod farm;
mod fog;
mod fuzz;
mod hero;
mod integrity;
mod ktx_readers;
mod openjd;
mod preview;
mod preview_clouds;
mod reference_physics;
mod render_sanity;
mod session;
mod transport;
