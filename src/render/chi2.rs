//! Chi-square goodness-of-fit tests of every direction sampler in
//! `sampling.rs` against the density it claims to sample, in the manner of
//! pbrt-v4's `chi2` tests and Mitsuba 3's `chi2.py` (Jakob et al.): draw
//! samples, bin them over the sphere, integrate the density over each bin
//! numerically, pool the cells whose expected count is below 5, form
//! Pearson's statistic and take its p-value from the regularised upper
//! incomplete gamma function, Q(dof/2, χ²/2).
//!
//! False-alarm rate: the goodness-of-fit cases below form one family of
//! [`N_CASES`] tests at a family-wise significance [`ALPHA_FAMILY`] = 1 %;
//! each case is rejected at the Šidák level α = 1 − (1 − 0.01)^(1/N_CASES)
//! (≈ 5.0e-4 for 20 cases; Šidák 1967), so with correct samplers the whole
//! module fails by chance with probability 1 % — but deterministically:
//! the seeds are fixed, so a given build either always passes or always
//! fails. The power tests (`wrong_samplers_are_rejected`) show that
//! deliberately wrong samplers fail at that same α.
//!
//! Binning: cells are a grid in (μ, φ) about the sampler's axis, μ = w · axis,
//! φ the azimuth in a frame of our own (not the samplers' frame). The μ edges
//! are the union of (a) [`N_MU_EQUAL`] edges equiprobable under the tested
//! density (bins uniform in the transformed variable F(μ), the density's own
//! CDF, so a forward peak gets bins as fine as it is narrow and every bin has
//! power) and (b) [`N_THETA_UNIFORM`] edges uniform in θ (so that where the
//! density is small — the back of a cloud droplet's phase function, the
//! lower hemisphere of the cosine lobe — bins stay a few degrees wide and
//! samples where the density is zero are seen; one within a quarter of
//! its spacing of an equiprobable edge is dropped). φ has [`N_PHI`] uniform
//! bins. The phase functions depend only on μ, so the φ integral over a cell
//! is exact (2π / N_PHI) and only a 1-D μ integral is done per μ bin, by
//! adaptive Simpson, split at the density's kinks (the knots of a phase
//! table, where it is linear in μ and Simpson is exact on each piece).

use super::medium::Phase;
use super::rng::Rng;
use super::sampling::{around, cosine_hemisphere, cosine_hemisphere_pdf, pick_weighted, sample_hg, sample_phase};
use crate::mie::{bhmie, bulk_optics, phase::phase_grid_deg, LogNormal, PhaseTable};
use glam::DVec3;
use num_complex::Complex64 as C64;
use std::f64::consts::PI;
use std::sync::{Arc, OnceLock};

/// Family-wise significance of the goodness-of-fit family.
const ALPHA_FAMILY: f64 = 0.01;
/// Number of goodness-of-fit cases in the family (checked by
/// `the_family_has_n_cases`).
const N_CASES: usize = 20;
/// Samples per case.
const N_SAMPLES: u64 = 1_000_000;
/// μ edges equiprobable under the density, edges uniform in θ, φ bins.
const N_MU_EQUAL: usize = 40;
const N_THETA_UNIFORM: usize = 24;
const N_PHI: usize = 32;
/// Cells with fewer expected samples are pooled (Cochran's rule, as Mitsuba).
const POOL_BELOW: f64 = 5.0;
/// Cells expected to receive fewer samples than this count as zero-density:
/// any sample in one rejects the case. (The density's rounding leaves
/// ~1e-18 sr⁻¹ where it is zero; the chance of such a rejection with a
/// correct sampler is below cells × 1e-9 ≈ 2e-6 per case.)
const ZERO_EXPECTED: f64 = 1e-9;
/// Master seed of every case's random streams.
const SEED: u64 = 0xC412_5EED;

/// The Šidák per-case significance: 1 − (1 − α_family)^(1/N).
fn alpha_per_case() -> f64 {
    1.0 - (1.0 - ALPHA_FAMILY).powf(1.0 / N_CASES as f64)
}

// ---------------------------------------------------------------------------
// The regularised upper incomplete gamma function Q(a, x) = Γ(a, x) / Γ(a),
// after Press, Teukolsky, Vetterling and Flannery, "Numerical Recipes in C",
// 2nd ed. (1992), §6.2: the series of P(a, x) (their gser, eq. 6.2.5) for
// x < a + 1 and the continued fraction of Q(a, x) (their gcf, eq. 6.2.7,
// evaluated by the modified Lentz method, §5.2) otherwise. ln Γ is libm's.

