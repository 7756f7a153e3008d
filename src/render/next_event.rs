//! The kernel's light estimates at a vertex: next-event estimation toward
//! the sun, the sun lobe as its second technique, and the skylight
//! estimates toward the lit air for vertices in the Earth's shadow (see
//! `kernel`).

use super::guide::RayGuide;
use super::kernel::{sum, Event, Kernel, Scratch};
use super::rng::Rng;
use super::sampling::sample_phase;
use super::segments::EPS_KM;
use glam::DVec3;
use std::f64::consts::PI;

/// The probability of drawing a second skylight direction from the
/// [`SkylightGuide`](super::sky_guide::SkylightGuide) at a vertex in the Earth's shadow.
pub const SKY_GUIDE_PROBABILITY: f64 = 0.5;

impl<'a, const N: usize> Kernel<'a, N> {
    /// The probability of the guided skylight technique at a vertex (see
    /// [`Kernel::guided_skylight`]): [`SKY_GUIDE_PROBABILITY`] in the
    /// Earth's shadow with a guide, else 0.
    #[inline]
    pub(super) fn sky_guide_beta(&self, shadowed: bool) -> f64 {
        if shadowed && self.t[0].skylight && self.sky_guide.is_some() {
            SKY_GUIDE_PROBABILITY
        } else {
            0.0
        }
    }

    /// At a vertex `x` in the Earth's shadow, with probability β, the
    /// skylight estimate ([`Kernel::skylight_along`]) along a second
    /// direction drawn from the [`SkylightGuide`](super::sky_guide::SkylightGuide) toward the lit air. It
    /// and the continuation's own estimate are combined by the balance
    /// heuristic over the two direction densities, local(w) + β guide(w)
    /// (Veach 1997, §9.2, with expected sample counts 1 and β), as the sun
    /// lobe's technique is: this one adds the guided estimate, and the
    /// continuation's divides by the factors of [`Kernel::guide_factors`].
    pub(super) fn guided_skylight(
        &self,
        x: DVec3,
        beta: f64,
        f: &[f64; N],
        pk: &[f64; N],
        local: impl Fn(DVec3) -> ([f64; N], [f64; N]),
        res: &mut [f64; N],
        scratch: &mut Scratch,
        rng: &mut Rng,
    ) {
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
    pub(super) fn guide_factors(&self, x: DVec3, beta: f64, local: &[f64; N], w: DVec3) -> [f64; N] {
        match self.sky_guide {
            Some(g) if beta > 0.0 => {
                let medium = self.t[0].medium;
                let p = beta * g.pdf(medium.up(x), medium.altitude(x), w);
                std::array::from_fn(|k| if local[k] > 0.0 { 1.0 + p / local[k] } else { 1.0 })
            }
            _ => [1.0; N],
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
    pub(super) fn lobe_next_event(
        &self,
        x: DVec3,
        alphas: &[f64; N],
        f: &[f64; N],
        pk: &[f64; N],
        local: impl Fn(DVec3) -> ([f64; N], [f64; N]),
        res: &mut [f64; N],
        rng: &mut Rng,
    ) {
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
    pub(super) fn continuation_factors(&self, alphas: &[f64; N], density: &[f64; N], w: DVec3) -> [f64; N] {
        std::array::from_fn(|k| {
            if alphas[k] > 0.0 && density[k] > 0.0 {
                1.0 + alphas[k] * self.t[k].lobe_pdf(w) / density[k]
            } else {
                1.0
            }
        })
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
    pub(super) fn skylight_along(
        &self,
        p: DVec3,
        d: DVec3,
        f: &[f64; N],
        pk: &[f64; N],
        res: &mut [f64; N],
        scratch: &mut Scratch,
        rng: &mut Rng,
    ) -> bool {
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
}
