//! Sun-angle columns: the source of the multiply scattered light where the
//! sun stands at different zenith angles, so that a view's ray, which in
//! spherical shells crosses ground where the sun stands higher or lower
//! (toward or away from it), reads the source of the ground it crosses.
//!
//! A column is the pseudo-spherical solution of `adding` for one local sun
//! zenith angle θ_s: the diffuse field at each altitude is that of a
//! horizontally homogeneous column, lit by the beam that reaches it along
//! the sun's true path through the shells; with the sun below the local
//! horizon (twilight), that beam travels up into the air above the Earth's
//! shadow. All columns of one wavelength share the sun-independent matrices
//! (`adding::ModeMatrices`): only the beam's sources and the adding's
//! vectors are per column.
//!
//! Along a ray from the observer, a point at arc angle α from it, in the
//! azimuth φ of the ray from the sun's, sees the sun at
//!   cos θ_s = cos α cos θ₀ + sin α sin θ₀ cos φ
//! (the spherical law of cosines), and the ray's azimuth from the local sun
//! follows from the scattering angle Θ, which is the same all along:
//!   cos φ_local = (cos Θ − μ μ_s) / (sin θ sin θ_s).
//! The source there is interpolated between the two nearest columns,
//! linearly in θ_s in its logarithm (the source falls nearly exponentially
//! as the sun sets) and linearly where it is not positive. TRANSPORT.md:
//! a single column, pseudo-spherical, is within 0.4 to 1.3 % of a spherical
//! solution to 88° and fails beyond 92°; what the columns leave out is the
//! light carried sideways between columns, the structure of deep twilight.

use super::adding::{chord_km, cosine_at, delta_m, source_coefficients, through_layer, ModeMatrices, Paths, Scaled};
use super::layers::Layers;
use super::legendre::normalised_associated;
use super::operator::Streams;
use std::f64::consts::PI;

/// The multiply scattered light's source for a set of local sun zenith
/// angles, at one wavelength, per unit solar irradiance normal to the beam.
#[derive(Debug, Clone)]
pub struct Columns {
    /// The local sun zenith angle of each column, radians, increasing.
    pub zenith_rad: Vec<f64>,
    /// `coef[c][m][i]`: the mode-m coefficients a_l (l = 0..=lmax) of
    /// column c at interface i (`adding::source_coefficients`), weighted by
    /// the phase function of the layer above the interface (`[0]`, empty at
    /// the top) and of the layer below it (`[1]`, empty at the ground):
    /// (ω/2) (2l + 1) χ_l a_l, so that J^m = Σ_l Λ_l^m(u) times these.
    coef: Vec<Vec<Vec<[Vec<f64>; 2]>>>,
    /// The irradiance on a horizontal ground under each column.
    pub ground_irradiance: Vec<f64>,
    layers: Vec<Scaled>,
    /// Each layer's optical depth before delta-M scaling.
    unscaled_tau: Vec<f64>,
    /// The interfaces' altitudes, top down, km.
    z_km: Vec<f64>,
    radius_km: Option<f64>,
    lmax: usize,
}

impl Columns {
    /// Solves every column, mode after mode, until two modes in a row
    /// change no column's source by more than 1e-6 of its mode 0.
    pub fn solve(layers: &Layers, streams: usize, zenith_rad: Vec<f64>) -> Columns {
        let solution = Solution::new(layers, streams, &zenith_rad);
        Columns::from_solution(layers, solution, zenith_rad)
    }

    /// The columns whose fields `solution` holds: each interface's
    /// coefficients weighted by the phase functions of the layers on its
    /// two sides.
    pub(super) fn from_solution(layers: &Layers, solution: Solution, zenith_rad: Vec<f64>) -> Columns {
        let Solution { s, scaled, a, ground_irradiance, .. } = solution;
        let nl = scaled.len();
        let coef = a
            .iter()
            .map(|column| {
                column
                    .iter()
                    .enumerate()
                    .map(|(m, interfaces)| {
                        (0..=nl)
                            .map(|i| {
                                let above =
                                    if i > 0 { weigh(&scaled[i - 1], s.lmax, m, &interfaces[i]) } else { Vec::new() };
                                let below =
                                    if i < nl { weigh(&scaled[i], s.lmax, m, &interfaces[i]) } else { Vec::new() };
                                [above, below]
                            })
                            .collect()
                    })
                    .collect()
            })
            .collect();
        Columns {
            zenith_rad,
            coef,
            ground_irradiance,
            layers: scaled,
            unscaled_tau: layers.layers.iter().map(|l| l.tau).collect(),
            z_km: interfaces_km(layers),
            radius_km: layers.shell_radius_km,
            lmax: s.lmax,
        }
    }

