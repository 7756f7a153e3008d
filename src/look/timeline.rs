//! A preview timeline (`sky preview --timeline FILE.toml`): keyframes of
//! the time of day (or the sun directly), the weather, the cumulus cover
//! and the wind, interpolated linearly into one state per frame; the wind
//! carries the clouds by its velocity times the time of day elapsed. The
//! file (every key gives `frame` and either `time` or both sun angles, and
//! the weather; `cumulus_cover` and `wind_km_h` default to 0.4 and calm):
//!
//! ```toml
//! frames = 96           # frames to render, numbered from 0
//! latitude_deg = 35.0   # for `time` (north positive)
//! day = 172             # day of the year, for `time`
//!
//! [[key]]
//! frame = 0
//! time = "05:30"        # local solar time
//! haziness = 0.1
//! cloudiness = 0.0
//! cumulus_cover = 0.3
//! wind_km_h = [40.0, 10.0]   # toward east, north
//!
//! [[key]]
//! frame = 95
//! time = "19:30"
//! haziness = 0.6
//! cloudiness = 0.4
//! cumulus_cover = 0.8
//! ```

use super::solar::{parse_time, sun_position_deg};
use serde::Deserialize;
use std::path::Path;

/// The state of one frame.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct FrameState {
    pub frame: usize,
    /// Local solar time, hours (None where the keys give the sun directly).
    pub hours: Option<f64>,
    pub sun_elevation_deg: f64,
    pub sun_azimuth_deg: f64,
    pub haziness: f64,
    pub cloudiness: f64,
    pub cumulus_cover: f64,
    /// How far the wind has carried the clouds since frame 0, km east, north.
    pub wind_offset_km: [f64; 2],
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    frames: usize,
    #[serde(default)]
    latitude_deg: Option<f64>,
    #[serde(default)]
    day: Option<u32>,
    key: Vec<Key>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Key {
    frame: usize,
    time: Option<String>,
    sun_elevation_deg: Option<f64>,
    sun_azimuth_deg: Option<f64>,
    haziness: f64,
    cloudiness: f64,
    #[serde(default = "default_cover")]
    cumulus_cover: f64,
    #[serde(default)]
    wind_km_h: [f64; 2],
}

fn default_cover() -> f64 {
    0.4
}

/// A key made numeric: (hours or the sun's two angles), weather, cover, wind.
struct Numeric {
    frame: usize,
    hours: Option<f64>,
    sun: Option<(f64, f64)>,
    values: [f64; 3],
    wind_km_h: [f64; 2],
}

/// Reads a timeline and returns every frame's state; errors name the
/// file, and the line for what TOML itself rejects.
pub fn load(path: &Path) -> Result<Vec<FrameState>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    parse(&text).map_err(|e| format!("{}: {e}", path.display()))
}

