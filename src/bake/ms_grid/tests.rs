//! The multiple-scattering grid's unit tests: its weights, the sun patch,
//! the horizon and the distance to the ground.

use super::*;
use crate::atmosphere::Geometry;
use crate::directions::camera::direction_deg;

fn grid() -> MsGrid {
    MsGrid::new([9, 7], Standpoint::new(Geometry::Spherical, 6371.0, 0.0))
}

/// Every node's own direction gets weight 1 on itself (the grid's away
/// from the sun patch, the patch's inside its fade).
#[test]
fn a_node_interpolates_to_itself() {
    let g = grid();
    assert_eq!((g.ground_rows, g.nodes()), (3, 12 * 7 + SUN_PATCH_ROWS * SUN_PATCH_COLS));
    let sun = (40.0, 30.0);
    let frame = SunFrame::new(sun);
    let mut checked = [0, 0];
    for k in 0..g.nodes() {
        let (z, a) = g.node_deg(k, sun);
        let gamma = frame.coordinates_deg(direction_deg(z, a)).0;
        let patch = k >= g.grid_nodes();
        // The zenith, nadir and sun rows are one direction each, whichever column.
        if !(1e-9..=180.0 - 1e-9).contains(&z)
            || gamma < 1e-6
            || (patch && gamma > (1.0 - SUN_PATCH_FADE) * SUN_PATCH_DEG)
            || (!patch && gamma < SUN_PATCH_DEG)
        {
            continue;
        }
        let w = g.weights(direction_deg(z, a), sun);
        let on: f64 = w.iter().filter(|(n, _)| *n == k).map(|(_, x)| x).sum();
        assert!((on - 1.0).abs() < 1e-9, "node {k} at ({z}, {a}): {w:?}");
        checked[patch as usize] += 1;
    }
    assert!(checked[0] > 50 && checked[1] == 5 * SUN_PATCH_COLS, "{checked:?}");
}

/// Inside the sun patch a field linear in its rows' and columns'
/// coordinates (linear in the angle from the sun between two rows)
/// comes back exactly; across the fade's outer edge the interpolation of
/// a smooth field is continuous; and a cell of the patch that reaches
/// below the horizon is not used.
#[test]
fn the_sun_patch_interpolates_and_fades_into_the_grid() {
    let g = grid();
    let sun = (50.0, 20.0);
    let frame = SunFrame::new(sun);
    let base = g.grid_nodes();
    let field = |k: usize| {
        let (j, i) = ((k - base) / SUN_PATCH_COLS, (k - base) % SUN_PATCH_COLS);
        1.0 + 0.3 * j as f64 + 0.1 * i as f64 + 0.02 * (j * i) as f64
    };
    let rows: Vec<f64> = (0..SUN_PATCH_ROWS).map(patch_row_deg).collect();
    for (gamma, psi) in [(0.5, 10.0), (2.5, 95.0), (6.0, 170.0)] {
        let w = g.weights(frame.direction(gamma, psi), sun);
        assert!(w.len() == 4 && w.iter().all(|&(k, x)| k >= base && x >= -1e-12), "{w:?}");
        let j = rows.iter().rposition(|&r| r <= gamma).unwrap();
        let r = j as f64 + (gamma - rows[j]) / (rows[j + 1] - rows[j]);
        let c = psi / 180.0 * (SUN_PATCH_COLS - 1) as f64;
        let want = 1.0 + 0.3 * r + 0.1 * c + 0.02 * r * c;
        let got: f64 = w.iter().map(|&(k, x)| x * field(k)).sum();
        assert!((got - want).abs() < 1e-9, "({gamma}, {psi}): {got} against {want}");
    }
    // A smooth field over the sphere, at every node's direction.
    let smooth = |k: usize| {
        let (z, a) = g.node_deg(k, sun);
        direction_deg(z, a).dot(glam::DVec3::new(0.3, -0.5, 0.8))
    };
    let at =
        |gamma: f64| -> f64 { g.weights(frame.direction(gamma, 60.0), sun).iter().map(|&(k, x)| x * smooth(k)).sum() };
    let (inside, outside) = (at(SUN_PATCH_DEG - 1e-7), at(SUN_PATCH_DEG + 1e-7));
    assert!((inside - outside).abs() < 1e-6, "{inside} against {outside}");
    assert!(g.weights(frame.direction(SUN_PATCH_DEG + 1e-7, 60.0), sun).iter().all(|&(k, _)| k < base));
    // The sun 1° over the horizon: below it, toward the horizon, the
    // patch's cells reach the ground.
    let low = (89.0, 20.0);
    let w = g.weights(SunFrame::new(low).direction(0.9, 175.0), low);
    assert!(w.iter().all(|&(k, _)| k < base), "{w:?}");
    let w = g.weights(SunFrame::new(low).direction(0.5, 5.0), low);
    assert!(w.iter().all(|&(k, _)| k >= base), "{w:?}");
}

