//! Vertical density profiles: the U.S. Standard 1976 air, exponentials, and
//! measured tables.

use super::us1976;

/// How a table is interpolated between rows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Interpolation {
    Linear,
    /// Linear in ln(density): exact for exponential pieces.
    Log,
}

/// The shape of a profile as a function of geometric altitude.
#[derive(Debug, Clone, PartialEq)]
pub enum ProfileShape {
    /// Number density of air, m⁻³, from the 1976 standard.
    UsStandard1976,
    /// exp(−(z − base)/H) between `min_km` and `max_km`, zero outside.
    Exponential { scale_height_km: f64, base_km: f64, min_km: f64, max_km: f64 },
    /// Rows of (altitude, density), zero outside the table.
    Table { altitude_km: Vec<f64>, density: Vec<f64>, interpolation: Interpolation },
}

/// Whether the profile's numbers are absolute number densities or a shape.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DensityUnits {
    Relative,
    /// Number per m³ (tables given in cm⁻³ are converted on load).
    PerM3,
}

/// A named vertical profile.
#[derive(Debug, Clone, PartialEq)]
pub struct Profile {
    pub name: String,
    pub shape: ProfileShape,
    pub units: DensityUnits,
}

/// Step of the numerical column integral, km.
const COLUMN_STEP_KM: f64 = 0.005;

impl Profile {
    /// Density at geometric altitude `z_km` (relative, or m⁻³).
    pub fn density(&self, z_km: f64) -> f64 {
        match &self.shape {
            ProfileShape::UsStandard1976 => us1976::number_density_m3(z_km.max(0.0)),
            ProfileShape::Exponential { scale_height_km, base_km, min_km, max_km } => {
                if z_km < *min_km || z_km > *max_km {
                    0.0
                } else {
                    (-(z_km - base_km) / scale_height_km).exp()
                }
            }
            ProfileShape::Table { altitude_km, density, interpolation } => {
                let n = altitude_km.len();
                if z_km < altitude_km[0] || z_km > altitude_km[n - 1] {
                    return 0.0;
                }
                if n == 1 {
                    return density[0];
                }
                let i = (altitude_km.partition_point(|&a| a <= z_km).max(1) - 1).min(n - 2);
                let t = (z_km - altitude_km[i]) / (altitude_km[i + 1] - altitude_km[i]);
                match interpolation {
                    Interpolation::Linear => density[i] + t * (density[i + 1] - density[i]),
                    Interpolation::Log => (density[i].ln() + t * (density[i + 1].ln() - density[i].ln())).exp(),
                }
            }
        }
    }

    /// ∫₀^top density dz in (density units) × km, by the trapezoid rule with
    /// 5 m steps plus the table's own rows as nodes.
    pub fn column_km(&self, top_km: f64) -> f64 {
        let mut nodes: Vec<f64> = Vec::new();
        let steps = (top_km / COLUMN_STEP_KM).ceil() as usize;
        for i in 0..=steps {
            nodes.push((i as f64 * COLUMN_STEP_KM).min(top_km));
        }
        match &self.shape {
            ProfileShape::Table { altitude_km, .. } => {
                nodes.extend(altitude_km.iter().copied().filter(|&a| a > 0.0 && a < top_km));
                // Both sides of a table's ends, where the density jumps to zero.
                for &a in [altitude_km[0], *altitude_km.last().unwrap()].iter() {
                    if a > 0.0 && a < top_km {
                        nodes.push(a - 1e-9);
                        nodes.push(a + 1e-9);
                    }
                }
            }
            ProfileShape::Exponential { min_km, max_km, .. } => {
                for &a in [*min_km, *max_km].iter() {
                    if a > 0.0 && a < top_km {
                        nodes.push(a - 1e-9);
                        nodes.push(a);
                        nodes.push(a + 1e-9);
                    }
                }
            }
            ProfileShape::UsStandard1976 => {}
        }
        nodes.sort_by(f64::total_cmp);
        nodes.dedup();
        let mut s = 0.0;
        let mut prev = (nodes[0], self.density(nodes[0]));
        for &z in &nodes[1..] {
            let d = self.density(z);
            s += 0.5 * (prev.1 + d) * (z - prev.0);
            prev = (z, d);
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exponential_column_is_analytic() {
        let p = Profile {
            name: "e".into(),
            shape: ProfileShape::Exponential {
                scale_height_km: 8.0,
                base_km: 0.0,
                min_km: f64::NEG_INFINITY,
                max_km: f64::INFINITY,
            },
            units: DensityUnits::Relative,
        };
        let c = p.column_km(100.0);
        let exact = 8.0 * (1.0 - (-100.0f64 / 8.0).exp());
        assert!((c / exact - 1.0).abs() < 1e-7, "{c} {exact}");
    }

    #[test]
    fn table_log_interpolation_and_edges() {
        let p = Profile {
            name: "t".into(),
            shape: ProfileShape::Table {
                altitude_km: vec![1.0, 2.0],
                density: vec![1.0, 0.01],
                interpolation: Interpolation::Log,
            },
            units: DensityUnits::Relative,
        };
        assert!((p.density(1.5) - 0.1).abs() < 1e-12);
        assert_eq!(p.density(0.5), 0.0);
        assert_eq!(p.density(2.5), 0.0);
        // ∫ 100^-(z-1) dz from 1 to 2 = (1 − 0.01)/ln 100.
        let exact = 0.99 / 100f64.ln();
        assert!((p.column_km(10.0) / exact - 1.0).abs() < 1e-4);
    }
}
