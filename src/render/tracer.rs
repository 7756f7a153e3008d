//! One band's view of the prepared scene for the path-tracing kernel
//! (`kernel`): the medium, the optics at one wavelength, the sun (a
//! parallel light with a visible disk for camera rays), the sun-lobe
//! technique's component, transmittances (exact from the column table where
//! the medium allows, else ratio tracking against the shell majorants:
//! Novák, Selle and Jarosz 2014), and the estimator's switches.
//!
//! Radiance is relative to `Spectral::sun_irradiance` (pass 1 to get the
//! radiance per unit solar irradiance, sr⁻¹). Transcendental functions come
//! from `libm` (pure Rust), so the kernel rounds the same on every platform.

use super::fog::Fog;
use super::guide::RayGuide;
use super::kernel::{Kernel, Scratch};
use super::medium::{ColumnPath, ColumnTable, Medium, Spectral};
use super::rng::Rng;
pub use super::sampling::{around, sample_hg};
use super::segments::Boundary;
use crate::atmosphere::Geometry;
use glam::DVec3;
use std::f64::consts::PI;

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
    /// Whether the caller computes the sunlight scattered once toward the
    /// camera (or reflected once by the ground) itself, by quadrature
    /// (`single`): the first vertex then skips its next-event estimate
    /// toward the sun, and paths estimate only light scattered twice or
    /// more.
    pub skip_single: bool,
    /// Global fog instead of the sky (see `fog`): the camera ray's first
    /// collision only within the fog's reach, the object and the ground
    /// at its end black.
    pub fog: Option<Fog>,
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

impl<'a> Tracer<'a> {
    pub fn new(
        medium: &'a Medium,
        spectral: &'a Spectral,
        sun_dir: DVec3,
        sun_angular_diameter_deg: f64,
        estimator: Estimator,
    ) -> Tracer<'a> {
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
            skip_single: false,
            fog: None,
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

    pub fn with_columns(mut self, columns: &'a ColumnTable) -> Self {
        self.columns = Some(columns);
        self
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

    /// See [`Tracer::skip_single`].
    pub fn with_single_skipped(mut self, skip: bool) -> Self {
        self.skip_single = skip;
        self
    }

    /// See [`Tracer::fog`].
    pub fn with_fog(mut self, fog: Option<Fog>) -> Self {
        self.fog = fog;
        self
    }

    pub fn with_sun_disk(mut self, visible: bool) -> Self {
        self.sun_disk = visible;
        self
    }

    /// A point at `altitude_km` above the origin of the horizontal plane
    /// (at least 1 mm, so rays looking down meet the ground ahead of them).
    pub fn observer(&self, altitude_km: f64) -> DVec3 {
        self.medium.observer(altitude_km)
    }

    #[inline]
    pub(crate) fn altitude(&self, p: DVec3) -> f64 {
        self.medium.altitude(p)
    }

    #[inline]
    pub(crate) fn up(&self, p: DVec3) -> DVec3 {
        self.medium.up(p)
    }

    /// Transmittance from `p` to space along `d` by ratio tracking (0 if
    /// the ray meets the ground), with Russian roulette below 0.1.
    pub fn transmittance(&self, p: DVec3, d: DVec3, rng: &mut Rng) -> f64 {
        self.ratio_track_n(
            p,
            d,
            f64::INFINITY,
            &self.spectral.majorant,
            |z| [self.spectral.sigma_t(self.medium, z)],
            rng,
        )[0]
    }

    /// Ratio tracking (Novák et al. 2014) of N extinction coefficients at
    /// once against one majorant per shell (a hero path's bands share one)
    /// over the first `t_max` km of the ray, or to space when `t_max` is
    /// infinite; 0 if the ground comes first. Russian roulette once the
    /// largest transmittance is below 0.1 keeps long, dark paths cheap.
    pub(crate) fn ratio_track_n<const N: usize>(
        &self,
        p: DVec3,
        d: DVec3,
        t_max: f64,
        majorant: &[f64],
        sigma_t: impl Fn(f64) -> [f64; N],
        rng: &mut Rng,
    ) -> [f64; N] {
        let mut tr = [1.0; N];
        for seg in self.medium.walk(p, d) {
            // A target at the boundary itself (the ground point of a flight)
            // counts as reached: the tolerance absorbs the rounding of the
            // shell-by-shell walk.
            let target_first = t_max <= seg.end_km + 1e-7;
            let end = if target_first { t_max.min(seg.end_km) } else { seg.end_km };
            let m = majorant[seg.shell];
            if m > 0.0 {
                let mut t = seg.start_km;
                loop {
                    t += -libm::log(1.0 - rng.uniform()) / m;
                    if !(t < end) {
                        break;
                    }
                    let st = sigma_t(self.medium.altitude(p + d * t));
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
            if target_first {
                return tr;
            }
            match seg.next {
                Boundary::Shell(_) => {}
                Boundary::Ground => return [0.0; N],
                Boundary::Space => return tr,
            }
        }
        tr
    }

    /// One path sample of the radiance arriving at `origin` from direction
    /// `-dir` (looking along `dir`), relative to the sun's irradiance, by
    /// the one-band kernel (see [`Kernel::radiance`]).
    pub fn radiance(&self, origin: DVec3, dir: DVec3, rng: &mut Rng) -> f64 {
        let p = self.radiance_parts(origin, dir, None, rng);
        p.direct + p.scattered
    }

    /// [`radiance`](Self::radiance) split into the sun's disk seen directly
    /// (attenuated) and everything scattered or reflected. `guide`, if any,
    /// shapes the distance of the forced first collision (see
    /// [`RayGuide`]). A convenience for tests: renders hold a [`Scratch`]
    /// per pixel and call the kernel.
    pub fn radiance_parts(
        &self,
        origin: DVec3,
        dir: DVec3,
        guide: Option<&RayGuide>,
        rng: &mut Rng,
    ) -> PathSample<f64> {
        let p = Kernel::single(self).radiance(origin, dir, guide, &mut Scratch::default(), rng);
        PathSample { direct: p.direct[0], scattered: p.scattered[0], cut: p.cut }
    }
}
