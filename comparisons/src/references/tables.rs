//! Reading the tables a reference ships: numeric CSV with a header, and the
//! `[parameters]` of its `meta.toml`.

use crate::scenario::UsageError;
use std::path::{Path, PathBuf};

/// Read `[parameters] key` of a reference `meta.toml`.
pub fn meta_number(meta: &toml::Table, file: &Path, key: &str) -> Result<f64, UsageError> {
    meta.get("parameters")
        .and_then(|t| t.get(key))
        .and_then(|v| v.as_float().or_else(|| v.as_integer().map(|i| i as f64)))
        .ok_or_else(|| UsageError(format!("{}: no number `parameters.{key}`", file.display())))
}

/// Read and parse `<dir>/meta.toml`; returns the table and its path.
pub fn read_meta(dir: &Path) -> Result<(toml::Table, PathBuf), UsageError> {
    let path = dir.join("meta.toml");
    let text =
        std::fs::read_to_string(&path).map_err(|e| UsageError(format!("cannot read {}: {e}", path.display())))?;
    let meta = toml::from_str(&text).map_err(|e| UsageError(format!("{}: {}", path.display(), e.message())))?;
    Ok((meta, path))
}

/// The named `columns` of a numeric CSV whose first line is a header, in
/// the order asked, one `Vec` per row; a missing column, a short or long
/// row, text that is not UTF-8 or a non-finite number is an error naming
/// file, line and column. Blank lines and lines starting with `#` (the
/// provenance a reference file opens with) are skipped.
pub fn read_csv_columns(file: &Path, columns: &[&str]) -> Result<Vec<Vec<f64>>, UsageError> {
    let bad = |what: String| UsageError(format!("{}: {what}", file.display()));
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .comment(Some(b'#'))
        .from_path(file)
        .map_err(|e| UsageError(format!("cannot read {}: {e}", file.display())))?;
    let header: Vec<String> = reader
        .headers()
        .map_err(|e| bad(e.to_string()))?
        .iter()
        .map(str::to_string)
        .collect();
    let index: Vec<usize> = columns
        .iter()
        .map(|c| {
            header
                .iter()
                .position(|h| h == c)
                .ok_or_else(|| bad(format!("missing column `{c}` (header: `{}`)", header.join(","))))
        })
        .collect::<Result<_, _>>()?;
    let mut rows = Vec::new();
    for record in reader.records() {
        let record = record.map_err(|e| bad(e.to_string()))?;
        let line = record.position().map_or(0, |p| p.line());
        let row: Vec<f64> = record
            .iter()
            .map(|c| c.parse::<f64>().ok().filter(|v| v.is_finite()))
            .collect::<Option<_>>()
            .filter(|r: &Vec<f64>| r.len() == header.len())
            .ok_or_else(|| {
                bad(format!(
                    "line {line}: expected {} finite numbers, got `{}`",
                    header.len(),
                    record.iter().collect::<Vec<_>>().join(",")
                ))
            })?;
        rows.push(index.iter().map(|&i| row[i]).collect());
    }
    Ok(rows)
}

/// Two named columns as `(x, y)` pairs with `x` strictly increasing and at
/// least two rows: a tabulated curve.
pub fn read_curve(file: &Path, x: &str, y: &str) -> Result<Vec<(f64, f64)>, UsageError> {
    let rows: Vec<(f64, f64)> = read_csv_columns(file, &[x, y])?
        .into_iter()
        .map(|r| (r[0], r[1]))
        .collect();
    if rows.len() < 2 || rows.windows(2).any(|w| !(w[1].0 > w[0].0)) {
        return Err(UsageError(format!(
            "{}: needs >= 2 rows of increasing `{x}`",
            file.display()
        )));
    }
    Ok(rows)
}

/// Linear interpolation of a tabulated curve (increasing `x`); `None`
/// outside its range.
pub fn interpolate(rows: &[(f64, f64)], x: f64) -> Option<f64> {
    let i = rows.windows(2).position(|w| x >= w[0].0 && x <= w[1].0)?;
    let (a, b) = (rows[i], rows[i + 1]);
    Some(a.1 + (b.1 - a.1) * (x - a.0) / (b.0 - a.0))
}
