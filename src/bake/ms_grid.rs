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
//! README). It is a grid turned to the sun, of C azimuths from the sun's,
//! φ = 180° t, t = i / (C − 1) (the sky is mirror-symmetric about the sun's
//! vertical), by R rows of zenith angle over the sky, crowding toward the
//! horizon,
//!
//!   θ = θ_sky (1 − (1 − s)²),  s = j / (R − 1),
//!
//! θ_sky a hair (`HORIZON_MARGIN_DEG`) above the observer's horizon (where
//! the renderer's rays start meeting the ground: 0.001° below the horizontal
//! for its lowest observer, 1 mm up), and G = max(2, ⌈R / 4⌉) rows over the
//! ground, evenly spaced in the distance to the ground, from the nadir's
//! (the observer's altitude) to the distance a hair below the horizon.
//!
//! The weights are linear in the zenith angle between two sky rows and in
//! the distance to the ground between two ground rows, not in s: a bake of
//! the hazed sky at a sun zenith of 85° measured against the same slice
//! rendered whole showed what else does. Interpolated in s, whose rows
//! crowd to the horizon as √ of the angle from it, the texels within 0.1° of
//! the horizon came out 1 % too bright; in angle toward the ground, the
//! ground texels by the horizon, whose rays from 1 mm up cross 50 to 110 m
//! of hazy air (the angle's last 0.01° holds nearly all of that distance),
//! came out 20 % too dark: their multiple scattering is mostly the light
//! the air between scatters, in proportion to that distance. A texel
//! between a last row and the horizon takes the row's value: the horizon,
//! where the sky meets the ground, is the one edge no bilinear filter may
//! cross.
//!
//! Multiple scattering also peaks toward the sun (light scattered forward
//! twice and more, by the aerosols above all), narrower than the grid's
//! cells: at a sun zenith of 85° the texels 0.5 to 2° from the sun came out
//! 1 to 4 % too dark. A patch of nodes around the sun covers it: P rows of
//! angle from the sun crowding toward it, γ = γ_max (j / (P − 1))², by Q
//! angles around it from its zenith side, ψ = 180° i / (Q − 1) (the same
//! mirror symmetry), bilinear in γ and ψ. Its share fades to the grid's
//! over its outer 30 % so that no seam shows, and a texel whose cell of the
//! patch reaches below the horizon takes the grid's alone.

use crate::directions::camera::Camera;
use crate::render::segments::Standpoint;
use crate::render::{Image, PixelResult, Scene, View};
use glam::DVec3;

/// How far from the horizon the grid's last rows lie, degrees: 0.0001°,
/// where the ground is 73 m away from the lowest observer (113 m at the
/// horizon itself).
pub const HORIZON_MARGIN_DEG: f64 = 1e-4;

/// The sun patch's rows (the first is the sun's own direction), angles
/// around the sun, and radius in degrees.
pub const SUN_PATCH_ROWS: usize = 8;
pub const SUN_PATCH_COLS: usize = 7;
pub const SUN_PATCH_DEG: f64 = 10.0;
/// The outer share of the patch's radius over which it fades to the grid.
const SUN_PATCH_FADE: f64 = 0.3;

/// A grid of directions over the sphere, turned to the sun (see the module).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MsGrid {
    pub rows: usize,
    pub cols: usize,
    pub ground_rows: usize,
    /// Where the observer stands: its horizon, and how far the ground is.
    pub standpoint: Standpoint,
}

impl MsGrid {
    /// The grid of `[rows, cols]` (both 2 or more) for an observer at
    /// `standpoint` (the renderer's, for the texels to be told from the
    /// ground as the renderer tells them).
    pub fn new([rows, cols]: [usize; 2], standpoint: Standpoint) -> MsGrid {
        MsGrid { rows, cols, ground_rows: rows.div_ceil(4).max(2), standpoint }
    }

    /// Nodes in all: the sky's rows, then the ground's, each of `cols`,
    /// then the sun patch's.
    pub fn nodes(&self) -> usize {
        self.grid_nodes() + SUN_PATCH_ROWS * SUN_PATCH_COLS
    }

    /// The nodes of the grid without the sun patch.
    fn grid_nodes(&self) -> usize {
        (self.rows + self.ground_rows) * self.cols
    }

