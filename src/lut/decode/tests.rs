//! The reference decoder's unit tests: a smooth synthetic sky baked into
//! every slice and read back through the decoder.

use super::*;
use crate::lut::manifest::SliceEntry;

const R: f64 = 6371.0;
const TOP: f64 = 100.0;

/// A smooth sky of world direction and sun: brighter toward the sun
/// and the horizon.
fn sky(d: DVec3, sun: DVec3) -> [f64; 3] {
    let c = d.dot(sun);
    let base = 1.0 + 0.6 * c + 0.3 * c * c + 0.4 * (1.0 - d.z.abs());
    [base, 2.0 * base, 0.5 + base]
}

fn entry_and_texture(w: usize, h: usize) -> (SkyEntry, Texture) {
    let threshold = mapping::default_threshold_deg(w, h);
    let mut slices = Vec::new();
    let mut layers = Vec::new();
    for i in 0..mapping::SLICES {
        let z = mapping::slice_sun_zenith_deg(i, R, TOP);
        let m = DirectionMapping::new(z, threshold);
        let sun = crate::directions::camera::direction_deg(z, 0.0);
        let scale_log2 = (i % 5) as i32 - 2;
        let layer = (0..h).flat_map(|y| (0..w).map(move |x| (x, y))).map(|(x, y)| {
            let d = m.direction((x as f64 + 0.5) / w as f64, (y as f64 + 0.5) / h as f64);
            sky(d, sun).map(|v| (v * (scale_log2 as f64).exp2()) as f32)
        });
        layers.push(layer.collect());
        slices.push(SliceEntry {
            index: i,
            sun_zenith_deg: z,
            scale_log2,
            mean_samples: 1.0,
            median_rel_stderr_y: 0.0,
        });
    }
    let entry = SkyEntry {
        name: "clear".into(),
        file: String::new(),
        format: String::new(),
        vk_format: 122,
        bytes: 0,
        width: w,
        height: h,
        layers: mapping::SLICES,
        atmosphere: String::new(),
        atmosphere_hash: String::new(),
        altitude_m: 0.0,
        planet_radius_km: R,
        top_km: TOP,
        d_min_km: TOP,
        d_max_km: mapping::horizontal_distance_km(R, TOP),
        threshold_sun_zenith_deg: threshold,
        slices,
        texels_clamped: 0,
        texels_denormal: 0,
        texels_negative_rgb: 0,
        sun: None,
        ambient: None,
    };
    (entry, Texture { width: w, height: h, layers })
}

#[test]
fn texel_centres_of_a_slice_decode_to_their_texels() {
    let (e, t) = entry_and_texture(32, 128);
    for i in [0, 10, 30, 46, 47, 50, 63] {
        let z = e.slices[i].sun_zenith_deg;
        let m = DirectionMapping::new(z, e.threshold_sun_zenith_deg);
        for (x, y) in [(0, 0), (5, 17), (31, 100), (16, 127), (20, 64)] {
            let d = m.direction((x as f64 + 0.5) / 32.0, (y as f64 + 0.5) / 128.0);
            // Any sun azimuth: the direction turns with the sun.
            let az: f64 = 37.0;
            let (s, c) = (az.to_radians().sin(), az.to_radians().cos());
            let world = DVec3::new(c * d.x - s * d.y, s * d.x + c * d.y, d.z);
            let got = sample_sky(&e, &t, z, az, world);
            let want = sky(d, crate::directions::camera::direction_deg(z, 0.0));
            for c in 0..3 {
                assert!((got[c] / want[c] - 1.0).abs() < 1e-5, "slice {i} texel ({x}, {y}): {got:?} vs {want:?}");
            }
            // And its mirror image reads the same texel.
            let mirror = sample_sky(&e, &t, z, 0.0, DVec3::new(d.x, -d.y, d.z));
            assert!((mirror[1] / want[1] - 1.0).abs() < 1e-5);
        }
    }
}

#[test]
fn the_decoded_sky_has_no_step_in_time() {
    // Along the sun's elevation in 0.05 degree steps, across every slice
    // boundary and the switch between the two direction mappings, the
    // decoded sky moves by at most a small fraction per step: the
    // decoder interpolates, it never jumps. (A sun above the horizon
    // moves the sky's pattern by up to 0.05 degrees of 11 per texel in
    // u: well under 1 %.) Not at the zenith: below the threshold the
    // latitude-longitude mapping's first row lies 11 degrees from the
    // zenith (its transform has infinite slope at v = 0), so the zenith
    // reads that row, and the step from the last sun-centred slice to
    // the first latitude-longitude one is as large as the sky's change
    // over those 11 degrees (`sky lut verify` measures it on real skies).
    // Likewise, across the one slice interval where the mapping switches,
    // the two slices sample a direction differently, and a step there is
    // allowed up to 3 %.
    let (e, t) = entry_and_texture(32, 128);
    let switch = e.slices.iter().position(|s| s.sun_zenith_deg > e.threshold_sun_zenith_deg).unwrap();
    let switch_zenith_deg = (e.slices[switch - 1].sun_zenith_deg, e.slices[switch].sun_zenith_deg);
    for (zen, az) in [(25.0, 0.0), (45.0, 30.0), (80.0, 170.0), (89.0, 90.0), (60.0, 300.0), (88.0, 5.0)] {
        let d = crate::directions::camera::direction_deg(zen, az);
        let mut last: Option<f64> = None;
        for k in 0..=2000 {
            let elev = -10.0 + k as f64 * 0.05;
            let y = sample_sky(&e, &t, 90.0 - elev, 0.0, d)[1];
            if let Some(l) = last {
                let bound = if (switch_zenith_deg.0..=switch_zenith_deg.1 + 0.05).contains(&(90.0 - elev)) {
                    0.03
                } else {
                    0.01
                };
                assert!((y / l - 1.0).abs() < bound, "direction ({zen}, {az}), sun elevation {elev}: {l} -> {y}");
            }
            last = Some(y);
        }
    }
}

#[test]
fn basis_skies_blend_by_the_weather_rule() {
    let (mut e, t) = entry_and_texture(8, 16);
    let mut hazed = e.clone();
    hazed.name = "hazed".into();
    let t2 = Texture {
        layers: t.layers.iter().map(|l| l.iter().map(|p| p.map(|v| 3.0 * v)).collect()).collect(),
        ..t.clone()
    };
    e.name = "clear".into();
    let manifest = crate::lut::manifest::tests::manifest_with(vec![e, hazed]);
    let luts =
        Luts { manifest, textures: vec![t, t2], transmittance: Vec::new(), fog: None, ambient_texture: Vec::new() };
    let d = crate::directions::camera::direction_deg(50.0, 20.0);
    let clear = luts.sample(30.0, 0.0, 0.0, 0.0, d);
    let half = luts.sample(30.0, 0.0, 0.5, 0.0, d);
    assert!((half[1] / clear[1] - 2.0).abs() < 1e-6, "{half:?} {clear:?}");
    // Cloudiness moves toward basis skies this bake lacks: what is
    // present is renormalised, so the sky neither darkens nor vanishes.
    let cloudy = luts.sample(30.0, 0.0, 0.5, 0.1, d);
    assert!((cloudy[1] / clear[1] - 2.0).abs() < 1e-6, "{cloudy:?} {clear:?}");
}
