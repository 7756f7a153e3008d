//! Multiple scattering from a coarser grid of texels, measured (`sky bench
//! bake --coarse-ms`; issue 12's candidate "multiple scattering is smooth in
//! direction ... estimate it on a coarser set of directions and
//! interpolate").
//!
//! With single scattering by quadrature a texel is SS + MS: SS exact and
//! cheap at every texel, MS the Monte Carlo part. If MS were rendered only
//! at every `stride`-th texel (`--stride UxV`: along u and along v) and
//! interpolated bilinearly in the slice's (u, v), its cost would fall by
//! U V, and what the
//! interpolation costs in accuracy is the question measured here, at the
//! worst place for a bilinear filter: the centre of each cell of the coarse
//! grid, where it is the mean of the four corners.
//!
//! The coarse grid is the benchmark's reference (texel centres of the
//! slice at a `stride`-th of its size, [`super::bench`]); the cell centres
//! are rendered at the same sample count. With Y the reference luminance,
//! S its single scattering by quadrature and M = Y − S, each cell centre c
//! has the relative error
//!
//!   e_c = (¼ Σ_corners M_k − M_c) / Y_c
//!
//! and, from the renders' own standard errors σ, the noise variance
//! n_c = (σ_c² + Σ σ_k² / 16) / Y_c². The interpolation's own RMS error is
//! √max(0, mean e² − mean n) (the noise taken out, as the benchmark does for
//! the variance); √(mean n) is the noise floor it cannot be told below.
//! Cells whose corners lie on both sides of the horizon (where the sky
//! meets the ground, a discontinuity no smooth filter crosses: a coarse
//! grid would have rows on either side of it) are counted apart.

use super::bench::BenchError;
use crate::bake::file::BasisSky;
use crate::directions::camera::Camera;
use crate::directions::mapping::DirectionMapping;
use crate::render::{self, Image, Scene, View};
use glam::DVec3;
use std::sync::atomic::AtomicBool;

/// The seed of the cell centres' renders.
const CENTRE_SEED: u64 = 0xce_47e5;

/// What interpolating multiple scattering over one slice's coarse grid costs
/// in accuracy.
#[derive(Debug, Clone, serde::Serialize)]
pub struct CoarseMs {
    /// Cell centres measured, and those left out for straddling the horizon.
    pub cells: usize,
    pub horizon_cells: usize,
    /// The interpolation's RMS relative error of Y, the noise taken out;
    /// the noise floor below which it cannot be told; the 95th percentile of
    /// the measured |e| (noise included).
    pub rms_rel_error: f64,
    pub noise_floor: f64,
    pub p95_abs_rel_error: f64,
    /// The mean share of single scattering in Y at the cell centres.
    pub single_share: f64,
    /// The same error over the cells away from the sun and the horizon
    /// (centre at least [`FAR_SUN_DEG`] from the sun and
    /// [`FAR_ELEVATION_DEG`] above the horizon): where the sky is smooth,
    /// if anywhere.
    pub far_cells: usize,
    pub far_rms_rel_error: f64,
    pub far_noise_floor: f64,
}

/// What "away from the sun and the horizon" means in [`CoarseMs`], degrees.
pub const FAR_SUN_DEG: f64 = 15.0;
pub const FAR_ELEVATION_DEG: f64 = 10.0;

/// Unit vector to (zenith, azimuth) in degrees, for a `directions` camera.
fn zenith_azimuth_deg(d: DVec3) -> (f64, f64) {
    (libm::acos(d.z.clamp(-1.0, 1.0)).to_degrees(), libm::atan2(d.y, d.x).to_degrees())
}

