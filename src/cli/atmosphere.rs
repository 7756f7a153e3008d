//! `sky atmosphere check` and `sky atmosphere inspect`.

use super::EXIT_INVALID;
use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::json;
use sky::atmosphere::optics::{self, SpectralOptics};
use sky::atmosphere::{Aerosol, AerosolOptics, AnalyticPhase, Atmosphere};
use sky::mie::{phase, MieCache};
use sky::plot::{self, Axes, Scale, Series};
use sky::spectrum;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(clap::Subcommand)]
pub enum AtmosphereCommand {
    /// Validate atmosphere files; prints every error with its file and line
    Check {
        /// Atmosphere TOML files
        #[arg(required = true)]
        files: Vec<PathBuf>,
    },
    /// Optical depths, albedos and asymmetries per layer and in total
    #[command(after_help = "Example:\n  sky atmosphere inspect atmospheres/clear.toml --plot out/")]
    Inspect {
        /// Atmosphere TOML file
        file: PathBuf,
        /// Wavelengths in nm
        #[arg(
            long,
            value_name = "W,...",
            allow_hyphen_values = true,
            value_delimiter = ',',
            default_value = "400,450,500,550,600,650,700"
        )]
        wavelengths: Vec<f64>,
        /// Machine-readable output
        #[arg(long)]
        json: bool,
        /// Write PNG plots (profiles, phase functions, optical depth) into DIR
        #[arg(long, value_name = "DIR")]
        plot: Option<PathBuf>,
    },
}

pub fn run(c: AtmosphereCommand) -> Result<ExitCode> {
    match c {
        AtmosphereCommand::Check { files } => {
            let mut bad = 0;
            for f in &files {
                match Atmosphere::load(f) {
                    Ok(a) => outln!(
                        "{}: ok ({} profiles, {} absorbers, {} aerosols)",
                        f.display(),
                        a.profiles.len(),
                        a.absorbers.len(),
                        a.aerosols.len()
                    ),
                    Err(e) => {
                        bad += 1;
                        eprintln!("{e}");
                    }
                }
            }
            if bad > 0 {
                eprintln!("{bad} of {} files invalid", files.len());
                return Ok(ExitCode::from(EXIT_INVALID));
            }
            Ok(ExitCode::SUCCESS)
        }
        AtmosphereCommand::Inspect { file, wavelengths, json, plot } => {
            inspect(&file, &wavelengths, json, plot.as_deref())
        }
    }
}

fn inspect(file: &Path, wavelengths: &[f64], as_json: bool, plot_dir: Option<&Path>) -> Result<ExitCode> {
    if let Some(w) = wavelengths.iter().find(|w| !(**w > 0.0)) {
        return super::usage(format!("--wavelengths: {w} is not a positive wavelength"));
    }
    let atm = match Atmosphere::load(file) {
        Ok(a) => a,
        Err(e) => {
            eprintln!("{e}");
            return Ok(ExitCode::from(EXIT_INVALID));
        }
    };
    let cache = MieCache::from_env();
    let bar = progress(wavelengths.len() as u64, "optics");
    let spectral: Vec<SpectralOptics> = wavelengths
        .iter()
        .map(|&w| {
            let s = optics::spectral_optics(&atm, w, &cache);
            bar.inc(1);
            s
        })
        .collect();
    bar.finish_and_clear();
    let sun_xyz = spectrum::spectrum_to_xyz(&atm.sun.irradiance_w_m2_nm);
    if as_json {
        let v = json!({
            "file": file.display().to_string(),
            "name": atm.name,
            "content_hash": atm.content_hash,
            "planet": {
                "radius_km": atm.planet.radius_km,
                "top_km": atm.planet.top_km,
                "geometry": format!("{:?}", atm.planet.geometry).to_lowercase(),
            },
            "sun": {
                "angular_diameter_deg": atm.sun.angular_diameter_deg,
                "solid_angle_sr": spectrum::disk_solid_angle_sr(atm.sun.angular_diameter_deg),
                "xyz_irradiance_w_m2": sun_xyz,
                "chromaticity_xy": spectrum::chromaticity(sun_xyz),
            },
            "spectral": spectral,
        });
        outln!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        print_table(&atm, &spectral, sun_xyz);
    }
    if let Some(dir) = plot_dir {
        std::fs::create_dir_all(dir).with_context(|| format!("--plot: cannot create {}", dir.display()))?;
        let written = write_plots(&atm, dir, &cache)?;
        for w in written {
            eprintln!("wrote {}", w.display());
        }
    }
    Ok(ExitCode::SUCCESS)
}

fn progress(n: u64, what: &str) -> ProgressBar {
    let bar = ProgressBar::new(n);
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} eta {eta}").unwrap().progress_chars("=> "),
    );
    bar.set_message(what.to_string());
    bar
}