const GAMMA_EPS: f64 = 1e-15;
const GAMMA_TINY: f64 = 1e-300;
/// Enough iterations for a ~ 10⁴ (the series needs O(√a) terms past x).
const GAMMA_ITMAX: usize = 100_000;

/// x^a e^(−x) / Γ(a), the common prefactor of both expansions.
fn gamma_prefactor(a: f64, x: f64) -> f64 {
    (-x + a * x.ln() - libm::lgamma(a)).exp()
}

/// P(a, x) by its series Σ x^n / (a (a+1) … (a+n)) (NR eq. 6.2.5).
fn gamma_p_series(a: f64, x: f64) -> f64 {
    let (mut ap, mut term) = (a, 1.0 / a);
    let mut sum = term;
    for _ in 0..GAMMA_ITMAX {
        ap += 1.0;
        term *= x / ap;
        sum += term;
        if term.abs() < sum.abs() * GAMMA_EPS {
            break;
        }
    }
    sum * gamma_prefactor(a, x)
}

/// Q(a, x) by its continued fraction 1/(x+1−a− 1(1−a)/(x+3−a− 2(2−a)/(x+5−a− …)))
/// (NR eq. 6.2.7), modified Lentz.
fn gamma_q_continued_fraction(a: f64, x: f64) -> f64 {
    let mut b = x + 1.0 - a;
    let mut c = 1.0 / GAMMA_TINY;
    let mut d = 1.0 / b;
    let mut h = d;
    for i in 1..GAMMA_ITMAX {
        let an = -(i as f64) * (i as f64 - a);
        b += 2.0;
        d = an * d + b;
        if d.abs() < GAMMA_TINY {
            d = GAMMA_TINY;
        }
        c = b + an / c;
        if c.abs() < GAMMA_TINY {
            c = GAMMA_TINY;
        }
        d = 1.0 / d;
        let delta = d * c;
        h *= delta;
        if (delta - 1.0).abs() < GAMMA_EPS {
            break;
        }
    }
    gamma_prefactor(a, x) * h
}

/// Q(a, x), the regularised upper incomplete gamma function, a > 0, x ≥ 0.
fn gamma_q(a: f64, x: f64) -> f64 {
    assert!(a > 0.0 && x >= 0.0, "gamma_q({a}, {x})");
    if x == 0.0 {
        1.0
    } else if x < a + 1.0 {
        1.0 - gamma_p_series(a, x)
    } else {
        gamma_q_continued_fraction(a, x)
    }
}

/// The p-value of a chi-square statistic with `dof` degrees of freedom.
fn chi2_p_value(chi2: f64, dof: usize) -> f64 {
    gamma_q(0.5 * dof as f64, 0.5 * chi2)
}

// ---------------------------------------------------------------------------
// Numerical integration of a density in μ.

/// Adaptive Simpson on [a, b] with Richardson's correction (Lyness 1969),
/// given f at a, the midpoint and b and the whole-interval estimate.
#[allow(clippy::too_many_arguments)]
fn simpson_adaptive(
    f: &dyn Fn(f64) -> f64,
    a: f64,
    b: f64,
    fa: f64,
    fm: f64,
    fb: f64,
    whole: f64,
    tol: f64,
    depth: u32,
) -> f64 {
    let m = 0.5 * (a + b);
    let (lm, rm) = (0.5 * (a + m), 0.5 * (m + b));
    let (flm, frm) = (f(lm), f(rm));
    let left = (m - a) / 6.0 * (fa + 4.0 * flm + fm);
    let right = (b - m) / 6.0 * (fm + 4.0 * frm + fb);
    let delta = left + right - whole;
    if depth == 0 || delta.abs() <= 15.0 * tol {
        return left + right + delta / 15.0;
    }
    simpson_adaptive(f, a, m, fa, flm, fm, left, 0.5 * tol, depth - 1)
        + simpson_adaptive(f, m, b, fm, frm, fb, right, 0.5 * tol, depth - 1)
}

