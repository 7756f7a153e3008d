//! The content-addressed cache of rendered slices. A slice's key is the
//! BLAKE3 of everything its pixels depend on: the atmosphere's content hash
//! (its file and every data file it reads), the spectral settings, the view
//! (camera and mapping, size, sun, observer, samples, seed), the quality and
//! the build. A re-run with nothing changed finds every slice; a changed
//! atmosphere misses only its own; a bake killed mid-way finds the slices it
//! finished (each is written whole, to a temporary file that is renamed).

use crate::render::{SpectralSettings, View};
use std::path::{Path, PathBuf};

/// One rendered slice: CIE XYZ per texel (row-major, v rows top to bottom,
/// u columns left to right), its standard error, and what it cost.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RenderedSlice {
    pub width: usize,
    pub height: usize,
    pub sun_zenith_deg: f64,
    pub xyz: Vec<[f64; 3]>,
    pub xyz_stderr: Vec<[f64; 3]>,
    pub samples: Vec<u32>,
    /// Seconds of wall time times the threads that rendered it.
    pub core_seconds: f64,
}

impl RenderedSlice {
    pub fn mean_samples(&self) -> f64 {
        self.samples.iter().map(|&s| s as f64).sum::<f64>() / self.samples.len().max(1) as f64
    }
}

/// The cache key of a slice.
pub fn slice_key(atmosphere_hash: &str, spectral: &SpectralSettings, view: &View, quality: &str) -> String {
    let key = serde_json::json!({
        "atmosphere": atmosphere_hash,
        "spectral": spectral,
        "view": view,
        "quality": quality,
        "build": crate::VERSION,
        "render_source": crate::RENDER_SOURCE,
        "format": FORMAT,
    });
    blake3::hash(key.to_string().as_bytes()).to_hex().to_string()
}

/// Bumped when [`RenderedSlice`]'s encoding changes.
const FORMAT: u32 = 1;
const MAGIC: &[u8; 8] = b"SKYSLC01";

#[derive(Debug, thiserror::Error)]
#[error("slice cache {}: {source}", path.display())]
pub struct CacheError {
    pub path: PathBuf,
    pub source: std::io::Error,
}

/// A folder of slices by key.
#[derive(Debug, Clone)]
pub struct SliceCache {
    dir: PathBuf,
}

impl SliceCache {
    pub fn open(dir: &Path) -> Result<SliceCache, CacheError> {
        std::fs::create_dir_all(dir).map_err(|source| CacheError { path: dir.to_path_buf(), source })?;
        Ok(SliceCache { dir: dir.to_path_buf() })
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    fn path(&self, key: &str) -> PathBuf {
        self.dir.join(format!("{key}.slice"))
    }

    /// The slice of `key`, if the cache holds a whole, readable one (a file
    /// that does not decode is a miss, to be rendered again).
    pub fn get(&self, key: &str) -> Option<RenderedSlice> {
        let bytes = std::fs::read(self.path(key)).ok()?;
        let body = bytes.strip_prefix(MAGIC.as_slice())?;
        let s: RenderedSlice = postcard::from_bytes(body).ok()?;
        (s.xyz.len() == s.width * s.height && s.xyz_stderr.len() == s.xyz.len() && s.samples.len() == s.xyz.len())
            .then_some(s)
    }

    /// Stores a slice under `key`: written to a temporary file, then renamed.
    pub fn put(&self, key: &str, slice: &RenderedSlice) -> Result<(), CacheError> {
        let path = self.path(key);
        let mut bytes = MAGIC.to_vec();
        bytes.extend(postcard::to_allocvec(slice).expect("a slice always encodes"));
        crate::mie::cache::write_atomic(&path, &bytes).map_err(|source| CacheError { path, source })
    }

    fn lighting_path(&self, key: &str) -> PathBuf {
        self.dir.join(format!("{key}.lighting"))
    }

    /// A basis sky's lighting (see [`super::lighting`]), if the cache holds
    /// a readable one.
    pub fn get_lighting(&self, key: &str) -> Option<super::lighting::SkyLighting> {
        let bytes = std::fs::read(self.lighting_path(key)).ok()?;
        postcard::from_bytes(bytes.strip_prefix(LIGHTING_MAGIC.as_slice())?).ok()
    }

    /// Stores a basis sky's lighting under `key` (temporary file, rename).
    pub fn put_lighting(&self, key: &str, lighting: &super::lighting::SkyLighting) -> Result<(), CacheError> {
        let path = self.lighting_path(key);
        let mut bytes = LIGHTING_MAGIC.to_vec();
        bytes.extend(postcard::to_allocvec(lighting).expect("lighting always encodes"));
        crate::mie::cache::write_atomic(&path, &bytes).map_err(|source| CacheError { path, source })
    }
}

const LIGHTING_MAGIC: &[u8; 8] = b"SKYLGT01";
const VALUE_MAGIC: &[u8; 8] = b"SKYVAL01";

impl SliceCache {
    fn value_path(&self, key: &str, kind: &str) -> PathBuf {
        self.dir.join(format!("{key}.{kind}"))
    }

    /// A value of some other kind (`kind` names the file's extension: a
    /// sky's fog falloff and Attenuation table, `bake::fog`), if the cache
    /// holds a readable one.
    pub fn get_value<T: serde::de::DeserializeOwned>(&self, key: &str, kind: &str) -> Option<T> {
        let bytes = std::fs::read(self.value_path(key, kind)).ok()?;
        postcard::from_bytes(bytes.strip_prefix(VALUE_MAGIC.as_slice())?).ok()
    }

    /// Stores a value under `key` (temporary file, rename).
    pub fn put_value<T: serde::Serialize>(&self, key: &str, kind: &str, value: &T) -> Result<(), CacheError> {
        let path = self.value_path(key, kind);
        let mut bytes = VALUE_MAGIC.to_vec();
        bytes.extend(postcard::to_allocvec(value).expect("cached values always encode"));
        crate::mie::cache::write_atomic(&path, &bytes).map_err(|source| CacheError { path, source })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn slice() -> RenderedSlice {
        RenderedSlice {
            width: 2,
            height: 1,
            sun_zenith_deg: 30.0,
            xyz: vec![[1.0, 2.0, 3.0], [0.1, 0.2, 0.3]],
            xyz_stderr: vec![[0.0; 3]; 2],
            samples: vec![8, 8],
            core_seconds: 0.5,
        }
    }

    /// The key names the renderer's source (build.rs), not only the version.
    #[test]
    fn the_key_names_the_renderers_source() {
        assert!(
            crate::RENDER_SOURCE.len() == 32 && crate::RENDER_SOURCE.bytes().all(|b| b.is_ascii_hexdigit()),
            "{}",
            crate::RENDER_SOURCE
        );
        assert!(crate::session::farm::build_version().contains(&crate::RENDER_SOURCE[..12]));
    }

    #[test]
    fn slices_round_trip_and_broken_files_miss() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("cache");
        let c = SliceCache::open(&dir).unwrap();
        assert!(c.get("k").is_none());
        c.put("k", &slice()).unwrap();
        assert_eq!(c.get("k"), Some(slice()));
        // A truncated file (a bake killed while writing would leave only a
        // temporary file, but a disk can fail too) is a miss, not an error.
        let full = std::fs::read(dir.join("k.slice")).unwrap();
        std::fs::write(dir.join("k.slice"), &full[..full.len() / 2]).unwrap();
        assert!(c.get("k").is_none());
    }
}
