//! Hero-wavelength sampling (Wilkie et al. 2014, "Hero Wavelength Spectral
//! Sampling"): each path carries four bands, the hero b0 drawn from the
//! band distribution and three companions at b0 + kN/4 (mod N). The path is
//! built with the hero's decisions; every band's contribution is weighted by
//! the balance heuristic over the four ways the same set could have been
//! drawn, Σ_j f_j(x) W_j / Σ_k p(b_k) P_k(x), where P_k is the density of
//! the path had band k been the hero.
//!
//! To make the P_k computable the bands share one majorant (the largest of
//! the four in each shell), so tentative collision points are common to all
//! of them and only the accept/null decisions, the scatterer choice and the
//! phase sampling differ between bands (the null-scattering path integral of
//! Miller, Georgiev and Jarosz 2019 gives these densities).

use super::guide::{RayGuide, SHADOW_TRANSMITTANCE};
use super::rng::Rng;
use super::tracer::{choose_forced, Forced, Tracer, EPS_KM};
use glam::DVec3;
use std::f64::consts::PI;

pub const HERO_N: usize = 4;


/// Four tracers of one medium at the four bands of a hero set (index 0 is the hero).
pub struct HeroTracer<'a> {
    pub t: [&'a Tracer<'a>; HERO_N],
    /// The shared majorant per shell (see [`shared_majorant`]).
    majorant: &'a [f64],
}

