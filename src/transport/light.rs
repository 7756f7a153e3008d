//! One wavelength's light for the suns of a view (`render`): the sun-angle
//! columns solved once for every sun of the view's parts (`Solved`), the
//! diffuse light read from them on a grid of view cosines and azimuths
//! (`Wavelength`), and the bands between spectral nodes interpolated from
//! the nodes' light (`between_nodes`).
//!
//! The diffuse light is integrated along the rays of K view cosines
//! ([`VIEW_NODES`] unless `Resolution::view_grid` says otherwise), μ_k =
//! (k / K)², k = 1..K, dense toward the horizon where the light changes
//! fastest, at P + 1 azimuths from 0 to π (P = [`AZIMUTH_INTERVALS`]),
//! and interpolated between them by Catmull-Rom in √μ and in azimuth (the
//! test below bounds what that costs against each pixel's own ray).

use super::columns::{self, Columns};
use super::layers::Layers;
use super::render::{Resolution, MAX_SUN_ZENITH_DEG, SPHERICAL_FROM_SUN_ZENITH_DEG};
use crate::render::medium::Spectral;
use crate::render::Scene;
use rayon::prelude::*;
use std::f64::consts::PI;

/// How many view cosines the diffuse light is solved at (see the module
/// documentation).
pub const VIEW_NODES: usize = 128;

/// How many intervals of azimuth, 0 to π, the diffuse light is solved at.
pub const AZIMUTH_INTERVALS: usize = 64;

/// The bake's grid of view cosines and azimuth intervals
/// (`Resolution::view_grid`): half the default's rays, still within the
/// bound of the view grid's test (8.4e-5; 64 x 32 and 64 x 48 were 1.8e-4,
/// 128 x 32 1.3e-4).
pub const BAKE_VIEW_GRID: (usize, usize) = (96, 40);

/// The draft bake's grid (`bake::solver::resolution`): a third of the
/// default's rays; the view grid's test bounds it at 3e-4 (measured 1.8e-4).
pub const DRAFT_VIEW_GRID: (usize, usize) = (64, 32);

/// How many wavelengths `render` solves for `scene` (`on_wavelength` is
/// called after each): the bands' nodes (`spectral_nodes`) and every
/// spectral line.
pub fn wavelengths_solved(scene: &Scene, resolution: &Resolution) -> usize {
    spectral_nodes(&scene.band_optics, resolution.ms_step_nm).len() + scene.line_optics.len()
}

/// The indices of the wavelengths of `optics` (increasing) whose multiply
/// scattered light is solved: the first, then each first one at least
/// `step_nm` beyond the last node, and the last; every one with a step
/// of 0.
pub(super) fn spectral_nodes(optics: &[Spectral], step_nm: f64) -> Vec<usize> {
    let mut nodes: Vec<usize> = Vec::new();
    for (i, o) in optics.iter().enumerate() {
        let far_enough = nodes.last().is_none_or(|&n| o.wavelength_nm >= optics[n].wavelength_nm + step_nm);
        if far_enough || i + 1 == optics.len() {
            nodes.push(i);
        }
    }
    nodes
}

