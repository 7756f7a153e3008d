//! Multiple scattering from a grid of directions of its own (issue 12's
//! "multiple scattering is smooth in direction ... estimate it on a coarser
//! set of directions and interpolate"), for a bake whose preset sets
//! `ms_grid = "RxC"`.
//!
//! With single scattering by quadrature (`SingleScatter::Quadrature`) a
//! texel is S + M: S, the sunlight scattered once (or reflected once by the
//! ground), exact and cheap at every texel; M, the light scattered more
//! than once, the Monte Carlo part. M is smooth in direction, so it is
//! rendered only at the nodes of a grid and interpolated bilinearly to each
//! texel, which then costs its quadrature alone.
//!
//! The grid is not the LUT's: the talk's sun-centred mapping bends steeply
//! at low sun, and interpolating M across its texels missed by 4.5 % (clear)
//! and 11 % (hazed) at a sun zenith of 85° (`sky bench bake --coarse-ms`,
//! README). It is a latitude-longitude grid turned to the sun: R rows of
//! zenith angle over the sky, crowding toward the horizon,
//!
//!   θ = θ_sky (1 − (1 − s)²),  s = j / (R − 1),
//!
//! θ_sky 0.01° above the observer's horizon (where the renderer's rays
//! start meeting the ground: 0.001° below the horizontal for its lowest
//! observer, 1 mm up), and rows mirrored from the nadir up to 0.01° below it
//! for the ground (G = max(2, ⌈R / 4⌉)
//! rows: at the ground the view sees the same sunlit ground in every
//! direction, and only an observer above it sees more), by C azimuths from
//! the sun's, φ = 180° t, t = i / (C − 1) (the sky is mirror-symmetric about
//! the sun's vertical). A texel between a last row and the horizon takes the
//! row's value: the horizon, where the sky meets the ground, is the one
//! edge no bilinear filter may cross.

use crate::render::camera::Camera;
use crate::render::{Image, PixelResult, Scene, View};
use glam::DVec3;

/// How far from the horizon the grid's last rows lie, degrees.
pub const HORIZON_MARGIN_DEG: f64 = 0.01;

/// A grid of directions over the sphere, turned to the sun (see the module).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MsGrid {
    pub rows: usize,
    pub cols: usize,
    pub ground_rows: usize,
    /// The zenith angle of the observer's horizon, degrees (90 on the ground).
    pub horizon_zenith_deg: f64,
}

impl MsGrid {
    /// The grid of `[rows, cols]` (both 2 or more) for an observer whose
    /// horizon lies at `horizon_zenith_deg`
    /// ([`crate::render::segments::horizon_zenith_deg`]: where the renderer's
    /// rays start meeting the ground, for the texels to be told apart as the
    /// renderer tells them).
    pub fn new([rows, cols]: [usize; 2], horizon_zenith_deg: f64) -> MsGrid {
        MsGrid { rows, cols, ground_rows: rows.div_ceil(4).max(2), horizon_zenith_deg }
    }

    /// Nodes in all: the sky's rows, then the ground's, each of `cols`.
    pub fn nodes(&self) -> usize {
        (self.rows + self.ground_rows) * self.cols
    }

    /// The sky's angular extent from the zenith and the ground's from the
    /// nadir, degrees.
    fn extents_deg(&self) -> (f64, f64) {
        (self.horizon_zenith_deg - HORIZON_MARGIN_DEG, 180.0 - self.horizon_zenith_deg - HORIZON_MARGIN_DEG)
    }

    /// The zenith angle of row `s` in [0, 1] of the sky's rows (0 the
    /// zenith, 1 the last row over the horizon), degrees.
    pub fn sky_zenith_deg(&self, s: f64) -> f64 {
        self.extents_deg().0 * (1.0 - (1.0 - s) * (1.0 - s))
    }

    /// Node `k` (row-major: the sky's rows from the zenith down, then the
    /// ground's from the nadir up) as (zenith, azimuth) in degrees, with the
    /// sun at azimuth `sun_azimuth_deg`.
    pub fn node_deg(&self, k: usize, sun_azimuth_deg: f64) -> (f64, f64) {
        let (row, col) = (k / self.cols, k % self.cols);
        let azimuth_deg = sun_azimuth_deg + 180.0 * col as f64 / (self.cols - 1) as f64;
        let zenith_deg = if row < self.rows {
            self.sky_zenith_deg(row as f64 / (self.rows - 1) as f64)
        } else {
            let s = (row - self.rows) as f64 / (self.ground_rows - 1) as f64;
            180.0 - self.extents_deg().1 * (1.0 - (1.0 - s) * (1.0 - s))
        };
        (zenith_deg, azimuth_deg)
    }

