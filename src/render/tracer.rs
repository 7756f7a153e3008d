//! The path-tracing kernel at one wavelength: free-flight sampling by delta
//! tracking and sun transmittance by ratio tracking against piecewise-
//! constant shell majorants (Novák, Selle and Jarosz 2014; Novák et al.
//! 2018), next-event estimation toward the sun as parallel light (the
//! talk's "sunlight is approximated as a parallel light"), a visible sun disk
//! for camera rays, a Lambertian ground, phase sampling from the tabulated
//! Mie inverse CDFs, and Russian roulette.
//!
//! Radiance is relative to `Spectral::sun_irradiance` (pass 1 to get the
//! radiance per unit solar irradiance, sr⁻¹). Transcendental functions come
//! from `libm` (pure Rust), so the kernel rounds the same on every platform.

use super::guide::RayGuide;
use super::medium::{ColumnPath, ColumnTable, Medium, Phase, Spectral};
use super::rng::Rng;
use super::sampling::{self, cosine_hemisphere};
pub use super::sampling::{around, sample_hg};
use crate::atmosphere::Geometry;
use glam::DVec3;
use std::f64::consts::PI;

/// Nudge past a boundary, km.
pub(crate) const EPS_KM: f64 = 1e-9;
/// Paths with more vertices than this are cut, and counted
/// ([`PathSample::cut`], `paths_cut` in a render's JSON). Far beyond what
/// the thickest basis sky needs: under a cloud of optical depth 60 with
/// g 0.85 (transport optical depth 9) a diffusing path takes of the order
/// of a thousand scatterings, and Russian roulette, on the throughput only,
/// does not shorten it.
pub const MAX_VERTICES: usize = 100_000;

/// One path's estimate: the directly seen sun's disk, everything scattered
/// or reflected, and whether the path was cut at [`MAX_VERTICES`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathSample<T> {
    pub direct: T,
    pub scattered: T,
    pub cut: bool,
}

/// The survival probability of Russian roulette on the path throughput
/// `beta` relative to `beta_ref`, its value after the first vertex: paths
/// whose throughput has not fallen are never killed (a fixed per-vertex
/// kill rate would end nearly every path inside a thick cloud and weight
/// the survivors by 0.95^-n). Survivors are weighted by 1 / q (unbiased).
#[inline]
pub(crate) fn survival_probability(beta: f64, beta_ref: f64) -> f64 {
    if !(beta_ref > 0.0) || !(beta > 0.0) {
        return 0.0;
    }
    (beta / beta_ref).min(1.0)
}

/// Vertices a path has before Russian roulette starts.
pub(crate) const ROULETTE_FROM_DEPTH: usize = 3;

/// How a flight ended.
enum Flight {
    Escape,
    Ground(DVec3),
    Collision(DVec3),
}

/// Which estimator to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Estimator {
    /// Delta tracking, phase sampling, next-event estimation with ratio
    /// tracking, Russian roulette: what `sky render` ships.
    Full,
    /// The naive baseline for benchmarks: analog tracking, no next-event
    /// estimation; light arrives only when a path escapes through the sun's
    /// disk or hits the ground... which never sees the sun directly either,
    /// so sunlight enters only through the disk.
    Naive,
}

/// Everything fixed during a render, at one wavelength.
pub struct Tracer<'a> {
    pub medium: &'a Medium,
    pub spectral: &'a Spectral,
    /// Unit vector toward the sun.
    pub sun_dir: DVec3,
    /// cos of the sun's angular radius.
    pub sun_cos_half: f64,
    /// Radiance of the sun's disk relative to `sun_irradiance` (1/Ω).
    pub sun_disk_radiance: f64,
    pub estimator: Estimator,
    /// Whether camera rays see the sun's disk.
    pub sun_disk: bool,
    /// Tabulated columns for transmittance toward space along rays that
    /// do not descend (None: ratio tracking everywhere).
    pub columns: Option<&'a ColumnTable>,
    /// Sun-lobe guiding: the component whose phase function is most
    /// forward-peaked, and the probability of drawing a scattered direction
    /// from its lobe around the sun instead of from the local phase function
    /// (see [`Tracer::sun_lobe`]).
    pub lobe: Option<(usize, f64)>,
    /// Whether vertices in the Earth's shadow estimate the sunlight
    /// scattered toward them along their scattered ray (see
    /// [`Tracer::skylight_along`]; on for the full estimator, needs the
    /// column table).
    pub skylight: bool,
}

/// Probability of drawing a scattered direction from the sun lobe, when the
/// medium has a forward-peaked component. Measured on the hazed sky (sun at
/// 80°, view 90° from it, 8192 paths at 550 nm): per-sample relative
/// deviation 2.41 without the lobe, 2.03 at α = 0.1, 2.18 at 0.25, 2.78 at
/// 0.5; the test `variance_reductions_are_unbiased` checks it still helps.
pub const LOBE_PROBABILITY: f64 = 0.25;
/// A component guides toward the sun only if its phase function peaks
/// above this, sr⁻¹ (Rayleigh peaks at 0.12; HG with g = 0.5 at 0.72).
const LOBE_MIN_PEAK_SR_INV: f64 = 1.0;

