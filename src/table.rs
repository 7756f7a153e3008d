//! Tabulated data files: the CSV format of `atmospheres/data/`.
//!
//! A file starts with `# ` comment lines (title, source, units, licence, how to
//! regenerate it), then one header line naming the columns, then rows of
//! numbers. Errors carry the file and the 1-based line.

use std::path::{Path, PathBuf};

/// A problem reading a data table, located at a file and line.
#[derive(Debug, thiserror::Error)]
#[error("{}{}: {message}", path.display(), line.map(|l| format!(":{l}")).unwrap_or_default())]
pub struct TableError {
    pub path: PathBuf,
    pub line: Option<usize>,
    pub message: String,
}

/// A numeric table, stored column by column.
#[derive(Debug, Clone)]
pub struct Table {
    pub path: PathBuf,
    pub columns: Vec<String>,
    pub data: Vec<Vec<f64>>,
}

impl Table {
    /// Reads a table from disk.
    pub fn read(path: &Path) -> Result<Table, TableError> {
        let text = std::fs::read_to_string(path).map_err(|e| TableError {
            path: path.to_path_buf(),
            line: None,
            message: format!("cannot read data file: {e}"),
        })?;
        Table::parse(path, &text)
    }

    /// Parses table text; `path` only names the source in errors.
    pub fn parse(path: &Path, text: &str) -> Result<Table, TableError> {
        let err = |line: usize, message: String| TableError { path: path.to_path_buf(), line: Some(line), message };
        let mut columns: Option<Vec<String>> = None;
        let mut data: Vec<Vec<f64>> = Vec::new();
        for (i, raw) in text.lines().enumerate() {
            let line_no = i + 1;
            let line = raw.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            match &columns {
                None => {
                    let names: Vec<String> = line.split(',').map(|s| s.trim().to_string()).collect();
                    if names.iter().any(|n| n.is_empty()) {
                        return Err(err(line_no, "header has an empty column name".into()));
                    }
                    data = vec![Vec::new(); names.len()];
                    columns = Some(names);
                }
                Some(names) => {
                    let fields: Vec<&str> = line.split(',').map(str::trim).collect();
                    if fields.len() != names.len() {
                        return Err(err(
                            line_no,
                            format!("expected {} values ({}), found {}", names.len(), names.join(","), fields.len()),
                        ));
                    }
                    for (c, f) in fields.iter().enumerate() {
                        let v: f64 = f
                            .parse()
                            .map_err(|_| err(line_no, format!("`{f}` is not a number (column {})", names[c])))?;
                        if !v.is_finite() {
                            return Err(err(line_no, format!("`{f}` is not finite (column {})", names[c])));
                        }
                        data[c].push(v);
                    }
                }
            }
        }
        let columns = columns.ok_or_else(|| TableError {
            path: path.to_path_buf(),
            line: None,
            message: "no header line and no data".into(),
        })?;
        if data[0].is_empty() {
            return Err(TableError { path: path.to_path_buf(), line: None, message: "table has no rows".into() });
        }
        Ok(Table { path: path.to_path_buf(), columns, data })
    }

    /// The column with this name.
    pub fn column(&self, name: &str) -> Result<&[f64], TableError> {
        self.columns.iter().position(|c| c == name).map(|i| self.data[i].as_slice()).ok_or_else(|| TableError {
            path: self.path.clone(),
            line: None,
            message: format!("no column `{name}` (columns: {})", self.columns.join(",")),
        })
    }

    /// Checks that the first column strictly increases.
    pub fn require_increasing(&self) -> Result<(), TableError> {
        let x = &self.data[0];
        for i in 1..x.len() {
            if x[i] <= x[i - 1] {
                return Err(TableError {
                    path: self.path.clone(),
                    line: None,
                    message: format!(
                        "{} must strictly increase (row {}: {} after {})",
                        self.columns[0],
                        i + 1,
                        x[i],
                        x[i - 1]
                    ),
                });
            }
        }
        Ok(())
    }

    /// A piecewise-linear function of the first column, using column `name`.
    pub fn function(&self, name: &str) -> Result<Tabulated, TableError> {
        self.require_increasing()?;
        Ok(Tabulated { x: self.data[0].clone(), y: self.column(name)?.to_vec() })
    }
}

/// A piecewise-linear function y(x) on strictly increasing abscissae,
/// held constant beyond its ends.
#[derive(Debug, Clone, PartialEq)]
pub struct Tabulated {
    pub x: Vec<f64>,
    pub y: Vec<f64>,
}

impl Tabulated {
    pub fn new(x: Vec<f64>, y: Vec<f64>) -> Tabulated {
        assert_eq!(x.len(), y.len());
        assert!(!x.is_empty());
        Tabulated { x, y }
    }

    pub fn constant(v: f64) -> Tabulated {
        Tabulated { x: vec![0.0], y: vec![v] }
    }

    /// Linear interpolation, clamped to the end values outside the range.
    pub fn eval(&self, x: f64) -> f64 {
        interp_linear(&self.x, &self.y, x)
    }

    pub fn range(&self) -> (f64, f64) {
        (self.x[0], *self.x.last().unwrap())
    }
}

/// Linear interpolation in a sorted table, clamped at both ends.
pub fn interp_linear(xs: &[f64], ys: &[f64], x: f64) -> f64 {
    let n = xs.len();
    if n == 1 || x <= xs[0] {
        return ys[0];
    }
    if x >= xs[n - 1] {
        return ys[n - 1];
    }
    let i = xs.partition_point(|&v| v <= x) - 1;
    let t = (x - xs[i]) / (xs[i + 1] - xs[i]);
    ys[i] + t * (ys[i + 1] - ys[i])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_comments_header_rows() {
        let t =
            Table::parse(Path::new("t.csv"), "# title\n# units: nm\nwavelength_nm,n,k\n400,1.33,1e-9\n500,1.34,2e-9\n")
                .unwrap();
        assert_eq!(t.columns, vec!["wavelength_nm", "n", "k"]);
        assert_eq!(t.column("k").unwrap(), &[1e-9, 2e-9]);
        let f = t.function("n").unwrap();
        assert!((f.eval(450.0) - 1.335).abs() < 1e-12);
        assert_eq!(f.eval(0.0), 1.33);
        assert_eq!(f.eval(900.0), 1.34);
    }

    #[test]
    fn errors_name_the_line() {
        let e = Table::parse(Path::new("t.csv"), "# x\na,b\n1,2\n3\n").unwrap_err();
        assert_eq!(e.line, Some(4));
        assert!(e.to_string().starts_with("t.csv:4:"), "{e}");
        let e = Table::parse(Path::new("t.csv"), "a,b\n1,zz\n").unwrap_err();
        assert!(e.to_string().contains("`zz` is not a number"), "{e}");
        let t = Table::parse(Path::new("t.csv"), "a,b\n2,1\n1,2\n").unwrap();
        assert!(t.function("b").is_err());
    }
}
