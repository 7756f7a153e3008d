//! The render farm: `sky worker` daemons on idle studio PCs and the
//! coordinator behind `sky render` that splits an image per pixel column
//! (the talk: "we distribute rendering tasks using multiple PCs", one
//! column per task).
//!
//! - [`job`]: what travels to a worker: optics (the atmosphere with its
//!   data files, the spectral settings, the prepared scene) named by hash
//!   and sent once, and a view with every task;
//! - [`tile`]: rendered columns on the wire, and the checks a result must
//!   pass before it is accepted;
//! - [`journal`]: accepted columns on disk, so an interrupted render resumes;
//! - [`worker`]: the gRPC service and the owner-first policies of a worker;
//! - [`scheduler`]: assignment, leases, duplicates, verification and
//!   quarantine, with no network and no clock;
//! - [`transport`]: the coordinator's side of the wire, one backend per
//!   worker (remote, or the embedded one);
//! - [`coordinator`]: drives the scheduler over the transport, keeps the
//!   workers' connections across a session's views, reports progress;
//! - [`protocol`]: what worker states and failures mean on the wire;
//! - [`stats`]: what a render reports.

pub mod config;
pub mod coordinator;
pub mod events;
pub mod faults;
pub mod job;
pub mod journal;
pub mod protocol;
pub mod scheduler;
pub mod stats;
pub mod tile;
pub mod transport;
pub mod worker;

/// The generated gRPC code (proto/sky/farm/v1/farm.proto).
#[allow(clippy::all, missing_docs)]
pub mod proto {
    tonic::include_proto!("sky.farm.v1");
}

/// The farm protocol's version: a worker and a coordinator must agree.
pub const PROTOCOL_VERSION: u32 = 2;

/// The build a job needs: only the same build renders bit-identically.
pub fn build_version() -> String {
    format!("{}+render.{}", crate::VERSION, &crate::RENDER_SOURCE[..12])
}

/// The largest message a worker or coordinator accepts, bytes (optics with
/// their data files and prepared scene are about 20 MB for the clear sky;
/// a tile of 64 columns of a 4096-high image with 4 spectral lines is about
/// 36 MiB).
pub const MAX_MESSAGE_BYTES: usize = 64 << 20;
