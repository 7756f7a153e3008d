//! What a final bake costs, measured rather than guessed (`sky bench bake`):
//! for each basis sky, a few slices (sun zenith 20, 60, 85, 88, 91, 93, 96
//! and 99° by default: twilight costs most and changes fastest) rendered through the sky's own LUT mapping on a regular subset
//! of its texels (every `stride`-th in both axes, so the subset spans the
//! whole slice), once at a fixed sample count per estimator and once as a
//! reference at many more samples.
//!
//! The noise of each estimator is measured against the reference, not taken
//! from its own standard error alone (heavy tails hide from the sample
//! variance, and adaptive stopping biases it): with e_i = (Y_i − R_i) / R_i
//! the relative error of texel i at n samples and s_i the reference's own
//! relative standard error,
//!
//!   v = n (mean e_i² − mean s_i²)
//!
//! is the per-sample relative variance of Y (the reference's noise taken
//! out). Its ratio κ to the estimator's own figure, n mean (σ_i / Y_i)², says
//! how honest the latter is; the cost model uses each texel's own variance
//! times κ. A texel needs n_i = κ v_i / 0.01² samples for a 1 % standard
//! error of Y, plus the adaptive pilot's 32 (and what the final quality
//! spends, its texels stopped at the cap, besides); at the measured time
//! per path plus a per-texel overhead (the first-
//! collision guide, single scattering by quadrature: measured by a one-
//! sample render), that is the slice's cost. A basis sky's 64 slices are
//! priced by interpolating the cost linearly in sun zenith between the
//! measured slices (constant beyond them), and scaled to the full slice
//! size.

use crate::atmosphere::Atmosphere;
use crate::bake::file::{BakeFile, BasisSky, FogSettings, Quality};
use crate::bake::run::spectral_settings;
use crate::directions::camera::Camera;
use crate::directions::mapping::{self, DirectionMapping};
use crate::mie::MieCache;
use crate::render::adaptive::{ADAPTIVE_MIN_SPP, ADAPTIVE_PILOT_SPP};
use crate::render::tracer::Estimator;
use crate::render::{self, Image, Scene, SingleScatter, View};
use std::sync::atomic::AtomicBool;
use std::time::Instant;

/// The relative standard error of Y a final bake asks of every texel.
pub const TARGET_REL_ERROR: f64 = 0.01;
/// The reference's seed (the measured renders use [`MEASURED_SEED`]).
const REFERENCE_SEED: u64 = 0x5ef_e7e4ce;
const MEASURED_SEED: u64 = 0xbe4c_4ba4e;

/// What to measure.
#[derive(Debug, Clone)]
pub struct BenchOptions {
    /// Basis skies by name (all of the bake's when empty).
    pub skies: Vec<String>,
    pub sun_zenith_deg: Vec<f64>,
    /// Every `stride[0]`-th texel along u (columns) and `stride[1]`-th
    /// along v (rows) of a slice.
    pub stride: [usize; 2],
    /// Samples per texel of the measured renders.
    pub spp: u32,
    /// Samples per texel of the reference.
    pub reference_spp: u32,
    pub methods: Vec<SingleScatter>,
    /// Threads of the renders (core-seconds are wall seconds times this).
    pub threads: usize,
    /// Measure the fog slices (the bake file's `[fog]`: their render is the
    /// Shadowed Fog, and the Fog's quadrature is priced per texel) instead
    /// of the sky's.
    pub fog: bool,
    /// Also measure multiple scattering interpolated from every
    /// `stride`-th texel (see [`super::bench_coarse`]; sky slices only).
    pub coarse_ms: bool,
    /// Also measure it interpolated from a grid of its own over the sky,
    /// rows × columns ([`super::bench_coarse::measure_latlong`]).
    pub coarse_ms_grid: Option<[usize; 2]>,
}

