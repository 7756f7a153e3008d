//! `sky bench`: timings reported in the README.

use anyhow::Result;
use serde_json::json;
use sky::atmosphere::RefractiveIndex;
use sky::mie::{self, phase, LogNormal};
use sky::table::Table;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

#[derive(clap::Subcommand)]
pub enum BenchCommand {
    /// Mie tables of a coarse water mode (r 4 um, sigma 0.55) over 400-800 nm every 5 nm,
    /// with the 601-angle phase tables, computed without the cache
    Mie {
        /// Water refractive index table (wavelength_nm,n,k); a constant 1.33-1e-7i if absent
        #[arg(long, default_value = "atmospheres/data/water_hale_querry_1973.csv")]
        water: PathBuf,
        /// Worker threads (default: all cores)
        #[arg(long)]
        threads: Option<usize>,
        /// Wavelength step in nm
        #[arg(long, default_value_t = 5.0)]
        step_nm: f64,
        /// Machine-readable output
        #[arg(long)]
        json: bool,
    },
}

pub fn run(c: BenchCommand) -> Result<ExitCode> {
    match c {
        BenchCommand::Mie { water, threads, step_nm, json } => {
            if !(step_nm > 0.0 && step_nm.is_finite()) {
                return super::usage("--step-nm must be positive");
            }
            let index = match Table::read(&water) {
                Ok(t) => RefractiveIndex::Table { n: t.function("n")?, k: t.function("k")? },
                Err(_) => RefractiveIndex::Constant(num_complex::Complex64::new(1.33, 1e-7)),
            };
            let threads = threads.unwrap_or_else(rayon::current_num_threads);
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
            let mode = LogNormal::new(4.0, 0.55);
            let grid = phase::phase_grid_deg();
            let n = ((800.0 - 400.0) / step_nm).floor() as usize + 1;
            let wavelengths: Vec<f64> = (0..n).map(|i| 400.0 + step_nm * i as f64).collect();
            let bar = indicatif::ProgressBar::new(n as u64);
            let start = Instant::now();
            let mut nodes = 0;
            pool.install(|| {
                for &w in &wavelengths {
                    let b = mie::bulk_optics(index.at(w), &mode, w, &grid);
                    let _table = phase::PhaseTable::new(&grid, &b.phase_sr_inv);
                    nodes += b.radius_nodes;
                    bar.inc(1);
                }
            });
            bar.finish_and_clear();
            let secs = start.elapsed().as_secs_f64();
            if json {
                println!(
                    "{}",
                    serde_json::to_string_pretty(&json!({
                        "benchmark": "mie-coarse-water", "wavelengths": n, "angles": grid.len(),
                        "radius_nodes": nodes, "threads": threads, "seconds": secs,
                        "seconds_per_wavelength": secs / n as f64,
                    }))?
                );
            } else {
                println!(
                    "mie coarse water mode (r_median 4 um, sigma 0.55), {n} wavelengths 400-800 nm, {} angles: {secs:.2} s on {threads} threads ({:.3} s per wavelength, {nodes} radius nodes in all)",
                    grid.len(),
                    secs / n as f64
                );
            }
            Ok(ExitCode::SUCCESS)
        }
    }
}
