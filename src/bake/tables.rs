//! The tables of a bake that come straight from a basis sky's prepared
//! scene, without rendering: the sun's transmittance (the Transmittance
//! LUT, Bruneton's layout) and the low atmosphere's transmittance to each
//! depth (the Attenuation LUT). Their layouts, decoders and texels are the
//! runtime contract's, in [`crate::lut::transmittance`] and
//! [`crate::lut::fog`]; what fills them needs the renderer's optics, so it
//! lives here.

use crate::colour::Mat3;
use crate::directions::camera::direction_deg;
use crate::lut::fog::{attenuation_texel, AttenuationTable, FogGeometry, ATTENUATION_SIZE};
use crate::lut::transmittance::{channel_ratio, TransmittanceMapping, TransmittanceTable, HEIGHT, WIDTH};
use crate::render::single::SingleScattering;
use crate::render::Scene;

/// The Transmittance table of a scene, from its band optics and column table.
pub fn transmittance_table(scene: &Scene) -> TransmittanceTable {
    let m = &scene.medium;
    let mapping = TransmittanceMapping::new(m.radius_km, m.top_km);
    let mut xyz = Vec::with_capacity(WIDTH * HEIGHT);
    for j in 0..HEIGHT {
        for i in 0..WIDTH {
            let (r, mu) = mapping.r_mu(i as f64 / (WIDTH - 1) as f64, j as f64 / (HEIGHT - 1) as f64);
            xyz.push(sun_xyz_at(scene, r - m.radius_km, mu));
        }
    }
    let top_xyz = scene.bands.weight.iter().fold([0.0; 3], |a, w| [a[0] + w[0], a[1] + w[1], a[2] + w[2]]);
    TransmittanceTable { mapping, xyz, top_xyz }
}

/// XYZ of the sun's irradiance reaching altitude `z_km` along cosine `mu`
/// (to space), directly from the scene's column table: Σ_b W_b T_b.
pub fn sun_xyz_at(scene: &Scene, z_km: f64, mu: f64) -> [f64; 3] {
    let mut xyz = [0.0; 3];
    for (w, o) in scene.bands.weight.iter().zip(&scene.band_optics) {
        let tau = scene.columns.optical_depth(z_km.max(0.0), mu, &o.extinction);
        let t = if tau.is_finite() { libm::exp(-tau) } else { 0.0 };
        for c in 0..3 {
            xyz[c] += w[c] * t;
        }
    }
    xyz
}

/// The Attenuation table of a scene: by the single-scattering quadrature's
/// view transmittance under the ceiling (`SingleScattering::transmittance_to`).
pub fn attenuation_table(scene: &Scene, geometry: FogGeometry) -> AttenuationTable {
    // The transmittance does not depend on the sun: any will do.
    let ss = SingleScattering::bands(scene, glam::DVec3::Z, geometry.observer_altitude_km);
    let mut xyz = Vec::with_capacity(ATTENUATION_SIZE * ATTENUATION_SIZE);
    for j in 0..ATTENUATION_SIZE {
        for i in 0..ATTENUATION_SIZE {
            let (depth, elevation) = attenuation_texel(&geometry, i, j);
            xyz.push(attenuated_xyz(scene, &ss, &geometry, depth, elevation));
        }
    }
    AttenuationTable {
        geometry,
        xyz,
        unattenuated_xyz: weighted(&scene.bands.weight, &vec![1.0; scene.band_optics.len()]),
    }
}

/// The per-channel transmittance (space of `m`) of one view to one
/// depth, computed as the table's texels are but at any point: what
/// the decoded table is checked against (`bake::verify_fog`).
pub fn direct_attenuation_rgb(
    scene: &Scene,
    geometry: &FogGeometry,
    depth_km: f64,
    elevation_deg: f64,
    m: &Mat3,
) -> [f64; 3] {
    let ss = SingleScattering::bands(scene, glam::DVec3::Z, geometry.observer_altitude_km);
    let xyz = attenuated_xyz(scene, &ss, geometry, depth_km, elevation_deg);
    let top = weighted(&scene.bands.weight, &vec![1.0; scene.band_optics.len()]);
    channel_ratio(crate::colour::apply(m, xyz), crate::colour::apply(m, top))
}

