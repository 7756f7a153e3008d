//! A spherical source for the columns: the multiply scattered light of
//! spherical shells, by iterating the radiative transfer equation along
//! true rays (source iteration, "successive orders") from the
//! pseudo-spherical columns' solution.
//!
//! The columns (`columns`) are each a horizontally homogeneous column: the
//! light that one column's air scatters stays in that column. In spherical
//! shells a ray from a point runs over ground where the sun stands higher
//! or lower, up to 10° of arc away at the horizon; at twilight the light in
//! the Earth's shadow is mostly light scattered in the sunlit air beside
//! it and carried there sideways, which no column holds (TRANSPORT.md:
//! −2 to −97 % at sun zenith 94 to 98°).
//!
//! The iteration. At a set of node levels (a subset of the layers'
//! interfaces), for every column (local sun zenith θ_c), every stream
//! direction and azimuths from 0 to π, the radiance
//!   L(x, ω) = ∫ e^{−τ(s)} [J₁ + J](x + s ω) ds + e^{−τ_g} (A/π) E(θ_s at the ground)
//! is integrated along the node's straight ray through the shells: at every
//! interface it crosses, the local sun zenith θ_s follows from the arc
//! travelled and the ray's azimuth (spherical law of cosines, as in
//! `columns`), the single scattering's source J₁ = (ω′/4π) p′(Θ) T′(z, θ_s)
//! is exact for the delta-M scaled medium, and the multiply scattered
//! light's source J is read from the columns at θ_s (linear in log J between
//! the two nearest). J₁ is integrated layer by layer, exponential in
//! optical path across each as the beam is (`through_layer_log`); J
//! between the ray's stops (`stops`: by default every interface; a draft's
//! every interface near the ground, sparser above), linear in the optical
//! path summed over the layers between. (J₁ needs every layer: it changes by orders of magnitude across
//! the Earth's shadow; with it on the stops too, the zenith at sun 96° came
//! out 8 % bright, now 0.6 %, against every interface for both.) The node
//! radiances are turned into Fourier modes of azimuth (trapezoid rule on
//! 0..π) and into the source's coefficients (`adding::source_coefficients`);
//! the difference from the pseudo-spherical coefficients at the node
//! levels, linear in altitude between them, corrects the columns' sources
//! at every interface, and the ground's irradiance follows from the new
//! downward radiance at the ground. Repeated until the sources stop
//! moving: each pass carries the light one more scattering sideways. In
//! and under thick clouds a pass moves the answer only a little of the
//! way (light diffuses through a cloud over tens of scatterings): after
//! each pass the columns' own plane-parallel solution of its change's
//! further scattering is added (`accelerate`, synthetic acceleration),
//! which leaves the fixed point where it is and reaches it in a few passes
//! (cloudy5 at 550 nm, draft: the largest move 3e-4 after 12 passes, 8e-8
//! after 35; without, 4e-4 after 60 passes and still 0.97 of the last at
//! each).
//!
//! Modes of azimuth above `Settings::modes` keep the columns' values.

use super::accelerate::Accelerator;
use super::adding::{source_coefficients, Scaled};
use super::columns::{bracket, interfaces_km, log_lerp, Columns, Solution};
use super::layers::Layers;
use super::operator::Streams;
use super::shell_rays::{stops, through_layer_log, trace, At, Beam, Ray};
use super::spherical_table::{AlongRay, Phases, Table};
use rayon::prelude::*;
use std::f64::consts::PI;

/// The iteration's resolutions and stopping rule.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    /// The altitudes (km) near which node levels are placed (the nearest
    /// interface of the layers to each; the top and the ground always).
    pub levels_km: Vec<f64>,
    /// The highest Fourier mode of azimuth the iteration corrects.
    pub modes: usize,
    /// Intervals of azimuth from 0 to π at which the node rays run.
    pub azimuth_intervals: usize,
    /// The view cosines, −1 to 1, of the sources' table along the rays.
    pub table_cosines: usize,
    /// Stop when no node's source moves by more than this fraction of the
    /// largest of its column.
    pub tolerance: f64,
    pub max_passes: usize,
    /// The node rays add up the layers between stops no closer than
    /// `.0` km + `.1` times the altitude (`stops`).
    pub stop_spacing: (f64, f64),
    /// ... nor more than this vertical optical depth (delta-M scaled)
    /// apart: the source is linear in optical path between stops, which a
    /// cloud's is not over more than a fraction of one.
    pub stop_tau: f64,
    /// Whether each pass is followed by the columns' own solution of the
    /// correction's further scattering (`Accelerator`).
    pub accelerate: bool,
}

