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
//!
//! This file holds the kernel and the path's vertices ([`Kernel::radiance`]);
//! its free flights and transmittances are in `flight`, its light estimates
//! at a vertex (sun, sun lobe, skylight) in `next_event`.

use super::guide::{RayGuide, SecondaryScratch};
use super::rng::Rng;
use super::sampling::{cosine_hemisphere, pick_weighted, sample_phase};
use super::segments::{MajorantSegment, EPS_KM};
use super::sky_guide::SkylightGuide;
use super::tracer::{survival_probability, Estimator, PathSample, Tracer, MAX_VERTICES, ROULETTE_FROM_DEPTH};
use glam::DVec3;
use std::f64::consts::PI;

/// Where a flight ended.
#[derive(Clone, Copy)]
pub(super) enum Event {
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
    pub(super) segments: Vec<MajorantSegment>,
    pub(super) secondary: SecondaryScratch,
}

/// N tracers of one medium, at the N bands a path carries (band 0 decides),
/// with the majorant they share.
pub struct Kernel<'a, const N: usize> {
    pub t: [&'a Tracer<'a>; N],
    /// The shared majorant per shell: for N > 1 the largest of the bands'
    /// (see `hero::shared_majorant_into`), so tentative collisions are
    /// common to all of them.
    pub(super) majorant: &'a [f64],
    /// Directions toward the lit air for vertices in the Earth's shadow
    /// (see `sky_guide` and [`Kernel::guided_skylight`]).
    pub(super) sky_guide: Option<&'a SkylightGuide>,
    /// [`SKYLIGHT_MAX_EXTINCTION_PER_KM`], or another value in a test.
    skylight_max_extinction_per_km: f64,
}

impl<'a> Kernel<'a, 1> {
    /// The kernel of one band, with its own majorant.
    pub fn single(t: &'a Tracer<'a>) -> Kernel<'a, 1> {
        Kernel {
            t: [t],
            majorant: &t.spectral.majorant,
            sky_guide: None,
            skylight_max_extinction_per_km: SKYLIGHT_MAX_EXTINCTION_PER_KM,
        }
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

pub use super::next_event::SKY_GUIDE_PROBABILITY;

#[inline]
pub(super) fn sum<const N: usize>(a: &[f64; N]) -> f64 {
    a.iter().sum()
}

/// The densities' sum for the sun estimate at a vertex reached along a
/// continuation direction with factors `r` (see `continuation_factors`).
#[inline]
fn nee_den<const N: usize>(pk: &[f64; N], r: &[f64; N]) -> f64 {
    (0..N).map(|k| pk[k] * r[k]).sum()
}

/// A path between its vertices (see [`Kernel::radiance`]): where it is and
/// where it goes, what it carries and what it has gathered.
struct PathState<const N: usize> {
    p: DVec3,
    d: DVec3,
    /// The path's throughput per band (the measurement contribution
    /// without its sampling densities).
    f: [f64; N],
    /// The path's density had band k decided (the uniform 1/N of the
    /// hero choice cancels in the balance heuristic).
    pk: [f64; N],
    /// The light scattered toward the camera so far, per band.
    res: [f64; N],
    /// Whether the sunlight single-scattered toward the last vertex along
    /// `d` has been estimated there (see `skylight_along`): the vertex the
    /// flight finds then skips its next-event estimation toward the sun.
    sun_done: bool,
    /// The factors r_k of the direction `d` for the next vertex's sun
    /// estimate (see `continuation_factors`); 1 for the camera ray.
    nee_r: [f64; N],
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

    /// The skylight estimates everywhere in the shadow, whatever the
    /// extinction (to test that the limit changes only the cost).
    #[cfg(test)]
    pub(crate) fn with_skylight_everywhere(mut self) -> Self {
        self.skylight_max_extinction_per_km = f64::INFINITY;
        self
    }

