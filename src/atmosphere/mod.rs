//! The atmosphere model: what `atmospheres/*.toml` describe, loaded and
//! validated (see `config`), and the optical properties derived from it
//! (see `optics`).

mod config;
pub mod optics;
pub mod profile;
pub mod rayleigh;
pub mod us1976;

use crate::mie::LogNormal;
use crate::table::Tabulated;
use num_complex::Complex64 as C64;
use std::path::{Path, PathBuf};

pub use profile::{DensityUnits, Interpolation, Profile, ProfileShape};

/// An error in an atmosphere file, located at its file and line.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}{}: {message}", path.display(), line.map(|l| format!(":{l}")).unwrap_or_default())]
pub struct Located {
    pub path: PathBuf,
    pub line: Option<usize>,
    pub message: String,
}

/// All the errors found in one atmosphere file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}", errors.iter().map(|e| e.to_string()).collect::<Vec<_>>().join("\n"))]
pub struct LoadError {
    pub errors: Vec<Located>,
}

/// Planet geometry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Geometry {
    Spherical,
    /// Horizontally infinite slab: for validation against 1-D codes.
    PlaneParallel,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Planet {
    pub radius_km: f64,
    pub top_km: f64,
    pub geometry: Geometry,
}

/// Where the Rayleigh cross-section comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum CrossSection {
    Bodhaine1999,
    Bucholtz1995,
    /// Tabulated, cm² per molecule against wavelength in nm.
    Table(Tabulated),
}

/// Depolarization ratio of air for the phase function.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Depolarization {
    /// From the Bodhaine King factor at each wavelength.
    Physical,
    Fixed(f64),
}

/// Air molecules (Rayleigh scattering).
#[derive(Debug, Clone, PartialEq)]
pub struct Air {
    pub profile: usize,
    /// Multiplies the profile to give number density in m⁻³.
    pub scale: f64,
    pub cross_section: CrossSection,
    pub depolarization: Depolarization,
}

/// A purely absorbing gas such as ozone.
#[derive(Debug, Clone, PartialEq)]
pub struct Absorber {
    pub name: String,
    pub profile: usize,
    /// Multiplies the profile to give number density in m⁻³.
    pub scale: f64,
    /// Absorption cross-section, cm² per molecule, against wavelength in nm.
    pub cross_section_cm2: Tabulated,
}

/// A complex refractive index, constant or against wavelength (Im ≥ 0).
#[derive(Debug, Clone, PartialEq)]
pub enum RefractiveIndex {
    Constant(C64),
    Table { n: Tabulated, k: Tabulated },
}

impl RefractiveIndex {
    pub fn at(&self, wavelength_nm: f64) -> C64 {
        match self {
            RefractiveIndex::Constant(m) => *m,
            RefractiveIndex::Table { n, k } => C64::new(n.eval(wavelength_nm), k.eval(wavelength_nm).abs()),
        }
    }
}

/// The analytic phase functions the talk compares the measured model with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AnalyticPhase {
    HenyeyGreenstein,
    CornetteShanks,
}

/// How an aerosol's particles scatter.
#[derive(Debug, Clone, PartialEq)]
pub enum AerosolOptics {
    /// Mie theory over log-normal modes (number distributions; volume
    /// distributions are converted on load), with number fractions.
    Mie { refractive_index: RefractiveIndex, modes: Vec<(f64, LogNormal)> },
    /// The approximations other engines use.
    Analytic { phase: AnalyticPhase, g: f64, single_scattering_albedo: f64, angstrom_exponent: f64 },
}

/// How the aerosol's amount is fixed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Amount {
    /// Number density (m⁻³) where the relative profile equals 1.
    NumberDensityM3(f64),
    /// Zenith optical depth (ground to top) at a wavelength.
    OpticalDepth { optical_depth: f64, wavelength_nm: f64 },
    /// The profile is already absolute (m⁻³).
    Profile,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Aerosol {
    pub name: String,
    pub profile: usize,
    pub optics: AerosolOptics,
    pub amount: Amount,
}

/// The sun: extraterrestrial spectral irradiance and disk size.
#[derive(Debug, Clone, PartialEq)]
pub struct Sun {
    /// W m⁻² nm⁻¹ at normal incidence, against wavelength in nm.
    pub irradiance_w_m2_nm: Tabulated,
    pub angular_diameter_deg: f64,
}

/// A loaded, validated atmosphere.
#[derive(Debug, Clone, PartialEq)]
pub struct Atmosphere {
    pub name: String,
    pub description: String,
    pub path: PathBuf,
    /// BLAKE3 of the file and every data file it references.
    pub content_hash: String,
    pub planet: Planet,
    pub profiles: Vec<Profile>,
    pub air: Option<Air>,
    pub absorbers: Vec<Absorber>,
    pub aerosols: Vec<Aerosol>,
    /// Lambertian ground albedo against wavelength in nm.
    pub ground_albedo: Tabulated,
    pub sun: Sun,
}

/// An atmosphere file's text with the data files it reads, keyed by the
/// names it gives them.
#[derive(Debug, Clone, PartialEq)]
pub struct Bundle {
    pub name: String,
    pub text: String,
    pub files: std::collections::BTreeMap<String, Vec<u8>>,
}

/// An atmosphere file's text; text that is not UTF-8 is an error at the
/// line of its first bad byte.
fn read_text(path: &Path) -> Result<String, LoadError> {
    let fail = |line, message| LoadError { errors: vec![Located { path: path.to_path_buf(), line, message }] };
    let bytes = std::fs::read(path).map_err(|e| fail(None, format!("cannot read: {e}")))?;
    String::from_utf8(bytes).map_err(|e| {
        let at = e.utf8_error().valid_up_to();
        let bytes = e.as_bytes();
        let line = bytes[..at].iter().filter(|&&b| b == b'\n').count() + 1;
        let col = at - bytes[..at].iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1) + 1;
        fail(Some(line), format!("not UTF-8 text: byte {:#04x} at column {col}", bytes[at]))
    })
}

impl Atmosphere {
    /// Loads and validates an atmosphere file.
    pub fn load(path: &Path) -> Result<Atmosphere, LoadError> {
        Atmosphere::from_str(path, &read_text(path)?)
    }

    /// Parses atmosphere text; `path` names it in errors and anchors its
    /// relative data paths.
    pub fn from_str(path: &Path, text: &str) -> Result<Atmosphere, LoadError> {
        config::parse(path, text, None).map(|(a, _)| a)
    }

    /// Loads an atmosphere file with every data file it reads, so that it
    /// can travel in a farm job (see [`Atmosphere::from_bundle`]).
    pub fn load_bundle(path: &Path) -> Result<(Atmosphere, Bundle), LoadError> {
        let text = read_text(path)?;
        let (atm, files) = config::parse(path, &text, None)?;
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        Ok((atm, Bundle { name, text, files }))
    }

    /// Parses a bundled atmosphere: data files come from the bundle only,
    /// never from the disk. Errors name the file as `job:NAME`.
    pub fn from_bundle(bundle: &Bundle) -> Result<Atmosphere, LoadError> {
        let path = PathBuf::from(format!("job:{}", bundle.name));
        config::parse(&path, &bundle.text, Some(&bundle.files)).map(|(a, _)| a)
    }

    pub fn profile(&self, i: usize) -> &Profile {
        &self.profiles[i]
    }
}
