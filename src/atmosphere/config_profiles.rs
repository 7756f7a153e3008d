//! The `[[profile]]` tables of an atmosphere file, a phase of
//! `config::parse`: each becomes a [`Profile`] that the air, absorbers and
//! aerosols then name.

use super::*;
use std::collections::HashMap;

/// Parses the `[[profile]]` tables in file order. A table with an error is
/// left out, so its name stays free and later references to it fail. Returns
/// the profiles and, by name, their index in that list.
pub(super) fn parse_profiles(ctx: &mut Ctx, raw: &[S<RawProfile>]) -> (Vec<Profile>, HashMap<String, usize>) {
    let mut profiles = Vec::new();
    let mut by_name: HashMap<String, usize> = HashMap::new();
    for rp in raw {
        let p = rp.get_ref();
        let name = p.name.get_ref().clone();
        let label = format!("profile \"{name}\"");
        if by_name.contains_key(&name) {
            ctx.err(&p.name, format!("{label} is defined twice"));
            continue;
        }
        let Some((shape, units)) = parse_profile(ctx, p, &label) else { continue };
        by_name.insert(name.clone(), profiles.len());
        profiles.push(Profile { name, shape, units });
    }
    (profiles, by_name)
}

/// The index of the profile that `who` names in `s`, or None after an error
/// that lists the profiles defined.
pub(super) fn lookup(ctx: &mut Ctx, by_name: &HashMap<String, usize>, s: &S<String>, who: &str) -> Option<usize> {
    match by_name.get(s.get_ref()) {
        Some(&i) => Some(i),
        None => {
            let mut known: Vec<&String> = by_name.keys().collect();
            known.sort();
            ctx.err(
                s,
                format!(
                    "{who}: no profile named \"{}\" (defined: {})",
                    s.get_ref(),
                    known.iter().map(|k| k.as_str()).collect::<Vec<_>>().join(", ")
                ),
            );
            None
        }
    }
}

/// One profile's shape and density units, or None after an error: its kind,
/// the keys that kind allows, its units, then the shape the kind describes.
fn parse_profile(ctx: &mut Ctx, p: &RawProfile, label: &str) -> Option<(ProfileShape, DensityUnits)> {
    let kind = p.kind.get_ref().as_str();
    let allowed: &[&str] = match kind {
        "us-standard-1976" => &[],
        "exponential" => &["scale_height_km", "base_km", "min_km", "max_km", "units"],
        "table" => &["file", "altitude_km", "density", "units", "interpolation"],
        other => {
            ctx.err(
                &p.kind,
                format!("{label}: kind must be \"us-standard-1976\", \"exponential\" or \"table\", found \"{other}\""),
            );
            return None;
        }
    };
    if !keys_fit_kind(ctx, p, kind, allowed, label) {
        return None;
    }
    let (mut units, unit_factor) = profile_units(ctx, p, label)?;
    let shape = match kind {
        "us-standard-1976" => {
            units = DensityUnits::PerM3;
            ProfileShape::UsStandard1976
        }
        "exponential" => exponential_shape(ctx, p, label, unit_factor)?,
        _ => table_shape(ctx, p, label, unit_factor)?,
    };
    Some((shape, units))
}

/// Whether every shape key the profile gives is `allowed` for its kind; an
/// error for each one that is not.
fn keys_fit_kind(ctx: &mut Ctx, p: &RawProfile, kind: &str, allowed: &[&str], label: &str) -> bool {
    let present: [(&str, Option<usize>); 9] = [
        ("file", p.file.as_ref().map(|s| s.span().start)),
        ("altitude_km", p.altitude_km.as_ref().map(|s| s.span().start)),
        ("density", p.density.as_ref().map(|s| s.span().start)),
        ("units", p.units.as_ref().map(|s| s.span().start)),
        ("interpolation", p.interpolation.as_ref().map(|s| s.span().start)),
        ("scale_height_km", p.scale_height_km.as_ref().map(|s| s.span().start)),
        ("base_km", p.base_km.as_ref().map(|s| s.span().start)),
        ("min_km", p.min_km.as_ref().map(|s| s.span().start)),
        ("max_km", p.max_km.as_ref().map(|s| s.span().start)),
    ];
    let mut ok = true;
    for (key, at) in present {
        if let Some(at) = at {
            if !allowed.contains(&key) {
                ctx.err_at(at, format!("{label}: key `{key}` does not apply to kind \"{kind}\""));
                ok = false;
            }
        }
    }
    ok
}

/// The profile's `units` (relative when absent) and the factor that takes
/// its densities to those units: 1 cm⁻³ = 10⁶ m⁻³. None after an error.
fn profile_units(ctx: &mut Ctx, p: &RawProfile, label: &str) -> Option<(DensityUnits, f64)> {
    let mut units = DensityUnits::Relative;
    let mut unit_factor = 1.0;
    if let Some(u) = &p.units {
        match u.get_ref().as_str() {
            "relative" => {}
            "m^-3" => units = DensityUnits::PerM3,
            "cm^-3" => {
                units = DensityUnits::PerM3;
                unit_factor = 1e6;
            }
            other => {
                ctx.err(u, format!("{label}: units must be \"relative\", \"cm^-3\" or \"m^-3\", found \"{other}\""));
                return None;
            }
        }
    }
    Some((units, unit_factor))
}