/// Every wavelength's light, `[wavelength][part]`, from the nodes' solved
/// (`solved[n]` of wavelength `nodes[n]`): a node's own; between two nodes
/// the diffuse light and the ground's irradiance a power law in wavelength
/// through theirs (`Wavelength::between`), the beam's transmittance and
/// the ground's albedo the wavelength's own.
pub(super) fn between_nodes(
    scene: &Scene,
    optics: &[Spectral],
    nodes: &[usize],
    solved: Vec<Vec<Wavelength>>,
    suns_rad: &[f64],
    resolution: &Resolution,
) -> Vec<Vec<Wavelength>> {
    if nodes.len() == optics.len() {
        return solved;
    }
    let mut solved: Vec<Option<Vec<Wavelength>>> = solved.into_iter().map(Some).collect();
    let mut all = Vec::with_capacity(optics.len());
    for (i, o) in optics.iter().enumerate() {
        let n = nodes.partition_point(|&k| k < i);
        if nodes.get(n) == Some(&i) {
            all.push(solved[n].take().expect("a node comes once"));
            continue;
        }
        let (a, c) = (nodes[n - 1], nodes[n]);
        let t =
            (o.wavelength_nm / optics[a].wavelength_nm).ln() / (optics[c].wavelength_nm / optics[a].wavelength_nm).ln();
        let layers = Layers::new(&scene.medium, o, 2 * resolution.streams, &resolution.grading);
        let lower = &all[a];
        let upper = solved[n].as_ref().expect("the next node comes after");
        let parts = suns_rad
            .iter()
            .zip(lower.iter().zip(upper))
            .map(|(&sun, (lo, hi))| {
                let beam = super::adding::sun_transmittance(&layers, sun.cos());
                Wavelength::between(lo, hi, t, beam, layers.ground_albedo)
            })
            .collect();
        all.push(parts);
    }
    all
}

/// `[wavelength][part]` to `[part][wavelength]`.
pub(super) fn transpose(by_wavelength: Vec<Vec<Wavelength>>, parts: usize) -> Vec<Vec<Wavelength>> {
    let mut by_part: Vec<Vec<Wavelength>> = (0..parts).map(|_| Vec::with_capacity(by_wavelength.len())).collect();
    for w in by_wavelength {
        for (k, part) in w.into_iter().enumerate() {
            by_part[k].push(part);
        }
    }
    by_part
}

/// One wavelength's multiply scattered light for the views of a set of
/// suns: the columns of the suns that see the day (`Columns::solve`), and
/// in spherical shells those of the suns from
/// `SPHERICAL_FROM_SUN_ZENITH_DEG` on (or all, with
/// `Resolution::spherical`) with their sources made spherical. Each set
/// of columns on one grid of multiples of the column step
/// (`columns::grid_for_suns`), so a sun's view reads the same columns
/// whether it is rendered alone or with the other slices of a bake (the
/// spherical iteration couples its columns, so its grid is the same for
/// every sun from `SPHERICAL_FROM_SUN_ZENITH_DEG` to `MAX_SUN_ZENITH_DEG`).
pub(super) struct Solved {
    layers: Layers,
    resolution: Resolution,
    day: Option<Columns>,
    twilight: Option<Columns>,
}

impl Solved {
    pub(super) fn new(scene: &Scene, optics: &Spectral, suns_rad: &[f64], resolution: &Resolution) -> Solved {
        let layers = Layers::new(&scene.medium, optics, 2 * resolution.streams, &resolution.grading);
        let step_rad = resolution.column_step_deg.to_radians();
        let (twilight, day): (Vec<f64>, Vec<f64>) =
            suns_rad.iter().partition(|&&z| Solved::is_twilight(&layers, resolution, z));
        let day = (!day.is_empty())
            .then(|| Columns::solve(&layers, resolution.streams, columns::grid_for_suns(&layers, &day, step_rad, 1.0)));
        let twilight = (!twilight.is_empty()).then(|| {
            // The node rays reach a ray's travel beyond the view's. One
            // grid for every sun of the judged span, so that a sun's view
            // is the same rendered alone or among a bake's slices.
            let span = [SPHERICAL_FROM_SUN_ZENITH_DEG.to_radians(), MAX_SUN_ZENITH_DEG.to_radians()];
            let suns: Vec<f64> = twilight.iter().chain(&span).copied().collect();
            let grid = columns::grid_for_suns(&layers, &suns, step_rad, 2.0);
            super::spherical::solve(&layers, resolution.streams, grid, &resolution.twilight.settings()).0
        });
        Solved { layers, resolution: *resolution, day, twilight }
    }

    /// Whether the sun at `sun_zenith_rad` takes the spherical source.
    fn is_twilight(layers: &Layers, resolution: &Resolution, sun_zenith_rad: f64) -> bool {
        layers.shell_radius_km.is_some()
            && (resolution.spherical || sun_zenith_rad >= SPHERICAL_FROM_SUN_ZENITH_DEG.to_radians())
    }