/// [`load`] of the text of a timeline.
pub fn parse(text: &str) -> Result<Vec<FrameState>, String> {
    let file: File = toml::from_str(text).map_err(|e| e.to_string())?;
    if file.frames == 0 {
        return Err("frames must be at least 1".into());
    }
    if file.key.is_empty() {
        return Err("a timeline needs at least one [[key]]".into());
    }
    let mut keys = Vec::new();
    for (k, key) in file.key.iter().enumerate() {
        let at = format!("key {} (frame {})", k + 1, key.frame);
        let (hours, sun) = match (&key.time, key.sun_elevation_deg, key.sun_azimuth_deg) {
            (Some(t), None, None) => {
                if file.latitude_deg.is_none() || file.day.is_none() {
                    return Err(format!("{at}: a time needs latitude_deg and day at the top of the file"));
                }
                (Some(parse_time(t).map_err(|e| format!("{at}: {e}"))?), None)
            }
            (None, Some(e), Some(a)) if (-90.0..=90.0).contains(&e) && a.is_finite() => (None, Some((e, a))),
            _ => {
                return Err(format!("{at}: give either time or both sun_elevation_deg (-90 to 90) and sun_azimuth_deg"))
            }
        };
        let unit = |name: &str, v: f64| {
            if (0.0..=1.0).contains(&v) {
                Ok(v)
            } else {
                Err(format!("{at}: {name} must be from 0 to 1, got {v}"))
            }
        };
        let values = [
            unit("haziness", key.haziness)?,
            unit("cloudiness", key.cloudiness)?,
            unit("cumulus_cover", key.cumulus_cover)?,
        ];
        if !key.wind_km_h.iter().all(|w| w.is_finite()) {
            return Err(format!("{at}: wind_km_h must be two numbers"));
        }
        if let Some(p) = keys.last().map(|p: &Numeric| p.frame) {
            if key.frame <= p {
                return Err(format!("{at}: keys must be in increasing frame order"));
            }
        }
        if key.frame >= file.frames {
            return Err(format!("{at}: past the last frame, {}", file.frames - 1));
        }
        keys.push(Numeric { frame: key.frame, hours, sun, values, wind_km_h: key.wind_km_h });
    }
    if keys.iter().any(|k| k.hours.is_some()) != keys.iter().all(|k| k.hours.is_some()) {
        return Err("give every key a time, or every key the sun's angles".into());
    }
    let (latitude, day) = (file.latitude_deg.unwrap_or(0.0), file.day.unwrap_or(1));
    if !(-90.0..=90.0).contains(&latitude) || !(1..=366).contains(&day) {
        return Err(format!("latitude_deg must be from -90 to 90 and day from 1 to 366, got {latitude} and {day}"));
    }
    let mut states: Vec<FrameState> = Vec::with_capacity(file.frames);
    for frame in 0..file.frames {
        // The keys around this frame (before the first or after the last: that key).
        let after = keys.iter().position(|k| k.frame >= frame).unwrap_or(keys.len() - 1);
        let before = if keys[after].frame > frame && after > 0 { after - 1 } else { after };
        let (a, b) = (&keys[before], &keys[after]);
        let t = if b.frame > a.frame {
            ((frame as f64 - a.frame as f64) / (b.frame - a.frame) as f64).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let lerp = |x: f64, y: f64| x + (y - x) * t;
        let hours = a.hours.zip(b.hours).map(|(x, y)| lerp(x, y));
        let (sun_elevation_deg, sun_azimuth_deg) = match (hours, a.sun, b.sun) {
            (Some(h), _, _) => sun_position_deg(latitude, day, h),
            (None, Some(x), Some(y)) => (lerp(x.0, y.0), lerp(x.1, y.1)),
            _ => unreachable!("every key has a time or every key the sun"),
        };
        let wind = [lerp(a.wind_km_h[0], b.wind_km_h[0]), lerp(a.wind_km_h[1], b.wind_km_h[1])];
        let wind_offset_km = match (states.last(), hours) {
            (Some(p), Some(h)) => {
                let dt = h - p.hours.unwrap_or(h);
                [p.wind_offset_km[0] + wind[0] * dt, p.wind_offset_km[1] + wind[1] * dt]
            }
            (Some(p), None) => p.wind_offset_km,
            (None, _) => [0.0, 0.0],
        };
        let [haziness, cloudiness, cumulus_cover] = std::array::from_fn(|i| lerp(a.values[i], b.values[i]));
        states.push(FrameState {
            frame,
            hours,
            sun_elevation_deg,
            sun_azimuth_deg,
            haziness,
            cloudiness,
            cumulus_cover,
            wind_offset_km,
        });
    }
    Ok(states)
}

#[cfg(test)]
mod tests {
    use super::*;

    const DAY: &str = "frames = 5\nlatitude_deg = 35.0\nday = 172\n[[key]]\nframe = 0\ntime = \"06:00\"\nhaziness = 0.0\ncloudiness = 0.0\nwind_km_h = [10.0, 0.0]\n[[key]]\nframe = 4\ntime = \"18:00\"\nhaziness = 1.0\ncloudiness = 0.5\ncumulus_cover = 0.8\nwind_km_h = [10.0, 0.0]\n";

    /// Keys interpolate linearly, the time through the sun's position, and
    /// the wind carries the clouds by its speed times the hours elapsed.
    #[test]
    fn a_timeline_interpolates_its_keys() {
        let states = parse(DAY).unwrap();
        assert_eq!(states.len(), 5);
        assert_eq!(states[2].hours, Some(12.0));
        assert_eq!((states[2].sun_elevation_deg, states[2].sun_azimuth_deg), sun_position_deg(35.0, 172, 12.0));
        assert!((states[2].haziness - 0.5).abs() < 1e-12 && (states[2].cloudiness - 0.25).abs() < 1e-12);
        assert!((states[2].cumulus_cover - 0.6).abs() < 1e-12, "{}", states[2].cumulus_cover);
        // 10 km/h for 12 hours.
        assert!((states[4].wind_offset_km[0] - 120.0).abs() < 1e-9, "{:?}", states[4].wind_offset_km);
    }

    /// Bad timelines are named: the line TOML rejects, and the key for
    /// values out of range, out of order or missing a sun.
    #[test]
    fn bad_timelines_say_what_is_wrong() {
        let cases = [
            (DAY.replace("haziness = 1.0", "haziness = 1.5"), "key 2 (frame 4): haziness must be from 0 to 1"),
            (DAY.replace("frame = 4", "frame = 0"), "increasing frame order"),
            (DAY.replace("frame = 4", "frame = 9"), "past the last frame"),
            (DAY.replace("time = \"18:00\"", "time = \"18h\""), "expected a time of day"),
            (DAY.replace("day = 172\n", ""), "needs latitude_deg and day"),
            (DAY.replace("cloudiness = 0.0\n", "cloudines = 0.0\n"), "line 8"),
        ];
        for (text, expected) in cases {
            let e = parse(&text).unwrap_err();
            assert!(e.contains(expected), "{e}\n(expected `{expected}`)");
        }
    }
}
