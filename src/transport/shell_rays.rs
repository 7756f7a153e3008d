//! Straight rays through spherical shells (or a plane-parallel slab) for
//! the spherical source iteration (`spherical`): where a ray from an
//! interface crosses the others, the local zenith cosine and the arc
//! travelled there, the optical path between; the sun's beam on a grid of
//! local sun zenith angles; and the integral of a source exponential in
//! optical path.

use super::adding::{slant_to_sun, through_layer};
use std::f64::consts::PI;

/// A point where a node's ray crosses an interface (or touches its tangent
/// altitude inside a layer).
#[derive(Debug, Clone, Copy)]
pub(super) struct Point {
    pub(super) at: At,
    /// The ray's zenith cosine there.
    pub(super) u: f64,
    pub(super) cos_arc: f64,
    pub(super) sin_arc: f64,
}

#[derive(Debug, Clone, Copy)]
pub(super) enum At {
    Interface(usize),
    /// Inside layer k, a fraction of the way from its top to its base.
    Inside(usize, f64),
}

/// A node's ray: its points, at every interface it crosses (and its
/// tangent point); between each two the layer and its optical path
/// (`steps`); the points where the multiply scattered light's source is
/// read (`stops`, indices into `points`) and between each two the layer
/// next to the first, the layer next to the second and the optical path
/// (`segments`); whether it ends on the ground (at its last point).
#[derive(Debug, Clone)]
pub(super) struct Ray {
    pub(super) points: Vec<Point>,
    pub(super) steps: Vec<(usize, f64)>,
    pub(super) stops: Vec<usize>,
    pub(super) segments: Vec<(usize, usize, f64)>,
    pub(super) ground: bool,
}

/// The ray from interface `i0` at zenith cosine `u0` through the
/// interfaces `z` (top down, km) of shells about a centre `radius` below
/// the ground (plane-parallel where None); `sigma`: each layer's scaled
/// extinction, km⁻¹. Stops only where `keep[i]` (and at the tangent point
/// and the end), the optical path summed over the layers between them.
pub(super) fn trace(radius: Option<f64>, z: &[f64], sigma: &[f64], keep: &[bool], i0: usize, u0: f64) -> Ray {
    let nl = z.len() - 1;
    // Every crossing: (where, distance along the ray, layer just crossed).
    let mut crossings: Vec<(At, f64, usize)> = Vec::new();
    let mut ground = false;
    let (r0, sin_v) = (radius.map_or(0.0, |r| r + z[i0]), (1.0 - u0 * u0).max(0.0).sqrt());
    match radius {
        None => {
            if u0 > 0.0 {
                (0..i0).rev().for_each(|i| crossings.push((At::Interface(i), (z[i] - z[i0]) / u0, i)));
            } else {
                (i0 + 1..=nl).for_each(|i| crossings.push((At::Interface(i), (z[i] - z[i0]) / u0, i - 1)));
                ground = true;
            }
        }
        Some(r) => {
            let b = r0 * sin_v;
            let along = |i: usize| ((r + z[i]) * (r + z[i]) - b * b).max(0.0).sqrt();
            let mut up_from = i0;
            if u0 < 0.0 {
                ground = b < r;
                let kt = if ground { nl } else { (i0..nl).find(|&k| b - r >= z[k + 1]).unwrap_or(nl - 1) };
                for i in i0 + 1..=kt.min(nl) {
                    crossings.push((At::Interface(i), -r0 * u0 - along(i), i - 1));
                }
                if !ground {
                    let w = ((z[kt] - (b - r)) / (z[kt] - z[kt + 1]).max(1e-12)).clamp(0.0, 1.0);
                    crossings.push((At::Inside(kt, w), -r0 * u0, kt));
                    up_from = kt + 1;
                }
            }
            if !ground {
                (0..up_from).rev().for_each(|i| crossings.push((At::Interface(i), along(i) - r0 * u0, i)));
            }
        }
    }
    let point = |at: At, t: f64| -> Point {
        if radius.is_none() {
            return Point { at, u: u0, cos_arc: 1.0, sin_arc: 0.0 };
        }
        let rt = (r0 * r0 + 2.0 * r0 * u0 * t + t * t).max(0.0).sqrt();
        let arc = libm::atan2(t * sin_v, r0 + t * u0);
        let u = if matches!(at, At::Inside(..)) { 0.0 } else { ((r0 * u0 + t) / rt).clamp(-1.0, 1.0) };
        Point { at, u, cos_arc: arc.cos(), sin_arc: arc.sin() }
    };
    let mut points = vec![point(At::Interface(i0), 0.0)];
    let (mut steps, mut stops, mut segments) = (Vec::new(), vec![0], Vec::new());
    let (mut t_last, mut tau, mut first_layer) = (0.0, 0.0, None);
    let count = crossings.len();
    for (q, &(at, t, k)) in crossings.iter().enumerate() {
        let step = sigma[k] * (t - t_last);
        t_last = t;
        tau += step;
        steps.push((k, step));
        points.push(point(at, t));
        let first = *first_layer.get_or_insert(k);
        let stop = match at {
            At::Interface(i) => keep[i] || q + 1 == count,
            At::Inside(..) => true,
        };
        if stop {
            segments.push((first, k, tau));
            stops.push(points.len() - 1);
            tau = 0.0;
            first_layer = None;
        }
    }
    Ray { points, steps, stops, segments, ground }
}