    /// The zenith angle of the sky's last row, degrees.
    fn sky_extent_deg(&self) -> f64 {
        self.standpoint.horizon_zenith_deg() - HORIZON_MARGIN_DEG
    }

    /// The distances to the ground of the ground's first row (the nadir)
    /// and last row (by the horizon), km.
    fn ground_extent_km(&self) -> (f64, f64) {
        let last = self.standpoint.horizon_zenith_deg() + HORIZON_MARGIN_DEG;
        (self.standpoint.altitude_km, self.standpoint.ground_distance_km(last).expect("below the horizon"))
    }

    /// The zenith angle of row `s` in [0, 1] of the sky's rows (0 the
    /// zenith, 1 the last row over the horizon), degrees.
    pub fn sky_zenith_deg(&self, s: f64) -> f64 {
        self.sky_extent_deg() * (1.0 - (1.0 - s) * (1.0 - s))
    }

    /// The distance to the ground of the ground's row `s` in [0, 1] (0 the
    /// nadir, 1 the last row under the horizon), km.
    fn ground_distance_km(&self, s: f64) -> f64 {
        let (near, far) = self.ground_extent_km();
        near + (far - near) * s
    }

    /// Node `k` (row-major: the sky's rows from the zenith down, then the
    /// ground's from the nadir up, then the sun patch's from the sun out)
    /// as (zenith, azimuth) in degrees, for the sun at `sun_deg` (zenith,
    /// azimuth).
    pub fn node_deg(&self, k: usize, sun_deg: (f64, f64)) -> (f64, f64) {
        if k >= self.grid_nodes() {
            let j = k - self.grid_nodes();
            let d =
                SunFrame::new(sun_deg).direction(patch_row_deg(j / SUN_PATCH_COLS), patch_col_deg(j % SUN_PATCH_COLS));
            return (libm::acos(d.z.clamp(-1.0, 1.0)).to_degrees(), libm::atan2(d.y, d.x).to_degrees());
        }
        let sun_azimuth_deg = sun_deg.1;
        let (row, col) = (k / self.cols, k % self.cols);
        let azimuth_deg = sun_azimuth_deg + 180.0 * col as f64 / (self.cols - 1) as f64;
        let zenith_deg = if row < self.rows {
            self.sky_zenith_deg(row as f64 / (self.rows - 1) as f64)
        } else {
            let s = (row - self.rows) as f64 / (self.ground_rows - 1) as f64;
            // The nadir row exactly (the inverse's rounding aside).
            if s == 0.0 {
                180.0
            } else {
                self.standpoint.zenith_for_ground_distance_deg(self.ground_distance_km(s))
            }
        };
        (zenith_deg, azimuth_deg)
    }

    /// The nodes around direction `d` and their weights (sum 1), the sun at
    /// `sun_deg` (zenith, azimuth): the sun patch's four, the grid's four,
    /// or both where the patch fades.
    pub fn weights(&self, d: DVec3, sun_deg: (f64, f64)) -> Vec<(usize, f64)> {
        let grid = self.grid_weights(d, sun_deg.1);
        let frame = SunFrame::new(sun_deg);
        let (gamma_deg, psi_deg) = frame.coordinates_deg(d);
        let share = ((SUN_PATCH_DEG - gamma_deg) / (SUN_PATCH_FADE * SUN_PATCH_DEG)).clamp(0.0, 1.0);
        let horizon = self.standpoint.horizon_zenith_deg();
        let in_sky = |d: DVec3| libm::acos(d.z.clamp(-1.0, 1.0)).to_degrees() < horizon;
        if share == 0.0 || !in_sky(d) {
            return grid.to_vec();
        }
        // Between patch rows j0 and j0 + 1 (γ_j = γ_max (j / (P − 1))²),
        // linear in γ; between its columns, linear in ψ.
        let last = (SUN_PATCH_ROWS - 1) as f64;
        let j0 = ((gamma_deg / SUN_PATCH_DEG).sqrt() * last).floor().min(last - 1.0) as usize;
        let (g0, g1) = (patch_row_deg(j0), patch_row_deg(j0 + 1));
        let fr = ((gamma_deg - g0) / (g1 - g0)).clamp(0.0, 1.0);
        let c = psi_deg / 180.0 * (SUN_PATCH_COLS - 1) as f64;
        let i0 = (c.floor() as usize).min(SUN_PATCH_COLS - 2);
        let fc = c - i0 as f64;
        let corners = [
            (j0, i0, (1.0 - fr) * (1.0 - fc)),
            (j0, i0 + 1, (1.0 - fr) * fc),
            (j0 + 1, i0, fr * (1.0 - fc)),
            (j0 + 1, i0 + 1, fr * fc),
        ];
        // A cell of the patch that reaches below the horizon would mix the
        // ground into the sky.
        if corners.iter().any(|&(j, i, _)| !in_sky(frame.direction(patch_row_deg(j), patch_col_deg(i)))) {
            return grid.to_vec();
        }
        let patch = corners.map(|(j, i, w)| (self.grid_nodes() + j * SUN_PATCH_COLS + i, w * share));
        let mut all = patch.to_vec();
        if share < 1.0 {
            all.extend(grid.map(|(k, w)| (k, w * (1.0 - share))));
        }
        all
    }

