//! The path-tracing kernel, generic over the number of wavelengths a path
//! carries: 1 for the single-band strategies and the spectral lines, 4 for
//! hero-wavelength sampling (see `hero`). One set of vertex logic for all:
//! free flights by delta tracking against piecewise-constant shell
//! majorants (Novák, Selle and Jarosz 2014), a forced first collision,
//! next-event estimation toward the sun as parallel light (the talk's
//! "sunlight is approximated as a parallel light"), the sun lobe as a
//! second technique of that estimate, the skylight estimate in the Earth's
//! shadow, a Lambertian ground, and Russian roulette on the throughput.
//!
//! Band 0 makes every decision of the path (it is the hero). Each band j
//! carries the path's throughput `f[j]` (the measurement contribution
//! without its sampling densities) and `pk[j]`, the path's density had band
//! j made the decisions; band j's estimate is f_j / Σ_k pk_k, the balance
//! heuristic over the N ways the same set of bands could have been drawn
//! (Wilkie et al. 2014; the null-scattering path integral of Miller,
//! Georgiev and Jarosz 2019 gives the densities of null and real
//! collisions). With N = 1 this is the ordinary estimator f / p: every
//! factor both carry cancels, and the kernel skips them.
//!
//! Radiance is relative to `Spectral::sun_irradiance` until the end, where
//! each band's estimate is scaled by it. Transcendental functions come from
//! `libm` (pure Rust), so the kernel rounds the same on every platform.

use super::guide::{RayGuide, SecondaryScratch};
use super::medium::depth_of_columns;
use super::rng::Rng;
use super::sampling::{cosine_hemisphere, pick_weighted, sample_phase};
use super::segments::{Boundary, MajorantSegment, EPS_KM};
use super::sky_guide::SkylightGuide;
use super::tracer::{survival_probability, Estimator, PathSample, Tracer, MAX_VERTICES, ROULETTE_FROM_DEPTH};
use glam::DVec3;
use std::f64::consts::PI;

/// Where a flight ended.
#[derive(Clone, Copy)]
enum Event {
    Escape,
    Collision(DVec3),
    Ground(DVec3),
    /// A forced collision fell where the medium is empty: nothing carried.
    Lost,
}

/// Buffers a path reuses, so that no sample allocates: one per thread (or
/// per pixel), passed to [`Kernel::radiance`].
#[derive(Default)]
pub struct Scratch {
    segments: Vec<MajorantSegment>,
    secondary: SecondaryScratch,
}

/// N tracers of one medium, at the N bands a path carries (band 0 decides),
/// with the majorant they share.
pub struct Kernel<'a, const N: usize> {
    pub t: [&'a Tracer<'a>; N],
    /// The shared majorant per shell: for N > 1 the largest of the bands'
    /// (see `hero::shared_majorant_into`), so tentative collisions are
    /// common to all of them.
    majorant: &'a [f64],
    /// Directions toward the lit air for vertices in the Earth's shadow
    /// (see `sky_guide` and [`Kernel::guided_skylight`]).
    sky_guide: Option<&'a SkylightGuide>,
    /// [`SKYLIGHT_MAX_EXTINCTION_PER_KM`], or another value in a test.
    skylight_max_extinction_per_km: f64,
}

/// The largest sum of the columns to space (band 0's optical depth) whose
/// difference gives a segment's transmittance; beyond, the segment is
/// integrated directly (see `Kernel::transmittance`). The columns'
/// interpolation error, about 1e-4 of a column, then stays below 1e-4 in
/// the segment's optical depth.
const MAX_DIFFERENCED_COLUMN_TAU: f64 = 1.0;

/// Nodes and weights of the 4-point Gauss–Legendre rule on [−1, 1]
/// (Abramowitz & Stegun 1964, table 25.4).
const GAUSS_LEGENDRE_4: [(f64, f64); 4] = [
    (-0.861_136_311_594_052_6, 0.347_854_845_137_453_9),
    (-0.339_981_043_584_856_3, 0.652_145_154_862_546_1),
    (0.339_981_043_584_856_3, 0.652_145_154_862_546_1),
    (0.861_136_311_594_052_6, 0.347_854_845_137_453_9),
];

/// The probability of drawing a second skylight direction from the
/// [`SkylightGuide`] at a vertex in the Earth's shadow.
pub const SKY_GUIDE_PROBABILITY: f64 = 0.5;

