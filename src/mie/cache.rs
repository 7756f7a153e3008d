//! On-disk cache of size-averaged Mie optics, keyed by a BLAKE3 hash of
//! everything the result depends on (algorithm version, refractive index,
//! mode, wavelength, angle grid). Entries are JSON files written to a
//! temporary file and renamed, so a crash never leaves a torn entry; an
//! unreadable entry is recomputed and replaced.

use super::lognormal::{bulk_optics, BulkOptics, LogNormal};
use num_complex::Complex64 as C64;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// Bump when the integration or solver changes results.
const ALGORITHM_VERSION: &str = "sky-mie-3";

/// A cache directory (or none: always compute).
#[derive(Debug, Default)]
pub struct MieCache {
    dir: Option<PathBuf>,
    pub hits: AtomicUsize,
    pub misses: AtomicUsize,
}

impl MieCache {
    /// A cache in `dir/mie`.
    pub fn new(dir: Option<PathBuf>) -> MieCache {
        MieCache { dir: dir.map(|d| d.join("mie")), ..Default::default() }
    }

    /// The default location: `$SKY_CACHE_DIR`, else the user cache directory
    /// (`~/.cache/sky` on Linux). `SKY_CACHE_DIR=off` disables caching.
    pub fn from_env() -> MieCache {
        match std::env::var_os("SKY_CACHE_DIR") {
            Some(v) if v == "off" => MieCache::new(None),
            Some(v) => MieCache::new(Some(PathBuf::from(v))),
            None => MieCache::new(dirs::cache_dir().map(|d| d.join("sky"))),
        }
    }

    /// The cache the test suites share: one folder in the system's
    /// temporary directory per renderer source ([`crate::RENDER_SOURCE`],
    /// which hashes `src/mie` among the rest), so a changed Mie or column
    /// code starts from an empty one. The droplets' optics take about two
    /// core-minutes to compute and the aerosols' one; without it every
    /// test that loads a cloudy or hazed atmosphere paid that again.
    #[doc(hidden)]
    pub fn shared_by_tests() -> MieCache {
        MieCache::new(Some(Self::test_dir()))
    }

    /// The folder of [`MieCache::shared_by_tests`], for `SKY_CACHE_DIR` of
    /// the command lines the tests run.
    #[doc(hidden)]
    pub fn test_dir() -> PathBuf {
        std::env::temp_dir().join(format!("sky-test-cache-{}", crate::RENDER_SOURCE))
    }

    pub fn dir(&self) -> Option<&Path> {
        self.dir.as_deref()
    }

    fn key(m: C64, mode: &LogNormal, wavelength_nm: f64, angles_deg: &[f64]) -> String {
        let mut h = blake3::Hasher::new();
        h.update(ALGORITHM_VERSION.as_bytes());
        for v in
            [m.re, m.im.abs(), mode.median_radius_um, mode.sigma, mode.min_radius_um, mode.max_radius_um, wavelength_nm]
        {
            h.update(&v.to_le_bytes());
        }
        h.update(&(angles_deg.len() as u64).to_le_bytes());
        for a in angles_deg {
            h.update(&a.to_le_bytes());
        }
        h.finalize().to_hex().to_string()
    }

    /// Cached [`bulk_optics`].
    pub fn bulk_optics(&self, m: C64, mode: &LogNormal, wavelength_nm: f64, angles_deg: &[f64]) -> BulkOptics {
        let Some(dir) = &self.dir else {
            self.misses.fetch_add(1, Ordering::Relaxed);
            return bulk_optics(m, mode, wavelength_nm, angles_deg);
        };
        let path = dir.join(format!("{}.json", Self::key(m, mode, wavelength_nm, angles_deg)));
        if let Ok(bytes) = std::fs::read(&path) {
            if let Ok(b) = serde_json::from_slice::<BulkOptics>(&bytes) {
                self.hits.fetch_add(1, Ordering::Relaxed);
                return b;
            }
        }
        self.misses.fetch_add(1, Ordering::Relaxed);
        let b = bulk_optics(m, mode, wavelength_nm, angles_deg);
        // A cache that cannot be written is not an error: the result stands.
        let _ = write_atomic(&path, &serde_json::to_vec(&b).expect("serialisable"));
        b
    }
}

/// Writes `bytes` to `path` through a temporary file in the same directory
/// and a rename ([`crate::atomic::write_atomically`]), creating the
/// directory if needed.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    std::fs::create_dir_all(path.parent().unwrap_or(Path::new(".")))?;
    crate::atomic::write_atomically(path, bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn second_lookup_hits_and_is_identical() {
        let dir = tempfile::tempdir().unwrap();
        let cache = MieCache::new(Some(dir.path().to_path_buf()));
        let m = C64::new(1.5, 0.001);
        let mode = LogNormal::new(0.2, 0.4);
        let a = cache.bulk_optics(m, &mode, 500.0, &[0.0, 90.0]);
        let b = cache.bulk_optics(m, &mode, 500.0, &[0.0, 90.0]);
        assert_eq!(a, b);
        assert_eq!(cache.hits.load(Ordering::Relaxed), 1);
        assert_eq!(cache.misses.load(Ordering::Relaxed), 1);
        // A corrupt entry is recomputed.
        for e in std::fs::read_dir(dir.path().join("mie")).unwrap() {
            std::fs::write(e.unwrap().path(), b"{garbage").unwrap();
        }
        let c = cache.bulk_optics(m, &mode, 500.0, &[0.0, 90.0]);
        assert_eq!(a, c);
        assert_eq!(cache.misses.load(Ordering::Relaxed), 2);
    }
}
