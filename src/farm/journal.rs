//! The coordinator's journal: every accepted column is appended to a file
//! next to the output, flushed and synced, so `sky render --resume` after a
//! crash or Ctrl-C continues where it stopped and renders nothing twice.
//!
//! Format: a text line `sky-journal 1`, a JSON header line (job hash and
//! image size), then records `kind (u8) | column (u32 LE) | length (u32 LE)
//! | payload | BLAKE3(kind, column, payload)`. Kind 1 carries one column as
//! an encoded `Tile`; kind 2 retracts a column (its worker was caught
//! sending a wrong result). A torn last record, from a crash mid-write,
//! fails its checksum and is cut off when the journal is reopened.

use super::proto;
use prost::Message;
use std::collections::BTreeMap;
use std::fs::{File, OpenOptions};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

const MAGIC: &str = "sky-journal 1\n";
const KIND_COLUMN: u8 = 1;
const KIND_RETRACT: u8 = 2;

#[derive(Debug, thiserror::Error)]
pub enum JournalError {
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("{path}: not a sky journal")]
    NotJournal { path: PathBuf },
    #[error("{path}: the journal is for another job (its atmosphere, settings or build differ); delete it or render without --resume")]
    OtherJob { path: PathBuf },
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Header {
    pub job_hash: String,
    pub width: u32,
    pub height: u32,
}

/// An open journal, appending.
pub struct Journal {
    path: PathBuf,
    file: File,
}

/// The journal's path for an output file: `OUT.exr.journal`.
pub fn path_for(out: &Path) -> PathBuf {
    let mut s = out.as_os_str().to_owned();
    s.push(".journal");
    PathBuf::from(s)
}

impl Journal {
    /// Starts a new journal (replacing any old one).
    pub fn create(path: &Path, header: &Header) -> Result<Journal, JournalError> {
        let io = |source| JournalError::Io { path: path.to_path_buf(), source };
        let mut file = File::create(path).map_err(io)?;
        let text = format!("{MAGIC}{}\n", serde_json::to_string(header).expect("header serialises"));
        file.write_all(text.as_bytes()).map_err(io)?;
        file.sync_all().map_err(io)?;
        Ok(Journal { path: path.to_path_buf(), file })
    }

    /// Reopens a journal for `header`'s job: the columns it holds (each as
    /// a one-column tile), with a torn tail cut off.
    pub fn resume(path: &Path, header: &Header) -> Result<(Journal, BTreeMap<u32, proto::Tile>), JournalError> {
        let io = |source| JournalError::Io { path: path.to_path_buf(), source };
        let mut file = OpenOptions::new().read(true).write(true).open(path).map_err(io)?;
        let mut bytes = Vec::new();
        file.read_to_end(&mut bytes).map_err(io)?;
        let not = || JournalError::NotJournal { path: path.to_path_buf() };
        if !bytes.starts_with(MAGIC.as_bytes()) {
            return Err(not());
        }
        let rest = &bytes[MAGIC.len()..];
        let nl = rest.iter().position(|&b| b == b'\n').ok_or_else(not)?;
        let theirs: Header = serde_json::from_slice(&rest[..nl]).map_err(|_| not())?;
        if &theirs != header {
            return Err(JournalError::OtherJob { path: path.to_path_buf() });
        }
        let mut at = MAGIC.len() + nl + 1;
        let mut columns = BTreeMap::new();
        while let Some((kind, column, payload, next)) = record(&bytes, at) {
            match kind {
                KIND_COLUMN => match proto::Tile::decode(payload) {
                    Ok(t) if t.first_column == column && t.columns == 1 => {
                        columns.insert(column, t);
                    }
                    _ => break,
                },
                KIND_RETRACT => {
                    columns.remove(&column);
                }
                _ => break,
            }
            at = next;
        }
        // Cut off anything after the last whole record.
        file.set_len(at as u64).map_err(io)?;
        file.seek(SeekFrom::End(0)).map_err(io)?;
        file.sync_all().map_err(io)?;
        Ok((Journal { path: path.to_path_buf(), file }, columns))
    }

    /// Appends one accepted column (a one-column tile) and syncs.
    pub fn append_column(&mut self, tile: &proto::Tile) -> Result<(), JournalError> {
        self.append_columns(std::slice::from_ref(tile))
    }