    /// The radiance of the light scattered twice or more that reaches the
    /// ground along rays looking up at zenith cosine `mu` > 0, at each
    /// azimuth of `phis` from the sun's, the sun at zenith angle
    /// `sun_zenith_rad` over the observer (within the columns' span).
    pub fn rays(&self, sun_zenith_rad: f64, mu: f64, phis: &[f64]) -> Vec<f64> {
        self.rays_for_suns(&[(sun_zenith_rad, phis)], mu).pop().expect("one sun")
    }

    /// `rays` for several suns at once (the slices of a bake), each with
    /// its azimuths: the sources of each column along the ray (the costly
    /// part, which does not depend on the sun) are evaluated once for all
    /// of them. Each sun's radiances are those `rays` gives it alone, bit
    /// for bit.
    pub fn rays_for_suns(&self, suns: &[(f64, &[f64])], mu: f64) -> Vec<Vec<f64>> {
        let (at, path) = (self.sources_along(suns, mu), self.path(mu));
        at.iter().map(|at| at.iter().map(|at| along(at, &path, f64::INFINITY).0).collect()).collect()
    }

    /// `rays` of the light last scattered within `reach_km` of the
    /// observer (the talk's global fog in front of an object;
    /// `render::fog`). The light that arrives is what was last scattered
    /// within the reach and what comes from beyond it, L(0) = F + T L(R),
    /// with T the true transmittance over the reach. The delta-M scaled
    /// medium's sum along the ray to the reach, F′ (the last layer in
    /// part, its source linear in optical path), has the scaled T′: it
    /// counts the light that the forward peak scatters within the reach as
    /// coming from beyond. So F = L(0) − T L(R) with L(R) = (L(0) − F′)/T′:
    /// F = L(0) − e^{−(τ − τ′)} (L(0) − F′), τ and τ′ the reach's optical
    /// paths before and after scaling. (Measured against the path tracer's
    /// Shadowed Fog, clear.toml, sun 60°, 5 km, views 80 and 88°: F′ was
    /// 3.8 and 4.7 % low.)
    pub fn rays_to(&self, sun_zenith_rad: f64, mu: f64, phis: &[f64], reach_km: f64) -> Vec<f64> {
        let (at, path) = (self.sources_along(&[(sun_zenith_rad, phis)], mu), self.path(mu));
        let unscaled: f64 = {
            let (mut travelled_km, mut tau) = (0.0, 0.0);
            for k in (0..path.len()).rev() {
                let (chord, optical) = path[k];
                let ratio = self.unscaled_tau[k] / self.layers[k].tau.max(1e-300);
                let part = ((reach_km - travelled_km) / chord).clamp(0.0, 1.0);
                tau += optical * ratio * part;
                travelled_km += chord;
                if travelled_km >= reach_km {
                    break;
                }
            }
            tau
        };
        at[0]
            .iter()
            .map(|at| {
                let (all, _) = along(at, &path, f64::INFINITY);
                let (within, scaled) = along(at, &path, reach_km);
                all - (scaled - unscaled).exp() * (all - within)
            })
            .collect()
    }

