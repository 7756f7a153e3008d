//! The diffuse radiance at the ground of a layered atmosphere, by discrete
//! ordinates in Fourier modes of azimuth, layer operators (`operator`) and
//! the adding method, with the single scattering exact. Plane-parallel
//! layers exactly; spherical shells pseudo-spherically (`Paths`: the
//! sun's beam and the views run straight through the shells).
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
use super::legendre::normalised_associated;
use super::linalg::{Lu, Mat};
use super::operator::{lambdas, LayerMatrices, Streams};
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
/// a hemisphere. The single scattering is the layers' closed form, which
/// holds in a plane-parallel atmosphere (`render` uses the path tracer's
/// quadrature instead, in any geometry).
pub fn ground_radiance(layers: &Layers, streams: usize, mu0: f64, views: &[View]) -> Vec<f64> {
    let diffuse = Diffuse::solve(layers, streams, mu0, views.iter().map(|v| v.mu).collect());
    views
        .iter()
        .enumerate()
        .map(|(k, v)| single_scattering(layers, mu0, v) + diffuse.at_node(k, v.azimuth_from_sun_rad))
        .collect()
}

/// The light scattered two or more times that reaches the ground, per unit
/// solar irradiance normal to the beam: its Fourier modes in azimuth at a
/// set of view cosines (`nodes`), and the irradiance on the ground.
#[derive(Debug, Clone)]
pub struct Diffuse {
    /// The view cosines the modes are evaluated at (> 0: looking up).
    pub nodes: Vec<f64>,
    /// `modes[m][k]`: the mode-m radiance at node k, sr⁻¹; the radiance is
    /// Σ_m modes[m][k] cos(m φ) for φ the azimuth from the sun.
    pub modes: Vec<Vec<f64>>,
    /// The irradiance on a horizontal ground, direct (delta-M scaled, so
    /// that the forward peak's light counts once) and diffuse.
    pub ground_irradiance: f64,
}

impl Diffuse {
    /// Solves mode after mode until two in a row add less than 1e-6 of the
    /// mode-0 radiance at every node. A sun below the horizon lights
    /// nothing in a plane-parallel atmosphere.
    pub fn solve(layers: &Layers, streams: usize, mu0: f64, nodes: Vec<f64>) -> Diffuse {
        if mu0 <= 0.0 && layers.shell_radius_km.is_none() {
            return Diffuse { modes: vec![vec![0.0; nodes.len()]], nodes, ground_irradiance: 0.0 };
        }
        let s = Streams::new(streams);
        let scaled = delta_m(layers, 2 * streams);
        let paths = Paths::new(layers, &scaled, mu0, &nodes);
        let mut modes: Vec<Vec<f64>> = Vec::new();
        let mut ground_irradiance = 0.0;
        let mut quiet = 0;
        for m in 0..2 * streams {
            let (mode, diffuse_flux) = multiple_scattering_mode(&s, &scaled, layers.ground_albedo, mu0, m, &paths);
            if m == 0 {
                ground_irradiance = mu0.max(0.0) * paths.beam[scaled.len()] + diffuse_flux;
            }
            let largest = mode
                .iter()
                .zip(modes.first().unwrap_or(&mode).iter())
                .map(|(x, z)| x.abs() / z.abs().max(1e-300))
                .fold(0.0, f64::max);
            modes.push(mode);
            quiet = if m > 0 && largest < 1e-6 { quiet + 1 } else { 0 };
            if quiet == 2 {
                break;
            }
        }
        Diffuse { nodes, modes, ground_irradiance }
    }

    /// The radiance at node `k` and azimuth `phi` from the sun.
    pub fn at_node(&self, k: usize, phi: f64) -> f64 {
        self.modes.iter().enumerate().map(|(m, mode)| mode[k] * (m as f64 * phi).cos()).sum()
    }
}

/// A layer after delta-M scaling.
#[derive(Debug, Clone)]
pub(super) struct Scaled {
    pub tau: f64,
    pub omega: f64,
    pub chi: Vec<f64>,
}

