//! Hero-wavelength sampling (Wilkie et al. 2014, "Hero Wavelength Spectral
//! Sampling"): each path carries the four bands of a [`HeroSet`], drawn at
//! stratified offsets of the band distribution with one of them, chosen
//! uniformly, as the hero. The path is built with the hero's decisions;
//! every band's contribution is weighted by the balance heuristic over the
//! four ways the same (closed) set could have been drawn, each with
//! probability 1/4: band j contributes f_j(x) W_j / (p(b_j) Σ_k P_k(x)),
//! where P_k is the density of the path had position k been the hero and
//! p(b_j) the band's own selection probability (each position is
//! distributed like one band draw).
//!
//! To make the P_k computable the bands share one majorant (the largest of
//! the four in each shell), so tentative collision points are common to all
//! of them and only the accept/null decisions, the scatterer choice and the
//! phase sampling differ between bands (the null-scattering path integral of
//! Miller, Georgiev and Jarosz 2019 gives these densities).

use super::bands::HeroSet;
pub use super::bands::HERO_N;
use super::guide::RayGuide;
use super::rng::Rng;
use super::tracer::{choose_forced, survival_probability, Forced, PathSample, Tracer, EPS_KM, MAX_VERTICES, ROULETTE_FROM_DEPTH};
use glam::DVec3;
use std::f64::consts::PI;

/// Where a flight ended.
#[derive(Clone, Copy)]
enum Event {
    Escape,
    Collision(DVec3),
    Ground(DVec3),
}

/// Four tracers of one medium at the four bands of a hero set (index 0 is the hero).
pub struct HeroTracer<'a> {
    pub t: [&'a Tracer<'a>; HERO_N],
    /// The shared majorant per shell (see [`shared_majorant`]).
    majorant: &'a [f64],
}

/// The largest of the bands' majorants in each shell, written into `out`
/// (a buffer reused across samples).
pub fn shared_majorant_into(majorants: [&[f64]; HERO_N], out: &mut Vec<f64>) {
    out.clear();
    out.extend((0..majorants[0].len()).map(|s| majorants.iter().map(|m| m[s]).fold(0.0, f64::max)));
}