    /// The sources along the ray of zenith cosine `mu` from the ground, for
    /// each sun and azimuth of `suns`: `[sun][azimuth][interface]`, the
    /// source as the base of the layer above (`.0`) and as the top of the
    /// layer below (`.1`).
    fn sources_along(&self, suns: &[(f64, &[f64])], mu: f64) -> Vec<Vec<Vec<(f64, f64)>>> {
        let nl = self.layers.len();
        let modes = self.coef.first().map_or(0, |c| c.len());
        let sin_v = (1.0 - mu * mu).max(0.0).sqrt();
        // The source on each side of each interface, per sun and azimuth:
        // as the base of the layer above (`.0`) and as the top of the
        // layer below (`.1`).
        let mut at: Vec<Vec<Vec<(f64, f64)>>> =
            suns.iter().map(|(_, phis)| vec![vec![(0.0, 0.0); nl + 1]; phis.len()]).collect();
        let mut jm: Vec<[f64; 2]> = Vec::new();
        for i in 0..=nl {
            let (u, arc) = self.ray_at(mu, self.z_km[i]);
            let sin_u = (1.0 - u * u).max(0.0).sqrt();
            let lam: Vec<Vec<f64>> = (0..modes).map(|m| normalised_associated(self.lmax, m, u)).collect();
            // The columns each sun's points at this interface can fall
            // between, and those of all the suns.
            let spans: Vec<(usize, usize)> = suns
                .iter()
                .map(|&(sun, _)| {
                    let (lo, _) = bracket(&self.zenith_rad, (sun - arc).max(0.0));
                    let (hi, w_hi) = bracket(&self.zenith_rad, (sun + arc).min(PI));
                    (lo, if w_hi > 0.0 { hi + 1 } else { hi })
                })
                .collect();
            let first = spans.iter().map(|s| s.0).min().unwrap_or(0);
            let last = spans.iter().map(|s| s.1).max().unwrap_or(0);
            // J^m of each column on each side: `jm[(c − first) modes + m]`.
            jm.clear();
            for c in first..=last {
                for (m, lam_m) in lam.iter().enumerate() {
                    let w = &self.coef[c][m][i];
                    let dot = |w: &[f64]| -> f64 { w.iter().zip(lam_m).skip(m).map(|(a, b)| a * b).sum() };
                    jm.push([dot(&w[0]), dot(&w[1])]);
                }
            }
            for ((&(sun, phis), &(lo, hi)), at) in suns.iter().zip(&spans).zip(at.iter_mut()) {
                let (sin0, cos0) = (sun.sin(), sun.cos());
                for (p, phi) in phis.iter().enumerate() {
                    let cos_phi = phi.cos();
                    let cos_s = (arc.cos() * cos0 + arc.sin() * sin0 * cos_phi).clamp(-1.0, 1.0);
                    let sin_s = (1.0 - cos_s * cos_s).max(0.0).sqrt();
                    let cos_scattering = mu * cos0 + sin_v * sin0 * cos_phi;
                    let cos_local = if sin_u * sin_s > 1e-12 {
                        ((cos_scattering - u * cos_s) / (sin_u * sin_s)).clamp(-1.0, 1.0)
                    } else {
                        1.0
                    };
                    let (c, w) = bracket(&self.zenith_rad, cos_s.acos());
                    let (c, w) = (c.clamp(lo, hi), if c < lo || c >= hi { 0.0 } else { w });
                    // Σ_m J^m cos(m φ), cos(m φ) by its recurrence.
                    let value = |c: usize| -> [f64; 2] {
                        let (mut prev, mut cos_m) = (cos_local, 1.0);
                        let mut sum = [0.0; 2];
                        for j in &jm[(c - first) * modes..(c - first + 1) * modes] {
                            sum[0] += j[0] * cos_m;
                            sum[1] += j[1] * cos_m;
                            (prev, cos_m) = (cos_m, 2.0 * cos_local * cos_m - prev);
                        }
                        sum
                    };
                    let a = value(c);
                    let j = if w == 0.0 {
                        a
                    } else {
                        let b = value(c + 1);
                        [0, 1].map(|s| log_lerp(a[s], b[s], w))
                    };
                    at[p][i] = (j[0], j[1]);
                }
            }
        }
        at
    }

    /// The ray of zenith cosine `mu` from the ground through each layer:
    /// (chord km, optical path), bottom layer last.
    fn path(&self, mu: f64) -> Vec<(f64, f64)> {
        (0..self.layers.len())
            .map(|k| {
                let chord = chord_km(self.radius_km, 0.0, mu, self.z_km[k + 1], self.z_km[k]);
                (chord, self.layers[k].tau / (self.z_km[k] - self.z_km[k + 1]) * chord)
            })
            .collect()
    }

    /// The irradiance on the ground under a sun at `sun_zenith_rad`.
    pub fn ground_irradiance_at(&self, sun_zenith_rad: f64) -> f64 {
        let (c, w) = bracket(&self.zenith_rad, sun_zenith_rad);
        let g = &self.ground_irradiance;
        if w == 0.0 {
            g[c]
        } else {
            g[c] * (1.0 - w) + g[c + 1] * w
        }
    }