impl<'a> Kernel<'a, 1> {
    /// The kernel of one band, with its own majorant.
    pub fn single(t: &'a Tracer<'a>) -> Kernel<'a, 1> {
        Kernel { t: [t], majorant: &t.spectral.majorant, sky_guide: None, skylight_max_extinction_per_km: SKYLIGHT_MAX_EXTINCTION_PER_KM }
    }
}

/// The skylight estimates at a shadowed vertex ([`Kernel::skylight_along`]
/// and the twilight guide's) are made only where every band's extinction
/// is at most this, km⁻¹: a free path of a kilometre or more. They find
/// the lit air along a whole ray (the secondary guide evaluates the
/// single-scattering integrand at 33 points of it, two column paths each),
/// which pays where an analog flight seldom ends there; inside a cloud the
/// next vertex is tens of metres away and the lit air beyond the cloud's
/// edge is out of reach, and a vertex there counts as shadowed whenever
/// the sun's grazing path through the layer underflows to 0 (with the sun
/// low, not only at twilight). Both choices are unbiased (the next vertex
/// then makes its own sun estimate), so this only moves cost. Clear air
/// is about 0.01 km⁻¹ at 550 nm, the hazed boundary layer 0.2, the cloud
/// layers 0.25 (cloudy0) to 30 (cloudy5).
const SKYLIGHT_MAX_EXTINCTION_PER_KM: f64 = 1.0;

#[inline]
fn sum<const N: usize>(a: &[f64; N]) -> f64 {
    a.iter().sum()
}

/// The densities' sum for the sun estimate at a vertex reached along a
/// continuation direction with factors `r` (see `continuation_factors`).
#[inline]
fn nee_den<const N: usize>(pk: &[f64; N], r: &[f64; N]) -> f64 {
    (0..N).map(|k| pk[k] * r[k]).sum()
}