    /// Appends accepted columns (one-column tiles) and syncs once.
    pub fn append_columns(&mut self, tiles: &[proto::Tile]) -> Result<(), JournalError> {
        if tiles.is_empty() {
            return Ok(());
        }
        let mut buf = Vec::new();
        for t in tiles {
            record_bytes(&mut buf, KIND_COLUMN, t.first_column, &t.encode_to_vec());
        }
        self.write_synced(&buf)
    }

    /// Records that a column must be rendered again.
    pub fn retract(&mut self, column: u32) -> Result<(), JournalError> {
        self.append(KIND_RETRACT, column, &[])
    }

    fn append(&mut self, kind: u8, column: u32, payload: &[u8]) -> Result<(), JournalError> {
        let mut rec = Vec::with_capacity(payload.len() + 41);
        record_bytes(&mut rec, kind, column, payload);
        self.write_synced(&rec)
    }

    fn write_synced(&mut self, bytes: &[u8]) -> Result<(), JournalError> {
        let io = |source| JournalError::Io { path: self.path.clone(), source };
        self.file.write_all(bytes).map_err(io)?;
        self.file.flush().map_err(io)?;
        self.file.sync_data().map_err(io)
    }

    pub fn path(&self) -> &Path {
        &self.path
    }
}

fn record_bytes(out: &mut Vec<u8>, kind: u8, column: u32, payload: &[u8]) {
    out.push(kind);
    out.extend_from_slice(&column.to_le_bytes());
    out.extend_from_slice(&(payload.len() as u32).to_le_bytes());
    out.extend_from_slice(payload);
    out.extend_from_slice(checksum(kind, column, payload).as_bytes());
}

fn checksum(kind: u8, column: u32, payload: &[u8]) -> blake3::Hash {
    let mut h = blake3::Hasher::new();
    h.update(&[kind]);
    h.update(&column.to_le_bytes());
    h.update(payload);
    h.finalize()
}

/// The record at `at`, if whole and intact: (kind, column, payload, next).
fn record(bytes: &[u8], at: usize) -> Option<(u8, u32, &[u8], usize)> {
    let head = bytes.get(at..at + 9)?;
    let kind = head[0];
    let column = u32::from_le_bytes(head[1..5].try_into().ok()?);
    let len = u32::from_le_bytes(head[5..9].try_into().ok()?) as usize;
    let payload = bytes.get(at + 9..at + 9 + len)?;
    let sum = bytes.get(at + 9 + len..at + 9 + len + 32)?;
    (checksum(kind, column, payload).as_bytes() == sum).then_some((kind, column, payload, at + 9 + len + 32))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tile(c: u32) -> proto::Tile {
        proto::Tile {
            job_hash: "h".into(),
            task_id: 1,
            first_column: c,
            columns: 1,
            height: 1,
            spectral_lines: 0,
            values: vec![c as f64; 9],
            samples: vec![4],
            paths_cut: vec![0],
        }
    }

    #[test]
    fn resume_keeps_whole_records_and_cuts_a_torn_tail() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.exr.journal");
        let h = Header { job_hash: "h".into(), width: 4, height: 1 };
        let mut j = Journal::create(&p, &h).unwrap();
        j.append_column(&tile(0)).unwrap();
        j.append_column(&tile(2)).unwrap();
        j.append_column(&tile(3)).unwrap();
        j.retract(3).unwrap();
        j.append_column(&tile(1)).unwrap();
        drop(j);
        // Tear the last record.
        let len = std::fs::metadata(&p).unwrap().len();
        OpenOptions::new().write(true).open(&p).unwrap().set_len(len - 5).unwrap();
        let (mut j, cols) = Journal::resume(&p, &h).unwrap();
        assert_eq!(cols.keys().copied().collect::<Vec<_>>(), vec![0, 2]);
        j.append_column(&tile(1)).unwrap();
        drop(j);
        let (_, cols) = Journal::resume(&p, &h).unwrap();
        assert_eq!(cols.keys().copied().collect::<Vec<_>>(), vec![0, 1, 2]);
        assert_eq!(cols[&2], tile(2));
        let other = Header { job_hash: "other".into(), ..h };
        assert!(matches!(Journal::resume(&p, &other), Err(JournalError::OtherJob { .. })));
    }
}
