//! The `sky` command line: argument definitions and dispatch.

/// `println!` that ends the program quietly, with exit code 0, when the
/// reader of stdout has gone away (`sky mie ... | head -2`: a closed pipe),
/// as ripgrep does, and with a message and exit code 1 on any other write
/// error, instead of panicking.
macro_rules! outln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        if let Err(e) = writeln!(std::io::stdout().lock(), $($arg)*) {
            $crate::cli::stdout_failed(e);
        }
    }};
}

mod atmosphere;
mod bake;
mod bench;
mod bench_bake;
mod bench_disort;
mod bench_farm;
mod bench_preview;
mod farm_args;
mod lut;
mod lut_check;
mod lut_fog;
mod lut_interpolation;
mod lut_verify;
mod mie;
mod preview;
mod progress;
mod render;
mod render_output;
mod worker;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// Exit code for bad input (an invalid atmosphere file, a failed check).
pub const EXIT_INVALID: u8 = 1;
/// Exit code for usage errors and unimplemented commands (clap also uses 2).
pub const EXIT_USAGE: u8 = 2;

#[derive(Parser)]
#[command(
    name = "sky",
    version,
    about = "Physically based spectral skies and LUTs for real-time engines",
    long_about = "sky renders full-spectrum, path-traced skies from measured atmosphere models \
(U.S. Standard 1976 air, ozone, Mie aerosols, spectral ground albedo, the ASTM G173 sun) \
and bakes them into look-up tables, after Polyphony Digital's GDC 2023 talk on Gran Turismo 7's skies.",
    after_help = "Exit codes: 0 success, 1 invalid input or failed run, 2 usage error or not implemented yet."
)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Path-trace a full-spectrum sky to an XYZ OpenEXR
    Render(render::RenderArgs),
    /// Run a render-farm worker daemon on an idle PC
    Worker(worker::WorkerArgs),
    /// Bake the talk's basis-sky LUTs (R11G11B10F texture arrays and a manifest)
    BakeLuts(bake::BakeArgs),
    /// Read a bake's LUTs as a runtime does: sample a direction, decode a whole sky
    #[command(subcommand)]
    Lut(lut::LutCommand),
    /// Headless GPU preview of a bake: its sky, the landscape through the global fog and cumulus clouds, drawn on the GPU (lavapipe without one) to EXR and PNG
    Preview(preview::PreviewArgs),
    /// Validate and inspect atmosphere files (TOML; a file without a [sun]
    /// table gets the shipped ASTM G173-03 extraterrestrial sun with a 0.533
    /// degree disk)
    #[command(subcommand)]
    Atmosphere(atmosphere::AtmosphereCommand),
    /// Mie scattering by one sphere or a log-normal size distribution
    Mie(mie::MieArgs),
    /// Benchmarks (timings for the README)
    #[command(subcommand)]
    Bench(bench::BenchCommand),
}

/// A bad flag value found after parsing: reported like clap's own errors
/// and with the same exit code.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct UsageError(pub String);

/// Returns a [`UsageError`] naming the flag.
pub fn usage<T>(msg: impl Into<String>) -> anyhow::Result<T> {
    Err(UsageError(msg.into()).into())
}

/// The hidden `--fault-*` flags make a worker or coordinator misbehave on
/// purpose for the farm's own tests (tests/farm.rs). They are refused unless
/// `SKY_FAULT_INJECTION=1` is set, so that a stray flag in a user's script
/// cannot corrupt a render; a corrupting worker is caught by the farm's
/// verification either way.
pub fn faults_allowed(any_fault_flag: bool) -> anyhow::Result<()> {
    if any_fault_flag && std::env::var_os("SKY_FAULT_INJECTION").is_none_or(|v| v != "1") {
        return usage("the --fault-* flags are for the farm's own tests and need SKY_FAULT_INJECTION=1");
    }
    Ok(())
}

/// What a failed write to stdout does (see `outln!`).
pub fn stdout_failed(e: std::io::Error) -> ! {
    if e.kind() == std::io::ErrorKind::BrokenPipe {
        std::process::exit(0);
    }
    eprintln!("error: writing to stdout: {e}");
    std::process::exit(EXIT_INVALID as i32)
}

/// Parses the command line and runs it.
pub fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Render(a) => render::run(a),
        Command::Worker(a) => worker::run(a),
        Command::BakeLuts(a) => bake::run(a),
        Command::Lut(c) => lut::run(c),
        Command::Preview(a) => preview::run(a),
        Command::Atmosphere(c) => atmosphere::run(c),
        Command::Mie(a) => mie::run(a),
        Command::Bench(b) => bench::run(b),
    };
    match result {
        Ok(code) => code,
        Err(e) if e.downcast_ref::<UsageError>().is_some() => {
            eprintln!("error: {e:#}\n\nFor more information, try '--help'.");
            ExitCode::from(EXIT_USAGE)
        }
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(EXIT_INVALID)
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn clap_definition_is_consistent() {
        use clap::CommandFactory;
        super::Cli::command().debug_assert();
    }
}
