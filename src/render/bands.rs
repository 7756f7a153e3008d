//! The visible range split into wavelength bands, the distribution samples
//! draw them from, and the hero-wavelength sets.
//!
//! A hero set is four bands drawn from the band distribution at the
//! stratified offsets s + j/4 (j = 0..3) of one offset s in [0, 1/4), as
//! pbrt-v4's `SampledWavelengths::SampleVisible` draws its four wavelengths
//! at u + j/4. Which of the four positions is the hero is a separate,
//! uniform choice. The set is therefore closed by construction, whatever
//! the band count: drawing it from any of its members (any position as the
//! hero) gives the same four bands, so the balance heuristic over the four
//! ways it could be drawn is exact. (The companions b + j·n/4 mod n used
//! before were closed only when 4 divides n.)

use super::{WavelengthSampling, KM_LM_PER_W};
use crate::atmosphere::Atmosphere;
use crate::spectrum::Cmf;

/// Bands carried by one hero path.
pub const HERO_N: usize = 4;

/// The visible range split into bands, with their colour weights.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Bands {
    pub centre_nm: Vec<f64>,
    /// W_b: 683 Σ E(λ) cmf(λ) over the band's 1 nm samples.
    pub weight: Vec<[f64; 3]>,
    pub ground_albedo: Vec<f64>,
    /// The probability of drawing each band.
    pub pdf: Vec<f64>,
    cdf: Vec<f64>,
}

impl Bands {
    pub fn new(atm: &Atmosphere, band_nm: f64, sampling: WavelengthSampling) -> Bands {
        let cmf = Cmf::cie1931();
        let n = ((cmf.wavelength_nm.len() as f64 - 1.0) / band_nm).floor().max(1.0) as usize;
        let mut sums = vec![(0.0, [0.0; 3], 0.0, 0usize); n];
        for (i, &l) in cmf.wavelength_nm.iter().enumerate() {
            let b = (((l - cmf.wavelength_nm[0]) / band_nm) as usize).min(n - 1);
            let e = atm.sun.irradiance_w_m2_nm.eval(l);
            let s = &mut sums[b];
            s.0 += l;
            s.1[0] += KM_LM_PER_W * e * cmf.x_bar[i];
            s.1[1] += KM_LM_PER_W * e * cmf.y_bar[i];
            s.1[2] += KM_LM_PER_W * e * cmf.z_bar[i];
            s.2 += atm.ground_albedo.eval(l);
            s.3 += 1;
        }
        let centre_nm = sums.iter().map(|s| s.0 / s.3 as f64).collect();
        let weight: Vec<[f64; 3]> = sums.iter().map(|s| s.1).collect();
        let ground_albedo = sums.iter().map(|s| s.2 / s.3 as f64).collect();
        let raw: Vec<f64> = weight
            .iter()
            .map(|w| match sampling {
                WavelengthSampling::Luminance => w[1],
                WavelengthSampling::Tristimulus | WavelengthSampling::Hero => w[0] + w[1] + w[2],
            })
            .collect();
        Bands::from_raw(centre_nm, weight, ground_albedo, &raw)
    }

    /// Bands with a sampling distribution proportional to `raw`.
    fn from_raw(centre_nm: Vec<f64>, weight: Vec<[f64; 3]>, ground_albedo: Vec<f64>, raw: &[f64]) -> Bands {
        let total: f64 = raw.iter().sum();
        let pdf: Vec<f64> = raw.iter().map(|r| r / total).collect();
        let mut cdf = Vec::with_capacity(pdf.len());
        let mut acc = 0.0;
        for p in &pdf {
            acc += p;
            cdf.push(acc);
        }
        Bands { centre_nm, weight, ground_albedo, pdf, cdf }
    }

    pub fn len(&self) -> usize {
        self.pdf.len()
    }

    pub fn is_empty(&self) -> bool {
        self.pdf.is_empty()
    }

    /// The band whose cumulative-probability interval holds `u` in [0, 1).
    pub fn sample(&self, u: f64) -> usize {
        self.cdf.partition_point(|&c| c <= u * self.cdf[self.cdf.len() - 1]).min(self.cdf.len() - 1)
    }

    /// The hero set of a sample with uniform variate `u` in [0, 1): the
    /// stratum offset s = frac(4u) / 4 fixes the four bands at s + j/4, and
    /// ⌊4u⌋ picks which of them is the hero (index 0 of the set; the others
    /// follow in stratum order, wrapping around).
    pub fn hero_set(&self, u: f64) -> HeroSet {
        let u4 = (u * HERO_N as f64).clamp(0.0, (HERO_N as f64) * (1.0 - f64::EPSILON));
        let hero = (u4 as usize).min(HERO_N - 1);
        self.hero_set_from(u4 - hero as f64, hero)
    }