/// ∫ f dμ over [a, b], split at the `kinks` (sorted) inside it, each piece
/// by adaptive Simpson to an absolute tolerance proportional to its width.
fn integrate_mu(f: &dyn Fn(f64) -> f64, a: f64, b: f64, kinks: &[f64]) -> f64 {
    let first = kinks.partition_point(|&k| k <= a);
    let last = kinks.partition_point(|&k| k < b);
    let mut total = 0.0;
    let mut lo = a;
    for &hi in kinks[first..last].iter().chain(std::iter::once(&b)) {
        if hi > lo {
            let (fa, fm, fb) = (f(lo), f(0.5 * (lo + hi)), f(hi));
            let whole = (hi - lo) / 6.0 * (fa + 4.0 * fm + fb);
            total += simpson_adaptive(f, lo, hi, fa, fm, fb, whole, 1e-13 * (hi - lo), 40);
        }
        lo = hi;
    }
    total
}

/// The μ edges of the binning (see the module comment), increasing from −1
/// to 1; `density` is in sr⁻¹ as a function of μ.
fn mu_edges(density: &dyn Fn(f64) -> f64) -> Vec<f64> {
    // The CDF on a fine grid uniform in θ (0.011° steps: finer than any
    // forward peak tested here), by the trapezoid rule; only the edges'
    // placement depends on its accuracy, not the expected counts.
    const FINE: usize = 16_384;
    let mu: Vec<f64> = (0..=FINE).map(|j| -(j as f64 * PI / FINE as f64).cos()).collect();
    let mut cdf = vec![0.0; FINE + 1];
    for j in 1..=FINE {
        cdf[j] = cdf[j - 1] + 0.5 * (density(mu[j - 1]) + density(mu[j])) * (mu[j] - mu[j - 1]);
    }
    let total = cdf[FINE];
    let mut edges = vec![-1.0, 1.0];
    for k in 1..N_MU_EQUAL {
        let target = total * k as f64 / N_MU_EQUAL as f64;
        let j = cdf.partition_point(|&c| c < target).clamp(1, FINE);
        let t = if cdf[j] > cdf[j - 1] { (target - cdf[j - 1]) / (cdf[j] - cdf[j - 1]) } else { 0.0 };
        edges.push(mu[j - 1] + t * (mu[j] - mu[j - 1]));
    }
    // The θ-uniform edges only fill the gaps: one within a quarter of their
    // spacing of an equiprobable edge would leave a sliver of a bin.
    let step_rad = PI / N_THETA_UNIFORM as f64;
    let theta_equal: Vec<f64> = edges.iter().map(|m| m.clamp(-1.0, 1.0).acos()).collect();
    for k in 1..N_THETA_UNIFORM {
        let theta = PI - k as f64 * step_rad;
        if theta_equal.iter().all(|t| (t - theta).abs() > 0.25 * step_rad) {
            edges.push(if k * 2 == N_THETA_UNIFORM { 0.0 } else { theta.cos() });
        }
    }
    edges.sort_by(f64::total_cmp);
    edges.dedup_by(|b, a| (*b - *a).abs() < 1e-12);
    edges
}

// ---------------------------------------------------------------------------
// Pearson's statistic.

/// The outcome of one chi-square test.
struct Outcome {
    name: String,
    samples: u64,
    cells: usize,
    dof: usize,
    chi2: f64,
    p_value: f64,
    /// |Σ over the sphere of the integrated density − 1|.
    normalisation_error: f64,
    /// Samples in cells where the density integrates to (nearly) zero,
    /// below [`ZERO_EXPECTED`] samples.
    zero_density_samples: u64,
    /// Samples that were not unit vectors.
    bad_samples: u64,
}

impl Outcome {
    fn rejected(&self, alpha: f64) -> bool {
        self.zero_density_samples > 0 || self.bad_samples > 0 || !(self.p_value >= alpha)
    }

    fn print(&self, alpha: f64) {
        println!(
            "chi2 {:<44} n {:>8} cells {:>5} dof {:>5} chi2 {:>12.2} p {:>10.3e} |norm-1| {:>8.1e} zero-density {} bad {} -> {}",
            self.name,
            self.samples,
            self.cells,
            self.dof,
            self.chi2,
            self.p_value,
            self.normalisation_error,
            self.zero_density_samples,
            self.bad_samples,
            if self.rejected(alpha) { "REJECTED" } else { "ok" }
        );
    }
}

