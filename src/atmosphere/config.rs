//! Parsing and validation of atmosphere TOML files. Every error names the
//! file and the line of the offending key; unknown keys are errors.

use super::*;
use crate::mie::parse_refractive_index;
use crate::table::Table;
use serde::Deserialize;
use std::collections::{BTreeMap, HashMap};
use toml::Spanned;

/// The sun of an atmosphere file without a `[sun]` table: the ASTM G173-03
/// extraterrestrial spectrum shipped as `atmospheres/data/astm_g173_etr.csv`
/// (its provenance is in the file's header), built into the binary so the
/// default works wherever the file lives.
pub const DEFAULT_SUN_CSV: &str = include_str!("../../atmospheres/data/astm_g173_etr.csv");
/// Its angular diameter, degrees: the mean apparent diameter of the sun
/// (about 0.533°, 31.99 arcminutes at 1 AU).
pub const DEFAULT_SUN_DIAMETER_DEG: f64 = 0.533;

type S<T> = Spanned<T>;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFile {
    name: Option<S<String>>,
    description: Option<S<String>>,
    planet: Option<S<RawPlanet>>,
    #[serde(default)]
    profile: Vec<S<RawProfile>>,
    air: Option<S<RawAir>>,
    #[serde(default)]
    absorber: Vec<S<RawAbsorber>>,
    #[serde(default)]
    aerosol: Vec<S<RawAerosol>>,
    ground: Option<S<RawGround>>,
    sun: Option<S<RawSun>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPlanet {
    radius_km: Option<S<f64>>,
    top_km: Option<S<f64>>,
    geometry: Option<S<String>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawProfile {
    name: S<String>,
    kind: S<String>,
    file: Option<S<String>>,
    altitude_km: Option<S<Vec<f64>>>,
    density: Option<S<Vec<f64>>>,
    units: Option<S<String>>,
    interpolation: Option<S<String>>,
    scale_height_km: Option<S<f64>>,
    base_km: Option<S<f64>>,
    min_km: Option<S<f64>>,
    max_km: Option<S<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAir {
    profile: S<String>,
    cross_section: Option<S<toml::Value>>,
    depolarization: Option<S<toml::Value>>,
    number_density_m3: Option<S<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAbsorber {
    name: S<String>,
    cross_section: S<String>,
    profile: S<String>,
    column_du: Option<S<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMode {
    median_radius_um: S<f64>,
    sigma: S<f64>,
    weight: Option<S<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAerosol {
    name: S<String>,
    profile: S<String>,
    refractive_index: Option<S<toml::Value>>,
    size_distribution: Option<S<String>>,
    modes: Option<S<Vec<S<RawMode>>>>,
    radius_range_um: Option<S<Vec<f64>>>,
    number_density_cm3: Option<S<f64>>,
    optical_depth: Option<S<f64>>,
    reference_wavelength_nm: Option<S<f64>>,
    phase: Option<S<String>>,
    g: Option<S<f64>>,
    single_scattering_albedo: Option<S<f64>>,
    angstrom_exponent: Option<S<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawGround {
    albedo: S<toml::Value>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSun {
    spectrum: S<String>,
    angular_diameter_deg: Option<S<f64>>,
}

/// The highest top of the atmosphere, km: the U.S. Standard 1976 ends at
/// 1000 km.
pub const MAX_TOP_KM: f64 = 1000.0;

/// 1 Dobson unit in molecules per m².
pub const DOBSON_UNIT_M2: f64 = 2.6867e20;

struct Ctx<'a> {
    path: &'a Path,
    text: &'a str,
    dir: PathBuf,
    errors: Vec<Located>,
    hasher: blake3::Hasher,
    /// Where data files come from: the disk (None) or a job's files.
    files: Option<&'a BTreeMap<String, Vec<u8>>>,
    /// Every data file read, by the name the atmosphere gives it.
    read: BTreeMap<String, Vec<u8>>,
}

impl Ctx<'_> {
    fn line(&self, offset: usize) -> usize {
        self.text[..offset.min(self.text.len())].bytes().filter(|&b| b == b'\n').count() + 1
    }

    fn err<T>(&mut self, span: &S<T>, message: impl Into<String>) {
        let line = self.line(span.span().start);
        self.errors.push(Located { path: self.path.to_path_buf(), line: Some(line), message: message.into() });
    }

    fn err_at(&mut self, offset: usize, message: impl Into<String>) {
        let line = self.line(offset);
        self.errors.push(Located { path: self.path.to_path_buf(), line: Some(line), message: message.into() });
    }

    /// Reads a data table named relative to the atmosphere file.
    fn table<T>(&mut self, at: &S<T>, rel: &str, what: &str) -> Option<Table> {
        let full = self.dir.join(rel);
        let bytes = match self.files {
            None => std::fs::read(&full),
            Some(files) => files.get(rel).cloned().ok_or_else(|| std::io::Error::new(std::io::ErrorKind::NotFound, "not among the job's files")),
        };
        match bytes {
            Ok(bytes) => {
                self.read.insert(rel.to_string(), bytes.clone());
                self.hasher.update(rel.as_bytes());
                self.hasher.update(&(bytes.len() as u64).to_le_bytes());
                self.hasher.update(&bytes);
                let text = match String::from_utf8(bytes) {
                    Ok(t) => t,
                    Err(_) => {
                        self.err(at, format!("{what}: {} is not UTF-8 text", full.display()));
                        return None;
                    }
                };
                match Table::parse(&full, &text) {
                    Ok(t) => Some(t),
                    Err(e) => {
                        self.err(at, format!("{what}: {e}"));
                        None
                    }
                }
            }
            Err(e) => {
                self.err(at, format!("{what}: cannot read {}: {e}", full.display()));
                None
            }
        }
    }

    /// A function of wavelength from a table with the given columns.
    fn spectral<T>(&mut self, at: &S<T>, rel: &str, what: &str, column: &str) -> Option<Tabulated> {
        let t = self.table(at, rel, what)?;
        if t.columns[0] != "wavelength_nm" {
            self.err(at, format!("{what}: {}: first column must be wavelength_nm, found {}", t.path.display(), t.columns[0]));
            return None;
        }
        match t.function(column) {
            Ok(f) => Some(f),
            Err(e) => {
                self.err(at, format!("{what}: {e}"));
                None
            }
        }
    }
}

fn positive(ctx: &mut Ctx, v: &Option<S<f64>>, key: &str, default: f64) -> f64 {
    match v {
        None => default,
        Some(s) => {
            let x = *s.get_ref();
            if !(x.is_finite() && x > 0.0) {
                ctx.err(s, format!("{key} must be a positive number, found {x}"));
                default
            } else {
                x
            }
        }
    }
}

/// Parses an atmosphere; data files come from the disk (relative to `path`)
/// or, with `files`, from a job. Returns the data files read, by name.
pub(super) fn parse(path: &Path, text: &str, files: Option<&BTreeMap<String, Vec<u8>>>) -> Result<(Atmosphere, BTreeMap<String, Vec<u8>>), LoadError> {
    let raw: RawFile = match toml::from_str(text) {
        Ok(r) => r,
        Err(e) => {
            let line = e.span().map(|s| text[..s.start.min(text.len())].bytes().filter(|&b| b == b'\n').count() + 1);
            let message = e.message().trim().to_string();
            return Err(LoadError { errors: vec![Located { path: path.to_path_buf(), line, message }] });
        }
    };
    let mut ctx = Ctx { path, text, dir: path.parent().map(Path::to_path_buf).unwrap_or_default(), errors: Vec::new(), hasher: blake3::Hasher::new(), files, read: BTreeMap::new() };
    ctx.hasher.update(text.as_bytes());

    // [planet]
    let planet = match &raw.planet {
        None => {
            ctx.err_at(0, "missing [planet] table (radius_km, top_km, geometry)");
            Planet { radius_km: 6371.0, top_km: 100.0, geometry: Geometry::Spherical }
        }
        Some(p) => {
            let p = p.get_ref();
            let radius_km = positive(&mut ctx, &p.radius_km, "planet.radius_km", 6371.0);
            let mut top_km = positive(&mut ctx, &p.top_km, "planet.top_km", 100.0);
            if let Some(t) = p.top_km.as_ref().filter(|_| top_km > MAX_TOP_KM) {
                // Column integrals take 5 m steps up to the top: 1e300 km
                // would never finish (or allocate its nodes).
                ctx.err(t, format!("planet.top_km must be at most {MAX_TOP_KM} km (where the U.S. Standard 1976 ends), found {top_km}"));
                top_km = 100.0;
            }
            let geometry = match &p.geometry {
                None => Geometry::Spherical,
                Some(g) => match g.get_ref().as_str() {
                    "spherical" => Geometry::Spherical,
                    "plane-parallel" => Geometry::PlaneParallel,
                    other => {
                        ctx.err(g, format!("planet.geometry must be \"spherical\" or \"plane-parallel\", found \"{other}\""));
                        Geometry::Spherical
                    }
                },
            };
            Planet { radius_km, top_km, geometry }
        }
    };

    // [[profile]]
    let mut profiles = Vec::new();
    let mut by_name: HashMap<String, usize> = HashMap::new();
    for rp in &raw.profile {
        let p = rp.get_ref();
        let name = p.name.get_ref().clone();
        let label = format!("profile \"{name}\"");
        if by_name.contains_key(&name) {
            ctx.err(&p.name, format!("{label} is defined twice"));
            continue;
        }
        let kind = p.kind.get_ref().as_str();
        let allowed: &[&str] = match kind {
            "us-standard-1976" => &[],
            "exponential" => &["scale_height_km", "base_km", "min_km", "max_km", "units"],
            "table" => &["file", "altitude_km", "density", "units", "interpolation"],
            other => {
                ctx.err(&p.kind, format!("{label}: kind must be \"us-standard-1976\", \"exponential\" or \"table\", found \"{other}\""));
                continue;
            }
        };
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
        if !ok {
            continue;
        }
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
                    continue;
                }
            }
        }
        let shape = match kind {
            "us-standard-1976" => {
                units = DensityUnits::PerM3;
                ProfileShape::UsStandard1976
            }
            "exponential" => {
                let Some(h) = &p.scale_height_km else {
                    ctx.err(&p.kind, format!("{label}: exponential profile needs scale_height_km"));
                    continue;
                };
                let scale_height_km = positive(&mut ctx, &Some(h.clone()), "scale_height_km", 1.0);
                let base_km = p.base_km.as_ref().map(|v| *v.get_ref()).unwrap_or(0.0);
                let min_km = p.min_km.as_ref().map(|v| *v.get_ref()).unwrap_or(f64::NEG_INFINITY);
                let max_km = p.max_km.as_ref().map(|v| *v.get_ref()).unwrap_or(f64::INFINITY);
                if min_km >= max_km {
                    let at = p.min_km.as_ref().map(|s| s.span().start).unwrap_or(p.kind.span().start);
                    ctx.err_at(at, format!("{label}: min_km must be below max_km"));
                    continue;
                }
                if unit_factor != 1.0 {
                    // An exponential in cm⁻³ has density 1 cm⁻³ at its base; keep it simple.
                    ctx.err(p.units.as_ref().unwrap(), format!("{label}: an exponential profile is relative or m^-3"));
                    continue;
                }
                ProfileShape::Exponential { scale_height_km, base_km, min_km, max_km }
            }
            _ => {
                let interpolation = match &p.interpolation {
                    None => Interpolation::Linear,
                    Some(s) => match s.get_ref().as_str() {
                        "linear" => Interpolation::Linear,
                        "log" => Interpolation::Log,
                        other => {
                            ctx.err(s, format!("{label}: interpolation must be \"linear\" or \"log\", found \"{other}\""));
                            continue;
                        }
                    },
                };
                if p.units.is_none() {
                    ctx.err(&p.kind, format!("{label}: a table must state its units (\"relative\", \"cm^-3\" or \"m^-3\")"));
                    continue;
                }
                let (alt, den, at_alt, at_den): (Vec<f64>, Vec<f64>, usize, usize) = match (&p.file, &p.altitude_km, &p.density) {
                    (Some(f), None, None) => {
                        let Some(t) = ctx.table(f, f.get_ref(), &label) else { continue };
                        if t.columns.len() != 2 || t.columns[0] != "altitude_km" {
                            ctx.err(f, format!("{label}: {} must have two columns, altitude_km and a density", t.path.display()));
                            continue;
                        }
                        (t.data[0].clone(), t.data[1].clone(), f.span().start, f.span().start)
                    }
                    (None, Some(a), Some(d)) => (a.get_ref().clone(), d.get_ref().clone(), a.span().start, d.span().start),
                    _ => {
                        ctx.err(&p.kind, format!("{label}: a table needs either `file` or both `altitude_km` and `density`"));
                        continue;
                    }
                };
                if alt.is_empty() || alt.len() != den.len() {
                    ctx.err_at(at_den, format!("{label}: altitude_km has {} rows but density has {}", alt.len(), den.len()));
                    continue;
                }
                if let Some(i) = (1..alt.len()).find(|&i| !(alt[i] > alt[i - 1])) {
                    ctx.err_at(at_alt, format!("{label}: altitude_km must increase (row {}: {} after {})", i + 1, alt[i], alt[i - 1]));
                    continue;
                }
                if let Some(v) = alt.iter().chain(&den).find(|v| !v.is_finite()) {
                    ctx.err_at(at_den, format!("{label}: values must be finite, found {v}"));
                    continue;
                }
                if let Some(i) = den.iter().position(|&d| d < 0.0) {
                    ctx.err_at(at_den, format!("{label}: density must not be negative (row {}: {})", i + 1, den[i]));
                    continue;
                }
                if interpolation == Interpolation::Log && den.iter().any(|&d| d <= 0.0) {
                    ctx.err_at(at_den, format!("{label}: log interpolation needs positive densities; use \"linear\""));
                    continue;
                }
                ProfileShape::Table { altitude_km: alt, density: den.iter().map(|d| d * unit_factor).collect(), interpolation }
            }
        };
        by_name.insert(name.clone(), profiles.len());
        profiles.push(Profile { name, shape, units });
    }

    let lookup = |ctx: &mut Ctx, s: &S<String>, who: &str| -> Option<usize> {
        match by_name.get(s.get_ref()) {
            Some(&i) => Some(i),
            None => {
                let mut known: Vec<&String> = by_name.keys().collect();
                known.sort();
                ctx.err(s, format!("{who}: no profile named \"{}\" (defined: {})", s.get_ref(), known.iter().map(|k| k.as_str()).collect::<Vec<_>>().join(", ")));
                None
            }
        }
    };

    // [air]
    let mut air = None;
    if let Some(ra) = &raw.air {
        let a = ra.get_ref();
        let prof = lookup(&mut ctx, &a.profile, "air");
        let cross_section = match &a.cross_section {
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
        };
        let depolarization = match &a.depolarization {
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
        };
        if let (Some(prof), Some(cross_section), Some(depolarization)) = (prof, cross_section, depolarization) {
            let p = &profiles[prof];
            let scale = match &a.number_density_m3 {
                Some(n) => {
                    let v = positive(&mut ctx, &Some(n.clone()), "air.number_density_m3", 1.0);
                    let d0 = p.density(0.0);
                    if d0 > 0.0 {
                        Some(v / d0)
                    } else {
                        ctx.err(n, format!("air: profile \"{}\" is zero at 0 km, so number_density_m3 cannot scale it", p.name));
                        None
                    }
                }
                None if p.units == DensityUnits::Relative => {
                    ctx.err(&a.profile, format!("air: profile \"{}\" is relative; give air.number_density_m3", p.name));
                    None
                }
                None => Some(1.0),
            };
            if let Some(scale) = scale {
                air = Some(Air { profile: prof, scale, cross_section, depolarization });
            }
        }
    }

    // [[absorber]]
    let mut absorbers = Vec::new();
    for rab in &raw.absorber {
        let a = rab.get_ref();
        let label = format!("absorber \"{}\"", a.name.get_ref());
        let prof = lookup(&mut ctx, &a.profile, &label);
        let xs = ctx.spectral(&a.cross_section, a.cross_section.get_ref(), &label, "cross_section_cm2");
        let (Some(prof), Some(xs)) = (prof, xs) else { continue };
        let p = &profiles[prof];
        let column = p.column_km(planet.top_km) * 1000.0; // (units) m
        let scale = match &a.column_du {
            Some(c) => {
                let du = positive(&mut ctx, &Some(c.clone()), "column_du", 1.0);
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

    // [[aerosol]]
    let mut aerosols = Vec::new();
    let mut aerosol_names: HashMap<String, ()> = HashMap::new();
    for rae in &raw.aerosol {
        let a = rae.get_ref();
        let label = format!("aerosol \"{}\"", a.name.get_ref());
        if aerosol_names.insert(a.name.get_ref().clone(), ()).is_some() {
            ctx.err(&a.name, format!("{label} is defined twice"));
        }
        let prof = lookup(&mut ctx, &a.profile, &label);
        let mie_keys = a.refractive_index.is_some() || a.modes.is_some() || a.size_distribution.is_some() || a.radius_range_um.is_some();
        let analytic_keys = a.phase.is_some() || a.g.is_some() || a.single_scattering_albedo.is_some() || a.angstrom_exponent.is_some();
        let optics = if mie_keys && analytic_keys {
            ctx.err(rae, format!("{label}: give either Mie optics (refractive_index, modes) or analytic optics (phase, g, single_scattering_albedo, angstrom_exponent), not both"));
            None
        } else if analytic_keys {
            analytic_optics(&mut ctx, a, rae, &label)
        } else if mie_keys {
            mie_optics(&mut ctx, a, rae, &label)
        } else {
            ctx.err(rae, format!("{label}: no optics: give refractive_index and modes (Mie) or phase, g, single_scattering_albedo, angstrom_exponent (analytic)"));
            None
        };
        let amount = match (&a.number_density_cm3, &a.optical_depth) {
            (Some(n), None) => {
                if matches!(optics, Some(AerosolOptics::Analytic { .. })) {
                    ctx.err(n, format!("{label}: analytic optics have no particle cross-section; give optical_depth"));
                    None
                } else {
                    Some(Amount::NumberDensityM3(positive(&mut ctx, &Some(n.clone()), "number_density_cm3", 1.0) * 1e6))
                }
            }
            (None, Some(t)) => {
                let optical_depth = positive(&mut ctx, &Some(t.clone()), "optical_depth", 0.1);
                let wavelength_nm = positive(&mut ctx, &a.reference_wavelength_nm, "reference_wavelength_nm", 550.0);
                Some(Amount::OpticalDepth { optical_depth, wavelength_nm })
            }
            (Some(n), Some(_)) => {
                ctx.err(n, format!("{label}: give number_density_cm3 or optical_depth, not both"));
                None
            }
            (None, None) => Some(Amount::Profile),
        };
        if let (Some(r), None) = (&a.reference_wavelength_nm, &a.optical_depth) {
            ctx.err(r, format!("{label}: reference_wavelength_nm only goes with optical_depth"));
        }
        let (Some(prof), Some(optics), Some(amount)) = (prof, optics, amount) else { continue };
        let p = &profiles[prof];
        match amount {
            Amount::Profile if p.units == DensityUnits::Relative || matches!(optics, AerosolOptics::Analytic { .. }) => {
                ctx.err(rae, format!("{label}: profile \"{}\" is relative; give number_density_cm3 or optical_depth", p.name));
                continue;
            }
            Amount::NumberDensityM3(_) if p.units != DensityUnits::Relative => {
                ctx.err(a.number_density_cm3.as_ref().unwrap(), format!("{label}: profile \"{}\" is already absolute; number_density_cm3 needs a relative profile", p.name));
                continue;
            }
            Amount::OpticalDepth { .. } if p.column_km(planet.top_km) <= 0.0 => {
                ctx.err(&a.profile, format!("{label}: profile \"{}\" is zero everywhere below top_km", p.name));
                continue;
            }
            _ => {}
        }
        aerosols.push(Aerosol { name: a.name.get_ref().clone(), profile: prof, optics, amount });
    }

    // [ground]
    let ground_albedo = match &raw.ground {
        None => Tabulated::constant(0.0),
        Some(g) => {
            let v = &g.get_ref().albedo;
            match v.get_ref() {
                toml::Value::Float(_) | toml::Value::Integer(_) => {
                    let x = v.get_ref().as_float().unwrap_or_else(|| v.get_ref().as_integer().unwrap() as f64);
                    if !(0.0..=1.0).contains(&x) {
                        ctx.err(v, format!("ground.albedo must be in [0, 1], found {x}"));
                    }
                    Tabulated::constant(x.clamp(0.0, 1.0))
                }
                toml::Value::String(f) => {
                    let f = f.clone();
                    match ctx.spectral(v, &f, "ground.albedo", "albedo") {
                        Some(t) => {
                            if let Some(x) = t.y.iter().find(|x| !(0.0..=1.0).contains(*x)) {
                                ctx.err(v, format!("ground.albedo: {f}: albedo must be in [0, 1], found {x}"));
                            }
                            t
                        }
                        None => Tabulated::constant(0.0),
                    }
                }
                _ => {
                    ctx.err(v, "ground.albedo must be a number or a spectrum file path");
                    Tabulated::constant(0.0)
                }
            }
        }
    };

    // [sun]
    let sun = match &raw.sun {
        None => {
            // The shipped sun (see `DEFAULT_SUN_CSV`), part of the content hash by name.
            ctx.hasher.update(b"[sun] default: ASTM G173-03 extraterrestrial, 0.533 deg");
            let path = std::path::Path::new("<built-in>/astm_g173_etr.csv");
            let t = Table::parse(path, DEFAULT_SUN_CSV).and_then(|t| t.function("irradiance_w_m2_nm")).expect("the built-in sun spectrum parses");
            Some(Sun { irradiance_w_m2_nm: t, angular_diameter_deg: DEFAULT_SUN_DIAMETER_DEG })
        }
        Some(s) => {
            let s = s.get_ref();
            let d = positive(&mut ctx, &s.angular_diameter_deg, "sun.angular_diameter_deg", 0.533);
            if d >= 30.0 {
                ctx.err(s.angular_diameter_deg.as_ref().unwrap(), format!("sun.angular_diameter_deg must be below 30, found {d}"));
            }
            ctx.spectral(&s.spectrum, s.spectrum.get_ref(), "sun.spectrum", "irradiance_w_m2_nm").map(|t| Sun { irradiance_w_m2_nm: t, angular_diameter_deg: d })
        }
    };

    if !ctx.errors.is_empty() {
        return Err(LoadError { errors: ctx.errors });
    }
    let name = raw.name.map(|n| n.into_inner()).unwrap_or_else(|| path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default());
    let atm = Atmosphere {
        name,
        description: raw.description.map(|d| d.into_inner()).unwrap_or_default(),
        path: path.to_path_buf(),
        content_hash: ctx.hasher.finalize().to_hex().to_string(),
        planet,
        profiles,
        air,
        absorbers,
        aerosols,
        ground_albedo,
        sun: sun.expect("no errors means a sun"),
    };
    Ok((atm, ctx.read))
}

fn analytic_optics(ctx: &mut Ctx, a: &RawAerosol, at: &S<RawAerosol>, label: &str) -> Option<AerosolOptics> {
    let phase = match a.phase.as_ref().map(|p| (p, p.get_ref().as_str())) {
        Some((_, "henyey-greenstein")) => AnalyticPhase::HenyeyGreenstein,
        Some((_, "cornette-shanks")) => AnalyticPhase::CornetteShanks,
        Some((p, other)) => {
            ctx.err(p, format!("{label}: phase must be \"henyey-greenstein\" or \"cornette-shanks\", found \"{other}\""));
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

fn mie_optics(ctx: &mut Ctx, a: &RawAerosol, at: &S<RawAerosol>, label: &str) -> Option<AerosolOptics> {
    let refractive_index = match &a.refractive_index {
        None => {
            ctx.err(at, format!("{label}: Mie optics need refractive_index"));
            None
        }
        Some(v) => match v.get_ref() {
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
                let k = if n.is_some() { ctx.spectral(v, &f, &format!("{label}: refractive_index"), "k") } else { None };
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
        },
    };
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
