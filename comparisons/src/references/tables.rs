//! Reading the tables a reference ships: numeric CSV with a header, and the
//! `[parameters]` of its `meta.toml`.

use crate::error::UsageError;
use std::path::{Path, PathBuf};
use surgbench_core::io::table;

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

/// The named `columns` of a numeric CSV whose first row is a header, in
/// the order asked, one `Vec` per row, read with [`table::rows`]; a missing
/// column, a short or long row, text that is not UTF-8 or a non-finite
/// number is an error naming file, line and column. Blank lines and lines
/// starting with `#` (the provenance a reference file opens with) are
/// skipped.
pub fn read_csv_columns(file: &Path, columns: &[&str]) -> Result<Vec<Vec<f64>>, UsageError> {
    let bad = |what: String| UsageError(format!("{}: {what}", file.display()));
    let text = std::fs::read_to_string(file).map_err(|e| UsageError(format!("cannot read {}: {e}", file.display())))?;
    let rows = table::rows(&text, true).map_err(|(line, e)| bad(format!("line {line}: {e}")))?;
    let Some((header, body)) = rows.split_first() else {
        return Err(bad("no header".into()));
    };
    let index: Vec<usize> = columns
        .iter()
        .map(|c| {
            table::column(&header.cells, c).ok_or_else(|| {
                let names: Vec<&str> = header.cells.iter().collect();
                bad(format!("missing column `{c}` (header: `{}`)", names.join(",")))
            })
        })
        .collect::<Result<_, _>>()?;
    let mut out = Vec::with_capacity(body.len());
    for row in body {
        let values: Vec<f64> = row
            .cells
            .iter()
            .map(|c| c.parse::<f64>().ok().filter(|v| v.is_finite()))
            .collect::<Option<_>>()
            .filter(|r: &Vec<f64>| r.len() == header.cells.len())
            .ok_or_else(|| {
                let cells: Vec<&str> = row.cells.iter().collect();
                bad(format!(
                    "line {}: expected {} finite numbers, got `{}`",
                    row.line,
                    header.cells.len(),
                    cells.join(",")
                ))
            })?;
        out.push(index.iter().map(|&i| values[i]).collect());
    }
    Ok(out)
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