/// One estimator on one slice.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SliceCost {
    pub sky: String,
    pub sun_zenith_deg: f64,
    pub method: SingleScatter,
    /// Texels measured (those the reference lit), of the subset.
    pub texels: usize,
    pub spp: u32,
    pub core_seconds: f64,
    /// Per-sample relative variance of Y against the reference, and from
    /// the estimator's own standard errors.
    pub rel_var_vs_reference: f64,
    pub rel_var_own: f64,
    /// The reference's median relative standard error.
    pub reference_rel_stderr: f64,
    pub core_seconds_per_path: f64,
    pub overhead_core_seconds_per_texel: f64,
    /// Mean samples per texel for 1 %, and the full slice's cost at that.
    pub samples_to_target: f64,
    pub slice_core_seconds_to_target: f64,
    /// What the final quality spends on the slice, its texels stopped at
    /// the cap (short of 1 % where [`capped_fraction`](Self::capped_fraction) > 0).
    pub slice_core_seconds_capped: f64,
    /// Texels that would hit the sample cap.
    pub capped_fraction: f64,
    /// With `coarse_ms` or `coarse_ms_grid` (quadrature only): multiple
    /// scattering from coarser grids.
    pub coarse_ms: Vec<CoarseCost>,
}

/// Multiple scattering from a coarser grid, on one slice.
#[derive(Debug, Clone, serde::Serialize)]
pub struct CoarseCost {
    /// `lut UxV` (every U-th texel along u and V-th along v) or `own RxC`
    /// (a grid of its own, R rows and C columns over the sky, the same
    /// again for the ground assumed in the cost).
    pub grid: String,
    pub accuracy: super::bench_coarse::CoarseMs,
    /// The Monte Carlo's part of the full slice's: nodes over texels.
    pub sampled_fraction: f64,
    /// The full slice to 1 % and at the cap: the per-texel overhead (the
    /// quadrature's) at every texel, the sampling at the nodes only.
    pub slice_core_seconds_to_target: f64,
    pub slice_core_seconds_capped: f64,
}

/// A basis sky's projected final bake with multiple scattering from a
/// coarser grid (see [`CoarseCost`]).
#[derive(Debug, Clone, serde::Serialize)]
pub struct CoarseSkyCost {
    pub sky: String,
    pub grid: String,
    pub core_hours: f64,
    pub capped_core_hours: f64,
}

/// A basis sky's projected final bake for one estimator.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SkyCost {
    pub sky: String,
    pub method: SingleScatter,
    pub slices: usize,
    /// To 1 % in every texel.
    pub core_hours: f64,
    /// What the final quality spends, its texels stopped at the cap.
    pub capped_core_hours: f64,
}

#[derive(Debug, Clone, serde::Serialize)]
pub struct BenchReport {
    pub slices: Vec<SliceCost>,
    pub skies: Vec<SkyCost>,
    /// Per estimator: the projected final bake of the measured skies,
    /// core-hours, to 1 % and at the cap.
    pub total_core_hours: Vec<(SingleScatter, f64)>,
    pub total_capped_core_hours: Vec<(SingleScatter, f64)>,
    /// The quadrature's projections with multiple scattering from coarser
    /// grids, per sky and in total (sky "total").
    pub coarse_ms: Vec<CoarseSkyCost>,
}

/// What can stop the benchmark.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    #[error("no basis sky named {0:?} in the bake file")]
    NoSuchSky(String),
    #[error("{sky}: {error}")]
    Atmosphere { sky: String, error: crate::atmosphere::LoadError },
    #[error("{0}")]
    Threads(String),
    #[error("cancelled")]
    Cancelled,
}

/// The measured slice's view: the sky's LUT mapping at `sun_zenith_deg`,
/// every `stride`-th texel (at the subset's own texel centres); with `fog`,
/// the Fog LUT's directions at a `stride`-th of its size each way, the
/// fog slice's render (the Shadowed Fog: it has no single scattering of
/// sunlight, so `method` changes nothing there).
fn view(
    sky: &BasisSky,
    fog: Option<&FogSettings>,
    sun_zenith_deg: f64,
    stride: [usize; 2],
    spp: u32,
    seed: u64,
    method: SingleScatter,
) -> View {
    if let Some(f) = fog {
        let subset = FogSettings { width: (f.width / stride[0]).max(1), height: (f.height / stride[1]).max(1), ..*f };
        return View {
            seed,
            single_scatter: method,
            ..crate::bake::fog::fog_view_at(sky, &subset, spp, sun_zenith_deg, true)
        };
    }
    View {
        camera: Camera::Lut { mapping: DirectionMapping::new(sun_zenith_deg, sky.threshold_deg), sun_azimuth_deg: 0.0 },
        width: (sky.width / stride[0]).max(1),
        height: (sky.height / stride[1]).max(1),
        sun_zenith_deg,
        sun_azimuth_deg: 0.0,
        altitude_m: sky.altitude_m,
        spp,
        seed,
        estimator: Estimator::Full,
        sun_disk: false,
        max_rel_error: None,
        single_scatter: method,
        fog: None,
    }
}

