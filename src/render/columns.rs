//! The column table: every component's column to the top of the
//! atmosphere against altitude and direction cosine, so that the optical
//! depth toward the sun (and along a straight segment, as columns added and
//! subtracted) comes without tracking noise (see [`ColumnTable`]).

use super::medium::{Medium, GRID_STEP_KM};
use crate::atmosphere::Geometry;

/// Columns of every component along rays to the top of the atmosphere,
/// tabulated against altitude and the cosine of the ray's zenith angle: the
/// medium is spherically (or horizontally) symmetric, so the optical depth
/// toward the sun from any point depends on those two numbers only, and the
/// sun's transmittance is exp(−Σ_i e_i(λ) C_i(z, μ)) without tracking noise
/// ("exact optical depth where the medium allows"). The columns are
/// integrated by the trapezoid rule on steps of 0.2 % of the altitude plus
/// 10 m, and interpolated bilinearly; rays that meet the ground are marked
/// by an infinite column.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct ColumnTable {
    z_km: Vec<f64>,
    theta_steps: usize,
    /// `columns[i][iz * (theta_steps + 1) + it]`, density units × km.
    columns: Vec<Vec<f64>>,
}

const COLUMN_Z_NODES: usize = 128;
const COLUMN_THETA_STEPS: usize = 1024;
/// The largest error of a component's vertical column, interpolated
/// linearly between the table's altitude nodes, as a fraction of its whole
/// column (see [`column_altitudes`]).
const COLUMN_REL_ERROR: f64 = 1e-3;

