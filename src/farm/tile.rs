//! Rendered columns on the wire and the checks a result passes before the
//! coordinator accepts it: the job hash, the task's columns, the tile's
//! size, and finite, non-negative values (stderr and radiance).

use super::proto;
use crate::render::PixelResult;

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum TileError {
    #[error("tile is for job {theirs}, the task's job is {ours}")]
    Job { theirs: String, ours: String },
    #[error("tile covers columns {first}+{columns} of task {task}, the task asked for {want_first}+{want_columns} of task {want_task}")]
    Columns { first: u32, columns: u32, task: u64, want_first: u32, want_columns: u32, want_task: u64 },
    #[error("tile is {got} values, {got_samples} sample counts and {got_cut} cut-path counts, expected {want}, {want_samples} and {want_samples} ({columns} columns x {height} rows, {lines} spectral lines)")]
    Size {
        got: usize,
        got_samples: usize,
        got_cut: usize,
        want: usize,
        want_samples: usize,
        columns: u32,
        height: u32,
        lines: u32,
    },
    #[error("tile value {index} is {value}: not a finite, non-negative radiance")]
    Value { index: usize, value: f64 },
    #[error("tile reports {samples} samples for a pixel, more than the job's {spp} spp")]
    Samples { samples: u32, spp: u32 },
}

/// Values per pixel: X Y Z, direct X Y Z, stderr X Y Z, the spectral lines
/// and their stderr.
pub fn values_per_pixel(lines: usize) -> usize {
    9 + 2 * lines
}

/// Packs columns (each top to bottom) into a tile.
pub fn encode(
    job_hash: &str,
    task_id: u64,
    first_column: u32,
    height: u32,
    lines: usize,
    columns: &[Vec<PixelResult>],
) -> proto::Tile {
    let mut values = Vec::with_capacity(columns.len() * height as usize * values_per_pixel(lines));
    let mut samples = Vec::with_capacity(columns.len() * height as usize);
    let mut paths_cut = Vec::with_capacity(columns.len() * height as usize);
    for col in columns {
        for p in col {
            values.extend_from_slice(&p.xyz);
            values.extend_from_slice(&p.xyz_direct);
            values.extend_from_slice(&p.xyz_stderr);
            values.extend_from_slice(&p.spectral);
            values.extend_from_slice(&p.spectral_stderr);
            samples.push(p.samples);
            paths_cut.push(p.paths_cut);
        }
    }
    proto::Tile {
        job_hash: job_hash.to_string(),
        task_id,
        first_column,
        columns: columns.len() as u32,
        height,
        spectral_lines: lines as u32,
        values,
        samples,
        paths_cut,
    }
}

/// What the coordinator expects of a tile.
#[derive(Debug, Clone)]
pub struct Expect<'a> {
    pub job_hash: &'a str,
    pub task_id: u64,
    pub first_column: u32,
    pub columns: u32,
    pub height: u32,
    pub lines: u32,
    pub spp: u32,
}

/// Checks a tile and unpacks it into columns of pixels.
pub fn decode(tile: &proto::Tile, want: &Expect) -> Result<Vec<Vec<PixelResult>>, TileError> {
    if tile.job_hash != want.job_hash {
        return Err(TileError::Job { theirs: tile.job_hash.clone(), ours: want.job_hash.to_string() });
    }
    if tile.first_column != want.first_column || tile.columns != want.columns || tile.task_id != want.task_id {
        return Err(TileError::Columns {
            first: tile.first_column,
            columns: tile.columns,
            task: tile.task_id,
            want_first: want.first_column,
            want_columns: want.columns,
            want_task: want.task_id,
        });
    }
    let lines = want.lines as usize;
    let per = values_per_pixel(lines);
    let pixels = want.columns as usize * want.height as usize;
    if tile.height != want.height
        || tile.spectral_lines != want.lines
        || tile.values.len() != pixels * per
        || tile.samples.len() != pixels
        || tile.paths_cut.len() != pixels
    {
        return Err(TileError::Size {
            got: tile.values.len(),
            got_samples: tile.samples.len(),
            got_cut: tile.paths_cut.len(),
            want: pixels * per,
            want_samples: pixels,
            columns: want.columns,
            height: want.height,
            lines: want.lines,
        });
    }
    if let Some((index, &value)) = tile.values.iter().enumerate().find(|(_, v)| !(v.is_finite() && **v >= 0.0)) {
        return Err(TileError::Value { index, value });
    }
    if let Some(&samples) = tile.samples.iter().find(|&&s| s > want.spp) {
        return Err(TileError::Samples { samples, spp: want.spp });
    }
    let mut out = Vec::with_capacity(want.columns as usize);
    for c in 0..want.columns as usize {
        let mut col = Vec::with_capacity(want.height as usize);
        for r in 0..want.height as usize {
            let i = c * want.height as usize + r;
            let v = &tile.values[i * per..(i + 1) * per];
            col.push(PixelResult {
                xyz: [v[0], v[1], v[2]],
                xyz_direct: [v[3], v[4], v[5]],
                xyz_stderr: [v[6], v[7], v[8]],
                spectral: v[9..9 + lines].to_vec(),
                spectral_stderr: v[9 + lines..9 + 2 * lines].to_vec(),
                samples: tile.samples[i],
                paths_cut: tile.paths_cut[i],
            });
        }
        out.push(col);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn px(v: f64) -> PixelResult {
        PixelResult {
            xyz: [v, v + 1.0, v + 2.0],
            xyz_direct: [0.0; 3],
            xyz_stderr: [0.1; 3],
            spectral: vec![v],
            spectral_stderr: vec![0.01],
            samples: 8,
            paths_cut: 0,
        }
    }

    #[test]
    fn tiles_round_trip_and_garbage_is_refused() {
        let cols = vec![vec![px(1.0), px(2.0)], vec![px(3.0), px(4.0)]];
        let t = encode("abc", 9, 4, 2, 1, &cols);
        let want = Expect { job_hash: "abc", task_id: 9, first_column: 4, columns: 2, height: 2, lines: 1, spp: 8 };
        assert_eq!(decode(&t, &want).unwrap(), cols);
        let mut bad = t.clone();
        bad.values[5] = f64::NAN;
        assert!(matches!(decode(&bad, &want), Err(TileError::Value { index: 5, .. })));
        let mut bad = t.clone();
        bad.values.pop();
        assert!(matches!(decode(&bad, &want), Err(TileError::Size { .. })));
        let mut bad = t.clone();
        bad.job_hash = "zzz".into();
        assert!(matches!(decode(&bad, &want), Err(TileError::Job { .. })));
        let mut bad = t.clone();
        bad.first_column = 5;
        assert!(matches!(decode(&bad, &want), Err(TileError::Columns { .. })));
        let mut bad = t;
        bad.samples[0] = 9;
        assert!(matches!(decode(&bad, &want), Err(TileError::Samples { .. })));
    }
}
