//! The weather rule: how haziness and cloudiness weight the eight basis
//! skies. The talk ("Interpolation of Basis Skies") gives the idea, not the
//! formula: "Haziness: Weight for 'clear' and 'hazed'", "Cloudiness: Weight
//! for 'cloudy' skies and mode transition". The formula is ours:
//!
//! - haziness h ∈ [0, 1] blends the sunny pair: (1 − h) clear + h hazed;
//! - cloudiness c ∈ [0, 1] in seven equal steps of 1/6: from c = 0 (sunny
//!   mode) to c = 1/6 the sunny pair fades linearly into cloudy0 (the mode
//!   transition); from there c = (k + 1) / 6 lands exactly on cloudy k, and
//!   the sky between two of them is their linear blend. With the shipped
//!   cloud optical depths (0.5 to 60 in equal steps of log τ) each step of c
//!   is one step of log τ.
//!
//! Every decoder (the CPU reference in [`super::decode`], the GPU preview)
//! calls this one function or a transcription of it tested against it.

/// The basis skies in the talk's order.
pub const BASIS: [&str; 8] = ["clear", "hazed", "cloudy0", "cloudy1", "cloudy2", "cloudy3", "cloudy4", "cloudy5"];

/// The width in c of the sunny-to-cloudy mode transition (and of each step
/// along the cloudy sequence).
pub const CLOUDY_STEP: f64 = 1.0 / 6.0;

/// The weight of each basis sky (in [`BASIS`] order) for haziness `h` and
/// cloudiness `c`, both clamped to [0, 1]. The weights are non-negative and
/// sum to 1; at most three are non-zero.
pub fn basis_weights(haziness: f64, cloudiness: f64) -> [f64; 8] {
    let h = if haziness.is_nan() { 0.0 } else { haziness.clamp(0.0, 1.0) };
    let c = if cloudiness.is_nan() { 0.0 } else { cloudiness.clamp(0.0, 1.0) };
    let mut w = [0.0; 8];
    if c < CLOUDY_STEP {
        let cloudy = c / CLOUDY_STEP;
        w[0] = (1.0 - cloudy) * (1.0 - h);
        w[1] = (1.0 - cloudy) * h;
        w[2] = cloudy;
    } else {
        // Position along cloudy0 ... cloudy5: 0 at c = 1/6, 5 at c = 1.
        let p = ((c - CLOUDY_STEP) / CLOUDY_STEP).min(5.0);
        let k = (p.floor() as usize).min(4);
        let f = p - k as f64;
        w[2 + k] = 1.0 - f;
        w[3 + k] += f;
    }
    w
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_are_a_partition_of_unity_and_hit_every_basis_sky() {
        for i in 0..=100 {
            for j in 0..=120 {
                let w = basis_weights(i as f64 / 100.0, j as f64 / 120.0);
                assert!(w.iter().all(|&x| x >= 0.0));
                assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
                assert!(w.iter().filter(|&&x| x > 0.0).count() <= 3);
            }
        }
        assert_eq!(basis_weights(0.0, 0.0), [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        assert_eq!(basis_weights(1.0, 0.0), [0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        for k in 0..6 {
            let w = basis_weights(0.3, (k + 1) as f64 / 6.0);
            assert!((w[2 + k] - 1.0).abs() < 1e-12, "cloudy{k}: {w:?}");
        }
        // Out of range and NaN clamp rather than extrapolate.
        assert_eq!(basis_weights(-1.0, 2.0), basis_weights(0.0, 1.0));
        assert_eq!(basis_weights(f64::NAN, f64::NAN), basis_weights(0.0, 0.0));
    }

    #[test]
    fn weights_are_continuous() {
        // No step anywhere: neighbouring settings differ by at most a
        // bounded multiple of the step (the rule is piecewise linear).
        let n = 6000;
        for hi in [0.0, 0.5, 1.0] {
            for j in 0..n {
                let (a, b) = (basis_weights(hi, j as f64 / n as f64), basis_weights(hi, (j + 1) as f64 / n as f64));
                let d: f64 = a.iter().zip(&b).map(|(x, y)| (x - y).abs()).sum();
                assert!(d <= 2.0 * 6.0 / n as f64 + 1e-12, "c = {}: {a:?} -> {b:?}", j as f64 / n as f64);
            }
        }
    }
}
