//! The spherical iteration's acceleration: what the columns' own
//! plane-parallel operator makes of a pass's change (synthetic
//! acceleration, as diffusion-synthetic acceleration does for source
//! iteration: Alcouffe 1977; Adams and Larsen 2002, "Fast iterative methods
//! for discrete-ordinates particle transport calculations", section 4).
//!
//! A pass of `spherical::iterate` is one transport sweep: the node
//! radiances it makes come from the sources it read, scattered once more
//! (a_{n+1} = K a_n + b, a the source's coefficients at the node levels,
//! linear in altitude between them). With e_n = a* − a_n the error,
//! e_{n+1} = K e_n, and the change of a pass ρ = a_{n+1} − a_n is
//! (I − K) e_n, so the rest of the way is
//!   a* − a_{n+1} = K e_n = (I − K)⁻¹ K ρ.
//! In a thick cloud K is close to 1 in what diffuses through it, and a
//! pass moves the answer only a little of the way (cloudy5 at sun 96°:
//! each change 0.84 of the last, for tens of passes).
//!
//! K here is the columns' plane-parallel sweep (the same for every column:
//! it does not depend on the sun) in the iteration's own representation:
//! node values spread linearly in altitude to every interface, the source
//! they make the same across each layer (the mean of its top's and base's),
//! carried to every interface without scattering (the adding of the layers
//! with their single-scattering albedo set to 0,
//! `adding::ModeMatrices::fields_of_uniform`; the ground reflects at once),
//! and read back at the node levels. It is kept for mode 0 (what diffuses;
//! the other modes converge in a few passes), one sweep per unknown, once
//! per solve. No light crosses between columns in it, so the step is
//! toward the spherical fixed point, not onto it; at the fixed point ρ = 0
//! and the step is 0: the answer is the iteration's own.

use super::adding::{source, source_coefficients, ModeMatrices, Scaled};
use super::linalg::{Lu, Mat};
use super::operator::{lambdas, Streams};
use rayon::prelude::*;
use std::f64::consts::PI;

/// The columns' sweep of mode 0 at the node levels.
pub(super) struct Accelerator<'a> {
    s: &'a Streams,
    scaled: &'a [Scaled],
    /// The layers' adding with no scattering.
    sweep: ModeMatrices,
    /// Λ^0 at the downward and upward streams.
    lam: (Vec<Vec<f64>>, Vec<Vec<f64>>),
    levels: Vec<usize>,
    /// `hat[v][i]`: the weight of node level v's value at interface i.
    hat: Vec<Vec<f64>>,
    /// K at the node levels, and I − K factorised.
    k: Mat,
    system: Lu,
}

/// A sweep's coefficients at every interface (`[interface][l]`) and the
/// diffuse irradiance it brings to the ground.
struct Sweep {
    a: Vec<Vec<f64>>,
    ground: f64,
}

