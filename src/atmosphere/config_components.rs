//! The components of an atmosphere file, phases of `config::parse` that run
//! after the profiles: `[air]`, the `[[absorber]]`s and the `[[aerosol]]`s
//! with their Mie or analytic optics.

use super::profiles::lookup;
use super::*;
use crate::mie::parse_refractive_index;
use std::collections::HashMap;

/// `[air]`: the molecular (Rayleigh) scatterer, or None when the file has no
/// `[air]` table or after an error. Checks its profile, cross-section and
/// depolarization, then the scale that takes the profile to m⁻³.
pub(super) fn parse_air(
    ctx: &mut Ctx,
    raw: Option<&S<RawAir>>,
    profiles: &[Profile],
    by_name: &HashMap<String, usize>,
) -> Option<Air> {
    let a = raw?.get_ref();
    let prof = lookup(ctx, by_name, &a.profile, "air");
    let cross_section = air_cross_section(ctx, a);
    let depolarization = air_depolarization(ctx, a);
    let (Some(prof), Some(cross_section), Some(depolarization)) = (prof, cross_section, depolarization) else {
        return None;
    };
    let p = &profiles[prof];
    let scale = match &a.number_density_m3 {
        Some(n) => {
            let v = positive(ctx, &Some(n.clone()), "air.number_density_m3", 1.0);
            let d0 = p.density(0.0);
            if d0 > 0.0 {
                Some(v / d0)
            } else {
                ctx.err(
                    n,
                    format!("air: profile \"{}\" is zero at 0 km, so number_density_m3 cannot scale it", p.name),
                );
                None
            }
        }
        None if p.units == DensityUnits::Relative => {
            ctx.err(&a.profile, format!("air: profile \"{}\" is relative; give air.number_density_m3", p.name));
            None
        }
        None => Some(1.0),
    };
    scale.map(|scale| Air { profile: prof, scale, cross_section, depolarization })
}

/// `air.cross_section`: Bodhaine et al. (1999) when absent, Bucholtz (1995),
/// or a table of cross_section_cm2 against wavelength. None after an error.
fn air_cross_section(ctx: &mut Ctx, a: &RawAir) -> Option<CrossSection> {
    match &a.cross_section {
        None => Some(CrossSection::Bodhaine1999),
        Some(v) => match v.get_ref() {
            toml::Value::String(s) if s == "bodhaine-1999" => Some(CrossSection::Bodhaine1999),
            toml::Value::String(s) if s == "bucholtz-1995" => Some(CrossSection::Bucholtz1995),
            toml::Value::Table(t) if t.len() == 1 && t.get("file").and_then(|f| f.as_str()).is_some() => {
                let f = t["file"].as_str().unwrap().to_string();
                ctx.spectral(v, &f, "air.cross_section", "cross_section_cm2").map(CrossSection::Table)
            }
            _ => {
                ctx.err(v, "air.cross_section must be \"bodhaine-1999\", \"bucholtz-1995\" or { file = \"...\" }");
                None
            }
        },
    }
}

/// `air.depolarization`: "physical" (the default: from the Bodhaine et al.
/// 1999 King factor at each wavelength) or a fixed ratio in [0, 0.5). None
/// after an error.
fn air_depolarization(ctx: &mut Ctx, a: &RawAir) -> Option<Depolarization> {
    match &a.depolarization {
        None => Some(Depolarization::Physical),
        Some(v) => match v.get_ref() {
            toml::Value::String(s) if s == "physical" => Some(Depolarization::Physical),
            toml::Value::Float(_) | toml::Value::Integer(_) => {
                let x = v.get_ref().as_float().unwrap_or_else(|| v.get_ref().as_integer().unwrap() as f64);
                if (0.0..0.5).contains(&x) {
                    Some(Depolarization::Fixed(x))
                } else {
                    ctx.err(v, format!("air.depolarization must be in [0, 0.5), found {x}"));
                    None
                }
            }
            _ => {
                ctx.err(v, "air.depolarization must be \"physical\" or a number");
                None
            }
        },
    }
}

