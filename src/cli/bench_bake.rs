//! `sky bench bake`: the projected cost of a final bake, per basis sky and
//! estimator, measured on a few slices against converged references (the
//! measurement itself is `sky::study::bench`).

use super::{usage, EXIT_INVALID};
use anyhow::Result;
use sky::render::SingleScatter;
use sky::study::bench::{self, BenchOptions, SliceCost};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::AtomicBool;

#[derive(Clone, Copy, PartialEq, clap::ValueEnum)]
pub enum MethodArg {
    Quadrature,
    MonteCarlo,
}

#[derive(clap::Args)]
pub struct BenchBakeArgs {
    /// The bake file whose basis skies are measured
    #[arg(default_value = "bakes/basis-skies.toml")]
    pub bake: PathBuf,
    /// Basis skies to measure, by name (default: all of the bake's)
    #[arg(long, value_delimiter = ',')]
    pub skies: Vec<String>,
    /// Sun zenith angles of the measured slices, degrees
    #[arg(long, value_delimiter = ',', default_value = "20,60,85,88,91,93,96,99", allow_hyphen_values = true)]
    pub sun_zenith_deg: Vec<f64>,
    /// Measure every N-th texel of a slice in both axes, or every U-th along u (columns) and V-th along v (rows) with UxV
    #[arg(long, default_value = "4", value_parser = parse_stride)]
    pub stride: [usize; 2],
    /// Samples per texel of the measured renders
    #[arg(long, default_value_t = 256)]
    pub spp: u32,
    /// Samples per texel of the reference renders
    #[arg(long, default_value_t = 4096)]
    pub reference_spp: u32,
    /// Estimators of single scattering to compare, in one run
    #[arg(long, value_delimiter = ',', value_enum, default_value = "monte-carlo,quadrature")]
    pub methods: Vec<MethodArg>,
    /// Threads (core-seconds are wall seconds times this; default: all cores)
    #[arg(long)]
    pub threads: Option<usize>,
    /// Measure the bake's fog slices (its `[fog]` size; their render is the Shadowed Fog, the Fog's quadrature is priced per texel) instead of its sky slices
    #[arg(long)]
    pub fog: bool,
    /// Also measure multiple scattering interpolated from every --stride-th texel (the quadrature's Monte Carlo part on a coarser grid): its error at the coarse cells' centres, rendered at the reference's samples, and what it would save
    #[arg(long, conflicts_with = "fog")]
    pub coarse_ms: bool,
    /// Also measure multiple scattering interpolated from a grid of its own over the sky, ROWSxCOLUMNS (zenith angles crowding toward the horizon, azimuths from the sun's 0 to 180 degrees), e.g. 24x19
    #[arg(long, value_parser = parse_stride, conflicts_with = "fog")]
    pub coarse_ms_grid: Option<[usize; 2]>,
    /// Machine-readable output
    #[arg(long)]
    pub json: bool,
}

/// "N" (both axes) or "UxV", each at least 1.
fn parse_stride(s: &str) -> Result<[usize; 2], String> {
    let parse = |t: &str| match t.trim().parse::<usize>() {
        Ok(n) if n >= 1 => Ok(n),
        _ => Err(format!("{t:?} is not a whole number of at least 1")),
    };
    match s.split_once('x') {
        Some((u, v)) => Ok([parse(u)?, parse(v)?]),
        None => parse(s).map(|n| [n, n]),
    }
}

fn method_name(m: SingleScatter) -> &'static str {
    match m {
        SingleScatter::Quadrature => "quadrature",
        SingleScatter::MonteCarlo => "monte-carlo",
    }
}

