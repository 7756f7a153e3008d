//! The diffuse radiance at the ground of a plane-parallel atmosphere, by
//! discrete ordinates in Fourier modes of azimuth, layer operators
//! (`operator`) and the adding method, with the single scattering exact.
//!
//! 1. Delta-M (Wiscombe 1977): with N streams a hemisphere, each layer's
//!    phase function keeps the moments below 2N, its forward peak
//!    f = χ_2N moves into the direct beam: χ′_l = (χ_l − f) / (1 − f),
//!    τ′ = (1 − ω f) τ, ω′ = ω (1 − f) / (1 − ω f).
//! 2. Per mode m, the layers' operators are added (Stamnes 1982's adding
//!    with internal fields, in the notation of `operator`): from the top
//!    down, the reflection R*_k of everything above interface k seen from
//!    below and the radiance D̂_k it sends down; from the ground up, the
//!    reflection R_g,k of everything below seen from above (the Lambertian
//!    ground reflects in mode 0 only: I⁻ = (A/π)(μ₀ F₀ e^{−τ′*/μ₀} + 2π Σ w μ I⁺))
//!    and the radiance Û_k it sends up. At each interface
//!    D_k = (I − R*_k R_g,k)⁻¹ (D̂_k + R*_k Û_k), U_k = R_g,k D_k + Û_k.
//! 3. The source of the light scattered twice or more, at a view cosine
//!    μ_v, is J^m(τ) = (ω′/2) Σ_j w_j [p′^m(μ_v, μ_j) D_j + p′^m(μ_v, −μ_j) U_j]
//!    at each layer's top and base (the direct beam left out); taken linear
//!    in τ′ across the layer, its integral to the ground,
//!    ∫ J e^{−(τ′* − τ′)/μ_v} dτ′/μ_v, is exact (Stamnes et al. 1988 do the
//!    same at user angles with their analytic layer solution).
//! 4. The single scattering, ω p(Θ) F₀ ∫ e^{−τ/μ₀} e^{−(τ* − τ)/μ_v} dτ/μ_v,
//!    in each homogeneous layer in closed form with the exact phase
//!    function and the unscaled optical depths (the "exact single
//!    scattering" of Nakajima and Tanaka 1988, which is what makes
//!    delta-M accurate outside the forward peak).
//!
//! Modes are summed until two in a row add less than 1e-6 of the mode-0
//! radiance at every view.

use super::layers::Layers;
use super::linalg::Mat;
use super::operator::{lambdas, layer, mode_phase, Operator, Streams};
use std::f64::consts::PI;

/// A view from the ground: the cosine of its zenith angle (> 0, looking up)
/// and its azimuth from the sun's, radians.
#[derive(Debug, Clone, Copy)]
pub struct View {
    pub mu: f64,
    pub azimuth_from_sun_rad: f64,
}

/// Diffuse radiance at the ground per unit solar irradiance normal to the
/// beam (sr⁻¹), for a sun of zenith cosine `mu0`, at each view; `streams`
/// a hemisphere.
pub fn ground_radiance(layers: &Layers, streams: usize, mu0: f64, views: &[View]) -> Vec<f64> {
    let s = Streams::new(streams);
    let scaled = delta_m(layers, 2 * streams);
    let mut out: Vec<f64> = views.iter().map(|v| single_scattering(layers, mu0, v)).collect();
    let mut quiet = 0;
    let mut mode0 = vec![0.0; views.len()];
    for m in 0..2 * streams {
        let modes = multiple_scattering_mode(&s, &scaled, layers.ground_albedo, mu0, m, views);
        if m == 0 {
            mode0 = modes.iter().map(|x| x.abs()).collect();
        }
        let mut largest = 0.0f64;
        for ((o, x), (v, z)) in out.iter_mut().zip(&modes).zip(views.iter().zip(&mode0)) {
            *o += x * (m as f64 * v.azimuth_from_sun_rad).cos();
            largest = largest.max(x.abs() / z.max(1e-300));
        }
        quiet = if m > 0 && largest < 1e-6 { quiet + 1 } else { 0 };
        if quiet == 2 {
            break;
        }
    }
    out
}

/// A layer after delta-M scaling.
#[derive(Debug, Clone)]
struct Scaled {
    tau: f64,
    omega: f64,
    chi: Vec<f64>,
}

fn delta_m(layers: &Layers, moments: usize) -> Vec<Scaled> {
    layers
        .layers
        .iter()
        .map(|l| {
            let f = l.chi.get(moments).copied().unwrap_or(0.0).max(0.0);
            let chi = (0..moments).map(|k| (l.chi[k] - f) / (1.0 - f)).collect();
            let tau = (1.0 - l.omega * f) * l.tau;
            let omega = if tau > 0.0 { l.omega * (1.0 - f) / (1.0 - l.omega * f) } else { 0.0 };
            Scaled { tau, omega, chi }
        })
        .collect()
}