/// Renders on the pool, returning the image and its core-seconds.
fn timed(
    pool: &rayon::ThreadPool,
    threads: usize,
    scene: &Scene,
    view: &View,
    cancel: &AtomicBool,
) -> Result<(Image, f64), BenchError> {
    let start = Instant::now();
    let img = pool.install(|| render::render(scene, view, cancel, &|| {})).map_err(|_| BenchError::Cancelled)?;
    Ok((img, start.elapsed().as_secs_f64() * threads as f64))
}

/// One estimator on one slice, against its reference.
fn measure(
    sky: &BasisSky,
    fog: Option<&FogSettings>,
    sun_zenith_deg: f64,
    method: SingleScatter,
    reference: &Image,
    o: &BenchOptions,
    scene: &Scene,
    pool: &rayon::ThreadPool,
    cap: u32,
    cancel: &AtomicBool,
) -> Result<SliceCost, BenchError> {
    let measured = view(sky, fog, sun_zenith_deg, o.stride, o.spp, MEASURED_SEED, method);
    let (img, core_seconds) = timed(pool, o.threads, scene, &measured, cancel)?;
    let (_, one_core_seconds) =
        timed(pool, o.threads, scene, &view(sky, fog, sun_zenith_deg, o.stride, 1, MEASURED_SEED, method), cancel)?;
    // A fog slice's Fog: its render plus the quadrature, per texel.
    let quadrature =
        if fog.is_some() { pool.install(|| crate::bake::fog::time_quadrature(scene, &measured)) } else { 0.0 };
    let n = o.spp as f64;
    let (mut e2, mut s2, mut own, mut own_each) = (0.0, 0.0, 0.0, Vec::new());
    let mut ref_rel = Vec::new();
    for (p, r) in img.pixels.iter().zip(&reference.pixels) {
        let (y, ry) = (p.xyz[1], r.xyz[1]);
        if !(ry > 0.0) {
            continue;
        }
        let e = (y - ry) / ry;
        let s = r.xyz_stderr[1] / ry;
        e2 += e * e;
        s2 += s * s;
        ref_rel.push(s);
        // The texel's own per-sample relative variance, relative to the
        // reference's Y (the estimate's own Y can be 0 in a dark texel).
        // A texel whose samples found no light is priced at the cap, as
        // `adaptive::samples_for` takes a pilot that saw none.
        let v = n * (p.xyz_stderr[1] / ry).powi(2);
        if p.xyz[1] > 0.0 {
            own += v;
            own_each.push(Some(v));
        } else {
            own_each.push(None);
        }
    }
    let texels = own_each.len();
    let m = texels.max(1) as f64;
    let rel_var_vs_reference = (n * (e2 - s2) / m).max(0.0);
    let rel_var_own = own / own_each.iter().flatten().count().max(1) as f64;
    let kappa = if rel_var_own > 0.0 { rel_var_vs_reference / rel_var_own } else { 1.0 };
    let subset = (img.width * img.height) as f64;
    let core_seconds_per_path = ((core_seconds - one_core_seconds) / (subset * (n - 1.0))).max(0.0);
    let overhead = (one_core_seconds / subset - core_seconds_per_path).max(0.0) + quadrature / subset;
    let target2 = TARGET_REL_ERROR * TARGET_REL_ERROR;
    let (mut samples, mut uncapped, mut capped) = (0.0, 0.0, 0usize);
    // As `adaptive_samples` counts them: the pilot, then the estimate's
    // samples between its floor and what the cap leaves (and without the
    // cap: what 1 % takes).
    let left = cap.saturating_sub(ADAPTIVE_PILOT_SPP) as f64;
    // A texel without light takes the cap, and to 1 % what the slice's
    // mean variance takes.
    for v in &own_each {
        let want = (kappa * v.unwrap_or(rel_var_own) / target2).ceil();
        capped += (v.is_none() || want > left) as usize;
        let at_cap = if v.is_some() { want.min(left) } else { left };
        samples += ADAPTIVE_PILOT_SPP as f64 + at_cap.max((ADAPTIVE_MIN_SPP as f64).min(left));
        uncapped += ADAPTIVE_PILOT_SPP as f64 + want.max(ADAPTIVE_MIN_SPP as f64);
    }
    let samples_to_target = uncapped / m;
    let samples_capped = samples / m;
    let full = fog.map_or(sky.width * sky.height, |f| f.width * f.height) as f64;
    ref_rel.sort_by(f64::total_cmp);
    Ok(SliceCost {
        sky: sky.name.clone(),
        sun_zenith_deg,
        method,
        texels,
        spp: o.spp,
        core_seconds,
        rel_var_vs_reference,
        rel_var_own,
        reference_rel_stderr: ref_rel.get(ref_rel.len() / 2).copied().unwrap_or(f64::NAN),
        core_seconds_per_path,
        overhead_core_seconds_per_texel: overhead,
        samples_to_target,
        slice_core_seconds_to_target: full * (overhead + samples_to_target * core_seconds_per_path),
        slice_core_seconds_capped: full * (overhead + samples_capped * core_seconds_per_path),
        capped_fraction: capped as f64 / m,
        coarse_ms: Vec::new(),
    })
}

