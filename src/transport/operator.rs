//! One homogeneous layer as an operator on the quadrature streams of one
//! Fourier mode: its reflection R and transmission T (the same from above
//! and from below: a homogeneous layer is symmetric), and the diffuse
//! radiance it sends down out of its base (S⁺) and up out of its top (S⁻)
//! per unit of the direct beam's irradiance at its top.
//!
//! The equation of mode m (τ downward, u the cosine of a stream's direction
//! with the downward vertical, so u > 0 travels down; see `legendre` for
//! p^m):
//!
//!   u dI^m/dτ = −I^m + (ω/2) ∫₋₁¹ p^m(u, u′) I^m(u′) du′ + Q^m(u) e^{−τ/μ₀},
//!   p^m(u, u′) = Σ_{l≥m} (2l + 1) χ_l Λ_l^m(u) Λ_l^m(u′),
//!   Q^m(u) = ω F₀ (2 − δ_m0) p^m(u, μ₀) / 4π,
//!
//! on the streams ±μ_i of the double-Gauss rule. A thin layer δ starts by
//! the diamond (trapezoidal) rule in τ, whose transmission and reflection
//! are a Cayley transform of the streams' coupling and so conserve flux
//! exactly when ω = 1; doubling (van de Hulst 1963; Hansen 1971; the
//! "adding-doubling" of de Haan, Bosma and Hovenier 1987) then builds the
//! layer from 2ⁿ copies:
//!
//!   R₂ = R + T G R T,   T₂ = T G T,   G = (I − R R)⁻¹,
//!
//! the beam's sources following the same interaction principle, the lower
//! copy lit by the beam that crossed the upper, e^{−τ/μ₀}.

use super::legendre::normalised_associated;
use super::linalg::{Lu, Mat};
use std::f64::consts::PI;

/// The thickest sub-layer the diamond rule starts from.
pub const DIAMOND_TAU: f64 = 1e-4;

/// The half-range quadrature and the normalised associated Legendre
/// functions at its nodes.
#[derive(Debug, Clone)]
pub struct Streams {
    pub mu: Vec<f64>,
    pub w: Vec<f64>,
    /// The largest moment kept (2N − 1 for N streams a hemisphere).
    pub lmax: usize,
}

impl Streams {
    pub fn new(per_hemisphere: usize) -> Streams {
        let (mu, w) = super::legendre::half_range(per_hemisphere);
        Streams { mu, w, lmax: 2 * per_hemisphere - 1 }
    }

    pub fn n(&self) -> usize {
        self.mu.len()
    }
}

/// p^m between two sets of cosines, given Λ_l^m at each.
pub fn mode_phase(chi: &[f64], lam_a: &[Vec<f64>], lam_b: &[Vec<f64>], m: usize, lmax: usize) -> Vec<Vec<f64>> {
    lam_a
        .iter()
        .map(|a| lam_b.iter().map(|b| (m..=lmax).map(|l| (2 * l + 1) as f64 * chi[l] * a[l] * b[l]).sum()).collect())
        .collect()
}

/// Λ_l^m at each cosine.
pub fn lambdas(mus: &[f64], m: usize, lmax: usize) -> Vec<Vec<f64>> {
    mus.iter().map(|&u| normalised_associated(lmax, m, u)).collect()
}

/// A layer's operator (see the module documentation).
#[derive(Debug, Clone)]
pub struct Operator {
    pub r: Mat,
    pub t: Mat,
    pub s_down: Vec<f64>,
    pub s_up: Vec<f64>,
}

/// The mode-m operator of a layer of optical depth `tau`, single-scattering
/// albedo `omega` and (truncated) moments `chi`, lit by a beam of cosine
/// `mu0` (F₀ = 1) that loses e^{−secant t} across a vertical optical depth
/// t of the layer: `secant` is 1/μ₀ in a plane-parallel atmosphere, and the
/// layer's average secant along the sun's curved path in shells
/// (pseudo-spherical, as DISORT's CHAPMN).
pub fn layer(s: &Streams, m: usize, tau: f64, omega: f64, chi: &[f64], mu0: f64, secant: f64) -> Operator {
    let matrices = LayerMatrices::new(s, m, tau, omega, chi);
    let (s_down, s_up) = matrices.sources(s, mu0, secant);
    Operator { r: matrices.r.clone(), t: matrices.t.clone(), s_down, s_up }
}

/// The part of a layer's operator that no sun changes: R and T, and what
/// the beam's sources need from the diamond start and from each doubling
/// (so that many suns share one set of matrices).
#[derive(Debug, Clone)]
pub struct LayerMatrices {
    pub r: Mat,
    pub t: Mat,
    /// The diamond start's two factorised systems (module documentation).
    start: (Lu, Lu),
    /// The thin sub-layer the diamond rule starts from.
    delta: f64,
    /// R, T and G = (I − R R)⁻¹ (factorised) of each copy before it is
    /// doubled.
    levels: Vec<(Mat, Mat, Lu)>,
    /// (ω k_m / 4π) (2l + 1) χ_l Λ_l^m(±μ_i): with Λ_l^m(μ₀) it makes the
    /// beam's source into the downward (`plus`) and upward streams.
    plus: Vec<Vec<f64>>,
    minus: Vec<Vec<f64>>,
    m: usize,
}