#[inline]
fn ln(x: f64) -> f64 {
    libm::log(x)
}

impl<'a> Tracer<'a> {
    pub fn new(medium: &'a Medium, spectral: &'a Spectral, sun_dir: DVec3, sun_angular_diameter_deg: f64, estimator: Estimator) -> Tracer<'a> {
        let half = 0.5 * sun_angular_diameter_deg.to_radians();
        let cos_half = libm::cos(half);
        let omega = 2.0 * PI * (1.0 - cos_half);
        let lobe = match estimator {
            Estimator::Naive => None,
            Estimator::Full => Tracer::sun_lobe(spectral).map(|i| (i, LOBE_PROBABILITY)),
        };
        Tracer {
            medium,
            spectral,
            sun_dir: sun_dir.normalize(),
            sun_cos_half: cos_half,
            sun_disk_radiance: 1.0 / omega,
            estimator,
            sun_disk: true,
            columns: None,
            lobe,
            skylight: estimator == Estimator::Full,
        }
    }

    /// The component whose phase function has the highest forward peak, if
    /// that peak is strong enough to be worth guiding toward.
    ///
    /// Why: the sun is a parallel light for scattering, so next-event
    /// estimation is the only way sunlight enters a path, and its value at
    /// a vertex is p(ω·ω_sun). When the direction ω arriving at that vertex
    /// was drawn from the previous vertex's phase function (or the ground's
    /// cosine lobe), nothing steers it toward the sun, and the rare ω that
    /// fall inside an aerosol's forward peak carry weights of p(1) ~ 10³
    /// sr⁻¹: fireflies in every multiply scattered pixel. Drawing ω with
    /// probability α from that peak centred on the sun, p_lobe(ω·ω_sun), and
    /// weighting by the one-sample balance heuristic over the two
    /// strategies, f(ω) / ((1 − α) p_local(ω) + α p_lobe(ω)), bounds those
    /// weights by 1/α times the next phase value's ratio to the lobe
    /// (Veach 1997, ch. 9: multiple importance sampling; the sun lobe is
    /// the "where forward-peaked aerosols see the sun" case of the issue).
    pub fn sun_lobe(spectral: &Spectral) -> Option<usize> {
        let mut best: Option<(usize, f64)> = None;
        for (i, ph) in spectral.phase.iter().enumerate() {
            if spectral.albedo[i] <= 0.0 || spectral.extinction[i] <= 0.0 {
                continue;
            }
            let peak = ph.eval(1.0);
            if peak > LOBE_MIN_PEAK_SR_INV && best.is_none_or(|(_, b)| peak > b) {
                best = Some((i, peak));
            }
        }
        best.map(|(i, _)| i)
    }

    /// The probability of taking the lobe technique's sample at a vertex
    /// whose sun transmittance is `t_sun` (see [`Tracer::lobe_next_event`]):
    /// [`LOBE_PROBABILITY`] times min(1, t_sun), so no flight is spent
    /// where the sun is out of sight (inside a thick cloud, in the Earth's
    /// shadow), where the next vertex would not see it either. It depends
    /// only on the vertex, as the multiple importance sampling requires.
    #[inline]
    pub(crate) fn lobe_alpha_at(&self, t_sun: f64) -> f64 {
        match self.lobe {
            Some((_, alpha)) if t_sun > 0.0 => alpha * t_sun.min(1.0),
            _ => 0.0,
        }
    }

    /// The lobe component's phase function toward the sun for a direction
    /// `w` (the lobe technique's density), 0 without a lobe.
    #[inline]
    pub(crate) fn lobe_pdf(&self, w: DVec3) -> f64 {
        self.lobe.map_or(0.0, |(i, _)| self.spectral.phase[i].eval(w.dot(self.sun_dir)))
    }

    /// Σ_i σ_s,i(z) p_i(μ) and Σ_i σ_s,i(z): the scattering coefficient
    /// weighted by each component's phase function at μ, and unweighted.
    #[inline]
    pub(crate) fn scattering_at(&self, z_km: f64, mu: f64) -> (f64, f64) {
        let sp = self.spectral;
        let (mut weighted, mut total) = (0.0, 0.0);
        for i in 0..sp.extinction.len() {
            let s = sp.extinction[i] * self.medium.density(i, z_km) * sp.albedo[i];
            if s > 0.0 {
                weighted += s * sp.phase[i].eval(mu);
                total += s;
            }
        }
        (weighted, total)
    }

    /// The lobe technique of the sun's next-event estimate at the *next*
    /// vertex. The sunlight single-scattered toward a vertex x along ω is
    /// ∫ f(ω) g(ω) dω, with f the vertex's scattering (phase function or
    /// cosine lobe, density `local_pdf` as sampled) and g the next vertex's
    /// next-event estimate; where an aerosol's or a cloud's forward peak
    /// (p(1) ~ 10³ sr⁻¹) sees the sun, directions drawn from f seldom fall
    /// in it and those that do carry huge estimates. Two techniques, then,
    /// combined by the balance heuristic with their expected sample counts
    /// (Veach 1997, §9.2): the path's own continuation ω ~ f (always; its
    /// next vertex's sun estimate is weighted by f / (f + α p_lobe), see
    /// [`Tracer::continuation_weight`]) and, with probability α, a direction
    /// ω' from the lobe component's phase function centred on the sun and a
    /// free flight along it, whose collision's sun estimate is weighted by
    /// f / (f + α p_lobe) as well (the densities' ratio to its own sampling
    /// and the weight multiply to that). The path itself is not changed:
    /// its throughput never carries a lobe weight, so Russian roulette does
    /// not kill paths that a lobe direction would have weighted down.
    /// Returns the estimate, already times `beta`.
    pub(crate) fn lobe_next_event(&self, x: DVec3, alpha: f64, beta: f64, local_pdf: impl Fn(DVec3) -> f64, rng: &mut Rng) -> f64 {
        let Some((i, _)) = self.lobe else { return 0.0 };
        if !(alpha > 0.0) || rng.uniform() >= alpha {
            return 0.0;
        }
        let w = self.sample_phase(&self.spectral.phase[i], self.sun_dir, rng);
        let f = local_pdf(w);
        if !(f > 0.0) {
            return 0.0;
        }
        let weight = f / (f + alpha * self.lobe_pdf(w));
        match self.fly(x, w, rng) {
            Flight::Escape => 0.0,
            Flight::Collision(y) => {
                let t_sun = self.transmittance_to_space(y, self.sun_dir, rng);
                if !(t_sun > 0.0) {
                    return 0.0;
                }
                let z = self.altitude(y);
                // Delta tracking reached y with density σ_t T: the estimate
                // is Σ_i σ_s,i p_i(μ_sun) / σ_t times the sun's transmittance.
                let (sp, _) = self.scattering_at(z, w.dot(self.sun_dir));
                let st = self.spectral.sigma_t(self.medium, z);
                if !(st > 0.0) {
                    return 0.0;
                }
                beta * weight * sp / st * t_sun
            }
            Flight::Ground(g) => {
                let n = self.up(g);
                let cos_s = n.dot(self.sun_dir);
                let a = self.spectral.ground_albedo;
                if cos_s <= 0.0 || a <= 0.0 {
                    return 0.0;
                }
                beta * weight * a / PI * cos_s * self.transmittance_to_space(g + n * EPS_KM, self.sun_dir, rng)
            }
        }
    }

    /// The weight of the sun's next-event estimate at the vertex a
    /// continuation direction `w` leads to (see [`Tracer::lobe_next_event`]).
    #[inline]
    pub(crate) fn continuation_weight(&self, alpha: f64, local_pdf: f64, w: DVec3) -> f64 {
        if alpha > 0.0 {
            local_pdf / (local_pdf + alpha * self.lobe_pdf(w))
        } else {
            1.0
        }
    }

    pub fn with_columns(mut self, columns: &'a ColumnTable) -> Self {
        self.columns = Some(columns);
        self
    }

    /// Transmittance from `p` to space along `d`: from the column table when
    /// there is one (exact optical depth, see [`ColumnPath`]), else by
    /// ratio tracking.
    pub fn transmittance_to_space(&self, p: DVec3, d: DVec3, rng: &mut Rng) -> f64 {
        if let Some(c) = self.columns {
            return match self.column_path(c, p, d, None) {
                None => 0.0,
                Some(path) => libm::exp(-c.path_optical_depth(&path, &self.spectral.extinction)),
            };
        }
        self.transmittance(p, d, rng)
    }

    /// The columns whose sum and difference give the optical depth from `p`
    /// along `d` over `t_km` (to space when None); None when a ray to space
    /// meets the ground. The segment must not cross the ground.
    pub(crate) fn column_path(&self, c: &ColumnTable, p: DVec3, d: DVec3, t_km: Option<f64>) -> Option<ColumnPath> {
        let mut path = ColumnPath::default();
        let mu_p = self.up(p).dot(d);
        let z_p = self.altitude(p);
        let end = t_km.map(|t| {
            let q = p + d * t;
            (self.altitude(q), self.up(q).dot(d))
        });
        if mu_p >= 0.0 {
            // Rising all along.
            path.push_add(c.node(z_p, mu_p));
            if let Some((z_q, mu_q)) = end {
                path.push_sub(c.node(z_q, mu_q));
            }
            return Some(path);
        }
        // Sinking at p: where is the lowest point of the line?
        let (t_low, z_low) = match self.medium.geometry {
            Geometry::PlaneParallel => (f64::INFINITY, f64::NEG_INFINITY),
            Geometry::Spherical => {
                let t_low = -p.dot(d);
                (t_low, (p + d * t_low).length() - self.medium.radius_km)
            }
        };
        match end {
            Some((z_q, mu_q)) if t_km.unwrap() <= t_low || mu_q <= 0.0 => {
                // Sinking all along: the reverse, q→p, rises.
                path.push_add(c.node(z_q, -mu_q));
                path.push_sub(c.node(z_p, -mu_p));
                Some(path)
            }
            _ => {
                if z_low < 0.0 {
                    return None; // the ray meets the ground (only asked for rays to space)
                }
                let low = c.node(z_low, 0.0);
                path.push_add(low);
                path.push_add(low);
                path.push_sub(c.node(z_p, -mu_p));
                if let Some((z_q, mu_q)) = end {
                    path.push_sub(c.node(z_q, mu_q));
                }
                Some(path)
            }
        }
    }

    pub fn with_sun_disk(mut self, visible: bool) -> Self {
        self.sun_disk = visible;
        self
    }

    /// A point at `altitude_km` above the origin of the horizontal plane
    /// (at least 1 mm, so rays looking down meet the ground ahead of them).
    pub fn observer(&self, altitude_km: f64) -> DVec3 {
        let altitude_km = altitude_km.max(1e-6);
        match self.medium.geometry {
            Geometry::Spherical => DVec3::new(0.0, 0.0, self.medium.radius_km + altitude_km),
            Geometry::PlaneParallel => DVec3::new(0.0, 0.0, altitude_km),
        }
    }

    #[inline]
    pub(crate) fn altitude(&self, p: DVec3) -> f64 {
        match self.medium.geometry {
            Geometry::Spherical => p.length() - self.medium.radius_km,
            Geometry::PlaneParallel => p.z,
        }
    }

    #[inline]
    pub(crate) fn up(&self, p: DVec3) -> DVec3 {
        match self.medium.geometry {
            Geometry::Spherical => p.normalize(),
            Geometry::PlaneParallel => DVec3::Z,
        }
    }

    /// Distance along `d` from `p` to the altitude `z_km` boundary (sphere
    /// or plane), if the ray reaches it; `leaving_upward` picks the far root.
    fn distance_to_altitude(&self, p: DVec3, d: DVec3, z_km: f64, upward: bool) -> Option<f64> {
        match self.medium.geometry {
            Geometry::PlaneParallel => {
                let t = (z_km - p.z) / d.z;
                (t > 0.0 && t.is_finite()).then_some(t)
            }
            Geometry::Spherical => {
                let r = self.medium.radius_km + z_km;
                let b = p.dot(d);
                let c = p.length_squared() - r * r;
                let disc = b * b - c;
                if disc < 0.0 {
                    return None;
                }
                let s = disc.sqrt();
                if upward {
                    let t = -b + s;
                    (t > 0.0).then_some(t)
                } else {
                    // Nearer root, only if the sphere is ahead.
                    let t = -b - s;
                    (t > 0.0).then_some(t)
                }
            }
        }
    }

    /// The distance from `p` along `d` to the ground, or else to the top of
    /// the atmosphere (None when the ray never meets either, as a ray
    /// leaving the top of the atmosphere).
    pub(crate) fn ray_end(&self, p: DVec3, d: DVec3) -> Option<f64> {
        self.distance_to_altitude(p, d, 0.0, false).or_else(|| self.distance_to_altitude(p, d, self.medium.top_km, true))
    }

    /// The shell at `p` and the distance along `d` to its boundary, with
    /// what lies beyond: Some(next shell) or None for space (ground is
    /// reported as shell usize::MAX).
    pub(crate) fn shell_exit(&self, p: DVec3, d: DVec3) -> (usize, f64, Option<usize>) {
        let top = self.medium.top_km;
        let shells = self.medium.shells();
        let z = self.altitude(p).clamp(0.0, top);
        let s = self.medium.shell_of(z);
        let lo = self.medium.shell_edges_km[s];
        let hi = self.medium.shell_edges_km[s + 1];
        let t_up = self.distance_to_altitude(p, d, hi, true).unwrap_or(f64::INFINITY);
        let t_down = self.distance_to_altitude(p, d, lo, false).unwrap_or(f64::INFINITY);
        if t_down < t_up {
            (s, t_down, Some(if s == 0 { usize::MAX } else { s - 1 }))
        } else if s + 1 >= shells {
            (s, t_up, None)
        } else {
            (s, t_up, Some(s + 1))
        }
    }

    /// Delta tracking from `p` along `d`.
    fn fly(&self, mut p: DVec3, d: DVec3, rng: &mut Rng) -> Flight {
        for _ in 0..1_000_000 {
            let (s, t_exit, next) = self.shell_exit(p, d);
            let m = self.spectral.majorant[s];
            if m > 0.0 {
                let t = -ln(1.0 - rng.uniform()) / m;
                if t < t_exit {
                    p += d * t;
                    let sigma_t = self.spectral.sigma_t(self.medium, self.altitude(p));
                    if rng.uniform() * m < sigma_t {
                        return Flight::Collision(p);
                    }
                    continue;
                }
            }
            if !t_exit.is_finite() {
                return Flight::Escape;
            }
            p += d * t_exit;
            match next {
                None => return Flight::Escape,
                Some(usize::MAX) => return Flight::Ground(p),
                Some(_) => p += d * EPS_KM,
            }
        }
        Flight::Escape
    }

    /// The majorant segments along the ray from `p` to where it leaves the
    /// atmosphere or meets the ground: (start, end, majorant) in km and
    /// km⁻¹, and the distance to the ground if it is met.
    pub(crate) fn segments(&self, mut p: DVec3, d: DVec3, majorant: &[f64], out: &mut Vec<(f64, f64, f64)>) -> Option<f64> {
        out.clear();
        let mut t = 0.0;
        for _ in 0..1_000_000 {
            let (s, t_exit, next) = self.shell_exit(p, d);
            if !t_exit.is_finite() {
                return None;
            }
            out.push((t, t + t_exit, majorant[s]));
            t += t_exit;
            p += d * t_exit;
            match next {
                None => return None,
                Some(usize::MAX) => return Some(t),
                Some(_) => {
                    p += d * EPS_KM;
                    t += EPS_KM;
                }
            }
        }
        None
    }

    /// Flight with a forced collision (a standard variance reduction for
    /// optically thin media): the collision distance is drawn from the
    /// majorant's free-path density truncated to the ray, q(t) = m(t)
    /// e^(−τ_m(t)) / (1 − e^(−τ_m)), and weighted by σ_t(t) T(0, t) / q(t)
    /// with T estimated by ratio tracking, so the estimate stays unbiased.
    /// When the ray meets the ground, the collision branch is taken with
    /// probability P = 1 − e^(−τ_m) (at least 0.1) and the ground branch
    /// otherwise, weighted by T(0, t_ground) / (1 − P). Returns the event
    /// and the weight.
    fn fly_forced(&self, p: DVec3, d: DVec3, guide: Option<&RayGuide>, rng: &mut Rng, segs: &mut Vec<(f64, f64, f64)>) -> (Flight, f64) {
        let ground = self.segments(p, d, &self.spectral.majorant, segs);
        match choose_forced(segs, ground, guide, rng) {
            Forced::Clear(None) => (Flight::Escape, 1.0),
            Forced::Clear(Some(t)) => (Flight::Ground(p + d * t), 1.0),
            Forced::Lost => (Flight::Escape, 0.0),
            Forced::Collision { t, pdf } => {
                let q = p + d * t;
                let sigma_t = self.spectral.sigma_t(self.medium, self.altitude(q));
                if sigma_t <= 0.0 {
                    return (Flight::Collision(q), 0.0);
                }
                let tr = self.transmittance_to(p, d, t, rng);
                (Flight::Collision(q), sigma_t * tr / pdf)
            }
            Forced::Ground { t, prob } => {
                let tr = self.transmittance_to(p, d, t, rng);
                (Flight::Ground(p + d * t), tr / prob)
            }
        }
    }

    /// Transmittance over the first `t_max` km of the ray: exact from the
    /// column table when there is one, else by ratio tracking (with Russian
    /// roulette below 0.1). Ratio tracking against a tight majorant is
    /// nearly a coin flip, 1 or ≈ 0, which made the forced-collision weight
    /// the largest source of noise in hazy skies.
    fn transmittance_to(&self, p: DVec3, d: DVec3, t_max: f64, rng: &mut Rng) -> f64 {
        if let Some(c) = self.columns {
            if let Some(path) = self.column_path(c, p, d, Some(t_max)) {
                return libm::exp(-c.path_optical_depth(&path, &self.spectral.extinction));
            }
        }
        self.ratio_track(p, d, t_max, rng)
    }

    /// Transmittance from `p` to space along `d` by ratio tracking (0 if
    /// the ray meets the ground), with Russian roulette below 0.1.
    pub fn transmittance(&self, p: DVec3, d: DVec3, rng: &mut Rng) -> f64 {
        self.ratio_track(p, d, f64::INFINITY, rng)
    }

    /// Ratio tracking (Novák et al. 2014) over the first `t_max` km of the
    /// ray, or to space when `t_max` is infinite; 0 if the ground comes
    /// first. Russian roulette below 0.1 keeps long, dark paths cheap.
    fn ratio_track(&self, p: DVec3, d: DVec3, t_max: f64, rng: &mut Rng) -> f64 {
        self.ratio_track_n(p, d, t_max, &self.spectral.majorant, |z| [self.spectral.sigma_t(self.medium, z)], rng)[0]
    }

    /// Ratio tracking of N extinction coefficients at once against one
    /// majorant per shell (the hero tracer's four bands share one); Russian
    /// roulette once the largest transmittance is below 0.1.
    pub(crate) fn ratio_track_n<const N: usize>(&self, mut p: DVec3, d: DVec3, t_max: f64, majorant: &[f64], sigma_t: impl Fn(f64) -> [f64; N], rng: &mut Rng) -> [f64; N] {
        let mut tr = [1.0; N];
        let mut remaining = t_max;
        for _ in 0..1_000_000 {
            let (s, t_exit, next) = self.shell_exit(p, d);
            // A target at the boundary itself (the ground point of a flight)
            // counts as reached: the tolerance absorbs the rounding of the
            // shell-by-shell walk.
            let target_first = remaining <= t_exit + 1e-7;
            let span = if target_first { remaining.min(t_exit) } else { t_exit };
            let m = majorant[s];
            let mut left = span;
            if m > 0.0 {
                loop {
                    let t = -ln(1.0 - rng.uniform()) / m;
                    if t >= left {
                        break;
                    }
                    left -= t;
                    p += d * t;
                    let st = sigma_t(self.altitude(p));
                    for j in 0..N {
                        tr[j] *= 1.0 - st[j] / m;
                    }
                    if tr.iter().cloned().fold(0.0, f64::max) < 0.1 {
                        if rng.uniform() < 0.5 {
                            return [0.0; N];
                        }
                        for v in &mut tr {
                            *v *= 2.0;
                        }
                    }
                }
            }
            if target_first || !t_exit.is_finite() {
                return tr;
            }
            match next {
                None => return tr,
                Some(usize::MAX) => return [0.0; N],
                Some(_) => {
                    p += d * (left + EPS_KM);
                    remaining -= t_exit + EPS_KM;
                }
            }
        }
        tr
    }

    /// Samples a direction from `phase` around `d`.
    pub(crate) fn sample_phase(&self, phase: &Phase, d: DVec3, rng: &mut Rng) -> DVec3 {
        sampling::sample_phase(phase, d, rng)
    }

    /// One path sample of the radiance arriving at `origin` from direction
    /// `-dir` (looking along `dir`), relative to the sun's irradiance.
    /// At a vertex in the Earth's shadow, adds to `l` the sunlight single-
    /// scattered toward `p` along the scattered direction `d` (throughput
    /// `beta`), estimated with one distance drawn from a coarse guide of
    /// the integrand ∫ T(0, t) Σ_i σ_s,i p_i(μ_sun) T_sun dt (see
    /// [`RayGuide::build_secondary`]). That is the expectation of the next
    /// vertex's next-event estimation toward the sun, which the caller then
    /// skips; the path goes on by analog flight, so no weight grows. At
    /// twilight the air above the shadow is lit but thin, and an analog
    /// flight from shadowed haze seldom ends there. Returns false (nothing
    /// estimated) when nothing on the ray is lit.
    pub(crate) fn skylight_along(&self, p: DVec3, d: DVec3, beta: f64, l: &mut f64, rng: &mut Rng) -> bool {
        let (t, pdf) = match RayGuide::sample_secondary(&[self], p, d, rng) {
            None => return false,
            Some((_, pdf)) if !(pdf > 0.0) => return true, // measure zero: the estimate is 0
            Some(s) => s,
        };
        let q = p + d * t;
        let z = self.altitude(q);
        let t_sun = self.transmittance_to_space(q, self.sun_dir, rng);
        if t_sun <= 0.0 {
            return true;
        }
        let (c, _) = self.scattering_at(z, d.dot(self.sun_dir));
        *l += beta * self.transmittance_to(p, d, t, rng) * c * t_sun / pdf;
        true
    }

    pub fn radiance(&self, origin: DVec3, dir: DVec3, rng: &mut Rng) -> f64 {
        let p = self.radiance_parts(origin, dir, None, rng);
        p.direct + p.scattered
    }

    /// [`radiance`](Self::radiance) split into the sun's disk seen directly
    /// (attenuated) and everything scattered or reflected.
    /// `guide`, if any, shapes the distance of the forced first collision
    /// (see [`RayGuide`]).
    pub fn radiance_parts(&self, origin: DVec3, dir: DVec3, guide: Option<&RayGuide>, rng: &mut Rng) -> PathSample<f64> {
        let mut direct = 0.0;
        let mut l = 0.0;
        let naive = self.estimator == Estimator::Naive;
        if !naive && self.sun_disk && dir.dot(self.sun_dir) >= self.sun_cos_half {
            direct = self.sun_disk_radiance * self.transmittance_to_space(origin, dir, rng);
        }
        let mut beta = 1.0;
        let mut p = origin;
        let mut d = dir;
        let mut segs = Vec::new();
        // Whether the last vertex estimated the sunlight scattered toward
        // it along `d` (see `skylight_along`).
        let mut sun_done = false;
        // The weight of the sun's estimate at the next vertex: below 1 where
        // the lobe technique of the last vertex also covers the direction
        // `d` (see `lobe_next_event`); 1 for the camera ray.
        let mut nee_weight = 1.0;
        let mut beta_ref = 1.0;
        let mut cut = false;
        for depth in 0..MAX_VERTICES {
            // Forced collisions on the camera ray only: later bounces fly
            // analogously, so escaping paths end instead of carrying ever
            // smaller weights into Russian roulette.
            let flight = if naive || depth > 0 {
                self.fly(p, d, rng)
            } else {
                let (f, w) = self.fly_forced(p, d, guide, rng, &mut segs);
                beta *= w;
                if beta <= 0.0 {
                    break;
                }
                f
            };
            match flight {
                Flight::Escape => {
                    if naive && (self.sun_disk || depth > 0) && d.dot(self.sun_dir) >= self.sun_cos_half {
                        l += beta * self.sun_disk_radiance;
                    }
                    break;
                }
                Flight::Ground(q) => {
                    let a = self.spectral.ground_albedo;
                    if a <= 0.0 {
                        break;
                    }
                    let n = self.up(q);
                    let q = q + n * EPS_KM;
                    let mut shadowed = true;
                    let mut t_sun = 0.0;
                    if !naive {
                        let cos_s = n.dot(self.sun_dir);
                        if cos_s > 0.0 {
                            t_sun = self.transmittance_to_space(q, self.sun_dir, rng);
                            shadowed = t_sun == 0.0;
                            l += beta * nee_weight * a / PI * cos_s * t_sun;
                        }
                    }
                    beta *= a;
                    let alpha = if naive { 0.0 } else { self.lobe_alpha_at(t_sun) };
                    let cosine_pdf = |w: DVec3| n.dot(w).max(0.0) / PI;
                    l += self.lobe_next_event(q, alpha, beta, cosine_pdf, rng);
                    let nd = cosine_hemisphere(n, rng);
                    let cos_o = n.dot(nd);
                    if cos_o <= 0.0 {
                        break;
                    }
                    nee_weight = self.continuation_weight(alpha, cos_o / PI, nd);
                    d = nd;
                    p = q;
                    sun_done = shadowed && self.skylight && self.skylight_along(p, d, beta, &mut l, rng);
                }
                Flight::Collision(q) => {
                    let z = self.altitude(q);
                    let sp = self.spectral;
                    let k = sp.extinction.len();
                    let mut sigma_t = 0.0;
                    let mut sigma_s = 0.0;
                    for i in 0..k {
                        let e = sp.extinction[i] * self.medium.density(i, z);
                        sigma_t += e;
                        sigma_s += e * sp.albedo[i];
                    }
                    if sigma_s <= 0.0 || sigma_t <= 0.0 {
                        break;
                    }
                    if naive {
                        // Analog absorption.
                        if rng.uniform() * sigma_t >= sigma_s {
                            break;
                        }
                    } else {
                        beta *= sigma_s / sigma_t;
                    }
                    // Pick the scatterer in proportion to its scattering coefficient.
                    let mut pick = rng.uniform() * sigma_s;
                    let mut which = k - 1;
                    for i in 0..k {
                        let s = sp.extinction[i] * self.medium.density(i, z) * sp.albedo[i];
                        if pick < s {
                            which = i;
                            break;
                        }
                        pick -= s;
                    }
                    let phase = &sp.phase[which];
                    let mut shadowed = false;
                    let mut t_sun = 0.0;
                    if !naive {
                        // Next-event estimation with the mixture of every
                        // scatterer's phase function (weighted by its
                        // scattering coefficient), not just the one picked
                        // to continue the path: removes the noise of that
                        // choice where a forward-peaked aerosol sees the sun.
                        // Skipped when the previous vertex estimated it.
                        let t = self.transmittance_to_space(q, self.sun_dir, rng);
                        t_sun = t;
                        shadowed = t == 0.0;
                        if t > 0.0 && !sun_done {
                            let (p_mix, _) = self.scattering_at(z, d.dot(self.sun_dir));
                            l += beta * nee_weight * p_mix / sigma_s * t;
                        }
                    }
                    // The direction's density as sampled: the mixture phase
                    // (the scatterer choice marginalised out).
                    let mixture_pdf = |w: DVec3| {
                        let (weighted, total) = self.scattering_at(z, d.dot(w));
                        if total > 0.0 {
                            weighted / total
                        } else {
                            0.0
                        }
                    };
                    let alpha = if naive { 0.0 } else { self.lobe_alpha_at(t_sun) };
                    l += self.lobe_next_event(q, alpha, beta, mixture_pdf, rng);
                    let nd = self.sample_phase(phase, d, rng);
                    nee_weight = if alpha > 0.0 { self.continuation_weight(alpha, mixture_pdf(nd), nd) } else { 1.0 };
                    d = nd;
                    p = q;
                    sun_done = shadowed && self.skylight && self.skylight_along(p, d, beta, &mut l, rng);
                }
            }
            if depth == 0 {
                beta_ref = beta;
            }
            if depth >= ROULETTE_FROM_DEPTH {
                let q = survival_probability(beta, beta_ref);
                if q < 1.0 {
                    if rng.uniform() >= q {
                        break;
                    }
                    beta /= q;
                }
            }
            cut = depth + 1 == MAX_VERTICES;
        }
        PathSample { direct: direct * self.spectral.sun_irradiance, scattered: l * self.spectral.sun_irradiance, cut }
    }
}

