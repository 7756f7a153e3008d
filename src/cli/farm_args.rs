//! The farm flags that `sky render` and `sky bake-luts` share, and the
//! workers and policy they name.

use super::usage;
use anyhow::{Context, Result};
use sky::farm::config;
use sky::farm::coordinator::{Options, WorkerSpec};
use std::path::PathBuf;

#[derive(clap::Args, Debug, Clone, Default)]
pub struct FarmArgs {
    /// Render on the `sky worker` daemons of this farm file (see farm/farm.toml)
    #[arg(long, value_name = "FILE", conflicts_with = "workers", help_heading = "Farm")]
    pub farm: Option<PathBuf>,
    /// Render on these workers, comma-separated HOST:PORT (or http[s]://HOST:PORT)
    #[arg(long, value_delimiter = ',', value_name = "HOST:PORT", help_heading = "Farm")]
    pub workers: Vec<String>,
    /// The farm's shared token (default: the farm file's token_file, else $SKY_FARM_TOKEN)
    #[arg(long, value_name = "FILE", help_heading = "Farm")]
    pub token_file: Option<PathBuf>,
    /// CA certificate (PEM) of the workers' TLS certificates (implies https)
    #[arg(long, value_name = "FILE", help_heading = "Farm")]
    pub tls_ca: Option<PathBuf>,
}

/// The workers and policy from --farm / --workers, or None for the
/// embedded worker.
pub fn farm_plan(a: &FarmArgs) -> Result<Option<(Vec<WorkerSpec>, Options)>> {
    let mut opts = Options::default();
    let (entries, file) = if let Some(f) = &a.farm {
        let file = config::FarmFile::load(f)?;
        (file.workers.iter().map(|w| (w.name.clone(), w.address.clone())).collect::<Vec<_>>(), Some(file))
    } else if !a.workers.is_empty() {
        (a.workers.iter().map(|w| (None, w.clone())).collect(), None)
    } else {
        return Ok(None);
    };
    if let Some(f) = &file {
        if let Some(l) = f.lease_s {
            opts.lease = std::time::Duration::from_secs_f64(l);
        }
        if let Some(t) = f.task_seconds {
            opts.task_seconds = t;
        }
        if let Some(v) = f.verify_fraction {
            opts.verify_fraction = v;
        }
    }
    let token_file = a.token_file.clone().or_else(|| file.as_ref().and_then(|f| f.token_file.clone()));
    opts.token = Some(match token_file {
        Some(p) => config::read_token(&p).map_err(anyhow::Error::msg)?,
        None => match std::env::var("SKY_FARM_TOKEN") {
            Ok(t) if !t.trim().is_empty() => t.trim().to_string(),
            _ => {
                return usage(
                    "a farm needs its token: --token-file FILE, token_file in the farm file, or SKY_FARM_TOKEN",
                )
            }
        },
    });
    let (ca, domain) = match (&a.tls_ca, file.as_ref().and_then(|f| f.tls.clone())) {
        (Some(ca), t) => (Some(ca.clone()), t.and_then(|t| t.domain)),
        (None, Some(t)) => (Some(t.ca), t.domain),
        (None, None) => (None, None),
    };
    if let Some(ca) = &ca {
        let pem = std::fs::read(ca).with_context(|| format!("--tls-ca {}", ca.display()))?;
        let mut tls =
            tonic::transport::ClientTlsConfig::new().ca_certificate(tonic::transport::Certificate::from_pem(pem));
        if let Some(d) = domain {
            tls = tls.domain_name(d);
        }
        opts.tls = Some(tls);
    }
    let workers = entries
        .into_iter()
        .map(|(name, address)| {
            let uri = config::worker_uri(&address, ca.is_some());
            WorkerSpec::Remote { name, uri }
        })
        .collect();
    Ok(Some((workers, opts)))
}