impl LayerMatrices {
    pub fn new(s: &Streams, m: usize, tau: f64, omega: f64, chi: &[f64]) -> LayerMatrices {
        let n = s.n();
        let plus = lambdas(&s.mu, m, s.lmax);
        let minus: Vec<f64> = s.mu.iter().map(|u| -u).collect();
        let minus = lambdas(&minus, m, s.lmax);
        let pp = mode_phase(chi, &plus, &plus, m, s.lmax);
        let pm = mode_phase(chi, &plus, &minus, m, s.lmax);
        let k_m = if m == 0 { 1.0 } else { 2.0 };
        let weigh = |lam: &Vec<Vec<f64>>| -> Vec<Vec<f64>> {
            lam.iter()
                .map(|a| {
                    (0..=s.lmax)
                        .map(
                            |l| if l < m { 0.0 } else { omega * k_m / (4.0 * PI) * (2 * l + 1) as f64 * chi[l] * a[l] },
                        )
                        .collect()
                })
                .collect()
        };

        let doublings = if tau > DIAMOND_TAU { (tau / DIAMOND_TAU).log2().ceil() as u32 } else { 0 };
        let delta = tau / 2f64.powi(doublings as i32);
        // Diamond start: a = (δ/2) M⁻¹ (I − (ω/2) P⁺⁺ W), b = (δ/2) M⁻¹ (ω/2) P⁺⁻ W.
        let (mut a, mut b) = (Mat::zeros(n), Mat::zeros(n));
        for i in 0..n {
            let h = 0.5 * delta / s.mu[i];
            for j in 0..n {
                let diag = if i == j { 1.0 } else { 0.0 };
                a.set(i, j, h * (diag - 0.5 * omega * pp[i][j] * s.w[j]));
                b.set(i, j, h * 0.5 * omega * pm[i][j] * s.w[j]);
            }
        }
        let id = Mat::identity(n);
        let p1 = id.add_scaled(&a, 1.0).add_scaled(&b, -1.0).lu().expect("diamond start is regular");
        let p2 = id.add_scaled(&a, 1.0).add_scaled(&b, 1.0).lu().expect("diamond start is regular");
        let x = p1.solve(&id.add_scaled(&a, -1.0).add_scaled(&b, 1.0));
        let y = p2.solve(&id.add_scaled(&a, -1.0).add_scaled(&b, -1.0));
        let mut r = x.add_scaled(&y, -1.0);
        let mut t = x.add_scaled(&y, 1.0);
        for v in r.a.iter_mut().chain(t.a.iter_mut()) {
            *v *= 0.5;
        }
        let mut levels = Vec::with_capacity(doublings as usize);
        for _ in 0..doublings {
            let g = r.mul(&r).one_minus().lu().expect("I − R R is regular for a layer that absorbs or transmits");
            let (r2, t2) = (r.add_scaled(&t.mul(&g.solve(&r.mul(&t))), 1.0), t.mul(&g.solve(&t)));
            levels.push((r, t, g));
            (r, t) = (r2, t2);
        }
        LayerMatrices { r, t, start: (p1, p2), delta, levels, plus: weigh(&plus), minus: weigh(&minus), m }
    }

    /// The diffuse radiance the layer sends down out of its base and up out
    /// of its top, per unit of a beam of cosine `mu0` at its top (F₀ = 1)
    /// that loses e^{−secant t} across a vertical optical depth t of it.
    /// A negative `mu0` is a beam that travels up (a sun below the local
    /// horizon lighting the air above the Earth's shadow), still weakening
    /// downward through the layer as `secant` says.
    pub fn sources(&self, s: &Streams, mu0: f64, secant: f64) -> (Vec<f64>, Vec<f64>) {
        let n = s.n();
        let beam = normalised_associated(s.lmax, self.m, mu0);
        let q = |c: &Vec<Vec<f64>>, i: usize| -> f64 { c[i].iter().zip(&beam).map(|(a, b)| a * b).sum() };
        let delta = self.delta;
        let e_mean = 0.5 * (1.0 + (-delta * secant).exp());
        let qd: Vec<f64> = (0..n).map(|i| delta * e_mean * q(&self.plus, i) / s.mu[i]).collect();
        let qu: Vec<f64> = (0..n).map(|i| delta * e_mean * q(&self.minus, i) / s.mu[i]).collect();
        self.build_sources(&qd, &qu, secant)
    }

    /// The diffuse radiance the layer sends down out of its base and up out
    /// of its top when a source J, the same at every depth of it, adds to
    /// its radiance equation (u dI/dτ = −I + scattering + J): `down[i]` is
    /// J along the downward stream i, `up[i]` along the upward one.
    pub fn uniform_sources(&self, s: &Streams, down: &[f64], up: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let delta = self.delta;
        let qd: Vec<f64> = down.iter().zip(&s.mu).map(|(j, u)| delta * j / u).collect();
        let qu: Vec<f64> = up.iter().zip(&s.mu).map(|(j, u)| delta * j / u).collect();
        self.build_sources(&qd, &qu, 0.0)
    }

