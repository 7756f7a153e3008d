//! The kernel's free flights and transmittances: delta tracking against
//! the shared majorant (Novák, Selle and Jarosz 2014), the forced first
//! collision of camera rays and its decision ([`choose_forced`]), and the
//! bands' transmittances along a segment, exact from the column table
//! where the medium allows, by ratio tracking otherwise (see `kernel`).

use super::guide::RayGuide;
use super::kernel::{Event, Kernel, Scratch};
use super::medium::depth_of_columns;
use super::rng::Rng;
use super::segments::{Boundary, MajorantSegment};
use glam::DVec3;

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

impl<'a, const N: usize> Kernel<'a, N> {
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
    pub(super) fn transmittance(&self, p: DVec3, d: DVec3, t_max: f64, rng: &mut Rng) -> [f64; N] {
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
                    return std::array::from_fn(|k| {
                        libm::exp(-if k == 0 {
                            depth_of_columns(add, sub)
                        } else {
                            c.path_optical_depth(&path, &self.t[k].spectral.extinction)
                        })
                    });
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
    pub(super) fn sun_transmittance(&self, p: DVec3, rng: &mut Rng) -> [f64; N] {
        self.transmittance(p, self.t[0].sun_dir, f64::INFINITY, rng)
    }

    /// Delta tracking from `p` along `d` against the shared majorant, one
    /// shell segment at a time: null and real decisions are made with band
    /// 0's σ_t and enter every band's `f` and `pk` (the tentative-point
    /// density is common to all and cancels).
    pub(super) fn fly(&self, p: DVec3, d: DVec3, f: &mut [f64; N], pk: &mut [f64; N], rng: &mut Rng) -> Event {
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
    pub(super) fn fly_forced(
        &self,
        p: DVec3,
        d: DVec3,
        guide: Option<&RayGuide>,
        f: &mut [f64; N],
        pk: &mut [f64; N],
        scratch: &mut Scratch,
        rng: &mut Rng,
    ) -> Event {
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
pub(crate) fn choose_forced(
    segs: &[MajorantSegment],
    ground: Option<f64>,
    guide: Option<&RayGuide>,
    rng: &mut Rng,
) -> Forced {
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
