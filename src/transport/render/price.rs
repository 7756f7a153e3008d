//! The price of [`Staged::finish`] before the wavelengths are solved, for
//! a bake's forecast: the per-texel work after the solutions (the light
//! interpolated between the nodes, each pixel's single scattering by
//! quadrature and its diffuse light read) is about a third of a sunny
//! sky's draft (`bakes/demo.toml`, clear, one thread: 24 s against 51 s of
//! solutions), and the solver's pilots alone left it out.

use super::{render_part, Staged};
use crate::transport::layers::Layers;
use crate::transport::light::Wavelength;
use crate::transport::render::SolvedWavelength;
use std::time::Instant;

impl Staged<'_> {
    /// Core-seconds that `finish` will take on this process's threads
    /// (wall time times threads), the result thrown away: the layers of
    /// one band between the nodes built (`between_nodes` builds every such
    /// band's, one after the other) and counted once a band; every
    /// `stride`-th part's pixels rendered with the `pilot`'s light in place
    /// of every wavelength's (the work does not depend on the values), that
    /// time scaled by the pixels of all the parts over those rendered.
    pub fn price_finish(&self, pilot: &SolvedWavelength, stride: usize) -> f64 {
        let (scene, threads) = (self.scene, rayon::current_num_threads() as f64);
        let between = scene.band_optics.len().saturating_sub(self.band_nodes.len());
        let layers_s = match (0..scene.band_optics.len()).find(|i| !self.band_nodes.contains(i)) {
            Some(i) => {
                let start = Instant::now();
                let (streams, grading) = (2 * self.resolution.streams, &self.resolution.grading);
                std::hint::black_box(Layers::new(&scene.medium, &scene.band_optics[i], streams, grading));
                start.elapsed().as_secs_f64()
            }
            None => 0.0,
        };
        let picked: Vec<usize> = (0..self.parts.len()).step_by(stride.max(1)).collect();
        let pixels = |k: usize| {
            let v = &self.parts[k].2;
            (v.width * v.height) as f64
        };
        let all: f64 = (0..self.parts.len()).map(pixels).sum();
        let sampled: f64 = picked.iter().map(|&k| pixels(k)).sum();
        let mut pixels_s = 0.0;
        for &k in &picked {
            let copies = |n: usize| -> Vec<Wavelength> { (0..n).map(|_| pilot.light[k].clone()).collect() };
            let (bands, lines) = (copies(scene.band_optics.len()), copies(scene.line_optics.len()));
            let start = Instant::now();
            std::hint::black_box(render_part(scene, &self.parts[k].2, &bands, &lines));
            pixels_s += start.elapsed().as_secs_f64();
        }
        let pixels_s = if sampled > 0.0 { pixels_s * all / sampled } else { 0.0 };
        (layers_s * between as f64 + pixels_s) * threads
    }
}