fn print_table(atm: &Atmosphere, spectral: &[SpectralOptics], sun_xyz: [f64; 3]) {
    let xy = spectrum::chromaticity(sun_xyz);
    outln!("{} ({})", atm.name, atm.path.display());
    if !atm.description.is_empty() {
        outln!("  {}", atm.description.trim());
    }
    outln!(
        "  planet: radius {} km, top {} km, {:?}; sun {} deg, xy ({:.4}, {:.4}); content hash {}",
        atm.planet.radius_km,
        atm.planet.top_km,
        atm.planet.geometry,
        atm.sun.angular_diameter_deg,
        xy[0],
        xy[1],
        &atm.content_hash[..16]
    );
    for s in spectral {
        outln!();
        outln!(
            "  {} nm: optical depth rayleigh {:.5}  absorbers {:.5}  aerosols {:.5}",
            s.wavelength_nm,
            s.rayleigh_optical_depth,
            s.absorber_optical_depth,
            s.aerosol_optical_depth
        );
        outln!("    {:<24} {:>10} {:>10} {:>10} {:>10} {:>14}", "component", "kind", "tau", "ssa", "g", "ext0_per_km");
        for c in s.components.iter().chain(std::iter::once(&s.total)) {
            outln!(
                "    {:<24} {:>10} {:>10.5} {:>10.5} {:>10.5} {:>14.5e}",
                c.name,
                c.kind,
                c.optical_depth,
                c.single_scattering_albedo,
                c.asymmetry,
                c.extinction_ground_per_km
            );
        }
    }
}

/// Altitudes for profile plots, km.
fn altitudes(top_km: f64) -> Vec<f64> {
    let n = 400;
    (0..=n).map(|i| top_km * i as f64 / n as f64).collect()
}

fn safe_name(s: &str) -> String {
    s.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '_' { c } else { '_' }).collect()
}

/// Writes the inspect plots into `dir`, in this order: number densities and
/// extinction at 550 nm against altitude, each aerosol's phase function, and
/// optical depth against wavelength. Returns the files written.
fn write_plots(atm: &Atmosphere, dir: &Path, cache: &MieCache) -> Result<Vec<PathBuf>> {
    let mut written = Vec::new();
    let zs_km = altitudes(atm.planet.top_km);
    let steps = 2 + atm.aerosols.len() as u64;
    let bar = progress(steps, "plots");
    written.push(plot_number_density(atm, dir, &zs_km, cache)?);
    written.push(plot_extinction_550nm(atm, dir, &zs_km, cache)?);
    bar.inc(1);
    let grid_deg = phase::phase_grid_deg();
    for a in &atm.aerosols {
        written.push(plot_phase(atm, a, dir, &grid_deg, cache)?);
        bar.inc(1);
    }
    written.push(plot_optical_depth(atm, dir, cache)?);
    bar.inc(1);
    bar.finish_and_clear();
    Ok(written)
}

/// `profiles.png`: number densities (m⁻³) of the air, the absorbers and the
/// Mie aerosols against altitude `zs_km`. Returns its path.
fn plot_number_density(atm: &Atmosphere, dir: &Path, zs_km: &[f64], cache: &MieCache) -> Result<PathBuf> {
    let mut series = Vec::new();
    if let Some(air) = &atm.air {
        let p = atm.profile(air.profile);
        series.push(Series::new(
            format!("air ({})", p.name),
            zs_km.iter().map(|&z| (air.scale * p.density(z), z)).collect(),
            series.len(),
        ));
    }
    for a in &atm.absorbers {
        let p = atm.profile(a.profile);
        series.push(Series::new(
            format!("{} ({})", a.name, p.name),
            zs_km.iter().map(|&z| (a.scale * p.density(z), z)).collect(),
            series.len(),
        ));
    }
    for a in &atm.aerosols {
        if let Some(n) = optics::aerosol_number_scale(atm, a, cache) {
            let p = atm.profile(a.profile);
            if matches!(a.optics, AerosolOptics::Mie { .. }) {
                series.push(Series::new(
                    format!("{} ({})", a.name, p.name),
                    zs_km.iter().map(|&z| (n * p.density(z), z)).collect(),
                    series.len(),
                ));
            }
        }
    }
    let path = dir.join("profiles.png");
    plot::line_plot(
        &path,
        &Axes {
            title: &format!("{}: number density", atm.name),
            x_label: "number density (m^-3)",
            y_label: "altitude (km)",
            x_scale: Scale::Log,
            y_scale: Scale::Linear,
        },
        &series,
    )
    .map_err(anyhow::Error::msg)?;
    Ok(path)
}