/// A source that varies exponentially along an optical path `x` between
/// `j_far` and `j_near` (as the sun's beam does), integrated as seen from
/// the near end: ∫₀ˣ J(s) e^{−s} ds with J(s) = j_near (j_far / j_near)^{s/x};
/// linear in s (`adding::through_layer`) where either end is dark.
/// With a = ln(j_far / j_near) − x the integral is j_near x (e^a − 1) / a,
/// written x (j_far e^{−x} − j_near) / a so that no ratio of the two ends
/// overflows (a beam of 1e-310 beside one of 1: the ratio is infinite,
/// and (e^a − 1) / a came out NaN).
pub(super) fn through_layer_log(j_far: f64, j_near: f64, x: f64) -> f64 {
    if j_far <= 0.0 || j_near <= 0.0 {
        return through_layer(j_far, j_near, x);
    }
    let a = j_far.ln() - j_near.ln() - x;
    if a.abs() < 1e-6 {
        j_near * x * (1.0 + 0.5 * a)
    } else {
        x * (j_far * (-x).exp() - j_near) / a
    }
}

/// Which interfaces the node rays stop at: the node levels, and others no
/// closer than `base_km` + z `growth` above the last one kept (from the
/// ground up), nor more than `max_tau` of vertical optical depth (`tau[k]`
/// of the layer between interfaces k and k + 1) above it.
pub(super) fn stops(
    z: &[f64],
    tau: &[f64],
    levels: &[usize],
    (base_km, growth): (f64, f64),
    max_tau: f64,
) -> Vec<bool> {
    let mut keep = vec![false; z.len()];
    levels.iter().for_each(|&i| keep[i] = true);
    let (mut last, mut tau_since) = (f64::NEG_INFINITY, 0.0);
    for i in (0..z.len()).rev() {
        if i < tau.len() {
            tau_since += tau[i];
        }
        if keep[i] || z[i] - last >= base_km + z[i] * growth || tau_since > max_tau {
            keep[i] = true;
            (last, tau_since) = (z[i], 0.0);
        }
    }
    keep
}

/// The direct beam's transmittance (scaled optical depths) at each
/// interface on a grid of local sun zenith angles, to where the Earth's
/// shadow covers the top of the atmosphere.
pub(super) struct Beam {
    step_rad: f64,
    /// `t[i][k]`: interface i, sun zenith k steps from the zenith.
    t: Vec<Vec<f64>>,
}