impl Default for Settings {
    fn default() -> Settings {
        Settings {
            levels_km: vec![
                0.0, 1.0, 2.0, 3.0, 4.0, 6.0, 8.0, 10.0, 12.0, 15.0, 18.0, 21.0, 25.0, 30.0, 35.0, 40.0, 50.0, 60.0,
                70.0, 85.0, 1e9,
            ],
            modes: 8,
            azimuth_intervals: 16,
            table_cosines: 129,
            tolerance: 1e-3,
            max_passes: 12,
            stop_spacing: (0.0, 0.0),
            stop_tau: 0.1,
            accelerate: true,
        }
    }
}

impl Settings {
    /// Coarser settings for a draft bake: every other node level, Fourier
    /// modes up to 4 on 8 intervals of azimuth, half the table's cosines,
    /// stops 0.5 km + 1/8 of the altitude apart (every 0.25 of optical depth
    /// in clouds), and a stopping tolerance of 3e-3. (The sparse stops
    /// alone, 16 streams, cloudy5 at 550 nm, against every interface:
    /// ground irradiance +1.4, +0.8, +1.0 and +2.7 % at sun 90, 93, 96 and
    /// 99°, for 0.68 times the twilight's time; in the tau-60 slab the
    /// iteration's fixed point 6e-3 off the exact columns, 2e-4 with every
    /// interface.) What it costs in the answer is
    /// measured against the defaults by `examples/draft_error`
    /// (`bake::solver::resolution`).
    pub fn draft() -> Settings {
        let full = Settings::default();
        Settings {
            levels_km: full.levels_km.iter().step_by(2).copied().collect(),
            modes: 4,
            azimuth_intervals: 8,
            table_cosines: 65,
            tolerance: 3e-3,
            stop_spacing: (0.5, 0.125),
            stop_tau: 0.25,
            ..full
        }
    }
}

/// Which of the iteration's settings a render takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Detail {
    /// `Settings::default()`: judged against the path tracer.
    #[default]
    Full,
    /// `Settings::draft()`.
    Draft,
}

impl Detail {
    pub fn settings(self) -> Settings {
        match self {
            Detail::Full => Settings::default(),
            Detail::Draft => Settings::draft(),
        }
    }
}

/// How the iteration went.
#[derive(Debug, Clone, Default)]
pub struct Report {
    /// The largest relative move of a source in each pass.
    pub moves: Vec<f64>,
}

/// The columns of `zenith_rad` with their sources made spherical.
pub fn solve(layers: &Layers, streams: usize, zenith_rad: Vec<f64>, settings: &Settings) -> (Columns, Report) {
    let mut solution = Solution::new(layers, streams, &zenith_rad);
    let report = iterate(layers, &mut solution, &zenith_rad, settings);
    (Columns::from_solution(layers, solution, zenith_rad), report)
}

/// Layers of more scaled extinction than this (per km) are a cloud's:
/// their edges are node levels (`node_levels`). The basis skies' clear air
/// and haze stay below 0.4 per km at 360 nm; cloudy2's slab (tau 3.4 over
/// 2 km) is above it.
const THICK_PER_KM: f64 = 1.0;

/// The interfaces nearest to `targets_km`, top down, with the top, the
/// ground, and the edges of every optically thick stretch (`sigma[k]`: the
/// scaled extinction per km of layer k, between interfaces k and k + 1).
/// The correction is linear in altitude between node levels: across a
/// cloud's top it would spread the bright top's source into the air above
/// and the dark interior's into the top.
fn node_levels(z: &[f64], sigma: &[f64], targets_km: &[f64]) -> Vec<usize> {
    let thick = |k: usize| sigma.get(k).is_some_and(|&s| s > THICK_PER_KM);
    let edges = (1..z.len().saturating_sub(1)).filter(|&i| thick(i - 1) != thick(i));
    let mut levels: Vec<usize> = targets_km
        .iter()
        .map(|&t| (0..z.len()).min_by(|&a, &b| (z[a] - t).abs().total_cmp(&(z[b] - t).abs())).unwrap_or(0))
        .chain([0, z.len() - 1])
        .chain(edges)
        .collect();
    levels.sort_unstable();
    levels.dedup();
    levels
}

