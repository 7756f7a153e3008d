//! The farm file (`--farm farm.toml`): the workers and the farm's policy.
//! See farm/farm.toml for an annotated example.

use serde::Deserialize;
use std::path::{Path, PathBuf};

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FarmFile {
    /// File holding the shared token (relative to the farm file).
    pub token_file: Option<PathBuf>,
    /// Seconds a worker may stay silent before its task is re-queued.
    pub lease_s: Option<f64>,
    /// Seconds of work per task, by each worker's measured speed.
    pub task_seconds: Option<f64>,
    /// Fraction of columns rendered twice on different workers.
    pub verify_fraction: Option<f64>,
    pub tls: Option<Tls>,
    #[serde(rename = "worker", default)]
    pub workers: Vec<WorkerEntry>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Tls {
    /// CA certificate (PEM) that signed the workers' certificates.
    pub ca: PathBuf,
    /// The name the workers' certificates carry, if not their host names.
    pub domain: Option<String>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorkerEntry {
    pub name: Option<String>,
    /// HOST:PORT, or http:// / https:// URI.
    pub address: String,
}

#[derive(Debug, thiserror::Error)]
#[error("{path}: {message}")]
pub struct FarmFileError {
    pub path: PathBuf,
    pub message: String,
}

impl FarmFile {
    /// Reads and checks a farm file; relative paths in it are made relative
    /// to its directory.
    pub fn load(path: &Path) -> Result<FarmFile, FarmFileError> {
        let err = |message: String| FarmFileError { path: path.to_path_buf(), message };
        let text = std::fs::read_to_string(path).map_err(|e| err(format!("cannot read: {e}")))?;
        let mut f: FarmFile = toml::from_str(&text).map_err(|e| {
            let line = e.span().map(|s| text[..s.start.min(text.len())].bytes().filter(|&b| b == b'\n').count() + 1);
            match line {
                Some(l) => {
                    FarmFileError { path: path.to_path_buf(), message: format!("line {l}: {}", e.message().trim()) }
                }
                None => err(e.message().trim().to_string()),
            }
        })?;
        if f.workers.is_empty() {
            return Err(err("no [[worker]] entries".into()));
        }
        if let Some(v) = f.verify_fraction {
            if !(0.0..=1.0).contains(&v) {
                return Err(err(format!("verify_fraction must be between 0 and 1, found {v}")));
            }
        }
        for (k, v) in [("lease_s", f.lease_s), ("task_seconds", f.task_seconds)] {
            if let Some(v) = v {
                if !(v > 0.0 && v.is_finite()) {
                    return Err(err(format!("{k} must be a positive number of seconds, found {v}")));
                }
            }
        }
        let dir = path.parent().unwrap_or(Path::new(""));
        if let Some(t) = &mut f.token_file {
            *t = dir.join(&*t);
        }
        if let Some(tls) = &mut f.tls {
            tls.ca = dir.join(&tls.ca);
        }
        Ok(f)
    }
}

/// A worker address as a URI: HOST:PORT becomes http://HOST:PORT (or
/// https:// when TLS is on).
pub fn worker_uri(address: &str, tls: bool) -> String {
    if address.starts_with("http://") || address.starts_with("https://") {
        address.to_string()
    } else if tls {
        format!("https://{address}")
    } else {
        format!("http://{address}")
    }
}

/// Reads a token file: its first line, trimmed; an empty token is an error.
pub fn read_token(path: &Path) -> Result<String, String> {
    let text =
        std::fs::read_to_string(path).map_err(|e| format!("{}: cannot read the farm token: {e}", path.display()))?;
    let t = text.lines().next().unwrap_or("").trim().to_string();
    if t.is_empty() {
        return Err(format!("{}: the farm token file is empty", path.display()));
    }
    Ok(t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn farm_files_parse_and_errors_name_the_line() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("farm.toml");
        std::fs::write(
            &p,
            "token_file = \"t\"\nverify_fraction = 0.1\n[[worker]]\nname = \"a\"\naddress = \"10.0.0.1:7878\"\n",
        )
        .unwrap();
        let f = FarmFile::load(&p).unwrap();
        assert_eq!(f.workers.len(), 1);
        assert_eq!(f.token_file.unwrap(), dir.path().join("t"));
        std::fs::write(&p, "[[worker]]\naddress = \"a:1\"\nport = 3\n").unwrap();
        let e = FarmFile::load(&p).unwrap_err().to_string();
        assert!(e.contains("line 3") && e.contains("port"), "{e}");
        std::fs::write(&p, "verify_fraction = 2.0\n[[worker]]\naddress = \"a:1\"\n").unwrap();
        assert!(FarmFile::load(&p).unwrap_err().to_string().contains("verify_fraction"));
        assert_eq!(worker_uri("h:1", false), "http://h:1");
        assert_eq!(worker_uri("h:1", true), "https://h:1");
    }
}