    /// The four nodes around direction `d` and their bilinear weights (sum
    /// 1), the sun at `sun_azimuth_deg`.
    pub fn weights(&self, d: DVec3, sun_azimuth_deg: f64) -> [(usize, f64); 4] {
        let zenith_deg = libm::acos(d.z.clamp(-1.0, 1.0)).to_degrees();
        // Azimuth from the sun's, folded into [0, 180] by the mirror symmetry.
        let phi = (libm::atan2(d.y, d.x).to_degrees() - sun_azimuth_deg).rem_euclid(360.0);
        let phi = if phi > 180.0 { 360.0 - phi } else { phi };
        let (sky, ground) = self.extents_deg();
        // Inverse of α = A (1 − (1 − s)²): s = 1 − √(1 − α / A).
        let s_of = |alpha: f64, a: f64| 1.0 - (1.0 - (alpha / a).clamp(0.0, 1.0)).sqrt();
        let (first_row, rows, s) = if zenith_deg <= self.horizon_zenith_deg { (0, self.rows, s_of(zenith_deg, sky)) } else { (self.rows, self.ground_rows, s_of(180.0 - zenith_deg, ground)) };
        let (r, c) = (s * (rows - 1) as f64, phi / 180.0 * (self.cols - 1) as f64);
        let (r0, c0) = ((r.floor() as usize).min(rows - 2), (c.floor() as usize).min(self.cols - 2));
        let (fr, fc) = (r - r0 as f64, c - c0 as f64);
        let at = |row: usize, col: usize| (first_row + row) * self.cols + col;
        [(at(r0, c0), (1.0 - fr) * (1.0 - fc)), (at(r0, c0 + 1), (1.0 - fr) * fc), (at(r0 + 1, c0), fr * (1.0 - fc)), (at(r0 + 1, c0 + 1), fr * fc)]
    }

    /// The view of the grid's nodes for `slice`: the same sun, observer,
    /// sampling and seed, one pixel per node.
    pub fn view(&self, slice: &View) -> View {
        self.probe_view(slice, 1)
    }

    /// Every `stride`-th node of [`MsGrid::view`] (what a draft's
    /// forecast times); all of them with a stride of 1.
    pub fn probe_view(&self, slice: &View, stride: usize) -> View {
        let dirs: Vec<(f64, f64)> = (0..self.nodes()).step_by(stride.max(1)).map(|k| self.node_deg(k, slice.sun_azimuth_deg)).collect();
        View { width: dirs.len(), height: 1, camera: Camera::Directions(dirs), ..slice.clone() }
    }

    /// Core-seconds of [`MsGrid::resample`]'s quadratures for `slice`
    /// (the texels' and the nodes'), on this process's threads: what a
    /// slice from a grid costs besides its nodes.
    pub fn time_quadrature(&self, scene: &Scene, slice: &View) -> f64 {
        let start = std::time::Instant::now();
        std::hint::black_box(crate::render::single_per_pixel(scene, slice));
        std::hint::black_box(crate::render::single_per_pixel(scene, &self.view(slice)));
        start.elapsed().as_secs_f64() * rayon::current_num_threads() as f64
    }