/// The largest of the bands' majorants in each shell.
pub fn shared_majorant(majorants: [&[f64]; HERO_N]) -> Vec<f64> {
    (0..majorants[0].len()).map(|s| majorants.iter().map(|m| m[s]).fold(0.0, f64::max)).collect()
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

    /// The density of a scattered direction had band `k` been the hero:
    /// the local strategy's density `local` mixed with band k's sun lobe
    /// at cos ν to the sun (see `Tracer::sun_lobe`).
    #[inline]
    fn mixture_pdf(&self, k: usize, local: f64, nu: f64) -> f64 {
        let t = self.t[k];
        match t.lobe {
            None => local,
            Some((i, alpha)) => (1.0 - alpha) * local + alpha * t.spectral.phase[i].eval(nu),
        }
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
            let mut c_j = 0.0;
            for i in 0..h.spectral.extinction.len() {
                let s = self.sigma_s_i(j, i, z);
                if s > 0.0 {
                    c_j += s * self.t[j].spectral.phase[i].eval(mu_s);
                }
            }
            res[j] += f[j] * tr[j] * c_j * t_sun[j] / den;
        }
        true
    }

    /// One hero path: the radiance estimate of each of the four bands
    /// (relative to each band's solar irradiance, already MIS-weighted and
    /// divided by the hero-selection densities `sel_pdf`), split into the
    /// directly seen sun and the rest.
    pub fn radiance(&self, origin: DVec3, dir: DVec3, sel_pdf: [f64; HERO_N], guide: Option<&RayGuide>, rng: &mut Rng) -> ([f64; HERO_N], [f64; HERO_N]) {
        let h = self.t[0];
        let mut direct = [0.0; HERO_N];
        let mut res = [0.0; HERO_N];
        let mut f = [1.0; HERO_N];
        let mut pk = sel_pdf;
        let sum = |a: &[f64; HERO_N]| a.iter().sum::<f64>();
        if h.sun_disk && dir.dot(h.sun_dir) >= h.sun_cos_half {
            let den = sum(&pk);
            for j in 0..HERO_N {
                direct[j] = f[j] * self.t[j].sun_disk_radiance * self.t[j].transmittance_to_space(origin, dir, rng) / den;
            }
        }
        let s0 = sum(&f) / sum(&pk);
        let mut p = origin;
        let mut d = dir;
        let mut segs: Vec<(f64, f64, f64)> = Vec::new();
        // Whether the sunlight single-scattered toward the last vertex along
        // `d` has been estimated there (see `skylight_along`): the vertex the
        // flight finds then skips its next-event estimation toward the sun.
        let mut sun_done = false;
        for depth in 0..10_000 {
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
                // Delta tracking against the shared majorant: null and real
                // decisions are made with the hero's σ_t and enter every band's
                // density. The tentative-point density is common and cancels.
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
                                collision = Some(q);
                                break;
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
                        break;
                    }
                    q += d * t_exit;
                    match next {
                        None => break,
                        Some(usize::MAX) => {
                            ground = Some(q);
                            break;
                        }
                        Some(_) => q += d * EPS_KM,
                    }
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
                let den = sum(&pk);
                let mut shadowed = true;
                if cos_s > 0.0 {
                    let t_sun = self.sun_transmittance(g, rng);
                    shadowed = t_sun.iter().all(|&t| t < SHADOW_TRANSMITTANCE);
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
                // Cosine-weighted, mixed with the sun lobe (Tracer::sun_lobe).
                let (nd, _) = h.guided(rng, |r| {
                    let u1 = r.uniform();
                    let phi = 2.0 * PI * r.uniform();
                    super::tracer::around(n, u1.sqrt(), phi)
                });
                let cos_o = n.dot(nd);
                if cos_o <= 0.0 {
                    break;
                }
                let nu = nd.dot(h.sun_dir);
                for k in 0..HERO_N {
                    let local = cos_o / PI;
                    f[k] *= local;
                    pk[k] *= self.mixture_pdf(k, local, nu);
                }
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
                let mu_s = d.dot(h.sun_dir);
                let den = sum(&pk);
                let k_comp = h.spectral.extinction.len();
                let t_sun = self.sun_transmittance(c, rng);
                let shadowed = t_sun.iter().all(|&t| t < SHADOW_TRANSMITTANCE);
                for j in 0..HERO_N {
                    if sun_done || f[j] == 0.0 || ss[j] <= 0.0 {
                        continue;
                    }
                    let t = t_sun[j];
                    if t > 0.0 {
                        let mut c_j = 0.0;
                        for i in 0..k_comp {
                            let s = self.sigma_s_i(j, i, z);
                            if s > 0.0 {
                                c_j += s * self.t[j].spectral.phase[i].eval(mu_s);
                            }
                        }
                        res[j] += f[j] * c_j * t / den;
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
                let (nd, _) = h.guided(rng, |r| h.sample_phase(&h.spectral.phase[which], d, r));
                let mu = d.dot(nd);
                let nu = nd.dot(h.sun_dir);
                for k in 0..HERO_N {
                    // The scatterer choice marginalised: Σ_i σ_s,i p_i(μ).
                    let mut sp = 0.0;
                    for i in 0..k_comp {
                        let s = self.sigma_s_i(k, i, z);
                        if s > 0.0 {
                            sp += s * self.t[k].spectral.phase[i].eval(mu);
                        }
                    }
                    f[k] *= sp;
                    let local = if ss[k] > 0.0 { sp / ss[k] } else { 0.0 };
                    pk[k] *= self.mixture_pdf(k, local, nu);
                }
                d = nd;
                p = c;
                sun_done = shadowed && h.skylight && self.skylight_along(p, d, &f, &pk, &mut res, rng);
            }
            // Russian roulette on a quantity symmetric in the four bands, so
            // its probability is the same whichever band is the hero.
            if depth >= 3 {
                let s = sum(&f) / sum(&pk) / s0;
                let q = s.min(0.95);
                if !(q > 0.0) || rng.uniform() >= q {
                    break;
                }
                for v in &mut pk {
                    *v *= q;
                }
            }
        }
        let scale = |a: [f64; HERO_N]| -> [f64; HERO_N] { std::array::from_fn(|j| a[j] * self.t[j].spectral.sun_irradiance) };
        (scale(direct), scale(res))
    }
}