/// The XYZ of the sun's spectrum (the bands' weights) after the low
/// atmosphere along a view of `elevation_deg` (clamped to the upper
/// hemisphere) to `depth_km`: a texel of the Attenuation table.
fn attenuated_xyz(
    scene: &Scene,
    ss: &SingleScattering,
    geometry: &FogGeometry,
    depth_km: f64,
    elevation_deg: f64,
) -> [f64; 3] {
    let t = if depth_km > 0.0 {
        ss.transmittance_to(
            direction_deg(90.0 - elevation_deg.clamp(0.0, 90.0), 0.0),
            depth_km,
            Some(geometry.ceiling_km),
        )
    } else {
        vec![1.0; scene.band_optics.len()]
    };
    weighted(&scene.bands.weight, &t)
}

/// Σ_b w_b t_b per channel.
fn weighted(weight: &[[f64; 3]], t: &[f64]) -> [f64; 3] {
    let mut xyz = [0.0; 3];
    for (w, tb) in weight.iter().zip(t) {
        for c in 0..3 {
            xyz[c] += w[c] * tb;
        }
    }
    xyz
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::atmosphere::Atmosphere;
    use crate::lut::transmittance::distance_to_top_km;
    use crate::mie::MieCache;
    use crate::render::{SpectralSettings, WavelengthSampling};

    /// An atmosphere file of the repository, by its path from the root.
    fn load(path: &str) -> Atmosphere {
        Atmosphere::load(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(path)).unwrap()
    }

    /// The prepared scene of `atm` at hero-wavelength sampling in bands of `band_nm`, XYZ only.
    fn hero_scene(atm: Atmosphere, band_nm: f64) -> Scene {
        let spectral =
            SpectralSettings { band_nm, wavelength_sampling: WavelengthSampling::Hero, spectral_nm: vec![], xyz: true };
        Scene::new(&atm, &spectral, &MieCache::shared_by_tests(), &|| {})
    }

    fn geometry() -> FogGeometry {
        FogGeometry { planet_radius_km: 6371.0, observer_altitude_km: 0.0, ceiling_km: 3.0 }
    }

    /// The table's bilinear decode against the column table's own
    /// transmittance at points between texel centres, the clear sky from 0
    /// to 12 km: within 0.2 % of the sun's Y wherever the sun is more than
    /// half a degree above the grazing ray (measured: 0.11 %, at the top of
    /// the aerosols' boundary layer at 2 km, whose kink falls between rows
    /// about 0.45 km apart there; 0.05 % elsewhere), and the sun's colour
    /// goes red toward the horizon.
    #[test]
    fn the_table_decodes_the_column_tables_transmittance() {
        let scene = hero_scene(load("atmospheres/clear.toml"), 20.0);
        let table = transmittance_table(&scene);
        let top_y = table.top_xyz[1];
        let mut worst: f64 = 0.0;
        for k in 0..400 {
            let z = 12.0 * ((k * 7919) % 400) as f64 / 400.0;
            let r = table.mapping.bottom_radius_km + z;
            let lo = table.mapping.mu_horizon(r).acos().to_degrees() - 0.5;
            let zenith_deg = lo * ((k * 104729) % 1000) as f64 / 1000.0;
            let mu = zenith_deg.to_radians().cos();
            let exact = sun_xyz_at(&scene, z, mu)[1];
            let decoded = table.sample_xyz(z, mu)[1];
            worst = worst.max((decoded - exact).abs() / top_y);
        }
        assert!(worst < 2e-3, "worst error {worst:e} of the sun's Y");
        let rgb = table.channel_texels(&crate::colour::ColourSpace::Rec709.xyz_to_rgb());
        let noon = rgb[0];
        let low = rgb[WIDTH - 8];
        assert!(noon.iter().all(|&t| t > 0.5 && t < 1.0), "{noon:?}");
        assert!(low[0] > low[1] && low[1] > low[2], "{low:?}");
        // Below the grazing ray: nothing.
        assert_eq!(table.sample_xyz(0.0, -0.05), [0.0; 3]);
    }

    /// The column table (what the LUT is made from) against an independent
    /// quadrature of the optical depth along the curved ray for the
    /// exponential Rayleigh slab of the DISORT tests, made spherical:
    /// σ(z) = σ₀ e^(−z/8 km) integrated by the midpoint rule on 20 000
    /// steps, at sun zeniths up to 89°, from 0 and 5 km.
    #[test]
    fn the_column_tables_transmittance_matches_quadrature() {
        let mut atm = load("tests/atmospheres/disort_rayleigh.toml");
        atm.planet.geometry = crate::atmosphere::Geometry::Spherical;
        let scene = hero_scene(atm, 40.0);
        let (rad, top) = (scene.medium.radius_km, scene.medium.top_km);
        let o = &scene.band_optics[0];
        let sigma0: f64 = o.extinction[0] * scene.medium.density(0, 0.0);
        for z0 in [0.0, 5.0] {
            for deg in [0.0, 45.0, 75.0, 85.0, 89.0] {
                let mu = f64::to_radians(deg).cos();
                let r0 = rad + z0;
                let len = distance_to_top_km(r0, mu, rad + top);
                let n = 20_000;
                let ds = len / n as f64;
                let tau: f64 = (0..n)
                    .map(|k| {
                        let s = (k as f64 + 0.5) * ds;
                        let r = (r0 * r0 + s * s + 2.0 * r0 * s * mu).sqrt();
                        sigma0 * (-(r - rad) / 8.0).exp() * ds
                    })
                    .sum();
                let ours = scene.columns.optical_depth(z0, mu, &o.extinction);
                assert!((ours / tau - 1.0).abs() < 2e-3, "{z0} km, {deg} deg: column {ours}, quadrature {tau}");
            }
        }
    }

    /// The Attenuation table against the quadrature's transmittance of the
    /// same rays in the hazed sky: its bilinear decode between texels is
    /// within 1 % of a direct evaluation, plus 1e-3 where the object is all
    /// but hidden (0.3° up at 30 km, T = 7.6e-4, decodes 8.3e-4: near the
    /// horizon depth_max changes fast from row to row, so a fixed depth is
    /// at different u in the two rows blended); 1 at depth 0, falling with
    /// depth.
    #[test]
    fn the_attenuation_table_decodes_to_the_direct_transmittance() {
        let scene = hero_scene(load("atmospheres/hazed.toml"), 40.0);
        let g = geometry();
        let table = attenuation_table(&scene, g);
        let y = |xyz: [f64; 3]| xyz[1] / table.unattenuated_xyz[1];
        assert!((y(table.xyz[0]) - 1.0).abs() < 1e-12);
        let ss = SingleScattering::bands(&scene, glam::DVec3::Z, 0.0);
        for elevation in [0.3f64, 2.0, 7.0, 30.0, 70.0] {
            let mut last = 1.0;
            for depth in [0.1f64, 1.0, 5.0, 30.0, 150.0] {
                if depth > g.depth_max_km(elevation) {
                    continue;
                }
                let direct = y(weighted(
                    &scene.bands.weight,
                    &ss.transmittance_to(direction_deg(90.0 - elevation, 0.0), depth, Some(3.0)),
                ));
                let decoded = y(table.sample_xyz(depth, elevation));
                eprintln!("elevation {elevation}, {depth} km: decoded {decoded:.5e}, direct {direct:.5e}");
                assert!(
                    (decoded - direct).abs() < 0.01 * direct + 1e-3,
                    "elevation {elevation}, {depth} km: decoded {decoded}, direct {direct}"
                );
                assert!(direct < last);
                last = direct;
            }
        }
    }
}
