//! What a look-dev preview shows over time, independent of the GPU: the
//! sun's position at a time of day ([`solar`]) and timelines of time,
//! weather, cumulus and wind ([`timeline`]).

pub mod solar;
pub mod timeline;
