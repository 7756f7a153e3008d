//! `sky mie`: Mie scattering of one sphere or a log-normal distribution.

use super::usage;
use anyhow::Result;
use num_complex::Complex64 as C64;
use serde_json::json;
use sky::mie::{self, LogNormal};
use std::f64::consts::PI;
use std::process::ExitCode;

#[derive(clap::Args)]
#[command(
    group(clap::ArgGroup::new("size").required(true).args(["x", "radius_um", "lognormal"])),
    after_help = "Refractive index sign convention: Bohren and Huffman write an absorbing particle as m = n + ik \
(time dependence exp(-iwt)); other codes write n - ik. sky takes |k| either way, so 1.33-1e-7i and \
1.33+1e-7i are the same weakly absorbing water droplet.\n\n\
Examples:\n  sky mie --m 1.33-1e-7i --x 10\n  sky mie --m 1.75-0.44i --radius-um 0.1 --wavelength-nm 550 --json\n  \
sky mie --m 1.33-1e-7i --lognormal 4.0,0.55 --wavelength-nm 450 --angles-deg 0,1,5,30,90,180"
)]
pub struct MieArgs {
    /// Complex refractive index, e.g. 1.33-1e-7i (see the sign convention below)
    #[arg(long = "m", value_name = "N-Ki", allow_hyphen_values = true, value_parser = parse_m)]
    m: C64,
    /// Size parameter x = 2 pi r / wavelength (one sphere)
    #[arg(long, value_name = "X", allow_hyphen_values = true)]
    x: Option<f64>,
    /// Sphere radius in micrometres (needs --wavelength-nm)
    #[arg(long, value_name = "R", requires = "wavelength_nm")]
    radius_um: Option<f64>,
    /// Log-normal number distribution: median radius (um) and sigma = ln(GSD) (needs --wavelength-nm)
    #[arg(long, value_name = "R_UM,SIGMA", requires = "wavelength_nm", value_delimiter = ',')]
    lognormal: Option<Vec<f64>>,
    /// Vacuum wavelength in nanometres
    #[arg(long, value_name = "W")]
    wavelength_nm: Option<f64>,
    /// Scattering angles for S1, S2 and the phase function, degrees
    #[arg(
        long,
        value_name = "A,B,...",
        allow_hyphen_values = true,
        value_delimiter = ',',
        default_value = "0,1,2,5,10,20,30,45,60,90,120,150,180"
    )]
    angles_deg: Vec<f64>,
    /// Machine-readable output
    #[arg(long)]
    json: bool,
}

fn parse_m(s: &str) -> Result<C64, String> {
    mie::parse_refractive_index(s)
}

fn check_positive(flag: &str, v: f64) -> Result<()> {
    if !(v.is_finite() && v > 0.0) {
        return usage(format!("{flag} must be a positive number, got {v}"));
    }
    Ok(())
}