/// The table's altitude nodes: a base grid quadratic in altitude (dense
/// near the ground), plus the raster nodes that a greedy pass over the
/// 10 m raster needs so that linear interpolation of every component's
/// vertical column misses by at most [`COLUMN_REL_ERROR`] of that
/// component's whole column. The base grid alone put 300 m between nodes
/// at 5 km, so the optical depth toward the sun just under the top of a
/// cloud of optical depth 60 was interpolated across the cloud's edge and
/// came out up to 1.6 too large: sunlight under-counted by e^-3 where a
/// thick cloud takes it in, and overcast skies an order of magnitude too
/// dark. With the refinement the columns' kinks (profile edges, cloud
/// tops) are nodes.
fn column_altitudes(m: &Medium) -> Vec<f64> {
    let top = m.top_km;
    let n = m.density.first().map_or(0, |d| d.len());
    let mut z: Vec<f64> = (0..COLUMN_Z_NODES).map(|i| top * (i as f64 / (COLUMN_Z_NODES - 1) as f64).powi(2)).collect();
    if n >= 2 {
        // Vertical columns to the top at each raster node (exact: the
        // density is linear between nodes).
        let columns: Vec<Vec<f64>> = m
            .density
            .iter()
            .map(|d| {
                let mut c = vec![0.0; n];
                for k in (0..n - 1).rev() {
                    let z0 = k as f64 * GRID_STEP_KM;
                    let z1 = ((k + 1) as f64 * GRID_STEP_KM).min(top);
                    c[k] = c[k + 1] + 0.5 * (d[k] + d[k + 1]) * (z1 - z0).max(0.0);
                }
                c
            })
            .collect();
        let tolerance: Vec<f64> = columns.iter().map(|c| COLUMN_REL_ERROR * c[0]).collect();
        let fits = |a: usize, b: usize| -> bool {
            columns.iter().zip(&tolerance).all(|(c, &tol)| {
                (a + 1..b).all(|k| {
                    let f = (k - a) as f64 / (b - a) as f64;
                    (c[k] - (c[a] + f * (c[b] - c[a]))).abs() <= tol
                })
            })
        };
        let mut a = 0;
        while a < n - 1 {
            // Exponential then binary search for the farthest node that fits.
            let mut step = 1;
            while a + 2 * step < n && fits(a, a + 2 * step) {
                step *= 2;
            }
            let (mut lo, mut hi) = (a + step, (a + 2 * step).min(n - 1));
            if !fits(a, lo) {
                hi = lo;
                lo = a + 1;
            }
            while hi > lo + 1 {
                let mid = (lo + hi) / 2;
                if fits(a, mid) {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            let b = if hi > lo && fits(a, hi) { hi } else { lo };
            z.push((b as f64 * GRID_STEP_KM).min(top));
            a = b;
        }
    }
    // Within the raster step on each side of a kink the columns are
    // quadratic with a large curvature (a cloud's 10 m edge): quarter steps.
    for &zk in &m.kinks_km {
        for j in [-3.0, -2.0, -1.0, 1.0, 2.0, 3.0] {
            let zq = zk + j * 0.25 * GRID_STEP_KM;
            if zq > 0.0 && zq < top {
                z.push(zq);
            }
        }
    }
    z.sort_by(f64::total_cmp);
    z.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    z
}

/// Bumped whenever [`ColumnTable::new`] computes differently, so that no
/// cached table of an older build is read.
const COLUMN_ALGORITHM: &str = "sky-columns-1";

impl ColumnTable {
    /// [`ColumnTable::new`], kept in `dir` (the Mie cache's folder) by a
    /// hash of the medium: the table depends only on the geometry and the
    /// density rasters, and computing it is most of what preparing an
    /// atmosphere's optics costs. A file that does not decode is computed
    /// again; a cache that cannot be written is not an error.
    pub fn cached(m: &Medium, dir: Option<&std::path::Path>) -> ColumnTable {
        let Some(dir) = dir else { return ColumnTable::new(m) };
        let mut h = blake3::Hasher::new();
        h.update(COLUMN_ALGORITHM.as_bytes());
        h.update(&postcard::to_allocvec(m).expect("a medium always encodes"));
        let path = dir.join("columns").join(format!("{}.postcard", h.finalize().to_hex()));
        if let Some(t) = std::fs::read(&path).ok().and_then(|b| postcard::from_bytes::<ColumnTable>(&b).ok()) {
            return t;
        }
        let t = ColumnTable::new(m);
        let _ = crate::mie::cache::write_atomic(&path, &postcard::to_allocvec(&t).expect("a table always encodes"));
        t
    }

    pub fn new(m: &Medium) -> ColumnTable {
        use rayon::prelude::*;
        let top = m.top_km;
        let z_km = column_altitudes(m);
        let nt = COLUMN_THETA_STEPS + 1;
        let k = m.components();
        // One row of all components for each (altitude, angle) node.
        // Plane-parallel columns are the vertical one over μ: one per altitude.
        let vertical: Vec<Vec<f64>> = match m.geometry {
            Geometry::PlaneParallel => z_km.par_iter().map(|&z| column_along(m, z.min(top - 1e-9), 1.0, k)).collect(),
            Geometry::Spherical => Vec::new(),
        };
        let cells: Vec<Vec<f64>> = (0..z_km.len() * nt)
            .into_par_iter()
            .map(|cell| {
                let (iz, it) = (cell / nt, cell % nt);
                let theta = std::f64::consts::PI * it as f64 / COLUMN_THETA_STEPS as f64;
                let mu = libm::cos(theta);
                match m.geometry {
                    Geometry::PlaneParallel if mu > 0.0 => vertical[iz].iter().map(|c| c / mu).collect(),
                    _ => column_along(m, z_km[iz].min(top - 1e-9), mu, k),
                }
            })
            .collect();
        let columns = (0..k).map(|i| cells.iter().map(|c| c[i]).collect()).collect();
        ColumnTable { z_km, theta_steps: COLUMN_THETA_STEPS, columns }
    }

    /// The altitude nodes of the table.
    pub fn altitudes_km(&self) -> &[f64] {
        &self.z_km
    }

    /// Where (altitude, direction cosine) falls in the table.
    pub fn node(&self, z_km: f64, mu: f64) -> ColumnNode {
        let z = z_km.clamp(0.0, *self.z_km.last().unwrap());
        let iz = (self.z_km.partition_point(|&v| v <= z).max(1) - 1).min(self.z_km.len() - 2);
        let fz = (z - self.z_km[iz]) / (self.z_km[iz + 1] - self.z_km[iz]);
        let t = libm::acos(mu.clamp(-1.0, 1.0)) / std::f64::consts::PI * self.theta_steps as f64;
        let it = (t as usize).min(self.theta_steps - 1);
        let ft = t - it as f64;
        // Catmull–Rom weights of the nodes it − 1 … it + 2 (the table is
        // even in θ at both poles: node −1 is node 1, node n + 1 is n − 1).
        let (t2, t3) = (ft * ft, ft * ft * ft);
        let wt = [
            0.5 * (-t3 + 2.0 * t2 - ft),
            0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
            0.5 * (-3.0 * t3 + 4.0 * t2 + ft),
            0.5 * (t3 - t2),
        ];
        let n = self.theta_steps;
        let jt = [if it == 0 { 1 } else { it - 1 }, it, it + 1, if it + 2 > n { n - 1 } else { it + 2 }];
        ColumnNode { iz, fz, it, ft, jt, wt }
    }

    /// Optical depth to space from altitude `z_km` along a ray whose cosine
    /// to the local vertical is `mu`, for per-component extinctions `e`
    /// (km⁻¹ per density unit); infinite if the ray meets the ground.
    pub fn optical_depth(&self, z_km: f64, mu: f64, e: &[f64]) -> f64 {
        self.optical_depth_at(&self.node(z_km, mu), e)
    }

    /// [`optical_depth`](Self::optical_depth) at a precomputed node.
    pub fn optical_depth_at(&self, n: &ColumnNode, e: &[f64]) -> f64 {
        let mut tau = 0.0;
        for i in 0..self.columns.len() {
            if e[i] == 0.0 {
                continue;
            }
            let c = self.column_at(n, i);
            if !c.is_finite() {
                return f64::INFINITY;
            }
            tau += e[i] * c;
        }
        tau
    }

    /// The column of component `i` at a node (density units × km);
    /// infinite in the shadow of the ground. [`optical_depth_at`](Self::optical_depth_at)
    /// is Σ_i e_i × this, so many wavelengths can share one interpolation
    /// per component.
    pub fn column_at(&self, n: &ColumnNode, i: usize) -> f64 {
        let ColumnNode { iz, fz, it, ft, .. } = *n;
        let nt = self.theta_steps + 1;
        let col = &self.columns[i];
        let c00 = col[iz * nt + it];
        let c01 = col[iz * nt + it + 1];
        let c10 = col[(iz + 1) * nt + it];
        let c11 = col[(iz + 1) * nt + it + 1];
        if !(c00.is_finite() && c01.is_finite() && c10.is_finite() && c11.is_finite()) {
            // Next to the shadow of the ground: the nearest node decides.
            return [[c00, c01], [c10, c11]][(fz > 0.5) as usize][(ft > 0.5) as usize];
        }
        // Cubic in θ where all four nodes of both rows are finite (the
        // slant columns' curvature near the horizon made linear
        // interpolation between 0.18° nodes 5e-4 too large there), kept
        // within the two bracketing nodes; linear otherwise.
        let row = |r: usize, lo: f64, hi: f64| -> f64 {
            let mut v = 0.0;
            for m in 0..4 {
                v += n.wt[m] * col[r * nt + n.jt[m]];
            }
            if v.is_finite() {
                v.clamp(lo.min(hi), lo.max(hi))
            } else {
                (1.0 - ft) * lo + ft * hi
            }
        };
        (1.0 - fz) * row(iz, c00, c01) + fz * row(iz + 1, c10, c11)
    }

    /// Optical depth of a path made of table columns, Σ added − Σ
    /// subtracted, never negative (see [`ColumnPath`]).
    pub fn path_optical_depth(&self, path: &ColumnPath, e: &[f64]) -> f64 {
        let (add, sub) = self.path_columns(path, e);
        depth_of_columns(add, sub)
    }

    /// The optical depths Σ added and Σ subtracted of a path: their sum
    /// bounds the interpolation error of the difference (see
    /// `Kernel::transmittance`).
    pub fn path_columns(&self, path: &ColumnPath, e: &[f64]) -> (f64, f64) {
        let add: f64 = path.add[..path.n_add].iter().map(|n| self.optical_depth_at(n, e)).sum();
        let sub: f64 = path.sub[..path.n_sub].iter().map(|n| self.optical_depth_at(n, e)).sum();
        (add, sub)
    }
}

/// The optical depth of columns Σ added and Σ subtracted (see
/// [`ColumnTable::path_columns`]): never negative, infinite if a column is.
pub fn depth_of_columns(add: f64, sub: f64) -> f64 {
    if add.is_infinite() {
        return f64::INFINITY;
    }
    (add - sub).max(0.0)
}

/// A position in the column table: altitude node and fraction, angle node
/// and fraction, and the four angle nodes and weights of the cubic.
#[derive(Debug, Clone, Copy, Default)]
pub struct ColumnNode {
    iz: usize,
    fz: f64,
    it: usize,
    ft: f64,
    jt: [usize; 4],
    wt: [f64; 4],
}

/// The optical depth of a straight segment (or ray to space) written as
/// columns to space added and subtracted: for a segment p→q that rises all
/// along, τ = C(p) − C(q); one that sinks all along is the reverse of a
/// rising one; one through its lowest point g is two rising halves from g,
/// τ = 2 C(g, horizontal) − C(p, reversed) − C(q) (and a ray to space drops
/// C(q)). Exact up to the table's interpolation, so transmittances along
/// camera rays and toward a sun below the horizon come without tracking
/// noise.
#[derive(Debug, Clone, Copy, Default)]
pub struct ColumnPath {
    pub add: [ColumnNode; 2],
    pub n_add: usize,
    pub sub: [ColumnNode; 2],
    pub n_sub: usize,
}

impl ColumnPath {
    pub fn push_add(&mut self, n: ColumnNode) {
        self.add[self.n_add] = n;
        self.n_add += 1;
    }
    pub fn push_sub(&mut self, n: ColumnNode) {
        self.sub[self.n_sub] = n;
        self.n_sub += 1;
    }
}

/// ∫ density ds from altitude `z0` along direction cosine `mu` to the top,
/// for every component; infinite if the ray meets the ground.
fn column_along(m: &Medium, z0: f64, mu: f64, k: usize) -> Vec<f64> {
    let mut out = vec![0.0; k];
    let (r0, top_r) = match m.geometry {
        Geometry::Spherical => (m.radius_km + z0, m.radius_km + m.top_km),
        Geometry::PlaneParallel => (0.0, 0.0),
    };
    let altitude_at = |s: f64| -> f64 {
        match m.geometry {
            Geometry::Spherical => (r0 * r0 + 2.0 * r0 * mu * s + s * s).sqrt() - m.radius_km,
            Geometry::PlaneParallel => z0 + mu * s,
        }
    };
    // Length of the ray inside the atmosphere, or None if it meets the ground.
    let length = match m.geometry {
        Geometry::Spherical => {
            let r_g = m.radius_km;
            let disc_g = r0 * r0 * (mu * mu - 1.0) + r_g * r_g;
            if mu < 0.0 && disc_g >= 0.0 && z0 > 0.0 {
                return vec![f64::INFINITY; k];
            }
            if mu < 0.0 && z0 <= 0.0 {
                return vec![f64::INFINITY; k];
            }
            -r0 * mu + (r0 * r0 * (mu * mu - 1.0) + top_r * top_r).sqrt()
        }
        Geometry::PlaneParallel => {
            if mu <= 0.0 {
                return vec![f64::INFINITY; k];
            }
            // Exactly the vertical column above z0 divided by μ: the
            // trapezoid rule on the raster's own nodes (the density is
            // linear between them).
            let mut z = z0;
            let mut prev: Vec<f64> = (0..k).map(|i| m.density(i, z)).collect();
            while z < m.top_km {
                let next = (((z / GRID_STEP_KM).floor() + 1.0) * GRID_STEP_KM).min(m.top_km);
                let dz = if next > z + 1e-12 { next - z } else { GRID_STEP_KM.min(m.top_km - z) };
                z += dz;
                for i in 0..k {
                    let d = m.density(i, z);
                    out[i] += 0.5 * (prev[i] + d) * dz;
                    prev[i] = d;
                }
            }
            return out.into_iter().map(|c| c / mu).collect();
        }
    };
    // Steps of 10 m plus 0.2 % of the altitude, cut short at the altitudes
    // where a density has a kink (a profile's edge, a cloud's base or top),
    // so the trapezoid rule never straddles one.
    let kinks = &m.kinks_km;
    let r2 = |z: f64| (m.radius_km + z) * (m.radius_km + z);
    let mut s = 0.0;
    let mut prev: Vec<f64> = (0..k).map(|i| m.density(i, z0)).collect();
    while s < length {
        let z = altitude_at(s);
        let mut ds = (0.01 + 0.002 * z.max(0.0)).min(length - s);
        let z_end = altitude_at(s + ds);
        let (lo, hi) = (z.min(z_end), z.max(z_end));
        let first = kinks.partition_point(|&x| x <= lo);
        if first < kinks.len() && kinks[first] < hi {
            // The nearest crossing of a kink ahead: a root of
            // s² + 2 r0 μ s + r0² − (R + z_k)² = 0 beyond s.
            let mut best = ds;
            for &zk in &kinks[first..kinks.partition_point(|&x| x < hi)] {
                let disc = r0 * r0 * mu * mu - r0 * r0 + r2(zk);
                if disc >= 0.0 {
                    let q = disc.sqrt();
                    for root in [-r0 * mu - q, -r0 * mu + q] {
                        let step = root - s;
                        if step > 1e-9 && step < best {
                            best = step;
                        }
                    }
                }
            }
            ds = best;
        }
        s += ds;
        let z1 = altitude_at(s);
        for i in 0..k {
            let d = m.density(i, z1);
            out[i] += 0.5 * (prev[i] + d) * ds;
            prev[i] = d;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cached_column_tables_are_the_computed_ones() {
        let atm = crate::atmosphere::Atmosphere::load(
            &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/atmospheres/disort_rayleigh.toml"),
        )
        .unwrap();
        let m = Medium::new(&atm);
        let dir = tempfile::tempdir().unwrap();
        let fresh = postcard::to_allocvec(&ColumnTable::new(&m)).unwrap();
        let first = postcard::to_allocvec(&ColumnTable::cached(&m, Some(dir.path()))).unwrap();
        assert_eq!(std::fs::read_dir(dir.path().join("columns")).unwrap().count(), 1);
        let second = postcard::to_allocvec(&ColumnTable::cached(&m, Some(dir.path()))).unwrap();
        assert!(fresh == first && first == second);
        // A damaged file is computed again, not trusted.
        let f = std::fs::read_dir(dir.path().join("columns")).unwrap().next().unwrap().unwrap().path();
        std::fs::write(&f, b"broken").unwrap();
        assert!(postcard::to_allocvec(&ColumnTable::cached(&m, Some(dir.path()))).unwrap() == fresh);
    }

    /// Slant columns from the table against direct integration along the
    /// ray (`column_along`, the trapezoid rule the table's nodes are built
    /// with), at altitude nodes (interpolation in altitude has its own
    /// budget, [`COLUMN_REL_ERROR`]) and between angle nodes up to half a
    /// degree above the horizon, as a fraction of the column from the
    /// ground in the same direction (what the error costs a view ray's
    /// transmittance): within 1e-4 (at worst 5.4e-5, the boundary layer half a degree above
    /// the horizon). Linear interpolation in θ missed by up
    /// to 2e-3 near the horizon (2 % of the boundary layer's column from
    /// 2 km).
    #[test]
    fn slant_columns_interpolate_in_angle_to_1e_4() {
        let atm = crate::atmosphere::Atmosphere::load(
            &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("atmospheres/hazed.toml"),
        )
        .unwrap();
        let m = Medium::new(&atm);
        let t = ColumnTable::new(&m);
        let mut worst: f64 = 0.0;
        for deg in [0.1, 30.0, 60.0, 75.0, 85.0, 88.0, 89.0, 89.5] {
            let mu = f64::cos(f64::to_radians(deg));
            let ground = column_along(&m, 0.0, mu, m.components());
            for z in [0.003, 0.05, 0.5, 2.0, 7.3] {
                let z = t.z_km[t.z_km.partition_point(|&n| n < z)];
                let exact = column_along(&m, z, mu, m.components());
                for i in 0..m.components() {
                    if !(ground[i] > 0.0) {
                        continue;
                    }
                    let e: Vec<f64> = (0..m.components()).map(|j| if j == i { 1.0 } else { 0.0 }).collect();
                    let rel = (t.optical_depth(z, mu, &e) - exact[i]) / ground[i];
                    worst = worst.max(rel.abs());
                    assert!(rel.abs() < 1e-4, "{} at {z} km, {deg} deg: {rel:e}", m.names[i]);
                }
            }
        }
        eprintln!("slant columns: worst relative error {worst:.1e}");
    }
}