    /// The set of the stratum offset `v` / 4 (`v` in [0, 1)) with the
    /// position `hero` as its hero.
    pub fn hero_set_from(&self, v: f64, hero: usize) -> HeroSet {
        let band = std::array::from_fn(|j| {
            let position = (hero + j) % HERO_N;
            self.sample((v + position as f64) / HERO_N as f64)
        });
        HeroSet { band, pdf: band.map(|b| self.pdf[b]) }
    }
}

/// The four bands of a hero path with each band's selection probability
/// (its marginal density: every position of a set is distributed like a
/// single band draw). Index 0 is the hero; a band may appear twice when it
/// holds more than a quarter of the distribution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeroSet {
    pub band: [usize; HERO_N],
    pub pdf: [f64; HERO_N],
}

impl HeroSet {
    /// The balance-heuristic weight of each way the set could have been
    /// drawn (position j as the hero, each with probability 1/4), given
    /// the path's density `path_pdf[j]` had position j been the hero:
    /// P_j / Σ_k P_k. A band's estimate is f_j / (p(b_j) Σ_k P_k), the sum
    /// over the four hero choices of these weights times f_j / (p_j P_j / 4)
    /// divided by four.
    pub fn mis_weights(path_pdf: &[f64; HERO_N]) -> [f64; HERO_N] {
        let total: f64 = path_pdf.iter().sum();
        if !(total > 0.0) {
            return [0.0; HERO_N];
        }
        path_pdf.map(|p| p / total)
    }

    /// The same set with position `j` as its hero (the rotation).
    pub fn rotated(&self, j: usize) -> HeroSet {
        HeroSet {
            band: std::array::from_fn(|k| self.band[(j + k) % HERO_N]),
            pdf: std::array::from_fn(|k| self.pdf[(j + k) % HERO_N]),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bands with a distribution that is not uniform (so the strata cut
    /// bands unevenly), for every count.
    fn bands(n: usize) -> Bands {
        let raw: Vec<f64> = (0..n).map(|b| 1.0 + ((b * 7919) % 13) as f64 + (b as f64 * 0.37).sin().abs()).collect();
        Bands::from_raw((0..n).map(|b| b as f64).collect(), vec![[1.0; 3]; n], vec![0.0; n], &raw)
    }

    /// For every band count from 1 to 200 and many offsets: the set drawn
    /// with any member as the hero is the same set (the same bands at the
    /// same positions, rotated), each band's pdf is its own, and the MIS
    /// weights of each position over the four ways the set can be drawn
    /// sum to 1 for arbitrary path densities.
    #[test]
    fn hero_sets_are_closed_for_every_band_count() {
        for n in 1..=200 {
            let b = bands(n);
            for k in 0..257 {
                let v = (k as f64 + 0.5) / 257.0;
                let base = b.hero_set_from(v, 0);
                for hero in 0..HERO_N {
                    let s = b.hero_set_from(v, hero);
                    assert_eq!(s, base.rotated(hero), "n {n}, v {v}, hero {hero}");
                    // Drawn through hero_set, with the u that selects this hero and offset.
                    let u = (v + hero as f64) / HERO_N as f64;
                    let t = b.hero_set(u);
                    let mut x = t.band;
                    let mut y = base.band;
                    x.sort_unstable();
                    y.sort_unstable();
                    assert_eq!(x, y, "n {n}, u {u}");
                    for j in 0..HERO_N {
                        assert_eq!(s.pdf[j], b.pdf[s.band[j]]);
                    }
                }
                // The weight of hero choice h is P_h / Σ_k P_k over the set it
                // draws, with path densities that depend on the band (as the
                // real ones do); they sum to 1 over the four choices only if
                // every choice draws the same set.
                let density = |band: usize| 0.1 + ((band * 31) % 7) as f64;
                let total: f64 =
                    (0..HERO_N).map(|h| HeroSet::mis_weights(&b.hero_set_from(v, h).band.map(density))[0]).sum();
                assert!((total - 1.0).abs() < 1e-12, "n {n}, v {v}: weights sum to {total}");
            }
        }
    }

    /// Each position of a set is marginally a single band draw: over a fine
    /// grid of u, the fraction of samples whose position j is band b is p(b).
    #[test]
    fn every_position_follows_the_band_distribution() {
        for n in [1, 3, 10, 47, 94] {
            let b = bands(n);
            let m = 40_000;
            for j in 0..HERO_N {
                let mut count = vec![0usize; n];
                for k in 0..m {
                    count[b.hero_set((k as f64 + 0.5) / m as f64).band[j]] += 1;
                }
                for (band, c) in count.iter().enumerate() {
                    let f = *c as f64 / m as f64;
                    assert!(
                        (f - b.pdf[band]).abs() < 4.0 / m as f64 + 1e-9,
                        "n {n}, position {j}, band {band}: {f} vs {}",
                        b.pdf[band]
                    );
                }
            }
        }
    }
}