/// The shape of an `exponential` profile, exp(-(z - base_km) / scale_height_km)
/// between min_km and max_km, or None after an error.
fn exponential_shape(ctx: &mut Ctx, p: &RawProfile, label: &str, unit_factor: f64) -> Option<ProfileShape> {
    let Some(h) = &p.scale_height_km else {
        ctx.err(&p.kind, format!("{label}: exponential profile needs scale_height_km"));
        return None;
    };
    let scale_height_km = positive(ctx, &Some(h.clone()), "scale_height_km", 1.0);
    let base_km = p.base_km.as_ref().map(|v| *v.get_ref()).unwrap_or(0.0);
    let min_km = p.min_km.as_ref().map(|v| *v.get_ref()).unwrap_or(f64::NEG_INFINITY);
    let max_km = p.max_km.as_ref().map(|v| *v.get_ref()).unwrap_or(f64::INFINITY);
    if min_km >= max_km {
        let at = p.min_km.as_ref().map(|s| s.span().start).unwrap_or(p.kind.span().start);
        ctx.err_at(at, format!("{label}: min_km must be below max_km"));
        return None;
    }
    if unit_factor != 1.0 {
        // An exponential in cm⁻³ has density 1 cm⁻³ at its base; keep it simple.
        ctx.err(p.units.as_ref().unwrap(), format!("{label}: an exponential profile is relative or m^-3"));
        return None;
    }
    Some(ProfileShape::Exponential { scale_height_km, base_km, min_km, max_km })
}

/// The shape of a `table` profile, or None after an error: its
/// interpolation and units, its rows (from `file` or inline), then the rows'
/// checks. Densities are scaled by `unit_factor` into the profile's units.
fn table_shape(ctx: &mut Ctx, p: &RawProfile, label: &str, unit_factor: f64) -> Option<ProfileShape> {
    let interpolation = match &p.interpolation {
        None => Interpolation::Linear,
        Some(s) => match s.get_ref().as_str() {
            "linear" => Interpolation::Linear,
            "log" => Interpolation::Log,
            other => {
                ctx.err(s, format!("{label}: interpolation must be \"linear\" or \"log\", found \"{other}\""));
                return None;
            }
        },
    };
    if p.units.is_none() {
        ctx.err(&p.kind, format!("{label}: a table must state its units (\"relative\", \"cm^-3\" or \"m^-3\")"));
        return None;
    }
    let (alt, den, at_alt, at_den) = table_rows(ctx, p, label)?;
    if alt.is_empty() || alt.len() != den.len() {
        ctx.err_at(at_den, format!("{label}: altitude_km has {} rows but density has {}", alt.len(), den.len()));
        return None;
    }
    if let Some(i) = (1..alt.len()).find(|&i| !(alt[i] > alt[i - 1])) {
        ctx.err_at(
            at_alt,
            format!("{label}: altitude_km must increase (row {}: {} after {})", i + 1, alt[i], alt[i - 1]),
        );
        return None;
    }
    if let Some(v) = alt.iter().chain(&den).find(|v| !v.is_finite()) {
        ctx.err_at(at_den, format!("{label}: values must be finite, found {v}"));
        return None;
    }
    if let Some(i) = den.iter().position(|&d| d < 0.0) {
        ctx.err_at(at_den, format!("{label}: density must not be negative (row {}: {})", i + 1, den[i]));
        return None;
    }
    if interpolation == Interpolation::Log && den.iter().any(|&d| d <= 0.0) {
        ctx.err_at(at_den, format!("{label}: log interpolation needs positive densities; use \"linear\""));
        return None;
    }
    Some(ProfileShape::Table {
        altitude_km: alt,
        density: den.iter().map(|d| d * unit_factor).collect(),
        interpolation,
    })
}

/// A table profile's rows, from its `file` or from `altitude_km` and
/// `density` given inline: (altitudes in km, densities, where to report an
/// error about the altitudes, where to report one about the densities).
/// None after an error.
fn table_rows(ctx: &mut Ctx, p: &RawProfile, label: &str) -> Option<(Vec<f64>, Vec<f64>, usize, usize)> {
    match (&p.file, &p.altitude_km, &p.density) {
        (Some(f), None, None) => {
            let t = ctx.table(f, f.get_ref(), label)?;
            if t.columns.len() != 2 || t.columns[0] != "altitude_km" {
                ctx.err(f, format!("{label}: {} must have two columns, altitude_km and a density", t.path.display()));
                return None;
            }
            Some((t.data[0].clone(), t.data[1].clone(), f.span().start, f.span().start))
        }
        (None, Some(a), Some(d)) => Some((a.get_ref().clone(), d.get_ref().clone(), a.span().start, d.span().start)),
        _ => {
            ctx.err(&p.kind, format!("{label}: a table needs either `file` or both `altitude_km` and `density`"));
            None
        }
    }
}