/// The `[[absorber]]` tables in file order; one with an error is left out.
/// An absorber's scale takes its profile to m⁻³: with `column_du`, the
/// column of the profile up to `top_km` is made that many Dobson units.
pub(super) fn parse_absorbers(
    ctx: &mut Ctx,
    raw: &[S<RawAbsorber>],
    profiles: &[Profile],
    by_name: &HashMap<String, usize>,
    top_km: f64,
) -> Vec<Absorber> {
    let mut absorbers = Vec::new();
    for rab in raw {
        let a = rab.get_ref();
        let label = format!("absorber \"{}\"", a.name.get_ref());
        let prof = lookup(ctx, by_name, &a.profile, &label);
        let xs = ctx.spectral(&a.cross_section, a.cross_section.get_ref(), &label, "cross_section_cm2");
        let (Some(prof), Some(xs)) = (prof, xs) else { continue };
        let p = &profiles[prof];
        let column = p.column_km(top_km) * 1000.0; // (units) m
        let scale = match &a.column_du {
            Some(c) => {
                let du = positive(ctx, &Some(c.clone()), "column_du", 1.0);
                if column > 0.0 {
                    du * DOBSON_UNIT_M2 / column
                } else {
                    ctx.err(c, format!("{label}: profile \"{}\" has no column below top_km", p.name));
                    continue;
                }
            }
            None if p.units == DensityUnits::Relative => {
                ctx.err(&a.profile, format!("{label}: profile \"{}\" is relative; give column_du", p.name));
                continue;
            }
            None => 1.0,
        };
        absorbers.push(Absorber { name: a.name.get_ref().clone(), profile: prof, scale, cross_section_cm2: xs });
    }
    absorbers
}

/// The `[[aerosol]]` tables in file order; one with an error is left out,
/// and a name given twice is an error.
pub(super) fn parse_aerosols(
    ctx: &mut Ctx,
    raw: &[S<RawAerosol>],
    profiles: &[Profile],
    by_name: &HashMap<String, usize>,
    top_km: f64,
) -> Vec<Aerosol> {
    let mut aerosols = Vec::new();
    let mut aerosol_names: HashMap<String, ()> = HashMap::new();
    for rae in raw {
        let a = rae.get_ref();
        let label = format!("aerosol \"{}\"", a.name.get_ref());
        if aerosol_names.insert(a.name.get_ref().clone(), ()).is_some() {
            ctx.err(&a.name, format!("{label} is defined twice"));
        }
        if let Some(aerosol) = parse_aerosol(ctx, rae, profiles, by_name, top_km, &label) {
            aerosols.push(aerosol);
        }
    }
    aerosols
}

/// One aerosol, or None after an error: its profile, its optics, its amount,
/// then whether the amount fits the profile's units (a relative profile needs
/// an amount; an absolute one takes none but an optical depth, which needs a
/// column below `top_km`).
fn parse_aerosol(
    ctx: &mut Ctx,
    rae: &S<RawAerosol>,
    profiles: &[Profile],
    by_name: &HashMap<String, usize>,
    top_km: f64,
    label: &str,
) -> Option<Aerosol> {
    let a = rae.get_ref();
    let prof = lookup(ctx, by_name, &a.profile, label);
    let optics = aerosol_optics(ctx, a, rae, label);
    let amount = aerosol_amount(ctx, a, optics.as_ref(), label);
    if let (Some(r), None) = (&a.reference_wavelength_nm, &a.optical_depth) {
        ctx.err(r, format!("{label}: reference_wavelength_nm only goes with optical_depth"));
    }
    let (Some(prof), Some(optics), Some(amount)) = (prof, optics, amount) else { return None };
    let p = &profiles[prof];
    match amount {
        Amount::Profile if p.units == DensityUnits::Relative || matches!(optics, AerosolOptics::Analytic { .. }) => {
            ctx.err(
                rae,
                format!("{label}: profile \"{}\" is relative; give number_density_cm3 or optical_depth", p.name),
            );
            return None;
        }
        Amount::NumberDensityM3(_) if p.units != DensityUnits::Relative => {
            ctx.err(
                a.number_density_cm3.as_ref().unwrap(),
                format!(
                    "{label}: profile \"{}\" is already absolute; number_density_cm3 needs a relative profile",
                    p.name
                ),
            );
            return None;
        }
        Amount::OpticalDepth { .. } if p.column_km(top_km) <= 0.0 => {
            ctx.err(&a.profile, format!("{label}: profile \"{}\" is zero everywhere below top_km", p.name));
            return None;
        }
        _ => {}
    }
    Some(Aerosol { name: a.name.get_ref().clone(), profile: prof, optics, amount })
}