/// Measures one slice: `reference` is the benchmark's reference render of
/// `reference_view` (the coarse grid).
pub(super) fn measure(
    sky: &BasisSky,
    reference_view: &View,
    reference: &Image,
    scene: &Scene,
    pool: &rayon::ThreadPool,
    cancel: &AtomicBool,
) -> Result<CoarseMs, BenchError> {
    let (nw, nh) = (reference.width, reference.height);
    let mapping = DirectionMapping::new(reference_view.sun_zenith_deg, sky.threshold_deg);
    let camera = Camera::Lut { mapping, sun_azimuth_deg: reference_view.sun_azimuth_deg };
    let at = |x: f64, y: f64| camera.direction(x, y, nw, nh).expect("a LUT camera maps every position");
    let node = |i: usize, j: usize| at(i as f64 + 0.5, j as f64 + 0.5);
    // The horizon as the observer sees it: the direction that grazes the ground.
    let r_km = scene.medium.radius_km;
    let h_km = sky.altitude_m / 1000.0;
    let horizon_z = if r_km > 0.0 && h_km > 0.0 { -libm::sqrt(1.0 - (r_km / (r_km + h_km)).powi(2)) } else { 0.0 };
    let below = |d: DVec3| d.z < horizon_z;
    let mut cells = Vec::new();
    let mut horizon_cells = 0;
    for j in 0..nh.saturating_sub(1) {
        for i in 0..nw.saturating_sub(1) {
            let corners = [(i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)];
            let c = at(i as f64 + 1.0, j as f64 + 1.0);
            let sides = corners.iter().map(|&(a, b)| below(node(a, b))).chain([below(c)]).collect::<Vec<_>>();
            if sides.iter().any(|&s| s != sides[0]) {
                horizon_cells += 1;
                continue;
            }
            cells.push((corners, c));
        }
    }
    let dirs: Vec<(f64, f64)> = cells.iter().map(|(_, c)| zenith_azimuth_deg(*c)).collect();
    if dirs.is_empty() {
        return Ok(CoarseMs { horizon_cells, ..interpolation_error(&[]) });
    }
    let view = View {
        single_scatter: reference_view.single_scatter,
        sun_azimuth_deg: reference_view.sun_azimuth_deg,
        ..View::directions(
            dirs,
            reference_view.sun_zenith_deg,
            reference_view.altitude_m,
            reference_view.spp,
            CENTRE_SEED,
        )
    };
    let centres = pool.install(|| render::render(scene, &view, cancel, &|| {})).map_err(|_| BenchError::Cancelled)?;
    // Single scattering by quadrature, as the renders added it.
    let single_y = |d: DVec3| render::single_by_quadrature(scene, &view, d).0[1];
    let node_single: Vec<f64> = pool.install(|| {
        use rayon::prelude::*;
        (0..nw * nh).into_par_iter().map(|k| single_y(node(k % nw, k / nw))).collect()
    });
    let samples: Vec<(Cell, DVec3)> = cells
        .iter()
        .zip(&centres.pixels)
        .map(|((corners, c), p)| {
            (
                Cell {
                    corners: corners.map(|(a, b)| texel(&reference.pixels[b * nw + a], node_single[b * nw + a])),
                    centre: texel(p, single_y(*c)),
                },
                *c,
            )
        })
        .collect();
    Ok(CoarseMs { horizon_cells, ..with_far(&samples, reference_view.sun_direction()) })
}

fn texel(p: &render::PixelResult, single: f64) -> Texel {
    Texel { y: p.xyz[1], stderr: p.xyz_stderr[1], single }
}

/// [`interpolation_error`] over all `cells` (each with its centre's
/// direction), and over those away from the sun and the horizon.
fn with_far(cells: &[(Cell, DVec3)], sun: DVec3) -> CoarseMs {
    let far = |c: DVec3| {
        c.z >= FAR_ELEVATION_DEG.to_radians().sin()
            && libm::acos(c.dot(sun).clamp(-1.0, 1.0)) >= FAR_SUN_DEG.to_radians()
    };
    let all: Vec<Cell> = cells.iter().map(|(c, _)| c.clone()).collect();
    let far_cells: Vec<Cell> = cells.iter().filter(|(_, d)| far(*d)).map(|(c, _)| c.clone()).collect();
    let f = interpolation_error(&far_cells);
    CoarseMs {
        far_cells: f.cells,
        far_rms_rel_error: f.rms_rel_error,
        far_noise_floor: f.noise_floor,
        ..interpolation_error(&all)
    }
}