impl<'a, const N: usize> Kernel<'a, N> {
    /// The kernel of N bands with a shared `majorant` (at least each band's
    /// own in every shell).
    pub fn new(t: [&'a Tracer<'a>; N], majorant: &'a [f64]) -> Kernel<'a, N> {
        Kernel { t, majorant, sky_guide: None, skylight_max_extinction_per_km: SKYLIGHT_MAX_EXTINCTION_PER_KM }
    }

    /// With a guide toward the lit air for shadowed vertices.
    pub fn with_sky_guide(mut self, guide: Option<&'a SkylightGuide>) -> Self {
        self.sky_guide = guide;
        self
    }

    /// The probability of the guided skylight technique at a vertex (see
    /// [`Kernel::guided_skylight`]): [`SKY_GUIDE_PROBABILITY`] in the
    /// Earth's shadow with a guide, else 0.
    #[inline]
    /// The skylight estimates everywhere in the shadow, whatever the
    /// extinction (to test that the limit changes only the cost).
    #[cfg(test)]
    pub(crate) fn with_skylight_everywhere(mut self) -> Self {
        self.skylight_max_extinction_per_km = f64::INFINITY;
        self
    }

    fn sky_guide_beta(&self, shadowed: bool) -> f64 {
        if shadowed && self.t[0].skylight && self.sky_guide.is_some() {
            SKY_GUIDE_PROBABILITY
        } else {
            0.0
        }
    }

    /// At a vertex `x` in the Earth's shadow, with probability β, the
    /// skylight estimate ([`Kernel::skylight_along`]) along a second
    /// direction drawn from the [`SkylightGuide`] toward the lit air. It
    /// and the continuation's own estimate are combined by the balance
    /// heuristic over the two direction densities, local(w) + β guide(w)
    /// (Veach 1997, §9.2, with expected sample counts 1 and β), as the sun
    /// lobe's technique is: this one adds the guided estimate, and the
    /// continuation's divides by the factors of [`Kernel::guide_factors`].
    fn guided_skylight(&self, x: DVec3, beta: f64, f: &[f64; N], pk: &[f64; N], local: impl Fn(DVec3) -> ([f64; N], [f64; N]), res: &mut [f64; N], scratch: &mut Scratch, rng: &mut Rng) {
        let Some(g) = self.sky_guide else { return };
        if !(beta > 0.0) || rng.uniform() >= beta {
            return;
        }
        let medium = self.t[0].medium;
        let (w, pdf) = g.sample(medium.up(x), medium.altitude(x), rng);
        let (factor, density) = local(w);
        if factor.iter().all(|v| !(*v > 0.0)) {
            return;
        }
        let fl: [f64; N] = std::array::from_fn(|k| f[k] * factor[k]);
        let pl: [f64; N] = std::array::from_fn(|k| pk[k] * (density[k] + beta * pdf));
        self.skylight_along(x, w, &fl, &pl, res, scratch, rng);
    }

    /// The factors (local_k + β guide) / local_k of the continuation
    /// direction `w` at `x` for its skylight estimate (1 where β = 0).
    #[inline]
    fn guide_factors(&self, x: DVec3, beta: f64, local: &[f64; N], w: DVec3) -> [f64; N] {
        match self.sky_guide {
            Some(g) if beta > 0.0 => {
                let medium = self.t[0].medium;
                let p = beta * g.pdf(medium.up(x), medium.altitude(x), w);
                std::array::from_fn(|k| if local[k] > 0.0 { 1.0 + p / local[k] } else { 1.0 })
            }
            _ => [1.0; N],
        }
    }

    #[inline]
    fn sigma_t(&self, z: f64) -> [f64; N] {
        let m = self.t[0].medium;
        std::array::from_fn(|j| self.t[j].spectral.sigma_t(m, z))
    }

    #[inline]
    fn sigma_s_i(&self, j: usize, i: usize, z: f64) -> f64 {
        let sp = self.t[j].spectral;
        sp.extinction[i] * self.t[0].medium.density(i, z) * sp.albedo[i]
    }

    #[inline]
    fn sigma_s(&self, z: f64) -> [f64; N] {
        std::array::from_fn(|j| (0..self.t[j].spectral.extinction.len()).map(|i| self.sigma_s_i(j, i, z)).sum())
    }

    /// Σ_i σ_s,i(z) p_i(μ) per band: the f factor of a scattered direction.
    #[inline]
    fn scattering_toward(&self, z: f64, mu: f64) -> [f64; N] {
        std::array::from_fn(|k| self.t[k].scattering_at(z, mu).0)
    }

    /// The bands' transmittances over the first `t_max` km of the ray
    /// (infinite: to space, 0 if it meets the ground): exact from the
    /// column table when there is one (one column path for all bands),
    /// else by ratio tracking of all of them at once.
    ///
    /// A segment whose columns to space are long (near the horizon, or
    /// through a cloud) has an optical depth that is the small difference
    /// of large columns, and their interpolation's error (about 1e-4 of a
    /// column) would dominate it: the view transmittance of a level ray in
    /// the hazed sky came out 0.3 % high over 20 km, a bias of the global
    /// fog near the camera. Where the columns differenced exceed
    /// [`MAX_DIFFERENCED_COLUMN_TAU`], the segment's optical depth is
    /// integrated directly (`optical_depth_along`).
    fn transmittance(&self, p: DVec3, d: DVec3, t_max: f64, rng: &mut Rng) -> [f64; N] {
        let h = self.t[0];
        if let Some(c) = h.columns {
            let limit = t_max.is_finite().then_some(t_max);
            match h.column_path(c, p, d, limit) {
                Some(path) => {
                    // Band 0's columns: the conditioning test and its own depth.
                    let (add, sub) = c.path_columns(&path, &h.spectral.extinction);
                    if limit.is_some() && add > MAX_DIFFERENCED_COLUMN_TAU {
                        let tau = self.optical_depth_along(p, d, t_max);
                        return std::array::from_fn(|k| libm::exp(-tau[k]));
                    }
                    return std::array::from_fn(|k| libm::exp(-if k == 0 { depth_of_columns(add, sub) } else { c.path_optical_depth(&path, &self.t[k].spectral.extinction) }));
                }
                None if limit.is_none() => return [0.0; N],
                None => {}
            }
        }
        h.ratio_track_n(p, d, t_max, self.majorant, |z| self.sigma_t(z), rng)
    }

    /// The bands' optical depths over the first `t_max` km of the ray (which
    /// must not cross the ground), by 4-point Gauss–Legendre quadrature
    /// in each shell it crosses (Abramowitz & Stegun 1964, table 25.4):
    /// within a shell the densities are smooth (the profiles' kinks are
    /// shell edges) and change by at most a few tens of per cent (shells are
    /// 250 m thick below 20 km), where the rule's error is below 1e-8.
    fn optical_depth_along(&self, p: DVec3, d: DVec3, t_max: f64) -> [f64; N] {
        let medium = self.t[0].medium;
        let mut tau = [0.0; N];
        for seg in medium.walk(p, d) {
            let (a, b) = (seg.start_km, seg.end_km.min(t_max));
            if b > a {
                let (mid, half) = (0.5 * (a + b), 0.5 * (b - a));
                for (x, w) in GAUSS_LEGENDRE_4 {
                    let st = self.sigma_t(medium.altitude(p + d * (mid + half * x)));
                    for k in 0..N {
                        tau[k] += w * half * st[k];
                    }
                }
            }
            if seg.end_km >= t_max || !matches!(seg.next, Boundary::Shell(_)) {
                break;
            }
        }
        tau
    }

    /// The bands' transmittances from `p` to the sun.
    #[inline]
    fn sun_transmittance(&self, p: DVec3, rng: &mut Rng) -> [f64; N] {
        self.transmittance(p, self.t[0].sun_dir, f64::INFINITY, rng)
    }

    /// Delta tracking from `p` along `d` against the shared majorant, one
    /// shell segment at a time: null and real decisions are made with band
    /// 0's σ_t and enter every band's `f` and `pk` (the tentative-point
    /// density is common to all and cancels).
    fn fly(&self, p: DVec3, d: DVec3, f: &mut [f64; N], pk: &mut [f64; N], rng: &mut Rng) -> Event {
        let medium = self.t[0].medium;
        for seg in medium.walk(p, d) {
            let m = self.majorant[seg.shell];
            if m > 0.0 {
                let mut t = seg.start_km;
                loop {
                    t += -libm::log(1.0 - rng.uniform()) / m;
                    if !(t < seg.end_km) {
                        break;
                    }
                    let q = p + d * t;
                    let st = self.sigma_t(medium.altitude(q));
                    if rng.uniform() * m < st[0] {
                        for k in 0..N {
                            pk[k] *= st[k] / m;
                            f[k] /= m;
                        }
                        return Event::Collision(q);
                    }
                    for k in 0..N {
                        let null = 1.0 - st[k] / m;
                        pk[k] *= null;
                        f[k] *= null;
                    }
                }
            }
            match seg.next {
                Boundary::Shell(_) => {}
                Boundary::Ground => return Event::Ground(p + d * seg.end_km),
                Boundary::Space => return Event::Escape,
            }
        }
        Event::Escape
    }

    /// A flight with a forced collision (a standard variance reduction for
    /// optically thin media; see [`choose_forced`]): the collision is drawn
    /// from the majorant's free-path density truncated to the ray, or the
    /// guide's mixture, and weighted by T(0, t) over its density (σ_t
    /// cancels against the collision's own density); the ground branch by
    /// T(0, t_ground) over its probability.
    ///
    /// For global fog (`Tracer::fog`) the collision is forced within the
    /// fog's reach, and a flight that reaches the object or the ground
    /// carries nothing (both are black): the segments end at the reach and
    /// the ground is no branch of its own.
    fn fly_forced(&self, p: DVec3, d: DVec3, guide: Option<&RayGuide>, f: &mut [f64; N], pk: &mut [f64; N], scratch: &mut Scratch, rng: &mut Rng) -> Event {
        let medium = self.t[0].medium;
        let mut ground_t = medium.majorant_segments(p, d, self.majorant, &mut scratch.segments);
        if let Some(fog) = &self.t[0].fog {
            let reach = fog.reach_km(medium, p, d);
            scratch.segments.retain(|s| s.start_km < reach);
            if let Some(last) = scratch.segments.last_mut() {
                last.end_km = last.end_km.min(reach);
            }
            ground_t = None;
        }
        let (t, density, collision) = match choose_forced(&scratch.segments, ground_t, guide, rng) {
            Forced::Clear(None) => return Event::Escape,
            Forced::Clear(Some(t)) => return Event::Ground(p + d * t),
            Forced::Lost => return Event::Lost,
            Forced::Collision { t, pdf } => (t, pdf, true),
            Forced::Ground { t, prob } => (t, prob, false),
        };
        let q = p + d * t;
        let tr = self.transmittance(p, d, t, rng);
        for k in 0..N {
            f[k] *= tr[k];
            pk[k] *= density;
        }
        if collision {
            Event::Collision(q)
        } else {
            Event::Ground(q)
        }
    }

    /// The sun's next-event estimate of every band at the end of a flight
    /// along `d` with throughput `f` (added to `res` over the densities'
    /// sum `den`).
    fn sun_estimate(&self, event: Event, d: DVec3, f: &[f64; N], den: f64, res: &mut [f64; N], rng: &mut Rng) {
        let h = self.t[0];
        match event {
            Event::Escape | Event::Lost => {}
            Event::Collision(y) => {
                let z = h.medium.altitude(y);
                let t_sun = self.sun_transmittance(y, rng);
                if t_sun.iter().all(|t| !(*t > 0.0)) {
                    return;
                }
                let c = self.scattering_toward(z, d.dot(h.sun_dir));
                for j in 0..N {
                    if t_sun[j] > 0.0 {
                        res[j] += f[j] * c[j] * t_sun[j] / den;
                    }
                }
            }
            Event::Ground(g) => {
                let n = h.medium.up(g);
                let cos_s = n.dot(h.sun_dir);
                if cos_s > 0.0 {
                    let t_sun = self.sun_transmittance(g + n * EPS_KM, rng);
                    for j in 0..N {
                        res[j] += f[j] * self.t[j].spectral.ground_albedo / PI * cos_s * t_sun[j] / den;
                    }
                }
            }
        }
    }

    /// The lobe technique of the next vertex's sun estimate (see
    /// `Tracer::lobe_alpha_at`): taken with band 0's probability
    /// `alphas[0]`, a direction from band 0's lobe (the most forward-peaked
    /// component's phase function centred on the sun) and a flight along
    /// it. The sunlight single-scattered toward the vertex along ω is
    /// ∫ f(ω) g(ω) dω, f the vertex's scattering (density as sampled:
    /// `local`) and g the next vertex's sun estimate; where a forward peak
    /// (p(1) ~ 10³ sr⁻¹) sees the sun, directions drawn from f seldom fall
    /// in it and those that do carry huge estimates. The two techniques,
    /// the path's own continuation (always) and this one (with probability
    /// α), are combined by the balance heuristic with their expected sample
    /// counts (Veach 1997, §9.2): band k's density of a direction is its
    /// local density plus α_k times its own lobe density. The path itself
    /// is not changed: its throughput never carries a lobe weight, so
    /// Russian roulette does not kill paths that a lobe direction would
    /// have weighted down. `local(w)` gives each band's f factor and local
    /// density of a direction w.
    fn lobe_next_event(&self, x: DVec3, alphas: &[f64; N], f: &[f64; N], pk: &[f64; N], local: impl Fn(DVec3) -> ([f64; N], [f64; N]), res: &mut [f64; N], rng: &mut Rng) {
        let h = self.t[0];
        let Some((i, _)) = h.lobe else { return };
        if !(alphas[0] > 0.0) || rng.uniform() >= alphas[0] {
            return;
        }
        let w = sample_phase(&h.spectral.phase[i], h.sun_dir, rng);
        let (factor, density) = local(w);
        if factor.iter().all(|v| !(*v > 0.0)) {
            return;
        }
        let mut fl: [f64; N] = std::array::from_fn(|k| f[k] * factor[k]);
        let mut pl: [f64; N] = std::array::from_fn(|k| pk[k] * (density[k] + alphas[k] * self.t[k].lobe_pdf(w)));
        let event = self.fly(x, w, &mut fl, &mut pl, rng);
        let den = sum(&pl);
        if den > 0.0 {
            self.sun_estimate(event, w, &fl, den, res, rng);
        }
    }

    /// The factors r_k = (local_k + α_k lobe_k) / local_k of a continuation
    /// direction: the next vertex's sun estimate divides by Σ_k pk_k r_k
    /// (see [`Kernel::lobe_next_event`]).
    #[inline]
    fn continuation_factors(&self, alphas: &[f64; N], density: &[f64; N], w: DVec3) -> [f64; N] {
        std::array::from_fn(|k| if alphas[k] > 0.0 && density[k] > 0.0 { 1.0 + alphas[k] * self.t[k].lobe_pdf(w) / density[k] } else { 1.0 })
    }

    /// At a vertex in the Earth's shadow, the sunlight single-scattered
    /// toward `p` along the scattered direction `d`, estimated by one
    /// distance drawn from a coarse guide of the integrand (see
    /// `guide::sample_secondary`) instead of by the analog flight's
    /// collision: at twilight the air above the shadow is lit but thin, and
    /// an analog flight from shadowed haze seldom ends there. The estimate
    /// has the expectation of the next vertex's next-event estimation
    /// toward the sun (∫ T(0, t) Σ_i σ_s,i p_i(μ_sun) T_sun dt), which that
    /// vertex then skips; the path itself goes on by analog flight, so no
    /// weight grows. The guide is the same whichever band decides, so the
    /// balance heuristic only gains the common factor 1 / g(t). Returns
    /// false (nothing estimated) when nothing on the ray is lit.
    fn skylight_along(&self, p: DVec3, d: DVec3, f: &[f64; N], pk: &[f64; N], res: &mut [f64; N], scratch: &mut Scratch, rng: &mut Rng) -> bool {
        let h = self.t[0];
        let (t, pdf) = match RayGuide::sample_secondary(&self.t, p, d, &mut scratch.secondary, rng) {
            None => return false,
            Some((_, pdf)) if !(pdf > 0.0) => return true, // measure zero: the estimate is 0
            Some(s) => s,
        };
        let q = p + d * t;
        let z = h.medium.altitude(q);
        let t_sun = self.sun_transmittance(q, rng);
        if t_sun.iter().all(|t| !(*t > 0.0)) {
            return true;
        }
        let tr = self.transmittance(p, d, t, rng);
        let c = self.scattering_toward(z, d.dot(h.sun_dir));
        let den = sum(pk) * pdf;
        for j in 0..N {
            if f[j] != 0.0 && t_sun[j] > 0.0 {
                res[j] += f[j] * tr[j] * c[j] * t_sun[j] / den;
            }
        }
        true
    }

    /// One path sample of the radiance arriving at `origin` from direction
    /// `-dir` (looking along `dir`), per band: each band's estimate, MIS-
    /// weighted over the N ways its set could have been drawn (not yet
    /// divided by the band's own selection probability), times its sun
    /// irradiance; split into the directly seen sun and the rest. `guide`,
    /// if any, shapes the distance of the forced first collision.
    pub fn radiance(&self, origin: DVec3, dir: DVec3, guide: Option<&RayGuide>, scratch: &mut Scratch, rng: &mut Rng) -> PathSample<[f64; N]> {
        let h = self.t[0];
        let medium = h.medium;
        let naive = h.estimator == Estimator::Naive;
        let mut direct = [0.0; N];
        let mut res = [0.0; N];
        let mut f = [1.0; N];
        // The path's density had band k decided (the uniform 1/N of the
        // hero choice cancels in the balance heuristic).
        let mut pk = [1.0; N];
        if !naive && h.sun_disk && dir.dot(h.sun_dir) >= h.sun_cos_half {
            let tr = self.transmittance(origin, dir, f64::INFINITY, rng);
            let den = sum(&pk);
            for j in 0..N {
                direct[j] = f[j] * self.t[j].sun_disk_radiance * tr[j] / den;
            }
        }
        // Russian roulette's reference: the throughput ratio after the first vertex.
        let mut s_ref = 1.0;
        let mut cut = false;
        let mut p = origin;
        let mut d = dir;
        // Whether the sunlight single-scattered toward the last vertex along
        // `d` has been estimated there (see `skylight_along`): the vertex the
        // flight finds then skips its next-event estimation toward the sun.
        let mut sun_done = false;
        // The factors r_k of the direction `d` for the next vertex's sun
        // estimate (see `continuation_factors`); 1 for the camera ray.
        let mut nee_r = [1.0; N];
        for depth in 0..MAX_VERTICES {
            // Forced collisions on the camera ray only: later bounces fly
            // analogously, so escaping paths end instead of carrying ever
            // smaller weights into Russian roulette.
            let event = if depth == 0 && !naive { self.fly_forced(p, d, guide, &mut f, &mut pk, scratch, rng) } else { self.fly(p, d, &mut f, &mut pk, rng) };
            match event {
                Event::Lost => break,
                Event::Escape => {
                    // The naive estimator's only light: the sun's disk seen
                    // by an escaping path.
                    if naive && (h.sun_disk || depth > 0) && d.dot(h.sun_dir) >= h.sun_cos_half {
                        let den = sum(&pk);
                        for j in 0..N {
                            res[j] += f[j] * self.t[j].sun_disk_radiance / den;
                        }
                    }
                    break;
                }
                Event::Ground(g) => {
                    let n = medium.up(g);
                    let g = g + n * EPS_KM;
                    let cos_s = n.dot(h.sun_dir);
                    let mut shadowed = true;
                    let mut t_sun = [0.0; N];
                    if !naive && cos_s > 0.0 {
                        let den = nee_den(&pk, &nee_r);
                        t_sun = self.sun_transmittance(g, rng);
                        shadowed = t_sun.iter().all(|&t| t == 0.0);
                        if !(depth == 0 && h.skip_single) {
                            for j in 0..N {
                                res[j] += f[j] * self.t[j].spectral.ground_albedo / PI * cos_s * t_sun[j] / den;
                            }
                        }
                    }
                    for j in 0..N {
                        f[j] *= self.t[j].spectral.ground_albedo;
                    }
                    if f.iter().all(|v| !(*v > 0.0)) {
                        break;
                    }
                    // Cosine-weighted, and the sun lobe as a separate
                    // technique of the next vertex's sun estimate. The
                    // cosine density is the same in every band, so f and pk
                    // need not carry it.
                    let alphas: [f64; N] = std::array::from_fn(|k| self.t[k].lobe_alpha_at(t_sun[k]));
                    let cosine = |w: DVec3| {
                        let c = n.dot(w).max(0.0) / PI;
                        ([c; N], [c; N])
                    };
                    self.lobe_next_event(g, &alphas, &f, &pk, cosine, &mut res, rng);
                    let beta = self.sky_guide_beta(shadowed);
                    self.guided_skylight(g, beta, &f, &pk, cosine, &mut res, scratch, rng);
                    let nd = cosine_hemisphere(n, rng);
                    let cos_o = n.dot(nd);
                    if cos_o <= 0.0 {
                        break;
                    }
                    nee_r = self.continuation_factors(&alphas, &[cos_o / PI; N], nd);
                    let sky_r = self.guide_factors(g, beta, &[cos_o / PI; N], nd);
                    d = nd;
                    p = g;
                    sun_done = shadowed && h.skylight && {
                        let pk_est: [f64; N] = std::array::from_fn(|k| pk[k] * sky_r[k]);
                        self.skylight_along(p, d, &f, &pk_est, &mut res, scratch, rng)
                    };
                }
                Event::Collision(c) => {
                    let z = medium.altitude(c);
                    let ss = self.sigma_s(z);
                    if !(ss[0] > 0.0) {
                        break;
                    }
                    let mut t_sun = [0.0; N];
                    let mut shadowed = false;
                    if naive {
                        // Analog absorption, with band k's probability in pk[k].
                        let st = self.sigma_t(z);
                        if rng.uniform() * st[0] >= ss[0] {
                            break;
                        }
                        for k in 0..N {
                            pk[k] *= if st[k] > 0.0 { ss[k] / st[k] } else { 0.0 };
                        }
                    } else {
                        // Next-event estimation with each band's mixture of
                        // every scatterer's phase function (weighted by its
                        // scattering coefficient), not just the one picked to
                        // continue the path: removes the noise of that choice
                        // where a forward-peaked aerosol sees the sun.
                        // Skipped when the previous vertex estimated it, or
                        // at the first vertex when the caller computes single
                        // scattering by quadrature.
                        t_sun = self.sun_transmittance(c, rng);
                        shadowed = t_sun.iter().all(|&t| t == 0.0);
                        let single_skipped = depth == 0 && h.skip_single;
                        if !sun_done && !shadowed && !single_skipped {
                            let den = nee_den(&pk, &nee_r);
                            let c_sun = self.scattering_toward(z, d.dot(h.sun_dir));
                            for j in 0..N {
                                if f[j] != 0.0 && t_sun[j] > 0.0 {
                                    res[j] += f[j] * c_sun[j] * t_sun[j] / den;
                                }
                            }
                        }
                    }
                    // The scatterer, in proportion to band 0's scattering coefficients.
                    let which = pick_weighted(rng.uniform() * ss[0], h.spectral.extinction.len(), |i| self.sigma_s_i(0, i, z));
                    // Each band's f factor of a direction w, Σ_i σ_s,i p_i(μ)
                    // (the scatterer choice marginalised), and its density.
                    let scatter = |w: DVec3| {
                        let sp = self.scattering_toward(z, d.dot(w));
                        (sp, std::array::from_fn(|k| if ss[k] > 0.0 { sp[k] / ss[k] } else { 0.0 }))
                    };
                    let alphas: [f64; N] = std::array::from_fn(|k| self.t[k].lobe_alpha_at(t_sun[k]));
                    self.lobe_next_event(c, &alphas, &f, &pk, scatter, &mut res, rng);
                    // The skylight estimates toward the lit air only where
                    // a free path is long (see `SKYLIGHT_MAX_EXTINCTION_PER_KM`).
                    let guided = shadowed && self.sigma_t(z).iter().all(|&s| s <= self.skylight_max_extinction_per_km);
                    let beta = self.sky_guide_beta(guided);
                    self.guided_skylight(c, beta, &f, &pk, scatter, &mut res, scratch, rng);
                    let nd = sample_phase(&h.spectral.phase[which], d, rng);
                    // The continuation's factors for the guided skylight's
                    // balance heuristic (see `guided_skylight`).
                    let mut sky_r = [1.0; N];
                    if N == 1 && !(alphas[0] > 0.0) && !(beta > 0.0) {
                        // One band: f gains Σσ_s p and pk its ratio to σ_s,
                        // so only σ_s is left; no phase function to evaluate.
                        f[0] *= ss[0];
                        nee_r = [1.0; N];
                    } else {
                        let (sp, local) = scatter(nd);
                        for k in 0..N {
                            f[k] *= sp[k];
                            pk[k] *= local[k];
                        }
                        nee_r = self.continuation_factors(&alphas, &local, nd);
                        sky_r = self.guide_factors(c, beta, &local, nd);
                    }
                    d = nd;
                    p = c;
                    sun_done = guided && h.skylight && {
                        let pk_est: [f64; N] = std::array::from_fn(|k| pk[k] * sky_r[k]);
                        self.skylight_along(p, d, &f, &pk_est, &mut res, scratch, rng)
                    };
                }
            }
            // f and pk are products over hundreds of vertices in a thick
            // cloud: rescale both by a common factor (every estimate uses
            // their ratios) so that neither underflows.
            let scale = sum(&pk);
            if scale > 0.0 && scale.is_finite() {
                for k in 0..N {
                    f[k] /= scale;
                    pk[k] /= scale;
                }
            }
            // Russian roulette on the throughput, measured by a quantity
            // symmetric in the bands, so its probability is the same
            // whichever band decides and enters every P_k alike.
            let ratio = sum(&f) / sum(&pk);
            if depth == 0 {
                s_ref = ratio;
            }
            if depth >= ROULETTE_FROM_DEPTH {
                let q = survival_probability(ratio, s_ref);
                if q < 1.0 {
                    if rng.uniform() >= q {
                        break;
                    }
                    for v in &mut pk {
                        *v *= q;
                    }
                }
            }
            cut = depth + 1 == MAX_VERTICES;
        }
        let scale = |a: [f64; N]| -> [f64; N] { std::array::from_fn(|j| a[j] * self.t[j].spectral.sun_irradiance) };
        PathSample { direct: scale(direct), scattered: scale(res), cut }
    }
}

/// The decision of a forced flight (see [`Kernel::fly_forced`]).
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
/// probability P = 1 − e^(−τ_m) clamped to [0.1, 0.9]. With a guide, the
/// collision comes from the one-sample mixture of q and the guide.
pub(crate) fn choose_forced(segs: &[MajorantSegment], ground: Option<f64>, guide: Option<&RayGuide>, rng: &mut Rng) -> Forced {
    let tau_m: f64 = segs.iter().map(|s| (s.end_km - s.start_km) * s.majorant_per_km).sum();
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
        for s in segs {
            if t < s.start_km {
                return 0.0; // in a gap between shells
            }
            let m = s.majorant_per_km;
            if t < s.end_km {
                return m * libm::exp(-(acc + (t - s.start_km) * m)) / one_minus;
            }
            acc += (s.end_km - s.start_km) * m;
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
        let end = segs.last().map_or(0.0, |s| s.end_km);
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
fn sample_majorant(segs: &[MajorantSegment], one_minus: f64, rng: &mut Rng) -> Option<f64> {
    let tau_star = -libm::log1p(-rng.uniform() * one_minus);
    let mut acc = 0.0;
    for s in segs {
        let m = s.majorant_per_km;
        let dt = (s.end_km - s.start_km) * m;
        if m > 0.0 && acc + dt > tau_star {
            return Some(s.start_km + (tau_star - acc) / m);
        }
        acc += dt;
    }
    None
}