    /// The diamond start's sources `qd`, `qu` (per stream, times δ/μ) of
    /// the thin sub-layer, doubled to the whole layer, the lower copy's
    /// weakened by e^{−secant t} across the upper's t.
    fn build_sources(&self, qd: &[f64], qu: &[f64], secant: f64) -> (Vec<f64>, Vec<f64>) {
        let delta = self.delta;
        let (p1, p2) = &self.start;
        let sum = p1.solve_vec(&qd.iter().zip(qu).map(|(d, u)| d + u).collect::<Vec<_>>());
        let diff = p2.solve_vec(&qd.iter().zip(qu).map(|(d, u)| d - u).collect::<Vec<_>>());
        let mut down: Vec<f64> = sum.iter().zip(&diff).map(|(a, b)| 0.5 * (a + b)).collect();
        let mut up: Vec<f64> = sum.iter().zip(&diff).map(|(a, b)| 0.5 * (a - b)).collect();
        let mut thickness = delta;
        for (r, t, g) in &self.levels {
            (down, up) = double_sources(r, t, g, &down, &up, (-thickness * secant).exp());
            thickness *= 2.0;
        }
        (down, up)
    }
}

/// The beam's sources of two copies of a symmetric layer (R, T, G its
/// matrices), the lower lit by the beam attenuated by `e` across the upper.
fn double_sources(r: &Mat, t: &Mat, g: &Lu, down: &[f64], up: &[f64], e: f64) -> (Vec<f64>, Vec<f64>) {
    let rs: Vec<f64> = r.mul_vec(up);
    let d = g.solve_vec(&down.iter().zip(&rs).map(|(s, r)| s + e * r).collect::<Vec<_>>());
    let rd = r.mul_vec(&d);
    let u: Vec<f64> = rd.iter().zip(up).map(|(a, b)| a + e * b).collect();
    let td = t.mul_vec(&d);
    let tu = t.mul_vec(&u);
    (td.iter().zip(down).map(|(a, b)| a + e * b).collect(), up.iter().zip(&tu).map(|(a, b)| a + b).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hg(g: f64, lmax: usize) -> Vec<f64> {
        (0..=lmax).map(|l| g.powi(l as i32)).collect()
    }

    /// With ω = 1 the mode-0 operator loses no flux: for radiance in any
    /// one stream j, Σ_i w_i μ_i (R_ij + T_ij) = w_j μ_j; and the beam's
    /// diffuse flux plus its direct part is the beam's. Thin to thick, the
    /// cloud's forward peak and Rayleigh.
    #[test]
    fn a_conservative_layer_conserves_flux() {
        let s = Streams::new(16);
        let n = s.n();
        for (tau, chi) in [
            (0.01, hg(0.85, 31)),
            (1.0, hg(0.85, 31)),
            (60.0, hg(0.85, 31)),
            (3.0, {
                let mut c = vec![0.0; 32];
                c[0] = 1.0;
                c[2] = 0.1;
                c
            }),
        ] {
            let mu0 = 0.5;
            let op = layer(&s, 0, tau, 1.0, &chi, mu0, 1.0 / mu0);
            for j in 0..n {
                let out: f64 = (0..n).map(|i| s.w[i] * s.mu[i] * (op.r.at(i, j) + op.t.at(i, j))).sum();
                let rel = (out - s.w[j] * s.mu[j]) / (s.w[j] * s.mu[j]);
                assert!(rel.abs() < 1e-4, "tau {tau}, stream {j}: relative flux error {rel:e}");
            }
            // Beam: 2π Σ w μ (S⁺ + S⁻) + μ₀ e^{−τ/μ₀} = μ₀.
            let diffuse: f64 = (0..n).map(|i| 2.0 * PI * s.w[i] * s.mu[i] * (op.s_down[i] + op.s_up[i])).sum();
            let rel = (diffuse + mu0 * (-tau / mu0).exp() - mu0) / mu0;
            assert!(rel.abs() < 1e-4, "tau {tau}: beam flux error {rel:e}");
        }
    }

    /// Reciprocity (Chandrasekhar 1960, §44): R_ij / (w_j μ_j) and
    /// T_ij / (w_j μ_j) are symmetric, for every mode, absorbing or not.
    #[test]
    fn the_operators_are_reciprocal() {
        let s = Streams::new(8);
        for m in [0, 1, 5] {
            let op = layer(&s, m, 2.5, 0.9, &hg(0.7, 15), 0.6, 1.0 / 0.6);
            for i in 0..s.n() {
                for j in 0..s.n() {
                    for mat in [&op.r, &op.t] {
                        let a = mat.at(i, j) / (s.w[j] * s.mu[j]);
                        let b = mat.at(j, i) / (s.w[i] * s.mu[i]);
                        assert!((a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1e-12), "m {m} ({i}, {j}): {a} {b}");
                    }
                }
            }
        }
    }
}
