//! Compiles the farm's gRPC service (proto/) with protox, a protobuf
//! compiler in pure Rust, so a fresh machine needs no system `protoc`; and
//! names the renderer's source: `SKY_RENDER_SOURCE` is a hash of every file
//! a rendered pixel depends on (the renderer, the atmosphere and Mie
//! models, the LUT mappings, the spectra and tables, Cargo.lock), so that
//! caches of rendered slices and farm workers tell builds of different
//! physics apart even under one version number, while builds of the same
//! source on different machines agree. `SKY_MS_GRID_SOURCE` names the same
//! way the bake's resampling of multiple scattering from a grid
//! (`src/bake/ms_grid.rs`), which a slice from a grid depends on too (and a
//! farm worker does not run), and `SKY_FOG_RESAMPLE_SOURCE` the resampling
//! of a Shadowed Fog rendered at a size of its own (`src/bake/fog_resample.rs`
//! and the Fog LUT's mapping, `src/lut/fog.rs`). `SKY_FORECAST_SOURCE`
//! names the code of a bake's forecast from pilots and the quadratures it
//! times, so that a pilot's saved forecast is planned again when it changes.

use std::path::{Path, PathBuf};

/// The files and folders (recursively) whose content names the renderer.
const RENDER_SOURCES: [&str; 8] = [
    "src/render",
    "src/atmosphere",
    "src/mie",
    "src/directions",
    "src/spectrum.rs",
    "src/table.rs",
    "src/session.rs",
    "Cargo.lock",
];

fn files(path: &Path, out: &mut Vec<PathBuf>) {
    if path.is_dir() {
        let mut entries: Vec<PathBuf> =
            std::fs::read_dir(path).map(|r| r.flatten().map(|e| e.path()).collect()).unwrap_or_default();
        entries.sort();
        for e in entries {
            files(&e, out);
        }
    } else if path.is_file() {
        out.push(path.to_path_buf());
    }
}

/// 128 bits of two FNV-1a 64-bit hashes (different offsets) over each
/// file's path and content of `sources`: a change detector, not a
/// cryptographic hash.
fn source_hash(sources: &[&str]) -> String {
    let mut all = Vec::new();
    for s in sources {
        println!("cargo:rerun-if-changed={s}");
        files(Path::new(s), &mut all);
    }
    let mut h = [0xcbf2_9ce4_8422_2325u64, 0x6c62_272e_07bb_0142u64];
    let mut feed = |bytes: &[u8]| {
        for &b in bytes {
            for x in h.iter_mut() {
                *x ^= b as u64;
                *x = x.wrapping_mul(0x0000_0100_0000_01b3);
            }
        }
    };
    // Paths with '/' and content without '\r', so that checkouts on
    // Windows (backslashes, CRLF line ends) name the same source.
    for f in all {
        feed(f.to_string_lossy().replace('\\', "/").as_bytes());
        feed(&[0]);
        let content: Vec<u8> = std::fs::read(&f).unwrap_or_default().into_iter().filter(|&b| b != b'\r').collect();
        feed(&content);
        feed(&[0]);
    }
    format!("{:016x}{:016x}", h[0], h[1])
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let proto = "proto/sky/farm/v1/farm.proto";
    println!("cargo:rerun-if-changed={proto}");
    println!("cargo:rustc-env=SKY_RENDER_SOURCE={}", source_hash(&RENDER_SOURCES));
    println!("cargo:rustc-env=SKY_MS_GRID_SOURCE={}", source_hash(&["src/bake/ms_grid.rs"]));
    println!("cargo:rustc-env=SKY_TRANSPORT_SOURCE={}", source_hash(&["src/transport"]));
    println!(
        "cargo:rustc-env=SKY_FOG_RESAMPLE_SOURCE={}",
        source_hash(&["src/bake/fog_resample.rs", "src/lut/fog.rs"])
    );
    println!(
        "cargo:rustc-env=SKY_FORECAST_SOURCE={}",
        source_hash(&["src/bake/forecast.rs", "src/bake/fog.rs", "src/bake/ms_grid.rs"])
    );
    let fds = protox::compile([proto], ["proto"])?;
    tonic_prost_build::configure().build_client(true).build_server(true).compile_fds(fds)?;
    Ok(())
}
