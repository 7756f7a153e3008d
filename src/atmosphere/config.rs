//! Parsing and validation of atmosphere TOML files. Every error names the
//! file and the line of the offending key; unknown keys are errors.
//!
//! `parse` runs in phases, in the order of the file's checks: the planet
//! here, the profiles (`config_profiles.rs`), the air, absorbers and aerosols
//! (`config_components.rs`), then the ground and the sun here.

use super::*;
use crate::table::Table;
use serde::Deserialize;
use std::collections::BTreeMap;
use toml::Spanned;

// The phases sit beside this file in src/atmosphere/, not in a config/
// folder: they use the atmosphere types of `super`, which calls `parse`, and
// a folder of their own would make that an import cycle across folders.
#[path = "config_components.rs"]
mod components;
#[path = "config_profiles.rs"]
mod profiles;

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
            Some(files) => files
                .get(rel)
                .cloned()
                .ok_or_else(|| std::io::Error::new(std::io::ErrorKind::NotFound, "not among the job's files")),
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
            self.err(
                at,
                format!("{what}: {}: first column must be wavelength_nm, found {}", t.path.display(), t.columns[0]),
            );
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
pub(super) fn parse(
    path: &Path,
    text: &str,
    files: Option<&BTreeMap<String, Vec<u8>>>,
) -> Result<(Atmosphere, BTreeMap<String, Vec<u8>>), LoadError> {
    let raw: RawFile = match toml::from_str(text) {
        Ok(r) => r,
        Err(e) => {
            let line = e.span().map(|s| text[..s.start.min(text.len())].bytes().filter(|&b| b == b'\n').count() + 1);
            let message = e.message().trim().to_string();
            return Err(LoadError { errors: vec![Located { path: path.to_path_buf(), line, message }] });
        }
    };
    let mut ctx = Ctx {
        path,
        text,
        dir: path.parent().map(Path::to_path_buf).unwrap_or_default(),
        errors: Vec::new(),
        hasher: blake3::Hasher::new(),
        files,
        read: BTreeMap::new(),
    };
    ctx.hasher.update(text.as_bytes());

    let planet = parse_planet(&mut ctx, raw.planet.as_ref());
    let (profiles, by_name) = profiles::parse_profiles(&mut ctx, &raw.profile);
    let air = components::parse_air(&mut ctx, raw.air.as_ref(), &profiles, &by_name);
    let absorbers = components::parse_absorbers(&mut ctx, &raw.absorber, &profiles, &by_name, planet.top_km);
    let aerosols = components::parse_aerosols(&mut ctx, &raw.aerosol, &profiles, &by_name, planet.top_km);
    let ground_albedo = parse_ground(&mut ctx, raw.ground.as_ref());
    let sun = parse_sun(&mut ctx, raw.sun.as_ref());

    if !ctx.errors.is_empty() {
        return Err(LoadError { errors: ctx.errors });
    }
    let name = raw
        .name
        .map(|n| n.into_inner())
        .unwrap_or_else(|| path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default());
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

/// `[planet]`: radius and top in km (6371 and 100 when absent or invalid;
/// the top at most `MAX_TOP_KM`) and the geometry, spherical by default. A
/// missing table is an error at the top of the file.
fn parse_planet(ctx: &mut Ctx, raw: Option<&S<RawPlanet>>) -> Planet {
    match raw {
        None => {
            ctx.err_at(0, "missing [planet] table (radius_km, top_km, geometry)");
            Planet { radius_km: 6371.0, top_km: 100.0, geometry: Geometry::Spherical }
        }
        Some(p) => {
            let p = p.get_ref();
            let radius_km = positive(ctx, &p.radius_km, "planet.radius_km", 6371.0);
            let mut top_km = positive(ctx, &p.top_km, "planet.top_km", 100.0);
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
                        ctx.err(
                            g,
                            format!("planet.geometry must be \"spherical\" or \"plane-parallel\", found \"{other}\""),
                        );
                        Geometry::Spherical
                    }
                },
            };
            Planet { radius_km, top_km, geometry }
        }
    }
}

/// `[ground]`: the Lambertian albedo against wavelength in nm, a number or
/// a spectrum file with an `albedo` column, each in [0, 1] (values outside
/// are errors); black (0) without the table.
fn parse_ground(ctx: &mut Ctx, raw: Option<&S<RawGround>>) -> Tabulated {
    match raw {
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
    }
}

/// `[sun]`: the spectrum file's irradiance (W m⁻² nm⁻¹) and the angular
/// diameter, 0.533° by default and below 30°; without the table, the
/// built-in ASTM G173-03 sun (`DEFAULT_SUN_CSV`). None, with an error
/// recorded, when the spectrum file cannot be read or lacks that column.
fn parse_sun(ctx: &mut Ctx, raw: Option<&S<RawSun>>) -> Option<Sun> {
    match raw {
        None => {
            // The shipped sun (see `DEFAULT_SUN_CSV`), part of the content hash by name.
            ctx.hasher.update(b"[sun] default: ASTM G173-03 extraterrestrial, 0.533 deg");
            let path = std::path::Path::new("<built-in>/astm_g173_etr.csv");
            let t = Table::parse(path, DEFAULT_SUN_CSV)
                .and_then(|t| t.function("irradiance_w_m2_nm"))
                .expect("the built-in sun spectrum parses");
            Some(Sun { irradiance_w_m2_nm: t, angular_diameter_deg: DEFAULT_SUN_DIAMETER_DEG })
        }
        Some(s) => {
            let s = s.get_ref();
            let d = positive(ctx, &s.angular_diameter_deg, "sun.angular_diameter_deg", 0.533);
            if d >= 30.0 {
                ctx.err(
                    s.angular_diameter_deg.as_ref().unwrap(),
                    format!("sun.angular_diameter_deg must be below 30, found {d}"),
                );
            }
            ctx.spectral(&s.spectrum, s.spectrum.get_ref(), "sun.spectrum", "irradiance_w_m2_nm")
                .map(|t| Sun { irradiance_w_m2_nm: t, angular_diameter_deg: d })
        }
    }
}