/// Pearson's χ² of `observed` against `expected` counts, pooling the cells
/// expected below [`POOL_BELOW`] into one (merged into the smallest other
/// cell if even the pool is below it); returns (χ², cells, dof).
fn pearson(observed: &[u64], expected: &[f64]) -> (f64, usize, usize) {
    let (mut pool_o, mut pool_e) = (0.0, 0.0);
    let mut cells: Vec<(f64, f64)> = Vec::new();
    for (&o, &e) in observed.iter().zip(expected) {
        if e < POOL_BELOW {
            pool_o += o as f64;
            pool_e += e;
        } else {
            cells.push((o as f64, e));
        }
    }
    if pool_e >= POOL_BELOW {
        cells.push((pool_o, pool_e));
    } else if pool_e > 0.0 || pool_o > 0.0 {
        if let Some(c) = cells.iter_mut().min_by(|a, b| a.1.total_cmp(&b.1)) {
            c.0 += pool_o;
            c.1 += pool_e;
        }
    }
    let chi2 = cells.iter().map(|(o, e)| (o - e) * (o - e) / e).sum();
    (chi2, cells.len(), cells.len().saturating_sub(1))
}

/// An orthonormal frame (t, b) about `axis`, built independently of the
/// samplers' `any_orthonormal_pair`.
fn frame(axis: DVec3) -> (DVec3, DVec3) {
    let helper = if axis.x.abs() < 0.6 { DVec3::X } else { DVec3::Y };
    let t = helper.cross(axis).normalize();
    (t, axis.cross(t))
}

/// Tests `sampler` against `density` (sr⁻¹, a function of μ = w · axis
/// only, with derivative jumps at `kinks`), drawing [`N_SAMPLES`] samples,
/// sample i from the stream `Rng::new(SEED, case, i)`.
fn run_case(
    name: &str,
    case: u64,
    axis: DVec3,
    density: &dyn Fn(f64) -> f64,
    kinks: &[f64],
    sampler: &mut dyn FnMut(&mut Rng) -> DVec3,
) -> Outcome {
    let axis = axis.normalize();
    let (t, b) = frame(axis);
    let edges = mu_edges(density);
    let n_mu = edges.len() - 1;
    // The probability of each μ bin: 2π ∫ p dμ (the φ integral is exact).
    let p_mu: Vec<f64> = edges.windows(2).map(|w| 2.0 * PI * integrate_mu(density, w[0], w[1], kinks)).collect();
    let normalisation_error = (p_mu.iter().sum::<f64>() - 1.0).abs();
    let mut observed = vec![0u64; n_mu * N_PHI];
    let mut bad_samples = 0;
    for i in 0..N_SAMPLES {
        let mut rng = Rng::new(SEED, case, i);
        let w = sampler(&mut rng);
        if !w.is_finite() || (w.length() - 1.0).abs() > 1e-9 {
            bad_samples += 1;
            continue;
        }
        let mu = w.dot(axis).clamp(-1.0, 1.0);
        let phi = w.dot(b).atan2(w.dot(t)).rem_euclid(2.0 * PI);
        let i_mu = (edges.partition_point(|&e| e <= mu) - 1).min(n_mu - 1);
        let i_phi = ((phi / (2.0 * PI) * N_PHI as f64) as usize).min(N_PHI - 1);
        observed[i_mu * N_PHI + i_phi] += 1;
    }
    let expected: Vec<f64> = (0..n_mu * N_PHI).map(|c| p_mu[c / N_PHI] / N_PHI as f64 * N_SAMPLES as f64).collect();
    // Where the density integrates to (nearly) zero over a cell, no sample
    // may land, however few: such cells are kept out of the pool, where
    // they would only add to its count.
    let zero_density_samples =
        observed.iter().zip(&expected).filter(|(_, &e)| e < ZERO_EXPECTED).map(|(&o, _)| o).sum();
    let (obs, exp): (Vec<u64>, Vec<f64>) =
        observed.iter().zip(&expected).filter(|(_, &e)| e >= ZERO_EXPECTED).map(|(&o, &e)| (o, e)).unzip();
    let (chi2, cells, dof) = pearson(&obs, &exp);
    let p_value = chi2_p_value(chi2, dof);
    Outcome {
        name: name.to_string(),
        samples: N_SAMPLES,
        cells,
        dof,
        chi2,
        p_value,
        normalisation_error,
        zero_density_samples,
        bad_samples,
    }
}

// ---------------------------------------------------------------------------
// The cases.