pub(super) fn delta_m(layers: &Layers, moments: usize) -> Vec<Scaled> {
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

/// The straight paths the solution needs through its layers (delta-M
/// scaled optical depths): the sun's, from each interface up, and each
/// view's, from the ground up. In a plane-parallel atmosphere a path across
/// a layer is its thickness over the cosine; in spherical shells (the
/// pseudo-spherical approximation: the diffuse light of each altitude is
/// that of a plane-parallel column, but the sun's beam reaching it and the
/// views leaving the ground run straight through curved shells) it is the
/// chord between the shells, and a view's cosine grows with altitude.
pub(super) struct Paths {
    /// The direct beam's transmittance to each interface, top down.
    pub(super) beam: Vec<f64>,
    /// Each layer's average secant along the sun's path (DISORT's CHAPMN):
    /// the slant optical depth across it per unit of its vertical depth.
    secant: Vec<f64>,
    /// Per view: its cosine at each interface, and its optical path across
    /// each layer.
    views: Vec<(Vec<f64>, Vec<f64>)>,
}

impl Paths {
    pub(super) fn new(layers: &Layers, scaled: &[Scaled], mu0: f64, view_mu: &[f64]) -> Paths {
        let nl = scaled.len();
        let radius = layers.shell_radius_km;
        let z: Vec<f64> = std::iter::once(layers.layers.first().map_or(0.0, |l| l.top_km))
            .chain(layers.layers.iter().map(|l| l.bottom_km))
            .collect();
        // Scaled extinction of each (homogeneous) layer, km⁻¹.
        let sigma: Vec<f64> = scaled.iter().enumerate().map(|(k, l)| l.tau / (z[k] - z[k + 1])).collect();
        let slant: Vec<f64> = (0..=nl).map(|i| slant_to_sun(radius, &z, &sigma, z[i], mu0)).collect();
        // The beam's profile across layer k: e^{−secant t} between its top's
        // and its base's transmittance (where the Earth's shadow falls
        // inside a layer, the beam is taken to die out within it).
        let secant = (0..nl)
            .map(|k| match radius {
                Some(_) if scaled[k].tau > 0.0 && slant[k].is_finite() => {
                    ((slant[k + 1] - slant[k]) / scaled[k].tau).clamp(1e-6, 1e6)
                }
                Some(_) => 1.0,
                None if mu0 > 0.0 => 1.0 / mu0,
                None => 1.0,
            })
            .collect();
        let views = view_mu
            .iter()
            .map(|&u| {
                let cosines = z.iter().map(|&zi| cosine_at(radius, u, zi)).collect();
                let optical = (0..nl).map(|k| sigma[k] * chord_km(radius, 0.0, u, z[k + 1], z[k])).collect();
                (cosines, optical)
            })
            .collect();
        Paths { beam: slant.iter().map(|t| (-t).exp()).collect(), secant, views }
    }
}

/// The direct beam's transmittance from the top of the atmosphere to the
/// ground (unscaled optical depths, along the sun's straight path through
/// the shells where the layers are spherical).
pub fn sun_transmittance(layers: &Layers, mu0: f64) -> f64 {
    if mu0 <= 0.0 {
        return 0.0;
    }
    let slant: f64 = layers
        .layers
        .iter()
        .map(|l| l.tau / (l.top_km - l.bottom_km) * chord_km(layers.shell_radius_km, 0.0, mu0, l.bottom_km, l.top_km))
        .sum();
    (-slant).exp()
}

/// The length (km) between altitudes `z_lo` < `z_hi` of a straight ray
/// that leaves altitude `z0` ≤ `z_lo` upward at zenith cosine `u` > 0: the
/// thickness over `u` in a plane-parallel atmosphere; in shells about a
/// centre `radius` below the ground, the difference of √((R + z)² − b²)
/// between the ends, with b = (R + z0) √(1 − u²) the ray's impact
/// parameter.
pub(super) fn chord_km(radius: Option<f64>, z0: f64, u: f64, z_lo: f64, z_hi: f64) -> f64 {
    match radius {
        None => (z_hi - z_lo) / u,
        Some(r) => {
            let b2 = (r + z0) * (r + z0) * (1.0 - u * u);
            let along = |z: f64| ((r + z) * (r + z) - b2).max(0.0).sqrt();
            along(z_hi) - along(z_lo)
        }
    }
}

/// The optical depth (delta-M scaled extinctions `sigma` of the layers
/// between interfaces `z`, top down) from altitude `z0` to the sun, whose
/// zenith cosine there is `mu0`. A sun above the local horizon: the path
/// straight up through the shells. A sun below it (shells only): the path
/// dips to its tangent altitude b − R, b = (R + z₀) √(1 − μ₀²), crossing
/// the shells between it and z₀ twice, unless the Earth is in the way
/// (b < R: infinite, the point is in the Earth's shadow).
pub(super) fn slant_to_sun(radius: Option<f64>, z: &[f64], sigma: &[f64], z0: f64, mu0: f64) -> f64 {
    let layers = z.windows(2).zip(sigma).map(|(w, &s)| (w[1], w[0], s));
    let Some(r) = radius else {
        return if mu0 > 0.0 {
            layers.filter(|l| l.1 > z0).map(|(lo, hi, s)| s * (hi - lo.max(z0)) / mu0).sum()
        } else {
            f64::INFINITY
        };
    };
    let b = (r + z0) * (1.0 - mu0 * mu0).max(0.0).sqrt();
    if mu0 < 0.0 && b < r {
        return f64::INFINITY;
    }
    let along = |z: f64| ((r + z) * (r + z) - b * b).max(0.0).sqrt();
    let tangent_km = if mu0 < 0.0 { b - r } else { z0 };
    layers
        .map(|(lo, hi, s)| {
            let above = if hi > z0 { along(hi) - along(lo.max(z0)) } else { 0.0 };
            let (a, c) = (lo.max(tangent_km), hi.min(z0));
            let dip = if c > a { 2.0 * (along(c) - along(a)) } else { 0.0 };
            s * (above + dip)
        })
        .sum()
}

/// The zenith cosine at altitude `z` of a ray that leaves the ground at
/// zenith cosine `u` > 0 (the same everywhere in a plane-parallel
/// atmosphere; in shells its sine falls as R / (R + z)).
pub(super) fn cosine_at(radius: Option<f64>, u: f64, z: f64) -> f64 {
    match radius {
        None => u,
        Some(r) => {
            let sine = r / (r + z) * (1.0 - u * u).max(0.0).sqrt();
            (1.0 - sine * sine).max(0.0).sqrt()
        }
    }
}

/// The diffuse radiance down (`.0`) and up (`.1`) the streams at each
/// interface, top down.
pub(super) type Fields = (Vec<Vec<f64>>, Vec<Vec<f64>>);

/// The sun-independent part of one mode's adding: the layers' matrices,
/// the reflections of everything below (`rg`) and above (`rs`) each
/// interface, and the factorised systems the adding solves (module
/// documentation, step 2).
pub(super) struct ModeMatrices {
    ops: Vec<LayerMatrices>,
    rg: Vec<Mat>,
    /// (I − R_g,k+1 R_k), factorised, for layer k.
    below: Vec<Lu>,
    rs: Vec<Mat>,
    /// (I − R*_k R_k), factorised, for layer k (the medium above it).
    above: Vec<Lu>,
    /// (I − R*_k R_g,k), factorised, at interface k.
    between: Vec<Lu>,
    /// Whether the ground reflects this mode (mode 0 over a bright ground).
    lambertian: bool,
}

impl ModeMatrices {
    pub(super) fn new(s: &Streams, layers: &[Scaled], albedo: f64, m: usize) -> ModeMatrices {
        let (n, nl) = (s.n(), layers.len());
        let ops: Vec<LayerMatrices> = layers.iter().map(|l| LayerMatrices::new(s, m, l.tau, l.omega, &l.chi)).collect();
        let mut rg = vec![Mat::zeros(n); nl + 1];
        if m == 0 && albedo > 0.0 {
            for i in 0..n {
                for j in 0..n {
                    rg[nl].set(i, j, 2.0 * albedo * s.w[j] * s.mu[j]);
                }
            }
        }
        let mut below = Vec::with_capacity(nl);
        for k in (0..nl).rev() {
            let op = &ops[k];
            let g = rg[k + 1].mul(&op.r).one_minus().lu().expect("the medium below reflects less than all");
            rg[k] = op.r.add_scaled(&op.t.mul(&g.solve(&rg[k + 1].mul(&op.t))), 1.0);
            below.push(g);
        }
        below.reverse();
        let mut rs = vec![Mat::zeros(n)];
        let mut above = Vec::with_capacity(nl);
        for op in &ops {
            let last = rs.last().expect("starts with the top");
            let g = last.mul(&op.r).one_minus().lu().expect("the medium above reflects less than all");
            let next = op.r.add_scaled(&op.t.mul(&g.solve(&last.mul(&op.t))), 1.0);
            above.push(g);
            rs.push(next);
        }
        let between = (0..=nl)
            .map(|k| rs[k].mul(&rg[k]).one_minus().lu().expect("the two sides reflect less than all"))
            .collect();
        ModeMatrices { ops, rg, below, rs, above, between, lambertian: m == 0 && albedo > 0.0 }
    }

    /// The diffuse radiance down (`.0`) and up (`.1`) the streams at each
    /// interface, top down, for a sun of cosine `mu0` (negative: below the
    /// local horizon) whose beam reaches the interfaces as `paths` says.
    pub(super) fn fields(&self, s: &Streams, albedo: f64, mu0: f64, paths: &Paths) -> Fields {
        let (n, nl) = (s.n(), self.ops.len());
        let beam = &paths.beam;
        let src: Vec<(Vec<f64>, Vec<f64>)> =
            self.ops.iter().zip(&paths.secant).map(|(op, &sec)| op.sources(s, mu0, sec)).collect();
        let ground = if self.lambertian { vec![albedo * mu0.max(0.0) * beam[nl] / PI; n] } else { vec![0.0; n] };
        self.fields_of(&src, beam, ground)
    }

    /// The diffuse radiance down and up the streams at each interface when
    /// a source J (`sources[k]`: J along the downward streams, then the
    /// upward), the same at every depth of layer k, adds to each layer's
    /// radiance equation; nothing enters at the top and the ground emits
    /// nothing of its own.
    pub(super) fn fields_of_uniform(&self, s: &Streams, sources: &[(Vec<f64>, Vec<f64>)]) -> Fields {
        let src: Vec<(Vec<f64>, Vec<f64>)> =
            self.ops.iter().zip(sources).map(|(op, (down, up))| op.uniform_sources(s, down, up)).collect();
        self.fields_of(&src, &vec![1.0; src.len()], vec![0.0; s.n()])
    }

    /// The adding of the layers' diffuse sources (what layer k sends down
    /// out of its base and up out of its top: `scale[k]` times `src[k]`)
    /// and the radiance `ground` the ground sends up of its own.
    fn fields_of(&self, src: &[(Vec<f64>, Vec<f64>)], scale: &[f64], ground: Vec<f64>) -> Fields {
        let (n, nl) = (ground.len(), self.ops.len());
        // From the ground up: the radiance Û_k everything below sends up.
        let mut ug = vec![vec![0.0; n]; nl + 1];
        ug[nl] = ground;
        for k in (0..nl).rev() {
            let op = &self.ops[k];
            let below = self.rg[k + 1].mul_vec(&src[k].0);
            let into: Vec<f64> = below.iter().zip(&ug[k + 1]).map(|(a, b)| scale[k] * a + b).collect();
            let up_into = self.below[k].solve_vec(&into);
            let t_up = op.t.mul_vec(&up_into);
            ug[k] = t_up.iter().zip(&src[k].1).map(|(a, b)| a + scale[k] * b).collect();
        }
        // From the top down, and the fields at each interface.
        let mut ds = vec![0.0; n];
        let mut down = vec![vec![0.0; n]; nl + 1];
        let mut up = vec![vec![0.0; n]; nl + 1];
        for k in 0..=nl {
            if k > 0 {
                let (op, (s_down, s_up)) = (&self.ops[k - 1], &src[k - 1]);
                let rsu = self.rs[k - 1].mul_vec(s_up);
                let into = self.above[k - 1]
                    .solve_vec(&ds.iter().zip(&rsu).map(|(d, r)| d + scale[k - 1] * r).collect::<Vec<_>>());
                let t_into = op.t.mul_vec(&into);
                ds = t_into.iter().zip(s_down).map(|(a, b)| a + scale[k - 1] * b).collect();
            }
            let rsu = self.rs[k].mul_vec(&ug[k]);
            down[k] = self.between[k].solve_vec(&ds.iter().zip(&rsu).map(|(d, r)| d + r).collect::<Vec<_>>());
            let rgd = self.rg[k].mul_vec(&down[k]);
            up[k] = rgd.iter().zip(&ug[k]).map(|(a, b)| a + b).collect();
        }
        (down, up)
    }
}

/// The source's coefficients at each interface (module documentation,
/// step 3): J^m(u) at interface i in layer k is
/// (ω_k/2) Σ_l (2l + 1) χ_kl Λ_l^m(u) a_l(i), with
/// a_l(i) = Σ_j w_j [Λ_l^m(μ_j) D_ij + Λ_l^m(−μ_j) U_ij] the same for every
/// layer: the phase function's sum is done once per interface, not per view.
pub(super) fn source_coefficients(s: &Streams, m: usize, down: &[Vec<f64>], up: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let plus = lambdas(&s.mu, m, s.lmax);
    let minus = lambdas(&s.mu.iter().map(|u| -u).collect::<Vec<_>>(), m, s.lmax);
    down.iter()
        .zip(up)
        .map(|(d, u)| {
            (0..=s.lmax).map(|l| (0..s.n()).map(|j| s.w[j] * (plus[j][l] * d[j] + minus[j][l] * u[j])).sum()).collect()
        })
        .collect()
}

/// The source J^m of layer `l` at an interface with coefficients `a`, for
/// Λ^m at the view's cosine there.
pub(super) fn source(l: &Scaled, m: usize, lmax: usize, lam: &[f64], a: &[f64]) -> f64 {
    0.5 * l.omega * (m..=lmax).map(|k| (2 * k + 1) as f64 * l.chi[k] * lam[k] * a[k]).sum::<f64>()
}

/// Each layer's source, linear in optical path `x` across it between
/// `j_top` and `j_base`, seen from below its base:
/// ∫₀ˣ J(s) e^{−s} ds with s the path from the base.
pub(super) fn through_layer(j_top: f64, j_base: f64, x: f64) -> f64 {
    let (base, top) = through_layer_weights(x);
    j_base * base + j_top * top
}

/// `through_layer`'s weights of the source at the base and at the top
/// of a layer of optical thickness `x`: (1 − q, q − e^{−x}) with
/// q = (1 − e^{−x}) / x.
pub(super) fn through_layer_weights(x: f64) -> (f64, f64) {
    let e = (-x).exp();
    // (1 − e^{−x}) / x, by its series for thin layers.
    let q = if x < 1e-5 { 1.0 - 0.5 * x + x * x / 6.0 } else { -(-x).exp_m1() / x };
    (1.0 - q, q - e)
}

/// The mode-m radiance of the light scattered two or more times at each
/// view, and (mode 0) the diffuse irradiance on the ground.
fn multiple_scattering_mode(
    s: &Streams,
    layers: &[Scaled],
    albedo: f64,
    mu0: f64,
    m: usize,
    paths: &Paths,
) -> (Vec<f64>, f64) {
    let (n, nl) = (s.n(), layers.len());
    let (down, up) = ModeMatrices::new(s, layers, albedo, m).fields(s, albedo, mu0, paths);
    let diffuse_flux = 2.0 * PI * (0..n).map(|j| s.w[j] * s.mu[j] * down[nl][j]).sum::<f64>();
    let a = source_coefficients(s, m, &down, &up);
    let radiance = paths
        .views
        .iter()
        .map(|(cosines, optical)| {
            // Λ^m at the view's cosine at each interface, computed once per
            // distinct cosine (one for all of them in a plane-parallel
            // atmosphere): `which[i]` indexes `lam`.
            let (mut lam, mut which): (Vec<Vec<f64>>, Vec<usize>) = (Vec::new(), Vec::with_capacity(nl + 1));
            for (i, &u) in cosines.iter().enumerate() {
                if i == 0 || cosines[i - 1] != u {
                    lam.push(normalised_associated(s.lmax, m, u));
                }
                which.push(lam.len() - 1);
            }
            // From the ground up: each layer's source, attenuated by the
            // layers below.
            let (mut radiance, mut below) = (0.0f64, 0.0f64);
            for k in (0..nl).rev() {
                let l = &layers[k];
                let j_top = source(l, m, s.lmax, &lam[which[k]], &a[k]);
                let j_base = source(l, m, s.lmax, &lam[which[k + 1]], &a[k + 1]);
                radiance += through_layer(j_top, j_base, optical[k]) * (-below).exp();
                below += optical[k];
            }
            radiance
        })
        .collect();
    (radiance, diffuse_flux)
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The optical depth to the sun through the shells against a plain
    /// march along the straight line (steps of 5 m), for suns above and
    /// below the local horizon; a sun whose line meets the ground leaves
    /// the point in the Earth's shadow.
    #[test]
    fn the_slant_to_the_sun_is_the_straight_line_s() {
        let radius = 6371.0;
        let z = [100.0, 50.0, 20.0, 10.0, 5.0, 0.0];
        let sigma = [0.001, 0.01, 0.05, 0.1, 0.2];
        let sigma_at = |alt: f64| -> f64 {
            z.windows(2).zip(&sigma).find(|(w, _)| alt >= w[1] && alt < w[0]).map_or(0.0, |(_, s)| *s)
        };
        let march = |z0: f64, mu0: f64| -> f64 {
            let (dx, dy) = ((1.0 - mu0 * mu0).sqrt(), mu0);
            let (step, mut sum) = (0.005, 0.0);
            for k in 0.. {
                let t = (k as f64 + 0.5) * step;
                let (x, y) = (t * dx, radius + z0 + t * dy);
                let alt = (x * x + y * y).sqrt() - radius;
                if alt < 0.0 {
                    return f64::INFINITY;
                }
                if alt > z[0] && y * dy + x * dx > 0.0 {
                    return sum;
                }
                sum += sigma_at(alt) * step;
            }
            unreachable!()
        };
        for (z0, mu0) in [(0.0, 0.5), (7.0, 0.05), (30.0, -0.05), (60.0, -0.1), (12.0, -0.02), (10.0, -0.2)] {
            let (got, want) = (slant_to_sun(Some(radius), &z, &sigma, z0, mu0), march(z0, mu0));
            if want.is_infinite() {
                assert!(got.is_infinite(), "altitude {z0}, sun cosine {mu0}: {got} where the Earth is in the way");
            } else {
                assert!((got / want - 1.0).abs() < 1e-3, "altitude {z0}, sun cosine {mu0}: {got} against {want}");
            }
        }
        assert!(slant_to_sun(Some(radius), &z, &sigma, 10.0, -0.2).is_infinite());
        assert!(slant_to_sun(None, &z, &sigma, 10.0, -0.01).is_infinite());
    }
}