/// What one pass of the iteration reads: the sources' table, the beam,
/// the layers, the columns' sun angles and the ground's diffuse
/// irradiance in each.
struct Pass<'a> {
    table: &'a Table,
    beam: &'a Beam,
    scaled: &'a [Scaled],
    phases: &'a Phases,
    zenith_rad: &'a [f64],
    albedo: f64,
    diffuse: &'a [f64],
}

impl Pass<'_> {
    /// The ground's irradiance where the sun stands at `zenith`.
    fn ground_at(&self, zenith: f64) -> f64 {
        let (c, w) = bracket(self.zenith_rad, zenith);
        let d = if w == 0.0 { self.diffuse[c] } else { self.diffuse[c] * (1.0 - w) + self.diffuse[c + 1] * w };
        d + zenith.cos().max(0.0) * self.beam.at(self.scaled.len(), zenith)
    }

    /// The geometry of `ray` (zenith cosine `u0` at its start) seen from
    /// azimuth `cos_phi` from the sun, whose zenith angle is (cos, sin)
    /// `sun` at the start: the cosine of the scattering angle, and in
    /// `at_points` each point's sun zenith (and its cosine).
    fn geometry(ray: &Ray, u0: f64, sun: (f64, f64), cos_phi: f64, at_points: &mut Vec<(f64, f64)>) -> f64 {
        let (cos_c, sin_c) = sun;
        let sin_v = (1.0 - u0 * u0).max(0.0).sqrt();
        at_points.clear();
        for p in &ray.points {
            let cos_s = (p.cos_arc * cos_c + p.sin_arc * sin_c * cos_phi).clamp(-1.0, 1.0);
            at_points.push((cos_s.acos(), cos_s));
        }
        (u0 * cos_c + sin_v * sin_c * cos_phi).clamp(-1.0, 1.0)
    }

    /// The light scattered once along `ray` toward its start (`geometry`'s
    /// scattering cosine and points), layer by layer, the beam exponential
    /// across each. The same in every pass.
    fn single(&self, ray: &Ray, cos_scattering: f64, at_points: &[(f64, f64)]) -> f64 {
        let beam_at = |pi: usize| -> f64 {
            let zenith = at_points[pi].0;
            match ray.points[pi].at {
                At::Interface(i) => self.beam.at(i, zenith),
                At::Inside(k, f) => (self.beam.at(k, zenith).max(1e-300).ln() * (1.0 - f)
                    + self.beam.at(k + 1, zenith).max(1e-300).ln() * f)
                    .exp(),
            }
        };
        let (mut radiance, mut before) = (0.0f64, 0.0f64);
        let mut t_near = beam_at(0);
        for (q, &(k, tau)) in ray.steps.iter().enumerate() {
            if before > 40.0 {
                break;
            }
            let t_far = beam_at(q + 1);
            let f = self.scaled[k].omega / (4.0 * PI) * self.phases.at(k, cos_scattering);
            radiance += f * through_layer_log(t_far, t_near, tau) * (-before).exp();
            (before, t_near) = (before + tau, t_far);
        }
        radiance
    }

    /// The radiance arriving at the start of `ray`: `single` (its light
    /// scattered once), plus that of the multiply scattered light's
    /// sources in this pass's table (`along`: at the ray's stops) and of
    /// the ground, with `geometry`'s scattering cosine and points.
    fn radiance(&self, ray: &Ray, along: &AlongRay, single: f64, cos_scattering: f64, at_points: &[(f64, f64)]) -> f64 {
        let mut radiance = single;
        // Where stop `q` reads the columns: the bracketing columns and the
        // azimuth from the local sun.
        let geometry = |q: usize| -> (usize, f64, f64) {
            let (zenith, cos_s) = at_points[ray.stops[q]];
            let u = ray.points[ray.stops[q]].u;
            let sin_s = (1.0 - cos_s * cos_s).max(0.0).sqrt();
            let sin_u = (1.0 - u * u).max(0.0).sqrt();
            let cos_local = if sin_u * sin_s > 1e-12 {
                ((cos_scattering - u * cos_s) / (sin_u * sin_s)).clamp(-1.0, 1.0)
            } else {
                1.0
            };
            let (cc, w) = bracket(self.zenith_rad, zenith);
            (cc, w, cos_local)
        };
        // The multiply scattered light's source at stop `q` (`geometry`
        // `g`), in layer k next to it.
        let multiple = |q: usize, (cc, w, cos_local): (usize, f64, f64), k: usize| -> f64 {
            let pi = ray.stops[q];
            let one = |slot: usize| -> f64 {
                let (a, b) = along.values(q, slot, cc, cos_local, w != 0.0);
                if w == 0.0 {
                    a
                } else {
                    log_lerp(a, b, w)
                }
            };
            match ray.points[pi].at {
                At::Interface(i) => one(if k + 1 == i { 0 } else { 1 }),
                At::Inside(_, f) => one(0) * (1.0 - f) + one(1) * f,
            }
        };
        let mut before = 0.0f64;
        let mut g_near = if ray.segments.is_empty() { (0, 0.0, 1.0) } else { geometry(0) };
        for (q, (&(k_near, k_far, tau), &(base, top, attenuation))) in
            ray.segments.iter().zip(along.segments()).enumerate()
        {
            if before > 40.0 {
                break;
            }
            let g_far = geometry(q + 1);
            let (far, near) = (multiple(q + 1, g_far, k_far), multiple(q, g_near, k_near));
            // `through_layer(far, near, tau) * (-before).exp()`, its
            // weights the ray's own.
            radiance += (near * base + far * top) * attenuation;
            before += tau;
            g_near = g_far;
        }
        if ray.ground && self.albedo > 0.0 {
            let zenith = at_points.last().map_or(0.0, |p| p.0);
            radiance += self.albedo / PI * self.ground_at(zenith) * (-before).exp();
        }
        radiance
    }

    /// Column c's light scattered once along its node rays (`rays[level]`
    /// of cosines `dirs`), at each of `phis`: `[(level · dirs + j) · phis
    /// + k]`.
    fn singles(&self, c: usize, rays: &[Vec<Ray>], dirs: &[f64], phis: &[f64]) -> Vec<f64> {
        let sun = (self.zenith_rad[c].cos(), self.zenith_rad[c].sin());
        let mut at_points = Vec::new();
        let mut out = Vec::with_capacity(rays.len() * dirs.len() * phis.len());
        for level_rays in rays {
            for (ray, &u0) in level_rays.iter().zip(dirs) {
                for phi in phis {
                    let cos_scattering = Self::geometry(ray, u0, sun, phi.cos(), &mut at_points);
                    out.push(self.single(ray, cos_scattering, &at_points));
                }
            }
        }
        out
    }

    /// Node ray `j` of level `lv` (`ray`, zenith cosine `u0`) in every
    /// column: its radiance as Fourier modes of azimuth (trapezoid rule on
    /// `phis`, 0..π), `[c][m]`; `singles[c]`: the columns' light scattered
    /// once (`singles`), `first` the ray's first in them. Every column
    /// reads the ray's stops from one `AlongRay` (the table at their view
    /// cosines), which stays in the cache while the columns take turns.
    fn ray_modes(
        &self,
        ray: &Ray,
        u0: f64,
        phis: &[f64],
        modes: usize,
        (singles, first): (&[Vec<f64>], usize),
    ) -> Vec<Vec<f64>> {
        let kk = phis.len() - 1;
        let along = AlongRay::new(self.table, ray);
        let mut at_points = Vec::new();
        (0..self.zenith_rad.len())
            .map(|c| {
                let sun = (self.zenith_rad[c].cos(), self.zenith_rad[c].sin());
                let along_phi: Vec<f64> = phis
                    .iter()
                    .zip(&singles[c][first..first + phis.len()])
                    .map(|(phi, &single)| {
                        let cos_scattering = Self::geometry(ray, u0, sun, phi.cos(), &mut at_points);
                        self.radiance(ray, &along, single, cos_scattering, &at_points)
                    })
                    .collect();
                (0..modes)
                    .map(|m| {
                        let sum: f64 = (0..=kk)
                            .map(|kp| {
                                let end = if kp == 0 || kp == kk { 0.5 } else { 1.0 };
                                end * along_phi[kp] * (m as f64 * phis[kp]).cos()
                            })
                            .sum();
                        sum * if m == 0 { 1.0 } else { 2.0 } / kk as f64
                    })
                    .collect()
            })
            .collect()
    }
}