impl<'a> HeroTracer<'a> {
    pub fn new(t: [&'a Tracer<'a>; HERO_N], majorant: &'a [f64]) -> HeroTracer<'a> {
        HeroTracer { t, majorant }
    }

    fn sigma_t(&self, z: f64) -> [f64; HERO_N] {
        let m = self.t[0].medium;
        std::array::from_fn(|j| self.t[j].spectral.sigma_t(m, z))
    }

    fn sigma_s(&self, z: f64) -> [f64; HERO_N] {
        let m = self.t[0].medium;
        std::array::from_fn(|j| {
            let sp = self.t[j].spectral;
            (0..sp.extinction.len()).map(|i| sp.extinction[i] * m.density(i, z) * sp.albedo[i]).sum()
        })
    }

    fn sigma_s_i(&self, j: usize, i: usize, z: f64) -> f64 {
        let sp = self.t[j].spectral;
        sp.extinction[i] * self.t[0].medium.density(i, z) * sp.albedo[i]
    }

    /// The four bands' transmittances over the first `t_max` km of the ray:
    /// exact from the column table when there is one, else by ratio
    /// tracking of all four at once.
    fn transmittance_to(&self, p: DVec3, d: DVec3, t_max: f64, rng: &mut Rng) -> [f64; HERO_N] {
        let h = self.t[0];
        if let Some(c) = h.columns {
            if let Some(path) = h.column_path(c, p, d, Some(t_max)) {
                return std::array::from_fn(|k| libm::exp(-c.path_optical_depth(&path, &self.t[k].spectral.extinction)));
            }
        }
        h.ratio_track_n(p, d, t_max, self.majorant, |z| self.sigma_t(z), rng)
    }

    /// The four bands' transmittances from `p` to the sun (one shared
    /// column path when there is a column table).
    fn sun_transmittance(&self, p: DVec3, rng: &mut Rng) -> [f64; HERO_N] {
        let h = self.t[0];
        if let Some(c) = h.columns {
            return match h.column_path(c, p, h.sun_dir, None) {
                None => [0.0; HERO_N],
                Some(path) => std::array::from_fn(|k| libm::exp(-c.path_optical_depth(&path, &self.t[k].spectral.extinction))),
            };
        }
        std::array::from_fn(|k| self.t[k].transmittance_to_space(p, h.sun_dir, rng))
    }

    /// At a vertex in the Earth's shadow, the sunlight single-scattered
    /// toward `p` along the scattered direction `d`, estimated by one
    /// distance drawn from a coarse guide of the integrand (see
    /// [`RayGuide::build_secondary`]) instead of by the analog flight's
    /// collision: at twilight the air above the shadow is lit but thin, and
    /// an analog flight from shadowed haze seldom ends there. The estimate
    /// has the expectation of the next vertex's next-event estimation
    /// toward the sun (∫ T(0, t) Σ_i σ_s,i p_i(μ_sun) T_sun dt), which that
    /// vertex then skips; the path itself goes on by analog flight, so no
    /// weight grows. The guide is the same whichever band is the hero, so
    /// the balance heuristic only gains the common factor 1 / g(t).
    /// Returns false (nothing estimated) when nothing on the ray is lit.
    fn skylight_along(&self, p: DVec3, d: DVec3, f: &[f64; HERO_N], pk: &[f64; HERO_N], res: &mut [f64; HERO_N], rng: &mut Rng) -> bool {
        let h = self.t[0];
        let (t, pdf) = match RayGuide::sample_secondary(&self.t, p, d, rng) {
            None => return false,
            Some((_, pdf)) if !(pdf > 0.0) => return true, // measure zero: the estimate is 0
            Some(s) => s,
        };
        let q = p + d * t;
        let z = h.altitude(q);
        let tr = self.transmittance_to(p, d, t, rng);
        let t_sun = self.sun_transmittance(q, rng);
        let mu_s = d.dot(h.sun_dir);
        let den = pk.iter().sum::<f64>() * pdf;
        for j in 0..HERO_N {
            if f[j] == 0.0 || t_sun[j] <= 0.0 {
                continue;
            }
            let (c_j, _) = self.t[j].scattering_at(z, mu_s);
            res[j] += f[j] * tr[j] * c_j * t_sun[j] / den;
        }
        true
    }

    /// Delta tracking from `p` along `d` against the shared majorant: null
    /// and real decisions are made with the hero's σ_t and enter every
    /// band's throughput `f` and density `pk` (the tentative-point density
    /// is common to all and cancels).
    fn fly(&self, p: DVec3, d: DVec3, f: &mut [f64; HERO_N], pk: &mut [f64; HERO_N], rng: &mut Rng) -> Event {
        let h = self.t[0];
        let mut q = p;
        loop {
            let (s, t_exit, next) = h.shell_exit(q, d);
            let m = self.majorant[s];
            if m > 0.0 {
                let t = -libm::log(1.0 - rng.uniform()) / m;
                if t < t_exit {
                    q += d * t;
                    let st = self.sigma_t(h.altitude(q));
                    if rng.uniform() * m < st[0] {
                        for k in 0..HERO_N {
                            pk[k] *= st[k] / m;
                            f[k] /= m;
                        }
                        return Event::Collision(q);
                    }
                    for k in 0..HERO_N {
                        let null = 1.0 - st[k] / m;
                        pk[k] *= null;
                        f[k] *= null;
                    }
                    continue;
                }
            }
            if !t_exit.is_finite() {
                return Event::Escape;
            }
            q += d * t_exit;
            match next {
                None => return Event::Escape,
                Some(usize::MAX) => return Event::Ground(q),
                Some(_) => q += d * EPS_KM,
            }
        }
    }

    /// Σ_i σ_s,i(z) p_i(μ) per band: the f factor of a scattered direction.
    fn scattering_toward(&self, z: f64, mu: f64) -> [f64; HERO_N] {
        std::array::from_fn(|k| self.t[k].scattering_at(z, mu).0)
    }

    /// The sun's next-event estimate of every band at a vertex `y` reached
    /// along `d` by a flight, with throughput `f` (added to `res` over the
    /// densities' sum `den`).
    fn sun_estimate(&self, event: Event, d: DVec3, f: &[f64; HERO_N], den: f64, res: &mut [f64; HERO_N], rng: &mut Rng) {
        let h = self.t[0];
        match event {
            Event::Escape => {}
            Event::Collision(y) => {
                let z = h.altitude(y);
                let t_sun = self.sun_transmittance(y, rng);
                let c = self.scattering_toward(z, d.dot(h.sun_dir));
                for j in 0..HERO_N {
                    if t_sun[j] > 0.0 {
                        res[j] += f[j] * c[j] * t_sun[j] / den;
                    }
                }
            }
            Event::Ground(g) => {
                let n = h.up(g);
                let cos_s = n.dot(h.sun_dir);
                if cos_s > 0.0 {
                    let t_sun = self.sun_transmittance(g + n * EPS_KM, rng);
                    for j in 0..HERO_N {
                        res[j] += f[j] * self.t[j].spectral.ground_albedo / PI * cos_s * t_sun[j] / den;
                    }
                }
            }
        }
    }

    /// The lobe technique of the next vertex's sun estimate (see
    /// `Tracer::lobe_next_event`), for four bands: taken with the hero's
    /// probability `alphas[0]`, a direction from the hero's lobe and a
    /// flight along it; band k's density of the direction is its own
    /// local density plus α_k times its own lobe density (the balance
    /// heuristic over the hero choices and the two techniques, with their
    /// expected sample counts). `local(w)` gives each band's f factor and
    /// local density of a direction w.
    fn lobe_next_event(
        &self,
        x: DVec3,
        alphas: &[f64; HERO_N],
        f: &[f64; HERO_N],
        pk: &[f64; HERO_N],
        local: impl Fn(DVec3) -> ([f64; HERO_N], [f64; HERO_N]),
        res: &mut [f64; HERO_N],
        rng: &mut Rng,
    ) {
        let h = self.t[0];
        let Some((i, _)) = h.lobe else { return };
        if !(alphas[0] > 0.0) || rng.uniform() >= alphas[0] {
            return;
        }
        let w = h.sample_phase(&h.spectral.phase[i], h.sun_dir, rng);
        let (factor, density) = local(w);
        if factor.iter().all(|v| !(*v > 0.0)) {
            return;
        }
        let mut fl: [f64; HERO_N] = std::array::from_fn(|k| f[k] * factor[k]);
        let mut pl: [f64; HERO_N] = std::array::from_fn(|k| pk[k] * (density[k] + alphas[k] * self.t[k].lobe_pdf(w)));
        let event = self.fly(x, w, &mut fl, &mut pl, rng);
        let den = pl.iter().sum::<f64>();
        if den > 0.0 {
            self.sun_estimate(event, w, &fl, den, res, rng);
        }
    }

    /// The weights' factors r_k = (local_k + α_k lobe_k) / local_k of a
    /// continuation direction: the next vertex's sun estimate divides by
    /// Σ_k pk_k r_k (see [`HeroTracer::lobe_next_event`]).
    fn continuation_factors(&self, alphas: &[f64; HERO_N], density: &[f64; HERO_N], w: DVec3) -> [f64; HERO_N] {
        std::array::from_fn(|k| if alphas[k] > 0.0 && density[k] > 0.0 { 1.0 + alphas[k] * self.t[k].lobe_pdf(w) / density[k] } else { 1.0 })
    }

    /// One hero path for the bands of `set` (whose tracers `self` holds, in
    /// the same order): the radiance estimate of each of the four bands,
    /// MIS-weighted and divided by each band's selection probability, split
    /// into the directly seen sun and the rest.
    pub fn radiance(&self, origin: DVec3, dir: DVec3, set: &HeroSet, guide: Option<&RayGuide>, rng: &mut Rng) -> PathSample<[f64; HERO_N]> {
        let h = self.t[0];
        let mut direct = [0.0; HERO_N];
        let mut res = [0.0; HERO_N];
        let mut f = [1.0; HERO_N];
        // The path's density had position k been the hero (the uniform 1/4
        // of the hero choice cancels in the balance heuristic).
        let mut pk = [1.0; HERO_N];
        let sum = |a: &[f64; HERO_N]| a.iter().sum::<f64>();
        if h.sun_disk && dir.dot(h.sun_dir) >= h.sun_cos_half {
            let den = sum(&pk);
            for j in 0..HERO_N {
                direct[j] = f[j] * self.t[j].sun_disk_radiance * self.t[j].transmittance_to_space(origin, dir, rng) / den;
            }
        }
        // Russian roulette's reference: the throughput ratio after the first vertex.
        let mut s_ref = 1.0;
        let mut cut = false;
        let mut p = origin;
        let mut d = dir;
        let mut segs: Vec<(f64, f64, f64)> = Vec::new();
        // Whether the sunlight single-scattered toward the last vertex along
        // `d` has been estimated there (see `skylight_along`): the vertex the
        // flight finds then skips its next-event estimation toward the sun.
        let mut sun_done = false;
        // The factors r_k of the direction `d` for the next vertex's sun
        // estimate (see `continuation_factors`); 1 for the camera ray.
        let mut nee_r = [1.0; HERO_N];
        for depth in 0..MAX_VERTICES {
            // --- flight ---
            let mut collision: Option<DVec3> = None;
            let mut ground: Option<DVec3> = None;
            if depth == 0 {
                // Forced first collision against the shared majorant.
                let ground_t = h.segments(p, d, self.majorant, &mut segs);
                match choose_forced(&segs, ground_t, guide, rng) {
                    Forced::Clear(None) | Forced::Lost => break,
                    Forced::Clear(Some(t)) => ground = Some(p + d * t),
                    Forced::Collision { t, pdf } => {
                        let tr = self.transmittance_to(p, d, t, rng);
                        for k in 0..HERO_N {
                            f[k] *= tr[k];
                            pk[k] *= pdf;
                        }
                        collision = Some(p + d * t);
                    }
                    Forced::Ground { t, prob } => {
                        let tr = self.transmittance_to(p, d, t, rng);
                        for k in 0..HERO_N {
                            f[k] *= tr[k];
                            pk[k] *= prob;
                        }
                        ground = Some(p + d * t);
                    }
                }
            } else {
                match self.fly(p, d, &mut f, &mut pk, rng) {
                    Event::Collision(q) => collision = Some(q),
                    Event::Ground(q) => ground = Some(q),
                    Event::Escape => {}
                }
                if collision.is_none() && ground.is_none() {
                    break;
                }
            }
            // --- vertex ---
            if let Some(g) = ground {
                let n = h.up(g);
                let g = g + n * EPS_KM;
                let cos_s = n.dot(h.sun_dir);
                let den = nee_den(&pk, &nee_r);
                let mut shadowed = true;
                let mut t_sun = [0.0; HERO_N];
                if cos_s > 0.0 {
                    t_sun = self.sun_transmittance(g, rng);
                    shadowed = t_sun.iter().all(|&t| t == 0.0);
                    for j in 0..HERO_N {
                        let a = self.t[j].spectral.ground_albedo;
                        if a > 0.0 {
                            res[j] += f[j] * a / PI * cos_s * t_sun[j] / den;
                        }
                    }
                }
                for j in 0..HERO_N {
                    f[j] *= self.t[j].spectral.ground_albedo;
                }
                if f.iter().all(|v| *v <= 0.0) {
                    break;
                }
                // Cosine-weighted, and the sun lobe as a separate technique
                // of the next vertex's sun estimate.
                let alphas: [f64; HERO_N] = std::array::from_fn(|k| self.t[k].lobe_alpha_at(t_sun[k]));
                let cosine = |w: DVec3| {
                    let c = n.dot(w).max(0.0) / PI;
                    ([c; HERO_N], [c; HERO_N])
                };
                self.lobe_next_event(g, &alphas, &f, &pk, cosine, &mut res, rng);
                let u1 = rng.uniform();
                let phi = 2.0 * PI * rng.uniform();
                let nd = super::tracer::around(n, u1.sqrt(), phi);
                let cos_o = n.dot(nd);
                if cos_o <= 0.0 {
                    break;
                }
                let local = [cos_o / PI; HERO_N];
                for k in 0..HERO_N {
                    f[k] *= local[k];
                    pk[k] *= local[k];
                }
                nee_r = self.continuation_factors(&alphas, &local, nd);
                d = nd;
                p = g;
                sun_done = shadowed && h.skylight && self.skylight_along(p, d, &f, &pk, &mut res, rng);
            } else if let Some(c) = collision {
                let z = h.altitude(c);
                let ss = self.sigma_s(z);
                if ss[0] <= 0.0 {
                    break;
                }
                // Next-event estimation with each band's mixture phase function.
                let den = nee_den(&pk, &nee_r);
                let k_comp = h.spectral.extinction.len();
                let t_sun = self.sun_transmittance(c, rng);
                let shadowed = t_sun.iter().all(|&t| t == 0.0);
                if !sun_done {
                    let c_sun = self.scattering_toward(z, d.dot(h.sun_dir));
                    for j in 0..HERO_N {
                        if f[j] != 0.0 && t_sun[j] > 0.0 {
                            res[j] += f[j] * c_sun[j] * t_sun[j] / den;
                        }
                    }
                }
                // Pick the scatterer with the hero's scattering coefficients.
                let mut pick = rng.uniform() * ss[0];
                let mut which = k_comp - 1;
                for i in 0..k_comp {
                    let s = self.sigma_s_i(0, i, z);
                    if pick < s {
                        which = i;
                        break;
                    }
                    pick -= s;
                }
                // Each band's f factor of a direction w, Σ_i σ_s,i p_i(μ)
                // (the scatterer choice marginalised), and its density.
                let scatter = |w: DVec3| {
                    let sp = self.scattering_toward(z, d.dot(w));
                    (sp, std::array::from_fn(|k| if ss[k] > 0.0 { sp[k] / ss[k] } else { 0.0 }))
                };
                let alphas: [f64; HERO_N] = std::array::from_fn(|k| self.t[k].lobe_alpha_at(t_sun[k]));
                self.lobe_next_event(c, &alphas, &f, &pk, scatter, &mut res, rng);
                let nd = h.sample_phase(&h.spectral.phase[which], d, rng);
                let (sp, local) = scatter(nd);
                for k in 0..HERO_N {
                    f[k] *= sp[k];
                    pk[k] *= local[k];
                }
                nee_r = self.continuation_factors(&alphas, &local, nd);
                d = nd;
                p = c;
                sun_done = shadowed && h.skylight && self.skylight_along(p, d, &f, &pk, &mut res, rng);
            }
            // f and pk are products over hundreds of vertices in a thick
            // cloud: rescale both by a common factor (every estimate uses
            // their ratios) so that neither underflows.
            let scale = sum(&pk);
            if scale > 0.0 && scale.is_finite() {
                for k in 0..HERO_N {
                    f[k] /= scale;
                    pk[k] /= scale;
                }
            }
            // Russian roulette on the throughput, measured by a quantity
            // symmetric in the four bands, so its probability is the same
            // whichever band is the hero and enters every P_k alike.
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
        let scale = |a: [f64; HERO_N]| -> [f64; HERO_N] { std::array::from_fn(|j| a[j] * self.t[j].spectral.sun_irradiance / set.pdf[j]) };
        PathSample { direct: scale(direct), scattered: scale(res), cut }
    }
}

/// The densities' sum for the sun estimate at a vertex reached along a
/// continuation direction with factors `r` (see `continuation_factors`).
#[inline]
fn nee_den(pk: &[f64; HERO_N], r: &[f64; HERO_N]) -> f64 {
    (0..HERO_N).map(|k| pk[k] * r[k]).sum()
}
