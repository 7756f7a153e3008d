//! The atmosphere as the path tracer sees it: every component's density
//! rasterised on a 10 m altitude grid (linear between nodes), piecewise-
//! constant majorants on altitude shells (250 m up to 20 km, 1 km to 40 km,
//! 5 km above, where there is next to nothing) for delta and ratio
//! tracking (Novák et al. 2014; Novák et al. 2018, §5), and per wavelength
//! the cross-section, albedo and phase function of each component.

use crate::atmosphere::optics::{self, rayleigh_cross_section_cm2, rayleigh_depolarization};
use crate::atmosphere::{AerosolOptics, AnalyticPhase, Atmosphere, Geometry};
use crate::mie::{phase, MieCache, PhaseTable};
use std::sync::Arc;

/// Altitude step of the density rasters, km.
pub const GRID_STEP_KM: f64 = 0.01;
/// The majorant shells' boundaries, km, up to `top_km`: every 250 m up to
/// 20 km, every km to 40 km, every 5 km above, plus `kinks_km` (the
/// raster's sharp bends: a cloud layer's base and top). A shell's majorant
/// is its densest point, so a shell that held both clear air and the
/// first metres of a cloud would carry the cloud's extinction over all of
/// its 250 m: delta tracking would take hundreds of null collisions there,
/// and the forced first collision, drawn from the majorant's free path,
/// would land in the clear air almost always and carry weights of
/// e^(τ_majorant − τ) ~ 10³ on the rare draws that reach the cloud (the
/// fireflies under an overcast sky).
fn shell_edges(top_km: f64, kinks_km: &[f64]) -> Vec<f64> {
    let mut e = vec![0.0];
    let mut z = 0.0f64;
    while z < top_km - 1e-9 {
        let step = if z < 20.0 - 1e-9 {
            0.25
        } else if z < 40.0 - 1e-9 {
            1.0
        } else {
            5.0
        };
        z = (z + step).min(top_km);
        e.push(z);
    }
    e.extend(kinks_km.iter().filter(|&&k| k > 0.0 && k < top_km));
    e.sort_by(f64::total_cmp);
    e.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    e
}

/// What scatters or absorbs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum ComponentKind {
    Rayleigh,
    Absorber,
    Aerosol,
}

/// The wavelength-independent part: geometry and density rasters.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Medium {
    pub geometry: Geometry,
    pub radius_km: f64,
    pub top_km: f64,
    pub names: Vec<String>,
    pub kinds: Vec<ComponentKind>,
    /// `density[i][k]`: density of component i (its profile's units) at k·GRID_STEP_KM.
    density: Vec<Vec<f64>>,
    /// `shell_max[i][s]`: the maximum of `density[i]` over shell s.
    shell_max: Vec<Vec<f64>>,
    /// Shell boundaries, km (shells + 1 of them).
    pub shell_edges_km: Vec<f64>,
    /// Raster altitudes where some density bends sharply (second
    /// difference above 0.1 % of its largest value), km, ascending.
    #[serde(default)]
    pub kinks_km: Vec<f64>,
}

/// A phase function at one wavelength.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub enum Phase {
    /// No scattering (a pure absorber).
    None,
    Rayleigh {
        depolarization: f64,
    },
    HenyeyGreenstein {
        g: f64,
    },
    CornetteShanks {
        g: f64,
    },
    Table(Arc<PhaseTable>),
}

impl Phase {
    /// p(μ), sr⁻¹.
    pub fn eval(&self, mu: f64) -> f64 {
        match self {
            Phase::None => 0.0,
            Phase::Rayleigh { depolarization } => crate::atmosphere::rayleigh::phase_sr_inv(mu, *depolarization),
            Phase::HenyeyGreenstein { g } => phase::henyey_greenstein(mu, *g),
            Phase::CornetteShanks { g } => phase::cornette_shanks(mu, *g),
            Phase::Table(t) => t.eval_mu(mu),
        }
    }
}

/// The optics of every component at one wavelength.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Spectral {
    pub wavelength_nm: f64,
    /// Extinction coefficient per unit of the component's profile, km⁻¹.
    pub extinction: Vec<f64>,
    pub albedo: Vec<f64>,
    pub phase: Vec<Phase>,
    /// Majorant extinction of each shell, km⁻¹.
    pub majorant: Vec<f64>,
    /// Solar irradiance normal to the beam, W m⁻² nm⁻¹.
    pub sun_irradiance: f64,
    pub ground_albedo: f64,
}