/// One column's node radiances by level and mode: (down, up) per stream.
type NodeModes = Vec<Vec<(Vec<f64>, Vec<f64>)>>;

/// Every column's node radiances (`NodeModes`) in this pass: the node rays
/// (`rays[level]`: the streams looking up, cosines `dirs`, then down) in
/// parallel, each in every column (`Pass::ray_modes`).
fn node_modes(
    pass: &Pass,
    rays: &[Vec<Ray>],
    (dirs, phis): (&[f64], &[f64]),
    modes: usize,
    singles: &[Vec<f64>],
) -> Vec<NodeModes> {
    let n = dirs.len() / 2;
    let per_ray: Vec<Vec<Vec<f64>>> = (0..rays.len() * dirs.len())
        .into_par_iter()
        .map(|r| {
            let (lv, j) = (r / dirs.len(), r % dirs.len());
            pass.ray_modes(&rays[lv][j], dirs[j], phis, modes, (singles, r * phis.len()))
        })
        .collect();
    let columns = pass.zenith_rad.len();
    let mut out = vec![vec![vec![(vec![0.0; n], vec![0.0; n]); modes]; rays.len()]; columns];
    for (r, by_column) in per_ray.into_iter().enumerate() {
        let (lv, j) = (r / dirs.len(), r % dirs.len());
        for (c, by_mode) in by_column.into_iter().enumerate() {
            for (m, value) in by_mode.into_iter().enumerate() {
                if j < n {
                    out[c][lv][m].0[j] = value;
                } else {
                    out[c][lv][m].1[j - n] = value;
                }
            }
        }
    }
    out
}