    /// The grid's four nodes around direction `d` and their bilinear
    /// weights (sum 1), the sun at azimuth `sun_azimuth_deg`.
    fn grid_weights(&self, d: DVec3, sun_azimuth_deg: f64) -> [(usize, f64); 4] {
        let zenith_deg = libm::acos(d.z.clamp(-1.0, 1.0)).to_degrees();
        // Azimuth from the sun's, folded into [0, 180] by the mirror symmetry.
        let phi = (libm::atan2(d.y, d.x).to_degrees() - sun_azimuth_deg).rem_euclid(360.0);
        let phi = if phi > 180.0 { 360.0 - phi } else { phi };
        // The row coordinate: over the sky, the row below by the inverse of
        // θ = A (1 − (1 − s)²), s = 1 − √(1 − θ / A), then linear in θ
        // between it and the next; over the ground, linear in the distance.
        let (first_row, rows, r) = match self
            .standpoint
            .ground_distance_km(zenith_deg)
            .filter(|_| zenith_deg > self.standpoint.horizon_zenith_deg())
        {
            None => {
                let a = self.sky_extent_deg();
                let last = (self.rows - 1) as f64;
                let s = 1.0 - (1.0 - (zenith_deg / a).clamp(0.0, 1.0)).sqrt();
                let r0 = (s * last).floor().min(last - 1.0);
                let (z0, z1) = (self.sky_zenith_deg(r0 / last), self.sky_zenith_deg((r0 + 1.0) / last));
                (0, self.rows, r0 + ((zenith_deg - z0) / (z1 - z0)).clamp(0.0, 1.0))
            }
            Some(distance_km) => {
                let (near, far) = self.ground_extent_km();
                (
                    self.rows,
                    self.ground_rows,
                    ((distance_km - near) / (far - near)).clamp(0.0, 1.0) * (self.ground_rows - 1) as f64,
                )
            }
        };
        let c = phi / 180.0 * (self.cols - 1) as f64;
        let (r0, c0) = ((r.floor() as usize).min(rows - 2), (c.floor() as usize).min(self.cols - 2));
        let (fr, fc) = (r - r0 as f64, c - c0 as f64);
        let at = |row: usize, col: usize| (first_row + row) * self.cols + col;
        [
            (at(r0, c0), (1.0 - fr) * (1.0 - fc)),
            (at(r0, c0 + 1), (1.0 - fr) * fc),
            (at(r0 + 1, c0), fr * (1.0 - fc)),
            (at(r0 + 1, c0 + 1), fr * fc),
        ]
    }