    /// The columns that serve the sun at `sun_zenith_rad`.
    fn columns_for(&self, sun_zenith_rad: f64) -> &Columns {
        let twilight = Solved::is_twilight(&self.layers, &self.resolution, sun_zenith_rad);
        let columns = if twilight { &self.twilight } else { &self.day };
        columns.as_ref().expect("the wavelength is solved for this sun")
    }

    /// The light of each sun of `suns_rad` (the suns solved for, one per
    /// part of the view); `pixel_rays[k]`: (pixel, zenith cosine, azimuth
    /// from the sun, reach km: infinite but in fog) of each pixel of part k
    /// looking up, where there are few enough of them or the view is fog. The other parts' tables of view nodes are made
    /// together, a view node's ray for all their suns at once
    /// (`Columns::rays_for_suns`): a part's table is what it would be alone.
    pub(super) fn wavelengths(&self, suns_rad: &[f64], pixel_rays: &[Option<&[PixelRay]>]) -> Vec<Wavelength> {
        let (cosines, azimuths) = self.resolution.view_grid;
        let phis = azimuth_nodes(azimuths);
        let mut tables: Vec<Vec<Vec<f64>>> = vec![Vec::new(); suns_rad.len()];
        for twilight in [false, true] {
            let parts: Vec<usize> = (0..suns_rad.len())
                .filter(|&k| pixel_rays[k].is_none())
                .filter(|&k| Solved::is_twilight(&self.layers, &self.resolution, suns_rad[k]) == twilight)
                .collect();
            let Some(&first) = parts.first() else { continue };
            let columns = self.columns_for(suns_rad[first]);
            let suns: Vec<(f64, &[f64])> = parts.iter().map(|&k| (suns_rad[k], &phis[..])).collect();
            let by_node: Vec<Vec<Vec<f64>>> =
                view_nodes(cosines).par_iter().map(|&mu| columns.rays_for_suns(&suns, mu)).collect();
            for node in by_node {
                for (&k, row) in parts.iter().zip(node) {
                    tables[k].push(row);
                }
            }
        }
        suns_rad
            .iter()
            .zip(pixel_rays)
            .zip(tables)
            .map(|((&sun, rays), table)| {
                let columns = self.columns_for(sun);
                let diffuse = match rays {
                    Some(rays) => DiffuseLight::Pixels(pixel_radiances(columns, sun, rays)),
                    None => DiffuseLight::Table(table),
                };
                Wavelength {
                    diffuse,
                    ground_irradiance: columns.ground_irradiance_at(sun),
                    sun_transmittance: super::adding::sun_transmittance(&self.layers, sun.cos()),
                    ground_albedo: self.layers.ground_albedo,
                }
            })
            .collect()
    }
}

/// A pixel's own ray: (pixel, zenith cosine, azimuth from the sun, reach
/// km along it).
pub(super) type PixelRay = (usize, f64, f64, f64);

/// The diffuse light along each pixel's own ray, by pixel index. Rays of
/// one zenith cosine and reach (a row of the Fog LUT: one elevation, its
/// azimuths) share one evaluation of the sources along them
/// (`Columns::rays_to` with all their azimuths), which is the costly
/// part; each pixel's value is the one its ray alone gives, bit for bit.
fn pixel_radiances(columns: &Columns, sun_zenith_rad: f64, rays: &[PixelRay]) -> Vec<f64> {
    let mut pixels = vec![0.0; rays.iter().map(|r| r.0 + 1).max().unwrap_or(0)];
    let mut groups: Vec<((u64, u64), Vec<(usize, f64)>)> = Vec::new();
    for &(i, mu, phi, reach_km) in rays {
        let key = (mu.to_bits(), reach_km.to_bits());
        match groups.iter_mut().find(|(k, _)| *k == key) {
            Some((_, members)) => members.push((i, phi)),
            None => groups.push((key, vec![(i, phi)])),
        }
    }
    for ((mu, reach_km), members) in groups {
        let phis: Vec<f64> = members.iter().map(|m| m.1).collect();
        let radiances = columns.rays_to(sun_zenith_rad, f64::from_bits(mu), &phis, f64::from_bits(reach_km));
        for ((i, _), radiance) in members.into_iter().zip(radiances) {
            pixels[i] = radiance;
        }
    }
    pixels
}

