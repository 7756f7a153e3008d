//! The path tracer's global fog (`render::fog`, issue 13) against
//! references it does not share code with: its sunlight scattered once
//! toward the camera against the deterministic quadrature of
//! `render::single` (an independent integration of the same integral, by
//! steps instead of by Monte Carlo collisions), and, at infinite depth with
//! no ceiling, against the sky (the talk: global fog "has the same
//! radiance at infinity as the sky").

use crate::common::Family;
use sky::atmosphere::Atmosphere;
use sky::directions::camera::direction_deg;
use sky::mie::MieCache;
use sky::render::fog::Fog;
use sky::render::guide::RayGuide;
use sky::render::kernel::{Kernel, Scratch};
use sky::render::rng::Rng;
use sky::render::single::SingleScattering;
use sky::render::tracer::{Estimator, Tracer};
use sky::render::{self, Scene, SpectralSettings, View, WavelengthSampling};
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn scene(name: &str, spectral: &SpectralSettings) -> Scene {
    let atm = Atmosphere::load(&root().join(format!("atmospheres/{name}.toml"))).unwrap();
    Scene::new(&atm, spectral, &MieCache::shared_by_tests(), &|| {})
}

/// The family-wise false-alarm rate of the tests below.
const ALPHA: f64 = 0.01;

/// The fog's first vertex: the path tracer's next-event estimate toward
/// the sun at the camera ray's first collision (forced within the fog's
/// reach, the object and the ground black) is the difference of a Fog and
/// a Shadowed Fog path drawn from the same random numbers (the estimate
/// draws none of its own), and its mean must be the quadrature's
/// `radiance_to`. Cases: the clear sky (sun 60°; from the ground; rays
/// 2°, 10° and 40° up to 1, 10 and 60 km, and level under a 1 km
/// ceiling), the hazed sky with a low sun (85°, from 500 m: a ray 2° down
/// meets the ground after 14 km, which must stay black, and rays under a
/// 3 km ceiling), and cloudy1 under its cloud base (3 km; the lit cloud
/// above must not scatter into the camera ray). 20 000 paths each, at
/// 550 nm; every z against the Šidák threshold for the family at 1 % and
/// the aggregate Σz/√m against a bias common to all. The standard error of
/// each comparison is printed relative to the fog (at most a few tenths of
/// a per cent: the noise level at which a bias of the size that matters
/// for a LUT would show).
#[test]
fn the_fogs_first_vertex_matches_the_quadrature() {
    let spectral = SpectralSettings {
        band_nm: 40.0,
        wavelength_sampling: WavelengthSampling::Hero,
        spectral_nm: vec![550.0],
        xyz: false,
    };
    // (sky, sun zenith, observer km, ceiling km, [(view zenith, distance km)])
    type Case<'a> = (&'a str, f64, f64, Option<f64>, &'a [(f64, f64)]);
    let cases: [Case; 5] = [
        ("clear", 60.0, 0.0, None, &[(88.0, 1.0), (88.0, 10.0), (88.0, 60.0), (80.0, 10.0), (50.0, 60.0)]),
        ("clear", 60.0, 0.0, Some(1.0), &[(90.0, 200.0), (80.0, f64::INFINITY)]),
        ("hazed", 85.0, 0.5, None, &[(92.0, f64::INFINITY), (89.5, 20.0)]),
        ("hazed", 85.0, 0.5, Some(3.0), &[(70.0, f64::INFINITY), (89.0, 100.0)]),
        ("cloudy1", 60.0, 0.0, Some(3.0), &[(30.0, f64::INFINITY), (85.0, 40.0), (89.0, f64::INFINITY)]),
    ];
    let samples = 20_000u64;
    let mut family = Family::default();
    let mut worst = 0.0f64;
    for (name, sun_zenith_deg, altitude_km, ceiling_km, views) in cases {
        let scene = scene(name, &spectral);
        let sun = direction_deg(sun_zenith_deg, 0.0);
        let sp = &scene.line_optics[0];
        let ss = SingleScattering::new(&scene.medium, &scene.columns, &scene.line_optics, sun, altitude_km);
        for (j, &(view_zenith_deg, distance_km)) in views.iter().enumerate() {
            let fog = Fog::lit(distance_km, ceiling_km);
            let make = |skip: bool| {
                Tracer::new(&scene.medium, sp, sun, 0.533, Estimator::Full)
                    .with_sun_disk(false)
                    .with_columns(&scene.columns)
                    .with_single_skipped(skip)
                    .with_fog(Some(fog))
            };
            let (lit, shadowed) = (make(false), make(true));
            let origin = lit.observer(altitude_km);
            let d = direction_deg(view_zenith_deg, 150.0);
            let guide = RayGuide::build(&lit, origin, d);
            let mut scratch = Scratch::default();
            let (mut m1, mut m2, mut total) = (0.0, 0.0, 0.0);
            for k in 0..samples {
                let a = Kernel::single(&lit)
                    .radiance(origin, d, guide.as_ref(), &mut scratch, &mut Rng::new(11, j as u64, k))
                    .scattered[0];
                let b = Kernel::single(&shadowed)
                    .radiance(origin, d, guide.as_ref(), &mut scratch, &mut Rng::new(11, j as u64, k))
                    .scattered[0];
                m1 += a - b;
                m2 += (a - b) * (a - b);
                total += a;
            }
            let n = samples as f64;
            let mean = m1 / n;
            let se = ((m2 / n - mean * mean).max(0.0) / (n - 1.0)).sqrt();
            let quad = ss.radiance_to(d, distance_km, ceiling_km)[0];
            let z = if se > 0.0 {
                (mean - quad) / se
            } else if mean == quad {
                0.0
            } else {
                f64::INFINITY
            };
            let label = format!("{name} sun {sun_zenith_deg} from {altitude_km} km under {ceiling_km:?} km, view {view_zenith_deg} to {distance_km} km");
            eprintln!("{label}: quadrature {quad:.5e}, Monte Carlo {mean:.5e} ± {se:.1e} (z {z:+.2}); fog {:.4e}, error {:.3} % of it", total / n, 100.0 * se / (total / n));
            assert!(quad > 0.0, "{label}: no single scattering");
            family.push(label, z);
            worst = worst.max(se / (total / n));
        }
    }
    let failures = family.failures(ALPHA);
    assert!(failures.is_empty(), "{failures:#?}");
    eprintln!("aggregate Σz/√m {:+.2}; worst standard error {:.3} % of the fog", family.aggregate(), 100.0 * worst);
}