/// An aerosol's optics: Mie (refractive_index, modes, ...) or analytic
/// (phase, g, ...), never both and never neither. None after an error.
fn aerosol_optics(ctx: &mut Ctx, a: &RawAerosol, rae: &S<RawAerosol>, label: &str) -> Option<AerosolOptics> {
    let mie_keys = a.refractive_index.is_some()
        || a.modes.is_some()
        || a.size_distribution.is_some()
        || a.radius_range_um.is_some();
    let analytic_keys =
        a.phase.is_some() || a.g.is_some() || a.single_scattering_albedo.is_some() || a.angstrom_exponent.is_some();
    if mie_keys && analytic_keys {
        ctx.err(rae, format!("{label}: give either Mie optics (refractive_index, modes) or analytic optics (phase, g, single_scattering_albedo, angstrom_exponent), not both"));
        None
    } else if analytic_keys {
        analytic_optics(ctx, a, rae, label)
    } else if mie_keys {
        mie_optics(ctx, a, rae, label)
    } else {
        ctx.err(rae, format!("{label}: no optics: give refractive_index and modes (Mie) or phase, g, single_scattering_albedo, angstrom_exponent (analytic)"));
        None
    }
}

/// How much of an aerosol there is: the number density where its relative
/// profile is 1 (given in cm⁻³, kept in m⁻³: 1 cm⁻³ = 10⁶ m⁻³), a zenith
/// optical depth at a reference wavelength (550 nm by default), or, with
/// neither, the profile's own numbers. None after an error.
fn aerosol_amount(ctx: &mut Ctx, a: &RawAerosol, optics: Option<&AerosolOptics>, label: &str) -> Option<Amount> {
    match (&a.number_density_cm3, &a.optical_depth) {
        (Some(n), None) => {
            if matches!(optics, Some(AerosolOptics::Analytic { .. })) {
                ctx.err(n, format!("{label}: analytic optics have no particle cross-section; give optical_depth"));
                None
            } else {
                Some(Amount::NumberDensityM3(positive(ctx, &Some(n.clone()), "number_density_cm3", 1.0) * 1e6))
            }
        }
        (None, Some(t)) => {
            let optical_depth = positive(ctx, &Some(t.clone()), "optical_depth", 0.1);
            let wavelength_nm = positive(ctx, &a.reference_wavelength_nm, "reference_wavelength_nm", 550.0);
            Some(Amount::OpticalDepth { optical_depth, wavelength_nm })
        }
        (Some(n), Some(_)) => {
            ctx.err(n, format!("{label}: give number_density_cm3 or optical_depth, not both"));
            None
        }
        (None, None) => Some(Amount::Profile),
    }
}

/// Analytic optics, or None after an error: the phase function
/// (Henyey–Greenstein or Cornette–Shanks), g in [-0.999, 0.999], the
/// single-scattering albedo in [0, 1] and the Ångström exponent in [-4, 6];
/// they need an optical_depth, having no particle cross-section.
fn analytic_optics(ctx: &mut Ctx, a: &RawAerosol, at: &S<RawAerosol>, label: &str) -> Option<AerosolOptics> {
    let phase = match a.phase.as_ref().map(|p| (p, p.get_ref().as_str())) {
        Some((_, "henyey-greenstein")) => AnalyticPhase::HenyeyGreenstein,
        Some((_, "cornette-shanks")) => AnalyticPhase::CornetteShanks,
        Some((p, other)) => {
            ctx.err(
                p,
                format!("{label}: phase must be \"henyey-greenstein\" or \"cornette-shanks\", found \"{other}\""),
            );
            return None;
        }
        None => {
            ctx.err(at, format!("{label}: analytic optics need phase"));
            return None;
        }
    };
    let need = |ctx: &mut Ctx, v: &Option<S<f64>>, key: &str, lo: f64, hi: f64| -> Option<f64> {
        match v {
            None => {
                ctx.err(at, format!("{label}: analytic optics need {key}"));
                None
            }
            Some(s) => {
                let x = *s.get_ref();
                if x.is_finite() && x >= lo && x <= hi {
                    Some(x)
                } else {
                    ctx.err(s, format!("{label}: {key} must be in [{lo}, {hi}], found {x}"));
                    None
                }
            }
        }
    };
    let g = need(ctx, &a.g, "g", -0.999, 0.999);
    let ssa = need(ctx, &a.single_scattering_albedo, "single_scattering_albedo", 0.0, 1.0);
    let ang = need(ctx, &a.angstrom_exponent, "angstrom_exponent", -4.0, 6.0);
    if a.optical_depth.is_none() {
        ctx.err(at, format!("{label}: analytic optics need optical_depth (and reference_wavelength_nm, default 550)"));
        return None;
    }
    Some(AerosolOptics::Analytic { phase, g: g?, single_scattering_albedo: ssa?, angstrom_exponent: ang? })
}