/// A field linear in the rows' and columns' coordinates (between rows,
/// in the zenith angle over the sky and in the distance to the ground
/// under it) comes back exactly, the weights sum to 1, the mirror image
/// about the sun's vertical gets the same weights, and no weight crosses
/// the horizon.
#[test]
fn bilinear_fields_come_back_and_the_horizon_is_not_crossed() {
    let g = grid();
    let sun_az = -40.0;
    let field = |k: usize| {
        let (row, col) = (k / g.cols, k % g.cols);
        1.0 + 0.3 * row as f64 + 0.1 * col as f64 + 0.02 * (row * col) as f64
    };
    let horizon = g.standpoint.horizon_zenith_deg();
    // The sky rows' zenith angles, and the ground rows' distances.
    let sky_rows: Vec<f64> = (0..9).map(|j| g.node_deg(j * 7, (60.0, 0.0)).0).collect();
    let (near, far) =
        (g.standpoint.altitude_km, g.standpoint.ground_distance_km(horizon + HORIZON_MARGIN_DEG).unwrap());
    // The sun high, far from these directions: by the zenith, between
    // the sky's last two rows, between its last row and the horizon;
    // under it, a ground texel by the horizon (60 m away from 1 mm up),
    // and farther down.
    let sun = (60.0, sun_az);
    for (z, a) in [
        (10.0, 5.0),
        (45.0, 100.0),
        (89.95, 170.0),
        (90.0005, 20.0),
        (90.0012, 30.0),
        (90.05, 60.0),
        (135.0, 179.0),
        (179.5, 0.0),
    ] {
        let d = direction_deg(z, sun_az + a);
        let w = g.weights(d, sun);
        assert_eq!(w.len(), 4);
        assert!((w.iter().map(|x| x.1).sum::<f64>() - 1.0).abs() < 1e-12, "{w:?}");
        assert!(w.iter().all(|&(n, x)| x >= -1e-12 && (n < g.rows * g.cols) == (z < horizon)), "({z}, {a}): {w:?}");
        // Row and column coordinates of d.
        let r = if z < horizon {
            let j = sky_rows.iter().rposition(|&zj| zj <= z).unwrap().min(7);
            j as f64 + ((z - sky_rows[j]) / (sky_rows[j + 1] - sky_rows[j])).min(1.0)
        } else {
            9.0 + ((g.standpoint.ground_distance_km(z).unwrap() - near) / (far - near)).min(1.0) * 2.0
        };
        let c = a / 180.0 * 6.0;
        let want = 1.0 + 0.3 * r + 0.1 * c + 0.02 * r * c;
        let got: f64 = w.iter().map(|&(n, x)| x * field(n)).sum();
        assert!((got - want).abs() < 1e-9, "({z}, {a}): {got} against {want}");
        let mirrored = g.weights(direction_deg(z, sun_az - a), sun);
        assert_eq!(w.iter().map(|x| x.0).collect::<Vec<_>>(), mirrored.iter().map(|x| x.0).collect::<Vec<_>>());
    }
}

/// Above the ground the horizon drops below 90°, and the rows follow it.
#[test]
fn the_horizon_follows_the_observer() {
    let up = Standpoint::new(Geometry::Spherical, 6371.0, 10.0);
    let h = up.horizon_zenith_deg();
    assert!((h - (90.0 + (6371.0f64 / 6381.0).acos().to_degrees())).abs() < 1e-12 && h > 93.0, "{h}");
    // On the ground, the renderer's observer is 1 mm up: 0.001° of dip.
    let ground = Standpoint::new(Geometry::Spherical, 6371.0, 0.0).horizon_zenith_deg();
    assert!(ground > 90.0009 && ground < 90.0011, "{ground}");
    assert_eq!(Standpoint::new(Geometry::PlaneParallel, 6371.0, 10.0).horizon_zenith_deg(), 90.0);
    let g = MsGrid::new([5, 3], up);
    let last_sky = g.node_deg(4 * 3, (45.0, 0.0)).0;
    let last_ground = g.node_deg(g.grid_nodes() - 1, (45.0, 0.0)).0;
    assert!(
        (last_sky - (h - HORIZON_MARGIN_DEG)).abs() < 1e-9 && (last_ground - (h + HORIZON_MARGIN_DEG)).abs() < 1e-9,
        "{last_sky} {last_ground}"
    );
}

/// The distance to the ground: the altitude at the nadir, √(h (2R + h))
/// at the horizon (the tangent's length), h / cos α over a plane, none
/// above the horizon; and its inverse gives the angle back.
#[test]
fn the_distance_to_the_ground_and_back() {
    for (geometry, altitude_km) in [
        (Geometry::Spherical, 0.0),
        (Geometry::Spherical, 0.3),
        (Geometry::Spherical, 10.0),
        (Geometry::PlaneParallel, 0.3),
    ] {
        let p = Standpoint::new(geometry, 6371.0, altitude_km);
        let (h, horizon) = (p.altitude_km, p.horizon_zenith_deg());
        assert!((p.ground_distance_km(180.0).unwrap() - h).abs() < 1e-12 * h.max(1.0), "{p:?}");
        assert_eq!(p.ground_distance_km(horizon - 1e-6), None, "{p:?}");
        if geometry == Geometry::Spherical {
            let tangent = (h * (2.0 * 6371.0 + h)).sqrt();
            let by_horizon = p.ground_distance_km(horizon + 1e-9).unwrap();
            assert!((by_horizon - tangent).abs() < 0.01 * tangent, "{p:?}: {by_horizon} against {tangent}");
        } else {
            assert!((p.ground_distance_km(120.0).unwrap() - h / 60f64.to_radians().cos()).abs() < 1e-12);
        }
        for z in [horizon + HORIZON_MARGIN_DEG, horizon + 0.01, 100.0, 150.0, 179.9] {
            let t = p.ground_distance_km(z).unwrap();
            let back = p.zenith_for_ground_distance_deg(t);
            assert!((back - z).abs() < 1e-7, "{p:?}: {z} -> {t} km -> {back}");
        }
    }
}
