//! Where the sun is at a time of day: the sun's direction from a
//! latitude, a day of the year and a local solar time, for the preview's
//! `--time` and timelines. An approximation good to about a degree, enough
//! to pick a LUT slice and light a look-dev frame, not for astronomy:
//!
//! - declination (Cooper 1969, "The absorption of radiation in solar
//!   stills", Solar Energy 12(3)): δ = 23.45° sin(360° (284 + N) / 365);
//! - hour angle h = 15° (t − 12) for local solar time t in hours;
//! - elevation: sin α = sin φ sin δ + cos φ cos δ cos h;
//! - azimuth from north, clockwise: A = atan2(−sin h cos δ,
//!   sin δ cos φ − cos δ sin φ cos h) (the standard horizontal-coordinate
//!   transformation, e.g. Meeus, "Astronomical Algorithms", ch. 13, with the
//!   azimuth counted from north instead of south).
//!
//! The preview's world frame has x east and y north (z up), and its
//! azimuths run from x toward y, so a compass azimuth A is 90° − A there.

/// The sun's elevation above the horizon and its azimuth in the
/// preview's frame (from east toward north), degrees, at `latitude_deg`
/// (north positive), day of the year `day` (1 to 366) and local solar time
/// `hours` (0 to 24).
pub fn sun_position_deg(latitude_deg: f64, day: u32, hours: f64) -> (f64, f64) {
    let declination = (23.45f64.to_radians()) * (360.0 * (284.0 + f64::from(day)) / 365.0).to_radians().sin();
    let hour_angle = (15.0 * (hours - 12.0)).to_radians();
    let latitude = latitude_deg.to_radians();
    let sin_elevation = latitude.sin() * declination.sin() + latitude.cos() * declination.cos() * hour_angle.cos();
    let elevation_deg = sin_elevation.clamp(-1.0, 1.0).asin().to_degrees();
    let compass = (-hour_angle.sin() * declination.cos())
        .atan2(declination.sin() * latitude.cos() - declination.cos() * latitude.sin() * hour_angle.cos());
    // In (-180, 180].
    let azimuth_deg = 180.0 - (180.0 - (90.0 - compass.to_degrees())).rem_euclid(360.0);
    (elevation_deg, azimuth_deg)
}

/// "HH:MM" (00:00 to 24:00) as hours.
pub fn parse_time(s: &str) -> Result<f64, String> {
    let bad = || format!("`{s}`: expected a time of day HH:MM, e.g. 06:30");
    let (h, m) = s.trim().split_once(':').ok_or_else(bad)?;
    let (h, m): (u32, u32) = (h.parse().map_err(|_| bad())?, m.parse().map_err(|_| bad())?);
    if m >= 60 || h > 24 || (h == 24 && m > 0) {
        return Err(bad());
    }
    Ok(f64::from(h) + f64::from(m) / 60.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Checks from geometry alone: at noon the sun is due south (north of
    /// the tropic of Cancer) at 90° − φ + δ; at the equinoxes (δ = 0,
    /// about day 81) it rises due east at 06:00 and is at the zenith over
    /// the equator at noon; on the June solstice (day 172, δ = 23.45°) it
    /// stands over the tropic at noon; morning and afternoon mirror about
    /// the meridian.
    #[test]
    fn the_sun_is_where_geometry_puts_it() {
        let (e, a) = sun_position_deg(35.0, 172, 12.0);
        assert!((e - (90.0 - 35.0 + 23.45)).abs() < 0.01, "{e}");
        assert!((a + 90.0).abs() < 1e-6, "noon azimuth {a}: expected due south (-90)");
        let (e, _) = sun_position_deg(23.45, 172, 12.0);
        assert!((e - 90.0).abs() < 0.05, "{e}");
        // Day 81: δ = 23.45° sin(360° · 365 / 365) = 0.
        let (e, _) = sun_position_deg(0.0, 81, 12.0);
        assert!((e - 90.0).abs() < 1e-6, "{e}");
        let (e, a6) = sun_position_deg(48.0, 81, 6.0);
        assert!(e.abs() < 1e-6 && a6.abs() < 1e-6, "sunrise at {e} degrees, azimuth {a6} (expected 0, east)");
        let (e_am, a_am) = sun_position_deg(40.0, 300, 9.5);
        let (e_pm, a_pm) = sun_position_deg(40.0, 300, 14.5);
        assert!((e_am - e_pm).abs() < 1e-9, "{e_am} against {e_pm}");
        // Mirror about the meridian (azimuth -90, south): a_am + 90 = -(a_pm + 90).
        assert!(((a_am + 90.0) + (a_pm + 90.0)).abs() < 1e-9, "{a_am} and {a_pm}");
        assert!(a_am > -90.0, "the morning sun is east of south: {a_am}");
    }

    #[test]
    fn times_parse_and_bad_ones_are_named() {
        assert_eq!(parse_time("06:30"), Ok(6.5));
        assert_eq!(parse_time("24:00"), Ok(24.0));
        for bad in ["6", "25:00", "12:60", "ab:cd", "24:01"] {
            assert!(parse_time(bad).unwrap_err().contains(bad), "{bad}");
        }
    }
}