/// The decision of a forced flight (see `Tracer::fly_forced`), shared by
/// the single-band and the hero tracer.
pub(crate) enum Forced {
    /// No medium on the ray: it escapes (None) or reaches the ground at t.
    Clear(Option<f64>),
    /// The sampled collision fell on an empty segment: the path carries nothing.
    Lost,
    /// A collision at t, drawn with density `pdf` (the branch choice included).
    Collision { t: f64, pdf: f64 },
    /// The ground at t, chosen with probability `prob`.
    Ground { t: f64, prob: f64 },
}

/// Chooses between a forced collision, drawn from the majorant free-path
/// density truncated to the ray, q(t) = m(t) e^(−τ_m(t)) / (1 − e^(−τ_m)),
/// and the ground (when the ray meets it), taking the collision branch with
/// probability P = 1 − e^(−τ_m) clamped to [0.1, 0.9].
pub(crate) fn choose_forced(segs: &[(f64, f64, f64)], ground: Option<f64>, guide: Option<&RayGuide>, rng: &mut Rng) -> Forced {
    let tau_m: f64 = segs.iter().map(|(a, b, m)| (b - a) * m).sum();
    if tau_m <= 0.0 {
        return Forced::Clear(ground);
    }
    let p_coll = match ground {
        None => 1.0,
        Some(_) => (-libm::expm1(-tau_m)).clamp(0.1, 0.9),
    };
    if let Some(t) = ground {
        if rng.uniform() >= p_coll {
            return Forced::Ground { t, prob: 1.0 - p_coll };
        }
    }
    let one_minus = -libm::expm1(-tau_m);
    // The majorant's density q(t) = m(t) e^(−τ_m(t)) / (1 − e^(−τ_m)) at t.
    let majorant_pdf = |t: f64| -> f64 {
        let mut acc = 0.0;
        for &(a, b, m) in segs {
            if t < a {
                return 0.0; // in a gap between shells
            }
            if t < b {
                return m * libm::exp(-(acc + (t - a) * m)) / one_minus;
            }
            acc += (b - a) * m;
        }
        0.0
    };
    if let Some(g) = guide {
        let alpha = super::guide::GUIDE_PROBABILITY;
        let t = if rng.uniform() < alpha {
            g.sample(rng.uniform())
        } else {
            match sample_majorant(segs, one_minus, rng) {
                Some(t) => t,
                None => return Forced::Lost,
            }
        };
        let end = segs.last().map_or(0.0, |s| s.1);
        if t >= end || ground.is_some_and(|tg| t >= tg) {
            return Forced::Lost;
        }
        let pdf = (1.0 - alpha) * majorant_pdf(t) + alpha * g.pdf(t);
        if !(pdf > 0.0) {
            return Forced::Lost;
        }
        return Forced::Collision { t, pdf: pdf * p_coll };
    }
    match sample_majorant(segs, one_minus, rng) {
        Some(t) => Forced::Collision { t, pdf: majorant_pdf(t) * p_coll },
        None => Forced::Lost,
    }
}

/// A distance from the majorant's free-path density truncated to the ray:
/// τ* from the truncated exponential on [0, τ_m), then located in its shell.
fn sample_majorant(segs: &[(f64, f64, f64)], one_minus: f64, rng: &mut Rng) -> Option<f64> {
    let tau_star = -libm::log1p(-rng.uniform() * one_minus);
    let mut acc = 0.0;
    for &(a, b, m) in segs {
        let dt = (b - a) * m;
        if m > 0.0 && acc + dt > tau_star {
            return Some(a + (tau_star - acc) / m);
        }
        acc += dt;
    }
    None
}