/// A function of sun zenith known at a few points: linear between them,
/// constant beyond.
fn interpolate(points: &[(f64, f64)], x: f64) -> f64 {
    let (first, last) = (points[0], points[points.len() - 1]);
    if x <= first.0 {
        return first.1;
    }
    if x >= last.0 {
        return last.1;
    }
    let k = points.partition_point(|p| p.0 <= x);
    let (a, b) = (points[k - 1], points[k]);
    a.1 + (b.1 - a.1) * (x - a.0) / (b.0 - a.0)
}

/// Runs the benchmark; `on_slice` hears of each measured slice.
pub fn run(
    bake: &BakeFile,
    o: &BenchOptions,
    mie: &MieCache,
    cancel: &AtomicBool,
    on_slice: &dyn Fn(&SliceCost),
) -> Result<BenchReport, BenchError> {
    for name in &o.skies {
        if !bake.skies.iter().any(|s| &s.name == name) {
            return Err(BenchError::NoSuchSky(name.clone()));
        }
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(o.threads)
        .build()
        .map_err(|e| BenchError::Threads(e.to_string()))?;
    let mut zeniths = o.sun_zenith_deg.clone();
    zeniths.sort_by(f64::total_cmp);
    let zero: Vec<(SingleScatter, f64)> = o.methods.iter().map(|m| (*m, 0.0)).collect();
    let mut report = BenchReport {
        slices: Vec::new(),
        skies: Vec::new(),
        total_core_hours: zero.clone(),
        total_capped_core_hours: zero,
        coarse_ms: Vec::new(),
    };
    for sky in bake.skies.iter().filter(|s| o.skies.is_empty() || o.skies.contains(&s.name)) {
        let (atm, _) = Atmosphere::load_bundle(&sky.atmosphere)
            .map_err(|error| BenchError::Atmosphere { sky: sky.name.clone(), error })?;
        // The final quality's optics and cap, whatever the bake file's draft.
        let final_ = sky.sampling(Quality::Final).clone();
        let cap = final_.spp;
        let scene = Scene::new(&atm, &spectral_settings(&final_), mie, &|| {});
        // Per method and sun zenith: the slice's cost to 1 % and at the cap,
        // then the same with multiple scattering from each coarser grid.
        let mut per_method: Vec<Vec<(f64, Vec<[f64; 2]>)>> = vec![Vec::new(); o.methods.len()];
        let full = (sky.width * sky.height) as f64;
        // The coarser grids measured, by name, in the order of each slice's `coarse_ms`.
        let lut_grid = (o.coarse_ms && !o.fog).then(|| format!("lut {}x{}", o.stride[0], o.stride[1]));
        let own_grid = o.coarse_ms_grid.filter(|_| !o.fog);
        let grid_names: Vec<String> =
            lut_grid.iter().cloned().chain(own_grid.map(|g| format!("own {}x{}", g[0], g[1]))).collect();
        for &z in &zeniths {
            let fog = o.fog.then_some(&bake.fog);
            let reference_view =
                view(sky, fog, z, o.stride, o.reference_spp, REFERENCE_SEED, SingleScatter::Quadrature);
            let (reference, _) = timed(&pool, o.threads, &scene, &reference_view, cancel)?;
            // Each coarser grid's accuracy and nodes over texels.
            let mut grids = Vec::new();
            if lut_grid.is_some() {
                let m = super::bench_coarse::measure(sky, &reference_view, &reference, &scene, &pool, cancel)?;
                grids.push((m, (reference.width * reference.height) as f64 / full));
            }
            if let Some(g) = own_grid {
                // The bake's grid: the sky's nodes measured, and the ground's too.
                let m = super::bench_coarse::measure_latlong(&reference_view, g, &scene, &pool, cancel)?;
                let nodes =
                    crate::bake::ms_grid::MsGrid::new(g, scene.medium.standpoint(sky.altitude_m / 1000.0)).nodes();
                grids.push((m, nodes as f64 / full));
            }
            for (k, &method) in o.methods.iter().enumerate() {
                let mut c = measure(sky, fog, z, method, &reference, o, &scene, &pool, cap, cancel)?;
                if method == SingleScatter::Quadrature {
                    // Only the sampling shrinks: the overhead stays at every texel.
                    let overhead = full * c.overhead_core_seconds_per_texel;
                    let (to_target, capped) = (c.slice_core_seconds_to_target, c.slice_core_seconds_capped);
                    c.coarse_ms = grid_names
                        .iter()
                        .zip(&grids)
                        .map(|(grid, (accuracy, f))| CoarseCost {
                            grid: grid.clone(),
                            accuracy: accuracy.clone(),
                            sampled_fraction: *f,
                            slice_core_seconds_to_target: overhead + (to_target - overhead) * f,
                            slice_core_seconds_capped: overhead + (capped - overhead) * f,
                        })
                        .collect();
                }
                on_slice(&c);
                let costs = std::iter::once([c.slice_core_seconds_to_target, c.slice_core_seconds_capped])
                    .chain(c.coarse_ms.iter().map(|g| [g.slice_core_seconds_to_target, g.slice_core_seconds_capped]))
                    .collect();
                per_method[k].push((z, costs));
                report.slices.push(c);
            }
        }
        let slice_zeniths: Vec<f64> = (0..sky.slices)
            .map(|i| mapping::slice_sun_zenith_deg(i, atm.planet.radius_km, atm.planet.top_km))
            .collect();
        for (k, &method) in o.methods.iter().enumerate() {
            let price = |variant: usize, which: usize| -> f64 {
                let points: Vec<(f64, f64)> = per_method[k].iter().map(|p| (p.0, p.1[variant][which])).collect();
                slice_zeniths.iter().map(|&z| interpolate(&points, z)).sum::<f64>() / 3600.0
            };
            let (core_hours, capped_core_hours) = (price(0, 0), price(0, 1));
            report.total_core_hours[k].1 += core_hours;
            report.total_capped_core_hours[k].1 += capped_core_hours;
            report.skies.push(SkyCost {
                sky: sky.name.clone(),
                method,
                slices: sky.slices,
                core_hours,
                capped_core_hours,
            });
            if method == SingleScatter::Quadrature {
                for (v, grid) in grid_names.iter().enumerate() {
                    report.coarse_ms.push(CoarseSkyCost {
                        sky: sky.name.clone(),
                        grid: grid.clone(),
                        core_hours: price(v + 1, 0),
                        capped_core_hours: price(v + 1, 1),
                    });
                }
            }
        }
    }
    let mut totals: Vec<CoarseSkyCost> = Vec::new();
    for c in &report.coarse_ms {
        match totals.iter_mut().find(|t| t.grid == c.grid) {
            Some(t) => {
                (t.core_hours, t.capped_core_hours) =
                    (t.core_hours + c.core_hours, t.capped_core_hours + c.capped_core_hours)
            }
            None => totals.push(CoarseSkyCost { sky: "total".into(), ..c.clone() }),
        }
    }
    report.coarse_ms.extend(totals);
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolation_is_linear_inside_and_constant_outside() {
        let p = [(20.0, 1.0), (60.0, 3.0), (96.0, 30.0)];
        assert_eq!(interpolate(&p, 10.0), 1.0);
        assert_eq!(interpolate(&p, 40.0), 2.0);
        assert_eq!(interpolate(&p, 100.0), 30.0);
        assert!((interpolate(&p, 78.0) - 16.5).abs() < 1e-12);
    }
}