/// `extinction_550nm.png`: every component's extinction coefficient at
/// 550 nm in km⁻¹ against altitude `zs_km`. A cross-section σ in cm² times a
/// number density n in m⁻³ gives σ · 10⁻⁴ · n m⁻¹, × 1000 per km. Returns
/// its path.
fn plot_extinction_550nm(atm: &Atmosphere, dir: &Path, zs_km: &[f64], cache: &MieCache) -> Result<PathBuf> {
    let mut series = Vec::new();
    if let Some(air) = &atm.air {
        let p = atm.profile(air.profile);
        let k = optics::rayleigh_cross_section_cm2(air, 550.0) * 1e-4 * air.scale * 1000.0;
        series.push(Series::new(
            "air (Rayleigh)",
            zs_km.iter().map(|&z| (k * p.density(z), z)).collect(),
            series.len(),
        ));
    }
    for a in &atm.absorbers {
        let p = atm.profile(a.profile);
        let k = a.cross_section_cm2.eval(550.0) * 1e-4 * a.scale * 1000.0;
        series.push(Series::new(a.name.clone(), zs_km.iter().map(|&z| (k * p.density(z), z)).collect(), series.len()));
    }
    for a in &atm.aerosols {
        let p = atm.profile(a.profile);
        let k = optics::aerosol_scale(atm, a, 550.0, cache).extinction_per_density_m * 1000.0;
        series.push(Series::new(a.name.clone(), zs_km.iter().map(|&z| (k * p.density(z), z)).collect(), series.len()));
    }
    let path = dir.join("extinction_550nm.png");
    plot::line_plot(
        &path,
        &Axes {
            title: &format!("{}: extinction at 550 nm", atm.name),
            x_label: "extinction coefficient (km^-1)",
            y_label: "altitude (km)",
            x_scale: Scale::Log,
            y_scale: Scale::Linear,
        },
        &series,
    )
    .map_err(anyhow::Error::msg)?;
    Ok(path)
}

/// `phase_<aerosol>.png`: the aerosol's phase function (sr⁻¹) at 450, 550
/// and 650 nm against scattering angle `grid_deg`, each with the best-fitting
/// Henyey–Greenstein dashed. Returns its path.
fn plot_phase(atm: &Atmosphere, a: &Aerosol, dir: &Path, grid_deg: &[f64], cache: &MieCache) -> Result<PathBuf> {
    let mut series = Vec::new();
    for (ci, w) in [450.0, 550.0, 650.0].into_iter().enumerate() {
        let p: Vec<f64> = match &a.optics {
            AerosolOptics::Mie { .. } => optics::mie_particle_optics(a, w, grid_deg, cache).unwrap().phase_sr_inv,
            AerosolOptics::Analytic { phase: ph, g, .. } => grid_deg
                .iter()
                .map(|t| {
                    let mu = t.to_radians().cos();
                    match ph {
                        AnalyticPhase::HenyeyGreenstein => phase::henyey_greenstein(mu, *g),
                        AnalyticPhase::CornetteShanks => phase::cornette_shanks(mu, *g),
                    }
                })
                .collect(),
        };
        let g_fit = phase::fit_henyey_greenstein(grid_deg, &p);
        series.push(Series::new(format!("{w} nm"), grid_deg.iter().copied().zip(p.iter().copied()).collect(), ci));
        series.push(
            Series::new(
                format!("best Henyey-Greenstein {w} nm, g = {g_fit:.3}"),
                grid_deg.iter().map(|t| (*t, phase::henyey_greenstein(t.to_radians().cos(), g_fit))).collect(),
                ci,
            )
            .dashed(),
        );
    }
    let path = dir.join(format!("phase_{}.png", safe_name(&a.name)));
    plot::line_plot(
        &path,
        &Axes {
            title: &format!("{}: {} phase function", atm.name, a.name),
            x_label: "scattering angle (deg)",
            y_label: "phase function (sr^-1)",
            x_scale: Scale::Linear,
            y_scale: Scale::Log,
        },
        &series,
    )
    .map_err(anyhow::Error::msg)?;
    Ok(path)
}

/// `optical_depth.png`: each component's zenith optical depth and their
/// total (dashed) against wavelength, 360 to 830 nm in 10 nm steps. Returns
/// its path.
fn plot_optical_depth(atm: &Atmosphere, dir: &Path, cache: &MieCache) -> Result<PathBuf> {
    let ws: Vec<f64> = (0..=47).map(|i| 360.0 + 10.0 * i as f64).collect();
    let spectral: Vec<SpectralOptics> = ws.iter().map(|&w| optics::spectral_optics(atm, w, cache)).collect();
    let mut series = Vec::new();
    let names: Vec<String> = spectral[0].components.iter().map(|c| c.name.clone()).collect();
    for (i, name) in names.iter().enumerate() {
        series.push(Series::new(
            name.clone(),
            spectral.iter().map(|s| (s.wavelength_nm, s.components[i].optical_depth)).collect(),
            i,
        ));
    }
    series.push(
        Series::new("total", spectral.iter().map(|s| (s.wavelength_nm, s.total.optical_depth)).collect(), names.len())
            .dashed(),
    );
    let path = dir.join("optical_depth.png");
    plot::line_plot(
        &path,
        &Axes {
            title: &format!("{}: zenith optical depth", atm.name),
            x_label: "wavelength (nm)",
            y_label: "optical depth",
            x_scale: Scale::Linear,
            y_scale: Scale::Log,
        },
        &series,
    )
    .map_err(anyhow::Error::msg)?;
    Ok(path)
}