/// Mie optics, or None after an error: the refractive index, whether the
/// modes are number or volume distributions, the radius range they are
/// truncated to, and the log-normal modes, whose weights become number
/// fractions that sum to 1.
fn mie_optics(ctx: &mut Ctx, a: &RawAerosol, at: &S<RawAerosol>, label: &str) -> Option<AerosolOptics> {
    let refractive_index = refractive_index(ctx, a, at, label);
    let volume = match &a.size_distribution {
        None => false,
        Some(s) => match s.get_ref().as_str() {
            "number" => false,
            "volume" => true,
            other => {
                ctx.err(s, format!("{label}: size_distribution must be \"number\" or \"volume\", found \"{other}\""));
                return None;
            }
        },
    };
    let Some(modes_s) = &a.modes else {
        ctx.err(at, format!("{label}: Mie optics need modes = [{{ median_radius_um, sigma, weight }}, ...]"));
        return None;
    };
    if modes_s.get_ref().is_empty() {
        ctx.err(modes_s, format!("{label}: modes is empty"));
        return None;
    }
    let (r_min, r_max) = match &a.radius_range_um {
        None => (0.0, f64::INFINITY),
        Some(rr) => match rr.get_ref().as_slice() {
            [lo, hi] if lo.is_finite() && hi.is_finite() && *lo >= 0.0 && hi > lo => (*lo, *hi),
            _ => {
                ctx.err(rr, format!("{label}: radius_range_um must be [min, max] with 0 <= min < max"));
                return None;
            }
        },
    };
    let mut modes = Vec::new();
    for m in modes_s.get_ref() {
        let r = m.get_ref();
        let radius = *r.median_radius_um.get_ref();
        let sigma = *r.sigma.get_ref();
        let weight = r.weight.as_ref().map(|w| *w.get_ref()).unwrap_or(1.0);
        if !(radius.is_finite() && radius > 0.0 && radius <= 1000.0) {
            ctx.err(&r.median_radius_um, format!("{label}: median_radius_um must be in (0, 1000], found {radius}"));
            continue;
        }
        if !(sigma.is_finite() && sigma > 0.0 && sigma <= 1.5) {
            ctx.err(&r.sigma, format!("{label}: sigma is ln(GSD) and must be in (0, 1.5], found {sigma}"));
            continue;
        }
        if !(weight.is_finite() && weight > 0.0) {
            ctx.err(r.weight.as_ref().unwrap(), format!("{label}: weight must be positive, found {weight}"));
            continue;
        }
        if volume {
            // Volume fraction → number fraction: N_i ∝ V_i / mean particle volume.
            let mode = LogNormal::from_volume_median(radius, sigma);
            modes.push((weight / mode.mean_volume_um3(), mode.truncated(r_min, r_max)));
        } else {
            modes.push((weight, LogNormal::new(radius, sigma).truncated(r_min, r_max)));
        }
    }
    if modes.len() != modes_s.get_ref().len() {
        return None;
    }
    let total: f64 = modes.iter().map(|m| m.0).sum();
    for m in &mut modes {
        m.0 /= total;
    }
    Some(AerosolOptics::Mie { refractive_index: refractive_index?, modes })
}

/// An aerosol's `refractive_index`: a constant such as "1.53-0.006i", or
/// `{ file = "..." }`, a table of n and k against wavelength in nm. None
/// after an error.
fn refractive_index(ctx: &mut Ctx, a: &RawAerosol, at: &S<RawAerosol>, label: &str) -> Option<RefractiveIndex> {
    match &a.refractive_index {
        None => {
            ctx.err(at, format!("{label}: Mie optics need refractive_index"));
            None
        }
        Some(v) => {
            match v.get_ref() {
                toml::Value::String(s) => match parse_refractive_index(s) {
                    Ok(m) => Some(RefractiveIndex::Constant(m)),
                    Err(e) => {
                        ctx.err(v, format!("{label}: refractive_index: {e}"));
                        None
                    }
                },
                toml::Value::Table(t) if t.len() == 1 && t.get("file").and_then(|f| f.as_str()).is_some() => {
                    let f = t["file"].as_str().unwrap().to_string();
                    let n = ctx.spectral(v, &f, &format!("{label}: refractive_index"), "n");
                    let k = if n.is_some() {
                        ctx.spectral(v, &f, &format!("{label}: refractive_index"), "k")
                    } else {
                        None
                    };
                    match (n, k) {
                        (Some(n), Some(k)) => {
                            if n.y.iter().any(|&x| x <= 0.0) {
                                ctx.err(v, format!("{label}: refractive_index: {f}: n must be positive"));
                            }
                            Some(RefractiveIndex::Table { n, k })
                        }
                        _ => None,
                    }
                }
                _ => {
                    ctx.err(v, format!("{label}: refractive_index must be a string such as \"1.53-0.006i\" or {{ file = \"...\" }}"));
                    None
                }
            }
        }
    }
}
