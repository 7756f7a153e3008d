//! `sky lut check`: a bake's files against the sizes and SHA-256 digests
//! its manifest records (`sky::lut::integrity`), and nothing else: for a
//! build pipeline's step between the bake and the engine's import.

use super::EXIT_INVALID;
use anyhow::Result;
use sky::lut::decode::read_manifest;
use sky::lut::integrity::{self, Checked};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(clap::Args, Debug)]
pub struct CheckArgs {
    /// The bake's manifest.json
    pub manifest: PathBuf,
    /// One JSON object on stdout: {"manifest", "intact", "files": [{"file", "bytes", "sha256"}], "error"}
    #[arg(long)]
    pub json: bool,
}

/// `sky lut check` (see its help): exit 0 when the manifest and every file
/// it names are as it records them, 1 otherwise (the first damage named).
pub fn run(a: CheckArgs) -> Result<ExitCode> {
    let outcome = read_manifest(&a.manifest).map_err(|e| e.to_string()).and_then(|(text, manifest)| {
        match integrity::check(&a.manifest, &text, &manifest) {
            Ok(Checked::Intact(files)) => Ok(files),
            Ok(Checked::Unsealed) => Err(format!(
                "{}: records no digests (a bake made before sky recorded them): nothing to check against; bake it again",
                a.manifest.display()
            )),
            Err(damage) => Err(damage.to_string()),
        }
    });
    if a.json {
        let (files, error) = match &outcome {
            Ok(files) => (files.clone(), None),
            Err(e) => (Vec::new(), Some(e.clone())),
        };
        let files: Vec<_> =
            files.iter().map(|f| serde_json::json!({ "file": f.file, "bytes": f.bytes, "sha256": f.sha256 })).collect();
        outln!(
            "{}",
            serde_json::json!({ "manifest": a.manifest, "intact": error.is_none(), "files": files, "error": error })
        );
    }
    match outcome {
        Ok(files) => {
            if !a.json {
                for f in &files {
                    outln!("{}  {}  {} bytes", f.sha256, f.file, f.bytes);
                }
            }
            let total: u64 = files.iter().map(|f| f.bytes).sum();
            eprintln!(
                "sky lut check: {}: intact (the manifest and {} files, {total} bytes, as it records them)",
                a.manifest.display(),
                files.len()
            );
            Ok(ExitCode::SUCCESS)
        }
        Err(e) => {
            eprintln!("sky lut check: {e}");
            Ok(ExitCode::from(EXIT_INVALID))
        }
    }
}
