//! The spherical iteration's tables: the multiply scattered light's
//! sources (`spherical`), their values along one node ray, and the layers'
//! phase functions.
//!
//! A pass integrates the sources along every node ray in every column and
//! at every azimuth: about 10⁹ look-ups, each of two neighbouring columns
//! at one view cosine. The table of a twilight solution is larger than the
//! processor's caches (`clear.toml`: 55 columns, 114 interfaces, 129
//! cosines, 9 modes: 58 MB of f32), so a look-up that goes to the table
//! waits for memory. A ray's stops have the same view cosine in every
//! column and at every azimuth; only the column read changes. So each ray
//! first interpolates the table to its stops' cosines for every column
//! (`AlongRay`, under a megabyte), and every column then reads that.

use super::adding::through_layer_weights;
use super::adding::Scaled;
use super::columns::Solution;
use super::legendre::{legendre_all, normalised_associated};
use super::shell_rays::{At, Ray};
use rayon::prelude::*;

/// The multiply scattered light's sources of every column, per interface,
/// side, view cosine on a uniform grid from −1 to 1, column and Fourier
/// mode m ≤ M: the columns and modes of one cosine side by side, so that
/// an `AlongRay` reads runs of them.
pub(super) struct Table {
    columns: usize,
    modes: usize,
    cosines: usize,
    values: Vec<f32>,
}

impl Table {
    /// The run of every column's modes at interface i, side `side` (0:
    /// the layer above, 1: below), cosine k.
    fn row(&self, i: usize, side: usize, k: usize) -> &[f32] {
        let len = self.columns * self.modes;
        let at = ((i * 2 + side) * self.cosines + k) * len;
        &self.values[at..at + len]
    }

    /// The table of the current coefficients of `solution`: modes below
    /// `modes`, `cosines` view cosines. A side with no layer (above the
    /// top, below the ground) is zero.
    pub(super) fn new(solution: &Solution, modes: usize, cosines: usize) -> Table {
        let (scaled, lmax) = (&solution.scaled, solution.s.lmax);
        let nl = scaled.len();
        let columns = solution.a.len();
        let grid_u: Vec<f64> = (0..cosines).map(|k| -1.0 + 2.0 * k as f64 / (cosines - 1) as f64).collect();
        let lam_grid: Vec<Vec<Vec<f64>>> =
            (0..modes).map(|m| grid_u.iter().map(|&u| normalised_associated(lmax, m, u)).collect()).collect();
        let mut table = Table { columns, modes, cosines, values: vec![0.0; (nl + 1) * 2 * cosines * columns * modes] };
        let block = 2 * cosines * columns * modes;
        table.values.par_chunks_mut(block).enumerate().for_each(|(i, out)| {
            for side in 0..2 {
                let k = if side == 0 { i.checked_sub(1) } else { (i < nl).then_some(i) };
                let Some(k) = k else { continue };
                let l = &scaled[k];
                for (c, a) in solution.a.iter().enumerate() {
                    for m in 0..modes {
                        let w = super::columns::weigh(l, lmax, m, &a[m][i]);
                        let at = side * cosines * columns * modes + c * modes + m;
                        for (q, lam) in lam_grid[m].iter().enumerate() {
                            out[at + q * columns * modes] = (m..=lmax).map(|j| w[j] * lam[j]).sum::<f64>() as f32;
                        }
                    }
                }
            }
        });
        table
    }
}

/// The table at the stops of one node ray, at each stop's view cosine
/// (linear between the table's cosines): per stop two slots (at an
/// interface i: the sides of the layer above and below; inside layer k:
/// interface k's side below and interface k + 1's side above), then every
/// column's modes. With the weights of each segment's source at its ends
/// and the attenuation before it (the same in every column).
pub(super) struct AlongRay {
    columns: usize,
    modes: usize,
    values: Vec<f32>,
    segments: Vec<(f64, f64, f64)>,
}

impl AlongRay {
    pub(super) fn new(table: &Table, ray: &Ray) -> AlongRay {
        let len = table.columns * table.modes;
        let mut values = Vec::with_capacity(ray.stops.len() * 2 * len);
        for &pi in &ray.stops {
            let point = &ray.points[pi];
            let x = (point.u + 1.0) * 0.5 * (table.cosines - 1) as f64;
            let k = (x.floor() as usize).min(table.cosines - 2);
            let w = (x - k as f64) as f32;
            let slots = match point.at {
                At::Interface(i) => [(i, 0), (i, 1)],
                At::Inside(k, _) => [(k, 1), (k + 1, 0)],
            };
            for (i, side) in slots {
                let (below, above) = (table.row(i, side, k), table.row(i, side, k + 1));
                values.extend(below.iter().zip(above).map(|(&lo, &hi)| lo * (1.0 - w) + hi * w));
            }
        }
        let mut before = 0.0f64;
        let segments = ray
            .segments
            .iter()
            .map(|&(_, _, tau)| {
                let (base, top) = through_layer_weights(tau);
                let weights = (base, top, (-before).exp());
                before += tau;
                weights
            })
            .collect();
        AlongRay { columns: table.columns, modes: table.modes, values, segments }
    }

    /// Per segment of the ray: the weights of its source at the near and
    /// the far stop (`adding::through_layer`) and the transmittance from
    /// the ray's start to the segment.
    pub(super) fn segments(&self) -> &[(f64, f64, f64)] {
        &self.segments
    }

    /// Σ_m J^m cos(m φ) of column c at stop q's `slot`, and with `next` of
    /// column c + 1 too (else 0): a point reads two neighbouring columns
    /// at one azimuth.
    pub(super) fn values(&self, q: usize, slot: usize, c: usize, cos_phi: f64, next: bool) -> (f64, f64) {
        let at = ((q * 2 + slot) * self.columns + c) * self.modes;
        let this = &self.values[at..at + self.modes];
        let other = if next { &self.values[at + self.modes..at + 2 * self.modes] } else { this };
        let (mut prev, mut cos_m) = (cos_phi, 1.0);
        let (mut sum, mut sum_next) = (0.0, 0.0);
        for (&a, &b) in this.iter().zip(other) {
            sum += a as f64 * cos_m;
            sum_next += b as f64 * cos_m;
            (prev, cos_m) = (cos_m, 2.0 * cos_phi * cos_m - prev);
        }
        (sum, if next { sum_next } else { 0.0 })
    }
}

/// Each layer's scaled phase function on a grid of cos Θ, −1 to 1.
pub(super) struct Phases {
    nodes: Vec<Vec<f64>>,
}

impl Phases {
    const NODES: usize = 4001;

    pub(super) fn new(scaled: &[Scaled], lmax: usize) -> Phases {
        let nodes = scaled
            .iter()
            .map(|l| {
                (0..Self::NODES)
                    .map(|k| {
                        let p = legendre_all(lmax, -1.0 + 2.0 * k as f64 / (Self::NODES - 1) as f64);
                        (0..l.chi.len()).map(|j| (2 * j + 1) as f64 * l.chi[j] * p[j]).sum()
                    })
                    .collect()
            })
            .collect();
        Phases { nodes }
    }

    /// Layer k's phase function at cos Θ.
    pub(super) fn at(&self, k: usize, cos_scattering: f64) -> f64 {
        let x = (cos_scattering + 1.0) * 0.5 * (Self::NODES - 1) as f64;
        let j = (x.floor() as usize).min(Self::NODES - 2);
        let w = x - j as f64;
        self.nodes[k][j] * (1.0 - w) + self.nodes[k][j + 1] * w
    }
}
