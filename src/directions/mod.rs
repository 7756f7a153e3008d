//! The ground floor of directions: the world frame, the cameras that turn
//! image positions into view directions, and the talk's LUT mappings between
//! texels and directions. It imports nothing else of the crate, so the
//! renderer, the LUT decoders and the bake can all stand on it.

pub mod camera;
pub mod mapping;

pub use camera::{direction_deg, Camera};
pub use mapping::DirectionMapping;