impl Medium {
    /// Rasterises the atmosphere's profiles.
    pub fn new(atm: &Atmosphere) -> Medium {
        let top = atm.planet.top_km;
        let n = (top / GRID_STEP_KM).ceil() as usize + 1;
        let zs: Vec<f64> = (0..n).map(|k| (k as f64 * GRID_STEP_KM).min(top)).collect();
        let mut names = Vec::new();
        let mut kinds = Vec::new();
        let mut density = Vec::new();
        let raster = |scale: f64, profile: usize| -> Vec<f64> { zs.iter().map(|&z| scale * atm.profiles[profile].density(z)).collect() };
        if let Some(air) = &atm.air {
            names.push("air".to_string());
            kinds.push(ComponentKind::Rayleigh);
            density.push(raster(air.scale, air.profile));
        }
        for a in &atm.absorbers {
            names.push(a.name.clone());
            kinds.push(ComponentKind::Absorber);
            density.push(raster(a.scale, a.profile));
        }
        for a in &atm.aerosols {
            names.push(a.name.clone());
            kinds.push(ComponentKind::Aerosol);
            // Aerosol extinction is carried per unit of the (possibly relative) profile.
            density.push(raster(1.0, a.profile));
        }
        let peaks: Vec<f64> = density.iter().map(|d| d.iter().cloned().fold(0.0, f64::max)).collect();
        let mut kinks_km = Vec::new();
        for k in 1..n.saturating_sub(1) {
            let bends = density.iter().zip(&peaks).any(|(d, &peak)| peak > 0.0 && (d[k - 1] - 2.0 * d[k] + d[k + 1]).abs() > 1e-3 * peak);
            if bends {
                kinks_km.push(zs[k]);
            }
        }
        let edges = shell_edges(top, &kinks_km);
        let shell_max = density
            .iter()
            .map(|d| {
                edges
                    .windows(2)
                    .map(|w| {
                        // The raster nodes spanning the shell; an edge on a
                        // node (up to rounding) takes only that node.
                        let lo = ((w[0] / GRID_STEP_KM + 1e-6).floor() as usize).min(d.len() - 1);
                        let hi = ((w[1] / GRID_STEP_KM - 1e-6).ceil() as usize).min(d.len() - 1);
                        d[lo..=hi].iter().cloned().fold(0.0, f64::max)
                    })
                    .collect()
            })
            .collect();
        Medium { geometry: atm.planet.geometry, radius_km: atm.planet.radius_km, top_km: top, names, kinds, density, shell_max, shell_edges_km: edges, kinks_km }
    }

    pub fn components(&self) -> usize {
        self.density.len()
    }

    pub fn shells(&self) -> usize {
        self.shell_edges_km.len() - 1
    }

    /// The shell holding altitude `z_km` (clamped to the atmosphere).
    #[inline]
    pub fn shell_of(&self, z_km: f64) -> usize {
        let e = &self.shell_edges_km;
        (e.partition_point(|&x| x <= z_km).max(1) - 1).min(e.len() - 2)
    }

    /// Density of component `i` at altitude `z_km` (linear on the raster, 0 outside).
    #[inline]
    pub fn density(&self, i: usize, z_km: f64) -> f64 {
        if !(0.0..=self.top_km).contains(&z_km) {
            return 0.0;
        }
        let d = &self.density[i];
        let u = z_km / GRID_STEP_KM;
        let k = (u as usize).min(d.len() - 2);
        let t = u - k as f64;
        d[k] + t * (d[k + 1] - d[k])
    }

    /// The optics of every component at one wavelength. `sun_irradiance`
    /// and `ground_albedo` are passed in so a caller can use band averages.
    pub fn spectral(&self, atm: &Atmosphere, wavelength_nm: f64, sun_irradiance: f64, ground_albedo: f64, cache: &MieCache) -> Spectral {
        let mut extinction = Vec::new();
        let mut albedo = Vec::new();
        let mut phase_fns = Vec::new();
        if let Some(air) = &atm.air {
            // σ [cm²] · n [m⁻³] → km⁻¹: 1e-4 m²/cm² · 1e3 m/km.
            extinction.push(rayleigh_cross_section_cm2(air, wavelength_nm) * 0.1);
            albedo.push(1.0);
            phase_fns.push(Phase::Rayleigh { depolarization: rayleigh_depolarization(air, wavelength_nm) });
        }
        for a in &atm.absorbers {
            extinction.push(a.cross_section_cm2.eval(wavelength_nm) * 0.1);
            albedo.push(0.0);
            phase_fns.push(Phase::None);
        }
        let grid = phase::phase_grid_deg();
        for a in &atm.aerosols {
            let s = optics::aerosol_scale(atm, a, wavelength_nm, cache);
            extinction.push(s.extinction_per_density_m * 1000.0);
            albedo.push(s.single_scattering_albedo);
            phase_fns.push(match &a.optics {
                AerosolOptics::Analytic { phase: AnalyticPhase::HenyeyGreenstein, g, .. } => Phase::HenyeyGreenstein { g: *g },
                AerosolOptics::Analytic { phase: AnalyticPhase::CornetteShanks, g, .. } => Phase::CornetteShanks { g: *g },
                AerosolOptics::Mie { .. } => {
                    let b = optics::mie_particle_optics(a, wavelength_nm, &grid, cache).expect("Mie aerosol");
                    Phase::Table(Arc::new(PhaseTable::new(&grid, &b.phase_sr_inv)))
                }
            });
        }
        let majorant = (0..self.shells())
            .map(|s| {
                let m: f64 = (0..self.components()).map(|i| extinction[i] * self.shell_max[i][s]).sum();
                // A hair above the raster's maximum, so rounding never makes σ_t exceed it.
                m * (1.0 + 1e-9)
            })
            .collect();
        Spectral { wavelength_nm, extinction, albedo, phase: phase_fns, majorant, sun_irradiance, ground_albedo }
    }
}

