//! The Shadowed Fog rendered at a size of its own (`fog_ms_size` in a bake
//! preset) and resampled to the Fog LUT's size. Its source names the cache
//! key of a Fog slice made so (`SKY_FOG_RESAMPLE_SOURCE`, build.rs).

use super::cache::RenderedSlice;

/// A Shadowed Fog slice rendered at a size of its own, resampled to the
/// Fog LUT's `width` × `height`: bilinear in the LUT's (u, v) (azimuth from
/// the sun, linear; the square root of the elevation), whose texels lie on
/// the edges of [0, 1]² at any size (`lut::fog::texel_position`), so every
/// texel lies between rendered ones. Multiple scattering is smooth in
/// direction, so far fewer texels carry it (measured against whole slices
/// with `examples/compare_slices.rs`, README "The fog's multiple scattering
/// at a smaller size"). A texel's standard error is that of the weighted
/// sum, √(Σ wᵢ² σᵢ²), and its samples its nearest rendered texel's; the
/// cost stays the render's.
pub fn resample_shadowed(slice: &RenderedSlice, width: usize, height: usize) -> RenderedSlice {
    if (slice.width, slice.height) == (width, height) {
        return slice.clone();
    }
    // For each target texel along an axis: the rendered texel below it and
    // the weight of the one above.
    let axis = |to: usize, from: usize| -> Vec<(usize, f64)> {
        (0..to)
            .map(|i| {
                let x = crate::lut::fog::texel_position(i, to) * (from - 1) as f64;
                let k = (x.floor() as usize).min(from.saturating_sub(2));
                (k, (x - k as f64).clamp(0.0, 1.0))
            })
            .collect()
    };
    let (us, vs) = (axis(width, slice.width), axis(height, slice.height));
    let mut out = RenderedSlice {
        width,
        height,
        xyz: Vec::with_capacity(width * height),
        xyz_stderr: Vec::with_capacity(width * height),
        samples: Vec::with_capacity(width * height),
        ..slice.clone()
    };
    for &(j, b) in &vs {
        for &(i, a) in &us {
            let (i1, j1) = ((i + 1).min(slice.width - 1), (j + 1).min(slice.height - 1));
            let corners =
                [(i, j, (1.0 - a) * (1.0 - b)), (i1, j, a * (1.0 - b)), (i, j1, (1.0 - a) * b), (i1, j1, a * b)];
            let (mut xyz, mut var) = ([0.0; 3], [0.0; 3]);
            for &(ci, cj, w) in &corners {
                let k = cj * slice.width + ci;
                for c in 0..3 {
                    xyz[c] += w * slice.xyz[k][c];
                    var[c] += (w * slice.xyz_stderr[k][c]).powi(2);
                }
            }
            let nearest = corners.iter().max_by(|p, q| p.2.total_cmp(&q.2)).expect("four corners");
            out.xyz.push(xyz);
            out.xyz_stderr.push(var.map(f64::sqrt));
            out.samples.push(slice.samples[nearest.1 * slice.width + nearest.0]);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Resampling a Shadowed Fog slice from its own size to the LUT's: a
    /// field bilinear in (u, v) comes back exactly at every texel (the
    /// rendered texels, on the edges of [0, 1]² at any size, included), a
    /// texel on a rendered one keeps its standard error and samples, one
    /// between four has the error of their weighted sum, and the same size
    /// is the identity.
    #[test]
    fn the_shadowed_fog_resamples_bilinearly_in_the_luts_coordinates() {
        use crate::lut::fog::texel_position;
        let field = |u: f64, v: f64| [1.0 + 2.0 * u + 3.0 * v + 4.0 * u * v, 5.0 - u, 0.5 + v * u];
        let (w, h) = (5, 3);
        let mut coarse = RenderedSlice {
            width: w,
            height: h,
            sun_zenith_deg: 60.0,
            xyz: vec![],
            xyz_stderr: vec![],
            samples: vec![],
            core_seconds: 7.0,
        };
        for j in 0..h {
            for i in 0..w {
                coarse.xyz.push(field(texel_position(i, w), texel_position(j, h)));
                coarse.xyz_stderr.push([0.1; 3]);
                coarse.samples.push((100 + j * w + i) as u32);
            }
        }
        let fine = resample_shadowed(&coarse, 9, 5);
        assert_eq!((fine.width, fine.height, fine.xyz.len(), fine.core_seconds), (9, 5, 45, 7.0));
        for j in 0..5 {
            for i in 0..9 {
                let want = field(texel_position(i, 9), texel_position(j, 5));
                let got = fine.xyz[j * 9 + i];
                assert!((0..3).all(|c| (got[c] - want[c]).abs() < 1e-12), "({i}, {j}): {got:?} against {want:?}");
            }
        }
        // Texel (2, 2) of 9 x 5 is rendered texel (1, 1) of 5 x 3; texel
        // (1, 1) lies midway between rendered (0..1, 0..1).
        assert_eq!((fine.xyz_stderr[2 * 9 + 2], fine.samples[2 * 9 + 2]), ([0.1; 3], coarse.samples[w + 1]));
        assert!(
            (fine.xyz_stderr[9 + 1][0] - 0.1 * (4.0 * 0.25f64.powi(2)).sqrt()).abs() < 1e-12,
            "{:?}",
            fine.xyz_stderr[9 + 1]
        );
        assert_eq!(resample_shadowed(&coarse, w, h), coarse);
    }
}
