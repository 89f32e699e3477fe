//! CSV tables with a header row, read through the `csv` crate: the rows of
//! trimmed cells with their 1-based line numbers, and the header's column
//! lookup the dataset readers share ([`super::truth_cube`],
//! [`crate::haptic::Session`]).
//!
//! ```
//! use surgbench_core::io::table;
//! let rows = table::rows("# note\nt, x\n0, 1\n\n1, 2\n", true).unwrap();
//! assert_eq!(rows.len(), 3);
//! assert_eq!((rows[0].line, rows[2].line), (2, 5));
//! assert_eq!(table::column(&rows[0].cells, "x"), Some(1));
//! assert_eq!(&rows[2].cells[1], "2");
//! ```

/// One non-empty row: its 1-based line and its cells, trimmed.
#[derive(Debug, Clone)]
pub struct Row {
    /// 1-based line number of the row in the text.
    pub line: usize,
    /// The row's cells, surrounding whitespace removed.
    pub cells: csv::StringRecord,
}

/// The non-empty rows of CSV `text` (rows whose cells are all empty are
/// skipped), each with its line number. Rows may have different lengths;
/// with `comments`, rows whose first cell starts with `#` are skipped
/// (filtered here: the `csv` reader's own comment and blank-line skipping
/// would leave those lines out of its line count).
/// Fails with the line and the reason when the text is not CSV (e.g. not
/// UTF-8 or an unterminated quote).
pub fn rows(text: &str, comments: bool) -> Result<Vec<Row>, (usize, String)> {
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .trim(csv::Trim::All)
        .from_reader(text.as_bytes());
    let mut out = Vec::new();
    for record in reader.records() {
        let cells = record.map_err(|e| (e.position().map_or(0, |p| line_at(text, p)), e.to_string()))?;
        let line = cells.position().map_or(0, |p| line_at(text, p));
        if cells.iter().all(str::is_empty) || (comments && cells.get(0).is_some_and(|c| c.starts_with('#'))) {
            continue;
        }
        out.push(Row { line, cells });
    }
    Ok(out)
}

/// Index of the header cell `name`, if the header has it.
pub fn column(header: &csv::StringRecord, name: &str) -> Option<usize> {
    header.iter().position(|h| h == name)
}

/// 1-based line of the record starting at the byte position `p` in `text`.
/// The `csv` reader's own line count leaves out the blank lines it skips,
/// and its position can stand before them: they are passed over here.
fn line_at(text: &str, p: &csv::Position) -> usize {
    let bytes = text.as_bytes();
    let mut byte = (p.byte() as usize).min(bytes.len());
    while byte < bytes.len() && matches!(bytes[byte], b'\n' | b'\r') {
        byte += 1;
    }
    bytes[..byte].iter().filter(|&&b| b == b'\n').count() + 1
}