impl Spectral {
    /// Extinction coefficient (km⁻¹) at an altitude.
    #[inline]
    pub fn sigma_t(&self, medium: &Medium, z_km: f64) -> f64 {
        (0..self.extinction.len()).map(|i| self.extinction[i] * medium.density(i, z_km)).sum()
    }
}

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
        let wt = [0.5 * (-t3 + 2.0 * t2 - ft), 0.5 * (3.0 * t3 - 5.0 * t2 + 2.0), 0.5 * (-3.0 * t3 + 4.0 * t2 + ft), 0.5 * (t3 - t2)];
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
        let atm = crate::atmosphere::Atmosphere::load(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/atmospheres/disort_rayleigh.toml")).unwrap();
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

    /// A ray from a point just above the top of a spherical atmosphere (a
    /// path's vertex can end up there by rounding) never re-enters it: its
    /// walk has no segment, where it had one of infinite length, along
    /// which delta and ratio tracking drew null collisions forever (a
    /// `sky lut verify` of the hazed sky with the sun on the horizon hung).
    #[test]
    fn a_ray_from_above_the_top_has_no_endless_segment() {
        use glam::DVec3;
        let atm = crate::atmosphere::Atmosphere::load(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("atmospheres/analytic-hg.toml")).unwrap();
        let m = Medium::new(&atm);
        for (above_km, d) in [(1e-9, DVec3::X), (1e-7, DVec3::new(0.3, 0.0, 1.0).normalize()), (0.0, DVec3::Y), (-1e-9, DVec3::X)] {
            let p = DVec3::new(0.0, 0.0, m.radius_km + m.top_km + above_km);
            let segs: Vec<_> = m.walk(p, d).collect();
            assert!(segs.iter().all(|s| s.end_km.is_finite()), "{above_km} km above the top along {d}: {segs:?}");
        }
    }

    /// A cloud layer with sharp edges (the shipped cloudy skies' tables:
    /// density 1 from 3 to 5 km, which the raster ramps to 0 over the 10 m
    /// outside each edge) gets shell edges at its base and top, so no shell
    /// holds both clear air and cloud: every shell's majorant exceeds the
    /// extinction by at most 0.2 of vertical optical depth (the 10 m ramps,
    /// 0.15 each at 30 km⁻¹). With 250 m shells alone the shells below the
    /// base and above the top exceeded it by 7.4: the forced first
    /// collision of a ray toward the cloud carried weights of e^7.4 when it
    /// reached the cloud (fireflies under cloudy5; per-sample relative
    /// variance 41 000 at the zenith, 5 600 with the edges).
    #[test]
    fn a_cloud_layer_has_shells_of_its_own() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let path = root.join("tests/atmospheres/disort_cloud_tau60.toml");
        let text =
            std::fs::read_to_string(&path).unwrap().replace("altitude_km = [3.0, 3.01, 4.99, 5.0]", "altitude_km = [3.0, 5.0]").replace("density = [0.0, 1.0, 1.0, 0.0]", "density = [1.0, 1.0]");
        let atm = crate::atmosphere::Atmosphere::from_str(&path, &text).unwrap();
        let m = Medium::new(&atm);
        for edge in [2.99, 3.0, 5.0, 5.01] {
            assert!(m.shell_edges_km.iter().any(|e| (e - edge).abs() < 1e-9), "no shell edge at {edge} km: {:?}", m.shell_edges_km);
        }
        let sp = m.spectral(&atm, 550.0, 1.0, 0.1, &MieCache::new(None));
        let mut worst = (0.0f64, 0);
        for s in 0..m.shells() {
            let (a, b) = (m.shell_edges_km[s], m.shell_edges_km[s + 1]);
            let steps = 1000;
            let dz = (b - a) / steps as f64;
            let excess: f64 = (0..steps).map(|k| (sp.majorant[s] - sp.sigma_t(&m, a + (k as f64 + 0.5) * dz)) * dz).sum();
            assert!(sp.majorant[s] >= sp.sigma_t(&m, a) && sp.majorant[s] >= sp.sigma_t(&m, b), "shell {s} ({a}-{b} km): majorant below the extinction");
            if excess > worst.0 {
                worst = (excess, s);
            }
        }
        let s = worst.1;
        assert!(worst.0 < 0.2, "shell {s} ({}-{} km): majorant exceeds the extinction by {:.2} of optical depth", m.shell_edges_km[s], m.shell_edges_km[s + 1], worst.0);
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
        let atm = crate::atmosphere::Atmosphere::load(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("atmospheres/hazed.toml")).unwrap();
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
