//! A bake's integrity: the manifest records the size and SHA-256 of every
//! file it names (`Manifest::files`) and a SHA-256 of its own text
//! (`Manifest::manifest_sha256`), and nothing reads a bake before both
//! agree with what is on disk (`check`). A truncated, altered or missing
//! file is named in the error; no number comes out of damaged data.
//!
//! The manifest's own digest is that of its text with the digest's 64 hex
//! digits written as zeros (`seal`): a change anywhere else in the text,
//! a number included, changes it. Only a writer that means to (and
//! recomputes the digest) can change a sealed manifest unseen: this guards
//! against damage (a full disk, a broken copy, a partial sync), not
//! against tampering, for which the manifest would need a signature.
//!
//! SHA-256 (FIPS 180-4) by `ring`, so a pipeline can check a file with
//! `sha256sum` against the manifest without this program.

use super::manifest::{FileEntry, Manifest};
use std::path::{Component, Path, PathBuf};

/// The manifest's digest field as `seal` finds it in the text.
const FIELD: &str = "\"manifest_sha256\": \"";

/// The digest written while the text's own digest is computed.
pub const UNSEALED: &str = "0000000000000000000000000000000000000000000000000000000000000000";

/// SHA-256 of `bytes`, lower-case hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    ring::digest::digest(&ring::digest::SHA256, bytes).as_ref().iter().map(|b| format!("{b:02x}")).collect()
}

/// The entry of file `name` (relative to `dir`) as it is on disk.
pub fn file_entry(dir: &Path, name: &str) -> std::io::Result<FileEntry> {
    let bytes = std::fs::read(dir.join(name))?;
    Ok(FileEntry { file: name.to_string(), bytes: bytes.len() as u64, sha256: sha256_hex(&bytes) })
}

/// Where the digest's hex digits start in `text`: None unless the field
/// occurs exactly once, followed by 64 characters and a quote.
fn digest_at(text: &str) -> Option<usize> {
    let mut found = text.match_indices(FIELD);
    let (at, _) = found.next()?;
    if found.next().is_some() {
        return None;
    }
    let start = at + FIELD.len();
    (text.get(start..start + 64).is_some() && text[start + 64..].starts_with('"')).then_some(start)
}

/// `text`, a manifest whose `manifest_sha256` is `UNSEALED`, with its
/// digest written in; and the digest.
pub fn seal(text: &str) -> (String, String) {
    let start = digest_at(text).expect("a manifest to seal has one digest field");
    debug_assert_eq!(&text[start..start + 64], UNSEALED);
    let digest = sha256_hex(text.as_bytes());
    (format!("{}{digest}{}", &text[..start], &text[start + 64..]), digest)
}

/// What `check` found wrong: the file (or the manifest) and why.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}: {message}", path.display())]
pub struct Damage {
    pub path: PathBuf,
    pub message: String,
}

/// How a bake stood its check.
#[derive(Debug, Clone, PartialEq)]
pub enum Checked {
    /// Sealed, and every file it names as it records.
    Intact(Vec<FileEntry>),
    /// A bake made before manifests recorded digests: nothing to check
    /// against.
    Unsealed,
}

/// Checks a bake: the manifest at `manifest_path` (its `text`, parsed as
/// `manifest`) against its own digest, then every file it names against
/// its size and digest, in order; the first damage found, named.
pub fn check(manifest_path: &Path, text: &str, manifest: &Manifest) -> Result<Checked, Damage> {
    let damage = |path: &Path, message: String| Damage { path: path.to_path_buf(), message };
    let (files, recorded) = match (&manifest.files, &manifest.manifest_sha256) {
        (None, None) => return Ok(Checked::Unsealed),
        (Some(files), Some(recorded)) => (files, recorded),
        _ => return Err(damage(manifest_path, "damaged: it records its files' digests or its own, not both".into())),
    };
    let start = digest_at(text)
        .filter(|&s| text[s..s + 64] == **recorded)
        .ok_or_else(|| damage(manifest_path, "damaged: its own SHA-256 field cannot be read".into()))?;
    let unsealed = format!("{}{UNSEALED}{}", &text[..start], &text[start + 64..]);
    let actual = sha256_hex(unsealed.as_bytes());
    if actual != *recorded {
        return Err(damage(
            manifest_path,
            format!("altered or damaged: its text's SHA-256 is {actual}, it records {recorded}"),
        ));
    }
    let dir = manifest_path.parent().unwrap_or(Path::new("."));
    for name in manifest.named_files() {
        if !files.iter().any(|f| f.file == name) {
            return Err(damage(manifest_path, format!("names {name} without its size and digest")));
        }
    }
    for f in files {
        let relative = Path::new(&f.file);
        if f.file.is_empty() || relative.components().any(|c| !matches!(c, Component::Normal(_))) {
            return Err(damage(manifest_path, format!("names {:?}, not a file beside it", f.file)));
        }
        let path = dir.join(relative);
        let bytes = std::fs::read(&path).map_err(|e| {
            let why = if e.kind() == std::io::ErrorKind::NotFound { "missing".to_string() } else { e.to_string() };
            damage(&path, format!("{why} (named by {})", manifest_path.display()))
        })?;
        if bytes.len() as u64 != f.bytes {
            let what = if (bytes.len() as u64) < f.bytes { "truncated" } else { "longer than written" };
            return Err(damage(&path, format!("{what}: {} bytes, the manifest records {}", bytes.len(), f.bytes)));
        }
        let actual = sha256_hex(&bytes);
        if actual != f.sha256 {
            return Err(damage(
                &path,
                format!("altered or damaged: SHA-256 {actual}, the manifest records {}", f.sha256),
            ));
        }
    }
    Ok(Checked::Intact(files.clone()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sha256_of_known_messages() {
        // FIPS 180-4 examples (NIST CSRC, "SHA256.pdf"): "abc" and the empty message.
        assert_eq!(sha256_hex(b"abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
        assert_eq!(sha256_hex(b""), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
    }

    #[test]
    fn a_sealed_text_checks_and_any_changed_byte_is_found() {
        let mut m = crate::lut::manifest::tests::manifest_with(Vec::new());
        m.files = Some(Vec::new());
        m.manifest_sha256 = Some(UNSEALED.into());
        let (text, _) = seal(&serde_json::to_string_pretty(&m).unwrap());
        let path = Path::new("/nowhere/manifest.json");
        let parsed: Manifest = serde_json::from_str(&text).unwrap();
        assert_eq!(check(path, &text, &parsed), Ok(Checked::Intact(Vec::new())));
        // Every byte of the text changed in turn (a digit, a letter, a
        // space): the check refuses all of those that still parse.
        let mut refused = 0;
        for at in (0..text.len()).filter(|&i| text.is_char_boundary(i) && text.is_char_boundary(i + 1)) {
            let b = text.as_bytes()[at];
            let other = match b {
                b'9' => b'0',
                b'0'..=b'8' => b + 1,
                b'x' => b'y',
                _ => b'x',
            };
            let mut bytes = text.clone().into_bytes();
            bytes[at] = other;
            let Ok(changed) = String::from_utf8(bytes) else { continue };
            let Ok(parsed) = serde_json::from_str::<Manifest>(&changed) else { continue };
            assert!(
                check(path, &changed, &parsed).is_err(),
                "byte {at} changed to {:?} passed: {:?}",
                other as char,
                &changed[at.saturating_sub(40)..at + 20]
            );
            refused += 1;
        }
        assert!(refused > 20, "only {refused} changes parsed");
    }
}