/// The sampler of a goodness-of-fit case.
enum Sampler {
    /// `sample_phase` about the axis; density `phase.eval(w · axis)`.
    Phase(Phase),
    /// A scatterer drawn with `pick_weighted` in proportion to the weights,
    /// then its phase function; density Σ wᵢ pᵢ / Σ wᵢ.
    Mixture(Vec<(f64, Phase)>),
    /// `cosine_hemisphere` about the axis against `cosine_hemisphere_pdf`.
    CosineHemisphere,
}

impl Sampler {
    fn density(&self, axis: DVec3) -> Box<dyn Fn(f64) -> f64 + '_> {
        match self {
            Sampler::Phase(p) => Box::new(move |mu| p.eval(mu)),
            Sampler::Mixture(parts) => {
                let total: f64 = parts.iter().map(|p| p.0).sum();
                Box::new(move |mu| parts.iter().map(|(w, p)| w * p.eval(mu)).sum::<f64>() / total)
            }
            // The pdf of a direction at μ from the axis (any azimuth).
            Sampler::CosineHemisphere => Box::new(move |mu| {
                cosine_hemisphere_pdf(axis, axis * mu + frame(axis).0 * (1.0 - mu * mu).max(0.0).sqrt())
            }),
        }
    }

    /// Where the density's derivative jumps (sorted).
    fn kinks(&self) -> Vec<f64> {
        let phases: Vec<&Phase> = match self {
            Sampler::Phase(p) => vec![p],
            Sampler::Mixture(parts) => parts.iter().map(|p| &p.1).collect(),
            Sampler::CosineHemisphere => return vec![0.0],
        };
        let mut k: Vec<f64> = phases
            .iter()
            .filter_map(|p| if let Phase::Table(t) = p { Some(t.mu.clone()) } else { None })
            .flatten()
            .collect();
        k.sort_by(f64::total_cmp);
        k.dedup();
        k
    }

    fn sample(&self, axis: DVec3, rng: &mut Rng) -> DVec3 {
        match self {
            Sampler::Phase(p) => sample_phase(p, axis, rng),
            Sampler::Mixture(parts) => {
                let total: f64 = parts.iter().map(|p| p.0).sum();
                let i = pick_weighted(rng.uniform() * total, parts.len(), |i| parts[i].0);
                sample_phase(&parts[i].1, axis, rng)
            }
            Sampler::CosineHemisphere => cosine_hemisphere(axis, rng),
        }
    }
}

struct Case {
    name: String,
    axis: DVec3,
    sampler: Sampler,
}

/// Tilted, non-axis-aligned directions of travel (and normals).
fn tilted(k: usize) -> DVec3 {
    const D: [[f64; 3]; 6] = [
        [0.36, -0.48, 0.8],
        [-0.62, 0.25, -0.74],
        [0.11, 0.93, 0.35],
        [-0.45, -0.71, 0.2],
        [0.8, 0.1, -0.59],
        [-0.2, 0.55, 0.81],
    ];
    DVec3::from_array(D[k % D.len()]).normalize()
}

/// The sun direction of the lobe cases: zenith 62°, azimuth 137° (z up).
fn sun_direction() -> DVec3 {
    let (z, a) = (62f64.to_radians(), 137f64.to_radians());
    DVec3::new(z.sin() * a.cos(), z.sin() * a.sin(), z.cos())
}

/// A water cloud droplet at 550 nm: one sphere of radius 5 µm (x ≈ 57),
/// m = 1.333 − 1.96e-9 i (Hale and Querry 1973), p(θ) = ½(|S1|² + |S2|²) /
/// (π x² Q_sca) (Bohren and Huffman 1983, eqs. 3.41 and 4.74) on the
/// renderer's angle grid: the hard, forward-peaked (p(0°) ~ 10³ sr⁻¹) case.
fn cloud_table() -> Arc<PhaseTable> {
    static T: OnceLock<Arc<PhaseTable>> = OnceLock::new();
    T.get_or_init(|| {
        let (radius_um, wavelength_um) = (5.0, 0.55);
        let x = 2.0 * PI * radius_um / wavelength_um;
        let grid = phase_grid_deg();
        let mus: Vec<f64> = grid.iter().map(|a| a.to_radians().cos()).collect();
        let r = bhmie(C64::new(1.333, 1.96e-9), x, &mus);
        let p_sr_inv: Vec<f64> =
            r.s1.iter()
                .zip(&r.s2)
                .map(|(s1, s2)| 0.5 * (s1.norm_sqr() + s2.norm_sqr()) / (PI * x * x * r.q_sca))
                .collect();
        let t = PhaseTable::new(&grid, &p_sr_inv);
        assert!((t.integral - 1.0).abs() < 1e-2, "cloud phase integral {}", t.integral);
        Arc::new(t)
    })
    .clone()
}