impl Beam {
    pub(super) fn new(radius: Option<f64>, z: &[f64], sigma: &[f64]) -> Beam {
        let step_rad = 0.05f64.to_radians();
        let last = match radius {
            Some(r) => PI - (r / (r + z[0])).asin(),
            None => 0.5 * PI,
        };
        let n = (last / step_rad).ceil() as usize + 1;
        let t = z
            .iter()
            .map(|&zi| {
                (0..=n).map(|k| (-slant_to_sun(radius, z, sigma, zi, (k as f64 * step_rad).cos())).exp()).collect()
            })
            .collect();
        Beam { step_rad, t }
    }

    pub(super) fn at(&self, i: usize, zenith_rad: f64) -> f64 {
        let row = &self.t[i];
        let x = zenith_rad / self.step_rad;
        let k = x.floor() as usize;
        if k + 1 >= row.len() {
            return 0.0;
        }
        let w = x - k as f64;
        row[k] * (1.0 - w) + row[k + 1] * w
    }
}

#[cfg(test)]
mod tests {
    use super::{stops, through_layer_log};

    /// ∫₀ˣ j_near (j_far / j_near)^{s/x} e^{−s} ds by the midpoint rule on
    /// 2 000 000 steps (relative error (k h)² / 24: 2e-8 for the steepest
    /// case below), in logarithms so that neither end overflows.
    fn midpoint(j_far: f64, j_near: f64, x: f64) -> f64 {
        let n = 2_000_000;
        let h = x / n as f64;
        let (lf, ln) = (j_far.ln(), j_near.ln());
        (0..n)
            .map(|k| {
                let s = (k as f64 + 0.5) * h;
                (ln + (lf - ln) * s / x - s).exp() * h
            })
            .sum()
    }

    /// The closed form against the midpoint rule, from equal ends to ends
    /// 600 orders of magnitude apart (a beam in the Earth's shadow beside a
    /// sunlit one: the ratio of the ends overflows, which once made NaN).
    /// The stops: every `base_km` + z `growth` up from the ground, the
    /// node levels, and wherever the optical depth since the last stop
    /// passes `max_tau` (a cloud's layers).
    #[test]
    fn the_rays_stop_in_clouds_every_max_tau() {
        // Interfaces top down, 10 km to the ground 1 km apart; layer k is
        // between z[k] and z[k + 1]: a cloud of 0.4 a layer from 6 to 3 km.
        let z: Vec<f64> = (0..=10).rev().map(f64::from).collect();
        let tau: Vec<f64> = (0..10).map(|k| if (4..7).contains(&k) { 0.4 } else { 0.01 }).collect();
        let kept = |keep: Vec<bool>| -> Vec<f64> { (0..z.len()).filter(|&i| keep[i]).map(|i| z[i]).collect() };
        assert_eq!(kept(stops(&z, &tau, &[0], (4.0, 0.0), f64::INFINITY)), [10.0, 8.0, 4.0, 0.0]);
        assert_eq!(kept(stops(&z, &tau, &[0], (4.0, 0.0), 0.5)), [10.0, 6.0, 4.0, 0.0]);
        assert_eq!(kept(stops(&z, &tau, &[0], (4.0, 0.0), 0.3)), [10.0, 6.0, 5.0, 4.0, 0.0]);
    }

    #[test]
    fn a_source_exponential_along_the_path_integrates_to_its_quadrature() {
        for (j_far, j_near, x) in [
            (1.0, 1.0, 0.3),
            (2.0, 1.0, 1e-3),
            (1.0 + 1e-9, 1.0, 0.5),
            (1e-3, 1.0, 2.0),
            (1.0, 1e-310, 0.1),
            (1e-310, 1.0, 0.1),
            (1e300, 1e-300, 0.05),
        ] {
            let (got, want) = (through_layer_log(j_far, j_near, x), midpoint(j_far, j_near, x));
            assert!(got.is_finite(), "{j_far} {j_near} {x}: {got}");
            assert!((got - want).abs() <= 1e-6 * want.abs(), "{j_far} {j_near} {x}: {got} against {want}");
        }
    }
}