pub fn run(a: MieArgs) -> Result<ExitCode> {
    if let Some(bad) = a.angles_deg.iter().find(|t| !(0.0..=180.0).contains(*t)) {
        return usage(format!("--angles-deg: {bad} is outside 0 to 180 degrees"));
    }
    if let Some(w) = a.wavelength_nm {
        check_positive("--wavelength-nm", w)?;
    }
    let mus: Vec<f64> = a.angles_deg.iter().map(|t| t.to_radians().cos()).collect();
    if let Some(ln) = &a.lognormal {
        let [r, sigma] = ln.as_slice() else { return usage("--lognormal takes R_UM,SIGMA, e.g. 4.0,0.55") };
        check_positive("--lognormal radius", *r)?;
        check_positive("--lognormal sigma", *sigma)?;
        if *sigma > 1.5 {
            return usage(format!("--lognormal sigma is ln(GSD) and must be at most 1.5, got {sigma}"));
        }
        let w = a.wavelength_nm.unwrap();
        let mode = LogNormal::new(*r, *sigma);
        let b = mie::bulk_optics(a.m, &mode, w, &a.angles_deg);
        if a.json {
            let v = json!({
                "m_re": a.m.re, "m_im": a.m.im, "wavelength_nm": w,
                "median_radius_um": r, "sigma": sigma,
                "c_ext_um2": b.c_ext_um2, "c_sca_um2": b.c_sca_um2, "c_abs_um2": b.c_ext_um2 - b.c_sca_um2,
                "single_scattering_albedo": b.single_scattering_albedo(), "g": b.g,
                "radius_nodes": b.radius_nodes,
                "angles_deg": a.angles_deg, "phase_sr_inv": b.phase_sr_inv,
            });
            outln!("{}", serde_json::to_string_pretty(&v)?);
        } else {
            outln!(
                "log-normal number distribution: r_median {r} um, sigma {sigma} (GSD {:.4}), m = {}{:+}i, {w} nm",
                sigma.exp(),
                a.m.re,
                -a.m.im
            );
            outln!(
                "  C_ext {:.6e} um^2   C_sca {:.6e} um^2   C_abs {:.6e} um^2",
                b.c_ext_um2,
                b.c_sca_um2,
                b.c_ext_um2 - b.c_sca_um2
            );
            outln!(
                "  single-scattering albedo {:.6}   g {:.6}   ({} radius nodes)",
                b.single_scattering_albedo(),
                b.g,
                b.radius_nodes
            );
            outln!("  {:>9}  {:>14}", "angle_deg", "phase_sr_inv");
            for (t, p) in a.angles_deg.iter().zip(&b.phase_sr_inv) {
                outln!("  {t:>9}  {p:>14.6e}");
            }
        }
        return Ok(ExitCode::SUCCESS);
    }
    let (x, radius_um) = match (a.x, a.radius_um) {
        (Some(x), _) => (x, None),
        (None, Some(r)) => {
            check_positive("--radius-um", r)?;
            (2.0 * PI * r / (a.wavelength_nm.unwrap() * 1e-3), Some(r))
        }
        _ => unreachable!("clap group"),
    };
    check_positive("--x", x)?;
    if x > 1e5 {
        return usage(format!("--x {x} is beyond the supported range (up to 1e5)"));
    }
    let r = mie::bhmie(a.m, x, &mus);
    let phase: Vec<f64> =
        r.s1.iter().zip(&r.s2).map(|(s1, s2)| 0.5 * (s1.norm_sqr() + s2.norm_sqr()) / (PI * x * x * r.q_sca)).collect();
    if a.json {
        let mut v = json!({
            "m_re": a.m.re, "m_im": a.m.im, "x": x,
            "q_ext": r.q_ext, "q_sca": r.q_sca, "q_abs": r.q_abs(), "q_back": r.q_back, "g": r.g,
            "single_scattering_albedo": r.q_sca / r.q_ext,
            "angles_deg": a.angles_deg,
            "s1_re": r.s1.iter().map(|c| c.re).collect::<Vec<_>>(),
            "s1_im": r.s1.iter().map(|c| c.im).collect::<Vec<_>>(),
            "s2_re": r.s2.iter().map(|c| c.re).collect::<Vec<_>>(),
            "s2_im": r.s2.iter().map(|c| c.im).collect::<Vec<_>>(),
            "phase_sr_inv": phase,
        });
        if let Some(rad) = radius_um {
            let area = PI * rad * rad;
            v["radius_um"] = json!(rad);
            v["wavelength_nm"] = json!(a.wavelength_nm);
            v["c_ext_um2"] = json!(r.q_ext * area);
            v["c_sca_um2"] = json!(r.q_sca * area);
        }
        outln!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        outln!("sphere: x = {x}, m = {}{:+}i", a.m.re, -a.m.im);
        outln!(
            "  Q_ext {:.8}   Q_sca {:.8}   Q_abs {:.8}   Q_back {:.8}   g {:.8}",
            r.q_ext,
            r.q_sca,
            r.q_abs(),
            r.q_back,
            r.g
        );
        if let Some(rad) = radius_um {
            let area = PI * rad * rad;
            outln!("  radius {rad} um: C_ext {:.6e} um^2   C_sca {:.6e} um^2", r.q_ext * area, r.q_sca * area);
        }
        outln!("  {:>9}  {:>26}  {:>26}  {:>14}", "angle_deg", "S1", "S2", "phase_sr_inv");
        for i in 0..mus.len() {
            outln!(
                "  {:>9}  {:>12.5e}{:+12.5e}i  {:>12.5e}{:+12.5e}i  {:>14.6e}",
                a.angles_deg[i],
                r.s1[i].re,
                r.s1[i].im,
                r.s2[i].re,
                r.s2[i].im,
                phase[i]
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}