    /// A ray leaving the ground at zenith cosine `mu`: its zenith cosine at
    /// altitude `z` km and the arc angle (radians) from the observer to the
    /// ground below it there.
    fn ray_at(&self, mu: f64, z: f64) -> (f64, f64) {
        let arc = match self.radius_km {
            None => 0.0,
            Some(r) => {
                let sin_v = (1.0 - mu * mu).max(0.0).sqrt();
                let t = ((r + z) * (r + z) - r * r * sin_v * sin_v).max(0.0).sqrt() - r * mu;
                libm::atan2(t * sin_v, r + t * mu)
            }
        };
        (cosine_at(self.radius_km, mu, z), arc)
    }
}

/// The radiance along a ray from the ground (`path`: its chord and
/// optical path through each layer) whose sources at each interface are
/// `at` (`Columns::sources_along`), to `reach_km` along it: each layer's
/// source, attenuated by the layers below; and the optical path to the
/// reach.
fn along(at: &[(f64, f64)], path: &[(f64, f64)], reach_km: f64) -> (f64, f64) {
    let (mut radiance, mut below, mut travelled_km) = (0.0f64, 0.0f64, 0.0f64);
    for k in (0..path.len()).rev() {
        let ((chord, optical), top, base) = (path[k], at[k].1, at[k + 1].0);
        if travelled_km + chord > reach_km {
            let f = ((reach_km - travelled_km) / chord).clamp(0.0, 1.0);
            radiance += through_layer(base + (top - base) * f, base, optical * f) * (-below).exp();
            return (radiance, below + optical * f);
        }
        radiance += through_layer(top, base, optical) * (-below).exp();
        below += optical;
        travelled_km += chord;
    }
    (radiance, below)
}

/// The pseudo-spherical columns' diffuse fields, as the coefficients of
/// their sources (`adding::source_coefficients`) per column, mode and
/// interface.
pub(super) struct Solution {
    pub(super) s: Streams,
    pub(super) scaled: Vec<Scaled>,
    /// `a[c][m][i]`: column c, mode m, interface i (top down), l = 0..=lmax.
    pub(super) a: Vec<Vec<Vec<Vec<f64>>>>,
    /// The irradiance on a horizontal ground under each column, direct
    /// (delta-M scaled) and diffuse.
    pub(super) ground_irradiance: Vec<f64>,
    /// The direct part of `ground_irradiance`.
    pub(super) ground_direct: Vec<f64>,
}

impl Solution {
    /// Every column, mode after mode, until two modes in a row change no
    /// column's source by more than 1e-6 of its mode 0.
    pub(super) fn new(layers: &Layers, streams: usize, zenith_rad: &[f64]) -> Solution {
        let s = Streams::new(streams);
        let scaled = delta_m(layers, 2 * streams);
        let nl = scaled.len();
        let paths: Vec<Paths> = zenith_rad.iter().map(|z| Paths::new(layers, &scaled, z.cos(), &[])).collect();
        let mut a: Vec<Vec<Vec<Vec<f64>>>> = vec![Vec::new(); zenith_rad.len()];
        let mut mode_zero_norm = vec![0.0; zenith_rad.len()];
        let mut ground_irradiance = vec![0.0; zenith_rad.len()];
        let mut ground_direct = vec![0.0; zenith_rad.len()];
        let norm = |a: &[Vec<f64>]| a.iter().map(|x| x.iter().map(|v| v.abs()).sum::<f64>()).fold(0.0, f64::max);
        let mut quiet = 0;
        for m in 0..2 * streams {
            let matrices = ModeMatrices::new(&s, &scaled, layers.ground_albedo, m);
            let mut largest = 0.0f64;
            for (c, zenith) in zenith_rad.iter().enumerate() {
                let mu0 = zenith.cos();
                let (down, up) = matrices.fields(&s, layers.ground_albedo, mu0, &paths[c]);
                if m == 0 {
                    let diffuse = 2.0 * PI * (0..s.n()).map(|j| s.w[j] * s.mu[j] * down[nl][j]).sum::<f64>();
                    ground_direct[c] = mu0.max(0.0) * paths[c].beam[nl];
                    ground_irradiance[c] = ground_direct[c] + diffuse;
                }
                let coefficients = source_coefficients(&s, m, &down, &up);
                if m == 0 {
                    mode_zero_norm[c] = norm(&coefficients);
                } else {
                    largest = largest.max(norm(&coefficients) / mode_zero_norm[c].max(1e-300));
                }
                a[c].push(coefficients);
            }
            quiet = if m > 0 && largest < 1e-6 { quiet + 1 } else { 0 };
            if quiet == 2 {
                break;
            }
        }
        Solution { s, scaled, a, ground_irradiance, ground_direct }
    }
}