/// The mode-m radiance of the light scattered two or more times at each view.
fn multiple_scattering_mode(
    s: &Streams,
    layers: &[Scaled],
    albedo: f64,
    mu0: f64,
    m: usize,
    views: &[View],
) -> Vec<f64> {
    let n = s.n();
    let nl = layers.len();
    let ops: Vec<Operator> = layers.iter().map(|l| layer(s, m, l.tau, l.omega, &l.chi, mu0)).collect();
    // Beam at each interface.
    let mut depth = vec![0.0; nl + 1];
    for k in 0..nl {
        depth[k + 1] = depth[k] + layers[k].tau;
    }
    let beam: Vec<f64> = depth.iter().map(|t| (-t / mu0).exp()).collect();
    // From the ground up.
    let mut rg = vec![Mat::zeros(n); nl + 1];
    let mut ug = vec![vec![0.0; n]; nl + 1];
    if m == 0 && albedo > 0.0 {
        for i in 0..n {
            for j in 0..n {
                rg[nl].set(i, j, 2.0 * albedo * s.w[j] * s.mu[j]);
            }
            ug[nl][i] = albedo * mu0 * beam[nl] / PI;
        }
    }
    for k in (0..nl).rev() {
        let op = &ops[k];
        let g = rg[k + 1].mul(&op.r).one_minus().lu().expect("the medium below reflects less than all");
        // Light entering layer k+1's top from below... (layer k spans interfaces k and k+1).
        let below = rg[k + 1].mul_vec(&op.s_down);
        let src: Vec<f64> = below.iter().zip(&ug[k + 1]).map(|(a, b)| beam[k] * a + b).collect();
        let up_into = g.solve_vec(&src);
        let t_up = op.t.mul_vec(&up_into);
        ug[k] = t_up.iter().zip(&op.s_up).map(|(a, b)| a + beam[k] * b).collect();
        rg[k] = op.r.add_scaled(&op.t.mul(&g.solve(&rg[k + 1].mul(&op.t))), 1.0);
    }
    // From the top down, and the fields at each interface.
    let mut rs = Mat::zeros(n);
    let mut ds = vec![0.0; n];
    let mut down = vec![vec![0.0; n]; nl + 1];
    let mut up = vec![vec![0.0; n]; nl + 1];
    for k in 0..=nl {
        if k > 0 {
            let op = &ops[k - 1];
            let g = rs.mul(&op.r).one_minus().lu().expect("the medium above reflects less than all");
            let rsu = rs.mul_vec(&op.s_up);
            let into = g.solve_vec(&ds.iter().zip(&rsu).map(|(d, r)| d + beam[k - 1] * r).collect::<Vec<_>>());
            let t_into = op.t.mul_vec(&into);
            ds = t_into.iter().zip(&op.s_down).map(|(a, b)| a + beam[k - 1] * b).collect();
            rs = op.r.add_scaled(&op.t.mul(&g.solve(&rs.mul(&op.t))), 1.0);
        }
        let g = rs.mul(&rg[k]).one_minus().lu().expect("the two sides reflect less than all");
        let rsu = rs.mul_vec(&ug[k]);
        down[k] = g.solve_vec(&ds.iter().zip(&rsu).map(|(d, r)| d + r).collect::<Vec<_>>());
        let rgd = rg[k].mul_vec(&down[k]);
        up[k] = rgd.iter().zip(&ug[k]).map(|(a, b)| a + b).collect();
    }
    // The source at each view, integrated to the ground.
    let plus = lambdas(&s.mu, m, s.lmax);
    let minus = lambdas(&s.mu.iter().map(|u| -u).collect::<Vec<_>>(), m, s.lmax);
    views
        .iter()
        .map(|v| {
            let lv = lambdas(&[v.mu], m, s.lmax);
            let mut radiance = 0.0;
            for k in 0..nl {
                let l = &layers[k];
                let pp = &mode_phase(&l.chi, &lv, &plus, m, s.lmax)[0];
                let pm = &mode_phase(&l.chi, &lv, &minus, m, s.lmax)[0];
                let j_at = |i: usize| -> f64 {
                    0.5 * l.omega * (0..n).map(|j| s.w[j] * (pp[j] * down[i][j] + pm[j] * up[i][j])).sum::<f64>()
                };
                let (j_top, j_base) = (j_at(k), j_at(k + 1));
                let x = l.tau / v.mu;
                let e = (-x).exp();
                // (1 − e^{−x}) / x, by its series for thin layers.
                let q = if x < 1e-5 { 1.0 - 0.5 * x + x * x / 6.0 } else { -(-x).exp_m1() / x };
                let through = j_base * (1.0 - q) + j_top * (q - e);
                radiance += through * (-(depth[nl] - depth[k + 1]) / v.mu).exp();
            }
            radiance
        })
        .collect()
}

/// Sunlight scattered once on its way to a view from the ground (module
/// documentation, step 4).
fn single_scattering(layers: &Layers, mu0: f64, v: &View) -> f64 {
    let cos_theta = (v.mu * mu0
        + (1.0 - v.mu * v.mu).max(0.0).sqrt() * (1.0 - mu0 * mu0).max(0.0).sqrt() * v.azimuth_from_sun_rad.cos())
    .clamp(-1.0, 1.0);
    let total = layers.total_tau();
    let c = 1.0 / mu0 - 1.0 / v.mu;
    let mut top = 0.0;
    let mut sum = 0.0;
    for l in &layers.layers {
        if l.tau > 0.0 && l.omega > 0.0 {
            // ∫ e^{−τ/μ₀ − (τ* − τ)/μ_v} dτ over the layer: e(top) ∫₀^Δ e^{−c s} ds,
            // or the difference of its ends where cΔ is large (neither overflows).
            let at = |t: f64| (-t / mu0 - (total - t) / v.mu).exp();
            let cd = c * l.tau;
            let integral = if cd.abs() < 1e-12 {
                at(top) * l.tau
            } else if cd.abs() < 1.0 {
                at(top) * -(-cd).exp_m1() / c
            } else {
                (at(top) - at(top + l.tau)) / c
            };
            sum += l.omega * layers.phase(l, cos_theta) * integral / v.mu;
        }
        top += l.tau;
    }
    sum
}