/// A haze mode at 550 nm: log-normal, number median radius 0.1 µm, σ = ln 2,
/// m = 1.45 − 0.005 i (a water-soluble-like accumulation mode): the moderate
/// case (g ≈ 0.7).
fn haze_table() -> Arc<PhaseTable> {
    static T: OnceLock<Arc<PhaseTable>> = OnceLock::new();
    T.get_or_init(|| {
        let grid = phase_grid_deg();
        let b = bulk_optics(C64::new(1.45, 0.005), &LogNormal::new(0.1, 2f64.ln()), 550.0, &grid);
        Arc::new(PhaseTable::new(&grid, &b.phase_sr_inv))
    })
    .clone()
}

fn case(name: &str, axis: DVec3, sampler: Sampler) -> Case {
    Case { name: name.to_string(), axis, sampler }
}

fn rayleigh_cases() -> Vec<Case> {
    [0.0, 0.0279, 0.1]
        .iter()
        .enumerate()
        .map(|(k, &rho)| {
            case(&format!("Rayleigh rho={rho}"), tilted(k), Sampler::Phase(Phase::Rayleigh { depolarization: rho }))
        })
        .collect()
}

fn cornette_shanks_cases() -> Vec<Case> {
    [0.2, 0.76, -0.3]
        .iter()
        .enumerate()
        .map(|(k, &g)| {
            case(&format!("Cornette-Shanks g={g}"), tilted(k + 1), Sampler::Phase(Phase::CornetteShanks { g }))
        })
        .collect()
}

fn henyey_greenstein_cases() -> Vec<Case> {
    [0.0, 0.5, 0.85, -0.6, 0.95]
        .iter()
        .enumerate()
        .map(|(k, &g)| {
            case(&format!("Henyey-Greenstein g={g}"), tilted(k + 2), Sampler::Phase(Phase::HenyeyGreenstein { g }))
        })
        .collect()
}

fn mie_cases() -> Vec<Case> {
    vec![
        case("Mie table, cloud droplet 5 um", tilted(3), Sampler::Phase(Phase::Table(cloud_table()))),
        case("Mie table, haze mode", tilted(4), Sampler::Phase(Phase::Table(haze_table()))),
    ]
}

fn lobe_cases() -> Vec<Case> {
    let sun = sun_direction();
    vec![
        case("lobe about the sun, cloud droplet", sun, Sampler::Phase(Phase::Table(cloud_table()))),
        case("lobe about the sun, haze mode", sun, Sampler::Phase(Phase::Table(haze_table()))),
        case("lobe about the sun, Cornette-Shanks g=0.76", sun, Sampler::Phase(Phase::CornetteShanks { g: 0.76 })),
    ]
}

fn mixture_cases() -> Vec<Case> {
    let rayleigh = Phase::Rayleigh { depolarization: 0.0279 };
    vec![
        case(
            "mixture 0.3 Rayleigh + 0.7 haze",
            tilted(5),
            Sampler::Mixture(vec![(0.3, rayleigh.clone()), (0.7, Phase::Table(haze_table()))]),
        ),
        case(
            "mixture 0.2 Rayl + 0 cloud + 0.8 haze",
            tilted(0),
            Sampler::Mixture(vec![
                (0.2, rayleigh),
                (0.0, Phase::Table(cloud_table())),
                (0.8, Phase::Table(haze_table())),
                (0.0, Phase::HenyeyGreenstein { g: -0.9 }),
            ]),
        ),
    ]
}

fn cosine_hemisphere_cases() -> Vec<Case> {
    vec![
        case("cosine hemisphere, normal 1", tilted(1), Sampler::CosineHemisphere),
        case("cosine hemisphere, normal 2", tilted(4), Sampler::CosineHemisphere),
    ]
}