/// Coefficients `[c][m][interface or level][l]`.
type Coefficients = Vec<Vec<Vec<Vec<f64>>>>;

/// The largest move of a node's coefficient from `previous`, relative to
/// the largest isotropic coefficient of its column; infinite where a
/// coefficient is not finite (so that the iteration does not stop on it).
fn largest_move(at_levels: &Coefficients, previous: &Coefficients) -> f64 {
    let mut largest = 0.0f64;
    for (c, column) in at_levels.iter().enumerate() {
        let scale = column[0].iter().map(|a| a[0].abs()).fold(0.0, f64::max).max(1e-300);
        for (m, per_level) in column.iter().enumerate() {
            for (lv, a) in per_level.iter().enumerate() {
                let moved = a
                    .iter()
                    .zip(&previous[c][m][lv])
                    .map(|(x, y)| if x.is_finite() { (x - y).abs() } else { f64::INFINITY })
                    .fold(0.0, f64::max);
                largest = largest.max(moved / scale);
            }
        }
    }
    largest
}

/// The source's coefficients of the node radiances `new` (per column),
/// modes below `modes`.
fn node_coefficients(s: &Streams, new: &[NodeModes], modes: usize) -> Coefficients {
    new.iter()
        .map(|levels_of_c| {
            (0..modes)
                .map(|m| {
                    levels_of_c
                        .iter()
                        .map(|modes_of_level| {
                            let (d, u) = &modes_of_level[m];
                            source_coefficients(s, m, std::slice::from_ref(d), std::slice::from_ref(u)).remove(0)
                        })
                        .collect()
                })
                .collect()
        })
        .collect()
}

/// The coefficients `a` (`[c][m][interface]`) of modes below `modes` at
/// the node `levels`.
fn at_node_levels(a: &Coefficients, levels: &[usize], modes: usize) -> Coefficients {
    a.iter()
        .map(|column| column[..modes].iter().map(|m| levels.iter().map(|&i| m[i].clone()).collect()).collect())
        .collect()
}

/// The coefficients `pp` corrected by the difference of `at_levels` from
/// them at the node `levels`, linear in altitude between.
fn correct(a: &mut Coefficients, pp: &Coefficients, at_levels: &Coefficients, levels: &[usize], z: &[f64]) {
    for (c, column) in at_levels.iter().enumerate() {
        for (m, per_level) in column.iter().enumerate() {
            let delta: Vec<Vec<f64>> = per_level
                .iter()
                .zip(levels)
                .map(|(a, &i)| a.iter().zip(&pp[c][m][i]).map(|(x, y)| x - y).collect())
                .collect();
            for w in 0..levels.len() - 1 {
                let (ia, ib) = (levels[w], levels[w + 1]);
                for i in ia..=ib {
                    let f = if ib > ia { (z[ia] - z[i]) / (z[ia] - z[ib]) } else { 0.0 };
                    a[c][m][i] = pp[c][m][i]
                        .iter()
                        .enumerate()
                        .map(|(l, p)| p + delta[w][l] * (1.0 - f) + delta[w + 1][l] * f)
                        .collect();
                }
            }
        }
    }
}

