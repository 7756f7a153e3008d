//! Mie theory: the BHMIE single-sphere solver, log-normal size averaging,
//! phase tables for sampling, and an on-disk cache of the results.

pub mod bhmie;
pub mod cache;
pub mod lognormal;
pub mod phase;

pub use bhmie::{bhmie, parse_refractive_index, MieResult};
pub use cache::MieCache;
pub use lognormal::{bulk_optics, BulkOptics, LogNormal};
pub use phase::PhaseTable;