/// Measures multiple scattering interpolated from a grid of its own over
/// the sky (the sky's `rows` × `cols` nodes of the bake's
/// [`crate::bake::ms_grid::MsGrid`]) instead of the
/// LUT's texels, whose mapping bends steeply at low sun: nodes and cell
/// centres rendered at the reference's samples. The sky above the horizon
/// only (a grid below it, for the ground, would be of the same kind and is
/// not measured).
pub(super) fn measure_latlong(
    reference_view: &View,
    [rows, cols]: [usize; 2],
    scene: &Scene,
    pool: &rayon::ThreadPool,
    cancel: &AtomicBool,
) -> Result<CoarseMs, BenchError> {
    let az = reference_view.sun_azimuth_deg;
    // Row s and column t, both in [0, 1], of the grid's sky.
    let grid =
        crate::bake::ms_grid::MsGrid::new([rows, cols], scene.medium.standpoint(reference_view.altitude_m / 1000.0));
    let direction = |s: f64, t: f64| crate::directions::camera::direction_deg(grid.sky_zenith_deg(s), az + 180.0 * t);
    let node = |i: usize, j: usize| direction(j as f64 / (rows - 1) as f64, i as f64 / (cols - 1) as f64);
    let centre =
        |i: usize, j: usize| direction((j as f64 + 0.5) / (rows - 1) as f64, (i as f64 + 0.5) / (cols - 1) as f64);
    let mut dirs: Vec<DVec3> = (0..rows * cols).map(|k| node(k % cols, k / cols)).collect();
    dirs.extend((0..(rows - 1) * (cols - 1)).map(|k| centre(k % (cols - 1), k / (cols - 1))));
    let view = View {
        single_scatter: reference_view.single_scatter,
        sun_azimuth_deg: az,
        ..View::directions(
            dirs.iter().map(|d| zenith_azimuth_deg(*d)).collect(),
            reference_view.sun_zenith_deg,
            reference_view.altitude_m,
            reference_view.spp,
            CENTRE_SEED,
        )
    };
    let img = pool.install(|| render::render(scene, &view, cancel, &|| {})).map_err(|_| BenchError::Cancelled)?;
    let at = |k: usize| texel(&img.pixels[k], render::single_by_quadrature(scene, &view, dirs[k]).0[1]);
    let nodes: Vec<Texel> = pool.install(|| {
        use rayon::prelude::*;
        (0..rows * cols).into_par_iter().map(at).collect()
    });
    let cells: Vec<(Cell, DVec3)> = (0..(rows - 1) * (cols - 1))
        .map(|k| {
            let (i, j) = (k % (cols - 1), k / (cols - 1));
            let corners = [(i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)].map(|(a, b)| nodes[b * cols + a]);
            (Cell { corners, centre: at(rows * cols + k) }, dirs[rows * cols + k])
        })
        .collect();
    Ok(with_far(&cells, reference_view.sun_direction()))
}

/// A rendered texel: its luminance, the standard error of that, and the
/// single scattering by quadrature in it.
#[derive(Debug, Clone, Copy)]
struct Texel {
    y: f64,
    stderr: f64,
    single: f64,
}

/// A cell of the coarse grid: its four corners and its centre.
#[derive(Clone)]
struct Cell {
    corners: [Texel; 4],
    centre: Texel,
}