/// A view of the directions `dirs` (zenith, azimuth), sun at azimuth 0.
fn directions(dirs: &[(f64, f64)], sun_zenith_deg: f64, spp: u32, seed: u64, fog: Option<Fog>) -> View {
    View { fog, ..View::directions(dirs.to_vec(), sun_zenith_deg, 0.0, spp, seed) }
}

/// The talk's consistency condition, through the whole renderer (hero
/// bands, XYZ, single scattering by quadrature, the guides): the fog at
/// infinite depth with no ceiling, toward directions that leave the
/// atmosphere, is the sky's radiance there. Clear and cloudy1 (sun 60°),
/// six directions each from the zenith to 1° above the horizon, 256
/// samples of each from independent seeds; Y compared with the Šidák
/// threshold at 1 % and the aggregate. Also: under a ceiling, or in front
/// of an object, the fog is darker than the sky, and the Shadowed Fog
/// darker still.
#[test]
fn fog_at_infinite_depth_is_the_sky() {
    let spectral = SpectralSettings {
        band_nm: 10.0,
        wavelength_sampling: WavelengthSampling::Hero,
        spectral_nm: vec![],
        xyz: true,
    };
    let dirs = [(0.0, 0.0), (40.0, 0.0), (60.0, 180.0), (80.0, 90.0), (87.0, 0.0), (89.0, 180.0)];
    let mut family = Family::default();
    for name in ["clear", "cloudy1"] {
        let scene = scene(name, &spectral);
        let render = |v: View| render::render(&scene, &v, &AtomicBool::new(false), &|| {}).unwrap();
        let sky = render(directions(&dirs, 60.0, 256, 1, None));
        let fog = render(directions(&dirs, 60.0, 256, 2, Some(Fog::lit(f64::INFINITY, None))));
        let near = render(directions(&dirs, 60.0, 64, 3, Some(Fog::lit(5.0, Some(3.0)))));
        let shadowed = render(directions(&dirs, 60.0, 64, 3, Some(Fog::lit(5.0, Some(3.0)).shadowed())));
        for (k, (zenith, azimuth)) in dirs.iter().enumerate() {
            let (a, b) = (&sky.pixels[k], &fog.pixels[k]);
            let se = a.xyz_stderr[1].hypot(b.xyz_stderr[1]);
            let z = (b.xyz[1] - a.xyz[1]) / se;
            let label = format!("{name}, view ({zenith}, {azimuth})");
            eprintln!(
                "{label}: sky Y {:.5e}, fog at infinity {:.5e} (z {z:+.2}); 5 km under 3 km {:.4e}, shadowed {:.4e}",
                a.xyz[1], b.xyz[1], near.pixels[k].xyz[1], shadowed.pixels[k].xyz[1]
            );
            family.push(label.clone(), z);
            assert!(near.pixels[k].xyz[1] < 0.9 * a.xyz[1], "{label}: the near fog is not darker than the sky");
            assert!(
                shadowed.pixels[k].xyz[1] < near.pixels[k].xyz[1],
                "{label}: the Shadowed Fog is not darker than the fog"
            );
            assert!(shadowed.pixels[k].xyz[1] > 0.0, "{label}: the Shadowed Fog is black");
        }
    }
    let failures = family.failures(ALPHA);
    assert!(failures.is_empty(), "{failures:#?}");
}

/// A fog the renderer cannot render is refused with a reason, not drawn:
/// an observer above the ceiling, a distance that is not positive, the
/// naive estimator.
#[test]
fn impossible_fogs_are_refused() {
    let mut v = directions(&[(0.0, 0.0)], 60.0, 4, 1, Some(Fog::lit(5.0, Some(1.0))));
    assert!(v.check().is_ok());
    v.altitude_m = 1500.0;
    assert!(v.check().unwrap_err().contains("ceiling"));
    v.altitude_m = 0.0;
    v.fog = Some(Fog::lit(0.0, None));
    assert!(v.check().unwrap_err().contains("distance"));
    v.fog = Some(Fog::lit(5.0, None));
    v.estimator = Estimator::Naive;
    assert!(v.check().unwrap_err().contains("naive"));
}
