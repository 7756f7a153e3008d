//! Tests of `spherical`: the iteration's fixed points in plane-parallel
//! media, where the columns are the exact solution.

use super::*;
use crate::transport::columns::grid;
use crate::transport::columns::tests::layers_with;

fn layers(file: &str, wavelength_nm: f64) -> Layers {
    layers_with(file, wavelength_nm, 16)
}

/// In a plane-parallel atmosphere the columns are the exact solution:
/// the iteration, which integrates each node's ray with the source
/// linear across each layer where the columns solve each layer exactly,
/// moves the view's radiance by no more than that discretisation.
#[test]
fn plane_parallel_columns_are_a_fixed_point() {
    let l = layers("tests/atmospheres/disort_rayleigh_hg.toml", 450.0);
    let sun = 50f64.to_radians();
    let plain = Columns::solve(&l, 8, grid(&l, sun, 1f64.to_radians()));
    let settings = Settings { stop_spacing: (0.0, 0.0), ..Settings::default() };
    let (iterated, report) = solve(&l, 8, grid(&l, sun, 1f64.to_radians()), &settings);
    assert!(report.moves.len() == 1, "{report:?}");
    let phis = [0.0, 0.7, 2.0, PI];
    for mu in [0.9, 0.5, 0.1] {
        for (a, b) in plain.rays(sun, mu, &phis).iter().zip(iterated.rays(sun, mu, &phis)) {
            assert!((b / a - 1.0).abs() < 3e-4, "view {mu}: {b} against {a}");
        }
    }
}

/// A thick cloud (the tau-60 slab, 4 streams) is a fixed point too
/// with the default node levels and stops: node levels at the cloud's
/// edges, the node rays stopping at least every `stop_tau` of optical
/// depth. Measured: views 1.2e-3 and the ground's irradiance 4.9e-4 off
/// the columns after one pass. Without the stops in optical depth the
/// rays read the cloud's source linear over tens of optical depths and
/// the iteration crept away from the columns, about 1 % a pass, never
/// converging (views 23 % off after 12 passes); with stops every 0.5
/// of optical depth 3 % off, still creeping.
#[test]
fn a_thick_cloud_in_plane_parallel_stays_at_the_columns() {
    let l = layers_with("tests/atmospheres/disort_cloud_tau60.toml", 550.0, 8);
    let sun = 50f64.to_radians();
    let plain = Columns::solve(&l, 4, grid(&l, sun, 1f64.to_radians()));
    let settings = Settings::default();
    let (iterated, report) = solve(&l, 4, grid(&l, sun, 1f64.to_radians()), &settings);
    assert!(report.moves.last().is_some_and(|&m| m < settings.tolerance), "not converged: {report:?}");
    let phis = [0.0, 2.0, PI];
    let mut worst = 0.0f64;
    for mu in [0.9, 0.5, 0.1] {
        for (a, b) in plain.rays(sun, mu, &phis).iter().zip(iterated.rays(sun, mu, &phis)) {
            worst = worst.max((b / a - 1.0).abs());
        }
    }
    let ground = iterated.ground_irradiance_at(sun) / plain.ground_irradiance_at(sun) - 1.0;
    assert!(worst < 3e-3 && ground.abs() < 3e-3, "views {worst:.2e}, ground {ground:.2e} off the columns");
}

/// The iteration finds the solution by itself: started from no diffuse
/// light at all (only the single scattering's source), in a
/// plane-parallel atmosphere it converges to the columns' exact
/// solution, within a few times the discretisation of the test above
/// (each order of scattering adds its own; measured −5.1e-4 at μ 0.5
/// and −1.23e-3 at μ 0.1 after 19 passes), when the node levels are every interface (every
/// 0.5 km here; with the default levels, the whole field read linearly
/// in altitude between them, it is 0.4 % low at μ 0.1).
#[test]
fn plane_parallel_iteration_from_nothing_finds_the_columns() {
    let l = layers("tests/atmospheres/disort_rayleigh_hg.toml", 450.0);
    let sun = 50f64.to_radians();
    let zenith = grid(&l, sun, 1f64.to_radians());
    let plain = Columns::solve(&l, 8, zenith.clone());
    let mut solution = Solution::new(&l, 8, &zenith);
    for column in solution.a.iter_mut() {
        for mode in column.iter_mut() {
            for a in mode.iter_mut() {
                a.iter_mut().for_each(|x| *x = 0.0);
            }
        }
    }
    solution.ground_irradiance = solution.ground_direct.clone();
    let settings = Settings {
        modes: 15,
        azimuth_intervals: 32,
        tolerance: 1e-6,
        max_passes: 60,
        levels_km: (0..200).map(|k| k as f64 * 0.5).collect(),
        stop_spacing: (0.0, 0.0),
        ..Settings::default()
    };
    let report = iterate(&l, &mut solution, &zenith, &settings);
    let iterated = Columns::from_solution(&l, solution, zenith);
    let phis = [0.0, 0.7, 2.0, PI];
    for mu in [0.9, 0.5, 0.1] {
        for (a, b) in plain.rays(sun, mu, &phis).iter().zip(iterated.rays(sun, mu, &phis)) {
            assert!((b / a - 1.0).abs() < 2e-3, "view {mu}: {b} against {a} after {} passes", report.moves.len() + 1);
        }
    }
}
