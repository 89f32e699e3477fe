//! The one error type of this crate.

use std::fmt;
use std::path::{Path, PathBuf};

/// Everything that can go wrong while writing, reading or rendering a report.
///
/// Every variant names the file it concerns; parse errors also name the line
/// (1-based, the header is line 1) and the column, so a person can open the
/// file and fix it.
#[derive(Debug)]
pub enum ReportError {
    /// Reading, writing or creating a file or folder failed.
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A CSV file is malformed: missing column, bad number, ragged row...
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number (the header is line 1).
        line: u64,
        /// Column name (or `"(header)"` / `"(row)"` when no single column is at fault).
        column: String,
        /// What is wrong, with the offending value.
        message: String,
    },
    /// `summary.json` could not be read or written as a [`crate::RunInfo`].
    Json {
        /// The file.
        path: PathBuf,
        /// The serde_json message (it carries line and column).
        message: String,
    },
    /// The data cannot be written as asked (e.g. a metric named like a fixed column).
    Invalid {
        /// The file being written.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// plotters failed to draw or encode a plot.
    Plot {
        /// The plot file.
        path: PathBuf,
        /// The plotters message.
        message: String,
    },
}

impl ReportError {
    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        ReportError::Io {
            path: path.to_path_buf(),
            source,
        }
    }

    pub(crate) fn parse(path: &Path, line: u64, column: &str, message: impl Into<String>) -> Self {
        ReportError::Parse {
            path: path.to_path_buf(),
            line,
            column: column.to_string(),
            message: message.into(),
        }
    }

    /// A CSV reader's or writer's error, in words: an I/O error stays one;
    /// a file that is not UTF-8 text (a binary file) or a ragged row is
    /// said so, with the line.
    pub(crate) fn csv(path: &Path, e: csv::Error) -> Self {
        let line = e.position().map(|p| p.line()).unwrap_or(0);
        let message = match e.kind() {
            csv::ErrorKind::Utf8 { err, .. } => format!(
                "not UTF-8 text (is it a binary file?): field {} has an invalid byte after {} valid bytes",
                err.field() + 1,
                err.valid_up_to()
            ),
            csv::ErrorKind::UnequalLengths { expected_len, len, .. } => {
                format!("{len} fields where the first row has {expected_len}")
            }
            _ => e.to_string(),
        };
        match e.into_kind() {
            csv::ErrorKind::Io(io) => ReportError::io(path, io),
            _ => ReportError::parse(path, line, "(row)", message),
        }
    }

    pub(crate) fn plot(path: &Path, message: impl fmt::Display) -> Self {
        ReportError::Plot {
            path: path.to_path_buf(),
            message: message.to_string(),
        }
    }
}

impl fmt::Display for ReportError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ReportError::Io { path, source } => write!(f, "{}: {}", path.display(), source),
            ReportError::Parse {
                path,
                line,
                column,
                message,
            } => write!(f, "{}: line {}, column `{}`: {}", path.display(), line, column, message),
            ReportError::Json { path, message } => write!(f, "{}: {}", path.display(), message),
            ReportError::Invalid { path, message } => write!(f, "{}: {}", path.display(), message),
            ReportError::Plot { path, message } => {
                write!(f, "{}: plotting failed: {}", path.display(), message)
            }
        }
    }
}

impl std::error::Error for ReportError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            ReportError::Io { source, .. } => Some(source),
            _ => None,
        }
    }
}