/// Iterates `solution` (the pseudo-spherical columns at `zenith_rad`) to
/// the spherical solution, in place: its coefficients at every interface,
/// modes up to `settings.modes`, and its ground irradiance.
pub(super) fn iterate(layers: &Layers, solution: &mut Solution, zenith_rad: &[f64], settings: &Settings) -> Report {
    let mut report = Report::default();
    let z = interfaces_km(layers);
    let (s, scaled) = (&solution.s.clone(), &solution.scaled.clone());
    if scaled.is_empty() || zenith_rad.is_empty() {
        return report;
    }
    let sigma: Vec<f64> = scaled.iter().enumerate().map(|(k, l)| l.tau / (z[k] - z[k + 1]).max(1e-12)).collect();
    let beam = Beam::new(layers.shell_radius_km, &z, &sigma);
    let phases = Phases::new(scaled, s.lmax);
    let levels = node_levels(&z, &sigma, &settings.levels_km);
    let modes = settings.modes.min(solution.a[0].len() - 1) + 1;
    let kk = settings.azimuth_intervals.max(2 * modes);
    let phis: Vec<f64> = (0..=kk).map(|k| k as f64 * PI / kk as f64).collect();
    // The node rays: [level][stream], streams looking up (μ_j), then down.
    let dirs: Vec<f64> = s.mu.iter().copied().chain(s.mu.iter().map(|u| -u)).collect();
    let tau: Vec<f64> = scaled.iter().map(|l| l.tau).collect();
    let keep = stops(&z, &tau, &levels, settings.stop_spacing, settings.stop_tau);
    let rays: Vec<Vec<Ray>> = levels
        .iter()
        .map(|&i| dirs.iter().map(|&u| trace(layers.shell_radius_km, &z, &sigma, &keep, i, u)).collect())
        .collect();
    let pp: Coefficients = solution.a.clone();
    let direct = solution.ground_direct.clone();
    let mut diffuse: Vec<f64> = solution.ground_irradiance.iter().zip(&direct).map(|(g, d)| g - d).collect();
    let accelerator =
        if settings.accelerate { Accelerator::new(s, scaled, layers.ground_albedo, &levels, &z) } else { None };
    let mut singles: Option<Vec<Vec<f64>>> = None;
    for _pass in 0..settings.max_passes {
        let table = Table::new(solution, modes, settings.table_cosines.max(3));
        let pass = Pass {
            table: &table,
            beam: &beam,
            scaled,
            phases: &phases,
            zenith_rad,
            albedo: layers.ground_albedo,
            diffuse: &diffuse,
        };
        let singles = singles.get_or_insert_with(|| {
            (0..zenith_rad.len()).into_par_iter().map(|c| pass.singles(c, &rays, &dirs, &phis)).collect()
        });
        let new = node_modes(&pass, &rays, (&dirs, &phis), modes, singles);
        let mut at_levels = node_coefficients(s, &new, modes);
        let read: Coefficients = at_node_levels(&solution.a, &levels, modes);
        let moved = largest_move(&at_levels, &read);
        for (c, modes_of_c) in new.iter().enumerate() {
            let ground = &modes_of_c[levels.len() - 1][0].0;
            diffuse[c] = 2.0 * PI * (0..s.n()).map(|j| s.w[j] * s.mu[j] * ground[j]).sum::<f64>();
        }
        if let Some(accelerator) = &accelerator {
            // The rest of the way, as the columns would scatter this
            // pass's change further.
            let steps: Vec<(Vec<Vec<f64>>, f64)> = (0..zenith_rad.len())
                .into_par_iter()
                .map(|c| accelerator.step(&at_levels[c][0], &read[c][0]))
                .collect();
            for (c, (step, ground)) in steps.into_iter().enumerate() {
                for (a, step) in at_levels[c][0].iter_mut().zip(&step) {
                    a.iter_mut().zip(step).for_each(|(a, d)| *a += d);
                }
                diffuse[c] += ground;
            }
        }
        correct(&mut solution.a, &pp, &at_levels, &levels, &z);
        for c in 0..zenith_rad.len() {
            solution.ground_irradiance[c] = direct[c] + diffuse[c];
        }
        report.moves.push(moved);
        if moved < settings.tolerance {
            break;
        }
    }
    report
}

#[cfg(test)]
#[path = "spherical_tests.rs"]
mod tests;