    /// The nodes that `slice`'s texels take (see [`RenderedNodes`]).
    pub fn rendered_nodes(&self, slice: &View) -> RenderedNodes {
        let sun_deg = (slice.sun_zenith_deg, slice.sun_azimuth_deg);
        let mut taken = vec![false; self.nodes()];
        let (w, h) = (slice.width, slice.height);
        for i in 0..w * h {
            if let Some(d) = slice.camera.direction((i % w) as f64 + 0.5, (i / w) as f64 + 0.5, w, h) {
                for (k, _) in self.weights(d, sun_deg).into_iter().filter(|&(_, wk)| wk > 0.0) {
                    taken[k] = true;
                }
            }
        }
        let mut nodes: Vec<usize> = Vec::new();
        let mut at = vec![None; self.nodes()];
        let direction = |k: usize| {
            let (z, a) = self.node_deg(k, sun_deg);
            crate::directions::camera::direction_deg(z, a)
        };
        for k in (0..self.nodes()).filter(|&k| taken[k]) {
            let d = direction(k);
            // The zenith's, the nadir's and the sun's row are each one
            // direction whatever the column: rendered once.
            at[k] = Some(match nodes.iter().position(|&j| direction(j).distance(d) < 1e-9) {
                Some(position) => position,
                None => {
                    nodes.push(k);
                    nodes.len() - 1
                }
            });
        }
        RenderedNodes { nodes, at }
    }

    /// The view of the nodes to render for `slice` (its
    /// [`MsGrid::rendered_nodes`]): the same sun, observer, sampling and
    /// seed, one pixel per node.
    pub fn view(&self, slice: &View) -> View {
        self.probe_view(slice, 1)
    }

    /// Every `stride`-th node of [`MsGrid::view`] (what a draft's
    /// forecast times); all of them with a stride of 1.
    pub fn probe_view(&self, slice: &View, stride: usize) -> View {
        let sun_deg = (slice.sun_zenith_deg, slice.sun_azimuth_deg);
        let dirs: Vec<(f64, f64)> = self
            .rendered_nodes(slice)
            .nodes
            .into_iter()
            .step_by(stride.max(1))
            .map(|k| self.node_deg(k, sun_deg))
            .collect();
        View { width: dirs.len(), height: 1, camera: Camera::Directions(dirs), ..slice.clone() }
    }

    /// Core-seconds of [`MsGrid::resample`]'s quadratures for `slice`
    /// (the texels' and the nodes'), on this process's threads: what a
    /// slice from a grid costs besides its nodes.
    pub fn time_quadrature(&self, scene: &Scene, slice: &View) -> f64 {
        time_single(scene, slice) + self.time_nodes_quadrature(scene, slice)
    }

    /// Core-seconds of the nodes' part of [`MsGrid::time_quadrature`].
    pub fn time_nodes_quadrature(&self, scene: &Scene, slice: &View) -> f64 {
        time_single(scene, &self.view(slice))
    }

    /// The slice of `slice` (a LUT view) from its grid's render (`nodes`,
    /// of [`MsGrid::view`]): each texel its single scattering by quadrature
    /// plus the bilinear mean of the nodes' multiple scattering (each
    /// node's XYZ less its own quadrature), its standard error that of the
    /// weighted mean of the nodes', its samples their weighted mean.
    pub fn resample(&self, nodes: &Image, scene: &Scene, slice: &View) -> Image {
        use rayon::prelude::*;
        let grid_view = self.view(slice);
        assert_eq!(nodes.pixels.len(), grid_view.width, "a render of this slice's nodes");
        let at = self.rendered_nodes(slice).at;
        let node_single = crate::render::single_per_pixel(scene, &grid_view);
        let multiple: Vec<[f64; 3]> =
            nodes.pixels.iter().zip(&node_single).map(|(p, s)| std::array::from_fn(|c| p.xyz[c] - s[c])).collect();
        let texel_single = crate::render::single_per_pixel(scene, slice);
        let (w, h) = (slice.width, slice.height);
        let pixels = (0..w * h)
            .into_par_iter()
            .map(|i| {
                let d = slice.camera.direction((i % w) as f64 + 0.5, (i / w) as f64 + 0.5, w, h);
                let Some(d) = d else { return PixelResult::from_xyz([0.0; 3]) };
                // The weights by rendered pixel: nodes of one direction
                // share one pixel's noise (a node of weight 0 is not rendered).
                let mut by_pixel: Vec<(usize, f64)> = Vec::with_capacity(8);
                for (k, wk) in self.weights(d, (slice.sun_zenith_deg, slice.sun_azimuth_deg)) {
                    let Some(at) = at[k].filter(|_| wk > 0.0) else { continue };
                    match by_pixel.iter_mut().find(|(j, _)| *j == at) {
                        Some((_, w)) => *w += wk,
                        None => by_pixel.push((at, wk)),
                    }
                }
                let (mut xyz, mut var, mut samples) = (texel_single[i], [0.0; 3], 0.0);
                for (k, wk) in by_pixel {
                    let p = &nodes.pixels[k];
                    for c in 0..3 {
                        xyz[c] += wk * multiple[k][c];
                        var[c] += wk * wk * p.xyz_stderr[c] * p.xyz_stderr[c];
                    }
                    samples += wk * p.samples as f64;
                }
                PixelResult {
                    xyz_stderr: var.map(f64::sqrt),
                    samples: samples.round() as u32,
                    ..PixelResult::from_xyz(xyz)
                }
            })
            .collect();
        Image { width: w, height: h, pixels }
    }
}