/// The light of one wavelength (a band or a spectral line), per unit solar
/// irradiance: the diffuse light reaching the ground on a grid of view
/// cosines and azimuths, the ground's irradiance, the beam's transmittance
/// to the ground, the ground's albedo.
#[derive(Clone)]
pub(super) struct Wavelength {
    pub(super) diffuse: DiffuseLight,
    pub(super) ground_irradiance: f64,
    pub(super) sun_transmittance: f64,
    pub(super) ground_albedo: f64,
}

/// The light scattered twice or more that reaches the ground.
#[derive(Clone)]
pub(super) enum DiffuseLight {
    /// `[k][p]`: at view cosine node k and azimuth node p.
    Table(Vec<Vec<f64>>),
    /// Along each pixel's own ray (views of few pixels looking up).
    Pixels(Vec<f64>),
}

/// Views with at most this many pixels looking up have the diffuse light
/// integrated along each pixel's own ray instead of the nodes' table (a
/// pixel's ray costs about half a view node's, which integrates 65
/// azimuths at once: the table of 128 nodes costs about 256 pixels' rays).
pub const PIXEL_RAYS: usize = 256;

impl Wavelength {
    /// The diffuse radiance toward a pixel looking up at cosine `mu`,
    /// azimuth `phi` from the sun: Catmull-Rom in √μ between the view
    /// nodes (clamped at the ends, and below the first node), and in
    /// azimuth between the azimuth nodes (mirrored about 0 and π, where
    /// the sky is symmetric).
    pub(super) fn diffuse_radiance(&self, pixel: usize, mu: f64, phi: f64) -> f64 {
        let table = match &self.diffuse {
            DiffuseLight::Pixels(p) => return p[pixel],
            DiffuseLight::Table(t) => t,
        };
        let (nodes, intervals) = (table.len(), table[0].len() - 1);
        let last = nodes as isize;
        let s = (mu.max(0.0).sqrt() * nodes as f64).clamp(1.0, last as f64);
        let k = (s.floor() as isize).min(last - 1);
        let wk = catmull_rom(s - k as f64);
        let ks = [k - 1, k, k + 1, k + 2].map(|i| (i.clamp(1, last) - 1) as usize);
        let folded = libm::atan2(phi.sin(), phi.cos()).abs();
        let t = folded / PI * intervals as f64;
        let p = (t.floor() as isize).min(intervals as isize - 1);
        let wp = catmull_rom(t - p as f64);
        let ps = [p - 1, p, p + 1, p + 2].map(|i| {
            let n = intervals as isize;
            (if i < 0 {
                -i
            } else if i > n {
                2 * n - i
            } else {
                i
            }) as usize
        });
        (0..4).map(|a| wk[a] * (0..4).map(|b| wp[b] * table[ks[a]][ps[b]]).sum::<f64>()).sum()
    }

