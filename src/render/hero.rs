//! Hero-wavelength sampling (Wilkie et al. 2014, "Hero Wavelength Spectral
//! Sampling"): each path carries the four bands of a
//! [`HeroSet`](super::bands::HeroSet), drawn at
//! stratified offsets of the band distribution with one of them, chosen
//! uniformly, as the hero. The path is built with the hero's decisions;
//! every band's contribution is weighted by the balance heuristic over the
//! four ways the same (closed) set could have been drawn, each with
//! probability 1/4: band j contributes f_j(x) W_j / (p(b_j) Σ_k P_k(x)),
//! where P_k is the density of the path had position k been the hero and
//! p(b_j) the band's own selection probability (each position is
//! distributed like one band draw).
//!
//! To make the P_k computable the bands share one majorant (the largest of
//! the four in each shell), so tentative collision points are common to all
//! of them and only the accept/null decisions, the scatterer choice and the
//! phase sampling differ between bands (the null-scattering path integral of
//! Miller, Georgiev and Jarosz 2019 gives these densities). The path itself
//! is the generic kernel's (`kernel`) at N = 4; the caller divides band j's
//! estimate by p(b_j).

pub use super::bands::HERO_N;
use super::kernel::Kernel;

/// The kernel of a hero path: four bands, one shared majorant (see the
/// module's note and `kernel`).
pub type HeroTracer<'a> = Kernel<'a, HERO_N>;

/// The largest of the bands' majorants in each shell, written into `out`
/// (a buffer reused across samples).
pub fn shared_majorant_into(majorants: [&[f64]; HERO_N], out: &mut Vec<f64>) {
    out.clear();
    out.extend((0..majorants[0].len()).map(|s| majorants.iter().map(|m| m[s]).fold(0.0, f64::max)));
}