/// Core-seconds of single scattering by quadrature at every pixel of
/// `view`, on this process's threads.
pub fn time_single(scene: &Scene, view: &View) -> f64 {
    let start = std::time::Instant::now();
    std::hint::black_box(crate::render::single_per_pixel(scene, view));
    start.elapsed().as_secs_f64() * rayon::current_num_threads() as f64
}

/// The nodes of a grid that a slice's texels take, each direction once:
/// a slice renders no others. At a low sun the patch's cells that reach
/// below the horizon are not taken (none with the sun 6° below it), and
/// the zenith's, the nadir's and the sun's rows are one direction each.
/// Of a 16 x 13 grid's 316 nodes, a slice of 32 x 128 texels renders 238 at
/// a sun zenith of 58.6°, 207 at 91.1° and 194 at 96.4° (tested).
#[derive(Debug, Clone, PartialEq)]
pub struct RenderedNodes {
    /// The nodes rendered, ascending: pixel i of [`MsGrid::view`] is node
    /// `nodes[i]`.
    pub nodes: Vec<usize>,
    /// For every node of the grid, the pixel whose render it takes, or
    /// None where no texel takes it.
    pub at: Vec<Option<usize>>,
}

/// The angle from the sun of the sun patch's row `j`, degrees.
fn patch_row_deg(j: usize) -> f64 {
    let t = j as f64 / (SUN_PATCH_ROWS - 1) as f64;
    SUN_PATCH_DEG * t * t
}

/// The angle around the sun of the sun patch's column `i`, degrees.
fn patch_col_deg(i: usize) -> f64 {
    180.0 * i as f64 / (SUN_PATCH_COLS - 1) as f64
}

/// Directions by their angle from the sun, γ, and around it, ψ, from the
/// side toward the zenith (0°) to the side away from it (180°), folded by
/// the mirror symmetry about the sun's vertical.
struct SunFrame {
    sun: DVec3,
    /// Perpendicular to the sun, toward the zenith (in the sun's vertical).
    up: DVec3,
    /// Perpendicular to the sun's vertical.
    side: DVec3,
}

impl SunFrame {
    fn new((zenith_deg, azimuth_deg): (f64, f64)) -> SunFrame {
        let sun = crate::directions::camera::direction_deg(zenith_deg, azimuth_deg);
        let up = DVec3::Z - sun * sun.z;
        // A sun at the zenith or the nadir: every side is alike.
        let up = if up.length() > 1e-9 {
            up.normalize()
        } else {
            -crate::directions::camera::direction_deg(90.0, azimuth_deg)
        };
        SunFrame { sun, up, side: sun.cross(up) }
    }

    /// (γ, ψ) of `d`, degrees.
    fn coordinates_deg(&self, d: DVec3) -> (f64, f64) {
        let gamma = libm::acos(d.dot(self.sun).clamp(-1.0, 1.0)).to_degrees();
        let psi = libm::atan2(d.dot(self.side), d.dot(self.up)).to_degrees().abs();
        (gamma, psi)
    }

    /// The direction at (γ, ψ), degrees.
    fn direction(&self, gamma_deg: f64, psi_deg: f64) -> DVec3 {
        let (g, p) = (gamma_deg.to_radians(), psi_deg.to_radians());
        self.sun * g.cos() + (self.up * p.cos() + self.side * p.sin()) * g.sin()
    }
}

#[cfg(test)]
mod tests;