    #[inline]
    pub(super) fn sigma_t(&self, z: f64) -> [f64; N] {
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
    pub(super) fn scattering_toward(&self, z: f64, mu: f64) -> [f64; N] {
        std::array::from_fn(|k| self.t[k].scattering_at(z, mu).0)
    }

    /// One path sample of the radiance arriving at `origin` from direction
    /// `-dir` (looking along `dir`), per band: each band's estimate, MIS-
    /// weighted over the N ways its set could have been drawn (not yet
    /// divided by the band's own selection probability), times its sun
    /// irradiance; split into the directly seen sun and the rest. `guide`,
    /// if any, shapes the distance of the forced first collision.
    pub fn radiance(
        &self,
        origin: DVec3,
        dir: DVec3,
        guide: Option<&RayGuide>,
        scratch: &mut Scratch,
        rng: &mut Rng,
    ) -> PathSample<[f64; N]> {
        let h = self.t[0];
        let naive = h.estimator == Estimator::Naive;
        let mut direct = [0.0; N];
        let mut path =
            PathState { p: origin, d: dir, f: [1.0; N], pk: [1.0; N], res: [0.0; N], sun_done: false, nee_r: [1.0; N] };
        if !naive && h.sun_disk && dir.dot(h.sun_dir) >= h.sun_cos_half {
            let tr = self.transmittance(origin, dir, f64::INFINITY, rng);
            let den = sum(&path.pk);
            for j in 0..N {
                direct[j] = path.f[j] * self.t[j].sun_disk_radiance * tr[j] / den;
            }
        }
        // Russian roulette's reference: the throughput ratio after the first vertex.
        let mut s_ref = 1.0;
        let mut cut = false;
        for depth in 0..MAX_VERTICES {
            // Forced collisions on the camera ray only: later bounces fly
            // analogously, so escaping paths end instead of carrying ever
            // smaller weights into Russian roulette.
            let event = if depth == 0 && !naive {
                self.fly_forced(path.p, path.d, guide, &mut path.f, &mut path.pk, scratch, rng)
            } else {
                self.fly(path.p, path.d, &mut path.f, &mut path.pk, rng)
            };
            match event {
                Event::Lost => break,
                Event::Escape => {
                    // The naive estimator's only light: the sun's disk seen
                    // by an escaping path.
                    if naive && (h.sun_disk || depth > 0) && path.d.dot(h.sun_dir) >= h.sun_cos_half {
                        let den = sum(&path.pk);
                        for j in 0..N {
                            path.res[j] += path.f[j] * self.t[j].sun_disk_radiance / den;
                        }
                    }
                    break;
                }
                Event::Ground(g) => {
                    if !self.ground_vertex(g, depth, &mut path, scratch, rng) {
                        break;
                    }
                }
                Event::Collision(c) => {
                    if !self.collision_vertex(c, depth, &mut path, scratch, rng) {
                        break;
                    }
                }
            }
            // f and pk are products over hundreds of vertices in a thick
            // cloud: rescale both by a common factor (every estimate uses
            // their ratios) so that neither underflows.
            let scale = sum(&path.pk);
            if scale > 0.0 && scale.is_finite() {
                for k in 0..N {
                    path.f[k] /= scale;
                    path.pk[k] /= scale;
                }
            }
            // Russian roulette on the throughput, measured by a quantity
            // symmetric in the bands, so its probability is the same
            // whichever band decides and enters every P_k alike.
            let ratio = sum(&path.f) / sum(&path.pk);
            if depth == 0 {
                s_ref = ratio;
            }
            if depth >= ROULETTE_FROM_DEPTH {
                let q = survival_probability(ratio, s_ref);
                if q < 1.0 {
                    if rng.uniform() >= q {
                        break;
                    }
                    for v in &mut path.pk {
                        *v *= q;
                    }
                }
            }
            cut = depth + 1 == MAX_VERTICES;
        }
        let scale = |a: [f64; N]| -> [f64; N] { std::array::from_fn(|j| a[j] * self.t[j].spectral.sun_irradiance) };
        PathSample { direct: scale(direct), scattered: scale(path.res), cut }
    }

    /// The path's vertex on the ground at `g` (depth `depth`, 0 on the
    /// camera ray): the sun's next-event estimate, the Lambertian
    /// reflection, the sun lobe's and the skylight's techniques, and the
    /// continuation by a cosine-weighted direction. False if the path ends.
    fn ground_vertex(
        &self,
        g: DVec3,
        depth: usize,
        path: &mut PathState<N>,
        scratch: &mut Scratch,
        rng: &mut Rng,
    ) -> bool {
        let h = self.t[0];
        let medium = h.medium;
        let naive = h.estimator == Estimator::Naive;
        let n = medium.up(g);
        let g = g + n * EPS_KM;
        let cos_s = n.dot(h.sun_dir);
        let mut shadowed = true;
        let mut t_sun = [0.0; N];
        if !naive && cos_s > 0.0 {
            let den = nee_den(&path.pk, &path.nee_r);
            t_sun = self.sun_transmittance(g, rng);
            shadowed = t_sun.iter().all(|&t| t == 0.0);
            if !(depth == 0 && h.skip_single) {
                for j in 0..N {
                    path.res[j] += path.f[j] * self.t[j].spectral.ground_albedo / PI * cos_s * t_sun[j] / den;
                }
            }
        }
        for j in 0..N {
            path.f[j] *= self.t[j].spectral.ground_albedo;
        }
        if path.f.iter().all(|v| !(*v > 0.0)) {
            return false;
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
        self.lobe_next_event(g, &alphas, &path.f, &path.pk, cosine, &mut path.res, rng);
        let beta = self.sky_guide_beta(shadowed);
        self.guided_skylight(g, beta, &path.f, &path.pk, cosine, &mut path.res, scratch, rng);
        let nd = cosine_hemisphere(n, rng);
        let cos_o = n.dot(nd);
        if cos_o <= 0.0 {
            return false;
        }
        path.nee_r = self.continuation_factors(&alphas, &[cos_o / PI; N], nd);
        let sky_r = self.guide_factors(g, beta, &[cos_o / PI; N], nd);
        path.d = nd;
        path.p = g;
        path.sun_done = shadowed && h.skylight && {
            let pk_est: [f64; N] = std::array::from_fn(|k| path.pk[k] * sky_r[k]);
            self.skylight_along(path.p, path.d, &path.f, &pk_est, &mut path.res, scratch, rng)
        };
        true
    }

    /// The path's vertex at a collision `c` in the medium (depth `depth`,
    /// 0 on the camera ray): analog absorption (naive) or the sun's
    /// next-event estimate, the sun lobe's and the skylight's techniques,
    /// and the continuation by a direction from the phase function of a
    /// scatterer drawn in proportion to band 0's scattering. False if the
    /// path ends.
    fn collision_vertex(
        &self,
        c: DVec3,
        depth: usize,
        path: &mut PathState<N>,
        scratch: &mut Scratch,
        rng: &mut Rng,
    ) -> bool {
        let h = self.t[0];
        let medium = h.medium;
        let naive = h.estimator == Estimator::Naive;
        let d = path.d;
        let z = medium.altitude(c);
        let ss = self.sigma_s(z);
        if !(ss[0] > 0.0) {
            return false;
        }
        let mut t_sun = [0.0; N];
        let mut shadowed = false;
        if naive {
            // Analog absorption, with band k's probability in pk[k].
            let st = self.sigma_t(z);
            if rng.uniform() * st[0] >= ss[0] {
                return false;
            }
            for k in 0..N {
                path.pk[k] *= if st[k] > 0.0 { ss[k] / st[k] } else { 0.0 };
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
            if !path.sun_done && !shadowed && !single_skipped {
                let den = nee_den(&path.pk, &path.nee_r);
                let c_sun = self.scattering_toward(z, d.dot(h.sun_dir));
                for j in 0..N {
                    if path.f[j] != 0.0 && t_sun[j] > 0.0 {
                        path.res[j] += path.f[j] * c_sun[j] * t_sun[j] / den;
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
        self.lobe_next_event(c, &alphas, &path.f, &path.pk, scatter, &mut path.res, rng);
        // The skylight estimates toward the lit air only where
        // a free path is long (see `SKYLIGHT_MAX_EXTINCTION_PER_KM`).
        let guided = shadowed && self.sigma_t(z).iter().all(|&s| s <= self.skylight_max_extinction_per_km);
        let beta = self.sky_guide_beta(guided);
        self.guided_skylight(c, beta, &path.f, &path.pk, scatter, &mut path.res, scratch, rng);
        let nd = sample_phase(&h.spectral.phase[which], d, rng);
        // The continuation's factors for the guided skylight's
        // balance heuristic (see `guided_skylight`).
        let mut sky_r = [1.0; N];
        if N == 1 && !(alphas[0] > 0.0) && !(beta > 0.0) {
            // One band: f gains Σσ_s p and pk its ratio to σ_s,
            // so only σ_s is left; no phase function to evaluate.
            path.f[0] *= ss[0];
            path.nee_r = [1.0; N];
        } else {
            let (sp, local) = scatter(nd);
            for k in 0..N {
                path.f[k] *= sp[k];
                path.pk[k] *= local[k];
            }
            path.nee_r = self.continuation_factors(&alphas, &local, nd);
            sky_r = self.guide_factors(c, beta, &local, nd);
        }
        path.d = nd;
        path.p = c;
        path.sun_done = guided && h.skylight && {
            let pk_est: [f64; N] = std::array::from_fn(|k| path.pk[k] * sky_r[k]);
            self.skylight_along(path.p, path.d, &path.f, &pk_est, &mut path.res, scratch, rng)
        };
        true
    }
}
