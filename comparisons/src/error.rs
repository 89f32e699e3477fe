//! The harness's usage error: what the CLI reports on one line with exit
//! code 2 (bad parameter, unknown name, malformed file).

use std::fmt;

/// A usage error: bad parameter, unknown name. The CLI prints it on one line
/// and exits with code 2.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UsageError(pub String);

impl fmt::Display for UsageError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for UsageError {}