/// Runs a list of cases (case ids from `first_id`), prints every outcome,
/// then asserts each passes at the Šidák level with a normalised density.
fn check_cases(cases: &[Case], first_id: u64) {
    let alpha = alpha_per_case();
    let outcomes: Vec<Outcome> = cases
        .iter()
        .enumerate()
        .map(|(k, c)| {
            let density = c.sampler.density(c.axis);
            run_case(&c.name, first_id + k as u64, c.axis, &*density, &c.sampler.kinks(), &mut |rng| {
                c.sampler.sample(c.axis, rng)
            })
        })
        .collect();
    for o in &outcomes {
        o.print(alpha);
    }
    for o in &outcomes {
        assert!(
            o.normalisation_error < 1e-4,
            "{}: the density integrates to 1 ± {:.2e}",
            o.name,
            o.normalisation_error
        );
        assert!(
            !o.rejected(alpha),
            "{}: χ² = {:.2} with {} dof, p = {:.3e} < α = {alpha:.3e} (zero-density samples {}, bad {})",
            o.name,
            o.chi2,
            o.dof,
            o.p_value,
            o.zero_density_samples,
            o.bad_samples
        );
    }
}

#[test]
fn the_family_has_n_cases() {
    let n = rayleigh_cases().len()
        + cornette_shanks_cases().len()
        + henyey_greenstein_cases().len()
        + mie_cases().len()
        + lobe_cases().len()
        + mixture_cases().len()
        + cosine_hemisphere_cases().len();
    assert_eq!(n, N_CASES, "update N_CASES (the Šidák correction) when adding cases");
    println!(
        "chi2 family: {N_CASES} cases, family-wise alpha {ALPHA_FAMILY}, Sidak per-case alpha {:.4e}",
        alpha_per_case()
    );
}

#[test]
fn incomplete_gamma_matches_known_values() {
    // Q(1, x) = e^−x; Q(1/2, x) = erfc(√x).
    for x in [0.01f64, 0.5, 1.9, 2.1, 7.0, 40.0] {
        assert!((gamma_q(1.0, x) / (-x).exp() - 1.0).abs() < 1e-12, "Q(1, {x})");
        assert!((gamma_q(0.5, x) / libm::erfc(x.sqrt()) - 1.0).abs() < 1e-10, "Q(1/2, {x})");
    }
    // Chi-square critical values (Abramowitz and Stegun 1964, Table 26.8).
    assert!((chi2_p_value(3.841_459, 1) - 0.05).abs() < 1e-6);
    assert!((chi2_p_value(18.307_04, 10) - 0.05).abs() < 1e-6);
    assert!((chi2_p_value(23.209_25, 10) - 0.01).abs() < 1e-6);
    // Q(n, x) = e^−x Σ_{k<n} x^k / k! for integer n, on both sides of x = a + 1
    // and at large a, where the series needs many terms.
    for (n, x) in [(5usize, 3.0f64), (5, 9.0), (300, 290.0), (300, 330.0), (1024, 1000.0), (1024, 1100.0)] {
        let (mut ln_term, mut sum) = (-x, 0.0);
        for k in 0..n {
            if k > 0 {
                ln_term += (x / k as f64).ln();
            }
            sum += ln_term.exp();
        }
        assert!((gamma_q(n as f64, x) / sum - 1.0).abs() < 1e-9, "Q({n}, {x}) = {} vs {sum}", gamma_q(n as f64, x));
    }
}

#[test]
fn rayleigh_phase_sampling() {
    check_cases(&rayleigh_cases(), 100);
}

#[test]
fn cornette_shanks_phase_sampling() {
    check_cases(&cornette_shanks_cases(), 200);
}

#[test]
fn henyey_greenstein_phase_sampling() {
    check_cases(&henyey_greenstein_cases(), 300);
}

#[test]
fn mie_table_phase_sampling() {
    for (name, t) in [("cloud droplet", cloud_table()), ("haze mode", haze_table())] {
        println!(
            "chi2 table {name}: input integral {:.5}, g {:.4}, p(0 deg) {:.4e} sr^-1, p(180 deg) {:.4e} sr^-1",
            t.integral,
            t.mean_cosine(),
            t.eval_mu(1.0),
            t.eval_mu(-1.0)
        );
    }
    check_cases(&mie_cases(), 400);
}

#[test]
fn lobe_sampling_about_the_sun() {
    check_cases(&lobe_cases(), 500);
}

#[test]
fn scatterer_mixture_sampling() {
    check_cases(&mixture_cases(), 600);
}