impl<'a> Accelerator<'a> {
    /// The accelerator of the node `levels` (interfaces, top down, at
    /// altitudes `z_km`); None where I − K is singular (it is not while
    /// light leaves the column or is absorbed).
    pub(super) fn new(
        s: &'a Streams,
        scaled: &'a [Scaled],
        albedo: f64,
        levels: &[usize],
        z_km: &[f64],
    ) -> Option<Accelerator<'a>> {
        let minus: Vec<f64> = s.mu.iter().map(|u| -u).collect();
        let hat = levels
            .iter()
            .enumerate()
            .map(|(v, &at)| {
                let mut w = vec![0.0; z_km.len()];
                w[at] = 1.0;
                let neighbours = [v.checked_sub(1).map(|u| levels[u]), levels.get(v + 1).copied()];
                for other in neighbours.into_iter().flatten() {
                    let (lo, hi) = (at.min(other), at.max(other));
                    for (i, w) in w.iter_mut().enumerate().take(hi).skip(lo + 1) {
                        *w = (z_km[i] - z_km[other]) / (z_km[at] - z_km[other]);
                    }
                }
                w
            })
            .collect();
        let transparent: Vec<Scaled> = scaled.iter().map(|l| Scaled { omega: 0.0, ..l.clone() }).collect();
        let mut accelerator = Accelerator {
            s,
            scaled,
            sweep: ModeMatrices::new(s, &transparent, albedo, 0),
            lam: (lambdas(&s.mu, 0, s.lmax), lambdas(&minus, 0, s.lmax)),
            levels: levels.to_vec(),
            hat,
            k: Mat::zeros(0),
            system: Mat::identity(1).lu()?,
        };
        let n = accelerator.unknowns();
        let columns: Vec<Vec<f64>> = (0..n)
            .into_par_iter()
            .map(|j| {
                let mut unit = vec![0.0; n];
                unit[j] = 1.0;
                accelerator.at_levels(&accelerator.sweep_of(&unit).a)
            })
            .collect();
        let mut k = Mat::zeros(n);
        for (j, column) in columns.iter().enumerate() {
            for (i, &v) in column.iter().enumerate() {
                k.set(i, j, v);
            }
        }
        accelerator.system = k.one_minus().lu()?;
        accelerator.k = k;
        Some(accelerator)
    }

    fn unknowns(&self) -> usize {
        self.levels.len() * (self.s.lmax + 1)
    }

    /// The step after a pass that read the node coefficients `read` (mode
    /// 0, `[level][l]`) and made `made` of them: the coefficients to add at
    /// each node level, and the diffuse irradiance to add on the ground
    /// (the sweep of the error the pass started from, ρ + step).
    pub(super) fn step(&self, made: &[Vec<f64>], read: &[Vec<f64>]) -> (Vec<Vec<f64>>, f64) {
        let change: Vec<f64> = made.iter().zip(read).flat_map(|(x, y)| x.iter().zip(y).map(|(x, y)| x - y)).collect();
        let rest = self.system.solve_vec(&self.k.mul_vec(&change));
        let error: Vec<f64> = change.iter().zip(&rest).map(|(a, b)| a + b).collect();
        let ground = self.sweep_of(&error).ground;
        (rest.chunks(self.s.lmax + 1).map(|c| c.to_vec()).collect(), ground)
    }

    /// The sweep of node values (`[level * (lmax + 1) + l]`) spread to the
    /// interfaces, as a uniform source in each layer.
    fn sweep_of(&self, node: &[f64]) -> Sweep {
        let (s, lmax) = (self.s, self.s.lmax);
        let at_interface = |i: usize| -> Vec<f64> {
            let mut a = vec![0.0; lmax + 1];
            for (v, hat) in self.hat.iter().enumerate() {
                if hat[i] != 0.0 {
                    a.iter_mut().zip(&node[v * (lmax + 1)..]).for_each(|(a, x)| *a += hat[i] * x);
                }
            }
            a
        };
        let mut above = at_interface(0);
        let sources: Vec<(Vec<f64>, Vec<f64>)> = self
            .scaled
            .iter()
            .enumerate()
            .map(|(k, layer)| {
                let below = at_interface(k + 1);
                let mean: Vec<f64> = above.iter().zip(&below).map(|(a, b)| 0.5 * (a + b)).collect();
                above = below;
                let along = |lam: &Vec<Vec<f64>>| -> Vec<f64> {
                    lam.iter().map(|lam| source(layer, 0, lmax, lam, &mean)).collect()
                };
                (along(&self.lam.0), along(&self.lam.1))
            })
            .collect();
        let (down, up) = self.sweep.fields_of_uniform(s, &sources);
        let last = down.len() - 1;
        let ground = 2.0 * PI * (0..s.n()).map(|j| s.w[j] * s.mu[j] * down[last][j]).sum::<f64>();
        Sweep { a: source_coefficients(s, 0, &down, &up), ground }
    }

    /// Coefficients at every interface, at the node levels.
    fn at_levels(&self, a: &[Vec<f64>]) -> Vec<f64> {
        self.levels.iter().flat_map(|&i| a[i].clone()).collect()
    }
}