/// (ω/2) (2l + 1) χ_l a_l of a layer for mode m (zero below l = m): the
/// coefficients whose sum against Λ_l^m(u) is the layer's source J^m(u).
pub(super) fn weigh(layer: &Scaled, lmax: usize, m: usize, a: &[f64]) -> Vec<f64> {
    (0..=lmax).map(|j| if j < m { 0.0 } else { 0.5 * layer.omega * (2 * j + 1) as f64 * layer.chi[j] * a[j] }).collect()
}

/// The altitudes of the layers' interfaces, top down, km.
pub(super) fn interfaces_km(layers: &Layers) -> Vec<f64> {
    std::iter::once(layers.layers.first().map_or(0.0, |l| l.top_km))
        .chain(layers.layers.iter().map(|l| l.bottom_km))
        .collect()
}

/// The column of `zenith_rad` (ascending) at or below `zenith` and the
/// weight of the next one, linear in the angle.
pub(super) fn bracket(zenith_rad: &[f64], zenith: f64) -> (usize, f64) {
    let c = zenith_rad.partition_point(|&x| x <= zenith).saturating_sub(1);
    if c + 1 >= zenith_rad.len() || zenith <= zenith_rad[c] {
        return (c, 0.0);
    }
    (c, ((zenith - zenith_rad[c]) / (zenith_rad[c + 1] - zenith_rad[c])).clamp(0.0, 1.0))
}

/// Between `a` and `b`, a fraction `w` of the way: linear in the logarithm
/// where both are positive, linear otherwise.
pub(super) fn log_lerp(a: f64, b: f64, w: f64) -> f64 {
    if a > 0.0 && b > 0.0 {
        (a.ln() * (1.0 - w) + b.ln() * w).exp()
    } else {
        a * (1.0 - w) + b * w
    }
}

/// The column grid for a sun at `sun_zenith_rad` seen from the ground of
/// `layers`: every multiple of `step_rad` from before to after the sun as
/// far as a ray from the ground travels in arc before it leaves the
/// atmosphere, within 0 to π; in a plane-parallel atmosphere the sun's own
/// column alone.
pub fn grid(layers: &Layers, sun_zenith_rad: f64, step_rad: f64) -> Vec<f64> {
    grid_reaches(layers, sun_zenith_rad, step_rad, 1.0)
}

/// `grid` to `reaches` times a ray's travel on both sides of the sun.
pub fn grid_reaches(layers: &Layers, sun_zenith_rad: f64, step_rad: f64, reaches: f64) -> Vec<f64> {
    grid_for_suns(layers, &[sun_zenith_rad], step_rad, reaches)
}