#[test]
fn cosine_hemisphere_sampling() {
    check_cases(&cosine_hemisphere_cases(), 700);
}

/// Power: deliberately wrong samplers, each tested against the density it
/// should have sampled, must be rejected at the same Šidák level.
#[test]
fn wrong_samplers_are_rejected() {
    let alpha = alpha_per_case();
    let d = tilted(2);
    let hg = |g: f64| Phase::HenyeyGreenstein { g };
    let rayleigh = |rho: f64| Phase::Rayleigh { depolarization: rho };
    let mix = Sampler::Mixture(vec![(0.3, rayleigh(0.0279)), (0.7, Phase::Table(haze_table()))]);
    let cosine = Sampler::CosineHemisphere;
    let cosine_density = cosine.density(d);
    let mut outcomes = Vec::new();
    for (k, g) in [0.5, 0.85].into_iter().enumerate() {
        let target = Phase::HenyeyGreenstein { g };
        outcomes.push(run_case(
            &format!("WRONG: HG g+0.02 against g={g}"),
            900 + k as u64,
            d,
            &|mu| target.eval(mu),
            &[],
            &mut |rng| sample_phase(&hg(g + 0.02), d, rng),
        ));
    }
    let target = rayleigh(0.1);
    outcomes.push(run_case("WRONG: Rayleigh rho=0 against rho=0.1", 910, d, &|mu| target.eval(mu), &[], &mut |rng| {
        sample_phase(&rayleigh(0.0), d, rng)
    }));
    outcomes.push(run_case("WRONG: cosine hemisphere with mu = u", 920, d, &*cosine_density, &[0.0], &mut |rng| {
        let mu = rng.uniform();
        around(d, mu, 2.0 * PI * rng.uniform())
    }));
    outcomes.push(run_case("WRONG: HG g=0.5 with phi in [0, pi)", 930, d, &|mu| hg(0.5).eval(mu), &[], &mut |rng| {
        let mu = sample_hg(0.5, rng.uniform());
        around(d, mu, PI * rng.uniform())
    }));
    outcomes.push(run_case(
        "WRONG: uniform sphere against the cosine lobe",
        950,
        d,
        &*cosine_density,
        &[0.0],
        &mut |rng| {
            let mu = 2.0 * rng.uniform() - 1.0;
            around(d, mu, 2.0 * PI * rng.uniform())
        },
    ));
    // A table sampler that returns the nearest table cosine above its μ
    // instead of interpolating (a lattice of directions). A subtler error,
    // inverting the CDF as if the density were constant within each table
    // interval, is not seen: it moves probability only within intervals
    // narrower than any bin (tried: p ≈ 0.95 for both tables).
    let cloud = cloud_table();
    let cloud_phase = Phase::Table(cloud.clone());
    outcomes.push(run_case(
        "WRONG: cloud table snapped to its knots",
        960,
        d,
        &|mu| cloud_phase.eval(mu),
        &cloud.mu,
        &mut |rng| {
            let mu = cloud.sample_mu(rng.uniform());
            let i = cloud.mu.partition_point(|&m| m < mu).min(cloud.mu.len() - 1);
            around(d, cloud.mu[i], 2.0 * PI * rng.uniform())
        },
    ));
    let mix_density = mix.density(d);
    let Sampler::Mixture(parts) = &mix else { unreachable!() };
    outcomes.push(run_case(
        "WRONG: mixture picked 0.4/0.6, not 0.3/0.7",
        940,
        d,
        &*mix_density,
        &mix.kinks(),
        &mut |rng| {
            let i = pick_weighted(rng.uniform(), 2, |i| [0.4, 0.6][i]);
            sample_phase(&parts[i].1, d, rng)
        },
    ));
    for o in &outcomes {
        o.print(alpha);
    }
    // The uniform sphere must be caught by its samples where the cosine
    // lobe is zero, not only by the statistic.
    assert!(outcomes.iter().any(|o| o.name.contains("uniform sphere") && o.zero_density_samples > 0));
    for o in &outcomes {
        assert!(o.normalisation_error < 1e-4, "{}: normalisation {:.2e}", o.name, o.normalisation_error);
        assert!(
            o.rejected(alpha),
            "{}: a wrong sampler passed, χ² = {:.2} with {} dof, p = {:.3e} ≥ α = {alpha:.3e}",
            o.name,
            o.chi2,
            o.dof,
            o.p_value
        );
    }
}