    /// The slice of `slice` (a LUT view) from its grid's render (`nodes`,
    /// of [`MsGrid::view`]): each texel its single scattering by quadrature
    /// plus the bilinear mean of the nodes' multiple scattering (each
    /// node's XYZ less its own quadrature), its standard error that of the
    /// weighted mean of the nodes', its samples their weighted mean.
    pub fn resample(&self, nodes: &Image, scene: &Scene, slice: &View) -> Image {
        use rayon::prelude::*;
        let grid_view = self.view(slice);
        let node_single = crate::render::single_per_pixel(scene, &grid_view);
        let multiple: Vec<[f64; 3]> = nodes.pixels.iter().zip(&node_single).map(|(p, s)| std::array::from_fn(|c| p.xyz[c] - s[c])).collect();
        let texel_single = crate::render::single_per_pixel(scene, slice);
        let (w, h) = (slice.width, slice.height);
        let pixels = (0..w * h)
            .into_par_iter()
            .map(|i| {
                let d = slice.camera.direction((i % w) as f64 + 0.5, (i / w) as f64 + 0.5, w, h);
                let Some(d) = d else { return PixelResult::from_xyz([0.0; 3]) };
                let (mut xyz, mut var, mut samples) = (texel_single[i], [0.0; 3], 0.0);
                for (k, wk) in self.weights(d, slice.sun_azimuth_deg) {
                    let p = &nodes.pixels[k];
                    for c in 0..3 {
                        xyz[c] += wk * multiple[k][c];
                        var[c] += wk * wk * p.xyz_stderr[c] * p.xyz_stderr[c];
                    }
                    samples += wk * p.samples as f64;
                }
                PixelResult { xyz_stderr: var.map(f64::sqrt), samples: samples.round() as u32, ..PixelResult::from_xyz(xyz) }
            })
            .collect();
        Image { width: w, height: h, pixels }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::camera::direction_deg;

    fn grid() -> MsGrid {
        MsGrid::new([9, 7], 90.0)
    }

    /// Every node's own direction gets weight 1 on itself.
    #[test]
    fn a_node_interpolates_to_itself() {
        let g = grid();
        assert_eq!((g.ground_rows, g.nodes()), (3, 12 * 7));
        for k in 0..g.nodes() {
            let (z, a) = g.node_deg(k, 30.0);
            // The zenith and nadir rows are one direction, whichever column.
            if !(1e-9..=180.0 - 1e-9).contains(&z) {
                continue;
            }
            let w = g.weights(direction_deg(z, a), 30.0);
            let on: f64 = w.iter().filter(|(n, _)| *n == k).map(|(_, x)| x).sum();
            assert!((on - 1.0).abs() < 1e-9, "node {k} at ({z}, {a}): {w:?}");
        }
    }

    /// A field linear in the rows' and columns' coordinates comes back
    /// exactly, the weights sum to 1, the mirror image about the sun's
    /// vertical gets the same weights, and no weight crosses the horizon.
    #[test]
    fn bilinear_fields_come_back_and_the_horizon_is_not_crossed() {
        let g = grid();
        let sun_az = -40.0;
        let field = |k: usize| {
            let (row, col) = (k / g.cols, k % g.cols);
            1.0 + 0.3 * row as f64 + 0.1 * col as f64 + 0.02 * (row * col) as f64
        };
        for (z, a) in [(10.0, 5.0), (45.0, 100.0), (89.95, 170.0), (90.05, 60.0), (135.0, 179.0), (179.5, 0.0)] {
            let d = direction_deg(z, sun_az + a);
            let w = g.weights(d, sun_az);
            assert!((w.iter().map(|x| x.1).sum::<f64>() - 1.0).abs() < 1e-12, "{w:?}");
            assert!(w.iter().all(|&(n, x)| x >= -1e-12 && (n < g.rows * g.cols) == (z < 90.0)), "({z}, {a}): {w:?}");
            // Row and column coordinates of d, from the grid's own formulas.
            let (sky, ground) = g.extents_deg();
            let r = if z < 90.0 { (1.0 - (1.0 - (z / sky).min(1.0)).sqrt()) * 8.0 } else { 9.0 + (1.0 - (1.0 - ((180.0 - z) / ground).min(1.0)).sqrt()) * 2.0 };
            let c = a / 180.0 * 6.0;
            let want = 1.0 + 0.3 * r + 0.1 * c + 0.02 * r * c;
            let got: f64 = w.iter().map(|&(n, x)| x * field(n)).sum();
            assert!((got - want).abs() < 1e-9, "({z}, {a}): {got} against {want}");
            let mirrored = g.weights(direction_deg(z, sun_az - a), sun_az);
            assert_eq!(w.map(|x| x.0), mirrored.map(|x| x.0));
        }
    }

    /// Above the ground the horizon drops below 90°, and the rows follow it.
    #[test]
    fn the_horizon_follows_the_observer() {
        use crate::atmosphere::Geometry;
        use crate::render::segments::horizon_zenith_deg;
        let h = horizon_zenith_deg(Geometry::Spherical, 6371.0, 10.0);
        assert!((h - (90.0 + (6371.0f64 / 6381.0).acos().to_degrees())).abs() < 1e-12 && h > 93.0, "{h}");
        // On the ground, the renderer's observer is 1 mm up: 0.001° of dip.
        let ground = horizon_zenith_deg(Geometry::Spherical, 6371.0, 0.0);
        assert!(ground > 90.0009 && ground < 90.0011, "{ground}");
        assert_eq!(horizon_zenith_deg(Geometry::PlaneParallel, 6371.0, 10.0), 90.0);
        let g = MsGrid::new([5, 3], h);
        let last_sky = g.node_deg(4 * 3, 0.0).0;
        let last_ground = g.node_deg(g.nodes() - 1, 0.0).0;
        assert!((last_sky - (h - HORIZON_MARGIN_DEG)).abs() < 1e-9 && (last_ground - (h + HORIZON_MARGIN_DEG)).abs() < 1e-9, "{last_sky} {last_ground}");
    }
}