    /// The light a fraction `t` of the way from `lo` to `hi` (in the
    /// logarithm of wavelength): the diffuse light and the ground's
    /// irradiance a power law through theirs (geometric where both are
    /// positive, else linear), with the beam's transmittance and the
    /// ground's albedo given.
    fn between(lo: &Wavelength, hi: &Wavelength, t: f64, sun_transmittance: f64, ground_albedo: f64) -> Wavelength {
        let lerp = |a: f64, b: f64| columns::log_lerp(a, b, t);
        let diffuse = match (&lo.diffuse, &hi.diffuse) {
            (DiffuseLight::Table(a), DiffuseLight::Table(b)) => DiffuseLight::Table(
                a.iter().zip(b).map(|(ra, rb)| ra.iter().zip(rb).map(|(&x, &y)| lerp(x, y)).collect()).collect(),
            ),
            (DiffuseLight::Pixels(a), DiffuseLight::Pixels(b)) => {
                DiffuseLight::Pixels(a.iter().zip(b).map(|(&x, &y)| lerp(x, y)).collect())
            }
            _ => unreachable!("the nodes of one part are read the same way"),
        };
        Wavelength {
            diffuse,
            ground_irradiance: lerp(lo.ground_irradiance, hi.ground_irradiance),
            sun_transmittance,
            ground_albedo,
        }
    }

    /// The radiance of the Lambertian ground.
    pub(super) fn ground_radiance(&self) -> f64 {
        self.ground_albedo / PI * self.ground_irradiance
    }
}

/// Catmull-Rom weights of the four nodes around a point a fraction `t` of
/// the way from the second to the third.
fn catmull_rom(t: f64) -> [f64; 4] {
    let (t2, t3) = (t * t, t * t * t);
    [0.5 * (-t3 + 2.0 * t2 - t), 0.5 * (3.0 * t3 - 5.0 * t2 + 2.0), 0.5 * (-3.0 * t3 + 4.0 * t2 + t), 0.5 * (t3 - t2)]
}

/// The view cosines the diffuse light is solved at.
fn view_nodes(count: usize) -> Vec<f64> {
    (1..=count).map(|k| (k as f64 / count as f64).powi(2)).collect()
}