pub fn run(a: BenchBakeArgs) -> Result<ExitCode> {
    if a.spp < 2 || a.reference_spp < 2 {
        return usage("--spp and --reference-spp must be at least 2");
    }
    if a.threads == Some(0) {
        return usage("--threads must be at least 1");
    }
    if a.sun_zenith_deg.is_empty() || a.sun_zenith_deg.iter().any(|z| !(0.0..=120.0).contains(z)) {
        return usage("--sun-zenith-deg: angles between 0 and 120 degrees");
    }
    if a.methods.is_empty() {
        return usage("--methods: at least one");
    }
    let Some(bake) = super::bake::load_bake(&a.bake) else { return Ok(ExitCode::from(EXIT_INVALID)) };
    let threads = a.threads.unwrap_or_else(rayon::current_num_threads);
    let o = BenchOptions {
        skies: a.skies.clone(),
        sun_zenith_deg: a.sun_zenith_deg.clone(),
        stride: a.stride,
        spp: a.spp,
        reference_spp: a.reference_spp,
        // The fog's render has no single scattering of sunlight to estimate either way.
        methods: if a.fog {
            vec![SingleScatter::Quadrature]
        } else {
            a.methods
                .iter()
                .map(
                    |m| if *m == MethodArg::Quadrature { SingleScatter::Quadrature } else { SingleScatter::MonteCarlo },
                )
                .collect()
        },
        threads,
        fog: a.fog,
        coarse_ms: a.coarse_ms,
        coarse_ms_grid: a.coarse_ms_grid,
    };
    if a.coarse_ms_grid.is_some_and(|[r, c]| r < 2 || c < 2) {
        return usage("--coarse-ms-grid: at least 2 rows and 2 columns");
    }
    if a.coarse_ms && a.stride[0] * a.stride[1] < 2 {
        return usage(
            "--coarse-ms interpolates from every --stride-th texel: --stride must exceed 1 in at least one axis",
        );
    }
    if !a.json {
        let what = if a.fog { "fog slices (the Shadowed Fog's render, the Fog's quadrature)" } else { "sky slices" };
        outln!("final-bake cost of the {what} from every {}th texel along u and {}th along v, {} spp against {} spp references, {threads} thread(s); per-sample relative variance of Y against the reference (own estimate), samples per texel and core-seconds per full slice to 1 %", a.stride[0], a.stride[1], a.spp, a.reference_spp);
    }
    let json = a.json;
    let on_slice = |c: &SliceCost| {
        if !json {
            eprintln!(
                "{:>8} sun {:>5.1}  {:<11} var {:>9.4} ({:>9.4})  ref ±{:.2} %  {:>8.0} spp  {:>10.1} core-s/slice ({:.1} at the cap){}",
                c.sky,
                c.sun_zenith_deg,
                method_name(c.method),
                c.rel_var_vs_reference,
                c.rel_var_own,
                100.0 * c.reference_rel_stderr,
                c.samples_to_target,
                c.slice_core_seconds_to_target,
                c.slice_core_seconds_capped,
                if c.capped_fraction > 0.0 { format!("  ({:.0} % of texels at the cap)", 100.0 * c.capped_fraction) } else { String::new() }
            );
            for g in &c.coarse_ms {
                let m = &g.accuracy;
                eprintln!(
                    "{:>8}  MS from {:<9} error {:.3} % RMS (noise floor {:.3} %, p95 |e| {:.2} %) over {} cells ({} at the horizon left out; single scattering {:.0} % of Y); away from the sun and the horizon {:.3} % (floor {:.3} %, {} cells); {:.1} % of the texels sampled  {:>10.1} core-s/slice ({:.1} at the cap)",
                    "",
                    g.grid,
                    100.0 * m.rms_rel_error,
                    100.0 * m.noise_floor,
                    100.0 * m.p95_abs_rel_error,
                    m.cells,
                    m.horizon_cells,
                    100.0 * m.single_share,
                    100.0 * m.far_rms_rel_error,
                    100.0 * m.far_noise_floor,
                    m.far_cells,
                    100.0 * g.sampled_fraction,
                    g.slice_core_seconds_to_target,
                    g.slice_core_seconds_capped
                );
            }
        }
    };
    let mie = sky::mie::MieCache::from_env();
    let report = match bench::run(&bake, &o, &mie, &AtomicBool::new(false), &on_slice) {
        Ok(r) => r,
        Err(e @ bench::BenchError::NoSuchSky(_)) => return usage(format!("--skies: {e}")),
        Err(e) => return Err(e.into()),
    };
    if json {
        outln!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(ExitCode::SUCCESS);
    }
    outln!("projected final bake (64 slices each, at the full slice size), core-hours to 1 % in every texel (and what the final quality spends, its texels stopped at the cap):");
    for s in &report.skies {
        outln!("  {:>8}  {:<11} {:>10.1} ({:.1})", s.sky, method_name(s.method), s.core_hours, s.capped_core_hours);
    }
    for ((m, h), (_, c)) in report.total_core_hours.iter().zip(&report.total_capped_core_hours) {
        outln!("  {:>8}  {:<11} {:>10.1} ({:.1})", "total", method_name(*m), h, c);
    }
    for c in &report.coarse_ms {
        outln!("  {:>8}  MS from {:<11} {:>10.1} ({:.1})", c.sky, c.grid, c.core_hours, c.capped_core_hours);
    }
    Ok(ExitCode::SUCCESS)
}
