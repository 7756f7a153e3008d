//! The U.S. Standard Atmosphere 1976 (NOAA/NASA/USAF, NOAA-S/T 76-1562),
//! lower part: 0 to 86 km geometric altitude, computed from its definition
//! (geopotential layers with linear molecular-scale temperature, hydrostatic
//! pressure, and the molecular-weight ratio M/M0 between 80 and 86 km).
//! Above 86 km the number density is extended exponentially with the
//! isothermal scale height at 86 km (the 1976 model's upper part has a
//! different formulation; above 86 km air holds < 1e-5 of the column).

/// Gravity at sea level, m s⁻² (1976 standard, section 1.2).
const G0: f64 = 9.80665;
/// Universal gas constant, J kmol⁻¹ K⁻¹ (the 1976 standard's value).
const R_STAR: f64 = 8.31432e3;
/// Sea-level mean molecular weight, kg kmol⁻¹.
const M0: f64 = 28.9644;
/// Avogadro's number per kmol (the 1976 standard's value).
const N_A: f64 = 6.022169e26;
/// Effective Earth radius for geopotential altitude, km.
const R0_KM: f64 = 6356.766;
/// Sea-level pressure, Pa.
pub const P0_PA: f64 = 101_325.0;

/// Layer bases: geopotential altitude (km'), molecular-scale temperature
/// lapse rate (K / km') — Table 4 of the standard.
const LAYERS: [(f64, f64); 8] =
    [(0.0, -6.5), (11.0, 0.0), (20.0, 1.0), (32.0, 2.8), (47.0, 0.0), (51.0, -2.8), (71.0, -2.0), (84.852, 0.0)];

/// M/M0 from 80 to 86 km geometric altitude every 0.5 km (Table 8).
const M_RATIO: [f64; 13] = [
    1.000000, 0.999996, 0.999989, 0.999971, 0.999941, 0.999909, 0.999870, 0.999829, 0.999786, 0.999741, 0.999694,
    0.999641, 0.999579,
];

/// The state of the air at one altitude.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AirState {
    /// Kinetic temperature, K.
    pub temperature_k: f64,
    pub pressure_pa: f64,
    pub density_kg_m3: f64,
    pub number_density_m3: f64,
}

struct LayerBase {
    h_km: f64,
    t_m: f64,
    lapse: f64,
    p: f64,
}

fn layer_bases() -> [LayerBase; 8] {
    let mut out: [LayerBase; 8] =
        std::array::from_fn(|i| LayerBase { h_km: LAYERS[i].0, t_m: 0.0, lapse: LAYERS[i].1, p: 0.0 });
    out[0].t_m = 288.15;
    out[0].p = P0_PA;
    for i in 1..8 {
        let (t, p) = molecular_temp_pressure(&out[i - 1], out[i].h_km);
        out[i].t_m = t;
        out[i].p = p;
    }
    out
}

/// Hydrostatic integration within one layer (equations 23a/23b of the standard).
fn molecular_temp_pressure(base: &LayerBase, h_km: f64) -> (f64, f64) {
    let dh_m = (h_km - base.h_km) * 1000.0;
    let lapse_per_m = base.lapse / 1000.0;
    let t = base.t_m + lapse_per_m * dh_m;
    let p = if base.lapse == 0.0 {
        base.p * (-G0 * M0 * dh_m / (R_STAR * base.t_m)).exp()
    } else {
        base.p * (base.t_m / t).powf(G0 * M0 / (R_STAR * lapse_per_m))
    };
    (t, p)
}

fn bases() -> &'static [LayerBase; 8] {
    static B: std::sync::OnceLock<[LayerBase; 8]> = std::sync::OnceLock::new();
    B.get_or_init(layer_bases)
}

/// Geopotential altitude (km') of a geometric altitude (km), equation 18.
pub fn geopotential_km(z_km: f64) -> f64 {
    R0_KM * z_km / (R0_KM + z_km)
}

/// The 1976 standard at a geometric altitude in km (0 to 86 km; beyond 86
/// km see [`number_density_m3`]; negative altitudes extrapolate the first layer).
pub fn state(z_km: f64) -> AirState {
    let z = z_km.min(86.0);
    let h = geopotential_km(z);
    let b = bases();
    let i = (0..8).rev().find(|&i| h >= b[i].h_km).unwrap_or(0);
    let (t_m, p) = molecular_temp_pressure(&b[i], h);
    let ratio = if z > 80.0 {
        let u = (z - 80.0) / 0.5;
        let j = (u.floor() as usize).min(11);
        let f = u - j as f64;
        M_RATIO[j] + f * (M_RATIO[j + 1] - M_RATIO[j])
    } else {
        1.0
    };
    let temperature_k = t_m * ratio;
    let density_kg_m3 = p * M0 / (R_STAR * t_m);
    let number_density_m3 = N_A * p / (R_STAR * temperature_k);
    AirState { temperature_k, pressure_pa: p, density_kg_m3, number_density_m3 }
}

/// Number density of air (m⁻³) at geometric altitude `z_km`, the 1976
/// standard to 86 km, then exponential with the 86 km scale height
/// H = R* T / (M g(z)), g(z) = g0 (r0 / (r0 + z))².
pub fn number_density_m3(z_km: f64) -> f64 {
    if z_km <= 86.0 {
        return state(z_km).number_density_m3;
    }
    let top = state(86.0);
    let g = G0 * (R0_KM / (R0_KM + 86.0)).powi(2);
    let m = M0 * M_RATIO[12];
    let scale_height_km = R_STAR * top.temperature_k / (m * g) / 1000.0;
    top.number_density_m3 * (-(z_km - 86.0) / scale_height_km).exp()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sea_level_values() {
        let s = state(0.0);
        assert!((s.temperature_k - 288.15).abs() < 1e-9);
        assert!((s.pressure_pa - 101325.0).abs() < 1e-6);
        // Table I of the standard: 1.2250 kg/m³, 2.5470e25 m⁻³.
        assert!((s.density_kg_m3 - 1.2250).abs() < 1e-4);
        assert!((s.number_density_m3 / 2.5470e25 - 1.0).abs() < 1e-4);
    }

    #[test]
    fn layer_base_pressures_match_table_4() {
        // Pb from the standard's Table 4.
        let expected = [101325.0, 22632.06, 5474.889, 868.0187, 110.9063, 66.93887, 3.956420, 0.3733836];
        for (b, e) in bases().iter().zip(expected) {
            assert!((b.p / e - 1.0).abs() < 2e-5, "{} vs {}", b.p, e);
        }
    }

    #[test]
    fn continuous_above_86_km() {
        let a = number_density_m3(86.0);
        let b = number_density_m3(86.0 + 1e-9);
        assert!((a / b - 1.0).abs() < 1e-9);
        assert!(number_density_m3(100.0) < 0.1 * a);
    }
}