/// The azimuths from the sun's the diffuse light is solved at, 0 to π.
fn azimuth_nodes(intervals: usize) -> Vec<f64> {
    (0..=intervals).map(|p| p as f64 * PI / intervals as f64).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::atmosphere::Atmosphere;
    use crate::mie::MieCache;
    use crate::render::medium::Medium;
    use crate::transport::layers::Grading;

    /// What the grids of view cosines and azimuths cost: the diffuse light
    /// interpolated between the nodes against the same light solved along
    /// each ray, in the hazed slab (the aerosol's forward lobe makes the
    /// most structure in azimuth) and in the clear sky in shells, for a
    /// high and a low sun, from the zenith to 0.1° above the horizon, at
    /// azimuths between the nodes. Bound: 1e-4 of the radiance, on the
    /// default grid and on the bake's (`BAKE_VIEW_GRID`) (measured: 7.8e-6,
    /// the hazed slab, sun 25°; 6.2e-6 with 256 view nodes, 8.4e-5 with 40
    /// azimuth intervals; the bake's 96 x 40, 8.4e-5). The draft bake's
    /// 64 x 32: bound 3e-4 (measured 1.8e-4).
    #[test]
    fn the_view_grid_interpolates_the_diffuse_light_within_1e_4() {
        let mus: Vec<f64> = (0..40)
            .map(|i| (0.1f64.to_radians()).sin().max(1e-3) + (i as f64 / 39.0).powi(3))
            .map(|m| m.min(1.0))
            .collect();
        let grids = [((VIEW_NODES, AZIMUTH_INTERVALS), 1e-4), (BAKE_VIEW_GRID, 1e-4), (DRAFT_VIEW_GRID, 3e-4)];
        for ((view_nodes_n, intervals), bound) in grids {
            let worst = view_grid_error(&mus, view_nodes_n, intervals);
            eprintln!(
                "{view_nodes_n} x {intervals}: worst interpolation error {:.2e} ({}, sun {:.0} deg, view cosine {:.4}, azimuth {:.2})",
                worst.0, worst.1, worst.2, worst.3, worst.4
            );
            assert!(worst.0 < bound, "{view_nodes_n} x {intervals}: {worst:?}");
        }
    }

    /// The worst relative error of the diffuse light interpolated on a grid
    /// of `nodes` view cosines and `intervals` azimuth intervals (see above).
    fn view_grid_error(mus: &[f64], nodes: usize, intervals: usize) -> (f64, &'static str, f64, f64, f64) {
        let phis: Vec<f64> = [0.3, 1.0, 1.5, 2.2, 3.0].iter().map(|p| p + 0.37 * PI / intervals as f64).collect();
        let mut worst = (0.0f64, "", 0.0, 0.0, 0.0);
        for file in ["tests/atmospheres/disort_rayleigh_hg.toml", "atmospheres/clear.toml"] {
            let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(file);
            let atm = Atmosphere::load(&path).unwrap();
            let medium = Medium::new(&atm);
            let optics = medium.spectral(&atm, 450.0, 1.0, 0.3, &MieCache::shared_by_tests());
            let layers = Layers::new(&medium, &optics, 32, &Grading::default());
            for sun in [25f64.to_radians(), 81f64.to_radians()] {
                let columns = Columns::solve(&layers, 16, columns::grid(&layers, sun, 1f64.to_radians()));
                let phi_nodes = azimuth_nodes(intervals);
                let grid = Wavelength {
                    diffuse: DiffuseLight::Table(
                        view_nodes(nodes).iter().map(|&mu| columns.rays(sun, mu, &phi_nodes)).collect(),
                    ),
                    ground_irradiance: 0.0,
                    sun_transmittance: 0.0,
                    ground_albedo: 0.3,
                };
                for &mu in mus {
                    for (want, &phi) in columns.rays(sun, mu, &phis).iter().zip(&phis) {
                        let rel = (grid.diffuse_radiance(0, mu, phi) - want).abs() / want;
                        if rel > worst.0 {
                            worst = (rel, file, sun.to_degrees(), mu, phi);
                        }
                    }
                }
            }
        }
        worst
    }

    /// Rays of one elevation and reach share their sources' evaluation
    /// (`pixel_radiances`), and each pixel still gets the value its ray
    /// alone gives, bit for bit: fog rows, mixed with rays of other
    /// elevations and reaches, in any order.
    #[test]
    fn rays_of_one_elevation_share_their_sources_bit_for_bit() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("atmospheres/clear.toml");
        let atm = Atmosphere::load(&path).unwrap();
        let medium = Medium::new(&atm);
        let optics = medium.spectral(&atm, 550.0, 1.0, 0.3, &MieCache::shared_by_tests());
        let layers = Layers::new(&medium, &optics, 8, &Grading::default().coarser());
        let sun = 60f64.to_radians();
        let columns = Columns::solve(&layers, 4, columns::grid(&layers, sun, 2f64.to_radians()));
        let rays: Vec<PixelRay> = vec![
            (3, 0.3, 0.2, 5.0),
            (0, 0.3, 1.7, 5.0),
            (5, 0.5, 0.2, 5.0),
            (1, 0.3, 2.9, 5.0),
            (2, 0.3, 0.2, f64::INFINITY),
            (4, 0.5, 3.1, 5.0),
        ];
        let shared = pixel_radiances(&columns, sun, &rays);
        for &(i, mu, phi, reach_km) in &rays {
            let alone = columns.rays_to(sun, mu, &[phi], reach_km)[0];
            assert!(alone > 0.0);
            assert_eq!(shared[i].to_bits(), alone.to_bits(), "pixel {i}");
        }
    }

    /// Catmull-Rom reproduces a cubic's values at the nodes and sums to one.
    #[test]
    fn catmull_rom_weights_are_a_partition_of_unity() {
        for t in [0.0, 0.25, 0.5, 0.9] {
            let w = catmull_rom(t);
            assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            // Exact for a line: nodes at -1, 0, 1, 2.
            let line: f64 = w.iter().zip([-1.0, 0.0, 1.0, 2.0]).map(|(a, x)| a * x).sum();
            assert!((line - t).abs() < 1e-12);
        }
        assert_eq!(catmull_rom(0.0), [0.0, 1.0, 0.0, 0.0]);
    }
}