/// The interpolation's error over `cells` (see the module's text); cells
/// with an unlit corner or centre are left out.
fn interpolation_error(cells: &[Cell]) -> CoarseMs {
    let (mut e2, mut n2, mut share, mut abs_e) = (0.0, 0.0, 0.0, Vec::new());
    for cell in cells.iter().filter(|c| c.centre.y > 0.0 && c.corners.iter().all(|k| k.y > 0.0)) {
        let c = cell.centre;
        let m: f64 = cell.corners.iter().map(|k| 0.25 * (k.y - k.single)).sum();
        let corner_var: f64 = cell.corners.iter().map(|k| k.stderr * k.stderr / 16.0).sum();
        let e = (m - (c.y - c.single)) / c.y;
        e2 += e * e;
        n2 += (c.stderr * c.stderr + corner_var) / (c.y * c.y);
        share += c.single / c.y;
        abs_e.push(e.abs());
    }
    let used = abs_e.len();
    // Nothing lit, nothing measured.
    let k = if used > 0 { used as f64 } else { f64::NAN };
    abs_e.sort_by(f64::total_cmp);
    CoarseMs {
        cells: used,
        horizon_cells: 0,
        rms_rel_error: if used > 0 { ((e2 - n2) / k).max(0.0).sqrt() } else { f64::NAN },
        noise_floor: (n2 / k).sqrt(),
        p95_abs_rel_error: abs_e.get((used * 95) / 100).or(abs_e.last()).copied().unwrap_or(f64::NAN),
        single_share: share / k,
        far_cells: 0,
        far_rms_rel_error: f64::NAN,
        far_noise_floor: f64::NAN,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::rng::Rng;

    /// Cells of a field M(x, y) of multiple scattering over a unit grid
    /// (single scattering 1 everywhere), each value with Gaussian noise of
    /// relative standard error `rel` (and that error reported).
    fn cells(field: impl Fn(f64, f64) -> f64, rel: f64) -> Vec<Cell> {
        let mut rng = Rng::new(7, 0, 0);
        let mut texel = |x: f64, y: f64| {
            let v = 1.0 + field(x, y);
            let (u1, u2) = (rng.uniform().max(1e-300), rng.uniform());
            let g = (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
            Texel { y: v * (1.0 + rel * g), stderr: v * rel, single: 1.0 }
        };
        let mut out = Vec::new();
        for j in 0..40 {
            for i in 0..40 {
                let (x, y) = (i as f64, j as f64);
                let corners = [texel(x, y), texel(x + 1.0, y), texel(x, y + 1.0), texel(x + 1.0, y + 1.0)];
                out.push(Cell { corners, centre: texel(x + 0.5, y + 0.5) });
            }
        }
        out
    }

    #[test]
    fn a_bilinear_field_interpolates_exactly() {
        let r = interpolation_error(&cells(|x, y| 2.0 + 0.1 * x + 0.05 * y + 0.01 * x * y, 0.0));
        assert_eq!(r.cells, 1600);
        assert!(r.rms_rel_error < 1e-12 && r.noise_floor == 0.0, "{r:?}");
        assert!(r.single_share > 0.0 && r.single_share < 0.5, "{r:?}");
        let none = interpolation_error(&[]);
        assert!(none.cells == 0 && none.rms_rel_error.is_nan() && none.noise_floor.is_nan(), "{none:?}");
    }

    #[test]
    fn a_curved_field_shows_its_interpolation_error() {
        // M = x²: the mean of the corners overshoots the centre by 1/4,
        // relative to Y = 1 + (x + 1/2)² at the centre.
        let r = interpolation_error(&cells(|x, _| x * x, 0.0));
        let want: f64 = (0..40).map(|i| (0.25 / (1.0 + (i as f64 + 0.5).powi(2))).powi(2)).sum::<f64>() / 40.0;
        assert!((r.rms_rel_error - want.sqrt()).abs() < 1e-12, "{} against {}", r.rms_rel_error, want.sqrt());
    }

    #[test]
    fn noise_is_taken_out_and_shown_as_the_floor() {
        // 1 % noise on a bilinear field: the floor is the noise of a centre
        // and of the mean of four corners, relative to Y. What is left of
        // the error is the noise of the mean square over 1600 cells, whose
        // standard deviation is √(2/1600) = 3.5 % of the floor squared: 0.4
        // of the floor is 4.6 such deviations, a chance of 2e-6 for a seed
        // drawn at random (this one is fixed).
        let r = interpolation_error(&cells(|x, y| 3.0 + 0.02 * x + 0.01 * y, 0.01));
        let floor = 0.01 * (1.0f64 + 4.0 / 16.0).sqrt();
        assert!((r.noise_floor / floor - 1.0).abs() < 0.05, "{r:?} against {floor}");
        assert!(r.rms_rel_error < 0.4 * r.noise_floor, "{r:?}");
        // A real error (the corners overshoot a curved field by 0.01, 0.05
        // to 0.25 % of Y) under noise half its size is seen, and measured
        // to within 10 %.
        let curved = |x: f64, _: f64| 3.0 + 0.04 * (x - 20.0).powi(2);
        let exact = interpolation_error(&cells(curved, 0.0)).rms_rel_error;
        let r = interpolation_error(&cells(curved, 0.0005));
        assert!(r.rms_rel_error > 1.5 * r.noise_floor, "{r:?}");
        assert!((r.rms_rel_error / exact - 1.0).abs() < 0.1, "{} against {exact}", r.rms_rel_error);
    }

    #[test]
    fn directions_round_trip_through_zenith_and_azimuth() {
        for d in [DVec3::new(0.3, -0.4, 0.866), DVec3::new(-0.9, 0.1, -0.2), DVec3::Z] {
            let d = d.normalize();
            let (z, a) = zenith_azimuth_deg(d);
            assert!((crate::directions::direction_deg(z, a) - d).length() < 1e-12, "{d}");
        }
    }
}