/// One grid for the views of every sun of `suns_rad` (the slices of a
/// bake): multiples of `step_rad`, so that a column is the same whichever
/// suns share it and a sun's view reads the columns its own render
/// (`grid_reaches`) would, from `reaches` rays' travel before the lowest
/// zenith angle to as far after the highest, within 0 to π (0 itself when
/// it is reached); in a plane-parallel atmosphere the suns themselves.
pub fn grid_for_suns(layers: &Layers, suns_rad: &[f64], step_rad: f64, reaches: f64) -> Vec<f64> {
    let reach = reaches
        * match (layers.shell_radius_km, layers.layers.first()) {
            (Some(r), Some(top)) => (r / (r + top.top_km)).acos(),
            _ => 0.0,
        };
    let (lowest, highest) = suns_rad.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &s| (a.min(s), b.max(s)));
    if reach == 0.0 {
        let mut suns = suns_rad.to_vec();
        suns.sort_by(f64::total_cmp);
        suns.dedup();
        return suns;
    }
    let first = ((lowest - reach) / step_rad).floor() as i64;
    let last = ((highest + reach) / step_rad).ceil() as i64;
    let mut zenith: Vec<f64> = (first..=last).map(|k| k as f64 * step_rad).filter(|&z| z > 0.0 && z < PI).collect();
    if first <= 0 {
        zenith.insert(0, 0.0);
    }
    zenith
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::atmosphere::Atmosphere;
    use crate::mie::MieCache;
    use crate::render::medium::Medium;
    use crate::transport::adding::Diffuse;
    use crate::transport::layers::Grading;

    /// The default layers of the atmosphere `file` (relative to the
    /// crate) at one wavelength, with `lmax` Legendre moments.
    pub(in crate::transport) fn layers_with(file: &str, wavelength_nm: f64, lmax: usize) -> Layers {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(file);
        let atm = Atmosphere::load(&path).unwrap();
        let medium = Medium::new(&atm);
        let optics = medium.spectral(&atm, wavelength_nm, 1.0, 0.3, &MieCache::shared_by_tests());
        Layers::new(&medium, &optics, lmax, &Grading::default())
    }

    fn layers(file: &str, wavelength_nm: f64) -> Layers {
        layers_with(file, wavelength_nm, 32)
    }

    /// Where a ray meets no other sun than the observer's (a plane-parallel
    /// atmosphere; the zenith in shells), the columns give what the single
    /// column of `adding::Diffuse` gives, and the ground's irradiance too.
    #[test]
    fn one_sun_along_the_ray_is_the_single_column() {
        for (file, views) in [
            ("tests/atmospheres/disort_rayleigh_hg.toml", vec![0.9, 0.5, 0.1, 0.02]),
            ("atmospheres/clear.toml", vec![1.0]),
        ] {
            let l = layers(file, 450.0);
            let sun = 50f64.to_radians();
            let columns = Columns::solve(&l, 8, grid(&l, sun, 1f64.to_radians()));
            let single = Diffuse::solve(&l, 8, sun.cos(), views.clone());
            let phis = [0.0, 0.7, 2.0, PI];
            for (k, &mu) in views.iter().enumerate() {
                for (got, &phi) in columns.rays(sun, mu, &phis).iter().zip(&phis) {
                    let want = single.at_node(k, phi);
                    assert!((got / want - 1.0).abs() < 1e-9, "{file}, view {mu}, azimuth {phi}: {got} against {want}");
                }
            }
            let (got, want) = (columns.ground_irradiance_at(sun), single.ground_irradiance);
            assert!((got / want - 1.0).abs() < 1e-12, "{file}: ground {got} against {want}");
        }
    }

    /// The column grid: every step on both sides of the sun as far as a ray
    /// travels, starting at the zenith when it reaches past it; nothing but
    /// the sun's own column in a plane-parallel atmosphere.
    #[test]
    fn the_grid_spans_a_ray_s_travel() {
        let l = layers("atmospheres/clear.toml", 550.0);
        let step = 1f64.to_radians();
        let g = grid(&l, 60f64.to_radians(), step);
        let reach = (l.shell_radius_km.unwrap() / (l.shell_radius_km.unwrap() + l.layers[0].top_km)).acos();
        assert!(
            g.first().unwrap() <= &(60f64.to_radians() - reach) && g.last().unwrap() >= &(60f64.to_radians() + reach)
        );
        assert!(g.windows(2).all(|w| (w[1] - w[0] - step).abs() < 1e-12));
        assert!(g.iter().all(|z| (z / step - (z / step).round()).abs() < 1e-9), "multiples of the step");
        assert_eq!(grid(&l, 3f64.to_radians(), step)[0], 0.0);
        // Several suns: one grid spanning them all, each sun's own grid in it.
        let suns = [40f64.to_radians(), 60.3f64.to_radians(), 95f64.to_radians()];
        let all = grid_for_suns(&l, &suns, step, 1.0);
        for &sun in &suns {
            assert!(grid(&l, sun, step).iter().all(|z| all.iter().any(|a| (a - z).abs() < 1e-12)));
        }
        let flat = layers("tests/atmospheres/disort_rayleigh_hg.toml", 550.0);
        assert_eq!(grid(&flat, 0.5, step), vec![0.5]);
        assert_eq!(grid_for_suns(&flat, &[0.7, 0.5, 0.7], step, 1.0), vec![0.5, 0.7]);
    }
}
