//! The talk's global fog as the path tracer renders it: the light scattered
//! toward the camera by the air between it and an opaque object ("unlike
//! the sky, the calculation ends in the foreground"), by the low atmosphere
//! only ("only low-altitude atmosphere affects our global fog, unlike the
//! sky"), and its "Shadowed Fog" variant without the sunlight scattered
//! once toward the camera ("Fog LUT without single-scattering component",
//! blended with the Fog LUT by cloud occlusion at run time).
//!
//! What is restricted is the camera ray alone: its first scattering must
//! lie before the object and below the ceiling (the cloud base), and the
//! object, or the ground if the ray meets it first, is black (the engine
//! draws and lights it; the fog only adds in front of it). The light that
//! reaches those scattering points is the whole sky's: the sun through every
//! layer, the clouds, the ground's reflection, the air above the ceiling.
//! So at infinite depth with no ceiling the fog toward a direction that
//! does not meet the ground is the sky's radiance there (the talk: "Global
//! fog ... has the same radiance at infinity as the sky"), which `tests`
//! check.
//!
//! A ray from an observer below the ceiling stays below it over one stretch
//! from its start (the altitude along a straight ray above a sphere or a
//! plane is convex), so the fog's reach along a ray is one distance.

use super::medium::Medium;
use glam::DVec3;

/// Global fog in front of an object: what a view renders instead of the
/// sky when [`View::fog`](super::View::fog) is set.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Fog {
    /// The object's distance along each camera ray, km (infinite: none;
    /// the ground ends the ray where it comes first). Travels as null when
    /// infinite (JSON has no infinity: farm tasks carry views as JSON).
    #[serde(with = "infinite_as_null")]
    pub max_distance_km: f64,
    /// Only the air below this altitude scatters toward the camera (and
    /// dims the camera ray): the cloud base. None: all of the atmosphere.
    pub ceiling_km: Option<f64>,
    /// The Shadowed Fog: without the sunlight scattered once toward the
    /// camera.
    pub shadowed: bool,
}

impl Fog {
    /// The fog in front of an object at `max_distance_km` under
    /// `ceiling_km`, with its single scattering of sunlight.
    pub fn lit(max_distance_km: f64, ceiling_km: Option<f64>) -> Fog {
        Fog { max_distance_km, ceiling_km, shadowed: false }
    }

    /// The same fog's Shadowed Fog.
    pub fn shadowed(self) -> Fog {
        Fog { shadowed: true, ..self }
    }

    /// Why this fog cannot be rendered from an observer at `altitude_km`,
    /// if it cannot: a distance that is not positive, or an observer above
    /// the ceiling (whose rays would cross the low atmosphere in a stretch
    /// that does not start at the camera).
    pub fn check(&self, altitude_km: f64) -> Result<(), String> {
        if !(self.max_distance_km > 0.0) {
            return Err(format!("the fog's object distance must be positive (got {} km)", self.max_distance_km));
        }
        match self.ceiling_km {
            Some(c) if !(c > altitude_km) => {
                Err(format!("the fog's ceiling ({c} km) must be above the observer ({altitude_km} km)"))
            }
            _ => Ok(()),
        }
    }

    /// The distance along `d` from the observer at `p` over which the air
    /// scatters toward the camera: to the object, or to where the ray
    /// rises through the ceiling, whichever is nearer (the ground, where
    /// the ray meets it first, ends the ray in any case).
    pub fn reach_km(&self, medium: &Medium, p: DVec3, d: DVec3) -> f64 {
        let through_ceiling =
            self.ceiling_km.and_then(|c| medium.distance_to_altitude(p, d, c, true)).unwrap_or(f64::INFINITY);
        self.max_distance_km.min(through_ceiling)
    }
}

/// A distance that may be infinite, (de)serialised as an optional number:
/// None for infinity.
mod infinite_as_null {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        if v.is_finite() {
            s.serialize_some(v)
        } else {
            s.serialize_none()
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::INFINITY))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fog with no object travels through JSON (a farm task's view) and
    /// postcard (a journal) and comes back infinite; a finite one exactly.
    #[test]
    fn an_infinite_distance_round_trips() {
        for fog in [Fog::lit(f64::INFINITY, Some(3.0)), Fog::lit(12.5, None).shadowed()] {
            let json = serde_json::to_string(&fog).unwrap();
            assert_eq!(serde_json::from_str::<Fog>(&json).unwrap(), fog, "{json}");
            let bytes = postcard::to_allocvec(&fog).unwrap();
            assert_eq!(postcard::from_bytes::<Fog>(&bytes).unwrap(), fog);
        }
    }
}
